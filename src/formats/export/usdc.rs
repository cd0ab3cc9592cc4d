//! USD binary ("crate", `.usdc`) files written natively from a `Layer`, the same layer the
//! `.usda` text holds, so usd-core reads both as one layer.
//!
//! Version 0.8.0 of the format, the one usd-core writes by default: usd-core 26.11 refuses
//! files older than 0.4.0, and every version from 0.4.0 on stores the structural sections
//! (tokens, fields, field sets, paths, specs) compressed, so 0.8.0 costs the writer nothing
//! more than the oldest readable one while being read by every USD that reads usd-core's own
//! files. Layout (all little-endian):
//!
//! - bootstrap: `PXR-USDC`, the version bytes, the table of contents' offset;
//! - the values that do not fit in a field's 48-bit payload (arrays, time samples, list ops,
//!   doubles...), each at an offset its field points to; arrays 8-byte aligned, `u64` count
//!   then the elements; int arrays of 16 or more compressed like usd-core does, float arrays
//!   stored plain (usd-core stores vectors plain too, and scalar float arrays plain unless
//!   they are integral or take few distinct values);
//! - TOKENS (every name, null-terminated), STRINGS (tokens used as strings), FIELDS (name token
//!   and value representation), FIELDSETS (each spec's fields, ~0-terminated), PATHS (the path
//!   tree, depth first), SPECS (path, field set, spec type);
//! - the table of contents: each section's name, start and size.
//!
//! Format reference: usd-core's `crateFile.cpp`; checked by reading our files back with
//! usd-core in the test suite.

mod compression;

use std::collections::{HashMap, HashSet};
use std::fs::File;
use std::io::{BufWriter, Seek, SeekFrom, Write};
use std::os::unix::fs::FileExt;
use std::path::Path;

use self::compression::{compressed_ints, fast_compression};
use super::layer::{Attribute, Layer, Prim, Property, Value};
use super::usd::{self, UsdSettings};
use crate::algorithms::blendshape::fullframe::FullFrame;
use crate::algorithms::geometry::attributes::CornerAttributes;
use crate::support::error::{Error, Result};

const VERSION: [u8; 3] = [0, 8, 0];

/// usd-core's type numbers of the values we write (crateDataTypes.h).
mod ty {
    pub(crate) const BOOL: u64 = 1;
    pub(crate) const INT: u64 = 3;
    pub const FLOAT: u64 = 8;
    pub(crate) const DOUBLE: u64 = 9;
    pub(crate) const STRING: u64 = 10;
    pub(crate) const TOKEN: u64 = 11;
    pub(crate) const ASSET_PATH: u64 = 12;
    pub(crate) const VEC2F: u64 = 20;
    pub(crate) const VEC3F: u64 = 24;
    pub(crate) const TOKEN_LIST_OP: u64 = 32;
    pub(crate) const PATH_LIST_OP: u64 = 34;
    pub(crate) const PATH_VECTOR: u64 = 40;
    pub(crate) const TOKEN_VECTOR: u64 = 41;
    pub(crate) const SPECIFIER: u64 = 42;
    pub(crate) const VARIABILITY: u64 = 44;
    pub(crate) const TIME_SAMPLES: u64 = 46;
    pub(crate) const DOUBLE_VECTOR: u64 = 48;
}

/// `SdfSpecType` numbers.
mod spec {
    pub(crate) const ATTRIBUTE: u32 = 1;
    pub(crate) const CONNECTION: u32 = 2;
    pub(crate) const PRIM: u32 = 6;
    pub(crate) const PSEUDO_ROOT: u32 = 7;
    pub(crate) const RELATIONSHIP: u32 = 8;
    pub(crate) const RELATIONSHIP_TARGET: u32 = 9;
}

const ARRAY_BIT: u64 = 1 << 63;
const INLINED_BIT: u64 = 1 << 62;
const COMPRESSED_BIT: u64 = 1 << 61;
const PAYLOAD_MASK: u64 = (1 << 48) - 1;
/// usd-core compresses int arrays from this length on.
const MIN_COMPRESSED_ARRAY: usize = 16;

/// A value representation: type, flags and a 48-bit payload (an inlined value or an offset).
fn rep(ty: u64, payload: u64) -> u64 {
    (ty << 48) | (payload & PAYLOAD_MASK)
}

fn inlined(ty: u64, payload: u32) -> u64 {
    rep(ty, payload as u64) | INLINED_BIT
}

/// The `.usdc` bytes of `layer`. `path` (the file it will be written to) only names the file
/// in errors: a value the format cannot hold (a NUL byte in a name or string) or a non-finite
/// number (a corrupted animation) is refused with a one-line error instead of a file.
pub fn bytes(layer: &Layer, path: &Path) -> Result<Vec<u8>> {
    check(layer).map_err(|problem| {
        Error::in_file(path, format!("cannot write the usdc file: {problem}"), "re-run the bake; if it persists, report the scene that makes it")
    })?;
    let mut w = Writer::default();
    w.out.extend_from_slice(&[0; 88]);
    w.layer(layer);
    match w.finish() {
        Out::Memory(bytes) => Ok(bytes),
        Out::File { .. } => unreachable!("written to memory"),
    }
}

/// One attribute's time samples produced one at a time while the file is written, instead of
/// held in the layer: a vertex cache's points (40k vertices x 150 frames is 72 MB as `f32`)
/// are then held once, as the file's bytes, with one frame's buffer reused.
pub struct StreamedSamples<'a> {
    /// The attribute's path (`/Root/Mesh.points`); it has no samples in the layer.
    pub attribute: String,
    /// The sample times, in order.
    pub times: &'a [f64],
    /// Sample `i`'s values into the buffer (its length is the reader's to set).
    pub read: &'a mut SampleReader<'a>,
}

/// Reads sample `i`'s values into a buffer (see [`StreamedSamples`]).
pub(crate) type SampleReader<'a> = dyn FnMut(usize, &mut Vec<[f32; 3]>) -> Result<()> + 'a;

