//! The error a written glb plays with, measured on its bytes: the file is read back by the glTF
//! clip reader (`crate::formats::cache::gltf_clip`, which dequantizes accessors and applies the
//! node transform as any client does), meshopt views decoded first, and its played points are
//! compared with what the writer was given. Nothing of the writer's internal arrays is used.

use serde_json::Value;

use super::{glb, meshopt, Placement};
use crate::algorithms::geometry::Point;
use crate::formats::cache::gltf_clip;
use crate::formats::work_dir::WorkDir;
use crate::support::error::{Error, Result};

const EXT: &str = "EXT_meshopt_compression";

/// The JSON and BIN chunks of a GLB (the writer's own layout: JSON first, then BIN).
pub(crate) fn chunks(bytes: &[u8]) -> Option<(Value, &[u8])> {
    let u32_at = |i: usize| bytes.get(i..i + 4).map(|b| u32::from_le_bytes(b.try_into().expect("4 bytes")) as usize);
    let json_len = u32_at(12)?;
    let json = serde_json::from_slice(bytes.get(20..20 + json_len)?).ok()?;
    let at = 20 + json_len;
    let bin = match u32_at(at) {
        Some(len) => bytes.get(at + 8..at + 8 + len)?,
        None => &[],
    };
    Some((json, bin))
}

/// A meshopt glb as the same glb without the extension: every compressed view decoded into
/// one buffer at its fallback offsets, the other views' bytes appended after them.
pub(crate) fn decode_meshopt(bytes: &[u8]) -> std::result::Result<Vec<u8>, String> {
    let (mut json, bin) = chunks(bytes).ok_or("not a GLB")?;
    let fallback = json["buffers"][1]["byteLength"].as_u64().ok_or("no fallback buffer")? as usize;
    let mut data = vec![0u8; fallback];
    for view in json["bufferViews"].as_array_mut().ok_or("no buffer views")? {
        let offset = view["byteOffset"].as_u64().unwrap_or(0) as usize;
        let length = view["byteLength"].as_u64().ok_or("a view without byteLength")? as usize;
        match view.get_mut("extensions").and_then(|e| e.as_object_mut()).and_then(|e| e.remove(EXT)) {
            Some(e) => {
                let at = e["byteOffset"].as_u64().unwrap_or(0) as usize;
                let len = e["byteLength"].as_u64().ok_or("an extension without byteLength")? as usize;
                let decoded = meshopt::decode(&e, bin.get(at..at + len).ok_or("compressed bytes beyond the buffer")?)?;
                data.get_mut(offset..offset + length)
                    .ok_or("a view beyond the fallback buffer")?
                    .copy_from_slice(decoded.get(..length).ok_or("decoded short")?);
                view.as_object_mut().expect("a view is an object").remove("extensions");
            }
            None => {
                let own = bin.get(offset..offset + length).ok_or("a view beyond the buffer")?;
                data.resize(data.len().next_multiple_of(4), 0);
                view["byteOffset"] = data.len().into();
                data.extend_from_slice(own);
            }
        }
        view["buffer"] = 0.into();
    }
    json["buffers"] = serde_json::json!([{ "byteLength": data.len() }]);
    for list in ["extensionsUsed", "extensionsRequired"] {
        if let Some(a) = json[list].as_array_mut() {
            a.retain(|e| e != EXT);
        }
    }
    Ok(glb(&serde_json::to_vec(&json).expect("JSON serializes"), &data))
}

/// A glb that was just written cannot be read back: the writer's fault, not the user's.
fn readback_failed(problem: String) -> Error {
    Error::general(format!("cannot read back the glb just written: {problem}"), "report it as a bug of blendsim's glTF writer")
}

/// Whether a glb's JSON has an animation to play back (`None`: nothing to measure), and if so
/// whether its views are meshopt compressed (decoded in memory before the clip reader reads).
fn animated_and_compressed(json: &Value) -> Option<bool> {
    if json["animations"].as_array().is_none_or(Vec::is_empty) {
        return None;
    }
    Some(json["extensionsRequired"].as_array().is_some_and(|a| a.iter().any(|e| e == EXT)))
}

