//! Cache bakes through the CLI, as files other tools play: the principal-component clip (the
//! default for a `fit` of a cache) opened by usd-core, the Khronos validator, three.js and
//! Blender; a skinned glTF clip baked through `blendsim bake` and played by three.js; the
//! `[cache] window_bytes` key.

use std::path::Path;
use std::process::Command;

use blendsim::algorithms::geometry::{bbox_diagonal, norm, sub, Point};
use blendsim::formats::cache::gltf_fixtures::skinned_clip;
use blendsim::formats::cache::{CacheOptions, VertexCache};
use blendsim::pipeline::stage_file::{OutputFile, OutputKind};
use serde_json::{json, Value};

use crate::cache_bake::{scene, write_cache};
use crate::common::bar::{bar, BarSettings};
use crate::common::checkers::{check_babylon, check_blender, Expected};
use crate::common::cli::{read_json, run, TempDir};
use crate::common::verify::{check_outputs_ranked, library_animation, output_files};

/// The bar's PC2 baked with `fit` and the default (principal) basis, in every format, and
/// again with LINEAR glTF weights: the blendshape files play the clip the report measured
/// (UsdSkel at and between frames, the validator and three.js at keys, in-betweens and frames),
/// every weight stays in [0, 1], and Blender 4.2 at default settings plays the usda, usdc and
/// LINEAR glb within 1e-5 of it at every frame, which is within the tolerance of the cache.
#[test]
fn a_principal_clip_plays_in_usd_gltf_three_and_blender() {
    let cache = bar(&BarSettings::default());
    let dir = TempDir::new("cache-principal-tools");
    write_cache(&dir.path, &cache, "bar.pc2");
    let base = scene("bar.pc2", "fps = 60\nrest = \"rest.obj\"\n", "fit", "keyframes = \"auto\"\ntolerance = 0.005")
        .replace("[\"usda\", \"glb\"]", "[\"usda\", \"usdc\", \"glb\"]");
    std::fs::write(dir.join("scene.toml"), &base).unwrap();
    // f32, so that Blender's playback is checked to 1e-5 (the quantized default within its
    // stated error is blender.rs's).
    std::fs::write(dir.join("linear.toml"), base.clone() + "gltf_interpolation = \"linear\"\ngltf_compression = \"none\"\n").unwrap();
    let mut played_frames = None;
    for name in ["scene", "linear"] {
        run(&dir.path, &["bake", &format!("{name}.toml"), "--out", name, "--quiet"]).success();
        let report = read_json(&dir.join(format!("{name}/report.json")));
        assert_eq!(report["basis"], "principal", "the default for a fit of a cache");
        let rank = report["rank"].as_u64().expect("a rank") as usize;
        let error = &report["cache"]["error"];
        assert!(error["per_frame"].as_array().unwrap().iter().all(|e| e.as_f64().unwrap() <= 0.005), "{error}");
        let anim = library_animation(&dir.join(format!("{name}.toml")));
        let (clip, chosen) = blendsim::pipeline::stages::export::blendshape_clip(&anim, None, &blendsim::support::budget::Budget::default()).unwrap();
        assert_eq!(chosen, Some(rank), "the library chooses the rank the CLI wrote");
        assert_eq!(clip.targets.len(), rank);
        // Every weight in [0, 1]: the stored key values, and the curves at every frame and
        // between frames (the range is exact per interval, not sampled).
        let frames: Vec<f64> = anim.trajectory.frames(anim.scene.fps).iter().map(|f| f.1).collect();
        assert!(clip.curves.iter().flat_map(|c| &c.values).all(|w| (0.0..=1.0).contains(w)));
        for i in 0..4 * frames.len() {
            let t = frames[0] + (frames[frames.len() - 1] - frames[0]) * i as f64 / (4 * frames.len() - 1) as f64;
            assert!(clip.weights_at(t).iter().all(|w| (0.0..=1.0).contains(w)), "t = {t}: {:?}", clip.weights_at(t));
        }
        let outputs: Vec<OutputFile> = output_files(&report["outputs"]).into_iter().filter(|f| f.kind == OutputKind::Blendshape).collect();
        let summaries = check_outputs_ranked(&dir.join(name), &anim, &outputs, Some(rank));
        assert_eq!(summaries.len(), 3);
        let size = |f: &str| report["outputs"].as_array().unwrap().iter().find(|o| o["path"] == f).unwrap()["bytes"].as_f64().unwrap();
        println!(
            "{name}: rank {rank} ({} keys), cache error max {:.3e}; usda {:.1} KB ({:.1}x), usdc {:.1} KB ({:.1}x), glb {:.1} KB ({:.1}x smaller than full frame)",
            anim.trajectory.key_count(),
            error["max"].as_f64().unwrap(),
            size("bar.usda") / 1024.0,
            size("bar.full.usda") / size("bar.usda"),
            size("bar.usdc") / 1024.0,
            size("bar.full.usdc") / size("bar.usdc"),
            size("bar.glb") / 1024.0,
            size("bar.full.glb") / size("bar.glb"),
        );
        played_frames = Some((frames, clip, anim.scene.fps));
    }
    // Blender: its importers at default settings, the mesh through the depsgraph at every frame.
    let (frames, clip, fps) = played_frames.unwrap();
    let mut expected = Expected::at(&frames, fps, |t| clip.points_at(t));
    (expected.fps, expected.up_axis, expected.meters_per_unit) = (Some(fps), Some("y".into()), Some(1.0));
    let files = [dir.join("scene/bar.usda"), dir.join("scene/bar.usdc"), dir.join("linear/bar.glb")];
    let summary = check_blender(&files.iter().map(|f| (f.as_path(), &expected)).collect::<Vec<_>>());
    for f in summary["files"].as_array().unwrap() {
        println!("blender {}: max error {} of the bbox diagonal, {} shape keys", f["file"], f["max_error"], f["shape_keys"]);
        assert_eq!(f["ok"], true, "Blender must play {}: {f}", f["file"]);
        assert!(f["max_error"].as_f64().unwrap() < 1e-5, "{f}");
    }
}

