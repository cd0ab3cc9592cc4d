//! The `solve` stage: the node trajectory of the body, by the scene's method.
//!
//! - `hermite`: the keyframes joined with zero velocities (the geometric baseline); its W is
//!   still evaluated, so reports compare methods on one scale.
//! - `spacetime`: BlendSim's spacetime projective dynamics, starting from that baseline.
//! - `mass-spring`: in-between shapes of Ma et al. 2012 on every interval
//!   ([`massspring::inbetween`](mod@crate::algorithms::massspring::inbetween)).
//!
//! The scene's `[solver]`, `[material]` and `[[obstacle]]` become the solver's [`Settings`] and
//! the body's elastic material here; the body's keyframes become its [`KeyConstraints`].

use std::time::Instant;

use crate::algorithms::massspring::{self, Bending};
use crate::algorithms::physics::elastic::Elastic;
use crate::algorithms::spacetime::contact::Contacts;
use crate::algorithms::spacetime::global_step::Method as GlobalMethod;
use crate::algorithms::spacetime::obstacles::Obstacle;
use crate::algorithms::spacetime::settings::{ModelHessian, Settings, Step, TimingSettings};
use crate::algorithms::spacetime::solver;
use crate::algorithms::spacetime::trajectory::Trajectory;
use crate::algorithms::spacetime::unknowns::KeyConstraints;
use crate::pipeline::report::guard_rails::{code, coded};
use crate::pipeline::scene::memory_model::{self, BakeCounts, StepChoice};
use crate::pipeline::scene::{Method, ObstacleSpec, Scene};
use crate::pipeline::stage_file::{Body, KeyPoses, Solution, SolverLog};
use crate::support::budget::Budget;
use crate::support::error::{Error, Result};
use crate::support::progress::Progress;

/// The solved body. `method` overrides the scene's `[solver] method` (the CLI's `--method`);
/// the solution's scene records the method used.
pub fn solve(body: &Body, method: Option<Method>, progress: &Progress) -> Result<Solution> {
    solve_within(body, method, &Budget::default(), progress)
}

/// [`solve`] within `budget` (the CLI's `--max-memory` and `--max-time`). Past its memory the
/// global step is solved iteratively, to the same solution within the solver's tolerance.
pub fn solve_within(body: &Body, method: Option<Method>, budget: &Budget, progress: &Progress) -> Result<Solution> {
    solve_starting(body, method, budget, progress, None)
}

/// The whole-bake model's counts of `body` before its solve: its own nodes, tets and held
/// positions; the global step as forced (else the cost model's, within what the rest leaves).
fn body_counts(body: &Body) -> BakeCounts {
    let (nodes, tets) = body.mesh.as_ref().map_or((0, 0), |m| (m.positions.len(), m.tets.len()));
    let keys = body.keys.times.len();
    let held: usize = body.keys.fixed.iter().map(|f| f.len()).sum();
    BakeCounts {
        keys,
        surface_vertices: body.surface.positions.len(),
        exported_vertices: body.surface.positions.len(),
        nodes,
        tets,
        unknowns: (2 * keys * nodes).saturating_sub(held),
        held,
        held_nodes: body.keys.fixed.iter().map(|f| f.len()).max().unwrap_or(0),
        caged: body.cage.is_some(),
        tetgen: false,
        step: StepChoice::of(&body.scene.solver),
    }
}

