//! The principal-component blendshape form of a Hermite trajectory (`[export] basis =
//! "principal"`): a few dense shapes instead of two or three sparse shapes per key.
//!
//! The key data of the trajectory, K poses minus their mean and K velocities scaled by the
//! key's mean interval `h_k` (so both rows are lengths), span every pose it plays: a pose at
//! time `t` is a combination of the key rows with the Hermite weights at `t`. The directions
//! `B_j` are the principal directions of the poses played at the scene's frames (their mean
//! `m` removed), computed in that span (an SVD of the key rows, then one of the frames'
//! coordinates in it), so truncating to rank `r` leaves the least squared error summed over
//! the frames, the error the files are measured with. Per key, `c_jk` is the key pose's
//! coordinate along `B_j` (about `m`) and `c'_jk` its velocity's. Truncated to rank `r`,
//!
//! ```text
//! x(t) = m + Σ_{j<r} c_j(t) B_j,     c_j the cubic Hermite curve through (c_jk, c'_jk)
//! ```
//!
//! is again exactly a Hermite trajectory (the projection of every key pose and velocity onto
//! the first `r` directions), so glTF CUBICSPLINE weights hold it at any instant and per-frame
//! samples (USD, LINEAR glTF) at every frame. Full rank (at most `2K`) reproduces the
//! trajectory, between frames too.
//!
//! Weights in [0, 1] (`weights = "bernstein"`, the default; Blender clamps shape-key values and
//! UsdSkel importers expect non-negative ones): per component, `lo_j` and `hi_j` are the exact
//! minimum and maximum of `c_j` over the clip (endpoints and the roots of its derivative on
//! every interval, not samples), widened by [`MARGIN`] so f32 rounding stays inside. Then
//!
//! ```text
//! x(t) = (m + Σ lo_j B_j) + Σ w_j(t) (hi_j - lo_j) B_j,    w_j = (c_j - lo_j) / (hi_j - lo_j) ∈ [0, 1]
//! ```
//!
//! an affine map of each curve, so `w_j` is still a cubic Hermite curve (values and slopes
//! divided by `hi_j - lo_j`). With `weights = "signed"` the base is `m` and `w_j = c_j / (hi_j -
//! lo_j)`, which may be negative.

use faer::Mat;

use super::clip::{clip_keys, f32x3, BlendShapeClip, Target, WeightCurve, Weights};
use crate::algorithms::geometry::Point;
use crate::algorithms::spacetime::trajectory::{hermite_weights, Trajectory};

/// Relative widening of each weight range, so the f32 values and slopes a file stores keep
/// every weight inside [0, 1] (f32 rounds at 6e-8 relative).
pub const MARGIN: f64 = 1e-6;

/// The principal components of a trajectory's keys, largest first.
#[derive(Debug, Clone)]
pub struct Components {
    /// The mean pose `m` over the frames.
    pub mean: Vec<Point>,
    /// Unit directions `B_j` (3V entries as V points), in decreasing singular value.
    pub directions: Vec<Vec<Point>>,
    /// `values[j][k]`: `c_j` at trajectory key `k`.
    pub values: Vec<Vec<f64>>,
    /// `slopes[j][k]`: `c_j'` at trajectory key `k` (per second).
    pub slopes: Vec<Vec<f64>>,
    /// Singular values of the centered frames along `B_j`, decreasing (zero for directions
    /// no frame shows): the rank-`r` clip's squared error summed over the frames is the sum
    /// of the squares of those past `r`.
    pub singular: Vec<f64>,
    /// The trajectory's key times (a contact's two keys share one time).
    pub times: Vec<f64>,
}

