//! Warm re-bakes (`blendsim bake --from`) against cold bakes, as a user runs them: the
//! `blendsim` process on the demo, the 20-key 2.6k-node body of the convergence bench (its key
//! 10 twisted 5° more) and, when the paper's assets are present, the DINO walk.
//! Per scene: a cold bake (the first of the loop, keeping its cache); the same inputs re-baked from it (TetGen and the solve reused);
//! one key edited and baked cold; the same edit baked from the first bake (the solve starts
//! from its solution). Wall and CPU seconds of the child, medians of `REPEATS` (default 5),
//! with the solver's iterations and W from each report.
//!
//! `cargo bench --bench warm` (`make bench-warm`); `target/release/blendsim` must be built.
//! `WARM_CASES=20-key` runs the cases whose names hold one of the comma-separated words (the
//! 20-key body's cold bake takes about a minute a repeat). Mind the load average printed with
//! it: the machine is shared.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use blendsim::algorithms::geometry::Axis;
use blendsim::algorithms::procedural::{prism, twist, Twist};
use blendsim::formats::mesh::obj;

mod common;
use common::{load, median, write_twenty_keys};

/// CPU seconds (user + system) of the waited-for children.
fn children_cpu() -> f64 {
    // SAFETY: getrusage writes one rusage struct it is given.
    let mut r: libc::rusage = unsafe { std::mem::zeroed() };
    unsafe { libc::getrusage(libc::RUSAGE_CHILDREN, &mut r) };
    let s = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 * 1e-6;
    s(r.ru_utime) + s(r.ru_stime)
}

/// One bake, as a user runs it: wall and CPU seconds of the process, and what it printed.
fn bake(bin: &Path, cwd: &Path, scene: &str, out: &str, from: Option<&str>) -> (f64, f64, String) {
    let mut command = Command::new(bin);
    command.current_dir(cwd).args(["bake", scene, "--out", out]);
    if let Some(from) = from {
        command.args(["--from", from]);
    }
    let (t, c) = (Instant::now(), children_cpu());
    let output = command.output().expect("blendsim starts");
    let (wall, cpu) = (t.elapsed().as_secs_f64(), children_cpu() - c);
    let stderr = String::from_utf8_lossy(&output.stderr).into_owned();
    assert!(output.status.success(), "{command:?} failed:\n{stderr}");
    (wall, cpu, stderr)
}

/// The solver's iterations and last W in a bake folder's report.json.
fn solved(dir: &Path) -> (u64, f64) {
    let report: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.join("report.json")).expect("report.json")).expect("JSON");
    let energy = report["solver"]["energy"].as_array().expect("energy");
    (report["solver"]["iterations"].as_u64().expect("iterations"), energy.last().and_then(|w| w.as_f64()).expect("W"))
}

/// A scene set up in its own folder: the file to bake, and how to edit one key.
struct Case {
    name: &'static str,
    dir: PathBuf,
    scene: &'static str,
    edit: Box<dyn Fn(&Path)>,
    restore: Box<dyn Fn(&Path)>,
}

/// The demo, its left key twisted `degrees` instead of 120 (by the demo's own generator).
fn demo(root: &Path, dir: PathBuf, degrees: f64, name: &'static str) -> Case {
    std::fs::create_dir_all(&dir).unwrap();
    for entry in std::fs::read_dir(root.join("fixtures/demo")).unwrap() {
        let path = entry.unwrap().path();
        std::fs::copy(&path, dir.join(path.file_name().unwrap())).unwrap();
    }
    let left = |degrees: f64| {
        move |dir: &Path| {
            let rest = prism([1.0, 3.0, 1.0], [3, 9, 3]);
            let mut m = rest.clone();
            m.positions = twist(&rest.positions, &Twist { axis: Axis::Y, degrees, axial_scale: 0.9 });
            std::fs::write(dir.join("prism_left.obj"), obj::write(&m)).unwrap();
        }
    };
    Case { name, dir, scene: "twist.toml", edit: Box::new(left(degrees)), restore: Box::new(left(120.0)) }
}

/// The convergence bench's "KEY20-2.6k" body (`common::twenty_keys_held`, bottom and top held),
/// its key 10 twisted 5° more.
fn twenty_keys(dir: PathBuf) -> Case {
    std::fs::create_dir_all(&dir).unwrap();
    let write = |edit: Option<(usize, f64)>| move |dir: &Path| drop(write_twenty_keys(dir, [12, 36, 12], 0.003, Some(&[0.0, 1.0]), edit));
    write(None)(&dir);
    Case {
        name: "20-key body (key 10 twisted 5 degrees more)",
        dir,
        scene: "scene.toml",
        edit: Box::new(write(Some((10, 5.0)))),
        restore: Box::new(write(None)),
    }
}

