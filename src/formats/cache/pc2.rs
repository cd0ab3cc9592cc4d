//! PC2 point caches (Blender, 3ds Max, Maya, Houdini), little-endian:
//!
//! | byte | type | field |
//! |---|---|---|
//! | 0 | `char[12]` | `"POINTCACHE2\0"` |
//! | 12 | `i32` | version, 1 |
//! | 16 | `i32` | points per sample `P` |
//! | 20 | `f32` | start frame |
//! | 24 | `f32` | sample rate: frames between samples |
//! | 28 | `i32` | samples `S` |
//! | 32 | `f32[S][P][3]` | positions |
//!
//! PC2 counts time in frames, not seconds: sample `i` is at frame `start + i * rate`, which
//! the caller's frames per second turn into seconds. The file must be exactly `32 + 12 P S`
//! bytes; the header is checked against the size before anything is allocated, and a frame is
//! read with one seek, so memory is one frame.

use std::fs::File;
use std::io::{BufWriter, Read, Seek, Write};
use std::path::{Path, PathBuf};

use super::binary::{decode_points, encode_points, open_regular, read_exact_at, word, Endian};
use super::{check_writable, FrameSource};
use crate::algorithms::geometry::Point;
use crate::support::error::{Error, Result};

pub(crate) const MAGIC: &[u8; 12] = b"POINTCACHE2\0";
pub(crate) const HEADER_BYTES: u64 = 32;

const FIX_DAMAGED: &str = "the file is truncated or its header does not match its data; re-export the cache";

/// The fields of a PC2 header, checked against the file size.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Pc2Header {
    pub points: usize,
    pub start_frame: f64,
    /// Frames between samples, > 0.
    pub sample_rate: f64,
    pub samples: usize,
}

impl Pc2Header {
    /// Parse the 32 header bytes of a file of `file_len` bytes. `header` may be shorter than 32
    /// bytes when the file is.
    pub fn parse(header: &[u8], file_len: u64, path: &Path) -> Result<Pc2Header> {
        let bad = |problem: String| Err(Error::in_file(path, problem, FIX_DAMAGED));
        if file_len < HEADER_BYTES {
            return bad(format!("is {file_len} bytes, shorter than the 32-byte PC2 header (truncated at byte {file_len})"));
        }
        if &header[..12] != MAGIC {
            return Err(Error::in_file(
                path,
                format!("does not start with the PC2 signature \"POINTCACHE2\" (byte 0: {:?})", String::from_utf8_lossy(&header[..12])),
                "give a .pc2 point cache, or name the file after its real format (.mdd, .obj sequence, .glb, .usd)",
            ));
        }
        let le = Endian::Little;
        let version = le.i32(word(header, 12));
        if version != 1 {
            return Err(Error::in_file(path, format!("PC2 version {version} at byte 12 (only version 1 exists)"), FIX_DAMAGED));
        }
        let (points, start, rate, samples) = (le.i32(word(header, 16)), le.f32(word(header, 20)), le.f32(word(header, 24)), le.i32(word(header, 28)));
        if points <= 0 {
            return bad(format!("point count {points} at byte 16 (must be positive)"));
        }
        if samples <= 0 {
            return bad(format!("sample count {samples} at byte 28 (must be positive)"));
        }
        if !start.is_finite() {
            return bad(format!("start frame {start} at byte 20 is not a number"));
        }
        if !(rate.is_finite() && rate > 0.0) {
            return bad(format!("sample rate {rate} at byte 24 (frames between samples) must be positive"));
        }
        // u128: 12 * i32::MAX * i32::MAX overflows u64.
        let frame_bytes = 12 * points as u64;
        let expected = HEADER_BYTES as u128 + frame_bytes as u128 * samples as u128;
        if file_len as u128 != expected {
            return bad(size_mismatch(
                file_len,
                expected,
                HEADER_BYTES,
                frame_bytes,
                &format!("{points} points (byte 16) x {samples} samples (byte 28)"),
            ));
        }
        Ok(Pc2Header { points: points as usize, start_frame: start as f64, sample_rate: rate as f64, samples: samples as usize })
    }
}

/// The problem of a file whose size does not match its header: where it ends (inside which
/// frame) or how many bytes follow the data. `file_len >= data_start`, where the frames begin.
pub(crate) fn size_mismatch(file_len: u64, expected: u128, data_start: u64, frame_bytes: u64, counts: &str) -> String {
    debug_assert!(file_len >= data_start);
    if (file_len as u128) < expected {
        let frame = (file_len - data_start) / frame_bytes;
        let at = data_start + frame * frame_bytes;
        format!("the header says {counts} = {expected} bytes, but the file ends at byte {file_len}, inside frame {frame} (which starts at byte {at}): truncated")
    } else {
        format!(
            "the header says {counts} = {expected} bytes, but the file has {} more bytes after byte {expected}: the counts do not match the data",
            file_len as u128 - expected
        )
    }
}

