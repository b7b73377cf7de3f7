//! Tasks as bytes: what a driver sends to a worker process and what comes back, and the
//! driver's side ([`Remote`], over any [`Transport`]); the worker's side is
//! [`crate::abc::worker`].
//!
//! A request names its problem (prior, seed, and the record, or the surface record's summaries
//! and the string its candidates drive: an [`Objective`]) and, for proposal tasks, its proposal
//! (for SMC, the previous population) by key, without their contents. A worker that does not hold them
//! yet answers [`Reply::Missing`], and the transport sends the same request again with both
//! payloads attached; the worker keeps them (and the problem's evaluator: one GPU context and
//! its pipelines per process) for the tasks that follow. So the record travels once per
//! worker and the previous population once per worker and population, whatever the number of
//! tasks. Everything is encoded with postcard (serde); a worker refuses a request from
//! another bitrock version or platform ([`build`]): SMC proposals go through the platform's
//! `ln`, `sin` and `cos`.

use super::{Output, Round, Task, Workers};
use crate::error::{Error, Result};
use crate::eval::gpu::{Shape, tune::ShapeWish};
use crate::eval::{Backend, Objective, Problem};
use serde::{Deserialize, Serialize};
use std::collections::BTreeSet;
use std::hash::{Hash, Hasher};
use std::sync::{Arc, Mutex};
use std::time::Instant;

/// The bitrock version every request carries.
pub const VERSION: &str = env!("CARGO_PKG_VERSION");

/// What a driver and its workers must share for a population to be the same on both: the
/// bitrock version, the platform, and the platform's `ln`, `sin` and `cos` (SMC's proposals go
/// through them), fingerprinted by their values at a few arguments. Every request carries it.
pub fn build() -> &'static str {
    static BUILD: std::sync::OnceLock<String> = std::sync::OnceLock::new();
    BUILD.get_or_init(|| {
        let mut h = std::hash::DefaultHasher::new();
        for x in [0.3f64, 1e-7, 0.5 + 1e-9, 2.5, 1234.5678, std::f64::consts::TAU] {
            (x.ln().to_bits(), x.sin().to_bits(), x.cos().to_bits()).hash(&mut h);
        }
        format!(
            "{VERSION} ({}-{}, libm {:016x})",
            std::env::consts::ARCH,
            std::env::consts::OS,
            h.finish()
        )
    })
}

/// The objective's payload: the sources of its law files' laws, then the objective itself (its
/// laws named), so that a worker registers the laws before it reads their names.
pub fn encode_objective(objective: &Objective) -> Vec<u8> {
    let sources: Vec<&str> = crate::laws::file::among(objective.problem().prior.laws())
        .into_iter()
        .filter_map(|law| law.file().map(|f| f.source.as_str()))
        .collect();
    encode(&(sources, encode(objective)))
}

/// Reads an objective's payload ([`encode_objective`]), registering its law files' laws.
pub fn decode_objective(bytes: &[u8]) -> Result<Objective> {
    let (sources, problem): (Vec<String>, Vec<u8>) = decode(bytes, "problem")?;
    for source in sources {
        let file = crate::laws::file::LawFile::parse(&source, std::path::Path::new("law file of the driver"))?;
        crate::laws::file::register(file)?;
    }
    decode(&problem, "problem")
}

/// A task for a worker.
#[derive(Debug, Serialize, Deserialize)]
pub struct Request {
    /// The driver's [`build`].
    pub version: String,
    /// Key of the problem's payload.
    pub problem: u64,
    /// Key of the context's payload, for SMC tasks.
    pub context: Option<u64>,
    pub backend: Backend,
    /// The GPU scoring shape the run recorded, if any, and its dispatch size.
    pub shape: ShapeWish,
    pub task: Task,
}

/// A worker's answer.
#[derive(Debug, Serialize, Deserialize)]
pub enum Reply {
    /// The task's output, the backend that scored it (`cpu`, `gpu`) and its GPU scoring shape.
    Done {
        output: Output,
        backend: String,
        shape: Option<Shape>,
    },
    /// The worker does not hold the request's problem or context: send the request again with
    /// the payloads.
    Missing,
    /// The task failed in a way running it again cannot mend (another bitrock version, a
    /// numerical failure, a refused GPU setting): the run stops with this message.
    Failed(String),
}

/// Postcard bytes of `value`.
pub fn encode<T: Serialize>(value: &T) -> Vec<u8> {
    postcard::to_stdvec(value).expect("bitrock's messages serialise")
}

