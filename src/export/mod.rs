//! Writers of the animation files (helper-owned, except `clip`).
//!
//! Contract of [`export`]: build the [`clip::BlendShapeClip`] (blendshapes) and the
//! [`fullframe::FullFrame`] (one pose per frame) from the animation, and stage, for each
//! format in `scene.export.formats`, `NAME.EXT` (blendshapes) and, when `full_frame`,
//! `NAME.full.EXT` (full-frame). `usdc` is converted from the staged `.usda` by usd-core.
//! Returns the list of staged files with their sizes.

pub mod clip;
pub mod fullframe;
pub mod gltf;
pub mod usda;
pub mod usdc;

use crate::error::Result;
use crate::output::Staging;
use crate::stage::{Animation, Outputs};

pub fn export(animation: &Animation, staging: &mut Staging) -> Result<Outputs> {
    let _ = (animation, staging);
    todo!("export::export")
}
