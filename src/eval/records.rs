//! Scoring the candidates of many records together: the selection check's replicates are
//! independent runs over records of equal length, and one replicate's requests are far too
//! small to fill a GPU.
//!
//! Each record's sampler runs on a thread of its own with a [`RecordEvaluator`]. A scoring call
//! waits until every sampler still running has one too, and the last to arrive scores them all
//! at once: on the GPU in one dispatch with a record index per segment (shaders/records.wgsl,
//! [`gpu::records::GpuRecords`]), on the CPU in one rayon pass over all the requests. A
//! record's ρ are exactly those its own evaluator of the same backend (and scoring shape)
//! gives, whatever else is in the batch, so a replicate's populations do not depend on how many
//! replicates are batched, nor on which finish first.
//!
//! Every sampler holds a [`Seat`], taken before any of them starts: a seat given up (the run
//! ended, failed or panicked) no longer holds the others back.

use super::{Backend, Candidates, Evaluator, KernelSums, Problem, Request, cpu, gpu};
use crate::error::Result;
use crate::prior::Candidate;
use rayon::prelude::*;
use std::collections::HashMap;
use std::sync::{Arc, Condvar, Mutex, MutexGuard};

/// How many batches a [`RecordBatch`] scored, and what they held.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BatchCounts {
    /// Times the waiting requests were scored together.
    pub batches: u64,
    /// Requests scored, over all batches.
    pub requests: u64,
    /// GPU dispatches (0 on the CPU).
    pub dispatches: u64,
    /// Wall time spent scoring batches, s.
    pub seconds: f64,
}

/// Where a batch is scored.
enum Scorer {
    Cpu,
    /// The shape, and the records' GPU buffers once the first batch built them (every record
    /// has registered by then: its sampler is waiting).
    Gpu {
        shape: gpu::Shape,
        records: Option<Box<gpu::records::GpuRecords>>,
        /// `auto`: the CPU scores when the records cannot be set up on the GPU.
        fallback: bool,
    },
}

/// What the samplers share: the records, the requests waiting, the results not yet collected.
struct State {
    problems: Vec<Arc<Problem>>,
    /// Seats not given up.
    seated: usize,
    pending: Vec<(u64, Request)>,
    done: HashMap<u64, std::result::Result<Vec<f64>, gpu::GpuError>>,
    next_ticket: u64,
    /// The scorer, taken out while a batch is scored (by one thread, outside the lock).
    scorer: Option<Scorer>,
    counts: BatchCounts,
}

/// Scores many records' requests together; see the module documentation.
pub struct RecordBatch {
    /// `cpu` or `gpu`; `cpu` once `auto` fell back.
    backend: Mutex<&'static str>,
    /// What the user should know that happened after [`RecordBatch::new`] (a fallback).
    notes: Mutex<Vec<String>>,
    /// Candidates per GPU dispatch at most (tests split requests with it).
    max_candidates: Option<usize>,
    /// The GPU scoring shape, while the GPU scores.
    shape: Option<gpu::Shape>,
    state: Mutex<State>,
    scored: Condvar,
}

impl RecordBatch {
    /// A batch of `records` records on `backend` (with `Auto`, the GPU when one can be set up,
    /// else the CPU, said through `note`), on the GPU in the shape `wish` leads to
    /// ([`gpu::tune::choose`], with `problem`, a record like the batch's, to measure on where
    /// this adapter was never measured). A software GPU under `Auto` scores only where it beats
    /// the CPU ([`super::auto`]) at the batch's dispatches: `records` times `wish`'s candidates,
    /// raced on `problem` (a dispatch costs the same per candidate whichever record it scores).
    pub fn new(
        backend: Backend,
        wish: gpu::tune::ShapeWish,
        problem: &Problem,
        records: usize,
        note: &mut dyn FnMut(String),
    ) -> Result<Arc<Self>> {
        let setup = || gpu::context().and_then(|ctx| Ok((ctx, gpu::tune::choose(ctx, problem, wish)?)));
        // The GPU kept, and whether the race already said so.
        let gpu = match backend {
            Backend::Cpu => None,
            Backend::Gpu => Some((setup()?, false)),
            Backend::Auto => match setup() {
                Ok((ctx, choice)) if ctx.is_software() => {
                    let batched = gpu::tune::ShapeWish {
                        candidates: wish.candidates.saturating_mul(records.max(1)),
                        ..wish
                    };
                    match super::auto::cpu_beats(ctx, problem, choice, batched, note)? {
                        super::auto::Kept::Cpu => None,
                        super::auto::Kept::Gpu { said } => Some(((ctx, choice), said)),
                    }
                }
                Ok(gpu) => Some((gpu, false)),
                Err(e) => {
                    super::fall_back_to_cpu(e, note)?;
                    None
                }
            },
        };
        let scorer = match gpu {
            Some(((ctx, choice), said)) => {
                if !said {
                    note(format!(
                        "{}: {}; records batched",
                        crate::eval::GPU_BACKEND_NOTE,
                        super::gpu_named(&ctx.describe(), choice.shape, choice.source)
                    ));
                }
                Scorer::Gpu {
                    shape: choice.shape,
                    records: None,
                    fallback: backend == Backend::Auto,
                }
            }
            None => Scorer::Cpu,
        };
        Ok(Self::with_scorer(scorer, None))
    }

