//! Blender as a consumer: the files a new user bakes, imported into Blender 4.2 (PyPI `bpy`)
//! with its own importers at their default settings, play the animation we computed.
//!
//! For the demo, the paper's DINO walk and a jumping body, baked with the CLI in the four forms
//! (`[export] weights` = bernstein | signed, `gltf_interpolation` = cubicspline | linear):
//! - Blender plays the default (Bernstein) usda and usdc within 1e-5 of the bbox diagonal of
//!   the trajectory at every frame, and the default glb (LINEAR, `KHR_mesh_quantization`) within
//!   1e-5 plus the quantization error the report states for it (`tests/checkers/blender_check.py`);
//! - the two forms it cannot play are caught by the same checker, so it is not vacuous: the
//!   signed usda (Blender clamps shape-key values to [0, 1], the velocity weights go
//!   negative) and the CUBICSPLINE glb (Blender's glTF importer drops the tangents);
//! - every blendshape file of the other forms still passes usd-core (validation, UsdSkel at and
//!   between frames), the Khronos validator and three.js (CUBICSPLINE exact at any instant,
//!   LINEAR at and between frames);
//! - the sizes of both forms are printed, and the Bernstein usdc of the demo stays 5 times
//!   smaller than its full-frame usdc.
//!
//! Units and up axis: a z-up centimetre animation and a y-up one arrive standing up, at the
//! right size, through glTF; through USD they stand up right, and their size is what the
//! pinned Blender does with `metersPerUnit` (4.2 ignores it; 5.0 applies it).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use blendsim::algorithms::blendshape::clip::{BlendShapeClip, Weights};
use blendsim::algorithms::geometry::Point;
use blendsim::pipeline::scene::{Format, SceneFile};
use blendsim::pipeline::stage_file::{Animation, OutputFile, OutputKind};
use blendsim::support::output::Staging;
use serde_json::Value;

use crate::common;
use crate::common::assets::paper_scene;
use crate::common::checkers::{check_blender, Expected};
use crate::common::cli::{read_json, run, TempDir};
use crate::common::verify::{check_outputs, library_animation, output_files};

/// A copy of `scene` in `dir` whose file paths are absolute and whose `[export]` table starts
/// with `export` (TOML lines): the same animation, exported another way.
pub(crate) fn scene_variant(scene: &Path, dir: &Path, name: &str, export: &str) -> PathBuf {
    let text = std::fs::read_to_string(scene).unwrap();
    let folder = scene.parent().unwrap();
    // Every quoted string naming a file beside the scene becomes that file's absolute path.
    let mut out = String::new();
    let mut parts = text.split('"');
    out.push_str(parts.next().unwrap());
    for (i, part) in parts.enumerate() {
        out.push('"');
        let file = folder.join(part);
        if i % 2 == 0 && !part.is_empty() && file.is_file() {
            out.push_str(&file.canonicalize().unwrap().to_string_lossy());
        } else {
            out.push_str(part);
        }
    }
    let out = if out.contains("\n[export]\n") {
        out.replacen("\n[export]\n", &format!("\n[export]\n{export}\n"), 1)
    } else {
        format!("{out}\n[export]\n{export}\n")
    };
    let path = dir.join(format!("{name}.toml"));
    std::fs::write(&path, out).unwrap();
    path
}

/// The four forms of a scene, baked by the CLI: (form, output folder, outputs).
fn bake_forms(dir: &TempDir, scene: &Path) -> Vec<(&'static str, PathBuf, Vec<OutputFile>)> {
    let forms = [
        ("bernstein-cubicspline", "gltf_interpolation = \"cubicspline\""),
        ("bernstein-linear", ""),
        ("signed-cubicspline", "weights = \"signed\"\ngltf_interpolation = \"cubicspline\""),
        ("signed-linear", "weights = \"signed\"\ngltf_interpolation = \"linear\""),
    ];
    forms
        .into_iter()
        .map(|(form, export)| {
            let variant = scene_variant(scene, &dir.path, form, export);
            run(&dir.path, &["bake", "-q", variant.to_str().unwrap(), "--out", form]).success();
            let out = dir.join(form);
            let outputs = output_files(&read_json(&out.join("report.json"))["outputs"]);
            (form, out, outputs)
        })
        .collect()
}

fn size(outputs: &[OutputFile], kind: OutputKind, format: Format) -> u64 {
    outputs.iter().find(|f| f.kind == kind && f.format == format).unwrap_or_else(|| panic!("no {kind:?} {format}")).bytes
}