/// [`bytes`] with the samples of `streamed.attribute` read from `streamed` as they are written:
/// the same bytes as [`bytes`] of the layer holding them.
pub fn bytes_streamed(layer: &Layer, path: &Path, streamed: StreamedSamples<'_>) -> Result<Vec<u8>> {
    match written(layer, path, streamed, Out::Memory(Vec::new()))? {
        Out::Memory(bytes) => Ok(bytes),
        Out::File { .. } => unreachable!("written to memory"),
    }
}

/// [`bytes_streamed`] written into `file` (opened for reading too: equal values are compared by reading back) as the bytes
/// are produced, through a buffer: the file is never held whole, however many samples it has.
/// `path` names the file in errors.
pub fn write_streamed(layer: &Layer, path: &Path, streamed: StreamedSamples<'_>, file: File) -> Result<()> {
    flushed(written(layer, path, streamed, Out::File { w: BufWriter::new(file), len: 0, error: None })?, path)
}

/// The end of a file written through [`Out::File`]: its buffer flushed, or its first error.
fn flushed(out: Out, path: &Path) -> Result<()> {
    match out {
        Out::File { mut w, error: None, .. } => w.flush().map_err(|e| Error::io(path, &e, "write the usdc file")),
        Out::File { error: Some(e), .. } => Err(Error::io(path, &e, "write the usdc file")),
        Out::Memory(_) => unreachable!("written to a file"),
    }
}

/// The file of `layer` with `streamed`'s samples, into `out`.
fn written(layer: &Layer, path: &Path, streamed: StreamedSamples<'_>, out: Out) -> Result<Out> {
    let unwritable = |problem: String| {
        Error::in_file(path, format!("cannot write the usdc file: {problem}"), "re-run the bake; if it persists, report the scene that makes it")
    };
    check(layer).map_err(unwritable)?;
    if streamed.times.iter().any(|t| !t.is_finite()) {
        return Err(unwritable(format!("{} has a non-finite sample time", streamed.attribute)));
    }
    let mut w = Writer { streamed: Some(streamed), out, ..Writer::default() };
    w.out.extend_from_slice(&[0; 88]);
    w.layer(layer);
    match w.failed.take() {
        Some(Failure::Read(e)) => Err(e),
        Some(Failure::Value(problem)) => Err(unwritable(problem)),
        None => Ok(w.finish()),
    }
}

/// The `.usdc` bytes of the full-frame layer (`usd::full_frame`), the same bytes as [`bytes`]
/// of it, with the points streamed from `frames` instead of copied into the layer. `weld_map`: as
/// `usd::full_frame_unsampled`.
pub fn full_frame(
    frames: &FullFrame,
    triangles: &[[u32; 3]],
    attributes: Option<&CornerAttributes>,
    settings: &UsdSettings,
    weld_map: Option<&[u32]>,
    path: &Path,
) -> Result<Vec<u8>> {
    full_frame_into(frames, triangles, attributes, settings, weld_map, path, Out::Memory(Vec::new())).map(|out| match out {
        Out::Memory(bytes) => bytes,
        Out::File { .. } => unreachable!("written to memory"),
    })
}

/// [`full_frame`] written into `file` (opened for reading too) as it is produced: a large
/// animation's frames are held by `frames` only, never a second time as the file's bytes.
pub fn write_full_frame(
    frames: &FullFrame,
    triangles: &[[u32; 3]],
    attributes: Option<&CornerAttributes>,
    settings: &UsdSettings,
    weld_map: Option<&[u32]>,
    path: &Path,
    file: File,
) -> Result<()> {
    flushed(
        full_frame_into(frames, triangles, attributes, settings, weld_map, path, Out::File { w: BufWriter::new(file), len: 0, error: None })?,
        path,
    )
}

/// The full-frame file into `out`.
fn full_frame_into(
    frames: &FullFrame,
    triangles: &[[u32; 3]],
    attributes: Option<&CornerAttributes>,
    settings: &UsdSettings,
    weld_map: Option<&[u32]>,
    path: &Path,
    out: Out,
) -> Result<Out> {
    let layer = usd::full_frame_unsampled(frames, triangles, attributes, settings, weld_map);
    let times: Vec<f64> = frames.frames.iter().map(|&f| f as f64).collect();
    let mut read = |i: usize, out: &mut Vec<[f32; 3]>| -> Result<()> {
        out.clear();
        out.extend_from_slice(&frames.points[i]);
        Ok(())
    };
    written(&layer, path, StreamedSamples { attribute: usd::points_path(settings), times: &times, read: &mut read }, out)
}

/// Where a file's bytes go as they are produced: memory, or a file through a buffer (a
/// full-frame file of gigabytes is then never held). Besides appending, the writer needs the
/// length so far (the offsets), to patch an 8-byte jump once its target is written (a seek
/// back in a file: two per time-sampled attribute, and the bootstrap), and to compare a value
/// with one written before whose hash it shares (a read back from the file: equal frames are
/// stored once).
enum Out {
    Memory(Vec<u8>),
    /// The file, the bytes written so far, and the first write error (nothing is written
    /// after it; the caller reports it).
    File {
        w: BufWriter<File>,
        len: u64,
        error: Option<std::io::Error>,
    },
}

impl Default for Out {
    fn default() -> Out {
        Out::Memory(Vec::new())
    }
}

impl Out {
    fn extend_from_slice(&mut self, bytes: &[u8]) {
        match self {
            Out::Memory(v) => v.extend_from_slice(bytes),
            Out::File { w, len, error } => {
                if error.is_none() {
                    if let Err(e) = w.write_all(bytes) {
                        *error = Some(e);
                    }
                }
                *len += bytes.len() as u64;
            }
        }
    }

    fn push(&mut self, byte: u8) {
        self.extend_from_slice(&[byte]);
    }

    fn len(&self) -> u64 {
        match self {
            Out::Memory(v) => v.len() as u64,
            Out::File { len, .. } => *len,
        }
    }

    /// Overwrite the bytes at `at` (already written) with `bytes`.
    fn patch(&mut self, at: u64, bytes: &[u8]) {
        match self {
            Out::Memory(v) => v[at as usize..at as usize + bytes.len()].copy_from_slice(bytes),
            Out::File { w, len, error } => {
                if error.is_none() {
                    let patched = w.seek(SeekFrom::Start(at)).and_then(|_| w.write_all(bytes)).and_then(|_| w.seek(SeekFrom::Start(*len)));
                    if let Err(e) = patched {
                        *error = Some(e);
                    }
                }
            }
        }
    }

