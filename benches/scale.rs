//! Production-size bakes through the CLI, as a user runs them: each scene is generated into a
//! scratch folder (procedural prisms, twisted and bent, keyframes as OBJ surfaces) and baked by
//! the `blendsim` binary under `/usr/bin/time -v`. Printed per scene: surface vertices, body
//! nodes (cage or TetGen), keys, the global step's solver (direct or iterative) and ordering,
//! bake seconds, whole-process peak memory, the cage's key reproduction error and the
//! in-between volume loss. Medians of `SCALE_REPEATS` runs (default 1: these are long).
//!
//! `cargo bench --bench scale` (or `make bench-scale`); `cargo bench --bench scale -- 100k`
//! runs only the scenes whose name contains an argument. `SCALE_KEEP=1` keeps the generated
//! scenes and outputs (their folder is printed) for profiling a bake by hand.
//!
//! The rows answer the targets of the issue on production meshes: a 100k-vertex surface with
//! 10 keys (under 60 s and 4 GB on 2 cores, embedded keys within 1% of the bbox diagonal), the
//! 20-key 2.6k-node body (under 20 s and 3 GB), and the CHEB-style check (a 6.8k-vertex surface
//! on a ~1k-node cage against the same scene on the full surface: in-between volume within one
//! percentage point).

use std::path::{Path, PathBuf};
use std::process::Command;

use blendsim::mesh::{obj, Axis, Point, TriMesh};
use blendsim::procedural::{prism, twist, Twist};

fn load() -> String {
    std::fs::read_to_string("/proc/loadavg").map(|l| l.split_whitespace().take(3).collect::<Vec<_>>().join(" ")).unwrap_or_default()
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Twist about y by `degrees` and bend about z by `bend` radians over the height.
fn pose(rest: &[Point], degrees: f64, bend: f64) -> Vec<Point> {
    let height = rest.iter().map(|p| p[1]).fold(0.0, f64::max);
    twist(rest, &Twist { axis: Axis::Y, degrees, axial_scale: 1.0 })
        .into_iter()
        .map(|[x, y, z]| {
            let (s, c) = (bend * y / height).sin_cos();
            [c * x - s * y, s * x + c * y, z]
        })
        .collect()
}

struct Case {
    name: &'static str,
    /// Prism size and divisions of the surface.
    size: [f64; 3],
    divisions: [usize; 3],
    keys: usize,
    /// Lines of the `[tet]` table.
    tet: &'static str,
    /// Lines of the `[solver]` table.
    solver: &'static str,
    /// Faces held at every key besides the default (`fixed` not given: the whole surface):
    /// `Some(&[0.0])` the bottom face, `Some(&[0.0, 1.0])` the bottom and top faces (y as a
    /// fraction of the height). Holding the bottom alone leaves every other vertex of every
    /// key free, so W's minimizer is the body at rest (W and S both 0) and the solve never
    /// meets the stopping rule: not a keyframe bake.
    hold: Option<&'static [f64]>,
    /// Extra `bake` arguments.
    args: &'static [&'static str],
}

/// Write the scene of `case` into `dir`; returns the scene file.
fn write_scene(case: &Case, dir: &Path) -> PathBuf {
    std::fs::create_dir_all(dir).unwrap();
    let rest: TriMesh = prism(case.size, case.divisions);
    let mut meshes = Vec::new();
    for k in 0..case.keys {
        let phase = 2.0 * std::f64::consts::PI * k as f64 / (case.keys - 1) as f64;
        let mut m = rest.clone();
        m.positions = pose(&rest.positions, 90.0 * phase.sin(), 0.4 * (phase + 1.0).sin() - 0.4 * 1f64.sin());
        let name = format!("k{k}.obj");
        std::fs::write(dir.join(&name), obj::write(&m)).unwrap();
        meshes.push(format!("\"{name}\""));
    }
    let times: Vec<String> = (0..case.keys).map(|k| format!("{:.1}", 0.5 * k as f64)).collect();
    let mut text = format!(
        "name = \"{}\"\nfps = 30\n[keyframes]\nmeshes = [{}]\ntimes = [{}]\n",
        case.name,
        meshes.join(", "),
        times.join(", ")
    );
    if let Some(faces) = case.hold {
        let held: String = rest.positions.iter().enumerate().filter(|(_, p)| faces.iter().any(|&f| (p[1] - f * case.size[1]).abs() <= 1e-9 * case.size[1])).map(|(i, _)| format!("{i}\n")).collect();
        std::fs::write(dir.join("held.txt"), held).unwrap();
        text.push_str(&format!("fixed = [{}]\n", vec!["\"held.txt\""; case.keys].join(", ")));
    }
    if !case.solver.is_empty() {
        text.push_str(&format!("[solver]\n{}\n", case.solver));
    }
    text.push_str(&format!("[tet]\n{}\n[export]\nformats = [\"usdc\", \"glb\"]\nfull_frame = false\n", case.tet));
    let scene = dir.join("scene.toml");
    std::fs::write(&scene, text).unwrap();
    scene
}

