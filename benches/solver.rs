//! Table 1 of the BlendSim paper on this machine: precompute (assembly + factorization) and
//! per-iteration time (local step + residuals + global step) of the spacetime solver, per
//! scene, beside the paper's figures (20-thread i7-14700KF). Medians of repeated runs.
//!
//! A second table times the keyframe timing optimization. **One timing round** is one Newton
//! iteration on the interval lengths with the keys held, started from the W the solver already
//! has ([`Timing::optimize_times_from`] with one iteration): the exact `∂W/∂T_i` and
//! `∂²W/∂T_i²` with fresh projections on every interval, the constrained Newton step, and its
//! Armijo line search on W (each trial: samples, local step and residuals at the trial times).
//! That is one timing step of the paper's alternating scheme (section 3.4), what its Table 1
//! "timing optimization" column measures. Not in it, and measured beside it: the rebuild of the
//! global step for the new times (assembly and numeric refactorization on the kept symbolic
//! analysis, against a fresh factorization), which our solver does only when an interval has
//! moved by more than `REFACTOR_CHANGE` since the last one, and what the time gradient adds to
//! each exact evaluation of the joint quasi-Newton iteration (the solver moves keys and times
//! together, so that is the timing work of every one of its iterations). Wall and CPU seconds
//! (all threads) of the round are given: under load the CPU seconds are the steadier figure.
//!
//! A third table runs the whole solver (contacts and their active set, the key times when the
//! scene optimizes them) for a few iterations and gives its mean time per iteration: for BALL
//! and SPOT that is what the paper's iteration column measures, the plain iteration of the
//! first table leaves the contacts out.
//!
//! `cargo bench --bench solver` (or `make bench`); `cargo bench --bench solver -- TWIST DINO`
//! runs only the named scenes. The machine's load average is printed with
//! every row: on a shared machine the timings are only as good as that number.

use std::time::Instant;

use blendsim::algorithms::physics::elastic::Elastic;
use blendsim::algorithms::spacetime::global_step::{GlobalStats, GlobalStep};
use blendsim::algorithms::spacetime::settings::{Settings, TimingSettings};
use blendsim::algorithms::spacetime::solver::{apply_step, initial_trajectory, objective, solve};
use blendsim::algorithms::spacetime::timing::{ProjectionMode, Timing};
use blendsim::algorithms::spacetime::trajectory::Trajectory;
use blendsim::algorithms::spacetime::unknowns::{KeyConstraints, Unknowns};
use blendsim::pipeline::stage_file::Body;
use blendsim::pipeline::stages::solve::solver_inputs;

mod common;
use common::{armadillo_size, cheb_size, cpu_seconds, load, median, scene_body};

struct Paper {
    /// The "timing optimization" column of Table 1 (s per iteration).
    timing: f64,
    verts: usize,
    tets: usize,
    keys: usize,
    samples: usize,
    precompute: f64,
    iteration: f64,
}

struct Measured {
    precompute: f64,
    assemble: f64,
    factor: f64,
    iteration: f64,
    local: f64,
    global: f64,
    unknowns: usize,
    matrix_nnz: usize,
    factor_nnz: usize,
    ordering: &'static str,
    /// Phase 2 of the solver: local step with projection Jacobians, exact gradient, one solve.
    exact_iteration: f64,
    timing: TimingMeasured,
    /// Residual samples over all intervals (contact intervals have their own count).
    samples: usize,
    /// The whole solver, a few iterations: mean s per iteration, iterations run, contacts held at the end.
    solver: (f64, usize, usize),
}

struct TimingMeasured {
    /// Exact dW/dT and d2W/dT2 with fresh projections.
    derivatives: f64,
    /// W at new times: samples, local step, residuals.
    energy: f64,
    /// One timing round (see the module documentation): wall and CPU seconds.
    round: f64,
    round_cpu: f64,
    /// W evaluations of the round's line search.
    trials: usize,
    /// What the time gradient adds to an exact evaluation (the solver's joint iteration).
    time_gradient: f64,
    /// CPU seconds (all threads) of the derivatives, a W evaluation, and the time gradient.
    derivatives_cpu: f64,
    energy_cpu: f64,
    time_gradient_cpu: f64,
    /// The global step rebuilt for new times: assembly + numeric refactorization.
    retime: f64,
    /// ... of which the numeric refactorization.
    refactor: f64,
    /// A fresh factorization for comparison: ordering, symbolic analysis and numeric.
    fresh_factor: f64,
    reused_symbolic: bool,
}

