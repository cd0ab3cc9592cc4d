//! Surface operations (helper-owned): boundary of a tet mesh, consistent outward winding,
//! compaction, and closedness diagnostics.

use super::{TetMesh, TriMesh};

/// Triangles that belong to exactly one tet, wound so their normal points out of the body
/// (tets positively oriented), in a deterministic order.
pub fn boundary(mesh: &TetMesh) -> Vec<[u32; 3]> {
    let _ = mesh;
    todo!()
}

/// Make the winding consistent across shared edges and pointing outward (positive enclosed
/// volume) for each connected component. Returns the number of triangles flipped.
pub fn orient_outward(mesh: &mut TriMesh) -> usize {
    let _ = mesh;
    todo!()
}

/// Drop vertices no triangle uses. Returns the compacted mesh and, for each new vertex, its
/// index in the input.
pub fn compact(mesh: &TriMesh) -> (TriMesh, Vec<u32>) {
    let _ = mesh;
    todo!()
}

/// Edges used by exactly one triangle (a hole's rim), as vertex pairs.
pub fn open_edges(mesh: &TriMesh) -> Vec<[u32; 2]> {
    let _ = mesh;
    todo!()
}
