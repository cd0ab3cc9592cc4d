//! The local step of projective dynamics: project a deformation gradient onto the strain
//! (rotation) and volume (det = 1) constraint manifolds.
//!
//! With `F = U diag(σ) Vᵀ` (signed SVD), the closest rotation is `R = U Vᵀ`, and the closest
//! matrix of unit determinant is `D = U diag(σ') Vᵀ` where `σ'` is the point of the surface
//! `σ'1 σ'2 σ'3 = 1` closest to `σ`. Strain and volume constraints of one element share its
//! gradient operator, so their sum is one quadratic with target
//! `P = r R + (1 - r) D`, `r = k_strain / (k_strain + k_volume)`; that is what the global
//! step sees.

use super::lanes::{lane, mul_lanes, to_lanes, with_widest_simd, Lanes, Mask, BATCH, M3};
#[cfg(doc)]
use super::mat3::scaled_product;
use super::mat3::Mat3;
use super::svd3::svd_lanes;

/// The point `σ'` of `{σ'1 σ'2 σ'3 = 1, σ' > 0}` closest to `sigma` (sorted as from [`svd3`](super::svd3::svd3):
/// `σ1 >= σ2 >= |σ3|`, `σ3` possibly negative for an inverted element).
///
/// Stationarity of `½|σ' - σ|² - λ(Πσ' - 1)` gives `σ'_i (σ'_i - σ_i) = λ` for every `i`, so
/// each `σ'_i` is a root of one quadratic in the common multiplier `λ`. On the branch
/// `σ'_i = (σ_i + sqrt(σ_i² + 4λ)) / 2` the product grows monotonically with `λ` and the root is
/// found by safeguarded Newton; this is the nearest point whenever the element is stretched
/// less than twice in every direction. Beyond that (`Π σ'(λ_min) > 1`), the smallest singular
/// value moves to the other root and the stationary point is found by bisection: a KKT
/// point that collapses the shortest axis, as the exact projection does.
pub fn volume_preserving(sigma: [f64; 3]) -> [f64; 3] {
    let (s, collapse) = volume_lanes::<1>(sigma.map(|v| Lanes([v])));
    if collapse.0[0] {
        return collapse_shortest_axis(sigma);
    }
    s.map(|v| v.0[0])
}

#[inline(always)]
fn product3<const N: usize>(s: &[Lanes<N>; 3]) -> Lanes<N> {
    s[0] * s[1] * s[2]
}

/// `σ'_i(λ) = (σ_i + sqrt(σ_i² + 4λ)) / 2`, the branch of the stationarity condition that
/// grows with λ (the radicand clamped at 0).
#[inline(always)]
fn plus_branch<const N: usize>(sigma: &[Lanes<N>; 3], l: Lanes<N>) -> [Lanes<N>; 3] {
    let (zero, half, four) = (Lanes::splat(0.0), Lanes::splat(0.5), Lanes::splat(4.0));
    let mut out = *sigma;
    for s in out.iter_mut() {
        *s = half * (*s + (*s * *s + four * l).max(zero).sqrt());
    }
    out
}

