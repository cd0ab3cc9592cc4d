//! A tet body for projective dynamics: lumped mass, the constant matrices `L` and `J`, and the
//! local step.
//!
//! Per tet `e` with rest edge matrix `Dm`, the deformation gradient is `F = Σ_a x_a g_aᵀ` where
//! `g_a` are the rest gradients of the linear shape functions (rows of `Dm⁻¹`, and minus their
//! sum for the first vertex). The elastic energy is
//!
//! ```text
//! E(x) = Σ_e V_e/2 (k_strain |F - R(F)|² + k_volume |F - D(F)|²)
//!      = Σ_e w_e/2 |F - P_e|² + const,   w_e = V_e (k_strain + k_volume)
//! ```
//!
//! with `P_e` the blended projection of [`super::projection::project`]. Hence
//! `∇E = L x - J p` with `L_ab = Σ_e w_e g_a·g_b` (constant) and `(J p)_a = Σ_e w_e P_e g_a`.

use rayon::prelude::*;

use super::csr::Csr;
use super::lanes::{Lanes, BATCH, M3};
use super::mat3::{self, Mat3};
#[cfg(doc)]
use super::projection::project;
use super::projection::{
    project_batch, project_forces, project_with_jacobian_batch, project_with_jacobian_extend, project_with_jacobian_lanes_into, volume_preserving,
    JacobianBatch, ProjectionJacobian,
};
use super::svd3::svd3;
use crate::algorithms::geometry::{Point, TetMesh};
use crate::support::error::{Error, Result};

/// The elastic constants of a body, per unit rest volume.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Material {
    /// Strain (as-rigid-as-possible) constraint weight `k_strain`.
    pub stiffness: f64,
    /// Volume-preservation constraint weight `k_volume`.
    pub volume: f64,
    /// Mass density, lumped to the nodes.
    pub density: f64,
}

/// A tet body ready for projective dynamics (see the module documentation).
#[derive(Debug, Clone)]
pub struct Elastic {
    /// Node indices of each tet (positively oriented at rest).
    pub tets: Vec<[u32; 4]>,
    /// Rest positions of the nodes (used to order the global solves geometrically).
    pub rest: Vec<Point>,
    /// Rest shape-function gradients `g_a` per tet.
    pub grads: Vec<[[f64; 3]; 4]>,
    /// Rest volumes.
    pub volumes: Vec<f64>,
    /// Constraint weight `w_e = V_e (k_strain + k_volume)`.
    pub weights: Vec<f64>,
    /// Strain constraint weight per unit rest volume.
    pub k_strain: f64,
    /// Volume constraint weight per unit rest volume.
    pub k_volume: f64,
    /// Lumped nodal masses `m_a = Σ_e ρ V_e / 4`.
    pub mass: Vec<f64>,
    /// `L`, symmetric positive semidefinite, constants in its null space.
    pub stiffness: Csr,
    /// For each node, the (tet, local vertex) pairs it belongs to, by increasing tet:
    /// `incidence[incidence_ptr[a]..incidence_ptr[a + 1]]`. Lets `J p` be a parallel gather.
    incidence_ptr: Vec<usize>,
    incidence: Vec<(u32, u8)>,
}