    /// A batch on the GPU in `shape`, at most `max_candidates` per dispatch (tests).
    pub fn on_gpu(shape: gpu::Shape, max_candidates: Option<usize>) -> Arc<Self> {
        let scorer = Scorer::Gpu {
            shape,
            records: None,
            fallback: false,
        };
        Self::with_scorer(scorer, max_candidates)
    }

    fn with_scorer(scorer: Scorer, max_candidates: Option<usize>) -> Arc<Self> {
        let (backend, shape) = match scorer {
            Scorer::Cpu => ("cpu", None),
            Scorer::Gpu { shape, .. } => ("gpu", Some(shape)),
        };
        Arc::new(Self {
            backend: Mutex::new(backend),
            shape,
            notes: Mutex::new(Vec::new()),
            max_candidates,
            state: Mutex::new(State {
                problems: Vec::new(),
                seated: 0,
                pending: Vec::new(),
                done: HashMap::new(),
                next_ticket: 0,
                scorer: Some(scorer),
                counts: BatchCounts::default(),
            }),
            scored: Condvar::new(),
        })
    }

    /// `cpu` or `gpu` (`cpu` once `auto` fell back to it).
    pub fn backend(&self) -> &'static str {
        *self.backend.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
    }

    /// The GPU scoring shape; `None` where the CPU scores.
    pub fn gpu_shape(&self) -> Option<gpu::Shape> {
        (self.backend() == "gpu").then_some(self.shape).flatten()
    }

    /// Lines for the user about what happened since [`RecordBatch::new`] (a fallback to the
    /// CPU), each once.
    pub fn take_notes(&self) -> Vec<String> {
        std::mem::take(&mut *self.notes.lock().unwrap_or_else(|poisoned| poisoned.into_inner()))
    }

    /// A seat for one sampler. Take every seat before any sampler starts: a batch is scored
    /// when every seat's holder waits on it.
    pub fn seat(self: &Arc<Self>) -> Seat {
        self.lock().seated += 1;
        Seat { batch: self.clone() }
    }

    /// What was scored so far.
    pub fn counts(&self) -> BatchCounts {
        self.lock().counts
    }

    fn lock(&self) -> MutexGuard<'_, State> {
        self.state.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
    }

    /// Scores `request` with the others' and returns its ρ.
    fn submit(&self, request: Request) -> Result<Vec<f64>> {
        let mut state = self.lock();
        let ticket = state.next_ticket;
        state.next_ticket += 1;
        state.pending.push((ticket, request));
        loop {
            if let Some(result) = state.done.remove(&ticket) {
                return Ok(result?);
            }
            state = if Self::ready(&state) {
                self.score_pending(state)
            } else {
                self.scored.wait(state).unwrap_or_else(|poisoned| poisoned.into_inner())
            };
        }
    }

    /// True when every seated sampler waits (as many requests as seats: the samplers call
    /// their evaluator from one thread; a sampler that made concurrent calls would only make
    /// batches go sooner, never hang) and nobody is scoring.
    fn ready(state: &State) -> bool {
        !state.pending.is_empty() && state.pending.len() >= state.seated && state.scorer.is_some()
    }

    /// Scores every waiting request (the lock released meanwhile) and wakes their samplers.
    fn score_pending<'a>(&'a self, mut state: MutexGuard<'a, State>) -> MutexGuard<'a, State> {
        let (tickets, requests): (Vec<u64>, Vec<Request>) = std::mem::take(&mut state.pending).into_iter().unzip();
        let mut scorer = state.scorer.take().expect("checked by ready");
        let problems = state.problems.clone();
        drop(state);
        let started = std::time::Instant::now();
        let (results, dispatches) = self.score_all(&mut scorer, &problems, &requests);
        let seconds = started.elapsed().as_secs_f64();
        let mut state = self.lock();
        state.scorer = Some(scorer);
        state.counts.batches += 1;
        state.counts.requests += requests.len() as u64;
        state.counts.dispatches += dispatches as u64;
        state.counts.seconds += seconds;
        for (ticket, result) in tickets.into_iter().zip(results) {
            state.done.insert(ticket, result);
        }
        self.scored.notify_all();
        state
    }

    /// ρ of every request, and the GPU dispatches made. With `auto`, records the GPU cannot
    /// hold are scored on the CPU from then on, and the user is told.
    fn score_all(
        &self,
        scorer: &mut Scorer,
        problems: &[Arc<Problem>],
        requests: &[Request],
    ) -> (Vec<std::result::Result<Vec<f64>, gpu::GpuError>>, usize) {
        let fail = |e: &gpu::GpuError| requests.iter().map(|_| Err(e.clone())).collect();
        if let Scorer::Gpu {
            shape,
            records,
            fallback,
        } = scorer
        {
            // Every record has registered before the first batch (its sampler waits in it);
            // one registering later would have the buffers rebuilt with it.
            let built = match records.take() {
                Some(built) if built.records() == problems.len() => Ok(built),
                _ => {
                    let all: Vec<&Problem> = problems.iter().map(|p| p.as_ref()).collect();
                    gpu::records::GpuRecords::new(&all, *shape, self.max_candidates).map(Box::new)
                }
            };
            match built {
                Ok(built) => {
                    return match records.insert(built).sum_sq_residuals(requests) {
                        Ok((ssr, dispatches)) => {
                            let rho = requests
                                .iter()
                                .zip(ssr)
                                .map(|(r, s)| {
                                    let sum_sq = problems[r.record].sum_sq_torque;
                                    Ok(s.into_iter().map(|v| super::rho_of_sum(f64::from(v), sum_sq)).collect())
                                })
                                .collect();
                            (rho, dispatches)
                        }
                        Err(e) => (fail(&e), 0),
                    };
                }
                Err(e) if *fallback => {
                    let line = format!("the records do not fit the GPU ({e}); computing on the CPU");
                    self.notes
                        .lock()
                        .unwrap_or_else(|poisoned| poisoned.into_inner())
                        .push(line);
                    *self.backend.lock().unwrap_or_else(|poisoned| poisoned.into_inner()) = "cpu";
                    *scorer = Scorer::Cpu;
                }
                Err(e) => return (fail(&e), 0),
            }
        }
        let results = requests
            .par_iter()
            .map(|r| {
                let problem = &problems[r.record];
                let mut rho = vec![0.0; r.candidates.len()];
                match &r.candidates {
                    Candidates::Stream { population, start, .. } => {
                        cpu::score_stream(problem, *population, *start, &mut rho)
                    }
                    Candidates::Explicit(c) => cpu::score_candidates(problem, c, &mut rho),
                }
                Ok(rho)
            })
            .collect();
        (results, 0)
    }
}