/// [`volume_preserving`] on lanes: every branch a per-lane select, the iterations running until
/// the slowest lane is done with finished lanes frozen, so each lane gets exactly the scalar
/// result. Lanes that need [`collapse_shortest_axis`] (an element stretched more than twice in
/// every direction) are flagged instead of solved.
#[inline(always)]
fn volume_lanes<const N: usize>(sigma: [Lanes<N>; 3]) -> ([Lanes<N>; 3], Mask<N>) {
    let (zero, one, half) = (Lanes::splat(0.0), Lanes::splat(1.0), Lanes::splat(0.5));
    // Already on the surface.
    let mut done = (product3(&sigma) - one).abs().le(Lanes::splat(1e-15));
    let mut result = sigma;
    let smallest = sigma[2];
    let positive = smallest.gt(zero);
    // Domain of the + branch: σ_i² + 4λ >= 0 for all i; for an inverted element λ > 0.
    let lambda_min = Lanes::select(positive, Lanes::splat(-0.25) * smallest * smallest, zero);
    let collapse = !done & positive & product3(&plus_branch(&sigma, lambda_min)).gt(one);
    done = done | collapse;
    // φ(λ) = Π σ'_i(λ) - 1 increases on (λ_min, ∞): bracket its root and run Newton from the
    // linearization σ'_i ≈ σ_i + λ/σ_i, falling back to bisection outside the bracket.
    let mut lo = lambda_min;
    let mut hi = zero.max(one - sigma[0]).max(one - sigma[1]).max(one - sigma[2]) + Lanes::splat(1e-3);
    loop {
        let grow = !done & product3(&plus_branch(&sigma, hi)).lt(one);
        if !grow.any() {
            break;
        }
        hi = Lanes::select(grow, Lanes::splat(2.0) * hi + one, hi);
    }
    let p0 = product3(&sigma);
    let linear = (one / p0 - one) / (one / (sigma[0] * sigma[0]) + one / (sigma[1] * sigma[1]) + one / (sigma[2] * sigma[2]));
    let mut l = Lanes::select(positive & linear.gt(lo) & linear.lt(hi), linear, half * (lo + hi));
    let mut active = !done;
    // `s` is the branch at the current `l`: carried from the end of the previous iteration
    // (which computed it for the `closed` test) instead of recomputed.
    let mut s = plus_branch(&sigma, l);
    for _ in 0..100 {
        if !active.any() {
            break;
        }
        let p = product3(&s);
        let phi = p - one;
        let converged = active & phi.abs().lt(Lanes::splat(1e-15));
        for i in 0..3 {
            result[i] = Lanes::select(converged, s[i], result[i]);
        }
        active = active & !converged;
        let below = phi.lt(zero);
        lo = Lanes::select(active & below, l, lo);
        hi = Lanes::select(active & !below, l, hi);
        // φ' = Π σ'_i · Σ σ'_i' / σ'_i with σ'_i' = 1 / (2σ'_i - σ_i).
        let two = Lanes::splat(2.0);
        let (t0, t1, t2) = (one / ((two * s[0] - sigma[0]) * s[0]), one / ((two * s[1] - sigma[1]) * s[1]), one / ((two * s[2] - sigma[2]) * s[2]));
        let dphi = p * (t0 + t1 + t2);
        let newton = l - phi / dphi;
        let inside = newton.gt(lo) & newton.lt(hi) & dphi.abs().lt(Lanes::splat(f64::INFINITY));
        l = Lanes::select(active, Lanes::select(inside, newton, half * (lo + hi)), l);
        let closed = active & (hi - lo).le(Lanes::splat(1e-16) * (one + hi.abs()));
        s = plus_branch(&sigma, l);
        for i in 0..3 {
            result[i] = Lanes::select(closed, s[i], result[i]);
        }
        active = active & !closed;
    }
    // Out of iterations: the last iterate.
    for i in 0..3 {
        result[i] = Lanes::select(active, s[i], result[i]);
    }
    (result, collapse)
}

/// The stationary point with the smallest singular value on the small root: parametrize by
/// `t = σ'3 ∈ (0, σ3/2]`, `λ = t (t - σ3)`, the others on the + branch, and bisect on the
/// product.
fn collapse_shortest_axis(sigma: [f64; 3]) -> [f64; 3] {
    let at = |t: f64| {
        let l = t * (t - sigma[2]);
        let big = |s: f64| 0.5 * (s + (s * s + 4.0 * l).max(0.0).sqrt());
        [big(sigma[0]), big(sigma[1]), t]
    };
    let (mut lo, mut hi) = (0.0, 0.5 * sigma[2]);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        let s = at(mid);
        if s[0] * s[1] * s[2] < 1.0 {
            lo = mid;
        } else {
            hi = mid;
        }
        if hi - lo <= 1e-17 * sigma[2] {
            break;
        }
    }
    at(0.5 * (lo + hi))
}

/// Projection target of one element: `r R + (1 - r) D` for deformation gradient `f` and
/// strain share `r` in [0, 1]. (The definition [`project_batch`] is tested against.)
#[cfg_attr(not(test), allow(dead_code))]
pub fn project(f: &Mat3, strain_share: f64) -> Mat3 {
    let p = project_lanes::<1>(&to_lanes(&[*f]), strain_share);
    lane(&p, 0)
}

