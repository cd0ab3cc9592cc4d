//! The spacetime objective and the local step.
//!
//! At sample `s` (time `t_s`, weight `dτ_s`) the residual force is
//!
//! ```text
//! f_s = M (ẍ + α ẋ - g) + L x - J p_s          (D = α M, f_ext = M g)
//! W   = Σ_s dτ_s ½ |f_s|²_{M⁻¹}
//! ```
//!
//! where `x, ẋ, ẍ` are the Hermite trajectory at `t_s`, and `p_s` are the element projections
//! at `x(t_s)` (the local step). With the projections held fixed, `f_s` is affine in the
//! keyframe unknowns: per slot `j` of the sample's interval, `∂f_s/∂u_j = c_j M + l_j L` with
//! `c_j = acc_j + α vel_j` and `l_j = pos_j` (the Hermite weights). So the gradient is, per
//! time slot σ, `Σ_s dτ_s (c_σ f_s + l_σ L M⁻¹ f_s) = F^c_σ + L M⁻¹ F^l_σ`, two accumulations
//! and one sparse product per slot instead of one per sample. This is the gradient of the
//! global step's quadratic model.
//!
//! The exact gradient of W also differentiates the projections: the stiffness seen by the
//! residual is `∇²E(x) = L - J DP dF`, not `L`, so it subtracts
//! `Σ_s dτ_s l_σ J DP_s[dF(M⁻¹ f_s)]` per slot (computed when the local step kept the
//! projection Jacobians). With the same Jacobians it also gives `∂W/∂T_i`, the derivative in
//! every interval length with the keys held (see [`super::timing`] for the formula), when asked.
//!
//! Supports: a node whose whole trajectory is prescribed (position and velocity held at every
//! key) cannot respond to anything, so its residual is the reaction force of whatever holds it
//! (a clamp, the ground), not an error of the dynamics. Its rows are left out of W: `f_s` is
//! zero there. Without this, a clamped bar's W mostly measures the clamp's reaction, which grows
//! with the duration, and W has no minimum at the bar's period (measured: over 98% of `|∇E|²`
//! at the bent key of a cantilever is the clamp's). Scenes without such nodes are unaffected.

use rayon::prelude::*;

use super::sampling::{Sample, TimeSlots};
use super::trajectory::{length_derivative, Trajectory};
use crate::algorithms::geometry::Point;
use crate::algorithms::physics::elastic::Elastic;
use crate::algorithms::physics::lanes::BATCH;
use crate::algorithms::physics::mat3::Mat3;
use crate::algorithms::physics::projection::JacobianBatch;

/// The local step: element projections of every sample (`[sample][tet]`), and optionally
/// their Jacobians (for the exact gradient).
#[derive(Debug, Clone)]
pub struct Projections {
    /// `targets[sample][tet]`.
    pub targets: Vec<Vec<Mat3>>,
    /// `jacobians[sample][batch]`, when asked for: tets `BATCH * batch..` of the sample in
    /// lane layout (`JacobianBatch`; `tet_count().div_ceil(BATCH)` per sample), as the local
    /// step computes them and the gradients apply them.
    pub jacobians: Option<Vec<Vec<JacobianBatch>>>,
}

impl Projections {
    /// One buffer per sample (and per sample's Jacobians when `with_jacobians`), keeping the
    /// buffers already there.
    fn shape(&mut self, samples: usize, with_jacobians: bool) {
        self.targets.resize_with(samples, Vec::new);
        if with_jacobians {
            self.jacobians.get_or_insert_with(Vec::new).resize_with(samples, Vec::new);
        } else {
            self.jacobians = None;
        }
    }
}

/// The quantities the objective needs besides the trajectory.
pub struct Objective<'a> {
    /// The body.
    pub elastic: &'a Elastic,
    /// Where the residual is sampled.
    pub samples: Vec<Sample>,
    /// The time slots of the unknowns.
    pub slots: TimeSlots,
    /// Rayleigh mass damping α (D = α M).
    pub damping: f64,
    /// Gravitational acceleration g.
    pub gravity: Point,
    /// Per node, whether it is a support (its whole trajectory is prescribed): its residual
    /// is left out of W.
    pub supports: Vec<bool>,
    /// Also evaluate `∂W/∂T_i` when the projections come with their Jacobians.
    pub time_gradient: bool,
}

