//! The weld map in the written files: a cache whose vertices were welded on import is written
//! on the welded vertices (glTF and USD meshes are indexed, so shared vertices are their
//! natural form), and each file says, per input vertex, which of its vertices that is, so the
//! input's vertex numbers (selections, index files) still find their points.
//!
//! - glTF: `mesh.extras.weldMap`, an array with one entry per input vertex;
//! - USD: `uniform int[] blendsim:weldMap` on the `Mesh` prim.

use serde_json::Value as Json;

use super::layer::{Attribute, Layer, Value};

/// The extras key (glTF) and attribute name (USD).
pub const GLTF_KEY: &str = "weldMap";
/// See [`GLTF_KEY`].
pub(crate) const USD_ATTRIBUTE: &str = "blendsim:weldMap";

/// `layer` with the map on its `Mesh` prims (the children of its root prims).
pub fn usd(layer: &mut Layer, map: &[u32]) {
    for root in &mut layer.prims {
        for mesh in root.children.iter_mut().filter(|p| p.type_name == "Mesh") {
            mesh.attribute(Attribute::uniform(USD_ATTRIBUTE, "int[]", Value::Ints(map.iter().map(|&v| v as i32).collect())));
        }
    }
}

/// The GLB `glb` with the map in every mesh's `extras` (its JSON chunk rewritten, padded with
/// spaces to 4 bytes; the BIN chunk unchanged). `glb` is a GLB this crate wrote.
pub fn gltf(glb: &[u8], map: &[u32]) -> Vec<u8> {
    let word = |at: usize| u32::from_le_bytes(glb[at..at + 4].try_into().expect("4 bytes")) as usize;
    let json_len = word(12);
    let mut json = gltf_json(&glb[20..20 + json_len], map);
    while !json.len().is_multiple_of(4) {
        json.push(b' ');
    }
    let rest = &glb[20 + json_len..];
    let mut out = Vec::with_capacity(20 + json.len() + rest.len());
    out.extend_from_slice(&glb[..8]);
    out.extend_from_slice(&((20 + json.len() + rest.len()) as u32).to_le_bytes());
    out.extend_from_slice(&(json.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&json);
    out.extend_from_slice(rest);
    out
}

/// A glTF JSON chunk (this crate's) with the map in every mesh's `extras`, unpadded: what
/// [`fn@gltf`] puts in the GLB, for a GLB still in parts (`glb::Glb::with_json`).
pub fn gltf_json(json: &[u8], map: &[u32]) -> Vec<u8> {
    let mut root: Json = serde_json::from_slice(json).expect("our own GLB's JSON");
    if let Some(meshes) = root.get_mut("meshes").and_then(Json::as_array_mut) {
        for mesh in meshes {
            let extras = mesh.as_object_mut().expect("a mesh is an object").entry("extras").or_insert_with(|| Json::Object(Default::default()));
            if let Some(extras) = extras.as_object_mut() {
                extras.insert(GLTF_KEY.into(), Json::from(map.to_vec()));
            }
        }
    }
    serde_json::to_vec(&root).expect("JSON serializes")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_map_joins_the_extras_and_the_container_stays_valid() {
        let json = br#"{"asset":{"version":"2.0"},"meshes":[{"name":"m","extras":{"targetNames":["a"]},"primitives":[]}]}"#.to_vec();
        let mut padded = json.clone();
        while !padded.len().is_multiple_of(4) {
            padded.push(b' ');
        }
        let bin = [1u8, 2, 3, 4, 8, 0, 0, 0, b'B', b'I', b'N', 0];
        let mut glb = b"glTF".to_vec();
        glb.extend(2u32.to_le_bytes());
        glb.extend(((20 + padded.len() + bin.len()) as u32).to_le_bytes());
        glb.extend((padded.len() as u32).to_le_bytes());
        glb.extend(b"JSON");
        glb.extend(&padded);
        glb.extend(bin);
        let out = gltf(&glb, &[0, 1, 0]);
        let len = u32::from_le_bytes(out[8..12].try_into().unwrap()) as usize;
        let json_len = u32::from_le_bytes(out[12..16].try_into().unwrap()) as usize;
        assert_eq!((len, json_len % 4), (out.len(), 0));
        assert_eq!(&out[20 + json_len..], &bin);
        let root: Json = serde_json::from_slice(&out[20..20 + json_len]).unwrap();
        assert_eq!(root["meshes"][0]["extras"]["weldMap"], serde_json::json!([0, 1, 0]));
        assert_eq!(root["meshes"][0]["extras"]["targetNames"], serde_json::json!(["a"]));
    }
}
