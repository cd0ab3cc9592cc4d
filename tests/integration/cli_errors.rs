//! Bad inputs and bad usage, through the `blendsim` binary as a user runs it.
//!
//! Every bad input must give exit code 1 and exactly one line on stderr, `error: FILE:
//! PROBLEM (fix: FIX)`, naming the offending file as the user can open it from where they ran
//! `blendsim`, and leave nothing behind: no output folder, no staging folder, no TetGen work
//! folder (the child's TMPDIR is a folder of the test's own, which must stay empty). Usage
//! errors exit 2. Each case builds its inputs in a fresh folder; meshes come from
//! `blendsim::procedural` and `blendsim::mesh::obj::write`, or are written out by hand.

use std::ffi::OsStr;
use std::path::Path;

use blendsim::mesh::{obj, TriMesh};
use blendsim::procedural::prism;

use crate::common::cli::{run, run_env, tree, Run, TempDir};

/// A closed 1 x 1 x 1 box surface with 2 segments per side (26 vertices, 48 triangles).
fn cube() -> TriMesh {
    prism([1.0, 1.0, 1.0], [2, 2, 2])
}

fn translated(mut mesh: TriMesh, by: [f64; 3]) -> TriMesh {
    for p in &mut mesh.positions {
        for d in 0..3 {
            p[d] += by[d];
        }
    }
    mesh
}

/// A minimal scene over the given keyframe files, one second apart, plus extra TOML lines
/// (`[keyframes]` keys first, then tables).
fn scene(meshes: &[&str], keyframe_lines: &str, tables: &str) -> String {
    let times: Vec<String> = (0..meshes.len()).map(|k| format!("{k}.0")).collect();
    let meshes: Vec<String> = meshes.iter().map(|m| format!("\"{m}\"")).collect();
    format!("name = \"t\"\n[keyframes]\nmeshes = [{}]\ntimes = [{}]\n{keyframe_lines}\n{tables}\n", meshes.join(", "), times.join(", "))
}

