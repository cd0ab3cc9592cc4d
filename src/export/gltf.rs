//! Binary glTF writers (helper-owned). Layout in `formats/gltf.md`.

use super::clip::BlendShapeClip;
use super::fullframe::FullFrame;

/// Morph targets + CUBICSPLINE weight animation reproducing the Hermite trajectory exactly.
pub fn blendshapes(clip: &BlendShapeClip, triangles: &[[u32; 3]], name: &str) -> Vec<u8> {
    let _ = (clip, triangles, name);
    todo!()
}

/// One morph target per frame with one-hot LINEAR weights.
pub fn full_frame(frames: &FullFrame, triangles: &[[u32; 3]], name: &str) -> Vec<u8> {
    let _ = (frames, triangles, name);
    todo!()
}
