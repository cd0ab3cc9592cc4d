//! Keyframe timing: W as a function of the interval lengths `T_i`, its exact first and second
//! derivatives, and the timing step that moves the keys in time.
//!
//! # Derivatives
//!
//! Keyframe positions and (true) velocities are held while `T_i` changes. Sample `k` of
//! interval `i` sits at the fixed local parameter `θ_k`, so the sample moves with the interval,
//! and its weight is `dτ = T_i / K`. Every Hermite weight is `c T^p` with a fixed power
//! (`p = 0, 1` for positions, `-1, 0` for velocities, `-2, -1` for accelerations; see
//! [`hermite_weights`](super::trajectory::hermite_weights)), so `∂/∂T` multiplies it by `p / T`
//! and `∂²/∂T²` by `p (p - 1) / T²`. In particular `x` is affine in `T` (`x_TT = 0`).
//! With `f = M (ẍ + α ẋ - g) + L x - J p`, per sample:
//!
//! ```text
//! W_s      = dτ ½ |f|²
//! ∂W_s/∂T  = (1/K) ½ |f|² + dτ f_T·f
//! ∂²W_s/∂T² = (2/K) f_T·f + dτ (|f_T|² + f_TT·f)          (all in the M⁻¹ norm)
//! f_T  = M (ẍ_T + α ẋ_T) + L x_T - J p_T
//! f_TT = M (ẍ_TT + α ẋ_TT)       - J p_TT
//! ```
//!
//! W is time-translation invariant (gravity is constant), and a sample depends on its own
//! interval only: `∂W/∂T_i` sums the samples of interval `i`, and **the Hessian in T is exactly
//! diagonal**. A zero-length (contact) interval has no samples and no derivative.
//!
//! Two versions, selected by [`ProjectionMode`]:
//! - **frozen**: the projections `p_s` held (`p_T = p_TT = 0`), the derivative of the global
//!   step's quadratic model (the paper's eq. 19 with the stiffness taken as `L`, as the
//!   reference code does);
//! - **fresh**: `p_s = P(x(t_s))` re-projected, so `p_T = DP[dF(x_T)]` and, as `F` is affine in
//!   `T` too, `p_TT = D²P[dF(x_T), dF(x_T)]`
//!   ([`project_along_forces`](crate::algorithms::physics::projection_curvature::project_along_forces)). This is the total derivative
//!   of W itself, the quantity the solver measures and the line search compares.
//!
//! There is no envelope argument that makes the two first derivatives agree: the projections
//! minimize the elastic energy `E(x, p)`, not W, and W is the squared norm of `∇E = L x - J p`,
//! whose derivative is the stiffness `L - J DP dF`, not `L`. The tests measure the difference
//! (15 to 40% of dW/dT on the test body) and check both against finite differences of the
//! function each one differentiates. (The envelope argument does hold one level up: at keys
//! that minimize W, `∂W/∂T` is the derivative of `W*(T) = min over keys of W`, tested too.)
//!
//! # The timing step
//!
//! [`Timing::optimize_times`]: Newton on the vector of `T` with the exact diagonal Hessian of
//! the fresh W (the function the line search measures), each entry replaced by a safe
//! gradient-step curvature where it is not positive; the step is the minimizer of that
//! separable quadratic model under the constraints; Armijo backtracking on W with fresh local
//! steps, so W never increases. The first trial is the full step, or less where an interval
//! would more than double or lose more than half its length (W grows like `T⁻³` as an
//! interval shrinks with its keys held, far faster than the model says).
//!
//! Constraints. A key's time is a prefix sum, `t_k = t_0 + Σ_{i<k} T_i`, and `t_0` never moves
//! (only lengths matter). So fixing key `k`'s time fixes `Σ_{i<k} T_i`; fixing keys `a < b`
//! fixes `Σ_{a<=i<b} T_i`: the intervals between two consecutive fixed keys form a block that
//! can only trade time internally. (Fixing one key does *not* fix the sum of its two adjacent
//! intervals unless both neighbours are fixed too: the time can flow from any interval on the
//! same side.) `keep_duration` fixes the last key. Intervals after the last fixed key are free.
//! Per block with a fixed sum, the constrained Newton step is `ΔT_i = max(lo_i, (μ - g_i)/H_i)`
//! with the one multiplier `μ` for which `Σ ΔT_i = 0` (found exactly on the sorted breakpoints);
//! `lo_i` keeps `T_i >=` the minimum. Zero-length intervals are outside every block and stay 0.
//! New key times are written block by block from the block's first key, and fixed keys keep
//! their time bit for bit.
//!
//! The step holds the keys, so its curvature is that of W with positions and velocities held.
//! Re-solving the keys at the new times absorbs part of a timing change, so `W*(T)` is flatter
//! (measured on a free fall with every position held: 199 against 3219), and alternating
//! solves and timing steps converges linearly there (3% of the timing error per round). A
//! secant update of the curvature across rounds (the gradients are exact derivatives of `W*`)
//! would recover the reduced curvature.

