//! Binary glTF writers. Layout in `formats/gltf.md`.
//!
//! - this file: the files' structure (node, mesh, targets, animation) and the GLB container;
//! - [`quantize`]: `KHR_mesh_quantization`, the integer grid chosen from the error budget;
//! - [`meshopt`]: `EXT_meshopt_compression` of the buffer views;
//! - [`readback`]: the error a written file plays with, measured on its bytes.
//!
//! The JSON is built with `gltf-json`; the GLB container is ours (12-byte header, a JSON chunk
//! padded with spaces, a BIN chunk padded with zeros). Every block of binary data starts on a
//! 4-byte boundary, so every accessor is aligned whatever its component type.

use gltf_json as json;
use json::accessor::{sparse, ComponentType, GenericComponentType, IndexComponentType, Type};
use json::animation::{Interpolation, Property};
use json::buffer::{Stride, Target as ViewTarget};
use json::validation::{Checked::Valid, USize64};
use json::Index;
use serde_json::{json as value, Value};

use super::texture::Texture;
use crate::algorithms::blendshape::clip::BlendShapeClip;
use crate::algorithms::blendshape::fullframe::FullFrame;
use crate::algorithms::geometry::attributes::{split_at_seams, CornerAttributes};
use crate::algorithms::geometry::Bounds;
use quantize::{Grid, Storage, Stored};

pub mod meshopt;
pub mod quantize;
pub mod readback;

/// How a glb stores its data (`[export] gltf_compression`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Compression {
    /// `KHR_mesh_quantization` (integer positions, offsets, normals; UVs in shorts): read by
    /// Blender, three.js, Babylon.js. Falls back to f32 when shorts cannot meet the budget.
    #[default]
    Quantize,
    /// Quantized, then `EXT_meshopt_compression` (required): three.js and Babyl.js with their
    /// meshopt decoders; Blender 4.2 to 5.0 refuse it.
    Meshopt,
    /// f32 everywhere, no extension.
    None,
}

/// How a writer stores the data: the compression and the error it may add.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Encoding {
    /// See [`Compression`].
    pub compression: Compression,
    /// The largest distance (scene units) a played point may move by quantization.
    pub max_error: f64,
}

impl Encoding {
    /// f32, no extension: the bytes as before compression existed.
    pub const FLOAT: Encoding = Encoding { compression: Compression::None, max_error: 0.0 };
}

/// How the node maps scene units to glTF's y-up meters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Placement {
    /// The scene's up axis is Z (rotated -90° about X to glTF's Y up).
    pub z_up: bool,
    /// Scene units in meters (the node is scaled by it).
    pub meters_per_unit: f64,
}

impl Placement {
    /// A scene point's direction in glTF's y-up frame (units not applied): `(x, z, -y)` for a
    /// z-up scene.
    pub fn place(&self, p: [f64; 3]) -> [f64; 3] {
        if self.z_up {
            [p[0], p[2], -p[1]]
        } else {
            p
        }
    }
}

/// Morph targets + CUBICSPLINE weight animation reproducing the Hermite trajectory exactly.
///
/// A clip without targets (a static animation) is a plain mesh with no animation: glTF has
/// no way to say "a weights channel over zero targets".
///
/// `attributes` add `TEXCOORD_0`, `NORMAL` and one primitive per material group (vertices split
/// at UV and normal seams, see `File::new`); without them the file is as before. `textures`
/// (per material group, `texture::load`; may be empty) are embedded and become the groups'
/// `baseColorTexture` when the surface has UVs.
pub fn blendshapes(clip: &BlendShapeClip, surface: Surface, name: &str, placement: Placement, encoding: Encoding) -> Glb {
    let times: Vec<f32> = clip.times.iter().map(|&t| t as f32).collect();
    let curves = &clip.curves;
    let mut output = Vec::with_capacity(3 * times.len() * curves.len());
    for k in 0..times.len() {
        output.extend(curves.iter().map(|c| c.in_tangents[k]));
        output.extend(curves.iter().map(|c| c.values[k]));
        output.extend(curves.iter().map(|c| c.out_tangents[k]));
    }
    // The weights between keys too: 8 samples per interval bound what is played.
    let sums = clip.times.windows(2).flat_map(|w| (0..8).map(move |i| w[0] + (w[1] - w[0]) * i as f64 / 8.0)).chain(clip.times.last().copied());
    let played: Vec<Vec<f64>> = sums.map(|t| clip.weights_at(t)).collect();
    with_weights(clip, surface, name, placement, (&times, &output, Interpolation::CubicSpline), &played, encoding)
}

/// Morph targets + LINEAR weights sampled at `frame_times` (seconds, every frame): exact at
/// frames, the linear blend of two frames in between, and nothing an importer could drop
/// (Blender's glTF importer ignores CUBICSPLINE tangents).
pub(crate) fn blendshapes_sampled(
    clip: &BlendShapeClip,
    frame_times: &[f64],
    surface: Surface,
    name: &str,
    placement: Placement,
    encoding: Encoding,
) -> Glb {
    let times: Vec<f32> = frame_times.iter().map(|&t| t as f32).collect();
    let output: Vec<f32> = frame_times.iter().flat_map(|&t| clip.weights_at(t)).map(|w| w as f32).collect();
    let played: Vec<Vec<f64>> = output.chunks(clip.targets.len().max(1)).map(|w| w.iter().map(|&x| x as f64).collect()).collect();
    with_weights(clip, surface, name, placement, (&times, &output, Interpolation::Linear), &played, encoding)
}

/// The weights animation: input times, output values, interpolation.
type Sampler<'a> = (&'a [f32], &'a [f32], Interpolation);

