//! The `[export]` table: the files to write.

use std::fmt;

use serde::{Deserialize, Serialize};

use super::{invalid, Axis, Weights, METERS_PER_UNIT_RANGE};
use crate::support::error::{number, Result};

/// An output file format (`[export] formats`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Format {
    /// USD, text.
    Usda,
    /// USD, binary crate (converted by usd-core).
    Usdc,
    /// Binary glTF.
    Glb,
}

impl Format {
    /// The file extension.
    pub fn extension(self) -> &'static str {
        match self {
            Format::Usda => "usda",
            Format::Usdc => "usdc",
            Format::Glb => "glb",
        }
    }
}

impl fmt::Display for Format {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.extension())
    }
}

/// The `[export]` table (defaults: [`Export::default`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Export {
    /// The formats to write, each as blendshapes (and full-frame when `full_frame`).
    pub formats: Vec<Format>,
    /// Also write the full-frame versions (one pose per frame) for comparison.
    pub full_frame: bool,
    /// The scene's up axis, "y" or "z" (USD `upAxis`; glTF files are rotated to y-up).
    pub up_axis: Axis,
    /// Scene units in meters: the older alias of the scene's `units` ([`Scene::meters_per_unit`](super::Scene::meters_per_unit)).
    pub meters_per_unit: f64,
    /// The blendshape form of the trajectory in every blendshape file.
    pub weights: Weights,
    /// How the blendshape glTF animates its weights.
    pub gltf_interpolation: GltfInterpolation,
    /// How every glb stores its data: quantized (default), quantized + meshopt, or f32.
    pub gltf_compression: crate::formats::export::glb::Compression,
    /// Give the blendshape glTF's morph targets NORMAL deltas (each target's recomputed
    /// normals minus the base's), for renderers that shade a morphed mesh with the file's
    /// normals (three.js, engines); Blender recomputes them. Off by default: it adds about as
    /// many bytes as the POSITION targets (README, "Animated normals").
    pub gltf_morph_normals: bool,
    /// The shapes of the blendshape files (`None`: [`Export::basis_for`] decides by the input).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub basis: Option<Basis>,
    /// For `basis = "principal"`: the number of components (`None`: the smallest meeting the
    /// tolerance, see `formats/scene.md`). Positive.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rank: Option<usize>,
}

/// The shapes of the blendshape files (`[export] basis`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Basis {
    /// A shape per key pose and per key velocity or control point (sparse): editable per key.
    #[default]
    Keys,
    /// A few principal components of those shapes (dense), chosen to meet the tolerance: the
    /// smallest files of long motions. The default for a `[cache]` scene.
    Principal,
}

/// The interpolation of the blendshape glTF's weight animation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum GltfInterpolation {
    /// Weights and their slopes at the keys: the trajectory exactly, at any instant.
    Cubicspline,
    /// Weights sampled at every frame: exact at frames, linear in between (Blender plays it).
    Linear,
}

impl Default for Export {
    fn default() -> Self {
        Export {
            formats: vec![Format::Usda, Format::Glb],
            full_frame: true,
            up_axis: Axis::Y,
            meters_per_unit: 1.0,
            weights: Weights::Bernstein,
            gltf_interpolation: GltfInterpolation::Linear,
            gltf_compression: Default::default(),
            gltf_morph_normals: false,
            basis: None,
            rank: None,
        }
    }
}

impl Export {
    pub(super) fn validate(&self) -> Result<()> {
        if self.up_axis == Axis::X {
            return invalid("[export] up_axis = \"x\"".into(), "USD and glTF support \"y\" or \"z\" up");
        }
        let (min, max) = METERS_PER_UNIT_RANGE;
        if !(self.meters_per_unit.is_finite() && self.meters_per_unit > 0.0) {
            return invalid(
                format!("[export] meters_per_unit = {} must be positive", number(self.meters_per_unit)),
                "use 1.0 for meters, 0.01 for centimeters",
            );
        }
        if !(min..=max).contains(&self.meters_per_unit) {
            return invalid(
                format!("[export] meters_per_unit = {} is out of range ({} to {})", number(self.meters_per_unit), number(min), number(max)),
                "give the length of one unit in metres: 1.0 for metres, 0.01 for centimetres, 0.001 for millimetres",
            );
        }
        if self.formats.is_empty() {
            return invalid("[export] formats is empty".into(), "list at least one of \"usda\", \"usdc\", \"glb\"");
        }
        match (self.rank, self.basis) {
            (Some(0), _) => return invalid("[export] rank = 0".into(), "give at least 1 component, or remove rank to choose it by the tolerance"),
            (Some(r), Some(Basis::Keys)) => {
                return invalid(
                    format!("[export] rank = {r} is given, but basis = \"keys\" has no rank"),
                    "remove rank, or set basis = \"principal\"",
                );
            }
            _ => {}
        }
        Ok(())
    }

    /// The basis of the blendshape files: as given, else `principal` when `cache_fit` (the
    /// least-squares fit of a cache: measured 3-6x smaller files than `keys` at the same
    /// tolerance on the rapier bars, README) or a `rank` is given, and `keys` otherwise
    /// (keyframe scenes, and simulated caches, whose keys stay exact and editable).
    pub fn basis_for(&self, cache_fit: bool) -> Basis {
        self.basis.unwrap_or(if cache_fit || self.rank.is_some() { Basis::Principal } else { Basis::Keys })
    }
}