/// The frames of a PC2 file, read on demand. `R` is a file, or any seekable bytes in tests.
#[derive(Debug)]
pub(crate) struct Pc2Frames<R = File> {
    path: PathBuf,
    reader: R,
    header: Pc2Header,
    fps: f64,
    bytes: Vec<u8>,
}

/// Open a PC2 file; `fps` is the frame rate of the frame numbers it stores.
pub fn open(path: &Path, fps: f64) -> Result<Pc2Frames> {
    let (file, len) = open_regular(path, "PC2 cache")?;
    Pc2Frames::new(path, file, len, fps)
}

impl<R: Read + Seek> Pc2Frames<R> {
    /// Read and check the header of `reader` (`len` bytes long).
    pub fn new(path: &Path, mut reader: R, len: u64, fps: f64) -> Result<Self> {
        assert!(fps.is_finite() && fps > 0.0, "fps is checked by the caller");
        let mut header = [0u8; HEADER_BYTES as usize];
        let available = len.min(HEADER_BYTES) as usize;
        read_exact_at(&mut reader, 0, &mut header[..available], path)?;
        let header = Pc2Header::parse(&header[..available], len, path)?;
        Ok(Pc2Frames { path: path.to_path_buf(), reader, header, fps, bytes: Vec::new() })
    }

    /// Samples per second: the frame rate divided by the frames between samples.
    pub(crate) fn sample_fps(&self) -> f64 {
        self.fps / self.header.sample_rate
    }
}

impl<R: Read + Seek> FrameSource for Pc2Frames<R> {
    fn vertex_count(&self) -> usize {
        self.header.points
    }

    fn frame_count(&self) -> usize {
        self.header.samples
    }

    fn time(&self, frame: usize) -> f64 {
        (self.header.start_frame + frame as f64 * self.header.sample_rate) / self.fps
    }

    fn read_frame(&mut self, frame: usize, out: &mut [Point]) -> Result<()> {
        assert!(frame < self.header.samples && out.len() == self.header.points, "frame and buffer match the cache");
        let frame_bytes = 12 * self.header.points;
        let offset = HEADER_BYTES + (frame_bytes as u64) * frame as u64;
        self.bytes.resize(frame_bytes, 0);
        read_exact_at(&mut self.reader, offset, &mut self.bytes, &self.path)?;
        decode_points(&self.bytes, Endian::Little, out, frame, offset, &self.path)
    }
}

/// Write `frames` as PC2 at `fps` (start frame `time(0) * fps`, one sample per frame),
/// streamed to a temporary file and renamed into place.
pub fn write(path: &Path, frames: &mut dyn FrameSource, fps: f64) -> Result<()> {
    let (points, samples) = check_writable(path, frames, fps)?;
    let header = |w: &mut dyn Write| -> std::io::Result<()> {
        w.write_all(MAGIC)?;
        w.write_all(&1i32.to_le_bytes())?;
        w.write_all(&(points as i32).to_le_bytes())?;
        w.write_all(&((frames.time(0) * fps) as f32).to_le_bytes())?;
        w.write_all(&1f32.to_le_bytes())?;
        w.write_all(&(samples as i32).to_le_bytes())
    };
    let mut head = Vec::with_capacity(32);
    header(&mut head).expect("writing to a Vec cannot fail");
    write_frames(path, &head, frames, Endian::Little)
}

