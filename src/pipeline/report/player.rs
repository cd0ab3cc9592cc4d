//! The data of `report.html`'s player: the blendshape clip (base, shapes, a weight per shape at
//! every shown frame) and the reference's positions at those frames, with each vertex's
//! distance from the hermite baseline. The page cannot read the glb (browsers refuse to fetch
//! `file://`), so it holds what it draws, within [`PLAYER_BYTES`]: bigger bakes show every
//! n-th frame, or every n-th vertex as points, and the page says so.

use crate::algorithms::blendshape::clip::BlendShapeClip;
use crate::algorithms::geometry::{norm, sub, Point};
use crate::algorithms::spacetime::trajectory::Trajectory;
use crate::support::error::Result;

/// The most bytes of player data in `report.html` (before base64, which adds a third): with
/// the page's tables and plots it keeps `report.html` under [`super::html::HTML_LIMIT`].
pub const PLAYER_BYTES: usize = 1_100_000;

/// What the player draws (every array over the kept vertices).
#[derive(Debug, Clone, PartialEq)]
pub struct Player {
    /// `full-frame` (the trajectory evaluated at each frame) or `cache` (the input cache).
    pub reference: String,
    /// Seconds of the shown frames.
    pub times: Vec<f64>,
    /// Every `frame_stride`-th frame is shown (1: all).
    pub frame_stride: usize,
    /// Frames of the reference before decimation.
    pub total_frames: usize,
    /// Every `vertex_stride`-th vertex is kept (1: all, drawn as triangles; else as points).
    pub vertex_stride: usize,
    /// Vertices of the surface before decimation.
    pub total_vertices: usize,
    /// The surface's triangles (empty when vertices are decimated).
    pub triangles: Vec<[u32; 3]>,
    /// The clip's base points.
    pub base: Vec<[f32; 3]>,
    /// Per shape: kept vertex indices and their offsets.
    pub shapes: Vec<(Vec<u32>, Vec<[f32; 3]>)>,
    /// Per shown frame, per shape: the weight as the files store it (f32).
    pub weights: Vec<Vec<f32>>,
    /// Per shown frame: the reference's positions.
    pub frames: Vec<Vec<[f32; 3]>>,
    /// Per shown frame, per vertex: distance of the played animation from the hermite baseline.
    pub hermite_distance: Vec<Vec<f32>>,
    /// The key times (the solution's).
    pub key_times: Vec<f64>,
    /// The diagonal the error series is relative to, in scene units.
    pub diagonal: f64,
}

/// About the fewest frames the player shows (every frame of a shorter bake): a second at 60 fps.
/// Below that the surface is thinned instead, as smooth motion tells more than every vertex.
pub const MIN_FRAMES: usize = 60;

/// The strides that keep the player within [`PLAYER_BYTES`]: `(vertex, frame)`. Vertices are
/// thinned until the fixed part fits in half the budget and [`MIN_FRAMES`] fit in the rest;
/// then frames, to fit them all.
pub fn strides(vertices: usize, triangles: usize, shape_entries: usize, shapes: usize, frames: usize) -> (usize, usize) {
    // Fixed part: base (12 B a vertex), shapes (16 B an entry), triangles (12 B; thinned
    // vertices are drawn as points); per frame: reference (6 B a vertex, int16), hermite
    // distance (1 B), weights (4 B a shape), its time and error as JSON text (under 48 B).
    let fixed = |s: usize| (12 * vertices + 16 * shape_entries) / s + if s == 1 { 12 * triangles } else { 0 };
    let room = |s: usize| PLAYER_BYTES.saturating_sub(fixed(s)) / (7 * vertices.div_ceil(s) + 4 * shapes + 48);
    let mut vertex_stride = 1;
    while (fixed(vertex_stride) > PLAYER_BYTES / 2 || room(vertex_stride) < frames.min(MIN_FRAMES)) && vertex_stride < vertices {
        vertex_stride += 1;
    }
    (vertex_stride, frames.div_ceil(room(vertex_stride).max(2)).max(1))
}

/// The player of `clip` (the files' shapes) against the reference frames at `times` (read by
/// `reference`, only those shown), coloured by the distance of `played` (the animation the
/// files play) from `hermite`. `diagonal`: what the error series is relative to.
#[allow(clippy::too_many_arguments)]
pub fn build(
    reference_name: &str,
    clip: &BlendShapeClip,
    triangles: &[[u32; 3]],
    times: &[f64],
    mut reference: impl FnMut(usize) -> Result<Vec<Point>>,
    played: &Trajectory,
    hermite: &Trajectory,
    key_times: &[f64],
    diagonal: f64,
) -> Result<Player> {
    let mut shown = ShownFrames::new(clip, triangles.len(), times.len());
    for f in 0..times.len() {
        if !shown.shows(f) {
            continue;
        }
        shown.add(&reference(f)?, &played.evaluate(times[f]), &hermite.evaluate(times[f]));
    }
    Ok(shown.player(reference_name, clip, triangles, times, key_times, diagonal))
}

