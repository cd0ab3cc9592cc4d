//! USD point caches (`.usd`, `.usda`, `.usdc`): the `points` time samples of one Mesh prim.
//!
//! Read through usd-core's `pxr` (the reference implementation), in a Python process running
//! `usd_cache.py`: it writes the selected samples one at a time to a temporary PC2 file, which
//! [`pc2`](super::pc2) then serves one frame per read, so neither process holds the whole cache
//! (usd-core itself keeps a `.usda` layer's text values in memory; `.usdc` values are read on
//! demand). The temporary folder goes with the reader.
//!
//! Frame `i` is at `time_code / timeCodesPerSecond`: the stage's rate is the cache's, whatever
//! the caller's fps. Faces are fan-triangulated in vertex order; a `leftHanded` mesh has its
//! triangles reversed so they face the same way as a `rightHanded` one. Points are in the
//! prim's own space (its transforms are not applied).
//!
//! Written natively, without usd-core: `.usda` as text streamed one frame at a time, `.usdc` /
//! `.usd` as a binary crate ([`crate::formats::export::usdc`]) of the same layer
//! ([`crate::formats::export::usd::sampled_points`], the layout of `formats/usd.md`'s full-frame file).
//! The Python executable that reads is `$BLENDSIM_PYTHON`, or `python3`.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

use super::binary::require_regular;
use super::pc2::{self, Pc2Frames};
use super::{check_writable, FrameSource};
use crate::algorithms::frames::FrameRange;
use crate::algorithms::geometry::{Point, TriMesh};
use crate::formats::child_script::ChildScript;
use crate::formats::export::layer::Value;
use crate::formats::export::usda::{extent, header, prim_name, push_topology, push_vec3s, UsdSettings};
use crate::formats::work_dir::WorkDir;
use crate::support::budget::Budget;
use crate::support::error::{Error, Result};

const SCRIPT: &str = include_str!("usd_cache.py");
const FIX_PXR: &str = "pip install usd-core (or set BLENDSIM_PYTHON to a Python that has it)";

/// `usd_cache.py` under the shared runner (killed at the `--max-time` deadline).
const READER: ChildScript = ChildScript {
    source: SCRIPT,
    purpose: "to read USD",
    library: "usd-core",
    module: "usd-core's pxr module",
    install: FIX_PXR,
    tag: "blendsim-usd: ",
    check: "check that usd-core opens the file (python3 -c \"from pxr import Usd; Usd.Stage.Open('FILE')\")",
    // usd-core maps .usdc files into memory by default, so every sample read stays resident;
    // pread keeps the reader at one sample.
    env: &[("USDC_USE_PREAD", "1")],
};

#[derive(serde::Deserialize)]
struct ReadInfo {
    prim: String,
    time_codes_per_second: f64,
    time_codes: Vec<f64>,
    points: usize,
    face_vertex_counts: Vec<i64>,
    face_vertex_indices: Vec<i64>,
    left_handed: bool,
    /// The stage's `metersPerUnit` when authored (USD's fallback, centimeters, is not assumed:
    /// a stage without it gets the scene's `units`).
    #[serde(default)]
    meters_per_unit: Option<f64>,
}

/// The frames of a USD point cache, served from a temporary PC2 copy of the selected samples.
#[derive(Debug)]
pub(crate) struct UsdFrames {
    pc2: Pc2Frames,
    /// Frame times in seconds.
    times: Vec<f64>,
    _temp: WorkDir,
}

/// An opened USD point cache.
#[derive(Debug)]
pub(crate) struct OpenedUsd {
    /// Topology and the first selected frame's points.
    pub mesh: TriMesh,
    pub frames: UsdFrames,
    /// The stage's timeCodesPerSecond.
    pub fps: f64,
    /// The Mesh prim read.
    pub prim: String,
    pub bytes: u64,
    /// The stage's authored `metersPerUnit` (positive and finite), if any.
    pub meters_per_unit: Option<f64>,
}

