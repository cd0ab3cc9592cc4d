//! Rigid transforms of the anchor: the best-fit rotation and translation between two point
//! sets (Kabsch), unit quaternions, and their interpolation (slerp; for more than two targets
//! the weighted spherical mean, which is slerp when two weights are nonzero).
//!
//! A [`Rigid`] turns about a fixed centre `c` (the anchor's centroid in target 0) and then
//! translates: `T(x) = R (x - c) + c + t`. Interpolating `t` linearly then moves the anchor's
//! centroid on a straight line while it turns about itself; with rotations about the origin a
//! linear `t` would swing the centroid on an arc as well.

use crate::algorithms::geometry::{add, sub, Point};
use crate::algorithms::physics::mat3::{self, Mat3};
use crate::algorithms::physics::svd3::svd3;

/// A unit quaternion `w + xi + yj + zk` (a rotation).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Quaternion {
    /// Scalar part.
    pub w: f64,
    /// Vector part `(x, y, z)`.
    pub v: [f64; 3],
}

impl Quaternion {
    /// The identity rotation.
    pub(crate) const IDENTITY: Quaternion = Quaternion { w: 1.0, v: [0.0; 3] };

    /// Dot product as 4-vectors: for unit quaternions, `±cos(θ/2)` of the rotation `θ` between
    /// them (negative when `o` is in the opposite hemisphere).
    pub fn dot(&self, o: &Quaternion) -> f64 {
        self.w * o.w + self.v[0] * o.v[0] + self.v[1] * o.v[1] + self.v[2] * o.v[2]
    }

    fn scaled(&self, s: f64) -> Quaternion {
        Quaternion { w: s * self.w, v: self.v.map(|c| s * c) }
    }

    fn normalized(&self) -> Quaternion {
        self.scaled(1.0 / self.dot(self).sqrt())
    }

    /// `w - v`: the inverse rotation of a unit quaternion.
    pub fn conjugate(&self) -> Quaternion {
        Quaternion { w: self.w, v: self.v.map(|c| -c) }
    }

    /// The Hamilton product `self · o`: the rotation `o` followed by `self`.
    pub fn mul(&self, o: &Quaternion) -> Quaternion {
        let (a, b) = (self.v, o.v);
        Quaternion {
            w: self.w * o.w - (a[0] * b[0] + a[1] * b[1] + a[2] * b[2]),
            v: [
                self.w * b[0] + o.w * a[0] + a[1] * b[2] - a[2] * b[1],
                self.w * b[1] + o.w * a[1] + a[2] * b[0] - a[0] * b[2],
                self.w * b[2] + o.w * a[2] + a[0] * b[1] - a[1] * b[0],
            ],
        }
    }

    /// The rotation of a proper rotation matrix (Shepperd's method: the largest of the four
    /// diagonal combinations is the pivot, so no division by a small number).
    pub(crate) fn from_matrix(r: &Mat3) -> Quaternion {
        let trace = r[0][0] + r[1][1] + r[2][2];
        let q = if trace >= r[0][0].max(r[1][1]).max(r[2][2]) {
            let s = 2.0 * (1.0 + trace).sqrt();
            Quaternion { w: s / 4.0, v: [(r[2][1] - r[1][2]) / s, (r[0][2] - r[2][0]) / s, (r[1][0] - r[0][1]) / s] }
        } else if r[0][0] >= r[1][1] && r[0][0] >= r[2][2] {
            let s = 2.0 * (1.0 + r[0][0] - r[1][1] - r[2][2]).sqrt();
            Quaternion { w: (r[2][1] - r[1][2]) / s, v: [s / 4.0, (r[0][1] + r[1][0]) / s, (r[0][2] + r[2][0]) / s] }
        } else if r[1][1] >= r[2][2] {
            let s = 2.0 * (1.0 + r[1][1] - r[0][0] - r[2][2]).sqrt();
            Quaternion { w: (r[0][2] - r[2][0]) / s, v: [(r[0][1] + r[1][0]) / s, s / 4.0, (r[1][2] + r[2][1]) / s] }
        } else {
            let s = 2.0 * (1.0 + r[2][2] - r[0][0] - r[1][1]).sqrt();
            Quaternion { w: (r[1][0] - r[0][1]) / s, v: [(r[0][2] + r[2][0]) / s, (r[1][2] + r[2][1]) / s, s / 4.0] }
        };
        q.normalized()
    }

