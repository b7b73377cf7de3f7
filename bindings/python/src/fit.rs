//! Least-squares fits of the laws to a record.

use crate::errors::*;
use crate::record::*;
use bitrock::fit::FitOptions;
use bitrock::{Law, documents};
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// The least-squares fit options from keyword arguments.
pub(crate) fn fit_options(py: Python<'_>, kw: &Bound<'_, PyDict>) -> PyResult<FitOptions> {
    let options = FitOptions::from_settings(
        kwarg(kw, "bounds")?.unwrap_or(true),
        kwarg(kw, "starts")?,
        kwarg(kw, "scale_by_wob")?.unwrap_or(false),
        kwarg(kw, "w_ref_kn")?,
    );
    check(py, options)
}

/// Least-squares fits of `laws` (`None`: all) to the record: `fit --json`'s document.
#[pyfunction]
#[pyo3(signature = (record, laws, options))]
pub(crate) fn fit(
    py: Python<'_>,
    record: &Record,
    laws: Option<Vec<String>>,
    options: &Bound<'_, PyDict>,
) -> PyResult<String> {
    let laws = self::laws(py, laws)?.unwrap_or_else(|| Law::ALL.to_vec());
    let opts = fit_options(py, options)?;
    let data = &record.data;
    let fits = py.detach(|| bitrock::fit::fit_record(&laws, data, &opts));
    let fits = check(py, fits)?;
    Ok(as_arguments(&documents::fit_json(data, &fits).to_string()))
}
