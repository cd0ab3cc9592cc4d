//! The plain data that flows between stages. Each subcommand reads one of these files and
//! writes the next; `bake` passes them in memory. Specified in `formats/stages.md`.
//!
//! ```text
//! import -> Keyframes -> tetrahedralize -> Body -> solve -> Solution -> embed -> Animation
//!        -> export (files + Outputs) -> report
//! ```
//!
//! Files are JSON with a header naming the stage, so passing the wrong file to a subcommand
//! is a clear error. Numbers are written with shortest round-trip formatting: a chain of
//! subcommands gives the same bytes as `bake`.
//!
//! This file holds the stage types and the file envelope; `stage_data.rs` what each stage
//! checks when its file is read, `solver_log.rs` the solver's record in a solution.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::algorithms::geometry::{Point, TetMesh, TriMesh};

use crate::algorithms::spacetime::trajectory::Trajectory;

use crate::pipeline::scene::{Format, Method, Scene};

use crate::support::budget::Budget;

use crate::support::error::{Error, Result};

mod cache_record;
mod solver_log;
mod stage_data;

pub use cache_record::{CacheRecord, CacheRecordOptions};
pub use solver_log::{CgSummary, SolverLog};
pub use stage_data::StageData;

/// A sorted set of vertex indices.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(transparent)]
pub struct VertexSet(Vec<u32>);

impl VertexSet {
    /// The indices where `mask` is true.
    pub fn from_mask(mask: &[bool]) -> Self {
        VertexSet(mask.iter().enumerate().filter(|(_, &m)| m).map(|(i, _)| i as u32).collect())
    }

    /// Every index below `n`.
    pub fn all(n: usize) -> Self {
        VertexSet((0..n as u32).collect())
    }

    /// A mask over `n` vertices.
    pub(crate) fn to_mask(&self, n: usize) -> Vec<bool> {
        let mut m = vec![false; n];
        for &i in &self.0 {
            m[i as usize] = true;
        }
        m
    }

    /// Whether `i` is in the set.
    pub fn contains(&self, i: u32) -> bool {
        self.0.binary_search(&i).is_ok()
    }

    /// Number of indices.
    pub fn len(&self) -> usize {
        self.0.len()
    }

    /// Whether the set is empty.
    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }

    /// The indices, increasing.
    pub fn indices(&self) -> &[u32] {
        &self.0
    }
}

/// The keyframes' shape before tetrahedralization: a surface or a ready tet mesh.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase")]
pub enum Shape {
    /// A closed surface, tetrahedralized by TetGen.
    Surface(TriMesh),
    /// A tet mesh, simulated as it is.
    Volume(TetMesh),
}

impl Shape {
    /// The vertex positions (the surface's, or the tet mesh's nodes).
    pub fn positions(&self) -> &[Point] {
        match self {
            Shape::Surface(s) => &s.positions,
            Shape::Volume(v) => &v.positions,
        }
    }
}

/// Output of `import`: keyframe poses on one topology, with their constraints.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Keyframes {
    /// The scene, carried along so later stages need no scene file.
    pub scene: Scene,
    /// The file the rest shape came from, as a path from where the process runs (for messages);
    /// the stage file holds it relative to its own folder ([`write()`], [`read`]).
    pub rest_source: String,
    /// The elastic rest shape. Every pose has its vertex count.
    pub rest: Shape,
    /// Key times in seconds, non-decreasing: a contact key and its duplicate share a time
    /// (`[keyframes] contact`), every other key has its own.
    pub times: Vec<f64>,
    /// `poses[key][vertex]`, as read (after any procedural deformation).
    pub poses: Vec<Vec<Point>>,
    /// Per key, vertices whose position is prescribed.
    pub fixed: Vec<VertexSet>,
    /// Per key, vertices whose velocity is prescribed (to zero).
    pub fixed_velocity: Vec<VertexSet>,
    /// The last key is the first: the animation loops.
    pub cyclic: bool,
    /// A separate surface to embed and export, in the rest pose (`[embed] surface`).
    pub display: Option<TriMesh>,
    /// The cache the keys were taken from (`[cache]` scenes).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cache: Option<CacheRecord>,
    /// Bytes of the input as given (the keyframe files, each file once, or the cache), for the
    /// report's ratios; 0 in stage files written before it was recorded.
    #[serde(default)]
    pub input_bytes: u64,
    /// When the keyframe surface's vertices were welded (`[keyframes] weld`): per input vertex,
    /// its vertex here and in the files. A cache's weld is its record's (`CacheRecord::weld`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub weld: Option<Vec<u32>>,
}

