//! Mass-spring blendshapes (Ma et al. 2012, issue 12) through the CLI: `blendsim blend` on a
//! bar straight and bent by 90° (OBJ targets written here), its weights file written as a PC2
//! cache and an OBJ sequence, its bad input (one line, exit 1, nothing written), and
//! `[solver] method = "mass-spring"` baked on a keyframe scene of the same bar, every file
//! checked by the independent tools.

use std::path::Path;

use blendsim::algorithms::geometry::surface::enclosed_volume;
use blendsim::algorithms::geometry::{norm, sub, Point, TriMesh};
use blendsim::algorithms::procedural::prism;
use blendsim::formats::cache::{CacheOptions, VertexCache};
use blendsim::formats::mesh::obj;
use blendsim::pipeline::scene::Method;

use crate::common::cli::{read_json, run, tree, Run, TempDir};
use crate::common::verify::{check_outputs, library_animation_with, max_distance, output_files};

/// A 0.25 x 2 x 0.25 bar along +y.
fn bar() -> TriMesh {
    prism([0.25, 2.0, 0.25], [2, 16, 2])
}

/// The bar bent into a quarter circle in the xy plane about its centre line x = 0.125 (which
/// keeps its length; the bend keeps the volume).
fn bent(points: &[Point], degrees: f64) -> Vec<Point> {
    let angle = degrees.to_radians();
    let radius = 2.0 / angle;
    let centre_x = 0.125 + radius;
    points
        .iter()
        .map(|p| {
            let phi = angle * p[1] / 2.0;
            let rho = centre_x - p[0];
            [centre_x - rho * phi.cos(), rho * phi.sin(), p[2]]
        })
        .collect()
}

/// Write the straight bar as a.obj, bent by 90° as b.obj and by -60° as c.obj.
pub(crate) fn targets(dir: &TempDir) -> TriMesh {
    let mesh = bar();
    for (name, degrees) in [("a.obj", 0.0), ("b.obj", 90.0), ("c.obj", -60.0)] {
        let positions = if degrees == 0.0 { mesh.positions.clone() } else { bent(&mesh.positions, degrees) };
        std::fs::write(dir.join(name), obj::write(&TriMesh { positions, triangles: mesh.triangles.clone(), attributes: None })).unwrap();
    }
    mesh
}

fn volume_ratio(path: &Path, rest: &TriMesh) -> f64 {
    let shape = obj::read(path).unwrap();
    assert_eq!(shape.triangles, rest.triangles, "{}: the blend keeps the targets' triangles", path.display());
    enclosed_volume(&shape.positions, &shape.triangles) / enclosed_volume(&rest.positions, &rest.triangles)
}

