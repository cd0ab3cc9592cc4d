//! Studio caches in: Alembic and FBX, with Blender 4.2 (`bpy`) as the independent writer.
//!
//! `tests/checkers/blender_studio_export.py` builds an animated mesh in Blender (an animated
//! shape key, a 3-bone armature, a Displace modifier after it, non-unit object scale, a
//! centimetre scene) and exports it with Blender's own Alembic and FBX exporters, beside the
//! mesh Blender evaluates at every frame. Each file is read by `blendsim import --cache-out`
//! and compared with Blender's mesh after the documented conversion (Blender `(x, y, z)` is
//! `(x, z, -y)`; Alembic in Blender units, FBX in metres), then baked through `[cache]` with
//! `method = "fit"`, and three of its frames are taken as keys by `[keyframes] clip`. The FBX
//! is also baked with `method = "spacetime"` and its files played back in Blender. The tests
//! fail (never skip) when Blender is missing.

use std::path::Path;

use blendsim::algorithms::geometry::{bbox_diagonal, Point};
use blendsim::formats::cache::{CacheOptions, VertexCache};
use blendsim::pipeline::scene::Format;
use blendsim::pipeline::stage_file::{self, Keyframes, OutputKind};
use blendsim::support::budget::Budget;
use serde_json::Value;

use crate::common::checkers::{check_blender, required_blender_python, Expected};
use crate::common::cli::{read_json, run, TempDir};
use crate::common::verify::{library_animation, output_files};

/// Run the Blender script into `dir`: the exports and Blender's evaluated frames.
fn blender_exports(dir: &Path, frames: usize) -> Value {
    let python = required_blender_python();
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/checkers/blender_studio_export.py");
    let out = std::process::Command::new(&python).arg(script).arg(dir).arg(frames.to_string()).output().unwrap();
    assert!(out.status.success(), "Blender failed: {}\n{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    read_json(&dir.join("info.json"))
}

/// Blender's frames (`FRAMES x vertices x 3` float32, z up) converted to y up and scaled.
fn blender_frames(path: &Path, vertices: usize, scale: f64) -> Vec<Vec<Point>> {
    let bytes = std::fs::read(path).unwrap();
    let values: Vec<f64> = bytes.chunks_exact(4).map(|c| f32::from_le_bytes(c.try_into().unwrap()) as f64).collect();
    values.chunks_exact(3 * vertices).map(|f| f.chunks_exact(3).map(|p| [p[0] * scale, p[2] * scale, -p[1] * scale]).collect()).collect()
}

/// The largest distance between the two, over every frame and vertex.
fn farthest(cache: &mut VertexCache, reference: &[Vec<Point>]) -> f64 {
    assert_eq!((cache.frame_count(), cache.frames.vertex_count()), (reference.len(), reference[0].len()));
    let mut got = vec![[0.0; 3]; reference[0].len()];
    let mut worst: f64 = 0.0;
    for (f, expected) in reference.iter().enumerate() {
        cache.frames.read_frame(f, &mut got).unwrap();
        for (p, q) in got.iter().zip(expected) {
            worst = worst.max(((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt());
        }
    }
    worst
}

/// The signed volume of a closed mesh: positive when its triangles face outward.
fn signed_volume(positions: &[Point], triangles: &[[u32; 3]]) -> f64 {
    triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| positions[i as usize]);
            (a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0]) + a[2] * (b[0] * c[1] - b[1] * c[0])) / 6.0
        })
        .sum()
}

/// `import --cache-out` of the cache at `path` (with `extra` keys in `[cache]`) exits 1 with one
/// line that says `says` and its fix, and writes nothing; the line.
fn refused(dir: &Path, path: &str, extra: &str, says: &str) -> String {
    std::fs::write(dir.join("bad.toml"), scene(path, extra)).unwrap();
    let r = run(dir, &["import", "bad.toml", "--cache-out", "bad.glb"]);
    assert_eq!(r.code, Some(1), "{path} {extra}: {r}");
    let line = r.stderr.trim().to_string();
    assert!(line.contains(says) && line.contains(" (fix: ") && !line.contains('\n'), "{path} {extra}: {line}");
    assert!(!dir.join("bad.glb").exists(), "{path} {extra}: nothing written");
    println!("{path} {}: {line}", extra.trim());
    line
}

