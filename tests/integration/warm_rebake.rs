//! `blendsim bake --from DIR`: a re-bake reuses the stages whose inputs are the same bytes
//! (TetGen's mesh, the solve) and starts the solve from the previous solution when only key
//! poses moved; what it reused is said on stderr. Timings are in `benches/warm.rs` (`make bench-warm`).

use std::path::Path;

use blendsim::algorithms::geometry::Axis;
use blendsim::algorithms::procedural::{prism, twist, Twist};
use blendsim::formats::mesh::obj;
use serde_json::Value;

use crate::common::cli::{copy_demo, energies, names, read_json, run, TempDir};

/// The demo's left key twisted by `degrees` instead of its 120 (the demo's own generator).
fn edit_left_key(dir: &Path, degrees: f64) {
    let rest = prism([1.0, 3.0, 1.0], [3, 9, 3]);
    let mut m = rest.clone();
    m.positions = twist(&rest.positions, &Twist { axis: Axis::Y, degrees, axial_scale: 0.9 });
    std::fs::write(dir.join("prism_left.obj"), obj::write(&m)).unwrap();
}

/// Assert that every file of `a` has the bytes of the same file in `b`.
fn same_files(a: &Path, b: &Path) {
    assert_eq!(names(a), names(b));
    for name in names(a) {
        assert!(
            std::fs::read(a.join(&name)).unwrap() == std::fs::read(b.join(&name)).unwrap(),
            "{name} differs between {} and {}",
            a.display(),
            b.display()
        );
    }
}

/// Assert that every animation file of `a` has the bytes of the same file in `b` (the
/// report and the cache hold the solve's timings).
fn same_animation(a: &Path, b: &Path) {
    assert_eq!(names(a), names(b));
    for name in names(a).iter().filter(|n| !n.starts_with("report.") && *n != "bake.cache") {
        assert!(
            std::fs::read(a.join(name)).unwrap() == std::fs::read(b.join(name)).unwrap(),
            "{name} differs between {} and {}",
            a.display(),
            b.display()
        );
    }
}

/// The line saying what was reused.
fn reuse_line(stderr: &str) -> &str {
    stderr.lines().find(|l| l.starts_with("blendsim: from ")).unwrap_or_else(|| panic!("no reuse line in:\n{stderr}"))
}

/// The solved node trajectory kept in a bake folder's `bake.cache`: its key positions and
/// velocities, flattened.
#[allow(clippy::type_complexity)]
fn trajectory(dir: &Path) -> (Vec<f64>, Vec<f64>) {
    let cache = read_json(&dir.join("bake.cache"));
    let flat = |v: &Value| {
        v.as_array().unwrap().iter().flat_map(|k| k.as_array().unwrap()).flat_map(|p| p.as_array().unwrap()).map(|x| x.as_f64().unwrap()).collect()
    };
    let tr = &cache["solve"]["trajectory"];
    (flat(&tr["positions"]), flat(&tr["velocities"]))
}

#[test]
fn unchanged_inputs_rebake_to_the_same_bytes_without_tetgen_or_the_solve() {
    let dir = TempDir::new("warm-unchanged");
    copy_demo(&dir.path);
    // The first bake into its own --out has nothing to reuse, and keeps a cache.
    let first = run(&dir.path, &["bake", "twist.toml", "--out", "cold", "--from", "cold"]).success();
    assert_eq!(reuse_line(&first.stderr), "blendsim: from cold: nothing to reuse, every stage ran", "{first}");
    assert!(names(&dir.join("cold")).contains("bake.cache"));
    let warm = run(&dir.path, &["bake", "twist.toml", "--out", "warm", "--from", "cold"]).success();
    assert_eq!(reuse_line(&warm.stderr), "blendsim: from cold: reused TetGen's mesh, the solve", "{warm}");
    // Every file, the report and the cache included: the solve's log is the one kept.
    same_files(&dir.join("cold"), &dir.join("warm"));
    // Into the folder it reads from.
    let again = run(&dir.path, &["bake", "twist.toml", "--out", "cold", "--from", "cold"]).success();
    assert!(reuse_line(&again.stderr).ends_with("reused TetGen's mesh, the solve"), "{again}");
    same_files(&dir.join("cold"), &dir.join("warm"));
}

