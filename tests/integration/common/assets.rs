//! The paper's scenes under `../shared/assets/paper` (outside this repository).
//!
//! Tests that need them call [`paper_asset`] or [`paper_scene`]: with `CI=true` a missing file
//! fails the test (CI must never pass by skipping); elsewhere the test returns early with a
//! note on stderr.

use std::path::{Path, PathBuf};

/// `../shared/assets/paper` beside the repository.
pub fn paper_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/assets/paper")
}

fn ci() -> bool {
    std::env::var("CI").as_deref() == Ok("true")
}

/// A file of the paper's assets (`rel` below `../shared/assets/paper`), or `None` with a note
/// when it is missing and `CI` is not `true`. Panics when it is missing and `CI=true`.
pub fn paper_asset(rel: &str) -> Option<PathBuf> {
    paper_asset_in(&paper_dir(), rel, ci())
}

/// [`paper_asset`] with the folder and the CI flag given (for testing the rule itself).
pub fn paper_asset_in(dir: &Path, rel: &str, ci: bool) -> Option<PathBuf> {
    let path = dir.join(rel);
    if path.is_file() {
        return Some(path);
    }
    assert!(!ci, "test asset {} is missing (required when CI=true): put the paper's assets in ../shared/assets/paper", path.display());
    eprintln!("skipped: test asset {} is missing (set CI=true to make this a failure)", path.display());
    None
}

/// `fixtures/paper/NAME.toml` when every paper asset it reads is present (see
/// [`paper_asset`] for what happens when one is not).
pub fn paper_scene(name: &str) -> Option<PathBuf> {
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/paper").join(format!("{name}.toml"));
    let text = std::fs::read_to_string(&scene).unwrap_or_else(|e| panic!("{}: {e}", scene.display()));
    // Every quoted path into the shared assets, as the scene writes it.
    let marker = "shared/assets/paper/";
    let mut rest = text.as_str();
    while let Some(at) = rest.find(marker) {
        let tail = &rest[at + marker.len()..];
        let end = tail.find('"').expect("asset paths are quoted");
        paper_asset(&tail[..end])?;
        rest = &tail[end..];
    }
    Some(scene)
}
