//! Vertex caches: frame-by-frame positions of one mesh (OBJ sequences, PC2, MDD, glTF clips,
//! USD point caches), read one frame at a time so memory stays proportional to a few frames.
//!
//! [`FrameSource`] is the contract between the cache readers and what consumes a cache
//! (keyframe selection, the Hermite fit, the error report).

pub mod band;
pub mod deviation;
pub mod fit;
pub mod keyframes;

use crate::error::Result;
use crate::mesh::Point;

/// Frames of one mesh's vertex positions, read on demand.
///
/// Invariants: every frame has [`FrameSource::vertex_count`] vertices; frame times are
/// strictly increasing; `read_frame` may be called in any order and any number of times (a
/// reader re-reads from its file rather than keeping every frame).
pub trait FrameSource {
    /// Vertices per frame.
    fn vertex_count(&self) -> usize;
    /// Number of frames.
    fn frame_count(&self) -> usize;
    /// Time of `frame` in seconds.
    fn time(&self, frame: usize) -> f64;
    /// Positions of `frame` into `out` (`out.len() == vertex_count()`).
    fn read_frame(&mut self, frame: usize, out: &mut [Point]) -> Result<()>;
}

/// Frames held in memory (tests, and caches computed in-process).
#[derive(Debug, Clone, PartialEq)]
pub struct MemoryFrames {
    /// Time of every frame in seconds, strictly increasing.
    pub times: Vec<f64>,
    /// `frames[frame][vertex]`.
    pub frames: Vec<Vec<Point>>,
}

impl FrameSource for MemoryFrames {
    fn vertex_count(&self) -> usize {
        self.frames.first().map_or(0, Vec::len)
    }

    fn frame_count(&self) -> usize {
        self.frames.len()
    }

    fn time(&self, frame: usize) -> f64 {
        self.times[frame]
    }

    fn read_frame(&mut self, frame: usize, out: &mut [Point]) -> Result<()> {
        out.copy_from_slice(&self.frames[frame]);
        Ok(())
    }
}
