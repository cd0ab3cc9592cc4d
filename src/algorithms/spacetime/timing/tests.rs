//! Verification of the timing derivatives and the timing step.

use super::*;
use crate::algorithms::physics::elastic::Elastic;
use crate::algorithms::physics::svd3::svd3;
use crate::algorithms::spacetime::tests::{all, from_mask, keys, material, settings, wobbly};
use crate::algorithms::spacetime::unknowns::KeyConstraints;
use crate::algorithms::testing::cube_mesh;
use crate::support::testing::Rng;

/// `tr` with interval `i` set to length `len`, later keys shifted with it.
fn with_length(tr: &Trajectory, i: usize, len: f64) -> Trajectory {
    let mut times = tr.times.clone();
    let shift = len - (times[i + 1] - times[i]);
    for t in &mut times[i + 1..] {
        *t += shift;
    }
    Trajectory { times, ..tr.clone() }
}

/// Richardson-extrapolated central differences (error O(h⁴)) of `w` at `x`: first and
/// second derivative.
fn differences(w: &dyn Fn(f64) -> f64, x: f64, h: f64) -> (f64, f64) {
    let w0 = w(x);
    let at = |h: f64| {
        let (p, m) = (w(x + h), w(x - h));
        ((p - m) / (2.0 * h), (p - 2.0 * w0 + m) / (h * h))
    };
    let (d1, d2) = (at(h), at(0.5 * h));
    ((4.0 * d2.0 - d1.0) / 3.0, (4.0 * d2.1 - d1.1) / 3.0)
}

struct Row {
    case: String,
    interval: usize,
    gradient: (f64, f64),
    curvature: (f64, f64),
}

fn relative(a: f64, b: f64) -> f64 {
    (a - b).abs() / a.abs().max(b.abs()).max(f64::MIN_POSITIVE)
}

/// Analytic vs finite-difference derivatives in every interval of the wobbly cube.
fn table(damping: f64, gravity: Point, cyclic: bool, frozen: bool) -> Vec<Row> {
    let mesh = cube_mesh(2);
    let el = Elastic::new(&mesh, &material()).unwrap();
    let tr = wobbly(&mesh.positions, cyclic);
    let timing = Timing { damping, gravity, ..plain_timing(&el, &tr.times, cyclic, 5) };
    let p = timing.objective(&tr.times).local_step(&tr, false);
    let d = timing.derivatives(&tr, if frozen { ProjectionMode::Frozen(&p) } else { ProjectionMode::Fresh });
    let case = format!(
        "damping {damping}, gravity {}, {}, {}",
        gravity != [0.0; 3],
        if cyclic { "cyclic" } else { "open" },
        if frozen { "frozen" } else { "fresh" }
    );
    (0..3)
        .map(|i| {
            let t = tr.times[i + 1] - tr.times[i];
            let w = |len: f64| {
                let moved = with_length(&tr, i, len);
                if frozen {
                    timing.objective(&moved.times).evaluate(&moved, &p).value
                } else {
                    timing.energy(&moved)
                }
            };
            let (fd1, fd2) = differences(&w, t, 1e-3 * t);
            Row { case: case.clone(), interval: i, gradient: (d.gradient[i], fd1), curvature: (d.curvature[i], fd2) }
        })
        .collect()
}

#[test]
fn derivatives_match_finite_differences() {
    let mut worst: f64 = 0.0;
    println!("| case | T_i | dW/dT analytic | FD | rel. error | d2W/dT2 analytic | FD | rel. error |");
    println!("|---|---|---:|---:|---:|---:|---:|---:|");
    for damping in [0.0, 4.0] {
        for gravity in [[0.0; 3], [0.0, -9.81, 3.0]] {
            for cyclic in [false, true] {
                for frozen in [true, false] {
                    for r in table(damping, gravity, cyclic, frozen) {
                        let (e1, e2) = (relative(r.gradient.0, r.gradient.1), relative(r.curvature.0, r.curvature.1));
                        println!(
                            "| {} | {} | {:.10e} | {:.10e} | {:.1e} | {:.10e} | {:.10e} | {:.1e} |",
                            r.case, r.interval, r.gradient.0, r.gradient.1, e1, r.curvature.0, r.curvature.1, e2
                        );
                        worst = worst.max(e1).max(e2);
                    }
                }
            }
        }
    }
    assert!(worst < 1e-6, "largest relative error {worst:e}");
}

