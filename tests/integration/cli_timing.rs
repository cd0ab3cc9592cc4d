//! Key-time optimization (`[solver] optimize_timing`) through the CLI: the elastic bar's
//! cyclic swing finds its natural period, and a ballistic jump with `keep_duration` finds the
//! parabola's key times. The exported files carry the optimized times.

use blendsim::internals::{natural_vibration, Elastic, ElasticMaterial, RestStiffness};
use blendsim::mesh::{Point, TetMesh};
use blendsim::stage::Solution;
use serde_json::Value;

use crate::common::bar::{bar, BarSettings};
use crate::cli_contacts::{bake_and_check, FALLING, FLOOR};
use crate::cli_physics::solve_scene;
use crate::common::cli::{energies, key_times, TempDir};
use crate::common::verify::max_distance;

/// MEDIT text of `mesh` with its nodes at `positions`.
fn medit(mesh: &TetMesh, positions: &[Point]) -> String {
    let mut s = format!("MeshVersionFormatted 1\nDimension 3\nVertices\n{}\n", positions.len());
    for p in positions {
        s += &format!("{:.17e} {:.17e} {:.17e} 0\n", p[0], p[1], p[2]);
    }
    s += &format!("Tetrahedra\n{}\n", mesh.tets.len());
    for t in &mesh.tets {
        s += &format!("{} {} {} {} 0\n", t[0] + 1, t[1] + 1, t[2] + 1, t[3] + 1);
    }
    s + "End\n"
}

/// The projective-dynamics constants with rapier's small-strain behaviour: the strain term
/// `½ k_s |F - R|²` linearizes to `(k_s / 2) |ε|²` and the volume term `½ k_v |F - P(F)|²` to
/// `(k_v / 6) (tr ε)²`, so `μ = k_s / 2` and `λ = k_v / 3`.
fn lame_to_pd(s: &BarSettings) -> ElasticMaterial {
    let (e, nu) = (s.young_modulus, s.poisson_ratio);
    let mu = e / (2.0 * (1.0 + nu));
    let lambda = e * nu / ((1.0 + nu) * (1.0 - 2.0 * nu));
    ElasticMaterial { stiffness: 2.0 * mu, volume: 3.0 * lambda, density: s.density }
}

/// The period of the tip's vertical swing in a simulated cache: the mean spacing of its
/// upward crossings of its mean height, each located by linear interpolation between frames.
fn swing_period(tip: &[Point], fps: f64) -> f64 {
    let y: Vec<f64> = tip.iter().map(|p| p[1]).collect();
    // The mean over whole swings: between the first and last downward turning points.
    let turns: Vec<usize> = (1..y.len() - 1).filter(|&f| y[f] < y[f - 1] && y[f] <= y[f + 1]).collect();
    let (a, b) = (turns[0], *turns.last().unwrap());
    let mean = y[a..b].iter().sum::<f64>() / (b - a) as f64;
    let ups: Vec<f64> = (1..y.len()).filter(|&f| y[f - 1] < mean && y[f] >= mean).map(|f| (f - 1) as f64 + (mean - y[f - 1]) / (y[f] - y[f - 1])).collect();
    assert!(ups.len() >= 3, "too few swings: {ups:?}");
    (ups[ups.len() - 1] - ups[0]) / (ups.len() - 1) as f64 / fps
}

/// The bar of the period tests: its tet mesh and material, its first bending period
/// in y by the tangent eigenvalue and by rapier's simulation, and the bar bent along that mode.
struct PeriodBar {
    mesh: TetMesh,
    material: ElasticMaterial,
    eigen: f64,
    rapier: f64,
    bent: Vec<Point>,
}

