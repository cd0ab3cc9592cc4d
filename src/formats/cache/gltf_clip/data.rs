//! The bytes behind a glTF document, read on demand.
//!
//! A `.glb` is opened by its header and JSON chunk only; its BIN chunk and the external
//! `.bin` files of a `.gltf` stay on disk and accessors are read from them with a seek, so a
//! clip with one morph target per frame costs one target per frame in memory, not the file.
//! Buffers in `data:` URIs (base64) are decoded once: they are in the JSON anyway.
//!
//! Every accessor is checked against its buffer view, every view against its buffer, and
//! every buffer against the bytes that really exist, before anything sized by them is
//! allocated.

use std::fs::File;
use std::path::{Path, PathBuf};

use gltf::accessor::{sparse::IndexType, DataType, Dimensions};
use gltf::buffer::Source;
use gltf::Document;

use crate::formats::cache::binary::{open_regular, read_exact_at, require_regular};
use crate::support::error::{Error, Result};

const FIX_DAMAGED: &str = "the glTF file is damaged or was written by a faulty exporter; re-export it (and check it with the Khronos glTF validator)";

/// Where one buffer's bytes are.
#[derive(Debug)]
enum BufferData {
    /// `len` bytes at `offset` of `files[file]`.
    File {
        file: usize,
        offset: u64,
        len: u64,
    },
    Memory(Vec<u8>),
}

/// The buffers of a document, with the files they live in.
#[derive(Debug)]
pub(crate) struct BufferStore {
    path: PathBuf,
    files: Vec<(PathBuf, File)>,
    buffers: Vec<BufferData>,
    /// Bytes of the glTF file and its external buffers.
    pub bytes: u64,
}

/// A parsed and validated document with its buffers.
pub(crate) struct Loaded {
    pub document: Document,
    pub store: BufferStore,
}

fn damaged(path: &Path, problem: String) -> Error {
    Error::in_file(path, problem, FIX_DAMAGED)
}

/// Open a `.glb` or `.gltf` (told apart by the `glTF` magic, not the extension).
pub(crate) fn load(path: &Path) -> Result<Loaded> {
    let (mut file, len) = open_regular(path, "glTF file")?;
    let mut magic = [0u8; 12];
    let head = len.min(12) as usize;
    read_exact_at(&mut file, 0, &mut magic[..head], path)?;
    let (json, bin) = if head >= 4 && &magic[..4] == b"glTF" {
        glb_chunks(path, &mut file, len, &magic[..head])?
    } else {
        // Bounded by the file's size.
        let mut json = vec![0u8; len as usize];
        read_exact_at(&mut file, 0, &mut json, path)?;
        (json, None)
    };
    let root = gltf::json::Root::from_slice(&json).map_err(|e| damaged(path, format!("its glTF JSON does not parse: {e}")))?;
    drop(json);
    if let Some(ext) = root.extensions_required.iter().find(|e| *e != "KHR_mesh_quantization") {
        return Err(Error::in_file(
            path,
            format!("requires the glTF extension {ext}, which the cache reader does not decode"),
            "re-export without mesh compression (Draco, meshopt), e.g. with gltf-transform or your exporter's settings",
        ));
    }
    let document = validate(path, root)?;
    let mut store = BufferStore { path: path.to_path_buf(), files: vec![(path.to_path_buf(), file)], buffers: Vec::new(), bytes: len };
    for buffer in document.buffers() {
        let need = buffer.length() as u64;
        let data = match buffer.source() {
            Source::Bin => {
                let Some((offset, bin_len)) = bin else {
                    return Err(damaged(path, format!("buffer {} refers to the GLB's BIN chunk, which the file does not have", buffer.index())));
                };
                if need > bin_len {
                    return Err(damaged(
                        path,
                        format!("buffer {} is {need} bytes, but the BIN chunk (at byte {offset}) holds {bin_len}", buffer.index()),
                    ));
                }
                BufferData::File { file: 0, offset, len: need }
            }
            Source::Uri(uri) if uri.starts_with("data:") => {
                let bytes = decode_data_uri(uri).ok_or_else(|| damaged(path, format!("buffer {}'s data URI is not base64 data", buffer.index())))?;
                if (bytes.len() as u64) < need {
                    return Err(damaged(path, format!("buffer {} is {need} bytes, but its data URI holds {}", buffer.index(), bytes.len())));
                }
                BufferData::Memory(bytes)
            }
            Source::Uri(uri) => {
                let relative = percent_decode(uri)
                    .ok_or_else(|| damaged(path, format!("buffer {}'s URI {uri:?} is not a valid relative path", buffer.index())))?;
                let bin_path = path.parent().unwrap_or(Path::new("")).join(relative);
                let bin_len = require_regular(&bin_path, "glTF buffer file")?;
                if need > bin_len {
                    return Err(Error::in_file(
                        &bin_path,
                        format!("is {bin_len} bytes, but buffer {} of {} needs {need}", buffer.index(), path.display()),
                        FIX_DAMAGED,
                    ));
                }
                let index = match store.files.iter().position(|(p, _)| *p == bin_path) {
                    Some(i) => i,
                    None => {
                        let (file, _) = open_regular(&bin_path, "glTF buffer file")?;
                        store.bytes += bin_len;
                        store.files.push((bin_path, file));
                        store.files.len() - 1
                    }
                };
                BufferData::File { file: index, offset: 0, len: need }
            }
        };
        store.buffers.push(data);
    }
    Ok(Loaded { document, store })
}

