//! The projection target along a line of deformation gradients: `P(F + τG)` and its first
//! and second derivatives in `τ` at `τ = 0`.
//!
//! Why: when a keyframe interval length `T` changes, a sample's positions move along a line
//! (`x` is affine in `T`), so its deformation gradients do too, and the exact second
//! derivative of W in `T` needs `d²P/dτ²` on that line (the first derivative alone is
//! [`ProjectionJacobian`](super::projection::ProjectionJacobian)).
//!
//! Method: in the singular frame of `F = U Σ Vᵀ` (signed SVD), `F̃(τ) = Σ + τ G̃` with
//! `G̃ = Uᵀ G V`. Write `F̃ = R S` (R a rotation, S symmetric; `R(0) = I`, `S(0) = Σ`) and
//! `P = R Q(S)`, `Q = r I + (1 - r) S_d` where `S_d` is the volume-projected stretch
//! (eigenvalues `σ'` on `Π σ' = 1`). Everything follows from differentiating the defining
//! conditions, never an SVD derivative, so coincident singular values (the rest pose) need
//! no special case:
//!
//! - `SΩ + ΩS = (G̃ - G̃ᵀ)` for `R' = RΩ` (`SᵀR` symmetric), and the same equation with a
//!   known right-hand side for `Ω'`; at `τ = 0` it is diagonal: `(σ_i + σ_j) Ω_ij = ...`;
//! - `S' = G̃ - ΩΣ`, `S'' = (Ω² - Ω')Σ - 2ΩG̃`;
//! - the volume projection's stationarity `S_d² - S_d S = λ I` and `det S_d = 1`, differentiated
//!   once and twice: entry `(i, j)` gives `S_d'_ij (σ'_i + σ'_j - σ_j) = σ'_i S'_ij + λ' δ_ij`,
//!   and for the second derivative the right-hand side gains `2 (S_d' S')_ij - 2 (S_d'²)_ij`;
//!   `λ'`, `λ''` come from `tr(S_d⁻¹ S_d') = 0` and `tr(S_d⁻¹ S_d'') = tr((S_d⁻¹ S_d')²)`;
//! - `P' = ΩQ + Q'`, `P'' = (Ω² + Ω')Q + 2ΩQ' + Q''`, rotated back by `U · Vᵀ`.
//!
//! The stationarity conditions hold on both branches of the volume projection (including the
//! collapsed shortest axis), so the formulas do too. Like the first derivative, they are
//! singular only where `σ_i + σ_j = 0` (an inverted element with `|σ3| = σ2`), where the
//! rotation itself is not differentiable; the same bounded factor is used there.

use super::lanes::{lane, mul_lanes, to_lanes, with_widest_simd, Lanes, BATCH, M3, V3};
use super::mat3::{mul, transpose, Mat3};
use super::projection::{volume_preserving, volume_with_fallback};
#[cfg(test)]
use super::svd3::svd3;
use super::svd3::svd_lanes;
use super::svd3::Svd3;

/// `P(F)`, `dP/dτ` and `d²P/dτ²` of `τ ↦ P(F + τG)` at `τ = 0`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProjectionPath {
    /// `P(F)`.
    pub value: Mat3,
    /// `dP/dτ` at `τ = 0`.
    pub first: Mat3,
    /// `d²P/dτ²` at `τ = 0`.
    pub second: Mat3,
}

/// `1 / (σ_i + σ_j)`, bounded where the rotation is not differentiable (as in the Jacobian).
#[cfg_attr(not(test), allow(dead_code))]
#[inline]
fn inverse_pair_sum(si: f64, sj: f64) -> f64 {
    let den = si + sj;
    1.0 / if den.abs() < 1e-12 { 1e-12f64.copysign(den) } else { den }
}

/// The skew matrix `Ω` with `(σ_i + σ_j) Ω_ij = B_ij - B_ji`.
#[cfg_attr(not(test), allow(dead_code))]
#[inline]
fn skew_solve(sigma: &[f64; 3], b: &Mat3) -> Mat3 {
    let mut w = [[0.0; 3]; 3];
    for (i, j) in [(0, 1), (0, 2), (1, 2)] {
        let v = (b[i][j] - b[j][i]) * inverse_pair_sum(sigma[i], sigma[j]);
        w[i][j] = v;
        w[j][i] = -v;
    }
    w
}

