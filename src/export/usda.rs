//! USD ASCII writers (helper-owned). Layout in `formats/usd.md`.

use super::clip::BlendShapeClip;
use super::fullframe::FullFrame;

/// Stage-level settings shared by both USD files.
#[derive(Debug, Clone, PartialEq)]
pub struct UsdSettings {
    /// Prim-safe name of the asset (used for the SkelRoot / mesh names).
    pub name: String,
    pub fps: f64,
    /// "Y" or "Z".
    pub up_axis: char,
    pub meters_per_unit: f64,
}

/// UsdSkel blendshape animation: weights sampled at every frame of the clip's key range.
pub fn blendshapes(clip: &BlendShapeClip, triangles: &[[u32; 3]], settings: &UsdSettings) -> String {
    let _ = (clip, triangles, settings);
    todo!()
}

/// Full-frame animation: `points.timeSamples` at every frame.
pub fn full_frame(frames: &FullFrame, triangles: &[[u32; 3]], settings: &UsdSettings) -> String {
    let _ = (frames, triangles, settings);
    todo!()
}