/// A tolerance at which one grid's shorts cannot hold the rapier bar's principal clip.
const TIGHT: f64 = 2e-4;

/// The rapier bar's cache baked through the CLI by `fit` at [`TIGHT`] with automatic keys, no
/// full-frame files and `export` added to `[export]`, and what the tests read of its glb.
struct TightBar {
    dir: TempDir,
    report: Value,
    rank: usize,
    bytes: Vec<u8>,
    json: Value,
    json_len: usize,
    /// The component type of each morph target's POSITION accessor.
    targets: Vec<u64>,
}

fn tight_bar(name: &str, export: &str) -> TightBar {
    let dir = TempDir::new(name);
    write_cache(&dir.path, &bar(&BarSettings::default()), "bar.pc2");
    let text = scene("bar.pc2", "fps = 60\nrest = \"rest.obj\"\n", "fit", &format!("keyframes = \"auto\"\ntolerance = {TIGHT}"));
    std::fs::write(dir.join("scene.toml"), text.replace("full_frame = true", &format!("full_frame = false\n{export}"))).unwrap();
    run(&dir.path, &["bake", "scene.toml", "--out", "out", "--quiet"]).success();
    let report = read_json(&dir.join("out/report.json"));
    let rank = report["rank"].as_u64().expect("a rank") as usize;
    let bytes = std::fs::read(dir.join("out/bar.glb")).unwrap();
    let json_len = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
    let json: Value = serde_json::from_slice(&bytes[20..20 + json_len]).unwrap();
    let primitive = &json["meshes"][0]["primitives"][0];
    let component = |a: &Value| json["accessors"][a.as_u64().unwrap() as usize]["componentType"].as_u64().unwrap();
    assert_eq!(component(&primitive["attributes"]["POSITION"]), 5126, "the base in f32");
    let targets: Vec<u64> = primitive["targets"].as_array().unwrap().iter().map(|t| component(&t["POSITION"])).collect();
    assert_eq!(targets.len(), rank);
    assert!(targets.iter().any(|&c| c == 5120 || c == 5122), "integer targets: {targets:?}");
    TightBar { dir, report, rank, bytes, json, json_len, targets }
}

