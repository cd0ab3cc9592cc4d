//! # blendsim
//!
//! Keyframe meshes in, compact physically plausible blendshape animation out (USD, glTF),
//! with a report of how much smaller and how faithful it is than the full-frame version.
//!
//! The method is BlendSim (Wu & Umetani, Eurographics 2025): spacetime projective dynamics on
//! cubic Hermite trajectories. The library is a chain of stages ([`pipeline::stages`]), each a
//! function from one plain data type ([`pipeline::stage_file`]) to the next; the `blendsim`
//! binary is a thin CLI over it, and [`pipeline::stages::bake()`] runs the whole chain:
//!
//! ```text
//! scene -> import -> tetrahedralize -> solve -> embed -> export -> report
//! ```
//!
//! ```no_run
//! use blendsim::support::output::Staging;
//! use blendsim::support::progress::Progress;
//! use blendsim::pipeline::scene::SceneFile;
//!
//! # fn main() -> blendsim::Result<()> {
//! let scene = SceneFile::load("scene.toml".as_ref())?;
//! let mut staging = Staging::new("build/scene".as_ref())?;
//! let report = blendsim::pipeline::stages::bake(&scene, None, &mut staging, &Progress::hidden())?;
//! staging.commit()?;
//! println!("usdc smaller by {:?}", report.ratios);
//! # Ok(())
//! # }
//! ```
//!
//! ## Layers
//!
//! Four layers, each using only those below it (a test, `tests/integration/layers.rs`, fails
//! on an import that points up):
//!
//! ```text
//! pipeline    scene file, stage data, stages, bake, report      (the CLI sits on top)
//! formats     mesh and cache readers, USD and glTF writers, the TetGen process
//! algorithms  geometry, physics, spacetime solver, mass-spring, cage, binding, fits
//! support     errors, output folder, interruption, progress, budgets
//! ```
//!
//! - [`pipeline`]: what a bake is made of, in the terms of the scene file;
//! - [`formats`]: files in and out, one module per format, each specified in `formats/`;
//! - [`algorithms`]: plain arrays and mesh types in and out, never a file or a scene;
//! - [`support`]: errors ([`Error`]), the output folder, interruption, progress, budgets.

pub mod algorithms;
pub mod formats;
pub mod pipeline;
pub mod support;

pub use support::error::{Error, Result};
