//! The `[solver]` table: the method and its settings.

use std::fmt;

use serde::{Deserialize, Serialize};

use super::invalid;
use crate::support::error::{number, Result};

/// How the trajectory is made (`[solver] method`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Method {
    /// Keyframes joined by cubic Hermite curves with zero velocities (the geometric baseline).
    Hermite,
    /// BlendSim's spacetime projective dynamics.
    Spacetime,
    /// Mass-spring blendshapes (Ma et al. 2012): in-between shapes from blended spring rest
    /// lengths (`[mass_spring]`).
    MassSpring,
    /// The least-squares cubic Hermite fit of a cache on its keys, no physics (`[cache]` only).
    Fit,
}

impl fmt::Display for Method {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Method::Hermite => "hermite",
            Method::Spacetime => "spacetime",
            Method::MassSpring => "mass-spring",
            Method::Fit => "fit",
        })
    }
}

/// The `[solver]` table (defaults: [`Solver::default`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Solver {
    /// The method.
    pub method: Method,
    /// Sample points per interval at which the residual force is evaluated.
    pub samples: usize,
    /// Iterations before the solver stops unconverged.
    pub max_iterations: usize,
    /// Stop when W fell by less than `tolerance × (W + 0.001 S)` over the last 10 quasi-Newton
    /// iterations (S: the force scale; `spacetime::solver`, "When it stops").
    pub tolerance: f64,
    /// Proximal regularization time scale h: adds (1/h⁴) Σ dτ BᵀMB (0 = off).
    pub regularization: f64,
    /// Residual samples on the intervals that begin or end at a contact.
    pub contact_samples: usize,
    /// Optimize the key times too.
    pub optimize_timing: bool,
    /// With `optimize_timing`: keep the total duration.
    pub keep_duration: bool,
    /// With `optimize_timing`: keys (scene indices) whose time may not move.
    pub fixed_times: Vec<usize>,
    /// With `optimize_timing`: the shortest interval (seconds).
    pub min_interval: f64,
    /// The quasi-Newton phase's model Hessian: `"auto"`, `"projective"` or `"tangent"`
    /// (see `spacetime::settings::ModelHessian`).
    pub model_hessian: String,
    /// How the global step is inverted: `"auto"` (the cheapest predicted within the memory
    /// budget), `"direct"`, `"modal"` or `"iterative"` (see `spacetime::global_step::Method`).
    pub global_step: String,
    /// Samples per interval of a first, coarse solve whose result the solve at `samples`
    /// starts from (0: none; not used with obstacles or `optimize_timing`, nor when not below
    /// `samples`; see `spacetime::solver`, "Coarse to fine").
    pub coarse_samples: usize,
    /// The quasi-Newton phase's step: `"auto"`, `"quasi-newton"` (L-BFGS) or `"gauss-newton"`
    /// (truncated CG on the Gauss-Newton Hessian; see `spacetime::settings::Step`).
    pub step: String,
}

impl Default for Solver {
    fn default() -> Self {
        Solver {
            method: Method::Spacetime,
            samples: 10,
            max_iterations: crate::algorithms::spacetime::settings::DEFAULT_MAX_ITERATIONS,
            tolerance: crate::algorithms::spacetime::settings::DEFAULT_TOLERANCE,
            regularization: 0.1,
            contact_samples: 20,
            optimize_timing: false,
            keep_duration: false,
            fixed_times: Vec::new(),
            min_interval: 1e-3,
            model_hessian: "auto".to_string(),
            global_step: "auto".to_string(),
            coarse_samples: crate::algorithms::spacetime::settings::DEFAULT_COARSE_SAMPLES,
            step: "auto".to_string(),
        }
    }
}

impl Solver {
    pub(super) fn validate(&self, keys: Option<usize>) -> Result<()> {
        if self.samples == 0 {
            return invalid("[solver] samples = 0".into(), "use at least 1 sample per interval (10 is typical)");
        }
        if self.contact_samples == 0 {
            return invalid("[solver] contact_samples = 0".into(), "use at least 1 sample per interval next to a contact (20 is typical)");
        }
        if !self.optimize_timing && (self.keep_duration || !self.fixed_times.is_empty()) {
            let key = if self.keep_duration { "keep_duration" } else { "fixed_times" };
            return invalid(
                format!("[solver] {key} is set but optimize_timing is false, so the key times do not move anyway"),
                "set optimize_timing = true, or remove the key",
            );
        }
        if let Some((k, keys)) = keys.and_then(|keys| self.fixed_times.iter().find(|&&k| k >= keys).map(|&k| (k, keys))) {
            return invalid(
                format!("[solver] fixed_times lists key {k}, but there are {keys} keys"),
                "list key indices from 0, as in [keyframes] times",
            );
        }
        if !["auto", "projective", "tangent"].contains(&self.model_hessian.as_str()) {
            return invalid(
                format!("[solver] model_hessian = {:?} is not a model", self.model_hessian),
                "use \"auto\", \"projective\" or \"tangent\"",
            );
        }
        if !["auto", "quasi-newton", "gauss-newton"].contains(&self.step.as_str()) {
            return invalid(format!("[solver] step = {:?} is not a step", self.step), "use \"auto\", \"quasi-newton\" or \"gauss-newton\"");
        }
        if !["auto", "direct", "modal", "iterative"].contains(&self.global_step.as_str()) {
            return invalid(
                format!("[solver] global_step = {:?} is not a way to solve the global step", self.global_step),
                "use \"auto\", \"direct\", \"modal\" or \"iterative\"",
            );
        }
        if !(self.min_interval.is_finite() && self.min_interval > 0.0) {
            return invalid(
                format!("[solver] min_interval = {} must be positive", number(self.min_interval)),
                "use a small length in seconds, e.g. 0.001",
            );
        }
        if !(self.tolerance.is_finite() && self.tolerance > 0.0) {
            return invalid(
                format!("[solver] tolerance = {} must be positive", number(self.tolerance)),
                "use e.g. 0.001 (W decreasing by 0.1% over the last iterations)",
            );
        }
        if !(self.regularization.is_finite() && self.regularization >= 0.0) {
            return invalid(
                format!("[solver] regularization = {} must be >= 0", number(self.regularization)),
                "use a time scale like 0.1, or 0 for none",
            );
        }
        Ok(())
    }
}