#[test]
fn blend_keeps_the_bent_bars_volume_where_the_linear_blend_loses_it() {
    let dir = TempDir::new("blend-bar");
    let rest = targets(&dir);
    run(&dir.path, &["blend", "-q", "--targets", "a.obj", "b.obj", "--weights", "0.5,0.5", "--out", "spring.obj"]).success();
    run(&dir.path, &["blend", "-q", "--targets", "a.obj", "b.obj", "--weights", "0.5,0.5", "--out", "linear.obj", "--linear"]).success();
    let (spring, linear) = (volume_ratio(&dir.join("spring.obj"), &rest), volume_ratio(&dir.join("linear.obj"), &rest));
    eprintln!("bar bent 90°, alpha 0.5: volume linear {:.2}%, mass-spring {:.2}% of rest", 100.0 * linear, 100.0 * spring);
    assert!(linear < 0.9, "the linear blend loses volume: {linear}");
    assert!((spring - 1.0).abs() < 0.02, "mass-spring keeps the volume within 2%: {spring}");

    // A zero weight on a third target changes nothing (to the solver's tolerance), and the
    // targets themselves come back.
    run(&dir.path, &["blend", "-q", "--targets", "a.obj", "b.obj", "c.obj", "--weights", "0.5,0.5,0", "--out", "three.obj"]).success();
    let shape = |name: &str| obj::read(&dir.join(name)).unwrap().positions;
    let diagonal = 2.0;
    assert!(max_distance(&shape("three.obj"), &shape("spring.obj")) < 1e-5 * diagonal);
    run(&dir.path, &["blend", "-q", "--targets", "a.obj", "b.obj", "--weights", "0,1", "--out", "b_again.obj"]).success();
    assert!(max_distance(&shape("b_again.obj"), &shape("b.obj")) < 1e-6 * diagonal);

    // With the bar's end held (fixed vertices follow the linear blend, which is the identity
    // there) the blend keeps the volume too.
    let root: Vec<String> = (0..rest.positions.len()).filter(|&v| rest.positions[v][1] == 0.0).map(|v| v.to_string()).collect();
    std::fs::write(dir.join("root.txt"), root.join("\n")).unwrap();
    run(&dir.path, &["blend", "-q", "--targets", "a.obj", "b.obj", "--weights", "0.5,0.5", "--fixed", "root.txt", "--out", "held.obj"]).success();
    let held = shape("held.obj");
    assert!((volume_ratio(&dir.join("held.obj"), &rest) - 1.0).abs() < 0.02);
    for v in root.iter().map(|s| s.parse::<usize>().unwrap()) {
        assert_eq!(held[v], rest.positions[v], "fixed vertex {v} stays");
    }

    // Same input, same bytes.
    run(&dir.path, &["blend", "-q", "--targets", "a.obj", "b.obj", "--weights", "0.5,0.5", "--out", "spring2.obj"]).success();
    assert!(std::fs::read(dir.join("spring.obj")).unwrap() == std::fs::read(dir.join("spring2.obj")).unwrap());
}

#[test]
fn a_weights_file_becomes_a_pc2_cache_and_an_obj_sequence() {
    let dir = TempDir::new("blend-weights-file");
    let rest = targets(&dir);
    std::fs::write(dir.join("w.txt"), "# alpha 0, 0.25, 0.5 (blank lines and comments are skipped)\n1, 0\n\n0.75 0.25\n0.5,0.5  # half\n").unwrap();
    run(&dir.path, &["blend", "-q", "--targets", "a.obj", "b.obj", "--weights-file", "w.txt", "--out", "w.pc2", "--fps", "30"]).success();
    std::fs::create_dir(dir.join("frames")).unwrap();
    run(&dir.path, &["blend", "-q", "--targets", "a.obj", "b.obj", "--weights-file", "w.txt", "--out", "frames/frame_####.obj"]).success();
    run(&dir.path, &["blend", "-q", "--targets", "a.obj", "b.obj", "--weights", "0.5,0.5", "--out", "half.obj"]).success();
    let half = obj::read(&dir.join("half.obj")).unwrap().positions;

    let options = CacheOptions { fps: Some(30.0), rest: Some(dir.join("a.obj")), ..Default::default() };
    let mut cache = VertexCache::open(&dir.join("w.pc2"), &options).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!((cache.frames.frame_count(), cache.fps), (3, 30.0));
    let mut frame = vec![[0.0; 3]; rest.positions.len()];
    cache.frames.read_frame(0, &mut frame).unwrap();
    assert!(max_distance(&frame, &rest.positions) < 1e-6, "weights 1,0 give target a (f32)");
    cache.frames.read_frame(2, &mut frame).unwrap();
    // The third blend was warm-started from the second, the single one cold: equal to the
    // solver's tolerance, then f32.
    assert!(max_distance(&frame, &half) < 1e-5, "the file's last line is the single blend 0.5,0.5");

    // (The sequence writer's staging keeps a manifest of its files beside them.)
    let names: Vec<String> = tree(&dir.join("frames")).into_iter().filter(|n| n.ends_with(".obj")).collect();
    assert_eq!(names.len(), 3, "{names:?}");
    let third = obj::read(&dir.join("frames").join(&names[2])).unwrap();
    assert_eq!(third.triangles, rest.triangles);
    assert!(max_distance(&third.positions, &half) < 1e-5);
}

