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
//! Test hooks (environment): `BLENDSIM_TEST_PAUSE` (see `interrupt::pause_point`)
//! stops at `staged` (the first file is staged), `commit-staged` (the new folder is complete,
//! before the swap), `commit-moved-aside` (fallback only: `DIR` renamed away) and
//! `commit-swapped` (after the swap, before the old folder is removed);
//! `BLENDSIM_TEST_NO_EXCHANGE=1` forces the two-rename fallback. Both only in a build with
//! `--features test-hooks` (`make test`).

use std::collections::{BTreeMap, BTreeSet};
use std::fs::{File, OpenOptions};
use std::io::Write as _;
use std::path::{Component, Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use crate::support::error::{Error, Result};
use crate::support::interrupt::{self, Token};

static COUNTER: AtomicU64 = AtomicU64::new(0);

fn unique_suffix() -> String {
    format!("{}-{}", std::process::id(), COUNTER.fetch_add(1, Ordering::Relaxed))
}

/// The manifest of the files blendsim wrote into an output folder.
pub const MANIFEST: &str = ".blendsim-manifest.json";
/// Present in a staging folder until it is complete.
const MARKER: &str = ".blendsim-incomplete";
/// The group of files staged before any [`Staging::set_group`].
const DEFAULT_GROUP: &str = "files";

/// Write `bytes` to `path` atomically: readers see the old file or the whole new one.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    write_atomic_with(path, |tmp| std::fs::write(tmp, bytes).map_err(|e| Error::io(tmp, &e, "write a temporary output file")))
}

/// Write `path` atomically from a closure that fills a temporary file beside it (streamed, or
/// by an external tool), then rename it into place; on error, or on SIGINT, SIGTERM or SIGHUP,
/// the temporary is removed. The temporary keeps `path`'s extension (`.STEM.tmp-PID-N.EXT`):
/// tools that pick a format by extension write the right one. It is created and flocked before
/// `fill` runs and stays locked until it is renamed, so a run in another PID namespace never
/// takes it for a leftover; temporaries of dead processes are swept first. `path` must not be
/// a device, FIFO or folder (the rename would replace it: `-o /dev/null` as root).
pub(crate) fn write_atomic_with(path: &Path, fill: impl FnOnce(&Path) -> Result<()>) -> Result<()> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    if !dir.is_dir() {
        return Err(Error::in_file(dir, "output folder does not exist", "create the folder first, or choose another output path"));
    }
    let name = path.file_name().ok_or_else(|| Error::in_file(path, "is not a file path", "give a file name"))?.to_string_lossy();
    if std::fs::metadata(path).is_ok_and(|m| !m.is_file()) {
        return Err(Error::in_file(
            path,
            "exists and is not a regular file, so it cannot be replaced by the output",
            "give the path of a file to write",
        ));
    }
    let (prefix, suffix) = match name.rsplit_once('.') {
        Some((stem, ext)) if !stem.is_empty() => (format!(".{stem}.tmp-"), format!(".{ext}")),
        _ => (format!(".{name}.tmp-"), String::new()),
    };
    remove_dead_temporaries(dir, &prefix, &suffix);
    let tmp = dir.join(format!("{prefix}{}{suffix}", unique_suffix()));
    let token = interrupt::register_file(tmp.clone());
    let result = File::create(&tmp).map_err(|e| Error::io(&tmp, &e, "create a temporary output file")).and_then(|lock| {
        let _ = lock.lock();
        let done = fill(&tmp).and_then(|_| std::fs::rename(&tmp, path).map_err(|e| Error::io(path, &e, "move the finished file into place")));
        drop(lock);
        done
    });
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    drop(token);
    result
}

/// Temporaries `PREFIX{pid}-{n}SUFFIX` in `dir` whose process is gone (killed mid-write) and
/// whose lock nobody holds.
fn remove_dead_temporaries(dir: &Path, prefix: &str, suffix: &str) {
    let Ok(entries) = std::fs::read_dir(dir) else { return };
    for entry in entries.flatten() {
        let name = entry.file_name();
        let Some(pid) = name.to_str().and_then(|n| n.strip_prefix(prefix)).and_then(|n| n.strip_suffix(suffix)).and_then(pid_of) else {
            continue;
        };
        let unlocked = || File::open(entry.path()).is_ok_and(|f| f.try_lock().is_ok());
        if pid != std::process::id() && !interrupt::process_alive(pid) && unlocked() {
            let _ = std::fs::remove_file(entry.path());
        }
    }
}

/// The pid in a `PID-N` suffix.
fn pid_of(suffix: &str) -> Option<u32> {
    let (pid, n) = suffix.split_once('-')?;
    n.parse::<u64>().ok()?;
    pid.parse().ok()
}

/// What [`Staging::open`] does when another run holds the output folder.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LockWait {
    /// Wait for it, saying so on stderr.
    Wait,
    /// Fail at once with an error naming the folder and the other run's pid.
    Fail,
}

/// The lock of one output folder: `P/.NAME.blendsim-lock`, flocked, removed by its holder.
#[derive(Debug)]
struct FolderLock {
    path: PathBuf,
    file: File,
    _token: Token,
}

