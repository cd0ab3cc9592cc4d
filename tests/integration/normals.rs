//! Animated normals, measured: how far from the true normals of the animated surface each way
//! a consumer can get its normals is, and what morph-target NORMAL deltas would cost.
//!
//! `cargo test --release --test integration normals:: -- --nocapture` prints the table in the
//! README. At every frame, for every vertex (every split vertex where the surface has normal
//! creases), the angle between the true normal and:
//! - (a) the rest normals (the file's `NORMAL`: the OBJ's `vn`, or recomputed at the base
//!   pose), which is what a renderer shows when the file has no morph-target normals
//!   (three.js, engines: morphing moves positions only);
//! - (b) normals recomputed from the morphed positions on the file's vertices (three.js's
//!   `computeVertexNormals` on the glb's split vertices: area weighted, each seam copy seeing
//!   only its own triangles; Blender recomputes on its welded mesh, which is the truth);
//! - (c) glTF morph-target NORMAL deltas (each target's recomputed normals minus the base's),
//!   added to (a) with the frame's weights and renormalized, as a shader does.
//!
//! The true normal is the area-weighted normal of the surface at that frame, over the corners
//! that share a rest normal (smooth across the surface, creased where the OBJ's `vn` crease):
//! what three.js computes on a welded mesh. (On the prism its fanned quads weigh a vertex's two
//! side faces unequally, so even at rest it is up to 7.9 degrees from the OBJ's radial `vn`.)

use std::path::Path;

use blendsim::algorithms::blendshape::clip::BlendShapeClip;
use blendsim::algorithms::geometry::attributes::split_at_seams;
use blendsim::algorithms::geometry::{cross, norm, sub, Point};
use blendsim::pipeline::stage_file::Animation;

use blendsim::pipeline::stage_file::OutputKind;
use serde_json::Value;

use crate::attributes::Glb;
use crate::common::assets::paper_scene;
use crate::common::cli::{read_json, run, TempDir};
use crate::common::verify::{check_outputs, library_animation, output_files};

/// Area-weighted normals of `triangles` over `vertices` (unit; zero where no area).
fn normals(points: &[Point], triangles: &[[u32; 3]], sources: &[u32]) -> Vec<Point> {
    let mut n = vec![[0.0; 3]; sources.len()];
    for t in triangles {
        let p = t.map(|i| points[sources[i as usize] as usize]);
        let f = cross(sub(p[1], p[0]), sub(p[2], p[0]));
        for &i in t {
            let x = &mut n[i as usize];
            *x = [x[0] + f[0], x[1] + f[1], x[2] + f[2]];
        }
    }
    n.iter().map(|x| unit(*x)).collect()
}

fn unit(x: Point) -> Point {
    let l = norm(x);
    if l > 0.0 {
        x.map(|c| c / l)
    } else {
        x
    }
}

fn degrees(a: Point, b: Point) -> f64 {
    (a[0] * b[0] + a[1] * b[1] + a[2] * b[2]).clamp(-1.0, 1.0).acos().to_degrees()
}

/// Angle errors in degrees: (max, 99th percentile, mean).
fn stats(mut e: Vec<f64>) -> (f64, f64, f64) {
    e.sort_by(f64::total_cmp);
    let mean = e.iter().sum::<f64>() / e.len() as f64;
    (*e.last().unwrap(), e[(e.len() - 1) * 99 / 100], mean)
}

/// One row: errors of (a), (b), (c), and the bytes of NORMAL deltas against the glb's.
struct Row {
    name: String,
    rest: (f64, f64, f64),
    recomputed: (f64, f64, f64),
    morph: (f64, f64, f64),
    delta_bytes: usize,
    position_bytes: usize,
}

/// The rest normals on the file's vertices and, per target, the change of every vertex's
/// normal from the base's to the target shape's (both recomputed): NORMAL morph deltas.
fn rest_and_deltas(clip: &BlendShapeClip, triangles: &[[u32; 3]], sources: &[u32]) -> (Vec<Point>, Vec<Vec<Point>>) {
    let base: Vec<Point> = clip.base.iter().map(|p| p.map(f64::from)).collect();
    let rest = normals(&base, triangles, sources);
    let deltas = clip
        .targets
        .iter()
        .map(|t| {
            let mut shape = base.clone();
            for (&i, o) in t.indices.iter().zip(&t.offsets) {
                shape[i as usize] = [shape[i as usize][0] + o[0] as f64, shape[i as usize][1] + o[1] as f64, shape[i as usize][2] + o[2] as f64];
            }
            normals(&shape, triangles, sources).iter().zip(&rest).map(|(a, b)| sub(*a, *b)).collect()
        })
        .collect();
    (rest, deltas)
}

