//! Welding of keyframe meshes (`[keyframes] weld`), through the CLI.
//!
//! The UV prism of `attributes` written with a vertex per face corner (as exporters often write
//! it: 144 vertices for 34 points, the UVs, normals and groups per corner) bakes on its 34
//! welded vertices, the weld map in every file (glTF `meshes[0].extras.weldMap`, USD
//! `blendsim:weldMap`), to the same positions per input vertex as the prism welded by hand;
//! `weld = false` keeps today's behaviour; a selection numbered in input vertices selects their
//! welded vertex; a map that is not the index list (every vertex written twice) has an accessor
//! of its own; and a clip's keys (a per-corner glTF clip) weld the same way.

use std::fmt::Write as _;
use std::path::Path;

use blendsim::algorithms::frames::MemoryFrames;
use blendsim::algorithms::geometry::{Point, TriMesh};
use serde_json::Value;

use crate::attributes::{prism_obj, Glb};
use crate::common::checkers::usd_probe;
use crate::common::cli::{read_json, run, TempDir};
use crate::common::verify::{check_outputs, library_animation, output_files};

/// The prism's points (`attributes::SIDES` x (`RINGS` + 1) ring vertices and two cap centres).
const POINTS: usize = 34;

/// `obj` with a vertex per face corner: corner `c` (in face order) is vertex `c`, at the
/// position of the vertex it copies; `vt`/`vn`/`usemtl` lines as given. Returns the text and,
/// per new vertex, the 0-based vertex of `obj` it copies.
fn per_corner(obj: &str) -> (String, Vec<usize>) {
    let vertices: Vec<&str> = obj.lines().filter(|l| l.starts_with("v ")).collect();
    let (mut copies, mut rest) = (Vec::new(), String::new());
    for line in obj.lines().filter(|l| !l.starts_with("v ")) {
        match line.strip_prefix("f ") {
            Some(corners) => {
                let mut face = String::from("f");
                for corner in corners.split_whitespace() {
                    let (v, attributes) = corner.split_once('/').unwrap();
                    copies.push(v.parse::<usize>().unwrap() - 1);
                    let _ = write!(face, " {}/{attributes}", copies.len());
                }
                let _ = writeln!(rest, "{face}");
            }
            None => {
                let _ = writeln!(rest, "{line}");
            }
        }
    }
    let mut text: String = copies.iter().map(|&v| format!("{}\n", vertices[v])).collect();
    text.push_str(&rest);
    (text, copies)
}

/// The UV prism's scene (three keys, hermite, usda/usdc/glb, f32 glb) with its full-frame
/// files and `extra` lines in `[keyframes]`.
fn scene(extra: &str) -> String {
    crate::attributes::SCENE
        .replace("name = \"uvprism\"", "name = \"welded\"")
        .replace("times = [0.0, 0.5, 1.0]\n", &format!("times = [0.0, 0.5, 1.0]\n{extra}"))
        .replace("[export]\n", "[export]\nfull_frame = true\n")
}

/// The rest and stretched keys in `dir`, per corner or as written.
fn write_keys(dir: &Path, corners: bool) -> Vec<usize> {
    let mut copies = Vec::new();
    for (name, stretch) in [("rest.obj", 1.0), ("long.obj", 1.3)] {
        let text = prism_obj(stretch);
        let text = if corners {
            let (t, c) = per_corner(&text);
            copies = c;
            t
        } else {
            text
        };
        std::fs::write(dir.join(name), text).unwrap();
    }
    copies
}

/// usd-core's view of a file's Mesh: its points at every time code and `blendsim:weldMap`
/// (`null` when absent).
const USD_POINTS: &str = r#"
import json, sys
from pxr import Usd, UsdGeom
stage = Usd.Stage.Open(sys.argv[1])
mesh = [p for p in stage.Traverse() if p.IsA(UsdGeom.Mesh)][0]
points = UsdGeom.Mesh(mesh).GetPointsAttr()
times = points.GetTimeSamples() or [Usd.TimeCode.Default()]
attr = mesh.GetAttribute("blendsim:weldMap")
print(json.dumps({
    "frames": [[[float(c) for c in p] for p in points.Get(t)] for t in times],
    "weldMap": list(attr.Get()) if attr and attr.HasValue() else None,
}))
"#;

fn usd_frames(file: &Path) -> (Vec<Vec<Point>>, Option<Vec<usize>>) {
    let v = usd_probe(USD_POINTS, file);
    (serde_json::from_value(v["frames"].clone()).unwrap(), serde_json::from_value(v["weldMap"].clone()).unwrap())
}