/// [`project`] of [`BATCH`] elements at once (bit-identical to it, element by element).
pub fn project_batch(f: &[Mat3; BATCH], strain_share: f64) -> [Mat3; BATCH] {
    let p = dispatch_project(&to_lanes(f), strain_share);
    std::array::from_fn(|l| lane(&p, l))
}

with_widest_simd!(dispatch_project, fn(f: &M3<BATCH>, strain_share: f64) -> M3<BATCH> { project_lanes(f, strain_share) });

/// Node forces of one batch, on lanes: `[corner][coordinate]`, lane `l` the tet `first + l`.
pub(crate) type CornerForces = [[Lanes<BATCH>; 3]; 4];

/// [`project_batch`]'s targets as node forces, from deformation gradients on lanes: for tet
/// lane `l` and corner `k`, `weights[l] P_l grads[l][k]` with the sums of
/// [`Elastic::apply_j_sequential`](super::elastic::Elastic::apply_j_sequential), so that adding
/// them per node in tet order gives its bytes (for a caller that needs `J p`, not `p`). Written
/// on lanes (`out[k][i].0[l]`): vector stores, no transposition inside the kernel.
pub(crate) fn project_forces(f: &M3<BATCH>, strain_share: f64, grads: &[[[f64; 3]; 4]; BATCH], weights: &[f64; BATCH], out: &mut CornerForces) {
    dispatch_project_forces(f, strain_share, grads, weights, out);
}

with_widest_simd!(dispatch_project_forces, fn(f: &M3<BATCH>, strain_share: f64, grads: &[[[f64; 3]; 4]; BATCH], weights: &[f64; BATCH], out: &mut CornerForces) -> () {
    let p = project_lanes(f, strain_share);
    let w = Lanes(*weights);
    for k in 0..4 {
        // A loop, not `array::from_fn`: its closures are not inlined into this SIMD body.
        let mut gk = [Lanes::splat(0.0); 3];
        for (j, gkj) in gk.iter_mut().enumerate() {
            for (l, grad) in grads.iter().enumerate() {
                gkj.0[l] = grad[k][j];
            }
        }
        for i in 0..3 {
            out[k][i] = w * (p[i][0] * gk[0] + p[i][1] * gk[1] + p[i][2] * gk[2]);
        }
    }
});

#[inline(always)]
fn project_lanes<const N: usize>(f: &M3<N>, strain_share: f64) -> M3<N> {
    let (u, sigma, v) = svd_lanes(f);
    let blend = if strain_share >= 1.0 {
        [Lanes::splat(1.0); 3]
    } else {
        let s = volume_with_fallback(sigma);
        let (r, rest) = (Lanes::splat(strain_share), Lanes::splat(1.0 - strain_share));
        [r + rest * s[0], r + rest * s[1], r + rest * s[2]]
    };
    scaled_product_lanes(&u, blend, &v)
}

/// [`volume_preserving`] of every lane (the rare collapsed lanes one by one).
#[inline(always)]
pub(crate) fn volume_with_fallback<const N: usize>(sigma: [Lanes<N>; 3]) -> [Lanes<N>; 3] {
    let (mut s, collapse) = volume_lanes(sigma);
    if collapse.any() {
        for l in 0..N {
            if collapse.0[l] {
                let c = collapse_shortest_axis([sigma[0].0[l], sigma[1].0[l], sigma[2].0[l]]);
                for i in 0..3 {
                    s[i].0[l] = c[i];
                }
            }
        }
    }
    s
}

/// `U diag(s) Vᵀ` with the sums of [`scaled_product`].
#[inline(always)]
fn scaled_product_lanes<const N: usize>(u: &M3<N>, s: [Lanes<N>; 3], v: &M3<N>) -> M3<N> {
    let z = Lanes::splat(0.0);
    let mut c = [[z; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            c[i][j] = u[i][0] * s[0] * v[j][0] + u[i][1] * s[1] * v[j][1] + u[i][2] * s[2] * v[j][2];
        }
    }
    c
}

