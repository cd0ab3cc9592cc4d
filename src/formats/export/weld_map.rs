//! The weld map in the written files: a cache whose vertices were welded on import is written
//! on the welded vertices (glTF and USD meshes are indexed, so shared vertices are their
//! natural form), and each file says, per input vertex, which of its vertices that is, so the
//! input's vertex numbers (selections, index files) still find their points.
//!
//! - glTF: `meshes[0].extras.weldMap` is the index of a SCALAR accessor of unsigned shorts (or
//!   unsigned ints past 65535 points) with one entry per input vertex, in the BIN chunk (the
//!   glb writer puts it there, `glb::Surface::weld_map`). When the map is the primitive's
//!   index list (an input with a vertex per triangle corner), it is that accessor: no bytes
//!   of its own;
//! - USD: `uniform int[] blendsim:weldMap` on the `Mesh` prim.

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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::algorithms::blendshape::clip::{BlendShapeClip, Target, WeightCurve};
    use crate::formats::export::glb::readback::{chunks, decode_meshopt};
    use crate::formats::export::glb::{self, Compression, Encoding, Placement, Surface};
    use serde_json::Value as Json;

    fn clip() -> BlendShapeClip {
        BlendShapeClip {
            base: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]],
            targets: vec![Target { name: "lift".into(), indices: vec![2, 3], offsets: vec![[0.0, 0.0, 0.5], [0.0, 0.0, 0.25]] }],
            times: vec![0.0, 1.0],
            curves: vec![WeightCurve { values: vec![0.0, 1.0], in_tangents: vec![1.0, 1.0], out_tangents: vec![1.0, 1.0] }],
        }
    }

    /// The weld map of a GLB this crate wrote (meshopt views decoded first), `None` when its
    /// mesh has none; `Err` names what is malformed. (The pipeline never reads a map back; the
    /// integration tests read it with their own glTF reader.)
    fn from_glb(glb: &[u8]) -> Result<Option<Vec<u32>>, String> {
        let (json, _) = chunks(glb).ok_or("not a GLB")?;
        let Some(index) = json["meshes"][0]["extras"].get(GLTF_KEY) else { return Ok(None) };
        let index = index.as_u64().ok_or("extras.weldMap is not an accessor index")? as usize;
        let compressed = json["extensionsRequired"].as_array().is_some_and(|a| a.iter().any(|e| e == "EXT_meshopt_compression"));
        let decoded;
        let glb = if compressed {
            decoded = decode_meshopt(glb)?;
            &decoded[..]
        } else {
            glb
        };
        let (json, bin) = chunks(glb).ok_or("not a GLB")?;
        let accessor = &json["accessors"][index];
        let size = match accessor["componentType"].as_u64() {
            Some(5121) => 1,
            Some(5123) => 2,
            Some(5125) => 4,
            _ => return Err(format!("the weld map's accessor {index} is not of unsigned integers")),
        };
        if accessor["type"] != "SCALAR" {
            return Err(format!("the weld map's accessor {index} is not SCALAR"));
        }
        let count = accessor["count"].as_u64().ok_or("the weld map's accessor has no count")? as usize;
        let view: &Json = &json["bufferViews"][accessor["bufferView"].as_u64().ok_or("the weld map's accessor has no buffer view")? as usize];
        let start = view["byteOffset"].as_u64().unwrap_or(0) as usize + accessor["byteOffset"].as_u64().unwrap_or(0) as usize;
        let stride = view["byteStride"].as_u64().map_or(size, |s| s as usize);
        (0..count)
            .map(|i| {
                let at = start + i * stride;
                let b = bin.get(at..at + size).ok_or("the weld map runs past the BIN chunk")?;
                Ok(match size {
                    1 => b[0] as u32,
                    2 => u16::from_le_bytes([b[0], b[1]]) as u32,
                    _ => u32::from_le_bytes([b[0], b[1], b[2], b[3]]),
                })
            })
            .collect::<Result<Vec<u32>, String>>()
            .map(Some)
    }

    /// The map is read back from the BIN chunk in every compression; a per-corner map is the
    /// index list itself (the same accessor), any other has its own u16 accessor.
    #[test]
    fn the_map_is_binary_and_shares_the_index_list_when_equal() {
        let triangles = [[0, 1, 2], [0, 2, 3]];
        let per_corner = [0, 1, 2, 0, 2, 3];
        let other = [3, 0, 1, 2, 2];
        let placement = Placement { z_up: false, meters_per_unit: 1.0 };
        for compression in [Compression::None, Compression::Quantize, Compression::Meshopt] {
            let encoding = Encoding { compression, max_error: 1e-4 };
            for map in [&per_corner[..], &other[..]] {
                let surface = Surface { weld_map: Some(map), ..Surface::plain(&triangles) };
                let bytes = glb::blendshapes(&clip(), surface, "m", placement, encoding).to_vec();
                assert_eq!(from_glb(&bytes).unwrap().as_deref(), Some(map), "{compression:?}");
                let (json, _) = chunks(&bytes).unwrap();
                let shared = json["meshes"][0]["extras"][GLTF_KEY] == json["meshes"][0]["primitives"][0]["indices"];
                assert_eq!(shared, map == per_corner, "{compression:?}");
                let accessor = &json["accessors"][json["meshes"][0]["extras"][GLTF_KEY].as_u64().unwrap() as usize];
                assert_eq!((accessor["componentType"].as_u64(), accessor["count"].as_u64()), (Some(5123), Some(map.len() as u64)));
            }
            let bytes = glb::blendshapes(&clip(), Surface::plain(&triangles), "m", placement, encoding).to_vec();
            assert_eq!(from_glb(&bytes), Ok(None), "no map without welding");
        }
    }
}
