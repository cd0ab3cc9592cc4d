//! Numeric supernodal `L Lᵀ` over faer's symbolic analysis, with the two halves of the
//! elimination tree on two threads.
//!
//! faer's own supernodal factorization parallelizes only inside dense supernodes (1.3x on two
//! cores). This is the same left-looking algorithm (supernode `s` gathers the updates of its
//! descendants, then factors its diagonal block and solves the rows under it), with faer's
//! dense kernels, scheduled by the [`SplitPlan`]:
//!
//! 1. the two groups of independent subtrees are factored concurrently, each on one core (a
//!    supernode's descendants are in its own subtree);
//! 2. then the top supernodes in order: a large one's columns are cut in two halves of equal
//!    entries, each gathering the updates of all descendants on its own core; the dense
//!    diagonal block and the solve under it use both cores inside faer's kernels.
//!
//! Without a plan (a tree that does not branch below its top chain) every supernode is
//! factored as a top one.
//!
//! The arithmetic is fixed by the plan, not by the threads: one thread (a one-thread pool, or
//! `Par::Seq`) runs the same operations in the same order and gives the same bytes.

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::{cholesky_in_place, cholesky_in_place_scratch, LltRegularization};
use faer::linalg::matmul::triangular::BlockStructure;
use faer::reborrow::{Reborrow, ReborrowMut};
use faer::sparse::linalg::cholesky::supernodal::SymbolicSupernodalCholesky;
use faer::sparse::SparseColMatRef;
use faer::{Accum, MatMut, MatRef, Par};
use std::ops::Range;

use super::split::{GroupPlan, TOP};
use super::NotPositiveDefinite;

/// For every supernode `s`, the supernodes `d < s` whose pattern has a row among `s`'s
/// columns (the descendants that update `s`), in increasing order.
pub(super) struct Updates {
    ptr: Vec<usize>,
    from: Vec<usize>,
}

impl Updates {
    pub(super) fn new(sym: &SymbolicSupernodalCholesky<usize>) -> Updates {
        let ns = sym.n_supernodes();
        let end = sym.supernode_end();
        let mut owner = vec![0usize; sym.nrows()];
        for s in 0..ns {
            owner[sym.supernode_begin()[s]..end[s]].fill(s);
        }
        let owner = &owner;
        // Patterns are sorted, so the supernodes a pattern reaches come in order; count, then fill.
        let targets = |d: usize| {
            let mut last = usize::MAX;
            sym.supernode(d).pattern().iter().filter_map(move |&r| {
                let s = owner[r];
                (s != last).then(|| {
                    last = s;
                    s
                })
            })
        };
        let mut ptr = vec![0usize; ns + 1];
        for d in 0..ns {
            for s in targets(d) {
                ptr[s + 1] += 1;
            }
        }
        for s in 0..ns {
            ptr[s + 1] += ptr[s];
        }
        let mut next = ptr.clone();
        let mut from = vec![0usize; ptr[ns]];
        for d in 0..ns {
            for s in targets(d) {
                from[next[s]] = d;
                next[s] += 1;
            }
        }
        Updates { ptr, from }
    }

    fn of(&self, s: usize) -> &[usize] {
        &self.from[self.ptr[s]..self.ptr[s + 1]]
    }
}

/// Predicted flops of every supernode's own work: its diagonal block's Cholesky, the solve
/// under it, and the updates it sends to its ancestors. The split balances these.
pub(super) fn supernode_flops(sym: &SymbolicSupernodalCholesky<usize>) -> Vec<usize> {
    (0..sym.n_supernodes())
        .map(|s| {
            let w = sym.supernode_end()[s] - sym.supernode_begin()[s];
            let r = sym.supernode(s).pattern().len();
            w * w * w / 3 + r * w * w + r * r * w
        })
        .collect()
}

/// Columns of an update's product formed at once (bounds the product's memory: rows x 64).
const PRODUCT_COLUMNS: usize = 64;

/// One thread's scratch: the positions of the current supernode's pattern rows, the update
/// products, and faer's dense Cholesky scratch.
struct Scratch {
    local: Vec<usize>,
    product: Vec<f64>,
    dense: MemBuffer,
}

