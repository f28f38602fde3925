//! `gast`: GAST Studio's command line.
//!
//! Every subcommand drives the same `gast-core` code the studio uses; long work
//! shows progress bars, and errors carry the file and what was expected.

mod cli;
mod progress;

use clap::Parser;

fn main() -> std::process::ExitCode {
    let args = cli::Cli::parse();
    match cli::run(args) {
        Ok(code) => code,
        Err(err) => {
            eprintln!("error: {err:#}");
            std::process::ExitCode::FAILURE
        }
    }
}
