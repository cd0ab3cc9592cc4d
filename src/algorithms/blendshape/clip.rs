//! The blendshape form of a Hermite trajectory, shared by every blendshape writer.
//!
//! Two forms ([`Weights`]); [`BlendShapeClip::new`] builds either. Below is the *signed* form
//! (`[export] weights = "signed"`); the default Bernstein form, whose weights stay in [0, 1],
//! is built in `export/bernstein.rs` from the same types.
//!
//! With base pose `b = x_0`, a *pose target* `P_k = x_k - b` per key and a *velocity target*
//! `V_k = v_k` per key, the trajectory is exactly
//!
//! ```text
//! x(t) = b + Σ_k w_Pk(t) P_k + Σ_k w_Vk(t) V_k
//! ```
//!
//! where `w_Pk` is the cubic Hermite spline through the key times with value 1 at key `k`, 0 at
//! the others and zero slopes, and `w_Vk` has value 0 at every key and slope 1 at key `k` only
//! (slope in 1/second, so `V_k` stays a velocity). On each interval the position weights sum
//! to `h00 + h01 = 1`, which is why the base can be dropped from the sum. These are precisely
//! glTF's CUBICSPLINE curves (value, in-tangent, out-tangent per key), so glTF reproduces the
//! trajectory exactly; USD samples the same curves once per frame.
//!
//! Targets whose offsets are all zero (a key equal to the base, a velocity fixed to zero) are
//! dropped; in a cyclic clip the last key aliases the first, so its velocity curve gets slope
//! 1 at both ends and it has no pose target of its own. Whether a clip is cyclic is decided
//! here, from the data ([`is_cyclic`]), for every writer and for the report alike.
//!
//! The weight curves are evaluated with the trajectory's own Hermite basis and interval lookup
//! (`spacetime::trajectory::hermite_weights` and `locate`).

use crate::algorithms::geometry::Point;
use crate::algorithms::spacetime::trajectory::{hermite_weights, locate, Trajectory};

/// The form of the blendshapes and their weights (the scene's `[export] weights`;
/// `formats/usd.md`, "Weights").
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Weights {
    /// Each interval in the Bernstein basis: a shape per key pose and per control point, every
    /// weight in [0, 1]. Plays right in consumers that clamp shape-key values (Blender).
    Bernstein,
    /// A pose and a velocity shape per key; velocity weights go negative. Fewer shapes.
    Signed,
}

/// One blendshape: a named set of vertex offsets.
#[derive(Debug, Clone, PartialEq)]
pub struct Target {
    /// A valid USD prim name and glTF target name (`key_3`, `key_0_velocity`, `key_3_out`).
    pub name: String,
    /// The vertices this target moves, increasing. Vertices not listed have zero offset.
    pub indices: Vec<u32>,
    /// Offsets of those vertices, in the file's precision.
    pub offsets: Vec<[f32; 3]>,
}

/// A weight curve as cubic Hermite keys on the clip's key times. Tangents are slopes in
/// weight per second.
#[derive(Debug, Clone, PartialEq)]
pub struct WeightCurve {
    /// The weight at each key.
    pub values: Vec<f32>,
    /// The slope arriving at each key.
    pub in_tangents: Vec<f32>,
    /// The slope leaving each key.
    pub out_tangents: Vec<f32>,
}

/// A blendshape animation: base points, targets, and one weight curve per target.
#[derive(Debug, Clone, PartialEq)]
pub struct BlendShapeClip {
    /// The first key's positions: the mesh's points with every weight zero.
    pub base: Vec<[f32; 3]>,
    /// The blendshapes.
    pub targets: Vec<Target>,
    /// Key times in seconds (strictly increasing: a contact's two keys are one clip key).
    pub times: Vec<f64>,
    /// `curves[j]` drives `targets[j]`.
    pub curves: Vec<WeightCurve>,
}

pub(super) fn f32x3(p: Point) -> [f32; 3] {
    [p[0] as f32, p[1] as f32, p[2] as f32]
}

