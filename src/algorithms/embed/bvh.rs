//! Bounding volume hierarchy over axis-aligned boxes, serving the binding's two queries:
//! "every item whose box contains a point" and a best-first search by box distance.
//!
//! Built once, top down: a node's items are split at the median of their box centers along
//! the longest axis of those centers' bounds, down to leaves of at most [`LEAF_SIZE`] items.
//! Nodes live in one flat `Vec` (children before parents; the root is the last node), and the
//! items are permuted so that every leaf owns a contiguous range of them.
//!
//! Kept rather than parry3d's tree: two queries in 300 lines, where parry would be a runtime
//! dependency (with nalgebra) and is f32; the f64 points here would need parry3d-f64 as well.

use std::cmp::Ordering;
use std::collections::BinaryHeap;

use crate::algorithms::geometry::{Bounds, Point};

/// Leaves hold at most this many items.
pub(super) const LEAF_SIZE: usize = 4;

#[derive(Debug, Clone, Copy)]
enum Kind {
    /// Owns `Bvh::items[first..end]`.
    Leaf {
        first: u32,
        end: u32,
    },
    Inner {
        left: u32,
        right: u32,
    },
}

#[derive(Debug, Clone)]
struct Node {
    bounds: Bounds,
    kind: Kind,
}

#[derive(Debug, Clone)]
pub(super) struct Bvh {
    /// Children before parents; the root is the last node. Empty when there are no items.
    nodes: Vec<Node>,
    /// Item ids (indices into the boxes given to `build`) in leaf order.
    items: Vec<u32>,
    /// `item_bounds[k]` is the box of `items[k]`.
    item_bounds: Vec<Bounds>,
}

/// Reusable traversal buffers, one per worker thread.
#[derive(Debug, Default)]
pub(super) struct Scratch {
    stack: Vec<u32>,
    queue: BinaryHeap<Queued>,
}

/// A node waiting in the best-first queue, ordered so that the nearest pops first.
#[derive(Debug, Clone, Copy)]
struct Queued {
    distance: f64,
    node: u32,
}

impl Ord for Queued {
    fn cmp(&self, other: &Self) -> Ordering {
        // `BinaryHeap` pops the greatest: reverse both keys.
        other.distance.total_cmp(&self.distance).then(other.node.cmp(&self.node))
    }
}

impl PartialOrd for Queued {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

impl PartialEq for Queued {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == Ordering::Equal
    }
}

impl Eq for Queued {}

impl Bvh {
    /// Build the hierarchy over `boxes`; item `i` is `boxes[i]`. Deterministic: the median
    /// split orders centers by coordinate, then by item id.
    pub fn build(boxes: &[Bounds]) -> Bvh {
        let count = u32::try_from(boxes.len()).expect("more than u32::MAX items");
        let centers: Vec<Point> = boxes.iter().map(Bounds::center).collect();
        let mut items: Vec<u32> = (0..count).collect();
        let mut nodes = Vec::new();
        if !items.is_empty() {
            build_node(boxes, &centers, &mut items, 0, &mut nodes);
        }
        let item_bounds = items.iter().map(|&i| boxes[i as usize]).collect();
        Bvh { nodes, items, item_bounds }
    }

    /// Call `visit(item)` for every item whose box contains `p`, descending only into nodes
    /// whose box contains `p`. Order: depth first, left before right.
    pub(crate) fn for_each_containing(&self, p: Point, scratch: &mut Scratch, mut visit: impl FnMut(u32)) {
        let stack = &mut scratch.stack;
        stack.clear();
        if let Some(root) = self.root() {
            stack.push(root);
        }
        while let Some(n) = stack.pop() {
            let node = &self.nodes[n as usize];
            if !node.bounds.contains(p) {
                continue;
            }
            match node.kind {
                Kind::Leaf { first, end } => {
                    for k in first as usize..end as usize {
                        if self.item_bounds[k].contains(p) {
                            visit(self.items[k]);
                        }
                    }
                }
                Kind::Inner { left, right } => {
                    stack.push(right);
                    stack.push(left);
                }
            }
        }
    }

    /// Best-first branch and bound. Nodes are expanded in order of increasing box distance to
    /// `p`; `visit(item)` is called for each item whose box is within the current search
    /// radius and returns the new radius (initially infinite; it must never grow). The search
    /// ends when the nearest unexpanded box is farther than the radius, so every item whose
    /// box distance is at most the final radius has been visited.
    pub(crate) fn nearest_search(&self, p: Point, scratch: &mut Scratch, mut visit: impl FnMut(u32) -> f64) {
        let queue = &mut scratch.queue;
        queue.clear();
        let Some(root) = self.root() else { return };
        let mut radius = f64::INFINITY;
        queue.push(Queued { distance: self.nodes[root as usize].bounds.distance(p), node: root });
        while let Some(Queued { distance, node }) = queue.pop() {
            if distance > radius {
                break;
            }
            match self.nodes[node as usize].kind {
                Kind::Leaf { first, end } => {
                    for k in first as usize..end as usize {
                        if self.item_bounds[k].distance(p) <= radius {
                            radius = visit(self.items[k]);
                        }
                    }
                }
                Kind::Inner { left, right } => {
                    for child in [left, right] {
                        let d = self.nodes[child as usize].bounds.distance(p);
                        if d <= radius {
                            queue.push(Queued { distance: d, node: child });
                        }
                    }
                }
            }
        }
    }

    fn root(&self) -> Option<u32> {
        self.nodes.len().checked_sub(1).map(|r| r as u32)
    }
}

