//! # blendsim
//!
//! Keyframe meshes in, compact physically plausible blendshape animation out (USD, glTF),
//! with a report of how much smaller and how faithful it is than the full-frame version.
//!
//! The method is BlendSim (Wu & Umetani, Eurographics 2025): spacetime projective dynamics on
//! cubic Hermite trajectories. The library is a chain of stages ([`stages`]), each a function
//! from one plain data type ([`stage`]) to the next; the `blendsim` binary is a thin CLI over
//! it, and [`stages::bake()`] runs the whole chain:
//!
//! ```text
//! scene -> import -> tetrahedralize -> solve -> embed -> export -> report
//! ```
//!
//! ```no_run
//! use blendsim::output::Staging;
//! use blendsim::progress::Progress;
//! use blendsim::scene::SceneFile;
//!
//! # fn main() -> blendsim::Result<()> {
//! let scene = SceneFile::load("scene.toml".as_ref())?;
//! let mut staging = Staging::new("build/scene".as_ref())?;
//! let report = blendsim::stages::bake(&scene, None, &mut staging, &Progress::hidden())?;
//! staging.commit()?;
//! println!("usdc smaller by {:?}", report.ratios);
//! # Ok(())
//! # }
//! ```
//!
//! The public surface: the stages and their data ([`stages`], [`scene`], [`stage`],
//! [`report`]), the meshes and their files ([`mesh`], [`procedural`] shapes), the trajectory the
//! stage files carry ([`Trajectory`]) and the blendshape clip the files hold ([`clip`]), vertex
//! caches ([`cache`]), output staging ([`output`]), clean interruption ([`interrupt`]),
//! progress ([`progress`]) and errors ([`Error`]). The algorithms (physics, the spacetime
//! solver, TetGen, the binding, the writers) are internal: they take plain inputs and know
//! neither the scene file nor the stage files.

#![warn(missing_docs)]
// Numeric kernels index several arrays (and SIMD lanes) in lockstep on purpose.
#![allow(clippy::needless_range_loop)]

pub mod cache;
pub mod interrupt;
pub mod mesh;
pub mod output;
pub mod procedural;
pub mod progress;
pub mod report;
pub mod resources;
pub mod scene;
pub mod stage;
pub mod stages;

mod cage;
mod embed;
mod error;
mod export;
#[cfg(test)]
mod fuzz;
#[cfg(test)]
mod fuzz_stages;
mod input;
mod massspring;
mod physics;
mod spacetime;
mod tetgen;

#[doc(hidden)]
pub mod internals;
#[cfg(test)]
mod testing;

pub use error::{Error, Result};
pub use export::clip;
pub use spacetime::trajectory::Trajectory;