/// The player's frames gathered one shown frame at a time, in order, so that a caller that
/// walks every frame for its own measures hands the player the poses it already evaluated.
pub struct ShownFrames {
    /// Every `vertex_stride`-th vertex is kept.
    vertex_stride: usize,
    /// Every `frame_stride`-th frame is shown.
    frame_stride: usize,
    /// Per shown frame: the reference's kept positions.
    frames: Vec<Vec<[f32; 3]>>,
    /// Per shown frame: the played animation's distance from hermite at the kept vertices.
    hermite_distance: Vec<Vec<f32>>,
}

impl ShownFrames {
    /// The strides of `clip` on a surface of `triangles` triangles over `frames` frames
    /// ([`strides`]), and no frame yet.
    pub fn new(clip: &BlendShapeClip, triangles: usize, frames: usize) -> ShownFrames {
        let entries: usize = clip.targets.iter().map(|t| t.indices.len()).sum();
        let (vertex_stride, frame_stride) = strides(clip.base.len(), triangles, entries, clip.targets.len(), frames);
        let shown = frames.div_ceil(frame_stride);
        ShownFrames { vertex_stride, frame_stride, frames: Vec::with_capacity(shown), hermite_distance: Vec::with_capacity(shown) }
    }

    /// Whether frame `f` is shown (the next [`ShownFrames::add`] must be the next shown one).
    pub fn shows(&self, f: usize) -> bool {
        f.is_multiple_of(self.frame_stride)
    }

    /// The next shown frame: the reference's pose, and the played animation's and hermite's.
    pub fn add(&mut self, reference: &[Point], played: &[Point], hermite: &[Point]) {
        let vs = self.vertex_stride;
        self.frames.push(reference.iter().step_by(vs).map(|p| [p[0] as f32, p[1] as f32, p[2] as f32]).collect());
        self.hermite_distance.push(played.iter().zip(hermite).step_by(vs).map(|(p, q)| norm(sub(*p, *q)) as f32).collect());
    }

    /// The player of these frames (see [`build`]).
    pub fn player(
        self,
        reference_name: &str,
        clip: &BlendShapeClip,
        triangles: &[[u32; 3]],
        times: &[f64],
        key_times: &[f64],
        diagonal: f64,
    ) -> Player {
        let (vs, fs) = (self.vertex_stride, self.frame_stride);
        let shown: Vec<usize> = (0..times.len()).step_by(fs).collect();
        Player {
            reference: reference_name.into(),
            times: shown.iter().map(|&f| times[f]).collect(),
            frame_stride: fs,
            total_frames: times.len(),
            vertex_stride: vs,
            total_vertices: clip.base.len(),
            triangles: if vs == 1 { triangles.to_vec() } else { Vec::new() },
            base: clip.base.iter().step_by(vs).copied().collect(),
            shapes: clip
                .targets
                .iter()
                .map(|t| {
                    let kept = t.indices.iter().zip(&t.offsets).filter(|(i, _)| (**i as usize).is_multiple_of(vs));
                    kept.map(|(i, o)| (*i / vs as u32, *o)).unzip()
                })
                .collect(),
            weights: shown.iter().map(|&f| clip.weights_at(times[f]).iter().map(|&w| w as f32).collect()).collect(),
            frames: self.frames,
            hermite_distance: self.hermite_distance,
            key_times: key_times.to_vec(),
            diagonal,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn strides_keep_the_budget() {
        // The demo: everything.
        assert_eq!(strides(128, 252, 1000, 9, 121), (1, 1));
        // A big bake: frames, then vertices, decimated.
        let (vs, fs) = strides(20_000, 40_000, 200_000, 20, 1000);
        assert!(vs > 1 && fs > 1);
        let kept = 20_000usize.div_ceil(vs);
        assert!((12 * 20_000 + 16 * 200_000) / vs + (7 * kept + 80 + 48) * 1000usize.div_ceil(fs) <= PLAYER_BYTES);
        // Room for a second at 60 fps; the whole-number stride shows a little fewer.
        assert!(1000usize.div_ceil(fs) >= 50, "{vs} {fs}");
        // Many frames of a small surface: every vertex, every n-th frame.
        let (vs, fs) = strides(128, 252, 1000, 9, 2401);
        assert_eq!(vs, 1);
        assert!(fs > 1 && 2401usize.div_ceil(fs) * (7 * 128 + 36 + 48) <= PLAYER_BYTES);
    }
}