/// A tolerance tight enough that one grid's shorts cannot hold the bar at the step the budget
/// allows: the default glb keeps `KHR_mesh_quantization` with the base in f32 and each target on
/// a step of its own, in shorts or bytes where the budget allows (its weights scaled by the
/// step's ratio to the node's, so every weight stays in [0, 1]). The Khronos validator and
/// three.js (`check_outputs_ranked`), Blender 4.2 at default settings and Babylon.js play it within the
/// clip plus the quantization error the report states, and that error is within a tenth of the
/// tolerance.
#[test]
fn a_tight_tolerance_stores_targets_on_steps_of_their_own_that_play_everywhere() {
    let tolerance = TIGHT;
    let TightBar { dir, report, rank, bytes, json, json_len, targets } = tight_bar("cache-per-target-steps", "");
    assert_eq!(json["extensionsRequired"], json!(["KHR_mesh_quantization"]));
    // The weights as stored: every one in [0, 1] (Blender clamps to the shape key's range).
    let output = &json["accessors"][json["animations"][0]["samplers"][0]["output"].as_u64().unwrap() as usize];
    let view = &json["bufferViews"][output["bufferView"].as_u64().unwrap() as usize];
    let at = 28 + json_len + view["byteOffset"].as_u64().unwrap_or(0) as usize + output["byteOffset"].as_u64().unwrap_or(0) as usize;
    let weights: Vec<f32> =
        bytes[at..at + 4 * output["count"].as_u64().unwrap() as usize].chunks(4).map(|b| f32::from_le_bytes(b.try_into().unwrap())).collect();
    assert!(weights.iter().all(|w| (0.0..=1.0).contains(w)), "weights outside [0, 1]");
    let outputs: Vec<OutputFile> = output_files(&report["outputs"]).into_iter().filter(|f| f.kind == OutputKind::Blendshape).collect();
    let glb = outputs.iter().find(|f| f.path == "bar.glb").expect("the glb is listed");
    let stated = glb.quantization_error.expect("a quantized glb states its error");
    println!("rank {rank}, targets {targets:?}, glb {} bytes, quantization error {stated:.2e}", glb.bytes);
    assert!(stated <= 0.1 * tolerance * 1.001, "quantization error {stated:e} within a tenth of the tolerance");
    let anim = library_animation(&dir.join("scene.toml"));
    check_outputs_ranked(&dir.join("out"), &anim, &outputs, Some(rank));
    let (clip, _) = blendsim::pipeline::stages::export::blendshape_clip(&anim, None, &blendsim::support::budget::Budget::default()).unwrap();
    let fps = anim.scene.fps;
    let frames: Vec<f64> = anim.trajectory.frames(fps).iter().map(|f| f.1).collect();
    let mut expected = Expected::at(&frames, fps, |t| clip.points_at(t));
    (expected.fps, expected.up_axis, expected.meters_per_unit) = (Some(fps), Some("y".into()), Some(1.0));
    expected.tolerance += stated * 1.001;
    let summary = check_blender(&[(dir.join("out/bar.glb").as_path(), &expected)]);
    for f in summary["files"].as_array().unwrap() {
        println!("blender {}: max error {} of the bbox diagonal, {} shape keys", f["file"], f["max_error"], f["shape_keys"]);
        assert_eq!(f["ok"], true, "Blender must play {}: {f}", f["file"]);
        assert!(f["max_error"].as_f64().unwrap() < expected.tolerance, "{f}");
    }
    let babylon = check_babylon(&dir.join("out/bar.glb"), &expected);
    println!("Babylon.js: {babylon}");
    assert_eq!(babylon["ok"], true, "Babylon.js must play bar.glb: {babylon}");
}

