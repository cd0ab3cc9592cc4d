//! The memory budget of the global step through the CLI: `--max-memory` below the predicted
//! factor makes `bake` and `solve` take a step that fits (the body's modes here), and the
//! iterative step gives the direct solve's result (the same W history to round-off, files that
//! pass the checkers against the direct solve's animation); a malformed amount is a usage error.

use std::path::{Path, PathBuf};

use serde_json::Value;

use crate::common::cli::{energies, read_json, run, run_env, TempDir};
use crate::common::verify::{check_outputs, library_animation, output_files};

fn demo_scene() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/demo/twist.toml")
}

/// The demo with 2 samples per interval, copied into `dir`: its whole bake without the global
/// step (about 6 MB estimated: the samples, the solver's state) fits in a 10 MiB budget, and
/// what that leaves the global step (about 4 MB) holds its modes (1.1 MB predicted) but not
/// its factor (6.3 MB), so `--max-memory 10M` exercises the fallback. (`--max-memory` is the
/// one budget of every estimate, so the demo itself is refused below its own.) `global_step`:
/// the scene's `[solver] global_step`.
fn lean_demo(dir: &TempDir, global_step: &str) -> PathBuf {
    let from = demo_scene().parent().unwrap().to_path_buf();
    let to = dir.join(format!("lean-{global_step}"));
    std::fs::create_dir_all(&to).unwrap();
    for e in std::fs::read_dir(&from).unwrap() {
        let e = e.unwrap();
        std::fs::copy(e.path(), to.join(e.file_name())).unwrap();
    }
    let scene = std::fs::read_to_string(to.join("twist.toml")).unwrap();
    assert!(scene.contains("\nsamples = 6\n"));
    let lean = scene.replace("\nsamples = 6\n", &format!("\nsamples = 2\nglobal_step = \"{global_step}\"\n"));
    let path = to.join("twist.toml");
    std::fs::write(&path, lean).unwrap();
    path
}

fn bake(dir: &TempDir, out: &str, global_step: &str, extra: &[&str]) -> Value {
    let scene = lean_demo(dir, global_step);
    let mut args = vec!["bake", "-q", scene.to_str().unwrap(), "--out", out];
    args.extend(extra);
    run(&dir.path, &args).success();
    read_json(&dir.join(out).join("report.json"))
}

#[test]
fn over_the_memory_budget_a_step_that_fits_gives_the_direct_result() {
    let dir = TempDir::new("budget");
    let direct = bake(&dir, "direct", "direct", &[]);
    // The factor (6.3 MB predicted) is over the budget; the modes (1.1 MB) fit and are the
    // faster; the iterative step is asked for, under the same budget.
    let fitting = bake(&dir, "fitting", "auto", &["--max-memory", "10M"]);
    let iterative = bake(&dir, "iterative", "iterative", &["--max-memory", "10M"]);
    assert_eq!(direct["solver"]["linear_solver"], "direct");
    assert_eq!(fitting["solver"]["linear_solver"], "modal");
    assert_eq!(iterative["solver"]["linear_solver"], "iterative");
    let a = energies(&direct);
    for (name, other) in [("modal", &fitting), ("iterative", &iterative)] {
        let b = energies(other);
        assert_eq!(a.len(), b.len(), "same iterations: {a:?} vs {b:?} ({name})");
        // CG stops at a relative residual of 1e-10, and the quasi-Newton iterations carry such a
        // difference on (through the curvature pairs and the learned scale of H0): over the lean
        // demo's 145 iterations it grows to at most 6.1e-8 of W (measured), far below what a
        // user could see. The modes are exact: they differ from the factor at round-off.
        for (k, (x, y)) in a.iter().zip(&b).enumerate() {
            assert!((x - y).abs() <= 1e-6 * x.abs(), "iteration {k}: W {x} (direct) vs {y} ({name})");
        }
    }
    // The iterative bake's files against the direct solve's animation.
    let anim = library_animation(&lean_demo(&dir, "direct"));
    assert_eq!(anim.log.linear_solver, "direct");
    assert_eq!(check_outputs(&dir.join("iterative"), &anim, &output_files(&iterative["outputs"])).len(), 6);
    // `solve` takes the flag too.
    let scene = lean_demo(&dir, "auto");
    run(&dir.path, &["import", scene.to_str().unwrap(), "-o", "keys.json"]).success();
    run(&dir.path, &["tetrahedralize", "keys.json", "-o", "body.json"]).success();
    run(&dir.path, &["solve", "body.json", "-o", "solution.json", "--max-memory", "10M"]).success();
    assert_eq!(read_json(&dir.join("solution.json"))["data"]["log"]["linear_solver"], "modal");
    // A malformed amount is a usage error (exit 2) that says what to give.
    for bad in ["abc", "0", "4X"] {
        let r = run(&dir.path, &["bake", scene.to_str().unwrap(), "--out", "never", "--max-memory", bad]);
        assert_eq!(r.code, Some(2), "{bad}: {r}");
        assert!(r.stderr.contains("--max-memory") && r.stderr.contains("4G"), "{bad}: {r}");
    }
    assert!(!dir.join("never").exists());
}

