//! [`VertexCache`]: one opened cache of any format, and [`write`] for every format.

use std::path::{Path, PathBuf};

use super::sequence::SequencePattern;
use super::{abc, fbx, gltf_clip, mdd, pc2, sequence, usd, FrameSource};
use crate::algorithms::frames::{FrameRange, Subrange};
use crate::algorithms::geometry::TriMesh;
use crate::formats::mesh::obj;
use crate::support::budget::Budget;
use crate::support::error::{Error, Result};

/// The file formats of vertex caches.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum CacheFormat {
    /// `frames/frame_####.obj`: one OBJ file per frame.
    ObjSequence,
    /// `.pc2`: Blender's and 3ds Max's point cache (little-endian, `POINTCACHE2`).
    Pc2,
    /// `.mdd`: LightWave's motion designer cache (big-endian, with frame times).
    Mdd,
    /// `.glb` or `.gltf`: a morph and/or skinned clip.
    Gltf,
    /// `.usd`, `.usda`, `.usdc`: `points` time samples of a Mesh prim.
    Usd,
    /// `.abc` (Ogawa): the points of a PolyMesh or SubD, its transforms applied (read only).
    Alembic,
    /// `.fbx`: a mesh deformed by skinning and blend shapes over an animation stack (read only).
    Fbx,
}

impl CacheFormat {
    /// The format a path names: a frame-number placeholder makes an OBJ sequence, otherwise
    /// the extension decides.
    pub fn of(path: &Path) -> Option<CacheFormat> {
        if SequencePattern::is_pattern(path) {
            return Some(CacheFormat::ObjSequence);
        }
        let ext = path.extension()?.to_str()?.to_ascii_lowercase();
        Some(match ext.as_str() {
            "pc2" => CacheFormat::Pc2,
            "mdd" => CacheFormat::Mdd,
            "glb" | "gltf" => CacheFormat::Gltf,
            "usd" | "usda" | "usdc" => CacheFormat::Usd,
            "abc" => CacheFormat::Alembic,
            "fbx" => CacheFormat::Fbx,
            _ => return None,
        })
    }

    /// The format with its article, for messages: "an OBJ sequence", "a PC2 cache", ...
    pub(crate) fn described(self) -> &'static str {
        match self {
            CacheFormat::ObjSequence => "an OBJ sequence",
            CacheFormat::Pc2 => "a PC2 cache",
            CacheFormat::Mdd => "an MDD cache",
            CacheFormat::Gltf => "a glTF clip",
            CacheFormat::Usd => "a USD point cache",
            CacheFormat::Alembic => "an Alembic cache",
            CacheFormat::Fbx => "an FBX animation",
        }
    }

    /// The name used in reports: `obj-sequence`, `pc2`, `mdd`, `gltf`, `usd`, `alembic`, `fbx`.
    pub fn name(self) -> &'static str {
        match self {
            CacheFormat::ObjSequence => "obj-sequence",
            CacheFormat::Pc2 => "pc2",
            CacheFormat::Mdd => "mdd",
            CacheFormat::Gltf => "gltf",
            CacheFormat::Usd => "usd",
            CacheFormat::Alembic => "alembic",
            CacheFormat::Fbx => "fbx",
        }
    }
}

/// What only the caller (the scene) knows about a cache. Each field applies to some formats;
/// giving one to a format that does not use it is an error, so nothing is silently ignored.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct CacheOptions {
    /// Frames per second: required for OBJ sequences and PC2 (which counts frames, not
    /// seconds); used by MDD when its frame times are unusable; the sampling rate of a glTF
    /// clip (default: the rate of its evenly spaced keys). USD uses the stage's rate.
    pub fps: Option<f64>,
    /// The mesh a PC2 or MDD cache animates (OBJ: topology and UVs), required for them.
    pub rest: Option<PathBuf>,
    /// The glTF animation to evaluate (default: the only one).
    pub animation: Option<String>,
    /// The USD Mesh prim (default: the only Mesh, or the only animated one).
    pub prim: Option<String>,
    /// The Alembic or FBX mesh object (default: the only mesh, or the only animated one).
    pub object: Option<String>,
    /// The FBX animation stack (default: the only one).
    pub take: Option<String>,
    /// Metres per unit to convert an FBX file's lengths to (default: metres); the scene's units.
    pub meters_per_unit: Option<f64>,
    /// The frames to read.
    pub range: FrameRange,
    /// `--max-time`: bounds the USD and Alembic readers' processes (killed at the deadline).
    pub budget: Budget,
}

