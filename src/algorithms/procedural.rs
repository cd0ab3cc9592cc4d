//! Procedural shapes and deformations: the demo's prism, Kuhn tet grids, spheres for
//! benchmarks, and the scene file's `twist` deformation.

use std::collections::HashMap;

use serde::{Deserialize, Serialize};

use crate::algorithms::geometry::{norm, scale, Axis, Bounds, Point, TetMesh, TriMesh};

/// A procedural twist of a keyframe mesh about an axis through its bounding-box centre: the
/// rotation angle grows linearly from 0 at the low end of the box to `degrees` at the high end,
/// and the axial coordinate is scaled by `axial_scale` about the low end. The scene file's
/// `twist` table (see `formats/scene.md`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Twist {
    /// The axis the mesh turns about.
    pub axis: Axis,
    /// The turn at the high end of the box, right-handed about +axis.
    pub degrees: f64,
    /// Scale of the axial coordinate about the low end (default 1).
    #[serde(default = "one")]
    pub axial_scale: f64,
}

fn one() -> f64 {
    1.0
}

/// A box [0, size] split into `divisions` cells of 6 tets each: the Kuhn triangulation (the six
/// monotone paths from corner 000 to 111 of every cell, so shared faces match), positive. Node
/// `(i, j, k)` of the grid is `(i * (ny + 1) + j) * (nz + 1) + k`. A conforming tet body with
/// no TetGen run, the same on every machine (the cantilever tests, the simulated test caches).
pub fn box_tets(size: [f64; 3], divisions: [usize; 3]) -> TetMesh {
    let [nx, ny, nz] = divisions;
    let node = |i: usize, j: usize, k: usize| ((i * (ny + 1) + j) * (nz + 1) + k) as u32;
    let mut positions = Vec::with_capacity((nx + 1) * (ny + 1) * (nz + 1));
    for i in 0..=nx {
        for j in 0..=ny {
            for k in 0..=nz {
                let c = [i, j, k];
                positions.push(std::array::from_fn(|d| size[d] * (c[d] as f64 / divisions[d] as f64)));
            }
        }
    }
    let mut tets = Vec::with_capacity(6 * nx * ny * nz);
    for i in 0..nx {
        for j in 0..ny {
            for k in 0..nz {
                for order in [[0, 1, 2], [0, 2, 1], [1, 0, 2], [1, 2, 0], [2, 0, 1], [2, 1, 0]] {
                    let mut c = [i, j, k];
                    let mut tet = [node(i, j, k); 4];
                    for (step, &axis) in order.iter().enumerate() {
                        c[axis] += 1;
                        tet[step + 1] = node(c[0], c[1], c[2]);
                    }
                    tets.push(tet);
                }
            }
        }
    }
    let mut m = TetMesh { positions, tets };
    m.orient_positive();
    m
}

/// A closed box surface `[0,size]` with `divisions` segments per axis, outward wound.
///
/// Only the grid points on the box surface are vertices, each once, numbered in x-major,
/// then y, then z order (the order of the paper's `stretch3d` meshes); every grid square is
/// split along the same diagonal. Panics if a division is 0 (a programming error: scene
/// values are validated before they get here).
pub fn prism(size: [f64; 3], divisions: [usize; 3]) -> TriMesh {
    assert!(divisions.iter().all(|&d| d > 0), "prism divisions must be at least 1, got {divisions:?}");
    let [nx, ny, nz] = divisions;
    let grid = |c: [usize; 3]| (c[0] * (ny + 1) + c[1]) * (nz + 1) + c[2];
    let mut index = vec![u32::MAX; (nx + 1) * (ny + 1) * (nz + 1)];
    let mut positions = Vec::new();
    for i in 0..=nx {
        for j in 0..=ny {
            for k in 0..=nz {
                if i == 0 || i == nx || j == 0 || j == ny || k == 0 || k == nz {
                    index[grid([i, j, k])] = positions.len() as u32;
                    // size * (i / n) keeps the far faces exactly at `size`.
                    let c = [i, j, k];
                    positions.push(std::array::from_fn(|d| size[d] * (c[d] as f64 / divisions[d] as f64)));
                }
            }
        }
    }
    let mut triangles = Vec::new();
    for a in 0..3 {
        // (u, v, a) is right-handed, so a quad listed counter-clockwise in (u, v) faces +a.
        let (u, v) = ((a + 1) % 3, (a + 2) % 3);
        for side in [0, divisions[a]] {
            for iu in 0..divisions[u] {
                for iv in 0..divisions[v] {
                    let corner = |du: usize, dv: usize| {
                        let mut c = [0; 3];
                        (c[a], c[u], c[v]) = (side, iu + du, iv + dv);
                        index[grid(c)]
                    };
                    let (q00, q10, q11, q01) = (corner(0, 0), corner(1, 0), corner(1, 1), corner(0, 1));
                    if side == 0 {
                        triangles.extend([[q00, q11, q10], [q00, q01, q11]]);
                    } else {
                        triangles.extend([[q00, q10, q11], [q00, q11, q01]]);
                    }
                }
            }
        }
    }
    TriMesh { positions, triangles, attributes: None }
}

