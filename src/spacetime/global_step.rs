//! The global step: with the projections fixed, W is quadratic in the keyframe unknowns, with
//! a Hessian that does not depend on the iteration. It is assembled and factorized once.
//!
//! Structure: per sample, `∂f/∂u_j = c_j M + l_j L` (see [`super::objective`]), so in the
//! `M⁻¹` norm the Hessian block of time slots (σ, σ') is
//!
//! ```text
//! Σ_s dτ (c_σ M + l_σ L) M⁻¹ (c_σ' M + l_σ' L)
//!   = C_MM[σ,σ'] M + C_ML[σ,σ'] L + C_KK[σ,σ'] L M⁻¹ L
//! ```
//!
//! with three small dense matrices over time slots and three fixed sparse matrices over
//! nodes. The proximal regularization `(1/h⁴) Σ dτ Bᵀ M B` adds `C_KK / h⁴` to `C_MM`
//! (in the M⁻¹ norm of W, 1/h⁴ is the weight whose units make h a time). The
//! matrix restricted to the free unknowns is written straight into compressed columns in
//! node-major order (rows come out sorted; no triplet sort), and the three coordinates are
//! three right-hand sides of one factorization.
//!
//! Cost: `L M⁻¹ L` couples nodes two rings apart, so the factor fills in heavily (50M entries
//! for 25k unknowns on a 2.6k-node body). Every node's free slots stay together: the
//! fill-reducing order is found on the node graph ([`fill_reducing_order`]), the numeric
//! factorization is faer's supernodal one (parallel above 1 G predicted flops), and the
//! solves sweep the factor once per direction for all three coordinates, on two threads
//! ([`Cholesky::solve_rows3`]).
//!
//! The step itself is the minimizer of the quadratic model plus the proximal term around the
//! current iterate `q`: `q + Δ` with `(H + P) Δ = -∇W`. At a fixed point `∇W = 0`, so the
//! regularization never moves the fixed point; it only damps the path to it.

use faer::sparse::{SparseColMat, SymbolicSparseColMat};
use faer::Par;
use rayon::prelude::*;

use super::objective::Objective;
use super::unknowns::Unknowns;
use crate::error::{Error, Result};
use crate::mesh::Point;
use crate::physics::cholesky::Cholesky;
use crate::physics::ordering::{expand, minimum_degree, nested_dissection, postorder, predicted_cost, Cost, FillOrdering, Graph};

/// Dense coefficient matrices over time slots (row-major, `slots × slots`).
#[derive(Debug, Clone, PartialEq)]
pub struct TimeCoefficients {
    pub slots: usize,
    pub mm: Vec<f64>,
    pub ml: Vec<f64>,
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

/// What the precomputation built, for the report and the benchmark.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GlobalStats {
    /// Free unknowns per coordinate.
    pub unknowns: usize,
    /// Stored entries of the lower triangle of the matrix.
    pub matrix_nnz: usize,
    /// Stored entries of the Cholesky factor.
    pub factor_nnz: usize,
    /// The fill-reducing ordering that was used (see `fill_reducing_order`).
    pub ordering: &'static str,
    /// Coefficients and assembly of the matrix.
    pub assemble_seconds: f64,
    /// Ordering, symbolic analysis and numeric factorization.
    pub factor_seconds: f64,
}

/// The normal matrix of the free unknowns, factorized: solves the global step.
pub struct GlobalStep {
    unknowns: Unknowns,
    /// None when there are no unknowns.
    cholesky: Option<Cholesky>,
    /// Which time-slot pairs the matrix couples ([`coupling`]): the matrix pattern depends on
    /// the time coefficients only through this, so equal couplings mean equal patterns.
    coupling: Vec<(bool, bool)>,
    /// What the precomputation built.
    pub stats: GlobalStats,
}

/// How [`GlobalStep::retime`] rebuilt the factorization.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Retimed {
    pub assemble_seconds: f64,
    pub factor_seconds: f64,
    /// Numeric refactorization on the kept symbolic analysis (false: a fresh factorization,
    /// because a time coefficient cancelled exactly and the pattern changed).
    pub reused_symbolic: bool,
}

