//! Private temporary folders for the external processes (TetGen, usd-core's and Alembic's
//! readers) and the glb read-back: named `blendsim-WHAT-PID-N`, removed when dropped, when the
//! run is interrupted, and (once their process is gone) by the next run that makes one, so a
//! killed run leaves nothing behind for long.
//!
//! Kept rather than `tempfile::TempDir`: its random, unowned names cannot be told dead by the
//! next run; the PID in ours and the flock are what make that cleanup safe.

use std::path::PathBuf;
use std::sync::atomic::{AtomicUsize, Ordering};

/// A fresh folder only this run uses (so no stray file of another run is picked up), removed
/// with everything in it when dropped or when the run is interrupted. It is flocked while in
/// use; creating one removes the work folders of the same kind of runs that were killed (their
/// process is gone and nobody holds their lock: the lock also protects a run in another PID
/// namespace sharing the temporary folder).
#[derive(Debug)]
pub(crate) struct WorkDir {
    /// The folder.
    pub(crate) path: PathBuf,
    _lock: Option<std::fs::File>,
    _token: crate::support::interrupt::Token,
}

impl WorkDir {
    /// A new `blendsim-{what}-PID-N` folder in the temporary folder, mode 0700.
    pub(crate) fn create(what: &str) -> std::io::Result<WorkDir> {
        static NEXT: AtomicUsize = AtomicUsize::new(0);
        let mut builder = std::fs::DirBuilder::new();
        #[cfg(unix)]
        std::os::unix::fs::DirBuilderExt::mode(&mut builder, 0o700);
        let prefix = format!("blendsim-{what}-");
        remove_dead_work_dirs(&prefix);
        loop {
            let name = format!("{prefix}{}-{}", std::process::id(), NEXT.fetch_add(1, Ordering::Relaxed));
            let path = std::env::temp_dir().join(name);
            // Created and registered with the signal cleanup waiting, so it never misses it.
            let _critical = crate::support::interrupt::critical();
            match builder.create(&path) {
                Ok(()) => {
                    let token = crate::support::interrupt::register_tree(path.clone());
                    let lock = std::fs::File::open(&path).ok().filter(|f| f.lock().is_ok());
                    return Ok(WorkDir { path, _lock: lock, _token: token });
                }
                // Left behind by an earlier process with the same id: take the next name.
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
                Err(e) => return Err(e),
            }
        }
    }
}

/// `{prefix}PID-N` folders of our user in the temporary folder whose process is gone and whose
/// lock nobody holds.
fn remove_dead_work_dirs(prefix: &str) {
    let Ok(entries) = std::fs::read_dir(std::env::temp_dir()) else { return };
    for entry in entries.flatten() {
        let name = entry.file_name();
        let pid = name.to_str().and_then(|n| n.strip_prefix(prefix)).and_then(|r| r.split_once('-'));
        let Some(pid) = pid.and_then(|(p, _)| p.parse::<u32>().ok()) else { continue };
        #[cfg(unix)]
        {
            // Only our own user's folders (a shared /tmp holds other users' too).
            use std::os::unix::fs::MetadataExt;
            // SAFETY: getuid cannot fail and touches no memory.
            let uid = unsafe { libc::getuid() };
            let mine = entry.metadata().is_ok_and(|m| m.uid() == uid);
            if !mine {
                continue;
            }
        }
        let unlocked = || std::fs::File::open(entry.path()).is_ok_and(|f| f.try_lock().is_ok());
        if pid != std::process::id() && !crate::support::interrupt::process_alive(pid) && unlocked() {
            let _ = std::fs::remove_dir_all(entry.path());
        }
    }
}

impl Drop for WorkDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.path);
    }
}
