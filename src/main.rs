//! The `bitrock` binary: parses the command line, dispatches to the command's module under
//! `cli/`, and maps errors to exit statuses. Bad input exits with status 2 and a message naming
//! the file, line, column or flag; other failures exit 1.

mod cli;

use bitrock::Error;
use clap::Parser;
use cli::{Cli, Command};
use std::process::ExitCode;

fn main() -> ExitCode {
    let result = match Cli::parse().command {
        Command::Fit(cmd) => cli::fit::run(&cmd),
        Command::Abc(cmd) => cli::abc::run(&cmd),
        Command::Export(cmd) => cli::export::run(&cmd),
        Command::Report(cmd) => cli::report::run(&cmd),
        Command::Simulate(cmd) => cli::simulate::run(&cmd),
        Command::Demo(cmd) => cli::demo::run(&cmd),
        Command::Parity(cmd) => cli::parity::run(&cmd),
        Command::Bench(cmd) => cli::bench::run(&cmd),
        Command::Fe(cmd) => cli::fe::run(&cmd),
        Command::Stability(cmd) => cli::stability::run(&cmd),
    };
    match result {
        Ok(code) => code,
        Err(err) => {
            eprintln!("error: {err:#}");
            let bad_input = err
                .chain()
                .any(|e| e.downcast_ref::<Error>().is_some_and(Error::is_bad_input));
            ExitCode::from(if bad_input { 2 } else { 1 })
        }
    }
}
