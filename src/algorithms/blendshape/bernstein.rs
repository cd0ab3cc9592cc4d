//! The Bernstein blendshape form of a Hermite trajectory: every weight in [0, 1], every shape
//! sparse. The default of `[export] weights`.
//!
//! On interval `i` (keys `i`, `i+1`, length `T`, `s = (t - t_i) / T`) the Hermite curve is the
//! cubic Bezier curve with control points `x_i`, `x_i + T v_i / 3`, `x_{i+1} - T v_{i+1} / 3`,
//! `x_{i+1}`, weighted by the Bernstein polynomials `B0 = (1-s)^3`, `B1 = 3s(1-s)^2`,
//! `B2 = 3s^2(1-s)`, `B3 = s^3` (non-negative, summing to one). Storing the two inner control
//! points against the base pose would make them dense wherever the key differs from the base;
//! stored against *their key* they are sparse (only the vertices that move at that key):
//!
//! ```text
//! x(t) = b + (B0 + B1) P_i + (B2 + B3) P_{i+1} + B1 O_i + B2 I_{i+1}
//!        P_k = x_k - b          shape key_K       weight h00 on its outgoing interval, h01 on its incoming one
//!        O_i = T v_i / 3        shape key_I_out   weight B1 on interval i only
//!        I_{i+1} = -T v_{i+1}/3 shape key_J_in    weight B2 on interval i only (J = i+1)
//! ```
//!
//! `B0 + B1 = h00` and `B2 + B3 = h01` are the Hermite position weights, in [0, 1]; `B1` and `B2`
//! peak at 4/9. Compared with the signed form (`clip.rs`), the velocity shape of a key is split
//! into the two directions it is used in (`+v` leaving the key, `-v` arriving), because
//! non-negative weights cannot reverse a shape: one more shape per key with a velocity.
//!
//! Each weight is a cubic Hermite curve on the key times, so glTF's CUBICSPLINE holds it
//! exactly: `key_I_out` has value 0 at every key and out-slope `3 / T` at key `i`
//! (`h10 · T · 3/T = B1`), `key_J_in` has in-slope `-3 / T` at key `i+1` (`h11 · T · (-3/T) = B2`).

use super::clip::{clip_keys, f32x3, sparse_target, BlendShapeClip, WeightCurve};
use crate::algorithms::geometry::{scale, sub, Point};
use crate::algorithms::spacetime::trajectory::Trajectory;

