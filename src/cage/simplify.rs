//! Simplification of a closed 2-manifold by quadric-error edge collapses (Garland & Heckbert
//! 1997), kept a closed 2-manifold and kept from folding.
//!
//! Each vertex carries the sum of the plane quadrics of its original triangles; collapsing an
//! edge puts the merged vertex where that sum is least (or at the better end or the midpoint
//! when the quadric is singular), at a cost equal to the sum of squared distances to those
//! planes. Cheapest first, a collapse is taken only when
//! - the cost stays within `max_error²` (the surface moves by about `max_error` at most);
//! - the link condition holds (the edge's two ends share exactly the two opposite vertices),
//!   so the surface stays a 2-manifold, and no piece shrinks below a tetrahedron;
//! - no surviving triangle around it turns by more than 60 degrees or loses most of its
//!   quality, so the surface does not fold onto itself locally.
//!
//! Global self-intersections are not excluded by these rules; the caller checks the result
//! ([`super::tree::TriangleTree::crossing_pair`]). Deterministic: ties by vertex indices.

use std::cmp::Reverse;
use std::collections::BinaryHeap;

use crate::mesh::{add, cross, dot, norm, scale, sub, Point, TriMesh};

/// A symmetric 4x4 quadric `[A b; bᵀ c]`: the squared distance sum `xᵀAx + 2bᵀx + c`.
#[derive(Debug, Clone, Copy, Default)]
struct Quadric {
    a: [[f64; 3]; 3],
    b: Point,
    c: f64,
    /// Total area of the planes (their weights).
    w: f64,
}

impl Quadric {
    /// The plane through `p` with unit normal `n`, weighted by `area`.
    fn of_plane(n: Point, p: Point, area: f64) -> Quadric {
        let d = -dot(n, p);
        Quadric {
            a: std::array::from_fn(|i| std::array::from_fn(|j| area * n[i] * n[j])),
            b: scale(n, area * d),
            c: area * d * d,
            w: area,
        }
    }

    fn plus(&self, o: &Quadric) -> Quadric {
        Quadric {
            a: std::array::from_fn(|i| std::array::from_fn(|j| self.a[i][j] + o.a[i][j])),
            b: add(self.b, o.b),
            c: self.c + o.c,
            w: self.w + o.w,
        }
    }

    fn error(&self, x: Point) -> f64 {
        let ax: Point = std::array::from_fn(|i| dot(self.a[i], x));
        (dot(x, ax) + 2.0 * dot(self.b, x) + self.c).max(0.0)
    }

    /// The minimizer `A x = -b`, if `A` is well conditioned.
    fn minimizer(&self) -> Option<Point> {
        let a = self.a;
        let det = a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1]) - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
            + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0]);
        let size = (0..3).map(|i| a[i][i]).sum::<f64>();
        if det.abs() <= 1e-6 * size * size * size {
            return None;
        }
        let rhs = scale(self.b, -1.0);
        // Cramer's rule.
        let col = |m: [[f64; 3]; 3], c: usize| {
            let mut m = m;
            for r in 0..3 {
                m[r][c] = rhs[r];
            }
            m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
                + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
        };
        Some([col(a, 0) / det, col(a, 1) / det, col(a, 2) / det])
    }
}

struct Collapser {
    positions: Vec<Point>,
    triangles: Vec<[u32; 3]>,
    alive: Vec<bool>,
    /// Live triangles around each vertex.
    around: Vec<Vec<u32>>,
    quadrics: Vec<Quadric>,
    /// Bumped when a vertex moves, so stale heap entries are skipped.
    version: Vec<u32>,
    removed: Vec<bool>,
    vertices: usize,
}

/// A heap entry: cost bits (non-negative floats order as their bits), the edge, the versions
/// it was computed at, and the target position.
type Entry = Reverse<(u64, u32, u32, u32, u32)>;

impl Collapser {
    fn neighbours(&self, v: u32) -> Vec<u32> {
        let mut n: Vec<u32> = self.around[v as usize].iter().flat_map(|&t| self.triangles[t as usize]).filter(|&u| u != v).collect();
        n.sort_unstable();
        n.dedup();
        n
    }

