//! Writing outputs so that a failed run leaves nothing behind.
//!
//! - [`write_atomic`]: one file, written under a temporary name beside it and renamed.
//! - [`Staging`]: several files for one output folder, written to a hidden staging folder and
//!   moved into place only by [`Staging::commit`]; dropping it uncommitted deletes everything.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use crate::error::{Error, Result};

static COUNTER: AtomicU64 = AtomicU64::new(0);

fn unique_suffix() -> String {
    format!("{}-{}", std::process::id(), COUNTER.fetch_add(1, Ordering::Relaxed))
}

/// Write `bytes` to `path` atomically: readers see the old file or the whole new one.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    if !dir.is_dir() {
        return Err(Error::in_file(dir, "output folder does not exist", "create the folder first, or choose another output path"));
    }
    let name = path.file_name().ok_or_else(|| Error::in_file(path, "is not a file path", "give a file name"))?;
    let tmp = dir.join(format!(".{}.tmp-{}", name.to_string_lossy(), unique_suffix()));
    let result = std::fs::write(&tmp, bytes)
        .map_err(|e| Error::io(&tmp, &e, "write a temporary output file"))
        .and_then(|_| std::fs::rename(&tmp, path).map_err(|e| Error::io(path, &e, "move the finished file into place")));
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

/// Write `path` atomically from a closure that fills a temporary file beside it (streamed, or
/// by an external tool), then rename it into place; on error the temporary is removed.
/// The temporary keeps `path`'s extension (`.NAME.tmp-ID.usdc`): tools that pick a format by
/// extension write the right one.
pub fn write_atomic_with(path: &Path, fill: impl FnOnce(&Path) -> Result<()>) -> Result<()> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    if !dir.is_dir() {
        return Err(Error::in_file(dir, "output folder does not exist", "create the folder first, or choose another output path"));
    }
    let name = path.file_name().ok_or_else(|| Error::in_file(path, "is not a file path", "give a file name"))?.to_string_lossy();
    let tmp = match name.rsplit_once('.') {
        Some((stem, ext)) if !stem.is_empty() => dir.join(format!(".{stem}.tmp-{}.{ext}", unique_suffix())),
        _ => dir.join(format!(".{name}.tmp-{}", unique_suffix())),
    };
    let result = fill(&tmp).and_then(|_| std::fs::rename(&tmp, path).map_err(|e| Error::io(path, &e, "move the finished file into place")));
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

/// Files for one output folder, kept out of sight until the whole run has succeeded.
#[derive(Debug)]
pub struct Staging {
    target: PathBuf,
    dir: PathBuf,
    files: Vec<String>,
    committed: bool,
}

impl Staging {
    /// Start staging files for `target`, which need not exist yet (nor its parents: they are
    /// created at commit). The staging folder is hidden in the nearest existing ancestor, so
    /// the final renames stay on one file system and a failed run creates nothing.
    pub fn new(target: &Path) -> Result<Staging> {
        if target.exists() && !target.is_dir() {
            return Err(Error::in_file(target, "exists and is not a folder", "choose a folder for --out"));
        }
        let mut anchor = if target.as_os_str().is_empty() { PathBuf::from(".") } else { target.to_path_buf() };
        while !anchor.is_dir() {
            anchor = match anchor.parent() {
                Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
                _ => PathBuf::from("."),
            };
        }
        let dir = anchor.join(format!(".blendsim-staging-{}", unique_suffix()));
        std::fs::create_dir(&dir).map_err(|e| Error::io(&anchor, &e, "create a staging folder for the outputs"))?;
        Ok(Staging { target: target.to_path_buf(), dir, files: Vec::new(), committed: false })
    }

    /// Where a staged file lives until commit (for external tools that write it themselves).
    pub fn path(&self, name: &str) -> PathBuf {
        self.dir.join(name)
    }

    /// The final path of a file once committed.
    pub fn final_path(&self, name: &str) -> PathBuf {
        self.target.join(name)
    }

    /// Write a file into the staging folder.
    pub fn write(&mut self, name: &str, bytes: &[u8]) -> Result<()> {
        let p = self.path(name);
        std::fs::write(&p, bytes).map_err(|e| Error::io(&p, &e, "write an output file"))?;
        self.record(name);
        Ok(())
    }

    /// Record a file that an external tool wrote at [`Staging::path`].
    pub fn record(&mut self, name: &str) {
        if !self.files.iter().any(|f| f == name) {
            self.files.push(name.to_string());
        }
    }

    /// Size of a staged file.
    pub fn size(&self, name: &str) -> Result<u64> {
        let p = self.path(name);
        std::fs::metadata(&p).map(|m| m.len()).map_err(|e| Error::io(&p, &e, "measure an output file"))
    }

    /// Move every staged file into the target folder (created if missing).
    pub fn commit(mut self) -> Result<()> {
        std::fs::create_dir_all(&self.target).map_err(|e| Error::io(&self.target, &e, "create the output folder"))?;
        for name in &self.files {
            let (from, to) = (self.dir.join(name), self.target.join(name));
            std::fs::rename(&from, &to).map_err(|e| Error::io(&to, &e, "move the finished file into place"))?;
        }
        self.committed = true;
        let _ = std::fs::remove_dir_all(&self.dir);
        Ok(())
    }
}

impl Drop for Staging {
    fn drop(&mut self) {
        if !self.committed {
            let _ = std::fs::remove_dir_all(&self.dir);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("blendsim-output-{name}-{}", unique_suffix()));
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn atomic_write_replaces_and_leaves_no_temporaries() {
        let d = scratch("atomic");
        let f = d.join("a.txt");
        write_atomic(&f, b"one").unwrap();
        write_atomic(&f, b"two").unwrap();
        assert_eq!(std::fs::read(&f).unwrap(), b"two");
        assert_eq!(std::fs::read_dir(&d).unwrap().count(), 1);
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
    fn missing_parents_are_created_only_on_commit() {
        let d = scratch("parents");
        let target = d.join("a/b/out");
        {
            let mut s = Staging::new(&target).unwrap();
            s.write("x.glb", b"glTF").unwrap();
        }
        assert_eq!(std::fs::read_dir(&d).unwrap().count(), 0, "a failed run creates nothing");
        let mut s = Staging::new(&target).unwrap();
        s.write("x.glb", b"glTF").unwrap();
        s.commit().unwrap();
        assert_eq!(std::fs::read(target.join("x.glb")).unwrap(), b"glTF");
        assert_eq!(std::fs::read_dir(&d).unwrap().count(), 1, "no staging folder left");
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn uncommitted_staging_leaves_nothing() {
        let d = scratch("staging");
        let target = d.join("out");
        {
            let mut s = Staging::new(&target).unwrap();
            s.write("x.usda", b"#usda 1.0").unwrap();
        }
        assert!(!target.exists());
        assert_eq!(std::fs::read_dir(&d).unwrap().count(), 0);
        let mut s = Staging::new(&target).unwrap();
        s.write("x.usda", b"#usda 1.0").unwrap();
        s.commit().unwrap();
        assert_eq!(std::fs::read(target.join("x.usda")).unwrap(), b"#usda 1.0");
        assert_eq!(std::fs::read_dir(&d).unwrap().count(), 1);
        std::fs::remove_dir_all(&d).unwrap();
    }
}
