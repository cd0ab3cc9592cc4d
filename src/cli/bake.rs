use std::path::PathBuf;
use std::time::Instant;

use blendsim::pipeline::scene::SceneFile;
use blendsim::pipeline::stages;
use blendsim::support::output::{LockWait, Staging};
use blendsim::support::progress::Progress;
use blendsim::Result;

use super::MethodArg;

/// Bake a scene: import, tetrahedralize, solve, embed, export and report in one process.
///
/// Writes NAME.usda / NAME.glb (and the other formats of [export]), their full-frame
/// versions NAME.full.EXT, report.json and report.md into --out. Nothing is written unless
/// the whole bake succeeds; the folder is then replaced in one step, keeping files that are
/// not blendsim's and removing those an earlier run wrote that this one does not (whatever
/// scene they were of), and says on stderr which it removed and which it kept.
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
    /// Memory the solve's global step may use (e.g. 4G, 512M); past it the step is solved
    /// iteratively instead of by a sparse factorization; every other memory estimate (frames,
    /// samples) must fit in it too. Default: 60% of the available memory.
    #[arg(long, value_parser = super::parse_bytes)]
    max_memory: Option<u64>,
    /// Time the bake may take, in seconds (e.g. 600, 90s, 10m, 2h): TetGen gets at most what
    /// is left of it (or [tet] timeout, the smaller); the solve checks it before its global
    /// step is built (against the predicted cost) and at every iteration, a cache's key
    /// selection, fit and error measure at every frame they read, the mass-spring blend at every Newton
    /// iteration; the bake stops with an error (nothing written) once it is spent. Default: no limit.
    #[arg(long, value_parser = super::parse_seconds)]
    max_time: Option<f64>,
    /// Fail at once if another blendsim is writing into --out (by default: wait for it).
    #[arg(long)]
    no_wait: bool,
}

impl Args {
    pub fn input(&self) -> &std::path::Path {
        &self.scene
    }
}

pub fn run(args: Args, progress: &Progress, quiet: bool) -> Result<()> {
    let start = Instant::now();
    if let Some(bytes) = args.max_memory {
        blendsim::support::resources::set_max_memory(bytes);
    }
    if let Some(seconds) = args.max_time {
        blendsim::support::resources::set_max_time(seconds);
    }
    let scene = SceneFile::load(&args.scene)?;
    // Check the output location before the work, not after.
    let mut staging = Staging::open(&args.out, if args.no_wait { LockWait::Fail } else { LockWait::Wait })?;
    // A bake is the folder's whole blendsim content: an earlier bake's files go, whatever
    // scene wrote them (a renamed scene's too); files blendsim did not write stay.
    staging.replace_every_group();
    // A user's file or folder at one of the names is refused before the work, not after.
    staging.claim(&stages::bake::file_names(&scene))?;
    let r = stages::Bake::new(&scene, progress).method(args.method.map(Into::into)).max_memory(args.max_memory).files(&mut staging)?;
    let committed = staging.commit_with_summary()?;
    if !quiet {
        for line in committed.messages(&args.out, "bake") {
            eprintln!("blendsim: {line}");
        }
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