impl Scratch {
    fn new(sym: &SymbolicSupernodalCholesky<usize>, par: Par) -> Scratch {
        let widest = (0..sym.n_supernodes()).map(|s| sym.supernode_end()[s] - sym.supernode_begin()[s]).max().unwrap_or(0);
        Scratch {
            local: vec![usize::MAX; sym.nrows()],
            product: Vec::new(),
            dense: MemBuffer::new(cholesky_in_place_scratch::<f64>(widest, par, Default::default())),
        }
    }
}

/// The factorization's inputs: the symbolic structure, the update lists and the matrix.
struct Front<'a> {
    sym: &'a SymbolicSupernodalCholesky<usize>,
    updates: &'a Updates,
    lower: SparseColMatRef<'a, usize, f64>,
}

/// Factor `lower` (same pattern as the analysed matrix) into `values`, splitting the work by
/// `plan` when there is one; `par` is used inside the top supernodes' dense kernels, and
/// `Par::Seq` runs everything on this thread (same bytes).
pub(super) fn factorize(
    sym: &SymbolicSupernodalCholesky<usize>,
    updates: &Updates,
    plan: Option<&GroupPlan>,
    values: &mut [f64],
    lower: SparseColMatRef<'_, usize, f64>,
    par: Par,
) -> Result<(), NotPositiveDefinite> {
    let front = Front { sym, updates, lower };
    let ns = sym.n_supernodes();
    let cp = sym.col_ptr_for_val();
    // One block of values per supernode, each owned by the thread that computes it.
    let mut blocks: Vec<&mut [f64]> = Vec::with_capacity(ns);
    let mut rest = values;
    for s in 0..ns {
        let (block, tail) = rest.split_at_mut(cp[s + 1] - cp[s]);
        blocks.push(block);
        rest = tail;
    }
    // Without a plan every supernode is a top one.
    let top = |s: usize| plan.is_none_or(|p| p.owner[s] == TOP);
    if let Some(plan) = plan {
        let (mut a, mut b, mut t) = (Vec::with_capacity(ns), Vec::with_capacity(ns), Vec::with_capacity(ns));
        for (s, block) in blocks.into_iter().enumerate() {
            let mine = |g: u8| plan.owner[s] == g;
            let (block_a, rest): (&mut [f64], &mut [f64]) = if mine(0) { (block, &mut []) } else { (&mut [], block) };
            let (block_b, block_t): (&mut [f64], &mut [f64]) = if mine(1) { (rest, &mut []) } else { (&mut [], rest) };
            a.push(block_a);
            b.push(block_b);
            t.push(block_t);
        }
        let group = |blocks: &mut Vec<&mut [f64]>, g: u8| front.group(blocks, |s| plan.owner[s] == g, &mut Scratch::new(sym, Par::Seq));
        let (ra, rb) = join(par, || group(&mut a, 0), || group(&mut b, 1));
        ra?;
        rb?;
        blocks = a.into_iter().zip(b).zip(t).enumerate().map(|(s, ((a, b), t))| [a, b, t].into_iter().nth(plan.owner[s] as usize).unwrap()).collect();
    }
    // The top: a large supernode's columns in two halves of about equal update work, each
    // gathering the updates of all descendants on its own thread; then the dense diagonal
    // block on both.
    let mut scratch = Scratch::new(sym, par);
    let mut other = Vec::new();
    for s in (0..ns).filter(|&s| top(s)) {
        let (done, rest) = blocks.split_at_mut(s);
        let ls = &mut *rest[0];
        front.scatter_pattern(s, &mut scratch.local);
        front.assemble(s, ls, &scratch.local);
        let (w, rows) = (front.width(s), ls.len() / front.width(s));
        let half = if ls.len() >= SPLIT_ENTRIES { front.half(s) } else { w };
        let (left, right) = ls.split_at_mut(half * rows);
        let (local, product, done) = (&scratch.local, &mut scratch.product, &*done);
        join(par, || front.update(s, left, 0..half, done, local, product), || front.update(s, right, half..w, done, local, &mut other));
        front.finish(s, ls, &mut scratch, par)?;
        front.clear_pattern(s, &mut scratch.local);
    }
    Ok(())
}

