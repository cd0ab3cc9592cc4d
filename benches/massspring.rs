//! Table I of Ma et al. 2012 on this machine: seconds per interpolation step of the mass-spring
//! blendshape model at the paper's vertex and spring counts, beside the paper's CPU (PARDISO,
//! 2.66 GHz Core 2 Quad) and GPU (Cusp) figures.
//!
//! The paper's models are not available, so each row is a procedural stand-in of the same
//! kind with the same counts: a figure built of boxes (a standing man with arms out, a
//! head-sized slab with a nose, a cat and a horse on four legs with head and tail, a hand
//! with four fingers and a thumb), its voxel surface (a regular grid triangulation)
//! tetrahedralized by TetGen, with the paper's spring structure (structure + 2-ring bending +
//! internal tet edges + the default anchor: 4 points, 8 attachments each). Vertex counts are
//! matched within 2%; spring counts within 6% for Man, Face and Hand, while Cat and Horse (11
//! springs per vertex in the paper) get 9-10% fewer: a regular triangulation's 2-ring gives at
//! most about 10.5 per vertex. Every model blends from rest to a target where the part beyond
//! a joint is bent by 90° (the man at the hips, the face's upper part, the cat's and horse's
//! front half sideways, the hand's fingers), in 36 steps (alpha = k/35), as the paper's table
//! assumes.
//!
//! - warm: the 35 steps after the first, each starting from the previous step's equilibrium
//!   (what a sequence of in-betweens costs); median and mean seconds per step;
//! - cold: alpha = 0.25, 0.5, 0.75 each from the linear blend (no previous step);
//! - build: springs, anchor placement in the bent target, ordering and symbolic analysis.
//!
//! `cargo bench --bench massspring [-- NAME]` (rows whose name contains NAME). The load average
//! is printed with every row: the machine is shared, and timings are only as good as that
//! number. `BLENDSIM_BENCH_DETAIL=1` prints every step's work (Newton and CG iterations,
//! factorization and solve seconds) on stderr.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;
use std::time::Instant;

use blendsim::algorithms::geometry::{Point, TetMesh, TriMesh};
use blendsim::algorithms::massspring::{Blend, Boundary, MassSpring, Settings, Targets};
use blendsim::formats::tetgen::{run as tetgen, TetgenOptions};

struct Row {
    name: &'static str,
    /// The paper's counts and seconds per step.
    verts: usize,
    springs: usize,
    cpu: f64,
    gpu: f64,
    /// The stand-in: boxes in units of 0.1, cells per unit, TetGen quality and maximum volume
    /// (0 = none), and the motion: the part beyond `start` along axis `along` bends by 90°
    /// over `length` towards axis `towards`, about the centre line `line`.
    boxes: &'static [([i32; 3], [i32; 3])],
    cells: i32,
    quality: f64,
    max_volume: f64,
    along: usize,
    towards: usize,
    start: f64,
    length: f64,
    line: f64,
}

