use std::path::PathBuf;

use blendsim::pipeline::stages;
use blendsim::pipeline::stages::blend::{BlendJob, Weights};
use blendsim::support::progress::Progress;
use blendsim::Result;

use super::Summary;

/// Blend target meshes with mass-spring blendshapes (Ma et al. 2012): the rest lengths of a
/// spring network on the targets are blended with convex weights, and the network's
/// equilibrium is the shape.
///
///   blendsim blend --targets a.obj b.obj c.obj --weights 0.2,0.5,0.3 --out shape.obj
///   blendsim blend --targets a.obj b.obj --weights-file w.txt --out frames/frame_####.obj
///
/// Targets are one mesh with moved vertices. Weights are convex: each at least 0, all
/// summing to one. A weights file holds one blend per line; its shapes are written as an OBJ
/// sequence or a vertex cache (.pc2, .mdd, .glb, .usda), one frame per line. Nothing is
/// written on error.
#[derive(clap::Args)]
#[command(verbatim_doc_comment)]
pub(crate) struct Args {
    /// The target meshes (OBJ), at least two; the first is the rest of the spring network.
    #[arg(long, num_args = 2.., required = true)]
    targets: Vec<PathBuf>,
    /// One weight per target, comma separated.
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true, required_unless_present = "weights_file", conflicts_with = "weights_file")]
    weights: Option<Vec<f64>>,
    /// A text file with one blend per line (weights separated by commas or spaces, # comments).
    #[arg(long)]
    weights_file: Option<PathBuf>,
    /// The output: shape.obj for --weights; frames/frame_####.obj or a cache for --weights-file.
    #[arg(short = 'o', long, alias = "output", value_name = "PATH")]
    out: PathBuf,
    /// Frame rate of a cache output.
    #[arg(long, default_value_t = 24.0)]
    fps: f64,
    /// Vertices that follow the linear blend (a file of 0-based indices, or a .dmat mask)
    /// instead of the default anchor at the centre of mass.
    #[arg(long)]
    fixed: Option<PathBuf>,
    /// A TOML file of [[obstacle]] tables (kind = "plane" or "sphere") the shapes collide with.
    #[arg(long)]
    obstacles: Option<PathBuf>,
    /// Surface springs only: no TetGen body (for open surfaces).
    #[arg(long)]
    no_body: bool,
    /// Split surface edges longer than this multiple of the median edge before building the
    /// springs (the output then has the refined mesh's extra vertices).
    #[arg(long)]
    refine: Option<f64>,
    /// Write the linear blend of the positions instead (the baseline, for comparison).
    #[arg(long)]
    linear: bool,
    #[command(flatten)]
    budget: super::BudgetArgs,
}

impl Args {
    /// The weights file, or the first target (the spring network's rest).
    pub(crate) fn input(&self) -> &std::path::Path {
        self.weights_file.as_deref().unwrap_or(&self.targets[0])
    }
}

pub(crate) fn run(args: Args, progress: &Progress, quiet: bool) -> Result<Summary> {
    let budget = args.budget.budget();
    let job = BlendJob {
        targets: args.targets,
        weights: match (args.weights, args.weights_file) {
            (Some(w), _) => Weights::One(w),
            (None, Some(f)) => Weights::File(f),
            (None, None) => unreachable!("clap requires --weights or --weights-file"),
        },
        out: args.out,
        fps: args.fps,
        fixed: args.fixed,
        obstacles: args.obstacles,
        body: !args.no_body,
        refine: args.refine,
        linear: args.linear,
    };
    let s = stages::blend(&job, &budget, progress)?;
    if !quiet {
        eprintln!(
            "blendsim: {} blend(s) of {} springs on {} vertices in {:.2} s ({:.2} s building, {} Newton iterations); wrote {}",
            s.blends,
            s.springs,
            s.vertices,
            s.build_seconds + s.blend_seconds,
            s.build_seconds,
            s.iterations,
            job.out.display()
        );
    }
    Ok(Summary::wrote([job.out]))
}
