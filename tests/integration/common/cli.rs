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

/// A fresh folder `$TMPDIR/blendsim-NAME-XXXXXX`, removed when the test succeeds and kept (with
/// a note on stderr) when it fails, so its files can be inspected.
pub struct TempDir {
    pub path: PathBuf,
    dir: Option<tempfile::TempDir>,
}

impl TempDir {
    pub fn new(name: &str) -> TempDir {
        let dir =
            tempfile::Builder::new().prefix(&format!("blendsim-{name}-")).tempdir().unwrap_or_else(|e| panic!("a temporary folder for {name}: {e}"));
        TempDir { path: dir.path().to_path_buf(), dir: Some(dir) }
    }

    pub fn join(&self, rel: impl AsRef<Path>) -> PathBuf {
        self.path.join(rel)
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        if std::thread::panicking() {
            if let Some(dir) = self.dir.take() {
                eprintln!("kept for inspection: {}", dir.keep().display());
            }
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

/// Runs the chain of subcommands (import .. export) on `scene` in `cwd`, into `cwd/chained`,
/// and asserts that each of `files` has the bytes `bake` wrote into `cwd/baked`: the stage
/// files carry everything, and their readers accept what the writers wrote.
pub fn assert_chain_gives_bake_bytes(cwd: &Path, scene: &str, baked: &str, files: &[&str]) {
    for args in [
        &["import", scene, "-o", "keys.json"][..],
        &["tetrahedralize", "keys.json", "-o", "body.json"],
        &["solve", "body.json", "-o", "solution.json"],
        &["embed", "solution.json", "-o", "animation.json"],
        &["export", "animation.json", "--out", "chained"],
    ] {
        run(cwd, args).success();
    }
    for name in files {
        let (chained, bake) = (std::fs::read(cwd.join("chained").join(name)).unwrap(), std::fs::read(cwd.join(baked).join(name)).unwrap());
        assert!(chained == bake, "{name}: the chain of subcommands differs from the bake");
    }
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
    // The iterations' split: its counts are the solve's, its seconds the clock's.
    if let Some(split) = solver.get_mut("iteration_split").and_then(Value::as_object_mut) {
        for key in ["evaluation_seconds", "solve_seconds"] {
            assert!(split.remove(key).is_some(), "report.json solver.iteration_split.{key} is missing");
        }
    }
    report
}

/// `solver.energy` of a report.json.
pub fn energies(report: &Value) -> Vec<f64> {
    report["solver"]["energy"].as_array().expect("solver.energy is an array").iter().map(|w| w.as_f64().unwrap()).collect()
}

/// The solver's key times of a report (`solver.times`: optimized, when the scene optimizes them).
pub fn key_times(report: &Value) -> Vec<f64> {
    report["solver"]["times"].as_array().expect("solver.times is an array").iter().map(|t| t.as_f64().unwrap()).collect()
}

/// Run `blendsim ARGS` in `cwd` with extra environment, failing the test if it has not ended
/// within `seconds` (a hang is a failure, not a stuck test run).
pub fn run_timeout<S: AsRef<OsStr>>(cwd: &Path, args: &[S], env: &[(&str, &OsStr)], seconds: f64) -> Run {
    let mut p = Spawned::start(cwd, args, env);
    let status = p.wait_timeout(seconds).unwrap_or_else(|| {
        p.kill();
        let stderr = p.stderr_so_far();
        panic!("blendsim {:?} did not finish within {seconds} s; stderr so far:\n{stderr}", p.args)
    });
    p.finish(status)
}

/// A `blendsim` process running in the background, its stderr read line by line (to wait for
/// the `BLENDSIM_TEST_PAUSE` hook's line).
pub struct Spawned {
    pub args: Vec<String>,
    pub child: std::process::Child,
    lines: std::sync::mpsc::Receiver<String>,
    stderr: Vec<String>,
    stdout: std::thread::JoinHandle<String>,
}

impl Spawned {
    pub fn start<S: AsRef<OsStr>>(cwd: &Path, args: &[S], env: &[(&str, &OsStr)]) -> Spawned {
        use std::io::{BufRead, Read};
        let mut cmd = Command::new(bin());
        cmd.args(args).current_dir(cwd).stdin(std::process::Stdio::null()).stdout(std::process::Stdio::piped()).stderr(std::process::Stdio::piped());
        for (k, v) in env {
            cmd.env(k, v);
        }
        let mut child = cmd.spawn().unwrap_or_else(|e| panic!("cannot start {}: {e}", bin()));
        let (send, lines) = std::sync::mpsc::channel();
        let err = child.stderr.take().unwrap();
        std::thread::spawn(move || {
            for line in std::io::BufReader::new(err).lines() {
                let Ok(line) = line else { break };
                if send.send(line).is_err() {
                    break;
                }
            }
        });
        let mut out = child.stdout.take().unwrap();
        let stdout = std::thread::spawn(move || {
            let mut s = String::new();
            let _ = out.read_to_string(&mut s);
            s
        });
        Spawned { args: args.iter().map(|a| a.as_ref().to_string_lossy().into_owned()).collect(), child, lines, stderr: Vec::new(), stdout }
    }

    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// Wait for a stderr line containing `needle`; returns it, or panics after `seconds`.
    pub fn wait_for_line(&mut self, needle: &str, seconds: f64) -> String {
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs_f64(seconds);
        loop {
            let left = deadline.saturating_duration_since(std::time::Instant::now());
            match self.lines.recv_timeout(left) {
                Ok(line) => {
                    self.stderr.push(line.clone());
                    if line.contains(needle) {
                        return line;
                    }
                }
                Err(_) => {
                    self.kill();
                    panic!("blendsim {:?} never said {needle:?} within {seconds} s; stderr:\n{}", self.args, self.stderr.join("\n"))
                }
            }
        }
    }

    /// Send `signal` (a libc signal number).
    pub fn signal(&self, signal: i32) {
        // SAFETY: kill(2) on our own child's pid.
        assert_eq!(unsafe { libc::kill(self.pid() as libc::pid_t, signal) }, 0, "kill {signal}");
    }

    pub fn kill(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }

    /// The exit status, or `None` if it is still running after `seconds`.
    pub fn wait_timeout(&mut self, seconds: f64) -> Option<std::process::ExitStatus> {
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs_f64(seconds);
        loop {
            if let Some(status) = self.child.try_wait().expect("try_wait") {
                return Some(status);
            }
            if std::time::Instant::now() > deadline {
                return None;
            }
            std::thread::sleep(std::time::Duration::from_millis(10));
        }
    }

    pub fn stderr_so_far(&mut self) -> String {
        while let Ok(line) = self.lines.try_recv() {
            self.stderr.push(line);
        }
        self.stderr.join("\n")
    }

    /// Collect everything once the process has ended with `status`.
    pub fn finish(mut self, status: std::process::ExitStatus) -> Run {
        // The reader thread ends with the pipe; drain what is left.
        while let Ok(line) = self.lines.recv_timeout(std::time::Duration::from_secs(5)) {
            self.stderr.push(line);
        }
        let stdout = self.stdout.join().unwrap_or_default();
        let mut stderr = self.stderr.join("\n");
        if !stderr.is_empty() {
            stderr.push('\n');
        }
        Run { args: self.args, code: status.code(), stdout, stderr }
    }
}

/// Whether a process with this id exists and is not a zombie.
pub fn process_alive(pid: u32) -> bool {
    match std::fs::read_to_string(format!("/proc/{pid}/stat")) {
        Ok(stat) => stat.rsplit_once(") ").is_some_and(|(_, rest)| !rest.starts_with(['Z', 'X'])),
        Err(_) => false,
    }
}

/// Every file under `dir` (hidden ones included) with its bytes, and every folder (with no
/// bytes): what a folder holds, to compare before and after a run.
pub fn snapshot(dir: &Path) -> std::collections::BTreeMap<String, Option<Vec<u8>>> {
    fn walk(root: &Path, dir: &Path, out: &mut std::collections::BTreeMap<String, Option<Vec<u8>>>) {
        let Ok(entries) = std::fs::read_dir(dir) else { return };
        for e in entries {
            let path = e.unwrap().path();
            let rel = path.strip_prefix(root).unwrap().to_string_lossy().into_owned();
            if path.is_dir() {
                out.insert(rel, None);
                walk(root, &path, out);
            } else {
                out.insert(rel, Some(std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))));
            }
        }
    }
    let mut out = std::collections::BTreeMap::new();
    walk(dir, dir, &mut out);
    out
}

/// A copy of the bundled demo scene (`fixtures/demo`) in `to`.
pub fn copy_demo(to: &Path) {
    copy_tree(&Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/demo"), to);
}

/// Copy a folder tree (files and folders only).
pub fn copy_tree(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        let (src, dst) = (e.path(), to.join(e.file_name()));
        if src.is_dir() {
            copy_tree(&src, &dst);
        } else {
            std::fs::copy(&src, &dst).unwrap();
        }
    }
}
