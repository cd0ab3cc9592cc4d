//! The report's measures: distances between animations, enclosed volume over frames, and
//! file size ratios.

use std::collections::BTreeMap;

use super::{Deviation, VolumeRange};
use crate::algorithms::blendshape::clip::BlendShapeClip;
use crate::algorithms::geometry::{norm, sub, surface, Point};
use crate::algorithms::spacetime::trajectory::Trajectory;
use crate::pipeline::scene::Format;
use crate::pipeline::stage_file::{OutputFile, OutputKind};

/// Distances between the poses of `pairs`, relative to `diagonal` (the rest bounding-box
/// diagonal; 1 when it is zero).
pub fn deviation(pairs: impl Iterator<Item = (Vec<Point>, Vec<Point>)>, diagonal: f64) -> Deviation {
    let (mut max, mut sum2, mut count, mut samples) = (0.0f64, 0.0f64, 0usize, 0usize);
    for (a, b) in pairs {
        for (p, q) in a.iter().zip(&b) {
            let d = norm(sub(*p, *q));
            max = max.max(d);
            sum2 += d * d;
            count += 1;
        }
        samples += 1;
    }
    let scale = if diagonal > 0.0 { diagonal } else { 1.0 };
    Deviation {
        max: max / scale,
        rms: if count > 0 { (sum2 / count as f64).sqrt() / scale } else { 0.0 },
        relative_to: "bbox_diagonal".into(),
        samples,
    }
}

/// The blendshape `clip` of `tr` as the files store it (f32 shapes, f32 weights sampled at
/// `frames`) against the trajectory itself at those frames, and per frame the largest and the
/// rms distance (relative to `diagonal`, as the deviation).
pub(crate) fn blendshape_error(clip: &BlendShapeClip, tr: &Trajectory, frames: &[(i64, f64)], diagonal: f64) -> (Deviation, Vec<f64>, Vec<f64>) {
    // As USD stores it: f32 weights sampled at frames.
    let stored = |t: f64| clip.points_with_weights(&clip.weights_at(t).iter().map(|&w| w as f32 as f64).collect::<Vec<_>>());
    let scale = if diagonal > 0.0 { diagonal } else { 1.0 };
    let (mut per_frame, mut per_frame_rms) = (Vec::with_capacity(frames.len()), Vec::with_capacity(frames.len()));
    // One frame's two poses at a time (all of them held at once were 48 bytes per frame and
    // vertex: most of a long bake's peak memory).
    let poses = frames.iter().map(|&(_, t)| {
        let (a, b) = (stored(t), tr.evaluate(t));
        let d: Vec<f64> = a.iter().zip(&b).map(|(p, q)| norm(sub(*p, *q))).collect();
        per_frame.push(d.iter().copied().fold(0.0, f64::max) / scale);
        per_frame_rms.push(if d.is_empty() { 0.0 } else { (d.iter().map(|x| x * x).sum::<f64>() / d.len() as f64).sqrt() / scale });
        (a, b)
    });
    let deviation = deviation(poses, diagonal);
    (deviation, per_frame, per_frame_rms)
}

/// Enclosed volume of the surface `triangles` moving on `tr` at each of `frames`.
pub fn volume_series(tr: &Trajectory, frames: &[(i64, f64)], triangles: &[[u32; 3]]) -> Vec<f64> {
    frames.iter().map(|&(_, t)| surface::enclosed_volume(&tr.evaluate(t), triangles)).collect()
}

/// Enclosed volume of the surface `triangles` moving on `tr`, over `frames`, relative to
/// `rest` (see [`VolumeRange`]); `series` is [`volume_series`] of the same (in volume units).
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
