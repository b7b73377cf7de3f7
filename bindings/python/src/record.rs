//! Records: a CSV file or columns read into SI samples, their units and warnings.

use crate::errors::*;
use bitrock::data::{DataOptions, FieldData};
use bitrock::units::{ForceUnit, SpeedUnit, TorqueUnit};
use numpy::{PyArray1, PyReadonlyArray1};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::{Path, PathBuf};

/// A field record, read and split into calibration and validation samples (SI inside).
#[pyclass(frozen, module = "bitrock._bitrock")]
pub(crate) struct Record {
    pub(crate) data: FieldData,
}

#[pymethods]
impl Record {
    /// Where the record came from.
    #[getter]
    fn source(&self) -> String {
        self.data.source.display().to_string()
    }
    #[getter]
    fn rows_read(&self) -> usize {
        self.data.rows_read
    }
    #[getter]
    fn rows_used(&self) -> usize {
        self.data.rows_used
    }
    /// The unit torques are given and reported in (`kN·m`, `N·m`).
    #[getter]
    fn torque_unit(&self) -> &'static str {
        self.data.torque_unit.label()
    }
    #[getter]
    fn speed_unit(&self) -> &'static str {
        self.data.speed_unit.label()
    }
    #[getter]
    fn warnings(&self) -> Vec<String> {
        self.data.warnings.clone()
    }
    /// `{"speed", "torque", "wob", "time"}`: the columns read.
    #[getter]
    fn columns(&self) -> (String, String, Option<String>, Option<String>) {
        let c = &self.data.columns;
        (c.speed.clone(), c.torque.clone(), c.wob.clone(), c.time.clone())
    }
    /// The calibration samples: bit speed (rad/s) and torque (N·m), without copies.
    fn calibration<'py>(&self, py: Python<'py>) -> (Bound<'py, PyArray1<f64>>, Bound<'py, PyArray1<f64>>) {
        let s = &self.data.calibration;
        (
            PyArray1::from_slice(py, &s.speed_rad_s),
            PyArray1::from_slice(py, &s.torque_nm),
        )
    }
    /// Pickling: the record whole (samples, units, columns, warnings) as JSON, exact to the
    /// bit (shortest round-trip decimals), rebuilt by [`Record::_from_state`].
    fn __reduce__<'py>(slf: &Bound<'py, Self>) -> PyResult<(Bound<'py, PyAny>, (String,))> {
        crate::errors::reduce_to_json(slf.as_any(), &slf.get().data, "record")
    }
    /// The record a pickle's state describes.
    #[staticmethod]
    fn _from_state(py: Python<'_>, state: &str) -> PyResult<Self> {
        let data: FieldData = crate::errors::from_json_state(py, state, "record", "record")?;
        Ok(Record { data })
    }
    fn __repr__(&self) -> String {
        let d = &self.data;
        format!(
            "<bitrock.Record {}: {} of {} rows used ({} calibration, {} validation), torque in {}, {} warning{}>",
            d.source.display(),
            d.rows_used,
            d.rows_read,
            d.calibration.len(),
            d.validation.len(),
            d.torque_unit.label(),
            d.warnings.len(),
            if d.warnings.len() == 1 { "" } else { "s" }
        )
    }
    /// A notebook's view: where the record came from, what was used, in which units, the
    /// speed and torque ranges of the calibration samples, and the warnings.
    fn _repr_html_(&self) -> String {
        let d = &self.data;
        let c = &d.calibration;
        let range = |v: &[f64]| {
            let (lo, hi) = v.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &x| {
                (lo.min(x), hi.max(x))
            });
            (lo, hi)
        };
        let (w_lo, w_hi) = range(&c.speed_rad_s);
        let (t_lo, t_hi) = range(&c.torque_nm);
        let unit = d.torque_unit.newton_metres();
        let rpm = 1.0 / bitrock::units::RAD_S_PER_RPM;
        let columns = &d.columns;
        let rows = [
            ("source", escape(&d.source.display().to_string())),
            (
                "rows",
                format!(
                    "{} of {} used: {} calibration, {} validation",
                    d.rows_used,
                    d.rows_read,
                    c.len(),
                    d.validation.len()
                ),
            ),
            (
                "columns",
                escape(&format!(
                    "speed '{}', torque '{}'{}",
                    columns.speed,
                    columns.torque,
                    columns
                        .wob
                        .as_ref()
                        .map_or(String::new(), |w| format!(", weight on bit '{w}'"))
                )),
            ),
            (
                "bit speed",
                format!(
                    "{:.1} to {:.1} rpm (read in {})",
                    w_lo * rpm,
                    w_hi * rpm,
                    d.speed_unit.label()
                ),
            ),
            (
                "torque",
                format!("{:.4} to {:.4} {}", t_lo / unit, t_hi / unit, d.torque_unit.label()),
            ),
        ];
        let mut html = String::from("<div><b>bitrock.Record</b><table>");
        for (name, value) in rows {
            html.push_str(&format!(
                "<tr><th style=\"text-align:left\">{name}</th><td style=\"text-align:left\">{value}</td></tr>"
            ));
        }
        html.push_str("</table>");
        if !d.warnings.is_empty() {
            html.push_str("<ul>");
            for w in &d.warnings {
                html.push_str(&format!("<li>warning: {}</li>", escape(w)));
            }
            html.push_str("</ul>");
        }
        html.push_str("</div>");
        html
    }
    /// The validation samples: bit speed (rad/s) and torque (N·m).
    fn validation<'py>(&self, py: Python<'py>) -> (Bound<'py, PyArray1<f64>>, Bound<'py, PyArray1<f64>>) {
        let s = &self.data.validation;
        (
            PyArray1::from_slice(py, &s.speed_rad_s),
            PyArray1::from_slice(py, &s.torque_nm),
        )
    }
}

