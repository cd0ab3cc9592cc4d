//! UVs, normals and material groups through the CLI: an octagonal prism written as OBJ with a
//! cylindrical UV unwrap (a seam where u wraps from 1 to 0), per-corner normals on the sides,
//! and two `usemtl` groups (sides, caps), baked to usda/usdc/glb.
//!
//! usd-core reads `primvars:st` faceVarying and indexed with the OBJ's UV at every corner, and
//! the `materialBind` subsets as a valid partition bound to materials; the glTF validator gives
//! 0 errors / 0 warnings and three.js morphs every vertex (seam copies included) onto our
//! points at every frame (`check_outputs`), with TEXCOORD_0 and NORMAL on two primitives.

use std::fmt::Write as _;

use blendsim::pipeline::stage_file::OutputKind;
use serde_json::Value;

use crate::common::checkers::usd_probe;
use crate::common::cli::{read_json, run, TempDir};
use crate::common::verify::{check_outputs, library_animation, output_files};

pub(crate) const SIDES: usize = 8;
pub(crate) const RINGS: usize = 3;

/// The prism as OBJ, stretched along y by `stretch`: ring vertices, then the two cap centres;
/// UV columns 0..=SIDES per ring (column SIDES repeats column 0's vertices at u = 1: the seam).
pub(crate) fn prism_obj(stretch: f64) -> String {
    let mut s = String::from("# blendsim attributes test\n");
    let angle = |k: usize| 2.0 * std::f64::consts::PI * k as f64 / SIDES as f64;
    for r in 0..=RINGS {
        for k in 0..SIDES {
            let _ = writeln!(s, "v {} {} {}", 0.5 * angle(k).cos(), 2.0 * stretch * r as f64 / RINGS as f64, 0.5 * angle(k).sin());
        }
    }
    let _ = writeln!(s, "v 0 {} 0\nv 0 0 0", 2.0 * stretch);
    for r in 0..=RINGS {
        for k in 0..=SIDES {
            let _ = writeln!(s, "vt {} {}", k as f64 / SIDES as f64, 0.2 + 0.6 * r as f64 / RINGS as f64);
        }
    }
    let _ = writeln!(s, "vt 0.5 0.95\nvt 0.5 0.05");
    for k in 0..SIDES {
        let _ = writeln!(s, "vn {} 0 {}", angle(k).cos(), angle(k).sin());
    }
    let _ = writeln!(s, "vn 0 1 0\nvn 0 -1 0");
    let v = |r: usize, k: usize| r * SIDES + k % SIDES + 1;
    let t = |r: usize, k: usize| r * (SIDES + 1) + k + 1;
    let (top, bottom, cap_uv) = ((RINGS + 1) * SIDES + 1, (RINGS + 1) * SIDES + 2, (RINGS + 1) * (SIDES + 1));
    s.push_str("usemtl side\n");
    for r in 0..RINGS {
        for k in 0..SIDES {
            let c = |r: usize, k: usize| format!("{}/{}/{}", v(r, k), t(r, k), k % SIDES + 1);
            let _ = writeln!(s, "f {} {} {} {}", c(r, k), c(r + 1, k), c(r + 1, k + 1), c(r, k + 1));
        }
    }
    s.push_str("usemtl cap\n");
    let (up, down) = (SIDES + 1, SIDES + 2);
    for k in 0..SIDES {
        let _ = writeln!(s, "f {}/{}/{up} {top}/{}/{up} {}/{}/{up}", v(RINGS, k + 1), t(RINGS, k + 1), cap_uv + 1, v(RINGS, k), t(RINGS, k));
        let _ = writeln!(s, "f {}/{}/{down} {}/{}/{down} {bottom}/{}/{down}", v(0, k), t(0, k), v(0, k + 1), t(0, k + 1), cap_uv + 2);
    }
    s
}

pub(crate) const SCENE: &str = r#"name = "uvprism"
fps = 24

[keyframes]
meshes = ["rest.obj", "long.obj", "rest.obj"]
times = [0.0, 0.5, 1.0]

[tet]
quality = 1.414
max_volume = 0.05

[solver]
method = "hermite"

[export]
formats = ["usda", "usdc", "glb"]
# The UV, normal and texture checks read the glb's f32 accessors by hand (`Glb::floats`).
gltf_compression = "none"
"#;

/// usd-core's view of a file's mesh: st (interpolation, indexed, per-corner values in face
/// order with the point of each corner), normals interpolation, and the subsets.
const USD_PROBE: &str = r#"
import json, sys
from pxr import Usd, UsdGeom, UsdShade
stage = Usd.Stage.Open(sys.argv[1])
mesh = [UsdGeom.Mesh(p) for p in stage.Traverse() if p.IsA(UsdGeom.Mesh)][0]
st = UsdGeom.PrimvarsAPI(mesh).GetPrimvar("st")
values = st.Get()
indices = st.GetIndices() if st.IsIndexed() else None
points = list(mesh.GetFaceVertexIndicesAttr().Get())
if st.GetInterpolation() == "faceVarying":
    corners = [values[indices[c]] if indices else values[c] for c in range(len(points))]
