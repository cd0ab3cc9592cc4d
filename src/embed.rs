//! Barycentric binding of surface points to a tet mesh (helper-owned).
//!
//! Contract: each point gets a tet and four barycentric weights summing to 1. Points inside
//! the mesh use the tet containing them; points outside use the closest tet and the
//! barycentric coordinates of the closest point on it (all weights >= 0). A BVH over tet
//! bounds finds candidates; results are deterministic (ties broken by lowest tet index).

use crate::mesh::{Point, TetMesh};

#[derive(Debug, Clone, PartialEq)]
pub struct Binding {
    pub tets: Vec<u32>,
    pub weights: Vec<[f64; 4]>,
    /// Distance from each point to its tet (0 inside), for diagnostics.
    pub distances: Vec<f64>,
}

impl Binding {
    pub fn compute(mesh: &TetMesh, points: &[Point]) -> Binding {
        let _ = (mesh, points);
        todo!()
    }

    /// Points carried by node positions `nodes` (same indexing as the mesh).
    pub fn apply(&self, mesh: &TetMesh, nodes: &[Point]) -> Vec<Point> {
        let _ = (mesh, nodes);
        todo!()
    }
}

/// The `embed` stage: carry the body's exported surface on the solved node trajectory. The
/// input keyframes are carried by the same binding, so reports compare like with like.
pub fn embed(solution: &crate::stage::Solution) -> crate::error::Result<crate::stage::Animation> {
    let body = &solution.body;
    let binding = Binding::compute(&body.mesh, &body.surface.positions);
    let carry = |nodes: &[Point]| binding.apply(&body.mesh, nodes);
    Ok(crate::stage::Animation {
        scene: body.scene.clone(),
        counts: crate::stage::Counts {
            vertices: body.surface.positions.len(),
            faces: body.surface.triangles.len(),
            tet_nodes: body.mesh.positions.len(),
            tets: body.mesh.tets.len(),
            keyframes: body.keys.times.len(),
        },
        mesh: body.surface.clone(),
        trajectory: solution.trajectory.map_linear(carry),
        input_keys: body.keys.positions.iter().map(|p| carry(p)).collect(),
        log: solution.log.clone(),
    })
}
