//! Surface operations: boundary of a tet mesh, consistent outward winding, compaction, and
//! closedness diagnostics.
//!
//! Everything here is deterministic: adjacency is built by sorting, never by hashing, so the
//! same input gives the same output order on every run.

use std::collections::VecDeque;

use super::{cross, dot, sub, Point, TetMesh, TriMesh};

/// The faces of tet `[a, b, c, d]` opposite a, b, c and d, wound so that their normals point
/// out of a positively oriented tet.
const OUTWARD_FACES: [[usize; 3]; 4] = [[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]];

/// Triangles that belong to exactly one tet, wound so their normal points out of the body
/// (tets positively oriented), in a deterministic order.
///
/// The order is by tet, then by the face opposite vertex a, b, c, d. A negatively oriented
/// tet's faces are reversed, so the result is outward even before `orient_positive`.
pub fn boundary(mesh: &TetMesh) -> Vec<[u32; 3]> {
    let mut faces: Vec<([u32; 3], usize)> = Vec::with_capacity(4 * mesh.tets.len());
    for (t, tet) in mesh.tets.iter().enumerate() {
        for (f, local) in OUTWARD_FACES.iter().enumerate() {
            let mut key = local.map(|k| tet[k]);
            key.sort_unstable();
            faces.push((key, 4 * t + f));
        }
    }
    faces.sort_unstable();
    let mut on_boundary = vec![false; faces.len()];
    for group in faces.chunk_by(|x, y| x.0 == y.0) {
        if let [(_, id)] = group {
            on_boundary[*id] = true;
        }
    }
    (0..on_boundary.len())
        .filter(|&id| on_boundary[id])
        .map(|id| {
            let (t, f) = (id / 4, id % 4);
            let mut triangle = OUTWARD_FACES[f].map(|k| mesh.tets[t][k]);
            if mesh.signed_volume_at(&mesh.positions, t) < 0.0 {
                triangle.swap(1, 2);
            }
            triangle
        })
        .collect()
}

/// Make the winding consistent across shared edges and pointing outward (positive enclosed
/// volume) for each connected component. Returns the number of triangles flipped.
///
/// Winding spreads breadth-first from the lowest-numbered triangle of each component across
/// edges shared by exactly two triangles (non-manifold edges do not propagate). Each
/// component is taken as a separate body: the inner shell of a hollow object would be turned
/// outward too, so cavities are not supported.
pub fn orient_outward(mesh: &mut TriMesh) -> usize {
    let count = mesh.triangles.len();
    let mut neighbours = vec![Vec::new(); count];
    for group in edge_uses(&mesh.triangles).chunk_by(|x, y| x.0 == y.0) {
        if let [(_, a), (_, b)] = group {
            let (s, t) = (a / 3, b / 3);
            neighbours[s].push(t);
            neighbours[t].push(s);
        }
    }
    let original = mesh.triangles.clone();
    let mut visited = vec![false; count];
    let mut queue = VecDeque::new();
    for seed in 0..count {
        if visited[seed] {
            continue;
        }
        visited[seed] = true;
        queue.push_back(seed);
        let mut component = Vec::new();
        while let Some(t) = queue.pop_front() {
            component.push(t);
            for &n in &neighbours[t] {
                if !visited[n] {
                    visited[n] = true;
                    if shares_edge_direction(mesh.triangles[t], mesh.triangles[n]) {
                        mesh.triangles[n].swap(1, 2);
                    }
                    queue.push_back(n);
                }
            }
        }
        if signed_volume(&mesh.positions, component.iter().map(|&t| &mesh.triangles[t])) < 0.0 {
            component.iter().for_each(|&t| mesh.triangles[t].swap(1, 2));
        }
    }
    // Every change above swaps corners 1 and 2 (an even number of times undoes it), so the
    // per-corner attributes follow the triangles that differ from their original.
    if let Some(attributes) = &mut mesh.attributes {
        (0..count).filter(|&t| mesh.triangles[t] != original[t]).for_each(|t| attributes.swap_corners(t));
    }
    mesh.triangles.iter().zip(&original).filter(|(now, before)| !same_winding(**now, **before)).count()
}