//!
//! # Cost
//!
//! One *timing round* is one Newton iteration of [`Timing::optimize_times_from`]: the
//! derivatives on every interval, then one W evaluation (samples, fresh projections,
//! residuals; no gradient, [`Objective::fresh_value`]) per line-search trial, starting from the
//! W the caller has.
//! The derivatives move every tet at every sample along its line in `T`: the projection, its
//! two derivatives and their node forces run 16 tets at a time in SIMD lanes, the SVD included
//! ([`project_along_forces`](crate::algorithms::physics::projection_curvature::project_along_forces)), with the bytes of the scalar definition
//! ([`project_along_svd`](crate::algorithms::physics::projection_curvature::project_along_svd); tested on
//! the whole derivatives). Around the kernel, per sample: the five combinations of the unknowns
//! in one pass, `L x` and `L x_T` in one pass over `L`, and each tet's `F` and `F_T` from one
//! read of its nodes, written straight into lanes.

use rayon::prelude::*;

use super::objective::{Objective, Projections};
use super::sampling::{sample_counts, samples, Sample, TimeSlots};
use super::settings::{Settings, TimingSettings};
use super::trajectory::{length_derivative, Trajectory};
use super::unknowns::KeyConstraints;
use crate::algorithms::geometry::Point;
use crate::algorithms::physics::elastic::Elastic;
use crate::algorithms::physics::lanes::{Lanes, BATCH};
use crate::algorithms::physics::projection_curvature::project_along_forces_lanes;
use crate::support::error::{Error, Result};

/// The spacetime objective as a function of the key times.
#[derive(Clone)]
pub struct Timing<'a> {
    /// The body.
    pub elastic: &'a Elastic,
    /// The keys' time slots (a loop's last key is its first, a contact's keys share a pose).
    pub slots: TimeSlots,
    /// Samples on each interval (contacts have none whatever their count).
    pub per_interval: Vec<usize>,
    /// Rayleigh mass damping α.
    pub damping: f64,
    /// Gravitational acceleration.
    pub gravity: Point,
    /// Nodes whose residual W leaves out (see [`Objective::supports`]).
    pub supports: Vec<bool>,
}

/// Which projections the derivatives hold.
#[derive(Clone, Copy)]
pub enum ProjectionMode<'p> {
    /// Held at these values (one per sample of [`Timing::objective`] at the current times).
    Frozen(&'p Projections),
    /// Re-projected at every sample: the total derivative of W.
    Fresh,
}

/// W and its derivatives in every interval length (zero for zero-length intervals).
#[derive(Debug, Clone, PartialEq)]
pub struct TimeDerivatives {
    /// W.
    pub value: f64,
    /// `∂W/∂T_i`.
    pub gradient: Vec<f64>,
    /// `∂²W/∂T_i²`, the whole Hessian (it is diagonal).
    pub curvature: Vec<f64>,
}

/// What a timing step did.
#[derive(Debug, Clone, PartialEq)]
pub struct TimingStep {
    /// The new key times.
    pub times: Vec<f64>,
    /// W at the start and after every accepted Newton iteration (non-increasing).
    pub energy: Vec<f64>,
    /// Newton iterations whose step was accepted.
    pub iterations: usize,
    /// Interval curvatures that were not positive and were replaced by a gradient step.
    pub gradient_steps: usize,
    /// Step halvings of the line search, in all.
    pub halvings: usize,
    /// Why the step stopped, in words.
    pub stop_reason: String,
}