/// The derivative of [`project`] at one `F`, for products `dP = DP(F)[dF]`.
///
/// `P(F) = U diag(p(σ)) Vᵀ` is an isotropic function of `F`, so in the singular frame
/// (`dF̃ = Uᵀ dF V`) its derivative is
///
/// ```text
/// dP̃_ii = Σ_j ∂p_i/∂σ_j dF̃_jj
/// dP̃_ij = ½ (dF̃_ij + dF̃_ji) (p_i - p_j)/(σ_i - σ_j) + ½ (dF̃_ij - dF̃_ji) (p_i + p_j)/(σ_i + σ_j)
/// ```
///
/// With `p = r + (1 - r) σ'` and the volume projection's stationarity `σ'_i(σ'_i - σ_i) = λ`,
/// `(σ'_i - σ'_j)/(σ_i - σ_j) = σ'_j / (σ'_i + σ'_j - σ_i)` exactly, so the symmetric factor has
/// no cancellation when singular values coincide (the rest pose); `∂σ'/∂σ` follows from
/// differentiating the same conditions.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ProjectionJacobian {
    u: Mat3,
    v: Mat3,
    /// `∂p_i/∂σ_j`.
    diag: Mat3,
    /// Symmetric and antisymmetric factors for the pairs (0,1), (0,2), (1,2).
    sym: [f64; 3],
    anti: [f64; 3],
}

const PAIRS: [(usize, usize); 3] = [(0, 1), (0, 2), (1, 2)];

impl ProjectionJacobian {
    /// `dP` for a change `df` of the deformation gradient.
    pub fn apply(&self, df: &Mat3) -> Mat3 {
        use super::mat3::{mul, transpose};
        let t = mul(&mul(&transpose(&self.u), df), &self.v);
        let mut dp = [[0.0; 3]; 3];
        for i in 0..3 {
            dp[i][i] = self.diag[i][0] * t[0][0] + self.diag[i][1] * t[1][1] + self.diag[i][2] * t[2][2];
        }
        for (k, &(i, j)) in PAIRS.iter().enumerate() {
            let (sym, anti) = (0.5 * (t[i][j] + t[j][i]), 0.5 * (t[i][j] - t[j][i]));
            dp[i][j] = self.sym[k] * sym + self.anti[k] * anti;
            dp[j][i] = self.sym[k] * sym - self.anti[k] * anti;
        }
        mul(&mul(&self.u, &dp), &transpose(&self.v))
    }
}

/// The [`ProjectionJacobian`]s of [`BATCH`] consecutive tets in lane layout (a struct of
/// arrays: each factor's entry `[l]` is tet `first + l`'s), as the vectorized local step makes
/// them and as the exact gradient applies them: no transposition out to per-tet structs and
/// back per product. Lanes past a body's last tet hold whatever the local step computed for
/// its padding (the identity's Jacobian); their products are computed and dropped.
#[derive(Debug, Clone)]
pub struct JacobianBatch(JacobianLanes<BATCH>);

impl Default for JacobianBatch {
    /// Zero factors (a placeholder the local step overwrites).
    fn default() -> JacobianBatch {
        let z = Lanes::splat(0.0);
        JacobianBatch(JacobianLanes { u: [[z; 3]; 3], v: [[z; 3]; 3], diag: [[z; 3]; 3], sym: [z; 3], anti: [z; 3] })
    }
}

/// Lane by lane (every lane, padding included).
impl PartialEq for JacobianBatch {
    fn eq(&self, other: &JacobianBatch) -> bool {
        (0..BATCH).all(|l| self.lane(l) == other.lane(l))
    }
}

impl JacobianBatch {
    /// Up to [`BATCH`] Jacobians gathered into lanes (the rest zero).
    pub(crate) fn from_jacobians(jacobians: &[ProjectionJacobian]) -> JacobianBatch {
        let mut j = JacobianBatch::default();
        for (l, jac) in jacobians.iter().enumerate().take(BATCH) {
            for a in 0..3 {
                for b in 0..3 {
                    j.0.u[a][b].0[l] = jac.u[a][b];
                    j.0.v[a][b].0[l] = jac.v[a][b];
                    j.0.diag[a][b].0[l] = jac.diag[a][b];
                }
                j.0.sym[a].0[l] = jac.sym[a];
                j.0.anti[a].0[l] = jac.anti[a];
            }
        }
        j
    }

    /// The Jacobian of lane `l`.
    pub fn lane(&self, l: usize) -> ProjectionJacobian {
        jacobian_lane(&self.0, l)
    }

