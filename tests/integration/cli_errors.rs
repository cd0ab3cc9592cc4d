//! Bad inputs and bad usage, through the `blendsim` binary as a user runs it.
//!
//! Every bad input must give exit code 1 and exactly one line on stderr, `error: FILE:
//! PROBLEM (fix: FIX)`, naming the offending file as the user can open it from where they ran
//! `blendsim`, and leave nothing behind: no output folder, no staging folder, no TetGen work
//! folder (the child's TMPDIR is a folder of the test's own, which must stay empty). Usage
//! errors exit 2. Each case builds its inputs in a fresh folder; meshes come from
//! `blendsim::algorithms::procedural` and `blendsim::formats::mesh::obj::write`, or are written out by hand.
//! `corpus_of_bad_inputs` runs a table of bad inputs of every family twice, into a fresh
//! place and over a good bake (which must stay byte-identical), and prints the table of
//! messages with `--nocapture`.

use std::ffi::OsStr;
use std::path::Path;

use blendsim::algorithms::geometry::TriMesh;
use blendsim::algorithms::procedural::prism;
use blendsim::formats::mesh::obj;

use crate::common::cli::{run, run_env, tree, Run, TempDir};

/// A closed 1 x 1 x 1 box surface with 2 segments per side (26 vertices, 48 triangles).
fn cube() -> TriMesh {
    prism([1.0, 1.0, 1.0], [2, 2, 2])
}

fn scaled(mut mesh: TriMesh, by: [f64; 3]) -> TriMesh {
    for p in &mut mesh.positions {
        for d in 0..3 {
            p[d] *= by[d];
        }
    }
    mesh
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
        files: vec![("k0.obj", obj::write(&cube())), ("k1.obj", obj::write(&flipped)), ("scene.toml", scene(&["k0.obj", "k1.obj"], "", ""))],
        args: vec![],
        env: vec![],
    });
    assert_names(&r, "in/k1.obj");
    assert_says(&r, "connect different vertices");
}

/// Messy surfaces bake through an automatic cage by default (tests/integration/cli_cage.rs);
/// with the cage off they reach TetGen, whose failures must still be one clear line.
const CAGE_OFF: &str = "[tet]\ncage = false";

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
        files: vec![("k0.obj", obj::write(&holed())), ("scene.toml", scene(&["k0.obj", "k0.obj"], "", CAGE_OFF))],
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
        files: vec![("k0.obj", obj::write(&two_overlapping_boxes())), ("scene.toml", scene(&["k0.obj", "k0.obj"], "", CAGE_OFF))],
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
            bad_bake(Case { name, files: vec![("k0.obj", mesh), ("scene.toml", scene(&["k0.obj", "k0.obj"], "", CAGE_OFF))], args: vec![], env });
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
    let (r, _dir) =
        bad_bake(Case { name: "unknown-key", files: vec![("k0.obj", obj::write(&cube())), ("scene.toml", text)], args: vec![], env: vec![] });
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
        ("import", &["<SCENE>", "scene file", "-o, --out", "keyframes stage file"]),
        ("tetrahedralize", &["<KEYFRAMES>", "keyframes stage file", "-o, --out", "body stage file", "TetGen"]),
        ("solve", &["<BODY>", "body stage file", "-o, --out", "solution stage file", "--method", "hermite", "spacetime"]),
        ("embed", &["<SOLUTION>", "solution stage file", "-o, --out", "animation stage file"]),
        ("export", &["<ANIMATION>", "animation stage file", "--out", "NAME.usda", "NAME.usdc", "NAME.glb", "NAME.full.EXT", "NAME.outputs.json"]),
        (
            "report",
            &["[ANIMATION]", "animation stage file", "--outputs", "NAME.outputs.json", "--out", "report.json", "report.md", "--batch", "summary.csv"],
        ),
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

// --- The corpus: bad inputs of every family, each into a fresh place and over a good bake. ---

