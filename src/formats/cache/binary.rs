//! Byte-level helpers shared by the binary cache readers (PC2, MDD, glTF buffers).
//!
//! Readers open inputs with [`open_regular`] (a FIFO or a device would block or never end,
//! and their size cannot be checked up front) and read with [`read_exact_at`], whose errors
//! name the byte offset.

use std::fs::File;
use std::io::{Read, Seek, SeekFrom};
use std::path::Path;

use crate::algorithms::geometry::Point;
use crate::support::error::{Error, Result};

/// Refuse anything but a regular file (following symlinks), before opening it: opening a FIFO
/// for reading blocks until a writer appears.
pub(crate) fn require_regular(path: &Path, what: &str) -> Result<u64> {
    let meta = std::fs::metadata(path).map_err(|e| Error::io(path, &e, &format!("read the {what}")))?;
    if meta.is_file() {
        return Ok(meta.len());
    }
    let kind = if meta.is_dir() { "a folder" } else { "not a regular file (a FIFO, socket or device)" };
    Err(Error::in_file(path, format!("the {what} is {kind}"), "give the path of a regular file; copy a stream to a file first"))
}

/// Open a regular file for reading; returns it with its size.
pub(crate) fn open_regular(path: &Path, what: &str) -> Result<(File, u64)> {
    require_regular(path, what)?;
    let file = File::open(path).map_err(|e| Error::io(path, &e, &format!("open the {what}")))?;
    let len = file.metadata().map_err(|e| Error::io(path, &e, &format!("measure the {what}")))?.len();
    Ok((file, len))
}

/// Read `buf.len()` bytes at `offset`; a short read is an error naming the offset.
pub(crate) fn read_exact_at<R: Read + Seek>(reader: &mut R, offset: u64, buf: &mut [u8], path: &Path) -> Result<()> {
    reader.seek(SeekFrom::Start(offset)).and_then(|_| reader.read_exact(buf)).map_err(|e| {
        Error::in_file(
            path,
            format!("cannot read {} bytes at byte {offset}: {e}", buf.len()),
            "the file is damaged or changed while reading; re-export it",
        )
    })
}

/// Byte order of a binary cache.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Endian {
    Little,
    Big,
}

impl Endian {
    #[inline]
    pub(crate) fn f32(self, b: [u8; 4]) -> f32 {
        match self {
            Endian::Little => f32::from_le_bytes(b),
            Endian::Big => f32::from_be_bytes(b),
        }
    }

    #[inline]
    pub(crate) fn i32(self, b: [u8; 4]) -> i32 {
        match self {
            Endian::Little => i32::from_le_bytes(b),
            Endian::Big => i32::from_be_bytes(b),
        }
    }

    #[inline]
    pub(crate) fn f32_bytes(self, x: f32) -> [u8; 4] {
        match self {
            Endian::Little => x.to_le_bytes(),
            Endian::Big => x.to_be_bytes(),
        }
    }
}

/// The 4 bytes at `at` of a slice known to hold them.
#[inline]
pub(crate) fn word(bytes: &[u8], at: usize) -> [u8; 4] {
    [bytes[at], bytes[at + 1], bytes[at + 2], bytes[at + 3]]
}

/// Decode `out.len()` points of three f32 from `bytes` (which hold exactly that many), refusing
/// non-finite coordinates: the error names the frame, the vertex and its byte offset
/// (`base_offset` is where `bytes` starts in the file).
pub(crate) fn decode_points(bytes: &[u8], endian: Endian, out: &mut [Point], frame: usize, base_offset: u64, path: &Path) -> Result<()> {
    debug_assert_eq!(bytes.len(), out.len() * 12);
    for (v, (p, chunk)) in out.iter_mut().zip(bytes.chunks_exact(12)).enumerate() {
        let xyz = [endian.f32(word(chunk, 0)), endian.f32(word(chunk, 4)), endian.f32(word(chunk, 8))];
        if let Some(d) = xyz.iter().position(|x| !x.is_finite()) {
            return Err(Error::in_file(
                path,
                format!(
                    "frame {frame}, vertex {v}: coordinate {} is {} (byte {})",
                    ["x", "y", "z"][d],
                    xyz[d],
                    base_offset + 12 * v as u64 + 4 * d as u64
                ),
                "the simulation that wrote the cache diverged or the file is damaged; re-bake it",
            ));
        }
        *p = xyz.map(f64::from);
    }
    Ok(())
}

/// Append the f32 form of `points` in `endian` order.
pub(crate) fn encode_points(points: &[Point], endian: Endian, out: &mut Vec<u8>) {
    out.reserve(points.len() * 12);
    for p in points {
        for x in p {
            out.extend_from_slice(&endian.f32_bytes(*x as f32));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_fifo_is_refused_without_opening_it() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path();
        let fifo = dir.join("anim.pc2");
        let status = std::process::Command::new("mkfifo").arg(&fifo).status().expect("mkfifo runs");
        assert!(status.success());
        // Opening the FIFO for reading would block this test forever.
        let s = open_regular(&fifo, "PC2 cache").unwrap_err().to_string();
        assert!(s.starts_with(&format!("{}: the PC2 cache is not a regular file", fifo.display())) && s.contains("(fix: "), "{s}");
        let s = open_regular(dir, "PC2 cache").unwrap_err().to_string();
        assert!(s.contains("the PC2 cache is a folder"), "{s}");
    }

    #[test]
    fn non_finite_coordinates_name_frame_vertex_and_byte() {
        let mut bytes = Vec::new();
        encode_points(&[[1.0, 2.0, 3.0], [4.0, f64::NAN, 6.0]], Endian::Big, &mut bytes);
        let mut out = [[0.0; 3]; 2];
        let e = decode_points(&bytes, Endian::Big, &mut out, 7, 100, Path::new("a.mdd")).unwrap_err().to_string();
        assert!(e.starts_with("a.mdd: frame 7, vertex 1: coordinate y is NaN (byte 116)"), "{e}");
        let mut bytes = Vec::new();
        encode_points(&[[1.0, 2.0, 3.0]], Endian::Little, &mut bytes);
        decode_points(&bytes, Endian::Little, &mut out[..1], 0, 0, Path::new("a.pc2")).unwrap();
        assert_eq!(out[0], [1.0, 2.0, 3.0]);
    }
}
