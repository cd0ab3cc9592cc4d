//! Alembic point caches (`.abc`, Ogawa): one `PolyMesh`'s (or `SubD`'s cage) positions with the
//! transforms of its `Xform` ancestors applied.
//!
//! Read through the Alembic C++ library's Python bindings (PyPI `alembic3d`) in a Python
//! process running `abc_cache.py`, as the USD reader does with usd-core: it writes the selected
//! samples one at a time to a temporary PC2 file, which [`pc2`](super::pc2) then serves one
//! frame per read, so neither process holds the whole cache. No Rust reader reads the files
//! Blender writes (`ogawa-rs` 0.4 panics on their vertex samples), and the C++ library is the
//! reference the DCCs link. The old HDF5 flavour is refused before Python starts.
//!
//! Frame `i` is at the sample's time in seconds; the rate is that of the sample times. Alembic
//! stores faces clockwise, so the fan triangles are reversed to face the way they do in the
//! writer. Positions are in the file's units and axes (Alembic is y-up by convention and has
//! no unit). The Python executable is `$BLENDSIM_PYTHON`, or `python3`.

use std::ffi::OsStr;
use std::path::{Path, PathBuf};

use super::binary::require_regular;
use super::pc2::{self, Pc2Frames};
use super::FrameSource;
use crate::algorithms::frames::{rate_of, FrameRange};
use crate::algorithms::geometry::{Point, TriMesh};
use crate::formats::child_script::ChildScript;
use crate::formats::work_dir::WorkDir;
use crate::support::budget::Budget;
use crate::support::error::{Error, Result};

const SCRIPT: &str = include_str!("abc_cache.py");
const FIX_BINDINGS: &str = "pip install alembic3d (or make deps-alembic, or set BLENDSIM_PYTHON to a Python that has it)";

/// `abc_cache.py` under the shared runner (killed at the `--max-time` deadline).
const READER: ChildScript = ChildScript {
    source: SCRIPT,
    purpose: "to read Alembic",
    library: "the Alembic library",
    module: "the Alembic bindings",
    install: FIX_BINDINGS,
    tag: "blendsim-abc: ",
    check: "check that the file is a complete Ogawa Alembic archive (abcls lists it)",
    env: &[],
};

/// The first bytes of an HDF5 file: the Alembic flavour before Ogawa (Alembic 1.5).
const HDF5_MAGIC: &[u8] = b"\x89HDF\r\n\x1a\n";

#[derive(serde::Deserialize)]
struct ReadInfo {
    object: String,
    kind: String,
    times: Vec<f64>,
    points: usize,
    face_vertex_counts: Vec<i64>,
    face_vertex_indices: Vec<i64>,
}

/// The frames of an Alembic mesh, served from a temporary PC2 copy of the selected samples.
#[derive(Debug)]
pub(crate) struct AbcFrames {
    pc2: Pc2Frames,
    /// Frame times in seconds.
    times: Vec<f64>,
    path: PathBuf,
    object: String,
    _temp: WorkDir,
}

/// An opened Alembic cache.
#[derive(Debug)]
pub(crate) struct OpenedAbc {
    /// Topology and the first selected frame's points.
    pub mesh: TriMesh,
    /// The frames.
    pub frames: AbcFrames,
    /// The rate of the sample times.
    pub fps: f64,
    /// The object read (its full name) and its schema, e.g. `/Rig/Body/BodyMesh (PolyMesh)`.
    pub object: String,
    /// Bytes of the file.
    pub bytes: u64,
}