/// A file of a corpus case.
enum Content {
    Text(String),
    Bytes(Vec<u8>),
    Fifo,
    Folder,
    Link(&'static str),
}

struct Bad {
    name: &'static str,
    files: Vec<(String, Content)>,
    /// The file the message must name, as a path from where blendsim runs.
    names: String,
    says: Vec<String>,
}

fn text(name: &str, content: impl Into<String>) -> (String, Content) {
    (name.to_string(), Content::Text(content.into()))
}

/// A two-tet MEDIT mesh (the second tet written with negative orientation).
const TWO_TETS: &str = "MeshVersionFormatted 1\nDimension 3\nVertices 5\n0 0 0 1\n1 0 0 1\n0 1 0 1\n0 0 1 1\n0 0 -1 7\n\
                        Tetrahedra 2\n1 2 3 4 1\n1 2 3 5 1\nEnd\n";

/// The good scene over k0.obj and k1.obj with extra `[keyframes]` lines and tables.
fn good_scene(keyframe_lines: &str, tables: &str) -> String {
    scene(&["k0.obj", "k1.obj"], keyframe_lines, tables)
}

fn bad(name: &'static str, files: Vec<(String, Content)>, names: &str, says: &[&str]) -> Bad {
    let mut all = vec![text("k0.obj", obj::write(&cube())), text("k1.obj", obj::write(&translated(cube(), [0.0, 0.5, 0.0])))];
    for f in files {
        all.retain(|(n, _)| *n != f.0);
        all.push(f);
    }
    Bad { name, files: all, names: names.to_string(), says: says.iter().map(|s| s.to_string()).collect() }
}

/// A scene-file case: the good scene edited by `edit`.
fn bad_scene(name: &'static str, scene_text: String, says: &[&str]) -> Bad {
    bad(name, vec![text("scene.toml", scene_text)], "in/scene.toml", says)
}

fn corpus() -> Vec<Bad> {
    let base = good_scene("", "");
    let with = |line: &str| good_scene(line, "");
    let table = |t: &str| good_scene("", t);
    let renamed = |n: &str| base.replacen("name = \"t\"", &format!("name = {n}"), 1);
    let key1 = |content: String| vec![text("scene.toml", base.clone()), text("k1.obj", content)];
    let cube_obj = obj::write(&cube());
    let moved = |t: &str| TWO_TETS.replace("0 0 1 1\n", t);
    let tets = |k1: String| vec![text("k0.mesh", TWO_TETS), text("k1.mesh", k1), text("scene.toml", scene(&["k0.mesh", "k1.mesh"], "", ""))];
    let dmat = |values: &str| {
        vec![text("sel.dmat", format!("1 26\n{}{values}\n", "0\n".repeat(25))), text("scene.toml", with("fixed = [\"all\", \"sel.dmat\"]"))]
    };
    let index = |content: &str| vec![text("ends.txt", content), text("scene.toml", with("fixed = [\"all\", \"ends.txt\"]"))];
    let huge = "7".repeat(1_000_000);
    // Keys in the material `wood` of m.mtl, whose texture is `tex`.
    let textured = |mtl: Content, tex: Option<Content>| {
        let with_mtl = |mesh: TriMesh| format!("mtllib m.mtl\nusemtl wood\n{}", obj::write(&mesh));
        let mut files = vec![
            text("k0.obj", with_mtl(cube())),
            text("k1.obj", with_mtl(translated(cube(), [0.0, 0.5, 0.0]))),
            ("m.mtl".to_string(), mtl),
            text("scene.toml", base.clone()),
        ];
        files.extend(tex.map(|t| ("tex.png".to_string(), t)));
        files
    };
    let mtl = || Content::Text("newmtl wood\nmap_Kd tex.png\n".into());
    let png = crate::texture::png(2, 2, |x, y| [64 * x as u8, 64 * y as u8, 128]);
    // The same PNG, its header claiming 10^6 x 10^6 pixels (the CRC made to match).
    let mut claiming = png.clone();
    claiming[16..24].copy_from_slice(&[1_000_000u32.to_be_bytes(), 1_000_000u32.to_be_bytes()].concat());
    let crc = crate::texture::crc32(&claiming[12..29]);
    claiming[29..33].copy_from_slice(&crc.to_be_bytes());
    let garbage = [&png[..8], &[0x5a; 64]].concat();
    let material = |key: &str, value: &str| table(&format!("[material]\n{key} = {value}"));
    vec![
        // The scene file itself.
        bad_scene("scene-syntax", "name = \"t\"\n[keyframes\nmeshes = []\n".into(), &["line 2: "]),
        bad_scene("scene-missing-table", "name = \"t\"\n".into(), &["neither [keyframes] nor [cache]", "(fix: add a [keyframes] table"]),
        bad_scene("scene-unknown-table", table("[solverr]\nsamples = 3"), &["unknown field `solverr`"]),
        bad(
            "scene-not-utf8",
            vec![("scene.toml".into(), Content::Bytes(b"name = \"caf\xe9\"\n".to_vec()))],
            "in/scene.toml",
            &["is not UTF-8 text (invalid byte at offset 11)"],
        ),
        bad("scene-fifo", vec![("scene.toml".into(), Content::Fifo)], "in/scene.toml", &["is a named pipe (FIFO), not a regular file"]),
        bad("scene-folder", vec![("scene.toml".into(), Content::Folder)], "in/scene.toml", &["is a folder, not a regular file"]),
        bad_scene("name-newline", renamed("\"a\\nb\""), &["name `a\\nb` cannot be a file stem: it contains a control character"]),
        bad_scene("name-escape", renamed("\"\\u001b[31mred\""), &["name `\\u{1b}[31mred` cannot be a file stem"]),
        bad_scene("name-carriage-return", renamed("\"a\\rb\""), &["name `a\\rb`", "contains a control character"]),
        bad_scene("name-parent", renamed("\"../escape\""), &["contains a path separator"]),
        bad_scene("name-backslash", renamed("\"a\\\\b\""), &["contains a path separator"]),
        bad_scene("name-hidden", renamed("\".t\""), &["starts with '.'"]),
        bad_scene("fps-zero", base.replacen("[keyframes]", "fps = 0\n[keyframes]", 1), &["fps = 0 must be positive"]),
        bad_scene("fps-nan", base.replacen("[keyframes]", "fps = nan\n[keyframes]", 1), &["fps = NaN must be positive"]),
        bad_scene("one-key", scene(&["k0.obj"], "", ""), &["[keyframes] has 1 mesh(es)"]),
        bad_scene("times-count", base.replace("times = [0.0, 1.0]", "times = [0.0, 1.0, 2.0]"), &["has 2 meshes but 3 times"]),
        bad_scene("times-decrease", base.replace("times = [0.0, 1.0]", "times = [1.0, 0.0]"), &["times decrease at key 1"]),
        bad_scene("times-equal", base.replace("times = [0.0, 1.0]", "times = [0.5, 0.5]"), &["keys 0 and 1 share the time 0.5"]),
        bad_scene("times-inf", base.replace("times = [0.0, 1.0]", "times = [0.0, inf]"), &["times[1] is not a number"]),
        bad_scene(
            "twist-inf",
            base.replace("\"k1.obj\"", "{ mesh = \"k1.obj\", twist = { axis = \"y\", degrees = inf } }"),
            &["meshes[1] has a twist of inf degrees", "(fix: give the twist angle as a finite number"],
        ),
        bad_scene(
            "twist-axial-scale",
            base.replace("\"k1.obj\"", "{ mesh = \"k1.obj\", twist = { axis = \"y\", degrees = 90.0, axial_scale = -1.0 } }"),
            &["meshes[1] has a twist with axial_scale = -1", "(fix: give a positive axial_scale"],
        ),
        bad_scene("rest-range", with("rest = 5"), &["rest = 5 but there are 2 keys"]),
        bad_scene("rest-negative", with("rest = -1"), &["rest key index must be >= 0"]),
        bad_scene("cyclic-two-keys", with("cyclic = true"), &["cyclic = true needs at least 3 keys"]),
        bad_scene("fixed-count", with("fixed = [\"all\"]"), &["fixed has 1 entries for 2 keys"]),
        bad_scene("slab-nan", with("fixed = [\"all\", { axis = \"y\", min = nan }]"), &["fixed[1]: the y slab has min = nan"]),
        bad_scene(
            "slab-crossed",
            with("fixed_velocity = [\"none\", [{ axis = \"x\", min = 2.0, max = 1.0 }]]"),
            &["fixed_velocity[1]: the x slab has min = 2 > max = 1"],
        ),
        bad_scene("slab-and-file", with("fixed = [\"all\", { file = \"a.txt\", axis = \"y\" }]"), &["either `file` or `axis`"]),
        bad_scene("gravity-four", table("[material]\ngravity = [0.0, -9.8, 0.0, 1.0]"), &["expected 3 components (x, y, z), found 4"]),
        bad_scene("gravity-nan", table("[material]\ngravity = [0.0, nan, 0.0]"), &["gravity has a non-finite component"]),
        bad_scene("quality", table("[tet]\nquality = 0.5"), &["[tet] quality = 0.5 must be >= 1"]),
        bad_scene("max-volume", table("[tet]\nmax_volume = -1.0"), &["[tet] max_volume = -1 must be >= 0"]),
        bad_scene("timeout", table("[tet]\ntimeout = 0"), &["[tet] timeout = 0 must be positive"]),
        bad_scene("density", table("[material]\ndensity = 0.0"), &["[material] density = 0 is out of range"]),
        // Once "singular: some motion costs nothing", with a fix that did not help.
        bad_scene("stiffness-1e308", material("stiffness", "1e308"), &["[material] stiffness = 1e308 is out of range (0 or 1e-30 to 1e30)"]),
        bad_scene("volume-1e308", material("volume", "1e308"), &["[material] volume = 1e308 is out of range"]),
        bad_scene("density-1e-300", material("density", "1e-300"), &["[material] density = 1e-300 is out of range (1e-30 to 1e30)"]),
        bad_scene("damping-huge", material("damping", "1e20"), &["[material] damping = 1e20 is out of range"]),
        // Numbers echoed short, not in 300 digits.
        bad_scene("tolerance-short", table("[solver]\ntolerance = -1e300"), &["tolerance = -1e300 must be positive"]),
        bad_scene("no-stiffness", table("[material]\nstiffness = 0.0\nvolume = 0.0"), &["stiffness and volume are both 0"]),
        bad_scene("samples-zero", table("[solver]\nsamples = 0"), &["[solver] samples = 0"]),
        bad_scene("samples-negative", table("[solver]\nsamples = -3"), &["line 7: invalid value: integer `-3`, expected usize"]),
        bad_scene("tolerance", table("[solver]\ntolerance = -1.0"), &["tolerance = -1 must be positive"]),
        bad_scene("regularization", table("[solver]\nregularization = -1.0"), &["regularization = -1 must be >= 0"]),
        bad_scene("method", table("[solver]\nmethod = \"magic\""), &["unknown variant `magic`"]),
        bad_scene("up-axis", table("[export]\nup_axis = \"x\""), &["up_axis = \"x\""]),
        bad_scene("meters-per-unit", table("[export]\nmeters_per_unit = 0.0"), &["meters_per_unit = 0 must be positive"]),
        bad_scene(
            "meters-per-unit-1e300",
            table("[export]\nmeters_per_unit = 1e300"),
            &["meters_per_unit = 1e300 is out of range (1e-6 to 1000000)"],
        ),
        bad_scene("meters-per-unit-1e-300", table("[export]\nmeters_per_unit = 1e-300"), &["meters_per_unit = 1e-300 is out of range"]),
        bad_scene("formats-empty", table("[export]\nformats = []"), &["formats is empty"]),
        bad_scene("formats-unknown", table("[export]\nformats = [\"fbx\"]"), &["unknown variant `fbx`"]),
        // OBJ keyframes.
        bad(
            "obj-nan",
            key1(cube_obj.replacen("v ", "v nan ", 1).replacen("nan 0", "nan", 1)),
            "in/k1.obj",
            &["line 1: vertex coordinate `nan` is not finite"],
        ),
        bad("obj-index-zero", key1(format!("{cube_obj}f 0 1 2\n")), "in/k1.obj", &["face refers to vertex 0, but OBJ vertex numbers start at 1"]),
        bad("obj-index-range", key1(format!("{cube_obj}f 1 2 99\n")), "in/k1.obj", &["face refers to vertex 99, but only 26 vertices"]),
        bad("obj-no-faces", key1("v 0 0 0\nv 1 0 0\n".into()), "in/k1.obj", &["has no faces (2 vertices"]),
        bad("obj-huge-token", key1(format!("v 0 0 {huge}x\n")), "in/k1.obj", &["line 1: vertex coordinate `7777", "(1000001 bytes) is not a number"]),
        bad(
            "obj-fifo",
            vec![("k1.obj".into(), Content::Fifo), text("scene.toml", base.clone())],
            "in/k1.obj",
            &["is a named pipe (FIFO), not a regular file, so it cannot be read as the OBJ surface"],
        ),
        bad(
            "obj-folder",
            vec![("k1.obj".into(), Content::Folder), text("scene.toml", base.clone())],
            "in/k1.obj",
            &["is a folder, not a regular file"],
        ),
        bad(
            "obj-device",
            vec![("k1.obj".into(), Content::Link("/dev/zero")), text("scene.toml", base.clone())],
            "in/k1.obj",
            &["is a device, not a regular file"],
        ),
        bad(
            "mesh-extension",
            vec![text("k1.stl", cube_obj.clone()), text("scene.toml", scene(&["k0.obj", "k1.stl"], "", ""))],
            "in/k1.stl",
            &["unknown mesh format"],
        ),
        bad(
            "path-escape",
            vec![text("scene.toml", scene(&["k0.obj", "k\\u001b[2J.obj"], "", ""))],
            "in/k\\u{1b}[2J.obj",
            &["cannot read the OBJ surface"],
        ),
        bad("path-newline", vec![text("scene.toml", scene(&["k0.obj", "k\\n1.obj"], "", ""))], "in/k\\n1.obj", &["cannot read the OBJ surface"]),
        bad("obj-vertex-count", key1(obj::write(&prism([1.0, 1.0, 1.0], [3, 2, 2]))), "in/k1.obj", &["has 34 vertices but in/k0.obj has 26"]),
        // MEDIT and TetGen keyframes.
        bad("medit-nan-row", tets(moved("nan 0 1 1\n")), "in/k1.mesh", &["line 7: Vertices row 4: `nan` is not a finite number"]),
        bad("medit-inf-row", tets(moved("0 inf 1 1\n")), "in/k1.mesh", &["Vertices row 4: `inf` is not a finite number"]),
        bad(
            "medit-index",
            tets(TWO_TETS.replace("1 2 3 5 1", "1 2 3 6 1")),
            "in/k1.mesh",
            &["Tetrahedra row 2 refers to vertex 6, but vertices are numbered 1 to 5"],
        ),
        bad("medit-flat", tets(TWO_TETS.replace("1 2 3 5 1", "1 2 3 3 1")), "in/k1.mesh", &["Tetrahedra row 2 (vertices 1 2 3 3) is flat"]),
        bad(
            "medit-count",
            tets(TWO_TETS.replace("Vertices 5", "Vertices 6")),
            "in/k1.mesh",
            &["`Vertices` declares 6 rows but only 5 follow before `Tetrahedra`"],
        ),
        bad("medit-no-tets", tets(TWO_TETS.replace("Tetrahedra 2\n1 2 3 4 1\n1 2 3 5 1\n", "")), "in/k1.mesh", &["has no tetrahedra"]),
        bad("medit-dimension", tets(TWO_TETS.replace("Dimension 3", "Dimension 2")), "in/k1.mesh", &["the mesh has dimension 2, blendsim needs 3"]),
        bad(
            "medit-huge-keyword",
            tets(format!("{}{TWO_TETS}", "Q".repeat(100_000))),
            "in/k1.mesh",
            &["line 1: `QQQQ", "(100020 bytes) declares 1 rows but only 0 follow before `Dimension`"],
        ),
        bad(
            "mixed-kinds",
            vec![text("k1.mesh", TWO_TETS), text("scene.toml", scene(&["k0.obj", "k1.mesh"], "", ""))],
            "in/k1.mesh",
            &["is a tet mesh but in/k0.obj is a surface"],
        ),
        bad(
            "tetgen-no-ele",
            vec![
                text("k0.node", "5 3 0 0\n0 0 0 0\n1 1 0 0\n2 0 1 0\n3 0 0 1\n4 0 0 -1\n"),
                text("scene.toml", scene(&["k0.node", "k0.node"], "", "")),
            ],
            "in/k0.ele",
            &["cannot read the TetGen tetrahedra"],
        ),
        bad(
            "tetgen-header",
            vec![text("k0.node", "x 3 0 0\n"), text("k0.ele", "0 4 0\n"), text("scene.toml", scene(&["k0.node", "k0.node"], "", ""))],
            "in/k0.node",
            &["line 1: the node count `x` is not a valid number"],
        ),
        // Keys the files' 32-bit positions cannot hold: once baked 19801 diagonals off.
        bad(
            "key-far-away",
            key1(obj::write(&translated(cube(), [1e12, 0.0, 0.0]))),
            "in/k1.obj",
            &["key 1 has a coordinate of 1.000e12, 5.8e11 times the rest shape's size (1.732e0) from the origin, beyond the 8192"],
        ),
        // Once "has no area", then a TetGen abort.
        bad(
            "box-1e300",
            vec![
                text("k0.obj", obj::write(&scaled(cube(), [1e300; 3]))),
                text("k1.obj", obj::write(&scaled(translated(cube(), [0.0, 0.5, 0.0]), [1e300; 3]))),
                text("scene.toml", base.clone()),
            ],
            "in/k0.obj",
            &["the surface is 1e300 units across, outside the 1e-30 to 1e30 that TetGen's arithmetic handles"],
        ),
        // Materials and textures: a FIFO once hung the bake; a folder or device "did not exist";
        // a damaged or huge PNG was embedded as it was.
        bad(
            "mtl-fifo",
            textured(Content::Fifo, None),
            "in/m.mtl",
            &["is a named pipe (FIFO), not a regular file, so it cannot be read as the material library"],
        ),
        bad(
            "texture-folder",
            textured(mtl(), Some(Content::Folder)),
            "in/m.mtl",
            &["line 2: map_Kd names the texture `tex.png`, which is a folder, not an image file"],
        ),
        bad(
            "texture-device",
            textured(mtl(), Some(Content::Link("/dev/zero"))),
            "in/m.mtl",
            &["line 2: map_Kd names the texture `tex.png`, which is a device, not an image file"],
        ),
        bad(
            "texture-damaged",
            textured(mtl(), Some(Content::Bytes(garbage))),
            "in/m.mtl",
            &["line 2: map_Kd names the texture `tex.png`, which is not a readable png image: ", "(fix: re-save the image"],
        ),
        bad(
            "texture-huge",
            textured(mtl(), Some(Content::Bytes(claiming))),
            "in/m.mtl",
            &[
                "which is a png image of 1000000 x 1000000 pixels, over the 16384 a side",
                "(fix: scale the image down to at most 16384 pixels a side)",
            ],
        ),
        bad("texture-gif", textured(mtl(), Some(Content::Bytes(b"GIF89a....".to_vec()))), "in/m.mtl", &["which is not a PNG or JPEG image"]),
        // Selection files.
        bad("dmat-half", dmat("0.5"), "in/sel.dmat", &["line 27: value `0.5` is neither 0 nor 1"]),
        bad("dmat-two", dmat("2"), "in/sel.dmat", &["value `2` is neither 0 nor 1"]),
        bad("dmat-negative", dmat("-1"), "in/sel.dmat", &["value `-1` is neither 0 nor 1"]),
        bad("dmat-nan", dmat("nan"), "in/sel.dmat", &["value `nan` is neither 0 nor 1"]),
        bad(
            "dmat-header",
            vec![text("sel.dmat", "2 26\n"), text("scene.toml", with("fixed = [\"all\", \"sel.dmat\"]"))],
            "in/sel.dmat",
            &["is a 26x2 matrix"],
        ),
        bad("index-word", index("0\nabc\n"), "in/ends.txt", &["line 2: `abc` is not a vertex index"]),
        bad("index-negative", index("-1\n"), "in/ends.txt", &["line 1: `-1` is not a vertex index"]),
        bad("index-missing", vec![text("scene.toml", with("fixed = [\"all\", \"ends.txt\"]"))], "in/ends.txt", &["cannot read the vertex selection"]),
        bad(
            "index-fifo",
            vec![("ends.txt".into(), Content::Fifo), text("scene.toml", with("fixed = [\"all\", \"ends.txt\"]"))],
            "in/ends.txt",
            &["is a named pipe (FIFO)"],
        ),
        bad(
            "embed-surface-missing",
            vec![text("scene.toml", table("[embed]\nsurface = \"fine.obj\""))],
            "in/fine.obj",
            &["cannot read the OBJ surface"],
        ),
        // Degenerate keys: once baked with volumes down to -100%.
        bad(
            "key-mirrored",
            key1(obj::write(&scaled(cube(), [-1.0, 1.0, 1.0]))),
            "in/k1.obj",
            &["key 1 is inside out (mirrored): it encloses -100.0% of the rest shape's volume"],
        ),
        bad("key-flattened", key1(obj::write(&scaled(cube(), [1.0, 0.0, 1.0]))), "in/k1.obj", &["key 1 is flattened or collapsed: it encloses 0.0%"]),
        bad("key-collapsed", key1(obj::write(&scaled(cube(), [0.0, 0.0, 0.0]))), "in/k1.obj", &["key 1 is flattened or collapsed"]),
        // Beyond the machine's memory: once a capacity-overflow panic or an allocation abort.
        bad_scene(
            "samples-max",
            table("[solver]\nsamples = 9223372036854775807"),
            &[
                "would need about",
                "GB of memory for 9223372036854775807 samples per interval x 1 intervals x 12 tets",
                "more than the memory budget (60% of the available memory; --max-memory sets it) of ",
                "lower [solver] samples",
            ],
        ),
        bad_scene(
            "samples-1e9",
            table("[solver]\nsamples = 1000000000"),
            &["would need about 3456.0 GB of memory for 1000000000 samples per interval"],
        ),
        bad_scene("samples-float", table("[solver]\nsamples = 1e9"), &["invalid type: floating point `1000000000.0`, expected usize"]),
        bad_scene(
            "fps-1e9",
            base.replacen("[keyframes]", "fps = 1e9\n[keyframes]", 1),
            &["GB of memory for 1.000e9 frames (1 s at 1000000000 fps) of 26 vertices", "lower fps"],
        ),
        bad_scene(
            "times-1e6",
            base.replace("times = [0.0, 1.0]", "times = [0.0, 1e6]"),
            &["GB of memory for 6.000e7 frames (1000000 s at 60 fps) of 26 vertices"],
        ),
        // Found after TetGen and the solve: these once named no file, now the scene.
        bad_scene("singular", good_scene("fixed = [\"none\", \"none\"]", "[solver]\nregularization = 0.0"), &["the spacetime system is singular"]),
        bad_scene(
            "no-frame",
            base.replace("times = [0.0, 1.0]", "times = [0.010, 0.015]"),
            &["cannot export: the animation runs from 0.01 s to 0.015 s, between two frames at 60 fps"],
        ),
    ]
}

fn make(dir: &Path, name: &str, content: &Content) {
    let path = dir.join(name);
    match content {
        Content::Text(t) => std::fs::write(&path, t).unwrap(),
        Content::Bytes(b) => std::fs::write(&path, b).unwrap(),
        Content::Folder => std::fs::create_dir(&path).unwrap(),
        Content::Link(to) => std::os::unix::fs::symlink(to, &path).unwrap(),
        Content::Fifo => {
            let c = std::ffi::CString::new(path.to_str().unwrap()).unwrap();
            // SAFETY: mkfifo with a valid path.
            assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o644) }, 0, "mkfifo {}", path.display());
        }
    }
}

