//! Small tet meshes shared by the unit tests of several modules (the random generator and the
//! paper's assets are `support::testing`'s).

use crate::algorithms::geometry::TetMesh;

/// A cube [0,1]³ split into `n³` cells of 6 tets each (Kuhn triangulation, positive).
pub fn cube_mesh(n: usize) -> TetMesh {
    box_mesh([1.0; 3], [n; 3])
}

/// A box [0, size] split into `divisions` cells of 6 tets each ([`crate::algorithms::procedural::box_tets`]).
pub fn box_mesh(size: [f64; 3], divisions: [usize; 3]) -> TetMesh {
    crate::algorithms::procedural::box_tets(size, divisions)
}
