//! glTF 2.0 clips (`.glb`, `.gltf`) as vertex caches: one mesh evaluated under one animation
//! at the cache rate, one frame per call.
//!
//! What is evaluated (glTF 2.0 §3.7, §3.11 and Appendix C):
//! - the mesh: the one mesh node of the scene, or, when there are several, the one the
//!   animation moves (a weights channel, a TRS channel on it or an ancestor, or on a joint of
//!   its skin); all its TRIANGLES primitives, concatenated in order, vertex order kept;
//! - morph targets on POSITION with the node's (or mesh's) default weights, animated by a
//!   `weights` channel: STEP, LINEAR or CUBICSPLINE (tangents in units per second, scaled by
//!   the key interval);
//! - node TRS animation (rotations slerped, CUBICSPLINE rotations normalized) through the
//!   node hierarchy;
//! - skinning: joint matrix = joint's global transform x inverse bind matrix, each vertex
//!   blended by JOINTS_n / WEIGHTS_n (weights normalized to sum 1, as three.js does; a vertex
//!   with no weight follows joint 0). As the spec says, the skinned mesh node's own transform
//!   is ignored.
//!
//! Positions are in the scene's world space (a non-skinned mesh is moved by its node's
//! global transform). Frames are sampled from the animation's first key to its last, at the
//! caller's fps or, when none is given, at the rate of evenly spaced keys; a frame time that
//! lands on a key within f32 rounding takes the key's exact time.
//!
//! Only morph targets with a non-zero weight are read, from disk, per frame: a clip with one
//! target per frame costs one or two targets of memory per frame.

mod data;
#[doc(hidden)]
pub mod fixtures;
pub mod sampler;
#[cfg(test)]
mod tests;
pub mod transform;
mod write;

pub use write::write;

use std::path::{Path, PathBuf};

use gltf::animation::{Interpolation as GltfInterpolation, Property};
use gltf::mesh::{Mode, Semantic};
use gltf::scene::Transform;
use gltf::Document;

use super::{rate_of, FrameSource, MAX_FRAMES};
use crate::algorithms::geometry::{Point, TriMesh};
use crate::support::error::{Error, Result};
use data::{BufferStore, Layout};
use sampler::{Curve, Interpolation};
use transform::{apply, mul, Mat4, Trs, IDENTITY};

const FIX_DAMAGED: &str = "the glTF file is damaged or was written by a faulty exporter; re-export it (and check it with the Khronos glTF validator)";

/// An opened clip: the first frame's mesh, the frames, and the rate.
#[derive(Debug)]
pub(crate) struct OpenedClip {
    pub mesh: TriMesh,
    pub frames: GltfFrames,
    pub fps: f64,
    /// The rate came from evenly spaced keys (the caller gave none).
    pub fps_from_keys: bool,
    /// Bytes of the file and its external buffers.
    pub bytes: u64,
}

/// A node's rest transform.
#[derive(Debug, Clone, Copy)]
enum Local {
    Trs(Trs),
    /// A `matrix` node, which glTF forbids animating.
    Matrix(Mat4),
}

#[derive(Debug)]
enum Target {
    Translation,
    Rotation,
    Scale,
    Weights,
}

#[derive(Debug)]
struct Channel {
    node: usize,
    target: Target,
    curve: Curve,
}

#[derive(Debug)]
struct Primitive {
    /// First vertex in the concatenated mesh, and vertex count.
    offset: usize,
    count: usize,
    /// POSITION displacement per morph target (`None`: that target does not move positions).
    targets: Vec<Option<Layout>>,
}

#[derive(Debug)]
struct Skin {
    joints: Vec<usize>,
    inverse_bind: Vec<Mat4>,
    /// `influences` (joint slot, weight) pairs per vertex, weights summing to 1.
    influences: usize,
    joint: Vec<u32>,
    weight: Vec<f64>,
}