impl FolderLock {
    fn acquire(parent: &Path, name: &str, target: &Path, wait: LockWait) -> Result<FolderLock> {
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

/// What a commit did to the entries the output folder held before it (for messages).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Committed {
    /// Files an earlier run wrote (listed in the manifest) that this commit removed because it
    /// replaces their group and did not write them again, sorted.
    pub removed: Vec<String>,
    /// Top-level entries that blendsim did not write (not in the manifest), kept through the
    /// commit, sorted. Entries the commit wrote under the same name were replaced instead.
    pub kept: Vec<String>,
    /// The files this commit wrote (names inside the folder), sorted.
    pub written: Vec<String>,
}

impl Committed {
    /// One line for each list that is not empty (cargo-like: say what was replaced), naming the
    /// first few entries; `folder` as the user named it, `run` what wrote it (`bake`).
    pub fn messages(&self, folder: &Path, run: &str) -> Vec<String> {
        const SHOWN: usize = 5;
        let folder = crate::support::error::printable(&folder.display().to_string());
        let names = |list: &[String]| {
            let mut text = list.iter().take(SHOWN).map(|n| crate::support::error::printable(n)).collect::<Vec<_>>().join(", ");
            if list.len() > SHOWN {
                text.push_str(&format!(" and {} more", list.len() - SHOWN));
            }
            text
        };
        let count = |n: usize, one: &str, many: &str| if n == 1 { format!("1 {one}") } else { format!("{n} {many}") };
        let mut lines = Vec::new();
        if !self.removed.is_empty() {
            lines.push(format!(
                "removed from {folder} {} of an earlier run that this {run} did not write again: {}",
                count(self.removed.len(), "file", "files"),
                names(&self.removed)
            ));
        }
        if !self.kept.is_empty() {
            lines.push(format!("kept in {folder} {} that blendsim did not write: {}", count(self.kept.len(), "entry", "entries"), names(&self.kept)));
        }
        lines
    }
}

/// Files for one output folder, kept out of sight until the whole run has succeeded.
#[derive(Debug)]
pub struct Staging {
    /// The folder as the user named it (for messages).
    target: PathBuf,
    /// The folder, absolute, symlinks resolved.
    folder: PathBuf,
    parent: PathBuf,
    /// The folder's own name.
    name: String,
    dir: PathBuf,
    /// Staged files and their groups.
    files: Vec<(String, String)>,
    group: String,
    /// The commit replaces every group of the manifest, not only those it staged.
    every_group: bool,
    committed: bool,
    /// Parents of `folder` this run created, outermost first (removed again on failure).
    created: Vec<(PathBuf, Token)>,
    lock: Option<FolderLock>,
    dir_token: Option<Token>,
}

impl Staging {
    /// [`Staging::open`], waiting for another run into the same folder.
    pub fn new(target: &Path) -> Result<Staging> {
        Staging::open(target, LockWait::Wait)
    }

    /// Start staging files for `target`, which need not exist yet (nor its parents: they are
    /// created now and removed again if the run fails). Locks the folder, cleans what killed
    /// runs left beside it, and creates the staging folder.
    pub fn open(target: &Path, wait: LockWait) -> Result<Staging> {
        let folder = resolve(target)?;
        let (Some(parent), Some(name)) = (folder.parent(), folder.file_name().and_then(|n| n.to_str())) else {
            return Err(Error::in_file(
                target,
                "cannot be an output folder (it has no parent folder or no UTF-8 name)",
                "choose a folder such as build/NAME",
            ));
        };
        let (parent, name) = (parent.to_path_buf(), name.to_string());
        if let Ok(cwd) = std::env::current_dir().and_then(|d| d.canonicalize()) {
            if cwd.starts_with(&folder) {
                return Err(Error::in_file(
                    target,
                    "is the working folder or one of its parents; blendsim replaces its output folder as a whole when it commits",
                    "write into a folder of its own, e.g. --out build/NAME",
                ));
            }
        }
        let mut staging = Staging {
            target: target.to_path_buf(),
            folder,
            parent,
            name,
            dir: PathBuf::new(),
            files: Vec::new(),
            group: DEFAULT_GROUP.into(),
            every_group: false,
            committed: false,
            created: Vec::new(),
            lock: None,
            dir_token: None,
        };
        staging.create_parents()?;
        staging.lock = Some(FolderLock::acquire(&staging.parent, &staging.name, target, wait)?);
        staging.recover()?;
        let mut builder = std::fs::DirBuilder::new();
        loop {
            let dir = staging.parent.join(format!(".{}.blendsim-staging-{}", staging.name, unique_suffix()));
            // Created and registered with the signal cleanup waiting, so it never misses it.
            let _critical = interrupt::critical();
            match builder.create(&dir) {
                Ok(()) => {
                    staging.dir_token = Some(interrupt::register_tree(dir.clone()));
                    staging.dir = dir;
                    break;
                }
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
                Err(e) => return Err(Error::io(&staging.parent, &e, "create a staging folder beside the output folder")),
            }
        }
        builder.recursive(false);
        std::fs::write(staging.dir.join(MARKER), b"").map_err(|e| Error::io(&staging.dir, &e, "create a staging folder beside the output folder"))?;
        Ok(staging)
    }

    fn create_parents(&mut self) -> Result<()> {
        let missing: Vec<PathBuf> = self.parent.ancestors().take_while(|p| !p.is_dir()).map(Path::to_path_buf).collect();
        for dir in missing.into_iter().rev() {
            let _critical = interrupt::critical();
            match std::fs::create_dir(&dir) {
                Ok(()) => {
                    let token = interrupt::register_empty_dir(dir.clone());
                    self.created.push((dir, token));
                }
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists && dir.is_dir() => {}
                Err(e) => return Err(Error::io(&dir, &e, "create the output folder's parent")),
            }
        }
        Ok(())
    }

    /// Under the lock: put back an old folder a killed fallback commit had moved aside, and
    /// remove (after giving back foreign files) every staging or old folder of this output.
    fn recover(&self) -> Result<()> {
        let staging_prefix = format!(".{}.blendsim-staging-", self.name);
        let old_prefix = format!(".{}.blendsim-old-", self.name);
        let mut stale: Vec<(PathBuf, bool)> = Vec::new();
        if let Ok(entries) = std::fs::read_dir(&self.parent) {
            for entry in entries.flatten() {
                let file_name = entry.file_name();
                let Some(n) = file_name.to_str() else { continue };
                let old = n.strip_prefix(&old_prefix).and_then(pid_of).is_some();
                if old || n.strip_prefix(&staging_prefix).and_then(pid_of).is_some() {
                    stale.push((entry.path(), old));
                }
            }
        }
        stale.sort();
        if !self.folder.exists() {
            if let Some(i) = stale.iter().position(|(_, old)| *old) {
                let (old, _) = stale.remove(i);
                std::fs::rename(&old, &self.folder)
                    .map_err(|e| Error::io(&old, &e, "restore the previous bake that an interrupted commit had moved aside"))?;
            }
        }
        for (dir, _) in &stale {
            remove_stale(dir, &self.folder)?;
        }
        // Older blendsim versions staged inside the output folder.
        if let Ok(entries) = std::fs::read_dir(&self.folder) {
            for entry in entries.flatten() {
                if is_dead_legacy_staging(&entry.file_name().to_string_lossy()) {
                    let _ = std::fs::remove_dir_all(entry.path());
                }
            }
        }
        Ok(())
    }

