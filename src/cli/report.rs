use std::path::PathBuf;

use blendsim::pipeline::report::batch;
use blendsim::pipeline::stage_file::{self, Animation, Outputs};
use blendsim::pipeline::stages;
use blendsim::support::output::{LockWait, Staging};
use blendsim::support::progress::Progress;
use blendsim::Result;

use super::{refuse_warnings, Summary};

/// Write report.json, report.md and report.html into --out; or, with --batch, summary.csv,
/// summary.md and summary.html of many bakes.
///
/// Sizes of the blendshape and full-frame files side by side, fidelity against the full-frame
/// evaluation, keyframe deviation, volume, the solver's history, and for a cache the error
/// against its frames (see formats/report.md). `--batch DIR...` reads the report.json of each
/// DIR (or of each subfolder of DIR) and writes one row per bake.
#[derive(clap::Args)]
#[command(
    override_usage = "blendsim report [OPTIONS] --out <DIR> <ANIMATION> --outputs <NAME.outputs.json>\n       blendsim report [OPTIONS] --out <DIR> --batch <DIR>..."
)]
pub(crate) struct Args {
    /// The animation stage file from `blendsim embed`.
    #[arg(required_unless_present = "batch", conflicts_with = "batch")]
    animation: Option<PathBuf>,
    /// The NAME.outputs.json written by `blendsim export`: required with ANIMATION (without
    /// --batch).
    #[arg(long, value_name = "NAME.outputs.json", required_unless_present = "batch", conflicts_with = "batch")]
    outputs: Option<PathBuf>,
    /// Bake output folders (or folders of them) to summarize.
    #[arg(long, num_args = 1.., value_name = "DIR")]
    batch: Vec<PathBuf>,
    /// Output folder for report.json, report.md and report.html (summary.csv, summary.md and
    /// summary.html with --batch).
    #[arg(short = 'o', long, alias = "output", value_name = "DIR")]
    out: PathBuf,
    /// Fail at once if another blendsim is writing into --out (by default: wait for it).
    #[arg(long)]
    no_wait: bool,
    #[command(flatten)]
    budget: super::BudgetArgs,
    /// Every warning (the animation's and the report's guard rails, formats/report.md
    /// "Warnings") is an error: one line each, exit code 3, nothing written.
    #[arg(long, conflicts_with = "batch")]
    strict: bool,
}

impl Args {
    pub(crate) fn input(&self) -> &std::path::Path {
        self.animation.as_deref().or(self.batch.first().map(PathBuf::as_path)).unwrap_or(&self.out)
    }
}

pub(crate) fn run(args: Args, progress: &Progress) -> Result<Summary> {
    let budget = args.budget.budget();
    let mut staging = Staging::open(&args.out, if args.no_wait { LockWait::Fail } else { LockWait::Wait })?;
    if !args.batch.is_empty() {
        let reports = batch::find_reports(&args.batch)?.into_iter().map(|p| batch::read(&p).map(|r| (p, r))).collect::<Result<Vec<_>>>()?;
        let (csv, md, html) = batch::summarize(&reports, &args.out);
        staging.set_group("summary");
        staging.write("summary.csv", csv.as_bytes())?;
        staging.write("summary.md", md.as_bytes())?;
        staging.write("summary.html", html.as_bytes())?;
        let committed = staging.commit_with_summary()?;
        return Ok(Summary::folder(&args.out, &committed));
    }
    let (Some(animation), Some(outputs)) = (&args.animation, &args.outputs) else { unreachable!("clap requires both without --batch") };
    let animation: Animation = stage_file::read(animation, &budget)?;
    let outputs: Outputs = stage_file::read(outputs, &budget)?;
    let report = stages::report(&animation, &outputs, &budget)?;
    if args.strict {
        refuse_warnings(&report.warnings)?;
    }
    // The stages' own warnings were printed by the stages; the guard rails' are new here.
    report.warnings[animation.warnings.len()..].iter().for_each(|w| progress.warn(w));
    report.write(&mut staging)?;
    let committed = staging.commit_with_summary()?;
    Ok(Summary {
        ratios: report.ratios.iter().map(|(f, x)| (f.to_string(), *x)).collect(),
        warnings: report.warnings,
        ..Summary::folder(&args.out, &committed)
    })
}
