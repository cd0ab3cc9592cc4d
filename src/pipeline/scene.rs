//! The scene file (TOML): what to bake and how. Specified in `formats/scene.md`.
//!
//! Parsing is strict: an unknown key is an error that names it and its line, so a typo never
//! silently falls back to a default. Paths stay as written; [`SceneFile::resolve`] turns them
//! into paths relative to the scene file's folder.

use std::fmt;
use std::path::{Path, PathBuf};

use serde::de::{self, Deserializer, MapAccess, SeqAccess, Visitor};
use serde::{Deserialize, Serialize};

pub use crate::algorithms::blendshape::clip::Weights;
pub use crate::algorithms::geometry::Axis;
pub use crate::algorithms::procedural::Twist;
use crate::support::budget::Budget;
use crate::support::error::{number, Error, Result};

mod cache_table;
mod keyframe_clip;
pub(crate) mod memory_model;
pub use cache_table::{CacheKeys, CacheSpec, DEFAULT_TOLERANCE};
pub use memory_model::{BakeCounts, PhaseBytes, StepChoice};

/// A parsed, validated scene and the folder its relative paths resolve against.
#[derive(Debug, Clone)]
pub struct SceneFile {
    /// Where the scene was read from.
    pub path: PathBuf,
    /// Its content.
    pub scene: Scene,
}

impl SceneFile {
    /// Read, parse and validate a scene file.
    pub fn load(path: &Path) -> Result<SceneFile> {
        let text = crate::support::input::read_text(path, "the scene file")?;
        let text = text.strip_prefix('\u{feff}').unwrap_or(&text);
        let scene = Scene::parse(text).map_err(|e| e.with_path(path))?;
        Ok(SceneFile { path: path.to_path_buf(), scene })
    }

    /// A path from the scene file, resolved against the scene file's folder.
    pub fn resolve(&self, relative: &str) -> PathBuf {
        let p = Path::new(relative);
        if p.is_absolute() {
            p.to_path_buf()
        } else {
            self.path.parent().unwrap_or(Path::new(".")).join(p)
        }
    }
}

/// A scene: what to bake and how, one field per table of the file.
///
/// Invariants once parsed ([`Scene::parse`]): every value is in range (see `formats/scene.md`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scene {
    /// Stem of every output file.
    pub name: String,
    /// Full-frame rate, and the USD weight sample rate (frames per second).
    #[serde(default = "default_fps")]
    pub fps: f64,
    /// The length unit of every coordinate and length in the input (`None`: `[export]
    /// meters_per_unit`, by default meters); see [`Scene::meters_per_unit`].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub units: Option<Units>,
    /// `[keyframes]`: the keyframe meshes, their times and constraints (exclusive with
    /// `[cache]`: a scene has exactly one of them).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub keyframes: Option<KeyframeSpec>,
    /// `[cache]`: a vertex cache whose frames give the keys (see [`CacheSpec`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cache: Option<CacheSpec>,
    /// `[tet]`: TetGen's settings.
    #[serde(default)]
    pub tet: Tet,
    /// `[material]`: the body's physics.
    #[serde(default)]
    pub material: Material,
    /// `[solver]`: the method and its settings.
    #[serde(default)]
    pub solver: Solver,
    /// `[embed]`: the surface carried on the body.
    #[serde(default)]
    pub embed: Embed,
    /// `[export]`: the files to write.
    #[serde(default)]
    pub export: Export,
    /// `[mass_spring]`: the in-betweens of `[solver] method = "mass-spring"`.
    #[serde(default)]
    pub mass_spring: MassSpring,
    /// `[[obstacle]]`: static obstacles the body may not enter.
    #[serde(default, rename = "obstacle", skip_serializing_if = "Vec::is_empty")]
    pub obstacles: Vec<ObstacleSpec>,
}

/// The input's length unit (`units`): a name, or the meters in one unit.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum Units {
    /// One of [`UNIT_NAMES`].
    Name(String),
    /// Meters per unit (> 0).
    MetersPerUnit(f64),
}

/// The unit names `units` accepts, with their meters, the most used first.
pub const UNIT_NAMES: [(&str, f64); 7] = [("m", 1.0), ("cm", 0.01), ("mm", 0.001), ("in", 0.0254), ("ft", 0.3048), ("dm", 0.1), ("km", 1000.0)];

impl Units {
    /// Meters per unit (`None` for an unknown name or a number that is not positive).
    pub fn meters_per_unit(&self) -> Option<f64> {
        match self {
            Units::Name(name) => UNIT_NAMES.iter().find(|(n, _)| n == name).map(|&(_, m)| m),
            Units::MetersPerUnit(m) => (m.is_finite() && *m > 0.0).then_some(*m),
        }
    }
}

/// One `[[obstacle]]` entry.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase", deny_unknown_fields)]
pub enum ObstacleSpec {
    /// The half-space behind a plane: `point` on it, `normal` pointing out of the obstacle.
    Plane {
        /// A point on the plane.
        point: [f64; 3],
        /// The outward normal (any nonzero length).
        normal: [f64; 3],
    },
    /// A solid sphere.
    Sphere {
        /// Its centre.
        center: [f64; 3],
        /// Its radius (> 0).
        radius: f64,
    },
}

fn default_fps() -> f64 {
    60.0
}

/// The `[keyframes]` table.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct KeyframeSpec {
    /// One mesh per key: a path, or `{ mesh = PATH, twist = {...} }` for a procedurally
    /// deformed copy (empty with `clip`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub meshes: Vec<KeyMesh>,
    /// Key times in seconds, strictly increasing: one per mesh, or with `clip` the clip's
    /// frames to take (instead of `frames`).
    #[serde(default)]
    pub times: Vec<f64>,
    /// An animated file (any vertex cache format blendsim reads) whose frames give the keys,
    /// at `frames` or `times`, instead of `meshes` (`formats/scene.md`, "Keys from a clip").
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub clip: Option<String>,
    /// With `clip`: the clip's frames to take (0-based, file order, strictly increasing).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frames: Option<Vec<usize>>,
    /// With `clip`: its frames per second, for the formats that carry none (OBJ sequence, PC2).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fps: Option<f64>,
    /// With a glTF `clip`: the animation to evaluate (default: the only one).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub animation: Option<String>,
    /// With a USD `clip`: the Mesh prim (default: the only animated Mesh).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub prim: Option<String>,
    /// With an Alembic or FBX `clip`: the mesh object (default: the only animated one).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub object: Option<String>,
    /// With an FBX `clip`: the take (animation stack; default: the only one).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub take: Option<String>,
    /// Per key, the vertices whose position is prescribed (default: "all" at every key).
    #[serde(default)]
    pub fixed: Option<Vec<Selection>>,
    /// Per key, the vertices whose velocity is prescribed to zero (default: "none").
    #[serde(default)]
    pub fixed_velocity: Option<Vec<Selection>>,
    /// The first and last keys share positions and velocities.
    #[serde(default)]
    pub cyclic: bool,
    /// The elastic rest shape: a key index (default 0) or a mesh path with the keys' topology.
    #[serde(default)]
    pub rest: Rest,
    /// Contact keys: each listed key is duplicated at the same time (a zero-length interval),
    /// the two sharing their pose but not their velocities, so the velocity can jump there.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub contact: Vec<usize>,
}

/// The `[tet]` table (defaults: [`Tet::default`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Tet {
    /// TetGen `-q` radius-edge ratio bound (0 = no quality refinement).
    pub quality: f64,
    /// TetGen `-a` maximum tet volume; 0 means no bound.
    pub max_volume: f64,
    /// Seconds TetGen may run before it is stopped.
    pub timeout: f64,
    /// Simulate a surface that is too fine (more than `max_nodes` vertices) or messy (open,
    /// in several parts, non-manifold, self-intersecting) on an automatic cage around it;
    /// `false` sends every surface to TetGen as it is.
    pub cage: bool,
    /// Surfaces with more vertices than this are simulated on a cage.
    pub max_nodes: usize,
    /// Tet nodes a generated cage aims at.
    pub cage_nodes: usize,
}