/// The document, validated by gltf-json except for one rule it adds to the spec (an accessor
/// without a buffer view and without sparse values is all zeros, glTF 2.0 §3.6.2.3: how a
/// morph target that moves nothing is written, as our full-frame frame 0), and for the
/// animation channel targets it does not check.
fn validate(path: &Path, root: gltf::json::Root) -> Result<Document> {
    use gltf::json::validation::{Checked, Error as Invalid, Validate};
    // gltf-json's primitive check indexes the POSITION accessor before validating the index.
    for (m, mesh) in root.meshes.iter().enumerate() {
        for (p, primitive) in mesh.primitives.iter().enumerate() {
            if primitive.attributes.get(&Checked::Valid(gltf::json::mesh::Semantic::Positions)).is_some_and(|a| a.value() >= root.accessors.len()) {
                return Err(damaged(
                    path,
                    format!("its glTF JSON is not valid glTF 2.0 (meshes[{m}].primitives[{p}].attributes.POSITION: Index out of range)"),
                ));
            }
        }
    }
    let mut errors = Vec::new();
    root.validate(&root, gltf::json::Path::new, &mut |at, error| {
        let at = at().to_string();
        let zeros = matches!(error, Invalid::Missing) && at.starts_with("accessors[") && at.ends_with("].bufferView");
        // Supported here, though gltf-json does not list it.
        let quantization = matches!(error, Invalid::Unsupported) && at.contains("KHR_mesh_quantization");
        if !zeros && !quantization {
            errors.push(format!("{at}: {error}"));
        }
    });
    // gltf-json 1.4 does not validate animation channel targets, which the gltf crate then
    // unwraps: check them here.
    for (a, animation) in root.animations.iter().enumerate() {
        for (c, channel) in animation.channels.iter().enumerate() {
            if channel.target.node.value() >= root.nodes.len() {
                errors.push(format!("animations[{a}].channels[{c}].target.node: Index out of range"));
            }
            if !matches!(channel.target.path, gltf::json::validation::Checked::Valid(_)) {
                errors.push(format!("animations[{a}].channels[{c}].target.path: Invalid value"));
            }
        }
    }
    if let Some(first) = errors.first() {
        return Err(damaged(
            path,
            format!(
                "its glTF JSON is not valid glTF 2.0 ({first}{})",
                if errors.len() > 1 { format!(", and {} more", errors.len() - 1) } else { String::new() }
            ),
        ));
    }
    Ok(Document::from_json_without_validation(root))
}

/// Byte offset and length of a GLB's BIN chunk data.
type BinChunk = (u64, u64);