fn with_weights(
    clip: &BlendShapeClip,
    surface: Surface,
    name: &str,
    placement: Placement,
    (times, output, interpolation): Sampler,
    played: &[Vec<f64>],
    encoding: Encoding,
) -> Glb {
    let ranges: Vec<f32> = clip.targets.iter().map(|t| t.offsets.iter().flatten().fold(0.0f32, |m, x| m.max(x.abs()))).collect();
    let largest = ranges.iter().copied().fold(0.0f32, f32::max);
    let weight_sum = played.iter().map(|w| w.iter().map(|x| x.abs()).sum::<f64>()).fold(0.0, f64::max);
    // A static clip (no animation) stays f32: there is no played error to read back and state.
    let mut storage = vec![Storage::Grid; clip.targets.len()];
    let grid = grid(encoding, &clip.base, largest, weight_sum).or_else(|| {
        // One grid would overflow shorts: a step per target instead of an f32 file.
        let weight_max: Vec<f64> = (0..ranges.len()).map(|j| played.iter().map(|w| w[j].abs()).fold(0.0, f64::max)).collect();
        let (g, s) =
            quantize::per_target(&clip.base, &ranges, &weight_max, encoding.max_error).filter(|_| encoding.compression != Compression::None)?;
        storage = s;
        Some((g, encoding.compression))
    });
    let grid = grid.filter(|_| !clip.targets.is_empty());
    // Targets on steps of their own: their weights carry the factor the node's scale undoes.
    let scaled: Vec<f32>;
    let output = match grid {
        Some((g, _)) if storage.iter().any(|s| matches!(s, Storage::Step(_))) => {
            let n = clip.targets.len();
            scaled = output.iter().enumerate().map(|(i, &w)| (w as f64 * storage[i % n].weight_scale(&g)) as f32).collect();
            &scaled[..]
        }
        _ => output,
    };
    let mut file = File::new(name, surface, &clip.base, placement, grid);
    let n = clip.vertex_count();
    let mut targets: Vec<(String, Index<json::Accessor>, Option<Index<json::Accessor>>)> =
        clip.targets.iter().zip(&storage).map(|(t, &s)| (t.name.clone(), file.morph_target(n, &t.indices, &t.offsets, s), None)).collect();
    if let Some(triangles) = file.normal_triangles.clone() {
        let deltas = morph_normal_deltas(clip, &triangles, file.sources.as_deref());
        let vertices = file.sources.as_ref().map_or(n, Vec::len);
        // Normal deltas stay f32: the position grid is not theirs, and glTF takes a quantized
        // NORMAL target only as normalized integers.
        let grid = file.grid.take();
        for (target, (indices, offsets)) in targets.iter_mut().zip(deltas) {
            target.2 = Some(file.morph_target(vertices, &indices, &offsets, Storage::Float));
        }
        file.grid = grid;
    }
    if !targets.is_empty() {
        file.morph(targets, times, output, interpolation);
    }
    file.finish()
}

/// One morph target per frame (the offset of that frame from frame 0) with one-hot LINEAR
/// weights: what a vertex cache looks like in glTF.
pub fn full_frame(frames: &FullFrame, surface: Surface, name: &str, placement: Placement, encoding: Encoding) -> Glb {
    let base = &frames.points[0];
    let largest =
        frames.points.iter().flat_map(|f| f.iter().zip(base).flat_map(|(p, b)| (0..3).map(move |a| (p[a] - b[a]).abs()))).fold(0.0f32, f32::max);
    // One-hot weights: a played frame is the base plus one target.
    let mut file = File::new(name, surface, base, placement, grid(encoding, base, largest, 1.0));
    let mut targets = Vec::with_capacity(frames.frames.len());
    for (frame, points) in frames.frames.iter().zip(&frames.points) {
        let (mut indices, mut offsets) = (Vec::new(), Vec::new());
        for (i, (p, b)) in points.iter().zip(base).enumerate() {
            let d = [p[0] - b[0], p[1] - b[1], p[2] - b[2]];
            if d != [0.0; 3] {
                indices.push(i as u32);
                offsets.push(d);
            }
        }
        targets.push((format!("frame_{frame}"), file.morph_target(base.len(), &indices, &offsets, Storage::Grid), None));
    }
    let times: Vec<f32> = frames.times.iter().map(|&t| t as f32).collect();
    let count = times.len();
    let mut output = vec![0.0f32; count * count];
    for k in 0..count {
        output[k * count + k] = 1.0;
    }
    file.morph(targets, &times, &output, Interpolation::Linear);
    file.finish()
}

/// The grid of a quantized file (with its compression), or `None` for f32.
fn grid(encoding: Encoding, base: &[[f32; 3]], largest_offset: f32, weight_sum: f64) -> Option<(Grid, Compression)> {
    match encoding.compression {
        Compression::None => None,
        c => Grid::for_budget(base, largest_offset, weight_sum, encoding.max_error).map(|g| (g, c)),
    }
}

/// Area-weighted unit normals of the glTF vertices (`sources[j]`: the point vertex `j` shows;
/// `None`: vertex `j` is point `j`), each from the triangles that use that vertex: what a
/// renderer computes on the file's vertices (three.js `computeVertexNormals`).
fn vertex_normals(points: &[[f64; 3]], triangles: &[[u32; 3]], sources: Option<&[u32]>) -> Vec<[f64; 3]> {
    let point = |j: u32| points[sources.map_or(j, |s| s[j as usize]) as usize];
    let mut n = vec![[0.0; 3]; sources.map_or(points.len(), <[u32]>::len)];
    for t in triangles {
        let p = t.map(point);
        let f = crate::algorithms::geometry::cross(crate::algorithms::geometry::sub(p[1], p[0]), crate::algorithms::geometry::sub(p[2], p[0]));
        for &j in t {
            let x = &mut n[j as usize];
            *x = [x[0] + f[0], x[1] + f[1], x[2] + f[2]];
        }
    }
    n.into_iter()
        .map(|x| {
            let l = crate::algorithms::geometry::norm(x);
            if l > 0.0 {
                x.map(|c| c / l)
            } else {
                x
            }
        })
        .collect()
}

/// Per target, the glTF vertices whose normal changes and by how much: the normals of the
/// target's shape (base + offsets) minus the base's, both recomputed on the file's vertices. A
/// renderer adds them with the target weights and renormalizes: the normals of the blended
/// shape to first order (README, "Animated normals", measures how close).
pub fn morph_normal_deltas(clip: &BlendShapeClip, triangles: &[[u32; 3]], sources: Option<&[u32]>) -> Vec<(Vec<u32>, Vec<[f32; 3]>)> {
    let base: Vec<[f64; 3]> = clip.base.iter().map(|p| p.map(f64::from)).collect();
    let rest = vertex_normals(&base, triangles, sources);
    clip.targets
        .iter()
        .map(|t| {
            let mut shape = base.clone();
            for (&i, o) in t.indices.iter().zip(&t.offsets) {
                let p = &mut shape[i as usize];
                *p = [p[0] + o[0] as f64, p[1] + o[1] as f64, p[2] + o[2] as f64];
            }
            let mut out = (Vec::new(), Vec::new());
            for (j, (a, b)) in vertex_normals(&shape, triangles, sources).iter().zip(&rest).enumerate() {
                let d = [(a[0] - b[0]) as f32, (a[1] - b[1]) as f32, (a[2] - b[2]) as f32];
                if d != [0.0; 3] {
                    out.0.push(j as u32);
                    out.1.push(d);
                }
            }
            out
        })
        .collect()
}

/// The binary data, one buffer view per kind, in this order.
#[derive(Debug, Clone, Copy)]
enum Block {
    Indices,
    /// Base positions and dense morph targets (vec3 f32, so one view with stride 12).
    Vertices,
    SparseIndices,
    SparseValues,
    Animation,
    /// Elements of 8 bytes: TEXCOORD_0 (vec2 f32), quantized positions and dense targets (vec3
    /// i16 + padding); after the others, so files without UVs keep their layout.
    Stride8,
    /// Elements of 4 bytes: quantized normals and byte targets (vec3 i8 + padding), UVs (vec2 u16).
    Stride4,
    /// The weld map (`extras.weldMap`) when it is not the index list: last, so files without
    /// one keep their layout.
    WeldMap,
}
const BLOCKS: usize = 8;
const KINDS: [Block; BLOCKS] =
    [Block::Indices, Block::Vertices, Block::SparseIndices, Block::SparseValues, Block::Animation, Block::Stride8, Block::Stride4, Block::WeldMap];