/// The frames of a glTF clip, evaluated on demand.
#[derive(Debug)]
pub(crate) struct GltfFrames {
    path: PathBuf,
    store: BufferStore,
    rest: Vec<Local>,
    /// Nodes in an order that visits parents first, with their parents.
    order: Vec<usize>,
    parent: Vec<Option<usize>>,
    channels: Vec<Channel>,
    mesh_node: usize,
    base: Vec<Point>,
    primitives: Vec<Primitive>,
    default_weights: Vec<f64>,
    skin: Option<Skin>,
    /// Every key time of the animation, sorted: frame times snap to them.
    keys: Vec<f64>,
    start: f64,
    fps: f64,
    count: usize,
    // Scratch, reused between frames.
    floats: Vec<f32>,
    bytes: Vec<u8>,
}

fn damaged(path: &Path, problem: String) -> Error {
    Error::in_file(path, problem, FIX_DAMAGED)
}

fn node_name(node: &gltf::Node) -> String {
    match node.name() {
        Some(n) => format!("\"{n}\" (node {})", node.index()),
        None => format!("node {}", node.index()),
    }
}

/// Open `path`, evaluating `animation` (or the only one) at `fps` (or the keys' rate).
pub fn open(path: &Path, animation: Option<&str>, fps: Option<f64>) -> Result<OpenedClip> {
    let data::Loaded { document, mut store } = data::load(path)?;
    let anim = choose_animation(path, &document, animation)?;
    let anim_name = anim.name().map_or_else(|| format!("animation {}", anim.index()), |n| format!("animation \"{n}\""));

    let (parent, order) = hierarchy(path, &document)?;
    let rest: Vec<Local> = document
        .nodes()
        .map(|n| match n.transform() {
            Transform::Matrix { matrix } => Local::Matrix(std::array::from_fn(|i| matrix[i / 4][i % 4] as f64)),
            Transform::Decomposed { translation, rotation, scale } => {
                Local::Trs(Trs { translation: translation.map(f64::from), rotation: rotation.map(f64::from), scale: scale.map(f64::from) })
            }
        })
        .collect();

    let mut channels = Vec::new();
    let (mut floats, mut bytes) = (Vec::new(), Vec::new());
    for channel in anim.channels() {
        let node = channel.target().node();
        let what = format!("{anim_name}, channel {} (on {})", channel.index(), node_name(&node));
        let (target, width) = match channel.target().property() {
            Property::Translation => (Target::Translation, 3),
            Property::Rotation => (Target::Rotation, 4),
            Property::Scale => (Target::Scale, 3),
            Property::MorphTargetWeights => {
                let targets = node.mesh().and_then(|m| m.primitives().next()).map_or(0, |p| p.morph_targets().len());
                if targets == 0 {
                    return Err(damaged(path, format!("{what} animates morph weights of a node without morph targets")));
                }
                (Target::Weights, targets)
            }
        };
        if !matches!(target, Target::Weights) && matches!(rest[node.index()], Local::Matrix(_)) {
            return Err(damaged(path, format!("{what} animates a node that has a matrix (glTF allows animating TRS nodes only)")));
        }
        let sampler = channel.sampler();
        let interpolation = match sampler.interpolation() {
            GltfInterpolation::Step => Interpolation::Step,
            GltfInterpolation::Linear => Interpolation::Linear,
            GltfInterpolation::CubicSpline => Interpolation::CubicSpline,
        };
        let input = store.layout(&sampler.input(), &format!("the key times of {what}"))?;
        store.require_data(&input, &format!("the key times of {what}"))?;
        let output = store.layout(&sampler.output(), &format!("the values of {what}"))?;
        // Checked before reading: an output without a view (sparse) is bounded only by this.
        let (groups, per_key) =
            (if interpolation == Interpolation::CubicSpline { 3 } else { 1 }, if matches!(target, Target::Weights) { width } else { 1 });
        let components = if matches!(target, Target::Weights) { 1 } else { width };
        if input.components != 1 || output.components != components || output.count as u128 != input.count as u128 * groups * per_key as u128 {
            return Err(damaged(
                path,
                format!(
                    "{what}, sampler {}: {} outputs of {} components for {} keys, expected {} of {components}",
                    sampler.index(),
                    output.count,
                    output.components,
                    input.count,
                    input.count as u128 * groups * per_key as u128
                ),
            ));
        }
        store.read_floats(&input, &mut floats, &mut bytes)?;
        let times = floats.clone();
        store.read_floats(&output, &mut floats, &mut bytes)?;
        let values = floats.clone();
        let curve = Curve::new(times, values, width, interpolation, matches!(target, Target::Rotation))
            .map_err(|problem| damaged(path, format!("{what}, sampler {}: {problem}", sampler.index())))?;
        channels.push(Channel { node: node.index(), target, curve });
    }
    if channels.is_empty() {
        return Err(damaged(path, format!("{anim_name} has no channels")));
    }

    let node = choose_mesh_node(path, &document, &parent, &channels)?;
    let mesh_node = node.index();
    let mesh = node.mesh().expect("a mesh node");
    let mut base = Vec::new();
    let mut triangles = Vec::new();
    let mut primitives = Vec::new();
    let mut joint_sets: Vec<(usize, Vec<u32>, Vec<f32>, usize)> = Vec::new();
    let target_count = mesh.primitives().next().map_or(0, |p| p.morph_targets().len());
    for primitive in mesh.primitives() {
        let what =
            format!("primitive {} of mesh {}", primitive.index(), mesh.name().map_or_else(|| mesh.index().to_string(), |n| format!("\"{n}\"")));
        if primitive.mode() != Mode::Triangles {
            return Err(Error::in_file(path, format!("{what} draws {:?}, not triangles", primitive.mode()), "export the mesh as triangles"));
        }
        let position = primitive.get(&Semantic::Positions).ok_or_else(|| damaged(path, format!("{what} has no POSITION")))?;
        let layout = store.layout(&position, &format!("POSITION of {what}"))?;
        store.require_data(&layout, &format!("POSITION of {what}"))?;
        if layout.components != 3 {
            return Err(damaged(path, format!("POSITION of {what} is not VEC3")));
        }
        let (offset, count) = (base.len(), layout.count);
        store.read_floats(&layout, &mut floats, &mut bytes)?;
        base.extend(floats.chunks_exact(3).map(|p| [p[0] as f64, p[1] as f64, p[2] as f64]));
        match primitive.indices() {
            Some(indices) => {
                let layout = store.layout(&indices, &format!("the indices of {what}"))?;
                store.require_data(&layout, &format!("the indices of {what}"))?;
                let indices = store.read_uints(&layout, &format!("the indices of {what}"))?;
                if indices.len() % 3 != 0 || layout.components != 1 {
                    return Err(damaged(path, format!("{what} has {} indices, not a whole number of triangles", indices.len())));
                }
                if let Some(i) = indices.iter().position(|&i| i as usize >= count) {
                    return Err(damaged(path, format!("index {i} of {what} is {}, but it has {count} vertices", indices[i])));
                }
                triangles.extend(indices.chunks_exact(3).map(|t| [t[0], t[1], t[2]].map(|i| (offset + i as usize) as u32)));
            }
            None if count % 3 == 0 => triangles.extend((0..count / 3).map(|t| [0, 1, 2].map(|k| (offset + 3 * t + k) as u32))),
            None => return Err(damaged(path, format!("{what} has no indices and {count} vertices, not a whole number of triangles"))),
        }
        if primitive.morph_targets().len() != target_count {
            return Err(damaged(
                path,
                format!("{what} has {} morph targets, but the mesh's first primitive has {target_count}", primitive.morph_targets().len()),
            ));
        }
        let mut targets = Vec::new();
        for (k, target) in primitive.morph_targets().enumerate() {
            targets.push(match target.positions() {
                Some(a) => {
                    let layout = store.layout(&a, &format!("morph target {k} of {what}"))?;
                    if layout.components != 3 || layout.count != count {
                        return Err(damaged(
                            path,
                            format!(
                                "morph target {k} of {what} has {} elements of {} components; POSITION has {count} of 3",
                                layout.count, layout.components
                            ),
                        ));
                    }
                    Some(layout)
                }
                None => None,
            });
        }
        primitives.push(Primitive { offset, count, targets });
        if node.skin().is_some() {
            let mut set = 0;
            let (mut joints, mut weights) = (Vec::new(), Vec::new());
            while let Some(j) = primitive.get(&Semantic::Joints(set)) {
                let w =
                    primitive.get(&Semantic::Weights(set)).ok_or_else(|| damaged(path, format!("{what} has JOINTS_{set} but no WEIGHTS_{set}")))?;
                let (jl, wl) = (store.layout(&j, &format!("JOINTS_{set} of {what}"))?, store.layout(&w, &format!("WEIGHTS_{set} of {what}"))?);
                if jl.components != 4 || wl.components != 4 || jl.count != count || wl.count != count {
                    return Err(damaged(path, format!("JOINTS_{set} / WEIGHTS_{set} of {what} are not VEC4 with one element per vertex")));
                }
                joints.push(store.read_uints(&jl, &format!("JOINTS_{set} of {what}"))?);
                store.read_floats(&wl, &mut floats, &mut bytes)?;
                weights.push(floats.clone());
                set += 1;
            }
            if set == 0 {
                return Err(damaged(path, format!("{what} is skinned but has no JOINTS_0 / WEIGHTS_0")));
            }
            // Interleave the sets per vertex: 4 * sets influences.
            let n = 4 * set as usize;
            let (mut j, mut w) = (vec![0u32; n * count], vec![0f32; n * count]);
            for v in 0..count {
                for s in 0..set as usize {
                    j[v * n + 4 * s..v * n + 4 * s + 4].copy_from_slice(&joints[s][4 * v..4 * v + 4]);
                    w[v * n + 4 * s..v * n + 4 * s + 4].copy_from_slice(&weights[s][4 * v..4 * v + 4]);
                }
            }
            joint_sets.push((count, j, w, n));
        }
    }
    if triangles.is_empty() {
        return Err(Error::in_file(path, format!("the mesh of {} has no triangles", node_name(&node)), "export the mesh with its faces"));
    }

    let default_weights: Vec<f64> = match node.weights().or_else(|| mesh.weights()) {
        Some(w) if w.len() == target_count => w.iter().map(|&x| x as f64).collect(),
        Some(w) => return Err(damaged(path, format!("{} has {} default morph weights for {target_count} targets", node_name(&node), w.len()))),
        None => vec![0.0; target_count],
    };
    let skin = match node.skin() {
        None => None,
        Some(skin) => Some(read_skin(path, &mut store, &skin, joint_sets)?),
    };

    let mut keys: Vec<f64> = channels.iter().flat_map(|c| c.curve.times().iter().map(|&t| t as f64)).collect();
    keys.sort_by(f64::total_cmp);
    keys.dedup();
    let (start, end) = (keys[0], keys[keys.len() - 1]);
    let (fps, fps_from_keys) = match fps {
        Some(fps) => (fps, false),
        None => {
            let rate = keys_rate(&keys).ok_or_else(|| {
                let problem = match keys.len() {
                    1 => format!("{anim_name} has a single key time, so the cache's frame rate is unknown"),
                    n => format!("the {n} key times of {anim_name} are not evenly spaced, so the cache's frame rate is unknown"),
                };
                Error::in_file(path, problem, "give the cache's fps (the rate to sample the animation at)")
            })?;
            (rate, true)
        }
    };
    let span = (end - start) * fps;
    let whole = span.round();
    let frames = if (span - whole).abs() <= 1e-3 { whole } else { span.floor() };
    if frames + 1.0 > MAX_FRAMES as f64 {
        return Err(Error::in_file(
            path,
            format!("{anim_name} lasts {} s: {} frames at {fps} fps is more than {MAX_FRAMES}", end - start, frames + 1.0),
            "give a lower fps or a shorter animation",
        ));
    }

    let mut clip = GltfFrames {
        path: path.to_path_buf(),
        store,
        rest,
        order,
        parent,
        channels,
        mesh_node,
        base,
        primitives,
        default_weights,
        skin,
        keys,
        start,
        fps,
        count: frames as usize + 1,
        floats,
        bytes,
    };
    let mut first = vec![[0.0; 3]; clip.base.len()];
    clip.read_frame(0, &mut first)?;
    let bytes = clip.store.bytes;
    Ok(OpenedClip { mesh: TriMesh { positions: first, triangles, attributes: None }, frames: clip, fps, fps_from_keys, bytes })
}

