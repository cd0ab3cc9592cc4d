//! End-to-end tests of the mass-spring model (issue 12's list): target reproduction, the bent
//! bar's volume, zero weights, obstacles, rigid motions, determinism, and input errors.

use std::path::Path;

use super::springs::SpringKind;
use super::testing::bend;
use super::*;
use crate::algorithms::geometry::surface::enclosed_volume;
use crate::algorithms::geometry::{norm, sub, Point, TetMesh, TriMesh};
use crate::algorithms::procedural::prism;
use crate::formats::tetgen::{run as tetrahedralize, TetgenOptions};

/// A 0.25 x 2 x 0.25 bar along +y, and its TetGen body (35 interior nodes).
fn bar() -> (TriMesh, TetMesh) {
    let surface = prism([0.25, 2.0, 0.25], [2, 16, 2]);
    let options = TetgenOptions { quality: 1.414, max_volume: 0.0003, timeout: 60.0 };
    let body = tetrahedralize(&surface, &options, Path::new("bar")).expect("tetgen (apt-get install tetgen)");
    (surface, body)
}

/// The bar straight and bent by `degrees` about its centre line (x = 0.125).
fn bent(surface: &TriMesh, degrees: f64) -> Vec<Point> {
    bend(&surface.positions, 2.0, degrees.to_radians(), 0.125)
}

fn max_distance(a: &[Point], b: &[Point]) -> f64 {
    a.iter().zip(b).map(|(p, q)| norm(sub(*p, *q))).fold(0.0, f64::max)
}

fn size(points: &[Point]) -> f64 {
    crate::algorithms::geometry::bbox_diagonal(points)
}

/// The end of the bar at y = 0 (the same in every target).
fn root(surface: &TriMesh) -> Vec<u32> {
    (0..surface.positions.len() as u32).filter(|&v| surface.positions[v as usize][1] == 0.0).collect()
}

#[test]
fn each_target_is_reproduced_from_its_own_rest_lengths() {
    let (surface, body) = bar();
    let targets = vec![surface.positions.clone(), bent(&surface, 90.0), bent(&surface, -45.0)];
    let t = Targets { surface: &targets, triangles: &surface.triangles, body: Some(&body), body_poses: None };
    for boundary in [Boundary::Fixed(root(&surface)), Boundary::Anchor(None)] {
        let mut model = MassSpring::new(&t, &boundary, &Settings::default()).unwrap();
        // Each target is reached warm from an equilibrium between targets (from another target
        // the start would already be exact: the predictor adds the change of the linear blend).
        for j in [1, 2, 0] {
            let mut w = [0.0; 3];
            w[j] = 1.0;
            model.blend(&[0.2, 0.5, 0.3], &[]).unwrap();
            let shape = model.blend(&w, &[]).unwrap();
            let error = max_distance(&shape.positions, &model.target_pose(j)) / size(&targets[0]);
            assert!(error < 1e-8, "{boundary:?}, target {j}: {error:e} ({:?})", shape.report);
            assert!(shape.report.warm && shape.report.iterations > 1, "it had to move: {:?}", shape.report);
            // The surface is the input target itself.
            assert!(max_distance(shape.surface(), &targets[j]) / size(&targets[0]) < 1e-8);
        }
    }
}

/// Root-mean-square relative deviation of the surface edges from their blended rest lengths.
fn edge_length_error(model: &MassSpring, x: &[Point], weights: &[f64]) -> f64 {
    let springs = model.springs();
    let (mut sum, mut count) = (0.0, 0);
    for q in 0..springs.len() {
        if springs.kinds[q] == SpringKind::Structure {
            let [i, j] = springs.ends[q];
            let rest: f64 = weights.iter().enumerate().map(|(t, w)| w * model.rest_lengths(t)[q]).sum();
            let e = norm(sub(x[i as usize], x[j as usize])) / rest - 1.0;
            sum += e * e;
            count += 1;
        }
    }
    (sum / count as f64).sqrt()
}

