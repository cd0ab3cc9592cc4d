//! Fill-reducing orderings of the node graph: geometric nested dissection, minimum degree, their
//! predicted cost, and postordering.
//!
//! The spacetime normal matrix has one block of unknowns per mesh node (its free time slots,
//! contiguous in the unknown order), and two nodes are coupled when they are within two rings
//! of each other (the pattern of `L M⁻¹ L`). Ordering that node graph (2.6k nodes for a 25k x
//! 25k matrix) is much cheaper than ordering the matrix, and every node's block stays together,
//! so the factorization sees dense `slots x slots` blocks and forms large supernodes.
//!
//! Nested dissection: split the nodes by a plane through their rest positions, turn the edge cut
//! into the smallest vertex separator of that bipartition (a minimum vertex cover of the cut
//! edges, by König's theorem from a maximum matching), order both halves recursively and the
//! separator last. Several planes are tried at every level (the coordinate axes and the
//! principal axes of the part, each at a few balanced positions) and the separator that is
//! smallest for its balance wins. Everything is deterministic: ties break by candidate order and
//! node index.
//!
//! [`predicted_cost`] compares orders in milliseconds from a symbolic factorization of the node
//! graph with node weights (slots per node); [`postorder`] renumbers an order along its
//! elimination tree so that subtrees are contiguous; [`expand`] turns a node order into an
//! order of the unknowns, the [`FillOrdering`] the Cholesky factorization is given.

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::perm::PermRef;
use faer::sparse::linalg::amd;
use faer::sparse::linalg::cholesky::{factorize_symbolic_cholesky, CholeskySymbolicParams, SymbolicCholeskyRaw, SymmetricOrdering};
use faer::sparse::SymbolicSparseColMat;
use faer::Side;

use super::mat3::Mat3;
use super::svd3::svd3;
use crate::algorithms::geometry::Point;

/// A fill-reducing ordering of a symmetric matrix's rows and columns, as the Cholesky
/// factorization takes it.
#[derive(Debug, Clone)]
pub enum FillOrdering {
    /// faer's approximate minimum degree.
    Amd,
    /// `perm[i]` = original index of the i-th pivot.
    Custom(Vec<usize>),
}

/// An undirected graph without self loops in compressed adjacency form.
#[derive(Debug, Clone, PartialEq)]
pub struct Graph {
    /// Node `v`'s neighbours are `adj[xadj[v]..xadj[v + 1]]` (`node_count() + 1` offsets).
    pub xadj: Vec<usize>,
    /// Every node's neighbour list, concatenated (each edge is listed at both ends).
    pub adj: Vec<u32>,
}

impl Graph {
    /// Number of nodes.
    pub fn node_count(&self) -> usize {
        self.xadj.len() - 1
    }

    /// The neighbours of node `v`.
    pub fn neighbours(&self, v: usize) -> &[u32] {
        &self.adj[self.xadj[v]..self.xadj[v + 1]]
    }

    /// The quotient graph of a symmetric matrix pattern (lower triangle, compressed columns:
    /// `col_ptr`, `row_idx`) whose unknown `i` belongs to block `block_of[i]`: blocks are
    /// adjacent when any of their unknowns are coupled.
    pub(crate) fn of_blocks(col_ptr: &[usize], row_idx: &[usize], block_of: &[u32], blocks: usize) -> Graph {
        // Blocks below each block's columns, found once each with a marker array (`mark[a] == b`
        // once a was found under block b).
        let mut neighbours: Vec<Vec<u32>> = vec![Vec::new(); blocks];
        let mut mark = vec![u32::MAX; blocks];
        let mut j = 0;
        let n = col_ptr.len() - 1;
        while j < n {
            let b = block_of[j] as usize;
            let mut end = j;
            while end < n && block_of[end] as usize == b {
                end += 1;
            }
            for col in j..end {
                for &i in &row_idx[col_ptr[col]..col_ptr[col + 1]] {
                    let a = block_of[i] as usize;
                    if mark[a] != b as u32 {
                        mark[a] = b as u32;
                        neighbours[b].push(a as u32);
                    }
                }
            }
            j = end;
        }
        // Symmetrize: the lower triangle gives (a, b) with a >= b once.
        let mut full: Vec<Vec<u32>> = vec![Vec::new(); blocks];
        for (b, list) in neighbours.iter().enumerate() {
            for &a in list {
                if a as usize != b {
                    full[b].push(a);
                    full[a as usize].push(b as u32);
                }
            }
        }
        let mut xadj = Vec::with_capacity(blocks + 1);
        xadj.push(0);
        let mut adj = Vec::new();
        for mut list in full {
            list.sort_unstable();
            list.dedup();
            adj.extend(list);
            xadj.push(adj.len());
        }
        Graph { xadj, adj }
    }
}

