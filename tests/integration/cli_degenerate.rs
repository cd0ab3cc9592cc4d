//! Degenerate geometry per tet through the CLI: a tet key that folds one tet while its total
//! volume is unchanged, and a folded rest tet mesh, are one-line errors naming the file and the
//! tet with its vertices; a surface key whose interior fit folds tets, and a `max_volume` TetGen
//! could not honour, are warning lines that the report keeps.

use blendsim::algorithms::procedural::prism;
use blendsim::formats::mesh::obj;

use crate::cli_physics::cube_medit;
use crate::common::cli::{read_json, run, TempDir};

const SCENE: &str = "name = \"fold\"\n[keyframes]\nmeshes = [\"rest.mesh\", \"key.mesh\"]\ntimes = [0.0, 1.0]\n[solver]\nsamples = 3\n[export]\nformats = [\"usda\"]\n";

/// The centre node of the 2x2x2 cube (index 13 of its 27 nodes) moved by `by`.
fn centre_moved(by: [f64; 3]) -> String {
    cube_medit(2, |p| if p == [0.5, 0.5, 0.5] { [p[0] + by[0], p[1] + by[1], p[2] + by[2]] } else { p })
}

fn assert_one_line_error(dir: &TempDir, needles: &[&str]) {
    let r = run(&dir.path, &["bake", "-q", "scene.toml", "--out", "out"]);
    assert_eq!(r.code, Some(1), "{r}");
    assert_eq!(r.stderr.lines().count(), 1, "{r}");
    for n in needles {
        assert!(r.stderr.contains(n), "'{n}' missing: {r}");
    }
    assert!(!dir.join("out").exists());
}

#[test]
fn a_tet_key_that_folds_tets_bakes_with_one_warning_naming_the_key_and_the_tets() {
    let dir = TempDir::new("degenerate-key");
    std::fs::write(dir.join("rest.mesh"), cube_medit(2, |p| p)).unwrap();
    std::fs::write(dir.join("scene.toml"), SCENE.replace("[solver]", "fixed = [\"all\", \"all\"]\n[solver]")).unwrap();
    // The centre node pushed through the top: the tets around it invert, the boundary (and so
    // the total volume) does not move. Flattened, not inverted: the centre node almost on the
    // top face.
    for (by, counts) in [(0.7, "tets inverted, 0 flattened"), (0.49999, "0 tets inverted, ")] {
        std::fs::write(dir.join("key.mesh"), centre_moved([0.0, 0.0, by])).unwrap();
        let r = run(&dir.path, &["bake", "-q", "scene.toml", "--out", "out"]).success();
        // One line for the key (the inverted centre also drives the boundary out of the
        // volume band between the keys: a `volume-band` warning may follow).
        assert_eq!(r.stderr.lines().filter(|l| l.contains("folded-key")).count(), 1, "{r}");
        assert!(r.stderr.starts_with("blendsim: warning: folded-key: key.mesh: key 1 folds the tet body: ") && r.stderr.contains(counts), "{r}");
        let report = read_json(&dir.join("out/report.json"));
        assert!(report["warnings"][0].as_str().unwrap().starts_with("folded-key: key.mesh: key 1 "), "{report}");
    }
}

#[test]
fn a_folded_rest_mesh_is_an_error_naming_the_tet() {
    let dir = TempDir::new("degenerate-rest");
    let folded = centre_moved([0.0, 0.0, 0.7]);
    std::fs::write(dir.join("rest.mesh"), &folded).unwrap();
    std::fs::write(dir.join("key.mesh"), &folded).unwrap();
    std::fs::write(dir.join("scene.toml"), SCENE).unwrap();
    assert_one_line_error(&dir, &["error: rest.mesh: the rest mesh is folded: tet ", "(vertices ", "overlap across their shared face", "untangle"]);
    // A mirrored mesh (every tet negative in the file's order) is not folded.
    let unfolded = cube_medit(2, |p| [p[0], p[1], -p[2]]);
    std::fs::write(dir.join("rest.mesh"), &unfolded).unwrap();
    std::fs::write(dir.join("key.mesh"), &unfolded).unwrap();
    run(&dir.path, &["bake", "-q", "scene.toml", "--out", "out"]).success();
}

