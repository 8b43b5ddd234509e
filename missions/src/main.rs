//! `cps-survey`: parse, run, print the error chain, exit 0 / 1 / 2.
#![allow(clippy::print_stderr)]

use std::process::ExitCode;

use clap::Parser;
use missions::cli::{Cli, Outcome, run};

fn main() -> ExitCode {
    let cli = Cli::parse();
    match run(cli) {
        Ok(Outcome::Success) => ExitCode::SUCCESS,
        Ok(Outcome::AcceptanceFailed) => ExitCode::from(1),
        Err(e) => {
            eprintln!("error: {e}");
            for cause in e.chain().skip(1) {
                eprintln!("  caused by: {cause}");
            }
            ExitCode::from(2)
        }
    }
}
