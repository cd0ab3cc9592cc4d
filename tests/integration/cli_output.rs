//! The output folder through the `blendsim` binary: concurrent bakes into one folder (the
//! second waits and says so, or fails at once with `--no-wait`), a re-bake with fewer formats
//! (stale files of the earlier bake removed, the user's files kept as the same files), a bake
//! of another scene (the earlier bake's files removed whatever their name, and said), the
//! `export` + `report` chain sharing a folder, and folders that cannot be output folders.

use std::ffi::OsStr;
use std::os::unix::fs::MetadataExt;
use std::os::unix::process::ExitStatusExt;
use std::path::Path;

use crate::common::checkers::check_same_layer;
use crate::common::cli::{names, read_json, run, run_env, snapshot, Spawned, TempDir};
use blendsim::algorithms::geometry::TriMesh;
use blendsim::algorithms::procedural::prism;
use blendsim::formats::mesh::obj;

fn cube() -> TriMesh {
    prism([1.0, 1.0, 1.0], [2, 2, 2])
}

/// A two-key box scene `NAME.toml` in `dir/in` with the given formats.
fn scene(dir: &Path, file: &str, formats: &str) {
    let input = dir.join("in");
    std::fs::create_dir_all(&input).unwrap();
    let mut k1 = cube();
    k1.positions.iter_mut().for_each(|p| p[1] += 0.5);
    std::fs::write(input.join("k0.obj"), obj::write(&cube())).unwrap();
    std::fs::write(input.join("k1.obj"), obj::write(&k1)).unwrap();
    let text = format!("name = \"box\"\n[keyframes]\nmeshes = [\"k0.obj\", \"k1.obj\"]\ntimes = [0.0, 1.0]\n[export]\nformats = {formats}\n");
    std::fs::write(input.join(file), text).unwrap();
}

fn manifest_files(folder: &Path) -> Vec<String> {
    let m = read_json(&folder.join(".blendsim-manifest.json"));
    m["files"].as_object().expect("files").keys().cloned().collect()
}

fn set(items: &[&str]) -> std::collections::BTreeSet<String> {
    items.iter().map(|s| s.to_string()).collect()
}

#[test]
fn a_rebake_with_fewer_formats_removes_its_stale_files_and_keeps_the_users() {
    let dir = TempDir::new("output-fewer");
    scene(&dir.path, "all.toml", "[\"usda\", \"usdc\", \"glb\"]");
    scene(&dir.path, "glb.toml", "[\"glb\"]");
    run(&dir.path, &["bake", "in/all.toml", "--out", "out", "-q"]).success();
    let out = dir.join("out");
    std::fs::write(out.join("notes.txt"), "keep me").unwrap();
    std::fs::create_dir_all(out.join("renders/frames")).unwrap();
    std::fs::write(out.join("renders/frames/0001.png"), "png").unwrap();
    // A file named like one blendsim writes, but that this bake does not own (no manifest
    // entry): it is the user's, and stays.
    std::fs::write(out.join("box.fbx"), "user's export").unwrap();
    let inode = |p: &str| std::fs::metadata(out.join(p)).unwrap().ino();
    let before = [inode("notes.txt"), inode("renders/frames/0001.png"), inode("box.fbx")];

    run(&dir.path, &["bake", "in/glb.toml", "--out", "out", "-q"]).success();
    assert_eq!(
        names(&out),
        set(&[".blendsim-manifest.json", "box.fbx", "box.full.glb", "box.glb", "notes.txt", "renders", "report.html", "report.json", "report.md"])
    );
    assert_eq!(manifest_files(&out), ["box.full.glb", "box.glb", "report.html", "report.json", "report.md"]);
    assert_eq!([inode("notes.txt"), inode("renders/frames/0001.png"), inode("box.fbx")], before, "the same files, untouched");
    let report = read_json(&out.join("report.json"));
    let listed: Vec<&str> = report["outputs"].as_array().unwrap().iter().map(|f| f["path"].as_str().unwrap()).collect();
    assert_eq!(listed, ["box.glb", "box.full.glb"], "the report lists exactly the files in the folder");
    assert_eq!(names(&dir.path), set(&["in", "out"]), "nothing left beside the folder");
}

