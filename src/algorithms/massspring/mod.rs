//! Mass-spring blendshapes (Ma, Wang, Fyffe, Chen, Debevec 2012, "A blendshape model that
//! incorporates physical interaction"): blend the rest lengths of a spring network built on
//! the targets, not the positions, and take the network's equilibrium as the blended shape.
//! Large rotations between targets then keep lengths and volume where a linear blend shrinks,
//! and obstacles push the shape aside.
//!
//! - [`springs`]: the network (structure, bending, internal and anchor springs);
//! - [`energy`]: spring energy, gradient and exact stiffness blocks;
//! - [`newton`]: the equilibrium by Newton's method on a reused symbolic factorization;
//! - [`rigid`]: best-fit rigid motions and quaternion interpolation for the anchor;
//! - [`anchor`]: the default anchor and its attachment;
//! - [`obstacle`]: planes and spheres;
//! - [`refine`]: splitting long surface edges before the springs are built;
//! - [`blend`]: the model: targets in, blended shapes (with diagnostics) out;
//! - [`inbetween`](mod@inbetween): in-between shapes on every keyframe interval, as keys of a
//!   node trajectory (`[solver] method = "mass-spring"`).
//!
//! The module takes plain inputs (points, triangles, an optional tet mesh, index lists) and
//! its own settings; it knows nothing of scene or stage files.
//!
//! ```no_run
//! use blendsim::algorithms::massspring::{Boundary, MassSpring, Settings, Targets};
//! # fn shapes() -> (Vec<Vec<[f64; 3]>>, Vec<[u32; 3]>) { unimplemented!() }
//! let (surface, triangles) = shapes();
//! let targets = Targets { surface: &surface, triangles: &triangles, body: None, body_poses: None };
//! let mut model = MassSpring::new(&targets, &Boundary::Anchor(None), &Settings::default())?;
//! let shape = model.blend(&[0.5, 0.5], &[])?;
//! println!("{} vertices, {} Newton iterations", shape.surface().len(), shape.report.iterations);
//! # Ok::<(), blendsim::Error>(())
//! ```

pub mod anchor;
pub mod blend;
pub mod energy;
pub mod inbetween;
pub mod newton;
pub mod obstacle;
pub mod refine;
pub mod rigid;
pub mod springs;

#[cfg(test)]
pub(crate) mod testing;
#[cfg(test)]
mod tests;

pub use blend::{check_weights, linear_blend, Blend, Boundary, MassSpring, Settings, Targets};
pub use inbetween::{inbetween, Inbetweens};
pub use obstacle::Obstacle;
pub use springs::Bending;
