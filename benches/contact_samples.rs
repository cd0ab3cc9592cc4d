//! What denser sampling next to a contact buys (`[solver] contact_samples`), on BALL and SPOT
//! (every interval of both touches the contact): for each count, the body's solve, then W
//! re-evaluated on one dense sampling (80 per interval) so the rows compare, the deepest any
//! node goes below the floor between the checked frames (the trajectory at 2400 Hz), and the
//! solve's wall time (only the ratios count on a shared machine: the load average is printed
//! with every row). The table `docs/paper-scenes.md` quotes; minutes.
//!
//! `cargo bench --bench contact_samples`

mod common;

use std::path::Path;

use blendsim::algorithms::spacetime::solver::objective;
use blendsim::pipeline::scene::SceneFile;
use blendsim::pipeline::stages::solve::{solve, solver_inputs};
use blendsim::pipeline::stages::Bake;
use blendsim::support::progress::Progress;
use common::load;

fn main() {
    println!("| scene | contact_samples | iterations | solve s | W (own sampling) | W at 80 samples | deepest below the floor between frames | contact time s | load |");
    println!("|---|---:|---:|---:|---:|---:|---:|---:|---|");
    for name in ["ball", "spot"] {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("fixtures/paper/{name}.toml"));
        for cs in [5, 10, 20, 40] {
            let mut scene = SceneFile::load(&path).expect("the paper scene loads (its meshes are in the shared assets)");
            scene.scene.solver.contact_samples = cs;
            let progress = Progress::hidden();
            let body = Bake::new(&scene, &progress).body().expect("import and tetrahedralize");
            let solution = solve(&body, None, &progress).expect("solve");
            let tr = &solution.trajectory;
            let (elastic, mut keys, mut settings) = solver_inputs(&solution.body).expect("a simulated body");
            keys.times = tr.times.clone();
            settings.samples = 80;
            settings.contact_samples = 80;
            let dense = objective(&elastic, &keys, &settings);
            let w = dense.evaluate(tr, &dense.local_step(tr, false)).value;
            let (start, end) = (tr.times[0], *tr.times.last().expect("keys"));
            let steps = ((end - start) * 2400.0).round() as usize;
            let deepest = (0..=steps)
                .map(|s| start + (end - start) * s as f64 / steps as f64)
                .flat_map(|t| tr.evaluate(t))
                .map(|p| p[1])
                .fold(f64::INFINITY, f64::min);
            let log = &solution.log;
            println!(
                "| {} | {cs} | {} | {:.2} | {:.3e} | {:.3e} | {:.2e} | {:.5} | {} |",
                name.to_uppercase(),
                log.iterations,
                log.seconds,
                log.energy.last().expect("W"),
                w,
                (-deepest).max(0.0),
                tr.times[1],
                load()
            );
        }
    }
}
