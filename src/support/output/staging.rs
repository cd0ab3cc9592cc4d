//! The files of one output folder, staged beside it and committed by a swap.

use std::collections::{BTreeMap, BTreeSet};
use std::fs::File;
use std::io::Write as _;
use std::path::{Path, PathBuf};

use super::exchange::{exchange_dirs, exchange_unsupported};
use super::lock::{FolderLock, LockWait};
use super::manifest::{contained, manifest_json, read_manifest, MANIFEST, MARKER};
use super::tree::{concurrently, link_tree, remove_folder, remove_stale, rescue, sync_dir};
use super::{pid_of, unique_suffix};
use crate::support::error::{Error, Result};
use crate::support::interrupt::{self, Token};

/// The group of files staged before any [`Staging::set_group`].
const DEFAULT_GROUP: &str = "files";

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
    /// The staging folder.
    pub(super) dir: PathBuf,
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

/// `.blendsim-staging-PID-N` of a blendsim before output locking, whose process is gone.
fn is_dead_legacy_staging(name: &str) -> bool {
    name.strip_prefix(".blendsim-staging-").and_then(pid_of).is_some_and(|pid| !interrupt::process_alive(pid))
}