impl Components {
    /// The components of the trajectory played at `frames` (seconds; see the module docs).
    /// Directions with no key data (a zero singular value of the keys) are dropped.
    pub fn new(tr: &Trajectory, frames: &[f64]) -> Self {
        let k = tr.key_count();
        let v = tr.positions[0].len();
        let mut mean = vec![[0.0; 3]; v];
        for pose in &tr.positions {
            for (m, p) in mean.iter_mut().zip(pose) {
                for d in 0..3 {
                    m[d] += p[d] / k as f64;
                }
            }
        }
        // Key k's velocity row is scaled by its mean adjacent interval (positive intervals
        // only: a contact's zero-length interval carries no time), so both rows are lengths.
        let h: Vec<f64> = (0..k)
            .map(|key| {
                let sides: Vec<f64> =
                    [key.checked_sub(1).map(|a| tr.times[key] - tr.times[a]), (key + 1 < k).then(|| tr.times[key + 1] - tr.times[key])]
                        .into_iter()
                        .flatten()
                        .filter(|&l| l > 0.0)
                        .collect();
                if sides.is_empty() {
                    1.0
                } else {
                    sides.iter().sum::<f64>() / sides.len() as f64
                }
            })
            .collect();
        let a = Mat::<f64>::from_fn(2 * k, 3 * v, |r, c| {
            let (p, d) = (c / 3, c % 3);
            if r < k {
                tr.positions[r][p][d] - mean[p][d]
            } else {
                h[r - k] * tr.velocities[r - k][p][d]
            }
        });
        // The key data's span: A = U S Vᵀ, numerically zero directions (noise) left out.
        let svd = a.thin_svd().expect("the SVD of a finite matrix converges");
        let (u, s, vt) = (svd.U(), svd.S(), svd.V());
        let top = if s.dim() > 0 { s[0] } else { 0.0 };
        let r0 = (0..s.dim()).take_while(|&j| s[j] > top * 1e-13 && s[j] > 0.0).count();
        let mut out =
            Components { mean, directions: Vec::new(), values: Vec::new(), slopes: Vec::new(), singular: Vec::new(), times: tr.times.clone() };
        if r0 == 0 {
            return out;
        }
        // Every played frame is a row of H A (H: the Hermite weights of the key rows at that
        // instant), so in the span's coordinates it is the row of Q = H U S. The principal
        // directions of the frames (their mean removed) are V W, W from the SVD of Q's
        // centered rows: what minimizes the squared error summed over the frames the files
        // play, where the keys' own SVD would weigh key poses and interval-scaled velocities.
        let g = Mat::<f64>::from_fn(2 * k, r0, |r, j| u[(r, j)] * s[j]);
        let at: Vec<f64> = if frames.is_empty() { tr.times.clone() } else { frames.to_vec() };
        let q = Mat::<f64>::from_fn(at.len(), r0, |f, j| {
            let (i, theta) = tr.locate(at[f]);
            let w = hermite_weights(theta, tr.times[i + 1] - tr.times[i]);
            w.pos[0] * g[(i, j)] + w.pos[2] * g[(i + 1, j)] + w.pos[1] / h[i] * g[(k + i, j)] + w.pos[3] / h[i + 1] * g[(k + i + 1, j)]
        });
        let q_mean: Vec<f64> = (0..r0).map(|j| (0..at.len()).map(|f| q[(f, j)]).sum::<f64>() / at.len() as f64).collect();
        let centered = Mat::<f64>::from_fn(at.len(), r0, |f, j| q[(f, j)] - q_mean[j]);
        // The full SVD: W is square, so directions no frame shows (fewer frames than key
        // rows) are kept, last, and full rank still reproduces the trajectory between frames.
        let frame_svd = centered.svd().expect("the SVD of a finite matrix converges");
        let (w, s2) = (frame_svd.V(), frame_svd.S());
        // The frames' mean: m + Σ q̄_j V_j.
        for (p, m) in out.mean.iter_mut().enumerate() {
            for d in 0..3 {
                m[d] += (0..r0).map(|j| q_mean[j] * vt[(3 * p + d, j)]).sum::<f64>();
            }
        }
        let directions = vt.subcols(0, r0) * w;
        let gw = &g * w;
        let shift: Vec<f64> = (0..r0).map(|i| (0..r0).map(|j| q_mean[j] * w[(j, i)]).sum()).collect();
        for i in 0..r0 {
            out.directions.push((0..v).map(|p| [directions[(3 * p, i)], directions[(3 * p + 1, i)], directions[(3 * p + 2, i)]]).collect());
            out.values.push((0..k).map(|key| gw[(key, i)] - shift[i]).collect());
            out.slopes.push((0..k).map(|key| gw[(k + key, i)] / h[key]).collect());
            out.singular.push(if i < s2.dim() { s2[i] } else { 0.0 });
        }
        out
    }

