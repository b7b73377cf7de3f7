//! The coupled axial-torsional bit (RGD): one string, a regime map, a drilling record's
//! calibration and the regimes' probabilities over its posterior, a well of formations, the
//! structure a bit or surface record shows, as `bitrock coupled` runs them
//! (`bitrock::run::coupled`, `bitrock::run::choice`).

use crate::errors::*;
use bitrock::data::drilling::{DrillingOptions, DrillingRecord};
use bitrock::data::surface::{SurfaceOptions, SurfaceRecord};
use bitrock::run::choice::{choice, surface_choice};
use bitrock::run::coupled::{self as run, Settings};
use bitrock::simulate::coupled::well::CoupledWell;
use bitrock::units::{AccelerationUnit, ForceUnit, RateUnit, SpeedUnit, TorqueUnit};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::PathBuf;

/// Calls `note` with each of the run's notes (a GPU fallback), once it is done.
fn say(py: Python<'_>, note: &Option<Py<PyAny>>, notes: Vec<String>) -> PyResult<()> {
    if let Some(callback) = note {
        for line in notes {
            callback.call1(py, (as_arguments(&line),))?;
        }
    }
    Ok(())
}

/// `bitrock coupled` with the settings in `options`: one string (its summary and steady
/// drilling, and with `record` its samples as columns), or with `map` the regime map (the
/// escape map with the `escape` setting); as JSON text.
#[pyfunction]
#[pyo3(signature = (options, record, map, note))]
pub(crate) fn coupled(
    py: Python<'_>,
    options: &Bound<'_, PyDict>,
    record: bool,
    map: bool,
    note: Option<Py<PyAny>>,
) -> PyResult<String> {
    let settings: Settings = settings(options)?;
    check(py, run::check_escape_start(&settings, map, false, true))?;
    let mut notes = Vec::new();
    let value = if map && settings.escape {
        let m = py.detach(|| run::escape_map(&settings, &mut |line| notes.push(line)));
        serde_json::to_value(check(py, m)?)
    } else if map {
        let m = py.detach(|| run::map(&settings, &mut |line| notes.push(line)));
        serde_json::to_value(check(py, m)?)
    } else {
        let mut samples = Vec::new();
        let one = py.detach(|| {
            run::one(&settings, &mut |s| {
                if record {
                    samples.push(*s)
                }
            })
        });
        let one = check(py, one)?;
        notes.extend(one.warning.as_ref().map(|w| format!("warning: {w}")));
        let mut value = serde_json::to_value(one).expect("a report serialises");
        if record {
            let columns = run::record_columns(&samples, &|_| settings.omega_rpm)
                .into_iter()
                .map(|(name, values)| (name.to_string(), values.into()));
            value["record"] = serde_json::Value::Object(columns.collect());
        }
        Ok(value)
    };
    say(py, &note, notes)?;
    Ok(value.expect("a report serialises").to_string())
}

/// One string drilled through the well file at `path` (`bitrock coupled --well`): each
/// segment's report, and with `record` the samples as columns (`segment` each sample's
/// segment's index); as JSON text. `note` hears a segment spent off bottom.
#[pyfunction]
#[pyo3(signature = (path, record, note))]
pub(crate) fn coupled_well(py: Python<'_>, path: PathBuf, record: bool, note: Option<Py<PyAny>>) -> PyResult<String> {
    let well = check(py, CoupledWell::load(&path))?;
    if record {
        check(py, well.check_record_memory())?;
    }
    let mut samples = Vec::new();
    let segments = py.detach(|| {
        run::well(&well, &mut |i, s| {
            if record {
                samples.push((i, *s))
            }
        })
    });
    let segments = check(py, segments)?;
    let notes = segments
        .iter()
        .filter_map(|s| s.warning.as_ref().map(|w| format!("warning: segment {}: {w}", s.name)))
        .collect();
    say(py, &note, notes)?;
    let mut value = serde_json::json!({ "segments": segments });
    if record {
        let (segment, columns) = run::well_record_columns(&well, &samples);
        let mut columns: serde_json::Map<String, serde_json::Value> = columns
            .into_iter()
            .map(|(name, values)| (name.to_string(), values.into()))
            .collect();
        columns.insert("segment".into(), segment.into());
        value["record"] = serde_json::Value::Object(columns);
    }
    Ok(value.to_string())
}

