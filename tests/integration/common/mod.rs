//! Shared helpers for integration tests: scratch folders, synthetic animations, and the
//! independent checkers (`checkers`). Each test file uses only part of it.
#![allow(dead_code)]

pub mod assets;
pub mod bar;
pub mod checkers;
pub mod cli;
pub mod verify;

use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};

use blendsim::algorithms::geometry::{Point, TriMesh};
use blendsim::algorithms::spacetime::trajectory::Trajectory;
use blendsim::pipeline::scene::{Method, Scene};
use blendsim::pipeline::stage_file::{Animation, Counts, SolverLog};

/// A fresh, empty folder under Cargo's per-target scratch space, kept after the test so its
/// files can be inspected.
pub fn scratch(name: &str) -> PathBuf {
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!("{name}-{}-{}", std::process::id(), COUNTER.fetch_add(1, Ordering::Relaxed)));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Keys of an analytic motion `x(p, t)` with its exact time derivative, so the trajectory has
/// real (nonzero) velocities.
pub fn sample_motion(rest: &[Point], times: &[f64], motion: impl Fn(Point, f64) -> (Point, Point)) -> Trajectory {
    let (mut positions, mut velocities) = (Vec::new(), Vec::new());
    for &t in times {
        let (x, v): (Vec<Point>, Vec<Point>) = rest.iter().map(|&p| motion(p, t)).unzip();
        positions.push(x);
        velocities.push(v);
    }
    Trajectory { times: times.to_vec(), positions, velocities }
}

/// An `Animation` as `blendsim embed` would hand it to `export`, with a scene built from
/// `name`, `fps`, the trajectory's key times and the `[export]` table given as TOML lines.
pub fn animation(name: &str, fps: f64, mesh: TriMesh, trajectory: Trajectory, cyclic: bool, export_toml: &str) -> Animation {
    let keys = trajectory.key_count();
    let meshes = vec!["\"k.obj\""; keys].join(", ");
    let times: Vec<String> = trajectory.times.iter().map(|t| format!("{t:?}")).collect();
    let text = format!(
        "name = \"{name}\"\nfps = {fps:?}\n[keyframes]\nmeshes = [{meshes}]\ntimes = [{}]\ncyclic = {cyclic}\n[export]\n{export_toml}\n",
        times.join(", ")
    );
    let scene = Scene::parse(&text).unwrap_or_else(|e| panic!("test scene does not parse: {e}\n{text}"));
    Animation {
        scene,
        counts: Counts {
            vertices: mesh.positions.len(),
            faces: mesh.triangles.len(),
            tet_nodes: 0,
            tets: 0,
            keyframes: keys,
            largest_tet_volume: None,
        },
        input_keys: trajectory.positions.clone(),
        mesh,
        trajectory,
        log: SolverLog::closed_form(Method::Hermite, Vec::new(), 0.0, 0, "synthetic test animation".into(), Vec::new()),
        cache: None,
        cage: None,
        warnings: Vec::new(),
        input_bytes: 0,
        weld: None,
    }
}
