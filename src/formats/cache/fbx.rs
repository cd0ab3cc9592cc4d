//! FBX animations as vertex caches: one mesh's deformed positions (skinning, blend shapes, both,
//! and its node's transforms) at every frame of one animation stack, through the `ufbx` loader.
//!
//! The file is loaded once; every [`FrameSource::read_frame`] evaluates the scene at that
//! frame's time (`ufbx::evaluate_scene` with skinning, which applies blend shapes first), so
//! memory is one evaluated scene whatever the animation's length. Positions are converted to
//! right-handed Y-up and to the caller's unit (metres when none is given), from the file's axis
//! and unit settings. Frame `i` is at `time_begin + i / fps` of the stack, `fps` the file's
//! frame rate; frames run to the stack's `time_end`. Faces are fan-triangulated in vertex
//! order (points and lines are dropped); vertices are the mesh's control points (unwelded as
//! the file stores them).

use std::collections::HashSet;
use std::path::Path;

use super::binary::require_regular;
use super::FrameSource;
use crate::algorithms::geometry::{Point, TriMesh};
use crate::support::error::{Error, Result};

/// What the caller chooses in an FBX file.
#[derive(Debug, Clone, Default)]
pub(crate) struct FbxChoice<'a> {
    /// The mesh node (default: the only mesh, or the only animated one).
    pub object: Option<&'a str>,
    /// The animation stack (default: the only one).
    pub take: Option<&'a str>,
    /// Metres per unit of the output (default 1: metres).
    pub meters_per_unit: Option<f64>,
}

/// An opened FBX animation.
pub(crate) struct OpenedFbx {
    /// Topology and the first frame's positions.
    pub mesh: TriMesh,
    /// The frames, evaluated on demand.
    pub frames: FbxFrames,
    /// The file's frame rate.
    pub fps: f64,
    /// The mesh node read.
    pub object: String,
    /// The animation stack read.
    pub take: String,
    /// The file's metres per unit (before the conversion).
    pub file_meters_per_unit: f64,
    /// Bytes of the file.
    pub bytes: u64,
}

/// The frames of one mesh of one animation stack, evaluated per read.
pub(crate) struct FbxFrames {
    scene: ufbx::SceneRoot,
    stack: usize,
    node: usize,
    vertices: usize,
    begin: f64,
    fps: f64,
    count: usize,
    /// For messages: the file and the object.
    path: std::path::PathBuf,
    object: String,
}

impl std::fmt::Debug for FbxFrames {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FbxFrames").field("object", &self.object).field("vertices", &self.vertices).field("frames", &self.count).finish()
    }
}

const FIX_EXPORT: &str = "re-export the FBX from your tool with the animation baked (Blender: bake_anim = True)";

fn names<'a>(list: impl Iterator<Item = &'a str>) -> String {
    let all: Vec<&str> = list.collect();
    let shown: Vec<String> = all.iter().take(8).map(|n| format!("\"{n}\"")).collect();
    shown.join(", ") + if all.len() > 8 { ", ..." } else { "" }
}

/// The properties that move points when animated: a node's transform (with its pivots and
/// geometric offset) and a blend channel's weight. A take that animates only others (a
/// material's, a renderer's settings) leaves the mesh where it is.
const MOVING_PROPERTIES: [&str; 14] = [
    "Lcl Translation",
    "Lcl Rotation",
    "Lcl Scaling",
    "PreRotation",
    "PostRotation",
    "RotationOffset",
    "RotationPivot",
    "ScalingOffset",
    "ScalingPivot",
    "GeometricTranslation",
    "GeometricRotation",
    "GeometricScaling",
    "RotationOrder",
    "DeformPercent",
];

/// The elements an animation stack animates in a way that moves points (by element id).
fn animated_elements(stack: &ufbx::AnimStack) -> HashSet<u32> {
    stack
        .layers
        .iter()
        .flat_map(|layer| layer.anim_props.iter())
        .filter(|p| MOVING_PROPERTIES.contains(&&*p.prop_name))
        .map(|p| p.element.element_id)
        .collect()
}