#[test]
fn bent_bar_keeps_its_volume_where_the_linear_blend_loses_it() {
    let (surface, body) = bar();
    let targets = vec![surface.positions.clone(), bent(&surface, 90.0)];
    let rest_volume = enclosed_volume(&targets[0], &surface.triangles);
    let bent_volume = enclosed_volume(&targets[1], &surface.triangles);
    assert!((bent_volume / rest_volume - 1.0).abs() < 0.01, "the bend keeps volume: {}", bent_volume / rest_volume);
    let t = Targets { surface: &targets, triangles: &surface.triangles, body: Some(&body), body_poses: None };
    let w = [0.5, 0.5];
    let linear = linear_blend(&targets, &w);
    let linear_volume = enclosed_volume(&linear, &surface.triangles) / rest_volume;
    for boundary in [Boundary::Fixed(root(&surface)), Boundary::Anchor(None)] {
        let mut model = MassSpring::new(&t, &boundary, &Settings::default()).unwrap();
        let shape = model.blend(&w, &[]).unwrap();
        let volume = enclosed_volume(shape.surface(), &surface.triangles) / rest_volume;
        let mut linear_all = model.target_pose(0);
        linear_all[..linear.len()].copy_from_slice(&linear);
        let (e_linear, e_spring) = (edge_length_error(&model, &linear_all, &w), edge_length_error(&model, &shape.positions, &w));
        eprintln!(
            "{boundary:?}: volume linear {:.2}% mass-spring {:.2}% of rest; edge-length error (rms) linear {:.3}% mass-spring {:.3}%; {} iterations",
            100.0 * linear_volume,
            100.0 * volume,
            100.0 * e_linear,
            100.0 * e_spring,
            shape.report.iterations
        );
        assert!(linear_volume < 0.95, "the linear blend loses volume: {linear_volume}");
        assert!((volume - 1.0).abs() < 0.02, "mass-spring keeps volume within 2%: {volume}");
        assert!(e_spring < e_linear, "edge lengths: {e_spring} vs linear {e_linear}");
    }
}

#[test]
fn a_zero_weight_target_changes_nothing() {
    let (surface, body) = bar();
    let three = vec![surface.positions.clone(), bent(&surface, 90.0), bent(&surface, -60.0)];
    let two = three[..2].to_vec();
    for boundary in [Boundary::Fixed(root(&surface)), Boundary::Anchor(None)] {
        let settings = Settings::default();
        let t3 = Targets { surface: &three, triangles: &surface.triangles, body: Some(&body), body_poses: None };
        let t2 = Targets { surface: &two, triangles: &surface.triangles, body: Some(&body), body_poses: None };
        let mut m3 = MassSpring::new(&t3, &boundary, &settings).unwrap();
        let mut m2 = MassSpring::new(&t2, &boundary, &settings).unwrap();
        for (a, b) in [(0.7, 0.3), (0.35, 0.65), (0.0, 1.0)] {
            let s3 = m3.blend(&[a, b, 0.0], &[]).unwrap();
            let s2 = m2.blend(&[a, b], &[]).unwrap();
            assert_eq!(s3.positions, s2.positions, "{boundary:?}, weights {a} {b}");
        }
        // And the third target does take part when weighted.
        let s = m3.blend(&[0.4, 0.3, 0.3], &[]).unwrap();
        assert!(max_distance(&s.positions, &m2.blend(&[0.4, 0.6], &[]).unwrap().positions) > 1e-2);
    }
}

