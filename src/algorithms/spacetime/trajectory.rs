//! Cubic Hermite trajectories: every vertex moves on a C1 piecewise cubic through keyframe
//! positions `x_i` with keyframe velocities `v_i`.
//!
//! On interval `i` (length `T_i = t_{i+1} - t_i`, local parameter `θ = (t - t_i) / T_i`):
//!
//! ```text
//! x(θ) = h00(θ) x_i + h10(θ) T_i v_i + h01(θ) x_{i+1} + h11(θ) T_i v_{i+1}
//! ```
//!
//! This is the Bézier curve with control points `x_i + T_i v_i / 3` and `x_{i+1} - T_i v_{i+1} / 3`,
//! so `dx/dt` at a key is exactly `v_i` (the paper's eq. 1 writes `T_i v_i`, which makes the key
//! velocity `3 v_i`; storing true velocities is the same curve family, see the reference notes).
//! `v` is always a true velocity in units per second: glTF CUBICSPLINE tangents use the same
//! convention, so exporting is a copy, not a conversion.

use crate::algorithms::geometry::Point;

/// Weights of the four interval unknowns `(x_i, v_i, x_{i+1}, v_{i+1})` in the position,
/// velocity and acceleration at one instant. The `T` factors are included, so for example
/// `position = Σ_j pos[j] * unknown_j` directly.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SlotWeights {
    /// Weights in the position.
    pub pos: [f64; 4],
    /// Weights in the velocity (per second).
    pub vel: [f64; 4],
    /// Weights in the acceleration (per second squared).
    pub acc: [f64; 4],
}

/// Hermite basis weights at local parameter `theta` of an interval of length `t_len > 0`.
pub fn hermite_weights(theta: f64, t_len: f64) -> SlotWeights {
    let s = theta;
    let s2 = s * s;
    let s3 = s2 * s;
    // Values.
    let h00 = 2.0 * s3 - 3.0 * s2 + 1.0;
    let h10 = s3 - 2.0 * s2 + s;
    let h01 = -2.0 * s3 + 3.0 * s2;
    let h11 = s3 - s2;
    // d/dθ.
    let d00 = 6.0 * s2 - 6.0 * s;
    let d10 = 3.0 * s2 - 4.0 * s + 1.0;
    let d01 = -6.0 * s2 + 6.0 * s;
    let d11 = 3.0 * s2 - 2.0 * s;
    // d²/dθ².
    let e00 = 12.0 * s - 6.0;
    let e10 = 6.0 * s - 4.0;
    let e01 = -12.0 * s + 6.0;
    let e11 = 6.0 * s - 2.0;
    let t = t_len;
    SlotWeights { pos: [h00, t * h10, h01, t * h11], vel: [d00 / t, d10, d01 / t, d11], acc: [e00 / (t * t), e10 / t, e01 / (t * t), e11 / t] }
}

/// Powers of `T` in the weights of `(x_i, v_i, x_{i+1}, v_{i+1})` (see [`hermite_weights`]):
/// every weight is a constant times `T^p`, so at fixed `θ` its derivative in `T` is `p / T`
/// times itself.
const POS_POWER: [f64; 4] = [0.0, 1.0, 0.0, 1.0];
const VEL_POWER: [f64; 4] = [-1.0, 0.0, -1.0, 0.0];
const ACC_POWER: [f64; 4] = [-2.0, -1.0, -2.0, -1.0];

/// The first (`order = 1`) or second (`order = 2`) derivative of the weights `w` of an
/// interval of length `t_len` with respect to that length, at fixed `θ` (the instant moves with
/// the interval).
pub(crate) fn length_derivative(w: &SlotWeights, t_len: f64, order: u32) -> SlotWeights {
    let d = |weights: &[f64; 4], powers: &[f64; 4]| -> [f64; 4] {
        std::array::from_fn(|j| {
            let p = powers[j];
            let factor = if order == 1 { p / t_len } else { p * (p - 1.0) / (t_len * t_len) };
            factor * weights[j]
        })
    };
    SlotWeights { pos: d(&w.pos, &POS_POWER), vel: d(&w.vel, &VEL_POWER), acc: d(&w.acc, &ACC_POWER) }
}