/// Every case of the corpus, once into a place with no output folder (nothing may be
/// created) and once over a good bake (it must stay byte for byte as it was, with nothing left
/// beside it). Prints the corpus table with `--nocapture`.
#[test]
fn corpus_of_bad_inputs() {
    let template = TempDir::new("errors-corpus-template");
    std::fs::create_dir_all(template.join("in")).unwrap();
    std::fs::write(template.join("in/k0.obj"), obj::write(&cube())).unwrap();
    std::fs::write(template.join("in/k1.obj"), obj::write(&translated(cube(), [0.0, 0.5, 0.0]))).unwrap();
    std::fs::write(template.join("in/scene.toml"), good_scene("", "[export]\nformats = [\"glb\"]")).unwrap();
    run(&template.path, &["bake", "in/scene.toml", "--out", "out/baked", "-q"]).success();
    let good = crate::common::cli::snapshot(&template.join("out/baked"));

    let cases = corpus();
    let mut rows = Vec::new();
    for case in &cases {
        let mut message = String::new();
        for over_a_bake in [false, true] {
            let dir = TempDir::new(&format!("errors-corpus-{}-{over_a_bake}", case.name));
            std::fs::create_dir_all(dir.join("in")).unwrap();
            std::fs::create_dir_all(dir.join("tmp")).unwrap();
            for (name, content) in &case.files {
                make(&dir.join("in"), name, content);
            }
            if over_a_bake {
                crate::common::cli::copy_tree(&template.join("out"), &dir.join("out"));
            }
            let before = tree(&dir.path);
            let tmp = dir.join("tmp");
            let r =
                crate::common::cli::run_timeout(&dir.path, &["bake", "in/scene.toml", "--out", "out/baked"], &[("TMPDIR", tmp.as_os_str())], 600.0);
            assert_eq!(r.code, Some(1), "{}: bad input must exit 1:\n{r}", case.name);
            assert_one_line_error(&r);
            assert!(r.stdout.is_empty(), "{}:\n{r}", case.name);
            assert!(!r.stderr.trim_end().chars().any(char::is_control), "{}: a control character in the message:\n{r:?}", case.name);
            assert!(r.stderr.len() < 1000, "{}: a message of {} bytes", case.name, r.stderr.len());
            assert_names(&r, &case.names);
            for s in &case.says {
                assert_says(&r, s);
            }
            assert_eq!(tree(&dir.path), before, "{}: the run left files behind or removed some:\n{r}", case.name);
            if over_a_bake {
                assert_eq!(crate::common::cli::snapshot(&dir.join("out/baked")), good, "{}: the earlier bake changed", case.name);
            }
            message = r.stderr.trim_end().trim_start_matches("error: ").to_string();
        }
        rows.push(format!("| {} | `{}` |", case.name, message.replace('|', "\\|")));
    }
    eprintln!("| input | message (exit 1) |\n|---|---|\n{}", rows.join("\n"));
    assert!(cases.len() >= 60, "{} cases", cases.len());
}

