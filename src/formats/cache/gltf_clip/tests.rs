//! glTF clip reader and writer tests: files written here with gltf-json, evaluated by our
//! reader and by three.js (`tests/checkers/gltf_cache_check.mjs`), which must agree to 1e-5
//! of the bounding-box diagonal at every frame.

use std::path::{Path, PathBuf};
use std::process::Command;

use gltf_json as json;
use json::animation::{Interpolation as Interp, Property};
use serde_json::json as value;

use super::fixtures::{quat, skinned_clip, Builder};
use super::*;
use crate::algorithms::frames::MemoryFrames;
use crate::formats::cache::tests::{assert_frames_equal, scratch, wave, wave_mesh};

fn f32s(points: &[[f64; 3]]) -> Vec<[f32; 3]> {
    points.iter().map(|p| p.map(|x| x as f32)).collect()
}

/// A 5 x 5 grid with two morph targets under a moved parent node, and four animations:
/// CUBICSPLINE, LINEAR and STEP weights, and LINEAR node TRS.
fn morph_clip(path: &Path) {
    let grid = wave_mesh(5);
    let base = f32s(&grid.positions);
    let bump: Vec<[f32; 3]> = base.iter().map(|p| [0.0, 0.0, 0.3 * p[0].sin()]).collect();
    let shear: Vec<[f32; 3]> = base.iter().map(|p| [0.2 * p[1], 0.0, 0.0]).collect();
    let mut b = Builder::new();
    let mesh = b.mesh(&base, &grid.triangles, &[bump, shear], None);
    let node = b.node(json::Node {
        mesh: Some(mesh),
        name: Some("grid".into()),
        translation: Some([0.0, 0.5, 0.0]),
        scale: Some([1.0, 2.0, 1.0]),
        ..Default::default()
    });
    let root = b.node(json::Node {
        name: Some("root".into()),
        children: Some(vec![node]),
        translation: Some([1.0, 0.0, 0.0]),
        rotation: Some(json::scene::UnitQuaternion(quat([0.0, 1.0, 0.0], 30.0))),
        ..Default::default()
    });
    // CUBICSPLINE: per key, in-tangents (2), values (2), out-tangents (2); uneven intervals.
    #[rustfmt::skip]
    let cubic = [
        0.0, 0.0,   0.0, 0.0,   2.0, -1.0,
        1.5, 0.5,   0.8, 0.3,   -0.5, 2.0,
        -1.0, 0.0,  0.1, 0.9,   0.0, 0.0,
    ];
    b.animation("cubic", &[(node, Property::MorphTargetWeights, Interp::CubicSpline, &[0.0, 0.4, 1.0], &cubic)]);
    b.animation("linear", &[(node, Property::MorphTargetWeights, Interp::Linear, &[0.0, 0.5, 1.0], &[0.0, 0.0, 1.0, 0.5, 0.2, 1.0])]);
    b.animation("step", &[(node, Property::MorphTargetWeights, Interp::Step, &[0.0, 0.3, 0.6, 0.9], &[0.0, 0.0, 1.0, 0.0, 0.5, 0.5, 0.0, 1.0])]);
    let spin = [quat([0.0, 0.0, 1.0], 0.0), quat([0.0, 0.0, 1.0], 50.0), quat([1.0, 0.0, 0.0], 70.0)].concat();
    b.animation(
        "trs",
        &[
            (root, Property::Translation, Interp::Linear, &[0.0, 1.0], &[1.0, 0.0, 0.0, 1.0, 2.0, -1.0]),
            (node, Property::Rotation, Interp::Linear, &[0.0, 0.5, 1.0], &spin),
            (node, Property::MorphTargetWeights, Interp::Linear, &[0.0, 1.0], &[0.0, 0.0, 1.0, 1.0]),
        ],
    );
    std::fs::write(path, b.glb(vec![root])).unwrap();
}

/// Every frame of a clip as our reader evaluates it: (times, points).
fn evaluate(frames: &mut dyn FrameSource) -> (Vec<f64>, Vec<Vec<Point>>) {
    let times = (0..frames.frame_count()).map(|f| frames.time(f)).collect();
    let points = (0..frames.frame_count())
        .map(|f| {
            let mut out = vec![[0.0; 3]; frames.vertex_count()];
            frames.read_frame(f, &mut out).unwrap();
            out
        })
        .collect();
    (times, points)
}

fn checkers_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/checkers")
}

