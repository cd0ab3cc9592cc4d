//! The automatic cage through the CLI: a messy surface (a procedural teapot-like asset: four
//! parts, open edges, quads, a lid that crosses the body) and a surface over `[tet]
//! max_nodes` bake on a generated cage, with every file they write opened by the independent
//! checkers; the report says why the cage was used, its size and how closely its keys
//! reproduce the input keys; masks on the fine surface carry over to the cage nodes near
//! them; a clean surface under the budget still goes straight to TetGen, and `[tet] cage =
//! false` gives today's TetGen error on the messy surface.
//!
//! No licensed teapot ships with the project, so [`teapot`] builds one with the same defects
//! as the public test teapots.

use std::f64::consts::PI;
use std::path::{Path, PathBuf};

use blendsim::algorithms::geometry::Point;
use serde_json::Value;

use crate::common::cli::{copy_demo, read_json, run, TempDir};
use crate::common::verify::{check_outputs, library_animation, output_files};

/// A surface of quads: rings of `n` points, consecutive rings joined.
#[derive(Default)]
struct Quads {
    points: Vec<Point>,
    quads: Vec<[usize; 4]>,
}

impl Quads {
    /// Join `rings` (each of `n` points, appended in order) into a band of quads; the two
    /// end rings stay open.
    fn band(&mut self, rings: Vec<Vec<Point>>) {
        let n = rings[0].len();
        let base = self.points.len();
        for i in 0..rings.len() - 1 {
            for k in 0..n {
                let at = |r: usize, k: usize| base + r * n + k % n;
                self.quads.push([at(i, k), at(i, k + 1), at(i + 1, k + 1), at(i + 1, k)]);
            }
        }
        self.points.extend(rings.into_iter().flatten());
    }

    /// The OBJ text with the points moved by `f` (the same faces in every key).
    fn obj(&self, f: impl Fn(Point) -> Point) -> String {
        let mut s = String::from("# a procedural teapot-like surface: four open parts of quads\n");
        for &p in &self.points {
            let [x, y, z] = f(p);
            s.push_str(&format!("v {x:.6} {y:.6} {z:.6}\n"));
        }
        for q in &self.quads {
            s.push_str(&format!("f {} {} {} {}\n", q[0] + 1, q[1] + 1, q[2] + 1, q[3] + 1));
        }
        s
    }
}

/// A ring of `n` points around the y axis.
fn ring(r: f64, y: f64, n: usize) -> Vec<Point> {
    (0..n).map(|k| 2.0 * PI * k as f64 / n as f64).map(|a| [r * a.cos(), y, r * a.sin()]).collect()
}

/// A ring of `n` points of radius `r` around `c`, in the plane normal to the (xy-plane)
/// direction `t`.
fn tube_ring(c: Point, t: [f64; 2], r: f64, n: usize) -> Vec<Point> {
    let l = t[0].hypot(t[1]);
    let side = [-t[1] / l, t[0] / l];
    (0..n).map(|k| 2.0 * PI * k as f64 / n as f64).map(|a| [c[0] + r * a.cos() * side[0], c[1] + r * a.cos() * side[1], c[2] + r * a.sin()]).collect()
}

/// A teapot-like asset: a body open at the top, a lid (open at its rim, which crosses the
/// body's), a spout and a handle (open tubes): 4 parts, 132 open edges, 406 vertices, quads.
fn teapot() -> Quads {
    let mut t = Quads::default();
    let n = 24;
    let body = [(0.01, 0.0), (0.6, 0.02), (0.9, 0.3), (1.0, 0.6), (0.9, 0.95), (0.7, 1.1)];
    t.band(body.iter().map(|&(r, y)| ring(r, y, n)).collect());
    let lid = [(0.72, 1.08), (0.6, 1.2), (0.3, 1.3), (0.1, 1.42), (0.01, 1.45)];
    t.band(lid.iter().map(|&(r, y)| ring(r, y, n)).collect());
    let spout = (0..7).map(|i| i as f64 / 6.0).map(|s| tube_ring([0.85 + 0.5 * s, 0.4 + 0.7 * s * s, 0.0], [0.5, 1.4 * s + 0.01], 0.12, 10));
    t.band(spout.collect());
    let handle = (0..9)
        .map(|i| i as f64 / 8.0)
        .map(|s| tube_ring([-0.9 - 0.35 * (PI * s).sin(), 0.3 + 0.6 * s, 0.0], [-0.35 * PI * (PI * s).cos(), 0.6], 0.07, 8));
    t.band(handle.collect());
    t
}

