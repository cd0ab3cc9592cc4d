//! Table I of Ma et al. 2012 on this machine: seconds per interpolation step of the mass-spring
//! blendshape model at the paper's vertex and spring counts, beside the paper's CPU (PARDISO,
//! 2.66 GHz Core 2 Quad) and GPU (Cusp) figures.
//!
//! The paper's models are not available, so each row is a procedural stand-in with the same
//! counts: a box surface (grid triangulation) tetrahedralized by TetGen, with the paper's
//! spring structure (structure + 2-ring bending + internal tet edges + the default anchor:
//! 4 points, 8 attachments each). Interior-heavy rows (Face, Hand: about 8 springs per vertex)
//! get TetGen quality points; surface-heavy rows (Cat, Horse: 11) get none and land a few
//! percent under the paper's spring count, the most a regular triangulation's 2-ring gives.
//! Every model blends from rest to a 90° bend along its long axis in 36 steps (alpha = k/35),
//! as the paper's table assumes.
//!
//! - warm: the 35 steps after the first, each starting from the previous step's equilibrium
//!   (what a sequence of in-betweens costs); median and mean seconds per step;
//! - cold: alpha = 0.25, 0.5, 0.75 each from the linear blend (no previous step);
//! - build: springs, anchor placement in the bent target, ordering and symbolic analysis.
//!
//! `cargo bench --bench massspring` (or `make bench-massspring`). The load average is printed
//! with every row: the machine is shared, and timings are only as good as that number.

use std::path::Path;
use std::time::Instant;

use blendsim::massspring::{Blend, Boundary, MassSpring, Settings, Targets};
use blendsim::mesh::TetMesh;
use blendsim::{procedural, tetgen};

struct Row {
    name: &'static str,
    /// The paper's counts and seconds per step.
    verts: usize,
    springs: usize,
    cpu: f64,
    gpu: f64,
    /// The stand-in: box size and divisions, TetGen quality and maximum volume (0 = none).
    size: [f64; 3],
    divisions: [usize; 3],
    quality: f64,
    max_volume: f64,
}

const ROWS: [Row; 5] = [
    Row { name: "Man", verts: 2_200, springs: 21_600, cpu: 2.23, gpu: 3.62, size: [0.4, 2.0, 0.3], divisions: [9, 50, 7], quality: 1.414, max_volume: 1.2e-4 },
    Row { name: "Face", verts: 8_100, springs: 65_100, cpu: 40.11, gpu: 3.67, size: [0.5, 1.3, 1.0], divisions: [10, 26, 20], quality: 1.414, max_volume: 4.5e-5 },
    Row { name: "Cat", verts: 7_300, springs: 81_700, cpu: 67.58, gpu: 13.67, size: [0.5, 2.0, 0.6], divisions: [24, 72, 20], quality: 0.0, max_volume: 0.0 },
    Row { name: "Horse", verts: 8_500, springs: 96_100, cpu: 81.36, gpu: 15.95, size: [0.5, 2.0, 0.6], divisions: [26, 76, 22], quality: 0.0, max_volume: 0.0 },
    Row { name: "Hand", verts: 18_600, springs: 150_400, cpu: 153.99, gpu: 26.28, size: [0.4, 1.5, 1.0], divisions: [12, 45, 30], quality: 1.414, max_volume: 1.6e-5 },
];

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        (v[n / 2 - 1] + v[n / 2]) / 2.0
    }
}

fn load_average() -> String {
    std::fs::read_to_string("/proc/loadavg").map(|s| s.split_whitespace().take(3).collect::<Vec<_>>().join(" ")).unwrap_or_else(|_| "?".into())
}

/// Bend a box lying along +y (from y = 0 to `length`) by `angle` radians towards +x about its
/// centre line x = `axis_x`: the centre line keeps its length and the volume is kept.
fn bend(points: &[[f64; 3]], length: f64, angle: f64, axis_x: f64) -> Vec<[f64; 3]> {
    let centre_x = axis_x + length / angle;
    points
        .iter()
        .map(|p| {
            let phi = angle * p[1] / length;
            let rho = centre_x - p[0];
            [centre_x - rho * phi.cos(), rho * phi.sin(), p[2]]
        })
        .collect()
}

fn checksum(shapes: &[Blend]) -> u64 {
    // FNV-1a over every coordinate's bits.
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for s in shapes {
        for c in s.positions.iter().flatten() {
            for b in c.to_bits().to_le_bytes() {
                h = (h ^ b as u64).wrapping_mul(0x100_0000_01b3);
            }
        }
    }
    h
}

