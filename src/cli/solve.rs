use std::path::PathBuf;

use blendsim::pipeline::report::guard_rails::not_converged;
use blendsim::pipeline::stage_file::{self, Body};
use blendsim::pipeline::stages;
use blendsim::support::progress::Progress;
use blendsim::Result;

use super::{MethodArg, Summary};

/// Optimize the keyframe trajectory of a body and write the solution stage file.
///
/// `spacetime` (default) runs BlendSim's spacetime projective dynamics; `hermite` joins the
/// keyframes with zero velocities (the geometric baseline); `mass-spring` makes in-between
/// shapes by Ma et al. 2012's mass-spring blendshapes ([mass_spring] in the scene); `fit`
/// (a [cache] scene) fits Hermite keys, positions and velocities, to the cache's frames.
#[derive(clap::Args)]
pub(crate) struct Args {
    /// The body stage file from `blendsim tetrahedralize`.
    body: PathBuf,
    /// Where to write the solution stage file (JSON).
    #[arg(short = 'o', long = "out", alias = "output", value_name = "FILE")]
    output: PathBuf,
    /// Override the scene's [solver] method.
    #[arg(long, value_enum)]
    method: Option<MethodArg>,
    /// Every warning known after the solve (the body's, `cg-capped`, `not-converged`:
    /// formats/report.md, "Warnings") is an error: one line each, exit code 3, nothing written.
    #[arg(long)]
    strict: bool,
    #[command(flatten)]
    budget: super::BudgetArgs,
}

impl Args {
    pub(crate) fn input(&self) -> &std::path::Path {
        &self.body
    }
}

pub(crate) fn run(args: Args, progress: &Progress) -> Result<Summary> {
    let budget = args.budget.budget();
    let body: Body = stage_file::read(&args.body, &budget)?;
    let progress = if args.strict { progress.without_warnings() } else { progress.clone() };
    let solution = stages::solve_within(&body, args.method.map(Into::into), &budget, &progress)?;
    if args.strict {
        let mut warnings = solution.body.warnings.clone();
        warnings.extend(not_converged(&solution.log));
        super::refuse_warnings(&warnings)?;
    }
    stage_file::write(&args.output, &solution)?;
    Ok(Summary { warnings: solution.body.warnings, ..Summary::wrote([args.output]) })
}
