//! The `[material]` table: the body's physics.

use serde::{Deserialize, Serialize};

use super::{invalid, three_components};
use crate::support::error::{number, Result};

/// The `[material]` table (defaults: [`Material::default`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Material {
    /// Strain (as-rigid-as-possible) constraint weight per unit rest volume.
    pub stiffness: f64,
    /// Volume-preservation constraint weight per unit rest volume.
    pub volume: f64,
    /// Mass per unit rest volume (lumped to the nodes).
    pub density: f64,
    /// Rayleigh mass damping: D = damping * M (per second).
    pub damping: f64,
    /// Gravitational acceleration (units per second squared), applied as M g.
    #[serde(deserialize_with = "three_components")]
    pub gravity: [f64; 3],
}

impl Default for Material {
    fn default() -> Self {
        Material { stiffness: 70.0, volume: 70.0, density: 1.0, damping: 0.1, gravity: [0.0; 3] }
    }
}

/// The range of `stiffness`, `volume` and `density` (the first two may also be 0): wide enough
/// for a material converted by hand to any length unit (density scales with the cube of the
/// unit: a body in nanometres has density 1e27), narrow enough that the solve's matrices keep
/// their digits (a stiffness of 1e308 overflows; a density of 1e-300 leaves the body's motion
/// without cost, and the bake would fail later as a "singular" system).
pub(crate) const MATERIAL_RANGE: (f64, f64) = (1e-30, 1e30);

/// The range of `damping` (per second, whatever the length unit; it may also be 0).
pub(crate) const DAMPING_RANGE: (f64, f64) = (1e-9, 1e12);

impl Material {
    pub(super) fn validate(&self) -> Result<()> {
        for (key, v, zero_ok, (min, max)) in [
            ("stiffness", self.stiffness, true, MATERIAL_RANGE),
            ("volume", self.volume, true, MATERIAL_RANGE),
            ("density", self.density, false, MATERIAL_RANGE),
            ("damping", self.damping, true, DAMPING_RANGE),
        ] {
            if !((zero_ok && v == 0.0) || (min..=max).contains(&v)) {
                let zero = if zero_ok { "0 or " } else { "" };
                return invalid(
                    format!("[material] {key} = {} is out of range ({zero}{} to {})", number(v), number(min), number(max)),
                    "give a value in the range (the defaults are stiffness = volume = 70, density = 1, damping = 0.1)",
                );
            }
        }
        if self.stiffness + self.volume <= 0.0 {
            return invalid("[material] stiffness and volume are both 0".into(), "give the body some stiffness");
        }
        if self.gravity.iter().any(|g| !g.is_finite()) {
            return invalid("[material] gravity has a non-finite component".into(), "use e.g. [0.0, -9.81, 0.0]");
        }
        Ok(())
    }
}