/// The `[material]` table (defaults: [`Material::default`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Material {
    /// Strain (as-rigid-as-possible) constraint weight per unit rest volume.
    pub stiffness: f64,
    /// Volume-preservation constraint weight per unit rest volume.
    pub volume: f64,
    /// Mass per unit rest volume (lumped to the nodes).
    pub density: f64,
    /// Rayleigh mass damping: D = damping * M (per second).
    pub damping: f64,
    /// Gravitational acceleration (units per second squared), applied as M g.
    #[serde(deserialize_with = "three_components")]
    pub gravity: [f64; 3],
}

/// How the trajectory is made (`[solver] method`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Method {
    /// Keyframes joined by cubic Hermite curves with zero velocities (the geometric baseline).
    Hermite,
    /// BlendSim's spacetime projective dynamics.
    Spacetime,
    /// Mass-spring blendshapes (Ma et al. 2012): in-between shapes from blended spring rest
    /// lengths (`[mass_spring]`).
    MassSpring,
    /// The least-squares cubic Hermite fit of a cache on its keys, no physics (`[cache]` only).
    Fit,
}

impl fmt::Display for Method {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Method::Hermite => "hermite",
            Method::Spacetime => "spacetime",
            Method::MassSpring => "mass-spring",
            Method::Fit => "fit",
        })
    }
}

/// The `[solver]` table (defaults: [`Solver::default`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Solver {
    /// The method.
    pub method: Method,
    /// Sample points per interval at which the residual force is evaluated.
    pub samples: usize,
    /// Iterations before the solver stops unconverged.
    pub max_iterations: usize,
    /// Stop when W fell by less than `tolerance × (W + 0.001 S)` over the last 10 quasi-Newton
    /// iterations (S: the force scale; `spacetime::solver`, "When it stops").
    pub tolerance: f64,
    /// Proximal regularization time scale h: adds (1/h⁴) Σ dτ BᵀMB (0 = off).
    pub regularization: f64,
    /// Residual samples on the intervals that begin or end at a contact.
    pub contact_samples: usize,
    /// Optimize the key times too.
    pub optimize_timing: bool,
    /// With `optimize_timing`: keep the total duration.
    pub keep_duration: bool,
    /// With `optimize_timing`: keys (scene indices) whose time may not move.
    pub fixed_times: Vec<usize>,
    /// With `optimize_timing`: the shortest interval (seconds).
    pub min_interval: f64,
    /// The quasi-Newton phase's model Hessian: `"auto"`, `"projective"` or `"tangent"`
    /// (see `spacetime::settings::ModelHessian`).
    pub model_hessian: String,
    /// How the global step is inverted: `"auto"` (the cheapest predicted within the memory
    /// budget), `"direct"`, `"modal"` or `"iterative"` (see `spacetime::global_step::Method`).
    pub global_step: String,
    /// Samples per interval of a first, coarse solve whose result the solve at `samples`
    /// starts from (0: none; not used with obstacles or `optimize_timing`, nor when not below
    /// `samples`; see `spacetime::solver`, "Coarse to fine").
    pub coarse_samples: usize,
    /// The quasi-Newton phase's step: `"auto"`, `"quasi-newton"` (L-BFGS) or `"gauss-newton"`
    /// (truncated CG on the Gauss-Newton Hessian; see `spacetime::settings::Step`).
    pub step: String,
}

/// The `[embed]` table.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Embed {
    /// A finer surface (OBJ, in the rest pose) to carry on the tet trajectory; by default the
    /// exported surface is the keyframe surface itself.
    #[serde(default)]
    pub surface: Option<String>,
}

/// An output file format (`[export] formats`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Format {
    /// USD, text.
    Usda,
    /// USD, binary crate (converted by usd-core).
    Usdc,
    /// Binary glTF.
    Glb,
}

impl Format {
    /// The file extension.
    pub fn extension(self) -> &'static str {
        match self {
            Format::Usda => "usda",
            Format::Usdc => "usdc",
            Format::Glb => "glb",
        }
    }
}

impl fmt::Display for Format {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.extension())
    }
}

/// The `[export]` table (defaults: [`Export::default`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Export {
    /// The formats to write, each as blendshapes (and full-frame when `full_frame`).
    pub formats: Vec<Format>,
    /// Also write the full-frame versions (one pose per frame) for comparison.
    pub full_frame: bool,
    /// The scene's up axis, "y" or "z" (USD `upAxis`; glTF files are rotated to y-up).
    pub up_axis: Axis,
    /// Scene units in meters: the older alias of the scene's `units` ([`Scene::meters_per_unit`]).
    pub meters_per_unit: f64,
    /// The blendshape form of the trajectory in every blendshape file.
    pub weights: Weights,
    /// How the blendshape glTF animates its weights.
    pub gltf_interpolation: GltfInterpolation,
    /// How every glb stores its data: quantized (default), quantized + meshopt, or f32.
    pub gltf_compression: crate::formats::export::glb::Compression,
    /// Give the blendshape glTF's morph targets NORMAL deltas (each target's recomputed
    /// normals minus the base's), for renderers that shade a morphed mesh with the file's
    /// normals (three.js, engines); Blender recomputes them. Off by default: it adds about as
    /// many bytes as the POSITION targets (README, "Animated normals").
    pub gltf_morph_normals: bool,
    /// The shapes of the blendshape files (`None`: [`Export::basis_for`] decides by the input).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub basis: Option<Basis>,
    /// For `basis = "principal"`: the number of components (`None`: the smallest meeting the
    /// tolerance, see `formats/scene.md`). Positive.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rank: Option<usize>,
}

/// The shapes of the blendshape files (`[export] basis`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Basis {
    /// A shape per key pose and per key velocity or control point (sparse): editable per key.
    #[default]
    Keys,
    /// A few principal components of those shapes (dense), chosen to meet the tolerance: the
    /// smallest files of long motions. The default for a `[cache]` scene.
    Principal,
}

/// The interpolation of the blendshape glTF's weight animation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum GltfInterpolation {
    /// Weights and their slopes at the keys: the trajectory exactly, at any instant.
    Cubicspline,
    /// Weights sampled at every frame: exact at frames, linear in between (Blender plays it).
    Linear,
}

// The defaults of every table, written once: `#[serde(default)]` fills a missing key from these.

impl Default for Tet {
    fn default() -> Self {
        // max_nodes: a 5-key bake of a 3k-node body takes about 5 s and 1 GB on 2 cores;
        // cage_nodes: the paper's cages (922 nodes for CHEB) bake 10 keys in seconds.
        Tet { quality: 1.414, max_volume: 0.0, timeout: 120.0, cage: true, max_nodes: 3000, cage_nodes: 1000 }
    }
}

impl Default for Material {
    fn default() -> Self {
        Material { stiffness: 70.0, volume: 70.0, density: 1.0, damping: 0.1, gravity: [0.0; 3] }
    }
}

impl Default for Solver {
    fn default() -> Self {
        Solver {
            method: Method::Spacetime,
            samples: 10,
            max_iterations: crate::algorithms::spacetime::settings::DEFAULT_MAX_ITERATIONS,
            tolerance: crate::algorithms::spacetime::settings::DEFAULT_TOLERANCE,
            regularization: 0.1,
            contact_samples: 20,
            optimize_timing: false,
            keep_duration: false,
            fixed_times: Vec::new(),
            min_interval: 1e-3,
            model_hessian: "auto".to_string(),
            global_step: "auto".to_string(),
            coarse_samples: crate::algorithms::spacetime::settings::DEFAULT_COARSE_SAMPLES,
            step: "auto".to_string(),
        }
    }
}

