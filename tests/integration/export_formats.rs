//! `export` end to end: synthetic animations go through `stages::export`, and every file it
//! writes is opened by the reference tools (usd-core, the Khronos glTF validator, three.js,
//! Chromium) and evaluated against our own evaluation of the same animation.

use std::collections::BTreeSet;
use std::f64::consts::PI;
use std::path::{Path, PathBuf};

use blendsim::algorithms::blendshape::clip::{BlendShapeClip, Weights};
use blendsim::algorithms::geometry::Point;
use blendsim::algorithms::procedural::prism as box_mesh;
use blendsim::pipeline::scene::Format;
use blendsim::pipeline::stage_file::{Animation, OutputKind, Outputs};
use blendsim::pipeline::stages::export;
use blendsim::support::output::Staging;

use crate::common::checkers::{check_babylon, render_glb, try_check_glb, try_check_usd, Expected};
use crate::common::{animation, sample_motion, scratch};

/// A twist about the box's vertical (y) axis: the angle grows with height above `from` (a
/// fraction of the height) and with `s(t)`; `ds` is `s'(t)`. Returns the position and its
/// exact velocity.
fn twist(size: [f64; 3], degrees: f64, from: f64, s: impl Fn(f64) -> f64, ds: impl Fn(f64) -> f64) -> impl Fn(Point, f64) -> (Point, Point) {
    move |p, t| {
        let reach = ((p[1] / size[1] - from) / (1.0 - from)).max(0.0);
        let amount = degrees.to_radians() * reach;
        let (theta, dtheta) = (amount * s(t), amount * ds(t));
        let (x, z) = (p[0] - size[0] / 2.0, p[2] - size[2] / 2.0);
        let (sin, cos) = theta.sin_cos();
        // A little vertical breathing too, so y moves as well.
        let lift = 0.1 * reach * s(t);
        let position = [size[0] / 2.0 + x * cos - z * sin, p[1] + lift, size[2] / 2.0 + x * sin + z * cos];
        let velocity = [-(x * sin + z * cos) * dtheta, 0.1 * reach * ds(t), (x * cos - z * sin) * dtheta];
        (position, velocity)
    }
}

const SIZE: [f64; 3] = [1.0, 2.0, 1.0];

/// The twisting box: four uneven keys over 2 s, real velocities, y up in meters.
fn twisting_box(formats: &str) -> Animation {
    let mesh = box_mesh(SIZE, [4, 8, 4]);
    let w = PI / 2.4;
    let tr = sample_motion(&mesh.positions, &[0.0, 0.6, 1.3, 2.0], twist(SIZE, 120.0, 0.0, |t| (w * t).sin(), |t| w * (w * t).cos()));
    animation("twist-box", 60.0, mesh, tr, false, &format!("formats = {formats}"))
}

/// One full twist back and forth in 1 s; the last key repeats the first exactly. Z up, in
/// centimeters, at 24 fps.
fn cyclic_box(formats: &str) -> Animation {
    let mesh = box_mesh(SIZE, [3, 6, 3]);
    let w = 2.0 * PI;
    let mut tr = sample_motion(&mesh.positions, &[0.0, 0.3, 0.65, 1.0], twist(SIZE, 60.0, 0.0, |t| (w * t).sin(), |t| w * (w * t).cos()));
    let last = tr.key_count() - 1;
    tr.positions[last] = tr.positions[0].clone();
    tr.velocities[last] = tr.velocities[0].clone();
    animation("cyclic", 24.0, mesh, tr, true, &format!("formats = {formats}\nup_axis = \"z\"\nmeters_per_unit = 0.01"))
}

/// Only the top quarter of the box moves, so every target is sparse. Keys start at 0.5 s.
fn waving_top(formats: &str) -> Animation {
    let mesh = box_mesh(SIZE, [4, 8, 4]);
    let tr = sample_motion(&mesh.positions, &[0.5, 1.0, 1.75], twist(SIZE, 90.0, 0.75, |t| (3.0 * t).sin(), |t| 3.0 * (3.0 * t).cos()));
    animation("waving_top", 30.0, mesh, tr, false, &format!("formats = {formats}"))
}