/// Stream `head` then every frame as f32 in `endian` order to `path`, atomically.
pub(crate) fn write_frames(path: &Path, head: &[u8], frames: &mut dyn FrameSource, endian: Endian) -> Result<()> {
    crate::support::output::write_atomic_with(path, |tmp| {
        let file = File::create(tmp).map_err(|e| Error::io(tmp, &e, "create the cache file"))?;
        let mut w = BufWriter::new(file);
        let io = |e: std::io::Error| Error::io(path, &e, "write the cache file");
        w.write_all(head).map_err(io)?;
        let mut points = vec![[0.0; 3]; frames.vertex_count()];
        let mut bytes = Vec::new();
        for frame in 0..frames.frame_count() {
            frames.read_frame(frame, &mut points)?;
            bytes.clear();
            encode_points(&points, endian, &mut bytes);
            w.write_all(&bytes).map_err(io)?;
        }
        w.into_inner().map_err(|e| io(e.into_error()))?.sync_all().map_err(io)
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::formats::cache::tests::{assert_frames_equal, scratch, wave};
    use std::io::Cursor;

    fn pc2_bytes(points: i32, start: f32, rate: f32, samples: i32, data: &[f32]) -> Vec<u8> {
        let mut b = MAGIC.to_vec();
        for w in [1i32.to_le_bytes(), points.to_le_bytes(), start.to_le_bytes(), rate.to_le_bytes(), samples.to_le_bytes()] {
            b.extend_from_slice(&w);
        }
        b.extend(data.iter().flat_map(|x| x.to_le_bytes()));
        b
    }

    fn open_bytes(bytes: Vec<u8>) -> Result<Pc2Frames<Cursor<Vec<u8>>>> {
        let len = bytes.len() as u64;
        Pc2Frames::new(Path::new("anim.pc2"), Cursor::new(bytes), len, 30.0)
    }

    #[test]
    fn reads_a_hand_made_file_with_frame_times() {
        let data: Vec<f32> = (0..12).map(|i| i as f32).collect();
        let mut pc2 = open_bytes(pc2_bytes(2, 10.0, 0.5, 2, &data)).unwrap();
        assert_eq!((pc2.vertex_count(), pc2.frame_count()), (2, 2));
        assert_eq!((pc2.time(0), pc2.time(1), pc2.sample_fps()), (10.0 / 30.0, 10.5 / 30.0, 60.0));
        let mut out = [[0.0; 3]; 2];
        pc2.read_frame(1, &mut out).unwrap();
        assert_eq!(out, [[6.0, 7.0, 8.0], [9.0, 10.0, 11.0]]);
    }

    #[test]
    fn round_trip_through_a_file() {
        let dir = scratch("pc2-roundtrip");
        let path = dir.join("wave.pc2");
        let mut frames = wave(7, 5, 24.0);
        write(&path, &mut frames, 24.0).unwrap();
        assert_eq!(std::fs::metadata(&path).unwrap().len(), 32 + 12 * 7 * 5);
        let mut back = open(&path, 24.0).unwrap();
        assert_frames_equal(&mut frames, &mut back, 1e-12);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn bad_headers_and_sizes_name_the_byte() {
        let data = vec![0.5f32; 12];
        let good = pc2_bytes(2, 0.0, 1.0, 2, &data);
        let cases: Vec<(Vec<u8>, &str)> = vec![
            (good[..20].to_vec(), "is 20 bytes, shorter than the 32-byte PC2 header (truncated at byte 20)"),
            (Vec::new(), "is 0 bytes, shorter than the 32-byte PC2 header"),
            (good[..40].to_vec(), "the header says 2 points (byte 16) x 2 samples (byte 28) = 80 bytes, but the file ends at byte 40, inside frame 0 (which starts at byte 32): truncated"),
            (good[..70].to_vec(), "ends at byte 70, inside frame 1 (which starts at byte 56): truncated"),
            ([good.clone(), vec![0; 5]].concat(), "has 5 more bytes after byte 80: the counts do not match the data"),
            (pc2_bytes(3, 0.0, 1.0, 2, &data), "the header says 3 points (byte 16) x 2 samples (byte 28) = 104 bytes, but the file ends at byte 80"),
            (pc2_bytes(-1, 0.0, 1.0, 2, &data), "point count -1 at byte 16"),
            (pc2_bytes(2, 0.0, 1.0, 0, &data), "sample count 0 at byte 28"),
            (pc2_bytes(2, f32::NAN, 1.0, 2, &data), "start frame NaN at byte 20"),
            (pc2_bytes(2, 0.0, 0.0, 2, &data), "sample rate 0 at byte 24"),
            (pc2_bytes(i32::MAX, 0.0, 1.0, i32::MAX, &data), "the header says 2147483647 points (byte 16) x 2147483647 samples (byte 28)"),
            ([b"POINTCACHE3\0".as_slice(), &good[12..]].concat(), "does not start with the PC2 signature"),
            ({
                let mut b = good.clone();
                b[12] = 2;
                b
            }, "PC2 version 2 at byte 12"),
        ];
        for (bytes, expected) in cases {
            let s = open_bytes(bytes).unwrap_err().to_string();
            assert!(
                s.starts_with("anim.pc2: ") && s.contains(expected) && s.contains(" (fix: ") && !s.contains('\n'),
                "expected {expected:?}, got {s}"
            );
        }
        let mut nan = data.clone();
        nan[10] = f32::INFINITY;
        let mut pc2 = open_bytes(pc2_bytes(2, 0.0, 1.0, 2, &nan)).unwrap();
        let mut out = [[0.0; 3]; 2];
        pc2.read_frame(0, &mut out).unwrap();
        let s = pc2.read_frame(1, &mut out).unwrap_err().to_string();
        assert!(s.contains("frame 1, vertex 1: coordinate y is inf (byte 72)"), "{s}");
    }

    #[test]
    fn a_file_that_shrinks_after_opening_is_an_error_not_a_panic() {
        let dir = scratch("pc2-shrink");
        let path = dir.join("a.pc2");
        let mut frames = wave(4, 3, 30.0);
        write(&path, &mut frames, 30.0).unwrap();
        let mut pc2 = open(&path, 30.0).unwrap();
        std::fs::OpenOptions::new().write(true).open(&path).unwrap().set_len(40).unwrap();
        let mut out = vec![[0.0; 3]; 4];
        let s = pc2.read_frame(2, &mut out).unwrap_err().to_string();
        assert!(s.contains("cannot read 48 bytes at byte 128"), "{s}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
