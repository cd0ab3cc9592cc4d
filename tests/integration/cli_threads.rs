//! Same input, same bytes out, on any thread count: bakes run with `RAYON_NUM_THREADS` = 1, 2
//! and 3 write the same files, byte for byte (the report's wall-clock fields aside). Every
//! parallel reduction of the solve either sums per-item results in item order or splits its
//! work into a count fixed by the problem (faer's kernels: `physics::fixed_par`), never by the
//! pool's size.

use std::path::Path;

use crate::cli_physics::cube_medit;
use crate::common::cli::{copy_demo, read_json, run_env, without_timings, TempDir};

/// Bake `scene` in `dir` into `out-N` with N threads for N = 1, 2, 3, and check that every
/// output is the same bytes as the one-thread bake's (report.json without its timings,
/// report.md without its time row).
fn same_bytes_on_1_2_3_threads(dir: &Path, scene: &str) {
    let bake = |threads: usize| {
        let out = format!("out-{threads}");
        let threads = threads.to_string();
        run_env(dir, &["bake", scene, "--out", &out], &[("RAYON_NUM_THREADS", threads.as_ref())]).success();
        dir.join(out)
    };
    let one = bake(1);
    let mut names: Vec<String> = std::fs::read_dir(&one).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    names.sort();
    assert!(names.iter().any(|n| n.ends_with(".usdc")) && names.iter().any(|n| n.ends_with(".glb")), "{names:?}");
    let md = |path: &Path| std::fs::read_to_string(path).unwrap().lines().filter(|l| !l.starts_with("| time |")).collect::<Vec<_>>().join("\n");
    let html =
        |path: &Path| std::fs::read_to_string(path).unwrap().lines().filter(|l| !l.starts_with("<tr><td>time</td>")).collect::<Vec<_>>().join("\n");
    for threads in [2, 3] {
        let other = bake(threads);
        let mut other_names: Vec<String> =
            std::fs::read_dir(&other).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
        other_names.sort();
        assert_eq!(other_names, names, "{threads} threads: the same files");
        for name in &names {
            let (a, b) = (one.join(name), other.join(name));
            match name.as_str() {
                "report.json" => assert_eq!(without_timings(read_json(&a)), without_timings(read_json(&b)), "{scene}, {threads} threads: {name}"),
                "report.md" => assert_eq!(md(&a), md(&b), "{scene}, {threads} threads: {name}"),
                // The same numbers but the wall-clock row, and the same player.
                "report.html" => assert_eq!(html(&a), html(&b), "{scene}, {threads} threads: {name}"),
                _ => assert!(
                    std::fs::read(&a).unwrap() == std::fs::read(&b).unwrap(),
                    "{scene}, {threads} threads: {name} differs from the one-thread bake's"
                ),
            }
        }
    }
}

/// The demo's twisting prism (through TetGen) with each of the three global steps: the
/// vibration modes (the cost model's choice here), the direct factorization and conjugate
/// gradients.
/// 0.8, 0.8 and 1.8 CPU s per bake (load 9).
#[test]
fn the_demo_bakes_the_same_bytes_on_one_two_and_three_threads() {
    let dir = TempDir::new("threads-demo");
    copy_demo(&dir.path);
    let scene = std::fs::read_to_string(dir.join("twist.toml")).unwrap();
    for global_step in ["auto", "direct", "iterative"] {
        let name = format!("twist-{global_step}.toml");
        let text = scene.replacen("method = \"spacetime\"", &format!("method = \"spacetime\"\nglobal_step = \"{global_step}\""), 1);
        assert_ne!(text, scene);
        std::fs::write(dir.join(&name), text).unwrap();
        same_bytes_on_1_2_3_threads(&dir.path, &name);
        let linear_solver = read_json(&dir.join("out-1/report.json"))["solver"]["linear_solver"].as_str().unwrap().to_string();
        assert_eq!(linear_solver, if global_step == "auto" { "modal" } else { global_step });
    }
}

/// A key-time solve with the tangent model Hessian: a cube of 162 tets clamped at its base
/// sways to a held bent key and back in a loop whose duration is optimized (the quasi-Newton
/// path, the tangent model's factorizations, the time line searches). 0.1 CPU s per bake.
#[test]
fn a_timing_bake_with_the_tangent_model_is_the_same_bytes_on_one_two_and_three_threads() {
    let dir = TempDir::new("threads-timing");
    std::fs::write(dir.join("rest.mesh"), cube_medit(3, |p| p)).unwrap();
    std::fs::write(dir.join("bent.mesh"), cube_medit(3, |p| [p[0] + 0.1 * p[1] * p[1], p[1], p[2]])).unwrap();
    let clamp = r#"{ axis = "y", max = 1e-9 }"#;
    let scene = format!(
        r#"name = "sway"
fps = 30
[keyframes]
meshes = ["rest.mesh", "bent.mesh", "rest.mesh"]
times = [0.0, 0.3, 0.6]
cyclic = true
fixed = [{clamp}, "all", {clamp}]
fixed_velocity = [{clamp}, {clamp}, {clamp}]
[material]
stiffness = 200.0
volume = 200.0
damping = 0.0
[solver]
optimize_timing = true
model_hessian = "tangent"
[export]
formats = ["usda", "usdc", "glb"]
"#
    );
    std::fs::write(dir.join("scene.toml"), scene).unwrap();
    same_bytes_on_1_2_3_threads(&dir.path, "scene.toml");
    let solver = &read_json(&dir.join("out-1/report.json"))["solver"];
    let stop = solver["stop_reason"].as_str().unwrap();
    assert!(stop.contains("tangent model Hessian") && solver["timing_iterations"].as_u64().unwrap() > 0, "{stop}");
}