/// Per slot pair: whether the mass block and the stiffness blocks are present in [`assemble`].
fn coupling(c: &TimeCoefficients) -> Vec<(bool, bool)> {
    (0..c.slots * c.slots).map(|at| (c.mm[at] != 0.0, c.ml[at] != 0.0 || c.kk[at] != 0.0)).collect()
}

/// Lower triangle of the normal matrix restricted to the free unknowns.
pub fn assemble(objective: &Objective, unknowns: &Unknowns, coefficients: &TimeCoefficients) -> SparseColMat<usize, f64> {
    let el = objective.elastic;
    let n = el.node_count();
    let inv_mass: Vec<f64> = el.mass.iter().map(|m| 1.0 / m).collect();
    let k = el.stiffness.sandwich_diagonal(&inv_mass);
    let l = &el.stiffness;
    let s_count = coefficients.slots;
    let (mm, ml, kk) = (&coefficients.mm, &coefficients.ml, &coefficients.kk);
    // Columns of node b, for every b in parallel: (column lengths, rows, values).
    let blocks: Vec<(Vec<usize>, Vec<usize>, Vec<f64>)> = (0..n)
        .into_par_iter()
        .map(|b| {
            let (mut lens, mut rows, mut vals) = (Vec::new(), Vec::new(), Vec::new());
            let neighbours: Vec<(usize, f64, f64)> = k
                .row(b)
                .filter(|&(a, _)| a >= b)
                .map(|(a, kab)| (a, l.get(a, b), kab))
                .collect();
            for s2 in 0..s_count {
                if unknowns.get(b, s2).is_none() {
                    continue;
                }
                let start = rows.len();
                for &(a, lab, kab) in &neighbours {
                    let mab = if a == b { el.mass[a] } else { 0.0 };
                    for s1 in 0..s_count {
                        if a == b && s1 < s2 {
                            continue;
                        }
                        let Some(u) = unknowns.get(a, s1) else { continue };
                        let at = s1 * s_count + s2;
                        if !((a == b && mm[at] != 0.0) || ml[at] != 0.0 || kk[at] != 0.0) {
                            continue;
                        }
                        rows.push(u);
                        vals.push(mm[at] * mab + ml[at] * lab + kk[at] * kab);
                    }
                }
                lens.push(rows.len() - start);
            }
            (lens, rows, vals)
        })
        .collect();
    let dim = unknowns.count();
    let mut col_ptr = Vec::with_capacity(dim + 1);
    col_ptr.push(0usize);
    let total: usize = blocks.iter().map(|b| b.1.len()).sum();
    let (mut rows, mut vals) = (Vec::with_capacity(total), Vec::with_capacity(total));
    for (lens, r, v) in blocks {
        for len in lens {
            col_ptr.push(col_ptr.last().unwrap() + len);
        }
        rows.extend(r);
        vals.extend(v);
    }
    // The checked constructor validates sortedness and bounds.
    let symbolic = SymbolicSparseColMat::new_checked(dim, dim, col_ptr, None, rows);
    SparseColMat::new(symbolic, vals)
}

/// Predicted flops above which the numeric factorization runs in parallel (measured on 2
/// cores: 0.37 G flops, DINO: 24-40 ms sequential, 31-55 ms parallel; 2.6 G, TWIST: 101-134 ms
/// vs 77-106 ms; 85 G, ARMADILLO-size: 2.3 s vs 1.4 s).
const PARALLEL_FACTOR_FLOPS: f64 = 1e9;

/// A fill-reducing order of the unknowns and how it was found.
pub struct FillReducingOrder {
    /// `perm[k]` = the unknown eliminated k-th.
    pub perm: Vec<usize>,
    pub name: &'static str,
    /// Predicted cost of the factorization in this order.
    pub cost: Cost,
}

