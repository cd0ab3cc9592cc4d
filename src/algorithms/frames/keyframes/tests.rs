use super::*;
use crate::algorithms::frames::MemoryFrames;

fn sampled(count: usize, fps: f64, rest: &[Point], x: impl Fn(Point, f64) -> Point) -> MemoryFrames {
    let times: Vec<f64> = (0..count).map(|f| f as f64 / fps).collect();
    let frames = times.iter().map(|&t| rest.iter().map(|&p| x(p, t)).collect()).collect();
    MemoryFrames { times, frames }
}

/// A 3 x 3 x 3 grid of points in the unit cube.
fn grid() -> Vec<Point> {
    (0..27).map(|i| [(i % 3) as f64 * 0.5, ((i / 3) % 3) as f64 * 0.5, (i / 9) as f64 * 0.5]).collect()
}

fn settings(tolerance: f64) -> AutoSettings {
    AutoSettings { tolerance, ..AutoSettings::default() }
}

/// The selection meets the tolerance at every frame, its trajectory is the plain fit on its
/// keys, and no single key can be dropped with the fit still within tolerance (checked by
/// refitting without each key in turn). Returns the key count.
fn check(cache: &mut MemoryFrames, s: &AutoSettings, name: &str) -> usize {
    let auto = select(cache, s).unwrap();
    let frames = cache.frames.len();
    assert_eq!(auto.keys[0], 0);
    assert_eq!(*auto.keys.last().unwrap(), frames - 1);
    assert_eq!(auto.deviation.per_frame_max.len(), frames);
    assert!(auto.deviation.max <= s.tolerance, "{name}: max error {} over tolerance {}", auto.deviation.max, s.tolerance);
    let pins: Vec<Vec<bool>> = if s.pinned.is_empty() { vec![] } else { vec![s.pinned.clone(); auto.keys.len()] };
    assert_eq!(fit(cache, &auto.keys, &pins, &s.fit).unwrap(), auto.trajectory, "{name}: the trajectory is the fit on the keys");
    let diagonal = cache_diagonal(cache).unwrap();
    let mut removable = Vec::new();
    for k in 1..auto.keys.len() - 1 {
        let mut fewer = auto.keys.clone();
        fewer.remove(k);
        let pins: Vec<Vec<bool>> = if s.pinned.is_empty() { vec![] } else { vec![s.pinned.clone(); fewer.len()] };
        let tr = fit(cache, &fewer, &pins, &s.fit).unwrap();
        if deviation(cache, &tr, diagonal).unwrap().max <= s.tolerance {
            removable.push(auto.keys[k]);
        }
    }
    let uniform = fewest_uniform_keys(cache, s, diagonal);
    println!(
        "{name}: {} keys for {frames} frames (rounds {:?}, inserted {}, removed {}), max error {:.2e}, {} frame reads ({:.1} passes), {} global fits, removable: {removable:?}, uniform: {}",
        auto.keys.len(),
        auto.stats.rounds.iter().map(|r| (r.slack, r.candidate_keys, r.fitted_keys)).collect::<Vec<_>>(),
        auto.stats.inserted,
        auto.stats.removed,
        auto.deviation.max,
        auto.stats.frame_reads,
        auto.stats.frame_reads as f64 / frames as f64,
        auto.stats.global_fits,
        uniform,
    );
    assert!(removable.is_empty(), "{name}: keys {removable:?} can each be removed within tolerance");
    assert!(auto.keys.len() <= uniform, "{name}: {} keys, but {uniform} evenly spaced keys meet the tolerance", auto.keys.len());
    auto.keys.len()
}

/// The fewest evenly spaced keys whose fit meets the tolerance: the yardstick for smooth,
/// uniform motions (for which evenly spaced keys are near optimal).
fn fewest_uniform_keys(cache: &mut MemoryFrames, s: &AutoSettings, diagonal: f64) -> usize {
    let frames = cache.frames.len();
    (2..=frames)
        .find(|&n| {
            let keys: Vec<usize> = (0..n).map(|k| (k * (frames - 1) + (n - 1) / 2) / (n - 1)).collect();
            let pins: Vec<Vec<bool>> = if s.pinned.is_empty() { vec![] } else { vec![s.pinned.clone(); n] };
            let tr = fit(cache, &keys, &pins, &s.fit).unwrap();
            deviation(cache, &tr, diagonal).unwrap().max <= s.tolerance
        })
        .unwrap()
}

#[test]
fn a_hermite_cache_needs_no_more_keys_than_it_was_made_with() {
    let rest = grid();
    let truth_keys = [0usize, 20, 45, 70, 100];
    let fps = 30.0;
    let times: Vec<f64> = truth_keys.iter().map(|&f| f as f64 / fps).collect();
    let positions: Vec<Vec<Point>> =
        (0..5).map(|k| rest.iter().map(|p| [p[0] + (k % 2) as f64 * 0.4, p[1] * (1.0 + 0.1 * k as f64), p[2]]).collect()).collect();
    let velocities: Vec<Vec<Point>> = (0..5).map(|k| rest.iter().map(|p| [0.3 * (k as f64 - 2.0), -p[0], 0.5 * p[1]]).collect()).collect();
    let truth = Trajectory { times, positions, velocities };
    let mut cache = sampled(101, fps, &rest, |_, _| [0.0; 3]);
    for (f, frame) in cache.frames.iter_mut().enumerate() {
        *frame = truth.evaluate(f as f64 / fps);
    }
    let n = check(&mut cache, &settings(1e-3), "hermite");
    assert!(n <= truth_keys.len(), "{n} keys");
}

