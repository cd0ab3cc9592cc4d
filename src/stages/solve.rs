//! The `solve` stage: the node trajectory of the body, by the scene's method.
//!
//! - `hermite`: the keyframes joined with zero velocities (the geometric baseline); its W is
//!   still evaluated, so reports compare methods on one scale.
//! - `spacetime`: BlendSim's spacetime projective dynamics, starting from that baseline.

use std::time::Instant;

use crate::error::Result;
use crate::physics::elastic::Elastic;
use crate::progress::Progress;
use crate::scene::Method;
use crate::spacetime::solver::{self, initial_trajectory, Settings};
use crate::stage::{Body, Solution, SolverLog};

pub fn solve(body: &Body, progress: &Progress) -> Result<Solution> {
    let scene = &body.scene;
    let elastic = Elastic::new(&body.mesh, &scene.material)?;
    let settings = Settings::from_scene(scene);
    let (trajectory, log) = match scene.solver.method {
        Method::Hermite => {
            let start = Instant::now();
            let trajectory = initial_trajectory(&body.keys);
            let objective = solver::objective(&elastic, &body.keys, &settings);
            let w = objective.evaluate(&trajectory, &objective.local_step(&trajectory, false)).value;
            let log = SolverLog {
                method: Method::Hermite,
                iterations: 0,
                energy: vec![w],
                seconds: start.elapsed().as_secs_f64(),
                precompute_seconds: 0.0,
                iteration_seconds: 0.0,
                unknowns: 0,
                halvings: 0,
                converged: true,
                stop_reason: "hermite: keyframes joined with zero velocities, nothing to optimize".into(),
            };
            (trajectory, log)
        }
        Method::Spacetime => {
            let bar = progress.bar(scene.solver.max_iterations as u64, "solve: spacetime");
            let solved = solver::solve(&elastic, &body.keys, &settings, &|k, w| {
                bar.set_position(k as u64);
                bar.set_message(format!("solve: spacetime W = {w:.4e}"));
            })?;
            bar.finish_and_clear();
            (solved.trajectory, solved.log)
        }
    };
    Ok(Solution { body: body.clone(), trajectory, log })
}
