//! How the supernodal sweeps share the elimination tree between two threads.
//!
//! Below its top chain (the supernodes with one child, from the root) the tree branches into
//! independent subtrees; they are dealt to two groups whose work balances best. The two groups
//! are swept concurrently and the top chain after (forward) or before (backward) them (see
//! [`super::sweeps`]), or factored concurrently and the top chain after (see [`super::numeric`]).

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
    /// to the two groups so that their `own_work` (per supernode: stored entries for the
    /// sweeps, flops for the factorization) balances best.
    pub(super) fn new(sym: &SymbolicSupernodalCholesky<usize>, own_work: &[usize]) -> Option<SplitPlan> {
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
        // Work and first descendant of every subtree; postorder means the subtree of s is
        // exactly first[s]..=s.
        let mut work = own_work.to_vec();
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
        // `below` are consecutive subtrees in postorder; split them where the work balances.
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

/// [`GroupPlan::owner`] of the supernodes factored after the two groups.
pub(super) const TOP: u8 = 2;

/// How the numeric factorization shares the elimination tree between two threads: whole
/// subtrees go to group 0 or group 1 (factored concurrently), the supernodes above them are
/// the top (factored after, both threads inside each supernode). Unlike [`SplitPlan`] the
/// groups need not be contiguous: the split may reach below an unbalanced branching.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct GroupPlan {
    /// 0 or 1 for a group, [`TOP`] for the top; every supernode's descendants have its owner
    /// (or it is a top one).
    pub(super) owner: Vec<u8>,
}

/// A top supernode's work over the same work in a group: the top's supernodes are large and
/// use both threads (measured 1.5-1.9x on their updates, about 1.6x on the dense blocks).
const TOP_SPEEDUP: f64 = 1.6;

/// A candidate split: its predicted time, each hanging subtree with its group, which supernodes
/// are in the top.
type Candidate = (f64, Vec<(usize, u8)>, Vec<bool>);

impl GroupPlan {
    /// Start from the top chain (from the roots down to the first branching); while it
    /// predicts a shorter time, move the heaviest hanging subtree's root into the top. The
    /// hanging subtrees are dealt heaviest first to the lighter group.
    pub(super) fn new(sym: &SymbolicSupernodalCholesky<usize>, own_work: &[usize]) -> Option<GroupPlan> {
        let ns = sym.n_supernodes();
        if ns < 2 {
            return None;
        }
        let (begin, end) = (sym.supernode_begin(), sym.supernode_end());
        let mut owner_of_row = vec![0usize; sym.nrows()];
        for s in 0..ns {
            owner_of_row[begin[s]..end[s]].fill(s);
        }
        let parent: Vec<Option<usize>> = (0..ns).map(|s| sym.supernode(s).pattern().first().map(|&row| owner_of_row[row])).collect();
        let mut work = own_work.to_vec();
        let mut children = vec![Vec::new(); ns];
        let mut frontier = Vec::new();
        for s in 0..ns {
            match parent[s] {
                Some(p) if p <= s => return None,
                Some(p) => {
                    work[p] += work[s];
                    children[p].push(s);
                }
                None => frontier.push(s),
            }
        }
        let mut top = vec![false; ns];
        let mut top_work = 0usize;
        let expand = |frontier: &mut Vec<usize>, top: &mut Vec<bool>, top_work: &mut usize, h: usize| {
            frontier.retain(|&s| s != h);
            frontier.extend(&children[h]);
            top[h] = true;
            *top_work += own_work[h];
        };
        while frontier.len() == 1 && !children[frontier[0]].is_empty() {
            let h = frontier[0];
            expand(&mut frontier, &mut top, &mut top_work, h);
        }
        let deal = |frontier: &[usize]| {
            let mut sorted = frontier.to_vec();
            sorted.sort_by_key(|&s| (std::cmp::Reverse(work[s]), s));
            let mut load = [0usize; 2];
            let mut group = Vec::with_capacity(sorted.len());
            for s in sorted {
                let g = (load[1] < load[0]) as usize;
                load[g] += work[s];
                group.push((s, g as u8));
            }
            (load, group)
        };
        let mut best: Option<Candidate> = None;
        for _ in 0..64 {
            let (load, group) = deal(&frontier);
            let predicted = load[0].max(load[1]) as f64 + top_work as f64 / TOP_SPEEDUP;
            if load[0].min(load[1]) > 0 && best.as_ref().is_none_or(|b| predicted < b.0) {
                best = Some((predicted, group, top.clone()));
            }
            let Some(&h) = frontier.iter().filter(|&&s| !children[s].is_empty()).max_by_key(|&&s| (work[s], std::cmp::Reverse(s))) else { break };
            expand(&mut frontier, &mut top, &mut top_work, h);
        }
        let (_, group, top) = best?;
        let mut owner = vec![TOP; ns];
        // A hanging subtree's supernodes are its root's descendants: mark them from the roots
        // down (parents come after children in postorder, so walk backwards).
        let mut root_group = vec![None; ns];
        for (s, g) in group {
            root_group[s] = Some(g);
        }
        for s in (0..ns).rev() {
            if top[s] {
                continue;
            }
            owner[s] = match root_group[s] {
                Some(g) => g,
                None => owner[parent[s].expect("a supernode below the top has a parent")],
            };
        }
        Some(GroupPlan { owner })
    }
}
