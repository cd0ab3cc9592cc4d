//! USD ASCII writers. Layout in `formats/usd.md`.
//!
//! Written as text directly (no USD library in Rust): the layout is small and fixed, and
//! writing it ourselves keeps the bytes deterministic. Floats are f32 in their shortest
//! round-trip form, so reading the file back gives exactly the values we hold.

use std::fmt::Write;

use super::clip::BlendShapeClip;
use super::fullframe::FullFrame;
use super::usda_attributes as attrs;
use crate::mesh::attributes::CornerAttributes;
use crate::mesh::Bounds;
use crate::spacetime::trajectory::frames_between;

/// Stage-level settings shared by both USD files.
#[derive(Debug, Clone, PartialEq)]
pub struct UsdSettings {
    /// Prim-safe name of the asset (used for the SkelRoot / mesh names).
    pub name: String,
    /// Frames per second (`timeCodesPerSecond`).
    pub fps: f64,
    /// "Y" or "Z".
    pub up_axis: char,
    /// Scene units in meters (`metersPerUnit`).
    pub meters_per_unit: f64,
}

/// A valid USD prim name from an asset name: letters, digits and `_`, not starting with a digit.
pub fn prim_name(name: &str) -> String {
    let mut s: String = name.chars().map(|c| if c.is_ascii_alphanumeric() { c } else { '_' }).collect();
    if !s.starts_with(|c: char| c.is_ascii_alphabetic() || c == '_') {
        s.insert(0, '_');
    }
    s
}

/// UsdSkel blendshape animation: weights sampled at every frame of the clip's key range.
///
/// A clip without targets (a static animation) is written as a plain mesh under an Xform:
/// a SkelAnimation with no blend shapes would only add noise for importers.
///
/// `attributes` (UVs, normals, material groups of the surface) add `primvars:st`, `normals`,
/// `GeomSubset`s and their placeholder materials; without them the file is as before.
pub fn blendshapes(clip: &BlendShapeClip, triangles: &[[u32; 3]], attributes: Option<&CornerAttributes>, settings: &UsdSettings) -> String {
    let (start, end) = (clip.times[0], *clip.times.last().expect("a clip has keys"));
    let frames = frames_between(start, end, settings.fps);
    let mut out = header(settings, frames[0].0, frames[frames.len() - 1].0);
    let root = &settings.name;
    if clip.targets.is_empty() {
        let _ = writeln!(out, "def Xform \"{root}\"\n{{\n    def Mesh \"Mesh\"\n    {{");
        push_attr(&mut out, 8, "float3[] extent", |o| push_vec3s(o, extent(&clip.base).iter()));
        push_topology(&mut out, triangles);
        push_mesh_attributes(&mut out, triangles, clip.vertex_count(), attributes);
        push_attr(&mut out, 8, "point3f[] points", |o| push_vec3s(o, clip.base.iter()));
        out.push_str("        uniform token subdivisionScheme = \"none\"\n");
        close_mesh_and_root(&mut out, attributes, root);
        return out;
    }

    // The SkelRoot's extent bounds the whole animation, so culling never clips a deformed pose.
    let weights: Vec<Vec<f64>> = frames.iter().map(|&(_, t)| clip.weights_at(t)).collect();
    let mut bounds = Bounds::of_f32(&clip.base);
    for w in &weights {
        let posed: Vec<[f32; 3]> = clip.points_with_weights(w).iter().map(|p| p.map(|x| x as f32)).collect();
        bounds = bounds.union(Bounds::of_f32(&posed));
    }
    let lo_hi = bounds.to_f32();
    let names = || clip.targets.iter().map(|t| t.name.as_str());

    let _ = writeln!(out, "def SkelRoot \"{root}\"\n{{");
    push_attr(&mut out, 4, "float3[] extent", |o| push_vec3s(o, lo_hi.iter()));
    out.push('\n');
    out.push_str("    def Mesh \"Mesh\" (\n        prepend apiSchemas = [\"SkelBindingAPI\"]\n    )\n    {\n");
    push_attr(&mut out, 8, "float3[] extent", |o| push_vec3s(o, extent(&clip.base).iter()));
    push_topology(&mut out, triangles);
    push_mesh_attributes(&mut out, triangles, clip.vertex_count(), attributes);
    push_attr(&mut out, 8, "point3f[] points", |o| push_vec3s(o, clip.base.iter()));
    push_attr(&mut out, 8, "uniform token[] skel:blendShapes", |o| push_tokens(o, names()));
    push_attr(&mut out, 8, "rel skel:blendShapeTargets", |o| {
        push_list(o, names(), |o, n| {
            let _ = write!(o, "</{root}/Mesh/{n}>");
        })
    });
    let _ = writeln!(out, "        rel skel:skeleton = </{root}/Skel>");
    out.push_str("        uniform token subdivisionScheme = \"none\"\n");
    let n = clip.vertex_count();
    for target in &clip.targets {
        let _ = writeln!(out, "\n        def BlendShape \"{}\"\n        {{", target.name);
        if super::sparse_is_smaller(target.indices.len(), n, 4) {
            push_attr(&mut out, 12, "uniform vector3f[] offsets", |o| push_vec3s(o, target.offsets.iter()));
            push_attr(&mut out, 12, "uniform int[] pointIndices", |o| push_ints(o, target.indices.iter().copied()));
        } else {
            let mut dense = vec![[0.0f32; 3]; n];
            for (&i, o) in target.indices.iter().zip(&target.offsets) {
                dense[i as usize] = *o;
            }
            push_attr(&mut out, 12, "uniform vector3f[] offsets", |o| push_vec3s(o, dense.iter()));
        }
        out.push_str("        }\n");
    }
    if let Some(a) = attributes.filter(|a| !a.groups.is_empty()) {
        attrs::push_subsets(&mut out, a, root);
    }
    out.push_str("    }\n\n");
    if let Some(a) = attributes.filter(|a| !a.groups.is_empty()) {
        attrs::push_materials(&mut out, a, root);
        out.push('\n');
    }

    out.push_str("    def Skeleton \"Skel\" (\n        prepend apiSchemas = [\"SkelBindingAPI\"]\n    )\n    {\n");
    out.push_str("        uniform token[] joints = []\n");
    let _ = writeln!(out, "        rel skel:animationSource = </{root}/Skel/Anim>\n");
    out.push_str("        def SkelAnimation \"Anim\"\n        {\n");
    push_attr(&mut out, 12, "uniform token[] blendShapes", |o| push_tokens(o, names()));
    out.push_str("            float[] blendShapeWeights.timeSamples = {\n");
    for ((frame, _), w) in frames.iter().zip(&weights) {
        let _ = write!(out, "                {frame}: ");
        push_list(&mut out, w.iter(), |o, &x| push_f32(o, x as f32));
        out.push_str(",\n");
    }
    out.push_str("            }\n        }\n    }\n}\n");
    out
}

