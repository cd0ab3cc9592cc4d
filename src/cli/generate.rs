use std::path::{Path, PathBuf};

use blendsim::support::output::write_atomic;
use blendsim::{Error, Result};
use clap_complete::{Generator, Shell};

use super::Summary;

/// Write shell completions or man pages, generated from the command-line definitions (so they
/// never drift from `--help`). `make completions` runs it; `make install` installs them.
///
///   blendsim generate completions bash -o build/share/bash-completion/completions
///   blendsim generate man -o build/share/man/man1
#[derive(clap::Args)]
#[command(verbatim_doc_comment)]
pub(crate) struct Args {
    #[command(subcommand)]
    what: What,
    /// Output folder (created if missing).
    #[arg(short = 'o', long, alias = "output", value_name = "DIR", global = true, default_value = ".")]
    out: PathBuf,
}

#[derive(clap::Subcommand)]
enum What {
    /// Completions for a shell, in the file name that shell looks for (blendsim.bash, _blendsim,
    /// blendsim.fish, blendsim.elv, _blendsim.ps1).
    Completions {
        /// The shell.
        shell: Shell,
    },
    /// One man page per command: blendsim.1, blendsim-bake.1, ...
    Man,
}

impl Args {
    pub(crate) fn input(&self) -> &Path {
        &self.out
    }
}

pub(crate) fn run(args: Args, mut cli: clap::Command) -> Result<Summary> {
    let mut written = Vec::new();
    let mut write = |name: String, bytes: Vec<u8>| -> Result<()> {
        std::fs::create_dir_all(&args.out).map_err(|e| Error::io(&args.out, &e, "create the output folder"))?;
        let path = args.out.join(name);
        write_atomic(&path, &bytes)?;
        written.push(path);
        Ok(())
    };
    match args.what {
        What::Completions { shell } => {
            let mut bytes = Vec::new();
            clap_complete::generate(shell, &mut cli, "blendsim", &mut bytes);
            write(shell.file_name("blendsim"), bytes)?;
        }
        What::Man => {
            cli.build();
            // The hidden `generate` itself gets no page.
            let pages = std::iter::once((String::from("blendsim"), cli.clone()))
                .chain(cli.get_subcommands().filter(|c| !c.is_hide_set()).map(|c| (format!("blendsim-{}", c.get_name()), c.clone())));
            for (name, command) in pages {
                let mut bytes = Vec::new();
                clap_mangen::Man::new(command.name(name.clone()))
                    .render(&mut bytes)
                    .map_err(|e| Error::general(format!("could not render the man page {name}.1: {e}"), "report this as a bug"))?;
                write(format!("{name}.1"), bytes)?;
            }
        }
    }
    Ok(Summary::wrote(written))
}
