//! The selection check of a run.

use crate::errors::*;
use bitrock::error::Error;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::PathBuf;

/// Checks the selection of the run in directory `run` by re-simulation, writes it into the
/// run's `selection/` (as `bitrock check-selection` does) and returns its document; a run kept
/// in memory (`in_memory`, `run` then `None`) is checked alike and its document only returned.
#[pyfunction]
#[pyo3(signature = (run, in_memory, options, progress, note))]
pub(crate) fn check_selection(
    py: Python<'_>,
    run: Option<PathBuf>,
    in_memory: Option<PyRef<'_, crate::run::Run>>,
    options: &Bound<'_, PyDict>,
    progress: Option<Py<PyAny>>,
    note: Option<Py<PyAny>>,
) -> PyResult<String> {
    use bitrock::selection::{self, CheckOptions, CheckedRun};
    let defaults = CheckOptions::default();
    let options = CheckOptions {
        replicates: kwarg(options, "replicates")?.unwrap_or(defaults.replicates),
        backend: named(py, "backend", kwarg(options, "backend")?)?,
        batch: kwarg(options, "batch")?,
    };
    // Replicates finish on any thread: the callback's first error is kept and raised after.
    let raised = std::sync::Mutex::new(None::<PyErr>);
    let report = |done: usize, total: usize| {
        if let Some(callback) = &progress {
            Python::attach(|py| {
                if let Err(e) = callback.call1(py, (done, total)) {
                    raised.lock().expect("not poisoned").get_or_insert(e);
                }
            });
        }
    };
    let kept = match (&run, &in_memory) {
        (None, Some(result)) => Some(check(
            py,
            result
                .in_memory()
                .unwrap_or_else(|| Err(Error::setting("source", "the result holds no run"))),
        )?),
        _ => None,
    };
    let mut notes = Vec::new();
    let checked = py.detach(|| {
        let checked = match (run, kept) {
            (Some(run), _) => {
                let checked = CheckedRun::open(&run)?;
                notes.extend(bitrock::run::Store::open(&run)?.early_end()?);
                checked
            }
            (None, Some((config, stored))) => CheckedRun::in_memory(config, stored)?,
            (None, None) => return Err(Error::setting("source", "give a run directory or a result")),
        };
        let check = selection::check(&checked, &options, &report, &mut |line| notes.push(line))?;
        if checked.dir.is_some() {
            bitrock::report::write_selection(&checked, &check)?;
        }
        Ok::<_, Error>(check)
    });
    if let Some(e) = raised.into_inner().expect("not poisoned") {
        return Err(e);
    }
    let check = check(py, checked)?;
    if let Some(callback) = &note {
        for line in notes {
            callback.call1(py, (as_arguments(&line),))?;
        }
    }
    serde_json::to_string(&check).map_err(|e| to_py(py, Error::Numerical(e.to_string())))
}
