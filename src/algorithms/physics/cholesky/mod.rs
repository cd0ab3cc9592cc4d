//! Sparse Cholesky factorization (faer) with the symbolic analysis kept for refactorization:
//! the spacetime matrix changes values, never pattern, when keyframe times move. Solves with
//! the three coordinates of the spacetime unknowns have their own supernodal sweeps
//! ([`Cholesky::solve_rows3`]).
//!
//! Three concerns, three files: this one wraps faer (symbolic analysis in a given
//! [`FillOrdering`], numeric factorization, solves through faer); `split` plans how the elimination tree is shared by
//! two threads; `sweeps` are the forward and backward sweeps for three right-hand sides
//! (portable code, compiled for AVX2 when the CPU has it; same bytes either way).

mod numeric;
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

use numeric::Updates;
use split::{GroupPlan, SplitPlan};
use sweeps::SupernodalSolve;

use super::ordering::FillOrdering;

/// Predicted flops (see [`super::ordering::Cost`]) above which a factorization is given both
/// threads (`Par::rayon`): below, the thread hand-offs cost more than the second core saves
/// (measured with faer's factorization on 2 cores: 0.37 G flops, 24-40 ms on one thread, 31-55
/// ms on two; 2.6 G flops, 101-134 ms against 77-106 ms).
pub(crate) const PARALLEL_FACTOR_FLOPS: f64 = 1e9;

/// The matrix is not (numerically) positive definite.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct NotPositiveDefinite;

/// A sparse `L Lᵀ` factorization with its symbolic analysis (see the module documentation).
pub struct Cholesky {
    symbolic: SymbolicCholesky<usize>,
    values: Vec<f64>,
    pub(crate) par: Par,
    /// How [`Cholesky::solve_rows3`] splits a supernodal factor between two threads.
    plan: Option<SplitPlan>,
    /// A supernodal factor's numeric factorization: which descendants update each supernode,
    /// and how the elimination tree is split between two threads (balancing flops).
    numeric: Option<(Updates, Option<GroupPlan>)>,
}

impl Cholesky {
    /// Analyse and factor the symmetric matrix whose lower triangle is `lower`.
    pub fn factor(lower: &SparseColMat<usize, f64>, ordering: &FillOrdering, par: Par) -> Result<Cholesky, NotPositiveDefinite> {
        let mut chol = Cholesky::analyse(lower, ordering, par);
        chol.refactor(lower)?;
        Ok(chol)
    }

    /// The symbolic analysis alone (the factor's values are zero until [`Cholesky::refactor`]).
    pub(crate) fn analyse(lower: &SparseColMat<usize, f64>, ordering: &FillOrdering, par: Par) -> Cholesky {
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
        let (plan, numeric) = match symbolic.raw() {
            SymbolicCholeskyRaw::Supernodal(sym) => {
                let cp = sym.col_ptr_for_val();
                let entries: Vec<usize> = (0..sym.n_supernodes()).map(|s| cp[s + 1] - cp[s]).collect();
                (SplitPlan::new(sym, &entries), Some((Updates::new(sym), GroupPlan::new(sym, &numeric::supernode_flops(sym)))))
            }
            SymbolicCholeskyRaw::Simplicial(_) => (None, None),
        };
        Cholesky { values: vec![0.0; symbolic.len_val()], symbolic, par, plan, numeric }
    }

    /// Numeric refactorization of a matrix with the same pattern. A supernodal factor is
    /// computed by `numeric::factorize` (two threads on the two halves of the elimination
    /// tree, same bytes on one); a simplicial one (small systems) by faer.
    pub fn refactor(&mut self, lower: &SparseColMat<usize, f64>) -> Result<(), NotPositiveDefinite> {
        let par = self.par;
        if let (SymbolicCholeskyRaw::Supernodal(sym), Some((updates, plan))) = (self.symbolic.raw(), &self.numeric) {
            // Our supernodes are in the permuted order: factor P A Pᵀ.
            let permuted;
            let a = match self.symbolic.perm() {
                Some(perm) => {
                    permuted = permute_lower(lower, perm.arrays().1);
                    permuted.as_ref()
                }
                None => lower.as_ref(),
            };
            return numeric::factorize(sym, updates, plan.as_ref(), &mut self.values, a, par);
        }
        self.refactor_by_faer(lower)
    }

