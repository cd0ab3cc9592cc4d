//! The full-frame form of an animation: one pose per frame at the scene's fps.
//!
//! This is what a vertex cache holds, and the baseline the blendshape files are measured
//! against (size and deviation).

use crate::algorithms::frames::FrameSource;
use crate::algorithms::spacetime::trajectory::Trajectory;
use crate::support::error::Result;

/// An animation as a vertex cache: every vertex at every frame.
#[derive(Debug, Clone, PartialEq)]
pub struct FullFrame {
    /// Frame numbers (USD time codes at `fps`).
    pub frames: Vec<i64>,
    /// Frame times in seconds.
    pub times: Vec<f64>,
    /// `points[frame][vertex]`.
    pub points: Vec<Vec<[f32; 3]>>,
}

impl FullFrame {
    /// Sample `trajectory` at every frame of its key range (`Trajectory::frames`).
    pub(crate) fn from_trajectory(trajectory: &Trajectory, fps: f64) -> FullFrame {
        let frames = trajectory.frames(fps);
        let mut buffer = vec![[0.0; 3]; trajectory.vertex_count()];
        let points = frames
            .iter()
            .map(|&(_, t)| {
                trajectory.evaluate_into(t, &mut buffer);
                buffer.iter().map(|p| [p[0] as f32, p[1] as f32, p[2] as f32]).collect()
            })
            .collect();
        FullFrame { frames: frames.iter().map(|f| f.0).collect(), times: frames.iter().map(|f| f.1).collect(), points }
    }

    /// Every frame of `source` (a vertex cache) as it is, at its own times: the input of a
    /// cache bake written per frame. Frame numbers are the times at `fps`, rounded (a cache
    /// sampled off the frame grid, or unevenly, keeps its times; the numbers only label
    /// USD's time codes and stay increasing).
    pub(crate) fn from_source(source: &mut dyn FrameSource, fps: f64) -> Result<FullFrame> {
        let count = source.frame_count();
        let mut buffer = vec![[0.0; 3]; source.vertex_count()];
        let (mut frames, mut times, mut points) = (Vec::with_capacity(count), Vec::with_capacity(count), Vec::with_capacity(count));
        for f in 0..count {
            let t = source.time(f);
            let number = ((t * fps).round() as i64).max(frames.last().map_or(i64::MIN, |&n: &i64| n + 1));
            source.read_frame(f, &mut buffer)?;
            frames.push(number);
            times.push(t);
            points.push(buffer.iter().map(|p| [p[0] as f32, p[1] as f32, p[2] as f32]).collect());
        }
        Ok(FullFrame { frames, times, points })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_cache_is_taken_frame_for_frame_at_its_own_times() {
        use crate::algorithms::frames::MemoryFrames;
        let times = vec![(1.0f32 / 24.0) as f64, (2.0f32 / 24.0) as f64, (17.0f32 / 24.0) as f64];
        let mut cache = MemoryFrames { times: times.clone(), frames: (0..3).map(|i| vec![[i as f64 * 0.1, 1.0, 2.0]]).collect() };
        let ff = FullFrame::from_source(&mut cache, 24.0).unwrap();
        assert_eq!((ff.frames, ff.times), (vec![1, 2, 17], times));
        assert_eq!(ff.points[2], vec![[0.2f32, 1.0, 2.0]]);
    }

    #[test]
    fn one_pose_per_frame_of_the_key_range() {
        let tr = Trajectory::with_zero_velocities(vec![0.5, 1.0], vec![vec![[0.0; 3]], vec![[1.0, 0.0, 0.0]]]);
        let ff = FullFrame::from_trajectory(&tr, 10.0);
        assert_eq!(ff.frames, (5..=10).collect::<Vec<_>>());
        assert_eq!(ff.points.len(), 6);
        assert_eq!(ff.points[0][0], [0.0; 3]);
        assert_eq!(ff.points[5][0], [1.0, 0.0, 0.0]);
        // Frame 7 is at 40% of the interval: smoothstep h01(0.4) = 0.352 with zero velocities.
        assert!((ff.points[2][0][0] - 0.352).abs() < 1e-6, "{:?}", ff.points[2]);
    }
}