/// `d/dτ` and `d²/dτ²` of the volume-projected stretch `S_d` in the singular frame, from
/// those of `S` (`ds`, `dds`, symmetric) at `S = diag(sigma)`, `S_d = diag(sp)`.
#[cfg_attr(not(test), allow(dead_code))]
fn volume_stretch_derivatives(sigma: &[f64; 3], sp: &[f64; 3], ds: &Mat3, dds: &Mat3) -> (Mat3, Mat3) {
    let a = [0, 1, 2].map(|i| 2.0 * sp[i] - sigma[i]);
    let inv_sum: f64 = (0..3).map(|i| 1.0 / (a[i] * sp[i])).sum();
    // Off-diagonal entries from equation (i, j) and (j, i), averaged: they agree exactly, and
    // the average keeps the result symmetric to the last bit.
    let off = |rhs: &dyn Fn(usize, usize) -> f64, out: &mut Mat3| {
        for (i, j) in [(0, 1), (0, 2), (1, 2)] {
            let v = 0.5 * (rhs(i, j) / (sp[i] + sp[j] - sigma[j]) + rhs(j, i) / (sp[i] + sp[j] - sigma[i]));
            out[i][j] = v;
            out[j][i] = v;
        }
    };
    let mut d1 = [[0.0; 3]; 3];
    off(&|i, j| sp[i] * ds[i][j], &mut d1);
    let dl = -(0..3).map(|i| ds[i][i] / a[i]).sum::<f64>() / inv_sum;
    for i in 0..3 {
        d1[i][i] = (sp[i] * ds[i][i] + dl) / a[i];
    }
    let (d1ds, d1d1) = (mul(&d1, ds), mul(&d1, &d1));
    let rhs2 = |i: usize, j: usize| sp[i] * dds[i][j] + 2.0 * d1ds[i][j] - 2.0 * d1d1[i][j];
    let mut d2 = [[0.0; 3]; 3];
    off(&rhs2, &mut d2);
    // Σ_i S_d''_ii / σ'_i = Σ_ij (S_d'_ij)² / (σ'_i σ'_j), with S_d''_ii = (b_i + λ'') / a_i.
    let mut target = 0.0;
    for i in 0..3 {
        for j in 0..3 {
            target += d1[i][j] * d1[i][j] / (sp[i] * sp[j]);
        }
    }
    let b = [0, 1, 2].map(|i| rhs2(i, i));
    let ddl = (target - (0..3).map(|i| b[i] / (a[i] * sp[i])).sum::<f64>()) / inv_sum;
    for i in 0..3 {
        d2[i][i] = (b[i] + ddl) / a[i];
    }
    (d1, d2)
}

/// [`ProjectionPath`] of the blended projection (strain share `strain_share`, as in
/// [`project`](super::projection::project)) at `f` in direction `g`. The timing derivatives
/// call [`project_along_batch`]; this entry point is for tests.
#[cfg(test)]
pub(crate) fn project_along(f: &Mat3, strain_share: f64, g: &Mat3) -> ProjectionPath {
    project_along_svd(&svd3(f), strain_share, g)
}

