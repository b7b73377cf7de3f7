//! `bitrock._bitrock`: the library's entry points for the Python package. Arguments arrive as
//! the Python layer's keyword arguments (named like the command line's flags without dashes);
//! results leave as JSON documents (the ones `run.json` and `fit --json` hold) and NumPy
//! arrays. Work runs with the interpreter released; Ctrl-C stops a run between batches.

use bitrock::abc::shard::wire::{Exchanged, Payloads, Traffic};
use bitrock::abc::shard::{Remote, Transport, Workers};
use bitrock::abc::{Observer, Population, Progress};
use bitrock::data::{DataOptions, FieldData};
use bitrock::error::Error;
use bitrock::eval::Backend;
use bitrock::fit::FitOptions;
use bitrock::pipeline::AbcJob;
use bitrock::run;
use bitrock::run::{Continuation, Settings};
use bitrock::units::{ForceUnit, SpeedUnit, TorqueUnit};
use bitrock::{Law, documents};
use numpy::{PyArray1, PyArrayMethods, PyReadonlyArray1};
use pyo3::exceptions::PyKeyboardInterrupt;
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict, PyList};
use std::path::{Path, PathBuf};
use std::sync::{Mutex, OnceLock};

/// Keyword arguments whose names differ from the library's configuration fields: an error
/// about the field names the argument the caller wrote.
const ARGUMENTS: &[(&str, &str)] = &[
    ("speed_column", "speed_col"),
    ("torque_column", "torque_col"),
    ("wob_column", "wob_col"),
    ("time_column", "time_col"),
    ("prior", "prior_file"),
    ("bounded", "bounds"),
    ("no_bounds", "bounds=False"),
];

/// `message` with the configuration fields it names (`` `speed_column` ``) said as the
/// keyword arguments a Python caller writes (`` `speed_col` ``).
fn as_arguments(message: &str) -> String {
    ARGUMENTS.iter().fold(message.to_string(), |text, (field, argument)| {
        text.replace(&format!("`{field}`"), &format!("`{argument}`"))
    })
}

/// The Python exception for a library error: `InputError` naming the argument, the matching
/// `OSError` for files, `GpuError`, `KeyboardInterrupt` for a run stopped by Ctrl-C,
/// `BitrockError` otherwise (all but the last two defined in Python, so that they pickle).
fn to_py(py: Python<'_>, err: Error) -> PyErr {
    let message = as_arguments(&err.to_string());
    if matches!(err, Error::Interrupted) {
        return PyKeyboardInterrupt::new_err(message);
    }
    let built = py.import("bitrock._errors").and_then(|errors| match &err {
        Error::InvalidSetting { field, message } => {
            let argument = ARGUMENTS
                .iter()
                .find(|(f, _)| f == field)
                .map_or(field.as_str(), |(_, a)| a);
            errors
                .getattr("InputError")?
                .call1((format!("{argument}: {}", as_arguments(message)), argument))
        }
        Error::Read { path, source } | Error::Write { path, source } | Error::Output { path, source, .. } => errors
            .getattr("os_error")?
            .call1((source.raw_os_error().unwrap_or(0), message, path.display().to_string())),
        Error::Gpu(_) => errors.getattr("GpuError")?.call1((message,)),
        e if e.is_bad_input() => errors.getattr("InputError")?.call1((message, py.None())),
        _ => errors.getattr("BitrockError")?.call1((message,)),
    });
    match built {
        Ok(value) => PyErr::from_value(value),
        Err(e) => e,
    }
}

/// `Ok` or the Python exception of the library's error.
fn check<T>(py: Python<'_>, result: bitrock::Result<T>) -> PyResult<T> {
    result.map_err(|e| to_py(py, e))
}

/// A value of one of the library's lowercase enums (`cpu`, `smc`, `nested`…) from its name.
fn named<T: serde::de::DeserializeOwned>(py: Python<'_>, argument: &str, value: Option<String>) -> PyResult<Option<T>> {
    value
        .map(|v| {
            serde_json::from_value(serde_json::Value::String(v.to_lowercase())).map_err(|_| {
                to_py(
                    py,
                    Error::setting(argument, format!("`{v}` is not one of the accepted values")),
                )
            })
        })
        .transpose()
}

/// A unit from its command-line name (`rpm`, `rad_s`, `knm`, `nm`, `kn`, `n`), read as a
/// column suffix is.
fn unit<T>(
    py: Python<'_>,
    argument: &str,
    value: Option<String>,
    from_suffix: fn(&str) -> Option<T>,
) -> PyResult<Option<T>> {
    value
        .map(|v| {
            from_suffix(&format!("column_{}", v.to_lowercase()))
                .ok_or_else(|| to_py(py, Error::setting(argument, format!("unknown unit `{v}`"))))
        })
        .transpose()
}

