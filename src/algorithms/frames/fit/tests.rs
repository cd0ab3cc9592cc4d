use super::*;
use crate::algorithms::frames::MemoryFrames;
use crate::algorithms::geometry::norm;

const FPS: f64 = 30.0;

fn frame_times(count: usize) -> Vec<f64> {
    (0..count).map(|f| f as f64 / FPS).collect()
}

/// A cache sampled from a motion `x(vertex, t)` at `count` frames.
fn sampled(count: usize, vertices: usize, x: impl Fn(usize, f64) -> Point) -> MemoryFrames {
    let times = frame_times(count);
    let frames = times.iter().map(|&t| (0..vertices).map(|v| x(v, t)).collect()).collect();
    MemoryFrames { times, frames }
}

/// A Hermite trajectory with arbitrary (deterministic, non-smooth) key values.
fn hermite_on(keys: &[usize], vertices: usize) -> Trajectory {
    let mut s = 0.123f64;
    let mut next = || {
        s = (s * 7919.0 + 0.31).fract();
        2.0 * s - 1.0
    };
    let mut gen = |scale: f64| -> Vec<Vec<Point>> {
        keys.iter().map(|_| (0..vertices).map(|_| [scale * next(), scale * next(), scale * next()]).collect()).collect()
    };
    let positions = gen(1.0);
    let velocities = gen(3.0);
    Trajectory { times: keys.iter().map(|&f| f as f64 / FPS).collect(), positions, velocities }
}

fn max_diff(a: &[Vec<Point>], b: &[Vec<Point>]) -> f64 {
    a.iter().zip(b).flat_map(|(p, q)| p.iter().zip(q).map(|(x, y)| norm(crate::algorithms::geometry::sub(*x, *y)))).fold(0.0, f64::max)
}

fn exact() -> FitSettings {
    FitSettings { regularization: 0.0 }
}

/// The position at every frame of the unit trajectory of one unknown (key `k`, position or
/// velocity, coordinate x of vertex 0): the columns of the dense design matrix.
fn basis_column(times: &[f64], key_times: &[f64], k: usize, velocity: bool) -> Vec<f64> {
    let zero = || vec![vec![[0.0; 3]]; key_times.len()];
    let (mut positions, mut velocities) = (zero(), zero());
    if velocity {
        velocities[k][0][0] = 1.0;
    } else {
        positions[k][0][0] = 1.0;
    }
    let unit = Trajectory { times: key_times.to_vec(), positions, velocities };
    times.iter().map(|&t| unit.evaluate(t)[0][0]).collect()
}

#[test]
fn recovers_a_hermite_cache_exactly() {
    let keys = [0, 7, 13, 25, 40];
    let truth = hermite_on(&keys, 4);
    let mut cache = sampled(41, 4, |v, t| truth.evaluate(t)[v]);
    let got = fit(&mut cache, &keys, &[], &exact()).unwrap();
    assert_eq!(got.times, truth.times);
    assert!(max_diff(&got.positions, &truth.positions) < 1e-11, "{}", max_diff(&got.positions, &truth.positions));
    assert!(max_diff(&got.velocities, &truth.velocities) < 1e-9, "{}", max_diff(&got.velocities, &truth.velocities));
    // The bending term only breaks ties: a determined fit is the same.
    let reg = fit(&mut cache, &keys, &[], &FitSettings::default()).unwrap();
    assert!(max_diff(&reg.positions, &truth.positions) < 1e-11);
    assert!(max_diff(&reg.velocities, &truth.velocities) < 1e-9, "{}", max_diff(&reg.velocities, &truth.velocities));
}

#[test]
fn residual_is_orthogonal_to_every_basis_function() {
    // Not a Hermite curve: the normal equations B^T (y - B u) = 0 must hold for every unknown.
    let keys = [0, 9, 20, 31];
    let mut cache = sampled(32, 3, |v, t| [(3.0 * t + v as f64).sin(), (7.0 * t).cos() * t, (t * t * 5.0).sin() + v as f64]);
    let got = fit(&mut cache, &keys, &[], &exact()).unwrap();
    let residual: Vec<Vec<Point>> = (0..32)
        .map(|f| got.evaluate(cache.times[f]).iter().zip(&cache.frames[f]).map(|(x, y)| crate::algorithms::geometry::sub(*y, *x)).collect())
        .collect();
    let scale: f64 = residual.iter().flatten().map(|r| norm(*r)).fold(0.0, f64::max);
    assert!(scale > 1e-3, "the data must not be fitted exactly ({scale})");
    for k in 0..keys.len() {
        for velocity in [false, true] {
            let phi = basis_column(&cache.times, &got.times, k, velocity);
            for v in 0..3 {
                for d in 0..3 {
                    let dot: f64 = (0..32).map(|f| phi[f] * residual[f][v][d]).sum();
                    assert!(dot.abs() < 1e-12, "key {k} velocity {velocity}: {dot}");
                }
            }
        }
    }
}

