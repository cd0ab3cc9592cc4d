//! The full-frame form of an animation: one pose per frame at the scene's fps.

use crate::spacetime::trajectory::Trajectory;

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
    pub fn from_trajectory(trajectory: &Trajectory, fps: f64) -> FullFrame {
        let _ = (trajectory, fps);
        todo!()
    }
}