/// A material group's primitive: its name, triangles (over glTF vertices) and texture.
type Group<'t> = (String, Vec<[u32; 3]>, Option<&'t Texture>);

/// The surface a file shows: its triangles, corner attributes, and per material group its
/// diffuse texture (empty: none).
#[derive(Debug, Clone, Copy)]
pub struct Surface<'a> {
    /// Triangles over the animated points.
    pub triangles: &'a [[u32; 3]],
    /// UVs, normals and material groups, per corner.
    pub attributes: Option<&'a CornerAttributes>,
    /// Per material group, its diffuse texture (may be shorter than the groups, or empty).
    pub textures: &'a [Option<Texture>],
    /// Morph targets carry NORMAL deltas (and the base gets recomputed `NORMAL`s if the
    /// surface has none): see [`morph_normal_deltas`].
    pub morph_normals: bool,
    /// A welded input: per input vertex, its point here (`extras.weldMap`, see
    /// [`weld_map`](super::weld_map)).
    pub weld_map: Option<&'a [u32]>,
}

impl<'a> Surface<'a> {
    /// Triangles only: no UVs, normals, groups or textures.
    pub fn plain(triangles: &'a [[u32; 3]]) -> Surface<'a> {
        Surface { triangles, attributes: None, textures: &[], morph_normals: false, weld_map: None }
    }
}

/// A glTF file under construction: one node, one mesh with one primitive per material group
/// (all sharing the vertex attributes and morph targets).
struct File {
    root: json::Root,
    blocks: [Vec<u8>; BLOCKS],
    /// For each glTF vertex, the animated point it shows, when vertices were split at seams.
    sources: Option<Vec<u32>>,
    /// Morph target names, for the mesh's `extras`.
    target_names: Vec<String>,
    /// Embedded images (one buffer view each, after the blocks), in `images` order.
    images: Vec<Vec<u8>>,
    /// The triangles over glTF vertices (split at seams), kept when morph normals are asked.
    normal_triangles: Option<Vec<[u32; 3]>>,
    /// Quantized (`KHR_mesh_quantization`) on this grid, and how the views are compressed.
    grid: Option<(Grid, Compression)>,
    /// glTF vertices and primitives, for the index codec.
    vertex_count: usize,
    /// The accessor holding the weld map, for the mesh's `extras.weldMap`.
    weld_map: Option<Index<json::Accessor>>,
}

fn f32x3_value(v: [f32; 3]) -> Value {
    value!([v[0] as f64, v[1] as f64, v[2] as f64])
}

/// `(lo, hi)` of the points (infinite, inverted, for none).
fn bounds(points: &[[f32; 3]]) -> ([f32; 3], [f32; 3]) {
    let b = Bounds::of_f32(points);
    (b.lo.map(|x| x as f32), b.hi.map(|x| x as f32))
}

fn vec3_bytes(points: impl Iterator<Item = [f32; 3]>) -> Vec<u8> {
    points.flat_map(|p| p.into_iter().flat_map(f32::to_le_bytes)).collect()
}

/// Smallest unsigned type holding `0..count`, with its size. `u8` only where asked (sparse
/// indices: triangle indices in u8 are legal but no GPU's native format); `u16` leaves 65535
/// free because it is the primitive-restart value for triangle indices.
fn index_type(count: usize, allow_u8: bool) -> (ComponentType, usize) {
    if allow_u8 && count <= 1 << 8 {
        (ComponentType::U8, 1)
    } else if count < 1 << 16 {
        (ComponentType::U16, 2)
    } else {
        (ComponentType::U32, 4)
    }
}

fn index_bytes(values: impl Iterator<Item = u32>, size: usize) -> Vec<u8> {
    let mut out = Vec::new();
    for v in values {
        match size {
            1 => out.push(v as u8),
            2 => out.extend((v as u16).to_le_bytes()),
            _ => out.extend(v.to_le_bytes()),
        }
    }
    out
}

fn accessor(view: Option<(Block, u64)>, count: usize, component: ComponentType, type_: Type) -> json::Accessor {
    accessor_in(view.map(|(b, o)| (b as u32, o)), count, component, type_)
}

/// An accessor of `count` elements at (buffer view, byte offset), or with no view (all zero,
/// or sparse values set by the caller). Shared with the vertex-cache glTF writer.
pub(crate) fn accessor_in(view: Option<(u32, u64)>, count: usize, component: ComponentType, type_: Type) -> json::Accessor {
    json::Accessor {
        buffer_view: view.map(|(b, _)| Index::new(b)),
        byte_offset: view.map(|(_, o)| USize64(o)).filter(|o| o.0 != 0),
        count: USize64(count as u64),
        component_type: Valid(GenericComponentType(component)),
        extensions: None,
        extras: None,
        type_: Valid(type_),
        min: None,
        max: None,
        name: None,
        normalized: false,
        sparse: None,
    }
}

impl File {
    /// The node, mesh and primitives of `base` (one position per animated point). With UVs or
    /// normals, vertices are split where a point's corners differ (`split_at_seams`): the first
    /// `base.len()` glTF vertices are the points in order, the seam copies follow, and
    /// `extras.seamSources` lists the point each copy shows.
    fn new(name: &str, surface: Surface, base: &[[f32; 3]], placement: Placement, grid: Option<(Grid, Compression)>) -> File {
        let Surface { triangles, attributes, textures, morph_normals, weld_map } = surface;
        let mut f = File {
            root: json::Root::default(),
            blocks: Default::default(),
            sources: None,
            target_names: Vec::new(),
            images: Vec::new(),
            normal_triangles: None,
            grid,
            vertex_count: 0,
            weld_map: None,
        };
        f.root.asset = json::Asset {
            copyright: None,
            extensions: None,
            extras: None,
            generator: Some(format!("blendsim {}", env!("CARGO_PKG_VERSION"))),
            min_version: None,
            version: "2.0".into(),
        };
        let split = attributes.filter(|a| !a.uv_corners.is_empty() || !a.normal_corners.is_empty()).map(|a| split_at_seams(triangles, base.len(), a));
        let triangles: &[[u32; 3]] = split.as_ref().map_or(triangles, |s| &s.triangles);
        if let Some(s) = &split {
            f.sources = Some(s.sources.clone());
        }
        let position = f.positions(base, None);
        let mut attributes_json = vec![(Valid(json::mesh::Semantic::Positions), position)];
        if morph_normals {
            f.normal_triangles = Some(triangles.to_vec());
        }
        let recomputed: Option<Vec<[f64; 3]>> = (morph_normals && split.as_ref().and_then(|s| s.normals.as_ref()).is_none()).then(|| {
            let points: Vec<[f64; 3]> = base.iter().map(|p| p.map(f64::from)).collect();
            vertex_normals(&points, triangles, f.sources.as_deref())
        });
        if let Some(normals) = split.as_ref().and_then(|s| s.normals.as_ref()).or(recomputed.as_ref()) {
            let unit: Vec<[f32; 3]> = normals
                .iter()
                .map(|n| {
                    let length = crate::algorithms::geometry::norm(*n);
                    if length > 0.0 {
                        n.map(|x| (x / length) as f32)
                    } else {
                        [0.0, 0.0, 1.0]
                    }
                })
                .collect();
            let count = normals.len();
            let a = if f.grid.is_some() {
                let offset = f.push(Block::Stride4, &quantize::normal_bytes(&unit));
                json::Accessor { normalized: true, ..accessor(Some((Block::Stride4, offset)), count, ComponentType::I8, Type::Vec3) }
            } else {
                let offset = f.push(Block::Vertices, &vec3_bytes(unit.into_iter()));
                accessor(Some((Block::Vertices, offset)), count, ComponentType::F32, Type::Vec3)
            };
            attributes_json.push((Valid(json::mesh::Semantic::Normals), f.root.push(a)));
        }
        if let Some(uvs) = split.as_ref().and_then(|s| s.uvs.as_ref()) {
            // glTF's v runs down the image, OBJ's up.
            let flipped: Vec<[f32; 2]> = uvs.iter().map(|&[u, v]| [u as f32, (1.0 - v) as f32]).collect();
            let a = match quantize::uv_bytes(&flipped).filter(|_| f.grid.is_some()) {
                Some(bytes) => {
                    let offset = f.push(Block::Stride4, &bytes);
                    json::Accessor { normalized: true, ..accessor(Some((Block::Stride4, offset)), uvs.len(), ComponentType::U16, Type::Vec2) }
                }
                None => {
                    let bytes: Vec<u8> = flipped.iter().flatten().flat_map(|x| x.to_le_bytes()).collect();
                    let offset = f.push(Block::Stride8, &bytes);
                    accessor(Some((Block::Stride8, offset)), uvs.len(), ComponentType::F32, Type::Vec2)
                }
            };
            attributes_json.push((Valid(json::mesh::Semantic::TexCoords(0)), f.root.push(a)));
        }
        let has_uvs = split.as_ref().is_some_and(|s| s.uvs.is_some());
        let vertex_count = split.as_ref().map_or(base.len(), |s| s.sources.len());
        f.vertex_count = vertex_count;
        let (component, size) = index_type(vertex_count, false);
        // One primitive per material group, its triangles in surface order.
        let groups: Vec<Group> = match attributes.filter(|a| !a.groups.is_empty()) {
            Some(a) => a
                .groups
                .iter()
                .enumerate()
                .map(|(g, group)| {
                    let tris = triangles.iter().zip(&a.triangle_groups).filter(|(_, &x)| x as usize == g).map(|(t, _)| *t).collect();
                    (group.clone(), tris, textures.get(g).and_then(Option::as_ref).filter(|_| has_uvs))
                })
                .filter(|(_, tris, _): &Group| !tris.is_empty())
                .collect(),
            None => vec![(name.to_string(), triangles.to_vec(), None)],
        };
        // A single index list equal to the weld map (an input with a vertex per triangle
        // corner, welded: input vertex `3t + c` is corner `c` of triangle `t`) is the map.
        let single = groups.len() == 1;
        let map_is_indices = |tris: &[[u32; 3]]| single && weld_map.is_some_and(|m| m.iter().copied().eq(tris.iter().flatten().copied()));
        let mut primitives = Vec::with_capacity(groups.len());
        // Texture index per image file name: groups sharing an image share its texture.
        let mut texture_of: Vec<(String, Index<json::Texture>)> = Vec::new();
        for (material_name, tris, texture) in groups {
            let offset = f.push(Block::Indices, &index_bytes(tris.iter().flatten().copied(), size));
            let indices = f.root.push(accessor(Some((Block::Indices, offset)), tris.len() * 3, component, Type::Scalar));
            if map_is_indices(&tris) {
                f.weld_map = Some(indices);
            }
            // glTF's default material is fully metallic, which renders black without an
            // environment map; a plain dielectric reads in every viewer.
            let mut material = json::Material { name: Some(material_name), ..Default::default() };
            material.pbr_metallic_roughness.metallic_factor = json::material::StrengthFactor(0.0);
            if let Some(texture) = texture {
                let index = match texture_of.iter().find(|(n, _)| *n == texture.file_name) {
                    Some(&(_, i)) => i,
                    None => {
                        let i = f.texture(texture);
                        texture_of.push((texture.file_name.clone(), i));
                        i
                    }
                };
                material.pbr_metallic_roughness.base_color_texture =
                    Some(json::texture::Info { index, tex_coord: 0, extensions: None, extras: None });
            }
            let material = f.root.push(material);
            primitives.push(json::mesh::Primitive {
                attributes: attributes_json.iter().cloned().collect(),
                extensions: None,
                extras: None,
                indices: Some(indices),
                material: Some(material),
                mode: Valid(json::mesh::Mode::Triangles),
                targets: None,
            });
        }
        if let (Some(map), None) = (weld_map, f.weld_map) {
            // Its own view (no target: neither vertex nor index data), u16 unless a point
            // number needs more.
            let (component, size) = index_type(base.len(), false);
            let offset = f.push(Block::WeldMap, &index_bytes(map.iter().copied(), size));
            f.weld_map = Some(f.root.push(accessor(Some((Block::WeldMap, offset)), map.len(), component, Type::Scalar)));
        }
        let mesh = f.root.push(json::Mesh { extensions: None, extras: None, name: Some(name.into()), primitives, weights: None });
        // The placement, after the grid's dequantization: `m R (step q + center)`.
        let m = placement.meters_per_unit;
        let (step, center) = f.grid.map_or((1.0, [0.0; 3]), |(g, _)| (g.step as f64, g.center.map(f64::from)));
        let s = (m * step) as f32;
        let placed = placement.place(center).map(|x| (m * x) as f32);
        let half = std::f32::consts::FRAC_1_SQRT_2;
        let node = f.root.push(json::Node {
            mesh: Some(mesh),
            name: Some(name.into()),
            rotation: placement.z_up.then_some(json::scene::UnitQuaternion([-half, 0.0, 0.0, half])),
            scale: (s != 1.0).then_some([s; 3]),
            translation: (placed != [0.0; 3]).then_some(placed),
            ..Default::default()
        });
        if f.grid.is_some() {
            f.root.extensions_used.push("KHR_mesh_quantization".into());
            f.root.extensions_required.push("KHR_mesh_quantization".into());
        }
        let scene = f.root.push(json::Scene { extensions: None, extras: None, name: Some(name.into()), nodes: vec![node] });
        f.root.scene = Some(scene);
        f
    }

