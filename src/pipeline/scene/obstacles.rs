//! The `[[obstacle]]` entries.

use serde::{Deserialize, Serialize};

use super::invalid;
use crate::support::error::Result;

/// One `[[obstacle]]` entry.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase", deny_unknown_fields)]
pub enum ObstacleSpec {
    /// The half-space behind a plane: `point` on it, `normal` pointing out of the obstacle.
    Plane {
        /// A point on the plane.
        point: [f64; 3],
        /// The outward normal (any nonzero length).
        normal: [f64; 3],
    },
    /// A solid sphere.
    Sphere {
        /// Its centre.
        center: [f64; 3],
        /// Its radius (> 0).
        radius: f64,
    },
}

/// Obstacles: finite numbers, a nonzero plane normal, a positive radius.
pub(super) fn validate_obstacles(obstacles: &[ObstacleSpec]) -> Result<()> {
    for (i, o) in obstacles.iter().enumerate() {
        let (finite, problem) = match o {
            ObstacleSpec::Plane { point, normal } => {
                let length = normal.iter().map(|x| x * x).sum::<f64>().sqrt();
                (point.iter().chain(normal).all(|x| x.is_finite()), (length > 0.0).then_some(()).ok_or("its normal is zero"))
            }
            ObstacleSpec::Sphere { center, radius } => {
                (center.iter().all(|x| x.is_finite()) && radius.is_finite(), (*radius > 0.0).then_some(()).ok_or("its radius is not positive"))
            }
        };
        if !finite {
            return invalid(format!("[[obstacle]] {i} has a non-finite number"), "give finite coordinates");
        }
        if let Err(p) = problem {
            return invalid(format!("[[obstacle]] {i}: {p}"), "a plane needs a nonzero normal pointing out of the obstacle, a sphere a radius > 0");
        }
    }
    Ok(())
}