fn period_bar() -> PeriodBar {
    // The rapier bar (same tet mesh, same material), swinging freely from a small sag. Its
    // section is twice as deep as high, so the first mode is a clean bending in y (on a square
    // section the tets' diagonals split the y/z pair into two diagonal bendings 7% apart, and
    // gravity excites both).
    let settings = BarSettings { size: [1.2, 0.16, 0.32], divisions: [30, 4, 8], gravity: 0.5, ..BarSettings::default() };
    let simulated = bar(&settings);
    let rapier = swing_period(&simulated.tip, settings.fps);
    // Our elastic model of it: the clamped end held; the first bending periods by the tangent
    // stiffness at rest (a square bar bends alike in y and z: a pair).
    let mesh = simulated.body.clone();
    let material = lame_to_pd(&settings);
    let elastic = Elastic::new(&mesh, &material).unwrap();
    let clamped: Vec<bool> = mesh.positions.iter().map(|p| p[0] == 0.0).collect();
    let modes = natural_vibration(&elastic, &clamped, RestStiffness::Tangent, 2).unwrap();
    // The bending in y is the one gravity excites in rapier's swing.
    let tip: Vec<usize> = (0..mesh.positions.len()).filter(|&a| mesh.positions[a][0] == settings.size[0]).collect();
    let tip_mean = |shape: &[Point], d: usize| tip.iter().map(|&a| shape[a][d]).sum::<f64>() / tip.len() as f64;
    let y_share = |m: usize| tip_mean(&modes.shapes[m], 1).abs() / (tip_mean(&modes.shapes[m], 1).abs() + tip_mean(&modes.shapes[m], 2).abs());
    let mode = if y_share(0) > y_share(1) { 0 } else { 1 };
    assert!(y_share(mode) > 0.95, "mode {mode} is not a bending in y: {}", y_share(mode));
    let eigen = modes.periods()[mode];
    println!(
        "first bending period in y: tangent eigenvalue {eigen:.4} s (in z {:.4} s), rapier {rapier:.4} s, Euler-Bernoulli {:.4} s",
        modes.periods()[1 - mode],
        1.0 / settings.euler_bernoulli_frequency()
    );
    assert!((rapier / eigen - 1.0).abs() < 0.05, "rapier {rapier} vs eigen {eigen}");
    // The y bending scaled to a tip amplitude of 1e-3 of the length.
    let shape = &modes.shapes[mode];
    let tip_y = |shape: &[Point]| tip_mean(shape, 1);
    let amplitude = 1e-3 * settings.size[0] / tip_y(shape);
    let bent: Vec<Point> = mesh.positions.iter().zip(shape).map(|(p, u)| std::array::from_fn(|d| p[d] + amplitude * u[d])).collect();
    PeriodBar { mesh, material, eigen, rapier, bent }
}

#[test]
fn the_bar_period_by_the_tangent_eigenvalue_matches_rapier() {
    let bar = period_bar();
    assert!((bar.rapier / bar.eigen - 1.0).abs() < 0.05, "rapier {} vs eigen {}", bar.rapier, bar.eigen);
}

