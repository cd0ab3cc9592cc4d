//! MDD point caches (LightWave's Motion Designer, Blender, Maya), big-endian:
//!
//! | byte | type | field |
//! |---|---|---|
//! | 0 | `i32` | frames `F` |
//! | 4 | `i32` | points per frame `P` |
//! | 8 | `f32[F]` | frame times in seconds |
//! | 8 + 4F | `f32[F][P][3]` | positions |
//!
//! Some exporters put one extra rest pose (`f32[P][3]`) before the frames; a file exactly
//! that much longer is read with the rest pose skipped. Any other size is an error, checked
//! before anything is allocated; a frame is read with one seek, so memory is one frame.
//!
//! The frame times are used when they are finite and strictly increasing; otherwise (some
//! exporters write zeros) the caller's frames per second number the frames from time 0.

use std::fs::File;
use std::io::{Read, Seek};
use std::path::{Path, PathBuf};

use super::binary::{decode_points, open_regular, read_exact_at, word, Endian};
use super::pc2::{size_mismatch, write_frames};
use super::{check_writable, rate_of, FrameSource};
use crate::algorithms::geometry::Point;
use crate::support::error::{Error, Result};

const FIX_DAMAGED: &str = "the file is truncated or its header does not match its data; re-export the cache";
const BE: Endian = Endian::Big;

/// Where an MDD file's frame times come from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum MddTimes {
    /// The file's own times (finite, strictly increasing), at this mean rate.
    File { fps: f64 },
    /// Frame `i` at `i / fps`: the file's times were unusable and the caller gave a rate.
    Caller { fps: f64 },
}

/// The frames of an MDD file, read on demand. `R` is a file, or any seekable bytes in tests.
#[derive(Debug)]
pub(crate) struct MddFrames<R = File> {
    path: PathBuf,
    reader: R,
    points: usize,
    /// Byte offset of frame 0 (after the times, and the rest pose when there is one).
    data_start: u64,
    times: Vec<f64>,
    rate: MddTimes,
    bytes: Vec<u8>,
}

/// Open an MDD file; `fps` numbers the frames when the file's times are unusable.
pub fn open(path: &Path, fps: Option<f64>) -> Result<MddFrames> {
    let (file, len) = open_regular(path, "MDD cache")?;
    MddFrames::new(path, file, len, fps)
}

impl<R: Read + Seek> MddFrames<R> {
    /// Read and check the header and times of `reader` (`len` bytes long).
    pub fn new(path: &Path, mut reader: R, len: u64, fps: Option<f64>) -> Result<Self> {
        let bad = |problem: String| Err(Error::in_file(path, problem, FIX_DAMAGED));
        if len < 8 {
            return bad(format!("is {len} bytes, shorter than the 8-byte MDD header (truncated at byte {len})"));
        }
        let mut header = [0u8; 8];
        read_exact_at(&mut reader, 0, &mut header, path)?;
        let (frames, points) = (BE.i32(word(&header, 0)), BE.i32(word(&header, 4)));
        if frames <= 0 {
            return bad(format!("frame count {frames} at byte 0 (must be positive; MDD is big-endian)"));
        }
        if points <= 0 {
            return bad(format!("point count {points} at byte 4 (must be positive; MDD is big-endian)"));
        }
        let (f, p) = (frames as u64, points as u64);
        let times_end = 8 + 4 * f;
        if len < times_end {
            return bad(format!(
                "the header says {frames} frames (byte 0), whose times end at byte {times_end}, but the file ends at byte {len}: truncated"
            ));
        }
        let frame_bytes = 12 * p;
        let expected = times_end as u128 + frame_bytes as u128 * f as u128;
        let data_start = if len as u128 == expected {
            times_end
        } else if len as u128 == expected + frame_bytes as u128 {
            times_end + frame_bytes
        } else {
            return bad(size_mismatch(len, expected, times_end, frame_bytes, &format!("{frames} frames (byte 0) x {points} points (byte 4)")));
        };
        // Bounded by the file size, checked above.
        let mut raw = vec![0u8; 4 * frames as usize];
        read_exact_at(&mut reader, 8, &mut raw, path)?;
        let file_times: Vec<f64> = raw.chunks_exact(4).map(|c| BE.f32(word(c, 0)) as f64).collect();
        let unusable = file_times.iter().position(|t| !t.is_finite()).or_else(|| file_times.windows(2).position(|w| w[1] <= w[0]).map(|i| i + 1));
        let (times, rate) = match (unusable, fps) {
            (None, _) if file_times.len() >= 2 => {
                let fps = rate_of(&file_times).expect("increasing times have a rate");
                (file_times, MddTimes::File { fps })
            }
            (_, Some(fps)) => ((0..frames as usize).map(|i| i as f64 / fps).collect(), MddTimes::Caller { fps }),
            (Some(i), None) => {
                return Err(Error::in_file(
                    path,
                    match i {
                        0 => format!("frame time 0 (byte 8) is {}: the frame times are not finite and increasing", file_times[0]),
                        _ => format!(
                            "frame time {i} (byte {}) is {}, after {}: the frame times are not finite and increasing",
                            8 + 4 * i,
                            file_times[i],
                            file_times[i - 1]
                        ),
                    },
                    "give the cache's fps (frames per second); the frames are then numbered from time 0",
                ))
            }
            (None, None) => {
                return Err(Error::in_file(path, "holds a single frame, so its frame rate is unknown", "give the cache's fps (frames per second)"));
            }
        };
        Ok(MddFrames { path: path.to_path_buf(), reader, points: points as usize, data_start, times, rate, bytes: Vec::new() })
    }

