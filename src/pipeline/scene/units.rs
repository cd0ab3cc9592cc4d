//! The input's length unit (`units`).

use serde::{Deserialize, Serialize};

/// The input's length unit (`units`): a name, or the meters in one unit.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum Units {
    /// One of [`UNIT_NAMES`].
    Name(String),
    /// Meters per unit (> 0).
    MetersPerUnit(f64),
}

/// The unit names `units` accepts, with their meters, the most used first.
pub const UNIT_NAMES: [(&str, f64); 7] = [("m", 1.0), ("cm", 0.01), ("mm", 0.001), ("in", 0.0254), ("ft", 0.3048), ("dm", 0.1), ("km", 1000.0)];

impl Units {
    /// Meters per unit (`None` for an unknown name or a number that is not positive).
    pub fn meters_per_unit(&self) -> Option<f64> {
        match self {
            Units::Name(name) => UNIT_NAMES.iter().find(|(n, _)| n == name).map(|&(_, m)| m),
            Units::MetersPerUnit(m) => (m.is_finite() && *m > 0.0).then_some(*m),
        }
    }
}

/// The range of `[export] meters_per_unit`: micrometres to 1000 km. The glTF node scale is
/// written as a 32-bit float, which holds it exactly enough (1e300 would be written as null,
/// 1e-300 as 0).
pub(crate) const METERS_PER_UNIT_RANGE: (f64, f64) = (1e-6, 1e6);