/// The nonzero entries of `offsets` (after rounding to f32).
pub(super) fn sparse_target(name: String, offsets: impl Iterator<Item = Point>) -> Option<Target> {
    let (mut indices, mut values) = (Vec::new(), Vec::new());
    for (i, o) in offsets.enumerate() {
        let o = f32x3(o);
        if o != [0.0; 3] {
            indices.push(i as u32);
            values.push(o);
        }
    }
    (!indices.is_empty()).then_some(Target { name, indices, offsets: values })
}

/// Whether the clip of `trajectory` is cyclic: its last key repeats the first (positions and
/// velocities, in the f32 the files hold), so it saves that key's targets. Decided from the
/// data, not the scene's `cyclic` flag: the cyclic form is exact exactly when the keys alias.
pub fn is_cyclic(trajectory: &Trajectory) -> bool {
    let same = |a: &[[f64; 3]], b: &[[f64; 3]]| a.iter().zip(b).all(|(p, q)| p.map(|x| x as f32) == q.map(|x| x as f32));
    let last = trajectory.key_count() - 1;
    same(&trajectory.positions[0], &trajectory.positions[last]) && same(&trajectory.velocities[0], &trajectory.velocities[last])
}

/// The clip keys of trajectory keys at `times`: a contact's two keys (equal times) share one.
/// Returns the clip key of every trajectory key and the clip's (strictly increasing) times.
pub(super) fn clip_keys(times: &[f64]) -> (Vec<usize>, Vec<f64>) {
    let mut clip_key = Vec::with_capacity(times.len());
    let mut clip_times: Vec<f64> = Vec::with_capacity(times.len());
    for &t in times {
        if clip_times.last() != Some(&t) {
            clip_times.push(t);
        }
        clip_key.push(clip_times.len() - 1);
    }
    (clip_key, clip_times)
}

impl BlendShapeClip {
    /// The blendshape form of `trajectory` in the form `weights` names, cyclic when
    /// [`is_cyclic`] says so: the one constructor of the clip every blendshape file holds.
    pub fn new(trajectory: &Trajectory, weights: Weights) -> Self {
        let cyclic = is_cyclic(trajectory);
        match weights {
            Weights::Bernstein => Self::bernstein(trajectory, cyclic),
            Weights::Signed => Self::signed(trajectory, cyclic),
        }
    }

    /// The signed blendshape form of `trajectory`: `key_K` (pose) and `key_K_velocity`.
    /// `cyclic`: the last key aliases the first.
    ///
    /// A contact (two keys at one time, one pose, two velocities) becomes one clip key: its
    /// pose once, the arriving key's velocity as the in-tangent and the leaving key's as the
    /// out-tangent (glTF CUBICSPLINE keys carry both), so the clip's times stay strictly
    /// increasing.
    pub(super) fn signed(trajectory: &Trajectory, cyclic: bool) -> Self {
        let n_keys = trajectory.key_count();
        let base_f64 = &trajectory.positions[0];
        let base: Vec<[f32; 3]> = base_f64.iter().map(|&p| f32x3(p)).collect();
        // Offsets are taken against the f32 base, so base + offset rounds back to the key.
        let base_rounded: Vec<Point> = base.iter().map(|b| [b[0] as f64, b[1] as f64, b[2] as f64]).collect();
        // Keys that own their own unknowns: in a cyclic clip the last key is the first.
        let owner = |k: usize| if cyclic && k == n_keys - 1 { 0 } else { k };
        let (clip_key, times) = clip_keys(&trajectory.times);
        let leaves_contact = |k: usize| k > 0 && clip_key[k] == clip_key[k - 1];
        let arrives_contact = |k: usize| k + 1 < n_keys && clip_key[k + 1] == clip_key[k];
        let n_clip = times.len();

        let mut targets = Vec::new();
        let mut curves = Vec::new();
        let zeros = || vec![0.0f32; n_clip];
        for k in 1..n_keys {
            if owner(k) != k || leaves_contact(k) {
                continue;
            }
            let offsets = trajectory.positions[k].iter().zip(&base_rounded).map(|(x, b)| crate::algorithms::geometry::sub(*x, *b));
            if let Some(t) = sparse_target(format!("key_{k}"), offsets) {
                let mut values = zeros();
                values[clip_key[k]] = 1.0;
                targets.push(t);
                curves.push(WeightCurve { values, in_tangents: zeros(), out_tangents: zeros() });
            }
        }
        for k in 0..n_keys {
            if owner(k) != k {
                continue;
            }
            if let Some(t) = sparse_target(format!("key_{k}_velocity"), trajectory.velocities[k].iter().copied()) {
                let (mut in_t, mut out_t) = (zeros(), zeros());
                for key in (0..n_keys).filter(|&key| owner(key) == k) {
                    if !leaves_contact(key) {
                        in_t[clip_key[key]] = 1.0;
                    }
                    if !arrives_contact(key) {
                        out_t[clip_key[key]] = 1.0;
                    }
                }
                targets.push(t);
                curves.push(WeightCurve { values: zeros(), in_tangents: in_t, out_tangents: out_t });
            }
        }
        BlendShapeClip { base, targets, times, curves }
    }

