//! The external TetGen process (helper-owned): write the surface as a PLC, run `tetgen` with a
//! time bound, read `.node`/`.ele` back and check the result.
//!
//! Contract: `-pYz` plus `-q{quality}` and `-a{max_volume}` when nonzero, quiet, in a private
//! temporary folder. Surface vertices keep their indices: node `i < surface.positions.len()`
//! is surface vertex `i` (checked by position). Diagnosed failures, each an [`Error`] naming
//! the surface file and a fix: `tetgen` not installed (how to install), a surface with a hole
//! (TetGen exits 0 with no tets; name an open edge), self-intersections (exit 134; name the
//! intersecting faces via `tetgen -d` when possible), timeout, unreadable output.

use std::path::Path;

use crate::error::{Error, Result};
use crate::mesh::{TetMesh, TriMesh};

#[derive(Debug, Clone, PartialEq)]
pub struct TetgenOptions {
    /// `-q` radius-edge bound; 0 = no quality refinement.
    pub quality: f64,
    /// `-a` maximum volume; 0 = none.
    pub max_volume: f64,
    /// Seconds before the process is killed.
    pub timeout: f64,
}

/// Tetrahedralize a closed surface. `source` is the file the surface came from (for errors).
pub fn tetrahedralize(surface: &TriMesh, options: &TetgenOptions, source: &Path) -> Result<TetMesh> {
    let _ = (surface, options, source, Error::general("", ""));
    todo!("tetgen::tetrahedralize")
}