    /// Whether the bytes at `at` begin with `body`.
    fn holds(&mut self, at: u64, body: &[u8]) -> bool {
        match self {
            Out::Memory(v) => v[at as usize..].starts_with(body),
            Out::File { w, len, error } => {
                if error.is_some() || at + body.len() as u64 > *len {
                    return false;
                }
                if let Err(e) = w.flush() {
                    *error = Some(e);
                    return false;
                }
                let mut there = vec![0; body.len()];
                match w.get_ref().read_exact_at(&mut there, at) {
                    Ok(()) => there == body,
                    Err(e) => {
                        *error = Some(e);
                        false
                    }
                }
            }
        }
    }
}

/// Why a streamed sample was not written.
enum Failure {
    /// Its reader failed.
    Read(Error),
    /// A value the format cannot store (as [`check`] states it).
    Value(String),
}

/// A value the format cannot store, or a non-finite number, as a problem statement.
fn check(layer: &Layer) -> std::result::Result<(), String> {
    fn text(what: &str, s: &str) -> std::result::Result<(), String> {
        if s.contains('\0') {
            return Err(format!("{what} `{}` contains a NUL byte", s.replace('\0', "\\0")));
        }
        Ok(())
    }
    fn value(at: &str, v: &Value) -> std::result::Result<(), String> {
        let finite = match v {
            Value::Token(s) | Value::String(s) | Value::Asset(s) => return text(&format!("the value of {at}"), s),
            Value::Tokens(items) => return items.iter().try_for_each(|s| text(&format!("a value of {at}"), s)),
            Value::Double(x) => x.is_finite(),
            Value::Float(x) => x.is_finite(),
            Value::Vec3f(v) => v.iter().all(|x| x.is_finite()),
            Value::Ints(_) => true,
            Value::Floats(items) => items.iter().all(|x| x.is_finite()),
            Value::Vec2fs(items) => items.iter().flatten().all(|x| x.is_finite()),
            Value::Vec3fs(items) => items.iter().flatten().all(|x| x.is_finite()),
        };
        if finite {
            Ok(())
        } else {
            Err(format!("{at} holds a non-finite number (NaN or infinity)"))
        }
    }
    fn prim(parent: &str, p: &Prim) -> std::result::Result<(), String> {
        let path = format!("{parent}/{}", p.name);
        text("the prim name", &p.name)?;
        for property in &p.properties {
            let at = format!("{path}.{}", property.name());
            text("the property name", property.name())?;
            if let Property::Attribute(a) = property {
                a.default.iter().chain(a.samples.iter().map(|(_, v)| v)).try_for_each(|v| value(&at, v))?;
                if a.samples.iter().any(|(t, _)| !t.is_finite()) {
                    return Err(format!("{at} has a non-finite sample time"));
                }
            }
        }
        p.children.iter().try_for_each(|c| prim(&path, c))
    }
    fn spec_paths(parent: &str, p: &Prim, paths: &mut HashSet<String>) {
        let path = format!("{parent}/{}", p.name);
        paths.extend(p.properties.iter().map(|q| format!("{path}.{}", q.name())));
        p.children.iter().for_each(|c| spec_paths(&path, c, paths));
        paths.insert(path);
    }
    fn targets_exist(parent: &str, p: &Prim, paths: &HashSet<String>) -> std::result::Result<(), String> {
        let path = format!("{parent}/{}", p.name);
        for property in &p.properties {
            let targets: &[String] = match property {
                Property::Relationship { targets, .. } => targets,
                Property::Attribute(Attribute { connection: Some(c), .. }) => std::slice::from_ref(c),
                Property::Attribute(_) => &[],
            };
            if let Some(t) = targets.iter().find(|t| !paths.contains(*t)) {
                return Err(format!("{path}.{} targets {t}, which is not in the layer", property.name()));
            }
        }
        p.children.iter().try_for_each(|c| targets_exist(&path, c, paths))
    }
    layer.metadata.iter().try_for_each(|(key, v)| value(&format!("the layer's {key}"), v))?;
    layer.prims.iter().try_for_each(|p| prim("", p))?;
    let mut paths = HashSet::new();
    layer.prims.iter().for_each(|p| spec_paths("", p, &mut paths));
    layer.prims.iter().try_for_each(|p| targets_exist("", p, &paths))
}

/// A path of the layer: its children, its last element's token, and whether that element is a
/// property name (`.name`) rather than a prim name or a target (`[/path]`).
struct PathEntry {
    element: u32,
    property: bool,
    children: Vec<u32>,
}

#[derive(Default)]
struct Writer<'a> {
    out: Out,
    /// The attribute whose samples are read while written, until written.
    streamed: Option<StreamedSamples<'a>>,
    /// The first streamed sample that could not be written (nothing after it is).
    failed: Option<Failure>,
    tokens: Vec<String>,
    token_index: HashMap<String, u32>,
    strings: Vec<u32>,
    string_index: HashMap<String, u32>,
    paths: Vec<PathEntry>,
    path_index: HashMap<String, u32>,
    fields: Vec<(u32, u64)>,
    field_index: HashMap<(u32, u64), u32>,
    field_sets: Vec<u32>,
    field_set_index: HashMap<Vec<u32>, u32>,
    /// (path, field set, spec type)
    specs: Vec<(u32, u32, u32)>,
    /// Offsets of the arrays written, by (representation, hash of their bytes).
    stored: HashMap<(u64, u64), Vec<u64>>,
}