/// A failed blend: exit 1, one line on stderr naming the problem, no file left behind.
fn refused(dir: &TempDir, args: &[&str], says: &[&str]) -> Run {
    let before = tree(&dir.path);
    let r = run(&dir.path, args);
    assert_eq!(r.code, Some(1), "{r}");
    let lines: Vec<&str> = r.stderr.lines().filter(|l| !l.trim().is_empty()).collect();
    assert_eq!(lines.len(), 1, "one line: {r}");
    assert!(lines[0].starts_with("error: "), "{r}");
    for s in says {
        assert!(lines[0].contains(s), "{s:?} missing in {:?}", lines[0]);
    }
    assert_eq!(tree(&dir.path), before, "nothing written by {args:?}");
    r
}

#[test]
fn bad_blend_input_is_one_line_and_writes_nothing() {
    let dir = TempDir::new("blend-bad");
    let rest = targets(&dir);
    let out = ["--out", "shape.obj"];
    let blend =
        |extra: &[&str]| -> Vec<String> { ["blend", "--targets", "a.obj", "b.obj"].iter().chain(extra).chain(&out).map(|s| s.to_string()).collect() };
    let args = |v: &Vec<String>| v.clone();
    let check = |extra: &[&str], says: &[&str]| {
        let v = args(&blend(extra));
        let v: Vec<&str> = v.iter().map(String::as_str).collect();
        refused(&dir, &v, says);
    };
    check(&["--weights", "0.7,0.7"], &["--weights", "sum to 1.4", "convex"]);
    check(&["--weights", "-0.2,1.2"], &["weight 1 is -0.2", "negative", "convex"]);
    check(&["--weights", "1"], &["1 weights", "2 targets"]);
    std::fs::write(dir.join("w.txt"), "0.5,0.5\n0.9,0.3\n").unwrap();
    let v: Vec<&str> = vec!["blend", "--targets", "a.obj", "b.obj", "--weights-file", "w.txt", "--out", "w.pc2"];
    refused(&dir, &v, &["w.txt", "line 2", "sum to 1.2"]);
    std::fs::write(dir.join("w.txt"), "0.5,zero\n").unwrap();
    refused(&dir, &v, &["w.txt", "line 1", "\"zero\" is not a number"]);
    let v: Vec<&str> = vec!["blend", "--targets", "a.obj", "b.obj", "--weights-file", "w.txt", "--out", "one.obj"];
    refused(&dir, &v, &["one.obj", "OBJ sequence"]);

    // Targets that are not one mesh.
    let mut fewer = rest.clone();
    fewer.positions.push([9.0, 9.0, 9.0]);
    std::fs::write(dir.join("d.obj"), obj::write(&fewer)).unwrap();
    let counts = format!("has {} vertices but a.obj has {}", rest.positions.len() + 1, rest.positions.len());
    refused(&dir, &["blend", "--targets", "a.obj", "d.obj", "--weights", "0.5,0.5", "--out", "shape.obj"], &["d.obj", &counts, "one mesh"]);
    let mut flipped = rest.clone();
    flipped.triangles[0].swap(1, 2);
    std::fs::write(dir.join("e.obj"), obj::write(&flipped)).unwrap();
    refused(&dir, &["blend", "--targets", "a.obj", "e.obj", "--weights", "0.5,0.5", "--out", "shape.obj"], &["e.obj", "other triangles"]);
    refused(&dir, &["blend", "--targets", "a.obj", "missing.obj", "--weights", "0.5,0.5", "--out", "shape.obj"], &["missing.obj"]);

    // An open surface cannot be tetrahedralized: the fix names --no-body, which then works.
    let mut open = rest.clone();
    open.triangles.pop();
    std::fs::write(dir.join("open_a.obj"), obj::write(&open)).unwrap();
    std::fs::write(
        dir.join("open_b.obj"),
        obj::write(&TriMesh { positions: bent(&open.positions, 90.0), triangles: open.triangles.clone(), attributes: None }),
    )
    .unwrap();
    refused(
        &dir,
        &["blend", "--targets", "open_a.obj", "open_b.obj", "--weights", "0.5,0.5", "--out", "shape.obj"],
        &["open_a.obj", "not a closed surface", "--no-body"],
    );
    run(&dir.path, &["blend", "-q", "--targets", "open_a.obj", "open_b.obj", "--weights", "0.5,0.5", "--out", "open.obj", "--no-body"]).success();

    // Obstacles: a degenerate one is refused; a sphere pushed into the blend leaves no
    // surface vertex inside.
    std::fs::write(dir.join("o.toml"), "[[obstacle]]\nkind = \"sphere\"\ncenter = [0, 1, 0]\nradius = -1\n").unwrap();
    refused(
        &dir,
        &["blend", "--targets", "a.obj", "b.obj", "--weights", "0.5,0.5", "--obstacles", "o.toml", "--out", "shape.obj"],
        &["o.toml", "positive radius"],
    );
    let half = {
        run(&dir.path, &["blend", "-q", "--targets", "a.obj", "b.obj", "--weights", "0.5,0.5", "--out", "free.obj"]).success();
        obj::read(&dir.join("free.obj")).unwrap().positions
    };
    // A sphere whose surface passes 0.05 inside the middle of the blended bar's outer side.
    let middle = (0..half.len()).filter(|&v| (rest.positions[v][1] - 1.0).abs() < 1e-9).min_by(|&a, &b| half[a][0].total_cmp(&half[b][0])).unwrap();
    let radius = 0.3;
    let centre = [half[middle][0] - radius + 0.05, half[middle][1], half[middle][2]];
    std::fs::write(dir.join("o.toml"), format!("[[obstacle]]\nkind = \"sphere\"\ncenter = {centre:?}\nradius = {radius}\n")).unwrap();
    run(&dir.path, &["blend", "-q", "--targets", "a.obj", "b.obj", "--weights", "0.5,0.5", "--obstacles", "o.toml", "--out", "pushed.obj"]).success();
    let pushed = obj::read(&dir.join("pushed.obj")).unwrap().positions;
    let inside = pushed.iter().filter(|p| norm(sub(**p, centre)) < radius * (1.0 - 1e-6)).count();
    assert_eq!(inside, 0, "no surface vertex stays inside the sphere");
    assert!(max_distance(&pushed, &half) > 0.04, "the sphere pushed the shape");
}

