//! `bitrock export DIR`: the run store's contents as CSV (particles) or JSON (the whole run),
//! for users who would rather not open run.sqlite themselves.

use crate::cli::{ExportCmd, ExportFormat};
use crate::output;
use bitrock::Error;
use bitrock::abc::Population;
use bitrock::store::RunStore;
use serde_json::json;
use std::io::Write;

pub fn export_cmd(cmd: &ExportCmd) -> anyhow::Result<()> {
    let store = RunStore::open(&cmd.dir)?;
    let stored = store.load()?;
    let setup = &stored.setup;
    let populations: Vec<&Population> = match cmd.population {
        None => stored.populations.iter().collect(),
        Some(g) => vec![stored.populations.get(g).ok_or_else(|| {
            Error::arg(
                "--population",
                if stored.populations.is_empty() {
                    "the run has no completed population".to_string()
                } else {
                    format!("the run has populations 0..={}", stored.populations.len() - 1)
                },
            )
        })?],
    };
    let unit = setup.data.torque_unit;
    let laws: Vec<bitrock::Law> = setup.prior.boxes.iter().map(|b| b.law).collect();
    let mut text = Vec::new();
    match cmd.format {
        ExportFormat::Csv => output::write_particles(&mut text, &populations, &laws, unit)?,
        ExportFormat::Json => {
            let fits = output::fit_json(&setup.data, &setup.fits);
            let value = json!({
                "version": env!("CARGO_PKG_VERSION"),
                "config": setup.config,
                "data": {
                    "source": fits["source"],
                    "columns": fits["columns"],
                    "torque_unit": unit.label(),
                    "rows_read": setup.data.rows_read,
                    "rows_used": setup.data.rows_used,
                    "calibration_rows": setup.data.calibration.len(),
                    "validation_rows": setup.data.validation.len(),
                },
                "fits": fits["fits"],
                "priors": output::prior_json(&setup.prior, unit),
                "populations": populations
                    .iter()
                    .map(|p| output::population_with_particles_json(p, unit))
                    .collect::<Vec<_>>(),
            });
            serde_json::to_writer_pretty(&mut text, &value)?;
            text.push(b'\n');
        }
    }
    match &cmd.out {
        None => std::io::stdout().lock().write_all(&text)?,
        Some(path) => output::write_file_atomically(path, |file| Ok(file.write_all(&text)?))?,
    }
    Ok(())
}
