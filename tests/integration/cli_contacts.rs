//! Obstacles through the CLI: a first guess inside an obstacle (a key the user holds there is a
//! clear error; a free key is put on the obstacle's surface and the scene bakes), a body pushed
//! into a sphere, and the paper's BALL and SPOT scenes (`fixtures/paper/`), every file checked
//! by usd-core, the glTF validator and three.js, and no vertex inside an obstacle at any frame.

use std::path::Path;

use blendsim::algorithms::geometry::{norm, sub, Point};
use blendsim::pipeline::stage_file::Animation;
use serde_json::Value;

use crate::cli_physics::cube_medit;
use crate::common::assets::paper_scene;
use crate::common::cli::{key_times, read_json, run, TempDir};
use crate::common::verify::{check_outputs, library_animation, output_files};

/// The smallest `distance` of any exported vertex at any frame of the full-frame output.
fn lowest(anim: &Animation, distance: impl Fn(Point) -> f64) -> f64 {
    let tr = &anim.trajectory;
    tr.frames(anim.scene.fps).iter().flat_map(|(_, t)| tr.evaluate(*t)).map(&distance).fold(f64::INFINITY, f64::min)
}

/// The bounding-box diagonal of some points.
fn diagonal(points: &[Point]) -> f64 {
    let lo: Point = std::array::from_fn(|c| points.iter().map(|p| p[c]).fold(f64::INFINITY, f64::min));
    let hi: Point = std::array::from_fn(|c| points.iter().map(|p| p[c]).fold(f64::NEG_INFINITY, f64::max));
    norm(sub(hi, lo))
}

/// Bake `scene` (in `cwd`) into `cwd/out` and check every file against the library's animation.
pub(crate) fn bake_and_check(cwd: &Path, scene: &Path) -> (Value, Animation) {
    let r = run(cwd, &["bake", scene.to_str().unwrap(), "--out", "out"]).success();
    eprintln!("{}", r.stderr.trim_end());
    let report = read_json(&cwd.join("out/report.json"));
    let anim = library_animation(scene);
    check_outputs(&cwd.join("out"), &anim, &output_files(&report["outputs"]));
    (report, anim)
}

/// A soft body falling freely under gravity (no damping): the material of the drop scenes.
pub(crate) const FALLING: &str = "[material]\nstiffness = 60.0\nvolume = 60.0\ndamping = 0.0\ngravity = [0.0, -9.81, 0.0]\n";

/// The floor `y = 0` as a scene's obstacle.
pub(crate) const FLOOR: &str = "[[obstacle]]\nkind = \"plane\"\npoint = [0.0, 0.0, 0.0]\nnormal = [0.0, 1.0, 0.0]\n";

/// A unit cube of 3 x 3 x 3 cells with its lowest corner at `at`.
fn cube_at(at: Point) -> String {
    cube_medit(3, |p| std::array::from_fn(|c| p[c] + at[c]))
}

/// A cube dropped from rest onto the floor y = 0 and bouncing back up, its contact key given
/// 0.2 below the floor: `fixed` at the contact key decides who may move it.
fn sunk_cube_scene(dir: &TempDir, contact_fixed: &str) {
    for (name, y) in [("high.mesh", 1.2), ("sunk.mesh", -0.2)] {
        std::fs::write(dir.join(name), cube_at([0.0, y, 0.0])).unwrap();
    }
    let scene = format!(
        r#"
name = "sunk"
fps = 30
[keyframes]
meshes = ["high.mesh", "sunk.mesh", "high.mesh"]
times = [0.0, 0.5, 1.0]
contact = [1]
fixed = ["all", "{contact_fixed}", "all"]
fixed_velocity = ["all", "none", "none"]
{FALLING}[solver]
samples = 10
max_iterations = 100
{FLOOR}[export]
formats = ["usda", "glb"]
"#
    );
    std::fs::write(dir.join("scene.toml"), scene).unwrap();
}

