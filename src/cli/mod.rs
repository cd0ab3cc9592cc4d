//! Command-line definitions: one file per subcommand, nothing else.
//!
//! Exit codes: 0 success; 1 bad input or a failed stage (the message names the file, the
//! problem and the fix); 2 usage errors (from clap); 3 `--strict` refused the result because
//! of warnings (one `error: CODE: ...` line each; nothing written, the previous output kept). SIGINT, SIGTERM and SIGHUP remove the
//! unfinished outputs and end the process by the same signal (see `blendsim::support::interrupt`).

mod bake;
mod blend;
mod commit;
mod embed;
mod export;
mod generate;
mod import;
mod inputs;
mod report;
mod solve;
mod tetrahedralize;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use blendsim::pipeline::scene::Method;
use blendsim::support::budget::Budget;
use blendsim::support::progress::Progress;
use clap::{CommandFactory, Parser, Subcommand};

/// Turn keyframe meshes into compact, physically plausible blendshape animation for USD and
/// glTF (BlendSim: spacetime projective dynamics on cubic Hermite trajectories), and report how
/// much smaller and how faithful it is than the full-frame version.
///
/// The stages chain through files, so a Makefile can cache them:
///
///   blendsim import SCENE.toml -o keys.json
///   blendsim tetrahedralize keys.json -o body.json
///   blendsim solve body.json -o solution.json
///   blendsim embed solution.json -o animation.json
///   blendsim export animation.json -o DIR
///   blendsim report animation.json --outputs DIR/NAME.outputs.json -o DIR
///
/// `blendsim bake SCENE.toml -o DIR` runs them all in one process; `blendsim blend`
/// blends target meshes with mass-spring blendshapes. Every subcommand takes its output as
/// `-o/--out` (a file for the stage files, a folder otherwise), `--max-memory`, `--max-time`
/// and `--json`.
///
/// Exit codes: 0 success (warnings, if any, on stderr and in the report); 1 bad input or a
/// failed stage; 2 usage errors; 3 --strict refused a result that has warnings (nothing
/// written, the previous output kept; see formats/report.md, "Warnings").
#[derive(Parser)]
#[command(name = "blendsim", version, about, long_about, verbatim_doc_comment, propagate_version = true)]
struct Cli {
    /// No progress output on stderr.
    #[arg(long, short, global = true)]
    quiet: bool,
    /// Print one line of JSON on stdout when done: the command, its status (ok, error,
    /// refused), exit code, files written, size ratios, warnings, error message and seconds
    /// (docs/cli.md).
    #[arg(long, global = true)]
    json: bool,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    Import(import::Args),
    Tetrahedralize(tetrahedralize::Args),
    Solve(solve::Args),
    Embed(embed::Args),
    Export(export::Args),
    Report(report::Args),
    Bake(bake::Args),
    Blend(blend::Args),
    /// Write shell completions or the man pages (generated from these definitions).
    #[command(hide = true)]
    Generate(generate::Args),
    /// List the files each scene's bake reads, as JSON lines (for the cluster driver).
    #[command(hide = true)]
    Inputs(inputs::Args),
    /// Commit a bake's output folder made elsewhere into --out (for the cluster driver).
    #[command(hide = true)]
    Commit(commit::Args),
}

impl Command {
    /// The subcommand's name, as typed.
    fn name(&self) -> &'static str {
        match self {
            Command::Import(_) => "import",
            Command::Tetrahedralize(_) => "tetrahedralize",
            Command::Solve(_) => "solve",
            Command::Embed(_) => "embed",
            Command::Export(_) => "export",
            Command::Report(_) => "report",
            Command::Bake(_) => "bake",
            Command::Blend(_) => "blend",
            Command::Generate(_) => "generate",
            Command::Inputs(_) => "inputs",
            Command::Commit(_) => "commit",
        }
    }
}

/// What a subcommand did, for `--json`.
#[derive(Debug, Default, serde::Serialize)]
pub(crate) struct Summary {
    /// Every file written, as the user named its place (`-o` joined with the file's name).
    pub(crate) outputs: Vec<PathBuf>,
    /// Bytes of the full-frame file over bytes of the blendshape file, per format (bake and
    /// report only).
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub(crate) ratios: BTreeMap<String, f64>,
    /// The run's warnings (also on stderr and in the reports).
    pub(crate) warnings: Vec<String>,
}

impl Summary {
    /// A run that wrote `outputs` and had no warnings.
    pub(crate) fn wrote(outputs: impl IntoIterator<Item = PathBuf>) -> Summary {
        Summary { outputs: outputs.into_iter().collect(), ..Summary::default() }
    }

