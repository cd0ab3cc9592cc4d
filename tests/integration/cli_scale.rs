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

/// The demo's folder copied to `dir`, its OBJ keys and `max_volume` in a unit of `1/s` meters
/// (coordinates times `s`), saying so with `units` (`None`: left as it is).
fn write_demo_in_unit(dir: &TempDir, s: Option<f64>) {
    let demo = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/demo");
    let s_or_1 = s.unwrap_or(1.0);
    for entry in std::fs::read_dir(&demo).unwrap() {
        let path = entry.unwrap().path();
        let to = dir.join(path.file_name().unwrap());
        if path.extension().is_some_and(|e| e == "obj") {
            let mut mesh = obj::read(&path).unwrap();
            mesh.positions.iter_mut().for_each(|p| *p = p.map(|c| c * s_or_1));
            std::fs::write(to, obj::write(&mesh)).unwrap();
        } else {
            std::fs::copy(&path, to).unwrap();
        }
    }
    let scene = std::fs::read_to_string(demo.join("twist.toml")).unwrap();
    assert!(scene.contains("max_volume = 0.005\n") && scene.contains("fps = 60\n"), "the demo scene changed: update this test");
    let scene = scene.replace("max_volume = 0.005\n", &format!("max_volume = {:e}\n", 0.005 * s_or_1.powi(3)));
    let scene = match s {
        Some(s) => scene.replace("fps = 60\n", &format!("fps = 60\nunits = {:e}\n", 1.0 / s)),
        None => scene,
    };
    std::fs::write(dir.join("twist.toml"), scene).unwrap();
}

/// The demo's tet body (as TetGen made it in meters) with its five keys as MEDIT files, in a
/// unit of `1/s` meters: TetGen's own choices are not scale-free to the last bit (the demo's
/// keys times 100 and back, 12 of 384 coordinates an ulp off, give it 734 tets, not 777), so
/// the conversion is measured on the same body at every unit.
fn write_demo_body_in_unit(dir: &TempDir, body: &blendsim::pipeline::stage_file::Body, s: Option<f64>) {
    write_demo_in_unit(dir, None);
    let tets = &body.mesh.as_ref().unwrap().tets;
    let s_or_1 = s.unwrap_or(1.0);
    for (k, pose) in body.keys.positions.iter().enumerate() {
        let mut text = format!("MeshVersionFormatted 1\nDimension 3\nVertices\n{}\n", pose.len());
        pose.iter().for_each(|p| text += &format!("{:?} {:?} {:?} 0\n", p[0] * s_or_1, p[1] * s_or_1, p[2] * s_or_1));
        text += &format!("Tetrahedra\n{}\n", tets.len());
        tets.iter().for_each(|t| text += &format!("{} {} {} {} 0\n", t[0] + 1, t[1] + 1, t[2] + 1, t[3] + 1));
        std::fs::write(dir.join(format!("key_{k}.mesh")), text + "End\n").unwrap();
    }
    let scene = std::fs::read_to_string(dir.join("twist.toml")).unwrap();
    let meshes = "meshes = [\"key_0.mesh\", \"key_1.mesh\", \"key_2.mesh\", \"key_3.mesh\", \"key_4.mesh\"]\n";
    let scene = scene.lines().map(|l| if l.starts_with("meshes = ") { meshes.to_string() } else { format!("{l}\n") }).collect::<String>();
    let scene = match s {
        Some(s) => scene.replace("fps = 60\n", &format!("fps = 60\nunits = {:e}\n", 1.0 / s)),
        None => scene,
    };
    std::fs::write(dir.join("twist.toml"), scene).unwrap();
}

/// Bake the scene in `dir` and solve it through the subcommands: the report and the solution.
fn bake_demo(dir: &TempDir) -> (serde_json::Value, Solution) {
    run(&dir.path, &["bake", "-q", "twist.toml", "--out", "out"]).success();
    run(&dir.path, &["import", "-q", "twist.toml", "-o", "keys.json"]).success();
    run(&dir.path, &["tetrahedralize", "-q", "keys.json", "-o", "body.json"]).success();
    run(&dir.path, &["solve", "-q", "body.json", "-o", "solution.json"]).success();
    (read_json(&dir.join("out/report.json")), stage_file::read(&dir.join("solution.json"), &blendsim::support::budget::Budget::default()).unwrap())
}