else:
    corners = [values[p] for p in points]
ok, why = UsdGeom.Subset.ValidateFamily(mesh, UsdGeom.Tokens.face, "materialBind")
subsets = {}
for s in UsdGeom.Subset.GetAllGeomSubsets(mesh):
    material = UsdShade.MaterialBindingAPI(s.GetPrim()).ComputeBoundMaterial()[0]
    subsets[s.GetPrim().GetName()] = {"faces": len(s.GetIndicesAttr().Get()), "material": str(material.GetPath()) if material else None}
print(json.dumps({
    "st": st.GetInterpolation(), "indexed": st.IsIndexed(),
    "corners": [[points[c], float(u), float(v)] for c, (u, v) in enumerate(corners)],
    "normals": mesh.GetNormalsInterpolation(), "normal_count": len(mesh.GetNormalsAttr().Get()),
    "family_valid": ok, "why": why, "subsets": subsets,
}))
"#;

/// Triangles given as the (point, u, v) of their corners, in a form that compares equal
/// whatever the triangle order and winding: UVs rounded to 1e-6, each triangle's corners
/// sorted, the triangles sorted.
pub(crate) fn corner_uv_sets(triangles: impl IntoIterator<Item = [(u64, f64, f64); 3]>) -> Vec<Vec<(u64, i64, i64)>> {
    let mut out: Vec<Vec<_>> = triangles
        .into_iter()
        .map(|t| {
            let mut t: Vec<_> = t.iter().map(|&(p, u, v)| (p, (u * 1e6).round() as i64, (v * 1e6).round() as i64)).collect();
            t.sort();
            t
        })
        .collect();
    out.sort();
    out
}

/// The OBJ's (vertex, u, v) at every corner of every triangle (fans of its quads), as
/// [`corner_uv_sets`].
pub(crate) fn obj_corner_uvs(text: &str) -> Vec<Vec<(u64, i64, i64)>> {
    let mesh = blendsim::formats::mesh::obj::parse(text).unwrap();
    let a = mesh.attributes.unwrap();
    corner_uv_sets(
        mesh.triangles
            .iter()
            .zip(&a.uv_corners)
            .map(|(t, c)| std::array::from_fn(|k| (t[k] as u64, a.uvs[c[k] as usize][0], a.uvs[c[k] as usize][1]))),
    )
}

