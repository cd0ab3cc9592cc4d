//! Writers of the animation files. The two forms they write, the blendshape clip and the
//! full-frame poses, are computed in [`crate::algorithms::blendshape`].
//!
//! - [`usd`]: the USD layout as a [`layer::Layer`], which [`usda`] writes as text and [`usdc`]
//!   as a binary crate file; [`glb`]: the glTF file;
//! - [`texture`]: the material groups' diffuse textures they carry.
//!
//! The layouts are specified in `formats/usd.md` and `formats/gltf.md`; which files a scene
//! gets is decided by the export stage (`crate::pipeline::stages::export`).

mod float_text;
pub mod glb;
pub mod layer;
pub mod texture;
pub mod usd;
mod usd_attributes;
pub mod usda;
pub mod usdc;
pub mod weld_map;

/// Whether a target moving `moved` of `vertices` vertices is smaller stored sparse (an index of
/// `index_bytes` plus 12 bytes of offset per moved vertex) than dense (12 bytes per vertex).
/// With 4-byte indices (USD's `int[] pointIndices`) that is "moves fewer than 3/4".
pub(crate) fn sparse_is_smaller(moved: usize, vertices: usize, index_bytes: usize) -> bool {
    moved * (index_bytes + 12) < vertices * 12
}
