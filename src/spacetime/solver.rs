//! The spacetime projective-dynamics iteration: local step, residuals, global step, repeat.
//!
//! Starts from the keyframes joined with zero velocities (the hermite baseline). Each
//! iteration evaluates W at the current trajectory with fresh projections, stops if W has
//! settled (change below `tolerance × W₀`), and otherwise takes one global step. W is recorded
//! per iteration; NaN or sustained growth is an error, never a silent result.

use std::time::Instant;

use super::global_step::{GlobalStats, GlobalStep};
use super::objective::{Evaluation, Objective};
use super::sampling::{samples, TimeSlots};
use super::trajectory::Trajectory;
use super::unknowns::Unknowns;
use crate::error::{Error, Result};
use crate::mesh::Point;
use crate::physics::elastic::Elastic;
use crate::scene::Method;
use crate::stage::{KeyPoses, SolverLog};

/// Solver settings (from the scene's `[solver]` and `[material]`).
#[derive(Debug, Clone, PartialEq)]
pub struct Settings {
    pub samples: usize,
    pub max_iterations: usize,
    pub tolerance: f64,
    /// Proximal time scale h (0 = off).
    pub regularization: f64,
    pub damping: f64,
    pub gravity: Point,
}

impl Settings {
    pub fn from_scene(scene: &crate::scene::Scene) -> Settings {
        Settings {
            samples: scene.solver.samples,
            max_iterations: scene.solver.max_iterations,
            tolerance: scene.solver.tolerance,
            regularization: scene.solver.regularization,
            damping: scene.material.damping,
            gravity: scene.material.gravity,
        }
    }
}

/// A finished solve.
#[derive(Debug, Clone)]
pub struct Solved {
    pub trajectory: Trajectory,
    pub log: SolverLog,
    pub stats: GlobalStats,
}

/// The initial guess: the input keyframes with zero velocities. In a loop the last key is the
/// first.
pub fn initial_trajectory(keys: &KeyPoses) -> Trajectory {
    let mut positions = keys.positions.clone();
    if keys.cyclic {
        let first = positions[0].clone();
        *positions.last_mut().expect("keys") = first;
    }
    Trajectory::with_zero_velocities(keys.times.clone(), positions)
}

/// The objective of `keys` on `elastic` with these settings.
pub fn objective<'a>(elastic: &'a Elastic, keys: &KeyPoses, settings: &Settings) -> Objective<'a> {
    let slots = TimeSlots { keys: keys.times.len(), cyclic: keys.cyclic };
    Objective {
        elastic,
        samples: samples(&keys.times, settings.samples, &slots),
        slots,
        damping: settings.damping,
        gravity: settings.gravity,
    }
}

/// Add a per-slot step to the trajectory (every key sharing a slot gets the same value).
pub fn apply_step(tr: &mut Trajectory, slots: &TimeSlots, delta: &[Vec<Point>], scale: f64) {
    for (s, ds) in delta.iter().enumerate() {
        for k in slots.keys_of(s) {
            let target = if s % 2 == 0 { &mut tr.positions[k] } else { &mut tr.velocities[k] };
            for (x, d) in target.iter_mut().zip(ds) {
                for c in 0..3 {
                    x[c] += scale * d[c];
                }
            }
        }
    }
}

/// Halvings of a step that would increase W before the iteration stops.
const MAX_HALVINGS: usize = 8;

/// Optimize keyframe positions and velocities. `on_iteration(k, W)` reports progress.
///
/// Each iteration takes the local/global step of the paper. That step is exact for the
/// quadratic model with frozen projections, but not a descent direction of W everywhere (its
/// stiffness is `L`, not `∇²E`), and near its fixed point it can turn W back up. So a step
/// that would increase W is halved until W decreases (the trial's local step is the next
/// iteration's, so an accepted step costs nothing extra); if none does, the iteration stops
/// there. W therefore never increases, and fixed points are untouched.
pub fn solve(elastic: &Elastic, keys: &KeyPoses, settings: &Settings, on_iteration: &dyn Fn(usize, f64)) -> Result<Solved> {
    let start = Instant::now();
    let mut tr = initial_trajectory(keys);
    let objective = objective(elastic, keys, settings);
    let unknowns = Unknowns::new(keys, elastic.node_count());
    let global = GlobalStep::new(&objective, unknowns, settings.regularization)?;
    let precompute_seconds = start.elapsed().as_secs_f64();

    let evaluate = |tr: &Trajectory, iteration: usize| -> Result<Evaluation> {
        let eval = objective.evaluate(tr, &objective.local_step(tr));
        if !eval.value.is_finite() {
            return Err(Error::general(
                format!("the spacetime energy W became {} at iteration {iteration}", eval.value),
                "check the keyframes for flat or inverted tets, and lower [solver] regularization (h) to damp the steps",
            ));
        }
        Ok(eval)
    };
    let t_iterations = Instant::now();
    let mut eval = evaluate(&tr, 0)?;
    on_iteration(0, eval.value);
    let mut energy = vec![eval.value];
    let mut halvings = 0usize;
    let w0 = eval.value;
    let (converged, stop_reason) = loop {
        let w = *energy.last().expect("energy has the initial value");
        if global.unknowns().count() == 0 {
            break (true, "nothing to optimize: every keyframe position and velocity is fixed".to_string());
        }
        if w0 == 0.0 {
            break (true, "W is zero: the keyframes are already physically exact".to_string());
        }
        if energy.len() >= 2 {
            let change = (energy[energy.len() - 2] - w).abs() / w0;
            if change < settings.tolerance {
                break (true, format!("W changed by {change:.3e} of its initial value, below the tolerance {}", settings.tolerance));
            }
        }
        if energy.len() > settings.max_iterations {
            break (false, format!("stopped after max_iterations = {} before W settled", settings.max_iterations));
        }
        let delta = global.step(&eval.gradient);
        let mut scale = 1.0;
        let accepted = loop {
            let mut trial = tr.clone();
            apply_step(&mut trial, &objective.slots, &delta, scale);
            let trial_eval = evaluate(&trial, energy.len())?;
            if trial_eval.value <= w {
                break Some((trial, trial_eval));
            }
            if halvings_exhausted(scale) {
                break None;
            }
            scale *= 0.5;
            halvings += 1;
        };
        let Some((next, next_eval)) = accepted else {
            break (
                false,
                format!("the local/global step no longer decreases W (tried down to 1/{} of it)", 1usize << MAX_HALVINGS),
            );
        };
        tr = next;
        eval = next_eval;
        on_iteration(energy.len(), eval.value);
        energy.push(eval.value);
    };
    let iterations = energy.len() - 1;
    let iteration_time = t_iterations.elapsed().as_secs_f64();
    let log = SolverLog {
        method: Method::Spacetime,
        iterations,
        energy,
        seconds: start.elapsed().as_secs_f64(),
        precompute_seconds,
        iteration_seconds: if iterations > 0 { iteration_time / (iterations + 1) as f64 } else { 0.0 },
        unknowns: global.stats.unknowns,
        halvings,
        converged,
        stop_reason,
    };
    Ok(Solved { trajectory: tr, log, stats: global.stats })
}

fn halvings_exhausted(scale: f64) -> bool {
    scale <= 0.5f64.powi(MAX_HALVINGS as i32)
}
