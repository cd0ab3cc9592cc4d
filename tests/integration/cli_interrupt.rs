//! Interrupted bakes, through the `blendsim` binary: SIGINT, SIGTERM and SIGKILL at every
//! phase (during TetGen, the solve, the export and the usd-core conversion, and between the
//! steps of the commit), stopped there deterministically by the `BLENDSIM_TEST_PAUSE` test
//! hook. Each time the output folder must hold the complete old bake or the complete new one
//! (byte for byte, but for the report's timings), the files in it that are not blendsim's must
//! be the same files (same inodes), no TetGen or Python child may survive, SIGINT/SIGTERM must
//! leave no staging folder, lock or TetGen work folder, and after a SIGKILL the next bake must
//! find and remove what was left. A run with `BLENDSIM_TEST_NO_EXCHANGE=1` covers the
//! two-rename fallback of file systems without `RENAME_EXCHANGE`.
//!
//! Run with `--nocapture` to see the results table.

use std::collections::BTreeMap;
use std::ffi::OsStr;
use std::os::unix::fs::MetadataExt;
use std::os::unix::process::ExitStatusExt;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use crate::common::cli::{copy_tree, names, process_alive, run_env, snapshot, Spawned, TempDir};
use blendsim::algorithms::geometry::TriMesh;
use blendsim::algorithms::procedural::prism;
use blendsim::formats::mesh::obj;

fn cube() -> TriMesh {
    prism([1.0, 1.0, 1.0], [2, 2, 2])
}

fn moved(by: [f64; 3]) -> TriMesh {
    let mut m = cube();
    m.positions.iter_mut().for_each(|p| (0..3).for_each(|d| p[d] += by[d]));
    m
}

/// The old bake writes usda and glb; the new one also usdc (so the two differ in their file
/// lists as well as in their report); the slow one asks TetGen for millions of tets, so TetGen
/// is still running when the signal comes. (The slow one reads a finer box, `fine.obj`: with
/// `-Y`, TetGen 1.5 does not refine the 2 x 2 x 2 box at all and ends within milliseconds,
/// whatever the volume bound.)
fn scene(formats: &str, tet: &str) -> String {
    format!(
        "name = \"box\"\n[keyframes]\nmeshes = [\"k0.obj\", \"k1.obj\", \"k0.obj\"]\ntimes = [0.0, 0.5, 1.0]\n\
         fixed = [\"all\", \"none\", \"all\"]\n{tet}\n[export]\nformats = {formats}\n"
    )
}

struct Fixture {
    dir: PathBuf,
    /// Normalized contents of the old and the new bake.
    old: Contents,
    new: Contents,
}

type Contents = BTreeMap<String, Option<Vec<u8>>>;

/// Inputs and the reference bakes, made once for every test of this file.
fn fixture() -> &'static Fixture {
    static FIXTURE: OnceLock<Fixture> = OnceLock::new();
    FIXTURE.get_or_init(|| {
        // Under Cargo's scratch folder: a static is never dropped, so it would not be removed.
        let dir = crate::common::scratch("interrupt-fixture");
        let input = dir.join("in");
        std::fs::create_dir_all(&input).unwrap();
        std::fs::write(input.join("k0.obj"), obj::write(&cube())).unwrap();
        std::fs::write(input.join("k1.obj"), obj::write(&moved([0.0, 0.4, 0.1]))).unwrap();
        std::fs::write(input.join("old.toml"), scene("[\"usda\", \"glb\"]", "")).unwrap();
        std::fs::write(input.join("new.toml"), scene("[\"usda\", \"usdc\", \"glb\"]", "")).unwrap();
        std::fs::write(input.join("fine.obj"), obj::write(&prism([1.0, 1.0, 1.0], [4, 4, 4]))).unwrap();
        let slow = scene("[\"usda\", \"usdc\", \"glb\"]", "[tet]\nmax_volume = 1e-8")
            .replace("\"k0.obj\", \"k1.obj\", \"k0.obj\"", "\"fine.obj\", \"fine.obj\", \"fine.obj\"");
        assert!(slow.contains("fine.obj"));
        std::fs::write(input.join("slow.toml"), slow).unwrap();
        std::fs::write(input.join("bad.toml"), scene("[\"usda\"]", "").replace("k1.obj", "missing.obj")).unwrap();
        for which in ["old", "new"] {
            run_env(&dir, &["bake", &format!("in/{which}.toml"), "--out", &format!("ref/{which}"), "-q"], &[]).success();
        }
        let old = normalized(&dir.join("ref/old"));
        let new = normalized(&dir.join("ref/new"));
        assert_ne!(old, new);
        Fixture { dir, old, new }
    })
}

