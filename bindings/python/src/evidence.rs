//! The model evidence of a record's laws.

use crate::distributed::{PyTransport, remote_each};
use crate::errors::*;
use crate::fit::fit_options;
use crate::record::*;
use crate::run::PyObserver;
use bitrock::Law;
use bitrock::data::FieldData;
use bitrock::error::Error;
use bitrock::run::evidence::EvidenceAnalysis;
use bitrock::run::evidence::dir::{self, Unfinished};
use bitrock::run::evidence::{Progress, check as check_evidence, check_size, replicates_asked};
use bitrock::run::{self, MakeWorkers, Placement, Scoring};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::PathBuf;

/// The evidence of `laws` (`None`: all four) on the record, with the options of
/// `bitrock.evidence`: `bitrock evidence --json`'s document, with each law's posterior sets
/// (`"posterior": {"params": [[...]], "weights": [...], "island": [...]}`, the record's torque
/// unit) added, kept whole so that it can be saved as an evidence directory later. With
/// a `dispatcher` (`bitrock._distributed.Dispatcher`), the samplers' candidates are scored by
/// its workers, `parallelism` tasks a batch unless it says otherwise.
#[pyfunction]
#[pyo3(signature = (record, laws, options, note, dispatcher=None, parallelism=1))]
pub(crate) fn evidence(
    py: Python<'_>,
    record: &Record,
    laws: Option<Vec<String>>,
    options: &Bound<'_, PyDict>,
    note: Option<Py<PyAny>>,
    dispatcher: Option<Py<PyAny>>,
    parallelism: usize,
) -> PyResult<ComputedEvidence> {
    let laws = self::laws(py, laws)?.unwrap_or_else(|| Law::ALL.to_vec());
    let settings: run::evidence::Settings = crate::errors::settings(options)?;
    let mut job = check(py, settings.job(laws, fit_options(py, options)?))?;
    job.string = check(py, crate::stability::string_given(py, options)?.spec())?;
    let replicates = replicates_asked(kwarg(options, "check")?, job.laws.len());
    let out: Option<PathBuf> = kwarg(options, "out")?;
    let force: bool = kwarg(options, "force")?.unwrap_or(false);
    let data = &record.data;
    if let Some(k) = replicates {
        check(py, check_size(k, "check", &job, data))?;
    }
    let unfinished = match &out {
        None => None,
        Some(dir) => Some(check(py, py.detach(|| Unfinished::start(dir, force, &job, data)))?),
    };
    let workers = Workers {
        dispatcher,
        parallelism,
    };
    compute(
        py,
        &job,
        data,
        unfinished,
        Progress::default(),
        replicates,
        workers,
        note,
    )
}

/// Continues the evidence under way in `dir` (on `backend`, default its own), checks it with
/// `check` replicates per law (by default the small check; 0 none), and writes the directory:
/// the document, as [`evidence`] returns it.
#[pyfunction]
#[pyo3(signature = (dir, backend, check, note, dispatcher=None, parallelism=1))]
pub(crate) fn resume_evidence(
    py: Python<'_>,
    dir: PathBuf,
    backend: Option<String>,
    check: Option<usize>,
    note: Option<Py<PyAny>>,
    dispatcher: Option<Py<PyAny>>,
    parallelism: usize,
) -> PyResult<ComputedEvidence> {
    // The library names the directory by the command line's flag; here it is the argument.
    let opened = py.detach(|| Unfinished::open(&dir)).map_err(|err| match err {
        Error::InvalidSetting { field, message } if field == "resume" => Error::InvalidSetting {
            field: "directory".into(),
            message,
        },
        err => err,
    });
    let (unfinished, mut job, data, progress) = crate::errors::check(py, opened)?;
    if let Some(backend) = named(py, "backend", backend)? {
        job.backend = backend;
    }
    let check = replicates_asked(check, job.laws.len());
    if let Some(k) = check {
        crate::errors::check(py, check_size(k, "check", &job, &data))?;
    }
    let workers = Workers {
        dispatcher,
        parallelism,
    };
    compute(py, &job, &data, Some(unfinished), progress, check, workers, note)
}

/// Scoring by the workers `make` makes, or here.
pub(crate) fn scoring<'a, 'w>(make: &'a mut Option<Box<MakeWorkers<'w>>>) -> Scoring<'a, 'w> {
    match make {
        None => Scoring::Here,
        Some(make) => Scoring::Workers(make.as_mut()),
    }
}

/// The pool of workers an evidence's candidates are scored by, if any.
pub(crate) struct Workers {
    pub(crate) dispatcher: Option<Py<PyAny>>,
    pub(crate) parallelism: usize,
}

impl Workers {
    /// The transport to the pool, where there is one.
    pub(crate) fn transport(self) -> Option<PyTransport> {
        self.dispatcher
            .map(|dispatcher| PyTransport::new(dispatcher, self.parallelism))
    }
}

/// Workers on `transport`'s pool for each problem an evidence job asks for.
pub(crate) fn make_workers(transport: &PyTransport) -> Box<MakeWorkers<'_>> {
    let mut make = remote_each(transport);
    Box::new(move |problem, placement: &Placement, _note: &mut dyn FnMut(String)| make(problem, placement))
}

