//! The `report` stage: measure an animation and the files exported from it.

use crate::mesh::{bbox_diagonal, surface};
use crate::report::measures::{blendshape_error, deviation, size_ratios, volume_range};
use crate::report::{Report, Volume};
use crate::spacetime::trajectory::Trajectory;
use crate::stage::{Animation, Outputs};

/// The report of an animation and the files exported from it.
pub fn report(animation: &Animation, outputs: &Outputs) -> Report {
    let scene = &animation.scene;
    let tr = &animation.trajectory;
    let frames = tr.frames(scene.fps);
    let diagonal = bbox_diagonal(&animation.mesh.positions);
    let error = blendshape_error(tr, scene.export.weights, &frames, diagonal);
    // At the input keys' times: a trajectory may hold in-between keys too (mass-spring).
    let key_times = &scene.keyframes.times;
    let keyframe_deviation = deviation(key_times.iter().map(|&t| tr.evaluate(t)).zip(animation.input_keys.iter().cloned()), diagonal);
    let triangles = &animation.mesh.triangles;
    let closed = !triangles.is_empty() && surface::open_edges(&animation.mesh).is_empty();
    let rest_volume = surface::enclosed_volume(&animation.mesh.positions, triangles);
    let volume = (closed && rest_volume > 0.0).then(|| {
        let hermite = Trajectory::with_zero_velocities(key_times.clone(), animation.input_keys.clone());
        Volume {
            rest: rest_volume,
            animation: volume_range(tr, &frames, triangles, rest_volume),
            hermite: volume_range(&hermite, &frames, triangles, rest_volume),
        }
    });
    Report {
        scene: scene.name.clone(),
        vertices: animation.counts.vertices,
        faces: animation.counts.faces,
        tet_nodes: animation.counts.tet_nodes,
        tets: animation.counts.tets,
        keyframes: animation.counts.keyframes,
        duration_s: tr.duration(),
        fps: scene.fps,
        frames: frames.len(),
        solver: animation.log.clone(),
        outputs: outputs.files.clone(),
        ratios: size_ratios(&outputs.files),
        error,
        keyframe_deviation,
        volume,
    }
}