impl Writer<'_> {
    fn token(&mut self, s: &str) -> u32 {
        if let Some(&i) = self.token_index.get(s) {
            return i;
        }
        let i = self.tokens.len() as u32;
        self.tokens.push(s.to_string());
        self.token_index.insert(s.to_string(), i);
        i
    }

    fn string(&mut self, s: &str) -> u32 {
        if let Some(&i) = self.string_index.get(s) {
            return i;
        }
        let token = self.token(s);
        let i = self.strings.len() as u32;
        self.strings.push(token);
        self.string_index.insert(s.to_string(), i);
        i
    }

    /// The index of `path` (the root is `/`), adding it after its parent; `element` is its last
    /// element as a path tree stores it (a prim or property name, or `[/target]`).
    fn path(&mut self, path: &str, parent: Option<&str>, element: &str, property: bool) -> u32 {
        if let Some(&i) = self.path_index.get(path) {
            return i;
        }
        let parent = parent.map(|p| self.path_index[p]);
        let element = self.token(element);
        let i = self.paths.len() as u32;
        self.paths.push(PathEntry { element, property, children: Vec::new() });
        if let Some(p) = parent {
            self.paths[p as usize].children.push(i);
        }
        self.path_index.insert(path.to_string(), i);
        i
    }

    /// The index of a path added by `prim_paths` (targets are among them: see `check`).
    fn existing_path(&self, path: &str) -> u32 {
        self.path_index[path]
    }

    fn spec(&mut self, path: u32, spec_type: u32, fields: &[(&str, u64)]) {
        let indices: Vec<u32> = fields
            .iter()
            .map(|&(name, value)| {
                let key = (self.token(name), value);
                let next = self.fields.len() as u32;
                *self.field_index.entry(key).or_insert_with(|| {
                    self.fields.push(key);
                    next
                })
            })
            .collect();
        let next = self.field_sets.len() as u32;
        let set = match self.field_set_index.get(&indices) {
            Some(&s) => s,
            None => {
                self.field_sets.extend(&indices);
                self.field_sets.push(u32::MAX);
                self.field_set_index.insert(indices, next);
                next
            }
        };
        self.specs.push((path, set, spec_type));
    }

    fn layer(&mut self, layer: &Layer) {
        // Token 0 is the root's (empty) element, so no property name gets index 0: the path
        // tree marks property names by negating their token index.
        let root = self.path("/", None, "", false);
        // Every path first (the tree), so targets and connections can name any of them.
        for p in &layer.prims {
            self.prim_paths("", p);
        }
        let mut fields = Vec::new();
        for (key, value) in &layer.metadata {
            let name = if *key == "doc" { "documentation" } else { key };
            fields.push((name, self.value(value)));
        }
        let children: Vec<&str> = layer.prims.iter().map(|p| p.name.as_str()).collect();
        if !children.is_empty() {
            fields.push(("primChildren", self.token_vector(&children)));
        }
        self.spec(root, spec::PSEUDO_ROOT, &fields);
        for p in &layer.prims {
            self.prim("", p);
        }
    }

    fn prim_paths(&mut self, parent: &str, p: &Prim) {
        let path = format!("{parent}/{}", p.name);
        self.path(&path, Some(if parent.is_empty() { "/" } else { parent }), &p.name, false);
        for property in &p.properties {
            let at = format!("{path}.{}", property.name());
            self.path(&at, Some(&path), property.name(), true);
            let targets: &[String] = match property {
                Property::Relationship { targets, .. } => targets,
                Property::Attribute(Attribute { connection: Some(c), .. }) => std::slice::from_ref(c),
                Property::Attribute(_) => &[],
            };
            for t in targets {
                let element = format!("[{t}]");
                self.path(&format!("{at}{element}"), Some(&at), &element, false);
            }
        }
        for c in &p.children {
            self.prim_paths(&path, c);
        }
    }

    fn prim(&mut self, parent: &str, p: &Prim) {
        let path = format!("{parent}/{}", p.name);
        let mut fields = vec![("specifier", inlined(ty::SPECIFIER, 0)), ("typeName", inlined(ty::TOKEN, self.token(p.type_name)))];
        if !p.api_schemas.is_empty() {
            let items: Vec<u32> = p.api_schemas.iter().map(|s| self.token(s)).collect();
            fields.push(("apiSchemas", self.list_op(ty::TOKEN_LIST_OP, ListOp::Prepend, &items)));
        }
        if !p.children.is_empty() {
            let names: Vec<&str> = p.children.iter().map(|c| c.name.as_str()).collect();
            fields.push(("primChildren", self.token_vector(&names)));
        }
        if !p.properties.is_empty() {
            let names: Vec<&str> = p.properties.iter().map(Property::name).collect();
            fields.push(("properties", self.token_vector(&names)));
        }
        let index = self.existing_path(&path);
        self.spec(index, spec::PRIM, &fields);
        for property in &p.properties {
            let at = format!("{path}.{}", property.name());
            let index = self.existing_path(&at);
            let custom = ("custom", inlined(ty::BOOL, 0));
            match property {
                Property::Attribute(a) => {
                    let mut fields = vec![
                        ("typeName", inlined(ty::TOKEN, self.token(a.type_name))),
                        custom,
                        ("variability", inlined(ty::VARIABILITY, a.uniform as u32)),
                    ];
                    if let Some(v) = &a.default {
                        fields.push(("default", self.value(v)));
                    }
                    if !a.samples.is_empty() {
                        fields.push(("timeSamples", self.time_samples(&a.samples)));
                    } else if self.streamed.as_ref().is_some_and(|s| s.attribute == at) {
                        fields.push(("timeSamples", self.streamed_samples()));
                    }
                    if let Some(c) = &a.connection {
                        let target = self.existing_path(c);
                        fields.push(("connectionPaths", self.list_op(ty::PATH_LIST_OP, ListOp::Explicit, &[target])));
                        fields.push(("connectionChildren", self.index_vector(ty::PATH_VECTOR, &[target])));
                    }
                    if let Some(i) = a.interpolation {
                        fields.push(("interpolation", inlined(ty::TOKEN, self.token(i))));
                    }
                    self.spec(index, spec::ATTRIBUTE, &fields);
                    if let Some(c) = &a.connection {
                        let target = self.existing_path(&format!("{at}[{c}]"));
                        self.spec(target, spec::CONNECTION, &[]);
                    }
                }
                Property::Relationship { targets, .. } => {
                    let items: Vec<u32> = targets.iter().map(|t| self.existing_path(t)).collect();
                    let fields = [
                        custom,
                        ("variability", inlined(ty::VARIABILITY, 1)),
                        ("targetPaths", self.list_op(ty::PATH_LIST_OP, ListOp::Explicit, &items)),
                        ("targetChildren", self.index_vector(ty::PATH_VECTOR, &items)),
                    ];
                    self.spec(index, spec::RELATIONSHIP, &fields);
                    for t in targets {
                        let target = self.existing_path(&format!("{at}[{t}]"));
                        self.spec(target, spec::RELATIONSHIP_TARGET, &[]);
                    }
                }
            }
        }
        for c in &p.children {
            self.prim(&path, c);
        }
    }

    fn put_u32(&mut self, x: u32) {
        self.out.extend_from_slice(&x.to_le_bytes());
    }

    fn put_u64(&mut self, x: u64) {
        self.out.extend_from_slice(&x.to_le_bytes());
    }

    fn align8(&mut self) {
        while !self.out.len().is_multiple_of(8) {
            self.out.push(0);
        }
    }

    fn here(&self) -> u64 {
        self.out.len()
    }

    fn token_vector(&mut self, names: &[&str]) -> u64 {
        let items: Vec<u32> = names.iter().map(|n| self.token(n)).collect();
        self.index_vector(ty::TOKEN_VECTOR, &items)
    }

    /// A `std::vector` of token or path indices: `u64` count, then the `u32` indices.
    fn index_vector(&mut self, ty: u64, items: &[u32]) -> u64 {
        let at = self.here();
        self.put_u64(items.len() as u64);
        items.iter().for_each(|&i| self.put_u32(i));
        rep(ty, at)
    }

    /// An `SdfListOp` of token or path indices: a header byte, then the one list it holds.
    fn list_op(&mut self, ty: u64, op: ListOp, items: &[u32]) -> u64 {
        let at = self.here();
        // Header bits: IsExplicit 1, HasExplicitItems 2, HasPrependedItems 32.
        self.out.push(match op {
            ListOp::Explicit => 1 | 2,
            ListOp::Prepend => 32,
        });
        self.index_vector(0, items);
        rep(ty, at)
    }

    /// Time samples: a jump over the times (a `double` vector), their representation, a jump
    /// over the values, then the count and each value's representation.
    fn time_samples(&mut self, samples: &[(f64, Value)]) -> u64 {
        let at = self.here();
        self.put_u64(0);
        let mut times: Vec<u8> = (samples.len() as u64).to_le_bytes().to_vec();
        samples.iter().for_each(|(t, _)| times.extend_from_slice(&t.to_le_bytes()));
        let times = self.stored(rep(ty::DOUBLE_VECTOR, 0), times, false);
        self.patch_jump(at);
        self.put_u64(times);
        let values_jump = self.here();
        self.put_u64(0);
        let reps: Vec<u64> = samples.iter().map(|(_, v)| self.value(v)).collect();
        self.patch_jump(values_jump);
        self.put_u64(reps.len() as u64);
        reps.iter().for_each(|&r| self.put_u64(r));
        rep(ty::TIME_SAMPLES, at)
    }

    /// [`Writer::time_samples`] of the streamed attribute, each value read into one buffer
    /// and written before the next is read (the same bytes).
    fn streamed_samples(&mut self) -> u64 {
        let s = self.streamed.take().expect("called for the streamed attribute");
        let at = self.here();
        self.put_u64(0);
        let mut times: Vec<u8> = (s.times.len() as u64).to_le_bytes().to_vec();
        s.times.iter().for_each(|t| times.extend_from_slice(&t.to_le_bytes()));
        let times = self.stored(rep(ty::DOUBLE_VECTOR, 0), times, false);
        self.patch_jump(at);
        self.put_u64(times);
        let values_jump = self.here();
        self.put_u64(0);
        let mut value = Value::Vec3fs(Vec::new());
        let mut reps = Vec::with_capacity(s.times.len());
        for i in 0..s.times.len() {
            let Value::Vec3fs(buffer) = &mut value else { unreachable!("a Vec3fs") };
            if let Err(e) = (s.read)(i, buffer) {
                self.failed = Some(Failure::Read(e));
                break;
            }
            if !buffer.iter().flatten().all(|x| x.is_finite()) {
                self.failed = Some(Failure::Value(format!("{} holds a non-finite number (NaN or infinity)", s.attribute)));
                break;
            }
            reps.push(self.value(&value));
        }
        self.patch_jump(values_jump);
        self.put_u64(reps.len() as u64);
        reps.iter().for_each(|&r| self.put_u64(r));
        rep(ty::TIME_SAMPLES, at)
    }

    /// Write at `at` the distance from `at` to the end of the output.
    fn patch_jump(&mut self, at: u64) {
        let jump = (self.here() - at).to_le_bytes();
        self.out.patch(at, &jump);
    }

    /// A value's representation, writing what does not fit in the payload.
    fn value(&mut self, v: &Value) -> u64 {
        match v {
            Value::Token(s) => inlined(ty::TOKEN, self.token(s)),
            Value::String(s) => inlined(ty::STRING, self.string(s)),
            Value::Asset(s) => inlined(ty::ASSET_PATH, self.token(s)),
            Value::Float(x) => inlined(ty::FLOAT, x.to_bits()),
            Value::Double(x) => {
                let at = self.here();
                self.out.extend_from_slice(&x.to_le_bytes());
                rep(ty::DOUBLE, at)
            }
            Value::Vec3f(v) => {
                let at = self.here();
                v.iter().for_each(|x| self.out.extend_from_slice(&x.to_le_bytes()));
                rep(ty::VEC3F, at)
            }
            Value::Tokens(items) => {
                let indices: Vec<u32> = items.iter().map(|s| self.token(s)).collect();
                self.array(ty::TOKEN, indices.len(), |out| indices.iter().for_each(|i| out.extend_from_slice(&i.to_le_bytes())))
            }
            Value::Ints(items) if items.len() >= MIN_COMPRESSED_ARRAY => {
                let mut body = (items.len() as u64).to_le_bytes().to_vec();
                let compressed = compressed_ints(items);
                body.extend_from_slice(&(compressed.len() as u64).to_le_bytes());
                body.extend_from_slice(&compressed);
                self.stored(rep(ty::INT, 0) | ARRAY_BIT | COMPRESSED_BIT, body, false)
            }
            Value::Ints(items) => self.array(ty::INT, items.len(), |out| items.iter().for_each(|x| out.extend_from_slice(&x.to_le_bytes()))),
            Value::Floats(items) => self.array(ty::FLOAT, items.len(), |out| items.iter().for_each(|x| out.extend_from_slice(&x.to_le_bytes()))),
            Value::Vec2fs(items) => {
                self.array(ty::VEC2F, items.len(), |out| items.iter().flatten().for_each(|x| out.extend_from_slice(&x.to_le_bytes())))
            }
            Value::Vec3fs(items) => {
                self.array(ty::VEC3F, items.len(), |out| items.iter().flatten().for_each(|x| out.extend_from_slice(&x.to_le_bytes())))
            }
        }
    }

    /// An uncompressed array: empty ones are a zero payload; others 8-byte aligned (so a reader
    /// can map them in place), `u64` count, elements.
    fn array(&mut self, ty: u64, len: usize, elements: impl FnOnce(&mut Vec<u8>)) -> u64 {
        if len == 0 {
            return rep(ty, 0) | ARRAY_BIT;
        }
        // Sized at once: a dense target's offsets are megabytes, grown from 8 bytes they were
        // copied about 20 times.
        let element = match ty {
            ty::VEC3F => 12,
            ty::VEC2F => 8,
            _ => 4,
        };
        let mut body = Vec::with_capacity(8 + len * element);
        body.extend_from_slice(&(len as u64).to_le_bytes());
        elements(&mut body);
        self.stored(rep(ty, 0) | ARRAY_BIT, body, true)
    }

    /// `rep` pointing at `body`, written once per file like usd-core does (the same weights or
    /// offsets in two places, the same sample times of two attributes): an equal body of the
    /// same representation is found by its hash and compared with the bytes already written.
    fn stored(&mut self, rep: u64, body: Vec<u8>, aligned: bool) -> u64 {
        let mut hasher = std::hash::DefaultHasher::new();
        std::hash::Hash::hash(&body, &mut hasher);
        let key = (rep, std::hash::Hasher::finish(&hasher));
        if let Some(offsets) = self.stored.get(&key) {
            for &at in offsets {
                if self.out.holds(at, &body) {
                    return rep | at;
                }
            }
        }
        if aligned {
            self.align8();
        }
        let at = self.here();
        self.out.extend_from_slice(&body);
        self.stored.entry(key).or_default().push(at);
        rep | at
    }

    /// The structural sections, the table of contents and the bootstrap.
    fn finish(mut self) -> Out {
        let mut sections: Vec<(&str, u64, u64)> = Vec::new();
        let mut section = |w: &mut Writer, name: &'static str, write: &dyn Fn(&mut Writer)| {
            w.align8();
            let start = w.here();
            write(w);
            sections.push((name, start, w.here() - start));
        };
        section(&mut self, "TOKENS", &|w| {
            let mut chars = Vec::new();
            for t in &w.tokens {
                chars.extend_from_slice(t.as_bytes());
                chars.push(0);
            }
            let compressed = fast_compression(&chars);
            w.put_u64(w.tokens.len() as u64);
            w.put_u64(chars.len() as u64);
            w.put_u64(compressed.len() as u64);
            w.out.extend_from_slice(&compressed);
        });
        section(&mut self, "STRINGS", &|w| {
            let strings = w.strings.clone();
            w.index_vector(0, &strings);
        });
        section(&mut self, "FIELDS", &|w| {
            let names: Vec<i32> = w.fields.iter().map(|f| f.0 as i32).collect();
            let reps: Vec<u8> = w.fields.iter().flat_map(|f| f.1.to_le_bytes()).collect();
            w.put_u64(names.len() as u64);
            w.put_ints(&names);
            let reps = fast_compression(&reps);
            w.put_u64(reps.len() as u64);
            w.out.extend_from_slice(&reps);
        });
        section(&mut self, "FIELDSETS", &|w| {
            let sets: Vec<i32> = w.field_sets.iter().map(|&f| f as i32).collect();
            w.put_u64(sets.len() as u64);
            w.put_ints(&sets);
        });
        section(&mut self, "PATHS", &|w| {
            let (mut indices, mut elements, mut jumps) = (Vec::new(), Vec::new(), Vec::new());
            w.path_tree(0, false, &mut indices, &mut elements, &mut jumps);
            w.put_u64(w.paths.len() as u64);
            w.put_u64(indices.len() as u64);
            w.put_ints(&indices);
            w.put_ints(&elements);
            w.put_ints(&jumps);
        });
        section(&mut self, "SPECS", &|w| {
            let column = |f: fn(&(u32, u32, u32)) -> u32| w.specs.iter().map(|s| f(s) as i32).collect::<Vec<i32>>();
            let (paths, sets, types) = (column(|s| s.0), column(|s| s.1), column(|s| s.2));
            w.put_u64(w.specs.len() as u64);
            w.put_ints(&paths);
            w.put_ints(&sets);
            w.put_ints(&types);
        });
        self.align8();
        let toc = self.here();
        self.put_u64(sections.len() as u64);
        for (name, start, size) in sections {
            let mut padded = [0u8; 16];
            padded[..name.len()].copy_from_slice(name.as_bytes());
            self.out.extend_from_slice(&padded);
            self.put_u64(start);
            self.put_u64(size);
        }
        let mut boot = [0u8; 88];
        boot[..8].copy_from_slice(b"PXR-USDC");
        boot[8..11].copy_from_slice(&VERSION);
        boot[16..24].copy_from_slice(&toc.to_le_bytes());
        self.out.patch(0, &boot);
        self.out
    }

    /// Compressed ints: `u64` compressed size, then the bytes.
    fn put_ints(&mut self, ints: &[i32]) {
        let compressed = compressed_ints(ints);
        self.put_u64(compressed.len() as u64);
        self.out.extend_from_slice(&compressed);
    }

    /// The path tree depth first from `node`: its index, its element token (negated for a
    /// property name), and a jump: -2 a leaf with no sibling after it, -1 a child follows and no
    /// sibling, 0 no child and the sibling follows, n > 0 a child follows and the sibling is n
    /// entries ahead.
    fn path_tree(&self, node: u32, has_sibling: bool, indices: &mut Vec<i32>, elements: &mut Vec<i32>, jumps: &mut Vec<i32>) {
        let entry = &self.paths[node as usize];
        let me = indices.len();
        indices.push(node as i32);
        elements.push(if entry.property { -(entry.element as i32) } else { entry.element as i32 });
        jumps.push(0);
        let has_child = !entry.children.is_empty();
        for (k, &c) in entry.children.iter().enumerate() {
            self.path_tree(c, k + 1 < entry.children.len(), indices, elements, jumps);
        }
        jumps[me] = match (has_child, has_sibling) {
            (false, false) => -2,
            (true, false) => -1,
            (false, true) => 0,
            (true, true) => (indices.len() - me) as i32,
        };
    }
}

