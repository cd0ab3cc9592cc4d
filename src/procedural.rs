//! Procedural shapes and deformations (helper-owned): the demo's prism, spheres for
//! benchmarks, and the scene file's `twist` deformation.

use crate::mesh::{Point, TriMesh};
use crate::scene::Twist;

/// A closed box surface `[0,size]` with `divisions` segments per axis, outward wound.
pub fn prism(size: [f64; 3], divisions: [usize; 3]) -> TriMesh {
    let _ = (size, divisions);
    todo!()
}

/// A unit icosphere with `subdivisions` levels (0 = icosahedron), outward wound.
pub fn icosphere(subdivisions: usize) -> TriMesh {
    let _ = subdivisions;
    todo!()
}

/// Apply a twist (see [`Twist`]) to points: angle grows linearly along the axis over the
/// points' own bounding box, about the axis through the box centre; the axial coordinate
/// is scaled about the low end.
pub fn twist(points: &[Point], twist: &Twist) -> Vec<Point> {
    let _ = (points, twist);
    todo!()
}
