//! Forward and backward sweeps of a supernodal `L Lᵀ` for three right-hand sides.
//!
//! Supernode `s` stores its columns as one column-major block of `w + r` rows (the `w x w`
//! lower-triangular diagonal block, then the `r` rows of its pattern). Each sweep reads every
//! column once, front to back, and does its arithmetic on the three right-hand sides together:
//! memory traffic is the factor, once per sweep. Reductions use [`LANES`] explicit partial sums
//! combined in a fixed order, so the result does not depend on the SIMD width: the AVX2 build of
//! the same code (chosen at run time) gives the same bytes as the baseline one.
//!
//! Two threads: a [`SplitPlan`] cuts the elimination tree below its top chain into two groups of
//! independent subtrees, swept concurrently (`rayon::join`); contributions to the top rows are
//! collected per group and added in a fixed order, so the bytes do not depend on the thread
//! count.

use std::ops::Range;

use faer::sparse::linalg::cholesky::supernodal::SymbolicSupernodalCholesky;

use super::split::SplitPlan;
use crate::algorithms::physics::lanes::simd_dispatch;

/// A supernodal factor to sweep: its symbolic structure, its values, and how to split it
/// between two threads (none: one thread sweeps all).
pub(super) struct SupernodalSolve<'a> {
    pub(super) sym: &'a SymbolicSupernodalCholesky<usize>,
    pub(super) values: &'a [f64],
    pub(super) plan: Option<&'a SplitPlan>,
}

/// Partial sums per reduction (the width of an AVX2 register of `f64`).
const LANES: usize = 4;