fn scene(path: &str, extra: &str) -> String {
    format!(
        "name = \"body\"\n[cache]\npath = \"{path}\"\n{extra}keyframes = \"auto\"\ntolerance = 0.005\n[solver]\nmethod = \"fit\"\n[export]\nformats = [\"usda\", \"glb\"]\n"
    )
}

/// Blender's Alembic and FBX exports read as Blender evaluates them (1e-5 of the bbox
/// diagonal; measured: Alembic ~1e-8, FBX ~1e-7, both float32), face outward, and bake.
#[test]
fn blender_alembic_and_fbx_read_as_blender_evaluates_them_and_bake() {
    let dir = TempDir::new("studio-blender");
    let frames = 24;
    let info = blender_exports(&dir.path, frames);
    let vertices = info["vertices"].as_u64().unwrap() as usize;
    let unit = info["unit_scale"].as_f64().unwrap();
    // Blender keeps the unit scale in float32.
    assert!((unit - 0.01).abs() < 1e-9, "a centimetre scene: {unit}");
    for (file, reference, scale) in [("body.abc", "abc.f32", 1.0), ("body.fbx", "fbx.f32", 0.01)] {
        let expected = blender_frames(&dir.join(reference), vertices, scale);
        assert_eq!(expected.len(), frames);
        let diagonal = bbox_diagonal(&expected.concat());
        std::fs::write(dir.join("scene.toml"), scene(file, "")).unwrap();
        let out = format!("{file}.glb");
        run(&dir.path, &["import", "scene.toml", "--cache-out", &out]).success();
        let mut cache = VertexCache::open(&dir.join(&out), &CacheOptions::default()).unwrap();
        let d = farthest(&mut cache, &expected) / diagonal;
        let moved = expected
            .iter()
            .map(|f| f.iter().zip(&expected[0]).map(|(p, q)| (p[1] - q[1]).abs().max((p[0] - q[0]).abs())).fold(0.0, f64::max))
            .fold(0.0, f64::max);
        println!("{file}: {frames} frames of {vertices} vertices, farthest point {d:.2e} of the diagonal {diagonal:.4} from Blender's (the mesh moves {:.3} of it)", moved / diagonal);
        assert!(moved > 0.05 * diagonal, "{file}: the mesh really moves");
        assert!(d <= 1e-5, "{file}: {d:.3e} of the diagonal from Blender's evaluated mesh");
        assert!(signed_volume(&cache.mesh.positions, &cache.mesh.triangles) > 0.0, "{file}: faces outward");
        // The fit bake through [cache].
        let baked = format!("{file}-baked");
        run(&dir.path, &["bake", "scene.toml", "--out", &baked, "--quiet"]).success();
        let report = read_json(&dir.join(&baked).join("report.json"));
        let c = &report["cache"];
        let format = if file.ends_with(".abc") { "alembic" } else { "fbx" };
        assert_eq!((c["format"].as_str(), c["frames"].as_u64()), (Some(format), Some(frames as u64)), "{c}");
        assert!(c["error"]["max"].as_f64().unwrap() <= 0.005, "{file}: {}", c["error"]);
        println!("{file}: baked with {} keys, error max {}", c["keys"].as_array().unwrap().len(), c["error"]["max"]);
        // Keys from the clip: its frames 0, 6 and 23 as keyframes are Blender's poses there,
        // at the clip's frame times.
        let picked = [0usize, 6, frames - 1];
        let keys = format!("name = \"body\"\n[keyframes]\nclip = \"{file}\"\nframes = [0, 6, {}]\n[solver]\nmethod = \"hermite\"\n", frames - 1);
        std::fs::write(dir.join("keys.toml"), keys).unwrap();
        run(&dir.path, &["import", "keys.toml", "-o", "keys.json"]).success();
        let k: Keyframes = stage_file::read(&dir.join("keys.json"), &Budget::default()).unwrap();
        assert_eq!(k.poses.len(), picked.len(), "{file}");
        for (key, &f) in picked.iter().enumerate() {
            let since = k.times[key] - k.times[0];
            assert!((since - f as f64 / 24.0).abs() < 1e-6, "{file}: key {key} at {since} s after the first");
            let worst =
                k.poses[key].iter().zip(&expected[f]).map(|(p, q)| (0..3).map(|d| (p[d] - q[d]).powi(2)).sum::<f64>().sqrt()).fold(0.0, f64::max);
            assert!(worst <= 1e-5 * diagonal, "{file}: key {key} is {:.2e} of the diagonal from Blender's frame {f}", worst / diagonal);
        }
        println!("{file}: frames {picked:?} as keyframes are Blender's poses");
    }
}

