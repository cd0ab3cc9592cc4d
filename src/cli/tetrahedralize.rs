use std::path::PathBuf;

use blendsim::pipeline::stage_file::{self, Keyframes};
use blendsim::pipeline::stages;
use blendsim::support::progress::Progress;
use blendsim::Result;

use super::Summary;

/// Turn keyframes into a simulation body (tet mesh and per-node keyframe poses).
///
/// Surface keyframes are tetrahedralized by TetGen (`apt-get install tetgen`); the interior
/// nodes get a quasi-static pose per key. Tet-mesh keyframes pass through.
#[derive(clap::Args)]
pub(crate) struct Args {
    /// The keyframes stage file from `blendsim import`.
    keyframes: PathBuf,
    /// Where to write the body stage file (JSON).
    #[arg(short = 'o', long = "out", alias = "output", value_name = "FILE")]
    output: PathBuf,
    /// Every warning (folded-key, max-volume: formats/report.md, "Warnings") is an error: one
    /// line each, exit code 3, nothing written.
    #[arg(long)]
    strict: bool,
    #[command(flatten)]
    budget: super::BudgetArgs,
}

impl Args {
    pub(crate) fn input(&self) -> &std::path::Path {
        &self.keyframes
    }
}

pub(crate) fn run(args: Args, progress: &Progress) -> Result<Summary> {
    let budget = args.budget.budget();
    let keys: Keyframes = stage_file::read(&args.keyframes, &budget)?;
    let body = if args.strict {
        let body = stages::tetrahedralize(&keys, &budget, &progress.without_warnings())?;
        super::refuse_warnings(&body.warnings)?;
        body
    } else {
        stages::tetrahedralize(&keys, &budget, progress)?
    };
    stage_file::write(&args.output, &body)?;
    Ok(Summary { warnings: body.warnings, ..Summary::wrote([args.output]) })
}