    /// The files of a committed output folder.
    pub(crate) fn folder(out: &Path, committed: &blendsim::support::output::Committed) -> Summary {
        Summary::wrote(committed.written.iter().map(|n| out.join(n)))
    }
}

/// The `--json` line: [`Summary`] plus how the run ended.
#[derive(serde::Serialize)]
struct JsonLine<'a> {
    command: &'a str,
    /// `ok` (exit 0), `error` (exit 1) or `refused` (exit 3: --strict and warnings).
    status: &'a str,
    exit: u8,
    #[serde(flatten)]
    summary: Summary,
    #[serde(skip_serializing_if = "Option::is_none")]
    error: Option<String>,
    seconds: f64,
}

/// `--method`, for `solve` and `bake`: overrides the scene's `[solver] method`.
#[derive(Clone, Copy, clap::ValueEnum)]
pub(crate) enum MethodArg {
    Hermite,
    Spacetime,
    MassSpring,
    Fit,
}

impl From<MethodArg> for Method {
    fn from(m: MethodArg) -> Method {
        match m {
            MethodArg::Hermite => Method::Hermite,
            MethodArg::Spacetime => Method::Spacetime,
            MethodArg::MassSpring => Method::MassSpring,
            MethodArg::Fit => Method::Fit,
        }
    }
}

/// `--max-memory` and `--max-time`, the same on every subcommand: the budget every stage
/// checks before it allocates or runs long (`blendsim::support::budget`).
#[derive(clap::Args)]
pub(crate) struct BudgetArgs {
    /// Memory the command may use (e.g. 4G, 512M): every large allocation (frames, solver
    /// samples, textures: their file and decoded size from the header) is estimated first and
    /// refused past it, and the solve's global step is solved
    /// iteratively instead of by a sparse factorization when its factor would not fit.
    /// Default: 60% of the available memory.
    #[arg(long, value_parser = parse_bytes)]
    max_memory: Option<u64>,
    /// Time the command may take, in seconds (e.g. 600, 90s, 10m, 2h), counted from its start:
    /// the keyframe import checks it before every key; TetGen and usd-core's cache reader get
    /// at most what is left of it (TetGen: or [tet] timeout, the smaller); the solve checks
    /// it before its global step is built (against the predicted cost) and at every iteration;
    /// a cache's key selection, fit and error measure at every frame they read; the mass-spring
    /// blend at every Newton iteration. Once it is spent the command stops with an error and
    /// writes nothing. At most 1e9 s. Default: no limit.
    #[arg(long, value_parser = parse_seconds)]
    max_time: Option<f64>,
}

impl BudgetArgs {
    /// The budget, its clock started now.
    pub(crate) fn budget(&self) -> Budget {
        Budget::new(self.max_memory, self.max_time)
    }
}

/// `--strict`: an error (exit code 3) when there are `warnings`.
pub(crate) fn refuse_warnings(warnings: &[String]) -> blendsim::Result<()> {
    if warnings.is_empty() {
        Ok(())
    } else {
        Err(blendsim::support::error::Error::refused(warnings))
    }
}

/// A byte count as `--max-memory` takes it: a number with an optional unit. `K`, `M`, `G`, `T`
/// and `KiB`..`TiB` are powers of 1024 (`4G`, `2GiB`); `KB`..`TB` are powers of 1000 (`512MB`);
/// no unit or `B` is bytes. More than 2^64 bytes is refused, not wrapped.
/// Kept rather than `bytesize`: it reads `4G` as 10^9 bytes, not 2^30, and not `1e3M`.
pub(crate) fn parse_bytes(text: &str) -> std::result::Result<u64, String> {
    let t = text.trim();
    // The unit is the trailing run of letters (`1e3M` is a number with an exponent, then `M`).
    let split = t.trim_end_matches(|c: char| c.is_ascii_alphabetic()).len();
    let (number, unit) = (t[..split].trim(), t[split..].to_ascii_uppercase());
    let scale: f64 = match unit.as_str() {
        "" | "B" => 1.0,
        "K" | "KIB" => 1024.0,
        "M" | "MIB" => 1024f64.powi(2),
        "G" | "GIB" => 1024f64.powi(3),
        "T" | "TIB" => 1024f64.powi(4),
        "KB" => 1e3,
        "MB" => 1e6,
        "GB" => 1e9,
        "TB" => 1e12,
        _ => {
            return Err(format!(
                "unknown unit {:?} in {text:?}: use K, M, G, T (powers of 1024, also KiB..TiB) or KB, MB, GB, TB (powers of 1000), e.g. 4G or 512MB",
                &t[split..]
            ))
        }
    };
    match number.parse::<f64>() {
        Ok(x) if x.is_finite() && x > 0.0 && x * scale < u64::MAX as f64 => Ok((x * scale).round().max(1.0) as u64),
        Ok(x) if x.is_finite() && x > 0.0 => Err(format!("{text:?} is more memory than a byte count holds (16 EiB): give e.g. 4G or 512MB")),
        _ => Err(format!("{text:?} is not a positive amount of memory: give e.g. 4G, 2GiB or 512MB")),
    }
}

