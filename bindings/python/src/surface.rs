//! Laws from a surface record (top-drive speed and surface torque) through simulated strings.

use crate::distributed::{PyTransport, after_remote, remote_on};
use crate::errors::*;
use bitrock::Law;
use bitrock::abc::shard::Remote;
use bitrock::data::surface::{SurfaceOptions, SurfaceRecord};
use bitrock::run::surface::dir::{self, Sampled, SurfaceDir};
use bitrock::run::surface::{Sampling, Settings as SurfaceRunSettings, SurfaceResult, infer_continuing};
use bitrock::run::{Placement, Scoring};
use bitrock::units::{ForceUnit, SpeedUnit, TorqueUnit};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::PathBuf;
use std::sync::OnceLock;

/// `bitrock surface` on the record at `path`: the whole result as JSON text, written as a
/// surface directory to `out` where given, its sampler's strings simulated by the workers of
/// `dispatcher` where given (the result then carries their `traffic`). The notes of the run
/// (a GPU fallback of the advice's strings, say) go to `note` once it is done.
#[pyfunction]
#[pyo3(signature = (path, laws, options, note, out=None, force=false, dispatcher=None, parallelism=1))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn surface(
    py: Python<'_>,
    path: PathBuf,
    laws: Option<Vec<String>>,
    options: &Bound<'_, PyDict>,
    note: Option<Py<PyAny>>,
    out: Option<PathBuf>,
    force: bool,
    dispatcher: Option<Py<PyAny>>,
    parallelism: usize,
) -> PyResult<String> {
    let laws = crate::errors::laws(py, laws)?.unwrap_or_else(|| {
        Law::ALL
            .into_iter()
            .chain(bitrock::laws::file::registered_laws())
            .collect()
    });
    let settings: SurfaceRunSettings = crate::errors::settings(options)?;
    let seed = settings.seed;
    let columns = surface_columns(py, options)?;
    let mut notes = Vec::new();
    let cell = OnceLock::new();
    let text = py.detach(|| {
        // The prior file read once, into the job a surface directory keeps.
        let job = dir::Job::new(laws, settings, columns, &path)?;
        let s = job.config()?;
        if let Some(out) = &out {
            dir::check_out(out, force)?;
        }
        let record = SurfaceRecord::read(&path, &job.columns)?;
        let mut note = |line| notes.push(line);
        on_workers(&cell, dispatcher, parallelism, |scoring| {
            match &out {
                Some(out) => {
                    // The record as the directory keeps it, read from its bytes.
                    let (run, record) = SurfaceDir::start(out, force, job)?;
                    let result = run.run(&record, &s, Sampled::default(), false, scoring, &mut note)?;
                    run.finish(&record, &result)?;
                    Ok((record, result))
                }
                None => {
                    let mut keep = |_: &[bitrock::abc::Population]| Ok(());
                    let sampling = Sampling {
                        previous: Vec::new(),
                        stopped: None,
                        keep: &mut keep,
                        warm: &[],
                        scoring,
                    };
                    let result = infer_continuing(&record, &s, seed, sampling, &mut note)?;
                    Ok((record, result))
                }
            }
        })
    });
    // The workers' exception first: it is what stopped the run.
    let text = with_traffic(cell, text)?;
    said(py, &note, &notes)?;
    check(py, text)
}

/// `run` with the sampler's strings on the workers of `dispatcher` (through `cell`, which
/// keeps them for their traffic), or here; the result as Python reads it.
fn on_workers<'a>(
    cell: &'a OnceLock<Remote<PyTransport>>,
    dispatcher: Option<Py<PyAny>>,
    parallelism: usize,
    run: impl FnOnce(Scoring<'_, 'a>) -> bitrock::Result<(SurfaceRecord, SurfaceResult)>,
) -> bitrock::Result<serde_json::Value> {
    let (record, result) = match dispatcher {
        None => run(Scoring::Here)?,
        Some(dispatcher) => {
            let mut make = remote_on(cell, dispatcher, parallelism);
            let mut workers =
                move |objective, placement: &Placement, _note: &mut dyn FnMut(String)| make(objective, placement);
            run(Scoring::Workers(&mut workers))?
        }
    };
    Ok(document(&record, &result))
}

/// The document's text, with the workers' traffic where the run had workers; the Python
/// exception that stopped them, where one did.
fn with_traffic(
    cell: OnceLock<Remote<PyTransport>>,
    document: bitrock::Result<serde_json::Value>,
) -> PyResult<bitrock::Result<String>> {
    let (traffic, raised) = after_remote(cell);
    if let Some(e) = raised {
        return Err(e);
    }
    Ok(document.map(|mut document| {
        if let Some(traffic) = traffic {
            document["traffic"] = serde_json::from_str(&traffic).expect("traffic is JSON");
        }
        document.to_string()
    }))
}

