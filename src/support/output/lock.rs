//! The lock of an output folder, beside it so that it survives the swap.

use std::fs::{File, OpenOptions};
use std::io::Write as _;
use std::path::{Path, PathBuf};

use crate::support::error::{Error, Result};
use crate::support::interrupt::{self, Token};

/// What [`Staging::open`](super::Staging::open) does when another run holds the output folder.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LockWait {
    /// Wait for it, saying so on stderr.
    Wait,
    /// Fail at once with an error naming the folder and the other run's pid.
    Fail,
}

/// The lock of one output folder: `P/.NAME.blendsim-lock`, flocked, removed by its holder.
#[derive(Debug)]
pub(super) struct FolderLock {
    path: PathBuf,
    file: File,
    _token: Token,
}

impl FolderLock {
    pub(super) fn acquire(parent: &Path, name: &str, target: &Path, wait: LockWait) -> Result<FolderLock> {
        let path = parent.join(format!(".{name}.blendsim-lock"));
        let mut announced = false;
        for _ in 0..1000 {
            // A signal between creating the lock file and registering it would leave the file
            // behind: the cleanup waits for this section (but not for a wait on another run).
            let mut critical = Some(interrupt::critical());
            let file = match OpenOptions::new().read(true).write(true).create(true).truncate(false).open(&path) {
                Ok(f) => f,
                // A run that failed removed the parent it had created: make it again.
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                    std::fs::create_dir_all(parent).map_err(|e| Error::io(parent, &e, "create the output folder's parent"))?;
                    continue;
                }
                Err(e) => return Err(Error::io(&path, &e, "create the output folder's lock file")),
            };
            match file.try_lock() {
                Ok(()) => {}
                Err(std::fs::TryLockError::WouldBlock) => {
                    // The file is the holder's (it removes it): waiting stays interruptible.
                    critical = None;
                    let holder = std::fs::read_to_string(&path).ok().and_then(|s| s.trim().parse::<u32>().ok());
                    let who = holder.map_or("another blendsim".to_string(), |p| format!("another blendsim (pid {p})"));
                    if wait == LockWait::Fail {
                        return Err(Error::in_file(
                            target,
                            format!("{who} is writing into this output folder"),
                            "wait for it to finish and run again (without --no-wait, blendsim waits by itself), or choose another --out",
                        ));
                    }
                    if !announced {
                        eprintln!(
                            "blendsim: waiting for {who} to finish writing {}",
                            crate::support::error::printable(&target.display().to_string())
                        );
                        announced = true;
                    }
                    file.lock().map_err(|e| Error::io(&path, &e, "lock the output folder"))?;
                }
                Err(std::fs::TryLockError::Error(e)) => return Err(Error::io(&path, &e, "lock the output folder")),
            }
            // The holder before us may have removed the file we locked: lock the one there now.
            if !same_file(&file, &path) {
                continue;
            }
            let token = interrupt::register_file(path.clone());
            drop(critical);
            let mut f = &file;
            let _ = f.set_len(0).and_then(|_| writeln!(f, "{}", std::process::id()));
            return Ok(FolderLock { path, file, _token: token });
        }
        Err(Error::in_file(&path, "could not be locked: it keeps being removed", "check what else writes into the output folder's parent"))
    }
}

impl Drop for FolderLock {
    fn drop(&mut self) {
        // Removed while still held, so a waiter that locks the old file sees it is gone.
        let _ = std::fs::remove_file(&self.path);
        let _ = self.file.unlock();
    }
}

#[cfg(unix)]
fn same_file(file: &File, path: &Path) -> bool {
    use std::os::unix::fs::MetadataExt;
    match (file.metadata(), std::fs::metadata(path)) {
        (Ok(a), Ok(b)) => a.dev() == b.dev() && a.ino() == b.ino(),
        _ => false,
    }
}

#[cfg(not(unix))]
fn same_file(_file: &File, path: &Path) -> bool {
    path.exists()
}
