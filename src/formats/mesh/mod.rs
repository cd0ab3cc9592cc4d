//! Mesh files: the readers keep the vertex order of the file, since per-vertex masks in scene
//! files index it.
//!
//! - [`obj`] surfaces, [`medit`] and [`tetgen_io`] tet meshes (and the `.smesh` TetGen reads);
//! - [`selection`]: vertex index and `.dmat` files.

pub mod medit;
pub mod obj;
pub mod selection;
pub mod tetgen_io;

use std::path::Path;

use crate::algorithms::geometry::{Point, TetMesh, TriMesh};
use crate::support::error::{Error, Result};

/// What a keyframe file holds: a surface to tetrahedralize, or a ready tet mesh.
#[derive(Debug, Clone, PartialEq)]
pub enum MeshFile {
    /// An OBJ surface.
    Surface(TriMesh),
    /// A MEDIT or TetGen tet mesh.
    Volume(TetMesh),
}

impl MeshFile {
    /// The vertex (or node) positions.
    pub fn positions(&self) -> &[Point] {
        match self {
            MeshFile::Surface(m) => &m.positions,
            MeshFile::Volume(m) => &m.positions,
        }
    }
}

/// Read a keyframe mesh, choosing the format by extension: `.obj` (surface), `.mesh` (MEDIT
/// tets), `.node` or `.ele` (TetGen pair, the other file beside it).
pub fn read(path: &Path) -> Result<MeshFile> {
    let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    match ext.as_deref() {
        Some("obj") => obj::read(path).map(MeshFile::Surface),
        Some("mesh") => medit::read(path).map(MeshFile::Volume),
        Some("node") | Some("ele") => tetgen_io::read(path).map(MeshFile::Volume),
        _ => Err(Error::in_file(path, "unknown mesh format", "use .obj for surfaces, .mesh (MEDIT) or .node/.ele (TetGen) for tet meshes")),
    }
}