/// The laws named in `laws`, or `None` for every law.
fn laws(py: Python<'_>, laws: Option<Vec<String>>) -> PyResult<Option<Vec<Law>>> {
    laws.map(|names| {
        names
            .iter()
            .map(|n| {
                n.parse::<Law>()
                    .map_err(|e| to_py(py, Error::setting("laws", e.to_string())))
            })
            .collect()
    })
    .transpose()
}

/// A field record, read and split into calibration and validation samples (SI inside).
#[pyclass(frozen, module = "bitrock._bitrock")]
struct Record {
    data: FieldData,
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
    /// The validation samples: bit speed (rad/s) and torque (N·m).
    fn validation<'py>(&self, py: Python<'py>) -> (Bound<'py, PyArray1<f64>>, Bound<'py, PyArray1<f64>>) {
        let s = &self.data.validation;
        (
            PyArray1::from_slice(py, &s.speed_rad_s),
            PyArray1::from_slice(py, &s.torque_nm),
        )
    }
}

/// The keyword argument `key` of `kw`, `None` when absent or `None`. A value of the wrong
/// type or out of range (a negative count, an integer beyond 64 bits, a string for a number)
/// and a bool where a number belongs (`particles=True`) are `InputError`s naming `key`.
fn kwarg<'py, T>(kw: &Bound<'py, PyDict>, key: &str) -> PyResult<Option<T>>
where
    T: for<'a> FromPyObject<'a, 'py> + 'static,
    for<'a> <T as FromPyObject<'a, 'py>>::Error: Into<PyErr>,
{
    let Some(value) = kw.get_item(key)?.filter(|v| !v.is_none()) else {
        return Ok(None);
    };
    let py = kw.py();
    let refuse = |why: String| {
        let shown = value.repr().map_or_else(|_| "the value".to_string(), |r| r.to_string());
        to_py(py, Error::setting(key, format!("{shown} is not accepted: {why}")))
    };
    if value.is_instance_of::<pyo3::types::PyBool>() && std::any::TypeId::of::<T>() != std::any::TypeId::of::<bool>() {
        return Err(refuse("a bool is not a number here".into()));
    }
    value
        .extract()
        .map(Some)
        .map_err(|e| refuse(Into::<PyErr>::into(e).value(py).to_string()))
}

/// The record options from `bitrock.read_record`'s keyword arguments (`None`: the library's
/// default).
fn data_options(py: Python<'_>, kw: &Bound<'_, PyDict>) -> PyResult<DataOptions> {
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
    })
}

