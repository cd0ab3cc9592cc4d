use std::path::PathBuf;

use blendsim::progress::Progress;
use blendsim::scene::Method;
use blendsim::stage::{self, Body};
use blendsim::{solve, Result};

/// Optimize the keyframe trajectory of a body and write the solution stage file.
///
/// `spacetime` (default) runs BlendSim's spacetime projective dynamics; `hermite` joins the
/// keyframes with zero velocities (the geometric baseline).
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
}

#[derive(Clone, Copy, clap::ValueEnum)]
pub enum MethodArg {
    Hermite,
    Spacetime,
}

impl From<MethodArg> for Method {
    fn from(m: MethodArg) -> Method {
        match m {
            MethodArg::Hermite => Method::Hermite,
            MethodArg::Spacetime => Method::Spacetime,
        }
    }
}

impl Args {
    pub fn input(&self) -> &std::path::Path {
        &self.body
    }
}

pub fn run(args: Args, progress: &Progress) -> Result<()> {
    let mut body: Body = stage::read(&args.body)?;
    if let Some(m) = args.method {
        body.scene.solver.method = m.into();
    }
    stage::write(&args.output, &solve::solve(&body, progress)?)
}