/// A bake owns its folder's blendsim files, so the folder holds one bake: a bake of the box
/// renamed `crate`, with other formats, killed once its new folder is complete but before the
/// swap, leaves the first bake byte for byte; run again, it removes every file of the first
/// bake (another scene's names, formats it does not write), keeps the user's file as the same
/// file, and says both on stderr; its report lists exactly the files in the folder.
#[test]
#[cfg_attr(not(feature = "test-hooks"), ignore = "needs the test hooks: cargo test --features test-hooks (make test)")]
fn a_bake_replaces_an_earlier_bake_of_another_scene_and_says_so() {
    let dir = TempDir::new("output-renamed");
    scene(&dir.path, "all.toml", "[\"usda\", \"usdc\", \"glb\"]");
    let renamed = std::fs::read_to_string(dir.join("in/all.toml")).unwrap().replace("name = \"box\"", "name = \"crate\"");
    std::fs::write(dir.join("in/crate.toml"), renamed.replace("[\"usda\", \"usdc\", \"glb\"]", "[\"glb\"]")).unwrap();
    run(&dir.path, &["bake", "in/all.toml", "--out", "out", "-q"]).success();
    let out = dir.join("out");
    std::fs::write(out.join("notes.txt"), "keep me").unwrap();
    let first = snapshot(&out);
    let notes = std::fs::metadata(out.join("notes.txt")).unwrap().ino();

    let mut killed = Spawned::start(&dir.path, &["bake", "in/crate.toml", "--out", "out"], &[("BLENDSIM_TEST_PAUSE", OsStr::new("commit-staged"))]);
    killed.wait_for_line("paused at commit-staged", 600.0);
    killed.kill();
    assert!(snapshot(&out) == first, "an interrupted bake leaves the previous one, complete and alone");

    let r = run(&dir.path, &["bake", "in/crate.toml", "--out", "out"]).success();
    assert_eq!(names(&out), set(&[".blendsim-manifest.json", "crate.full.glb", "crate.glb", "notes.txt", "report.html", "report.json", "report.md"]));
    assert_eq!(manifest_files(&out), ["crate.full.glb", "crate.glb", "report.html", "report.json", "report.md"]);
    assert_eq!(std::fs::metadata(out.join("notes.txt")).unwrap().ino(), notes, "the user's file, untouched");
    let lines: Vec<&str> = r.stderr.lines().collect();
    assert_eq!(
        lines[..2],
        [
            "blendsim: removed from out 6 files of an earlier run that this bake did not write again: box.full.glb, box.full.usda, box.full.usdc, box.glb, box.usda and 1 more",
            "blendsim: kept in out 1 entry that blendsim did not write: notes.txt",
        ],
        "{r}"
    );
    assert!(lines.len() == 3 && lines[2].starts_with("blendsim: baked crate"), "{r}");
    let report = read_json(&out.join("report.json"));
    let listed: Vec<&str> = report["outputs"].as_array().unwrap().iter().map(|f| f["path"].as_str().unwrap()).collect();
    assert_eq!(listed, ["crate.glb", "crate.full.glb"], "the report lists exactly the bake's files");
    assert_eq!(names(&dir.path), set(&["in", "out"]), "the killed run's staging folder is gone");
}

