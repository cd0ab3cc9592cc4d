//! Static obstacles the body may not enter: a half-space bounded by a plane, or a solid sphere.
//!
//! Each obstacle is a signed distance `φ(x)` (positive outside, zero on the surface) and its
//! gradient, the outward normal. The solver keeps `φ(x_a(t)) >= 0` for every node `a` at the
//! check times ([`super::contact`]); a node's position at a fixed time is linear in the keyframe
//! unknowns, so the plane's constraint is linear in them. The sphere's is not: it is linearized
//! at the current position, `n·(x - c) >= r` with `n` the outward normal there. That half-space
//! lies outside the sphere, so satisfying the linearization satisfies the sphere.
//!
//! The whole body stays outside a plane when its nodes do (every point of a tet is a convex
//! combination of its nodes); for a sphere the nodes are checked, not the faces between them.

use crate::algorithms::geometry::{dot, norm, scale, sub, Point};

/// An obstacle.
///
/// Invariants: a plane's `normal` has unit length; a sphere's `radius` is positive.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Obstacle {
    /// The half-space behind the plane through `point` with outward unit `normal`.
    Plane {
        /// A point on the plane.
        point: Point,
        /// Outward unit normal, pointing away from the solid side.
        normal: Point,
    },
    /// The solid ball of `radius` about `center`.
    Sphere {
        /// Centre of the ball.
        center: Point,
        /// Radius of the ball, positive.
        radius: f64,
    },
}

impl Obstacle {
    /// A plane through `point` with outward `normal` (any nonzero length).
    pub fn plane(point: Point, normal: Point) -> Obstacle {
        Obstacle::Plane { point, normal: scale(normal, 1.0 / norm(normal)) }
    }

    /// Signed distance of `x` to the surface, positive outside.
    pub fn distance(&self, x: Point) -> f64 {
        match *self {
            Obstacle::Plane { point, normal } => dot(normal, sub(x, point)),
            Obstacle::Sphere { center, radius } => norm(sub(x, center)) - radius,
        }
    }

    /// The point of the surface nearest to `x` (`x` itself when it is on the surface): where
    /// a penetrating node of a first guess is put.
    pub fn project(&self, x: Point) -> Point {
        let n = self.normal(x);
        let d = self.distance(x);
        std::array::from_fn(|c| x[c] - d * n[c])
    }

    /// The outward unit normal at `x` (the gradient of [`Obstacle::distance`]); at a sphere's
    /// centre, where it is undefined, straight up along +y.
    pub fn normal(&self, x: Point) -> Point {
        match *self {
            Obstacle::Plane { normal, .. } => normal,
            Obstacle::Sphere { center, .. } => {
                let d = sub(x, center);
                let l = norm(d);
                if l > 0.0 {
                    scale(d, 1.0 / l)
                } else {
                    [0.0, 1.0, 0.0]
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn distances_and_normals() {
        let plane = Obstacle::plane([0.0, 1.0, 0.0], [0.0, 2.0, 0.0]);
        assert_eq!(plane.distance([5.0, 3.0, -2.0]), 2.0);
        assert_eq!(plane.distance([0.0, 0.5, 0.0]), -0.5);
        assert_eq!(plane.normal([9.0; 3]), [0.0, 1.0, 0.0]);
        let sphere = Obstacle::Sphere { center: [1.0, 0.0, 0.0], radius: 2.0 };
        assert_eq!(sphere.distance([1.0, 3.0, 0.0]), 1.0);
        assert_eq!(sphere.distance([1.0, 0.0, 0.0]), -2.0);
        assert_eq!(sphere.normal([1.0, 0.0, -4.0]), [0.0, 0.0, -1.0]);
        // The linearization at x lies outside the sphere: points on its tangent plane are at
        // least the radius away from the centre.
        let x = [2.0, 2.5, 1.0];
        let n = sphere.normal(x);
        let on_tangent = [x[0] + 0.7 * n[1], x[1] - 0.7 * n[0], x[2]];
        assert!(dot(n, sub(on_tangent, [1.0, 0.0, 0.0])) - dot(n, sub(x, [1.0, 0.0, 0.0])) < 1e-12);
        assert!(sphere.distance(on_tangent) >= sphere.distance(x));
    }

    #[test]
    fn projections_land_on_the_surface_along_the_normal() {
        let plane = Obstacle::plane([0.0, 1.0, 0.0], [0.0, 1.0, 1.0]);
        let sphere = Obstacle::Sphere { center: [1.0, 0.0, 0.0], radius: 2.0 };
        for x in [[0.3, -0.7, 0.2], [2.0, 0.5, -1.0], [1.0, 0.0, 0.0], [4.0, 3.0, 2.0]] {
            for o in [plane, sphere] {
                let p = o.project(x);
                assert!(o.distance(p).abs() < 1e-14, "{o:?} {x:?}");
                // The step is along the normal, and as long as the distance.
                let step = sub(x, p);
                assert!((norm(step) - o.distance(x).abs()).abs() < 1e-14);
                assert!(norm(step) < 1e-15 || (dot(step, o.normal(p)).abs() - norm(step)).abs() < 1e-14);
            }
        }
    }
}
