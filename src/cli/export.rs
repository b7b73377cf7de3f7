//! `bitrock export DIR`: the run store's contents as CSV (particles) or JSON (the whole run),
//! for users who would rather not open run.sqlite themselves.

use bitrock::Error;
use bitrock::abc::Population;
use bitrock::documents;
use clap::{Args, ValueEnum};
use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

/// Format of `bitrock export`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum ExportFormat {
    /// Particles: population, law, candidate, rho, weight, then every law's parameters.
    Csv,
    /// Configuration, data summary, fits, prior, and every population with its particles.
    Json,
}

#[derive(Debug, Args)]
pub struct ExportCmd {
    /// Run directory (written by `bitrock abc --out`).
    pub dir: PathBuf,
    #[arg(long, value_enum, default_value_t = ExportFormat::Csv)]
    pub format: ExportFormat,
    /// Only this population [default: all].
    #[arg(long, value_name = "G")]
    pub population: Option<usize>,
    /// Write to FILE instead of stdout.
    #[arg(long, short, value_name = "FILE")]
    pub out: Option<PathBuf>,
    /// Replace FILE even when bitrock did not write it (or it was changed since); without it
    /// only bitrock's own unchanged output is replaced.
    #[arg(long, requires = "out")]
    pub force: bool,
}

pub fn run(cmd: &ExportCmd) -> anyhow::Result<ExitCode> {
    if let Some(path) = &cmd.out {
        bitrock::run::dir::check_output_file(path, "out", cmd.force)?;
    }
    bitrock::run::dir::refuse_unfinished_evidence(&cmd.dir)?;
    let store = bitrock::run::abc::Store::open(&cmd.dir)?;
    let stored = store.load()?;
    let setup = &stored.setup;
    let populations: Vec<&Population> = match cmd.population {
        None => stored.populations.iter().collect(),
        Some(g) => vec![stored.populations.get(g).ok_or_else(|| {
            Error::setting(
                "population",
                if stored.populations.is_empty() {
                    "the run has no completed population".to_string()
                } else {
                    format!("the run has populations 0..={}", stored.populations.len() - 1)
                },
            )
        })?],
    };
    let text = match cmd.format {
        ExportFormat::Csv => {
            let laws: Vec<bitrock::Law> = setup.prior.laws().collect();
            documents::particles_csv(&populations, &laws, setup.data.torque_unit)
        }
        ExportFormat::Json => {
            let mut text = serde_json::to_vec_pretty(&documents::export_json(
                &setup.config,
                &setup.data,
                &setup.fits,
                &setup.prior,
                &populations,
            ))?;
            text.push(b'\n');
            text
        }
    };
    match &cmd.out {
        None => super::print::stdout().write_all(&text)?,
        Some(path) => bitrock::run::dir::write_whole(path, "out", cmd.force, |file| file.write_all(&text))?,
    }
    Ok(ExitCode::SUCCESS)
}