/// The interval of non-decreasing key `times` (at least two) containing `t`, clamped to
/// the key range, and the local parameter `θ` in it: at a key, the interval it starts (never a
/// zero-length interval: at a contact, the interval after it).
pub fn locate(times: &[f64], t: f64) -> (usize, f64) {
    let n = times.len();
    let t = t.clamp(times[0], times[n - 1]);
    // Last interval whose start is <= t.
    let i = times[..n - 1].partition_point(|&s| s <= t).saturating_sub(1);
    let len = times[i + 1] - times[i];
    let theta = if len > 0.0 { ((t - times[i]) / len).clamp(0.0, 1.0) } else { 0.0 };
    (i, theta)
}

/// Keyframe positions and velocities of every vertex, on a shared set of key times.
///
/// Invariants: `positions.len() == velocities.len() == times.len() >= 2`, every key has the same
/// vertex count, and `times` is non-decreasing: two equal consecutive times are a contact, two
/// keys with the same positions and separate velocities (the velocity jumps there), never at
/// the first or last key and never two in a row.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Trajectory {
    /// Key times in seconds.
    pub times: Vec<f64>,
    /// `positions[key][vertex]`.
    pub positions: Vec<Vec<Point>>,
    /// `velocities[key][vertex]`, true `dx/dt` in units per second.
    pub velocities: Vec<Vec<Point>>,
}

impl Trajectory {
    /// The geometric baseline: keyframes joined with zero velocities ("hermite" method).
    pub(crate) fn with_zero_velocities(times: Vec<f64>, positions: Vec<Vec<Point>>) -> Self {
        let velocities = positions.iter().map(|p| vec![[0.0; 3]; p.len()]).collect();
        Trajectory { times, positions, velocities }
    }

    /// Number of keys.
    pub fn key_count(&self) -> usize {
        self.times.len()
    }

    /// Vertices per key.
    pub fn vertex_count(&self) -> usize {
        self.positions.first().map_or(0, Vec::len)
    }

    /// Time of the first key.
    pub fn start(&self) -> f64 {
        self.times[0]
    }

    /// Time of the last key.
    pub fn end(&self) -> f64 {
        *self.times.last().expect("a trajectory has keys")
    }

    /// Seconds from the first key to the last.
    pub fn duration(&self) -> f64 {
        self.end() - self.start()
    }

    /// The interval containing `t` (clamped to the key range) and the local parameter in it:
    /// at a key, the interval it starts.
    pub fn locate(&self, t: f64) -> (usize, f64) {
        locate(&self.times, t)
    }

    /// Positions of all vertices at time `t` (held constant outside the key range).
    pub fn evaluate(&self, t: f64) -> Vec<Point> {
        let mut out = vec![[0.0; 3]; self.vertex_count()];
        self.evaluate_into(t, &mut out);
        out
    }

    /// [`Trajectory::evaluate`] into a caller's buffer.
    pub(crate) fn evaluate_into(&self, t: f64, out: &mut [Point]) {
        let (i, theta) = self.locate(t);
        let w = hermite_weights(theta, self.times[i + 1] - self.times[i]);
        self.combine(i, &w.pos, out);
    }

    /// Velocities of all vertices at time `t`.
    pub fn velocity(&self, t: f64) -> Vec<Point> {
        let (i, theta) = self.locate(t);
        let w = hermite_weights(theta, self.times[i + 1] - self.times[i]);
        let mut out = vec![[0.0; 3]; self.vertex_count()];
        self.combine(i, &w.vel, &mut out);
        out
    }

    /// Accelerations of all vertices at time `t`.
    pub fn acceleration(&self, t: f64) -> Vec<Point> {
        let (i, theta) = self.locate(t);
        let w = hermite_weights(theta, self.times[i + 1] - self.times[i]);
        let mut out = vec![[0.0; 3]; self.vertex_count()];
        self.combine(i, &w.acc, &mut out);
        out
    }

    /// `out = Σ_j w[j] * unknown_j` over the four unknowns of interval `i`.
    fn combine(&self, i: usize, w: &[f64; 4], out: &mut [Point]) {
        let (x0, v0) = (&self.positions[i], &self.velocities[i]);
        let (x1, v1) = (&self.positions[i + 1], &self.velocities[i + 1]);
        for (v, o) in out.iter_mut().enumerate() {
            for d in 0..3 {
                o[d] = w[0] * x0[v][d] + w[1] * v0[v][d] + w[2] * x1[v][d] + w[3] * v1[v][d];
            }
        }
    }

