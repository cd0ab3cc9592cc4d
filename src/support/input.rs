//! Reading input files: regular files only, so a FIFO, a folder or a device given as a mesh,
//! scene or selection is a clear error instead of a hang (a FIFO with no writer blocks its
//! reader forever, `/dev/zero` never ends).

use std::io::Read;
use std::path::Path;

use crate::support::error::{Error, Result};

/// The bytes of the regular file `path`; `what` names it in errors ("the OBJ surface").
pub(crate) fn read_bytes(path: &Path, what: &str) -> Result<Vec<u8>> {
    let mut options = std::fs::OpenOptions::new();
    options.read(true);
    // Opening a FIFO for reading blocks until a writer appears, unless non-blocking.
    #[cfg(unix)]
    std::os::unix::fs::OpenOptionsExt::custom_flags(&mut options, libc::O_NONBLOCK);
    let mut file = options.open(path).map_err(|e| Error::io(path, &e, &format!("read {what}")))?;
    let meta = file.metadata().map_err(|e| Error::io(path, &e, &format!("read {what}")))?;
    if !meta.is_file() {
        return Err(Error::in_file(
            path,
            format!("is {}, not a regular file, so it cannot be read as {what}", kind(&meta)),
            "give the path of the file itself",
        ));
    }
    let mut bytes = Vec::with_capacity(usize::try_from(meta.len()).unwrap_or(0).min(1 << 30));
    file.read_to_end(&mut bytes).map_err(|e| Error::io(path, &e, &format!("read {what}")))?;
    Ok(bytes)
}

/// The UTF-8 text of the regular file `path` (see [`read_bytes`]).
pub(crate) fn read_text(path: &Path, what: &str) -> Result<String> {
    String::from_utf8(read_bytes(path, what)?).map_err(|e| {
        Error::in_file(
            path,
            format!("is not UTF-8 text (invalid byte at offset {}), so it cannot be read as {what}", e.utf8_error().valid_up_to()),
            "save the file as UTF-8 text, or check that it is the file you meant",
        )
    })
}

/// What a file that is not a regular one is, for messages ("a folder", "a named pipe (FIFO)").
pub(crate) fn kind(meta: &std::fs::Metadata) -> &'static str {
    let t = meta.file_type();
    if t.is_dir() {
        return "a folder";
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if t.is_fifo() {
            return "a named pipe (FIFO)";
        }
        if t.is_socket() {
            return "a socket";
        }
        if t.is_char_device() || t.is_block_device() {
            return "a device";
        }
    }
    "not a regular file"
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_regular_files_are_read() {
        let tmp = tempfile::tempdir().unwrap();
        let d = tmp.path();
        std::fs::write(d.join("a.obj"), "v 0 0 0\n").unwrap();
        assert_eq!(read_text(&d.join("a.obj"), "the OBJ surface").unwrap(), "v 0 0 0\n");
        let e = read_text(d, "the OBJ surface").unwrap_err().to_string();
        assert!(e.contains("is a folder, not a regular file, so it cannot be read as the OBJ surface"), "{e}");
        let fifo = d.join("pipe.obj");
        let _ = std::fs::remove_file(&fifo);
        assert!(std::process::Command::new("mkfifo").arg(&fifo).status().unwrap().success());
        let e = read_text(&fifo, "the OBJ surface").unwrap_err().to_string();
        assert!(e.contains("is a named pipe (FIFO), not a regular file"), "{e}");
        let e = read_bytes(Path::new("/dev/zero"), "the scene file").unwrap_err().to_string();
        assert!(e.contains("is a device"), "{e}");
        std::fs::write(d.join("latin1.txt"), b"caf\xe9").unwrap();
        let e = read_text(&d.join("latin1.txt"), "the selection").unwrap_err().to_string();
        assert!(e.contains("is not UTF-8 text (invalid byte at offset 3)"), "{e}");
    }
}
