//! USD ASCII: a `Layer` (`export::layer`) as `.usda` text. Layout in `formats/usd.md`.
//!
//! Written as text directly (no USD library in Rust): the layout is small and fixed, and
//! writing it ourselves keeps the bytes deterministic. Floats are f32 in their shortest
//! round-trip form, so reading the file back gives exactly the values we hold. The streaming
//! helpers below (`header`, `push_topology`, `push_vec3s`) also serve the vertex-cache writer,
//! which writes frames as they come instead of building a layer.

use std::fmt::Write;

use super::float_text::{f32_text, ROOM};
use super::layer::{Attribute, Layer, Prim, Property, Value};
pub(crate) use super::usd::extent;
pub use super::usd::{prim_name, UsdSettings};
use crate::algorithms::blendshape::clip::BlendShapeClip;
use crate::algorithms::blendshape::fullframe::FullFrame;
use crate::algorithms::geometry::attributes::CornerAttributes;

/// `usd::blendshapes` as text.
pub fn blendshapes(clip: &BlendShapeClip, triangles: &[[u32; 3]], attributes: Option<&CornerAttributes>, settings: &UsdSettings) -> String {
    text(&super::usd::blendshapes(clip, triangles, attributes, settings))
}

/// `usd::full_frame` as text.
pub fn full_frame(frames: &FullFrame, triangles: &[[u32; 3]], attributes: Option<&CornerAttributes>, settings: &UsdSettings) -> String {
    text(&super::usd::full_frame(frames, triangles, attributes, settings))
}

/// The layer as `.usda` text: metadata, then each prim with its properties, then its children
/// (a blank line before a child that follows anything).
pub fn text(layer: &Layer) -> String {
    let mut out = String::new();
    push_layer(&mut out, layer, &mut None);
    out
}

/// `text(&usd::full_frame(frames, ..))` written to `file` as it is made: the points are
/// formatted from `frames` in pieces of 65,536 points, a batch of them at once on
/// the thread pool while the batch before is written, so neither the text (2.7 GB at 538k
/// vertices x 136 frames) nor a copy of the points is held. The same bytes on any number of
/// threads. `weld_map`: as `usd::full_frame_unsampled`.
pub fn write_full_frame(
    frames: &FullFrame,
    triangles: &[[u32; 3]],
    attributes: Option<&CornerAttributes>,
    settings: &UsdSettings,
    weld_map: Option<&[u32]>,
    file: &mut dyn std::io::Write,
) -> std::io::Result<()> {
    let layer = super::usd::full_frame_unsampled(frames, triangles, attributes, settings, weld_map);
    let mut stream = Some(Streamed { attribute: super::usd::points_path(settings), frames, file, failed: None });
    let mut out = String::new();
    push_layer(&mut out, &layer, &mut stream);
    let Some(Streamed { file, failed, .. }) = stream else { unreachable!("taken only here") };
    match failed {
        Some(e) => Err(e),
        None => file.write_all(out.as_bytes()),
    }
}

/// The points of a full-frame layer written from the frames (`write_full_frame`).
struct Streamed<'a> {
    /// The points attribute's path; the layer holds no samples for it.
    attribute: String,
    frames: &'a FullFrame,
    file: &'a mut dyn std::io::Write,
    /// The first write that failed (nothing is written after it).
    failed: Option<std::io::Error>,
}

impl Streamed<'_> {
    /// Write `bytes` unless a write failed before.
    fn write(&mut self, bytes: &[u8]) {
        if self.failed.is_none() {
            if let Err(e) = self.file.write_all(bytes) {
                self.failed = Some(e);
            }
        }
    }

    /// The samples `INDENT FRAME: [(x, y, z), ...],` of the frames, after `out` (passed on
    /// first). A frame's points are cut into pieces whose texts are independent, so a batch of
    /// pieces is formatted in parallel (two per thread, about 2.4 MB of text each) while the
    /// batch before is written: memory bounded by two batches, the bytes in order.
    fn samples(&mut self, out: &mut String, indent: usize) {
        self.write(out.as_bytes());
        out.clear();
        let frames = self.frames;
        let pieces: Vec<(usize, usize)> = frames
            .points
            .iter()
            .enumerate()
            .flat_map(|(f, points)| (0..points.len().div_ceil(POINTS_PER_PIECE).max(1)).map(move |p| (f, p * POINTS_PER_PIECE)))
            .collect();
        let batch = 2 * rayon::current_num_threads().max(1);
        let text = |&(f, start): &(usize, usize), text: &mut Vec<u8>| {
            let points = &frames.points[f];
            let end = (start + POINTS_PER_PIECE).min(points.len());
            text.clear();
            text.reserve((end - start) * 54 + indent + 32);
            if start == 0 {
                let mut label = String::new();
                let _ = write!(label, "{:indent$}{}: [", "", frames.frames[f] as f64);
                text.extend_from_slice(label.as_bytes());
            }
            push_piece_bytes(text, &points[start..end], start);
            if end == points.len() {
                text.extend_from_slice(b"],\n");
            }
        };
        let mut ready: Vec<Vec<u8>> = Vec::new();
        let mut next: Vec<Vec<u8>> = Vec::new();
        for chunk in pieces.chunks(batch) {
            next.resize_with(chunk.len(), Vec::new);
            rayon::in_place_scope(|scope| {
                for (piece, buffer) in chunk.iter().zip(next.iter_mut()) {
                    scope.spawn(move |_| text(piece, buffer));
                }
                ready.iter().for_each(|t| self.write(t));
            });
            std::mem::swap(&mut ready, &mut next);
        }
        ready.iter().for_each(|t| self.write(t));
    }
}

