//! keyframes = "auto": the fewest keys whose Hermite fit ([`super::fit`]) stays within a
//! tolerance of every cache frame (largest vertex distance / the cache's bounding-box diagonal).
//!
//! Keys placed where the error is largest cluster around hard spots and stall (each new key
//! next to an old one barely helps), so selection is a shortest path over a cheap model,
//! checked and repaired with the real fit (`formats/cache-keyframes.md` gives the costs):
//!
//! 1. **Candidates by shortest path.** A model that needs no solve: an interval `[a, b]` keeps
//!    the cache positions at `a` and `b`, and takes the velocities the cache shows inside it
//!    (the slope of the parabola through `a` and the two frames after it, and through `b` and
//!    the two before it). The interval is feasible when this model is within the tolerance at
//!    every frame between. The fewest keys is the shortest path from the first frame to the
//!    last over feasible intervals (ties: the path furthest inside the feasible reach, for
//!    headroom). One pass over the cache with a sliding window of frames; the reach of each
//!    frame is found by galloping search, a few interval checks per frame.
//! 2. **Fit and repair.** The least-squares fit on those keys, checked at every frame; every
//!    interval still over the tolerance is split at its middle frame (not at its worst frame),
//!    and the fit is redone, until no frame is over.
//! 3. **Calibration.** The fit is usually well inside the tolerance on the model's keys, so
//!    stages 1 and 2 are rerun with the model's tolerance stretched by the headroom the fit
//!    left, bisecting between stretches that needed repairs and stretches that did not; the
//!    round with the fewest keys is kept. When the model's keys need repairs at the requested
//!    tolerance itself, the model is tightened instead (a quarter at a time) until its keys
//!    need none: repairs split intervals at their middle, off the frames a tighter model
//!    would have chosen, so without this a looser tolerance could end with more keys than a
//!    tighter one (a two-target morph clip: 11 keys at 0.005, 8 at 0.001). A first clean
//!    round with little headroom (under 1.25) is probed once at twice the slack, kept when
//!    clean: stretching by the headroom would barely move the model, while a looser model can
//!    land on frames that fit far closer (the same clip: 9 keys at 8.3e-4 for 0.001, where
//!    0.002 finds its 8 exact keys). Of rounds with as many keys, the closest fit is kept.
//! 4. **Removal.** Keys of the quietest intervals first: remove the key and refit the two keys
//!    on each side with the keys beyond them held (a local least-squares problem over a few
//!    intervals, reading only their frames); keep the removal when that window stays within
//!    90% of the tolerance. The patched trajectory still meets the tolerance everywhere.
//! 5. **Final fit** on the surviving keys, with stage 2's repair if least squares lands over
//!    the tolerance somewhere (and the keys before stage 4 if that repair adds as many keys
//!    as stage 4 removed).
//!
//! Stage 1 is exact for its model when feasibility is monotone (then no fewer keys meet the
//! tolerance with cache positions and cache slopes at the keys); stage 2 makes the fit meet
//! it, and stages 3 and 4 turn the fit's extra freedom (moving key positions, sharing
//! velocities) into fewer keys. Everything is sequential and deterministic: the same cache
//! gives the same keys.

use std::collections::{BTreeSet, VecDeque};

use super::deviation::{cache_diagonal, deviation, frame_distance, CacheDeviation};
use super::fit::{fit, FitSettings, NormalEquations};
use super::FrameSource;
use crate::algorithms::geometry::Point;
use crate::algorithms::spacetime::trajectory::{hermite_weights, Trajectory};
use crate::support::error::{Error, Result};

/// Settings of the automatic key selection.
#[derive(Debug, Clone, PartialEq)]
pub struct AutoSettings {
    /// Largest vertex distance allowed at any frame, relative to the cache's bounding-box
    /// diagonal (`> 0`).
    pub tolerance: f64,
    /// Settings of every least-squares fit the selection solves.
    pub fit: FitSettings,
    /// Empty, or one flag per vertex: flagged vertices keep their cache positions at every key.
    pub pinned: Vec<bool>,
    /// Memory for the frames held at once: stage 1's window (it bounds the longest interval to
    /// `window_bytes / (72 * vertices)` frames, at least 8) and stage 4's trials (re-read from
    /// the source when over).
    pub window_bytes: usize,
}

impl Default for AutoSettings {
    fn default() -> Self {
        AutoSettings { tolerance: 0.005, fit: FitSettings::default(), pinned: Vec::new(), window_bytes: 256 << 20 }
    }
}

