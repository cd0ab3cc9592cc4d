//! Run the independent checkers in `tests/checkers/` from Rust tests.
//!
//! Each helper writes the expected points to a JSON file (format in
//! `tests/checkers/README.md`), runs the checker, and panics with the checker's whole output
//! when it fails. Missing tools are a failure naming `make test-deps`, never a skip: a test
//! that silently passes without its checker proves nothing.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use blendsim::algorithms::geometry::Point;
use blendsim::pipeline::scene::Axis;
use blendsim::pipeline::stage_file::Animation;
use serde::Serialize;
use serde_json::Value;

/// What a checker compares a file with. `times` (seconds) drive glTF animations, `timecodes`
/// (frames) drive USD stages; both have one entry per pose in `points`.
#[derive(Debug, Clone, Serialize)]
pub struct Expected {
    pub times: Vec<f64>,
    pub timecodes: Vec<f64>,
    pub points: Vec<Vec<Point>>,
    /// Largest allowed point distance, relative to the expected points' bounding-box diagonal.
    pub tolerance: f64,
    /// "blendshape" or "full-frame": how the file must animate.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub kind: Option<String>,
    /// Frames per second, checked against the USD stage metadata.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fps: Option<f64>,
    /// "y" or "z": the scene's up axis (USD `upAxis`; glTF node rotation).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub up_axis: Option<String>,
    /// USD `metersPerUnit`; glTF node scale.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub meters_per_unit: Option<f64>,
    /// Per triangle, its corners' (point, u, v), v up (OBJ's convention): the UVs a consumer
    /// must read back (Blender checker).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub corners: Option<Vec<[(u32, f64, f64); 3]>>,
    /// Per triangle, its material's name (Blender checker).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub triangle_materials: Option<Vec<String>>,
    /// The file may have more vertices than points (glTF seam copies): match each to the
    /// nearest point at the first time (Blender checker).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub map_vertices: Option<bool>,
}

impl Expected {
    /// Points at the given times, with frame numbers `t * fps` and the default tolerance 1e-5.
    pub fn at(times: &[f64], fps: f64, points: impl Fn(f64) -> Vec<Point>) -> Expected {
        Expected {
            times: times.to_vec(),
            timecodes: times.iter().map(|t| (t * fps * 1e9).round() / 1e9).collect(),
            points: times.iter().map(|&t| points(t)).collect(),
            tolerance: 1e-5,
            kind: None,
            fps: None,
            up_axis: None,
            meters_per_unit: None,
            corners: None,
            triangle_materials: None,
            map_vertices: None,
        }
    }

    /// An animation's trajectory at every frame, with its stage's fps, up axis and units: what
    /// the full-frame files hold, and what a consumer must play.
    pub fn every_frame(anim: &Animation) -> Expected {
        let fps = anim.scene.fps;
        let frames: Vec<f64> = anim.trajectory.frames(fps).iter().map(|f| f.1).collect();
        let mut e = Expected::at(&frames, fps, |t| anim.trajectory.evaluate(t));
        e.fps = Some(fps);
        e.up_axis = Some(if anim.scene.export.up_axis == Axis::Z { "z" } else { "y" }.into());
        e.meters_per_unit = Some(anim.scene.export.meters_per_unit);
        e
    }
}

fn checkers_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/checkers")
}

fn python() -> String {
    std::env::var("BLENDSIM_PYTHON").unwrap_or_else(|_| "python3".into())
}

fn require_pxr() {
    let python = python();
    match Command::new(&python).args(["-c", "import pxr.UsdValidation, pxr.UsdSkel"]).output() {
        Ok(o) if o.status.success() => {}
        Ok(o) => panic!(
            "usd-core is not importable by {python} ({}): run `make test-deps`",
            String::from_utf8_lossy(&o.stderr).trim().lines().last().unwrap_or("")
        ),
        Err(e) => panic!("cannot run {python} ({e}): run `make test-deps`"),
    }
}

fn require_node_modules(packages: &[&str]) {
    if let Err(e) = Command::new("node").arg("--version").output() {
        panic!("cannot run node ({e}): install Node.js 20, then run `make test-deps`");
    }
    for p in packages {
        let manifest = checkers_dir().join("node_modules").join(p).join("package.json");
        assert!(manifest.is_file(), "{} is missing: run `make test-deps` (npm ci in tests/checkers)", manifest.display());
    }
}

/// The expected points as a JSON file beside `file`.
fn write_expected(file: &Path, expected: &Expected) -> PathBuf {
    let path = file.with_extension(format!("{}.expected.json", file.extension().unwrap().to_string_lossy()));
    std::fs::write(&path, serde_json::to_vec(expected).unwrap()).unwrap();
    path
}

/// The checker's one-line JSON summary, or everything it printed when it failed.
fn summary(what: &str, output: Output) -> Result<Value, String> {
    let stdout = String::from_utf8_lossy(&output.stdout);
    let stderr = String::from_utf8_lossy(&output.stderr);
    if !output.status.success() {
        return Err(format!("{what} failed ({}):\n--- stdout\n{stdout}--- stderr\n{stderr}", output.status));
    }
    let last = stdout.lines().rev().find(|l| !l.trim().is_empty()).unwrap_or("");
    serde_json::from_str(last).map_err(|e| format!("{what}: summary is not JSON ({e}):\n{stdout}\n{stderr}"))
}