const SCENE: &str = r#"
name = "bend"
fps = 24.0

[keyframes]
meshes = ["a.obj", "b.obj", "c.obj"]
times = [0.0, 1.0, 2.0]

[tet]
max_volume = 0.0003

[solver]
method = "mass-spring"

[mass_spring]
inbetweens = 3

[export]
formats = ["usda", "glb"]
"#;

#[test]
fn mass_spring_scene_keeps_volume_and_its_files_pass_the_checkers() {
    let dir = TempDir::new("blend-scene");
    targets(&dir);
    std::fs::write(dir.join("bend.toml"), SCENE).unwrap();
    run(&dir.path, &["bake", "-q", "bend.toml", "--out", "out"]).success();
    let report = read_json(&dir.join("out/report.json"));
    assert_eq!(report["solver"]["method"], "mass-spring");
    // Keys reproduced, the in-betweens keep the volume the hermite (linear) in-betweens lose.
    let deviation = report["keyframe_deviation"]["max"].as_f64().unwrap_or_else(|| panic!("{}", report["keyframe_deviation"]));
    assert!(deviation < 1e-9, "keys: {deviation}");
    let volume = &report["volume"];
    let (spring_min, hermite_min) = (volume["animation"]["min"].as_f64().unwrap(), volume["hermite"]["min"].as_f64().unwrap());
    eprintln!(
        "volume over the frames, fraction of rest: mass-spring min {spring_min:.4}, hermite min {hermite_min:.4}; W {}",
        report["solver"]["energy"]
    );
    assert!(hermite_min < 0.9, "the hermite in-betweens lose volume: {volume}");
    assert!(spring_min > 0.97, "mass-spring in-betweens keep it: {volume}");

    let anim = library_animation_with(&dir.join("bend.toml"), Some(Method::MassSpring));
    assert_eq!(anim.trajectory.key_count(), 3 + 2 * 3, "keys and 3 in-betweens per interval");
    check_outputs(&dir.join("out"), &anim, &output_files(&report["outputs"]));
    // Its stage files (in-betweens as trajectory keys) pass the stage readers' checks, and the
    // chain of subcommands gives the bake's bytes.
    crate::common::cli::assert_chain_gives_bake_bytes(&dir.path, "bend.toml", "out", &["bend.usda", "bend.glb"]);
}