/// Choosing what to read: several takes or meshes and none named is a one-line error that
/// lists them; naming them reads; a static mesh, a wrong name, an HDF5 archive are errors.
#[test]
fn takes_and_objects_are_chosen_by_name() {
    let dir = TempDir::new("studio-choice");
    blender_exports(&dir.path, 12);
    let fails = |path: &str, extra: &str, says: &str| {
        refused(&dir.path, path, extra, says);
    };
    fails("choice.fbx", "", "has several takes (");
    fails("choice.fbx", "take = \"Nope\"\n", "has no take \"Nope\" (its takes: ");
    fails("choice.fbx", "take = \"Rig|Wave\"\nobject = \"Nope\"\n", "has no mesh object \"Nope\" (its meshes: ");
    fails("choice.fbx", "take = \"Rig|Wave\"\nobject = \"Crate\"\n", "mesh \"Crate\" does not move in take \"Rig|Wave\"");
    fails("static.fbx", "", "has no animation stack");
    fails("choice.abc", "object = \"Crate\"\n", "does not move");
    fails("choice.abc", "object = \"/Nope\"\n", "has no mesh object /Nope (its meshes: ");
    fails("choice.abc", "take = \"x\"\n", "`take` was given, but an Alembic cache does not use it");
    fails("choice.abc", "fps = 30\n", "fps is given, but Alembic and FBX files carry their own frame times");
    std::fs::write(dir.join("old.abc"), b"\x89HDF\r\n\x1a\n and the rest of an HDF5 file").unwrap();
    fails("old.abc", "", "is an HDF5 Alembic archive");
    // Named, they read: the animated mesh among two (the only animated one needs no name in
    // Alembic), and one take.
    for (path, extra) in [("choice.fbx", "take = \"Rig|Wave\"\nobject = \"Body\"\n"), ("choice.abc", ""), ("choice.abc", "object = \"Body\"\n")] {
        std::fs::write(dir.join("ok.toml"), scene(path, extra)).unwrap();
        run(&dir.path, &["import", "ok.toml", "--cache-out", "ok.glb"]).success();
        let cache = VertexCache::open(&dir.join("ok.glb"), &CacheOptions::default()).unwrap();
        assert_eq!(cache.frame_count(), 12, "{path} {extra}");
    }
}

/// An Alembic file written by another writer (the Alembic library itself, through PyPI
/// `alembic3d`): a waving sheet under a 2x-scaled Xform reads as the formula times 2; a NaN and
/// a point count that changes are one-line errors naming the file, the object and the frame.
#[test]
fn alembic_from_the_library_reads_and_damage_is_named() {
    let dir = TempDir::new("studio-abc-library");
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("benches/studio/abc_wave.py");
    let python = std::env::var_os("BLENDSIM_PYTHON").unwrap_or_else(|| "python3".into());
    let write = |name: &str, damage: &[&str]| {
        let out = std::process::Command::new(&python).arg(&script).arg(dir.join(name)).args(["6", "5"]).args(damage).output().unwrap();
        assert!(out.status.success(), "alembic3d (make deps-alembic): {}", String::from_utf8_lossy(&out.stderr));
    };
    write("sheet.abc", &[]);
    write("nan.abc", &["nan"]);
    write("grow.abc", &["grow"]);
    let mut cache = VertexCache::open(&dir.join("sheet.abc"), &CacheOptions::default()).unwrap();
    assert_eq!((cache.frame_count(), cache.frames.vertex_count(), cache.fps, cache.mesh.triangles.len()), (5, 36, 24.0, 50));
    let mut got = vec![[0.0; 3]; 36];
    for f in 0..5 {
        cache.frames.read_frame(f, &mut got).unwrap();
        let t = f as f64 / 24.0;
        for (v, p) in got.iter().enumerate() {
            let (x, y) = ((v % 6) as f64 / 6.0, (v / 6) as f64 / 6.0);
            let want = [2.0 * x, 2.0 * 0.1 * (6.0 * x - 3.0 * t).sin() * (4.0 * y + t).cos(), 2.0 * y];
            assert!((0..3).all(|d| (p[d] - want[d]).abs() < 1e-6), "frame {f} vertex {v}: {p:?} vs {want:?}");
        }
    }
    let nan = match VertexCache::open(&dir.join("nan.abc"), &CacheOptions::default()) {
        Ok(mut c) => c.frames.read_frame(4, &mut got).unwrap_err().to_string(),
        Err(e) => e.to_string(),
    };
    assert!(
        nan.contains("nan.abc: /Sheet/SheetShape (PolyMesh) has a non-finite position at frame 4 (vertex 0: coordinate x is NaN)")
            && !nan.contains('\n'),
        "{nan}"
    );
    let grow = VertexCache::open(&dir.join("grow.abc"), &CacheOptions::default()).unwrap_err().to_string();
    assert!(grow.contains("grow.abc: the topology of /Sheet/SheetShape changes at frame 4") && !grow.contains('\n'), "{grow}");
    println!("{nan}\n{grow}");
}

