//! The paper's scenes that need no collision or timing, baked with the CLI from the scene
//! files in `fixtures/paper/` (STRETCH cyclic, TWIST, DINO: tet meshes given), plus an OBJ
//! scene from the paper's prism that goes through TetGen.
//!
//! For each: exit 0, a converged solve whose W never increases (with the scene's proximal
//! regularization on), and every output file checked by the independent tools against the
//! library's own evaluation of the same scene. TWIST: the in-between volume loss of the
//! hermite baseline, measured here with our own volume and Hermite code, is at least 5 times
//! that of the spacetime solution.
//!
//! The assets live in `../shared/assets/paper`; with `CI=true` a missing asset fails.

use std::path::Path;

use blendsim::algorithms::geometry::Point;
use blendsim::pipeline::stage_file::{Animation, OutputKind};
use serde_json::Value;

use crate::common::assets::{paper_asset, paper_asset_in, paper_scene};
use crate::common::cli::{energies, names, read_json, run, TempDir};
use crate::common::verify::{check_outputs, library_animation, output_files};

/// Bake `scene` into `dir/out` with the CLI and check the report and every file. Returns the
/// report and the library's animation of the scene.
fn bake_and_check(dir: &TempDir, scene: &Path, expect_name: &str) -> (Value, Animation) {
    let r = run(&dir.path, &["bake", scene.to_str().unwrap(), "--out", "out"]).success();
    assert_eq!(r.stderr.lines().count(), 1, "one summary line:\n{r}");
    eprintln!("{}", r.stderr.trim_end());
    let out = dir.join("out");
    let report = read_json(&out.join("report.json"));
    assert_eq!(report["scene"], expect_name);

    let solver = &report["solver"];
    assert_eq!(solver["method"], "spacetime", "{solver}");
    assert_eq!(solver["converged"], true, "the solve must converge: {solver}");
    let w = energies(&report);
    let iterations = solver["iterations"].as_u64().unwrap() as usize;
    assert!(iterations >= 1, "{solver}");
    assert_eq!(w.len(), iterations + 1, "W of the baseline, then one per iteration: {solver}");
    for (k, pair) in w.windows(2).enumerate() {
        assert!(pair[1] <= pair[0], "W increased at iteration {}: {} -> {} ({w:?})", k + 1, pair[0], pair[1]);
    }
    assert!(w[iterations] < w[0], "W must decrease overall: {w:?}");

    // Our evaluation: the same scene through the library in this process.
    let anim = library_animation(scene);
    assert!(anim.scene.solver.regularization > 0.0, "the monotone guarantee is for a regularized solve");
    assert_eq!(anim.log.iterations, iterations, "library and CLI ran the same solve");
    for (a, b) in anim.log.energy.iter().zip(&w) {
        assert!((a - b).abs() <= 1e-12 * a.abs(), "library W {a} vs report W {b}");
    }

    let outputs = output_files(&report["outputs"]);
    let mut expected: std::collections::BTreeSet<String> = outputs.iter().map(|f| f.path.clone()).collect();
    expected.extend(["report.json".into(), "report.md".into(), "report.html".into(), ".blendsim-manifest.json".into()]);
    assert_eq!(names(&out), expected, "the output folder holds the listed files and the report");
    for kind in [OutputKind::Blendshape, OutputKind::FullFrame] {
        assert!(outputs.iter().filter(|f| f.kind == kind).count() >= 2, "usda and glb of each kind: {outputs:?}");
    }
    check_outputs(&out, &anim, &outputs);

    let bytes = |path: &str| outputs.iter().find(|f| f.path == path).map_or(0, |f| f.bytes);
    eprintln!(
        "{expect_name}: {} vertices, {} tet nodes, {} tets, {} keys, {} frames; {iterations} iterations, W {:.6e} -> {:.6e}; \
         {expect_name}.usda {} B vs full {} B, {expect_name}.glb {} B vs full {} B; ratios {}; error max {:.2e}; stop: {}",
        report["vertices"],
        report["tet_nodes"],
        report["tets"],
        report["keyframes"],
        report["frames"],
        w[0],
        w[iterations],
        bytes(&format!("{expect_name}.usda")),
        bytes(&format!("{expect_name}.full.usda")),
        bytes(&format!("{expect_name}.glb")),
        bytes(&format!("{expect_name}.full.glb")),
        report["ratios"],
        report["error"]["max"].as_f64().unwrap(),
        solver["stop_reason"],
    );
    (report, anim)
}