/// Drop vertices no triangle uses. Returns the compacted mesh and, for each new vertex, its
/// index in the input.
///
/// Kept vertices stay in their input order.
pub fn compact(mesh: &TriMesh) -> (TriMesh, Vec<u32>) {
    let mut new_index = vec![u32::MAX; mesh.positions.len()];
    mesh.triangles.iter().flatten().for_each(|&v| new_index[v as usize] = 0);
    let mut kept = Vec::new();
    for (old, slot) in new_index.iter_mut().enumerate() {
        if *slot == 0 {
            *slot = kept.len() as u32;
            kept.push(old as u32);
        }
    }
    let compacted = TriMesh {
        positions: kept.iter().map(|&old| mesh.positions[old as usize]).collect(),
        triangles: mesh.triangles.iter().map(|t| t.map(|v| new_index[v as usize])).collect(),
        attributes: mesh.attributes.clone(),
    };
    (compacted, kept)
}

/// Edges used by exactly one triangle (a hole's rim), as vertex pairs.
///
/// Each edge is given in the direction its triangle traverses it, ordered by triangle.
pub(crate) fn open_edges(mesh: &TriMesh) -> Vec<[u32; 2]> {
    let mut open: Vec<usize> =
        edge_uses(&mesh.triangles).chunk_by(|x, y| x.0 == y.0).filter_map(|group| if let [(_, id)] = group { Some(*id) } else { None }).collect();
    open.sort_unstable();
    open.into_iter().map(|id| directed_edge(mesh.triangles[id / 3], id % 3)).collect()
}

/// Signed volume enclosed by the triangles (positive when a closed surface is wound outward).
pub fn enclosed_volume(positions: &[Point], triangles: &[[u32; 3]]) -> f64 {
    signed_volume(positions, triangles.iter())
}

fn signed_volume<'a>(positions: &[Point], triangles: impl Iterator<Item = &'a [u32; 3]>) -> f64 {
    let mut triangles = triangles.peekable();
    // Measured from a vertex of the surface, not the origin, to limit cancellation.
    let Some(origin) = triangles.peek().map(|t| positions[t[0] as usize]) else { return 0.0 };
    triangles
        .map(|t| {
            let [a, b, c] = t.map(|v| sub(positions[v as usize], origin));
            dot(a, cross(b, c))
        })
        .sum::<f64>()
        / 6.0
}

/// Every edge of every triangle as (sorted vertex pair, 3 * triangle + local edge), sorted.
fn edge_uses(triangles: &[[u32; 3]]) -> Vec<([u32; 2], usize)> {
    let mut uses: Vec<([u32; 2], usize)> = Vec::with_capacity(3 * triangles.len());
    for (t, triangle) in triangles.iter().enumerate() {
        for e in 0..3 {
            let [a, b] = directed_edge(*triangle, e);
            uses.push(([a.min(b), a.max(b)], 3 * t + e));
        }
    }
    uses.sort_unstable();
    uses
}

fn directed_edge(triangle: [u32; 3], e: usize) -> [u32; 2] {
    [triangle[e], triangle[(e + 1) % 3]]
}

/// Whether two triangles traverse a shared edge in the same direction (inconsistent winding).
fn shares_edge_direction(s: [u32; 3], t: [u32; 3]) -> bool {
    (0..3).any(|i| (0..3).any(|j| directed_edge(s, i) == directed_edge(t, j)))
}