/// Nothing moves: zero targets.
fn still_box(formats: &str) -> Animation {
    let mesh = box_mesh(SIZE, [2, 2, 2]);
    let tr = sample_motion(&mesh.positions, &[0.0, 1.0], |p, _| (p, [0.0; 3]));
    animation("still", 60.0, mesh, tr, false, &format!("formats = {formats}"))
}

fn export_to(anim: &Animation, dir: &Path) -> Outputs {
    let mut staging = Staging::new(dir).unwrap();
    let outputs = export(anim, &blendsim::support::budget::Budget::default(), &mut staging).unwrap();
    staging.commit().unwrap();
    outputs
}

/// Export, then check every file with the independent checkers against our own evaluation:
/// the blendshape clip's exact curves (glTF) or its per-frame samples (USD), the trajectory
/// at frames for full-frame files. Returns the output folder and the outputs.
fn export_and_check(anim: &Animation) -> (PathBuf, Outputs) {
    let dir = scratch(&anim.scene.name).join("out");
    let outputs = export_to(anim, &dir);
    let mut listed: BTreeSet<String> = outputs.files.iter().map(|f| f.path.clone()).collect();
    listed.insert(blendsim::support::output::MANIFEST.to_string());
    let on_disk: BTreeSet<String> = std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    assert_eq!(listed, on_disk, "the folder holds exactly the listed files and the manifest");
    crate::common::verify::check_outputs(&dir, anim, &outputs.files);
    (dir, outputs)
}

fn names(outputs: &Outputs) -> Vec<&str> {
    outputs.files.iter().map(|f| f.path.as_str()).collect()
}

#[test]
fn twisting_box_in_every_format() {
    let (_, outputs) = export_and_check(&twisting_box("[\"glb\", \"usdc\", \"usda\"]"));
    assert_eq!(
        names(&outputs),
        ["twist-box.usda", "twist-box.usdc", "twist-box.glb", "twist-box.full.usda", "twist-box.full.usdc", "twist-box.full.glb"]
    );
}

/// The other forms: signed weights, CUBICSPLINE weight keys, meshopt and f32 glTF.
#[test]
fn signed_weights_and_linear_gltf_in_every_format() {
    for export in [
        "weights = \"signed\"",
        "gltf_interpolation = \"cubicspline\"",
        "weights = \"signed\"\ngltf_interpolation = \"cubicspline\"",
        "gltf_compression = \"meshopt\"",
        "gltf_compression = \"meshopt\"\ngltf_interpolation = \"cubicspline\"",
        "gltf_compression = \"none\"",
    ] {
        let anim = cyclic_box(&format!("[\"usda\", \"usdc\", \"glb\"]\n{export}"));
        let (_, outputs) = export_and_check(&anim);
        assert_eq!(outputs.files.len(), 6, "{export}");
    }
}

/// The default glb (LINEAR weights per frame, `KHR_mesh_quantization`) and its full-frame file
/// play in Babylon.js within the quantization error the export states for them (read back from
/// the file), z up in centimetres: the quantization grid composes with the placement. The
/// tolerance is a tenth of 0.005 of the diagonal, and the files meet it.
#[test]
fn default_glb_plays_in_babylon_within_its_stated_error() {
    use crate::common::verify::{frames_and_midpoints, sampled_points};
    let anim = cyclic_box("[\"glb\"]");
    let (dir, outputs) = export_and_check(&anim);
    let fps = anim.scene.fps;
    let frames: Vec<f64> = anim.trajectory.frames(fps).iter().map(|f| f.1).collect();
    let clip = BlendShapeClip::new(&anim.trajectory, anim.scene.export.weights);
    for f in &outputs.files {
        let bytes = std::fs::read(dir.join(&f.path)).unwrap();
        assert!(bytes.windows(21).any(|w| w == b"KHR_mesh_quantization"), "{}: quantized by default", f.path);
        let stated = f.quantization_error.unwrap();
        assert!(stated > 0.0 && stated <= 0.1 * 0.005 * 1.001, "{}: quantization error {stated:e}", f.path);
        let mut e = match f.kind {
            OutputKind::FullFrame => Expected::at(&frames, fps, |t| anim.trajectory.evaluate(t)),
            OutputKind::Blendshape => Expected::at(&frames_and_midpoints(&frames), fps, |t| sampled_points(&clip, &frames, t)),
        };
        e.up_axis = Some("z".into());
        e.meters_per_unit = Some(anim.scene.export.meters_per_unit);
        e.tolerance += stated * 1.001;
        let summary = check_babylon(&dir.join(&f.path), &e);
        eprintln!("{}: stated {stated:.2e}, Babylon.js {summary}", f.path);
        assert_eq!(summary["ok"], true, "{}: {summary}", f.path);
    }
}

