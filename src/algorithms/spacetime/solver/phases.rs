//! One solve: its state (the iterate and the factorized matrices), the two phases of the
//! iteration (local/global, then quasi-Newton over the keys and the key times), the line
//! search on W, and the obstacles' active set.

use std::cell::RefCell;
use std::collections::BTreeSet;
use std::time::Instant;

use super::super::active_set::{Preconditioner, Projection, Row, RowKind};
use super::super::contact::{At, Check, Contacts};
use super::super::gauss_newton::{truncated_cg, CgEnd, Forcing, TruncatedCg};
use super::super::global_step::GlobalStep;
use super::super::objective::{Evaluation, Objective, Projections};
use super::super::quasi_newton::{dot, Lbfgs};
use super::super::settings::{ModelHessian, Settings, Step, GAUSS_NEWTON_CG, REFACTOR_CHANGE, WINDOW};
use super::super::tangent_step::TangentStep;
use super::super::timing::{safe_curvature, Blocks, ProjectionMode, Timing};
use super::super::trajectory::Trajectory;
use super::super::unknowns::{KeyConstraints, Unknowns};
use super::predict::prediction;
use super::{apply_step, initial_trajectory, objective, IterationSplit, Log, Solved};
use crate::algorithms::geometry::Point;
use crate::algorithms::physics::elastic::Elastic;
use crate::support::error::{Error, Result};

/// The local/global phase hands over to quasi-Newton when an iteration lowers W by less than
/// this fraction of W.
const PHASE1_SWITCH: f64 = 1e-2;
/// Largest relative change of an interval in one step.
const MAX_INTERVAL_CHANGE: f64 = 0.5;
/// Penetration allowed at a trial point, relative to the body's size (the linearized steps
/// keep the active checks to second order when the times move).
const CLEARANCE_TOLERANCE: f64 = 1e-6;

/// Halvings of a step that would increase W before it is given up.
const MAX_HALVINGS: usize = 8;

/// Directions blocked at once in a row (each adding a row to the active set) before a phase
/// gives up.
const MAX_HOLDS: usize = 50;

/// Rounds of [`Solver::make_feasible`]'s projection (each adds the checks still inside).
const MAX_FEASIBILITY_ROUNDS: usize = 50;

/// Curvature pairs kept by the quasi-Newton phase. More do not pay: 16 to 64 pairs reach the
/// 20-key body's stopping W no sooner, and cost 1.2 ms and 4.9 MB a pair there (README,
/// "Production-size surfaces").
const LBFGS_MEMORY: usize = 8;

/// How a phase of the iteration ended.
#[derive(Debug, Clone, PartialEq)]
enum PhaseEnd {
    /// W settled (the relative decrease in the stopping rule's measure).
    Settled(f64),
    /// No step along the phase's direction decreased W.
    Stalled,
    /// The iteration budget ran out.
    OutOfIterations,
}

/// The current iterate and the history of W.
struct Iterate {
    tr: Trajectory,
    eval: Evaluation,
    energy: Vec<f64>,
    halvings: usize,
    /// Checks held on their obstacle.
    active: BTreeSet<Check>,
    /// Interval variables held at their minimum length.
    at_minimum: Vec<bool>,
    /// Quasi-Newton iterations that moved the times.
    timing_iterations: usize,
    refactorizations: usize,
    /// The key times after each iteration (when they are optimized).
    times: Vec<Vec<f64>>,
    /// Gauss-Newton steps taken, their products with the Gauss-Newton Hessian, and the CG
    /// solves stopped by the iteration cap.
    gauss_newton: (usize, usize, usize),
}

/// Optimize keyframe positions and velocities (and key times). `on_iteration(k, W, floor)`
/// Where a solve may start: the coarse phase's result or an earlier bake's solution, the words
/// that say so in the stop reason, and the coarse phase's factorized matrices, the fine
/// quasi-Newton phase's preconditioner (any positive definite model serves there; the
/// curvature pairs learn the rest, and W's line search keeps every step a descent).
pub(super) struct Warm<'t> {
    pub(super) trajectory: &'t Trajectory,
    pub(super) label: String,
    pub(super) factors: Option<Factors>,
}

/// The factorized matrices of a solve: the global step and the tangent model Hessian.
pub(super) struct Factors {
    global: GlobalStep,
    tangent: Option<TangentStep>,
}

