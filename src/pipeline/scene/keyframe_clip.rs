//! `[keyframes]` keys taken from one animated file (`clip`) at given frames or times, instead
//! of one mesh file per key. Specified in `formats/scene.md`, "Keys from a clip".

use super::{invalid, KeyframeSpec};
use crate::support::error::{number, Result};

impl KeyframeSpec {
    /// Whether to weld the surface vertices that coincide in every key (`weld`, default true).
    pub fn weld(&self) -> bool {
        self.weld.unwrap_or(true)
    }

    /// The number of keys the table gives (before contacts are duplicated): one per mesh, or
    /// per listed frame or time of the clip.
    pub fn key_count(&self) -> usize {
        match (&self.clip, &self.frames) {
            (Some(_), Some(frames)) => frames.len(),
            (Some(_), None) => self.times.len(),
            (None, _) => self.meshes.len(),
        }
    }

    /// Per key, how the scene names it in messages: its mesh as written, or the clip and the
    /// frame or time.
    pub(crate) fn key_names(&self) -> Vec<String> {
        match (&self.clip, &self.frames) {
            (Some(clip), Some(frames)) => frames.iter().map(|f| format!("{clip} frame {f}")).collect(),
            (Some(clip), None) => self.times.iter().map(|t| format!("{clip} at {} s", number(*t))).collect(),
            (None, _) => self.meshes.iter().map(|m| m.path().to_string()).collect(),
        }
    }

    /// The clip's keys: exactly one of `meshes` and `clip`; with a clip, exactly one of
    /// `frames` and `times`, at least two, increasing; the clip's reader options only with it.
    pub(super) fn validate_clip(&self) -> Result<()> {
        let Some(clip) = &self.clip else {
            let given = [
                ("frames", self.frames.is_some()),
                ("fps", self.fps.is_some()),
                ("animation", self.animation.is_some()),
                ("prim", self.prim.is_some()),
                ("object", self.object.is_some()),
                ("take", self.take.is_some()),
            ];
            if let Some((key, _)) = given.iter().find(|(_, g)| *g) {
                return invalid(
                    format!("[keyframes] {key} is given without clip"),
                    &format!("add clip = \"anim.fbx\" (the animated file the keys are taken from), or remove {key}"),
                );
            }
            return Ok(());
        };
        // As the scene writes it (escaped: a control character stays one line).
        let named = format!("{clip:?}");
        if clip.is_empty() {
            return invalid("[keyframes] clip is empty".into(), "name the animated file, e.g. clip = \"walk.fbx\"");
        }
        if !self.meshes.is_empty() {
            return invalid(
                format!("[keyframes] has both meshes and clip = {named}"),
                "keep one: meshes (a file per key), or clip with the frames or times to take",
            );
        }
        if let Some(fps) = self.fps {
            if !(fps.is_finite() && fps > 0.0) {
                return invalid(format!("[keyframes] fps = {} must be positive", number(fps)), "give the clip's frames per second, e.g. 24");
            }
        }
        match &self.frames {
            Some(_) if !self.times.is_empty() => invalid(
                format!("[keyframes] gives both frames and times for clip = {named}"),
                "keep one: frames (the clip's frame indices, from 0) or times (seconds on the clip's clock)",
            ),
            None if self.times.is_empty() => invalid(
                format!("[keyframes] clip = {named} lists no keys"),
                "give the frames to take, e.g. frames = [0, 12, 30] (the clip's frame indices, from 0), or times in seconds",
            ),
            Some(f) if f.len() < 2 => {
                invalid(format!("[keyframes] frames lists {} frame(s) of the clip", f.len()), "list at least two frame indices")
            }
            Some(f) => match (1..f.len()).find(|&i| f[i] <= f[i - 1]) {
                Some(i) => invalid(
                    format!("[keyframes] frames are not strictly increasing at entry {i} ({} after {})", f[i], f[i - 1]),
                    "list each frame once, in increasing order",
                ),
                None => Ok(()),
            },
            None if self.times.len() < 2 => {
                invalid(format!("[keyframes] times lists {} time(s) of the clip", self.times.len()), "list at least two times")
            }
            None => Ok(()),
        }
    }
}