    /// The number of components (at most twice the key count).
    pub fn len(&self) -> usize {
        self.singular.len()
    }

    /// Whether there is no component (keys that never move).
    pub fn is_empty(&self) -> bool {
        self.singular.is_empty()
    }

    /// The first `rank` components (all of them when `rank` is larger) as a clip: `component_J`
    /// shapes, one per component whose curve is not constant, in the form `weights` names.
    pub fn clip(&self, rank: usize, weights: Weights) -> BlendShapeClip {
        let (clip_key, times) = clip_keys(&self.times);
        let n_keys = self.times.len();
        // Per clip key: the first trajectory key (arriving side) and the last (leaving side).
        let mut first = vec![usize::MAX; times.len()];
        let mut last = vec![0; times.len()];
        for (k, &c) in clip_key.iter().enumerate() {
            first[c] = first[c].min(k);
            last[c] = k;
        }
        let mut base: Vec<Point> = self.mean.clone();
        let mut shapes: Vec<(usize, f64, WeightCurve)> = Vec::new();
        for j in 0..rank.min(self.len()) {
            let value: Vec<f64> = first.iter().map(|&k| self.values[j][k]).collect();
            let in_slope: Vec<f64> = first.iter().map(|&k| self.slopes[j][k]).collect();
            let out_slope: Vec<f64> = last.iter().map(|&k| self.slopes[j][k]).collect();
            let (lo, hi) = range(&times, &value, &out_slope, &in_slope);
            let span = hi - lo;
            if span.is_nan() || span <= 0.0 {
                // Constant: it is part of the base.
                add(&mut base, &self.directions[j], lo);
                continue;
            }
            let (lo, span) = (lo - MARGIN * span, span * (1.0 + 2.0 * MARGIN));
            let shift = if weights == Weights::Bernstein { lo } else { 0.0 };
            add(&mut base, &self.directions[j], shift);
            let curve = WeightCurve {
                // In [MARGIN, 1 - MARGIN] exactly; the clamp only guards the f32 rounding.
                values: value
                    .iter()
                    .map(|&c| ((c - shift) / span) as f32)
                    .map(|w| if weights == Weights::Bernstein { w.clamp(0.0, 1.0) } else { w })
                    .collect(),
                in_tangents: in_slope.iter().map(|&m| (m / span) as f32).collect(),
                out_tangents: out_slope.iter().map(|&m| (m / span) as f32).collect(),
            };
            shapes.push((j, span, curve));
        }
        debug_assert!(n_keys >= 2);
        let base: Vec<[f32; 3]> = base.into_iter().map(f32x3).collect();
        let mut clip = BlendShapeClip { base, targets: Vec::new(), times, curves: Vec::new() };
        for (j, span, curve) in shapes {
            let offsets: Vec<[f32; 3]> = self.directions[j].iter().map(|b| f32x3([b[0] * span, b[1] * span, b[2] * span])).collect();
            // Dense (a principal direction moves nearly every vertex); zero rows dropped.
            let (indices, offsets): (Vec<u32>, Vec<[f32; 3]>) =
                offsets.into_iter().enumerate().filter(|(_, o)| *o != [0.0; 3]).map(|(i, o)| (i as u32, o)).unzip();
            clip.targets.push(Target { name: format!("component_{j}"), indices, offsets });
            clip.curves.push(curve);
        }
        clip
    }
}

fn add(base: &mut [Point], direction: &[Point], scale: f64) {
    if scale != 0.0 {
        for (b, d) in base.iter_mut().zip(direction) {
            for i in 0..3 {
                b[i] += scale * d[i];
            }
        }
    }
}

