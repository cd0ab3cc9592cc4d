//! Guard rails: the warnings a bake's own figures call for, so that a result a user should not
//! trust never passes silently under exit 0 (`formats/report.md`, "Warnings").
//!
//! Every warning, these and the stages' own, is one line that starts with a stable code and a
//! colon (`not-converged: ...`), so scripts match the code and people read the rest.

use super::Report;
use crate::pipeline::scene::Method;
use crate::pipeline::stage_file::SolverLog;

/// The codes of the warnings a bake can give, in the order the report lists them.
pub mod code {
    /// A key of a tet body with inverted or flattened tets (a rig pose; `tetrahedralize`).
    pub(crate) const FOLDED_KEY: &str = "folded-key";
    /// TetGen left a tet far over `[tet] max_volume` (`tetrahedralize`).
    pub(crate) const MAX_VOLUME: &str = "max-volume";
    /// The body's size, in meters after `units`, is far from what the material is meant for
    /// (`tetrahedralize`).
    pub(crate) const BODY_SIZE: &str = "body-size";
    /// An `[embed] surface` reaching far outside the body (`tetrahedralize`).
    pub const EMBED_FAR: &str = "embed-far";
    /// A cache file stating a unit other than the scene's `units` (`tetrahedralize`).
    pub(crate) const UNITS_CONFLICT: &str = "units-conflict";
    /// Iterative global-step solves stopped at their iteration cap short of their residual
    /// goal (`solve`).
    pub(crate) const CG_CAPPED: &str = "cg-capped";
    /// The solve stopped before its stopping rule was met.
    pub(crate) const NOT_CONVERGED: &str = "not-converged";
    /// The exported animation misses the input keyframes by more than [`super::KEYS_MOVED_SHARE`].
    pub(crate) const KEYS_MOVED: &str = "keys-moved";
    /// The volume left the band [`super::VOLUME_BAND`] around rest while hermite stayed in it.
    pub const VOLUME_BAND: &str = "volume-band";
    /// The key times are probably frame numbers ([`super::looks_like_frames`]).
    pub(crate) const TIMES_LOOK_LIKE_FRAMES: &str = "times-look-like-frames";
    /// A blendshape file larger than the full-frame file or the cache it replaces.
    pub(crate) const OUTPUT_LARGER: &str = "output-larger";
    /// A glb whose quantization error, read back from the file, exceeds the scene's tolerance.
    pub(crate) const QUANTIZATION_ERROR: &str = "quantization-error";
    /// A cache bake whose in-betweens (physics or interpolation, not a fit) end far from the
    /// cache: more than [`super::CACHE_DRIFT_FACTOR`] times what its keys can do.
    pub(crate) const CACHE_DRIFT: &str = "cache-drift";
}

/// `code: message`, the form of every warning line.
pub fn coded(code: &str, message: impl std::fmt::Display) -> String {
    format!("{code}: {message}")
}

/// The code a warning line starts with; `warning` for a report written before codes existed.
pub(crate) fn code_of(warning: &str) -> &str {
    match warning.split_once(": ") {
        Some((code, _)) if !code.is_empty() && code.bytes().all(|b| b.is_ascii_lowercase() || b == b'-') => code,
        _ => "warning",
    }
}

/// Keyframe deviation (largest distance, relative to the rest bbox diagonal) past which the
/// solver's moving of unpinned key vertices is a warning. The demo moves 0.071, the paper
/// scenes at most 0.107 (stretch); the base-only pin moved 0.565, the demo at 100x 0.26.
pub const KEYS_MOVED_SHARE: f64 = 0.15;

/// The band around the rest volume (as a ratio, `1 ± VOLUME_BAND`) an animation should stay in
/// when hermite does. Of the demo and the paper scenes, those whose hermite stays in it (dino,
/// ball, spot) keep 0.95 to 1.03 of rest; the others' keys themselves leave it (hermite down
/// to 0.45 on the paper's twist), so only the physics is blamed.
pub const VOLUME_BAND: f64 = 0.1;