    /// Files staged from now on belong to `group` (e.g. `export:NAME`, `report`): the commit
    /// removes the files of the groups it staged that a previous commit wrote and it did not.
    pub fn set_group(&mut self, group: &str) {
        self.group = group.to_string();
    }

    /// This run writes the folder's whole content (a bake): the commit removes every file an
    /// earlier run wrote (the manifest's) that this one does not write, whatever its group,
    /// not only those of the groups it staged. Files that are not blendsim's are kept.
    pub fn replace_every_group(&mut self) {
        self.every_group = true;
    }

    /// Where a staged file lives until commit (for external tools that write it themselves).
    /// Never outside the staging folder: a name that is not a plain file name maps to a
    /// harmless one there, and [`Staging::write`] and [`Staging::commit`] refuse it.
    pub fn path(&self, name: &str) -> PathBuf {
        self.dir.join(contained(name))
    }

    /// The final path of a file once committed.
    pub(crate) fn final_path(&self, name: &str) -> PathBuf {
        self.target.join(contained(name))
    }

    /// Write a file into the staging folder.
    pub fn write(&mut self, name: &str, bytes: &[u8]) -> Result<()> {
        self.check_name(name)?;
        let p = self.path(name);
        // A signal's cleanup removes the staging folder while this thread runs on: a file
        // created after its listing would make that removal fail and stay behind. The write
        // is a critical section, so the cleanup waits for it and no write starts after it.
        let written = {
            let _critical = interrupt::critical();
            std::fs::write(&p, bytes)
        };
        written.map_err(|e| Error::io(self.final_path(name), &e, "write an output file"))?;
        self.record(name);
        Ok(())
    }

    /// Write a file into the staging folder from `fill`, through a buffer: a large file made
    /// in pieces is never held whole.
    pub fn write_with(&mut self, name: &str, fill: impl FnOnce(&mut dyn std::io::Write) -> std::io::Result<()>) -> Result<()> {
        let created = self.create(name)?;
        let fail = |e: std::io::Error| Error::io(self.final_path(name), &e, "write an output file");
        let mut w = std::io::BufWriter::new(created);
        fill(&mut w).and_then(|_| w.flush()).map_err(fail)?;
        drop(w);
        self.record(name);
        Ok(())
    }

    /// Create (or truncate) a file in the staging folder, open for writing and reading back,
    /// from any thread: the writers of one export fill their files in parallel, and the caller
    /// [`Staging::record`]s each once it is complete.
    pub fn create(&self, name: &str) -> Result<File> {
        self.check_name(name)?;
        let p = self.path(name);
        // Created in a critical section, as `write`'s file is (a signal's cleanup lists the
        // staging folder after it, or removed the folder before and the creation fails);
        // what is written after a cleanup goes to a file already unlinked.
        let created = {
            let _critical = interrupt::critical();
            File::options().read(true).write(true).create(true).truncate(true).open(&p)
        };
        created.map_err(|e| Error::io(self.final_path(name), &e, "write an output file"))
    }

    /// Record a file that an external tool wrote at [`Staging::path`].
    pub fn record(&mut self, name: &str) {
        match self.files.iter_mut().find(|(f, _)| f == name) {
            Some(entry) => entry.1 = self.group.clone(),
            None => {
                self.files.push((name.to_string(), self.group.clone()));
                if self.files.len() == 1 {
                    interrupt::pause_point("staged", name);
                }
            }
        }
    }

    /// Size of a staged file.
    pub fn size(&self, name: &str) -> Result<u64> {
        let p = self.path(name);
        std::fs::metadata(&p).map(|m| m.len()).map_err(|e| Error::io(self.final_path(name), &e, "measure an output file"))
    }

    fn check_name(&self, name: &str) -> Result<()> {
        if contained(name) != name || name == MANIFEST || name == MARKER {
            return Err(Error::in_file(
                &self.target,
                format!("refuses the output file name {}: it is not a plain file name", crate::support::error::quoted(name)),
                "give the scene a `name` of letters, digits, '-' and '_'",
            ));
        }
        self.claim(&[name])
    }

    /// Refuse output names at which the folder holds something blendsim did not write: an
    /// entry its manifest does not list, or one that is no longer a regular file (a folder
    /// the user put at `report.md`). The commit would replace it, a folder with all it holds.
    /// Checked when a file is staged and again at commit; a run that knows its names calls it
    /// first, so the refusal comes before any work.
    pub fn claim<S: AsRef<str>>(&self, names: &[S]) -> Result<()> {
        let mut manifest = None;
        for name in names.iter().map(AsRef::as_ref) {
            let Ok(meta) = std::fs::symlink_metadata(self.folder.join(contained(name))) else { continue };
            let ours = meta.is_file() && manifest.get_or_insert_with(|| read_manifest(&self.folder)).contains_key(name);
            if ours {
                continue;
            }
            let what = match meta.file_type() {
                t if t.is_symlink() => "a link",
                t if t.is_file() => "a file",
                _ => crate::support::input::kind(&meta),
            };
            return Err(Error::in_file(
                self.final_path(name),
                format!("is {what} that blendsim did not write, at the name of a file this run writes; it is left as it is and nothing is written"),
                "move or rename it, or choose another --out",
            ));
        }
        Ok(())
    }