/// Keyframe data per tet node: what the solver constrains and starts from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct KeyPoses {
    /// Key times in seconds, non-decreasing (equal for the two keys of a contact).
    pub times: Vec<f64>,
    /// `positions[key][node]`: the input poses (interior nodes from a quasi-static fit).
    pub positions: Vec<Vec<Point>>,
    /// Per key, nodes whose position is prescribed (added interior nodes are free).
    pub fixed: Vec<VertexSet>,
    /// Per key, nodes whose velocity is prescribed (to zero).
    pub fixed_velocity: Vec<VertexSet>,
    /// The last key is the first: the animation loops.
    pub cyclic: bool,
}

/// A generated cage: why it was used, its size, and how well its posed keys reproduce the
/// fine keyframes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CageInfo {
    /// Why the surface was simulated on a cage, in words.
    pub reason: String,
    /// Vertices of the fine keyframe surface.
    pub fine_vertices: usize,
    /// Nodes on the cage's boundary.
    pub boundary_nodes: usize,
    /// Tet nodes of the cage.
    pub nodes: usize,
    /// Tets of the cage.
    pub tets: usize,
    /// The side of the cage's cubes, in scene units (the cage reaches at most one cube
    /// diagonal beyond the fine surface).
    pub spacing: f64,
    /// The fine keyframes against their embedding on the posed cage keys, relative to the
    /// fine rest surface's bounding-box diagonal: largest and root mean square over every
    /// vertex of every key.
    pub key_error_max: f64,
    /// See `key_error_max`.
    pub key_error_rms: f64,
}

/// Output of `tetrahedralize`: the simulation body, its keyframes, and the surface to export.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Body {
    /// The scene.
    pub scene: Scene,
    /// Rest pose, every tet positively oriented; none when nothing is simulated (method
    /// `fit`: the trajectory is the surface's own).
    pub mesh: Option<TetMesh>,
    /// The keyframes of every node.
    pub keys: KeyPoses,
    /// The surface that is exported, in the rest pose, outward oriented. Keyframe and `[embed]`
    /// surfaces keep every vertex of their file, unused ones included, so point `i` of the
    /// files is the input's vertex `i` (a welded keyframe surface's: point `weld[i]`); a tet
    /// mesh's is its boundary (interior nodes left out). It is embedded in `mesh`.
    pub surface: TriMesh,
    /// The cache the keys were taken from (`[cache]` scenes).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cache: Option<CacheRecord>,
    /// When `mesh` is a generated cage around the keyframe surface: how it was made.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cage: Option<CageInfo>,
    /// What `tetrahedralize` and `solve` warned about (one line each, its code first:
    /// `folded-key`, a key with inverted or flattened tets; `max-volume`, a `max_volume` TetGen
    /// could not honour; `body-size`, `embed-far`, `units-conflict`; `cg-capped` from `solve`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub warnings: Vec<String>,
    /// Bytes of the input as given (the keyframe files, each file once, or the cache), for the
    /// report's ratios; 0 in stage files written before it was recorded.
    #[serde(default)]
    pub input_bytes: u64,
    /// When the keyframe surface's vertices were welded (`[keyframes] weld`): per input vertex,
    /// its vertex here and in the files. A cache's weld is its record's (`CacheRecord::weld`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub weld: Option<Vec<u32>>,
}

impl Body {
    /// Print `line` as a warning (through `progress`, silent under `--strict`) and keep it
    /// for the report.
    pub fn warn(&mut self, progress: &crate::support::progress::Progress, line: String) {
        progress.warn(&line);
        self.warnings.push(line);
    }
}

/// Output of `solve`: the body and its optimized node trajectory.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Solution {
    /// The body (its scene records the method used).
    pub body: Body,
    /// The trajectory of every node.
    pub trajectory: Trajectory,
    /// What the solver did.
    pub log: SolverLog,
}

/// Sizes of the problem, for the report.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Counts {
    /// Vertices of the exported surface.
    pub vertices: usize,
    /// Triangles of the exported surface.
    pub faces: usize,
    /// Nodes of the simulated body.
    pub tet_nodes: usize,
    /// Tets of the simulated body.
    pub tets: usize,
    /// Keyframes.
    pub keyframes: usize,
    /// The largest rest volume of a tet of the body (compared with `[tet] max_volume` in the
    /// report).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub largest_tet_volume: Option<f64>,
}