#[test]
fn a_bake_whose_estimate_is_over_the_budget_is_refused_before_tetgen() {
    // The demo's whole bake is estimated before TetGen at about 4 MB (its solve on the
    // surface's 128 vertices, the least TetGen's body can be), over a 3 MiB budget that its
    // frames and samples alone fit in. The refusal comes before TetGen starts (the program
    // named here does not exist) and writes nothing.
    let dir = TempDir::new("budget-whole-bake");
    let scene = demo_scene();
    let env = [("BLENDSIM_TETGEN", std::ffi::OsStr::new("/nonexistent/tetgen"))];
    let r = run_env(&dir.path, &["bake", scene.to_str().unwrap(), "--out", "never", "--max-memory", "3M"], &env);
    assert_eq!(r.code, Some(1), "{r}");
    assert_eq!(r.stderr.lines().count(), 1, "{r}");
    assert!(
        r.stderr.contains("twist.toml: the scene would need about ")
            && r.stderr.contains(" MB of memory for the whole bake (its peak in the solve, on about 128 tet nodes and 5 keys)"),
        "{r}"
    );
    assert!(r.stderr.contains("more than the --max-memory budget of 3.1 MB") && r.stderr.contains("raise [tet] max_volume"), "{r}");
    assert!(!r.stderr.contains("tetgen"), "{r}");
    assert!(!dir.join("never").exists());
    // Within the budget, the same refusal does not come: TetGen is the next thing run.
    let r = run_env(&dir.path, &["bake", scene.to_str().unwrap(), "--out", "never", "--max-memory", "1T"], &env);
    assert!(r.code == Some(1) && r.stderr.contains("is not installed") && !r.stderr.contains("whole bake"), "{r}");
    assert!(!dir.join("never").exists());
}

#[test]
fn max_memory_is_the_one_budget_of_every_estimate() {
    // The demo needs about 5.4 MB for its spacetime samples and 1.5 MB for its frames: under a
    // 1 MB budget the bake is the one-line estimate error, before any work, and writes nothing.
    let dir = TempDir::new("budget-estimate");
    let scene = demo_scene();
    let r = run(&dir.path, &["bake", scene.to_str().unwrap(), "--out", "never", "--max-memory", "1M"]);
    assert_eq!(r.code, Some(1), "{r}");
    assert_eq!(r.stderr.lines().count(), 1, "{r}");
    assert!(r.stderr.contains("twist.toml: the scene would need about ") && r.stderr.contains("more than the --max-memory budget of 1.0 MB"), "{r}");
    assert!(r.stderr.contains("raise --max-memory"), "{r}");
    assert!(!dir.join("never").exists());
}

