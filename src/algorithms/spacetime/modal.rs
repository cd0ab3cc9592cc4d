//! The global step solved exactly in the body's vibration modes.
//!
//! The global step's matrix is the Kronecker sum `C_MM ⊗ M + C_ML ⊗ L + C_KK ⊗ L M⁻¹ L` over
//! (time slot, node) ([`super::global_step`]). The generalized eigenvectors of `(L, M)`,
//! `L φ_i = λ_i M φ_i` with `Φᵀ M Φ = I`, diagonalize all three node matrices at once
//! (`Φᵀ L Φ = Λ`, `Φᵀ L M⁻¹ L Φ = Λ²`), so in that basis the matrix splits into one small
//! `slots × slots` system per mode:
//!
//! ```text
//! A⁻¹ = (I ⊗ Φ) diag_i(B_i⁻¹) (I ⊗ Φᵀ),   B_i = C_MM + λ_i C_ML + λ_i² C_KK
//! ```
//!
//! The basis is taken on the nodes W keeps (supports leave out their rows and all their
//! slots, so the restriction is exact). Held values of the other nodes (a position held at
//! some keys, e.g. a bottom held at every key with its velocity free) break the product
//! structure; they are eliminated exactly with the capacitance matrix `G = E_C A⁻¹ E_Cᵀ` of
//! the `c` held entries: the free solution is the unconstrained solve of `b` plus a
//! combination of the unconstrained responses to the held entries that puts them back to 0.
//!
//! Cost: one dense symmetric eigendecomposition of the nodes (`O(n³)`, `8 n²` bytes per
//! copy), `G` (`c² n` flops, `8 c²` bytes) and its Cholesky factor; every solve is two dense
//! products `n × n` by `n × 3 slots` and small per-mode products: no fill-in, whatever the
//! number of keys. Key times that move change only the `B_i` and `G`, never the basis.
//!
//! Deterministic: faer's dense kernels split their work by the thread count only (never by
//! timing), per-mode work writes disjoint columns.

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::LltRegularization;
use faer::linalg::matmul::matmul;
use faer::{Accum, Conj, Mat, MatMut, MatRef, Par};
use rayon::prelude::*;

use super::time_coefficients::TimeCoefficients;
use super::unknowns::Unknowns;
use crate::algorithms::geometry::Point;
use crate::algorithms::physics::elastic::Elastic;

/// Why the modal step cannot be built (the caller falls back to another solver).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ModalFailure {
    /// The eigendecomposition did not converge.
    Eigen,
    /// A mode's `B_i` or the capacitance matrix is not positive definite (no regularization
    /// and a motion that costs nothing).
    NotPositiveDefinite,
}

/// The body's modes: the basis of [`ModalStep`], independent of the key times.
pub struct Modes {
    /// Basis node `j` is body node `nodes[j]` (the non-supports, in order).
    nodes: Vec<u32>,
    /// `Φ` (`n × n`, column `i` the mode `φ_i`, `Φᵀ M Φ = I`).
    phi: Mat<f64>,
    /// `λ_i`, nondecreasing.
    lambda: Vec<f64>,
}

impl Modes {
    /// The generalized eigenvectors of `(L, M)` on the non-support nodes of `elastic`.
    pub fn new(elastic: &Elastic, supports: &[bool], par: Par) -> Result<Modes, ModalFailure> {
        let nodes: Vec<u32> = (0..elastic.node_count() as u32).filter(|&a| !supports[a as usize]).collect();
        let n = nodes.len();
        let mut place = vec![u32::MAX; elastic.node_count()];
        for (j, &a) in nodes.iter().enumerate() {
            place[a as usize] = j as u32;
        }
        // S = M^-1/2 L M^-1/2 (lumped M): Φ = M^-1/2 U for S = U Λ Uᵀ.
        let scale: Vec<f64> = nodes.iter().map(|&a| 1.0 / elastic.mass[a as usize].sqrt()).collect();
        let mut s = Mat::<f64>::zeros(n, n);
        for (j, &a) in nodes.iter().enumerate() {
            for (b, v) in elastic.stiffness.row(a as usize) {
                let k = place[b];
                if k != u32::MAX && k as usize >= j {
                    s[(k as usize, j)] = v * scale[j] * scale[k as usize];
                }
            }
        }
        let mut u = Mat::<f64>::zeros(n, n);
        let mut lambda = vec![0.0; n];
        {
            let params = Default::default();
            let mut buffer =
                MemBuffer::new(faer::linalg::evd::self_adjoint_evd_scratch::<f64>(n, faer::linalg::evd::ComputeEigenvectors::Yes, par, params));
            let diag = faer::diag::DiagMut::from_slice_mut(&mut lambda);
            faer::linalg::evd::self_adjoint_evd(s.as_ref(), diag, Some(u.as_mut()), par, MemStack::new(&mut buffer), params)
                .map_err(|_| ModalFailure::Eigen)?;
        }
        drop(s);
        for j in 0..n {
            for i in 0..n {
                u[(j, i)] *= scale[j];
            }
        }
        Ok(Modes { nodes, phi: u, lambda })
    }