/// Run three.js on `file` at our frames; panics with the checker's output when they disagree.
/// A missing Node or npm checker is a failure naming `make test-deps`, never a skip.
fn three_js_agrees(file: &Path, animation: Option<&str>, times: &[f64], points: &[Vec<Point>]) -> serde_json::Value {
    for package in ["gltf-validator", "three"] {
        let manifest = checkers_dir().join("node_modules").join(package).join("package.json");
        assert!(manifest.is_file(), "{} is missing: run `make test-deps` (npm ci in tests/checkers)", manifest.display());
    }
    let expected = file.with_extension("expected.json");
    std::fs::write(&expected, value!({ "animation": animation, "times": times, "points": points, "tolerance": 1e-5 }).to_string()).unwrap();
    let output = Command::new("node")
        .arg(checkers_dir().join("gltf_cache_check.mjs"))
        .arg(file)
        .arg(&expected)
        .output()
        .unwrap_or_else(|e| panic!("cannot run node ({e}): install Node.js 20, then run `make test-deps`"));
    let (stdout, stderr) = (String::from_utf8_lossy(&output.stdout), String::from_utf8_lossy(&output.stderr));
    assert!(output.status.success(), "gltf_cache_check.mjs {} failed:\n{stdout}\n{stderr}", file.display());
    serde_json::from_str(stdout.lines().last().unwrap()).unwrap()
}

/// The largest displacement from frame 0 relative to the diagonal: the clip must really move.
fn motion(points: &[Vec<Point>]) -> f64 {
    let all: Vec<Point> = points.iter().flatten().copied().collect();
    let diagonal = crate::algorithms::geometry::bbox_diagonal(&all);
    points
        .iter()
        .flat_map(|f| f.iter().zip(&points[0]).map(|(p, q)| crate::algorithms::geometry::norm(crate::algorithms::geometry::sub(*p, *q))))
        .fold(0.0, f64::max)
        / diagonal
}

