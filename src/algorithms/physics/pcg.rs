//! Preconditioned conjugate gradients for a sparse symmetric positive definite matrix with
//! three right-hand sides stored per row (`x[i][d]`), the shape of the spacetime unknowns:
//! the fallback when a direct factorization would not fit in memory.
//!
//! The preconditioner is block Jacobi: the diagonal blocks of a partition of the unknowns
//! (for the spacetime matrix, one block per key: a key's positions and velocities of every
//! node, which holds the stiff spatial coupling `L M⁻¹ L` while dropping the weaker coupling
//! between neighbouring keys), each factorized by sparse Cholesky. The three coordinates run
//! three independent CG recurrences that share every matrix and preconditioner pass.
//!
//! Deterministic: products are row-wise (each row summed in a fixed order, rows in parallel),
//! dot products are sequential, and blocks write disjoint entries.

use faer::sparse::{SparseColMat, Triplet};
use faer::Par;
use rayon::prelude::*;

use super::cholesky::{Cholesky, NotPositiveDefinite};
use super::ordering::FillOrdering;
use crate::algorithms::geometry::Point;

/// A symmetric positive definite linear operator on per-row 3-vectors: what CG multiplies by.
pub trait SymmetricOperator: Sync {
    /// `y = A x`, deterministic (the same bytes on any thread count).
    fn apply(&self, x: &[Point], y: &mut [Point]);
}

#[cfg(test)]
impl SymmetricOperator for SymmetricRows {
    fn apply(&self, x: &[Point], y: &mut [Point]) {
        SymmetricRows::apply(self, x, y)
    }
}

/// A symmetric matrix stored by full rows (both triangles), for row-parallel products (the
/// reference the matrix-free operators are tested against).
#[cfg(test)]
pub(crate) struct SymmetricRows {
    row_ptr: Vec<usize>,
    cols: Vec<u32>,
    vals: Vec<f64>,
}

#[cfg(test)]
impl SymmetricRows {
    /// The full matrix of the symmetric matrix whose lower triangle is `lower`.
    pub(crate) fn from_lower(lower: &SparseColMat<usize, f64>) -> SymmetricRows {
        let n = lower.nrows();
        let (cp, ri, v) = (lower.symbolic().col_ptr(), lower.symbolic().row_idx(), lower.val());
        let mut count = vec![0usize; n + 1];
        for j in 0..n {
            for &i in &ri[cp[j]..cp[j + 1]] {
                count[i + 1] += 1;
                if i != j {
                    count[j + 1] += 1;
                }
            }
        }
        for i in 0..n {
            count[i + 1] += count[i];
        }
        let row_ptr = count.clone();
        let mut next = count;
        let (mut cols, mut vals) = (vec![0u32; row_ptr[n]], vec![0.0; row_ptr[n]]);
        // Columns in increasing order give every row its entries in increasing column order.
        for j in 0..n {
            for (k, &i) in ri[cp[j]..cp[j + 1]].iter().enumerate() {
                let a = v[cp[j] + k];
                // Entry (i, j) in row i; its mirror (j, i) in row j (rows j see columns i > j
                // after their own lower entries, still in order since i runs upward).
                cols[next[i]] = j as u32;
                vals[next[i]] = a;
                next[i] += 1;
                if i != j {
                    cols[next[j]] = i as u32;
                    vals[next[j]] = a;
                    next[j] += 1;
                }
            }
        }
        SymmetricRows { row_ptr, cols, vals }
    }

    /// Stored entries (both triangles).
    #[cfg(test)]
    pub fn nnz(&self) -> usize {
        self.vals.len()
    }

    /// `y = A x`.
    pub fn apply(&self, x: &[Point], y: &mut [Point]) {
        y.par_iter_mut().enumerate().with_min_len(256).for_each(|(i, yi)| {
            let mut s = [0.0; 3];
            for k in self.row_ptr[i]..self.row_ptr[i + 1] {
                let (a, xj) = (self.vals[k], x[self.cols[k] as usize]);
                for d in 0..3 {
                    s[d] += a * xj[d];
                }
            }
            *yi = s;
        });
    }
}

/// Block Jacobi: the inverse of the diagonal blocks of a partition (see the module
/// documentation).
pub struct BlockJacobi {
    /// Per block: its unknowns (increasing) and the factor of its diagonal block.
    blocks: Vec<(Vec<usize>, Cholesky)>,
}

