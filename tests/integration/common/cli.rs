//! Run the `blendsim` binary as a user (or a Makefile) does, in a temporary folder of its own,
//! and inspect what it left behind.

use std::collections::BTreeSet;
use std::ffi::OsStr;
use std::path::{Path, PathBuf};
use std::process::Command;

use serde_json::Value;

/// The binary Cargo built for this test run.
pub fn bin() -> &'static str {
    env!("CARGO_BIN_EXE_blendsim")
}

/// What one run of `blendsim` did.
#[derive(Debug)]
pub struct Run {
    pub args: Vec<String>,
    /// The exit code (`None` when killed by a signal).
    pub code: Option<i32>,
    pub stdout: String,
    pub stderr: String,
}

impl Run {
    /// Panic with the whole run unless it exited 0.
    pub fn success(self) -> Run {
        assert_eq!(self.code, Some(0), "blendsim {:?} failed:\n{}", self.args, self);
        self
    }
}

impl std::fmt::Display for Run {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "exit {:?}\n--- stdout\n{}--- stderr\n{}", self.code, self.stdout, self.stderr)
    }
}

/// Run `blendsim ARGS` in `cwd` with extra environment variables (for the child only).
pub fn run_env<S: AsRef<OsStr>>(cwd: &Path, args: &[S], env: &[(&str, &OsStr)]) -> Run {
    let mut cmd = Command::new(bin());
    cmd.args(args).current_dir(cwd).stdin(std::process::Stdio::null());
    for (k, v) in env {
        cmd.env(k, v);
    }
    let out = cmd.output().unwrap_or_else(|e| panic!("cannot start {}: {e}", bin()));
    Run {
        args: args.iter().map(|a| a.as_ref().to_string_lossy().into_owned()).collect(),
        code: out.status.code(),
        stdout: String::from_utf8_lossy(&out.stdout).into_owned(),
        stderr: String::from_utf8_lossy(&out.stderr).into_owned(),
    }
}

/// Run `blendsim ARGS` in `cwd`.
pub fn run<S: AsRef<OsStr>>(cwd: &Path, args: &[S]) -> Run {
    run_env(cwd, args, &[])
}

/// A fresh folder `$TMPDIR/blendsim-NAME-PID`, removed when the test succeeds and kept (with a
/// note on stderr) when it fails, so its files can be inspected.
pub struct TempDir {
    pub path: PathBuf,
}

impl TempDir {
    pub fn new(name: &str) -> TempDir {
        let path = std::env::temp_dir().join(format!("blendsim-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&path);
        std::fs::create_dir_all(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        TempDir { path }
    }

    pub fn join(&self, rel: impl AsRef<Path>) -> PathBuf {
        self.path.join(rel)
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        if std::thread::panicking() {
            eprintln!("kept for inspection: {}", self.path.display());
        } else {
            let _ = std::fs::remove_dir_all(&self.path);
        }
    }
}

/// Every file and folder under `dir` (hidden ones included), as paths relative to it.
pub fn tree(dir: &Path) -> BTreeSet<String> {
    fn walk(root: &Path, dir: &Path, out: &mut BTreeSet<String>) {
        let Ok(entries) = std::fs::read_dir(dir) else { return };
        for e in entries {
            let path = e.unwrap().path();
            out.insert(path.strip_prefix(root).unwrap().to_string_lossy().into_owned());
            if path.is_dir() {
                walk(root, &path, out);
            }
        }
    }
    let mut out = BTreeSet::new();
    walk(dir, dir, &mut out);
    out
}

/// The file names directly in `dir`.
pub fn names(dir: &Path) -> BTreeSet<String> {
    std::fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect()
}

pub fn read_json(path: &Path) -> Value {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_slice(&bytes).unwrap_or_else(|e| panic!("{} is not JSON: {e}", path.display()))
}

/// A report.json without the fields that measure wall-clock time.
pub fn without_timings(mut report: Value) -> Value {
    let solver = report["solver"].as_object_mut().expect("report.json has a solver object");
    for key in ["seconds", "precompute_seconds", "iteration_seconds"] {
        assert!(solver.remove(key).is_some(), "report.json solver.{key} is missing");
    }
    report
}

/// `solver.energy` of a report.json.
pub fn energies(report: &Value) -> Vec<f64> {
    report["solver"]["energy"].as_array().expect("solver.energy is an array").iter().map(|w| w.as_f64().unwrap()).collect()
}