    /// `dP_l = DP_l[df_l]` in every lane: [`ProjectionJacobian::apply`]'s operations on lanes, so
    /// every product gets the bytes of the scalar one (tested).
    pub(crate) fn apply(&self, df: &M3<BATCH>) -> M3<BATCH> {
        dispatch_apply_jacobian(&self.0, df)
    }
}

/// [`ProjectionJacobian::apply`] of up to [`BATCH`] Jacobians, each to its own `df` (lanes past
/// `jacobians.len()` are computed on zeros and dropped), through [`JacobianBatch`]: the bytes of
/// the scalar products. For callers that hold per-tet Jacobians.
#[cfg_attr(not(test), allow(dead_code))]
pub(crate) fn apply_jacobians_batch(jacobians: &[ProjectionJacobian], df: &[Mat3; BATCH]) -> [Mat3; BATCH] {
    let dp = JacobianBatch::from_jacobians(jacobians).apply(&to_lanes(df));
    std::array::from_fn(|l| lane(&dp, l))
}

with_widest_simd!(dispatch_apply_jacobian, fn(j: &JacobianLanes<BATCH>, df: &M3<BATCH>) -> M3<BATCH> { apply_jacobian_lanes(j, df) });

/// [`ProjectionJacobian::apply`] on lanes.
#[inline(always)]
fn apply_jacobian_lanes<const N: usize>(j: &JacobianLanes<N>, df: &M3<N>) -> M3<N> {
    let (zero, half) = (Lanes::splat(0.0), Lanes::splat(0.5));
    let transpose = |a: &M3<N>| [[a[0][0], a[1][0], a[2][0]], [a[0][1], a[1][1], a[2][1]], [a[0][2], a[1][2], a[2][2]]];
    let t = mul_lanes(&mul_lanes(&transpose(&j.u), df), &j.v);
    let mut dp = [[zero; 3]; 3];
    for i in 0..3 {
        dp[i][i] = j.diag[i][0] * t[0][0] + j.diag[i][1] * t[1][1] + j.diag[i][2] * t[2][2];
    }
    for (k, &(i, l)) in PAIRS.iter().enumerate() {
        let (sym, anti) = (half * (t[i][l] + t[l][i]), half * (t[i][l] - t[l][i]));
        dp[i][l] = j.sym[k] * sym + j.anti[k] * anti;
        dp[l][i] = j.sym[k] * sym - j.anti[k] * anti;
    }
    mul_lanes(&mul_lanes(&j.u, &dp), &transpose(&j.v))
}

/// [`project`] and its derivative at `f`. (The definition [`project_with_jacobian_batch`] is
/// tested against.)
#[cfg_attr(not(test), allow(dead_code))]
pub fn project_with_jacobian(f: &Mat3, strain_share: f64) -> (Mat3, ProjectionJacobian) {
    let (p, j) = project_with_jacobian_lanes::<1>(&to_lanes(&[*f]), strain_share);
    (lane(&p, 0), jacobian_lane(&j, 0))
}

/// [`project_with_jacobian`] of [`BATCH`] elements at once (bit-identical, element by element).
pub fn project_with_jacobian_batch(f: &[Mat3; BATCH], strain_share: f64) -> [(Mat3, ProjectionJacobian); BATCH] {
    let (p, j) = dispatch_project_with_jacobian(&to_lanes(f), strain_share);
    std::array::from_fn(|l| (lane(&p, l), jacobian_lane(&j, l)))
}

/// [`project_with_jacobian_batch`] of the first `count` lanes appended to `targets` and
/// `jacobians` (each read straight out of the lanes into the vectors: no batch-sized copy).
pub(crate) fn project_with_jacobian_extend(
    f: &[Mat3; BATCH],
    strain_share: f64,
    count: usize,
    targets: &mut Vec<Mat3>,
    jacobians: &mut Vec<ProjectionJacobian>,
) {
    let (p, j) = dispatch_project_with_jacobian(&to_lanes(f), strain_share);
    let count = count.min(BATCH);
    targets.extend((0..count).map(|l| lane(&p, l)));
    jacobians.extend((0..count).map(|l| jacobian_lane(&j, l)));
}