/// Reads a CSV record at `path` (`None`: the embedded demo record).
#[pyfunction]
fn read_csv(py: Python<'_>, path: Option<PathBuf>, options: &Bound<'_, PyDict>) -> PyResult<Record> {
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
fn read_columns(
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

/// The least-squares fit options from keyword arguments.
fn fit_options(py: Python<'_>, kw: &Bound<'_, PyDict>) -> PyResult<FitOptions> {
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
fn fit(py: Python<'_>, record: &Record, laws: Option<Vec<String>>, options: &Bound<'_, PyDict>) -> PyResult<String> {
    let laws = self::laws(py, laws)?.unwrap_or_else(|| Law::ALL.to_vec());
    let opts = fit_options(py, options)?;
    let data = &record.data;
    let fits = py.detach(|| bitrock::fit::fit_record(&laws, data, &opts));
    let fits = check(py, fits)?;
    Ok(as_arguments(&documents::fit_json(data, &fits).to_string()))
}

/// Watches a run for Python: progress to a callable, notes to `warnings`-like callable, and
/// Ctrl-C (checked after every batch) stops it.
struct PyObserver {
    progress: Option<Py<PyAny>>,
    note: Option<Py<PyAny>>,
    /// A Python exception raised by a callback or by a signal handler.
    raised: Option<PyErr>,
}

impl Observer for PyObserver {
    fn progress(&mut self, p: &Progress) {
        if self.raised.is_some() {
            return;
        }
        Python::attach(|py| {
            if let Err(e) = py.check_signals() {
                self.raised = Some(e);
                return;
            }
            if let Some(callback) = &self.progress
                && let Err(e) = callback.call1(py, (p.population, p.accepted, p.target, p.draws, p.epsilon))
            {
                self.raised = Some(e);
            }
        });
    }

    fn population_done(&mut self, population: &Population, _previous: Option<&Population>) -> bitrock::Result<()> {
        if let Some(callback) = &self.progress {
            let r = &population.record;
            Python::attach(|py| {
                if let Err(e) = callback.call1(py, (r.index, r.accepted, r.accepted, r.draws, r.epsilon)) {
                    self.raised.get_or_insert(e);
                }
            });
        }
        Ok(())
    }

    fn note(&mut self, line: String) {
        if let Some(callback) = &self.note {
            Python::attach(|py| {
                if let Err(e) = callback.call1(py, (line,)) {
                    self.raised.get_or_insert(e);
                }
            });
        }
    }

    fn interrupted(&mut self) -> bool {
        self.raised.is_some()
    }
}

/// Carries a run's tasks to workers through a Python dispatcher (`bitrock._distributed`): its
/// `exchange(requests, problem, context, (problem_key, context_key))` returns the replies and
/// the payload bytes shipped.
struct PyTransport {
    dispatcher: Py<PyAny>,
    parallelism: usize,
    /// The Python exception that stopped an exchange (Ctrl-C, a task failing on every try).
    raised: Mutex<Option<PyErr>>,
    /// The payloads as Python bytes, by key: made once, not copied again every round.
    payloads: Mutex<Vec<(u64, Py<PyBytes>)>>,
}

impl PyTransport {
    /// `bytes` (named `key`) as Python bytes, made on first use; the problem's and the latest
    /// context's are kept.
    fn payload(&self, py: Python<'_>, key: u64, bytes: &[u8]) -> Py<PyBytes> {
        let mut held = self.payloads.lock().unwrap_or_else(|p| p.into_inner());
        if let Some((_, b)) = held.iter().find(|(k, _)| *k == key) {
            return b.clone_ref(py);
        }
        if held.len() >= 2 {
            held.remove(1); // the previous context; the problem stays first
        }
        let made: Py<PyBytes> = PyBytes::new(py, bytes).unbind();
        held.push((key, made.clone_ref(py)));
        made
    }
}

impl Transport for PyTransport {
    fn exchange(&self, requests: Vec<Vec<u8>>, payloads: &Payloads) -> bitrock::Result<Exchanged> {
        let exchanged = Python::attach(|py| -> PyResult<Exchanged> {
            let requests = PyList::new(py, requests.iter().map(|r| PyBytes::new(py, r)))?;
            let problem = self.payload(py, payloads.problem_key, payloads.problem);
            let context = payloads
                .context
                .zip(payloads.context_key)
                .map(|(bytes, key)| self.payload(py, key, bytes));
            let keys = (payloads.problem_key, payloads.context_key);
            let answer = self
                .dispatcher
                .call_method1(py, "exchange", (requests, problem, context, keys))?;
            let (replies, payload_bytes): (Vec<Bound<'_, PyBytes>>, u64) = answer.extract(py)?;
            Ok(Exchanged {
                replies: replies.iter().map(|r| r.as_bytes().to_vec()).collect(),
                payload_bytes,
            })
        });
        exchanged.map_err(|e| {
            *self.raised.lock().unwrap_or_else(|p| p.into_inner()) = Some(e);
            Error::Interrupted
        })
    }

    fn parallelism(&self) -> usize {
        // Asked each round: a Dask cluster may have grown since the last.
        Python::attach(|py| self.dispatcher.getattr(py, "parallelism")?.extract::<usize>(py))
            .unwrap_or(self.parallelism)
    }
}

/// Makes the workers of a run on `dispatcher` once its problem is known, keeping them in
/// `cell` so that their traffic and any Python exception can be read after the run.
#[allow(clippy::needless_lifetimes)] // eliding 'a leaves the boxed workers' lifetime unnamed
fn remote_on<'a>(
    cell: &'a OnceLock<Remote<PyTransport>>,
    dispatcher: Py<PyAny>,
    parallelism: usize,
) -> impl FnMut(bitrock::eval::AbcProblem, &bitrock::run::Config) -> bitrock::Result<Box<dyn Workers + 'a>> {
    let mut transport = Some(PyTransport {
        dispatcher,
        parallelism,
        raised: Mutex::new(None),
        payloads: Mutex::new(Vec::new()),
    });
    move |problem, config| {
        let transport = transport.take().expect("a run makes its workers once");
        let (backend, shape) = (config.backend, bitrock::run::shape_wish(config));
        Ok(Box::new(
            cell.get_or_init(|| Remote::new(problem, backend, shape, transport)),
        ))
    }
}

/// The traffic of a distributed run as JSON, and the Python exception that stopped it.
fn after_remote(cell: OnceLock<Remote<PyTransport>>) -> (Option<String>, Option<PyErr>) {
    match cell.into_inner() {
        None => (None, None),
        Some(remote) => {
            let traffic: Vec<Traffic> = remote.traffic();
            let raised = remote
                .transport()
                .raised
                .lock()
                .unwrap_or_else(|p| p.into_inner())
                .take();
            (
                Some(serde_json::to_string(&traffic).expect("traffic serialises")),
                raised,
            )
        }
    }
}

/// Answers a task on a worker process (see `bitrock::abc::shard::wire`).
#[pyfunction]
#[pyo3(signature = (request, problem=None, context=None))]
fn serve<'py>(py: Python<'py>, request: &[u8], problem: Option<&[u8]>, context: Option<&[u8]>) -> Bound<'py, PyBytes> {
    let reply = py.detach(|| bitrock::abc::worker::serve(request, problem, context));
    PyBytes::new(py, &reply)
}

