//! The `bitrock` binary: parses the command line, dispatches to the command's module under
//! `cli/`, and maps errors to exit statuses ([`cli::exit`]): bad input exits 2 with a message
//! naming the file, line, column or flag; failures that stopped the work exit 3; a closed pipe
//! on stdout ends quietly with 141.

// Everything for people goes through `cli::print` (stdout with its errors named, stderr that
// never panics); the print macros panic when a stream fails.
#![deny(clippy::print_stdout, clippy::print_stderr)]

mod cli;

use bitrock::Error;
use clap::Parser;
use cli::{Cli, Command, exit};
use std::io::ErrorKind;
use std::process::ExitCode;

fn main() -> ExitCode {
    quiet_device_select();
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => return parse_error(&e),
    };
    let result = match cli.register_law_files() {
        Err(e) => Err(e),
        Ok(()) => run(cli.command),
    };
    match result {
        Ok(code) => code,
        Err(err) if is_closed_pipe(&err) => ExitCode::from(exit::CLOSED_PIPE),
        Err(err) => {
            // A file's error speaks of its keys (a well file's `params`), not of the flags
            // that share their names.
            let in_a_file = err
                .chain()
                .any(|e| matches!(e.downcast_ref::<Error>(), Some(Error::Syntax { .. })));
            if in_a_file {
                cli::print::note_verbatim(format_args!("error: {}", message(&err)));
            } else {
                cli::print::note(format_args!("error: {}", message(&err)));
            }
            let bad_input = err
                .chain()
                .any(|e| e.downcast_ref::<Error>().is_some_and(Error::is_bad_input));
            ExitCode::from(if bad_input { exit::BAD_INPUT } else { exit::FAILURE })
        }
    }
}

/// Switches off Mesa's device-select Vulkan layer unless the user set `NODEVICE_SELECT`: it only
/// orders the Vulkan devices (bitrock ranks the adapters itself), and where no desktop session
/// runs it prints "XDG_RUNTIME_DIR is invalid or not set" twice on every command that may use a
/// GPU.
fn quiet_device_select() {
    if std::env::var_os("NODEVICE_SELECT").is_none() {
        // SAFETY: the first thing `main` does, before any other thread exists to read the
        // environment at the same time.
        unsafe { std::env::set_var("NODEVICE_SELECT", "1") };
    }
}

/// Ends on what clap says instead of a command: help or version text on standard output
/// (exit 0, or 141 / 3 with the cause named when it cannot be written: `--help > /dev/full`),
/// or a usage error on standard error (exit 2).
fn parse_error(e: &clap::Error) -> ExitCode {
    use std::io::Write;
    let printed = e.print().and_then(|()| std::io::stdout().flush());
    match printed {
        Err(io) if !e.use_stderr() => {
            if io.kind() == ErrorKind::BrokenPipe {
                return ExitCode::from(exit::CLOSED_PIPE);
            }
            cli::print::note(format_args!("error: standard output: cannot write: {io}"));
            ExitCode::from(exit::FAILURE)
        }
        _ => ExitCode::from(u8::try_from(e.exit_code()).unwrap_or(exit::BAD_INPUT)),
    }
}

/// Runs one command.
fn run(command: Command) -> anyhow::Result<ExitCode> {
    match command {
        Command::Fit(cmd) => cli::fit::run(&cmd),
        Command::Abc(cmd) => cli::abc::run(&cmd),
        Command::Evidence(cmd) => cli::evidence::run(&cmd),
        Command::Export(cmd) => cli::export::run(&cmd),
        Command::Report(cmd) => cli::report::run(&cmd),
        Command::Simulate(cmd) => cli::simulate::run(&cmd),
        Command::Surface(cmd) => cli::surface::run(&cmd),
        Command::Coupled(cmd) => cli::coupled::run(&cmd),
        Command::Demo(cmd) => cli::demo::run(&cmd),
        Command::Parity(cmd) => cli::parity::run(&cmd),
        Command::Bench(cmd) => cli::bench::run(&cmd),
        Command::CheckSelection(cmd) => cli::check::run(&cmd),
        Command::Fe(cmd) => cli::fe::run(&cmd),
        Command::Stability(cmd) => cli::stability::run(&cmd),
        Command::Devices(cmd) => cli::devices::run(&cmd),
        Command::Law(cmd) => cli::law::run(&cmd),
        Command::Watch(cmd) => cli::watch::run(&cmd),
        Command::Serve(cmd) => cli::serve::run(&cmd),
    }
}

/// The error and its causes joined by ": ", each once: a cause whose text the message already
/// holds (an OS error that a library error quotes) is not repeated.
fn message(err: &anyhow::Error) -> String {
    let mut text = String::new();
    for cause in err.chain() {
        let line = cause.to_string();
        if text.contains(&line) {
            continue;
        }
        if !text.is_empty() {
            text.push_str(": ");
        }
        text.push_str(&line);
    }
    text
}

/// True when a write failed because the reader of the pipe went away.
fn is_closed_pipe(err: &anyhow::Error) -> bool {
    err.chain().any(is_broken_pipe)
}

/// A broken pipe in `e` itself or in the I/O error it wraps: serde_json and csv keep their
/// I/O error out of the source chain, and `io::Error::other(csv_error)` hides it further.
fn is_broken_pipe(e: &(dyn std::error::Error + 'static)) -> bool {
    if let Some(io) = e.downcast_ref::<std::io::Error>() {
        io.kind() == ErrorKind::BrokenPipe || io.get_ref().is_some_and(|inner| is_broken_pipe(inner))
    } else if let Some(json) = e.downcast_ref::<serde_json::Error>() {
        json.io_error_kind() == Some(ErrorKind::BrokenPipe)
    } else if let Some(csv) = e.downcast_ref::<csv::Error>() {
        matches!(csv.kind(), csv::ErrorKind::Io(io) if io.kind() == ErrorKind::BrokenPipe)
    } else {
        false
    }
}