/// `value` from postcard `bytes`, or what is wrong with them.
pub fn decode<'a, T: Deserialize<'a>>(bytes: &'a [u8], what: &str) -> Result<T> {
    postcard::from_bytes(bytes).map_err(|e| Error::Worker(format!("not a bitrock {what}: {e}")))
}

/// True when `reply` asks for the payloads ([`Reply::Missing`]): what a transport checks.
pub fn needs_payloads(reply: &[u8]) -> bool {
    matches!(decode::<Reply>(reply, "reply"), Ok(Reply::Missing))
}

/// The key a payload is named by: a hash of its bytes.
pub fn key_of(bytes: &[u8]) -> u64 {
    let mut h = std::hash::DefaultHasher::new();
    bytes.hash(&mut h);
    h.finish()
}

/// The payloads a request may need, for a transport to attach when a worker asks, with the
/// keys the requests name them by (the same bytes keep their key from round to round).
pub struct Payloads<'a> {
    pub problem: &'a [u8],
    pub problem_key: u64,
    pub context: Option<&'a [u8]>,
    pub context_key: Option<u64>,
}

/// What a transport sent and got back.
pub struct Exchanged {
    /// One [`Reply`] (encoded) per request, none of them [`Reply::Missing`], in request order.
    pub replies: Vec<Vec<u8>>,
    /// Bytes of the payloads the transport shipped (problem and context, once per worker
    /// that asked).
    pub payload_bytes: u64,
}

/// Carries requests to workers and their replies back: an executor of Python, Dask or Ray, or
/// anything that can call [`crate::abc::worker::serve`] elsewhere. It answers [`Reply::Missing`] by sending the
/// request again with the payloads, and may run a request more than once (a lost worker):
/// tasks are pure.
pub trait Transport: Sync {
    /// The replies to `requests`.
    fn exchange(&self, requests: Vec<Vec<u8>>, payloads: &Payloads) -> Result<Exchanged>;
    /// Tasks a round is worth cutting into (a few per worker).
    fn parallelism(&self) -> usize;
}

impl<T: Transport + ?Sized> Transport for &T {
    fn exchange(&self, requests: Vec<Vec<u8>>, payloads: &Payloads) -> Result<Exchanged> {
        (**self).exchange(requests, payloads)
    }

    fn parallelism(&self) -> usize {
        (**self).parallelism()
    }
}

/// What one population cost in traffic and waiting.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Traffic {
    pub population: usize,
    pub rounds: u64,
    pub tasks: u64,
    /// Bytes of the requests sent (first sending).
    pub request_bytes: u64,
    /// Bytes of the problem and context payloads shipped.
    pub payload_bytes: u64,
    /// Bytes of the replies received.
    pub reply_bytes: u64,
    /// Seconds the driver waited for the workers.
    pub wait_seconds: f64,
}

/// Workers reached through a [`Transport`]: the driver's side of a distributed run.
pub struct Remote<T> {
    objective: Objective,
    problem_bytes: Vec<u8>,
    problem_key: u64,
    backend: Backend,
    shape: ShapeWish,
    transport: T,
    /// The context payload of the population in progress.
    context: Mutex<Option<EncodedContext>>,
    /// Backends the workers reported.
    seen: Mutex<(bool, bool)>,
    /// GPU scoring shapes the workers reported.
    shapes: Mutex<BTreeSet<Shape>>,
    traffic: Mutex<Vec<Traffic>>,
}

impl<T: Transport> Remote<T> {
    /// Workers for `objective` (a record's [`Problem`], or strings simulated against a surface
    /// record) through `transport`, asked to score on `backend` (a GPU in the shape `shape`
    /// leads to on each worker: the same everywhere once the run recorded one).
    pub fn new(objective: impl Into<Objective>, backend: Backend, shape: ShapeWish, transport: T) -> Self {
        let objective = objective.into();
        let problem_bytes = encode_objective(&objective);
        Self {
            problem_key: key_of(&problem_bytes),
            objective,
            problem_bytes,
            backend,
            shape,
            transport,
            context: Mutex::new(None),
            seen: Mutex::new((false, false)),
            shapes: Mutex::new(BTreeSet::new()),
            traffic: Mutex::new(Vec::new()),
        }
    }

    /// The transport the requests go through.
    pub fn transport(&self) -> &T {
        &self.transport
    }

    /// The traffic of every population so far.
    pub fn traffic(&self) -> Vec<Traffic> {
        self.traffic.lock().expect("traffic").clone()
    }