/// Parts at most this large are not split further (their nodes are nearly all coupled).
const LEAF: usize = 48;

/// Split positions tried along every direction, as fractions of the part.
const FRACTIONS: [f64; 5] = [0.5, 0.44, 0.56, 0.38, 0.62];

struct Work<'a> {
    graph: &'a Graph,
    coords: &'a [Point],
    /// `member[v] == stamp` when v is in the part being split.
    member: Vec<u32>,
    stamp: u32,
    /// 0 = left, 1 = right, for members.
    side: Vec<u8>,
    /// Local index of a boundary node in the bipartite graph, per side.
    local: Vec<u32>,
    order: Vec<u32>,
}

/// A vertex separator of a part.
struct Split {
    /// Its nodes, in increasing order.
    separator: Vec<u32>,
    /// Its size, penalized by imbalance (lower is better).
    score: f64,
    /// Per node of the part (in the part's order): 0 or 1 for the two sides, 2 in the separator.
    side: Vec<u8>,
}

/// Nested dissection order of `graph` (`order[k]` = the node eliminated k-th), from node
/// coordinates `coords`.
pub(crate) fn nested_dissection(graph: &Graph, coords: &[Point]) -> Vec<u32> {
    let n = graph.node_count();
    assert_eq!(coords.len(), n, "one coordinate per node");
    let mut work =
        Work { graph, coords, member: vec![u32::MAX; n], stamp: 0, side: vec![0; n], local: vec![u32::MAX; n], order: Vec::with_capacity(n) };
    let nodes: Vec<u32> = (0..n as u32).collect();
    dissect(&mut work, nodes);
    debug_assert_eq!(work.order.len(), n);
    work.order
}

fn dissect(work: &mut Work, nodes: Vec<u32>) {
    if nodes.len() <= LEAF {
        work.order.extend(nodes);
        return;
    }
    let Some(split) = best_split(work, &nodes) else {
        work.order.extend(nodes);
        return;
    };
    // `split.side` is aligned with `nodes`; separator nodes are marked 2.
    let (mut left, mut right) = (Vec::new(), Vec::new());
    for (&v, &s) in nodes.iter().zip(&split.side) {
        match s {
            0 => left.push(v),
            1 => right.push(v),
            _ => {}
        }
    }
    drop(nodes);
    dissect(work, left);
    dissect(work, right);
    work.order.extend(split.separator);
}

