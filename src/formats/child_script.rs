//! Python child processes that read what no Rust crate reads (usd-core for USD, the Alembic
//! library's `alembic3d` bindings for Alembic): one runner, so every reader has the same
//! contract with its script and is bounded by `--max-time` the same way.
//!
//! The contract: the script is passed with `python -c`; it exits 0 on success (its results go
//! to files the caller names), [`NO_MODULE`] when it cannot import its library, [`USER_ERROR`]
//! with a last stderr line `TAG: PROBLEM | FIX` for a problem of the file, anything else for a
//! failure of the library. The Python executable is `$BLENDSIM_PYTHON`, or `python3`.
//!
//! The child is started in its own process group that dies with us (`interrupt::spawn`);
//! under a `--max-time` budget it is killed, with its group, at the deadline, and the error is
//! the budget's, naming the file. Its work folder is the caller's ([`super::work_dir::WorkDir`]),
//! removed when dropped, so a stopped child leaves nothing behind.

use std::ffi::{OsStr, OsString};
use std::path::Path;
use std::process::{Command, Stdio};

use crate::support::budget::Budget;
use crate::support::error::{Error, Result};

/// The exit status of a script that cannot import its library.
pub(crate) const NO_MODULE: i32 = 3;
/// The exit status of a script that found a problem in the file (its last line says which).
pub(crate) const USER_ERROR: i32 = 4;

/// One Python script and how to speak of it in messages.
pub(crate) struct ChildScript<'a> {
    /// The script's source.
    pub source: &'static str,
    /// What the script does, for "cannot run python3 {purpose}": "to read Alembic".
    pub purpose: &'a str,
    /// The library, for messages: "usd-core", "the Alembic library".
    pub library: &'a str,
    /// What the script imports, for "python3 cannot import {module}".
    pub module: &'a str,
    /// The fix when Python or the module is missing.
    pub install: &'a str,
    /// The prefix of the script's one-line problems: "blendsim-usd: ".
    pub tag: &'a str,
    /// The fix of a failure of the library.
    pub check: &'a str,
    /// Environment variables for the child.
    pub env: &'a [(&'a str, &'a str)],
}

impl ChildScript<'_> {
    /// Run the script with `args`; its one-line errors become errors about `path`. Under a
    /// `--max-time` budget the process is killed (with its process group) once the budget is
    /// spent: a hanging reader stops the bake at the deadline with the budget's error.
    pub(crate) fn run(&self, path: &Path, args: &[&OsStr], budget: &Budget) -> Result<()> {
        let python = std::env::var_os("BLENDSIM_PYTHON").unwrap_or_else(|| OsString::from("python3"));
        let py = python.to_string_lossy().into_owned();
        let cannot_run = |e: std::io::Error| Error::in_file(path, format!("cannot run {py} {}: {e}", self.purpose), self.install);
        let mut command = Command::new(&python);
        command.envs(self.env.iter().copied()).arg("-c").arg(self.source).args(args);
        // Started so that it dies with us (signal or kill), see `interrupt::spawn`. Its stdout
        // is unused (results go to files); its stderr is drained by a thread while it runs, so
        // a script (or its library) that writes more than a pipe buffer never blocks on it.
        let mut child =
            crate::support::interrupt::spawn(command.stdin(Stdio::null()).stdout(Stdio::null()).stderr(Stdio::piped())).map_err(cannot_run)?;
        let mut pipe = child.child().stderr.take().expect("stderr is piped");
        let drain = std::thread::spawn(move || {
            let mut bytes = Vec::new();
            // A read error ends the message early; the exit status still tells what happened.
            let _ = std::io::Read::read_to_end(&mut pipe, &mut bytes);
            bytes
        });
        if budget.time_left().is_some() {
            let started = std::time::Instant::now();
            // Poll: a reader takes half a second to start Python, so 20 ms is nothing.
            while child.child().try_wait().map_err(cannot_run)?.is_none() {
                if budget.time_left().is_some_and(|left| left <= 0.0) {
                    // Dropping the guard kills the reader's process group (the drain then ends).
                    drop(child);
                    let reached = format!("{}'s reader stopped after {:.2} s", self.library, started.elapsed().as_secs_f64());
                    let spent = budget.time_spent("cache reading", &reached);
                    return Err(Error { fix: format!("raise --max-time; if the reader hangs, {}", self.check), ..spent.with_path(path) });
                }
                std::thread::sleep(std::time::Duration::from_millis(20));
            }
        }
        let status = child.wait_with_output().map_err(cannot_run)?.status;
        let stderr = drain.join().unwrap_or_default();
        let output = std::process::Output { status, stdout: Vec::new(), stderr };
        if output.status.success() {
            return Ok(());
        }
        let stderr = String::from_utf8_lossy(&output.stderr);
        let last = stderr.lines().rev().find(|l| !l.trim().is_empty()).unwrap_or("no message").trim();
        Err(match output.status.code() {
            Some(NO_MODULE) => Error::in_file(path, format!("{py} cannot import {} ({last})", self.module), self.install),
            Some(USER_ERROR) => {
                let message = stderr.lines().rev().find_map(|l| l.strip_prefix(self.tag)).unwrap_or(last);
                let (problem, fix) = message.split_once(" | ").unwrap_or((message, self.check));
                Error::in_file(path, problem, fix)
            }
            _ => Error::in_file(path, format!("{} failed ({}: {last})", self.library, output.status), self.check),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A script that writes `bytes` of noise to stderr, then a problem of the file.
    const NOISY: &str =
        "import sys\nsys.stderr.write('x' * int(sys.argv[1]) + '\\n')\nsys.stderr.write('test-tag: the file is bad | fix it\\n')\nsys.exit(4)\n";

    fn noisy() -> ChildScript<'static> {
        ChildScript {
            source: NOISY,
            purpose: "to test",
            library: "the test library",
            module: "sys",
            install: "install python3",
            tag: "test-tag: ",
            check: "check the test",
            env: &[],
        }
    }

    /// More than a pipe buffer (64 KiB) on stderr, under a `--max-time` budget: the child is
    /// not blocked on its pipe until the deadline (whose error would be the budget's), and its
    /// last line becomes the error.
    #[test]
    fn a_child_that_writes_much_to_stderr_ends_and_its_problem_is_read() {
        let budget = Budget::new(None, Some(30.0));
        let err = noisy().run(Path::new("bad.abc"), &[OsStr::new("1000000")], &budget).unwrap_err();
        assert_eq!((err.problem.as_str(), err.fix.as_str()), ("the file is bad", "fix it"), "{err}");
    }
}