#[test]
fn cyclic_z_up_centimeters_without_usda() {
    let (_, outputs) = export_and_check(&cyclic_box("[\"usdc\", \"glb\"]"));
    // No .usda is written or left behind when only usdc is asked for.
    assert_eq!(names(&outputs), ["cyclic.usdc", "cyclic.glb", "cyclic.full.usdc", "cyclic.full.glb"]);
}

#[test]
fn sparse_targets_stay_sparse() {
    let anim = waving_top("[\"usda\", \"glb\"]");
    let clip = BlendShapeClip::new(&anim.trajectory, Weights::Bernstein);
    let n = clip.vertex_count();
    assert!(clip.targets.iter().all(|t| 4 * t.indices.len() < 3 * n), "the test needs sparse targets");
    let (dir, _) = export_and_check(&anim);
    let usda = std::fs::read_to_string(dir.join("waving_top.usda")).unwrap();
    assert_eq!(usda.matches("uniform int[] pointIndices").count(), clip.targets.len(), "every BlendShape is sparse");
    // The USD file starts at the first key's frame.
    assert!(usda.contains("    startTimeCode = 15\n") && usda.contains("    endTimeCode = 52\n"), "{}", &usda[..400]);
}

#[test]
fn a_static_animation_still_validates() {
    let anim = still_box("[\"usda\", \"usdc\", \"glb\"]");
    assert!(BlendShapeClip::new(&anim.trajectory, anim.scene.export.weights).targets.is_empty());
    export_and_check(&anim);
}

#[test]
fn export_is_deterministic() {
    let anim = cyclic_box("[\"usda\", \"usdc\", \"glb\"]");
    let (a, b) = (scratch("det-a").join("out"), scratch("det-b").join("out"));
    let (oa, ob) = (export_to(&anim, &a), export_to(&anim, &b));
    assert_eq!(oa, ob);
    for f in &oa.files {
        assert!(std::fs::read(a.join(&f.path)).unwrap() == std::fs::read(b.join(&f.path)).unwrap(), "{} differs between runs", f.path);
    }
}

#[test]
fn blendshapes_are_smaller_than_full_frame() {
    // About 1,000 vertices, 2 s at 60 fps.
    let mesh = box_mesh(SIZE, [10, 20, 10]);
    let w = PI / 2.4;
    let tr = sample_motion(&mesh.positions, &[0.0, 0.7, 1.4, 2.0], twist(SIZE, 120.0, 0.0, |t| (w * t).sin(), |t| w * (w * t).cos()));
    let anim = animation("sizes", 60.0, mesh, tr, false, "formats = [\"usda\", \"usdc\", \"glb\"]");
    let outputs = export_to(&anim, &scratch("sizes").join("out"));
    let size = |kind: OutputKind, format: Format| outputs.files.iter().find(|f| f.kind == kind && f.format == format).unwrap().bytes;
    for format in [Format::Usda, Format::Usdc, Format::Glb] {
        let (blend, full) = (size(OutputKind::Blendshape, format), size(OutputKind::FullFrame, format));
        eprintln!("{format}: blendshapes {blend} bytes, full-frame {full} bytes ({:.1}x smaller)", full as f64 / blend as f64);
        assert!(blend * 5 < full, "{format}: blendshapes {blend} bytes should be far smaller than full-frame {full} bytes");
    }
}