#[test]
fn a_key_held_inside_the_floor_is_a_one_line_error() {
    let dir = TempDir::new("contact-held-inside");
    sunk_cube_scene(&dir, "all");
    let r = run(&dir.path, &["bake", "scene.toml", "--out", "out"]);
    assert_eq!(r.code, Some(1), "{r}");
    let err = r.stderr.trim_end();
    assert_eq!(err.lines().count(), 1, "{err}");
    for want in [
        "scene.toml",
        "the keyframe at t = 0.5000 s holds 16 node(s) inside obstacle 1 (a plane)",
        "by 2.0000e-1",
        "fix: move that keyframe's mesh out of the obstacle",
    ] {
        assert!(err.contains(want), "{want:?} not in: {err}");
    }
    assert!(!dir.join("out").exists(), "no partial output");
}

#[test]
fn a_free_key_inside_the_floor_is_put_on_it_and_bakes() {
    // The contact key's first guess is 0.2 below the floor, its vertices free: the solver starts
    // from them projected onto the floor, and nothing is below it at any frame.
    let dir = TempDir::new("contact-free-inside");
    sunk_cube_scene(&dir, "none");
    let (report, anim) = bake_and_check(&dir.path, &dir.join("scene.toml"));
    let tolerance = 1e-4 * diagonal(&anim.trajectory.positions[0]);
    let floor = lowest(&anim, |p| p[1]);
    let key = anim.trajectory.positions[1].iter().map(|p| p[1]).fold(f64::INFINITY, f64::min);
    println!(
        "sunk cube: lowest vertex over the frames {floor:.3e}, at the contact key {key:.3e}; clearance {}; {}",
        report["solver"]["clearance"], report["solver"]["stop_reason"]
    );
    assert!(floor >= -tolerance, "a vertex at {floor}");
    assert!(key.abs() < 0.05, "the contact pose rests on the floor: lowest at {key}");
    assert_eq!(anim.trajectory.positions[1], anim.trajectory.positions[2], "one contact pose");
}

#[test]
fn a_body_pushed_into_a_sphere_stays_outside_it() {
    // A cube slid 4 units along x past a sphere whose top is 0.2 above the cube's bottom face:
    // the straight first guess passes through the sphere; the result goes over it.
    let dir = TempDir::new("contact-sphere");
    std::fs::write(dir.join("left.mesh"), cube_at([-2.5, 0.0, 0.0])).unwrap();
    std::fs::write(dir.join("right.mesh"), cube_at([1.5, 0.0, 0.0])).unwrap();
    let (center, radius) = ([0.0, -0.3, 0.5], 0.5);
    let scene = format!(
        r#"
name = "sphere"
fps = 30
[keyframes]
meshes = ["left.mesh", "right.mesh"]
times = [0.0, 1.0]
[material]
stiffness = 60.0
volume = 60.0
[solver]
samples = 10
[[obstacle]]
kind = "sphere"
center = {center:?}
radius = {radius}
[export]
formats = ["usda", "glb"]
"#
    );
    std::fs::write(dir.join("scene.toml"), scene).unwrap();
    let (report, anim) = bake_and_check(&dir.path, &dir.join("scene.toml"));
    let tolerance = 1e-4 * diagonal(&anim.trajectory.positions[0]);
    let clearance = lowest(&anim, |p| norm(sub(p, center)) - radius);
    // The first guess (the keys joined with zero velocities) does go through it.
    let guess = |t: f64| {
        let s = t * t * (3.0 - 2.0 * t);
        anim.trajectory.positions[0].iter().map(|p| norm(sub([p[0] + 4.0 * s, p[1], p[2]], center)) - radius).fold(f64::INFINITY, f64::min)
    };
    println!("sphere: clearance over the frames {clearance:.3e} (first guess at t = 0.5: {:.3e}); {}", guess(0.5), report["solver"]["stop_reason"]);
    assert!(guess(0.5) < -0.1);
    assert!(clearance >= -tolerance, "a vertex {clearance} inside the sphere");
}

