//! The report of a cache bake: the input cache, its size beside the files written, and the
//! distance of the animation from every cache frame (and, for the simulated methods, of the
//! least-squares fit on the same keys, for comparison).

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::algorithms::frames::deviation::CacheDeviation;
use crate::pipeline::scene::Format;
use crate::pipeline::stage_file::{OutputFile, OutputKind};

/// `report.json` `cache`: the input cache and what the animation made of it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CacheReport {
    /// The cache path (an OBJ sequence's pattern).
    pub path: String,
    /// `obj-sequence`, `pc2`, `mdd`, `gltf` or `usd`.
    pub format: String,
    /// Frames in the range.
    pub frames: usize,
    /// Frames per second of the cache.
    pub fps: f64,
    /// Where the rate came from.
    pub fps_source: String,
    /// Bytes of the input cache.
    pub bytes: u64,
    /// Vertices of the input cache.
    #[serde(default)]
    pub input_vertices: usize,
    /// Vertices after welding those equal at every frame (`[cache] weld`): the files' vertices.
    #[serde(default)]
    pub vertices: usize,
    /// The key frames (counted from the range's first frame).
    pub keys: Vec<usize>,
    /// The tolerance of `keyframes = "auto"`, else none.
    pub tolerance: Option<f64>,
    /// Per format: cache bytes / blendshape bytes.
    pub ratios: BTreeMap<Format, f64>,
    /// The animation against the cache.
    pub error: CacheError,
    /// The least-squares fit on the same keys and constraints against the cache (methods other
    /// than `fit`), for comparison.
    pub fit_error: Option<CacheError>,
}

/// Distances from every cache frame, relative to the cache's bounding-box diagonal (over all
/// its frames).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CacheError {
    /// Largest vertex distance over every frame.
    pub max: f64,
    /// Root mean square over every frame and vertex.
    pub rms: f64,
    /// `bbox_diagonal`: of every vertex of every cache frame.
    pub relative_to: String,
    /// `cache`: the distances are from the cache's frames.
    pub reference: String,
    /// The diagonal, in scene units.
    pub diagonal: f64,
    /// Per frame, the largest vertex distance.
    pub per_frame: Vec<f64>,
    /// Per frame, the root mean square vertex distance.
    pub per_frame_rms: Vec<f64>,
}

impl From<CacheDeviation> for CacheError {
    fn from(d: CacheDeviation) -> CacheError {
        CacheError {
            max: d.max,
            rms: d.rms,
            relative_to: "bbox_diagonal".into(),
            reference: "cache".into(),
            diagonal: d.diagonal,
            per_frame: d.per_frame_max,
            per_frame_rms: d.per_frame_rms,
        }
    }
}

/// Per format: `cache_bytes` / the blendshape file's bytes.
pub(crate) fn cache_ratios(cache_bytes: u64, outputs: &[OutputFile]) -> BTreeMap<Format, f64> {
    outputs.iter().filter(|f| f.kind == OutputKind::Blendshape && f.bytes > 0).map(|f| (f.format, cache_bytes as f64 / f.bytes as f64)).collect()
}

/// The report.md lines of a cache bake: the error and the sizes side by side.
pub fn markdown(c: &CacheReport, outputs: &[OutputFile]) -> String {
    let mut s = String::new();
    s.push_str(&format!(
        "\n## Cache\n\n{} ({}, {} frames at {}; {} bytes; {} vertices{}). Keys: {} frames {:?}{}.\n\n",
        c.path,
        c.format,
        c.frames,
        c.fps_source,
        c.bytes,
        c.input_vertices,
        if c.vertices != c.input_vertices { format!(", {} once welded", c.vertices) } else { String::new() },
        c.keys.len(),
        c.keys,
        c.tolerance.map(|t| format!(", chosen for a tolerance of {t}")).unwrap_or_default()
    ));
    s.push_str("| against the cache | max | rms |\n|---|---:|---:|\n");
    s.push_str(&format!("| this animation | {:.3e} | {:.3e} |\n", c.error.max, c.error.rms));
    if let Some(f) = &c.fit_error {
        s.push_str(&format!("| least-squares fit, same keys | {:.3e} | {:.3e} |\n", f.max, f.rms));
    }
    s.push_str("\n(relative to the diagonal of the cache's bounding box over all frames)\n\n");
    s.push_str("| file | format | bytes | cache / file |\n|---|---|---:|---:|\n");
    s.push_str(&format!("| input cache | {} | {} | 1.0 |\n", c.format, c.bytes));
    for kind in [OutputKind::FullFrame, OutputKind::Blendshape] {
        for f in outputs.iter().filter(|f| f.kind == kind) {
            let ratio = if f.bytes > 0 { format!("{:.1}", c.bytes as f64 / f.bytes as f64) } else { "n/a".into() };
            s.push_str(&format!("| {} | {} | {} | {ratio} |\n", f.path, f.format, f.bytes));
        }
    }
    s
}