impl Default for Export {
    fn default() -> Self {
        Export {
            formats: vec![Format::Usda, Format::Glb],
            full_frame: true,
            up_axis: Axis::Y,
            meters_per_unit: 1.0,
            weights: Weights::Bernstein,
            gltf_interpolation: GltfInterpolation::Linear,
            gltf_compression: Default::default(),
            gltf_morph_normals: false,
            basis: None,
            rank: None,
        }
    }
}

/// One keyframe mesh: a file, optionally deformed procedurally.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(untagged)]
pub enum KeyMesh {
    /// A mesh file, as written in the scene.
    Path(String),
    /// `{ mesh = PATH, twist = {...} }`.
    Deformed(DeformedMesh),
}

/// A mesh file and the deformation applied to it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DeformedMesh {
    /// The mesh file, as written in the scene.
    pub mesh: String,
    /// A twist about an axis.
    #[serde(default)]
    pub twist: Option<Twist>,
    /// A translation, applied after the twist (e.g. one mesh dropped from several heights).
    #[serde(default, deserialize_with = "optional_offset", skip_serializing_if = "Option::is_none")]
    pub offset: Option<[f64; 3]>,
}

impl KeyMesh {
    /// The mesh file, as written in the scene.
    pub fn path(&self) -> &str {
        match self {
            KeyMesh::Path(p) => p,
            KeyMesh::Deformed(d) => &d.mesh,
        }
    }

    /// The deformation, if any.
    pub fn twist(&self) -> Option<&Twist> {
        match self {
            KeyMesh::Path(_) => None,
            KeyMesh::Deformed(d) => d.twist.as_ref(),
        }
    }

    /// The translation, if any.
    pub fn offset(&self) -> Option<[f64; 3]> {
        match self {
            KeyMesh::Path(_) => None,
            KeyMesh::Deformed(d) => d.offset,
        }
    }
}

/// The elastic rest shape.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(untagged)]
pub enum Rest {
    /// The pose of this key.
    Key(usize),
    /// A mesh file with the keys' topology.
    Mesh(String),
}

impl Default for Rest {
    fn default() -> Self {
        Rest::Key(0)
    }
}

/// A set of vertices of one keyframe.
///
/// - `"all"`, `"none"`;
/// - a path: a `.txt` file of 0-based vertex indices, one per line (`#` comments allowed), or
///   a libigl `.dmat` column of 0/1 flags, one per vertex;
/// - `{ file = PATH, invert = true }`: the same, complemented;
/// - `{ axis = "y", min = A, max = B, invert = false }`: vertices whose rest-pose coordinate
///   on `axis` lies in `[min, max]` (either bound may be omitted);
/// - a list of the above: their union.
#[derive(Debug, Clone, PartialEq)]
pub enum Selection {
    /// Every vertex.
    All,
    /// No vertex.
    None,
    /// The vertices a selection file lists (see [`crate::formats::mesh::selection`]), or the others.
    File {
        /// The file, as written in the scene.
        file: String,
        /// Select the vertices the file does not list.
        invert: bool,
    },
    /// The vertices whose rest coordinate on `axis` is in `[min, max]`, or the others.
    Slab {
        /// The coordinate tested.
        axis: Axis,
        /// Lower bound (none: unbounded).
        min: Option<f64>,
        /// Upper bound (none: unbounded).
        max: Option<f64>,
        /// Select the vertices outside the slab.
        invert: bool,
    },
    /// The union of the listed selections.
    Union(Vec<Selection>),
}

/// Written back in the scene syntax, so a stage file's scene reads like the scene file.
impl Serialize for Selection {
    fn serialize<S: serde::Serializer>(&self, ser: S) -> std::result::Result<S::Ok, S::Error> {
        use serde::ser::{SerializeMap, SerializeSeq};
        match self {
            Selection::All => ser.serialize_str("all"),
            Selection::None => ser.serialize_str("none"),
            Selection::File { file, invert: false } => ser.serialize_str(file),
            Selection::File { file, invert: true } => {
                let mut m = ser.serialize_map(Some(2))?;
                m.serialize_entry("file", file)?;
                m.serialize_entry("invert", &true)?;
                m.end()
            }
            Selection::Slab { axis, min, max, invert } => {
                let mut m = ser.serialize_map(None)?;
                m.serialize_entry("axis", axis)?;
                if let Some(lo) = min {
                    m.serialize_entry("min", lo)?;
                }
                if let Some(hi) = max {
                    m.serialize_entry("max", hi)?;
                }
                if *invert {
                    m.serialize_entry("invert", &true)?;
                }
                m.end()
            }
            Selection::Union(items) => {
                let mut seq = ser.serialize_seq(Some(items.len()))?;
                for item in items {
                    seq.serialize_element(item)?;
                }
                seq.end()
            }
        }
    }
}

// --- Deserialization of the string-or-table entries, with precise messages. ---

/// A vector of exactly three numbers (serde's own `[f64; 3]` would drop a fourth).
fn three_components<'de, D: Deserializer<'de>>(d: D) -> std::result::Result<[f64; 3], D::Error> {
    let v = Vec::<f64>::deserialize(d)?;
    <[f64; 3]>::try_from(v.as_slice()).map_err(|_| de::Error::custom(format!("expected 3 components (x, y, z), found {}", v.len())))
}

/// A keyframe mesh's `offset`: three finite numbers.
fn optional_offset<'de, D: Deserializer<'de>>(d: D) -> std::result::Result<Option<[f64; 3]>, D::Error> {
    let v = three_components(d)?;
    if v.iter().any(|x| !x.is_finite()) {
        return Err(de::Error::custom(format!("offset must be three finite numbers, found {v:?}")));
    }
    Ok(Some(v))
}

impl<'de> Deserialize<'de> for KeyMesh {
    fn deserialize<D: Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = KeyMesh;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("a mesh path or a table { mesh = PATH, twist = {...} }")
            }
            fn visit_str<E: de::Error>(self, s: &str) -> std::result::Result<KeyMesh, E> {
                Ok(KeyMesh::Path(s.to_string()))
            }
            fn visit_map<A: MapAccess<'de>>(self, map: A) -> std::result::Result<KeyMesh, A::Error> {
                DeformedMesh::deserialize(de::value::MapAccessDeserializer::new(map)).map(KeyMesh::Deformed)
            }
        }
        d.deserialize_any(V)
    }
}

impl<'de> Deserialize<'de> for Rest {
    fn deserialize<D: Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = Rest;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("a keyframe index or a mesh path")
            }
            fn visit_i64<E: de::Error>(self, i: i64) -> std::result::Result<Rest, E> {
                usize::try_from(i).map(Rest::Key).map_err(|_| E::custom("rest key index must be >= 0"))
            }
            fn visit_u64<E: de::Error>(self, i: u64) -> std::result::Result<Rest, E> {
                Ok(Rest::Key(i as usize))
            }
            fn visit_str<E: de::Error>(self, s: &str) -> std::result::Result<Rest, E> {
                Ok(Rest::Mesh(s.to_string()))
            }
        }
        d.deserialize_any(V)
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SelectionTable {
    file: Option<String>,
    axis: Option<Axis>,
    min: Option<f64>,
    max: Option<f64>,
    #[serde(default)]
    invert: bool,
}