const FOREIGN: [&str; 3] = ["notes.txt", "renders", "renders/a.png"];

/// A bake folder's contents without the files that are not blendsim's, and without the
/// report's wall-clock timings.
fn normalized(folder: &Path) -> Contents {
    let mut s = snapshot(folder);
    for f in FOREIGN {
        s.remove(f);
    }
    if let Some(Some(bytes)) = s.get_mut("report.json") {
        let report = crate::common::cli::without_timings(serde_json::from_slice(bytes).unwrap());
        *bytes = serde_json::to_vec(&report).unwrap();
    }
    if let Some(Some(bytes)) = s.get_mut("report.md") {
        let text = String::from_utf8(bytes.clone()).unwrap();
        *bytes = text.lines().filter(|l| !l.starts_with("| time |")).collect::<Vec<_>>().join("\n").into_bytes();
    }
    if let Some(Some(bytes)) = s.get_mut("report.html") {
        let text = String::from_utf8(bytes.clone()).unwrap();
        *bytes = text.lines().filter(|l| !l.starts_with("<tr><td>time</td>")).collect::<Vec<_>>().join("\n").into_bytes();
    }
    s
}

#[derive(Clone, Copy, PartialEq, Debug)]
enum State {
    Old,
    New,
    /// Only the fallback commit killed between its renames: no folder, the old one beside it.
    MovedAside,
}

struct Phase {
    hook: &'static str,
    scene: &'static str,
    /// The bake had passed its point of no return.
    committed: bool,
    fallback: bool,
    /// The hook line names a child process (TetGen).
    child: bool,
}

const PHASES: [Phase; 7] = [
    Phase { hook: "tetgen", scene: "slow", committed: false, fallback: false, child: true },
    Phase { hook: "solve", scene: "new", committed: false, fallback: false, child: false },
    Phase { hook: "staged", scene: "new", committed: false, fallback: false, child: false },
    Phase { hook: "usdc", scene: "new", committed: false, fallback: false, child: false },
    Phase { hook: "commit-staged", scene: "new", committed: false, fallback: false, child: false },
    Phase { hook: "commit-swapped", scene: "new", committed: true, fallback: false, child: false },
    Phase { hook: "commit-moved-aside", scene: "new", committed: true, fallback: true, child: false },
];

fn signal_name(signal: i32) -> &'static str {
    match signal {
        libc::SIGINT => "SIGINT",
        libc::SIGTERM => "SIGTERM",
        _ => "SIGKILL",
    }
}