/// One sampler's place in a [`RecordBatch`]; giving it up (dropping it) lets the others' batches
/// go without it.
pub struct Seat {
    batch: Arc<RecordBatch>,
}

impl Seat {
    /// The evaluator of `problem`, a record of the batch (of the same length as the others).
    pub fn evaluator(&self, problem: Problem) -> RecordEvaluator {
        let problem = Arc::new(problem);
        let mut state = self.batch.lock();
        if let Some(first) = state.problems.first() {
            assert_eq!(
                first.data_len(),
                problem.data_len(),
                "records scored together have equal lengths"
            );
        }
        let record = state.problems.len();
        state.problems.push(problem.clone());
        RecordEvaluator {
            batch: self.batch.clone(),
            record,
            problem,
            kernel_sums: Default::default(),
        }
    }
}

impl Drop for Seat {
    fn drop(&mut self) {
        let mut state = self.batch.lock();
        state.seated -= 1;
        if RecordBatch::ready(&state) {
            drop(self.batch.score_pending(state));
        }
    }
}

/// Scores one record's candidates through its [`RecordBatch`].
pub struct RecordEvaluator {
    batch: Arc<RecordBatch>,
    record: usize,
    problem: Arc<Problem>,
    /// Buffers of the SMC kernel sums on the GPU (computed per record, not batched).
    kernel_sums: gpu::kernel_sums::Scratch,
}

impl Evaluator for RecordEvaluator {
    fn backend(&self) -> &'static str {
        self.batch.backend()
    }

    fn problem(&self) -> &Problem {
        &self.problem
    }

    fn score(&self, population: u32, start: u64, out: &mut [f64]) -> Result<()> {
        let rho = self.batch.submit(Request {
            record: self.record,
            candidates: Candidates::Stream {
                population,
                start,
                len: out.len(),
            },
        })?;
        out.copy_from_slice(&rho);
        Ok(())
    }

    fn score_params(&self, candidates: &[Candidate], out: &mut [f64]) -> Result<()> {
        assert_eq!(candidates.len(), out.len(), "one ρ per candidate");
        let rho = self.batch.submit(Request {
            record: self.record,
            candidates: Candidates::Explicit(candidates.to_vec()),
        })?;
        out.copy_from_slice(&rho);
        Ok(())
    }

    fn kernel_sums(&self, sums: &KernelSums, out: &mut [f64]) -> Result<()> {
        if self.batch.backend() == "gpu" {
            self.kernel_sums.run(gpu::context()?, sums, out)?;
        } else {
            cpu::kernel_sums(sums, out);
        }
        Ok(())
    }
}