impl BlendShapeClip {
    /// The Bernstein form of `trajectory`: `key_K`, `key_K_in`, `key_K_out`, in key order.
    /// `cyclic` says the last key aliases the first (its pose is the base, and its incoming
    /// control point is named after key 0). Shapes whose offsets are all zero are dropped.
    pub(super) fn bernstein(trajectory: &Trajectory, cyclic: bool) -> Self {
        let n_keys = trajectory.key_count();
        let times = &trajectory.times;
        let base: Vec<[f32; 3]> = trajectory.positions[0].iter().map(|&p| f32x3(p)).collect();
        // Offsets against the f32 base, so base + offset rounds back to the key.
        let base_rounded: Vec<Point> = base.iter().map(|b| b.map(f64::from)).collect();
        let aliased = |k: usize| cyclic && k == n_keys - 1;
        // A contact's two keys (equal times, one pose) are one clip key: the pose once; the
        // zero-length interval between them has no control points (their offsets are zero).
        let (clip_key, clip_times) = clip_keys(times);
        let leaves_contact = |k: usize| k > 0 && clip_key[k] == clip_key[k - 1];
        let zeros = || vec![0.0f32; clip_times.len()];
        let mut clip = BlendShapeClip { base, targets: Vec::new(), times: clip_times.clone(), curves: Vec::new() };

        for k in 0..n_keys {
            let name = if aliased(k) { 0 } else { k };
            if k > 0 && !aliased(k) && !leaves_contact(k) {
                let offsets = trajectory.positions[k].iter().zip(&base_rounded).map(|(x, b)| sub(*x, *b));
                if let Some(t) = sparse_target(format!("key_{k}"), offsets) {
                    let mut values = zeros();
                    values[clip_key[k]] = 1.0;
                    clip.targets.push(t);
                    clip.curves.push(WeightCurve { values, in_tangents: zeros(), out_tangents: zeros() });
                }
            }
            // The control point before key k (on interval k-1) and after it (on interval k).
            let sides = [(k > 0).then(|| (k - 1, "in", -1.0)), (k + 1 < n_keys).then_some((k, "out", 1.0))];
            for (interval, side, sign) in sides.into_iter().flatten() {
                let length = times[interval + 1] - times[interval];
                let offsets = trajectory.velocities[k].iter().map(|&v| scale(v, sign * length / 3.0));
                if let Some(t) = sparse_target(format!("key_{name}_{side}"), offsets) {
                    let (mut in_t, mut out_t) = (zeros(), zeros());
                    let slope = (3.0 / length) as f32;
                    if sign > 0.0 {
                        out_t[clip_key[k]] = slope;
                    } else {
                        in_t[clip_key[k]] = -slope;
                    }
                    clip.targets.push(t);
                    clip.curves.push(WeightCurve { values: zeros(), in_tangents: in_t, out_tangents: out_t });
                }
            }
        }
        clip
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::algorithms::geometry::norm;

    /// Four uneven keys, five vertices; vertex 0 never moves, vertices 0-1 have no velocity.
    fn wavy(cyclic: bool) -> Trajectory {
        let times = vec![0.0, 0.4, 1.0, 1.5];
        let n = 5;
        let pose = |k: usize| -> Vec<Point> {
            (0..n).map(|v| if v == 0 { [0.0; 3] } else { [v as f64 + 0.1 * k as f64, (k * v) as f64 * 0.05, 0.3 * k as f64] }).collect()
        };
        let vel = |k: usize| -> Vec<Point> { (0..n).map(|v| if v < 2 { [0.0; 3] } else { [0.2 * v as f64 - k as f64 * 0.1, 0.0, 0.7] }).collect() };
        let mut positions: Vec<_> = (0..4).map(pose).collect();
        let mut velocities: Vec<_> = (0..4).map(vel).collect();
        if cyclic {
            positions[3] = positions[0].clone();
            velocities[3] = velocities[0].clone();
        }
        Trajectory { times, positions, velocities }
    }

    fn times(tr: &Trajectory) -> impl Iterator<Item = f64> + '_ {
        (0..=300).map(|k| tr.start() + (tr.end() - tr.start()) * k as f64 / 300.0)
    }

    #[test]
    fn a_contact_is_one_clip_key() {
        // Keys 1 and 2 are a contact: one pose, the velocity jumps from arriving to leaving.
        let mut tr = wavy(false);
        tr.times = vec![0.0, 0.4, 0.4, 1.5];
        tr.positions[2] = tr.positions[1].clone();
        let clip = BlendShapeClip::bernstein(&tr, false);
        assert_eq!(clip.times, vec![0.0, 0.4, 1.5]);
        assert!(clip.targets.iter().all(|t| t.name != "key_2" && t.name != "key_1_out" && t.name != "key_2_in"));
        assert!(clip.curves.iter().flat_map(|c| c.in_tangents.iter().chain(&c.out_tangents)).all(|x| x.is_finite()));
        let worst =
            times(&tr).map(|t| tr.evaluate(t).iter().zip(&clip.points_at(t)).map(|(p, q)| norm(sub(*p, *q))).fold(0.0, f64::max)).fold(0.0, f64::max);
        assert!(worst < 1e-6, "{worst}");
    }

    #[test]
    fn reproduces_the_trajectory_at_any_time() {
        for cyclic in [false, true] {
            let tr = wavy(cyclic);
            let clip = BlendShapeClip::bernstein(&tr, cyclic);
            let worst = times(&tr)
                .map(|t| tr.evaluate(t).iter().zip(&clip.points_at(t)).map(|(p, q)| norm(sub(*p, *q))).fold(0.0, f64::max))
                .fold(0.0, f64::max);
            assert!(worst < 1e-6, "cyclic={cyclic}: {worst}");
        }
    }

