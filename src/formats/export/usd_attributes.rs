//! The USD form of a surface's corner attributes (helper of `usd`): `primvars:st`, `normals`,
//! and material groups as `GeomSubset`s bound to placeholder `Material`s. Layout in
//! `formats/usd.md`.
//!
//! Per-vertex (`vertex` interpolation) when every corner of a vertex agrees, `faceVarying`
//! otherwise (UVs indexed, so a seam costs one int per corner, not a value). Points are never
//! split: the mesh's points stay the animation's points.

use super::layer::{Attribute, Prim, Value};
use crate::algorithms::geometry::attributes::CornerAttributes;

/// Unique prim names for the material groups (sanitized; a clash gets `_2`, `_3`...).
pub(crate) fn group_prim_names(attributes: &CornerAttributes) -> Vec<String> {
    let mut names: Vec<String> = Vec::with_capacity(attributes.groups.len());
    for g in &attributes.groups {
        let base = super::layer::prim_name(g);
        let mut name = base.clone();
        let mut k = 2;
        while names.contains(&name) {
            name = format!("{base}_{k}");
            k += 1;
        }
        names.push(name);
    }
    names
}

fn uvs(uvs: impl Iterator<Item = [f64; 2]>) -> Value {
    Value::Vec2fs(uvs.map(|[u, v]| [u as f32, v as f32]).collect())
}

/// The mesh properties: `primvars:st` (+ `:indices`), `normals`, and the subset family type.
pub(crate) fn push_properties(mesh: &mut Prim, triangles: &[[u32; 3]], vertices: usize, attributes: &CornerAttributes) {
    if !attributes.uv_corners.is_empty() {
        match attributes.uvs_per_vertex(triangles, vertices) {
            Some(per_vertex) => {
                mesh.attribute(Attribute::new("primvars:st", "texCoord2f[]", uvs(per_vertex.into_iter())).with_interpolation("vertex"))
            }
            None => {
                mesh.attribute(Attribute::new("primvars:st", "texCoord2f[]", uvs(attributes.uvs.iter().copied())).with_interpolation("faceVarying"));
                let indices = attributes.uv_corners.iter().flatten().map(|&i| i as i32).collect();
                mesh.attribute(Attribute::new("primvars:st:indices", "int[]", Value::Ints(indices)));
            }
        }
    }
    if !attributes.normal_corners.is_empty() {
        let f32s = |n: &[f64; 3]| n.map(|x| x as f32);
        let (values, interpolation): (Vec<[f32; 3]>, &str) = match attributes.normals_per_vertex(triangles, vertices) {
            Some(per_vertex) => (per_vertex.iter().map(f32s).collect(), "vertex"),
            None => (attributes.normal_corners.iter().flatten().map(|&i| f32s(&attributes.normals[i as usize])).collect(), "faceVarying"),
        };
        mesh.attribute(Attribute::new("normals", "normal3f[]", Value::Vec3fs(values)).with_interpolation(interpolation));
    }
    if !attributes.groups.is_empty() {
        mesh.attribute(Attribute::uniform("subsetFamily:materialBind:familyType", "token", Value::Token("partition".into())));
    }
}

/// One `GeomSubset` per material group (children of the mesh), bound to `ROOT/Materials/NAME`.
pub(crate) fn subsets(attributes: &CornerAttributes, root: &str) -> Vec<Prim> {
    let token = |s: &str| Value::Token(s.into());
    group_prim_names(attributes)
        .into_iter()
        .enumerate()
        .map(|(g, name)| {
            let mut subset = Prim::new("GeomSubset", name.clone()).with_api("MaterialBindingAPI");
            subset.attribute(Attribute::uniform("elementType", "token", token("face")));
            subset.attribute(Attribute::uniform("familyName", "token", token("materialBind")));
            let faces = attributes.triangle_groups.iter().enumerate().filter(|(_, &x)| x as usize == g).map(|(t, _)| t as i32).collect();
            subset.attribute(Attribute::new("indices", "int[]", Value::Ints(faces)));
            subset.relationship("material:binding", vec![format!("/{root}/Materials/{name}")]);
            subset
        })
        .collect()
}

/// The materials the subsets bind, named after the OBJ's `usemtl` (importers create material
/// slots only for bound materials): a UsdPreviewSurface each, grey, or with the group's
/// texture (`map_Kd`, copied beside the file by the export stage: `@./NAME@`) read by a
/// UsdUVTexture at `primvars:st` (when the surface has UVs).
pub(crate) fn materials(attributes: &CornerAttributes, root: &str) -> Prim {
    let textures = super::texture::file_names(&attributes.textures);
    let has_uvs = !attributes.uv_corners.is_empty();
    let token = |s: &str| Value::Token(s.into());
    let mut scope = Prim::new("Scope", "Materials");
    for (i, name) in group_prim_names(attributes).iter().enumerate() {
        let path = format!("/{root}/Materials/{name}");
        let texture = textures.get(i).and_then(Option::as_ref).filter(|_| has_uvs);
        let mut material = Prim::new("Material", name.clone());
        material.attribute(Attribute::connected("outputs:surface", "token", format!("{path}/Surface.outputs:surface")));
        let mut surface = Prim::new("Shader", "Surface");
        surface.attribute(Attribute::uniform("info:id", "token", token("UsdPreviewSurface")));
        match texture {
            Some(_) => surface.attribute(Attribute::connected("inputs:diffuseColor", "color3f", format!("{path}/Texture.outputs:rgb"))),
            None => surface.attribute(Attribute::new("inputs:diffuseColor", "color3f", Value::Vec3f([0.8; 3]))),
        }
        surface.attribute(Attribute::new("inputs:roughness", "float", Value::Float(0.5)));
        surface.attribute(Attribute::declared("outputs:surface", "token"));
        material.children.push(surface);
        if let Some(file) = texture {
            // The asset path is relative to the layer, so the folder can move as a whole.
            let mut shader = Prim::new("Shader", "Texture");
            shader.attribute(Attribute::uniform("info:id", "token", token("UsdUVTexture")));
            shader.attribute(Attribute::new("inputs:file", "asset", Value::Asset(format!("./{file}"))));
            shader.attribute(Attribute::connected("inputs:st", "float2", format!("{path}/St.outputs:result")));
            shader.attribute(Attribute::new("inputs:wrapS", "token", token("repeat")));
            shader.attribute(Attribute::new("inputs:wrapT", "token", token("repeat")));
            shader.attribute(Attribute::declared("outputs:rgb", "float3"));
            material.children.push(shader);
            let mut st = Prim::new("Shader", "St");
            st.attribute(Attribute::uniform("info:id", "token", token("UsdPrimvarReader_float2")));
            st.attribute(Attribute::new("inputs:varname", "string", Value::String("st".into())));
            st.attribute(Attribute::declared("outputs:result", "float2"));
            material.children.push(st);
        }
        scope.children.push(material);
    }
    scope
}
