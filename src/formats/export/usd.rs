//! The USD layout of our animations as a [`Layer`] (written by `usda` as text and by `usdc`
//! as a binary crate). Layout in `formats/usd.md`.

pub use super::layer::prim_name;
use super::layer::{Attribute, Layer, Prim, Value};
use super::usd_attributes as attrs;
use crate::algorithms::blendshape::clip::BlendShapeClip;
use crate::algorithms::blendshape::fullframe::FullFrame;
use crate::algorithms::geometry::attributes::CornerAttributes;
use crate::algorithms::geometry::Bounds;
use crate::algorithms::spacetime::trajectory::frames_between;

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

/// UsdSkel blendshape animation: weights sampled at every frame of the clip's key range.
///
/// A clip without targets (a static animation) is written as a plain mesh under an Xform:
/// a SkelAnimation with no blend shapes would only add noise for importers.
///
/// `attributes` (UVs, normals, material groups of the surface) add `primvars:st`, `normals`,
/// `GeomSubset`s and their placeholder materials; without them the layer is as before.
pub fn blendshapes(clip: &BlendShapeClip, triangles: &[[u32; 3]], attributes: Option<&CornerAttributes>, settings: &UsdSettings) -> Layer {
    let (start, end) = (clip.times[0], *clip.times.last().expect("a clip has keys"));
    let frames = frames_between(start, end, settings.fps);
    let metadata = metadata(settings, frames[0].0, frames[frames.len() - 1].0);
    let root = &settings.name;
    let mut mesh = Prim::new("Mesh", "Mesh");
    mesh.attribute(Attribute::new("extent", "float3[]", Value::Vec3fs(extent(&clip.base).to_vec())));
    push_topology(&mut mesh, triangles);
    if let Some(a) = attributes {
        attrs::push_properties(&mut mesh, triangles, clip.vertex_count(), a);
    }
    mesh.attribute(Attribute::new("points", "point3f[]", Value::Vec3fs(clip.base.clone())));
    if clip.targets.is_empty() {
        mesh.attribute(Attribute::uniform("subdivisionScheme", "token", Value::Token("none".into())));
        return Layer { metadata, prims: vec![plain_root(mesh, attributes, root)] };
    }

    // The SkelRoot's extent bounds the whole animation, so culling never clips a deformed pose.
    let weights: Vec<Vec<f64>> = frames.iter().map(|&(_, t)| clip.weights_at(t)).collect();
    let mut bounds = Bounds::of_f32(&clip.base);
    for w in &weights {
        let posed: Vec<[f32; 3]> = clip.points_with_weights(w).iter().map(|p| p.map(|x| x as f32)).collect();
        bounds = bounds.union(Bounds::of_f32(&posed));
    }
    let names: Vec<String> = clip.targets.iter().map(|t| t.name.clone()).collect();

    let mut skel_root = Prim::new("SkelRoot", root.clone());
    skel_root.attribute(Attribute::new("extent", "float3[]", Value::Vec3fs(bounds.to_f32().to_vec())));
    let mut mesh = mesh.with_api("SkelBindingAPI");
    mesh.attribute(Attribute::uniform("skel:blendShapes", "token[]", Value::Tokens(names.clone())));
    mesh.relationship("skel:blendShapeTargets", names.iter().map(|n| format!("/{root}/Mesh/{n}")).collect());
    mesh.relationship("skel:skeleton", vec![format!("/{root}/Skel")]);
    mesh.attribute(Attribute::uniform("subdivisionScheme", "token", Value::Token("none".into())));
    let n = clip.vertex_count();
    for target in &clip.targets {
        let mut shape = Prim::new("BlendShape", target.name.clone());
        if super::sparse_is_smaller(target.indices.len(), n, 4) {
            shape.attribute(Attribute::uniform("offsets", "vector3f[]", Value::Vec3fs(target.offsets.clone())));
            shape.attribute(Attribute::uniform("pointIndices", "int[]", Value::Ints(target.indices.iter().map(|&i| i as i32).collect())));
        } else {
            let mut dense = vec![[0.0f32; 3]; n];
            for (&i, o) in target.indices.iter().zip(&target.offsets) {
                dense[i as usize] = *o;
            }
            shape.attribute(Attribute::uniform("offsets", "vector3f[]", Value::Vec3fs(dense)));
        }
        mesh.children.push(shape);
    }
    push_mesh(&mut skel_root, mesh, attributes, root);

    let mut skel = Prim::new("Skeleton", "Skel").with_api("SkelBindingAPI");
    skel.attribute(Attribute::uniform("joints", "token[]", Value::Tokens(Vec::new())));
    skel.relationship("skel:animationSource", vec![format!("/{root}/Skel/Anim")]);
    let mut anim = Prim::new("SkelAnimation", "Anim");
    anim.attribute(Attribute::uniform("blendShapes", "token[]", Value::Tokens(names)));
    let samples = frames.iter().zip(&weights).map(|(&(frame, _), w)| (frame as f64, Value::Floats(w.iter().map(|&x| x as f32).collect()))).collect();
    anim.attribute(Attribute::sampled("blendShapeWeights", "float[]", samples));
    skel.children.push(anim);
    skel_root.children.push(skel);
    Layer { metadata, prims: vec![skel_root] }
}