/// [`solve_within`], a spacetime solve starting from `start` when given (an earlier bake's
/// solution moved with the keys' edits, [`solver::solve_starting`]).
pub fn solve_starting(body: &Body, method: Option<Method>, budget: &Budget, progress: &Progress, start: Option<&Trajectory>) -> Result<Solution> {
    let mut body = body.clone();
    if let Some(m) = method {
        body.scene.solver.method = m;
    }
    let scene = &body.scene;
    let tets = match (&body.mesh, scene.solver.method) {
        (None, Method::Fit) => return solve_fit(body, budget),
        (Some(tets), Method::Hermite | Method::Spacetime | Method::MassSpring) => tets,
        (Some(_), Method::Fit) => {
            return Err(Error::general(
                "method fit was chosen after import: this body was tetrahedralized for a simulation",
                "set [solver] method = \"fit\" in the [cache] scene (or bake with --method fit), so the chain skips TetGen",
            ))
        }
        (None, m) => {
            return Err(Error::general(
                format!("method {m} needs a tet mesh, but this body was imported for method fit (nothing to simulate)"),
                format!("set [solver] method = \"{m}\" in the scene (or bake with --method {m}) and re-run import and tetrahedralize"),
            ))
        }
    };
    scene.check_resources(&body.keys.times, body.surface.positions.len(), tets.tets.len(), budget)?;
    let counts = body_counts(&body);
    memory_model::check(scene, &body.keys.times, &counts, budget, true)?;
    let elastic = Elastic::new(tets, &super::elastic_material(scene))?;
    // The global step's cost model chooses within what the solve's other arrays leave.
    let settings = Settings { budget: memory_model::step_budget(scene, &body.keys.times, &counts, budget), ..settings(scene) };
    let keys = key_constraints(&body.keys);
    let input_times = keys.times.clone();
    let (trajectory, log) = match scene.solver.method {
        Method::Hermite => {
            let start = Instant::now();
            let (trajectory, w) = solver::baseline(&elastic, &keys, &settings);
            let stop_reason = "hermite: keyframes joined with zero velocities, nothing to optimize".into();
            let log = SolverLog::closed_form(Method::Hermite, vec![w], start.elapsed().as_secs_f64(), 0, stop_reason, input_times);
            (trajectory, log)
        }
        Method::Spacetime => {
            // The total is the stopping rule's own prediction from the W so far
            // (`solver::IterationEstimate`; not max_iterations, which a converging solve never
            // reaches). The force scale S of every iterate is kept for the report (the floor is
            // `negligible` S), so the estimate can be replayed as the solve made it.
            let bar = progress.iterations("solve: spacetime");
            let estimate = std::sync::Mutex::new((solver::IterationEstimate::default(), Vec::new()));
            // On a worker of the thread pool: the solve's parallel loops (about ten an iteration,
            // each a fraction of a millisecond on a small body) then start inside the pool,
            // instead of each handing itself over from this thread and putting it to sleep (two
            // context switches apiece; the same bytes).
            let solved = rayon::scope(|_| {
                let on_iteration = |k, w, floor| {
                    let mut guard = estimate.lock().unwrap_or_else(|e| e.into_inner());
                    let (running, scales) = &mut *guard;
                    scales.truncate(k);
                    scales.push(if settings.negligible > 0.0 { floor / settings.negligible } else { 0.0 });
                    let total = running.update(k, w, floor, settings.tolerance, settings.max_iterations);
                    drop(guard);
                    match total {
                        Some(total) => bar.set_length(total as u64),
                        None => bar.unset_length(),
                    }
                    bar.set_position(k as u64);
                    bar.set_message(format!("solve: spacetime W = {w:.4e}"));
                };
                match start {
                    Some(start) => solver::solve_starting(&elastic, &keys, &settings, start, &on_iteration),
                    None => solver::solve(&elastic, &keys, &settings, &on_iteration),
                }
            })?;
            bar.finish_and_clear();
            let force_scales = estimate.into_inner().unwrap_or_else(|e| e.into_inner()).1;
            let log = SolverLog::spacetime(solved.log, input_times, solved.trajectory.times.clone(), force_scales);
            (solved.trajectory, log)
        }
        Method::MassSpring => mass_spring(&body, budget, progress)?,
        Method::Fit => unreachable!("handled above"),
    };
    if let Some(w) = cg_capped(&log) {
        body.warn(progress, w);
    }
    Ok(Solution { body, trajectory, log })
}

/// An earlier bake's `solution` of the same body and settings, taken as this one's: the
/// solve's warnings said again.
pub fn reused(mut solution: Solution, progress: &Progress) -> Solution {
    if let Some(w) = cg_capped(&solution.log) {
        solution.body.warn(progress, w);
    }
    solution
}

/// The `cg-capped` warning: iterative global-step solves that stopped at their iteration cap
/// with a residual above their goal, so the result may differ from the direct solve's.
fn cg_capped(log: &SolverLog) -> Option<String> {
    let c = log.conjugate_gradients.as_ref().filter(|c| c.capped > 0)?;
    Some(coded(
        code::CG_CAPPED,
        format_args!(
            "{} of {} iterative global-step solves stopped at {} CG iterations with a relative residual up to {:.1e} (goal {:.0e}); the result may differ from the direct solve's (give the direct solver the memory with --max-memory, or use fewer keys or a coarser body)",
            c.capped, c.solves, c.max_iterations, c.worst_residual, c.tolerance
        ),
    ))
}

