//! The USD form of a surface's corner attributes (helper of `usda`): `primvars:st`, `normals`,
//! and material groups as `GeomSubset`s bound to placeholder `Material`s. Layout in
//! `formats/usd.md`.
//!
//! Per-vertex (`vertex` interpolation) when every corner of a vertex agrees, `faceVarying`
//! otherwise (UVs indexed, so a seam costs one int per corner, not a value). Points are never
//! split: the mesh's points stay the animation's points.

use std::fmt::Write;

use super::usda::{push_attr, push_f32, push_ints, push_list, push_vec3s};
use crate::mesh::attributes::CornerAttributes;

/// Unique prim names for the material groups (sanitized; a clash gets `_2`, `_3`...).
pub(crate) fn group_prim_names(attributes: &CornerAttributes) -> Vec<String> {
    let mut names: Vec<String> = Vec::with_capacity(attributes.groups.len());
    for g in &attributes.groups {
        let base = super::usda::prim_name(g);
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

fn push_uvs(out: &mut String, uvs: impl Iterator<Item = [f64; 2]>) {
    push_list(out, uvs, |o, [u, v]| {
        o.push('(');
        push_f32(o, u as f32);
        o.push_str(", ");
        push_f32(o, v as f32);
        o.push(')');
    });
}

/// The mesh properties: `primvars:st` (+ `:indices`), `normals`, and the subset family type.
pub(crate) fn push_properties(out: &mut String, triangles: &[[u32; 3]], vertices: usize, attributes: &CornerAttributes) {
    if !attributes.uv_corners.is_empty() {
        match attributes.uvs_per_vertex(triangles, vertices) {
            Some(per_vertex) => {
                push_attr(out, 8, "texCoord2f[] primvars:st", |o| push_uvs(o, per_vertex.into_iter()));
                out.truncate(out.len() - 1);
                out.push_str(" (\n            interpolation = \"vertex\"\n        )\n");
            }
            None => {
                push_attr(out, 8, "texCoord2f[] primvars:st", |o| push_uvs(o, attributes.uvs.iter().copied()));
                out.truncate(out.len() - 1);
                out.push_str(" (\n            interpolation = \"faceVarying\"\n        )\n");
                push_attr(out, 8, "int[] primvars:st:indices", |o| push_ints(o, attributes.uv_corners.iter().flatten().copied()));
            }
        }
    }
    if !attributes.normal_corners.is_empty() {
        let f32s = |n: &[f64; 3]| n.map(|x| x as f32);
        let (values, interpolation): (Vec<[f32; 3]>, &str) = match attributes.normals_per_vertex(triangles, vertices) {
            Some(per_vertex) => (per_vertex.iter().map(f32s).collect(), "vertex"),
            None => (attributes.normal_corners.iter().flatten().map(|&i| f32s(&attributes.normals[i as usize])).collect(), "faceVarying"),
        };
        push_attr(out, 8, "normal3f[] normals", |o| push_vec3s(o, values.iter()));
        out.truncate(out.len() - 1);
        let _ = writeln!(out, " (\n            interpolation = \"{interpolation}\"\n        )");
    }
    if !attributes.groups.is_empty() {
        out.push_str("        uniform token subsetFamily:materialBind:familyType = \"partition\"\n");
    }
}

/// One `GeomSubset` per material group (children of the mesh), bound to `ROOT/Materials/NAME`.
pub(crate) fn push_subsets(out: &mut String, attributes: &CornerAttributes, root: &str) {
    for (g, name) in group_prim_names(attributes).iter().enumerate() {
        let _ = writeln!(out, "\n        def GeomSubset \"{name}\" (\n            prepend apiSchemas = [\"MaterialBindingAPI\"]\n        )\n        {{");
        out.push_str("            uniform token elementType = \"face\"\n            uniform token familyName = \"materialBind\"\n");
        let faces = attributes.triangle_groups.iter().enumerate().filter(|(_, &x)| x as usize == g).map(|(t, _)| t as u32);
        push_attr(out, 12, "int[] indices", |o| push_ints(o, faces));
        let _ = writeln!(out, "            rel material:binding = </{root}/Materials/{name}>\n        }}");
    }
}

/// The materials the subsets bind, named after the OBJ's `usemtl` (importers create material
/// slots only for bound materials): a UsdPreviewSurface each, grey, or with the group's
/// texture (`map_Kd`, copied beside the file by the export stage: `@./NAME@`) read by a
/// UsdUVTexture at `primvars:st` (when the surface has UVs).
pub(crate) fn push_materials(out: &mut String, attributes: &CornerAttributes, root: &str) {
    let textures = super::texture::file_names(&attributes.textures);
    let has_uvs = !attributes.uv_corners.is_empty();
    out.push_str("\n    def Scope \"Materials\"\n    {\n");
    for (i, name) in group_prim_names(attributes).iter().enumerate() {
        if i > 0 {
            out.push('\n');
        }
        let path = format!("/{root}/Materials/{name}");
        let texture = textures.get(i).and_then(Option::as_ref).filter(|_| has_uvs);
        let _ = writeln!(out, "        def Material \"{name}\"\n        {{");
        let _ = writeln!(out, "            token outputs:surface.connect = <{path}/Surface.outputs:surface>\n");
        out.push_str("            def Shader \"Surface\"\n            {\n                uniform token info:id = \"UsdPreviewSurface\"\n");
        match texture {
            Some(_) => {
                let _ = writeln!(out, "                color3f inputs:diffuseColor.connect = <{path}/Texture.outputs:rgb>");
            }
            None => out.push_str("                color3f inputs:diffuseColor = (0.8, 0.8, 0.8)\n"),
        }
        out.push_str("                float inputs:roughness = 0.5\n                token outputs:surface\n            }\n");
        if let Some(file) = texture {
            // The asset path is relative to the layer, so the folder can move as a whole.
            out.push_str("\n            def Shader \"Texture\"\n            {\n                uniform token info:id = \"UsdUVTexture\"\n");
            let _ = writeln!(out, "                asset inputs:file = @./{file}@");
            let _ = writeln!(out, "                float2 inputs:st.connect = <{path}/St.outputs:result>");
            out.push_str("                token inputs:wrapS = \"repeat\"\n                token inputs:wrapT = \"repeat\"\n");
            out.push_str("                float3 outputs:rgb\n            }\n");
            out.push_str("\n            def Shader \"St\"\n            {\n                uniform token info:id = \"UsdPrimvarReader_float2\"\n");
            out.push_str("                string inputs:varname = \"st\"\n                float2 outputs:result\n            }\n");
        }
        out.push_str("        }\n");
    }
    out.push_str("    }\n");
}