/// Removals are kept when the local refit stays within this fraction of the tolerance, which
/// leaves the global refit room to redistribute the error.
const REMOVAL_MARGIN: f64 = 0.9;

/// Rounds of stages 1 and 2 at most (see the calibration in [`select`]).
const CALIBRATION_ROUNDS: usize = 8;

/// Below this headroom (tolerance over the fit's error) stretching the model by the headroom
/// would barely move it: calibration probes twice the slack once instead.
const PROBE_HEADROOM: f64 = 1.25;

/// One round of stages 1 and 2.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Round {
    /// The model's tolerance, as a multiple of the requested one.
    pub slack: f64,
    /// Keys of the shortest path (stage 1).
    pub candidate_keys: usize,
    /// Keys after the fit's repair (stage 2).
    pub fitted_keys: usize,
}

/// What stage of the selection did how much work.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SelectionStats {
    /// Frames in the cache.
    pub frames: usize,
    /// What each round of stages 1 to 5 did.
    pub rounds: Vec<Round>,
    /// Keys added by the repairs (stages 2 and 5, all rounds).
    pub inserted: usize,
    /// Keys removed by stage 4 (0 when stage 5 had to take them back).
    pub removed: usize,
    /// Frames read from the source over the whole selection (a pass is `frames` reads).
    pub frame_reads: usize,
    /// Most frames stage 1 held at once.
    pub window_frames: usize,
    /// Global least-squares fits solved.
    pub global_fits: usize,
}

/// The keys chosen, their fit, and its distance from every frame.
#[derive(Debug, Clone, PartialEq)]
pub struct AutoKeys {
    /// Frame indices, strictly increasing, first and last frame included.
    pub keys: Vec<usize>,
    /// The least-squares fit on `keys` ([`super::fit::fit`] with the same settings).
    pub trajectory: Trajectory,
    /// The fit's distance from every frame.
    pub deviation: CacheDeviation,
    /// How much work the selection did.
    pub stats: SelectionStats,
}