/// True when a worker's reply asks for the problem and context payloads.
#[pyfunction]
fn needs_payloads(reply: &[u8]) -> bool {
    bitrock::abc::shard::wire::needs_payloads(reply)
}

/// A finished run: its `run.json` document, and the particles of any population.
#[pyclass(frozen, module = "bitrock._bitrock")]
struct Run {
    /// The run.json document.
    #[pyo3(get)]
    summary: String,
    /// The run directory; `None` for a run in memory.
    #[pyo3(get)]
    path: Option<PathBuf>,
    /// Every population of a run in memory (with particles); empty for a stored run, whose
    /// particles are read from its store.
    populations: Vec<Population>,
    torque_unit: TorqueUnit,
    /// Per population of a distributed run: tasks, bytes shipped, seconds waited (JSON).
    #[pyo3(get)]
    traffic: Option<String>,
}

#[pymethods]
impl Run {
    /// The particles of population `g` by law: `{law: (params [n, k] in the record's torque
    /// unit, weights, rho, candidate index)}`.
    fn particles<'py>(&self, py: Python<'py>, g: usize) -> PyResult<Bound<'py, PyDict>> {
        let loaded;
        let particles = match (&self.path, self.populations.get(g)) {
            (_, Some(p)) if !p.particles.is_empty() => &p.particles,
            (Some(dir), _) => {
                loaded = check(py, run::Store::open(dir).and_then(|s| s.load_particles(g)))?;
                &loaded
            }
            (None, _) => {
                return Err(to_py(
                    py,
                    Error::setting("population", format!("the run has no population {g}")),
                ));
            }
        };
        let out = PyDict::new(py);
        let mut laws: Vec<Law> = particles.iter().map(|p| p.law).collect();
        laws.dedup();
        laws.sort_by_key(|l| l.name());
        laws.dedup();
        for law in laws {
            let of_law: Vec<_> = particles.iter().filter(|p| p.law == law).collect();
            let k = law.n_params();
            let flat: Vec<f64> = of_law
                .iter()
                .flat_map(|p| documents::to_record_units(law, &p.params, self.torque_unit))
                .collect();
            let params = PyArray1::from_vec(py, flat).reshape([of_law.len(), k])?;
            let weights = PyArray1::from_vec(py, of_law.iter().map(|p| p.weight).collect());
            let rho = PyArray1::from_vec(py, of_law.iter().map(|p| p.rho).collect());
            let index = PyArray1::from_vec(py, of_law.iter().map(|p| p.index).collect());
            let names = PyList::new(py, law.param_names())?;
            out.set_item(law.name(), (names, params, weights, rho, index))?;
        }
        Ok(out)
    }
}

/// The `Run` of an analysis: its document and, in memory, its populations.
fn run_of(analysis: bitrock::pipeline::Analysis, path: Option<PathBuf>) -> Run {
    let summary = as_arguments(&analysis.json().to_string());
    let torque_unit = analysis.outcome.setup.data.torque_unit;
    let populations = if path.is_some() {
        Vec::new()
    } else {
        analysis.outcome.run.populations
    };
    Run {
        summary,
        path,
        populations,
        torque_unit,
        traffic: None,
    }
}

/// Runs the ABC job on `record` with the settings in `settings` (keyword arguments of
/// `bitrock.abc`), into `out` when given.
#[pyfunction]
#[pyo3(signature = (record, settings, out, force, progress, note, dispatcher=None, parallelism=1))]
#[allow(clippy::too_many_arguments)] // the Python layer's keyword arguments, passed through
fn abc(
    py: Python<'_>,
    record: &Record,
    settings: &Bound<'_, PyDict>,
    out: Option<PathBuf>,
    force: bool,
    progress: Option<Py<PyAny>>,
    note: Option<Py<PyAny>>,
    dispatcher: Option<Py<PyAny>>,
    parallelism: usize,
) -> PyResult<Run> {
    let s = run_settings(py, settings)?;
    let config = check(py, s.config())?;
    let job = AbcJob {
        config,
        summary_population: None,
        out: out.clone().map(|path| run::Dir { path, replace: force }),
    };
    let mut observer = PyObserver {
        progress,
        note,
        raised: None,
    };
    let data = record.data.clone();
    let cell = OnceLock::new();
    let result = match dispatcher {
        None => py.detach(|| job.run(data, &mut observer)),
        Some(dispatcher) => {
            let mut make = remote_on(&cell, dispatcher, parallelism);
            py.detach(|| {
                job.run_on(
                    data,
                    Some(&mut |problem, config, _note| make(problem, config)),
                    &mut observer,
                )
            })
        }
    };
    finish_run(py, result, observer, cell, out)
}

