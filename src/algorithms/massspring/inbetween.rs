//! In-between shapes on every keyframe interval: the mass-spring model used to animate keys
//! (`[solver] method = "mass-spring"`).
//!
//! Interval `[t_k, t_k+1]` gets `inbetweens` shapes at `θ = i / (inbetweens + 1)` with weights
//! `(1 - α, α)` on keys `k` and `k + 1`, `α = 3θ² - 2θ³`: the hermite baseline's easing, so the
//! linear blend at the same `α` IS the hermite trajectory and the two methods differ in shape,
//! not timing. Each shape's velocity is `dX/dα · dα/dt` (`dX/dα` by central differences over
//! the interval's shapes, zero at the keys like the baseline's), and the trajectory is the
//! cubic Hermite curve through keys and in-betweens: every in-between is an exact equilibrium,
//! frames between them are interpolated. Vertices held at EVERY key (and not the whole
//! surface) follow the eased linear blend as fixed vertices; otherwise the body hangs on the
//! paper's default anchor. The tet body's edges are the internal springs and every node's
//! keyframe pose is its target pose.

use std::time::Instant;

use super::blend::ModelSummary;
use super::{Boundary, MassSpring, Obstacle, Settings, Targets};
use crate::algorithms::geometry::{surface, Point, TetMesh};
use crate::algorithms::spacetime::trajectory::Trajectory;
use crate::algorithms::spacetime::unknowns::KeyConstraints;
use crate::support::error::{Error, Result};
use crate::support::progress::Progress;

/// The trajectory through keys and in-betweens, and what it took.
#[derive(Debug, Clone)]
pub struct Inbetweens {
    /// Keys and in-betweens, in time order, with their velocities.
    pub trajectory: Trajectory,
    /// Newton iterations over all in-betweens.
    pub iterations: usize,
    /// In-betweens solved.
    pub blends: usize,
    /// Vertex holds on obstacles over all in-betweens.
    pub held_vertices: usize,
    /// Seconds spent building the spring network.
    pub network_seconds: f64,
    /// Whether the vertices held at every key were the boundary (else the default anchor).
    pub fixed: bool,
    /// The network.
    pub summary: ModelSummary,
}

/// The hermite baseline's easing `α(θ) = 3θ² - 2θ³` and its derivative.
fn ease(theta: f64) -> (f64, f64) {
    (theta * theta * (3.0 - 2.0 * theta), 6.0 * theta * (1.0 - theta))
}