/// One bad bake: files written into `in/` of a fresh folder, `blendsim bake in/scene.toml
/// --out out/baked` run from that folder.
struct Case {
    name: &'static str,
    /// (file name in `in/`, contents); `scene.toml` is the scene.
    files: Vec<(&'static str, String)>,
    /// Extra arguments after `bake in/scene.toml --out out/baked`.
    args: Vec<&'static str>,
    /// Extra environment for the child.
    env: Vec<(&'static str, String)>,
}

/// Run a bad case and check everything common to bad inputs. Returns the run and the
/// folder (for case-specific checks).
fn bad_bake(case: Case) -> (Run, TempDir) {
    let dir = TempDir::new(&format!("errors-{}", case.name));
    std::fs::create_dir_all(dir.join("in")).unwrap();
    std::fs::create_dir_all(dir.join("tmp")).unwrap();
    for (name, text) in &case.files {
        std::fs::write(dir.join("in").join(name), text).unwrap();
    }
    let before = tree(&dir.path);
    let mut args = vec!["bake", "in/scene.toml", "--out", "out/baked"];
    args.extend(&case.args);
    let tmp = dir.join("tmp");
    let mut env: Vec<(&str, &OsStr)> = vec![("TMPDIR", tmp.as_os_str())];
    env.extend(case.env.iter().map(|(k, v)| (*k, OsStr::new(v))));
    let r = run_env(&dir.path, &args, &env);
    assert_eq!(r.code, Some(1), "{}: bad input must exit 1:\n{r}", case.name);
    assert_one_line_error(&r);
    assert!(r.stdout.is_empty(), "nothing on stdout:\n{r}");
    assert!(!dir.join("out").exists(), "a failed bake created its output folder:\n{r}");
    assert_eq!(tree(&dir.path), before, "a failed bake left files behind (staging, TetGen work folders):\n{r}");
    (r, dir)
}

/// Exactly one line on stderr: `error: ... (fix: ...)`.
fn assert_one_line_error(r: &Run) {
    assert!(r.stderr.starts_with("error: "), "stderr must start with `error: `:\n{r}");
    assert!(r.stderr.ends_with('\n') && r.stderr.lines().count() == 1, "stderr must be exactly one line:\n{r}");
    let fix = r.stderr.find("(fix: ").unwrap_or_else(|| panic!("the message gives no fix:\n{r}"));
    assert!(r.stderr.trim_end().ends_with(')') && r.stderr.len() - fix > 12, "the fix is empty:\n{r}");
}

/// The message names `file` (a path relative to where blendsim ran) right after `error: `.
fn assert_names(r: &Run, file: &str) {
    assert!(r.stderr.starts_with(&format!("error: {file}: ")), "the message must start by naming {file}:\n{r}");
}

fn assert_says(r: &Run, problem: &str) {
    assert!(r.stderr.contains(problem), "the message must say {problem:?}:\n{r}");
}

#[test]
fn different_vertex_counts_between_keyframes() {
    let (r, _dir) = bad_bake(Case {
        name: "vertex-counts",
        files: vec![
            ("k0.obj", obj::write(&cube())),
            ("k1.obj", obj::write(&prism([1.0, 1.0, 1.0], [3, 2, 2]))),
            ("scene.toml", scene(&["k0.obj", "k1.obj"], "", "")),
        ],
        args: vec![],
        env: vec![],
    });
    assert_names(&r, "in/k1.obj");
    assert_says(&r, "has 34 vertices but in/k0.obj has 26");
}

#[test]
fn same_counts_but_different_triangles() {
    // The same vertices, but the first quad split along its other diagonal.
    let mut flipped = cube();
    let ([q00, q11, q10], q01) = (flipped.triangles[0], flipped.triangles[1][1]);
    assert_eq!(flipped.triangles[1], [q00, q01, q11], "the prism's first quad is split along q00-q11");
    flipped.triangles[0] = [q00, q01, q10];
    flipped.triangles[1] = [q01, q11, q10];
    let (r, _dir) = bad_bake(Case {
        name: "triangles",
        files: vec![
            ("k0.obj", obj::write(&cube())),
            ("k1.obj", obj::write(&flipped)),
            ("scene.toml", scene(&["k0.obj", "k1.obj"], "", "")),
        ],
        args: vec![],
        env: vec![],
    });
    assert_names(&r, "in/k1.obj");
    assert_says(&r, "connect different vertices");
}

/// The prism with one triangle removed: TetGen itself would exit 0 with no tets.
fn holed() -> TriMesh {
    let mut m = cube();
    m.triangles.remove(5);
    m
}

#[test]
fn a_surface_with_a_hole() {
    let (r, _dir) = bad_bake(Case {
        name: "hole",
        files: vec![("k0.obj", obj::write(&holed())), ("scene.toml", scene(&["k0.obj", "k0.obj"], "", ""))],
        args: vec![],
        env: vec![],
    });
    assert!(r.stderr.starts_with("error: ") && r.stderr.contains("k0.obj: "), "names the surface:\n{r}");
    assert_says(&r, "the surface has a hole");
    assert_says(&r, "(3 open edges in all)");
}

/// Two overlapping boxes in one OBJ: each is closed, together they cross each other.
fn two_overlapping_boxes() -> TriMesh {
    let a = prism([1.0, 1.0, 1.0], [1, 1, 1]);
    let b = translated(prism([1.0, 1.0, 1.0], [1, 1, 1]), [0.5, 0.3, 0.4]);
    let n = a.positions.len() as u32;
    let mut m = a;
    m.positions.extend(b.positions);
    m.triangles.extend(b.triangles.iter().map(|t| t.map(|v| v + n)));
    m
}

#[test]
fn a_self_intersecting_surface() {
    let (r, _dir) = bad_bake(Case {
        name: "self-intersecting",
        files: vec![("k0.obj", obj::write(&two_overlapping_boxes())), ("scene.toml", scene(&["k0.obj", "k0.obj"], "", ""))],
        args: vec![],
        env: vec![],
    });
    assert!(r.stderr.starts_with("error: ") && r.stderr.contains("k0.obj: "), "names the surface:\n{r}");
    assert_says(&r, "the surface intersects itself: triangle ");
    assert_says(&r, "boolean-union");
}

#[test]
fn no_tetgen_installed() {
    let (r, _dir) = bad_bake(Case {
        name: "no-tetgen",
        files: vec![("k0.obj", obj::write(&cube())), ("scene.toml", scene(&["k0.obj", "k0.obj"], "", ""))],
        args: vec![],
        env: vec![("BLENDSIM_TETGEN", "/nonexistent/tetgen".into())],
    });
    assert!(r.stderr.starts_with("error: ") && r.stderr.contains("k0.obj: "), "names the surface:\n{r}");
    assert_says(&r, "`tetgen` is not installed");
    assert_says(&r, "(fix: apt-get install tetgen");
}

/// The same with the default program name: no `tetgen` on PATH (and BLENDSIM_TETGEN empty,
/// which means unset).
#[test]
fn no_tetgen_on_path() {
    let (r, _dir) = bad_bake(Case {
        name: "no-tetgen-on-path",
        files: vec![("k0.obj", obj::write(&cube())), ("scene.toml", scene(&["k0.obj", "k0.obj"], "", ""))],
        args: vec![],
        env: vec![("PATH", "/nonexistent/bin".into()), ("BLENDSIM_TETGEN", String::new())],
    });
    assert_says(&r, "`tetgen` is not installed (starting `tetgen` failed");
    assert_says(&r, "(fix: apt-get install tetgen");
}

/// TetGen's errors name the surface only as the scene file spells it (`k0.obj`), not as a
/// path from where blendsim runs (`in/k0.obj`), unlike every other input error.
#[test]
fn tetgen_errors_name_the_surface_from_the_working_folder() {
    let cases = [
        ("hole-path", obj::write(&holed()), vec![]),
        ("self-intersecting-path", obj::write(&two_overlapping_boxes()), vec![]),
        ("no-tetgen-path", obj::write(&cube()), vec![("BLENDSIM_TETGEN", "/nonexistent/tetgen".to_string())]),
    ];
    for (name, mesh, env) in cases {
        let (r, _dir) =
            bad_bake(Case { name, files: vec![("k0.obj", mesh), ("scene.toml", scene(&["k0.obj", "k0.obj"], "", ""))], args: vec![], env });
        assert_names(&r, "in/k0.obj");
    }
}

#[test]
fn a_missing_keyframe_file() {
    let (r, _dir) = bad_bake(Case {
        name: "missing",
        files: vec![("k0.obj", obj::write(&cube())), ("scene.toml", scene(&["k0.obj", "k1.obj"], "", ""))],
        args: vec![],
        env: vec![],
    });
    assert_names(&r, "in/k1.obj");
    assert_says(&r, "cannot read");
    assert_says(&r, "(fix: check the path");
}

#[test]
fn a_missing_scene_file() {
    let (r, _dir) = bad_bake(Case { name: "missing-scene", files: vec![], args: vec![], env: vec![] });
    assert_names(&r, "in/scene.toml");
    assert_says(&r, "cannot read the scene file");
}

#[test]
fn a_malformed_obj() {
    let text = obj::write(&cube()) + "f 1 2 x\n";
    let line = text.lines().count();
    let (r, _dir) = bad_bake(Case {
        name: "malformed",
        files: vec![("k0.obj", obj::write(&cube())), ("k1.obj", text), ("scene.toml", scene(&["k0.obj", "k1.obj"], "", ""))],
        args: vec![],
        env: vec![],
    });
    assert_names(&r, "in/k1.obj");
    assert_says(&r, &format!("line {line}: face corner `x`"));
}

#[test]
fn an_unknown_scene_key() {
    let text = scene(&["k0.obj", "k0.obj"], "", "[material]\nstifness = 1");
    let line = text.lines().position(|l| l.starts_with("stifness")).unwrap() + 1;
    let (r, _dir) = bad_bake(Case {
        name: "unknown-key",
        files: vec![("k0.obj", obj::write(&cube())), ("scene.toml", text)],
        args: vec![],
        env: vec![],
    });
    assert_names(&r, "in/scene.toml");
    assert_says(&r, &format!("line {line}: unknown field `stifness`"));
    assert_says(&r, "(fix: remove or rename the key");
}

#[test]
fn an_index_file_selecting_a_vertex_out_of_range() {
    let (r, _dir) = bad_bake(Case {
        name: "index-range",
        files: vec![
            ("k0.obj", obj::write(&cube())),
            ("ends.txt", "# held vertices\n0\n1\n26\n".into()),
            ("scene.toml", scene(&["k0.obj", "k0.obj"], "fixed = [\"all\", \"ends.txt\"]", "")),
        ],
        args: vec![],
        env: vec![],
    });
    assert_names(&r, "in/ends.txt");
    assert_says(&r, "line 4: vertex 26 does not exist (the mesh has 26 vertices");
}

#[test]
fn a_dmat_selection_of_the_wrong_size() {
    // libigl ASCII .dmat: "cols rows", then one flag per vertex; here 30 rows for 26 vertices.
    let dmat = format!("1 30\n{}", "0\n1\n".repeat(15));
    let (r, _dir) = bad_bake(Case {
        name: "dmat-range",
        files: vec![
            ("k0.obj", obj::write(&cube())),
            ("tail.dmat", dmat),
            ("scene.toml", scene(&["k0.obj", "k0.obj"], "fixed = [\"all\", { file = \"tail.dmat\", invert = true }]", "")),
        ],
        args: vec![],
        env: vec![],
    });
    assert_names(&r, "in/tail.dmat");
    assert_says(&r, "is a 30x1 matrix but the mesh has 26 vertices");
}

#[test]
fn cyclic_with_a_last_key_unlike_the_first() {
    let (r, _dir) = bad_bake(Case {
        name: "cyclic",
        files: vec![
            ("k0.obj", obj::write(&cube())),
            ("k1.obj", obj::write(&translated(cube(), [0.0, 0.5, 0.0]))),
            ("k2.obj", obj::write(&translated(cube(), [0.0, 0.01, 0.0]))),
            ("scene.toml", scene(&["k0.obj", "k1.obj", "k2.obj"], "cyclic = true", "")),
        ],
        args: vec![],
        env: vec![],
    });
    assert_names(&r, "in/k2.obj");
    assert_says(&r, "cyclic = true, but the last keyframe differs from the first");
    assert_says(&r, "(fix: repeat the first keyframe's mesh");
}

/// A usdc bake with a Python that cannot give usd-core's `pxr`: fails after the solve, and
/// must still leave nothing (the staged .usda and the staging folder go too).
fn usdc_without_pxr(name: &'static str, python: String) -> Run {
    let (r, _dir) = bad_bake(Case {
        name,
        files: vec![
            ("k0.obj", obj::write(&cube())),
            ("k1.obj", obj::write(&translated(cube(), [0.0, 0.5, 0.0]))),
            ("scene.toml", scene(&["k0.obj", "k1.obj"], "", "[export]\nformats = [\"usda\", \"usdc\", \"glb\"]")),
        ],
        args: vec![],
        env: vec![("BLENDSIM_PYTHON", python)],
    });
    assert_says(&r, "out/baked/t.usdc: ");
    assert_says(&r, "(fix: pip install usd-core");
    r
}

#[test]
fn usdc_with_no_python() {
    let r = usdc_without_pxr("usdc-no-python", "/nonexistent/python3".into());
    assert_says(&r, "cannot run /nonexistent/python3");
}

#[test]
fn usdc_with_a_python_lacking_pxr() {
    // The real interpreter with its site-packages (where usd-core lives) turned off.
    let out = std::process::Command::new("python3").args(["-c", "import sys; print(sys.executable)"]).output().expect("python3 runs");
    let python = String::from_utf8(out.stdout).unwrap().trim().to_string();
    let wrapper = TempDir::new("errors-python-wrapper");
    let script = wrapper.join("python3-without-site");
    std::fs::write(&script, format!("#!/bin/sh\nexec {python} -S \"$@\"\n")).unwrap();
    std::fs::set_permissions(&script, std::os::unix::fs::PermissionsExt::from_mode(0o755)).unwrap();
    let r = usdc_without_pxr("usdc-no-pxr", script.to_string_lossy().into_owned());
    assert_says(&r, "cannot import usd-core's pxr module");
}

/// A good tiny scene and its stage files, made by the chain of subcommands.
fn stage_files(dir: &Path) {
    std::fs::create_dir_all(dir.join("in")).unwrap();
    std::fs::write(dir.join("in/k0.obj"), obj::write(&cube())).unwrap();
    std::fs::write(dir.join("in/k1.obj"), obj::write(&translated(cube(), [0.0, 0.5, 0.0]))).unwrap();
    std::fs::write(dir.join("in/scene.toml"), scene(&["k0.obj", "k1.obj"], "", "")).unwrap();
    for args in [
        ["import", "in/scene.toml", "-o", "keys.json"],
        ["tetrahedralize", "keys.json", "-o", "body.json"],
        ["solve", "body.json", "-o", "solution.json"],
        ["embed", "solution.json", "-o", "animation.json"],
    ] {
        run(dir, &args).success();
    }
    run(dir, &["export", "animation.json", "--out", "exported"]).success();
}

#[test]
fn a_wrong_stage_file_passed_to_a_subcommand() {
    let dir = TempDir::new("errors-wrong-stage");
    stage_files(&dir.path);
    let before = tree(&dir.path);
    let cases: [(&[&str], &str, &str); 7] = [
        (
            &["solve", "keys.json", "-o", "new.json"],
            "keys.json",
            "holds a 'keyframes' stage, not 'body' (fix: pass the body file written by `blendsim tetrahedralize`)",
        ),
        (&["tetrahedralize", "body.json", "-o", "new.json"], "body.json", "holds a 'body' stage, not 'keyframes'"),
        (&["embed", "animation.json", "-o", "new.json"], "animation.json", "holds a 'animation' stage, not 'solution'"),
        (&["export", "solution.json", "--out", "new"], "solution.json", "holds a 'solution' stage, not 'animation'"),
        (&["report", "animation.json", "--outputs", "animation.json", "--out", "new"], "animation.json", "not 'outputs'"),
        (&["embed", "in/scene.toml", "-o", "new.json"], "in/scene.toml", "is not a blendsim stage file"),
        (&["solve", "in/k0.obj", "-o", "new.json"], "in/k0.obj", "is not a blendsim stage file"),
    ];
    for (args, file, problem) in cases {
        let r = run(&dir.path, args);
        assert_eq!(r.code, Some(1), "{args:?}:\n{r}");
        assert_one_line_error(&r);
        assert_names(&r, file);
        assert_says(&r, problem);
        assert_eq!(tree(&dir.path), before, "{args:?} left files behind:\n{r}");
    }
}

#[test]
fn usage_errors_exit_2() {
    let dir = TempDir::new("errors-usage");
    stage_files(&dir.path);
    let before = tree(&dir.path);
    let cases: [&[&str]; 9] = [
        &[],
        &["frobnicate"],
        &["bake"],
        &["bake", "in/scene.toml"],
        &["bake", "--out", "new"],
        &["bake", "in/scene.toml", "--out", "new", "--method", "magic"],
        &["import", "in/scene.toml"],
        &["solve", "body.json", "-o", "new.json", "--bogus"],
        &["report", "animation.json", "--out", "new"],
    ];
    for args in cases {
        let r = run(&dir.path, args);
        assert_eq!(r.code, Some(2), "usage error {args:?} must exit 2:\n{r}");
        assert!(r.stderr.contains("Usage: blendsim") || r.stderr.contains("try '--help'"), "{args:?}: stderr points to the usage:\n{r}");
        assert!(r.stdout.is_empty(), "{args:?}:\n{r}");
        assert_eq!(tree(&dir.path), before, "{args:?} created files:\n{r}");
    }
}

/// `--help` of the tool and of every subcommand exits 0 and names what it reads and writes.
#[test]
fn help_of_every_subcommand() {
    let dir = TempDir::new("errors-help");
    let cases: [(&str, &[&str]); 8] = [
        ("", &["import", "tetrahedralize", "solve", "embed", "export", "report", "bake", "--quiet"]),
        ("import", &["<SCENE>", "scene file", "--output", "keyframes stage file"]),
        ("tetrahedralize", &["<KEYFRAMES>", "keyframes stage file", "--output", "body stage file", "TetGen"]),
        ("solve", &["<BODY>", "body stage file", "--output", "solution stage file", "--method", "hermite", "spacetime"]),
        ("embed", &["<SOLUTION>", "solution stage file", "--output", "animation stage file"]),
        (
            "export",
            &["<ANIMATION>", "animation stage file", "--out", "NAME.usda", "NAME.usdc", "NAME.glb", "NAME.full.EXT", "NAME.outputs.json"],
        ),
        ("report", &["<ANIMATION>", "animation stage file", "--outputs", "NAME.outputs.json", "--out", "report.json", "report.md"]),
        ("bake", &["<SCENE>", "scene file", "--out", "NAME.usda", "NAME.glb", "NAME.full.EXT", "report.json", "report.md", "--method"]),
    ];
    for (sub, words) in cases {
        let args: Vec<&str> = if sub.is_empty() { vec!["--help"] } else { vec![sub, "--help"] };
        let r = run(&dir.path, &args);
        assert_eq!(r.code, Some(0), "{args:?}:\n{r}");
        assert!(r.stderr.is_empty(), "{args:?}:\n{r}");
        for w in words {
            assert!(r.stdout.contains(w), "`blendsim {}` must mention {w:?}:\n{r}", args.join(" "));
        }
        if !sub.is_empty() {
            // `blendsim help SUB` says the same.
            let h = run(&dir.path, &["help", sub]);
            assert_eq!((h.code, &h.stdout), (Some(0), &r.stdout), "blendsim help {sub}");
        }
    }
    assert!(tree(&dir.path).is_empty());
}