/// Full-frame animation: `points.timeSamples` at every frame.
pub fn full_frame(frames: &FullFrame, triangles: &[[u32; 3]], attributes: Option<&CornerAttributes>, settings: &UsdSettings) -> Layer {
    let (first, last) = (frames.frames[0], frames.frames[frames.frames.len() - 1]);
    let samples = frames.frames.iter().zip(&frames.points).map(|(&frame, p)| (frame as f64, p.clone())).collect();
    sampled_points(samples, triangles, attributes, settings, (first, last))
}

/// [`full_frame`] without the points' samples, for a writer that streams them from `frames`
/// (`usdc::full_frame`): the points are not copied into the layer. With `weld_map` (per
/// input vertex, its point: a welded bake), the mesh carries it (`weld_map::usd`).
pub(crate) fn full_frame_unsampled(
    frames: &FullFrame,
    triangles: &[[u32; 3]],
    attributes: Option<&CornerAttributes>,
    settings: &UsdSettings,
    weld_map: Option<&[u32]>,
) -> Layer {
    let (first, last) = (frames.frames[0], frames.frames[frames.frames.len() - 1]);
    let extents = frames.frames.iter().zip(&frames.points).map(|(&frame, p)| (frame as f64, extent(p))).collect();
    let vertices = frames.points.first().map_or(0, Vec::len);
    let mut layer = sampled_points_layer(extents, Vec::new(), vertices, triangles, attributes, settings, (first, last));
    if let Some(map) = weld_map {
        super::weld_map::usd(&mut layer, map);
    }
    layer
}

/// The path of the points attribute of [`full_frame`] and [`sampled_points`]' layers.
pub(crate) fn points_path(settings: &UsdSettings) -> String {
    format!("/{}/Mesh.points", settings.name)
}

/// A mesh whose `points` (and `extent`) are sampled at `samples`' time codes (increasing,
/// every sample with the same vertex count), under `Xform ROOT`: the full-frame file's layout,
/// and a `.usdc` vertex cache's (`cache::usd`, whose `.usda` text is this layer too).
/// `time_codes` is the stage's `(startTimeCode, endTimeCode)`.
pub fn sampled_points(
    samples: Vec<(f64, Vec<[f32; 3]>)>,
    triangles: &[[u32; 3]],
    attributes: Option<&CornerAttributes>,
    settings: &UsdSettings,
    time_codes: (i64, i64),
) -> Layer {
    let extents = samples.iter().map(|(code, p)| (*code, extent(p))).collect();
    let vertices = samples.first().map_or(0, |s| s.1.len());
    // The points move into the layer: a cache is held once, not copied.
    let points = samples.into_iter().map(|(code, p)| (code, Value::Vec3fs(p))).collect();
    sampled_points_layer(extents, points, vertices, triangles, attributes, settings, time_codes)
}