    /// The rotation matrix of a unit quaternion (acting on column vectors).
    pub(crate) fn to_matrix(self) -> Mat3 {
        let (w, [x, y, z]) = (self.w, self.v);
        [
            [1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - w * z), 2.0 * (x * z + w * y)],
            [2.0 * (x * y + w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - w * x)],
            [2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y)],
        ]
    }

    /// `log`: the rotation vector / 2 (axis times half-angle) of a unit quaternion with `w >= 0`.
    fn log(&self) -> [f64; 3] {
        let s = (self.v[0] * self.v[0] + self.v[1] * self.v[1] + self.v[2] * self.v[2]).sqrt();
        if s < 1e-300 {
            return [0.0; 3];
        }
        let half_angle = s.atan2(self.w);
        self.v.map(|c| c * half_angle / s)
    }

    /// `exp` of a half rotation vector (inverse of [`Quaternion::log`]).
    fn exp(h: [f64; 3]) -> Quaternion {
        let a = (h[0] * h[0] + h[1] * h[1] + h[2] * h[2]).sqrt();
        if a < 1e-300 {
            return Quaternion::IDENTITY;
        }
        let (s, c) = a.sin_cos();
        Quaternion { w: c, v: h.map(|x| x * s / a) }
    }

    /// Spherical linear interpolation from `self` (t = 0) to `o` (t = 1) along the shorter arc.
    pub fn slerp(&self, o: &Quaternion, t: f64) -> Quaternion {
        let o = if self.dot(o) < 0.0 { o.scaled(-1.0) } else { *o };
        // self * exp(t log(self⁻¹ o)): exact at t = 0 and stable for nearby rotations.
        let mut rel = self.conjugate().mul(&o);
        if rel.w < 0.0 {
            rel = rel.scaled(-1.0);
        }
        let h = rel.log().map(|c| t * c);
        self.mul(&Quaternion::exp(h)).normalized()
    }

    /// Weighted spherical mean (Karcher mean on the unit-quaternion sphere, each `q` taken in
    /// the hemisphere of `qs[0]`): the rotation minimizing `Σ w_j angle(q, q_j)²`. Weights are
    /// convex. Zero weights are skipped, so a mean with one nonzero weight is that rotation and
    /// with two it is their slerp (exactly: it is computed as one).
    pub fn weighted_mean(qs: &[Quaternion], weights: &[f64]) -> Quaternion {
        let reference = qs[0];
        let used: Vec<(Quaternion, f64)> =
            qs.iter().zip(weights).filter(|(_, &w)| w != 0.0).map(|(q, &w)| (if q.dot(&reference) < 0.0 { q.scaled(-1.0) } else { *q }, w)).collect();
        match used.as_slice() {
            [] => Quaternion::IDENTITY,
            [(q, _)] => *q,
            [(a, wa), (b, wb)] => a.slerp(b, wb / (wa + wb)),
            _ => {
                // Gauss-Newton on the sphere from the heaviest rotation (ties: the first).
                let mut mean = used.iter().fold(used[0], |best, &c| if c.1 > best.1 { c } else { best }).0;
                let total: f64 = used.iter().map(|(_, w)| w).sum();
                for _ in 0..100 {
                    let mut step = [0.0; 3];
                    for (q, w) in &used {
                        let mut rel = mean.conjugate().mul(q);
                        if rel.w < 0.0 {
                            rel = rel.scaled(-1.0);
                        }
                        let l = rel.log();
                        for c in 0..3 {
                            step[c] += w / total * l[c];
                        }
                    }
                    mean = mean.mul(&Quaternion::exp(step)).normalized();
                    if step.iter().map(|c| c * c).sum::<f64>().sqrt() < 1e-15 {
                        break;
                    }
                }
                mean
            }
        }
    }
}

/// `T(x) = R (x - centre) + centre + translation`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rigid {
    /// The rotation `R` about `centre`.
    pub rotation: Quaternion,
    /// The fixed point of the rotation (the anchor's centroid in target 0).
    pub centre: Point,
    /// Applied after the rotation.
    pub translation: Point,
}

