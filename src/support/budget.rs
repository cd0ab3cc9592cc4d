//! The resources one bake may use, as a value: a memory budget and a time budget
//! ([`Budget`]), made by the CLI from `--max-memory` and `--max-time` and passed down to every
//! stage and algorithm that allocates or runs long. Two bakes in one process can have two
//! budgets; nothing here is process-wide.
//!
//! Memory estimates are checked before the large allocations: the frames an export or a report
//! evaluates (frames x vertices) and the spacetime samples the solver keeps (samples x tets).
//! A scene whose estimate exceeds the memory budget is a one-line error with the estimate in
//! GB and the setting to change, instead of a capacity-overflow panic or an allocation abort.
//!
//! The estimates are in `f64`, so absurd settings (`samples = 9223372036854775807`) cannot
//! overflow. They are deliberately rough upper bounds of the dominant arrays, not a profile.

use std::time::Instant;

use crate::support::error::{Error, Result};

/// Bytes per frame and exported vertex a full-frame export holds: the full-frame poses (3
/// f32, `FullFrame`) and the full-frame glb's morph targets (3 f32, or 3 i16 quantized, held
/// as its blocks until written). `.usda` and `.usdc` stream from the poses, and the report
/// measures one frame at a time; without full-frame files nothing is held per frame and vertex.
/// (The former 96 bytes counted the glb three times, a whole usdc, and every frame's two poses
/// in the report: 62 bytes measured per frame and vertex, 54 of them without full-frame files.)
const BYTES_PER_FULL_FRAME_VERTEX: f64 = 24.0;
/// Bytes per frame for the frame list itself (frame number and time).
const BYTES_PER_FRAME: f64 = 16.0;
/// Bytes per spacetime sample and tet: the projection target (a 3x3 matrix), its residual and
/// deformation gradient, and the optional projection Jacobian the timing derivatives keep.
const BYTES_PER_SAMPLE_TET: f64 = 4.0 * 72.0;

/// The fraction of the machine's available memory a bake may use when no `--max-memory` is
/// given (the rest is for the process's other arrays, the OS and other programs).
pub const DEFAULT_MEMORY_FRACTION: f64 = 0.6;

/// What to do when the time budget runs out (the same advice wherever it runs out).
const TIME_FIX: &str = "raise --max-time, or make the problem smaller: raise [tet] max_volume, lower [solver] samples or max_iterations, or let [tet] cage simulate a coarser body";

/// Where a memory budget came from, so that a message names the budget that applied.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
enum MemorySource {
    /// `--max-memory`.
    Flag,
    /// No `--max-memory`: [`DEFAULT_MEMORY_FRACTION`] of the available memory.
    #[default]
    Default,
    /// No `--max-memory` and the available memory unknown: a figure a step assumed.
    Assumed,
}

/// The memory and time one bake may use.
///
/// Invariant: the time budget's clock started when the budget was made ([`Budget::new`]), so
/// every phase that checks it sees the time spent since the bake began. `Copy`: passed down
/// by value, never stored in a global.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Budget {
    /// `--max-memory` in bytes; `None`: [`DEFAULT_MEMORY_FRACTION`] of the available memory.
    /// Once a step has resolved or narrowed it ([`Budget::with_max_memory`], [`Budget::narrowed_to`]), those bytes.
    max_memory: Option<u64>,
    /// Where `max_memory` came from: `--max-memory` or the default budget.
    source: MemorySource,
    /// Whether `max_memory` is the part of the budget left for one step (the rest held by
    /// the step's caller), not the whole budget.
    part: bool,
    /// `--max-time`: when the clock started, and the seconds allowed from then.
    max_time: Option<(Instant, f64)>,
}

impl Budget {
    /// A budget of `max_memory` bytes and `max_time` seconds counted from now (`None`: the
    /// default memory budget, no time limit).
    pub fn new(max_memory: Option<u64>, max_time: Option<f64>) -> Budget {
        let source = if max_memory.is_some() { MemorySource::Flag } else { MemorySource::Default };
        Budget { max_memory, source, part: false, max_time: max_time.map(|seconds| (Instant::now(), seconds)) }
    }

    /// The same budget with its memory resolved to `bytes` (a step reads the default budget
    /// once, so that a rebuild chooses under the same bytes), its origin kept for messages:
    /// `--max-memory`, the default budget, or a figure assumed where the available memory is
    /// unknown. A part stays a part ([`Budget::narrowed_to`]).
    pub(crate) fn with_max_memory(self, bytes: u64) -> Budget {
        let source = match (self.max_memory, self.source) {
            (None, MemorySource::Default) if available_memory().is_none() => MemorySource::Assumed,
            _ => self.source,
        };
        Budget { max_memory: Some(bytes), source, ..self }
    }

    /// The part of this budget left for one step, `bytes` (the rest held by the step's
    /// caller): messages then say "left for it of" the budget it came from.
    pub(crate) fn narrowed_to(self, bytes: u64) -> Budget {
        Budget { part: true, ..self.with_max_memory(bytes) }
    }