/// One sample's residual and what it contributes to W.
struct Residual {
    /// `f = M (ẍ + α ẋ - g) + L x - J p` at every node.
    force: Vec<Point>,
    /// `dτ ½ |f|²_{M⁻¹}`.
    w: f64,
    /// `dτ ½ |L x - J p|²_{M⁻¹}`.
    w_elastic: f64,
    /// `dτ ½ (|M (ẍ + α ẋ)|² + |M g|² + |L x - J p|²)_{M⁻¹}`: the forces f is the sum of.
    w_forces: f64,
    /// `J DP[dF(M⁻¹ f)]`, the exact gradient's correction (when the projections came with
    /// their Jacobians).
    correction: Option<Vec<Point>>,
    /// `∂W_s/∂T` of the sample's interval, when asked for.
    time_derivative: Option<f64>,
}

/// W and its gradient at one trajectory.
#[derive(Debug, Clone)]
pub struct Evaluation {
    /// W.
    pub value: f64,
    /// The elastic part `Σ dτ ½ |L x - J p|²_{M⁻¹}` (zero for rigid motion).
    pub elastic: f64,
    /// The force scale `S = Σ dτ ½ (|M (ẍ + α ẋ)|² + |M g|² + |L x - J p|²)_{M⁻¹}`: W with
    /// the forces that make up the residual squared one by one instead of summed, so that
    /// `0 <= W <= 3 S`, and `W / S` is the squared relative size of the residual (what the
    /// forces fail to cancel). It does not depend on the units or on how W started.
    pub force_scale: f64,
    /// `∂W/∂u` with the projections held fixed (the global step's model), for every slot
    /// (fixed entries included: callers mask them), `[slot][node]`.
    pub gradient: Vec<Vec<Point>>,
    /// The exact `∂W/∂u`, when the projections came with their Jacobians.
    pub exact_gradient: Option<Vec<Vec<Point>>>,
    /// The exact `∂W/∂T_i` per interval (zero for contacts), when the projections came with
    /// their Jacobians and [`Objective::time_gradient`] is set.
    pub time_gradient: Option<Vec<f64>>,
}

impl<'a> Objective<'a> {
    /// Mass coefficient `c_j = acc_j + α vel_j` and stiffness coefficient `l_j = pos_j` of the
    /// four unknowns of a sample.
    #[inline]
    pub fn coefficients(&self, s: &Sample) -> ([f64; 4], [f64; 4]) {
        let b = &s.basis;
        let c = [0, 1, 2, 3].map(|j| b.acc[j] + self.damping * b.vel[j]);
        (c, b.pos)
    }

    /// The mass and stiffness coefficients of time slot `slot` in sample `s` (summed over the
    /// sample's unknowns in that slot; zero when the slot is not in its interval).
    #[inline]
    fn slot_coefficients(&self, s: &Sample, slot: usize) -> (f64, f64) {
        let (c, l) = self.coefficients(s);
        (0..4).filter(|&j| s.slots[j] == slot).fold((0.0, 0.0), |(cs, ls), j| (cs + c[j], ls + l[j]))
    }

