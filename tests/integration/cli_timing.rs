//! Key-time optimization (`[solver] optimize_timing`) through the CLI: the elastic bar's
//! cyclic swing finds its natural period, and a ballistic jump with `keep_duration` finds the
//! parabola's key times. The exported files carry the optimized times.

use blendsim::algorithms::geometry::{Point, TetMesh};
use blendsim::algorithms::physics::elastic::{Elastic, Material as ElasticMaterial};
use blendsim::algorithms::physics::equilibrium::loaded_equilibrium;
use blendsim::algorithms::physics::vibration::{natural_vibration, RestStiffness};
use blendsim::pipeline::stage_file::Solution;
use serde_json::Value;

use crate::cli_contacts::{bake_and_check, FALLING, FLOOR};
use crate::cli_physics::solve_scene;
use crate::common::bar::{bar_body, bar_released, BarSettings};
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
    let ups: Vec<f64> =
        (1..y.len()).filter(|&f| y[f - 1] < mean && y[f] >= mean).map(|f| (f - 1) as f64 + (mean - y[f - 1]) / (y[f] - y[f - 1])).collect();
    assert!(ups.len() >= 3, "too few swings: {ups:?}");
    (ups[ups.len() - 1] - ups[0]) / (ups.len() - 1) as f64 / fps
}

/// The bar of the period tests: its tet mesh and material, its first bending period in y by
/// the tangent eigenvalue, the bar bent in y to a tip displacement of `amplitude` times its
/// length as a static pose it can hold, and the period of rapier's simulation of it released
/// from that pose.
struct PeriodBar {
    mesh: TetMesh,
    material: ElasticMaterial,
    eigen: f64,
    rapier: f64,
    bent: Vec<Point>,
}