impl Elastic {
    /// Build from the rest mesh. A tet with (near) zero rest volume is an error: its
    /// gradients do not exist.
    pub fn new(mesh: &TetMesh, material: &Material) -> Result<Elastic> {
        let n = mesh.positions.len();
        let diag = crate::algorithms::geometry::bbox_diagonal(&mesh.positions);
        let mut grads = Vec::with_capacity(mesh.tets.len());
        let mut volumes = Vec::with_capacity(mesh.tets.len());
        for (e, tet) in mesh.tets.iter().enumerate() {
            let [x0, x1, x2, x3] = tet.map(|i| mesh.positions[i as usize]);
            let cols = [crate::algorithms::geometry::sub(x1, x0), crate::algorithms::geometry::sub(x2, x0), crate::algorithms::geometry::sub(x3, x0)];
            let dm = [[cols[0][0], cols[1][0], cols[2][0]], [cols[0][1], cols[1][1], cols[2][1]], [cols[0][2], cols[1][2], cols[2][2]]];
            let volume = mat3::det(&dm) / 6.0;
            let inv = mat3::inverse(&dm).filter(|_| volume > 1e-12 * diag * diag * diag).ok_or_else(|| {
                Error::general(
                    format!("tet {e} (nodes {tet:?}) has rest volume {volume:e}: it is flat or inverted"),
                    "remesh the body (raise [tet] quality or repair the input mesh)",
                )
            })?;
            // g_k = row k of Dm⁻¹ (k = 1..3), g_0 = -(g_1 + g_2 + g_3).
            let (g1, g2, g3) = (inv[0], inv[1], inv[2]);
            let g0 = [-(g1[0] + g2[0] + g3[0]), -(g1[1] + g2[1] + g3[1]), -(g1[2] + g2[2] + g3[2])];
            grads.push([g0, g1, g2, g3]);
            volumes.push(volume);
        }
        let k_total = material.stiffness + material.volume;
        let weights: Vec<f64> = volumes.iter().map(|v| v * k_total).collect();
        let mut mass = vec![0.0; n];
        for (tet, v) in mesh.tets.iter().zip(&volumes) {
            for &a in tet {
                mass[a as usize] += material.density * v / 4.0;
            }
        }
        if let Some(a) = mass.iter().position(|&m| m <= 0.0) {
            return Err(Error::general(format!("node {a} belongs to no tet, so it has no mass"), "remove unreferenced nodes from the tet mesh"));
        }
        let mut triplets = Vec::with_capacity(16 * mesh.tets.len());
        for ((tet, g), w) in mesh.tets.iter().zip(&grads).zip(&weights) {
            for a in 0..4 {
                for b in 0..4 {
                    triplets.push((tet[a], tet[b], w * crate::algorithms::geometry::dot(g[a], g[b])));
                }
            }
        }
        let stiffness = Csr::from_triplets(n, triplets);
        let mut counts = vec![0usize; n + 1];
        for tet in &mesh.tets {
            for &a in tet {
                counts[a as usize + 1] += 1;
            }
        }
        for a in 0..n {
            counts[a + 1] += counts[a];
        }
        let mut fill = counts.clone();
        let mut incidence = vec![(0u32, 0u8); counts[n]];
        for (e, tet) in mesh.tets.iter().enumerate() {
            for (local, &a) in tet.iter().enumerate() {
                incidence[fill[a as usize]] = (e as u32, local as u8);
                fill[a as usize] += 1;
            }
        }
        Ok(Elastic {
            tets: mesh.tets.clone(),
            rest: mesh.positions.clone(),
            grads,
            volumes,
            weights,
            k_strain: material.stiffness,
            k_volume: material.volume,
            mass,
            stiffness,
            incidence_ptr: counts,
            incidence,
        })
    }

    /// Nodes of the body.
    pub fn node_count(&self) -> usize {
        self.mass.len()
    }

    /// Tets of the body.
    pub fn tet_count(&self) -> usize {
        self.tets.len()
    }

    /// Share of the strain constraint in the blended projection target.
    pub fn strain_share(&self) -> f64 {
        self.k_strain / (self.k_strain + self.k_volume)
    }

    /// Deformation gradient of tet `e` at positions `x`.
    #[inline]
    pub fn deformation_gradient(&self, e: usize, x: &[Point]) -> Mat3 {
        let tet = &self.tets[e];
        let g = &self.grads[e];
        let mut f = [[0.0; 3]; 3];
        for a in 0..4 {
            let p = x[tet[a] as usize];
            for i in 0..3 {
                for j in 0..3 {
                    f[i][j] += p[i] * g[a][j];
                }
            }
        }
        f
    }

