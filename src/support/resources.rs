//! Memory estimates, checked before the large allocations: the frames an export or a report
//! evaluates (frames x vertices) and the spacetime samples the solver keeps (samples x tets).
//! A scene whose estimate exceeds the memory budget is a one-line error with the estimate in
//! GB and the setting to change, instead of a capacity-overflow panic or an allocation abort.
//!
//! The estimates are in `f64`, so absurd settings (`samples = 9223372036854775807`) cannot
//! overflow. They are deliberately rough upper bounds of the dominant arrays, not a profile.

use crate::support::error::{Error, Result};

/// Bytes per evaluated frame and vertex: the full-frame pose (3 f64), the blendshape
/// reconstruction compared with it in the report, and the written copy (USD text or glb).
const BYTES_PER_FRAME_VERTEX: f64 = 4.0 * 24.0;
/// Bytes per frame for the frame list itself (frame number and time).
const BYTES_PER_FRAME: f64 = 16.0;
/// Bytes per spacetime sample and tet: the projection target (a 3x3 matrix), its residual and
/// deformation gradient, and the optional projection Jacobian the timing derivatives keep.
const BYTES_PER_SAMPLE_TET: f64 = 4.0 * 72.0;

/// The fraction of the machine's available memory a bake may use when no `--max-memory` is
/// given (the rest is for the process's other arrays, the OS and other programs).
pub const DEFAULT_MEMORY_FRACTION: f64 = 0.6;

/// `--max-memory`, once the CLI has read it (see [`set_max_memory`]).
static MAX_MEMORY: std::sync::OnceLock<u64> = std::sync::OnceLock::new();

/// Route the CLI's `--max-memory` (bytes) here: from then on it is the one budget of every
/// estimate ([`check`]) and of the solver's direct factorization. Set once per process.
pub fn set_max_memory(bytes: u64) {
    let _ = MAX_MEMORY.set(bytes);
}

/// The `--max-time` budget: when it was set, and its seconds.
static MAX_TIME: std::sync::OnceLock<(std::time::Instant, f64)> = std::sync::OnceLock::new();

/// Route the CLI's `--max-time` (seconds, counted from this call) here: from then on TetGen
/// is bounded by what is left of it ([`time_left`]) and the solve, the cache fit, its key
/// selection and error measure, and the mass-spring blend check it ([`check_time`], [`check_predicted_time`]). Set once per process.
pub fn set_max_time(seconds: f64) {
    let _ = MAX_TIME.set((std::time::Instant::now(), seconds));
}

/// What to do when the time budget runs out (the same advice wherever it runs out).
const TIME_FIX: &str = "raise --max-time, or make the problem smaller: raise [tet] max_volume, lower [solver] samples or max_iterations, or let [tet] cage simulate a coarser body";

/// Err when the bake has run past `--max-time` (none set: always Ok). `phase` and `reached`
/// say where it stopped, e.g. "solve" and "after 12 iterations".
pub fn check_time(phase: &str, reached: impl FnOnce() -> String) -> Result<()> {
    match MAX_TIME.get() {
        Some(&(start, seconds)) if start.elapsed().as_secs_f64() > seconds => Err(time_spent(phase, &reached())),
        _ => Ok(()),
    }
}

/// Seconds left of `--max-time` (negative once spent), `None` when none was set. A process
/// the bake waits for (TetGen) is given at most this long.
pub fn time_left() -> Option<f64> {
    MAX_TIME.get().map(|&(start, seconds)| seconds - start.elapsed().as_secs_f64())
}

/// [`check_time`]'s error, for a caller that stopped the work itself when [`time_left`] ran
/// out (a killed TetGen). No budget set: an error saying so (callers only use it with one).
pub fn time_spent(phase: &str, reached: &str) -> Error {
    let (elapsed, seconds) = MAX_TIME.get().map_or((0.0, 0.0), |&(start, seconds)| (start.elapsed().as_secs_f64(), seconds));
    Error::general(format!("blendsim ran past its --max-time budget of {seconds} s ({}) in the {phase}, {reached}", duration(elapsed)), TIME_FIX)
}

/// Err when `what` is predicted to take more than the time left of `--max-time` (before it
/// starts; a budget already spent is [`check_time`]'s error).
pub fn check_predicted_time(predicted_seconds: f64, what: &str) -> Result<()> {
    check_time("solve", || "before its global step was built".into())?;
    match MAX_TIME.get() {
        Some(&(start, seconds)) if predicted_seconds > seconds - start.elapsed().as_secs_f64() => Err(Error::general(
            format!(
                "{what} would take about {}, more than the {} left of the --max-time budget of {seconds} s",
                duration(predicted_seconds),
                duration(seconds - start.elapsed().as_secs_f64())
            ),
            TIME_FIX,
        )),
        _ => Ok(()),
    }
}