/// `fit`: the least-squares cubic Hermite fit of the body's cache on its keys, with the keys'
/// `fixed` vertices held on the cache frames. No physics: W is not evaluated.
fn solve_fit(body: Body, budget: &Budget) -> Result<Solution> {
    let start = Instant::now();
    let record = body
        .cache
        .as_ref()
        .ok_or_else(|| Error::general("method fit needs a vertex cache, and this body has none", "give the scene a [cache] table"))?;
    let trajectory = super::import_cache::fit_cache(record, budget)?;
    let stop_reason = "fit: linear least squares, solved exactly".into();
    let log = SolverLog::closed_form(
        Method::Fit,
        Vec::new(),
        start.elapsed().as_secs_f64(),
        2 * body.keys.times.len(),
        stop_reason,
        body.keys.times.clone(),
    );
    Ok(Solution { body, trajectory, log })
}

/// `method = "mass-spring"`: the node trajectory of `body` with `[mass_spring] inbetweens`
/// equilibria per keyframe interval ([`massspring::inbetween`](mod@massspring::inbetween)), and
/// its log. Its `W` is the spacetime objective of that trajectory (the same integral, sampled
/// on the finer intervals), so reports compare it with the other methods.
fn mass_spring(body: &Body, budget: &Budget, progress: &Progress) -> Result<(Trajectory, SolverLog)> {
    let start = Instant::now();
    let scene = &body.scene;
    let spec = &scene.mass_spring;
    let keys = &body.keys;
    let Some(mesh) = body.mesh.as_ref() else {
        return Err(Error::general(
            "method mass-spring needs a tet mesh, but this body was imported for method fit",
            "set [solver] method = \"mass-spring\" in the scene (or bake with --method mass-spring) and re-run import and tetrahedralize",
        ));
    };
    let model = massspring::Settings {
        bending: if spec.bending == "hinge" { Bending::Hinge } else { Bending::TwoRing },
        tolerance: spec.tolerance,
        budget: *budget,
        ..massspring::Settings::default()
    };
    // The scene's `[[obstacle]]` entries, the same ones the spacetime solver's contacts use.
    let obstacles: Vec<massspring::Obstacle> = scene.obstacles.iter().map(super::blend::model_obstacle).collect();
    let done = massspring::inbetween(mesh, &key_constraints(keys), spec.inbetweens, &model, &obstacles, progress)?;
    let trajectory = done.trajectory;
    // Say whether the exported frames are equilibria: frames on a key or an in-between are,
    // frames between them are Hermite-interpolated.
    let frames = trajectory.frames(scene.fps);
    let between = frames.iter().filter(|(_, t)| !trajectory.times.iter().any(|k| (k - t).abs() <= 1e-9 / scene.fps)).count();
    let frames_note = if between == 0 {
        "; every frame is an equilibrium (a key or an in-between)".to_string()
    } else {
        format!("; {between} of {} frames fall between in-betweens and are Hermite-interpolated (for an equilibrium at every frame, keys on frames and inbetweens = frames per interval - 1)", frames.len())
    };
    // W on the spacetime scale: the trajectory's keys (in-betweens included) as the keys of
    // the objective, so its samples cover every sub-interval.
    let elastic = Elastic::new(mesh, &super::elastic_material(scene))?;
    let constraints = KeyConstraints {
        times: trajectory.times.clone(),
        positions: trajectory.positions.clone(),
        fixed: vec![Vec::new(); trajectory.key_count()],
        fixed_velocity: vec![Vec::new(); trajectory.key_count()],
        cyclic: keys.cyclic,
    };
    let objective = solver::objective(&elastic, &constraints, &settings(scene));
    let w = objective.evaluate(&trajectory, &objective.local_step(&trajectory, false)).value;
    let (summary, iterations, blends) = (&done.summary, done.iterations, done.blends);
    let stop_reason = format!(
        "mass-spring: {} in-betweens per interval, each the equilibrium of the blended springs ({} springs, {}; {iterations} Newton iterations in all{}){frames_note}",
        spec.inbetweens,
        summary.springs,
        if done.fixed { "vertices held at every key follow the linear blend" } else { "default anchor" },
        if done.held_vertices > 0 { format!(", {} vertex holds on obstacles", done.held_vertices) } else { String::new() },
    );
    let unknowns = summary.surface_vertices + summary.interior_vertices;
    let mut log = SolverLog::closed_form(Method::MassSpring, vec![w], start.elapsed().as_secs_f64(), unknowns, stop_reason, keys.times.clone());
    log.iterations = iterations;
    log.precompute_seconds = done.network_seconds;
    log.iteration_seconds = if blends > 0 { (start.elapsed().as_secs_f64() - done.network_seconds) / blends as f64 } else { 0.0 };
    Ok((trajectory, log))
}