/// [`sampled_points`] from each sample's extent and the points' samples (empty when the usdc
/// writer streams them: [`crate::formats::export::usdc::bytes_streamed`]) of `vertices` points.
pub(crate) fn sampled_points_layer(
    extents: Vec<(f64, [[f32; 3]; 2])>,
    points: Vec<(f64, Value)>,
    vertices: usize,
    triangles: &[[u32; 3]],
    attributes: Option<&CornerAttributes>,
    settings: &UsdSettings,
    time_codes: (i64, i64),
) -> Layer {
    let metadata = metadata(settings, time_codes.0, time_codes.1);
    let mut mesh = Prim::new("Mesh", "Mesh");
    mesh.attribute(Attribute::sampled("extent", "float3[]", extents.into_iter().map(|(code, e)| (code, Value::Vec3fs(e.to_vec()))).collect()));
    push_topology(&mut mesh, triangles);
    if let Some(a) = attributes {
        attrs::push_properties(&mut mesh, triangles, vertices, a);
    }
    mesh.attribute(Attribute::sampled("points", "point3f[]", points));
    mesh.attribute(Attribute::uniform("subdivisionScheme", "token", Value::Token("none".into())));
    Layer { metadata, prims: vec![plain_root(mesh, attributes, &settings.name)] }
}

/// `Xform ROOT` holding a plain mesh (with its subsets) and the materials they bind.
fn plain_root(mesh: Prim, attributes: Option<&CornerAttributes>, root: &str) -> Prim {
    let mut xform = Prim::new("Xform", root);
    push_mesh(&mut xform, mesh, attributes, root);
    xform
}

/// `mesh` as a child of the root prim `parent` (a SkelRoot or an Xform) with the surface's
/// material groups: a `GeomSubset` per group under the mesh, then beside it the materials the
/// subsets bind (`/ROOT/Materials`), so both layouts bind materials the same way.
fn push_mesh(parent: &mut Prim, mut mesh: Prim, attributes: Option<&CornerAttributes>, root: &str) {
    let groups = attributes.filter(|a| !a.groups.is_empty());
    if let Some(a) = groups {
        mesh.children.extend(attrs::subsets(a, root));
    }
    parent.children.push(mesh);
    if let Some(a) = groups {
        parent.children.push(attrs::materials(a, root));
    }
}

fn metadata(s: &UsdSettings, start: i64, end: i64) -> Vec<(&'static str, Value)> {
    vec![
        ("defaultPrim", Value::Token(s.name.clone())),
        ("doc", Value::String(format!("blendsim {}", env!("CARGO_PKG_VERSION")))),
        ("endTimeCode", Value::Double(end as f64)),
        ("framesPerSecond", Value::Double(s.fps)),
        ("metersPerUnit", Value::Double(s.meters_per_unit)),
        ("startTimeCode", Value::Double(start as f64)),
        ("timeCodesPerSecond", Value::Double(s.fps)),
        ("upAxis", Value::Token(s.up_axis.to_string())),
    ]
}

/// Triangles as USD faces; our triangles are counter-clockwise seen from outside, which is
/// USD's `rightHanded` orientation.
fn push_topology(mesh: &mut Prim, triangles: &[[u32; 3]]) {
    mesh.attribute(Attribute::new("faceVertexCounts", "int[]", Value::Ints(vec![3; triangles.len()])));
    mesh.attribute(Attribute::new("faceVertexIndices", "int[]", Value::Ints(triangles.iter().flatten().map(|&i| i as i32).collect())));
    mesh.attribute(Attribute::uniform("orientation", "token", Value::Token("rightHanded".into())));
}

/// `[(lo), (hi)]` of a point set (zeros when empty).
pub(crate) fn extent(points: &[[f32; 3]]) -> [[f32; 3]; 2] {
    Bounds::of_f32(points).to_f32()
}