/// How far past what its keys can do (the larger of the scene's tolerance and the least-squares
/// fit's error on the same keys) a cache bake's error against the cache may go before it warns
/// `cache-drift`: an order of magnitude. The methods other than `fit` fill the in-betweens with
/// physics or interpolation, not with the cache, so they may miss it by a few tolerances. The
/// rapier bar's cache with `spacetime`: its auto keys at tolerance 0.005 (fit 3.6e-3) end 6.7e-2
/// from it (13x, warned); keys 5 frames apart on its first 20 frames, 5.0e-3 (fit 5.9e-4).
pub const CACHE_DRIFT_FACTOR: f64 = 10.0;

/// Key times spanning more than this many seconds, all whole numbers, look like frame numbers.
pub const FRAME_TIMES_MIN_SPAN_S: f64 = 10.0;

/// Whether `times` (seconds, ascending) look like frame numbers: at least two keys, every time a
/// whole number, and a span over [`FRAME_TIMES_MIN_SPAN_S`]. Keys in seconds are rarely all
/// whole and that far apart (a 10 s clip keyed only on whole seconds); frames at any frame rate
/// are whole and span more than 10 as soon as the clip is longer than 10 frames.
pub fn looks_like_frames(times: &[f64]) -> bool {
    let span = times.last().zip(times.first()).map_or(0.0, |(b, a)| b - a);
    times.len() >= 2 && times.iter().all(|t| t.fract() == 0.0) && span > FRAME_TIMES_MIN_SPAN_S
}

/// The guard-rail warnings of a finished report (its outputs and ratios filled in).
pub fn guard_rails(report: &Report) -> Vec<String> {
    let mut out = Vec::new();
    let sv = &report.solver;
    out.extend(not_converged(sv));
    let moved = report.keyframe_deviation.max;
    if moved > KEYS_MOVED_SHARE {
        out.push(coded(
            code::KEYS_MOVED,
            format!(
                "the animation misses the input keyframes by up to {:.1}% of the bounding-box diagonal (more than {:.0}%): the solver moved key vertices that [keyframes] fixed does not hold (hold them, e.g. fixed = \"all\")",
                100.0 * moved,
                100.0 * KEYS_MOVED_SHARE
            ),
        ));
    }
    if let Some(v) = &report.volume {
        let inside = |min: f64, max: f64| min >= 1.0 - VOLUME_BAND && max <= 1.0 + VOLUME_BAND;
        if !inside(v.animation.min, v.animation.max) && inside(v.hermite.min, v.hermite.max) {
            out.push(coded(
                code::VOLUME_BAND,
                format!(
                    "the volume leaves {:.0}% to {:.0}% of rest ({:.1}% to {:.1}%) while the hermite baseline stays within it ({:.1}% to {:.1}%); the physics, not the keys, changed it (check the mesh's units against [material], and keys that fold tets)",
                    100.0 * (1.0 - VOLUME_BAND),
                    100.0 * (1.0 + VOLUME_BAND),
                    100.0 * v.animation.min,
                    100.0 * v.animation.max,
                    100.0 * v.hermite.min,
                    100.0 * v.hermite.max
                ),
            ));
        }
    }
    // A cache's key times come from its frame rate; a scene's are the user's.
    if report.cache.is_none() && sv.method != Method::Fit && looks_like_frames(&sv.input_times) {
        let span = sv.input_times.last().copied().unwrap_or(0.0) - sv.input_times.first().copied().unwrap_or(0.0);
        out.push(coded(
            code::TIMES_LOOK_LIKE_FRAMES,
            format!(
                "the key times {} are whole numbers spanning {span} s: if they are frame numbers, give seconds (divide by the frame rate: at fps = {} the clip lasts {:.3} s)",
                short_list(&sv.input_times),
                report.fps,
                span / report.fps
            ),
        ));
    }
    out.extend(larger_outputs(report));
    out.extend(cache_drift(report));
    let tolerance = report.cache.as_ref().and_then(|c| c.tolerance).unwrap_or(crate::pipeline::scene::DEFAULT_TOLERANCE);
    for f in &report.outputs {
        if let Some(e) = f.quantization_error.filter(|e| e.is_nan() || *e > tolerance) {
            out.push(coded(
                code::QUANTIZATION_ERROR,
                format!(
                    "{} plays up to {e:.2e} of the bounding-box diagonal away from the animation it holds, over the tolerance {tolerance:e} (write it unquantized: [export] gltf_compression = \"none\")",
                    f.path
                ),
            ));
        }
    }
    out
}

