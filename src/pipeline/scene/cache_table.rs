//! The scene's `[cache]` table: a vertex cache (OBJ sequence, PC2, MDD, glTF clip, USD point
//! cache) whose frames give the keys, instead of `[keyframes]` meshes. Specified in
//! `formats/scene.md`.

use std::fmt;

use serde::de::{self, Deserializer, SeqAccess, Visitor};
use serde::{Deserialize, Serialize};

use super::{invalid, Method, Rest, Scene, Selection};
use crate::support::error::Result;

/// The `[cache]` table.
///
/// Invariants once parsed: `fps` is positive when given; `keyframes` lists at least two
/// increasing frame indices; `tolerance` is given only for `"auto"` and is positive.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CacheSpec {
    /// The cache: an OBJ sequence pattern (`frames/frame_####.obj`), `.pc2`, `.mdd`,
    /// `.glb`/`.gltf` or `.usd`/`.usda`/`.usdc`, relative to the scene file.
    pub path: String,
    /// Frames per second of the cache: needed by OBJ sequences and PC2, used by MDD when its
    /// frame times are unusable and by glTF as the sampling rate; USD carries its own rate
    /// (`timeCodesPerSecond`) and refuses it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fps: Option<f64>,
    /// First frame used (0-based in file order; negative counts from the end).
    #[serde(default)]
    pub start: i64,
    /// Last frame used, inclusive (-1: the last).
    #[serde(default = "minus_one")]
    pub end: i64,
    /// `"auto"` (the fewest keys meeting `tolerance`) or frame indices (file order).
    #[serde(default)]
    pub keyframes: CacheKeys,
    /// For `"auto"`: the largest vertex distance from any frame, relative to the cache's
    /// bounding-box diagonal (default 0.005).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tolerance: Option<f64>,
    /// Vertices whose position is held on the cache frame at every key (default: "all" for
    /// spacetime and hermite, "none" for fit). One selection, applied at every key, since the
    /// key count may be chosen automatically.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fixed: Option<Selection>,
    /// Vertices whose velocity is prescribed to zero at every key (default: "none").
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fixed_velocity: Option<Selection>,
    /// The elastic rest shape: a frame index (file order), or a mesh path (an OBJ with the
    /// cache's vertex order). PC2 and MDD need a mesh: it also gives their triangles. Default:
    /// that mesh for PC2/MDD, else the first frame of the range.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rest: Option<Rest>,
    /// The glTF animation to evaluate (default: the only one).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub animation: Option<String>,
    /// The USD Mesh prim (default: the only animated Mesh).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub prim: Option<String>,
    /// The Alembic or FBX mesh object (default: the only mesh, or the only animated one).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub object: Option<String>,
    /// The FBX take (animation stack; default: the only one).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub take: Option<String>,
    /// For `"auto"`: bytes of cache frames the key selection may hold at once (default
    /// `DEFAULT_WINDOW_BYTES`, 256 MiB). It bounds the selection's memory, not its result
    /// unless a swing between two keys needs more frames than fit (at least 8 always do).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub window_bytes: Option<u64>,
    /// Merge the vertices that coincide at every frame (default true); `false` keeps the
    /// input's vertices. Selections and the report keep the input's vertex numbers.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub weld: Option<bool>,
}

/// The default frame window of `keyframes = "auto"`: 256 MiB.
pub const DEFAULT_WINDOW_BYTES: u64 = 256 << 20;

fn minus_one() -> i64 {
    -1
}

/// The default tolerance of `keyframes = "auto"`.
pub const DEFAULT_TOLERANCE: f64 = 0.005;

/// Which cache frames become keys.
#[derive(Debug, Clone, PartialEq, Default)]
pub enum CacheKeys {
    /// The fewest keys whose fit meets the tolerance at every frame.
    #[default]
    Auto,
    /// These frames (0-based, file order, strictly increasing).
    Frames(Vec<usize>),
}

impl Serialize for CacheKeys {
    fn serialize<S: serde::Serializer>(&self, ser: S) -> std::result::Result<S::Ok, S::Error> {
        match self {
            CacheKeys::Auto => ser.serialize_str("auto"),
            CacheKeys::Frames(f) => f.serialize(ser),
        }
    }
}