#[derive(Clone, Copy)]
enum ListOp {
    Explicit,
    Prepend,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::formats::export::layer::Attribute;

    /// Every kind of value, property and prim our layouts use, with edge cases: empty and
    /// short arrays, int arrays long enough to be compressed with every code width, negative
    /// and extreme values, a string, an asset, connections and relationships, time samples.
    fn every_kind() -> Layer {
        let mut shader = Prim::new("Shader", "S");
        shader.attribute(Attribute::uniform("info:id", "token", Value::Token("UsdUVTexture".into())));
        shader.attribute(Attribute::new("inputs:file", "asset", Value::Asset("./a b.png".into())));
        shader.attribute(Attribute::new("inputs:varname", "string", Value::String("st".into())));
        shader.attribute(Attribute::new("inputs:roughness", "float", Value::Float(-0.1)));
        shader.attribute(Attribute::new("inputs:diffuseColor", "color3f", Value::Vec3f([0.8, -1e-30, 3.4e38])));
        shader.attribute(Attribute::declared("outputs:rgb", "float3"));
        let mut material = Prim::new("Material", "M");
        material.attribute(Attribute::connected("outputs:surface", "token", "/root/M/S.outputs:rgb".into()));
        material.children.push(shader);
        let mut mesh = Prim::new("Mesh", "Mesh").with_api("SkelBindingAPI").with_api("MaterialBindingAPI");
        let long: Vec<i32> = (0..300).map(|i: i32| [i, -i, i * 1000, i.wrapping_mul(1 << 20), i32::MIN, i32::MAX, 7][i as usize % 7]).collect();
        mesh.attribute(Attribute::new("faceVertexIndices", "int[]", Value::Ints(long)));
        mesh.attribute(Attribute::new("faceVertexCounts", "int[]", Value::Ints(vec![3, 3, -4])));
        mesh.attribute(Attribute::new("primvars:st", "texCoord2f[]", Value::Vec2fs(vec![[0.0, 1.0], [0.5, 0.25]])).with_interpolation("faceVarying"));
        mesh.attribute(Attribute::uniform("joints", "token[]", Value::Tokens(Vec::new())));
        mesh.attribute(Attribute::uniform("names", "token[]", Value::Tokens(vec!["a".into(), "b".into(), "a".into()])));
        mesh.attribute(Attribute::sampled("weights", "float[]", vec![(-2.0, Value::Floats(vec![0.25, -1.0])), (0.5, Value::Floats(vec![]))]));
        mesh.attribute(Attribute::sampled(
            "points",
            "point3f[]",
            vec![(1.0, Value::Vec3fs(vec![[1.0, 2.0, 3.0]])), (2.0, Value::Vec3fs(vec![[4.0, 5.0, 6.0]; 20]))],
        ));
        mesh.relationship("material:binding", vec!["/root/M".into()]);
        mesh.relationship("skel:blendShapeTargets", vec!["/root/M".into(), "/root/M/S".into()]);
        let mut root = Prim::new("Xform", "root");
        root.children.push(mesh);
        root.children.push(material);
        let metadata = vec![
            ("defaultPrim", Value::Token("root".into())),
            ("doc", Value::String("a \"doc\"".into())),
            ("metersPerUnit", Value::Double(0.01)),
            ("endTimeCode", Value::Double(1e300)),
        ];
        Layer { metadata, prims: vec![root, Prim::new("Scope", "second")] }
    }

