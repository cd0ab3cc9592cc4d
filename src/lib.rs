//! # blendsim
//!
//! Keyframe meshes in, compact physically plausible blendshape animation out (USD, glTF),
//! with a report of how much smaller and how faithful it is than the full-frame version.
//!
//! The method is BlendSim (Wu & Umetani, Eurographics 2025): spacetime projective dynamics on
//! cubic Hermite trajectories. The library is a chain of stages, each a function from one
//! plain data type (see [`stage`]) to the next; the `blendsim` binary is a thin CLI over it.
//!
//! ```text
//! import -> tetrahedralize -> solve -> embed -> export -> report
//! ```

// Numeric kernels index several arrays (and SIMD lanes) in lockstep on purpose.
#![allow(clippy::needless_range_loop)]

pub mod cache;
pub mod embed;
pub mod error;
pub mod export;
pub mod import;
pub mod massspring;
pub mod mesh;
pub mod output;
pub mod physics;
pub mod procedural;
pub mod progress;
pub mod report;
pub mod scene;
pub mod solve;
pub mod spacetime;
pub mod stage;
pub mod tetgen;
pub mod tetrahedralize;

pub use error::{Error, Result};