/// The size table of both forms (usda, usdc, glb cubicspline, glb linear), and the
/// Bernstein/signed usdc ratios against full-frame.
fn print_sizes(name: &str, forms: &[(&str, PathBuf, Vec<OutputFile>)]) -> BTreeMap<&'static str, (u64, u64, u64, u64, u64)> {
    let get = |form: &str| &forms.iter().find(|f| f.0 == form).unwrap().2;
    let kb = |b: u64| format!("{:.1} KB", b as f64 / 1000.0);
    let mut table = BTreeMap::new();
    for weights in ["bernstein", "signed"] {
        let (cubic, linear) = (get(&format!("{weights}-cubicspline")), get(&format!("{weights}-linear")));
        let b = OutputKind::Blendshape;
        let row = (
            size(cubic, b, Format::Usda),
            size(cubic, b, Format::Usdc),
            size(cubic, b, Format::Glb),
            size(linear, b, Format::Glb),
            size(cubic, OutputKind::FullFrame, Format::Usdc),
        );
        eprintln!(
            "{name} {weights:9}: usda {}, usdc {} ({:.1}x smaller than full-frame {}), glb cubicspline {}, glb linear {}",
            kb(row.0),
            kb(row.1),
            row.4 as f64 / row.1 as f64,
            kb(row.4),
            kb(row.2),
            kb(row.3)
        );
        table.insert(weights, row);
    }
    table
}

fn file(forms: &[(&str, PathBuf, Vec<OutputFile>)], form: &str, name: &str) -> PathBuf {
    forms.iter().find(|f| f.0 == form).unwrap().1.join(name)
}

/// Everything the module doc promises, for one scene. Returns the Blender summary.
fn plays_in_blender(scene: &Path, stem: &str) -> Value {
    let dir = TempDir::new(&format!("blender-{stem}"));
    let forms = bake_forms(&dir, scene);
    let anim = library_animation(scene);
    let sizes = print_sizes(stem, &forms);

    // The reference tools, on the blendshape files of every form but the default (which the
    // paper and demo tests check already).
    for (form, out, outputs) in &forms[1..] {
        let mut anim = anim.clone();
        anim.scene.export = SceneFile::load(&dir.join(format!("{form}.toml"))).unwrap().scene.export;
        let blendshapes: Vec<OutputFile> = outputs.iter().filter(|f| f.kind == OutputKind::Blendshape).cloned().collect();
        check_outputs(out, &anim, &blendshapes);
    }

    let expected = Expected::every_frame(&anim);
    // The default glb plays within its stated quantization error (report.json).
    let default_glb = forms[1].2.iter().find(|f| f.kind == OutputKind::Blendshape && f.format == Format::Glb).unwrap();
    let stated = default_glb.quantization_error.expect("the default glb states its quantization error");
    assert!(stated < 0.1 * 0.005 * 1.001, "{stem}: quantization error {stated:e} within a tenth of the tolerance");
    let mut expected_glb = expected.clone();
    expected_glb.tolerance += stated * 1.001;
    let plays = [
        file(&forms, "bernstein-linear", &format!("{stem}.usda")),
        file(&forms, "bernstein-linear", &format!("{stem}.usdc")),
        file(&forms, "bernstein-linear", &format!("{stem}.glb")),
    ];
    let clamped = file(&forms, "signed-cubicspline", &format!("{stem}.usda"));
    let tangents_dropped = file(&forms, "bernstein-cubicspline", &format!("{stem}.glb"));
    let mut all: Vec<(&Path, &Expected)> = plays.iter().zip([&expected, &expected, &expected_glb]).map(|(p, e)| (p.as_path(), e)).collect();
    all.extend([(clamped.as_path(), &expected), (tangents_dropped.as_path(), &expected)]);
    let started = Instant::now();
    let summary = check_blender(&all);
    let seconds = started.elapsed().as_secs_f64();
    let files = summary["files"].as_array().unwrap();
    for f in files {
        eprintln!("blender {}: max error {} of the bbox diagonal, {} shape keys", f["file"], f["max_error"], f["shape_keys"]);
    }
    eprintln!("{stem}: one Blender process for {} files, {seconds:.1} s (exit {})", files.len(), summary["exit"]);
    for (f, e) in files[..3].iter().zip([&expected, &expected, &expected_glb]) {
        assert_eq!(f["ok"], true, "Blender must play {}: {f}", f["file"]);
        assert!(f["max_error"].as_f64().unwrap() < e.tolerance, "{f}");
        let names: Vec<&str> = f["shape_key_names"].as_array().unwrap().iter().map(|n| n.as_str().unwrap()).collect();
        assert!(names.iter().all(|n| *n == "..." || n.starts_with("key_")), "readable shape-key names: {names:?}");
    }
    // The USD importer takes the stage's frame range (time code N is frame N).
    let frames = anim.trajectory.frames(anim.scene.fps);
    assert_eq!(files[0]["frame_range"], serde_json::json!([frames[0].0, frames[frames.len() - 1].0]), "{}", files[0]);
    for (f, why) in [(&files[3], "clamps the signed form's negative weights"), (&files[4], "drops CUBICSPLINE tangents")] {
        assert_eq!(f["ok"], false, "Blender {why}, so the checker must reject {}: {f}", f["file"]);
        assert!(f["max_error"].as_f64().unwrap() > 1e-3, "{f}");
    }

    // The default form's cost: one more shape per key with a velocity.
    let (bernstein, signed) = (sizes["bernstein"], sizes["signed"]);
    assert!(bernstein.1 > signed.1, "the Bernstein form has more shapes: {bernstein:?} vs {signed:?}");
    let clip = BlendShapeClip::new(&anim.trajectory, Weights::Bernstein);
    assert!(clip.targets.iter().all(|t| t.name.starts_with("key_")));
    summary
}