/// The record options from `bitrock.read_record`'s keyword arguments (`None`: the library's
/// default).
pub(crate) fn data_options(py: Python<'_>, kw: &Bound<'_, PyDict>) -> PyResult<DataOptions> {
    let defaults = DataOptions::default();
    Ok(DataOptions {
        speed_column: kwarg(kw, "speed_col")?,
        torque_column: kwarg(kw, "torque_col")?,
        wob_column: kwarg(kw, "wob_col")?,
        time_column: kwarg(kw, "time_col")?,
        speed_unit: unit(py, "speed_unit", kwarg(kw, "speed_unit")?, SpeedUnit::from_suffix)?,
        torque_unit: unit(py, "torque_unit", kwarg(kw, "torque_unit")?, TorqueUnit::from_suffix)?,
        wob_unit: unit(py, "wob_unit", kwarg(kw, "wob_unit")?, ForceUnit::from_suffix)?,
        min_speed_rpm: kwarg(kw, "min_speed_rpm")?.unwrap_or(defaults.min_speed_rpm),
        t_start_s: kwarg(kw, "t_start_s")?,
        t_end_s: kwarg(kw, "t_end_s")?,
        thin: kwarg(kw, "thin")?.unwrap_or(defaults.thin),
        calibration_fraction: kwarg(kw, "calibration_fraction")?.unwrap_or(defaults.calibration_fraction),
        split: named(py, "split", kwarg(kw, "split")?)?.unwrap_or(defaults.split),
        column_map: kwarg(kw, "column_map")?,
    })
}

/// Reads a CSV record at `path` (`None`: the embedded demo record).
#[pyfunction]
pub(crate) fn read_csv(py: Python<'_>, path: Option<PathBuf>, options: &Bound<'_, PyDict>) -> PyResult<Record> {
    let opts = data_options(py, options)?;
    let data = py.detach(|| match &path {
        Some(path) => bitrock::data::read_field_data(path, &opts),
        None => bitrock::data::demo_field_data(&opts),
    });
    Ok(Record { data: check(py, data)? })
}

/// Reads a record from named float64 columns (a DataFrame's), read without copies; `None`
/// for a column that holds no numbers.
#[pyfunction]
pub(crate) fn read_columns(
    py: Python<'_>,
    names: Vec<String>,
    columns: Vec<Option<PyReadonlyArray1<'_, f64>>>,
    source: String,
    options: &Bound<'_, PyDict>,
) -> PyResult<Record> {
    let opts = data_options(py, options)?;
    let slices = columns
        .iter()
        .map(|c| c.as_ref().map(|c| c.as_slice()).transpose())
        .collect::<Result<Vec<Option<&[f64]>>, _>>()?;
    let data = bitrock::data::field_data_from_columns(&names, &slices, Path::new(&source), &opts);
    Ok(Record { data: check(py, data)? })
}

/// `text` safe inside HTML.
fn escape(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}