impl BlockJacobi {
    /// The preconditioner of the matrix whose lower triangle is `lower`, unknown `i` in block
    /// `block_of[i] < blocks`. Each block is factorized in the order of `rank` (unknowns of
    /// lower rank first, ties by index: e.g. the position of the unknown's node in a nested
    /// dissection of the node graph), or by faer's AMD without it.
    pub fn new(lower: &SparseColMat<usize, f64>, block_of: &[u32], blocks: usize, rank: Option<&[u32]>) -> Result<BlockJacobi, NotPositiveDefinite> {
        let n = lower.nrows();
        let mut members: Vec<Vec<usize>> = vec![Vec::new(); blocks];
        let mut local = vec![0usize; n];
        for i in 0..n {
            let b = block_of[i] as usize;
            local[i] = members[b].len();
            members[b].push(i);
        }
        let (cp, ri, v) = (lower.symbolic().col_ptr(), lower.symbolic().row_idx(), lower.val());
        let mut triplets: Vec<Vec<Triplet<usize, usize, f64>>> = vec![Vec::new(); blocks];
        for j in 0..n {
            let b = block_of[j];
            for (k, &i) in ri[cp[j]..cp[j + 1]].iter().enumerate() {
                if block_of[i] == b {
                    triplets[b as usize].push(Triplet::new(local[i], local[j], v[cp[j] + k]));
                }
            }
        }
        let factors: Vec<Result<Cholesky, NotPositiveDefinite>> = members
            .par_iter()
            .zip(&triplets)
            .map(|(m, t)| {
                let a = SparseColMat::<usize, f64>::try_new_from_triplets(m.len(), m.len(), t).expect("valid block triplets");
                let ordering = match rank {
                    Some(rank) => {
                        let mut perm: Vec<usize> = (0..m.len()).collect();
                        perm.sort_by_key(|&l| (rank[m[l]], l));
                        FillOrdering::Custom(perm)
                    }
                    None => FillOrdering::Amd,
                };
                Cholesky::factor(&a, &ordering, Par::Seq)
            })
            .collect();
        let mut out = Vec::with_capacity(blocks);
        for (m, f) in members.into_iter().zip(factors) {
            if !m.is_empty() {
                out.push((m, f?));
            }
        }
        Ok(BlockJacobi { blocks: out })
    }

    /// Stored entries of the block factors.
    pub fn factor_nnz(&self) -> usize {
        self.blocks.iter().map(|(_, c)| c.factor_nnz()).sum()
    }

    /// `z = M⁻¹ r`.
    pub fn apply(&self, r: &[Point], z: &mut [Point]) {
        let solved: Vec<Vec<Point>> = self
            .blocks
            .par_iter()
            .map(|(m, chol)| {
                let mut x: Vec<Point> = m.iter().map(|&i| r[i]).collect();
                chol.solve_rows3(&mut x);
                x
            })
            .collect();
        for ((m, _), x) in self.blocks.iter().zip(solved) {
            for (&i, xi) in m.iter().zip(x) {
                z[i] = xi;
            }
        }
    }
}

/// How a CG solve ended.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CgStats {
    /// Iterations taken (`max_iterations` when the tolerance was not reached).
    pub iterations: usize,
    /// Largest `|b - A x| / |b|` of the three coordinates.
    pub relative_residual: f64,
}

fn dots(a: &[Point], b: &[Point]) -> [f64; 3] {
    let mut s = [0.0; 3];
    for (p, q) in a.iter().zip(b) {
        for d in 0..3 {
            s[d] += p[d] * q[d];
        }
    }
    s
}

