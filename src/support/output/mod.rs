//! Writing outputs so that a failed or interrupted run leaves nothing behind and a finished one
//! replaces its output folder as a whole.
//!
//! - [`write_atomic`]: one file, written under a temporary name beside it and renamed.
//! - [`Staging`]: the files of one output folder `DIR`, written to a staging folder beside it
//!   and committed by swapping the two folders in one step.
//!
//! The contract of an output folder `DIR` (with parent `P` and name `NAME`):
//!
//! - **Atomic.** After a kill at any moment, `DIR` holds the complete previous bake or the
//!   complete new one, never a mix; a failed or interrupted run leaves it untouched. The new
//!   folder is built as `P/.NAME.blendsim-staging-PID-N` and swapped with `DIR` by
//!   `renameat2(RENAME_EXCHANGE)`. Where the kernel or file system cannot exchange, `DIR` is
//!   renamed to `P/.NAME.blendsim-old-PID-N` and the staging folder renamed into place: a kill
//!   between those two renames leaves no `DIR` until the next run into it restores the old one.
//! - **Ours and theirs.** `DIR/.blendsim-manifest.json` lists the files blendsim wrote, each
//!   with its group (`export:NAME` for an export's files, `report` for the report). A commit
//!   removes the files of its own groups that it did not write again (a re-bake with fewer
//!   formats leaves no stale file) and keeps everything else: other groups' files (`export`
//!   then `report` into one folder) and files that are not blendsim's, which are hard-linked
//!   into the new folder (folders re-created and their files linked), so they are never copied,
//!   moved or lost. A file of the same name as one the commit writes is replaced only if it is
//!   blendsim's (a regular file the manifest lists); anything else at such a name (a user's
//!   file, a folder, a link, a FIFO) is refused by [`Staging::claim`] and the run fails with
//!   nothing written, so a user's folder at `report.md` is never replaced. A run that
//!   writes a folder's whole content ([`Staging::replace_every_group`]: a bake) removes every
//!   file of the manifest it does not write again, whatever its group (a renamed scene's files
//!   too), so the folder holds one bake. [`Staging::commit_with_summary`] says what was
//!   removed and what was kept, for the command line to say it.
//! - **Locked.** `P/.NAME.blendsim-lock` is held with `flock` from [`Staging::open`] to the
//!   end of the commit (it is beside `DIR`, so it survives the swap). A second run into the
//!   same folder waits and says so on stderr, or fails at once with [`LockWait::Fail`]. The
//!   lock file is removed by its holder (waiters check they locked the file still at that path).
//! - **Clean.** Staging folders, temporaries and created parents are registered with
//!   [`crate::support::interrupt`], so SIGINT, SIGTERM and SIGHUP remove them. What a SIGKILL leaves is
//!   found by the next run into the same folder (by name, under the lock, so it cannot belong
//!   to a live run): an incomplete staging folder is deleted; a complete one, or an old folder
//!   after the swap, first gives back to `DIR` any file that is not blendsim's and that `DIR`
//!   lacks. Staging folders of older blendsim versions (`.blendsim-staging-PID-N`) are removed
//!   once their process is gone.
//!
//! `DIR` may not be the working folder or one of its parents (the swap would leave the shell
//! in a deleted folder), and its parent must be writable. A symlink to a folder is followed.
//!
//! The module by concern: `atomic` (one file), `lock` (the folder's lock), `staging` (the folder's
//! files and the commit), `manifest` (whose files are whose), `tree` (linking, rescuing and
//! removing folders), `exchange` (the swap of two folders).
//!
//! Test hooks (environment): `BLENDSIM_TEST_PAUSE` (see `interrupt::pause_point`)
//! stops at `staged` (the first file is staged), `commit-staged` (the new folder is complete,
//! before the swap), `commit-moved-aside` (fallback only: `DIR` renamed away) and
//! `commit-swapped` (after the swap, before the old folder is removed);
//! `BLENDSIM_TEST_NO_EXCHANGE=1` forces the two-rename fallback. Both only in a build with
//! `--features test-hooks` (`make test`).

mod atomic;
mod exchange;
mod lock;
mod manifest;
mod staging;
mod tree;

#[cfg(test)]
mod tests;

use std::sync::atomic::{AtomicU64, Ordering};

pub use atomic::write_atomic;
pub(crate) use atomic::write_atomic_with;
pub use lock::LockWait;
pub use manifest::MANIFEST;
pub use staging::{Committed, Staging};

static COUNTER: AtomicU64 = AtomicU64::new(0);

/// `PID-N`: unique among this process's temporaries and staging folders.
fn unique_suffix() -> String {
    format!("{}-{}", std::process::id(), COUNTER.fetch_add(1, Ordering::Relaxed))
}

/// The pid in a `PID-N` suffix.
fn pid_of(suffix: &str) -> Option<u32> {
    let (pid, n) = suffix.split_once('-')?;
    n.parse::<u64>().ok()?;
    pid.parse().ok()
}
