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

use super::mat3::{mul, Mat3};

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Svd3 {
    pub u: Mat3,
    pub sigma: [f64; 3],
    pub v: Mat3,
}

/// Columns of a row-major matrix.
#[inline]
fn col(m: &Mat3, j: usize) -> [f64; 3] {
    [m[0][j], m[1][j], m[2][j]]
}

#[inline]
fn set_col(m: &mut Mat3, j: usize, c: [f64; 3]) {
    for i in 0..3 {
        m[i][j] = c[i];
    }
}

#[inline]
fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

#[inline]
fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

/// A unit vector orthogonal to the unit vector `a`.
fn any_orthogonal(a: [f64; 3]) -> [f64; 3] {
    // Cross with the axis least aligned with a.
    let axis = if a[0].abs() <= a[1].abs() && a[0].abs() <= a[2].abs() {
        [1.0, 0.0, 0.0]
    } else if a[1].abs() <= a[2].abs() {
        [0.0, 1.0, 0.0]
    } else {
        [0.0, 0.0, 1.0]
    };
    let c = cross(a, axis);
    let n = dot(c, c).sqrt();
    [c[0] / n, c[1] / n, c[2] / n]
}

/// Eigen-decomposition of a symmetric matrix by cyclic Jacobi rotations: returns the
/// eigenvalues and the eigenvectors as columns of a rotation matrix. Only the six distinct
/// entries are updated; sweeps stop once the off-diagonal part is negligible relative to the
/// diagonal (typically 2 to 4 sweeps).
fn symmetric_eigen(s: Mat3) -> ([f64; 3], Mat3) {
    let mut v = super::mat3::IDENTITY;
    // d: diagonal; o: off-diagonal entries (0,1), (0,2), (1,2).
    let mut d = [s[0][0], s[1][1], s[2][2]];
    let mut o = [s[0][1], s[0][2], s[1][2]];
    for _sweep in 0..12 {
        let off = o[0] * o[0] + o[1] * o[1] + o[2] * o[2];
        let scale = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
        if off <= 1e-30 * scale || off == 0.0 {
            break;
        }
        // Planes (p, q) with their off-diagonal slot, and the slots (r, p) and (r, q) of the
        // third index r.
        for (p, q, pq, rp, rq) in [(0, 1, 0, 1, 2), (0, 2, 1, 0, 2), (1, 2, 2, 0, 1)] {
            let apq = o[pq];
            if apq == 0.0 {
                continue;
            }
            // Rotation that zeroes (p, q) (Golub & Van Loan, sym.schur2).
            let theta = (d[q] - d[p]) / (2.0 * apq);
            let t = if theta == 0.0 { 1.0 } else { theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt()) };
            let c = 1.0 / (t * t + 1.0).sqrt();
            let sn = t * c;
            d[p] -= t * apq;
            d[q] += t * apq;
            o[pq] = 0.0;
            let (arp, arq) = (o[rp], o[rq]);
            o[rp] = c * arp - sn * arq;
            o[rq] = sn * arp + c * arq;
            for row in v.iter_mut() {
                let (vp, vq) = (row[p], row[q]);
                row[p] = c * vp - sn * vq;
                row[q] = sn * vp + c * vq;
            }
        }
    }
    (d, v)
}

/// Signed SVD of `f` (see the module documentation).
pub fn svd3(f: &Mat3) -> Svd3 {
    let ftf = super::mat3::mul(&super::mat3::transpose(f), f);
    let (lambda, v0) = symmetric_eigen(ftf);
    // Sort eigenpairs by decreasing eigenvalue.
    let mut order = [0usize, 1, 2];
    order.sort_by(|&a, &b| lambda[b].total_cmp(&lambda[a]));
    let mut v = [[0.0; 3]; 3];
    for (j, &o) in order.iter().enumerate() {
        set_col(&mut v, j, col(&v0, o));
    }
    if super::mat3::det(&v) < 0.0 {
        let c = col(&v, 2);
        set_col(&mut v, 2, [-c[0], -c[1], -c[2]]);
    }
    // QR of B = F V by Gram-Schmidt: B = U R, diag(R) = σ (the last one signed).
    let b = mul(f, &v);
    let (b1, b2, b3) = (col(&b, 0), col(&b, 1), col(&b, 2));
    let scale = dot(b1, b1).sqrt().max(dot(b2, b2).sqrt()).max(dot(b3, b3).sqrt());
    let tiny = 1e-300_f64.max(scale * 1e-15);
    let s1 = dot(b1, b1).sqrt();
    let u1 = if s1 > tiny { [b1[0] / s1, b1[1] / s1, b1[2] / s1] } else { col(&v, 0) };
    let r12 = dot(u1, b2);
    let w2 = [b2[0] - r12 * u1[0], b2[1] - r12 * u1[1], b2[2] - r12 * u1[2]];
    let s2 = dot(w2, w2).sqrt();
    let u2 = if s2 > tiny { [w2[0] / s2, w2[1] / s2, w2[2] / s2] } else { any_orthogonal(u1) };
    let u3 = cross(u1, u2);
    let s3 = dot(u3, b3);
    let mut u = [[0.0; 3]; 3];
    set_col(&mut u, 0, u1);
    set_col(&mut u, 1, u2);
    set_col(&mut u, 2, u3);
    Svd3 { u, sigma: [s1, if s2 > tiny { s2 } else { 0.0 }, s3], v }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::physics::mat3::{det, distance, mul_transpose, scaled_product, transpose, IDENTITY};

    /// A small deterministic generator for test matrices (xorshift).
    pub(crate) struct Rng(pub u64);
    impl Rng {
        pub fn next(&mut self) -> f64 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            (self.0 >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
        }
        pub fn mat(&mut self) -> Mat3 {
            [[self.next(), self.next(), self.next()], [self.next(), self.next(), self.next()], [self.next(), self.next(), self.next()]]
        }
    }

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
