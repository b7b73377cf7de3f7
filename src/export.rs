//! `bitrock export DIR`: the run store's contents as CSV (particles) or JSON (the whole run),
//! for users who would rather not open run.sqlite themselves.

use crate::cli::{ExportCmd, ExportFormat};
use crate::output;
use bitrock::Error;
use bitrock::abc::Population;
use bitrock::documents;
use bitrock::store::RunStore;
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
    let text = match cmd.format {
        ExportFormat::Csv => {
            let laws: Vec<bitrock::Law> = setup.prior.boxes.iter().map(|b| b.law).collect();
            documents::particles_csv(&populations, &laws, setup.data.torque_unit)
        }
        ExportFormat::Json => {
            let mut text = serde_json::to_vec_pretty(&documents::export_json(setup, &populations))?;
            text.push(b'\n');
            text
        }
    };
    match &cmd.out {
        None => std::io::stdout().lock().write_all(&text)?,
        Some(path) => output::write_file_atomically(path, |file| Ok(file.write_all(&text)?))?,
    }
    Ok(())
}
