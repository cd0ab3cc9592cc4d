use std::path::PathBuf;
use std::time::Instant;

use blendsim::output::Staging;
use blendsim::progress::Progress;
use blendsim::scene::SceneFile;
use blendsim::{stages, Result};

use super::MethodArg;

/// Bake a scene: import, tetrahedralize, solve, embed, export and report in one process.
///
/// Writes NAME.usda / NAME.glb (and the other formats of [export]), their full-frame
/// versions NAME.full.EXT, report.json and report.md into --out. Nothing is written unless
/// the whole bake succeeds.
#[derive(clap::Args)]
pub struct Args {
    /// The scene file (TOML; see formats/scene.md).
    scene: PathBuf,
    /// Output folder (created if missing).
    #[arg(long)]
    out: PathBuf,
    /// Override the scene's [solver] method.
    #[arg(long, value_enum)]
    method: Option<MethodArg>,
}

pub fn run(args: Args, progress: &Progress, quiet: bool) -> Result<()> {
    let start = Instant::now();
    let scene = SceneFile::load(&args.scene)?;
    // Check the output location before the work, not after.
    let mut staging = Staging::new(&args.out)?;
    let r = stages::bake(&scene, args.method.map(Into::into), &mut staging, progress)?;
    staging.commit()?;
    if !quiet {
        let best = r.ratios.iter().map(|(f, x)| format!("{f} {x:.1}x")).collect::<Vec<_>>().join(", ");
        eprintln!(
            "blendsim: baked {} in {:.2} s ({} keys, {} tets, {} {} iterations); blendshapes smaller by {best}; report in {}",
            r.scene,
            start.elapsed().as_secs_f64(),
            r.keyframes,
            r.tets,
            r.solver.method,
            r.solver.iterations,
            args.out.join("report.md").display()
        );
    }
    Ok(())
}