/// The JSON chunk (read) and the BIN chunk of a GLB of `len` bytes.
fn glb_chunks(path: &Path, file: &mut File, len: u64, header: &[u8]) -> Result<(Vec<u8>, Option<BinChunk>)> {
    let u32_at = |b: &[u8], i: usize| u32::from_le_bytes([b[i], b[i + 1], b[i + 2], b[i + 3]]) as u64;
    if len < 20 {
        return Err(damaged(path, format!("is {len} bytes, shorter than a GLB header and JSON chunk header (20 bytes): truncated")));
    }
    let version = u32_at(header, 4);
    if version != 2 {
        return Err(Error::in_file(path, format!("is GLB version {version} (byte 4); only glTF 2.0 is read"), "re-export as glTF 2.0"));
    }
    let total = u32_at(header, 8);
    if total != len {
        return Err(damaged(path, format!("its GLB header (byte 8) says {total} bytes, but the file has {len}")));
    }
    let mut chunk = [0u8; 8];
    read_exact_at(file, 12, &mut chunk, path)?;
    let json_len = u32_at(&chunk, 0);
    if &chunk[4..] != b"JSON" || 20 + json_len > len {
        return Err(damaged(path, format!("its first GLB chunk (byte 12) is not a JSON chunk of {json_len} bytes within the file")));
    }
    let mut json = vec![0u8; json_len as usize];
    read_exact_at(file, 20, &mut json, path)?;
    let at = 20 + json_len;
    if at + 8 > len {
        return Ok((json, None));
    }
    read_exact_at(file, at, &mut chunk, path)?;
    let bin_len = u32_at(&chunk, 0);
    if &chunk[4..] != b"BIN\0" {
        return Ok((json, None));
    }
    if at + 8 + bin_len > len {
        return Err(damaged(path, format!("its BIN chunk (byte {at}) says {bin_len} bytes, but the file ends at byte {len}: truncated")));
    }
    Ok((json, Some((at + 8, bin_len))))
}

/// The bytes of a `data:[...];base64,` URI, if it is one. Lenient as glTF readers are: the
/// URL-safe digits are read as the standard ones, padding is optional and stray low bits of
/// the last digit are ignored.
fn decode_data_uri(uri: &str) -> Option<Vec<u8>> {
    use base64::engine::{general_purpose::GeneralPurpose, DecodePaddingMode, GeneralPurposeConfig};
    use base64::Engine as _;
    const LENIENT: GeneralPurpose = GeneralPurpose::new(
        &base64::alphabet::STANDARD,
        GeneralPurposeConfig::new().with_decode_padding_mode(DecodePaddingMode::Indifferent).with_decode_allow_trailing_bits(true),
    );
    let (meta, data) = uri.strip_prefix("data:")?.split_once(',')?;
    if !meta.ends_with(";base64") {
        return None;
    }
    if data.contains(['-', '_']) {
        let standard: Vec<u8> = data
            .bytes()
            .map(|c| match c {
                b'-' => b'+',
                b'_' => b'/',
                c => c,
            })
            .collect();
        return LENIENT.decode(standard).ok();
    }
    LENIENT.decode(data).ok()
}

/// A relative URI with `%XX` escapes decoded; `None` for absolute or non-file URIs.
fn percent_decode(uri: &str) -> Option<PathBuf> {
    if uri.contains("://") || uri.starts_with('/') {
        return None;
    }
    let bytes = uri.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        if bytes[i] == b'%' {
            let hex = std::str::from_utf8(bytes.get(i + 1..i + 3)?).ok()?;
            out.push(u8::from_str_radix(hex, 16).ok()?);
            i += 3;
        } else {
            out.push(bytes[i]);
            i += 1;
        }
    }
    Some(PathBuf::from(String::from_utf8(out).ok()?))
}

/// Bytes `offset .. offset + len` of one buffer.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Span {
    buffer: usize,
    offset: u64,
    len: u64,
}

/// An accessor resolved against its views and buffers: reading it cannot go out of bounds.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Layout {
    pub index: usize,
    pub count: usize,
    pub components: usize,
    component: DataType,
    normalized: bool,
    /// The dense data (`None`: zeros) and its stride.
    dense: Option<(Span, usize)>,
    sparse: Option<SparseLayout>,
}

#[derive(Debug, Clone, PartialEq)]
struct SparseLayout {
    count: usize,
    index_type: DataType,
    indices: Span,
    values: Span,
}

fn component_size(c: DataType) -> usize {
    match c {
        DataType::I8 | DataType::U8 => 1,
        DataType::I16 | DataType::U16 => 2,
        DataType::U32 | DataType::F32 => 4,
    }
}