#[test]
fn the_demo_in_any_unit_bakes_the_demo_scaled() {
    // The same physical scene measured in another unit: the material is converted to it, so
    // the result is the demo's times s (up to rounding), written with the unit as metadata.
    let obj_dir = TempDir::new("units-demo-obj");
    write_demo_in_unit(&obj_dir, None);
    let (_, obj_demo) = bake_demo(&obj_dir);
    let metres = TempDir::new("units-demo");
    write_demo_body_in_unit(&metres, &obj_demo.body, None);
    let (report, demo) = bake_demo(&metres);
    let diagonal = blendsim::algorithms::geometry::bbox_diagonal(&demo.trajectory.positions[0]);
    let mut table = vec![format!("{:>6} {:>10} {:>12}", "s", "iterations", "max |x/s-x1| / diagonal")];
    for s in [1e-3, 1e-2, 1e2, 1e3] {
        let dir = TempDir::new(&format!("units-demo-{s:e}"));
        write_demo_body_in_unit(&dir, &obj_demo.body, Some(s));
        let (scaled_report, scaled) = bake_demo(&dir);
        assert_eq!(scaled.log.iterations, demo.log.iterations, "s = {s:e}: {}", scaled.log.stop_reason);
        assert_eq!(scaled_report["solver"]["iterations"], report["solver"]["iterations"], "s = {s:e}");
        let mut worst = 0.0f64;
        for (a, b) in [(&scaled.trajectory.positions, &demo.trajectory.positions), (&scaled.trajectory.velocities, &demo.trajectory.velocities)] {
            for (pa, pb) in a.iter().flatten().zip(b.iter().flatten()) {
                (0..3).for_each(|d| worst = worst.max((pa[d] / s - pb[d]).abs()));
            }
        }
        // Rounding in the converted material and coordinates, carried through 117 iterations:
        // measured 4.1e-9 of the diagonal at most (s = 1e-3).
        table.push(format!("{s:>6.0e} {:>10} {:>12.1e}", scaled.log.iterations, worst / diagonal));
        assert!(worst <= 1e-8 * diagonal, "s = {s:e}: positions or velocities differ by {worst:e} of the demo's (diagonal {diagonal})");
        for figure in ["min", "max", "in_between_loss"] {
            let (a, b) = (scaled_report["volume"]["animation"][figure].as_f64().unwrap(), report["volume"]["animation"][figure].as_f64().unwrap());
            assert!((a - b).abs() <= 1e-9, "s = {s:e}: volume {figure} {a} against the demo's {b}");
        }
        assert!(scaled_report["warnings"].as_array().is_none_or(|w| w.is_empty()), "s = {s:e}: {}", scaled_report["warnings"]);
        let usda = std::fs::read_to_string(dir.join("out/twist.usda")).unwrap();
        assert!(usda.contains(&format!("metersPerUnit = {}\n", 1.0 / s)), "s = {s:e}: the USD file does not say its unit");
    }
    println!("{}", table.join("\n"));
}

#[test]
fn a_body_far_from_the_materials_size_is_warned_of() {
    // The demo's keys in centimeters with no unit: a 3.3 m body read as 330 m.
    let dir = TempDir::new("units-implausible");
    write_demo_in_unit(&dir, Some(100.0));
    let scene = std::fs::read_to_string(dir.join("twist.toml")).unwrap();
    std::fs::write(dir.join("twist.toml"), scene.replace("units = 1e-2\n", "")).unwrap();
    let r = run(&dir.path, &["bake", "-q", "twist.toml", "--out", "out"]);
    assert_eq!(r.code, Some(0), "{r}");
    let warning = "if the mesh is in cm, set units = \"cm\"";
    assert!(r.stderr.contains(warning), "{r}");
    let report = read_json(&dir.join("out/report.json"));
    assert!(report["warnings"].to_string().contains("over the 1e-3 to 20 m"), "{}", report["warnings"]);
    assert!(std::fs::read_to_string(dir.join("out/report.md")).unwrap().contains(warning), "report.md lacks the warning");
    // Said in centimeters, the same keys bake without the warning.
    write_demo_in_unit(&dir, Some(100.0));
    let r = run(&dir.path, &["bake", "-q", "twist.toml", "--out", "out2"]);
    assert!(!r.stderr.contains("the material is meant for"), "{r}");
}