#[test]
fn a_surface_key_folded_by_the_interior_fit_is_a_warning_the_report_keeps() {
    let dir = TempDir::new("degenerate-surface");
    let rest = prism([1.0, 1.0, 1.0], [2, 2, 2]);
    let mut key = rest.clone();
    // The centre of the top face pushed down to near the bottom: a local fold of the surface.
    let top = key.positions.iter().position(|p| (p[0] - 0.5).abs() < 1e-9 && (p[1] - 0.5).abs() < 1e-9 && p[2] > 0.9).expect("top centre");
    key.positions[top][2] = 0.05;
    std::fs::write(dir.join("rest.obj"), obj::write(&rest)).unwrap();
    std::fs::write(dir.join("dent.obj"), obj::write(&key)).unwrap();
    let scene = "name = \"dent\"\n[keyframes]\nmeshes = [\"rest.obj\", \"dent.obj\"]\ntimes = [0.0, 1.0]\n[tet]\nmax_volume = 0.01\n[solver]\nsamples = 3\n[export]\nformats = [\"usda\"]\n";
    std::fs::write(dir.join("scene.toml"), scene).unwrap();
    let r = run(&dir.path, &["bake", "-q", "scene.toml", "--out", "out"]).success();
    let warning = r.stderr.lines().find(|l| l.contains("folds the tet body")).unwrap_or_else(|| panic!("no fold warning: {}", r.stderr));
    assert!(warning.starts_with("blendsim: warning: folded-key: dent.obj: key 1 folds the tet body: ") && warning.contains("(nodes "), "{warning}");
    let report = read_json(&dir.join("out/report.json"));
    let warnings = report["warnings"].as_array().expect("warnings in report.json");
    assert!(warnings.iter().any(|w| w.as_str().unwrap().starts_with("folded-key: dent.obj: key 1 folds the tet body")), "{warnings:?}");
}

#[test]
fn a_max_volume_tetgen_cannot_honour_is_reported() {
    let dir = TempDir::new("degenerate-max-volume");
    std::fs::write(dir.join("box.obj"), obj::write(&prism([1.0, 1.0, 1.0], [2, 2, 2]))).unwrap();
    let scene = |max_volume: &str| {
        format!("name = \"b\"\n[keyframes]\nmeshes = [\"box.obj\", \"box.obj\"]\ntimes = [0.0, 1.0]\n[tet]\nquality = 0.0\nmax_volume = {max_volume}\n[solver]\nsamples = 3\n[export]\nformats = [\"usda\"]\n")
    };
    std::fs::write(dir.join("scene.toml"), scene("1e-9")).unwrap();
    let r = run(&dir.path, &["bake", "-q", "scene.toml", "--out", "out"]).success();
    assert_eq!(r.stderr.lines().count(), 1, "{r}");
    assert!(
        r.stderr.starts_with("blendsim: warning: max-volume: box.obj: TetGen could not honour [tet] max_volume = 1e-9: the largest of its "),
        "{r}"
    );
    let report = read_json(&dir.join("out/report.json"));
    let largest = report["largest_tet_volume"].as_f64().unwrap();
    assert_eq!(report["max_volume"].as_f64(), Some(1e-9));
    assert!(largest > 1e-8, "{largest}");
    assert_eq!(report["warnings"].as_array().map(Vec::len), Some(1));
    // An honoured bound: no warning, the largest volume within it.
    std::fs::write(dir.join("scene.toml"), scene("0.05")).unwrap();
    let r = run(&dir.path, &["bake", "-q", "scene.toml", "--out", "out"]).success();
    assert!(r.stderr.is_empty(), "{r}");
    let report = read_json(&dir.join("out/report.json"));
    assert!(report["largest_tet_volume"].as_f64().unwrap() <= 0.05 && report.get("warnings").is_none(), "{report}");
}
