//! Runs: started, resumed or opened, their progress reported to Python, their populations
//! and summaries handed back.

use crate::distributed::*;
use crate::errors::*;
use crate::fit::*;
use crate::record::*;
use bitrock::abc::shard::Remote;
use bitrock::abc::{Observer, Population, Progress};
use bitrock::error::Error;
use bitrock::eval::Backend;
use bitrock::run;
use bitrock::run::abc::{Continuation, Settings};
use bitrock::run::{Placement, Scoring};
use bitrock::units::TorqueUnit;
use bitrock::{Law, documents};
use numpy::{PyArray1, PyArrayMethods};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// Watches a run for Python: progress to a callable, notes to `warnings`-like callable, and
/// Ctrl-C (checked after every batch) stops it.
pub(crate) struct PyObserver {
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
        if self.raised.is_none() {
            Python::attach(|py| {
                if let Err(e) = py.check_signals() {
                    self.raised = Some(e);
                }
            });
        }
        self.raised.is_some()
    }
}

impl PyObserver {
    /// An observer with a progress callable and a note callable (either may be absent).
    pub(crate) fn new(progress: Option<Py<PyAny>>, note: Option<Py<PyAny>>) -> Self {
        Self {
            progress,
            note,
            raised: None,
        }
    }

    /// The Python exception a callback or a signal raised, if any: it stops the work.
    pub(crate) fn take_raised(&mut self) -> Option<PyErr> {
        self.raised.take()
    }
}

/// A finished run: its `run.json` document, and the particles of any population.
#[pyclass(frozen, module = "bitrock._bitrock")]
#[derive(serde::Serialize, serde::Deserialize)]
pub(crate) struct Run {
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
    /// A run in memory's set-up and ending, from which it can be written to a directory or
    /// checked; `None` for a stored run.
    #[serde(default)]
    kept: Option<Kept>,
}

/// What a run in memory keeps besides its populations, so that it can become the run
/// directory `bitrock abc --out` would have written, or be checked by re-simulation.
#[derive(serde::Serialize, serde::Deserialize)]
struct Kept {
    setup: run::abc::Setup,
    stop: bitrock::abc::StopReason,
    evaluations: u64,
    seconds: f64,
    /// The backend that scored (`cpu`, `gpu`, `cpu+gpu`).
    backend: String,
    summary_population: usize,
}

impl Kept {
    /// The outcome this run in memory was: its configuration, set-up and `populations`.
    fn outcome(&self, populations: Vec<Population>) -> bitrock::Result<run::abc::Outcome> {
        let config: run::abc::Config = serde_json::from_value(self.setup.config.clone())
            .map_err(|e| Error::setting("result", format!("the run's configuration cannot be read: {e}")))?;
        let backend = ["cpu", "gpu", "cpu+gpu"]
            .into_iter()
            .find(|b| *b == self.backend)
            .unwrap_or("cpu");
        Ok(run::abc::Outcome {
            config,
            setup: self.setup.clone(),
            added: populations.len(),
            run: bitrock::abc::Run {
                populations,
                stop: self.stop,
                evaluations: self.evaluations,
                seconds: self.seconds,
            },
            backend,
            lock: None,
        })
    }
}