/// Largest growth of an interval in one Newton iteration (a factor of 1 + this).
const MAX_GROWTH: f64 = 1.0;
/// Largest shrink of an interval in the first trial of a Newton iteration (a fraction of its
/// length). Why: W grows like `T⁻³` as an interval with held keys shortens (its accelerations
/// go as `T⁻²`), far faster than the quadratic model says, and a step that the model sends to
/// the minimum length is a clamp, not the model's minimum; on DINO the full step that shrank
/// two intervals from 0.35 to 0.001 s failed and its half was taken, one W evaluation more.
const MAX_SHRINK: f64 = 0.5;
/// Relative change of an interval taken by the gradient step that replaces a non-positive
/// curvature.
const GRADIENT_STEP: f64 = 0.25;
/// Armijo's sufficient-decrease fraction.
const ARMIJO: f64 = 1e-4;
const MAX_HALVINGS: usize = 30;

impl<'a> Timing<'a> {
    /// The timing problem of the solver's objective for `keys` with these settings.
    pub fn new(elastic: &'a Elastic, keys: &KeyConstraints, settings: &Settings) -> Timing<'a> {
        Timing {
            elastic,
            slots: keys.slots(),
            per_interval: sample_counts(&keys.times, settings.samples, settings.contact_samples),
            damping: settings.damping,
            gravity: settings.gravity,
            supports: keys.supports(elastic.node_count()),
        }
    }

    /// The objective at key times `times`: samples on every interval of positive length
    /// (zero-length intervals have none).
    pub fn objective(&self, times: &[f64]) -> Objective<'a> {
        Objective {
            elastic: self.elastic,
            samples: samples(times, &self.per_interval, &self.slots),
            slots: self.slots.clone(),
            damping: self.damping,
            gravity: self.gravity,
            supports: self.supports.clone(),
            time_gradient: false,
        }
    }

    /// W at `tr` (at its own times) with fresh projections.
    pub fn energy(&self, tr: &Trajectory) -> f64 {
        self.objective(&tr.times).fresh_value(tr)
    }

    /// W and its exact derivatives in every `T_i` at `tr` (see the module documentation).
    pub fn derivatives(&self, tr: &Trajectory, mode: ProjectionMode) -> TimeDerivatives {
        let objective = self.objective(&tr.times);
        if let ProjectionMode::Frozen(p) = mode {
            assert_eq!(p.targets.len(), objective.samples.len(), "frozen projections are one per sample at these times");
        }
        let per_sample: Vec<(usize, [f64; 3])> =
            objective.samples.par_iter().enumerate().map(|(k, s)| (s.interval, self.sample_derivatives(tr, s, k, mode))).collect();
        let intervals = tr.times.len() - 1;
        let (mut value, mut gradient, mut curvature) = (0.0, vec![0.0; intervals], vec![0.0; intervals]);
        for (i, [w, g, h]) in per_sample {
            value += w;
            gradient[i] += g;
            curvature[i] += h;
        }
        TimeDerivatives { value, gradient, curvature }
    }

