//! The swap of two folders in one step, and when the kernel or file system cannot do it.

use std::path::Path;

/// Exchange `a` and `b` atomically (`renameat2` with `RENAME_EXCHANGE`, through rustix's
/// system-call layer: no dependency on the C library's wrapper, glibc >= 2.28).
#[cfg(target_os = "linux")]
pub(super) fn exchange_dirs(a: &Path, b: &Path) -> std::io::Result<()> {
    use rustix::fs::{renameat_with, RenameFlags, CWD};
    renameat_with(CWD, a, CWD, b, RenameFlags::EXCHANGE).map_err(std::io::Error::from)
}

#[cfg(not(target_os = "linux"))]
pub(super) fn exchange_dirs(_a: &Path, _b: &Path) -> std::io::Result<()> {
    Err(std::io::Error::from(std::io::ErrorKind::Unsupported))
}

/// The kernel or the file system cannot exchange (old kernel, NFS, ...): use two renames.
pub(super) fn exchange_unsupported(e: &std::io::Error) -> bool {
    #[cfg(unix)]
    if matches!(e.raw_os_error(), Some(libc::EINVAL | libc::ENOSYS | libc::EOPNOTSUPP)) {
        return true;
    }
    e.kind() == std::io::ErrorKind::Unsupported
}