/// Bend about the z axis by `angle` radians over the teapot's height.
fn bend(p: Point, angle: f64) -> Point {
    let (s, c) = (angle * p[1] / 1.5).sin_cos();
    [c * p[0] - s * p[1], s * p[0] + c * p[1], p[2]]
}

/// The teapot scene in `dir` (rest, bent left, rest, bent right, rest, as a loop), with extra
/// TOML tables.
fn teapot_scene(dir: &Path, tables: &str) -> PathBuf {
    let t = teapot();
    std::fs::write(dir.join("rest.obj"), t.obj(|p| p)).unwrap();
    std::fs::write(dir.join("left.obj"), t.obj(|p| bend(p, 0.35))).unwrap();
    std::fs::write(dir.join("right.obj"), t.obj(|p| bend(p, -0.35))).unwrap();
    let scene = dir.join("teapot.toml");
    std::fs::write(
        &scene,
        format!(
            "name = \"teapot\"\nfps = 30\n[keyframes]\nmeshes = [\"rest.obj\", \"left.obj\", \"rest.obj\", \"right.obj\", \"rest.obj\"]\n\
             times = [0.0, 0.5, 1.0, 1.5, 2.0]\ncyclic = true\n[export]\nformats = [\"usda\", \"usdc\", \"glb\"]\nfull_frame = true\n{tables}\n"
        ),
    )
    .unwrap();
    scene
}

/// The bundled demo (a twisted prism, 128 vertices, ends held) copied to `dir` with extra
/// `[tet]` lines.
fn demo_scene(dir: &Path, tet_lines: &str) -> PathBuf {
    copy_demo(dir);
    let scene = dir.join("twist.toml");
    let text = std::fs::read_to_string(&scene).unwrap().replace("[tet]\n", &format!("[tet]\n{tet_lines}\n"));
    std::fs::write(&scene, text).unwrap();
    scene
}

/// Bake `scene` into `dir/out`, check every file with the independent tools, and return the
/// report.
fn bake_and_check(dir: &TempDir, scene: &Path) -> Value {
    run(&dir.path, &["bake", "-q", scene.to_str().unwrap(), "--out", "out"]).success();
    let report = read_json(&dir.join("out/report.json"));
    let summaries = check_outputs(&dir.join("out"), &library_animation(scene), &output_files(&report["outputs"]));
    assert_eq!(summaries.len(), 6);
    assert_eq!(report["solver"]["converged"], true, "{report}");
    report
}

#[test]
fn a_messy_teapot_bakes_on_a_cage_and_every_file_passes_the_checkers() {
    let dir = TempDir::new("cage-teapot");
    let scene = teapot_scene(&dir.path, "");
    let report = bake_and_check(&dir, &scene);
    let cage = &report["cage"];
    let reason = cage["reason"].as_str().unwrap();
    for defect in ["open (132 open edges)", "in 4 parts", "self-intersecting"] {
        assert!(reason.contains(defect), "the report must say the surface is {defect}: {reason}");
    }
    // The fine surface is what is exported; the cage is the simulated body.
    assert_eq!((report["vertices"].as_u64(), cage["fine_vertices"].as_u64()), (Some(406), Some(406)));
    assert_eq!(report["tet_nodes"], cage["nodes"]);
    let nodes = cage["nodes"].as_u64().unwrap();
    assert!((700..=1300).contains(&nodes), "default cage of about 1000 nodes, got {nodes}");
    let key_error = cage["key_error_max"].as_f64().unwrap();
    assert!(key_error > 0.0 && key_error < 1e-2, "cage keys reproduce the input keys to {key_error}");
    let md = std::fs::read_to_string(dir.join("out/report.md")).unwrap();
    assert!(md.contains("| cage | ") && md.contains("because the surface is open"), "{md}");
    assert_eq!(report["basis"], "keys");
    assert!(md.contains("\n| basis | keys |\n"), "report.json's basis: {md}");
}

