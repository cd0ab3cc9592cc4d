//! Signed singular value decomposition of a 3x3 matrix: `F = U diag(σ) Vᵀ` with `U`, `V`
//! proper rotations (det +1), `σ1 >= σ2 >= |σ3|`, and `σ3 < 0` exactly when `det F < 0`.
//!
//! The signed form is what projective dynamics needs: `U Vᵀ` is then the rotation closest to
//! `F` even for inverted elements, and the sign of `σ3` tells a volume projection that the
//! element is inside out.
//!
//! Method: cyclic Jacobi on `FᵀF` gives `V`; a Gram-Schmidt QR of `F V` gives `U` and the
//! signed singular values (so small `σ` are read off `F` directly, not as square roots of
//! small eigenvalues).
//!
//! Speed: one decomposition is a chain of dependent square roots and divisions (latency bound,
//! ~370 ns), so the local step decomposes [`BATCH`] matrices at once
//! ([`svd_lanes`]): the same code runs on lanes ([`super::lanes`]: `[f64; N]` arithmetic that
//! the compiler turns into SIMD, AVX-512 or AVX2 chosen at run time), every branch a per-lane
//! select and the Jacobi sweeps continuing until the slowest lane has converged while converged
//! lanes stay frozen. Each lane does exactly the operations [`svd3`] does on its own (which is
//! the same code with one lane; no fused multiply-adds are ever generated), so a matrix gets the
//! same bytes whichever path and batch it goes through.

use super::lanes::{cross, det, dot, lane, mul_lanes, select3, to_lanes, Lanes, Mask, M3, V3};
use super::lanes::{with_widest_simd, BATCH};
use super::mat3::Mat3;

#[derive(Debug, Clone, Copy, PartialEq)]
/// `F = U diag(sigma) Vᵀ`, see the module documentation.
pub struct Svd3 {
    pub u: Mat3,
    pub sigma: [f64; 3],
    pub v: Mat3,
}

/// A unit vector orthogonal to the unit vector `a` (cross with the axis least aligned with a).
#[inline(always)]
fn any_orthogonal<const N: usize>(a: V3<N>) -> V3<N> {
    let (x, y, z) = (a[0].abs(), a[1].abs(), a[2].abs());
    let pick_x = x.le(y) & x.le(z);
    let pick_y = !pick_x & y.le(z);
    let pick_z = !pick_x & !pick_y;
    let (one, zero) = (Lanes::splat(1.0), Lanes::splat(0.0));
    let axis = [Lanes::select(pick_x, one, zero), Lanes::select(pick_y, one, zero), Lanes::select(pick_z, one, zero)];
    let c = cross(a, axis);
    let n = dot(c, c).sqrt();
    [c[0] / n, c[1] / n, c[2] / n]
}

/// Jacobi planes `(p, q)` with the slot of their off-diagonal entry and the slots `(r, p)` and
/// `(r, q)` of the third index `r` (off-diagonal slots: (0,1), (0,2), (1,2)).
const PLANES: [(usize, usize, usize, usize, usize); 3] = [(0, 1, 0, 1, 2), (0, 2, 1, 0, 2), (1, 2, 2, 0, 1)];

/// Eigen-decomposition of the symmetric lane matrices with diagonal `d` and off-diagonal `o` by
/// cyclic Jacobi rotations: eigenvalues, and eigenvectors as the columns of a rotation. Only the
/// six distinct entries are updated; a lane stops once its off-diagonal part is negligible
/// relative to its diagonal (typically 2 to 4 sweeps).
#[inline(always)]
fn symmetric_eigen<const N: usize>(mut d: V3<N>, mut o: V3<N>) -> (V3<N>, M3<N>) {
    let (zero, one) = (Lanes::splat(0.0), Lanes::splat(1.0));
    let mut v = [[one, zero, zero], [zero, one, zero], [zero, zero, one]];
    let mut active = Mask::splat(true);
    for _sweep in 0..12 {
        let off = o[0] * o[0] + o[1] * o[1] + o[2] * o[2];
        let scale = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
        active = active & !(off.le(Lanes::splat(1e-30) * scale) | off.eq(zero));
        if !active.any() {
            break;
        }
        for (p, q, pq, rp, rq) in PLANES {
            let apq = o[pq];
            let go = active & !apq.eq(zero);
            // Rotation that zeroes (p, q) (Golub & Van Loan, sym.schur2).
            let theta = (d[q] - d[p]) / (Lanes::splat(2.0) * apq);
            let t = Lanes::select(
                theta.eq(zero),
                one,
                theta.sign() / (theta.abs() + (theta * theta + one).sqrt()),
            );
            let c = one / (t * t + one).sqrt();
            let sn = t * c;
            d[p] = Lanes::select(go, d[p] - t * apq, d[p]);
            d[q] = Lanes::select(go, d[q] + t * apq, d[q]);
            o[pq] = Lanes::select(go, zero, o[pq]);
            let (arp, arq) = (o[rp], o[rq]);
            o[rp] = Lanes::select(go, c * arp - sn * arq, arp);
            o[rq] = Lanes::select(go, sn * arp + c * arq, arq);
            for row in v.iter_mut() {
                let (vp, vq) = (row[p], row[q]);
                row[p] = Lanes::select(go, c * vp - sn * vq, vp);
                row[q] = Lanes::select(go, sn * vp + c * vq, vq);
            }
        }
    }
    (d, v)
}

