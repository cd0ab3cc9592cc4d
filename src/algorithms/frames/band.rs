//! Symmetric banded matrices and their Cholesky factor `A = L Lᵀ`, solved for many right-hand
//! sides at once.
//!
//! The Hermite fit's normal matrix couples key `k` only with keys `k ± 1`: with the unknowns
//! ordered `(x_0, v_0, x_1, v_1, ...)` it has half-bandwidth 3, and its factor has no fill
//! outside the band. Factoring costs `O(n w²)`, a solve `O(n w)` per right-hand side.

/// Lower band of a symmetric `n x n` matrix with half-bandwidth `w`: entry `(i, j)`,
/// `i - w <= j <= i`, is stored at `i * (w + 1) + (j + w - i)`. Entries outside the band are
/// zero by invariant.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Band {
    n: usize,
    w: usize,
    data: Vec<f64>,
}

/// The matrix is not numerically positive definite: the pivot of `row` fell to `pivot` (relative
/// to the largest diagonal entry).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NotPositiveDefinite {
    pub row: usize,
    pub pivot: f64,
}

/// Pivots below this fraction of the largest diagonal entry are treated as zero: the matrix is
/// singular to working precision.
const PIVOT_TOLERANCE: f64 = 1e-13;

impl Band {
    pub fn zeros(n: usize, w: usize) -> Band {
        Band { n, w, data: vec![0.0; n * (w + 1)] }
    }

    #[cfg(test)]
    pub fn dimension(&self) -> usize {
        self.n
    }

    #[inline]
    fn at(&self, i: usize, j: usize) -> usize {
        debug_assert!(j <= i && i - j <= self.w && i < self.n);
        i * (self.w + 1) + (j + self.w - i)
    }

    /// `A[i][j] += value` (and `A[j][i]`, the same stored entry). Panics outside the band.
    #[inline]
    pub fn add(&mut self, i: usize, j: usize, value: f64) {
        let (i, j) = if i >= j { (i, j) } else { (j, i) };
        assert!(i - j <= self.w, "entry ({i}, {j}) is outside half-bandwidth {}", self.w);
        let k = self.at(i, j);
        self.data[k] += value;
    }

    /// `A[i][j]`; zero outside the band.
    pub fn get(&self, i: usize, j: usize) -> f64 {
        let (i, j) = if i >= j { (i, j) } else { (j, i) };
        if i - j > self.w {
            0.0
        } else {
            self.data[self.at(i, j)]
        }
    }

    /// `self += other` (same shape).
    pub(crate) fn add_band(&mut self, other: &Band) {
        assert!(self.n == other.n && self.w == other.w, "band shapes differ");
        self.data.iter_mut().zip(&other.data).for_each(|(a, b)| *a += b);
    }

    pub(crate) fn any_nonzero(&self) -> bool {
        self.data.iter().any(|&x| x != 0.0)
    }

    /// The principal submatrix on the rows/columns where `keep` is true, in their order. It is
    /// banded with the same half-bandwidth (dropping rows cannot widen the band).
    pub fn submatrix(&self, keep: &[bool]) -> Band {
        assert_eq!(keep.len(), self.n);
        let index: Vec<usize> = keep.iter().enumerate().filter(|(_, &k)| k).map(|(i, _)| i).collect();
        let mut sub = Band::zeros(index.len(), self.w);
        for (a, &i) in index.iter().enumerate() {
            for (b, &j) in index[..=a].iter().enumerate().rev() {
                if i - j > self.w {
                    break;
                }
                let k = sub.at(a, b);
                sub.data[k] = self.get(i, j);
            }
        }
        sub
    }

    /// `y += A x` for `cols` right-hand sides stored row-major (`x[i * cols + c]`).
    pub(crate) fn mul_add_rows(&self, x: &[f64], y: &mut [f64], cols: usize) {
        assert!(x.len() == self.n * cols && y.len() == self.n * cols);
        for i in 0..self.n {
            for j in i.saturating_sub(self.w)..=i {
                let a = self.data[self.at(i, j)];
                if a == 0.0 {
                    continue;
                }
                axpy(a, &x[j * cols..(j + 1) * cols], &mut y[i * cols..(i + 1) * cols]);
                if i != j {
                    axpy(a, &x[i * cols..(i + 1) * cols], &mut y[j * cols..(j + 1) * cols]);
                }
            }
        }
    }

    /// The Cholesky factor, or the first row whose pivot is not positive to working precision.
    pub fn cholesky(&self) -> Result<BandCholesky, NotPositiveDefinite> {
        let (n, w) = (self.n, self.w);
        let scale = (0..n).map(|i| self.get(i, i)).fold(0.0f64, f64::max);
        let mut l = Band { n, w, data: self.data.clone() };
        for i in 0..n {
            let lo = i.saturating_sub(w);
            for j in lo..=i {
                // s = A[i][j] - Σ_{k<j} L[i][k] L[j][k], over k inside both bands.
                let mut s = l.data[l.at(i, j)];
                for k in lo.max(j.saturating_sub(w))..j {
                    s -= l.data[l.at(i, k)] * l.data[l.at(j, k)];
                }
                let idx = l.at(i, j);
                if i == j {
                    // Also catches NaN pivots.
                    if s.is_nan() || s <= PIVOT_TOLERANCE * scale {
                        return Err(NotPositiveDefinite { row: i, pivot: if scale > 0.0 { s / scale } else { s } });
                    }
                    l.data[idx] = s.sqrt();
                } else {
                    l.data[idx] = s / l.data[l.at(j, j)];
                }
            }
        }
        Ok(BandCholesky { l })
    }
}

