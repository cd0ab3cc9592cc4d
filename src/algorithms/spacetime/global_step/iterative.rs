//! The iterative global step: preconditioned conjugate gradients on the Kronecker sum applied
//! without assembling it, with per-key block Jacobi, warm-started from the previous solve.

use faer::sparse::SparseColMat;
use rayon::prelude::*;

use crate::algorithms::geometry::Point;
use crate::algorithms::physics::csr::Csr;
use crate::algorithms::physics::pcg::{pcg, BlockJacobi, SymmetricOperator};
use crate::algorithms::spacetime::objective::Objective;
use crate::algorithms::spacetime::time_coefficients::TimeCoefficients;
use crate::algorithms::spacetime::unknowns::Unknowns;

/// The normal matrix as the Kronecker sum it is, `C_MM ⊗ M + C_ML ⊗ L + C_KK ⊗ L M⁻¹ L`
/// restricted to the free unknowns, applied without assembling it: per time slot two sparse
/// products with `L` over the nodes, then the banded time coefficients mix the slots. A product
/// costs about `slots × 2 nnz(L)` instead of the assembled matrix's `nnz(A)` (2.6k nodes, 20
/// keys: 40 × 2 × 40k against about 30M entries), and nothing of the size of `A` is kept.
pub(super) struct KroneckerSum {
    unknowns: Unknowns,
    mass: Vec<f64>,
    /// `1/m` at free nodes, 0 at supports (their rows are not in W).
    inv_mass: Vec<f64>,
    stiffness: Csr,
    /// Per slot σ: the slots σ' it is coupled to, with `(C_MM, C_ML, C_KK)[σ, σ']`.
    coupled: Vec<Vec<(usize, [f64; 3])>>,
}

impl KroneckerSum {
    pub(super) fn new(objective: &Objective, unknowns: &Unknowns, c: &TimeCoefficients) -> KroneckerSum {
        let el = objective.elastic;
        let inv_mass = el.mass.iter().zip(&objective.supports).map(|(m, &support)| if support { 0.0 } else { 1.0 / m }).collect();
        let n = c.slots;
        let coupled = (0..n)
            .map(|s| (0..n).map(|t| (t, [c.mm[s * n + t], c.ml[s * n + t], c.kk[s * n + t]])).filter(|(_, v)| v.iter().any(|&x| x != 0.0)).collect())
            .collect();
        KroneckerSum { unknowns: unknowns.clone(), mass: el.mass.clone(), inv_mass, stiffness: el.stiffness.clone(), coupled }
    }
}

impl SymmetricOperator for KroneckerSum {
    fn apply(&self, x: &[Point], y: &mut [Point]) {
        let (u, nodes) = (&self.unknowns, self.unknowns.nodes);
        let slots = u.slots.count();
        // Per slot: X (zero at fixed entries), L X and L M⁻¹ L X. Each slot on one thread, every
        // sum in a fixed order: the same bytes on any thread count.
        let per_slot: Vec<[Vec<Point>; 3]> = (0..slots)
            .into_par_iter()
            .map(|s| {
                let xs: Vec<Point> = (0..nodes).map(|a| u.get(a, s).map_or([0.0; 3], |i| x[i])).collect();
                let mut lx = vec![[0.0; 3]; nodes];
                self.stiffness.mul_points_sequential(&xs, &mut lx);
                let scaled: Vec<Point> = lx.iter().zip(&self.inv_mass).map(|(p, &w)| crate::algorithms::geometry::scale(*p, w)).collect();
                let mut kx = vec![[0.0; 3]; nodes];
                self.stiffness.mul_points_sequential(&scaled, &mut kx);
                [xs, lx, kx]
            })
            .collect();
        let rows: Vec<Vec<Point>> = (0..slots)
            .into_par_iter()
            .map(|s| {
                let mut out = vec![[0.0; 3]; nodes];
                for &(t, [mm, ml, kk]) in &self.coupled[s] {
                    let [xs, lx, kx] = &per_slot[t];
                    for a in 0..nodes {
                        let m = mm * self.mass[a];
                        for d in 0..3 {
                            out[a][d] += m * xs[a][d] + ml * lx[a][d] + kk * kx[a][d];
                        }
                    }
                }
                out
            })
            .collect();
        for (s, row) in rows.iter().enumerate() {
            for (a, v) in row.iter().enumerate() {
                if let Some(i) = u.get(a, s) {
                    y[i] = *v;
                }
            }
        }
    }
}