/// The weld map of a glb's first mesh, if any: `extras.weldMap` names a SCALAR accessor of
/// unsigned shorts or ints in the BIN chunk (`formats/caches.md`, "Welding").
pub(crate) fn glb_weld_map(file: &Path) -> Option<Vec<usize>> {
    let glb = Glb::parse(&std::fs::read(file).unwrap());
    let a = glb.json["meshes"][0]["extras"].get("weldMap")?.as_u64().expect("extras.weldMap is an accessor index");
    assert_eq!(glb.json["accessors"][a as usize]["type"], "SCALAR", "{}", file.display());
    Some(glb.indices(a))
}

fn bytes_of(report: &Value, name: &str) -> u64 {
    report["outputs"].as_array().unwrap().iter().find(|f| f["path"] == name).unwrap()["bytes"].as_u64().unwrap()
}

/// The per-corner prism bakes on its welded points with the weld map in every file (validator,
/// three.js and usd-core play them), and every input vertex moves as the hand-welded prism's
/// vertex it copies, to 1e-6 of the diagonal, in the full-frame USD file.
#[test]
fn per_corner_keys_are_welded_and_map_back() {
    let dir = TempDir::new("weld-keys");
    let (corners, welded) = (dir.join("corners"), dir.join("by-hand"));
    std::fs::create_dir_all(&corners).unwrap();
    std::fs::create_dir_all(&welded).unwrap();
    let copies = write_keys(&corners, true);
    write_keys(&welded, false);
    for d in [&corners, &welded] {
        std::fs::write(d.join("scene.toml"), scene("")).unwrap();
        run(d, &["bake", "-q", "scene.toml", "--out", "out"]).success();
    }
    let out = corners.join("out");
    let report = read_json(&out.join("report.json"));
    assert_eq!((report["vertices"].as_u64(), report["input_vertices"].as_u64()), (Some(POINTS as u64), Some(copies.len() as u64)));
    assert!(report["cage"].is_null(), "the welded prism goes to TetGen as a closed surface: {}", report["cage"]);
    let outputs = output_files(&report["outputs"]);
    assert_eq!(outputs.len(), 6);
    check_outputs(&out, &library_animation(&corners.join("scene.toml")), &outputs);

    let map = glb_weld_map(&out.join("welded.glb")).expect("a weld map in the glb");
    assert_eq!(map.len(), copies.len());
    assert_eq!(glb_weld_map(&out.join("welded.full.glb")).as_ref(), Some(&map), "the full-frame glb's map");
    // Two input vertices share a welded vertex exactly when they copy the same point.
    for i in 0..copies.len() {
        for j in 0..copies.len() {
            assert_eq!(map[i] == map[j], copies[i] == copies[j], "input vertices {i} and {j}");
        }
    }
    let (hand, none) = usd_frames(&welded.join("out/welded.full.usda"));
    assert!(none.is_none(), "no weld map when nothing was welded");
    for file in ["welded.usda", "welded.usdc", "welded.full.usda", "welded.full.usdc"] {
        let (frames, read) = usd_frames(&out.join(file));
        assert_eq!(read.as_ref(), Some(&map), "{file}: the glb's weld map");
        assert!(frames.iter().all(|f| f.len() == POINTS), "{file}: the welded points");
        if !file.contains("full") {
            continue;
        }
        assert_eq!(frames.len(), hand.len(), "{file}: frames");
        let diagonal = blendsim::algorithms::geometry::bbox_diagonal(&hand[0]);
        let mut worst = 0.0f64;
        for (f, h) in frames.iter().zip(&hand) {
            for (i, &c) in copies.iter().enumerate() {
                worst = worst.max(blendsim::algorithms::geometry::norm(blendsim::algorithms::geometry::sub(f[map[i]], h[c])) / diagonal);
            }
        }
        assert!(worst <= 1e-6, "{file}: input vertices are {worst:.2e} of the diagonal from the hand-welded bake's");
    }
    let by_hand = read_json(&welded.join("out/report.json"));
    assert!(by_hand["input_vertices"].is_null(), "no input count when nothing was welded");
    for name in ["welded.glb", "welded.usdc", "welded.full.glb"] {
        println!("{name}: welded {} B, welded by hand {} B", bytes_of(&report, name), bytes_of(&by_hand, name));
    }
}