#[pymethods]
impl Run {
    /// Pickling: the document, the directory, and a run in memory's populations with their
    /// particles, as JSON exact to the bit; rebuilt by [`Run::_from_state`].
    fn __reduce__<'py>(slf: &Bound<'py, Self>) -> PyResult<(Bound<'py, PyAny>, (String,))> {
        crate::errors::reduce_to_json(slf.as_any(), slf.get(), "run")
    }
    /// The run a pickle's state describes.
    #[staticmethod]
    fn _from_state(py: Python<'_>, state: &str) -> PyResult<Self> {
        crate::errors::from_json_state(py, state, "result", "run")
    }
    /// Writes a run kept in memory to the run directory `path` (`force` replaces a run
    /// there), as `bitrock abc --out` would have written it, and returns the stored run.
    fn save(&self, py: Python<'_>, path: PathBuf, force: bool) -> PyResult<Run> {
        let Some(kept) = &self.kept else {
            let at = self
                .path
                .as_deref()
                .map(|p| p.display().to_string())
                .unwrap_or_default();
            return Err(to_py(
                py,
                Error::setting("result", format!("the run is stored already, in {at}")),
            ));
        };
        let dir = run::Dir {
            path: path.clone(),
            replace: force,
        };
        let populations = self.populations.clone();
        let analysis = py.detach(|| {
            let outcome = kept.outcome(populations)?;
            let analysis = bitrock::run::abc::Analysis::new(outcome, Some(kept.summary_population), None)?;
            analysis.save(&dir)?;
            Ok::<_, Error>(analysis)
        });
        Ok(run_of(check(py, analysis)?, Some(path)))
    }

    /// The record the run was made from (its calibration and validation samples as the run
    /// used them).
    fn record(&self, py: Python<'_>) -> PyResult<Record> {
        let data = match (&self.kept, &self.path) {
            (Some(kept), _) => kept.setup.data.clone(),
            (None, Some(dir)) => check(py, run::abc::Store::open(dir).and_then(|s| s.load()))?.setup.data,
            (None, None) => return Err(to_py(py, Error::setting("result", "the result holds no run"))),
        };
        Ok(Record { data })
    }

    /// The particles of population `g` by law: `{law: (params [n, k] in the record's torque
    /// unit, weights, rho, candidate index)}`.
    fn particles<'py>(&self, py: Python<'py>, g: usize) -> PyResult<Bound<'py, PyDict>> {
        let particles = self.population_particles(py, g)?;
        let particles = particles.as_ref();
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

    /// The `level` posterior predictive band of every law with particles in population `g` at
    /// the bit speeds `speed_rad_s` and weight-on-bit ratio `r`: `{law: (lower, median,
    /// upper)}` in the record's torque unit, pointwise quantiles as the run's envelopes.
    fn predictive<'py>(
        &self,
        py: Python<'py>,
        g: usize,
        speed_rad_s: Vec<f64>,
        level: f64,
        r: f64,
    ) -> PyResult<Bound<'py, PyDict>> {
        if !(level > 0.0 && level < 1.0) {
            return Err(to_py(
                py,
                Error::setting("level", format!("must lie in (0, 1), got {level}")),
            ));
        }
        if !(r.is_finite() && r > 0.0) {
            return Err(to_py(
                py,
                Error::setting("r", format!("must be a positive number, got {r}")),
            ));
        }
        if let Some(w) = speed_rad_s.iter().find(|w| !w.is_finite()) {
            return Err(to_py(
                py,
                Error::setting("speed_rad_s", format!("must be finite numbers, got {w}")),
            ));
        }
        let particles = self.population_particles(py, g)?;
        let particles = particles.as_ref();
        let mut laws: Vec<Law> = particles.iter().map(|p| p.law).collect();
        laws.sort_by_key(|l| l.name());
        laws.dedup();
        let scale = self.torque_unit.newton_metres();
        let out = PyDict::new(py);
        for law in laws {
            let envelope = py
                .detach(|| bitrock::abc::posterior::predictive_envelope(particles, law, &speed_rad_s, level, r))
                .expect("the law has particles");
            let in_unit = |v: &[f64]| v.iter().map(|t| t / scale).collect::<Vec<f64>>();
            out.set_item(
                law.name(),
                (
                    PyArray1::from_vec(py, in_unit(&envelope.lower)),
                    PyArray1::from_vec(py, in_unit(&envelope.median)),
                    PyArray1::from_vec(py, in_unit(&envelope.upper)),
                ),
            )?;
        }
        Ok(out)
    }
}