/// The JSON a test's own usd-core script (`python -c script file`) prints about `file`.
pub fn usd_probe(script: &str, file: &Path) -> Value {
    require_pxr();
    let probe = Command::new(python()).args(["-c", script, file.to_str().unwrap()]).output().unwrap();
    assert!(probe.status.success(), "{}: {}", file.display(), String::from_utf8_lossy(&probe.stderr));
    serde_json::from_slice(&probe.stdout).unwrap()
}

/// `usd_check.py`: usd-core validation with every registered validator, then UsdSkel (or
/// `points`) evaluation at `expected.timecodes`. With `usdc`, also converts to usdc and
/// checks that the reopened file evaluates the same.
pub fn check_usd(file: &Path, expected: &Expected, usdc: bool) -> Value {
    try_check_usd(file, expected, usdc).unwrap_or_else(|e| panic!("{e}"))
}

/// [`check_usd`] returning the checker's failure instead of panicking (missing tools still
/// panic).
pub fn try_check_usd(file: &Path, expected: &Expected, usdc: bool) -> Result<Value, String> {
    require_pxr();
    let json = write_expected(file, expected);
    let mut cmd = Command::new(python());
    cmd.arg(checkers_dir().join("usd_check.py")).arg(file).arg(&json);
    if usdc {
        cmd.arg("--usdc");
    }
    let output = cmd.output().expect("run usd_check.py");
    summary(&format!("usd_check.py {}", file.display()), output)
}

/// `usd_same_layer.py`: usd-core opens both files without an error and finds the same layer
/// in them (as usd-core's own usda text, and spec by spec, field by field, sample by sample).
pub fn check_same_layer(usda: &Path, usdc: &Path) -> Value {
    require_pxr();
    let output = Command::new(python()).arg(checkers_dir().join("usd_same_layer.py")).arg(usda).arg(usdc).output().expect("run usd_same_layer.py");
    summary(&format!("usd_same_layer.py {} {}", usda.display(), usdc.display()), output).unwrap_or_else(|e| panic!("{e}"))
}

/// `gltf_check.mjs`: the Khronos validator (no errors, no warnings), then three.js's
/// GLTFLoader and AnimationMixer evaluated at `expected.times`.
pub fn check_glb(file: &Path, expected: &Expected) -> Value {
    try_check_glb(file, expected).unwrap_or_else(|e| panic!("{e}"))
}

/// [`check_glb`] returning the checker's failure instead of panicking (missing tools still
/// panic).
pub fn try_check_glb(file: &Path, expected: &Expected) -> Result<Value, String> {
    require_node_modules(&["gltf-validator", "three"]);
    let json = write_expected(file, expected);
    let output = Command::new("node").arg(checkers_dir().join("gltf_check.mjs")).arg(file).arg(&json).output().expect("run gltf_check.mjs");
    summary(&format!("gltf_check.mjs {}", file.display()), output)
}

/// `babylon_check.mjs`: Babylon.js (NullEngine, in Node) plays the glb within
/// `expected.tolerance` of the expected points, in scene units through the node transform.
pub fn check_babylon(file: &Path, expected: &Expected) -> Value {
    require_node_modules(&["@babylonjs/core", "@babylonjs/loaders"]);
    let json = write_expected(file, expected);
    let output = Command::new("node").arg(checkers_dir().join("babylon_check.mjs")).arg(file).arg(&json).output().expect("run babylon_check.mjs");
    summary(&format!("babylon_check.mjs {}", file.display()), output).unwrap_or_else(|e| panic!("{e}"))
}

/// `render_check.mjs`: three.js in headless Chromium renders the file at two animation times
/// (`times`, or the start and middle of the animation), writes both PNGs to `out_dir`, and
/// checks that the mesh is visible and moves.
pub fn render_glb(file: &Path, out_dir: &Path, times: Option<[f64; 2]>) -> Value {
    require_node_modules(&["three", "playwright-core"]);
    assert!(Path::new("/usr/bin/chromium").is_file(), "/usr/bin/chromium is missing: run `make test-deps` (apt-get install chromium)");
    let mut cmd = Command::new("node");
    cmd.arg(checkers_dir().join("render_check.mjs")).arg(file).arg(out_dir);
    if let Some([a, b]) = times {
        cmd.arg(format!("--times={a},{b}"));
    }
    let output = cmd.output().expect("run render_check.mjs");
    summary(&format!("render_check.mjs {}", file.display()), output).unwrap_or_else(|e| panic!("{e}"))
}