/// `P(F + τG)` and its τ-derivatives at 0 from the signed SVD of `F`: the definition, one
/// element at a time, that [`project_along_batch`] is tested against bit for bit.
#[cfg_attr(not(test), allow(dead_code))]
pub fn project_along_svd(svd: &Svd3, strain_share: f64, g: &Mat3) -> ProjectionPath {
    let (u, s, v) = (&svd.u, svd.sigma, &svd.v);
    let gt = mul(&mul(&transpose(u), g), v);
    // Rotation: R' = Ω, R'' = Ω² + Ω'.
    let w = skew_solve(&s, &gt);
    let ww = mul(&w, &w);
    let wg = mul(&w, &gt);
    let mut a = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            a[i][j] = ww[i][j] * s[j] - 2.0 * wg[i][j];
        }
    }
    let dw = skew_solve(&s, &a);
    // Stretch: S' = G̃ - ΩΣ, S'' = (Ω² - Ω')Σ - 2ΩG̃ (both symmetric; symmetrized for roundoff).
    let (mut ds, mut dds) = ([[0.0; 3]; 3], [[0.0; 3]; 3]);
    for i in 0..3 {
        for j in 0..3 {
            ds[i][j] = gt[i][j] - w[i][j] * s[j];
            dds[i][j] = (ww[i][j] - dw[i][j]) * s[j] - 2.0 * wg[i][j];
        }
    }
    for m in [&mut ds, &mut dds] {
        for (i, j) in [(0, 1), (0, 2), (1, 2)] {
            let v = 0.5 * (m[i][j] + m[j][i]);
            m[i][j] = v;
            m[j][i] = v;
        }
    }
    // Q = r I + (1 - r) S_d and its derivatives (diagonal q at τ = 0).
    let r = strain_share;
    let (q, dq, ddq) = if r >= 1.0 {
        ([1.0; 3], [[0.0; 3]; 3], [[0.0; 3]; 3])
    } else {
        let sp = volume_preserving(s);
        let (d1, d2) = volume_stretch_derivatives(&s, &sp, &ds, &dds);
        let rest = 1.0 - r;
        (sp.map(|x| r + rest * x), d1.map(|row| row.map(|x| rest * x)), d2.map(|row| row.map(|x| rest * x)))
    };
    let (wdq, wwdw) = (mul(&w, &dq), [0, 1, 2].map(|i| [0, 1, 2].map(|j| ww[i][j] + dw[i][j])));
    let (mut p0, mut p1, mut p2) = ([[0.0; 3]; 3], [[0.0; 3]; 3], [[0.0; 3]; 3]);
    for i in 0..3 {
        p0[i][i] = q[i];
        for j in 0..3 {
            p1[i][j] = w[i][j] * q[j] + dq[i][j];
            p2[i][j] = wwdw[i][j] * q[j] + 2.0 * wdq[i][j] + ddq[i][j];
        }
    }
    let back = |m: &Mat3| mul(&mul(u, m), &transpose(v));
    ProjectionPath { value: back(&p0), first: back(&p1), second: back(&p2) }
}

/// [`project_along_svd`] of [`BATCH`] deformation gradients `f` along directions `g`, the
/// decompositions included: the same operations on lanes ([`super::lanes`]), compiled for the
/// widest vector instructions, so every element gets the bytes of
/// `project_along_svd(&svd3(f), strain_share, g)` (tested). Why: the scalar form is a chain of
/// dependent divisions and square roots per element, and the timing derivatives run it for every
/// tet at every sample.
#[cfg_attr(not(test), allow(dead_code))]
pub fn project_along_batch(f: &[Mat3; BATCH], strain_share: f64, g: &[Mat3; BATCH]) -> [ProjectionPath; BATCH] {
    let (value, first, second) = dispatch_project_along(&to_lanes(f), strain_share, &to_lanes(g));
    std::array::from_fn(|l| ProjectionPath { value: lane(&value, l), first: lane(&first, l), second: lane(&second, l) })
}

with_widest_simd!(dispatch_project_along, fn(f: &M3<BATCH>, strain_share: f64, g: &M3<BATCH>) -> (M3<BATCH>, M3<BATCH>, M3<BATCH>) {
    project_along_lanes(f, strain_share, g)
});

/// Node forces of one batch along a line, on lanes: `[matrix][corner][coordinate]` (matrix:
/// value, first, second derivative), lane `l` the tet `first + l`.
pub(crate) type PathForces = [[[Lanes<BATCH>; 3]; 4]; 3];

/// The node forces of [`project_along_batch`]'s three matrices: for tet lane `l`, matrix `m`
/// (value, first, second derivative) and corner `k`, `weights[l] P_m grads[l][k]` with the
/// sums of [`Elastic::apply_j_sequential`](super::elastic::Elastic::apply_j_sequential), so
/// that adding them per node in tet order gives its bytes. Written into `out[l][m][k]` (the
/// kernel itself writes lanes, `project_along_forces_lanes`).
#[cfg_attr(not(test), allow(dead_code))]
pub fn project_along_forces(
    f: &[Mat3; BATCH],
    strain_share: f64,
    g: &[Mat3; BATCH],
    grads: &[[[f64; 3]; 4]; BATCH],
    weights: &[f64; BATCH],
    out: &mut [[[[f64; 3]; 4]; 3]; BATCH],
) {
    let mut lanes = [[[Lanes::splat(0.0); 3]; 4]; 3];
    dispatch_project_along_forces(&to_lanes(f), strain_share, &to_lanes(g), grads, weights, &mut lanes);
    for (l, o) in out.iter_mut().enumerate() {
        for m in 0..3 {
            for k in 0..4 {
                for i in 0..3 {
                    o[m][k][i] = lanes[m][k][i].0[l];
                }
            }
        }
    }
}

