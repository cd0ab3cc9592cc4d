use std::path::PathBuf;
use std::time::Instant;

use blendsim::pipeline::scene::SceneFile;
use blendsim::pipeline::stages;
use blendsim::pipeline::stages::bake_cache::{self, BakeCache};
use blendsim::support::output::{LockWait, Staging};
use blendsim::support::progress::Progress;
use blendsim::Result;

use super::{MethodArg, Summary};

/// Bake a scene: import, tetrahedralize, solve, embed, export and report in one process.
///
/// Writes NAME.usda / NAME.glb (and the other formats of [export]), their full-frame
/// versions NAME.full.EXT, report.json, report.md and report.html into --out. Nothing is written unless
/// the whole bake succeeds; the folder is then replaced in one step, keeping files that are
/// not blendsim's and removing those an earlier run wrote that this one does not (whatever
/// scene they were of), and says on stderr which it removed and which it kept.
#[derive(clap::Args)]
pub(crate) struct Args {
    /// The scene file (TOML; see formats/scene.md).
    scene: PathBuf,
    /// Output folder (created if missing).
    #[arg(short = 'o', long, alias = "output", value_name = "DIR")]
    out: PathBuf,
    /// Reuse an earlier bake's work, kept in its bake.cache: the stages whose inputs (files,
    /// settings, the blendsim binary) are the same bytes are not run again (TetGen, the solve),
    /// and when only key poses moved the solve starts from that bake's solution. DIR is that
    /// bake's --out; this bake keeps its own bake.cache in --out for the next, so the loop is
    /// `bake SCENE --out DIR --from DIR` (the first bake into DIR runs cold). A damaged or
    /// older cache is a warning and a cold bake; a DIR that is no bake's output, an error.
    #[arg(long, value_name = "DIR")]
    from: Option<PathBuf>,
    /// Override the scene's [solver] method.
    #[arg(long, value_enum)]
    method: Option<MethodArg>,
    /// Fail at once if another blendsim is writing into --out (by default: wait for it).
    #[arg(long)]
    no_wait: bool,
    /// Every warning is an error (formats/report.md, "Warnings"): one `error: CODE: ...` line
    /// each, exit code 3, nothing written and --out left as it was.
    #[arg(long)]
    strict: bool,
    /// Also write a Make depfile: every file written depends on every file the bake read (the
    /// scene, meshes, selections, .mtl files, textures, the cache's frames), with an empty rule
    /// per input (as `cc -MD -MP`). Written only when the bake succeeds.
    #[arg(long, value_name = "FILE")]
    depfile: Option<PathBuf>,
    #[command(flatten)]
    budget: super::BudgetArgs,
}

impl Args {
    pub(crate) fn input(&self) -> &std::path::Path {
        &self.scene
    }
}

pub(crate) fn run(args: Args, progress: &Progress, quiet: bool) -> Result<Summary> {
    let budget = args.budget.budget();
    let start = Instant::now();
    let scene = SceneFile::load(&args.scene)?;
    let previous = match &args.from {
        // A first bake into its own --out has nothing to reuse yet.
        Some(from) if from == &args.out && !from.exists() => None,
        Some(from) => match BakeCache::load(from)? {
            Ok(cache) => Some(cache),
            Err(why) => {
                eprintln!("blendsim: warning: --from: {why}; baking cold");
                None
            }
        },
        None => None,
    };
    // Check the output location before the work, not after.
    let mut staging = Staging::open(&args.out, if args.no_wait { LockWait::Fail } else { LockWait::Wait })?;
    // A bake is the folder's whole blendsim content: an earlier bake's files go, whatever
    // scene wrote them (a renamed scene's too); files blendsim did not write stay.
    staging.replace_every_group();
    // A user's file or folder at one of the names is refused before the work, not after.
    let mut names = stages::bake::file_names(&scene);
    if args.from.is_some() {
        names.push(bake_cache::FILE.into());
    }
    staging.claim(&names)?;
    // Under --strict the warnings are printed once, as errors, if the bake gets that far.
    let progress = if args.strict { progress.without_warnings() } else { progress.clone() };
    let bake = stages::Bake::new(&scene, &progress).method(args.method.map(Into::into)).budget(budget).reusing(previous.as_ref());
    let (r, reused) = if args.from.is_some() { bake.files_reusing(&mut staging)? } else { (bake.files(&mut staging)?, Default::default()) };
    if args.strict {
        // Before the commit: the staged files go with `staging`, --out stays as it was.
        super::refuse_warnings(&r.warnings)?;
    }
    // The inputs are listed before the commit: a bake whose depfile cannot be made writes nothing.
    let inputs = args.depfile.as_ref().map(|_| blendsim::pipeline::depfile::inputs(&scene)).transpose()?;
    let committed = staging.commit_with_summary()?;
    let mut summary = Summary::folder(&args.out, &committed);
    if let (Some(depfile), Some(inputs)) = (&args.depfile, inputs) {
        blendsim::support::output::write_atomic(depfile, blendsim::pipeline::depfile::render(&summary.outputs, &inputs).as_bytes())?;
        summary.outputs.push(depfile.clone());
    }
    if !quiet {
        for line in committed.messages(&args.out, "bake") {
            eprintln!("blendsim: {line}");
        }
        if let Some(from) = &args.from {
            let what = if previous.is_some() { reused.describe() } else { "nothing to reuse, every stage ran".into() };
            eprintln!("blendsim: from {}: {what}", from.display());
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
    Ok(Summary { ratios: r.ratios.iter().map(|(f, x)| (f.to_string(), *x)).collect(), warnings: r.warnings, ..summary })
}
