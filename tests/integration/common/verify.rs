//! Check a folder of baked or exported files with the independent checkers against our own
//! evaluation of the animation they were made from.

use std::collections::BTreeSet;
use std::path::Path;

use blendsim::clip::BlendShapeClip;
use blendsim::mesh::{bbox_diagonal, norm, sub, Point};
use blendsim::progress::Progress;
use blendsim::scene::{Axis, Format, Method, SceneFile};
use blendsim::stage::{Animation, OutputFile, OutputKind};
use blendsim::stages::Bake;
use serde_json::Value;

use super::checkers::{check_glb, check_usd, Expected};

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

/// The `outputs` list of a report.json (or of NAME.outputs.json's `data`).
pub fn output_files(list: &Value) -> Vec<OutputFile> {
    serde_json::from_value(list.clone()).unwrap_or_else(|e| panic!("not a list of output files ({e}): {list}"))
}

/// Check every file of `outputs` in `dir` with the reference tools: blendshape files against
/// the blendshape clip (UsdSkel at every frame, three.js at keys, in-betweens and every 5th
/// frame), full-frame files against the trajectory at every frame. A `.usda` is also
/// converted to `.usdc` by usd-core and re-checked when the scene asks for no `.usdc` of its
/// own. Returns each file's checker summary.
pub fn check_outputs(dir: &Path, anim: &Animation, outputs: &[OutputFile]) -> Vec<(String, Value)> {
    assert!(!outputs.is_empty(), "no output files to check");
    let tr = &anim.trajectory;
    let fps = anim.scene.fps;
    let export = &anim.scene.export;
    let clip = BlendShapeClip::from_trajectory(tr);
    let frames: Vec<f64> = tr.frames(fps).iter().map(|f| f.1).collect();
    // Our two evaluations agree before either is compared with a file.
    let diagonal = bbox_diagonal(&tr.positions.concat());
    for &t in &glb_times(anim) {
        let d = max_distance(&clip.points_at(t), &tr.evaluate(t));
        assert!(d <= 1e-6 * diagonal, "blendshape clip and trajectory differ by {d:e} at t = {t}");
    }
    let decorate = |mut e: Expected, kind: &str| {
        e.kind = Some(kind.into());
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
        let summary = match (f.kind, f.format) {
            (OutputKind::Blendshape, Format::Glb) => {
                check_glb(&path, &decorate(Expected::at(&glb_times(anim), fps, |t| clip.points_at(t)), "blendshape"))
            }
            (OutputKind::FullFrame, Format::Glb) => {
                check_glb(&path, &decorate(Expected::at(&frames, fps, |t| tr.evaluate(t)), "full-frame"))
            }
            (OutputKind::Blendshape, format) => check_usd(
                &path,
                &decorate(Expected::at(&frames, fps, |t| clip.points_at(t)), "blendshape"),
                format == Format::Usda && round_trip,
            ),
            (OutputKind::FullFrame, format) => check_usd(
                &path,
                &decorate(Expected::at(&frames, fps, |t| tr.evaluate(t)), "full-frame"),
                format == Format::Usda && round_trip,
            ),
        };
        eprintln!("{}: {} bytes: {summary}", f.path, f.bytes);
        assert_eq!(summary["ok"], true, "{}: {summary}", f.path);
        summaries.push((f.path.clone(), summary));
    }
    summaries
}
