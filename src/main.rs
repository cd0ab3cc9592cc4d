//! `blendsim`: the command-line front end. Every subcommand is a thin layer over one library
//! stage; see `blendsim --help`.

mod cli;

use std::process::ExitCode;

fn main() -> ExitCode {
    cli::main()
}