    fn scratch(name: &str) -> std::path::PathBuf {
        // Kept: the test removes it when it is done.
        tempfile::Builder::new().prefix(&format!("blendsim-usdc-{name}-")).tempdir().unwrap().keep()
    }

    /// usd-core reads our bytes as the layer our usda text holds (the test suite's checker).
    #[test]
    fn usd_core_reads_every_kind_of_value_as_the_usda_layer() {
        let d = scratch("kinds");
        let layer = every_kind();
        let (a, c) = (d.join("x.usda"), d.join("x.usdc"));
        std::fs::write(&a, crate::formats::export::usda::text(&layer)).unwrap();
        let bytes = super::bytes(&layer, &c).unwrap();
        assert_eq!(bytes, super::bytes(&layer, &c).unwrap(), "same bytes every time");
        std::fs::write(&c, bytes).unwrap();
        let checker = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/checkers/usd_same_layer.py");
        let out =
            std::process::Command::new(std::env::var("BLENDSIM_PYTHON").unwrap_or("python3".into())).arg(checker).arg(&a).arg(&c).output().unwrap();
        let stdout = String::from_utf8_lossy(&out.stdout);
        assert!(out.status.success() && stdout.contains("\"ok\": true"), "{stdout}\n{}", String::from_utf8_lossy(&out.stderr));
        std::fs::remove_dir_all(&d).unwrap();
    }

