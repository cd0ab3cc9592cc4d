//! OBJ sequences: one OBJ file per frame, named by a pattern such as `frames/frame_####.obj`.
//!
//! The pattern's file name holds exactly one frame-number placeholder:
//! - a run of `#`: the number zero-padded to as many digits as there are `#` (`####`: 0007,
//!   0123, 12345); a number wider than the run is written in full, without leading zeros;
//!   one `#` is the plain number (7, 123);
//! - or printf's `%0Nd` (the same as N `#`) or `%d` (the same as `#`).
//!
//! Each number has exactly one spelling, so `frame_007.obj` does not match `frame_####.obj`
//! and no two files can claim the same frame. Negative frame numbers are not supported.
//!
//! Frame index 0 is the lowest number found in the folder; index `i` is that number plus `i`,
//! at time `number / fps`. Every number of the selected range must exist (a missing one is an
//! error naming its file), and every frame must have the first frame's vertex count and
//! faces. Frames are parsed with our own OBJ reader, which keeps the file's vertex order.

use std::path::{Path, PathBuf};

use super::binary::require_regular;
use super::{check_writable, FrameSource, MAX_FRAMES};
use crate::algorithms::frames::FrameRange;
use crate::algorithms::geometry::{Point, TriMesh};
use crate::formats::mesh::obj;
use crate::support::error::{Error, Result};
use crate::support::output::Staging;

/// A parsed sequence pattern: `dir/prefix<number>suffix`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SequencePattern {
    dir: PathBuf,
    prefix: String,
    suffix: String,
    /// Minimum digits (zero-padded); 1 for unpadded.
    width: usize,
}

/// The placeholder of a file name: (start, end, width), if any; `Err` when there are several.
fn placeholder(name: &str) -> std::result::Result<Option<(usize, usize, usize)>, String> {
    let bytes = name.as_bytes();
    let mut found = Vec::new();
    let mut i = 0;
    while i < bytes.len() {
        if bytes[i] == b'#' {
            let start = i;
            while i < bytes.len() && bytes[i] == b'#' {
                i += 1;
            }
            found.push((start, i, i - start));
            continue;
        }
        if bytes[i] == b'%' {
            // %d or %0Nd (N of one or two digits).
            let rest = &bytes[i + 1..];
            let digits = rest.iter().take_while(|b| b.is_ascii_digit()).count();
            if rest.get(digits) == Some(&b'd') {
                let spec = &name[i + 1..i + 1 + digits];
                let width = match spec {
                    "" => Some(1),
                    s if s.starts_with('0') && s.len() >= 2 && s.len() <= 3 => s[1..].parse::<usize>().ok().filter(|&w| w >= 1),
                    _ => None,
                };
                if let Some(width) = width {
                    found.push((i, i + 2 + digits, width));
                    i += 2 + digits;
                    continue;
                }
            }
        }
        i += 1;
    }
    match found.len() {
        0 => Ok(None),
        1 => Ok(Some(found[0])),
        n => Err(format!("has {n} frame-number placeholders in its file name; it needs exactly one")),
    }
}

impl SequencePattern {
    /// Whether `path` names a sequence (its file name has a placeholder) rather than one file.
    pub(crate) fn is_pattern(path: &Path) -> bool {
        path.file_name().and_then(|n| n.to_str()).is_some_and(|n| !matches!(placeholder(n), Ok(None)))
    }

    /// Parse a pattern; the problem on failure (the caller names the file).
    pub fn parse(path: &Path) -> std::result::Result<SequencePattern, String> {
        let name =
            path.file_name().and_then(|n| n.to_str()).ok_or_else(|| "has no file name in UTF-8 to hold the frame-number placeholder".to_string())?;
        let (start, end, width) = placeholder(name)?.ok_or_else(|| "has no frame-number placeholder (#### or %04d) in its file name".to_string())?;
        if width > 18 {
            return Err(format!("pads frame numbers to {width} digits; at most 18 are supported"));
        }
        let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
        Ok(SequencePattern { dir, prefix: name[..start].to_string(), suffix: name[end..].to_string(), width })
    }