    /// Nodes of the basis.
    pub fn node_count(&self) -> usize {
        self.nodes.len()
    }
}

/// The exact inverse of the global step's matrix through the modes (module documentation).
pub struct ModalStep {
    modes: Modes,
    slots: usize,
    /// Per mode, `B_i⁻¹` (`slots × slots`, row-major).
    inverse: Vec<f64>,
    /// The held entries of basis nodes: slot-major, `(slot, row of phi_held)`.
    held: Vec<(usize, usize)>,
    /// The rows of `Φ` at the nodes with a held entry (`held nodes × n`).
    phi_held: Mat<f64>,
    /// The body node of each row of `phi_held`.
    held_nodes: Vec<u32>,
    /// The Cholesky factor of the capacitance matrix `G` (`c × c`, lower), if any entry is held.
    capacitance: Option<Mat<f64>>,
    par: Par,
}

/// `L Lᵀ` of a small dense SPD matrix (row-major, in place, lower); false if not positive definite.
fn small_cholesky(a: &mut [f64], n: usize) -> bool {
    for j in 0..n {
        let mut d = a[j * n + j];
        for k in 0..j {
            d -= a[j * n + k] * a[j * n + k];
        }
        if d.is_nan() || d <= 0.0 {
            return false;
        }
        let d = d.sqrt();
        a[j * n + j] = d;
        for i in j + 1..n {
            let mut v = a[i * n + j];
            for k in 0..j {
                v -= a[i * n + k] * a[j * n + k];
            }
            a[i * n + j] = v / d;
        }
    }
    true
}

/// The inverse of a small SPD matrix from its Cholesky factor (row-major).
fn small_inverse(l: &[f64], n: usize) -> Vec<f64> {
    let mut inv = vec![0.0; n * n];
    let mut x = vec![0.0; n];
    for c in 0..n {
        // L y = e_c, Lᵀ x = y.
        for i in 0..n {
            let mut v = if i == c { 1.0 } else { 0.0 };
            for k in 0..i {
                v -= l[i * n + k] * x[k];
            }
            x[i] = v / l[i * n + i];
        }
        for i in (0..n).rev() {
            let mut v = x[i];
            for k in i + 1..n {
                v -= l[k * n + i] * x[k];
            }
            x[i] = v / l[i * n + i];
        }
        for i in 0..n {
            inv[i * n + c] = x[i];
        }
    }
    // Exactly symmetric.
    for i in 0..n {
        for j in 0..i {
            let v = 0.5 * (inv[i * n + j] + inv[j * n + i]);
            inv[i * n + j] = v;
            inv[j * n + i] = v;
        }
    }
    inv
}

impl ModalStep {
    /// The step for the time coefficients `c` and the free unknowns `unknowns` on `modes`.
    pub fn new(modes: Modes, c: &TimeCoefficients, unknowns: &Unknowns, par: Par) -> Result<ModalStep, ModalFailure> {
        let slots = c.slots;
        let mut step = ModalStep {
            modes,
            slots,
            inverse: Vec::new(),
            held: Vec::new(),
            phi_held: Mat::zeros(0, 0),
            held_nodes: Vec::new(),
            capacitance: None,
            par,
        };
        let mut held_place = vec![u32::MAX; unknowns.nodes];
        for s in 0..slots {
            for &a in &step.modes.nodes {
                if unknowns.get(a as usize, s).is_none() {
                    if held_place[a as usize] == u32::MAX {
                        held_place[a as usize] = step.held_nodes.len() as u32;
                        step.held_nodes.push(a);
                    }
                    step.held.push((s, held_place[a as usize] as usize));
                }
            }
        }
        let n = step.modes.node_count();
        let rows: Vec<usize> = step.held_nodes.iter().map(|&a| step.modes.nodes.binary_search(&a).expect("a basis node")).collect();
        step.phi_held = Mat::from_fn(rows.len(), n, |r, i| step.modes.phi[(rows[r], i)]);
        step.retime(c)?;
        Ok(step)
    }

