//! Barycentric binding of surface points to a tet mesh.
//!
//! Contract: each point gets a tet and four barycentric weights summing to 1. Points inside
//! the mesh use the tet containing them; points outside use the closest tet and the
//! barycentric coordinates of the closest point on it (all weights >= 0). A BVH over tet
//! bounds finds candidates; results are deterministic (ties broken by lowest tet index).
//!
//! The binding is a fixed linear map from node values to point values, so it carries node
//! positions, velocities or whole Hermite trajectories exactly ([`Binding::apply`]).
//!
//! # Algorithm
//!
//! 1. A BVH over the tets' boxes (`bvh`) is built once per [`Binding::compute`].
//! 2. Containment: among the tets whose box holds the point, the lowest-index one whose
//!    barycentric coordinates are all `>= -EPS` binds it, with those coordinates.
//! 3. Otherwise, nearest: a best-first search by box distance computes the closest point on
//!    each candidate solid tet (the best of the closest points on its four faces), pruning
//!    boxes farther than the best distance so far; the minimum distance wins, then the lowest
//!    index.
//!
//! Points are independent and processed in parallel; each result depends only on its point.
//!
//! # Tolerances and ties
//!
//! - A point is in a tet when every barycentric coordinate is `>= -EPS` (`EPS = 1e-12`), so a
//!   point on a face shared by two tets is in both, and the lower index wins.
//! - Outside the mesh there is no distance tolerance: the distance to the mesh is flat to first
//!   order around its minimum, so a tolerance of `EPS` on it would admit closest points
//!   `~sqrt(EPS)` apart. Ties are exact instead, and made reliable by computing shared
//!   features identically in every tet (below): a point nearest to a boundary edge or vertex
//!   gets bitwise the same distance from every tet around it, and the lowest index wins. (The
//!   choice among those tets does not change [`Binding::apply`]: the weights off the shared
//!   feature are exactly 0.)
//! - Tet boxes are padded by `8 * EPS * scale`, where `scale` is the mesh's bounding-box
//!   diagonal plus its largest coordinate magnitude (the size rounding errors are relative
//!   to), so neither query can miss a tet the rules above pick: the tests compare against a
//!   search over all tets.
//!
//! Shared features give bitwise-equal answers in every tet that has them, whatever the order
//! of its vertices:
//! - the sub-tet volume of a face is evaluated with the face's vertices sorted by global index,
//!   so two tets sharing a face get exactly opposite values for it: their in/out decisions
//!   agree, and no point falls through the crack between them;
//! - the closest point on an edge is computed symmetrically in its two ends, and on a vertex it
//!   is the vertex.

mod bvh;

use rayon::prelude::*;

use crate::algorithms::geometry::{cross, dot, norm, sub, Bounds, Point, TetMesh};
use bvh::Bvh;

/// Every point's tet and barycentric weights in a tet mesh (see the module documentation).
#[derive(Debug, Clone, PartialEq)]
pub struct Binding {
    /// The tet each point is bound to.
    pub tets: Vec<u32>,
    /// Barycentric weights on the vertices of `tets[i]`, in the mesh's vertex order. They sum
    /// to 1 (up to rounding). Outside points have all weights >= 0; inside points may have
    /// weights down to `-1e-12` (a point within rounding of a face).
    pub weights: Vec<[f64; 4]>,
    /// Distance from each point to its tet (0 inside), for diagnostics.
    pub distances: Vec<f64>,
}

/// The cost model of [`Binding::predicted_seconds`] (CPU seconds; measured on TetGen bodies of
/// 3k to 70k tets and cages around prisms with 200 to 120k surface vertices).
const BIND_SECONDS_PER_TET: f64 = 5e-7;
const BIND_SECONDS_PER_POINT: f64 = 3e-7;

/// Containment tolerance on barycentric coordinates (see the module docs).
const EPS: f64 = 1e-12;

/// Local vertex triples of a tet's faces; face `i` is opposite vertex `i` and oriented so that
/// `det[x_a - p, x_b - p, x_c - p]` is six times the signed volume of the tet with vertex `i`
/// replaced by `p` (positive when `p` is on the same side of the face as vertex `i`).
const FACES: [[usize; 3]; 4] = [[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]];

impl Binding {
    /// Seconds [`Binding::compute`] is predicted to take for `points` points in a mesh of
    /// `tets` tets (CPU seconds; for the progress bar's estimate; measured by `cargo bench
    /// --bench demo -- models`): the tree over the tets, and one search per point.
    pub fn predicted_seconds(tets: usize, points: usize) -> f64 {
        BIND_SECONDS_PER_TET * tets as f64 + BIND_SECONDS_PER_POINT * points as f64
    }

    /// Bind every point to a tet of `mesh` (which must satisfy the [`TetMesh`] invariant:
    /// positive volumes, indices in range).
    ///
    /// # Panics
    /// If `points` is not empty but the mesh has no tets, or if a point is not finite.
    pub fn compute(mesh: &TetMesh, points: &[Point]) -> Binding {
        if points.is_empty() {
            return Binding { tets: Vec::new(), weights: Vec::new(), distances: Vec::new() };
        }
        assert!(!mesh.tets.is_empty(), "cannot bind {} points to a mesh without tets", points.len());
        let locator = Locator::new(mesh);
        let located: Vec<Located> = points
            .par_iter()
            .enumerate()
            .map_init(bvh::Scratch::default, |scratch, (i, &p)| {
                assert!(p.iter().all(|c| c.is_finite()), "point {i} is not finite: {p:?}");
                locator.locate(p, scratch)
            })
            .collect();
        Binding {
            tets: located.iter().map(|l| l.tet).collect(),
            weights: located.iter().map(|l| l.weights).collect(),
            distances: located.iter().map(|l| l.distance).collect(),
        }
    }