/// Iterations of the whole-solver measurement.
const SOLVER_ITERATIONS: usize = 20;

fn measure(body: &Body, repeats: usize, iterations: usize) -> Measured {
    let mut pre = Vec::new();
    let mut last = None;
    for _ in 0..repeats {
        let t = Instant::now();
        let (elastic, keys, settings) = solver_inputs(body).unwrap();
        let objective = objective(&elastic, &keys, &settings);
        let global = GlobalStep::new(&objective, Unknowns::new(&keys, elastic.node_count()), settings.regularization).unwrap();
        pre.push(t.elapsed().as_secs_f64());
        last = Some((elastic, keys, settings, global));
    }
    let (elastic, keys, settings, global) = last.unwrap();
    let objective = objective(&elastic, &keys, &settings);
    let mut tr = initial_trajectory(&keys);
    let (mut it, mut loc, mut glo) = (Vec::new(), Vec::new(), Vec::new());
    for _ in 0..iterations {
        let t = Instant::now();
        let p = objective.local_step(&tr, false);
        let t_local = t.elapsed().as_secs_f64();
        let e = objective.evaluate(&tr, &p);
        let t1 = Instant::now();
        let d = global.step(&e.gradient);
        glo.push(t1.elapsed().as_secs_f64());
        apply_step(&mut tr, &objective.slots, &d, 1.0);
        loc.push(t_local);
        it.push(t.elapsed().as_secs_f64());
    }
    let mut exact = Vec::new();
    for _ in 0..iterations.min(5) {
        let t = Instant::now();
        let e = objective.evaluate(&tr, &objective.local_step(&tr, true));
        let mut g = global.gather(e.exact_gradient.as_ref().expect("requested"));
        global.apply_inverse(&mut g);
        exact.push(t.elapsed().as_secs_f64());
    }
    let (timing, s) = measure_timing(&elastic, &keys, &settings, &tr, global, repeats);
    let samples = objective.samples.len();
    let short = Settings { max_iterations: SOLVER_ITERATIONS, ..settings.clone() };
    let solved = solve(&elastic, &keys, &short, &|_, _, _| {}).expect("solve");
    let solver = (solved.log.iteration_seconds, solved.log.iterations, solved.log.active_contacts);
    Measured {
        samples,
        solver,
        timing,
        ordering: s.ordering,
        exact_iteration: median(exact),
        precompute: median(pre),
        assemble: s.assemble_seconds,
        factor: s.factor_seconds,
        iteration: median(it),
        local: median(loc),
        global: median(glo),
        unknowns: s.unknowns,
        matrix_nnz: s.matrix_nnz,
        factor_nnz: s.factor_nnz,
    }
}

