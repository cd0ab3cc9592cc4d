//! The time coefficients of the global step's matrix: per pair of time slots, the weights of
//! `M`, `L` and `L M⁻¹ L` in the Kronecker sum `C_MM ⊗ M + C_ML ⊗ L + C_KK ⊗ L M⁻¹ L`
//! ([`super::global_step`]), which the direct, modal and iterative steps all invert, and the
//! proximal weight `1/h⁴` added to `C_MM`.

use super::objective::Objective;

/// Dense coefficient matrices over time slots (row-major, `slots × slots`).
#[derive(Debug, Clone, PartialEq)]
pub struct TimeCoefficients {
    /// Time slots: each matrix is `slots × slots`.
    pub slots: usize,
    /// `C_MM`, the coefficients of `M` (the proximal term `C_KK / h⁴` included).
    pub mm: Vec<f64>,
    /// `C_ML`, the coefficients of `L`.
    pub ml: Vec<f64>,
    /// `C_KK`, the coefficients of `L M⁻¹ L`.
    pub kk: Vec<f64>,
}

impl TimeCoefficients {
    /// Accumulate the sample coefficients; `proximal` is the weight `1/h⁴` (0 = off).
    pub fn new(objective: &Objective, proximal: f64) -> TimeCoefficients {
        let n = objective.slots.count();
        let (mut mm, mut ml, mut kk) = (vec![0.0; n * n], vec![0.0; n * n], vec![0.0; n * n]);
        for s in &objective.samples {
            let (c, l) = objective.coefficients(s);
            for j in 0..4 {
                for k in 0..4 {
                    let at = s.slots[j] * n + s.slots[k];
                    mm[at] += s.weight * c[j] * c[k];
                    ml[at] += s.weight * (c[j] * l[k] + l[j] * c[k]);
                    kk[at] += s.weight * l[j] * l[k];
                }
            }
        }
        for (m, k) in mm.iter_mut().zip(&kk) {
            *m += proximal * k;
        }
        TimeCoefficients { slots: n, mm, ml, kk }
    }
}

/// The smallest proximal weight relative to the body's stiffest rate `ω⁴ = max_i (L_ii / m_i)²`
/// (1/s⁴: the fourth power of its fastest vibration). In the matrix, translations of the free
/// unknowns cost only inertia (`C_MM M`, since `L 1 = 0`) while every other motion costs
/// `C_KK L M⁻¹ L ~ ω⁴ C_KK M`; when a scene is very stiff for its size and mass (a 1e-4 m box
/// of density 1 and stiffness 70 is 1e16 times stiffer than its inertia) the translation pivots
/// drown in round-off and Cholesky fails. Flooring `1/h⁴` at `1e-10 ω⁴` keeps those pivots
/// above round-off whatever the units. The proximal term never moves the fixed point (see the
/// module documentation); the floor is far below the default `1/h⁴` at ordinary scales
/// (`1e-10 ω⁴ ≈ 1e-3` for the demo against `1/0.1⁴ = 1e4`), so it only acts in those extremes.
pub const PROXIMAL_FLOOR: f64 = 1e-10;

/// The proximal weight `1/h⁴` for the regularization time scale `h` (0 = off), floored by
/// [`PROXIMAL_FLOOR`] times the body's stiffest rate.
pub(crate) fn proximal_weight(objective: &Objective, regularization: f64) -> f64 {
    if regularization <= 0.0 {
        return 0.0;
    }
    let elastic = objective.elastic;
    let rate = (0..elastic.node_count())
        .filter(|&i| elastic.mass[i] > 0.0)
        .map(|i| (elastic.stiffness.get(i, i) / elastic.mass[i]).powi(2))
        .fold(0.0f64, f64::max);
    (1.0 / regularization.powi(4)).max(PROXIMAL_FLOOR * rate)
}