    /// The file name of frame `number`.
    pub fn file_name(&self, number: u64) -> String {
        format!("{}{number:0width$}{}", self.prefix, self.suffix, width = self.width)
    }

    /// The file name with `digits` in the placeholder's place (fuzzing).
    #[cfg(test)]
    pub(crate) fn with_digits(&self, digits: &str) -> String {
        format!("{}{digits}{}", self.prefix, self.suffix)
    }

    /// The path of frame `number`.
    pub fn path(&self, number: u64) -> PathBuf {
        self.dir.join(self.file_name(number))
    }

    /// The folder the frames are in (`.` for a bare pattern).
    pub fn dir(&self) -> &Path {
        if self.dir.as_os_str().is_empty() {
            Path::new(".")
        } else {
            &self.dir
        }
    }

    /// The frame number a file name spells in this pattern, if it matches.
    pub(crate) fn number_of(&self, file_name: &str) -> Option<u64> {
        let digits = file_name.strip_prefix(&self.prefix)?.strip_suffix(&self.suffix)?;
        let canonical = digits.len() == self.width || (digits.len() > self.width && !digits.starts_with('0'));
        if digits.is_empty() || digits.len() > 19 || !canonical || !digits.bytes().all(|b| b.is_ascii_digit()) {
            return None;
        }
        digits.parse().ok()
    }

    /// The numbers of the matching files in the folder, sorted (an error when none matches).
    pub fn scan(&self, pattern: &Path) -> Result<Vec<u64>> {
        let entries = std::fs::read_dir(self.dir()).map_err(|e| Error::io(self.dir(), &e, "list the frames of the OBJ sequence"))?;
        let mut numbers = Vec::new();
        for entry in entries {
            let entry = entry.map_err(|e| Error::io(self.dir(), &e, "list the frames of the OBJ sequence"))?;
            if let Some(n) = entry.file_name().to_str().and_then(|n| self.number_of(n)) {
                numbers.push(n);
            }
        }
        if numbers.is_empty() {
            return Err(Error::in_file(
                pattern,
                format!("no file in {} matches the pattern {}", self.dir().display(), self.describe()),
                "check the folder and the pattern; #### matches exactly 4 digits (more only without leading zeros)",
            ));
        }
        numbers.sort_unstable();
        Ok(numbers)
    }

    /// `frame_####.obj (#### = the frame number zero-padded to 4 digits)`.
    fn describe(&self) -> String {
        let hashes = "#".repeat(self.width);
        match self.width {
            1 => format!("{}{hashes}{} (# = the frame number, unpadded)", self.prefix, self.suffix),
            w => format!("{}{hashes}{} ({hashes} = the frame number zero-padded to {w} digits)", self.prefix, self.suffix),
        }
    }
}

/// The frames of an OBJ sequence, parsed one file at a time.
#[derive(Debug)]
pub(crate) struct ObjSequence {
    pattern: SequencePattern,
    /// Frame number of index 0 of the selected range.
    first: u64,
    count: usize,
    fps: f64,
    vertices: usize,
    triangles: Vec<[u32; 3]>,
}

/// An opened sequence: the first selected frame's mesh, its frames, and their total bytes.
#[derive(Debug)]
pub(crate) struct OpenedSequence {
    pub mesh: TriMesh,
    pub frames: ObjSequence,
    pub bytes: u64,
}