/// The value of the component at the start of `bytes` (little-endian), normalized when asked (glTF 2.0
/// §3.11: signed values divide by the type's max and clamp at -1).
#[inline(always)]
fn component(bytes: &[u8], c: DataType, normalized: bool) -> f32 {
    match (c, normalized) {
        (DataType::F32, _) => f32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]]),
        (DataType::U32, _) => u32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]]) as f32,
        (DataType::I8, false) => bytes[0] as i8 as f32,
        (DataType::U8, false) => bytes[0] as f32,
        (DataType::I16, false) => i16::from_le_bytes([bytes[0], bytes[1]]) as f32,
        (DataType::U16, false) => u16::from_le_bytes([bytes[0], bytes[1]]) as f32,
        (DataType::I8, true) => (bytes[0] as i8 as f32 / 127.0).max(-1.0),
        (DataType::U8, true) => bytes[0] as f32 / 255.0,
        (DataType::I16, true) => (i16::from_le_bytes([bytes[0], bytes[1]]) as f32 / 32767.0).max(-1.0),
        (DataType::U16, true) => u16::from_le_bytes([bytes[0], bytes[1]]) as f32 / 65535.0,
    }
}

fn index_value(bytes: &[u8], c: DataType) -> u32 {
    match c {
        DataType::U8 => bytes[0] as u32,
        DataType::U16 => u16::from_le_bytes([bytes[0], bytes[1]]) as u32,
        _ => u32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]]),
    }
}

impl BufferStore {
    fn buffer_len(&self, buffer: usize) -> u64 {
        match &self.buffers[buffer] {
            BufferData::File { len, .. } => *len,
            BufferData::Memory(bytes) => bytes.len() as u64,
        }
    }

    /// `len` bytes of a view, from `offset` within it, checked against the view and buffer.
    fn span(&self, view: &gltf::buffer::View, offset: u64, len: u64, what: &str) -> Result<Span> {
        let buffer = view.buffer().index();
        let (view_offset, view_len) = (view.offset() as u64, view.length() as u64);
        if view_offset as u128 + view_len as u128 > self.buffer_len(buffer) as u128 {
            return Err(damaged(
                &self.path,
                format!(
                    "buffer view {} (bytes {view_offset} + {view_len}) runs past the end of buffer {buffer} ({} bytes)",
                    view.index(),
                    self.buffer_len(buffer)
                ),
            ));
        }
        if offset as u128 + len as u128 > view_len as u128 {
            return Err(damaged(
                &self.path,
                format!("{what} needs bytes {offset} to {} of buffer view {}, which has {view_len}", offset as u128 + len as u128, view.index()),
            ));
        }
        Ok(Span { buffer, offset: view_offset + offset, len })
    }

    /// Check an accessor against its data and return how to read it. `what` names it in errors.
    pub fn layout(&self, accessor: &gltf::Accessor, what: &str) -> Result<Layout> {
        let what = format!("{what} (accessor {})", accessor.index());
        let (component, dims) = (accessor.data_type(), accessor.dimensions());
        let components = dims.multiplicity();
        // Matrix columns of 1- and 2-byte components are padded to 4 bytes; we read none.
        if matches!(dims, Dimensions::Mat2 | Dimensions::Mat3) && component_size(component) < 4 {
            return Err(damaged(&self.path, format!("{what} is a padded {dims:?} of {component:?}, which the cache reader does not read")));
        }
        let element = components * component_size(component);
        let count = accessor.count();
        let dense = match accessor.view() {
            None => None,
            Some(view) => {
                let stride = view.stride().unwrap_or(element);
                if stride < element {
                    return Err(damaged(
                        &self.path,
                        format!("{what}: buffer view {} has stride {stride}, less than the {element}-byte element", view.index()),
                    ));
                }
                let len = if count == 0 { 0 } else { stride as u128 * (count as u128 - 1) + element as u128 };
                let len = u64::try_from(len).map_err(|_| damaged(&self.path, format!("{what} has an impossible count {count}")))?;
                Some((self.span(&view, accessor.offset() as u64, len, &what)?, stride))
            }
        };
        let sparse = match accessor.sparse() {
            None => None,
            Some(s) => {
                let n = s.count();
                if n > count {
                    return Err(damaged(&self.path, format!("{what} has {n} sparse values but only {count} elements")));
                }
                let index_type = match s.indices().index_type() {
                    IndexType::U8 => DataType::U8,
                    IndexType::U16 => DataType::U16,
                    IndexType::U32 => DataType::U32,
                };
                let bytes = |size: usize| {
                    u64::try_from(n as u128 * size as u128).map_err(|_| damaged(&self.path, format!("{what} has an impossible sparse count {n}")))
                };
                let indices = self.span(
                    &s.indices().view(),
                    s.indices().offset() as u64,
                    bytes(component_size(index_type))?,
                    &format!("the sparse indices of {what}"),
                )?;
                let values = self.span(&s.values().view(), s.values().offset() as u64, bytes(element)?, &format!("the sparse values of {what}"))?;
                Some(SparseLayout { count: n, index_type, indices, values })
            }
        };
        // Without a view an accessor is zeros (plus its sparse values): allowed, and callers
        // check its count against an accessor that has data before reading it.
        Ok(Layout { index: accessor.index(), count, components, component, normalized: accessor.normalized(), dense, sparse })
    }

