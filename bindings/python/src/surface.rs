//! Laws from a surface record (top-drive speed and surface torque) through simulated strings.

use crate::errors::*;
use bitrock::Law;
use bitrock::data::surface::{SurfaceOptions, SurfaceRecord};
use bitrock::run::surface::{Settings as SurfaceRunSettings, infer};
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
    let settings: SurfaceRunSettings = crate::errors::settings(options)?;
    let seed = settings.seed;
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
        downhole_min_column: kwarg(options, "downhole_min_col")?,
        downhole_max_column: kwarg(options, "downhole_max_col")?,
        downhole_unit: unit(
            py,
            "downhole_unit",
            kwarg(options, "downhole_unit")?,
            SpeedUnit::from_suffix,
        )?,
        downhole_window_s: kwarg(options, "downhole_window_s")?,
    };
    let mut notes = Vec::new();
    let text = py.detach(|| {
        let s = settings.config(laws)?;
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