/// Order the normal matrix by its node graph: every node's free slots are contiguous unknowns
/// (node-major layout) and stay together, so ordering the 2-ring graph of the nodes (a few
/// thousand vertices) orders the matrix (tens of thousands of rows).
///
/// Two candidates, and the one with fewer predicted flops wins: geometric nested dissection
/// (best on large 3D bodies: 85 G vs 101 G flops for minimum degree on the 2.6k-node benchmark
/// body, whose matrix faer's AMD orders to 127 G) and minimum degree (better on small or thin
/// bodies: 0.37 G vs 0.98 G on DINO). Both and their predictions take about 60 ms on the
/// 2.6k-node body. The winner is put in postorder of its elimination tree (same fill), which
/// lets the solve give whole subtrees to two threads.
pub fn fill_reducing_order(lower: &SparseColMat<usize, f64>, unknowns: &Unknowns, rest: &[Point]) -> FillReducingOrder {
    let nodes = unknowns.nodes;
    let slots = unknowns.slots.count();
    let mut block_of = vec![0u32; unknowns.count()];
    let mut block_start = vec![0usize; nodes + 1];
    for a in 0..nodes {
        let mut count = 0;
        for s in 0..slots {
            if let Some(u) = unknowns.get(a, s) {
                block_of[u] = a as u32;
                count += 1;
            }
        }
        block_start[a + 1] = block_start[a] + count;
    }
    let graph = Graph::of_blocks(lower.symbolic().col_ptr(), lower.symbolic().row_idx(), &block_of, nodes);
    let weights: Vec<usize> = (0..nodes).map(|a| block_start[a + 1] - block_start[a]).collect();
    let dissection = nested_dissection(&graph, rest);
    let degree = minimum_degree(&graph);
    let (cost_nd, cost_md) = (predicted_cost(&graph, &dissection, &weights), predicted_cost(&graph, &degree, &weights));
    let (order, name, cost) = if cost_nd.flops <= cost_md.flops {
        (dissection, "nested dissection (nodes)", cost_nd)
    } else {
        (degree, "minimum degree (nodes)", cost_md)
    };
    FillReducingOrder { perm: expand(&postorder(&graph, &order), &block_start), name, cost }
}

impl GlobalStep {
    /// Assemble and factorize. `regularization` is the proximal time scale h (0 = off).
    pub fn new(objective: &Objective, unknowns: Unknowns, regularization: f64) -> Result<GlobalStep> {
        let proximal = if regularization > 0.0 { 1.0 / regularization.powi(4) } else { 0.0 };
        if proximal == 0.0 && unknowns.count() > 0 && !unknowns.any_position_fixed() {
            // Singular by construction; a factorization may still pass on roundoff pivots.
            return Err(Error::general(
                "the spacetime system is singular: no keyframe position is held and regularization = 0, so moving the whole animation costs nothing",
                "fix some vertices at one key (`fixed`), or set [solver] regularization > 0 (e.g. 0.1)",
            ));
        }
        let t0 = std::time::Instant::now();
        let coefficients = TimeCoefficients::new(objective, proximal);
        let dim = unknowns.count();
        if dim == 0 {
            let stats =
                GlobalStats { unknowns: 0, matrix_nnz: 0, factor_nnz: 0, ordering: "none", assemble_seconds: 0.0, factor_seconds: 0.0 };
            return Ok(GlobalStep { unknowns, cholesky: None, coupling: coupling(&coefficients), stats });
        }
        let a = assemble(objective, &unknowns, &coefficients);
        let assemble_seconds = t0.elapsed().as_secs_f64();
        let t1 = std::time::Instant::now();
        let order = fill_reducing_order(&a, &unknowns, &objective.elastic.rest);
        // faer's parallel supernodal factorization pays off only for large fronts.
        let par = if order.cost.flops > PARALLEL_FACTOR_FLOPS { Par::rayon(0) } else { Par::Seq };
        let cholesky = Cholesky::factor(&a, &FillOrdering::Custom(order.perm), par).map_err(|_| {
            Error::general(
                "the spacetime system is singular: some motion (e.g. drifting or spinning freely) costs nothing",
                "fix some vertices at one key (`fixed`), or set [solver] regularization > 0 (e.g. 0.1)",
            )
        })?;
        let stats = GlobalStats {
            unknowns: dim,
            matrix_nnz: a.compute_nnz(),
            factor_nnz: cholesky.factor_nnz(),
            ordering: order.name,
            assemble_seconds,
            factor_seconds: t1.elapsed().as_secs_f64(),
        };
        Ok(GlobalStep { unknowns, cholesky: Some(cholesky), coupling: coupling(&coefficients), stats })
    }

