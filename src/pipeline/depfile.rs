//! Make depfiles (`bake --depfile FILE`): every file a bake reads, so that a Makefile that
//! includes the depfile re-bakes when a mesh, a selection, a texture or the cache changes, not
//! only the scene.
//!
//! The format is the one compilers write with `-MD -MP`: one rule `OUTPUTS: INPUTS`, then an
//! empty rule per input, so that deleting an input (a renamed mesh) makes `make` re-bake
//! instead of stopping with "No rule to make target".

use std::path::{Path, PathBuf};

use super::scene::{Rest, SceneFile, Selection};
use crate::formats::cache::SequencePattern;
use crate::formats::mesh::obj;
use crate::support::error::Result;

/// The files a bake of `scene` reads, in the order first met, each once: the scene, the
/// keyframe meshes or clip (or the cache: every frame of an OBJ sequence), the rest and embedded
/// surfaces, selection files, and the `.mtl` files and textures of the OBJ files among them.
/// Files that do not exist are left out (the bake itself reports them).
pub fn inputs(scene_file: &SceneFile) -> Result<Vec<PathBuf>> {
    let scene = &scene_file.scene;
    let mut found = vec![scene_file.path.clone()];
    let mut add = |path: PathBuf| -> Result<()> {
        if path.is_file() && !found.contains(&path) {
            if path.extension().is_some_and(|e| e.eq_ignore_ascii_case("obj")) {
                found.push(path.clone());
                for companion in obj::companions(&path)? {
                    if !found.contains(&companion) {
                        found.push(companion);
                    }
                }
            } else {
                found.push(path);
            }
        }
        Ok(())
    };
    let rest_mesh = |rest: &Rest| match rest {
        Rest::Mesh(m) => Some(scene_file.resolve(m)),
        Rest::Key(_) => None,
    };
    // A cache or clip: its file, or every frame of an OBJ sequence.
    let animated = |path: PathBuf| match SequencePattern::parse(&path) {
        Ok(pattern) if SequencePattern::is_pattern(&path) => pattern.scan(&path).unwrap_or_default().into_iter().map(|n| pattern.path(n)).collect(),
        _ => vec![path],
    };
    if let Some(keys) = &scene.keyframes {
        for mesh in &keys.meshes {
            add(scene_file.resolve(mesh.path()))?;
        }
        if let Some(clip) = &keys.clip {
            for file in animated(scene_file.resolve(clip)) {
                add(file)?;
            }
        }
        if let Some(m) = rest_mesh(&keys.rest) {
            add(m)?;
        }
        for selection in keys.fixed.iter().chain(&keys.fixed_velocity).flatten() {
            for file in selection_files(selection) {
                add(scene_file.resolve(file))?;
            }
        }
    }
    if let Some(cache) = &scene.cache {
        for file in animated(scene_file.resolve(&cache.path)) {
            add(file)?;
        }
        if let Some(m) = cache.rest.as_ref().and_then(rest_mesh) {
            add(m)?;
        }
        for selection in cache.fixed.iter().chain(&cache.fixed_velocity) {
            for file in selection_files(selection) {
                add(scene_file.resolve(file))?;
            }
        }
    }
    if let Some(surface) = &scene.embed.surface {
        add(scene_file.resolve(surface))?;
    }
    Ok(found)
}

/// The index files a selection reads (a union's, each of its parts').
fn selection_files(selection: &Selection) -> Vec<&str> {
    match selection {
        Selection::File { file, .. } => vec![file.as_str()],
        Selection::Union(parts) => parts.iter().flat_map(selection_files).collect(),
        _ => Vec::new(),
    }
}

/// The depfile text: `targets` depend on `inputs`, and each input has an empty rule.
pub fn render(targets: &[PathBuf], inputs: &[PathBuf]) -> String {
    let names = |paths: &[PathBuf]| paths.iter().map(|p| escape(p)).collect::<Vec<_>>().join(" \\\n  ");
    let mut text = format!("{}: \\\n  {}\n", names(targets), names(inputs));
    for input in inputs {
        text.push_str(&format!("\n{}:\n", escape(input)));
    }
    text
}

/// A path as Make reads it in a rule: spaces, `#`, `:` and backslashes escaped, `$` doubled.
fn escape(path: &Path) -> String {
    let mut out = String::new();
    for c in path.to_string_lossy().chars() {
        match c {
            ' ' | '#' | ':' | '\\' => {
                out.push('\\');
                out.push(c);
            }
            '$' => out.push_str("$$"),
            c => out.push(c),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rules_escape_what_make_would_split() {
        let text = render(&[PathBuf::from("out/report.json")], &[PathBuf::from("my scene.toml"), PathBuf::from("a$b#c.obj")]);
        assert_eq!(text, "out/report.json: \\\n  my\\ scene.toml \\\n  a$$b\\#c.obj\n\nmy\\ scene.toml:\n\na$$b\\#c.obj:\n");
    }
}