impl<'de> Deserialize<'de> for CacheKeys {
    fn deserialize<D: Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = CacheKeys;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("\"auto\" or a list of frame indices")
            }
            fn visit_str<E: de::Error>(self, s: &str) -> std::result::Result<CacheKeys, E> {
                match s {
                    "auto" => Ok(CacheKeys::Auto),
                    other => Err(E::custom(format!("keyframes = {other:?}: expected \"auto\" or a list of frame indices"))),
                }
            }
            fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> std::result::Result<CacheKeys, A::Error> {
                let mut frames = Vec::new();
                while let Some(f) = seq.next_element::<i64>()? {
                    frames.push(usize::try_from(f).map_err(|_| de::Error::custom(format!("keyframe frame index {f} is negative")))?);
                }
                Ok(CacheKeys::Frames(frames))
            }
        }
        d.deserialize_any(V)
    }
}

impl CacheSpec {
    /// The tolerance of `"auto"`.
    pub fn tolerance(&self) -> f64 {
        self.tolerance.unwrap_or(DEFAULT_TOLERANCE)
    }

    /// Whether to weld the vertices that coincide at every frame (`weld`, default true).
    pub fn weld(&self) -> bool {
        self.weld.unwrap_or(true)
    }

    /// The frame window of `"auto"`, in bytes.
    pub fn window_bytes(&self) -> u64 {
        self.window_bytes.unwrap_or(DEFAULT_WINDOW_BYTES)
    }

    /// The `fixed` selection for `method`: as given, else "all" (the keys are the cache's
    /// frames) for spacetime and hermite, "none" (least squares places the keys) for fit.
    pub(crate) fn fixed_for(&self, method: Method) -> Selection {
        self.fixed.clone().unwrap_or(if method == Method::Fit { Selection::None } else { Selection::All })
    }

    pub(super) fn validate(&self, scene: &Scene) -> Result<()> {
        if self.path.is_empty() {
            return invalid("[cache] path is empty".into(), "name the cache file, e.g. path = \"anim.pc2\"");
        }
        if let Some(fps) = self.fps {
            if !(fps.is_finite() && fps > 0.0) {
                return invalid(format!("[cache] fps = {fps} must be positive"), "give the cache's frames per second, e.g. 60");
            }
        }
        match (&self.keyframes, self.tolerance) {
            (CacheKeys::Auto, Some(t)) if !(t.is_finite() && t > 0.0) => {
                return invalid(
                    format!("[cache] tolerance = {t} must be positive"),
                    "give the largest error allowed as a fraction of the bounding-box diagonal, e.g. 0.005",
                );
            }
            (CacheKeys::Frames(_), Some(_)) => {
                return invalid("[cache] tolerance is given, but keyframes lists the frames".into(), "remove tolerance, or set keyframes = \"auto\"");
            }
            (CacheKeys::Frames(_), None) if self.window_bytes.is_some() => {
                return invalid(
                    "[cache] window_bytes is given, but keyframes lists the frames".into(),
                    "remove window_bytes (it bounds the automatic selection), or set keyframes = \"auto\"",
                );
            }
            (CacheKeys::Frames(f), None) => {
                if f.len() < 2 {
                    return invalid(format!("[cache] keyframes lists {} frame(s)", f.len()), "list at least two frame indices, or use \"auto\"");
                }
                if let Some(i) = (1..f.len()).find(|&i| f[i] <= f[i - 1]) {
                    return invalid(
                        format!("[cache] keyframes are not strictly increasing at entry {i} ({} after {})", f[i], f[i - 1]),
                        "list each frame once, in increasing order",
                    );
                }
            }
            _ => {}
        }
        if self.window_bytes == Some(0) {
            return invalid(
                "[cache] window_bytes = 0".into(),
                "give the bytes of frames the key selection may hold, e.g. 268435456 (256 MiB, the default)",
            );
        }
        for (what, sel) in [("fixed", &self.fixed), ("fixed_velocity", &self.fixed_velocity)] {
            if let Some(sel) = sel {
                check_slabs(what, sel)?;
            }
        }
        if scene.embed.surface.is_some() {
            return invalid(
                "[embed] surface is set, but a [cache] scene exports the cache's own mesh (its error is measured vertex by vertex)".into(),
                "remove [embed] surface",
            );
        }
        Ok(())
    }
}