    /// `(W_s, ∂W_s/∂T, ∂²W_s/∂T²)` of sample `s` (index `k`).
    fn sample_derivatives(&self, tr: &Trajectory, s: &Sample, k: usize, mode: ProjectionMode) -> [f64; 3] {
        let el = self.elastic;
        let n = el.node_count();
        let i = s.interval;
        let t = tr.times[i + 1] - tr.times[i];
        let b = &s.basis;
        let alpha = self.damping;
        let (d1, d2) = (length_derivative(b, t, 1), length_derivative(b, t, 2));
        let pos = b.pos;
        let pos_t = d1.pos;
        let c: [f64; 4] = std::array::from_fn(|j| b.acc[j] + alpha * b.vel[j]);
        let c_t: [f64; 4] = std::array::from_fn(|j| d1.acc[j] + alpha * d1.vel[j]);
        let c_tt: [f64; 4] = std::array::from_fn(|j| d2.acc[j] + alpha * d2.vel[j]);
        let u = [&tr.positions[i], &tr.velocities[i], &tr.positions[i + 1], &tr.velocities[i + 1]];
        // The five combinations of the interval's unknowns in one pass over them.
        let mut combos: [Vec<Point>; 5] = std::array::from_fn(|_| Vec::with_capacity(n));
        for a in 0..n {
            let (u0, u1, u2, u3) = (u[0][a], u[1][a], u[2][a], u[3][a]);
            for (w, out) in [&pos, &pos_t, &c, &c_t, &c_tt].into_iter().zip(combos.iter_mut()) {
                let at = |d: usize| w[0] * u0[d] + w[1] * u1[d] + w[2] * u2[d] + w[3] * u3[d];
                out.push([at(0), at(1), at(2)]);
            }
        }
        let [x, x_t, acc, acc_t, acc_tt] = combos;
        let (mut lx, mut lx_t) = (vec![[0.0; 3]; n], vec![[0.0; 3]; n]);
        el.stiffness.mul_points_pair_sequential([&x, &x_t], [&mut lx, &mut lx_t]);
        let (mut jp, mut jp_t, mut jp_tt) = (vec![[0.0; 3]; n], vec![[0.0; 3]; n], vec![[0.0; 3]; n]);
        match mode {
            ProjectionMode::Frozen(p) => el.apply_j_sequential(&p.targets[k], &mut jp),
            ProjectionMode::Fresh => {
                // p, p_T, p_TT of every tet, BATCH tets per vectorized call, their node forces
                // added in tet order like `apply_j_sequential`.
                let share = el.strain_share();
                let count = el.tet_count();
                let mut forces = [[[Lanes::splat(0.0); 3]; 4]; 3];
                let (mut f, mut f_t) = ([[Lanes::splat(0.0); 3]; 3], [[Lanes::splat(0.0); 3]; 3]);
                let mut last = ([[[0.0; 3]; 4]; BATCH], [0.0; BATCH]);
                for first in (0..count).step_by(BATCH) {
                    let lanes = BATCH.min(count - first);
                    // F and F_T straight into lanes (past the last tet: the identity and zero).
                    el.deformation_gradient_lanes(first, &x, Some((&x_t, &mut f_t)), &mut f);
                    let (grads, weights) = el.batch_grads_weights(first, &mut last);
                    project_along_forces_lanes(&f, share, &f_t, grads, weights, &mut forces);
                    let [value, first_t, second_t] = &forces;
                    for (l, e) in (first..first + lanes).enumerate() {
                        for (k, &a) in el.tets[e].iter().enumerate() {
                            let a = a as usize;
                            for i in 0..3 {
                                jp[a][i] += value[k][i].0[l];
                                jp_t[a][i] += first_t[k][i].0[l];
                                jp_tt[a][i] += second_t[k][i].0[l];
                            }
                        }
                    }
                }
            }
        }
        let g = self.gravity;
        let (mut ff, mut ftf, mut ftft, mut fttf) = (0.0, 0.0, 0.0, 0.0);
        for a in (0..n).filter(|&a| !self.supports[a]) {
            let m = el.mass[a];
            for d in 0..3 {
                let f = m * (acc[a][d] - g[d]) + lx[a][d] - jp[a][d];
                let f_t = m * acc_t[a][d] + lx_t[a][d] - jp_t[a][d];
                let f_tt = m * acc_tt[a][d] - jp_tt[a][d];
                ff += f * f / m;
                ftf += f_t * f / m;
                ftft += f_t * f_t / m;
                fttf += f_tt * f / m;
            }
        }
        let (w, dw) = (s.weight, s.weight / t);
        [0.5 * w * ff, 0.5 * dw * ff + w * ftf, 2.0 * dw * ftf + w * (ftft + fttf)]
    }

    /// The timing step: move the key times of `tr` (positions and velocities held) to lower
    /// W, under `settings`' constraints. W never increases; on any failure to decrease it the
    /// times stay where they are.
    pub fn optimize_times(&self, tr: &Trajectory, settings: &TimingSettings) -> Result<TimingStep> {
        Blocks::new(&tr.times, settings)?;
        self.optimize_times_from(tr, self.finite_energy(tr, 0)?, settings)
    }