/// Where Debian's `assimp-testmodels` (the Assimp project's test files) keeps its FBX files.
const ASSIMP_FBX: &str = "/usr/share/assimp/models/FBX";

/// FBX files that this project did not write: the Assimp project's test files (Debian
/// `assimp-testmodels`). Two skinned, animated files written by other Blender exporters
/// (2.90 and 2.79) read as Blender 4.2's own FBX importer plays them (1e-5 of the diagonal;
/// measured ~3e-7, float32), in metres y up; an ASCII file of the FBX SDK 2018 whose take
/// animates only renderer settings is refused as static; a file whose header is damaged
/// (its zero bytes turned to spaces) is a one-line error naming it.
#[test]
fn fbx_from_other_writers_reads_as_blender_imports_them() {
    let samples = Path::new(ASSIMP_FBX);
    assert!(samples.is_dir(), "{ASSIMP_FBX} is missing: run `make deps-fbx-samples` (or `make test-deps`): Debian's assimp-testmodels");
    let dir = TempDir::new("studio-fbx-others");
    let python = required_blender_python();
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/checkers/blender_fbx_import.py");
    // (file, its writer, vertices, frames)
    for (file, writer, vertices, frames) in [("animation_with_skeleton.fbx", "Blender 2.90", 1058, 21), ("huesitos.fbx", "Blender 2.79", 62, 40)] {
        let path = samples.join(file);
        let creator = std::fs::read(&path).unwrap();
        let version = writer.replace("Blender ", "");
        assert!(creator.windows(version.len()).any(|w| w == version.as_bytes()), "{file} names its writer, {writer}");
        let stem = file.trim_end_matches(".fbx");
        let blender = dir.join(stem);
        std::fs::create_dir_all(&blender).unwrap();
        let out = std::process::Command::new(&python).arg(&script).arg(&path).arg(&blender).output().unwrap();
        assert!(out.status.success(), "Blender failed on {file}: {}", String::from_utf8_lossy(&out.stderr));
        let info = read_json(&blender.join("info.json"));
        assert_eq!((info["vertices"].as_u64(), info["frames"].as_u64()), (Some(vertices), Some(frames)), "{file}: {info}");
        let expected = blender_frames(&blender.join("frames.f32"), vertices as usize, 1.0);
        let diagonal = bbox_diagonal(&expected.concat());

        std::fs::write(dir.join(format!("{stem}.toml")), scene(&path.display().to_string(), "")).unwrap();
        let glb = format!("{stem}.glb");
        run(&dir.path, &["import", &format!("{stem}.toml"), "--cache-out", &glb]).success();
        let mut cache = VertexCache::open(&dir.join(&glb), &CacheOptions::default()).unwrap();
        assert_eq!(Some(cache.fps), info["fps"].as_f64(), "{file}: the file's frame rate");
        let d = farthest(&mut cache, &expected) / diagonal;
        let moved = expected
            .iter()
            .map(|f| f.iter().zip(&expected[0]).map(|(p, q)| (0..3).map(|k| (p[k] - q[k]).abs()).fold(0.0, f64::max)).fold(0.0, f64::max))
            .fold(0.0, f64::max);
        println!(
            "{file} ({writer}): {frames} frames of {vertices} vertices, farthest point {d:.2e} of the diagonal {diagonal:.3} m from Blender 4.2's import (the mesh moves {:.3} of it)",
            moved / diagonal
        );
        assert!(moved > 0.02 * diagonal, "{file}: the mesh really moves");
        assert!(d <= 1e-5, "{file}: {d:.3e} of the diagonal from Blender's import");
    }
    // The FBX SDK's ASCII file (Blender cannot import ASCII FBX): its take animates only a
    // renderer's settings, so the box does not move.
    let fails = |file: &str, message: &str| {
        let line = refused(&dir.path, &samples.join(file).display().to_string(), "", message);
        assert!(line.contains(file), "{file}: {line}");
    };
    fails("box_orphant_embedded_texture.fbx", "mesh \"Box\" does not move in take \"Take 001\"");
    fails("transparentTest.fbx", "ufbx cannot read the FBX file: Not an FBX file");
}

