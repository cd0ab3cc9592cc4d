//! The `[mass_spring]` table: the in-betweens of `[solver] method = "mass-spring"`.

use serde::{Deserialize, Serialize};

use super::invalid;
use crate::support::error::{number, Result};

/// The `[mass_spring]` table (defaults: [`MassSpring::default`]): how `method = "mass-spring"`
/// makes the in-betweens of each keyframe interval (see `formats/scene.md`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MassSpring {
    /// In-between shapes per keyframe interval, evenly spaced in time; each becomes a key of
    /// the exported animation.
    pub inbetweens: usize,
    /// Bending springs: "two-ring" (the paper's: surface vertices two edges apart) or "hinge"
    /// (the far corners of each edge's two triangles).
    pub bending: String,
    /// Newton stops when no vertex moves more than this fraction of the size in a step.
    pub tolerance: f64,
}

impl Default for MassSpring {
    fn default() -> Self {
        MassSpring { inbetweens: 3, bending: "two-ring".into(), tolerance: 1e-7 }
    }
}

impl MassSpring {
    pub(super) fn validate(&self) -> Result<()> {
        if self.inbetweens > 1000 {
            return invalid(
                format!("[mass_spring] inbetweens = {} is more than 1000 per interval", self.inbetweens),
                "use a few in-betweens per interval (3 is typical)",
            );
        }
        if !matches!(self.bending.as_str(), "two-ring" | "hinge") {
            return invalid(
                format!("[mass_spring] bending = {:?} is not a bending kind", self.bending),
                "use \"two-ring\" (the paper's) or \"hinge\"",
            );
        }
        if !(self.tolerance.is_finite() && self.tolerance > 0.0 && self.tolerance < 1.0) {
            return invalid(
                format!("[mass_spring] tolerance = {} must be between 0 and 1", number(self.tolerance)),
                "use e.g. 1e-7 (a fraction of the size)",
            );
        }
        Ok(())
    }
}
