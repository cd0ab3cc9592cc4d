//! Where the demo bake's time goes (issue 11: "the demo bake under 0.25 s"): the whole `bake`
//! process, then each phase run in this process the way `Bake` runs it, then one solver
//! iteration taken apart, and usd-core's Python start-up on its own. Wall and CPU seconds
//! (CPU: every thread of this process, or of the child), medians of `REPEATS` (default 5).
//!
//! `cargo bench --bench demo` (`make bench-demo`); `RAYON_NUM_THREADS=1` for one thread.
//! Mind the load average printed with it: the machine is shared.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use blendsim::algorithms::spacetime::global_step::GlobalStep;
use blendsim::algorithms::spacetime::solver::{initial_trajectory, objective};
use blendsim::algorithms::spacetime::unknowns::Unknowns;
use blendsim::formats::tetgen::{run as tetgen, TetgenOptions};
use blendsim::pipeline::scene::{Format, SceneFile};
use blendsim::pipeline::stage_file::Shape;
use blendsim::pipeline::stages::solve::solver_inputs;
use blendsim::pipeline::stages::{self, blendshape_clip, embed, export_with, import, solve, tetrahedralize};
use blendsim::support::budget::Budget;
use blendsim::support::output::Staging;
use blendsim::support::progress::Progress;

mod common;
use common::{load, median};

const SCENE: &str = "fixtures/demo/twist.toml";

/// CPU seconds (user + system) of this process's threads, or of its waited-for children.
fn cpu(who: i32) -> f64 {
    // SAFETY: getrusage writes one rusage struct it is given.
    let mut r: libc::rusage = unsafe { std::mem::zeroed() };
    unsafe { libc::getrusage(who, &mut r) };
    let s = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 * 1e-6;
    s(r.ru_utime) + s(r.ru_stime)
}

/// Wall and CPU seconds of `f` (CPU of this process), and its result.
fn timed<T>(f: impl FnOnce() -> T) -> (f64, f64, T) {
    let (t, c) = (Instant::now(), cpu(libc::RUSAGE_SELF));
    let out = f();
    (t.elapsed().as_secs_f64(), cpu(libc::RUSAGE_SELF) - c, out)
}

/// Wall and CPU seconds of a child process run to its end.
fn child(command: &mut Command) -> (f64, f64) {
    let (t, c) = (Instant::now(), cpu(libc::RUSAGE_CHILDREN));
    let status = command.status().expect("the command starts");
    assert!(status.success(), "{command:?} failed");
    (t.elapsed().as_secs_f64(), cpu(libc::RUSAGE_CHILDREN) - c)
}

/// Medians of the wall and CPU columns.
struct Row {
    name: String,
    wall: Vec<f64>,
    cpu: Vec<f64>,
    note: String,
}

impl Row {
    fn new(name: &str) -> Row {
        Row { name: name.into(), wall: Vec::new(), cpu: Vec::new(), note: String::new() }
    }
    fn push(&mut self, (wall, cpu): (f64, f64)) {
        self.wall.push(wall);
        self.cpu.push(cpu);
    }
    fn print(&self) {
        println!("| {} | {:.5} | {:.5} | {} |", self.name, median(self.wall.clone()), median(self.cpu.clone()), self.note);
    }
}