fn measure(name: &str, anim: &Animation) -> Row {
    let mesh = &anim.mesh;
    let n = mesh.positions.len();
    let attributes = mesh.attributes.clone().unwrap_or_default();
    let identity: Vec<u32> = (0..n as u32).collect();
    // The truth's vertices: split where the OBJ's normals crease (not at UV seams).
    let creases = blendsim::algorithms::geometry::attributes::CornerAttributes { uvs: vec![], uv_corners: vec![], ..attributes.clone() };
    let truth_split = if creases.normal_corners.is_empty() { None } else { Some(split_at_seams(&mesh.triangles, n, &creases)) };
    let (truth_tris, truth_sources) = truth_split.as_ref().map_or((&mesh.triangles, &identity), |s| (&s.triangles, &s.sources));
    // The glb's vertices: split at UV and normal seams.
    let file_split =
        (!attributes.uv_corners.is_empty() || !attributes.normal_corners.is_empty()).then(|| split_at_seams(&mesh.triangles, n, &attributes));
    let (file_tris, file_sources) = file_split.as_ref().map_or((&mesh.triangles, &identity), |s| (&s.triangles, &s.sources));
    // Each file vertex's truth vertex: the truth split's copy with the same point and normal.
    let truth_of: Vec<usize> = {
        let mut at = vec![usize::MAX; file_sources.len()];
        for (ft, tt) in file_tris.iter().zip(truth_tris.iter()) {
            for k in 0..3 {
                at[ft[k] as usize] = tt[k] as usize;
            }
        }
        at
    };

    let clip = BlendShapeClip::new(&anim.trajectory, anim.scene.export.weights);
    let (recomputed_rest, deltas) = rest_and_deltas(&clip, file_tris, file_sources);
    // The file's NORMALs: the OBJ's `vn` when it has them, else recomputed (as the writer does).
    let rest: Vec<Point> = match file_split.as_ref().and_then(|s| s.normals.as_ref()) {
        Some(n) => n.iter().map(|x| unit(*x)).collect(),
        None => recomputed_rest,
    };
    // glTF stores a delta target like a position target: sparse when smaller (u16 indices).
    let target_bytes = |moved: usize| if moved * 14 < 12 * file_sources.len() { moved * 14 } else { 12 * file_sources.len() };
    let delta_bytes: usize = deltas.iter().map(|d| target_bytes(d.iter().filter(|x| **x != [0.0; 3]).count())).sum();
    let position_bytes: usize = clip.targets.iter().map(|t| target_bytes(t.indices.len())).sum();

    let (mut ea, mut eb, mut ec) = (Vec::new(), Vec::new(), Vec::new());
    for (_, t) in anim.trajectory.frames(anim.scene.fps) {
        let points = anim.trajectory.evaluate(t);
        let truth = normals(&points, truth_tris, truth_sources);
        let recomputed = normals(&points, file_tris, file_sources);
        let w = clip.weights_at(t);
        for v in 0..file_sources.len() {
            let truth = truth[truth_of[v]];
            ea.push(degrees(rest[v], truth));
            eb.push(degrees(recomputed[v], truth));
            let mut m = rest[v];
            for (d, &wi) in deltas.iter().zip(&w) {
                m = [m[0] + wi * d[v][0], m[1] + wi * d[v][1], m[2] + wi * d[v][2]];
            }
            ec.push(degrees(unit(m), truth));
        }
    }
    Row { name: name.into(), rest: stats(ea), recomputed: stats(eb), morph: stats(ec), delta_bytes, position_bytes }
}

#[test]
fn animated_normals_error_table() {
    let mut rows = Vec::new();
    let demo = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/demo/twist.toml");
    rows.push(measure("demo (twist)", &library_animation(&demo)));
    if let Some(dino) = paper_scene("dino") {
        rows.push(measure("DINO (paper)", &library_animation(&dino)));
    }
    let dir = TempDir::new("normals-prism");
    crate::texture::textured_prism(&dir.path, "");
    rows.push(measure("textured prism (seams, creases)", &library_animation(&dir.join("scene.toml"))));
    let f = |s: (f64, f64, f64)| format!("{:.2} / {:.2} / {:.3}", s.0, s.1, s.2);
    eprintln!(
        "| scene | (a) rest normals | (b) recomputed on the file's vertices | (c) morph NORMAL deltas | NORMAL deltas vs POSITION targets (bytes) |"
    );
    eprintln!("|---|---|---|---|---|");
    for r in &rows {
        eprintln!(
            "| {} | {} | {} | {} | {:.1} KB vs {:.1} KB (+{:.0}%) |",
            r.name,
            f(r.rest),
            f(r.recomputed),
            f(r.morph),
            r.delta_bytes as f64 / 1000.0,
            r.position_bytes as f64 / 1000.0,
            100.0 * r.delta_bytes as f64 / r.position_bytes as f64
        );
    }
    for r in &rows {
        // The morph blend is a first-order approximation: it must not be worse than ignoring
        // the motion on average. (Recomputing on split vertices can be: seam copies see half
        // their triangles, the prism's row.)
        assert!(r.morph.2 <= r.rest.2 + 1e-9, "{}: morph deltas {:?} vs rest {:?}", r.name, r.morph, r.rest);
    }
    assert!(rows[0].morph.2 < 0.25 * rows[0].rest.2, "the demo's twist: NORMAL deltas cut the mean error at least 4x");
    assert!(rows[0].recomputed.0 < 1e-3, "no seams in the demo: recomputing is the truth (to acos's precision, in degrees)");
}

