//! Clean interruption: what a signal must undo, child processes that die with us, and the
//! test hook that stops the binary at a named point.
//!
//! Files and folders a run creates before it has succeeded (staging folders, temporaries,
//! TetGen's work folder, a lock file) are registered here while they exist, and so are child
//! processes. [`install`] (called once by the CLI, before any thread starts) has SIGINT,
//! SIGTERM and SIGHUP delivered to a thread of its own (signal-hook's iterator), where the
//! cleanup runs in ordinary code: it kills the registered children's process groups, removes
//! the registered paths, and dies by the same signal (so a shell or `make` sees the usual
//! status). The commit of an output folder is a critical section (`critical`): a signal
//! that arrives during it waits until the folder holds the new bake (or, before the point of no
//! return, until the commit has backed out), so the folder is never left half-replaced.
//!
//! SIGKILL cannot be caught: children still die with us because they are started with
//! `PR_SET_PDEATHSIG = SIGKILL` (Linux; the signal fires when the *thread* that started them
//! exits, and they are started from the thread that waits for them), and the next run into the
//! same output folder removes what was left (see [`crate::support::output`]).

use std::path::PathBuf;
use std::process::{Child, Command, Output};
use std::sync::atomic::{AtomicI32, Ordering};
use std::sync::{Mutex, MutexGuard};
use std::time::Duration;

/// What to undo for one registered item.
#[derive(Debug)]
enum Undo {
    /// A folder and everything in it.
    Tree(PathBuf),
    /// One file.
    File(PathBuf),
    /// A folder, only if it is empty (a parent created for an output folder).
    EmptyDir(PathBuf),
    /// A child process, leader of its own process group.
    Child(u32),
}

struct State {
    next: u64,
    items: Vec<(u64, Undo)>,
}

static STATE: Mutex<State> = Mutex::new(State { next: 0, items: Vec::new() });
/// Held during a commit; the signal thread takes it before cleaning up.
static COMMIT: Mutex<()> = Mutex::new(());
/// The signal that asked us to stop, or 0.
static REQUESTED: AtomicI32 = AtomicI32::new(0);

fn state() -> MutexGuard<'static, State> {
    STATE.lock().unwrap_or_else(|e| e.into_inner())
}

/// A registered item; dropping it unregisters it (the owner has undone it, or made it
/// permanent).
#[derive(Debug)]
#[must_use = "the item is unregistered when the token is dropped"]
pub(crate) struct Token(u64);

impl Drop for Token {
    fn drop(&mut self) {
        state().items.retain(|(id, _)| *id != self.0);
    }
}

fn register(undo: Undo) -> Token {
    let mut s = state();
    register_locked(&mut s, undo)
}

fn register_locked(s: &mut State, undo: Undo) -> Token {
    s.next += 1;
    let id = s.next;
    s.items.push((id, undo));
    Token(id)
}

/// Remove `path` (a folder, recursively) if the run is interrupted while the token lives.
pub(crate) fn register_tree(path: PathBuf) -> Token {
    register(Undo::Tree(path))
}

/// Remove the file `path` if the run is interrupted while the token lives.
pub(crate) fn register_file(path: PathBuf) -> Token {
    register(Undo::File(path))
}

/// Remove the folder `path` if it is empty when the run is interrupted while the token lives.
pub(crate) fn register_empty_dir(path: PathBuf) -> Token {
    register(Undo::EmptyDir(path))
}

/// The signal number that asked this process to stop, if one has.
pub(crate) fn requested() -> Option<i32> {
    match REQUESTED.load(Ordering::SeqCst) {
        0 => None,
        s => Some(s),
    }
}

/// A critical section: while it is held, a signal's cleanup waits. When a signal arrived
/// during it, the thread that leaves it stops there ([`settle`]) and the cleanup ends the
/// process.
pub(crate) fn critical() -> Critical {
    Critical(Some(COMMIT.lock().unwrap_or_else(|e| e.into_inner())))
}

