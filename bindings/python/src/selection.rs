//! The selection check of a run.

use crate::errors::*;
use bitrock::error::Error;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::PathBuf;

/// Checks the selection of the run in directory `run` by re-simulation, writes it into the
/// run's `selection/` (as `bitrock check-selection` does) and returns its document; a run kept
/// in memory (`in_memory`, `run` then `None`) is checked alike and its document only returned.
/// An evidence directory's evidence is computed again and checked, the check written into its
/// document and returned; with a `dispatcher` (`bitrock._distributed.Dispatcher`) its
/// candidates are scored by the dispatcher's workers, `parallelism` tasks a batch.
#[pyfunction]
#[pyo3(signature = (run, in_memory, options, progress, note, dispatcher=None, parallelism=1))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn check_selection(
    py: Python<'_>,
    run: Option<PathBuf>,
    in_memory: Option<PyRef<'_, crate::run::Run>>,
    options: &Bound<'_, PyDict>,
    progress: Option<Py<PyAny>>,
    note: Option<Py<PyAny>>,
    dispatcher: Option<Py<PyAny>>,
    parallelism: usize,
) -> PyResult<String> {
    use bitrock::run::selection::{self, CheckOptions, CheckedRun};
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
    let workers = crate::evidence::Workers {
        dispatcher,
        parallelism,
    };
    if let Some(dir) = run.as_deref().filter(|dir| bitrock::run::dir::is_evidence_dir(dir)) {
        return check_evidence(py, dir, &options, &report, &raised, note, workers);
    }
    if workers.dispatcher.is_some() {
        return Err(to_py(
            py,
            Error::setting(
                "executor",
                "applies to an evidence directory's check; a run's check scores its replicates together in this process (`batch`)",
            ),
        ));
    }
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
                notes.extend(bitrock::run::abc::Store::open(&run)?.early_end()?);
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

/// The check of the evidence directory `dir` ([`bitrock::run::evidence::dir::check_dir`]),
/// as JSON.
fn check_evidence(
    py: Python<'_>,
    dir: &std::path::Path,
    options: &bitrock::run::selection::CheckOptions,
    report: &(dyn Fn(usize, usize) + Sync),
    raised: &std::sync::Mutex<Option<PyErr>>,
    note: Option<Py<PyAny>>,
    workers: crate::evidence::Workers,
) -> PyResult<String> {
    if options.batch.is_some() {
        return Err(to_py(
            py,
            Error::setting(
                "batch",
                "an evidence's check runs its replicates one after the other: leave batch out",
            ),
        ));
    }
    struct Notes(Vec<String>);
    impl bitrock::abc::Observer for Notes {
        fn note(&mut self, line: String) {
            self.0.push(line);
        }
    }
    let mut notes = Notes(Vec::new());
    let transport = workers.transport();
    let checked = py.detach(|| {
        let mut make = transport.as_ref().map(crate::evidence::make_workers);
        bitrock::run::evidence::dir::check_dir(
            dir,
            options.replicates,
            options.backend,
            &mut crate::evidence::scoring(&mut make),
            &mut |done, total| report(done, total),
            &mut notes,
        )
    });
    if let Some(e) = transport
        .as_ref()
        .and_then(crate::distributed::PyTransport::take_raised)
    {
        return Err(e);
    }
    if let Some(e) = raised.lock().expect("not poisoned").take() {
        return Err(e);
    }
    let check = check(py, checked)?;
    if let Some(callback) = &note {
        for line in notes.0 {
            callback.call1(py, (as_arguments(&line),))?;
        }
    }
    serde_json::to_string(&check).map_err(|e| to_py(py, Error::Numerical(e.to_string())))
}