/// Output of `embed`: the exported surface and its exact trajectory.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Animation {
    /// The scene.
    pub scene: Scene,
    /// Sizes of the problem.
    pub counts: Counts,
    /// The surface in the rest pose.
    pub mesh: TriMesh,
    /// The surface's trajectory: the node trajectory carried by the embedding.
    pub trajectory: Trajectory,
    /// The input keyframe poses carried by the same embedding, `[key][vertex]`.
    pub input_keys: Vec<Vec<Point>>,
    /// What the solver did.
    pub log: SolverLog,
    /// The cache the keys were taken from (`[cache]` scenes): the report measures against it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cache: Option<CacheRecord>,
    /// The cage the surface was simulated on, if any.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cage: Option<CageInfo>,
    /// The body's warnings ([`Body::warnings`]), for the report.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub warnings: Vec<String>,
    /// Bytes of the input as given (the keyframe files, each file once, or the cache), for the
    /// report's ratios; 0 in stage files written before it was recorded.
    #[serde(default)]
    pub input_bytes: u64,
    /// When the keyframe surface's vertices were welded (`[keyframes] weld`): per input vertex,
    /// its vertex here and in the files. A cache's weld is its record's (`CacheRecord::weld`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub weld: Option<Vec<u32>>,
}

impl Animation {
    /// Per input vertex, its vertex in the files, when the input was welded (a keyframe
    /// surface's or a cache's weld); none when the files number the input's vertices.
    pub fn weld_map(&self) -> Option<&[u32]> {
        self.weld.as_deref().or_else(|| self.cache.as_ref().and_then(|c| c.weld.as_deref()))
    }
}

/// The two forms of the animation in the files.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum OutputKind {
    /// Blendshapes and weight curves (`NAME.EXT`).
    Blendshape,
    /// One pose per frame (`NAME.full.EXT`), for comparison.
    FullFrame,
}

/// One file written by `export`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OutputFile {
    /// File name inside the output folder.
    pub path: String,
    /// Which form of the animation it holds.
    pub kind: OutputKind,
    /// Its format.
    pub format: Format,
    /// Its size.
    pub bytes: u64,
    /// A glb's largest distance at any frame between what it plays (read back from the file)
    /// and the animation it holds, relative to the rest bounding-box diagonal: its quantization
    /// error (`formats/gltf.md`, "Quantization"). `None` for USD files and static glbs.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub quantization_error: Option<f64>,
}

/// Output of `export` (beside the files): what was written.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Outputs {
    /// The files, blendshapes first, then full-frame, each in the order usda, usdc, glb.
    pub files: Vec<OutputFile>,
    /// With `[export] basis = "principal"`: the number of components the blendshape files hold
    /// (chosen by the tolerance or given), so the report measures the same clip.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rank: Option<usize>,
}

/// Stage file format version; bumped when a stage type changes incompatibly.
pub(crate) const FORMAT_VERSION: u32 = 1;

#[derive(Serialize)]
struct HeaderOut<'a, T> {
    blendsim: u32,
    stage: &'a str,
    data: &'a T,
}

#[derive(Deserialize)]
struct HeaderIn {
    blendsim: Option<u32>,
    stage: Option<String>,
}

#[derive(Deserialize)]
struct BodyIn<T> {
    data: T,
}

/// Serialize a stage to JSON bytes (with its header).
pub fn to_json<T: StageData>(value: &T) -> Vec<u8> {
    let mut bytes = serde_json::to_vec(&HeaderOut { blendsim: FORMAT_VERSION, stage: T::STAGE, data: value }).expect("stage data serializes");
    bytes.push(b'\n');
    bytes
}

/// Write a stage file atomically. Texture, cache and rest source paths are written relative to
/// the file's folder.
pub fn write<T: StageData + Clone>(path: &Path, value: &T) -> Result<()> {
    let mut value = std::borrow::Cow::Borrowed(value);
    if value.has_textures() {
        let folder = stage_folder(path)?;
        for mesh in value.to_mut().surfaces_mut() {
            for texture in textures_mut(mesh) {
                *texture = relative_to(&folder, Path::new(texture.as_str())).to_string_lossy().into_owned();
            }
        }
    }
    if value.has_files() {
        let folder = stage_folder(path)?;
        for file in value.to_mut().files_mut() {
            *file = relative_to(&folder, &resolved(Path::new(file.as_str()))).to_string_lossy().into_owned();
        }
    }
    crate::support::output::write_atomic(path, &to_json(value.as_ref()))
}

