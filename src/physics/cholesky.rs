//! Sparse Cholesky factorization (faer) with the symbolic analysis kept for refactorization:
//! the spacetime matrix changes values, never pattern, when keyframe times move.

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::LltRegularization;
use faer::perm::PermRef;
use faer::sparse::linalg::cholesky::{
    factorize_symbolic_cholesky, CholeskySymbolicParams, LltRef, SymbolicCholesky, SymmetricOrdering,
};
use faer::sparse::SparseColMat;
use faer::{Conj, MatMut, Par, Side};

/// The matrix is not (numerically) positive definite.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct NotPositiveDefinite;

/// A fill-reducing ordering.
#[derive(Debug, Clone)]
pub enum Ordering {
    /// faer's approximate minimum degree.
    Amd,
    /// `perm[i]` = original index of the i-th pivot.
    Custom(Vec<usize>),
}

pub struct Cholesky {
    symbolic: SymbolicCholesky<usize>,
    values: Vec<f64>,
    par: Par,
}

impl Cholesky {
    /// Analyse and factor the symmetric matrix whose lower triangle is `lower`.
    pub fn factor(lower: &SparseColMat<usize, f64>, ordering: &Ordering, par: Par) -> Result<Cholesky, NotPositiveDefinite> {
        let n = lower.nrows();
        let (fwd, inv);
        let ord = match ordering {
            Ordering::Amd => SymmetricOrdering::Amd,
            Ordering::Custom(perm) => {
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
        let mut chol = Cholesky { values: vec![0.0; symbolic.len_val()], symbolic, par };
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
        for ordering in [Ordering::Amd, Ordering::Custom((0..n).rev().collect())] {
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
    fn indefinite_matrix_is_reported() {
        let t = [Triplet::new(0, 0, 1.0), Triplet::new(1, 0, 2.0), Triplet::new(1, 1, 1.0)];
        let a = SparseColMat::<usize, f64>::try_new_from_triplets(2, 2, &t).unwrap();
        assert!(Cholesky::factor(&a, &Ordering::Amd, Par::Seq).is_err());
    }
}
