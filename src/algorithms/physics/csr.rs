//! A compressed-sparse-row matrix acting on per-node 3-vectors (`L x` with `x` an n×3 array),
//! with the one product the spacetime normal equations need: `L diag(d) L`.

use rayon::prelude::*;

use crate::algorithms::geometry::Point;

/// A square sparse matrix in compressed rows.
#[derive(Debug, Clone, PartialEq)]
pub struct Csr {
    /// Rows, and columns.
    pub n: usize,
    /// Row `i`'s entries are `row_ptr[i]..row_ptr[i + 1]` of `cols` and `vals` (`n + 1` offsets).
    pub row_ptr: Vec<usize>,
    /// Column indices, increasing within each row.
    pub cols: Vec<u32>,
    /// Values of the stored entries, parallel to `cols`.
    pub vals: Vec<f64>,
}

impl Csr {
    /// Build from `(row, col, value)` triplets; duplicates are summed (in a fixed order, so
    /// the result does not depend on anything but the input).
    pub(crate) fn from_triplets(n: usize, mut triplets: Vec<(u32, u32, f64)>) -> Csr {
        triplets.sort_by_key(|&(r, c, _)| (r, c));
        let mut row_ptr = vec![0usize; n + 1];
        let mut cols = Vec::with_capacity(triplets.len());
        let mut vals: Vec<f64> = Vec::with_capacity(triplets.len());
        let mut last: Option<(u32, u32)> = None;
        for (r, c, v) in triplets {
            if last == Some((r, c)) {
                *vals.last_mut().expect("a previous entry") += v;
            } else {
                cols.push(c);
                vals.push(v);
                row_ptr[r as usize + 1] += 1;
                last = Some((r, c));
            }
        }
        for i in 0..n {
            row_ptr[i + 1] += row_ptr[i];
        }
        Csr { n, row_ptr, cols, vals }
    }

    /// Stored entries.
    pub fn nnz(&self) -> usize {
        self.vals.len()
    }

    /// The entries of row `i` as (column, value).
    pub fn row(&self, i: usize) -> impl Iterator<Item = (usize, f64)> + '_ {
        let r = self.row_ptr[i]..self.row_ptr[i + 1];
        self.cols[r.clone()].iter().zip(&self.vals[r]).map(|(&c, &v)| (c as usize, v))
    }

    /// Entry (i, j), zero when not stored.
    pub fn get(&self, i: usize, j: usize) -> f64 {
        let r = self.row_ptr[i]..self.row_ptr[i + 1];
        match self.cols[r.clone()].binary_search(&(j as u32)) {
            Ok(k) => self.vals[r.start + k],
            Err(_) => 0.0,
        }
    }

    /// `out = self * x` for n×3 arrays, rows in parallel (each row summed in column order).
    pub fn mul_points(&self, x: &[Point], out: &mut [Point]) {
        out.par_iter_mut().enumerate().with_min_len(256).for_each(|(i, o)| {
            let mut acc = [0.0; 3];
            for (j, v) in self.row(i) {
                acc[0] += v * x[j][0];
                acc[1] += v * x[j][1];
                acc[2] += v * x[j][2];
            }
            *o = acc;
        });
    }

    /// [`Csr::mul_points`] on the calling thread (the same sums), for callers that are
    /// already parallel.
    pub fn mul_points_sequential(&self, x: &[Point], out: &mut [Point]) {
        for (i, o) in out.iter_mut().enumerate() {
            let mut acc = [0.0; 3];
            for (j, v) in self.row(i) {
                acc[0] += v * x[j][0];
                acc[1] += v * x[j][1];
                acc[2] += v * x[j][2];
            }
            *o = acc;
        }
    }

    /// [`Csr::mul_points_sequential`] of two vectors in one pass over the matrix (the same sums).
    pub(crate) fn mul_points_pair_sequential(&self, x: [&[Point]; 2], out: [&mut [Point]; 2]) {
        let [ox, oy] = out;
        for (i, (o, p)) in ox.iter_mut().zip(oy.iter_mut()).enumerate() {
            let (mut a, mut b) = ([0.0; 3], [0.0; 3]);
            for (j, v) in self.row(i) {
                a[0] += v * x[0][j][0];
                a[1] += v * x[0][j][1];
                a[2] += v * x[0][j][2];
                b[0] += v * x[1][j][0];
                b[1] += v * x[1][j][1];
                b[2] += v * x[1][j][2];
            }
            (*o, *p) = (a, b);
        }
    }

    /// `self * diag(d) * self` for a symmetric `self` (its pattern is the 2-ring of the graph).
    pub(crate) fn sandwich_diagonal(&self, d: &[f64]) -> Csr {
        let n = self.n;
        let rows: Vec<(Vec<u32>, Vec<f64>)> = (0..n)
            .into_par_iter()
            .map_init(
                || (vec![0.0f64; n], vec![false; n]),
                |(acc, seen), i| {
                    let mut touched = Vec::new();
                    for (k, lik) in self.row(i) {
                        let s = lik * d[k];
                        for (j, lkj) in self.row(k) {
                            if !seen[j] {
                                seen[j] = true;
                                touched.push(j as u32);
                            }
                            acc[j] += s * lkj;
                        }
                    }
                    touched.sort_unstable();
                    let vals = touched.iter().map(|&j| std::mem::take(&mut acc[j as usize])).collect();
                    for &j in &touched {
                        seen[j as usize] = false;
                    }
                    (touched, vals)
                },
            )
            .collect();
        let mut row_ptr = Vec::with_capacity(n + 1);
        row_ptr.push(0);
        let (mut cols, mut vals) = (Vec::new(), Vec::new());
        for (c, v) in rows {
            cols.extend(c);
            vals.extend(v);
            row_ptr.push(cols.len());
        }
        Csr { n, row_ptr, cols, vals }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn triplets_merge_and_products_match_dense() {
        // A path graph Laplacian on 5 nodes.
        let mut t = Vec::new();
        for i in 0..4u32 {
            t.extend([(i, i, 1.0), (i + 1, i + 1, 1.0), (i, i + 1, -1.0), (i + 1, i, -1.0)]);
        }
        let l = Csr::from_triplets(5, t);
        assert_eq!(l.get(1, 1), 2.0);
        assert_eq!(l.get(0, 4), 0.0);
        let d = [1.0, 2.0, 0.5, 4.0, 1.0];
        let k = l.sandwich_diagonal(&d);
        for i in 0..5 {
            for j in 0..5 {
                let dense: f64 = (0..5).map(|m| l.get(i, m) * d[m] * l.get(m, j)).sum();
                assert!((k.get(i, j) - dense).abs() < 1e-14, "({i},{j})");
            }
        }
        let x: Vec<Point> = (0..5).map(|i| [i as f64, 1.0, (i * i) as f64]).collect();
        let mut y = vec![[0.0; 3]; 5];
        l.mul_points(&x, &mut y);
        assert_eq!(y[2], [0.0, 0.0, -2.0]);
    }
}
