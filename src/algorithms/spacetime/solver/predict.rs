//! How far a solve is from its stop: the stopping rule's last window and the geometric
//! extrapolation of the windows' decreases, for the log and for the progress bar.

use super::super::settings::WINDOW;

/// The decrease of W over the last window, and the geometric extrapolation of the last two
/// windows' decreases (the solver's module documentation), both relative to `W + floor`.
pub(super) fn prediction(energy: &[f64], floor: f64) -> (f64, Option<f64>) {
    let k = energy.len() - 1;
    let w = energy[k] + floor;
    if w <= 0.0 || k == 0 {
        return (0.0, None);
    }
    let window = WINDOW.min(k);
    let last = energy[k - window] - energy[k];
    if k < 2 * WINDOW {
        return (last / w, None);
    }
    let before = energy[k - 2 * WINDOW] - energy[k - WINDOW];
    let ratio = last / before;
    let remaining = (before > 0.0 && ratio < 1.0).then(|| last * ratio / (1.0 - ratio) / w);
    (last / w, remaining)
}

/// The iterations left before the stopping rule stops a solve whose W went through `energy`
/// (one entry per iteration, the first guess first), for a progress estimate: the same
/// geometric extrapolation of the last two windows' decreases as [`Log::predicted_remaining`](super::Log::predicted_remaining),
/// run forward until the window's decrease falls to `tolerance` of the W it levels off at plus
/// `floor` (the stopping rule's `negligible × S`). `None` before two windows, or when the
/// decreases do not shrink (or W heads to zero with no floor, where a relative rule has no
/// predictable end); `Some(0)` once the last window is within tolerance.
pub fn predicted_iterations(energy: &[f64], tolerance: f64, floor: f64) -> Option<usize> {
    let k = energy.len().checked_sub(1)?;
    if k < 2 * WINDOW {
        return None;
    }
    let last = energy[k - WINDOW] - energy[k];
    let before = energy[k - 2 * WINDOW] - energy[k - WINDOW];
    if last <= tolerance * (energy[k] + floor) {
        return Some(0);
    }
    let ratio = last / before;
    if !(before > 0.0 && ratio > 0.0 && ratio < 1.0) {
        return None;
    }
    // Decreases over a sliding window shrink by `ratio` every WINDOW iterations; the rule's
    // reference `W + floor` levels off at `settled` (W's limit clamped at 0: W is never negative).
    let settled = (energy[k] - last * ratio / (1.0 - ratio)).max(0.0) + floor;
    if settled.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        return None;
    }
    let windows = (tolerance * settled / last).ln() / ratio.ln();
    Some((WINDOW as f64 * windows).ceil().max(0.0) as usize)
}

/// The predicted total iteration count of a running solve, for its progress bar: the median
/// of the last WINDOW `predicted_iterations`, shown only while most of them exist. After a
/// stall W can speed up again (a buckling, a contact settling); the few windows whose decrease
/// shrinks again right after it extrapolate from one uncertain ratio and can be off by 4x, so
/// a total waits for a majority of the window to agree rather than show one of them.
#[derive(Debug, Default)]
pub struct IterationEstimate {
    energy: Vec<f64>,
    totals: std::collections::VecDeque<Option<usize>>,
    shown: Option<usize>,
}

impl IterationEstimate {
    /// Record iteration `k`'s `w` and the stopping rule's `floor` (the arguments of
    /// `solve`'s `on_iteration`), and return the predicted total (at least `k`, at most
    /// `max_iterations`), or `None` while nothing reliable is predicted.
    pub fn update(&mut self, k: usize, w: f64, floor: f64, tolerance: f64, max_iterations: usize) -> Option<usize> {
        self.energy.push(w);
        self.totals.push_back(predicted_iterations(&self.energy, tolerance, floor).map(|left| (k + left).min(max_iterations)));
        if self.totals.len() > WINDOW {
            self.totals.pop_front();
        }
        let mut known: Vec<usize> = self.totals.iter().flatten().copied().collect();
        known.sort_unstable();
        if self.totals.len() == WINDOW && 2 * known.len() > WINDOW {
            self.shown = Some(known[known.len() / 2].max(k));
        } else if self.shown.is_some_and(|n| n < k) {
            // The last total stands until it is passed.
            self.shown = None;
        }
        self.shown
    }
}
