//! An automatic cage: a coarse, closed, non-self-intersecting surface around a surface that is
//! too fine or too messy to simulate directly (the paper bakes its characters on coarse tet
//! cages, e.g. 922 nodes around a 6.7k-vertex surface). The caller tetrahedralizes the cage,
//! poses it from the fine keyframes ([`fit`]) and embeds the fine surface in it.
//!
//! # Algorithm ([`cage_surface`])
//!
//! 1. A solid that encloses the surface, whatever its defects: on a regular grid ([`CELLS`]
//!    cells along the longest side), the signed distance to the surface whose sign is the
//!    generalized winding number (inside where it is at least ½: open, multi-part,
//!    non-manifold and self-intersecting surfaces all have one), offset outward by `offset`:
//!    `f = ±distance - offset`. Every point within `offset` of the surface is inside, so thin
//!    parts, open sheets and small gaps are enclosed.
//! 2. Its boundary `f = 0` by marching tetrahedra ([`contour`]): closed, 2-manifold, free of
//!    self-intersections by construction.
//! 3. Quadric-error simplification to the vertex target, moving the surface by at most half the
//!    offset ([`simplify`]), then checked for crossing triangles ([`tree`]); a crossing
//!    result is simplified again less aggressively.
//! 4. Checked to enclose every point that must be embedded (winding number of the cage at
//!    least ½); otherwise the offset grows by half and the cage is rebuilt.
//!
//! Why this and not a library simplifier of the raw surface: the raw surface may be open or
//! self-intersecting, and a simplified surface is only useful to TetGen when it is closed and
//! free of crossings; building the cage from a volume makes the first true by construction and
//! the second a check. (The `meshopt` simplifier was not adopted: it needs a C++ build, and
//! guarantees neither property on these inputs.)

mod contour;
pub mod fit;
mod simplify;
pub(crate) mod tree;

use rayon::prelude::*;

use crate::mesh::{cross, norm, sub, Bounds, Point, TriMesh};
use contour::Grid;
use tree::TriangleTree;

/// Grid cells along the longest side of the surface's box for the enclosing solid.
pub const CELLS: usize = 48;

/// What is wrong with a surface for direct tetrahedralization.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Defects {
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
        let mut edges: Vec<[u32; 2]> = surface
            .triangles
            .iter()
            .flat_map(|t| (0..3).map(move |k| [t[k].min(t[(k + 1) % 3]), t[k].max(t[(k + 1) % 3])]))
            .collect();
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

/// A cage surface and how it was made.
#[derive(Debug, Clone)]
pub struct CageSurface {
    /// Closed, 2-manifold, no crossing triangles, outward wound, enclosing the points.
    pub surface: TriMesh,
    /// How far the solid reaches beyond the input surface.
    pub offset: f64,
    /// Grid spacing of the solid.
    pub spacing: f64,
}

/// Why no cage could be made.
#[derive(Debug, Clone, PartialEq)]
pub enum CageError {
    /// The surface has no triangles with area.
    Empty,
    /// Every attempt left some of the points outside, or crossing triangles.
    NotEnclosing { outside: usize },
}

/// A cage of about `target` vertices around `surface` that encloses `points` (see the module
/// documentation).
pub fn cage_surface(surface: &TriMesh, points: &[Point], target: usize) -> Result<CageSurface, CageError> {
    let used: Vec<Point> = {
        let mut mask = vec![false; surface.positions.len()];
        surface.triangles.iter().flatten().for_each(|&v| mask[v as usize] = true);
        surface.positions.iter().zip(&mask).filter(|(_, &m)| m).map(|(p, _)| *p).collect()
    };
    let bounds = Bounds::of(&used).union(Bounds::of(points));
    let longest = (0..3).map(|d| bounds.hi[d] - bounds.lo[d]).fold(0.0, f64::max);
    let area: f64 = surface
        .triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|v| surface.positions[v as usize]);
            0.5 * norm(cross(sub(b, a), sub(c, a)))
        })
        .sum();
    if !(longest > 0.0 && area > 0.0) {
        return Err(CageError::Empty);
    }
    let tree = TriangleTree::new(surface);
    let h = longest / CELLS as f64;
    // The edge length of a cage of `target` vertices over a surface of this area (an
    // equilateral mesh has about 2 triangles per vertex), capped for very crumpled surfaces.
    let edge = (area / (0.87 * target.max(8) as f64)).sqrt().min(0.25 * longest);
    let mut offset = (1.5 * h).max(0.3 * edge);
    let mut outside = points.len();
    for _attempt in 0..4 {
        let grid = solid(&tree, &bounds, h, offset);
        let raw = contour::zero_surface(&grid, 0.05 * h);
        let mut cage = None;
        for relax in [1.0, 1.5, 2.5] {
            let simple = simplify::simplify(&raw, (target as f64 * relax) as usize, 0.5 * offset / relax);
            if TriangleTree::new(&simple).crossing_pair().is_none() {
                cage = Some(simple);
                break;
            }
        }
        let Some(cage) = cage else {
            offset *= 1.5;
            continue;
        };
        let cage_tree = TriangleTree::new(&cage);
        outside = points.par_iter().filter(|&&p| cage_tree.winding(p) < 0.5).count();
        if outside == 0 {
            return Ok(CageSurface { surface: cage, offset, spacing: h });
        }
        offset *= 1.5;
    }
    Err(CageError::NotEnclosing { outside })
}