/// [`project_with_jacobian_batch`] from deformation gradients on lanes: the targets of the first
/// `targets.len()` (at most [`BATCH`]) lanes into `targets`, the Jacobians into `jacobians` in
/// lane layout, as computed (the same bytes, per lane).
pub(crate) fn project_with_jacobian_lanes_into(f: &M3<BATCH>, strain_share: f64, targets: &mut [Mat3], jacobians: &mut JacobianBatch) {
    let p = dispatch_project_with_jacobian_into(f, strain_share, &mut jacobians.0);
    for (l, t) in targets.iter_mut().enumerate().take(BATCH) {
        *t = lane(&p, l);
    }
}

with_widest_simd!(dispatch_project_with_jacobian, fn(f: &M3<BATCH>, strain_share: f64) -> (M3<BATCH>, JacobianLanes<BATCH>) {
    project_with_jacobian_lanes(f, strain_share)
});

with_widest_simd!(dispatch_project_with_jacobian_into, fn(f: &M3<BATCH>, strain_share: f64, out: &mut JacobianLanes<BATCH>) -> M3<BATCH> {
    let (p, j) = project_with_jacobian_lanes(f, strain_share);
    *out = j;
    p
});

/// [`ProjectionJacobian`] on lanes.
#[derive(Debug, Clone)]
struct JacobianLanes<const N: usize> {
    u: M3<N>,
    v: M3<N>,
    diag: M3<N>,
    sym: [Lanes<N>; 3],
    anti: [Lanes<N>; 3],
}

fn jacobian_lane<const N: usize>(j: &JacobianLanes<N>, l: usize) -> ProjectionJacobian {
    ProjectionJacobian { u: lane(&j.u, l), v: lane(&j.v, l), diag: lane(&j.diag, l), sym: j.sym.map(|x| x.0[l]), anti: j.anti.map(|x| x.0[l]) }
}

