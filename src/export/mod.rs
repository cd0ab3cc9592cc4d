//! Writers of the animation files, and the two forms they write.
//!
//! - [`clip`]: the blendshape form of a Hermite trajectory (base, targets, weight curves), in
//!   the signed form or the Bernstein form of `bernstein` (every weight in [0, 1]);
//! - [`fullframe`]: one pose per frame (what a vertex cache holds);
//! - [`usd`]: the USD layout as a [`layer::Layer`], which [`usda`] writes as text and [`usdc`]
//!   as a binary crate file; [`glb`]: the glTF file;
//! - [`texture`]: the material groups' diffuse textures they carry.
//!
//! The layouts are specified in `formats/usd.md` and `formats/gltf.md`; which files a scene
//! gets is decided by the export stage (`crate::stages::export`).

mod bernstein;
pub mod principal;
mod usd_attributes;
pub mod clip;
pub mod fullframe;
pub mod glb;
pub mod layer;
pub mod texture;
pub mod usd;
pub mod usda;
pub mod usdc;

/// Whether a target moving `moved` of `vertices` vertices is smaller stored sparse (an index of
/// `index_bytes` plus 12 bytes of offset per moved vertex) than dense (12 bytes per vertex).
/// With 4-byte indices (USD's `int[] pointIndices`) that is "moves fewer than 3/4".
pub(crate) fn sparse_is_smaller(moved: usize, vertices: usize, index_bytes: usize) -> bool {
    moved * (index_bytes + 12) < vertices * 12
}