/// A glb accessor's vec3 values, dense or sparse (zeros where a sparse accessor has no entry).
fn vec3s(glb: &Glb, a: u64) -> Vec<[f32; 3]> {
    let acc = &glb.json["accessors"][a as usize];
    let count = acc["count"].as_u64().unwrap() as usize;
    let mut out = if acc["bufferView"].is_u64() { glb.floats(a, 3).chunks(3).map(|c| [c[0], c[1], c[2]]).collect() } else { vec![[0.0; 3]; count] };
    if let Some(sparse) = acc.get("sparse") {
        let at = |part: &Value| {
            let view = &glb.json["bufferViews"][part["bufferView"].as_u64().unwrap() as usize];
            view["byteOffset"].as_u64().unwrap_or(0) as usize + part["byteOffset"].as_u64().unwrap_or(0) as usize
        };
        let (i0, v0) = (at(&sparse["indices"]), at(&sparse["values"]));
        let size = match sparse["indices"]["componentType"].as_u64().unwrap() {
            5121 => 1,
            5123 => 2,
            _ => 4,
        };
        for k in 0..sparse["count"].as_u64().unwrap() as usize {
            let b = &glb.bin[i0 + k * size..i0 + (k + 1) * size];
            let i = match size {
                1 => b[0] as usize,
                2 => u16::from_le_bytes([b[0], b[1]]) as usize,
                _ => u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize,
            };
            let f = |c: usize| f32::from_le_bytes(glb.bin[v0 + 12 * k + 4 * c..v0 + 12 * k + 4 * c + 4].try_into().unwrap());
            out[i] = [f(0), f(1), f(2)];
        }
    }
    out
}

/// `[export] gltf_morph_normals = true`: every morph target of the blendshape glb carries the
/// NORMAL deltas measured above (read back from the file, dense or sparse), the base gets
/// NORMALs when the OBJ has none, the validator and three.js accept the file, and the
/// full-frame glb is unchanged. Prints the size cost.
#[test]
fn morph_normals_in_the_glb_are_the_measured_deltas() {
    let dir = TempDir::new("normals-morph");
    crate::texture::textured_prism(&dir.path, "gltf_morph_normals = true");
    let demo = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/demo/twist.toml");
    crate::blender::scene_variant(&demo, &dir.path, "twist", "gltf_morph_normals = true");
    for scene in ["scene.toml", "twist.toml"] {
        let out_name = format!("out-{}", scene.trim_end_matches(".toml"));
        run(&dir.path, &["bake", "-q", scene, "--out", &out_name]).success();
        let out = dir.join(&out_name);
        let outputs = output_files(&read_json(&out.join("report.json"))["outputs"]);
        let anim = library_animation(&dir.join(scene));
        assert!(anim.scene.export.gltf_morph_normals);
        check_outputs(&out, &anim, &outputs);
        let glb_file = outputs.iter().find(|f| f.kind == OutputKind::Blendshape && f.path.ends_with(".glb")).unwrap();
        let glb = Glb::parse(&std::fs::read(out.join(&glb_file.path)).unwrap());
        let primitive = &glb.json["meshes"][0]["primitives"][0];
        let n = anim.mesh.positions.len() as u32;
        let sources: Vec<u32> = (0..n)
            .chain(
                glb.json["meshes"][0]["extras"]["seamSources"].as_array().map_or(vec![], |a| a.iter().map(|x| x.as_u64().unwrap() as u32).collect()),
            )
            .collect();
        let attributes = anim.mesh.attributes.clone().unwrap_or_default();
        let triangles = if sources.len() as u32 == n {
            anim.mesh.triangles.clone()
        } else {
            split_at_seams(&anim.mesh.triangles, n as usize, &attributes).triangles
        };
        let clip = BlendShapeClip::new(&anim.trajectory, anim.scene.export.weights);
        let (_, deltas) = rest_and_deltas(&clip, &triangles, &sources);
        assert!(primitive["attributes"]["NORMAL"].is_u64(), "{scene}: the base has NORMALs");
        let targets = primitive["targets"].as_array().unwrap();
        assert_eq!(targets.len(), deltas.len());
        let mut worst = 0.0f64;
        for (t, d) in targets.iter().zip(&deltas) {
            let got = vec3s(&glb, t["NORMAL"].as_u64().expect("a NORMAL delta per target"));
            assert_eq!(got.len(), d.len());
            for (g, w) in got.iter().zip(d) {
                worst = worst.max((0..3).map(|k| (g[k] as f64 - w[k]).abs()).fold(0.0, f64::max));
            }
        }
        assert!(worst < 1e-6, "{scene}: the file's NORMAL deltas are the measured ones (max difference {worst})");
        let full = outputs.iter().find(|f| f.kind == OutputKind::FullFrame && f.path.ends_with(".glb")).unwrap();
        let full_glb = Glb::parse(&std::fs::read(out.join(&full.path)).unwrap());
        assert!(full_glb.json["meshes"][0]["primitives"][0]["targets"][0].get("NORMAL").is_none(), "full-frame files are unchanged");
        let size = |morph_normals| {
            let surface = blendsim::formats::export::glb::Surface {
                triangles: &anim.mesh.triangles,
                attributes: anim.mesh.attributes.as_ref(),
                textures: &[],
                morph_normals,
                weld_map: None,
            };
            blendsim::formats::export::glb::blendshapes(
                &clip,
                surface,
                "x",
                blendsim::formats::export::glb::Placement { z_up: false, meters_per_unit: 1.0 },
                blendsim::formats::export::glb::Encoding::FLOAT,
            )
            .len() as f64
                / 1000.0
        };
        eprintln!("{scene}: blendshape glb {:.1} KB with NORMAL deltas, {:.1} KB without (texture not embedded)", size(true), size(false));
    }
}