    /// [`Timing::optimize_times`] from a trajectory whose W the caller already has, `w0` (as
    /// [`Timing::energy`] gives it; an alternating solver has it from its last iteration).
    /// Every Newton iteration of it is one *timing round*: the exact derivatives in every
    /// interval length, the constrained Newton step, and its line search on W.
    pub fn optimize_times_from(&self, tr: &Trajectory, w0: f64, settings: &TimingSettings) -> Result<TimingStep> {
        let keys = tr.times.len();
        let blocks = Blocks::new(&tr.times, settings)?;
        let mut tr = tr.clone();
        let mut energy = vec![w0];
        let (mut iterations, mut gradient_steps, mut halvings) = (0, 0, 0);
        let lengths = |times: &[f64]| -> Vec<f64> { (0..keys - 1).map(|i| times[i + 1] - times[i]).collect() };
        let lower: Vec<f64> = lengths(&tr.times).iter().map(|&t| settings.min_interval.min(t)).collect();
        let stop_reason = loop {
            let w = *energy.last().expect("initial W");
            if iterations >= settings.max_iterations {
                break format!("stopped after {} Newton iterations", settings.max_iterations);
            }
            if w == 0.0 {
                break "W is zero".to_string();
            }
            let d = self.derivatives(&tr, ProjectionMode::Fresh);
            let t = lengths(&tr.times);
            let h = safe_curvature(&d.gradient, &d.curvature, &t);
            gradient_steps += (0..keys - 1).filter(|&i| h[i] != d.curvature[i] && blocks.moves(i)).count();
            let lo: Vec<f64> = (0..keys - 1).map(|i| lower[i] - t[i]).collect();
            let step = blocks.newton_step(&d.gradient, &h, &lo);
            let decrease: f64 = -step.iter().zip(&d.gradient).map(|(s, g)| s * g).sum::<f64>();
            if decrease.is_nan() || decrease <= settings.tolerance * w {
                break format!("stationary: the predicted decrease {:.3e} is below {:.0e} of W", decrease.max(0.0), settings.tolerance);
            }
            // Start at the full step, or less where an interval would more than double or lose
            // more than half its length.
            let mut scale = step.iter().zip(&t).fold(1.0f64, |a, (&s, &t)| {
                if s > 0.0 {
                    a.min(MAX_GROWTH * t / s)
                } else if s < 0.0 {
                    a.min(MAX_SHRINK * t / -s)
                } else {
                    a
                }
            });
            let mut accepted = None;
            for halving in 0..=MAX_HALVINGS {
                let trial = Trajectory { times: blocks.times(&tr.times, &step, scale), ..tr.clone() };
                let w_trial = self.finite_energy(&trial, iterations + 1)?;
                if w_trial <= w - ARMIJO * scale * decrease {
                    accepted = Some((trial, w_trial));
                    halvings += halving;
                    break;
                }
                scale *= 0.5;
            }
            let Some((trial, w_trial)) = accepted else {
                halvings += MAX_HALVINGS;
                break "no step along the Newton direction decreases W enough (Armijo)".to_string();
            };
            tr = trial;
            energy.push(w_trial);
            iterations += 1;
        };
        Ok(TimingStep { times: tr.times, energy, iterations, gradient_steps, halvings, stop_reason })
    }

    fn finite_energy(&self, tr: &Trajectory, iteration: usize) -> Result<f64> {
        let w = self.energy(tr);
        if !w.is_finite() {
            return Err(Error::general(
                format!("the spacetime energy W became {w} in timing iteration {iteration} (key times {:?})", tr.times),
                "check the keyframes for flat or inverted tets, and raise the minimum interval length",
            ));
        }
        Ok(w)
    }
}

/// The curvatures for the Newton model: the exact ones where positive, elsewhere the one
/// that turns the Newton step into a gradient step changing the interval by
/// [`GRADIENT_STEP`] of its length `t` (floored at 1e-6 of the largest gradient, so an
/// interval with no gradient and no curvature is not thrown far by a block's multiplier).
pub(super) fn safe_curvature(gradient: &[f64], curvature: &[f64], t: &[f64]) -> Vec<f64> {
    let floor = gradient.iter().fold(0.0f64, |m, g| m.max(g.abs())).max(f64::MIN_POSITIVE) * 1e-6;
    (0..gradient.len())
        .map(|i| {
            if curvature[i] > 0.0 && curvature[i].is_finite() {
                curvature[i]
            } else {
                gradient[i].abs().max(floor) / (GRADIENT_STEP * t[i].max(f64::MIN_POSITIVE))
            }
        })
        .collect()
}

/// The intervals grouped by the fixed key times (see the module documentation).
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Blocks {
    /// Keys whose time is held: key 0, `fixed_times`, and the last key with `keep_duration`.
    anchored: Vec<bool>,
    /// Movable intervals (positive length) per block, and whether the block's sum is fixed.
    pub(super) blocks: Vec<(Vec<usize>, bool)>,
}

