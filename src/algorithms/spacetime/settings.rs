//! The spacetime solver's settings, shared by the solver and the timing problem (which reads
//! the samples, damping and gravity of the same objective), and their measured defaults.

use super::contact::Contacts;
use super::unknowns::KeyConstraints;
use crate::algorithms::geometry::Point;
use crate::algorithms::physics::elastic::Elastic;
use crate::support::budget::Budget;

/// Solver settings.
#[derive(Debug, Clone, PartialEq)]
pub struct Settings {
    /// Residual samples per interval.
    pub samples: usize,
    /// Residual samples on an interval that begins or ends at a contact.
    pub contact_samples: usize,
    /// Iterations (of both phases together) before the solve gives up.
    pub max_iterations: usize,
    /// Stop when W decreased by less than `tolerance × (W + negligible × S)` over the last
    /// [`WINDOW`] quasi-Newton iterations (S: the force scale, the solver's module documentation).
    pub tolerance: f64,
    /// The part of the force scale S below which W counts as zero in the stopping rule (0: the
    /// purely relative rule, which never fires where W can reach 0).
    pub negligible: f64,
    /// Proximal time scale h (0 = off).
    pub regularization: f64,
    /// Rayleigh mass damping α (D = α M), per second.
    pub damping: f64,
    /// Gravitational acceleration.
    pub gravity: Point,
    /// The memory the global step may use (its direct factor's predicted peak; past it the
    /// step is solved iteratively) and the time the solve may take.
    pub budget: Budget,
    /// Optimize the key times too, under these constraints (`max_iterations` and `tolerance`
    /// of [`TimingSettings`] are those of [`super::timing::Timing::optimize_times`], not used here).
    pub timing: Option<TimingSettings>,
    /// Obstacles the nodes may not enter.
    pub contacts: Option<Contacts>,
    /// The quasi-Newton phase's model Hessian (its preconditioner). Default: auto, which keeps
    /// the projective one wherever a key moves beyond `LINEAR_REGIME` (every Table 1 scene
    /// and the demo) and takes the tangent one for small motions about the rest shape, where
    /// the projective one stalls: on the cyclic bar L-BFGS preconditioned by `L` lowers W at
    /// the first guess's times by 0.26% in 670 iterations, against the 8.8% the tangent model
    /// finds in one, and the stopping rule then rightly ends a solve that is not moving.
    pub model_hessian: ModelHessian,
    /// How the global step is inverted; `None`: the cheapest predicted within the memory
    /// budget (`super::global_step::choose`).
    pub global_step: Option<super::global_step::Method>,
    /// Residual samples per interval of the coarse phase (0: none; the solver's module documentation,
    /// "Coarse to fine"). Not used with obstacles or optimized key times, nor when it is not
    /// below `samples`.
    pub coarse_samples: usize,
    /// The coarse phase's own `tolerance` (its stopping rule is the fine one's otherwise).
    pub coarse_tolerance: f64,
    /// The quasi-Newton phase's step: L-BFGS, or a Gauss-Newton step solved by truncated CG
    /// ([`Step`]).
    pub step: Step,
}

/// The step of the quasi-Newton phase (the solver's module documentation, "Gauss-Newton steps").
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Step {
    /// L-BFGS on the exact W, preconditioned by the model Hessian.
    QuasiNewton,
    /// A truncated Gauss-Newton step (module `gauss_newton`), preconditioned by the model
    /// Hessian, falling back to the L-BFGS step where its line search fails. Not with obstacles
    /// or moving key times (L-BFGS is used there).
    GaussNewton,
    /// [`Step::GaussNewton`] where it was measured to win (nowhere yet: every scene measured costs more), else [`Step::QuasiNewton`]
    /// ([`Step::resolve`]).
    Auto,
}

/// The default of [`Settings::step`].
pub(crate) const DEFAULT_STEP: Step = Step::Auto;

/// CG iterations (products with the Gauss-Newton Hessian) per Gauss-Newton step at most.
pub const GAUSS_NEWTON_CG: usize = 20;

impl Step {
    /// The step taken: `Auto` decided, and L-BFGS wherever Gauss-Newton does not apply.
    pub fn resolve(self, settings: &Settings) -> Step {
        if settings.contacts.is_some() || settings.timing.is_some() {
            return Step::QuasiNewton;
        }
        match self {
            // Measured: Gauss-Newton cuts the iterations 1.5 to 3.4x but costs 1.5 to 2.4x the CPU time
            // (the solver's module documentation, "Gauss-Newton steps").
            Step::Auto => Step::QuasiNewton,
            other => other,
        }
    }
}