/// The `Run` of a finished job, or the exception that stopped it (a callback's or the
/// workers' before the library's own).
fn finish_run(
    py: Python<'_>,
    result: bitrock::Result<bitrock::pipeline::Analysis>,
    mut observer: PyObserver,
    cell: OnceLock<Remote<PyTransport>>,
    path: Option<PathBuf>,
) -> PyResult<Run> {
    let (traffic, raised) = after_remote(cell);
    if let Some(e) = raised.or_else(|| observer.raised.take()) {
        return Err(e);
    }
    let analysis = check(py, result)?;
    let mut run = run_of(analysis, path);
    run.traffic = traffic;
    Ok(run)
}

/// Continues the run in `path` with the stopping rules in `more`.
#[pyfunction]
#[pyo3(signature = (path, more, progress, note, dispatcher=None, parallelism=1))]
fn resume(
    py: Python<'_>,
    path: PathBuf,
    more: &Bound<'_, PyDict>,
    progress: Option<Py<PyAny>>,
    note: Option<Py<PyAny>>,
    dispatcher: Option<Py<PyAny>>,
    parallelism: usize,
) -> PyResult<Run> {
    let continuation = Continuation {
        eps_min: kwarg(more, "eps_min")?,
        max_populations: kwarg(more, "max_populations")?,
        max_draws: kwarg(more, "max_draws")?,
        min_acceptance: kwarg(more, "min_acceptance")?,
        max_seconds: kwarg(more, "max_seconds")?,
        backend: named::<Backend>(py, "backend", kwarg(more, "backend")?)?,
        devices: named(py, "devices", kwarg(more, "devices")?)?,
        summary_population: None,
    };
    let mut observer = PyObserver {
        progress,
        note,
        raised: None,
    };
    let cell = OnceLock::new();
    let result = match dispatcher {
        None => py.detach(|| bitrock::pipeline::resume(&path, &continuation, &mut observer)),
        Some(dispatcher) => {
            let mut make = remote_on(&cell, dispatcher, parallelism);
            py.detach(|| {
                bitrock::pipeline::resume_on(
                    &path,
                    &continuation,
                    Some(&mut |problem, config: &bitrock::run::Config, _note| make(problem, config)),
                    &mut observer,
                )
            })
        }
    };
    finish_run(py, result, observer, cell, Some(path))
}

/// Opens the finished run in `path`: its run.json and its store.
#[pyfunction]
fn open_run(py: Python<'_>, path: PathBuf) -> PyResult<Run> {
    let summary = as_arguments(&check(py, read_summary(&path))?);
    let store = check(py, run::Store::open(&path).and_then(|s| s.load()))?;
    Ok(Run {
        summary,
        path: Some(path),
        populations: Vec::new(),
        torque_unit: store.setup.data.torque_unit,
        traffic: None,
    })
}