#[test]
fn max_time_stops_the_solve_with_one_line_and_writes_nothing() {
    // A budget spent before the work starts: TetGen is not started (it is bounded by what is
    // left of the budget), one line naming the scene and the fix.
    let dir = TempDir::new("budget-time");
    let scene = demo_scene();
    let r = run(&dir.path, &["bake", scene.to_str().unwrap(), "--out", "never", "--max-time", "0.001"]);
    assert_eq!(r.code, Some(1), "{r}");
    assert_eq!(r.stderr.lines().count(), 1, "{r}");
    assert!(r.stderr.contains("twist.toml: ") && r.stderr.contains("--max-time budget of 0.001 s") && r.stderr.contains("raise --max-time"), "{r}");
    assert!(!dir.join("never").exists());
    // A generous budget changes nothing: the same bytes as without one.
    let lean = lean_demo(&dir, "auto");
    for (out, extra) in [("free", vec![]), ("timed", vec!["--max-time", "1h"])] {
        let mut args = vec!["bake", "-q", lean.to_str().unwrap(), "--out", out];
        args.extend(extra);
        run(&dir.path, &args).success();
    }
    for file in ["twist.usda", "twist.glb"] {
        assert_eq!(std::fs::read(dir.join("free").join(file)).unwrap(), std::fs::read(dir.join("timed").join(file)).unwrap(), "{file}");
    }
    // A malformed duration is a usage error.
    let r = run(&dir.path, &["bake", lean.to_str().unwrap(), "--out", "x", "--max-time", "soon"]);
    assert_eq!(r.code, Some(2), "{r}");
    assert!(r.stderr.contains("is not a positive duration"), "{r}");
}

/// A bake refused by `--max-time`: exit 1, one line naming `file`, the budget and the fix,
/// with `phase` (where it ran out), and no output folder.
fn out_of_time(dir: &TempDir, args: &[&str], file: &str, phase: &str) {
    let r = run(&dir.path, args);
    assert_eq!(r.code, Some(1), "{r}");
    assert_eq!(r.stderr.lines().count(), 1, "{r}");
    assert!(r.stderr.contains(&format!("{file}: ")) && r.stderr.contains("--max-time budget of ") && r.stderr.contains("raise --max-time"), "{r}");
    assert!(r.stderr.contains(phase), "expected {phase:?}: {r}");
    assert!(!dir.join("never").exists() && !dir.join("never.obj").exists());
}

#[test]
fn max_time_bounds_tetgen_by_what_is_left_of_it() {
    // The demo asking TetGen for tets of 1e-8 (millions of them: minutes of TetGen) with the
    // default [tet] timeout of 120 s: a 5 s budget stops TetGen after what is left of it. The
    // budget must outlast reading the scene (milliseconds) even on a loaded machine, or the
    // bake stops before TetGen starts; the bound on the whole run only has to separate the
    // budget from the 120 s timeout.
    let dir = TempDir::new("budget-tetgen");
    let scene = lean_demo(&dir, "auto");
    let text = std::fs::read_to_string(&scene).unwrap();
    std::fs::write(&scene, text.replace("max_volume = 0.005", "max_volume = 1e-8")).unwrap();
    let start = std::time::Instant::now();
    let args = ["bake", scene.to_str().unwrap(), "--out", "never", "--max-time", "5"];
    out_of_time(&dir, &args, "twist.toml", "in the tetrahedralization, TetGen stopped after ");
    assert!(start.elapsed().as_secs_f64() < 100.0, "stopped by the budget, not by [tet] timeout: {:?}", start.elapsed());
    // The smaller bound wins: [tet] timeout below the budget is TetGen's own error.
    std::fs::write(&scene, text.replace("max_volume = 0.005", "max_volume = 1e-8\ntimeout = 1")).unwrap();
    let r = run(&dir.path, &["bake", scene.to_str().unwrap(), "--out", "never", "--max-time", "1h"]);
    assert_eq!(r.code, Some(1), "{r}");
    assert!(r.stderr.contains("TetGen did not finish within 1 s and was stopped") && r.stderr.contains("raise [tet] timeout"), "{r}");
    // A budget spent before TetGen starts (1 ns: spent by the time the scene is read, so the
    // keyframe import meets it at its first key).
    out_of_time(
        &dir,
        &["bake", scene.to_str().unwrap(), "--out", "never", "--max-time", "1e-9"],
        "twist.toml",
        "in the keyframe import, after reading 0 of 5 keys",
    );
}