/// Open the `points` time samples of `prim` (or the stage's only / only animated Mesh).
pub fn open(path: &Path, prim: Option<&str>, range: FrameRange, budget: &Budget) -> Result<OpenedUsd> {
    let bytes = require_regular(path, "USD file")?;
    let temp = WorkDir::create("usd-read").map_err(|e| Error::io(std::env::temp_dir(), &e, "create a private folder for usd-core's reader"))?;
    let (start, end) = (range.start.to_string(), range.end.to_string());
    let args = [
        std::ffi::OsStr::new("read"),
        path.as_os_str(),
        std::ffi::OsStr::new(prim.unwrap_or("-")),
        start.as_ref(),
        end.as_ref(),
        temp.path.as_os_str(),
    ];
    READER.run(path, &args, budget)?;
    let info_path = temp.path.join("info.json");
    let text = std::fs::read(&info_path).map_err(|e| Error::io(&info_path, &e, "read what usd-core found"))?;
    let info: ReadInfo =
        serde_json::from_slice(&text).map_err(|e| Error::in_file(path, format!("usd-core's summary does not parse: {e}"), "report this as a bug"))?;
    let where_ = &info.prim;
    let bad = |problem: String| Error::in_file(path, problem, "re-export the mesh from your tool; check it with usd-core");
    if !(info.time_codes_per_second.is_finite() && info.time_codes_per_second > 0.0) {
        return Err(bad(format!("timeCodesPerSecond is {}", info.time_codes_per_second)));
    }
    let fps = info.time_codes_per_second;
    let n = info.points;
    let mut triangles = Vec::new();
    let mut at = 0usize;
    for (f, &c) in info.face_vertex_counts.iter().enumerate() {
        if c < 3 || at + c as usize > info.face_vertex_indices.len() {
            return Err(bad(format!(
                "face {f} of {where_} has {c} vertices (faceVertexCounts and faceVertexIndices disagree, or a face has fewer than 3)"
            )));
        }
        let face = &info.face_vertex_indices[at..at + c as usize];
        if let Some(&i) = face.iter().find(|&&i| i < 0 || i as usize >= n) {
            return Err(bad(format!("face {f} of {where_} uses point {i}, but there are {n} points")));
        }
        for k in 1..face.len() - 1 {
            let t = [face[0] as u32, face[k] as u32, face[k + 1] as u32];
            triangles.push(if info.left_handed { [t[0], t[2], t[1]] } else { t });
        }
        at += c as usize;
    }
    if at != info.face_vertex_indices.len() || triangles.is_empty() {
        return Err(bad(format!(
            "{where_} has {} faceVertexIndices for faces totalling {at} (and needs at least one face)",
            info.face_vertex_indices.len()
        )));
    }
    let pc2_path = temp.path.join("frames.pc2");
    let mut pc2 = pc2::open(&pc2_path, fps).map_err(|e| Error { path: Some(path.to_path_buf()), ..e })?;
    if pc2.frame_count() != info.time_codes.len() || pc2.vertex_count() != n {
        return Err(bad("usd-core's frames do not match its summary".into()));
    }
    let mut positions = vec![[0.0; 3]; n];
    pc2.read_frame(0, &mut positions).map_err(|e| Error { path: Some(path.to_path_buf()), ..e })?;
    let times = info.time_codes.iter().map(|t| t / fps).collect();
    let frames = UsdFrames { pc2, times, _temp: temp };
    let meters_per_unit = match info.meters_per_unit {
        Some(m) if !(m.is_finite() && m > 0.0) => return Err(bad(format!("the stage's metersPerUnit is {m}, not a positive length"))),
        m => m,
    };
    Ok(OpenedUsd { mesh: TriMesh { positions, triangles, attributes: None }, frames, fps, prim: info.prim, bytes, meters_per_unit })
}

impl FrameSource for UsdFrames {
    fn vertex_count(&self) -> usize {
        self.pc2.vertex_count()
    }

    fn frame_count(&self) -> usize {
        self.times.len()
    }

    fn time(&self, frame: usize) -> f64 {
        self.times[frame]
    }