#[test]
fn stretch_cyclic() {
    let Some(scene) = paper_scene("stretch") else { return };
    let dir = TempDir::new("paper-stretch");
    let (report, anim) = bake_and_check(&dir, &scene, "stretch");
    assert!(anim.scene.keyframes.as_ref().unwrap().cyclic);
    assert_eq!((report["tet_nodes"].as_u64(), report["tets"].as_u64(), report["keyframes"].as_u64()), (Some(594), Some(2400), Some(3)));
    // A loop: the last key is the first, position and velocity.
    let tr = &anim.trajectory;
    assert_eq!(tr.positions[0], tr.positions[2]);
    assert_eq!(tr.velocities[0], tr.velocities[2]);
    assert!(tr.velocities[0].iter().any(|v| *v != [0.0; 3]), "the solve gives the keys velocities");
}

#[test]
fn dino_walk() {
    let Some(scene) = paper_scene("dino") else { return };
    let dir = TempDir::new("paper-dino");
    let (report, anim) = bake_and_check(&dir, &scene, "dino");
    assert_eq!((report["tet_nodes"].as_u64(), report["tets"].as_u64(), report["keyframes"].as_u64()), (Some(439), Some(1192), Some(10)));
    // The tail is free at the inner keys, so the solve moves it off the input keys; the
    // first and last keys are held entirely.
    let first_last_gap = |k: usize| {
        anim.trajectory.positions[k]
            .iter()
            .zip(&anim.input_keys[k])
            .map(|(p, q)| crate::common::verify::max_distance(&[*p], &[*q]))
            .fold(0.0, f64::max)
    };
    assert_eq!(first_last_gap(0), 0.0);
    assert_eq!(first_last_gap(9), 0.0);
    assert!(report["keyframe_deviation"]["max"].as_f64().unwrap() > 1e-3, "the free tail moves: {}", report["keyframe_deviation"]);
}

// --- Volume, measured here, independently of src/pipeline/report/measures.rs. ---

fn enclosed_volume(points: &[Point], triangles: &[[u32; 3]]) -> f64 {
    triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| points[i as usize]);
            // a . (b x c)
            a[0] * (b[1] * c[2] - b[2] * c[1]) + a[1] * (b[2] * c[0] - b[0] * c[2]) + a[2] * (b[0] * c[1] - b[1] * c[0])
        })
        .sum::<f64>()
        / 6.0
}

/// The geometric baseline: keys joined by cubic Hermite curves with zero velocities.
fn hermite_baseline(times: &[f64], keys: &[Vec<Point>], t: f64) -> Vec<Point> {
    let i = (0..times.len() - 1).rfind(|&i| times[i] <= t).unwrap_or(0);
    let s = ((t - times[i]) / (times[i + 1] - times[i])).clamp(0.0, 1.0);
    let (h0, h1) = (2.0 * s * s * s - 3.0 * s * s + 1.0, -2.0 * s * s * s + 3.0 * s * s);
    keys[i].iter().zip(&keys[i + 1]).map(|(p, q)| std::array::from_fn(|d| h0 * p[d] + h1 * q[d])).collect()
}