impl<'de> Deserialize<'de> for Selection {
    fn deserialize<D: Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = Selection;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("\"all\", \"none\", an index file path, a table { file | axis, min, max }, or a list of these")
            }
            fn visit_str<E: de::Error>(self, s: &str) -> std::result::Result<Selection, E> {
                Ok(match s {
                    "all" => Selection::All,
                    "none" => Selection::None,
                    path => Selection::File { file: path.to_string(), invert: false },
                })
            }
            fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> std::result::Result<Selection, A::Error> {
                let mut items = Vec::new();
                while let Some(item) = seq.next_element::<Selection>()? {
                    items.push(item);
                }
                Ok(Selection::Union(items))
            }
            fn visit_map<A: MapAccess<'de>>(self, map: A) -> std::result::Result<Selection, A::Error> {
                let t = SelectionTable::deserialize(de::value::MapAccessDeserializer::new(map))?;
                match (t.file, t.axis) {
                    (Some(file), None) if t.min.is_none() && t.max.is_none() => Ok(Selection::File { file, invert: t.invert }),
                    (None, Some(axis)) => Ok(Selection::Slab { axis, min: t.min, max: t.max, invert: t.invert }),
                    _ => Err(de::Error::custom("a selection table has either `file` or `axis` (with `min`/`max`), not both")),
                }
            }
        }
        d.deserialize_any(V)
    }
}

/// The scene name is the stem of every output file: one plain file name component, printable.
fn check_name(name: &str) -> Result<()> {
    let problem = if name.is_empty() {
        Some("is empty")
    } else if name.contains(['/', '\\']) {
        Some("contains a path separator")
    } else if name.starts_with('.') {
        Some("starts with '.' (a hidden file)")
    } else if name.chars().any(|c| c.is_control()) {
        Some("contains a control character")
    } else if name.len() > 200 {
        Some("is longer than 200 bytes")
    } else {
        None
    };
    match problem {
        Some(p) => Err(Error::general(
            format!("name {} cannot be a file stem: it {p}", crate::support::error::quoted(name)),
            "use letters, digits, '-' and '_'",
        )),
        None => Ok(()),
    }
}

impl Scene {
    /// The memory the scene needs for the frames it exports (`vertices` exported vertices over
    /// the key times at the scene's fps) and the samples it solves (`tets`, or a lower bound
    /// before TetGen), checked against `budget` before anything that size is allocated.
    pub(crate) fn check_resources(&self, times: &[f64], vertices: usize, tets: usize, budget: &Budget) -> Result<()> {
        if let (Some(start), Some(end)) = (times.first(), times.last()) {
            budget.check_frames(*start, *end, self.fps, vertices, self.export.full_frame)?;
        }
        // Both methods evaluate W over the samples (`hermite` once, for the report).
        budget.check_samples(self.solver.samples, times.len().saturating_sub(1), tets)
    }

    /// The whole bake's estimated peak bytes with keys at `times` and these counts: the largest
    /// phase of `memory_model::phase_bytes` (what `--max-memory` refuses a bake over).
    pub fn memory_estimate(&self, times: &[f64], counts: &BakeCounts) -> f64 {
        memory_model::phase_bytes(self, times, counts).peak().1
    }

    /// Parse and validate scene text. Errors carry no path; [`SceneFile::load`] adds it.
    pub fn parse(text: &str) -> Result<Scene> {
        let scene: Scene = toml::from_str(text).map_err(|e| {
            let line = e.span().map(|s| text[..s.start.min(text.len())].matches('\n').count() + 1);
            let msg = e.message().trim().to_string();
            let fix = if msg.starts_with("unknown field") {
                "remove or rename the key; formats/scene.md lists every key"
            } else if msg.starts_with("missing field") {
                "add the key; formats/scene.md lists every key"
            } else {
                "correct the value; formats/scene.md gives the syntax"
            };
            let at = line.map(|l| format!("line {l}: ")).unwrap_or_default();
            Error::general(format!("{at}{msg}"), fix)
        })?;
        scene.validate()?;
        Ok(scene)
    }

    /// Meters per unit of the input: `units`, else its alias `[export] meters_per_unit` (both
    /// validated). The physics runs in SI (`formats/scene.md`, "Units"); the files are written
    /// in the input's units with this as their metadata.
    pub fn meters_per_unit(&self) -> f64 {
        self.units.as_ref().and_then(Units::meters_per_unit).unwrap_or(self.export.meters_per_unit)
    }

    /// Every table's values in range, checked table by table in file order (the first problem
    /// is reported). Also run on the scene embedded in a stage file.
    pub(crate) fn validate(&self) -> Result<()> {
        check_name(&self.name)?;
        if !(self.fps.is_finite() && self.fps > 0.0) {
            return invalid(format!("fps = {} must be positive", number(self.fps)), "set fps to the frame rate, e.g. 60");
        }
        if let Some(units) = &self.units {
            let names = UNIT_NAMES.map(|(n, _)| format!("\"{n}\"")).join(", ");
            match units.meters_per_unit() {
                None => {
                    let given = match units {
                        Units::Name(n) => format!("\"{n}\""),
                        Units::MetersPerUnit(m) => format!("{m:e}"),
                    };
                    return invalid(
                        format!("units = {given} is not a length unit"),
                        &format!("use one of {names}, or the meters in one unit (a number > 0)"),
                    );
                }
                Some(m) if !(METERS_PER_UNIT_RANGE.0..=METERS_PER_UNIT_RANGE.1).contains(&m) => {
                    let (min, max) = METERS_PER_UNIT_RANGE;
                    return invalid(
                        format!("units = {} m is out of range ({} to {} m per unit)", number(m), number(min), number(max)),
                        &format!("use one of {names}, or the meters in one unit between {} and {}", number(min), number(max)),
                    );
                }
                Some(m) if self.export.meters_per_unit != 1.0 && self.export.meters_per_unit != m => {
                    return invalid(
                        format!("units ({m:e} m) and [export] meters_per_unit = {:e} disagree", self.export.meters_per_unit),
                        "give the unit once, as units (the [export] key is its older alias)",
                    );
                }
                Some(_) => {}
            }
        }
        match (&self.keyframes, &self.cache) {
            (Some(k), None) => k.validate()?,
            (None, Some(c)) => c.validate(self)?,
            (Some(_), Some(_)) => {
                return invalid(
                    "the scene has both [keyframes] and [cache]".into(),
                    "keep one: keyframe meshes, or a vertex cache to take keys from",
                );
            }
            (None, None) => {
                return invalid(
                    "the scene has neither [keyframes] nor [cache]".into(),
                    "add a [keyframes] table of meshes, or a [cache] table naming a vertex cache",
                );
            }
        }
        if self.keyframes.is_some() && self.solver.method == Method::Fit {
            return invalid(
                "[solver] method = \"fit\" fits a vertex cache, but the scene has [keyframes]".into(),
                "use \"spacetime\" or \"hermite\", or give a [cache]",
            );
        }
        self.tet.validate()?;
        self.material.validate()?;
        // A cache's key count is known only after the selection: fixed_times is checked then.
        self.solver.validate(self.keyframes.as_ref().map(KeyframeSpec::key_count))?;
        self.mass_spring.validate()?;
        self.export.validate()?;
        validate_obstacles(&self.obstacles)
    }
}

/// A scene error: the problem and its fix (the caller adds the file).
fn invalid(problem: String, fix: &str) -> Result<()> {
    Err(Error::general(problem, fix))
}

/// Slab bounds must be numbers with `min <= max` (NaN or crossed bounds select nothing).
fn check_selections(k: &KeyframeSpec) -> Result<()> {
    fn check(what: &str, key: usize, s: &Selection) -> Result<()> {
        match s {
            Selection::Slab { axis, min, max, .. } => {
                let axis = format!("{axis:?}").to_lowercase();
                for (bound, v) in [("min", min), ("max", max)] {
                    if v.is_some_and(f64::is_nan) {
                        return Err(Error::general(
                            format!("[keyframes] {what}[{key}]: the {axis} slab has {bound} = nan"),
                            "give the bound as a number, or leave it out for no bound",
                        ));
                    }
                }
                if let (Some(lo), Some(hi)) = (min, max) {
                    if lo > hi {
                        return Err(Error::general(
                            format!(
                                "[keyframes] {what}[{key}]: the {axis} slab has min = {} > max = {}, so it selects nothing",
                                number(*lo),
                                number(*hi)
                            ),
                            "swap the bounds (use `invert = true` to select outside a slab)",
                        ));
                    }
                }
                Ok(())
            }
            Selection::Union(items) => items.iter().try_for_each(|i| check(what, key, i)),
            _ => Ok(()),
        }
    }
    for (what, list) in [("fixed", &k.fixed), ("fixed_velocity", &k.fixed_velocity)] {
        for (key, s) in list.iter().flatten().enumerate() {
            check(what, key, s)?;
        }
    }
    Ok(())
}