    /// Where the frame times come from, and the rate.
    pub fn rate(&self) -> MddTimes {
        self.rate
    }

    /// Whether the file has a rest pose before the frames (skipped).
    #[cfg(test)]
    pub(crate) fn has_rest_pose(&self) -> bool {
        self.data_start > 8 + 4 * self.times.len() as u64
    }
}

impl<R: Read + Seek> FrameSource for MddFrames<R> {
    fn vertex_count(&self) -> usize {
        self.points
    }

    fn frame_count(&self) -> usize {
        self.times.len()
    }

    fn time(&self, frame: usize) -> f64 {
        self.times[frame]
    }

    fn read_frame(&mut self, frame: usize, out: &mut [Point]) -> Result<()> {
        assert!(frame < self.times.len() && out.len() == self.points, "frame and buffer match the cache");
        let frame_bytes = 12 * self.points;
        let offset = self.data_start + (frame_bytes as u64) * frame as u64;
        self.bytes.resize(frame_bytes, 0);
        read_exact_at(&mut self.reader, offset, &mut self.bytes, &self.path)?;
        decode_points(&self.bytes, BE, out, frame, offset, &self.path)
    }
}

/// Write `frames` as MDD with their own times (as f32 seconds), streamed to a temporary file
/// and renamed into place.
pub fn write(path: &Path, frames: &mut dyn FrameSource, fps: f64) -> Result<()> {
    let (points, count) = check_writable(path, frames, fps)?;
    let mut head = Vec::with_capacity(8 + 4 * count);
    head.extend_from_slice(&(count as i32).to_be_bytes());
    head.extend_from_slice(&(points as i32).to_be_bytes());
    for i in 0..count {
        head.extend_from_slice(&(frames.time(i) as f32).to_be_bytes());
    }
    write_frames(path, &head, frames, BE)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::formats::cache::tests::{assert_frames_equal, scratch, wave};
    use std::io::Cursor;

    fn mdd_bytes(frames: i32, points: i32, times: &[f32], data: &[f32]) -> Vec<u8> {
        let mut b = [frames.to_be_bytes(), points.to_be_bytes()].concat();
        b.extend(times.iter().chain(data).flat_map(|x| x.to_be_bytes()));
        b
    }

    fn open_bytes(bytes: Vec<u8>, fps: Option<f64>) -> Result<MddFrames<Cursor<Vec<u8>>>> {
        let len = bytes.len() as u64;
        MddFrames::new(Path::new("anim.mdd"), Cursor::new(bytes), len, fps)
    }

    #[test]
    fn file_times_win_and_zero_times_need_the_callers_fps() {
        let data: Vec<f32> = (0..18).map(|i| i as f32).collect();
        let mut mdd = open_bytes(mdd_bytes(3, 2, &[0.0, 1.0 / 24.0, 2.0 / 24.0], &data), Some(60.0)).unwrap();
        assert_eq!(mdd.rate(), MddTimes::File { fps: 24.0 });
        assert_eq!(mdd.time(1), (1.0f32 / 24.0) as f64);
        let mut out = [[0.0; 3]; 2];
        mdd.read_frame(2, &mut out).unwrap();
        assert_eq!(out, [[12.0, 13.0, 14.0], [15.0, 16.0, 17.0]]);

        let zeros = mdd_bytes(3, 2, &[0.0; 3], &data);
        let mdd = open_bytes(zeros.clone(), Some(50.0)).unwrap();
        assert_eq!((mdd.rate(), mdd.time(2)), (MddTimes::Caller { fps: 50.0 }, 0.04));
        let s = open_bytes(zeros, None).unwrap_err().to_string();
        assert!(
            s.starts_with("anim.mdd: frame time 1 (byte 12) is 0, after 0: the frame times are not finite and increasing (fix: give the cache's fps"),
            "{s}"
        );
    }

    #[test]
    fn a_leading_rest_pose_is_skipped() {
        let rest = [9.0f32; 6];
        let data: Vec<f32> = (0..12).map(|i| i as f32).collect();
        let mut mdd = open_bytes(mdd_bytes(2, 2, &[0.0, 0.5], &[&rest[..], &data].concat()), None).unwrap();
        assert!(mdd.has_rest_pose());
        let mut out = [[0.0; 3]; 2];
        mdd.read_frame(0, &mut out).unwrap();
        assert_eq!(out, [[0.0, 1.0, 2.0], [3.0, 4.0, 5.0]]);
    }

    #[test]
    fn round_trip_through_a_file() {
        let dir = scratch("mdd-roundtrip");
        let path = dir.join("wave.mdd");
        let mut frames = wave(9, 6, 30.0);
        write(&path, &mut frames, 30.0).unwrap();
        assert_eq!(std::fs::metadata(&path).unwrap().len(), 8 + 4 * 6 + 12 * 9 * 6);
        let mut back = open(&path, None).unwrap();
        assert_eq!(back.rate(), MddTimes::File { fps: 30.0 });
        assert_frames_equal(&mut frames, &mut back, 1e-6);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn bad_headers_and_sizes_name_the_byte() {
        let data = vec![0.5f32; 12];
        let good = mdd_bytes(2, 2, &[0.0, 0.1], &data);
        let cases: Vec<(Vec<u8>, &str)> = vec![
            (good[..5].to_vec(), "is 5 bytes, shorter than the 8-byte MDD header (truncated at byte 5)"),
            (good[..12].to_vec(), "the header says 2 frames (byte 0), whose times end at byte 16, but the file ends at byte 12: truncated"),
            (good[..30].to_vec(), "the header says 2 frames (byte 0) x 2 points (byte 4) = 64 bytes, but the file ends at byte 30, inside frame 0 (which starts at byte 16): truncated"),
            (good[..50].to_vec(), "ends at byte 50, inside frame 1 (which starts at byte 40): truncated"),
            ([good.clone(), vec![0; 4]].concat(), "has 4 more bytes after byte 64: the counts do not match the data"),
            (mdd_bytes(0, 2, &[], &[]), "frame count 0 at byte 0 (must be positive; MDD is big-endian)"),
            (mdd_bytes(2, -7, &[0.0, 0.1], &data), "point count -7 at byte 4"),
            (mdd_bytes(i32::MAX, i32::MAX, &[0.0, 0.1], &data), "the header says 2147483647 frames (byte 0), whose times end at byte 8589934596"),
            // A little-endian header read as big-endian: an absurd count, caught by the size.
            ([2i32.to_le_bytes(), 2i32.to_le_bytes()].concat(), "the header says 33554432 frames (byte 0)"),
        ];
        for (bytes, expected) in cases {
            let s = open_bytes(bytes, Some(30.0)).unwrap_err().to_string();
            assert!(
                s.starts_with("anim.mdd: ") && s.contains(expected) && s.contains(" (fix: ") && !s.contains('\n'),
                "expected {expected:?}, got {s}"
            );
        }
        let s = open_bytes(mdd_bytes(1, 2, &[0.0], &data[..6]), None).unwrap_err().to_string();
        assert!(s.contains("holds a single frame, so its frame rate is unknown"), "{s}");
    }
}