/// `gltf_check.mjs` reports max_error 0 on the blendshape glb (with or without NORMAL deltas):
/// three.js and `BlendShapeClip::points_at` evaluate the same stored f32 base, deltas and
/// CUBICSPLINE weight keys with the same f64 arithmetic (glTF's Hermite basis), so they agree to
/// the bit at every time, not only at keys. That the comparison measures something: the
/// animation moves at the checked times, and the same file with every weight key scaled by
/// (1 + 1e-6) gives a small nonzero error (under the 1e-5 tolerance), by (1 + 1e-2) a failure.
#[test]
fn gltf_check_agrees_exactly_with_the_stored_clip_and_sees_a_perturbed_weight() {
    use crate::common::checkers::{try_check_glb, Expected};
    let dir = TempDir::new("normals-exact");
    crate::texture::textured_prism(&dir.path, "gltf_morph_normals = true\ngltf_interpolation = \"cubicspline\"");
    run(&dir.path, &["bake", "-q", "scene.toml", "--out", "out"]).success();
    let anim = library_animation(&dir.join("scene.toml"));
    let clip = BlendShapeClip::new(&anim.trajectory, anim.scene.export.weights);
    let times = crate::common::verify::glb_times(&anim);
    let expected = Expected::at(&times, anim.scene.fps, |t| clip.points_at(t));
    let file = dir.join("out/uvprism.glb");
    let exact = try_check_glb(&file, &expected).unwrap_or_else(|e| panic!("{e}"));
    eprintln!("as written: {exact}");
    assert_eq!(exact["max_error"], 0.0, "{exact}");
    assert!(exact["moving_times"].as_u64().unwrap() + 2 >= times.len() as u64, "the prism moves at the checked times: {exact}");
    let scaled = |factor: f32| {
        let mut bytes = std::fs::read(&file).unwrap();
        let glb = Glb::parse(&bytes);
        let bin = bytes.len() - glb.bin.len();
        let samplers = glb.json["animations"][0]["samplers"].as_array().unwrap();
        assert!(samplers.iter().all(|s| s["interpolation"] == "CUBICSPLINE"));
        for s in samplers {
            let a = s["output"].as_u64().unwrap();
            let values = glb.floats(a, 1);
            let (start, stride, _) = glb.start(a);
            for (i, w) in values.iter().enumerate() {
                let at = bin + start + i * stride.max(4);
                bytes[at..at + 4].copy_from_slice(&(w * factor).to_le_bytes());
            }
        }
        let path = dir.join(format!("scaled-{factor}.glb"));
        std::fs::write(&path, bytes).unwrap();
        try_check_glb(&path, &expected)
    };
    let slightly = scaled(1.0 + 1e-6).unwrap_or_else(|e| panic!("{e}"));
    eprintln!("weights x (1 + 1e-6): {slightly}");
    let error = slightly["max_error"].as_f64().unwrap();
    assert!(error > 0.0 && error < 1e-5, "{slightly}");
    let failure = scaled(1.0 + 1e-2).expect_err("weights 1% off must fail the check");
    assert!(failure.contains("exceeds 0.00001"), "{failure}");
}
