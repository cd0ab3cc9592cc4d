//! Check a folder of baked or exported files with the independent checkers against our own
//! evaluation of the animation they were made from.

use std::collections::BTreeSet;
use std::path::Path;

use blendsim::algorithms::blendshape::clip::BlendShapeClip;
use blendsim::algorithms::geometry::{bbox_diagonal, norm, sub, Point};
use blendsim::pipeline::scene::{Axis, Format, GltfInterpolation, Method, SceneFile};
use blendsim::pipeline::stage_file::{Animation, OutputFile, OutputKind};
use blendsim::pipeline::stages::Bake;
use blendsim::support::progress::Progress;
use serde_json::Value;

use super::checkers::{check_glb, check_same_layer, check_usd, Expected};

/// The animation of a scene computed in this process by the library, as `bake` does (our
/// reference evaluation; no file in between).
pub fn library_animation(scene: &Path) -> Animation {
    library_animation_with(scene, None)
}

/// [`library_animation`] with the scene's solver method overridden (as `--method` does).
pub fn library_animation_with(scene: &Path, method: Option<Method>) -> Animation {
    let hidden = Progress::hidden();
    let scene = SceneFile::load(scene).unwrap_or_else(|e| panic!("{e}"));
    Bake::new(&scene, &hidden).method(method).animation().unwrap_or_else(|e| panic!("{e}"))
}

pub fn max_distance(a: &[Point], b: &[Point]) -> f64 {
    a.iter().zip(b).map(|(p, q)| norm(sub(*p, *q))).fold(0.0, f64::max)
}

/// Times at which to compare a glTF animation: every key, each interval's third and middle,
/// and every 5th frame.
pub fn glb_times(anim: &Animation) -> Vec<f64> {
    let tr = &anim.trajectory;
    let mut times: Vec<f64> = tr.times.clone();
    for w in tr.times.windows(2) {
        times.extend([w[0] + (w[1] - w[0]) / 3.0, (w[0] + w[1]) / 2.0]);
    }
    times.extend(tr.frames(anim.scene.fps).iter().step_by(5).map(|f| f.1));
    let set: BTreeSet<u64> = times.iter().map(|t| t.to_bits()).collect();
    set.into_iter().map(f64::from_bits).collect()
}

/// Every frame time and the midpoint between each two frames, in order.
pub fn frames_and_midpoints(frames: &[f64]) -> Vec<f64> {
    let mut times = Vec::with_capacity(2 * frames.len());
    for (i, &t) in frames.iter().enumerate() {
        if i > 0 {
            times.push((frames[i - 1] + t) / 2.0);
        }
        times.push(t);
    }
    times
}

/// The points a consumer of per-frame weight samples plays at `t` (USD time samples, a LINEAR
/// glTF sampler): the exact weights at the two frames around `t`, blended linearly. At frames
/// this is the clip itself; in between, the best a linear interpolant of the frames can do.
pub fn sampled_points(clip: &BlendShapeClip, frames: &[f64], t: f64) -> Vec<Point> {
    if frames.len() < 2 {
        return clip.points_at(frames[0]);
    }
    let i = frames.partition_point(|&f| f <= t).clamp(1, frames.len() - 1) - 1;
    let s = ((t - frames[i]) / (frames[i + 1] - frames[i])).clamp(0.0, 1.0);
    let (a, b) = (clip.weights_at(frames[i]), clip.weights_at(frames[i + 1]));
    clip.points_with_weights(&a.iter().zip(&b).map(|(x, y)| (1.0 - s) * x + s * y).collect::<Vec<_>>())
}

/// The `outputs` list of a report.json (or of NAME.outputs.json's `data`).
pub fn output_files(list: &Value) -> Vec<OutputFile> {
    serde_json::from_value(list.clone()).unwrap_or_else(|e| panic!("not a list of output files ({e}): {list}"))
}

/// Check every file of `outputs` in `dir` with the reference tools: blendshape files against
/// the blendshape clip in the scene's `[export] weights` form (UsdSkel at every frame and
/// between frames, where USD blends the frames' weights linearly; three.js at keys,
/// in-betweens and every 5th frame for CUBICSPLINE, at and between frames for LINEAR),
/// full-frame files against the trajectory at every frame. A `.usda` is also
/// converted to `.usdc` by usd-core and re-checked when the scene asks for no `.usdc` of its
/// own. Returns each file's checker summary.
pub fn check_outputs(dir: &Path, anim: &Animation, outputs: &[OutputFile]) -> Vec<(String, Value)> {
    check_outputs_ranked(dir, anim, outputs, None)
}