/// Not passing yet (measured, see the report of issue 10 part 2): the solver does not converge
/// on the bar's bending. At a fixed loop duration W falls by 4% in 300 quasi-Newton iterations
/// (0.428 -> 0.412 at 0.7 periods) and W*(D) as solved grows with D (0.362, 0.412, 0.570, 0.807
/// at 0.52, 0.7, 1.0, 1.4 periods), so the timing follows it down to short loops. The global
/// step's matrix, the preconditioner, is built on the projective stiffness L, which resists
/// bending about 55 times more than the tangent stiffness does (part 1: the L period is 7.4
/// times shorter), so the slow bending mode is the one the iteration barely moves.
///
/// Part 3: preconditioned by the tangent model Hessian (`model_hessian = "tangent"`, or
/// `"auto"` for this bar) W goes further, in far fewer iterations (at 0.35, 0.45, 0.4978, 0.55, 0.7 s:
/// 0.324, 0.368, 0.398, 0.438, 0.576 in 16-74 iterations, against 0.413, 0.516, 0.570, 0.630,
/// 0.807 after 200 projective ones), but the line search then finds no step that lowers W, and
/// these W still grow with D. They are not the minimum: on the one-mode model (a 1-DOF
/// oscillator, the same two-interval cyclic Hermite loop) the best loop leaves 2% of the
/// initial W at the period and 91% at 0.7 periods, a minimum sharp enough (W 50x larger at 0.7
/// periods) to find; here 67% is left at the period. What holds W up is still open (the next
/// check: the exact gradient against finite differences of W on this bar, whose stiffness is
/// 1e5 times the unit tests').
#[test]
#[ignore = "the solver does not converge on the bar's bending mode yet (see the comment)"]
fn the_cyclic_bar_finds_its_first_bending_period() {
    let PeriodBar { mesh, material, eigen, rapier, bent } = period_bar();
    let meshes = [("rest.mesh", medit(&mesh, &mesh.positions)), ("bent.mesh", medit(&mesh, &bent))];
    // A loop: the straight bar (free but for the clamp), the bent bar half a loop later (held),
    // the loop's end. The clamp is a support: position and velocity held at every key.
    let solve = |dir: &TempDir, duration: f64| -> (f64, Solution) {
        let scene = format!(
            r#"
name = "bar"
[keyframes]
meshes = ["rest.mesh", "bent.mesh", "rest.mesh"]
times = [0.0, {half}, {duration}]
cyclic = true
fixed = [{{ axis = "x", max = 1e-9 }}, "all", {{ axis = "x", max = 1e-9 }}]
fixed_velocity = [{{ axis = "x", max = 1e-9 }}, {{ axis = "x", max = 1e-9 }}, {{ axis = "x", max = 1e-9 }}]
[material]
stiffness = {ks}
volume = {kv}
density = {rho}
damping = 0.0
[solver]
optimize_timing = true
"#,
            half = 0.5 * duration,
            ks = material.stiffness,
            kv = material.volume,
            rho = material.density
        );
        let solution = solve_scene(dir, &meshes, &scene);
        (*solution.trajectory.times.last().unwrap(), solution)
    };
    let mut found = Vec::new();
    for start in [0.7 * eigen, 1.4 * eigen] {
        let dir = TempDir::new(&format!("timing-bar-{}", (start * 1000.0).round()));
        let (duration, solution) = solve(&dir, start);
        let log = &solution.log;
        println!(
            "started at {start:.4} s: the loop takes {duration:.4} s (times {:?}), W {:.4e} -> {:.4e}, {} iterations ({} moving the times, {} refactorizations): {}",
            solution.trajectory.times,
            log.energy[0],
            log.energy.last().unwrap(),
            log.iterations,
            log.timing_iterations,
            log.refactorizations,
            log.stop_reason
        );
        assert!(log.converged, "{}", log.stop_reason);
        assert!(log.energy.windows(2).all(|w| w[1] <= w[0]), "W never increases");
        assert_eq!(log.input_times, vec![0.0, 0.5 * start, start]);
        assert_eq!(log.times, solution.trajectory.times);
        assert!((duration / eigen - 1.0).abs() < 0.05, "from {start}: {duration} vs the eigen period {eigen}");
        assert!((duration / rapier - 1.0).abs() < 0.05, "from {start}: {duration} vs rapier's {rapier}");
        found.push(duration);
    }
    assert!((found[0] / found[1] - 1.0).abs() < 0.01, "the two starts end at {found:?}");
}

