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
    /// Memory the global step may use (e.g. 4G, 512M); past it the step is solved iteratively
    /// instead of by a sparse factorization; every other memory estimate must fit in it too.
    /// Default: 60% of the available memory.
    #[arg(long, value_parser = super::parse_bytes)]
    max_memory: Option<u64>,
    /// Time the solve may take, in seconds (e.g. 600, 90s, 10m, 2h): the solve checks it
    /// before its global step is built (against the predicted cost) and at every iteration,
    /// and stops with an error (nothing written) once it is spent. Default: no limit.
    #[arg(long, value_parser = super::parse_seconds)]
    max_time: Option<f64>,
}

impl Args {
    pub fn input(&self) -> &std::path::Path {
        &self.body
    }
}

pub fn run(args: Args, progress: &Progress) -> Result<()> {
    if let Some(bytes) = args.max_memory {
        blendsim::support::resources::set_max_memory(bytes);
    }
    if let Some(seconds) = args.max_time {
        blendsim::support::resources::set_max_time(seconds);
    }
    let body: Body = stage_file::read(&args.body)?;
    stage_file::write(&args.output, &stages::solve_within(&body, args.method.map(Into::into), args.max_memory, progress)?)
}
