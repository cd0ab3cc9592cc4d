//! The stopping rule, measured: each scene solved to a tolerance of 1e-8 (the reference W it
//! levels off at), then with the default rule, the purely relative rule it replaced
//! (`negligible = 0`), the tolerances around the default and (with `MODELS=1`) the other model
//! Hessians, beside the reference: how far above it W stops, `W / S` (S the force scale), the
//! predicted remaining decrease the log reports, iterations and CPU seconds. The default must
//! stop STRETCH, TWIST, DINO and CHEB-size within 2% of the reference (issue 10). BALL and
//! SPOT, where W can reach 0, have no reference row: their rows give the contact time instead.
//!
//! `cargo bench --bench convergence`; `-- TWIST SPOT` runs some scenes. Environment: `TOLS`
//! the tolerance rows (default `1e-2,1e-4`; empty: none), `MODELS=1` the model-Hessian rows,
//! `QUICK=1` leaves out the relative-rule row, `STEPS=1` adds the rows of each quasi-Newton-phase step, `REF=W` (or per scene `REF=TWIST=W,DINO=W`) a
//! known reference W (skips the 1e-8 solve), `TRACE=1` prints W / S and the key times
//! per iteration, `NEG=1e-4` runs only the default rule with that `negligible`, `PERTURB=1e-7,-1e-7`
//! runs only the default rule from the first guess and from first guesses moved by these fractions
//! of the body's size (how stable the stop is under a tiny change of path).

use std::time::Instant;

use blendsim::algorithms::spacetime::settings::{ModelHessian, Settings, Step, DEFAULT_COARSE_TOLERANCE, DEFAULT_TOLERANCE, NEGLIGIBLE};
use blendsim::algorithms::spacetime::solver::solve;
use blendsim::pipeline::stage_file::Body;
use blendsim::pipeline::stages::solve::solver_inputs;

mod common;
use common::{cheb_size, load, scene_body, twenty_keys, twenty_keys_held};

/// CPU seconds of this process so far (user + system, every thread), from `/proc/self/stat`.
fn cpu_seconds() -> f64 {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    // Fields after the command name (which may hold spaces): utime and stime are the 12th and
    // 13th of them, in clock ticks of 1/100 s.
    let rest = stat.rsplit_once(')').map_or("", |r| r.1);
    let f: Vec<f64> = rest.split_whitespace().map(|x| x.parse().unwrap_or(0.0)).collect();
    (f.get(11).unwrap_or(&0.0) + f.get(12).unwrap_or(&0.0)) / 100.0
}

struct Run {
    w: f64,
    scale: f64,
    iterations: usize,
    seconds: f64,
    cpu: f64,
    predicted: Option<f64>,
    converged: bool,
    times: Vec<f64>,
    model: String,
    coarse: usize,
}

fn run(body: &Body, change: impl Fn(&mut Settings)) -> Run {
    run_perturbed(body, change, 0.0)
}

/// [`run`] with the first guess moved by `perturbation` of the body's bounding-box diagonal: every
/// key position the keys do not hold (the first guess's alone, not the problem's) shifted by a
/// fixed pattern of that size (`PERTURB`: how far a tiny change of path moves the stop).
fn run_perturbed(body: &Body, change: impl Fn(&mut Settings), perturbation: f64) -> Run {
    let (elastic, mut keys, mut settings) = solver_inputs(body).unwrap();
    if perturbation != 0.0 {
        let size = perturbation * blendsim::algorithms::geometry::bbox_diagonal(&elastic.rest);
        for (positions, fixed) in keys.positions.iter_mut().zip(&keys.fixed) {
            let mut held = vec![false; positions.len()];
            fixed.iter().for_each(|&a| held[a as usize] = true);
            for (i, p) in positions.iter_mut().enumerate().filter(|(i, _)| !held[*i]) {
                let x = i as f64;
                p[0] += size * x.sin();
                p[1] += size * (1.3 * x).cos();
                p[2] += size * (0.7 * x + 1.0).sin();
            }
        }
    }
    settings.max_iterations = 20000;
    change(&mut settings);
    let (t, cpu) = (Instant::now(), cpu_seconds());
    let solved = solve(&elastic, &keys, &settings, &|_, _, _| {}).unwrap();
    let (seconds, cpu) = (t.elapsed().as_secs_f64(), cpu_seconds() - cpu);
    let l = solved.log;
    if std::env::var("TRACE").is_ok() {
        eprintln!("TRACE tolerance {} negligible {}: {}", settings.tolerance, settings.negligible, l.stop_reason);
        for (k, w) in l.energy.iter().enumerate() {
            let times = l.times.get(k).map_or(String::new(), |t| format!("{t:.6?}"));
            eprintln!("TRACE {k} W {w:.6e} W/S {:.3e} {times}", w / l.force_scale);
        }
    }
    let model = if l.stop_reason.contains("tangent") { "tangent" } else { "projective" }.to_string();
    Run {
        w: *l.energy.last().unwrap(),
        scale: l.force_scale,
        iterations: l.iterations,
        seconds,
        cpu,
        predicted: l.predicted_remaining,
        converged: l.converged,
        times: solved.trajectory.times,
        model,
        coarse: l.coarse_iterations,
    }
}

