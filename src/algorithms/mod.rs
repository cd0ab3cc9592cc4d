//! The algorithms layer: geometry, physics, the spacetime solver, the mass-spring blend, the
//! cage and the binding, the Hermite fit of frame sequences, the blendshape forms.
//!
//! Plain arrays and mesh types in and out: nothing here reads or writes a file, or knows the
//! scene or the stage files (those are [`crate::formats`] and [`crate::pipeline`], above).

pub mod blendshape;
pub mod cage;
pub mod embed;
pub mod frames;
pub mod geometry;
pub mod massspring;
pub mod physics;
pub mod procedural;
pub mod spacetime;
#[cfg(test)]
pub(crate) mod testing;
