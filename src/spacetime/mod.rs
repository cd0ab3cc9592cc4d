//! BlendSim's spacetime projective dynamics on Hermite trajectories.
//!
//! - [`trajectory`]: the cubic Hermite curves of every vertex;
//! - [`sampling`]: sample points of the residual, and the time slots of the unknowns;
//! - [`unknowns`]: free keyframe positions/velocities (masks eliminated, loops aliased);
//! - [`objective`]: W, its gradient, and the local step over all samples;
//! - [`global_step`]: the normal matrix, assembled and factorized once (refactorized when the
//!   key times move);
//! - [`solver`]: the local/global iteration;
//! - [`timing`]: W as a function of the key times, its exact derivatives, the timing step.

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