impl KeyframeSpec {
    fn validate(&self) -> Result<()> {
        self.validate_clip()?;
        let n = self.key_count();
        if self.clip.is_none() {
            if n < 2 {
                return invalid(format!("[keyframes] has {n} mesh(es)"), "give at least two keyframe meshes, or clip = \"anim.fbx\" and its frames");
            }
            if self.times.len() != n {
                return invalid(format!("[keyframes] has {n} meshes but {} times", self.times.len()), "give one time per mesh");
            }
        }
        if let Some(i) = self.times.iter().position(|t| !t.is_finite()) {
            return invalid(format!("[keyframes] times[{i}] is not a number"), "use seconds, e.g. 0.5");
        }
        for (i, twist) in self.meshes.iter().enumerate().filter_map(|(i, m)| Some((i, m.twist()?))) {
            // Non-finite values would also not survive the scene's trip through a stage file
            // (JSON has no infinity).
            if !twist.degrees.is_finite() {
                return invalid(
                    format!("[keyframes] meshes[{i}] has a twist of {} degrees", number(twist.degrees)),
                    "give the twist angle as a finite number of degrees, e.g. 90.0",
                );
            }
            if !(twist.axial_scale.is_finite() && twist.axial_scale > 0.0) {
                return invalid(
                    format!("[keyframes] meshes[{i}] has a twist with axial_scale = {} (it scales the axial coordinate: a zero or negative one flattens or mirrors the mesh)", number(twist.axial_scale)),
                    "give a positive axial_scale, e.g. 0.8, or leave it out (1)",
                );
            }
        }
        // (With a clip's frames, times is empty.)
        for i in 1..self.times.len() {
            if self.times[i] < self.times[i - 1] {
                return invalid(
                    format!("[keyframes] times decrease at key {i} ({} after {})", number(self.times[i]), number(self.times[i - 1])),
                    "list keyframe times in increasing order",
                );
            }
            if self.times[i] == self.times[i - 1] {
                return invalid(
                    format!("[keyframes] keys {} and {i} share the time {} (a zero-length interval)", i - 1, number(self.times[i])),
                    "give every key its own time; for a contact list the key in `contact = [k]` and it is duplicated for you",
                );
            }
        }
        for (j, &k) in self.contact.iter().enumerate() {
            if k == 0 || k + 1 >= n {
                return invalid(
                    format!(
                        "[keyframes] contact = {:?} lists key {k}, but a contact needs a key before and after it (keys 1 to {})",
                        self.contact,
                        n.saturating_sub(2)
                    ),
                    "list the key at which the body hits the obstacle, not the first or last",
                );
            }
            if j > 0 && k <= self.contact[j - 1] {
                return invalid(
                    format!("[keyframes] contact = {:?} is not increasing", self.contact),
                    "list each contact key once, in increasing order",
                );
            }
        }
        for (what, list) in [("fixed", &self.fixed), ("fixed_velocity", &self.fixed_velocity)] {
            if let Some(list) = list {
                if list.len() != n {
                    return invalid(
                        format!("[keyframes] {what} has {} entries for {n} keys", list.len()),
                        "give one entry per key (\"all\", \"none\", a file, or a table)",
                    );
                }
            }
        }
        if let Rest::Key(r) = self.rest {
            if r >= n {
                return invalid(format!("[keyframes] rest = {r} but there are {n} keys"), "use a key index from 0");
            }
        }
        if self.cyclic && n < 3 {
            return invalid(
                "[keyframes] cyclic = true needs at least 3 keys (the last repeats the first)".into(),
                "add an in-between key, or set cyclic = false",
            );
        }
        check_selections(self)
    }
}

impl Tet {
    fn validate(&self) -> Result<()> {
        if !(self.quality.is_finite() && self.quality >= 1.0) && self.quality != 0.0 {
            return invalid(
                format!("[tet] quality = {} must be >= 1 (or 0 for none)", number(self.quality)),
                "TetGen needs a radius-edge bound like 1.414",
            );
        }
        if !(self.max_volume.is_finite() && self.max_volume >= 0.0) {
            return invalid(format!("[tet] max_volume = {} must be >= 0", number(self.max_volume)), "use 0 for no bound");
        }
        if !(self.timeout.is_finite() && self.timeout > 0.0) {
            return invalid(format!("[tet] timeout = {} must be positive", number(self.timeout)), "give seconds, e.g. 120");
        }
        if self.max_nodes < 4 {
            return invalid(format!("[tet] max_nodes = {} is too small for a body", self.max_nodes), "use e.g. 3000");
        }
        if self.cage_nodes < 50 {
            return invalid(format!("[tet] cage_nodes = {} is too small for a cage", self.cage_nodes), "use e.g. 1000 (at least 50)");
        }
        Ok(())
    }
}

/// The range of `stiffness`, `volume` and `density` (the first two may also be 0): wide enough
/// for a material converted by hand to any length unit (density scales with the cube of the
/// unit: a body in nanometres has density 1e27), narrow enough that the solve's matrices keep
/// their digits (a stiffness of 1e308 overflows; a density of 1e-300 leaves the body's motion
/// without cost, and the bake would fail later as a "singular" system).
pub(crate) const MATERIAL_RANGE: (f64, f64) = (1e-30, 1e30);

/// The range of `damping` (per second, whatever the length unit; it may also be 0).
pub(crate) const DAMPING_RANGE: (f64, f64) = (1e-9, 1e12);

/// The range of `[export] meters_per_unit`: micrometres to 1000 km. The glTF node scale is
/// written as a 32-bit float, which holds it exactly enough (1e300 would be written as null,
/// 1e-300 as 0).
pub(crate) const METERS_PER_UNIT_RANGE: (f64, f64) = (1e-6, 1e6);

impl Material {
    fn validate(&self) -> Result<()> {
        for (key, v, zero_ok, (min, max)) in [
            ("stiffness", self.stiffness, true, MATERIAL_RANGE),
            ("volume", self.volume, true, MATERIAL_RANGE),
            ("density", self.density, false, MATERIAL_RANGE),
            ("damping", self.damping, true, DAMPING_RANGE),
        ] {
            if !((zero_ok && v == 0.0) || (min..=max).contains(&v)) {
                let zero = if zero_ok { "0 or " } else { "" };
                return invalid(
                    format!("[material] {key} = {} is out of range ({zero}{} to {})", number(v), number(min), number(max)),
                    "give a value in the range (the defaults are stiffness = volume = 70, density = 1, damping = 0.1)",
                );
            }
        }
        if self.stiffness + self.volume <= 0.0 {
            return invalid("[material] stiffness and volume are both 0".into(), "give the body some stiffness");
        }
        if self.gravity.iter().any(|g| !g.is_finite()) {
            return invalid("[material] gravity has a non-finite component".into(), "use e.g. [0.0, -9.81, 0.0]");
        }
        Ok(())
    }
}