#[test]
fn export_and_report_share_a_folder_and_each_replaces_only_its_own_files() {
    let dir = TempDir::new("output-chain");
    scene(&dir.path, "all.toml", "[\"usda\", \"glb\"]");
    let d = &dir.path;
    run(d, &["import", "in/all.toml", "-o", "keys.json"]).success();
    run(d, &["tetrahedralize", "keys.json", "-o", "body.json"]).success();
    run(d, &["solve", "body.json", "-o", "solution.json"]).success();
    run(d, &["embed", "solution.json", "-o", "animation.json"]).success();
    run(d, &["export", "animation.json", "--out", "out"]).success();
    run(d, &["report", "animation.json", "--outputs", "out/box.outputs.json", "--out", "out"]).success();
    let out = dir.join("out");
    let all = [
        ".blendsim-manifest.json",
        "box.full.glb",
        "box.full.usda",
        "box.glb",
        "box.outputs.json",
        "box.usda",
        "report.html",
        "report.json",
        "report.md",
    ];
    assert_eq!(names(&out), set(&all), "report kept the export's files");
    // Export again with fewer formats (the animation file edited to ask for glb only): the
    // report stays, the usda files go.
    let mut animation = read_json(&dir.join("animation.json"));
    animation["data"]["scene"]["export"]["formats"] = serde_json::json!(["glb"]);
    std::fs::write(dir.join("animation.json"), serde_json::to_vec(&animation).unwrap()).unwrap();
    run(d, &["export", "animation.json", "--out", "out"]).success();
    assert_eq!(
        names(&out),
        set(&[".blendsim-manifest.json", "box.full.glb", "box.glb", "box.outputs.json", "report.html", "report.json", "report.md"])
    );
    // A bake owns both groups: the export's list goes too.
    run(d, &["bake", "in/all.toml", "--out", "out", "-q"]).success();
    assert_eq!(
        names(&out),
        set(&[".blendsim-manifest.json", "box.full.glb", "box.full.usda", "box.glb", "box.usda", "report.html", "report.json", "report.md"])
    );
}

/// The first bake holds the folder (paused by the test hook); the second waits and says so,
/// `--no-wait` fails at once; when the first is stopped, the second takes over and completes.
#[test]
#[cfg_attr(not(feature = "test-hooks"), ignore = "needs the test hooks: cargo test --features test-hooks (make test)")]
fn a_second_bake_into_a_busy_folder_waits_or_fails_clearly() {
    let dir = TempDir::new("output-busy");
    scene(&dir.path, "usda.toml", "[\"usda\"]");
    scene(&dir.path, "glb.toml", "[\"glb\"]");
    // The time limits below only turn a hang into a failure: generous, so that a loaded
    // machine (CI's 2 cores at load 20) never reaches them.
    let mut first = Spawned::start(&dir.path, &["bake", "in/usda.toml", "--out", "out", "-q"], &[("BLENDSIM_TEST_PAUSE", OsStr::new("solve"))]);
    first.wait_for_line("paused at solve", 600.0);

    let r = run(&dir.path, &["bake", "in/glb.toml", "--out", "out", "--no-wait"]);
    assert_eq!(r.code, Some(1), "{r}");
    assert_eq!(
        r.stderr,
        format!(
            "error: out: another blendsim (pid {}) is writing into this output folder (fix: wait for it to finish and run again (without --no-wait, blendsim waits by itself), or choose another --out)\n",
            first.pid()
        )
    );

    let mut second = Spawned::start(&dir.path, &["bake", "in/glb.toml", "--out", "out"], &[]);
    let waiting = second.wait_for_line("waiting", 300.0);
    assert_eq!(waiting, format!("blendsim: waiting for another blendsim (pid {}) to finish writing out", first.pid()));
    std::thread::sleep(std::time::Duration::from_millis(500));
    assert!(second.wait_timeout(0.0).is_none(), "the second bake still waits");
    first.signal(libc::SIGTERM);
    let status = first.wait_timeout(300.0).expect("the first bake stops");
    assert_eq!(status.signal(), Some(libc::SIGTERM));
    let status = second.wait_timeout(600.0).expect("the second bake finishes");
    let r = second.finish(status);
    assert_eq!(r.code, Some(0), "{r}");
    assert_eq!(manifest_files(&dir.join("out")), ["box.full.glb", "box.glb", "report.html", "report.json", "report.md"]);
    assert_eq!(names(&dir.path), set(&["in", "out"]));
}

