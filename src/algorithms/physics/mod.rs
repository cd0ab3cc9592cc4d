//! Projective-dynamics physics on tet meshes: the elastic body ([`elastic::Elastic`]: lumped
//! mass, `L`, `J`, local step), its per-element projections, the quasi-static fit
//! ([`equilibrium`]), and the linear algebra under them: 3x3 matrices and their signed SVD on
//! SIMD lanes ([`mat3`], [`svd3`], [`lanes`]), sparse matrices ([`csr`]), sparse Cholesky
//! ([`cholesky`]) and its fill-reducing orderings ([`ordering`]).

pub mod cholesky;
pub mod csr;
pub mod elastic;
pub mod equilibrium;
pub mod fixed_par;
pub mod lanes;
pub mod mat3;
pub mod ordering;
pub mod pcg;
pub mod projection;
pub mod projection_curvature;
pub mod svd3;
pub mod vibration;
