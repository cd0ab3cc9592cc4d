use std::path::PathBuf;

use blendsim::pipeline::report::guard_rails::not_converged;
use blendsim::pipeline::stage_file::{self, Animation};
use blendsim::pipeline::stages;
use blendsim::support::output::{LockWait, Staging};
use blendsim::support::progress::Progress;
use blendsim::Result;

use super::Summary;

/// Write the blendshape and full-frame animation files into --out.
///
/// Formats are the scene's [export] formats; NAME.outputs.json lists what was written.
/// Blendshape: NAME.usda / NAME.usdc (UsdSkel BlendShapes and weights), NAME.glb (morph
/// targets with CUBICSPLINE weights). Full-frame: NAME.full.EXT. Every format is written
/// natively (no usd-core). Nothing is written unless every file succeeds; the folder is then
/// replaced in one step, keeping files that are not blendsim's and removing the files an
/// earlier export of the same scene wrote that this one does not.
#[derive(clap::Args)]
pub(crate) struct Args {
    /// The animation stage file from `blendsim embed`.
    animation: PathBuf,
    /// Output folder (created if missing).
    #[arg(short = 'o', long, alias = "output", value_name = "DIR")]
    out: PathBuf,
    /// Fail at once if another blendsim is writing into --out (by default: wait for it).
    #[arg(long)]
    no_wait: bool,
    /// Every warning the animation carries (formats/report.md, "Warnings") is an error: one
    /// line each, exit code 3, nothing written and --out left as it was.
    #[arg(long)]
    strict: bool,
    #[command(flatten)]
    budget: super::BudgetArgs,
}

impl Args {
    pub(crate) fn input(&self) -> &std::path::Path {
        &self.animation
    }
}

pub(crate) fn run(args: Args, progress: &Progress) -> Result<Summary> {
    let budget = args.budget.budget();
    let animation: Animation = stage_file::read(&args.animation, &budget)?;
    if args.strict {
        let mut warnings = animation.warnings.clone();
        warnings.extend(not_converged(&animation.log));
        super::refuse_warnings(&warnings)?;
    }
    let mut staging = Staging::open(&args.out, if args.no_wait { LockWait::Fail } else { LockWait::Wait })?;
    let clip = stages::blendshape_clip(&animation, None, &budget)?;
    let outputs = stages::export_with(&animation, &clip, &mut staging, &budget, progress)?;
    staging.write(&stages::export::outputs_list_name(&animation.scene), &stage_file::to_json(&outputs))?;
    let committed = staging.commit_with_summary()?;
    Ok(Summary { warnings: animation.warnings, ..Summary::folder(&args.out, &committed) })
}