/// See [`critical`].
pub(crate) struct Critical(Option<MutexGuard<'static, ()>>);

impl Drop for Critical {
    fn drop(&mut self) {
        self.0 = None;
        settle();
    }
}

/// Once a signal has asked the process to stop, wait here for its cleanup to end the process:
/// the thread must not carry on (or exit with a status of its own) behind the cleanup's back.
/// Returns at once when no signal arrived.
pub fn settle() {
    while requested().is_some() {
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// Handle SIGINT, SIGTERM and SIGHUP in a thread of their own (signal-hook's handler only
/// wakes it: the cleanup runs there, in ordinary code). Call once, first thing in `main`.
#[cfg(unix)]
pub fn install() {
    use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM};
    // Without a handler thread the default actions stay: the run dies uncleaned rather than
    // ignoring the signal.
    let Ok(mut signals) = signal_hook::iterator::Signals::new([SIGINT, SIGTERM, SIGHUP]) else { return };
    let handle = signals.handle();
    let spawned = std::thread::Builder::new().name("blendsim-signals".into()).spawn(move || {
        if let Some(signal) = signals.forever().next() {
            stop(signal);
        }
    });
    if spawned.is_err() {
        // Unregisters the handlers: the default actions again.
        handle.close();
    }
}

#[cfg(not(unix))]
pub fn install() {}

#[cfg(unix)]
fn signal_name(signal: i32) -> &'static str {
    match signal {
        libc::SIGINT => "SIGINT",
        libc::SIGTERM => "SIGTERM",
        libc::SIGHUP => "SIGHUP",
        _ => "a signal",
    }
}

/// Undo everything registered and die by `signal`.
#[cfg(unix)]
fn stop(signal: i32) -> ! {
    REQUESTED.store(signal, Ordering::SeqCst);
    // Let a commit in progress reach a complete folder (it backs out before the point of no
    // return when it sees the request), then hold both locks until the process is gone: no new
    // file or child can be registered behind our back.
    let _commit = COMMIT.lock().unwrap_or_else(|e| e.into_inner());
    let mut s = state();
    undo_all(&mut s);
    eprintln!("blendsim: stopped by {}; unfinished files were removed", signal_name(signal));
    // The default action, unblocked and raised: the process ends with the status a shell
    // expects (for these three signals signal-hook aborts rather than return).
    let _ = signal_hook::low_level::emulate_default_handler(signal);
    std::process::exit(128 + signal)
}

/// Children first (so nothing writes into a folder being removed), then files and folders,
/// then the empty parents, last created first.
fn undo_all(s: &mut State) {
    for (_, undo) in &s.items {
        if let Undo::Child(pid) = undo {
            kill_group(*pid);
        }
    }
    for (_, undo) in &s.items {
        match undo {
            Undo::Tree(p) => {
                let _ = std::fs::remove_dir_all(p);
            }
            Undo::File(p) => {
                let _ = std::fs::remove_file(p);
            }
            _ => {}
        }
    }
    for (_, undo) in s.items.iter().rev() {
        if let Undo::EmptyDir(p) = undo {
            let _ = std::fs::remove_dir(p);
        }
    }
    s.items.clear();
}

/// SIGKILL the process group led by `pid` and reap the leader (our child).
#[cfg(unix)]
fn kill_group(pid: u32) {
    let Ok(pid) = libc::pid_t::try_from(pid) else { return };
    // SAFETY: plain syscalls on a pid we started; a reaped pid gives ESRCH/ECHILD, no harm.
    unsafe {
        libc::kill(-pid, libc::SIGKILL);
        let mut status = 0;
        libc::waitpid(pid, &mut status, 0);
    }
}

#[cfg(not(unix))]
fn kill_group(_pid: u32) {}

/// A child process started by [`spawn`]: registered while it runs, killed (with its process
/// group) when dropped before it finished.
#[derive(Debug)]
pub(crate) struct ChildGuard {
    child: Option<Child>,
    _token: Token,
}

impl ChildGuard {
    /// The running child (to take its pipes, wait for it or poll it).
    pub(crate) fn child(&mut self) -> &mut Child {
        self.child.as_mut().expect("the child is present until consumed")
    }

    /// The child's process id (0 once it has been consumed).
    pub(crate) fn id(&self) -> u32 {
        self.child.as_ref().map_or(0, Child::id)
    }

    /// Wait for the child and collect its output (as [`Child::wait_with_output`]).
    pub(crate) fn wait_with_output(mut self) -> std::io::Result<Output> {
        self.child.take().expect("the child is present until consumed").wait_with_output()
    }
}

impl Drop for ChildGuard {
    fn drop(&mut self) {
        if let Some(child) = &mut self.child {
            if matches!(child.try_wait(), Ok(None)) {
                kill_group(child.id());
                let _ = child.wait();
            }
        }
    }
}

/// Start `command` so that it dies with this process: in a process group of its own (killed as
/// a whole on SIGINT/SIGTERM, and out of reach of the terminal's Ctrl-C, which we handle), with
/// SIGKILL as its parent-death signal on Linux. Registered before a signal's cleanup can run.
pub(crate) fn spawn(command: &mut Command) -> std::io::Result<ChildGuard> {
    #[cfg(unix)]
    {
        use std::os::unix::process::CommandExt;
        command.process_group(0);
        #[cfg(target_os = "linux")]
        {
            // SAFETY: getpid is async-signal-safe; the closure below runs between fork and
            // exec and calls only prctl, getppid and _exit, all async-signal-safe.
            let parent = unsafe { libc::getpid() };
            unsafe {
                command.pre_exec(move || {
                    if libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGKILL as libc::c_ulong, 0, 0, 0) != 0 {
                        return Err(std::io::Error::last_os_error());
                    }
                    // The parent died before prctl took effect: nobody will wait for us.
                    if libc::getppid() != parent {
                        libc::_exit(1);
                    }
                    Ok(())
                });
            }
        }
    }
    let mut s = state();
    let child = command.spawn()?;
    let token = register_locked(&mut s, Undo::Child(child.id()));
    drop(s);
    Ok(ChildGuard { child: Some(child), _token: token })
}

