//! The manifest: which files of an output folder blendsim wrote, and in which group.

use std::collections::BTreeMap;
use std::path::{Component, Path};

/// The manifest of the files blendsim wrote into an output folder.
pub const MANIFEST: &str = ".blendsim-manifest.json";
/// Present in a staging folder until it is complete.
pub(super) const MARKER: &str = ".blendsim-incomplete";

/// `name` if it is one plain path component; otherwise a harmless stand-in.
pub(super) fn contained(name: &str) -> String {
    let plain = !name.is_empty()
        && !name.contains(['/', '\\', '\0'])
        && matches!(Path::new(name).components().collect::<Vec<_>>()[..], [Component::Normal(_)]);
    if plain {
        name.to_string()
    } else {
        ".blendsim-refused-name".to_string()
    }
}

/// The manifest's files and their groups (none when it is missing or damaged), names that
/// are not plain or are blendsim's own bookkeeping left out.
pub(super) fn read_manifest(folder: &Path) -> BTreeMap<String, String> {
    #[derive(serde::Deserialize)]
    struct Manifest {
        files: BTreeMap<String, String>,
    }
    std::fs::read(folder.join(MANIFEST))
        .ok()
        .and_then(|bytes| serde_json::from_slice::<Manifest>(&bytes).ok())
        .map(|m| m.files.into_iter().filter(|(n, _)| contained(n) == *n && n != MANIFEST && n != MARKER).collect())
        .unwrap_or_default()
}

/// The manifest's bytes for `files`.
pub(super) fn manifest_json(files: &BTreeMap<String, String>) -> Vec<u8> {
    let mut bytes = serde_json::to_vec_pretty(&serde_json::json!({ "blendsim": 1, "files": files })).expect("a map of strings serializes");
    bytes.push(b'\n');
    bytes
}
