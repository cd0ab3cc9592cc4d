//! Keys from a clip (`[keyframes] clip`): the rapier3d bar (an independent simulator) written
//! in every cache format blendsim reads, its frames taken as keys by `frames` and by `times`
//! through `blendsim import`, compared with the cache's own frames; a bake lists the clip in
//! its depfile; bad clip keys are one-line errors naming the file and the fix.

use blendsim::algorithms::frames::FrameSource;
use blendsim::pipeline::stage_file::{self, Keyframes};
use blendsim::support::budget::Budget;

use crate::cache_bake::{write_cache, FORMATS};
use crate::common::bar::{bar, BarSettings};
use crate::common::cli::{run, tree, TempDir};

/// A keyframe scene whose keys come from `clip` (with its `extra` reader keys) at `keys`
/// (`frames = [...]` or `times = [...]`).
fn scene(clip: &str, extra: &str, keys: &str) -> String {
    format!(
        "name = \"bar\"\nfps = 60\n[keyframes]\nclip = \"{clip}\"\n{extra}{keys}\n[solver]\nmethod = \"hermite\"\n[export]\nformats = [\"glb\"]\n"
    )
}

/// Every format, by frames and by times: the keys are the cache's frames at the cache's times.
#[test]
fn keys_from_a_clip_in_every_format_are_its_frames() {
    let cache = bar(&BarSettings { duration: 0.25, ..BarSettings::default() });
    let dir = TempDir::new("keyframe-clip");
    let picked = [0usize, 6, 15];
    for (label, path, extra) in FORMATS {
        write_cache(&dir.path, &cache, path);
        for keys in ["frames = [0, 6, 15]", "times = [0.0, 0.1, 0.25]"] {
            std::fs::write(dir.join("scene.toml"), scene(path, extra, keys)).unwrap();
            run(&dir.path, &["import", "scene.toml", "-o", "keys.json"]).success();
            let k: Keyframes = stage_file::read(&dir.join("keys.json"), &Budget::default()).unwrap();
            assert_eq!(k.poses.len(), 3, "{label} {keys}");
            let mut frame = vec![[0.0; 3]; cache.frames.vertex_count()];
            for (key, &f) in picked.iter().enumerate() {
                assert!((k.times[key] - f as f64 / 60.0).abs() < 1e-6, "{label} {keys}: key {key} at {}", k.times[key]);
                cache.frames.clone().read_frame(f, &mut frame).unwrap();
                let worst = k.poses[key].iter().zip(&frame).flat_map(|(p, q)| (0..3).map(move |d| (p[d] - q[d]).abs())).fold(0.0, f64::max);
                assert!(worst < 1e-5, "{label} {keys}: key {key} is {worst:.2e} from frame {f}");
            }
            assert_eq!(k.input_bytes, std::fs::metadata(dir.join(path)).map_or(k.input_bytes, |m| m.len()), "{label}: the clip's bytes");
        }
        println!("{label}: keys at frames {picked:?} and at their times are the cache's frames");
    }
    // A bake of a clip's keys: the report counts them, the depfile lists the clip.
    std::fs::write(dir.join("scene.toml"), scene("bar.pc2", "fps = 60\nrest = \"rest.obj\"\n", "frames = [0, 6, 15]")).unwrap();
    run(&dir.path, &["bake", "scene.toml", "--out", "out", "--quiet", "--depfile", "bar.d"]).success();
    let report: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.join("out/report.json")).unwrap()).unwrap();
    assert_eq!(report["keyframes"], 3, "{}", report["keyframes"]);
    let depfile = std::fs::read_to_string(dir.join("bar.d")).unwrap();
    assert!(depfile.contains("bar.pc2") && depfile.contains("rest.obj"), "{depfile}");
}

/// Bad clip keys: exit 1, one line naming the file and the fix, nothing written.
#[test]
fn bad_clip_keys_are_one_line_errors() {
    let cache = bar(&BarSettings { duration: 0.25, ..BarSettings::default() });
    let dir = TempDir::new("keyframe-clip-bad");
    write_cache(&dir.path, &cache, "bar.pc2");
    write_cache(&dir.path, &cache, "bar.usda");
    let pc2 = "fps = 60\nrest = \"rest.obj\"\n";
    let cases = [
        (scene("bar.pc2", pc2, "frames = [0, 16]"), "bar.pc2: [keyframes] frames lists frame 16, but the clip has 16 frames (0 to 15)"),
        (scene("bar.pc2", pc2, "frames = [0, 6]\ntimes = [0.0, 0.1]"), "scene.toml: [keyframes] gives both frames and times for clip = \"bar.pc2\""),
        (scene("bar.pc2", pc2, ""), "[keyframes] clip = \"bar.pc2\" lists no keys"),
        (scene("bar.pc2", pc2, "frames = [6, 2]"), "frames are not strictly increasing"),
        (scene("bar.pc2", pc2, "times = [0.0, 0.105]"), "bar.pc2: [keyframes] times[1] = 0.105 s falls between frames 6 (0.1 s) and 7"),
        (scene("bar.pc2", pc2, "times = [0.0, 0.5]"), "bar.pc2: [keyframes] times[1] = 0.5 s is outside the clip (0 to 0.25 s, 16 frames)"),
        (scene("bar.pc2", "fps = 60\n", "frames = [0, 6]"), "bar.pc2: holds positions only"),
        (scene("bar.usda", "fps = 60\n", "frames = [0, 6]"), "fps is given in [keyframes], but a USD point cache carries its own frame times"),
        (scene("bar.pc2", &format!("{pc2}object = \"Body\"\n"), "frames = [0, 6]"), "`object` was given, but a PC2 cache does not use it"),
        (
            scene("bar.pc2", pc2, "frames = [0, 6]").replace("clip = \"bar.pc2\"\n", "meshes = [\"rest.obj\", \"rest.obj\"]\n"),
            "[keyframes] frames is given without clip",
        ),
        (scene("bar.pc2", pc2, "frames = [0, 6]\nmeshes = [\"rest.obj\", \"rest.obj\"]"), "[keyframes] has both meshes and clip"),
        (scene("missing.fbx", "", "frames = [0, 6]"), "missing.fbx"),
    ];
    for (text, says) in cases {
        std::fs::write(dir.join("scene.toml"), &text).unwrap();
        let before = tree(&dir.path);
        let r = run(&dir.path, &["bake", "scene.toml", "--out", "out"]);
        assert_eq!(r.code, Some(1), "{says}:\n{r}");
        let line = r.stderr.trim();
        assert!(line.starts_with("error: ") && !line.contains('\n') && line.contains(" (fix: "), "{says}: {line}");
        assert!(line.contains(says), "expected {says:?} in {line}");
        assert_eq!(tree(&dir.path), before, "nothing written: {line}");
        println!("{line}");
    }
}