#[test]
fn with_the_cage_off_the_teapot_gets_tetgens_error() {
    let dir = TempDir::new("cage-off-teapot");
    let scene = teapot_scene(&dir.path, "[tet]\ncage = false");
    let r = run(&dir.path, &["bake", scene.to_str().unwrap(), "--out", "out"]);
    assert_eq!(r.code, Some(1), "{r}");
    assert!(r.stderr.starts_with("error: ") && r.stderr.lines().count() == 1, "{r}");
    assert!(r.stderr.contains("rest.obj: the surface has a hole"), "{r}");
    assert!(!dir.join("out").exists());
}

#[test]
fn a_surface_over_max_nodes_bakes_on_a_cage_with_its_masks_carried() {
    let dir = TempDir::new("cage-budget");
    // Under the default budget the clean demo prism goes straight to TetGen.
    let plain = TempDir::new("cage-budget-plain");
    let scene = demo_scene(&plain.path, "");
    run(&plain.path, &["import", scene.to_str().unwrap(), "-o", "keys.json"]).success();
    run(&plain.path, &["tetrahedralize", "keys.json", "-o", "body.json"]).success();
    assert!(read_json(&plain.join("body.json"))["data"].get("cage").is_none());

    let scene = demo_scene(&dir.path, "max_nodes = 100\ncage_nodes = 300");
    run(&dir.path, &["import", scene.to_str().unwrap(), "-o", "keys.json"]).success();
    run(&dir.path, &["tetrahedralize", "keys.json", "-o", "body.json"]).success();
    let body = read_json(&dir.join("body.json"));
    let cage = &body["data"]["cage"];
    assert_eq!(cage["reason"], "the surface has 128 vertices, more than [tet] max_nodes = 100");
    // Held nodes: those the held fine vertices (the prism's ends at y = 0 and y = 3) carry
    // most of the binding weight of, so within one cube of an end, and some at each end.
    let h = cage["spacing"].as_f64().unwrap();
    let positions: Vec<[f64; 3]> = serde_json::from_value(body["data"]["mesh"]["positions"].clone()).unwrap();
    let keys = &body["data"]["keys"];
    let ys = |set: &Value| -> Vec<f64> { set.as_array().unwrap().iter().map(|i| positions[i.as_u64().unwrap() as usize][1]).collect() };
    for (k, set) in keys["fixed"].as_array().unwrap().iter().enumerate() {
        let y = ys(set);
        assert!(y.iter().all(|&y| y.abs() < h || (y - 3.0).abs() < h), "key {k}: held nodes away from the ends: {y:?}");
        assert!(y.iter().any(|&y| y < 1.5) && y.iter().any(|&y| y > 1.5), "key {k}: both ends held: {y:?}");
    }
    for set in keys["fixed_velocity"].as_array().unwrap() {
        let y = ys(set);
        assert!(!y.is_empty() && y.iter().all(|&y| y.abs() < h), "velocity held away from the bottom: {y:?}");
    }
    let report = bake_and_check(&dir, &scene);
    assert_eq!(report["cage"], *cage);
    // The held ends keep the embedded keys close to the input keys.
    assert!(report["keyframe_deviation"]["max"].as_f64().unwrap() < 0.1, "{}", report["keyframe_deviation"]);
}