#[test]
fn a_sphere_pushed_into_the_blend_holds_only_surface_vertices_and_none_stays_inside() {
    let (surface, body) = bar();
    let targets = vec![surface.positions.clone(), bent(&surface, 90.0)];
    let t = Targets { surface: &targets, triangles: &surface.triangles, body: Some(&body), body_poses: None };
    let mut model = MassSpring::new(&t, &Boundary::Fixed(root(&surface)), &Settings::default()).unwrap();
    let free = model.blend(&[0.5, 0.5], &[]).unwrap();
    // A sphere centred just outside the bar's outer side at mid-length, reaching well into it.
    let mid =
        (0..surface.positions.len()).filter(|&v| (surface.positions[v][1] - 1.0).abs() < 1e-9 && surface.positions[v][0] == 0.0).collect::<Vec<_>>();
    let (p, q) = (free.positions[mid[0]], free.positions[mid[mid.len() - 1]]);
    let outward = {
        let c = free.surface().iter().fold([0.0; 3], |a, p| crate::algorithms::geometry::add(a, *p));
        let centroid = c.map(|x| x / free.surface().len() as f64);
        let d = sub(p, centroid);
        crate::algorithms::geometry::scale(d, 1.0 / norm(d))
    };
    let touch = crate::algorithms::geometry::scale(crate::algorithms::geometry::add(p, q), 0.5);
    // Deep enough to reach past the centre line, so interior nodes are inside it too.
    let radius = 0.3;
    let center = crate::algorithms::geometry::add(touch, crate::algorithms::geometry::scale(outward, radius - 0.2));
    let sphere = Obstacle::Sphere { center, radius };
    let inside_before = free.surface().iter().filter(|x| sphere.signed_distance(**x) < 0.0).count();
    let interior_before = free.positions[surface.positions.len()..].iter().filter(|x| sphere.signed_distance(**x) < 0.0).count();
    assert!(
        inside_before > 3 && interior_before > 0,
        "the sphere starts inside the shape: {inside_before} surface, {interior_before} interior vertices"
    );
    model.reset_warm_start();
    let shape = model.blend(&[0.5, 0.5], &[sphere]).unwrap();
    let tolerance = Settings::default().tolerance * size(&targets[0]);
    for (v, x) in shape.surface().iter().enumerate() {
        assert!(sphere.signed_distance(*x) >= -tolerance, "surface vertex {v} inside by {}", -sphere.signed_distance(*x));
    }
    assert!(shape.report.held.len() >= inside_before, "{:?}", shape.report.held);
    let on_surface: std::collections::BTreeSet<u32> = surface.triangles.iter().flatten().copied().collect();
    assert!(shape.report.held.iter().all(|v| on_surface.contains(v)), "only surface vertices are held");
    let interior_inside = shape.positions[surface.positions.len()..].iter().filter(|x| sphere.signed_distance(**x) < 0.0).count();
    eprintln!(
        "sphere: {inside_before} surface and {interior_before} interior vertices inside before, {} held in {} rounds, {} interior nodes left inside (allowed)",
        shape.report.held.len(),
        shape.report.solves.len(),
        interior_inside
    );
    // Held vertices sit on the sphere.
    for &v in &shape.report.held {
        assert!(sphere.signed_distance(shape.positions[v as usize]).abs() < 1e-12, "vertex {v}");
    }
}