/// The node of every unknown.
pub(super) fn node_blocks(unknowns: &Unknowns) -> Vec<u32> {
    let mut block_of = vec![0u32; unknowns.count()];
    for a in 0..unknowns.nodes {
        for s in 0..unknowns.slots.count() {
            if let Some(u) = unknowns.get(a, s) {
                block_of[u] = a as u32;
            }
        }
    }
    block_of
}

/// The iterative global step (see the module documentation).
pub(super) struct Iterative {
    pub(super) operator: KroneckerSum,
    pub(super) preconditioner: BlockJacobi,
    /// The previous solution, the next solve's start.
    pub(super) previous: std::sync::Mutex<Option<Vec<Point>>>,
    /// How the solves went.
    pub(super) log: std::sync::Mutex<CgLog>,
}

/// How the iterative global step's CG solves went (for the report and the warning when a
/// solve stops at its iteration cap).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct CgLog {
    /// CG solves made.
    pub solves: usize,
    /// CG iterations over all solves.
    pub iterations: usize,
    /// CG iterations of the last solve.
    pub last_iterations: usize,
    /// Solves that stopped at `CG_MAX_ITERATIONS` above `CG_TOLERANCE`.
    pub capped: usize,
    /// The largest final relative residual of any solve.
    pub worst_residual: f64,
    /// The iteration cap the solves ran with.
    pub max_iterations: usize,
    /// The relative residual at which the solves stopped.
    pub tolerance: f64,
}

/// Relative residual at which a CG solve of the global step stops: far below the solver's
/// tolerance on W, so the iterates follow the direct solve's.
pub(super) const CG_TOLERANCE: f64 = 1e-10;

/// CG iterations per solve at most.
pub(super) const CG_MAX_ITERATIONS: usize = 5000;

impl Iterative {
    /// The full rows of `a` and its per-key block preconditioner.
    pub(super) fn new(
        a: &SparseColMat<usize, f64>,
        operator: KroneckerSum,
        order: &[u32],
    ) -> std::result::Result<Iterative, crate::algorithms::physics::cholesky::NotPositiveDefinite> {
        let unknowns = &operator.unknowns;
        // Every key's block is ordered by the node graph (as the direct factor is): its
        // unknowns by their node's place in `order` ([`key_block_order`]): 70M factor entries
        // instead of faer's AMD's 83M at 20 keys on 2.7k nodes.
        let node_of = node_blocks(unknowns);
        let mut place = vec![0u32; unknowns.nodes];
        for (k, &v) in order.iter().enumerate() {
            place[v as usize] = k as u32;
        }
        let rank: Vec<u32> = node_of.iter().map(|&v| place[v as usize]).collect();
        let mut key_of = vec![0u32; unknowns.count()];
        let slots = unknowns.slots.count();
        for node in 0..unknowns.nodes {
            for s in 0..slots {
                if let Some(u) = unknowns.get(node, s) {
                    key_of[u] = (s / 2) as u32;
                }
            }
        }
        let preconditioner = BlockJacobi::new(a, &key_of, slots / 2, Some(&rank))?;
        Ok(Iterative {
            operator,
            preconditioner,
            previous: std::sync::Mutex::new(None),
            log: std::sync::Mutex::new(CgLog { max_iterations: CG_MAX_ITERATIONS, tolerance: CG_TOLERANCE, ..CgLog::default() }),
        })
    }

    /// `x <- A⁻¹ x` by PCG from the previous solution.
    pub(super) fn solve(&self, x: &mut [Point]) {
        let mut previous = self.previous.lock().expect("no panic while solving");
        let mut solution = previous.take().unwrap_or_else(|| vec![[0.0; 3]; x.len()]);
        let stats = pcg(&self.operator, &self.preconditioner, x, &mut solution, CG_TOLERANCE, CG_MAX_ITERATIONS);
        x.copy_from_slice(&solution);
        let mut log = self.log.lock().expect("no panic while solving");
        log.solves += 1;
        log.iterations += stats.iterations;
        log.last_iterations = stats.iterations;
        log.capped += (stats.relative_residual > CG_TOLERANCE) as usize;
        log.worst_residual = log.worst_residual.max(stats.relative_residual);
        *previous = Some(solution);
    }
}