impl Rigid {
    /// No motion, about `centre`.
    pub fn identity(centre: Point) -> Rigid {
        Rigid { rotation: Quaternion::IDENTITY, centre, translation: [0.0; 3] }
    }

    /// `T(x) = R (x - centre) + centre + translation`.
    pub fn apply(&self, x: Point) -> Point {
        let r = self.rotation.to_matrix();
        add(add(mat_vec(&r, sub(x, self.centre)), self.centre), self.translation)
    }

    /// `T⁻¹(y) = Rᵀ (y - centre - translation) + centre`.
    pub fn apply_inverse(&self, y: Point) -> Point {
        let rt = mat3::transpose(&self.rotation.to_matrix());
        add(mat_vec(&rt, sub(sub(y, self.centre), self.translation)), self.centre)
    }

    /// A direction mapped back (the inverse rotation, no translation).
    pub(crate) fn rotate_inverse(&self, v: Point) -> Point {
        mat_vec(&mat3::transpose(&self.rotation.to_matrix()), v)
    }

    /// The best-fit rigid motion taking `from` to `to` about the centroid `centre` of `from`
    /// (Kabsch): the rotation maximizing `Σ (q_i - q̄)ᵀ R (p_i - p̄)`, which is the closest
    /// rotation (polar factor) to `M = Σ (q_i - q̄)(p_i - p̄)ᵀ`, and the translation that maps
    /// `p̄` to `q̄`. `None` when the points lie on a line (the rotation about it is undetermined).
    pub(crate) fn best_fit(from: &[Point], to: &[Point]) -> Option<Rigid> {
        assert_eq!(from.len(), to.len());
        let (p_bar, q_bar) = (centroid(from), centroid(to));
        let mut m = [[0.0; 3]; 3];
        for (p, q) in from.iter().zip(to) {
            let (p, q) = (sub(*p, p_bar), sub(*q, q_bar));
            for r in 0..3 {
                for c in 0..3 {
                    m[r][c] += q[r] * p[c];
                }
            }
        }
        let svd = svd3(&m);
        // Signed SVD: U, V are proper rotations, so U Vᵀ is the closest rotation even when
        // det M < 0. The rotation is determined when the two largest singular values are
        // nonzero (the points span a plane).
        let scale = svd.sigma[0].abs();
        if svd.sigma[1].is_nan() || svd.sigma[1].abs() <= 1e-12 * scale {
            return None;
        }
        let r = mat3::mul_transpose(&svd.u, &svd.v);
        Some(Rigid { rotation: Quaternion::from_matrix(&r), centre: p_bar, translation: sub(q_bar, p_bar) })
    }

    /// The weighted blend of rigid motions about the same centre: the weighted spherical mean
    /// of the rotations ([`Quaternion::weighted_mean`]: slerp for two) and the weighted mean of
    /// the translations.
    pub fn blend(transforms: &[Rigid], weights: &[f64]) -> Rigid {
        let rotations: Vec<Quaternion> = transforms.iter().map(|t| t.rotation).collect();
        let mut translation = [0.0; 3];
        for (t, &w) in transforms.iter().zip(weights) {
            if w != 0.0 {
                for c in 0..3 {
                    translation[c] += w * t.translation[c];
                }
            }
        }
        Rigid { rotation: Quaternion::weighted_mean(&rotations, weights), centre: transforms[0].centre, translation }
    }
}

/// The mean of `points` (NaN when there are none).
pub fn centroid(points: &[Point]) -> Point {
    let mut c = [0.0; 3];
    for p in points {
        c = add(c, *p);
    }
    c.map(|v| v / points.len() as f64)
}

