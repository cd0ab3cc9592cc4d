//! A frame range of a cache: `start` and `end` are 0-based frame indices in file order,
//! `end` inclusive, negative values counting from the end (`-1` is the last frame), as in the
//! scene's `[cache]` table (`start = 0`, `end = -1` is the whole cache).

use super::FrameSource;
use crate::algorithms::geometry::Point;
use crate::support::error::Result;

/// A range of frames, 0-based with `end` inclusive; negative values count from the end
/// (`-1` is the last frame), as in the scene's `[cache] start` / `end`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FrameRange {
    /// First frame.
    pub start: i64,
    /// Last frame (inclusive).
    pub end: i64,
}

impl Default for FrameRange {
    fn default() -> Self {
        FrameRange::ALL
    }
}

impl FrameRange {
    /// Every frame.
    pub(crate) const ALL: FrameRange = FrameRange { start: 0, end: -1 };

    /// The first selected frame and how many there are, out of `available` frames; on failure
    /// the problem and its fix, for the caller to attach to the cache file.
    pub fn resolve(&self, available: usize) -> std::result::Result<(usize, usize), (String, String)> {
        let at = |i: i64| if i < 0 { available as i64 + i } else { i };
        let (first, last) = (at(self.start), at(self.end));
        if first < 0 || last >= available as i64 || first > last {
            return Err((
                format!(
                    "frame range start = {}, end = {} selects no frames of the {available} the cache holds (indices 0 to {})",
                    self.start,
                    self.end,
                    available as i64 - 1
                ),
                format!("choose 0 <= start <= end < {available}; negative values count from the end (-1 is the last frame)"),
            ));
        }
        Ok((first as usize, (last - first + 1) as usize))
    }
}

/// The frames `first .. first + count` of another source, renumbered from 0 (times unchanged).
#[derive(Debug)]
pub struct Subrange<S> {
    inner: S,
    first: usize,
    count: usize,
}

impl<S: FrameSource> Subrange<S> {
    /// Invariant: `first + count <= inner.frame_count()` (as [`FrameRange::resolve`] returns).
    pub fn new(inner: S, first: usize, count: usize) -> Self {
        assert!(first + count <= inner.frame_count(), "a subrange lies within its source");
        Subrange { inner, first, count }
    }
}

impl<S: FrameSource> FrameSource for Subrange<S> {
    fn vertex_count(&self) -> usize {
        self.inner.vertex_count()
    }

    fn frame_count(&self) -> usize {
        self.count
    }

    fn time(&self, frame: usize) -> f64 {
        assert!(frame < self.count, "frame {frame} of {}", self.count);
        self.inner.time(self.first + frame)
    }

    fn read_frame(&mut self, frame: usize, out: &mut [Point]) -> Result<()> {
        assert!(frame < self.count, "frame {frame} of {}", self.count);
        self.inner.read_frame(self.first + frame, out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::algorithms::frames::MemoryFrames;

    #[test]
    fn negative_indices_count_from_the_end() {
        assert_eq!(FrameRange::ALL.resolve(10), Ok((0, 10)));
        assert_eq!(FrameRange { start: 2, end: -3 }.resolve(10), Ok((2, 6)));
        assert_eq!(FrameRange { start: -1, end: -1 }.resolve(10), Ok((9, 1)));
        assert_eq!(FrameRange { start: 4, end: 4 }.resolve(10), Ok((4, 1)));
        for bad in [FrameRange { start: 5, end: 3 }, FrameRange { start: 0, end: 10 }, FrameRange { start: -11, end: -1 }] {
            let (problem, fix) = bad.resolve(10).unwrap_err();
            assert!(problem.contains("selects no frames of the 10 the cache holds (indices 0 to 9)"), "{problem}");
            assert!(fix.contains("-1 is the last frame"), "{fix}");
        }
        assert!(FrameRange::ALL.resolve(0).is_err(), "an empty cache has no range");
    }

    #[test]
    fn subrange_renumbers_frames_and_keeps_times() {
        let frames = MemoryFrames { times: vec![0.0, 0.5, 1.0, 1.5], frames: (0..4).map(|i| vec![[i as f64; 3]]).collect() };
        let mut sub = Subrange::new(frames, 1, 2);
        assert_eq!((sub.frame_count(), sub.vertex_count(), sub.time(0), sub.time(1)), (2, 1, 0.5, 1.0));
        let mut out = [[0.0; 3]];
        sub.read_frame(1, &mut out).unwrap();
        assert_eq!(out, [[2.0; 3]]);
    }
}