/// The largest distance, over `times` (frames at `fps`), between the points the glb `bytes` plays (read back by
/// the clip reader, in glTF's y-up meters) and `expected(t)` placed the same way, relative to
/// `diagonal` (scene units). Only the first `expected(t).len()` vertices are compared (seam
/// copies follow them and show the same points). `None` for a file with no animation.
pub(crate) fn played_error(
    bytes: &[u8],
    (times, fps): (&[f64], f64),
    expected: &dyn Fn(f64) -> Vec<Point>,
    placement: Placement,
    diagonal: f64,
) -> Result<Option<f64>> {
    let (json, _) = chunks(bytes).ok_or_else(|| readback_failed("not a GLB".into()))?;
    let Some(compressed) = animated_and_compressed(&json) else { return Ok(None) };
    let decoded;
    let bytes = if compressed {
        decoded = decode_meshopt(bytes).map_err(readback_failed)?;
        &decoded[..]
    } else {
        bytes
    };
    // A private folder like the external readers': removed on a signal too, and by the next
    // run after a kill.
    let dir = WorkDir::create("readback").map_err(|e| readback_failed(format!("a private folder for the read-back: {e}")))?;
    let path = dir.path.join("readback.glb");
    std::fs::write(&path, bytes).map_err(|e| readback_failed(format!("{}: {e}", path.display())))?;
    played_error_at(&path, (times, fps), expected, placement, diagonal)
}

/// `played_error` of the glb file at `path` (the staged file, written as it was made): read in
/// place, as the clip reader streams it, unless its views are meshopt compressed (then read
/// and decoded in memory, as `played_error` does).
pub fn played_error_of_file(
    path: &std::path::Path,
    (times, fps): (&[f64], f64),
    expected: &dyn Fn(f64) -> Vec<Point>,
    placement: Placement,
    diagonal: f64,
) -> Result<Option<f64>> {
    use std::io::Read;
    let io = |e: std::io::Error| readback_failed(format!("{}: {e}", path.display()));
    let mut file = std::fs::File::open(path).map_err(io)?;
    let mut header = [0u8; 20];
    file.read_exact(&mut header).map_err(io)?;
    let mut json = vec![0u8; u32::from_le_bytes(header[12..16].try_into().expect("4 bytes")) as usize];
    file.read_exact(&mut json).map_err(io)?;
    drop(file);
    let json: Value = serde_json::from_slice(&json).map_err(|e| readback_failed(format!("not a GLB: {e}")))?;
    match animated_and_compressed(&json) {
        None => Ok(None),
        Some(true) => played_error(&std::fs::read(path).map_err(io)?, (times, fps), expected, placement, diagonal),
        Some(false) => played_error_at(path, (times, fps), expected, placement, diagonal),
    }
}

/// The played error of the uncompressed glb file at `path`.
fn played_error_at(
    path: &std::path::Path,
    (times, fps): (&[f64], f64),
    expected: &dyn Fn(f64) -> Vec<Point>,
    placement: Placement,
    diagonal: f64,
) -> Result<Option<f64>> {
    // The rate given: CUBICSPLINE keys need not be evenly spaced.
    let mut clip = gltf_clip::open(path, None, Some(fps))?;
    let mut got = clip.mesh.positions.clone();
    let m = placement.meters_per_unit;
    let mut worst = 0.0f64;
    for &t in times {
        clip.frames.pose(t, &mut got)?;
        for (g, p) in got.iter().zip(expected(t)) {
            let want = placement.place(p).map(|x| m * x);
            let d = ((g[0] - want[0]).powi(2) + (g[1] - want[1]).powi(2) + (g[2] - want[2]).powi(2)).sqrt();
            worst = worst.max(d / m);
        }
    }
    Ok(Some(worst / diagonal))
}