/// Every vertex written twice, odd faces on the copies (a map that is not the index list): the
/// glb's map has an accessor of its own, which the validator (one information, `UNUSED_OBJECT`,
/// no warning), three.js and usd-core accept, and both copies of a vertex map to one point.
#[test]
fn doubled_keys_carry_a_map_of_their_own() {
    let dir = TempDir::new("weld-keys-doubled");
    for (name, stretch) in [("rest.obj", 1.0), ("long.obj", 1.3)] {
        let text = prism_obj(stretch);
        let vertices: Vec<&str> = text.lines().filter(|l| l.starts_with("v ")).collect();
        let mut doubled: String = vertices.iter().chain(&vertices).map(|v| format!("{v}\n")).collect();
        for (f, line) in text.lines().filter(|l| !l.starts_with("v ")).enumerate() {
            match line.strip_prefix("f ") {
                Some(corners) if f % 2 == 1 => {
                    let shifted: Vec<String> = corners
                        .split_whitespace()
                        .map(|c| {
                            let (v, attributes) = c.split_once('/').unwrap();
                            format!("{}/{attributes}", v.parse::<usize>().unwrap() + vertices.len())
                        })
                        .collect();
                    let _ = writeln!(doubled, "f {}", shifted.join(" "));
                }
                _ => {
                    let _ = writeln!(doubled, "{line}");
                }
            }
        }
        std::fs::write(dir.join(name), doubled).unwrap();
    }
    std::fs::write(dir.join("scene.toml"), scene("")).unwrap();
    run(&dir.path, &["bake", "-q", "scene.toml", "--out", "out"]).success();
    let out = dir.join("out");
    let report = read_json(&out.join("report.json"));
    let n = POINTS;
    assert_eq!((report["vertices"].as_u64(), report["input_vertices"].as_u64()), (Some(n as u64), Some(2 * n as u64)));
    check_outputs(&out, &library_animation(&dir.join("scene.toml")), &output_files(&report["outputs"]));
    let glb = Glb::parse(&std::fs::read(out.join("welded.glb")).unwrap());
    let own = glb.json["meshes"][0]["extras"]["weldMap"].as_u64().expect("a weld map");
    assert_ne!(Some(own), glb.json["meshes"][0]["primitives"][0]["indices"].as_u64(), "not the index list");
    let map = glb_weld_map(&out.join("welded.glb")).unwrap();
    assert_eq!(map.len(), 2 * n);
    assert!((0..n).all(|i| map[i] == map[i + n]), "both copies of a vertex are one point: {map:?}");
    assert_eq!(usd_frames(&out.join("welded.usda")).1.as_ref(), Some(&map), "USD's map is the glb's");
}

/// `weld = false` keeps the input's vertices as before: a surface of unconnected triangles is
/// refused by the surface check before TetGen (`[tet] cage = false`), or simulated on a cage
/// around its 144 vertices, with no weld map.
#[test]
fn weld_false_keeps_the_input_vertices() {
    let dir = TempDir::new("weld-keys-off");
    write_keys(&dir.path, true);
    let refused = scene("weld = false\n").replace("[tet]\n", "[tet]\ncage = false\n");
    std::fs::write(dir.join("refused.toml"), refused).unwrap();
    let r = run(&dir.path, &["bake", "-q", "refused.toml", "--out", "refused"]);
    assert_ne!(r.code, Some(0), "{r}");
    assert!(r.stderr.contains("rest.obj: the surface has a hole") && r.stderr.contains("merge the vertices along the seam"), "{}", r.stderr);
    assert!(!dir.join("refused").exists(), "no partial output");
    std::fs::write(dir.join("caged.toml"), scene("weld = false\n").replace("formats = [\"usda\", \"usdc\", \"glb\"]", "formats = [\"glb\"]"))
        .unwrap();
    run(&dir.path, &["bake", "-q", "caged.toml", "--out", "caged"]).success();
    let report = read_json(&dir.join("caged/report.json"));
    assert_eq!(report["vertices"].as_u64(), Some(144));
    assert!(report["input_vertices"].is_null() && !report["cage"].is_null(), "{report}");
    assert!(glb_weld_map(&dir.join("caged/welded.glb")).is_none(), "no weld map without welding");
}

/// A surface error on welded keys says its vertex numbers are the welded ones: the prism
/// without its last face has a hole (`[tet] cage = false`, so the surface goes to TetGen's
/// checks).
#[test]
fn surface_errors_say_the_numbers_are_welded() {
    let dir = TempDir::new("weld-keys-hole");
    for (name, stretch) in [("rest.obj", 1.0), ("long.obj", 1.3)] {
        let text = prism_obj(stretch);
        let without_last_face = &text[..text.trim_end().rfind('\n').unwrap() + 1];
        std::fs::write(dir.join(name), per_corner(without_last_face).0).unwrap();
    }
    std::fs::write(dir.join("scene.toml"), scene("").replace("[tet]\n", "[tet]\ncage = false\n")).unwrap();
    let r = run(&dir.path, &["bake", "-q", "scene.toml", "--out", "out"]);
    assert_ne!(r.code, Some(0), "{r}");
    assert!(r.stderr.contains("rest.obj: the surface has a hole: the edge from vertex "), "{}", r.stderr);
    assert!(r.stderr.contains("(vertex numbers after welding, [keyframes] weld: "), "{}", r.stderr);
    assert!(!dir.join("out").exists(), "no partial output");
}

