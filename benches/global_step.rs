//! The global step's three ways to invert its matrix on many-keys bodies: the sparse Cholesky
//! (on one thread and on all), conjugate gradients with the per-key blocks, and the body's
//! vibration modes. Per body: what the cost model predicts for each (seconds, bytes) and which it
//! chooses, then each method built and timed (set-up wall and CPU seconds, the median of three
//! solves) with its largest difference from the direct solve. A method whose predicted set-up
//! exceeds `MAX_SECONDS` (default 60) is left out of the timed rows.
//!
//! `cargo bench --bench global_step` (or `make bench-global-step`); `cargo bench --bench
//! global_step -- 400-nodes` runs only the named bodies. The machine's load average is printed
//! with every row: on a shared machine the timings are only as good as that number.

use std::time::Instant;

use blendsim::algorithms::geometry::{norm, sub, Point};
use blendsim::algorithms::spacetime::global_step::{GlobalStep, Method};
use blendsim::algorithms::spacetime::solver::objective;
use blendsim::algorithms::spacetime::unknowns::Unknowns;
use blendsim::pipeline::stage_file::Body;
use blendsim::pipeline::stages::solve::solver_inputs;
use blendsim::support::budget::Budget;

mod common;
use common::{armadillo_size, cpu_seconds, load, median, twenty_keys, twenty_keys_held};

/// Solves timed per method (the median is printed).
const SOLVES: usize = 3;

fn main() {
    type Case = (&'static str, Box<dyn Fn() -> Body>);
    let cases: Vec<Case> = vec![
        ("ARMADILLO-size-5-keys", Box::new(armadillo_size)),
        ("400-nodes-20-keys", Box::new(|| twenty_keys([6, 18, 6], 0.024, false))),
        ("2.6k-nodes-20-keys", Box::new(|| twenty_keys_held([12, 36, 12], 0.003, Some(&[0.0, 1.0])))),
    ];
    let only: Vec<String> = std::env::args().skip(1).filter(|a| !a.starts_with('-')).collect();
    let max_seconds: f64 = std::env::var("MAX_SECONDS").ok().and_then(|v| v.parse().ok()).unwrap_or(60.0);
    println!("machine: {} threads, load average {}", rayon::current_num_threads(), load());
    println!();
    println!("| body | nodes | keys | unknowns | chosen | ordering | predicted direct s / MB | predicted iterative s / MB | predicted modal s / MB | load |");
    println!("|---|---:|---:|---:|---|---|---:|---:|---:|---|");
    let mut timed_rows = Vec::new();
    for (name, body) in cases {
        if !only.is_empty() && !only.iter().any(|o| name.contains(o.as_str())) {
            continue;
        }
        let body = body();
        let (elastic, keys, settings) = solver_inputs(&body).expect("solver inputs");
        let objective = objective(&elastic, &keys, &settings);
        let unknowns = Unknowns::new(&keys, elastic.node_count());
        let chosen = GlobalStep::within(&objective, unknowns.clone(), settings.regularization, &Budget::default()).expect("global step");
        let s = chosen.stats;
        println!(
            "| {name} | {} | {} | {} | {} | {} | {:.2} / {:.0} | {:.2} / {:.0} | {:.2} / {:.0} | {} |",
            elastic.node_count(),
            keys.times.len(),
            s.unknowns,
            s.linear_solver,
            s.ordering,
            s.predicted_seconds,
            s.predicted_bytes / 1e6,
            s.predicted_iterative_seconds,
            s.predicted_iterative_bytes / 1e6,
            s.predicted_modal_seconds,
            s.predicted_modal_bytes / 1e6,
            load()
        );
        // A fixed right-hand side, the same for every method.
        let gradient: Vec<Vec<Point>> = (0..unknowns.slots.count())
            .map(|slot| (0..unknowns.nodes).map(|i| [((i * 7 + slot) % 13) as f64 - 6.0, ((i * 3 + slot) % 5) as f64 - 2.0, 1.0]).collect())
            .collect();
        let reference = chosen.step(&gradient);
        drop(chosen);
        let runs: [(&str, Method, Option<usize>, f64); 4] = [
            ("direct, 1 thread", Method::Direct, Some(1), s.predicted_seconds),
            ("direct, all threads", Method::Direct, None, s.predicted_seconds),
            ("iterative", Method::Iterative, None, s.predicted_iterative_seconds),
            ("modal", Method::Modal, None, s.predicted_modal_seconds),
        ];
        for (label, method, threads, predicted) in runs {
            if predicted > max_seconds {
                timed_rows.push(format!("| {name} | {label} | predicted {predicted:.0} s > MAX_SECONDS | | | | | | {} |", load()));
                continue;
            }
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads.unwrap_or(0)).build().expect("thread pool");
            let row = pool.install(|| {
                let (wall, cpu) = (Instant::now(), cpu_seconds());
                let step =
                    GlobalStep::build(&objective, unknowns.clone(), settings.regularization, &Budget::default(), Some(method)).expect("global step");
                let (setup, setup_cpu) = (wall.elapsed().as_secs_f64(), cpu_seconds() - cpu);
                let mut solves = Vec::new();
                let mut out = Vec::new();
                for _ in 0..SOLVES {
                    let t = Instant::now();
                    out = step.step(&gradient);
                    solves.push(t.elapsed().as_secs_f64());
                }
                let scale = reference.iter().flatten().map(|p| norm(*p)).fold(0.0, f64::max);
                let difference = out.iter().flatten().zip(reference.iter().flatten()).map(|(a, b)| norm(sub(*a, *b))).fold(0.0, f64::max);
                format!(
                    "| {name} | {label} | {setup:.3} | {setup_cpu:.3} | {:.3} | {:.3} | {:.4} | {:.1e} | {} |",
                    step.stats.assemble_seconds,
                    step.stats.factor_seconds,
                    median(solves),
                    difference / scale.max(f64::MIN_POSITIVE),
                    load()
                )
            });
            timed_rows.push(row);
        }
    }
    println!();
    println!("Each method built and timed: set-up (assembly, ordering, factorization or modes), the median of {SOLVES} solves, and the largest difference from the cost model's choice relative to its largest entry");
    println!();
    println!("| body | method | set-up s | set-up CPU s | assemble s | factor s | solve s | difference | load |");
    println!("|---|---|---:|---:|---:|---:|---:|---:|---|");
    for row in timed_rows {
        println!("{row}");
    }
    println!();
    println!("load average after: {}", load());
}