/// One case: an old bake with files of the user's beside it, a new bake stopped at `phase`
/// by `signal`. Returns the row of the results table.
fn interrupt(signal: i32, phase: &Phase) -> String {
    let f = fixture();
    let case = TempDir::new(&format!("interrupt-{}-{}", signal_name(signal), phase.hook));
    copy_tree(&f.dir.join("in"), &case.join("in"));
    let folder = case.join("out/box");
    copy_tree(&f.dir.join("ref/old"), &folder);
    std::fs::write(folder.join("notes.txt"), "the user's notes").unwrap();
    std::fs::create_dir(folder.join("renders")).unwrap();
    std::fs::write(folder.join("renders/a.png"), "a render").unwrap();
    let inodes = |folder: &Path| ["notes.txt", "renders/a.png"].map(|f| std::fs::metadata(folder.join(f)).unwrap().ino());
    let foreign = inodes(&folder);
    let tmp = case.join("tmp");
    std::fs::create_dir(&tmp).unwrap();
    let mut env: Vec<(&str, &OsStr)> = vec![("TMPDIR", tmp.as_os_str()), ("BLENDSIM_TEST_PAUSE", OsStr::new(phase.hook))];
    if phase.fallback {
        env.push(("BLENDSIM_TEST_NO_EXCHANGE", OsStr::new("1")));
    }
    let scene = format!("in/{}.toml", phase.scene);
    let mut p = Spawned::start(&case.path, &["bake", &scene, "--out", "out/box", "-q"], &env);
    // The time limits of these tests only turn a hang into a failure: generous, so that a
    // loaded machine (CI's 2 cores at load 20) never reaches them.
    let line = p.wait_for_line(&format!("test hook: paused at {}", phase.hook), 600.0);
    let child: Option<u32> = line.split("(pid ").nth(1).and_then(|r| r.trim_end_matches(')').parse().ok());
    assert_eq!(child.is_some(), phase.child, "{line}");
    if let Some(c) = child {
        assert!(process_alive(c), "the child {c} runs while the bake is paused: {line}");
    }
    p.signal(signal);
    let status = p.wait_timeout(300.0).unwrap_or_else(|| {
        p.kill();
        panic!("{} at {} did not end the process", signal_name(signal), phase.hook)
    });
    let run = p.finish(status);
    assert_eq!(status.signal(), Some(signal), "{} at {}: the process must end by the signal:\n{run}", signal_name(signal), phase.hook);
    let mut child_note = "-".to_string();
    if let Some(c) = child {
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs(60);
        while process_alive(c) && std::time::Instant::now() < deadline {
            std::thread::sleep(std::time::Duration::from_millis(20));
        }
        assert!(!process_alive(c), "{} at {}: the child {c} outlived blendsim", signal_name(signal), phase.hook);
        child_note = "killed".into();
    }

    let state = if !folder.exists() {
        State::MovedAside
    } else if normalized(&folder) == f.old {
        State::Old
    } else if normalized(&folder) == f.new {
        State::New
    } else {
        panic!("{} at {}: the folder holds neither the old nor the new bake: {:?}", signal_name(signal), phase.hook, snapshot(&folder).keys());
    };
    let expected = match (signal, phase.committed, phase.fallback) {
        (libc::SIGKILL, true, true) => State::MovedAside,
        (_, true, _) => State::New,
        _ => State::Old,
    };
    assert_eq!(state, expected, "{} at {}", signal_name(signal), phase.hook);
    let out = case.join("out");
    let leftovers: Vec<String> = names(&out).into_iter().filter(|n| n != "box").collect();
    let leftover_note = if signal == libc::SIGKILL {
        // The killed run left its staging folder (and lock) for the next run to find.
        assert!(!leftovers.is_empty(), "a SIGKILL leaves what the next run must clean: {leftovers:?}");
        if state == State::MovedAside {
            let old = leftovers.iter().find(|n| n.starts_with(".box.blendsim-old-")).expect("the old folder beside");
            assert_eq!(normalized(&out.join(old)), f.old, "the moved-aside folder is the complete old bake");
            // Any next run into the folder puts the old bake back first, even one that fails.
            let r = run_env(&case.path, &["bake", "in/bad.toml", "--out", "out/box", "-q"], &[("TMPDIR", tmp.as_os_str())]);
            assert_eq!(r.code, Some(1), "{r}");
            assert_eq!(normalized(&folder), f.old, "restored by the next run");
        }
        let r = run_env(&case.path, &["bake", "in/new.toml", "--out", "out/box", "-q"], &[("TMPDIR", tmp.as_os_str())]).success();
        // Quiet but for the scene's own warnings (its free middle key moves: keys-moved).
        assert!(r.stderr.lines().all(|l| l.starts_with("blendsim: warning: ")), "{r}");
        assert_eq!(normalized(&folder), f.new, "the next bake completes");
        format!("{} left; removed by the next bake", leftovers.join(" "))
    } else {
        assert!(leftovers.is_empty(), "{} at {} left {leftovers:?}", signal_name(signal), phase.hook);
        assert!(run.stderr.ends_with(&format!("blendsim: stopped by {}; unfinished files were removed\n", signal_name(signal))), "{run}");
        "none".to_string()
    };
    assert_eq!(names(&out), ["box".to_string()].into(), "nothing beside the output folder");
    assert!(names(&tmp).is_empty(), "TetGen's work folder is gone: {:?}", names(&tmp));
    assert_eq!(inodes(&folder), foreign, "the user's files are the same files");
    assert_eq!(std::fs::read_to_string(folder.join("notes.txt")).unwrap(), "the user's notes");
    let state = match state {
        State::Old => "old bake, complete",
        State::New => "new bake, complete",
        State::MovedAside => "no folder; old bake complete beside it (restored by the next run)",
    };
    format!(
        "| {} | {}{} | {state} | {child_note} | {leftover_note} |",
        signal_name(signal),
        phase.hook,
        if phase.fallback { " (fallback)" } else { "" }
    )
}

