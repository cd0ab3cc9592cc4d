//! How the supernodal sweeps share the elimination tree between two threads.
//!
//! Below its top chain (the supernodes with one child, from the root) the tree branches into
//! independent subtrees; they are dealt to two groups whose factor entries balance best. The
//! two groups are swept concurrently and the top chain after (forward) or before (backward)
//! them; see [`super::sweeps`].

use faer::sparse::linalg::cholesky::supernodal::SymbolicSupernodalCholesky;

/// Two groups of whole subtrees of the supernodal elimination tree, and the supernodes above
/// them (the top chain). Supernodes are numbered in postorder, so each group and the top are
/// contiguous ranges of supernodes and of rows: group A, then group B, then the top.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct SplitPlan {
    /// Supernode ranges `a = 0..b_first`, `b = b_first..top_first`, `top = top_first..`.
    pub(super) b_first: usize,
    pub(super) top_first: usize,
    /// First rows of group B and of the top.
    pub(super) b_row: usize,
    pub(super) top_row: usize,
}

impl SplitPlan {
    /// The split, if the tree allows a useful one: the top chain (supernodes with one child,
    /// from the root) ends at a supernode with at least two children, whose subtrees are dealt
    /// to the two groups so that their entries balance best.
    pub(super) fn new(sym: &SymbolicSupernodalCholesky<usize>) -> Option<SplitPlan> {
        let ns = sym.n_supernodes();
        let n = sym.nrows();
        if ns < 2 {
            return None;
        }
        let (begin, end) = (sym.supernode_begin(), sym.supernode_end());
        let mut owner = vec![0usize; n];
        for s in 0..ns {
            owner[begin[s]..end[s]].fill(s);
        }
        let parent: Vec<Option<usize>> = (0..ns).map(|s| sym.supernode(s).pattern().first().map(|&row| owner[row])).collect();
        let cp = sym.col_ptr_for_val();
        // Entries and first descendant of every subtree; postorder means the subtree of s is
        // exactly first[s]..=s.
        let mut work: Vec<usize> = (0..ns).map(|s| cp[s + 1] - cp[s]).collect();
        let mut first: Vec<usize> = (0..ns).collect();
        let mut size = vec![1usize; ns];
        for s in 0..ns {
            if let Some(p) = parent[s] {
                if p <= s {
                    return None;
                }
                work[p] += work[s];
                first[p] = first[p].min(first[s]);
                size[p] += size[s];
            }
        }
        if (0..ns).any(|s| s + 1 - first[s] != size[s]) {
            return None;
        }
        let mut children = vec![Vec::new(); ns];
        let mut roots = Vec::new();
        for s in 0..ns {
            match parent[s] {
                Some(p) => children[p].push(s),
                None => roots.push(s),
            }
        }
        // Walk down the top chain.
        let mut below = roots;
        while below.len() == 1 {
            below = std::mem::take(&mut children[below[0]]);
        }
        if below.len() < 2 {
            return None;
        }
        // `below` are consecutive subtrees in postorder; split them where the entries balance.
        let total: usize = below.iter().map(|&c| work[c]).sum();
        let mut acc = 0;
        let mut best = (usize::MAX, 1);
        for (m, &c) in below.iter().enumerate().take(below.len() - 1) {
            acc += work[c];
            let imbalance = acc.abs_diff(total - acc);
            if imbalance < best.0 {
                best = (imbalance, m + 1);
            }
        }
        let (last_a, last) = (below[best.1 - 1], below[below.len() - 1]);
        if first[below[0]] != 0 {
            return None;
        }
        Some(SplitPlan { b_first: last_a + 1, top_first: last + 1, b_row: end[last_a], top_row: end[last] })
    }
}
