//! `report.json` `series`: the per-frame and per-iteration numbers the plots of `report.html`
//! draw (volume over the frames, the error per frame, the phases of W's iterations).

use serde::{Deserialize, Serialize};

use crate::pipeline::scene::Method;
use crate::pipeline::stage_file::SolverLog;

/// The per-frame and per-iteration series of a bake.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Series {
    /// Seconds of the frames of the key range at the scene's fps (the frames `volume` is
    /// measured at).
    pub frame_times: Vec<f64>,
    /// Present when the surface is closed: enclosed volume per frame.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub volume: Option<VolumeSeries>,
    /// The blendshape animation against its reference, per frame.
    pub error: ErrorSeries,
    /// The phases of `solver.energy`, in order.
    pub energy_phases: Vec<Phase>,
}

/// Enclosed volume per frame, as a ratio to the rest volume.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct VolumeSeries {
    /// The exported animation, at `frame_times`.
    pub animation: Vec<f64>,
    /// The hermite baseline (input keys, zero velocities), at `frame_times`.
    pub hermite: Vec<f64>,
    /// The keys: their times, the animation's own key volumes and the input keys' volumes.
    pub keys: Vec<KeyVolume>,
}

/// One key's volumes, as ratios to the rest volume.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct KeyVolume {
    /// The key's time in seconds (the solution's).
    pub time: f64,
    /// The animation at the key (where the physics moved it).
    pub animation: f64,
    /// The input keyframe.
    pub input: f64,
}

/// Distances per frame between the blendshape animation and its reference, relative to a
/// bounding-box diagonal (`report.json` `error` or `cache.error` says which).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ErrorSeries {
    /// `full-frame`: the full-frame evaluation of the trajectory (a keyframe bake; the error is
    /// `error`'s, the storage error); `cache`: the input cache's frames (`cache.error`'s).
    pub reference: String,
    /// The frames' times in seconds.
    pub times: Vec<f64>,
    /// The largest vertex distance per frame.
    pub max: Vec<f64>,
    /// The root mean square vertex distance per frame.
    pub rms: Vec<f64>,
}

/// A phase of the iterations: `solver.energy[first..=last]`, `first` the iterate it starts from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Phase {
    /// `coarse`, `local/global`, `quasi-Newton`, or `iterations` when the log does not split them.
    pub name: String,
    /// Index in `solver.energy` of the iterate the phase starts from.
    pub first: usize,
    /// Index in `solver.energy` of its last iterate.
    pub last: usize,
}

/// The phases of `log.energy`: the coarse phase (`[solver] coarse_samples`), then the
/// local/global and quasi-Newton iterations as the solver's stop reason counts them. A log
/// that does not split them (other methods, a warm start, an older report) is one phase.
pub fn energy_phases(log: &SolverLog) -> Vec<Phase> {
    let last = log.energy.len().saturating_sub(1);
    if last == 0 {
        return Vec::new();
    }
    let mut phases = Vec::new();
    let mut at = 0;
    if log.coarse_iterations > 0 {
        phases.push(Phase { name: "coarse".into(), first: 0, last: 1 });
        at = 1;
    }
    let counts = (log.method == Method::Spacetime).then(|| split_counts(&log.stop_reason)).flatten();
    match counts {
        Some((lg, qn)) if at + lg + qn == last => {
            for (name, n) in [("local/global", lg), ("quasi-Newton", qn)] {
                if n > 0 {
                    phases.push(Phase { name: name.into(), first: at, last: at + n });
                    at += n;
                }
            }
        }
        _ => phases.push(Phase { name: "iterations".into(), first: at, last }),
    }
    phases
}

/// `(local/global, quasi-Newton)` from a stop reason holding `N local/global + M quasi-Newton`.
fn split_counts(reason: &str) -> Option<(usize, usize)> {
    let number_before = |end: usize| {
        let head = reason[..end].trim_end();
        let start = head.rfind(|c: char| !c.is_ascii_digit()).map_or(0, |i| i + 1);
        head[start..].parse::<usize>().ok()
    };
    let lg = number_before(reason.find(" local/global + ")?)?;
    let qn_at = reason.find(" quasi-Newton iterations")?;
    Some((lg, number_before(qn_at)?))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn splits_the_stop_reason() {
        assert_eq!(split_counts("W decreased ... (23 local/global + 94 quasi-Newton iterations)"), Some((23, 94)));
        assert_eq!(split_counts("hermite: nothing to optimize"), None);
    }
}