/// Directions to split along: the coordinate axes and the principal axes of the part.
fn directions(coords: &[Point], nodes: &[u32]) -> Vec<[f64; 3]> {
    let count = nodes.len() as f64;
    let mut mean = [0.0; 3];
    for &v in nodes {
        for d in 0..3 {
            mean[d] += coords[v as usize][d] / count;
        }
    }
    let mut cov: Mat3 = [[0.0; 3]; 3];
    for &v in nodes {
        let p = coords[v as usize];
        for i in 0..3 {
            for j in 0..3 {
                cov[i][j] += (p[i] - mean[i]) * (p[j] - mean[j]);
            }
        }
    }
    let axes = svd3(&cov).v;
    let mut dirs = vec![[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    for j in 0..3 {
        dirs.push([axes[0][j], axes[1][j], axes[2][j]]);
    }
    dirs
}

fn best_split(work: &mut Work, nodes: &[u32]) -> Option<Split> {
    work.stamp += 1;
    let stamp = work.stamp;
    for &v in nodes {
        work.member[v as usize] = stamp;
    }
    let mut best: Option<Split> = None;
    let mut keyed: Vec<(f64, u32)> = Vec::with_capacity(nodes.len());
    for dir in directions(work.coords, nodes) {
        keyed.clear();
        keyed.extend(nodes.iter().map(|&v| {
            let p = work.coords[v as usize];
            (p[0] * dir[0] + p[1] * dir[1] + p[2] * dir[2], v)
        }));
        keyed.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        for frac in FRACTIONS {
            let cut = ((nodes.len() as f64 * frac).round() as usize).clamp(1, nodes.len() - 1);
            for (k, &(_, v)) in keyed.iter().enumerate() {
                work.side[v as usize] = (k >= cut) as u8;
            }
            let separator = vertex_cover(work, nodes, stamp);
            // Sizes left on each side once the separator (side 2 from now on) is removed.
            let mut sizes = [0usize; 2];
            for &v in nodes {
                sizes[work.side[v as usize] as usize] += 1;
            }
            for &v in &separator {
                sizes[work.side[v as usize] as usize] -= 1;
                work.side[v as usize] = 2;
            }
            if sizes[0] == 0 || sizes[1] == 0 {
                continue;
            }
            let m = (sizes[0] + sizes[1]) as f64;
            // The separator size, penalized by imbalance (equal to it at a perfect split).
            let score = separator.len() as f64 * m * m / (4.0 * sizes[0] as f64 * sizes[1] as f64);
            if best.as_ref().is_none_or(|b| score < b.score) {
                best = Some(Split { separator, score, side: nodes.iter().map(|&v| work.side[v as usize]).collect() });
            }
        }
    }
    best
}

/// The minimum vertex cover of the edges between the two sides of the part (`work.side`), from a
/// maximum bipartite matching (König). Returned in increasing node order.
fn vertex_cover(work: &mut Work, nodes: &[u32], stamp: u32) -> Vec<u32> {
    let g = work.graph;
    // Boundary nodes of each side, with local indices.
    let (mut left, mut right): (Vec<u32>, Vec<u32>) = (Vec::new(), Vec::new());
    let mut edges: Vec<(u32, u32)> = Vec::new();
    for &v in nodes {
        if work.side[v as usize] != 0 {
            continue;
        }
        for &u in g.neighbours(v as usize) {
            if work.member[u as usize] == stamp && work.side[u as usize] == 1 {
                if work.local[v as usize] == u32::MAX {
                    work.local[v as usize] = left.len() as u32;
                    left.push(v);
                }
                if work.local[u as usize] == u32::MAX {
                    work.local[u as usize] = right.len() as u32;
                    right.push(u);
                }
                edges.push((work.local[v as usize], work.local[u as usize]));
            }
        }
    }
    for &v in left.iter().chain(&right) {
        work.local[v as usize] = u32::MAX;
    }
    if edges.is_empty() {
        return Vec::new();
    }
    // Adjacency of left boundary nodes (edges are grouped by left node already).
    let mut ptr = vec![0usize; left.len() + 1];
    for &(x, _) in &edges {
        ptr[x as usize + 1] += 1;
    }
    for i in 0..left.len() {
        ptr[i + 1] += ptr[i];
    }
    let ys: Vec<u32> = edges.iter().map(|e| e.1).collect();
    let (matched_x, matched_y) = maximum_matching(&ptr, &ys, left.len(), right.len());
    // König: Z = nodes reachable from unmatched left nodes by alternating paths; the cover is
    // (left \ Z) ∪ (right ∩ Z).
    let (mut zx, mut zy) = (vec![false; left.len()], vec![false; right.len()]);
    let mut stack: Vec<u32> = (0..left.len() as u32).filter(|&x| matched_x[x as usize] == u32::MAX).collect();
    for &x in &stack {
        zx[x as usize] = true;
    }
    while let Some(x) = stack.pop() {
        for &y in &ys[ptr[x as usize]..ptr[x as usize + 1]] {
            if !zy[y as usize] {
                zy[y as usize] = true;
                let x2 = matched_y[y as usize];
                if x2 != u32::MAX && !zx[x2 as usize] {
                    zx[x2 as usize] = true;
                    stack.push(x2);
                }
            }
        }
    }
    let mut cover: Vec<u32> = left.iter().zip(&zx).filter(|(_, &z)| !z).map(|(&v, _)| v).collect();
    cover.extend(right.iter().zip(&zy).filter(|(_, &z)| z).map(|(&v, _)| v));
    cover.sort_unstable();
    cover
}

/// Maximum matching of a bipartite graph (left nodes with adjacency `ptr`/`ys`) by augmenting
/// paths from a greedy start. Returns the partner of every left and right node (`u32::MAX` if
/// unmatched).
fn maximum_matching(ptr: &[usize], ys: &[u32], nx: usize, ny: usize) -> (Vec<u32>, Vec<u32>) {
    let (mut mx, mut my) = (vec![u32::MAX; nx], vec![u32::MAX; ny]);
    for x in 0..nx {
        if let Some(&y) = ys[ptr[x]..ptr[x + 1]].iter().find(|&&y| my[y as usize] == u32::MAX) {
            mx[x] = y;
            my[y as usize] = x as u32;
        }
    }
    let mut visited = vec![0u32; ny];
    let mut round = 0u32;
    // Iterative DFS: (left node, next edge position).
    let mut stack: Vec<(u32, usize)> = Vec::new();
    for root in 0..nx {
        if mx[root] != u32::MAX {
            continue;
        }
        round += 1;
        stack.clear();
        stack.push((root as u32, ptr[root]));
        // Path of right nodes chosen at each depth.
        let mut path: Vec<u32> = Vec::new();
        let mut found = false;
        while let Some(top) = stack.last_mut() {
            let (x, pos) = (top.0 as usize, top.1);
            if pos == ptr[x + 1] {
                stack.pop();
                path.pop();
                continue;
            }
            top.1 += 1;
            let y = ys[pos];
            if visited[y as usize] == round {
                continue;
            }
            visited[y as usize] = round;
            path.push(y);
            let partner = my[y as usize];
            if partner == u32::MAX {
                found = true;
                break;
            }
            stack.push((partner, ptr[partner as usize]));
        }
        if found {
            // Flip the path: stack[k].0 is matched to path[k].
            for (k, &(x, _)) in stack.iter().enumerate() {
                let y = path[k];
                mx[x as usize] = y;
                my[y as usize] = x;
            }
        }
    }
    (mx, my)
}

/// Approximate minimum degree order of `graph` (faer's AMD on the node graph).
pub(crate) fn minimum_degree(graph: &Graph) -> Vec<u32> {
    let n = graph.node_count();
    let pattern = lower_pattern(graph, None);
    let (mut perm, mut inv) = (vec![0usize; n], vec![0usize; n]);
    let mut mem = MemBuffer::new(amd::order_scratch::<usize>(n, pattern.compute_nnz()));
    amd::order(&mut perm, &mut inv, pattern.as_ref(), amd::Control::default(), MemStack::new(&mut mem)).expect("AMD of a valid pattern");
    perm.into_iter().map(|v| v as u32).collect()
}

/// Lower triangle (with the diagonal) of the adjacency pattern, optionally permuted: with
/// `order`, row/column k is node `order[k]`.
fn lower_pattern(graph: &Graph, order: Option<&[u32]>) -> SymbolicSparseColMat<usize> {
    let n = graph.node_count();
    let mut position = vec![0usize; n];
    for k in 0..n {
        position[order.map_or(k, |o| o[k] as usize)] = k;
    }
    let mut col_ptr = Vec::with_capacity(n + 1);
    col_ptr.push(0);
    let mut rows = Vec::with_capacity(graph.adj.len() / 2 + n);
    let mut column = Vec::new();
    for k in 0..n {
        let v = order.map_or(k, |o| o[k] as usize);
        column.clear();
        column.push(k);
        column.extend(graph.neighbours(v).iter().map(|&u| position[u as usize]).filter(|&j| j > k));
        column.sort_unstable();
        rows.extend_from_slice(&column);
        col_ptr.push(rows.len());
    }
    SymbolicSparseColMat::new_checked(n, n, col_ptr, None, rows)
}

/// The cost of factorizing a matrix whose node `v` carries `weights[v]` unknowns (kept together)
/// in node order `order`: the floating-point operations `Σ_j c_j²` (multiplies and adds of the
/// column updates; `n³/3` for a dense matrix) and the stored entries `Σ_j c_j` over the
/// factor's columns `j` with `c_j` entries each, from the symbolic factorization of the node
/// graph. Two orders of one matrix compare in milliseconds, without touching the matrix.
pub fn predicted_cost(graph: &Graph, order: &[u32], weights: &[usize]) -> Cost {
    let n = graph.node_count();
    let pattern = lower_pattern(graph, Some(order));
    // The pattern is already in elimination order; faer's `Identity` ordering would read it as
    // an upper triangle, so pass the identity as a custom permutation.
    let identity: Vec<usize> = (0..n).collect();
    let symbolic = factorize_symbolic_cholesky(
        pattern.as_ref(),
        Side::Lower,
        SymmetricOrdering::Custom(PermRef::new_checked(&identity, &identity, n)),
        CholeskySymbolicParams::default(),
    )
    .expect("symbolic factorization of a valid pattern");
    let w = |k: usize| weights[order[k] as usize] as f64;
    // below[k]: unknowns in rows after node k in its factor column.
    let mut below = vec![0.0; n];
    match symbolic.raw() {
        SymbolicCholeskyRaw::Simplicial(s) => {
            let (cp, ri) = (s.col_ptr(), s.row_idx());
            for k in 0..n {
                below[k] = ri[cp[k]..cp[k + 1]].iter().filter(|&&i| i > k).map(|&i| w(i)).sum();
            }
        }
        SymbolicCholeskyRaw::Supernodal(s) => {
            for sn in 0..s.n_supernodes() {
                let (begin, end) = (s.supernode_begin()[sn], s.supernode_end()[sn]);
                let mut rows: f64 = s.supernode(sn).pattern().iter().map(|&i| w(i)).sum();
                for k in (begin..end).rev() {
                    below[k] = rows;
                    rows += w(k);
                }
            }
        }
    }
    let mut cost = Cost { flops: 0.0, entries: 0.0 };
    for k in 0..n {
        for j in 0..weights[order[k] as usize] {
            let c = (w(k) - j as f64) + below[k];
            cost.flops += c * c;
            cost.entries += c;
        }
    }
    cost
}

/// Predicted factorization cost (see [`predicted_cost`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cost {
    /// Floating-point operations of the numeric factorization, `Σ_j c_j²`.
    pub flops: f64,
    /// Stored entries of the factor, `Σ_j c_j`.
    pub entries: f64,
}

/// The same elimination in postorder of its elimination tree: every subtree becomes a
/// contiguous range ending at its root, which lets a solve deal whole subtrees to threads. The
/// fill is unchanged (a postorder is an equivalent order); children are visited in their order
/// in `order`, so an order that already is a postorder comes back unchanged.
pub fn postorder(graph: &Graph, order: &[u32]) -> Vec<u32> {
    let n = graph.node_count();
    let mut position = vec![0u32; n];
    for (k, &v) in order.iter().enumerate() {
        position[v as usize] = k as u32;
    }
    // Elimination tree (Liu): for each column k, the roots of the subtrees holding its earlier
    // neighbours hang below k; `ancestor` compresses paths.
    let none = u32::MAX;
    let (mut parent, mut ancestor) = (vec![none; n], vec![none; n]);
    for k in 0..n {
        for &u in graph.neighbours(order[k] as usize) {
            let mut i = position[u as usize];
            if i as usize >= k {
                continue;
            }
            while ancestor[i as usize] != none && ancestor[i as usize] != k as u32 {
                let next = ancestor[i as usize];
                ancestor[i as usize] = k as u32;
                i = next;
            }
            if ancestor[i as usize] == none {
                ancestor[i as usize] = k as u32;
                parent[i as usize] = k as u32;
            }
        }
    }
    let mut children: Vec<Vec<u32>> = vec![Vec::new(); n];
    let mut roots = Vec::new();
    for k in 0..n {
        match parent[k] {
            p if p == none => roots.push(k as u32),
            p => children[p as usize].push(k as u32),
        }
    }
    let mut out = Vec::with_capacity(n);
    let mut stack: Vec<(u32, usize)> = Vec::new();
    for &r in &roots {
        stack.push((r, 0));
        while let Some(&mut (k, ref mut next)) = stack.last_mut() {
            if let Some(&c) = children[k as usize].get(*next) {
                *next += 1;
                stack.push((c, 0));
            } else {
                out.push(order[k as usize]);
                stack.pop();
            }
        }
    }
    out
}

/// Expand a node order to unknowns: node `v` owns unknowns `block_start[v]..block_start[v + 1]`,
/// which stay together in their original order. Returns `perm[k]` = the unknown eliminated
/// k-th.
pub fn expand(order: &[u32], block_start: &[usize]) -> Vec<usize> {
    let mut perm = Vec::with_capacity(*block_start.last().unwrap_or(&0));
    for &v in order {
        perm.extend(block_start[v as usize]..block_start[v as usize + 1]);
    }
    perm
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A k x k x k grid graph with 26-neighbour coupling (like a 2-ring).
    fn grid(k: usize) -> (Graph, Vec<Point>) {
        let id = |i: usize, j: usize, l: usize| i * k * k + j * k + l;
        let mut coords = Vec::new();
        let mut lists = vec![Vec::new(); k * k * k];
        for i in 0..k {
            for j in 0..k {
                for l in 0..k {
                    coords.push([i as f64, j as f64, l as f64]);
                    for di in -1i64..=1 {
                        for dj in -1i64..=1 {
                            for dl in -1i64..=1 {
                                let (a, b, c) = (i as i64 + di, j as i64 + dj, l as i64 + dl);
                                if (di, dj, dl) == (0, 0, 0) || a < 0 || b < 0 || c < 0 || a >= k as i64 || b >= k as i64 || c >= k as i64 {
                                    continue;
                                }
                                lists[id(i, j, l)].push(id(a as usize, b as usize, c as usize) as u32);
                            }
                        }
                    }
                }
            }
        }
        let mut xadj = vec![0];
        let mut adj = Vec::new();
        for l in lists {
            adj.extend(l);
            xadj.push(adj.len());
        }
        (Graph { xadj, adj }, coords)
    }

    #[test]
    fn order_is_a_permutation_and_separators_separate() {
        let (g, coords) = grid(9);
        let order = nested_dissection(&g, &coords);
        let mut seen = vec![false; g.node_count()];
        for &v in &order {
            assert!(!seen[v as usize]);
            seen[v as usize] = true;
        }
        assert!(seen.iter().all(|&s| s));
        // The last plane of a 9³ grid is a 9x9 separator at the middle.
        let last = &order[order.len() - 81..];
        let plane = (0..3).find(|&d| last.iter().all(|&v| coords[v as usize][d] == 4.0));
        assert!(plane.is_some(), "the top separator is the middle plane");
        // Deterministic.
        assert_eq!(order, nested_dissection(&g, &coords));
    }

    #[test]
    fn cost_of_a_clique_is_that_of_a_dense_factorization() {
        // K5 with weights 1: columns of 5, 4, ..., 1 entries.
        let lists: Vec<Vec<u32>> = (0..5u32).map(|v| (0..5u32).filter(|&u| u != v).collect()).collect();
        let mut xadj = vec![0];
        let mut adj = Vec::new();
        for l in lists {
            adj.extend(l);
            xadj.push(adj.len());
        }
        let g = Graph { xadj, adj };
        let c = predicted_cost(&g, &[0, 1, 2, 3, 4], &[1; 5]);
        assert_eq!((c.flops, c.entries), (55.0, 15.0));
        // One node of 3 unknowns and two of 1: the same dense 5x5 factor.
        let g2 = Graph { xadj: vec![0, 2, 4, 6], adj: vec![1, 2, 0, 2, 0, 1] };
        let c2 = predicted_cost(&g2, &[2, 0, 1], &[3, 1, 1]);
        assert_eq!((c2.flops, c2.entries), (55.0, 15.0));
    }

    #[test]
    fn postorder_keeps_the_fill_and_is_idempotent() {
        let (g, coords) = grid(7);
        let weights = vec![2; g.node_count()];
        for order in [nested_dissection(&g, &coords), minimum_degree(&g), (0..g.node_count() as u32).collect()] {
            let post = postorder(&g, &order);
            let mut sorted = post.clone();
            sorted.sort_unstable();
            assert_eq!(sorted, (0..g.node_count() as u32).collect::<Vec<_>>());
            assert_eq!(predicted_cost(&g, &post, &weights), predicted_cost(&g, &order, &weights));
            assert_eq!(postorder(&g, &post), post);
        }
    }

    #[test]
    fn matching_cover_is_minimum_on_a_small_case() {
        // Left {0,1,2}, right {0,1}: edges 0-0, 1-0, 2-0, 2-1: max matching 2.
        let ptr = [0, 1, 2, 4];
        let ys = [0, 0, 0, 1];
        let (mx, my) = maximum_matching(&ptr, &ys, 3, 2);
        assert_eq!(mx.iter().filter(|&&y| y != u32::MAX).count(), 2);
        assert_eq!(my.iter().filter(|&&x| x != u32::MAX).count(), 2);
    }

    #[test]
    fn block_graph_and_expansion() {
        // 3 blocks of sizes 2, 1, 2; unknowns 0,1 | 2 | 3,4. Lower pattern: diagonal, (2,0),
        // (4,1): blocks 0-1 and 0-2 coupled, 1-2 not.
        let col_ptr = [0, 2, 4, 5, 6, 7];
        let row_idx = [0, 2, 1, 4, 2, 3, 4];
        let block_of = [0, 0, 1, 2, 2];
        let g = Graph::of_blocks(&col_ptr, &row_idx, &block_of, 3);
        assert_eq!(g.neighbours(0), &[1, 2]);
        assert_eq!(g.neighbours(1), &[0]);
        assert_eq!(g.neighbours(2), &[0]);
        assert_eq!(expand(&[2, 0, 1], &[0, 2, 3, 5]), vec![3, 4, 0, 1, 2]);
    }
}