/// Points per piece of a streamed sample's text (about 2.4 MB of it).
const POINTS_PER_PIECE: usize = 1 << 16;

fn push_layer(out: &mut String, layer: &Layer, stream: &mut Option<Streamed<'_>>) {
    out.push_str("#usda 1.0\n(\n");
    for (key, value) in &layer.metadata {
        let _ = write!(out, "    {key} = ");
        push_value(out, value);
        out.push('\n');
    }
    out.push_str(")\n\n");
    for (i, prim) in layer.prims.iter().enumerate() {
        if i > 0 {
            out.push('\n');
        }
        push_prim(out, prim, "", 0, stream);
    }
}

fn push_prim(out: &mut String, prim: &Prim, parent: &str, indent: usize, stream: &mut Option<Streamed<'_>>) {
    let path = format!("{parent}/{}", prim.name);
    let _ = write!(out, "{:indent$}def {} \"{}\"", "", prim.type_name, prim.name);
    if !prim.api_schemas.is_empty() {
        let _ = write!(out, " (\n{:w$}prepend apiSchemas = ", "", w = indent + 4);
        push_list(out, prim.api_schemas.iter(), |o, s| {
            let _ = write!(o, "\"{s}\"");
        });
        let _ = write!(out, "\n{:indent$})", "");
    }
    let _ = writeln!(out, "\n{:indent$}{{", "");
    let inner = indent + 4;
    for property in &prim.properties {
        let _ = write!(out, "{:inner$}", "");
        match property {
            Property::Attribute(a) => {
                let streamed = stream.as_mut().filter(|s| a.samples.is_empty() && s.attribute == format!("{path}.{}", a.name));
                push_attribute(out, a, inner, streamed)
            }
            Property::Relationship { name, targets } => {
                let _ = write!(out, "rel {name} = ");
                if let [one] = &targets[..] {
                    let _ = write!(out, "<{one}>");
                } else {
                    push_list(out, targets.iter(), |o, t| {
                        let _ = write!(o, "<{t}>");
                    });
                }
            }
        }
        out.push('\n');
    }
    for (i, child) in prim.children.iter().enumerate() {
        if i > 0 || !prim.properties.is_empty() {
            out.push('\n');
        }
        push_prim(out, child, &path, inner, stream);
    }
    let _ = writeln!(out, "{:indent$}}}", "");
}

/// `streamed`: the attribute's samples are the frames' points (see [`write_full_frame`]).
fn push_attribute(out: &mut String, a: &Attribute, indent: usize, streamed: Option<&mut Streamed<'_>>) {
    let _ = write!(out, "{}{} {}", if a.uniform { "uniform " } else { "" }, a.type_name, a.name);
    if let Some(path) = &a.connection {
        let _ = write!(out, ".connect = <{path}>");
    } else if let Some(s) = streamed {
        // As the samples below, with each `Value::Vec3fs` taken from the frames.
        out.push_str(".timeSamples = {\n");
        s.samples(out, indent + 4);
        let _ = write!(out, "{:indent$}}}", "");
    } else if !a.samples.is_empty() {
        out.push_str(".timeSamples = {\n");
        for (time, value) in &a.samples {
            let _ = write!(out, "{:w$}{time}: ", "", w = indent + 4);
            push_value(out, value);
            out.push_str(",\n");
        }
        let _ = write!(out, "{:indent$}}}", "");
    } else if let Some(value) = &a.default {
        out.push_str(" = ");
        push_value(out, value);
    }
    if let Some(interpolation) = a.interpolation {
        let _ = write!(out, " (\n{:w$}interpolation = \"{interpolation}\"\n{:indent$})", "", "", w = indent + 4);
    }
}

