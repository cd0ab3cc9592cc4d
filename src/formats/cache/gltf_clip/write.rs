//! A vertex cache as a glTF morph clip (`.glb`): what "full frame" means in glTF.
//!
//! Frame 0 is the base mesh; frame `k` is morph target `k` (its offset from frame 0, so
//! target 0 is an accessor without data), and one LINEAR weights channel is one-hot at each
//! frame's time. The one-hot output (frames x frames weights) is a sparse accessor holding
//! only the ones, so the file grows linearly with the frame count. A target is stored sparse
//! when that is smaller (vertices that do not move are left out), dense otherwise.
//!
//! Streamed: a first pass over the frames measures each target (bounds, moved vertices),
//! which fixes the JSON; then the binary chunk is written frame by frame. Memory is a few
//! frames plus a few numbers per frame.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

use gltf_json as json;
use json::accessor::{sparse, ComponentType, IndexComponentType, Type};
use json::animation::{Interpolation, Property};
use json::buffer::{Stride, Target as ViewTarget};
use json::validation::{Checked::Valid, USize64};
use json::Index;
use serde_json::{json as value, Value};

use crate::algorithms::frames::FrameSource;
use crate::algorithms::geometry::TriMesh;
use crate::formats::cache::check_writable;
use crate::formats::export::glb::accessor_in as accessor;
use crate::formats::export::sparse_is_smaller;
use crate::support::error::{Error, Result};

/// glTF targets are indexed by a u32 weight slot, and the one-hot output has frames^2 slots.
pub(crate) const MAX_GLB_FRAMES: usize = 65_535;

#[derive(Debug, Clone, Copy, PartialEq)]
enum Storage {
    /// Nothing moves: an accessor without data.
    Zero,
    Dense,
    Sparse,
}

/// What the first pass learns about one target.
#[derive(Debug, Clone, Copy)]
struct Measure {
    moved: usize,
    lo: [f32; 3],
    hi: [f32; 3],
    storage: Storage,
}

fn f32_points(points: &[[f64; 3]]) -> impl Iterator<Item = [f32; 3]> + Clone + '_ {
    points.iter().map(|p| p.map(|x| x as f32))
}

fn bounds(points: impl Iterator<Item = [f32; 3]>) -> ([f32; 3], [f32; 3]) {
    points.fold(([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]), |(mut lo, mut hi), p| {
        for d in 0..3 {
            lo[d] = lo[d].min(p[d]);
            hi[d] = hi[d].max(p[d]);
        }
        (lo, hi)
    })
}

fn vec3_value(v: [f32; 3]) -> Value {
    value!([v[0] as f64, v[1] as f64, v[2] as f64])
}

fn pad4(n: usize) -> usize {
    n.next_multiple_of(4)
}

/// The smallest index type for `count` slots: (component, bytes). u8 only where asked (sparse
/// indices); u16 leaves 65535 free, the primitive-restart value of triangle indices.
fn index_type(count: usize, allow_u8: bool) -> (ComponentType, usize) {
    if allow_u8 && count <= 1 << 8 {
        (ComponentType::U8, 1)
    } else if count < 1 << 16 {
        (ComponentType::U16, 2)
    } else {
        (ComponentType::U32, 4)
    }
}

fn push_index(out: &mut Vec<u8>, v: u32, size: usize) {
    match size {
        1 => out.push(v as u8),
        2 => out.extend((v as u16).to_le_bytes()),
        _ => out.extend(v.to_le_bytes()),
    }
}

fn pad_to_4(out: &mut Vec<u8>) {
    out.resize(pad4(out.len()), 0);
}

fn sparse_of(
    count: usize,
    index_view: u32,
    index_offset: usize,
    index_component: ComponentType,
    value_view: u32,
    value_offset: usize,
) -> sparse::Sparse {
    sparse::Sparse {
        count: USize64(count as u64),
        indices: sparse::Indices {
            buffer_view: Index::new(index_view),
            byte_offset: USize64(index_offset as u64),
            component_type: Valid(IndexComponentType(index_component)),
            extensions: None,
            extras: None,
        },
        values: sparse::Values { buffer_view: Index::new(value_view), byte_offset: USize64(value_offset as u64), extensions: None, extras: None },
        extensions: None,
        extras: None,
    }
}

