//! The global step's cost model: the predicted seconds and bytes of the direct, modal and
//! iterative steps (constants measured on the development machines), and the choice among
//! them within the memory budget ([`choose`]).

use crate::algorithms::physics::ordering::Cost;
use crate::algorithms::spacetime::objective::Objective;
use crate::algorithms::spacetime::unknowns::Unknowns;
use crate::support::budget::Budget;

use super::Method;

/// Seconds per stored factor entry of one solve with three right-hand sides (both sweeps read
/// every entry once), on one thread and on two (the solve splits the elimination tree's two
/// subtrees over the cores): 87M entries in 0.126 CPU s on one thread; ARMADILLO-size's 50M
/// entries in 0.046 s a global step on two, idle.
pub(super) const SWEEP_SECONDS_PER_ENTRY: [f64; 2] = [1.45e-9, 0.92e-9];

/// Global-step solves a bake is assumed to make (one per iteration, local/global and
/// quasi-Newton alike; the converged-by-default stopping rule: TWIST 120 iterations, DINO 150,
/// the demo 140, the 20-key body over 180), and CG iterations per iterative solve (measured at
/// 20 keys on 2.7k nodes: 37-46 with the warm start).
pub(super) const ASSUMED_SOLVES: f64 = 150.0;

/// See [`ASSUMED_SOLVES`].
pub(super) const ASSUMED_CG_ITERATIONS: f64 = 40.0;

/// One CG iteration costs about this many preconditioner sweeps (the matrix-free product and
/// the vector updates add about 30%, measured).
pub(super) const CG_ITERATION_PER_SWEEP: f64 = 1.3;

/// The size of the modal step: basis nodes, time slots, held entries in the basis and the
/// nodes they are on (see `super::modal`).
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
    /// Predicted (seconds, peak bytes) of building the modal step and `ASSUMED_SOLVES` solves:
    /// the eigendecomposition (`EIGEN_SECONDS_PER_NODE3 n³`), the capacitance matrix (`c² n`
    /// flops) and its factor (`c³ / 3`), and per solve the two products with `Φ`
    /// (`2 × 2 n² × 3 slots` flops), the two with the held rows of `Φ`, the capacitance solve and
    /// the per-mode systems, times `MODAL_SOLVE_OVERHEAD`.
    pub fn predicted(&self) -> (f64, f64) {
        let (n, s, c, h) = (self.nodes as f64, self.slots as f64, self.held as f64, self.held_nodes as f64);
        let setup = EIGEN_SECONDS_PER_NODE3 * n * n * n + (c * c * n + c * c * c / 3.0) / DENSE_FLOPS_PER_SECOND;
        let solve = MODAL_SOLVE_OVERHEAD
            * (2.0 * 2.0 * n * n * 3.0 * s + 2.0 * 2.0 * h * n * 3.0 * s + 2.0 * 3.0 * c * c + 2.0 * 2.0 * 3.0 * n * s * s)
            / DENSE_FLOPS_PER_SECOND;
        let seconds = setup + ASSUMED_SOLVES * solve;
        // The capacitance matrix once: it is factored in place (`modal.rs`); the pair blocks it is
        // assembled from are dropped before, and measured under the other terms' slack.
        let bytes = 8.0 * (MODAL_COPIES * n * n + n * s * s + c * c + h * n + 2.0 * 3.0 * s * n);
        (seconds, bytes)
    }
}

/// Seconds of the dense symmetric eigendecomposition (tridiagonalization, divide-and-conquer
/// eigenvectors, back-transformation) per cubed node count on 2 cores. Measured at 2744 nodes:
/// 5.7-6.8 CPU s (2.8e-10 to 3.3e-10 per n³, on one thread or two), 16 s wall on two threads
/// against 23 s on one under the same load: 1.4x from the second core.
pub(super) const EIGEN_SECONDS_PER_NODE3: f64 = 2.2e-10;

/// Flops per second of faer's dense products as the modal step uses them (measured at 2744
/// nodes, 20 keys: the capacitance matrix of 3920 held entries, 6.2e10 flops, in 2.0-2.2 CPU s;
/// one solve's 4.0e9 flops in 0.13 CPU s on one thread; a lone 120 x 2744 x 2744 product runs
/// at 4.5e10 per CPU second).
pub(super) const DENSE_FLOPS_PER_SECOND: f64 = 3.0e10;

/// A modal solve's time over its products' flops at [`DENSE_FLOPS_PER_SECOND`] (gathering and
/// scattering the unknowns, the per-mode systems' memory traffic): measured 1.0-1.4 at 20 keys
/// (0.13-0.19 CPU s), 1.7-2.8 at 5 keys (0.055-0.094 CPU s for 1e9 flops).
pub(super) const MODAL_SOLVE_OVERHEAD: f64 = 1.5;

/// `n × n` matrices alive at the modal step's peak (the eigenproblem, its eigenvectors and
/// the decomposition's workspace).
pub(super) const MODAL_COPIES: f64 = 3.0;

/// The cost model: predicted (seconds, bytes) of a bake's global steps, direct (factorize
/// once, then `ASSUMED_SOLVES` solves), iterative (the per-key blocks factorized once, then
/// `ASSUMED_SOLVES` CG solves of `ASSUMED_CG_ITERATIONS` iterations each) and, when
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
pub(super) fn modal_size(objective: &Objective, unknowns: &Unknowns) -> ModalSize {
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

/// Bytes a direct factorization needs per predicted factor entry, measured as the whole
/// process's peak over the predicted entries (the numeric factorization alone, one per process; cube-13, 5 keys, 6.86e7
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
/// thread and on two. One: 3.28-3.36e10 per CPU second (cube-13 at 5
/// keys, 2.19e11 flops, `Par::Seq`; CPU time holds under load, measured at load average 6-9).
/// Two: that times 1.58, the ratio of the phases' thread CPU seconds (both groups, both top
/// halves, the dense blocks) to the critical path of the split (the longer group, the longer
/// half of each top supernode, the dense blocks counted on one core); a wall-clock ratio needs
/// an idle machine (faer's own parallel factorization gave 1.6x on 85 G flops idle).
pub(super) const FACTOR_FLOPS_PER_SECOND: [f64; 2] = [3.3e10, 5.2e10];

/// The bytes the global step may use under `budget` ([`Budget::memory`]: `--max-memory`, else
/// 60% of `MemAvailable`), or 4 GiB when that cannot be read.
pub fn memory_bytes(budget: &Budget) -> u64 {
    budget.memory().map_or(4 << 30, |bytes| bytes as u64)
}