/// Whether `node`'s mesh moves in `stack`: its node or an ancestor, a bone of its skin (or the
/// bone's ancestors), or a blend channel of it is animated.
fn is_animated(node: &ufbx::Node, animated: &HashSet<u32>) -> bool {
    let moves = |mut n: Option<&ufbx::Node>| {
        while let Some(x) = n {
            if animated.contains(&x.element.element_id) {
                return true;
            }
            n = x.parent.as_deref();
        }
        false
    };
    let Some(mesh) = node.mesh.as_ref() else { return false };
    moves(Some(node))
        || mesh.skin_deformers.iter().any(|skin| skin.clusters.iter().any(|c| moves(c.bone_node.as_deref())))
        || mesh.blend_deformers.iter().any(|b| b.channels.iter().any(|c| animated.contains(&c.element.element_id)))
}

/// Open the deformed positions of a mesh of an FBX file.
pub fn open(path: &Path, choice: &FbxChoice) -> Result<OpenedFbx> {
    let bytes = require_regular(path, "FBX file")?;
    let target = choice.meters_per_unit.unwrap_or(1.0);
    let opts = ufbx::LoadOpts {
        target_axes: ufbx::CoordinateAxes::right_handed_y_up(),
        target_unit_meters: target,
        space_conversion: ufbx::SpaceConversion::TransformRoot,
        // The loader reads the file whole; other files (textures, caches) are not opened.
        load_external_files: false,
        ..Default::default()
    };
    let name = path.to_str().ok_or_else(|| Error::in_file(path, "the path is not UTF-8", "rename the file"))?;
    let scene = ufbx::load_file(name, opts).map_err(|e| {
        Error::in_file(
            path,
            // ufbx's `info` says where (e.g. which node or which byte), when it knows.
            match e.info().trim() {
                "" => format!("ufbx cannot read the FBX file: {}", e.description.trim()),
                info => format!("ufbx cannot read the FBX file: {} ({info})", e.description.trim()),
            },
            "check that the file is a complete FBX (binary or ASCII)",
        )
    })?;
    let mesh_nodes: Vec<usize> = (0..scene.nodes.len()).filter(|&i| scene.nodes[i].mesh.is_some()).collect();
    let mesh_names = || names(mesh_nodes.iter().map(|&i| &*scene.nodes[i].element.name));
    if mesh_nodes.is_empty() {
        return Err(Error::in_file(path, "has no mesh", "export the animated mesh (FBX object type Mesh)"));
    }
    // The animation stack.
    let stack = match (choice.take, scene.anim_stacks.len()) {
        (_, 0) => return Err(Error::in_file(path, "has no animation stack (take): a static file", FIX_EXPORT)),
        (Some(take), _) => (0..scene.anim_stacks.len()).find(|&i| &*scene.anim_stacks[i].element.name == take).ok_or_else(|| {
            Error::in_file(
                path,
                format!("has no take \"{take}\" (its takes: {})", names(scene.anim_stacks.iter().map(|s| &*s.element.name))),
                "set take to one of the names listed",
            )
        })?,
        (None, 1) => 0,
        (None, _) => {
            return Err(Error::in_file(
                path,
                format!("has several takes ({})", names(scene.anim_stacks.iter().map(|s| &*s.element.name))),
                "set take = \"NAME\" in [cache] to the one to read",
            ))
        }
    };
    let stack_ref = &scene.anim_stacks[stack];
    let take = stack_ref.element.name.to_string();
    let animated = animated_elements(stack_ref);
    // The mesh node.
    let node = match choice.object {
        Some(object) => *mesh_nodes.iter().find(|&&i| &*scene.nodes[i].element.name == object).ok_or_else(|| {
            Error::in_file(path, format!("has no mesh object \"{object}\" (its meshes: {})", mesh_names()), "set object to one of the names listed")
        })?,
        None if mesh_nodes.len() == 1 => mesh_nodes[0],
        None => {
            let moving: Vec<usize> = mesh_nodes.iter().copied().filter(|&i| is_animated(&scene.nodes[i], &animated)).collect();
            if moving.len() != 1 {
                return Err(Error::in_file(
                    path,
                    format!("has several meshes ({}), {} of them animated by take \"{take}\"", mesh_names(), moving.len()),
                    "set object = \"NAME\" in [cache] to the mesh to read",
                ));
            }
            moving[0]
        }
    };
    let object = scene.nodes[node].element.name.to_string();
    if !is_animated(&scene.nodes[node], &animated) {
        return Err(Error::in_file(
            path,
            format!(
                "mesh \"{object}\" does not move in take \"{take}\" (no animated bone, blend shape or transform): a static mesh, not an animation"
            ),
            "choose the animated object and take, or export the animation",
        ));
    }
    let fbx_mesh = scene.nodes[node].mesh.as_ref().expect("a mesh node");
    let vertices = fbx_mesh.vertices.len();
    let mut triangles = Vec::with_capacity(fbx_mesh.num_triangles);
    let all_corners: &[u32] = &fbx_mesh.vertex_indices;
    for face in fbx_mesh.faces.iter() {
        let corners = &all_corners[face.index_begin as usize..(face.index_begin + face.num_indices) as usize];
        for k in 2..corners.len() {
            triangles.push([corners[0], corners[k - 1], corners[k]]);
        }
    }
    if triangles.is_empty() || vertices == 0 {
        return Err(Error::in_file(path, format!("mesh \"{object}\" has no faces"), "export the mesh with its polygons"));
    }
    let fps = scene.settings.frames_per_second;
    let span = stack_ref.time_end - stack_ref.time_begin;
    if !(fps.is_finite() && fps > 0.0 && span.is_finite() && span >= 0.0) {
        return Err(Error::in_file(path, format!("take \"{take}\" has frame rate {fps} and length {span} s"), FIX_EXPORT));
    }
    let count = (span * fps + 1e-6).floor() as usize + 1;
    if count > super::MAX_FRAMES {
        return Err(Error::in_file(path, format!("take \"{take}\" has {count} frames, more than {}", super::MAX_FRAMES), "split the animation"));
    }
    let begin = stack_ref.time_begin;
    let file_meters_per_unit = scene.settings.original_unit_meters;
    let mut frames = FbxFrames { scene, stack, node, vertices, begin, fps, count, path: path.to_path_buf(), object: object.clone() };
    let mut positions = vec![[0.0; 3]; vertices];
    frames.read_frame(0, &mut positions)?;
    Ok(OpenedFbx { mesh: TriMesh { positions, triangles, attributes: None }, frames, fps, object, take, file_meters_per_unit, bytes })
}