/// Solve `A x = b` by preconditioned CG from the start `x` (for each coordinate, the start is
/// first rescaled by the factor that minimizes the A-norm error along it, so a poor warm
/// start is never worse than zero), until every coordinate's residual is below `tolerance`
/// times its right-hand side or after `max_iterations`.
pub fn pcg<A: SymmetricOperator + ?Sized>(a: &A, m: &BlockJacobi, b: &[Point], x: &mut [Point], tolerance: f64, max_iterations: usize) -> CgStats {
    let n = b.len();
    let mut ax = vec![[0.0; 3]; n];
    a.apply(x, &mut ax);
    let (xb, xax) = (dots(x, b), dots(x, &ax));
    let alpha0: [f64; 3] = std::array::from_fn(|d| if xax[d] > 0.0 { xb[d] / xax[d] } else { 0.0 });
    for (xi, axi) in x.iter_mut().zip(ax.iter_mut()) {
        for d in 0..3 {
            xi[d] *= alpha0[d];
            axi[d] *= alpha0[d];
        }
    }
    let mut r: Vec<Point> = b.iter().zip(&ax).map(|(p, q)| std::array::from_fn(|d| p[d] - q[d])).collect();
    let bb = dots(b, b);
    let goal: [f64; 3] = std::array::from_fn(|d| tolerance * tolerance * bb[d]);
    let relative = |rr: [f64; 3]| (0..3).map(|d| if bb[d] > 0.0 { (rr[d] / bb[d]).sqrt() } else { 0.0 }).fold(0.0, f64::max);
    let mut rr = dots(&r, &r);
    let done = |rr: [f64; 3]| (0..3).all(|d| rr[d] <= goal[d]);
    if done(rr) {
        return CgStats { iterations: 0, relative_residual: relative(rr) };
    }
    let mut z = vec![[0.0; 3]; n];
    m.apply(&r, &mut z);
    let mut p = z.clone();
    let mut rz = dots(&r, &z);
    let mut ap = vec![[0.0; 3]; n];
    for iteration in 1..=max_iterations {
        a.apply(&p, &mut ap);
        let pap = dots(&p, &ap);
        // A coordinate already converged keeps its iterate (step 0).
        let alpha: [f64; 3] = std::array::from_fn(|d| if rr[d] > goal[d] && pap[d] > 0.0 { rz[d] / pap[d] } else { 0.0 });
        for i in 0..n {
            for d in 0..3 {
                x[i][d] += alpha[d] * p[i][d];
                r[i][d] -= alpha[d] * ap[i][d];
            }
        }
        rr = dots(&r, &r);
        if done(rr) {
            return CgStats { iterations: iteration, relative_residual: relative(rr) };
        }
        m.apply(&r, &mut z);
        let rz_next = dots(&r, &z);
        let beta: [f64; 3] = std::array::from_fn(|d| if rz[d] != 0.0 { rz_next[d] / rz[d] } else { 0.0 });
        rz = rz_next;
        for i in 0..n {
            for d in 0..3 {
                p[i][d] = z[i][d] + beta[d] * p[i][d];
            }
        }
    }
    CgStats { iterations: max_iterations, relative_residual: relative(rr) }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 1D Laplacian chain plus a shift, coupled to a second chain: SPD, not block diagonal.
    fn matrix(n: usize) -> SparseColMat<usize, f64> {
        let mut t = Vec::new();
        for i in 0..n {
            t.push(Triplet::new(i, i, 2.5 + 0.1 * (i % 3) as f64));
            if i + 1 < n {
                t.push(Triplet::new(i + 1, i, -1.0));
            }
            if i + 7 < n {
                t.push(Triplet::new(i + 7, i, -0.2));
            }
        }
        SparseColMat::try_new_from_triplets(n, n, &t).unwrap()
    }

    #[test]
    fn pcg_matches_the_direct_solve_and_the_full_rows_match_the_lower_triangle() {
        let n = 200;
        let lower = matrix(n);
        let rows = SymmetricRows::from_lower(&lower);
        assert_eq!(rows.nnz(), 2 * lower.compute_nnz() - n);
        let b: Vec<Point> = (0..n).map(|i| [(i as f64).sin(), 1.0, if i % 2 == 0 { 0.0 } else { 1.0 }]).collect();
        let direct = Cholesky::factor(&lower, &FillOrdering::Amd, Par::Seq).unwrap();
        let mut expected = b.clone();
        direct.solve_rows3(&mut expected);
        // A x = b through the full rows.
        let mut ax = vec![[0.0; 3]; n];
        rows.apply(&expected, &mut ax);
        for i in 0..n {
            for d in 0..3 {
                assert!((ax[i][d] - b[i][d]).abs() < 1e-12, "row {i}");
            }
        }
        let block_of: Vec<u32> = (0..n).map(|i| (i / 40) as u32).collect();
        let m = BlockJacobi::new(&lower, &block_of, 5, None).unwrap();
        // Ordered by a rank (reversed index), the same preconditioner up to roundoff.
        let rank: Vec<u32> = (0..n as u32).rev().collect();
        let ranked = BlockJacobi::new(&lower, &block_of, 5, Some(&rank)).unwrap();
        let (mut z0, mut z1) = (vec![[0.0; 3]; n], vec![[0.0; 3]; n]);
        m.apply(&b, &mut z0);
        ranked.apply(&b, &mut z1);
        for i in 0..n {
            for d in 0..3 {
                assert!((z0[i][d] - z1[i][d]).abs() < 1e-12 * (1.0 + z0[i][d].abs()), "row {i}");
            }
        }
        // From zero, from the answer (no iteration), and from a poor start.
        for start in [vec![[0.0; 3]; n], expected.clone(), vec![[1e3, -1e3, 5.0]; n]] {
            let mut x = start;
            let stats = pcg(&rows, &m, &b, &mut x, 1e-12, 500);
            assert!(stats.relative_residual <= 1e-12, "{stats:?}");
            for i in 0..n {
                for d in 0..3 {
                    assert!((x[i][d] - expected[i][d]).abs() < 1e-9, "row {i}: {stats:?}");
                }
            }
        }
        // One block is the exact inverse: one iteration.
        let exact = BlockJacobi::new(&lower, &vec![0; n], 1, None).unwrap();
        let mut x = vec![[0.0; 3]; n];
        assert!(pcg(&rows, &exact, &b, &mut x, 1e-10, 500).iterations <= 1);
    }
}