    #[test]
    fn every_weight_stays_in_zero_one_and_the_key_weights_sum_to_one() {
        let tr = wavy(false);
        let clip = BlendShapeClip::bernstein(&tr, false);
        let poses: Vec<bool> = clip.targets.iter().map(|t| !t.name.ends_with("_in") && !t.name.ends_with("_out")).collect();
        for t in times(&tr) {
            let w = clip.weights_at(t);
            assert!(w.iter().all(|&x| (-1e-7..=1.0 + 1e-7).contains(&x)), "t={t}: {w:?}");
            // key_0 is the base (weight 1 - the others); the pose weights of an interval sum to one.
            let pose_sum: f64 = w.iter().zip(&poses).filter(|(_, &p)| p).map(|(x, _)| x).sum();
            assert!((-1e-7..=1.0 + 1e-7).contains(&pose_sum), "t={t}: {pose_sum}");
            // The control-point weights are B1, B2 <= 4/9.
            assert!(w.iter().zip(&poses).filter(|(_, &p)| !p).all(|(&x, _)| x <= 4.0 / 9.0 + 1e-6), "t={t}: {w:?}");
        }
        // The peak of B1 = 3 s (1-s)^2 is 4/9 at s = 1/3: on the first interval of key_0_out.
        let out = clip.targets.iter().position(|t| t.name == "key_0_out").unwrap();
        assert!((clip.weights_at(0.4 / 3.0)[out] - 4.0 / 9.0).abs() < 1e-6);
    }

    #[test]
    fn shapes_are_named_per_key_and_sparse() {
        let clip = BlendShapeClip::bernstein(&wavy(false), false);
        let names: Vec<&str> = clip.targets.iter().map(|t| t.name.as_str()).collect();
        assert_eq!(names, ["key_0_out", "key_1", "key_1_in", "key_1_out", "key_2", "key_2_in", "key_2_out", "key_3", "key_3_in"]);
        // Vertex 0 never moves: no pose shape lists it; vertices 0-1 have no velocity.
        for t in &clip.targets {
            let control_point = t.name.ends_with("_in") || t.name.ends_with("_out");
            let expect: &[u32] = if control_point { &[2, 3, 4] } else { &[1, 2, 3, 4] };
            assert_eq!(t.indices, expect, "{}", t.name);
        }
        // In and out shapes of a key are its velocity scaled by -T_before/3 and +T_after/3.
        let get = |n: &str| &clip.targets[names.iter().position(|&x| x == n).unwrap()];
        let v = wavy(false).velocities[1][2];
        assert_eq!(get("key_1_in").offsets[0], f32x3(scale(v, -0.4 / 3.0)));
        assert_eq!(get("key_1_out").offsets[0], f32x3(scale(v, 0.6 / 3.0)));
    }

    #[test]
    fn cyclic_clips_name_the_last_control_point_after_key_0() {
        let clip = BlendShapeClip::bernstein(&wavy(true), true);
        let names: Vec<&str> = clip.targets.iter().map(|t| t.name.as_str()).collect();
        assert_eq!(names, ["key_0_out", "key_1", "key_1_in", "key_1_out", "key_2", "key_2_in", "key_2_out", "key_0_in"]);
        let mut unique = names.clone();
        unique.sort();
        unique.dedup();
        assert_eq!(unique.len(), names.len(), "shape names are unique");
    }

    #[test]
    fn zero_velocities_leave_only_pose_shapes() {
        let tr =
            Trajectory::with_zero_velocities(vec![0.0, 1.0, 2.0], vec![vec![[0.0; 3], [1.0; 3]], vec![[0.0; 3], [2.0; 3]], vec![[0.0; 3], [1.0; 3]]]);
        let clip = BlendShapeClip::bernstein(&tr, true);
        assert_eq!(clip.targets.iter().map(|t| t.name.as_str()).collect::<Vec<_>>(), ["key_1"]);
        assert_eq!(clip, BlendShapeClip::signed(&tr, true), "without velocities both forms are the same file");
    }
}