    /// Numeric refactorization by faer's own supernodal or simplicial code (the reference the
    /// tests and benchmarks compare [`Cholesky::refactor`] with).
    pub(crate) fn refactor_by_faer(&mut self, lower: &SparseColMat<usize, f64>) -> Result<(), NotPositiveDefinite> {
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
    pub(crate) fn solve_in_place(&self, rhs: MatMut<'_, f64>) {
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

    /// Rows (and columns) of the factorized matrix.
    pub fn dimension(&self) -> usize {
        self.symbolic.nrows()
    }

    /// Stored entries of the factor (a measure of fill).
    pub fn factor_nnz(&self) -> usize {
        self.values.len()
    }
}

/// The lower triangle of `P A Pᵀ` from the lower triangle of `A` (entries above the diagonal
/// are ignored, as faer does), where `inverse[i]` is the new index of unknown `i`. Rows within
/// a column are in the order met, which the numeric factorization does not need sorted.
fn permute_lower(lower: &SparseColMat<usize, f64>, inverse: &[usize]) -> SparseColMat<usize, f64> {
    let n = lower.nrows();
    let entries = || {
        (0..n).flat_map(|j| {
            lower
                .row_idx_of_col_raw(j)
                .iter()
                .zip(lower.val_of_col(j))
                .filter(move |e| *e.0 >= j)
                .map(move |(&i, &v)| (inverse[i].max(inverse[j]), inverse[i].min(inverse[j]), v))
        })
    };
    let mut col_ptr = vec![0usize; n + 1];
    for (_, c, _) in entries() {
        col_ptr[c + 1] += 1;
    }
    for c in 0..n {
        col_ptr[c + 1] += col_ptr[c];
    }
    let mut next = col_ptr.clone();
    let (mut rows, mut vals) = (vec![0usize; col_ptr[n]], vec![0.0; col_ptr[n]]);
    for (r, c, v) in entries() {
        rows[next[c]] = r;
        vals[next[c]] = v;
        next[c] += 1;
    }
    SparseColMat::new(faer::sparse::SymbolicSparseColMat::new_unsorted_checked(n, n, col_ptr, None, rows), vals)
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
        let (a, perm) = grid_problem(12);
        let n = a.nrows();
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

    /// The 27-point grid operator of `supernodal_sweeps_solve_three_right_hand_sides` on `k³`
    /// nodes and a nested-dissection order of it.
    fn grid_problem(k: usize) -> (SparseColMat<usize, f64>, Vec<usize>) {
        let id = |i: usize, j: usize, l: usize| (i * k + j) * k + l;
        let (mut t, mut coords, mut lists) = (Vec::new(), Vec::new(), vec![Vec::new(); k * k * k]);
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
        let (mut xadj, mut adj) = (vec![0], Vec::new());
        for l in lists {
            adj.extend(l);
            xadj.push(adj.len());
        }
        let graph = crate::algorithms::physics::ordering::Graph { xadj, adj };
        let order = crate::algorithms::physics::ordering::nested_dissection(&graph, &coords);
        (
            SparseColMat::<usize, f64>::try_new_from_triplets(n, n, &t).unwrap(),
            crate::algorithms::physics::ordering::expand(&order, &(0..=n).collect::<Vec<_>>()),
        )
    }

    /// `A x` for the symmetric matrix whose lower triangle is `lower`.
    fn apply(lower: &SparseColMat<usize, f64>, x: &[f64]) -> Vec<f64> {
        let mut y = vec![0.0; x.len()];
        for j in 0..lower.ncols() {
            for (&i, &v) in lower.row_idx_of_col_raw(j).iter().zip(lower.val_of_col(j)) {
                y[i] += v * x[j];
                if i != j {
                    y[j] += v * x[i];
                }
            }
        }
        y
    }

    /// Our numeric factorization against faer's on `lower`: the factor's entries agree to
    /// round-off, the solve's relative residual is below 1e-12, and the bytes are the same on
    /// two threads, a one-thread pool and `Par::Seq`.
    fn check_against_faer(lower: &SparseColMat<usize, f64>, ordering: &FillOrdering) -> Cholesky {
        let n = lower.nrows();
        let chol = Cholesky::factor(lower, ordering, Par::rayon(0)).unwrap();
        assert!(chol.numeric.is_some(), "the test needs a supernodal factor");
        let one =
            rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap().install(|| Cholesky::factor(lower, ordering, Par::rayon(0)).unwrap());
        assert!(chol.values.iter().zip(&one.values).all(|(a, b)| a.to_bits() == b.to_bits()), "same bytes on one thread");
        let seq = Cholesky::factor(lower, ordering, Par::Seq).unwrap();
        assert!(chol.values.iter().zip(&seq.values).all(|(a, b)| a.to_bits() == b.to_bits()), "same bytes with Par::Seq");
        let mut reference = Cholesky::factor(lower, ordering, Par::Seq).unwrap();
        reference.refactor_by_faer(lower).unwrap();
        let scale = reference.values.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let worst = chol.values.iter().zip(&reference.values).fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
        assert!(worst <= 1e-12 * scale, "factor entries differ from faer's by {worst:e} (largest {scale:e})");
        let b: Vec<f64> = (0..n).map(|i| (i as f64 * 0.37).sin() + 0.5).collect();
        let mut x = faer::Mat::<f64>::from_fn(n, 1, |i, _| b[i]);
        chol.solve_in_place(x.as_mut());
        let ax = apply(lower, &(0..n).map(|i| x[(i, 0)]).collect::<Vec<_>>());
        let (r, nb) = (ax.iter().zip(&b).map(|(a, b)| (a - b) * (a - b)).sum::<f64>().sqrt(), b.iter().map(|v| v * v).sum::<f64>().sqrt());
        assert!(r <= 1e-12 * nb, "relative residual {:e}", r / nb);
        chol
    }

    #[test]
    fn numeric_factorization_on_two_threads_matches_faer() {
        let (a, perm) = grid_problem(12);
        let chol = check_against_faer(&a, &FillOrdering::Custom(perm));
        assert!(chol.numeric.as_ref().unwrap().1.is_some(), "the nested-dissection tree splits in two");
        // Refactorization with new values and the same pattern: same checks.
        let mut b = a.clone();
        for (k, v) in b.val_mut().iter_mut().enumerate() {
            *v *= 1.0 + 0.05 * ((k % 11) as f64 / 11.0);
        }
        let mut again = Cholesky::factor(&a, &FillOrdering::Custom(grid_problem(12).1), Par::rayon(0)).unwrap();
        again.refactor(&b).unwrap();
        let fresh = check_against_faer(&b, &FillOrdering::Custom(grid_problem(12).1));
        assert!(again.values.iter().zip(&fresh.values).all(|(x, y)| x.to_bits() == y.to_bits()), "a refactorization equals a fresh factorization");
    }

    #[test]
    fn the_numeric_split_deals_whole_subtrees_to_two_groups() {
        let (a, perm) = grid_problem(12);
        let chol = Cholesky::analyse(&a, &FillOrdering::Custom(perm), Par::Seq);
        let (SymbolicCholeskyRaw::Supernodal(sym), Some((_, Some(plan)))) = (chol.symbolic.raw(), &chol.numeric) else {
            panic!("the nested-dissection tree splits in two")
        };
        let (begin, end) = (sym.supernode_begin(), sym.supernode_end());
        let owner_of_row = |row: usize| (0..sym.n_supernodes()).find(|&s| begin[s] <= row && row < end[s]).unwrap();
        let flops = numeric::supernode_flops(sym);
        let mut group_flops = [0usize; 3];
        for s in 0..sym.n_supernodes() {
            group_flops[plan.owner[s] as usize] += flops[s];
            // A group supernode's parent is in its group or in the top; a top one's is in the top.
            if let Some(&row) = sym.supernode(s).pattern().first() {
                let p = plan.owner[owner_of_row(row)];
                assert!(p == split::TOP || p == plan.owner[s], "supernode {s}: owner {} under {p}", plan.owner[s]);
            }
        }
        assert!(group_flops[0] > 0 && group_flops[1] > 0, "{group_flops:?}");
    }

    #[test]
    fn numeric_factorization_matches_faer_on_random_spd_matrices() {
        let mut rng = crate::support::testing::Rng::new(3);
        for (n, per_column) in [(400, 6), (900, 4)] {
            // A random symmetric pattern, made SPD by diagonal dominance.
            let mut t = Vec::new();
            let mut diagonal = vec![1.0; n];
            for j in 0..n {
                for _ in 0..per_column {
                    let i = ((rng.next() * 0.5 + 0.5) * n as f64) as usize % n;
                    if i > j {
                        let v = rng.next();
                        t.push(Triplet::new(i, j, v));
                        diagonal[i] += v.abs();
                        diagonal[j] += v.abs();
                    }
                }
            }
            t.extend(diagonal.iter().enumerate().map(|(i, &d)| Triplet::new(i, i, d)));
            let a = SparseColMat::<usize, f64>::try_new_from_triplets(n, n, &t).unwrap();
            check_against_faer(&a, &FillOrdering::Amd);
        }
    }

    #[test]
    fn indefinite_matrix_is_reported() {
        let t = [Triplet::new(0, 0, 1.0), Triplet::new(1, 0, 2.0), Triplet::new(1, 1, 1.0)];
        let a = SparseColMat::<usize, f64>::try_new_from_triplets(2, 2, &t).unwrap();
        assert!(Cholesky::factor(&a, &FillOrdering::Amd, Par::Seq).is_err());
        // A supernodal factor, split in two: a negative pivot in either group or in the top.
        let (a, perm) = grid_problem(8);
        let n = a.nrows();
        for unknown in [perm[0], perm[n / 2], perm[n - 1]] {
            let mut b = a.clone();
            let col = b.symbolic().col_ptr()[unknown];
            assert_eq!(b.symbolic().row_idx()[col], unknown, "the diagonal entry comes first");
            b.val_mut()[col] = -1.0;
            for par in [Par::Seq, Par::rayon(0)] {
                assert!(Cholesky::factor(&b, &FillOrdering::Custom(perm.clone()), par).is_err(), "unknown {unknown}");
            }
        }
    }
}
