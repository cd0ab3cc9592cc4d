//! One command line across subcommands, as a Makefile or a pipeline script uses it: `-o/--out`
//! everywhere (the old `--output` kept as a hidden alias), sizes and durations in the usual
//! spellings and refused when they overflow, `--json` (one line on stdout, whatever the end),
//! `bake --depfile` driving a real `make`, `BLENDSIM_PROGRESS`, and the generated completions
//! and man pages.

use std::ffi::OsStr;
use std::path::Path;
use std::process::Command;

use crate::common::cli::{bin, run, run_env, TempDir};
use blendsim::algorithms::geometry::TriMesh;
use blendsim::algorithms::procedural::prism;
use blendsim::formats::mesh::obj;
use serde_json::Value;

const SUBCOMMANDS: [&str; 8] = ["import", "tetrahedralize", "solve", "embed", "export", "report", "bake", "blend"];

fn cube() -> TriMesh {
    prism([1.0, 1.0, 1.0], [2, 2, 2])
}

/// A two-key box scene `in/box.toml` whose first key has a material with a texture and whose
/// fixed vertices come from a selection file: every kind of input a depfile must list.
fn scene(dir: &Path) {
    let input = dir.join("in");
    std::fs::create_dir_all(&input).unwrap();
    let mut k1 = cube();
    k1.positions.iter_mut().for_each(|p| p[1] += 0.5);
    let k0 = format!("mtllib box.mtl\nusemtl wood\n{}", obj::write(&cube()));
    std::fs::write(input.join("k0.obj"), k0).unwrap();
    std::fs::write(input.join("k1.obj"), obj::write(&k1)).unwrap();
    std::fs::write(input.join("box.mtl"), "newmtl wood\nKd 1 1 1\nmap_Kd wood.png\n").unwrap();
    std::fs::write(input.join("wood.png"), tiny_png()).unwrap();
    std::fs::write(input.join("bottom.txt"), "0\n1\n").unwrap();
    let text = "name = \"box\"\n[keyframes]\nmeshes = [\"k0.obj\", \"k1.obj\"]\ntimes = [0.0, 1.0]\nfixed = [\"all\", \"all\"]\nfixed_velocity = [\"bottom.txt\", \"bottom.txt\"]\n[export]\nformats = [\"glb\"]\n";
    std::fs::write(input.join("box.toml"), text).unwrap();
}

/// A valid 1x1 RGB PNG.
fn tiny_png() -> Vec<u8> {
    let mut bytes = Vec::new();
    let mut encoder = png::Encoder::new(&mut bytes, 1, 1);
    encoder.set_color(png::ColorType::Rgb);
    encoder.write_header().unwrap().write_image_data(&[200, 150, 100]).unwrap();
    bytes
}

fn json_line(stdout: &str) -> Value {
    let lines: Vec<&str> = stdout.lines().collect();
    assert_eq!(lines.len(), 1, "--json prints exactly one line on stdout, got {stdout:?}");
    serde_json::from_str(lines[0]).unwrap_or_else(|e| panic!("--json line is not JSON ({e}): {}", lines[0]))
}

#[test]
fn every_subcommand_takes_its_output_as_dash_o_or_out() {
    let dir = TempDir::new("conventions-help");
    for sub in SUBCOMMANDS {
        let help = run(&dir.path, &[sub, "--help"]).success().stdout;
        assert!(help.contains("-o, --out <"), "{sub} --help lists -o, --out:\n{help}");
        assert!(!help.contains("--output <"), "{sub} --help shows the old spelling:\n{help}");
        for option in ["--max-memory", "--max-time", "--json"] {
            assert!(help.contains(option), "{sub} --help lists {option}");
        }
    }
    // The old spellings still run (hidden aliases), and the new ones give the same bytes.
    scene(&dir.path);
    run(&dir.path, &["import", "in/box.toml", "--output", "old.json"]).success();
    run(&dir.path, &["import", "in/box.toml", "-o", "new.json"]).success();
    assert_eq!(std::fs::read(dir.join("old.json")).unwrap(), std::fs::read(dir.join("new.json")).unwrap());
    run(&dir.path, &["bake", "in/box.toml", "-o", "short", "-q"]).success();
    run(&dir.path, &["bake", "in/box.toml", "--output", "long", "-q"]).success();
    assert_eq!(std::fs::read(dir.join("short/box.glb")).unwrap(), std::fs::read(dir.join("long/box.glb")).unwrap());
}