    /// Check that an accessor is backed by data (a buffer view), so its count is bounded by
    /// the file; accessors read without that check have a count tied to one that is.
    pub(crate) fn require_data(&self, layout: &Layout, what: &str) -> Result<()> {
        match layout.dense {
            Some(_) => Ok(()),
            None if layout.count <= 1 => Ok(()),
            None => Err(damaged(&self.path, format!("{what} (accessor {}) has {} elements but no buffer view", layout.index, layout.count))),
        }
    }

    fn read_span(&mut self, span: Span, out: &mut Vec<u8>) -> Result<()> {
        out.resize(span.len as usize, 0);
        match &self.buffers[span.buffer] {
            BufferData::Memory(bytes) => {
                out.copy_from_slice(&bytes[span.offset as usize..(span.offset + span.len) as usize]);
                Ok(())
            }
            BufferData::File { file, offset, .. } => {
                let (path, handle) = &mut self.files[*file];
                read_exact_at(handle, offset + span.offset, out, path)
            }
        }
    }

    /// Every component of every element as f32 (normalized integers converted), sparse
    /// substitution applied: `count * components` values into `out`. `scratch` holds bytes.
    pub(crate) fn read_floats(&mut self, layout: &Layout, out: &mut Vec<f32>, scratch: &mut Vec<u8>) -> Result<()> {
        let (c, size) = (layout.component, component_size(layout.component));
        out.clear();
        out.resize(layout.count * layout.components, 0.0);
        if let Some((span, stride)) = layout.dense {
            self.read_span(span, scratch)?;
            // One loop per kind of component (`component` inlined with it fixed), not a match
            // per value: the played-error check reads every target of a 500k-vertex file back.
            fn dense(out: &mut [f32], scratch: &[u8], (components, stride, size): (usize, usize, usize), read: impl Fn(&[u8]) -> f32) {
                for (values, element) in out.chunks_exact_mut(components).zip(scratch.chunks(stride)) {
                    for (k, v) in values.iter_mut().enumerate() {
                        *v = read(&element[k * size..]);
                    }
                }
            }
            let shape = (layout.components, stride, size);
            match (c, layout.normalized) {
                (DataType::F32, _) => dense(out, scratch, shape, |b| component(b, DataType::F32, false)),
                (DataType::I16, false) => dense(out, scratch, shape, |b| component(b, DataType::I16, false)),
                (DataType::I16, true) => dense(out, scratch, shape, |b| component(b, DataType::I16, true)),
                (DataType::I8, false) => dense(out, scratch, shape, |b| component(b, DataType::I8, false)),
                (DataType::I8, true) => dense(out, scratch, shape, |b| component(b, DataType::I8, true)),
                (c, normalized) => dense(out, scratch, shape, |b| component(b, c, normalized)),
            }
        }
        if let Some(sparse) = layout.sparse.clone() {
            let indices = self.sparse_indices(layout, &sparse, scratch)?;
            self.read_span(sparse.values, scratch)?;
            let element = layout.components * size;
            for (j, &i) in indices.iter().enumerate() {
                for k in 0..layout.components {
                    out[i as usize * layout.components + k] = component(&scratch[j * element + k * size..], c, layout.normalized);
                }
            }
        }
        Ok(())
    }