/// [`project_along_forces`] of matrices already on lanes, the forces written on lanes
/// (`out[m][k][i].0[l]`): vector stores, no transposition inside the kernel.
pub(crate) fn project_along_forces_lanes(
    f: &M3<BATCH>,
    strain_share: f64,
    g: &M3<BATCH>,
    grads: &[[[f64; 3]; 4]; BATCH],
    weights: &[f64; BATCH],
    out: &mut PathForces,
) {
    dispatch_project_along_forces(f, strain_share, g, grads, weights, out);
}

with_widest_simd!(dispatch_project_along_forces, fn(f: &M3<BATCH>, strain_share: f64, g: &M3<BATCH>, grads: &[[[f64; 3]; 4]; BATCH], weights: &[f64; BATCH], out: &mut PathForces) -> () {
    let paths = project_along_lanes(f, strain_share, g);
    let w = Lanes(*weights);
    // The corners' gradients on lanes, once for the three matrices (loops, not closures: the
    // closures of `array::from_fn` are not inlined into this SIMD-compiled body).
    let mut gks = [[Lanes::splat(0.0); 3]; 4];
    for (k, gk) in gks.iter_mut().enumerate() {
        for (j, gkj) in gk.iter_mut().enumerate() {
            for (l, grad) in grads.iter().enumerate() {
                gkj.0[l] = grad[k][j];
            }
        }
    }
    for (m, p) in [&paths.0, &paths.1, &paths.2].into_iter().enumerate() {
        for (k, gk) in gks.iter().enumerate() {
            for i in 0..3 {
                out[m][k][i] = w * (p[i][0] * gk[0] + p[i][1] * gk[1] + p[i][2] * gk[2]);
            }
        }
    }
});

#[inline(always)]
fn transpose_lanes<const N: usize>(a: &M3<N>) -> M3<N> {
    [[a[0][0], a[1][0], a[2][0]], [a[0][1], a[1][1], a[2][1]], [a[0][2], a[1][2], a[2][2]]]
}

/// [`inverse_pair_sum`] on lanes for the pairs (0,1), (0,2), (1,2): computed once for the two
/// skew solves of a path (the same divisions, so the same bytes).
#[inline(always)]
fn inverse_pair_sums_lanes<const N: usize>(sigma: &V3<N>) -> V3<N> {
    let (one, small) = (Lanes::splat(1.0), Lanes::splat(1e-12));
    let mut inverse = [one; 3];
    for (k, (i, j)) in [(0, 1), (0, 2), (1, 2)].into_iter().enumerate() {
        let den = sigma[i] + sigma[j];
        inverse[k] = one / Lanes::select(den.abs().lt(small), den.tiny_with_sign(), den);
    }
    inverse
}

/// [`skew_solve`] on lanes, from the [`inverse_pair_sums_lanes`].
#[inline(always)]
fn skew_solve_lanes<const N: usize>(inverse_pair_sums: &V3<N>, b: &M3<N>) -> M3<N> {
    let mut w = [[Lanes::splat(0.0); 3]; 3];
    for (k, (i, j)) in [(0, 1), (0, 2), (1, 2)].into_iter().enumerate() {
        let v = (b[i][j] - b[j][i]) * inverse_pair_sums[k];
        w[i][j] = v;
        w[j][i] = -v;
    }
    w
}

