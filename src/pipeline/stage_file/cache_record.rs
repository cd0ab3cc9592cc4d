//! The stage data of a cache scene: where the cache is, how it was opened, which frames are
//! the keys. The frames themselves are not copied into the stage files: the stages that need
//! them (the `fit` solve, the report's error) stream them again from the cache, after checking
//! that it is still the file `import` read.

use serde::{Deserialize, Serialize};

use super::VertexSet;
use crate::algorithms::frames::keyframes::SelectionStats;

/// A vertex cache as `import` opened it, and the keys it chose.
///
/// Invariants: `keys` are strictly increasing frame indices below `frames`, counted from the
/// range's first frame (`start`); `bytes` and `modified_ns` identify the cache's content.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CacheRecord {
    /// The cache path (an OBJ sequence's pattern), as `import` resolved it.
    pub path: String,
    /// `obj-sequence`, `pc2`, `mdd`, `gltf` or `usd`.
    pub format: String,
    /// Options passed to the reader (`[cache]`'s fps, rest mesh, animation, prim, range).
    pub options: CacheRecordOptions,
    /// Frames in the range.
    pub frames: usize,
    /// Vertices per frame.
    pub vertices: usize,
    /// Frames per second of the cache.
    pub fps: f64,
    /// Where the rate came from, for the report (e.g. "24 fps (from the file: ...)").
    pub fps_note: String,
    /// Bytes of the input (every file of a sequence, a glTF's buffers).
    pub bytes: u64,
    /// Modification time of the cache file in ns since the epoch (none for a sequence, whose
    /// frames are many files: its byte count and frame count identify it).
    pub modified_ns: Option<u64>,
    /// Diagonal of the box holding every vertex of every frame: errors are relative to it.
    pub diagonal: f64,
    /// The key frames (from `start`).
    pub keys: Vec<usize>,
    /// The `fixed` vertices, held on the cache frame at every key.
    pub fixed: VertexSet,
    /// The tolerance the keys were chosen for (`keyframes = "auto"`), else none.
    pub tolerance: Option<f64>,
    /// What the automatic selection did (`keyframes = "auto"`).
    pub selection: Option<SelectionStats>,
    /// The length unit the file states, in meters (glTF: 1; USD: its authored
    /// `metersPerUnit`), or none; the scene's `units` default to it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub meters_per_unit: Option<f64>,
    /// When vertices were welded (`[cache] weld`): per input vertex, its welded vertex; every
    /// later stage reads the cache through it, and `vertices` counts the welded ones.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub weld: Option<Vec<u32>>,
}

/// The reader options of a [`CacheRecord`], so a later stage opens the cache the same way.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CacheRecordOptions {
    /// The scene's `fps`.
    pub fps: Option<f64>,
    /// The topology mesh of a PC2 / MDD cache (resolved path).
    pub rest: Option<String>,
    /// The glTF animation.
    pub animation: Option<String>,
    /// The USD prim.
    pub prim: Option<String>,
    /// The Alembic or FBX object.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub object: Option<String>,
    /// The FBX take.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub take: Option<String>,
    /// Metres per unit an FBX file's lengths are converted to (the scene's units).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub meters_per_unit: Option<f64>,
    /// First frame of the range.
    pub start: i64,
    /// Last frame of the range.
    pub end: i64,
}