#[test]
fn the_objective_gives_the_same_time_gradient() {
    // The solver takes ∂W/∂T from the objective's exact evaluation (the projection Jacobians
    // of its local step); it must be the fresh derivative above, with supports and contacts.
    let mesh = cube_mesh(2);
    let el = Elastic::new(&mesh, &material()).unwrap();
    let supports: Vec<bool> = mesh.positions.iter().map(|p| p[1] == 0.0).collect();
    for (tr, cyclic) in [(wobbly(&mesh.positions, true), true), (contact_trajectory(&mesh.positions), false)] {
        for damping in [0.0, 2.5] {
            let timing = Timing { damping, gravity: [0.3, -9.81, 0.0], supports: supports.clone(), ..plain_timing(&el, &tr.times, cyclic, 4) };
            let d = timing.derivatives(&tr, ProjectionMode::Fresh);
            let mut objective = timing.objective(&tr.times);
            objective.time_gradient = true;
            let e = objective.evaluate(&tr, &objective.local_step(&tr, true));
            assert!(relative(e.value, d.value) < 1e-12);
            let g = e.time_gradient.expect("asked for");
            for (i, (a, b)) in g.iter().zip(&d.gradient).enumerate() {
                assert!(relative(*a, *b) < 1e-9 || (a - b).abs() < 1e-12 * d.value, "interval {i}: {a} vs {b}");
            }
            // The line search's W is the evaluation's to the bit, and the derivatives are the
            // same bytes on one thread (the vectorized kernels and the per-sample sums).
            assert_eq!(timing.energy(&tr), objective.evaluate(&tr, &objective.local_step(&tr, false)).value);
            let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
            assert_eq!(one.install(|| timing.derivatives(&tr, ProjectionMode::Fresh)), d);
            assert_eq!(one.install(|| objective.evaluate(&tr, &objective.local_step(&tr, true))).time_gradient, Some(g.clone()));
            // And the supports' rows are out of both: W changes when they are counted.
            let counted = Timing { supports: vec![false; el.node_count()], ..timing.clone() };
            assert!(relative(counted.energy(&tr), d.value) > 1e-6);
        }
    }
}

/// The fresh derivatives written with the per-tet scalar definitions: every combination of the
/// unknowns by itself, each tet's deformation gradients, signed SVD and projection path one at a
/// time ([`project_along_svd`](crate::algorithms::physics::projection_curvature::project_along_svd)), their
/// node forces summed in tet order ([`Elastic::apply_j_sequential_with`]), samples summed in order.
fn per_tet_derivatives(timing: &Timing, tr: &Trajectory) -> TimeDerivatives {
    use crate::algorithms::physics::projection_curvature::{project_along_svd, ProjectionPath};
    let (el, alpha, g) = (timing.elastic, timing.damping, timing.gravity);
    let n = el.node_count();
    let intervals = tr.times.len() - 1;
    let (mut value, mut gradient, mut curvature) = (0.0, vec![0.0; intervals], vec![0.0; intervals]);
    for s in &timing.objective(&tr.times).samples {
        let (i, b) = (s.interval, &s.basis);
        let t = tr.times[i + 1] - tr.times[i];
        let (d1, d2) = (length_derivative(b, t, 1), length_derivative(b, t, 2));
        let c: [f64; 4] = std::array::from_fn(|j| b.acc[j] + alpha * b.vel[j]);
        let c_t: [f64; 4] = std::array::from_fn(|j| d1.acc[j] + alpha * d1.vel[j]);
        let c_tt: [f64; 4] = std::array::from_fn(|j| d2.acc[j] + alpha * d2.vel[j]);
        let u = [&tr.positions[i], &tr.velocities[i], &tr.positions[i + 1], &tr.velocities[i + 1]];
        let combine = |w: &[f64; 4]| -> Vec<Point> {
            (0..n).map(|a| [0, 1, 2].map(|d| w[0] * u[0][a][d] + w[1] * u[1][a][d] + w[2] * u[2][a][d] + w[3] * u[3][a][d])).collect()
        };
        let (x, x_t, acc, acc_t, acc_tt) = (combine(&b.pos), combine(&d1.pos), combine(&c), combine(&c_t), combine(&c_tt));
        let paths: Vec<ProjectionPath> = (0..el.tet_count())
            .map(|e| project_along_svd(&svd3(&el.deformation_gradient(e, &x)), el.strain_share(), &el.deformation_gradient(e, &x_t)))
            .collect();
        let (mut jp, mut jp_t, mut jp_tt) = (vec![[0.0; 3]; n], vec![[0.0; 3]; n], vec![[0.0; 3]; n]);
        el.apply_j_sequential_with(|e| paths[e].value, &mut jp);
        el.apply_j_sequential_with(|e| paths[e].first, &mut jp_t);
        el.apply_j_sequential_with(|e| paths[e].second, &mut jp_tt);
        let (mut lx, mut lx_t) = (vec![[0.0; 3]; n], vec![[0.0; 3]; n]);
        el.stiffness.mul_points_sequential(&x, &mut lx);
        el.stiffness.mul_points_sequential(&x_t, &mut lx_t);
        let (mut ff, mut ftf, mut ftft, mut fttf) = (0.0, 0.0, 0.0, 0.0);
        for a in (0..n).filter(|&a| !timing.supports[a]) {
            let m = el.mass[a];
            for d in 0..3 {
                let f = m * (acc[a][d] - g[d]) + lx[a][d] - jp[a][d];
                let f_t = m * acc_t[a][d] + lx_t[a][d] - jp_t[a][d];
                let f_tt = m * acc_tt[a][d] - jp_tt[a][d];
                ff += f * f / m;
                ftf += f_t * f / m;
                ftft += f_t * f_t / m;
                fttf += f_tt * f / m;
            }
        }
        let (w, dw) = (s.weight, s.weight / t);
        value += 0.5 * w * ff;
        gradient[i] += 0.5 * dw * ff + w * ftf;
        curvature[i] += 2.0 * dw * ftf + w * (ftft + fttf);
    }
    TimeDerivatives { value, gradient, curvature }
}