/// The same tolerance with `gltf_compression = "meshopt"`: the per-target steps under
/// `EXT_meshopt_compression` (the JSON still names each accessor's type: an f32 base, integer
/// targets), passed by the Khronos validator and played by three.js with its meshopt decoder
/// within the clip plus the stated quantization error (`check_outputs_ranked`).
#[test]
fn a_tight_tolerance_meshopt_glb_keeps_its_steps_and_plays_in_three_js() {
    let TightBar { dir, report, rank, json, targets, .. } = tight_bar("cache-per-target-steps-meshopt", "gltf_compression = \"meshopt\"");
    assert_eq!(json["extensionsRequired"], json!(["KHR_mesh_quantization", "EXT_meshopt_compression"]));
    let outputs: Vec<OutputFile> = output_files(&report["outputs"]).into_iter().filter(|f| f.kind == OutputKind::Blendshape).collect();
    let glb = outputs.iter().find(|f| f.path == "bar.glb").expect("the glb is listed");
    let stated = glb.quantization_error.expect("a quantized glb states its error");
    assert!(stated <= 0.1 * TIGHT * 1.001, "quantization error {stated:e} within a tenth of the tolerance");
    println!("rank {rank}, targets {targets:?}, meshopt glb {} bytes, quantization error {stated:.2e}", glb.bytes);
    check_outputs_ranked(&dir.join("out"), &library_animation(&dir.join("scene.toml")), &outputs, Some(rank));
}

/// three.js (GLTFLoader + AnimationMixer, after the Khronos validator) plays `file` at `times`
/// within `tolerance` of `points` (of their bbox diagonal). Returns its summary.
fn three_js_plays(file: &Path, times: &[f64], points: &[Vec<Point>], tolerance: f64) -> Value {
    let checkers = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/checkers");
    for package in ["gltf-validator", "three"] {
        assert!(checkers.join("node_modules").join(package).join("package.json").is_file(), "{package} is missing: run `make test-deps`");
    }
    let expected = file.with_extension("expected.json");
    std::fs::write(&expected, json!({ "animation": null, "times": times, "points": points, "tolerance": tolerance }).to_string()).unwrap();
    let output = Command::new("node")
        .arg(checkers.join("gltf_cache_check.mjs"))
        .arg(file)
        .arg(&expected)
        .output()
        .expect("run node: install Node.js 20, then `make test-deps`");
    let (stdout, stderr) = (String::from_utf8_lossy(&output.stdout), String::from_utf8_lossy(&output.stderr));
    assert!(output.status.success(), "three.js on {}:\n{stdout}\n{stderr}", file.display());
    serde_json::from_str(stdout.lines().last().unwrap()).unwrap()
}

fn every_frame(path: &Path, fps: f64) -> (Vec<f64>, Vec<Vec<Point>>) {
    let mut cache = VertexCache::open(path, &CacheOptions { fps: Some(fps), ..CacheOptions::default() }).unwrap();
    let frames = cache.frames.as_mut();
    let times = (0..frames.frame_count()).map(|f| frames.time(f)).collect();
    let points = (0..frames.frame_count())
        .map(|f| {
            let mut p = vec![[0.0; 3]; frames.vertex_count()];
            frames.read_frame(f, &mut p).unwrap();
            p
        })
        .collect();
    (times, points)
}