/// Choose keys for a cache. See the module documentation for the algorithm.
pub fn select<S: FrameSource + ?Sized>(source: &mut S, settings: &AutoSettings) -> Result<AutoKeys> {
    let frames = source.frame_count();
    if frames < 2 {
        return Err(Error::general(format!("a cache of {frames} frame(s) has no motion to key"), "use a cache with at least two frames"));
    }
    if !(settings.tolerance > 0.0 && settings.tolerance.is_finite()) {
        return Err(Error::general(
            format!("the keyframe tolerance {} is not a positive number", settings.tolerance),
            "set tolerance to a fraction of the bounding-box diagonal, e.g. 0.005",
        ));
    }
    let vertices = source.vertex_count();
    if !settings.pinned.is_empty() && settings.pinned.len() != vertices {
        return Err(Error::general(
            format!("the pinned-vertex mask has {} entries for {vertices} vertices", settings.pinned.len()),
            "give one flag per cache vertex, or none",
        ));
    }
    let mut source = super::Metered::new(source, |_, _| Ok(()));
    let diagonal = cache_diagonal(&mut source)?;
    let scale = if diagonal > 0.0 { diagonal } else { 1.0 };
    let eps = settings.tolerance * scale;
    let max_window = (settings.window_bytes / (72 * vertices.max(1))).max(8);

    // Stages 1 and 2, calibrated: the fit is usually well inside the tolerance on the model's
    // keys, so the model is rerun with its tolerance stretched by the headroom the fit left
    // (the slack). A slack whose keys the fit had to repair is too much: the next round
    // bisects (geometrically) between the largest clean slack and the smallest repaired one.
    let mut stats = SelectionStats { frames, rounds: Vec::new(), inserted: 0, removed: 0, frame_reads: 0, window_frames: 0, global_fits: 0 };
    // `clean`: the largest slack whose keys needed no repair (0: none yet).
    let (mut slack, mut clean, mut repaired) = (1.0f64, 0.0f64, f64::INFINITY);
    let mut best: Option<(Vec<usize>, Trajectory, CacheDeviation)> = None;
    let mut best_clean = usize::MAX;
    // Outcomes by candidate keys (fitted key count, headroom): the same keys need no new fit.
    let mut seen: Vec<(Vec<usize>, usize, f64)> = Vec::new();
    // Whether this round is the probe at twice a clean slack with little headroom.
    let mut probing = false;
    for _ in 0..CALIBRATION_ROUNDS {
        let (candidates, window_frames) = shortest_path(&mut source, eps * slack, max_window)?;
        stats.window_frames = stats.window_frames.max(window_frames);
        let (fitted, headroom) = match seen.iter().find(|s| s.0 == candidates) {
            Some(&(_, fitted, headroom)) => (fitted, headroom),
            None => {
                let mut keys = candidates.clone();
                let (trajectory, dev) = repair(&mut source, &mut keys, settings, diagonal, &mut stats)?;
                let headroom = if dev.max > 0.0 { settings.tolerance / dev.max } else { f64::INFINITY };
                let fitted = keys.len();
                // Fewest keys; of as many, the smallest error (a looser model's keys can fit
                // closer than a tighter one's).
                if best.as_ref().is_none_or(|b| fitted < b.0.len() || (fitted == b.0.len() && dev.max < b.2.max)) {
                    best = Some((keys, trajectory, dev));
                }
                seen.push((candidates.clone(), fitted, headroom));
                (fitted, headroom)
            }
        };
        stats.rounds.push(Round { slack, candidate_keys: candidates.len(), fitted_keys: fitted });
        if fitted == candidates.len() {
            // Clean: stretch further, unless stretching stopped paying.
            if fitted >= best_clean || candidates.len() <= 2 {
                break;
            }
            best_clean = fitted;
            clean = slack;
            probing = false;
            slack = if repaired.is_finite() {
                (clean * repaired).sqrt()
            } else if headroom < PROBE_HEADROOM {
                // The fit barely meets the tolerance on these keys, but a looser model may
                // land on other frames that fit closer (a morph clip's own key frames, which
                // fit exactly): one round at twice the slack, kept only if it needs no repair.
                probing = true;
                slack * 2.0
            } else {
                slack * headroom.min(16.0)
            };
        } else {
            repaired = slack;
            if probing {
                break;
            }
            // No clean round yet: the model itself is too loose for this cache (its slopes
            // miss what the fit can do), and splitting the repaired intervals at their middle
            // lands keys off the cache's own key frames. Tighten the model until its keys need
            // no repair, as a tighter tolerance would: a looser tolerance must never end with
            // more keys than a tighter one.
            // A tighter model never has fewer candidate keys (feasibility is monotone in the
            // tolerance), so once they are as many as the best fit's, tightening is done.
            if clean == 0.0 && best.as_ref().is_some_and(|b| candidates.len() >= b.0.len()) {
                break;
            }
            slack = if clean > 0.0 { (clean * repaired).sqrt() } else { slack / 4.0 };
        }
        if clean > 0.0 && repaired / clean < 1.15 {
            break;
        }
    }
    let best_fit = best.expect("at least one round");
    let (mut keys, mut trajectory, mut dev) = best_fit.clone();

    // Stage 4: quietest keys first; ties by position.
    let mut interval_error = vec![0.0f64; keys.len() - 1];
    for (f, &e) in dev.per_frame_max.iter().enumerate() {
        let i = keys.partition_point(|&k| k <= f).clamp(1, keys.len() - 1) - 1;
        interval_error[i] = interval_error[i].max(e);
    }
    let mut order: Vec<usize> = (1..keys.len() - 1).collect();
    order.sort_by(|&a, &b| interval_error[a - 1].max(interval_error[a]).total_cmp(&interval_error[b - 1].max(interval_error[b])).then(a.cmp(&b)));
    let order: Vec<usize> = order.iter().map(|&k| keys[k]).collect();
    for frame in order {
        let k = keys.binary_search(&frame).expect("keys are only removed by this loop");
        if let Some((lo, local)) = try_removal(&mut source, &keys, &trajectory, k, eps * REMOVAL_MARGIN, settings)? {
            keys.remove(k);
            splice(&mut trajectory, lo, local);
            stats.removed += 1;
        }
    }

    // Stage 5. Should the refit need more repairs than the removals saved, the keys before
    // stage 4 stand.
    if stats.removed > 0 {
        let before = (keys.len() + stats.removed, best_fit);
        (trajectory, dev) = repair(&mut source, &mut keys, settings, diagonal, &mut stats)?;
        if keys.len() >= before.0 {
            (keys, trajectory, dev) = before.1;
            stats.removed = 0;
        }
    }
    stats.frame_reads = source.reads;
    Ok(AutoKeys { keys, trajectory, deviation: dev, stats })
}

