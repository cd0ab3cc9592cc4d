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

use std::path::{Path, PathBuf};

use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

use crate::algorithms::geometry::{Point, TetMesh, TriMesh};
use crate::algorithms::spacetime::solver::{self, IterationSplit};
use crate::algorithms::spacetime::trajectory::Trajectory;
use crate::pipeline::scene::{Format, Method, Scene};
use crate::support::budget::Budget;
use crate::support::error::{Error, Result};

mod cache_record;
pub use cache_record::{CacheRecord, CacheRecordOptions};

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
    /// files is the input's vertex `i`; a tet mesh's is its boundary (interior nodes left
    /// out). It is embedded in `mesh`.
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
}

impl Body {
    /// Print `line` as a warning (through `progress`, silent under `--strict`) and keep it
    /// for the report.
    pub fn warn(&mut self, progress: &crate::support::progress::Progress, line: String) {
        progress.warn(&line);
        self.warnings.push(line);
    }
}

/// What the solver did.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SolverLog {
    /// The method that made the trajectory.
    pub method: Method,
    /// Iterations taken (0 for `hermite`).
    pub iterations: usize,
    /// W after each iteration, starting with the initial guess (the hermite baseline).
    pub energy: Vec<f64>,
    /// Wall-clock seconds for the whole solve.
    pub seconds: f64,
    /// Seconds spent assembling and factorizing before the first iteration.
    pub precompute_seconds: f64,
    /// Mean seconds per iteration (local step, residuals, global step).
    pub iteration_seconds: f64,
    /// Free unknowns per coordinate (keyframe positions and velocities).
    pub unknowns: usize,
    /// Steps halved because the full step would have increased W.
    pub halvings: usize,
    /// Whether W settled within the iteration budget (always for `hermite`).
    pub converged: bool,
    /// Why the iteration stopped, in words.
    pub stop_reason: String,
    /// How the global step was solved: `direct` (sparse Cholesky) or `iterative` (conjugate
    /// gradients, when the factor would not fit in the memory budget).
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub linear_solver: String,
    /// W's relative decrease over the last iterations of the stopping rule's window.
    #[serde(default)]
    pub last_decrease: f64,
    /// The predicted further decrease of W (relative to the final W) had the solve gone on,
    /// when the last windows' decreases shrink geometrically.
    #[serde(default)]
    pub predicted_remaining: Option<f64>,
    /// The force scale S at the solution (spacetime only): W with the forces the residual is
    /// the sum of (inertia and damping, gravity, elasticity) squared one by one; `W / S` is the
    /// squared relative size of the residual force.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub force_scale: Option<f64>,
    /// The force scale S at each iterate of `energy` (spacetime only; the last is
    /// `force_scale`): the stopping rule's floor is `settings::NEGLIGIBLE` S at each iteration.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub force_scales: Vec<f64>,
    /// The key times given to the solver.
    #[serde(default)]
    pub input_times: Vec<f64>,
    /// The key times of the solution: the optimized ones with `optimize_timing`, else the
    /// input ones (the trajectory's, repeated here for the report).
    #[serde(default)]
    pub times: Vec<f64>,
    /// Iterations that moved the key times (with `optimize_timing`).
    #[serde(default)]
    pub timing_iterations: usize,
    /// Refactorizations of the global step for new key times.
    #[serde(default)]
    pub refactorizations: usize,
    /// Node-obstacle checks held on an obstacle at the end.
    #[serde(default)]
    pub active_contacts: usize,
    /// The smallest distance of a node to an obstacle over keys and frames (with obstacles).
    #[serde(default)]
    pub clearance: Option<f64>,
    /// How the iterative global step's conjugate-gradient solves went (iterative only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub conjugate_gradients: Option<CgSummary>,
    /// Iterations of the coarse phase, included in `iterations` (0: none ran; spacetime's
    /// `[solver] coarse_samples`). `energy` holds W at `samples` only: the first guess, the
    /// coarse phase's result, then one entry per fine iteration.
    #[serde(default)]
    pub coarse_iterations: usize,
    /// Samples per interval of the coarse phase (0: none ran).
    #[serde(default)]
    pub coarse_samples: usize,
    /// Where the spacetime iterations' time went: W's evaluations and the global step's solves.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub iteration_split: Option<IterationSplit>,
}