    /// Vertices of the mesh.
    pub fn vertex_count(&self) -> usize {
        self.base.len()
    }

    /// Every target's weight at time `t` (clamped to the key range), by cubic Hermite
    /// interpolation of the curves, as glTF defines CUBICSPLINE.
    pub fn weights_at(&self, t: f64) -> Vec<f64> {
        let (i, theta) = locate(&self.times, t);
        let w = hermite_weights(theta, self.times[i + 1] - self.times[i]).pos;
        self.curves
            .iter()
            .map(|c| w[0] * c.values[i] as f64 + w[1] * c.out_tangents[i] as f64 + w[2] * c.values[i + 1] as f64 + w[3] * c.in_tangents[i + 1] as f64)
            .collect()
    }

    /// Points for the given target weights: `base + Σ_j w_j offsets_j`.
    pub fn points_with_weights(&self, weights: &[f64]) -> Vec<Point> {
        let mut out: Vec<Point> = self.base.iter().map(|b| [b[0] as f64, b[1] as f64, b[2] as f64]).collect();
        for (target, &w) in self.targets.iter().zip(weights) {
            if w == 0.0 {
                continue;
            }
            for (&i, o) in target.indices.iter().zip(&target.offsets) {
                let p = &mut out[i as usize];
                for d in 0..3 {
                    p[d] += w * o[d] as f64;
                }
            }
        }
        out
    }