fn mat_vec(m: &Mat3, v: Point) -> Point {
    std::array::from_fn(|r| m[r][0] * v[0] + m[r][1] * v[1] + m[r][2] * v[2])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::algorithms::geometry::norm;
    use crate::support::testing::Rng;

    fn rotation_about(axis: Point, angle: f64) -> Quaternion {
        let n = norm(axis);
        let (s, c) = (angle / 2.0).sin_cos();
        Quaternion { w: c, v: axis.map(|a| a / n * s) }
    }

    fn angle_between(a: &Quaternion, b: &Quaternion) -> f64 {
        2.0 * a.dot(b).abs().min(1.0).acos()
    }

    #[test]
    fn matrix_round_trip_for_every_pivot_branch() {
        let mut rng = Rng::new(5);
        for case in 0..400 {
            // Angles up to pi exercise all four branches of Shepperd's method.
            let axis = [rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0)];
            let q = rotation_about(axis, rng.uniform(0.0, std::f64::consts::PI) * if case % 2 == 0 { 1.0 } else { 0.999 });
            let back = Quaternion::from_matrix(&q.to_matrix());
            assert!(angle_between(&q, &back) < 1e-7, "case {case}: {q:?} vs {back:?}");
            let (r, rb) = (q.to_matrix(), back.to_matrix());
            assert!((0..9).all(|k| (r[k / 3][k % 3] - rb[k / 3][k % 3]).abs() < 1e-14), "case {case}");
        }
    }

    #[test]
    fn slerp_moves_at_constant_angular_speed_along_the_short_arc() {
        let a = rotation_about([0.0, 0.0, 1.0], 0.3);
        let b = rotation_about([1.0, 1.0, 0.0], 2.0);
        let total = angle_between(&a, &b);
        for t in [0.0, 0.25, 0.5, 0.9, 1.0] {
            let s = a.slerp(&b, t);
            assert!((angle_between(&a, &s) - t * total).abs() < 1e-12, "t {t}");
            assert!((angle_between(&s, &b) - (1.0 - t) * total).abs() < 1e-12, "t {t}");
        }
        // -b is the same rotation: the result does not change.
        let minus_b = Quaternion { w: -b.w, v: b.v.map(|c| -c) };
        assert!(angle_between(&a.slerp(&b, 0.4), &a.slerp(&minus_b, 0.4)) < 1e-12);
        assert!(angle_between(&a.slerp(&b, 0.0), &a) < 1e-15);
    }

    #[test]
    fn weighted_mean_is_slerp_for_two_and_stationary_for_three() {
        let qs = [Quaternion::IDENTITY, rotation_about([0.0, 1.0, 0.0], 1.2), rotation_about([1.0, 0.0, 0.2], 0.7)];
        assert_eq!(Quaternion::weighted_mean(&qs, &[0.3, 0.7, 0.0]), qs[0].slerp(&qs[1], 0.7));
        assert_eq!(Quaternion::weighted_mean(&qs, &[0.0, 0.0, 1.0]), qs[2]);
        // Three: the weighted sum of the logs at the mean vanishes (first-order optimality).
        let w = [0.2, 0.5, 0.3];
        let m = Quaternion::weighted_mean(&qs, &w);
        let mut g = [0.0; 3];
        for (q, wi) in qs.iter().zip(w) {
            let l = m.conjugate().mul(q).log();
            (0..3).for_each(|c| g[c] += wi * l[c]);
        }
        assert!(norm(g) < 1e-14, "{g:?}");
    }

    #[test]
    fn best_fit_recovers_a_rigid_motion_and_inverts() {
        let mut rng = Rng::new(9);
        let from: Vec<Point> = (0..7).map(|_| [rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0)]).collect();
        let truth = Rigid { rotation: rotation_about([0.2, -1.0, 0.5], 2.5), centre: centroid(&from), translation: [1.0, -2.0, 0.5] };
        let to: Vec<Point> = from.iter().map(|&p| truth.apply(p)).collect();
        let fit = Rigid::best_fit(&from, &to).unwrap();
        assert!(angle_between(&fit.rotation, &truth.rotation) < 1e-10);
        for (p, q) in from.iter().zip(&to) {
            assert!(norm(sub(fit.apply(*p), *q)) < 1e-12);
            assert!(norm(sub(fit.apply_inverse(*q), *p)) < 1e-12);
        }
        // Collinear points: the rotation about their line is undetermined.
        let line: Vec<Point> = (0..4).map(|i| [i as f64, 2.0 * i as f64, 0.0]).collect();
        assert!(Rigid::best_fit(&line, &line).is_none());
        // A mirror image gets the best proper rotation, not the reflection.
        let mirrored: Vec<Point> = from.iter().map(|p| [-p[0], p[1], p[2]]).collect();
        let r = Rigid::best_fit(&from, &mirrored).unwrap().rotation.to_matrix();
        assert!((mat3::det(&r) - 1.0).abs() < 1e-12);
    }
}
