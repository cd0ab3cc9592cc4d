//! glTF animation samplers (glTF 2.0 §3.11.2, Appendix C): STEP, LINEAR (slerp for
//! rotations) and CUBICSPLINE, evaluated at any time. Before the first key the curve holds
//! the first value, after the last key the last one.

/// How a sampler interpolates between keys.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Interpolation {
    Step,
    Linear,
    CubicSpline,
}

/// One sampler's keys. Invariants (checked by [`Curve::new`]): `times` finite and strictly
/// increasing, at least one key; `values` holds `width` components per key, and for
/// CUBICSPLINE three groups per key: in-tangents, values, out-tangents (tangents in units per
/// second).
#[derive(Debug, Clone, PartialEq)]
pub struct Curve {
    times: Vec<f32>,
    values: Vec<f32>,
    width: usize,
    interpolation: Interpolation,
    /// Values are quaternions (x, y, z, w): LINEAR is slerp, CUBICSPLINE is normalized.
    rotation: bool,
}

impl Curve {
    /// Check the keys; the problem on failure.
    pub fn new(times: Vec<f32>, values: Vec<f32>, width: usize, interpolation: Interpolation, rotation: bool) -> Result<Curve, String> {
        if times.is_empty() {
            return Err("has no keys".into());
        }
        if let Some(k) = times.iter().position(|t| !t.is_finite()) {
            return Err(format!("key time {k} is {}", times[k]));
        }
        if let Some(k) = times.windows(2).position(|w| w[1] <= w[0]) {
            return Err(format!("key times do not increase at key {}: {} after {}", k + 1, times[k + 1], times[k]));
        }
        let groups = if interpolation == Interpolation::CubicSpline { 3 } else { 1 };
        if width == 0 || values.len() != times.len() * groups * width {
            return Err(format!(
                "has {} output values for {} keys, expected {} ({groups} x {width} per key)",
                values.len(),
                times.len(),
                times.len() * groups * width
            ));
        }
        if let Some(i) = values.iter().position(|v| !v.is_finite()) {
            return Err(format!("output value {i} is {}", values[i]));
        }
        Ok(Curve { times, values, width, interpolation, rotation })
    }

    pub fn times(&self) -> &[f32] {
        &self.times
    }

    /// The value part of key `k`.
    fn value(&self, k: usize) -> &[f32] {
        match self.interpolation {
            Interpolation::CubicSpline => &self.values[(3 * k + 1) * self.width..(3 * k + 2) * self.width],
            _ => &self.values[k * self.width..(k + 1) * self.width],
        }
    }

    /// The curve at time `t` into `out` (`width` values).
    pub fn sample(&self, t: f64, out: &mut [f64]) {
        debug_assert_eq!(out.len(), self.width);
        let n = self.times.len();
        let copy = |out: &mut [f64], v: &[f32]| out.iter_mut().zip(v).for_each(|(o, &x)| *o = x as f64);
        // Index of the first key after t.
        let next = self.times.partition_point(|&k| k as f64 <= t);
        if next == 0 {
            return copy(out, self.value(0));
        }
        if next == n {
            return copy(out, self.value(n - 1));
        }
        let k = next - 1;
        let (t0, t1) = (self.times[k] as f64, self.times[next] as f64);
        let s = (t - t0) / (t1 - t0);
        let w = self.width;
        match self.interpolation {
            Interpolation::Step => copy(out, self.value(k)),
            Interpolation::Linear if self.rotation => slerp(self.value(k), self.value(next), s, out),
            Interpolation::Linear => {
                for (o, (&a, &b)) in out.iter_mut().zip(self.value(k).iter().zip(self.value(next))) {
                    *o = a as f64 + s * (b as f64 - a as f64);
                }
            }
            Interpolation::CubicSpline => {
                let dt = t1 - t0;
                let (s2, s3) = (s * s, s * s * s);
                let (h00, h10, h01, h11) = (2.0 * s3 - 3.0 * s2 + 1.0, s3 - 2.0 * s2 + s, -2.0 * s3 + 3.0 * s2, s3 - s2);
                let (at0, at1) = (3 * k * w, 3 * next * w);
                for i in 0..w {
                    let p0 = self.values[at0 + w + i] as f64;
                    let m0 = self.values[at0 + 2 * w + i] as f64 * dt;
                    let p1 = self.values[at1 + w + i] as f64;
                    let m1 = self.values[at1 + i] as f64 * dt;
                    out[i] = h00 * p0 + h10 * m0 + h01 * p1 + h11 * m1;
                }
                if self.rotation {
                    normalize(out);
                }
            }
        }
    }
}

fn normalize(q: &mut [f64]) {
    let len = q.iter().map(|x| x * x).sum::<f64>().sqrt();
    if len > 0.0 {
        q.iter_mut().for_each(|x| *x /= len);
    }
}