/// Open the frames of `pattern` selected by `range`, at `fps` frames per second.
pub fn open(pattern: &Path, fps: f64, range: FrameRange) -> Result<OpenedSequence> {
    let parsed = SequencePattern::parse(pattern).map_err(|p| Error::in_file(pattern, p, "name the frames like frames/frame_####.obj"))?;
    if !parsed.suffix.to_ascii_lowercase().ends_with(".obj") {
        return Err(Error::in_file(pattern, "is a frame sequence of another format than OBJ", "export the sequence as OBJ files (frame_####.obj)"));
    }
    let numbers = parsed.scan(pattern)?;
    let (lowest, highest) = (numbers[0], numbers[numbers.len() - 1]);
    let available = usize::try_from(highest - lowest).ok().filter(|&n| n < MAX_FRAMES).map(|n| n + 1).ok_or_else(|| {
        Error::in_file(
            pattern,
            format!("frame numbers run from {lowest} to {highest}, more than {MAX_FRAMES} frames"),
            "remove stray files that match the pattern, or rename the sequence",
        )
    })?;
    let (start, count) = range.resolve(available).map_err(|(p, f)| Error::in_file(pattern, p, f))?;
    let first = lowest + start as u64;
    // The found numbers in the range must be exactly first, first + 1, ...
    let at = numbers.partition_point(|&n| n < first);
    if let Some(j) = (0..count).find(|&j| numbers.get(at + j) != Some(&(first + j as u64))) {
        let missing = first + j as u64;
        return Err(Error::in_file(
            parsed.path(missing),
            format!("frame {missing} of the OBJ sequence is missing (the folder has {} to {})", parsed.file_name(lowest), parsed.file_name(highest)),
            "re-export the missing frame, or choose a frame range (start, end) that avoids it",
        ));
    }
    let mut bytes = 0;
    for j in 0..count as u64 {
        bytes += require_regular(&parsed.path(first + j), "OBJ frame")?;
    }
    let first_path = parsed.path(first);
    let mesh = obj::read(&first_path)?;
    let frames = ObjSequence { pattern: parsed, first, count, fps, vertices: mesh.positions.len(), triangles: mesh.triangles.clone() };
    Ok(OpenedSequence { mesh, frames, bytes })
}

impl ObjSequence {
    /// The file of frame index `frame`.
    pub(crate) fn frame_path(&self, frame: usize) -> PathBuf {
        self.pattern.path(self.first + frame as u64)
    }
}

impl FrameSource for ObjSequence {
    fn vertex_count(&self) -> usize {
        self.vertices
    }

    fn frame_count(&self) -> usize {
        self.count
    }

    fn time(&self, frame: usize) -> f64 {
        (self.first + frame as u64) as f64 / self.fps
    }

    fn read_frame(&mut self, frame: usize, out: &mut [Point]) -> Result<()> {
        assert!(frame < self.count && out.len() == self.vertices, "frame and buffer match the cache");
        let path = self.frame_path(frame);
        require_regular(&path, "OBJ frame")?;
        let mesh = obj::read(&path)?;
        let first = self.pattern.file_name(self.first);
        let fix = "export every frame from the same mesh, with no modifier that changes vertices or faces";
        if mesh.positions.len() != self.vertices {
            return Err(Error::in_file(
                &path,
                format!("has {} vertices, but the first frame {first} has {}", mesh.positions.len(), self.vertices),
                fix,
            ));
        }
        if mesh.triangles.len() != self.triangles.len() {
            return Err(Error::in_file(
                &path,
                format!("has {} triangles (after fan triangulation), but the first frame {first} has {}", mesh.triangles.len(), self.triangles.len()),
                fix,
            ));
        }
        if let Some(t) = mesh.triangles.iter().zip(&self.triangles).position(|(a, b)| a != b) {
            let one_based = |t: [u32; 3]| t.map(|i| (i + 1).to_string()).join(" ");
            return Err(Error::in_file(
                &path,
                format!(
                    "triangle {t} (after fan triangulation) joins vertices {}, but in the first frame {first} it joins {}",
                    one_based(mesh.triangles[t]),
                    one_based(self.triangles[t])
                ),
                fix,
            ));
        }
        out.copy_from_slice(&mesh.positions);
        Ok(())
    }
}

