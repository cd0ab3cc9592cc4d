//! Mesh refinement before the springs are built (Ma et al. 2012, section 3.1): long springs
//! dominate a mass-spring system, so surface edges longer than `max_ratio` times the median
//! edge are split at their midpoints, longest first, until none is.
//!
//! An edge's length is its largest length over the targets, so the result is short in every
//! target. A new vertex is the midpoint of its edge in every target: each target keeps its
//! exact piecewise-linear shape and all targets keep one topology. New vertices are appended
//! after the input's, so vertex `v < n` is still input vertex `v`. Run this before
//! tetrahedralizing; TetGen's `-a` (maximum volume, see [`regular_tet_volume`]) bounds the
//! interior edges.

use std::collections::{BTreeMap, BinaryHeap};

use crate::algorithms::geometry::{add, norm, scale, sub, Point};

/// A refined surface.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Refined {
    /// Positions per target: the input's, then one per split.
    pub surface: Vec<Vec<Point>>,
    /// The triangles after splitting, shared by every target.
    pub triangles: Vec<[u32; 3]>,
    /// For new vertex `n + k`, the two vertices it is the midpoint of.
    pub parents: Vec<[u32; 2]>,
}

/// The median over surface edges of the largest length over the targets.
pub(crate) fn median_edge(surface: &[Vec<Point>], triangles: &[[u32; 3]]) -> f64 {
    let mut lengths: Vec<f64> = edges(triangles).keys().map(|&e| length(surface, e)).collect();
    if lengths.is_empty() {
        return 0.0;
    }
    let mid = lengths.len() / 2;
    *lengths.select_nth_unstable_by(mid, f64::total_cmp).1
}

/// Split every edge longer than `max_ratio` times the median edge (see the module docs).
/// `max_ratio` must be greater than 1 (a ratio of 1 or less could never be met by halving).
pub(crate) fn split_long_edges(surface: &[Vec<Point>], triangles: &[[u32; 3]], max_ratio: f64) -> Refined {
    assert!(max_ratio > 1.0, "max_ratio must exceed 1");
    let mut surface: Vec<Vec<Point>> = surface.to_vec();
    let mut triangles = triangles.to_vec();
    let mut parents = Vec::new();
    let limit = max_ratio * median_edge(&surface, &triangles);
    let mut by_edge = edges(&triangles);
    // Longest first; lengths are positive, so their bit patterns order like the numbers.
    let mut queue: BinaryHeap<(u64, [u32; 2])> =
        by_edge.keys().map(|&e| (length(&surface, e).to_bits(), e)).filter(|&(l, _)| f64::from_bits(l) > limit).collect();
    while let Some((_, e @ [a, b])) = queue.pop() {
        let Some(sides) = by_edge.remove(&e) else { continue };
        let m = surface[0].len() as u32;
        for target in &mut surface {
            let midpoint = scale(add(target[a as usize], target[b as usize]), 0.5);
            target.push(midpoint);
        }
        parents.push(e);
        for t in sides {
            // Triangle t = (a, b, c) up to rotation and orientation.
            let tri = triangles[t];
            let k = (0..3).find(|&k| tri[k] != a && tri[k] != b).expect("a triangle of the edge");
            let c = tri[k];
            let (first, second) = (tri[(k + 1) % 3], tri[(k + 2) % 3]); // edge in winding order
            let new_t = triangles.len();
            triangles[t] = [c, first, m];
            triangles.push([c, m, second]);
            let mut link = |e: [u32; 2], old: Option<usize>, new: usize| {
                let key = [e[0].min(e[1]), e[0].max(e[1])];
                let list = by_edge.entry(key).or_default();
                match old {
                    Some(o) => list.iter_mut().filter(|x| **x == o).for_each(|x| *x = new),
                    None => list.push(new),
                }
            };
            link([first, m], None, t);
            link([m, second], None, new_t);
            link([c, m], None, t);
            link([c, m], None, new_t);
            link([second, c], Some(t), new_t);
            for key in [[first, m], [m, second], [c, m]] {
                let key = [key[0].min(key[1]), key[0].max(key[1])];
                let l = length(&surface, key);
                if l > limit {
                    queue.push((l.to_bits(), key));
                }
            }
        }
    }
    Refined { surface, triangles, parents }
}

/// The volume of a regular tetrahedron with edges of length `edge`: as TetGen's maximum tet
/// volume (`-a`), it keeps interior edges near `edge` (with a quality bound such as `-q1.414`).
pub fn regular_tet_volume(edge: f64) -> f64 {
    edge.powi(3) / (6.0 * std::f64::consts::SQRT_2)
}

fn length(surface: &[Vec<Point>], [a, b]: [u32; 2]) -> f64 {
    surface.iter().map(|t| norm(sub(t[a as usize], t[b as usize]))).fold(0.0, f64::max)
}

/// Surface edges (sorted ends) and the triangles that use them.
fn edges(triangles: &[[u32; 3]]) -> BTreeMap<[u32; 2], Vec<usize>> {
    let mut map: BTreeMap<[u32; 2], Vec<usize>> = BTreeMap::new();
    for (t, tri) in triangles.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (tri[k], tri[(k + 1) % 3]);
            map.entry([a.min(b), a.max(b)]).or_default().push(t);
        }
    }
    map
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::algorithms::geometry::surface::{enclosed_volume, open_edges, orient_outward};
    use crate::algorithms::geometry::TriMesh;
    use crate::algorithms::procedural::prism;

    #[test]
    fn long_box_edges_are_split_until_none_exceeds_the_ratio() {
        // A box with a very coarse long side: edges along y are 8x the others.
        let b = prism([1.0, 8.0, 1.0], [4, 4, 4]);
        let bent: Vec<Point> = b.positions.iter().map(|p| [p[0] + 0.1 * p[1], p[1], p[2]]).collect();
        let targets = vec![b.positions.clone(), bent];
        let before = median_edge(&targets, &b.triangles);
        let r = split_long_edges(&targets, &b.triangles, 1.5);
        let limit = 1.5 * before;
        for e in edges(&r.triangles).keys() {
            assert!(length(&r.surface, *e) <= limit, "{e:?}");
        }
        // The input vertices keep their numbers; new ones are midpoints in every target.
        assert_eq!(&r.surface[0][..b.positions.len()], &b.positions[..]);
        for (k, &[a, c]) in r.parents.iter().enumerate() {
            for t in &r.surface {
                let m = t[b.positions.len() + k];
                assert!(norm(sub(m, scale(add(t[a as usize], t[c as usize]), 0.5))) < 1e-15);
            }
        }
        // Still a closed, consistently wound surface of the same volume.
        let mesh = TriMesh { positions: r.surface[0].clone(), triangles: r.triangles.clone(), attributes: None };
        assert!(open_edges(&mesh).is_empty());
        assert_eq!(orient_outward(&mut mesh.clone()), 0);
        assert!((enclosed_volume(&mesh.positions, &mesh.triangles) - 8.0).abs() < 1e-12);
        assert!(r.triangles.len() > b.triangles.len());
        // Deterministic.
        assert_eq!(r, split_long_edges(&targets, &b.triangles, 1.5));
    }

    #[test]
    fn an_even_mesh_is_left_alone() {
        let b = prism([1.0; 3], [3, 3, 3]);
        let r = split_long_edges(std::slice::from_ref(&b.positions), &b.triangles, 2.0);
        assert!(r.parents.is_empty());
        assert_eq!(r.triangles, b.triangles);
    }
}
