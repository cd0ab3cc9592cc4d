//! Sparse Cholesky factorization (faer) with the symbolic analysis kept for refactorization:
//! the spacetime matrix changes values, never pattern, when keyframe times move. Solves with
//! the three coordinates of the spacetime unknowns have their own supernodal sweeps
//! ([`Cholesky::solve_rows3`]).
//!
//! Three concerns, three files: this one wraps faer (symbolic analysis in a given
//! [`FillOrdering`], numeric factorization, solves through faer); [`split`] plans how the elimination tree is shared by
//! two threads; [`sweeps`] are the forward and backward sweeps for three right-hand sides
//! (portable code, compiled for AVX2 when the CPU has it; same bytes either way).

mod split;
mod sweeps;

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::LltRegularization;
use faer::perm::PermRef;
use faer::sparse::linalg::cholesky::{
    factorize_symbolic_cholesky, CholeskySymbolicParams, LltRef, SymbolicCholesky, SymbolicCholeskyRaw, SymmetricOrdering,
};
use faer::sparse::SparseColMat;
use faer::{Conj, MatMut, Par, Side};

use split::SplitPlan;
use sweeps::SupernodalSolve;

use super::ordering::FillOrdering;

/// The matrix is not (numerically) positive definite.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct NotPositiveDefinite;

/// A sparse `L Lᵀ` factorization with its symbolic analysis (see the module documentation).
pub struct Cholesky {
    symbolic: SymbolicCholesky<usize>,
    values: Vec<f64>,
    par: Par,
    /// How [`Cholesky::solve_rows3`] splits a supernodal factor between two threads.
    plan: Option<SplitPlan>,
}

impl Cholesky {
    /// Analyse and factor the symmetric matrix whose lower triangle is `lower`.
    pub fn factor(lower: &SparseColMat<usize, f64>, ordering: &FillOrdering, par: Par) -> Result<Cholesky, NotPositiveDefinite> {
        let n = lower.nrows();
        let (fwd, inv);
        let ord = match ordering {
            FillOrdering::Amd => SymmetricOrdering::Amd,
            FillOrdering::Custom(perm) => {
                fwd = perm.clone();
                let mut i = vec![0usize; n];
                for (k, &p) in fwd.iter().enumerate() {
                    i[p] = k;
                }
                inv = i;
                SymmetricOrdering::Custom(PermRef::new_checked(&fwd, &inv, n))
            }
        };
        let symbolic = factorize_symbolic_cholesky(lower.symbolic(), Side::Lower, ord, CholeskySymbolicParams::default())
            .expect("symbolic Cholesky of a well-formed matrix");
        let plan = match symbolic.raw() {
            SymbolicCholeskyRaw::Supernodal(sym) => SplitPlan::new(sym),
            SymbolicCholeskyRaw::Simplicial(_) => None,
        };
        let mut chol = Cholesky { values: vec![0.0; symbolic.len_val()], symbolic, par, plan };
        chol.refactor(lower)?;
        Ok(chol)
    }

    /// Numeric refactorization of a matrix with the same pattern.
    pub fn refactor(&mut self, lower: &SparseColMat<usize, f64>) -> Result<(), NotPositiveDefinite> {
        let par = self.par;
        let mut mem = MemBuffer::new(self.symbolic.factorize_numeric_llt_scratch::<f64>(par, Default::default()));
        self.symbolic
            .factorize_numeric_llt(
                &mut self.values,
                lower.as_ref(),
                Side::Lower,
                LltRegularization::default(),
                par,
                MemStack::new(&mut mem),
                Default::default(),
            )
            .map(|_| ())
            .map_err(|_| NotPositiveDefinite)
    }

    /// Solve `A X = B` in place for all columns of `rhs` at once.
    pub fn solve_in_place(&self, rhs: MatMut<'_, f64>) {
        let par = self.par;
        let mut mem = MemBuffer::new(self.symbolic.solve_in_place_scratch::<f64>(rhs.ncols(), par));
        LltRef::new(&self.symbolic, &self.values).solve_in_place_with_conj(Conj::No, rhs, par, MemStack::new(&mut mem));
    }

    /// Solve `A x = b` in place for three right-hand sides stored per row (`x[i][d]`), the
    /// shape of the spacetime unknowns. A supernodal factor is swept by our own code: each
    /// column of `L` is streamed once per sweep for all three coordinates, and independent
    /// subtrees go to two threads (same bytes on any thread count). A simplicial factor (small
    /// systems) goes through faer.
    pub fn solve_rows3(&self, x: &mut [[f64; 3]]) {
        let n = self.dimension();
        assert_eq!(x.len(), n);
        match self.symbolic.raw() {
            SymbolicCholeskyRaw::Supernodal(sym) => {
                let fwd: Option<&[usize]> = self.symbolic.perm().map(|p| p.arrays().0);
                // y = P x, one contiguous column per coordinate.
                let mut y = vec![0.0; 3 * n];
                for i in 0..n {
                    let src = fwd.map_or(i, |f| f[i]);
                    for d in 0..3 {
                        y[d * n + i] = x[src][d];
                    }
                }
                SupernodalSolve { sym, values: &self.values, plan: self.plan.as_ref() }.solve(&mut y);
                for i in 0..n {
                    let dst = fwd.map_or(i, |f| f[i]);
                    for d in 0..3 {
                        x[dst][d] = y[d * n + i];
                    }
                }
            }
            SymbolicCholeskyRaw::Simplicial(_) => {
                let mut rhs = faer::Mat::<f64>::from_fn(n, 3, |i, d| x[i][d]);
                self.solve_in_place(rhs.as_mut());
                for (i, v) in x.iter_mut().enumerate() {
                    *v = [rhs[(i, 0)], rhs[(i, 1)], rhs[(i, 2)]];
                }
            }
        }
    }