impl Blocks {
    pub(super) fn new(times: &[f64], settings: &TimingSettings) -> Result<Blocks> {
        let keys = times.len();
        if !(settings.min_interval > 0.0 && settings.min_interval.is_finite()) {
            return Err(Error::general(
                format!("the minimum interval length is {}, it must be positive", settings.min_interval),
                "set a small positive minimum interval, e.g. 1e-3 s",
            ));
        }
        let mut anchored = vec![false; keys];
        anchored[0] = true;
        if settings.keep_duration {
            anchored[keys - 1] = true;
        }
        for &k in &settings.fixed_times {
            if k >= keys {
                return Err(Error::general(
                    format!("fixed_times lists key {k}, but there are only {keys} keys"),
                    format!("list key indices from 0 to {}", keys - 1),
                ));
            }
            anchored[k] = true;
        }
        if let Some(i) = (0..keys - 1).find(|&i| times[i + 1].partial_cmp(&times[i]).is_none_or(|o| o.is_lt())) {
            return Err(Error::general(
                format!("key {} (t = {}) comes before key {i} (t = {})", i + 1, times[i + 1], times[i]),
                "give the keys non-decreasing times",
            ));
        }
        let mut blocks = Vec::new();
        let mut current = Vec::new();
        for i in 0..keys - 1 {
            if times[i + 1] > times[i] {
                current.push(i);
            }
            if anchored[i + 1] {
                blocks.push((std::mem::take(&mut current), true));
            }
        }
        if !anchored[keys - 1] {
            blocks.push((current, false));
        }
        Ok(Blocks { anchored, blocks })
    }

    /// Whether interval `i` can change at all.
    fn moves(&self, i: usize) -> bool {
        self.blocks.iter().any(|(b, fixed_sum)| b.contains(&i) && !(*fixed_sum && b.len() == 1))
    }

    /// Minimizer of `Σ g_i Δ_i + ½ h_i Δ_i²` (h > 0) with `Δ_i >= lo_i` and a zero sum per
    /// fixed-sum block; zero for intervals outside every block.
    fn newton_step(&self, g: &[f64], h: &[f64], lo: &[f64]) -> Vec<f64> {
        let mut step = vec![0.0; g.len()];
        for (block, fixed_sum) in &self.blocks {
            if !fixed_sum {
                for &i in block {
                    step[i] = (-g[i] / h[i]).max(lo[i]);
                }
                continue;
            }
            // Δ_i(μ) = max(lo_i, (μ - g_i)/h_i) is unclamped for μ above μ_i = g_i + h_i lo_i.
            // Walk the breakpoints upwards: on each segment the sum is linear in μ.
            let mut order: Vec<(f64, usize)> = block.iter().map(|&i| (g[i] + h[i] * lo[i], i)).collect();
            order.sort_by(|a, b| a.0.total_cmp(&b.0));
            let (mut clamped_sum, mut gh, mut inv_h): (f64, f64, f64) = (block.iter().map(|&i| lo[i]).sum(), 0.0, 0.0);
            let mut mu = None;
            for (k, &(_, i)) in order.iter().enumerate() {
                clamped_sum -= lo[i];
                gh += g[i] / h[i];
                inv_h += 1.0 / h[i];
                let candidate = (gh - clamped_sum) / inv_h;
                let upper = order.get(k + 1).map_or(f64::INFINITY, |b| b.0);
                if candidate <= upper {
                    mu = Some(candidate.max(order[k].0));
                    break;
                }
            }
            let mu = mu.expect("the last segment is unbounded above");
            for &i in block {
                step[i] = ((mu - g[i]) / h[i]).max(lo[i]);
            }
        }
        step
    }

    /// Key times after the step `scale × step` on the interval lengths: each key is the
    /// previous one plus its interval, except anchored keys, which keep their time exactly
    /// (so a fixed sum holds to the bit, the last interval of a block absorbing roundoff).
    pub(super) fn times(&self, times: &[f64], step: &[f64], scale: f64) -> Vec<f64> {
        let mut out = times.to_vec();
        for k in 1..times.len() {
            if !self.anchored[k] {
                let i = k - 1;
                let len = times[k] - times[i];
                out[k] = if len > 0.0 { out[i] + (len + scale * step[i]) } else { out[i] };
            }
        }
        out
    }
}

#[cfg(test)]
mod tests;