/// A skinned glTF clip through the CLI: `blendsim import --cache-out` writes our evaluation
/// of it, which three.js matches at every frame (1e-5 of the diagonal); `blendsim bake` of the
/// `[cache]` scene naming it meets the tolerance at every frame in its report, and three.js
/// plays the baked blendshape glb within that tolerance of the skinned clip it plays.
#[test]
fn a_skinned_clip_bakes_through_the_cli_and_matches_three_js() {
    let dir = TempDir::new("cache-skinned-cli");
    // The clip reader's own skinned test clip (STEP, LINEAR and CUBICSPLINE joint TRS and a
    // morph target under a translated armature).
    skinned_clip(&dir.join("skinned.glb"));
    let text = "name = \"ribbon\"\n[cache]\npath = \"skinned.glb\"\nfps = 30\nkeyframes = \"auto\"\ntolerance = 0.005\n[solver]\nmethod = \"fit\"\n[export]\nformats = [\"usda\", \"glb\"]\n";
    std::fs::write(dir.join("scene.toml"), text).unwrap();
    // Our evaluation, through the CLI, written as a morph clip; three.js on the skinned file.
    run(&dir.path, &["import", "scene.toml", "--cache-out", "evaluated.glb"]).success();
    let (times, points) = every_frame(&dir.join("evaluated.glb"), 30.0);
    assert_eq!(times.len(), 31);
    let diagonal = bbox_diagonal(&points.concat());
    let moved = points.iter().flat_map(|f| f.iter().zip(&points[0]).map(|(p, q)| norm(sub(*p, *q)))).fold(0.0, f64::max);
    assert!(moved > 0.2 * diagonal, "the skin really moves: {moved} of {diagonal}");
    let summary = three_js_plays(&dir.join("skinned.glb"), &times, &points, 1e-5);
    assert_eq!(summary["skinned"], true, "{summary}");
    println!("three.js on the skinned clip: {summary}");
    // The bake through the CLI.
    run(&dir.path, &["bake", "scene.toml", "--out", "out", "--quiet"]).success();
    let report = read_json(&dir.join("out/report.json"));
    let c = &report["cache"];
    assert_eq!((c["format"].as_str(), c["frames"].as_u64()), (Some("gltf"), Some(31)), "{c}");
    assert!(c["error"]["per_frame"].as_array().unwrap().iter().all(|e| e.as_f64().unwrap() <= 0.005), "{c}");
    let summary = three_js_plays(&dir.join("out/ribbon.glb"), &times, &points, 0.005 + 1e-6);
    println!("three.js on the baked clip ({} keys, rank {}): {summary}", c["keys"].as_array().unwrap().len(), report["rank"]);
    // The error three.js sees is the one the report states.
    let seen = summary["max_error"].as_f64().unwrap();
    assert!((seen - c["error"]["max"].as_f64().unwrap()).abs() < 1e-4, "three.js {seen} vs report {}", c["error"]["max"]);
}

/// `[cache] window_bytes` reaches the key selection: a window of a few frames still meets
/// the tolerance at every frame (the selection re-reads frames instead of holding them).
#[test]
fn window_bytes_bounds_the_selection_and_keeps_the_tolerance() {
    let cache = bar(&BarSettings { duration: 1.0, ..BarSettings::default() });
    let dir = TempDir::new("cache-window-bytes");
    write_cache(&dir.path, &cache, "bar.pc2");
    let keys = |name: &str, extra: &str| {
        let text = scene("bar.pc2", &format!("fps = 60\nrest = \"rest.obj\"\n{extra}"), "fit", "keyframes = \"auto\"\ntolerance = 0.005");
        std::fs::write(dir.join(format!("{name}.toml")), text).unwrap();
        run(&dir.path, &["bake", &format!("{name}.toml"), "--out", name, "--quiet"]).success();
        let r = read_json(&dir.join(format!("{name}/report.json")));
        assert!(r["cache"]["error"]["max"].as_f64().unwrap() <= 0.005, "{name}: {}", r["cache"]["error"]);
        r["cache"]["keys"].clone()
    };
    let default = keys("default", "");
    // 8 frames of 514 vertices (72 bytes each per frame) is the floor: 1 byte means that.
    let small = keys("small", "window_bytes = 1\n");
    println!("keys with the default window: {default}; with an 8-frame window: {small}");
    std::fs::write(dir.join("zero.toml"), scene("bar.pc2", "fps = 60\nrest = \"rest.obj\"\nwindow_bytes = 0\n", "fit", "keyframes = \"auto\""))
        .unwrap();
    let r = run(&dir.path, &["bake", "zero.toml", "--out", "zero", "--quiet"]);
    assert_eq!(r.code, Some(1), "{r}");
    assert!(r.stderr.contains("window_bytes = 0") && r.stderr.contains("fix:") && !dir.join("zero").exists(), "{r}");
}