/// The period tests' bar meshed with `divisions` cells per axis (six tets each).
fn period_bar(amplitude: f64, divisions: [usize; 3]) -> PeriodBar {
    // Its section is twice as deep as high, so the first mode is a clean bending in y (on a
    // square section the tets' diagonals split the y/z pair into two diagonal bendings 7%
    // apart). No gravity: the bar swings about its straight rest shape.
    let settings = BarSettings { size: [1.2, 0.16, 0.32], divisions, gravity: 0.0, ..BarSettings::default() };
    let mesh = bar_body(&settings);
    // Our elastic model of it: the clamped end held; the first bending periods by the tangent
    // stiffness at rest (one in y, one in z).
    let material = lame_to_pd(&settings);
    let elastic = Elastic::new(&mesh, &material).unwrap();
    let clamped: Vec<bool> = mesh.positions.iter().map(|p| p[0] == 0.0).collect();
    let modes = natural_vibration(&elastic, &clamped, RestStiffness::Tangent, 2).unwrap();
    let tip: Vec<usize> = (0..mesh.positions.len()).filter(|&a| mesh.positions[a][0] == settings.size[0]).collect();
    let tip_mean = |shape: &[Point], d: usize| tip.iter().map(|&a| shape[a][d]).sum::<f64>() / tip.len() as f64;
    let y_share = |m: usize| tip_mean(&modes.shapes[m], 1).abs() / (tip_mean(&modes.shapes[m], 1).abs() + tip_mean(&modes.shapes[m], 2).abs());
    let mode = if y_share(0) > y_share(1) { 0 } else { 1 };
    println!("mode {mode}: y share of the tip motion {:.4}", y_share(mode));
    // With two cells across the height the tets' diagonals tilt the mode (0.90 on 15 x 2 x 4).
    assert!(y_share(mode) > 0.85, "mode {mode} is not a bending in y: {}", y_share(mode));
    let eigen = modes.periods()[mode];
    // The bent key: the static pose under the mode's inertial load λ M φ (whose linear response
    // is φ itself), scaled so that the tip moves up by the amplitude. Unlike φ scaled up (which
    // moves points across the bar only, stretching it), the pose's stretch along the bar is the
    // bar's own. The load is rescaled once by the measured tip (the response is linear to
    // O(amplitude)).
    let (lambda, shape) = (modes.eigenvalues[mode], &modes.shapes[mode]);
    let target = amplitude * settings.size[0];
    let mut bent = mesh.positions.clone();
    let mut scale = target / tip_mean(shape, 1);
    for _ in 0..2 {
        let load: Vec<Point> = shape.iter().zip(&elastic.mass).map(|(u, m)| u.map(|c| scale * lambda * m * c)).collect();
        let info = loaded_equilibrium(&elastic, &clamped, &load, &mut bent, 1e-9 * target, 200).unwrap();
        let residual = elastic
            .energy_gradient(&bent)
            .iter()
            .zip(&load)
            .zip(&clamped)
            .filter(|(_, &c)| !c)
            .map(|((g, f), _)| (0..3).map(|d| (g[d] - f[d]).powi(2)).sum::<f64>())
            .sum::<f64>()
            .sqrt();
        let force = load.iter().map(|f| f.iter().map(|c| c * c).sum::<f64>()).sum::<f64>().sqrt();
        println!(
            "bent key: {} Newton steps, last move {:.1e} m, |∇E - f| / |f| = {:.1e}, tip {:.6e} m",
            info.iterations,
            info.last_move,
            residual / force,
            tip_mean(&bent, 1) - settings.size[1] / 2.0
        );
        scale *= target / (tip_mean(&bent, 1) - tip_mean(&mesh.positions, 1));
    }
    let rest_tip = tip_mean(&mesh.positions, 1);
    // rapier released from the same pose: the same mesh, material and amplitude.
    let simulated = bar_released(&settings, &bent);
    let rapier = swing_period(&simulated.tip, settings.fps);
    let swing = simulated.tip.iter().map(|p| p[1] - rest_tip).fold(0.0f64, |m, y| m.max(y.abs()));
    println!(
        "first bending period in y: tangent eigenvalue {eigen:.4} s (in z {:.4} s), rapier released from the bent key (tip {:.3e} of the length, largest tip swing {:.3e}) {rapier:.4} s, Euler-Bernoulli {:.4} s",
        modes.periods()[1 - mode],
        (tip_mean(&bent, 1) - rest_tip) / settings.size[0],
        swing / settings.size[0],
        1.0 / settings.euler_bernoulli_frequency()
    );
    PeriodBar { mesh, material, eigen, rapier, bent }
}

/// The cyclic bar's amplitude: its tip moves by this fraction of its length (0.12 mm).
const AMPLITUDE: f64 = 1e-4;
/// The period tests' mesh: 30 x 4 x 8 cells, 5760 tets.
const FINE: [usize; 3] = [30, 4, 8];
/// The same bar with half the cells per axis (an eighth of the tets, 720) for the loop at a
/// visible amplitude.
const COARSE: [usize; 3] = [15, 2, 4];

#[test]
fn the_bar_period_by_the_tangent_eigenvalue_matches_rapier() {
    let bar = period_bar(AMPLITUDE, FINE);
    assert!((bar.rapier / bar.eigen - 1.0).abs() < 0.05, "rapier {} vs eigen {}", bar.rapier, bar.eigen);
}