/// The phases shown with a predicted duration, measured on prisms of growing size beside what
/// their cost models predict (`cargo bench --bench demo -- models`).
fn models() {
    use blendsim::algorithms::cage::{fit::CageFit, voxel_cage};
    use blendsim::algorithms::embed::Binding;
    use blendsim::algorithms::physics::elastic::{Elastic, Material as ElasticMaterial};
    use blendsim::algorithms::procedural::prism;
    println!("cost models against measurement (one run each; load average {})", load());
    println!();
    println!("| surface vertices | triangles | phase | work | measured s | CPU s | predicted s |");
    println!("|---:|---:|---|---:|---:|---:|---:|");
    let material = ElasticMaterial { stiffness: 70.0, volume: 70.0, density: 1.0 };
    let sizes: Vec<usize> =
        std::env::var("SIZES").map(|v| v.split(',').map(|x| x.parse().expect("SIZES: numbers")).collect()).unwrap_or(vec![4, 8, 16, 32, 64, 100]);
    for d in sizes {
        let surface = prism([1.0, 2.5, 1.0], [d, (5 * d) / 2, d]);
        let (n, t) = (surface.positions.len(), surface.triangles.len());
        if n <= 15000 {
            for max_volume in [0.0, 0.01, 0.001] {
                let options = TetgenOptions { quality: 1.414, max_volume, timeout: 600.0 };
                let k0 = cpu(libc::RUSAGE_CHILDREN);
                let (w, c, mesh) = timed(|| tetgen(&surface, &options, Path::new("prism")).expect("TetGen"));
                let c = c + cpu(libc::RUSAGE_CHILDREN) - k0;
                let predicted = blendsim::formats::tetgen::predicted_seconds(&surface, &options);
                println!("| {n} | {t} | TetGen -a{max_volume} | {} tets | {w:.3} | {c:.3} | {predicted:.3} |", mesh.tets.len());
                let (w, c, _) = timed(|| Binding::compute(&mesh, &surface.positions));
                println!(
                    "| {n} | {t} | embed in the TetGen body | {} tets | {w:.3} | {c:.3} | {:.3} |",
                    mesh.tets.len(),
                    Binding::predicted_seconds(mesh.tets.len(), n)
                );
            }
        }
        let (w, c, cage) = timed(|| voxel_cage(&surface, &surface.positions, 1000).expect("cage"));
        println!(
            "| {n} | {t} | cage | {} nodes | {w:.3} | {c:.3} | {:.3} |",
            cage.mesh.positions.len(),
            blendsim::algorithms::cage::predicted_seconds(t, 1000)
        );
        let (w, c, binding) = timed(|| Binding::compute(&cage.mesh, &surface.positions));
        println!(
            "| {n} | {t} | embed in the cage | {} tets | {w:.3} | {c:.3} | {:.3} |",
            cage.mesh.tets.len(),
            Binding::predicted_seconds(cage.mesh.tets.len(), n)
        );
        let elastic = Elastic::new(&cage.mesh, &material).expect("elastic");
        let twisted: Vec<_> = surface
            .positions
            .iter()
            .map(|p| {
                let (s, c) = (0.3 * p[1]).sin_cos();
                [c * (p[0] - 0.5) - s * (p[2] - 0.5) + 0.5, p[1], s * (p[0] - 0.5) + c * (p[2] - 0.5) + 0.5]
            })
            .collect();
        let (w, c, _) = timed(|| {
            let fit = CageFit::new(&cage.mesh, &binding, &elastic);
            fit.pose(&surface.positions, &twisted)
        });
        println!(
            "| {n} | {t} | cage fit, one key | {} nodes | {w:.3} | {c:.3} | {:.3} |",
            cage.mesh.positions.len(),
            CageFit::predicted_seconds(cage.mesh.tets.len(), n, 1)
        );
    }
}

