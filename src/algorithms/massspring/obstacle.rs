//! Rigid obstacles a blended shape collides with (Ma et al. 2012, section 4): planes and
//! spheres, the scene file's `[[obstacle]]` kinds. The free side of a plane is the side its
//! normal points to; a sphere is solid.

use crate::algorithms::geometry::{add, dot, norm, scale, sub, Point};
use crate::support::error::{Error, Result};

/// A rigid obstacle in world coordinates (the targets' units), as a scene's `[[obstacle]]`
/// table gives it.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum Obstacle {
    /// The half-space behind `point` against `normal` is solid.
    Plane {
        /// A point on the plane.
        point: Point,
        /// Normal pointing to the free side; any nonzero length until [`Obstacle::validated`]
        /// makes it unit.
        normal: Point,
    },
    /// A solid ball of `radius` about `center`.
    Sphere {
        /// Centre of the ball.
        center: Point,
        /// Radius of the ball, positive.
        radius: f64,
    },
}

impl Obstacle {
    /// Check the numbers and normalize the plane's normal. `name` says which obstacle (for
    /// example `obstacle 2`) in the message.
    pub fn validated(&self, name: &str) -> Result<Obstacle> {
        let finite = |p: &Point| p.iter().all(|c| c.is_finite());
        match *self {
            Obstacle::Plane { point, normal } => {
                let length = norm(normal);
                if !finite(&point) || !finite(&normal) || length == 0.0 {
                    return Err(Error::general(
                        format!("{name}: a plane needs a finite point and a nonzero normal, got point {point:?}, normal {normal:?}"),
                        "give the plane as point = [x, y, z] on it and normal = [nx, ny, nz] pointing to the free side",
                    ));
                }
                Ok(Obstacle::Plane { point, normal: scale(normal, 1.0 / length) })
            }
            Obstacle::Sphere { center, radius } => {
                if !(finite(&center) && radius > 0.0 && radius.is_finite()) {
                    return Err(Error::general(
                        format!("{name}: a sphere needs a finite center and a positive radius, got center {center:?}, radius {radius}"),
                        "give the sphere as center = [x, y, z] and radius > 0",
                    ));
                }
                Ok(*self)
            }
        }
    }

    /// Signed distance to the obstacle's surface: negative inside. (Planes: `normal` must be
    /// unit, as [`Obstacle::validated`] makes it.)
    pub(crate) fn signed_distance(&self, x: Point) -> f64 {
        match *self {
            Obstacle::Plane { point, normal } => dot(sub(x, point), normal),
            Obstacle::Sphere { center, radius } => norm(sub(x, center)) - radius,
        }
    }

    /// The nearest point of the obstacle's surface (moving along the penetration normal).
    pub fn project(&self, x: Point) -> Point {
        match *self {
            Obstacle::Plane { point, normal } => sub(x, scale(normal, dot(sub(x, point), normal))),
            Obstacle::Sphere { center, radius } => {
                let d = sub(x, center);
                let l = norm(d);
                // At the very centre every direction is as near: take +z.
                let direction = if l > 0.0 { scale(d, 1.0 / l) } else { [0.0, 0.0, 1.0] };
                add(center, scale(direction, radius))
            }
        }
    }

    /// The same obstacle seen in another frame: `point` maps points, `direction` maps vectors
    /// (a rigid motion and its rotation).
    pub fn mapped(&self, point: impl Fn(Point) -> Point, direction: impl Fn(Point) -> Point) -> Obstacle {
        match *self {
            Obstacle::Plane { point: p, normal } => Obstacle::Plane { point: point(p), normal: direction(normal) },
            Obstacle::Sphere { center, radius } => Obstacle::Sphere { center: point(center), radius },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plane_and_sphere_distances_and_projections() {
        let plane = Obstacle::Plane { point: [0.0, 1.0, 0.0], normal: [0.0, 2.0, 0.0] }.validated("plane").unwrap();
        assert_eq!(plane.signed_distance([5.0, 0.5, 1.0]), -0.5);
        assert_eq!(plane.project([5.0, 0.5, 1.0]), [5.0, 1.0, 1.0]);
        let sphere = Obstacle::Sphere { center: [1.0, 0.0, 0.0], radius: 2.0 }.validated("sphere").unwrap();
        assert_eq!(sphere.signed_distance([1.0, 1.0, 0.0]), -1.0);
        let p = sphere.project([1.0, 0.0, 0.5]);
        assert!((sphere.signed_distance(p)).abs() < 1e-15 && p[2] > 0.0);
        assert_eq!(sphere.project([1.0, 0.0, 0.0]), [1.0, 0.0, 2.0]);
    }

    #[test]
    fn bad_obstacles_are_rejected_with_a_fix() {
        let e = Obstacle::Plane { point: [0.0; 3], normal: [0.0; 3] }.validated("obstacle 1").unwrap_err();
        assert!(e.problem.starts_with("obstacle 1: a plane needs") && e.fix.contains("normal"), "{e}");
        let e = Obstacle::Sphere { center: [0.0; 3], radius: -1.0 }.validated("obstacle 2").unwrap_err();
        assert!(e.to_string().contains("positive radius"), "{e}");
        assert!(Obstacle::Sphere { center: [f64::NAN, 0.0, 0.0], radius: 1.0 }.validated("s").is_err());
    }

    #[test]
    fn scene_syntax_parses() {
        #[derive(serde::Deserialize)]
        struct File {
            obstacle: Vec<Obstacle>,
        }
        let text = "[[obstacle]]\nkind = \"plane\"\npoint = [0, 0, 0]\nnormal = [0, 1, 0]\n\n[[obstacle]]\nkind = \"sphere\"\ncenter = [0, 2, 0]\nradius = 0.5\n";
        let file: File = toml::from_str(text).unwrap();
        assert_eq!(
            file.obstacle,
            vec![Obstacle::Plane { point: [0.0; 3], normal: [0.0, 1.0, 0.0] }, Obstacle::Sphere { center: [0.0, 2.0, 0.0], radius: 0.5 }]
        );
    }
}