#[test]
fn agrees_with_a_dense_least_squares_solve() {
    use faer::linalg::solvers::SolveLstsq;
    let keys = [2, 6, 15, 19];
    let frames = 23;
    let mut cache = sampled(frames, 2, |v, t| [t.exp() * (v as f64 + 1.0), (11.0 * t).sin(), 1.0 / (1.0 + t)]);
    let got = fit(&mut cache, &keys, &[], &exact()).unwrap();
    // Dense design matrix over the fitted frames (2..=19), one column per unknown.
    let fitted: Vec<usize> = (keys[0]..=keys[3]).collect();
    let times: Vec<f64> = fitted.iter().map(|&f| cache.times[f]).collect();
    let cols: Vec<Vec<f64>> = (0..4).flat_map(|k| [false, true].map(|vel| basis_column(&times, &got.times, k, vel))).collect();
    let b = faer::Mat::<f64>::from_fn(times.len(), 8, |r, c| cols[c][r]);
    let y = faer::Mat::<f64>::from_fn(times.len(), 6, |r, c| cache.frames[fitted[r]][c / 3][c % 3]);
    let u = b.qr().solve_lstsq(&y);
    // The default bending term only breaks ties: a determined fit is the same least squares.
    let default = fit(&mut cache, &keys, &[], &FitSettings::default()).unwrap();
    for got in [&got, &default] {
        for k in 0..4 {
            for c in 0..6 {
                let (v, d) = (c / 3, c % 3);
                assert!((u[(2 * k, c)] - got.positions[k][v][d]).abs() < 1e-9, "x key {k} col {c}");
                assert!((u[(2 * k + 1, c)] - got.velocities[k][v][d]).abs() < 1e-8, "v key {k} col {c}");
            }
        }
    }
}

#[test]
fn a_single_interval_holds_any_cubic() {
    let cubic = |v: usize, t: f64| [1.0 + 2.0 * t - 3.0 * t * t + 0.5 * t.powi(3), v as f64 * t.powi(3), -t * t];
    let mut cache = sampled(16, 2, cubic);
    let got = fit(&mut cache, &[0, 15], &[], &exact()).unwrap();
    assert_eq!(got.key_count(), 2);
    for f in 0..16 {
        let t = cache.times[f];
        assert!(max_diff(&[got.evaluate(t)], &[cache.frames[f].clone()]) < 1e-11, "frame {f}");
    }
}

#[test]
fn keys_inside_the_cache_fit_only_their_range() {
    // A cubic between frames 5 and 20; garbage outside, which must not pull the fit.
    let mut cache = sampled(30, 1, |_, t| if (5.0 / FPS..=20.0 / FPS).contains(&t) { [t.powi(3), t, 1.0] } else { [99.0, -99.0, 7.0] });
    let got = fit(&mut cache, &[5, 12, 20], &[], &exact()).unwrap();
    for f in 5..=20 {
        assert!(max_diff(&[got.evaluate(cache.times[f])], &[cache.frames[f].clone()]) < 1e-11, "frame {f}");
    }
    // Outside the key range the trajectory holds its end poses.
    assert_eq!(got.evaluate(0.0), got.positions[0]);
    assert_eq!(got.evaluate(1.0), got.positions[2]);
}

#[test]
fn keys_at_the_first_and_last_frame_fit_every_frame() {
    let mut cache = sampled(50, 2, |v, t| [(4.0 * t).sin(), (v as f64 + 1.0) * (3.0 * t).cos(), t]);
    let got = fit(&mut cache, &[0, 12, 25, 37, 49], &[], &FitSettings::default()).unwrap();
    assert_eq!((got.start(), got.end()), (0.0, 49.0 / FPS));
    // Smooth data, 12-frame intervals: a good fit at every frame, ends included.
    for f in 0..50 {
        let e = max_diff(&[got.evaluate(cache.times[f])], &[cache.frames[f].clone()]);
        assert!(e < 1e-2, "frame {f}: {e}");
    }
}