#[test]
fn max_time_bounds_the_keyframe_import_key_by_key() {
    // 400 keys (the demo's three poses over and over): a budget spent by the time the scene is
    // read stops the import at its first key, with the import's own fix; `import` alone too.
    let dir = TempDir::new("budget-import");
    let scene = lean_demo(&dir, "auto");
    let text = std::fs::read_to_string(&scene).unwrap();
    let n = 400;
    let meshes: Vec<String> = (0..n).map(|k| format!("\"{}\"", ["prism_rest.obj", "prism_left.obj", "prism_right.obj"][k % 3])).collect();
    let times: Vec<String> = (0..n).map(|k| format!("{:.3}", k as f64 / 60.0)).collect();
    let long: String = text
        .lines()
        .filter(|l| !l.starts_with("fixed") && !l.starts_with("cyclic"))
        .map(|l| match l {
            l if l.starts_with("meshes = ") => format!("meshes = [{}]\n", meshes.join(", ")),
            l if l.starts_with("times = ") => format!("times = [{}]\n", times.join(", ")),
            l => format!("{l}\n"),
        })
        .collect();
    std::fs::write(&scene, long).unwrap();
    let phase = format!("in the keyframe import, after reading 0 of {n} keys");
    out_of_time(&dir, &["bake", scene.to_str().unwrap(), "--out", "never", "--max-time", "1e-9"], "twist.toml", &phase);
    out_of_time(&dir, &["import", scene.to_str().unwrap(), "-o", "never.json", "--max-time", "1e-9"], "twist.toml", &phase);
    assert!(!dir.join("never.json").exists());
    let r = run(&dir.path, &["import", scene.to_str().unwrap(), "-o", "never.json", "--max-time", "1e-9"]);
    assert!(r.stderr.contains("or give fewer keys"), "{r}");
    // Given the time, the same scene imports.
    run(&dir.path, &["import", "-q", scene.to_str().unwrap(), "-o", "keys.json", "--max-time", "1h"]).success();
}

/// A stand-in for the Python that runs usd-core's reader: it hangs (as a reader stuck on a
/// network file or a FIFO would) until killed.
fn hanging_python(dir: &TempDir) -> PathBuf {
    let path = dir.join("hanging-python");
    std::fs::write(&path, "#!/bin/sh\nexec sleep 600\n").unwrap();
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o755)).unwrap();
    }
    path
}

/// The `blendsim-{usd,abc}-read-*` folders in `tmp`.
fn reader_work_dirs(tmp: &Path) -> Vec<String> {
    let names = std::fs::read_dir(tmp).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned());
    names.filter(|n| n.starts_with("blendsim-usd-read-") || n.starts_with("blendsim-abc-read-")).collect()
}