/// One solve at `settings.samples`, from the first guess, or from `warm` when W is lower there
/// (then straight to the quasi-Newton phase, on the warm start's matrices); whether it started
/// from `warm`, and the matrices, for a next solve to reuse.
pub(super) fn solve_from(
    elastic: &Elastic,
    keys: &KeyConstraints,
    settings: &Settings,
    warm: Option<Warm>,
    on_iteration: &dyn Fn(usize, f64, f64),
) -> Result<(Solved, bool, Factors)> {
    let start = Instant::now();
    let blocks = settings.timing.as_ref().map(|t| Blocks::new(&keys.times, t)).transpose()?;
    let objective = objective(elastic, keys, settings);
    // Only without obstacles (whose first guess is moved out of them first): W at the first
    // guess and at the warm start, on this solve's samples.
    let mut first = None;
    let mut reused = None;
    if let Some(warm) = warm.filter(|_| settings.contacts.is_none()) {
        let at = |tr: &Trajectory, k| finite(objective.evaluate(tr, &objective.local_step(tr, false)), k);
        let guess = initial_trajectory(keys);
        let (e0, e1) = (at(&guess, 0)?, at(warm.trajectory, 1)?);
        if e1.value < e0.value {
            first = Some((e0, Some((warm.trajectory.clone(), e1, warm.label))));
            reused = warm.factors;
        } else {
            first = Some((e0, None));
        }
    }
    let t_factors = Instant::now();
    let Factors { global, tangent } = match reused {
        Some(factors) => factors,
        None => factors(elastic, keys, settings, &objective)?,
    };
    let precompute_seconds = t_factors.elapsed().as_secs_f64();
    let timing = Timing::new(elastic, keys, settings);
    // The optimized interval lengths: every interval of positive length.
    let mut vars = vec![None; keys.times.len() - 1];
    let mut intervals = Vec::new();
    if blocks.is_some() {
        for (i, var) in vars.iter_mut().enumerate() {
            if keys.times[i + 1] > keys.times[i] {
                *var = Some(intervals.len());
                intervals.push(i);
            }
        }
    }
    let lower: Vec<f64> =
        intervals.iter().map(|&i| settings.timing.as_ref().map_or(0.0, |t| t.min_interval.min(keys.times[i + 1] - keys.times[i]))).collect();
    let size = crate::algorithms::geometry::bbox_diagonal(&elastic.rest);
    let mut solver = Solver {
        timing,
        global,
        tangent,
        settings,
        on_iteration,
        blocks,
        vars,
        intervals,
        lower,
        curvature: Vec::new(),
        factored_times: keys.times.clone(),
        clearance_tolerance: CLEARANCE_TOLERANCE * size,
        projections: RefCell::new(std::array::from_fn(|_| Projections { targets: Vec::new(), jacobians: None })),
        split: RefCell::default(),
    };

    let t_iterations = Instant::now();
    let mut tr = initial_trajectory(keys);
    let mut active = BTreeSet::new();
    if let Some(contacts) = &settings.contacts {
        solver.make_feasible(contacts, &mut tr, &mut active)?;
    }
    let (eval, warm) = match first {
        Some(first) => first,
        None => (solver.evaluate(&tr, 0, false)?, None),
    };
    on_iteration(0, eval.value, settings.negligible * eval.force_scale);
    let at_minimum = vec![false; solver.intervals.len()];
    let times = if solver.blocks.is_some() { vec![tr.times.clone()] } else { Vec::new() };
    let mut it = Iterate {
        tr,
        energy: vec![eval.value],
        eval,
        halvings: 0,
        active,
        at_minimum,
        timing_iterations: 0,
        refactorizations: 0,
        times,
        gauss_newton: (0, 0, 0),
    };
    let mut label = String::new();
    if let Some((tr, eval, words)) = warm {
        on_iteration(1, eval.value, settings.negligible * eval.force_scale);
        it.energy.push(eval.value);
        (it.tr, it.eval, label) = (tr, eval, words);
    }
    let warm = it.energy.len() - 1;
    let (converged, stop_reason) = solver.iterate(&mut it, &label)?;
    let iterations = it.energy.len() - 1;
    let iteration_time = t_iterations.elapsed().as_secs_f64();
    let force_scale = it.eval.force_scale;
    // The stopping rule's windows, after the warm start's step from the first guess.
    let (last_decrease, predicted_remaining) = prediction(&it.energy[warm..], settings.negligible * force_scale);
    let clearance = settings.contacts.as_ref().map(|c| c.clearance(&c.snapshot(&it.tr, &solver.timing.slots)));
    let log = Log {
        iterations,
        seconds: start.elapsed().as_secs_f64(),
        precompute_seconds,
        iteration_seconds: iteration_time / (iterations + 1) as f64,
        unknowns: solver.global.stats.unknowns,
        halvings: it.halvings,
        converged,
        stop_reason,
        linear_solver: solver.global.stats.linear_solver.to_string(),
        last_decrease,
        predicted_remaining,
        timing_iterations: it.timing_iterations,
        times: it.times,
        refactorizations: it.refactorizations,
        active_contacts: it.active.len(),
        clearance,
        conjugate_gradients: solver.global.cg_log(),
        force_scale,
        energy: it.energy,
        coarse_iterations: 0,
        coarse_samples: 0,
        split: solver.split.take(),
    };
    Ok((Solved { trajectory: it.tr, log }, warm == 1, Factors { global: solver.global, tangent: solver.tangent }))
}

/// The global step of `objective` and, when the settings ask for it, the tangent model Hessian.
fn factors(elastic: &Elastic, keys: &KeyConstraints, settings: &Settings, objective: &Objective) -> Result<Factors> {
    let unknowns = Unknowns::new(keys, elastic.node_count());
    let global = GlobalStep::build(objective, unknowns, settings.regularization, &settings.budget, settings.global_step)?;
    let global_unknowns = global.unknowns();
    // The active-set projection solves with the preconditioner per coordinate: with obstacles
    // the quasi-Newton phase keeps the global step's matrix.
    let tangent = match settings.model_hessian.resolve(elastic, keys) {
        _ if global_unknowns.count() == 0 || settings.contacts.is_some() => None,
        // Chosen: its errors are the solve's.
        ModelHessian::Tangent if settings.model_hessian == ModelHessian::Tangent => Some(TangentStep::new(objective, global_unknowns)?),
        // Guessed: without the proximal term a free drift can cost nothing, and then the
        // global step's matrix (which has it) is kept.
        ModelHessian::Tangent => TangentStep::new(objective, global_unknowns).ok(),
        _ => None,
    };
    Ok(Factors { global, tangent })
}