    /// `--max-memory` as given (or as a step resolved it), in bytes.
    pub fn max_memory(&self) -> Option<u64> {
        self.max_memory
    }

    /// The memory budget in bytes: `--max-memory` when given, else [`DEFAULT_MEMORY_FRACTION`]
    /// of the machine's available memory now (`MemAvailable`), or `None` where that is
    /// unknown (no check). Every pre-allocation estimate and the global step's choice between
    /// its direct and iterative solve read it here.
    pub fn memory(&self) -> Option<f64> {
        match self.max_memory {
            Some(bytes) => Some(bytes as f64),
            None => available_memory().map(|m| DEFAULT_MEMORY_FRACTION * m),
        }
    }

    /// The memory budget of `bytes` named by where it came from, for messages.
    fn described(&self, bytes: f64) -> String {
        let origin = match self.source {
            MemorySource::Flag => "the --max-memory budget".to_string(),
            MemorySource::Default => {
                format!("the memory budget ({:.0}% of the available memory; --max-memory sets it)", 100.0 * DEFAULT_MEMORY_FRACTION)
            }
            MemorySource::Assumed => "the memory budget assumed where the available memory cannot be read (--max-memory sets it)".to_string(),
        };
        if self.part {
            format!("the {} left for it of {origin}", gb(bytes))
        } else {
            format!("{origin} of {}", gb(bytes))
        }
    }

    /// Fail when `bytes` exceed the memory budget. `what` says what needs the memory, `fix`
    /// which setting to change.
    pub fn check(&self, bytes: f64, what: &str, fix: &str) -> Result<()> {
        match self.memory() {
            Some(budget) if bytes.is_nan() || bytes > budget => Err(Error::general(
                format!("the scene would need about {} of memory for {what}, more than {}", gb(bytes), self.described(budget)),
                format!("{fix}; or raise --max-memory"),
            )),
            _ => Ok(()),
        }
    }

    /// The frames an export or a report evaluates: the frame list, and `frames x vertices`
    /// when the export writes full-frame files (`full_frame`); without them every frame is
    /// evaluated, measured and let go (the report's player is bounded on its own).
    pub(crate) fn check_frames(&self, start: f64, end: f64, fps: f64, vertices: usize, full_frame: bool) -> Result<()> {
        let frames = frame_count(start, end, fps);
        self.check(
            frames_bytes(frames, vertices, full_frame),
            &format!("{frames:.3e} frames ({} s at {fps} fps) of {vertices} vertices", end - start),
            "lower fps, or shorten the key times (they are in seconds)",
        )
    }

    /// The spacetime samples the solver keeps: `samples per interval x intervals x tets`.
    pub(crate) fn check_samples(&self, samples: usize, intervals: usize, tets: usize) -> Result<()> {
        self.check(
            samples_bytes(samples, intervals, tets),
            &format!("{samples} samples per interval x {intervals} intervals x {tets} tets"),
            "lower [solver] samples (10 is typical)",
        )
    }

    /// Err when the bake has run past `--max-time` (none set: always Ok). `phase` and
    /// `reached` say where it stopped, e.g. "solve" and "after 12 iterations".
    pub fn check_time(&self, phase: &str, reached: impl FnOnce() -> String) -> Result<()> {
        match self.max_time {
            Some((start, seconds)) if start.elapsed().as_secs_f64() > seconds => Err(self.time_spent(phase, &reached())),
            _ => Ok(()),
        }
    }

    /// [`Budget::check_time`] with a phase's own `fix` instead of the solve's advice.
    pub(crate) fn check_time_to(&self, phase: &str, reached: impl FnOnce() -> String, fix: &str) -> Result<()> {
        self.check_time(phase, reached).map_err(|e| Error { fix: fix.into(), ..e })
    }

    /// Seconds left of `--max-time` (negative once spent), `None` when none was set. A
    /// process the bake waits for (TetGen) is given at most this long.
    pub fn time_left(&self) -> Option<f64> {
        self.max_time.map(|(start, seconds)| seconds - start.elapsed().as_secs_f64())
    }

    /// [`Budget::check_time`]'s error, for a caller that stopped the work itself when
    /// [`Budget::time_left`] ran out (a killed TetGen).
    pub(crate) fn time_spent(&self, phase: &str, reached: &str) -> Error {
        let (elapsed, seconds) = self.max_time.map_or((0.0, 0.0), |(start, seconds)| (start.elapsed().as_secs_f64(), seconds));
        Error::general(format!("blendsim ran past its --max-time budget of {seconds} s ({}) in the {phase}, {reached}", duration(elapsed)), TIME_FIX)
    }

    /// Err when `what` is predicted to take more than the time left of `--max-time` (before
    /// it starts; a budget already spent is [`Budget::check_time`]'s error).
    pub(crate) fn check_predicted_time(&self, predicted_seconds: f64, what: &str) -> Result<()> {
        self.check_time("solve", || "before its global step was built".into())?;
        match self.time_left() {
            Some(left) if predicted_seconds > left => Err(Error::general(
                format!(
                    "{what} would take about {}, more than the {} left of the --max-time budget of {} s",
                    duration(predicted_seconds),
                    duration(left),
                    self.max_time.map_or(0.0, |(_, s)| s)
                ),
                TIME_FIX,
            )),
            _ => Ok(()),
        }
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

/// `MemAvailable` of `/proc/meminfo`, in bytes.
/// Kept rather than `sysinfo`: four lines here, a dozen dependencies there, for one number.
pub(crate) fn available_memory() -> Option<f64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kb: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024.0)
}