    /// Replace the output folder by the staged files (plus the files kept from it) in one step.
    pub fn commit(self) -> Result<()> {
        self.commit_with_summary().map(drop)
    }

    /// [`Staging::commit`], returning what it removed and kept of the folder's earlier files.
    pub fn commit_with_summary(mut self) -> Result<Committed> {
        for (name, _) in &self.files {
            self.check_name(name)?;
        }
        let critical = interrupt::critical();
        let result = self.swap_in();
        drop(critical);
        result
    }

    fn swap_in(&mut self) -> Result<Committed> {
        let folder_exists = self.folder.is_dir();
        let old_manifest = if folder_exists { read_manifest(&self.folder) } else { BTreeMap::new() };
        let mine: BTreeMap<&str, &str> = self.files.iter().map(|(n, g)| (n.as_str(), g.as_str())).collect();
        let my_groups: BTreeSet<&str> = mine.values().copied().collect();
        let every_group = self.every_group;
        let replaced = |name: &str| mine.contains_key(name) || old_manifest.get(name).is_some_and(|g| every_group || my_groups.contains(g.as_str()));
        let removed: Vec<String> = old_manifest
            .keys()
            .filter(|n| replaced(n) && !mine.contains_key(n.as_str()) && self.folder.join(n).symlink_metadata().is_ok())
            .cloned()
            .collect();
        let mut manifest: BTreeMap<String, String> = old_manifest
            .iter()
            .filter(|(n, _)| !replaced(n) && self.folder.join(n).symlink_metadata().is_ok())
            .map(|(n, g)| (n.clone(), g.clone()))
            .collect();
        manifest.extend(mine.iter().map(|(n, g)| (n.to_string(), g.to_string())));
        let manifest_path = self.dir.join(MANIFEST);
        std::fs::write(&manifest_path, manifest_json(&manifest)).map_err(|e| Error::io(&manifest_path, &e, "write the output manifest"))?;

        // Everything else in the folder comes along, by hard links.
        let mut kept = Vec::new();
        if folder_exists {
            let entries = std::fs::read_dir(&self.folder).map_err(|e| Error::io(&self.target, &e, "list the output folder"))?;
            for entry in entries {
                let entry = entry.map_err(|e| Error::io(&self.target, &e, "list the output folder"))?;
                let file_name = entry.file_name();
                let n = file_name.to_string_lossy();
                if n == MANIFEST || replaced(&n) || is_dead_legacy_staging(&n) {
                    continue;
                }
                link_tree(&entry.path(), &self.dir.join(&file_name))?;
                if !old_manifest.contains_key(n.as_ref()) {
                    kept.push(n.into_owned());
                }
            }
        }
        let names: Vec<&str> = mine.keys().copied().chain([MANIFEST]).collect();
        let synced = concurrently(&names, |name| File::open(self.dir.join(name)).and_then(|f| f.sync_all()));
        for (name, done) in names.iter().zip(synced) {
            done.map_err(|e| Error::io(self.final_path(name), &e, "flush an output file to disk"))?;
        }
        if folder_exists {
            if let Ok(m) = std::fs::metadata(&self.folder) {
                let _ = std::fs::set_permissions(&self.dir, m.permissions());
            }
        }
        interrupt::pause_point("commit-staged", "");
        if let Some(signal) = interrupt::requested() {
            return Err(Error::in_file(
                &self.target,
                format!("the run was stopped by signal {signal} before its outputs were committed"),
                "run it again",
            ));
        }
        std::fs::remove_file(self.dir.join(MARKER)).map_err(|e| Error::io(&self.dir, &e, "finish the staging folder"))?;
        sync_dir(&self.dir);

        // The point of no return.
        let old = if !folder_exists {
            std::fs::rename(&self.dir, &self.folder).map_err(|e| Error::io(&self.target, &e, "move the finished outputs into place"))?;
            None
        } else if let Some(old) = self.exchange()? {
            Some(old)
        } else {
            Some(self.dir.clone())
        };
        self.committed = true;
        sync_dir(&self.parent);
        interrupt::pause_point("commit-swapped", "");
        if let Some(old) = old {
            let ours: BTreeSet<String> = old_manifest.into_keys().collect();
            match rescue(&old, &self.folder, &ours) {
                Ok(()) => {
                    let _ = remove_folder(&old);
                }
                Err(e) => {
                    let old = crate::support::error::printable(&old.display().to_string());
                    eprintln!("blendsim: warning: {e}; the previous bake stays in {old} until the next run")
                }
            }
        }
        kept.sort();
        let mut written: Vec<String> = self.files.iter().map(|(n, _)| n.clone()).collect();
        written.sort();
        written.dedup();
        Ok(Committed { removed, kept, written })
    }