/// Read a stage file, checking that it holds the expected stage and that its data keeps the
/// stage's invariants ([`StageData::validate`]). Relative texture paths are resolved against
/// the file's folder; relative cache and rest source paths are joined to the folder as `path`
/// names it (so a stage file in the working folder gives the path `import` had).
pub fn read<T: StageData>(path: &Path, budget: &Budget) -> Result<T> {
    let bytes = crate::support::input::read_bytes(path, &format!("the {} file", T::STAGE))?;
    let mut value: T = from_json(&bytes, path, budget)?;
    let parent = path.parent().unwrap_or(Path::new(""));
    for file in value.files_mut().into_iter().filter(|f| Path::new(f.as_str()).is_relative()) {
        *file = parent.join(file.as_str()).to_string_lossy().into_owned();
    }
    let mut surfaces = value.surfaces_mut();
    if surfaces.iter_mut().any(|m| textures_mut(m).any(|t| Path::new(t.as_str()).is_relative())) {
        let folder = stage_folder(path)?;
        for mesh in surfaces {
            for texture in textures_mut(mesh).filter(|t| Path::new(t.as_str()).is_relative()) {
                let joined = folder.join(texture.as_str());
                *texture = joined.canonicalize().unwrap_or(joined).to_string_lossy().into_owned();
            }
        }
    }
    Ok(value)
}

/// The paths of a cache record: the cache (an OBJ sequence's pattern) and its topology mesh.
fn cache_paths_mut(record: &mut CacheRecord) -> impl Iterator<Item = &mut String> {
    std::iter::once(&mut record.path).chain(record.options.rest.as_mut())
}

/// `path` absolute (against the working folder), its folder with symbolic links resolved as a
/// stage folder's are ([`stage_folder`]); the file name is kept as it is (a sequence's pattern
/// names no file), and so is a path whose folder does not exist.
fn resolved(path: &Path) -> PathBuf {
    let absolute = std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf());
    match (absolute.parent(), absolute.file_name()) {
        (Some(folder), Some(name)) => folder.canonicalize().map_or(absolute.clone(), |f| f.join(name)),
        _ => absolute,
    }
}

/// Whether a surface's material groups name a texture.
fn textured(mesh: &TriMesh) -> bool {
    mesh.attributes.as_ref().is_some_and(|a| a.textures.iter().any(Option::is_some))
}

/// The texture paths of a surface's material groups.
fn textures_mut(mesh: &mut TriMesh) -> impl Iterator<Item = &mut String> {
    mesh.attributes.iter_mut().flat_map(|a| a.textures.iter_mut().flatten())
}

/// The folder of a stage file, absolute and with symbolic links resolved (as texture paths
/// are), so a path relative to it means the same file to the OS.
fn stage_folder(path: &Path) -> Result<PathBuf> {
    let folder = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    folder.canonicalize().map_err(|e| Error::io(folder, &e, "resolve the stage file's folder"))
}

/// `path` relative to the folder `from` (both absolute): `..` up to their common ancestor,
/// then down to `path`.
fn relative_to(from: &Path, path: &Path) -> PathBuf {
    let (a, b): (Vec<_>, Vec<_>) = (from.components().collect(), path.components().collect());
    let common = a.iter().zip(&b).take_while(|(x, y)| x == y).count();
    let mut out: PathBuf = a[common..].iter().map(|_| std::path::Component::ParentDir).collect();
    out.extend(&b[common..]);
    out
}

/// Parse and validate the bytes of a stage file (the memory of the stages after it within
/// `budget`); `path` is named in errors.
pub(crate) fn from_json<T: StageData>(bytes: &[u8], path: &Path, budget: &Budget) -> Result<T> {
    let wrong = |what: String| Error::in_file(path, what, format!("pass the {} file written by `{}`", T::STAGE, T::WRITER));
    let header: HeaderIn = serde_json::from_slice(bytes).map_err(|e| wrong(format!("is not a blendsim stage file ({e})")))?;
    match (header.blendsim, header.stage.as_deref()) {
        (Some(FORMAT_VERSION), Some(s)) if s == T::STAGE => {}
        (Some(v), _) if v != FORMAT_VERSION => {
            return Err(Error::in_file(
                path,
                format!("was written by stage format {v}, this blendsim reads format {FORMAT_VERSION}"),
                "re-run the earlier stages with this blendsim",
            ))
        }
        (_, Some(s)) => return Err(wrong(format!("holds a '{s}' stage, not '{}'", T::STAGE))),
        _ => return Err(wrong("has no blendsim stage header".into())),
    }
    let body: BodyIn<T> = serde_json::from_slice(bytes).map_err(|e| wrong(format!("has a malformed {} stage: {e}", T::STAGE)))?;
    body.data.validate(budget).map_err(|e| Error::in_file(path, format!("{} stage: {}", T::STAGE, e.problem), e.fix))?;
    Ok(body.data)
}