#[test]
fn fresh_derivatives_are_the_bytes_of_the_per_tet_definition() {
    // The derivatives run 16 tets per vectorized call, F and F_T written straight into lanes,
    // the body's arrays read in place, the five combinations in one pass: none of that may
    // change a bit. A 3x3x3 cube has 162 tets, so the last batch is partial (padded lanes).
    let mesh = cube_mesh(3);
    let el = Elastic::new(&mesh, &material()).unwrap();
    assert_ne!(el.tet_count() % BATCH, 0);
    let supports: Vec<bool> = mesh.positions.iter().map(|p| p[1] == 0.0).collect();
    for (tr, cyclic) in [(wobbly(&mesh.positions, false), false), (wobbly(&mesh.positions, true), true), (contact_trajectory(&mesh.positions), false)]
    {
        for (damping, gravity, supports) in [(0.0, [0.0; 3], vec![false; el.node_count()]), (2.5, [0.3, -9.81, 0.0], supports.clone())] {
            let timing = Timing { damping, gravity, supports, ..plain_timing(&el, &tr.times, cyclic, 4) };
            let reference = per_tet_derivatives(&timing, &tr);
            assert_eq!(timing.derivatives(&tr, ProjectionMode::Fresh), reference);
            let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
            assert_eq!(one.install(|| timing.derivatives(&tr, ProjectionMode::Fresh)), reference);
        }
    }
}

#[test]
fn frozen_projections_do_not_give_the_derivative_of_w() {
    // The envelope argument does not apply: the projections minimize the elastic energy, not
    // W. The frozen-projection derivative misses -J DP[dF(x_T)] in f_T.
    for cyclic in [false, true] {
        let frozen = table(0.0, [0.0, -9.81, 0.0], cyclic, true);
        let fresh = table(0.0, [0.0, -9.81, 0.0], cyclic, false);
        for (a, b) in frozen.iter().zip(&fresh) {
            let gap = relative(a.gradient.0, b.gradient.1);
            println!("interval {}: frozen dW/dT {:.6e}, FD of W {:.6e}: relative gap {gap:.2}", a.interval, a.gradient.0, b.gradient.1);
            assert!(gap > 0.1, "the frozen derivative happens to match W's on this body: {gap:e}");
        }
    }
}

/// The timing problem of `times` with `samples` per interval, no damping, no gravity, no
/// supports.
fn plain_timing<'a>(el: &'a Elastic, times: &[f64], cyclic: bool, samples: usize) -> Timing<'a> {
    Timing {
        elastic: el,
        slots: TimeSlots::new(times, cyclic),
        per_interval: vec![samples; times.len() - 1],
        damping: 0.0,
        gravity: [0.0; 3],
        supports: vec![false; el.node_count()],
    }
}

