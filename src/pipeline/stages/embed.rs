//! The `embed` stage: carry the body's exported surface on the solved node trajectory.
//!
//! The surface is bound to the rest tet mesh by barycentric coordinates (`embed::Binding`: the
//! closest tet for points outside). The binding is linear, so the Hermite trajectory is carried
//! exactly, not resampled. The input keyframes are carried by the same binding, so reports
//! compare like with like.

use crate::algorithms::embed::Binding;
use crate::algorithms::geometry::Point;
use crate::pipeline::stage_file::{Animation, Counts, Solution};
use crate::support::error::Result;

/// The exported surface's animation.
pub fn embed(solution: &Solution) -> Result<Animation> {
    let body = &solution.body;
    let Some(tets) = &body.mesh else {
        // Nothing simulated (`fit`): the trajectory is the surface's own.
        return Ok(Animation {
            scene: body.scene.clone(),
            counts: Counts {
                vertices: body.surface.positions.len(),
                faces: body.surface.triangles.len(),
                tet_nodes: 0,
                tets: 0,
                keyframes: body.keys.times.len(),
                largest_tet_volume: None,
            },
            mesh: body.surface.clone(),
            trajectory: solution.trajectory.clone(),
            input_keys: body.keys.positions.clone(),
            log: solution.log.clone(),
            cache: body.cache.clone(),
            cage: None,
            warnings: body.warnings.clone(),
            input_bytes: body.input_bytes,
            weld: body.weld.clone(),
        });
    };
    let binding = Binding::compute(tets, &body.surface.positions);
    let carry = |nodes: &[Point]| binding.apply(tets, nodes);
    Ok(Animation {
        scene: body.scene.clone(),
        counts: Counts {
            vertices: body.surface.positions.len(),
            faces: body.surface.triangles.len(),
            tet_nodes: tets.positions.len(),
            tets: tets.tets.len(),
            keyframes: body.keys.times.len(),
            largest_tet_volume: Some((0..tets.tets.len()).map(|t| tets.signed_volume_at(&tets.positions, t).abs()).fold(0.0, f64::max)),
        },
        mesh: body.surface.clone(),
        trajectory: solution.trajectory.map_linear(carry),
        input_keys: body.keys.positions.iter().map(|p| carry(p)).collect(),
        log: solution.log.clone(),
        cache: body.cache.clone(),
        cage: body.cage.clone(),
        warnings: body.warnings.clone(),
        input_bytes: body.input_bytes,
        weld: body.weld.clone(),
    })
}