/// Two bakes started together into one folder, many times: both succeed, one after the
/// other, and the folder always holds exactly one of the two complete bakes.
#[test]
fn concurrent_bakes_into_one_folder_never_mix() {
    let dir = TempDir::new("output-race");
    scene(&dir.path, "usda.toml", "[\"usda\"]");
    scene(&dir.path, "glb.toml", "[\"glb\"]");
    let usda = set(&[".blendsim-manifest.json", "box.full.usda", "box.usda", "report.html", "report.json", "report.md"]);
    let glb = set(&[".blendsim-manifest.json", "box.full.glb", "box.glb", "report.html", "report.json", "report.md"]);
    let mut waited = 0;
    for round in 0..4 {
        let a = Spawned::start(&dir.path, &["bake", "in/usda.toml", "--out", "out"], &[]);
        let b = Spawned::start(&dir.path, &["bake", "in/glb.toml", "--out", "out"], &[]);
        let mut results = Vec::new();
        for mut p in [a, b] {
            let status = p.wait_timeout(600.0).expect("bake finishes");
            results.push(p.finish(status));
        }
        for r in &results {
            assert_eq!(r.code, Some(0), "round {round}: {r}");
            waited += r.stderr.lines().filter(|l| l.starts_with("blendsim: waiting for another blendsim")).count();
        }
        let now = names(&dir.join("out"));
        assert!(now == usda || now == glb, "round {round}: a mixed folder {now:?}");
        let report = read_json(&dir.join("out/report.json"));
        let first = report["outputs"][0]["path"].as_str().unwrap();
        assert!(now.contains(first), "round {round}: the report belongs to the bake whose files are there");
        assert_eq!(names(&dir.path), set(&["in", "out"]));
    }
    // Whether they overlapped is up to the scheduler (almost always one waits); the waiting
    // itself is checked deterministically by a_second_bake_into_a_busy_folder_waits_or_fails_clearly.
    eprintln!("{waited} of 8 bakes waited for the other");
}

#[test]
fn folders_that_cannot_be_output_folders() {
    let dir = TempDir::new("output-refused");
    scene(&dir.path, "glb.toml", "[\"glb\"]");
    std::fs::write(dir.join("file"), "").unwrap();
    let cases: [(&[&str], &str); 3] = [
        (&["bake", "in/glb.toml", "--out", "file"], "error: file: exists and is not a folder"),
        (&["bake", "in/glb.toml", "--out", "."], "error: .: is the working folder or one of its parents"),
        (&["bake", "in/glb.toml", "--out", "in/.."], "error: in/..: is the working folder or one of its parents"),
    ];
    for (args, expected) in cases {
        let r = run(&dir.path, args);
        assert_eq!(r.code, Some(1), "{r}");
        assert!(r.stderr.starts_with(expected) && r.stderr.lines().count() == 1, "{r}");
    }
    // A symlink to a folder is followed: the link stays a link, the folder is replaced.
    std::fs::create_dir(dir.join("real")).unwrap();
    std::os::unix::fs::symlink("real", dir.join("link")).unwrap();
    run(&dir.path, &["bake", "in/glb.toml", "--out", "link", "-q"]).success();
    assert!(std::fs::symlink_metadata(dir.join("link")).unwrap().file_type().is_symlink());
    assert!(dir.join("real/box.glb").is_file());
    assert_eq!(names(&dir.path), set(&["file", "in", "link", "real"]));
    // The two-rename fallback gives the same folder.
    let r = run_env(&dir.path, &["bake", "in/glb.toml", "--out", "real", "-q"], &[("BLENDSIM_TEST_NO_EXCHANGE", OsStr::new("1"))]).success();
    assert!(r.stderr.is_empty(), "{r}");
    assert!(dir.join("real/box.glb").is_file());
    assert_eq!(names(&dir.path), set(&["file", "in", "link", "real"]));
}

