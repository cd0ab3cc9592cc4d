//! MEDIT ASCII `.mesh` tet meshes (helper-owned).
//!
//! Contract: `MeshVersionFormatted`, `Dimension 3`, `Vertices`, `Tetrahedra` blocks (others,
//! e.g. `Triangles`, `Edges`, `Corners`, are skipped), 1-based indices, each row ending with
//! a reference number; `End` optional. Every tet is oriented to positive volume on load.
//! Degenerate (zero-volume) tets and out-of-range indices are errors naming the block row.

use std::path::Path;

use super::TetMesh;
use crate::error::Result;

pub fn read(path: &Path) -> Result<TetMesh> {
    let _ = path;
    todo!("mesh::medit::read")
}

pub fn parse(text: &str) -> Result<TetMesh> {
    let _ = text;
    todo!("mesh::medit::parse")
}
