//! A bounding-volume tree over the triangles of a surface, answering the three questions the
//! cage asks of a (possibly open, non-manifold, self-intersecting) surface:
//!
//! - the generalized winding number at a point ([`TriangleTree::winding`]): the signed solid
//!   angle the surface subtends there over 4π, 1 inside a closed outward surface, 0 outside,
//!   and a graceful in-between near holes (Jacobson et al. 2013). Far clusters of triangles
//!   are replaced by their area-weighted dipole (the first term of Barill et al. 2018's fast
//!   winding numbers) when the point is more than [`FAR`] cluster radii away;
//! - the distance to the nearest triangle, up to a cap ([`TriangleTree::distance`]);
//! - pairs of triangles that cross each other ([`TriangleTree::crossing_pair`]).
//!
//! Built top down by median splits along the longest axis of the triangle centroids; leaves
//! hold at most [`LEAF`] triangles. Deterministic: no hashing, ties by triangle index.
//!
//! Kept rather than parry3d's tree: no crate's tree carries the clusters' dipoles the winding
//! number needs, and it is not [`crate::algorithms::embed`]'s box tree (triangles, not boxes).

use crate::algorithms::geometry::{add, cross, dot, norm, scale, sub, Bounds, Point, TriMesh};

/// Leaves hold at most this many triangles.
const LEAF: usize = 8;

/// A cluster is replaced by its dipole beyond this many cluster radii (Barill et al. use 2).
const FAR: f64 = 2.0;

#[derive(Debug, Clone)]
struct Node {
    bounds: Bounds,
    /// Area-weighted centroid of the cluster's triangles.
    center: Point,
    /// Largest distance from `center` to a vertex of the cluster.
    radius: f64,
    /// Sum of the triangles' area vectors `½ (b - a) × (c - a)`.
    area: Point,
    /// Leaf: triangles `order[first..end]`; inner: children `left`, `right` (`end == 0`).
    first: u32,
    end: u32,
    left: u32,
    right: u32,
}

/// The triangles of a surface in a bounding-volume tree (see the module documentation).
#[derive(Debug, Clone)]
pub struct TriangleTree {
    corners: Vec<[Point; 3]>,
    /// Triangle indices of the input surface, in leaf order.
    order: Vec<u32>,
    /// `ids[k]`: the vertex indices of triangle `k` (to skip neighbours in crossing tests).
    ids: Vec<[u32; 3]>,
    nodes: Vec<Node>,
}

impl TriangleTree {
    /// The tree of `surface`'s triangles.
    pub fn new(surface: &TriMesh) -> TriangleTree {
        let corners: Vec<[Point; 3]> = surface.triangles.iter().map(|t| t.map(|v| surface.positions[v as usize])).collect();
        let mut tree =
            TriangleTree { corners, order: (0..surface.triangles.len() as u32).collect(), ids: surface.triangles.clone(), nodes: Vec::new() };
        if !tree.order.is_empty() {
            let n = tree.order.len();
            tree.build(0, n);
        }
        tree
    }

    fn centroid(&self, t: u32) -> Point {
        let [a, b, c] = self.corners[t as usize];
        std::array::from_fn(|d| (a[d] + b[d] + c[d]) / 3.0)
    }