    fn error(layer: &Layer) -> String {
        let e = super::bytes(layer, Path::new("out/x.usdc")).unwrap_err().to_string();
        assert!(!e.contains('\n') && e.contains("out/x.usdc: cannot write the usdc file: ") && e.contains("(fix: "), "{e}");
        e
    }

    #[test]
    fn values_the_format_cannot_hold_are_one_line_errors() {
        let mut nan = every_kind();
        let Property::Attribute(a) = &mut nan.prims[0].children[0].properties[6] else { panic!() };
        a.samples[1].1 = Value::Vec3fs(vec![[0.0, f32::NAN, 0.0]]);
        assert!(error(&nan).contains("/root/Mesh.points holds a non-finite number"));
        let mut nul = every_kind();
        nul.prims[1].name = "a\0b".into();
        assert!(error(&nul).contains("the prim name `a\\0b` contains a NUL byte"));
        let mut dangling = every_kind();
        dangling.prims[0].children[0].relationship("skel:skeleton", vec!["/root/Skel".into()]);
        assert!(error(&dangling).contains("/root/Mesh.skel:skeleton targets /root/Skel, which is not in the layer"));
    }

    /// The bootstrap points at a table of contents that lists the six sections in order, each
    /// inside the file.
    #[test]
    fn bootstrap_and_table_of_contents() {
        let bytes = super::bytes(&every_kind(), Path::new("x.usdc")).unwrap();
        assert_eq!(&bytes[..8], b"PXR-USDC");
        assert_eq!(&bytes[8..16], &[0, 8, 0, 0, 0, 0, 0, 0]);
        let u64_at = |at: usize| u64::from_le_bytes(bytes[at..at + 8].try_into().unwrap()) as usize;
        let toc = u64_at(16);
        assert_eq!(u64_at(toc), 6);
        let mut end = 88;
        for (k, name) in ["TOKENS", "STRINGS", "FIELDS", "FIELDSETS", "PATHS", "SPECS"].iter().enumerate() {
            let at = toc + 8 + 32 * k;
            assert_eq!(&bytes[at..at + name.len()], name.as_bytes());
            assert!(bytes[at + name.len()..at + 16].iter().all(|&b| b == 0));
            let (start, size) = (u64_at(at + 16), u64_at(at + 24));
            assert!(start >= end && size > 0 && start + size <= toc, "{name}: {start} + {size}");
            end = start + size;
        }
        assert_eq!(bytes.len(), toc + 8 + 32 * 6);
    }

