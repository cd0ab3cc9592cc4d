//! The two forms an animation is written in, computed from a Hermite trajectory.
//!
//! - [`clip`]: the blendshape form (base, targets, weight curves), in the signed form or the
//!   Bernstein form of `bernstein` (every weight in [0, 1]);
//! - [`principal`]: the principal components of the key offsets, for a smaller basis;
//! - [`fullframe`]: one pose per frame (what a vertex cache holds).
//!
//! The writers of [`crate::formats::export`] write them.

mod bernstein;
pub mod clip;
pub mod fullframe;
pub mod principal;