/// Full-frame animation: `points.timeSamples` at every frame.
pub fn full_frame(frames: &FullFrame, triangles: &[[u32; 3]], attributes: Option<&CornerAttributes>, settings: &UsdSettings) -> String {
    let (first, last) = (frames.frames[0], frames.frames[frames.frames.len() - 1]);
    let mut out = header(settings, first, last);
    let _ = writeln!(out, "def Xform \"{}\"\n{{\n    def Mesh \"Mesh\"\n    {{", settings.name);
    out.push_str("        float3[] extent.timeSamples = {\n");
    for (frame, points) in frames.frames.iter().zip(&frames.points) {
        let _ = write!(out, "            {frame}: ");
        push_vec3s(&mut out, extent(points).iter());
        out.push_str(",\n");
    }
    out.push_str("        }\n");
    push_topology(&mut out, triangles);
    let vertices = frames.points.first().map_or(0, Vec::len);
    push_mesh_attributes(&mut out, triangles, vertices, attributes);
    out.push_str("        point3f[] points.timeSamples = {\n");
    for (frame, points) in frames.frames.iter().zip(&frames.points) {
        let _ = write!(out, "            {frame}: ");
        push_vec3s(&mut out, points.iter());
        out.push_str(",\n");
    }
    out.push_str("        }\n        uniform token subdivisionScheme = \"none\"\n");
    close_mesh_and_root(&mut out, attributes, &settings.name);
    out
}

fn push_mesh_attributes(out: &mut String, triangles: &[[u32; 3]], vertices: usize, attributes: Option<&CornerAttributes>) {
    if let Some(a) = attributes {
        attrs::push_properties(out, triangles, vertices, a);
    }
}