/// A UTF-8 byte order mark is accepted by every text reader: scene, OBJ, MEDIT, selections.
#[test]
fn byte_order_marks_are_accepted_everywhere() {
    let dir = TempDir::new("errors-bom");
    let input = dir.join("in");
    std::fs::create_dir_all(&input).unwrap();
    let bom = |s: String| format!("\u{feff}{s}");
    std::fs::write(input.join("k0.obj"), bom(obj::write(&cube()))).unwrap();
    std::fs::write(input.join("k1.obj"), bom(obj::write(&translated(cube(), [0.0, 0.5, 0.0])))).unwrap();
    std::fs::write(input.join("ends.txt"), bom("0\n1\n".into())).unwrap();
    std::fs::write(input.join("sel.dmat"), bom(format!("1 26\n{}", "1\n".repeat(26)))).unwrap();
    let text = good_scene("fixed = [\"sel.dmat\", \"ends.txt\"]", "[export]\nformats = [\"glb\"]");
    std::fs::write(input.join("scene.toml"), bom(text)).unwrap();
    run(&dir.path, &["bake", "in/scene.toml", "--out", "out", "-q"]).success();
    let tets = dir.join("tets");
    std::fs::create_dir_all(&tets).unwrap();
    std::fs::write(tets.join("k0.mesh"), bom(TWO_TETS.into())).unwrap();
    std::fs::write(tets.join("scene.toml"), bom(scene(&["k0.mesh", "k0.mesh"], "", "[export]\nformats = [\"glb\"]"))).unwrap();
    run(&dir.path, &["bake", "tets/scene.toml", "--out", "out2", "-q"]).success();
}