/// Our usdc holds the layer of our usda of the same animation: the one written beside it, or
/// one exported now (into a scratch folder) when the scene asked for usdc alone.
pub fn same_layer_as_usda(usdc: &Path, anim: &Animation) -> Value {
    let beside = usdc.with_extension("usda");
    let summary = if beside.is_file() {
        check_same_layer(&beside, usdc)
    } else {
        let folder = tempfile::Builder::new().prefix("blendsim-same-layer-").tempdir().unwrap();
        let scratch = folder.path().join("usda");
        let mut usda_only = anim.clone();
        usda_only.scene.export.formats = vec![Format::Usda];
        let mut staging = blendsim::support::output::Staging::new(&scratch).unwrap();
        blendsim::pipeline::stages::export::export(&usda_only, &blendsim::support::budget::Budget::default(), &mut staging).unwrap();
        staging.commit().unwrap();
        check_same_layer(&scratch.join(beside.file_name().unwrap()), usdc)
    };
    eprintln!("{}: same layer as its usda: {summary}", usdc.display());
    assert_eq!(summary["ok"], true, "{}: {summary}", usdc.display());
    summary
}

/// [`check_outputs`] for files of `[export] basis = "principal"` at `rank` (the report's):
/// the blendshape files must play that clip, the full-frame files the unreduced trajectory.
pub fn check_outputs_ranked(dir: &Path, anim: &Animation, outputs: &[OutputFile], rank: Option<usize>) -> Vec<(String, Value)> {
    assert!(!outputs.is_empty(), "no output files to check");
    let tr = &anim.trajectory;
    let fps = anim.scene.fps;
    let export = &anim.scene.export;
    let clip = match rank {
        Some(_) => blendsim::pipeline::stages::export::blendshape_clip(anim, rank, &blendsim::support::budget::Budget::default()).unwrap().0,
        None => BlendShapeClip::new(tr, export.weights),
    };
    // The trajectory the clip plays: the animation's, or its principal projection.
    let played = if rank.is_some() { clip.played(&tr.times) } else { tr.clone() };
    let frames: Vec<f64> = tr.frames(fps).iter().map(|f| f.1).collect();
    // Our two evaluations agree before either is compared with a file.
    let diagonal = bbox_diagonal(&tr.positions.concat());
    for &t in &glb_times(anim) {
        let d = max_distance(&clip.points_at(t), &played.evaluate(t));
        assert!(d <= 1e-6 * diagonal, "blendshape clip and trajectory differ by {d:e} at t = {t}");
    }
    let decorate_with = |mut e: Expected, kind: &str, quantized: f64| {
        e.kind = Some(kind.into());
        e.tolerance += quantized;
        e.fps = Some(fps);
        e.up_axis = Some(if export.up_axis == Axis::Z { "z" } else { "y" }.into());
        e.meters_per_unit = Some(export.meters_per_unit);
        e
    };
    let round_trip = !export.formats.contains(&Format::Usdc);
    let mut summaries = Vec::new();
    for f in outputs {
        let path = dir.join(&f.path);
        let bytes = std::fs::metadata(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display())).len();
        assert_eq!(bytes, f.bytes, "{}: size on disk vs listed", f.path);
        // A glb plays within its stated quantization error (read back from it by blendsim; a
        // LINEAR or full-frame file's error between frames is a blend of its errors at frames,
        // a CUBICSPLINE one's is bounded by the same rule with some margin).
        let cubic = f.kind == OutputKind::Blendshape && export.gltf_interpolation == GltfInterpolation::Cubicspline;
        let quantized = f.quantization_error.unwrap_or(0.0) * if cubic { 1.5 } else { 1.001 };
        let decorate = |e: Expected, kind: &str| decorate_with(e, kind, quantized);
        let summary = match (f.kind, f.format) {
            (OutputKind::Blendshape, Format::Glb) if export.gltf_interpolation == GltfInterpolation::Linear => {
                check_glb(&path, &decorate(Expected::at(&frames_and_midpoints(&frames), fps, |t| sampled_points(&clip, &frames, t)), "blendshape"))
            }
            (OutputKind::Blendshape, Format::Glb) => {
                check_glb(&path, &decorate(Expected::at(&glb_times(anim), fps, |t| clip.points_at(t)), "blendshape"))
            }
            (OutputKind::FullFrame, Format::Glb) => check_glb(&path, &decorate(Expected::at(&frames, fps, |t| tr.evaluate(t)), "full-frame")),
            (OutputKind::Blendshape, format) => check_usd(
                &path,
                &decorate(Expected::at(&frames_and_midpoints(&frames), fps, |t| sampled_points(&clip, &frames, t)), "blendshape"),
                format == Format::Usda && round_trip,
            ),
            (OutputKind::FullFrame, format) => {
                check_usd(&path, &decorate(Expected::at(&frames, fps, |t| tr.evaluate(t)), "full-frame"), format == Format::Usda && round_trip)
            }
        };
        eprintln!("{}: {} bytes: {summary}", f.path, f.bytes);
        assert_eq!(summary["ok"], true, "{}: {summary}", f.path);
        if f.format == Format::Usdc {
            same_layer_as_usda(&path, anim);
        }
        summaries.push((f.path.clone(), summary));
    }
    summaries
}