    /// Build the subtree over `order[first..end]`; returns its node index.
    fn build(&mut self, first: usize, end: usize) -> u32 {
        let mut bounds = Bounds::EMPTY;
        let mut area = [0.0; 3];
        let mut weighted = [0.0; 3];
        let mut total = 0.0;
        for &t in &self.order[first..end] {
            let [a, b, c] = self.corners[t as usize];
            bounds = bounds.including(a).including(b).including(c);
            let at = scale(cross(sub(b, a), sub(c, a)), 0.5);
            area = add(area, at);
            let w = norm(at);
            weighted = add(weighted, scale(self.centroid(t), w));
            total += w;
        }
        let center = if total > 0.0 { scale(weighted, 1.0 / total) } else { bounds.center() };
        let radius = self.order[first..end].iter().flat_map(|&t| self.corners[t as usize]).map(|p| norm(sub(p, center))).fold(0.0, f64::max);
        let index = self.nodes.len() as u32;
        self.nodes.push(Node { bounds, center, radius, area, first: first as u32, end: end as u32, left: 0, right: 0 });
        if end - first > LEAF {
            let centers = Bounds::of(&self.order[first..end].iter().map(|&t| self.centroid(t)).collect::<Vec<_>>());
            let axis = (0..3).max_by(|&i, &j| (centers.hi[i] - centers.lo[i]).total_cmp(&(centers.hi[j] - centers.lo[j]))).unwrap_or(0);
            let key = |tree: &TriangleTree, t: u32| (tree.centroid(t)[axis], t);
            let mut slice: Vec<u32> = self.order[first..end].to_vec();
            let mid = slice.len() / 2;
            slice.select_nth_unstable_by(mid, |&s, &t| {
                let (ks, kt) = (key(self, s), key(self, t));
                ks.0.total_cmp(&kt.0).then(ks.1.cmp(&kt.1))
            });
            self.order[first..end].copy_from_slice(&slice);
            let left = self.build(first, first + mid);
            let right = self.build(first + mid, end);
            let node = &mut self.nodes[index as usize];
            node.left = left;
            node.right = right;
            node.end = 0;
        }
        index
    }

    fn is_leaf(node: &Node) -> bool {
        node.end != 0
    }

    /// The generalized winding number of the surface at `q` (see the module documentation).
    pub fn winding(&self, q: Point) -> f64 {
        if self.nodes.is_empty() {
            return 0.0;
        }
        let mut sum = 0.0;
        let mut stack = vec![0u32];
        while let Some(i) = stack.pop() {
            let node = &self.nodes[i as usize];
            let r = sub(node.center, q);
            let d = norm(r);
            if d > FAR * node.radius {
                // The cluster's dipole: its area vector seen from q.
                sum += dot(r, node.area) / (d * d * d);
            } else if Self::is_leaf(node) {
                for &t in &self.order[node.first as usize..node.end as usize] {
                    sum += solid_angle(q, self.corners[t as usize]);
                }
            } else {
                stack.push(node.left);
                stack.push(node.right);
            }
        }
        sum / (4.0 * std::f64::consts::PI)
    }

    /// The distance from `q` to the nearest triangle, or `cap` when none is nearer.
    pub fn distance(&self, q: Point, cap: f64) -> f64 {
        let mut best = cap;
        if self.nodes.is_empty() {
            return best;
        }
        let mut stack = vec![0u32];
        while let Some(i) = stack.pop() {
            let node = &self.nodes[i as usize];
            if node.bounds.distance(q) >= best {
                continue;
            }
            if Self::is_leaf(node) {
                for &t in &self.order[node.first as usize..node.end as usize] {
                    best = best.min(distance_to_triangle(q, self.corners[t as usize]));
                }
            } else {
                let (l, r) = (&self.nodes[node.left as usize], &self.nodes[node.right as usize]);
                // Nearer child last, so it is searched first.
                if l.bounds.distance(q) < r.bounds.distance(q) {
                    stack.push(node.right);
                    stack.push(node.left);
                } else {
                    stack.push(node.left);
                    stack.push(node.right);
                }
            }
        }
        best
    }

    /// The first pair (by triangle index) of triangles that share no vertex and cross each
    /// other, if any.
    pub fn crossing_pair(&self) -> Option<(usize, usize)> {
        let mut found: Option<(usize, usize)> = None;
        let mut stack = Vec::new();
        for s in 0..self.corners.len() {
            let [a, b, c] = self.corners[s];
            let bs = Bounds::of(&[a, b, c]);
            stack.clear();
            stack.push(0u32);
            while let Some(i) = stack.pop() {
                let node = &self.nodes[i as usize];
                if !overlaps(&node.bounds, &bs) {
                    continue;
                }
                if Self::is_leaf(node) {
                    for &t in &self.order[node.first as usize..node.end as usize] {
                        let t = t as usize;
                        if t <= s || self.ids[t].iter().any(|v| self.ids[s].contains(v)) {
                            continue;
                        }
                        if triangles_cross(self.corners[s], self.corners[t]) && found.is_none_or(|f| (s, t) < f) {
                            found = Some((s, t));
                        }
                    }
                } else {
                    stack.push(node.left);
                    stack.push(node.right);
                }
            }
            if found.is_some() {
                return found;
            }
        }
        found
    }
}