fn main() {
    type Case = (&'static str, Box<dyn Fn() -> Body>);
    let cases: Vec<Case> = vec![
        ("STRETCH", Box::new(|| scene_body("fixtures/paper/stretch.toml"))),
        ("TWIST", Box::new(|| scene_body("fixtures/paper/twist.toml"))),
        ("DINO", Box::new(|| scene_body("fixtures/paper/dino.toml"))),
        ("CHEB-size", Box::new(cheb_size)),
        ("DEMO", Box::new(|| scene_body("fixtures/demo/twist.toml"))),
        ("BALL", Box::new(|| scene_body("fixtures/paper/ball.toml"))),
        ("SPOT", Box::new(|| scene_body("fixtures/paper/spot.toml"))),
        // The scale benchmark's 20-key body on 400 nodes, its surface held at every key (held
        // by the bottom face only, as there, W falls to 0 with the body at rest: README).
        ("KEY20-small", Box::new(|| twenty_keys([6, 18, 6], 0.024, true))),
        // The scale benchmark's "2.6k-nodes-20-keys" (bottom and top held): long, run by name.
        ("KEY20-2.6k", Box::new(|| twenty_keys_held([12, 36, 12], 0.003, Some(&[0.0, 1.0])))),
    ];
    let only: Vec<String> = std::env::args().skip(1).filter(|a| !a.starts_with('-')).collect();
    let tolerances: Vec<f64> =
        std::env::var("TOLS").map(|v| v.split(',').filter(|x| !x.is_empty()).map(|x| x.parse().unwrap()).collect()).unwrap_or(vec![1e-2, 1e-4]);
    let models = std::env::var("MODELS").is_ok();
    println!(
        "machine: {} threads, load average {}; default tolerance {DEFAULT_TOLERANCE}, negligible {NEGLIGIBLE}",
        rayon::current_num_threads(),
        load()
    );
    println!();
    println!(
        "| scene | rule | model | iterations | CPU s | wall s | W | above the 1e-8 W | W / S | predicted remaining | converged | key times | load |"
    );
    println!("|---|---|---|---:|---:|---:|---:|---:|---:|---:|---|---|---|");
    for (name, make) in cases.iter().filter(|c| if only.is_empty() { c.0 != "KEY20-2.6k" } else { only.iter().any(|o| o == c.0) }) {
        let body = make();
        if let Ok(v) = std::env::var("NEG") {
            // One row: the default rule with this floor (a measurement aid, with TRACE).
            let negligible: f64 = v.parse().unwrap();
            row(name, &format!("negligible {negligible:e}"), &run(&body, |s| s.negligible = negligible), None);
            continue;
        }
        // `PERTURB=1e-7,-1e-7`: the default rule from first guesses moved by these fractions of
        // the bounding-box diagonal (`run_perturbed`), beside the default from the first guess.
        if let Ok(v) = std::env::var("PERTURB") {
            row(name, "default", &run(&body, |_| {}), None);
            for p in v.split(',').filter(|x| !x.is_empty()) {
                let r = run_perturbed(&body, |_| {}, p.parse().unwrap());
                row(name, &format!("default, first guess moved by {p}"), &r, None);
            }
            continue;
        }
        let bounce = matches!(*name, "BALL" | "SPOT");
        // `REF=W`, or per scene `REF=TWIST=W,DINO=W`.
        let given = std::env::var("REF").ok().and_then(|v| {
            v.split(',').find_map(|p| match p.split_once('=') {
                Some((n, w)) if n == *name => w.parse::<f64>().ok(),
                Some(_) => None,
                None => p.parse::<f64>().ok(),
            })
        });
        let w_ref = match given.ok_or(()) {
            Ok(v) => Some(v),
            Err(_) if bounce => None,
            Err(_) => {
                let r = run(&body, |s| (s.tolerance, s.coarse_samples) = (1e-8, 0));
                row(name, "1e-8", &r, None);
                Some(r.w)
            }
        };
        // With `STEPS`, the quasi-newton row is the default's.
        if std::env::var("STEPS").is_err() {
            row(name, "default", &run(&body, |_| {}), w_ref);
        }
        // Before: the relative rule alone; it never stops BALL and SPOT, whose scene files capped
        // them at 300 iterations.
        let cap = if bounce { 300 } else { 20000 };
        if std::env::var("QUICK").is_err() {
            row(name, "relative only (before)", &run(&body, |s| (s.negligible, s.max_iterations) = (0.0, cap)), w_ref);
        }
        for &tol in &tolerances {
            row(name, &format!("{tol:e}"), &run(&body, |s| s.tolerance = tol), w_ref);
        }
        // `COARSE=2,3,5`: the default rule after a coarse phase at these samples (`COARSE_TOL`
        // its tolerance, default the solver's), and with `COARSE=-`, without one (when it is
        // the default).
        if let Ok(v) = std::env::var("COARSE") {
            let tol: f64 = std::env::var("COARSE_TOL").ok().and_then(|t| t.parse().ok()).unwrap_or(DEFAULT_COARSE_TOLERANCE);
            for c in v.split(',').filter(|x| !x.is_empty()) {
                let samples = if c == "-" { 0 } else { c.parse().unwrap() };
                let r = run(&body, |s| (s.coarse_samples, s.coarse_tolerance) = (samples, tol));
                row(name, &format!("coarse {samples} (tol {tol:e}; {} coarse it.)", r.coarse), &r, w_ref);
            }
        }
        // `STEPS=1`: the default rule with each step of the quasi-Newton phase forced.
        if std::env::var("STEPS").is_ok() {
            // `STEPS=gauss-newton` (or `quasi-newton`): that row only.
            let only_step = std::env::var("STEPS").unwrap_or_default();
            for (label, step) in [("quasi-newton", Step::QuasiNewton), ("gauss-newton", Step::GaussNewton)]
                .into_iter()
                .filter(|(l, _)| !only_step.contains('-') || only_step == *l)
            {
                row(name, &format!("default, step {label}"), &run(&body, |s| s.step = step), w_ref);
            }
        }
        if models {
            for (label, model) in [("auto", ModelHessian::Auto), ("tangent", ModelHessian::Tangent)] {
                row(name, &format!("default, model {label}"), &run(&body, |s| s.model_hessian = model), w_ref);
            }
        }
    }
}

fn row(name: &str, rule: &str, r: &Run, w_ref: Option<f64>) {
    let above =
        w_ref.map_or("-".to_string(), |w| if rule == "1e-8" { "(reference)".to_string() } else { format!("{:.2}%", 100.0 * (r.w / w - 1.0)) });
    let predicted = r.predicted.map_or("-".to_string(), |p| format!("{:.2}%", 100.0 * p));
    let times = if r.times.len() <= 4 { r.times.iter().map(|t| format!("{t:.5}")).collect::<Vec<_>>().join(", ") } else { "given".to_string() };
    println!(
        "| {name} | {rule} | {} | {} | {:.2} | {:.2} | {:.4e} | {above} | {:.2e} | {predicted} | {} | {times} | {} |",
        r.model,
        r.iterations,
        r.cpu,
        r.seconds,
        r.w,
        r.w / r.scale,
        if r.converged { "yes" } else { "no" },
        load()
    );
}