/// Errors found after a stage file was read (by the solver, the export's checks) once named
/// no file; they name the stage file the subcommand was given.
#[test]
fn errors_found_after_reading_a_stage_file_name_it() {
    let dir = TempDir::new("errors-after-stage");
    stage_files(&dir.path);
    let edit = |file: &str, to: &str, change: &dyn Fn(&mut serde_json::Value)| {
        let mut v: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.join(file)).unwrap()).unwrap();
        change(&mut v);
        std::fs::write(dir.join(to), serde_json::to_vec(&v).unwrap()).unwrap();
    };
    edit("body.json", "free.json", &|v| {
        v["data"]["scene"]["solver"]["regularization"] = 0.0.into();
        let keys = v["data"]["keys"]["fixed"].as_array().unwrap().len();
        v["data"]["keys"]["fixed"] = serde_json::json!(vec![Vec::<u32>::new(); keys]);
    });
    edit("animation.json", "broken.json", &|v| v["data"]["mesh"]["triangles"][0] = serde_json::json!([0, 1, 100000]));
    let before = tree(&dir.path);
    let cases: [(&[&str], &str, &str); 2] = [
        (&["solve", "free.json", "-o", "new.json"], "free.json", "the spacetime system is singular"),
        (&["export", "broken.json", "--out", "new"], "broken.json", "animation stage: mesh triangle 0 uses vertex 100000, but there are 26 vertices"),
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

// --- Stage files: hand-edited copies of a real chain's files. ---

/// One edited stage file: the subcommand reading it, the file edited (and written as `bad.json`),
/// the edit, and what the message must say.
struct BadStage {
    name: &'static str,
    args: &'static [&'static str],
    file: &'static str,
    edit: fn(&mut serde_json::Value),
    says: &'static str,
}

