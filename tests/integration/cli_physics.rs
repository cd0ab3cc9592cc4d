//! The solver's analytic cases through the CLI, as a user runs it: tet-mesh keyframes written
//! as MEDIT files, `import -> tetrahedralize -> solve`, and the solution stage file read back.

use blendsim::algorithms::geometry::Point;
use blendsim::algorithms::spacetime::trajectory::Trajectory;
use blendsim::pipeline::stage_file::{self, Solution};

use crate::common::cli::{read_json, run, TempDir};

/// MEDIT text of a cube `[0,1]³` split into `n³` cells of 6 tets, its nodes moved by `place`.
pub(crate) fn cube_medit(n: usize, place: impl Fn(Point) -> Point) -> String {
    let idx = |i: usize, j: usize, k: usize| i * (n + 1) * (n + 1) + j * (n + 1) + k + 1;
    let mut s = String::from("MeshVersionFormatted 1\nDimension 3\n");
    s += &format!("Vertices\n{}\n", (n + 1).pow(3));
    for i in 0..=n {
        for j in 0..=n {
            for k in 0..=n {
                let p = place([i as f64 / n as f64, j as f64 / n as f64, k as f64 / n as f64]);
                s += &format!("{} {} {} 0\n", p[0], p[1], p[2]);
            }
        }
    }
    s += &format!("Tetrahedra\n{}\n", 6 * n * n * n);
    for i in 0..n {
        for j in 0..n {
            for k in 0..n {
                for perm in [[0, 1, 2], [0, 2, 1], [1, 0, 2], [1, 2, 0], [2, 0, 1], [2, 1, 0]] {
                    let mut c = [i, j, k];
                    let mut v = vec![idx(c[0], c[1], c[2])];
                    for axis in perm {
                        c[axis] += 1;
                        v.push(idx(c[0], c[1], c[2]));
                    }
                    s += &format!("{} {} {} {} 0\n", v[0], v[1], v[2], v[3]);
                }
            }
        }
    }
    s + "End\n"
}

/// Write the scene and its meshes, run the first three stages, read the solution back.
pub(crate) fn solve_scene(dir: &TempDir, meshes: &[(&str, String)], scene: &str) -> Solution {
    for (name, text) in meshes {
        std::fs::write(dir.join(name), text).unwrap();
    }
    std::fs::write(dir.join("scene.toml"), scene).unwrap();
    run(&dir.path, &["import", "scene.toml", "-o", "keys.json"]).success();
    run(&dir.path, &["tetrahedralize", "keys.json", "-o", "body.json"]).success();
    run(&dir.path, &["solve", "body.json", "-o", "solution.json"]).success();
    stage_file::read(&dir.join("solution.json"), &blendsim::support::budget::Budget::default()).unwrap()
}

#[test]
fn free_fall_through_the_cli_is_an_exact_parabola() {
    // The first key is held; the second key's pose and both velocities are free. With gravity
    // and no damping, the optimum is a rigid fall: a parabola, which a cubic holds exactly.
    let dir = TempDir::new("physics-free-fall");
    let scene = r#"
name = "fall"
[keyframes]
meshes = ["cube.mesh", "cube.mesh"]
times = [0.0, 1.0]
fixed = ["all", "none"]
[material]
damping = 0.0
gravity = [0.0, -9.81, 0.0]
[solver]
samples = 6
regularization = 0.5
tolerance = 1e-13
max_iterations = 400
"#;
    let solution = solve_scene(&dir, &[("cube.mesh", cube_medit(2, |p| p))], scene);
    let w = &solution.log.energy;
    assert!(w.last().unwrap() < &(1e-12 * w[0]), "W {} -> {} ({})", w[0], w.last().unwrap(), solution.log.stop_reason);
    let tr: &Trajectory = &solution.trajectory;
    for k in 0..6 {
        let t = (k as f64 + 0.5) / 6.0;
        for a in tr.acceleration(t) {
            let error = ((a[0]).powi(2) + (a[1] + 9.81).powi(2) + a[2].powi(2)).sqrt();
            assert!(error < 1e-6 * 9.81, "acceleration {a:?} at t = {t}");
        }
    }
    // Every node falls the same way: the body stays rigid.
    let drop: Vec<f64> = tr.positions[1].iter().zip(&tr.positions[0]).map(|(p, q)| p[1] - q[1]).collect();
    assert!(drop.iter().all(|d| (d - drop[0]).abs() < 1e-6), "{drop:?}");
}

#[test]
fn rigidly_placed_keys_cost_nothing() {
    // Every key is the same rotated and translated cube: no elastic force, no motion, W = 0,
    // for the hermite baseline and the spacetime solver alike.
    let dir = TempDir::new("physics-rigid");
    let (s, c) = 0.9f64.sin_cos();
    let placed = cube_medit(2, |p| [c * p[0] + s * p[2] + 3.0, p[1] - 1.0, -s * p[0] + c * p[2] + 0.5]);
    let scene = r#"
name = "rigid"
[keyframes]
meshes = ["placed.mesh", "placed.mesh", "placed.mesh"]
times = [0.0, 0.4, 1.0]
rest = "rest.mesh"
fixed = ["all", "none", "all"]
"#;
    let meshes = [("placed.mesh", placed), ("rest.mesh", cube_medit(2, |p| p))];
    let solution = solve_scene(&dir, &meshes, scene);
    assert!(solution.log.energy[0] < 1e-20, "W = {:?}", solution.log.energy);
    run(&dir.path, &["solve", "body.json", "-o", "hermite.json", "--method", "hermite"]).success();
    let hermite = read_json(&dir.join("hermite.json"));
    let w = hermite["data"]["log"]["energy"][0].as_f64().unwrap();
    assert!(w < 1e-20, "hermite W = {w}");
}

#[test]
fn regularization_makes_an_unconstrained_scene_well_posed() {
    // Nothing is held: without regularization the body may drift for free and the system is
    // singular (a clear error); with it, the solve goes through and lowers W.
    let dir = TempDir::new("physics-unconstrained");
    let bent = cube_medit(2, |p| [p[0] + 0.2 * (3.0 * p[1]).sin(), p[1], p[2]]);
    let scene = |h: f64| {
        format!(
            "name = \"free\"\n[keyframes]\nmeshes = [\"rest.mesh\", \"bent.mesh\", \"rest.mesh\"]\ntimes = [0.0, 0.5, 1.0]\n\
             fixed = [\"none\", \"none\", \"none\"]\n[solver]\nregularization = {h}\n"
        )
    };
    let meshes = [("rest.mesh", cube_medit(2, |p| p)), ("bent.mesh", bent)];
    let solution = solve_scene(&dir, &meshes, &scene(0.1));
    let w = &solution.log.energy;
    assert!(w.len() > 1 && w.last().unwrap() < &(0.5 * w[0]), "{w:?}");

    std::fs::write(dir.join("scene.toml"), scene(0.0)).unwrap();
    run(&dir.path, &["import", "scene.toml", "-o", "keys0.json"]).success();
    run(&dir.path, &["tetrahedralize", "keys0.json", "-o", "body0.json"]).success();
    let failed = run(&dir.path, &["solve", "body0.json", "-o", "solution0.json"]);
    assert_eq!(failed.code, Some(1), "{failed}");
    assert!(failed.stderr.contains("singular") && failed.stderr.contains("regularization"), "{failed}");
    assert_eq!(failed.stderr.lines().count(), 1, "{failed}");
    assert!(!dir.join("solution0.json").exists());
}