/// The largest `1 - V(t) / V̄(t)` over frames, `V̄` blending the animation's own key volumes
/// linearly in time (what the interpolation loses between keys, whatever the keys hold).
fn in_between_loss(times: &[f64], key_volumes: &[f64], fps: f64, volume_at: impl Fn(f64) -> f64) -> f64 {
    let (start, end) = (times[0], times[times.len() - 1]);
    let frames = ((start * fps).ceil() as i64)..=((end * fps + 1e-9).floor() as i64);
    frames
        .map(|f| {
            let t = f as f64 / fps;
            let i = (0..times.len() - 1).rfind(|&i| times[i] <= t).unwrap_or(0);
            let s = ((t - times[i]) / (times[i + 1] - times[i])).clamp(0.0, 1.0);
            1.0 - volume_at(t) / ((1.0 - s) * key_volumes[i] + s * key_volumes[i + 1])
        })
        .fold(0.0, f64::max)
}

#[test]
fn twist_keeps_volume_five_times_better_than_hermite() {
    let Some(scene) = paper_scene("twist") else { return };
    let dir = TempDir::new("paper-twist");
    let (report, anim) = bake_and_check(&dir, &scene, "twist");
    assert_eq!((report["tet_nodes"].as_u64(), report["tets"].as_u64(), report["keyframes"].as_u64()), (Some(594), Some(2400), Some(5)));

    // Measured on the exported surface: the spacetime curve (the points the checkers just
    // matched in every file) and the hermite baseline through the input keys.
    let tri = &anim.mesh.triangles;
    let times = &anim.trajectory.times;
    let volumes = |keys: &[Vec<Point>]| keys.iter().map(|k| enclosed_volume(k, tri)).collect::<Vec<f64>>();
    let rest = enclosed_volume(&anim.mesh.positions, tri);
    assert!((rest - 4.8).abs() < 1e-9, "the prism 1.6 x 3 x 1: {rest}");
    let fps = anim.scene.fps;
    let hermite = in_between_loss(times, &volumes(&anim.input_keys), fps, |t| enclosed_volume(&hermite_baseline(times, &anim.input_keys, t), tri));
    let spacetime = in_between_loss(times, &volumes(&anim.trajectory.positions), fps, |t| enclosed_volume(&anim.trajectory.evaluate(t), tri));
    eprintln!(
        "TWIST in-between volume loss: hermite baseline {:.4} ({:.2}%), spacetime {:.4} ({:.2}%), {:.2}x smaller",
        hermite,
        100.0 * hermite,
        spacetime,
        100.0 * spacetime,
        hermite / spacetime
    );
    // The report says the same.
    let volume = &report["volume"];
    let reported = |which: &str| volume[which]["in_between_loss"].as_f64().unwrap();
    eprintln!("report.json: volume.hermite.in_between_loss = {}, volume.animation.in_between_loss = {}", reported("hermite"), reported("animation"));
    assert!((reported("hermite") - hermite).abs() < 1e-9, "{volume}");
    assert!((reported("animation") - spacetime).abs() < 1e-9, "{volume}");
    assert!(hermite > 0.3, "the hermite baseline of a half-turn twist loses volume: {hermite}");
    assert!(
        hermite >= 5.0 * spacetime,
        "the spacetime solution must lose at most a fifth of the baseline's in-between volume: hermite {hermite}, spacetime {spacetime}"
    );
    assert!(reported("hermite") >= 5.0 * reported("animation"));

    // `--method hermite` bakes that baseline: its own animation loss is the baseline's.
    run(&dir.path, &["bake", "-q", scene.to_str().unwrap(), "--out", "hermite", "--method", "hermite"]).success();
    let baseline = read_json(&dir.join("hermite/report.json"));
    let baked = baseline["volume"]["animation"]["in_between_loss"].as_f64().unwrap();
    assert!((baked - hermite).abs() < 1e-9, "hermite bake: {baked} vs measured {hermite}");
}