impl SolverLog {
    /// The log of a method that does not iterate the spacetime solver (`hermite`, `fit`, and
    /// `mass-spring`, which then sets its own iteration counts): W when it is evaluated, the
    /// wall time, the free unknowns and why it stopped; the key `times` are kept as given.
    pub fn closed_form(method: Method, energy: Vec<f64>, seconds: f64, unknowns: usize, stop_reason: String, times: Vec<f64>) -> SolverLog {
        SolverLog {
            method,
            iterations: 0,
            energy,
            seconds,
            precompute_seconds: 0.0,
            iteration_seconds: 0.0,
            unknowns,
            halvings: 0,
            converged: true,
            stop_reason,
            linear_solver: String::new(),
            last_decrease: 0.0,
            predicted_remaining: None,
            force_scale: None,
            force_scales: Vec::new(),
            input_times: times.clone(),
            times,
            timing_iterations: 0,
            refactorizations: 0,
            active_contacts: 0,
            clearance: None,
            conjugate_gradients: None,
            coarse_iterations: 0,
            coarse_samples: 0,
            iteration_split: None,
        }
    }

    /// The log of a spacetime solve: the solver's own `log`, the key times given to it and
    /// those of its solution, and the force scale S at each iterate (the progress callback's).
    pub fn spacetime(log: solver::Log, input_times: Vec<f64>, times: Vec<f64>, force_scales: Vec<f64>) -> SolverLog {
        let split = log.split;
        SolverLog {
            method: Method::Spacetime,
            iterations: log.iterations,
            seconds: log.seconds,
            precompute_seconds: log.precompute_seconds,
            iteration_seconds: log.iteration_seconds,
            unknowns: log.unknowns,
            halvings: log.halvings,
            converged: log.converged,
            linear_solver: log.linear_solver,
            last_decrease: log.last_decrease,
            predicted_remaining: log.predicted_remaining,
            force_scale: Some(log.force_scale),
            force_scales,
            input_times,
            times,
            timing_iterations: log.timing_iterations,
            refactorizations: log.refactorizations,
            active_contacts: log.active_contacts,
            clearance: log.clearance,
            conjugate_gradients: log.conjugate_gradients.map(|c| CgSummary {
                solves: c.solves,
                iterations: c.iterations,
                capped: c.capped,
                max_iterations: c.max_iterations,
                tolerance: c.tolerance,
                worst_residual: c.worst_residual,
            }),
            coarse_iterations: log.coarse_iterations,
            coarse_samples: log.coarse_samples,
            iteration_split: Some(split),
            stop_reason: log.stop_reason,
            energy: log.energy,
        }
    }
}

/// The conjugate-gradient solves of an iterative global step.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CgSummary {
    /// Global-step solves (one per iteration of the solver, and per constraint projection).
    pub solves: usize,
    /// CG iterations over all solves.
    pub iterations: usize,
    /// Solves that stopped at `max_iterations` with the residual above `tolerance`.
    pub capped: usize,
    /// The iteration cap of one solve.
    pub max_iterations: usize,
    /// The relative residual a solve stops at.
    pub tolerance: f64,
    /// The largest final relative residual of any solve.
    pub worst_residual: f64,
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