    /// Swap the staging folder with the output folder. `Ok(None)`: exchanged in one step (the
    /// old folder is now at the staging path); `Ok(Some(old))`: the two-rename fallback, the
    /// old folder moved to `old`.
    fn exchange(&self) -> Result<Option<PathBuf>> {
        let forced_fallback = cfg!(feature = "test-hooks") && std::env::var_os("BLENDSIM_TEST_NO_EXCHANGE").is_some_and(|v| v == "1");
        if !forced_fallback {
            match exchange_dirs(&self.dir, &self.folder) {
                Ok(()) => return Ok(None),
                Err(e) if exchange_unsupported(&e) => {}
                Err(e) if e.kind() == std::io::ErrorKind::CrossesDevices || e.kind() == std::io::ErrorKind::ResourceBusy => {
                    return Err(Error::in_file(
                        &self.target,
                        format!("cannot be replaced as a whole ({e}): it is a mount point or on another file system than its parent"),
                        "bake into a folder inside it, e.g. --out DIR/NAME",
                    ))
                }
                Err(e) => return Err(Error::io(&self.target, &e, "swap the finished outputs into place")),
            }
        }
        let old = self.parent.join(format!(".{}.blendsim-old-{}", self.name, unique_suffix()));
        std::fs::rename(&self.folder, &old).map_err(|e| Error::io(&self.target, &e, "move the previous outputs aside"))?;
        interrupt::pause_point("commit-moved-aside", "");
        if let Err(e) = std::fs::rename(&self.dir, &self.folder) {
            let _ = std::fs::rename(&old, &self.folder);
            return Err(Error::io(&self.target, &e, "move the finished outputs into place"));
        }
        Ok(Some(old))
    }
}

impl Drop for Staging {
    fn drop(&mut self) {
        if !self.committed && !self.dir.as_os_str().is_empty() {
            let _ = std::fs::remove_dir_all(&self.dir);
        }
        self.dir_token = None;
        self.lock = None;
        for (dir, _) in self.created.iter().rev() {
            if !self.committed {
                let _ = std::fs::remove_dir(dir);
            }
        }
        self.created.clear();
    }
}

/// The output folder as an absolute path with symlinks resolved; where it does not exist yet,
/// its nearest existing ancestor resolved and the rest appended.
fn resolve(target: &Path) -> Result<PathBuf> {
    let given = if target.as_os_str().is_empty() { Path::new(".") } else { target };
    if let Ok(meta) = std::fs::symlink_metadata(given) {
        let canonical = given.canonicalize().map_err(|e| Error::io(target, &e, "resolve the output folder"))?;
        if !canonical.is_dir() {
            let what = if meta.file_type().is_symlink() { "is a link to something that is not a folder" } else { "exists and is not a folder" };
            return Err(Error::in_file(target, what, "choose a folder for --out"));
        }
        return Ok(canonical);
    }
    let mut anchor = given.to_path_buf();
    let mut rest = Vec::new();
    while std::fs::symlink_metadata(&anchor).is_err() {
        match (anchor.file_name(), anchor.parent()) {
            (Some(n), Some(p)) => {
                rest.push(n.to_os_string());
                anchor = if p.as_os_str().is_empty() { PathBuf::from(".") } else { p.to_path_buf() };
            }
            _ => return Err(Error::in_file(target, "cannot be resolved to a folder", "give a plain folder path for --out")),
        }
    }
    let mut folder = anchor.canonicalize().map_err(|e| Error::io(&anchor, &e, "resolve the output folder"))?;
    if !folder.is_dir() {
        return Err(Error::in_file(&anchor, "is not a folder, so it cannot hold the output folder", "choose another --out"));
    }
    for n in rest.iter().rev() {
        folder.push(n);
    }
    Ok(folder)
}

/// `name` if it is one plain path component; otherwise a harmless stand-in.
fn contained(name: &str) -> String {
    let plain = !name.is_empty()
        && !name.contains(['/', '\\', '\0'])
        && matches!(Path::new(name).components().collect::<Vec<_>>()[..], [Component::Normal(_)]);
    if plain {
        name.to_string()
    } else {
        ".blendsim-refused-name".to_string()
    }
}

/// `.blendsim-staging-PID-N` of a blendsim before output locking, whose process is gone.
fn is_dead_legacy_staging(name: &str) -> bool {
    name.strip_prefix(".blendsim-staging-").and_then(pid_of).is_some_and(|pid| !interrupt::process_alive(pid))
}

fn read_manifest(folder: &Path) -> BTreeMap<String, String> {
    #[derive(serde::Deserialize)]
    struct Manifest {
        files: BTreeMap<String, String>,
    }
    std::fs::read(folder.join(MANIFEST))
        .ok()
        .and_then(|bytes| serde_json::from_slice::<Manifest>(&bytes).ok())
        .map(|m| m.files.into_iter().filter(|(n, _)| contained(n) == *n && n != MANIFEST && n != MARKER).collect())
        .unwrap_or_default()
}

fn manifest_json(files: &BTreeMap<String, String>) -> Vec<u8> {
    let mut bytes = serde_json::to_vec_pretty(&serde_json::json!({ "blendsim": 1, "files": files })).expect("a map of strings serializes");
    bytes.push(b'\n');
    bytes
}

/// Hard-link `from` to `to`; a folder is re-created and its contents linked.
fn link_tree(from: &Path, to: &Path) -> Result<()> {
    let fail = |e: std::io::Error| Error::io(from, &e, "keep this file (not blendsim's) in the output folder through the commit, by a hard link");
    let meta = std::fs::symlink_metadata(from).map_err(fail)?;
    if !meta.is_dir() {
        return std::fs::hard_link(from, to).map_err(fail);
    }
    std::fs::create_dir(to).map_err(fail)?;
    for entry in std::fs::read_dir(from).map_err(fail)? {
        let entry = entry.map_err(fail)?;
        link_tree(&entry.path(), &to.join(entry.file_name()))?;
    }
    let _ = std::fs::set_permissions(to, meta.permissions());
    Ok(())
}

/// Move into `to` every entry of `from` that `to` lacks, except blendsim's own files `ours`
/// (at the top level only); folders present in both are merged the same way.
fn rescue(from: &Path, to: &Path, ours: &BTreeSet<String>) -> Result<()> {
    let fail = |p: &Path, e: std::io::Error| Error::io(p, &e, "give a file that is not blendsim's back to the output folder");
    for entry in std::fs::read_dir(from).map_err(|e| fail(from, e))? {
        let entry = entry.map_err(|e| fail(from, e))?;
        let file_name = entry.file_name();
        let n = file_name.to_string_lossy();
        if ours.contains(n.as_ref()) || n == MANIFEST || n == MARKER {
            continue;
        }
        let dest = to.join(&file_name);
        match std::fs::symlink_metadata(&dest) {
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => std::fs::rename(entry.path(), &dest).map_err(|e| fail(&dest, e))?,
            Ok(m) if m.is_dir() && entry.file_type().is_ok_and(|t| t.is_dir()) => rescue(&entry.path(), &dest, &BTreeSet::new())?,
            _ => {}
        }
    }
    Ok(())
}

/// A staging or old folder a killed run left: an incomplete staging folder is all ours;
/// otherwise give foreign files back first.
fn remove_stale(dir: &Path, folder: &Path) -> Result<()> {
    if !dir.join(MARKER).exists() && folder.is_dir() {
        let ours: BTreeSet<String> = read_manifest(dir).into_keys().collect();
        rescue(dir, folder, &ours)?;
    }
    std::fs::remove_dir_all(dir).map_err(|e| Error::io(dir, &e, "remove what an interrupted run left beside the output folder"))
}

/// `f` of every item, on up to [`IO_THREADS`] threads at once; the results in the items'
/// order. For blocking file-system calls (`fsync`, `unlink`): concurrent ones share the
/// journal's commits, where one after the other each waits for its own (ext4, the demo's nine
/// files: fsyncs 7-15 ms instead of 13-50 ms, unlinks 4-13 ms instead of 28-40 ms).
fn concurrently<T: Sync, R: Send>(items: &[T], f: impl Fn(&T) -> R + Sync) -> Vec<R> {
    let threads = items.len().min(IO_THREADS);
    if threads <= 1 {
        return items.iter().map(f).collect();
    }
    let mut out: Vec<Option<R>> = std::iter::repeat_with(|| None).take(items.len()).collect();
    std::thread::scope(|scope| {
        let f = &f;
        let workers: Vec<_> = (0..threads)
            .map(|t| scope.spawn(move || items.iter().enumerate().skip(t).step_by(threads).map(|(i, x)| (i, f(x))).collect::<Vec<_>>()))
            .collect();
        for worker in workers {
            for (i, r) in worker.join().unwrap_or_else(|panic| std::panic::resume_unwind(panic)) {
                out[i] = Some(r);
            }
        }
    });
    out.into_iter().map(|r| r.expect("every item has its result")).collect()
}

/// Threads of [`concurrently`].
const IO_THREADS: usize = 16;

/// Remove `dir` and everything in it: its files unlinked [`concurrently`], then the rest.
fn remove_folder(dir: &Path) -> std::io::Result<()> {
    let files: Vec<PathBuf> =
        std::fs::read_dir(dir)?.filter_map(|e| e.ok()).filter(|e| e.file_type().is_ok_and(|t| !t.is_dir())).map(|e| e.path()).collect();
    concurrently(&files, |p| {
        let _ = std::fs::remove_file(p);
    });
    std::fs::remove_dir_all(dir)
}

fn sync_dir(dir: &Path) {
    if let Ok(f) = File::open(dir) {
        let _ = f.sync_all();
    }
}

#[cfg(target_os = "linux")]
fn exchange_dirs(a: &Path, b: &Path) -> std::io::Result<()> {
    use std::os::unix::ffi::OsStrExt;
    let c = |p: &Path| std::ffi::CString::new(p.as_os_str().as_bytes()).map_err(|_| std::io::Error::from(std::io::ErrorKind::InvalidInput));
    let (a, b) = (c(a)?, c(b)?);
    // SAFETY: two valid NUL-terminated paths; the raw syscall avoids depending on the C
    // library's wrapper (glibc >= 2.28).
    let r = unsafe { libc::syscall(libc::SYS_renameat2, libc::AT_FDCWD, a.as_ptr(), libc::AT_FDCWD, b.as_ptr(), libc::RENAME_EXCHANGE) };
    if r == 0 {
        Ok(())
    } else {
        Err(std::io::Error::last_os_error())
    }
}

#[cfg(not(target_os = "linux"))]
fn exchange_dirs(_a: &Path, _b: &Path) -> std::io::Result<()> {
    Err(std::io::Error::from(std::io::ErrorKind::Unsupported))
}

/// The kernel or the file system cannot exchange (old kernel, NFS, ...): use two renames.
fn exchange_unsupported(e: &std::io::Error) -> bool {
    #[cfg(unix)]
    if matches!(e.raw_os_error(), Some(libc::EINVAL | libc::ENOSYS | libc::EOPNOTSUPP)) {
        return true;
    }
    e.kind() == std::io::ErrorKind::Unsupported
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("blendsim-output-{name}-{}", unique_suffix()));
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    fn listing(d: &Path) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(d).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
        v.sort();
        v
    }

    fn bake(target: &Path, group: &str, files: &[(&str, &str)]) {
        let mut s = Staging::new(target).unwrap();
        s.set_group(group);
        for (n, text) in files {
            s.write(n, text.as_bytes()).unwrap();
        }
        s.commit().unwrap();
    }

    #[test]
    fn atomic_write_replaces_and_leaves_no_temporaries() {
        let d = scratch("atomic");
        let f = d.join("a.txt");
        write_atomic(&f, b"one").unwrap();
        write_atomic(&f, b"two").unwrap();
        assert_eq!(std::fs::read(&f).unwrap(), b"two");
        assert_eq!(std::fs::read_dir(&d).unwrap().count(), 1);
        // A temporary of a dead process is swept by the next write of that file.
        std::fs::write(d.join(".a.tmp-999999999-0.txt"), b"x").unwrap();
        write_atomic(&f, b"three").unwrap();
        assert_eq!(listing(&d), ["a.txt"]);
        let e = write_atomic(Path::new("/dev/null"), b"x").unwrap_err().to_string();
        assert!(e.contains("/dev/null: exists and is not a regular file"), "{e}");
        std::fs::create_dir(d.join("sub")).unwrap();
        assert!(write_atomic(&d.join("sub"), b"x").is_err());
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn atomic_write_with_keeps_the_extension_and_cleans_up_on_error() {
        let d = scratch("atomic-with");
        let f = d.join("a.usdc");
        write_atomic_with(&f, |tmp| {
            assert!(tmp.to_string_lossy().ends_with(".usdc") && tmp.parent() == Some(d.as_path()), "{}", tmp.display());
            std::fs::write(tmp, b"one").map_err(|e| Error::io(tmp, &e, "write"))
        })
        .unwrap();
        assert_eq!(std::fs::read(&f).unwrap(), b"one");
        let e = write_atomic_with(&f, |tmp| {
            std::fs::write(tmp, b"half").unwrap();
            Err(Error::general("failed midway", "none"))
        });
        assert!(e.is_err());
        assert_eq!(std::fs::read(&f).unwrap(), b"one", "the old file stays");
        assert_eq!(std::fs::read_dir(&d).unwrap().count(), 1, "no temporary left");
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn missing_parents_are_removed_after_a_failed_run() {
        let d = scratch("parents");
        let target = d.join("a/b/out");
        {
            let mut s = Staging::new(&target).unwrap();
            s.write("x.glb", b"glTF").unwrap();
        }
        assert_eq!(std::fs::read_dir(&d).unwrap().count(), 0, "a failed run leaves nothing");
        bake(&target, "g", &[("x.glb", "glTF")]);
        assert_eq!(std::fs::read(target.join("x.glb")).unwrap(), b"glTF");
        assert_eq!(listing(&d.join("a/b")), ["out"], "no staging folder or lock left");
        assert_eq!(listing(&target), [MANIFEST, "x.glb"]);
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn uncommitted_staging_leaves_the_old_folder_untouched() {
        let d = scratch("staging");
        let target = d.join("out");
        bake(&target, "g", &[("x.usda", "#usda 1.0")]);
        {
            let mut s = Staging::new(&target).unwrap();
            s.write("x.usda", b"#usda 1.0 new").unwrap();
            assert_eq!(listing(&d).len(), 3, "out, the lock and the staging folder");
        }
        assert_eq!(std::fs::read(target.join("x.usda")).unwrap(), b"#usda 1.0");
        assert_eq!(listing(&d), ["out"]);
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn a_commit_removes_its_groups_stale_files_and_keeps_everything_else() {
        let d = scratch("groups");
        let target = d.join("out");
        bake(&target, "export:t", &[("t.usda", "a"), ("t.glb", "b"), ("t.outputs.json", "c")]);
        bake(&target, "report", &[("report.md", "r")]);
        std::fs::write(target.join("notes.txt"), "mine").unwrap();
        std::fs::create_dir_all(target.join("renders/deep")).unwrap();
        std::fs::write(target.join("renders/deep/f.png"), "png").unwrap();
        #[cfg(unix)]
        std::os::unix::fs::symlink("notes.txt", target.join("link")).unwrap();
        use std::os::unix::fs::MetadataExt;
        let inode = std::fs::metadata(target.join("renders/deep/f.png")).unwrap().ino();
        // Fewer formats: t.usda goes, the report and the foreign files stay.
        bake(&target, "export:t", &[("t.glb", "B"), ("t.outputs.json", "C")]);
        assert_eq!(listing(&target), [MANIFEST, "link", "notes.txt", "renders", "report.md", "t.glb", "t.outputs.json"]);
        assert_eq!(std::fs::read_to_string(target.join("t.glb")).unwrap(), "B");
        assert_eq!(std::fs::read_to_string(target.join("notes.txt")).unwrap(), "mine");
        assert_eq!(std::fs::metadata(target.join("renders/deep/f.png")).unwrap().ino(), inode, "the same file, linked");
        assert_eq!(std::fs::read_link(target.join("link")).unwrap(), Path::new("notes.txt"));
        let manifest = read_manifest(&target);
        assert_eq!(manifest.keys().collect::<Vec<_>>(), ["report.md", "t.glb", "t.outputs.json"]);
        assert_eq!(manifest["report.md"], "report");
        assert_eq!(listing(&d), ["out"]);
        std::fs::remove_dir_all(&d).unwrap();
    }

    /// A run that replaces every group (a bake of a renamed scene) removes the earlier run's
    /// files of every group and says which; files that are not blendsim's are kept and listed.
    #[test]
    fn a_commit_of_every_group_removes_every_earlier_file_it_does_not_write() {
        let d = scratch("every");
        let target = d.join("out");
        bake(&target, "export:old", &[("old.usda", "a"), ("old.glb", "b"), ("shared.png", "t")]);
        bake(&target, "summary", &[("summary.md", "s")]);
        std::fs::write(target.join("notes.txt"), "mine").unwrap();
        std::fs::create_dir(target.join("renders")).unwrap();
        let mut s = Staging::new(&target).unwrap();
        s.replace_every_group();
        s.set_group("export:new");
        s.write("new.glb", b"B").unwrap();
        s.write("shared.png", b"T").unwrap();
        s.set_group("report");
        s.write("report.md", b"r").unwrap();
        let summary = s.commit_with_summary().unwrap();
        assert_eq!(
            summary,
            Committed {
                removed: vec!["old.glb".into(), "old.usda".into(), "summary.md".into()],
                kept: vec!["notes.txt".into(), "renders".into()],
                written: vec!["new.glb".into(), "report.md".into(), "shared.png".into()]
            }
        );
        assert_eq!(
            summary.messages(Path::new("build/x"), "bake"),
            [
                "removed from build/x 3 files of an earlier run that this bake did not write again: old.glb, old.usda, summary.md",
                "kept in build/x 2 entries that blendsim did not write: notes.txt, renders"
            ]
        );
        assert_eq!(listing(&target), [MANIFEST, "new.glb", "notes.txt", "renders", "report.md", "shared.png"]);
        assert_eq!(read_manifest(&target).keys().collect::<Vec<_>>(), ["new.glb", "report.md", "shared.png"]);
        // Without it, a commit keeps the other groups (and has nothing of its own to remove).
        let mut s = Staging::new(&target).unwrap();
        s.set_group("export:other");
        s.write("other.glb", b"O").unwrap();
        let summary = s.commit_with_summary().unwrap();
        assert_eq!(summary.removed, Vec::<String>::new());
        assert!(Committed::default().messages(Path::new("x"), "bake").is_empty());
        let many = Committed { removed: vec![], kept: (0..7).map(|i| format!("f{i}")).chain(["bad\nname".into()]).collect(), written: vec![] };
        assert_eq!(many.messages(Path::new("x"), "bake"), ["kept in x 8 entries that blendsim did not write: f0, f1, f2, f3, f4 and 3 more"]);
        let one = Committed { removed: vec!["a\u{1b}[2J".into()], kept: vec![], written: vec![] };
        assert_eq!(one.messages(Path::new("x"), "bake"), ["removed from x 1 file of an earlier run that this bake did not write again: a\\u{1b}[2J"]);
        assert_eq!(listing(&target), [MANIFEST, "new.glb", "notes.txt", "other.glb", "renders", "report.md", "shared.png"]);
        std::fs::remove_dir_all(&d).unwrap();
    }

    /// A file written in pieces is staged and committed like a written one; a failed fill is
    /// an error naming the file, and nothing of that run is committed.
    #[test]
    fn a_file_written_in_pieces_is_staged_like_any() {
        let d = scratch("pieces");
        let target = d.join("out");
        let mut s = Staging::new(&target).unwrap();
        s.write_with("big.usda", |f| (0..3).try_for_each(|i| f.write_all(format!("piece {i}\n").as_bytes()))).unwrap();
        s.commit().unwrap();
        assert_eq!(std::fs::read_to_string(target.join("big.usda")).unwrap(), "piece 0\npiece 1\npiece 2\n");
        assert_eq!(read_manifest(&target).keys().collect::<Vec<_>>(), ["big.usda"]);
        let mut s = Staging::new(&target).unwrap();
        let e = s.write_with("big.usda", |_| Err(std::io::Error::other("disk full"))).unwrap_err().to_string();
        assert!(e.contains("big.usda") && e.contains("disk full"), "{e}");
        drop(s);
        assert_eq!(std::fs::read_to_string(target.join("big.usda")).unwrap(), "piece 0\npiece 1\npiece 2\n");
        assert_eq!(listing(&d), ["out"]);
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn what_a_killed_run_left_is_cleaned_and_foreign_files_given_back() {
        let d = scratch("stale");
        let target = d.join("out");
        bake(&target, "g", &[("x.glb", "old")]);
        // An incomplete staging folder (marker present): deleted.
        let incomplete = d.join(".out.blendsim-staging-999999999-0");
        std::fs::create_dir(&incomplete).unwrap();
        std::fs::write(incomplete.join(MARKER), "").unwrap();
        std::fs::write(incomplete.join("x.glb"), "partial").unwrap();
        // An old folder after a swap, holding a foreign file created during the commit.
        let old = d.join(".out.blendsim-old-999999999-1");
        std::fs::create_dir(&old).unwrap();
        std::fs::write(old.join(MANIFEST), manifest_json(&BTreeMap::from([("x.glb".into(), "g".into())]))).unwrap();
        std::fs::write(old.join("x.glb"), "older").unwrap();
        std::fs::write(old.join("late.txt"), "foreign").unwrap();
        // A staging folder of an older blendsim whose process is gone.
        std::fs::create_dir(target.join(".blendsim-staging-999999999-3")).unwrap();
        bake(&target, "g", &[("x.glb", "new")]);
        assert_eq!(listing(&d), ["out"]);
        assert_eq!(listing(&target), [MANIFEST, "late.txt", "x.glb"]);
        assert_eq!(std::fs::read_to_string(target.join("x.glb")).unwrap(), "new");
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn a_fallback_commit_killed_between_its_renames_is_restored() {
        let d = scratch("fallback");
        let target = d.join("out");
        bake(&target, "g", &[("x.glb", "old")]);
        std::fs::rename(&target, d.join(".out.blendsim-old-999999999-0")).unwrap();
        let s = Staging::new(&target).unwrap();
        assert_eq!(std::fs::read_to_string(target.join("x.glb")).unwrap(), "old", "restored before anything else");
        drop(s);
        assert_eq!(listing(&d), ["out"]);
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn a_busy_folder_fails_at_once_or_waits() {
        let d = scratch("busy");
        let target = d.join("out");
        let first = Staging::new(&target).unwrap();
        let e = Staging::open(&target, LockWait::Fail).unwrap_err().to_string();
        assert!(e.contains(&format!("another blendsim (pid {}) is writing into this output folder", std::process::id())), "{e}");
        let waiter = {
            let target = target.clone();
            std::thread::spawn(move || {
                let mut s = Staging::new(&target).unwrap();
                s.set_group("b");
                s.write("second", b"2").unwrap();
                s.commit().unwrap();
            })
        };
        std::thread::sleep(std::time::Duration::from_millis(100));
        assert!(!waiter.is_finished(), "the second run waits for the first");
        let mut first = first;
        first.set_group("a");
        first.write("first", b"1").unwrap();
        first.commit().unwrap();
        waiter.join().unwrap();
        assert_eq!(listing(&target), [MANIFEST, "first", "second"]);
        assert_eq!(listing(&d), ["out"]);
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn names_that_are_not_plain_never_leave_the_staging_folder() {
        let d = scratch("names");
        let target = d.join("out");
        let mut s = Staging::new(&target).unwrap();
        for bad in ["../x", "a/b", "..", ".", "", MANIFEST] {
            assert!(s.path(bad).starts_with(&s.dir), "{bad}");
            let e = s.write(bad, b"x").unwrap_err().to_string();
            assert!(e.contains("it is not a plain file name"), "{e}");
        }
        s.record("../escaped");
        assert!(s.commit().unwrap_err().to_string().contains("it is not a plain file name"));
        assert_eq!(listing(&d), Vec::<String>::new());
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn a_file_or_the_working_folder_is_refused() {
        let d = scratch("refused");
        std::fs::write(d.join("f"), "").unwrap();
        assert!(Staging::new(&d.join("f")).unwrap_err().to_string().contains("exists and is not a folder"));
        let cwd = std::env::current_dir().unwrap();
        assert!(Staging::new(&cwd).unwrap_err().to_string().contains("is the working folder or one of its parents"));
        std::fs::remove_dir_all(&d).unwrap();
    }
}
