//! TetGen `.node` / `.ele` files and the `.smesh` PLC we feed TetGen (helper-owned).

use std::path::Path;

use super::{Point, TetMesh, TriMesh};
use crate::error::Result;

/// Read a `.node`/`.ele` pair given either file; indices may be 0- or 1-based (taken from the
/// first node number). Tets are oriented to positive volume.
pub fn read(path: &Path) -> Result<TetMesh> {
    let _ = path;
    todo!("mesh::tetgen_io::read")
}

/// Parse `.node` text: returns the points and the first index (0 or 1).
pub fn parse_node(text: &str) -> Result<(Vec<Point>, usize)> {
    let _ = text;
    todo!()
}

/// Parse `.ele` text given the first node index.
pub fn parse_ele(text: &str, first_index: usize, node_count: usize) -> Result<Vec<[u32; 4]>> {
    let _ = (text, first_index, node_count);
    todo!()
}

/// A `.smesh` PLC for a closed surface (all vertices listed, 0-based).
pub fn write_smesh(surface: &TriMesh) -> String {
    let _ = surface;
    todo!()
}