#[test]
fn demo_plays_in_blender_at_default_settings() {
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/demo/twist.toml");
    plays_in_blender(&scene, "twist");
    // The README promises at least 5x for the demo's usdc with the default form.
    let dir = TempDir::new("blender-demo-ratio");
    run(&dir.path, &["bake", "-q", scene.to_str().unwrap(), "--out", "out"]).success();
    let outputs = output_files(&read_json(&dir.join("out/report.json"))["outputs"]);
    let ratio = size(&outputs, OutputKind::FullFrame, Format::Usdc) as f64 / size(&outputs, OutputKind::Blendshape, Format::Usdc) as f64;
    assert!(ratio >= 5.0, "demo usdc: full-frame / blendshape = {ratio:.2}, must stay at least 5x");
}

#[test]
fn dino_plays_in_blender_at_default_settings() {
    let Some(scene) = paper_scene("dino") else { return };
    plays_in_blender(&scene, "dino");
}

/// A character-like body jumping (the case: large velocities, so the signed form's
/// velocity weights go far negative): a 0.6 x 1.8 x 0.6 box crouching, taking off, rising to
/// 1.1 above the ground, landing and recovering, ten OBJ keys over 1.8 s, squashed and
/// stretched at constant volume, every key held, velocities solved under gravity.
fn jump_scene(dir: &Path) -> PathBuf {
    let rest = blendsim::algorithms::procedural::prism([0.6, 1.8, 0.6], [3, 9, 3]);
    // (time, lift, vertical scale)
    let keys = [
        (0.0, 0.0, 1.0),
        (0.25, 0.0, 0.7),
        (0.4, 0.15, 1.25),
        (0.6, 0.8, 1.05),
        (0.8, 1.1, 1.0),
        (1.0, 0.8, 1.05),
        (1.2, 0.15, 1.2),
        (1.35, 0.0, 0.7),
        (1.6, 0.0, 1.1),
        (1.8, 0.0, 1.0),
    ];
    let mut meshes = Vec::new();
    for (k, &(_, lift, squash)) in keys.iter().enumerate() {
        let mut m = rest.clone();
        let wide = 1.0 / f64::sqrt(squash);
        for p in &mut m.positions {
            *p = [0.3 + (p[0] - 0.3) * wide, p[1] * squash + lift, 0.3 + (p[2] - 0.3) * wide];
        }
        std::fs::write(dir.join(format!("jump_{k}.obj")), blendsim::formats::mesh::obj::write(&m)).unwrap();
        meshes.push(format!("\"jump_{k}.obj\""));
    }
    let times: Vec<String> = keys.iter().map(|k| format!("{:?}", k.0)).collect();
    let scene = dir.join("jump.toml");
    std::fs::write(
        &scene,
        format!(
            "name = \"jump\"\nfps = 60\n[keyframes]\nmeshes = [{}]\ntimes = [{}]\n[tet]\nmax_volume = 0.002\n[material]\ngravity = [0.0, -9.8, 0.0]\n[export]\nformats = [\"usda\", \"usdc\", \"glb\"]\n",
            meshes.join(", "),
            times.join(", ")
        ),
    )
    .unwrap();
    scene
}

#[test]
fn jumping_body_plays_in_blender_at_default_settings() {
    let dir = TempDir::new("blender-jump-scene");
    plays_in_blender(&jump_scene(&dir.path), "jump");
}

/// A sideways sway with a lift, z up, in a scene's own units.
fn swaying_column(name: &str, export: &str) -> Animation {
    let mesh = blendsim::algorithms::procedural::prism([1.0, 1.0, 3.0], [2, 2, 6]);
    let motion = |p: Point, t: f64| {
        let (s, c) = ((3.0 * t).sin(), 3.0 * (3.0 * t).cos());
        let h = p[2] / 3.0;
        ([p[0] + 0.5 * h * s, p[1], p[2] + 0.2 * h * s * s], [0.5 * h * c, 0.0, 0.4 * h * s * c])
    };
    let tr = common::sample_motion(&mesh.positions, &[0.0, 0.5, 1.0], motion);
    common::animation(name, 30.0, mesh, tr, false, export)
}