/// `eval`, or an error naming the iteration when W is not finite.
fn finite(eval: Evaluation, iteration: usize) -> Result<Evaluation> {
    if !eval.value.is_finite() {
        return Err(Error::general(
            format!("the spacetime energy W became {} at iteration {iteration}", eval.value),
            "check the keyframes for flat or inverted tets, and lower [solver] regularization (h) to damp the steps",
        ));
    }
    Ok(eval)
}

/// The objective, the factorized global step and the constraints of one solve.
struct Solver<'a> {
    timing: Timing<'a>,
    global: GlobalStep,
    /// The tangent model Hessian, when the quasi-Newton phase uses it.
    tangent: Option<TangentStep>,
    settings: &'a Settings,
    on_iteration: &'a dyn Fn(usize, f64, f64),
    /// The fixed-sum blocks of intervals, when the times are optimized.
    blocks: Option<Blocks>,
    /// `vars[i]`: the variable of interval `i`, if its length is optimized.
    vars: Vec<Option<usize>>,
    /// The interval of each variable.
    intervals: Vec<usize>,
    /// The smallest length of each variable.
    lower: Vec<f64>,
    /// `D_T`: the inverse held-keys curvature of each variable.
    curvature: Vec<f64>,
    /// The key times the global step was last factorized at.
    factored_times: Vec<f64>,
    /// Penetration allowed at a trial point (absolute).
    clearance_tolerance: f64,
    /// The local step's buffers, kept between evaluations (`[0]` without the Jacobians, `[1]`
    /// with them): every trial point fills them again instead of allocating them.
    projections: RefCell<[Projections; 2]>,
    /// The evaluations' and solves' count and time ([`Log::split`]).
    split: RefCell<IterationSplit>,
}

/// A step of both kinds of variables: the keyframe unknowns (flat, three per unknown) and the
/// interval variables.
fn split(z: &[f64], unknowns: usize) -> (&[f64], &[f64]) {
    z.split_at(3 * unknowns)
}