/// The rate of evenly spaced keys (within 1e-3 of the mean interval: f32 times jitter).
fn keys_rate(keys: &[f64]) -> Option<f64> {
    let fps = rate_of(keys)?;
    let mean = (keys[keys.len() - 1] - keys[0]) / (keys.len() - 1) as f64;
    keys.windows(2).all(|w| ((w[1] - w[0]) - mean).abs() <= 1e-3 * mean).then_some(fps)
}

fn choose_animation<'a>(path: &Path, document: &'a Document, name: Option<&str>) -> Result<gltf::Animation<'a>> {
    let names: Vec<String> =
        document.animations().map(|a| a.name().map_or_else(|| format!("#{} (unnamed)", a.index()), |n| format!("\"{n}\""))).collect();
    let list = if names.is_empty() { "none".to_string() } else { names.join(", ") };
    match name {
        Some(name) => document.animations().find(|a| a.name() == Some(name)).ok_or_else(|| {
            Error::in_file(
                path,
                format!("has no animation named \"{name}\" (its animations: {list})"),
                "set animation to one of the names the file has",
            )
        }),
        None => {
            let mut all = document.animations();
            match (all.next(), all.next()) {
                (Some(only), None) => Ok(only),
                (None, _) => Err(Error::in_file(path, "has no animation", "export the clip with its animation (morph weights or skinning)")),
                _ => Err(Error::in_file(path, format!("has several animations ({list})"), "choose one with animation = \"NAME\"")),
            }
        }
    }
}

