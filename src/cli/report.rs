//! `bitrock report`: the paper's figures and report.md from run directories.

use clap::Args;
use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Debug, Args)]
pub struct ReportCmd {
    /// Run directories (written by `bitrock abc --out`), all calibrated on the same record.
    #[arg(required = true, value_name = "DIR")]
    pub runs: Vec<PathBuf>,
    /// Report directory: report.md and figures/, replaced as a whole (a directory holding
    /// anything else is refused).
    #[arg(long, value_name = "DIR", default_value = "bitrock-report")]
    pub out: PathBuf,
}

pub fn run(cmd: &ReportCmd) -> anyhow::Result<ExitCode> {
    let (setup, runs) = bitrock::report::read_run_dirs(&cmd.runs)?;
    let summary = bitrock::report::write_paper_report(&cmd.out, &setup, &runs, None)?;
    writeln!(
        super::print::stdout(),
        "report written to {} ({} figures, SVG and PNG)",
        summary.dir.join("report.md").display(),
        summary.figures.len()
    )?;
    Ok(ExitCode::SUCCESS)
}
