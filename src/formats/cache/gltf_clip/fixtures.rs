//! glTF clips written for tests (unit and integration: `formats::cache::gltf_fixtures`), with
//! gltf-json: a small document builder and the skinned ribbon clip that exercises the clip
//! reader's skinning, TRS interpolations and morph weights together. Not API.

use std::path::Path;

use gltf_json as json;
use json::accessor::{ComponentType, Type};
use json::animation::{Interpolation as Interp, Property};
use json::validation::{Checked::Valid, USize64};
use json::Index;
use serde_json::json as value;

/// One animation channel for [`Builder::animation`]: node, property, interpolation, key
/// times, output values.
pub(crate) type ChannelSpec<'a> = (Index<json::Node>, Property, Interp, &'a [f32], &'a [f32]);

/// A glTF document under construction: one buffer, one view per accessor.
pub(crate) struct Builder {
    pub(crate) root: json::Root,
    bin: Vec<u8>,
}

impl Builder {
    pub(crate) fn new() -> Builder {
        let mut root = json::Root::default();
        root.asset.generator = Some("blendsim tests".into());
        Builder { root, bin: Vec::new() }
    }

    pub(crate) fn accessor(
        &mut self,
        bytes: &[u8],
        count: usize,
        component: ComponentType,
        type_: Type,
        target: Option<json::buffer::Target>,
    ) -> json::Accessor {
        let offset = self.bin.len();
        self.bin.extend_from_slice(bytes);
        self.bin.resize(self.bin.len().next_multiple_of(4), 0);
        let view = self.root.push(json::buffer::View {
            buffer: Index::new(0),
            byte_length: USize64(bytes.len() as u64),
            byte_offset: Some(USize64(offset as u64)),
            byte_stride: None,
            name: None,
            target: target.map(Valid),
            extensions: None,
            extras: None,
        });
        crate::formats::export::glb::accessor_in(Some((view.value() as u32, 0)), count, component, type_)
    }

    pub(crate) fn floats(&mut self, values: &[f32], type_: Type, bounds: bool) -> Index<json::Accessor> {
        let width = type_.multiplicity();
        let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        let target = (type_ == Type::Vec3 || type_ == Type::Vec4).then_some(json::buffer::Target::ArrayBuffer).filter(|_| bounds);
        let mut a = self.accessor(&bytes, values.len() / width, ComponentType::F32, type_, target);
        if bounds {
            let lo: Vec<f64> = (0..width).map(|k| values.iter().skip(k).step_by(width).fold(f32::INFINITY, |m, &x| m.min(x)) as f64).collect();
            let hi: Vec<f64> = (0..width).map(|k| values.iter().skip(k).step_by(width).fold(f32::NEG_INFINITY, |m, &x| m.max(x)) as f64).collect();
            (a.min, a.max) = (Some(value!(lo)), Some(value!(hi)));
        }
        self.root.push(a)
    }

    pub(crate) fn points(&mut self, points: &[[f32; 3]]) -> Index<json::Accessor> {
        self.floats(&points.concat(), Type::Vec3, true)
    }

    pub(crate) fn u16s(&mut self, values: &[u16], type_: Type, target: json::buffer::Target) -> Index<json::Accessor> {
        let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        let a = self.accessor(&bytes, values.len() / type_.multiplicity(), ComponentType::U16, type_, Some(target));
        self.root.push(a)
    }