#[test]
fn rigid_motions_of_the_targets_give_the_rigidly_moved_shape() {
    use super::rigid::{Quaternion, Rigid};
    let (surface, body) = bar();
    let centre = super::rigid::centroid(&surface.positions);
    let about = |axis: Point, degrees: f64, t: Point| {
        let (s, c) = (degrees.to_radians() / 2.0).sin_cos();
        let n = norm(axis);
        Rigid { rotation: Quaternion { w: c, v: axis.map(|a| a / n * s) }, centre, translation: t }
    };
    let motions = [Rigid::identity(centre), about([0.0, 0.0, 1.0], 100.0, [0.5, 0.2, 0.0]), about([1.0, 1.0, 0.0], -70.0, [0.0, -1.0, 0.3])];
    let targets: Vec<Vec<Point>> = motions.iter().map(|m| surface.positions.iter().map(|&p| m.apply(p)).collect()).collect();
    let t = Targets { surface: &targets, triangles: &surface.triangles, body: Some(&body), body_poses: None };
    let mut model = MassSpring::new(&t, &Boundary::Anchor(None), &Settings::default()).unwrap();
    for w in [vec![0.7, 0.3, 0.0], vec![0.2, 0.5, 0.3], vec![0.0, 0.0, 1.0]] {
        let shape = model.blend(&w, &[]).unwrap();
        // A rigid motion of target 0: the best fit leaves no residual, and no spring is strained.
        let fit = Rigid::best_fit(&surface.positions, shape.surface()).unwrap();
        let moved: Vec<Point> = surface.positions.iter().map(|&p| fit.apply(p)).collect();
        let residual = max_distance(&moved, shape.surface()) / size(&surface.positions);
        assert!(residual < 1e-8, "weights {w:?}: {residual:e}");
        assert!(shape.report.energy < 1e-20, "{:?}", shape.report);
        if w[2] == 0.0 {
            // Two targets: the rotation is the slerp of the targets' rotations.
            let expected = motions[0].rotation.slerp(&motions[1].rotation, w[1]);
            assert!(fit.rotation.dot(&expected).abs() > 1.0 - 1e-12, "{:?} vs {expected:?}", fit.rotation);
        }
    }
}

#[test]
fn the_same_blends_give_the_same_bytes() {
    let (surface, body) = bar();
    let targets = vec![surface.positions.clone(), bent(&surface, 90.0), bent(&surface, -45.0)];
    let t = Targets { surface: &targets, triangles: &surface.triangles, body: Some(&body), body_poses: None };
    let sphere = Obstacle::Sphere { center: [0.9, 1.2, 0.125], radius: 0.2 };
    let run = || {
        let mut model = MassSpring::new(&t, &Boundary::Anchor(None), &Settings::default()).unwrap();
        let weights: Vec<Vec<f64>> = (0..=4).map(|i| i as f64 / 4.0).map(|a| vec![1.0 - a, 0.6 * a, 0.4 * a]).collect();
        let shapes = model.blend_batch(&weights, &[sphere]).unwrap();
        shapes.iter().flat_map(|s| s.positions.iter().flatten().map(|c| c.to_bits())).collect::<Vec<u64>>()
    };
    assert_eq!(run(), run());
}

#[test]
fn bad_input_is_refused_with_a_fix() {
    let (surface, _) = bar();
    let targets = vec![surface.positions.clone(), bent(&surface, 30.0)];
    let t = Targets { surface: &targets, triangles: &surface.triangles, body: None, body_poses: None };
    let mut model = MassSpring::new(&t, &Boundary::Fixed(root(&surface)), &Settings::default()).unwrap();
    let problem = |r: crate::Result<Blend>| r.unwrap_err().to_string();
    assert!(problem(model.blend(&[0.5, 0.6], &[])).contains("sum to 1.1, not 1 (fix: give convex weights"));
    assert!(problem(model.blend(&[1.2, -0.2], &[])).contains("weight 2 is -0.2: mass-spring blending takes convex weights only"));
    assert!(problem(model.blend(&[1.0], &[])).contains("1 weights (1) for 2 targets"));
    assert!(problem(model.blend(&[f64::NAN, 1.0], &[])).contains("weight 1 is NaN"));
    let plane = Obstacle::Plane { point: [0.0; 3], normal: [0.0; 3] };
    assert!(problem(model.blend(&[0.5, 0.5], &[plane])).contains("obstacle 1: a plane needs"));
    let error = |boundary: Boundary, t: &Targets| MassSpring::new(t, &boundary, &Settings::default()).err().expect("refused").to_string();
    assert!(error(Boundary::Fixed(vec![0, 1]), &t).contains("the 2 fixed vertices lie on one line"));
    assert!(error(Boundary::Fixed(vec![0, 1, 99999]), &t).contains("fixed vertex 99999 does not exist"));
    assert!(error(Boundary::Anchor(Some(vec![[0.1, 0.5, 0.1], [0.1, 1.0, 0.1], [0.1, 1.5, 0.1]])), &t).contains("anchor points lie on one line"));
    let short = vec![surface.positions.clone(), surface.positions[1..].to_vec()];
    let ts = Targets { surface: &short, ..t };
    assert!(error(Boundary::Anchor(None), &ts).contains("target 1 has"));
    let mut loose = surface.positions.clone();
    loose.push([5.0, 5.0, 5.0]);
    let loose_targets = vec![loose.clone(), loose];
    let tl = Targets { surface: &loose_targets, ..t };
    assert!(error(Boundary::Anchor(None), &tl).contains(&format!("surface vertex {} belongs to no triangle", surface.positions.len())));
    let mut collapsed = targets[1].clone();
    collapsed[1] = collapsed[0];
    let tc_targets = vec![targets[0].clone(), collapsed];
    let tc = Targets { surface: &tc_targets, ..t };
    assert!(error(Boundary::Fixed(root(&surface)), &tc).contains("coincide in target 1"));
    let other = TetMesh { positions: vec![[9.0; 3]; surface.positions.len()], tets: vec![] };
    let tb = Targets { body: Some(&other), ..t };
    assert!(error(Boundary::Anchor(None), &tb).contains("body node 0 is at"));
    let settings = Settings { tolerance: 0.0, ..Settings::default() };
    assert!(MassSpring::new(&t, &Boundary::Anchor(None), &settings).err().unwrap().to_string().contains("tolerance = 0 is not a positive number"));
}