/// The straight bar at t = 0 and bent by 90° at t = 1, at 24 frames per second, with
/// `inbetweens` mass-spring in-betweens and the given `[[obstacle]]` tables; the default anchor
/// holds it (no fixed vertices).
fn obstacle_scene(inbetweens: usize, obstacles: &str) -> String {
    format!(
        "name = \"bend\"\nfps = 24.0\n[keyframes]\nmeshes = [\"a.obj\", \"b.obj\"]\ntimes = [0.0, 1.0]\n[tet]\nmax_volume = 0.0003\n[solver]\nmethod = \"mass-spring\"\n[mass_spring]\ninbetweens = {inbetweens}\n{obstacles}\n[export]\nformats = [\"usda\", \"glb\"]\nfull_frame = true\n"
    )
}

/// The direction (in the bend's plane) in which the bending bar reaches further between the
/// keys than at either key: its support along it is 1.89 at both keys and 2.04 at a 50° bend
/// (measured on the constant-length bend of `bent`).
fn sweep_direction() -> Point {
    let a = 62f64.to_radians();
    [a.cos(), a.sin(), 0.0]
}

/// Deepest penetration (positive inside) of the surface into the obstacle `inside` (signed
/// distance, negative inside) over every frame of the trajectory.
fn deepest(anim: &blendsim::pipeline::stage_file::Animation, signed: impl Fn(Point) -> f64) -> f64 {
    let tr = &anim.trajectory;
    tr.frames(anim.scene.fps).iter().flat_map(|&(_, t)| tr.evaluate(t)).map(|p| -signed(p)).fold(f64::NEG_INFINITY, f64::max)
}

/// Frames between the in-betweens are Hermite-interpolated; with an in-between at every frame
/// (`inbetweens` = frames per interval - 1) every exported frame is an equilibrium. Measured
/// here: how far the interpolated frames of 3 in-betweens per interval are from those
/// equilibria, and how deep they enter an obstacle that every equilibrium stays out of.
#[test]
fn interpolated_frames_deviate_from_the_per_frame_equilibria_by_a_measured_amount() {
    let dir = TempDir::new("blend-frames");
    targets(&dir);
    let n = sweep_direction();
    let (centre, radius) = (n.map(|c| 2.2 * c), 0.3);
    let sphere = format!("[[obstacle]]\nkind = \"sphere\"\ncenter = {centre:?}\nradius = {radius}\n");
    let mut measured = Vec::new();
    for (name, obstacles) in [("free", String::new()), ("sphere", sphere)] {
        let anim = |inbetweens: usize| {
            let scene = dir.join(format!("{name}-{inbetweens}.toml"));
            std::fs::write(&scene, obstacle_scene(inbetweens, &obstacles)).unwrap();
            library_animation_with(&scene, None)
        };
        let (coarse, every) = (anim(3), anim(23));
        assert_eq!(every.trajectory.key_count(), 25, "an equilibrium at every frame");
        // The log says which frames are equilibria.
        assert!(every.log.stop_reason.contains("every frame is an equilibrium"), "{}", every.log.stop_reason);
        assert!(
            coarse.log.stop_reason.contains("20 of 25 frames fall between in-betweens and are Hermite-interpolated"),
            "{}",
            coarse.log.stop_reason
        );
        let size = blendsim::algorithms::geometry::bbox_diagonal(&every.trajectory.positions[0]);
        let deviation = coarse
            .trajectory
            .frames(24.0)
            .iter()
            .map(|&(_, t)| max_distance(&coarse.trajectory.evaluate(t), &every.trajectory.evaluate(t)))
            .fold(0.0, f64::max)
            / size;
        let depth = |a: &blendsim::pipeline::stage_file::Animation| deepest(a, |p| norm(sub(p, centre)) - radius) / size;
        eprintln!("{name}: interpolated frames (3 in-betweens) vs an equilibrium per frame: max deviation {:.3e} of the size; deepest in the sphere: {:.3e} (3 in-betweens), {:.3e} (every frame)", deviation, depth(&coarse), depth(&every));
        measured.push((deviation, depth(&coarse), depth(&every)));
    }
    let (free, pushed) = (measured[0], measured[1]);
    // Without obstacles the interpolated frames are close to equilibria: the in-betweens
    // follow a smooth family of shapes.
    assert!(free.0 > 0.0 && free.0 < 0.02, "free bend: {free:?}");
    // With the sphere, frames between the in-betweens cut into it, equilibria at every frame do not.
    assert!(pushed.1 > 1e-3, "the interpolated frames enter the sphere: {pushed:?}");
    assert!(pushed.2 <= 1e-6, "an equilibrium at every frame stays out: {pushed:?}");
}