fn main() {
    if std::env::args().skip(1).any(|a| a == "models") {
        return models();
    }
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let repeats: usize = std::env::var("REPEATS").ok().and_then(|r| r.parse().ok()).unwrap_or(5);
    let bin = root.join("target/release/blendsim");
    let scratch = tempfile::Builder::new().prefix("blendsim-bench-demo-").tempdir().expect("a scratch folder");
    let out = |name: &str| -> PathBuf { scratch.path().join(name) };
    let python = std::env::var_os("BLENDSIM_PYTHON").unwrap_or_else(|| "python3".into());
    println!("demo bake ({SCENE}), medians of {repeats}; {} rayon threads; load average {}", rayon::current_num_threads(), load());
    println!();
    println!("| phase | wall s | CPU s | |");
    println!("|---|---:|---:|---|");

    // The whole process, as `make demo` runs it.
    let mut whole = Row::new("`blendsim bake` (the process)");
    if bin.is_file() {
        for _ in 0..repeats {
            whole.push(child(Command::new(&bin).arg("bake").arg(root.join(SCENE)).arg("--out").arg(out("cli")).arg("--quiet")));
        }
        whole.note = format!("load {}", load());
        whole.print();
    } else {
        println!("| `blendsim bake` | | | {} missing: `cargo build --release` first |", bin.display());
    }

    // Each phase in this process.
    let scene = SceneFile::load(&root.join(SCENE)).expect("the demo scene loads");
    let progress = Progress::hidden();
    let budget = Budget::default();
    let mut rows: Vec<Row> = [
        "import",
        "TetGen alone",
        "tetrahedralize (TetGen + interior fit)",
        "solve",
        "  precompute (assembly, ordering, factor or modes)",
        "  iterations",
        "embed",
        "blendshape clip",
        "export usda + glb",
        "export usda + usdc + glb",
        "report measures",
        "commit over the previous bake (fsyncs, swap, old files removed)",
    ]
    .iter()
    .map(|n| Row::new(n))
    .collect();
    let mut iterations = Vec::new();
    let mut per_iteration = Vec::new();
    for r in 0..repeats {
        let (w, c, keys) = timed(|| import(&scene, &budget).expect("import"));
        rows[0].push((w, c));
        if let Shape::Surface(rest) = &keys.rest {
            let s = &keys.scene.tet;
            let options = TetgenOptions { quality: s.quality, max_volume: s.max_volume, timeout: s.timeout };
            let k0 = cpu(libc::RUSAGE_CHILDREN);
            let (w, c, _) = timed(|| tetgen(rest, &options, Path::new("rest")).expect("TetGen"));
            rows[1].push((w, c + cpu(libc::RUSAGE_CHILDREN) - k0));
        }
        let k0 = cpu(libc::RUSAGE_CHILDREN);
        let (w, c, body) = timed(|| tetrahedralize(&keys, &budget, &progress).expect("tetrahedralize"));
        rows[2].push((w, c + cpu(libc::RUSAGE_CHILDREN) - k0));
        let (w, c, solution) = timed(|| solve(&body, None, &progress).expect("solve"));
        rows[3].push((w, c));
        let log = &solution.log;
        rows[4].push((log.precompute_seconds, f64::NAN));
        rows[5].push((log.seconds - log.precompute_seconds, f64::NAN));
        iterations.push(log.iterations as f64);
        per_iteration.push(log.iteration_seconds);
        let (w, c, animation) = timed(|| embed(&solution).expect("embed"));
        rows[6].push((w, c));
        let (w, c, clip) = timed(|| blendshape_clip(&animation, None, &budget).expect("clip"));
        rows[7].push((w, c));
        let mut light = animation.clone();
        light.scene.export.formats.retain(|f| *f != Format::Usdc);
        let (w, c, _) = timed(|| {
            let mut staging = Staging::new(&out(&format!("light{r}"))).expect("staging");
            export_with(&light, &clip, &mut staging, &budget, &progress).expect("export");
            staging.commit().expect("commit");
        });
        rows[8].push((w, c));
        let (t, c0, k0) = (Instant::now(), cpu(libc::RUSAGE_SELF), cpu(libc::RUSAGE_CHILDREN));
        {
            let mut staging = Staging::new(&out(&format!("all{r}"))).expect("staging");
            export_with(&animation, &clip, &mut staging, &budget, &progress).expect("export with usdc");
            staging.commit().expect("commit");
        }
        rows[9].push((t.elapsed().as_secs_f64(), cpu(libc::RUSAGE_SELF) - c0 + cpu(libc::RUSAGE_CHILDREN) - k0));
        let (w, c, _) = timed(|| stages::report::measure(&animation, &clip, &budget).expect("measure"));
        rows[10].push((w, c));
        // A re-bake into the same folder (`make demo` again, the process row): the commit also
        // removes the previous bake's files. Timed on the second of two.
        for timed_commit in [false, true] {
            let mut staging = Staging::new(&out("again")).expect("staging");
            export_with(&animation, &clip, &mut staging, &budget, &progress).expect("export");
            let (w, c, _) = timed(|| staging.commit().expect("commit"));
            if timed_commit {
                rows[11].push((w, c));
            }
        }
    }
    rows[1].note = "CPU includes the TetGen child".into();
    rows[2].note = rows[1].note.clone();
    rows[5].note = format!("{} iterations, {:.2} ms each", median(iterations), 1e3 * median(per_iteration));
    for row in &rows {
        row.print();
    }

    // Python alone: what a usd-core converter would cost at start-up (bakes write usdc natively).
    let mut bare = Row::new("Python start (`python3 -c pass`)");
    let mut pxr = Row::new("Python start + `from pxr import Sdf`");
    for _ in 0..repeats {
        bare.push(child(Command::new(&python).arg("-c").arg("pass")));
        pxr.push(child(Command::new(&python).arg("-c").arg("from pxr import Sdf")));
    }
    bare.print();
    pxr.print();

    // One solver iteration taken apart, at the demo's first guess.
    let body = stages::Bake::new(&scene, &progress).body().expect("body");
    let (elastic, keys, settings) = solver_inputs(&body).expect("solver inputs");
    let objective = objective(&elastic, &keys, &settings);
    let mut build = Row::new("global step built (assembly; the cost model's choice: ordering and factorization, or the modes)");
    let mut stages = (Vec::new(), Vec::new());
    for _ in 0..repeats {
        let (w, c, g) =
            timed(|| GlobalStep::new(&objective, Unknowns::new(&keys, elastic.node_count()), settings.regularization).expect("global step"));
        build.push((w, c));
        stages.0.push(g.stats.assemble_seconds);
        stages.1.push(g.stats.factor_seconds);
    }
    build.note = format!("assembly {:.4} s, the rest {:.4} s (wall)", median(stages.0), median(stages.1));
    let global = GlobalStep::new(&objective, Unknowns::new(&keys, elastic.node_count()), settings.regularization).expect("global step");
    let tr = initial_trajectory(&keys);
    let reps = 10 * repeats;
    let mut parts: Vec<Row> = [
        "local step (projections)",
        "local step with Jacobians",
        "residuals + model gradient",
        "residuals + exact gradient",
        "global solve (3 coordinates)",
        "exact evaluation in one pass (the solver's: local step + residuals + gradients)",
    ]
    .iter()
    .map(|n| Row::new(n))
    .collect();
    let (p, pj) = (objective.local_step(&tr, false), objective.local_step(&tr, true));
    let e = objective.evaluate(&tr, &pj);
    let g = global.gather(e.exact_gradient.as_ref().expect("exact"));
    let mut buffers = blendsim::algorithms::spacetime::objective::Projections { targets: Vec::new(), jacobians: None };
    // On a worker of the thread pool, as `stages::solve` runs the solver (`rayon::scope`): the
    // parts' parallel loops start inside the pool, not handed over from this thread.
    rayon::scope(|_| {
        for _ in 0..reps {
            let (w, c, _) = timed(|| objective.local_step(&tr, false));
            parts[0].push((w, c));
            let (w, c, _) = timed(|| objective.local_step(&tr, true));
            parts[1].push((w, c));
            let (w, c, _) = timed(|| objective.evaluate(&tr, &p));
            parts[2].push((w, c));
            let (w, c, _) = timed(|| objective.evaluate(&tr, &pj));
            parts[3].push((w, c));
            let mut x = g.clone();
            let (w, c, _) = timed(|| global.apply_inverse(&mut x));
            parts[4].push((w, c));
            let (w, c, _) = timed(|| objective.evaluate_fresh(&tr, true, &mut buffers));
            parts[5].push((w, c));
        }
    });
    println!();
    let stats = &global.stats;
    let inverse = match stats.linear_solver {
        "direct" => format!("factor {} entries ({}), {:.1} MB", stats.factor_nnz, stats.ordering, 8e-6 * stats.factor_nnz as f64),
        other => format!("global step {other} ({})", stats.ordering),
    };
    println!(
        "one iteration's parts ({} nodes, {} tets, {} samples, {} unknowns per coordinate, {} matrix entries, {inverse}), on a worker of the pool as the solve runs them, medians of {reps}:",
        elastic.node_count(),
        elastic.tet_count(),
        objective.samples.len(),
        global.unknowns().count(),
        stats.matrix_nnz,
    );
    println!();
    println!("| part | wall s | CPU s | |");
    println!("|---|---:|---:|---|");
    if stats.linear_solver == "direct" {
        // The two sweeps read every factor entry once each: the solve's rate through the factor.
        parts[4].note = format!("{:.1} GB/s of factor read (two sweeps)", 2.0 * 8e-9 * stats.factor_nnz as f64 / median(parts[4].wall.clone()));
    }
    build.print();
    for row in &parts {
        row.print();
    }
    println!();
    println!("load average after: {}", load());
}