/// `texture_check.mjs`: each glb rendered by three.js in headless Chromium at each pose's time
/// with its own texture, against the pose's OBJ keyframe loaded by OBJLoader with `texture`
/// (unlit, same camera, looking along `view`). Returns the summary whatever the verdict
/// (`files`: one entry per glb, each with its own `ok` and per-time `mismatch`); the caller
/// decides which files must pass.
pub fn check_texture(files: &[&Path], texture: &Path, out_dir: &Path, poses: &[(f64, &Path)], view: [f64; 3]) -> Value {
    require_node_modules(&["three", "playwright-core"]);
    assert!(Path::new("/usr/bin/chromium").is_file(), "/usr/bin/chromium is missing: run `make test-deps` (apt-get install chromium)");
    let list: Vec<String> = files.iter().map(|f| f.to_string_lossy().into_owned()).collect();
    let mut cmd = Command::new("node");
    cmd.arg(checkers_dir().join("texture_check.mjs")).arg(list.join(",")).arg(texture).arg(out_dir);
    for (t, obj) in poses {
        cmd.arg(format!("{t}={}", obj.display()));
    }
    cmd.arg(format!("--view={},{},{}", view[0], view[1], view[2]));
    let output = cmd.output().expect("run texture_check.mjs");
    let stdout = String::from_utf8_lossy(&output.stdout);
    let last = stdout.lines().rev().find(|l| !l.trim().is_empty()).unwrap_or("");
    match serde_json::from_str::<Value>(last) {
        Ok(v) if v["files"].as_array().is_some_and(|f| f.len() == files.len()) => v,
        _ => panic!(
            "texture_check.mjs gave no summary ({}):\n--- stdout\n{stdout}--- stderr\n{}",
            output.status,
            String::from_utf8_lossy(&output.stderr)
        ),
    }
}

/// The Python that has Blender's `bpy`: `$BLENDSIM_BLENDER_PYTHON`, or the venv `make
/// deps-blender` creates in build/blender-venv.
fn blender_python() -> PathBuf {
    std::env::var_os("BLENDSIM_BLENDER_PYTHON")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("build/blender-venv/bin/python"))
}

/// [`blender_python`], which must exist: a Blender test fails (never skips) without it.
pub fn required_blender_python() -> PathBuf {
    let python = blender_python();
    assert!(
        python.exists(),
        "{} is missing: run `make deps-blender` (or `make test-deps`), or set BLENDSIM_BLENDER_PYTHON to a Python 3.11 with bpy==4.2.0",
        python.display()
    );
    python
}

/// `blender_check.py`: each file imported into Blender (bpy 4.2.0) with its own importer at
/// default settings, evaluated through the depsgraph at `expected.timecodes` (USD) or
/// `expected.times` (glTF) in world space, and compared with the expected points placed z up in
/// meters. One Blender process for all the files. Returns the summary (`files`: one entry per
/// file, in order, each with its own `ok`); the caller decides which files must pass.
///
/// Blender 4.2.0 can crash while its interpreter shuts down after a glTF import; the script
/// leaves with `os._exit` once its summary is printed, and a crash after a complete summary is
/// judged by the summary (and noted in it as `exit`).
pub fn check_blender(files: &[(&Path, &Expected)]) -> Value {
    let python = required_blender_python();
    let mut cmd = Command::new(&python);
    cmd.arg(checkers_dir().join("blender_check.py"));
    for (file, expected) in files {
        cmd.arg(file).arg(write_expected(file, expected));
    }
    let output = cmd.output().unwrap_or_else(|e| panic!("cannot run {} ({e}): run `make deps-blender`", python.display()));
    let stdout = String::from_utf8_lossy(&output.stdout);
    let stderr = String::from_utf8_lossy(&output.stderr);
    let last = stdout.lines().rev().find(|l| !l.trim().is_empty()).unwrap_or("");
    let mut summary: Value = match serde_json::from_str::<Value>(last) {
        Ok(v) if v["files"].as_array().is_some_and(|f| f.len() == files.len()) => v,
        _ => panic!("blender_check.py gave no summary ({}):\n--- stdout\n{stdout}--- stderr\n{stderr}", output.status),
    };
    summary["exit"] = output.status.code().map_or_else(|| Value::from(output.status.to_string()), Value::from);
    summary
}

/// `report_check.mjs`: a bake's `report.html` (or a batch's `summary.html`) opened from
/// `file://` in headless Chromium, refusing every other request; its plots, player and
/// scrubber (or links and sorting) checked, and html-validate's recommended rules. With
/// `screenshot`, the page is saved there. Returns the summary whatever the verdict.
pub fn check_report_html(file: &Path, screenshot: Option<&Path>) -> Value {
    require_node_modules(&["playwright-core", "html-validate"]);
    assert!(Path::new("/usr/bin/chromium").is_file(), "/usr/bin/chromium is missing: run `make test-deps` (apt-get install chromium)");
    let mut cmd = Command::new("node");
    cmd.arg(checkers_dir().join("report_check.mjs")).arg(file);
    if let Some(s) = screenshot {
        cmd.arg(s);
    }
    let output = cmd.output().expect("run report_check.mjs");
    let stdout = String::from_utf8_lossy(&output.stdout);
    let last = stdout.lines().rev().find(|l| !l.trim().is_empty()).unwrap_or("");
    serde_json::from_str(last).unwrap_or_else(|e| {
        panic!("report_check.mjs {}: summary is not JSON ({e}):\n{stdout}\n{}", file.display(), String::from_utf8_lossy(&output.stderr))
    })
}