/// `}` of a plain mesh (after its subsets) and of its root (after the materials).
fn close_mesh_and_root(out: &mut String, attributes: Option<&CornerAttributes>, root: &str) {
    let groups = attributes.filter(|a| !a.groups.is_empty());
    if let Some(a) = groups {
        attrs::push_subsets(out, a, root);
    }
    out.push_str("    }\n");
    if let Some(a) = groups {
        attrs::push_materials(out, a, root);
    }
    out.push_str("}\n");
}

pub(crate) fn header(s: &UsdSettings, start: i64, end: i64) -> String {
    format!(
        "#usda 1.0\n(\n    defaultPrim = \"{name}\"\n    doc = \"blendsim {version}\"\n    endTimeCode = {end}\n    \
         framesPerSecond = {fps}\n    metersPerUnit = {mpu}\n    startTimeCode = {start}\n    \
         timeCodesPerSecond = {fps}\n    upAxis = \"{up}\"\n)\n\n",
        name = s.name,
        version = env!("CARGO_PKG_VERSION"),
        fps = s.fps,
        mpu = s.meters_per_unit,
        up = s.up_axis,
    )
}

/// Triangles as USD faces; our triangles are counter-clockwise seen from outside, which is
/// USD's `rightHanded` orientation.
pub(crate) fn push_topology(out: &mut String, triangles: &[[u32; 3]]) {
    push_attr(out, 8, "int[] faceVertexCounts", |o| push_list(o, triangles.iter(), |o, _| o.push('3')));
    push_attr(out, 8, "int[] faceVertexIndices", |o| push_ints(o, triangles.iter().flatten().copied()));
    out.push_str("        uniform token orientation = \"rightHanded\"\n");
}

/// `[(lo), (hi)]` of a point set (zeros when empty).
pub(crate) fn extent(points: &[[f32; 3]]) -> [[f32; 3]; 2] {
    Bounds::of_f32(points).to_f32()
}

/// `INDENT DECLARATION = VALUE\n`.
pub(super) fn push_attr(out: &mut String, indent: usize, declaration: &str, value: impl FnOnce(&mut String)) {
    let _ = write!(out, "{:indent$}{declaration} = ", "");
    value(out);
    out.push('\n');
}

pub(super) fn push_list<T>(out: &mut String, items: impl Iterator<Item = T>, mut item: impl FnMut(&mut String, T)) {
    out.push('[');
    for (i, x) in items.enumerate() {
        if i > 0 {
            out.push_str(", ");
        }
        item(out, x);
    }
    out.push(']');
}

pub(super) fn push_ints(out: &mut String, items: impl Iterator<Item = u32>) {
    push_list(out, items, |o, i| {
        let _ = write!(o, "{i}");
    });
}

fn push_tokens<'a>(out: &mut String, items: impl Iterator<Item = &'a str>) {
    push_list(out, items, |o, s| {
        let _ = write!(o, "\"{s}\"");
    });
}

pub(crate) fn push_vec3s<'a>(out: &mut String, items: impl Iterator<Item = &'a [f32; 3]>) {
    push_list(out, items, |o, p| {
        o.push('(');
        push_f32(o, p[0]);
        o.push_str(", ");
        push_f32(o, p[1]);
        o.push_str(", ");
        push_f32(o, p[2]);
        o.push(')');
    });
}