/// The bit calibrated on the drilling record at `path` (columns and units in `columns`), and
/// with `map` the regimes' probabilities over its posterior (with the `escape` setting, each
/// draw's bit continued from where it is at the start, and the way out); as JSON text.
#[pyfunction]
#[pyo3(signature = (path, columns, options, map, note))]
pub(crate) fn coupled_calibrate(
    py: Python<'_>,
    path: PathBuf,
    columns: &Bound<'_, PyDict>,
    options: &Bound<'_, PyDict>,
    map: bool,
    note: Option<Py<PyAny>>,
) -> PyResult<String> {
    let settings: Settings = settings(options)?;
    let speed_given = options.get_item("omega_rpm")?.is_some_and(|v| !v.is_none());
    check(py, run::check_escape_start(&settings, map, true, speed_given))?;
    let record = check(py, DrillingRecord::read(&path, &drilling_options(py, columns, true)?))?;
    let calibration = check(py, run::calibration(&record, &settings))?;
    let mut notes = calibration.notes();
    let value = if map && settings.escape {
        let m = py.detach(|| run::posterior_escape_map(&settings, &calibration, &mut |line| notes.push(line)));
        serde_json::json!({"map": check(py, m)?, "calibration": calibration})
    } else if map {
        let m = py.detach(|| run::posterior_map(&settings, &calibration, &mut |line| notes.push(line)));
        serde_json::json!({"map": check(py, m)?, "calibration": calibration})
    } else {
        serde_json::to_value(&calibration).expect("a calibration serialises")
    };
    say(py, &note, notes)?;
    Ok(value.to_string())
}

/// The drilling record's columns and units named in `columns` (each defaulted where absent), its
/// axial acceleration read where `calibrating`.
fn drilling_options(py: Python<'_>, columns: &Bound<'_, PyDict>, calibrating: bool) -> PyResult<DrillingOptions> {
    Ok(DrillingOptions {
        read_axial_acceleration: calibrating,
        speed_column: kwarg(columns, "speed_col")?,
        torque_column: kwarg(columns, "torque_col")?,
        wob_column: kwarg(columns, "wob_col")?,
        rop_column: kwarg(columns, "rop_col")?,
        axial_speed_column: kwarg(columns, "axial_speed_col")?,
        axial_acceleration_column: kwarg(columns, "axial_acceleration_col")?,
        time_column: kwarg(columns, "time_col")?,
        speed_unit: unit(py, "speed_unit", kwarg(columns, "speed_unit")?, SpeedUnit::from_suffix)?,
        torque_unit: unit(
            py,
            "torque_unit",
            kwarg(columns, "torque_unit")?,
            TorqueUnit::from_suffix,
        )?,
        wob_unit: unit(py, "wob_unit", kwarg(columns, "wob_unit")?, ForceUnit::from_suffix)?,
        rop_unit: unit(py, "rop_unit", kwarg(columns, "rop_unit")?, RateUnit::from_suffix)?,
        acceleration_unit: unit(
            py,
            "acceleration_unit",
            kwarg(columns, "acceleration_unit")?,
            AccelerationUnit::from_suffix,
        )?,
    })
}

/// The structure the bit record at `path` shows (columns and units in `columns`): a torsional
/// law or the coupled bit, chosen by simulation and checked by re-simulation
/// (`bitrock::run::choice`); as JSON text.
#[pyfunction]
#[pyo3(signature = (path, columns, options, note))]
pub(crate) fn coupled_select(
    py: Python<'_>,
    path: PathBuf,
    columns: &Bound<'_, PyDict>,
    options: &Bound<'_, PyDict>,
    note: Option<Py<PyAny>>,
) -> PyResult<String> {
    let settings: Settings = settings(options)?;
    let record = check(py, DrillingRecord::read(&path, &drilling_options(py, columns, false)?))?;
    let mut notes = Vec::new();
    let c = py.detach(|| choice(&record, &settings, &mut |line| notes.push(line)));
    let c = check(py, c)?;
    say(py, &note, notes)?;
    Ok(serde_json::to_string(&c).expect("a choice serialises"))
}

/// The structure the surface record at `path` shows (columns and units in `columns`), from
/// its surface torque at its steady top-drive speed (`bitrock::run::choice::surface_choice`);
/// as JSON text.
#[pyfunction]
#[pyo3(signature = (path, columns, options, note))]
pub(crate) fn coupled_select_surface(
    py: Python<'_>,
    path: PathBuf,
    columns: &Bound<'_, PyDict>,
    options: &Bound<'_, PyDict>,
    note: Option<Py<PyAny>>,
) -> PyResult<String> {
    let settings: Settings = settings(options)?;
    let surface = SurfaceOptions {
        // The choice compares the surface torque alone.
        ignore_downhole: true,
        ..crate::surface::surface_columns(py, columns)?
    };
    let record = check(py, SurfaceRecord::read(&path, &surface))?;
    let mut notes = Vec::new();
    let c = py.detach(|| surface_choice(&record, &settings, &mut |line| notes.push(line)));
    let c = check(py, c)?;
    say(py, &note, notes)?;
    Ok(serde_json::to_string(&c).expect("a choice serialises"))
}