/// A mass-spring scene on the default anchor with a plane and then a sphere in the bending
/// bar's way (but clear of both keys), an equilibrium at every frame: the obstacle pushes the
/// in-betweens, no surface vertex is inside it at any frame of the exported animation, and
/// every file passes usd-core, the glTF validator and three.js and plays that animation.
#[test]
fn mass_spring_scene_with_a_plane_or_a_sphere_keeps_every_frame_outside() {
    let dir = TempDir::new("blend-obstacles");
    targets(&dir);
    let n = sweep_direction();
    let level = 1.95;
    let (centre, radius) = (n.map(|c| 2.2 * c), 0.3);
    let plane = format!("[[obstacle]]\nkind = \"plane\"\npoint = {:?}\nnormal = {:?}\n", n.map(|c| level * c), n.map(|c| -c));
    let sphere = format!("[[obstacle]]\nkind = \"sphere\"\ncenter = {centre:?}\nradius = {radius}\n");
    let free = {
        std::fs::write(dir.join("free.toml"), obstacle_scene(23, "")).unwrap();
        library_animation_with(&dir.join("free.toml"), None)
    };
    let plane_signed = |p: Point| level - (p[0] * n[0] + p[1] * n[1] + p[2] * n[2]);
    let sphere_signed = |p: Point| norm(sub(p, centre)) - radius;
    let size = blendsim::algorithms::geometry::bbox_diagonal(&free.trajectory.positions[0]);
    for (name, obstacle, signed) in [("plane", plane, &plane_signed as &dyn Fn(Point) -> f64), ("sphere", sphere, &sphere_signed)] {
        // Without the obstacle the bar would enter it between the keys; the keys are clear.
        let free_depth = deepest(&free, signed);
        assert!(free_depth > 0.05, "{name}: the free bend enters the obstacle by {free_depth}");
        for key in &free.input_keys {
            assert!(key.iter().all(|&p| signed(p) > 0.0), "{name}: the keys are outside");
        }
        let scene = format!("{name}.toml");
        std::fs::write(dir.join(&scene), obstacle_scene(23, &obstacle)).unwrap();
        let out = format!("out-{name}");
        run(&dir.path, &["bake", "-q", &scene, "--out", &out]).success();
        let report = read_json(&dir.join(&out).join("report.json"));
        assert_eq!(report["solver"]["method"], "mass-spring");
        let stop = report["solver"]["stop_reason"].as_str().unwrap();
        assert!(stop.contains("default anchor") && stop.contains("vertex holds on obstacles"), "{name}: {stop}");
        let anim = library_animation_with(&dir.join(&scene), None);
        let depth = deepest(&anim, signed);
        eprintln!("{name}: deepest surface vertex over the frames {depth:.3e} (free bend: {free_depth:.3e}); {stop}");
        assert!(depth <= 1e-6 * size, "{name}: a surface vertex is {depth} inside at some frame");
        let moved = anim
            .trajectory
            .frames(24.0)
            .iter()
            .map(|&(_, t)| max_distance(&anim.trajectory.evaluate(t), &free.trajectory.evaluate(t)))
            .fold(0.0, f64::max);
        assert!(moved > 0.03, "{name}: the obstacle pushed the bar ({moved})");
        let deviation = report["keyframe_deviation"]["max"].as_f64().unwrap();
        assert!(deviation < 1e-9, "{name}: keys {deviation}");
        check_outputs(&dir.join(&out), &anim, &output_files(&report["outputs"]));
    }
}