fn stage_corpus() -> Vec<BadStage> {
    use serde_json::json;
    let solve: &[&str] = &["solve", "bad.json", "-o", "new.json"];
    let tetrahedralize: &[&str] = &["tetrahedralize", "bad.json", "-o", "new.json"];
    let embed: &[&str] = &["embed", "bad.json", "-o", "new.json"];
    let export: &[&str] = &["export", "bad.json", "--out", "new"];
    let report: &[&str] = &["report", "bad.json", "--outputs", "exported/t.outputs.json", "--out", "new"];
    let report_outputs: &[&str] = &["report", "animation.json", "--outputs", "bad.json", "--out", "new"];
    fn pop(v: &mut serde_json::Value) {
        v.as_array_mut().unwrap().pop();
    }
    vec![
        // Once panics (exit 101) in the solver.
        BadStage {
            name: "body-tet-index",
            args: solve,
            file: "body.json",
            edit: |v| v["data"]["mesh"]["tets"][0][0] = json!(100000),
            says: "body stage: mesh tet 0 uses node 100000, but there are",
        },
        BadStage {
            name: "body-pose-short",
            args: solve,
            file: "body.json",
            edit: |v| pop(&mut v["data"]["keys"]["positions"][1]),
            says: "keys.positions[1] has 25 points but the mesh has 26",
        },
        BadStage {
            name: "body-fixed-index",
            args: solve,
            file: "body.json",
            edit: |v| v["data"]["keys"]["fixed"][0].as_array_mut().unwrap().push(json!(100000)),
            says: "keys.fixed[0] holds index 100000, but there are 26 vertices",
        },
        BadStage {
            name: "body-times-extra",
            args: solve,
            file: "body.json",
            edit: |v| v["data"]["keys"]["times"].as_array_mut().unwrap().push(json!(2.0)),
            says: "keys.positions has 2 poses for 3 key times",
        },
        // Once accepted with garbage, or misdiagnosed.
        BadStage {
            name: "body-times-short",
            args: solve,
            file: "body.json",
            edit: |v| pop(&mut v["data"]["keys"]["times"]),
            says: "keys.times has 1 key times, at least 2 are needed",
        },
        BadStage {
            name: "body-times-decrease",
            args: solve,
            file: "body.json",
            edit: |v| v["data"]["keys"]["times"] = json!([1.0, 0.0]),
            says: "keys.times do not increase at key 1 (0 after 1)",
        },
        BadStage {
            name: "body-samples-zero",
            args: solve,
            file: "body.json",
            edit: |v| v["data"]["scene"]["solver"]["samples"] = json!(0),
            says: "body stage: its scene: [solver] samples = 0",
        },
        BadStage {
            name: "body-samples-max",
            args: solve,
            file: "body.json",
            edit: |v| v["data"]["scene"]["solver"]["samples"] = json!(9223372036854775807u64),
            says: "body stage: the scene would need about",
        },
        BadStage {
            name: "animation-fps-1e9",
            args: report,
            file: "animation.json",
            edit: |v| v["data"]["scene"]["fps"] = json!(1e9),
            says: "frames (1 s at 1000000000 fps) of 26 vertices",
        },
        BadStage {
            name: "body-fixed-count",
            args: solve,
            file: "body.json",
            edit: |v| pop(&mut v["data"]["keys"]["fixed"]),
            says: "keys.fixed has 1 sets for 2 keys",
        },
        BadStage {
            name: "body-fixed-unsorted",
            args: solve,
            file: "body.json",
            edit: |v| v["data"]["keys"]["fixed"][0] = json!([3, 1]),
            says: "keys.fixed[0] is not sorted without repeats",
        },
        BadStage {
            name: "body-inverted-tet",
            args: solve,
            file: "body.json",
            edit: |v| {
                let t = v["data"]["mesh"]["tets"][0].clone();
                v["data"]["mesh"]["tets"][0] = json!([t[1], t[0], t[2], t[3]]);
            },
            says: "mesh tet 0 is inverted or flat in the rest pose",
        },
        BadStage {
            name: "body-cyclic-two-keys",
            args: solve,
            file: "body.json",
            edit: |v| v["data"]["keys"]["cyclic"] = json!(true),
            says: "cyclic is true with 2 keys",
        },
        BadStage { name: "body-no-tets", args: solve, file: "body.json", edit: |v| v["data"]["mesh"]["tets"] = json!([]), says: "mesh has no tets" },
        // tetrahedralize: once a copy_from_slice panic.
        BadStage {
            name: "keys-pose-short",
            args: tetrahedralize,
            file: "keys.json",
            edit: |v| pop(&mut v["data"]["poses"][1]),
            says: "keyframes stage: poses[1] has 25 points but the mesh has 26",
        },
        BadStage {
            name: "keys-triangle-index",
            args: tetrahedralize,
            file: "keys.json",
            edit: |v| v["data"]["rest"]["triangles"][2][1] = json!(26),
            says: "rest surface triangle 2 uses vertex 26, but there are 26 vertices",
        },
        BadStage {
            name: "keys-velocity-index",
            args: tetrahedralize,
            file: "keys.json",
            edit: |v| v["data"]["fixed_velocity"][1] = json!([26]),
            says: "fixed_velocity[1] holds index 26",
        },
        BadStage {
            name: "keys-name",
            args: tetrahedralize,
            file: "keys.json",
            edit: |v| v["data"]["scene"]["name"] = json!("../x"),
            says: "its scene: name `../x` cannot be a file stem: it contains a path separator",
        },
        // embed: once an assertion, and an out-of-range triangle accepted.
        BadStage {
            name: "solution-trajectory-short",
            args: embed,
            file: "solution.json",
            edit: |v| pop(&mut v["data"]["trajectory"]["positions"][1]),
            says: "trajectory.positions[1] has",
        },
        BadStage {
            name: "solution-velocities-missing",
            args: embed,
            file: "solution.json",
            edit: |v| pop(&mut v["data"]["trajectory"]["velocities"]),
            says: "trajectory.velocities has 1 keys for 2 key times",
        },
        BadStage {
            name: "solution-surface-index",
            args: embed,
            file: "solution.json",
            edit: |v| v["data"]["body"]["surface"]["triangles"][0][0] = json!(100000),
            says: "body surface triangle 0 uses vertex 100000",
        },
        // export: fps = 0 once reached usd-core; the name once escaped --out.
        BadStage {
            name: "animation-fps-zero",
            args: export,
            file: "animation.json",
            edit: |v| v["data"]["scene"]["fps"] = json!(0.0),
            says: "animation stage: its scene: fps = 0 must be positive",
        },
        BadStage {
            name: "animation-name-escape",
            args: export,
            file: "animation.json",
            edit: |v| v["data"]["scene"]["name"] = json!("../../x"),
            says: "name `../../x` cannot be a file stem",
        },
        BadStage {
            name: "animation-name-newline",
            args: export,
            file: "animation.json",
            edit: |v| v["data"]["scene"]["name"] = json!("a\nb"),
            says: "name `a\\nb` cannot be a file stem: it contains a control character",
        },
        BadStage {
            name: "animation-input-keys",
            args: export,
            file: "animation.json",
            edit: |v| pop(&mut v["data"]["input_keys"]),
            says: "input_keys has 1 poses for 2 key times",
        },
        BadStage {
            name: "animation-counts",
            args: export,
            file: "animation.json",
            edit: |v| v["data"]["counts"]["vertices"] = json!(7),
            says: "counts say 7 vertices",
        },
        BadStage {
            name: "animation-meters",
            args: export,
            file: "animation.json",
            edit: |v| v["data"]["scene"]["export"]["meters_per_unit"] = json!(-1.0),
            says: "meters_per_unit = -1 must be positive",
        },
        BadStage {
            name: "animation-times-report",
            args: report,
            file: "animation.json",
            edit: |v| v["data"]["trajectory"]["times"] = json!([0.0, 0.0]),
            says: "trajectory.times do not increase at key 1",
        },
        BadStage {
            name: "outputs-path",
            args: report_outputs,
            file: "exported/t.outputs.json",
            edit: |v| v["data"]["files"][0]["path"] = json!("../x.glb"),
            says: "outputs stage: files[0] is `../x.glb`, not a plain file name",
        },
    ]
}

