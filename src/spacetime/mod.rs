//! BlendSim's spacetime projective dynamics on Hermite trajectories.

pub mod trajectory;