/// Stage 1: the fewest keys such that every interval between consecutive keys, modelled from
/// its own end frames, is within `eps` of every frame inside it. Returns the keys and the most
/// frames held at once.
///
/// Feasibility is taken as monotone (a longer interval is no closer): the reach `e(a)`, the
/// last frame an interval from `a` may end on, is found by galloping from `e(a - 1)` and
/// bisecting, a few interval checks per frame instead of one per frame in reach. Every
/// interval `[a, b]`, `b <= e(a)`, is then an edge; the shortest path breaks ties by the
/// smallest largest `(b - a) / (e(a) - a)` on the path: the path furthest inside the reaches.
fn shortest_path<S: FrameSource + ?Sized>(source: &mut S, eps: f64, max_window: usize) -> Result<(Vec<usize>, usize)> {
    let frames = source.frame_count();
    let mut window = FrameWindow::new(source);
    // best[b] = (keys on the best path to b, largest reach use on it); pred[b] = the key before b.
    let mut best = vec![(usize::MAX, f64::INFINITY); frames];
    let mut pred = vec![usize::MAX; frames];
    best[0] = (1, 0.0);
    let mut reach = 1;
    for a in 0..frames - 1 {
        window.drop_before(a);
        let cap = (frames - 1).min(a + max_window - 1);
        // Adjacent frames have no frame between: always feasible.
        let mut good = a + 1;
        if cap >= a + 2 {
            let mut feasible = |b: usize| -> Result<bool> {
                window.load_through(source, b)?;
                Ok(window.within(a, b, eps))
            };
            let start = reach.clamp(a + 2, cap);
            let mut bad = None;
            if feasible(start)? {
                good = start;
                let mut step = 1;
                while good < cap {
                    let next = (good + step).min(cap);
                    if feasible(next)? {
                        good = next;
                        step *= 2;
                    } else {
                        bad = Some(next);
                        break;
                    }
                }
            } else {
                bad = Some(start);
            }
            if let Some(mut bad) = bad {
                while bad - good > 1 {
                    let mid = good + (bad - good) / 2;
                    if feasible(mid)? {
                        good = mid;
                    } else {
                        bad = mid;
                    }
                }
            }
        }
        reach = good;
        let (count, worst) = best[a];
        for b in a + 1..=good {
            let candidate = (count + 1, worst.max((b - a) as f64 / (good - a) as f64));
            if candidate.0 < best[b].0 || (candidate.0 == best[b].0 && candidate.1 < best[b].1) {
                best[b] = candidate;
                pred[b] = a;
            }
        }
    }
    let mut keys = vec![frames - 1];
    while keys[keys.len() - 1] != 0 {
        keys.push(pred[keys[keys.len() - 1]]);
    }
    keys.reverse();
    Ok((keys, window.peak))
}

/// Consecutive frames held in memory, each with its one-sided velocity estimates: `forward`
/// from the frame and the two after it, `backward` from the two before it and the frame (the
/// derivative of the parabola through the three; second order in the frame spacing). An
/// interval `[a, b]` takes `a`'s forward and `b`'s backward velocity, so it is modelled from
/// its own frames only, and a kink in the motion at a key (an impact, an acceleration jump)
/// does not spoil either side.
struct FrameWindow {
    /// Index of `frames[0]`.
    first: usize,
    frames: VecDeque<Vec<Point>>,
    forward: VecDeque<Option<Vec<Point>>>,
    backward: VecDeque<Option<Vec<Point>>>,
    times: Vec<f64>,
    peak: usize,
}

impl FrameWindow {
    fn new<S: FrameSource + ?Sized>(source: &S) -> FrameWindow {
        let times = (0..source.frame_count()).map(|f| source.time(f)).collect();
        FrameWindow { first: 0, frames: VecDeque::new(), forward: VecDeque::new(), backward: VecDeque::new(), times, peak: 0 }
    }

    fn end(&self) -> usize {
        self.first + self.frames.len()
    }

    fn frame(&self, f: usize) -> &[Point] {
        &self.frames[f - self.first]
    }

    /// Forget frames before `a`.
    fn drop_before(&mut self, a: usize) {
        while self.first < a && !self.frames.is_empty() {
            self.frames.pop_front();
            self.forward.pop_front();
            self.backward.pop_front();
            self.first += 1;
        }
        self.first = self.first.max(a);
    }