    /// The corner gradients and weights of the batch of [`BATCH`] tets from `first`: the body's
    /// arrays in place for a whole batch; the last, partial one copied into `pad`, whose entries
    /// past the last tet stay as they are (zeros as the callers make it).
    pub(crate) fn batch_grads_weights<'a>(
        &'a self,
        first: usize,
        pad: &'a mut ([[[f64; 3]; 4]; BATCH], [f64; BATCH]),
    ) -> (&'a [[[f64; 3]; 4]; BATCH], &'a [f64; BATCH]) {
        match (self.grads[first..].first_chunk::<BATCH>(), self.weights[first..].first_chunk::<BATCH>()) {
            (Some(g), Some(w)) => (g, w),
            _ => {
                let lanes = self.grads.len() - first;
                pad.0[..lanes].copy_from_slice(&self.grads[first..]);
                pad.1[..lanes].copy_from_slice(&self.weights[first..]);
                (&pad.0, &pad.1)
            }
        }
    }

    /// [`Elastic::deformation_gradient`] of the [`BATCH`] tets from `first` at `x`, and at `y`
    /// when given, written straight into lanes (the same sums; lanes past the last tet hold the
    /// identity at `x` and zero at `y`). One read of each tet's nodes and gradients for both: a
    /// tet along a line of positions (the timing derivatives' `x` and `x_T`); no transposition
    /// into lanes after the fact.
    #[inline]
    pub(crate) fn deformation_gradient_lanes(&self, first: usize, x: &[Point], y: Option<(&[Point], &mut M3<BATCH>)>, f: &mut M3<BATCH>) {
        let lanes = BATCH.min(self.tets.len() - first);
        let (zero, one) = (Lanes::splat(0.0), Lanes::splat(1.0));
        *f = [[one, zero, zero], [zero, one, zero], [zero, zero, one]];
        // Each tet's sums in registers, then one store per entry.
        match y {
            Some((y, h)) => {
                *h = [[zero; 3]; 3];
                for l in 0..lanes {
                    let (fl, hl) = self.deformation_gradients_at(first + l, x, y);
                    for i in 0..3 {
                        for j in 0..3 {
                            f[i][j].0[l] = fl[i][j];
                            h[i][j].0[l] = hl[i][j];
                        }
                    }
                }
            }
            None => {
                for l in 0..lanes {
                    let fl = self.deformation_gradient(first + l, x);
                    for i in 0..3 {
                        for j in 0..3 {
                            f[i][j].0[l] = fl[i][j];
                        }
                    }
                }
            }
        }
    }

    /// [`Elastic::deformation_gradient`] of tet `e` at `x` and at `y`, reading the tet once.
    #[inline(always)]
    fn deformation_gradients_at(&self, e: usize, x: &[Point], y: &[Point]) -> (Mat3, Mat3) {
        let (tet, g) = (&self.tets[e], &self.grads[e]);
        let (mut f, mut h) = ([[0.0; 3]; 3], [[0.0; 3]; 3]);
        for a in 0..4 {
            let (p, q) = (x[tet[a] as usize], y[tet[a] as usize]);
            for i in 0..3 {
                for j in 0..3 {
                    f[i][j] += p[i] * g[a][j];
                    h[i][j] += q[i] * g[a][j];
                }
            }
        }
        (f, h)
    }

    /// Deformation gradients of the [`BATCH`] tets from `first` (the identity past the last
    /// tet: those lanes are computed and dropped).
    #[inline]
    fn deformation_gradients(&self, first: usize, x: &[Point]) -> [Mat3; BATCH] {
        let mut f = [mat3::IDENTITY; BATCH];
        for (l, fl) in f.iter_mut().enumerate().take(self.tets.len().saturating_sub(first)) {
            *fl = self.deformation_gradient(first + l, x);
        }
        f
    }

    /// The local step: every tet's projection target at positions `x`, in parallel, [`BATCH`]
    /// tets per call of the vectorized projection (bit-identical to [`project`] per tet).
    pub fn local_step(&self, x: &[Point], targets: &mut [Mat3]) {
        let share = self.strain_share();
        targets.par_chunks_mut(BATCH).enumerate().with_min_len(4).for_each(|(c, out)| {
            let p = project_batch(&self.deformation_gradients(c * BATCH, x), share);
            out.copy_from_slice(&p[..out.len()]);
        });
    }

    /// The local step with the derivative of every projection (for exact Hessian products).
    pub fn local_step_with_jacobians(&self, x: &[Point], targets: &mut [Mat3], jacobians: &mut [ProjectionJacobian]) {
        let share = self.strain_share();
        targets.par_chunks_mut(BATCH).zip(jacobians.par_chunks_mut(BATCH)).enumerate().with_min_len(4).for_each(|(c, (out, jac))| {
            let pj = project_with_jacobian_batch(&self.deformation_gradients(c * BATCH, x), share);
            for (l, (p, j)) in pj.into_iter().take(out.len()).enumerate() {
                (out[l], jac[l]) = (p, j);
            }
        });
    }

    /// [`Elastic::local_step`] on the calling thread, into a new vector (for callers that are
    /// already parallel, e.g. over samples): no zero-filled buffer, no nested tasks.
    pub fn local_step_sequential(&self, x: &[Point]) -> Vec<Mat3> {
        let mut targets = Vec::new();
        self.local_step_sequential_into(x, &mut targets);
        targets
    }

    /// [`Elastic::local_step_with_jacobians`] on the calling thread, into new vectors.
    pub fn local_step_with_jacobians_sequential(&self, x: &[Point]) -> (Vec<Mat3>, Vec<ProjectionJacobian>) {
        let (mut targets, mut jacobians) = (Vec::new(), Vec::new());
        self.local_step_with_jacobians_sequential_into(x, &mut targets, &mut jacobians);
        (targets, jacobians)
    }

    /// [`Elastic::local_step_sequential`] into `targets` (cleared first; its capacity is
    /// reused, so an iteration that keeps its buffers allocates nothing). Same bytes.
    pub fn local_step_sequential_into(&self, x: &[Point], targets: &mut Vec<Mat3>) {
        self.local_step_scattered(x, targets, None);
    }

    /// [`Elastic::local_step_sequential_into`], with `jp = J p` of its targets scattered batch by
    /// batch when `jp` is given.
    fn local_step_scattered(&self, x: &[Point], targets: &mut Vec<Mat3>, mut jp: Option<&mut [Point]>) {
        let (share, count) = (self.strain_share(), self.tet_count());
        targets.clear();
        targets.reserve(count);
        if let Some(jp) = jp.as_deref_mut() {
            jp.fill([0.0; 3]);
        }
        for first in (0..count).step_by(BATCH) {
            let p = project_batch(&self.deformation_gradients(first, x), share);
            let p = &p[..BATCH.min(count - first)];
            targets.extend_from_slice(p);
            if let Some(jp) = jp.as_deref_mut() {
                self.scatter_targets(first, p, jp);
            }
        }
    }

    /// [`Elastic::local_step_with_jacobians_sequential`] into `targets` and `jacobians`
    /// (cleared first, their capacity reused). Same bytes.
    pub(crate) fn local_step_with_jacobians_sequential_into(&self, x: &[Point], targets: &mut Vec<Mat3>, jacobians: &mut Vec<ProjectionJacobian>) {
        let (share, count) = (self.strain_share(), self.tet_count());
        targets.clear();
        jacobians.clear();
        targets.reserve(count);
        jacobians.reserve(count);
        for first in (0..count).step_by(BATCH) {
            project_with_jacobian_extend(&self.deformation_gradients(first, x), share, count - first, targets, jacobians);
        }
    }

    /// [`Elastic::local_step_with_jacobians`] with the Jacobians kept in lane layout, one
    /// [`JacobianBatch`] per [`BATCH`] tets (`jacobians.len()` is `tet_count().div_ceil(BATCH)`).
    /// The same bytes, tet by tet.
    pub fn local_step_with_jacobian_batches(&self, x: &[Point], targets: &mut [Mat3], jacobians: &mut [JacobianBatch]) {
        let share = self.strain_share();
        targets.par_chunks_mut(BATCH).zip(jacobians.par_iter_mut()).enumerate().with_min_len(4).for_each(|(c, (out, jac))| {
            let mut f = [[Lanes::splat(0.0); 3]; 3];
            self.deformation_gradient_lanes(c * BATCH, x, None, &mut f);
            project_with_jacobian_lanes_into(&f, share, out, jac);
        });
    }

    /// [`Elastic::local_step_with_jacobian_batches`] on the calling thread, into `targets` and
    /// `jacobians` (resized; their capacity reused, so an iteration that keeps its buffers
    /// allocates nothing). Same bytes.
    pub fn local_step_with_jacobian_batches_sequential_into(&self, x: &[Point], targets: &mut Vec<Mat3>, jacobians: &mut Vec<JacobianBatch>) {
        self.local_step_with_jacobian_batches_scattered(x, targets, jacobians, None);
    }

    /// [`Elastic::local_step_with_jacobian_batches_sequential_into`], with `jp = J p` of its
    /// targets scattered batch by batch when `jp` is given.
    fn local_step_with_jacobian_batches_scattered(
        &self,
        x: &[Point],
        targets: &mut Vec<Mat3>,
        jacobians: &mut Vec<JacobianBatch>,
        mut jp: Option<&mut [Point]>,
    ) {
        let (share, count) = (self.strain_share(), self.tet_count());
        targets.resize(count, [[0.0; 3]; 3]);
        jacobians.resize_with(count.div_ceil(BATCH), JacobianBatch::default);
        if let Some(jp) = jp.as_deref_mut() {
            jp.fill([0.0; 3]);
        }
        let mut f = [[Lanes::splat(0.0); 3]; 3];
        for (c, (out, jac)) in targets.chunks_mut(BATCH).zip(jacobians.iter_mut()).enumerate() {
            self.deformation_gradient_lanes(c * BATCH, x, None, &mut f);
            project_with_jacobian_lanes_into(&f, share, out, jac);
            if let Some(jp) = jp.as_deref_mut() {
                self.scatter_targets(c * BATCH, out, jp);
            }
        }
    }

    /// [`Elastic::local_step_sequential_into`] and `jp = J p` of its targets
    /// ([`Elastic::apply_j_sequential`]) in the same pass, as
    /// [`Elastic::local_step_with_jacobian_batches_and_forces_sequential_into`]. The bytes of the two.
    pub(crate) fn local_step_and_forces_sequential_into(&self, x: &[Point], targets: &mut Vec<Mat3>, jp: &mut [Point]) {
        self.local_step_scattered(x, targets, Some(jp));
    }

    /// `jp += J p` of the tets from `first` with targets `p`, in tet order.
    #[inline]
    fn scatter_targets(&self, first: usize, p: &[Mat3], jp: &mut [Point]) {
        for (e, p) in (first..).zip(p) {
            let w = self.weights[e];
            for (&a, g) in self.tets[e].iter().zip(&self.grads[e]) {
                let o = &mut jp[a as usize];
                for i in 0..3 {
                    o[i] += w * (p[i][0] * g[0] + p[i][1] * g[1] + p[i][2] * g[2]);
                }
            }
        }
    }

    /// [`Elastic::local_step_with_jacobian_batches_sequential_into`] and `jp = J p` of its
    /// targets ([`Elastic::apply_j_sequential`]) in the same pass: each batch's targets go into
    /// `jp` right after their projection, while they and the batch's gradients are in cache,
    /// instead of in a second pass over every tet. The bytes of the two (every node sums its
    /// tets in increasing order from zero).
    pub fn local_step_with_jacobian_batches_and_forces_sequential_into(
        &self,
        x: &[Point],
        targets: &mut Vec<Mat3>,
        jacobians: &mut Vec<JacobianBatch>,
        jp: &mut [Point],
    ) {
        self.local_step_with_jacobian_batches_scattered(x, targets, jacobians, Some(jp));
    }

    /// `out = J DP[dF(u)]` from the projection Jacobians of every tet in lane layout, on the
    /// calling thread: the part of the elastic Hessian product `∇²E u` that the projections
    /// contribute. The bytes of [`Elastic::apply_j_sequential`] of the per-tet products
    /// [`ProjectionJacobian::apply`] (the same sums in the same order; tested).
    pub(crate) fn apply_jacobians_sequential(&self, jacobians: &[JacobianBatch], u: &[Point], out: &mut [Point]) {
        out.fill([0.0; 3]);
        let count = self.tet_count();
        let mut df = [[Lanes::splat(0.0); 3]; 3];
        for (c, jac) in jacobians.iter().enumerate().take(count.div_ceil(BATCH)) {
            let first = c * BATCH;
            self.deformation_gradient_lanes(first, u, None, &mut df);
            let dp = jac.apply(&df);
            for (l, e) in (first..count.min(first + BATCH)).enumerate() {
                let w = self.weights[e];
                for (&a, g) in self.tets[e].iter().zip(&self.grads[e]) {
                    let o = &mut out[a as usize];
                    for i in 0..3 {
                        o[i] += w * (dp[i][0].0[l] * g[0] + dp[i][1].0[l] * g[1] + dp[i][2].0[l] * g[2]);
                    }
                }
            }
        }
    }

    /// `out = ∇²E(x) u = L u - J DP[dF(u)]`, the exact Hessian of the elastic energy applied to
    /// `u`, from the projection Jacobians at `x`.
    pub fn hessian_apply(&self, jacobians: &[ProjectionJacobian], u: &[Point], out: &mut [Point]) {
        let dp: Vec<Mat3> = jacobians.par_iter().enumerate().with_min_len(64).map(|(e, j)| j.apply(&self.deformation_gradient(e, u))).collect();
        let mut jdp = vec![[0.0; 3]; u.len()];
        self.apply_j(&dp, &mut jdp);
        self.stiffness.mul_points(u, out);
        for (o, d) in out.iter_mut().zip(&jdp) {
            *o = crate::algorithms::geometry::sub(*o, *d);
        }
    }

    /// `out = J p`: per node, `Σ w_e P_e g_a` over its tets (a parallel gather, summed in tet
    /// order, so results do not depend on the thread count).
    pub fn apply_j(&self, targets: &[Mat3], out: &mut [Point]) {
        out.par_iter_mut().enumerate().with_min_len(128).for_each(|(a, o)| {
            let mut acc = [0.0; 3];
            for &(e, local) in &self.incidence[self.incidence_ptr[a]..self.incidence_ptr[a + 1]] {
                let (p, g, w) = (&targets[e as usize], &self.grads[e as usize][local as usize], self.weights[e as usize]);
                for i in 0..3 {
                    acc[i] += w * (p[i][0] * g[0] + p[i][1] * g[1] + p[i][2] * g[2]);
                }
            }
            *o = acc;
        });
    }

    /// [`Elastic::apply_j`] on the calling thread, as a scatter in tet order: it streams the
    /// targets and gradients instead of gathering them per node, for callers that are already
    /// parallel (one sample each). Every node sums its tets in increasing order starting from
    /// zero, as the gather does, so the bytes are the same.
    pub fn apply_j_sequential(&self, targets: &[Mat3], out: &mut [Point]) {
        self.apply_j_sequential_with(|e| targets[e], out);
    }

    /// [`Elastic::apply_j_sequential`] with the target of tet `e` computed by `target(e)`, once
    /// per tet in increasing order.
    pub fn apply_j_sequential_with(&self, mut target: impl FnMut(usize) -> Mat3, out: &mut [Point]) {
        out.fill([0.0; 3]);
        for e in 0..self.tet_count() {
            self.scatter_targets(e, &[target(e)], out);
        }
    }

    /// `J p(x)` with fresh projections, on the calling thread, without storing the targets:
    /// the bytes of `apply_j_sequential(&local_step_sequential(x))` (the projection and its
    /// node forces in one vectorized kernel, `project_forces`).
    pub(crate) fn projected_forces_sequential(&self, x: &[Point], out: &mut [Point]) {
        out.fill([0.0; 3]);
        let (share, count) = (self.strain_share(), self.tet_count());
        let mut forces = [[Lanes::splat(0.0); 3]; 4];
        let mut f = [[Lanes::splat(0.0); 3]; 3];
        let mut last = ([[[0.0; 3]; 4]; BATCH], [0.0; BATCH]);
        for first in (0..count).step_by(BATCH) {
            let lanes = BATCH.min(count - first);
            self.deformation_gradient_lanes(first, x, None, &mut f);
            let (grads, weights) = self.batch_grads_weights(first, &mut last);
            project_forces(&f, share, grads, weights, &mut forces);
            for (l, e) in (first..first + lanes).enumerate() {
                for (&a, force) in self.tets[e].iter().zip(&forces) {
                    let o = &mut out[a as usize];
                    for i in 0..3 {
                        o[i] += force[i].0[l];
                    }
                }
            }
        }
    }

    /// `∇E = L x - J p(x)`, the negated elastic force, with fresh projections.
    pub fn energy_gradient(&self, x: &[Point]) -> Vec<Point> {
        let mut targets = vec![[[0.0; 3]; 3]; self.tet_count()];
        self.local_step(x, &mut targets);
        let (mut lx, mut jp) = (vec![[0.0; 3]; x.len()], vec![[0.0; 3]; x.len()]);
        self.stiffness.mul_points(x, &mut lx);
        self.apply_j(&targets, &mut jp);
        lx.iter().zip(&jp).map(|(a, b)| crate::algorithms::geometry::sub(*a, *b)).collect()
    }

    /// Elastic energy `Σ V_e/2 (k_s |F - R|² + k_v |F - D|²)`.
    pub fn energy(&self, x: &[Point]) -> f64 {
        (0..self.tet_count())
            .into_par_iter()
            .with_min_len(64)
            .map(|e| {
                let f = self.deformation_gradient(e, x);
                let d = svd3(&f);
                let r = mat3::mul_transpose(&d.u, &d.v);
                let dv = mat3::scaled_product(&d.u, volume_preserving(d.sigma), &d.v);
                0.5 * self.volumes[e] * (self.k_strain * mat3::distance(&f, &r).powi(2) + self.k_volume * mat3::distance(&f, &dv).powi(2))
            })
            .collect::<Vec<f64>>()
            .iter()
            .sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::algorithms::physics::projection::project_with_jacobian;
    use crate::algorithms::testing::cube_mesh;

    fn material() -> Material {
        Material { stiffness: 70.0, volume: 30.0, density: 2.0 }
    }

    fn rotate(p: Point, angle: f64) -> Point {
        let (s, c) = angle.sin_cos();
        [c * p[0] - s * p[2], p[1], s * p[0] + c * p[2]]
    }

    #[test]
    fn mass_sums_to_density_times_volume() {
        let el = Elastic::new(&cube_mesh(3), &material()).unwrap();
        assert!((el.mass.iter().sum::<f64>() - 2.0).abs() < 1e-12);
        assert!((el.volumes.iter().sum::<f64>() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn rigid_motion_has_no_energy_and_no_force() {
        let mesh = cube_mesh(3);
        let el = Elastic::new(&mesh, &material()).unwrap();
        let x: Vec<Point> = mesh.positions.iter().map(|&p| crate::algorithms::geometry::add(rotate(p, 1.1), [0.3, -2.0, 5.0])).collect();
        assert!(el.energy(&x) < 1e-20);
        let g = el.energy_gradient(&x);
        assert!(
            g.iter().all(|v| crate::algorithms::geometry::norm(*v) < 1e-12),
            "{:?}",
            g.iter().map(|v| crate::algorithms::geometry::norm(*v)).fold(0.0, f64::max)
        );
    }

    #[test]
    fn stiffness_annihilates_constants_and_is_symmetric() {
        let el = Elastic::new(&cube_mesh(2), &material()).unwrap();
        let n = el.node_count();
        let mut y = vec![[0.0; 3]; n];
        el.stiffness.mul_points(&vec![[1.0, -2.0, 3.0]; n], &mut y);
        assert!(y.iter().all(|v| crate::algorithms::geometry::norm(*v) < 1e-12));
        for i in 0..n {
            for (j, v) in el.stiffness.row(i) {
                assert!((el.stiffness.get(j, i) - v).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn energy_gradient_matches_finite_differences() {
        // ∇E = Lx - Jp(x) is exact (envelope theorem): check it against central differences.
        let mesh = cube_mesh(2);
        let el = Elastic::new(&mesh, &material()).unwrap();
        let x: Vec<Point> =
            mesh.positions.iter().map(|p| [p[0] * 1.2 + 0.1 * p[1], p[1] * 0.8 + 0.05 * p[2] * p[0], p[2] + 0.2 * p[0] * p[1]]).collect();
        let g = el.energy_gradient(&x);
        let h = 1e-6;
        let mut worst: f64 = 0.0;
        let scale = g.iter().map(|v| crate::algorithms::geometry::norm(*v)).fold(0.0, f64::max);
        for a in (0..x.len()).step_by(3) {
            for d in 0..3 {
                let (mut xp, mut xm) = (x.clone(), x.clone());
                xp[a][d] += h;
                xm[a][d] -= h;
                let fd = (el.energy(&xp) - el.energy(&xm)) / (2.0 * h);
                worst = worst.max((fd - g[a][d]).abs() / scale);
            }
        }
        assert!(worst < 1e-6, "relative gradient error {worst}");
    }

    #[test]
    fn batched_local_step_matches_the_projection_of_every_tet() {
        // 3³ cells x 6 = 162 tets: not a multiple of the batch, so the last batch is padded.
        let mesh = cube_mesh(3);
        let el = Elastic::new(&mesh, &material()).unwrap();
        assert_ne!(el.tet_count() % BATCH, 0);
        let x: Vec<Point> =
            mesh.positions.iter().map(|p| [p[0] * 1.3 - 0.4 * p[2] * p[1], -p[1] + 0.2 * p[0], p[2] * 0.6 + 0.5 * p[0] * p[0]]).collect();
        let (mut targets, mut jac) = (vec![[[0.0; 3]; 3]; el.tet_count()], vec![ProjectionJacobian::default(); el.tet_count()]);
        el.local_step(&x, &mut targets);
        let mut with_jacobians = vec![[[0.0; 3]; 3]; el.tet_count()];
        el.local_step_with_jacobians(&x, &mut with_jacobians, &mut jac);
        assert_eq!(el.local_step_sequential(&x), targets);
        assert_eq!(el.local_step_with_jacobians_sequential(&x), (with_jacobians.clone(), jac.clone()));
        // The Jacobians in lane layout: the same targets and, lane by lane, the same Jacobians;
        // their products the bytes of the per-tet ones scattered in tet order.
        let batches = el.tet_count().div_ceil(BATCH);
        let (mut lane_targets, mut lane_jac) = (vec![[[0.0; 3]; 3]; el.tet_count()], vec![JacobianBatch::default(); batches]);
        el.local_step_with_jacobian_batches(&x, &mut lane_targets, &mut lane_jac);
        let (mut seq_targets, mut seq_jac) = (vec![[[1.0; 3]; 3]; 3], vec![JacobianBatch::default(); 1]);
        el.local_step_with_jacobian_batches_sequential_into(&x, &mut seq_targets, &mut seq_jac);
        assert_eq!((&lane_targets, &lane_jac), (&with_jacobians, &seq_jac));
        assert_eq!(seq_targets, with_jacobians);
        for e in 0..el.tet_count() {
            assert_eq!(lane_jac[e / BATCH].lane(e % BATCH), jac[e], "tet {e}");
        }
        let u: Vec<Point> = (0..x.len()).map(|a| [(a as f64 * 0.37).sin(), (a as f64 * 0.91).cos(), 0.5 - (a % 3) as f64 * 0.4]).collect();
        let (mut lanes, mut per_tet) = (vec![[1.0; 3]; x.len()], vec![[0.0; 3]; x.len()]);
        el.apply_jacobians_sequential(&lane_jac, &u, &mut lanes);
        let products: Vec<Mat3> = (0..el.tet_count()).map(|e| jac[e].apply(&el.deformation_gradient(e, &u))).collect();
        el.apply_j_sequential(&products, &mut per_tet);
        assert_eq!(lanes, per_tet);
        for e in 0..el.tet_count() {
            let f = el.deformation_gradient(e, &x);
            assert_eq!(targets[e], crate::algorithms::physics::projection::project(&f, el.strain_share()), "tet {e}");
            assert_eq!((with_jacobians[e], jac[e]), project_with_jacobian(&f, el.strain_share()), "tet {e}");
        }
    }

    #[test]
    fn sequential_products_give_the_bytes_of_the_parallel_ones() {
        let mesh = cube_mesh(3);
        let el = Elastic::new(&mesh, &material()).unwrap();
        let x: Vec<Point> = mesh.positions.iter().map(|p| [p[0] * 1.1 + 0.3 * p[2], p[1] - 0.2 * p[0] * p[2], p[2] * 0.9]).collect();
        let mut targets = vec![[[0.0; 3]; 3]; el.tet_count()];
        el.local_step(&x, &mut targets);
        let n = x.len();
        let (mut a, mut b) = (vec![[0.0; 3]; n], vec![[1.0; 3]; n]);
        el.apply_j(&targets, &mut a);
        el.apply_j_sequential(&targets, &mut b);
        assert_eq!(a, b);
        // Fresh projections straight to forces (cube_mesh(3) has a partial last batch).
        assert_ne!(el.tet_count() % BATCH, 0);
        el.projected_forces_sequential(&x, &mut b);
        assert_eq!(a, b);
        // The local step with the Jacobians and J p in one pass: the bytes of the two passes
        // (into buffers holding other values).
        let (mut t, mut j) = (Vec::new(), Vec::new());
        el.local_step_with_jacobian_batches_sequential_into(&x, &mut t, &mut j);
        let (mut fused_t, mut fused_j) = (vec![[[2.0; 3]; 3]; 1], vec![JacobianBatch::default(); 50]);
        b.fill([3.0; 3]);
        el.local_step_with_jacobian_batches_and_forces_sequential_into(&x, &mut fused_t, &mut fused_j, &mut b);
        assert_eq!((&fused_t, &fused_j, &b), (&t, &j, &a));
        let mut fused_t = vec![[[2.0; 3]; 3]; 3];
        b.fill([3.0; 3]);
        el.local_step_and_forces_sequential_into(&x, &mut fused_t, &mut b);
        assert_eq!((&fused_t, &b), (&targets, &a));
        el.stiffness.mul_points(&x, &mut a);
        el.stiffness.mul_points_sequential(&x, &mut b);
        assert_eq!(a, b);
    }

    #[test]
    fn hessian_product_matches_finite_differences() {
        let mesh = cube_mesh(2);
        let el = Elastic::new(&mesh, &material()).unwrap();
        let x: Vec<Point> = mesh.positions.iter().map(|p| [p[0] * 1.3 + 0.2 * p[1] * p[2], p[1] * 0.7, p[2] + 0.3 * p[0] * p[0]]).collect();
        let u: Vec<Point> = (0..x.len()).map(|a| [(a as f64 * 0.37).sin(), (a as f64 * 0.91).cos(), 0.5 - (a % 3) as f64 * 0.4]).collect();
        let (mut targets, mut jac) = (
            vec![[[0.0; 3]; 3]; el.tet_count()],
            vec![project_with_jacobian(&[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], 0.5).1; el.tet_count()],
        );
        el.local_step_with_jacobians(&x, &mut targets, &mut jac);
        let mut hu = vec![[0.0; 3]; x.len()];
        el.hessian_apply(&jac, &u, &mut hu);
        let h = 1e-6;
        let shifted = |s: f64| {
            x.iter().zip(&u).map(|(p, d)| crate::algorithms::geometry::add(*p, crate::algorithms::geometry::scale(*d, s))).collect::<Vec<_>>()
        };
        let (gp, gm) = (el.energy_gradient(&shifted(h)), el.energy_gradient(&shifted(-h)));
        let scale = hu.iter().map(|v| crate::algorithms::geometry::norm(*v)).fold(0.0, f64::max);
        for a in 0..x.len() {
            for d in 0..3 {
                let fd = (gp[a][d] - gm[a][d]) / (2.0 * h);
                assert!((fd - hu[a][d]).abs() < 1e-6 * scale, "node {a}: {fd} vs {}", hu[a][d]);
            }
        }
    }

    #[test]
    fn flat_tet_is_an_error() {
        let mesh = TetMesh { positions: vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 1.0, 0.0]], tets: vec![[0, 1, 2, 3]] };
        let e = Elastic::new(&mesh, &material()).unwrap_err().to_string();
        assert!(e.contains("tet 0") && e.contains("flat or inverted"), "{e}");
    }
}