/// The run.json of a run directory; a run stopped before its end has none, and is refused
/// saying how to continue it.
fn read_summary(dir: &Path) -> bitrock::Result<String> {
    let path = dir.join(bitrock::run::dir::RUN_JSON);
    match std::fs::read_to_string(&path) {
        Err(e)
            if e.kind() == std::io::ErrorKind::NotFound
                && let Some(holder) = bitrock::files::DirLock::holder(dir) =>
        {
            Err(Error::Data {
                path: dir.to_path_buf(),
                message: format!(
                    "the run is being written by {holder} and has no run.json yet: open it once its first population is stored"
                ),
            })
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound && run::Store::open(dir).is_ok() => Err(Error::Data {
            path: dir.to_path_buf(),
            message:
                "the run was stopped before it finished (it has no run.json yet): continue it with `bitrock.resume`"
                    .into(),
        }),
        result => result.map_err(|source| Error::Read { path, source }),
    }
}

/// The run settings from `bitrock.abc`'s keyword arguments.
fn run_settings(py: Python<'_>, kw: &Bound<'_, PyDict>) -> PyResult<Settings> {
    let text = |key: &str| kwarg::<String>(kw, key);
    Ok(Settings {
        laws: laws(py, kwarg(kw, "laws")?)?,
        fit: fit_options(py, kw)?,
        sampler: named(py, "sampler", text("sampler")?)?.unwrap_or_default(),
        particles: kwarg(kw, "particles")?,
        delta: kwarg(kw, "delta")?,
        prior_rule: named(py, "prior_rule", text("prior_rule")?)?.unwrap_or_default(),
        prior_k: kwarg(kw, "prior_k")?,
        prior_file: kwarg(kw, "prior_file")?,
        eps_min: kwarg(kw, "eps_min")?,
        epsilons: kwarg(kw, "epsilons")?,
        start_epsilon: kwarg(kw, "start_epsilon")?,
        max_populations: kwarg(kw, "max_populations")?,
        max_draws: kwarg(kw, "max_draws")?,
        min_acceptance: kwarg(kw, "min_acceptance")?,
        max_seconds: kwarg(kw, "max_seconds")?,
        mode: named(py, "mode", text("mode")?)?,
        p_stay: kwarg(kw, "p_stay")?,
        kernel_scale: kwarg(kw, "kernel_scale")?,
        smc_weights: named(py, "smc_weights", text("smc_weights")?)?,
        refill: named(py, "refill", text("refill")?)?,
        law_proposal: named(py, "law_proposal", text("law_proposal")?)?,
        perturbation: named(py, "perturbation", text("perturbation")?)?,
        seed: kwarg(kw, "seed")?,
        backend: named(py, "backend", text("backend")?)?,
        devices: named(py, "devices", text("devices")?)?,
    })
}

/// Stability maps over (Ω, W) for the run in `run`, or for `law` at `params` (torques in
/// `torque_unit`): a dict of NumPy arrays the Python layer makes a Dataset of.
#[pyfunction]
#[pyo3(signature = (run, law, params, options, note))]
fn stability<'py>(
    py: Python<'py>,
    run: Option<PathBuf>,
    law: Option<String>,
    params: Option<Vec<f64>>,
    options: &Bound<'py, PyDict>,
    note: Option<Py<PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    use bitrock::pipeline::stability::{self as job, MapSource, StabilityJob, Structure};
    use bitrock::stability::{fe::DrillStringSettings, lumped::Lumped, map};
    let source = match (run, law, params) {
        (Some(dir), None, None) => MapSource::Run(dir),
        (None, Some(law), Some(params)) => {
            let law = self::laws(py, Some(vec![law]))?.expect("one law")[0];
            let unit = unit(
                py,
                "torque_unit",
                kwarg(options, "torque_unit")?,
                TorqueUnit::from_suffix,
            )?;
            check(py, MapSource::law(law, &params, unit.unwrap_or(TorqueUnit::KNm)))?
        }
        _ => {
            return Err(to_py(
                py,
                Error::setting(
                    "source",
                    "give a run (a Result or its directory) or a law with its params",
                ),
            ));
        }
    };
    // An axis: values, or "MIN:MAX:COUNT" as on the command line.
    let axis = |key: &str, default: &str| -> PyResult<Vec<f64>> {
        match options.get_item(key)?.filter(|v| !v.is_none()) {
            None => check(py, map::parse_axis(default, key)),
            Some(value) => match value.extract::<String>() {
                Ok(text) => check(py, map::parse_axis(&text, key)),
                Err(_) => value.extract(),
            },
        }
    };
    let lumped_defaults = Lumped::default();
    let lumped = Lumped {
        inertia_kg_m2: kwarg(options, "inertia_kg_m2")?.unwrap_or(lumped_defaults.inertia_kg_m2),
        omega_n_rad_s: kwarg(options, "omega_n_rad_s")?.unwrap_or(lumped_defaults.omega_n_rad_s),
        damping_ratio: kwarg(options, "damping_ratio")?.unwrap_or(lumped_defaults.damping_ratio),
    };
    let fe = DrillStringSettings {
        fe_file: kwarg(options, "fe_file")?,
        dp_elements: kwarg(options, "dp_elements")?,
        bha_elements: kwarg(options, "bha_elements")?,
        alpha: kwarg(options, "alpha")?,
        beta: kwarg(options, "beta")?,
    };
    let structure: Structure = named(py, "structure", kwarg(options, "structure")?)?.unwrap_or_default();
    let job = StabilityJob {
        source,
        omega_rpm: axis("omega_rpm", job::DEFAULT_OMEGA_RPM)?,
        wob_kn: axis("wob_kn", job::DEFAULT_WOB_KN)?,
        criterion: map::Criterion::Lumped(lumped),
        w_ref_n: kwarg::<f64>(options, "w_ref_kn")?.map_or(bitrock::laws::PAPER_W_REF_N, |kn| kn * 1000.0),
        percentile: kwarg::<f64>(options, "percentile")?.unwrap_or(job::DEFAULT_PERCENT) / 100.0,
        samples: kwarg(options, "samples")?.unwrap_or(job::DEFAULT_SAMPLES),
        backend: named(py, "backend", kwarg(options, "backend")?)?.unwrap_or_default(),
    };
    let mut notes = Vec::new();
    let maps = py.detach(|| {
        let job = job.on(structure, lumped, &fe)?;
        let maps = job.run(&mut |line| notes.push(line))?;
        Ok::<_, Error>((job, maps))
    });
    let (job, maps) = check(py, maps)?;
    if let Some(callback) = &note {
        for line in notes.into_iter().chain(maps.early_end.clone()) {
            callback.call1(py, (as_arguments(&line),))?;
        }
    }
    let nan = |v: &Option<f64>| v.unwrap_or(f64::NAN);
    let (n_omega, n_wob) = (job.omega_rpm.len(), job.wob_kn.len());
    let out = PyDict::new(py);
    out.set_item("laws", maps.inputs.iter().map(|i| i.law.name()).collect::<Vec<_>>())?;
    out.set_item(
        "probability",
        maps.inputs.iter().map(|i| i.probability).collect::<Vec<_>>(),
    )?;
    out.set_item(
        "samples",
        maps.inputs.iter().map(|i| i.samples_si.len()).collect::<Vec<_>>(),
    )?;
    out.set_item("omega_rpm", PyArray1::from_slice(py, &job.omega_rpm))?;
    out.set_item("wob_kn", PyArray1::from_slice(py, &job.wob_kn))?;
    let grids: Vec<f64> = maps.grids.concat();
    out.set_item(
        "probability_unstable",
        PyArray1::from_vec(py, grids).reshape([maps.inputs.len(), n_omega, n_wob])?,
    )?;
    let boundary = |pick: fn(&map::LawBoundaries) -> &Vec<Option<f64>>| -> PyResult<_> {
        let flat: Vec<f64> = maps
            .boundaries
            .laws
            .iter()
            .flat_map(|b| pick(b).iter().map(nan))
            .collect();
        PyArray1::from_vec(py, flat).reshape([maps.inputs.len(), n_omega])
    };
    out.set_item("map_wob_kn", boundary(|b| &b.map_wob_kn)?)?;
    out.set_item("p_wob_kn", boundary(|b| &b.p_wob_kn)?)?;
    if let Some(mixture) = &maps.boundaries.mixture_wob_kn {
        out.set_item(
            "mixture_p_wob_kn",
            PyArray1::from_vec(py, mixture.iter().map(nan).collect()),
        )?;
    }
    out.set_item("critical_bit_damping_nms", job.criterion.critical_nms())?;
    out.set_item("percentile", job.percentile * 100.0)?;
    out.set_item(
        "structure",
        serde_json::to_value(structure)
            .ok()
            .and_then(|v| v.as_str().map(String::from)),
    )?;
    Ok(out)
}

