//! The layers of `src/` (support -> algorithms -> formats -> pipeline -> cli) and the rule that
//! an import never points up: the source is read as text, every `crate::LAYER` path outside
//! comments and test code is an arrow, and an arrow to a higher layer fails the test with the
//! file, the line and the path. Test code (`#[cfg(test)]` modules and the files they declare)
//! may use any layer: a unit test of a reader may bake a scene.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use crate::common::cli::TempDir;

/// The layers from the bottom; a file's layer is the first folder under `src/`.
const LAYERS: [&str; 5] = ["support", "algorithms", "formats", "pipeline", "cli"];

fn rank(layer: &str) -> Option<usize> {
    LAYERS.iter().position(|l| *l == layer)
}

/// The `crate::LAYER` (or, in the binary's `cli`, `blendsim::LAYER`) arrows of one file's
/// non-test code: (line number, target layer, the path as written).
fn arrows(text: &str) -> Vec<(usize, String, String)> {
    let mut out = Vec::new();
    let mut lines = text.lines().enumerate().peekable();
    while let Some((i, line)) = lines.next() {
        let trimmed = line.trim_start();
        if trimmed.starts_with("#[cfg(test)]") {
            // The next item is test code: a `mod x;` line, or a block to its closing brace at
            // the same indentation.
            let Some((_, item)) = lines.next() else { break };
            if item.trim_end().ends_with('{') {
                let indent = item.len() - item.trim_start().len();
                for (_, l) in lines.by_ref() {
                    if l.len() - l.trim_start().len() == indent && l.trim_start().starts_with('}') {
                        break;
                    }
                }
            }
            continue;
        }
        if trimmed.starts_with("//") {
            continue;
        }
        let code = line.split("//").next().unwrap_or("");
        for prefix in ["crate::", "blendsim::"] {
            let mut rest = code;
            while let Some(at) = rest.find(prefix) {
                let after = &rest[at + prefix.len()..];
                let name: String = after.chars().take_while(|c| c.is_ascii_alphanumeric() || *c == '_').collect();
                let whole: String = after.chars().take_while(|c| c.is_ascii_alphanumeric() || *c == '_' || *c == ':').collect();
                rest = &after[name.len()..];
                if rank(&name).is_some() {
                    out.push((i + 1, name, format!("{prefix}{whole}")));
                }
            }
        }
    }
    out
}

/// Files that are test code as a whole: declared as `#[cfg(test)] mod NAME;` in their parent.
fn test_files(files: &[PathBuf]) -> BTreeSet<PathBuf> {
    let mut tests = BTreeSet::new();
    for file in files {
        let text = std::fs::read_to_string(file).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        for w in lines.windows(2) {
            if w[0].trim() != "#[cfg(test)]" {
                continue;
            }
            let item = w[1].trim();
            let Some(name) = item.strip_prefix("mod ").or_else(|| item.strip_prefix("pub(crate) mod ")).and_then(|s| s.strip_suffix(';')) else {
                continue;
            };
            // A module's children live beside `mod.rs`/`lib.rs`, else in the folder named after the file.
            let dir = match file.file_name().and_then(|n| n.to_str()) {
                Some("mod.rs") | Some("lib.rs") | Some("main.rs") => file.parent().unwrap().to_path_buf(),
                _ => file.with_extension(""),
            };
            for candidate in [dir.join(format!("{name}.rs")), dir.join(name).join("mod.rs")] {
                if candidate.exists() {
                    tests.insert(candidate);
                }
            }
        }
    }
    // A test module's own children are test code too.
    let roots: Vec<PathBuf> = tests.iter().cloned().collect();
    for root in roots {
        let dir = if root.file_name().is_some_and(|n| n == "mod.rs") { root.parent().unwrap().to_path_buf() } else { root.with_extension("") };
        tests.extend(files.iter().filter(|f| f.starts_with(&dir)).cloned());
    }
    tests
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
    out.sort();
}

/// Every arrow that points up, as `file:line: LAYER -> path`.
fn upward_arrows(src: &Path) -> Vec<String> {
    let mut files = Vec::new();
    rust_files(src, &mut files);
    let tests = test_files(&files);
    let mut bad = Vec::new();
    for file in files.iter().filter(|f| !tests.contains(*f)) {
        let relative = file.strip_prefix(src).unwrap();
        let Some(layer) = relative.components().next().and_then(|c| c.as_os_str().to_str()).and_then(rank) else { continue };
        for (line, target, path) in arrows(&std::fs::read_to_string(file).unwrap()) {
            if rank(&target).unwrap() > layer {
                bad.push(format!("src/{}:{line}: {} -> {path}", relative.display(), LAYERS[layer]));
            }
        }
    }
    bad
}

#[test]
fn no_import_points_up() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let bad = upward_arrows(&src);
    assert!(bad.is_empty(), "imports that point up a layer (support < algorithms < formats < pipeline < cli):\n{}", bad.join("\n"));
    // Every folder under src/ is a layer: a new top-level module must be placed in one.
    for entry in std::fs::read_dir(&src).unwrap() {
        let path = entry.unwrap().path();
        let name = path.file_name().unwrap().to_str().unwrap().to_owned();
        assert!(path.is_file() && ["lib.rs", "main.rs"].contains(&name.as_str()) || rank(&name).is_some(), "src/{name} is in no layer ({LAYERS:?})");
    }
}

#[test]
fn the_layer_check_sees_an_upward_arrow() {
    let dir = TempDir::new("layers");
    let src = dir.join("src");
    std::fs::create_dir_all(src.join("algorithms")).unwrap();
    std::fs::write(
        src.join("algorithms/solver.rs"),
        "use crate::support::error::Result;\n/// [`crate::pipeline`] in a comment is no arrow.\nuse crate::pipeline::scene::Scene;\n#[cfg(test)]\nmod tests {\n    use crate::pipeline::stages::bake;\n}\n#[cfg(test)]\nmod fixtures;\n",
    )
    .unwrap();
    std::fs::create_dir_all(src.join("algorithms/solver")).unwrap();
    std::fs::write(src.join("algorithms/solver/fixtures.rs"), "use crate::formats::mesh::obj;\n").unwrap();
    assert_eq!(upward_arrows(&src), vec!["src/algorithms/solver.rs:3: algorithms -> crate::pipeline::scene::Scene".to_string()]);
}
