//! A user's vertex numbers survive into every file, through the CLI.
//!
//! Unused vertices: the octagonal prism of `attributes` (UVs with a seam, per-corner normals,
//! two groups) with loose interior vertices, one in the middle of its `v` list and two at the
//! end, baked to usda, usdc and glb, blendshape and full-frame. usd-core reads point `i` of
//! every USD file as the OBJ's vertex `i`; in every glb, glTF vertex `i` is the OBJ's vertex
//! `i` (the seam copies follow them), the loose ones referenced by no triangle; and the files
//! play the animation (`check_outputs`: glTF validator, three.js, usd-core).

use std::fmt::Write as _;

use blendsim::pipeline::stage_file::OutputKind;

use crate::attributes::{prism_obj, Glb};
use crate::common::checkers::usd_probe;
use crate::common::cli::{read_json, run, TempDir};
use crate::common::verify::{check_outputs, library_animation, output_files};

/// The input index of the loose vertex in the middle of the `v` list.
const MIDDLE: usize = 9;

/// `prism_obj(stretch)` with a loose interior vertex inserted as vertex `MIDDLE` and two more
/// after the last (faces renumbered to keep their vertices). Returns the text and its vertices
/// in `v` order.
fn with_loose_vertices(stretch: f64) -> (String, Vec<[f64; 3]>) {
    let text = prism_obj(stretch);
    let loose = |x: f64, y: f64, z: f64| format!("v {x} {} {z}", y * stretch);
    let (mut out, mut vertices, mut seen) = (String::new(), Vec::new(), 0);
    let lines: Vec<&str> = text.lines().collect();
    let last_v = lines.iter().rposition(|l| l.starts_with("v ")).unwrap();
    for (i, line) in lines.iter().enumerate() {
        let mut emit = |l: &str, out: &mut String| {
            if let Some(coordinates) = l.strip_prefix("v ") {
                let p: Vec<f64> = coordinates.split_whitespace().map(|x| x.parse().unwrap()).collect();
                vertices.push([p[0], p[1], p[2]]);
            }
            let _ = writeln!(out, "{l}");
        };
        if line.starts_with("v ") {
            if seen == MIDDLE {
                emit(&loose(0.1, 0.9, 0.05), &mut out);
            }
            seen += 1;
        }
        if let Some(corners) = line.strip_prefix("f ") {
            // 1-based vertex j is input vertex j - 1; those from MIDDLE on moved up by one.
            let renumber = |c: &str| {
                let (v, rest) = c.split_once('/').unwrap();
                let v: usize = v.parse().unwrap();
                format!("{}/{rest}", if v > MIDDLE { v + 1 } else { v })
            };
            emit(&format!("f {}", corners.split_whitespace().map(renumber).collect::<Vec<_>>().join(" ")), &mut out);
        } else {
            emit(line, &mut out);
        }
        if i == last_v {
            emit(&loose(-0.1, 0.5, 0.0), &mut out);
            emit(&loose(0.0, 1.5, -0.1), &mut out);
        }
    }
    (out, vertices)
}

/// The UV prism's scene (`attributes::SCENE`: three keys, hermite, usda/usdc/glb, f32 glb read
/// by hand) with its full-frame files too.
fn scene() -> String {
    crate::attributes::SCENE.replace("name = \"uvprism\"", "name = \"loose\"").replace("[export]\n", "[export]\nfull_frame = true\n")
}

/// usd-core's points of a file's mesh at its first time code (the rest pose: the first key is
/// the rest mesh), and the points its faces use.
const USD_POINTS: &str = r#"
import json, sys
from pxr import Usd, UsdGeom
stage = Usd.Stage.Open(sys.argv[1])
mesh = [UsdGeom.Mesh(p) for p in stage.Traverse() if p.IsA(UsdGeom.Mesh)][0]
points = mesh.GetPointsAttr().Get(Usd.TimeCode(stage.GetStartTimeCode()))
used = sorted(set(mesh.GetFaceVertexIndicesAttr().Get()))
print(json.dumps({"points": [[float(c) for c in p] for p in points], "used": used}))
"#;

