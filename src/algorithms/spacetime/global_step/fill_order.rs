//! Fill-reducing orders of the global step's unknowns: found on the node graph (every node's
//! free slots stay together), with key separators for many keys, and their predicted cost.

use faer::sparse::SparseColMat;

use crate::algorithms::geometry::Point;
use crate::algorithms::physics::ordering::{expand, minimum_degree, nested_dissection, postorder, predicted_cost, Cost, Graph};
use crate::algorithms::spacetime::unknowns::Unknowns;

use super::iterative::node_blocks;

/// The order of every key's block in the iterative step's preconditioner, and the blocks'
/// predicted cost: the node graph ordered by the better of nested dissection and minimum
/// degree, two unknowns (position, velocity) per node and key.
pub(super) fn key_block_order(orders: &NodeOrders, unknowns: &Unknowns) -> (Vec<u32>, Cost) {
    let graph = &orders.graph;
    let weights = vec![2usize; unknowns.nodes];
    let (cost_nd, cost_md) = (predicted_cost(graph, &orders.dissection, &weights), predicted_cost(graph, &orders.degree, &weights));
    let keys = (unknowns.slots.count() / 2) as f64;
    let (order, cost) = if cost_nd.flops <= cost_md.flops { (&orders.dissection, cost_nd) } else { (&orders.degree, cost_md) };
    (order.clone(), Cost { flops: keys * cost.flops, entries: keys * cost.entries })
}

/// The node graph of the normal matrix (its vertices the nodes, its edges the nodes' coupled
/// unknowns) and its two candidate orders, computed once for both the direct step's order
/// ([`fill_reducing_order_of`]) and the iterative step's key blocks (`key_block_order`):
/// the graph is the same for both, only the weights of its vertices differ.
pub struct NodeOrders {
    graph: Graph,
    dissection: Vec<u32>,
    degree: Vec<u32>,
}

impl NodeOrders {
    /// Geometric nested dissection (at the nodes' `rest` positions) and minimum degree of the
    /// node graph of `lower`.
    pub fn new(lower: &SparseColMat<usize, f64>, unknowns: &Unknowns, rest: &[Point]) -> NodeOrders {
        let graph = Graph::of_blocks(lower.symbolic().col_ptr(), lower.symbolic().row_idx(), &node_blocks(unknowns), unknowns.nodes);
        let (dissection, degree) = (nested_dissection(&graph, rest), minimum_degree(&graph));
        NodeOrders { graph, dissection, degree }
    }
}

/// A fill-reducing order of the unknowns and how it was found.
pub struct FillReducingOrder {
    /// `perm[k]` = the unknown eliminated k-th.
    pub perm: Vec<usize>,
    /// Which candidate won, for the report (e.g. `nested dissection (nodes)`).
    pub name: &'static str,
    /// Predicted cost of the factorization in this order.
    pub cost: Cost,
}

/// Order the normal matrix by its node graph: every node's free slots are contiguous unknowns
/// (node-major layout) and stay together, so ordering the 2-ring graph of the nodes (a few
/// thousand vertices) orders the matrix (tens of thousands of rows).
///
/// Two candidates, and the one with fewer predicted flops wins: geometric nested dissection
/// (best on large 3D bodies: 85 G vs 101 G flops for minimum degree on the 2.6k-node benchmark
/// body, whose matrix faer's AMD orders to 127 G) and minimum degree (better on small or thin
/// bodies: 0.37 G vs 0.98 G on DINO). Both and their predictions take about 60 ms on the
/// 2.6k-node body. With many keys a third candidate is weighed on the finer graph of (node,
/// key) blocks: the keys as the top-level separators (the middle key last, each half ordered
/// the same way, every key's nodes in the better node order), which cuts the fill that the
/// coupling of neighbouring keys causes once there are more than about ten keys
/// ([`KEY_SEPARATOR_MIN_KEYS`]). The winner is put in postorder of its elimination tree (same
/// fill), which lets the solve give whole subtrees to two threads.
///
/// The key-separator candidate is weighed only when `weigh_keys` says so for the node order's
/// cost: its graph of (node, key) blocks and two symbolic counts took 1.3 of the 10 CPU s of a
/// modal step's set-up at 20 keys on 2.7k nodes, so `GlobalStep::build` skips it when only a
/// direct step could use it.
///
/// `orders` are the node graph's orders ([`NodeOrders`]), shared with the iterative step's key blocks.
pub fn fill_reducing_order_of(
    lower: &SparseColMat<usize, f64>,
    unknowns: &Unknowns,
    orders: &NodeOrders,
    weigh_keys: impl FnOnce(&Cost) -> bool,
) -> FillReducingOrder {
    let nodes = unknowns.nodes;
    let slots = unknowns.slots.count();
    let mut block_start = vec![0usize; nodes + 1];
    for a in 0..nodes {
        block_start[a + 1] = block_start[a] + (0..slots).filter(|&s| unknowns.get(a, s).is_some()).count();
    }
    let graph = &orders.graph;
    let weights: Vec<usize> = (0..nodes).map(|a| block_start[a + 1] - block_start[a]).collect();
    let (cost_nd, cost_md) = (predicted_cost(graph, &orders.dissection, &weights), predicted_cost(graph, &orders.degree, &weights));
    let (order, name, cost) = if cost_nd.flops <= cost_md.flops {
        (&orders.dissection, "nested dissection (nodes)", cost_nd)
    } else {
        (&orders.degree, "minimum degree (nodes)", cost_md)
    };
    let keys = slots / 2;
    if keys >= KEY_SEPARATOR_MIN_KEYS && weigh_keys(&cost) {
        if let Some(by_keys) = key_separator_order(lower, unknowns, order) {
            if by_keys.cost.flops < by_keys.node_cost.flops {
                return FillReducingOrder { perm: by_keys.perm, name: "keys as separators, nodes inside", cost: by_keys.cost };
            }
        }
    }
    FillReducingOrder { perm: expand(&postorder(graph, order), &block_start), name, cost }
}