/// The offset solid on a grid around `bounds` (see the module documentation, step 1).
fn solid(tree: &TriangleTree, bounds: &Bounds, h: f64, offset: f64) -> Grid {
    let pad = offset + 2.0 * h;
    let lo = bounds.lo.map(|c| c - pad);
    let dims: [usize; 3] = std::array::from_fn(|d| ((bounds.hi[d] - bounds.lo[d] + 2.0 * pad) / h).ceil() as usize + 1);
    let mut grid = Grid { dims, origin: lo, h, values: Vec::new() };
    let cap = offset + 2.0 * h;
    let count = dims[0] * dims[1] * dims[2];
    grid.values = (0..count)
        .into_par_iter()
        .map(|p| {
            let at = [p % dims[0], (p / dims[0]) % dims[1], p / (dims[0] * dims[1])];
            let x = grid.point(at);
            let d = tree.distance(x, cap);
            if d < offset {
                d - offset
            } else if tree.winding(x) >= 0.5 {
                -d - offset
            } else {
                d - offset
            }
        })
        .collect();
    grid
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::surface::open_edges;
    use crate::procedural::{icosphere, prism};

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

    #[test]
    fn a_sphere_gets_a_closed_enclosing_cage_of_about_the_target_size() {
        let sphere = icosphere(5);
        let cage = cage_surface(&sphere, &sphere.positions, 400).unwrap();
        let s = &cage.surface;
        assert!(open_edges(s).is_empty());
        assert!(s.positions.len() <= 400 && s.positions.len() > 200, "{}", s.positions.len());
        assert_eq!(TriangleTree::new(s).crossing_pair(), None);
        let cage_tree = TriangleTree::new(s);
        assert!(sphere.positions.iter().all(|&p| cage_tree.winding(p) > 0.5));
        // Tight: within two offsets of the unit sphere.
        let radius = s.positions.iter().map(|&p| norm(p)).fold(0.0, f64::max);
        assert!(radius < 1.0 + 2.0 * cage.offset, "{radius} vs offset {}", cage.offset);
    }

    #[test]
    fn an_open_bowl_and_a_loose_sheet_are_enclosed() {
        let sphere = icosphere(3);
        let mut messy = sphere.clone();
        messy.triangles.retain(|t| t.iter().all(|&v| sphere.positions[v as usize][1] <= 0.3));
        let n = messy.positions.len() as u32;
        messy.positions.extend([[-0.5, 1.2, -0.5], [0.5, 1.2, -0.5], [0.0, 1.2, 0.5]]);
        messy.triangles.push([n, n + 1, n + 2]);
        let used: Vec<Point> = messy.triangles.iter().flatten().map(|&v| messy.positions[v as usize]).collect();
        let cage = cage_surface(&messy, &used, 300).unwrap();
        assert!(open_edges(&cage.surface).is_empty());
        let cage_tree = TriangleTree::new(&cage.surface);
        assert!(used.iter().all(|&p| cage_tree.winding(p) > 0.5));
        // The bowl's inside is filled (winding >= 1/2 there), so its centre is in the cage.
        assert!(cage_tree.winding([0.0, -0.3, 0.0]) > 0.5);
    }
}