    /// New time coefficients (the key times moved): the per-mode inverses and the capacitance
    /// matrix, on the same modes.
    pub fn retime(&mut self, c: &TimeCoefficients) -> Result<(), ModalFailure> {
        let (slots, n) = (self.slots, self.modes.node_count());
        assert_eq!(c.slots, slots, "the same time slots");
        let inverses: Vec<Option<Vec<f64>>> = self
            .modes
            .lambda
            .par_iter()
            .map(|&l| {
                let mut b: Vec<f64> = (0..slots * slots).map(|at| c.mm[at] + l * c.ml[at] + l * l * c.kk[at]).collect();
                small_cholesky(&mut b, slots).then(|| small_inverse(&b, slots))
            })
            .collect();
        self.inverse = Vec::with_capacity(n * slots * slots);
        for inv in inverses {
            self.inverse.extend(inv.ok_or(ModalFailure::NotPositiveDefinite)?);
        }
        self.capacitance = None;
        let count = self.held.len();
        if count == 0 {
            return Ok(());
        }
        // G[p, q] = Σ_i Φ[j_p, i] Φ[j_q, i] B_i⁻¹[s_p, s_q], one slot pair at a time: the rows
        // of Φ at the held entries of slot s, column i scaled by B_i⁻¹[s, t], times those of
        // slot t. The pairs go to the threads whole, each product sequential: every block of G
        // is one sequential product, the same bytes on any thread count.
        let mut by_slot: Vec<Vec<(usize, usize)>> = vec![Vec::new(); slots];
        for (p, &(s, r)) in self.held.iter().enumerate() {
            by_slot[s].push((p, r));
        }
        let phi_rows = |list: &[(usize, usize)]| Mat::from_fn(list.len(), n, |k, i| self.phi_held[(list[k].1, i)]);
        let per_slot: Vec<Mat<f64>> = by_slot.iter().map(|l| phi_rows(l)).collect();
        let pairs: Vec<(usize, usize)> =
            (0..slots).flat_map(|s| (0..=s).map(move |t| (s, t))).filter(|&(s, t)| !by_slot[s].is_empty() && !by_slot[t].is_empty()).collect();
        let ss = slots * slots;
        let blocks: Vec<Mat<f64>> = pairs
            .par_iter()
            .map(|&(s, t)| {
                let at = s * slots + t;
                let weight: Vec<f64> = (0..n).map(|i| self.inverse[i * ss + at]).collect();
                let rows = &per_slot[s];
                let scaled = Mat::from_fn(rows.nrows(), n, |k, i| rows[(k, i)] * weight[i]);
                let mut block = Mat::<f64>::zeros(by_slot[s].len(), by_slot[t].len());
                matmul(block.as_mut(), Accum::Replace, scaled.as_ref(), per_slot[t].transpose(), 1.0, Par::Seq);
                block
            })
            .collect();
        let mut g = Mat::<f64>::zeros(count, count);
        for (&(s, t), block) in pairs.iter().zip(&blocks) {
            for (k, &(p, _)) in by_slot[s].iter().enumerate() {
                for (m, &(q, _)) in by_slot[t].iter().enumerate() {
                    if q <= p {
                        g[(p, q)] = block[(k, m)];
                    }
                }
            }
        }
        drop(blocks);
        let mut buffer = MemBuffer::new(faer::linalg::cholesky::llt::factor::cholesky_in_place_scratch::<f64>(count, self.par, Default::default()));
        faer::linalg::cholesky::llt::factor::cholesky_in_place(
            g.as_mut(),
            LltRegularization::default(),
            self.par,
            MemStack::new(&mut buffer),
            Default::default(),
        )
        .map_err(|_| ModalFailure::NotPositiveDefinite)?;
        self.capacitance = Some(g);
        Ok(())
    }