fn every_phase(signal: i32) {
    let rows: Vec<String> = PHASES.iter().map(|phase| interrupt(signal, phase)).collect();
    eprintln!("| signal | phase | folder after the signal | child | staging, lock, work folder |\n|---|---|---|---|---|\n{}", rows.join("\n"));
}

#[test]
#[cfg_attr(not(feature = "test-hooks"), ignore = "needs the test hooks: cargo test --features test-hooks (make test)")]
fn sigint_at_every_phase() {
    every_phase(libc::SIGINT);
}

#[test]
#[cfg_attr(not(feature = "test-hooks"), ignore = "needs the test hooks: cargo test --features test-hooks (make test)")]
fn sigterm_at_every_phase() {
    every_phase(libc::SIGTERM);
}

#[test]
#[cfg_attr(not(feature = "test-hooks"), ignore = "needs the test hooks: cargo test --features test-hooks (make test)")]
fn sigkill_at_every_phase() {
    every_phase(libc::SIGKILL);
}

/// No hook: SIGINT after a range of delays into a real bake. Whatever it interrupts, the
/// folder holds one complete bake and nothing is left beside it.
#[test]
fn sigint_at_arbitrary_moments() {
    let f = fixture();
    for delay_ms in [20, 100, 300, 600, 1000, 1600, 2500, 4000] {
        let case = TempDir::new(&format!("interrupt-any-{delay_ms}"));
        copy_tree(&f.dir.join("in"), &case.join("in"));
        let folder = case.join("out/box");
        copy_tree(&f.dir.join("ref/old"), &folder);
        let tmp = case.join("tmp");
        std::fs::create_dir(&tmp).unwrap();
        let mut p = Spawned::start(&case.path, &["bake", "in/new.toml", "--out", "out/box", "-q"], &[("TMPDIR", tmp.as_os_str())]);
        std::thread::sleep(std::time::Duration::from_millis(delay_ms));
        p.signal(libc::SIGINT);
        let status = p.wait_timeout(600.0).expect("the bake ends");
        let contents = normalized(&folder);
        let state = if contents == f.old {
            "old"
        } else if contents == f.new {
            "new"
        } else {
            panic!("mixed folder after {delay_ms} ms")
        };
        eprintln!("SIGINT after {delay_ms} ms: {status:?}, {state} bake");
        assert!(status.signal() == Some(libc::SIGINT) || (status.success() && state == "new"), "{status:?}");
        assert_eq!(names(&case.join("out")), ["box".to_string()].into());
        assert!(names(&tmp).is_empty());
    }
}