    /// Points at time `t` with exact (unsampled) weights.
    pub fn points_at(&self, t: f64) -> Vec<Point> {
        self.points_with_weights(&self.weights_at(t))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn wavy(cyclic: bool) -> Trajectory {
        let times = vec![0.0, 0.4, 1.0, 1.5];
        let n = 5;
        let pose = |k: usize| -> Vec<Point> {
            (0..n).map(|v| [v as f64 + 0.1 * k as f64, (k * v) as f64 * 0.05, if v == 0 { 0.0 } else { 0.3 * k as f64 }]).collect()
        };
        let vel = |k: usize| -> Vec<Point> { (0..n).map(|v| [0.2 * v as f64 - k as f64 * 0.1, 0.0, if v < 2 { 0.0 } else { 0.7 }]).collect() };
        let mut positions: Vec<_> = (0..4).map(pose).collect();
        let mut velocities: Vec<_> = (0..4).map(vel).collect();
        if cyclic {
            positions[3] = positions[0].clone();
            velocities[3] = velocities[0].clone();
        }
        Trajectory { times, positions, velocities }
    }

    fn max_error(tr: &Trajectory, clip: &BlendShapeClip) -> f64 {
        let mut worst: f64 = 0.0;
        for k in 0..=150 {
            let t = 1.5 * k as f64 / 150.0;
            let (a, b) = (tr.evaluate(t), clip.points_at(t));
            for (p, q) in a.iter().zip(&b) {
                worst = worst.max(crate::algorithms::geometry::norm(crate::algorithms::geometry::sub(*p, *q)));
            }
        }
        worst
    }

    #[test]
    fn clip_reproduces_the_trajectory() {
        for cyclic in [false, true] {
            let tr = wavy(cyclic);
            assert_eq!(is_cyclic(&tr), cyclic);
            let clip = BlendShapeClip::new(&tr, Weights::Signed);
            assert!(max_error(&tr, &clip) < 1e-5, "cyclic={cyclic}: {}", max_error(&tr, &clip));
        }
    }

    #[test]
    fn a_contact_is_one_clip_key_with_its_two_velocities_as_tangents() {
        // Keys 1 and 2 are a contact: one pose, the velocity jumps from arriving to leaving.
        let mut tr = wavy(false);
        tr.times = vec![0.0, 0.4, 0.4, 1.5];
        tr.positions[2] = tr.positions[1].clone();
        let clip = BlendShapeClip::signed(&tr, false);
        assert_eq!(clip.times, vec![0.0, 0.4, 1.5]);
        assert!(clip.targets.iter().all(|t| t.name != "key_2"), "the shared pose is one target");
        assert!(max_error(&tr, &clip) < 1e-5, "{}", max_error(&tr, &clip));
        // Both sides of the contact: the arriving and the leaving velocity.
        let slope = |t0: f64, t1: f64| -> Vec<Point> {
            let (a, b) = (clip.points_at(t0), clip.points_at(t1));
            a.iter().zip(&b).map(|(p, q)| crate::algorithms::geometry::scale(crate::algorithms::geometry::sub(*q, *p), 1.0 / (t1 - t0))).collect()
        };
        let h = 1e-4;
        for (v, (before, after)) in slope(0.4 - h, 0.4).iter().zip(slope(0.4, 0.4 + h)).enumerate() {
            for d in 0..3 {
                assert!((before[d] - tr.velocities[1][v][d]).abs() < 1e-2, "arriving, vertex {v}");
                assert!((after[d] - tr.velocities[2][v][d]).abs() < 1e-2, "leaving, vertex {v}");
            }
        }
    }

    #[test]
    fn zero_targets_are_dropped_and_sparse_ones_are_sparse() {
        let tr =
            Trajectory::with_zero_velocities(vec![0.0, 1.0, 2.0], vec![vec![[0.0; 3], [1.0; 3]], vec![[0.0; 3], [2.0; 3]], vec![[0.0; 3], [1.0; 3]]]);
        let clip = BlendShapeClip::new(&tr, Weights::Signed);
        // Key 2 aliases key 0 (cyclic), velocities are zero: only key_1 remains, moving vertex 1.
        assert_eq!(clip.targets.len(), 1);
        assert_eq!(clip.targets[0].name, "key_1");
        assert_eq!(clip.targets[0].indices, vec![1]);
        assert!(max_error(&tr, &clip) < 1e-6);
    }

    #[test]
    fn aliasing_keys_are_detected_in_f32() {
        let key = |x: f64| vec![[x, 0.0, 0.0]];
        let tr = Trajectory::with_zero_velocities(vec![0.0, 1.0, 2.0], vec![key(0.1), key(1.0), key(0.1 + 1e-12)]);
        assert!(is_cyclic(&tr));
        let tr = Trajectory::with_zero_velocities(vec![0.0, 1.0, 2.0], vec![key(0.1), key(1.0), key(0.1 + 1e-6)]);
        assert!(!is_cyclic(&tr));
    }

    #[test]
    fn weights_follow_the_trajectory_basis_at_and_between_keys() {
        let tr = wavy(false);
        let clip = BlendShapeClip::new(&tr, Weights::Signed);
        for (k, &t) in tr.times.iter().enumerate() {
            let w = clip.weights_at(t);
            for (target, wj) in clip.targets.iter().zip(&w) {
                let expected = if target.name == format!("key_{k}") { 1.0 } else { 0.0 };
                assert_eq!(*wj, expected, "{} at key {k}", target.name);
            }
        }
        // Outside the key range the weights hold the end values.
        assert_eq!(clip.weights_at(-1.0), clip.weights_at(0.0));
        assert_eq!(clip.weights_at(9.0), clip.weights_at(1.5));
    }
}