#[test]
fn unused_obj_vertices_keep_their_numbers_in_every_file() {
    let dir = TempDir::new("vertex-numbers");
    let (rest, input) = with_loose_vertices(1.0);
    std::fs::write(dir.join("rest.obj"), &rest).unwrap();
    std::fs::write(dir.join("long.obj"), with_loose_vertices(1.3).0).unwrap();
    std::fs::write(dir.join("scene.toml"), scene()).unwrap();
    run(&dir.path, &["bake", "-q", "scene.toml", "--out", "out"]).success();
    let out = dir.join("out");
    let report = read_json(&out.join("report.json"));
    let n = input.len();
    let loose = [MIDDLE, n - 2, n - 1];
    assert_eq!(report["vertices"].as_u64(), Some(n as u64), "every OBJ vertex is exported: {}", report["vertices"]);
    let outputs = output_files(&report["outputs"]);
    assert_eq!(outputs.len(), 6);
    let anim = library_animation(&dir.join("scene.toml"));
    check_outputs(&out, &anim, &outputs);

    let near = |got: &[f64], want: [f64; 3]| got.iter().zip(want).all(|(a, b)| (a - b).abs() < 1e-5);
    for file in outputs.iter().filter(|f| f.path.contains(".usd")) {
        let v = usd_probe(USD_POINTS, &out.join(&file.path));
        let points: Vec<Vec<f64>> = serde_json::from_value(v["points"].clone()).unwrap();
        assert_eq!(points.len(), n, "{}: one point per OBJ vertex", file.path);
        for (i, (p, q)) in points.iter().zip(&input).enumerate() {
            assert!(near(p, *q), "{}: point {i} is {p:?}, the OBJ's vertex {i} is {q:?}", file.path);
        }
        let used: Vec<usize> = serde_json::from_value(v["used"].clone()).unwrap();
        assert_eq!(used, (0..n).filter(|i| !loose.contains(i)).collect::<Vec<_>>(), "{}: the faces use the OBJ's vertices", file.path);
    }
    for file in outputs.iter().filter(|f| f.path.ends_with(".glb")) {
        let glb = Glb::parse(&std::fs::read(out.join(&file.path)).unwrap());
        let mesh = &glb.json["meshes"][0];
        let primitives = mesh["primitives"].as_array().unwrap();
        let attributes = &primitives[0]["attributes"];
        let positions = glb.floats(attributes["POSITION"].as_u64().unwrap(), 3);
        let copies = mesh["extras"]["seamSources"].as_array().unwrap().len();
        assert_eq!(positions.len() / 3, n + copies, "{}: the points, then the seam copies", file.path);
        for (i, q) in input.iter().enumerate() {
            let p: Vec<f64> = positions[3 * i..3 * i + 3].iter().map(|&x| x as f64).collect();
            assert!(near(&p, *q), "{}: vertex {i} is {p:?}, the OBJ's vertex {i} is {q:?}", file.path);
        }
        let used: std::collections::BTreeSet<usize> = primitives.iter().flat_map(|p| glb.indices(p["indices"].as_u64().unwrap())).collect();
        assert!(loose.iter().all(|i| !used.contains(i)) && (0..n).filter(|i| !loose.contains(i)).all(|i| used.contains(&i)), "{}", file.path);
        // A loose vertex has no corner to take attributes from: normal +Z, UV (0, 0) as OBJ reads it.
        let normals = glb.floats(attributes["NORMAL"].as_u64().unwrap(), 3);
        let uvs = glb.floats(attributes["TEXCOORD_0"].as_u64().unwrap(), 2);
        for &i in &loose {
            assert_eq!((&normals[3 * i..3 * i + 3], &uvs[2 * i..2 * i + 2]), (&[0.0, 0.0, 1.0][..], &[0.0, 1.0][..]), "{}: vertex {i}", file.path);
        }
    }
    assert!(outputs.iter().any(|f| f.kind == OutputKind::FullFrame));
}