/// Both Python readers (usd-core's and the Alembic library's) run under the same runner: a
/// hanging one is killed at the deadline, with a one-line error naming the file and its folder gone.
#[test]
fn max_time_kills_a_hanging_python_reader_and_leaves_no_folder() {
    let dir = TempDir::new("budget-usd");
    let tmp = dir.join("tmp");
    std::fs::create_dir_all(&tmp).unwrap();
    std::fs::write(dir.join("bar.usda"), "#usda 1.0\n").unwrap();
    // Not HDF5, so it goes to the Alembic library's reader.
    std::fs::write(dir.join("bar.abc"), "Ogawa and the rest of an archive").unwrap();
    // A folder left by a killed run (its process is gone): the next reader removes it.
    let stale = tmp.join("blendsim-usd-read-4194999-0");
    std::fs::create_dir_all(&stale).unwrap();
    std::fs::write(stale.join("frames.pc2"), "partial").unwrap();
    let python = hanging_python(&dir);
    let env = [("TMPDIR", tmp.as_os_str()), ("BLENDSIM_PYTHON", python.as_os_str())];
    for (file, reader) in [("bar.usda", "usd-core's reader"), ("bar.abc", "the Alembic library's reader")] {
        let scene = format!("name = \"bar\"\n[cache]\npath = \"{file}\"\nkeyframes = [0, 1]\n[solver]\nmethod = \"fit\"\n");
        std::fs::write(dir.join("scene.toml"), scene).unwrap();
        let start = std::time::Instant::now();
        let r = crate::common::cli::run_timeout(&dir.path, &["bake", "scene.toml", "--out", "never", "--max-time", "2"], &env, 300.0);
        assert_eq!(r.code, Some(1), "{r}");
        assert_eq!(r.stderr.lines().count(), 1, "{r}");
        assert!(r.stderr.contains(&format!("{file}: blendsim ran past its --max-time budget")) && r.stderr.contains("if the reader hangs"), "{r}");
        assert!(r.stderr.contains("--max-time budget of 2 s") && r.stderr.contains(&format!("in the cache reading, {reader} stopped after ")), "{r}");
        assert!(start.elapsed().as_secs_f64() < 250.0, "stopped by the budget, not by the reader's end");
        assert_eq!(reader_work_dirs(&tmp), Vec::<String>::new(), "the killed reader's folder and the stale one are gone");
        assert!(!dir.join("never").exists());
    }
}

#[test]
fn a_texture_over_the_memory_budget_is_refused_before_it_is_read() {
    // A PNG header claiming 16000 x 16000 RGB pixels (768 MB decoded) in a few hundred bytes.
    let dir = TempDir::new("budget-texture");
    crate::texture::textured_prism(&dir.path, "formats = [\"glb\"]\nfull_frame = false");
    let scene = std::fs::read_to_string(dir.join("scene.toml")).unwrap().replace("formats = [\"usda\", \"usdc\", \"glb\"]\n", "");
    std::fs::write(dir.join("scene.toml"), scene).unwrap();
    let mut png = crate::texture::png(2, 2, |_, _| [128, 128, 128]);
    png[16..20].copy_from_slice(&16000u32.to_be_bytes());
    png[20..24].copy_from_slice(&16000u32.to_be_bytes());
    let crc = crate::texture::crc32(&png[12..29]);
    png[29..33].copy_from_slice(&crc.to_be_bytes());
    std::fs::write(dir.join("uvgrid.png"), &png).unwrap();
    let args = ["bake", "-q", "--method", "hermite", "scene.toml", "--out", "out", "--max-memory", "256M"];
    let r = run(&dir.path, &args);
    assert_eq!(r.code, Some(1), "{r}");
    assert_eq!(r.stderr.lines().count(), 1, "{r}");
    assert!(r.stderr.contains("uvgrid.png: the scene would need about ") && r.stderr.contains("768.0 MB of pixels decoded"), "{r}");
    assert!(r.stderr.contains("more than the --max-memory budget of 0.3 GB") && r.stderr.contains("scale the texture down"), "{r}");
    assert!(!dir.join("out").exists());
    // Under a budget that holds it, the same scene bakes.
    run(&dir.path, &["bake", "-q", "--method", "hermite", "scene.toml", "--out", "out", "--max-memory", "4G"]).success();
}

#[test]
fn budgets_past_what_their_numbers_hold_are_usage_errors() {
    let dir = TempDir::new("budget-overflow");
    let scene = demo_scene();
    for (flag, value, says) in [
        ("--max-memory", "99999999999999999999G", "more memory than a byte count holds"),
        ("--max-memory", "1e300T", "more memory than a byte count holds"),
        ("--max-time", "1e300s", "longer than the longest --max-time"),
        ("--max-time", "1e20h", "longer than the longest --max-time"),
    ] {
        let r = run(&dir.path, &["bake", scene.to_str().unwrap(), "--out", "never", flag, value]);
        assert_eq!(r.code, Some(2), "{flag} {value}: {r}");
        assert_eq!(r.stderr.lines().filter(|l| l.starts_with("error: ")).count(), 1, "{r}");
        assert!(r.stderr.contains(says) && r.stderr.contains(flag), "{flag} {value}: {r}");
    }
    assert!(!dir.join("never").exists());
}