impl SupernodalSolve<'_> {
    /// `y` holds the three permuted right-hand sides one after the other.
    pub(super) fn solve(&self, y: &mut [f64]) {
        let sym = self.sym;
        let (n, ns) = (sym.nrows(), sym.n_supernodes());
        let (y0, rest) = y.split_at_mut(n);
        let (y1, y2) = rest.split_at_mut(n);
        let mut y = [y0, y1, y2];
        let Some(plan) = self.plan else {
            sweep_forward(self, 0..ns, &mut y, 0, &mut [&mut [], &mut [], &mut []], n);
            sweep_backward(self, 0..ns, &mut y, 0, [&[], &[], &[]], n);
            return;
        };
        let (a, b, top) = (0..plan.b_first, plan.b_first..plan.top_first, plan.top_first..ns);
        let (b_row, top_row) = (plan.b_row, plan.top_row);
        // Forward: the two groups, each collecting what it sends to the top rows; then the top.
        let n_top = n - top_row;
        {
            let (mut ya, mut yb, mut yt) = split_rows(&mut y, b_row, top_row);
            let group = |range: Range<usize>, own: &mut [&mut [f64]; 3], own_row: usize| {
                let mut spill = vec![0.0; 3 * n_top];
                let (s0, r) = spill.split_at_mut(n_top);
                let (s1, s2) = r.split_at_mut(n_top);
                sweep_forward(self, range, own, own_row, &mut [s0, s1, s2], top_row);
                spill
            };
            let (spill_a, spill_b) = rayon::join(|| group(a.clone(), &mut ya, 0), || group(b.clone(), &mut yb, b_row));
            for d in 0..3 {
                for (i, v) in yt[d].iter_mut().enumerate() {
                    *v = (*v + spill_a[d * n_top + i]) + spill_b[d * n_top + i];
                }
            }
            sweep_forward(self, top.clone(), &mut yt, top_row, &mut [&mut [], &mut [], &mut []], n);
        }
        // Backward: the top, then the two groups reading the solved top rows.
        let (mut ya, mut yb, mut yt) = split_rows(&mut y, b_row, top_row);
        sweep_backward(self, top, &mut yt, top_row, [&[], &[], &[]], n);
        let yt = [&*yt[0], &*yt[1], &*yt[2]];
        rayon::join(|| sweep_backward(self, a, &mut ya, 0, yt, top_row), || sweep_backward(self, b, &mut yb, b_row, yt, top_row));
    }

    /// Forward sweeps of the supernodes `range` in order (see [`SupernodalSolve::forward`]);
    /// [`sweep_forward`] runs it compiled for AVX2 when the CPU has it.
    #[inline(always)]
    fn sweep_forward_generic(&self, range: Range<usize>, own: &mut Rows3, own_row: usize, spill: &mut Rows3, spill_row: usize) {
        let mut tmp = self.work_space(range.clone());
        for s in range {
            self.forward(s, own, own_row, spill, spill_row, &mut tmp);
        }
    }

    /// Backward sweeps of the supernodes `range` in reverse order (see
    /// [`SupernodalSolve::backward`]); [`sweep_backward`] runs it compiled for AVX2 when the CPU
    /// has it.
    #[inline(always)]
    fn sweep_backward_generic(&self, range: Range<usize>, own: &mut Rows3, own_row: usize, above: [&[f64]; 3], above_row: usize) {
        let mut tmp = self.work_space(range.clone());
        for s in range.rev() {
            self.backward(s, own, own_row, above, above_row, &mut tmp);
        }
    }

    /// Work space for the tallest supernode of `range`: its rows, three coordinates.
    fn work_space(&self, range: Range<usize>) -> Vec<f64> {
        let sym = self.sym;
        let height = |s: usize| sym.supernode_end()[s] - sym.supernode_begin()[s] + sym.supernode(s).pattern().len();
        vec![0.0; 3 * range.map(height).max().unwrap_or(0)]
    }

    /// Supernode `s`: its first column, width, pattern and values.
    #[inline(always)]
    fn block(&self, s: usize) -> (usize, usize, &[usize], &[f64]) {
        let sym = self.sym;
        let start = sym.supernode_begin()[s];
        let w = sym.supernode_end()[s] - start;
        let pattern = sym.supernode(s).pattern();
        let cp = sym.col_ptr_for_val();
        (start, w, pattern, &self.values[cp[s]..cp[s + 1]])
    }

    #[inline(always)]
    /// Forward sweep of supernode `s`. Its own rows (and pattern rows below `spill_row`) live
    /// in `own` from row `own_row`; pattern rows from `spill_row` on receive their updates in
    /// `spill` (from row `spill_row`).
    fn forward(&self, s: usize, own: &mut [&mut [f64]; 3], own_row: usize, spill: &mut [&mut [f64]; 3], spill_row: usize, tmp: &mut [f64]) {
        let (start, w, pattern, blk) = self.block(s);
        let start = start - own_row;
        let r = pattern.len();
        let ld = w + r;
        // Work on the whole column height at once: u = (y of the block's rows, then zeros for
        // the pattern rows), one contiguous array per coordinate.
        let (u0, rest) = tmp[..3 * ld].split_at_mut(ld);
        let (u1, u2) = rest.split_at_mut(ld);
        let mut u = [u0, u1, u2];
        for d in 0..3 {
            u[d][..w].copy_from_slice(&own[d][start..start + w]);
            u[d][w..].fill(0.0);
        }
        // Four columns at a time: solve their 4x4 triangle, then subtract their contribution
        // from every row below (one contiguous slice of each column).
        let mut k = 0;
        while k < w {
            let q = (w - k).min(4);
            let mut a = [[0.0; 3]; 4];
            for j in 0..q {
                let col = &blk[(k + j) * ld..(k + j + 1) * ld];
                for d in 0..3 {
                    let mut v = u[d][k + j];
                    for (i, ai) in a.iter().enumerate().take(j) {
                        v -= blk[(k + i) * ld + k + j] * ai[d];
                    }
                    a[j][d] = v / col[k + j];
                    u[d][k + j] = a[j][d];
                }
            }
            let below = k + q;
            if q == 4 {
                let c = [0, 1, 2, 3].map(|j| &blk[(k + j) * ld + below..(k + j + 1) * ld]);
                update4(&mut u, below, c, a);
            } else {
                for j in 0..q {
                    let c = &blk[(k + j) * ld + below..(k + j + 1) * ld];
                    for d in 0..3 {
                        for (v, l) in u[d][below..].iter_mut().zip(c) {
                            *v -= l * a[j][d];
                        }
                    }
                }
            }
            k += q;
        }
        let split = pattern.partition_point(|&p| p < spill_row);
        for d in 0..3 {
            own[d][start..start + w].copy_from_slice(&u[d][..w]);
            for (&p, v) in pattern[..split].iter().zip(&u[d][w..w + split]) {
                own[d][p - own_row] += v;
            }
            for (&p, v) in pattern[split..].iter().zip(&u[d][w + split..]) {
                spill[d][p - spill_row] += v;
            }
        }
    }

    #[inline(always)]
    /// Backward sweep of supernode `s`: its rows live in `own` from row `own_row`, solved
    /// pattern rows below `above_row` too, and those from `above_row` on in `above`.
    fn backward(&self, s: usize, own: &mut [&mut [f64]; 3], own_row: usize, above: [&[f64]; 3], above_row: usize, tmp: &mut [f64]) {
        let (start, w, pattern, blk) = self.block(s);
        let start = start - own_row;
        let r = pattern.len();
        let ld = w + r;
        // u = (y of the block's rows, then the already solved pattern rows).
        let (u0, rest) = tmp[..3 * ld].split_at_mut(ld);
        let (u1, u2) = rest.split_at_mut(ld);
        let u = [u0, u1, u2];
        let split = pattern.partition_point(|&p| p < above_row);
        for d in 0..3 {
            u[d][..w].copy_from_slice(&own[d][start..start + w]);
            for (&p, v) in pattern[..split].iter().zip(&mut u[d][w..w + split]) {
                *v = own[d][p - own_row];
            }
            for (&p, v) in pattern[split..].iter().zip(&mut u[d][w + split..]) {
                *v = above[d][p - above_row];
            }
        }
        // Columns in pairs from the last: x_k = (u_k - Σ_{i>k} L_ik x_i) / L_kk, the sums over
        // the rows below the pair taken as one dot product per column.
        let mut k = w;
        while k > 0 {
            if k >= 2 {
                let (k0, k1) = (k - 2, k - 1);
                let (c0, c1) = (&blk[k0 * ld + k..(k0 + 1) * ld], &blk[k1 * ld + k..(k1 + 1) * ld]);
                let dots = dot3x2(c0, c1, [&u[0][k..], &u[1][k..], &u[2][k..]]);
                let (l11, l10, l00) = (blk[k1 * ld + k1], blk[k0 * ld + k1], blk[k0 * ld + k0]);
                for d in 0..3 {
                    let x1 = (u[d][k1] - dots[1][d]) / l11;
                    u[d][k1] = x1;
                    u[d][k0] = (u[d][k0] - dots[0][d] - l10 * x1) / l00;
                }
                k -= 2;
            } else {
                let col = &blk[1..ld];
                let dot = dot3(col, [&u[0][1..], &u[1][1..], &u[2][1..]]);
                for d in 0..3 {
                    u[d][0] = (u[d][0] - dot[d]) / blk[0];
                }
                k = 0;
            }
        }
        for d in 0..3 {
            own[d][start..start + w].copy_from_slice(&u[d][..w]);
        }
    }
}