#[test]
fn a_sine_wave_gets_keys_in_proportion_to_its_periods() {
    let rest = grid();
    let wave = |p: Point, t: f64, hz: f64| [p[0], p[1] + 0.3 * (std::f64::consts::TAU * (hz * t + p[0])).sin(), p[2]];
    let mut slow = sampled(181, 60.0, &rest, |p, t| wave(p, t, 1.0));
    let mut fast = sampled(181, 60.0, &rest, |p, t| wave(p, t, 2.0));
    let n_slow = check(&mut slow, &settings(0.005), "sine 1 Hz");
    let n_fast = check(&mut fast, &settings(0.005), "sine 2 Hz");
    // Cubic pieces: error ~ (interval)^4, so a constant key density per period, well below the frame count.
    assert!(n_slow <= 181 / 8, "{n_slow}");
    assert!(n_fast > n_slow && n_fast <= 2 * n_slow + 2, "{n_slow} -> {n_fast}");
}

#[test]
fn a_rigid_rotation_meets_the_tolerance() {
    let rest = grid();
    let spin = |p: Point, t: f64| {
        let a = 2.0 * t; // rad/s
        let (c, s) = (a.cos(), a.sin());
        let (x, z) = (p[0] - 0.5, p[2] - 0.5);
        [0.5 + c * x - s * z, p[1], 0.5 + s * x + c * z]
    };
    let mut cache = sampled(241, 60.0, &rest, spin);
    let n = check(&mut cache, &settings(0.002), "rigid rotation");
    assert!(n < 241 / 10, "{n}");
}

#[test]
fn a_still_cache_needs_two_keys() {
    let rest = grid();
    let mut cache = sampled(50, 24.0, &rest, |p, _| p);
    let auto = select(&mut cache, &settings(0.005)).unwrap();
    assert_eq!(auto.keys, vec![0, 49]);
    assert!(auto.deviation.max < 1e-12);
}

#[test]
fn a_jump_gets_keys_on_both_sides_and_the_fit_stays_within_tolerance() {
    // A teleport between frames 29 and 30: no cubic can follow it, the keys must close in.
    let rest = grid();
    let mut cache = sampled(60, 30.0, &rest, |p, t| if t < 1.0 { p } else { [p[0] + 1.0, p[1], p[2]] });
    check(&mut cache, &settings(0.01), "jump");
    let auto = select(&mut cache, &settings(0.01)).unwrap();
    assert!(auto.keys.contains(&29) && auto.keys.contains(&30), "{:?}", auto.keys);
    assert!(auto.keys.len() <= 8, "{:?}", auto.keys);
}

#[test]
fn pinned_vertices_keep_their_cache_positions_at_every_key() {
    let rest = grid();
    let mut cache = sampled(121, 60.0, &rest, |p, t| [p[0], p[1] + 0.2 * p[0] * (5.0 * t).sin(), p[2]]);
    let pinned: Vec<bool> = rest.iter().map(|p| p[0] == 1.0).collect();
    let s = AutoSettings { pinned: pinned.clone(), ..settings(0.003) };
    check(&mut cache, &s, "pinned");
    let auto = select(&mut cache, &s).unwrap();
    for (k, &f) in auto.keys.iter().enumerate() {
        for v in (0..rest.len()).filter(|&v| pinned[v]) {
            assert_eq!(auto.trajectory.positions[k][v], cache.frames[f][v]);
        }
    }
}

#[test]
fn same_cache_same_keys() {
    let rest = grid();
    let mut cache = sampled(150, 60.0, &rest, |p, t| [p[0] + 0.1 * (7.0 * t).sin() * p[1], p[1] + 0.2 * (3.0 * t + p[2]).cos(), p[2]]);
    let a = select(&mut cache, &settings(0.002)).unwrap();
    let b = select(&mut cache, &settings(0.002)).unwrap();
    assert_eq!(a, b);
}

#[test]
fn a_small_window_budget_still_meets_the_tolerance() {
    // 8 frames at most in memory: long quiet stretches need extra keys, never a violation.
    let rest = grid();
    let mut cache = sampled(100, 30.0, &rest, |p, t| [p[0] + 0.05 * t, p[1], p[2]]);
    let auto = select(&mut cache, &AutoSettings { window_bytes: 1, ..settings(0.005) }).unwrap();
    assert!(auto.stats.window_frames <= 8, "{}", auto.stats.window_frames);
    assert!(auto.deviation.max <= 0.005);
}