/// A timing round and a retime at the trajectory `tr`; `global` is retimed in place.
fn measure_timing(
    elastic: &Elastic,
    keys: &KeyConstraints,
    settings: &Settings,
    tr: &Trajectory,
    mut global: GlobalStep,
    repeats: usize,
) -> (TimingMeasured, GlobalStats) {
    let timing = Timing::new(elastic, keys, settings);
    let (mut derivatives, mut energy, mut round, mut round_cpu) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let (mut retime, mut refactor, mut reused) = (Vec::new(), Vec::new(), true);
    let (mut with_time, mut without_time) = (Vec::new(), Vec::new());
    let (mut derivatives_cpu, mut energy_cpu, mut with_time_cpu, mut without_time_cpu) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let one_newton = TimingSettings { max_iterations: 1, tolerance: 0.0, ..TimingSettings::default() };
    let w = timing.energy(tr);
    let mut trials = 0;
    for k in 0..repeats {
        let (t, c) = (Instant::now(), cpu_seconds());
        let _ = timing.derivatives(tr, ProjectionMode::Fresh);
        derivatives.push(t.elapsed().as_secs_f64());
        derivatives_cpu.push(cpu_seconds() - c);
        let (t, c) = (Instant::now(), cpu_seconds());
        let _ = timing.energy(tr);
        energy.push(t.elapsed().as_secs_f64());
        energy_cpu.push(cpu_seconds() - c);
        let (t, c) = (Instant::now(), cpu_seconds());
        let step = timing.optimize_times_from(tr, w, &one_newton).expect("timing step");
        round.push(t.elapsed().as_secs_f64());
        round_cpu.push(cpu_seconds() - c);
        trials = 1 + step.halvings;
        for time_gradient in [true, false] {
            let mut objective = timing.objective(&tr.times);
            objective.time_gradient = time_gradient;
            let (t, c) = (Instant::now(), cpu_seconds());
            let _ = objective.evaluate(tr, &objective.local_step(tr, true));
            let (wall, cpu) = (t.elapsed().as_secs_f64(), cpu_seconds() - c);
            if time_gradient { &mut with_time } else { &mut without_time }.push(wall);
            if time_gradient { &mut with_time_cpu } else { &mut without_time_cpu }.push(cpu);
        }
        // Alternate between two sets of times so every rebuild changes the values.
        let times: Vec<f64> = if k % 2 == 0 { step.times.clone() } else { tr.times.clone() };
        let t = Instant::now();
        let r = global.retime(&timing.objective(&times), settings.regularization).expect("retime");
        retime.push(t.elapsed().as_secs_f64());
        refactor.push(r.factor_seconds);
        reused &= r.reused_symbolic;
    }
    let stats = global.stats;
    let measured = TimingMeasured {
        derivatives: median(derivatives),
        energy: median(energy),
        round: median(round),
        round_cpu: median(round_cpu),
        trials,
        time_gradient: median(with_time) - median(without_time),
        derivatives_cpu: median(derivatives_cpu),
        energy_cpu: median(energy_cpu),
        time_gradient_cpu: median(with_time_cpu) - median(without_time_cpu),
        retime: median(retime),
        refactor: median(refactor),
        fresh_factor: stats.factor_seconds,
        reused_symbolic: reused,
    };
    (measured, stats)
}