    pub(crate) fn mesh(
        &mut self,
        positions: &[[f32; 3]],
        triangles: &[[u32; 3]],
        targets: &[Vec<[f32; 3]>],
        skin: Option<(&[u16], &[f32])>,
    ) -> Index<json::Mesh> {
        let position = self.points(positions);
        let indices: Vec<u16> = triangles.iter().flatten().map(|&i| i as u16).collect();
        let indices = self.u16s(&indices, Type::Scalar, json::buffer::Target::ElementArrayBuffer);
        let mut attributes: std::collections::BTreeMap<_, _> = [(Valid(json::mesh::Semantic::Positions), position)].into_iter().collect();
        if let Some((joints, weights)) = skin {
            attributes.insert(Valid(json::mesh::Semantic::Joints(0)), self.u16s(joints, Type::Vec4, json::buffer::Target::ArrayBuffer));
            let w = self.floats(weights, Type::Vec4, false);
            attributes.insert(Valid(json::mesh::Semantic::Weights(0)), w);
        }
        let targets: Vec<json::mesh::MorphTarget> =
            targets.iter().map(|t| json::mesh::MorphTarget { positions: Some(self.points(t)), normals: None, tangents: None }).collect();
        let count = targets.len();
        self.root.push(json::Mesh {
            extensions: None,
            extras: None,
            name: Some("mesh".into()),
            primitives: vec![json::mesh::Primitive {
                attributes,
                extensions: None,
                extras: None,
                indices: Some(indices),
                material: None,
                mode: Valid(json::mesh::Mode::Triangles),
                targets: (count > 0).then_some(targets),
            }],
            weights: (count > 0).then(|| vec![0.0; count]),
        })
    }

    pub(crate) fn node(&mut self, node: json::Node) -> Index<json::Node> {
        self.root.push(node)
    }

    /// An animation of `(node, property, interpolation, times, values)` channels.
    pub(crate) fn animation(&mut self, name: &str, channels: &[ChannelSpec]) {
        let (mut samplers, mut list) = (Vec::new(), Vec::new());
        for (i, &(node, property, interpolation, times, values)) in channels.iter().enumerate() {
            let input = self.floats(times, Type::Scalar, true);
            let type_ = match property {
                Property::Translation | Property::Scale => Type::Vec3,
                Property::Rotation => Type::Vec4,
                Property::MorphTargetWeights => Type::Scalar,
            };
            let output = self.floats(values, type_, false);
            samplers.push(json::animation::Sampler { extensions: None, extras: None, input, interpolation: Valid(interpolation), output });
            list.push(json::animation::Channel {
                sampler: Index::new(i as u32),
                target: json::animation::Target { extensions: None, extras: None, node, path: Valid(property) },
                extensions: None,
                extras: None,
            });
        }
        self.root.push(json::Animation { extensions: None, extras: None, name: Some(name.into()), channels: list, samplers });
    }

    pub(crate) fn glb(mut self, roots: Vec<Index<json::Node>>) -> Vec<u8> {
        let scene = self.root.push(json::Scene { extensions: None, extras: None, name: None, nodes: roots });
        self.root.scene = Some(scene);
        self.root.push(json::Buffer { byte_length: USize64(self.bin.len() as u64), name: None, uri: None, extensions: None, extras: None });
        let mut json = self.root.to_vec().unwrap();
        json.resize(json.len().next_multiple_of(4), b' ');
        let total = 12 + 8 + json.len() + 8 + self.bin.len();
        let mut out = b"glTF".to_vec();
        out.extend(2u32.to_le_bytes());
        out.extend((total as u32).to_le_bytes());
        out.extend((json.len() as u32).to_le_bytes());
        out.extend_from_slice(b"JSON");
        out.extend_from_slice(&json);
        out.extend((self.bin.len() as u32).to_le_bytes());
        out.extend_from_slice(b"BIN\0");
        out.extend_from_slice(&self.bin);
        out
    }
}

/// The unit quaternion (x, y, z, w) of a rotation by `degrees` about the unit `axis`.
pub(crate) fn quat(axis: [f32; 3], degrees: f32) -> [f32; 4] {
    let (s, c) = (degrees.to_radians() / 2.0).sin_cos();
    [axis[0] * s, axis[1] * s, axis[2] * s, c]
}