#[test]
fn bad_settings_are_one_line_errors() {
    let rest = grid();
    let mut cache = sampled(10, 30.0, &rest, |p, _| p);
    for (s, want) in [
        (settings(0.0), "not a positive number"),
        (settings(f64::NAN), "not a positive number"),
        (AutoSettings { pinned: vec![true; 3], ..settings(0.01) }, "3 entries for 27 vertices"),
    ] {
        let e = select(&mut cache, &s).unwrap_err();
        assert!(e.problem.contains(want), "{e}");
    }
    let mut one = sampled(1, 30.0, &rest, |p, _| p);
    assert!(select(&mut one, &settings(0.01)).unwrap_err().problem.contains("1 frame"));
}

#[test]
fn a_read_error_is_passed_on_not_a_panic() {
    let rest = grid();
    let mut inner = sampled(40, 30.0, &rest, |p, t| [p[0] + t, p[1], p[2]]);
    // The file goes bad at frame 23.
    let mut bad = crate::algorithms::frames::Metered::new(&mut inner, |frame, _| match frame {
        23 => Err(Error::in_file("anim.pc2", format!("frame {frame} is truncated at byte 4096"), "re-export the cache")),
        _ => Ok(()),
    });
    let e = select(&mut bad, &settings(0.005)).unwrap_err();
    assert_eq!(e.to_string(), "anim.pc2: frame 23 is truncated at byte 4096 (fix: re-export the cache)");
    let e = fit(&mut bad, &[0, 39], &[], &FitSettings::default()).unwrap_err();
    assert!(e.problem.contains("frame 23"));
    let e = deviation(&mut bad, &Trajectory::with_zero_velocities(vec![0.0, 1.0], vec![rest.clone(), rest.clone()]), 1.0).unwrap_err();
    assert!(e.problem.contains("frame 23"));
}

/// A two-target morph clip: two shapes blended by C1 weight curves keyed at uneven frames
/// (what a glTF morph clip with CUBICSPLINE weights holds), exact for a Hermite fit on the
/// weights' own keys.
fn two_target_clip() -> MemoryFrames {
    let rest = grid();
    let fps = 30.0;
    let key_frames = [0usize, 9, 23, 31, 52, 60, 77, 90];
    let times: Vec<f64> = key_frames.iter().map(|&f| f as f64 / fps).collect();
    let w: Vec<[f64; 2]> = (0..key_frames.len()).map(|k| [((k * 7) % 5) as f64 / 4.0, ((k * 3) % 4) as f64 / 3.0]).collect();
    let wv: Vec<[f64; 2]> = (0..key_frames.len()).map(|k| [((k * 5) % 3) as f64 - 1.0, 2.0 - ((k * 11) % 5) as f64]).collect();
    let one = |c: usize| Trajectory {
        times: times.clone(),
        positions: w.iter().map(|w| vec![[w[c], 0.0, 0.0]]).collect(),
        velocities: wv.iter().map(|v| vec![[v[c], 0.0, 0.0]]).collect(),
    };
    let (w0, w1) = (one(0), one(1));
    let target0 = |p: Point| [0.3 * p[1], 0.2 * p[0] * p[2], -0.1];
    let target1 = |p: Point| [-0.05, 0.25 * p[2] * p[2], 0.15 * p[0]];
    sampled(91, fps, &rest, |p, t| {
        let (a, b) = (w0.evaluate(t)[0][0], w1.evaluate(t)[0][0]);
        let (d0, d1) = (target0(p), target1(p));
        std::array::from_fn(|d| p[d] + a * d0[d] + b * d1[d])
    })
}

/// The sweep meets every tolerance, and a tighter tolerance never picks fewer keys nor gives
/// a larger error (the cases: a looser tolerance no longer repairs its way to more
/// keys than the 8 an exact fit needs, and 0.001 no longer stops at 9 keys and 8.3e-4 where
/// twice the tolerance finds the exact 8).
#[test]
fn a_tighter_tolerance_never_picks_fewer_keys_nor_gives_a_larger_error() {
    let mut cache = two_target_clip();
    let (mut keys, mut error) = (0, f64::INFINITY);
    for tolerance in [0.05, 0.02, 0.01, 0.007, 0.005, 0.003, 0.002, 0.001, 5e-4, 2e-4, 1e-4, 1e-5] {
        let auto = select(&mut cache, &settings(tolerance)).unwrap();
        println!(
            "tolerance {tolerance:.0e}: {} keys {:?}, max error {:.2e}, rounds {:?}",
            auto.keys.len(),
            auto.keys,
            auto.deviation.max,
            auto.stats.rounds.iter().map(|r| (r.slack, r.candidate_keys, r.fitted_keys)).collect::<Vec<_>>()
        );
        assert!(auto.deviation.max <= tolerance, "tolerance {tolerance}: max error {}", auto.deviation.max);
        assert!(auto.keys.len() >= keys, "tolerance {tolerance}: {} keys, fewer than the {keys} of a looser tolerance", auto.keys.len());
        assert!(
            auto.deviation.max <= error,
            "tolerance {tolerance}: max error {:.3e}, over the {error:.3e} of a looser tolerance",
            auto.deviation.max
        );
        (keys, error) = (auto.keys.len(), auto.deviation.max);
    }
}