#[test]
fn renders_and_moves_in_chromium() {
    let anim = twisting_box("[\"glb\"]");
    let mut anim = anim;
    anim.scene.export.full_frame = false;
    let dir = scratch("render");
    let outputs = export_to(&anim, &dir.join("out"));
    assert_eq!(names(&outputs), ["twist-box.glb"]);
    let summary = render_glb(&dir.join("out/twist-box.glb"), &dir.join("png"), Some([0.0, 1.0]));
    eprintln!("{summary}");
    assert_eq!(summary["ok"], true, "{summary}");
    for png in summary["screenshots"].as_array().unwrap() {
        let bytes = std::fs::read(png.as_str().unwrap()).unwrap();
        assert_eq!(&bytes[1..4], b"PNG");
    }
}

#[test]
fn a_broken_animation_is_a_one_line_error_and_stages_nothing() {
    let mut anim = still_box("[\"usda\", \"glb\"]");
    anim.trajectory.positions[1].pop();
    let dir = scratch("broken");
    let mut staging = Staging::new(&dir.join("out")).unwrap();
    let e = export(&anim, &blendsim::support::budget::Budget::default(), &mut staging).unwrap_err().to_string();
    assert!(e.contains("key 1 has 25 positions but the mesh has 26 vertices"), "{e}");
    assert!(e.contains("(fix: re-run `blendsim embed`"), "{e}");
    assert!(!e.contains('\n'));
    drop(staging);
    assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 0);

    // Keys from 10 ms to 15 ms hold no frame at 60 fps.
    let mut anim = still_box("[\"usda\"]");
    anim.trajectory.times = vec![0.010, 0.015];
    let mut staging = Staging::new(&dir.join("out")).unwrap();
    let e = export(&anim, &blendsim::support::budget::Budget::default(), &mut staging).unwrap_err().to_string();
    assert!(e.contains("between two frames at 60 fps (fix: "), "{e}");
}

/// The checkers are not vacuous: wrong points, a Skeleton without SkelBindingAPI and a wrong
/// channel path all fail.
#[test]
fn checkers_reject_wrong_points_and_broken_files() {
    let anim = twisting_box("[\"usda\", \"glb\"]");
    let mut anim = anim;
    anim.scene.export.full_frame = false;
    let dir = scratch("negative").join("out");
    export_to(&anim, &dir);
    let clip = BlendShapeClip::new(&anim.trajectory, anim.scene.export.weights);
    let frames: Vec<f64> = anim.trajectory.frames(60.0).iter().map(|f| f.1).collect();
    // Expected one frame late.
    let late = Expected::at(&frames, 60.0, |t| clip.points_at(t + 1.0 / 60.0));
    let e = try_check_usd(&dir.join("twist-box.usda"), &late, false).unwrap_err();
    assert!(e.contains("max error"), "{e}");
    let e = try_check_glb(&dir.join("twist-box.glb"), &late).unwrap_err();
    assert!(e.contains("max error"), "{e}");

    let right = Expected::at(&frames, 60.0, |t| clip.points_at(t));
    let usda = std::fs::read_to_string(dir.join("twist-box.usda")).unwrap();
    let skeleton = usda.find("def Skeleton").unwrap();
    let broken =
        format!("{}{}", &usda[..skeleton], usda[skeleton..].replacen("(\n        prepend apiSchemas = [\"SkelBindingAPI\"]\n    )\n", "", 1));
    std::fs::write(dir.join("broken.usda"), broken).unwrap();
    let e = try_check_usd(&dir.join("broken.usda"), &right, false).unwrap_err();
    assert!(e.contains("MissingSkelBindingAPI"), "{e}");

    let glb = std::fs::read(dir.join("twist-box.glb")).unwrap();
    let at = glb.windows(16).position(|w| w == b"\"path\":\"weights\"").unwrap();
    let mut broken = glb.clone();
    broken[at..at + 16].copy_from_slice(b"\"path\":\"weightz\"");
    std::fs::write(dir.join("broken.glb"), broken).unwrap();
    let e = try_check_glb(&dir.join("broken.glb"), &right).unwrap_err();
    assert!(e.contains("VALUE_NOT_IN_LIST"), "{e}");
}