#[inline(always)]
fn project_with_jacobian_lanes<const N: usize>(f: &M3<N>, strain_share: f64) -> (M3<N>, JacobianLanes<N>) {
    let (u, sigma, v) = svd_lanes(f);
    let r = strain_share;
    let (zero, one, two) = (Lanes::splat(0.0), Lanes::splat(1.0), Lanes::splat(2.0));
    let mut diag = [[zero; 3]; 3];
    let mut sym = [zero; 3];
    let p = if r >= 1.0 {
        [one; 3]
    } else {
        let s = volume_with_fallback(sigma);
        let rest = Lanes::splat(1.0 - r);
        // ∂σ'_i/∂σ_j = (σ'_i δ_ij - (1/a_j) / Σ_k 1/(a_k σ'_k)) / a_i, a_i = 2σ'_i - σ_i.
        let a = [two * s[0] - sigma[0], two * s[1] - sigma[1], two * s[2] - sigma[2]];
        let c = one / (one / (a[0] * s[0]) + one / (a[1] * s[1]) + one / (a[2] * s[2]));
        for i in 0..3 {
            for j in 0..3 {
                let ds = ((if i == j { s[i] } else { zero }) - c / a[j]) / a[i];
                diag[i][j] = rest * ds;
            }
        }
        for (k, &(i, j)) in PAIRS.iter().enumerate() {
            sym[k] = rest * s[j] / (s[i] + s[j] - sigma[i]);
        }
        let r = Lanes::splat(r);
        [r + rest * s[0], r + rest * s[1], r + rest * s[2]]
    };
    let mut anti = [zero; 3];
    for (k, &(i, j)) in PAIRS.iter().enumerate() {
        let den = sigma[i] + sigma[j];
        // σ_i + σ_j = 0 only for an inverted element with |σ3| = σ2: the rotation is not
        // differentiable there; a bounded factor keeps the product finite.
        let den = Lanes::select(den.abs().lt(Lanes::splat(1e-12)), den.tiny_with_sign(), den);
        anti[k] = (p[i] + p[j]) / den;
    }
    (scaled_product_lanes(&u, p, &v), JacobianLanes { u, v, diag, sym, anti })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::algorithms::physics::mat3::{det, distance, mul, mul_transpose, IDENTITY};
    use crate::support::testing::Rng;

    fn dist2(a: [f64; 3], b: [f64; 3]) -> f64 {
        (0..3).map(|i| (a[i] - b[i]).powi(2)).sum()
    }

    /// Closest point on Πσ' = 1 by searching (ln a, ln b) on ever finer grids.
    fn brute_force(sigma: [f64; 3]) -> [f64; 3] {
        let eval = |x: f64, y: f64| {
            let (a, b) = (x.exp(), y.exp());
            let p = [a, b, 1.0 / (a * b)];
            (dist2(p, sigma), p)
        };
        let (mut cx, mut cy, mut half) = (0.0, 0.0, 4.0);
        let mut best = eval(cx, cy);
        for _ in 0..40 {
            let n = 40;
            let (bx, by) = (cx, cy);
            for i in 0..=n {
                for j in 0..=n {
                    let x = bx - half + 2.0 * half * i as f64 / n as f64;
                    let y = by - half + 2.0 * half * j as f64 / n as f64;
                    let e = eval(x, y);
                    if e.0 < best.0 {
                        best = e;
                        cx = x;
                        cy = y;
                    }
                }
            }
            half *= 0.3;
        }
        best.1
    }

    fn sorted(mut s: [f64; 3]) -> [f64; 3] {
        s.sort_by(|a, b| b.total_cmp(a));
        s
    }

    #[test]
    fn unit_volume_and_stationary() {
        let mut rng = Rng::new(7);
        for _ in 0..3000 {
            let mut s = sorted([1.0 + 0.9 * rng.next(), 1.0 + 0.9 * rng.next(), 1.0 + 0.9 * rng.next()]);
            if rng.next() < -0.6 {
                s[2] = -s[2].abs() * 0.5; // inverted element
                s = [s[0].max(s[2].abs()), s[1].max(s[2].abs()), s[2]];
            }
            let p = volume_preserving(s);
            assert!((p[0] * p[1] * p[2] - 1.0).abs() < 1e-12, "{s:?} -> {p:?}");
            assert!(p.iter().all(|&v| v > 0.0));
            // KKT: σ'_i (σ'_i - σ_i) is the same for all i.
            let l: Vec<f64> = (0..3).map(|i| p[i] * (p[i] - s[i])).collect();
            assert!((l[0] - l[1]).abs() < 1e-9 && (l[1] - l[2]).abs() < 1e-9, "{s:?} -> {p:?}: {l:?}");
        }
    }

    #[test]
    fn nearest_point_for_moderate_stretch() {
        let mut rng = Rng::new(11);
        for _ in 0..200 {
            let s = sorted([1.0 + 0.7 * rng.next(), 1.0 + 0.7 * rng.next(), 1.0 + 0.7 * rng.next()]);
            let p = volume_preserving(s);
            let b = brute_force(s);
            assert!(dist2(p, s) <= dist2(b, s) + 1e-10, "{s:?}: ours {p:?} {} vs brute {b:?} {}", dist2(p, s), dist2(b, s));
        }
    }

    #[test]
    fn batched_jacobian_products_give_the_bytes_of_single_ones() {
        // Mild, strong and inverted elements, every strain share, a full and a partial batch.
        let mut rng = Rng::new(23);
        for share in [0.0, 0.4, 1.0] {
            for len in [BATCH, 5] {
                let jacobians: Vec<ProjectionJacobian> = (0..len)
                    .map(|k| {
                        let m = rng.mat();
                        let scale = [0.1, 0.6, 1.5][k % 3];
                        let f: Mat3 = std::array::from_fn(|i| std::array::from_fn(|j| if i == j { 1.0 } else { 0.0 } + scale * m[i][j]));
                        project_with_jacobian(&f, share).1
                    })
                    .collect();
                let df: [Mat3; BATCH] = std::array::from_fn(|_| rng.mat());
                let batch = apply_jacobians_batch(&jacobians, &df);
                for (l, j) in jacobians.iter().enumerate() {
                    assert_eq!(batch[l], j.apply(&df[l]), "lane {l}, share {share}");
                }
            }
        }
    }

    #[test]
    fn batches_give_the_bytes_of_single_projections() {
        // Mild, strong (some collapse the shortest axis), inverted and degenerate gradients in
        // mixed batches: every lane must equal the one-element path.
        let mut rng = Rng::new(23);
        let mut cases: Vec<Mat3> = (0..30 * BATCH)
            .map(|k| {
                let m = rng.mat();
                let scale = [0.05, 0.5, 1.5, 3.0][k % 4];
                let mut f: Mat3 = std::array::from_fn(|i| std::array::from_fn(|j| if i == j { 1.0 } else { 0.0 } + scale * m[i][j]));
                if k % 5 == 0 {
                    f = f.map(|row| row.map(|v| 2.5 * v)); // stretched more than twice
                }
                f
            })
            .collect();
        cases.extend([
            [[0.0; 3]; 3],
            IDENTITY,
            [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]],
            [[3.0, 0.0, 0.0], [0.0, 3.0, 0.0], [0.0, 0.0, 3.0]],
        ]);
        cases.resize(cases.len().div_ceil(BATCH) * BATCH, IDENTITY);
        for share in [0.0, 0.4, 1.0] {
            for chunk in cases.chunks_exact(BATCH) {
                let batch: [Mat3; BATCH] = chunk.try_into().unwrap();
                let (p, pj) = (project_batch(&batch, share), project_with_jacobian_batch(&batch, share));
                for l in 0..BATCH {
                    assert_eq!(p[l], project(&batch[l], share), "{:?}", batch[l]);
                    assert_eq!(pj[l], project_with_jacobian(&batch[l], share), "{:?}", batch[l]);
                }
            }
        }
    }

    #[test]
    fn extreme_stretch_collapses_the_shortest_axis() {
        let s = [3.0, 3.0, 3.0];
        let p = volume_preserving(s);
        assert!((p[0] * p[1] * p[2] - 1.0).abs() < 1e-12);
        assert!(p[2] < 0.2 && p[0] > 2.5, "{p:?}");
        assert!(dist2(p, s) < dist2([1.0; 3], s), "closer than the symmetric stationary point");
    }

    #[test]
    fn projection_of_rotations_and_scaled_rotations() {
        let r0 = [[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]];
        for share in [0.0, 0.3, 1.0] {
            assert!(distance(&project(&r0, share), &r0) < 1e-12, "a rotation is its own projection");
        }
        // Uniform scaling by 1.1: strain target R, volume target R (σ' = 1 by symmetry).
        let f = r0.map(|row| row.map(|v| 1.1 * v));
        assert!(distance(&project(&f, 0.5), &r0) < 1e-12);
    }

    #[test]
    fn jacobian_matches_finite_differences() {
        let mut rng = Rng::new(17);
        let mut worst: f64 = 0.0;
        for case in 0..400 {
            let m = rng.mat();
            let mut f = IDENTITY;
            for i in 0..3 {
                for j in 0..3 {
                    f[i][j] += 0.4 * m[i][j];
                }
            }
            if case % 7 == 0 {
                f = IDENTITY; // coincident singular values
            }
            let df = rng.mat();
            for share in [0.0, 0.5, 1.0] {
                let (p, jac) = project_with_jacobian(&f, share);
                assert!(distance(&p, &project(&f, share)) < 1e-14);
                let h = 1e-6;
                let step = |s: f64| -> Mat3 {
                    let mut g = f;
                    for i in 0..3 {
                        for j in 0..3 {
                            g[i][j] += s * df[i][j];
                        }
                    }
                    g
                };
                let (pp, pm) = (project(&step(h), share), project(&step(-h), share));
                let analytic = jac.apply(&df);
                for i in 0..3 {
                    for j in 0..3 {
                        let fd = (pp[i][j] - pm[i][j]) / (2.0 * h);
                        worst = worst.max((fd - analytic[i][j]).abs());
                    }
                }
            }
        }
        assert!(worst < 1e-7, "largest difference {worst:e}");
    }

    #[test]
    fn volume_target_has_unit_determinant_and_strain_target_is_a_rotation() {
        let mut rng = Rng::new(3);
        for _ in 0..500 {
            let f = rng.mat();
            let d = project(&f, 0.0);
            assert!((det(&d) - 1.0).abs() < 1e-9, "{}", det(&d));
            let r = project(&f, 1.0);
            assert!(distance(&mul_transpose(&r, &r), &IDENTITY) < 1e-12 && (det(&r) - 1.0).abs() < 1e-12);
            let _ = mul(&r, &d);
        }
    }
}