/// Each node's parent, and an order visiting parents first; a node with two parents or a
/// cycle is refused (glTF nodes form a forest).
fn hierarchy(path: &Path, document: &Document) -> Result<(Vec<Option<usize>>, Vec<usize>)> {
    let count = document.nodes().len();
    let mut parent = vec![None; count];
    for node in document.nodes() {
        for child in node.children() {
            if parent[child.index()].replace(node.index()).is_some() {
                return Err(damaged(path, format!("node {} has two parents; glTF nodes must form a tree", child.index())));
            }
        }
    }
    let mut order = Vec::with_capacity(count);
    let mut stack: Vec<usize> = (0..count).filter(|&n| parent[n].is_none()).collect();
    let nodes: Vec<gltf::Node> = document.nodes().collect();
    while let Some(n) = stack.pop() {
        order.push(n);
        stack.extend(nodes[n].children().map(|c| c.index()));
    }
    if order.len() != count {
        return Err(damaged(path, "its node hierarchy has a cycle; glTF nodes must form a tree".into()));
    }
    Ok((parent, order))
}

/// The mesh node to read: the scene's only one, or the only one the animation moves.
fn choose_mesh_node<'a>(path: &Path, document: &'a Document, parent: &[Option<usize>], channels: &[Channel]) -> Result<gltf::Node<'a>> {
    let scene = document.default_scene().or_else(|| document.scenes().next());
    let in_scene = |mut n: usize| -> bool {
        let Some(scene) = &scene else { return true };
        while let Some(p) = parent[n] {
            n = p;
        }
        scene.nodes().any(|r| r.index() == n)
    };
    let moved = |mut n: usize| -> bool {
        loop {
            if channels.iter().any(|c| c.node == n && !matches!(c.target, Target::Weights)) {
                return true;
            }
            match parent[n] {
                Some(p) => n = p,
                None => return false,
            }
        }
    };
    let candidates: Vec<gltf::Node> = document.nodes().filter(|n| n.mesh().is_some() && in_scene(n.index())).collect();
    let animated: Vec<&gltf::Node> = candidates
        .iter()
        .filter(|n| {
            channels.iter().any(|c| c.node == n.index() && matches!(c.target, Target::Weights))
                || moved(n.index())
                || n.skin().is_some_and(|s| s.joints().any(|j| moved(j.index())))
        })
        .collect();
    match (candidates.len(), animated.len()) {
        (0, _) => Err(Error::in_file(path, "has no mesh in its scene", "export the animated mesh")),
        (1, _) => Ok(candidates[0].clone()),
        (_, 1) => Ok(animated[0].clone()),
        _ => {
            let names: Vec<String> =
                (if animated.is_empty() { candidates.iter().collect() } else { animated }).iter().map(|n| node_name(n)).collect();
            Err(Error::in_file(
                path,
                format!("has several meshes the animation could be about: {}", names.join(", ")),
                "export only the animated mesh (one mesh per cache file)",
            ))
        }
    }
}