#[test]
fn uvs_seams_normals_and_material_groups_reach_usd_and_gltf() {
    let dir = TempDir::new("attributes");
    let rest = prism_obj(1.0);
    std::fs::write(dir.join("rest.obj"), &rest).unwrap();
    std::fs::write(dir.join("long.obj"), prism_obj(1.3)).unwrap();
    std::fs::write(dir.join("scene.toml"), SCENE).unwrap();
    run(&dir.path, &["bake", "scene.toml", "--out", "out"]).success();
    let out = dir.join("out");
    let report = read_json(&out.join("report.json"));
    let outputs = output_files(&report["outputs"]);

    // Every file against our own evaluation: glTF validator 0/0, three.js at every frame
    // (seam copies compared with the points they show), usd-core.
    let anim = library_animation(&dir.join("scene.toml"));
    assert!(anim.mesh.attributes.is_some(), "the attributes reach the animation stage");
    check_outputs(&out, &anim, &outputs);

    let want = obj_corner_uvs(&rest);
    for file in outputs.iter().filter(|f| f.path.contains("usd")) {
        let v = usd_probe(USD_PROBE, &out.join(&file.path));
        assert_eq!((v["st"].as_str(), v["indexed"].as_bool()), (Some("faceVarying"), Some(true)), "{}: a seam needs faceVarying", file.path);
        let corners = v["corners"].as_array().unwrap();
        let corner = |c: &Value| (c[0].as_u64().unwrap(), c[1].as_f64().unwrap(), c[2].as_f64().unwrap());
        let got = corner_uv_sets(corners.chunks(3).map(|t| std::array::from_fn(|k| corner(&t[k]))));
        assert_eq!(got, want, "{}: the UV of every corner is the OBJ's", file.path);
        // Side normals are smooth around the prism but differ from the caps': faceVarying.
        assert_eq!((v["normals"].as_str(), v["normal_count"].as_u64()), (Some("faceVarying"), Some(corners.len() as u64)), "{}", file.path);
        assert_eq!(v["family_valid"], true, "{}: {}", file.path, v["why"]);
        let faces = |name: &str| v["subsets"][name]["faces"].as_u64();
        assert_eq!((faces("side"), faces("cap")), (Some((2 * SIDES * RINGS) as u64), Some((2 * SIDES) as u64)), "{}: {}", file.path, v["subsets"]);
        assert_eq!(v["subsets"]["cap"]["material"], "/uvprism/Materials/cap", "{}", file.path);
    }

    for file in outputs.iter().filter(|f| f.path.ends_with(".glb")) {
        let bytes = std::fs::read(out.join(&file.path)).unwrap();
        let glb = Glb::parse(&bytes);
        let mesh = &glb.json["meshes"][0];
        let primitives = mesh["primitives"].as_array().unwrap();
        let materials: Vec<&str> =
            primitives.iter().map(|p| glb.json["materials"][p["material"].as_u64().unwrap() as usize]["name"].as_str().unwrap()).collect();
        assert_eq!(materials, ["side", "cap"], "{}", file.path);
        let attributes = &primitives[0]["attributes"];
        assert!(
            primitives.iter().all(|p| p["attributes"] == *attributes && p["targets"] == primitives[0]["targets"]),
            "{}: primitives share vertices and targets",
            file.path
        );
        let positions = glb.floats(attributes["POSITION"].as_u64().unwrap(), 3).len() / 3;
        let uvs = glb.floats(attributes["TEXCOORD_0"].as_u64().unwrap(), 2);
        let normals = glb.floats(attributes["NORMAL"].as_u64().unwrap(), 3);
        // Points: 8 per ring and the two cap centres. Copies: the seam vertex of each ring (u = 1
        // beside u = 0), each cap's ring vertices (the cap normal), and in each cap the seam
        // vertex once more (the cap fan reuses the ring's UV columns 0 and SIDES).
        let points = (RINGS + 1) * SIDES + 2;
        assert_eq!((uvs.len() / 2, normals.len() / 3), (positions, positions), "{}", file.path);
        assert_eq!(positions, points + (RINGS + 1) + 2 * (SIDES + 1), "{}", file.path);
        let sources: Vec<u64> =
            mesh["extras"]["seamSources"].as_array().expect("seam copies need extras.seamSources").iter().map(|x| x.as_u64().unwrap()).collect();
        let point_of = |j: usize| if j < points { j as u64 } else { sources[j - points] };
        // Corner UVs (v flipped back), through the file's own mapping, equal the OBJ's.
        let corner = |j: usize| (point_of(j), uvs[2 * j] as f64, 1.0 - uvs[2 * j + 1] as f64);
        let indices: Vec<usize> = primitives.iter().flat_map(|p| glb.indices(p["indices"].as_u64().unwrap())).collect();
        let got = corner_uv_sets(indices.chunks(3).map(|t| std::array::from_fn(|k| corner(t[k]))));
        assert_eq!(got, want, "{}: the UV of every corner is the OBJ's", file.path);
    }
    assert!(outputs.iter().any(|f| f.kind == OutputKind::FullFrame && f.path.ends_with(".glb")));
}

/// The JSON and BIN chunks of a GLB, read by hand (the point is not to trust our writer's types).
pub(crate) struct Glb {
    pub json: Value,
    pub bin: Vec<u8>,
}

impl Glb {
    pub fn parse(bytes: &[u8]) -> Glb {
        let u32_at = |i: usize| u32::from_le_bytes(bytes[i..i + 4].try_into().unwrap()) as usize;
        let json_len = u32_at(12);
        let json = serde_json::from_slice(&bytes[20..20 + json_len]).unwrap();
        Glb { json, bin: bytes[20 + json_len + 8..].to_vec() }
    }

    /// Where accessor `a`'s data starts, and its element stride.
    pub fn start(&self, a: u64) -> (usize, usize, usize) {
        let acc = &self.json["accessors"][a as usize];
        let view = &self.json["bufferViews"][acc["bufferView"].as_u64().unwrap() as usize];
        let start = view["byteOffset"].as_u64().unwrap_or(0) + acc["byteOffset"].as_u64().unwrap_or(0);
        (start as usize, view["byteStride"].as_u64().unwrap_or(0) as usize, acc["count"].as_u64().unwrap() as usize)
    }

    pub fn floats(&self, a: u64, width: usize) -> Vec<f32> {
        let (start, stride, count) = self.start(a);
        let stride = if stride == 0 { 4 * width } else { stride };
        (0..count)
            .flat_map(|i| (0..width).map(move |k| start + i * stride + 4 * k))
            .map(|o| f32::from_le_bytes(self.bin[o..o + 4].try_into().unwrap()))
            .collect()
    }

    pub fn indices(&self, a: u64) -> Vec<usize> {
        let (start, _, count) = self.start(a);
        match self.json["accessors"][a as usize]["componentType"].as_u64().unwrap() {
            5123 => (0..count).map(|i| u16::from_le_bytes(self.bin[start + 2 * i..start + 2 * i + 2].try_into().unwrap()) as usize).collect(),
            5125 => (0..count).map(|i| u32::from_le_bytes(self.bin[start + 4 * i..start + 4 * i + 4].try_into().unwrap()) as usize).collect(),
            other => panic!("index component type {other}"),
        }
    }
}