fn main() {
    // `cargo bench -- NAME` runs the rows whose name contains NAME.
    let filter: Option<String> = std::env::args().skip(1).find(|a| !a.starts_with('-'));
    println!("Ma et al. 2012, Table I: seconds per interpolation step (36 steps, rest -> 90° bend), default anchor, 2-ring bending");
    println!("machine: {} logical CPUs; load average at start {}", std::thread::available_parallelism().map_or(0, |n| n.get()), load_average());
    println!();
    println!("| shape | n_v paper / ours | n_s paper / ours | paper CPU | paper GPU | ours warm (median / mean) | vs CPU | per step: Newton / factor. / CG | ours cold (median) | build | factor nnz | load |");
    println!("|---|---|---|---:|---:|---:|---:|---|---:|---:|---:|---|");
    for row in ROWS.iter().filter(|r| filter.as_deref().is_none_or(|f| r.name.to_lowercase().contains(&f.to_lowercase()))) {
        let surface = procedural::prism(row.size, row.divisions);
        let options = tetgen::TetgenOptions { quality: row.quality, max_volume: row.max_volume, timeout: 300.0 };
        let body: TetMesh = tetgen::tetrahedralize(&surface, &options, Path::new(row.name)).expect("tetgen");
        let length = row.size[1];
        let targets = vec![surface.positions.clone(), bend(&surface.positions, length, std::f64::consts::FRAC_PI_2, row.size[0] / 2.0)];
        let t = Targets { surface: &targets, triangles: &surface.triangles, body: Some(&body), body_poses: None };
        let settings = Settings::default();
        let t0 = Instant::now();
        let mut model = MassSpring::new(&t, &Boundary::Anchor(None), &settings).expect("model");
        let build = t0.elapsed().as_secs_f64();
        let summary = model.summary().clone();
        eprintln!("{}: predicted flops {:.3e}, matrix nnz {}, factor nnz {}, build {:?}", row.name, summary.predicted_flops, summary.matrix_nnz, summary.factor_nnz, summary);
        let n_v = summary.surface_vertices + summary.interior_vertices + summary.anchor_points;
        let alphas: Vec<f64> = (0..36).map(|k| k as f64 / 35.0).collect();
        let mut warm = Vec::new();
        let mut iterations = Vec::new();
        let (mut factorizations, mut cg) = (0usize, 0usize);
        let mut shapes = Vec::new();
        for (k, &a) in alphas.iter().enumerate() {
            let t1 = Instant::now();
            let shape = model.blend(&[1.0 - a, a], &[]).expect("blend");
            if k > 0 {
                warm.push(t1.elapsed().as_secs_f64());
                iterations.push(shape.report.iterations as f64);
                factorizations += shape.report.work.factorizations;
                cg += shape.report.work.cg_iterations;
                if std::env::var_os("MS_DETAIL").is_some() {
                    let w = &shape.report.work;
                    eprintln!("step {k}: newton {} fact {} cg {} factor {:.3} solve {:.3} total {:.3} wall {:.3}", shape.report.iterations, w.factorizations, w.cg_iterations, w.factor_seconds, w.solve_seconds, w.seconds, shape.report.seconds);
                }
            }
            shapes.push(shape);
        }
        let mut cold = Vec::new();
        for a in [0.25, 0.5, 0.75] {
            model.reset_warm_start();
            let t1 = Instant::now();
            model.blend(&[1.0 - a, a], &[]).expect("cold blend");
            cold.push(t1.elapsed().as_secs_f64());
        }
        // Same bytes again (the smallest row only: a second pass costs as much as the first).
        let same = if row.name == "Man" {
            let mut again = MassSpring::new(&t, &Boundary::Anchor(None), &settings).expect("model");
            let shapes2: Vec<Blend> = alphas.iter().map(|&a| again.blend(&[1.0 - a, a], &[]).expect("blend")).collect();
            if checksum(&shapes) == checksum(&shapes2) { " (same bytes twice)" } else { " (BYTES DIFFER)" }
        } else {
            ""
        };
        let warm_median = median(warm.clone());
        let warm_mean = warm.iter().sum::<f64>() / warm.len() as f64;
        println!(
            "| {}{same} | {} / {} | {} / {} | {:.2} s | {:.2} s | {:.3} / {:.3} s | {:.0}x | {:.1} / {:.2} / {:.1} | {:.3} s | {:.2} s | {:.1}M ({}) | {} |",
            row.name,
            row.verts,
            n_v,
            row.springs,
            summary.springs,
            row.cpu,
            row.gpu,
            warm_median,
            warm_mean,
            row.cpu / warm_median,
            iterations.iter().sum::<f64>() / iterations.len() as f64,
            factorizations as f64 / warm.len() as f64,
            cg as f64 / warm.len() as f64,
            median(cold),
            build,
            summary.factor_nnz as f64 / 1e6,
            summary.ordering,
            load_average(),
        );
    }
}