/// The test hook: when `BLENDSIM_TEST_PAUSE` names `point` (a comma-separated list of point
/// names), say `blendsim: test hook: paused at POINT DETAIL` on stderr and wait until a signal
/// asks the process to stop, then carry on (the signal's cleanup, or the commit's own check of
/// [`requested`], decides what happens next). Lets tests interrupt a run at a known step.
/// Only in a build with `--features test-hooks` (`make test`); elsewhere it does nothing.
#[cfg(feature = "test-hooks")]
pub(crate) fn pause_point(point: &str, detail: &str) {
    let Some(list) = std::env::var_os("BLENDSIM_TEST_PAUSE") else { return };
    if !list.to_string_lossy().split(',').any(|p| p.trim() == point) {
        return;
    }
    eprintln!("blendsim: test hook: paused at {point}{}{detail}", if detail.is_empty() { "" } else { " " });
    while requested().is_none() {
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// The test hook compiled out: a build without `--features test-hooks` never pauses.
#[cfg(not(feature = "test-hooks"))]
#[inline(always)]
pub(crate) fn pause_point(_point: &str, _detail: &str) {}

/// Whether a process with this id exists (a zombie counts as gone).
pub(crate) fn process_alive(pid: u32) -> bool {
    #[cfg(target_os = "linux")]
    {
        match std::fs::read_to_string(format!("/proc/{pid}/stat")) {
            // The state follows the parenthesised command name.
            Ok(stat) => stat.rsplit_once(") ").is_some_and(|(_, rest)| !rest.starts_with(['Z', 'X'])),
            Err(_) => false,
        }
    }
    #[cfg(all(unix, not(target_os = "linux")))]
    {
        let Ok(pid) = libc::pid_t::try_from(pid) else { return false };
        // SAFETY: signal 0 only checks for existence.
        unsafe { libc::kill(pid, 0) == 0 || std::io::Error::last_os_error().raw_os_error() == Some(libc::EPERM) }
    }
    #[cfg(not(unix))]
    {
        let _ = pid;
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tokens_register_and_unregister() {
        let path = std::env::temp_dir().join(format!("blendsim-interrupt-{}", std::process::id()));
        let before = state().items.len();
        let token = register_tree(path.clone());
        assert!(state().items.iter().any(|(_, u)| matches!(u, Undo::Tree(p) if *p == path)));
        drop(token);
        assert_eq!(state().items.len(), before);
    }

    #[test]
    fn a_dropped_child_is_killed_and_a_finished_one_reaped() {
        let mut guard = spawn(Command::new("sleep").arg("30")).unwrap();
        let pid = guard.id();
        assert!(process_alive(pid));
        assert!(guard.child().try_wait().unwrap().is_none());
        drop(guard);
        assert!(!process_alive(pid), "the child died with its guard");
        let out = spawn(Command::new("sh").args(["-c", "echo hi"]).stdout(std::process::Stdio::piped())).unwrap().wait_with_output().unwrap();
        assert_eq!(out.stdout, b"hi\n");
        assert!(process_alive(std::process::id()));
    }
}