/// An evidence computed in this process: its document (`bitrock evidence --json`'s, each law's
/// posterior sets added) and what writing it as an evidence directory needs.
#[pyclass(frozen, module = "bitrock._bitrock")]
#[derive(serde::Serialize, serde::Deserialize)]
pub(crate) struct ComputedEvidence {
    document: serde_json::Value,
    /// The posterior's particle CSV ([`EvidenceAnalysis::posterior_csv`]).
    posterior_csv: String,
    job: run::evidence::Job,
    data: FieldData,
}

impl ComputedEvidence {
    fn new(
        document: serde_json::Value,
        analysis: &EvidenceAnalysis,
        job: &run::evidence::Job,
        data: &FieldData,
    ) -> Self {
        let csv = analysis.posterior_csv(&job.laws, data);
        Self {
            document,
            posterior_csv: String::from_utf8(csv).expect("a CSV bitrock writes is UTF-8"),
            job: job.clone(),
            data: data.clone(),
        }
    }
}

#[pymethods]
impl ComputedEvidence {
    /// Pickling: the document, the posterior's CSV, the job and the record, as JSON exact to
    /// the bit; rebuilt by [`ComputedEvidence::_from_state`].
    fn __reduce__<'py>(slf: &Bound<'py, Self>) -> PyResult<(Bound<'py, PyAny>, (String,))> {
        crate::errors::reduce_to_json(slf.as_any(), slf.get(), "evidence")
    }

    /// The evidence a pickle's state describes.
    #[staticmethod]
    fn _from_state(py: Python<'_>, state: &str) -> PyResult<Self> {
        crate::errors::from_json_state(py, state, "evidence", "evidence")
    }

    /// The evidence's document, as JSON.
    #[getter]
    fn document(&self) -> String {
        as_arguments(&self.document.to_string())
    }

    /// Writes the evidence as the evidence directory `path` (`force` replaces an evidence
    /// there), as `bitrock evidence --out` writes one.
    fn save(&self, py: Python<'_>, path: PathBuf, force: bool) -> PyResult<()> {
        let saved = py.detach(|| {
            dir::save(
                &path,
                force,
                &self.document,
                self.posterior_csv.as_bytes(),
                &self.job,
                &self.data,
            )
        });
        // The library names the directory by the command line's flag; here it is the argument.
        check(
            py,
            saved.map_err(|err| match err {
                Error::InvalidSetting { field, message } if field == "out" => Error::InvalidSetting {
                    field: "path".into(),
                    message,
                },
                err => err,
            }),
        )
    }
}

/// `job`'s evidence on `data` from `progress` (kept as it goes in `unfinished`, and written
/// there once done), checked with `replicates` per law where given.
#[allow(clippy::too_many_arguments)]
fn compute(
    py: Python<'_>,
    job: &run::evidence::Job,
    data: &FieldData,
    unfinished: Option<Unfinished>,
    progress: Progress,
    replicates: Option<usize>,
    workers: Workers,
    note: Option<Py<PyAny>>,
) -> PyResult<ComputedEvidence> {
    let mut observer = PyObserver::new(None, note);
    let transport = workers.transport();
    let result = py.detach(|| {
        let mut make = transport.as_ref().map(make_workers);
        let analysis = match &unfinished {
            None => job.run(data, scoring(&mut make), &mut observer),
            Some(unfinished) => unfinished.run(job, data, progress, scoring(&mut make), &mut observer),
        }?;
        let checked = replicates
            .map(|k| {
                let mut scoring = scoring(&mut make);
                check_evidence(job, data, &analysis, k, &mut scoring, &mut |_, _| {}, &mut observer)
            })
            .transpose()?;
        Ok((analysis, checked))
    });
    if let Some(e) = transport.as_ref().and_then(PyTransport::take_raised) {
        return Err(e);
    }
    if let Some(e) = observer.take_raised() {
        return Err(e);
    }
    let (analysis, selection) = check(py, result)?;
    let mut said = Vec::new();
    let advice = check(
        py,
        py.detach(|| analysis.record_advice(data, job, &mut |line| said.push(line))),
    )?;
    for line in said {
        bitrock::abc::Observer::note(&mut observer, line);
    }
    if let Some(e) = observer.take_raised() {
        return Err(e);
    }
    let mut document = bitrock::run::evidence::EvidenceAnalysis::with_advice(
        analysis.document(data, &job.prior.describe(), true),
        data,
        advice.as_ref(),
    );
    if let Some(selection) = selection {
        analysis.with_check(&mut document, &selection);
    }
    if let Some(unfinished) = unfinished {
        check(py, py.detach(|| unfinished.finish(&document, &analysis, job, data)))?;
    }
    Ok(ComputedEvidence::new(document, &analysis, job, data))
}

/// The document of the evidence directory `dir` (`bitrock evidence --out`, `bitrock.evidence(...,
/// out=...)`), as JSON.
#[pyfunction]
pub(crate) fn read_evidence(py: Python<'_>, dir: PathBuf) -> PyResult<String> {
    let document = check(py, py.detach(|| bitrock::run::evidence::dir::read(&dir)))?;
    Ok(document.to_string())
}

/// True when `dir` is an evidence directory.
#[pyfunction]
pub(crate) fn is_evidence_dir(dir: PathBuf) -> bool {
    bitrock::run::dir::is_evidence_dir(&dir)
}