    /// An embedded image and the texture showing it (default sampler: repeat, linear).
    /// The image's buffer view is its place in `images` until `finish` lays them out.
    fn texture(&mut self, texture: &Texture) -> Index<json::Texture> {
        let image = self.root.push(json::Image {
            buffer_view: Some(Index::new(self.images.len() as u32)),
            mime_type: Some(json::image::MimeType(texture.mime.into())),
            name: Some(texture.file_name.clone()),
            uri: None,
            extensions: None,
            extras: None,
        });
        self.images.push(texture.bytes.clone());
        self.root.push(json::Texture { name: None, sampler: None, source: image, extensions: None, extras: None })
    }

    /// Append `bytes` to a block at a 4-byte boundary; returns their offset in the block.
    fn push(&mut self, block: Block, bytes: &[u8]) -> u64 {
        let data = &mut self.blocks[block as usize];
        let offset = data.len() as u64;
        data.extend_from_slice(bytes);
        data.resize(data.len().next_multiple_of(4), 0);
        offset
    }

    /// A dense vec3 accessor with the min/max that POSITION accessors require: points (the base),
    /// or with `offsets` a dense target stored that way; on the grid when quantized.
    fn positions(&mut self, points: &[[f32; 3]], offsets: Option<Storage>) -> Index<json::Accessor> {
        let expanded: Vec<[f32; 3]>;
        let points = match &self.sources {
            Some(sources) if sources.len() != points.len() => {
                expanded = sources.iter().map(|&i| points[i as usize]).collect();
                &expanded[..]
            }
            _ => points,
        };
        let units: Vec<[f32; 3]>;
        let points = match self.grid.map(|(grid, _)| grid.store(points, offsets.is_some(), offsets.unwrap_or(Storage::Grid))) {
            Some(Stored::Ints(q)) => {
                let (component, size) = quantize::component(&q);
                let block = if size == 1 { Block::Stride4 } else { Block::Stride8 };
                let offset = self.push(block, &quantize::vec3_bytes(&q, size, true));
                let (lo, hi) = quantize::int_bounds(&q);
                let mut a = accessor(Some((block, offset)), q.len(), component, Type::Vec3);
                (a.min, a.max) = (Some(value!(lo)), Some(value!(hi)));
                return self.root.push(a);
            }
            // f32 in grid units (a file with per-target steps).
            Some(Stored::Floats(f)) => {
                units = f;
                &units[..]
            }
            None => points,
        };
        let offset = self.push(Block::Vertices, &vec3_bytes(points.iter().copied()));
        let (lo, hi) = bounds(points);
        let mut a = accessor(Some((Block::Vertices, offset)), points.len(), ComponentType::F32, Type::Vec3);
        (a.min, a.max) = (Some(f32x3_value(lo)), Some(f32x3_value(hi)));
        self.root.push(a)
    }

