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
//! nodes (`M⁻¹` in the middle of `L M⁻¹ L` skips the supports, whose rows W leaves out). The proximal regularization `(1/h⁴) Σ dτ Bᵀ M B` adds `C_KK / h⁴` to `C_MM`
//! (in the M⁻¹ norm of W, 1/h⁴ is the weight whose units make h a time). The
//! matrix restricted to the free unknowns is written straight into compressed columns in
//! node-major order (rows come out sorted; no triplet sort), and the three coordinates are
//! three right-hand sides of one factorization.
//!
//! Cost: `L M⁻¹ L` couples nodes two rings apart, so the factor fills in heavily (50M entries
//! for 25k unknowns on a 2.6k-node body). Every node's free slots stay together: the
//! fill-reducing order is found on the node graph ([`fill_reducing_order_of`]), the numeric
//! factorization is supernodal over faer's symbolic analysis, the two halves of the
//! elimination tree on two threads above 1 G predicted flops ([`Cholesky::refactor`]), and the
//! solves sweep the factor once per direction for all three coordinates, on two threads
//! ([`Cholesky::solve_rows3`]).
//!
//! Bounded: the factor's size and time are predicted from the symbolic count before anything
//! is allocated ([`fill_reducing_order_of`]), and when the predicted peak is over the memory
//! budget the step is solved by preconditioned conjugate gradients instead (per-key block
//! Jacobi, warm-started from the previous solution; see [`crate::algorithms::physics::pcg`]): slower per
//! iteration, but in memory that grows like the matrix, not like its factor.
//!
//! The step itself is the minimizer of the quadratic model plus the proximal term around the
//! current iterate `q`: `q + Δ` with `(H + P) Δ = -∇W`. At a fixed point `∇W = 0`, so the
//! regularization never moves the fixed point; it only damps the path to it.

use faer::sparse::{SparseColMat, SymbolicSparseColMat};
use faer::Par;
use rayon::prelude::*;

use super::modal::{ModalStep, Modes};
use super::objective::Objective;
use super::unknowns::Unknowns;
use crate::algorithms::geometry::Point;
use crate::algorithms::physics::cholesky::{Cholesky, PARALLEL_FACTOR_FLOPS};
use crate::algorithms::physics::csr::Csr;
use crate::algorithms::physics::ordering::{expand, minimum_degree, nested_dissection, postorder, predicted_cost, Cost, FillOrdering, Graph};
use crate::algorithms::physics::pcg::{pcg, BlockJacobi, SymmetricOperator};
use crate::support::error::{Error, Result};

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
    /// Ordering, symbolic analysis and numeric factorization (or the preconditioner's).
    pub factor_seconds: f64,
    /// The direct factor's predicted peak memory in bytes (see `predicted_peak_bytes`), and
    /// its predicted factorization time.
    pub predicted_bytes: f64,
    /// See `predicted_bytes`.
    pub predicted_seconds: f64,
    /// `"direct"` (sparse Cholesky), or `"iterative"` when the predicted peak was over the
    /// memory budget or the predicted time of the iterative step was lower (`choose`).
    pub linear_solver: &'static str,
    /// The iterative step's predicted peak memory and time (see `choose`).
    pub predicted_iterative_bytes: f64,
    /// See `predicted_iterative_bytes`.
    pub predicted_iterative_seconds: f64,
    /// The modal step's predicted peak memory and time (see `choose`; 0 when there are no unknowns).
    pub predicted_modal_bytes: f64,
    /// See `predicted_modal_bytes`.
    pub predicted_modal_seconds: f64,
}

/// Seconds per stored factor entry of one solve with three right-hand sides (both sweeps read
/// every entry once), on one thread and on two (the solve splits the elimination tree's two
/// subtrees over the cores): 87M entries in 0.126 CPU s on one thread; ARMADILLO-size's 50M
/// entries in 0.046 s a global step on two, idle.
const SWEEP_SECONDS_PER_ENTRY: [f64; 2] = [1.45e-9, 0.92e-9];

/// Global-step solves a bake is assumed to make (one per iteration, local/global and
/// quasi-Newton alike; the converged-by-default stopping rule: TWIST 120 iterations, DINO 150,
/// the demo 140, the 20-key body over 180), and CG iterations per iterative solve (measured at
/// 20 keys on 2.7k nodes: 37-46 with the warm start).
const ASSUMED_SOLVES: f64 = 150.0;
/// See [`ASSUMED_SOLVES`].
const ASSUMED_CG_ITERATIONS: f64 = 40.0;

/// One CG iteration costs about this many preconditioner sweeps (the matrix-free product and
/// the vector updates add about 30%, measured).
const CG_ITERATION_PER_SWEEP: f64 = 1.3;

/// The global step's three ways to invert its matrix.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Method {
    /// Sparse Cholesky of the assembled matrix.
    Direct,
    /// The body's vibration modes ([`super::modal`]).
    Modal,
    /// Conjugate gradients with the per-key blocks.
    Iterative,
}

/// The size of the modal step: basis nodes, time slots, held entries in the basis and the
/// nodes they are on (see [`super::modal`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ModalSize {
    /// Nodes of the basis (every node but the supports).
    pub nodes: usize,
    /// Time slots.
    pub slots: usize,
    /// (node, slot) entries of the basis nodes that are held rather than free.
    pub held: usize,
    /// Basis nodes with at least one held slot.
    pub held_nodes: usize,
}

impl ModalSize {
    /// Predicted (seconds, peak bytes) of building the modal step and [`ASSUMED_SOLVES`] solves:
    /// the eigendecomposition (`EIGEN_SECONDS_PER_NODE3 n³`), the capacitance matrix (`c² n`
    /// flops) and its factor (`c³ / 3`), and per solve the two products with `Φ`
    /// (`2 × 2 n² × 3 slots` flops), the two with the held rows of `Φ`, the capacitance solve and
    /// the per-mode systems, times [`MODAL_SOLVE_OVERHEAD`].
    pub fn predicted(&self) -> (f64, f64) {
        let (n, s, c, h) = (self.nodes as f64, self.slots as f64, self.held as f64, self.held_nodes as f64);
        let setup = EIGEN_SECONDS_PER_NODE3 * n * n * n + (c * c * n + c * c * c / 3.0) / DENSE_FLOPS_PER_SECOND;
        let solve = MODAL_SOLVE_OVERHEAD
            * (2.0 * 2.0 * n * n * 3.0 * s + 2.0 * 2.0 * h * n * 3.0 * s + 2.0 * 3.0 * c * c + 2.0 * 2.0 * 3.0 * n * s * s)
            / DENSE_FLOPS_PER_SECOND;
        let seconds = setup + ASSUMED_SOLVES * solve;
        let bytes = 8.0 * (MODAL_COPIES * n * n + n * s * s + 2.0 * c * c + h * n + 2.0 * 3.0 * s * n);
        (seconds, bytes)
    }
}

/// Seconds of the dense symmetric eigendecomposition (tridiagonalization, divide-and-conquer
/// eigenvectors, back-transformation) per cubed node count on 2 cores. Measured at 2744 nodes:
/// 5.7-6.8 CPU s (2.8e-10 to 3.3e-10 per n³, on one thread or two), 16 s wall on two threads
/// against 23 s on one under the same load: 1.4x from the second core.
const EIGEN_SECONDS_PER_NODE3: f64 = 2.2e-10;
/// Flops per second of faer's dense products as the modal step uses them (measured at 2744
/// nodes, 20 keys: the capacitance matrix of 3920 held entries, 6.2e10 flops, in 2.0-2.2 CPU s;
/// one solve's 4.0e9 flops in 0.13 CPU s on one thread; a lone 120 x 2744 x 2744 product runs
/// at 4.5e10 per CPU second).
const DENSE_FLOPS_PER_SECOND: f64 = 3.0e10;
/// A modal solve's time over its products' flops at [`DENSE_FLOPS_PER_SECOND`] (gathering and
/// scattering the unknowns, the per-mode systems' memory traffic): measured 1.0-1.4 at 20 keys
/// (0.13-0.19 CPU s), 1.7-2.8 at 5 keys (0.055-0.094 CPU s for 1e9 flops).
const MODAL_SOLVE_OVERHEAD: f64 = 1.5;
/// `n × n` matrices alive at the modal step's peak (the eigenproblem, its eigenvectors and
/// the decomposition's workspace).
const MODAL_COPIES: f64 = 3.0;

