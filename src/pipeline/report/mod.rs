//! The report of a bake: file sizes side by side, fidelity of the blendshape animation against
//! the full-frame evaluation, deviation from the input keyframes, volume, and the solver's
//! history. Written as `report.json` (specified in `formats/report.md`), `report.md` and
//! `report.html`: one model, three renderers.
//!
//! - this file: the model and its JSON form, and writing the files;
//! - [`measures`]: how the numbers are measured; [`series`]: the per-frame series;
//! - [`markdown`]: the table a person reads; [`html`]: the page with [`plot`]s and a [`player`].
//!
//! The `report` stage (`crate::pipeline::stages::report`) fills the model from an animation and its files.

pub mod batch;
pub mod cache_fit;
pub mod guard_rails;
pub mod html;
pub mod markdown;
pub mod measures;
pub mod player;
pub mod plot;
pub mod series;

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::pipeline::scene::{Basis, Format};
use crate::pipeline::stage_file::{CageInfo, OutputFile, SolverLog};
use crate::support::error::Result;
use crate::support::output::Staging;

/// The files [`Report::write`] stages.
pub(crate) const FILES: [&str; 3] = ["report.json", "report.md", "report.html"];

/// Distances between two animations, relative to the rest bounding-box diagonal.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Deviation {
    /// Largest distance.
    pub max: f64,
    /// Root mean square of the distances.
    pub rms: f64,
    /// What the distances are relative to (`bbox_diagonal`: of the rest surface).
    pub relative_to: String,
    /// How many poses were compared.
    pub samples: usize,
}

/// Enclosed volume over the frames of one animation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct VolumeRange {
    /// Smallest volume, as a ratio to the rest volume.
    pub min: f64,
    /// Largest volume, as a ratio to the rest volume.
    pub max: f64,
    /// In-between volume loss: the largest `1 - V(t) / V̄(t)` over frames, where `V̄` blends
    /// this animation's own keyframe volumes linearly in time. It measures what the
    /// interpolation loses between keys, whatever volume the keys themselves have; zero when
    /// no in-between dips below its keys.
    pub in_between_loss: f64,
}

/// Enclosed volume of the animation and of the hermite baseline.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Volume {
    /// Volume enclosed by the surface in the rest pose.
    pub rest: f64,
    /// The exported animation.
    pub animation: VolumeRange,
    /// The hermite baseline (input keyframes, zero velocities), for comparison.
    pub hermite: VolumeRange,
}

/// The report of one bake (`report.json`, see `formats/report.md`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Report {
    /// The scene's name.
    pub scene: String,
    /// Vertices of the exported surface.
    pub vertices: usize,
    /// Vertices of the input when welding merged some (`[keyframes] weld`, `[cache] weld`):
    /// `vertices` counts the welded ones, the files' points.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub input_vertices: Option<usize>,
    /// Triangles of the exported surface.
    pub faces: usize,
    /// Nodes of the simulated body.
    pub tet_nodes: usize,
    /// Tets of the simulated body.
    pub tets: usize,
    /// Keyframes.
    pub keyframes: usize,
    /// The largest tet's rest volume, and `[tet] max_volume` when it bounds TetGen: TetGen
    /// keeping the surface (`-Y`) cannot split tets whose corners all lie on it, so the bound is
    /// not always met (the demo: 161 of 777 tets over 0.005, the largest 0.0123).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub largest_tet_volume: Option<f64>,
    /// See `largest_tet_volume`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_volume: Option<f64>,
    /// Seconds from the first key to the last.
    pub duration_s: f64,
    /// Frame rate of the full-frame files and USD weights.
    pub fps: f64,
    /// Frames in the key range.
    pub frames: usize,
    /// What the solver did.
    pub solver: SolverLog,
    /// The files written.
    pub outputs: Vec<OutputFile>,
    /// Per format: full-frame bytes / blendshape bytes, the two files written in the same format
    /// (and compression): the fair ratio. For a cache bake the full-frame files are the cache
    /// itself, frame for frame.
    pub ratios: BTreeMap<Format, f64>,
    /// Bytes of the input as given: the keyframe files (each file once), or the cache (0 in
    /// reports of stage files that did not record it).
    #[serde(default)]
    pub input_bytes: u64,
    /// Per format: `input_bytes` / blendshape bytes.
    #[serde(default)]
    pub input_ratios: BTreeMap<Format, f64>,
    /// Bytes of the full-frame version of the input: for a cache bake, the cache itself; for
    /// keyframes, the animation at every frame as a plain f32 vertex cache (PC2: 32 + 12 x
    /// vertices x frames bytes).
    #[serde(default)]
    pub full_frame_input_bytes: u64,
    /// Per format: `full_frame_input_bytes` / blendshape bytes.
    #[serde(default)]
    pub full_frame_input_ratios: BTreeMap<Format, f64>,
    /// The blendshape animation (as stored: f32 shapes, f32 weights at every frame) against the
    /// full-frame evaluation of the trajectory at every frame.
    pub error: Deviation,
    /// The exported animation at key times against the input keyframes (free vertices move).
    pub keyframe_deviation: Deviation,
    /// Present when the surface is closed.
    pub volume: Option<Volume>,
    /// A cache bake: the cache, sizes against it, and the error against its frames.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cache: Option<cache_fit::CacheReport>,
    /// Present when the surface was simulated on a generated cage: why, its size, and how
    /// closely the embedded cage keys reproduce the input keyframes.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cage: Option<CageInfo>,
    /// The shapes of the blendshape files (`[export] basis`, resolved; reports written before
    /// it existed had `keys`).
    #[serde(default)]
    pub basis: Basis,
    /// For the principal basis: the components the files hold.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rank: Option<usize>,
    /// What the bake warned about on stderr (one line each, starting with its code: see
    /// [`guard_rails`]): a key with inverted or flattened tets, a `[tet] max_volume` TetGen
    /// could not honour, and the guard rails (not converged, keys moved, volume out of band,
    /// times that look like frames, an output larger than what it replaces).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub warnings: Vec<String>,
    /// The per-frame and per-iteration series the plots draw (absent in reports written before
    /// it existed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub series: Option<series::Series>,
    /// The player's data: in `report.html` only, not in `report.json` (too big for it).
    #[serde(skip)]
    pub player: Option<player::Player>,
}

impl Report {
    /// `report.json`: pretty-printed, with a final newline.
    pub fn to_json(&self) -> Vec<u8> {
        let mut bytes = serde_json::to_vec_pretty(self).expect("the report serializes");
        bytes.push(b'\n');
        bytes
    }

    /// Stage `report.json`, `report.md` and `report.html`, in the staging group `report` (a
    /// commit replaces the report an earlier run wrote, and keeps an export's files beside it).
    pub fn write(&self, staging: &mut Staging) -> Result<()> {
        let [json, md, html] = FILES;
        staging.set_group("report");
        staging.write(json, &self.to_json())?;
        staging.write(md, markdown::render(self).as_bytes())?;
        staging.write(html, html::render(self).as_bytes())
    }
}
