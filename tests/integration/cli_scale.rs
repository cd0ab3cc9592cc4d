//! Scale-free numerics through the CLI: the same box scene at every decade of size from 1e-9
//! to 1e9.
//!
//! A scene whose geometry and dimensional constants are converted to a length unit `1/s` is the
//! same physical scene: coordinates and `max_volume` scale by `s` and `s³`, stiffness (a
//! stress) by `1/s`, density by `1/s³`, gravity by `s`; times, damping and the regularization
//! time scale are unchanged. Its solution must be `s` times the unit one (positions and
//! velocities within 1e-6 of the bounding-box diagonal), with the same tet count, the same
//! iteration count, and `W` scaled by `s²` (a force² · time / mass). The geometry alone scaled
//! (a different physical scene: a tiny box is hugely stiff for its mass, a huge one floppy)
//! must still bake at every decade.

use blendsim::algorithms::geometry::TriMesh;
use blendsim::algorithms::procedural::prism;
use blendsim::formats::mesh::obj;
use blendsim::pipeline::stage_file::{self, Solution};

use crate::common::cli::{read_json, run, TempDir};

/// The decades of the sweep.
fn decades() -> Vec<f64> {
    (-9..=9).map(|e| 10f64.powi(e)).collect()
}

fn box_mesh(s: f64, stretch: f64) -> TriMesh {
    let mut mesh = prism([1.0, 1.0, 1.0], [2, 2, 2]);
    for p in &mut mesh.positions {
        *p = [p[0] * stretch * s, p[1] * s, p[2] * s];
    }
    mesh
}

/// A box stretched and released under gravity, the middle key free. With `physics`, the
/// material and gravity are converted to the unit of size `s` too.
fn write_scene(dir: &TempDir, s: f64, physics: bool, solver: &str) {
    std::fs::write(dir.join("rest.obj"), obj::write(&box_mesh(s, 1.0))).unwrap();
    std::fs::write(dir.join("long.obj"), obj::write(&box_mesh(s, 1.3))).unwrap();
    let (k, rho, g) = if physics { (70.0 / s, 1.0 / (s * s * s), -9.81 * s) } else { (70.0, 1.0, -9.81) };
    let scene = format!(
        "name = \"box\"\n[keyframes]\nmeshes = [\"rest.obj\", \"long.obj\", \"rest.obj\"]\ntimes = [0.0, 0.5, 1.0]\n\
         fixed = [\"all\", \"none\", \"all\"]\n[tet]\nmax_volume = {:e}\n[material]\nstiffness = {k:e}\nvolume = {k:e}\n\
         density = {rho:e}\ngravity = [0.0, {g:e}, 0.0]\n[solver]\nsamples = 4\n{solver}\n[export]\nformats = [\"usda\", \"glb\"]\n",
        0.05 * s * s * s
    );
    std::fs::write(dir.join("scene.toml"), scene).unwrap();
}

/// Bake the scene (the whole chain must succeed), and solve it through the subcommands.
fn bake_and_solve(dir: &TempDir) -> (serde_json::Value, Solution) {
    run(&dir.path, &["bake", "-q", "scene.toml", "--out", "out"]).success();
    run(&dir.path, &["import", "-q", "scene.toml", "-o", "keys.json"]).success();
    run(&dir.path, &["tetrahedralize", "-q", "keys.json", "-o", "body.json"]).success();
    run(&dir.path, &["solve", "-q", "body.json", "-o", "solution.json"]).success();
    (read_json(&dir.join("out/report.json")), stage_file::read(&dir.join("solution.json"), &blendsim::support::budget::Budget::default()).unwrap())
}

#[test]
fn a_scene_converted_to_any_unit_gives_the_scaled_result() {
    let unit_dir = TempDir::new("scale-unit");
    write_scene(&unit_dir, 1.0, true, "");
    let (unit_report, unit) = bake_and_solve(&unit_dir);
    let w0 = unit.log.energy[0];
    let diagonal = 3f64.sqrt() * 1.3;
    let mut table = vec![format!("{:>6} {:>5} {:>10} {:>12} {:>12}", "s", "tets", "iterations", "max |x/s-x1|", "W/s²/W1 - 1")];
    for s in decades() {
        let dir = TempDir::new(&format!("scale-{s:e}"));
        write_scene(&dir, s, true, "");
        let (report, scaled) = bake_and_solve(&dir);
        assert_eq!(tets(&scaled), tets(&unit), "s = {s:e}: TetGen made another body");
        assert_eq!(report["solver"]["iterations"], unit_report["solver"]["iterations"], "s = {s:e}: {}", report["solver"]["stop_reason"]);
        assert_eq!(scaled.log.iterations, unit.log.iterations, "s = {s:e}");
        let mut worst = 0.0f64;
        for (a, b) in [(&scaled.trajectory.positions, &unit.trajectory.positions), (&scaled.trajectory.velocities, &unit.trajectory.velocities)] {
            for (ka, kb) in a.iter().zip(b) {
                for (pa, pb) in ka.iter().zip(kb) {
                    for d in 0..3 {
                        worst = worst.max((pa[d] / s - pb[d]).abs());
                    }
                }
            }
        }
        let w = scaled.log.energy[0] / (s * s) / w0 - 1.0;
        table.push(format!("{s:>6.0e} {:>5} {:>10} {:>12.1e} {:>12.1e}", tets(&scaled), scaled.log.iterations, worst, w));
        assert!(worst <= 1e-6 * diagonal, "s = {s:e}: positions or velocities differ by {worst:e} of the unit result");
        assert!(w.abs() <= 1e-9, "s = {s:e}: W / s² differs from the unit W by {w:e}");
    }
    println!("{}", table.join("\n"));
}

#[test]
fn the_geometry_alone_scaled_bakes_at_every_decade() {
    // The default regularization's floor keeps the global step factorizable when the body is
    // 1e16 times stiffer than its inertia (see time_coefficients::PROXIMAL_FLOOR); a huge box is so
    // soft for its mass that the solver stops on max_iterations, which is a result, not an error.
    for s in decades() {
        let dir = TempDir::new(&format!("scale-geometry-{s:e}"));
        write_scene(&dir, s, false, "max_iterations = 40");
        let r = run(&dir.path, &["bake", "-q", "scene.toml", "--out", "out"]);
        assert_eq!(r.code, Some(0), "s = {s:e}: {r}");
        let report = read_json(&dir.join("out/report.json"));
        let w = report["solver"]["energy"].as_array().unwrap();
        assert!(w.iter().all(|w| w.as_f64().is_some_and(f64::is_finite)), "s = {s:e}: W {w:?}");
        assert!(report["solver"]["iterations"].as_u64().unwrap() > 0, "s = {s:e}: {}", report["solver"]["stop_reason"]);
    }
}

fn tets(solution: &Solution) -> usize {
    solution.body.mesh.as_ref().map_or(0, |m| m.tets.len())
}
