//! `bitrock report`: the paper's figures and report.md from run directories; a watch's or an
//! evidence's report from its directory.

use super::args::{FeArgs, LumpedArgs};
use bitrock::report::StabilitySettings;
use bitrock::watch::store::is_watch_dir;
use clap::Args;
use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Debug, Args)]
pub struct ReportCmd {
    /// Run directories (written by `bitrock abc --out`), all calibrated on the same record; or
    /// one watch directory (written by `bitrock watch --out`): the law probabilities,
    /// parameters and risk of stick-slip along its record, changes marked; or one evidence
    /// directory (written by `bitrock evidence --out`): each law's evidence, its posterior
    /// predictive envelope over the samples, the Bayes factors; or one surface directory
    /// (written by `bitrock surface --out`): the laws with their check, the string, and the
    /// bit's speed the surface implies.
    #[arg(required = true, value_name = "DIR")]
    pub runs: Vec<PathBuf>,
    /// Report directory: report.md and figures/, replaced as a whole (a directory holding
    /// anything else is refused).
    #[arg(long, value_name = "DIR", default_value = "bitrock-report")]
    pub out: PathBuf,
    /// Also map stick-slip by simulating the 1-DOF string in time for the reference run's
    /// posterior samples: where it develops from steady rotation, where it persists from the
    /// record's operating point, the bistable band between them (a table and a figure).
    #[arg(long)]
    pub simulate: bool,
    /// Where the strings of the record's advice and of --simulate's maps are integrated: gpu,
    /// cpu, or auto (the GPU when an adapter exists, else the CPU, saying so).
    #[arg(long, value_enum, default_value_t = bitrock::eval::Backend::Auto)]
    pub backend: bitrock::eval::Backend,
    /// The 1-DOF string of the runs' maps and advice [default: the paper's 5 km field string].
    #[command(flatten)]
    pub lumped: LumpedArgs,
    /// A finite-element string compared with the 1-DOF one, instead of the paper's three.
    #[command(flatten)]
    pub fe: FeArgs,
}

/// The maps the flags describe: the string they give, laid over the first run's own (else the
/// paper's); a finite-element string given or kept is compared instead of the paper's three.
fn stability(cmd: &ReportCmd) -> anyhow::Result<StabilitySettings> {
    let stored = bitrock::run::stability::stored_string(&cmd.runs[0])?;
    if let Some(string) = &stored {
        super::print::note(format_args!("note: the run's own drill string: {}", string.describe()));
    }
    // The report maps on the 1-DOF string and compares a finite-element one: no structure.
    let (_, lumped, fe) = cmd.lumped.given(None, &cmd.fe).over(stored.as_ref());
    let paper = StabilitySettings::default();
    let own_fe = fe.first_given().is_some() || fe.base.is_some();
    Ok(StabilitySettings {
        lumped,
        strings: if own_fe {
            vec![fe.drill_string()?]
        } else {
            paper.strings.clone()
        },
        simulated: cmd.simulate.then(Default::default),
        backend: cmd.backend,
        ..paper
    })
}

pub fn run(cmd: &ReportCmd) -> anyhow::Result<ExitCode> {
    // A watch or an evidence is reported alone.
    let alone: Vec<(&PathBuf, &str)> = cmd
        .runs
        .iter()
        .filter_map(|d| {
            if is_watch_dir(d) {
                Some((d, "a watch"))
            } else if bitrock::run::dir::is_evidence_dir(d) {
                Some((d, "an evidence"))
            } else if bitrock::run::surface::dir::is_surface_dir(d) {
                Some((d, "a surface run"))
            } else {
                None
            }
        })
        .collect();
    let summary = match (alone.as_slice(), cmd.runs.len()) {
        ([(dir, "a watch")], 1) => bitrock::watch::report::write(&cmd.out, &bitrock::watch::store::read(dir)?)?,
        ([(dir, "a surface run")], 1) => bitrock::report::write_surface_report(&cmd.out, dir)?,
        ([(dir, _)], 1) => bitrock::report::write_evidence_report(&cmd.out, dir)?,
        ([], _) => {
            let (setup, runs) = bitrock::report::read_run_dirs(&cmd.runs)?;
            bitrock::report::write_paper_report(&cmd.out, &setup, &runs, None, stability(cmd)?)?
        }
        ([(dir, what), ..], _) => {
            return Err(bitrock::Error::setting(
                "runs",
                format!(
                    "{} is {what} directory: {what} is reported alone, not with other directories",
                    dir.display()
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