#[test]
fn keys_on_adjacent_frames_take_the_least_bending_velocity() {
    // Two frames: positions are determined, velocities are not. With the bending term the fit is
    // the straight line; without it the system is singular, and that is a one-line error.
    let mut cache = MemoryFrames { times: vec![0.0, 0.5], frames: vec![vec![[0.0, 1.0, 2.0]], vec![[1.0, 1.0, 0.0]]] };
    let got = fit(&mut cache, &[0, 1], &[], &FitSettings::default()).unwrap();
    for k in 0..2 {
        let v = got.velocities[k][0];
        assert!((v[0] - 2.0).abs() < 1e-6 && v[1].abs() < 1e-6 && (v[2] + 4.0).abs() < 1e-6, "{v:?}");
    }
    let err = fit(&mut cache, &[0, 1], &[], &exact()).unwrap_err();
    assert!(err.problem.contains("velocity of the key at frame 0"), "{err}");
    assert!(!err.to_string().contains('\n'));
}

#[test]
fn pins_hold_key_positions_on_the_cache() {
    let mut cache = sampled(31, 3, |v, t| [(6.0 * t + v as f64).sin(), (9.0 * t).cos(), t * t]);
    let keys = [0, 10, 20, 30];
    let free = fit(&mut cache, &keys, &[], &exact()).unwrap();
    // Vertex 1 pinned at key 1 and vertex 2 at keys 0 and 3: three vertex groups.
    let mask = |on: &[usize]| (0..3).map(|v| on.contains(&v)).collect::<Vec<bool>>();
    let pins = vec![mask(&[2]), mask(&[1]), vec![], mask(&[2])];
    let pinned = fit(&mut cache, &keys, &pins, &exact()).unwrap();
    assert_eq!(pinned.positions[1][1], cache.frames[10][1]);
    assert_eq!(pinned.positions[0][2], cache.frames[0][2]);
    assert_eq!(pinned.positions[3][2], cache.frames[30][2]);
    assert!(norm(crate::algorithms::geometry::sub(free.positions[1][1], cache.frames[10][1])) > 1e-6, "the free fit does not interpolate");
    // Vertex 0 has no pins: same as the free fit.
    for k in 0..4 {
        assert!(norm(crate::algorithms::geometry::sub(pinned.positions[k][0], free.positions[k][0])) < 1e-12);
    }
    // The pinned fit is still a least-squares optimum over its free unknowns.
    for (v, k, velocity) in [(1, 1, true), (1, 0, false), (1, 2, false), (2, 0, true), (2, 1, false)] {
        let phi = basis_column(&cache.times, &pinned.times, k, velocity);
        for d in 0..3 {
            let dot: f64 = (0..31).map(|f| phi[f] * (cache.frames[f][v][d] - pinned.evaluate(cache.times[f])[v][d])).sum();
            assert!(dot.abs() < 1e-12, "vertex {v} key {k} velocity {velocity}: {dot}");
        }
    }
}

#[test]
fn bad_keys_and_masks_are_one_line_errors() {
    let mut cache = sampled(10, 2, |_, t| [t, 0.0, 0.0]);
    let s = FitSettings::default();
    for (keys, want) in
        [(vec![3], "at least 2 keys"), (vec![0, 10], "past the end"), (vec![0, 5, 5], "strictly increasing"), (vec![4, 2], "strictly increasing")]
    {
        let e = fit(&mut cache, &keys, &[], &s).unwrap_err();
        assert!(e.problem.contains(want), "{keys:?}: {e}");
    }
    let e = fit(&mut cache, &[0, 9], &[vec![true]], &s).unwrap_err();
    assert!(e.problem.contains("1 pin masks for 2 keys"), "{e}");
    let e = fit(&mut cache, &[0, 9], &[vec![true], vec![]], &s).unwrap_err();
    assert!(e.problem.contains("1 entries for 2 vertices"), "{e}");
    let e = fit(&mut cache, &[0, 9], &[], &FitSettings { regularization: -1.0 }).unwrap_err();
    assert!(e.problem.contains("regularization"), "{e}");
}

#[test]
fn same_input_same_bits() {
    let mut cache = sampled(40, 5, |v, t| [(t * v as f64).sin(), t.cos(), (2.0 * t).sin() * v as f64]);
    let a = fit(&mut cache, &[0, 13, 27, 39], &[], &FitSettings::default()).unwrap();
    let b = fit(&mut cache, &[0, 13, 27, 39], &[], &FitSettings::default()).unwrap();
    assert_eq!(a, b);
}