/// Keys (slot pairs) from which the key-separator order is weighed (measured: 2.5x fewer
/// predicted flops at 20 keys on a 1k-node body, 1.3x on 2.6k, worse at 10 keys or fewer).
pub const KEY_SEPARATOR_MIN_KEYS: usize = 8;

/// The most the key-separator order is assumed to cut the node order's predicted flops and
/// factor entries (measured at most 2.5x: 20 keys on a 1k-node body), for skipping it when even
/// that cut could not make the direct step the choice (`GlobalStep::build`).
pub const KEY_SEPARATOR_MAX_GAIN: f64 = 4.0;

/// The key-separator candidate, with the node order's cost on the same (node, key) graph so
/// that the two compare exactly.
pub(super) struct KeySeparators {
    pub(super) perm: Vec<usize>,
    pub(super) cost: Cost,
    pub(super) node_cost: Cost,
}

/// See [`fill_reducing_order_of`]. Blocks are (node `a`, key `k`) with id `k * nodes + a`, holding
/// that node's free position and velocity of key `k`.
pub(super) fn key_separator_order(lower: &SparseColMat<usize, f64>, unknowns: &Unknowns, node_order: &[u32]) -> Option<KeySeparators> {
    let nodes = unknowns.nodes;
    let keys = unknowns.slots.count() / 2;
    let mut block_of = vec![0u32; unknowns.count()];
    let mut members: Vec<Vec<usize>> = vec![Vec::new(); nodes * keys];
    for a in 0..nodes {
        for s in 0..2 * keys {
            if let Some(u) = unknowns.get(a, s) {
                let b = (s / 2) * nodes + a;
                block_of[u] = b as u32;
                members[b].push(u);
            }
        }
    }
    let blocks = nodes * keys;
    if blocks > u32::MAX as usize {
        return None;
    }
    let graph = Graph::of_blocks(lower.symbolic().col_ptr(), lower.symbolic().row_idx(), &block_of, blocks);
    let weights: Vec<usize> = members.iter().map(Vec::len).collect();
    fn bisect(lo: usize, hi: usize, nodes: usize, node_order: &[u32], out: &mut Vec<u32>) {
        if lo >= hi {
            return;
        }
        let m = if hi - lo == 1 { lo } else { (lo + hi) / 2 };
        if hi - lo > 1 {
            bisect(lo, m, nodes, node_order, out);
            bisect(m + 1, hi, nodes, node_order, out);
        }
        out.extend(node_order.iter().map(|&a| (m * nodes + a as usize) as u32));
    }
    let mut by_keys = Vec::with_capacity(blocks);
    bisect(0, keys, nodes, node_order, &mut by_keys);
    let by_nodes: Vec<u32> = node_order.iter().flat_map(|&a| (0..keys).map(move |k| (k * nodes + a as usize) as u32)).collect();
    let (cost, node_cost) = (predicted_cost(&graph, &by_keys, &weights), predicted_cost(&graph, &by_nodes, &weights));
    let perm = postorder(&graph, &by_keys).iter().flat_map(|&b| members[b as usize].iter().copied()).collect();
    Some(KeySeparators { perm, cost, node_cost })
}