/// Seconds for a message: two decimals below ten seconds, whole seconds above.
fn duration(seconds: f64) -> String {
    if seconds < 10.0 {
        format!("{seconds:.2} s")
    } else {
        format!("{seconds:.0} s")
    }
}

/// The one memory budget of a bake, in bytes: `--max-memory` when given, else
/// [`DEFAULT_MEMORY_FRACTION`] of the machine's available memory (`MemAvailable` in
/// `/proc/meminfo`), or `None` where that is unknown (no check). Every pre-allocation estimate
/// and the global step's choice between its direct and iterative solve read it here.
pub fn memory_budget() -> Option<f64> {
    match MAX_MEMORY.get() {
        Some(&bytes) => Some(bytes as f64),
        None => available_memory().map(|m| DEFAULT_MEMORY_FRACTION * m),
    }
}

/// Where the budget came from, for messages.
fn budget_source() -> &'static str {
    if MAX_MEMORY.get().is_some() {
        "the --max-memory budget"
    } else {
        "the memory budget (60% of the available memory; --max-memory sets it)"
    }
}

/// `MemAvailable` of `/proc/meminfo`, in bytes.
pub fn available_memory() -> Option<f64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kb: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024.0)
}

/// Frames of an animation from `start` to `end` seconds at `fps` (an upper bound).
pub fn frame_count(start: f64, end: f64, fps: f64) -> f64 {
    ((end - start) * fps).abs().floor() + 2.0
}

/// Fail when `bytes` exceed the budget. `what` says what needs the memory, `fix` which
/// setting to change.
pub fn check(bytes: f64, what: &str, fix: &str) -> Result<()> {
    check_against(bytes, memory_budget(), what, fix)
}

fn check_against(bytes: f64, budget: Option<f64>, what: &str, fix: &str) -> Result<()> {
    match budget {
        Some(budget) if bytes.is_nan() || bytes > budget => Err(Error::general(
            format!("the scene would need about {} of memory for {what}, more than {} of {}", gb(bytes), budget_source(), gb(budget)),
            format!("{fix}; or raise --max-memory"),
        )),
        _ => Ok(()),
    }
}

fn gb(bytes: f64) -> String {
    let g = bytes / 1e9;
    if g < 0.1 {
        format!("{:.1} MB", bytes / 1e6)
    } else if g < 1e6 {
        format!("{g:.1} GB")
    } else {
        format!("{g:.1e} GB")
    }
}

/// The frames an export or a report evaluates: `frames x vertices`.
pub fn check_frames(start: f64, end: f64, fps: f64, vertices: usize) -> Result<()> {
    let frames = frame_count(start, end, fps);
    let bytes = frames * (BYTES_PER_FRAME + BYTES_PER_FRAME_VERTEX * vertices as f64);
    check(
        bytes,
        &format!("{frames:.3e} frames ({} s at {fps} fps) of {vertices} vertices", end - start),
        "lower fps, or shorten the key times (they are in seconds)",
    )
}

/// The spacetime samples the solver keeps: `samples per interval x intervals x tets`.
pub fn check_samples(samples: usize, intervals: usize, tets: usize) -> Result<()> {
    let bytes = samples as f64 * intervals as f64 * tets as f64 * BYTES_PER_SAMPLE_TET;
    check(bytes, &format!("{samples} samples per interval x {intervals} intervals x {tets} tets"), "lower [solver] samples (10 is typical)")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn estimates_over_the_budget_fail_with_the_estimate() {
        let e = check_against(3.0e10, Some(2.0e10), "x", "y").unwrap_err();
        assert!(e.problem.starts_with("the scene would need about 30.0 GB of memory for x, more than the "), "{}", e.problem);
        assert!(e.problem.ends_with(" of 20.0 GB"), "{}", e.problem);
        assert!(check_against(1.0e9, Some(2.0e10), "x", "y").is_ok());
        assert!(check_against(f64::INFINITY, Some(2.0e10), "x", "y").is_err());
        assert!(check_against(f64::NAN, Some(2.0e10), "x", "y").is_err());
        assert!(check_against(1e300, None, "x", "y").is_ok());
        assert!(check_samples(usize::MAX, 1, 1).is_err() || memory_budget().is_none());
        assert!(available_memory().is_none_or(|m| m > 0.0));
    }

    #[test]
    fn frame_counts_include_both_ends() {
        assert_eq!(frame_count(0.0, 1.0, 60.0), 62.0);
        assert_eq!(frame_count(0.0, 1e6, 1e9), 1e15 + 2.0);
    }
}