/// `y += a x`.
#[inline]
pub(crate) fn axpy(a: f64, x: &[f64], y: &mut [f64]) {
    for (y, x) in y.iter_mut().zip(x) {
        *y += a * x;
    }
}

/// `L` of `A = L Lᵀ`, banded like `A`.
#[derive(Debug, Clone)]
pub(crate) struct BandCholesky {
    l: Band,
}

impl BandCholesky {
    /// Solve `A X = B` in place for `cols` right-hand sides stored row-major (`b[i * cols + c]`):
    /// each row operation is one contiguous `axpy` over all columns.
    pub(crate) fn solve_rows(&self, b: &mut [f64], cols: usize) {
        let (n, w) = (self.l.n, self.l.w);
        assert_eq!(b.len(), n * cols);
        if cols == 0 {
            return;
        }
        // L y = b.
        for i in 0..n {
            let (done, rest) = b.split_at_mut(i * cols);
            let row = &mut rest[..cols];
            for j in i.saturating_sub(w)..i {
                axpy(-self.l.data[self.l.at(i, j)], &done[j * cols..(j + 1) * cols], row);
            }
            let d = 1.0 / self.l.data[self.l.at(i, i)];
            row.iter_mut().for_each(|x| *x *= d);
        }
        // Lᵀ x = y.
        for i in (0..n).rev() {
            let (head, tail) = b.split_at_mut((i + 1) * cols);
            let row = &mut head[i * cols..];
            for j in i + 1..n.min(i + w + 1) {
                axpy(-self.l.data[self.l.at(j, i)], &tail[(j - i - 1) * cols..(j - i) * cols], row);
            }
            let d = 1.0 / self.l.data[self.l.at(i, i)];
            row.iter_mut().for_each(|x| *x *= d);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A deterministic SPD band matrix: diagonally dominant with pseudo-random off-diagonals.
    fn sample(n: usize, w: usize) -> Band {
        let mut a = Band::zeros(n, w);
        let mut s = 0.37f64;
        for i in 0..n {
            for j in i.saturating_sub(w)..i {
                s = (s * 9301.0 + 0.49297).fract();
                a.add(i, j, s - 0.5);
            }
            a.add(i, i, 2.0 * w as f64 + 1.0);
        }
        a
    }

    fn dense_mul(a: &Band, x: &[f64], cols: usize) -> Vec<f64> {
        let n = a.dimension();
        let mut y = vec![0.0; n * cols];
        for i in 0..n {
            for j in 0..n {
                for c in 0..cols {
                    y[i * cols + c] += a.get(i, j) * x[j * cols + c];
                }
            }
        }
        y
    }

    #[test]
    fn solve_inverts_the_matrix_for_every_column() {
        for (n, w) in [(1, 3), (2, 3), (7, 1), (12, 3), (30, 5)] {
            let a = sample(n, w);
            let cols = 4;
            let x: Vec<f64> = (0..n * cols).map(|k| ((k * 7919) % 23) as f64 - 11.0).collect();
            let mut b = dense_mul(&a, &x, cols);
            a.cholesky().unwrap().solve_rows(&mut b, cols);
            for (got, want) in b.iter().zip(&x) {
                assert!((got - want).abs() < 1e-12 * 11.0, "n {n} w {w}: {got} vs {want}");
            }
        }
    }

    #[test]
    fn mul_add_matches_dense_product() {
        let a = sample(9, 3);
        let x: Vec<f64> = (0..18).map(|k| k as f64 * 0.5 - 3.0).collect();
        let mut y = vec![1.0; 18];
        a.mul_add_rows(&x, &mut y, 2);
        let want = dense_mul(&a, &x, 2);
        for (g, w) in y.iter().zip(&want) {
            assert!((g - (w + 1.0)).abs() < 1e-12);
        }
    }

    #[test]
    fn submatrix_keeps_the_selected_rows_and_columns() {
        let a = sample(8, 3);
        let keep = [true, false, true, true, false, false, true, true];
        let s = a.submatrix(&keep);
        let idx: Vec<usize> = (0..8).filter(|&i| keep[i]).collect();
        for (p, &i) in idx.iter().enumerate() {
            for (q, &j) in idx.iter().enumerate() {
                assert_eq!(s.get(p, q), a.get(i, j), "({p},{q}) <- ({i},{j})");
            }
        }
    }

    #[test]
    fn singular_and_indefinite_matrices_are_reported() {
        // [[1, 1], [1, 1]] is singular: the second pivot is 0.
        let mut a = Band::zeros(2, 1);
        a.add(0, 0, 1.0);
        a.add(1, 0, 1.0);
        a.add(1, 1, 1.0);
        assert_eq!(a.cholesky().unwrap_err().row, 1);
        let mut b = Band::zeros(2, 1);
        b.add(0, 0, -1.0);
        assert_eq!(b.cholesky().unwrap_err().row, 0);
    }
}