/// The cost model: predicted (seconds, bytes) of a bake's global steps, direct (factorize
/// once, then [`ASSUMED_SOLVES`] solves), iterative (the per-key blocks factorized once, then
/// [`ASSUMED_SOLVES`] CG solves of [`ASSUMED_CG_ITERATIONS`] iterations each) and, when
/// `modal` is given, modal ([`ModalSize::predicted`]). Returns the fastest whose peak fits in
/// `budget` (the iterative step when none does), and the (seconds, bytes) of the three (the
/// modal ones 0 without `modal`).
pub fn choose(direct: &Cost, blocks: &Cost, modal: Option<&ModalSize>, parallel: bool, budget: u64) -> (Method, [(f64, f64); 3]) {
    let rate = FACTOR_FLOPS_PER_SECOND[parallel as usize];
    let direct_seconds = direct.flops / rate + ASSUMED_SOLVES * direct.entries * SWEEP_SECONDS_PER_ENTRY[parallel as usize];
    let iterative_seconds = blocks.flops / FACTOR_FLOPS_PER_SECOND[0]
        + ASSUMED_SOLVES * ASSUMED_CG_ITERATIONS * CG_ITERATION_PER_SWEEP * blocks.entries * SWEEP_SECONDS_PER_ENTRY[0];
    let (direct_bytes, iterative_bytes) = (predicted_peak_bytes(direct), predicted_peak_bytes(blocks));
    // Weighed on every body: on small ones too the modes can win, their solves being two dense
    // products that stay in cache where the factor's sweeps do not (the demo: 182 nodes,
    // 1.0 ms a direct solve against 0.2 ms a modal one).
    let modal_cost = modal.map(ModalSize::predicted);
    let candidates = [
        (Method::Direct, direct_seconds, direct_bytes),
        (Method::Modal, modal_cost.map_or(f64::INFINITY, |c| c.0), modal_cost.map_or(f64::INFINITY, |c| c.1)),
        (Method::Iterative, iterative_seconds, iterative_bytes),
    ];
    let method = candidates.iter().filter(|c| c.2 <= budget as f64).min_by(|a, b| a.1.total_cmp(&b.1)).map_or(Method::Iterative, |c| c.0);
    let modal_cost = modal_cost.unwrap_or((0.0, 0.0));
    (method, [(direct_seconds, direct_bytes), modal_cost, (iterative_seconds, iterative_bytes)])
}

/// The modal step's size for these unknowns.
fn modal_size(objective: &Objective, unknowns: &Unknowns) -> ModalSize {
    let slots = unknowns.slots.count();
    let (mut nodes, mut held, mut held_nodes) = (0, 0, 0);
    for a in (0..unknowns.nodes).filter(|&a| !objective.supports[a]) {
        nodes += 1;
        let h = (0..slots).filter(|&s| unknowns.get(a, s).is_none()).count();
        held += h;
        held_nodes += (h > 0) as usize;
    }
    ModalSize { nodes, slots, held, held_nodes }
}

/// The order of every key's block in the iterative step's preconditioner, and the blocks'
/// predicted cost: the node graph ordered by the better of nested dissection and minimum
/// degree, two unknowns (position, velocity) per node and key.
fn key_block_order(orders: &NodeOrders, unknowns: &Unknowns) -> (Vec<u32>, Cost) {
    let graph = &orders.graph;
    let weights = vec![2usize; unknowns.nodes];
    let (cost_nd, cost_md) = (predicted_cost(graph, &orders.dissection, &weights), predicted_cost(graph, &orders.degree, &weights));
    let keys = (unknowns.slots.count() / 2) as f64;
    let (order, cost) = if cost_nd.flops <= cost_md.flops { (&orders.dissection, cost_nd) } else { (&orders.degree, cost_md) };
    (order.clone(), Cost { flops: keys * cost.flops, entries: keys * cost.entries })
}

/// The node graph of the normal matrix (its vertices the nodes, its edges the nodes' coupled
/// unknowns) and its two candidate orders, computed once for both the direct step's order
/// ([`fill_reducing_order_of`]) and the iterative step's key blocks (`key_block_order`):
/// the graph is the same for both, only the weights of its vertices differ.
pub struct NodeOrders {
    graph: Graph,
    dissection: Vec<u32>,
    degree: Vec<u32>,
}

impl NodeOrders {
    /// Geometric nested dissection (at the nodes' `rest` positions) and minimum degree of the
    /// node graph of `lower`.
    pub fn new(lower: &SparseColMat<usize, f64>, unknowns: &Unknowns, rest: &[Point]) -> NodeOrders {
        let graph = Graph::of_blocks(lower.symbolic().col_ptr(), lower.symbolic().row_idx(), &node_blocks(unknowns), unknowns.nodes);
        let (dissection, degree) = (nested_dissection(&graph, rest), minimum_degree(&graph));
        NodeOrders { graph, dissection, degree }
    }
}

/// Bytes a direct factorization needs per predicted factor entry, measured as the whole
/// process's peak over the predicted entries (`factor_peak_memory`; cube-13, 5 keys, 6.86e7
/// entries predicted: 949 MB with our two-thread factorization, 915 MB with faer's: 13.8 and
/// 13.3 bytes per entry; at 20 keys, 7.66e8 entries, ours: 8,660 MB, 11.3 bytes). What it
/// holds: the factor's values, 8
/// bytes per stored entry, and faer's supernodes store 1.26 entries per predicted one (their
/// relaxed patterns' explicit zeros): 10.1 bytes; the assembled matrix and, while it is
/// factorized, its copy in the factor's order (16 bytes per matrix entry each: 1.7 bytes per
/// factor entry at 5 keys, 0.7 at 20); the numeric scratch (the update products, 64 columns at
/// a time, and the dense kernels', about 1%); and the rest of the process. The rest shrinks
/// per entry with more keys, so one constant over-predicts many keys (by 24% at 20); it is
/// set to the 5-key measurement so that no measured factorization exceeds its prediction.
/// (Closer: 10.1 bytes per predicted entry plus about 65 per matrix entry, measured 59-72.)
pub const BYTES_PER_FACTOR_ENTRY: f64 = 14.0;

/// The predicted peak memory of a direct solve with `cost`.
pub fn predicted_peak_bytes(cost: &Cost) -> f64 {
    BYTES_PER_FACTOR_ENTRY * cost.entries
}

/// Predicted flops per second of the numeric factorization ([`Cholesky::refactor`]), on one
/// thread and on two. One: 3.28-3.36e10 per CPU second (`factor_on_two_cores`, cube-13 at 5
/// keys, 2.19e11 flops, `Par::Seq`; CPU time holds under load, measured at load average 6-9).
/// Two: that times 1.58, the ratio of the phases' thread CPU seconds (both groups, both top
/// halves, the dense blocks) to the critical path of the split (the longer group, the longer
/// half of each top supernode, the dense blocks counted on one core); a wall-clock ratio needs
/// an idle machine (faer's own parallel factorization gave 1.6x on 85 G flops idle).
const FACTOR_FLOPS_PER_SECOND: [f64; 2] = [3.3e10, 5.2e10];