impl FrameSource for FbxFrames {
    fn vertex_count(&self) -> usize {
        self.vertices
    }

    fn frame_count(&self) -> usize {
        self.count
    }

    fn time(&self, frame: usize) -> f64 {
        self.begin + frame as f64 / self.fps
    }

    fn read_frame(&mut self, frame: usize, out: &mut [Point]) -> Result<()> {
        let fail = |problem: String| Error::in_file(&self.path, problem, FIX_EXPORT);
        let stack = &self.scene.anim_stacks[self.stack];
        let opts = ufbx::EvaluateOpts { evaluate_skinning: true, ..Default::default() };
        let evaluated = ufbx::evaluate_scene(&self.scene, &stack.anim, self.time(frame), opts)
            .map_err(|e| fail(format!("ufbx cannot evaluate mesh \"{}\" at frame {frame}: {}", self.object, e.description.trim())))?;
        let node = &evaluated.nodes[self.node];
        let mesh = node.mesh.as_ref().expect("the evaluated scene has the same nodes");
        let skinned = &mesh.skinned_position;
        let to_world = (mesh.skinned_is_local || !skinned.exists).then_some(&node.geometry_to_world);
        let source = if skinned.exists { skinned } else { &mesh.vertex_position };
        let point = |p: ufbx::Vec3| {
            let p = to_world.map_or(p, |m| ufbx::transform_position(m, p));
            [p.x, p.y, p.z]
        };
        if source.values.len() == out.len() {
            // One value per vertex (loose vertices included).
            for (o, &p) in out.iter_mut().zip(source.values.iter()) {
                *o = point(p);
            }
        } else {
            // Values per index: every index of a vertex carries its point.
            out.fill([f64::NAN; 3]);
            for (index, &v) in mesh.vertex_indices.iter().enumerate() {
                out[v as usize] = point(source[index]);
            }
        }
        if let Some(v) = out.iter().position(|p| !p.iter().all(|x| x.is_finite())) {
            return Err(fail(format!("mesh \"{}\" has a non-finite position at frame {frame} (vertex {v})", self.object)));
        }
        Ok(())
    }
}