/// Progress on a non-terminal stderr: forced by `BLENDSIM_PROGRESS=lines`, each stage of a bake
/// names itself in plain lines (no cursor movements) and the solve's bar gives an estimate;
/// `--quiet` silences everything; by default a pipe gets only the summary line.
#[test]
fn progress_lines_when_forced_and_nothing_with_quiet() {
    let dir = TempDir::new("progress");
    scene(&dir.path, "box.toml", "[\"usda\", \"usdc\", \"glb\"]");
    let forced = [("BLENDSIM_PROGRESS", OsStr::new("lines"))];
    let shown = run_env(&dir.path, &["bake", "in/box.toml", "--out", "out/a"], &forced).success();
    for stage in ["import", "tetrahedralize", "solve", "embed", "export", "report"] {
        assert!(shown.stderr.lines().any(|l| l.contains(stage)), "no progress line for {stage}:\n{shown}");
    }
    assert!(shown.stderr.lines().any(|l| l.contains("solve") && l.contains(" eta ")), "the solve's bar has no estimate:\n{shown}");
    assert!(!shown.stderr.contains('\x1b') && !shown.stderr.contains('\r'), "progress lines must be plain text:\n{shown}");
    assert!(shown.stderr.lines().last().unwrap().starts_with("blendsim: baked box"), "{shown}");

    let quiet = run_env(&dir.path, &["bake", "in/box.toml", "--out", "out/b", "--quiet"], &forced).success();
    assert_eq!(quiet.stderr, "", "--quiet must silence progress:\n{quiet}");
    let piped = run(&dir.path, &["bake", "in/box.toml", "--out", "out/c"]).success();
    assert_eq!(piped.stderr.lines().count(), 1, "no progress on a pipe unless asked:\n{piped}");
    // The same files with or without progress.
    for file in ["box.usda", "box.usdc", "box.glb"] {
        let a = std::fs::read(dir.join("out/a").join(file)).unwrap();
        assert_eq!(a, std::fs::read(dir.join("out/b").join(file)).unwrap(), "{file}");
        assert_eq!(a, std::fs::read(dir.join("out/c").join(file)).unwrap(), "{file}");
    }
}

/// The usdc files are written natively (issue 11): a bake with no Python at all (a
/// `BLENDSIM_PYTHON` that does not exist) writes them, the same bytes twice, and usd-core reads
/// each as the same layer as the usda beside it.
#[test]
fn usdc_needs_no_python_and_has_the_same_bytes_every_run() {
    let dir = TempDir::new("usdc-native");
    scene(&dir.path, "box.toml", "[\"usda\", \"usdc\"]\nfull_frame = true");
    let no_python = [("BLENDSIM_PYTHON", OsStr::new("/nonexistent/python3"))];
    for out in ["out/a", "out/b"] {
        run_env(&dir.path, &["bake", "in/box.toml", "--out", out, "-q"], &no_python).success();
    }
    for file in ["box.usdc", "box.full.usdc"] {
        let a = std::fs::read(dir.join("out/a").join(file)).unwrap();
        assert_eq!(&a[..8], b"PXR-USDC", "{file}");
        assert_eq!(a, std::fs::read(dir.join("out/b").join(file)).unwrap(), "{file}: different bytes in two runs");
        let usda = dir.join("out/a").join(file.replace(".usdc", ".usda"));
        let summary = check_same_layer(&usda, &dir.join("out/a").join(file));
        assert_eq!(summary["ok"], true, "{file}: {summary}");
    }
}