/// Entries of a top supernode from which its updates are gathered in two halves concurrently
/// (below, a `rayon::join` costs more than it saves).
const SPLIT_ENTRIES: usize = 1 << 14;

/// `rayon::join`, or the two calls in order on this thread for `Par::Seq`.
fn join<A: Send, B: Send>(par: Par, a: impl FnOnce() -> A + Send, b: impl FnOnce() -> B + Send) -> (A, B) {
    match par {
        Par::Seq => (a(), b()),
        _ => rayon::join(a, b),
    }
}

impl Front<'_> {
    /// Factor the supernodes `mine` (whole subtrees) in order on this thread; `blocks` holds
    /// their values (the others' are empty).
    fn group(&self, blocks: &mut [&mut [f64]], mine: impl Fn(usize) -> bool, scratch: &mut Scratch) -> Result<(), NotPositiveDefinite> {
        for s in (0..blocks.len()).filter(|&s| mine(s)) {
            let (done, rest) = blocks.split_at_mut(s);
            let ls = &mut *rest[0];
            self.scatter_pattern(s, &mut scratch.local);
            self.assemble(s, ls, &scratch.local);
            self.update(s, ls, 0..self.width(s), done, &scratch.local, &mut scratch.product);
            self.finish(s, ls, scratch, Par::Seq)?;
            self.clear_pattern(s, &mut scratch.local);
        }
        Ok(())
    }

    fn scatter_pattern(&self, s: usize, local: &mut [usize]) {
        let w = self.width(s);
        for (i, &r) in self.sym.supernode(s).pattern().iter().enumerate() {
            local[r] = w + i;
        }
    }

    fn clear_pattern(&self, s: usize, local: &mut [usize]) {
        for &r in self.sym.supernode(s).pattern() {
            local[r] = usize::MAX;
        }
    }

    fn width(&self, s: usize) -> usize {
        self.sym.supernode_end()[s] - self.sym.supernode_begin()[s]
    }

    /// Row `r`'s position in supernode `s`'s block (`local` holds its pattern's positions).
    #[inline]
    fn position(&self, s: usize, r: usize, local: &[usize]) -> usize {
        let (begin, end) = (self.sym.supernode_begin()[s], self.sym.supernode_end()[s]);
        if r < end {
            r - begin
        } else {
            local[r]
        }
    }

    /// `ls` = the matrix's lower-triangle entries of `s`'s columns.
    fn assemble(&self, s: usize, ls: &mut [f64], local: &[usize]) {
        ls.fill(0.0);
        let (begin, end) = (self.sym.supernode_begin()[s], self.sym.supernode_end()[s]);
        let rows = self.width(s) + self.sym.supernode(s).pattern().len();
        for j in begin..end {
            let col = &mut ls[(j - begin) * rows..][..rows];
            for (&i, &v) in self.lower.row_idx_of_col_raw(j).iter().zip(self.lower.val_of_col(j)) {
                if i >= j {
                    col[self.position(s, i, local)] += v;
                }
            }
        }
    }

    /// The column cutting supernode `s` in two halves of about equal update work (the
    /// products of its descendants' columns, and its own entries).
    fn half(&self, s: usize) -> usize {
        let sym = self.sym;
        let (begin, end) = (sym.supernode_begin()[s], sym.supernode_end()[s]);
        let (w, rows) = (end - begin, self.width(s) + sym.supernode(s).pattern().len());
        let mut work: Vec<usize> = (0..w).map(|j| rows - j).collect();
        for &d in self.updates.of(s) {
            let pattern = sym.supernode(d).pattern();
            let below = &pattern[pattern.partition_point(|&r| r < begin)..];
            let k = below.partition_point(|&r| r < end);
            for (j, &r) in below[..k].iter().enumerate() {
                work[r - begin] += (below.len() - j) * self.width(d);
            }
        }
        let total: usize = work.iter().sum();
        let mut acc = 0;
        for (j, v) in work.iter().enumerate() {
            if 2 * (acc + v) > total {
                return j;
            }
            acc += v;
        }
        w
    }

    /// Subtract from `ls`, columns `cols` of supernode `s` (`ls` holds just those), the updates
    /// of its descendants (whose values are in `done`) in order: `ls -= L_d,rows L_d,colsᵀ` on the rows and columns
    /// of `s` that `d` reaches. The products are formed [`PRODUCT_COLUMNS`] columns at a time.
    #[allow(clippy::too_many_arguments)]
    fn update(&self, s: usize, ls: &mut [f64], cols: Range<usize>, done: &[&mut [f64]], local: &[usize], product: &mut Vec<f64>) {
        let sym = self.sym;
        let (s_begin, s_end) = (sym.supernode_begin()[s], sym.supernode_end()[s]);
        let s_rows = self.width(s) + sym.supernode(s).pattern().len();
        let (first_col, last_col) = (s_begin + cols.start, s_begin + cols.end);
        let mut rows = Vec::new();
        for &d in self.updates.of(s) {
            let pattern = sym.supernode(d).pattern();
            let dw = self.width(d);
            let ld = MatRef::from_column_major_slice(done[d], dw + pattern.len(), dw);
            // d's rows from s's first column on; of those, the ones in `cols` are `j0..j1`.
            let first = pattern.partition_point(|&r| r < s_begin);
            let below = &pattern[first..];
            let (j0, j1) = (below.partition_point(|&r| r < first_col), below.partition_point(|&r| r < last_col.min(s_end)));
            if j0 == j1 {
                continue;
            }
            let m = below.len();
            let ld = ld.subrows(dw + first, m);
            rows.clear();
            rows.extend(below.iter().map(|&r| self.position(s, r, local)));
            for c0 in (j0..j1).step_by(PRODUCT_COLUMNS) {
                let c1 = (c0 + PRODUCT_COLUMNS).min(j1);
                // Rows c0.. of the product of columns c0..c1: a lower triangle, then a rectangle.
                let (h, k) = (m - c0, c1 - c0);
                product.clear();
                product.resize(h * k, 0.0);
                let mut p = MatMut::from_column_major_slice_mut(product, h, k);
                let (p_tri, p_rect) = p.rb_mut().split_at_row_mut(k);
                let right = ld.subrows(c0, k).transpose();
                faer::linalg::matmul::triangular::matmul(
                    p_tri,
                    BlockStructure::TriangularLower,
                    Accum::Replace,
                    ld.subrows(c0, k),
                    BlockStructure::Rectangular,
                    right,
                    BlockStructure::Rectangular,
                    1.0,
                    Par::Seq,
                );
                faer::linalg::matmul::matmul(p_rect, Accum::Replace, ld.subrows(c1, m - c1), right, 1.0, Par::Seq);
                for j in 0..k {
                    let col = &mut ls[(below[c0 + j] - first_col) * s_rows..][..s_rows];
                    let pj = &product[j * h..(j + 1) * h];
                    for i in j..h {
                        col[rows[c0 + i]] -= pj[i];
                    }
                }
            }
        }
    }

    /// Cholesky of `s`'s diagonal block, and the rows under it: `L_below = A_below L_diag⁻ᵀ`.
    fn finish(&self, s: usize, ls: &mut [f64], scratch: &mut Scratch, par: Par) -> Result<(), NotPositiveDefinite> {
        let w = self.width(s);
        let rows = w + self.sym.supernode(s).pattern().len();
        let block = MatMut::from_column_major_slice_mut(ls, rows, w);
        let (mut diag, mut below) = block.split_at_row_mut(w);
        cholesky_in_place(diag.rb_mut(), LltRegularization::default(), par, MemStack::new(&mut scratch.dense), Default::default())
            .map_err(|_| NotPositiveDefinite)?;
        faer::linalg::triangular_solve::solve_lower_triangular_in_place(diag.rb(), below.rb_mut().transpose_mut(), par);
        Ok(())
    }
}
