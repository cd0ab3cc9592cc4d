//! The `report` stage: file sizes side by side, fidelity of the blendshape animation against
//! the full-frame evaluation, deviation from the input keyframes, volume, and the solver's
//! history. Written as `report.json` (specified in `formats/report.md`) and `report.md`.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::mesh::{bbox_diagonal, norm, sub, surface, Point};
use crate::scene::Format;
use crate::spacetime::trajectory::Trajectory;
use crate::stage::{Animation, OutputFile, OutputKind, Outputs, SolverLog};

/// Distances between two animations, relative to the rest bounding-box diagonal.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Deviation {
    pub max: f64,
    pub rms: f64,
    pub relative_to: String,
    /// How many poses were compared.
    pub samples: usize,
}

/// Enclosed volume over the frames of one animation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct VolumeRange {
    /// Smallest and largest volume, as ratios to the rest volume.
    pub min: f64,
    pub max: f64,
    /// In-between volume loss: the largest `1 - V(t) / V̄(t)` over frames, where `V̄` blends
    /// this animation's own keyframe volumes linearly in time. It measures what the
    /// interpolation loses between keys, whatever volume the keys themselves have; zero when
    /// no in-between dips below its keys.
    pub in_between_loss: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Volume {
    /// Volume enclosed by the surface in the rest pose.
    pub rest: f64,
    /// The exported animation.
    pub animation: VolumeRange,
    /// The hermite baseline (input keyframes, zero velocities), for comparison.
    pub hermite: VolumeRange,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Report {
    pub scene: String,
    pub vertices: usize,
    pub faces: usize,
    pub tet_nodes: usize,
    pub tets: usize,
    pub keyframes: usize,
    pub duration_s: f64,
    pub fps: f64,
    pub frames: usize,
    pub solver: SolverLog,
    pub outputs: Vec<OutputFile>,
    /// Per format: full-frame bytes / blendshape bytes.
    pub ratios: BTreeMap<Format, f64>,
    /// The blendshape animation (as stored: f32 shapes, f32 weights at every frame) against the
    /// full-frame evaluation of the trajectory at every frame.
    pub error: Deviation,
    /// The exported animation at key times against the input keyframes (free vertices move).
    pub keyframe_deviation: Deviation,
    /// Present when the surface is closed.
    pub volume: Option<Volume>,
}

fn deviation(pairs: impl Iterator<Item = (Vec<Point>, Vec<Point>)>, diagonal: f64) -> Deviation {
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

fn volume_range(tr: &Trajectory, frames: &[(i64, f64)], triangles: &[[u32; 3]], rest: f64) -> VolumeRange {
    let volumes: Vec<(f64, f64)> = frames.iter().map(|&(_, t)| (t, surface::enclosed_volume(&tr.evaluate(t), triangles))).collect();
    let key_volumes: Vec<f64> = tr.positions.iter().map(|k| surface::enclosed_volume(k, triangles)).collect();
    let blend = |t: f64| {
        let (i, theta) = tr.locate(t);
        (1.0 - theta) * key_volumes[i] + theta * key_volumes[i + 1]
    };
    VolumeRange {
        min: volumes.iter().map(|v| v.1 / rest).fold(f64::INFINITY, f64::min),
        max: volumes.iter().map(|v| v.1 / rest).fold(f64::NEG_INFINITY, f64::max),
        in_between_loss: volumes.iter().map(|&(t, v)| 1.0 - v / blend(t)).fold(0.0, f64::max),
    }
}

/// The report of an animation and the files exported from it.
pub fn report(animation: &Animation, outputs: &Outputs) -> Report {
    let scene = &animation.scene;
    let tr = &animation.trajectory;
    let frames = tr.frames(scene.fps);
    let diagonal = bbox_diagonal(&animation.mesh.positions);
    let clip = crate::export::blendshape_clip(tr, scene.export.weights);
    // As USD stores it: f32 weights sampled at frames.
    let stored = |t: f64| clip.points_with_weights(&clip.weights_at(t).iter().map(|&w| w as f32 as f64).collect::<Vec<_>>());
    let error = deviation(frames.iter().map(|&(_, t)| (stored(t), tr.evaluate(t))), diagonal);
    let keyframe_deviation =
        deviation(tr.positions.iter().cloned().zip(animation.input_keys.iter().cloned()), diagonal);
    let triangles = &animation.mesh.triangles;
    let closed = !triangles.is_empty() && surface::open_edges(&animation.mesh).is_empty();
    let rest_volume = surface::enclosed_volume(&animation.mesh.positions, triangles);
    let volume = (closed && rest_volume > 0.0).then(|| {
        let hermite = Trajectory::with_zero_velocities(tr.times.clone(), animation.input_keys.clone());
        Volume {
            rest: rest_volume,
            animation: volume_range(tr, &frames, triangles, rest_volume),
            hermite: volume_range(&hermite, &frames, triangles, rest_volume),
        }
    });
    let mut ratios = BTreeMap::new();
    for format in [Format::Usda, Format::Usdc, Format::Glb] {
        let size = |kind| outputs.files.iter().find(|f| f.format == format && f.kind == kind).map(|f| f.bytes);
        if let (Some(full), Some(blend)) = (size(OutputKind::FullFrame), size(OutputKind::Blendshape)) {
            ratios.insert(format, full as f64 / blend as f64);
        }
    }
    Report {
        scene: scene.name.clone(),
        vertices: animation.counts.vertices,
        faces: animation.counts.faces,
        tet_nodes: animation.counts.tet_nodes,
        tets: animation.counts.tets,
        keyframes: animation.counts.keyframes,
        duration_s: tr.duration(),
        fps: scene.fps,
        frames: frames.len(),
        solver: animation.log.clone(),
        outputs: outputs.files.clone(),
        ratios,
        error,
        keyframe_deviation,
        volume,
    }
}

impl Report {
    pub fn to_json(&self) -> Vec<u8> {
        let mut bytes = serde_json::to_vec_pretty(self).expect("the report serializes");
        bytes.push(b'\n');
        bytes
    }

    /// A table a person reads in a terminal or a merge request.
    pub fn to_markdown(&self) -> String {
        let mut s = String::new();
        let push = |s: &mut String, line: String| {
            s.push_str(&line);
            s.push('\n');
        };
        push(&mut s, format!("# blendsim report: {}\n", self.scene));
        push(&mut s, "| | |".into());
        push(&mut s, "|---|---|".into());
        push(&mut s, format!("| surface | {} vertices, {} triangles |", self.vertices, self.faces));
        push(&mut s, format!("| body | {} tet nodes, {} tets |", self.tet_nodes, self.tets));
        push(&mut s, format!("| animation | {} keyframes, {:.3} s at {} fps ({} frames) |", self.keyframes, self.duration_s, self.fps, self.frames));
        let sv = &self.solver;
        let (w0, w1) = (sv.energy.first().copied().unwrap_or(0.0), sv.energy.last().copied().unwrap_or(0.0));
        let change = if w0 > 0.0 { format!(" ({:+.1}%)", 100.0 * (w1 - w0) / w0) } else { String::new() };
        push(
            &mut s,
            format!(
                "| solver | {}, {} iterations, W {:.4e} -> {:.4e}{change}, {} |",
                sv.method,
                sv.iterations,
                w0,
                w1,
                if sv.converged { "converged" } else { "not converged" }
            ),
        );
        push(
            &mut s,
            format!(
                "| time | {:.3} s (precompute {:.3} s, {:.4} s per iteration, {} unknowns per coordinate) |",
                sv.seconds, sv.precompute_seconds, sv.iteration_seconds, sv.unknowns
            ),
        );
        push(&mut s, format!("| fidelity | max {:.2e}, rms {:.2e} of the bbox diagonal over {} frames (blendshape vs full-frame) |", self.error.max, self.error.rms, self.error.samples));
        push(
            &mut s,
            format!(
                "| keyframes | moved up to {:.2e} (rms {:.2e}) of the bbox diagonal from the input |",
                self.keyframe_deviation.max, self.keyframe_deviation.rms
            ),
        );
        if let Some(v) = &self.volume {
            push(
                &mut s,
                format!(
                    "| volume | {:.1}% to {:.1}% of rest, in-between loss {:.1}% (hermite baseline: {:.1}% to {:.1}%, loss {:.1}%) |",
                    100.0 * v.animation.min,
                    100.0 * v.animation.max,
                    100.0 * v.animation.in_between_loss,
                    100.0 * v.hermite.min,
                    100.0 * v.hermite.max,
                    100.0 * v.hermite.in_between_loss
                ),
            );
        }
        push(&mut s, String::new());
        push(&mut s, "| format | full-frame | blendshape | smaller by |".into());
        push(&mut s, "|---|---:|---:|---:|".into());
        for (format, ratio) in &self.ratios {
            let size = |kind| self.outputs.iter().find(|f| f.format == *format && f.kind == kind).map_or(0, |f| f.bytes);
            push(
                &mut s,
                format!("| {format} | {} | {} | {ratio:.1}x |", human_bytes(size(OutputKind::FullFrame)), human_bytes(size(OutputKind::Blendshape))),
            );
        }
        push(&mut s, String::new());
        push(&mut s, "| file | kind | bytes |".into());
        push(&mut s, "|---|---|---:|".into());
        for f in &self.outputs {
            let kind = match f.kind {
                OutputKind::Blendshape => "blendshape",
                OutputKind::FullFrame => "full-frame",
            };
            push(&mut s, format!("| {} | {kind} | {} |", f.path, f.bytes));
        }
        s
    }
}

/// `1.2 MB`, `45.3 KB`, `812 B` (decimal units, as file managers show).
pub fn human_bytes(bytes: u64) -> String {
    let b = bytes as f64;
    if b >= 1e6 {
        format!("{:.1} MB", b / 1e6)
    } else if b >= 1e3 {
        format!("{:.1} KB", b / 1e3)
    } else {
        format!("{bytes} B")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn human_sizes() {
        assert_eq!(human_bytes(812), "812 B");
        assert_eq!(human_bytes(45_300), "45.3 KB");
        assert_eq!(human_bytes(8_600_000), "8.6 MB");
    }
}