fn read_skin(path: &Path, store: &mut BufferStore, skin: &gltf::Skin, sets: Vec<(usize, Vec<u32>, Vec<f32>, usize)>) -> Result<Skin> {
    let joints: Vec<usize> = skin.joints().map(|j| j.index()).collect();
    let what = format!("skin {}", skin.index());
    let inverse_bind = match skin.inverse_bind_matrices() {
        None => vec![IDENTITY; joints.len()],
        Some(a) => {
            let layout = store.layout(&a, &format!("the inverse bind matrices of {what}"))?;
            store.require_data(&layout, &format!("the inverse bind matrices of {what}"))?;
            if layout.components != 16 || layout.count < joints.len() {
                return Err(damaged(
                    path,
                    format!(
                        "the inverse bind matrices of {what} are {} elements of {} components, for {} joints (need MAT4 each)",
                        layout.count,
                        layout.components,
                        joints.len()
                    ),
                ));
            }
            let (mut floats, mut bytes) = (Vec::new(), Vec::new());
            store.read_floats(&layout, &mut floats, &mut bytes)?;
            floats.chunks_exact(16).take(joints.len()).map(|m| std::array::from_fn(|i| m[i] as f64)).collect()
        }
    };
    let influences = sets.iter().map(|s| s.3).max().unwrap_or(4);
    let vertices: usize = sets.iter().map(|s| s.0).sum();
    let (mut joint, mut weight) = (Vec::with_capacity(vertices * influences), Vec::with_capacity(vertices * influences));
    for (count, j, w, n) in sets {
        for v in 0..count {
            let (js, ws) = (&j[v * n..(v + 1) * n], &w[v * n..(v + 1) * n]);
            if let Some(k) = ws.iter().position(|&x| !(x.is_finite() && x >= 0.0)) {
                return Err(damaged(
                    path,
                    format!("vertex {} of the skinned mesh has weight {} (weights must be finite and non-negative)", joint.len() / influences, ws[k]),
                ));
            }
            if let Some(k) = js.iter().position(|&x| x as usize >= joints.len()) {
                return Err(damaged(
                    path,
                    format!("vertex {} of the skinned mesh uses joint {}, but {what} has {} joints", joint.len() / influences, js[k], joints.len()),
                ));
            }
            let sum: f64 = ws.iter().map(|&x| x as f64).sum();
            joint.extend_from_slice(js);
            joint.extend(std::iter::repeat_n(0, influences - n));
            if sum > 0.0 {
                weight.extend(ws.iter().map(|&x| x as f64 / sum));
                weight.extend(std::iter::repeat_n(0.0, influences - n));
            } else {
                // As three.js: a vertex without weights follows its first joint.
                weight.push(1.0);
                weight.extend(std::iter::repeat_n(0.0, influences - 1));
            }
        }
    }
    Ok(Skin { joints, inverse_bind, influences, joint, weight })
}