fn wobbly_timing(el: &Elastic, cyclic: bool) -> Timing<'_> {
    Timing { damping: 0.5, gravity: [0.0, -9.81, 0.0], ..plain_timing(el, &[0.0, 0.3, 0.8, 1.1], cyclic, 5) }
}

fn lengths(times: &[f64]) -> Vec<f64> {
    times.windows(2).map(|w| w[1] - w[0]).collect()
}

#[test]
fn timing_step_never_increases_w_and_respects_the_constraints() {
    let mesh = cube_mesh(2);
    let el = Elastic::new(&mesh, &material()).unwrap();
    for cyclic in [false, true] {
        let tr = wobbly(&mesh.positions, cyclic);
        let timing = wobbly_timing(&el, cyclic);
        for (keep_duration, fixed_times) in [(false, vec![]), (true, vec![]), (false, vec![1]), (true, vec![2]), (true, vec![1, 2])] {
            let settings = TimingSettings { keep_duration, fixed_times: fixed_times.clone(), ..TimingSettings::default() };
            let step = timing.optimize_times(&tr, &settings).unwrap();
            let w = &step.energy;
            println!(
                "cyclic {cyclic}, keep {keep_duration}, fixed {fixed_times:?}: T {:?} -> {:?}, W {:?} ({})",
                lengths(&tr.times),
                lengths(&step.times),
                w,
                step.stop_reason
            );
            assert!(w.windows(2).all(|p| p[1] < p[0]), "{w:?}");
            let moved = Trajectory { times: step.times.clone(), ..tr.clone() };
            assert_eq!(timing.energy(&moved), *w.last().unwrap(), "the reported W is W at the new times");
            assert_eq!(step.times[0], tr.times[0]);
            if keep_duration {
                assert_eq!(step.times[3], tr.times[3], "duration kept to the bit");
            }
            for &k in &fixed_times {
                assert_eq!(step.times[k], tr.times[k], "key {k} is fixed");
            }
            if keep_duration && fixed_times == [1, 2] {
                assert_eq!(step.times, tr.times, "every key fixed: nothing moves");
                assert_eq!(step.iterations, 0);
            } else {
                assert!(w.last().unwrap() < &(0.999 * w[0]), "the timing step lowered W: {w:?}");
            }
        }
    }
}

#[test]
fn intervals_clamp_at_the_minimum() {
    let mesh = cube_mesh(2);
    let el = Elastic::new(&mesh, &material()).unwrap();
    let tr = wobbly(&mesh.positions, false);
    let timing = wobbly_timing(&el, false);
    // Unconstrained, every interval shrinks (to 0.149, 0.115, 0.090 from 0.3, 0.5, 0.3):
    // a minimum of 0.2 stops all of them there, also with the duration kept (the time then
    // goes to the interval that gains the most).
    let free = timing.optimize_times(&tr, &TimingSettings::default()).unwrap();
    let before = lengths(&tr.times);
    assert!(lengths(&free.times).iter().zip(&before).all(|(a, b)| a < &0.2 && a < b), "{:?}", free.times);
    let clamped = timing.optimize_times(&tr, &TimingSettings { min_interval: 0.2, ..TimingSettings::default() }).unwrap();
    for t in lengths(&clamped.times) {
        assert!((t - 0.2).abs() < 1e-12, "{:?}", clamped.times);
    }
    let kept = timing.optimize_times(&tr, &TimingSettings { min_interval: 0.25, keep_duration: true, ..TimingSettings::default() }).unwrap();
    let t = lengths(&kept.times);
    println!("clamped {:?}; kept duration with minimum 0.25: {t:?}", lengths(&clamped.times));
    assert!(t.iter().all(|&x| x >= 0.25 - 1e-12), "{t:?}");
    assert!(t.iter().any(|&x| (x - 0.25).abs() < 1e-12), "a bound is active: {t:?}");
    assert_eq!(kept.times[3], tr.times[3]);
    assert!(kept.energy.windows(2).all(|p| p[1] < p[0]));
}