#[test]
fn morph_weights_with_every_sampler_and_node_trs_match_three_js() {
    let dir = scratch("gltf-morph");
    let path = dir.join("morph.glb");
    morph_clip(&path);
    for animation in ["cubic", "linear", "step", "trs"] {
        let mut opened = open(&path, Some(animation), Some(30.0)).unwrap();
        assert_eq!((opened.frames.frame_count(), opened.fps_from_keys), (if animation == "step" { 28 } else { 31 }, false), "{animation}");
        let (times, points) = evaluate(&mut opened.frames);
        assert!(motion(&points) > 0.05, "{animation} moves");
        let summary = three_js_agrees(&path, Some(animation), &times, &points);
        assert_eq!(summary["skinned"], false);
        assert!(summary["max_error"].as_f64().unwrap() <= 1e-5, "{animation}: {summary}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn cubic_spline_weights_are_exact_at_keys_in_world_space() {
    // At key 1 (0.4 s) the weights are the key values (0.8, 0.3); the world transform is the
    // parent's rotation about y and translation, then the node's translation and scale.
    let dir = scratch("gltf-cubic-key");
    let path = dir.join("morph.glb");
    morph_clip(&path);
    let mut opened = open(&path, Some("cubic"), Some(5.0)).unwrap();
    assert_eq!((opened.frames.frame_count(), opened.frames.time(2)), (6, 0.4f32 as f64), "the frame at 0.4 s snaps to the f32 key");
    let mut out = vec![[0.0; 3]; 25];
    opened.frames.read_frame(2, &mut out).unwrap();
    let (s, c) = 30f64.to_radians().sin_cos();
    for (v, p) in wave_mesh(5).positions.iter().enumerate() {
        let (x, y) = (p[0] as f32, p[1] as f32);
        let local = [x as f64 + 0.3 * (0.2 * y) as f64, y as f64, 0.8 * (0.3 * x.sin()) as f64];
        let node = [local[0], 2.0 * local[1] + 0.5, local[2]];
        let world = [c * node[0] + s * node[2] + 1.0, node[1], -s * node[0] + c * node[2]];
        assert!((0..3).all(|d| (out[v][d] - world[d]).abs() < 1e-6), "vertex {v}: {:?} vs {world:?}", out[v]);
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn skinned_clip_with_trs_joints_and_morph_matches_three_js() {
    let dir = scratch("gltf-skinned");
    let path = dir.join("skinned.glb");
    skinned_clip(&path);
    let mut opened = open(&path, None, Some(30.0)).unwrap();
    // At rest (frame 0) the skin is the bind pose: joints times inverse binds are identities.
    assert!((opened.mesh.positions[13][1] - 3.0).abs() < 1e-12 && opened.mesh.positions[13][2] == 0.0, "{:?}", opened.mesh.positions[13]);
    let (times, points) = evaluate(&mut opened.frames);
    assert_eq!(times.len(), 31);
    assert!(motion(&points) > 0.1, "the ribbon swings");
    let summary = three_js_agrees(&path, Some("swing"), &times, &points);
    assert_eq!(summary["skinned"], true);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn glb_writer_round_trips_and_is_valid_for_three_js() {
    let dir = scratch("gltf-write");
    let path = dir.join("wave.glb");
    let (mesh, mut frames) = (wave_mesh(4), wave(16, 7, 24.0));
    write(&path, &mesh, &mut frames, 24.0).unwrap();
    // No fps given: the evenly spaced keys give it.
    let mut opened = open(&path, None, None).unwrap();
    assert_eq!((opened.fps, opened.fps_from_keys), (24.0, true));
    assert_eq!(opened.mesh.triangles, mesh.triangles);
    assert_frames_equal(&mut frames, &mut opened.frames, 1e-6);
    let (times, points) = evaluate(&mut opened.frames);
    three_js_agrees(&path, None, &times, &points);

    // Few vertices move: sparse targets (and a frame equal to frame 0: a zero target).
    let mut still =
        MemoryFrames { times: vec![0.0, 0.5, 1.0, 1.5], frames: vec![f32s(&mesh.positions).iter().map(|p| p.map(f64::from)).collect(); 4] };
    still.frames[1][5][2] = 0.25;
    still.frames[3][0] = [-1.0, 2.0, 0.5];
    let sparse = dir.join("still.glb");
    write(&sparse, &mesh, &mut still, 2.0).unwrap();
    let text = String::from_utf8_lossy(&std::fs::read(&sparse).unwrap()).into_owned();
    assert_eq!(text.matches("\"sparse\":").count(), 3, "two sparse targets and the one-hot weights");
    let mut opened = open(&sparse, None, None).unwrap();
    assert_frames_equal(&mut still, &mut opened.frames, 0.0);
    let (times, points) = evaluate(&mut opened.frames);
    three_js_agrees(&sparse, None, &times, &points);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn gltf_with_external_buffer_and_data_uri_read_the_same() {
    let dir = scratch("gltf-external");
    let glb = dir.join("morph.glb");
    morph_clip(&glb);
    let bytes = std::fs::read(&glb).unwrap();
    let json_len = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
    let mut root: serde_json::Value = serde_json::from_slice(&bytes[20..20 + json_len]).unwrap();
    let bin = &bytes[20 + json_len + 8..];
    std::fs::write(dir.join("my clip.bin"), bin).unwrap();
    root["buffers"][0]["uri"] = value!("my%20clip.bin");
    std::fs::write(dir.join("external.gltf"), root.to_string()).unwrap();
    let mut a = open(&glb, Some("cubic"), Some(30.0)).unwrap();
    let mut b = open(&dir.join("external.gltf"), Some("cubic"), Some(30.0)).unwrap();
    assert_eq!(b.bytes, std::fs::metadata(dir.join("external.gltf")).unwrap().len() + bin.len() as u64);
    assert_frames_equal(&mut a.frames, &mut b.frames, 0.0);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn bad_clips_are_one_line_errors_naming_the_file() {
    let dir = scratch("gltf-bad");
    let path = dir.join("morph.glb");
    morph_clip(&path);
    let err = |p: &Path, animation: Option<&str>, fps: Option<f64>| {
        let s = open(p, animation, fps).unwrap_err().to_string();
        assert!(s.starts_with(&p.display().to_string()) && s.contains(" (fix: ") && !s.contains('\n'), "{s}");
        s
    };
    let s = err(&path, Some("walk"), Some(30.0));
    assert!(s.contains("has no animation named \"walk\" (its animations: \"cubic\", \"linear\", \"step\", \"trs\")"), "{s}");
    let s = err(&path, None, Some(30.0));
    assert!(s.contains("has several animations"), "{s}");
    let s = err(&path, Some("cubic"), None);
    assert!(s.contains("the 3 key times of animation \"cubic\" are not evenly spaced"), "{s}");

    let bytes = std::fs::read(&path).unwrap();
    let cut = dir.join("cut.glb");
    std::fs::write(&cut, &bytes[..bytes.len() - 100]).unwrap();
    let s = err(&cut, Some("cubic"), Some(30.0));
    assert!(s.contains(&format!("its GLB header (byte 8) says {} bytes, but the file has {}", bytes.len(), bytes.len() - 100)), "{s}");
    std::fs::write(&cut, &bytes[..10]).unwrap();
    assert!(err(&cut, None, None).contains("is 10 bytes, shorter than a GLB header"));

    // A .gltf whose external buffer is shorter than it says.
    let json_len = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
    let mut root: serde_json::Value = serde_json::from_slice(&bytes[20..20 + json_len]).unwrap();
    root["buffers"][0]["uri"] = value!("short.bin");
    std::fs::write(dir.join("short.bin"), [0u8; 16]).unwrap();
    let short = dir.join("short.gltf");
    std::fs::write(&short, root.to_string()).unwrap();
    let s = open(&short, Some("cubic"), Some(30.0)).unwrap_err().to_string();
    assert!(s.starts_with(&format!("{}: is 16 bytes, but buffer 0 of {} needs", dir.join("short.bin").display(), short.display())), "{s}");
    // An accessor beyond its view.
    root["buffers"][0]["uri"] = value!("full.bin");
    std::fs::write(dir.join("full.bin"), &bytes[20 + json_len + 8..]).unwrap();
    root["accessors"][0]["count"] = value!(26);
    std::fs::write(&short, root.to_string()).unwrap();
    let s = err(&short, Some("cubic"), Some(30.0));
    assert!(s.contains("POSITION of primitive 0 of mesh \"mesh\" (accessor 0) needs bytes 0 to 312 of buffer view 0, which has 300"), "{s}");
    std::fs::write(&short, "{\"asset\": {\"version\": \"2.0\"}, \"accessors\": [{\"count\": 1}]}").unwrap();
    assert!(err(&short, None, None).contains("its glTF JSON"));
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Every numeric leaf of a JSON value, as a JSON pointer.
fn numeric_pointers(v: &serde_json::Value, at: String, out: &mut Vec<String>) {
    match v {
        serde_json::Value::Number(_) => out.push(at),
        serde_json::Value::Array(a) => a.iter().enumerate().for_each(|(i, x)| numeric_pointers(x, format!("{at}/{i}"), out)),
        serde_json::Value::Object(o) => o.iter().for_each(|(k, x)| numeric_pointers(x, format!("{at}/{k}"), out)),
        _ => {}
    }
}

/// A GLB with `json` as its JSON chunk and `bin` as its BIN chunk.
fn glb_with(json: &serde_json::Value, bin: &[u8]) -> Vec<u8> {
    let mut text = json.to_string().into_bytes();
    text.resize(text.len().next_multiple_of(4), b' ');
    let total = 12 + 8 + text.len() + 8 + bin.len();
    let mut out = b"glTF".to_vec();
    for w in [2u32, total as u32, text.len() as u32] {
        out.extend(w.to_le_bytes());
    }
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&text);
    out.extend((bin.len() as u32).to_le_bytes());
    out.extend_from_slice(b"BIN\0");
    out.extend_from_slice(bin);
    out
}

/// Open a clip and read every frame (capped): errors are fine, panics are not.
fn exercise_clip(path: &Path) {
    match open(path, Some("swing"), Some(30.0)) {
        Ok(mut clip) => {
            let mut out = vec![[0.0; 3]; clip.frames.vertex_count()];
            for f in 0..clip.frames.frame_count().min(40) {
                if let Err(e) = clip.frames.read_frame(f, &mut out) {
                    assert!(e.to_string().contains(" (fix: "), "{e}");
                }
            }
        }
        Err(e) => assert!(!e.to_string().contains('\n'), "{e}"),
    }
}

mod fuzz {
    use super::*;
    use proptest::prelude::*;

    /// The skinned clip's JSON and BIN, made once.
    fn parts() -> &'static (serde_json::Value, Vec<u8>) {
        static PARTS: std::sync::OnceLock<(serde_json::Value, Vec<u8>)> = std::sync::OnceLock::new();
        PARTS.get_or_init(|| {
            let dir = scratch("gltf-fuzz-source");
            let path = dir.join("skinned.glb");
            skinned_clip(&path);
            let bytes = std::fs::read(&path).unwrap();
            std::fs::remove_dir_all(&dir).unwrap();
            let json_len = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
            (serde_json::from_slice(&bytes[20..20 + json_len]).unwrap(), bytes[20 + json_len + 8..].to_vec())
        })
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 400, failure_persistence: None, ..ProptestConfig::default() })]

        /// Numbers of the JSON (counts, offsets, indices, component types, ...) replaced by
        /// extremes, and bytes of the BIN chunk flipped.
        #[test]
        fn mutated_clips_never_panic(
            edits in prop::collection::vec((any::<prop::sample::Index>(), prop_oneof![
                Just(-1i64), Just(0), Just(1), Just(3), Just(4), Just(5126), Just(5121), Just(65535), Just(1 << 31), Just(1 << 40), Just(i64::MAX), -10..400i64,
            ]), 1..4),
            flips in prop::collection::vec((any::<prop::sample::Index>(), 1..=255u8), 0..3),
            truncate in prop::option::weighted(0.1, any::<prop::sample::Index>()),
        ) {
            let (json, bin) = parts();
            let (mut json, mut bin) = (json.clone(), bin.clone());
            let mut pointers = Vec::new();
            numeric_pointers(&json, String::new(), &mut pointers);
            for (at, value) in edits {
                let pointer = at.get(&pointers).clone();
                *json.pointer_mut(&pointer).unwrap() = serde_json::json!(value);
            }
            for (at, mask) in flips {
                let i = at.index(bin.len());
                bin[i] ^= mask;
            }
            let mut bytes = glb_with(&json, &bin);
            if let Some(at) = truncate {
                bytes.truncate(at.index(bytes.len()));
            }
            let dir = tempfile::tempdir().unwrap();
            let path = dir.path().join("fuzz.glb");
            std::fs::write(&path, &bytes).unwrap();
            exercise_clip(&path);
        }
    }
}

/// The CUBICSPLINE morph clip and the skinned clip baked end to end through the chain
/// (`[cache]` with `keyframes = "auto"`, method `fit`): within the tolerance of our reader's
/// frames at every frame, which three.js agrees with (the tests above).
#[test]
fn cubic_morph_and_skinned_clips_bake_end_to_end() {
    let dir = scratch("gltf-bake");
    morph_clip(&dir.join("morph.glb"));
    skinned_clip(&dir.join("skinned.glb"));
    for (file, animation) in [("morph.glb", "animation = \"cubic\"\n"), ("skinned.glb", "")] {
        let scene_path = dir.join("scene.toml");
        std::fs::write(
            &scene_path,
            format!("name = \"clip\"\n[cache]\npath = \"{file}\"\nfps = 30\n{animation}keyframes = \"auto\"\ntolerance = 0.005\n[solver]\nmethod = \"fit\"\n[export]\nformats = [\"glb\"]\n"),
        )
        .unwrap();
        let scene = crate::pipeline::scene::SceneFile::load(&scene_path).unwrap();
        let out = dir.join(format!("out-{file}"));
        let mut staging = crate::support::output::Staging::new(&out).unwrap();
        let report = crate::pipeline::stages::bake(&scene, None, &mut staging, &crate::support::progress::Progress::new(true))
            .unwrap_or_else(|e| panic!("{file}: {e}"));
        staging.commit().unwrap();
        let c = report.cache.expect("a cache report");
        assert_eq!((c.format.as_str(), c.frames), ("gltf", 31), "{file}");
        assert!(c.error.max <= 0.005 && c.error.per_frame.iter().all(|&e| e <= 0.005), "{file}: {:?}", c.error);
        assert!(c.keys.len() >= 2 && c.keys[0] == 0 && *c.keys.last().unwrap() == 30, "{file}: {:?}", c.keys);
        // The baked glb, read back at the clip's frames, is within the tolerance of the clip.
        let mut clip = open(&dir.join(file), (!animation.is_empty()).then_some("cubic"), Some(30.0)).unwrap();
        let mut baked = open(&out.join("clip.glb"), None, Some(30.0)).unwrap();
        let (_, expected) = evaluate(&mut clip.frames);
        let (_, got) = evaluate(&mut baked.frames);
        assert!(motion(&expected) > 0.05, "{file}: the clip moves");
        let all: Vec<Point> = expected.iter().flatten().copied().collect();
        let diagonal = crate::algorithms::geometry::bbox_diagonal(&all);
        let max = expected
            .iter()
            .zip(&got)
            .flat_map(|(a, b)| a.iter().zip(b).map(|(p, q)| crate::algorithms::geometry::norm(crate::algorithms::geometry::sub(*p, *q))))
            .fold(0.0, f64::max);
        assert!(max / diagonal <= 0.005 + 1e-6, "{file}: {}", max / diagonal);
    }
    std::fs::remove_dir_all(&dir).unwrap();
}