#[test]
fn sizes_and_durations_take_the_usual_spellings_and_refuse_overflow() {
    let dir = TempDir::new("conventions-sizes");
    scene(&dir.path);
    for memory in ["512MB", "2GiB", "4G", "1.5g", "3000000000"] {
        run(&dir.path, &["import", "in/box.toml", "-o", "k.json", "--max-memory", memory]).success();
    }
    for (flag, value) in [("--max-memory", "99999999999999999999G"), ("--max-memory", "12XB"), ("--max-time", "1e300s"), ("--max-time", "400d")] {
        let r = run(&dir.path, &["import", "in/box.toml", "-o", "k.json", flag, value]);
        assert_eq!(r.code, Some(2), "{flag} {value} is a usage error: {}", r.stderr);
        assert!(r.stderr.contains(value), "the message quotes the value: {}", r.stderr);
    }
}

#[test]
fn json_is_one_line_on_stdout_for_success_error_and_refusal() {
    let dir = TempDir::new("conventions-json");
    scene(&dir.path);
    let ok = run(&dir.path, &["bake", "in/box.toml", "-o", "out", "--json"]).success();
    let line = json_line(&ok.stdout);
    assert_eq!((line["command"].as_str(), line["status"].as_str(), line["exit"].as_u64()), (Some("bake"), Some("ok"), Some(0)));
    let outputs: Vec<&str> = line["outputs"].as_array().unwrap().iter().map(|o| o.as_str().unwrap()).collect();
    for name in ["out/box.glb", "out/box.full.glb", "out/report.json", "out/report.md"] {
        assert!(outputs.contains(&name), "{name} in {outputs:?}");
        assert!(dir.join(name).is_file());
    }
    assert!(line["ratios"]["glb"].as_f64().unwrap() > 1.0, "{line}");
    assert!(line["seconds"].as_f64().unwrap() > 0.0);

    let bad = run(&dir.path, &["bake", "in/missing.toml", "-o", "out2", "--json"]);
    assert_eq!(bad.code, Some(1));
    let line = json_line(&bad.stdout);
    assert_eq!((line["status"].as_str(), line["exit"].as_u64()), (Some("error"), Some(1)));
    assert!(line["error"].as_str().unwrap().contains("missing.toml"), "{line}");
    assert!(!dir.join("out2").exists());

    // Key times that look like frame numbers warn; --strict refuses them.
    let frames = std::fs::read_to_string(dir.join("in/box.toml")).unwrap().replace("times = [0.0, 1.0]", "times = [0.0, 48.0]");
    std::fs::write(dir.join("in/frames.toml"), frames).unwrap();
    let refused = run(&dir.path, &["bake", "in/frames.toml", "-o", "out3", "--json", "--strict"]);
    assert_eq!(refused.code, Some(3), "{}", refused.stderr);
    let line = json_line(&refused.stdout);
    assert_eq!((line["status"].as_str(), line["exit"].as_u64()), (Some("refused"), Some(3)));
    assert!(!line["warnings"].as_array().unwrap().is_empty());
    assert!(!dir.join("out3").exists());

    // The stage subcommands too.
    let import = run(&dir.path, &["import", "in/box.toml", "-o", "keys.json", "--json"]).success();
    assert_eq!(json_line(&import.stdout)["outputs"], serde_json::json!(["keys.json"]));
}

fn make(dir: &Path, args: &[&str]) -> std::process::Output {
    Command::new("make").current_dir(dir).args(args).output().expect("make runs")
}