/// One solve of the cyclic bar's loop started at `duration`, with these `[solver]` lines
/// besides `optimize_timing`: the loop's duration and the solution.
fn cyclic_bar(bar: &PeriodBar, dir: &TempDir, duration: f64, solver: &str, quarters: bool) -> (f64, Solution) {
    let meshes = [("rest.mesh", medit(&bar.mesh, &bar.mesh.positions)), ("bent.mesh", medit(&bar.mesh, &bar.bent))];
    // A loop: the straight bar (free but for the clamp), the bent bar half a loop later (held),
    // the loop's end. The clamp is a support: position and velocity held at every key.
    let clamp = r#"{ axis = "x", max = 1e-9 }"#;
    let keys = if quarters {
        format!(
            r#"meshes = ["rest.mesh", "rest.mesh", "bent.mesh", "rest.mesh", "rest.mesh"]
times = [0.0, {}, {}, {}, {duration}]
fixed = [{clamp}, {clamp}, "all", {clamp}, {clamp}]
fixed_velocity = [{clamp}, {clamp}, {clamp}, {clamp}, {clamp}]"#,
            0.25 * duration,
            0.5 * duration,
            0.75 * duration
        )
    } else {
        format!(
            r#"meshes = ["rest.mesh", "bent.mesh", "rest.mesh"]
times = [0.0, {}, {duration}]
fixed = [{clamp}, "all", {clamp}]
fixed_velocity = [{clamp}, {clamp}, {clamp}]"#,
            0.5 * duration
        )
    };
    let scene = format!(
        r#"
name = "bar"
[keyframes]
{keys}
cyclic = true
[material]
stiffness = {ks}
volume = {kv}
density = {rho}
damping = 0.0
[solver]
optimize_timing = true
{solver}
"#,
        ks = bar.material.stiffness,
        kv = bar.material.volume,
        rho = bar.material.density
    );
    let solution = solve_scene(dir, &meshes, &scene);
    (*solution.trajectory.times.last().unwrap(), solution)
}

/// Both starts (0.7 and 1.4 eigen periods) of the cyclic bar's loop end at the same duration,
/// within 5% of the eigen period and of rapier's; prints the comparison table.
fn both_starts_find_the_period(bar: &PeriodBar, quarters: bool) {
    println!("| start (s) | period (s) | vs eigen {:.4} s | vs rapier {:.4} s | iterations | moving the times | solver (s) |", bar.eigen, bar.rapier);
    let mut found = Vec::new();
    for start in [0.7 * bar.eigen, 1.4 * bar.eigen] {
        let dir = TempDir::new(&format!("timing-bar-{}-{}", if quarters { 5 } else { 3 }, (start * 1000.0).round()));
        // The default model Hessian: `auto` takes the tangent one (the keys are within 1% of
        // the bar's size of its rest shape).
        let (duration, solution) = cyclic_bar(bar, &dir, start, "", quarters);
        let log = &solution.log;
        println!(
            "| {start:.4} | {duration:.4} | {:+.2}% | {:+.2}% | {} | {} | {:.2} |",
            100.0 * (duration / bar.eigen - 1.0),
            100.0 * (duration / bar.rapier - 1.0),
            log.iterations,
            log.timing_iterations,
            log.seconds
        );
        println!(
            "times {:?}, W {:.4e} -> {:.4e}, {} refactorizations: {}",
            solution.trajectory.times,
            log.energy[0],
            log.energy.last().unwrap(),
            log.refactorizations,
            log.stop_reason
        );
        assert!(log.converged, "{}", log.stop_reason);
        assert!(log.stop_reason.contains("tangent model Hessian"), "{}", log.stop_reason);
        assert!(log.energy.windows(2).all(|w| w[1] <= w[0]), "W never increases");
        let keys = if quarters { 4 } else { 2 };
        assert_eq!(log.input_times, (0..=keys).map(|k| start * k as f64 / keys as f64).collect::<Vec<f64>>());
        assert_eq!(log.times, solution.trajectory.times);
        assert!((duration / bar.eigen - 1.0).abs() < 0.05, "from {start}: {duration} vs the eigen period {}", bar.eigen);
        assert!((duration / bar.rapier - 1.0).abs() < 0.05, "from {start}: {duration} vs rapier's {}", bar.rapier);
        found.push(duration);
    }
    assert!((found[0] / found[1] - 1.0).abs() < 0.01, "the two starts end at {found:?}");
}