/// The shorter of `{}` and `{:e}`: both are the shortest round-trip digits of the f32, and the
/// exponent form keeps tiny offsets (`1.5e-9`) from spelling out their leading zeros.
pub(super) fn push_f32(out: &mut String, x: f32) {
    let start = out.len();
    let _ = write!(out, "{x}");
    // Only runs of zeros make the exponent form shorter; skip formatting it otherwise.
    let plain = &out[start..];
    if plain.contains("0.00") || plain.ends_with("000") {
        let exp = format!("{x:e}");
        if exp.len() < out.len() - start {
            out.truncate(start);
            out.push_str(&exp);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::export::clip::{Target, WeightCurve};

    fn settings() -> UsdSettings {
        UsdSettings { name: "box".into(), fps: 10.0, up_axis: 'Z', meters_per_unit: 0.01 }
    }

    fn f32s(values: &[f32]) -> String {
        let mut s = String::new();
        push_list(&mut s, values.iter(), |o, &x| push_f32(o, x));
        s
    }

    #[test]
    fn floats_are_shortest_round_trip() {
        assert_eq!(f32s(&[1.0, 0.1, -2.5, 1e-9, 1.5e-7, 123456790.0, 1e20, 0.0]), "[1, 0.1, -2.5, 1e-9, 1.5e-7, 123456790, 1e20, 0]");
        for x in [0.1f32, 1.0 / 3.0, 7.0e-12, 3.4e38, -f32::MIN_POSITIVE] {
            let mut s = String::new();
            push_f32(&mut s, x);
            assert_eq!(s.parse::<f32>().unwrap(), x, "{s}");
        }
    }

    #[test]
    fn prim_names_are_identifiers() {
        assert_eq!(prim_name("twist-box.v2"), "twist_box_v2");
        assert_eq!(prim_name("3dbox"), "_3dbox");
        assert_eq!(prim_name("_ok"), "_ok");
    }

    /// Four vertices; `sparse` moves one of them, `dense` moves all four.
    fn clip() -> BlendShapeClip {
        let curve = || WeightCurve { values: vec![0.0, 1.0], in_tangents: vec![0.0; 2], out_tangents: vec![0.0; 2] };
        BlendShapeClip {
            base: vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            targets: vec![
                Target { name: "sparse".into(), indices: vec![2], offsets: vec![[0.0, 0.5, 0.0]] },
                Target { name: "dense".into(), indices: vec![0, 1, 2, 3], offsets: vec![[0.25, 0.0, 0.0]; 4] },
            ],
            times: vec![0.0, 0.2],
            curves: vec![curve(), curve()],
        }
    }

    #[test]
    fn blendshape_layout() {
        let text = blendshapes(&clip(), &[[0, 2, 1], [0, 1, 3]], None, &settings());
        assert!(text.starts_with("#usda 1.0\n(\n    defaultPrim = \"box\"\n"), "{text}");
        for line in [
            "    endTimeCode = 2\n",
            "    startTimeCode = 0\n",
            "    timeCodesPerSecond = 10\n",
            "    upAxis = \"Z\"\n",
            "    metersPerUnit = 0.01\n",
            "def SkelRoot \"box\"\n",
            "    float3[] extent = [(0, 0, 0), (1.25, 1.5, 1)]\n",
            "        int[] faceVertexCounts = [3, 3]\n",
            "        int[] faceVertexIndices = [0, 2, 1, 0, 1, 3]\n",
            "        rel skel:blendShapeTargets = [</box/Mesh/sparse>, </box/Mesh/dense>]\n",
            "            uniform vector3f[] offsets = [(0, 0.5, 0)]\n            uniform int[] pointIndices = [2]\n",
            "            uniform vector3f[] offsets = [(0.25, 0, 0), (0.25, 0, 0), (0.25, 0, 0), (0.25, 0, 0)]\n        }\n",
            "        rel skel:animationSource = </box/Skel/Anim>\n",
            "                0: [0, 0],\n                1: [0.5, 0.5],\n                2: [1, 1],\n            }\n",
        ] {
            assert!(text.contains(line), "missing {line:?} in\n{text}");
        }
    }

    #[test]
    fn a_static_clip_is_a_plain_mesh() {
        let mut c = clip();
        c.targets.clear();
        c.curves.clear();
        let text = blendshapes(&c, &[[0, 2, 1]], None, &settings());
        assert!(text.contains("def Xform \"box\"\n{\n    def Mesh \"Mesh\"\n"), "{text}");
        assert!(!text.contains("Skel"), "{text}");
    }

    #[test]
    fn full_frame_layout() {
        let ff = FullFrame { frames: vec![3, 4], times: vec![0.3, 0.4], points: vec![vec![[0.0; 3], [1.0; 3]], vec![[0.0; 3], [2.0; 3]]] };
        let text = full_frame(&ff, &[[0, 1, 1]], None, &settings());
        assert!(text.contains("    endTimeCode = 4\n"), "{text}");
        assert!(text.contains("    startTimeCode = 3\n"), "{text}");
        assert!(text.contains("            4: [(0, 0, 0), (2, 2, 2)],\n"), "{text}");
        assert_eq!(text.matches("3: [(0, 0, 0), (1, 1, 1)],\n").count(), 2, "extent and points at frame 3:\n{text}");
    }
}
