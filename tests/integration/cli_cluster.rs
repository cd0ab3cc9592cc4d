//! The two hidden subcommands the cluster driver (cluster/, docs/cluster.md) runs, as it runs
//! them: `inputs` lists the files a bake reads without baking; `commit` commits a bake's
//! folder made elsewhere (on a worker) into the output folder as `bake` commits its own. The
//! driver itself is tested on a local Ray cluster by `make test-ray` (cluster/tests).

use std::path::Path;

use serde_json::Value;

use crate::common::cli::{copy_tree, run, snapshot, TempDir};

fn demo(dir: &Path) {
    copy_tree(&Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/demo"), &dir.join("in"));
}

/// The one stderr line of a failed run, `error: ...`.
fn one_error_line(stderr: &str) -> &str {
    let lines: Vec<&str> = stderr.lines().filter(|l| !l.trim().is_empty()).collect();
    assert_eq!(lines.len(), 1, "one line: {stderr}");
    assert!(lines[0].starts_with("error: ") && lines[0].contains("(fix: "), "{}", lines[0]);
    lines[0]
}

#[test]
fn inputs_lists_what_the_depfile_lists_and_each_bad_scenes_error_without_baking() {
    let dir = TempDir::new("cluster-inputs");
    demo(&dir.path);
    let before = snapshot(&dir.path);
    let listed = run(&dir.path, &["inputs", "in/twist.toml", "in/missing.toml"]).success();
    assert_eq!(snapshot(&dir.path), before, "inputs writes nothing");
    let lines: Vec<Value> = listed.stdout.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    assert_eq!(lines.len(), 2, "one line per scene: {}", listed.stdout);
    let inputs: Vec<&str> = lines[0]["inputs"].as_array().unwrap().iter().map(|p| p.as_str().unwrap()).collect();
    assert_eq!(inputs, ["in/twist.toml", "in/prism_rest.obj", "in/prism_left.obj", "in/prism_right.obj", "in/ends.txt", "in/bottom.txt"]);
    // The same files as the depfile of a bake (one empty rule each).
    run(&dir.path, &["bake", "in/twist.toml", "-o", "out", "--depfile", "twist.d", "-q"]).success();
    let depfile = std::fs::read_to_string(dir.join("twist.d")).unwrap();
    let rules: Vec<&str> = depfile.split("\n\n").skip(1).map(|r| r.trim().trim_end_matches(':')).collect();
    assert_eq!(rules, inputs);
    // A scene that cannot be read: its line holds the bake's one-line message.
    assert_eq!(lines[1]["scene"], "in/missing.toml");
    let error = lines[1]["error"].as_str().unwrap();
    let bake = run(&dir.path, &["bake", "in/missing.toml", "-o", "out2"]);
    assert_eq!(bake.code, Some(1));
    assert_eq!(one_error_line(&bake.stderr), format!("error: {error}"));
}

#[test]
fn commit_replaces_the_folder_as_bake_does_and_refuses_what_bake_refuses() {
    let dir = TempDir::new("cluster-commit");
    demo(&dir.path);
    run(&dir.path, &["bake", "in/twist.toml", "-o", "made", "-q"]).success();
    let made = snapshot(&dir.join("made"));

    // Into a new folder: the same files, manifest included, and FROM left as it was.
    run(&dir.path, &["commit", "made", "-o", "dest", "-q"]).success();
    assert_eq!(snapshot(&dir.join("dest")), made);
    assert_eq!(snapshot(&dir.join("made")), made);

    // Over an earlier bake with a user's file beside it and a file of another scene's bake:
    // the user's file stays, the stale one goes (a bake's whole content is replaced).
    std::fs::write(dir.join("dest/notes.txt"), b"mine").unwrap();
    std::fs::write(dir.join("dest/old.glb"), b"stale").unwrap();
    let manifest = std::fs::read_to_string(dir.join("dest/.blendsim-manifest.json")).unwrap();
    std::fs::write(dir.join("dest/.blendsim-manifest.json"), manifest.replace("\"files\": {", "\"files\": {\n    \"old.glb\": \"export:old\","))
        .unwrap();
    let committed = run(&dir.path, &["commit", "made", "-o", "dest"]).success();
    assert!(committed.stderr.contains("old.glb") && committed.stderr.contains("notes.txt"), "says what it removed and kept: {}", committed.stderr);
    let mut expected = made.clone();
    expected.insert("notes.txt".into(), Some(b"mine".to_vec()));
    assert_eq!(snapshot(&dir.join("dest")), expected);

    // A user's folder at the name of a file it writes: refused, nothing written.
    std::fs::create_dir_all(dir.join("theirs/report.md")).unwrap();
    let before = snapshot(&dir.join("theirs"));
    let refused = run(&dir.path, &["commit", "made", "-o", "theirs"]);
    assert_eq!(refused.code, Some(1));
    assert!(one_error_line(&refused.stderr).contains("report.md"), "{}", refused.stderr);
    assert_eq!(snapshot(&dir.join("theirs")), before);
    assert!(
        !std::fs::read_dir(&dir.path).unwrap().any(|e| e.unwrap().file_name().to_string_lossy().starts_with(".theirs")),
        "no staging or lock left"
    );

    // A folder that is not a bake's: its missing manifest named, no output folder made.
    let bad = run(&dir.path, &["commit", "in", "-o", "nothing"]);
    assert_eq!(bad.code, Some(1));
    assert!(one_error_line(&bad.stderr).contains(".blendsim-manifest.json"), "{}", bad.stderr);
    assert!(!dir.join("nothing").exists());
}
