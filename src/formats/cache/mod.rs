//! Vertex caches: frame-by-frame positions of one mesh (OBJ sequences, PC2, MDD, glTF clips,
//! USD point caches, Alembic, FBX animations), read one frame at a time so memory stays proportional to a few frames.
//!
//! Every reader implements [`FrameSource`], the contract with what consumes a cache (keyframe
//! selection, the Hermite fit, the error report: [`crate::algorithms::frames`]). [`VertexCache::open`] picks the
//! reader by extension and returns the topology, the frames and what the report needs;
//! [`write()`] writes any format from a mesh and its frames. The formats and what each reader
//! accepts are specified in `formats/caches.md`.
//!
//! Every reader checks its file's structure against the file's size before allocating
//! anything sized by the file, and reads one frame per call: memory stays at a few frames
//! whatever the cache's length.

mod abc;
mod binary;
mod fbx;
#[cfg(test)]
mod fuzz;
pub(crate) mod gltf_clip;
mod mdd;
mod pc2;
mod sequence;
mod usd;
mod vertex_cache;

pub use gltf_clip::fixtures as gltf_fixtures;
pub use sequence::SequencePattern;
pub use vertex_cache::{write, CacheFormat, CacheOptions, FpsSource, VertexCache};

use std::path::Path;

use crate::algorithms::frames::{rate_of, FrameSource};
use crate::support::error::{Error, Result};

/// The most frames a cache may hold: consumers keep a few numbers per frame, and a header
/// or an animation asking for more is damaged rather than long (10 hours at 60 fps).
pub(crate) const MAX_FRAMES: usize = 2_160_000;

/// What every writer needs of its frames: a positive finite fps, at least one frame and one
/// vertex, counts that fit the formats' 32-bit fields, increasing times. Returns
/// (vertices, frames).
pub(crate) fn check_writable(path: &Path, frames: &dyn FrameSource, fps: f64) -> Result<(usize, usize)> {
    let fail =
        |problem: String| Err(Error::general(format!("cannot write {}: {problem}", path.display()), "pass a cache with frames and a positive fps"));
    if !(fps.is_finite() && fps > 0.0) {
        return fail(format!("fps {fps} is not positive"));
    }
    let (vertices, count) = (frames.vertex_count(), frames.frame_count());
    if vertices == 0 || count == 0 {
        return fail(format!("{count} frames of {vertices} vertices"));
    }
    if vertices > i32::MAX as usize / 12 || count > MAX_FRAMES {
        return fail(format!("{count} frames of {vertices} vertices is more than the cache formats hold"));
    }
    if let Some(i) = (1..count).find(|&i| frames.time(i).partial_cmp(&frames.time(i - 1)) != Some(std::cmp::Ordering::Greater)) {
        return fail(format!("frame times do not increase at frame {i}"));
    }
    Ok((vertices, count))
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::algorithms::frames::MemoryFrames;
    use crate::algorithms::geometry::TriMesh;

    /// A fresh scratch folder for one test.
    pub fn scratch(name: &str) -> std::path::PathBuf {
        // Kept: the test removes it when it is done.
        tempfile::Builder::new().prefix(&format!("blendsim-cache-{name}-")).tempdir().unwrap().keep()
    }

    /// An `n` x `n` grid in the xy plane, two triangles per square.
    pub(crate) fn wave_mesh(n: u32) -> TriMesh {
        let positions = (0..n * n).map(|v| [(v % n) as f64, (v / n) as f64, 0.0]).collect();
        let mut triangles = Vec::new();
        for i in 0..n - 1 {
            for j in 0..n - 1 {
                let a = i * n + j;
                triangles.push([a, a + 1, a + n + 1]);
                triangles.push([a, a + n + 1, a + n]);
            }
        }
        TriMesh { positions, triangles, attributes: None }
    }

    /// `frames` frames at `fps` of `vertices` points on a travelling wave, values that are
    /// exact in f32 only by accident (so f32 rounding is exercised).
    pub fn wave(vertices: usize, frames: usize, fps: f64) -> MemoryFrames {
        let n = (vertices as f64).sqrt().ceil() as usize;
        MemoryFrames {
            times: (0..frames).map(|f| f as f64 / fps).collect(),
            frames: (0..frames)
                .map(|f| {
                    let t = f as f64 / fps;
                    (0..vertices).map(|v| [(v % n) as f64 + 0.1 * t, (v / n) as f64, (0.7 * (v % n) as f64 - 3.0 * t).sin() / 3.0]).collect()
                })
                .collect(),
        }
    }

    /// Same counts, times within 1e-6 s, and every point within `tolerance` plus f32 rounding.
    pub(crate) fn assert_frames_equal(expected: &mut dyn FrameSource, got: &mut dyn FrameSource, tolerance: f64) {
        assert_eq!((got.frame_count(), got.vertex_count()), (expected.frame_count(), expected.vertex_count()));
        let mut a = vec![[0.0; 3]; expected.vertex_count()];
        let mut b = a.clone();
        for f in 0..expected.frame_count() {
            assert!((got.time(f) - expected.time(f)).abs() < 1e-6, "frame {f}: time {} vs {}", got.time(f), expected.time(f));
            expected.read_frame(f, &mut a).unwrap();
            got.read_frame(f, &mut b).unwrap();
            for (v, (p, q)) in a.iter().zip(&b).enumerate() {
                for d in 0..3 {
                    let f32_rounding = 2.0 * f32::EPSILON as f64 * p[d].abs().max(1.0);
                    assert!((p[d] - q[d]).abs() <= tolerance + f32_rounding, "frame {f}, vertex {v}: {p:?} vs {q:?}");
                }
            }
        }
    }
}