    /// A POSITION morph target: no data at all when nothing moves (glTF reads an accessor
    /// without a buffer view as zeros), sparse when that is smaller, dense otherwise.
    fn morph_target(&mut self, vertices: usize, indices: &[u32], offsets: &[[f32; 3]], storage: Storage) -> Index<json::Accessor> {
        // Seam copies move with their point: the target's entries in glTF vertex order.
        let remapped: (Vec<u32>, Vec<[f32; 3]>);
        let (vertices, indices, offsets) = match &self.sources {
            Some(sources) if sources.len() != vertices => {
                let mut at = vec![u32::MAX; vertices];
                indices.iter().enumerate().for_each(|(k, &i)| at[i as usize] = k as u32);
                remapped = sources
                    .iter()
                    .enumerate()
                    .filter(|(_, &s)| at[s as usize] != u32::MAX)
                    .map(|(j, &s)| (j as u32, offsets[at[s as usize] as usize]))
                    .unzip();
                (sources.len(), &remapped.0[..], &remapped.1[..])
            }
            _ => (vertices, indices, offsets),
        };
        let (component, size) = index_type(vertices, true);
        let units: Vec<[f32; 3]>;
        let raw = offsets;
        let (offsets, quantized) = match self.grid.map(|(g, _)| g.store(offsets, true, storage)) {
            Some(Stored::Ints(q)) => (offsets, Some(q)),
            Some(Stored::Floats(f)) => {
                units = f;
                (&units[..], None)
            }
            None => (offsets, None),
        };
        // Quantized, a target's offsets take 3 or 6 bytes instead of 12; meshopt compresses
        // dense zeros to almost nothing (and cannot encode sparse views).
        // Sparse: an index and a packed value per moved vertex; dense: a padded value per vertex.
        let (value_size, dense_size) = match &quantized {
            Some(q) if quantize::component(q).1 == 1 => (3, 4),
            Some(_) => (6, 8),
            None => (12, 12),
        };
        let meshopt = matches!(self.grid, Some((_, Compression::Meshopt)));
        let sparse_smaller = indices.len() * (size + value_size) < vertices * dense_size;
        if !indices.is_empty() && (meshopt || !sparse_smaller) {
            let mut dense = vec![[0.0f32; 3]; vertices];
            for (&i, o) in indices.iter().zip(raw) {
                dense[i as usize] = *o;
            }
            return self.positions(&dense, Some(storage));
        }
        let (value_component, value_bytes, (mut lo, mut hi)) = match &quantized {
            Some(q) => {
                let (c, s) = quantize::component(q);
                let (lo, hi) = quantize::int_bounds(q);
                (c, quantize::vec3_bytes(q, s, false), (lo.map(|x| x as f32), hi.map(|x| x as f32)))
            }
            None => (ComponentType::F32, vec3_bytes(offsets.iter().copied()), bounds(offsets)),
        };
        let mut a = accessor(None, vertices, if indices.is_empty() { ComponentType::F32 } else { value_component }, Type::Vec3);
        if indices.len() < vertices {
            // The vertices not listed are zeros.
            (lo, hi) = (lo.map(|x| x.min(0.0)), hi.map(|x| x.max(0.0)));
        }
        (a.min, a.max) = match &quantized {
            Some(_) if !indices.is_empty() => (Some(value!(lo.map(|x| x as i32))), Some(value!(hi.map(|x| x as i32)))),
            _ => (Some(f32x3_value(lo)), Some(f32x3_value(hi))),
        };
        if !indices.is_empty() {
            let index_offset = self.push(Block::SparseIndices, &index_bytes(indices.iter().copied(), size));
            let value_offset = self.push(Block::SparseValues, &value_bytes);
            a.sparse = Some(sparse::Sparse {
                count: USize64(indices.len() as u64),
                indices: sparse::Indices {
                    buffer_view: Index::new(Block::SparseIndices as u32),
                    byte_offset: USize64(index_offset),
                    component_type: Valid(IndexComponentType(component)),
                    extensions: None,
                    extras: None,
                },
                values: sparse::Values {
                    buffer_view: Index::new(Block::SparseValues as u32),
                    byte_offset: USize64(value_offset),
                    extensions: None,
                    extras: None,
                },
                extensions: None,
                extras: None,
            });
        }
        self.root.push(a)
    }

