use std::path::PathBuf;

use blendsim::progress::Progress;
use blendsim::scene::SceneFile;
use blendsim::{stage, stages, Result};

/// Read a scene's keyframe meshes and write the keyframes stage file.
///
/// Checks that every keyframe has the same topology, applies procedural deformations,
/// orients the rest shape, and resolves the per-key `fixed` / `fixed_velocity` selections.
#[derive(clap::Args)]
pub struct Args {
    /// The scene file (TOML; see formats/scene.md).
    scene: PathBuf,
    /// Where to write the keyframes stage file (JSON).
    #[arg(short, long)]
    output: PathBuf,
}

impl Args {
    pub fn input(&self) -> &std::path::Path {
        &self.scene
    }
}

pub fn run(args: Args, _progress: &Progress) -> Result<()> {
    let scene = SceneFile::load(&args.scene)?;
    stage::write(&args.output, &stages::import(&scene)?)
}
