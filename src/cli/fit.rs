//! `bitrock fit`: least squares per law on a record, printed as tables or JSON.

use super::args::{DataArgs, FitArgs, load_data};
use super::print;
use bitrock::Law;
use bitrock::data::FieldData;
use bitrock::fit::{self, FitOptions, LawFit};
use clap::Args;
use std::process::ExitCode;

#[derive(Debug, Args)]
pub struct FitCmd {
    #[command(flatten)]
    pub data_args: DataArgs,
    #[command(flatten)]
    pub fit: FitArgs,
    /// Print JSON instead of tables.
    #[arg(long)]
    pub json: bool,
}

pub fn run(cmd: &FitCmd) -> anyhow::Result<ExitCode> {
    let opts = cmd.fit.options()?;
    let data = load_data(&cmd.data_args)?;
    fit_and_print(&data, &cmd.fit.laws()?, &opts, cmd.json)?;
    Ok(ExitCode::SUCCESS)
}

/// Fits `laws` to `data` and prints them (also the start of `bitrock demo`).
pub fn fit_and_print(data: &FieldData, laws: &[Law], opts: &FitOptions, json: bool) -> anyhow::Result<Vec<LawFit>> {
    let fits = fit::fit_record(laws, data, opts)?;
    let separations = bitrock::separation::separations(&fits, &data.calibration, opts)?;
    let mut out = super::print::stdout();
    if json {
        let mut document = bitrock::documents::fit_json(data, &fits);
        document["separations"] = serde_json::to_value(&separations)?;
        super::print::json(&mut out, document)?;
    } else {
        print::fit_tables(&mut out, data, &fits)?;
        print::separation_tables(&mut out, &separations, laws)?;
    }
    Ok(fits)
}