    pub fn dimension(&self) -> usize {
        self.symbolic.nrows()
    }

    /// Stored entries of the factor (a measure of fill).
    pub fn factor_nnz(&self) -> usize {
        self.values.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use faer::sparse::Triplet;

    #[test]
    fn solves_a_small_spd_system_with_three_right_hand_sides() {
        // Tridiagonal 2,-1 plus identity: SPD.
        let n = 50;
        let mut t = Vec::new();
        for i in 0..n {
            t.push(Triplet::new(i, i, 3.0));
            if i + 1 < n {
                t.push(Triplet::new(i + 1, i, -1.0));
            }
        }
        let a = SparseColMat::<usize, f64>::try_new_from_triplets(n, n, &t).unwrap();
        for ordering in [FillOrdering::Amd, FillOrdering::Custom((0..n).rev().collect())] {
            let chol = Cholesky::factor(&a, &ordering, Par::Seq).unwrap();
            let mut x = faer::Mat::<f64>::from_fn(n, 3, |i, j| (i + j) as f64);
            let b = x.clone();
            chol.solve_in_place(x.as_mut());
            for j in 0..3 {
                for i in 0..n {
                    let mut ax = 3.0 * x[(i, j)];
                    if i > 0 {
                        ax -= x[(i - 1, j)];
                    }
                    if i + 1 < n {
                        ax -= x[(i + 1, j)];
                    }
                    assert!((ax - b[(i, j)]).abs() < 1e-12);
                }
            }
        }
    }

    #[test]
    fn supernodal_sweeps_solve_three_right_hand_sides() {
        // A 27-point grid operator plus a shift on 12³ nodes, in nested-dissection order:
        // large fronts, so faer builds a supernodal factor and the custom sweeps are used.
        let k = 12;
        let id = |i: usize, j: usize, l: usize| (i * k + j) * k + l;
        let mut t = Vec::new();
        let mut coords = Vec::new();
        let mut lists = vec![Vec::new(); k * k * k];
        for i in 0..k {
            for j in 0..k {
                for l in 0..k {
                    coords.push([i as f64, j as f64, l as f64]);
                    t.push(Triplet::new(id(i, j, l), id(i, j, l), 27.5));
                    for (di, dj, dl) in (0..27).map(|c| (c / 9, (c / 3) % 3, c % 3)) {
                        let (a, b, c) = (i + di, j + dj, l + dl);
                        if (di, dj, dl) == (1, 1, 1) || a == 0 || b == 0 || c == 0 || a > k || b > k || c > k {
                            continue;
                        }
                        let (row, col) = (id(a - 1, b - 1, c - 1), id(i, j, l));
                        lists[col].push(row as u32);
                        if row > col {
                            t.push(Triplet::new(row, col, -1.0 + 0.01 * ((row + col) % 7) as f64));
                        }
                    }
                }
            }
        }
        let n = k * k * k;
        let a = SparseColMat::<usize, f64>::try_new_from_triplets(n, n, &t).unwrap();
        let mut xadj = vec![0];
        let mut adj = Vec::new();
        for l in lists {
            adj.extend(l);
            xadj.push(adj.len());
        }
        let graph = crate::physics::ordering::Graph { xadj, adj };
        let order = crate::physics::ordering::nested_dissection(&graph, &coords);
        let perm = crate::physics::ordering::expand(&order, &(0..=n).collect::<Vec<_>>());
        let chol = Cholesky::factor(&a, &FillOrdering::Custom(perm), Par::Seq).unwrap();
        assert!(matches!(chol.symbolic.raw(), SymbolicCholeskyRaw::Supernodal(_)), "the test needs a supernodal factor");
        let b: Vec<[f64; 3]> = (0..n).map(|i| [(i as f64 * 0.3).sin(), (i as f64 * 0.7).cos(), 1.0 + (i % 5) as f64]).collect();
        assert!(chol.plan.is_some(), "the nested-dissection tree splits in two");
        let mut x = b.clone();
        chol.solve_rows3(&mut x);
        // The same bytes on one thread.
        let mut one = b.clone();
        rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap().install(|| chol.solve_rows3(&mut one));
        assert_eq!(x, one);
        let mut reference = faer::Mat::<f64>::from_fn(n, 3, |i, d| b[i][d]);
        chol.solve_in_place(reference.as_mut());
        for i in 0..n {
            for d in 0..3 {
                assert!((x[i][d] - reference[(i, d)]).abs() < 1e-12 * (1.0 + reference[(i, d)].abs()), "row {i}");
            }
        }
    }

    #[test]
    fn indefinite_matrix_is_reported() {
        let t = [Triplet::new(0, 0, 1.0), Triplet::new(1, 0, 2.0), Triplet::new(1, 1, 1.0)];
        let a = SparseColMat::<usize, f64>::try_new_from_triplets(2, 2, &t).unwrap();
        assert!(Cholesky::factor(&a, &FillOrdering::Amd, Par::Seq).is_err());
    }
}