    /// A float scalar accessor in the animation block.
    fn floats(&mut self, values: &[f32], with_bounds: bool) -> Index<json::Accessor> {
        let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        let offset = self.push(Block::Animation, &bytes);
        let mut a = accessor(Some((Block::Animation, offset)), values.len(), ComponentType::F32, Type::Scalar);
        if with_bounds {
            let lo = values.iter().copied().fold(f32::INFINITY, f32::min);
            let hi = values.iter().copied().fold(f32::NEG_INFINITY, f32::max);
            (a.min, a.max) = (Some(value!([lo as f64])), Some(value!([hi as f64])));
        }
        self.root.push(a)
    }

    /// Attach named morph targets (default weights 0) and their weights animation.
    fn morph(
        &mut self,
        targets: Vec<(String, Index<json::Accessor>, Option<Index<json::Accessor>>)>,
        times: &[f32],
        output: &[f32],
        interpolation: Interpolation,
    ) {
        self.target_names = targets.iter().map(|(n, _, _)| n.clone()).collect();
        let mesh = &mut self.root.meshes[0];
        mesh.weights = Some(vec![0.0; targets.len()]);
        for primitive in &mut mesh.primitives {
            primitive.targets =
                Some(targets.iter().map(|&(_, a, normals)| json::mesh::MorphTarget { positions: Some(a), normals, tangents: None }).collect());
        }
        let input = self.floats(times, true);
        let output = self.floats(output, false);
        let name = self.root.meshes[0].name.clone();
        self.root.push(json::Animation {
            extensions: None,
            extras: None,
            name,
            channels: vec![json::animation::Channel {
                sampler: Index::new(0),
                target: json::animation::Target { extensions: None, extras: None, node: Index::new(0), path: Valid(Property::MorphTargetWeights) },
                extensions: None,
                extras: None,
            }],
            samplers: vec![json::animation::Sampler { extensions: None, extras: None, input, interpolation: Valid(interpolation), output }],
        });
    }

    /// Lay the non-empty blocks out as buffer views of one buffer, point the accessors (which
    /// hold block numbers until now) at them, and wrap JSON and binary into a GLB.
    fn finish(mut self) -> Glb {
        let mut extras = serde_json::Map::new();
        if let Some(sources) = &self.sources {
            // Points keep their index (`split_at_seams`); the copies follow them.
            let points = sources.iter().enumerate().take_while(|&(j, &s)| j as u32 == s).count();
            extras.insert("seamSources".into(), value!(&sources[points..]));
        }
        if !self.target_names.is_empty() {
            extras.insert("targetNames".into(), value!(self.target_names));
        }
        if let Some(map) = self.weld_map {
            extras.insert(super::weld_map::GLTF_KEY.into(), value!(map.value()));
        }
        if !extras.is_empty() {
            let text = serde_json::to_string(&Value::Object(extras)).expect("extras serialize");
            self.root.meshes[0].extras = Some(json::extras::RawValue::from_string(text).expect("valid JSON"));
        }
        // The BIN chunk as its pieces (the blocks, then the images), laid out by their lengths
        // alone and never concatenated (see `Glb`); `bin_len` is the bytes laid out so far.
        let (mut pieces, mut bin_len) = (Vec::new(), 0u64);
        let mut view_of = [None; BLOCKS];
        // Per view, its meshopt encoding (meshopt files), else `None`: stored as is.
        let mut encoded: Vec<Option<meshopt::Encoded>> = Vec::new();
        let meshopt = matches!(self.grid, Some((_, Compression::Meshopt)));
        let index_size = index_type(self.vertex_count, false).1;
        let primitives = self.root.meshes.first().map_or(0, |m| m.primitives.len());
        for (block, data) in KINDS.into_iter().zip(std::mem::take(&mut self.blocks)) {
            if data.is_empty() {
                continue;
            }
            let (target, stride) = match block {
                Block::Indices => (Some(ViewTarget::ElementArrayBuffer), None),
                Block::Vertices => (Some(ViewTarget::ArrayBuffer), Some(Stride(12))),
                Block::Stride8 => (Some(ViewTarget::ArrayBuffer), Some(Stride(8))),
                Block::Stride4 => (Some(ViewTarget::ArrayBuffer), Some(Stride(4))),
                _ => (None, None),
            };
            encoded.push(
                meshopt
                    .then(|| match block {
                        Block::Indices => Some(meshopt::indices(&data, index_size, self.vertex_count, primitives == 1)),
                        Block::Animation => Some(meshopt::attributes(&data, 4)),
                        _ => stride.map(|s| meshopt::attributes(&data, s.0)),
                    })
                    .flatten(),
            );
            view_of[block as usize] = Some(self.root.push(json::buffer::View {
                buffer: Index::new(0),
                byte_length: USize64(data.len() as u64),
                byte_offset: (bin_len > 0).then_some(USize64(bin_len)),
                byte_stride: stride,
                name: None,
                target: target.map(Valid),
                extensions: None,
                extras: None,
            }));
            bin_len += data.len() as u64;
            pieces.push(data);
        }
        // Images after the blocks, one view each (a view holding an image holds nothing else).
        let mut image_views = Vec::with_capacity(self.images.len());
        for mut data in std::mem::take(&mut self.images) {
            image_views.push(self.root.push(json::buffer::View {
                buffer: Index::new(0),
                byte_length: USize64(data.len() as u64),
                byte_offset: (bin_len > 0).then_some(USize64(bin_len)),
                byte_stride: None,
                name: None,
                target: None,
                extensions: None,
                extras: None,
            }));
            data.resize(data.len().next_multiple_of(4), 0);
            bin_len += data.len() as u64;
            pieces.push(data);
        }
        for image in &mut self.root.images {
            image.buffer_view = image.buffer_view.map(|i| image_views[i.value()]);
        }
        let view = |i: Index<json::buffer::View>| view_of[i.value()].expect("a used block has a view");
        for a in &mut self.root.accessors {
            a.buffer_view = a.buffer_view.map(view);
            if let Some(s) = &mut a.sparse {
                s.indices.buffer_view = view(s.indices.buffer_view);
                s.values.buffer_view = view(s.values.buffer_view);
            }
        }
        if !meshopt {
            self.root.push(json::Buffer { byte_length: USize64(bin_len), name: None, uri: None, extensions: None, extras: None });
            return Glb { json: self.root.to_vec().expect("glTF JSON serializes"), bin: pieces };
        }
        compress_views(self.root, &pieces.concat(), encoded)
    }
}

/// The meshopt form of a laid-out file: buffer 0 (the BIN chunk) holds each view's compressed
/// bytes (or, for a view the codecs do not take, its bytes as they are); buffer 1 is the
/// extension's fallback buffer, with no data: the decoded views live there, at the offsets
/// they had in `bin`. `encoded` lists the views in order (images excluded: stored as they are).
fn compress_views(mut root: json::Root, bin: &[u8], encoded: Vec<Option<meshopt::Encoded>>) -> Glb {
    const EXT: &str = "EXT_meshopt_compression";
    root.extensions_used.push(EXT.into());
    root.extensions_required.push(EXT.into());
    let mut out = Vec::new();
    let mut extensions = Vec::new();
    for (i, view) in root.buffer_views.iter_mut().enumerate() {
        let start = view.byte_offset.map_or(0, |o| o.0) as usize;
        let data = &bin[start..start + view.byte_length.0 as usize];
        match encoded.get(i).and_then(Option::as_ref) {
            Some(e) => {
                extensions.push(Some(e.extension(out.len())));
                view.buffer = Index::new(1);
                out.extend_from_slice(&e.bytes);
            }
            None => {
                extensions.push(None);
                view.byte_offset = (!out.is_empty()).then_some(USize64(out.len() as u64));
                out.extend_from_slice(data);
            }
        }
        out.resize(out.len().next_multiple_of(4), 0);
    }
    root.push(json::Buffer { byte_length: USize64(out.len() as u64), name: None, uri: None, extensions: None, extras: None });
    root.push(json::Buffer { byte_length: USize64(bin.len() as u64), name: None, uri: None, extensions: None, extras: None });
    let mut tree = serde_json::to_value(&root).expect("glTF JSON serializes");
    for (view, extension) in tree["bufferViews"].as_array_mut().expect("views").iter_mut().zip(extensions) {
        if let Some(e) = extension {
            view["extensions"] = value!({ EXT: e });
        }
    }
    tree["buffers"][1]["extensions"] = value!({ EXT: { "fallback": true } });
    Glb { json: serde_json::to_vec(&tree).expect("glTF JSON serializes"), bin: vec![out] }
}

/// The GLB container: header, JSON chunk (space padded), BIN chunk (zero padded).
fn glb(json: &[u8], bin: &[u8]) -> Vec<u8> {
    Glb { json: json.to_vec(), bin: vec![bin.to_vec()] }.to_vec()
}

/// A GLB as its parts: the JSON chunk, then the BIN chunk's pieces, written out in order
/// without being concatenated.
///
/// The JSON chunk comes first in the file and holds the BIN chunk's byte lengths and the
/// accessors' bounds, so the JSON is made once every block is laid out; the blocks are then
/// written from where they are (`write_to`, through the caller's buffer). A full-frame file is
/// so held once, as its blocks, instead of three times (blocks, a BIN buffer, the file's bytes),
/// and nothing is reserved and patched afterwards. (Holding even the blocks would need the
/// targets made twice, once for the bounds and once for the bytes.)
pub struct Glb {
    json: Vec<u8>,
    bin: Vec<Vec<u8>>,
}

impl Glb {
    fn bin_len(&self) -> usize {
        self.bin.iter().map(Vec::len).sum::<usize>().next_multiple_of(4)
    }

