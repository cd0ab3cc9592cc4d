use std::path::PathBuf;

use blendsim::pipeline::depfile;
use blendsim::pipeline::scene::SceneFile;
use blendsim::Result;

use super::Summary;

/// List the files a bake of each scene reads (the depfile's inputs), without baking: one JSON
/// line per scene on stdout, `{"scene", "inputs"}` or `{"scene", "error"}` (the one-line
/// message the bake would print). The cluster driver (cluster/) ships these files to its
/// workers.
#[derive(clap::Args)]
pub(crate) struct Args {
    /// The scene files (TOML; see formats/scene.md).
    #[arg(required = true)]
    scenes: Vec<PathBuf>,
}

impl Args {
    pub(crate) fn input(&self) -> &std::path::Path {
        &self.scenes[0]
    }
}

pub(crate) fn run(args: Args) -> Result<Summary> {
    for scene in &args.scenes {
        // Each scene's own error, so one bad scene does not hide the others' inputs.
        let line = match SceneFile::load(scene).and_then(|s| depfile::inputs(&s)) {
            Ok(inputs) => serde_json::json!({ "scene": scene, "inputs": inputs }),
            Err(e) => serde_json::json!({ "scene": scene, "error": e.with_path(scene.clone()).to_string() }),
        };
        println!("{line}");
    }
    Ok(Summary::default())
}