/// The loop: the straight bar (free but for the clamp), the bar bent to a tip displacement of
/// 1e-4 of its length as the static pose under its first mode's inertial load (held) half a
/// loop later, the loop's end. rapier released from that pose swings with the period (0.4982 s)
/// and so does the loop: 0.4951 s from both starts (measured, 18-22 iterations). The key is a
/// pose the bar can hold: its stretch along the bar is its own (the linear mode scaled up
/// stretched the bar by half its squared rotation, and at 1e-3 of the length those held axial
/// forces made the loops shorter than 0.7 periods best). At 1e-3 of the length the equilibrium
/// key alone is not enough (measured: 0.3722 s from both starts, 25% short; 0.392 s with the
/// projective model Hessian): the swing shortens the bar at twice its frequency, a motion two
/// cubic intervals per loop cannot follow, and the bar's stiff axial response to that misfit
/// costs W in proportion to the loop's duration; free keys at the quarters fix it (see
/// [`the_cyclic_bar_at_a_visible_amplitude_finds_its_period`]). The default model Hessian
/// (`auto`) is the tangent one here (a Newton model about the rest shape), and it is needed:
/// the projective one stalls ([`the_projective_model_hessian_stalls_on_the_bar`]).
#[test]
fn the_cyclic_bar_finds_its_first_bending_period() {
    both_starts_find_the_period(&period_bar(AMPLITUDE, FINE), false);
}

/// The loop at a visible amplitude: the tip moves by 1e-3 of the length (1.2 mm), the bent key
/// as above, and free keys (the straight bar to start from) at a quarter and three quarters of
/// the loop, so that the bar's shortening at twice the swing's frequency has two cubic
/// intervals per cycle. On the same bar meshed with half the cells per axis (720 tets instead
/// of 5760; its coarse tets make it stiffer: 0.3999 s instead of 0.4978 s, and the first mode
/// leans 10% into z), where rapier released from the bent key swings with 0.4005 s (+0.15%).
/// Measured (load 19): 0.4009 s from both starts (+0.23% of the eigen period, +0.09% of
/// rapier's), 59 and 90 iterations on any thread count (the bar's modes are computed with a
/// fixed split: `physics::fixed_par`), 7 CPU s in all with rapier's simulation. On the fine mesh the same loop found 0.4981 s
/// and 0.4988 s (+0.05%, +0.20%) in 41 and 66 iterations, for 117 CPU s.
#[test]
fn the_cyclic_bar_at_a_visible_amplitude_finds_its_period() {
    let bar = period_bar(1e-3, COARSE);
    // The two independent periods of this mesh agree (the measurement is meaningful here too).
    assert!((bar.rapier / bar.eigen - 1.0).abs() < 0.01, "rapier {} vs eigen {}", bar.rapier, bar.eigen);
    both_starts_find_the_period(&bar, true);
}