/// The bytes `Budget::check_frames` estimates for `frames` frames of `vertices` vertices.
pub fn frames_bytes(frames: f64, vertices: usize, full_frame: bool) -> f64 {
    frames * (BYTES_PER_FRAME + if full_frame { BYTES_PER_FULL_FRAME_VERTEX * vertices as f64 } else { 0.0 })
}

/// The bytes `Budget::check_samples` estimates.
pub fn samples_bytes(samples: usize, intervals: usize, tets: usize) -> f64 {
    samples as f64 * intervals as f64 * tets as f64 * BYTES_PER_SAMPLE_TET
}

/// Frames of an animation from `start` to `end` seconds at `fps` (an upper bound).
pub fn frame_count(start: f64, end: f64, fps: f64) -> f64 {
    ((end - start) * fps).abs().floor() + 2.0
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn estimates_over_the_budget_fail_with_the_estimate() {
        let budget = Budget::new(Some(20_000_000_000), None);
        let e = budget.check(3.0e10, "x", "y").unwrap_err();
        assert_eq!(e.problem, "the scene would need about 30.0 GB of memory for x, more than the --max-memory budget of 20.0 GB");
        assert!(budget.check(1.0e9, "x", "y").is_ok());
        assert!(budget.check(f64::INFINITY, "x", "y").is_err());
        assert!(budget.check(f64::NAN, "x", "y").is_err());
        assert!(budget.check_samples(usize::MAX, 1, 1).is_err());
        assert!(Budget::default().check_samples(usize::MAX, 1, 1).is_err() || Budget::default().memory().is_none());
        assert!(available_memory().is_none_or(|m| m > 0.0));
    }

    #[test]
    fn two_budgets_in_one_process_are_independent() {
        let (small, large) = (Budget::new(Some(1_000_000), None), Budget::new(Some(1 << 40), None));
        assert!(small.check_frames(0.0, 1.0, 60.0, 10_000, true).is_err());
        assert!(large.check_frames(0.0, 1.0, 60.0, 10_000, true).is_ok());
        let (spent, open) = (Budget::new(None, Some(0.0)), Budget::new(None, Some(3600.0)));
        std::thread::sleep(std::time::Duration::from_millis(2));
        let e = spent.check_time("solve", || "after 3 iterations".into()).unwrap_err();
        assert!(e.problem.starts_with("blendsim ran past its --max-time budget of 0 s ("), "{}", e.problem);
        assert!(e.problem.ends_with(") in the solve, after 3 iterations"), "{}", e.problem);
        assert!(open.check_time("solve", || unreachable!()).is_ok());
        assert!(open.check_predicted_time(7200.0, "the direct solve").is_err());
        assert!(open.check_predicted_time(1.0, "the direct solve").is_ok());
        assert!(Budget::default().time_left().is_none() && Budget::default().check_predicted_time(1e300, "x").is_ok());
    }

    #[test]
    fn messages_name_the_budget_that_applied() {
        let problem = |b: Budget| b.check(3.0e10, "x", "y").unwrap_err().problem;
        let flag = Budget::new(Some(20_000_000_000), None);
        assert!(problem(flag.with_max_memory(2_000_000_000)).ends_with("more than the --max-memory budget of 2.0 GB"));
        assert!(problem(flag.narrowed_to(2_000_000_000)).ends_with("more than the 2.0 GB left for it of the --max-memory budget"));
        // No --max-memory: a budget resolved or narrowed from the default one still says so.
        let default = Budget::new(None, None);
        let (resolved, part) = (default.with_max_memory(2_000_000_000), default.narrowed_to(1_000_000_000));
        if available_memory().is_some() {
            let origin = "the memory budget (60% of the available memory; --max-memory sets it)";
            assert_eq!(problem(resolved), format!("the scene would need about 30.0 GB of memory for x, more than {origin} of 2.0 GB"));
            assert!(problem(part).ends_with(&format!("more than the 1.0 GB left for it of {origin}")), "{}", problem(part));
            // Narrowed twice, still a part of the default budget.
            assert!(problem(part.with_max_memory(500_000_000)).ends_with(&format!("the 0.5 GB left for it of {origin}")));
        } else {
            assert!(problem(resolved).contains("the memory budget assumed where the available memory cannot be read"));
        }
        for b in [resolved, part] {
            assert!(!problem(b).contains("the --max-memory budget"), "{}", problem(b));
        }
    }

    #[test]
    fn frame_counts_include_both_ends() {
        assert_eq!(frame_count(0.0, 1.0, 60.0), 62.0);
        assert_eq!(frame_count(0.0, 1e6, 1e9), 1e15 + 2.0);
    }
}