    /// The key and bytes of `round`'s context, encoded once per population.
    fn context_payload(&self, round: &Round) -> Option<(u64, Arc<Vec<u8>>)> {
        let context = round.context?;
        let mut cached = self.context.lock().expect("context cache");
        if let Some(c) = cached.as_ref().filter(|c| c.population == round.population) {
            return Some((c.key, c.bytes.clone()));
        }
        let bytes = Arc::new(encode(&context.encode()));
        let key = key_of(&bytes);
        *cached = Some(EncodedContext {
            population: round.population,
            key,
            bytes: bytes.clone(),
        });
        Some((key, bytes))
    }
}

/// A population's context as bytes, encoded once for all its rounds.
struct EncodedContext {
    population: usize,
    key: u64,
    bytes: Arc<Vec<u8>>,
}

impl<T: Transport> Workers for Remote<T> {
    fn problem(&self) -> &Problem {
        self.objective.problem()
    }

    fn backend(&self) -> &'static str {
        match *self.seen.lock().expect("backends") {
            (true, true) => "cpu+gpu",
            (false, true) => "gpu",
            (true, false) => "cpu",
            (false, false) => match self.backend {
                Backend::Cpu => "cpu",
                Backend::Gpu => "gpu",
                Backend::Auto => "auto",
            },
        }
    }

    fn parallelism(&self) -> usize {
        self.transport.parallelism().max(1)
    }

    fn min_task_len(&self) -> u64 {
        match self.objective {
            Objective::Record(_) => super::MIN_TASK,
            Objective::Surface(_) => super::MIN_STRING_TASK,
        }
    }

    /// The one shape the GPU workers reported; none before any did, or when they differ.
    fn gpu_shape(&self) -> Option<Shape> {
        let shapes = self.shapes.lock().expect("shapes");
        match shapes.len() {
            1 => shapes.first().copied(),
            _ => None,
        }
    }

    fn run(&self, round: &Round) -> Result<Vec<Output>> {
        let context = self.context_payload(round);
        let requests: Vec<Vec<u8>> = round
            .tasks
            .iter()
            .map(|task| {
                encode(&Request {
                    version: build().to_string(),
                    problem: self.problem_key,
                    context: context.as_ref().map(|c| c.0),
                    backend: self.backend,
                    shape: self.shape,
                    task: task.clone(),
                })
            })
            .collect();
        let request_bytes: u64 = requests.iter().map(|r| r.len() as u64).sum();
        let started = Instant::now();
        let exchanged = self.transport.exchange(
            requests,
            &Payloads {
                problem: &self.problem_bytes,
                problem_key: self.problem_key,
                context: context.as_ref().map(|c| c.1.as_slice()),
                context_key: context.as_ref().map(|c| c.0),
            },
        )?;
        let wait_seconds = started.elapsed().as_secs_f64();
        if exchanged.replies.len() != round.tasks.len() {
            return Err(Error::Worker(format!(
                "{} replies to {} tasks",
                exchanged.replies.len(),
                round.tasks.len()
            )));
        }
        let reply_bytes: u64 = exchanged.replies.iter().map(|r| r.len() as u64).sum();
        let mut outputs = Vec::with_capacity(round.tasks.len());
        for reply in &exchanged.replies {
            match decode::<Reply>(reply, "reply")? {
                Reply::Done { output, backend, shape } => {
                    if let Some(shape) = shape {
                        self.shapes.lock().expect("shapes").insert(shape);
                    }
                    let mut seen = self.seen.lock().expect("backends");
                    if backend == "gpu" {
                        seen.1 = true;
                    } else {
                        seen.0 = true;
                    }
                    outputs.push(output);
                }
                Reply::Failed(message) => return Err(Error::Worker(message)),
                Reply::Missing => return Err(Error::Worker("a worker still lacks the payloads it was sent".into())),
            }
        }
        let mut traffic = self.traffic.lock().expect("traffic");
        if traffic.last().is_none_or(|t| t.population != round.population) {
            traffic.push(Traffic {
                population: round.population,
                ..Traffic::default()
            });
        }
        let t = traffic.last_mut().expect("just pushed");
        t.rounds += 1;
        t.tasks += round.tasks.len() as u64;
        t.request_bytes += request_bytes;
        t.payload_bytes += exchanged.payload_bytes;
        t.reply_bytes += reply_bytes;
        t.wait_seconds += wait_seconds;
        Ok(outputs)
    }
}