/// Names the stage a file holds, so a wrong file passed to a subcommand is caught at once.
pub trait StageData: Serialize + DeserializeOwned {
    /// The stage name in the file header.
    const STAGE: &'static str;
    /// The subcommand that writes it.
    const WRITER: &'static str;
    /// The invariants the types document but JSON cannot enforce (lengths, index ranges,
    /// increasing times, finite numbers, the embedded scene), checked when a file is read, so a
    /// hand-edited or damaged file fails here with one line instead of deep inside a stage.
    /// The memory the stages after it need is checked against `budget`.
    fn validate(&self, budget: &Budget) -> Result<()>;
    /// The surfaces the data carries, whose texture paths (absolute in memory) the file holds
    /// relative to its own folder ([`write()`], [`read`]), so a staged folder can be moved.
    fn surfaces_mut(&mut self) -> Vec<&mut TriMesh> {
        Vec::new()
    }
    /// Whether any surface has a texture (so [`write()`] has paths to rewrite).
    fn has_textures(&self) -> bool {
        false
    }
    /// The cache record the data carries (`[cache]` scenes), whose paths (the cache, its rest
    /// mesh) the file holds relative to its own folder like the textures.
    fn cache(&self) -> Option<&CacheRecord> {
        None
    }
    /// See [`StageData::cache`].
    fn cache_mut(&mut self) -> Option<&mut CacheRecord> {
        None
    }
    /// Whether the data names files other than textures ([`StageData::files_mut`]).
    fn has_files(&self) -> bool {
        self.cache().is_some()
    }
    /// The file paths the data names other than textures: the cache and its rest mesh, and the
    /// keyframes' rest source. The file holds them relative to its own folder like the textures.
    fn files_mut(&mut self) -> Vec<&mut String> {
        self.cache_mut().into_iter().flat_map(cache_paths_mut).collect()
    }
}

