//! An automatic cage: a coarse tet body around a surface that is too fine or too messy to
//! simulate directly (the paper bakes its characters on coarse tet cages, e.g. 922 nodes
//! around a 6.7k-vertex surface). The caller poses it from the fine keyframes ([`fit`]) and
//! embeds the fine surface in it.
//!
//! # Algorithm ([`voxel_cage`])
//!
//! 1. A solid that encloses the surface, whatever its defects, on a grid of cubes of side `h`:
//!    a cube belongs to the cage when its centre is inside the surface (generalized winding
//!    number at least ½: open, multi-part, non-manifold and self-intersecting surfaces all
//!    have one) or the surface comes within the cube's circumscribed sphere (distance from the
//!    centre at most `h √3 / 2`), or it holds one of the points that must be embedded. Every
//!    point of the surface is then inside a cage cube, so the cage encloses the surface by
//!    construction, and thin parts, open sheets and small gaps are covered.
//! 2. Every cube is split into the six tets of its Kuhn triangulation, which conform across
//!    cubes: a valid, positively oriented tet mesh whose tets all have the same good shape.
//! 3. `h` is chosen so that the cage has about the target number of nodes (a few rounds of
//!    `h ← h (nodes / target)^(1/3)`, keeping the closest).
//!
//! Why a voxel body and not a simplified surface meshed by TetGen: that route was built and
//! measured first (marching tetrahedra on the offset solid, quadric simplification kept
//! 2-manifold and unfolded, a crossing check). Its simplified surfaces kept sliver triangles
//! along curved features (worst triangle quality 0.005 on an offset prism), TetGen turned them
//! into tets of volume 1e-8 of a typical one, and their stiffness made the posed keys and the
//! solve fail (initial W 1e5 times the direct body's). A quality-preserving simplifier got
//! stuck far above the target. The voxel body has no slivers by construction, needs no
//! external process, hits its node budget directly, and its staircase boundary costs little:
//! the fine surface, not the cage, is what is exported. (The `meshopt` simplifier would not
//! have helped here: it needs a C++ build and guarantees neither closedness nor triangle
//! quality on these inputs.)

pub mod fit;
pub(crate) mod tree;

use rayon::prelude::*;

use crate::algorithms::geometry::{Bounds, Point, TetMesh, TriMesh};
use tree::TriangleTree;

/// What is wrong with a surface for direct tetrahedralization.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub(crate) struct Defects {
    /// Edges used by one triangle.
    pub open_edges: usize,
    /// Edges used by more than two triangles.
    pub nonmanifold_edges: usize,
    /// Edge-connected parts.
    pub parts: usize,
    /// A pair of triangles that share no vertex and cross, when checked.
    pub crossing: Option<(usize, usize)>,
}

impl Defects {
    /// The defects of `surface`; crossings are looked for when `crossings` (it costs a tree
    /// query per triangle).
    pub fn of(surface: &TriMesh, crossings: bool) -> Defects {
        let mut edges: Vec<[u32; 2]> =
            surface.triangles.iter().flat_map(|t| (0..3).map(move |k| [t[k].min(t[(k + 1) % 3]), t[k].max(t[(k + 1) % 3])])).collect();
        edges.sort_unstable();
        let (mut open_edges, mut nonmanifold_edges) = (0, 0);
        for group in edges.chunk_by(|a, b| a == b) {
            match group.len() {
                1 => open_edges += 1,
                2 => {}
                _ => nonmanifold_edges += 1,
            }
        }
        // Parts: union-find over the triangles' vertices.
        let mut parent: Vec<u32> = (0..surface.positions.len() as u32).collect();
        fn find(parent: &mut [u32], mut v: u32) -> u32 {
            while parent[v as usize] != v {
                parent[v as usize] = parent[parent[v as usize] as usize];
                v = parent[v as usize];
            }
            v
        }
        for t in &surface.triangles {
            for k in 1..3 {
                let (a, b) = (find(&mut parent, t[0]), find(&mut parent, t[k]));
                if a != b {
                    parent[a.max(b) as usize] = a.min(b);
                }
            }
        }
        let mut roots: Vec<u32> = surface.triangles.iter().map(|t| find(&mut parent, t[0])).collect();
        roots.sort_unstable();
        roots.dedup();
        let crossing = if crossings { TriangleTree::new(surface).crossing_pair() } else { None };
        Defects { open_edges, nonmanifold_edges, parts: roots.len(), crossing }
    }