/// Open the positions of `object` (its full name or its name; default: the only mesh, or the
/// only animated one). The reader is killed at the `--max-time` deadline of `budget`.
pub fn open(path: &Path, object: Option<&str>, range: FrameRange, budget: &Budget) -> Result<OpenedAbc> {
    let bytes = require_regular(path, "Alembic file")?;
    let mut head = [0u8; 8];
    let got = std::io::Read::read(&mut std::fs::File::open(path).map_err(|e| Error::io(path, &e, "open the Alembic file"))?, &mut head)
        .map_err(|e| Error::io(path, &e, "read the Alembic file"))?;
    if &head[..got] == HDF5_MAGIC {
        return Err(Error::in_file(
            path,
            "is an HDF5 Alembic archive (the flavour before Alembic 1.5), which blendsim does not read",
            "re-export it as Ogawa (the default of every current exporter), or convert it with abcconvert -toOgawa",
        ));
    }
    if !head.starts_with(b"Ogawa") {
        return Err(Error::in_file(path, "is not an Ogawa Alembic archive (no Ogawa header)", "export the cache as Alembic (.abc, Ogawa)"));
    }
    let temp = WorkDir::create("abc-read").map_err(|e| Error::io(std::env::temp_dir(), &e, "create a private folder for the Alembic reader"))?;
    let (start, end) = (range.start.to_string(), range.end.to_string());
    let args = [OsStr::new("read"), path.as_os_str(), OsStr::new(object.unwrap_or("-")), start.as_ref(), end.as_ref(), temp.path.as_os_str()];
    READER.run(path, &args, budget)?;
    let info_path = temp.path.join("info.json");
    let text = std::fs::read(&info_path).map_err(|e| Error::io(&info_path, &e, "read what the Alembic library found"))?;
    let info: ReadInfo = serde_json::from_slice(&text)
        .map_err(|e| Error::in_file(path, format!("the Alembic reader's summary does not parse: {e}"), "report this as a bug"))?;
    let where_ = format!("{} ({})", info.object, info.kind);
    let bad = |problem: String| Error::in_file(path, problem, "re-export the mesh from your tool");
    let n = info.points;
    let mut triangles = Vec::new();
    let mut at = 0usize;
    for (f, &c) in info.face_vertex_counts.iter().enumerate() {
        if c < 3 || at + c as usize > info.face_vertex_indices.len() {
            return Err(bad(format!("face {f} of {where_} has {c} vertices (face counts and indices disagree, or a face has fewer than 3)")));
        }
        let face = &info.face_vertex_indices[at..at + c as usize];
        if let Some(&i) = face.iter().find(|&&i| i < 0 || i as usize >= n) {
            return Err(bad(format!("face {f} of {where_} uses point {i}, but there are {n} points")));
        }
        for k in 1..face.len() - 1 {
            // Clockwise in the file: reversed.
            triangles.push([face[0] as u32, face[k + 1] as u32, face[k] as u32]);
        }
        at += c as usize;
    }
    if at != info.face_vertex_indices.len() || triangles.is_empty() {
        return Err(bad(format!(
            "{where_} has {} face indices for faces totalling {at} (and needs at least one face)",
            info.face_vertex_indices.len()
        )));
    }
    if info.times.windows(2).any(|w| w[1].partial_cmp(&w[0]) != Some(std::cmp::Ordering::Greater)) {
        return Err(bad(format!("the sample times of {where_} do not increase")));
    }
    let fps = match rate_of(&info.times) {
        Some(fps) => fps,
        None => {
            return Err(Error::in_file(path, format!("{where_} has one frame in the range: nothing moves"), "choose a range of at least two frames"))
        }
    };
    let pc2_path = temp.path.join("frames.pc2");
    let pc2 = pc2::open(&pc2_path, fps).map_err(|e| Error { path: Some(path.to_path_buf()), ..e })?;
    if pc2.frame_count() != info.times.len() || pc2.vertex_count() != n {
        return Err(bad("the Alembic reader's frames do not match its summary".into()));
    }
    let mut frames = AbcFrames { pc2, times: info.times, path: path.to_path_buf(), object: where_.clone(), _temp: temp };
    let mut positions = vec![[0.0; 3]; n];
    frames.read_frame(0, &mut positions)?;
    Ok(OpenedAbc { mesh: TriMesh { positions, triangles, attributes: None }, frames, fps, object: where_, bytes })
}

impl FrameSource for AbcFrames {
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
        // The copy's reader refuses non-finite coordinates; its message places them in the
        // temporary copy, so it is said again of the Alembic object.
        self.pc2.read_frame(frame, out).map_err(|e| {
            if !e.problem.contains(": coordinate ") {
                return Error { path: Some(self.path.clone()), ..e };
            }
            let detail = e.problem.split(" (byte").next().unwrap_or(&e.problem);
            let detail = detail.strip_prefix(&format!("frame {frame}, ")).unwrap_or(detail);
            Error::in_file(
                &self.path,
                format!("{} has a non-finite position at frame {frame} ({detail})", self.object),
                "re-export the cache; check the simulation or rig that wrote it",
            )
        })
    }
}