/// The paper's surface prism (an OBJ with 252 loose interior points) as keyframes, twisted
/// by the scene file, through TetGen; usda, usdc and glb.
#[test]
fn paper_prism_obj_through_tetgen() {
    let Some(obj) = paper_asset("stretch3d/rectangular_prism.obj") else { return };
    let dir = TempDir::new("paper-prism-obj");
    let a = obj.to_str().unwrap();
    let ends = "[{ axis = \"y\", max = 0.001 }, { axis = \"y\", min = 2.999 }]";
    let scene = format!(
        "name = \"prism\"\nfps = 30\n[keyframes]\nmeshes = [\"{a}\", {{ mesh = \"{a}\", twist = {{ axis = \"y\", degrees = 90.0, axial_scale = 0.9 }} }}, \"{a}\", \
         {{ mesh = \"{a}\", twist = {{ axis = \"y\", degrees = -90.0, axial_scale = 0.9 }} }}, \"{a}\"]\ntimes = [0.0, 0.5, 1.0, 1.5, 2.0]\ncyclic = true\n\
         fixed = [{}]\nfixed_velocity = [{}]\n[export]\nformats = [\"usda\", \"usdc\", \"glb\"]\n",
        [ends; 5].join(", "),
        ["{ axis = \"y\", max = 0.001 }"; 5].join(", ")
    );
    let path = dir.join("prism.toml");
    std::fs::write(&path, scene).unwrap();
    let (report, anim) = bake_and_check(&dir, &path, "prism");
    // TetGen ran: the surface's 342 used vertices plus its 252 loose interior points are
    // nodes, and every one of the OBJ's 594 vertices is exported, loose ones included.
    assert_eq!(report["vertices"].as_u64(), Some(594));
    assert!(report["tet_nodes"].as_u64().unwrap() >= 594 && report["tets"].as_u64().unwrap() > 0, "{report}");
    assert_eq!(output_files(&report["outputs"]).len(), 6);
    let volume = &report["volume"]["animation"];
    assert!(volume["min"].as_f64().unwrap() > 0.8, "the twisted prism keeps its volume: {volume}");
    assert!(anim.trajectory.velocities[1].iter().any(|v| *v != [0.0; 3]));
}

/// The paper scenes through the chain of subcommands give the bytes `bake` gives.
#[test]
fn paper_scenes_chain_like_bake() {
    for name in ["stretch", "twist", "dino"] {
        let Some(scene) = paper_scene(name) else { return };
        let dir = TempDir::new(&format!("paper-chain-{name}"));
        let s = scene.to_str().unwrap();
        for args in [
            vec!["import", s, "-o", "keys.json"],
            vec!["tetrahedralize", "keys.json", "-o", "body.json"],
            vec!["solve", "body.json", "-o", "solution.json"],
            vec!["embed", "solution.json", "-o", "animation.json"],
            vec!["export", "animation.json", "--out", "chain"],
            vec!["bake", "-q", s, "--out", "bake"],
        ] {
            run(&dir.path, &args).success();
        }
        for f in output_files(&read_json(&dir.join("bake/report.json"))["outputs"]) {
            let (a, b) = (std::fs::read(dir.join("chain").join(&f.path)).unwrap(), std::fs::read(dir.join("bake").join(&f.path)).unwrap());
            assert!(a == b, "{name}: {} differs between the chain and bake", f.path);
        }
    }
}

/// The asset rule itself: a missing asset is a failure under CI and a skip elsewhere.
#[test]
fn a_missing_paper_asset_fails_under_ci() {
    let dir = crate::common::assets::paper_dir();
    assert!(paper_asset_in(&dir, "no/such/asset.mesh", false).is_none());
    let under_ci = std::panic::catch_unwind(|| paper_asset_in(&dir, "no/such/asset.mesh", true));
    assert!(under_ci.is_err(), "with CI=true a missing asset must fail the test");
    if dir.join("stretch3d/0.mesh").is_file() {
        assert_eq!(paper_asset_in(&dir, "stretch3d/0.mesh", true), Some(dir.join("stretch3d/0.mesh")));
    }
}