/// Every edit of a real chain's stage files that once panicked, was accepted or was
/// misdiagnosed is one line naming the file, exit 1, nothing written. Prints the table with
/// `--nocapture`.
#[test]
fn corpus_of_bad_stage_files() {
    let dir = TempDir::new("errors-stage-corpus");
    stage_files(&dir.path);
    let mut rows = Vec::new();
    for case in stage_corpus() {
        let mut v: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.join(case.file)).unwrap()).unwrap();
        (case.edit)(&mut v);
        std::fs::write(dir.join("bad.json"), serde_json::to_vec(&v).unwrap()).unwrap();
        let before = tree(&dir.path);
        let r = crate::common::cli::run_timeout(&dir.path, case.args, &[], 600.0);
        assert_eq!(r.code, Some(1), "{}: a bad stage file must exit 1:\n{r}", case.name);
        assert_one_line_error(&r);
        assert!(!r.stderr.trim_end().chars().any(char::is_control), "{}: a control character in the message:\n{r:?}", case.name);
        assert_names(&r, "bad.json");
        assert_says(&r, case.says);
        assert_says(&r, "re-run ");
        assert_eq!(tree(&dir.path), before, "{}: the run left files behind or removed some:\n{r}", case.name);
        rows.push(format!("| {} | `{}` |", case.name, r.stderr.trim_end().trim_start_matches("error: ").replace('|', "\\|")));
        std::fs::remove_file(dir.join("bad.json")).unwrap();
    }
    eprintln!("| stage file edit | message (exit 1) |\n|---|---|\n{}", rows.join("\n"));
}

// --- Output names taken by the user, reports that are not files, and measures of nothing. ---

/// A user's folder or file at the name of a file the bake writes (`report.md/`, `t.glb/`, a
/// `t.glb` of their own) is refused before any stage runs: exit 1, one line naming it, the
/// output folder and everything in it as it was. Once the folder was replaced and the user's
/// files in it deleted without a word.
#[test]
fn a_users_folder_or_file_at_an_output_name_is_refused_before_the_work() {
    let dir = TempDir::new("errors-output-names");
    std::fs::create_dir_all(dir.join("in")).unwrap();
    std::fs::write(dir.join("in/k0.obj"), obj::write(&cube())).unwrap();
    std::fs::write(dir.join("in/k1.obj"), obj::write(&translated(cube(), [0.0, 0.5, 0.0]))).unwrap();
    std::fs::write(dir.join("in/scene.toml"), good_scene("", "[export]\nformats = [\"glb\"]")).unwrap();
    run(&dir.path, &["bake", "in/scene.toml", "--out", "out/baked", "-q"]).success();
    let good = crate::common::cli::snapshot(&dir.join("out/baked"));
    // Progress lines forced: a refusal before the work prints no stage.
    let lines = [("BLENDSIM_PROGRESS", OsStr::new("lines"))];
    let refused = |out: &str, entry: &str, what: &str| {
        let before = tree(&dir.path);
        let r = run_env(&dir.path, &["bake", "in/scene.toml", "--out", out], &lines);
        assert_eq!(r.code, Some(1), "{entry}:\n{r}");
        assert_one_line_error(&r);
        assert_names(&r, &format!("{out}/{entry}"));
        assert_says(&r, &format!("is {what} that blendsim did not write, at the name of a file this run writes"));
        assert_says(&r, "(fix: move or rename it, or choose another --out)");
        assert_eq!(tree(&dir.path), before, "{entry}: the run changed files:\n{r}");
    };

    // Over a bake: report.md replaced by a folder holding a user's file.
    std::fs::remove_file(dir.join("out/baked/report.md")).unwrap();
    std::fs::create_dir(dir.join("out/baked/report.md")).unwrap();
    std::fs::write(dir.join("out/baked/report.md/notes.txt"), "mine").unwrap();
    refused("out/baked", "report.md", "a folder");
    assert_eq!(std::fs::read_to_string(dir.join("out/baked/report.md/notes.txt")).unwrap(), "mine");
    std::fs::remove_dir_all(dir.join("out/baked/report.md")).unwrap();
    // A folder, a file and a FIFO of the user's at t.glb in a folder blendsim never wrote.
    std::fs::create_dir_all(dir.join("out/mine/t.glb")).unwrap();
    std::fs::write(dir.join("out/mine/t.glb/keep.txt"), "mine").unwrap();
    refused("out/mine", "t.glb", "a folder");
    std::fs::remove_dir_all(dir.join("out/mine/t.glb")).unwrap();
    std::fs::write(dir.join("out/mine/t.glb"), "my own glb").unwrap();
    refused("out/mine", "t.glb", "a file");
    std::fs::remove_file(dir.join("out/mine/t.glb")).unwrap();
    make(&dir.join("out/mine"), "report.json", &Content::Fifo);
    refused("out/mine", "report.json", "a named pipe (FIFO)");
    std::fs::remove_file(dir.join("out/mine/report.json")).unwrap();

    // Files blendsim wrote are replaced as before; the user's other files are kept.
    std::fs::write(dir.join("out/mine/notes.txt"), "mine").unwrap();
    run(&dir.path, &["bake", "in/scene.toml", "--out", "out/mine", "-q"]).success();
    run(&dir.path, &["bake", "in/scene.toml", "--out", "out/baked", "-q"]).success();
    assert_eq!(std::fs::read_to_string(dir.join("out/mine/notes.txt")).unwrap(), "mine");
    let mut again = crate::common::cli::snapshot(&dir.join("out/baked"));
    let mut good = good;
    for report in [&mut again, &mut good] {
        report.retain(|name, _| !name.starts_with("report."));
    }
    assert_eq!(again, good, "a re-bake gives the same files");
}