    /// The file's length in bytes.
    pub fn len(&self) -> usize {
        let bin = self.bin_len();
        12 + 8 + self.json.len().next_multiple_of(4) + if bin == 0 { 0 } else { 8 + bin }
    }

    /// Never: a GLB has at least its header.
    pub fn is_empty(&self) -> bool {
        false
    }

    /// Write the file: header, JSON chunk (space padded), BIN chunk (zero padded).
    pub fn write_to(&self, w: &mut dyn std::io::Write) -> std::io::Result<()> {
        let json_len = self.json.len().next_multiple_of(4);
        let bin_len = self.bin_len();
        w.write_all(b"glTF")?;
        w.write_all(&2u32.to_le_bytes())?;
        w.write_all(&(self.len() as u32).to_le_bytes())?;
        w.write_all(&(json_len as u32).to_le_bytes())?;
        w.write_all(b"JSON")?;
        w.write_all(&self.json)?;
        w.write_all(&b"   "[..json_len - self.json.len()])?;
        if bin_len > 0 {
            w.write_all(&(bin_len as u32).to_le_bytes())?;
            w.write_all(b"BIN\0")?;
            let mut written = 0;
            for piece in &self.bin {
                w.write_all(piece)?;
                written += piece.len();
            }
            w.write_all(&[0; 3][..bin_len - written])?;
        }
        Ok(())
    }

