//! `gast`: GAST Studio, the desktop studio and its command line. With no
//! arguments it opens the studio on the demo scene and style.
//!
//! Every subcommand drives the same `gast-core` code the studio uses; long work
//! shows progress bars, and errors carry the file and what was expected.

mod cli;
mod progress;
mod report;
mod studio;
mod study;
mod turntable;

use clap::Parser;

fn main() -> std::process::ExitCode {
    let args = cli::Cli::parse();
    match cli::run(args) {
        Ok(code) => code,
        Err(err) => {
            eprintln!("error: {}", error_text(&err));
            std::process::ExitCode::FAILURE
        }
    }
}

/// An error and its causes on one line, each cause once: the core's errors
/// already quote their source in their own message.
pub fn error_text(err: &anyhow::Error) -> String {
    let mut out = String::new();
    for cause in err.chain() {
        let text = cause.to_string();
        if !out.contains(&text) {
            if !out.is_empty() {
                out.push_str(": ");
            }
            out.push_str(&text);
        }
    }
    out
}