/// Blender's FBX export baked with `method = "spacetime"` through `[cache]`, and the files
/// played back in Blender (its own importers, default settings): the usda and the default
/// (quantized LINEAR) glb play our trajectory at every frame within 1e-5 of the bbox diagonal
/// (the glb plus the quantization error its report states), and the keys are the cache's frames.
#[test]
fn fbx_spacetime_bake_plays_in_blender() {
    let dir = TempDir::new("studio-spacetime");
    blender_exports(&dir.path, 24);
    let text = scene("body.fbx", "").replace("method = \"fit\"", "method = \"spacetime\"");
    std::fs::write(dir.join("scene.toml"), text).unwrap();
    run(&dir.path, &["bake", "scene.toml", "--out", "out", "--quiet"]).success();
    let report = read_json(&dir.join("out/report.json"));
    let c = &report["cache"];
    assert_eq!((c["format"].as_str(), c["frames"].as_u64()), (Some("fbx"), Some(24)), "{c}");
    // Spacetime is physics between the keys, not a fit: the report states how far from the
    // cache it goes; at the keys it is the cache.
    let error = c["error"]["max"].as_f64().unwrap();
    let per_frame = c["error"]["per_frame"].as_array().unwrap();
    for key in c["keys"].as_array().unwrap() {
        let at = per_frame[key.as_u64().unwrap() as usize].as_f64().unwrap();
        assert!(at <= 1e-6, "key frame {key}: {at} from the cache");
    }
    // What the files must play: the library's trajectory of the same scene at every frame.
    let expected = Expected::every_frame(&library_animation(&dir.join("scene.toml")));
    let outputs = output_files(&report["outputs"]);
    // The full-frame glb holds the cache, and its stated error is measured against the cache
    // (not the trajectory, 0.24 of the diagonal away): within its share of the tolerance.
    let full = outputs.iter().find(|f| f.kind == OutputKind::FullFrame && f.format == Format::Glb).expect("a full-frame glb");
    assert!(full.quantization_error.unwrap() <= 0.1 * 0.005 * 1.001, "{}: {:?}", full.path, full.quantization_error);
    assert!(!report["warnings"].to_string().contains("quantization-error"), "{}", report["warnings"]);
    let glb = outputs.iter().find(|f| f.kind == OutputKind::Blendshape && f.format == Format::Glb).expect("a blendshape glb");
    let mut expected_glb = expected.clone();
    expected_glb.tolerance += glb.quantization_error.unwrap_or(0.0) * 1.001;
    let (usda, glb) = (dir.join("out/body.usda"), dir.join("out").join(&glb.path));
    let summary = check_blender(&[(usda.as_path(), &expected), (glb.as_path(), &expected_glb)]);
    for (f, e) in summary["files"].as_array().unwrap().iter().zip([&expected, &expected_glb]) {
        println!(
            "blender {}: max error {} of the bbox diagonal (allowed {:.2e}), {} shape keys",
            f["file"], f["max_error"], e.tolerance, f["shape_keys"]
        );
        assert_eq!(f["ok"], true, "Blender must play {}: {f}", f["file"]);
    }
    println!("body.fbx spacetime: {} keys, cache error max {error}", c["keys"].as_array().unwrap().len());
}
