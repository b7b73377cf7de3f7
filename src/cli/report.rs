//! `bitrock report`: the paper's figures and report.md from run directories.

use bitrock::watch::store::is_watch_dir;
use clap::Args;
use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Debug, Args)]
pub struct ReportCmd {
    /// Run directories (written by `bitrock abc --out`), all calibrated on the same record; or
    /// one watch directory (written by `bitrock watch --out`): the law probabilities,
    /// parameters and risk of stick-slip along its record, changes marked.
    #[arg(required = true, value_name = "DIR")]
    pub runs: Vec<PathBuf>,
    /// Report directory: report.md and figures/, replaced as a whole (a directory holding
    /// anything else is refused).
    #[arg(long, value_name = "DIR", default_value = "bitrock-report")]
    pub out: PathBuf,
}

pub fn run(cmd: &ReportCmd) -> anyhow::Result<ExitCode> {
    let watches: Vec<&PathBuf> = cmd.runs.iter().filter(|d| is_watch_dir(d)).collect();
    let summary = match (watches.as_slice(), cmd.runs.len()) {
        ([dir], 1) => bitrock::watch::report::write(&cmd.out, &bitrock::watch::store::read(dir)?)?,
        ([], _) => {
            let (setup, runs) = bitrock::report::read_run_dirs(&cmd.runs)?;
            bitrock::report::write_paper_report(&cmd.out, &setup, &runs, None)?
        }
        _ => {
            return Err(bitrock::Error::setting(
                "runs",
                format!(
                    "{} is a watch directory: a watch is reported alone, not with other directories",
                    watches[0].display()
                ),
            )
            .into());
        }
    };
    writeln!(
        super::print::stdout(),
        "report written to {} ({} figures, SVG and PNG)",
        summary.dir.join("report.md").display(),
        summary.figures.len()
    )?;
    Ok(ExitCode::SUCCESS)
}
