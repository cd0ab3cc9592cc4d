//! The local step of projective dynamics: project a deformation gradient onto the strain
//! (rotation) and volume (det = 1) constraint manifolds.
//!
//! With `F = U diag(σ) Vᵀ` (signed SVD), the closest rotation is `R = U Vᵀ`, and the closest
//! matrix of unit determinant is `D = U diag(σ') Vᵀ` where `σ'` is the point of the surface
//! `σ'1 σ'2 σ'3 = 1` closest to `σ`. Strain and volume constraints of one element share its
//! gradient operator, so their sum is one quadratic with target
//! `P = r R + (1 - r) D`, `r = k_strain / (k_strain + k_volume)`; that is what the global
//! step sees.

use super::mat3::{scaled_product, Mat3};
use super::svd3::svd3;

/// The point `σ'` of `{σ'1 σ'2 σ'3 = 1, σ' > 0}` closest to `sigma` (sorted as from [`svd3`]:
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
    let product = sigma[0] * sigma[1] * sigma[2];
    if (product - 1.0).abs() <= 1e-15 {
        return sigma;
    }
    let plus = |l: f64| sigma.map(|s| 0.5 * (s + (s * s + 4.0 * l).max(0.0).sqrt()));
    let smallest = sigma[2];
    // Domain of the + branch: σ_i² + 4λ >= 0 for all i; for an inverted element λ > 0.
    let lambda_min = if smallest > 0.0 { -0.25 * smallest * smallest } else { 0.0 };
    let product = |s: [f64; 3]| s[0] * s[1] * s[2];

    if smallest > 0.0 && product(plus(lambda_min)) > 1.0 {
        return collapse_shortest_axis(sigma);
    }
    // φ(λ) = Π σ'_i(λ) - 1 increases on (λ_min, ∞): bracket its root and run Newton from the
    // linearization σ'_i ≈ σ_i + λ/σ_i, falling back to bisection outside the bracket.
    let mut lo = lambda_min;
    let mut hi = sigma.iter().map(|s| 1.0 - s).fold(0.0f64, f64::max) + 1e-3;
    while product(plus(hi)) < 1.0 {
        hi = 2.0 * hi + 1.0;
    }
    let p0 = product(sigma);
    let linear = (1.0 / p0 - 1.0) / sigma.iter().map(|s| 1.0 / (s * s)).sum::<f64>();
    let mut l = if smallest > 0.0 && linear > lo && linear < hi { linear } else { 0.5 * (lo + hi) };
    for _ in 0..100 {
        let s = plus(l);
        let p = product(s);
        let phi = p - 1.0;
        if phi.abs() < 1e-15 {
            return s;
        }
        if phi < 0.0 {
            lo = l;
        } else {
            hi = l;
        }
        // φ' = Π σ'_i · Σ σ'_i' / σ'_i with σ'_i' = 1 / (2σ'_i - σ_i).
        let dphi = p * (0..3).map(|i| 1.0 / ((2.0 * s[i] - sigma[i]) * s[i])).sum::<f64>();
        let newton = l - phi / dphi;
        l = if newton > lo && newton < hi && dphi.is_finite() { newton } else { 0.5 * (lo + hi) };
        if hi - lo <= 1e-16 * (1.0 + hi.abs()) {
            break;
        }
    }
    plus(l)
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
/// strain share `r` in [0, 1].
pub fn project(f: &Mat3, strain_share: f64) -> Mat3 {
    let d = svd3(f);
    let blend = if strain_share >= 1.0 {
        [1.0; 3]
    } else {
        let s = volume_preserving(d.sigma);
        s.map(|v| strain_share + (1.0 - strain_share) * v)
    };
    scaled_product(&d.u, blend, &d.v)
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

/// [`project`] and its derivative at `f`.
pub fn project_with_jacobian(f: &Mat3, strain_share: f64) -> (Mat3, ProjectionJacobian) {
    let d = svd3(f);
    let r = strain_share;
    let sigma = d.sigma;
    let mut diag = [[0.0; 3]; 3];
    let mut sym = [0.0; 3];
    let p = if r >= 1.0 {
        [1.0; 3]
    } else {
        let s = volume_preserving(sigma);
        // ∂σ'_i/∂σ_j = (σ'_i δ_ij - (1/a_j) / Σ_k 1/(a_k σ'_k)) / a_i, a_i = 2σ'_i - σ_i.
        let a = [0, 1, 2].map(|i| 2.0 * s[i] - sigma[i]);
        let c = 1.0 / (0..3).map(|k| 1.0 / (a[k] * s[k])).sum::<f64>();
        for i in 0..3 {
            for j in 0..3 {
                let ds = ((if i == j { s[i] } else { 0.0 }) - c / a[j]) / a[i];
                diag[i][j] = (1.0 - r) * ds;
            }
        }
        for (k, &(i, j)) in PAIRS.iter().enumerate() {
            sym[k] = (1.0 - r) * s[j] / (s[i] + s[j] - sigma[i]);
        }
        s.map(|v| r + (1.0 - r) * v)
    };
    let mut anti = [0.0; 3];
    for (k, &(i, j)) in PAIRS.iter().enumerate() {
        let den = sigma[i] + sigma[j];
        // σ_i + σ_j = 0 only for an inverted element with |σ3| = σ2: the rotation is not
        // differentiable there; a bounded factor keeps the product finite.
        let den = if den.abs() < 1e-12 { 1e-12f64.copysign(den) } else { den };
        anti[k] = (p[i] + p[j]) / den;
    }
    (scaled_product(&d.u, p, &d.v), ProjectionJacobian { u: d.u, v: d.v, diag, sym, anti })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::mat3::{det, distance, mul, mul_transpose, IDENTITY};
    use crate::physics::svd3::tests::Rng;

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
        let mut rng = Rng(7);
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
        let mut rng = Rng(11);
        for _ in 0..200 {
            let s = sorted([1.0 + 0.7 * rng.next(), 1.0 + 0.7 * rng.next(), 1.0 + 0.7 * rng.next()]);
            let p = volume_preserving(s);
            let b = brute_force(s);
            assert!(dist2(p, s) <= dist2(b, s) + 1e-10, "{s:?}: ours {p:?} {} vs brute {b:?} {}", dist2(p, s), dist2(b, s));
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
        let mut rng = Rng(17);
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
        let mut rng = Rng(3);
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
