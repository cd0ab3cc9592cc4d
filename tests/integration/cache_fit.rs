//! The Hermite fit, automatic keyframes and the error report on caches from an independent
//! simulator (rapier3d's FEM: an elastic bar clamped at one end, swinging under gravity).

use std::time::Instant;

use crate::common::bar::{bar, BarSettings};
use blendsim::algorithms::frames::deviation::{cache_diagonal, deviation};
use blendsim::algorithms::frames::fit::{fit, FitSettings};
use blendsim::algorithms::frames::keyframes::{select, AutoSettings};
use blendsim::algorithms::frames::FrameSource;
use blendsim::algorithms::geometry::{bbox_diagonal, norm, sub};

#[test]
fn the_simulated_bar_swings_like_a_cantilever() {
    let settings = BarSettings::default();
    let t = Instant::now();
    let cache = bar(&settings);
    println!(
        "bar: {} nodes, {} tets, {} surface vertices, {} frames ({:.1} s to simulate or load)",
        cache.body.positions.len(),
        cache.body.tets.len(),
        cache.surface.positions.len(),
        cache.frames.frame_count(),
        t.elapsed().as_secs_f64()
    );
    assert!((2500..=3500).contains(&cache.body.tets.len()));
    assert_eq!(cache.frames.frame_count(), 181);
    assert_eq!(cache.frames.vertex_count(), cache.surface.positions.len());
    // Frame 0 is the rest pose in surface order (rapier computes in f32).
    let rest_offset = cache.frames.frames[0].iter().zip(&cache.surface.positions).map(|(p, q)| norm(sub(*p, *q))).fold(0.0, f64::max);
    assert!(rest_offset < 1e-6, "frame 0 is {rest_offset} from the rest surface");
    // The clamped end does not move.
    for frame in &cache.frames.frames {
        for (v, p) in frame.iter().enumerate().filter(|(v, _)| cache.surface.positions[*v][0] == 0.0) {
            assert!(norm(sub(*p, cache.surface.positions[v])) < 1e-6, "clamped vertex {v} moved");
        }
    }
    // The tip swings down and back: count its turning points and compare the period with
    // Euler-Bernoulli (the simulated bar is thick, swings far, and has coarse tets).
    let y: Vec<f64> = cache.tip.iter().map(|p| p[1] - cache.tip[0][1]).collect();
    let lowest = y.iter().copied().fold(f64::INFINITY, f64::min);
    let turns: Vec<usize> = (1..y.len() - 1).filter(|&f| (y[f] - y[f - 1]) * (y[f + 1] - y[f]) < 0.0).collect();
    println!(
        "tip: lowest {lowest:.4} m, turning points at frames {turns:?} (y {:?}), Euler-Bernoulli {:.3} Hz",
        turns.iter().map(|&f| (y[f] * 1000.0).round() / 1000.0).collect::<Vec<_>>(),
        settings.euler_bernoulli_frequency()
    );
    assert!(lowest < -0.05 && lowest > -0.6, "tip sag {lowest}");
    assert!(turns.len() >= 6, "the bar swings several times in 3 s: {turns:?}");
    let period = 2.0 * (turns[turns.len() - 1] - turns[0]) as f64 / (turns.len() - 1) as f64 / settings.fps;
    let expected = 1.0 / settings.euler_bernoulli_frequency();
    println!("period {period:.3} s, Euler-Bernoulli {expected:.3} s");
    assert!((period / expected - 1.0).abs() < 0.3, "period {period} vs {expected}");
    // It settles about the static sag: the middle of its last two turning points.
    let rest_sag = -0.5 * (y[turns[turns.len() - 1]] + y[turns[turns.len() - 2]]);
    println!("settling about a sag of {rest_sag:.4} m, Euler-Bernoulli {:.4} m", settings.euler_bernoulli_sag());
    assert!((rest_sag / settings.euler_bernoulli_sag() - 1.0).abs() < 0.35);
}

#[test]
fn the_bar_is_simulated_once_and_read_back_bit_for_bit() {
    let settings = BarSettings { duration: 0.25, ..BarSettings::default() };
    let a = bar(&settings);
    let b = bar(&settings);
    assert_eq!(a.frames, b.frames);
    assert_eq!(a.tip, b.tip);
}

#[test]
fn auto_keys_meet_the_tolerance_on_the_simulated_bar() {
    let cache = bar(&BarSettings::default());
    let mut frames = cache.frames.clone();
    let settings = AutoSettings { tolerance: 0.005, ..AutoSettings::default() };
    let t = Instant::now();
    let auto = select(&mut frames, &settings).unwrap();
    let seconds = t.elapsed().as_secs_f64();
    println!(
        "bar: {} keys for {} frames {:?}, max error {:.2e}, rms {:.2e}, {:.2} s, {} frame reads, rounds {:?}, inserted {}, removed {}",
        auto.keys.len(),
        frames.frame_count(),
        auto.keys,
        auto.deviation.max,
        auto.deviation.rms,
        seconds,
        auto.stats.frame_reads,
        auto.stats.rounds,
        auto.stats.inserted,
        auto.stats.removed
    );
    assert!(auto.deviation.max <= 0.005);
    assert!(auto.deviation.per_frame_max.iter().all(|&e| e <= 0.005));
    assert!(auto.keys.len() * 6 <= frames.frame_count(), "few keys: {}", auto.keys.len());
    // The report's numbers are the fit's: recomputed independently.
    let diagonal = cache_diagonal(&mut frames).unwrap();
    assert!(diagonal > bbox_diagonal(&cache.surface.positions));
    let refit = fit(&mut frames, &auto.keys, &[], &FitSettings::default()).unwrap();
    assert_eq!(refit, auto.trajectory);
    assert_eq!(deviation(&mut frames, &refit, diagonal).unwrap(), auto.deviation);
    // Same cache, same keys.
    assert_eq!(select(&mut frames, &settings).unwrap().keys, auto.keys);
}

#[test]
fn clamped_vertices_pinned_at_every_key_stay_on_the_cache() {
    let cache = bar(&BarSettings::default());
    let mut frames = cache.frames.clone();
    let pinned: Vec<bool> = cache.surface.positions.iter().map(|p| p[0] == 0.0).collect();
    let auto = select(&mut frames, &AutoSettings { tolerance: 0.005, pinned: pinned.clone(), ..AutoSettings::default() }).unwrap();
    assert!(auto.deviation.max <= 0.005);
    for (k, &f) in auto.keys.iter().enumerate() {
        for v in (0..pinned.len()).filter(|&v| pinned[v]) {
            assert_eq!(auto.trajectory.positions[k][v], frames.frames[f][v]);
        }
    }
}

#[test]
fn auto_needs_no_more_keys_than_evenly_spaced_keys_on_the_bar() {
    let cache = bar(&BarSettings::default());
    let mut frames = cache.frames.clone();
    let diagonal = cache_diagonal(&mut frames).unwrap();
    let n = frames.frame_count();
    let uniform = (2..=n)
        .find(|&k| {
            let keys: Vec<usize> = (0..k).map(|i| (i * (n - 1) + (k - 1) / 2) / (k - 1)).collect();
            let tr = fit(&mut frames, &keys, &[], &FitSettings::default()).unwrap();
            deviation(&mut frames, &tr, diagonal).unwrap().max <= 0.005
        })
        .unwrap();
    let auto = select(&mut frames, &AutoSettings { tolerance: 0.005, ..AutoSettings::default() }).unwrap();
    println!("bar: auto {} keys, fewest evenly spaced {uniform}", auto.keys.len());
    assert!(auto.keys.len() <= uniform);
}
