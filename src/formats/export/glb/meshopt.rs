//! `EXT_meshopt_compression`: buffer views encoded with meshoptimizer's codecs (the `meshopt`
//! crate): vertex attributes, morph targets and animation data with the vertex codec, triangle
//! indices with the index codec. Both are lossless on the (already quantized) bytes, so a
//! meshopt file plays exactly what its `KHR_mesh_quantization` twin plays.
//!
//! The vertex codec is written in format version 0, the only one `EXT_meshopt_compression`
//! defines (version 1 belongs to the newer `KHR_meshopt_compression`).

use serde_json::{json, Value};

/// A view's bytes as the extension stores them, with the extension object's fields other than
/// `buffer` and `byteOffset`.
#[derive(Debug)]
pub struct Encoded {
    /// The compressed bytes.
    pub bytes: Vec<u8>,
    /// `byteStride`: the element size the codec worked on.
    pub byte_stride: usize,
    /// `count`: elements.
    pub count: usize,
    /// `mode`: `ATTRIBUTES`, `TRIANGLES` or `INDICES`.
    pub mode: &'static str,
}

impl Encoded {
    /// The extension object of a view whose compressed bytes are at `byte_offset` in buffer 0.
    pub fn extension(&self, byte_offset: usize) -> Value {
        json!({
            "buffer": 0,
            "byteOffset": byte_offset,
            "byteLength": self.bytes.len(),
            "byteStride": self.byte_stride,
            "count": self.count,
            "mode": self.mode,
        })
    }
}

fn elements<const N: usize>(data: &[u8]) -> Vec<[u8; N]> {
    data.chunks_exact(N).map(|c| c.try_into().expect("N bytes")).collect()
}

fn encode_elements<const N: usize>(data: &[u8]) -> Vec<u8> {
    meshopt::encoding::encode_vertex_buffer_level(&elements::<N>(data), 2, Some(0)).expect("meshopt encodes any vertex buffer")
}

/// Vertex data in elements of `stride` bytes (4, 8 or 12), `ATTRIBUTES` mode.
pub fn attributes(data: &[u8], stride: usize) -> Encoded {
    assert_eq!(data.len() % stride, 0, "whole elements");
    let bytes = match stride {
        4 => encode_elements::<4>(data),
        8 => encode_elements::<8>(data),
        12 => encode_elements::<12>(data),
        _ => unreachable!("the writer's strides are 4, 8 and 12"),
    };
    Encoded { bytes, byte_stride: stride, count: data.len() / stride, mode: "ATTRIBUTES" }
}

/// Indices of `size` bytes (2 or 4): `TRIANGLES` mode when they are whole triangles (one
/// primitive, no padding), else `INDICES` (any sequence, e.g. several primitives each padded to
/// 4 bytes).
pub fn indices(data: &[u8], size: usize, vertices: usize, whole_triangles: bool) -> Encoded {
    let values: Vec<u32> = match size {
        2 => data.chunks_exact(2).map(|c| u16::from_le_bytes([c[0], c[1]]) as u32).collect(),
        _ => data.chunks_exact(4).map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect(),
    };
    let triangles = whole_triangles && values.len().is_multiple_of(3);
    let bytes = if triangles {
        meshopt::encoding::encode_index_buffer(&values, vertices)
    } else {
        meshopt::encoding::encode_index_sequence(&values, vertices)
    }
    .expect("meshopt encodes any index buffer");
    Encoded { bytes, byte_stride: size, count: values.len(), mode: if triangles { "TRIANGLES" } else { "INDICES" } }
}

fn flat<const N: usize>(v: Vec<[u8; N]>) -> Vec<u8> {
    v.into_iter().flatten().collect()
}

/// The bytes of a compressed view, from its extension object (`mode`, `count`, `byteStride`;
/// no filter, which the writer never uses) and the compressed bytes: what a decoder gives.
pub fn decode(extension: &Value, compressed: &[u8]) -> Result<Vec<u8>, String> {
    let field = |k: &str| extension[k].as_u64().map(|x| x as usize).ok_or_else(|| format!("EXT_meshopt_compression without {k}"));
    let (count, stride) = (field("count")?, field("byteStride")?);
    if extension.get("filter").is_some_and(|f| f != "NONE") {
        return Err(format!("filter {} is not decoded here", extension["filter"]));
    }
    let err = |e: meshopt::Error| e.to_string();
    match (extension["mode"].as_str(), stride) {
        (Some("ATTRIBUTES"), 4) => meshopt::encoding::decode_vertex_buffer::<[u8; 4]>(compressed, count).map(flat).map_err(err),
        (Some("ATTRIBUTES"), 8) => meshopt::encoding::decode_vertex_buffer::<[u8; 8]>(compressed, count).map(flat).map_err(err),
        (Some("ATTRIBUTES"), 12) => meshopt::encoding::decode_vertex_buffer::<[u8; 12]>(compressed, count).map(flat).map_err(err),
        (Some("TRIANGLES"), 2) => {
            Ok(meshopt::encoding::decode_index_buffer::<u16>(compressed, count).map_err(err)?.iter().flat_map(|x| x.to_le_bytes()).collect())
        }
        (Some("TRIANGLES"), 4) => {
            Ok(meshopt::encoding::decode_index_buffer::<u32>(compressed, count).map_err(err)?.iter().flat_map(|x| x.to_le_bytes()).collect())
        }
        (Some("INDICES"), 2) => {
            Ok(meshopt::encoding::decode_index_sequence::<u16>(compressed, count).map_err(err)?.iter().flat_map(|x| x.to_le_bytes()).collect())
        }
        (Some("INDICES"), 4) => {
            Ok(meshopt::encoding::decode_index_sequence::<u32>(compressed, count).map_err(err)?.iter().flat_map(|x| x.to_le_bytes()).collect())
        }
        (mode, stride) => Err(format!("mode {mode:?} with byteStride {stride} is not decoded here")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn views_round_trip_through_the_codecs() {
        let data: Vec<u8> = (0..96u32).flat_map(|i| ((i * 7) as i16).to_le_bytes()).collect();
        for stride in [4, 8, 12] {
            let e = attributes(&data, stride);
            assert_eq!(e.count, data.len() / stride);
            assert_eq!(decode(&e.extension(0), &e.bytes).unwrap(), data);
        }
        let tris: Vec<u8> = [0u16, 1, 2, 2, 1, 3].iter().flat_map(|x| x.to_le_bytes()).collect();
        let e = indices(&tris, 2, 4, true);
        assert_eq!(e.mode, "TRIANGLES");
        assert_eq!(decode(&e.extension(0), &e.bytes).unwrap(), tris);
        let padded: Vec<u8> = [0u16, 1, 2, 0].iter().flat_map(|x| x.to_le_bytes()).collect();
        let e = indices(&padded, 2, 3, false);
        assert_eq!(e.mode, "INDICES");
        assert_eq!(decode(&e.extension(0), &e.bytes).unwrap(), padded);
    }
}