    /// The four unknown arrays of a sample's interval.
    fn unknowns<'t>(tr: &'t Trajectory, s: &Sample) -> [&'t [Point]; 4] {
        let i = s.interval;
        [&tr.positions[i], &tr.velocities[i], &tr.positions[i + 1], &tr.velocities[i + 1]]
    }

    /// `Σ_j w_j u_j` over a sample's unknowns.
    fn combine(u: &[&[Point]; 4], w: &[f64; 4], out: &mut [Point]) {
        for (a, o) in out.iter_mut().enumerate() {
            for d in 0..3 {
                o[d] = w[0] * u[0][a][d] + w[1] * u[1][a][d] + w[2] * u[2][a][d] + w[3] * u[3][a][d];
            }
        }
    }

    /// The local step: projections of every element at every sample, in parallel over
    /// samples and elements; with their Jacobians when `with_jacobians`.
    pub fn local_step(&self, tr: &Trajectory, with_jacobians: bool) -> Projections {
        let mut p = Projections { targets: Vec::new(), jacobians: None };
        self.local_step_into(tr, with_jacobians, &mut p);
        p
    }

    /// [`Objective::local_step`] into `out`, reusing its buffers (the same bytes). An iteration
    /// that keeps one `Projections` allocates none of the projections again: on a small body
    /// (the demo: 40 samples of 777 tets, 10 MB with the Jacobians) fresh buffers cost more in
    /// page faults and heap trimming on the worker threads than the allocation itself.
    pub(crate) fn local_step_into(&self, tr: &Trajectory, with_jacobians: bool, out: &mut Projections) {
        out.shape(self.samples.len(), with_jacobians);
        let split_tets = self.split_tets();
        let project = |s: &Sample, p: &mut Vec<Mat3>, j: Option<&mut Vec<JacobianBatch>>| self.project_sample(tr, s, p, j, split_tets);
        match out.jacobians.as_mut() {
            Some(jacobians) => {
                self.samples.par_iter().zip(out.targets.par_iter_mut()).zip(jacobians.par_iter_mut()).for_each(|((s, p), j)| project(s, p, Some(j)))
            }
            None => self.samples.par_iter().zip(out.targets.par_iter_mut()).for_each(|(s, p)| project(s, p, None)),
        }
    }

    /// Samples run in parallel, each projecting its tets on its thread; with too few samples to
    /// keep the threads busy, the tets of each sample are split instead (same bytes).
    fn split_tets(&self) -> bool {
        self.samples.len() < 4 * rayon::current_num_threads()
    }

    /// The local step of one sample into `p` (and `j`), reusing their buffers.
    fn project_sample(&self, tr: &Trajectory, s: &Sample, p: &mut Vec<Mat3>, j: Option<&mut Vec<JacobianBatch>>, split_tets: bool) {
        let (el, m) = (self.elastic, self.elastic.tet_count());
        let x = self.positions(tr, s);
        match (j, split_tets) {
            (None, false) => el.local_step_sequential_into(&x, p),
            (Some(j), false) => el.local_step_with_jacobian_batches_sequential_into(&x, p, j),
            (None, true) => {
                p.resize(m, [[0.0; 3]; 3]);
                el.local_step(&x, p);
            }
            (Some(j), true) => {
                p.resize(m, [[0.0; 3]; 3]);
                j.resize_with(m.div_ceil(BATCH), JacobianBatch::default);
                el.local_step_with_jacobian_batches(&x, p, j);
            }
        }
    }

    /// [`Objective::evaluate`] after [`Objective::local_step`] (with the Jacobians when `exact`),
    /// to the bit, in one pass over the samples: each sample's residual is taken right after
    /// its projections, while they (205 KB with the Jacobians on the demo) are still in cache,
    /// instead of after every sample's have gone out to memory. `scratch` keeps the buffers.
    pub fn evaluate_fresh(&self, tr: &Trajectory, exact: bool, scratch: &mut Projections) -> Evaluation {
        if self.split_tets() {
            self.local_step_into(tr, exact, scratch);
            return self.evaluate(tr, scratch);
        }
        scratch.shape(self.samples.len(), exact);
        let residuals: Vec<Residual> = match scratch.jacobians.as_mut() {
            // The projections' node forces `J p` taken in the local step's pass over the tets
            // (the same sums; both branches), and the positions combined once for both.
            Some(jacobians) => self
                .samples
                .par_iter()
                .zip(scratch.targets.par_iter_mut())
                .zip(jacobians.par_iter_mut())
                .map(|((s, p), j)| {
                    let x = self.positions(tr, s);
                    let mut jp = vec![[0.0; 3]; x.len()];
                    self.elastic.local_step_with_jacobian_batches_and_forces_sequential_into(&x, p, j, &mut jp);
                    self.sample_residual_from(tr, s, self.residual_at(tr, s, &x, &jp), Some(j))
                })
                .collect(),
            None => self
                .samples
                .par_iter()
                .zip(scratch.targets.par_iter_mut())
                .map(|(s, p)| {
                    let x = self.positions(tr, s);
                    let mut jp = vec![[0.0; 3]; x.len()];
                    self.elastic.local_step_and_forces_sequential_into(&x, p, &mut jp);
                    self.sample_residual_from(tr, s, self.residual_at(tr, s, &x, &jp), None)
                })
                .collect(),
        };
        self.assemble(tr, residuals, exact)
    }

    /// W, its elastic part, and its gradient with the projections held at `p` (and the exact
    /// gradient when `p` has the projection Jacobians).
    pub fn evaluate(&self, tr: &Trajectory, p: &Projections) -> Evaluation {
        let residuals = self.residuals(tr, p);
        self.assemble(tr, residuals, p.jacobians.is_some())
    }

    /// W and its gradients from every sample's residual (in sample order); the exact gradient
    /// when the residuals were taken with the projection Jacobians.
    fn assemble(&self, tr: &Trajectory, residuals: Vec<Residual>, exact: bool) -> Evaluation {
        let value = residuals.iter().map(|r| r.w).sum();
        let elastic = residuals.iter().map(|r| r.w_elastic).sum();
        let force_scale = residuals.iter().map(|r| r.w_forces).sum();
        let gradient = self.model_gradient(&residuals);
        let exact_gradient = exact.then(|| self.exact_gradient(&gradient, &residuals));
        let time_gradient = residuals.first().is_some_and(|r| r.time_derivative.is_some()).then(|| {
            let mut g = vec![0.0; tr.times.len() - 1];
            for (s, r) in self.samples.iter().zip(&residuals) {
                g[s.interval] += r.time_derivative.expect("every sample has it");
            }
            g
        });
        Evaluation { value, elastic, force_scale, gradient, exact_gradient, time_gradient }
    }

    /// W alone with fresh projections: the value of [`Objective::evaluate`] after
    /// [`Objective::local_step`] to the bit, without the gradients and without storing the
    /// projections (what a line search on the key times needs).
    pub fn fresh_value(&self, tr: &Trajectory) -> f64 {
        let per_sample: Vec<f64> = self.samples.par_iter().map(|s| 0.5 * s.weight * self.residual(tr, s, None).1).collect();
        per_sample.into_iter().sum()
    }

    /// One sample's residual force `f` (zero at supports), `|f|²_{M⁻¹}`, `|L x - J p|²_{M⁻¹}` and
    /// the three forces squared apart, `|M a|² + |M g|² + |L x - J p|²` in `M⁻¹` (the force scale's
    /// share; all without the weight), with the projections held at `targets`, or fresh ones.
    fn residual(&self, tr: &Trajectory, s: &Sample, targets: Option<&[Mat3]>) -> (Vec<Point>, f64, f64, f64) {
        let el = self.elastic;
        let x = self.positions(tr, s);
        let mut jp = vec![[0.0; 3]; x.len()];
        // Samples run in parallel: the products run on this thread (same bytes).
        match targets {
            Some(targets) => el.apply_j_sequential(targets, &mut jp),
            None => el.projected_forces_sequential(&x, &mut jp),
        }
        self.residual_at(tr, s, &x, &jp)
    }

    /// The positions `x(t_s)` of a sample.
    fn positions(&self, tr: &Trajectory, s: &Sample) -> Vec<Point> {
        let mut x = vec![[0.0; 3]; self.elastic.node_count()];
        Self::combine(&Self::unknowns(tr, s), &s.basis.pos, &mut x);
        x
    }

    /// [`Objective::residual`] at the sample's positions `x` with the projections' node forces
    /// `jp = J p`.
    fn residual_at(&self, tr: &Trajectory, s: &Sample, x: &[Point], jp: &[Point]) -> (Vec<Point>, f64, f64, f64) {
        let el = self.elastic;
        let n = el.node_count();
        let g = self.gravity;
        let (c, _) = self.coefficients(s);
        let mut acc = vec![[0.0; 3]; n];
        Self::combine(&Self::unknowns(tr, s), &c, &mut acc);
        let mut lx = vec![[0.0; 3]; n];
        el.stiffness.mul_points_sequential(x, &mut lx);
        let (mut w, mut w_el, mut w_forces) = (0.0, 0.0, 0.0);
        let mut f = vec![[0.0; 3]; n];
        for a in 0..n {
            if self.supports[a] {
                continue;
            }
            let m = el.mass[a];
            for d in 0..3 {
                let e = lx[a][d] - jp[a][d];
                f[a][d] = m * (acc[a][d] - g[d]) + e;
                w += f[a][d] * f[a][d] / m;
                w_el += e * e / m;
                w_forces += m * (acc[a][d] * acc[a][d] + g[d] * g[d]) + e * e / m;
            }
        }
        (f, w, w_el, w_forces)
    }

    /// The residual of every sample, with the projections held at `p`.
    fn residuals(&self, tr: &Trajectory, p: &Projections) -> Vec<Residual> {
        self.samples
            .par_iter()
            .enumerate()
            .map(|(k, s)| self.sample_residual(tr, s, &p.targets[k], p.jacobians.as_ref().map(|j| j[k].as_slice())))
            .collect()
    }

    /// One sample's residual with its projections held at `targets` (and their Jacobians `jac`).
    fn sample_residual(&self, tr: &Trajectory, s: &Sample, targets: &[Mat3], jac: Option<&[JacobianBatch]>) -> Residual {
        // Residual per sample: f = M (a - g) + L x - J p, and its elastic part L x - J p.
        self.sample_residual_from(tr, s, self.residual(tr, s, Some(targets)), jac)
    }

    /// [`Objective::sample_residual`] from the sample's [`Objective::residual`].
    fn sample_residual_from(&self, tr: &Trajectory, s: &Sample, residual: (Vec<Point>, f64, f64, f64), jac: Option<&[JacobianBatch]>) -> Residual {
        let el = self.elastic;
        let n = el.node_count();
        let u = Self::unknowns(tr, s);
        let (f, w, w_el, w_forces) = residual;
        // J DP[dF(M⁻¹ f)]: the part of ∇²E M⁻¹ f that the frozen model leaves out.
        let correction = jac.map(|jac| {
            let u: Vec<Point> = f.iter().zip(&el.mass).map(|(v, m)| crate::algorithms::geometry::scale(*v, 1.0 / m)).collect();
            let mut z = vec![[0.0; 3]; n];
            el.apply_jacobians_sequential(jac, &u, &mut z);
            z
        });
        // ∂W_s/∂T = (dτ/T) ½|f|² + dτ f_T·f with f_T = M (ẍ_T + α ẋ_T) + L x_T - J DP[dF(x_T)].
        let time_derivative = jac.filter(|_| self.time_gradient).map(|jac| {
            let t_len = tr.times[s.interval + 1] - tr.times[s.interval];
            let d = length_derivative(&s.basis, t_len, 1);
            let c_t = [0, 1, 2, 3].map(|j| d.acc[j] + self.damping * d.vel[j]);
            let (mut x_t, mut acc_t) = (vec![[0.0; 3]; n], vec![[0.0; 3]; n]);
            Self::combine(&u, &d.pos, &mut x_t);
            Self::combine(&u, &c_t, &mut acc_t);
            let (mut lx_t, mut jp_t) = (vec![[0.0; 3]; n], vec![[0.0; 3]; n]);
            el.stiffness.mul_points_sequential(&x_t, &mut lx_t);
            el.apply_jacobians_sequential(jac, &x_t, &mut jp_t);
            let mut ftf = 0.0;
            for a in (0..n).filter(|&a| !self.supports[a]) {
                for d in 0..3 {
                    ftf += (el.mass[a] * acc_t[a][d] + lx_t[a][d] - jp_t[a][d]) * f[a][d] / el.mass[a];
                }
            }
            0.5 * s.weight / t_len * w + s.weight * ftf
        });
        Residual {
            force: f,
            w: 0.5 * s.weight * w,
            w_elastic: 0.5 * s.weight * w_el,
            w_forces: 0.5 * s.weight * w_forces,
            correction,
            time_derivative,
        }
    }

    /// The gradient of the global step's model per slot: `F^c + L M⁻¹ F^l`, each slot's sums
    /// taken in sample order.
    fn model_gradient(&self, residuals: &[Residual]) -> Vec<Vec<Point>> {
        let el = self.elastic;
        let n = el.node_count();
        (0..self.slots.count())
            .into_par_iter()
            .map(|slot| {
                let (mut fc, mut fl) = (vec![[0.0; 3]; n], vec![[0.0; 3]; n]);
                for (s, r) in self.samples.iter().zip(residuals) {
                    let f = &r.force;
                    let (cs, ls) = self.slot_coefficients(s, slot);
                    if cs == 0.0 && ls == 0.0 {
                        continue;
                    }
                    let (cs, ls) = (s.weight * cs, s.weight * ls);
                    for a in 0..n {
                        for d in 0..3 {
                            fc[a][d] += cs * f[a][d];
                            fl[a][d] += ls * f[a][d] / el.mass[a];
                        }
                    }
                }
                let mut lfl = vec![[0.0; 3]; n];
                el.stiffness.mul_points_sequential(&fl, &mut lfl);
                fc.iter().zip(&lfl).map(|(a, b)| crate::algorithms::geometry::add(*a, *b)).collect::<Vec<Point>>()
            })
            .collect()
    }

    /// The exact gradient per slot: the model's, minus `Σ_s dτ_s l_σ J DP_s[dF(M⁻¹ f_s)]`.
    fn exact_gradient(&self, gradient: &[Vec<Point>], residuals: &[Residual]) -> Vec<Vec<Point>> {
        (0..self.slots.count())
            .into_par_iter()
            .map(|slot| {
                let mut g = gradient[slot].clone();
                for (s, r) in self.samples.iter().zip(residuals) {
                    let (_, l) = self.slot_coefficients(s, slot);
                    if l == 0.0 {
                        continue;
                    }
                    let z = r.correction.as_ref().expect("computed with the Jacobians");
                    for (ga, za) in g.iter_mut().zip(z) {
                        for d in 0..3 {
                            ga[d] -= s.weight * l * za[d];
                        }
                    }
                }
                g
            })
            .collect()
    }
}