impl Run {
    /// A run kept in memory as its configuration and store would read it back (every
    /// population with its particles); `None` for a stored run.
    pub(crate) fn in_memory(&self) -> Option<bitrock::Result<(run::abc::Config, run::abc::Stored)>> {
        let kept = self.kept.as_ref()?;
        Some(kept.outcome(Vec::new()).map(|outcome| {
            (
                outcome.config,
                run::abc::Stored {
                    setup: kept.setup.clone(),
                    populations: self.populations.clone(),
                },
            )
        }))
    }

    /// The last population's particles of a run kept in memory; `None` for a stored run (whose
    /// store the caller reads) or a run without a population.
    pub(crate) fn last_particles_in_memory(&self) -> Option<&[bitrock::abc::Particle]> {
        self.populations
            .last()
            .map(|p| p.particles.as_slice())
            .filter(|p| !p.is_empty())
    }

    /// What a run kept in memory's record showed of its bit, and the W_ref (N) its parameters
    /// are for where its fit scaled each torque by WOB / W_ref; `None` for a stored run (whose
    /// store the caller reads).
    pub(crate) fn record_in_memory(&self) -> Option<(Option<bitrock::data::BitSeen>, Option<f64>)> {
        let setup = &self.kept.as_ref()?.setup;
        let w_ref_n = serde_json::from_value::<run::abc::Config>(setup.config.clone())
            .ok()
            .and_then(|c| c.fit.w_ref_n);
        Some((setup.data.bit, w_ref_n))
    }

    /// The drill string a run kept in memory was made with, where it was given one.
    pub(crate) fn string_in_memory(&self) -> Option<bitrock::run::stability::DrillStringSpec> {
        let setup = &self.kept.as_ref()?.setup;
        serde_json::from_value::<run::abc::Config>(setup.config.clone())
            .ok()?
            .string
    }

    /// Population `g`'s particles: held in memory, or read from the store.
    fn population_particles(
        &self,
        py: Python<'_>,
        g: usize,
    ) -> PyResult<std::borrow::Cow<'_, [bitrock::abc::Particle]>> {
        match (&self.path, self.populations.get(g)) {
            (_, Some(p)) if !p.particles.is_empty() => Ok(std::borrow::Cow::Borrowed(&p.particles)),
            (Some(dir), _) => Ok(std::borrow::Cow::Owned(check(
                py,
                run::abc::Store::open(dir).and_then(|s| s.load_particles(g)),
            )?)),
            (None, _) => Err(to_py(
                py,
                Error::setting("population", format!("the run has no population {g}")),
            )),
        }
    }
}

/// The `Run` of an analysis: its document and, in memory, its populations.
pub(crate) fn run_of(analysis: bitrock::run::abc::Analysis, path: Option<PathBuf>) -> Run {
    let summary = as_arguments(&analysis.json().to_string());
    let torque_unit = analysis.outcome.setup.data.torque_unit;
    let (populations, kept) = if path.is_some() {
        (Vec::new(), None)
    } else {
        let outcome = analysis.outcome;
        let kept = Kept {
            setup: outcome.setup,
            stop: outcome.run.stop,
            evaluations: outcome.run.evaluations,
            seconds: outcome.run.seconds,
            backend: outcome.backend.to_string(),
            summary_population: analysis.summary_population,
        };
        (outcome.run.populations, Some(kept))
    };
    Run {
        summary,
        path,
        populations,
        torque_unit,
        traffic: None,
        kept,
    }
}

/// Runs the ABC job on `record` with the settings in `settings` (keyword arguments of
/// `bitrock.abc`), into `out` when given.
#[pyfunction]
#[pyo3(signature = (record, settings, out, force, progress, note, dispatcher=None, parallelism=1))]
#[allow(clippy::too_many_arguments)] // the Python layer's keyword arguments, passed through
pub(crate) fn abc(
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
    let config = run_config(py, settings)?;
    let job = run::abc::Job {
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
        None => py.detach(|| job.run(data, Scoring::Here, &mut observer)),
        Some(dispatcher) => {
            let mut make = remote_on(&cell, dispatcher, parallelism);
            let mut workers = |problem, placement: &Placement, _note: &mut dyn FnMut(String)| make(problem, placement);
            py.detach(|| job.run(data, Scoring::Workers(&mut workers), &mut observer))
        }
    };
    finish_run(py, result, observer, cell, out)
}