/// The rows of three columns cut at `b_row` and `top_row`: (group A, group B, top).
type Rows3<'a> = [&'a mut [f64]; 3];
fn split_rows<'a>(y: &'a mut Rows3<'_>, b_row: usize, top_row: usize) -> (Rows3<'a>, Rows3<'a>, Rows3<'a>) {
    let [y0, y1, y2] = y;
    let (a0, r0) = y0.split_at_mut(b_row);
    let (b0, t0) = r0.split_at_mut(top_row - b_row);
    let (a1, r1) = y1.split_at_mut(b_row);
    let (b1, t1) = r1.split_at_mut(top_row - b_row);
    let (a2, r2) = y2.split_at_mut(b_row);
    let (b2, t2) = r2.split_at_mut(top_row - b_row);
    ([a0, a1, a2], [b0, b1, b2], [t0, t1, t2])
}

/// `u_d[from..] -= Σ_j c_j a_j,d` for four columns `c_j` (each `u_d.len() - from` long).
#[inline(always)]
fn update4(u: &mut [&mut [f64]; 3], from: usize, c: [&[f64]; 4], a: [[f64; 3]; 4]) {
    let m = u[0].len() - from;
    let (c0, c1, c2, c3) = (&c[0][..m], &c[1][..m], &c[2][..m], &c[3][..m]);
    let [u0, u1, u2] = u;
    let (u0, u1, u2) = (&mut u0[from..from + m], &mut u1[from..from + m], &mut u2[from..from + m]);
    // Rows outer, coordinates inner: each entry of the four columns is read once.
    for i in 0..m {
        let (l0, l1, l2, l3) = (c0[i], c1[i], c2[i], c3[i]);
        u0[i] -= (l0 * a[0][0] + l1 * a[1][0]) + (l2 * a[2][0] + l3 * a[3][0]);
        u1[i] -= (l0 * a[0][1] + l1 * a[1][1]) + (l2 * a[2][1] + l3 * a[3][1]);
        u2[i] -= (l0 * a[0][2] + l1 * a[1][2]) + (l2 * a[2][2] + l3 * a[3][2]);
    }
}

/// `Σ_i a_i b_d,i` for three vectors `b_d`, with [`LANES`] partial sums added pairwise at the
/// end (a fixed order, independent of the instruction set).
#[inline(always)]
fn dot3(a: &[f64], b: [&[f64]; 3]) -> [f64; 3] {
    let n = a.len();
    let b = [&b[0][..n], &b[1][..n], &b[2][..n]];
    let mut acc = [[0.0; LANES]; 3];
    let chunks = n / LANES;
    for c in 0..chunks {
        let o = c * LANES;
        let p = &a[o..o + LANES];
        let (x0, x1, x2) = (&b[0][o..o + LANES], &b[1][o..o + LANES], &b[2][o..o + LANES]);
        for l in 0..LANES {
            acc[0][l] += p[l] * x0[l];
            acc[1][l] += p[l] * x1[l];
            acc[2][l] += p[l] * x2[l];
        }
    }
    let tail = chunks * LANES;
    [0, 1, 2].map(|d| {
        let mut s = combine(&acc[d]);
        for i in tail..n {
            s += a[i] * b[d][i];
        }
        s
    })
}