/// Slab bounds are numbers with `min <= max` (NaN or crossed bounds select nothing).
fn check_slabs(what: &str, selection: &Selection) -> Result<()> {
    match selection {
        Selection::Slab { min, max, .. } => {
            if min.is_some_and(f64::is_nan) || max.is_some_and(f64::is_nan) || matches!((min, max), (Some(lo), Some(hi)) if lo > hi) {
                return invalid(
                    format!("[cache] {what}: a slab has bounds {min:?}, {max:?}, so it selects nothing"),
                    "give numbers with min <= max, or leave a bound out (use `invert = true` to select outside a slab)",
                );
            }
            Ok(())
        }
        Selection::Union(items) => items.iter().try_for_each(|i| check_slabs(what, i)),
        _ => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const CACHE: &str = "name = \"bar\"\n[cache]\npath = \"bar.pc2\"\nfps = 60\nrest = \"bar.obj\"\n";

    #[test]
    fn a_cache_table_takes_its_defaults() {
        let s = Scene::parse(CACHE).unwrap();
        assert!(s.keyframes.is_none());
        let c = s.cache.unwrap();
        assert_eq!((c.start, c.end, &c.keyframes, c.tolerance()), (0, -1, &CacheKeys::Auto, DEFAULT_TOLERANCE));
        assert_eq!(c.rest, Some(Rest::Mesh("bar.obj".into())));
        assert_eq!(c.window_bytes(), 256 << 20);
        assert_eq!(Scene::parse(&(CACHE.to_string() + "window_bytes = 1048576\n")).unwrap().cache.unwrap().window_bytes(), 1 << 20);
        assert_eq!((c.fixed_for(Method::Spacetime), c.fixed_for(Method::Fit)), (Selection::All, Selection::None));
        let listed =
            Scene::parse(&(CACHE.to_string() + "keyframes = [0, 10, 20]\nfixed = { axis = \"x\", max = 0.0 }\n[solver]\nmethod = \"fit\"\n"))
                .unwrap();
        let c = listed.cache.clone().unwrap();
        assert_eq!(c.keyframes, CacheKeys::Frames(vec![0, 10, 20]));
        assert_eq!(
            c.fixed_for(Method::Fit),
            Selection::Slab { axis: crate::algorithms::geometry::Axis::X, min: None, max: Some(0.0), invert: false }
        );
        // The stage files carry the scene: it round-trips through JSON.
        let json = serde_json::to_string(&listed).unwrap();
        assert_eq!(serde_json::from_str::<Scene>(&json).unwrap(), listed, "{json}");
    }

    #[test]
    fn bad_cache_tables_are_rejected_with_a_fix() {
        let keys = "[keyframes]\nmeshes = [\"a.obj\", \"b.obj\"]\ntimes = [0.0, 1.0]\n";
        let cases = [
            (CACHE.to_string() + keys, "both [keyframes] and [cache]"),
            ("name = \"x\"\n".to_string(), "neither [keyframes] nor [cache]"),
            (CACHE.to_string() + "tolerance = 0.0\n", "tolerance = 0 must be positive"),
            (CACHE.to_string() + "tolerance = -1.0\n", "must be positive"),
            (CACHE.to_string() + "keyframes = [0, 5]\ntolerance = 0.01\n", "tolerance is given, but keyframes lists"),
            (CACHE.to_string() + "keyframes = [5, 5]\n", "not strictly increasing"),
            (CACHE.to_string() + "keyframes = [3]\n", "lists 1 frame"),
            (CACHE.to_string() + "keyframes = [0, -2]\n", "negative"),
            (CACHE.to_string() + "keyframes = \"every\"\n", "expected \"auto\""),
            (CACHE.replace("fps = 60", "fps = 0"), "fps = 0 must be positive"),
            (CACHE.to_string() + "speed = 2\n", "unknown field `speed`"),
            (CACHE.to_string() + "window_bytes = 0\n", "window_bytes = 0"),
            (CACHE.to_string() + "window_bytes = -5\n", "integer `-5`, expected u64"),
            (CACHE.to_string() + "window_bytes = \"1G\"\n", "expected u64"),
            (CACHE.to_string() + "keyframes = [0, 5]\nwindow_bytes = 1000000\n", "window_bytes is given, but keyframes lists"),
            (CACHE.to_string() + "fixed = [\"all\", { axis = \"x\", min = 2.0, max = 1.0 }]\n", "[cache] fixed: a slab has bounds"),
            (CACHE.to_string() + "[embed]\nsurface = \"fine.obj\"\n", "[embed] surface is set"),
            ("name = \"k\"\n".to_string() + keys + "[solver]\nmethod = \"fit\"\n", "fits a vertex cache"),
        ];
        for (text, expect) in cases {
            let e = Scene::parse(&text).unwrap_err().to_string();
            assert!(e.contains(expect), "expected {expect:?} in {e}");
            assert!(e.contains("(fix: "), "{e}");
        }
        let e = Scene::parse(&(CACHE.to_string() + "speed = 2\n")).unwrap_err().to_string();
        assert!(e.contains("line 6"), "{e}");
    }
}