/// A unit icosphere with `subdivisions` levels (0 = icosahedron), outward wound.
///
/// Level n has 10·4ⁿ + 2 vertices and 20·4ⁿ triangles; each level splits every triangle in
/// four at its edge midpoints, pushed out to the sphere.
pub fn icosphere(subdivisions: usize) -> TriMesh {
    let t = (1.0 + 5f64.sqrt()) / 2.0;
    let corners: [Point; 12] = [
        [-1.0, t, 0.0],
        [1.0, t, 0.0],
        [-1.0, -t, 0.0],
        [1.0, -t, 0.0],
        [0.0, -1.0, t],
        [0.0, 1.0, t],
        [0.0, -1.0, -t],
        [0.0, 1.0, -t],
        [t, 0.0, -1.0],
        [t, 0.0, 1.0],
        [-t, 0.0, -1.0],
        [-t, 0.0, 1.0],
    ];
    let mut positions: Vec<Point> = corners.iter().map(|&p| scale(p, 1.0 / norm(p))).collect();
    let mut triangles: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..subdivisions {
        // Midpoints are numbered in order of first use, so the result is deterministic.
        let mut midpoints: HashMap<(u32, u32), u32> = HashMap::new();
        let mut midpoint = |a: u32, b: u32| {
            *midpoints.entry((a.min(b), a.max(b))).or_insert_with(|| {
                let [p, q] = [positions[a as usize], positions[b as usize]];
                let m = [p[0] + q[0], p[1] + q[1], p[2] + q[2]];
                positions.push(scale(m, 1.0 / norm(m)));
                positions.len() as u32 - 1
            })
        };
        triangles = triangles
            .iter()
            .flat_map(|&[a, b, c]| {
                let (ab, bc, ca) = (midpoint(a, b), midpoint(b, c), midpoint(c, a));
                [[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]
            })
            .collect();
    }
    TriMesh { positions, triangles, attributes: None }
}

/// Apply a twist (see [`Twist`]) to points: angle grows linearly along the axis over the
/// points' own bounding box, about the axis through the box centre; the axial coordinate
/// is scaled about the low end.
///
/// With s = (p_a − lo) / (hi − lo) along axis a, a point turns by `degrees`·s, right-handed
/// about +a, around the centre of the other two coordinates' bounds, and its axial
/// coordinate becomes lo + `axial_scale`·(p_a − lo). Points with no extent along the axis
/// do not turn.
pub fn twist(points: &[Point], twist: &Twist) -> Vec<Point> {
    let Bounds { lo, hi } = Bounds::of(points);
    if points.is_empty() {
        return Vec::new();
    }
    let a = twist.axis.index();
    // (b, c, a) is right-handed: turning b towards c is a positive rotation about a.
    let (b, c) = ((a + 1) % 3, (a + 2) % 3);
    let length = hi[a] - lo[a];
    let (centre_b, centre_c) = ((lo[b] + hi[b]) / 2.0, (lo[c] + hi[c]) / 2.0);
    points
        .iter()
        .map(|p| {
            let s = if length > 0.0 { (p[a] - lo[a]) / length } else { 0.0 };
            let (sin, cos) = (twist.degrees.to_radians() * s).sin_cos();
            let (db, dc) = (p[b] - centre_b, p[c] - centre_c);
            let mut q = [0.0; 3];
            q[a] = lo[a] + twist.axial_scale * (p[a] - lo[a]);
            q[b] = centre_b + cos * db - sin * dc;
            q[c] = centre_c + sin * db + cos * dc;
            q
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::algorithms::geometry::sub;
    use crate::algorithms::geometry::surface::{enclosed_volume, open_edges, orient_outward};
    use crate::formats::mesh::{medit, obj};
    use crate::support::testing::paper_asset;

    fn assert_closed_outward(mesh: &TriMesh) {
        assert!(open_edges(mesh).is_empty(), "closed");
        assert_eq!(orient_outward(&mut mesh.clone()), 0, "consistently wound and outward");
        let mut sorted = mesh.positions.clone();
        sorted.sort_by(|p, q| p.partial_cmp(q).unwrap());
        assert!(sorted.windows(2).all(|w| w[0] != w[1]), "no duplicate vertices");
    }

    #[test]
    fn prism_is_a_closed_outward_box() {
        let mesh = prism([1.0, 3.0, 1.0], [3, 9, 3]);
        assert_eq!((mesh.positions.len(), mesh.triangles.len()), (4 * 10 * 4 - 2 * 8 * 2, 4 * (27 + 27 + 9)));
        assert_closed_outward(&mesh);
        assert!((enclosed_volume(&mesh.positions, &mesh.triangles) - 3.0).abs() < 1e-12);
        assert_eq!(Bounds::of(&mesh.positions), Bounds { lo: [0.0; 3], hi: [1.0, 3.0, 1.0] });
        assert_eq!(mesh, prism([1.0, 3.0, 1.0], [3, 9, 3]), "deterministic");
        let cube = prism([2.0; 3], [1, 1, 1]);
        assert_eq!((cube.positions.len(), cube.triangles.len()), (8, 12));
        assert_closed_outward(&cube);
    }

    #[test]
    fn prism_matches_the_paper_stretch3d_surface() {
        let Some(path) = paper_asset("stretch3d/rectangular_prism.obj") else { return };
        let paper = obj::read(&path).unwrap();
        let ours = prism([1.6, 3.0, 1.0], [8, 10, 5]);
        assert_eq!(ours.triangles.len(), paper.triangles.len());
        let mut used = vec![false; paper.positions.len()];
        paper.triangles.iter().flatten().for_each(|&v| used[v as usize] = true);
        let surface_points: Vec<Point> = (0..used.len()).filter(|&v| used[v]).map(|v| paper.positions[v]).collect();
        assert_eq!(surface_points.len(), ours.positions.len());
        // Same points in the same order, once moved to the paper's frame.
        for (p, q) in ours.positions.iter().zip(&surface_points) {
            assert!(norm(sub([p[0] - 0.8, p[1], p[2] - 0.5], *q)) < 1e-12, "{p:?} vs {q:?}");
        }
    }

    #[test]
    fn icosphere_levels_are_closed_unit_spheres() {
        for level in 0..=3 {
            let mesh = icosphere(level);
            let n = 4usize.pow(level as u32);
            assert_eq!((mesh.positions.len(), mesh.triangles.len()), (10 * n + 2, 20 * n));
            assert!(mesh.positions.iter().all(|p| (norm(*p) - 1.0).abs() < 1e-15));
            assert_closed_outward(&mesh);
        }
        let volume = enclosed_volume(&icosphere(3).positions, &icosphere(3).triangles);
        let ball = 4.0 / 3.0 * std::f64::consts::PI;
        assert!(volume < ball && volume > 0.97 * ball, "{volume}");
    }

    #[test]
    fn twist_turns_right_handed_about_the_box_centre() {
        let points = [[0.0, 0.0, 1.0], [0.0, 1.5, 1.0], [0.0, 3.0, 1.0], [0.0, 0.0, -1.0], [2.0, 3.0, -1.0]];
        // Centre of x and z bounds: (1, 0).
        let quarter = twist(&points, &Twist { axis: Axis::Y, degrees: 180.0, axial_scale: 0.8 });
        let expected = [[0.0, 0.0, 1.0], [2.0, 1.2, 1.0], [2.0, 2.4, -1.0], [0.0, 0.0, -1.0], [0.0, 2.4, 1.0]];
        for (p, q) in quarter.iter().zip(expected) {
            assert!(norm(sub(*p, q)) < 1e-12, "{p:?} vs {q:?}");
        }
        // About +z, a quarter turn takes +x to +y.
        let about_z = twist(&[[0.0, 0.0, 0.0], [1.0, 0.0, 1.0], [-1.0, 0.0, 0.0]], &Twist { axis: Axis::Z, degrees: 90.0, axial_scale: 1.0 });
        assert!(norm(sub(about_z[1], [0.0, 1.0, 1.0])) < 1e-15, "{:?}", about_z[1]);
        assert!(twist(&[], &Twist { axis: Axis::X, degrees: 90.0, axial_scale: 1.0 }).is_empty());
        let flat = [[0.0, 1.0, 2.0], [0.0, 3.0, 4.0]];
        assert_eq!(twist(&flat, &Twist { axis: Axis::X, degrees: 90.0, axial_scale: 2.0 }), flat.to_vec());
    }

    #[test]
    fn paper_twist_keyframe_keeps_every_tet_positive() {
        let Some(path) = paper_asset("stretch3d/0.mesh") else { return };
        let rest = medit::read(&path).unwrap();
        for degrees in [180.0, -180.0] {
            let key = twist(&rest.positions, &Twist { axis: Axis::Y, degrees, axial_scale: 0.8 });
            for (p, q) in rest.positions.iter().zip(&key) {
                let expected = match p[1] {
                    0.0 => *p,
                    3.0 => [-p[0], 2.4, -p[2]],
                    _ => continue,
                };
                assert!(norm(sub(*q, expected)) < 1e-12, "{p:?} -> {q:?}");
            }
            assert!((0..rest.tets.len()).all(|t| rest.signed_volume_at(&key, t) > 0.0));
            // The continuous map scales volume by exactly 0.8; straight tet edges lose a little.
            let ratio = rest.volume_at(&key) / (0.8 * 4.8);
            assert!(ratio < 1.0 && ratio > 0.97, "{ratio}");
        }
    }
}
