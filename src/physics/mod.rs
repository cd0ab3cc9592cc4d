//! Projective-dynamics physics on tet meshes.
