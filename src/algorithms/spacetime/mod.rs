//! BlendSim's spacetime projective dynamics on Hermite trajectories.
//!
//! - [`trajectory`]: the cubic Hermite curves of every vertex;
//! - [`sampling`]: sample points of the residual, and the time slots of the unknowns;
//! - [`unknowns`]: the keyframe constraints ([`unknowns::KeyConstraints`]) and the free keyframe
//!   positions/velocities they leave (masks eliminated, loops aliased);
//! - [`objective`]: W, its gradient, and the local step over all samples;
//! - [`time_coefficients`]: the weights over pairs of time slots of the normal matrix's three
//!   node matrices (`M`, `L`, `L M⁻¹ L`), shared by every way of inverting it;
//! - [`global_step`]: the normal matrix, assembled and factorized once (refactorized on the
//!   kept symbolic analysis when the key times move), or inverted in modes or by CG, as its
//!   cost model chooses;
//! - [`modal`]: the global step solved exactly in the body's vibration modes (many keys);
//! - [`gauss_newton`]: the Gauss-Newton product `Jᵀ M⁻¹ J v` and truncated CG for its step;
//! - [`quasi_newton`]: L-BFGS preconditioned by the global step or the tangent model;
//! - [`tangent_step`]: the normal matrix with the rest tangent stiffness (a Newton model for
//!   small motions about the rest shape);
//! - [`settings`]: the solver's settings and measured defaults (the timing problem reads them too);
//! - [`solver`]: the two phases of the iteration (local/global, then quasi-Newton), its log,
//!   and the prediction of the iterations left;
//! - [`timing`]: W as a function of the key times, its exact derivatives, the timing step;
//! - [`obstacles`]: planes and spheres the body may not enter;
//! - [`contact`]: the node-obstacle checks at keys and frames, linearized as constraints;
//! - [`active_set`]: the constraints held in a step, by projection of the preconditioner.
//!
//! Inputs are plain: an [`Elastic`](crate::algorithms::physics::elastic::Elastic) body, the key
//! constraints and the solver [`Settings`](settings::Settings); the result is the trajectory and
//! the solver's own [`Log`](solver::Log). The stage layer translates the scene and stage files.

pub mod active_set;
pub mod contact;
pub mod gauss_newton;
pub mod global_step;
pub mod modal;
pub mod objective;
pub mod obstacles;
pub mod quasi_newton;
pub mod sampling;
pub mod settings;
pub mod solver;
pub mod tangent_step;
pub mod time_coefficients;
pub mod timing;
pub mod trajectory;
pub mod unknowns;

#[cfg(test)]
mod cantilever_tests;
#[cfg(test)]
mod tests;