/// A texture named like a file the bake writes beside the USD files (`report.json`) would be
/// overwritten by it: refused, naming the texture. Embedded in a glb it is harmless and bakes.
#[test]
fn a_texture_named_like_an_output_is_refused() {
    let dir = TempDir::new("errors-texture-name");
    std::fs::create_dir_all(dir.join("in")).unwrap();
    let with_mtl = |mesh: TriMesh| format!("mtllib m.mtl\nusemtl wood\n{}", obj::write(&mesh));
    std::fs::write(dir.join("in/k0.obj"), with_mtl(cube())).unwrap();
    std::fs::write(dir.join("in/k1.obj"), with_mtl(translated(cube(), [0.0, 0.5, 0.0]))).unwrap();
    std::fs::write(dir.join("in/m.mtl"), "newmtl wood\nmap_Kd report.json\n").unwrap();
    std::fs::write(dir.join("in/report.json"), crate::texture::png(2, 2, |_, _| [200, 100, 50])).unwrap();
    let scene_with = |formats: &str| scene(&["k0.obj", "k1.obj"], "", &format!("[export]\nformats = {formats}"));
    std::fs::write(dir.join("in/scene.toml"), scene_with("[\"usda\"]")).unwrap();
    let before = tree(&dir.path);
    let r = run(&dir.path, &["bake", "in/scene.toml", "--out", "out"]);
    assert_eq!(r.code, Some(1), "{r}");
    assert_one_line_error(&r);
    let texture = dir.join("in/report.json").canonicalize().unwrap();
    assert_names(&r, &texture.display().to_string());
    assert_says(&r, "the texture's file name `report.json` is that of a file the bake writes beside the USD files");
    assert_says(&r, "(fix: rename the texture and its .mtl map_Kd line)");
    assert_eq!(tree(&dir.path), before, "nothing written:\n{r}");
    std::fs::write(dir.join("in/scene.toml"), scene_with("[\"glb\"]")).unwrap();
    run(&dir.path, &["bake", "in/scene.toml", "--out", "out", "-q"]).success();
    assert_eq!(crate::common::cli::read_json(&dir.join("out/report.json"))["scene"], "t", "the report is the report");
}

/// `report` over an outputs list whose files are empty (0 bytes) prints no `NaNx` or `infx`:
/// the ratio is "n/a" in report.md and absent from report.json.
#[test]
fn a_report_of_empty_outputs_has_no_ratio() {
    let dir = TempDir::new("errors-empty-outputs");
    stage_files(&dir.path);
    let mut outputs = crate::common::cli::read_json(&dir.join("exported/t.outputs.json"));
    for f in outputs["data"]["files"].as_array_mut().unwrap() {
        if f["kind"] == "blendshape" {
            f["bytes"] = 0.into();
        }
    }
    std::fs::write(dir.join("empty.outputs.json"), serde_json::to_vec(&outputs).unwrap()).unwrap();
    run(&dir.path, &["report", "animation.json", "--outputs", "empty.outputs.json", "--out", "reported"]).success();
    let md = std::fs::read_to_string(dir.join("reported/report.md")).unwrap();
    assert!(!md.contains("NaN") && !md.contains("inf"), "{md}");
    let glb = md.lines().find(|l| l.starts_with("| glb | 0 B |")).unwrap_or_else(|| panic!("{md}"));
    assert!(glb.contains("| n/a |") && !glb.contains('x'), "every ratio of a zero-byte file is n/a: {glb}");
    let json = crate::common::cli::read_json(&dir.join("reported/report.json"));
    assert_eq!(json["ratios"], serde_json::json!({}), "{json}");
}

/// `report --batch` over a folder of bakes, one of whose report.json is a folder or a FIFO:
/// one line naming it (once it was silently left out of the summary).
#[test]
fn a_batch_report_names_a_report_that_is_not_a_file() {
    let dir = TempDir::new("errors-batch");
    std::fs::create_dir_all(dir.join("in")).unwrap();
    std::fs::write(dir.join("in/k0.obj"), obj::write(&cube())).unwrap();
    std::fs::write(dir.join("in/k1.obj"), obj::write(&translated(cube(), [0.0, 0.5, 0.0]))).unwrap();
    std::fs::write(dir.join("in/scene.toml"), good_scene("", "[export]\nformats = [\"glb\"]")).unwrap();
    run(&dir.path, &["bake", "in/scene.toml", "--out", "bakes/a", "-q"]).success();
    run(&dir.path, &["report", "--batch", "bakes", "--out", "summary"]).success();
    std::fs::create_dir_all(dir.join("bakes/b/report.json")).unwrap();
    for (content, what) in [(None, "a folder"), (Some(Content::Fifo), "a named pipe (FIFO)")] {
        if let Some(content) = content {
            std::fs::remove_dir(dir.join("bakes/b/report.json")).unwrap();
            make(&dir.join("bakes/b"), "report.json", &content);
        }
        for batch in ["bakes", "bakes/b"] {
            let before = crate::common::cli::snapshot(&dir.join("summary"));
            let r = run(&dir.path, &["report", "--batch", batch, "--out", "summary"]);
            assert_eq!(r.code, Some(1), "{r}");
            assert_one_line_error(&r);
            assert_names(&r, "bakes/b/report.json");
            assert_says(&r, &format!("is {what}, not a regular file, so it cannot be read as a blendsim report"));
            assert_eq!(crate::common::cli::snapshot(&dir.join("summary")), before, "the summary changed");
        }
    }
}

/// An `[embed] surface` far outside the body bakes with a warning on stderr, in report.json's
/// `warnings` and in report.md; one on the body does not.
#[test]
fn an_embedded_surface_far_outside_the_body_is_a_warning() {
    let dir = TempDir::new("errors-embed-far");
    std::fs::create_dir_all(dir.join("in")).unwrap();
    std::fs::write(dir.join("in/k0.obj"), obj::write(&cube())).unwrap();
    std::fs::write(dir.join("in/k1.obj"), obj::write(&translated(cube(), [0.0, 0.5, 0.0]))).unwrap();
    // The body's diagonal is sqrt(3): the far box's far side is 10 units out (5.77 diagonals),
    // the near box's 0.05 (0.029).
    std::fs::write(dir.join("in/far.obj"), obj::write(&translated(cube(), [10.0, 0.0, 0.0]))).unwrap();
    std::fs::write(dir.join("in/near.obj"), obj::write(&translated(scaled(cube(), [1.1, 1.0, 1.0]), [-0.05, 0.0, 0.0]))).unwrap();
    for (surface, warned) in [("far.obj", true), ("near.obj", false)] {
        let text = good_scene("", &format!("[embed]\nsurface = \"{surface}\"\n[export]\nformats = [\"glb\"]"));
        std::fs::write(dir.join("in/scene.toml"), text).unwrap();
        let out = format!("out/{surface}");
        let r = run(&dir.path, &["bake", "in/scene.toml", "--out", &out]).success();
        let says = "the [embed] surface reaches";
        let line = r.stderr.lines().find(|l| l.contains(says));
        assert_eq!(line.is_some(), warned, "{surface}:\n{r}");
        let json = crate::common::cli::read_json(&dir.join(&out).join("report.json"));
        let listed = json["warnings"].as_array().is_some_and(|list| list.iter().any(|w| w.as_str().unwrap().contains(says)));
        assert_eq!(listed, warned, "{surface}: {}", json["warnings"]);
        let md = std::fs::read_to_string(dir.join(&out).join("report.md")).unwrap();
        assert_eq!(md.contains(says), warned, "{surface}");
        if let Some(line) = line {
            assert!(
                line.starts_with("blendsim: warning: embed-far: in/k0.obj: the [embed] surface reaches 5.77 of this body's bounding-box diagonal"),
                "{line}"
            );
        }
    }
}