/// A paper scene with a floor at y = 0, baked with the default stopping rule: converged, no
/// vertex below the floor at any frame, the files checked, the motion an exact free fall, and
/// the contact where the free fall from the first key meets the floor (BALL) or where the free
/// fall is at the contact time (SPOT, whose contact pose is free).
fn paper_bounce(name: &str) {
    let Some(scene) = paper_scene(name) else { return };
    let dir = TempDir::new(&format!("paper-{name}"));
    let (report, anim) = bake_and_check(&dir.path, &scene);
    let t = key_times(&report);
    let g = 9.81;
    let drop = anim.trajectory.positions[0].iter().map(|p| p[1]).fold(f64::INFINITY, f64::min);
    let parabola = (2.0 * drop / g).sqrt();
    let diameter = diagonal(&anim.trajectory.positions[0]);
    let floor = lowest(&anim, |p| p[1]);
    let solver = &report["solver"];
    println!(
        "{name}: {} vertices, {} tet nodes; contact at {:.6} s (parabola {parabola:.6}), lowest vertex {floor:.3e} ({:.2e} of the diameter), W {:.3e} -> {:.3e}, {} iterations, {:.3} s per iteration; {}",
        report["vertices"],
        report["tet_nodes"],
        t[1],
        floor / diameter,
        solver["energy"][0].as_f64().unwrap(),
        solver["energy"].as_array().unwrap().last().unwrap().as_f64().unwrap(),
        solver["iterations"],
        solver["iteration_seconds"].as_f64().unwrap(),
        solver["stop_reason"]
    );
    assert_eq!(t.len(), 4);
    assert_eq!(t[1], t[2], "a contact is a zero-length interval");
    assert!(solver["converged"].as_bool().unwrap(), "{}", solver["stop_reason"]);
    assert!(floor >= -1e-4 * diameter, "a vertex at {floor}");
    // The fall from the first key, and the rise to the last, are exact parabolas (W / S, the
    // squared relative residual force, far below the 1e-3 of the stopping rule's floor).
    let w_over_s = solver["energy"].as_array().unwrap().last().unwrap().as_f64().unwrap() / solver["force_scale"].as_f64().unwrap();
    assert!(w_over_s < 1e-4, "W = {w_over_s:e} S");
    if name == "ball" {
        // BALL's contact pose is held on the floor: one contact time is exact, the parabola's.
        assert!((t[1] - parabola).abs() < 2e-3, "contact at {} vs {parabola}", t[1]);
    } else {
        // SPOT's contact pose is free (only kept out of the floor): every contact time up to the
        // parabola's is an exact bounce (W = 0), the pose at the free-fall height of that time,
        // so W does not choose one and neither can the stopping rule (measured: 0.4544 s after
        // 1000 iterations, 0.4516 s at the default stop after 383, against 0.4565 s). What is
        // asserted is the physics: the contact pose is where the free fall is at the contact
        // time, and never below the floor (the contact is at most the parabola's time).
        let contact_low = anim.trajectory.positions[1].iter().map(|p| p[1]).fold(f64::INFINITY, f64::min);
        let fall = drop - 0.5 * g * t[1] * t[1];
        println!("spot: contact pose's lowest vertex {contact_low:.5e}, free-fall height at the contact time {fall:.5e}");
        // Measured 2.5e-3 apart (1e-3 of the diameter; the pose is elastic) with the floor 2.2e-2
        // below: the pose is where the fall is, not where the floor is.
        assert!((contact_low - fall).abs() < 3e-3 * diameter, "contact pose at {contact_low} vs the free fall's {fall}");
        // And the drift along that family stays small (5%).
        assert!(t[1] < parabola + 1e-3 * parabola && t[1] > 0.95 * parabola, "contact at {} vs {parabola}", t[1]);
    }
}

#[test]
fn paper_ball_bounces_at_the_parabola_time() {
    paper_bounce("ball");
}

#[test]
fn paper_spot_bounces_at_the_parabola_time() {
    paper_bounce("spot");
}