/// The `Run` of a finished job, or the exception that stopped it (a callback's or the
/// workers' before the library's own).
pub(crate) fn finish_run(
    py: Python<'_>,
    result: bitrock::Result<bitrock::run::abc::Analysis>,
    mut observer: PyObserver,
    cell: OnceLock<Remote<PyTransport>>,
    path: Option<PathBuf>,
) -> PyResult<Run> {
    let (traffic, raised) = after_remote(cell);
    if let Some(e) = raised.or_else(|| observer.raised.take()) {
        return Err(e);
    }
    let analysis = check(py, result)?;
    // What the command says after a run's tables, said as Python's warnings (the record's
    // own were said when it was read).
    for warning in analysis.run_warnings() {
        observer.note(warning);
    }
    if let Some(e) = observer.raised.take() {
        return Err(e);
    }
    let mut run = run_of(analysis, path);
    run.traffic = traffic;
    Ok(run)
}

/// Continues the run in `path` with the stopping rules in `more`.
#[pyfunction]
#[pyo3(signature = (path, more, progress, note, dispatcher=None, parallelism=1))]
pub(crate) fn resume(
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
        None => py.detach(|| bitrock::run::abc::resume(&path, &continuation, Scoring::Here, &mut observer)),
        Some(dispatcher) => {
            let mut make = remote_on(&cell, dispatcher, parallelism);
            let mut workers = |problem, placement: &Placement, _note: &mut dyn FnMut(String)| make(problem, placement);
            py.detach(|| bitrock::run::abc::resume(&path, &continuation, Scoring::Workers(&mut workers), &mut observer))
        }
    };
    finish_run(py, result, observer, cell, Some(path))
}

/// Opens the finished run in `path`: its run.json and its store.
#[pyfunction]
pub(crate) fn open_run(py: Python<'_>, path: PathBuf) -> PyResult<Run> {
    check(py, run::dir::refuse_unfinished_evidence(&path))?;
    let summary = as_arguments(&check(py, read_summary(&path))?);
    let store = check(py, run::abc::Store::open(&path).and_then(|s| s.load()))?;
    Ok(Run {
        summary,
        path: Some(path),
        populations: Vec::new(),
        torque_unit: store.setup.data.torque_unit,
        traffic: None,
        kept: None,
    })
}

/// The run.json of a run directory; a run stopped before its end has none, and is refused
/// saying how to continue it.
pub(crate) fn read_summary(dir: &Path) -> bitrock::Result<String> {
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
        Err(e) if e.kind() == std::io::ErrorKind::NotFound && run::abc::Store::open(dir).is_ok() => Err(Error::Data {
            path: dir.to_path_buf(),
            message:
                "the run was stopped before it finished (it has no run.json yet): continue it with `bitrock.resume`"
                    .into(),
        }),
        result => result.map_err(|source| Error::Read { path, source }),
    }
}

/// The run's configuration from `bitrock.abc`'s keyword arguments: its settings through the
/// library's gate, with the laws and the least squares' options.
pub(crate) fn run_config(py: Python<'_>, kw: &Bound<'_, PyDict>) -> PyResult<run::abc::Config> {
    let settings: Settings = crate::errors::settings(kw)?;
    let laws = laws(py, kwarg(kw, "laws")?)?;
    let config = check(py, settings.config(laws, fit_options(py, kw)?))?;
    let string = check(py, crate::stability::string_given(py, kw)?.spec())?;
    Ok(run::abc::Config { string, ..config })
}