/// Where a cache's frame rate came from.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum FpsSource {
    /// The file: what in it (e.g. "the stage's timeCodesPerSecond").
    File(String),
    /// The caller's `fps` (the file has no rate, or its times were unusable).
    Caller,
}

/// An opened vertex cache: topology, streamed frames, and what the report says about it.
///
/// Invariants: `mesh.positions.len() == frames.vertex_count()`; every triangle indexes
/// `mesh.positions`; `frames.frame_count() >= 1`.
pub struct VertexCache {
    /// The format the path named.
    pub format: CacheFormat,
    /// The path as given (the pattern, for an OBJ sequence).
    pub path: PathBuf,
    /// Triangles (polygons fan-triangulated in vertex order) and positions: the `rest` mesh's
    /// when one was given (PC2, MDD), otherwise the first frame of the range.
    pub mesh: TriMesh,
    /// The frames, streamed from the file.
    pub frames: Box<dyn FrameSource + Send>,
    /// Frames per second of the cache (samples per second).
    pub fps: f64,
    /// Where `fps` came from: the file, or the caller.
    pub fps_source: FpsSource,
    /// Bytes of the input: every frame file of a sequence, a glTF's external buffers.
    pub bytes: u64,
    /// The length unit the file states, in meters: a glTF's (always meters), a USD stage's
    /// authored `metersPerUnit`; `None` for formats that carry none (OBJ, PC2, MDD) and a USD
    /// stage without the metadata.
    pub meters_per_unit: Option<f64>,
}

impl std::fmt::Debug for VertexCache {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("VertexCache")
            .field("format", &self.format)
            .field("path", &self.path)
            .field("vertices", &self.mesh.positions.len())
            .field("triangles", &self.mesh.triangles.len())
            .field("frames", &self.frames.frame_count())
            .field("fps", &self.fps)
            .field("fps_source", &self.fps_source)
            .field("bytes", &self.bytes)
            .finish()
    }
}

fn unused(path: &Path, format: CacheFormat, field: &str, used_by: &str) -> Error {
    Error::in_file(
        path,
        format!("`{field}` was given, but {} does not use it ({used_by})", format.described()),
        format!("remove `{field}` from the scene's [cache] or [keyframes] table"),
    )
}

/// The rest mesh of a PC2 / MDD cache, matched against its point count.
fn rest_mesh(path: &Path, rest: Option<&Path>, points: usize, format: CacheFormat) -> Result<TriMesh> {
    let Some(rest) = rest else {
        return Err(Error::in_file(
            path,
            format!("{} holds positions only, so its triangles must come from the mesh it animates", format.described()),
            "give rest = \"mesh.obj\", the mesh the cache was baked from",
        ));
    };
    super::binary::require_regular(rest, "rest mesh")?;
    let mesh = obj::read(rest)?;
    if mesh.positions.len() != points {
        return Err(Error::in_file(
            rest,
            format!("has {} vertices, but {} has {points} points per frame", mesh.positions.len(), path.display()),
            "give the mesh the cache was baked from, exported with the same vertex order (no welding or splitting)",
        ));
    }
    Ok(mesh)
}

fn subrange<S: FrameSource + Send + 'static>(path: &Path, frames: S, range: FrameRange) -> Result<Box<dyn FrameSource + Send>> {
    let (first, count) = range.resolve(frames.frame_count()).map_err(|(p, f)| Error::in_file(path, p, f))?;
    if frames.frame_count() > super::MAX_FRAMES {
        return Err(Error::in_file(
            path,
            format!("holds {} frames, more than {}", frames.frame_count(), super::MAX_FRAMES),
            "split the cache, or choose a frame range",
        ));
    }
    Ok(Box::new(Subrange::new(frames, first, count)))
}