/// `(FᵀF)_ij`.
#[inline(always)]
fn gram<const N: usize>(f: &M3<N>, i: usize, j: usize) -> Lanes<N> {
    f[0][i] * f[0][j] + f[1][i] * f[1][j] + f[2][i] * f[2][j]
}

#[inline(always)]
fn column<const N: usize>(m: &M3<N>, j: usize) -> V3<N> {
    [m[0][j], m[1][j], m[2][j]]
}

/// The signed SVD of lane matrices (see the module documentation).
#[inline(always)]
pub(crate) fn svd_lanes<const N: usize>(f: &M3<N>) -> (M3<N>, V3<N>, M3<N>) {
    // FᵀF: its diagonal and the off-diagonal entries (0,1), (0,2), (1,2).
    let (d, o) = ([gram(f, 0, 0), gram(f, 1, 1), gram(f, 2, 2)], [gram(f, 0, 1), gram(f, 0, 2), gram(f, 1, 2)]);
    let (lambda, mut v) = symmetric_eigen(d, o);
    // Sort eigenpairs by decreasing eigenvalue: a stable bubble sort over (0,1), (1,2), (0,1).
    let mut l = lambda;
    for (i, j) in [(0, 1), (1, 2), (0, 1)] {
        let swap = l[j].gt(l[i]);
        (l[i], l[j]) = (Lanes::select(swap, l[j], l[i]), Lanes::select(swap, l[i], l[j]));
        for row in v.iter_mut() {
            (row[i], row[j]) = (Lanes::select(swap, row[j], row[i]), Lanes::select(swap, row[i], row[j]));
        }
    }
    let flip = det(&v).lt(Lanes::splat(0.0));
    for row in v.iter_mut() {
        row[2] = Lanes::select(flip, -row[2], row[2]);
    }
    // QR of B = F V by Gram-Schmidt: B = U R, diag(R) = σ (the last one signed).
    let b = mul_lanes(f, &v);
    let (b1, b2, b3) = (column(&b, 0), column(&b, 1), column(&b, 2));
    let scale = dot(b1, b1).sqrt().max(dot(b2, b2).sqrt()).max(dot(b3, b3).sqrt());
    let tiny = Lanes::splat(1e-300).max(scale * Lanes::splat(1e-15));
    let s1 = dot(b1, b1).sqrt();
    let u1 = select3(s1.gt(tiny), [b1[0] / s1, b1[1] / s1, b1[2] / s1], column(&v, 0));
    let r12 = dot(u1, b2);
    let w2 = [b2[0] - r12 * u1[0], b2[1] - r12 * u1[1], b2[2] - r12 * u1[2]];
    let s2 = dot(w2, w2).sqrt();
    let full = s2.gt(tiny);
    let u2 = select3(full, [w2[0] / s2, w2[1] / s2, w2[2] / s2], any_orthogonal(u1));
    let u3 = cross(u1, u2);
    let s3 = dot(u3, b3);
    let u = [[u1[0], u2[0], u3[0]], [u1[1], u2[1], u3[1]], [u1[2], u2[2], u3[2]]];
    (u, [s1, Lanes::select(full, s2, Lanes::splat(0.0)), s3], v)
}

/// Signed SVD of `f` (see the module documentation).
pub fn svd3(f: &Mat3) -> Svd3 {
    let (u, sigma, v) = svd_lanes::<1>(&to_lanes(&[*f]));
    Svd3 { u: lane(&u, 0), sigma: [sigma[0].0[0], sigma[1].0[0], sigma[2].0[0]], v: lane(&v, 0) }
}