    /// The defects in words, or `None` for a closed, 2-manifold, one-part surface without
    /// crossings.
    pub fn describe(&self) -> Option<String> {
        let mut said = Vec::new();
        if self.open_edges > 0 {
            said.push(format!("open ({} open edges)", self.open_edges));
        }
        if self.nonmanifold_edges > 0 {
            said.push(format!("non-manifold ({} edges with more than two triangles)", self.nonmanifold_edges));
        }
        if self.parts > 1 {
            said.push(format!("in {} parts", self.parts));
        }
        if let Some((s, t)) = self.crossing {
            said.push(format!("self-intersecting (triangles {s} and {t} cross)"));
        }
        (!said.is_empty()).then(|| said.join(", "))
    }
}

/// A generated cage.
#[derive(Debug, Clone)]
pub struct Cage {
    /// The tet body: Kuhn tets of the cage cubes, positively oriented.
    pub mesh: TetMesh,
    /// The side of the cubes.
    pub spacing: f64,
    /// Nodes on the cage's boundary.
    pub boundary_nodes: usize,
}

/// Why no cage could be made.
#[derive(Debug, Clone, PartialEq)]
pub enum CageError {
    /// The surface has no extent (no triangle, or all its vertices at one point).
    Empty,
}

/// Seconds [`voxel_cage`] is predicted to take for a surface of `triangles` triangles and a
/// cage of about `target` nodes, on the threads of the pool (for the progress bar's estimate;
/// measured by `cargo bench --bench demo -- models`): the triangle tree, and the winding and
/// distance queries of up to four cube grids.
pub fn predicted_seconds(triangles: usize, target: usize) -> f64 {
    CAGE_SECONDS_PER_TRIANGLE * triangles as f64 + CAGE_SECONDS_PER_NODE * target as f64
}

/// The cost model of [`predicted_seconds`] (CPU seconds; measured on prisms of 200 to 120k
/// surface vertices, cages of 1000 nodes: 0.02 s to 0.25 s).
const CAGE_SECONDS_PER_TRIANGLE: f64 = 1e-6;
const CAGE_SECONDS_PER_NODE: f64 = 2e-5;

/// A voxel cage of about `target` nodes around `surface` that encloses `points` (see the
/// module documentation).
pub fn voxel_cage(surface: &TriMesh, points: &[Point], target: usize) -> Result<Cage, CageError> {
    let mut used = vec![false; surface.positions.len()];
    surface.triangles.iter().flatten().for_each(|&v| used[v as usize] = true);
    let vertices: Vec<Point> = surface.positions.iter().zip(&used).filter(|(_, &u)| u).map(|(p, _)| *p).collect();
    let bounds = Bounds::of(&vertices).union(Bounds::of(points));
    let sides: Point = std::array::from_fn(|d| bounds.hi[d] - bounds.lo[d]);
    let longest = sides.iter().fold(0.0f64, |m, &s| m.max(s));
    if surface.triangles.is_empty() || !longest.is_finite() || longest <= 0.0 {
        return Err(CageError::Empty);
    }
    let tree = TriangleTree::new(surface);
    // A first guess from the box: nodes ≈ cells, a third of the box solid.
    let volume: f64 = sides.iter().map(|&s| s.max(0.05 * longest)).product();
    let mut h = (volume / (3.0 * target as f64)).cbrt();
    let mut best: Option<Cage> = None;
    for _ in 0..4 {
        let cage = cubes(&tree, &bounds, points, h);
        let nodes = cage.mesh.positions.len();
        let error = |c: &Cage| (c.mesh.positions.len() as f64 / target as f64).ln().abs();
        if best.as_ref().is_none_or(|b| error(&cage) < error(b)) {
            best = Some(cage);
        }
        let ratio = nodes as f64 / target as f64;
        if (0.9..=1.1).contains(&ratio) {
            break;
        }
        h *= ratio.cbrt();
    }
    Ok(best.expect("at least one round"))
}