/// Two columns' [`dot3`] at once, sharing the loads of `b` (same arithmetic per column).
#[inline(always)]
fn dot3x2(a0: &[f64], a1: &[f64], b: [&[f64]; 3]) -> [[f64; 3]; 2] {
    let n = a0.len();
    let (a1, b) = (&a1[..n], [&b[0][..n], &b[1][..n], &b[2][..n]]);
    let chunks = n / LANES;
    let acc = lane_sums_3x2(a0, a1, b, chunks);
    let tail = chunks * LANES;
    let column = |a: &[f64], acc: &[[f64; LANES]; 3]| {
        [0, 1, 2].map(|d| {
            let mut s = combine(&acc[d]);
            for i in tail..n {
                s += a[i] * b[d][i];
            }
            s
        })
    };
    [column(a0, &acc[0]), column(a1, &acc[1])]
}

/// Lane-wise partial sums of [`dot3x2`] over the first `chunks * LANES` entries.
#[inline(always)]
fn lane_sums_3x2(a0: &[f64], a1: &[f64], b: [&[f64]; 3], chunks: usize) -> [[[f64; LANES]; 3]; 2] {
    #[cfg(target_arch = "x86_64")]
    if cfg!(target_feature = "avx2") || std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: AVX2 is available; every load reads `LANES` entries below `chunks * LANES`,
        // which is within all five slices (checked by the callers' slicing to equal lengths).
        return unsafe { lane_sums_3x2_avx2(a0, a1, b, chunks) };
    }
    let mut acc = [[[0.0; LANES]; 3]; 2];
    for c in 0..chunks {
        let o = c * LANES;
        for l in 0..LANES {
            let (p0, p1) = (a0[o + l], a1[o + l]);
            for d in 0..3 {
                acc[0][d][l] += p0 * b[d][o + l];
                acc[1][d][l] += p1 * b[d][o + l];
            }
        }
    }
    acc
}

/// [`lane_sums_3x2`] with one 4-lane register per partial sum (multiply, then add: the same
/// rounding as the portable loop).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn lane_sums_3x2_avx2(a0: &[f64], a1: &[f64], b: [&[f64]; 3], chunks: usize) -> [[[f64; LANES]; 3]; 2] {
    use std::arch::x86_64::*;
    assert!(a0.len() >= chunks * LANES && a1.len() >= chunks * LANES && b.iter().all(|v| v.len() >= chunks * LANES));
    let z = _mm256_setzero_pd();
    let (mut s00, mut s01, mut s02, mut s10, mut s11, mut s12) = (z, z, z, z, z, z);
    let (pa0, pa1) = (a0.as_ptr(), a1.as_ptr());
    let (pb0, pb1, pb2) = (b[0].as_ptr(), b[1].as_ptr(), b[2].as_ptr());
    for c in 0..chunks {
        let o = c * LANES;
        let (x0, x1) = (_mm256_loadu_pd(pa0.add(o)), _mm256_loadu_pd(pa1.add(o)));
        let (y0, y1, y2) = (_mm256_loadu_pd(pb0.add(o)), _mm256_loadu_pd(pb1.add(o)), _mm256_loadu_pd(pb2.add(o)));
        s00 = _mm256_add_pd(s00, _mm256_mul_pd(x0, y0));
        s01 = _mm256_add_pd(s01, _mm256_mul_pd(x0, y1));
        s02 = _mm256_add_pd(s02, _mm256_mul_pd(x0, y2));
        s10 = _mm256_add_pd(s10, _mm256_mul_pd(x1, y0));
        s11 = _mm256_add_pd(s11, _mm256_mul_pd(x1, y1));
        s12 = _mm256_add_pd(s12, _mm256_mul_pd(x1, y2));
    }
    let out = |v: __m256d| {
        let mut a = [0.0; LANES];
        _mm256_storeu_pd(a.as_mut_ptr(), v);
        a
    };
    [[out(s00), out(s01), out(s02)], [out(s10), out(s11), out(s12)]]
}

#[inline(always)]
fn combine(q: &[f64; LANES]) -> f64 {
    (q[0] + q[2]) + (q[1] + q[3])
}

simd_dispatch!(sweep_forward, ["avx2"], fn(this: &SupernodalSolve, range: Range<usize>, own: &mut Rows3, own_row: usize, spill: &mut Rows3, spill_row: usize) -> () {
    this.sweep_forward_generic(range, own, own_row, spill, spill_row)
});

simd_dispatch!(sweep_backward, ["avx2"], fn(this: &SupernodalSolve, range: Range<usize>, own: &mut Rows3, own_row: usize, above: [&[f64]; 3], above_row: usize) -> () {
    this.sweep_backward_generic(range, own, own_row, above, above_row)
});