    fn read_frame(&mut self, frame: usize, out: &mut [Point]) -> Result<()> {
        self.pc2.read_frame(frame, out)
    }
}

/// Time codes of the frames at `fps`, whole numbers when within 1e-6 of one.
fn time_codes(frames: &dyn FrameSource, fps: f64) -> Vec<f64> {
    (0..frames.frame_count())
        .map(|i| {
            let code = frames.time(i) * fps;
            if (code - code.round()).abs() <= 1e-6 {
                code.round()
            } else {
                code
            }
        })
        .collect()
}

/// Write `frames` as a USD point cache: `.usda` as text, `.usdc` / `.usd` as a binary crate.
/// The stage is `/NAME/Mesh` (NAME from the file name), timeCodesPerSecond = `fps`.
pub fn write(path: &Path, mesh: &TriMesh, frames: &mut dyn FrameSource, fps: f64) -> Result<()> {
    let (n, _) = check_writable(path, frames, fps)?;
    if mesh.positions.len() != n || mesh.triangles.is_empty() {
        return Err(Error::general(
            format!(
                "cannot write {}: the mesh has {} vertices and {} triangles, the frames {n} vertices",
                path.display(),
                mesh.positions.len(),
                mesh.triangles.len()
            ),
            "pass the mesh the frames belong to",
        ));
    }
    let name = prim_name(&path.file_stem().map_or_else(|| "cache".into(), |s| s.to_string_lossy().into_owned()));
    let codes = time_codes(frames, fps);
    let (start, end) = (codes[0].floor() as i64, codes[codes.len() - 1].ceil() as i64);
    let settings = UsdSettings { name, fps, up_axis: 'Y', meters_per_unit: 1.0 };
    // Marked as a conversion, as the glb cache's generator is.
    let doc = format!("blendsim {} (vertex cache)", env!("CARGO_PKG_VERSION"));
    let ascii = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("usda"));
    if ascii {
        return write_usda(path, mesh, frames, &codes, (&settings, &doc), start, end);
    }
    // The binary crate is written natively from the layer the `.usda` text holds, with the
    // points streamed: read once for the extents (which come first), then again frame by
    // frame into one buffer as the writer writes them to the file, so the frames are never
    // held (usd-core's writer held its layer too).
    let mut points = vec![[0.0; 3]; n];
    let mut extents = Vec::with_capacity(codes.len());
    let mut f32s: Vec<[f32; 3]> = Vec::with_capacity(n);
    for (i, &code) in codes.iter().enumerate() {
        frames.read_frame(i, &mut points)?;
        f32s.clear();
        f32s.extend(points.iter().map(|p| p.map(|x| x as f32)));
        extents.push((code, extent(&f32s)));
    }
    drop(f32s);
    let mut layer = crate::formats::export::usd::sampled_points_layer(extents, Vec::new(), n, &mesh.triangles, None, &settings, (start, end));
    layer.metadata.iter_mut().filter(|(key, _)| *key == "doc").for_each(|(_, value)| *value = Value::String(doc.clone()));
    let mut read = |i: usize, out: &mut Vec<[f32; 3]>| -> Result<()> {
        frames.read_frame(i, &mut points)?;
        out.clear();
        out.extend(points.iter().map(|p| p.map(|x| x as f32)));
        Ok(())
    };
    let streamed = crate::formats::export::usdc::StreamedSamples {
        attribute: crate::formats::export::usd::points_path(&settings),
        times: &codes,
        read: &mut read,
    };
    crate::support::output::write_atomic_with(path, |tmp| {
        let file =
            File::options().read(true).write(true).create(true).truncate(true).open(tmp).map_err(|e| Error::io(tmp, &e, "create the usdc file"))?;
        crate::formats::export::usdc::write_streamed(&layer, path, streamed, file)
    })
}