/// DINO's walk, its fifth key moved a tenth of the way towards the fourth (a Medit mesh:
/// the vertex lines after `Vertices` and their count rewritten).
fn dino(root: &Path, dir: PathBuf) -> Option<Case> {
    let assets = root.join("../shared/assets/paper").canonicalize().ok()?;
    let key = |k: usize| assets.join(format!("dino/anim/dino_tet_{k}.mesh"));
    if !key(5).is_file() {
        return None;
    }
    std::fs::create_dir_all(&dir).unwrap();
    let text =
        std::fs::read_to_string(root.join("fixtures/paper/dino.toml")).unwrap().replace("../../../shared/assets/paper", &assets.to_string_lossy());
    let scene = text.replace(&key(5).to_string_lossy().into_owned(), "key5.mesh");
    assert_ne!(scene, text, "the scene names key 5");
    std::fs::write(dir.join("dino.toml"), scene).unwrap();
    let original = std::fs::read_to_string(key(5)).unwrap();
    let towards = std::fs::read_to_string(key(4)).unwrap();
    let restore = original.clone();
    let edit = move |dir: &Path| {
        let vertices = |text: &str| -> Vec<(usize, [f64; 3])> {
            let lines: Vec<&str> = text.lines().collect();
            let at = lines.iter().position(|l| l.trim() == "Vertices").expect("a Vertices section");
            let n: usize = lines[at + 1].trim().parse().expect("a vertex count");
            (0..n)
                .map(|i| {
                    let v: Vec<f64> = lines[at + 2 + i].split_whitespace().take(3).map(|x| x.parse().unwrap()).collect();
                    (at + 2 + i, [v[0], v[1], v[2]])
                })
                .collect()
        };
        let (a, b) = (vertices(&original), vertices(&towards));
        let mut lines: Vec<String> = original.lines().map(String::from).collect();
        for ((line, p), (_, q)) in a.iter().zip(&b) {
            let reference = lines[*line].split_whitespace().nth(3).unwrap_or("0").to_string();
            let x: Vec<String> = (0..3).map(|c| format!("{}", p[c] + 0.1 * (q[c] - p[c]))).collect();
            lines[*line] = format!("{} {reference}", x.join(" "));
        }
        std::fs::write(dir.join("key5.mesh"), lines.join("\n") + "\n").unwrap();
    };
    let restore = move |dir: &Path| std::fs::write(dir.join("key5.mesh"), &restore).unwrap();
    restore(&dir);
    Some(Case { name: "DINO (key 5 a tenth towards key 4)", dir, scene: "dino.toml", edit: Box::new(edit), restore: Box::new(restore) })
}

fn main() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let repeats: usize = std::env::var("REPEATS").ok().and_then(|r| r.parse().ok()).unwrap_or(5);
    let bin = root.join("target/release/blendsim");
    assert!(bin.is_file(), "{} missing: `cargo build --release` first", bin.display());
    let folder = tempfile::Builder::new().prefix("blendsim-bench-warm-").tempdir().expect("a scratch folder");
    let scratch = folder.path();
    // A large edit (a sixth of the key's twist) and a touch-up.
    let mut cases = vec![
        demo(root, scratch.join("demo"), 100.0, "demo (left key 120 -> 100 degrees)"),
        demo(root, scratch.join("demo-touch"), 115.0, "demo (left key 120 -> 115 degrees)"),
    ];
    cases.push(twenty_keys(scratch.join("twenty-keys")));
    match dino(root, scratch.join("dino")) {
        Some(case) => cases.push(case),
        None => println!("(DINO skipped: the paper's assets are not in ../shared/assets)"),
    }
    if let Ok(only) = std::env::var("WARM_CASES") {
        let words: Vec<&str> = only.split(',').map(str::trim).filter(|w| !w.is_empty()).collect();
        cases.retain(|case| words.iter().any(|w| case.name.contains(w)));
    }
    println!("warm re-bakes (`blendsim bake --from`), medians of {repeats}; load average {}", load());
    println!();
    println!("| scene | bake | wall s | CPU s | of cold | iterations | W | reused |");
    println!("|---|---|---:|---:|---:|---:|---:|---|");
    for case in &cases {
        let dir = &case.dir;
        let mut rows = Vec::new();
        let mut run = |label: &str, out: &str, from: Option<&str>, prepare: &dyn Fn()| {
            let (mut wall, mut cpu, mut said) = (Vec::new(), Vec::new(), String::new());
            for _ in 0..repeats {
                prepare();
                let (w, c, stderr) = bake(&bin, dir, case.scene, out, from);
                wall.push(w);
                cpu.push(c);
                said = stderr
                    .lines()
                    .find_map(|l| l.strip_prefix("blendsim: from "))
                    .map(|l| l.split_once(": ").map_or(l, |x| x.1).to_string())
                    .unwrap_or_default();
            }
            let (iterations, w) = solved(&dir.join(out));
            rows.push((label.to_string(), median(wall), median(cpu), iterations, w, said));
        };
        (case.restore)(dir);
        // A first bake into its own folder, as the editing loop starts: cold, and it keeps
        // the cache the next rows read (each repeat into a fresh folder).
        let fresh = || {
            let _ = std::fs::remove_dir_all(dir.join("cold"));
        };
        run("cold (first --from into its own --out)", "cold", Some("cold"), &fresh);
        run("unchanged, --from cold", "same", Some("cold"), &|| {});
        (case.edit)(dir);
        run("one key edited, cold", "edited-cold", None, &|| {});
        // Each repeat from the same first bake: `warm` is rewritten, `cold` is not.
        run("one key edited, --from cold", "edited-warm", Some("cold"), &|| {});
        (case.restore)(dir);
        let cold = |i: usize| rows[i].1;
        for (i, (label, wall, cpu, iterations, w, said)) in rows.iter().enumerate() {
            let reference = if i < 2 { cold(0) } else { cold(2) };
            println!("| {} | {label} | {wall:.3} | {cpu:.3} | {:.0}% | {iterations} | {w:.6e} | {said} |", case.name, 100.0 * wall / reference);
        }
    }
    println!();
    println!("load average after: {}", load());
}