impl Solver {
    fn validate(&self, keys: Option<usize>) -> Result<()> {
        if self.samples == 0 {
            return invalid("[solver] samples = 0".into(), "use at least 1 sample per interval (10 is typical)");
        }
        if self.contact_samples == 0 {
            return invalid("[solver] contact_samples = 0".into(), "use at least 1 sample per interval next to a contact (20 is typical)");
        }
        if !self.optimize_timing && (self.keep_duration || !self.fixed_times.is_empty()) {
            let key = if self.keep_duration { "keep_duration" } else { "fixed_times" };
            return invalid(
                format!("[solver] {key} is set but optimize_timing is false, so the key times do not move anyway"),
                "set optimize_timing = true, or remove the key",
            );
        }
        if let Some((k, keys)) = keys.and_then(|keys| self.fixed_times.iter().find(|&&k| k >= keys).map(|&k| (k, keys))) {
            return invalid(
                format!("[solver] fixed_times lists key {k}, but there are {keys} keys"),
                "list key indices from 0, as in [keyframes] times",
            );
        }
        if !["auto", "projective", "tangent"].contains(&self.model_hessian.as_str()) {
            return invalid(
                format!("[solver] model_hessian = {:?} is not a model", self.model_hessian),
                "use \"auto\", \"projective\" or \"tangent\"",
            );
        }
        if !["auto", "quasi-newton", "gauss-newton"].contains(&self.step.as_str()) {
            return invalid(format!("[solver] step = {:?} is not a step", self.step), "use \"auto\", \"quasi-newton\" or \"gauss-newton\"");
        }
        if !["auto", "direct", "modal", "iterative"].contains(&self.global_step.as_str()) {
            return invalid(
                format!("[solver] global_step = {:?} is not a way to solve the global step", self.global_step),
                "use \"auto\", \"direct\", \"modal\" or \"iterative\"",
            );
        }
        if !(self.min_interval.is_finite() && self.min_interval > 0.0) {
            return invalid(
                format!("[solver] min_interval = {} must be positive", number(self.min_interval)),
                "use a small length in seconds, e.g. 0.001",
            );
        }
        if !(self.tolerance.is_finite() && self.tolerance > 0.0) {
            return invalid(
                format!("[solver] tolerance = {} must be positive", number(self.tolerance)),
                "use e.g. 0.001 (W decreasing by 0.1% over the last iterations)",
            );
        }
        if !(self.regularization.is_finite() && self.regularization >= 0.0) {
            return invalid(
                format!("[solver] regularization = {} must be >= 0", number(self.regularization)),
                "use a time scale like 0.1, or 0 for none",
            );
        }
        Ok(())
    }
}

/// Obstacles: finite numbers, a nonzero plane normal, a positive radius.
fn validate_obstacles(obstacles: &[ObstacleSpec]) -> Result<()> {
    for (i, o) in obstacles.iter().enumerate() {
        let (finite, problem) = match o {
            ObstacleSpec::Plane { point, normal } => {
                let length = normal.iter().map(|x| x * x).sum::<f64>().sqrt();
                (point.iter().chain(normal).all(|x| x.is_finite()), (length > 0.0).then_some(()).ok_or("its normal is zero"))
            }
            ObstacleSpec::Sphere { center, radius } => {
                (center.iter().all(|x| x.is_finite()) && radius.is_finite(), (*radius > 0.0).then_some(()).ok_or("its radius is not positive"))
            }
        };
        if !finite {
            return invalid(format!("[[obstacle]] {i} has a non-finite number"), "give finite coordinates");
        }
        if let Err(p) = problem {
            return invalid(format!("[[obstacle]] {i}: {p}"), "a plane needs a nonzero normal pointing out of the obstacle, a sphere a radius > 0");
        }
    }
    Ok(())
}

impl Export {
    fn validate(&self) -> Result<()> {
        if self.up_axis == Axis::X {
            return invalid("[export] up_axis = \"x\"".into(), "USD and glTF support \"y\" or \"z\" up");
        }
        let (min, max) = METERS_PER_UNIT_RANGE;
        if !(self.meters_per_unit.is_finite() && self.meters_per_unit > 0.0) {
            return invalid(
                format!("[export] meters_per_unit = {} must be positive", number(self.meters_per_unit)),
                "use 1.0 for meters, 0.01 for centimeters",
            );
        }
        if !(min..=max).contains(&self.meters_per_unit) {
            return invalid(
                format!("[export] meters_per_unit = {} is out of range ({} to {})", number(self.meters_per_unit), number(min), number(max)),
                "give the length of one unit in metres: 1.0 for metres, 0.01 for centimetres, 0.001 for millimetres",
            );
        }
        if self.formats.is_empty() {
            return invalid("[export] formats is empty".into(), "list at least one of \"usda\", \"usdc\", \"glb\"");
        }
        match (self.rank, self.basis) {
            (Some(0), _) => return invalid("[export] rank = 0".into(), "give at least 1 component, or remove rank to choose it by the tolerance"),
            (Some(r), Some(Basis::Keys)) => {
                return invalid(
                    format!("[export] rank = {r} is given, but basis = \"keys\" has no rank"),
                    "remove rank, or set basis = \"principal\"",
                );
            }
            _ => {}
        }
        Ok(())
    }

    /// The basis of the blendshape files: as given, else `principal` when `cache_fit` (the
    /// least-squares fit of a cache: measured 3-6x smaller files than `keys` at the same
    /// tolerance on the rapier bars, README) or a `rank` is given, and `keys` otherwise
    /// (keyframe scenes, and simulated caches, whose keys stay exact and editable).
    pub fn basis_for(&self, cache_fit: bool) -> Basis {
        self.basis.unwrap_or(if cache_fit || self.rank.is_some() { Basis::Principal } else { Basis::Keys })
    }
}

/// The `[mass_spring]` table (defaults: [`MassSpring::default`]): how `method = "mass-spring"`
/// makes the in-betweens of each keyframe interval (see `formats/scene.md`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MassSpring {
    /// In-between shapes per keyframe interval, evenly spaced in time; each becomes a key of
    /// the exported animation.
    pub inbetweens: usize,
    /// Bending springs: "two-ring" (the paper's: surface vertices two edges apart) or "hinge"
    /// (the far corners of each edge's two triangles).
    pub bending: String,
    /// Newton stops when no vertex moves more than this fraction of the size in a step.
    pub tolerance: f64,
}

impl Default for MassSpring {
    fn default() -> Self {
        MassSpring { inbetweens: 3, bending: "two-ring".into(), tolerance: 1e-7 }
    }
}