fn push_value(out: &mut String, value: &Value) {
    match value {
        Value::Token(s) | Value::String(s) => push_quoted(out, s),
        Value::Asset(s) => {
            let _ = write!(out, "@{s}@");
        }
        Value::Double(x) => {
            let _ = write!(out, "{x}");
        }
        Value::Float(x) => push_f32(out, *x),
        Value::Vec3f(v) => push_vec3(out, v),
        Value::Tokens(items) => push_list(out, items.iter(), |o, s| push_quoted(o, s)),
        Value::Ints(items) => push_list(out, items.iter(), |o, i| {
            let _ = write!(o, "{i}");
        }),
        Value::Floats(items) => push_list(out, items.iter(), |o, &x| push_f32(o, x)),
        Value::Vec2fs(items) => push_list(out, items.iter(), |o, [u, v]| {
            o.push('(');
            push_f32(o, *u);
            o.push_str(", ");
            push_f32(o, *v);
            o.push(')');
        }),
        Value::Vec3fs(items) => push_vec3_array(out, items),
    }
}

/// `[(x, y, z), ...]`; a long array (a dense blendshape target's offsets, hundreds of MB of
/// text at a million vertices) is formatted in pieces of [`POINTS_PER_PIECE`] on the pool and
/// joined in order, as the full-frame samples are: the same bytes on any number of threads.
fn push_vec3_array(out: &mut String, items: &[[f32; 3]]) {
    use rayon::prelude::*;
    if items.len() <= POINTS_PER_PIECE {
        return push_vec3s(out, items.iter());
    }
    let pieces: Vec<Vec<u8>> = items
        .par_chunks(POINTS_PER_PIECE)
        .enumerate()
        .map(|(i, chunk)| {
            let mut text = Vec::with_capacity(chunk.len() * 54);
            push_piece_bytes(&mut text, chunk, i * POINTS_PER_PIECE);
            text
        })
        .collect();
    out.reserve(pieces.iter().map(Vec::len).sum::<usize>() + 2);
    out.push('[');
    for piece in &pieces {
        out.push_str(std::str::from_utf8(piece).expect("ASCII"));
    }
    out.push(']');
}

/// A quoted string, with the escapes USD's text format reads (`\\`, `\"`, `\n`).
fn push_quoted(out: &mut String, s: &str) {
    out.push('"');
    for c in s.chars() {
        match c {
            '\\' => out.push_str("\\\\"),
            '"' => out.push_str("\\\""),
            '\n' => out.push_str("\\n"),
            c => out.push(c),
        }
    }
    out.push('"');
}