    /// The merged vertex of edge `uv`, its area-weighted quadric cost, and the mean squared
    /// distance to the planes (the cost over their area).
    fn target(&self, u: u32, v: u32) -> (f64, Point, f64) {
        let q = self.quadrics[u as usize].plus(&self.quadrics[v as usize]);
        let (pu, pv) = (self.positions[u as usize], self.positions[v as usize]);
        let mut candidates = vec![scale(add(pu, pv), 0.5), pu, pv];
        if let Some(x) = q.minimizer() {
            // Only trust the minimizer near the edge: far away it is a fold waiting to happen.
            let length = norm(sub(pu, pv));
            if norm(sub(x, scale(add(pu, pv), 0.5))) <= length {
                candidates.insert(0, x);
            }
        }
        let (cost, x) = candidates.into_iter().map(|x| (q.error(x), x)).min_by(|a, b| a.0.total_cmp(&b.0)).expect("candidates");
        (cost, x, if q.w > 0.0 { cost / q.w } else { 0.0 })
    }

    fn push(&self, heap: &mut BinaryHeap<Entry>, u: u32, v: u32) {
        let (u, v) = (u.min(v), u.max(v));
        let (cost, _, _) = self.target(u, v);
        heap.push(Reverse((cost.to_bits(), u, v, self.version[u as usize], self.version[v as usize])));
    }

    /// Collapse `v` into `u` at `x`, if the rules allow.
    fn try_collapse(&mut self, u: u32, v: u32, x: Point) -> bool {
        let (nu, nv) = (self.neighbours(u), self.neighbours(v));
        let shared: Vec<u32> = nu.iter().filter(|w| nv.binary_search(w).is_ok()).copied().collect();
        let both: Vec<u32> = self.around[u as usize].iter().filter(|t| self.triangles[**t as usize].contains(&v)).copied().collect();
        if shared.len() != 2 || both.len() != 2 || self.vertices <= 4 {
            return false;
        }
        // A closed piece with 4 vertices left would become flat.
        if nu.len() + nv.len() <= 6 {
            return false;
        }
        for &w in [u, v].iter() {
            for &t in &self.around[w as usize] {
                if both.contains(&t) {
                    continue;
                }
                let tri = self.triangles[t as usize];
                let old = tri.map(|i| self.positions[i as usize]);
                let new = tri.map(|i| if i == u || i == v { x } else { self.positions[i as usize] });
                let (n0, n1) = (cross(sub(old[1], old[0]), sub(old[2], old[0])), cross(sub(new[1], new[0]), sub(new[2], new[0])));
                let (l0, l1) = (norm(n0), norm(n1));
                if l1 <= 0.0 || dot(n0, n1) < 0.5 * l0 * l1 {
                    return false;
                }
                if quality(new) < 0.25 * quality(old).min(0.5) {
                    return false;
                }
            }
        }
        for &t in &both {
            self.alive[t as usize] = false;
        }
        let moved: Vec<u32> = self.around[v as usize].iter().filter(|t| !both.contains(t)).copied().collect();
        for &t in &moved {
            for i in self.triangles[t as usize].iter_mut() {
                if *i == v {
                    *i = u;
                }
            }
        }
        let mut list: Vec<u32> = self.around[u as usize].iter().filter(|t| !both.contains(t)).copied().collect();
        list.extend(moved);
        list.sort_unstable();
        self.around[u as usize] = list;
        for &t in &both {
            for &w in &self.triangles[t as usize] {
                if w != u && w != v {
                    self.around[w as usize].retain(|s| *s != t);
                }
            }
        }
        self.around[v as usize].clear();
        self.removed[v as usize] = true;
        self.positions[u as usize] = x;
        self.quadrics[u as usize] = self.quadrics[u as usize].plus(&self.quadrics[v as usize]);
        self.version[u as usize] += 1;
        self.version[v as usize] += 1;
        self.vertices -= 1;
        true
    }
}

/// `4√3 area / Σ edge²`: 1 for an equilateral triangle, 0 for a flat one.
fn quality([a, b, c]: [Point; 3]) -> f64 {
    let area = 0.5 * norm(cross(sub(b, a), sub(c, a)));
    let edges = dot(sub(b, a), sub(b, a)) + dot(sub(c, b), sub(c, b)) + dot(sub(a, c), sub(a, c));
    if edges > 0.0 {
        4.0 * 3f64.sqrt() * area / edges
    } else {
        0.0
    }
}