    fn load_through<S: FrameSource + ?Sized>(&mut self, source: &mut S, last: usize) -> Result<()> {
        while self.end() <= last {
            let g = self.end();
            let mut y = vec![[0.0; 3]; source.vertex_count()];
            source.read_frame(g, &mut y)?;
            self.frames.push_back(y);
            self.forward.push_back(None);
            self.backward.push_back(None);
            self.peak = self.peak.max(self.frames.len());
            if g >= 2 && g - 2 >= self.first {
                let back = self.derivative(g, [g - 2, g - 1, g]);
                let fwd = self.derivative(g - 2, [g - 2, g - 1, g]);
                self.backward[g - self.first] = Some(back);
                self.forward[g - 2 - self.first] = Some(fwd);
            }
        }
        Ok(())
    }

    /// At `t_f`, the derivative of the parabola through the three stencil frames.
    fn derivative(&self, f: usize, stencil: [usize; 3]) -> Vec<Point> {
        let t = stencil.map(|s| self.times[s]);
        let tf = self.times[f];
        // d/dt of the Lagrange basis polynomial of node i, at tf.
        let c: [f64; 3] = std::array::from_fn(|i| {
            let (j, k) = ((i + 1) % 3, (i + 2) % 3);
            ((tf - t[j]) + (tf - t[k])) / ((t[i] - t[j]) * (t[i] - t[k]))
        });
        let [y0, y1, y2] = stencil.map(|s| self.frame(s));
        (0..y0.len()).map(|p| std::array::from_fn(|d| c[0] * y0[p][d] + c[1] * y1[p][d] + c[2] * y2[p][d])).collect()
    }

    /// Whether the model interval `[a, b]` (`b >= a + 2`, all its frames held) is within `eps`
    /// of every frame strictly inside.
    fn within(&self, a: usize, b: usize, eps: f64) -> bool {
        let (ta, tb) = (self.times[a], self.times[b]);
        let len = tb - ta;
        let (ya, yb) = (self.frame(a), self.frame(b));
        let va = self.forward[a - self.first].as_deref().expect("frames a..a+2 are held");
        let vb = self.backward[b - self.first].as_deref().expect("frames b-2..b are held");
        let eps2 = eps * eps;
        // Middle frames first: that is where an interval too long fails.
        let mid = (a + b) / 2;
        let order = (mid..b).chain((a + 1..mid).rev());
        for f in order {
            let w = hermite_weights((self.times[f] - ta) / len, len).pos;
            let y = self.frame(f);
            for p in 0..y.len() {
                let mut d2 = 0.0;
                for d in 0..3 {
                    let x = w[0] * ya[p][d] + w[1] * va[p][d] + w[2] * yb[p][d] + w[3] * vb[p][d];
                    d2 += (x - y[p][d]) * (x - y[p][d]);
                }
                if d2 > eps2 {
                    return false;
                }
            }
        }
        true
    }
}

/// Stages 2 and 5: fit, and split every interval that is over the tolerance at its middle
/// frame, until none is. Ends at the latest with every frame a key (an exact fit).
fn repair<S: FrameSource + ?Sized>(
    source: &mut S,
    keys: &mut Vec<usize>,
    settings: &AutoSettings,
    diagonal: f64,
    stats: &mut SelectionStats,
) -> Result<(Trajectory, CacheDeviation)> {
    loop {
        let pins: Vec<Vec<bool>> = if settings.pinned.is_empty() { Vec::new() } else { vec![settings.pinned.clone(); keys.len()] };
        let trajectory = fit(source, keys, &pins, &settings.fit)?;
        let dev = deviation(source, &trajectory, diagonal)?;
        stats.global_fits += 1;
        let mut split = BTreeSet::new();
        for (f, &e) in dev.per_frame_max.iter().enumerate() {
            if e > settings.tolerance {
                let i = keys.partition_point(|&k| k <= f).clamp(1, keys.len() - 1) - 1;
                split.insert(i);
                // A key frame over the tolerance is pulled by both of its intervals.
                if f == keys[i] && i > 0 {
                    split.insert(i - 1);
                }
            }
        }
        if split.is_empty() {
            return Ok((trajectory, dev));
        }
        let mut splittable: Vec<usize> = split.into_iter().filter(|&i| keys[i + 1] - keys[i] >= 2).collect();
        if splittable.is_empty() {
            // Every violated interval is already two adjacent frames: split the longest one.
            let longest = (0..keys.len() - 1).max_by_key(|&i| (keys[i + 1] - keys[i], usize::MAX - i)).expect("two keys");
            if keys[longest + 1] - keys[longest] < 2 {
                // Every frame is a key: nothing left to add.
                return Ok((trajectory, dev));
            }
            splittable.push(longest);
        }
        let mut added: Vec<usize> = splittable.iter().map(|&i| middle_frame(source, keys[i], keys[i + 1])).collect();
        stats.inserted += added.len();
        keys.append(&mut added);
        keys.sort_unstable();
    }
}

