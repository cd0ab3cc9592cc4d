//! The report's measures: distances between animations, enclosed volume over frames, and
//! file size ratios.

use std::collections::BTreeMap;

use super::{Deviation, VolumeRange};
use crate::algorithms::blendshape::clip::BlendShapeClip;
use crate::algorithms::geometry::{norm, sub, surface, Point};
use crate::algorithms::spacetime::trajectory::Trajectory;
use crate::pipeline::scene::Format;
use crate::pipeline::stage_file::{OutputFile, OutputKind};

/// Point distances summed up pose by pose: the largest, the sum of squares and the counts.
#[derive(Debug, Default)]
struct Distances {
    max: f64,
    sum2: f64,
    count: usize,
    samples: usize,
}

impl Distances {
    /// One pose's point distances.
    fn add(&mut self, distances: &[f64]) {
        for &d in distances {
            self.max = self.max.max(d);
            self.sum2 += d * d;
            self.count += 1;
        }
        self.samples += 1;
    }

    /// The deviation relative to `diagonal` (1 when it is zero).
    fn deviation(&self, diagonal: f64) -> Deviation {
        let scale = if diagonal > 0.0 { diagonal } else { 1.0 };
        Deviation {
            max: self.max / scale,
            rms: if self.count > 0 { (self.sum2 / self.count as f64).sqrt() / scale } else { 0.0 },
            relative_to: "bbox_diagonal".into(),
            samples: self.samples,
        }
    }
}

/// The point distances between two poses.
fn distances(a: &[Point], b: &[Point]) -> Vec<f64> {
    a.iter().zip(b).map(|(p, q)| norm(sub(*p, *q))).collect()
}

/// Distances between the poses of `pairs`, relative to `diagonal` (the rest bounding-box
/// diagonal; 1 when it is zero).
pub fn deviation(pairs: impl Iterator<Item = (Vec<Point>, Vec<Point>)>, diagonal: f64) -> Deviation {
    let mut sum = Distances::default();
    for (a, b) in pairs {
        sum.add(&distances(&a, &b));
    }
    sum.deviation(diagonal)
}

/// The blendshape `clip` of a trajectory as the files store it (f32 shapes, f32 weights sampled
/// at the frames) against the trajectory itself, one frame at a time ([`StorageError::add`]):
/// over all frames and per frame the largest and the rms distance (relative to `diagonal`, as
/// the deviation). One frame's poses at a time: all of them held at once were 48 bytes per
/// frame and vertex, most of a long bake's peak memory.
pub(crate) struct StorageError<'a> {
    clip: &'a BlendShapeClip,
    diagonal: f64,
    sum: Distances,
    per_frame: Vec<f64>,
    per_frame_rms: Vec<f64>,
}

impl<'a> StorageError<'a> {
    /// The error of `clip` over `frames` frames, relative to `diagonal`.
    pub(crate) fn new(clip: &'a BlendShapeClip, frames: usize, diagonal: f64) -> StorageError<'a> {
        StorageError { clip, diagonal, sum: Distances::default(), per_frame: Vec::with_capacity(frames), per_frame_rms: Vec::with_capacity(frames) }
    }

    /// The frame at `t`, where the trajectory's pose is `pose`.
    pub(crate) fn add(&mut self, t: f64, pose: &[Point]) {
        // As USD stores it: f32 weights sampled at frames.
        let weights: Vec<f64> = self.clip.weights_at(t).iter().map(|&w| w as f32 as f64).collect();
        let d = distances(&self.clip.points_with_weights(&weights), pose);
        let scale = if self.diagonal > 0.0 { self.diagonal } else { 1.0 };
        self.per_frame.push(d.iter().copied().fold(0.0, f64::max) / scale);
        self.per_frame_rms.push(if d.is_empty() { 0.0 } else { (d.iter().map(|x| x * x).sum::<f64>() / d.len() as f64).sqrt() / scale });
        self.sum.add(&d);
    }

    /// The deviation over every frame added, and per frame the largest and the rms distance.
    pub(crate) fn finish(self) -> (Deviation, Vec<f64>, Vec<f64>) {
        (self.sum.deviation(self.diagonal), self.per_frame, self.per_frame_rms)
    }
}

/// Enclosed volume of the surface `triangles` moving on `tr`, over `frames`, relative to
/// `rest` (see [`VolumeRange`]); `series` is its enclosed volume at each of `frames` (in volume
/// units).
pub(crate) fn volume_range(tr: &Trajectory, frames: &[(i64, f64)], triangles: &[[u32; 3]], rest: f64, series: &[f64]) -> VolumeRange {
    let key_volumes: Vec<f64> = tr.positions.iter().map(|k| surface::enclosed_volume(k, triangles)).collect();
    let blend = |t: f64| {
        let (i, theta) = tr.locate(t);
        (1.0 - theta) * key_volumes[i] + theta * key_volumes[i + 1]
    };
    VolumeRange {
        min: series.iter().map(|v| v / rest).fold(f64::INFINITY, f64::min),
        max: series.iter().map(|v| v / rest).fold(f64::NEG_INFINITY, f64::max),
        in_between_loss: frames.iter().zip(series).map(|(&(_, t), v)| 1.0 - v / blend(t)).fold(0.0, f64::max),
    }
}

/// Per format: `bytes` / the blendshape file's bytes (none when `bytes` is 0: not recorded).
pub(crate) fn ratios_to(bytes: u64, outputs: &[OutputFile]) -> BTreeMap<Format, f64> {
    outputs
        .iter()
        .filter(|f| f.kind == OutputKind::Blendshape && f.bytes > 0 && bytes > 0)
        .map(|f| (f.format, bytes as f64 / f.bytes as f64))
        .collect()
}

/// Per format: full-frame bytes / blendshape bytes, for the formats written both ways.
pub(crate) fn size_ratios(outputs: &[OutputFile]) -> BTreeMap<Format, f64> {
    let mut ratios = BTreeMap::new();
    for format in [Format::Usda, Format::Usdc, Format::Glb] {
        let size = |kind| outputs.iter().find(|f| f.format == format && f.kind == kind).map(|f| f.bytes);
        // No ratio of an empty file (a damaged outputs list): it would read NaN or inf.
        if let (Some(full @ 1..), Some(blend @ 1..)) = (size(OutputKind::FullFrame), size(OutputKind::Blendshape)) {
            ratios.insert(format, full as f64 / blend as f64);
        }
    }
    ratios
}
