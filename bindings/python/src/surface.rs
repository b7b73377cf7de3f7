//! Laws from a surface record (top-drive speed and surface torque) through simulated strings.

use crate::errors::*;
use bitrock::Law;
use bitrock::data::surface::{SurfaceOptions, SurfaceRecord};
use bitrock::prior::PriorFile;
use bitrock::run::surface::{SurfaceSettings, infer};
use bitrock::simulate::surface::Integration;
use bitrock::units::{ForceUnit, SpeedUnit, TorqueUnit};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::PathBuf;

/// `bitrock surface` on the record at `path`: the whole result as JSON text. The notes of the
/// run (a GPU fallback of the advice's strings, say) go to `note` once it is done.
#[pyfunction]
#[pyo3(signature = (path, laws, options, note))]
pub(crate) fn surface(
    py: Python<'_>,
    path: PathBuf,
    laws: Option<Vec<String>>,
    options: &Bound<'_, PyDict>,
    note: Option<Py<PyAny>>,
) -> PyResult<String> {
    let laws = crate::errors::laws(py, laws)?.unwrap_or_else(|| {
        Law::ALL
            .into_iter()
            .chain(bitrock::laws::file::registered_laws())
            .collect()
    });
    let mut s = SurfaceSettings::new(laws);
    if let Some(file) = kwarg::<PathBuf>(options, "prior_file")? {
        s.prior_file = Some(check(py, PriorFile::read(&file))?);
    }
    s.prior_scale = kwarg(options, "prior_scale")?.unwrap_or(s.prior_scale);
    s.structure.inertia_kg_m2 = kwarg(options, "inertia_kg_m2")?.unwrap_or(s.structure.inertia_kg_m2);
    s.structure.omega_n_rad_s = kwarg(options, "omega_n_rad_s")?.unwrap_or(s.structure.omega_n_rad_s);
    s.structure.damping_ratio = kwarg(options, "damping_ratio")?.unwrap_or(s.structure.damping_ratio);
    s.w_ref_n = kwarg::<f64>(options, "w_ref_kn")?.map(|w| w * 1000.0);
    s.noise_sd_nm = kwarg::<f64>(options, "noise_sd_knm")?.map(|n| n * 1000.0);
    s.pilot = kwarg(options, "pilot")?.unwrap_or(s.pilot);
    s.check_replicates = kwarg(options, "check_replicates")?.unwrap_or(s.check_replicates);
    s.predictive_draws = kwarg(options, "predictive_draws")?.unwrap_or(s.predictive_draws);
    s.advice = kwarg(options, "advice")?.unwrap_or(s.advice);
    s.integration = Integration {
        dt_s: kwarg(options, "dt_s")?.unwrap_or(s.integration.dt_s),
        settle_s: kwarg(options, "settle_s")?.unwrap_or(s.integration.settle_s),
    };
    let schedule = &mut s.smc.schedule;
    schedule.particles = kwarg(options, "particles")?.unwrap_or(schedule.particles);
    schedule.max_populations = kwarg(options, "max_populations")?.unwrap_or(schedule.max_populations);
    schedule.max_seconds = kwarg(options, "max_seconds")?;
    let seed = kwarg(options, "seed")?.unwrap_or(1u64);
    let columns = SurfaceOptions {
        time_column: kwarg(options, "time_col")?,
        top_drive_column: kwarg(options, "top_drive_col")?,
        surface_torque_column: kwarg(options, "surface_torque_col")?,
        wob_column: kwarg(options, "wob_col")?,
        top_drive_unit: unit(
            py,
            "top_drive_unit",
            kwarg(options, "top_drive_unit")?,
            SpeedUnit::from_suffix,
        )?,
        torque_unit: unit(
            py,
            "torque_unit",
            kwarg(options, "torque_unit")?,
            TorqueUnit::from_suffix,
        )?,
        wob_unit: unit(py, "wob_unit", kwarg(options, "wob_unit")?, ForceUnit::from_suffix)?,
    };
    let mut notes = Vec::new();
    let text = py.detach(|| {
        s.validate()?;
        let record = SurfaceRecord::read(&path, &columns)?;
        let result = infer(&record, &s, seed, &mut |line| notes.push(line))?;
        let mut document = serde_json::to_value(&result).expect("a result serialises");
        document["time_s"] = serde_json::to_value(&record.time_s).expect("numbers serialise");
        Ok::<_, bitrock::Error>(document.to_string())
    });
    if let Some(callback) = &note {
        for line in &notes {
            callback.call1(py, (as_arguments(line),))?;
        }
    }
    check(py, text)
}