#[test]
fn one_moved_key_starts_from_the_previous_solution_and_lands_on_the_cold_result() {
    let dir = TempDir::new("warm-key");
    copy_demo(&dir.path);
    run(&dir.path, &["bake", "twist.toml", "--out", "before", "--from", "before"]).success();
    edit_left_key(&dir.path, 100.0);
    run(&dir.path, &["bake", "twist.toml", "--out", "cold", "--from", "cold"]).success();
    let warm = run(&dir.path, &["bake", "twist.toml", "--out", "warm", "--from", "before"]).success();
    assert_eq!(
        reuse_line(&warm.stderr),
        "blendsim: from before: reused TetGen's mesh, the solution as the solve's start (only keys moved)",
        "{warm}"
    );
    let (cold_report, warm_report) = (read_json(&dir.join("cold/report.json")), read_json(&dir.join("warm/report.json")));
    let stop = warm_report["solver"]["stop_reason"].as_str().unwrap();
    assert!(stop.contains("(the previous bake's solution with the keys' edits, then 0 local/global + "), "{stop}");
    // Both stopped by the rule at tolerance 1e-3, which stops within 2% of the W reached at
    // 1e-8 on the demo (docs/performance.md): the two W agree to that.
    let (w_cold, w_warm) = (*energies(&cold_report).last().unwrap(), *energies(&warm_report).last().unwrap());
    assert!((w_warm - w_cold).abs() <= 0.02 * w_cold, "W warm {w_warm} against cold {w_cold}");
    let before = *energies(&read_json(&dir.join("before/report.json"))).last().unwrap();
    assert!((w_cold - before).abs() > 0.02 * w_cold, "the edit changes the result beyond the tolerance ({before} -> {w_cold})");
    // The same motion: key positions within 2% of the body's diagonal (measured 0.85%; the
    // edit moved them by 6.7%). The velocities are what the stopping rule leaves loosest
    // (docs/performance.md, "Warm re-bakes"), so W is the measure.
    let apart = |a: &[f64], b: &[f64]| a.iter().zip(b).fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
    let (cold, warm, before) = (trajectory(&dir.join("cold")).0, trajectory(&dir.join("warm")).0, trajectory(&dir.join("before")).0);
    let diagonal = 11f64.sqrt();
    assert!(apart(&cold, &warm) < 0.02 * diagonal, "positions {} apart", apart(&cold, &warm));
    assert!(apart(&cold, &before) > 0.05 * diagonal, "the edit moves the keys by {}", apart(&cold, &before));
}

#[test]
fn changed_settings_or_mesh_run_their_stages_again() {
    let dir = TempDir::new("warm-changed");
    copy_demo(&dir.path);
    run(&dir.path, &["bake", "twist.toml", "--out", "before", "--from", "before"]).success();
    // A material setting: TetGen's inputs are the same, the solve's are not.
    let scene = std::fs::read_to_string(dir.join("twist.toml")).unwrap();
    std::fs::write(dir.join("twist.toml"), scene.replace("stiffness = 70.0", "stiffness = 80.0")).unwrap();
    let stiffer = run(&dir.path, &["bake", "twist.toml", "--out", "stiffer", "--from", "before"]).success();
    assert_eq!(reuse_line(&stiffer.stderr), "blendsim: from before: reused TetGen's mesh", "{stiffer}");
    run(&dir.path, &["bake", "twist.toml", "--out", "stiffer-cold", "--from", "stiffer-cold"]).success();
    same_animation(&dir.join("stiffer"), &dir.join("stiffer-cold"));
    // The rest mesh (and so the keys that use it): TetGen runs again, and nothing is reused.
    let rest = std::fs::read_to_string(dir.join("prism_rest.obj")).unwrap();
    std::fs::write(dir.join("prism_rest.obj"), rest.replacen("v 0 0 0\n", "v 0 -0.01 0\n", 1)).unwrap();
    let moved = run(&dir.path, &["bake", "twist.toml", "--out", "moved", "--from", "stiffer"]).success();
    assert_eq!(reuse_line(&moved.stderr), "blendsim: from stiffer: nothing reused (the inputs changed), every stage ran", "{moved}");
    // A [tet] setting alone: TetGen runs again.
    let scene = std::fs::read_to_string(dir.join("twist.toml")).unwrap();
    std::fs::write(dir.join("twist.toml"), scene.replace("max_volume = 0.005", "max_volume = 0.004")).unwrap();
    let finer = run(&dir.path, &["bake", "twist.toml", "--out", "finer", "--from", "moved"]).success();
    assert_eq!(reuse_line(&finer.stderr), "blendsim: from moved: nothing reused (the inputs changed), every stage ran", "{finer}");
}

