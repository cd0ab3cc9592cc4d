//! The `[keyframes]` table: the keyframe meshes, their times, rest pose and constraints.

use std::fmt;

use serde::de::{self, Deserializer, MapAccess, Visitor};
use serde::{Deserialize, Serialize};

use super::{invalid, three_components, Selection, Twist};
use crate::support::error::{number, Error, Result};

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
    /// Merge the surface vertices that coincide in every key (default true); `false` keeps the
    /// input's vertices. Selections (`fixed`, index files) keep the input's vertex numbers.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub weld: Option<bool>,
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

// --- Deserialization of the string-or-table entries, with precise messages. ---

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
    pub(super) fn validate(&self) -> Result<()> {
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