#[test]
fn a_ballistic_jump_with_keep_duration_finds_the_parabola_times() {
    // A rigid cube thrown up and caught a second later: every key's pose is held at a point of
    // the parabola, but the keys are given evenly spaced. With the duration kept, the times must
    // move to where the parabola passes those poses (paper Fig. 10: the in-air keys spread
    // around the apex), and the trajectory becomes the exact parabola (W -> 0).
    let g = 9.81;
    let (vx, vy) = (0.5, 0.5 * g);
    let truth = [0.0, 0.1, 0.5, 0.9, 1.0];
    let cube = |t: f64| -> String {
        let place = |p: Point| -> Point { [p[0] + vx * t, p[1] + vy * t - 0.5 * g * t * t, p[2]] };
        crate::cli_physics::cube_medit(2, place)
    };
    let meshes: Vec<(String, String)> = truth.iter().enumerate().map(|(k, &t)| (format!("k{k}.mesh"), cube(t))).collect();
    let dir = TempDir::new("timing-jump");
    for (name, text) in &meshes {
        std::fs::write(dir.join(name), text).unwrap();
    }
    let scene = r#"
name = "jump"
fps = 30
[keyframes]
meshes = ["k0.mesh", "k1.mesh", "k2.mesh", "k3.mesh", "k4.mesh"]
times = [0.0, 0.25, 0.5, 0.75, 1.0]
[material]
damping = 0.0
gravity = [0.0, -9.81, 0.0]
[solver]
optimize_timing = true
keep_duration = true
tolerance = 1e-6
[export]
formats = ["usda", "glb"]
"#;
    std::fs::write(dir.join("scene.toml"), scene).unwrap();
    // Every file, opened by usd-core, the glTF validator and three.js, plays the animation
    // computed in this process (checked below to be the exact parabola to 1e-4 of the size).
    let (report, anim) = bake_and_check(&dir.path, &dir.join("scene.toml"));
    let solver = &report["solver"];
    let (times, energy) = (key_times(&report), energies(&report));
    println!("optimized times {times:?}, W {:.3e} -> {:.3e}, {}", energy[0], energy.last().unwrap(), solver["stop_reason"]);
    assert_eq!(times[4], 1.0, "the duration is kept to the bit");
    for (t, want) in times.iter().zip(truth) {
        assert!((t - want).abs() < 2e-3, "times {times:?} vs the parabola's {truth:?}");
    }
    assert!(energy.last().unwrap() < &(1e-4 * energy[0]));
    let md = std::fs::read_to_string(dir.join("out/report.md")).unwrap();
    assert!(md.contains("| key times | optimized: 0.0000, 0.1"), "{md}");
    // The glTF clip's sampler input is the optimized key times.
    let glb = std::fs::read(dir.join("out/jump.glb")).unwrap();
    let input = gltf_sampler_input(&glb);
    assert_eq!(input, times.iter().map(|&t| t as f32).collect::<Vec<_>>());
    assert_eq!(anim.trajectory.times, times);
    for &t in &[0.05, 0.3, 0.5, 0.77] {
        let want: Vec<Point> = anim.trajectory.positions[0].iter().map(|p| [p[0] + vx * t, p[1] + vy * t - 0.5 * g * t * t, p[2]]).collect();
        let d = max_distance(&anim.trajectory.evaluate(t), &want);
        assert!(d < 1e-4, "{d} off the parabola at t = {t}");
    }
}

/// The input accessor of the first animation sampler of a GLB, as floats.
fn gltf_sampler_input(glb: &[u8]) -> Vec<f32> {
    let json_len = u32::from_le_bytes(glb[12..16].try_into().unwrap()) as usize;
    let json: Value = serde_json::from_slice(&glb[20..20 + json_len]).unwrap();
    let bin_start = 20 + json_len + 8;
    let accessor = &json["accessors"][json["animations"][0]["samplers"][0]["input"].as_u64().unwrap() as usize];
    let view = &json["bufferViews"][accessor["bufferView"].as_u64().unwrap() as usize];
    let offset = bin_start + view["byteOffset"].as_u64().unwrap_or(0) as usize + accessor["byteOffset"].as_u64().unwrap_or(0) as usize;
    (0..accessor["count"].as_u64().unwrap() as usize).map(|i| f32::from_le_bytes(glb[offset + 4 * i..offset + 4 * i + 4].try_into().unwrap())).collect()
}