fn main() {
    type Case = (&'static str, Box<dyn Fn() -> Body>, Paper);
    let cases: Vec<Case> = vec![
        (
            "STRETCH",
            Box::new(|| scene_body("fixtures/paper/stretch.toml")),
            Paper { timing: 0.023, verts: 594, tets: 2400, keys: 3, samples: 14, precompute: 0.18, iteration: 0.009 },
        ),
        (
            "TWIST",
            Box::new(|| scene_body("fixtures/paper/twist.toml")),
            Paper { timing: 0.016, verts: 594, tets: 2400, keys: 5, samples: 40, precompute: 0.699, iteration: 0.035 },
        ),
        (
            "DINO",
            Box::new(|| scene_body("fixtures/paper/dino.toml")),
            Paper { timing: 0.023, verts: 439, tets: 1192, keys: 10, samples: 90, precompute: 0.91, iteration: 0.030 },
        ),
        (
            "CHEB-size",
            Box::new(cheb_size),
            Paper { timing: 0.205, verts: 922, tets: 3125, keys: 10, samples: 90, precompute: 3.771, iteration: 0.080 },
        ),
        (
            "BALL",
            Box::new(|| scene_body("fixtures/paper/ball.toml")),
            Paper { timing: 0.009, verts: 316, tets: 1070, keys: 3, samples: 40, precompute: 0.412, iteration: 0.112 },
        ),
        (
            "SPOT",
            Box::new(|| scene_body("fixtures/paper/spot.toml")),
            Paper { timing: 0.012, verts: 823, tets: 2288, keys: 3, samples: 24, precompute: 1.043, iteration: 0.263 },
        ),
        (
            "ARMADILLO-size",
            Box::new(armadillo_size),
            Paper { timing: 0.246, verts: 2598, tets: 10024, keys: 5, samples: 40, precompute: 3.073, iteration: 0.100 },
        ),
    ];
    println!("machine: {} threads, load average {}", rayon::current_num_threads(), load());
    println!();
    println!("| scene | nodes | tets | keys | samples | unknowns/coord | nnz(A) | nnz(L) | precompute s (paper) | iteration s (paper) | local s | global s | assemble s | factor s | exact-gradient iteration s | ordering | load |");
    println!("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|---|");
    let mut timing_rows = Vec::new();
    let mut solver_rows = Vec::new();
    let only: Vec<String> = std::env::args().skip(1).filter(|a| !a.starts_with('-')).collect();
    for (name, make, paper) in cases.iter().filter(|c| only.is_empty() || only.iter().any(|o| o == c.0)) {
        let body = make();
        let tets = body.mesh.as_ref().expect("the paper scenes are simulated");
        let big = tets.tets.len() > 5000;
        let m = measure(&body, if big { 3 } else { 5 }, if big { 7 } else { 9 });
        let samples = m.samples;
        println!(
            "| {name} | {} ({}) | {} ({}) | {} ({}) | {samples} ({}) | {} | {:.2}M | {:.2}M | {:.3} ({:.3}) | {:.4} ({:.3}) | {:.4} | {:.4} | {:.3} | {:.3} | {:.4} | {} | {} |",
            tets.positions.len(), paper.verts, tets.tets.len(), paper.tets, body.keys.times.len(), paper.keys, paper.samples,
            m.unknowns, m.matrix_nnz as f64 / 1e6, m.factor_nnz as f64 / 1e6, m.precompute, paper.precompute, m.iteration, paper.iteration,
            m.local, m.global, m.assemble, m.factor, m.exact_iteration, m.ordering, load()
        );
        solver_rows.push(format!("| {name} | {:.4} ({:.3}) | {} | {} | {} |", m.solver.0, paper.iteration, m.solver.1, m.solver.2, load()));
        let t = &m.timing;
        timing_rows.push(format!(
            "| {name} | {:.4} ({:.3}) | {:.4} | {:.4} ({:.4}) | {:.4} ({:.4}) | {} | {:.4} ({:.4}) | {:.4} | {:.4} | {:.3} | {:.1}x | {} | {} |",
            t.round,
            paper.timing,
            t.round_cpu,
            t.derivatives,
            t.derivatives_cpu,
            t.energy,
            t.energy_cpu,
            t.trials,
            t.time_gradient,
            t.time_gradient_cpu,
            t.retime,
            t.refactor,
            t.fresh_factor,
            t.fresh_factor / t.refactor,
            if t.reused_symbolic { "yes" } else { "no" },
            load()
        ));
    }
    println!();
    println!("Timing optimization. One timing round: one Newton iteration on the interval lengths, keys held, from the current W: exact dW/dT_i and d2W/dT_i2 (fresh projections), the constrained Newton step, its line search on W (the paper's \"timing optimization\" column). Beside it: the time gradient's share of one exact evaluation of the joint quasi-Newton iteration, and the global step rebuilt for new times (done when an interval moved by more than 10%)");
    println!();
    println!("| scene | timing round s (paper) | round CPU s | T derivatives s (CPU) | W evaluation s (CPU) | W trials | time gradient per evaluation s (CPU) | retime s | of which refactor s | fresh factorization s | fresh / refactor | symbolic reused | load |");
    println!("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|---|");
    for row in timing_rows {
        println!("{row}");
    }
    println!();
    println!("The whole solver, {SOLVER_ITERATIONS} iterations (or until it stops): mean s per iteration, with the contacts' active set and the key times when the scene has them");
    println!();
    println!("| scene | solver s per iteration (paper's iteration) | iterations | contacts held | load |");
    println!("|---|---:|---:|---:|---|");
    for row in solver_rows {
        println!("{row}");
    }
    println!();
    println!("load average after: {}", load());
}
