//! The anchor of Ma et al. 2012, section 3.4: a few points inside the shape, tied to their
//! nearest vertices by springs and to each other by hard springs, that serve as the boundary
//! condition instead of surface vertices, so that every surface vertex moves freely.
//!
//! The default anchor is a small regular tetrahedron (four points, so the best-fit rotation is
//! determined) centred at the centre of mass of target 0, with an edge as long as the median
//! surface edge. Its placement inside the body is the user's concern for unusual shapes: the
//! centre of mass of a curved bar or a ring lies outside it, where the anchor still works
//! (springs do not care) but no longer sits "inside"; give explicit points then.

use crate::algorithms::geometry::{add, cross, dot, norm, scale, sub, Point};

/// Centre of mass of the solid a closed surface bounds (divergence theorem), or the
/// area-weighted centroid of the triangles when they enclose no volume (an open surface).
pub(crate) fn centre_of_mass(positions: &[Point], triangles: &[[u32; 3]]) -> Point {
    let Some(first) = triangles.first() else { return [0.0; 3] };
    // Moments about a vertex of the surface, to limit cancellation.
    let origin = positions[first[0] as usize];
    let (mut volume, mut moment) = (0.0, [0.0; 3]);
    let (mut area, mut area_moment) = (0.0, [0.0; 3]);
    for t in triangles {
        let [a, b, c] = t.map(|v| sub(positions[v as usize], origin));
        let v6 = dot(a, cross(b, c));
        volume += v6;
        // The centroid of the tet (origin, a, b, c) is (a + b + c) / 4.
        moment = add(moment, scale(add(add(a, b), c), v6 / 4.0));
        let doubled_area = norm(cross(sub(b, a), sub(c, a)));
        area += doubled_area;
        area_moment = add(area_moment, scale(add(add(a, b), c), doubled_area / 3.0));
    }
    let total_area = area.max(f64::MIN_POSITIVE);
    // "Encloses a volume": more than a sliver of what a ball of the same area would.
    let ball = total_area.powf(1.5) / 2.0;
    if volume.abs() > 1e-9 * ball {
        add(origin, scale(moment, 1.0 / volume))
    } else {
        add(origin, scale(area_moment, 1.0 / total_area))
    }
}

/// A regular tetrahedron of edge `edge` centred at `centre`.
pub(crate) fn tetrahedron_frame(centre: Point, edge: f64) -> Vec<Point> {
    // Alternate corners of a cube of side edge / √2.
    let h = edge / (2.0 * std::f64::consts::SQRT_2);
    [[1.0, 1.0, 1.0], [1.0, -1.0, -1.0], [-1.0, 1.0, -1.0], [-1.0, -1.0, 1.0]].iter().map(|c| add(centre, scale(*c, h))).collect()
}

/// The `k` vertices nearest to each point (ties by index), nearest first.
pub fn nearest(points: &[Point], vertices: &[Point], k: usize) -> Vec<Vec<u32>> {
    points
        .iter()
        .map(|p| {
            let mut by_distance: Vec<(f64, u32)> = vertices.iter().enumerate().map(|(v, q)| (norm(sub(*q, *p)), v as u32)).collect();
            let k = k.min(by_distance.len());
            if k < by_distance.len() {
                by_distance.select_nth_unstable_by(k, |a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            }
            by_distance.truncate(k);
            by_distance.sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            by_distance.into_iter().map(|(_, v)| v).collect()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::algorithms::procedural::{icosphere, prism};

    #[test]
    fn centre_of_mass_of_a_box_and_a_translated_sphere() {
        let b = prism([2.0, 4.0, 6.0], [2, 3, 4]);
        let c = centre_of_mass(&b.positions, &b.triangles);
        assert!(norm(sub(c, [1.0, 2.0, 3.0])) < 1e-12, "{c:?}");
        let s = icosphere(2);
        let moved: Vec<Point> = s.positions.iter().map(|p| add(*p, [10.0, -3.0, 0.5])).collect();
        assert!(norm(sub(centre_of_mass(&moved, &s.triangles), [10.0, -3.0, 0.5])) < 1e-12);
        // An open surface (one face of the box) falls back to the area centroid.
        let face: Vec<[u32; 3]> = b.triangles.iter().copied().filter(|t| t.iter().all(|&v| b.positions[v as usize][2] == 0.0)).collect();
        assert!(norm(sub(centre_of_mass(&b.positions, &face), [1.0, 2.0, 0.0])) < 1e-12);
    }

    #[test]
    fn frame_is_a_regular_tetrahedron_about_its_centre() {
        let f = tetrahedron_frame([1.0, 2.0, 3.0], 0.5);
        for i in 0..4 {
            for j in i + 1..4 {
                assert!((norm(sub(f[i], f[j])) - 0.5).abs() < 1e-15);
            }
        }
        let c = f.iter().fold([0.0; 3], |a, p| add(a, scale(*p, 0.25)));
        assert!(norm(sub(c, [1.0, 2.0, 3.0])) < 1e-15);
    }

    #[test]
    fn nearest_breaks_ties_by_index() {
        let v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [5.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 0.5]];
        assert_eq!(nearest(&[[0.0; 3]], &v, 3), vec![vec![4, 0, 1]]);
        assert_eq!(nearest(&[[0.0; 3]], &v, 9), vec![vec![4, 0, 1, 3, 2]]);
    }
}