/// The longest `--max-time`, in seconds (about 31.7 years): far beyond any bake, and small
/// enough that a deadline computed from it stays a valid `Duration` and `Instant`.
pub(crate) const MAX_SECONDS: f64 = 1e9;

/// `--max-time`: seconds, or a number with `s`, `m` or `h`.
/// Kept rather than `humantime`: it refuses a bare `600`, fractions (`0.05`) and exponents.
pub(crate) fn parse_seconds(text: &str) -> std::result::Result<f64, String> {
    let t = text.trim();
    let (number, scale) = match t.chars().last() {
        Some('s') => (&t[..t.len() - 1], 1.0),
        Some('m') => (&t[..t.len() - 1], 60.0),
        Some('h') => (&t[..t.len() - 1], 3600.0),
        _ => (t, 1.0),
    };
    match number.trim().parse::<f64>() {
        Ok(x) if x.is_finite() && x > 0.0 && x * scale <= MAX_SECONDS => Ok(x * scale),
        Ok(x) if x.is_finite() && x > 0.0 => {
            Err(format!("{text:?} is longer than the longest --max-time, 1e9 s (31 years): give seconds, e.g. 600, 90s, 10m or 2h"))
        }
        _ => Err(format!("{text:?} is not a positive duration: give seconds, e.g. 600, 90s, 10m or 2h")),
    }
}

pub(crate) fn main() -> ExitCode {
    // First, so that a signal at any later moment runs the cleanup.
    blendsim::support::interrupt::install();
    let start = Instant::now();
    let cli = Cli::parse();
    let progress = match Progress::from_env(cli.quiet) {
        Ok(p) => p,
        Err(message) => {
            eprintln!("error: {message}");
            return ExitCode::from(2);
        }
    };
    let command = cli.command.name();
    // An error that concerns no particular file is about the command's input.
    let input = match &cli.command {
        Command::Import(a) => a.input(),
        Command::Tetrahedralize(a) => a.input(),
        Command::Solve(a) => a.input(),
        Command::Embed(a) => a.input(),
        Command::Export(a) => a.input(),
        Command::Report(a) => a.input(),
        Command::Bake(a) => a.input(),
        Command::Blend(a) => a.input(),
        Command::Generate(a) => a.input(),
        Command::Inputs(a) => a.input(),
        Command::Commit(a) => a.input(),
    }
    .to_path_buf();
    let result = match cli.command {
        Command::Import(a) => import::run(a, &progress),
        Command::Tetrahedralize(a) => tetrahedralize::run(a, &progress),
        Command::Solve(a) => solve::run(a, &progress),
        Command::Embed(a) => embed::run(a, &progress),
        Command::Export(a) => export::run(a, &progress),
        Command::Report(a) => report::run(a, &progress),
        Command::Bake(a) => bake::run(a, &progress, cli.quiet),
        Command::Blend(a) => blend::run(a, &progress, cli.quiet),
        Command::Generate(a) => generate::run(a, Cli::command()),
        Command::Inputs(a) => inputs::run(a),
        Command::Commit(a) => commit::run(a, cli.quiet),
    };
    // Stopped by a signal: its cleanup ends the process, with the signal's status.
    blendsim::support::interrupt::settle();
    let (code, line) = match result.map_err(|e| e.with_path(input)) {
        Ok(summary) => (0, JsonLine { command, status: "ok", exit: 0, summary, error: None, seconds: 0.0 }),
        Err(e) if !e.refused.is_empty() => {
            for w in &e.refused {
                eprintln!("error: {}", one_line(w));
            }
            let summary = Summary { warnings: e.refused.clone(), ..Summary::default() };
            (3, JsonLine { command, status: "refused", exit: 3, summary, error: None, seconds: 0.0 })
        }
        Err(e) => {
            eprintln!("error: {e}");
            (1, JsonLine { command, status: "error", exit: 1, summary: Summary::default(), error: Some(e.to_string()), seconds: 0.0 })
        }
    };
    if cli.json {
        let line = JsonLine { seconds: start.elapsed().as_secs_f64(), ..line };
        println!("{}", serde_json::to_string(&line).expect("a summary serializes"));
    }
    ExitCode::from(code)
}

/// `line` with control characters (a newline inside a user's name) folded to spaces.
fn one_line(line: &str) -> String {
    line.chars().map(|c| if c.is_control() { ' ' } else { c }).collect()
}