/// Write `frames` as an OBJ sequence named by `pattern`, numbered from `round(time(0) * fps)`.
/// All files appear together (staged, then moved into the folder); a folder that already holds
/// frames of this pattern outside the new numbers is refused, so no stale frame can join the
/// sequence.
pub fn write(pattern: &Path, mesh: &TriMesh, frames: &mut dyn FrameSource, fps: f64) -> Result<()> {
    let parsed = SequencePattern::parse(pattern).map_err(|p| Error::in_file(pattern, p, "name the frames like frames/frame_####.obj"))?;
    let (vertices, count) = check_writable(pattern, frames, fps)?;
    if mesh.positions.len() != vertices {
        return Err(Error::general(
            format!("cannot write {}: the mesh has {} vertices but the frames have {vertices}", pattern.display(), mesh.positions.len()),
            "pass the mesh the frames belong to",
        ));
    }
    let start = (frames.time(0) * fps).round();
    if start < 0.0 {
        return Err(Error::in_file(
            pattern,
            format!("the first frame is at time {} s, a negative frame number", frames.time(0)),
            "shift the frames to start at time 0 or later",
        ));
    }
    let first = start as u64;
    let last = first + count as u64 - 1;
    if parsed.dir().is_dir() {
        let entries = std::fs::read_dir(parsed.dir()).map_err(|e| Error::io(parsed.dir(), &e, "list the output folder"))?;
        for entry in entries.flatten() {
            if let Some(n) = entry.file_name().to_str().and_then(|name| parsed.number_of(name)).filter(|n| !(first..=last).contains(n)) {
                return Err(Error::in_file(
                    parsed.path(n),
                    format!(
                        "is a frame of the same pattern outside the {count} frames being written ({} to {})",
                        parsed.file_name(first),
                        parsed.file_name(last)
                    ),
                    "remove the old sequence first, or write to another folder",
                ));
            }
        }
    }
    let mut staging = Staging::new(parsed.dir())?;
    let mut posed = TriMesh { positions: vec![[0.0; 3]; vertices], triangles: mesh.triangles.clone(), attributes: None };
    for i in 0..count {
        frames.read_frame(i, &mut posed.positions)?;
        staging.write(&parsed.file_name(first + i as u64), obj::write(&posed).as_bytes())?;
    }
    staging.commit()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::formats::cache::tests::{assert_frames_equal, scratch, wave, wave_mesh};

    fn pattern(s: &str) -> SequencePattern {
        SequencePattern::parse(Path::new(s)).unwrap()
    }

    #[test]
    fn placeholders_and_their_spellings() {
        let p = pattern("frames/frame_####.obj");
        assert_eq!(p.file_name(7), "frame_0007.obj");
        assert_eq!(p.file_name(12345), "frame_12345.obj");
        assert_eq!(p.path(7), Path::new("frames/frame_0007.obj"));
        assert_eq!(p.number_of("frame_0007.obj"), Some(7));
        assert_eq!(p.number_of("frame_12345.obj"), Some(12345));
        for other in [
            "frame_007.obj",
            "frame_00007.obj",
            "frame_01234.obj",
            "frame_00a7.obj",
            "frame_0007.obj.bak",
            "Frame_0007.obj",
            "frame_.obj",
            "frame_+007.obj",
        ] {
            assert_eq!(p.number_of(other), None, "{other}");
        }
        let plain = pattern("f#.obj");
        assert_eq!((plain.file_name(0), plain.file_name(42)), ("f0.obj".into(), "f42.obj".into()));
        assert_eq!((plain.number_of("f0.obj"), plain.number_of("f42.obj"), plain.number_of("f042.obj")), (Some(0), Some(42), None));
        assert_eq!(pattern("a_%04d.obj"), pattern("a_####.obj"));
        assert_eq!(pattern("a_%d.obj"), pattern("a_#.obj"));
        assert_eq!(pattern("100%_%03d.obj").file_name(5), "100%_005.obj", "a lone % is literal");
        assert!(SequencePattern::is_pattern(Path::new("x/f_##.obj")) && !SequencePattern::is_pattern(Path::new("x#/f.obj")));
        assert!(SequencePattern::parse(Path::new("a_##_##.obj")).unwrap_err().contains("has 2 frame-number placeholders"));
        assert!(SequencePattern::parse(Path::new("a.obj")).unwrap_err().contains("has no frame-number placeholder"));
        assert!(SequencePattern::parse(Path::new("a_%020d.obj")).unwrap_err().contains("at most 18"));
    }

    #[test]
    fn round_trip_with_a_range_and_numbering_from_time() {
        let dir = scratch("objseq-roundtrip");
        let pat = dir.join("out/frame_###.obj");
        let (mesh, mut frames) = (wave_mesh(4), wave(16, 6, 24.0));
        write(&pat, &mesh, &mut frames, 24.0).unwrap();
        assert!(dir.join("out/frame_000.obj").is_file() && dir.join("out/frame_005.obj").is_file());
        let mut opened = open(&pat, 24.0, FrameRange::ALL).unwrap();
        assert_eq!(opened.mesh.triangles, mesh.triangles);
        assert_eq!(opened.bytes, (0..6).map(|i| std::fs::metadata(dir.join(format!("out/frame_{i:03}.obj"))).unwrap().len()).sum::<u64>());
        assert_frames_equal(&mut frames, &mut opened.frames, 0.0);
        let sub = open(&pat, 24.0, FrameRange { start: 2, end: -2 }).unwrap();
        assert_eq!((sub.frames.frame_count(), sub.frames.time(0)), (3, 2.0 / 24.0));
        assert_eq!(sub.mesh.positions, frames.frames[2]);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn missing_frames_and_changed_topology_name_the_file() {
        let dir = scratch("objseq-bad");
        let pat = dir.join("f_####.obj");
        let (mesh, mut frames) = (wave_mesh(3), wave(9, 5, 30.0));
        write(&pat, &mesh, &mut frames, 30.0).unwrap();
        std::fs::remove_file(dir.join("f_0002.obj")).unwrap();
        let e = open(&pat, 30.0, FrameRange::ALL).unwrap_err().to_string();
        assert!(
            e.starts_with(&format!(
                "{}: frame 2 of the OBJ sequence is missing (the folder has f_0000.obj to f_0004.obj)",
                dir.join("f_0002.obj").display()
            )),
            "{e}"
        );
        assert!(e.contains("(fix: re-export the missing frame, or choose a frame range"), "{e}");
        // A range that avoids the gap opens.
        assert_eq!(open(&pat, 30.0, FrameRange { start: 3, end: -1 }).unwrap().frames.frame_count(), 2);

        let mut seq = open(&pat, 30.0, FrameRange { start: 3, end: 4 }).unwrap().frames;
        let mut out = vec![[0.0; 3]; 9];
        std::fs::write(dir.join("f_0004.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
        let e = seq.read_frame(1, &mut out).unwrap_err().to_string();
        assert!(e.contains("f_0004.obj: has 3 vertices, but the first frame f_0003.obj has 9"), "{e}");
        let mut text = obj::write(&TriMesh { positions: frames.frames[4].clone(), triangles: mesh.triangles.clone(), attributes: None });
        text = text.replacen("f 1 2 5", "f 1 5 2", 1);
        std::fs::write(dir.join("f_0004.obj"), text).unwrap();
        let e = seq.read_frame(1, &mut out).unwrap_err().to_string();
        assert!(e.contains("triangle 0 (after fan triangulation) joins vertices 1 5 2, but in the first frame f_0003.obj it joins 1 2 5"), "{e}");
        std::fs::write(dir.join("f_0004.obj"), "v 0 0 0\n").unwrap();
        let e = seq.read_frame(1, &mut out).unwrap_err().to_string();
        assert!(e.contains("f_0004.obj: has no faces"), "{e}");
        std::fs::remove_file(dir.join("f_0004.obj")).unwrap();
        let e = seq.read_frame(1, &mut out).unwrap_err().to_string();
        assert!(e.contains("f_0004.obj: cannot read the OBJ frame"), "{e}");

        let e = open(&dir.join("g_####.obj"), 30.0, FrameRange::ALL).unwrap_err().to_string();
        assert!(e.contains("no file in") && e.contains("matches the pattern g_####.obj (#### = the frame number zero-padded to 4 digits)"), "{e}");
        let e = write(&pat, &mesh, &mut wave(9, 2, 30.0), 30.0).unwrap_err().to_string();
        assert!(e.contains("f_0003.obj: is a frame of the same pattern outside the 2 frames being written (f_0000.obj to f_0001.obj)"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
