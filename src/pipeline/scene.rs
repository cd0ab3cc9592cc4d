//! The scene file (TOML): what to bake and how. Specified in `formats/scene.md`.
//!
//! Parsing is strict: an unknown key is an error that names it and its line, so a typo never
//! silently falls back to a default. Paths stay as written; [`SceneFile::resolve`] turns them
//! into paths relative to the scene file's folder.
//!
//! This file holds the scene as a whole (parsing, the scene-wide checks); each table's type,
//! defaults and validation are in its own file under `scene/`, and the memory a scene needs in
//! `scene/memory.rs`.

use std::path::{Path, PathBuf};

use serde::de::{self, Deserializer};
use serde::{Deserialize, Serialize};

pub use crate::algorithms::blendshape::clip::Weights;
pub use crate::algorithms::geometry::Axis;
pub use crate::algorithms::procedural::Twist;
use crate::support::error::{number, Error, Result};

mod cache_table;
mod embed;
mod export;
mod keyframe_clip;
mod keyframes;
mod mass_spring;
mod material;
mod memory;
pub(crate) mod memory_model;
mod obstacles;
mod selection;
mod solver;
mod tet;
mod units;

pub use cache_table::{CacheKeys, CacheSpec, DEFAULT_TOLERANCE};
pub use embed::Embed;
pub use export::{Basis, Export, Format, GltfInterpolation};
pub use keyframes::{DeformedMesh, KeyMesh, KeyframeSpec, Rest};
pub use mass_spring::MassSpring;
pub use material::Material;
pub use memory_model::{BakeCounts, PhaseBytes, StepChoice};
use obstacles::validate_obstacles;
pub use obstacles::ObstacleSpec;
pub use selection::Selection;
pub use solver::{Method, Solver};
pub use tet::Tet;
pub(crate) use units::METERS_PER_UNIT_RANGE;
pub use units::{Units, UNIT_NAMES};

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

fn default_fps() -> f64 {
    60.0
}

/// A vector of exactly three numbers (serde's own `[f64; 3]` would drop a fourth).
fn three_components<'de, D: Deserializer<'de>>(d: D) -> std::result::Result<[f64; 3], D::Error> {
    let v = Vec::<f64>::deserialize(d)?;
    <[f64; 3]>::try_from(v.as_slice()).map_err(|_| de::Error::custom(format!("expected 3 components (x, y, z), found {}", v.len())))
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

#[cfg(test)]
mod tests;
