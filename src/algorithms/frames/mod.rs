//! Frame sequences (what a vertex cache holds) and the algorithms on them: the least-squares
//! Hermite [`fit`] on given keys, the automatic choice of [`keyframes`], the [`deviation`] of a
//! trajectory from every frame, and frame `range`s.
//!
//! [`FrameSource`] is the contract between the cache readers ([`crate::formats::cache`]) and
//! what consumes a cache: the readers implement it, the algorithms here only read frames
//! through it, so they never see a file.

mod band;
pub mod deviation;
pub mod fit;
pub mod keyframes;
mod range;
pub mod weld;

pub use range::{FrameRange, Subrange};

use crate::algorithms::geometry::Point;
use crate::support::error::Result;

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

impl<S: FrameSource + ?Sized> FrameSource for Box<S> {
    fn vertex_count(&self) -> usize {
        (**self).vertex_count()
    }
    fn frame_count(&self) -> usize {
        (**self).frame_count()
    }
    fn time(&self, frame: usize) -> f64 {
        (**self).time(frame)
    }
    fn read_frame(&mut self, frame: usize, out: &mut [Point]) -> Result<()> {
        (**self).read_frame(frame, out)
    }
}

/// A frame source read through a hook: `before_read(frame, reads)` runs before every read
/// (`reads`: the frames read through it so far) and can refuse it, and the reads are counted.
/// The key selection's read statistics, the stages' `--max-time` check at every frame, and
/// the tests' damaged caches.
pub(crate) struct Metered<'a, S: ?Sized, F> {
    inner: &'a mut S,
    before_read: F,
    /// Frames read through it.
    pub reads: usize,
}

impl<'a, S: FrameSource + ?Sized, F: FnMut(usize, usize) -> Result<()>> Metered<'a, S, F> {
    /// `inner` read through `before_read`, no frame read yet.
    pub fn new(inner: &'a mut S, before_read: F) -> Self {
        Metered { inner, before_read, reads: 0 }
    }
}

impl<S: FrameSource + ?Sized, F: FnMut(usize, usize) -> Result<()>> FrameSource for Metered<'_, S, F> {
    fn vertex_count(&self) -> usize {
        self.inner.vertex_count()
    }
    fn frame_count(&self) -> usize {
        self.inner.frame_count()
    }
    fn time(&self, frame: usize) -> f64 {
        self.inner.time(frame)
    }
    fn read_frame(&mut self, frame: usize, out: &mut [Point]) -> Result<()> {
        (self.before_read)(frame, self.reads)?;
        self.reads += 1;
        self.inner.read_frame(frame, out)
    }
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

/// Mean frames per second of strictly increasing times, snapped to a whole or NTSC
/// (x/1.001) rate when within 1e-4 of one (f32 times carry rounding); `None` for fewer than
/// two times.
pub(crate) fn rate_of(times: &[f64]) -> Option<f64> {
    let span = times.last()? - times.first()?;
    if times.len() < 2 || span <= 0.0 {
        return None;
    }
    let rate = (times.len() - 1) as f64 / span;
    let whole = rate.round();
    let ntsc = (rate * 1.001).round() / 1.001;
    Some(if (rate - whole).abs() <= 1e-4 * rate {
        whole
    } else if (rate - ntsc).abs() <= 1e-4 * rate {
        ntsc
    } else {
        rate
    })
}