/// Standing figure (y up): two legs, torso, arms out, head; bends forward at the hips.
const MAN: &[([i32; 3], [i32; 3])] = &[
    ([1, 0, 0], [2, 5, 1]),
    ([3, 0, 0], [4, 5, 1]),
    ([1, 5, 0], [4, 9, 1]),
    ([-3, 8, 0], [1, 9, 1]),
    ([4, 8, 0], [8, 9, 1]),
    ([2, 9, 0], [3, 11, 1]),
];
/// A head-sized slab with a nose (towards -z); the upper part bends back.
const FACE: &[([i32; 3], [i32; 3])] = &[([0, 0, 0], [8, 10, 4]), ([3, 4, -2], [5, 6, 0])];
/// Body on four legs with a head and a tail (y forward, z up); the front half turns sideways.
const CAT: &[([i32; 3], [i32; 3])] = &[
    ([0, 0, 2], [3, 8, 5]),
    ([0, 0, 0], [1, 1, 2]),
    ([2, 0, 0], [3, 1, 2]),
    ([0, 7, 0], [1, 8, 2]),
    ([2, 7, 0], [3, 8, 2]),
    ([0, 8, 3], [3, 10, 6]),
    ([1, -4, 4], [2, 0, 5]),
];
/// Longer legs, a neck and a head.
const HORSE: &[([i32; 3], [i32; 3])] = &[
    ([0, 0, 4], [3, 9, 7]),
    ([0, 0, 0], [1, 1, 4]),
    ([2, 0, 0], [3, 1, 4]),
    ([0, 8, 0], [1, 9, 4]),
    ([2, 8, 0], [3, 9, 4]),
    ([1, 8, 7], [2, 9, 10]),
    ([1, 8, 10], [2, 11, 11]),
    ([1, -3, 6], [2, 0, 7]),
];
/// Palm, four fingers and a thumb (palm in the xy plane); the fingers curl over the palm.
const HAND: &[([i32; 3], [i32; 3])] = &[
    ([0, 0, 0], [11, 10, 3]),
    ([0, 10, 0], [2, 18, 2]),
    ([3, 10, 0], [5, 19, 2]),
    ([6, 10, 0], [8, 18, 2]),
    ([9, 10, 0], [11, 16, 2]),
    ([-4, 2, 0], [0, 4, 2]),
];