#[test]
fn max_time_stops_the_cache_fit_its_key_selection_and_its_error_measure() {
    use crate::cache_bake::{scene, write_cache};
    let dir = TempDir::new("budget-cache");
    write_cache(&dir.path, &crate::common::bar::bar(&Default::default()), "bar.pc2");
    // Welding reads every frame first and checks the budget too (the first case); without it
    // nothing else checks the budget on the way (no TetGen, no solver): the fit must, at its
    // first frame.
    std::fs::write(dir.join("welded.toml"), scene("bar.pc2", "fps = 60\nrest = \"rest.obj\"\n", "fit", "keyframes = [0, 60, 120, 180]\n")).unwrap();
    out_of_time(&dir, &["bake", "welded.toml", "--out", "never", "--max-time", "1e-9"], "bar.pc2", "in the cache weld, after reading ");
    let extra = "fps = 60\nrest = \"rest.obj\"\nweld = false\n";
    std::fs::write(dir.join("listed.toml"), scene("bar.pc2", extra, "fit", "keyframes = [0, 60, 120, 180]\n")).unwrap();
    std::fs::write(dir.join("auto.toml"), scene("bar.pc2", extra, "fit", "keyframes = \"auto\"\n")).unwrap();
    out_of_time(&dir, &["bake", "listed.toml", "--out", "never", "--max-time", "1e-9"], "bar.pc2", "in the cache fit, after reading 0 cache frames");
    out_of_time(&dir, &["bake", "auto.toml", "--out", "never", "--max-time", "1e-9"], "bar.pc2", "in the cache key selection, after reading ");
    // A generous budget changes nothing.
    for (out, extra) in [("free", vec![]), ("timed", vec!["--max-time", "1h"])] {
        let mut args = vec!["bake", "-q", "auto.toml", "--out", out];
        args.extend(extra);
        run(&dir.path, &args).success();
    }
    assert_eq!(std::fs::read(dir.join("free/bar.glb")).unwrap(), std::fs::read(dir.join("timed/bar.glb")).unwrap());
    // The error measure streams the whole cache too (the report's, and the export's search for
    // the smallest principal rank within the tolerance): `export` and `report` take the budget,
    // and spent, the measure stops at its first frame. Their stage files are made without one.
    for args in [
        &["import", "listed.toml", "-o", "keys.json"][..],
        &["tetrahedralize", "keys.json", "-o", "body.json"],
        &["solve", "body.json", "-o", "solution.json"],
        &["embed", "solution.json", "-o", "animation.json"],
        &["export", "animation.json", "--out", "chained"],
    ] {
        run(&dir.path, args).success();
    }
    let before = crate::common::cli::snapshot(&dir.path);
    out_of_time(
        &dir,
        &["export", "animation.json", "--out", "never", "--max-time", "1e-9"],
        "bar.pc2",
        "in the cache error measure, after reading 0 cache frames",
    );
    out_of_time(
        &dir,
        &["report", "animation.json", "--outputs", "chained/bar.outputs.json", "--out", "never", "--max-time", "1e-9"],
        "bar.pc2",
        "in the cache error measure, after reading 0 cache frames",
    );
    assert!(crate::common::cli::snapshot(&dir.path) == before, "the refused runs left the folder as it was");
    run(&dir.path, &["report", "animation.json", "--outputs", "chained/bar.outputs.json", "--out", "chained", "--max-time", "1h"]).success();
}