/// Every phase's progress carries an estimate (issue 11): the solve's total is the stopping
/// rule's prediction, close to the iterations it takes (never `max_iterations`), and TetGen,
/// the cage, its fit and the embedding show a cost model's predicted duration. The demo scene
/// with 50 samples per interval on one thread, so that the solve lasts several of the lines'
/// seconds (about 6 s on an idle machine).
///
/// Which iterations get a line depends on the machine's speed and load (a bar's first frame,
/// then at most one a second), so the lines are only held to what is true at every iteration
/// (`K <= N <= max_iterations`, and within a quarter of the iterations taken over the last
/// quarter); that the estimate exists and is that close over the whole last quarter is checked
/// on the solve's own W and force-scale history (report.json), whatever lines were printed.
#[test]
fn progress_estimates_every_phase() {
    use blendsim::algorithms::spacetime::settings::NEGLIGIBLE;
    use blendsim::algorithms::spacetime::solver::IterationEstimate;
    let dir = TempDir::new("progress-estimates");
    let demo = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/demo");
    let input = dir.join("in");
    std::fs::create_dir_all(&input).unwrap();
    for entry in std::fs::read_dir(&demo).unwrap() {
        let path = entry.unwrap().path();
        std::fs::copy(&path, input.join(path.file_name().unwrap())).unwrap();
    }
    let text = std::fs::read_to_string(demo.join("twist.toml")).unwrap();
    let slow = text
        .replace("samples = 6", "samples = 50")
        .replace("formats = [\"usda\", \"usdc\", \"glb\"]\nfull_frame = true", "formats = [\"usda\"]\nfull_frame = false");
    assert_ne!(slow, text);
    assert!(slow.contains("tolerance = 0.001"), "the estimate below uses the demo's tolerance");
    std::fs::write(input.join("slow.toml"), &slow).unwrap();
    std::fs::write(
        input.join("cage.toml"),
        slow.replace("samples = 50", "samples = 4").replace("[tet]\n", "[tet]\nmax_nodes = 60\ncage_nodes = 60\n"),
    )
    .unwrap();
    let env = [("BLENDSIM_PROGRESS", OsStr::new("lines")), ("RAYON_NUM_THREADS", OsStr::new("1"))];

    let shown = run_env(&dir.path, &["bake", "in/slow.toml", "--out", "out/slow"], &env).success();
    let report = read_json(&dir.join("out/slow/report.json"));
    let iterations = report["solver"]["iterations"].as_u64().expect("iterations");
    // A bar's first frame is always a line (drawn when the bar is made), whatever the timing.
    let line =
        |prefix: &str| shown.stderr.lines().find(|l| l.starts_with(prefix)).unwrap_or_else(|| panic!("no {prefix} line:\n{shown}")).to_string();
    for prefix in ["tetrahedralize: TetGen", "embed"] {
        let l = line(prefix);
        assert!(l.contains(" of ~") && l.contains(" eta "), "{prefix} has no predicted duration: {l}");
    }
    line("solve: spacetime");
    // `K/~N` on the lines printed: N the predicted total, never past max_iterations; over the
    // last quarter of the solve within a quarter of the iterations taken.
    let close = |k: u64, n: u64| 4 * k < 3 * iterations || 4 * n.abs_diff(iterations) <= iterations;
    let totals: Vec<(u64, u64)> = shown
        .stderr
        .lines()
        .filter(|l| l.starts_with("solve: spacetime"))
        .filter_map(|l| l.split_whitespace().find_map(|w| w.split_once("/~")).map(|(k, n)| (k.parse().unwrap(), n.parse().unwrap())))
        .collect();
    for &(k, n) in &totals {
        assert!(k <= n && n <= 1000, "predicted total {n} at iteration {k} (max_iterations is 1000):\n{shown}");
        assert!(close(k, n), "at iteration {k} the predicted total was {n}, the solve took {iterations}:\n{shown}");
    }
    // The same estimate at every iteration of this solve, as the solve made it: from the W and
    // the force scale S of each iterate (the stopping rule's floor is NEGLIGIBLE S).
    let energy = crate::common::cli::energies(&report);
    let scales: Vec<f64> = report["solver"]["force_scales"].as_array().expect("solver.force_scales").iter().map(|s| s.as_f64().unwrap()).collect();
    assert_eq!(scales.len(), energy.len(), "one force scale per iterate");
    let last = report["solver"]["force_scale"].as_f64().expect("solver.force_scale");
    assert!((scales[scales.len() - 1] / last - 1.0).abs() < 1e-12 && scales.iter().all(|&s| s > 0.0), "{scales:?} ends at {last}");
    let mut estimate = IterationEstimate::default();
    let every: Vec<Option<usize>> =
        energy.iter().zip(&scales).enumerate().map(|(k, (&w, &s))| estimate.update(k, w, NEGLIGIBLE * s, 1e-3, 1000)).collect();
    let late: Vec<(u64, u64)> =
        every.iter().enumerate().filter_map(|(k, n)| n.map(|n| (k as u64, n as u64))).filter(|&(k, _)| 4 * k >= 3 * iterations).collect();
    assert!(late.len() >= 10, "a total over the last quarter of the {iterations} iterations: {every:?}");
    for &(k, n) in &late {
        assert!(k <= n && n <= 1000 && close(k, n), "at iteration {k} the predicted total is {n}, the solve took {iterations}: {every:?}");
    }
    eprintln!("printed totals (iteration, total) {totals:?}; the solve took {iterations}");

    let caged = run_env(&dir.path, &["bake", "in/cage.toml", "--out", "out/cage"], &env).success();
    for prefix in ["tetrahedralize: cage", "tetrahedralize: fit"] {
        let l = caged.stderr.lines().find(|l| l.starts_with(prefix)).unwrap_or_else(|| panic!("no {prefix} line:\n{caged}"));
        assert!(l.contains(" of ~") && l.contains(" eta "), "{prefix} has no predicted duration: {l}");
    }
}
