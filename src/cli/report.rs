use std::path::PathBuf;

use blendsim::output::{LockWait, Staging};
use blendsim::progress::Progress;
use blendsim::stage::{self, Animation, Outputs};
use blendsim::{stages, Result};

/// Write report.json and report.md into --out.
///
/// Sizes of the blendshape and full-frame files side by side, fidelity against the full-frame
/// evaluation, keyframe deviation, volume, and the solver's history (see formats/report.md).
#[derive(clap::Args)]
pub struct Args {
    /// The animation stage file from `blendsim embed`.
    animation: PathBuf,
    /// The NAME.outputs.json written by `blendsim export`.
    #[arg(long)]
    outputs: PathBuf,
    /// Output folder for report.json and report.md.
    #[arg(long)]
    out: PathBuf,
    /// Fail at once if another blendsim is writing into --out (by default: wait for it).
    #[arg(long)]
    no_wait: bool,
}

impl Args {
    pub fn input(&self) -> &std::path::Path {
        &self.animation
    }
}

pub fn run(args: Args, _progress: &Progress) -> Result<()> {
    let animation: Animation = stage::read(&args.animation)?;
    let outputs: Outputs = stage::read(&args.outputs)?;
    let report = stages::report(&animation, &outputs);
    let mut staging = Staging::open(&args.out, if args.no_wait { LockWait::Fail } else { LockWait::Wait })?;
    report.write(&mut staging)?;
    staging.commit()
}