    /// The file's bytes.
    pub fn to_vec(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(self.len());
        self.write_to(&mut out).expect("writing to memory");
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::algorithms::blendshape::clip::{Target, WeightCurve};
    use crate::formats::export::sparse_is_smaller;

    const Y_UP: Placement = Placement { z_up: false, meters_per_unit: 1.0 };

    /// The JSON and BIN chunks of a GLB, checking the container's layout on the way.
    fn chunks(glb: &[u8]) -> (json::Root, Vec<u8>) {
        let u32_at = |i: usize| u32::from_le_bytes(glb[i..i + 4].try_into().unwrap()) as usize;
        assert_eq!(&glb[..4], b"glTF");
        assert_eq!(u32_at(4), 2);
        assert_eq!(u32_at(8), glb.len());
        assert_eq!(glb.len() % 4, 0);
        let json_len = u32_at(12);
        assert_eq!(json_len % 4, 0);
        assert_eq!(&glb[16..20], b"JSON");
        let root = json::Root::from_slice(&glb[20..20 + json_len]).unwrap();
        let at = 20 + json_len;
        assert_eq!(&glb[at + 4..at + 8], b"BIN\0");
        let bin_len = u32_at(at);
        assert_eq!(bin_len % 4, 0);
        assert_eq!(at + 8 + bin_len, glb.len());
        assert_eq!(root.buffers[0].byte_length.0 as usize, bin_len);
        (root, glb[at + 8..].to_vec())
    }

    fn read_f32s(root: &json::Root, bin: &[u8], a: Index<json::Accessor>) -> Vec<f32> {
        let acc = &root.accessors[a.value()];
        let view = &root.buffer_views[acc.buffer_view.unwrap().value()];
        let start = view.byte_offset.map_or(0, |o| o.0) as usize + acc.byte_offset.map_or(0, |o| o.0) as usize;
        let n = acc.count.0 as usize * if acc.type_ == Valid(Type::Vec3) { 3 } else { 1 };
        (0..n).map(|i| f32::from_le_bytes(bin[start + 4 * i..start + 4 * i + 4].try_into().unwrap())).collect()
    }

    /// 100 vertices; `one` moves vertex 7, `all` moves every vertex.
    fn clip() -> BlendShapeClip {
        let curve = |k: f32| WeightCurve {
            values: vec![k, 10.0 + k, 20.0 + k],
            in_tangents: vec![100.0 + k, 110.0 + k, 120.0 + k],
            out_tangents: vec![200.0 + k, 210.0 + k, 220.0 + k],
        };
        BlendShapeClip {
            base: (0..100).map(|i| [i as f32, 0.0, 0.0]).collect(),
            targets: vec![
                Target { name: "one".into(), indices: vec![7], offsets: vec![[0.0, -2.0, 0.5]] },
                Target { name: "all".into(), indices: (0..100).collect(), offsets: vec![[0.0, 1.0, 0.0]; 100] },
            ],
            times: vec![0.0, 0.5, 1.25],
            curves: vec![curve(0.0), curve(1.0)],
        }
    }

    #[test]
    fn glb_chunks_and_accessors_are_aligned() {
        // 3 triangles = 9 u16 indices = 18 bytes: the next block must still start aligned.
        let glb = blendshapes(&clip(), Surface::plain(&[[0, 1, 2], [2, 1, 3], [3, 4, 5]]), "box", Y_UP, Encoding::FLOAT).to_vec();
        let (root, _) = chunks(&glb);
        assert!(matches!(root.accessors[1].component_type, Valid(GenericComponentType(ComponentType::U16))));
        for v in &root.buffer_views {
            assert_eq!(v.byte_offset.map_or(0, |o| o.0) % 4, 0);
        }
        for a in &root.accessors {
            assert_eq!(a.byte_offset.map_or(0, |o| o.0) % 4, 0);
            if let Some(s) = &a.sparse {
                assert_eq!(s.indices.byte_offset.0 % 4, 0);
                assert_eq!(s.values.byte_offset.0 % 4, 0);
            }
        }
        // The JSON chunk is padded with spaces.
        let json_len = u32::from_le_bytes(glb[12..16].try_into().unwrap()) as usize;
        let json_text = std::str::from_utf8(&glb[20..20 + json_len]).unwrap();
        assert!(json_text.ends_with('}') || json_text.ends_with(' '));
        assert!(json_text.contains("\"targetNames\":[\"one\",\"all\"]"), "{json_text}");
    }

    #[test]
    fn cubicspline_output_groups_in_tangents_values_out_tangents_per_key() {
        let (root, bin) = chunks(&blendshapes(&clip(), Surface::plain(&[[0, 1, 2]]), "box", Y_UP, Encoding::FLOAT).to_vec());
        let sampler = &root.animations[0].samplers[0];
        assert_eq!(sampler.interpolation, Valid(Interpolation::CubicSpline));
        assert_eq!(read_f32s(&root, &bin, sampler.input), vec![0.0, 0.5, 1.25]);
        let out = read_f32s(&root, &bin, sampler.output);
        // 3 keys x 2 targets x (in, value, out): per key, both in-tangents, both values, both out-tangents.
        #[rustfmt::skip]
        assert_eq!(out, vec![
            100.0, 101.0, 0.0, 1.0, 200.0, 201.0,
            110.0, 111.0, 10.0, 11.0, 210.0, 211.0,
            120.0, 121.0, 20.0, 21.0, 220.0, 221.0,
        ]);
        assert_eq!(root.meshes[0].weights, Some(vec![0.0, 0.0]));
    }

    #[test]
    fn linear_output_is_the_weights_at_every_frame() {
        let c = clip();
        let frames = [0.0, 0.25, 0.5, 1.0];
        let (root, bin) = chunks(&blendshapes_sampled(&c, &frames, Surface::plain(&[[0, 1, 2]]), "box", Y_UP, Encoding::FLOAT).to_vec());
        let sampler = &root.animations[0].samplers[0];
        assert_eq!(sampler.interpolation, Valid(Interpolation::Linear));
        assert_eq!(read_f32s(&root, &bin, sampler.input), vec![0.0, 0.25, 0.5, 1.0]);
        // Per frame, the weights of both targets in target order.
        let expected: Vec<f32> = frames.iter().flat_map(|&t| c.weights_at(t)).map(|w| w as f32).collect();
        assert_eq!(read_f32s(&root, &bin, sampler.output), expected);
        assert_eq!(expected[4..6], [c.curves[0].values[1], c.curves[1].values[1]], "frame 2 is key 1: its values");
        assert_eq!(root.meshes[0].primitives[0].targets.as_ref().unwrap().len(), 2);
    }

    #[test]
    fn sparse_targets_only_when_smaller() {
        assert!(sparse_is_smaller(74, 100, 4));
        assert!(!sparse_is_smaller(75, 100, 4));
        assert!(sparse_is_smaller(85, 100, 2));
        assert!(!sparse_is_smaller(86, 100, 2));
        let (root, _) = chunks(&blendshapes(&clip(), Surface::plain(&[[0, 1, 2]]), "box", Y_UP, Encoding::FLOAT).to_vec());
        let targets = root.meshes[0].primitives[0].targets.as_ref().unwrap();
        let one = &root.accessors[targets[0].positions.unwrap().value()];
        let s = one.sparse.as_ref().expect("a target moving 1 of 100 vertices is sparse");
        assert!(one.buffer_view.is_none());
        assert_eq!(s.count.0, 1);
        assert!(matches!(s.indices.component_type, Valid(IndexComponentType(ComponentType::U8))));
        // Min/max cover the implicit zeros.
        assert_eq!((one.min.clone().unwrap(), one.max.clone().unwrap()), (value!([0.0, -2.0, 0.0]), value!([0.0, 0.0, 0.5])));
        let all = &root.accessors[targets[1].positions.unwrap().value()];
        assert!(all.sparse.is_none() && all.buffer_view.is_some(), "a target moving every vertex is dense");
    }

    #[test]
    fn full_frame_is_one_hot_linear_with_a_free_zero_target() {
        let ff = FullFrame {
            frames: vec![0, 1, 2],
            times: vec![0.0, 0.5, 1.0],
            points: vec![vec![[0.0; 3], [1.0; 3]], vec![[0.0; 3], [2.0; 3]], vec![[1.0; 3], [1.0; 3]]],
        };
        let (root, bin) =
            chunks(&full_frame(&ff, Surface::plain(&[[0, 1, 1]]), "ff", Placement { z_up: true, meters_per_unit: 0.01 }, Encoding::FLOAT).to_vec());
        let targets = root.meshes[0].primitives[0].targets.as_ref().unwrap();
        assert_eq!(targets.len(), 3);
        let frame0 = &root.accessors[targets[0].positions.unwrap().value()];
        assert!(frame0.buffer_view.is_none() && frame0.sparse.is_none(), "frame 0 is the base: an all-zero accessor");
        let sampler = &root.animations[0].samplers[0];
        assert_eq!(sampler.interpolation, Valid(Interpolation::Linear));
        assert_eq!(read_f32s(&root, &bin, sampler.output), vec![1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]);
        let node = &root.nodes[0];
        assert_eq!(node.scale, Some([0.01; 3]));
        assert!(node.rotation.is_some());
    }

    #[test]
    fn a_static_clip_has_no_animation() {
        let mut c = clip();
        c.targets.clear();
        c.curves.clear();
        let (root, _) = chunks(&blendshapes(&c, Surface::plain(&[[0, 1, 2]]), "box", Y_UP, Encoding::FLOAT).to_vec());
        assert!(root.animations.is_empty());
        assert!(root.meshes[0].weights.is_none() && root.meshes[0].primitives[0].targets.is_none());
    }
}