impl MassSpring {
    fn validate(&self) -> Result<()> {
        if self.inbetweens > 1000 {
            return invalid(
                format!("[mass_spring] inbetweens = {} is more than 1000 per interval", self.inbetweens),
                "use a few in-betweens per interval (3 is typical)",
            );
        }
        if !matches!(self.bending.as_str(), "two-ring" | "hinge") {
            return invalid(
                format!("[mass_spring] bending = {:?} is not a bending kind", self.bending),
                "use \"two-ring\" (the paper's) or \"hinge\"",
            );
        }
        if !(self.tolerance.is_finite() && self.tolerance > 0.0 && self.tolerance < 1.0) {
            return invalid(
                format!("[mass_spring] tolerance = {} must be between 0 and 1", number(self.tolerance)),
                "use e.g. 1e-7 (a fraction of the size)",
            );
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MINIMAL: &str = r#"
name = "twist"
[keyframes]
meshes = ["k0.obj", "k1.obj"]
times = [0.0, 0.5]
"#;

    #[test]
    fn minimal_scene_gets_defaults() {
        let s = Scene::parse(MINIMAL).unwrap();
        assert_eq!(s.fps, 60.0);
        assert_eq!(s.solver.method, Method::Spacetime);
        assert_eq!(s.export.formats, vec![Format::Usda, Format::Glb]);
        assert!(s.export.full_frame);
        assert_eq!((s.export.weights, s.export.gltf_interpolation), (Weights::Bernstein, GltfInterpolation::Linear));
        assert_eq!(s.export.gltf_compression, crate::formats::export::glb::Compression::Quantize);
        assert_eq!(s.keyframes.as_ref().unwrap().rest, Rest::Key(0));
    }

    #[test]
    fn the_export_basis_follows_the_input_unless_given() {
        let e = Scene::parse(MINIMAL).unwrap().export;
        assert_eq!((e.basis, e.rank, e.basis_for(false), e.basis_for(true)), (None, None, Basis::Keys, Basis::Principal));
        let e = Scene::parse(&(MINIMAL.to_string() + "[export]\nbasis = \"keys\"\n")).unwrap().export;
        assert_eq!(e.basis_for(true), Basis::Keys);
        let e = Scene::parse(&(MINIMAL.to_string() + "[export]\nrank = 3\n")).unwrap().export;
        assert_eq!((e.basis_for(false), e.rank), (Basis::Principal, Some(3)), "a rank asks for the principal basis");
        for (extra, says) in [
            ("rank = 0\n", "[export] rank = 0"),
            ("basis = \"keys\"\nrank = 2\n", "basis = \"keys\" has no rank"),
            ("basis = \"pca\"\n", "unknown variant `pca`"),
            ("rank = -1\n", "invalid value"),
        ] {
            let e = Scene::parse(&(MINIMAL.to_string() + "[export]\n" + extra)).unwrap_err().to_string();
            assert!(e.contains(says) && e.contains("(fix: "), "{extra}: {e}");
        }
    }

    #[test]
    fn a_partial_table_takes_the_other_defaults() {
        let s = Scene::parse(&(MINIMAL.to_string() + "[material]\nstiffness = 5.0\n[solver]\nsamples = 3\n[tet]\n")).unwrap();
        assert_eq!(s.material, Material { stiffness: 5.0, ..Material::default() });
        assert_eq!(s.solver, Solver { samples: 3, ..Solver::default() });
        assert_eq!((&s.tet, &s.export), (&Tet::default(), &Export::default()));
        assert_eq!(s.material.volume, 70.0, "the volume weight does not follow the strain weight");
        let s = Scene::parse(&(MINIMAL.to_string() + "[solver]\nsamples = 10\ncoarse_samples = 5\n")).unwrap();
        assert_eq!(s.solver, Solver { samples: 10, coarse_samples: 5, ..Solver::default() });
        assert_eq!(crate::pipeline::stages::solve::settings(&s).coarse_phase(), Some(5), "the key reaches the solver");
        let s = Scene::parse(&(MINIMAL.to_string() + "[solver]\nstep = \"gauss-newton\"\n")).unwrap();
        assert_eq!(
            crate::pipeline::stages::solve::settings(&s).step,
            crate::algorithms::spacetime::settings::Step::GaussNewton,
            "the key reaches the solver"
        );
        let e = Scene::parse(&(MINIMAL.to_string() + "[solver]\nstep = \"newton\"\n")).unwrap_err().to_string();
        assert!(e.contains("[solver] step = \"newton\" is not a step") && e.contains("(fix: "), "{e}");
    }

    #[test]
    fn the_issue_example_parses() {
        let text = r#"
name = "twist"
fps = 60
[keyframes]
meshes = ["k0.obj", "k1.obj"]
times = [0.0, 0.5]
fixed = ["all", "top.txt"]
cyclic = false
[tet]
quality = 1.414
max_volume = 0.0
[material]
stiffness = 70.0
volume = 70.0
density = 1.0
damping = 0.1
gravity = [0.0, 0.0, 0.0]
[solver]
method = "hermite"
samples = 10
[export]
formats = ["usda", "glb"]
full_frame = true
"#;
        let s = Scene::parse(text).unwrap();
        assert_eq!(s.solver.method, Method::Hermite);
        let e = Scene::parse(
            &(MINIMAL.to_string() + "[export]\nweights = \"signed\"\ngltf_interpolation = \"cubicspline\"\ngltf_compression = \"meshopt\"\n"),
        )
        .unwrap()
        .export;
        assert_eq!((e.weights, e.gltf_interpolation), (Weights::Signed, GltfInterpolation::Cubicspline));
        assert_eq!(e.gltf_compression, crate::formats::export::glb::Compression::Meshopt);
        assert_eq!(s.keyframes.as_ref().unwrap().fixed, Some(vec![Selection::All, Selection::File { file: "top.txt".into(), invert: false }]));
    }

    #[test]
    fn unknown_key_is_named_with_its_line() {
        let text = MINIMAL.to_string() + "[material]\nstifness = 3.0\n";
        let e = Scene::parse(&text).unwrap_err().to_string();
        assert!(e.contains("unknown field `stifness`"), "{e}");
        assert!(e.contains("line 7"), "{e}");
        assert!(e.contains("fix: remove or rename the key"), "{e}");
    }

    #[test]
    fn selections_and_deformed_meshes_parse() {
        let text = r#"
name = "t"
[keyframes]
meshes = ["a.mesh", { mesh = "a.mesh", twist = { axis = "y", degrees = 180.0, axial_scale = 0.8 } }, { mesh = "a.mesh", offset = [0.0, 1.5, -2.0] }]
times = [0.0, 0.5, 1.0]
fixed = ["all", [{ axis = "y", max = 0.01 }, { axis = "y", min = 2.99 }], { file = "tail.dmat", invert = true }]
rest = "rest.mesh"
"#;
        let s = Scene::parse(text).unwrap();
        assert_eq!(s.keyframes.as_ref().unwrap().meshes[1].twist().unwrap().degrees, 180.0);
        assert_eq!(s.keyframes.as_ref().unwrap().meshes[1].offset(), None);
        assert_eq!(s.keyframes.as_ref().unwrap().meshes[2].offset(), Some([0.0, 1.5, -2.0]));
        assert_eq!(s.keyframes.as_ref().unwrap().meshes[2].twist(), None);
        for bad in ["[0.0, 1.0]", "[0.0, nan, 1.0]"] {
            let e = Scene::parse(&text.replace("[0.0, 1.5, -2.0]", bad)).unwrap_err().to_string();
            assert!(e.contains("expected 3 components") || e.contains("offset must be three finite numbers"), "{e}");
        }
        // A twist the solver could not use, or a stage file could not carry (found by the fuzzer).
        for (bad, says) in
            [("degrees = inf", "twist of inf degrees"), ("degrees = nan", "twist of NaN degrees"), ("axial_scale = 0.0", "axial_scale = 0")]
        {
            let twist = if bad.starts_with("degrees") { format!("{bad}, axial_scale = 0.8") } else { format!("degrees = 180.0, {bad}") };
            let e = Scene::parse(&text.replace("degrees = 180.0, axial_scale = 0.8", &twist)).unwrap_err().to_string();
            assert!(e.contains("meshes[1]") && e.contains(says) && e.contains("fix:"), "{e}");
        }
        assert_eq!(s.keyframes.as_ref().unwrap().rest, Rest::Mesh("rest.mesh".into()));
        let fixed = s.keyframes.unwrap().fixed.unwrap();
        assert_eq!(
            fixed[1],
            Selection::Union(vec![
                Selection::Slab { axis: Axis::Y, min: None, max: Some(0.01), invert: false },
                Selection::Slab { axis: Axis::Y, min: Some(2.99), max: None, invert: false },
            ])
        );
        assert_eq!(fixed[2], Selection::File { file: "tail.dmat".into(), invert: true });
    }

    #[test]
    fn contacts_timing_and_obstacles_parse() {
        let text = r#"
name = "ball"
[keyframes]
meshes = ["a.obj", "b.obj", "c.obj"]
times = [0.0, 0.3, 0.6]
contact = [1]
[solver]
optimize_timing = true
keep_duration = true
fixed_times = [0]
contact_samples = 30
[[obstacle]]
kind = "plane"
point = [0.0, 0.0, 0.0]
normal = [0.0, 1.0, 0.0]
[[obstacle]]
kind = "sphere"
center = [0.0, -5.0, 0.0]
radius = 4.0
"#;
        let s = Scene::parse(text).unwrap();
        assert_eq!(s.keyframes.as_ref().unwrap().contact, vec![1]);
        assert!(s.solver.optimize_timing && s.solver.keep_duration && s.solver.contact_samples == 30);
        assert_eq!(s.obstacles.len(), 2);
        assert_eq!(s.obstacles[1], ObstacleSpec::Sphere { center: [0.0, -5.0, 0.0], radius: 4.0 });
        let back: Scene = serde_json::from_str(&serde_json::to_string(&s).unwrap()).unwrap();
        assert_eq!(back, s);
        let cases = [
            (text.replace("contact = [1]", "contact = [2]"), "needs a key before and after"),
            (text.replace("radius = 4.0", "radius = 0.0"), "radius is not positive"),
            (text.replace("normal = [0.0, 1.0, 0.0]", "normal = [0.0, 0.0, 0.0]"), "normal is zero"),
            (text.replace("kind = \"plane\"", "kind = \"cone\""), "unknown variant `cone`"),
            (text.replace("radius = 4.0", "radius = 4.0\nheight = 2.0"), "unknown field `height`"),
            (text.replace("fixed_times = [0]", "fixed_times = [3]"), "fixed_times lists key 3"),
            (text.replace("optimize_timing = true", "optimize_timing = false"), "keep_duration is set but optimize_timing is false"),
            (text.replace("times = [0.0, 0.3, 0.6]", "times = [0.0, 0.3, 0.3]"), "contact = [k]"),
        ];
        for (text, expect) in cases {
            let e = Scene::parse(&text).unwrap_err().to_string();
            assert!(e.contains(expect), "expected {expect:?} in {e}");
            assert!(e.contains("(fix: "), "{e}");
        }
    }

    #[test]
    fn selections_round_trip_through_json() {
        let text = r#"
name = "t"
[keyframes]
meshes = ["a.mesh", "a.mesh", "a.mesh", "a.mesh", "a.mesh"]
times = [0.0, 0.5, 1.0, 1.5, 2.0]
fixed = ["all", "none", "ends.txt", { file = "tail.dmat", invert = true }, [{ axis = "y", max = 0.01 }, { axis = "x", min = -1.0, max = 1.0, invert = true }]]
"#;
        let s = Scene::parse(text).unwrap();
        let json = serde_json::to_string(&s).unwrap();
        let back: Scene = serde_json::from_str(&json).unwrap();
        assert_eq!(back, s, "{json}");
    }

    #[test]
    fn unknown_key_inside_a_selection_table_is_named() {
        let text = MINIMAL.replace("times", "fixed = [\"all\", { axis = \"y\", maximum = 1.0 }]\ntimes");
        let e = Scene::parse(&text).unwrap_err().to_string();
        assert!(e.contains("unknown field `maximum`"), "{e}");
    }

    #[test]
    fn nonsense_values_are_rejected() {
        let sel = |entry: &str| MINIMAL.replace("times", &format!("fixed = [\"all\", {entry}]\ntimes"));
        let cases = [
            (MINIMAL.to_string() + "[material]\ngravity = [0.0, -9.8, 0.0, 1.0]\n", "expected 3 components (x, y, z), found 4"),
            (MINIMAL.to_string() + "[material]\ngravity = [0.0, -9.8]\n", "found 2"),
            (sel("{ axis = \"y\", min = nan }"), "[keyframes] fixed[1]: the y slab has min = nan"),
            (sel("[\"none\", { axis = \"x\", max = nan }]"), "the x slab has max = nan"),
            (sel("{ axis = \"z\", min = 2.0, max = 1.0 }"), "the z slab has min = 2 > max = 1, so it selects nothing"),
            (MINIMAL.replace("name = \"twist\"", "name = \"a\\nb\""), "name `a\\nb` cannot be a file stem: it contains a control character"),
            (MINIMAL.replace("name = \"twist\"", "name = \"\\u001b[31mred\""), "contains a control character"),
            (MINIMAL.replace("name = \"twist\"", "name = \"a\\\\b\""), "contains a path separator"),
            (MINIMAL.replace("name = \"twist\"", "name = \"../x\""), "contains a path separator"),
            (MINIMAL.replace("name = \"twist\"", "name = \".hidden\""), "starts with '.'"),
            (MINIMAL.replace("name = \"twist\"", "name = \"\""), "is empty"),
            (MINIMAL.replace("name = \"twist\"", &format!("name = \"{}\"", "n".repeat(300))), "is longer than 200 bytes"),
        ];
        for (text, expect) in cases {
            let e = Scene::parse(&text).unwrap_err().to_string();
            assert!(e.contains(expect), "expected {expect:?} in {e}");
            assert!(e.contains("(fix: ") && !e.contains('\n') && !e.contains('\u{1b}'), "{e}");
        }
        assert!(Scene::parse(&sel("{ axis = \"y\", min = 1.0, max = 1.0 }")).is_ok(), "a slab of zero thickness is fine");
    }

    #[test]
    fn units_are_a_name_or_meters_and_the_old_key_is_their_alias() {
        let mpu = |extra: &str| Scene::parse(&MINIMAL.replacen("\n", &format!("\n{extra}\n"), 1)).map(|s| s.meters_per_unit());
        assert_eq!(mpu("").unwrap(), 1.0);
        assert_eq!(mpu("units = \"cm\"").unwrap(), 0.01);
        assert_eq!(mpu("units = 100").unwrap(), 100.0);
        assert_eq!(mpu("units = 0.0254").unwrap(), 0.0254);
        assert_eq!(Scene::parse(&(MINIMAL.to_string() + "[export]\nmeters_per_unit = 0.001\n")).unwrap().meters_per_unit(), 0.001);
        for (bad, says) in [("units = \"yd\"", "units = \"yd\" is not a length unit"), ("units = -1", "units = -1e0 is not a length unit")] {
            let e = mpu(bad).unwrap_err().to_string();
            assert!(e.contains(says) && e.contains("\"cm\""), "{e}");
        }
        let both = MINIMAL.replacen("\n", "\nunits = \"cm\"\n", 1) + "[export]\nmeters_per_unit = 0.001\n";
        assert!(Scene::parse(&both).unwrap_err().to_string().contains("disagree"));
    }

    #[test]
    fn invalid_values_are_rejected_with_a_fix() {
        let cases = [
            (MINIMAL.replace("[0.0, 0.5]", "[0.5, 0.0]"), "times decrease"),
            (MINIMAL.replace("[0.0, 0.5]", "[0.0]"), "2 meshes but 1 times"),
            (MINIMAL.replace("name = \"twist\"", "name = \"a/b\""), "cannot be a file stem"),
            (MINIMAL.to_string() + "[solver]\nsamples = 0\n", "samples = 0"),
            (MINIMAL.to_string() + "[solver]\nmethod = \"magic\"\n", "unknown variant `magic`"),
            (MINIMAL.to_string() + "[export]\nformats = [\"fbx\"]\n", "unknown variant `fbx`"),
            (MINIMAL.to_string() + "[export]\nweights = \"positive\"\n", "unknown variant `positive`"),
            (MINIMAL.to_string() + "[export]\ngltf_interpolation = \"step\"\n", "unknown variant `step`"),
            (MINIMAL.to_string() + "[export]\ngltf_compression = \"draco\"\n", "unknown variant `draco`"),
        ];
        for (text, expect) in cases {
            let e = Scene::parse(&text).unwrap_err().to_string();
            assert!(e.contains(expect), "expected {expect:?} in {e}");
            assert!(e.contains("(fix: "), "{e}");
        }
    }
}
