//! The scene file (TOML): what to bake and how. Specified in `formats/scene.md`.
//!
//! Parsing is strict: an unknown key is an error that names it and its line, so a typo never
//! silently falls back to a default. Paths stay as written; [`SceneFile::resolve`] turns them
//! into paths relative to the scene file's folder.

use std::fmt;
use std::path::{Path, PathBuf};

use serde::de::{self, Deserializer, MapAccess, SeqAccess, Visitor};
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};

/// A parsed, validated scene and the folder its relative paths resolve against.
#[derive(Debug, Clone)]
pub struct SceneFile {
    pub path: PathBuf,
    pub scene: Scene,
}

impl SceneFile {
    /// Read, parse and validate a scene file.
    pub fn load(path: &Path) -> Result<SceneFile> {
        let text = crate::input::read_text(path, "the scene file")?;
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

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scene {
    /// Stem of every output file.
    pub name: String,
    /// Full-frame rate, and the USD weight sample rate (frames per second).
    #[serde(default = "defaults::fps")]
    pub fps: f64,
    pub keyframes: Keyframes,
    #[serde(default)]
    pub tet: Tet,
    #[serde(default)]
    pub material: Material,
    #[serde(default)]
    pub solver: Solver,
    #[serde(default)]
    pub embed: Embed,
    #[serde(default)]
    pub export: Export,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Keyframes {
    /// One mesh per key: a path, or `{ mesh = PATH, twist = {...} }` for a procedurally
    /// deformed copy.
    pub meshes: Vec<KeyMesh>,
    /// Key times in seconds, strictly increasing.
    pub times: Vec<f64>,
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
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Tet {
    /// TetGen `-q` radius-edge ratio bound.
    #[serde(default = "defaults::quality")]
    pub quality: f64,
    /// TetGen `-a` maximum tet volume; 0 means no bound.
    #[serde(default)]
    pub max_volume: f64,
    /// Seconds TetGen may run before it is stopped.
    #[serde(default = "defaults::tetgen_timeout")]
    pub timeout: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Material {
    /// Strain (as-rigid-as-possible) constraint weight per unit rest volume.
    #[serde(default = "defaults::stiffness")]
    pub stiffness: f64,
    /// Volume-preservation constraint weight per unit rest volume.
    #[serde(default = "defaults::stiffness")]
    pub volume: f64,
    /// Mass per unit rest volume (lumped to the nodes).
    #[serde(default = "defaults::density")]
    pub density: f64,
    /// Rayleigh mass damping: D = damping * M (per second).
    #[serde(default = "defaults::damping")]
    pub damping: f64,
    /// Gravitational acceleration (units per second squared), applied as M g.
    #[serde(default, deserialize_with = "three_components")]
    pub gravity: [f64; 3],
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Method {
    /// Keyframes joined by cubic Hermite curves with zero velocities (the geometric baseline).
    Hermite,
    /// BlendSim's spacetime projective dynamics.
    Spacetime,
}

impl fmt::Display for Method {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Method::Hermite => "hermite",
            Method::Spacetime => "spacetime",
        })
    }
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Solver {
    #[serde(default = "defaults::method")]
    pub method: Method,
    /// Sample points per interval at which the residual force is evaluated.
    #[serde(default = "defaults::samples")]
    pub samples: usize,
    #[serde(default = "defaults::max_iterations")]
    pub max_iterations: usize,
    /// Stop when W changes by less than `tolerance` times its initial value.
    #[serde(default = "defaults::tolerance")]
    pub tolerance: f64,
    /// Proximal regularization time scale h: adds (1/h⁴) Σ dτ BᵀMB (0 = off).
    #[serde(default = "defaults::regularization")]
    pub regularization: f64,
}

#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Embed {
    /// A finer surface (OBJ, in the rest pose) to carry on the tet trajectory; by default the
    /// exported surface is the keyframe surface itself.
    #[serde(default)]
    pub surface: Option<String>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Format {
    Usda,
    Usdc,
    Glb,
}

impl Format {
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

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Export {
    #[serde(default = "defaults::formats")]
    pub formats: Vec<Format>,
    /// Also write the full-frame versions (one pose per frame) for comparison.
    #[serde(default = "defaults::yes")]
    pub full_frame: bool,
    /// The scene's up axis, "y" or "z" (USD `upAxis`; glTF files are rotated to y-up).
    #[serde(default = "defaults::up_axis")]
    pub up_axis: Axis,
    /// Scene units in meters (USD `metersPerUnit`; glTF files are scaled to meters).
    #[serde(default = "defaults::one")]
    pub meters_per_unit: f64,
}

mod defaults {
    use super::{Format, Method};
    pub fn fps() -> f64 {
        60.0
    }
    pub fn quality() -> f64 {
        1.414
    }
    pub fn tetgen_timeout() -> f64 {
        120.0
    }
    pub fn stiffness() -> f64 {
        70.0
    }
    pub fn density() -> f64 {
        1.0
    }
    pub fn damping() -> f64 {
        0.1
    }
    pub fn method() -> Method {
        Method::Spacetime
    }
    pub fn samples() -> usize {
        10
    }
    pub fn max_iterations() -> usize {
        50
    }
    pub fn tolerance() -> f64 {
        0.01
    }
    pub fn regularization() -> f64 {
        0.1
    }
    pub fn formats() -> Vec<Format> {
        vec![Format::Usda, Format::Glb]
    }
    pub fn yes() -> bool {
        true
    }
    pub fn up_axis() -> super::Axis {
        super::Axis::Y
    }
    pub fn one() -> f64 {
        1.0
    }
}

impl Default for Tet {
    fn default() -> Self {
        Tet { quality: defaults::quality(), max_volume: 0.0, timeout: defaults::tetgen_timeout() }
    }
}

impl Default for Material {
    fn default() -> Self {
        Material {
            stiffness: defaults::stiffness(),
            volume: defaults::stiffness(),
            density: defaults::density(),
            damping: defaults::damping(),
            gravity: [0.0; 3],
        }
    }
}

impl Default for Solver {
    fn default() -> Self {
        Solver {
            method: defaults::method(),
            samples: defaults::samples(),
            max_iterations: defaults::max_iterations(),
            tolerance: defaults::tolerance(),
            regularization: defaults::regularization(),
        }
    }
}

impl Default for Export {
    fn default() -> Self {
        Export {
            formats: defaults::formats(),
            full_frame: true,
            up_axis: defaults::up_axis(),
            meters_per_unit: defaults::one(),
        }
    }
}

/// Coordinate axis.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Axis {
    X,
    Y,
    Z,
}

impl Axis {
    pub fn index(self) -> usize {
        self as usize
    }
}

/// A procedural twist of a keyframe mesh about an axis through its bounding-box centre: the
/// rotation angle grows linearly from 0 at the low end of the box to `degrees` at the high end,
/// and the axial coordinate is scaled by `axial_scale` about the low end.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Twist {
    pub axis: Axis,
    pub degrees: f64,
    #[serde(default = "defaults::one")]
    pub axial_scale: f64,
}

/// One keyframe mesh: a file, optionally deformed procedurally.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(untagged)]
pub enum KeyMesh {
    Path(String),
    Deformed(DeformedMesh),
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DeformedMesh {
    pub mesh: String,
    #[serde(default)]
    pub twist: Option<Twist>,
}

impl KeyMesh {
    pub fn path(&self) -> &str {
        match self {
            KeyMesh::Path(p) => p,
            KeyMesh::Deformed(d) => &d.mesh,
        }
    }

    pub fn twist(&self) -> Option<&Twist> {
        match self {
            KeyMesh::Path(_) => None,
            KeyMesh::Deformed(d) => d.twist.as_ref(),
        }
    }
}

/// The elastic rest shape.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(untagged)]
pub enum Rest {
    Key(usize),
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
    All,
    None,
    File { file: String, invert: bool },
    Slab { axis: Axis, min: Option<f64>, max: Option<f64>, invert: bool },
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
    <[f64; 3]>::try_from(v.as_slice())
        .map_err(|_| de::Error::custom(format!("expected 3 components (x, y, z), found {}", v.len())))
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
                    (Some(file), None) if t.min.is_none() && t.max.is_none() => {
                        Ok(Selection::File { file, invert: t.invert })
                    }
                    (None, Some(axis)) => Ok(Selection::Slab { axis, min: t.min, max: t.max, invert: t.invert }),
                    _ => Err(de::Error::custom(
                        "a selection table has either `file` or `axis` (with `min`/`max`), not both",
                    )),
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
            format!("name {} cannot be a file stem: it {p}", crate::error::quoted(name)),
            "use letters, digits, '-' and '_'",
        )),
        None => Ok(()),
    }
}

/// Slab bounds must be numbers with `min <= max` (NaN or crossed bounds select nothing).
fn check_selections(k: &Keyframes) -> Result<()> {
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
                            format!("[keyframes] {what}[{key}]: the {axis} slab has min = {lo} > max = {hi}, so it selects nothing"),
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

impl Scene {
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

    fn validate(&self) -> Result<()> {
        let bad = |problem: String, fix: &str| Err(Error::general(problem, fix));
        check_name(&self.name)?;
        check_selections(&self.keyframes)?;
        if !(self.fps.is_finite() && self.fps > 0.0) {
            return bad(format!("fps = {} must be positive", self.fps), "set fps to the frame rate, e.g. 60");
        }
        let k = &self.keyframes;
        let n = k.meshes.len();
        if n < 2 {
            return bad(format!("[keyframes] has {n} mesh(es)"), "give at least two keyframe meshes");
        }
        if k.times.len() != n {
            return bad(
                format!("[keyframes] has {n} meshes but {} times", k.times.len()),
                "give one time per mesh",
            );
        }
        if let Some(i) = k.times.iter().position(|t| !t.is_finite()) {
            return bad(format!("[keyframes] times[{i}] is not a number"), "use seconds, e.g. 0.5");
        }
        for i in 1..n {
            if k.times[i] < k.times[i - 1] {
                return bad(
                    format!("[keyframes] times decrease at key {i} ({} after {})", k.times[i], k.times[i - 1]),
                    "list keyframe times in increasing order",
                );
            }
            if k.times[i] == k.times[i - 1] {
                return bad(
                    format!("[keyframes] keys {} and {i} share the time {} (a zero-length interval)", i - 1, k.times[i]),
                    "give every key its own time; coincident collision keys are not supported yet",
                );
            }
        }
        for (what, list) in [("fixed", &k.fixed), ("fixed_velocity", &k.fixed_velocity)] {
            if let Some(list) = list {
                if list.len() != n {
                    return bad(
                        format!("[keyframes] {what} has {} entries for {n} keys", list.len()),
                        "give one entry per key (\"all\", \"none\", a file, or a table)",
                    );
                }
            }
        }
        if let Rest::Key(r) = k.rest {
            if r >= n {
                return bad(format!("[keyframes] rest = {r} but there are {n} keys"), "use a key index from 0");
            }
        }
        if k.cyclic && n < 3 {
            return bad(
                "[keyframes] cyclic = true needs at least 3 keys (the last repeats the first)".into(),
                "add an in-between key, or set cyclic = false",
            );
        }
        let t = &self.tet;
        if !(t.quality.is_finite() && t.quality >= 1.0) && t.quality != 0.0 {
            return bad(format!("[tet] quality = {} must be >= 1 (or 0 for none)", t.quality), "TetGen needs a radius-edge bound like 1.414");
        }
        if !(t.max_volume.is_finite() && t.max_volume >= 0.0) {
            return bad(format!("[tet] max_volume = {} must be >= 0", t.max_volume), "use 0 for no bound");
        }
        if !(t.timeout.is_finite() && t.timeout > 0.0) {
            return bad(format!("[tet] timeout = {} must be positive", t.timeout), "give seconds, e.g. 120");
        }
        let m = &self.material;
        for (key, v, min_ok) in [
            ("stiffness", m.stiffness, m.stiffness >= 0.0),
            ("volume", m.volume, m.volume >= 0.0),
            ("density", m.density, m.density > 0.0),
            ("damping", m.damping, m.damping >= 0.0),
        ] {
            if !(v.is_finite() && min_ok) {
                return bad(format!("[material] {key} = {v} is out of range"), "use a finite, non-negative value (density > 0)");
            }
        }
        if m.stiffness + m.volume <= 0.0 {
            return bad("[material] stiffness and volume are both 0".into(), "give the body some stiffness");
        }
        if m.gravity.iter().any(|g| !g.is_finite()) {
            return bad("[material] gravity has a non-finite component".into(), "use e.g. [0.0, -9.81, 0.0]");
        }
        let s = &self.solver;
        if s.samples == 0 {
            return bad("[solver] samples = 0".into(), "use at least 1 sample per interval (10 is typical)");
        }
        if !(s.tolerance.is_finite() && s.tolerance > 0.0) {
            return bad(format!("[solver] tolerance = {} must be positive", s.tolerance), "use e.g. 0.01 (1% of the initial W)");
        }
        if !(s.regularization.is_finite() && s.regularization >= 0.0) {
            return bad(format!("[solver] regularization = {} must be >= 0", s.regularization), "use a time scale like 0.1, or 0 for none");
        }
        if self.export.up_axis == Axis::X {
            return bad("[export] up_axis = \"x\"".into(), "USD and glTF support \"y\" or \"z\" up");
        }
        if !(self.export.meters_per_unit.is_finite() && self.export.meters_per_unit > 0.0) {
            return bad(format!("[export] meters_per_unit = {} must be positive", self.export.meters_per_unit), "use 1.0 for meters, 0.01 for centimeters");
        }
        if self.export.formats.is_empty() {
            return bad("[export] formats is empty".into(), "list at least one of \"usda\", \"usdc\", \"glb\"");
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
        assert_eq!(s.keyframes.rest, Rest::Key(0));
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
        assert_eq!(
            s.keyframes.fixed,
            Some(vec![Selection::All, Selection::File { file: "top.txt".into(), invert: false }])
        );
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
meshes = ["a.mesh", { mesh = "a.mesh", twist = { axis = "y", degrees = 180.0, axial_scale = 0.8 } }, "a.mesh"]
times = [0.0, 0.5, 1.0]
fixed = ["all", [{ axis = "y", max = 0.01 }, { axis = "y", min = 2.99 }], { file = "tail.dmat", invert = true }]
rest = "rest.mesh"
"#;
        let s = Scene::parse(text).unwrap();
        assert_eq!(s.keyframes.meshes[1].twist().unwrap().degrees, 180.0);
        assert_eq!(s.keyframes.rest, Rest::Mesh("rest.mesh".into()));
        let fixed = s.keyframes.fixed.unwrap();
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
    fn invalid_values_are_rejected_with_a_fix() {
        let cases = [
            (MINIMAL.replace("[0.0, 0.5]", "[0.5, 0.0]"), "times decrease"),
            (MINIMAL.replace("[0.0, 0.5]", "[0.0]"), "2 meshes but 1 times"),
            (MINIMAL.replace("name = \"twist\"", "name = \"a/b\""), "cannot be a file stem"),
            (MINIMAL.to_string() + "[solver]\nsamples = 0\n", "samples = 0"),
            (MINIMAL.to_string() + "[solver]\nmethod = \"magic\"\n", "unknown variant `magic`"),
            (MINIMAL.to_string() + "[export]\nformats = [\"fbx\"]\n", "unknown variant `fbx`"),
        ];
        for (text, expect) in cases {
            let e = Scene::parse(&text).unwrap_err().to_string();
            assert!(e.contains(expect), "expected {expect:?} in {e}");
            assert!(e.contains("(fix: "), "{e}");
        }
    }
}
