use std::collections::BTreeMap;
use std::path::PathBuf;

use blendsim::support::output::{LockWait, Staging, MANIFEST};
use blendsim::{Error, Result};

use super::Summary;

/// Commit a bake made elsewhere: the files of FROM (a bake's output folder, with its
/// manifest) replace --out as `bake` replaces it, staged beside it, locked and swapped in one
/// step (formats/stages.md). The cluster driver (cluster/) commits the folders its workers
/// send back this way; FROM is left as it was.
#[derive(clap::Args)]
pub(crate) struct Args {
    /// A bake's output folder (holding .blendsim-manifest.json).
    from: PathBuf,
    /// Output folder (created if missing).
    #[arg(short = 'o', long, alias = "output", value_name = "DIR")]
    out: PathBuf,
    /// Fail at once if another blendsim is writing into --out (by default: wait for it).
    #[arg(long)]
    no_wait: bool,
}

impl Args {
    pub(crate) fn input(&self) -> &std::path::Path {
        &self.from
    }
}

#[derive(serde::Deserialize)]
struct Manifest {
    files: BTreeMap<String, String>,
}

pub(crate) fn run(args: Args, quiet: bool) -> Result<Summary> {
    let manifest_path = args.from.join(MANIFEST);
    let text = std::fs::read_to_string(&manifest_path).map_err(|e| Error::io(&manifest_path, &e, "read the bake's manifest"))?;
    let manifest: Manifest = serde_json::from_str(&text)
        .map_err(|e| Error::in_file(&manifest_path, format!("is not a blendsim manifest ({e})"), "give the output folder of a finished bake"))?;
    let mut staging = Staging::open(&args.out, if args.no_wait { LockWait::Fail } else { LockWait::Wait })?;
    staging.replace_every_group();
    let names: Vec<&String> = manifest.files.keys().collect();
    staging.claim(&names)?;
    for (name, group) in &manifest.files {
        let source = args.from.join(name);
        let mut file = std::fs::File::open(&source).map_err(|e| Error::io(&source, &e, "read a file of the bake"))?;
        staging.set_group(group);
        staging.write_with(name, |w| std::io::copy(&mut file, w).map(drop))?;
    }
    let committed = staging.commit_with_summary()?;
    if !quiet {
        for line in committed.messages(&args.out, "bake") {
            eprintln!("blendsim: {line}");
        }
    }
    Ok(Summary::folder(&args.out, &committed))
}