/// Keys 0, 1, 2 = 3 (a contact: same time and pose, separate velocities), 4.
fn contact_trajectory(rest: &[Point]) -> Trajectory {
    let tr = wobbly(rest, false);
    let mut positions = tr.positions.clone();
    positions.insert(3, positions[2].clone());
    let mut velocities = tr.velocities.clone();
    velocities.insert(3, velocities[2].iter().map(|v| [-v[0], -v[1], 0.5 * v[2]]).collect());
    Trajectory { times: vec![0.0, 0.3, 0.8, 0.8, 1.1], positions, velocities }
}

#[test]
fn zero_length_intervals_have_no_samples_and_stay_zero() {
    let mesh = cube_mesh(2);
    let el = Elastic::new(&mesh, &material()).unwrap();
    let tr = contact_trajectory(&mesh.positions);
    let timing = Timing { damping: 0.5, gravity: [0.0, -9.81, 0.0], ..plain_timing(&el, &tr.times, false, 5) };
    let objective = timing.objective(&tr.times);
    assert_eq!(objective.samples.len(), 3 * timing.per_interval[0]);
    assert!(objective.samples.iter().all(|s| s.interval != 2 && s.weight > 0.0 && s.basis.acc.iter().all(|a| a.is_finite())));
    let d = timing.derivatives(&tr, ProjectionMode::Fresh);
    assert_eq!((d.gradient[2], d.curvature[2]), (0.0, 0.0));
    // The other intervals' derivatives still match W (interval 3 starts at the contact).
    for i in [1, 3] {
        let t = tr.times[i + 1] - tr.times[i];
        let (fd1, fd2) = differences(&|len| timing.energy(&with_length(&tr, i, len)), t, 1e-3 * t);
        assert!(relative(d.gradient[i], fd1) < 1e-6 && relative(d.curvature[i], fd2) < 1e-6, "interval {i}");
    }
    for settings in [TimingSettings::default(), TimingSettings { keep_duration: true, fixed_times: vec![1], ..TimingSettings::default() }] {
        let step = timing.optimize_times(&tr, &settings).unwrap();
        println!("{:?} -> {:?}", tr.times, step.times);
        assert_eq!(step.times[2], step.times[3], "the contact interval stays zero");
        assert_ne!(step.times[2], tr.times[2], "the contact time moved");
        assert!(step.energy.windows(2).all(|p| p[1] < p[0]));
    }
}

#[test]
fn constrained_newton_step_satisfies_its_optimality_conditions() {
    // Σ g Δ + ½ h Δ² with Δ >= lo and Σ Δ = 0: the unclamped share one multiplier μ = g + hΔ,
    // the clamped have g + h lo >= μ.
    let times = [0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0];
    let blocks = Blocks::new(&times, &TimingSettings { keep_duration: true, fixed_times: vec![4], ..TimingSettings::default() }).unwrap();
    assert_eq!(blocks.blocks, vec![(vec![0, 1, 2, 3], true), (vec![4, 5], true)]);
    let mut rng = Rng::new(3);
    for _ in 0..200 {
        let g: Vec<f64> = (0..6).map(|_| 3.0 * rng.next()).collect();
        let h: Vec<f64> = (0..6).map(|_| 1.5 + rng.next()).collect();
        let lo: Vec<f64> = (0..6).map(|_| -0.5 * (1.0 + rng.next())).collect();
        let step = blocks.newton_step(&g, &h, &lo);
        for (block, _) in &blocks.blocks {
            assert!(block.iter().map(|&i| step[i]).sum::<f64>().abs() < 1e-12);
            let free: Vec<usize> = block.iter().copied().filter(|&i| step[i] > lo[i]).collect();
            let mu = g[free[0]] + h[free[0]] * step[free[0]];
            for &i in block {
                assert!(step[i] >= lo[i]);
                if free.contains(&i) {
                    assert!((g[i] + h[i] * step[i] - mu).abs() < 1e-12);
                } else {
                    assert!(g[i] + h[i] * lo[i] >= mu - 1e-12);
                }
            }
        }
    }
    // A non-positive or undefined curvature becomes a gradient step of a quarter interval.
    let (g, t) = ([2.0, -3.0, 0.5, 1.0], [0.4, 0.2, 1.0, 1.0]);
    let h = safe_curvature(&g, &[-1.0, 0.0, f64::NAN, 7.0], &t);
    let free = Blocks::new(&[0.0, 0.4, 0.6, 1.6, 2.6], &TimingSettings::default()).unwrap();
    let step = free.newton_step(&g, &h, &[-1.0; 4]);
    for i in 0..3 {
        assert!((step[i] + GRADIENT_STEP * t[i] * g[i].signum()).abs() < 1e-15, "{step:?}");
    }
    assert_eq!((h[3], step[3]), (7.0, -1.0 / 7.0));
    // Free intervals after the last fixed key; a contact (zero length) in no block.
    let blocks = Blocks::new(&[0.0, 1.0, 1.0, 2.0, 3.0], &TimingSettings { fixed_times: vec![3], ..TimingSettings::default() }).unwrap();
    assert_eq!(blocks.blocks, vec![(vec![0, 2], true), (vec![3], false)]);
    let e = Blocks::new(&times, &TimingSettings { fixed_times: vec![7], ..TimingSettings::default() }).unwrap_err().to_string();
    assert!(e.contains("key 7") && e.contains("7 keys"), "{e}");
}