    /// Apply a linear map of vertex arrays (for example an embedding) to every key. A linear
    /// map commutes with the Hermite basis, so the mapped trajectory is exact, not resampled.
    pub(crate) fn map_linear(&self, map: impl Fn(&[Point]) -> Vec<Point>) -> Trajectory {
        Trajectory {
            times: self.times.clone(),
            positions: self.positions.iter().map(|p| map(p)).collect(),
            velocities: self.velocities.iter().map(|v| map(v)).collect(),
        }
    }

    /// Frame instants at `fps` covering the key range: frame numbers `f` with
    /// `start <= f / fps <= end` (within f32 rounding, see [`frames_between`]), and their
    /// times in seconds.
    pub fn frames(&self, fps: f64) -> Vec<(i64, f64)> {
        frames_between(self.start(), self.end(), fps)
    }
}

/// Frame numbers `f` with `start <= f / fps <= end`, with their times in seconds (clamped to
/// `[start, end]`, so the end frames play the end keys exactly).
///
/// Key times often come from f32 (glTF keys, PC2 and MDD headers): `17 / 24` s stored in
/// f32 is 16.9999995 frames in f64, and flooring it would drop the clip's last frame. A frame
/// within `1e-6 max(1, |frame|)` frames of the range is in it: f32 rounds a time by at most
/// 6e-8 of itself, and no frame rate puts two frames that close.
pub fn frames_between(start: f64, end: f64, fps: f64) -> Vec<(i64, f64)> {
    let slack = |frame: f64| (1e-9 * fps).max(1e-6 * frame.abs().max(1.0));
    let (a, b) = (start * fps, end * fps);
    let first = (a - slack(a)).ceil() as i64;
    let last = (b + slack(b)).floor() as i64;
    (first..=last).map(|f| (f, (f as f64 / fps).clamp(start, end))).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn one_vertex(times: Vec<f64>, x: Vec<f64>, v: Vec<f64>) -> Trajectory {
        Trajectory {
            times,
            positions: x.iter().map(|&x| vec![[x, 0.0, 0.0]]).collect(),
            velocities: v.iter().map(|&v| vec![[v, 0.0, 0.0]]).collect(),
        }
    }

    #[test]
    fn an_f32_end_just_under_a_frame_keeps_that_frame() {
        // 17 / 24 s in f32 is 16.9999995 frames at 24 fps; 224 / 30 in f32 is 224.0000076.
        for (frames, fps) in [(18i64, 24.0), (225, 30.0), (18, 30.0), (2, 60.0), (100_000, 24.0)] {
            let end = ((frames - 1) as f64 / fps) as f32 as f64;
            let got = frames_between(0.0, end, fps);
            assert_eq!(got.len() as i64, frames, "{frames} frames at {fps} fps, end {end}");
            // The last frame plays the last key (its time clamped to it when the key is under).
            let last = got[got.len() - 1];
            assert!(last.0 == frames - 1 && (last.1 - end).abs() < 1e-6 && last.1 <= end, "{frames} frames at {fps} fps: {last:?}, end {end}");
            let start = (1.0 / fps) as f32 as f64;
            assert_eq!(frames_between(start, end, fps)[0], (1, start), "{frames} frames at {fps} fps");
        }
        // A range between two frames holds none; half a frame is not rounding.
        assert!(frames_between(0.1 / 24.0, 0.9 / 24.0, 24.0).is_empty());
        assert_eq!(frames_between(0.0, 2.5 / 24.0, 24.0).len(), 3);
    }

    #[test]
    fn interpolates_keys_and_key_velocities() {
        let tr = one_vertex(vec![0.0, 0.5, 2.0], vec![1.0, -2.0, 3.0], vec![0.5, 4.0, -1.0]);
        for k in 0..3 {
            let t = tr.times[k];
            assert!((tr.evaluate(t)[0][0] - tr.positions[k][0][0]).abs() < 1e-14);
            assert!((tr.velocity(t)[0][0] - tr.velocities[k][0][0]).abs() < 1e-12, "key {k}");
        }
    }

    #[test]
    fn cubic_holds_a_parabola_exactly() {
        // x(t) = x0 + u t + g t²/2 is reproduced with x_i = x(t_i), v_i = x'(t_i).
        let (x0, u, g) = (0.3, 1.5, -9.81);
        let x = |t: f64| x0 + u * t + 0.5 * g * t * t;
        let xd = |t: f64| u + g * t;
        let times = vec![0.0, 0.4, 1.1];
        let tr = one_vertex(times.clone(), times.iter().map(|&t| x(t)).collect(), times.iter().map(|&t| xd(t)).collect());
        for k in 0..=50 {
            let t = 1.1 * k as f64 / 50.0;
            assert!((tr.evaluate(t)[0][0] - x(t)).abs() < 1e-13);
            assert!((tr.velocity(t)[0][0] - xd(t)).abs() < 1e-12);
            assert!((tr.acceleration(t)[0][0] - g).abs() < 1e-11);
        }
    }

    #[test]
    fn basis_derivatives_match_finite_differences() {
        let t_len = 0.7;
        let h = 1e-6;
        for k in 1..10 {
            let s = k as f64 / 10.0;
            let (a, b, c) = (hermite_weights(s - h, t_len), hermite_weights(s, t_len), hermite_weights(s + h, t_len));
            for j in 0..4 {
                // d/dt = (1/T) d/dθ.
                let fd_vel = (c.pos[j] - a.pos[j]) / (2.0 * h) / t_len;
                let fd_acc = (c.vel[j] - a.vel[j]) / (2.0 * h) / t_len;
                assert!((fd_vel - b.vel[j]).abs() < 1e-8, "vel slot {j} at {s}");
                assert!((fd_acc - b.acc[j]).abs() < 1e-7, "acc slot {j} at {s}");
            }
        }
    }

    #[test]
    fn length_derivatives_match_finite_differences() {
        let (theta, t, h) = (0.3, 0.7, 1e-5);
        let (a, b, c) = (hermite_weights(theta, t - h), hermite_weights(theta, t), hermite_weights(theta, t + h));
        let (d1, d2) = (length_derivative(&b, t, 1), length_derivative(&b, t, 2));
        for (k, (x, y, z)) in [(a.pos, b.pos, c.pos), (a.vel, b.vel, c.vel), (a.acc, b.acc, c.acc)].into_iter().enumerate() {
            let (e1, e2) = ([d1.pos, d1.vel, d1.acc][k], [d2.pos, d2.vel, d2.acc][k]);
            for j in 0..4 {
                assert!(((z[j] - x[j]) / (2.0 * h) - e1[j]).abs() < 1e-6 * (1.0 + e1[j].abs()), "order 1, kind {k}, slot {j}");
                assert!(((z[j] - 2.0 * y[j] + x[j]) / (h * h) - e2[j]).abs() < 1e-3 * (1.0 + e2[j].abs()), "order 2, kind {k}, slot {j}");
            }
        }
    }

    #[test]
    fn a_contact_is_located_after_it() {
        let tr = one_vertex(vec![0.0, 0.5, 0.5, 1.0], vec![0.0, 1.0, 1.0, 0.0], vec![2.0, 1.0, -1.0, -2.0]);
        assert_eq!(tr.locate(0.5), (2, 0.0));
        assert_eq!(tr.locate(0.4).0, 0);
        assert_eq!(tr.velocity(0.5)[0][0], -1.0, "the velocity leaving the contact");
        assert!((tr.velocity(0.5 - 1e-9)[0][0] - 1.0).abs() < 1e-6, "the velocity arriving");
    }

    #[test]
    fn locate_clamps_and_finds_intervals() {
        let tr = one_vertex(vec![0.0, 1.0, 3.0], vec![0.0; 3], vec![0.0; 3]);
        assert_eq!(tr.locate(-1.0), (0, 0.0));
        assert_eq!(tr.locate(0.5), (0, 0.5));
        assert_eq!(tr.locate(1.0), (1, 0.0));
        assert_eq!(tr.locate(2.0), (1, 0.5));
        assert_eq!(tr.locate(9.0), (1, 1.0));
    }

    #[test]
    fn frames_cover_the_key_range() {
        let f = frames_between(0.0, 0.1, 60.0);
        assert_eq!(f.first().unwrap().0, 0);
        assert_eq!(f.last().unwrap().0, 6);
        assert_eq!(f.len(), 7);
        let g = frames_between(0.5, 1.4, 60.0);
        assert_eq!((g[0].0, g.last().unwrap().0), (30, 84));
    }
}