/// The default memory budget: the bake's one budget ([`crate::support::resources::memory_budget`]:
/// `--max-memory`, else 60% of `MemAvailable`), or 4 GiB when that cannot be read.
pub fn default_memory_budget() -> u64 {
    crate::support::resources::memory_budget().map_or(4 << 30, |bytes| bytes as u64)
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
pub fn proximal_weight(objective: &Objective, regularization: f64) -> f64 {
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

/// The normal matrix as the Kronecker sum it is, `C_MM ⊗ M + C_ML ⊗ L + C_KK ⊗ L M⁻¹ L`
/// restricted to the free unknowns, applied without assembling it: per time slot two sparse
/// products with `L` over the nodes, then the banded time coefficients mix the slots. A product
/// costs about `slots × 2 nnz(L)` instead of the assembled matrix's `nnz(A)` (2.6k nodes, 20
/// keys: 40 × 2 × 40k against about 30M entries), and nothing of the size of `A` is kept.
struct KroneckerSum {
    unknowns: Unknowns,
    mass: Vec<f64>,
    /// `1/m` at free nodes, 0 at supports (their rows are not in W).
    inv_mass: Vec<f64>,
    stiffness: Csr,
    /// Per slot σ: the slots σ' it is coupled to, with `(C_MM, C_ML, C_KK)[σ, σ']`.
    coupled: Vec<Vec<(usize, [f64; 3])>>,
}

impl KroneckerSum {
    fn new(objective: &Objective, unknowns: &Unknowns, c: &TimeCoefficients) -> KroneckerSum {
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
fn node_blocks(unknowns: &Unknowns) -> Vec<u32> {
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
struct Iterative {
    operator: KroneckerSum,
    preconditioner: BlockJacobi,
    /// The previous solution, the next solve's start.
    previous: std::sync::Mutex<Option<Vec<Point>>>,
    /// How the solves went.
    log: std::sync::Mutex<CgLog>,
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
    /// Solves that stopped at [`CG_MAX_ITERATIONS`] above [`CG_TOLERANCE`].
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
const CG_TOLERANCE: f64 = 1e-10;

/// CG iterations per solve at most.
const CG_MAX_ITERATIONS: usize = 5000;

/// How the global step is inverted.
enum Inverse {
    Direct(Box<Cholesky>),
    Modal(Box<ModalStep>),
    Iterative(Box<Iterative>),
}

/// The normal matrix of the free unknowns, factorized: solves the global step.
pub struct GlobalStep {
    unknowns: Unknowns,
    /// None when there are no unknowns.
    cholesky: Option<Inverse>,
    /// The memory budget it was built under, in bytes.
    budget: u64,
    /// Which time-slot pairs the matrix couples ([`coupling`]): the matrix pattern depends on
    /// the time coefficients only through this, so equal couplings mean equal patterns.
    coupling: Vec<(bool, bool)>,
    /// What the precomputation built.
    pub stats: GlobalStats,
}

/// How [`GlobalStep::retime`] rebuilt the factorization.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Retimed {
    /// Seconds assembling the matrix (0 for the modal step, whose modes do not change).
    pub assemble_seconds: f64,
    /// Seconds refactorizing it (for the modal step: rebuilding its per-mode systems).
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
    // Supports' rows are not in W: the sum over the middle node of L M⁻¹ L skips them (the
    // other two blocks only couple free nodes, which are never supports).
    let inv_mass: Vec<f64> = el.mass.iter().zip(&objective.supports).map(|(m, &support)| if support { 0.0 } else { 1.0 / m }).collect();
    let k = el.stiffness.sandwich_diagonal(&inv_mass);
    let l = &el.stiffness;
    let s_count = coefficients.slots;
    let (mm, ml, kk) = (&coefficients.mm, &coefficients.ml, &coefficients.kk);
    // Columns of node b, for every b in parallel: (column lengths, rows, values).
    let blocks: Vec<(Vec<usize>, Vec<usize>, Vec<f64>)> = (0..n)
        .into_par_iter()
        .map(|b| {
            let (mut lens, mut rows, mut vals) = (Vec::new(), Vec::new(), Vec::new());
            let neighbours: Vec<(usize, f64, f64)> = k.row(b).filter(|&(a, _)| a >= b).map(|(a, kab)| (a, l.get(a, b), kab)).collect();
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

/// A fill-reducing order of the unknowns and how it was found.
pub struct FillReducingOrder {
    /// `perm[k]` = the unknown eliminated k-th.
    pub perm: Vec<usize>,
    /// Which candidate won, for the report (e.g. `nested dissection (nodes)`).
    pub name: &'static str,
    /// Predicted cost of the factorization in this order.
    pub cost: Cost,
}

/// [`fill_reducing_order_of`] with the node graph's orders computed here.
#[cfg(test)]
pub fn fill_reducing_order(
    lower: &SparseColMat<usize, f64>,
    unknowns: &Unknowns,
    rest: &[Point],
    weigh_keys: impl FnOnce(&Cost) -> bool,
) -> FillReducingOrder {
    fill_reducing_order_of(lower, unknowns, &NodeOrders::new(lower, unknowns, rest), weigh_keys)
}

/// Order the normal matrix by its node graph: every node's free slots are contiguous unknowns
/// (node-major layout) and stay together, so ordering the 2-ring graph of the nodes (a few
/// thousand vertices) orders the matrix (tens of thousands of rows).
///
/// Two candidates, and the one with fewer predicted flops wins: geometric nested dissection
/// (best on large 3D bodies: 85 G vs 101 G flops for minimum degree on the 2.6k-node benchmark
/// body, whose matrix faer's AMD orders to 127 G) and minimum degree (better on small or thin
/// bodies: 0.37 G vs 0.98 G on DINO). Both and their predictions take about 60 ms on the
/// 2.6k-node body. With many keys a third candidate is weighed on the finer graph of (node,
/// key) blocks: the keys as the top-level separators (the middle key last, each half ordered
/// the same way, every key's nodes in the better node order), which cuts the fill that the
/// coupling of neighbouring keys causes once there are more than about ten keys
/// ([`KEY_SEPARATOR_MIN_KEYS`]). The winner is put in postorder of its elimination tree (same
/// fill), which lets the solve give whole subtrees to two threads.
///
/// The key-separator candidate is weighed only when `weigh_keys` says so for the node order's
/// cost: its graph of (node, key) blocks and two symbolic counts took 1.3 of the 10 CPU s of a
/// modal step's set-up at 20 keys on 2.7k nodes, so [`GlobalStep::build`] skips it when only a
/// direct step could use it.
///
/// `orders` are the node graph's orders ([`NodeOrders`]), shared with the iterative step's key blocks.
pub fn fill_reducing_order_of(
    lower: &SparseColMat<usize, f64>,
    unknowns: &Unknowns,
    orders: &NodeOrders,
    weigh_keys: impl FnOnce(&Cost) -> bool,
) -> FillReducingOrder {
    let nodes = unknowns.nodes;
    let slots = unknowns.slots.count();
    let mut block_start = vec![0usize; nodes + 1];
    for a in 0..nodes {
        block_start[a + 1] = block_start[a] + (0..slots).filter(|&s| unknowns.get(a, s).is_some()).count();
    }
    let graph = &orders.graph;
    let weights: Vec<usize> = (0..nodes).map(|a| block_start[a + 1] - block_start[a]).collect();
    let (cost_nd, cost_md) = (predicted_cost(graph, &orders.dissection, &weights), predicted_cost(graph, &orders.degree, &weights));
    let (order, name, cost) = if cost_nd.flops <= cost_md.flops {
        (&orders.dissection, "nested dissection (nodes)", cost_nd)
    } else {
        (&orders.degree, "minimum degree (nodes)", cost_md)
    };
    let keys = slots / 2;
    if keys >= KEY_SEPARATOR_MIN_KEYS && weigh_keys(&cost) {
        if let Some(by_keys) = key_separator_order(lower, unknowns, order) {
            if by_keys.cost.flops < by_keys.node_cost.flops {
                return FillReducingOrder { perm: by_keys.perm, name: "keys as separators, nodes inside", cost: by_keys.cost };
            }
        }
    }
    FillReducingOrder { perm: expand(&postorder(graph, order), &block_start), name, cost }
}

/// Keys (slot pairs) from which the key-separator order is weighed (measured: 2.5x fewer
/// predicted flops at 20 keys on a 1k-node body, 1.3x on 2.6k, worse at 10 keys or fewer).
pub const KEY_SEPARATOR_MIN_KEYS: usize = 8;

/// The most the key-separator order is assumed to cut the node order's predicted flops and
/// factor entries (measured at most 2.5x: 20 keys on a 1k-node body), for skipping it when even
/// that cut could not make the direct step the choice ([`GlobalStep::build`]).
pub const KEY_SEPARATOR_MAX_GAIN: f64 = 4.0;

/// The key-separator candidate, with the node order's cost on the same (node, key) graph so
/// that the two compare exactly.
struct KeySeparators {
    perm: Vec<usize>,
    cost: Cost,
    node_cost: Cost,
}

/// See [`fill_reducing_order_of`]. Blocks are (node `a`, key `k`) with id `k * nodes + a`, holding
/// that node's free position and velocity of key `k`.
fn key_separator_order(lower: &SparseColMat<usize, f64>, unknowns: &Unknowns, node_order: &[u32]) -> Option<KeySeparators> {
    let nodes = unknowns.nodes;
    let keys = unknowns.slots.count() / 2;
    let mut block_of = vec![0u32; unknowns.count()];
    let mut members: Vec<Vec<usize>> = vec![Vec::new(); nodes * keys];
    for a in 0..nodes {
        for s in 0..2 * keys {
            if let Some(u) = unknowns.get(a, s) {
                let b = (s / 2) * nodes + a;
                block_of[u] = b as u32;
                members[b].push(u);
            }
        }
    }
    let blocks = nodes * keys;
    if blocks > u32::MAX as usize {
        return None;
    }
    let graph = Graph::of_blocks(lower.symbolic().col_ptr(), lower.symbolic().row_idx(), &block_of, blocks);
    let weights: Vec<usize> = members.iter().map(Vec::len).collect();
    fn bisect(lo: usize, hi: usize, nodes: usize, node_order: &[u32], out: &mut Vec<u32>) {
        if lo >= hi {
            return;
        }
        let m = if hi - lo == 1 { lo } else { (lo + hi) / 2 };
        if hi - lo > 1 {
            bisect(lo, m, nodes, node_order, out);
            bisect(m + 1, hi, nodes, node_order, out);
        }
        out.extend(node_order.iter().map(|&a| (m * nodes + a as usize) as u32));
    }
    let mut by_keys = Vec::with_capacity(blocks);
    bisect(0, keys, nodes, node_order, &mut by_keys);
    let by_nodes: Vec<u32> = node_order.iter().flat_map(|&a| (0..keys).map(move |k| (k * nodes + a as usize) as u32)).collect();
    let (cost, node_cost) = (predicted_cost(&graph, &by_keys, &weights), predicted_cost(&graph, &by_nodes, &weights));
    let perm = postorder(&graph, &by_keys).iter().flat_map(|&b| members[b as usize].iter().copied()).collect();
    Some(KeySeparators { perm, cost, node_cost })
}

impl GlobalStep {
    /// Assemble and factorize under the default memory budget ([`default_memory_budget`]).
    /// `regularization` is the proximal time scale h (0 = off).
    pub fn new(objective: &Objective, unknowns: Unknowns, regularization: f64) -> Result<GlobalStep> {
        GlobalStep::within(objective, unknowns, regularization, None)
    }

    /// Assemble, and factorize when the predicted peak fits in `max_memory` bytes (default:
    /// [`default_memory_budget`]); otherwise prepare the iterative step.
    pub fn within(objective: &Objective, unknowns: Unknowns, regularization: f64, max_memory: Option<u64>) -> Result<GlobalStep> {
        GlobalStep::build(objective, unknowns, regularization, max_memory, None)
    }

    /// [`GlobalStep::within`], inverted by `method` when given (whatever the cost model says).
    pub fn build(
        objective: &Objective,
        unknowns: Unknowns,
        regularization: f64,
        max_memory: Option<u64>,
        method: Option<Method>,
    ) -> Result<GlobalStep> {
        let forced = method;
        let budget = max_memory.unwrap_or_else(default_memory_budget);
        let proximal = proximal_weight(objective, regularization);
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
            let stats = GlobalStats {
                unknowns: 0,
                matrix_nnz: 0,
                factor_nnz: 0,
                ordering: "none",
                assemble_seconds: 0.0,
                factor_seconds: 0.0,
                predicted_bytes: 0.0,
                predicted_seconds: 0.0,
                linear_solver: "none",
                predicted_iterative_bytes: 0.0,
                predicted_iterative_seconds: 0.0,
                predicted_modal_bytes: 0.0,
                predicted_modal_seconds: 0.0,
            };
            return Ok(GlobalStep { unknowns, cholesky: None, budget, coupling: coupling(&coefficients), stats });
        }
        let a = assemble(objective, &unknowns, &coefficients);
        let assemble_seconds = t0.elapsed().as_secs_f64();
        let t1 = std::time::Instant::now();
        // One node graph and its two orders for both candidates' orders.
        let node_orders = NodeOrders::new(&a, &unknowns, &objective.elastic.rest);
        let (block_order, block_cost) = key_block_order(&node_orders, &unknowns);
        let size = modal_size(objective, &unknowns);
        // The key-separator order only where the direct step could use it: even cut by
        // KEY_SEPARATOR_MAX_GAIN and factorized at the parallel rate, would the node order's
        // cost make the direct step the choice? When not, the choice below is the same with or
        // without it.
        let could_be_direct = |node: &Cost| match forced {
            Some(m) => m == Method::Direct,
            None => {
                let optimistic = Cost { flops: node.flops / KEY_SEPARATOR_MAX_GAIN, entries: node.entries / KEY_SEPARATOR_MAX_GAIN };
                choose(&optimistic, &block_cost, Some(&size), true, budget).0 == Method::Direct
            }
        };
        let order = fill_reducing_order_of(&a, &unknowns, &node_orders, could_be_direct);
        drop(node_orders);
        // Two threads pay off only for large factorizations.
        let parallel = order.cost.flops > PARALLEL_FACTOR_FLOPS;
        let par = if parallel { Par::rayon(0) } else { Par::Seq };
        let (
            mut method,
            [(predicted_seconds, predicted_bytes), (predicted_modal_seconds, predicted_modal_bytes), (predicted_iterative_seconds, predicted_iterative_bytes)],
        ) = choose(&order.cost, &block_cost, Some(&size), parallel, budget);
        if let Some(forced) = forced {
            method = forced;
        }
        let singular = || {
            Error::general(
                "the spacetime system is singular: some motion (e.g. drifting or spinning freely) costs nothing",
                "fix some vertices at one key (`fixed`), or set [solver] regularization > 0 (e.g. 0.1)",
            )
        };
        let (solver_name, predicted) = match method {
            Method::Direct => ("the solve's global steps (a sparse factorization and its solves)", predicted_seconds),
            Method::Modal => ("the solve's global steps (the body's vibration modes)", predicted_modal_seconds),
            Method::Iterative => ("the solve's global steps (conjugate gradients)", predicted_iterative_seconds),
        };
        crate::support::resources::check_predicted_time(predicted, solver_name)?;
        let matrix_nnz = a.compute_nnz();
        // The modes never read the assembled matrix: free it before their dense matrices.
        let a = (method != Method::Modal).then_some(a);
        let mut modal = None;
        if method == Method::Modal {
            // A failed eigendecomposition (or a mode that costs nothing) falls back to the
            // next best way.
            // faer's kernels split by a fixed count, not the pool's: the same bytes on any thread count.
            let par = crate::algorithms::physics::fixed_par::par();
            modal =
                Modes::new(objective.elastic, &objective.supports, par).and_then(|modes| ModalStep::new(modes, &coefficients, &unknowns, par)).ok();
            if modal.is_none() {
                if forced.is_some() {
                    return Err(singular());
                }
                method = if predicted_bytes <= budget as f64 && predicted_seconds <= predicted_iterative_seconds {
                    Method::Direct
                } else {
                    Method::Iterative
                };
            }
        }
        let (inverse, factor_nnz, ordering, linear_solver) = match method {
            Method::Direct => {
                let a = a.unwrap_or_else(|| assemble(objective, &unknowns, &coefficients));
                let cholesky = Cholesky::factor(&a, &FillOrdering::Custom(order.perm), par).map_err(|_| singular())?;
                let nnz = cholesky.factor_nnz();
                (Inverse::Direct(Box::new(cholesky)), nnz, order.name, "direct")
            }
            Method::Modal => (Inverse::Modal(Box::new(modal.expect("built above"))), 0, "vibration modes", "modal"),
            Method::Iterative => {
                let a = a.unwrap_or_else(|| assemble(objective, &unknowns, &coefficients));
                let iterative = Iterative::new(&a, KroneckerSum::new(objective, &unknowns, &coefficients), &block_order).map_err(|_| singular())?;
                let nnz = iterative.preconditioner.factor_nnz();
                (Inverse::Iterative(Box::new(iterative)), nnz, "per-key blocks (preconditioner)", "iterative")
            }
        };
        let stats = GlobalStats {
            unknowns: dim,
            matrix_nnz,
            factor_nnz,
            ordering,
            assemble_seconds,
            factor_seconds: t1.elapsed().as_secs_f64(),
            predicted_bytes,
            predicted_seconds,
            linear_solver,
            predicted_iterative_bytes,
            predicted_iterative_seconds,
            predicted_modal_bytes,
            predicted_modal_seconds,
        };
        Ok(GlobalStep { unknowns, cholesky: Some(inverse), budget, coupling: coupling(&coefficients), stats })
    }

    /// Rebuild for new key times, `objective` holding the samples at those times: the time
    /// coefficients and the matrix values change, the pattern does not (unless a coefficient
    /// cancels exactly), so the factor is recomputed numerically on the kept ordering and
    /// symbolic analysis. With a changed pattern it falls back to [`GlobalStep::new`].
    pub fn retime(&mut self, objective: &Objective, regularization: f64) -> Result<Retimed> {
        let t0 = std::time::Instant::now();
        let proximal = proximal_weight(objective, regularization);
        let coefficients = TimeCoefficients::new(objective, proximal);
        if let Some(Inverse::Modal(modal)) = self.cholesky.as_mut() {
            // The modes do not depend on the times: only the per-mode systems change.
            modal.retime(&coefficients).map_err(|_| {
                Error::general(
                    "the spacetime system became singular at the new key times",
                    "keep [solver] regularization > 0, or raise the minimum interval length",
                )
            })?;
            return Ok(Retimed { assemble_seconds: 0.0, factor_seconds: t0.elapsed().as_secs_f64(), reused_symbolic: true });
        }
        let Some(Inverse::Direct(cholesky)) = self.cholesky.as_mut().filter(|_| coupling(&coefficients) == self.coupling) else {
            *self = GlobalStep::within(objective, self.unknowns.clone(), regularization, Some(self.budget))?;
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

    /// How the iterative step's CG solves went (None for a direct step).
    pub fn cg_log(&self) -> Option<CgLog> {
        match &self.cholesky {
            Some(Inverse::Iterative(it)) => Some(*it.log.lock().expect("no panic while solving")),
            _ => None,
        }
    }

    /// The free unknowns and their order.
    pub fn unknowns(&self) -> &Unknowns {
        &self.unknowns
    }

    /// The free entries of a per-slot array, in unknown order ([`Unknowns::gather`]).
    pub fn gather(&self, per_slot: &[Vec<Point>]) -> Vec<Point> {
        self.unknowns.gather(per_slot)
    }

    /// A per-slot array from free entries ([`Unknowns::scatter`]).
    pub fn scatter(&self, free: &[Point]) -> Vec<Vec<Point>> {
        self.unknowns.scatter(free)
    }

    /// `x <- (H + P)⁻¹ x` on free entries, the three coordinates as three right-hand sides.
    pub fn apply_inverse(&self, x: &mut [Point]) {
        match &self.cholesky {
            None => {}
            Some(Inverse::Direct(chol)) => chol.solve_rows3(x),
            Some(Inverse::Modal(modal)) => modal.solve(&self.unknowns, x),
            Some(Inverse::Iterative(it)) => it.solve(x),
        }
    }

    /// The step `Δ = -(H + P)⁻¹ ∇W` per slot (zero at fixed entries).
    pub fn step(&self, gradient: &[Vec<Point>]) -> Vec<Vec<Point>> {
        let mut g = self.gather(gradient);
        self.apply_inverse(&mut g);
        g.iter_mut().for_each(|v| *v = crate::algorithms::geometry::scale(*v, -1.0));
        self.scatter(&g)
    }
}

impl Iterative {
    /// The full rows of `a` and its per-key block preconditioner.
    fn new(
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
    fn solve(&self, x: &mut [Point]) {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::algorithms::physics::elastic::Elastic;
    use crate::algorithms::spacetime::solver::objective;
    use crate::algorithms::spacetime::tests::{keys, material, settings};
    use crate::support::testing::{cube_mesh, Rng};

    /// Ten keys of a bent cube, the bottom held at the first: enough keys for the
    /// key-separator candidate.
    fn problem() -> (Elastic, KeyConstraints) {
        let mesh = cube_mesh(4);
        let el = Elastic::new(&mesh, &material()).unwrap();
        let times: Vec<f64> = (0..10).map(|k| 0.2 * k as f64).collect();
        let poses = (0..10).map(|k| mesh.positions.iter().map(|p| [p[0] + 0.05 * k as f64 * p[1] * p[1], p[1], p[2]]).collect()).collect();
        let bottom: Vec<u32> = (0..mesh.positions.len() as u32).filter(|&i| mesh.positions[i as usize][1] == 0.0).collect();
        let mut fixed = vec![Vec::new(); 10];
        fixed[0] = bottom;
        (el, keys(times, poses, fixed, false))
    }

    use crate::algorithms::physics::pcg::SymmetricRows;
    use crate::algorithms::spacetime::unknowns::KeyConstraints;

    #[test]
    fn the_cost_model_prefers_the_faster_solver_within_the_budget() {
        // A small factor: direct. A factor with 100x the entries of all key blocks and 1e13
        // flops: iterative. Over the budget: iterative whatever the time.
        let small = Cost { flops: 1e9, entries: 1e6 };
        let blocks = Cost { flops: 1e8, entries: 5e5 };
        assert_eq!(choose(&small, &blocks, None, true, u64::MAX).0, Method::Direct);
        let huge = Cost { flops: 1e13, entries: 5e7 };
        let (method, [(ds, db), _, (is, ib)]) = choose(&huge, &blocks, None, true, u64::MAX);
        assert!(method == Method::Iterative && is < ds && ib < db, "{ds} {is}");
        assert_eq!(choose(&small, &blocks, None, true, 1).0, Method::Iterative);
        // A body of 2.6k nodes with 20 keys (40 slots) and 3.4k held entries on 169 nodes: the
        // modes beat both (predicted), within a budget that holds them but not the factor.
        let modal = ModalSize { nodes: 2600, slots: 40, held: 3400, held_nodes: 170 };
        let (modal_seconds, modal_bytes) = modal.predicted();
        let key_blocks = Cost { flops: 1e11, entries: 7e7 };
        assert_eq!(choose(&small, &blocks, Some(&modal), true, u64::MAX).0, Method::Direct, "a fast direct step is kept");
        let (method, [_, (ms, mb), _]) = choose(&huge, &key_blocks, Some(&modal), true, u64::MAX);
        assert_eq!((method, ms, mb), (Method::Modal, modal_seconds, modal_bytes));
        assert!(modal_bytes < 1e9, "{modal_bytes}");
        assert_eq!(choose(&huge, &key_blocks, Some(&modal), true, (modal_bytes * 0.9) as u64).0, Method::Iterative);
    }

    /// The choice on problem sizes recorded from the project's bodies (the costs `build` weighs,
    /// with the measured outcome): the 2744-node cube with 20 keys and with 5 keys, the bottom
    /// held at every key (`modal_setup_phases`), and the small bodies of the demo and the paper.
    #[test]
    fn the_cost_model_on_recorded_problem_sizes() {
        // 20 keys: the node order (the key separators are not weighed: even 4x fewer flops
        // would not make the direct step the choice), 1.4e13 flops and 1.1e9 entries (the
        // factorization measured 60 s and 6.9 GB with the key-separator order); the per-key
        // blocks; the modes measured 8 CPU s to set up and 0.13-0.19 CPU s per solve, CG 4.9-5.5 s
        // per solve.
        let direct = Cost { flops: 13999542089240.0, entries: 1098108520.0 };
        let blocks = Cost { flops: 37876401839.99901, entries: 58123760.0 };
        let modal = ModalSize { nodes: 2744, slots: 40, held: 3920, held_nodes: 196 };
        let (method, [(ds, db), (ms, mb), (is, _)]) = choose(&direct, &blocks, Some(&modal), true, 3 << 30);
        assert_eq!(method, Method::Modal, "{ds} {ms} {is}");
        assert!(db > 1e10 && mb < 5e8 && ms < is / 5.0 && ms < ds / 5.0, "{db} {mb} {ms} {is} {ds}");
        // Under a budget below the modes' dense matrices, CG.
        assert_eq!(choose(&direct, &blocks, Some(&modal), true, (mb * 0.9) as u64).0, Method::Iterative);
        // The cut the key separators may bring does not change that.
        let optimistic = Cost { flops: direct.flops / KEY_SEPARATOR_MAX_GAIN, entries: direct.entries / KEY_SEPARATOR_MAX_GAIN };
        assert_eq!(choose(&optimistic, &blocks, Some(&modal), true, u64::MAX).0, Method::Modal);
        // 5 keys: measured 6.9 CPU s to factorize (2.2e11 flops, 87M entries) and 0.126 CPU s
        // per solve, against the modes' 6.2-6.8 CPU s and 0.055-0.094 CPU s per solve: over a
        // bake's solves the modes are faster.
        let direct = Cost { flops: 218794320635.0, entries: 68641705.0 };
        let blocks = Cost { flops: 9469100459.999752, entries: 14530940.0 };
        let modal = ModalSize { nodes: 2744, slots: 10, held: 980, held_nodes: 196 };
        assert_eq!(choose(&direct, &blocks, Some(&modal), true, u64::MAX).0, Method::Modal);
        // ARMADILLO-size (2630 nodes, 5 keys, nothing held: 8.3e10 flops, 50M entries), idle:
        // the direct step factorizes in 2.0 s and solves in 0.046 s; the modes took 11.4 s to
        // set up and 0.20 s a solve at load 10. Direct (Table 1's precompute and iteration).
        let direct = Cost { flops: 8.3e10, entries: 50.15e6 };
        let blocks = Cost { flops: 4.0e9, entries: 10.0e6 };
        let modal = ModalSize { nodes: 2630, slots: 10, held: 0, held_nodes: 0 };
        let (method, [(ds, _), (ms, _), _]) = choose(&direct, &blocks, Some(&modal), true, u64::MAX);
        assert_eq!(method, Method::Direct, "direct {ds} s, modal {ms} s");
        // Small bodies, with the bakes' measured precompute plus solves (2026-12-03, load 5, so
        // only the ratios count): the demo (182 nodes, 4 keys of a loop) 0.175 s direct against
        // 0.072 s modal, the paper's TWIST 0.71 against 0.26; STRETCH 0.081 direct against 0.122
        // modal, DINO 0.48 against 8.1 (3966 held entries: the capacitance matrix is large).
        let small = |direct: [f64; 2], blocks: [f64; 2], modal: [usize; 4], parallel| {
            let [nodes, slots, held, held_nodes] = modal;
            let cost = |[flops, entries]: [f64; 2]| Cost { flops, entries };
            choose(&cost(direct), &cost(blocks), Some(&ModalSize { nodes, slots, held, held_nodes }), parallel, u64::MAX).0
        };
        assert_eq!(small([1.6977e8, 4.5290e5], [1.1534e7, 1.2121e5], [182, 8, 64, 16], false), Method::Modal, "the demo");
        assert_eq!(small([2.5544e9, 2.9960e6], [1.7333e8, 8.0396e5], [540, 8, 216, 54], true), Method::Modal, "TWIST");
        assert_eq!(small([3.7608e8, 8.5047e5], [1.1602e8, 4.8696e5], [594, 4, 216, 108], false), Method::Direct, "STRETCH");
        assert_eq!(small([3.6684e8, 1.2044e6], [2.5919e7, 4.2553e5], [439, 20, 3966, 439], false), Method::Direct, "DINO");
    }

    #[test]
    fn the_kronecker_sum_is_the_assembled_matrix() {
        // Supports (the bottom held at every key) and a key with extra held nodes: the
        // operator must drop exactly the rows and columns the assembly drops.
        let (el, mut k) = problem();
        let bottom = k.fixed[0].clone();
        for (f, v) in k.fixed.iter_mut().zip(k.fixed_velocity.iter_mut()) {
            f.clone_from(&bottom);
            v.clone_from(&bottom);
        }
        k.fixed[3].extend([40, 41, 42]);
        k.fixed_velocity[5].extend([7, 8]);
        let s = settings();
        let obj = objective(&el, &k, &s);
        assert!(obj.supports.iter().any(|&x| x), "the test needs supports");
        let unknowns = Unknowns::new(&k, el.node_count());
        let c = TimeCoefficients::new(&obj, 1.0 / s.regularization.powi(4));
        let a = assemble(&obj, &unknowns, &c);
        let rows = SymmetricRows::from_lower(&a);
        let op = KroneckerSum::new(&obj, &unknowns, &c);
        let mut rng = Rng(3);
        let x: Vec<Point> = (0..unknowns.count()).map(|_| [rng.next(), rng.next(), rng.next()]).collect();
        let (mut y0, mut y1) = (vec![[0.0; 3]; x.len()], vec![[1.0; 3]; x.len()]);
        rows.apply(&x, &mut y0);
        SymmetricOperator::apply(&op, &x, &mut y1);
        let scale = y0.iter().map(|p| crate::algorithms::geometry::norm(*p)).fold(0.0, f64::max);
        for (p, q) in y0.iter().zip(&y1) {
            assert!(crate::algorithms::geometry::norm(crate::algorithms::geometry::sub(*p, *q)) <= 1e-12 * scale, "{p:?} vs {q:?}");
        }
        // The same bytes on one thread.
        let mut y2 = vec![[0.0; 3]; x.len()];
        rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap().install(|| SymmetricOperator::apply(&op, &x, &mut y2));
        assert_eq!(y1, y2);
    }

    fn gradient(unknowns: &Unknowns) -> Vec<Vec<Point>> {
        let mut rng = Rng(7);
        (0..unknowns.slots.count()).map(|_| (0..unknowns.nodes).map(|_| [rng.next(), rng.next(), rng.next()]).collect()).collect()
    }

    #[test]
    fn the_iterative_step_over_budget_gives_the_direct_step() {
        let (el, k) = problem();
        let s = settings();
        let obj = objective(&el, &k, &s);
        let unknowns = Unknowns::new(&k, el.node_count());
        let direct = GlobalStep::build(&obj, unknowns.clone(), s.regularization, Some(u64::MAX), Some(Method::Direct)).unwrap();
        let iterative = GlobalStep::within(&obj, unknowns.clone(), s.regularization, Some(1)).unwrap();
        assert_eq!((direct.stats.linear_solver, iterative.stats.linear_solver), ("direct", "iterative"));
        assert!(direct.stats.predicted_bytes > 1.0 && direct.stats.predicted_seconds > 0.0);
        let g = gradient(&unknowns);
        // Twice: the second solve starts from the first's solution (a different right-hand
        // side), and must still converge to the direct answer.
        for g in [g.clone(), g.iter().map(|v| v.iter().map(|p| [p[1], -p[0], 2.0 * p[2]]).collect()).collect()] {
            let (a, b) = (direct.step(&g), iterative.step(&g));
            let scale = a.iter().flatten().map(|p| crate::algorithms::geometry::norm(*p)).fold(0.0, f64::max);
            for (x, y) in a.iter().flatten().zip(b.iter().flatten()) {
                assert!(crate::algorithms::geometry::norm(crate::algorithms::geometry::sub(*x, *y)) <= 1e-7 * scale, "{x:?} vs {y:?}");
            }
        }
    }

    /// The modal step is the direct step: with positions held at every key (velocities free),
    /// with supports and a few extra held entries, at the first times and after a retime; the
    /// same bytes when built twice and on one thread.
    #[test]
    fn the_modal_step_gives_the_direct_step() {
        for variant in 0..2 {
            let (el, mut k) = problem();
            let bottom = k.fixed[0].clone();
            for f in k.fixed.iter_mut() {
                f.clone_from(&bottom);
            }
            if variant == 1 {
                for v in k.fixed_velocity.iter_mut() {
                    v.clone_from(&bottom);
                }
                k.fixed[3].extend([40, 41, 42]);
                k.fixed_velocity[5].extend([60, 61]);
            }
            let s = settings();
            let obj = objective(&el, &k, &s);
            assert_eq!(obj.supports.iter().any(|&x| x), variant == 1);
            let unknowns = Unknowns::new(&k, el.node_count());
            let direct = GlobalStep::build(&obj, unknowns.clone(), s.regularization, None, Some(Method::Direct)).unwrap();
            let mut modal = GlobalStep::build(&obj, unknowns.clone(), s.regularization, None, Some(Method::Modal)).unwrap();
            assert_eq!((direct.stats.linear_solver, modal.stats.linear_solver), ("direct", "modal"));
            let g = gradient(&unknowns);
            let close = |a: &[Vec<Point>], b: &[Vec<Point>]| {
                let scale = a.iter().flatten().map(|p| crate::algorithms::geometry::norm(*p)).fold(0.0, f64::max);
                for (x, y) in a.iter().flatten().zip(b.iter().flatten()) {
                    assert!(
                        crate::algorithms::geometry::norm(crate::algorithms::geometry::sub(*x, *y)) <= 1e-9 * scale,
                        "variant {variant}: {x:?} vs {y:?}"
                    );
                }
            };
            let step = modal.step(&g);
            close(&direct.step(&g), &step);
            // Held entries stay zero (the step is scattered from the free ones only) and the
            // free ones solve the system: checked through the direct step above.
            let again = GlobalStep::build(&obj, unknowns.clone(), s.regularization, None, Some(Method::Modal)).unwrap();
            assert_eq!(again.step(&g), step);
            let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
            let single = one.install(|| GlobalStep::build(&obj, unknowns.clone(), s.regularization, None, Some(Method::Modal)).unwrap().step(&g));
            // The modes' kernels split by a fixed count: the same bytes on one thread.
            assert_eq!(single, step, "variant {variant}: one thread");
            // New key times: the same modes, new per-mode systems.
            let mut k2 = k.clone();
            k2.times = k.times.iter().enumerate().map(|(i, t)| t * (1.0 + 0.05 * (i % 3) as f64)).collect();
            let obj2 = objective(&el, &k2, &s);
            modal.retime(&obj2, s.regularization).unwrap();
            let fresh = GlobalStep::build(&obj2, unknowns.clone(), s.regularization, None, Some(Method::Direct)).unwrap();
            close(&fresh.step(&g), &modal.step(&g));
        }
    }

    /// The predicted flops of the node order and the key-separator order on a cube body with
    /// 5, 10 and 20 keys (`cargo test --release --lib key_separator_prediction -- --ignored
    /// --nocapture`): what `fill_reducing_order` weighs.
    #[test]
    #[ignore]
    fn key_separator_prediction() {
        for n in [8, 12] {
            let mesh = cube_mesh(n);
            let el = Elastic::new(&mesh, &material()).unwrap();
            for keys_count in [5, 10, 20] {
                let times: Vec<f64> = (0..keys_count).map(|k| 0.2 * k as f64).collect();
                let poses = vec![mesh.positions.clone(); keys_count];
                let bottom: Vec<u32> = (0..mesh.positions.len() as u32).filter(|&i| mesh.positions[i as usize][1] == 0.0).collect();
                let k = keys(times, poses, vec![bottom; keys_count], false);
                let s = settings();
                let obj = objective(&el, &k, &s);
                let unknowns = Unknowns::new(&k, el.node_count());
                let a = assemble(&obj, &unknowns, &TimeCoefficients::new(&obj, 1.0 / s.regularization.powi(4)));
                let graph = Graph::of_blocks(a.symbolic().col_ptr(), a.symbolic().row_idx(), &node_blocks(&unknowns), unknowns.nodes);
                let nd = nested_dissection(&graph, &el.rest);
                let by_keys = key_separator_order(&a, &unknowns, &nd).unwrap();
                let chosen = fill_reducing_order(&a, &unknowns, &el.rest, |_| true);
                println!(
                    "{} nodes, {keys_count} keys: node order {:.3e} flops, keys as separators {:.3e} ({:.2}x); chosen: {}",
                    unknowns.nodes,
                    by_keys.node_cost.flops,
                    by_keys.cost.flops,
                    by_keys.node_cost.flops / by_keys.cost.flops,
                    chosen.name
                );
            }
        }
    }

    #[test]
    fn keys_as_separators_is_a_valid_order_that_solves_the_system() {
        let (el, k) = problem();
        let s = settings();
        let obj = objective(&el, &k, &s);
        let unknowns = Unknowns::new(&k, el.node_count());
        let c = TimeCoefficients::new(&obj, 1.0 / s.regularization.powi(4));
        let a = assemble(&obj, &unknowns, &c);
        let node_order: Vec<u32> = (0..unknowns.nodes as u32).rev().collect();
        let by_keys = key_separator_order(&a, &unknowns, &node_order).unwrap();
        let mut sorted = by_keys.perm.clone();
        sorted.sort_unstable();
        assert_eq!(sorted, (0..unknowns.count()).collect::<Vec<_>>());
        assert!(by_keys.cost.flops > 0.0 && by_keys.node_cost.flops > 0.0);
        // Factorized in that order it solves the system.
        let chol = Cholesky::factor(&a, &FillOrdering::Custom(by_keys.perm), Par::Seq).unwrap();
        let b: Vec<Point> = (0..unknowns.count()).map(|i| [i as f64, 1.0, -1.0]).collect();
        let mut x = b.clone();
        chol.solve_rows3(&mut x);
        let rows = SymmetricRows::from_lower(&a);
        let mut ax = vec![[0.0; 3]; x.len()];
        rows.apply(&x, &mut ax);
        for (p, q) in ax.iter().zip(&b) {
            assert!(
                crate::algorithms::geometry::norm(crate::algorithms::geometry::sub(*p, *q)) < 1e-8 * (1.0 + crate::algorithms::geometry::norm(*q))
            );
        }
    }
}

#[cfg(test)]
mod experiment {
    use super::*;
    use crate::algorithms::physics::elastic::Elastic;
    use crate::algorithms::spacetime::solver::objective;
    use crate::algorithms::spacetime::tests::{keys, material, settings};
    use crate::support::testing::{cube_mesh, Rng};

    /// The measurements' body: a `CUBE`-per-side (default 13) Kuhn cube stretched to 1.2 x 3.6
    /// x 1.2, bent over `KEYS` (default 20) keys of 0.5 s, its bottom face held at every key.
    pub(super) fn many_keys_problem() -> (Elastic, crate::algorithms::spacetime::unknowns::KeyConstraints, usize) {
        let n: usize = std::env::var("CUBE").ok().and_then(|v| v.parse().ok()).unwrap_or(13);
        let kc: usize = std::env::var("KEYS").ok().and_then(|v| v.parse().ok()).unwrap_or(20);
        // `PRISM=d MAX_VOLUME=v`: the benchmark's prism series body instead (TetGen on the
        // 1.2 x 3.6 x 1.2 prism of d x 3d x d cells: 22 and 0.0005 give its 10k-node row).
        let prism: usize = std::env::var("PRISM").ok().and_then(|v| v.parse().ok()).unwrap_or(0);
        let mesh = if prism > 0 {
            let max_volume: f64 = std::env::var("MAX_VOLUME").ok().and_then(|v| v.parse().ok()).unwrap_or(0.0005);
            let surface = crate::algorithms::procedural::prism([1.2, 3.6, 1.2], [prism, 3 * prism, prism]);
            crate::formats::tetgen::run(
                &surface,
                &crate::formats::tetgen::TetgenOptions { quality: 1.414, max_volume, timeout: 600.0 },
                std::path::Path::new("prism"),
            )
            .unwrap()
        } else {
            let mut mesh = cube_mesh(n);
            for p in &mut mesh.positions {
                *p = [p[0] * 1.2, p[1] * 3.6, p[2] * 1.2];
            }
            mesh
        };
        let el = Elastic::new(&mesh, &material()).unwrap();
        let times: Vec<f64> = (0..kc).map(|k| 0.5 * k as f64).collect();
        let poses = (0..kc).map(|k| mesh.positions.iter().map(|p| [p[0] + 0.05 * (k as f64).sin() * p[1] * p[1], p[1], p[2]]).collect()).collect();
        let bottom: Vec<u32> = (0..mesh.positions.len() as u32).filter(|&i| mesh.positions[i as usize][1] == 0.0).collect();
        let k = keys(times, poses, vec![bottom; kc], false);
        (el, k, kc)
    }

    /// `cargo test --release --lib cg_at_20_keys -- --ignored --nocapture`
    #[test]
    #[ignore]
    fn cg_at_20_keys() {
        let (el, k, kc) = many_keys_problem();
        let mut s = settings();
        s.damping = 0.1;
        let obj = objective(&el, &k, &s);
        let unknowns = Unknowns::new(&k, el.node_count());
        let t = std::time::Instant::now();
        let it = GlobalStep::within(&obj, unknowns.clone(), s.regularization, Some(1)).unwrap();
        // The predicted seconds at the cost model's two-thread factorization rate (`choose`'s,
        // past PARALLEL_FACTOR_FLOPS as here); they include the solves' sweeps, so this bounds the factorization's flops from above.
        let flops = it.stats.predicted_seconds * FACTOR_FLOPS_PER_SECOND[1];
        println!(
            "{} nodes, {kc} keys, {} unknowns: iterative setup {:.2} s, predicted direct {flops:.3e} flops {:.1} GB {:.1} s",
            el.node_count(),
            it.stats.unknowns,
            t.elapsed().as_secs_f64(),
            it.stats.predicted_bytes / 1e9,
            it.stats.predicted_seconds
        );
        if let Some(Inverse::Iterative(itr)) = &it.cholesky {
            let x: Vec<Point> = (0..it.stats.unknowns).map(|i| [i as f64, 1.0, 2.0]).collect();
            let mut y = x.clone();
            let t = std::time::Instant::now();
            for _ in 0..5 {
                itr.operator.apply(&x, &mut y);
            }
            let mv = t.elapsed().as_secs_f64() / 5.0;
            let t = std::time::Instant::now();
            for _ in 0..5 {
                itr.preconditioner.apply(&x, &mut y);
            }
            println!(
                "matrix nnz {} factor nnz {}: matvec {:.4} s, preconditioner {:.4} s",
                it.stats.matrix_nnz,
                it.stats.factor_nnz,
                mv,
                t.elapsed().as_secs_f64() / 5.0
            );
        }
        let mut rng = Rng(7);
        let g: Vec<Vec<Point>> =
            (0..unknowns.slots.count()).map(|_| (0..unknowns.nodes).map(|_| [rng.next(), rng.next(), rng.next()]).collect()).collect();
        let t = std::time::Instant::now();
        let modal = GlobalStep::build(&obj, unknowns.clone(), s.regularization, None, Some(Method::Modal)).unwrap();
        println!(
            "modal setup {:.2} s (predicted {:.1} s, {:.0} MB)",
            t.elapsed().as_secs_f64(),
            modal.stats.predicted_modal_seconds,
            modal.stats.predicted_modal_bytes / 1e6
        );
        let t = std::time::Instant::now();
        let by_modes = modal.step(&g);
        println!("modal solve {:.3} s", t.elapsed().as_secs_f64());
        let by_cg = it.step(&g);
        let scale = by_cg.iter().flatten().map(|p| crate::algorithms::geometry::norm(*p)).fold(0.0, f64::max);
        let diff = by_cg
            .iter()
            .flatten()
            .zip(by_modes.iter().flatten())
            .map(|(a, b)| crate::algorithms::geometry::norm(crate::algorithms::geometry::sub(*a, *b)))
            .fold(0.0, f64::max);
        println!("modal vs CG: max difference {:.2e} of the largest entry", diff / scale);
        for round in 0..3 {
            let t = std::time::Instant::now();
            let gg: Vec<Vec<Point>> = g.iter().map(|v| v.iter().map(|p| [p[0] + 0.01 * round as f64 * p[1], p[1], p[2]]).collect()).collect();
            let _ = it.step(&gg);
            println!("solve {round}: {:.2} s, {:?}", t.elapsed().as_secs_f64(), it.cg_log());
        }
    }
}

#[cfg(test)]
mod modal_phases {
    use super::experiment::many_keys_problem;
    use super::*;
    use crate::algorithms::spacetime::solver::objective;
    use crate::algorithms::spacetime::tests::settings;
    use crate::support::testing::Rng;

    /// CPU seconds of the process (all threads), from getrusage.
    fn cpu() -> f64 {
        let mut u: libc::rusage = unsafe { std::mem::zeroed() };
        unsafe { libc::getrusage(libc::RUSAGE_SELF, &mut u) };
        let t = |v: libc::timeval| v.tv_sec as f64 + v.tv_usec as f64 * 1e-6;
        t(u.ru_utime) + t(u.ru_stime)
    }

    fn timed<T>(name: &str, f: impl FnOnce() -> T) -> T {
        let (w, c) = (std::time::Instant::now(), cpu());
        let out = f();
        println!("{name:<44} wall {:8.3} s  cpu {:8.3} s", w.elapsed().as_secs_f64(), cpu() - c);
        out
    }

    /// The global step's matrix of [`many_keys_problem`] with its fill-reducing order (every
    /// order allowed): what the factorization measurements factor.
    fn many_keys_matrix() -> (usize, Unknowns, SparseColMat<usize, f64>, FillReducingOrder) {
        let (el, k, kc) = many_keys_problem();
        let s = settings();
        let obj = objective(&el, &k, &s);
        let unknowns = Unknowns::new(&k, el.node_count());
        let c = TimeCoefficients::new(&obj, proximal_weight(&obj, s.regularization));
        let a = assemble(&obj, &unknowns, &c);
        let order = fill_reducing_order(&a, &unknowns, &el.rest, |_| true);
        (kc, unknowns, a, order)
    }

    /// The numeric factorization of the global step's matrix: faer's (one thread, both cores
    /// inside its dense kernels) against ours ([`Cholesky::refactor`]: the two halves of the
    /// elimination tree on two threads), medians of `REPEAT` (default 3), wall and CPU
    /// seconds. `CUBE=13 KEYS=5 cargo test --release --lib factor_on_two_cores -- --ignored --nocapture`
    #[test]
    #[ignore]
    fn factor_on_two_cores() {
        let (kc, unknowns, a, order) = many_keys_matrix();
        let repeat: usize = std::env::var("REPEAT").ok().and_then(|v| v.parse().ok()).unwrap_or(3);
        println!(
            "{} nodes, {kc} keys, {} unknowns, {} ordering, {:.3e} flops predicted, load {}",
            unknowns.nodes,
            unknowns.count(),
            order.name,
            order.cost.flops,
            std::fs::read_to_string("/proc/loadavg").unwrap_or_default().trim()
        );
        let mut chol = Cholesky::factor(&a, &FillOrdering::Custom(order.perm.clone()), Par::rayon(0)).unwrap();
        println!("factor entries {}\n{}", chol.factor_nnz(), chol.shape_report());
        let median = |mut v: Vec<(f64, f64)>| {
            v.sort_by(|a, b| a.0.total_cmp(&b.0));
            v[v.len() / 2]
        };
        let mut run = |name: &str, par: Par, ours: bool| {
            let times: Vec<(f64, f64)> = (0..repeat)
                .map(|_| {
                    let (w, c0) = (std::time::Instant::now(), cpu());
                    chol.par = par;
                    if ours {
                        chol.refactor(&a).unwrap()
                    } else {
                        chol.refactor_by_faer(&a).unwrap()
                    }
                    (w.elapsed().as_secs_f64(), cpu() - c0)
                })
                .collect();
            let (w, c) = median(times);
            println!(
                "{name:<36} wall {w:8.3} s  cpu {c:8.3} s  {:.3e} predicted flops per wall s, {:.3e} per CPU s",
                order.cost.flops / w,
                order.cost.flops / c
            );
            (w, chol.values_for_tests().to_vec())
        };
        // Our phases' thread CPU seconds on one thread: the two-core time they predict.
        let _ = run("(warm-up)", Par::Seq, true);
        *crate::algorithms::physics::cholesky::phases::CPU.lock().unwrap() = [0.0; 6];
        let _ = run("ours Par::Seq, phases timed", Par::Seq, true);
        let p = crate::algorithms::physics::cholesky::phases::CPU.lock().unwrap().map(|v| v / repeat as f64);
        let (total, path) = (p[0] + p[1] + p[2] + p[3] + p[4], p[0].max(p[1]) + p[5] + p[4]);
        println!("phases (thread CPU s): groups {:.3} + {:.3}, top halves {:.3} + {:.3} (longer {:.3}), top dense {:.3}; two-core critical path with the dense blocks on one core {:.3} s: {:.2}x", p[0], p[1], p[2], p[3], p[5], p[4], path, total / path);
        println!(
            "one thread: {:.3e} predicted flops per CPU s of the phases; two cores by the critical path: {:.3e}",
            order.cost.flops / total,
            order.cost.flops / path
        );
        let (faer_seq, reference) = run("faer Par::Seq", Par::Seq, false);
        let (faer_par, _) = run("faer Par::rayon", Par::rayon(0), false);
        let (ours_seq, one) = run("ours Par::Seq", Par::Seq, true);
        let (ours_par, two) = run("ours Par::rayon", Par::rayon(0), true);
        assert!(one.iter().zip(&two).all(|(x, y)| x.to_bits() == y.to_bits()));
        let scale = reference.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let worst = two.iter().zip(&reference).fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
        println!("speed-up over faer Par::Seq: faer rayon {:.2}x, ours seq {:.2}x, ours rayon {:.2}x; largest difference from faer {:.1e} of the largest entry", faer_seq / faer_par, faer_seq / ours_seq, faer_seq / ours_par, worst / scale);
    }

    /// A field of `/proc/self/status` in bytes (`VmHWM`: the peak resident set, `VmRSS`).
    fn status_bytes(field: &str) -> f64 {
        let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
        status.lines().find_map(|l| l.strip_prefix(field)?.trim().strip_suffix("kB")?.trim().parse::<f64>().ok()).map_or(0.0, |kb| kb * 1024.0)
    }

    /// The numeric factorization's own peak memory against what [`predicted_peak_bytes`]
    /// assumes: the resident peak is reset (`/proc/self/clear_refs`) after the assembly, the
    /// ordering and the symbolic analysis, then the factor is computed by ours (`FACTOR=ours`,
    /// the default) or by faer (`FACTOR=faer`). One factorization per process, so the two
    /// compare: `CUBE=13 KEYS=5 FACTOR=faer cargo test --release --lib factor_peak_memory --
    /// --ignored --nocapture`.
    #[test]
    #[ignore]
    fn factor_peak_memory() {
        let (kc, unknowns, a, order) = many_keys_matrix();
        let faer = std::env::var("FACTOR").is_ok_and(|v| v == "faer");
        let mut chol = Cholesky::analyse(&a, &FillOrdering::Custom(order.perm.clone()), Par::rayon(0));
        let before = status_bytes("VmRSS:");
        std::fs::write("/proc/self/clear_refs", "5").expect("reset the peak resident set");
        let (w, c0) = (std::time::Instant::now(), cpu());
        if faer {
            chol.refactor_by_faer(&a).unwrap()
        } else {
            chol.refactor(&a).unwrap()
        }
        let (wall, cpu_s) = (w.elapsed().as_secs_f64(), cpu() - c0);
        let peak = status_bytes("VmHWM:");
        let entries = chol.factor_nnz() as f64;
        let matrix = a.compute_nnz() as f64;
        println!(
            "{} nodes, {kc} keys, {} unknowns, {} ({:.3e} flops, {:.3e} entries predicted; {:.3e} stored), matrix {:.3e} entries, load {}",
            unknowns.nodes,
            unknowns.count(),
            order.name,
            order.cost.flops,
            order.cost.entries,
            entries,
            matrix,
            std::fs::read_to_string("/proc/loadavg").unwrap_or_default().trim()
        );
        println!(
            "{}: {wall:.2} s wall, {cpu_s:.2} CPU s; resident before {:.0} MB (of which the factor's zero pages are not resident), peak during {:.0} MB: {:.0} MB over before = {:.2} bytes per factor entry; process peak {:.2} bytes per entry; predicted peak {:.0} MB",
            if faer { "faer" } else { "ours" },
            before / 1e6,
            peak / 1e6,
            (peak - before) / 1e6,
            (peak - before) / entries,
            peak / entries,
            predicted_peak_bytes(&order.cost) / 1e6
        );
    }

    /// `cargo test --release --lib modal_setup_phases -- --ignored --nocapture` (CUBE, KEYS).
    #[test]
    #[ignore]
    fn modal_setup_phases() {
        let (el, k, kc) = many_keys_problem();
        let s = settings();
        let obj = objective(&el, &k, &s);
        let unknowns = Unknowns::new(&k, el.node_count());
        println!(
            "{} nodes, {kc} keys, {} unknowns, load {}",
            el.node_count(),
            unknowns.count(),
            std::fs::read_to_string("/proc/loadavg").unwrap_or_default().trim()
        );
        let c = timed("time coefficients", || TimeCoefficients::new(&obj, proximal_weight(&obj, s.regularization)));
        let a = timed("assemble", || assemble(&obj, &unknowns, &c));
        let order = timed("fill_reducing_order", || fill_reducing_order(&a, &unknowns, &el.rest, |_| true));
        println!("  {} {:.3e} flops", order.name, order.cost.flops);
        let _ = timed("key_block_order", || key_block_order(&NodeOrders::new(&a, &unknowns, &el.rest), &unknowns));
        let size = modal_size(&obj, &unknowns);
        println!("  modal size {size:?}, predicted {:?}", size.predicted());
        let _ = timed("fill_reducing_order without keys", || fill_reducing_order(&a, &unknowns, &el.rest, |_| false));
        if std::env::var("DIRECT").is_ok() {
            for par in [Par::Seq, Par::rayon(0)] {
                let chol =
                    timed(&format!("Cholesky::factor {par:?}"), || Cholesky::factor(&a, &FillOrdering::Custom(order.perm.clone()), par).unwrap());
                println!("  factor entries {}", chol.factor_nnz());
                let mut x: Vec<Point> = (0..unknowns.count()).map(|i| [i as f64, 1.0, 2.0]).collect();
                timed("  solve_rows3", || chol.solve_rows3(&mut x));
            }
        }
        let modes = timed("Modes::new (rayon)", || Modes::new(&el, &obj.supports, Par::rayon(0)).unwrap());
        if std::env::var("SEQ").is_ok() {
            let _ = timed("Modes::new (seq)", || Modes::new(&el, &obj.supports, Par::Seq).unwrap());
        }
        let step = timed("ModalStep::new (rayon)", || ModalStep::new(modes, &c, &unknowns, Par::rayon(0)).unwrap());
        let whole = timed("GlobalStep::build (modal, whole set-up)", || {
            GlobalStep::build(&obj, unknowns.clone(), s.regularization, None, Some(Method::Modal)).unwrap()
        });
        println!("  {:?}", whole.stats);
        drop(whole);
        let chosen =
            timed("GlobalStep::build (the cost model's choice)", || GlobalStep::build(&obj, unknowns.clone(), s.regularization, None, None).unwrap());
        println!("  {:?}", chosen.stats);
        drop(chosen);
        let mut rng = Rng(7);
        let x0: Vec<Point> = (0..unknowns.count()).map(|_| [rng.next(), rng.next(), rng.next()]).collect();
        for r in 0..3 {
            let mut x = x0.clone();
            timed(&format!("solve {r}"), || step.solve(&unknowns, &mut x));
        }
        let nn = size.nodes;
        let phi = faer::Mat::<f64>::from_fn(nn, nn, |i, j| ((i * 3 + j * 5) % 11) as f64);
        let r = faer::Mat::<f64>::from_fn(3 * c.slots, nn, |i, j| ((i * 7 + j) % 13) as f64);
        let mut y = faer::Mat::<f64>::zeros(3 * c.slots, nn);
        for par in [Par::rayon(0), Par::Seq] {
            timed(&format!("GEMM {}x{nn}x{nn} {par:?}", 3 * c.slots), || {
                faer::linalg::matmul::matmul(y.as_mut(), faer::Accum::Replace, r.as_ref(), phi.as_ref(), 1.0, par)
            });
            timed(&format!("GEMM^T {}x{nn}x{nn} {par:?}", 3 * c.slots), || {
                faer::linalg::matmul::matmul(y.as_mut(), faer::Accum::Replace, r.as_ref(), phi.transpose(), 1.0, par)
            });
        }
    }
}
