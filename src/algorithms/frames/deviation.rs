//! How far a trajectory is from a cache: per frame, the largest and the root-mean-square vertex
//! distance, relative to the cache's bounding-box diagonal. Both are computed in one pass over
//! the frames, holding two frames at a time.

use super::FrameSource;
use crate::algorithms::geometry::{norm, sub, Point};
use crate::algorithms::spacetime::trajectory::Trajectory;
use crate::support::error::{Error, Result};

/// Distances of a trajectory from every frame of a cache, relative to `diagonal`.
///
/// Invariants: `per_frame_max.len() == per_frame_rms.len() ==` the cache's frame count;
/// `max` is the largest of `per_frame_max`; `rms` is over all frames and vertices.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CacheDeviation {
    /// The length distances are divided by (the cache's bounding-box diagonal); 1 when the
    /// cache is a single point.
    pub diagonal: f64,
    /// Per frame, the largest vertex distance (relative to `diagonal`).
    pub per_frame_max: Vec<f64>,
    /// Per frame, the root mean square vertex distance (relative to `diagonal`).
    pub per_frame_rms: Vec<f64>,
    /// The largest of `per_frame_max`.
    pub max: f64,
    /// Root mean square over every frame and vertex.
    pub rms: f64,
}

/// The diagonal of the box holding every vertex of every frame: the length a cache's
/// tolerance is relative to. One pass over the frames.
pub fn cache_diagonal<S: FrameSource + ?Sized>(source: &mut S) -> Result<f64> {
    let mut frame = vec![[0.0; 3]; source.vertex_count()];
    let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    for f in 0..source.frame_count() {
        source.read_frame(f, &mut frame)?;
        for p in &frame {
            for d in 0..3 {
                lo[d] = lo[d].min(p[d]);
                hi[d] = hi[d].max(p[d]);
            }
        }
    }
    Ok(if lo[0] <= hi[0] { norm(sub(hi, lo)) } else { 0.0 })
}

/// The trajectory (evaluated at each frame's time; it holds its end poses outside its key
/// range) against every frame of the cache.
pub fn deviation<S: FrameSource + ?Sized>(source: &mut S, trajectory: &Trajectory, diagonal: f64) -> Result<CacheDeviation> {
    let vertices = source.vertex_count();
    if trajectory.vertex_count() != vertices {
        return Err(Error::general(
            format!("the trajectory has {} vertices but the cache has {vertices}", trajectory.vertex_count()),
            "compare a trajectory with the cache it was made from",
        ));
    }
    let scale = if diagonal > 0.0 { diagonal } else { 1.0 };
    let frames = source.frame_count();
    let (mut frame, mut pose) = (vec![[0.0; 3]; vertices], vec![[0.0; 3]; vertices]);
    let (mut per_frame_max, mut per_frame_rms) = (Vec::with_capacity(frames), Vec::with_capacity(frames));
    let mut sum2 = 0.0;
    for f in 0..frames {
        source.read_frame(f, &mut frame)?;
        trajectory.evaluate_into(source.time(f), &mut pose);
        let (max, s2) = frame_distance(&frame, &pose);
        sum2 += s2;
        per_frame_max.push(max / scale);
        per_frame_rms.push(if vertices > 0 { (s2 / vertices as f64).sqrt() / scale } else { 0.0 });
    }
    let count = (frames * vertices).max(1) as f64;
    Ok(CacheDeviation {
        diagonal: scale,
        max: per_frame_max.iter().copied().fold(0.0, f64::max),
        rms: (sum2 / count).sqrt() / scale,
        per_frame_max,
        per_frame_rms,
    })
}

/// Largest vertex distance and sum of squared distances between two poses.
pub(crate) fn frame_distance(a: &[Point], b: &[Point]) -> (f64, f64) {
    let (mut max2, mut sum2) = (0.0f64, 0.0);
    for (p, q) in a.iter().zip(b) {
        let d = sub(*p, *q);
        let d2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
        max2 = max2.max(d2);
        sum2 += d2;
    }
    (max2.sqrt(), sum2)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::algorithms::frames::MemoryFrames;

    #[test]
    fn measures_distance_per_frame_relative_to_the_cache_box() {
        // Two vertices moving apart along x: box from (0,0,0) to (4,3,0) over all frames.
        let mut cache = MemoryFrames {
            times: vec![0.0, 1.0, 2.0],
            frames: vec![vec![[0.0, 0.0, 0.0], [1.0, 3.0, 0.0]], vec![[0.0, 0.0, 0.0], [2.0, 3.0, 0.0]], vec![[0.0, 0.0, 0.0], [4.0, 3.0, 0.0]]],
        };
        let diagonal = cache_diagonal(&mut cache).unwrap();
        assert_eq!(diagonal, 5.0);
        // A trajectory that stays at frame 0: off by 0, 1 and 3 at vertex 1.
        let still = Trajectory::with_zero_velocities(vec![0.0, 2.0], vec![cache.frames[0].clone(), cache.frames[0].clone()]);
        let dev = deviation(&mut cache, &still, diagonal).unwrap();
        assert_eq!(dev.per_frame_max, vec![0.0, 0.2, 0.6]);
        let rms = |d: f64| (d * d / 2.0f64).sqrt() / 5.0;
        assert_eq!(dev.per_frame_rms, vec![0.0, rms(1.0), rms(3.0)]);
        assert_eq!(dev.max, 0.6);
        assert!((dev.rms - ((1.0 + 9.0) / 6.0f64).sqrt() / 5.0).abs() < 1e-15);
    }

    #[test]
    fn a_trajectory_of_another_mesh_is_an_error() {
        let mut cache = MemoryFrames { times: vec![0.0, 1.0], frames: vec![vec![[0.0; 3]; 2]; 2] };
        let other = Trajectory::with_zero_velocities(vec![0.0, 1.0], vec![vec![[0.0; 3]; 3]; 2]);
        let e = deviation(&mut cache, &other, 1.0).unwrap_err();
        assert!(e.problem.contains("3 vertices but the cache has 2"), "{e}");
    }
}