/// The `not-converged` warning of a solve that stopped before its stopping rule was met.
pub fn not_converged(sv: &SolverLog) -> Option<String> {
    (!sv.converged).then(|| {
        coded(
            code::NOT_CONVERGED,
            format!(
                "the {} solve did not converge after {} iterations ({}); the in-betweens may be far from the solution (raise [solver] max_iterations, or hold more vertices with [keyframes] fixed)",
                sv.method, sv.iterations, sv.stop_reason
            ),
        )
    })
}

/// The `cache-drift` warning of a cache bake whose animation misses the cache by more than
/// [`CACHE_DRIFT_FACTOR`] times what its keys can do. Only for methods that do not fit the cache
/// (those with a `fit_error` to compare with).
fn cache_drift(report: &Report) -> Option<String> {
    let c = report.cache.as_ref()?;
    let fit = c.fit_error.as_ref()?.max;
    let tolerance = c.tolerance.unwrap_or(crate::pipeline::scene::DEFAULT_TOLERANCE);
    let reachable = tolerance.max(fit);
    let e = c.error.max;
    let filled_by = if report.solver.method == Method::Hermite { "interpolation" } else { "physics" };
    (e.is_nan() || e > CACHE_DRIFT_FACTOR * reachable).then(|| {
        coded(
            code::CACHE_DRIFT,
            format!(
                "the {} animation is up to {:.1}% of the bounding-box diagonal from the cache {} between keys, {:.0}x the tolerance {tolerance} (the least-squares fit on the same keys: {:.2}%): its in-betweens are {filled_by}, not the cache (to follow the cache use method = \"fit\", or give more keys: a lower [cache] tolerance or more keyframes)",
                report.solver.method,
                100.0 * e,
                c.path,
                e / tolerance,
                100.0 * fit
            ),
        )
    })
}

/// `[0, 24, 48]`, or its first three and last for long lists.
fn short_list(times: &[f64]) -> String {
    let shown: Vec<String> = match times.len() {
        0..=4 => times.iter().map(|t| t.to_string()).collect(),
        n => times[..3].iter().map(|t| t.to_string()).chain(["...".into(), times[n - 1].to_string()]).collect(),
    };
    format!("[{}]", shown.join(", "))
}

/// One warning per blendshape file larger than what it replaces: the full-frame file of its
/// format (`ratios` below 1), or for a cache bake the cache.
fn larger_outputs(report: &Report) -> Vec<String> {
    let mut out = Vec::new();
    for (format, ratio) in &report.ratios {
        if *ratio < 1.0 {
            out.push(coded(
                code::OUTPUT_LARGER,
                format!("the blendshape {format} file is {:.2}x the size of the full-frame one it replaces (few frames per key: store the full-frame file, or give fewer keys)", 1.0 / ratio),
            ));
        }
    }
    if let Some(c) = &report.cache {
        for (format, ratio) in &c.ratios {
            if *ratio < 1.0 {
                out.push(coded(
                    code::OUTPUT_LARGER,
                    format!("the blendshape {format} file is {:.2}x the size of the cache {} it replaces (give fewer keys, or a larger [cache] tolerance)", 1.0 / ratio, c.path),
                ));
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_numbers_are_whole_and_span_more_than_ten() {
        assert!(looks_like_frames(&[0.0, 24.0, 48.0]));
        assert!(looks_like_frames(&[1.0, 12.0]));
        // Seconds: fractional, or whole within 10 s.
        assert!(!looks_like_frames(&[0.0, 0.5, 1.0]));
        assert!(!looks_like_frames(&[0.0, 1.0, 2.0]));
        assert!(!looks_like_frames(&[0.0, 10.0]));
        assert!(!looks_like_frames(&[0.0, 24.5, 48.0]));
        assert!(!looks_like_frames(&[30.0]));
    }

    #[test]
    fn the_code_is_the_lowercase_word_before_the_first_colon() {
        assert_eq!(code_of(&coded(code::KEYS_MOVED, "x: y")), "keys-moved");
        assert_eq!(code_of("dent.obj: key 1 folds"), "warning");
        assert_eq!(code_of("no colon"), "warning");
    }
}