#[test]
fn retimed_global_step_equals_a_fresh_one() {
    use crate::algorithms::spacetime::global_step::GlobalStep;
    use crate::algorithms::spacetime::unknowns::Unknowns;
    let mesh = cube_mesh(2);
    let el = Elastic::new(&mesh, &material()).unwrap();
    let n = el.node_count();
    let tr = wobbly(&mesh.positions, true);
    let mut fixed = vec![Vec::new(); 4];
    fixed[1] = from_mask(&(0..n).map(|a| a % 3 == 0).collect::<Vec<_>>());
    let keys = keys(tr.times.clone(), tr.positions.clone(), fixed, true);
    let timing = Timing { damping: 0.7, ..wobbly_timing(&el, true) };
    let unknowns = Unknowns::new(&keys, n);
    let mut global = GlobalStep::new(&timing.objective(&tr.times), unknowns.clone(), 0.1).unwrap();
    let times = vec![0.0, 0.21, 0.83, 1.4];
    let retimed = global.retime(&timing.objective(&times), 0.1).unwrap();
    assert!(retimed.reused_symbolic);
    let fresh = GlobalStep::new(&timing.objective(&times), unknowns, 0.1).unwrap();
    let moved = Trajectory { times: times.clone(), ..tr.clone() };
    let objective = timing.objective(&times);
    let gradient = objective.evaluate(&moved, &objective.local_step(&moved, false)).gradient;
    let (a, b) = (global.step(&gradient), fresh.step(&gradient));
    let scale = b.iter().flatten().map(|v| crate::algorithms::geometry::norm(*v)).fold(0.0, f64::max);
    let diff = a
        .iter()
        .flatten()
        .zip(b.iter().flatten())
        .map(|(x, y)| crate::algorithms::geometry::norm(crate::algorithms::geometry::sub(*x, *y)))
        .fold(0.0, f64::max);
    assert!(diff < 1e-12 * scale, "retimed and fresh steps differ by {diff:e} of {scale:e}");
    // And it is not the old matrix: the step at the old times differs.
    let old = GlobalStep::new(&timing.objective(&tr.times), Unknowns::new(&keys, n), 0.1).unwrap().step(&gradient);
    let change = a
        .iter()
        .flatten()
        .zip(old.iter().flatten())
        .map(|(x, y)| crate::algorithms::geometry::norm(crate::algorithms::geometry::sub(*x, *y)))
        .fold(0.0, f64::max);
    assert!(change > 1e-3 * scale);
}

/// Alternate a converged position/velocity solve at the current times with one timing step,
/// as the solver will; the times after every round and W before and after every timing step.
fn alternate(
    el: &Elastic,
    keys: &KeyConstraints,
    settings: &crate::algorithms::spacetime::settings::Settings,
    timing: &TimingSettings,
    rounds: usize,
) -> (Vec<Vec<f64>>, Vec<(f64, f64)>) {
    let mut keys = keys.clone();
    let (mut times, mut energy) = (vec![keys.times.clone()], Vec::new());
    for _ in 0..rounds {
        let solved = crate::algorithms::spacetime::solver::solve(el, &keys, settings, &|_, _, _| {}).unwrap();
        let t = Timing::new(el, &keys, settings);
        let step = t.optimize_times(&solved.trajectory, timing).unwrap();
        energy.push((step.energy[0], *step.energy.last().unwrap()));
        keys.times = step.times;
        times.push(keys.times.clone());
    }
    (times, energy)
}