    /// `y ← B_i⁻¹ y` for every mode, or `y ← y + B_i⁻¹ c` with `add = Some(c)` (`y` and `c`
    /// column-major `3 slots × n`, column `i` the mode's `(slot, coordinate)` values: each
    /// mode's column is contiguous, worked on in place).
    fn per_mode(&self, y: &mut [f64], add: Option<&[f64]>) {
        let ss = self.slots * self.slots;
        let slots = self.slots;
        let rows = 3 * slots;
        y.par_chunks_mut(rows).enumerate().for_each_init(
            || vec![0.0; rows],
            |out, (i, col)| {
                let inv = &self.inverse[i * ss..(i + 1) * ss];
                let from: &[f64] = match add {
                    Some(c) => &c[i * rows..(i + 1) * rows],
                    None => col,
                };
                // Row t of B_i⁻¹ is its column t (exactly symmetric): the sums over t in order,
                // as row by row, but each coordinate's slots contiguous, so they vectorize.
                out.fill(0.0);
                let (o0, rest) = out.split_at_mut(slots);
                let (o1, o2) = rest.split_at_mut(slots);
                for (row, f) in inv.chunks_exact(slots).zip(from.chunks_exact(3)) {
                    for (((a, b), c), &w) in o0.iter_mut().zip(o1.iter_mut()).zip(o2.iter_mut()).zip(row) {
                        *a += w * f[0];
                        *b += w * f[1];
                        *c += w * f[2];
                    }
                }
                for (s, v) in col.chunks_exact_mut(3).enumerate() {
                    let value = [o0[s], o1[s], o2[s]];
                    match add {
                        Some(_) => v.iter_mut().zip(value).for_each(|(x, o)| *x += o),
                        None => v.copy_from_slice(&value),
                    }
                }
            },
        );
    }

    /// `x ← A⁻¹ x` on the free unknowns (three coordinates as three right-hand sides).
    pub fn solve(&self, unknowns: &Unknowns, x: &mut [Point]) {
        let (slots, n) = (self.slots, self.modes.node_count());
        let rows = 3 * slots;
        // Rᵀ: (slot, coordinate) × basis node, zero at held entries.
        let r = Mat::from_fn(rows, n, |row, j| unknowns.get(self.modes.nodes[j] as usize, row / 3).map_or(0.0, |u| x[u][row % 3]));
        // Yᵀ = Rᵀ Φ, then B_i⁻¹ per mode (column-major, each mode's column contiguous).
        let mut y = vec![0.0; rows * n];
        matmul(MatMut::from_column_major_slice_mut(&mut y, rows, n), Accum::Replace, r.as_ref(), self.modes.phi.as_ref(), 1.0, self.par);
        drop(r);
        self.per_mode(&mut y, None);
        if let Some(g) = &self.capacitance {
            // The unconstrained solution at the held entries, then λ = -G⁻¹ of it.
            let held_rows = self.phi_held.nrows();
            let mut at_held = Mat::<f64>::zeros(rows, held_rows);
            matmul(at_held.as_mut(), Accum::Replace, MatRef::from_column_major_slice(&y, rows, n), self.phi_held.transpose(), 1.0, self.par);
            let mut lambda = Mat::<f64>::zeros(self.held.len(), 3);
            for (p, &(s, h)) in self.held.iter().enumerate() {
                for d in 0..3 {
                    lambda[(p, d)] = -at_held[(3 * s + d, h)];
                }
            }
            faer::linalg::cholesky::llt::solve::solve_in_place_with_conj(
                g.as_ref(),
                Conj::No,
                lambda.as_mut(),
                self.par,
                MemStack::new(&mut MemBuffer::new(faer::dyn_stack::StackReq::EMPTY)),
            );
            // Add B⁻¹ Φᵀ E_Cᵀ λ.
            let mut spread = Mat::<f64>::zeros(rows, held_rows);
            for (p, &(s, h)) in self.held.iter().enumerate() {
                for d in 0..3 {
                    spread[(3 * s + d, h)] = lambda[(p, d)];
                }
            }
            let mut correction = vec![0.0; rows * n];
            matmul(
                MatMut::from_column_major_slice_mut(&mut correction, rows, n),
                Accum::Replace,
                spread.as_ref(),
                self.phi_held.as_ref(),
                1.0,
                self.par,
            );
            self.per_mode(&mut y, Some(&correction));
        }
        // Xᵀ = Yᵀ Φᵀ.
        let mut out = vec![0.0; rows * n];
        matmul(
            MatMut::from_column_major_slice_mut(&mut out, rows, n),
            Accum::Replace,
            MatRef::from_column_major_slice(&y, rows, n),
            self.modes.phi.transpose(),
            1.0,
            self.par,
        );
        for (&a, col) in self.modes.nodes.iter().zip(out.chunks_exact(rows)) {
            for s in 0..slots {
                if let Some(u) = unknowns.get(a as usize, s) {
                    x[u] = [col[3 * s], col[3 * s + 1], col[3 * s + 2]];
                }
            }
        }
    }
}