/// `bitrock surface --resume`: the surface run in `dir` continued with `more`'s stopping rules
/// and backend, the directory written anew, on the workers of `dispatcher` where given; the
/// whole result as JSON text.
#[pyfunction]
#[pyo3(signature = (dir, max_populations, max_seconds, backend, check_replicates, note, dispatcher=None, parallelism=1))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn resume_surface(
    py: Python<'_>,
    dir: PathBuf,
    max_populations: Option<usize>,
    max_seconds: Option<f64>,
    backend: Option<String>,
    check_replicates: Option<usize>,
    note: Option<Py<PyAny>>,
    dispatcher: Option<Py<PyAny>>,
    parallelism: usize,
) -> PyResult<String> {
    let backend = named(py, "backend", backend)?;
    let more = dir::Continuation {
        max_populations,
        max_seconds,
        backend,
        check_replicates,
    };
    let mut notes = Vec::new();
    let cell = OnceLock::new();
    let text = py.detach(|| {
        let (mut run, record, sampled) = SurfaceDir::open(&dir)?;
        let settings = run.continued(&more, sampled.populations.len())?;
        on_workers(&cell, dispatcher, parallelism, |scoring| {
            let result = run.run(&record, &settings, sampled, false, scoring, &mut |line| {
                notes.push(line)
            })?;
            run.finish(&record, &result)?;
            Ok((record, result))
        })
    });
    // The workers' exception first: it is what stopped the run.
    let text = with_traffic(cell, text)?;
    said(py, &note, &notes)?;
    check(py, directory_named(text))
}

/// The library names the directory by the command line's flag (`resume`); here it is the
/// argument `directory`.
fn directory_named<T>(result: bitrock::Result<T>) -> bitrock::Result<T> {
    result.map_err(|err| match err {
        bitrock::Error::InvalidSetting { field, message } if field == "resume" => bitrock::Error::InvalidSetting {
            field: "directory".into(),
            message,
        },
        err => err,
    })
}

/// The finished surface run in `dir`: its document with the record's clock, as JSON text.
#[pyfunction]
pub(crate) fn read_surface(py: Python<'_>, dir: PathBuf) -> PyResult<String> {
    let text = py.detach(|| Ok::<_, bitrock::Error>(dir::Finished::read(&dir)?.with_clock().to_string()));
    check(py, directory_named(text))
}

/// `bitrock check-selection` on the surface directory `dir`: its check made again with
/// `replicates` records per law (default: the command's), on `backend` (default: the run's),
/// the directory written anew; the whole result as JSON text.
#[pyfunction]
#[pyo3(signature = (dir, replicates, backend, note))]
pub(crate) fn check_surface(
    py: Python<'_>,
    dir: PathBuf,
    replicates: Option<usize>,
    backend: Option<String>,
    note: Option<Py<PyAny>>,
) -> PyResult<String> {
    let backend = named(py, "backend", backend)?;
    let replicates = replicates.unwrap_or(bitrock::run::selection::CheckOptions::default().replicates);
    let mut notes = Vec::new();
    let text = py.detach(|| {
        dir::check_again(&dir, replicates, backend, &mut |line| notes.push(line))?;
        Ok::<_, bitrock::Error>(dir::Finished::read(&dir)?.with_clock().to_string())
    });
    said(py, &note, &notes)?;
    check(py, directory_named(text))
}

/// True when `dir` holds a surface run (`bitrock surface --out`).
#[pyfunction]
pub(crate) fn is_surface_dir(dir: PathBuf) -> bool {
    dir::is_surface_dir(&dir)
}

/// A result as Python reads it: the document with the record's clock.
fn document(record: &SurfaceRecord, result: &SurfaceResult) -> serde_json::Value {
    let mut document = serde_json::to_value(result).expect("a result serialises");
    document["time_s"] = serde_json::to_value(&record.time_s).expect("numbers serialise");
    document
}

/// Hands the run's notes to `note`.
fn said(py: Python<'_>, note: &Option<Py<PyAny>>, notes: &[String]) -> PyResult<()> {
    if let Some(callback) = note {
        for line in notes {
            callback.call1(py, (as_arguments(line),))?;
        }
    }
    Ok(())
}

/// A surface record's columns and units from the keyword arguments in `options` (each
/// defaulted where absent).
pub(crate) fn surface_columns(py: Python<'_>, options: &Bound<'_, PyDict>) -> PyResult<SurfaceOptions> {
    Ok(SurfaceOptions {
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
        ignore_downhole: false,
    })
}