    /// Points carried by node positions `nodes` (same indexing as the mesh).
    ///
    /// Linear in `nodes`: it applies equally to velocities, or to any per-node vector field.
    pub fn apply(&self, mesh: &TetMesh, nodes: &[Point]) -> Vec<Point> {
        assert_eq!(nodes.len(), mesh.positions.len(), "one node value per mesh vertex");
        self.tets.iter().zip(&self.weights).map(|(&t, &w)| combine(mesh.tets[t as usize].map(|v| nodes[v as usize]), w)).collect()
    }
}

/// One point's binding.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Located {
    tet: u32,
    weights: [f64; 4],
    distance: f64,
}

/// The mesh with its BVH: answers point queries.
struct Locator<'a> {
    mesh: &'a TetMesh,
    bvh: Bvh,
}

impl<'a> Locator<'a> {
    fn new(mesh: &'a TetMesh) -> Locator<'a> {
        // Containment accepts barycentric coordinates down to -EPS: the tet scaled by
        // 1 + 4 EPS about its centroid, which pokes out of its box by at most 4 EPS times the
        // box size (<= scale). The other half of the pad covers rounding, and keeps box
        // distances below the computed tet distances.
        let pad = 8.0 * EPS * length_scale(mesh);
        let boxes: Vec<Bounds> = (0..mesh.tets.len())
            .map(|t| {
                let (_, corners) = tet_at(mesh, t as u32);
                Bounds::of(&corners).padded(pad)
            })
            .collect();
        Locator { mesh, bvh: Bvh::build(&boxes) }
    }

    fn tet(&self, t: u32) -> ([u32; 4], [Point; 4]) {
        tet_at(self.mesh, t)
    }

    fn locate(&self, p: Point, scratch: &mut bvh::Scratch) -> Located {
        match self.containing(p, scratch) {
            Some(found) => found,
            None => self.nearest(p, scratch),
        }
    }

    /// The lowest-index tet containing `p`, if any.
    fn containing(&self, p: Point, scratch: &mut bvh::Scratch) -> Option<Located> {
        let mut found: Option<Located> = None;
        self.bvh.for_each_containing(p, scratch, |t| {
            if found.is_some_and(|f| f.tet < t) {
                return;
            }
            let (ids, corners) = self.tet(t);
            let weights = barycentric(p, ids, corners);
            if is_contained(weights) {
                found = Some(Located { tet: t, weights, distance: 0.0 });
            }
        });
        found
    }

    /// The lowest-index tet among those nearest to `p`, with the closest point on it.
    fn nearest(&self, p: Point, scratch: &mut bvh::Scratch) -> Located {
        let mut best = Located { tet: u32::MAX, weights: [0.0; 4], distance: f64::INFINITY };
        // Pruning keeps boxes at exactly the best distance, so exact ties are all visited.
        self.bvh.nearest_search(p, scratch, |t| {
            let (ids, corners) = self.tet(t);
            let (weights, distance) = closest_on_tet(p, ids, corners);
            if (distance, t) < (best.distance, best.tet) {
                best = Located { tet: t, weights, distance };
            }
            best.distance
        });
        assert!(best.tet != u32::MAX, "a mesh with tets has a nearest one");
        best
    }
}

/// The length rounding errors are relative to: the bounding-box diagonal plus the largest
/// coordinate magnitude (0 for a mesh without vertices).
fn length_scale(mesh: &TetMesh) -> f64 {
    let bounds = Bounds::of(&mesh.positions);
    if bounds.is_empty() {
        return 0.0;
    }
    let largest = bounds.lo.iter().chain(&bounds.hi).fold(0.0_f64, |m, c| m.max(c.abs()));
    bounds.diagonal() + largest
}

fn tet_at(mesh: &TetMesh, t: u32) -> ([u32; 4], [Point; 4]) {
    let ids = mesh.tets[t as usize];
    (ids, ids.map(|v| mesh.positions[v as usize]))
}

/// `Σ_j w_j x_j`.
fn combine(x: [Point; 4], w: [f64; 4]) -> Point {
    std::array::from_fn(|d| w[0] * x[0][d] + w[1] * x[1][d] + w[2] * x[2][d] + w[3] * x[3][d])
}

fn is_contained(weights: [f64; 4]) -> bool {
    weights.iter().all(|&w| w >= -EPS)
}

/// Barycentric coordinates of `p` in the tet with vertex ids `ids` at `corners`: the signed
/// volumes of the four sub-tets with one vertex replaced by `p`, over their sum (which is the
/// tet's volume, so they sum to 1 and `Σ λ_j x_j = p` in exact arithmetic).
fn barycentric(p: Point, ids: [u32; 4], corners: [Point; 4]) -> [f64; 4] {
    let mut volumes = [0.0; 4];
    for (volume, [a, b, c]) in volumes.iter_mut().zip(FACES) {
        *volume = face_orientation(p, [(ids[a], corners[a]), (ids[b], corners[b]), (ids[c], corners[c])]);
    }
    let total: f64 = volumes.iter().sum();
    volumes.map(|v| v / total)
}

/// `det[a - p, b - p, c - p]` for the face `(a, b, c)` (ids with positions), evaluated with
/// the vertices sorted by id and the sign of that permutation applied: every tet sharing the
/// face gets bitwise the same magnitude, with opposite signs for opposite orientations.
#[inline]
fn face_orientation(p: Point, mut face: [(u32, Point); 3]) -> f64 {
    let mut sign = 1.0;
    for (i, j) in [(0, 1), (1, 2), (0, 1)] {
        if face[i].0 > face[j].0 {
            face.swap(i, j);
            sign = -sign;
        }
    }
    let [a, b, c] = face.map(|(_, x)| sub(x, p));
    sign * dot(a, cross(b, c))
}

/// Closest point to `p` on the solid tet with vertex ids `ids` (for [`barycentric`]) at
/// `corners`: barycentric coordinates (all >= 0, summing to 1) and the distance.
///
/// Inside, `p` itself. Outside, the best of the closest points on the faces whose plane `p` is
/// beyond, i.e. with a negative coordinate (the first such face on exact ties). No other face
/// can hold the closest point `q`: `p - q = Σ α_i n_i` with `α_i >= 0` over the outward
/// normals of the faces through `q`, so `0 < |p - q|² = Σ α_i (p - q)·n_i`, and some face
/// through `q` has `(p - q)·n_i > 0`: `p` is beyond its plane.
fn closest_on_tet(p: Point, ids: [u32; 4], corners: [Point; 4]) -> ([f64; 4], f64) {
    let inside = barycentric(p, ids, corners);
    if inside.iter().all(|&w| w >= 0.0) {
        return (inside, 0.0);
    }
    let mut best = ([0.0; 4], f64::INFINITY);
    for (face, _) in FACES.into_iter().zip(inside).filter(|&(_, w)| w < 0.0) {
        let on_face = closest_on_triangle(p, face.map(|j| corners[j]));
        let mut weights = [0.0; 4];
        for (k, &j) in face.iter().enumerate() {
            weights[j] = on_face[k];
        }
        let distance = norm(sub(p, combine(corners, weights)));
        if distance < best.1 {
            best = (weights, distance);
        }
    }
    best
}

/// Closest point to `p` on the solid triangle `[a, b, c]`, as barycentric coordinates (all
/// >= 0, summing to 1).
///
/// Space around a triangle splits into seven Voronoi regions, one per feature: three vertex
/// regions, three edge slabs and the prism over the face. Each is bounded by planes through
/// the features, so membership needs only a few dot products; the closest point is then the
/// vertex, the foot on the edge or the foot on the plane. Vertex regions are tested first, then
/// edges, and what remains is the face (Ericson, *Real-Time Collision Detection*, 5.1.5).
///
/// Vertex and edge answers are bitwise independent of the order the triangle's vertices are
/// given in (each edge weight is its own ratio, symmetric in the two ends), so tets sharing
/// an edge or vertex agree on the closest point there exactly.
fn closest_on_triangle(p: Point, [a, b, c]: [Point; 3]) -> [f64; 3] {
    let (ab, ac, bc) = (sub(b, a), sub(c, a), sub(c, b));
    let (pa, pb, pc) = (sub(p, a), sub(p, b), sub(p, c));
    // How far p projects along each edge past each of its ends, towards the other end (times
    // the edge length): `ab_a = (p - a)·(b - a)`, `ab_b = (p - b)·(a - b)`, and so on. The two
    // values of an edge sum to its squared length.
    let (ab_a, ab_b) = (dot(pa, ab), -dot(pb, ab));
    let (ac_a, ac_c) = (dot(pa, ac), -dot(pc, ac));
    let (bc_b, bc_c) = (dot(pb, bc), -dot(pc, bc));

    // Vertex regions: p projects behind the vertex along both of its edges.
    if ab_a <= 0.0 && ac_a <= 0.0 {
        return [1.0, 0.0, 0.0];
    }
    if ab_b <= 0.0 && bc_b <= 0.0 {
        return [0.0, 1.0, 0.0];
    }
    if ac_c <= 0.0 && bc_c <= 0.0 {
        return [0.0, 0.0, 1.0];
    }

    // Barycentric coordinates of p's projection onto the plane, times |n|² (n = ab × ac):
    // `n·((b - p) × (c - p))` is |n| times twice the signed area of the sub-triangle the
    // projection forms with the opposite edge bc, and likewise for b and c.
    let n = cross(ab, ac);
    let wa = dot(n, cross(pb, pc));
    let wb = dot(n, cross(pc, pa));
    let wc = dot(n, cross(pa, pb));

    // Edge slabs: p is beyond the edge's line (the opposite coordinate is <= 0) and projects
    // between its ends. The foot splits the edge in the ratio of the two projections.
    if wc <= 0.0 && ab_a >= 0.0 && ab_b >= 0.0 {
        let s = ab_a + ab_b;
        return [ab_b / s, ab_a / s, 0.0];
    }
    if wb <= 0.0 && ac_a >= 0.0 && ac_c >= 0.0 {
        let s = ac_a + ac_c;
        return [ac_c / s, 0.0, ac_a / s];
    }
    if wa <= 0.0 && bc_b >= 0.0 && bc_c >= 0.0 {
        let s = bc_b + bc_c;
        return [0.0, bc_c / s, bc_b / s];
    }

    // The face prism: all three coordinates are positive in exact arithmetic. Clamping only
    // guards against rounding on a region boundary, and keeps the weights >= 0.
    let w = [wa, wb, wc].map(|x| x.max(0.0));
    let s = w[0] + w[1] + w[2];
    w.map(|x| x / s)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::algorithms::geometry::{add, tet_signed_volume};

    use crate::support::testing::Rng;

    /// The draws these tests make beyond the shared generator's.
    trait Draws {
        fn index(&mut self, n: usize) -> usize;
        fn point(&mut self, lo: Point, hi: Point) -> Point;
        /// `N` non-negative weights summing to 1.
        fn weights<const N: usize>(&mut self) -> [f64; N];
    }

    impl Draws for Rng {
        fn index(&mut self, n: usize) -> usize {
            (self.next_u64() % n as u64) as usize
        }

        fn point(&mut self, lo: Point, hi: Point) -> Point {
            std::array::from_fn(|d| self.uniform(lo[d], hi[d]))
        }

        fn weights<const N: usize>(&mut self) -> [f64; N] {
            let w: [f64; N] = std::array::from_fn(|_| self.uniform(0.01, 1.0));
            let s: f64 = w.iter().sum();
            w.map(|x| x / s)
        }
    }

    /// A `cells` grid of cubes of side `h` from `origin`, each cube split into the 6 tets of
    /// its Kuhn (Freudenthal) triangulation, which conforms across cubes. Every vertex is then
    /// moved by up to `jitter * h` per axis (0.1 keeps all volumes positive).
    fn grid(cells: [usize; 3], origin: Point, h: f64, jitter: f64, rng: &mut Rng) -> TetMesh {
        let [nx, ny, nz] = cells;
        let id = |c: [usize; 3]| (c[0] + (nx + 1) * (c[1] + (ny + 1) * c[2])) as u32;
        let mut positions = Vec::new();
        for k in 0..=nz {
            for j in 0..=ny {
                for i in 0..=nx {
                    let x = [i, j, k].map(|c| c as f64 * h);
                    positions.push(std::array::from_fn(|d| origin[d] + x[d] + jitter * h * rng.uniform(-1.0, 1.0)));
                }
            }
        }
        let mut tets = Vec::new();
        for k in 0..nz {
            for j in 0..ny {
                for i in 0..nx {
                    for axes in [[0, 1, 2], [0, 2, 1], [1, 0, 2], [1, 2, 0], [2, 0, 1], [2, 1, 0]] {
                        // The path 000 -> 111 stepping along the axes in this order.
                        let mut c = [i, j, k];
                        let mut tet = [id(c); 4];
                        for (s, axis) in axes.into_iter().enumerate() {
                            c[axis] += 1;
                            tet[s + 1] = id(c);
                        }
                        tets.push(tet);
                    }
                }
            }
        }
        let mut mesh = TetMesh { positions, tets };
        mesh.orient_positive();
        for t in 0..mesh.tets.len() {
            assert!(mesh.signed_volume_at(&mesh.positions, t) > 0.0, "test mesh tet {t} is degenerate");
        }
        mesh
    }

    fn jittered_grid(cells: [usize; 3], seed: u64) -> TetMesh {
        grid(cells, [-0.3, 0.2, 1.0], 0.25, 0.1, &mut Rng::new(seed))
    }

    /// A fixed rotation, so that points built on rotated features are only on them up to
    /// rounding.
    fn rotate(x: Point) -> Point {
        let (s, c) = (0.6, 0.8);
        let y = [c * x[0] - s * x[1], s * x[0] + c * x[1], x[2]];
        [y[0], c * y[1] - s * y[2], s * y[1] + c * y[2]]
    }

    fn corners(mesh: &TetMesh, t: u32) -> [Point; 4] {
        tet_at(mesh, t).1
    }

    /// Points of every kind, `total` in all: mesh vertices, points on tet edges and faces,
    /// inside tets, and in a box around the mesh (many of them outside), a few far away.
    fn mixed_points(mesh: &TetMesh, total: usize, rng: &mut Rng) -> Vec<Point> {
        let n = mesh.tets.len();
        let mut points = mesh.positions.clone();
        for _ in 0..total / 14 {
            let x = corners(mesh, rng.index(n) as u32);
            let (i, j) = (rng.index(4), rng.index(3));
            let j = if j >= i { j + 1 } else { j };
            let t = rng.uniform(0.0, 1.0);
            points.push(std::array::from_fn(|d| (1.0 - t) * x[i][d] + t * x[j][d]));
        }
        for _ in 0..total / 7 {
            let x = corners(mesh, rng.index(n) as u32);
            let face = FACES[rng.index(4)];
            let w: [f64; 3] = rng.weights();
            points.push(std::array::from_fn(|d| (0..3).map(|k| w[k] * x[face[k]][d]).sum()));
        }
        for _ in 0..total * 3 / 7 {
            points.push(combine(corners(mesh, rng.index(n) as u32), rng.weights()));
        }
        let Bounds { lo, hi } = Bounds::of(&mesh.positions);
        let margin = 0.3 * norm(sub(hi, lo));
        for _ in 0..total / 50 {
            points.push(rng.point(lo.map(|c| c - 10.0 * margin), hi.map(|c| c + 10.0 * margin)));
        }
        while points.len() < total {
            points.push(rng.point(lo.map(|c| c - margin), hi.map(|c| c + margin)));
        }
        points
    }

    /// The reference: the same rules as the BVH queries, applied to every tet of `mesh`.
    /// Returns the binding and how many tets tied for it.
    fn brute_force(mesh: &TetMesh, p: Point) -> (Located, usize) {
        let tets = 0..mesh.tets.len() as u32;
        let containing: Vec<Located> = tets
            .clone()
            .filter_map(|t| {
                let (ids, corners) = tet_at(mesh, t);
                let weights = barycentric(p, ids, corners);
                is_contained(weights).then_some(Located { tet: t, weights, distance: 0.0 })
            })
            .collect();
        if let Some(&first) = containing.first() {
            return (first, containing.len());
        }
        let nearest: Vec<Located> = tets
            .map(|t| {
                let (ids, corners) = tet_at(mesh, t);
                let (weights, distance) = closest_on_tet(p, ids, corners);
                Located { tet: t, weights, distance }
            })
            .collect();
        let d_min = nearest.iter().map(|l| l.distance).fold(f64::INFINITY, f64::min);
        let mut tied = nearest.into_iter().filter(|l| l.distance == d_min);
        let first = tied.next().expect("some tet is nearest");
        (first, 1 + tied.count())
    }

    fn distance(a: Point, b: Point) -> f64 {
        norm(sub(a, b))
    }

    /// `q` is the projection of `p` onto the convex hull of `vertices` (given `q` is in it) iff
    /// `(p - q)·(x - q) <= 0` for every vertex `x`.
    fn assert_projection(p: Point, q: Point, vertices: &[Point], tol: f64) {
        for &x in vertices {
            let g = dot(sub(p, q), sub(x, q));
            assert!(g <= tol, "not the closest point: p {p:?} q {q:?} vertex {x:?}: {g}");
        }
    }

    fn assert_weights_valid(w: &[f64], outside: bool) {
        let sum: f64 = w.iter().sum();
        assert!((sum - 1.0).abs() <= 1e-12, "weights {w:?} sum to {sum}");
        let floor = if outside { 0.0 } else { -EPS };
        assert!(w.iter().all(|&x| x >= floor), "weights {w:?} below {floor}");
    }

    #[test]
    fn closest_on_triangle_picks_each_voronoi_region() {
        let tri = [[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 2.0, 0.0]];
        let cases: [(Point, [f64; 3]); 8] = [
            ([-1.0, -1.0, 1.0], [1.0, 0.0, 0.0]),  // vertex a
            ([3.0, -1.0, -2.0], [0.0, 1.0, 0.0]),  // vertex b
            ([-1.0, 3.0, 5.0], [0.0, 0.0, 1.0]),   // vertex c
            ([1.5, -1.0, 2.0], [0.25, 0.75, 0.0]), // edge ab, foot (1.5, 0, 0)
            ([-1.0, 0.5, 0.0], [0.75, 0.0, 0.25]), // edge ac, foot (0, 0.5, 0)
            ([2.0, 1.0, -1.0], [0.0, 0.75, 0.25]), // edge bc, foot (1.5, 0.5, 0)
            ([0.5, 1.0, 3.0], [0.25, 0.25, 0.5]),  // face, foot (0.5, 1, 0)
            ([0.5, 1.0, 0.0], [0.25, 0.25, 0.5]),  // in the triangle itself
        ];
        for (p, expected) in cases {
            let w = closest_on_triangle(p, tri);
            for k in 0..3 {
                assert!((w[k] - expected[k]).abs() <= 1e-15, "p {p:?}: {w:?} != {expected:?}");
            }
        }
    }

    #[test]
    fn closest_on_triangle_edges_and_vertices_ignore_vertex_order() {
        let mut rng = Rng::new(17);
        let mut on_features = 0;
        for _ in 0..20_000 {
            let tri: [Point; 3] = std::array::from_fn(|_| rng.point([-1.0; 3], [1.0; 3]));
            let p = rng.point([-3.0; 3], [3.0; 3]);
            let w = closest_on_triangle(p, tri);
            if !w.contains(&0.0) {
                continue; // face interior: shared faces are inside the mesh, never nearest
            }
            on_features += 1;
            for perm in [[0, 2, 1], [1, 0, 2], [1, 2, 0], [2, 0, 1], [2, 1, 0]] {
                let permuted = closest_on_triangle(p, perm.map(|k| tri[k]));
                assert_eq!(permuted, perm.map(|k| w[k]), "p {p:?} triangle {tri:?}");
            }
        }
        assert!(on_features > 10_000);
    }

    #[test]
    fn closest_on_triangle_is_the_projection() {
        let mut rng = Rng::new(7);
        for _ in 0..20_000 {
            let tri: [Point; 3] = std::array::from_fn(|_| rng.point([-1.0; 3], [1.0; 3]));
            if norm(cross(sub(tri[1], tri[0]), sub(tri[2], tri[0]))) < 1e-3 {
                continue;
            }
            let p = rng.point([-3.0; 3], [3.0; 3]);
            let w = closest_on_triangle(p, tri);
            assert_weights_valid(&w, true);
            let q: Point = std::array::from_fn(|d| w[0] * tri[0][d] + w[1] * tri[1][d] + w[2] * tri[2][d]);
            assert_projection(p, q, &tri, 1e-12);
        }
    }

    #[test]
    fn closest_on_tet_is_the_projection() {
        let mut rng = Rng::new(11);
        let ids = [4, 9, 2, 7];
        let (mut inside, mut outside) = (0, 0);
        for _ in 0..20_000 {
            let mut x: [Point; 4] = std::array::from_fn(|_| rng.point([-1.0; 3], [1.0; 3]));
            let volume = tet_signed_volume(x[0], x[1], x[2], x[3]);
            if volume.abs() < 1e-2 {
                continue;
            }
            if volume < 0.0 {
                x.swap(2, 3);
            }
            // Around the tet, in and out.
            let offset = rng.point([-0.5; 3], [0.5; 3]);
            let p = add(combine(x, rng.weights()), offset);
            let (w, d) = closest_on_tet(p, ids, x);
            let q = combine(x, w);
            if d == 0.0 {
                inside += 1;
                assert_weights_valid(&w, true);
                assert!(distance(p, q) <= 1e-14);
            } else {
                outside += 1;
                assert_weights_valid(&w, true);
                assert_eq!(d, distance(p, q));
                assert!(w.contains(&0.0), "the closest point of an outside point is on a face");
                assert_projection(p, q, &x, 1e-12);
            }
        }
        assert!(inside > 100 && outside > 100);
    }

    #[test]
    fn face_orientation_is_exactly_antisymmetric() {
        // Two tets sharing a face see it in opposite orientations, in any vertex order: their
        // sub-volumes for it must be exact negatives, or a point on the face could be outside
        // both.
        let mut rng = Rng::new(3);
        let ids = [17, 3, 42];
        let perms = [([0, 1, 2], 1.0), ([1, 2, 0], 1.0), ([2, 0, 1], 1.0), ([1, 0, 2], -1.0), ([0, 2, 1], -1.0), ([2, 1, 0], -1.0)];
        for _ in 0..1000 {
            let x: [Point; 3] = std::array::from_fn(|_| rng.point([-1.0; 3], [1.0; 3]));
            let w: [f64; 3] = rng.weights();
            // On the face, up to rounding.
            let p: Point = std::array::from_fn(|d| w[0] * x[0][d] + w[1] * x[1][d] + w[2] * x[2][d]);
            let reference = face_orientation(p, [0, 1, 2].map(|k| (ids[k], x[k])));
            for (perm, sign) in perms {
                assert_eq!(face_orientation(p, perm.map(|k| (ids[k], x[k]))), sign * reference);
            }
        }
    }

    #[test]
    fn vertices_get_unit_weight_in_lowest_incident_tet() {
        let mesh = jittered_grid([3, 3, 3], 1);
        let binding = Binding::compute(&mesh, &mesh.positions);
        for (v, p) in mesh.positions.iter().enumerate() {
            let lowest = mesh.tets.iter().position(|tet| tet.contains(&(v as u32))).unwrap();
            assert_eq!(binding.tets[v] as usize, lowest, "vertex {v}");
            assert_eq!(binding.distances[v], 0.0);
            for (&w, &corner) in binding.weights[v].iter().zip(&mesh.tets[lowest]) {
                let expected = if corner as usize == v { 1.0 } else { 0.0 };
                assert!((w - expected).abs() <= 1e-12, "vertex {v} at {p:?}");
            }
        }
    }

    #[test]
    fn centroids_get_quarter_weights() {
        let mesh = jittered_grid([3, 3, 3], 2);
        let centroids: Vec<Point> = (0..mesh.tets.len()).map(|t| combine(corners(&mesh, t as u32), [0.25; 4])).collect();
        let binding = Binding::compute(&mesh, &centroids);
        for t in 0..mesh.tets.len() {
            assert_eq!(binding.tets[t] as usize, t);
            assert_eq!(binding.distances[t], 0.0);
            assert!(binding.weights[t].iter().all(|w| (w - 0.25).abs() <= 1e-12), "{:?}", binding.weights[t]);
        }
    }

    #[test]
    fn inside_points_are_reproduced() {
        let mesh = jittered_grid([4, 3, 5], 3);
        let mut rng = Rng::new(4);
        let points: Vec<Point> = (0..5000).map(|_| combine(corners(&mesh, rng.index(mesh.tets.len()) as u32), rng.weights())).collect();
        let binding = Binding::compute(&mesh, &points);
        let carried = binding.apply(&mesh, &mesh.positions);
        let tol = 1e-12 * length_scale(&mesh);
        for (i, p) in points.iter().enumerate() {
            assert_eq!(binding.distances[i], 0.0);
            assert_weights_valid(&binding.weights[i], false);
            assert!(distance(carried[i], *p) <= tol, "point {i}: {:?} != {p:?}", carried[i]);
        }
    }

    #[test]
    fn outside_points_project_onto_a_convex_mesh() {
        // An unjittered grid fills the box [lo, hi]: the closest point of the mesh to an
        // outside point is the box clamp, known independently of any tet.
        let (lo, h, cells) = ([1.0, -2.0, 0.5], 0.5, [3, 4, 5]);
        let hi: Point = std::array::from_fn(|d| lo[d] + h * cells[d] as f64);
        let mesh = grid(cells, lo, h, 0.0, &mut Rng::new(0));
        let mut rng = Rng::new(5);
        let points: Vec<Point> = std::iter::repeat_with(|| rng.point(lo.map(|c| c - 1.0), hi.map(|c| c + 1.0)))
            .filter(|p| !Bounds { lo, hi }.contains(*p))
            .take(5000)
            .collect();
        let binding = Binding::compute(&mesh, &points);
        let carried = binding.apply(&mesh, &mesh.positions);
        let tol = 1e-12 * length_scale(&mesh);
        for (i, &p) in points.iter().enumerate() {
            let clamp: Point = std::array::from_fn(|d| p[d].clamp(lo[d], hi[d]));
            let (reference, _) = brute_force(&mesh, p);
            assert_weights_valid(&binding.weights[i], true);
            assert!((binding.distances[i] - distance(p, clamp)).abs() <= tol, "point {i}");
            assert!((binding.distances[i] - reference.distance).abs() <= tol, "point {i}");
            assert!(distance(carried[i], clamp) <= tol, "point {i}: {:?} != {clamp:?}", carried[i]);
        }
    }

    #[test]
    fn containment_tolerance_is_eps_in_barycentric_coordinates() {
        // Points on the faces of an axis-aligned box of tets, pushed out through them: by a
        // tenth of EPS (relative to the tet size) they are still in the mesh; by ten EPS they
        // are outside, at the push distance. The first also lie outside every unpadded tet box.
        let (lo, h, cells) = ([1.0, -2.0, 0.5], 0.5, [3, 2, 2]);
        let hi: Point = std::array::from_fn(|d| lo[d] + h * cells[d] as f64);
        let mesh = grid(cells, lo, h, 0.0, &mut Rng::new(0));
        let mut rng = Rng::new(18);
        for push in [0.1 * EPS * h, 10.0 * EPS * h] {
            let points: Vec<Point> = (0..600)
                .map(|k| {
                    let mut p = rng.point(lo, hi);
                    let axis = k % 3;
                    p[axis] = if k % 2 == 0 { lo[axis] - push } else { hi[axis] + push };
                    p
                })
                .collect();
            let binding = Binding::compute(&mesh, &points);
            for (i, &p) in points.iter().enumerate() {
                assert_eq!(brute_force(&mesh, p).0.tet, binding.tets[i]);
                if push < EPS * h {
                    assert_eq!(binding.distances[i], 0.0, "point {i} at {p:?}");
                } else {
                    assert!((binding.distances[i] - push).abs() <= 1e-3 * push, "point {i} at {p:?}");
                }
            }
        }
    }

    #[test]
    fn affine_maps_are_reproduced() {
        let mesh = jittered_grid([3, 4, 3], 6);
        let mut rng = Rng::new(8);
        let points = mixed_points(&mesh, 3000, &mut rng);
        let binding = Binding::compute(&mesh, &points);
        let a = [[1.2, 0.3, -0.1], [0.05, 0.9, 0.4], [-0.2, 0.1, 1.1]];
        let b = [0.5, -1.0, 2.0];
        let map = |x: Point| -> Point { std::array::from_fn(|r| dot(a[r], x) + b[r]) };
        let moved: Vec<Point> = mesh.positions.iter().map(|&x| map(x)).collect();
        let carried = binding.apply(&mesh, &moved);
        let at_rest = binding.apply(&mesh, &mesh.positions);
        let tol = 1e-12 * length_scale(&TetMesh { positions: moved.clone(), tets: mesh.tets.clone() });
        for (i, &p) in points.iter().enumerate() {
            // Inside, the carried point is the mapped point; everywhere (weights sum to 1) it is
            // the mapped carried rest point.
            if binding.distances[i] == 0.0 {
                assert!(distance(carried[i], map(p)) <= tol, "point {i}");
            }
            assert!(distance(carried[i], map(at_rest[i])) <= tol, "point {i}");
        }
    }

    #[test]
    fn compute_is_deterministic_across_runs_and_thread_counts() {
        let mesh = jittered_grid([4, 4, 4], 9);
        let points = mixed_points(&mesh, 6000, &mut Rng::new(10));
        let first = Binding::compute(&mesh, &points);
        assert_eq!(first, Binding::compute(&mesh, &points));
        for threads in [1, 3] {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            assert_eq!(first, pool.install(|| Binding::compute(&mesh, &points)), "{threads} threads");
        }
    }

    #[test]
    fn empty_point_list_gives_empty_binding() {
        let mesh = jittered_grid([1, 1, 1], 12);
        let empty = Binding { tets: vec![], weights: vec![], distances: vec![] };
        assert_eq!(Binding::compute(&mesh, &[]), empty);
        assert_eq!(Binding::compute(&TetMesh::default(), &[]), empty);
        assert!(empty.apply(&mesh, &mesh.positions).is_empty());
    }

    #[test]
    #[should_panic(expected = "without tets")]
    fn points_need_tets() {
        Binding::compute(&TetMesh::default(), &[[0.0; 3]]);
    }

    #[test]
    fn point_on_shared_face_goes_to_lowest_index() {
        // Two tets on either side of the face (a, b, c), tilted so that points on it are only
        // on it up to rounding.
        let positions: Vec<Point> = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.2, 0.3, 1.0], [0.3, 0.2, -1.0]].map(rotate).to_vec();
        let above = [0, 1, 2, 3];
        let below = [0, 2, 1, 4];
        let mut rng = Rng::new(13);
        let on_face: Vec<Point> = (0..200)
            .map(|_| {
                let w: [f64; 3] = rng.weights();
                std::array::from_fn(|d| (0..3).map(|k| w[k] * positions[k][d]).sum())
            })
            .collect();
        for (tets, lower_apex) in [(vec![above, below], 3), (vec![below, above], 4)] {
            let mesh = TetMesh { positions: positions.clone(), tets };
            assert!((0..2).all(|t| mesh.signed_volume_at(&mesh.positions, t) > 0.0));
            let binding = Binding::compute(&mesh, &on_face);
            let carried = binding.apply(&mesh, &mesh.positions);
            for (i, &p) in on_face.iter().enumerate() {
                // A genuine tie: both tets contain the point.
                for t in 0..2 {
                    assert!(is_contained(barycentric(p, mesh.tets[t], corners(&mesh, t as u32))));
                }
                assert_eq!(binding.tets[i], 0);
                assert_eq!(binding.distances[i], 0.0);
                let apex = mesh.tets[0].iter().position(|&v| v == lower_apex).unwrap();
                assert!(binding.weights[i][apex].abs() <= 1e-12);
                assert!(distance(carried[i], p) <= 1e-15);
            }
        }
    }

    #[test]
    fn point_nearest_a_shared_boundary_edge_goes_to_lowest_index() {
        // A rotated box of Kuhn cubes: each segment of its edge along x through the origin is
        // shared by two tets of the same cube, which tie for the points nearest to it.
        let mut mesh = grid([4, 3, 3], [0.0; 3], 0.5, 0.0, &mut Rng::new(0));
        mesh.positions = mesh.positions.iter().map(|&x| rotate(x)).collect();
        // Vary each tet's vertex order (by even permutations, keeping volumes positive), as a
        // mesher would: tets sharing an edge then list it in different orders.
        let mut rng = Rng::new(16);
        for tet in &mut mesh.tets {
            let [a, b, c, d] = *tet;
            *tet = [[a, b, c, d], [b, c, a, d], [c, a, b, d], [b, a, d, c], [d, c, b, a], [a, d, b, c]][rng.index(6)];
        }
        for segment in 0..4u32 {
            let ends = [segment, segment + 1]; // grid vertices (segment, 0, 0) and (segment + 1, 0, 0)
            let around: Vec<u32> = (0..mesh.tets.len() as u32).filter(|&t| ends.iter().all(|v| mesh.tets[t as usize].contains(v))).collect();
            assert_eq!(around.len(), 2);
            assert!((0..2).all(|t| mesh.signed_volume_at(&mesh.positions, around[t] as usize) > 0.0));
            let points: Vec<Point> = (0..100)
                .map(|_| {
                    let x = 0.5 * (segment as f64 + rng.uniform(0.01, 0.99));
                    rotate([x, -rng.uniform(0.01, 1.0), -rng.uniform(0.01, 1.0)])
                })
                .collect();
            let binding = Binding::compute(&mesh, &points);
            for (i, &p) in points.iter().enumerate() {
                assert_eq!(brute_force(&mesh, p).1, 2, "both tets are exactly as near");
                assert_eq!(binding.tets[i], around[0]);
                for (&w, corner) in binding.weights[i].iter().zip(&mesh.tets[around[0] as usize]) {
                    if !ends.contains(corner) {
                        assert_eq!(w, 0.0, "weight off the edge");
                    }
                }
            }
        }
    }

    /// The paper's scale (28,098 points, 1,192 tets): 28,098 points of every kind in a
    /// jittered 5 x 6 x 7 grid of 1,260 tets, against the search over all tets.
    #[test]
    fn matches_brute_force_at_paper_scale() {
        let mesh = jittered_grid([5, 6, 7], 14);
        assert_eq!(mesh.tets.len(), 1260);
        let points = mixed_points(&mesh, 28_098, &mut Rng::new(15));
        assert_eq!(points.len(), 28_098);
        // Mesh vertices, edge, face and inside points come first, by construction of
        // `mixed_points`; all of them are in the mesh.
        let generated_inside = mesh.positions.len() + 28_098 / 14 + 28_098 / 7 + 28_098 * 3 / 7;

        let binding = Binding::compute(&mesh, &points);
        let carried = binding.apply(&mesh, &mesh.positions);
        let scale = length_scale(&mesh);
        let tol = 1e-12 * scale;
        let reference: Vec<(Located, usize)> = points.par_iter().map(|&p| brute_force(&mesh, p)).collect();
        let (mut outside, mut outside_ties) = (0, 0);
        for (i, &p) in points.iter().enumerate() {
            let found = Located { tet: binding.tets[i], weights: binding.weights[i], distance: binding.distances[i] };
            let (expected, ties) = reference[i];
            assert_eq!(found, expected, "point {i} at {p:?}");
            let w = &binding.weights[i];
            if i < generated_inside {
                assert_eq!(found.distance, 0.0, "point {i} was generated in the mesh");
            }
            if found.distance == 0.0 {
                assert_weights_valid(w, false);
                assert!(distance(carried[i], p) <= tol, "point {i}");
            } else {
                outside += 1;
                assert_weights_valid(w, true);
                assert_eq!(distance(p, carried[i]), found.distance);
                assert_projection(p, carried[i], &corners(&mesh, found.tet), tol * scale);
                if ties > 1 {
                    outside_ties += 1;
                }
            }
        }
        // The data exercise both queries and the tie rule away from the mesh.
        assert!(outside > 3000, "{outside} outside points");
        assert!(outside_ties > 100, "{outside_ties} outside points with tied tets");
    }
}