/// A ribbon along y skinned to a chain of three joints under a translated armature, with a
/// morph target, and one animation mixing STEP translation, LINEAR (slerp) and CUBICSPLINE
/// rotations, LINEAR scale and LINEAR weights.
pub fn skinned_clip(path: &Path) {
    let (mut positions, mut joints, mut weights, mut triangles) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for row in 0..7u16 {
        let y = 0.5 * row as f32;
        for x in [-0.2f32, 0.2] {
            positions.push([x, y, 0.0]);
            let (j, f) = ((y.floor() as u16).min(2), y - y.floor().min(2.0));
            if j < 2 && f > 0.0 {
                joints.extend([j, j + 1, 0, 0]);
                weights.extend([1.0 - f, f, 0.0, 0.0]);
            } else {
                joints.extend([j, 0, 0, 0]);
                weights.extend([1.0, 0.0, 0.0, 0.0]);
            }
        }
        if row > 0 {
            let a = 2 * (row as u32 - 1);
            triangles.extend([[a, a + 1, a + 3], [a, a + 3, a + 2]]);
        }
    }
    let thicken: Vec<[f32; 3]> = positions.iter().map(|p| [0.0, 0.0, 0.1 + 0.05 * p[1]]).collect();
    let mut b = Builder::new();
    let mesh = b.mesh(&positions, &triangles, &[thicken], Some((&joints, &weights)));
    let j2 = b.node(json::Node { name: Some("j2".into()), translation: Some([0.0, 1.0, 0.0]), ..Default::default() });
    let j1 = b.node(json::Node { name: Some("j1".into()), translation: Some([0.0, 1.0, 0.0]), children: Some(vec![j2]), ..Default::default() });
    let j0 = b.node(json::Node { name: Some("j0".into()), children: Some(vec![j1]), ..Default::default() });
    let armature =
        b.node(json::Node { name: Some("armature".into()), translation: Some([0.0, 0.5, 0.0]), children: Some(vec![j0]), ..Default::default() });
    // Inverse bind matrices: the joints' rest globals are translations by (0, 0.5 + j, 0).
    let ibm: Vec<f32> = (0..3).flat_map(|j| [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, -0.5 - j as f32, 0.0, 1.0]).collect();
    let ibm = b.floats(&ibm, Type::Mat4, false);
    let skin = b.root.push(json::Skin {
        extensions: None,
        extras: None,
        inverse_bind_matrices: Some(ibm),
        joints: vec![j0, j1, j2],
        name: None,
        skeleton: Some(j0),
    });
    let node = b.node(json::Node { mesh: Some(mesh), skin: Some(skin), name: Some("ribbon".into()), ..Default::default() });
    let swing = [quat([0.0, 0.0, 1.0], 0.0), quat([0.0, 0.0, 1.0], 40.0), quat([1.0, 0.0, 0.0], 40.0)].concat();
    let (r0, r1) = (quat([0.0, 0.0, 1.0], 0.0), quat([0.0, 0.0, 1.0], 60.0));
    #[rustfmt::skip]
    let whip = [
        [0.0; 4], r0, [0.0, 0.0, 0.3, 0.0],
        [0.0, 0.0, 0.2, -0.1], r1, [0.0; 4],
    ].concat();
    b.animation(
        "swing",
        &[
            (j0, Property::Translation, Interp::Step, &[0.0, 0.5], &[0.0, 0.0, 0.0, 0.1, 0.0, 0.0]),
            (j1, Property::Rotation, Interp::Linear, &[0.0, 0.5, 1.0], &swing),
            (j2, Property::Rotation, Interp::CubicSpline, &[0.0, 1.0], &whip),
            (j1, Property::Scale, Interp::Linear, &[0.0, 1.0], &[1.0, 1.0, 1.0, 1.0, 1.3, 1.0]),
            (node, Property::MorphTargetWeights, Interp::Linear, &[0.0, 1.0], &[0.0, 1.0]),
        ],
    );
    std::fs::write(path, b.glb(vec![node, armature])).unwrap();
}