/// The solver's inputs for a body, as [`solve`] builds them: the elastic body, its key
/// constraints, and the settings of its scene (for benchmarks and tests that drive the
/// solver's parts one by one).
pub fn solver_inputs(body: &Body) -> Result<(Elastic, KeyConstraints, Settings)> {
    let tets = body.mesh.as_ref().ok_or_else(|| Error::general("the body has no tet mesh (method fit)", "tetrahedralize for spacetime"))?;
    let elastic = Elastic::new(tets, &super::elastic_material(&body.scene))?;
    Ok((elastic, key_constraints(&body.keys), settings(&body.scene)))
}

/// The solver settings of a scene (`[solver]`, the damping and gravity of `[material]`, the
/// obstacles checked at every frame of `fps`). `fixed_times` index the scene's keys; a contact
/// key's duplicate is inserted after it, so later keys shift by the contacts before them.
pub(crate) fn settings(scene: &Scene) -> Settings {
    let s = &scene.solver;
    // A cache scene has no contact keys.
    let contacts: &[usize] = scene.keyframes.as_ref().map_or(&[], |k| &k.contact);
    let body_key = |k: usize| k + contacts.iter().filter(|&&c| c < k).count();
    Settings {
        samples: s.samples,
        contact_samples: s.contact_samples,
        max_iterations: s.max_iterations,
        tolerance: s.tolerance,
        negligible: crate::algorithms::spacetime::settings::NEGLIGIBLE,
        regularization: s.regularization,
        damping: scene.material.damping,
        gravity: super::gravity(scene),
        budget: Budget::default(),
        model_hessian: match s.model_hessian.as_str() {
            "projective" => ModelHessian::Projective,
            "tangent" => ModelHessian::Tangent,
            _ => ModelHessian::Auto,
        },
        global_step: match s.global_step.as_str() {
            "direct" => Some(GlobalMethod::Direct),
            "modal" => Some(GlobalMethod::Modal),
            "iterative" => Some(GlobalMethod::Iterative),
            _ => None,
        },
        coarse_samples: s.coarse_samples,
        coarse_tolerance: crate::algorithms::spacetime::settings::DEFAULT_COARSE_TOLERANCE,
        step: match s.step.as_str() {
            "gauss-newton" => Step::GaussNewton,
            "quasi-newton" => Step::QuasiNewton,
            _ => Step::Auto,
        },
        timing: s.optimize_timing.then(|| TimingSettings {
            min_interval: s.min_interval,
            keep_duration: s.keep_duration,
            fixed_times: s.fixed_times.iter().map(|&k| body_key(k)).collect(),
            ..TimingSettings::default()
        }),
        contacts: (!scene.obstacles.is_empty()).then(|| Contacts {
            obstacles: scene
                .obstacles
                .iter()
                .map(|o| match *o {
                    ObstacleSpec::Plane { point, normal } => Obstacle::plane(point, normal),
                    ObstacleSpec::Sphere { center, radius } => Obstacle::Sphere { center, radius },
                })
                .collect(),
            frame_rate: scene.fps,
        }),
    }
}

/// The solver's view of the body's keyframes.
pub(crate) fn key_constraints(keys: &KeyPoses) -> KeyConstraints {
    KeyConstraints {
        times: keys.times.clone(),
        positions: keys.positions.clone(),
        fixed: keys.fixed.iter().map(|s| s.indices().to_vec()).collect(),
        fixed_velocity: keys.fixed_velocity.iter().map(|s| s.indices().to_vec()).collect(),
        cyclic: keys.cyclic,
    }
}