/// The trajectory of `mesh` through `keys` with `inbetweens` equilibria per keyframe interval
/// (module documentation), the blends kept out of `obstacles`; `settings.budget` bounds the
/// time and the memory.
pub fn inbetween(
    mesh: &TetMesh,
    keys: &KeyConstraints,
    inbetweens: usize,
    settings: &Settings,
    obstacles: &[Obstacle],
    progress: &Progress,
) -> Result<Inbetweens> {
    let start = Instant::now();
    let nodes = mesh.positions.len();
    // Surface nodes first, in index order (the model's convention), then the interior.
    let triangles = surface::boundary(mesh);
    let mut on_surface = vec![false; nodes];
    triangles.iter().flatten().for_each(|&v| on_surface[v as usize] = true);
    let order: Vec<usize> = (0..nodes).filter(|&v| on_surface[v]).chain((0..nodes).filter(|&v| !on_surface[v])).collect();
    let surface_count = on_surface.iter().filter(|&&s| s).count();
    let mut new_index = vec![0u32; nodes];
    for (i, &v) in order.iter().enumerate() {
        new_index[v] = i as u32;
    }
    let permute = |x: &[Point]| -> Vec<Point> { order.iter().map(|&v| x[v]).collect() };
    let poses: Vec<Vec<Point>> = keys.positions.iter().map(|p| permute(p)).collect();
    let surfaces: Vec<Vec<Point>> = poses.iter().map(|p| p[..surface_count].to_vec()).collect();
    let triangles: Vec<[u32; 3]> = triangles.iter().map(|t| t.map(|v| new_index[v as usize])).collect();
    let tet_body = TetMesh { positions: poses[0].clone(), tets: mesh.tets.iter().map(|t| t.map(|v| new_index[v as usize])).collect() };
    let targets = Targets { surface: &surfaces, triangles: &triangles, body: Some(&tet_body), body_poses: Some(&poses) };
    // Held at every key, and not the whole surface: those follow the (eased) linear blend.
    let mut keys_holding = vec![0; nodes];
    keys.fixed.iter().flatten().for_each(|&v| keys_holding[v as usize] += 1);
    let held: Vec<u32> = (0..nodes as u32).filter(|&v| keys_holding[v as usize] == keys.fixed.len()).map(|v| new_index[v as usize]).collect();
    let boundary = if !held.is_empty() && held.len() < surface_count {
        let mut held = held;
        held.sort_unstable();
        Boundary::Fixed(held)
    } else {
        Boundary::Anchor(None)
    };
    let bar = progress.stage("solve: mass-spring network");
    let mut model = MassSpring::new(&targets, &boundary, settings)?;
    bar.finish_and_clear();
    let network_seconds = start.elapsed().as_secs_f64();

    let key_count = keys.times.len();
    let steps = inbetweens + 1;
    let mut times = vec![keys.times[0]];
    let mut positions = vec![keys.positions[0].clone()];
    let mut velocities = vec![vec![[0.0; 3]; nodes]];
    let (mut iterations, mut blends, mut held_vertices) = (0, 0, 0);
    let bar = progress.bar(((key_count - 1) * inbetweens) as u64, "solve: mass-spring in-betweens");
    let unpermute = |x: &[Point]| -> Vec<Point> { (0..nodes).map(|v| x[new_index[v] as usize]).collect() };
    for k in 0..key_count - 1 {
        let (t0, t1) = (keys.times[k], keys.times[k + 1]);
        // The interval's shapes at α = 0, the in-betweens, α = 1.
        let mut alphas = vec![0.0];
        let mut shapes = vec![keys.positions[k].clone()];
        for i in 1..steps {
            settings.budget.check_time("mass-spring in-betweens", || format!("after {blends} of {} in-betweens", (key_count - 1) * inbetweens))?;
            let (alpha, _) = ease(i as f64 / steps as f64);
            let mut w = vec![0.0; key_count];
            w[k] = 1.0 - alpha;
            w[k + 1] = alpha;
            let shape = model
                .blend(&w, obstacles)
                .map_err(|e| Error { problem: format!("mass-spring in-between {i} of interval {k} (t = {t0} to {t1}): {}", e.problem), ..e })?;
            iterations += shape.report.iterations;
            held_vertices += shape.report.held.len();
            blends += 1;
            alphas.push(alpha);
            shapes.push(unpermute(&shape.positions[..nodes]));
            bar.inc(1);
        }
        alphas.push(1.0);
        shapes.push(keys.positions[k + 1].clone());
        for i in 1..steps {
            let (_, rate) = ease(i as f64 / steps as f64);
            let scale = rate / (t1 - t0) / (alphas[i + 1] - alphas[i - 1]);
            times.push(t0 + (t1 - t0) * i as f64 / steps as f64);
            velocities.push((0..nodes).map(|v| std::array::from_fn(|c| (shapes[i + 1][v][c] - shapes[i - 1][v][c]) * scale)).collect());
            positions.push(shapes[i].clone());
        }
        times.push(t1);
        positions.push(keys.positions[k + 1].clone());
        velocities.push(vec![[0.0; 3]; nodes]);
    }
    bar.finish_and_clear();
    if keys.cyclic {
        // The last key is the first, exactly (as the other methods make it).
        let first = positions[0].clone();
        *positions.last_mut().expect("keys") = first;
    }
    Ok(Inbetweens {
        trajectory: Trajectory { times, positions, velocities },
        iterations,
        blends,
        held_vertices,
        network_seconds,
        fixed: matches!(boundary, Boundary::Fixed(_)),
        summary: model.summary().clone(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn easing_is_the_hermite_baselines() {
        // The hermite baseline's position weight of the next key is 3θ² - 2θ³; its derivative
        // checked by central differences.
        for theta in [0.0, 0.1, 0.25, 0.5, 0.9, 1.0] {
            let (a, da) = ease(theta);
            let h01 = crate::algorithms::spacetime::trajectory::hermite_weights(theta, 1.0).pos[2];
            assert!((a - h01).abs() < 1e-15, "θ = {theta}: {a} vs {h01}");
            let e = 1e-6;
            let fd = (ease(theta + e).0 - ease(theta - e).0) / (2.0 * e);
            assert!((da - fd).abs() < 1e-8, "θ = {theta}: {da} vs {fd}");
        }
    }
}
