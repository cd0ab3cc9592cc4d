//! The `[tet]` table: TetGen's settings.

use serde::{Deserialize, Serialize};

use super::invalid;
use crate::support::error::{number, Result};

/// The `[tet]` table (defaults: [`Tet::default`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Tet {
    /// TetGen `-q` radius-edge ratio bound (0 = no quality refinement).
    pub quality: f64,
    /// TetGen `-a` maximum tet volume; 0 means no bound.
    pub max_volume: f64,
    /// Seconds TetGen may run before it is stopped.
    pub timeout: f64,
    /// Simulate a surface that is too fine (more than `max_nodes` vertices) or messy (open,
    /// in several parts, non-manifold, self-intersecting) on an automatic cage around it;
    /// `false` sends every surface to TetGen as it is.
    pub cage: bool,
    /// Surfaces with more vertices than this are simulated on a cage.
    pub max_nodes: usize,
    /// Tet nodes a generated cage aims at.
    pub cage_nodes: usize,
}

// The defaults of every table, written once: `#[serde(default)]` fills a missing key from these.

impl Default for Tet {
    fn default() -> Self {
        // max_nodes: a 5-key bake of a 3k-node body takes about 5 s and 1 GB on 2 cores;
        // cage_nodes: the paper's cages (922 nodes for CHEB) bake 10 keys in seconds.
        Tet { quality: 1.414, max_volume: 0.0, timeout: 120.0, cage: true, max_nodes: 3000, cage_nodes: 1000 }
    }
}

impl Tet {
    pub(super) fn validate(&self) -> Result<()> {
        if !(self.quality.is_finite() && self.quality >= 1.0) && self.quality != 0.0 {
            return invalid(
                format!("[tet] quality = {} must be >= 1 (or 0 for none)", number(self.quality)),
                "TetGen needs a radius-edge bound like 1.414",
            );
        }
        if !(self.max_volume.is_finite() && self.max_volume >= 0.0) {
            return invalid(format!("[tet] max_volume = {} must be >= 0", number(self.max_volume)), "use 0 for no bound");
        }
        if !(self.timeout.is_finite() && self.timeout > 0.0) {
            return invalid(format!("[tet] timeout = {} must be positive", number(self.timeout)), "give seconds, e.g. 120");
        }
        if self.max_nodes < 4 {
            return invalid(format!("[tet] max_nodes = {} is too small for a body", self.max_nodes), "use e.g. 3000");
        }
        if self.cage_nodes < 50 {
            return invalid(format!("[tet] cage_nodes = {} is too small for a cage", self.cage_nodes), "use e.g. 1000 (at least 50)");
        }
        Ok(())
    }
}