/// The frame strictly between `a` and `b` (at least two apart) nearest the middle time.
fn middle_frame<S: FrameSource + ?Sized>(source: &S, a: usize, b: usize) -> usize {
    let mid = 0.5 * (source.time(a) + source.time(b));
    (a + 1..b).min_by(|&f, &g| (source.time(f) - mid).abs().total_cmp(&(source.time(g) - mid).abs())).expect("a frame between")
}

/// Stage 4: the fit of the keys around key `k` without it, the keys two away (if any) held at
/// their current positions and velocities. Returns the first key index of the window and the
/// refitted window (its keys, `k` left out), if it stays within `eps` of its frames.
fn try_removal<S: FrameSource + ?Sized>(
    source: &mut S,
    keys: &[usize],
    trajectory: &Trajectory,
    k: usize,
    eps: f64,
    settings: &AutoSettings,
) -> Result<Option<(usize, Trajectory)>> {
    let last = keys.len() - 1;
    let (lo, hi) = (k.saturating_sub(2), (k + 2).min(last));
    let window: Vec<usize> = (lo..=hi).filter(|&i| i != k).collect();
    let times: Vec<f64> = window.iter().map(|&i| trajectory.times[i]).collect();
    let vertices = source.vertex_count();
    let mut system = NormalEquations::new(times, vertices, settings.fit.regularization);
    let mut key_frames: Vec<Option<Vec<Point>>> = vec![None; window.len()];
    let mut frame = vec![[0.0; 3]; vertices];
    // The window's frames are kept for the check below when they fit the memory budget.
    let keep = (keys[hi] - keys[lo] + 1) * 24 * vertices <= settings.window_bytes;
    let mut kept: Vec<Vec<Point>> = Vec::new();
    for f in keys[lo]..=keys[hi] {
        source.read_frame(f, &mut frame)?;
        system.add_frame(source.time(f), &frame);
        if keep {
            kept.push(frame.clone());
        }
        if let Some(j) = window.iter().position(|&i| keys[i] == f) {
            if !settings.pinned.is_empty() {
                key_frames[j] = Some(frame.clone());
            }
        }
    }
    // Held: both unknowns of an end key that has intervals outside the window; pinned vertices'
    // positions at the other keys.
    let held = |j: usize| (j == 0 && lo > 0) || (j == window.len() - 1 && hi < last);
    let pattern = |pinned: bool| -> Vec<bool> { (0..window.len()).flat_map(|j| [held(j) || pinned, held(j)]).collect() };
    let patterns = vec![pattern(false), pattern(true)];
    let vertex_pattern: Vec<usize> = (0..vertices).map(|v| usize::from(settings.pinned.get(v) == Some(&true))).collect();
    let fixed_value = |row: usize, column: usize| -> f64 {
        let (j, v, d) = (row / 2, column / 3, column % 3);
        if held(j) {
            let i = window[j];
            if row.is_multiple_of(2) {
                trajectory.positions[i][v][d]
            } else {
                trajectory.velocities[i][v][d]
            }
        } else {
            key_frames[j].as_ref().expect("pinned key frames were captured")[v][d]
        }
    };
    let Ok(local) = system.solve(&patterns, &vertex_pattern, &fixed_value) else {
        // Undetermined without the key (possible only with no regularization): keep the key.
        return Ok(None);
    };
    // Every frame of the window; the end keys' own frames only where the end key moved.
    let mut pose = vec![[0.0; 3]; vertices];
    let first = keys[lo] + usize::from(held(0));
    let last = keys[hi] - usize::from(held(window.len() - 1));
    for f in first..=last {
        let y = if keep {
            &kept[f - keys[lo]]
        } else {
            source.read_frame(f, &mut frame)?;
            &frame
        };
        local.evaluate_into(source.time(f), &mut pose);
        if frame_distance(y, &pose).0 > eps {
            return Ok(None);
        }
    }
    Ok(Some((lo, local)))
}

/// Replace keys `lo ..= lo + local.key_count()` of `trajectory` (one more than `local` has: the
/// removed key) by `local`'s keys.
fn splice(trajectory: &mut Trajectory, lo: usize, local: Trajectory) {
    let range = lo..lo + local.key_count() + 1;
    trajectory.times.splice(range.clone(), local.times);
    trajectory.positions.splice(range.clone(), local.positions);
    trajectory.velocities.splice(range, local.velocities);
}

#[cfg(test)]
mod tests;