/// [`svd3`] of [`BATCH`] matrices at once (bit-identical to it, lane by lane). The batched
/// kernels (the local step, the timing derivatives) run [`svd_lanes`] inside themselves; this
/// entry point is for callers that need the decompositions themselves.
#[cfg_attr(not(test), allow(dead_code))]
pub fn svd3_batch(f: &[Mat3; BATCH]) -> [Svd3; BATCH] {
    let (u, sigma, v) = dispatch_svd(&to_lanes(f));
    std::array::from_fn(|l| Svd3 { u: lane(&u, l), sigma: [sigma[0].0[l], sigma[1].0[l], sigma[2].0[l]], v: lane(&v, l) })
}

with_widest_simd!(dispatch_svd, fn(f: &M3<BATCH>) -> (M3<BATCH>, V3<BATCH>, M3<BATCH>) { svd_lanes(f) });

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::mat3::{det, distance, mul, mul_transpose, scaled_product, transpose, IDENTITY};
    use crate::testing::Rng;

    fn check(f: &Mat3) {
        let s = svd3(f);
        let scale = f.iter().flatten().fold(0.0f64, |m, x| m.max(x.abs())).max(1e-300);
        assert!(distance(&scaled_product(&s.u, s.sigma, &s.v), f) <= 1e-12 * scale, "reconstruct {f:?} -> {s:?}");
        assert!(distance(&mul_transpose(&s.u, &s.u), &IDENTITY) < 1e-12, "U orthogonal");
        assert!(distance(&mul(&transpose(&s.v), &s.v), &IDENTITY) < 1e-12, "V orthogonal");
        assert!((det(&s.u) - 1.0).abs() < 1e-12 && (det(&s.v) - 1.0).abs() < 1e-12, "proper rotations");
        assert!(s.sigma[0] >= s.sigma[1] - 1e-12 * scale && s.sigma[1] >= s.sigma[2].abs() - 1e-12 * scale, "{:?}", s.sigma);
        let d = det(f);
        if d.abs() > 1e-9 * scale.powi(3) {
            assert_eq!(d < 0.0, s.sigma[2] < 0.0, "sign of σ3 follows det F");
        }
    }

    #[test]
    fn random_matrices_decompose() {
        let mut rng = Rng(0x9e3779b97f4a7c15);
        for _ in 0..2000 {
            check(&rng.mat());
        }
    }

    #[test]
    fn batches_give_the_bytes_of_single_decompositions() {
        let mut rng = Rng(99);
        let mut cases: Vec<Mat3> = (0..40 * BATCH).map(|k| {
            let m = rng.mat();
            // Near rotations (the common case), general, and rank-deficient matrices.
            match k % 3 {
                0 => std::array::from_fn(|i| std::array::from_fn(|j| if i == j { 1.0 } else { 0.0 } + 1e-3 * m[i][j])),
                1 => m,
                _ => [m[0], m[0], m[2]],
            }
        }).collect();
        cases.extend([[[0.0; 3]; 3], IDENTITY, [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]]]);
        cases.resize(cases.len().div_ceil(BATCH) * BATCH, IDENTITY);
        for chunk in cases.chunks_exact(BATCH) {
            let batch: [Mat3; BATCH] = chunk.try_into().unwrap();
            for (f, d) in batch.iter().zip(svd3_batch(&batch)) {
                assert_eq!(d, svd3(f), "{f:?}");
            }
        }
    }

    #[test]
    fn degenerate_and_inverted_matrices_decompose() {
        check(&[[0.0; 3]; 3]);
        check(&IDENTITY);
        check(&[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]]);
        check(&[[2.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 2.0]]);
        check(&[[1.0, 2.0, 3.0], [2.0, 4.0, 6.0], [3.0, 6.0, 9.0]]); // rank 1
        check(&[[1.0, 0.0, 0.0], [0.0, 1e-9, 0.0], [0.0, 0.0, 0.0]]);
        check(&[[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]); // pure rotation
        check(&[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1e-12]]);
    }

    #[test]
    fn rotation_factor_is_the_closest_rotation() {
        // For a rotation R0 and symmetric positive S, polar(R0 S) = R0.
        let r0 = [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]];
        let s = [[2.0, 0.3, 0.0], [0.3, 1.0, 0.1], [0.0, 0.1, 0.5]];
        let f = mul(&r0, &s);
        let d = svd3(&f);
        assert!(distance(&mul_transpose(&d.u, &d.v), &r0) < 1e-12);
    }
}