/// Why the bar needs the tangent model Hessian, measured on the coarse bar's 1e-4 loop from
/// 0.7 periods. Preconditioned by the projective `L` (which resists the rotations bending is
/// made of, about 55 times more than the bar does; the normal matrix holds it squared, `L M⁻¹
/// L`), L-BFGS takes steps of 1e-9 to 1e-7 m against a key moving by 1.2e-4 m: over the
/// first 10 iterations at the given times W falls by 0.09% (the window rule's 1e-3 then hands
/// over to the times), where the tangent model's first step lowers it by 8.8%, the minimum for
/// those times. Run on (tolerance 1e-9) the projective solve plateaus: 1% of the tangent's
/// decrease after 100 iterations, 3% after 670, 92% after 2000, 95% after 3000 (31 CPU s;
/// the tangent solve takes about 1 s), its times never moved. So the stop is not the rule's
/// fault: any rule that waited out the plateau would run every stalled solve thousands of
/// iterations. With the default rule both phases stop on their windows (23-25 iterations),
/// the times at the best
/// period for keys that barely moved, 15% short, W still 0.85 of the first guess's; the tangent
/// model ends within 0.1% of the period with W at 0.04 of it.
#[test]
fn the_projective_model_hessian_stalls_on_the_bar() {
    let bar = period_bar(AMPLITUDE, COARSE);
    let start = 0.7 * bar.eigen;
    let dir = TempDir::new("timing-bar-stall");
    let (default, solution) = cyclic_bar(&bar, &dir, start, "", false);
    let (log, w0) = (&solution.log, solution.log.energy[0]);
    println!(
        "default: {default:.4} s ({:+.2}% of the eigen period), W {:.3} of the first guess's, {} iterations: {}",
        100.0 * (default / bar.eigen - 1.0),
        log.energy.last().unwrap() / w0,
        log.iterations,
        log.stop_reason
    );
    assert!(log.stop_reason.contains("tangent model Hessian"), "{}", log.stop_reason);
    assert!((default / bar.eigen - 1.0).abs() < 0.01, "{default} vs the eigen period {}", bar.eigen);
    assert!(*log.energy.last().unwrap() < 0.1 * w0, "{:?}", log.energy);
    let (projective, solution) = cyclic_bar(&bar, &dir, start, r#"model_hessian = "projective""#, false);
    let log = &solution.log;
    println!(
        "projective: {projective:.4} s ({:+.2}%), W {:.3} of the first guess's, {} iterations: {}",
        100.0 * (projective / bar.eigen - 1.0),
        log.energy.last().unwrap() / w0,
        log.iterations,
        log.stop_reason
    );
    assert!(log.converged && !log.stop_reason.contains("tangent"), "{}", log.stop_reason);
    assert_eq!(log.energy[0], w0, "the same first guess");
    // Stalled: far from the period, W far above the tangent model's.
    assert!(projective < 0.9 * bar.eigen, "{projective} vs the eigen period {}", bar.eigen);
    assert!(*log.energy.last().unwrap() > 0.5 * w0, "{:?}", log.energy);
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
# CUBICSPLINE: the glTF sampler's input is then the key times themselves.
gltf_interpolation = "cubicspline"
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
    (0..accessor["count"].as_u64().unwrap() as usize)
        .map(|i| f32::from_le_bytes(glb[offset + 4 * i..offset + 4 * i + 4].try_into().unwrap()))
        .collect()
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
# CUBICSPLINE: the glTF sampler's input is then the key times themselves.
gltf_interpolation = "cubicspline"
"#
    );
    std::fs::write(dir.join("scene.toml"), scene).unwrap();
    // The files (usd-core, glTF validator, three.js) play exactly the animation checked below.
    let (report, anim) = bake_and_check(&dir.path, &dir.join("scene.toml"));
    let solver = &report["solver"];
    let (times, energy) = (key_times(&report), energies(&report));
    let parabola = (2.0 / g).sqrt();
    println!(
        "ball: times {times:?} (parabola meets the plane at {parabola:.6}), W {:.3e} -> {:.3e}, clearance {}, {}",
        energy[0],
        energy.last().unwrap(),
        solver["clearance"],
        solver["stop_reason"]
    );
    assert_eq!(times.len(), 4, "the contact key is duplicated");
    assert_eq!(times[1], times[2], "a contact is a zero-length interval");
    assert!((times[1] - parabola).abs() < 1e-3, "contact at {} vs {parabola}", times[1]);
    assert!(solver["clearance"].as_f64().unwrap() >= -1e-4);
    // No vertex below the plane at any frame of the full-frame output (1e-4 of the diameter).
    assert_eq!(anim.trajectory.times, times);
    let lowest = anim
        .trajectory
        .frames(60.0)
        .iter()
        .map(|(_, t)| anim.trajectory.evaluate(*t).iter().map(|p| p[1]).fold(f64::INFINITY, f64::min))
        .fold(f64::INFINITY, f64::min);
    println!("lowest vertex over the frames: {lowest:.3e}");
    assert!(lowest >= -1e-4, "a vertex at {lowest}");
    let glb = std::fs::read(dir.join("out/ball.glb")).unwrap();
    assert_eq!(gltf_sampler_input(&glb).len(), 3, "the contact is one glTF key");
    // The stage files of a contact scene (a key time repeated) pass the stage readers' checks,
    // and the chain of subcommands gives the bake's bytes.
    crate::common::cli::assert_chain_gives_bake_bytes(&dir.path, "scene.toml", "out", &["ball.usda", "ball.glb"]);
}