fn view(byte_offset: usize, byte_length: usize, stride: Option<usize>, target: Option<ViewTarget>) -> json::buffer::View {
    json::buffer::View {
        buffer: Index::new(0),
        byte_length: USize64(byte_length as u64),
        byte_offset: (byte_offset != 0).then_some(USize64(byte_offset as u64)),
        byte_stride: stride.map(Stride),
        name: None,
        target: target.map(Valid),
        extensions: None,
        extras: None,
    }
}

/// Write `frames` of `mesh` as a glb morph clip (see the module documentation), atomically.
pub fn write(path: &Path, mesh: &TriMesh, frames: &mut dyn FrameSource, fps: f64) -> Result<()> {
    let (n, count) = check_writable(path, frames, fps)?;
    if mesh.positions.len() != n || mesh.triangles.is_empty() {
        return Err(Error::general(
            format!(
                "cannot write {}: the mesh has {} vertices and {} triangles, the frames {n} vertices",
                path.display(),
                mesh.positions.len(),
                mesh.triangles.len()
            ),
            "pass the mesh the frames belong to",
        ));
    }
    if count > MAX_GLB_FRAMES {
        return Err(Error::in_file(
            path,
            format!("{count} frames is more than a glTF morph clip holds ({MAX_GLB_FRAMES})"),
            "write a shorter frame range, or use PC2, MDD or USD",
        ));
    }
    let times: Vec<f32> = (0..count).map(|k| frames.time(k) as f32).collect();
    if let Some(k) = times.windows(2).position(|w| w[1] <= w[0]) {
        return Err(Error::in_file(
            path,
            format!("frames {k} and {} have the same time in f32 ({} s)", k + 1, times[k]),
            "write frames with distinct times",
        ));
    }

    // Pass 1: the base and each target's bounds and moved vertices.
    let mut points = vec![[0.0; 3]; n];
    frames.read_frame(0, &mut points)?;
    let base: Vec<[f32; 3]> = f32_points(&points).collect();
    let (sparse_component, sparse_size) = index_type(n, true);
    let mut measures = Vec::with_capacity(count);
    for k in 0..count {
        frames.read_frame(k, &mut points)?;
        let offsets = f32_points(&points).zip(&base).map(|(p, b)| [p[0] - b[0], p[1] - b[1], p[2] - b[2]]);
        let moved = offsets.clone().filter(|d| *d != [0.0; 3]).count();
        let (mut lo, mut hi) = bounds(offsets);
        if moved < n {
            (lo, hi) = (lo.map(|x| x.min(0.0)), hi.map(|x| x.max(0.0)));
        }
        let storage = match moved {
            0 => Storage::Zero,
            m if sparse_is_smaller(m, n, sparse_size) => Storage::Sparse,
            _ => Storage::Dense,
        };
        measures.push(Measure { moved, lo, hi, storage });
    }

    // The JSON: views in the order their bytes follow in the BIN chunk.
    let (index_component, index_size) = index_type(n, false);
    let index_bytes = pad4(3 * mesh.triangles.len() * index_size);
    let dense = measures.iter().filter(|m| m.storage == Storage::Dense).count();
    let vertex_bytes = 12 * n * (1 + dense);
    let sparse_bytes: usize = measures.iter().filter(|m| m.storage == Storage::Sparse).map(|m| pad4(m.moved * sparse_size) + 12 * m.moved).sum();
    let animation_bytes = 12 * count;
    let asset = json::Asset {
        copyright: None,
        extensions: None,
        extras: None,
        generator: Some(format!("blendsim {} (vertex cache)", env!("CARGO_PKG_VERSION"))),
        min_version: None,
        version: "2.0".into(),
    };
    let mut root = json::Root { asset, ..Default::default() };
    let mut at = 0;
    let mut next_view = |root: &mut json::Root, len: usize, stride: Option<usize>, target: Option<ViewTarget>| -> Option<u32> {
        if len == 0 {
            return None;
        }
        root.push(view(at, len, stride, target));
        at += len;
        Some(root.buffer_views.len() as u32 - 1)
    };
    let index_view = next_view(&mut root, index_bytes, None, Some(ViewTarget::ElementArrayBuffer)).expect("triangles exist");
    let vertex_view = next_view(&mut root, vertex_bytes, Some(12), Some(ViewTarget::ArrayBuffer)).expect("vertices exist");
    let sparse_view = next_view(&mut root, sparse_bytes, None, None);
    let animation_view = next_view(&mut root, animation_bytes, None, None).expect("frames exist");
    let bin_len = at;

    let mut position = accessor(Some((vertex_view, 0)), n, ComponentType::F32, Type::Vec3);
    let (lo, hi) = bounds(base.iter().copied());
    (position.min, position.max) = (Some(vec3_value(lo)), Some(vec3_value(hi)));
    let position = root.push(position);
    let indices = root.push(accessor(Some((index_view, 0)), 3 * mesh.triangles.len(), index_component, Type::Scalar));
    let (mut dense_at, mut sparse_at) = (12 * n, 0);
    let mut targets = Vec::with_capacity(count);
    for m in &measures {
        let mut a = match m.storage {
            Storage::Zero => accessor(None, n, ComponentType::F32, Type::Vec3),
            Storage::Dense => {
                dense_at += 12 * n;
                accessor(Some((vertex_view, (dense_at - 12 * n) as u64)), n, ComponentType::F32, Type::Vec3)
            }
            Storage::Sparse => {
                let sv = sparse_view.expect("a sparse target has a view");
                let mut a = accessor(None, n, ComponentType::F32, Type::Vec3);
                let values_at = sparse_at + pad4(m.moved * sparse_size);
                a.sparse = Some(sparse_of(m.moved, sv, sparse_at, sparse_component, sv, values_at));
                sparse_at = values_at + 12 * m.moved;
                a
            }
        };
        (a.min, a.max) = (Some(vec3_value(m.lo)), Some(vec3_value(m.hi)));
        targets.push(json::mesh::MorphTarget { positions: Some(root.push(a)), normals: None, tangents: None });
    }
    let mut input = accessor(Some((animation_view, 0)), count, ComponentType::F32, Type::Scalar);
    (input.min, input.max) = (Some(value!([times[0] as f64])), Some(value!([times[count - 1] as f64])));
    let input = root.push(input);
    let mut output = accessor(None, count * count, ComponentType::F32, Type::Scalar);
    output.sparse = Some(sparse_of(count, animation_view, 4 * count, ComponentType::U32, animation_view, 8 * count));
    let output = root.push(output);

    let name = path.file_stem().map_or_else(|| "cache".to_string(), |s| s.to_string_lossy().into_owned());
    let mut material = json::Material { name: Some(name.clone()), ..Default::default() };
    // glTF's default material is fully metallic, black without an environment map.
    material.pbr_metallic_roughness.metallic_factor = json::material::StrengthFactor(0.0);
    let material = root.push(material);
    let names: Vec<String> = (0..count).map(|k| format!("frame_{k}")).collect();
    let extras = serde_json::to_string(&value!({ "targetNames": names })).expect("names serialize");
    let mesh_index = root.push(json::Mesh {
        extensions: None,
        extras: Some(json::extras::RawValue::from_string(extras).expect("valid JSON")),
        name: Some(name.clone()),
        primitives: vec![json::mesh::Primitive {
            attributes: [(Valid(json::mesh::Semantic::Positions), position)].into_iter().collect(),
            extensions: None,
            extras: None,
            indices: Some(indices),
            material: Some(material),
            mode: Valid(json::mesh::Mode::Triangles),
            targets: Some(targets),
        }],
        weights: Some(vec![0.0; count]),
    });
    let node = root.push(json::Node { mesh: Some(mesh_index), name: Some(name.clone()), ..Default::default() });
    let scene = root.push(json::Scene { extensions: None, extras: None, name: Some(name.clone()), nodes: vec![node] });
    root.scene = Some(scene);
    root.push(json::Animation {
        extensions: None,
        extras: None,
        name: Some(name),
        channels: vec![json::animation::Channel {
            sampler: Index::new(0),
            target: json::animation::Target { extensions: None, extras: None, node, path: Valid(Property::MorphTargetWeights) },
            extensions: None,
            extras: None,
        }],
        samplers: vec![json::animation::Sampler { extensions: None, extras: None, input, interpolation: Valid(Interpolation::Linear), output }],
    });
    root.push(json::Buffer { byte_length: USize64(bin_len as u64), name: None, uri: None, extensions: None, extras: None });
    let mut json_bytes =
        root.to_vec().map_err(|e| Error::general(format!("cannot write {}: glTF JSON: {e}", path.display()), "report this as a bug"))?;
    json_bytes.resize(pad4(json_bytes.len()), b' ');
    let total = 12 + 8 + json_bytes.len() + 8 + bin_len;
    if total > u32::MAX as usize {
        return Err(Error::in_file(
            path,
            format!("would be {total} bytes, more than a GLB holds (4 GiB)"),
            "write a shorter frame range, or use PC2, MDD or USD",
        ));
    }

    // Pass 2: stream the container.
    crate::support::output::write_atomic_with(path, |tmp| {
        let file = File::create(tmp).map_err(|e| Error::io(tmp, &e, "create the glb file"))?;
        let mut w = BufWriter::new(file);
        let io = |e: std::io::Error| Error::io(path, &e, "write the glb file");
        let mut bytes = Vec::new();
        bytes.extend_from_slice(b"glTF");
        bytes.extend(2u32.to_le_bytes());
        bytes.extend((total as u32).to_le_bytes());
        bytes.extend((json_bytes.len() as u32).to_le_bytes());
        bytes.extend_from_slice(b"JSON");
        bytes.extend_from_slice(&json_bytes);
        bytes.extend((bin_len as u32).to_le_bytes());
        bytes.extend_from_slice(b"BIN\0");
        for &i in mesh.triangles.iter().flatten() {
            push_index(&mut bytes, i, index_size);
        }
        pad_to_4(&mut bytes);
        w.write_all(&bytes).map_err(io)?;

        let mut write_vec3s = |w: &mut BufWriter<File>, points: &mut dyn Iterator<Item = [f32; 3]>| -> Result<()> {
            bytes.clear();
            points.for_each(|p| p.iter().for_each(|x| bytes.extend(x.to_le_bytes())));
            w.write_all(&bytes).map_err(io)
        };
        write_vec3s(&mut w, &mut base.iter().copied())?;
        for (k, m) in measures.iter().enumerate() {
            if m.storage == Storage::Dense {
                frames.read_frame(k, &mut points)?;
                write_vec3s(&mut w, &mut f32_points(&points).zip(&base).map(|(p, b)| [p[0] - b[0], p[1] - b[1], p[2] - b[2]]))?;
            }
        }
        let mut sparse = Vec::new();
        for (k, m) in measures.iter().enumerate() {
            if m.storage == Storage::Sparse {
                frames.read_frame(k, &mut points)?;
                let offsets: Vec<(usize, [f32; 3])> = f32_points(&points)
                    .zip(&base)
                    .map(|(p, b)| [p[0] - b[0], p[1] - b[1], p[2] - b[2]])
                    .enumerate()
                    .filter(|(_, d)| *d != [0.0; 3])
                    .collect();
                if offsets.len() != m.moved {
                    return Err(Error::general(
                        format!("cannot write {}: frame {k} changed while it was written", path.display()),
                        "write from a cache that is not being modified",
                    ));
                }
                sparse.clear();
                offsets.iter().for_each(|&(i, _)| push_index(&mut sparse, i as u32, sparse_size));
                pad_to_4(&mut sparse);
                offsets.iter().for_each(|(_, d)| d.iter().for_each(|x| sparse.extend(x.to_le_bytes())));
                w.write_all(&sparse).map_err(io)?;
            }
        }
        let mut animation = Vec::with_capacity(animation_bytes);
        times.iter().for_each(|t| animation.extend(t.to_le_bytes()));
        (0..count).for_each(|k| animation.extend(((k * count + k) as u32).to_le_bytes()));
        (0..count).for_each(|_| animation.extend(1f32.to_le_bytes()));
        w.write_all(&animation).map_err(io)?;
        w.into_inner().map_err(|e| io(e.into_error()))?.sync_all().map_err(io)
    })
}