impl GltfFrames {
    /// Positions at time `t` (seconds) into `out`.
    pub fn pose(&mut self, t: f64, out: &mut [Point]) -> Result<()> {
        let mut locals = self.rest.clone();
        let mut weights = self.default_weights.clone();
        let mut value = [0.0; 4];
        let mut many = Vec::new();
        for c in &self.channels {
            let local = match &mut locals[c.node] {
                Local::Trs(trs) => trs,
                Local::Matrix(_) => continue,
            };
            match c.target {
                Target::Translation => {
                    c.curve.sample(t, &mut value[..3]);
                    local.translation = [value[0], value[1], value[2]];
                }
                Target::Rotation => {
                    c.curve.sample(t, &mut value);
                    local.rotation = value;
                }
                Target::Scale => {
                    c.curve.sample(t, &mut value[..3]);
                    local.scale = [value[0], value[1], value[2]];
                }
                Target::Weights if c.node == self.mesh_node => {
                    many.resize(weights.len(), 0.0);
                    c.curve.sample(t, &mut many);
                    weights.copy_from_slice(&many);
                }
                Target::Weights => {}
            }
        }
        let mut global = vec![IDENTITY; locals.len()];
        for &n in &self.order {
            let m = match &locals[n] {
                Local::Trs(trs) => trs.matrix(),
                Local::Matrix(m) => *m,
            };
            global[n] = match self.parent[n] {
                Some(p) => mul(&global[p], &m),
                None => m,
            };
        }

        out.copy_from_slice(&self.base);
        for (k, &w) in weights.iter().enumerate() {
            if w == 0.0 {
                continue;
            }
            for p in &self.primitives {
                let Some(layout) = &p.targets[k] else { continue };
                self.store.read_floats(layout, &mut self.floats, &mut self.bytes)?;
                for (o, d) in out[p.offset..p.offset + p.count].iter_mut().zip(self.floats.chunks_exact(3)) {
                    for i in 0..3 {
                        o[i] += w * d[i] as f64;
                    }
                }
            }
        }
        match &self.skin {
            Some(skin) => {
                let joint_matrices: Vec<Mat4> = skin.joints.iter().zip(&skin.inverse_bind).map(|(&j, ibm)| mul(&global[j], ibm)).collect();
                let n = skin.influences;
                for (v, p) in out.iter_mut().enumerate() {
                    let mut q = [0.0; 3];
                    for k in v * n..(v + 1) * n {
                        let w = skin.weight[k];
                        if w != 0.0 {
                            let moved = apply(&joint_matrices[skin.joint[k] as usize], *p);
                            (0..3).for_each(|i| q[i] += w * moved[i]);
                        }
                    }
                    *p = q;
                }
            }
            None => {
                let m = global[self.mesh_node];
                out.iter_mut().for_each(|p| *p = apply(&m, *p));
            }
        }
        if let Some(v) = out.iter().position(|p| p.iter().any(|x| !x.is_finite())) {
            return Err(damaged(&self.path, format!("at {t} s vertex {v} evaluates to a non-finite position (non-finite data in the file)")));
        }
        Ok(())
    }
}

impl FrameSource for GltfFrames {
    fn vertex_count(&self) -> usize {
        self.base.len()
    }

    fn frame_count(&self) -> usize {
        self.count
    }

    fn time(&self, frame: usize) -> f64 {
        let t = self.start + frame as f64 / self.fps;
        // A key within f32 rounding of the frame time is the frame the file meant.
        let i = self.keys.partition_point(|&k| k < t);
        let near = [i.checked_sub(1), Some(i)]
            .into_iter()
            .flatten()
            .filter_map(|j| self.keys.get(j))
            .min_by(|a, b| (*a - t).abs().total_cmp(&(*b - t).abs()));
        match near {
            Some(&k) if (k - t).abs() <= (2.0 * f32::EPSILON as f64 * k.abs()).min(0.25 / self.fps) => k,
            _ => t,
        }
    }

    fn read_frame(&mut self, frame: usize, out: &mut [Point]) -> Result<()> {
        assert!(frame < self.count && out.len() == self.base.len(), "frame and buffer match the cache");
        self.pose(self.time(frame), out)
    }
}