    /// Integer elements (indices, joints) as u32: `count * components` values.
    pub(crate) fn read_uints(&mut self, layout: &Layout, what: &str) -> Result<Vec<u32>> {
        if !matches!(layout.component, DataType::U8 | DataType::U16 | DataType::U32) || layout.normalized {
            return Err(damaged(
                &self.path,
                format!(
                    "{what} (accessor {}) has {:?}{} components; it needs unsigned integers",
                    layout.index,
                    layout.component,
                    if layout.normalized { " normalized" } else { "" }
                ),
            ));
        }
        let mut scratch = Vec::new();
        // u32 through f32 would round above 2^24: decode integers directly.
        let (c, size) = (layout.component, component_size(layout.component));
        let mut out = vec![0u32; layout.count * layout.components];
        if let Some((span, stride)) = layout.dense {
            self.read_span(span, &mut scratch)?;
            for (e, values) in out.chunks_exact_mut(layout.components).enumerate() {
                for (k, v) in values.iter_mut().enumerate() {
                    *v = index_value(&scratch[e * stride + k * size..], c);
                }
            }
        }
        if let Some(sparse) = layout.sparse.clone() {
            let indices = self.sparse_indices(layout, &sparse, &mut scratch)?;
            self.read_span(sparse.values, &mut scratch)?;
            for (j, &i) in indices.iter().enumerate() {
                for k in 0..layout.components {
                    out[i as usize * layout.components + k] = index_value(&scratch[(j * layout.components + k) * size..], c);
                }
            }
        }
        Ok(out)
    }

    fn sparse_indices(&mut self, layout: &Layout, sparse: &SparseLayout, scratch: &mut Vec<u8>) -> Result<Vec<u32>> {
        self.read_span(sparse.indices, scratch)?;
        let size = component_size(sparse.index_type);
        let indices: Vec<u32> = scratch.chunks_exact(size).map(|b| index_value(b, sparse.index_type)).collect();
        if let Some(j) = (0..indices.len()).find(|&j| indices[j] as usize >= layout.count || (j > 0 && indices[j] <= indices[j - 1])) {
            return Err(damaged(
                &self.path,
                format!(
                    "sparse index {j} of accessor {} is {}: sparse indices must increase and stay below the count {}",
                    layout.index, indices[j], layout.count
                ),
            ));
        }
        Ok(indices)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn data_uris_and_percent_escapes() {
        assert_eq!(decode_data_uri("data:application/octet-stream;base64,AAECAw=="), Some(vec![0, 1, 2, 3]));
        assert_eq!(decode_data_uri("data:application/gltf-buffer;base64,/w"), Some(vec![255]));
        assert_eq!(decode_data_uri("data:text/plain,hello"), None);
        assert_eq!(decode_data_uri("data:;base64,a*b"), None);
        assert_eq!(decode_data_uri("data:;base64,-_8="), Some(vec![0xfb, 0xff]), "URL-safe digits");
        assert_eq!(decode_data_uri("data:;base64,/x=="), Some(vec![255]), "stray low bits");
        assert_eq!(decode_data_uri("data:;base64,AAECA"), None, "a lone last digit is no byte");
        assert_eq!(percent_decode("my%20clip.bin"), Some(PathBuf::from("my clip.bin")));
        assert_eq!(percent_decode("http://example.com/a.bin"), None);
        assert_eq!(percent_decode("bad%2"), None);
    }

    #[test]
    fn normalized_components_follow_the_spec() {
        assert_eq!(component(&[0x81], DataType::I8, true), -1.0);
        assert_eq!(component(&[0x80], DataType::I8, true), -1.0, "-128 clamps to -1");
        assert_eq!(component(&[255], DataType::U8, true), 1.0);
        assert_eq!(component(&0x7fffi16.to_le_bytes(), DataType::I16, true), 1.0);
        assert_eq!(component(&0xffffu16.to_le_bytes(), DataType::U16, true), 1.0);
        assert_eq!(component(&(-5i16).to_le_bytes(), DataType::I16, false), -5.0);
    }
}
