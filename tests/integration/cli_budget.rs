//! The memory budget of the global step through the CLI: `--max-memory` below the predicted
//! factor makes `bake` and `solve` fall back to the iterative step, which gives the direct
//! solve's result (the same W history to round-off, files that pass the checkers against the
//! direct solve's animation); a malformed amount is a usage error.

use std::path::{Path, PathBuf};

use serde_json::Value;

use crate::common::cli::{energies, read_json, run, TempDir};
use crate::common::verify::{check_outputs, library_animation, output_files};

fn demo_scene() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/demo/twist.toml")
}

fn bake(dir: &TempDir, out: &str, extra: &[&str]) -> Value {
    let scene = demo_scene();
    let mut args = vec!["bake", "-q", scene.to_str().unwrap(), "--out", out];
    args.extend(extra);
    run(&dir.path, &args).success();
    read_json(&dir.join(out).join("report.json"))
}

#[test]
fn over_the_memory_budget_the_iterative_step_gives_the_direct_result() {
    let dir = TempDir::new("budget");
    let direct = bake(&dir, "direct", &[]);
    let iterative = bake(&dir, "iterative", &["--max-memory", "1K"]);
    assert_eq!(direct["solver"]["linear_solver"], "direct");
    assert_eq!(iterative["solver"]["linear_solver"], "iterative");
    let (a, b) = (energies(&direct), energies(&iterative));
    assert_eq!(a.len(), b.len(), "same iterations: {a:?} vs {b:?}");
    for (x, y) in a.iter().zip(&b) {
        assert!((x - y).abs() <= 1e-8 * x.abs(), "W {x} (direct) vs {y} (iterative)");
    }
    // The iterative bake's files against the direct solve's animation (the library's default).
    let anim = library_animation(&demo_scene());
    assert_eq!(anim.log.linear_solver, "direct");
    assert_eq!(check_outputs(&dir.join("iterative"), &anim, &output_files(&iterative["outputs"])).len(), 6);
    // `solve` takes the flag too.
    let scene = demo_scene();
    run(&dir.path, &["import", scene.to_str().unwrap(), "-o", "keys.json"]).success();
    run(&dir.path, &["tetrahedralize", "keys.json", "-o", "body.json"]).success();
    run(&dir.path, &["solve", "body.json", "-o", "solution.json", "--max-memory", "0.5k"]).success();
    assert_eq!(read_json(&dir.join("solution.json"))["data"]["log"]["linear_solver"], "iterative");
    // A malformed amount is a usage error (exit 2) that says what to give.
    for bad in ["abc", "0", "4X"] {
        let r = run(&dir.path, &["bake", scene.to_str().unwrap(), "--out", "never", "--max-memory", bad]);
        assert_eq!(r.code, Some(2), "{bad}: {r}");
        assert!(r.stderr.contains("--max-memory") && r.stderr.contains("4G"), "{bad}: {r}");
    }
    assert!(!dir.join("never").exists());
}