/// The paper's ball (`../shared/assets/paper/ball/unit_sphere.obj`, diameter 1) moved up by
/// `dy`, as OBJ text.
fn ball_obj(dy: f64) -> Option<String> {
    let text = std::fs::read_to_string(crate::common::assets::paper_asset("ball/unit_sphere.obj")?).unwrap();
    let lines = text.lines().filter(|l| l.starts_with("v ") || l.starts_with("f ")).map(|l| {
        if let Some(rest) = l.strip_prefix("v ") {
            let p: Vec<f64> = rest.split_whitespace().map(|x| x.parse().unwrap()).collect();
            format!("v {:.17e} {:.17e} {:.17e}", p[0], p[1] + dy, p[2])
        } else {
            l.to_string()
        }
    });
    Some(lines.collect::<Vec<_>>().join("\n") + "\n")
}

#[test]
fn a_dropped_ball_bounces_off_the_plane_at_the_parabola_time() {
    // BALL: dropped from rest 1 m above its contact pose (touching the plane y = 0), it bounces
    // (`contact = [1]`: one pose, two velocities) and rises to where it started. The contact
    // time is free: it must move to where the free-fall parabola meets the plane, sqrt(2/g).
    let g: f64 = 9.81;
    let Some(high) = ball_obj(1.5) else { return };
    let low = ball_obj(0.5).unwrap();
    let dir = TempDir::new("timing-ball");
    for (name, text) in [("high.obj", &high), ("low.obj", &low)] {
        std::fs::write(dir.join(name), text).unwrap();
    }
    let scene = format!(
        r#"
name = "ball"
fps = 60
[keyframes]
meshes = ["high.obj", "low.obj", "high.obj"]
times = [0.0, 0.4, 0.9]
contact = [1]
fixed_velocity = ["all", "none", "none"]
[tet]
max_volume = 0.01
{FALLING}[solver]
samples = 20
optimize_timing = true
fixed_times = [0]
{FLOOR}[export]
formats = ["usda", "glb"]
"#
    );
    std::fs::write(dir.join("scene.toml"), scene).unwrap();
    // The files (usd-core, glTF validator, three.js) play exactly the animation checked below.
    let (report, anim) = bake_and_check(&dir.path, &dir.join("scene.toml"));
    let solver = &report["solver"];
    let (times, energy) = (key_times(&report), energies(&report));
    let parabola = (2.0 / g).sqrt();
    println!("ball: times {times:?} (parabola meets the plane at {parabola:.6}), W {:.3e} -> {:.3e}, clearance {}, {}", energy[0], energy.last().unwrap(), solver["clearance"], solver["stop_reason"]);
    assert_eq!(times.len(), 4, "the contact key is duplicated");
    assert_eq!(times[1], times[2], "a contact is a zero-length interval");
    assert!((times[1] - parabola).abs() < 1e-3, "contact at {} vs {parabola}", times[1]);
    assert!(solver["clearance"].as_f64().unwrap() >= -1e-4);
    // No vertex below the plane at any frame of the full-frame output (1e-4 of the diameter).
    assert_eq!(anim.trajectory.times, times);
    let lowest = anim.trajectory.frames(60.0).iter().map(|(_, t)| anim.trajectory.evaluate(*t).iter().map(|p| p[1]).fold(f64::INFINITY, f64::min)).fold(f64::INFINITY, f64::min);
    println!("lowest vertex over the frames: {lowest:.3e}");
    assert!(lowest >= -1e-4, "a vertex at {lowest}");
    let glb = std::fs::read(dir.join("out/ball.glb")).unwrap();
    assert_eq!(gltf_sampler_input(&glb).len(), 3, "the contact is one glTF key");
    // The stage files of a contact scene (a key time repeated) pass the stage readers' checks,
    // and the chain of subcommands gives the bake's bytes.
    crate::common::cli::assert_chain_gives_bake_bytes(&dir.path, "scene.toml", "out", &["ball.usda", "ball.glb"]);
}