/// Build the subtree over `items` (which occupy `offset..` in the final item order), push its
/// nodes (children first) and return the index of its root.
fn build_node(boxes: &[Bounds], centers: &[Point], items: &mut [u32], offset: usize, nodes: &mut Vec<Node>) -> u32 {
    let bounds = items.iter().map(|&i| boxes[i as usize]).reduce(Bounds::union).expect("no items");
    let kind = if items.len() <= LEAF_SIZE {
        Kind::Leaf { first: offset as u32, end: (offset + items.len()) as u32 }
    } else {
        let spread = items
            .iter()
            .map(|&i| {
                let c = centers[i as usize];
                Bounds { lo: c, hi: c }
            })
            .reduce(Bounds::union)
            .expect("no items");
        let extent: [f64; 3] = std::array::from_fn(|d| spread.hi[d] - spread.lo[d]);
        // Longest axis, the first one on ties.
        let axis = (1..3).fold(0, |best, d| if extent[d] > extent[best] { d } else { best });
        let mid = items.len() / 2;
        items.select_nth_unstable_by(mid, |&a, &b| centers[a as usize][axis].total_cmp(&centers[b as usize][axis]).then(a.cmp(&b)));
        let (low, high) = items.split_at_mut(mid);
        let left = build_node(boxes, centers, low, offset, nodes);
        let right = build_node(boxes, centers, high, offset + mid, nodes);
        Kind::Inner { left, right }
    };
    nodes.push(Node { bounds, kind });
    (nodes.len() - 1) as u32
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::support::testing::Rng;

    /// Deterministic pseudo-random boxes of assorted sizes.
    fn boxes(count: usize) -> Vec<Bounds> {
        let mut rng = Rng::new(1);
        (0..count)
            .map(|_| {
                let c: Point = [rng.uniform(0.0, 10.0), rng.uniform(0.0, 10.0), rng.uniform(0.0, 3.0)];
                let h: Point = [rng.uniform(0.0, 1.0), rng.uniform(0.0, 1.0), rng.uniform(0.0, 1.0)];
                Bounds { lo: std::array::from_fn(|d| c[d] - h[d]), hi: std::array::from_fn(|d| c[d] + h[d]) }
            })
            .collect()
    }

    fn contains_box(outer: &Bounds, inner: &Bounds) -> bool {
        (0..3).all(|d| outer.lo[d] <= inner.lo[d] && inner.hi[d] <= outer.hi[d])
    }

    /// Walk the tree from `n`, checking nesting and leaf sizes; collect the items
    /// it reaches and return its height.
    fn walk(bvh: &Bvh, n: u32, reached: &mut Vec<u32>) -> usize {
        let node = &bvh.nodes[n as usize];
        match node.kind {
            Kind::Leaf { first, end } => {
                assert!(first < end && (end - first) as usize <= LEAF_SIZE);
                for k in first as usize..end as usize {
                    assert!(contains_box(&node.bounds, &bvh.item_bounds[k]));
                    reached.push(bvh.items[k]);
                }
                0
            }
            Kind::Inner { left, right } => {
                // Children come before their parent in the flat array.
                assert!(left < n && right < n);
                [left, right]
                    .map(|child| {
                        assert!(contains_box(&node.bounds, &bvh.nodes[child as usize].bounds));
                        walk(bvh, child, reached) + 1
                    })
                    .into_iter()
                    .max()
                    .unwrap()
            }
        }
    }

    #[test]
    fn structure_covers_every_item_once() {
        for count in [0, 1, 4, 5, 17, 1000] {
            let boxes = boxes(count);
            let bvh = Bvh::build(&boxes);
            let mut reached = Vec::new();
            let height = bvh.root().map(|root| walk(&bvh, root, &mut reached));
            reached.sort_unstable();
            assert_eq!(reached, (0..count as u32).collect::<Vec<_>>());
            for (k, &i) in bvh.items.iter().enumerate() {
                assert_eq!(bvh.item_bounds[k], boxes[i as usize]);
            }
            // Median splits halve the items at each level, down to leaves of <= LEAF_SIZE.
            if let Some(height) = height {
                let balanced = (count as f64 / LEAF_SIZE as f64).log2().ceil().max(0.0) as usize;
                assert_eq!(height, balanced, "{count} items");
            }
        }
    }

    #[test]
    fn queries_match_brute_force() {
        let boxes = boxes(500);
        let bvh = Bvh::build(&boxes);
        let mut scratch = Scratch::default();
        for k in 0..400 {
            let t = k as f64;
            let p: Point = [(t * 0.37) % 12.0 - 1.0, (t * 0.71) % 12.0 - 1.0, (t * 0.13) % 5.0 - 1.0];

            let mut found = Vec::new();
            bvh.for_each_containing(p, &mut scratch, |i| found.push(i));
            found.sort_unstable();
            let expected: Vec<u32> = (0..boxes.len() as u32).filter(|&i| boxes[i as usize].contains(p)).collect();
            assert_eq!(found, expected);

            // Nearest box by branch and bound, radius = best distance so far.
            let mut best = (f64::INFINITY, u32::MAX);
            bvh.nearest_search(p, &mut scratch, |i| {
                let d = boxes[i as usize].distance(p);
                if (d, i) < best {
                    best = (d, i);
                }
                best.0
            });
            let brute =
                (0..boxes.len() as u32).map(|i| (boxes[i as usize].distance(p), i)).fold((f64::INFINITY, u32::MAX), |a, b| if b < a { b } else { a });
            assert_eq!(best, brute);
        }
    }
}