/// The exact minimum and maximum of the cubic Hermite curve with `values` at `times`, leaving
/// each key with `out_slope` and arriving with `in_slope`: on every interval, the endpoints and
/// the roots of the derivative inside it.
pub fn range(times: &[f64], values: &[f64], out_slope: &[f64], in_slope: &[f64]) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for i in 0..times.len() - 1 {
        let t = times[i + 1] - times[i];
        // Bezier control points of the interval.
        let b = [values[i], values[i] + t * out_slope[i] / 3.0, values[i + 1] - t * in_slope[i + 1] / 3.0, values[i + 1]];
        let at = |s: f64| {
            let r = 1.0 - s;
            r * r * r * b[0] + 3.0 * s * r * r * b[1] + 3.0 * s * s * r * b[2] + s * s * s * b[3]
        };
        let mut consider = |x: f64| {
            lo = lo.min(x);
            hi = hi.max(x);
        };
        consider(b[0]);
        consider(b[3]);
        // Derivative / 3 = d0 (1-s)^2 + 2 d1 s (1-s) + d2 s^2 = qa s^2 + qb s + d0.
        let (d0, d1, d2) = (b[1] - b[0], b[2] - b[1], b[3] - b[2]);
        let (qa, qb, qc) = (d0 - 2.0 * d1 + d2, 2.0 * (d1 - d0), d0);
        let mut roots = Vec::with_capacity(2);
        if qa.abs() <= 1e-14 * (qb.abs() + qc.abs()) {
            if qb != 0.0 {
                roots.push(-qc / qb);
            }
        } else {
            let disc = qb * qb - 4.0 * qa * qc;
            if disc >= 0.0 {
                // The stable form of the two roots.
                let q = -0.5 * (qb + qb.signum() * disc.sqrt());
                roots.push(q / qa);
                if q != 0.0 {
                    roots.push(qc / q);
                }
            }
        }
        for s in roots.into_iter().filter(|s| *s > 0.0 && *s < 1.0) {
            consider(at(s));
        }
    }
    (lo, hi)
}

impl BlendShapeClip {
    /// The trajectory this clip plays (its f32 data in f64), keyed like a trajectory at
    /// `times` (the trajectory it was made from, a contact's two keys at one time): the pose
    /// at each key, and the velocity arriving (the first of a contact, the last key) or leaving.
    pub fn played(&self, times: &[f64]) -> Trajectory {
        let (clip_key, _) = clip_keys(times);
        let n = times.len();
        let mut positions = Vec::with_capacity(n);
        let mut velocities = Vec::with_capacity(n);
        for k in 0..n {
            let c = clip_key[k];
            let arriving = k + 1 == n || (k + 1 < n && clip_key[k + 1] == c);
            positions.push(self.points_with_weights(&self.curves.iter().map(|w| w.values[c] as f64).collect::<Vec<_>>()));
            let slopes: Vec<f64> = self.curves.iter().map(|w| if arriving { w.in_tangents[c] } else { w.out_tangents[c] } as f64).collect();
            let mut v = vec![[0.0; 3]; self.base.len()];
            for (target, &w) in self.targets.iter().zip(&slopes) {
                for (&i, o) in target.indices.iter().zip(&target.offsets) {
                    for d in 0..3 {
                        v[i as usize][d] += w * o[d] as f64;
                    }
                }
            }
            velocities.push(v);
        }
        Trajectory { times: times.to_vec(), positions, velocities }
    }
}