/// The tetrahedron of `formats/usd.md` and `formats/gltf.md`: its top vertex rises by 0.5 in
/// 0.5 s while the whole shape starts with a sideways velocity of 0.5 units/s; z up, 4 fps.
fn tetra(export: &str) -> Animation {
    let positions = vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    let mesh = blendsim::algorithms::geometry::TriMesh {
        positions: positions.clone(),
        triangles: vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
        attributes: None,
    };
    let mut risen = positions.clone();
    risen[3][2] += 0.5;
    let tr = blendsim::algorithms::spacetime::trajectory::Trajectory {
        times: vec![0.0, 0.5],
        positions: vec![positions, risen],
        velocities: vec![vec![[0.5, 0.0, 0.0]; 4], vec![[0.0; 3]; 4]],
    };
    animation("tetra", 4.0, mesh, tr, false, &format!("formats = [\"usda\", \"glb\"]\nup_axis = \"z\"\n{export}"))
}

/// The fenced block of `doc` that follows the line containing `after`.
fn block_after<'a>(doc: &'a str, after: &str) -> &'a str {
    let at = doc.find(after).unwrap_or_else(|| panic!("no {after:?} in the doc"));
    let start = at + doc[at..].find("```").unwrap();
    let start = start + doc[start..].find('\n').unwrap() + 1;
    &doc[start..start + doc[start..].find("```").unwrap()]
}

/// The examples in the format documents are this version's real output, byte for byte (USD)
/// and value for value (the glTF JSON), and the sizes they state are the files' sizes.
#[test]
fn format_documents_show_real_output() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let usd_doc = std::fs::read_to_string(root.join("formats/usd.md")).unwrap();
    let gltf_doc = std::fs::read_to_string(root.join("formats/gltf.md")).unwrap();
    let (dir, outputs) = export_and_check(&tetra("gltf_interpolation = \"cubicspline\"\ngltf_compression = \"none\""));
    let read = |name: &str| std::fs::read(dir.join(name)).unwrap();
    for name in ["tetra.usda", "tetra.full.usda"] {
        let text = String::from_utf8(read(name)).unwrap();
        assert_eq!(block_after(&usd_doc, &format!("`{name}` (")), text, "formats/usd.md's {name} is not the current output");
        let stated = format!("`{name}` ({} bytes", fmt_thousands(text.len()));
        assert!(usd_doc.contains(&stated), "formats/usd.md must state {stated}");
    }
    let glb = read("tetra.glb");
    let json_len = u32::from_le_bytes(glb[12..16].try_into().unwrap()) as usize;
    let actual: serde_json::Value = serde_json::from_slice(&glb[20..20 + json_len]).unwrap();
    let documented: serde_json::Value = serde_json::from_str(block_after(&gltf_doc, "Its JSON chunk, pretty-printed")).unwrap();
    assert_eq!(documented, actual, "formats/gltf.md's JSON chunk is not the current output");
    for name in ["tetra.glb", "tetra.full.glb"] {
        let bytes = outputs.files.iter().find(|f| f.path == name).unwrap().bytes as usize;
        let stated = format!("`{name}` ({} bytes", fmt_thousands(bytes));
        assert!(
            gltf_doc.contains(&stated) || gltf_doc.contains(&format!("`{name}` is {} bytes", fmt_thousands(bytes))),
            "formats/gltf.md must state the size of {name}: {bytes}"
        );
    }
}

fn fmt_thousands(n: usize) -> String {
    let s = n.to_string();
    let mut out = String::new();
    for (i, c) in s.chars().enumerate() {
        if i > 0 && (s.len() - i).is_multiple_of(3) {
            out.push(',');
        }
        out.push(c);
    }
    out
}