/// glTF: standing up and in meters. USD: standing up, and at the size the pinned Blender
/// gives a `metersPerUnit` stage: 4.2's importer ignores it (the stage arrives in scene
/// units), 5.0.1's applies it (measured by hand with the same checker).
#[test]
fn up_axis_and_units_arrive_in_blender() {
    let dir = common::scratch("blender-units");
    let cases = [("column_z_cm", "up_axis = \"z\"\nmeters_per_unit = 0.01"), ("column_y_mm", "up_axis = \"y\"\nmeters_per_unit = 0.001")];
    let mut files = Vec::new();
    for (name, export) in cases {
        let anim = swaying_column(name, &format!("formats = [\"usda\", \"glb\"]\nfull_frame = false\ngltf_interpolation = \"linear\"\n{export}"));
        let mut staging = Staging::new(&dir.join(name)).unwrap();
        let outputs = blendsim::pipeline::stages::export(&anim, &blendsim::support::budget::Budget::default(), &mut staging).unwrap();
        staging.commit().unwrap();
        let expected = Expected::every_frame(&anim);
        for ext in ["usda", "glb"] {
            let file = format!("{name}.{ext}");
            // The quantized glb (its grid composed with the placement) within its stated error.
            let mut expected = expected.clone();
            expected.tolerance += outputs.files.iter().find(|f| f.path == file).unwrap().quantization_error.unwrap_or(0.0) * 1.001;
            files.push((dir.join(name).join(file), expected, anim.scene.export.meters_per_unit));
        }
    }
    let list: Vec<(&Path, &Expected)> = files.iter().map(|(p, e, _)| (p.as_path(), e)).collect();
    let summary = check_blender(&list);
    let usd_applies_units = !summary["blender"].as_str().unwrap().starts_with("4.2");
    for (f, (path, _, meters)) in summary["files"].as_array().unwrap().iter().zip(&files) {
        eprintln!("{}: max error {}, size {} of the expected, matrix_world {}", f["file"], f["max_error"], f["scale"], f["matrix_world"]);
        if path.extension().unwrap() == "glb" || usd_applies_units {
            assert_eq!(f["ok"], true, "{f}");
        } else {
            let scale = f["scale"].as_f64().unwrap();
            assert!((scale * meters - 1.0).abs() < 1e-6, "Blender 4.2 imports the stage in scene units: {f}");
            assert!(f["unscaled_error"].as_f64().unwrap() < 1e-5, "standing up right and animated right, only the size differs: {f}");
        }
    }
}

/// UVs and material slots read back by Blender: the textured prism of `texture` (a UV seam, two
/// material groups, a PNG per group), baked to usda, usdc and the LINEAR glb and imported at
/// default settings. Against the OBJ itself (not our animation's copy of it): every face
/// corner's UV, the slot names (the OBJ's `usemtl` groups) and each face's material; the glb's
/// seam copies are matched to their points by position (Blender keeps them as vertices).
#[test]
fn uvs_and_material_slots_arrive_in_blender() {
    let dir = TempDir::new("blender-uvs");
    crate::texture::textured_prism(&dir.path, "gltf_interpolation = \"linear\"\nfull_frame = false");
    run(&dir.path, &["bake", "-q", "scene.toml", "--out", "out"]).success();
    let anim = library_animation(&dir.join("scene.toml"));
    let obj = blendsim::formats::mesh::obj::parse(&std::fs::read_to_string(dir.join("rest.obj")).unwrap()).unwrap();
    let a = obj.attributes.as_ref().unwrap();
    let mut expected = Expected::every_frame(&anim);
    expected.corners = Some(
        obj.triangles.iter().zip(&a.uv_corners).map(|(t, c)| [0, 1, 2].map(|k| (t[k], a.uvs[c[k] as usize][0], a.uvs[c[k] as usize][1]))).collect(),
    );
    expected.triangle_materials = Some(a.triangle_groups.iter().map(|&g| a.groups[g as usize].clone()).collect());
    let mut seam_copies = expected.clone();
    seam_copies.map_vertices = Some(true);
    let out = dir.join("out");
    let (usda, usdc, glb) = (out.join("uvprism.usda"), out.join("uvprism.usdc"), out.join("uvprism.glb"));
    let summary = check_blender(&[(&usda, &expected), (&usdc, &expected), (&glb, &seam_copies)]);
    for f in summary["files"].as_array().unwrap() {
        eprintln!(
            "blender {}: max error {}, {} vertices, UV layers {}, UV error {}, slots {}, faces with another material {}",
            f["file"], f["max_error"], f["vertices"], f["uv_layers"], f["uv_error"], f["material_slots"], f["faces_wrong_material"]
        );
        assert_eq!(f["ok"], true, "{f}");
        assert_eq!(f["faces"], obj.triangles.len(), "{f}");
    }
}