/// Bake `scene` under `/usr/bin/time -v`: (seconds, peak KiB of the process tree, report, CPU
/// seconds (user + system)).
fn bake(scene: &Path, out: &Path, args: &[&str]) -> (f64, u64, serde_json::Value, f64) {
    let output = Command::new("/usr/bin/time")
        .arg("-v")
        .arg(env!("CARGO_BIN_EXE_blendsim"))
        .args(["bake", "-q", scene.to_str().unwrap(), "--out", out.to_str().unwrap()])
        .args(args)
        .output()
        .expect("run /usr/bin/time (apt-get install time)");
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "{} failed:\n{stderr}", scene.display());
    let field = |name: &str| stderr.lines().find_map(|l| l.trim().strip_prefix(name).map(str::to_string)).unwrap_or_default();
    let peak: u64 = field("Maximum resident set size (kbytes): ").parse().unwrap();
    let wall = field("Elapsed (wall clock) time (h:mm:ss or m:ss): ");
    let seconds = wall.split(':').fold(0.0, |acc, part| acc * 60.0 + part.parse::<f64>().unwrap());
    let report: serde_json::Value = serde_json::from_slice(&std::fs::read(out.join("report.json")).unwrap()).unwrap();
    let cpu = ["User time (seconds): ", "System time (seconds): "].iter().map(|f| field(f).parse::<f64>().unwrap_or(0.0)).sum();
    (seconds, peak, report, cpu)
}

/// The global step's solver, with the CG solves and their mean iterations when iterative.
fn global_step(solver: &serde_json::Value) -> String {
    let name = format!("{}, {} iterations", solver["linear_solver"].as_str().unwrap_or("-"), solver["iterations"]);
    let cg = &solver["conjugate_gradients"];
    match (cg["solves"].as_u64(), cg["iterations"].as_u64()) {
        (Some(solves), Some(iterations)) if solves > 0 => {
            let capped = cg["capped"].as_u64().unwrap_or(0);
            format!("{name} ({solves} CG solves x {:.0} iterations{})", iterations as f64 / solves as f64, if capped > 0 { format!(", {capped} capped") } else { String::new() })
        }
        _ => name,
    }
}

