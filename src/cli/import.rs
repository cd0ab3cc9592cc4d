use std::path::PathBuf;

use blendsim::pipeline::scene::SceneFile;
use blendsim::pipeline::{stage_file, stages};
use blendsim::support::progress::Progress;
use blendsim::Error;
use blendsim::Result;

use super::Summary;

/// Read a scene's keyframe meshes (or vertex cache) and write the keyframes stage file; or
/// convert the scene's cache to another cache format.
///
/// Checks that every keyframe has the same topology, applies procedural deformations,
/// orients the rest shape, and resolves the per-key `fixed` / `fixed_velocity` selections.
/// With a [cache], chooses its keys. `--cache-out PATH` writes the [cache] (its range) in the
/// format PATH names: an OBJ sequence (a #### pattern), .pc2, .mdd, .glb, .usda, .usdc or .usd.
#[derive(clap::Args)]
pub(crate) struct Args {
    /// The scene file (TOML; see formats/scene.md).
    scene: PathBuf,
    /// Where to write the keyframes stage file (JSON).
    #[arg(short = 'o', long = "out", alias = "output", value_name = "FILE", required_unless_present = "cache_out")]
    output: Option<PathBuf>,
    /// Also (or only) write the scene's [cache] in the format this path names.
    #[arg(long)]
    cache_out: Option<PathBuf>,
    #[command(flatten)]
    budget: super::BudgetArgs,
}

impl Args {
    pub(crate) fn input(&self) -> &std::path::Path {
        &self.scene
    }
}

pub(crate) fn run(args: Args, _progress: &Progress) -> Result<Summary> {
    let budget = args.budget.budget();
    let scene = SceneFile::load(&args.scene)?;
    if let Some(out) = &args.cache_out {
        let Some(spec) = &scene.scene.cache else {
            return Err(Error::in_file(
                &args.scene,
                "--cache-out converts a [cache], but the scene has [keyframes]",
                "give a scene with a [cache] table",
            ));
        };
        stages::import_cache::convert(&scene, spec, out)?;
    }
    if let Some(o) = &args.output {
        stage_file::write(o, &stages::import(&scene, &budget)?)?;
    }
    Ok(Summary::wrote(args.cache_out.into_iter().chain(args.output)))
}