impl VertexCache {
    /// Open a cache, choosing the reader by [`CacheFormat::of`].
    pub fn open(path: &Path, options: &CacheOptions) -> Result<VertexCache> {
        let format = CacheFormat::of(path).ok_or_else(|| {
            Error::in_file(
                path,
                "is not a vertex cache format blendsim reads",
                "give an OBJ sequence (frames/frame_####.obj), .pc2, .mdd, .glb/.gltf, .usd/.usda/.usdc, .abc or .fbx",
            )
        })?;
        if let Some(fps) = options.fps {
            if !(fps.is_finite() && fps > 0.0) {
                return Err(Error::in_file(path, format!("fps {fps} is not a positive number"), "give the cache's frames per second, e.g. fps = 60"));
            }
        }
        let uses_rest = matches!(format, CacheFormat::Pc2 | CacheFormat::Mdd);
        if options.rest.is_some() && !uses_rest {
            return Err(unused(path, format, "rest", "its file carries its own topology"));
        }
        if options.animation.is_some() && format != CacheFormat::Gltf {
            return Err(unused(path, format, "animation", "only glTF clips have named animations"));
        }
        if options.prim.is_some() && format != CacheFormat::Usd {
            return Err(unused(path, format, "prim", "only USD stages have prims"));
        }
        if options.object.is_some() && !matches!(format, CacheFormat::Alembic | CacheFormat::Fbx) {
            return Err(unused(path, format, "object", "only Alembic and FBX files name their meshes so"));
        }
        if options.take.is_some() && format != CacheFormat::Fbx {
            return Err(unused(path, format, "take", "only FBX files have takes"));
        }
        let need_fps = |why: &str| {
            options.fps.ok_or_else(|| {
                Error::in_file(path, format!("{} needs a frame rate: {why}", format.described()), "give the cache's fps (frames per second)")
            })
        };
        let path_buf = path.to_path_buf();
        let cache = match format {
            CacheFormat::ObjSequence => {
                let fps = need_fps("OBJ files carry no time")?;
                let opened = sequence::open(path, fps, options.range)?;
                VertexCache {
                    format,
                    path: path_buf,
                    mesh: opened.mesh,
                    frames: Box::new(opened.frames),
                    fps,
                    fps_source: FpsSource::Caller,
                    bytes: opened.bytes,
                    meters_per_unit: None,
                }
            }
            CacheFormat::Pc2 => {
                let fps = need_fps("PC2 numbers its samples in frames, not seconds")?;
                let frames = pc2::open(path, fps)?;
                let mesh = rest_mesh(path, options.rest.as_deref(), frames.vertex_count(), format)?;
                let sample_fps = frames.sample_fps();
                let bytes = std::fs::metadata(path).map_err(|e| Error::io(path, &e, "measure the cache"))?.len();
                VertexCache {
                    format,
                    path: path_buf,
                    mesh,
                    frames: subrange(path, frames, options.range)?,
                    fps: sample_fps,
                    fps_source: FpsSource::Caller,
                    bytes,
                    meters_per_unit: None,
                }
            }
            CacheFormat::Mdd => {
                let frames = mdd::open(path, options.fps)?;
                let mesh = rest_mesh(path, options.rest.as_deref(), frames.vertex_count(), format)?;
                let (fps, fps_source) = match frames.rate() {
                    mdd::MddTimes::File { fps } => (fps, FpsSource::File("the MDD frame times".into())),
                    mdd::MddTimes::Caller { fps } => (fps, FpsSource::Caller),
                };
                let bytes = std::fs::metadata(path).map_err(|e| Error::io(path, &e, "measure the cache"))?.len();
                VertexCache {
                    format,
                    path: path_buf,
                    mesh,
                    frames: subrange(path, frames, options.range)?,
                    fps,
                    fps_source,
                    bytes,
                    meters_per_unit: None,
                }
            }
            CacheFormat::Gltf => {
                let opened = gltf_clip::open(path, options.animation.as_deref(), options.fps)?;
                let fps_source =
                    if opened.fps_from_keys { FpsSource::File("the spacing of the glTF animation's keys".into()) } else { FpsSource::Caller };
                let frames = subrange(path, opened.frames, options.range)?;
                // glTF's unit is the meter (glTF 2.0, "Coordinate System and Units").
                let mut cache = VertexCache {
                    format,
                    path: path_buf,
                    mesh: opened.mesh,
                    frames,
                    fps: opened.fps,
                    fps_source,
                    bytes: opened.bytes,
                    meters_per_unit: Some(1.0),
                };
                if options.range != FrameRange::ALL {
                    // The mesh is the first frame of the range.
                    cache.frames.read_frame(0, &mut cache.mesh.positions)?;
                }
                cache
            }
            CacheFormat::Usd => {
                let opened = usd::open(path, options.prim.as_deref(), options.range, &options.budget)?;
                let fps_source = FpsSource::File(format!("the stage's timeCodesPerSecond (prim {})", opened.prim));
                VertexCache {
                    format,
                    path: path_buf,
                    mesh: opened.mesh,
                    frames: Box::new(opened.frames),
                    fps: opened.fps,
                    fps_source,
                    bytes: opened.bytes,
                    meters_per_unit: opened.meters_per_unit,
                }
            }
            CacheFormat::Alembic => {
                let opened = abc::open(path, options.object.as_deref(), options.range, &options.budget)?;
                let fps_source = FpsSource::File(format!("the sample times of {}", opened.object));
                let (mesh, frames) = (opened.mesh, Box::new(opened.frames));
                // Alembic states no unit.
                VertexCache { format, path: path_buf, mesh, frames, fps: opened.fps, fps_source, bytes: opened.bytes, meters_per_unit: None }
            }
            CacheFormat::Fbx => {
                let choice =
                    fbx::FbxChoice { object: options.object.as_deref(), take: options.take.as_deref(), meters_per_unit: options.meters_per_unit };
                let opened = fbx::open(path, &choice)?;
                let fps_source = FpsSource::File(format!(
                    "the frame rate of take \"{}\" (mesh \"{}\", {} m per unit in the file)",
                    opened.take, opened.object, opened.file_meters_per_unit
                ));
                let frames = subrange(path, opened.frames, options.range)?;
                // The reader converted the file's lengths to the scene's units, or to metres.
                let meters_per_unit = Some(options.meters_per_unit.unwrap_or(1.0));
                let mut cache = VertexCache {
                    format,
                    path: path_buf,
                    mesh: opened.mesh,
                    frames,
                    fps: opened.fps,
                    fps_source,
                    bytes: opened.bytes,
                    meters_per_unit,
                };
                if options.range != FrameRange::ALL {
                    // The mesh is the first frame of the range.
                    cache.frames.read_frame(0, &mut cache.mesh.positions)?;
                }
                cache
            }
        };
        Ok(cache)
    }