/// A `fixed` index file numbers the input's vertices: the last corner copy of the top cap's
/// centre selects its welded vertex (selected when any of its input vertices is).
#[test]
fn selections_number_the_input_vertices() {
    let dir = TempDir::new("weld-keys-select");
    let copies = write_keys(&dir.path, true);
    let top = attributes_top();
    let last = copies.iter().rposition(|&c| c == top).unwrap();
    assert!(copies.iter().position(|&c| c == top).unwrap() < last, "a copy other than the welded vertex's first");
    std::fs::write(dir.join("top.txt"), format!("# the top centre's last copy\n{last}\n")).unwrap();
    std::fs::write(dir.join("scene.toml"), scene("fixed = [\"all\", \"top.txt\", \"all\"]\n")).unwrap();
    run(&dir.path, &["import", "scene.toml", "-o", "keys.json"]).success();
    let keys = &read_json(&dir.join("keys.json"))["data"];
    let map: Vec<usize> = serde_json::from_value(keys["weld"].clone()).unwrap();
    assert_eq!(map.len(), copies.len());
    let fixed: Vec<Vec<usize>> = serde_json::from_value(keys["fixed"].clone()).unwrap();
    assert_eq!(fixed[1], vec![map[last]], "the welded vertex of input vertex {last}");
    assert_eq!((fixed[0].len(), fixed[2].len()), (POINTS, POINTS));
    // That vertex is the top centre in the rest pose.
    let rest: Vec<Point> = serde_json::from_value(keys["rest"]["positions"].clone()).unwrap();
    assert_eq!(rest.len(), POINTS);
    assert_eq!(rest[map[last]], [0.0, 2.0, 0.0]);
}

/// The top cap's centre, 0-based, in `attributes::prism_obj`.
fn attributes_top() -> usize {
    (crate::attributes::RINGS + 1) * crate::attributes::SIDES
}

/// Keys from a per-corner glTF clip (a closed box, 36 corners for 8 points, stretching) weld
/// too: 8 vertices, the map in the glb.
#[test]
fn clip_keys_are_welded() {
    let dir = TempDir::new("weld-keys-clip");
    let box_points: Vec<Point> = (0..8).map(|i| [(i & 1) as f64, ((i >> 1) & 1) as f64, (i >> 2) as f64]).collect();
    let faces: [[u32; 3]; 12] =
        [[0, 2, 1], [1, 2, 3], [4, 5, 6], [5, 7, 6], [0, 1, 4], [1, 5, 4], [2, 6, 3], [3, 6, 7], [0, 4, 2], [2, 4, 6], [1, 3, 5], [3, 7, 5]];
    let corners = TriMesh {
        positions: faces.iter().flat_map(|t| t.map(|v| box_points[v as usize])).collect(),
        triangles: (0..12u32).map(|t| [3 * t, 3 * t + 1, 3 * t + 2]).collect(),
        attributes: None,
    };
    let times: Vec<f64> = (0..25).map(|f| f as f64 / 24.0).collect();
    let frames = times.iter().map(|&t| corners.positions.iter().map(|p| [p[0], p[1] * (1.0 + 0.3 * t), p[2]]).collect()).collect();
    blendsim::formats::cache::write(&dir.join("box.glb"), &corners, &mut MemoryFrames { times, frames }, 24.0).unwrap();
    let text = "name = \"boxclip\"\nfps = 24\n[keyframes]\nclip = \"box.glb\"\nframes = [0, 12, 24]\n[solver]\nmethod = \"hermite\"\n[export]\nformats = [\"glb\"]\n";
    std::fs::write(dir.join("scene.toml"), text).unwrap();
    run(&dir.path, &["bake", "-q", "scene.toml", "--out", "out"]).success();
    let report = read_json(&dir.join("out/report.json"));
    assert_eq!((report["vertices"].as_u64(), report["input_vertices"].as_u64()), (Some(8), Some(36)));
    let map = glb_weld_map(&dir.join("out/boxclip.glb")).expect("a weld map");
    assert_eq!(map.len(), 36);
    for (i, &w) in map.iter().enumerate() {
        let (c, first) = (corners.positions[i], map.iter().position(|&x| x == w).unwrap());
        assert_eq!(corners.positions[first], c, "input vertex {i} and {first} share welded vertex {w}");
    }
    check_outputs(&dir.join("out"), &library_animation(&dir.join("scene.toml")), &output_files(&report["outputs"]));
}