fn write_usda(
    path: &Path,
    mesh: &TriMesh,
    frames: &mut dyn FrameSource,
    codes: &[f64],
    (settings, doc): (&UsdSettings, &str),
    start: i64,
    end: i64,
) -> Result<()> {
    crate::support::output::write_atomic_with(path, |tmp| {
        let file = File::create(tmp).map_err(|e| Error::io(tmp, &e, "create the usda file"))?;
        let mut w = BufWriter::new(file);
        let io = |e: std::io::Error| Error::io(path, &e, "write the usda file");
        let mut text = header(settings, doc, start, end);
        text.push_str(&format!("def Xform \"{}\"\n{{\n    def Mesh \"Mesh\"\n    {{\n", settings.name));
        w.write_all(text.as_bytes()).map_err(io)?;
        let mut points = vec![[0.0; 3]; frames.vertex_count()];
        let mut sampled = |w: &mut BufWriter<File>, declaration: &str, value: &mut dyn FnMut(&mut String, &[[f32; 3]])| -> Result<()> {
            w.write_all(format!("        {declaration}.timeSamples = {{\n").as_bytes()).map_err(io)?;
            for (i, code) in codes.iter().enumerate() {
                frames.read_frame(i, &mut points)?;
                let f32s: Vec<[f32; 3]> = points.iter().map(|p| p.map(|x| x as f32)).collect();
                let mut line = format!("            {code}: ");
                value(&mut line, &f32s);
                line.push_str(",\n");
                w.write_all(line.as_bytes()).map_err(io)?;
            }
            w.write_all(b"        }\n").map_err(io)
        };
        sampled(&mut w, "float3[] extent", &mut |line, p| push_vec3s(line, extent(p).iter()))?;
        let mut topology = String::new();
        push_topology(&mut topology, &mesh.triangles);
        w.write_all(topology.as_bytes()).map_err(io)?;
        sampled(&mut w, "point3f[] points", &mut |line, p| push_vec3s(line, p.iter()))?;
        w.write_all(b"        uniform token subdivisionScheme = \"none\"\n    }\n}\n").map_err(io)?;
        w.into_inner().map_err(|e| io(e.into_error()))?.sync_all().map_err(io)
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::ffi::OsString;
    use std::process::Command;

    use crate::formats::cache::tests::{assert_frames_equal, scratch, wave, wave_mesh};

    #[test]
    fn usda_and_usdc_round_trip_through_usd_core() {
        let dir = scratch("usd-roundtrip");
        let (mesh, mut frames) = (wave_mesh(3), wave(9, 5, 24.0));
        for name in ["wave.usda", "wave.usdc"] {
            let path = dir.join(name);
            write(&path, &mesh, &mut frames, 24.0).unwrap();
            let mut opened = open(&path, None, FrameRange::ALL, &Budget::default()).unwrap();
            assert_eq!((opened.fps, opened.prim.as_str()), (24.0, "/wave/Mesh"), "{name}");
            assert_eq!(opened.mesh.triangles, mesh.triangles, "{name}");
            assert_eq!(opened.bytes, std::fs::metadata(&path).unwrap().len());
            assert_frames_equal(&mut frames, &mut opened.frames, 0.0);
            let sub = open(&path, Some("/wave/Mesh"), FrameRange { start: 1, end: -2 }, &Budget::default()).unwrap();
            assert_eq!((sub.frames.frame_count(), sub.frames.time(0)), (3, 1.0 / 24.0));
        }
        assert_eq!(&std::fs::read(dir.join("wave.usdc")).unwrap()[..8], b"PXR-USDC");
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 2, "no temporaries left");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// The `.usdc` cache is the `.usda` cache's layer, written natively: usd-core's checker
    /// reads the two as one layer (every spec, field and time sample), also with time codes
    /// that are not whole (frames at 24 fps on a 30 fps stage), and a `.usd` is the same crate.
    #[test]
    fn usdc_holds_the_usda_layer() {
        let dir = scratch("usd-same-layer");
        let (mesh, frames) = (wave_mesh(4), wave(16, 7, 24.0));
        for name in ["wave.usda", "wave.usdc", "wave.usd"] {
            write(&dir.join(name), &mesh, &mut frames.clone(), 30.0).unwrap();
        }
        assert_eq!(std::fs::read(dir.join("wave.usdc")).unwrap(), std::fs::read(dir.join("wave.usd")).unwrap());
        let checker = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/checkers/usd_same_layer.py");
        let python = std::env::var_os("BLENDSIM_PYTHON").unwrap_or_else(|| OsString::from("python3"));
        let out = Command::new(python).arg(checker).arg(dir.join("wave.usda")).arg(dir.join("wave.usdc")).output().unwrap();
        let stdout = String::from_utf8_lossy(&out.stdout);
        assert!(out.status.success() && stdout.contains("\"ok\": true"), "{stdout}\n{}", String::from_utf8_lossy(&out.stderr));
        let text = std::fs::read_to_string(dir.join("wave.usda")).unwrap();
        assert!(text.contains("            1.25: [(") && text.contains(" (vertex cache)\"\n"), "fractional time codes, the doc of a cache");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn quads_are_fanned_and_left_handed_faces_reversed() {
        let dir = scratch("usd-quads");
        let path = dir.join("quad.usda");
        let text = "#usda 1.0\n(\n    timeCodesPerSecond = 30\n)\ndef Mesh \"Quad\"\n{\n    int[] faceVertexCounts = [4]\n    \
                    int[] faceVertexIndices = [0, 1, 2, 3]\n    uniform token orientation = \"leftHanded\"\n    \
                    point3f[] points.timeSamples = {\n        3: [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)],\n        \
                    4: [(0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)],\n    }\n}\n";
        std::fs::write(&path, text).unwrap();
        let opened = open(&path, None, FrameRange::ALL, &Budget::default()).unwrap();
        assert_eq!(opened.mesh.triangles, vec![[0, 2, 1], [0, 3, 2]]);
        assert_eq!((opened.fps, opened.frames.time(0), opened.frames.time(1)), (30.0, 0.1, 4.0 / 30.0));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn bad_prims_and_static_meshes_are_one_line_errors() {
        let dir = scratch("usd-bad");
        let (mesh, mut frames) = (wave_mesh(2), wave(4, 2, 24.0));
        let path = dir.join("a.usda");
        write(&path, &mesh, &mut frames, 24.0).unwrap();
        let err = |prim: Option<&str>, range: FrameRange| open(&path, prim, range, &Budget::default()).unwrap_err().to_string();
        let s = err(Some("/nope"), FrameRange::ALL);
        assert!(s.starts_with(&format!("{}: has no prim /nope (its meshes: /a/Mesh) (fix: set prim", path.display())), "{s}");
        let s = err(Some("/a"), FrameRange::ALL);
        assert!(s.contains("prim /a is a Xform, not a Mesh"), "{s}");
        let s = err(None, FrameRange { start: 0, end: 5 });
        assert!(s.contains("frame range start = 0, end = 5 selects no frames of the 2 the cache holds"), "{s}");

        let static_mesh = dir.join("static.usda");
        std::fs::write(&static_mesh, "#usda 1.0\ndef Mesh \"M\"\n{\n    int[] faceVertexCounts = [3]\n    int[] faceVertexIndices = [0, 1, 2]\n    point3f[] points = [(0, 0, 0), (1, 0, 0), (0, 1, 0)]\n}\n").unwrap();
        let s = open(&static_mesh, None, FrameRange::ALL, &Budget::default()).unwrap_err().to_string();
        assert!(
            s.starts_with(&format!(
                "{}: the points of /M have no time samples (a static mesh, not a point cache) (fix: export the animation as points time samples",
                static_mesh.display()
            )),
            "{s}"
        );
        assert!(!s.contains('\n'));

        let broken = dir.join("broken.usda");
        std::fs::write(&broken, "#usda 1.0\ndef Mesh \"M\" {\n").unwrap();
        let s = open(&broken, None, FrameRange::ALL, &Budget::default()).unwrap_err().to_string();
        assert!(s.contains("usd-core failed") && !s.contains('\n'), "{s}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