/// Simplify the closed 2-manifold `mesh` towards `target` vertices, moving the surface by about
/// `max_error` at most (see the module documentation). Unused vertices are dropped.
pub fn simplify(mesh: &TriMesh, target: usize, max_error: f64) -> TriMesh {
    let n = mesh.positions.len();
    let mut quadrics = vec![Quadric::default(); n];
    let mut around = vec![Vec::new(); n];
    for (t, tri) in mesh.triangles.iter().enumerate() {
        let [a, b, c] = tri.map(|v| mesh.positions[v as usize]);
        let normal = cross(sub(b, a), sub(c, a));
        let length = norm(normal);
        if length > 0.0 {
            let q = Quadric::of_plane(scale(normal, 1.0 / length), a, 0.5 * length);
            for &v in tri {
                quadrics[v as usize] = quadrics[v as usize].plus(&q);
            }
        }
        for &v in tri {
            around[v as usize].push(t as u32);
        }
    }
    let used = around.iter().filter(|a| !a.is_empty()).count();
    let mut c = Collapser {
        positions: mesh.positions.clone(),
        triangles: mesh.triangles.clone(),
        alive: vec![true; mesh.triangles.len()],
        around,
        quadrics,
        version: vec![0; n],
        removed: vec![false; n],
        vertices: used,
    };
    let mut heap = BinaryHeap::new();
    for tri in &mesh.triangles {
        for k in 0..3 {
            let (u, v) = (tri[k], tri[(k + 1) % 3]);
            if u < v {
                c.push(&mut heap, u, v);
            }
        }
    }
    let limit = max_error * max_error;
    while c.vertices > target {
        let Some(Reverse((_, u, v, vu, vv))) = heap.pop() else { break };
        if c.removed[u as usize] || c.removed[v as usize] || c.version[u as usize] != vu || c.version[v as usize] != vv {
            continue;
        }
        let (_, x, mean_square) = c.target(u, v);
        if mean_square > limit {
            continue;
        }
        if c.try_collapse(u, v, x) {
            for w in c.neighbours(u) {
                c.push(&mut heap, u, w);
            }
        }
    }
    let triangles: Vec<[u32; 3]> = c.triangles.iter().zip(&c.alive).filter(|(_, &a)| a).map(|(t, _)| *t).collect();
    crate::mesh::surface::compact(&TriMesh { positions: c.positions, triangles }).0
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::surface::{enclosed_volume, open_edges};
    use crate::procedural::{icosphere, prism};

    #[test]
    fn a_sphere_simplifies_to_the_target_and_stays_closed() {
        let sphere = icosphere(4);
        let simple = simplify(&sphere, 300, 0.1);
        assert!(simple.positions.len() <= 300, "{}", simple.positions.len());
        assert!(open_edges(&simple).is_empty());
        let (v0, v1) = (enclosed_volume(&sphere.positions, &sphere.triangles), enclosed_volume(&simple.positions, &simple.triangles));
        assert!((v1 - v0).abs() < 0.03 * v0, "{v1} vs {v0}");
        assert_eq!(crate::cage::tree::TriangleTree::new(&simple).crossing_pair(), None);
        assert_eq!(simplify(&sphere, 300, 0.1), simple, "deterministic");
    }

    #[test]
    fn flat_faces_collapse_for_free_and_corners_stay() {
        let cube = prism([1.0; 3], [8, 8, 8]);
        let simple = simplify(&cube, 8, 1e-9);
        assert!(open_edges(&simple).is_empty());
        assert!(simple.positions.len() < 40, "{}", simple.positions.len());
        let volume = enclosed_volume(&simple.positions, &simple.triangles);
        assert!((volume - 1.0).abs() < 1e-9, "{volume}");
    }

    #[test]
    fn the_error_bound_stops_the_collapses() {
        let sphere = icosphere(3);
        let simple = simplify(&sphere, 10, 1e-4);
        assert_eq!(simple.positions.len(), sphere.positions.len(), "no collapse on a curved surface within 1e-4");
    }
}
