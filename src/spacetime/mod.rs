//! BlendSim's spacetime projective dynamics on Hermite trajectories.
//!
//! - [`trajectory`]: the cubic Hermite curves of every vertex;
//! - [`sampling`]: sample points of the residual, and the time slots of the unknowns;
//! - [`unknowns`]: the keyframe constraints ([`unknowns::KeyConstraints`]) and the free keyframe
//!   positions/velocities they leave (masks eliminated, loops aliased);
//! - [`objective`]: W, its gradient, and the local step over all samples;
//! - [`global_step`]: the normal matrix, assembled and factorized once (refactorized on the
//!   kept symbolic analysis when the key times move);
//! - [`quasi_newton`]: L-BFGS preconditioned by the global step;
//! - [`solver`]: the two phases of the iteration (local/global, then quasi-Newton);
//! - [`timing`]: W as a function of the key times, its exact derivatives, the timing step.
//!
//! Inputs are plain: an [`Elastic`](crate::physics::elastic::Elastic) body, the key
//! constraints and the solver [`Settings`](solver::Settings); the result is the trajectory and
//! the solver's own [`Log`](solver::Log). The stage layer translates the scene and stage files.

pub mod global_step;
pub mod objective;
pub mod quasi_newton;
pub mod sampling;
pub mod solver;
pub mod timing;
pub mod trajectory;
pub mod unknowns;

#[cfg(test)]
mod tests;