    /// Frames in the (range of the) cache.
    pub fn frame_count(&self) -> usize {
        self.frames.frame_count()
    }

    /// One line for the user: the rate and where it came from, e.g.
    /// `60 fps (from the file: the stage's timeCodesPerSecond (prim /Root/Mesh))`.
    pub(crate) fn fps_note(&self) -> String {
        match &self.fps_source {
            FpsSource::File(what) => format!("{} fps (from the file: {what})", self.fps),
            FpsSource::Caller => format!("{} fps (given by the scene)", self.fps),
        }
    }
}

/// Write `frames` of `mesh` at `fps` in the format `path` names ([`CacheFormat::of`]):
/// an OBJ sequence, `.pc2`, `.mdd`, `.glb` (a morph clip; `.gltf` is not written), `.usda`,
/// `.usdc` or `.usd`. Every writer streams frame by frame and leaves nothing behind on error.
pub fn write(path: &Path, mesh: &TriMesh, frames: &mut dyn FrameSource, fps: f64) -> Result<()> {
    if mesh.positions.len() != frames.vertex_count() {
        return Err(Error::general(
            format!("cannot write {}: the mesh has {} vertices, the frames {}", path.display(), mesh.positions.len(), frames.vertex_count()),
            "pass the mesh the frames belong to",
        ));
    }
    let gltf_text = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("gltf"));
    match CacheFormat::of(path) {
        Some(CacheFormat::ObjSequence) => sequence::write(path, mesh, frames, fps),
        Some(CacheFormat::Pc2) => pc2::write(path, frames, fps),
        Some(CacheFormat::Mdd) => mdd::write(path, frames, fps),
        Some(CacheFormat::Gltf) if !gltf_text => gltf_clip::write(path, mesh, frames, fps),
        Some(CacheFormat::Usd) => usd::write(path, mesh, frames, fps),
        // Alembic and FBX are read only.
        _ => Err(Error::in_file(
            path,
            "is not a vertex cache format blendsim writes",
            "name the output frames/frame_####.obj, .pc2, .mdd, .glb, .usda, .usdc or .usd",
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::formats::cache::tests::{assert_frames_equal, scratch, wave, wave_mesh};

    fn options(fps: Option<f64>, rest: Option<&Path>) -> CacheOptions {
        CacheOptions { fps, rest: rest.map(Path::to_path_buf), ..CacheOptions::default() }
    }

    #[test]
    fn every_format_round_trips_through_write_and_open() {
        let dir = scratch("vc-roundtrip");
        let (mesh, mut frames) = (wave_mesh(4), wave(16, 6, 24.0));
        let rest = dir.join("rest.obj");
        std::fs::write(&rest, obj::write(&mesh)).unwrap();
        let file = FpsSource::File;
        let cases: Vec<(&str, CacheOptions, CacheFormat, FpsSource)> = vec![
            ("seq/f_####.obj", options(Some(24.0), None), CacheFormat::ObjSequence, FpsSource::Caller),
            ("a.pc2", options(Some(24.0), Some(&rest)), CacheFormat::Pc2, FpsSource::Caller),
            ("a.mdd", options(None, Some(&rest)), CacheFormat::Mdd, file("the MDD frame times".into())),
            ("a.glb", options(None, None), CacheFormat::Gltf, file("the spacing of the glTF animation's keys".into())),
            ("a.usda", options(Some(60.0), None), CacheFormat::Usd, file("the stage's timeCodesPerSecond (prim /a/Mesh)".into())),
            ("b.usdc", options(None, None), CacheFormat::Usd, file("the stage's timeCodesPerSecond (prim /b/Mesh)".into())),
            ("c.usd", options(None, None), CacheFormat::Usd, file("the stage's timeCodesPerSecond (prim /c/Mesh)".into())),
        ];
        for (name, options, format, source) in cases {
            let path = dir.join(name);
            write(&path, &mesh, &mut frames, 24.0).unwrap_or_else(|e| panic!("{name}: {e}"));
            let mut cache = VertexCache::open(&path, &options).unwrap_or_else(|e| panic!("{name}: {e}"));
            assert_eq!((cache.format, cache.fps, &cache.fps_source), (format, 24.0, &source), "{name}");
            assert_eq!(cache.mesh.triangles, mesh.triangles, "{name}");
            let first = if options.rest.is_some() { &mesh.positions } else { &frames.frames[0] };
            assert!(cache.mesh.positions.iter().zip(first).all(|(a, b)| (0..3).all(|d| (a[d] - b[d]).abs() < 1e-6)), "{name}");
            if format != CacheFormat::ObjSequence {
                assert_eq!(cache.bytes, std::fs::metadata(&path).unwrap().len(), "{name}");
            }
            assert_frames_equal(&mut frames, cache.frames.as_mut(), 1e-6);
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_range_selects_frames_and_the_mesh_is_its_first_frame() {
        let dir = scratch("vc-range");
        let (mesh, mut frames) = (wave_mesh(3), wave(9, 8, 30.0));
        let range = FrameRange { start: 2, end: -3 };
        for name in ["a.glb", "a.mdd"] {
            let path = dir.join(name);
            write(&path, &mesh, &mut frames, 30.0).unwrap();
            let rest = dir.join("rest.obj");
            std::fs::write(&rest, obj::write(&mesh)).unwrap();
            let opts = CacheOptions { range, rest: name.ends_with(".mdd").then_some(rest), ..CacheOptions::default() };
            let mut cache = VertexCache::open(&path, &opts).unwrap();
            assert_eq!(cache.frame_count(), 4, "{name}");
            assert!((cache.frames.time(0) - 2.0 / 30.0).abs() < 1e-7, "{name}: glTF keys are f32");
            if name.ends_with(".glb") {
                assert!(cache.mesh.positions.iter().zip(&frames.frames[2]).all(|(a, b)| (0..3).all(|d| (a[d] - b[d]).abs() < 1e-6)));
            }
            let mut out = vec![[0.0; 3]; 9];
            cache.frames.read_frame(3, &mut out).unwrap();
            assert!(out.iter().zip(&frames.frames[5]).all(|(a, b)| (0..3).all(|d| (a[d] - b[d]).abs() < 1e-6)), "{name}");
            let bad = CacheOptions { range: FrameRange { start: 6, end: 3 }, ..opts };
            let s = VertexCache::open(&path, &bad).unwrap_err().to_string();
            assert!(s.contains("frame range start = 6, end = 3 selects no frames of the 8 the cache holds"), "{s}");
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn missing_and_misplaced_options_are_errors() {
        let dir = scratch("vc-options");
        let (mesh, mut frames) = (wave_mesh(3), wave(9, 3, 30.0));
        let (pc2, glb) = (dir.join("a.pc2"), dir.join("a.glb"));
        write(&pc2, &mesh, &mut frames, 30.0).unwrap();
        write(&glb, &mesh, &mut frames, 30.0).unwrap();
        let small = dir.join("small.obj");
        std::fs::write(&small, obj::write(&wave_mesh(2))).unwrap();
        let err = |path: &Path, o: CacheOptions| {
            let s = VertexCache::open(path, &o).unwrap_err().to_string();
            assert!(s.contains(" (fix: ") && !s.contains('\n'), "{s}");
            s
        };
        assert!(err(&pc2, options(Some(30.0), None))
            .contains("a PC2 cache holds positions only, so its triangles must come from the mesh it animates (fix: give rest = "));
        assert!(err(&pc2, options(None, Some(&small))).contains("a PC2 cache needs a frame rate: PC2 numbers its samples in frames, not seconds"));
        let s = err(&pc2, options(Some(30.0), Some(&small)));
        assert!(s.starts_with(&format!("{}: has 4 vertices, but {} has 9 points per frame", small.display(), pc2.display())), "{s}");
        assert!(err(&glb, options(None, Some(&small))).contains("`rest` was given, but a glTF clip does not use it"));
        assert!(err(&pc2, CacheOptions { animation: Some("x".into()), ..options(Some(30.0), Some(&small)) })
            .contains("`animation` was given, but a PC2 cache"));
        assert!(err(&glb, CacheOptions { prim: Some("/x".into()), ..CacheOptions::default() }).contains("`prim` was given, but a glTF clip"));
        assert!(err(&glb, options(Some(-1.0), None)).contains("fps -1 is not a positive number"));
        assert!(err(&dir.join("a.ma"), CacheOptions::default()).contains("is not a vertex cache format blendsim reads"));
        assert!(err(&glb, CacheOptions { object: Some("Body".into()), ..CacheOptions::default() }).contains("`object` was given, but a glTF clip"));
        assert!(err(&glb, CacheOptions { take: Some("Walk".into()), ..CacheOptions::default() }).contains("`take` was given, but a glTF clip"));
        assert!(err(&dir.join("f_####.obj"), CacheOptions::default()).contains("an OBJ sequence needs a frame rate"));
        let s = write(&dir.join("a.gltf"), &mesh, &mut frames, 30.0).unwrap_err().to_string();
        assert!(s.contains("is not a vertex cache format blendsim writes"), "{s}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_fifo_as_input_is_refused_for_every_format() {
        let dir = scratch("vc-fifo");
        let (mesh, mut frames) = (wave_mesh(2), wave(4, 2, 30.0));
        let rest = dir.join("rest.obj");
        std::fs::write(&rest, obj::write(&mesh)).unwrap();
        let pc2 = dir.join("ok.pc2");
        write(&pc2, &mesh, &mut frames, 30.0).unwrap();
        let fifo = |name: &str| {
            let p = dir.join(name);
            assert!(std::process::Command::new("mkfifo").arg(&p).status().unwrap().success());
            p
        };
        let seq = dir.join("seq/f_#.obj");
        write(&seq, &mesh, &mut frames, 30.0).unwrap();
        std::fs::remove_file(dir.join("seq/f_1.obj")).unwrap();
        fifo("seq/f_1.obj");
        let cases = [
            (fifo("a.pc2"), options(Some(30.0), Some(&rest)), "the PC2 cache is not a regular file"),
            (fifo("a.mdd"), options(None, Some(&rest)), "the MDD cache is not a regular file"),
            (fifo("a.glb"), CacheOptions::default(), "the glTF file is not a regular file"),
            (fifo("a.usda"), CacheOptions::default(), "the USD file is not a regular file"),
            (pc2.clone(), options(Some(30.0), Some(&fifo("rest-fifo.obj"))), "the rest mesh is not a regular file"),
            (seq.clone(), options(Some(30.0), None), "the OBJ frame is not a regular file"),
        ];
        // Each would block forever if the reader opened the FIFO.
        for (path, options, expected) in cases {
            let s = VertexCache::open(&path, &options).unwrap_err().to_string();
            assert!(s.contains(expected) && s.contains("(fix: give the path of a regular file"), "{}: {s}", path.display());
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