    /// Rebuild for new key times, `objective` holding the samples at those times: the time
    /// coefficients and the matrix values change, the pattern does not (unless a coefficient
    /// cancels exactly), so the factor is recomputed numerically on the kept ordering and
    /// symbolic analysis. With a changed pattern it falls back to [`GlobalStep::new`].
    pub fn retime(&mut self, objective: &Objective, regularization: f64) -> Result<Retimed> {
        let t0 = std::time::Instant::now();
        let proximal = if regularization > 0.0 { 1.0 / regularization.powi(4) } else { 0.0 };
        let coefficients = TimeCoefficients::new(objective, proximal);
        let Some(cholesky) = self.cholesky.as_mut().filter(|_| coupling(&coefficients) == self.coupling) else {
            *self = GlobalStep::new(objective, self.unknowns.clone(), regularization)?;
            let s = self.stats;
            return Ok(Retimed { assemble_seconds: s.assemble_seconds, factor_seconds: s.factor_seconds, reused_symbolic: false });
        };
        let a = assemble(objective, &self.unknowns, &coefficients);
        let assemble_seconds = t0.elapsed().as_secs_f64();
        let t1 = std::time::Instant::now();
        cholesky.refactor(&a).map_err(|_| {
            Error::general(
                "the spacetime system became singular at the new key times",
                "keep [solver] regularization > 0, or raise the minimum interval length",
            )
        })?;
        Ok(Retimed { assemble_seconds, factor_seconds: t1.elapsed().as_secs_f64(), reused_symbolic: true })
    }

    /// The free unknowns and their order.
    pub fn unknowns(&self) -> &Unknowns {
        &self.unknowns
    }

    /// The free entries of a per-slot array, in unknown order.
    pub fn gather(&self, per_slot: &[Vec<Point>]) -> Vec<Point> {
        let u = &self.unknowns;
        let mut out = vec![[0.0; 3]; u.count()];
        for (s, values) in per_slot.iter().enumerate() {
            for (a, v) in values.iter().enumerate() {
                if let Some(i) = u.get(a, s) {
                    out[i] = *v;
                }
            }
        }
        out
    }

    /// A per-slot array from free entries (zero at fixed entries).
    pub fn scatter(&self, free: &[Point]) -> Vec<Vec<Point>> {
        let u = &self.unknowns;
        let mut out = vec![vec![[0.0; 3]; u.nodes]; u.slots.count()];
        for (s, values) in out.iter_mut().enumerate() {
            for (a, v) in values.iter_mut().enumerate() {
                if let Some(i) = u.get(a, s) {
                    *v = free[i];
                }
            }
        }
        out
    }

    /// `x <- (H + P)⁻¹ x` on free entries, the three coordinates as three right-hand sides.
    pub fn apply_inverse(&self, x: &mut [Point]) {
        let Some(chol) = &self.cholesky else { return };
        chol.solve_rows3(x);
    }

    /// The step `Δ = -(H + P)⁻¹ ∇W` per slot (zero at fixed entries).
    pub fn step(&self, gradient: &[Vec<Point>]) -> Vec<Vec<Point>> {
        let mut g = self.gather(gradient);
        self.apply_inverse(&mut g);
        g.iter_mut().for_each(|v| *v = crate::mesh::scale(*v, -1.0));
        self.scatter(&g)
    }
}