/// The quasi-Newton phase's initial inverse Hessian.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ModelHessian {
    /// [`ModelHessian::Tangent`] when every key stays within `LINEAR_REGIME` of the body's
    /// size of its rest shape (where the rest tangent stiffness is the body's) and its
    /// factorization succeeds, else [`ModelHessian::Projective`].
    Auto,
    /// The global step's matrix (projective stiffness `L`), factorized anyway for phase 1.
    Projective,
    /// The same normal matrix with the rest tangent stiffness (`super::tangent_step`);
    /// not with obstacles (the projective one is used there).
    Tangent,
}

/// How far (relative to the body's bounding-box diagonal) every key may be from the rest shape
/// for [`ModelHessian::Auto`] to choose the tangent model.
pub const LINEAR_REGIME: f64 = 0.01;

impl ModelHessian {
    /// The model for `keys` on `elastic`: `Auto` decided.
    pub fn resolve(self, elastic: &Elastic, keys: &KeyConstraints) -> ModelHessian {
        if self != ModelHessian::Auto {
            return self;
        }
        let size = crate::algorithms::geometry::bbox_diagonal(&elastic.rest);
        let far = keys
            .positions
            .iter()
            .flatten()
            .zip(elastic.rest.iter().cycle())
            .map(|(p, r)| crate::algorithms::geometry::norm(crate::algorithms::geometry::sub(*p, *r)))
            .fold(0.0, f64::max);
        if far <= LINEAR_REGIME * size {
            ModelHessian::Tangent
        } else {
            ModelHessian::Projective
        }
    }
}

impl Settings {
    /// The settings of an unconstrained solve with these samples and material.
    pub fn new(samples: usize, damping: f64, gravity: Point) -> Settings {
        Settings {
            samples,
            contact_samples: 2 * samples,
            max_iterations: DEFAULT_MAX_ITERATIONS,
            tolerance: DEFAULT_TOLERANCE,
            negligible: NEGLIGIBLE,
            regularization: 0.1,
            damping,
            gravity,
            budget: Budget::default(),
            timing: None,
            contacts: None,
            model_hessian: ModelHessian::Auto,
            global_step: None,
            coarse_samples: DEFAULT_COARSE_SAMPLES,
            coarse_tolerance: DEFAULT_COARSE_TOLERANCE,
            step: DEFAULT_STEP,
        }
    }

    /// The samples of the coarse phase, when one runs (the solver's module documentation, "Coarse to fine").
    pub fn coarse_phase(&self) -> Option<usize> {
        (self.coarse_samples > 0 && self.coarse_samples < self.samples && self.contacts.is_none() && self.timing.is_none())
            .then_some(self.coarse_samples)
    }
}

/// The default of [`Settings::coarse_samples`] (measured: see `formats/scene.md`).
pub(crate) const DEFAULT_COARSE_SAMPLES: usize = 0;
/// The default of [`Settings::coarse_tolerance`].
pub const DEFAULT_COARSE_TOLERANCE: f64 = 1e-3;

/// The default of [`Settings::tolerance`] (measured: see `formats/scene.md`).
pub const DEFAULT_TOLERANCE: f64 = 1e-3;
/// The default of [`Settings::negligible`] (the solver's module documentation).
pub const NEGLIGIBLE: f64 = 1e-3;
/// The default of [`Settings::max_iterations`].
pub(crate) const DEFAULT_MAX_ITERATIONS: usize = 1000;
/// Iterations over which the stopping rule measures the decrease of W.
pub const WINDOW: usize = 10;
/// Relative change of an interval since the last factorization that triggers a refactorization.
pub const REFACTOR_CHANGE: f64 = 0.1;

/// Constraints and budget of [`Timing::optimize_times`](super::timing::Timing::optimize_times).
#[derive(Debug, Clone, PartialEq)]
pub struct TimingSettings {
    /// Smallest interval length (s); an interval already shorter keeps its length as bound.
    pub min_interval: f64,
    /// Keep the total duration (the last key's time).
    pub keep_duration: bool,
    /// Keys whose time may not move.
    pub fixed_times: Vec<usize>,
    /// Newton iterations at most.
    pub max_iterations: usize,
    /// Stop when the model's predicted decrease `-g·ΔT` falls below `tolerance × W`.
    pub tolerance: f64,
}

impl Default for TimingSettings {
    fn default() -> Self {
        TimingSettings { min_interval: 1e-3, keep_duration: false, fixed_times: Vec::new(), max_iterations: 10, tolerance: 1e-9 }
    }
}