impl<'a> Solver<'a> {
    fn objective(&self, times: &[f64]) -> Objective<'a> {
        let mut o = self.timing.objective(times);
        o.time_gradient = self.blocks.is_some();
        o
    }

    /// The stopping rule's floor `negligible × S` at the current iterate.
    fn floor(&self, it: &Iterate) -> f64 {
        self.settings.negligible * it.eval.force_scale
    }

    fn unknown_count(&self) -> usize {
        self.global.unknowns().count()
    }

    /// W at `tr` with fresh projections (and the exact gradients when `exact`); a non-finite W
    /// is an error naming the iteration.
    fn evaluate(&self, tr: &Trajectory, iteration: usize, exact: bool) -> Result<Evaluation> {
        let start = Instant::now();
        let objective = self.objective(&tr.times);
        let eval = objective.evaluate_fresh(tr, exact, &mut self.projections.borrow_mut()[exact as usize]);
        let mut split = self.split.borrow_mut();
        split.evaluations += 1;
        split.exact_evaluations += usize::from(exact);
        split.evaluation_seconds += start.elapsed().as_secs_f64();
        finite(eval, iteration)
    }

    /// `x ← A⁻¹ x` with the global step's matrix, timed ([`Log::split`]).
    fn global_solve(&self, x: &mut [Point]) {
        self.timed_solve(|| self.global.apply_inverse(x));
    }

    /// Run one solve and count it and its wall time in [`Log::split`].
    fn timed_solve(&self, solve: impl FnOnce()) {
        let start = Instant::now();
        solve();
        let mut split = self.split.borrow_mut();
        split.solves += 1;
        split.solve_seconds += start.elapsed().as_secs_f64();
    }

    /// The joint gradient of an exact evaluation: the free unknowns' (flat), then the interval
    /// variables'.
    fn joint_gradient(&self, eval: &Evaluation, times: bool) -> Vec<f64> {
        let g = self.global.gather(eval.exact_gradient.as_ref().expect("exact phase"));
        let mut z: Vec<f64> = g.as_flattened().to_vec();
        if let Some(t) = eval.time_gradient.as_ref().filter(|_| times) {
            z.extend(self.intervals.iter().map(|&i| t[i]));
        }
        z
    }

    /// Whether another iteration fits in `max_iterations`; an error once `--max-time` is spent.
    fn budget_left(&self, it: &Iterate) -> Result<bool> {
        self.settings
            .budget
            .check_time("solve", || format!("after {} iterations (W {:.4e})", it.energy.len() - 1, it.energy.last().copied().unwrap_or(f64::NAN)))?;
        Ok(it.energy.len() <= self.settings.max_iterations)
    }

    /// The rows held in a step: the fixed sums of interval blocks, the intervals at their
    /// minimum, and the active contacts (linearized at the current iterate; with `times`, the
    /// contacts' dependence on the interval lengths too).
    fn rows(&self, it: &Iterate, times: bool) -> Vec<Row> {
        let mut rows = Vec::new();
        if times {
            if let Some(blocks) = &self.blocks {
                for (block, fixed_sum) in &blocks.blocks {
                    if *fixed_sum && !block.is_empty() {
                        let t = block.iter().filter_map(|&i| self.vars[i]).map(|j| (j, 1.0)).collect();
                        rows.push(Row { kind: RowKind::Sum, u: Vec::new(), normal: [0.0; 3], t });
                    }
                }
            }
            for (j, _) in it.at_minimum.iter().enumerate().filter(|(_, &b)| b) {
                rows.push(Row { kind: RowKind::Bound(j), u: Vec::new(), normal: [0.0; 3], t: vec![(j, 1.0)] });
            }
        }
        if let Some(contacts) = &self.settings.contacts {
            let no_times = vec![None; self.vars.len()];
            let vars = if times { &self.vars } else { &no_times };
            for (index, &check) in it.active.iter().enumerate() {
                if let Some((row, _)) = contacts.row(check, &it.tr, self.global.unknowns(), vars, RowKind::Contact(index)) {
                    rows.push(row);
                }
            }
        }
        rows
    }

    /// The quasi-Newton phase's initial inverse Hessian on the keyframe unknowns.
    fn model_inverse(&self, x: &mut [Point]) {
        match &self.tangent {
            Some(t) => self.timed_solve(|| t.apply_inverse(x)),
            None => self.global_solve(x),
        }
    }

    /// The step preconditioner restricted to the rows of `it` (with the times when `times`):
    /// the global step's, or the quasi-Newton model's when `model`.
    fn projection(&self, it: &Iterate, times: bool, model: bool) -> Projection {
        let solve = |x: &mut [Point]| if model { self.model_inverse(x) } else { self.global_solve(x) };
        let d_t: &[f64] = if times { &self.curvature } else { &[] };
        Projection::new(self.rows(it, times), &Preconditioner { unknowns: self.unknown_count(), solve: &solve, times: d_t })
    }

    fn preconditioner<'s>(&'s self, solve: &'s dyn Fn(&mut [Point]), times: bool) -> Preconditioner<'s> {
        Preconditioner { unknowns: self.unknown_count(), solve, times: if times { &self.curvature } else { &[] } }
    }

    /// Release the inequality rows whose multiplier (for the gradient `g`) is negative: the
    /// objective pulls away from them. Returns whether any was released. Checks in `keep`
    /// (just blocked) stay one more iteration.
    fn release(&self, it: &mut Iterate, projection: &Projection, lambda: &[f64], keep: Option<Check>) -> bool {
        let checks: Vec<Check> = it.active.iter().copied().collect();
        let mut released = false;
        let scale = lambda.iter().fold(0.0f64, |m, l| m.max(l.abs()));
        for (row, &l) in projection.rows.iter().zip(lambda) {
            if !(row.kind.is_inequality() && l < -1e-12 * scale) {
                continue;
            }
            match row.kind {
                RowKind::Contact(index) if Some(checks[index]) != keep => {
                    it.active.remove(&checks[index]);
                    released = true;
                }
                RowKind::Bound(j) => {
                    it.at_minimum[j] = false;
                    released = true;
                }
                _ => {}
            }
        }
        released
    }

    /// Move the initial guess out of the obstacles. First every key pose: a node whose
    /// position is free and inside an obstacle is put on the nearest point of its surface
    /// (a keyframe sculpted into the floor becomes a contact pose); a held one is an error
    /// naming the key's time and how deep the deepest held node is. Then the in-betweens:
    /// the smallest step (in the global step's metric) that puts every penetrating node on
    /// the surface, the projected nodes kept there, repeated while the step pushes others in.
    fn make_feasible(&self, contacts: &Contacts, tr: &mut Trajectory, active: &mut BTreeSet<Check>) -> Result<()> {
        let unknowns = self.global.unknowns();
        let slots = &self.timing.slots;
        let tolerance = 0.5 * self.clearance_tolerance;
        // (depth, node, obstacle) of the deepest held node, and how many are held inside, per key.
        let mut held: Vec<(usize, f64, usize, usize, usize)> = Vec::new();
        for k in 0..tr.key_count() {
            let s = slots.position(k);
            if slots.keys_of(s).next() != Some(k) {
                continue;
            }
            let mut deepest: Option<(f64, usize, usize)> = None;
            let mut count = 0;
            for node in 0..tr.positions[k].len() {
                for (o, obstacle) in contacts.obstacles.iter().enumerate() {
                    let x = tr.positions[k][node];
                    let d = obstacle.distance(x);
                    if d >= -tolerance {
                        continue;
                    }
                    if unknowns.get(node, s).is_some() {
                        let p = obstacle.project(x);
                        for key in slots.keys_of(s) {
                            tr.positions[key][node] = p;
                        }
                        active.insert(Check { at: At::Key(k), node: node as u32, obstacle: o as u16 });
                    } else {
                        count += 1;
                        if deepest.is_none_or(|(depth, _, _)| -d > depth) {
                            deepest = Some((-d, node, o));
                        }
                    }
                }
            }
            if let Some((depth, node, o)) = deepest {
                held.push((k, depth, node, o, count));
            }
        }
        if let Some(&(k, depth, node, o, count)) = held.first() {
            let others = if held.len() > 1 {
                format!(" (and the keys at {} s)", held[1..].iter().map(|h| format!("{:.4}", tr.times[h.0])).collect::<Vec<_>>().join(", "))
            } else {
                String::new()
            };
            return Err(Error::general(
                format!(
                    "the keyframe at t = {:.4} s holds {count} node(s) inside obstacle {} (a {}), node {node} deepest, by {depth:.4e}{others}; held positions cannot be moved out",
                    tr.times[k],
                    o + 1,
                    match contacts.obstacles[o] {
                        super::super::obstacles::Obstacle::Plane { .. } => "plane",
                        super::super::obstacles::Obstacle::Sphere { .. } => "sphere",
                    },
                ),
                "move that keyframe's mesh out of the obstacle, or free its vertices at that key (`fixed`) so the solver puts them on the surface",
            ));
        }
        let no_times = vec![None; self.vars.len()];
        for _ in 0..MAX_FEASIBILITY_ROUNDS {
            let snap = contacts.snapshot(tr, slots);
            let inside: Vec<(Check, f64)> = contacts.each(&snap).filter(|(_, _, d)| *d < -tolerance).map(|(c, _, d)| (c, d)).collect();
            if inside.is_empty() {
                return Ok(());
            }
            for &(check, d) in &inside {
                if contacts.row(check, tr, unknowns, &no_times, RowKind::Sum).is_none() {
                    let t = snap.instants.iter().find(|i| i.0 == check.at).map_or(f64::NAN, |i| i.1);
                    return Err(Error::general(
                        format!("node {} is inside obstacle {} by {:.4e} at t = {t:.4} s between the keys, and nothing there may move (the positions and velocities around it are held)", check.node, check.obstacle + 1, -d),
                        "move the keyframes around that time out of the obstacle, or free their vertices or velocities (`fixed`, `fixed_velocity`)",
                    ));
                }
                active.insert(check);
            }
            let mut rows = Vec::new();
            let mut targets = Vec::new();
            for (index, &check) in active.iter().enumerate() {
                if let Some((row, d)) = contacts.row(check, tr, unknowns, &no_times, RowKind::Contact(index)) {
                    rows.push(row);
                    targets.push(-d.min(0.0));
                } else {
                    targets.push(0.0);
                }
            }
            let solve = |x: &mut [Point]| self.global_solve(x);
            let h0 = self.preconditioner(&solve, false);
            let projection = Projection::new(rows, &h0);
            let kept: Vec<f64> = projection
                .rows
                .iter()
                .map(|r| match r.kind {
                    RowKind::Contact(index) => targets[index],
                    _ => 0.0,
                })
                .collect();
            let step = projection.correction(&kept, 3 * self.unknown_count());
            let (u, _) = split(&step, self.unknown_count());
            let points: Vec<Point> = u.as_chunks::<3>().0.to_vec();
            apply_step(tr, slots, &self.global.scatter(&points), 1.0);
        }
        Err(Error::general(
            "the first guess cannot be moved out of the obstacles: every correction pushes other nodes in",
            "check that the obstacles leave room for the body at every key and between them",
        ))
    }

    /// Both phases, or none when there is nothing to optimize: whether the solve converged,
    /// and why it stopped. After a warm start (`it` past the first guess; `label` says where it
    /// came from) the local/global phase is left out: its fixed point is not W's minimum, and
    /// the warm start is near the latter.
    fn iterate(&mut self, it: &mut Iterate, label: &str) -> Result<(bool, String)> {
        if self.unknown_count() == 0 && self.intervals.is_empty() {
            return Ok((true, "nothing to optimize: every keyframe position and velocity is fixed".to_string()));
        }
        if it.energy[0] == 0.0 {
            return Ok((true, "W is zero: the keyframes are already physically exact".to_string()));
        }
        let warm = it.energy.len() - 1;
        let phase1 = if self.unknown_count() > 0 && warm == 0 { self.local_global(it)? } else { PhaseEnd::Stalled };
        let local_global_iterations = it.energy.len() - 1 - warm;
        let mut phase2 = if phase1 == PhaseEnd::OutOfIterations { PhaseEnd::OutOfIterations } else { self.quasi_newton(it, false)? };
        if self.blocks.is_some() && phase2 != PhaseEnd::OutOfIterations {
            // The keys first settle at the given times, then keys and times move together: only
            // at settled keys is the held-keys time gradient the gradient of the reduced W (the
            // W of the best keys for those times, part 1's measurement); far from them it
            // mostly measures how bad the first guess is.
            phase2 = self.quasi_newton(it, true)?;
        }
        let mut phases = format!(
            "{label}{local_global_iterations} local/global + {} quasi-Newton iterations",
            it.energy.len() - 1 - warm - local_global_iterations
        );
        if self.tangent.is_some() {
            phases += ", preconditioned by the tangent model Hessian";
        }
        if it.gauss_newton.0 > 0 {
            phases += &format!(
                ", {} of them Gauss-Newton steps ({} CG products, {} solves capped at {GAUSS_NEWTON_CG})",
                it.gauss_newton.0, it.gauss_newton.1, it.gauss_newton.2
            );
        }
        if self.blocks.is_some() {
            phases += &format!(", {} moving the key times, {} refactorizations", it.timing_iterations, it.refactorizations);
        }
        let tolerance = self.settings.tolerance;
        Ok(match phase2 {
            PhaseEnd::Settled(change) => {
                let (w, scale) = (*it.energy.last().expect("W"), it.eval.force_scale);
                let of = if self.settings.negligible > 0.0 && scale > 0.0 {
                    format!("of W + {:e} S (W = {:.2e} S, S the force scale)", self.settings.negligible, w / scale)
                } else {
                    "of itself".to_string()
                };
                (true, format!("W decreased by {change:.3e} {of} over the last {WINDOW} iterations, below the tolerance {tolerance} ({phases})"))
            }
            PhaseEnd::Stalled => (true, format!("W is stationary: no step along its quasi-Newton direction decreases it ({phases})")),
            PhaseEnd::OutOfIterations => {
                (false, format!("stopped after max_iterations = {} before W settled ({phases})", self.settings.max_iterations))
            }
        })
    }

    /// Phase 1: the paper's local/global step (with the active contacts held), while it
    /// decreases W by at least [`PHASE1_SWITCH`] of W per iteration.
    fn local_global(&self, it: &mut Iterate) -> Result<PhaseEnd> {
        let (mut blocked, mut holds) = (None, 0);
        loop {
            if !self.budget_left(it)? {
                return Ok(PhaseEnd::OutOfIterations);
            }
            let mut d: Vec<f64> = self.global.gather(&it.eval.gradient).as_flattened().to_vec();
            let mut projection = self.projection(it, false, false);
            let solve = |x: &mut [Point]| self.global_solve(x);
            let h0 = self.preconditioner(&solve, false);
            let g = d.clone();
            let lambda = projection.apply(&mut d, &h0);
            if self.release(it, &projection, &lambda, blocked) {
                projection = self.projection(it, false, false);
                d.clone_from(&g);
                projection.apply(&mut d, &h0);
            }
            d.iter_mut().for_each(|x| *x = -*x);
            let w = *it.energy.last().expect("initial W");
            let step = match self.line_search(it, &d, false, 1.0)? {
                Outcome::Taken(step) => step,
                Outcome::Held(stop) => {
                    blocked = held_check(stop);
                    holds += 1;
                    if holds > MAX_HOLDS {
                        return Ok(PhaseEnd::Stalled);
                    }
                    continue;
                }
                Outcome::Failed => return Ok(PhaseEnd::Stalled),
            };
            holds = 0;
            blocked = step.blocked;
            let w_new = *it.energy.last().expect("accepted");
            let reference = w_new + self.floor(it);
            if (w - w_new) < PHASE1_SWITCH * reference {
                return Ok(PhaseEnd::Settled((w - w_new) / reference));
            }
        }
    }

    /// Phase 2: L-BFGS on the exact W (and the key times), preconditioned by the global
    /// step's matrix and the held-keys time curvature, restricted to the active rows.
    fn quasi_newton(&mut self, it: &mut Iterate, times: bool) -> Result<PhaseEnd> {
        it.eval = self.evaluate(&it.tr, it.energy.len(), true)?;
        if times {
            self.update_curvature(&it.tr, &it.eval);
        }
        let since = it.energy.len() - 1;
        // H₀'s scale is learned from the steps (`quasi_newton`), except with obstacles: their
        // active set re-projects H₀ and clears the pairs, and a scale learned under one set
        // misleads the next (measured: SPOT 502 iterations scaled, 383 as given;
        // `formats/scene.md`, "The scale of H₀").
        let mut lbfgs = Lbfgs::new(LBFGS_MEMORY, self.settings.contacts.is_none());
        let mut g = self.joint_gradient(&it.eval, times);
        let (mut blocked, mut holds) = (None, 0);
        let gauss_newton = !times && self.settings.step.resolve(self.settings) == Step::GaussNewton;
        let mut forcing = Forcing::default();
        loop {
            let k = it.energy.len() - 1;
            if k >= since + WINDOW {
                let w = it.energy[k];
                let change = (it.energy[k - WINDOW] - w) / (w + self.floor(it));
                if change <= self.settings.tolerance {
                    return Ok(PhaseEnd::Settled(change));
                }
            }
            if !self.budget_left(it)? {
                return Ok(PhaseEnd::OutOfIterations);
            }
            let solve = |x: &mut [Point]| self.model_inverse(x);
            let h0 = self.preconditioner(&solve, times);
            let mut projection = self.projection(it, times, true);
            if projection.rows.iter().any(|r| r.kind.is_inequality()) {
                let mut pg = g.clone();
                let lambda = projection.apply(&mut pg, &h0);
                if self.release(it, &projection, &lambda, blocked) {
                    projection = self.projection(it, times, true);
                }
            }
            let precondition = |q: &mut [f64]| {
                projection.apply(q, &h0);
            };
            let mut gauss_newton_step = None;
            if gauss_newton {
                // CG is preconditioned by the L-BFGS inverse Hessian (the curvature pairs of the
                // last steps on top of the model's): the model alone is too stiff along the slow
                // motions, and CG then ran into its cap on 52 of TWIST's 54 steps (measured;
                // the solver's module documentation).
                let lbfgs_precondition = |q: &mut [f64]| {
                    let d = lbfgs.direction(q, precondition);
                    q.iter_mut().zip(&d).for_each(|(a, b)| *a = -b);
                };
                let cg = self.gauss_newton_direction(it, &g, &lbfgs_precondition, forcing.next(dot(&g, &g).sqrt()));
                it.gauss_newton.1 += cg.products;
                it.gauss_newton.2 += usize::from(cg.end == CgEnd::Capped);
                if dot(&g, &cg.direction) < 0.0 {
                    if let Outcome::Taken(step) = self.line_search(it, &cg.direction, true, 1.0)? {
                        it.gauss_newton.0 += 1;
                        gauss_newton_step = Some((cg.direction, step));
                    }
                }
            }
            let (d, outcome) = match gauss_newton_step {
                Some((d, step)) => (d, Outcome::Taken(step)),
                None => {
                    let mut d = lbfgs.direction(&g, precondition);
                    // Not a descent direction (or NaN): start over from the preconditioned gradient.
                    if dot(&g, &d).partial_cmp(&0.0) != Some(std::cmp::Ordering::Less) {
                        lbfgs.clear();
                        d = lbfgs.direction(&g, precondition);
                    }
                    let mut outcome = self.line_search(it, &d, true, 1.0)?;
                    if matches!(outcome, Outcome::Failed) && !lbfgs.is_empty() {
                        // Restart from the preconditioned gradient.
                        lbfgs.clear();
                        d = lbfgs.direction(&g, precondition);
                        outcome = self.line_search(it, &d, true, 1.0)?;
                    }
                    (d, outcome)
                }
            };
            let step = match outcome {
                Outcome::Taken(step) => step,
                Outcome::Held(stop) => {
                    blocked = held_check(stop);
                    lbfgs.clear();
                    holds += 1;
                    if holds > MAX_HOLDS {
                        return Ok(PhaseEnd::Stalled);
                    }
                    continue;
                }
                Outcome::Failed => return Ok(PhaseEnd::Stalled),
            };
            holds = 0;
            blocked = step.blocked;
            if step.added {
                // The new row shrinks the subspace the curvature pairs live in.
                lbfgs.clear();
            }
            let g_new = self.joint_gradient(&it.eval, times);
            let s: Vec<f64> = d.iter().map(|v| v * step.scale).collect();
            let y: Vec<f64> = g_new.iter().zip(&g).map(|(a, b)| a - b).collect();
            if gauss_newton {
                // A Gauss-Newton step's length says nothing of H₀'s scale.
                lbfgs.push_pair(s, y);
            } else {
                lbfgs.push(s, y, step.scale, &g);
            }
            g = g_new;
            if times && step.moved_times {
                it.timing_iterations += 1;
                let moved = it.tr.times.windows(2).zip(self.factored_times.windows(2)).any(|(a, b)| {
                    let (now, then) = (a[1] - a[0], b[1] - b[0]);
                    then > 0.0 && ((now - then) / then).abs() > REFACTOR_CHANGE
                });
                if moved {
                    let objective = self.objective(&it.tr.times);
                    self.global.retime(&objective, self.settings.regularization)?;
                    if let Some(tangent) = self.tangent.as_mut() {
                        tangent.retime(&objective, self.global.unknowns())?;
                    }
                    self.factored_times.clone_from(&it.tr.times);
                    self.update_curvature(&it.tr, &it.eval);
                    it.refactorizations += 1;
                }
            }
        }
    }

    /// The truncated Gauss-Newton step at the current iterate (the keyframe unknowns only):
    /// `H d = -g` by CG preconditioned with `precondition`, to the relative residual `forcing`,
    /// with the projection Jacobians of the iterate's exact evaluation (the kept buffer: the
    /// last exact evaluation is the accepted iterate's).
    fn gauss_newton_direction(&self, it: &Iterate, g: &[f64], precondition: &dyn Fn(&mut [f64]), forcing: f64) -> TruncatedCg {
        let objective = self.objective(&it.tr.times);
        let buffers = self.projections.borrow();
        let projections = &buffers[1];
        let product = |v: &[f64]| -> Vec<f64> {
            let points: Vec<Point> = v.as_chunks::<3>().0.to_vec();
            let hv = objective.gauss_newton_product(projections, &self.global.scatter(&points));
            self.global.gather(&hv).as_flattened().to_vec()
        };
        truncated_cg(product, precondition, g, forcing, GAUSS_NEWTON_CG)
    }

    /// `D_T` from the held-keys curvature of W at `tr` (made positive where it is not).
    fn update_curvature(&mut self, tr: &Trajectory, eval: &Evaluation) {
        let d = self.timing.derivatives(tr, ProjectionMode::Fresh);
        let gradient = eval.time_gradient.as_ref().expect("time gradient");
        let lengths: Vec<f64> = tr.times.windows(2).map(|w| w[1] - w[0]).collect();
        let h = safe_curvature(gradient, &d.curvature, &lengths);
        self.curvature = self.intervals.iter().map(|&i| 1.0 / h[i]).collect();
    }

    /// Take the step `d` (flat unknowns, then interval variables when `times`) from the
    /// current iterate, halving until W decreases and every check stays outside; the accepted
    /// step, if any. The first trial is `limit`, or less where an interval would change by more
    /// than half or pass its minimum, or a check would enter an obstacle: the interval or check
    /// that stops it joins the active set if the step is taken whole.
    fn line_search(&self, it: &mut Iterate, d: &[f64], exact: bool, limit: f64) -> Result<Outcome> {
        let nu = self.unknown_count();
        let (du, dt_vars) = split(d, nu);
        let du_points: Vec<Point> = du.as_chunks::<3>().0.to_vec();
        let du_slots = self.global.scatter(&du_points);
        let mut dt = vec![0.0; it.tr.times.len() - 1];
        for (j, &i) in self.intervals.iter().enumerate().take(dt_vars.len()) {
            dt[i] = dt_vars[j];
        }
        let moves_times = dt.iter().any(|&x| x != 0.0);
        // Caps: interval changes and minimum lengths.
        let mut scale = limit;
        let mut stop: Option<Stop> = None;
        for (j, &i) in self.intervals.iter().enumerate().take(dt_vars.len()) {
            let (len, step) = (it.tr.times[i + 1] - it.tr.times[i], dt_vars[j]);
            if step == 0.0 {
                continue;
            }
            scale = scale.min(MAX_INTERVAL_CHANGE * len / step.abs());
            if step < 0.0 {
                let to_bound = (len - self.lower[j]).max(0.0) / -step;
                if to_bound < scale {
                    scale = to_bound;
                    stop = Some(Stop::Bound(j));
                }
            }
        }
        // Contacts: the first check the step would push in.
        let contacts = self.settings.contacts.as_ref();
        if let Some(contacts) = contacts {
            let snap = contacts.snapshot(&it.tr, &self.timing.slots);
            let mut direction = Trajectory {
                times: it.tr.times.clone(),
                positions: vec![vec![[0.0; 3]; it.tr.vertex_count()]; it.tr.key_count()],
                velocities: vec![vec![[0.0; 3]; it.tr.vertex_count()]; it.tr.key_count()],
            };
            apply_step(&mut direction, &self.timing.slots, &du_slots, 1.0);
            let motion = contacts.motion(&snap, &it.tr, &direction, &dt);
            let active = |c: Check| it.active.contains(&c);
            if let Some((alpha, check)) = contacts.blocking(&snap, &motion, &active, scale) {
                scale = alpha;
                stop = Some(Stop::Contact(check));
            }
        }
        if scale <= 0.0 {
            // Blocked at once: hold what blocks, and let the next direction go around it.
            return Ok(if self.hold(it, stop) { Outcome::Held(stop) } else { Outcome::Failed });
        }
        let w = *it.energy.last().expect("initial value");
        let first = scale;
        for halving in 0..=MAX_HALVINGS {
            let mut trial = it.tr.clone();
            apply_step(&mut trial, &self.timing.slots, &du_slots, scale);
            if moves_times {
                let blocks = self.blocks.as_ref().expect("times are optimized");
                trial.times = blocks.times(&it.tr.times, &dt, scale);
            }
            if let Some(contacts) = contacts {
                let clearance = contacts.clearance(&contacts.snapshot(&trial, &self.timing.slots));
                if clearance < -self.clearance_tolerance {
                    scale *= 0.5;
                    continue;
                }
            }
            let trial_eval = self.evaluate(&trial, it.energy.len(), exact)?;
            // Strictly lower: a step that changes nothing is no progress (W is stationary).
            if trial_eval.value < w {
                it.halvings += halving;
                it.tr = trial;
                it.eval = trial_eval;
                (self.on_iteration)(it.energy.len(), it.eval.value, self.settings.negligible * it.eval.force_scale);
                it.energy.push(it.eval.value);
                if self.blocks.is_some() {
                    it.times.push(it.tr.times.clone());
                }
                let whole = scale == first;
                let blocked = if whole { stop } else { None };
                let added = whole && self.hold(it, blocked);
                let check = match blocked {
                    Some(Stop::Contact(c)) => Some(c),
                    _ => None,
                };
                return Ok(Outcome::Taken(Accepted { scale, blocked: check, added, moved_times: moves_times }));
            }
            scale *= 0.5;
        }
        it.halvings += MAX_HALVINGS;
        Ok(Outcome::Failed)
    }

    /// Add what stopped a step to the active set; whether anything was added.
    fn hold(&self, it: &mut Iterate, stop: Option<Stop>) -> bool {
        match stop {
            Some(Stop::Bound(j)) => !std::mem::replace(&mut it.at_minimum[j], true),
            Some(Stop::Contact(c)) => it.active.insert(c),
            None => false,
        }
    }
}

/// The check in a stop, if it is one.
fn held_check(stop: Option<Stop>) -> Option<Check> {
    match stop {
        Some(Stop::Contact(c)) => Some(c),
        _ => None,
    }
}

/// What stopped a step short of its full length.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Stop {
    Bound(usize),
    Contact(Check),
}

/// What a line search did.
enum Outcome {
    /// A step was taken.
    Taken(Accepted),
    /// No step: what blocks the direction at once joined the active set.
    Held(Option<Stop>),
    /// No step decreases W.
    Failed,
}

/// An accepted step.
struct Accepted {
    /// The fraction of the direction taken.
    scale: f64,
    /// The check that stopped it, now held.
    blocked: Option<Check>,
    /// Whether a row joined the active set.
    added: bool,
    /// Whether the step moved the key times.
    moved_times: bool,
}