/// [`volume_stretch_derivatives`] on lanes.
#[inline(always)]
fn volume_stretch_derivatives_lanes<const N: usize>(sigma: &V3<N>, sp: &V3<N>, ds: &M3<N>, dds: &M3<N>) -> (M3<N>, M3<N>) {
    let (zero, one, two, half) = (Lanes::splat(0.0), Lanes::splat(1.0), Lanes::splat(2.0), Lanes::splat(0.5));
    let a = [two * sp[0] - sigma[0], two * sp[1] - sigma[1], two * sp[2] - sigma[2]];
    let inv_sum = one / (a[0] * sp[0]) + one / (a[1] * sp[1]) + one / (a[2] * sp[2]);
    let mut d1 = [[zero; 3]; 3];
    for (i, j) in [(0, 1), (0, 2), (1, 2)] {
        let v = half * (sp[i] * ds[i][j] / (sp[i] + sp[j] - sigma[j]) + sp[j] * ds[j][i] / (sp[i] + sp[j] - sigma[i]));
        d1[i][j] = v;
        d1[j][i] = v;
    }
    let dl = -(ds[0][0] / a[0] + ds[1][1] / a[1] + ds[2][2] / a[2]) / inv_sum;
    for i in 0..3 {
        d1[i][i] = (sp[i] * ds[i][i] + dl) / a[i];
    }
    let (d1ds, d1d1) = (mul_lanes(&d1, ds), mul_lanes(&d1, &d1));
    let mut rhs2 = [[zero; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            rhs2[i][j] = sp[i] * dds[i][j] + two * d1ds[i][j] - two * d1d1[i][j];
        }
    }
    let mut d2 = [[zero; 3]; 3];
    for (i, j) in [(0, 1), (0, 2), (1, 2)] {
        let v = half * (rhs2[i][j] / (sp[i] + sp[j] - sigma[j]) + rhs2[j][i] / (sp[i] + sp[j] - sigma[i]));
        d2[i][j] = v;
        d2[j][i] = v;
    }
    // The terms (i, j) and (j, i) are equal to the bit (d1 symmetric, products commute): each
    // division once, the sum in the order of the definition.
    let mut terms = [[zero; 3]; 3];
    for i in 0..3 {
        for j in i..3 {
            terms[i][j] = d1[i][j] * d1[i][j] / (sp[i] * sp[j]);
        }
    }
    let mut target = zero;
    for i in 0..3 {
        for j in 0..3 {
            target = target + terms[i.min(j)][i.max(j)];
        }
    }
    let b = [rhs2[0][0], rhs2[1][1], rhs2[2][2]];
    let ddl = (target - (b[0] / (a[0] * sp[0]) + b[1] / (a[1] * sp[1]) + b[2] / (a[2] * sp[2]))) / inv_sum;
    for i in 0..3 {
        d2[i][i] = (b[i] + ddl) / a[i];
    }
    (d1, d2)
}

