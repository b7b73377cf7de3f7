//! The worker's side of a distributed run: answers a request ([`serve`]), keeping the
//! problem (record, prior, seed), its evaluator (one GPU context and its pipelines per
//! process) and the population's proposal between tasks, so that each is shipped once per
//! worker. It names the samplers whose proposals a worker can rebuild (`proposal`): a
//! sampler that proposes registers here.

use super::shard::wire::{Reply, Request, build, decode, decode_objective, encode};
use super::shard::{self, Proposal};
use super::smc;
use crate::error::{Error, Result};
use crate::eval::gpu::tune::ShapeWish;
use crate::eval::{Backend, Evaluator, Objective, Problem};
use std::sync::{Arc, Mutex};

/// The environment variable that overrides, on a worker, the backend the driver asked for
/// (`cpu`, `gpu` or `auto`): a node without a GPU in a pool of GPU nodes, say.
pub const WORKER_BACKEND_VAR: &str = "BITROCK_WORKER_BACKEND";

/// What a worker's evaluator is made for: the problem's key, the backend and the shape wish.
type EvaluatorKey = (u64, Backend, ShapeWish);

/// Payloads and evaluators a worker process keeps, the most recently used last.
#[derive(Default)]
struct Held {
    problems: Vec<(u64, Arc<Objective>)>,
    evaluators: Vec<(EvaluatorKey, Arc<dyn Evaluator>)>,
    contexts: Vec<((u64, u64), Arc<dyn Proposal>)>,
}

/// Problems and contexts a worker keeps at most (older ones are dropped first): several runs
/// may share a pool of workers.
const HELD: usize = 4;

fn find<K: PartialEq + Copy, V: Clone>(list: &mut Vec<(K, V)>, key: K) -> Option<V> {
    let at = list.iter().position(|(k, _)| *k == key)?;
    let entry = list.remove(at);
    let value = entry.1.clone();
    list.push(entry);
    Some(value)
}

fn hold<K, V>(list: &mut Vec<(K, V)>, key: K, value: V) {
    if list.len() >= HELD {
        list.remove(0);
    }
    list.push((key, value));
}

static HELD_HERE: Mutex<Option<Held>> = Mutex::new(None);

/// Answers one request on a worker: the task's output, or [`Reply::Missing`] when the
/// problem or context it names is neither held nor attached. Payloads attached are kept for
/// later requests. Never fails: a failure is a [`Reply::Failed`].
pub fn serve(request: &[u8], problem: Option<&[u8]>, context: Option<&[u8]>) -> Vec<u8> {
    encode(&match answer(request, problem, context) {
        Ok(reply) => reply,
        Err(e) => Reply::Failed(e.to_string()),
    })
}

fn answer(request: &[u8], problem: Option<&[u8]>, context: Option<&[u8]>) -> Result<Reply> {
    let request: Request = decode(request, "request")?;
    let here = build();
    if request.version != here {
        return Err(Error::Worker(format!(
            "the driver runs bitrock {} and this worker {here}: driver and workers need the same bitrock on the same platform",
            request.version
        )));
    }
    let backend = match std::env::var(WORKER_BACKEND_VAR) {
        Ok(name) => worker_backend(&name)?,
        Err(_) => request.backend,
    };
    let (evaluator, context) = {
        let mut guard = HELD_HERE.lock().unwrap_or_else(|p| p.into_inner());
        let held = guard.get_or_insert_with(Held::default);
        if let Some(bytes) = problem
            && find(&mut held.problems, request.problem).is_none()
        {
            let decoded = decode_objective(bytes)?;
            hold(&mut held.problems, request.problem, Arc::new(decoded));
        }
        let Some(the_problem) = find(&mut held.problems, request.problem) else {
            return Ok(Reply::Missing);
        };
        let key = (request.problem, backend, request.shape);
        let evaluator = match find(&mut held.evaluators, key) {
            Some(e) => e,
            None => {
                let made: Arc<dyn Evaluator> =
                    Arc::from((*the_problem).clone().evaluator(backend, request.shape, &mut |_| {})?);
                hold(&mut held.evaluators, key, made.clone());
                made
            }
        };
        let context = match request.context {
            None => None,
            Some(key) => {
                if let Some(bytes) = context
                    && find(&mut held.contexts, (request.problem, key)).is_none()
                {
                    let made = proposal(the_problem.problem(), bytes)?;
                    hold(&mut held.contexts, (request.problem, key), made);
                }
                match find(&mut held.contexts, (request.problem, key)) {
                    Some(c) => Some(c),
                    None => return Ok(Reply::Missing),
                }
            }
        };
        (evaluator, context)
    };
    let output = shard::execute(evaluator.as_ref(), context.as_deref(), &request.task)?;
    Ok(Reply::Done {
        output,
        backend: evaluator.backend().to_string(),
        shape: evaluator.gpu_shape(),
    })
}

fn worker_backend(name: &str) -> Result<Backend> {
    match name {
        "cpu" => Ok(Backend::Cpu),
        "gpu" => Ok(Backend::Gpu),
        "auto" => Ok(Backend::Auto),
        other => Err(Error::setting(
            WORKER_BACKEND_VAR,
            format!("must be cpu, gpu or auto, got {other:?}"),
        )),
    }
}

/// The proposal a driver's [`Proposal::encode`] wrote, rebuilt for `problem`.
fn proposal(problem: &Problem, bytes: &[u8]) -> Result<Arc<dyn Proposal>> {
    let (sampler, payload): (String, Vec<u8>) = decode(bytes, "proposal")?;
    match sampler.as_str() {
        smc::SAMPLER => Ok(Arc::new(smc::Context::decode(problem, &payload)?)),
        other => Err(Error::Worker(format!(
            "a proposal of the sampler {other:?}, which this worker does not know"
        ))),
    }
}