/// A rigid cube at the given centre offsets, every position held.
fn rigid_keys(offsets: &[Point], times: Vec<f64>) -> (Elastic, KeyConstraints) {
    let mesh = cube_mesh(1);
    let el = Elastic::new(&mesh, &material()).unwrap();
    let n = mesh.positions.len();
    let poses = offsets.iter().map(|o| mesh.positions.iter().map(|p| crate::algorithms::geometry::add(*p, *o)).collect()).collect();
    (el, keys(times, poses, vec![all(n); offsets.len()], false))
}

#[test]
fn free_fall_key_times_move_back_to_the_parabola() {
    // x(t) = u t + g t²/2 at the true times 0, 0.5, 1; key 1 given at 0.62 instead.
    let (u, g) = ([1.0, 5.0, 0.0], [0.0, -9.81, 0.0]);
    let at = |t: f64| -> Point { [0, 1, 2].map(|d| u[d] * t + 0.5 * g[d] * t * t) };
    let (el, keys) = rigid_keys(&[at(0.0), at(0.5), at(1.0)], vec![0.0, 0.62, 1.0]);
    let settings = crate::algorithms::spacetime::settings::Settings { gravity: g, samples: 6, tolerance: 1e-12, max_iterations: 500, ..settings() };
    let (times, energy) = alternate(&el, &keys, &settings, &TimingSettings { keep_duration: true, ..TimingSettings::default() }, 4);
    for (t, w) in times.iter().zip(&energy) {
        println!("t1 = {:.6}: W {:.4e} -> {:.4e}", t[1], w.0, w.1);
    }
    // Every round moves key 1 towards 0.5 (by 3% of the error: the velocities, re-solved every
    // round, absorb most of the timing error, see the reduced-W test below).
    let errors: Vec<f64> = times.iter().map(|t| (t[1] - 0.5).abs()).collect();
    assert!(errors.windows(2).all(|e| e[1] < 0.99 * e[0]), "{errors:?}");
    assert!(errors.last().unwrap() < &(0.95 * errors[0]), "{errors:?}");
    assert!(times.iter().all(|t| t[2] == 1.0));
}

#[test]
fn a_high_jump_gets_longer_intervals_around_its_apex() {
    // Ground, ground, apex 3 m up, ground, ground at equal intervals of 0.5 s: falling 3 m takes
    // sqrt(2·3/9.81) = 0.78 s, so with the duration kept the flight intervals take time from the
    // ground intervals (the paper's Fig. 10).
    let g = [0.0, -9.81, 0.0];
    let (el, keys) = rigid_keys(&[[0.0; 3], [0.0; 3], [0.0, 3.0, 0.0], [0.0; 3], [0.0; 3]], vec![0.0, 0.5, 1.0, 1.5, 2.0]);
    let settings = crate::algorithms::spacetime::settings::Settings { gravity: g, samples: 6, tolerance: 1e-12, max_iterations: 500, ..settings() };
    let (times, energy) =
        alternate(&el, &keys, &settings, &TimingSettings { keep_duration: true, min_interval: 0.05, ..TimingSettings::default() }, 4);
    for (t, w) in times.iter().zip(&energy) {
        println!("T = {:?}: W {:.4e} -> {:.4e}", lengths(t), w.0, w.1);
    }
    let t = lengths(times.last().unwrap());
    assert!(t[1] > 0.6 && t[2] > 0.6 && t[0] < 0.4 && t[3] < 0.4, "{t:?}");
    assert_eq!(times.last().unwrap()[4], 2.0);
    assert!(energy.last().unwrap().1 < 0.5 * energy[0].0);
}