/// [`project_along_svd`] on lanes, the signed SVD of `f` included: value, first and second
/// derivative.
#[inline(always)]
fn project_along_lanes<const N: usize>(f: &M3<N>, strain_share: f64, g: &M3<N>) -> (M3<N>, M3<N>, M3<N>) {
    let (zero, one, two, half) = (Lanes::splat(0.0), Lanes::splat(1.0), Lanes::splat(2.0), Lanes::splat(0.5));
    let (u, s, v) = svd_lanes(f);
    let gt = mul_lanes(&mul_lanes(&transpose_lanes(&u), g), &v);
    let inverse_pair_sums = inverse_pair_sums_lanes(&s);
    let w = skew_solve_lanes(&inverse_pair_sums, &gt);
    let ww = mul_lanes(&w, &w);
    let wg = mul_lanes(&w, &gt);
    let mut a = [[zero; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            a[i][j] = ww[i][j] * s[j] - two * wg[i][j];
        }
    }
    let dw = skew_solve_lanes(&inverse_pair_sums, &a);
    let (mut ds, mut dds) = ([[zero; 3]; 3], [[zero; 3]; 3]);
    for i in 0..3 {
        for j in 0..3 {
            ds[i][j] = gt[i][j] - w[i][j] * s[j];
            dds[i][j] = (ww[i][j] - dw[i][j]) * s[j] - two * wg[i][j];
        }
    }
    for m in [&mut ds, &mut dds] {
        for (i, j) in [(0, 1), (0, 2), (1, 2)] {
            let v = half * (m[i][j] + m[j][i]);
            m[i][j] = v;
            m[j][i] = v;
        }
    }
    let r = strain_share;
    let (q, dq, ddq) = if r >= 1.0 {
        ([one; 3], [[zero; 3]; 3], [[zero; 3]; 3])
    } else {
        let sp = volume_with_fallback(s);
        let (d1, d2) = volume_stretch_derivatives_lanes(&s, &sp, &ds, &dds);
        let (r, rest) = (Lanes::splat(r), Lanes::splat(1.0 - r));
        let (mut dq, mut ddq) = ([[zero; 3]; 3], [[zero; 3]; 3]);
        for i in 0..3 {
            for j in 0..3 {
                dq[i][j] = rest * d1[i][j];
                ddq[i][j] = rest * d2[i][j];
            }
        }
        ([r + rest * sp[0], r + rest * sp[1], r + rest * sp[2]], dq, ddq)
    };
    let mut wwdw = [[zero; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            wwdw[i][j] = ww[i][j] + dw[i][j];
        }
    }
    let wdq = mul_lanes(&w, &dq);
    let (mut p0, mut p1, mut p2) = ([[zero; 3]; 3], [[zero; 3]; 3], [[zero; 3]; 3]);
    for i in 0..3 {
        p0[i][i] = q[i];
        for j in 0..3 {
            p1[i][j] = w[i][j] * q[j] + dq[i][j];
            p2[i][j] = wwdw[i][j] * q[j] + two * wdq[i][j] + ddq[i][j];
        }
    }
    let vt = transpose_lanes(&v);
    (mul_lanes(&mul_lanes(&u, &p0), &vt), mul_lanes(&mul_lanes(&u, &p1), &vt), mul_lanes(&mul_lanes(&u, &p2), &vt))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::algorithms::physics::mat3::IDENTITY;
    use crate::algorithms::physics::projection::{project, project_with_jacobian};
    use crate::support::testing::Rng;

    fn axpy(f: &Mat3, t: f64, g: &Mat3) -> Mat3 {
        std::array::from_fn(|i| std::array::from_fn(|j| f[i][j] + t * g[i][j]))
    }

    fn max_abs(m: &Mat3) -> f64 {
        m.iter().flatten().fold(0.0, |a, &b| a.max(b.abs()))
    }

    /// Mild, strong (some collapse the shortest axis), inverted, and exactly coincident
    /// singular values.
    fn cases() -> Vec<Mat3> {
        let mut rng = Rng::new(31);
        let mut out: Vec<Mat3> = (0..300)
            .map(|k| {
                let m = rng.mat();
                let scale = [0.1, 0.4, 0.8][k % 3];
                axpy(&IDENTITY, scale, &m)
            })
            .collect();
        out.push(IDENTITY);
        out.push([[1.3, 0.0, 0.0], [0.0, 1.3, 0.0], [0.0, 0.0, 0.7]]);
        out.push([[0.9, 0.1, 0.0], [0.0, 1.1, 0.0], [0.0, 0.0, -0.5]]); // inverted
        out.push([[2.6, 0.2, 0.0], [0.1, 2.5, 0.0], [0.0, 0.3, 2.4]]); // collapses an axis
        out
    }

    #[test]
    fn value_and_first_derivative_match_the_projection_and_its_jacobian() {
        let mut rng = Rng::new(5);
        for f in cases() {
            let g = rng.mat();
            for share in [0.0, 0.3, 1.0] {
                let path = project_along(&f, share, &g);
                let (p, jac) = project_with_jacobian(&f, share);
                let scale = 1.0 + max_abs(&p);
                let dp = jac.apply(&g);
                for i in 0..3 {
                    for j in 0..3 {
                        assert!((path.value[i][j] - p[i][j]).abs() < 1e-12 * scale, "{f:?}");
                        assert!((path.first[i][j] - dp[i][j]).abs() < 1e-9 * (1.0 + max_abs(&dp)), "{f:?} share {share}: {:?} vs {dp:?}", path.first);
                    }
                }
            }
        }
    }

    #[test]
    fn second_derivative_matches_finite_differences() {
        // Central differences of the analytic first derivative (error O(h²): measured 1e-5,
        // 1e-7, 1e-9, 2e-10 at h = 1e-3 ... 1e-6 on the worst case, an inverted element), and
        // second differences of the projection itself.
        let mut rng = Rng::new(9);
        let (mut worst_first, mut worst_value): (f64, f64) = (0.0, 0.0);
        for f in cases() {
            let g = rng.mat();
            for share in [0.0, 0.5, 1.0] {
                let path = project_along(&f, share, &g);
                let h = 1e-6;
                let (plus, minus) = (project_along(&axpy(&f, h, &g), share, &g), project_along(&axpy(&f, -h, &g), share, &g));
                let h2 = 1e-3;
                let (pp, p0, pm) = (project(&axpy(&f, h2, &g), share), project(&f, share), project(&axpy(&f, -h2, &g), share));
                let scale = 1.0 + max_abs(&path.second);
                for i in 0..3 {
                    for j in 0..3 {
                        let fd = (plus.first[i][j] - minus.first[i][j]) / (2.0 * h);
                        worst_first = worst_first.max((fd - path.second[i][j]).abs() / scale);
                        let fd2 = (pp[i][j] - 2.0 * p0[i][j] + pm[i][j]) / (h2 * h2);
                        worst_value = worst_value.max((fd2 - path.second[i][j]).abs() / scale);
                    }
                }
            }
        }
        assert!(worst_first < 1e-8, "against differences of the first derivative: {worst_first:e}");
        assert!(worst_value < 1e-4, "against second differences of P: {worst_value:e}");
    }

    #[test]
    fn batches_give_the_bytes_of_single_paths() {
        // Every case (mild, strong, collapsing, inverted, coincident singular values), in
        // batches with padding, against the scalar path of the same decomposition.
        let mut rng = Rng::new(17);
        let mut fs = cases();
        fs.resize(fs.len().div_ceil(BATCH) * BATCH + 5, IDENTITY);
        let gs: Vec<Mat3> = fs.iter().map(|_| rng.mat()).collect();
        for share in [0.0, 0.3, 1.0] {
            for (fc, gc) in fs.chunks(BATCH).zip(gs.chunks(BATCH)) {
                let (mut f, mut g) = ([IDENTITY; BATCH], [[[0.0; 3]; 3]; BATCH]);
                f[..fc.len()].copy_from_slice(fc);
                g[..gc.len()].copy_from_slice(gc);
                for ((f, g), path) in f.iter().zip(&g).zip(project_along_batch(&f, share, &g)).take(fc.len()) {
                    assert_eq!(path, project_along_svd(&svd3(f), share, g), "{f:?} along {g:?}, share {share}");
                }
                // The node forces: `w P g_k` with the scalar sums, to the bit.
                let grads: [[[f64; 3]; 4]; BATCH] = std::array::from_fn(|_| std::array::from_fn(|_| [rng.next(), rng.next(), rng.next()]));
                let weights: [f64; BATCH] = std::array::from_fn(|_| rng.next().abs());
                let mut forces = [[[[0.0; 3]; 4]; 3]; BATCH];
                project_along_forces(&f, share, &g, &grads, &weights, &mut forces);
                for l in 0..fc.len() {
                    let path = project_along_svd(&svd3(&f[l]), share, &g[l]);
                    for (m, p) in [path.value, path.first, path.second].iter().enumerate() {
                        for (k, gk) in grads[l].iter().enumerate() {
                            let expected: [f64; 3] = std::array::from_fn(|i| weights[l] * (p[i][0] * gk[0] + p[i][1] * gk[1] + p[i][2] * gk[2]));
                            assert_eq!(forces[l][m][k], expected, "lane {l}, matrix {m}, corner {k}");
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn rotation_along_a_skew_direction() {
        // F(τ) = I + τG with G skew: FᵀF = I - τ²G², so R = (I + τG)(I + τ²G²/2 + O(τ⁴)),
        // R'(0) = G and R''(0) = G² exactly.
        let g = [[0.0, -0.3, 0.2], [0.3, 0.0, -0.5], [-0.2, 0.5, 0.0]];
        let path = project_along(&IDENTITY, 1.0, &g);
        let gg = mul(&g, &g);
        for i in 0..3 {
            for j in 0..3 {
                assert!((path.second[i][j] - gg[i][j]).abs() < 1e-14, "{:?} vs {gg:?}", path.second);
                assert!((path.first[i][j] - g[i][j]).abs() < 1e-14);
            }
        }
    }
}