#[test]
fn max_time_stops_the_mass_spring_blend() {
    // Tet-mesh keys, imported without a budget (the import checks it at every key): the
    // mass-spring model (its first equilibrium, built with it) is the solve's first check.
    let dir = TempDir::new("budget-mass-spring");
    let cube = crate::cli_physics::cube_medit(2, |p| p);
    let sheared = crate::cli_physics::cube_medit(2, |p| [p[0] + 0.3 * p[1], p[1], p[2]]);
    std::fs::write(dir.join("a.mesh"), cube).unwrap();
    std::fs::write(dir.join("b.mesh"), sheared).unwrap();
    let scene = "name = \"shear\"\nfps = 24.0\n[keyframes]\nmeshes = [\"a.mesh\", \"b.mesh\"]\ntimes = [0.0, 1.0]\n[solver]\nmethod = \"mass-spring\"\n[mass_spring]\ninbetweens = 3\n[export]\nformats = [\"usda\"]\n";
    std::fs::write(dir.join("shear.toml"), scene).unwrap();
    run(&dir.path, &["import", "-q", "shear.toml", "-o", "keys.json"]).success();
    run(&dir.path, &["tetrahedralize", "-q", "keys.json", "-o", "body.json"]).success();
    out_of_time(
        &dir,
        &["solve", "body.json", "-o", "never.json", "--max-time", "1e-9"],
        "body.json",
        "in the mass-spring blend, after 0 Newton iterations",
    );
    assert!(!dir.join("never.json").exists());
    run(&dir.path, &["bake", "-q", "shear.toml", "--out", "timed", "--max-time", "1h"]).success();
    // `blend` takes the budget too: its equilibria, and TetGen for the body.
    crate::blend::targets(&dir);
    let blend = |out: &'static str, extra: &[&'static str]| -> Vec<&'static str> {
        [&["blend", "--targets", "a.obj", "b.obj", "--weights", "0.5,0.5", "--out", out][..], extra].concat()
    };
    out_of_time(&dir, &blend("never.obj", &["--no-body", "--max-time", "1e-9"]), "a.obj", "in the mass-spring blend, after 0 ");
    out_of_time(&dir, &blend("never.obj", &["--max-time", "1e-9"]), "a.obj", "in the tetrahedralization, before TetGen started");
    run(&dir.path, &blend("shape.obj", &["-q", "--max-time", "1h"])).success();
}

/// Budgets are values, not process state: two bakes of the demo in one process, at the same
/// time, one under a budget its samples do not fit in (refused, with the estimate) and one
/// under the default budget (baked), each getting its own answer; a time budget already spent
/// stops a third before TetGen.
#[test]
fn two_bakes_in_one_process_keep_their_own_budgets() {
    use blendsim::pipeline::scene::SceneFile;
    use blendsim::pipeline::stages::Bake;
    use blendsim::support::budget::Budget;
    use blendsim::support::output::Staging;
    use blendsim::support::progress::Progress;

    let dir = TempDir::new("two-budgets");
    let scene = SceneFile::load(&demo_scene()).unwrap();
    let progress = Progress::hidden();
    let bake = |budget: Budget, out: &str| {
        let mut staging = Staging::new(&dir.join(out)).unwrap();
        Bake::new(&scene, &progress).budget(budget).files(&mut staging).map(|report| report.solver.iterations)
    };
    let (small, default, spent) = std::thread::scope(|s| {
        let small = s.spawn(|| bake(Budget::new(Some(1 << 20), None), "small"));
        let default = s.spawn(|| bake(Budget::default(), "default"));
        let spent = s.spawn(|| bake(Budget::new(None, Some(1e-9)), "spent"));
        (small.join().unwrap(), default.join().unwrap(), spent.join().unwrap())
    });
    let small = small.expect_err("1 MB holds neither the demo's samples nor its frames");
    assert!(small.problem.contains("more than the --max-memory budget of 1.0 MB"), "{small}");
    assert!(default.expect("the default budget holds the demo") > 0);
    let spent = spent.expect_err("a spent time budget stops the bake");
    assert!(spent.problem.contains("ran past its --max-time budget"), "{spent}");
}
