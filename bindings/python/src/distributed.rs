//! Distributed runs: a Python executor as the transport of a run's tasks, and the worker's
//! side of a request.

use bitrock::abc::shard::wire::{Exchanged, Payloads, Traffic};
use bitrock::abc::shard::{Remote, Transport, Workers};
use bitrock::error::Error;
use bitrock::eval::Objective;
use bitrock::run::Placement;
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyList};
use std::sync::{Mutex, OnceLock};

/// Carries a run's tasks to workers through a Python dispatcher (`bitrock._distributed`): its
/// `exchange(requests, problem, context, (problem_key, context_key))` returns the replies and
/// the payload bytes shipped.
pub(crate) struct PyTransport {
    dispatcher: Py<PyAny>,
    parallelism: usize,
    /// The Python exception that stopped an exchange (Ctrl-C, a task failing on every try).
    raised: Mutex<Option<PyErr>>,
    /// The payloads as Python bytes, by key: made once, not copied again every round.
    payloads: Mutex<Vec<(u64, Py<PyBytes>)>>,
}

impl PyTransport {
    /// The transport of `dispatcher`, `parallelism` tasks a round unless it says otherwise.
    pub(crate) fn new(dispatcher: Py<PyAny>, parallelism: usize) -> Self {
        Self {
            dispatcher,
            parallelism,
            raised: Mutex::new(None),
            payloads: Mutex::new(Vec::new()),
        }
    }

    /// The Python exception that stopped an exchange, if one did.
    pub(crate) fn take_raised(&self) -> Option<PyErr> {
        self.raised.lock().unwrap_or_else(|p| p.into_inner()).take()
    }

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
pub(crate) fn remote_on<'a>(
    cell: &'a OnceLock<Remote<PyTransport>>,
    dispatcher: Py<PyAny>,
    parallelism: usize,
) -> impl FnMut(Objective, &Placement) -> bitrock::Result<Box<dyn Workers + 'a>> {
    let mut transport = Some(PyTransport::new(dispatcher, parallelism));
    move |objective, placement| {
        let transport = transport.take().expect("a run makes its workers once");
        Ok(Box::new(cell.get_or_init(|| {
            Remote::new(objective, placement.backend, placement.shape, transport)
        })))
    }
}

/// Makes workers on `transport`'s pool for each problem a job asks for (an evidence job asks
/// once per torque scaling).
#[allow(clippy::needless_lifetimes)] // eliding 'a leaves the boxed workers' lifetime unnamed
pub(crate) fn remote_each<'a>(
    transport: &'a PyTransport,
) -> impl FnMut(Objective, &Placement) -> bitrock::Result<Box<dyn Workers + 'a>> {
    move |objective, placement| {
        Ok(Box::new(Remote::new(
            objective,
            placement.backend,
            placement.shape,
            transport,
        )))
    }
}

/// The traffic of a distributed run as JSON, and the Python exception that stopped it.
pub(crate) fn after_remote(cell: OnceLock<Remote<PyTransport>>) -> (Option<String>, Option<PyErr>) {
    match cell.into_inner() {
        None => (None, None),
        Some(remote) => {
            let traffic: Vec<Traffic> = remote.traffic();
            let raised = remote.transport().take_raised();
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
pub(crate) fn serve<'py>(
    py: Python<'py>,
    request: &[u8],
    problem: Option<&[u8]>,
    context: Option<&[u8]>,
) -> Bound<'py, PyBytes> {
    let reply = py.detach(|| bitrock::abc::worker::serve(request, problem, context));
    PyBytes::new(py, &reply)
}

/// True when a worker's reply asks for the problem and context payloads.
#[pyfunction]
pub(crate) fn needs_payloads(reply: &[u8]) -> bool {
    bitrock::abc::shard::wire::needs_payloads(reply)
}