fn same_winding(s: [u32; 3], t: [u32; 3]) -> bool {
    s == t || s == [t[1], t[2], t[0]] || s == [t[2], t[0], t[1]]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::algorithms::procedural;
    use crate::formats::mesh::{medit, obj};
    use crate::support::testing::paper_asset;

    /// Every edge of a closed, consistently wound surface is traversed once in each direction.
    fn assert_closed_and_consistent(triangles: &[[u32; 3]]) {
        let mut directed: Vec<[u32; 2]> = triangles.iter().flat_map(|t| (0..3).map(|e| directed_edge(*t, e))).collect();
        directed.sort_unstable();
        assert!(directed.windows(2).all(|w| w[0] != w[1]), "an edge is traversed twice in the same direction");
        let mut reversed: Vec<[u32; 2]> = directed.iter().map(|[a, b]| [*b, *a]).collect();
        reversed.sort_unstable();
        assert_eq!(directed, reversed, "an edge is traversed in one direction only");
    }

    fn canonical(mut triangles: Vec<[u32; 3]>) -> Vec<[u32; 3]> {
        for t in &mut triangles {
            let k = (0..3).min_by_key(|&k| t[k]).unwrap();
            *t = [t[k], t[(k + 1) % 3], t[(k + 2) % 3]];
        }
        triangles.sort_unstable();
        triangles
    }

    fn unit_tet() -> TetMesh {
        TetMesh { positions: vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], tets: vec![[0, 1, 2, 3]] }
    }

    #[test]
    fn boundary_of_a_tet_points_outward_whatever_its_orientation() {
        for tets in [vec![[0, 1, 2, 3]], vec![[0, 1, 3, 2]]] {
            let mesh = TetMesh { tets, ..unit_tet() };
            let faces = boundary(&mesh);
            assert_eq!(faces.len(), 4);
            assert!((enclosed_volume(&mesh.positions, &faces) - 1.0 / 6.0).abs() < 1e-15);
            assert_closed_and_consistent(&faces);
        }
    }

    #[test]
    fn boundary_drops_shared_faces_and_keeps_tet_order() {
        let mut mesh = unit_tet();
        mesh.positions.push([1.0, 1.0, 1.0]);
        mesh.tets.push([1, 2, 3, 4]);
        mesh.orient_positive();
        let faces = boundary(&mesh);
        assert_eq!(faces.len(), 6);
        assert_eq!(&faces[..3], &[[0, 3, 2], [0, 1, 3], [0, 2, 1]]);
        assert!((enclosed_volume(&mesh.positions, &faces) - mesh.volume_at(&mesh.positions)).abs() < 1e-15);
        assert_closed_and_consistent(&faces);
    }

    #[test]
    fn orient_outward_carries_corner_attributes_and_compact_keeps_them() {
        // Corner attributes equal to the vertex numbers must stay equal to them whatever flips.
        let mut mesh = procedural::icosphere(1);
        mesh.triangles.iter_mut().step_by(3).for_each(|t| t.swap(0, 1));
        mesh.triangles[5].swap(1, 2);
        let corners = mesh.triangles.clone();
        mesh.attributes = Some(crate::algorithms::geometry::attributes::CornerAttributes {
            uvs: vec![[0.0; 2]; mesh.positions.len()],
            uv_corners: corners.clone(),
            normals: vec![[0.0; 3]; mesh.positions.len()],
            normal_corners: corners,
            ..Default::default()
        });
        assert!(orient_outward(&mut mesh) > 0);
        let a = mesh.attributes.as_ref().unwrap();
        assert_eq!(a.uv_corners, mesh.triangles);
        assert_eq!(a.normal_corners, mesh.triangles);
        mesh.positions.push([9.0; 3]);
        assert_eq!(compact(&mesh).0.attributes, mesh.attributes);
    }

    #[test]
    fn orient_outward_repairs_scrambled_components() {
        let sphere = procedural::icosphere(2);
        let mut box_inside_out = procedural::prism([1.0, 1.0, 1.0], [2, 2, 2]);
        box_inside_out.triangles.iter_mut().for_each(|t| t.swap(0, 1));
        // Two bodies in one mesh: a sphere with every third triangle flipped, and a box
        // entirely inside out, moved away from the sphere.
        let offset = sphere.positions.len() as u32;
        let mut mesh = sphere.clone();
        mesh.positions.extend(box_inside_out.positions.iter().map(|p| [p[0] + 3.0, p[1], p[2]]));
        mesh.triangles.extend(box_inside_out.triangles.iter().map(|t| t.map(|v| v + offset)));
        let mut scrambled = 0;
        for t in mesh.triangles.iter_mut().take(sphere.triangles.len()).step_by(3) {
            t.swap(1, 2);
            scrambled += 1;
        }
        let flipped = orient_outward(&mut mesh);
        assert_eq!(flipped, scrambled + box_inside_out.triangles.len());
        let (sphere_part, box_part) = mesh.triangles.split_at(sphere.triangles.len());
        assert_eq!(sphere_part, &sphere.triangles[..]);
        assert!((enclosed_volume(&mesh.positions, box_part) - 1.0).abs() < 1e-12);
        assert_closed_and_consistent(&mesh.triangles);
        assert_eq!(orient_outward(&mut mesh), 0, "orienting is idempotent");
    }

    #[test]
    fn compact_keeps_order_and_maps_back() {
        let mesh =
            TriMesh { positions: vec![[9.0; 3], [0.0; 3], [1.0, 0.0, 0.0], [8.0; 3], [0.0, 1.0, 0.0]], triangles: vec![[4, 1, 2]], attributes: None };
        let (compacted, kept) = compact(&mesh);
        assert_eq!(kept, vec![1, 2, 4]);
        assert_eq!(compacted.positions, vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
        assert_eq!(compacted.triangles, vec![[2, 0, 1]]);
    }

    #[test]
    fn open_edges_find_the_rim_of_a_hole() {
        let mut prism = procedural::prism([1.0, 2.0, 1.0], [2, 3, 2]);
        assert!(open_edges(&prism).is_empty());
        let [a, b, c] = prism.triangles.remove(5);
        let mut rim = open_edges(&prism);
        rim.sort_unstable();
        let mut expected = vec![[b, a], [c, b], [a, c]];
        expected.sort_unstable();
        assert_eq!(rim, expected, "the neighbours traverse the rim against the missing triangle");
    }

    #[test]
    fn paper_stretch3d_boundary_is_closed_and_outward() {
        let Some(path) = paper_asset("stretch3d/0.mesh") else { return };
        let mesh = medit::read(&path).unwrap();
        let faces = boundary(&mesh);
        assert_eq!(faces.len(), 680);
        let surface = TriMesh { positions: mesh.positions.clone(), triangles: faces.clone(), attributes: None };
        assert!(open_edges(&surface).is_empty());
        assert_closed_and_consistent(&faces);
        assert!((enclosed_volume(&mesh.positions, &faces) - 4.8).abs() < 1e-12);
        assert_eq!(boundary(&mesh), faces, "deterministic");
    }

    #[test]
    fn paper_rectangular_prism_orients_to_the_tet_mesh_boundary() {
        let Some(path) = paper_asset("stretch3d/rectangular_prism.obj") else { return };
        let mut surface = obj::read(&path).unwrap();
        assert!(open_edges(&surface).is_empty());
        let flipped = orient_outward(&mut surface);
        assert!(flipped > 0, "the file is inconsistently wound");
        assert_closed_and_consistent(&surface.triangles);
        // 1.6 x 3 x 1 box.
        assert!((enclosed_volume(&surface.positions, &surface.triangles) - 4.8).abs() < 1e-12);
        if let Some(rest) = paper_asset("stretch3d/0.mesh") {
            let rest = medit::read(&rest).unwrap();
            assert_eq!(canonical(surface.triangles.clone()), canonical(boundary(&rest)));
        }
        let (compacted, kept) = compact(&surface);
        assert_eq!((compacted.positions.len(), kept.len()), (342, 342));
    }

    #[test]
    fn paper_dino_and_spot_boundaries_are_closed() {
        for (rel, triangles) in [("dino/dino.mesh", 798), ("spot/spot.mesh", 1628)] {
            let Some(path) = paper_asset(rel) else { continue };
            let mesh = medit::read(&path).unwrap();
            let faces = boundary(&mesh);
            assert_eq!(faces.len(), triangles, "{rel}");
            assert_closed_and_consistent(&faces);
            assert!((enclosed_volume(&mesh.positions, &faces) - mesh.volume_at(&mesh.positions)).abs() < 1e-9, "{rel}");
        }
    }
}