const ROWS: [Row; 5] = [
    Row {
        name: "Man",
        verts: 2_200,
        springs: 21_600,
        cpu: 2.23,
        gpu: 3.62,
        boxes: MAN,
        cells: 4,
        quality: 1.414,
        max_volume: 1.2e-5,
        along: 1,
        towards: 2,
        start: 0.5,
        length: 0.2,
        line: 0.05,
    },
    Row {
        name: "Face",
        verts: 8_100,
        springs: 65_100,
        cpu: 40.11,
        gpu: 3.67,
        boxes: FACE,
        cells: 3,
        quality: 1.414,
        max_volume: 1.5e-5,
        along: 1,
        towards: 2,
        start: 0.3,
        length: 0.7,
        line: 0.2,
    },
    Row {
        name: "Cat",
        verts: 7_300,
        springs: 81_700,
        cpu: 67.58,
        gpu: 13.67,
        boxes: CAT,
        cells: 6,
        quality: 2.6,
        max_volume: 0.0,
        along: 1,
        towards: 0,
        start: 0.2,
        length: 0.5,
        line: 0.15,
    },
    Row {
        name: "Horse",
        verts: 8_500,
        springs: 96_100,
        cpu: 81.36,
        gpu: 15.95,
        boxes: HORSE,
        cells: 6,
        quality: 2.7,
        max_volume: 0.0,
        along: 1,
        towards: 0,
        start: 0.2,
        length: 0.5,
        line: 0.15,
    },
    Row {
        name: "Hand",
        verts: 18_600,
        springs: 150_400,
        cpu: 153.99,
        gpu: 26.28,
        boxes: HAND,
        cells: 3,
        quality: 1.414,
        max_volume: 8.3e-6,
        along: 1,
        towards: 2,
        start: 1.0,
        length: 0.4,
        line: 0.1,
    },
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

/// Seconds of CPU this process has used (user + system, all threads): what the work costs
/// whatever else the machine runs (wall-clock seconds grow with the load average on a shared
/// machine; CPU seconds do not, and for one thread they are the wall time on an idle core).
fn cpu_seconds() -> f64 {
    // SAFETY: getrusage only writes the struct it is given.
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    if unsafe { libc::getrusage(libc::RUSAGE_SELF, &mut usage) } != 0 {
        return f64::NAN;
    }
    let seconds = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 * 1e-6;
    seconds(usage.ru_utime) + seconds(usage.ru_stime)
}

fn load_average() -> String {
    std::fs::read_to_string("/proc/loadavg").map(|s| s.split_whitespace().take(3).collect::<Vec<_>>().join(" ")).unwrap_or_else(|_| "?".into())
}

/// A closed surface made of axis-aligned boxes (integer unit coordinates, `[lo, hi)`), sampled
/// at `m` cells per unit and scaled by `unit`: the boundary faces of the filled cells, each
/// split into two triangles, wound outward. Boxes meet face to face (never only along an edge
/// or at a corner), so the surface is a closed 2-manifold (checked).
fn figure(boxes: &[([i32; 3], [i32; 3])], m: i32, unit: f64) -> TriMesh {
    let mut cells = BTreeSet::new();
    for (lo, hi) in boxes {
        for x in lo[0] * m..hi[0] * m {
            for y in lo[1] * m..hi[1] * m {
                for z in lo[2] * m..hi[2] * m {
                    cells.insert([x, y, z]);
                }
            }
        }
    }
    let mut index: BTreeMap<[i32; 3], u32> = BTreeMap::new();
    let mut positions = Vec::new();
    let mut vertex = |c: [i32; 3]| {
        *index.entry(c).or_insert_with(|| {
            positions.push(c.map(|v| v as f64 * unit / m as f64));
            positions.len() as u32 - 1
        })
    };
    let mut triangles = Vec::new();
    for cell in &cells {
        for a in 0..3 {
            // (u, v, a) is right-handed: a quad counter-clockwise in (u, v) faces +a.
            let (u, v) = ((a + 1) % 3, (a + 2) % 3);
            for side in [0, 1] {
                let mut neighbour = *cell;
                neighbour[a] += if side == 1 { 1 } else { -1 };
                if cells.contains(&neighbour) {
                    continue;
                }
                let corner = |du: i32, dv: i32| {
                    let mut c = *cell;
                    c[a] += side;
                    c[u] += du;
                    c[v] += dv;
                    c
                };
                let q = [corner(0, 0), corner(1, 0), corner(1, 1), corner(0, 1)].map(&mut vertex);
                if side == 1 {
                    triangles.extend([[q[0], q[1], q[2]], [q[0], q[2], q[3]]]);
                } else {
                    triangles.extend([[q[0], q[2], q[1]], [q[0], q[3], q[2]]]);
                }
            }
        }
    }
    let mesh = TriMesh { positions, triangles, attributes: None };
    let mut edges: Vec<[u32; 2]> =
        mesh.triangles.iter().flat_map(|t| (0..3).map(move |k| [t[k].min(t[(k + 1) % 3]), t[k].max(t[(k + 1) % 3])])).collect();
    edges.sort_unstable();
    assert!(edges.chunk_by(|a, b| a == b).all(|g| g.len() == 2), "a closed 2-manifold figure");
    mesh
}

/// Bend the part of `points` beyond the plane `p[along] = start` about an axis parallel to
/// the third coordinate: over `length` along `along` the part curves into an arc of `angle`
/// radians towards `towards`, the rest turning rigidly with the arc's end. The arc's centre
/// line runs at `p[towards] = line`, which keeps its length; the volume is kept (Pappus).
fn bend(points: &[Point], along: usize, towards: usize, start: f64, length: f64, angle: f64, line: f64) -> Vec<Point> {
    let radius = length / angle;
    let centre = line + radius;
    points
        .iter()
        .map(|p| {
            let s = p[along] - start;
            if s <= 0.0 {
                return *p;
            }
            let (phi, beyond) = if s <= length { (angle * s / length, 0.0) } else { (angle, s - length) };
            let rho = centre - p[towards];
            let mut q = *p;
            // On the arc, then straight along its end tangent.
            q[towards] = centre - rho * phi.cos() + beyond * phi.sin();
            q[along] = start + rho * phi.sin() + beyond * phi.cos();
            q
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
    println!("| shape | n_v paper / ours | n_s paper / ours | paper CPU | paper GPU | ours warm (median / mean) | vs CPU | ours warm CPU s (median) | vs CPU | per step: Newton / factor. / CG | ours cold (median) | build | factor nnz | load |");
    println!("|---|---|---|---:|---:|---:|---:|---:|---:|---|---:|---:|---:|---|");
    for row in ROWS.iter().filter(|r| filter.as_deref().is_none_or(|f| r.name.to_lowercase().contains(&f.to_lowercase()))) {
        let surface = figure(row.boxes, row.cells, 0.1);
        let options = TetgenOptions { quality: row.quality, max_volume: row.max_volume, timeout: 300.0 };
        let body: TetMesh = tetgen(&surface, &options, Path::new(row.name)).expect("tetgen");
        let bent = bend(&surface.positions, row.along, row.towards, row.start, row.length, std::f64::consts::FRAC_PI_2, row.line);
        let targets = vec![surface.positions.clone(), bent];
        let t = Targets { surface: &targets, triangles: &surface.triangles, body: Some(&body), body_poses: None };
        let settings = Settings::default();
        let t0 = Instant::now();
        let mut model = MassSpring::new(&t, &Boundary::Anchor(None), &settings).expect("model");
        let build = t0.elapsed().as_secs_f64();
        let summary = model.summary().clone();
        if std::env::var_os("BLENDSIM_BENCH_DETAIL").is_some() {
            eprintln!("{}: {summary:?}", row.name);
        }
        let n_v = summary.surface_vertices + summary.interior_vertices + summary.anchor_points;
        let alphas: Vec<f64> = (0..36).map(|k| k as f64 / 35.0).collect();
        let mut warm = Vec::new();
        let mut warm_cpu = Vec::new();
        let mut iterations = Vec::new();
        let (mut factorizations, mut cg) = (0usize, 0usize);
        let mut shapes = Vec::new();
        for (k, &a) in alphas.iter().enumerate() {
            let (t1, c1) = (Instant::now(), cpu_seconds());
            let shape = model.blend(&[1.0 - a, a], &[]).expect("blend");
            if k > 0 {
                warm.push(t1.elapsed().as_secs_f64());
                warm_cpu.push(cpu_seconds() - c1);
                iterations.push(shape.report.iterations as f64);
                factorizations += shape.report.work.factorizations;
                cg += shape.report.work.cg_iterations;
                if std::env::var_os("BLENDSIM_BENCH_DETAIL").is_some() {
                    let w = &shape.report.work;
                    eprintln!(
                        "step {k}: newton {} fact {} cg {} factor {:.3} solve {:.3} total {:.3} wall {:.3} F/S {:.1}",
                        shape.report.iterations,
                        w.factorizations,
                        w.cg_iterations,
                        w.factor_seconds,
                        w.solve_seconds,
                        w.seconds,
                        shape.report.seconds,
                        if w.factorizations > 0 {
                            (w.factor_seconds / w.factorizations as f64) / (w.solve_seconds / w.cg_iterations as f64)
                        } else {
                            0.0
                        }
                    );
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
        // Same bytes again, on a row factorized on one thread (Man) and one on two (Cat: faer's
        // parallel supernodal factorization above 1 G flops); a second pass costs a first.
        let same = if row.name == "Man" || row.name == "Cat" {
            let mut again = MassSpring::new(&t, &Boundary::Anchor(None), &settings).expect("model");
            let shapes2: Vec<Blend> = alphas.iter().map(|&a| again.blend(&[1.0 - a, a], &[]).expect("blend")).collect();
            if checksum(&shapes) == checksum(&shapes2) {
                " (same bytes twice)"
            } else {
                " (BYTES DIFFER)"
            }
        } else {
            ""
        };
        let warm_median = median(warm.clone());
        let warm_mean = warm.iter().sum::<f64>() / warm.len() as f64;
        println!(
            "| {}{same} | {} / {} | {} / {} | {:.2} s | {:.2} s | {:.3} / {:.3} s | {:.0}x | {:.3} s | {:.0}x | {:.1} / {:.2} / {:.1} | {:.3} s | {:.2} s | {:.1}M ({}) | {} |",
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
            median(warm_cpu.clone()),
            row.cpu / median(warm_cpu.clone()),
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
