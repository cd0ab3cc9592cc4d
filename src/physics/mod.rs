//! Projective-dynamics physics on tet meshes: the elastic body ([`elastic::Elastic`]: lumped
//! mass, `L`, `J`, local step), its per-element projections, and the linear algebra under
//! them.

pub mod cholesky;
pub mod csr;
pub mod elastic;
pub mod equilibrium;
pub mod mat3;
pub mod ordering;
pub mod projection;
pub mod projection_curvature;
pub mod svd3;
pub mod vibration;