#[test]
fn a_depfile_makes_make_rebake_when_any_input_changes() {
    let dir = TempDir::new("conventions-depfile");
    scene(&dir.path);
    let makefile = format!(
        "out/report.json: in/box.toml\n\t{} bake $< -o out --depfile box.d -q\n-include box.d\n",
        std::fs::canonicalize(bin()).unwrap().display()
    );
    std::fs::write(dir.join("Makefile"), makefile).unwrap();
    let first = make(&dir.path, &[]);
    assert!(first.status.success(), "{}", String::from_utf8_lossy(&first.stderr));
    let depfile = std::fs::read_to_string(dir.join("box.d")).unwrap();
    for input in ["in/box.toml", "in/k0.obj", "in/k1.obj", "in/box.mtl", "in/wood.png", "in/bottom.txt"] {
        assert!(depfile.contains(input), "{input} in the depfile:\n{depfile}");
    }
    let up_to_date = |dir: &Path| make(dir, &["-q"]).status.success();
    // Times set by hand, so that no test depends on the file system's time resolution: every
    // input at t0, the outputs at t0 + 100 s, an edited input at t0 + 200 s.
    let t0 = std::time::SystemTime::now() - std::time::Duration::from_secs(1000);
    let at = |path: &str, seconds: u64| {
        let file = std::fs::File::options().append(true).open(dir.join(path)).unwrap();
        file.set_modified(t0 + std::time::Duration::from_secs(seconds)).unwrap();
    };
    let inputs = ["in/box.toml", "in/k0.obj", "in/k1.obj", "in/box.mtl", "in/wood.png", "in/bottom.txt"];
    let outputs = ["out/report.json", "out/report.md", "out/box.glb", "out/box.full.glb", "box.d"];
    let settle = || {
        inputs.iter().for_each(|i| at(i, 0));
        outputs.iter().for_each(|o| at(o, 100));
    };
    settle();
    assert!(up_to_date(&dir.path), "nothing changed: make has nothing to do");
    for input in ["in/k1.obj", "in/wood.png", "in/bottom.txt", "in/box.mtl"] {
        at(input, 200);
        assert!(!up_to_date(&dir.path), "editing {input} makes the bake out of date");
        let again = make(&dir.path, &[]);
        assert!(again.status.success(), "{}", String::from_utf8_lossy(&again.stderr));
        assert!(up_to_date(&dir.path), "after the re-bake for {input}, make has nothing to do");
        settle();
    }
    // A renamed input (the -MP empty rules): make re-bakes, and the bake then says what is missing.
    std::fs::rename(dir.join("in/bottom.txt"), dir.join("in/bottom2.txt")).unwrap();
    let renamed = make(&dir.path, &[]);
    let stderr = String::from_utf8_lossy(&renamed.stderr);
    assert!(!stderr.contains("No rule to make target"), "{stderr}");
    assert!(stderr.contains("bottom.txt"), "the bake names the missing selection: {stderr}");
}

#[test]
fn progress_lines_print_a_done_line_per_stage_and_unknown_settings_are_errors() {
    let dir = TempDir::new("conventions-progress");
    scene(&dir.path);
    let lines = run_env(&dir.path, &["bake", "in/box.toml", "-o", "out"], &[("BLENDSIM_PROGRESS", OsStr::new("lines"))]).success();
    let done: Vec<&str> = lines.stderr.lines().filter(|l| l.contains(": done in ")).collect();
    assert!(done.len() >= 4, "a done line per stage:\n{}", lines.stderr);
    for stage in ["import", "tetrahedralize", "solve", "export"] {
        assert!(done.iter().any(|l| l.starts_with(stage)), "{stage} has a done line: {done:?}");
    }
    let bad = run_env(&dir.path, &["bake", "in/box.toml", "-o", "out2"], &[("BLENDSIM_PROGRESS", OsStr::new("verbose"))]);
    assert_eq!(bad.code, Some(2));
    assert!(bad.stderr.contains("BLENDSIM_PROGRESS") && bad.stderr.contains("verbose"), "{}", bad.stderr);
    assert!(!dir.join("out2").exists());
}

#[test]
fn completions_and_man_pages_come_from_the_definitions() {
    let dir = TempDir::new("conventions-generate");
    for shell in ["bash", "zsh", "fish"] {
        run(&dir.path, &["generate", "completions", shell, "-o", "completions"]).success();
    }
    let bash = std::fs::read_to_string(dir.join("completions/blendsim.bash")).unwrap();
    for word in SUBCOMMANDS.iter().chain(&["--depfile", "--json", "--max-memory"]) {
        assert!(bash.contains(word), "bash completion knows {word}");
    }
    assert!(dir.join("completions/_blendsim").is_file() && dir.join("completions/blendsim.fish").is_file());
    run(&dir.path, &["generate", "man", "-o", "man"]).success();
    for sub in SUBCOMMANDS {
        let page = std::fs::read_to_string(dir.join(format!("man/blendsim-{sub}.1"))).unwrap();
        assert!(page.starts_with(".ie") || page.contains(".TH"), "a roff page for {sub}");
    }
    assert!(!dir.join("man/blendsim-generate.1").exists(), "the hidden subcommand has no page");
    // `man` itself renders the page, when installed.
    if let Ok(out) = Command::new("man").arg("-l").arg(dir.join("man/blendsim-bake.1")).env("MANPAGER", "cat").output() {
        if out.status.success() {
            assert!(String::from_utf8_lossy(&out.stdout).contains("depfile"));
        }
    }
}
