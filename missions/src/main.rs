//! `cps-survey`: parse, run, print the error chain, exit 0 / 1 / 2.
#![allow(clippy::print_stderr)]

use std::io::Write;
use std::process::ExitCode;

use clap::Parser;
use missions::cli::{Cli, exit_code, run};

fn main() -> ExitCode {
    let cli = Cli::parse();
    let mut stdout = std::io::stdout().lock();
    let result = run(cli, &mut stdout).and_then(|outcome| Ok(stdout.flush().map(|()| outcome)?));
    if let Err(e) = &result {
        // The reader of our output went away (`… | head`): nothing to report.
        let broken_pipe = e
            .chain()
            .any(|c| c.downcast_ref::<std::io::Error>().is_some_and(|io| io.kind() == std::io::ErrorKind::BrokenPipe));
        if broken_pipe {
            return ExitCode::SUCCESS;
        }
        eprintln!("error: {e}");
        for cause in e.chain().skip(1) {
            eprintln!("  caused by: {cause}");
        }
    }
    ExitCode::from(exit_code(&result))
}