/// The cage of cubes of side `h` (see the module documentation, steps 1 and 2).
fn cubes(tree: &TriangleTree, bounds: &Bounds, points: &[Point], h: f64) -> Cage {
    // Cubes centred on the box's centre, one spare layer all around.
    let dims: [usize; 3] = std::array::from_fn(|d| ((bounds.hi[d] - bounds.lo[d]) / h).ceil() as usize + 2);
    let center = bounds.center();
    let origin: Point = std::array::from_fn(|d| center[d] - 0.5 * h * dims[d] as f64);
    let cell_count = dims[0] * dims[1] * dims[2];
    let cell_center = |c: usize| -> Point {
        let at = [c % dims[0], (c / dims[0]) % dims[1], c / (dims[0] * dims[1])];
        std::array::from_fn(|d| origin[d] + h * (at[d] as f64 + 0.5))
    };
    let reach = 0.5 * 3f64.sqrt() * h;
    let mut inside: Vec<bool> = (0..cell_count)
        .into_par_iter()
        .map(|c| {
            let x = cell_center(c);
            tree.distance(x, reach * 1.0001) <= reach || tree.winding(x) >= 0.5
        })
        .collect();
    for p in points {
        let at: [usize; 3] = std::array::from_fn(|d| (((p[d] - origin[d]) / h).floor().max(0.0) as usize).min(dims[d] - 1));
        inside[at[0] + dims[0] * (at[1] + dims[1] * at[2])] = true;
    }
    // Nodes: the corners of the cage's cubes, numbered in grid order.
    let corners = [dims[0] + 1, dims[1] + 1, dims[2] + 1];
    let corner = |i: usize, j: usize, k: usize| i + corners[0] * (j + corners[1] * k);
    let mut node_of = vec![u32::MAX; corners[0] * corners[1] * corners[2]];
    let mut tets = Vec::new();
    let kuhn = [[0, 1, 2], [0, 2, 1], [1, 0, 2], [1, 2, 0], [2, 0, 1], [2, 1, 0]];
    for c in (0..cell_count).filter(|&c| inside[c]) {
        let at = [c % dims[0], (c / dims[0]) % dims[1], c / (dims[0] * dims[1])];
        for axes in kuhn {
            let mut step = [0usize; 3];
            let mut tet = [0u32; 4];
            tet[0] = corner(at[0], at[1], at[2]) as u32;
            for (s, &axis) in axes.iter().enumerate() {
                step[axis] = 1;
                tet[s + 1] = corner(at[0] + step[0], at[1] + step[1], at[2] + step[2]) as u32;
            }
            tets.push(tet);
        }
    }
    tets.iter().flatten().for_each(|&g| node_of[g as usize] = 0);
    let mut positions = Vec::new();
    for (g, slot) in node_of.iter_mut().enumerate() {
        if *slot == 0 {
            *slot = positions.len() as u32;
            let at = [g % corners[0], (g / corners[0]) % corners[1], g / (corners[0] * corners[1])];
            positions.push(std::array::from_fn(|d| origin[d] + h * at[d] as f64));
        }
    }
    let tets: Vec<[u32; 4]> = tets.iter().map(|t| t.map(|g| node_of[g as usize])).collect();
    let mut mesh = TetMesh { positions, tets };
    mesh.orient_positive();
    let mut on_boundary = vec![false; mesh.positions.len()];
    crate::algorithms::geometry::surface::boundary(&mesh).iter().flatten().for_each(|&v| on_boundary[v as usize] = true);
    let boundary_nodes = on_boundary.iter().filter(|&&b| b).count();
    Cage { mesh, spacing: h, boundary_nodes }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::algorithms::procedural::{icosphere, prism};

    #[test]
    fn defects_are_counted() {
        let cube = prism([1.0; 3], [2, 2, 2]);
        assert_eq!(Defects::of(&cube, true), Defects { parts: 1, ..Defects::default() });
        assert_eq!(Defects::of(&cube, true).describe(), None);
        let mut open = cube.clone();
        open.triangles.pop();
        let d = Defects::of(&open, false);
        assert_eq!((d.open_edges, d.parts), (3, 1));
        let mut two = cube.clone();
        let n = cube.positions.len() as u32;
        two.positions.extend(cube.positions.iter().map(|p| [p[0] + 3.0, p[1], p[2]]));
        two.triangles.extend(cube.triangles.iter().map(|t| t.map(|v| v + n)));
        assert_eq!(Defects::of(&two, true).describe().unwrap(), "in 2 parts");
        let mut fin = cube.clone();
        fin.positions.push([0.5, 0.5, 2.0]);
        let t = fin.triangles[0];
        fin.triangles.push([t[0], t[1], n]);
        assert!(Defects::of(&fin, false).describe().unwrap().contains("non-manifold (1 edges"));
    }

    /// Every point must lie in a cage tet (binding distance 0).
    fn assert_encloses(cage: &Cage, points: &[Point]) {
        let binding = crate::algorithms::embed::Binding::compute(&cage.mesh, points);
        let worst = binding.distances.iter().fold(0.0f64, |m, &d| m.max(d));
        assert_eq!(worst, 0.0, "a point lies outside the cage");
    }

    #[test]
    fn a_sphere_gets_an_enclosing_cage_of_about_the_target_size() {
        let sphere = icosphere(4);
        let cage = voxel_cage(&sphere, &sphere.positions, 500).unwrap();
        let n = cage.mesh.positions.len();
        assert!((350..=650).contains(&n), "{n} nodes");
        assert_encloses(&cage, &sphere.positions);
        // Tight: within a cube diagonal and a half of the unit sphere.
        let radius = cage.mesh.positions.iter().map(|&p| crate::algorithms::geometry::norm(p)).fold(0.0, f64::max);
        assert!(radius < 1.0 + 2.0 * 3f64.sqrt() * cage.spacing, "{radius} vs spacing {}", cage.spacing);
        assert!((0..cage.mesh.tets.len()).all(|t| cage.mesh.signed_volume_at(&cage.mesh.positions, t) > 0.0));
        // Deterministic.
        assert_eq!(voxel_cage(&sphere, &sphere.positions, 500).unwrap().mesh, cage.mesh);
    }

    #[test]
    fn an_open_bowl_and_a_loose_sheet_are_enclosed_and_the_bowl_is_filled() {
        let sphere = icosphere(3);
        let mut messy = sphere.clone();
        messy.triangles.retain(|t| t.iter().all(|&v| sphere.positions[v as usize][1] <= 0.3));
        let n = messy.positions.len() as u32;
        messy.positions.extend([[-0.5, 1.2, -0.5], [0.5, 1.2, -0.5], [0.0, 1.2, 0.5]]);
        messy.triangles.push([n, n + 1, n + 2]);
        let used: Vec<Point> = messy.triangles.iter().flatten().map(|&v| messy.positions[v as usize]).collect();
        let cage = voxel_cage(&messy, &used, 400).unwrap();
        assert_encloses(&cage, &used);
        // The bowl's inside has winding number above ½, so its centre is in the cage.
        assert_encloses(&cage, &[[0.0, -0.3, 0.0]]);
    }
}