impl StageData for Keyframes {
    const STAGE: &'static str = "keyframes";
    const WRITER: &'static str = "blendsim import";
    fn surfaces_mut(&mut self) -> Vec<&mut TriMesh> {
        let rest = match &mut self.rest {
            Shape::Surface(m) => Some(m),
            Shape::Volume(_) => None,
        };
        rest.into_iter().chain(self.display.as_mut()).collect()
    }
    fn has_textures(&self) -> bool {
        matches!(&self.rest, Shape::Surface(m) if textured(m)) || self.display.as_ref().is_some_and(textured)
    }
    fn cache(&self) -> Option<&CacheRecord> {
        self.cache.as_ref()
    }
    fn cache_mut(&mut self) -> Option<&mut CacheRecord> {
        self.cache.as_mut()
    }
    fn has_files(&self) -> bool {
        true
    }
    fn files_mut(&mut self) -> Vec<&mut String> {
        std::iter::once(&mut self.rest_source).chain(self.cache.iter_mut().flat_map(cache_paths_mut)).collect()
    }
    fn validate(&self, budget: &Budget) -> Result<()> {
        let rerun = Check(Self::WRITER, contact_keys(&self.scene), budget);
        rerun.scene(&self.scene)?;
        let n = match &self.rest {
            Shape::Surface(m) => rerun.tri_mesh("rest surface", m)?,
            Shape::Volume(m) => rerun.tet_mesh("rest mesh", m)?,
        };
        rerun.times("times", &self.times)?;
        let keys = self.times.len();
        rerun.poses("poses", &self.poses, keys, n)?;
        rerun.sets("fixed", &self.fixed, keys, n)?;
        rerun.sets("fixed_velocity", &self.fixed_velocity, keys, n)?;
        rerun.cyclic(self.cyclic, keys)?;
        if let Some(display) = &self.display {
            rerun.tri_mesh("display surface", display)?;
        }
        let tets = match &self.rest {
            Shape::Surface(m) => m.triangles.len().div_ceil(4),
            Shape::Volume(m) => m.tets.len(),
        };
        let vertices = self.display.as_ref().map_or(n, |d| d.positions.len());
        rerun.resources(&self.scene, &self.times, vertices, tets)
    }
}
impl StageData for Body {
    const STAGE: &'static str = "body";
    const WRITER: &'static str = "blendsim tetrahedralize";
    fn surfaces_mut(&mut self) -> Vec<&mut TriMesh> {
        vec![&mut self.surface]
    }
    fn has_textures(&self) -> bool {
        textured(&self.surface)
    }
    fn cache(&self) -> Option<&CacheRecord> {
        self.cache.as_ref()
    }
    fn cache_mut(&mut self) -> Option<&mut CacheRecord> {
        self.cache.as_mut()
    }
    fn validate(&self, budget: &Budget) -> Result<()> {
        let rerun = Check(Self::WRITER, contact_keys(&self.scene), budget);
        rerun.scene(&self.scene)?;
        // Without a tet mesh (method fit) the keys are the surface's own.
        let surface = rerun.tri_mesh("surface", &self.surface)?;
        let n = match &self.mesh {
            Some(m) => rerun.tet_mesh("mesh", m)?,
            None => surface,
        };
        rerun.key_poses(&self.keys, n)?;
        rerun.resources(&self.scene, &self.keys.times, surface, self.mesh.as_ref().map_or(0, |m| m.tets.len()))
    }
}
impl StageData for Solution {
    const STAGE: &'static str = "solution";
    const WRITER: &'static str = "blendsim solve";
    fn surfaces_mut(&mut self) -> Vec<&mut TriMesh> {
        vec![&mut self.body.surface]
    }
    fn has_textures(&self) -> bool {
        textured(&self.body.surface)
    }
    fn cache(&self) -> Option<&CacheRecord> {
        self.body.cache.as_ref()
    }
    fn cache_mut(&mut self) -> Option<&mut CacheRecord> {
        self.body.cache.as_mut()
    }
    fn validate(&self, budget: &Budget) -> Result<()> {
        let rerun = Check(Self::WRITER, contact_keys(&self.body.scene), budget);
        rerun.scene(&self.body.scene)?;
        let surface = rerun.tri_mesh("body surface", &self.body.surface)?;
        let (n, of) = match &self.body.mesh {
            Some(m) => (rerun.tet_mesh("body mesh", m)?, "tet nodes"),
            None => (surface, "surface vertices"),
        };
        rerun.key_poses(&self.body.keys, n)?;
        rerun.trajectory(&self.trajectory, n, of)?;
        rerun.resources(&self.body.scene, &self.trajectory.times, self.body.surface.positions.len(), 0)
    }
}
impl StageData for Animation {
    const STAGE: &'static str = "animation";
    const WRITER: &'static str = "blendsim embed";
    fn surfaces_mut(&mut self) -> Vec<&mut TriMesh> {
        vec![&mut self.mesh]
    }
    fn has_textures(&self) -> bool {
        textured(&self.mesh)
    }
    fn cache(&self) -> Option<&CacheRecord> {
        self.cache.as_ref()
    }
    fn cache_mut(&mut self) -> Option<&mut CacheRecord> {
        self.cache.as_mut()
    }
    fn validate(&self, budget: &Budget) -> Result<()> {
        let rerun = Check(Self::WRITER, contact_keys(&self.scene), budget);
        rerun.scene(&self.scene)?;
        let n = rerun.tri_mesh("mesh", &self.mesh)?;
        rerun.trajectory(&self.trajectory, n, "mesh vertices")?;
        // mass-spring's in-betweens are keys of the trajectory but not input keys.
        let input_keys = match self.log.method {
            Method::MassSpring => (self.trajectory.key_count().saturating_sub(1)) / (self.scene.mass_spring.inbetweens + 1) + 1,
            _ => self.trajectory.key_count(),
        };
        rerun.poses("input_keys", &self.input_keys, input_keys, n)?;
        let c = &self.counts;
        if c.vertices != n || c.faces != self.mesh.triangles.len() {
            return rerun.fail(format!(
                "counts say {} vertices and {} faces but the mesh has {n} and {}",
                c.vertices,
                c.faces,
                self.mesh.triangles.len()
            ));
        }
        rerun.resources(&self.scene, &self.trajectory.times, n, 0)
    }
}
impl StageData for Outputs {
    const STAGE: &'static str = "outputs";
    const WRITER: &'static str = "blendsim export";
    fn validate(&self, budget: &Budget) -> Result<()> {
        if self.rank == Some(0) {
            return Check(Self::WRITER, 0, budget).fail("rank is 0 (a principal clip has at least one component)".into());
        }
        for (i, f) in self.files.iter().enumerate() {
            let plain = !f.path.is_empty() && !f.path.starts_with('.') && !f.path.contains(['/', '\\']) && !f.path.chars().any(char::is_control);
            if !plain {
                return Check(Self::WRITER, 0, budget)
                    .fail(format!("files[{i}] is {}, not a plain file name", crate::support::error::quoted(&f.path)));
            }
        }
        Ok(())
    }
}