fn overlaps(a: &Bounds, b: &Bounds) -> bool {
    (0..3).all(|d| a.lo[d] <= b.hi[d] && b.lo[d] <= a.hi[d])
}

/// Signed solid angle of triangle `[a, b, c]` seen from `q` (Van Oosterom & Strackee 1983):
/// positive when `q` is behind the triangle (inside, for an outward surface).
fn solid_angle(q: Point, [a, b, c]: [Point; 3]) -> f64 {
    let (a, b, c) = (sub(a, q), sub(b, q), sub(c, q));
    let (la, lb, lc) = (norm(a), norm(b), norm(c));
    let numerator = dot(a, cross(b, c));
    let denominator = la * lb * lc + dot(a, b) * lc + dot(b, c) * la + dot(c, a) * lb;
    2.0 * numerator.atan2(denominator)
}

/// Distance from `q` to the solid triangle `[a, b, c]` (Ericson, Real-Time Collision
/// Detection 5.1.5: Voronoi regions of the vertices, edges and face).
pub(crate) fn distance_to_triangle(q: Point, [a, b, c]: [Point; 3]) -> f64 {
    norm(sub(q, closest_on_triangle(q, [a, b, c])))
}

fn closest_on_triangle(p: Point, [a, b, c]: [Point; 3]) -> Point {
    let (ab, ac, ap) = (sub(b, a), sub(c, a), sub(p, a));
    let (d1, d2) = (dot(ab, ap), dot(ac, ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return a;
    }
    let bp = sub(p, b);
    let (d3, d4) = (dot(ab, bp), dot(ac, bp));
    if d3 >= 0.0 && d4 <= d3 {
        return b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return add(a, scale(ab, d1 / (d1 - d3)));
    }
    let cp = sub(p, c);
    let (d5, d6) = (dot(ab, cp), dot(ac, cp));
    if d6 >= 0.0 && d5 <= d6 {
        return c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return add(a, scale(ac, d2 / (d2 - d6)));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        return add(b, scale(sub(c, b), (d4 - d3) / ((d4 - d3) + (d5 - d6))));
    }
    let denom = 1.0 / (va + vb + vc);
    add(a, add(scale(ab, vb * denom), scale(ac, vc * denom)))
}

/// Whether two triangles (sharing no vertex) cross: some edge of one passes through the other.
/// Touching within rounding counts as crossing, which errs on the safe side for a cage.
pub(crate) fn triangles_cross(s: [Point; 3], t: [Point; 3]) -> bool {
    let edge_hits = |tri: [Point; 3], other: [Point; 3]| (0..3).any(|k| segment_hits_triangle(tri[k], tri[(k + 1) % 3], other));
    edge_hits(s, t) || edge_hits(t, s)
}

/// Whether segment `pq` meets the solid triangle `[a, b, c]` (non-coplanar case; a segment in
/// the triangle's plane is reported when it crosses an edge of the triangle).
fn segment_hits_triangle(p: Point, q: Point, [a, b, c]: [Point; 3]) -> bool {
    let n = cross(sub(b, a), sub(c, a));
    let scale_len = norm(n).sqrt().max(f64::MIN_POSITIVE);
    let (dp, dq) = (dot(n, sub(p, a)), dot(n, sub(q, a)));
    let tolerance = 1e-12 * scale_len * scale_len * (norm(sub(q, p)) + scale_len);
    if dp.abs() <= tolerance && dq.abs() <= tolerance {
        // Coplanar: crossing edges in the plane.
        let tri = [a, b, c];
        return (0..3).any(|k| segments_cross_2d(p, q, tri[k], tri[(k + 1) % 3], n));
    }
    if (dp > tolerance && dq > tolerance) || (dp < -tolerance && dq < -tolerance) {
        return false;
    }
    let s = dp / (dp - dq);
    let x = add(p, scale(sub(q, p), s));
    // Inside test by edge normals.
    let inside = |u: Point, v: Point| dot(n, cross(sub(v, u), sub(x, u))) >= -1e-12 * dot(n, n);
    inside(a, b) && inside(b, c) && inside(c, a)
}

/// Whether segments `pq` and `uv`, in the plane with normal `n`, cross.
fn segments_cross_2d(p: Point, q: Point, u: Point, v: Point, n: Point) -> bool {
    let side = |a: Point, b: Point, x: Point| dot(n, cross(sub(b, a), sub(x, a)));
    let (s1, s2) = (side(p, q, u), side(p, q, v));
    let (s3, s4) = (side(u, v, p), side(u, v, q));
    s1 * s2 < 0.0 && s3 * s4 < 0.0
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::algorithms::procedural::{icosphere, prism};

    #[test]
    fn winding_is_one_inside_zero_outside_and_half_at_an_open_rim() {
        let sphere = icosphere(3);
        let tree = TriangleTree::new(&sphere);
        assert!((tree.winding([0.1, -0.2, 0.05]) - 1.0).abs() < 0.03, "{}", tree.winding([0.1, -0.2, 0.05]));
        assert!(tree.winding([0.0, 0.0, 3.0]).abs() < 0.03);
        // The lower half of the sphere: a bowl, winding 1/2 at the centre of its rim.
        let mut bowl = sphere.clone();
        bowl.triangles.retain(|t| t.iter().all(|&v| sphere.positions[v as usize][1] <= 1e-9));
        let w = TriangleTree::new(&bowl).winding([0.0, 0.0, 0.0]);
        assert!((w - 0.5).abs() < 0.02, "{w}");
    }

    /// The dipole approximation is within a few percent: plenty for a threshold at ½.
    #[test]
    fn far_field_matches_the_exact_sum() {
        let sphere = icosphere(4);
        let tree = TriangleTree::new(&sphere);
        for q in [[0.3, 0.2, 0.1], [1.2, 0.1, 0.0], [0.0, 0.99, 0.0], [2.0, 2.0, 2.0]] {
            let exact: f64 = tree.corners.iter().map(|&t| solid_angle(q, t)).sum::<f64>() / (4.0 * std::f64::consts::PI);
            assert!((tree.winding(q) - exact).abs() < 0.03, "{q:?}: {} vs {exact}", tree.winding(q));
        }
    }

    #[test]
    fn distance_matches_brute_force() {
        let cube = prism([1.0, 2.0, 1.0], [2, 3, 2]);
        let tree = TriangleTree::new(&cube);
        for q in [[0.5, 1.0, 0.5], [2.0, 1.0, 0.5], [-1.0, -1.0, -1.0], [0.5, 0.1, 0.5]] {
            let brute = tree.corners.iter().map(|&t| distance_to_triangle(q, t)).fold(f64::INFINITY, f64::min);
            assert!((tree.distance(q, f64::INFINITY) - brute).abs() < 1e-12);
        }
        assert_eq!(tree.distance([10.0, 0.0, 0.0], 1.0), 1.0, "capped");
        assert!((tree.distance([2.0, 1.0, 0.5], 10.0) - 1.0).abs() < 1e-12);
    }

    #[test]
    fn crossing_boxes_are_found_and_a_closed_box_is_clean() {
        let a = prism([1.0; 3], [2, 2, 2]);
        assert_eq!(TriangleTree::new(&a).crossing_pair(), None);
        let mut b = a.clone();
        let n = a.positions.len() as u32;
        b.positions.extend(a.positions.iter().map(|p| [p[0] + 0.5, p[1] + 0.5, p[2] + 0.5]));
        b.triangles.extend(a.triangles.iter().map(|t| t.map(|v| v + n)));
        let (s, t) = TriangleTree::new(&b).crossing_pair().expect("the boxes cross");
        assert!(s < a.triangles.len() && t >= a.triangles.len());
        // Apart, they do not.
        let mut c = a.clone();
        c.positions.extend(a.positions.iter().map(|p| [p[0] + 1.5, p[1], p[2]]));
        c.triangles.extend(a.triangles.iter().map(|t| t.map(|v| v + n)));
        assert_eq!(TriangleTree::new(&c).crossing_pair(), None);
    }
}
