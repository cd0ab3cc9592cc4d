use std::path::PathBuf;

use blendsim::pipeline::stage_file::{self, Body};
use blendsim::pipeline::stages;
use blendsim::support::progress::Progress;
use blendsim::Result;

use super::MethodArg;

/// Optimize the keyframe trajectory of a body and write the solution stage file.
///
/// `spacetime` (default) runs BlendSim's spacetime projective dynamics; `hermite` joins the
/// keyframes with zero velocities (the geometric baseline); `mass-spring` makes in-between
/// shapes by Ma et al. 2012's mass-spring blendshapes ([mass_spring] in the scene).
#[derive(clap::Args)]
pub struct Args {
    /// The body stage file from `blendsim tetrahedralize`.
    body: PathBuf,
    /// Where to write the solution stage file (JSON).
    #[arg(short, long)]
    output: PathBuf,
    /// Override the scene's [solver] method.
    #[arg(long, value_enum)]
    method: Option<MethodArg>,
    #[command(flatten)]
    budget: super::BudgetArgs,
}

impl Args {
    pub fn input(&self) -> &std::path::Path {
        &self.body
    }
}

pub fn run(args: Args, progress: &Progress) -> Result<()> {
    let budget = args.budget.budget();
    let body: Body = stage_file::read(&args.body, &budget)?;
    stage_file::write(&args.output, &stages::solve_within(&body, args.method.map(Into::into), &budget, progress)?)
}