#[test]
fn a_damaged_cache_is_a_warning_and_a_folder_that_is_no_bake_an_error() {
    let dir = TempDir::new("warm-damaged");
    copy_demo(&dir.path);
    run(&dir.path, &["bake", "twist.toml", "--out", "cold", "--from", "cold"]).success();
    // A bake without --from keeps no cache: a later --from it bakes cold.
    run(&dir.path, &["bake", "twist.toml", "--out", "plain"]).success();
    assert!(!names(&dir.join("plain")).contains("bake.cache"));
    let r = run(&dir.path, &["bake", "twist.toml", "--out", "after-plain", "--from", "plain"]).success();
    assert!(r.stderr.contains("blendsim: warning: --from: plain has no bake.cache (a bake keeps one only when run with --from); baking cold"), "{r}");
    run(&dir.path, &["bake", "twist.toml", "--out", "damaged", "--from", "damaged"]).success();
    let cache = dir.join("damaged/bake.cache");
    let bytes = std::fs::read(&cache).unwrap();
    std::fs::write(&cache, &bytes[..bytes.len() / 2]).unwrap();
    let r = run(&dir.path, &["bake", "twist.toml", "--out", "again", "--from", "damaged"]).success();
    assert!(r.stderr.contains("blendsim: warning: --from: damaged/bake.cache is damaged (") && r.stderr.contains("; baking cold"), "{r}");
    assert_eq!(reuse_line(&r.stderr), "blendsim: from damaged: nothing to reuse, every stage ran", "{r}");
    same_animation(&dir.join("cold"), &dir.join("again"));
    // Another binary's cache is not read.
    let foreign = String::from_utf8(bytes).unwrap();
    let at = foreign.find("\"binary\":\"").unwrap() + 10;
    std::fs::write(&cache, format!("{}0{}", &foreign[..at], &foreign[at + 1..])).unwrap();
    let r = run(&dir.path, &["bake", "twist.toml", "--out", "again", "--from", "damaged"]).success();
    assert!(r.stderr.contains("damaged/bake.cache was written by another blendsim build; baking cold"), "{r}");
    // A folder that is no bake's, and one that does not exist: one line, nothing written.
    std::fs::create_dir_all(dir.join("photos")).unwrap();
    for (from, problem) in [
        ("photos", "photos: is not a bake output folder (no bake.cache, no .blendsim-manifest.json)"),
        ("nowhere", "nowhere: is not a bake output folder (no such folder)"),
    ] {
        let r = run(&dir.path, &["bake", "twist.toml", "--out", "never", "--from", from]);
        assert_eq!(r.code, Some(1), "{r}");
        assert_eq!(r.stderr.lines().count(), 1, "{r}");
        assert!(r.stderr.contains(problem) && r.stderr.contains("the --out folder of an earlier `blendsim bake`"), "{r}");
        assert!(!dir.join("never").exists());
    }
    // A first bake into its own --out has nothing to reuse and says so.
    let r = run(&dir.path, &["bake", "twist.toml", "--out", "first", "--from", "first"]).success();
    assert_eq!(reuse_line(&r.stderr), "blendsim: from first: nothing to reuse, every stage ran", "{r}");
}