/// The smallest rank whose clip `meets` a criterion (the scene's tolerance), trying 1, 2, ...;
/// all components when none smaller does. `meets` may fail (it reads a cache).
pub(crate) fn smallest_rank<E>(
    components: &Components,
    weights: Weights,
    mut meets: impl FnMut(&BlendShapeClip) -> Result<bool, E>,
) -> Result<usize, E> {
    for rank in 1..components.len() {
        if meets(&components.clip(rank, weights))? {
            return Ok(rank);
        }
    }
    Ok(components.len().max(1))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::algorithms::geometry::{norm, sub};

    /// Five uneven keys of 40 vertices: a bending mode and a twist plus a little noise.
    fn wave() -> Trajectory {
        let times = vec![0.0, 0.3, 0.7, 1.2, 1.5];
        let n = 40;
        let a = [0.0, 1.0, -0.6, 0.4, -0.1];
        let b = [0.0, 0.2, 0.5, -0.3, 0.1];
        let pose = |k: usize| -> Vec<Point> {
            (0..n)
                .map(|v| {
                    let y = v as f64 / n as f64;
                    [y * y * a[k] + 1e-3 * ((v * 7 + k * 3) % 5) as f64, y, (3.0 * y).sin() * b[k]]
                })
                .collect()
        };
        let vel = |k: usize| -> Vec<Point> { (0..n).map(|v| [0.3 * a[k] * (v as f64 / n as f64), 0.0, -0.5 * b[k]]).collect() };
        Trajectory { times, positions: (0..5).map(pose).collect(), velocities: (0..5).map(vel).collect() }
    }

    /// The frames the clips are measured at: 30 fps over the wave's 1.5 s.
    fn frames() -> Vec<f64> {
        (0..=45).map(|f| f as f64 / 30.0).collect()
    }

    fn max_distance(tr: &Trajectory, clip: &BlendShapeClip) -> f64 {
        (0..=300)
            .map(|i| tr.start() + (tr.end() - tr.start()) * i as f64 / 300.0)
            .map(|t| tr.evaluate(t).iter().zip(&clip.points_at(t)).map(|(p, q)| norm(sub(*p, *q))).fold(0.0, f64::max))
            .fold(0.0, f64::max)
    }

    #[test]
    fn full_rank_reproduces_the_trajectory_at_any_time() {
        let tr = wave();
        let c = Components::new(&tr, &frames());
        assert!(c.len() <= 10);
        for weights in [Weights::Bernstein, Weights::Signed] {
            let clip = c.clip(c.len(), weights);
            assert!(max_distance(&tr, &clip) < 1e-6, "{weights:?}: {}", max_distance(&tr, &clip));
        }
        // Fewer frames than key rows: the directions no frame shows are kept, last.
        let few = Components::new(&tr, &[0.0, 0.75, 1.5]);
        assert_eq!(few.len(), c.len());
        assert!(few.singular[2..].iter().all(|&s| s < 1e-9 * few.singular[0]), "{:?}", few.singular);
        assert!(max_distance(&tr, &few.clip(few.len(), Weights::Signed)) < 1e-6);
    }

    #[test]
    fn a_truncated_clip_plays_the_projected_trajectory_and_its_error_falls_with_rank() {
        let tr = wave();
        let c = Components::new(&tr, &frames());
        let mut previous = f64::INFINITY;
        for rank in 1..=c.len() {
            let clip = c.clip(rank, Weights::Bernstein);
            assert_eq!(clip.targets.len(), rank);
            // The clip is exactly the Hermite trajectory of its key data.
            let played = clip.played(&tr.times);
            assert!(max_distance(&played, &clip) < 1e-6, "rank {rank}");
            // Its frames are the rank-r projection of the trajectory's: the residual summed
            // over the frames is the dropped singular values.
            let residual: f64 = frames()
                .iter()
                .map(|&t| tr.evaluate(t).iter().zip(&clip.points_at(t)).map(|(p, q)| norm(sub(*p, *q)).powi(2)).sum::<f64>())
                .sum::<f64>();
            let dropped = c.singular[rank..].iter().map(|s| s * s).sum::<f64>().sqrt();
            assert!((residual.sqrt() - dropped).abs() <= 1e-5, "rank {rank}: {} against {dropped}", residual.sqrt());
            let e = max_distance(&tr, &clip);
            assert!(e <= previous + 1e-6, "rank {rank}: {e} > {previous}");
            previous = e;
        }
    }

    #[test]
    fn every_weight_stays_in_zero_one_at_any_time_and_touches_both_ends() {
        let tr = wave();
        let c = Components::new(&tr, &frames());
        let clip = c.clip(4, Weights::Bernstein);
        let (mut lo, mut hi) = (vec![f64::INFINITY; 4], vec![f64::NEG_INFINITY; 4]);
        for i in 0..=20000 {
            let w = clip.weights_at(1.5 * i as f64 / 20000.0);
            for j in 0..4 {
                assert!((0.0..=1.0).contains(&w[j]), "component {j}: {}", w[j]);
                lo[j] = lo[j].min(w[j]);
                hi[j] = hi[j].max(w[j]);
            }
        }
        // The range is exact (not sampled): dense sampling reaches both ends within the margin.
        for j in 0..4 {
            assert!(lo[j] < 2e-6 && hi[j] > 1.0 - 2e-6, "component {j}: [{}, {}]", lo[j], hi[j]);
        }
        // Signed weights are the same curves, unshifted, same points.
        let signed = c.clip(4, Weights::Signed);
        assert!(signed.curves.iter().flat_map(|w| &w.values).any(|&x| x < 0.0));
        let d = (0..=100)
            .map(|i| {
                clip.points_at(0.015 * i as f64).iter().zip(&signed.points_at(0.015 * i as f64)).map(|(p, q)| norm(sub(*p, *q))).fold(0.0, f64::max)
            })
            .fold(0.0, f64::max);
        assert!(d < 1e-6, "{d}");
    }

    #[test]
    fn the_range_of_a_cubic_is_exact() {
        // c(t) = t^3 - t on [-2, 2] as one Hermite interval: values -6, 6, slopes 11, 11;
        // extrema at t = ±1/sqrt(3) are ±2/(3 sqrt 3), inside the ends.
        let (lo, hi) = range(&[-2.0, 2.0], &[-6.0, 6.0], &[11.0, 11.0], &[11.0, 11.0]);
        assert_eq!((lo, hi), (-6.0, 6.0));
        // c(t) = t^3 - 3t on [-1.5, 1.2]: local max 2 at -1, local min -2 at 1.
        let c = |t: f64| t * t * t - 3.0 * t;
        let d = |t: f64| 3.0 * t * t - 3.0;
        let (lo, hi) = range(&[-1.5, 1.2], &[c(-1.5), c(1.2)], &[d(-1.5), d(1.2)], &[d(-1.5), d(1.2)]);
        assert!((lo + 2.0).abs() < 1e-12 && (hi - 2.0).abs() < 1e-12, "{lo} {hi}");
        // A straight line (no interior root) and a constant.
        assert_eq!(range(&[0.0, 1.0, 2.0], &[0.0, 1.0, 2.0], &[1.0; 3], &[1.0; 3]), (0.0, 2.0));
        assert_eq!(range(&[0.0, 1.0], &[3.0, 3.0], &[0.0; 2], &[0.0; 2]), (3.0, 3.0));
    }

    #[test]
    fn a_contact_keeps_its_two_velocities() {
        let mut tr = wave();
        tr.times = vec![0.0, 0.3, 0.3, 1.2, 1.5];
        tr.positions[2] = tr.positions[1].clone();
        let c = Components::new(&tr, &frames());
        let clip = c.clip(c.len(), Weights::Bernstein);
        assert_eq!(clip.times, vec![0.0, 0.3, 1.2, 1.5]);
        let played = clip.played(&tr.times);
        for k in 0..5 {
            for (p, q) in tr.velocities[k].iter().zip(&played.velocities[k]) {
                assert!(norm(sub(*p, *q)) < 1e-5, "key {k}");
            }
        }
        assert!(max_distance(&tr, &clip) < 1e-6);
    }

    #[test]
    fn the_smallest_rank_is_the_first_that_meets() {
        let tr = wave();
        let c = Components::new(&tr, &frames());
        let errors: Vec<f64> = (1..=c.len()).map(|r| max_distance(&tr, &c.clip(r, Weights::Bernstein))).collect();
        let goal = errors[2] * 1.0001;
        let rank = smallest_rank::<()>(&c, Weights::Bernstein, |clip| Ok(max_distance(&tr, clip) <= goal)).unwrap();
        assert_eq!(rank, errors.iter().position(|&e| e <= goal).unwrap() + 1);
    }
}