    /// Points streamed into the file give the bytes of the layer that holds them (a repeated
    /// frame deduplicated alike); a reader's error and a non-finite point are one-line errors.
    #[test]
    fn streamed_samples_give_the_bytes_of_the_held_layer() {
        use crate::formats::export::usd::{sampled_points, sampled_points_layer, UsdSettings};
        let settings = UsdSettings { name: "cache".into(), fps: 24.0, up_axis: 'Y', meters_per_unit: 1.0 };
        let triangles = [[0, 1, 2], [0, 2, 3]];
        let frame = |k: usize| -> Vec<[f32; 3]> { (0..4).map(|a| [a as f32, (k % 3) as f32 * 0.25, 0.5 * a as f32 * k as f32]).collect() };
        let times = [0.0, 1.0, 2.0, 3.0, 4.5];
        let frames: Vec<Vec<[f32; 3]>> = [0, 1, 2, 1, 4].map(frame).to_vec();
        let held = sampled_points(times.iter().copied().zip(frames.iter().cloned()).collect(), &triangles, None, &settings, (0, 5));
        let want = super::bytes(&held, Path::new("x.usdc")).unwrap();
        let extents = times.iter().zip(&frames).map(|(t, p)| (*t, crate::formats::export::usd::extent(p))).collect::<Vec<_>>();
        let layer = sampled_points_layer(extents, Vec::new(), 4, &triangles, None, &settings, (0, 5));
        let mut read = |i: usize, out: &mut Vec<[f32; 3]>| -> Result<()> {
            out.clone_from(&frames[i]);
            Ok(())
        };
        let streamed = StreamedSamples { attribute: "/cache/Mesh.points".into(), times: &times, read: &mut read };
        assert!(bytes_streamed(&layer, Path::new("x.usdc"), streamed).unwrap() == want);
        let mut failing = |i: usize, out: &mut Vec<[f32; 3]>| -> Result<()> {
            out.clone_from(&frames[i]);
            if i == 2 {
                return Err(Error::general("frame 2 is unreadable", "fix it"));
            }
            Ok(())
        };
        let streamed = StreamedSamples { attribute: "/cache/Mesh.points".into(), times: &times, read: &mut failing };
        assert!(bytes_streamed(&layer, Path::new("x.usdc"), streamed).unwrap_err().to_string().contains("frame 2 is unreadable"));
        let mut nan = |i: usize, out: &mut Vec<[f32; 3]>| -> Result<()> {
            out.clone_from(&frames[i]);
            out[1][2] = if i == 3 { f32::NAN } else { out[1][2] };
            Ok(())
        };
        let streamed = StreamedSamples { attribute: "/cache/Mesh.points".into(), times: &times, read: &mut nan };
        let e = bytes_streamed(&layer, Path::new("out/x.usdc"), streamed).unwrap_err().to_string();
        assert!(!e.contains('\n') && e.contains("out/x.usdc: cannot write the usdc file: /cache/Mesh.points holds a non-finite number"), "{e}");
    }

    /// The full-frame file with its points streamed from the frames is byte for byte the file
    /// of the layer holding them, with material groups (prims after the mesh) and a repeated
    /// frame (stored once); a non-finite point is still refused.
    #[test]
    fn full_frame_streamed_gives_the_bytes_of_the_held_layer() {
        use crate::algorithms::blendshape::fullframe::FullFrame;
        use crate::algorithms::geometry::attributes::CornerAttributes;
        let settings = UsdSettings { name: "twist".into(), fps: 30.0, up_axis: 'Z', meters_per_unit: 0.01 };
        let triangles = [[0, 1, 2], [0, 2, 3]];
        let pose = |k: usize| -> Vec<[f32; 3]> { (0..4).map(|a| [a as f32 * 0.5, (k % 2) as f32 * 0.25 - 1.0, 0.125 * (a * k) as f32]).collect() };
        let mut frames = FullFrame { frames: vec![3, 4, 5, 6], times: vec![0.1, 0.133, 0.167, 0.2], points: [0, 1, 2, 1].map(pose).to_vec() };
        let groups = CornerAttributes { groups: vec!["side".into(), "cap".into()], triangle_groups: vec![0, 1], ..Default::default() };
        for attributes in [None, Some(&groups)] {
            let want = bytes(&usd::full_frame(&frames, &triangles, attributes, &settings), Path::new("x.usdc")).unwrap();
            assert!(full_frame(&frames, &triangles, attributes, &settings, None, Path::new("x.usdc")).unwrap() == want);
        }
        frames.points[2][3][1] = f32::INFINITY;
        let e = full_frame(&frames, &triangles, None, &settings, None, Path::new("out/x.usdc")).unwrap_err().to_string();
        assert!(e.contains("out/x.usdc: cannot write the usdc file") && e.contains("non-finite"), "{e}");
    }
}
