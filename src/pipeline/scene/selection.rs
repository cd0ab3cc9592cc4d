//! Vertex selections (`fixed`, `fixed_velocity`): "all", "none", a file, a slab or a union.

use std::fmt;

use serde::de::{self, Deserializer, MapAccess, SeqAccess, Visitor};
use serde::{Deserialize, Serialize};

use super::Axis;

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
