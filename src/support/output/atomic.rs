//! One file written atomically: under a temporary name beside it, then renamed.

use std::fs::File;
use std::path::Path;

use super::{pid_of, unique_suffix};
use crate::support::error::{Error, Result};
use crate::support::interrupt;

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