#[test]
fn refinement_before_tetgen_leaves_no_spring_much_longer_than_the_median() {
    use super::refine::{median_edge, regular_tet_volume, split_long_edges};
    // A bar whose long faces are single quads: edges 8x the short ones.
    let coarse = prism([0.25, 2.0, 0.25], [2, 1, 2]);
    let targets = vec![coarse.positions.clone(), bend(&coarse.positions, 2.0, 60f64.to_radians(), 0.125)];
    let refined = split_long_edges(&targets, &coarse.triangles, 1.5);
    let median = median_edge(&refined.surface, &refined.triangles);
    let surface = TriMesh { positions: refined.surface[0].clone(), triangles: refined.triangles.clone(), attributes: None };
    let options = TetgenOptions { quality: 1.414, max_volume: regular_tet_volume(1.5 * median), timeout: 60.0 };
    let body = tetrahedralize(&surface, &options, Path::new("refined bar")).unwrap();
    let t = Targets { surface: &refined.surface, triangles: &refined.triangles, body: Some(&body), body_poses: None };
    let settings = Settings { bending: Bending::None, ..Settings::default() };
    let mut model = MassSpring::new(&t, &Boundary::Anchor(None), &settings).unwrap();
    let (springs, rest) = (model.springs().clone(), model.rest_lengths(0).to_vec());
    let longest = |kind: SpringKind| (0..springs.len()).filter(|&q| springs.kinds[q] == kind).map(|q| rest[q]).fold(0.0, f64::max);
    eprintln!(
        "refined: {} -> {} surface vertices, median edge {median:.3}, longest structure {:.3}, internal {:.3}; summary {:?}",
        coarse.positions.len(),
        refined.surface[0].len(),
        longest(SpringKind::Structure),
        longest(SpringKind::Internal),
        model.summary().longest_over_median
    );
    assert!(longest(SpringKind::Structure) <= 1.5 * median + 1e-12);
    assert!(longest(SpringKind::Internal) <= 3.0 * median, "interior edges stay within a small multiple of the median");
    let shape = model.blend(&[0.5, 0.5], &[]).unwrap();
    // The input's vertices come first, in their order; the blend covers the refined surface.
    assert_eq!(refined.surface[0][..coarse.positions.len()], coarse.positions[..]);
    assert_eq!(shape.surface().len(), refined.surface[0].len());
}