/// The checks behind [`StageData::validate`]. Each returns the first problem, with the fix of
/// re-running the subcommand that writes the stage (`.0`). `.1` is the number of contact keys
/// of the scene: each is a zero-length interval, so that many key times may repeat. `.2` is
/// the budget the next stages run under.
struct Check<'a>(&'static str, usize, &'a Budget);

/// The contact keys of a scene (`contact = [k]`; none for a cache).
fn contact_keys(scene: &Scene) -> usize {
    scene.keyframes.as_ref().map_or(0, |k| k.contact.len())
}

impl Check<'_> {
    fn fail<T>(&self, problem: String) -> Result<T> {
        Err(Error::general(problem, format!("the file was edited or damaged; re-run `{}` to rewrite it", self.0)))
    }

    /// The embedded scene: the same rules as a scene file (name, fps > 0, every table).
    fn scene(&self, scene: &Scene) -> Result<()> {
        scene.validate().map_err(|e| {
            Error::general(
                format!("its scene: {}", e.problem),
                format!("{}; edit the scene file, then re-run the chain from `blendsim import`", e.fix),
            )
        })
    }

    /// The memory the stages after this one need, within the budget.
    fn resources(&self, scene: &Scene, times: &[f64], vertices: usize, tets: usize) -> Result<()> {
        scene
            .check_resources(times, vertices, tets, self.2)
            .map_err(|e| Error::general(e.problem, format!("{}; edit the scene file, then re-run the chain from `blendsim import`", e.fix)))
    }

    fn points(&self, what: &str, points: &[Point]) -> Result<()> {
        match points.iter().position(|p| p.iter().any(|x| !x.is_finite())) {
            Some(v) => self.fail(format!("{what} has a non-finite coordinate at vertex {v}")),
            None => Ok(()),
        }
    }

    /// Finite positions, triangle indices in range, at least one triangle. Returns the vertex count.
    fn tri_mesh(&self, what: &str, m: &TriMesh) -> Result<usize> {
        let n = m.positions.len();
        self.points(what, &m.positions)?;
        if m.triangles.is_empty() {
            return self.fail(format!("{what} has no triangles"));
        }
        if let Some(t) = m.triangles.iter().position(|t| t.iter().any(|&i| i as usize >= n)) {
            return self.fail(format!("{what} triangle {t} uses vertex {}, but there are {n} vertices", m.triangles[t].iter().max().unwrap()));
        }
        Ok(n)
    }

    /// Finite positions, tet indices in range, every tet positively oriented ([`TetMesh`]'s
    /// invariant). Returns the node count.
    fn tet_mesh(&self, what: &str, m: &TetMesh) -> Result<usize> {
        let n = m.positions.len();
        self.points(what, &m.positions)?;
        if m.tets.is_empty() {
            return self.fail(format!("{what} has no tets"));
        }
        if let Some(t) = m.tets.iter().position(|t| t.iter().any(|&i| i as usize >= n)) {
            return self.fail(format!("{what} tet {t} uses node {}, but there are {n} nodes", m.tets[t].iter().max().unwrap()));
        }
        if let Some(t) = (0..m.tets.len()).find(|&t| m.signed_volume_at(&m.positions, t).partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater)) {
            return self
                .fail(format!("{what} tet {t} is inverted or flat in the rest pose (signed volume {:e})", m.signed_volume_at(&m.positions, t)));
        }
        Ok(n)
    }

    /// At least two finite, strictly increasing times.
    fn times(&self, what: &str, times: &[f64]) -> Result<()> {
        if times.len() < 2 {
            return self.fail(format!("{what} has {} key times, at least 2 are needed", times.len()));
        }
        if let Some(k) = times.iter().position(|t| !t.is_finite()) {
            return self.fail(format!("{what}[{k}] is not a finite number"));
        }
        // A contact key and its duplicate share their time; nothing else may.
        let repeats = times.windows(2).filter(|w| w[0] == w[1]).count();
        let triple = times.windows(3).any(|w| w[0] == w[2]);
        if let Some(k) = times.windows(2).position(|w| w[0] > w[1] || (w[0] == w[1] && (repeats > self.1 || triple))) {
            return self.fail(format!("{what} do not increase at key {} ({} after {})", k + 1, times[k + 1], times[k]));
        }
        Ok(())
    }

    /// `keys` poses of `n` finite points each.
    fn poses(&self, what: &str, poses: &[Vec<Point>], keys: usize, n: usize) -> Result<()> {
        if poses.len() != keys {
            return self.fail(format!("{what} has {} poses for {keys} key times", poses.len()));
        }
        for (k, pose) in poses.iter().enumerate() {
            if pose.len() != n {
                return self.fail(format!("{what}[{k}] has {} points but the mesh has {n}", pose.len()));
            }
            self.points(&format!("{what}[{k}]"), pose)?;
        }
        Ok(())
    }

    /// One set per key, each strictly increasing and below `n`.
    fn sets(&self, what: &str, sets: &[VertexSet], keys: usize, n: usize) -> Result<()> {
        if sets.len() != keys {
            return self.fail(format!("{what} has {} sets for {keys} keys", sets.len()));
        }
        for (k, s) in sets.iter().enumerate() {
            if let Some(&i) = s.indices().iter().find(|&&i| i as usize >= n) {
                return self.fail(format!("{what}[{k}] holds index {i}, but there are {n} vertices"));
            }
            if s.indices().windows(2).any(|w| w[0] >= w[1]) {
                return self.fail(format!("{what}[{k}] is not sorted without repeats"));
            }
        }
        Ok(())
    }

    fn cyclic(&self, cyclic: bool, keys: usize) -> Result<()> {
        if cyclic && keys < 3 {
            return self.fail(format!("cyclic is true with {keys} keys (at least 3 are needed)"));
        }
        Ok(())
    }

    fn key_poses(&self, keys: &KeyPoses, n: usize) -> Result<()> {
        self.times("keys.times", &keys.times)?;
        let k = keys.times.len();
        self.poses("keys.positions", &keys.positions, k, n)?;
        self.sets("keys.fixed", &keys.fixed, k, n)?;
        self.sets("keys.fixed_velocity", &keys.fixed_velocity, k, n)?;
        self.cyclic(keys.cyclic, k)
    }

    /// Key times, positions and velocities of `n` points each.
    fn trajectory(&self, tr: &Trajectory, n: usize, of: &str) -> Result<()> {
        self.times("trajectory.times", &tr.times)?;
        let k = tr.times.len();
        for (what, keys) in [("trajectory.positions", &tr.positions), ("trajectory.velocities", &tr.velocities)] {
            if keys.len() != k {
                return self.fail(format!("{what} has {} keys for {k} key times", keys.len()));
            }
            for (key, pose) in keys.iter().enumerate() {
                if pose.len() != n {
                    return self.fail(format!("{what}[{key}] has {} points for {n} {of}", pose.len()));
                }
                self.points(&format!("{what}[{key}]"), pose)?;
            }
        }
        Ok(())
    }
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