/// Checks the selection of the run in `run` by re-simulation, writes it into the run's
/// `selection/` (as `bitrock check-selection` does) and returns its document.
#[pyfunction]
#[pyo3(signature = (run, options, progress, note))]
fn check_selection(
    py: Python<'_>,
    run: PathBuf,
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
    let mut notes = Vec::new();
    let checked = py.detach(|| {
        let checked = CheckedRun::open(&run)?;
        notes.extend(bitrock::run::Store::open(&run)?.early_end()?);
        let check = selection::check(&checked, &options, &report, &mut |line| notes.push(line))?;
        bitrock::report::write_selection(&checked, &check)?;
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

/// Simulates the 1-DOF string with `law` at top-drive speed `omega_rpm`: the record as
/// `bitrock simulate` writes it (CSV text, torques in kN·m).
#[pyfunction]
#[pyo3(signature = (law, params, omega_rpm, options))]
fn simulate(
    py: Python<'_>,
    law: String,
    params: Option<Vec<f64>>,
    omega_rpm: f64,
    options: &Bound<'_, PyDict>,
) -> PyResult<String> {
    use bitrock::simulate::{self as sim, Initial, SimConfig};
    use bitrock::units::RAD_S_PER_RPM;
    let law = self::laws(py, Some(vec![law]))?.expect("one law")[0];
    let unit = unit(
        py,
        "param_torque_unit",
        kwarg(options, "param_torque_unit")?,
        TorqueUnit::from_suffix,
    )?
    .unwrap_or(TorqueUnit::KNm);
    let params_nm = match params {
        Some(params) => {
            // The count first: scaling takes one value per parameter.
            if params.len() != law.n_params() {
                check(py, law.check_params(&params, "params"))?;
            }
            law.scale_torque(&params, unit.newton_metres())
        }
        None => match law.paper_estimate() {
            Some(p) => law.scale_torque(p, TorqueUnit::KNm.newton_metres()),
            None => {
                let message = format!("law {law} has no reference values to default to; give its parameters");
                return Err(to_py(py, bitrock::Error::setting("params", message)));
            }
        },
    };
    let mut c = SimConfig::new(law, params_nm, omega_rpm * RAD_S_PER_RPM, bitrock::laws::PAPER_W_REF_N);
    let kn = |key: &str| -> PyResult<Option<f64>> { Ok(kwarg::<f64>(options, key)?.map(|v| v * 1000.0)) };
    c.wob_n = kn("wob_kn")?.unwrap_or(c.wob_n);
    c.w_ref_n = kn("w_ref_kn")?.unwrap_or(c.w_ref_n);
    c.structure.inertia_kg_m2 = kwarg(options, "inertia_kg_m2")?.unwrap_or(c.structure.inertia_kg_m2);
    c.structure.omega_n_rad_s = kwarg(options, "omega_n_rad_s")?.unwrap_or(c.structure.omega_n_rad_s);
    c.structure.damping_ratio = kwarg(options, "damping_ratio")?.unwrap_or(c.structure.damping_ratio);
    c.duration_s = kwarg(options, "duration_s")?.unwrap_or(c.duration_s);
    c.settle_s = kwarg(options, "settle_s")?.unwrap_or(c.settle_s);
    c.sample_hz = kwarg(options, "sample_hz")?.unwrap_or(c.sample_hz);
    c.dt_s = kwarg(options, "dt_s")?.unwrap_or(c.dt_s);
    let kick_rpm = kwarg(options, "kick_rpm")?.unwrap_or(sim::DEFAULT_KICK_RPM);
    c.initial = match kwarg::<String>(options, "initial")?
        .as_deref()
        .map(str::to_lowercase)
        .as_deref()
    {
        None | Some("equilibrium") => Initial::Equilibrium {
            speed_perturbation_rad_s: kick_rpm * RAD_S_PER_RPM,
        },
        Some("rest") => Initial::Rest,
        Some(other) => {
            return Err(to_py(
                py,
                Error::setting("initial", format!("`{other}` is not one of equilibrium, rest")),
            ));
        }
    };
    c.noise_torque_nm = kn("noise_torque_knm")?.unwrap_or(c.noise_torque_nm);
    c.noise_speed_rad_s = kwarg::<f64>(options, "noise_speed_rpm")?.map_or(c.noise_speed_rad_s, |v| v * RAD_S_PER_RPM);
    c.wob_fluctuation_n = kn("wob_fluctuation_kn")?.unwrap_or(c.wob_fluctuation_n);
    c.wob_correlation_s = kwarg(options, "wob_correlation_s")?.unwrap_or(c.wob_correlation_s);
    c.seed = kwarg(options, "seed")?.unwrap_or(sim::DEFAULT_SEED);
    let text = py.detach(|| {
        c.validate()?;
        let trace = sim::simulate(&c)?;
        let mut text = Vec::new();
        sim::write_csv(&trace, &mut text).map_err(|e| Error::Numerical(e.to_string()))?;
        Ok::<_, Error>(String::from_utf8(text).expect("the CSV is ASCII"))
    });
    check(py, text)
}

/// CPU-vs-GPU parity on `record` (`None`: the embedded demo record): `bitrock parity`'s
/// report as JSON text.
#[pyfunction]
#[pyo3(signature = (record, laws, options))]
fn parity(
    py: Python<'_>,
    record: Option<&Record>,
    laws: Option<Vec<String>>,
    options: &Bound<'_, PyDict>,
) -> PyResult<String> {
    use bitrock::bench;
    let laws = self::laws(py, laws)?.unwrap_or_else(|| Law::ALL.to_vec());
    let candidates = kwarg(options, "candidates")?.unwrap_or(bench::PARITY_CANDIDATES);
    let epsilon = kwarg(options, "epsilon")?;
    let seed = kwarg(options, "seed")?.unwrap_or(bench::PARITY_SEED);
    let report = py.detach(|| {
        let demo;
        let data = match record {
            Some(r) => &r.data,
            None => {
                demo = bitrock::data::demo_field_data(&DataOptions::default())?;
                &demo
            }
        };
        bench::parity_on(data, &laws, candidates, epsilon, seed)
    });
    let report = check(py, report)?;
    serde_json::to_string(&report).map_err(|e| to_py(py, Error::Numerical(e.to_string())))
}

/// Reads, compiles and registers the law file at `path`; its law's name, for `laws=` and
/// `law=` everywhere in this process.
#[pyfunction]
fn load_law(py: Python<'_>, path: std::path::PathBuf) -> PyResult<String> {
    let law = check(py, bitrock::laws::file::load_and_register(&path))?;
    Ok(law.name().to_string())
}

/// The library's version.
#[pyfunction]
fn version() -> &'static str {
    env!("CARGO_PKG_VERSION")
}

#[pymodule]
fn _bitrock(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Record>()?;
    m.add_class::<Run>()?;
    m.add_function(wrap_pyfunction!(read_csv, m)?)?;
    m.add_function(wrap_pyfunction!(read_columns, m)?)?;
    m.add_function(wrap_pyfunction!(fit, m)?)?;
    m.add_function(wrap_pyfunction!(abc, m)?)?;
    m.add_function(wrap_pyfunction!(resume, m)?)?;
    m.add_function(wrap_pyfunction!(open_run, m)?)?;
    m.add_function(wrap_pyfunction!(stability, m)?)?;
    m.add_function(wrap_pyfunction!(check_selection, m)?)?;
    m.add_function(wrap_pyfunction!(simulate, m)?)?;
    m.add_function(wrap_pyfunction!(parity, m)?)?;
    m.add_function(wrap_pyfunction!(version, m)?)?;
    m.add_function(wrap_pyfunction!(load_law, m)?)?;
    m.add_function(wrap_pyfunction!(serve, m)?)?;
    m.add_function(wrap_pyfunction!(needs_payloads, m)?)?;
    Ok(())
}