#[test]
fn at_converged_keys_the_timing_gradient_is_the_gradient_of_the_reduced_w() {
    // W*(T) = min over positions and velocities of W: here the envelope argument holds (the
    // keys minimize W itself), so dW*/dT = ∂W/∂T at the solved keys. Its curvature is far
    // below the held-keys curvature (measured 199 vs 3219): the keys absorb most of a change of
    // timing, which is why alternating solves and timing steps converge only linearly here.
    let (u, g) = ([1.0, 5.0, 0.0], [0.0, -9.81, 0.0]);
    let at = |t: f64| -> Point { [0, 1, 2].map(|d| u[d] * t + 0.5 * g[d] * t * t) };
    let (el, keys) = rigid_keys(&[at(0.0), at(0.5), at(1.0)], vec![0.0, 0.62, 1.0]);
    let settings = crate::algorithms::spacetime::settings::Settings { gravity: g, samples: 6, tolerance: 1e-14, max_iterations: 2000, ..settings() };
    let solve_at = |t1: f64| {
        let mut k = keys.clone();
        k.times[1] = t1;
        crate::algorithms::spacetime::solver::solve(&el, &k, &settings, &|_, _, _| {}).unwrap()
    };
    let timing = Timing { gravity: g, ..plain_timing(&el, &keys.times, false, 6) };
    let d = timing.derivatives(&solve_at(0.62).trajectory, ProjectionMode::Fresh);
    // Moving key 1 lengthens interval 0 and shortens interval 1.
    let (held_gradient, held_curvature) = (d.gradient[0] - d.gradient[1], d.curvature[0] + d.curvature[1]);
    let w = |t1: f64| *solve_at(t1).log.energy.last().unwrap();
    let (fd1, fd2) = differences(&w, 0.62, 1e-3);
    println!("dW/dt1: held {held_gradient:.6e}, reduced (FD) {fd1:.6e}; d2W/dt1^2: held {held_curvature:.4e}, reduced (FD) {fd2:.4e}");
    assert!(relative(held_gradient, fd1) < 1e-4, "{held_gradient} vs {fd1}");
    assert!(fd2 > 0.0 && fd2 < 0.1 * held_curvature);
}

/// `solve` with the key times optimized under `timing`.
fn solve_timed(
    el: &Elastic,
    keys: &KeyConstraints,
    settings: &crate::algorithms::spacetime::settings::Settings,
    timing: TimingSettings,
) -> crate::algorithms::spacetime::solver::Solved {
    let settings = crate::algorithms::spacetime::settings::Settings { timing: Some(timing), ..settings.clone() };
    crate::algorithms::spacetime::solver::solve(el, keys, &settings, &|_, _, _| {}).unwrap()
}

#[test]
fn the_solver_moves_a_free_fall_key_to_the_parabola() {
    // The free fall above, solved with the key times optimized: every quasi-Newton iteration
    // moves the times and the keys together, and the curvature pairs learn how much the keys
    // absorb (the alternation above needs hundreds of rounds at 3% per round).
    let (u, g) = ([1.0, 5.0, 0.0], [0.0, -9.81, 0.0]);
    let at = |t: f64| -> Point { [0, 1, 2].map(|d| u[d] * t + 0.5 * g[d] * t * t) };
    let (el, keys) = rigid_keys(&[at(0.0), at(0.5), at(1.0)], vec![0.0, 0.62, 1.0]);
    let settings = crate::algorithms::spacetime::settings::Settings { gravity: g, samples: 6, tolerance: 1e-12, max_iterations: 500, ..settings() };
    let solved = solve_timed(&el, &keys, &settings, TimingSettings { keep_duration: true, ..TimingSettings::default() });
    let (t, log) = (&solved.trajectory.times, &solved.log);
    println!(
        "t1 = {:.8}, {} timing iterations of {}, {} refactorizations, W {:.3e} -> {:.3e}: {}",
        t[1],
        log.timing_iterations,
        log.iterations,
        log.refactorizations,
        log.energy[0],
        log.energy.last().unwrap(),
        log.stop_reason
    );
    assert!((t[1] - 0.5).abs() < 1e-4, "t1 = {}", t[1]);
    assert_eq!(t[2], 1.0, "the duration is kept to the bit");
    assert!(log.energy.windows(2).all(|p| p[1] <= p[0]), "W never increases");
    // Iterations until |t1 - 0.5| < 1e-4 (the error is 0.12 at the start).
    let within = log.times.iter().position(|t| (t[1] - 0.5).abs() < 1e-4).unwrap();
    println!(
        "t1 within 1e-4 of 0.5 after {within} iterations ({} of them quasi-Newton); t1 history {:?}",
        within - (log.iterations - log.timing_iterations),
        log.times.iter().map(|t| t[1]).collect::<Vec<_>>()
    );
    assert!(within - (log.iterations - log.timing_iterations) <= 25, "{within} iterations");
    assert!(*log.energy.last().unwrap() < 1e-10 * log.energy[0]);
}
