use std::path::PathBuf;

use blendsim::pipeline::report::guard_rails::not_converged;
use blendsim::pipeline::stage_file::{self, Solution};
use blendsim::pipeline::stages;
use blendsim::support::progress::Progress;
use blendsim::Result;

use super::Summary;

/// Carry the exported surface on the solved tet trajectory and write the animation stage file.
///
/// The surface is bound to the rest tet mesh by barycentric coordinates (the closest tet for
/// points outside it). The binding is linear, so the Hermite trajectory stays exact.
#[derive(clap::Args)]
pub(crate) struct Args {
    /// The solution stage file from `blendsim solve`.
    solution: PathBuf,
    /// Where to write the animation stage file (JSON).
    #[arg(short = 'o', long = "out", alias = "output", value_name = "FILE")]
    output: PathBuf,
    /// Every warning the solution carries (formats/report.md, "Warnings") is an error: one
    /// line each, exit code 3, nothing written.
    #[arg(long)]
    strict: bool,
    #[command(flatten)]
    budget: super::BudgetArgs,
}

impl Args {
    pub(crate) fn input(&self) -> &std::path::Path {
        &self.solution
    }
}

pub(crate) fn run(args: Args, _progress: &Progress) -> Result<Summary> {
    let budget = args.budget.budget();
    let solution: Solution = stage_file::read(&args.solution, &budget)?;
    let animation = stages::embed(&solution)?;
    if args.strict {
        let mut warnings = animation.warnings.clone();
        warnings.extend(not_converged(&solution.log));
        super::refuse_warnings(&warnings)?;
    }
    stage_file::write(&args.output, &animation)?;
    Ok(Summary { warnings: animation.warnings, ..Summary::wrote([args.output]) })
}