fn main() {
    let filters: Vec<String> = std::env::args().skip(1).filter(|a| !a.starts_with('-')).collect();
    let keep = std::env::var_os("SCALE_KEEP").is_some_and(|v| v != "0");
    let repeats: usize = std::env::var("SCALE_REPEATS").ok().and_then(|v| v.parse().ok()).unwrap_or(1);
    let cases = [
        // The benchmark's ARMADILLO-size body (2645 TetGen nodes) with 20 keys, its bottom and top
        // faces held at every key (the rest of the body free): the global step the cost model
        // chooses, then each of the other two forced.
        Case { name: "2.6k-nodes-20-keys", size: [1.2, 3.6, 1.2], divisions: [12, 36, 12], keys: 20, tet: "max_volume = 0.003", solver: "", hold: Some(&[0.0, 1.0]), args: &[] },
        Case {
            name: "2.6k-nodes-20-keys-direct",
            size: [1.2, 3.6, 1.2],
            divisions: [12, 36, 12],
            keys: 20,
            tet: "max_volume = 0.003",
            solver: "global_step = \"direct\"",
            hold: Some(&[0.0, 1.0]),
            args: &[],
        },
        Case {
            name: "2.6k-nodes-20-keys-iterative-2G",
            size: [1.2, 3.6, 1.2],
            divisions: [12, 36, 12],
            keys: 20,
            tet: "max_volume = 0.003",
            solver: "global_step = \"iterative\"",
            hold: Some(&[0.0, 1.0]),
            args: &["--max-memory", "2G"],
        },
        // The coarse-to-fine schedule on the same body (`[solver] coarse_samples`: README).
        Case {
            name: "2.6k-nodes-20-keys-coarse",
            size: [1.2, 3.6, 1.2],
            divisions: [12, 36, 12],
            keys: 20,
            tet: "max_volume = 0.003",
            solver: "coarse_samples = 5",
            hold: Some(&[0.0, 1.0]),
            args: &[],
        },
        Case { name: "2.6k-nodes-5-keys", size: [1.2, 3.6, 1.2], divisions: [12, 36, 12], keys: 5, tet: "max_volume = 0.003", solver: "", hold: Some(&[0.0, 1.0]), args: &[] },
        // CHEB-style: 6.8k surface vertices, on a ~1k-node cage and on the full surface.
        Case { name: "6.8k-cage", size: [1.0, 3.0, 1.0], divisions: [22, 66, 22], keys: 5, tet: "max_nodes = 3000", solver: "", hold: Some(&[0.0, 1.0]), args: &[] },
        Case { name: "6.8k-full", size: [1.0, 3.0, 1.0], divisions: [22, 66, 22], keys: 5, tet: "cage = false", solver: "", hold: Some(&[0.0, 1.0]), args: &[] },
        Case { name: "25k-cage", size: [1.0, 3.0, 1.0], divisions: [42, 130, 42], keys: 10, tet: "", solver: "", hold: None, args: &[] },
        Case { name: "100k-cage", size: [1.0, 3.0, 1.0], divisions: [85, 260, 85], keys: 10, tet: "", solver: "", hold: None, args: &[] },
    ];
    let scratch = std::env::temp_dir().join(format!("blendsim-bench-scale-{}", std::process::id()));
    println!("machine: {} threads, load average {}", std::thread::available_parallelism().map_or(0, |n| n.get()), load());
    println!();
    println!("| scene | surface vertices | body nodes | cage | keys | global step | bake s | CPU s | peak MB | cage key error max | in-between volume loss | load |");
    println!("|---|---:|---:|---|---:|---|---:|---:|---:|---:|---:|---|");
    for case in cases.iter().filter(|c| filters.is_empty() || filters.iter().any(|f| c.name.contains(f.as_str()))) {
        let dir = scratch.join(case.name);
        let scene = write_scene(case, &dir);
        let runs: Vec<(f64, u64, serde_json::Value, f64)> = (0..repeats).map(|r| bake(&scene, &dir.join(format!("out{r}")), case.args)).collect();
        let seconds = median(runs.iter().map(|r| r.0).collect());
        let peak = median(runs.iter().map(|r| r.1 as f64).collect());
        let cpu = median(runs.iter().map(|r| r.3).collect());
        let report = &runs[0].2;
        let cage = &report["cage"];
        let (cage_text, key_error) = if cage.is_null() {
            ("no".to_string(), "-".to_string())
        } else {
            (format!("{} nodes", cage["nodes"]), format!("{:.2}%", 100.0 * cage["key_error_max"].as_f64().unwrap()))
        };
        let loss = report["volume"]["animation"]["in_between_loss"].as_f64().map_or("-".into(), |l| format!("{:.2}%", 100.0 * l));
        println!(
            "| {} | {} | {} | {} | {} | {} | {:.1} | {:.1} | {:.0} | {} | {} | {} |",
            case.name,
            report["vertices"],
            report["tet_nodes"],
            cage_text,
            case.keys,
            global_step(&report["solver"]),
            seconds,
            cpu,
            peak / 1024.0,
            key_error,
            loss,
            load()
        );
        if !keep {
            let _ = std::fs::remove_dir_all(&dir);
        }
    }
    if keep {
        println!("\nscenes kept in {}", scratch.display());
    } else {
        let _ = std::fs::remove_dir_all(&scratch);
    }
}