/// The layer header of a streamed file (a vertex cache's), `doc` its documentation string
/// (plain text: no quote or backslash).
pub(crate) fn header(s: &UsdSettings, doc: &str, start: i64, end: i64) -> String {
    format!(
        "#usda 1.0\n(\n    defaultPrim = \"{name}\"\n    doc = \"{doc}\"\n    endTimeCode = {end}\n    \
         framesPerSecond = {fps}\n    metersPerUnit = {mpu}\n    startTimeCode = {start}\n    \
         timeCodesPerSecond = {fps}\n    upAxis = \"{up}\"\n)\n\n",
        name = s.name,
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

pub(crate) fn push_vec3s<'a>(out: &mut String, items: impl Iterator<Item = &'a [f32; 3]>) {
    push_list(out, items, push_vec3);
}

fn push_vec3(out: &mut String, p: &[f32; 3]) {
    let mut text = [0; VEC3_ROOM];
    let n = vec3_text(p, &mut text);
    out.push_str(std::str::from_utf8(&text[..n]).expect("ASCII"));
}

/// The shorter of `{}` and `{:e}` (`float_text`): both are the shortest round-trip digits of
/// the f32, and the exponent form keeps tiny offsets (`1.5e-9`) from spelling out their
/// leading zeros.
pub(super) fn push_f32(out: &mut String, x: f32) {
    let mut buffer = [0; ROOM];
    let n = f32_text(x, &mut buffer);
    out.push_str(std::str::from_utf8(&buffer[..n]).expect("ASCII"));
}

/// `points`, the piece of an array's text that starts at its point `start`: each point after
/// `, ` but the array's first. The pieces of an array, joined in order, are its text.
fn push_piece_bytes(out: &mut Vec<u8>, points: &[[f32; 3]], start: usize) {
    for (i, p) in points.iter().enumerate() {
        if start + i > 0 {
            out.extend_from_slice(b", ");
        }
        push_vec3_bytes(out, p);
    }
}

/// `push_vec3` into bytes, one append per point.
fn push_vec3_bytes(out: &mut Vec<u8>, p: &[f32; 3]) {
    let mut text = [0; VEC3_ROOM];
    let n = vec3_text(p, &mut text);
    out.extend_from_slice(&text[..n]);
}

/// The room [`vec3_text`] needs: the third float starts at most 37 bytes in (a parenthesis,
/// two floats of at most 16 bytes, two separators) and needs [`ROOM`] from there.
const VEC3_ROOM: usize = 37 + ROOM;

/// `(x, y, z)` at the start of `out` (at least [`VEC3_ROOM`] bytes, at most 54 of them
/// written); its length.
fn vec3_text(p: &[f32; 3], out: &mut [u8]) -> usize {
    out[0] = b'(';
    let mut at = 1;
    for (i, &x) in p.iter().enumerate() {
        if i > 0 {
            out[at] = b',';
            out[at + 1] = b' ';
            at += 2;
        }
        at += f32_text(x, &mut out[at..]);
    }
    out[at] = b')';
    at + 1
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::algorithms::blendshape::clip::{Target, WeightCurve};

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

    /// A long array formatted in pieces on the pool is the text of one pass over it, on the
    /// pool and on one thread.
    #[test]
    fn long_arrays_in_pieces_are_one_pass() {
        let items: Vec<[f32; 3]> = (0..2 * POINTS_PER_PIECE + 7).map(|i| [i as f32 * 0.001, -(i as f32).sqrt(), 1.0 / (1 + i) as f32]).collect();
        let mut want = String::new();
        push_vec3s(&mut want, items.iter());
        let mut got = String::new();
        push_vec3_array(&mut got, &items);
        assert!(got == want);
        let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
        got.clear();
        one.install(|| push_vec3_array(&mut got, &items));
        assert!(got == want, "on one thread");
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

    /// The full-frame text written in pieces from the frames is the text of the layer holding
    /// them, byte for byte, also with material groups (prims after the mesh), with each frame
    /// cut into several pieces, on the pool and on one thread; a failing write is an error.
    #[test]
    fn full_frame_written_in_pieces_is_the_text_of_the_held_layer() {
        use crate::algorithms::geometry::attributes::CornerAttributes;
        let n = 140_000;
        let triangles: Vec<[u32; 3]> = (0..n as u32 - 2).map(|i| [i, i + 1, i + 2]).collect();
        let pose = |k: usize| -> Vec<[f32; 3]> { (0..n).map(|a| [a as f32 * 0.001, (k as f32 * 0.37).sin(), -0.5 * (a * k) as f32]).collect() };
        let frames = FullFrame { frames: vec![-1, 0, 1, 2], times: vec![-0.1, 0.0, 0.1, 0.2], points: (0..4).map(pose).collect() };
        let groups = CornerAttributes {
            groups: vec!["a".into(), "b".into()],
            triangle_groups: (0..n - 2).map(|t| (t % 2) as u32).collect(),
            ..Default::default()
        };
        for attributes in [None, Some(&groups)] {
            let want = text(&crate::formats::export::usd::full_frame(&frames, &triangles, attributes, &settings()));
            assert!(n > 2 * POINTS_PER_PIECE, "several pieces per frame");
            let mut got = Vec::new();
            write_full_frame(&frames, &triangles, attributes, &settings(), None, &mut got).unwrap();
            assert!(got == want.as_bytes());
            let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
            got.clear();
            one.install(|| write_full_frame(&frames, &triangles, attributes, &settings(), None, &mut got)).unwrap();
            assert!(got == want.as_bytes(), "on one thread");
        }
        struct Full(usize);
        impl std::io::Write for Full {
            fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
                if self.0 < buf.len() {
                    return Err(std::io::Error::new(std::io::ErrorKind::StorageFull, "disk full"));
                }
                self.0 -= buf.len();
                Ok(buf.len())
            }
            fn flush(&mut self) -> std::io::Result<()> {
                Ok(())
            }
        }
        let e = write_full_frame(&frames, &triangles, None, &settings(), None, &mut Full(1 << 20)).unwrap_err();
        assert_eq!(e.kind(), std::io::ErrorKind::StorageFull);
    }
}