/// Spherical linear interpolation along the shorter arc (glTF Appendix C); nearly parallel
/// quaternions are interpolated linearly and normalized.
fn slerp(a: &[f32], b: &[f32], s: f64, out: &mut [f64]) {
    let a: [f64; 4] = std::array::from_fn(|i| a[i] as f64);
    let mut b: [f64; 4] = std::array::from_fn(|i| b[i] as f64);
    let mut dot: f64 = (0..4).map(|i| a[i] * b[i]).sum();
    if dot < 0.0 {
        b = b.map(|x| -x);
        dot = -dot;
    }
    let nearly_parallel = dot > 1.0 - 1e-9;
    let (wa, wb) = if nearly_parallel {
        (1.0 - s, s)
    } else {
        let theta = dot.min(1.0).acos();
        let sin = theta.sin();
        (((1.0 - s) * theta).sin() / sin, (s * theta).sin() / sin)
    };
    for i in 0..4 {
        out[i] = wa * a[i] + wb * b[i];
    }
    if nearly_parallel {
        normalize(out);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(c: &Curve, t: f64) -> Vec<f64> {
        let mut out = vec![0.0; c.width];
        c.sample(t, &mut out);
        out
    }

    #[test]
    fn step_and_linear_hold_the_ends() {
        let step = Curve::new(vec![0.0, 1.0, 2.0], vec![1.0, 5.0, 9.0], 1, Interpolation::Step, false).unwrap();
        assert_eq!([at(&step, -1.0), at(&step, 0.0), at(&step, 0.99), at(&step, 1.0), at(&step, 7.0)], [[1.0], [1.0], [1.0], [5.0], [9.0]]);
        let linear = Curve::new(vec![0.0, 2.0], vec![0.0, 10.0, 4.0, 30.0], 2, Interpolation::Linear, false).unwrap();
        assert_eq!(at(&linear, 0.5), vec![1.0, 15.0]);
        assert_eq!(at(&linear, 3.0), vec![4.0, 30.0]);
    }

    #[test]
    fn cubic_spline_matches_hermite_and_its_tangents_are_per_second() {
        // Keys at 1 s and 3 s; value 2 -> 5, out-tangent 4/s, in-tangent of key 1: -1/s.
        // Layout per key: in-tangent, value, out-tangent.
        let c = Curve::new(vec![1.0, 3.0], vec![99.0, 2.0, 4.0, -1.0, 5.0, 99.0], 1, Interpolation::CubicSpline, false).unwrap();
        assert_eq!(at(&c, 1.0), vec![2.0]);
        assert_eq!(at(&c, 3.0), vec![5.0]);
        // Midpoint: h00 = h01 = 1/2, h10 = 1/8, h11 = -1/8, tangents times dt = 2.
        assert!((at(&c, 2.0)[0] - (0.5 * 2.0 + 0.125 * 8.0 + 0.5 * 5.0 - 0.125 * -2.0)).abs() < 1e-12);
        // Finite differences at the ends of the interval recover the tangents in units/s.
        let h = 1e-6;
        let d0 = (at(&c, 1.0 + h)[0] - at(&c, 1.0)[0]) / h;
        let d1 = (at(&c, 3.0)[0] - at(&c, 3.0 - h)[0]) / h;
        assert!((d0 - 4.0).abs() < 1e-4 && (d1 + 1.0).abs() < 1e-4, "{d0} {d1}");
    }

    #[test]
    fn rotations_slerp_along_the_short_arc_and_cubic_ones_are_normalized() {
        let h = std::f32::consts::FRAC_1_SQRT_2;
        // Identity to 90 degrees about z, the second given as its negation (same rotation).
        let c = Curve::new(vec![0.0, 1.0], vec![0.0, 0.0, 0.0, 1.0, 0.0, 0.0, -h, -h], 4, Interpolation::Linear, true).unwrap();
        let q = at(&c, 0.5);
        let angle = (std::f64::consts::PI / 8.0).sin();
        assert!((q[2] - angle).abs() < 1e-7 && (q[3] - (std::f64::consts::PI / 8.0).cos()).abs() < 1e-7, "{q:?}");
        let cubic = Curve::new(
            vec![0.0, 1.0],
            [[0.0; 4], [0.0, 0.0, 0.0, 1.0], [0.0; 4], [0.0; 4], [0.0, 0.0, h, h], [0.0; 4]].concat(),
            4,
            Interpolation::CubicSpline,
            true,
        )
        .unwrap();
        let q = at(&cubic, 0.3);
        assert!((q.iter().map(|x| x * x).sum::<f64>() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn malformed_keys_are_refused() {
        assert!(Curve::new(vec![], vec![], 1, Interpolation::Linear, false).unwrap_err().contains("no keys"));
        assert!(Curve::new(vec![0.0, 0.0], vec![1.0, 2.0], 1, Interpolation::Linear, false).unwrap_err().contains("do not increase at key 1"));
        assert!(Curve::new(vec![0.0, f32::NAN], vec![1.0, 2.0], 1, Interpolation::Linear, false).unwrap_err().contains("key time 1 is NaN"));
        assert!(Curve::new(vec![0.0, 1.0], vec![1.0, 2.0], 1, Interpolation::CubicSpline, false).unwrap_err().contains("expected 6 (3 x 1 per key)"));
        assert!(Curve::new(vec![0.0], vec![f32::INFINITY], 1, Interpolation::Step, false).unwrap_err().contains("output value 0 is inf"));
    }
}
