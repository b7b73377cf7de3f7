//! Populations as pure tasks: how a population is cut into pieces that any process can compute,
//! and how their results are put back together into exactly the population one process makes.
//!
//! A sampler fills a population in *rounds*: a range of candidate indices (today's batch,
//! sized by the projected acceptance). A round is cut into [`Task`]s, a [`Workers`] runs them
//! (here, or on other processes and machines), and the sampler merges their [`Output`]s in
//! index order. Because candidate i of stream g is a pure function of (seed, g, i) (see
//! [`crate::rng`]) and a task returns every candidate its range holds below ε or near it
//! ([`kept`]), the merge sees exactly what a scan of the whole round sees: the first N
//! accepted in index order are the same whatever the cut, the number of workers, the order
//! results arrive in, or a task run twice. Candidates a task scored past the N-th acceptance
//! are discarded by the merge (or, in nested rejection, kept for the next population).
//!
//! Four kinds of task:
//! - [`Task::Scan`]: a range of the prior's candidate stream (rejection, and SMC's
//!   population 0);
//! - [`Task::Propose`]: a range of proposals, made on the worker from the round's
//!   [`Proposal`] (for SMC, the previous population and its kernels), so that proposals are
//!   never shipped;
//! - [`Task::Weigh`]: the log importance weights of a range of the new population's
//!   particles against the round's [`Proposal`] (for SMC, the O(N²) kernel-density sums);
//! - [`Task::Score`]: explicit candidates made by the driver (the evidence sampler's
//!   Metropolis moves), scored as they are ([`score_candidates`]).
//!
//! The task layer knows no sampler: a sampler that proposes implements [`Proposal`], and the
//! worker side ([`super::worker`]) names the samplers whose proposals it can rebuild.
//!
//! One process runs every task itself ([`Local`]): the single-process path and a distributed
//! run go through the same planner ([`split`]) and merge. [`wire`] turns tasks, problems and
//! proposals into bytes and back; [`super::worker::serve`] answers a request on a worker
//! process.

use super::Particle;
use crate::error::{Error, Result};
use crate::eval::gpu::{Shape, tune::ShapeWish};
use crate::eval::{Evaluator, PARITY_TOLERANCE, Problem};
use crate::prior::Candidate;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

pub mod wire;

pub use wire::{Remote, Transport};

/// True when a task returns a candidate of misfit `rho` at tolerance `epsilon`: below ε, or
/// within twice the parity tolerance above it. That holds every candidate the acceptance rule
/// (ρ < ε) and the near-threshold count (|ρ − ε| ≤ tolerance·ε) look at, at ε and at any
/// smaller tolerance (nested rejection scans the same candidates again at ε_{g+1} < ε_g); the
/// factor 2 keeps rounding in the products from ever excluding one of them.
#[inline]
pub fn kept(rho: f64, epsilon: f64) -> bool {
    rho <= epsilon * (1.0 + 2.0 * PARITY_TOLERANCE)
}

/// One piece of a population's work.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum Task {
    /// Score candidates `start .. start + len` of the prior's stream `stream`; return those
    /// [`kept`] at `epsilon`.
    Scan {
        stream: u32,
        start: u64,
        len: u64,
        epsilon: f64,
    },
    /// Make proposals `start .. start + len` of stream `stream` from the round's
    /// [`Proposal`], score those inside the prior box, return those [`kept`] at `epsilon`.
    Propose {
        stream: u32,
        start: u64,
        len: u64,
        epsilon: f64,
    },
    /// The log importance weights (unnormalised) of the new population's particles `first ..
    /// first + particles.len()` against the round's [`Proposal`].
    Weigh { first: usize, particles: Vec<Particle> },
    /// The misfit ρ of explicit candidates `first ..` of a batch and, when `lagged`, their
    /// lag-1 sums ([`Evaluator::score_params_lagged`]).
    Score {
        first: usize,
        candidates: Vec<Candidate>,
        lagged: bool,
    },
}

/// What a task returns.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum Output {
    /// The result of a [`Task::Scan`] or [`Task::Propose`] over `start .. start + len`.
    Found {
        start: u64,
        len: u64,
        /// Candidates scored (proposals outside the prior box are not).
        scored: u64,
        /// (index, ρ) of the candidates kept, in index order.
        kept: Vec<(u64, f64)>,
        /// The draws of the range (every candidate, scored or not), per prior slot: the merge
        /// counts a population's draws per law from these, not by making candidates again.
        slots: Vec<u64>,
        /// For each kept candidate, the draws per slot from `start` to it (itself included),
        /// `slots.len()` numbers each: where a population stops inside a range.
        prefix: Vec<u64>,
    },
    /// The result of a [`Task::Weigh`]: one log weight per particle from `first` on.
    LogWeights { first: usize, values: Vec<f64> },
    /// The result of a [`Task::Score`]: ρ of each candidate from `first` on, and their lag-1
    /// sums (empty unless asked for).
    Scores { first: usize, rho: Vec<f64>, lag: Vec<f64> },
}

/// A population's proposal distribution, built by its sampler from the previous population:
/// what [`Task::Propose`] and [`Task::Weigh`] run with. Proposals are a pure function of the
/// proposal, the seed, the stream and the index, so a worker elsewhere rebuilt from
/// [`Proposal::encode`] makes the very same ones.
pub trait Proposal: Send + Sync {
    /// Makes proposals `indexes` of `stream`, scores those inside the prior box with
    /// `evaluator`, and keeps those [`kept`] at `epsilon`.
    fn propose_and_score(
        &self,
        evaluator: &dyn Evaluator,
        stream: u32,
        indexes: std::ops::Range<u64>,
        epsilon: f64,
    ) -> Result<Proposed>;
    /// The log importance weights (unnormalised) of `particles`.
    fn log_weights(&self, evaluator: &dyn Evaluator, particles: &[Particle]) -> Result<Vec<f64>>;
    /// The sampler's name and the bytes its worker side rebuilds the proposal from.
    fn encode(&self) -> (&'static str, Vec<u8>);
}

/// A range of proposals, scored: how many were inside the prior box and scored, the (index,
/// ρ) of those kept, and every proposal's law slot.
pub struct Proposed {
    pub scored: u64,
    pub kept: Vec<(u64, f64)>,
    pub slots: Vec<u8>,
}

/// A round of a population: its tasks and, for proposals and weights, the proposal
/// distribution they need.
pub struct Round<'a> {
    /// The population the round belongs to.
    pub population: usize,
    pub context: Option<&'a dyn Proposal>,
    pub tasks: Vec<Task>,
}

/// Runs rounds of tasks: in this process ([`Local`]), or on workers elsewhere.
pub trait Workers: Sync {
    /// The problem every task is scored against.
    fn problem(&self) -> &Problem;
    /// The backend that scores, for records (`cpu`, `gpu`, or both for a mixed pool).
    fn backend(&self) -> &'static str;
    /// Tasks a round is cut into at most (1: one task per round).
    fn parallelism(&self) -> usize {
        1
    }
    /// Candidates a task of a round holds at least, unless the round is smaller: below it a
    /// task's round trip outweighs its work.
    fn min_task_len(&self) -> u64 {
        MIN_TASK
    }
    /// The GPU scoring shape the workers score in, where one is known (for the run's record).
    fn gpu_shape(&self) -> Option<Shape> {
        None
    }
    /// One output per task of `round`, in any order.
    fn run(&self, round: &Round) -> Result<Vec<Output>>;
}

impl<W: Workers + ?Sized> Workers for &W {
    fn problem(&self) -> &Problem {
        (**self).problem()
    }

    fn backend(&self) -> &'static str {
        (**self).backend()
    }

    fn parallelism(&self) -> usize {
        (**self).parallelism()
    }

    fn min_task_len(&self) -> u64 {
        (**self).min_task_len()
    }

    fn gpu_shape(&self) -> Option<Shape> {
        (**self).gpu_shape()
    }

    fn run(&self, round: &Round) -> Result<Vec<Output>> {
        (**self).run(round)
    }
}

/// Every task run in this process by one evaluator.
pub struct Local<E>(pub E);

impl<E> Workers for Local<E>
where
    E: std::ops::Deref + Sync,
    E::Target: Evaluator,
{
    fn problem(&self) -> &Problem {
        self.0.problem()
    }

    fn backend(&self) -> &'static str {
        self.0.backend()
    }

    fn gpu_shape(&self) -> Option<Shape> {
        self.0.gpu_shape()
    }

    fn run(&self, round: &Round) -> Result<Vec<Output>> {
        let evaluator: &E::Target = &self.0;
        round
            .tasks
            .iter()
            .map(|task| execute(&evaluator, round.context, task))
            .collect()
    }
}

/// Every task run in this process on one of several evaluators (one per GPU: `devices`
/// all): a round's tasks are dealt to them in turn and each evaluator runs its share on a
/// thread of its own.
pub struct Several<E>(pub Vec<E>);

impl<E: Evaluator> Workers for Several<E> {
    fn problem(&self) -> &Problem {
        self.0[0].problem()
    }

    fn backend(&self) -> &'static str {
        self.0[0].backend()
    }

    fn gpu_shape(&self) -> Option<Shape> {
        self.0[0].gpu_shape()
    }

    fn parallelism(&self) -> usize {
        self.0.len()
    }

    fn run(&self, round: &Round) -> Result<Vec<Output>> {
        let context = round.context;
        let n = self.0.len();
        std::thread::scope(|scope| {
            let shares: Vec<_> = self
                .0
                .iter()
                .enumerate()
                .map(|(k, evaluator)| {
                    scope.spawn(move || -> Result<Vec<Output>> {
                        round
                            .tasks
                            .iter()
                            .skip(k)
                            .step_by(n)
                            .map(|task| execute(evaluator, context, task))
                            .collect()
                    })
                })
                .collect();
            let mut outputs = Vec::with_capacity(round.tasks.len());
            for share in shares {
                outputs.extend(share.join().expect("a device's thread does not panic")?);
            }
            Ok(outputs)
        })
    }
}

/// Which devices of this machine a run scores on.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "lowercase")]
pub enum Devices {
    /// One: the GPU the environment names (`BITROCK_ADAPTER`, `CUDA_VISIBLE_DEVICES`), or the
    /// CPU.
    #[default]
    One,
    /// Every GPU of the machine, each scoring a share of every round.
    All,
}

/// The workers of this process: one evaluator on `backend`, or with [`Devices::All`] one per
/// GPU (under `auto`, the CPU when there is none, said through `note`).
pub fn here(
    problem: Problem,
    backend: crate::eval::Backend,
    devices: Devices,
    wish: ShapeWish,
    note: &mut dyn FnMut(String),
) -> Result<Box<dyn Workers>> {
    use crate::eval::Backend;
    if devices == Devices::All && backend != Backend::Cpu {
        match crate::eval::gpu::residual::GpuEvaluator::on_every_gpu(&problem, wish) {
            Ok(gpus) => {
                let names: Vec<String> = gpus.iter().map(|g| g.adapter()).collect();
                note(format!(
                    "{} on {} devices ({} scoring, {}): {}",
                    crate::eval::GPU_BACKEND_NOTE,
                    gpus.len(),
                    gpus[0].shape(),
                    gpus[0].shape_source(),
                    names.join("; ")
                ));
                return Ok(Box::new(Several(gpus)));
            }
            Err(e) if backend == Backend::Auto => crate::eval::fall_back_to_cpu(e, note)?,
            Err(e) => return Err(e.into()),
        }
    }
    Ok(Box::new(Local(crate::eval::evaluator(problem, backend, wish, note)?)))
}

/// Runs one task with `evaluator`: what every worker does, here or elsewhere.
pub fn execute(evaluator: &dyn Evaluator, context: Option<&dyn Proposal>, task: &Task) -> Result<Output> {
    let needs_context =
        || context.ok_or_else(|| Error::Numerical("a proposal task arrived without its population's proposal".into()));
    match *task {
        Task::Scan {
            stream,
            start,
            len,
            epsilon,
        } => {
            let mut rho = vec![0.0; to_usize(len)?];
            evaluator.score(stream, start, &mut rho)?;
            let problem = evaluator.problem();
            let slots: Vec<u8> = (0..rho.len())
                .into_par_iter()
                .with_min_len(4096)
                .map(|k| problem.prior.candidate_slot(problem.seed, stream, start + k as u64) as u8)
                .collect();
            let kept = keep(start, &rho, epsilon);
            let (slots, prefix) = slot_counts(problem.prior.boxes.len(), start, &slots, &kept);
            Ok(Output::Found {
                start,
                len,
                scored: len,
                kept,
                slots,
                prefix,
            })
        }
        Task::Propose {
            stream,
            start,
            len,
            epsilon,
        } => {
            let Proposed { scored, kept, slots } =
                needs_context()?.propose_and_score(evaluator, stream, start..start + len, epsilon)?;
            let (slots, prefix) = slot_counts(evaluator.problem().prior.boxes.len(), start, &slots, &kept);
            Ok(Output::Found {
                start,
                len,
                scored,
                kept,
                slots,
                prefix,
            })
        }
        Task::Weigh { first, ref particles } => {
            let values = needs_context()?.log_weights(evaluator, particles)?;
            Ok(Output::LogWeights { first, values })
        }
        Task::Score {
            first,
            ref candidates,
            lagged,
        } => {
            let mut rho = vec![0.0; candidates.len()];
            let mut lag = Vec::new();
            if lagged {
                lag.resize(candidates.len(), 0.0);
                evaluator.score_params_lagged(candidates, &mut rho, &mut lag)?;
            } else {
                evaluator.score_params(candidates, &mut rho)?;
            }
            Ok(Output::Scores { first, rho, lag })
        }
    }
}

fn to_usize(len: u64) -> Result<usize> {
    usize::try_from(len).map_err(|_| Error::Numerical(format!("a task of {len} candidates")))
}

/// (index, ρ) of the candidates of `rho` (candidate `start` first) kept at `epsilon`.
pub(crate) fn keep(start: u64, rho: &[f64], epsilon: f64) -> Vec<(u64, f64)> {
    rho.iter()
        .enumerate()
        .filter(|&(_, &r)| kept(r, epsilon))
        .map(|(k, &r)| (start + k as u64, r))
        .collect()
}

/// The draws per slot of candidates `start ..` whose slots are `slots`, and at each `kept`
/// candidate the draws per slot up to it (see [`Output::Found`]).
fn slot_counts(n: usize, start: u64, slots: &[u8], kept: &[(u64, f64)]) -> (Vec<u64>, Vec<u64>) {
    let mut running = vec![0u64; n];
    let mut prefix = Vec::with_capacity(kept.len() * n);
    let mut at = 0usize;
    for &(index, _) in kept {
        let upto = (index - start) as usize + 1;
        for &slot in &slots[at..upto] {
            running[slot as usize] += 1;
        }
        at = upto;
        prefix.extend_from_slice(&running);
    }
    for &slot in &slots[at..] {
        running[slot as usize] += 1;
    }
    (running, prefix)
}

/// Tasks under this many candidates or particles are not cut further: below it the cost of a
/// task's round trip outweighs its work.
pub const MIN_TASK: u64 = 4096;

/// [`MIN_TASK`] for candidates that are each a string simulated over a record (a millisecond
/// or more, not a microsecond): enough for a worker's lanes of eight strings on each of its
/// threads.
pub const MIN_STRING_TASK: u64 = 64;

/// Cuts `start .. start + len` into at most `pieces` contiguous ranges of near-equal length,
/// none shorter than [`MIN_TASK`] unless the whole is.
pub fn split(start: u64, len: u64, pieces: usize) -> Vec<(u64, u64)> {
    split_from(start, len, pieces, MIN_TASK)
}

/// Cuts a round's `start .. start + len` into the tasks `workers` take: at most one per unit
/// of their parallelism, none shorter than their [`Workers::min_task_len`] unless the whole is.
pub fn split_for(workers: &(impl Workers + ?Sized), start: u64, len: u64) -> Vec<(u64, u64)> {
    split_from(start, len, workers.parallelism(), workers.min_task_len())
}

/// Explicit candidates a [`Task::Score`] holds at least, unless the batch is smaller: a
/// candidate is shipped (its law slot and six f32, about 25 bytes of postcard) rather than
/// named, and a batch of them (a sweep of the evidence sampler) is a few thousand, which
/// should still reach every worker.
pub const MIN_SCORE_TASK: u64 = 256;

/// [`split`] with pieces no shorter than `least` unless the whole is.
fn split_from(start: u64, len: u64, pieces: usize, least: u64) -> Vec<(u64, u64)> {
    let pieces = (pieces.max(1) as u64).min(len.div_ceil(least.max(1))).max(1);
    let (base, extra) = (len / pieces, len % pieces);
    let mut ranges = Vec::with_capacity(pieces as usize);
    let mut at = start;
    for k in 0..pieces {
        let n = base + u64::from(k < extra);
        ranges.push((at, n));
        at += n;
    }
    ranges
}

/// The candidates of a round, merged from its tasks' outputs in index order: what a scan of
/// the whole round in one process sees.
pub(crate) struct Found {
    pub start: u64,
    pub len: u64,
    pub scored: u64,
    pub kept: Vec<(u64, f64)>,
    /// Per task, in index order: its range and its draws per slot.
    parts: Vec<(u64, u64, Vec<u64>)>,
    /// Draws per slot from the start of its task to each kept candidate (see [`Output::Found`]).
    prefix: Vec<u64>,
    /// Prior slots.
    slots: usize,
}

impl Found {
    /// One past the last candidate of the round.
    pub fn end(&self) -> u64 {
        self.start + self.len
    }

    /// Adds the draws per slot of candidates `from .. to` to `counts`. Each end lies at a
    /// task's start or end, or just past a kept candidate: where a scan starts and stops.
    pub fn add_draws(&self, from: u64, to: u64, counts: &mut [u64]) {
        for (start, end, totals) in &self.parts {
            let (lo, hi) = (from.max(*start), to.min(*end));
            if lo >= hi {
                continue;
            }
            let upper = self.drawn_before(hi, *start, *end, totals);
            let lower = self.drawn_before(lo, *start, *end, totals);
            for (c, (u, l)) in counts.iter_mut().zip(upper.iter().zip(&lower)) {
                *c += u - l;
            }
        }
    }

    /// Draws per slot of a task's candidates `start .. position`.
    fn drawn_before(&self, position: u64, start: u64, end: u64, totals: &[u64]) -> Vec<u64> {
        if position == start {
            return vec![0; self.slots];
        }
        if position == end {
            return totals.to_vec();
        }
        let k = self
            .kept
            .binary_search_by_key(&(position - 1), |&(index, _)| index)
            .expect("a scan stops just past a kept candidate");
        self.prefix[k * self.slots..(k + 1) * self.slots].to_vec()
    }
}

/// Runs `tasks` (scans or proposals covering `start .. start + len`) on `workers` and merges
/// their outputs, checking that they cover the round exactly once.
pub(crate) fn run_found(workers: &dyn Workers, round: &Round, start: u64, len: u64) -> Result<Found> {
    let slots = workers.problem().prior.boxes.len();
    let mut outputs: Vec<Output> = workers.run(round)?;
    outputs.sort_by_key(|o| match o {
        Output::Found { start, .. } => *start,
        Output::LogWeights { .. } | Output::Scores { .. } => 0,
    });
    let mut merged = Found {
        start,
        len,
        scored: 0,
        kept: Vec::new(),
        parts: Vec::new(),
        prefix: Vec::new(),
        slots,
    };
    let mut at = start;
    for output in outputs {
        let Output::Found {
            start: s,
            len: n,
            scored,
            kept,
            slots: totals,
            prefix,
        } = output
        else {
            return Err(unexpected("another task's result for a scan"));
        };
        let end = s + n;
        if s != at
            || kept.iter().any(|&(i, _)| i < s || i >= end)
            || totals.len() != slots
            || prefix.len() != kept.len() * slots
        {
            return Err(unexpected(&format!(
                "a result for candidates {s}..{end} where {at} was next"
            )));
        }
        at = end;
        merged.scored += scored;
        merged.kept.extend(kept);
        merged.prefix.extend(prefix);
        merged.parts.push((s, end, totals));
    }
    if at != start + len {
        return Err(unexpected(&format!(
            "results end at candidate {at}, not {}",
            start + len
        )));
    }
    Ok(merged)
}

/// Runs `tasks` (weighings of `n` particles) on `workers` and merges their log weights.
pub(crate) fn run_log_weights(workers: &dyn Workers, round: &Round, n: usize) -> Result<Vec<f64>> {
    let mut outputs: Vec<(usize, Vec<f64>)> = workers
        .run(round)?
        .into_iter()
        .map(|o| match o {
            Output::LogWeights { first, values } => Ok((first, values)),
            _ => Err(unexpected("another task's result for a weighing")),
        })
        .collect::<Result<_>>()?;
    outputs.sort_by_key(|o| o.0);
    let mut merged = Vec::with_capacity(n);
    for (first, values) in outputs {
        if first != merged.len() {
            return Err(unexpected(&format!(
                "weights from particle {first} where {} was next",
                merged.len()
            )));
        }
        merged.extend(values);
    }
    if merged.len() != n {
        return Err(unexpected(&format!("{} weights for {n} particles", merged.len())));
    }
    Ok(merged)
}

/// ρ of `candidates` (and, when `lagged`, their lag-1 sums) scored by `workers`, in order:
/// the batch cut into [`Task::Score`]s, a task per piece. Each candidate's score depends on it
/// alone, so the cut does not change a bit of the result. `round` names the round in the
/// workers' traffic.
pub fn score_candidates(
    workers: &dyn Workers,
    round: usize,
    candidates: &[Candidate],
    lagged: bool,
    rho: &mut Vec<f64>,
    lag: &mut Vec<f64>,
) -> Result<()> {
    let tasks = split_from(0, candidates.len() as u64, workers.parallelism(), MIN_SCORE_TASK)
        .into_iter()
        .map(|(first, len)| Task::Score {
            first: first as usize,
            candidates: candidates[first as usize..(first + len) as usize].to_vec(),
            lagged,
        })
        .collect();
    let mut outputs: Vec<(usize, Vec<f64>, Vec<f64>)> = workers
        .run(&Round {
            population: round,
            context: None,
            tasks,
        })?
        .into_iter()
        .map(|o| match o {
            Output::Scores { first, rho, lag } => Ok((first, rho, lag)),
            _ => Err(unexpected("another task's result for explicit candidates")),
        })
        .collect::<Result<_>>()?;
    outputs.sort_by_key(|o| o.0);
    rho.clear();
    lag.clear();
    for (first, values, lags) in outputs {
        if first != rho.len() || (lagged && lags.len() != values.len()) {
            return Err(unexpected(&format!(
                "scores from candidate {first} where {} was next",
                rho.len()
            )));
        }
        rho.extend(values);
        lag.extend(lags);
    }
    if rho.len() != candidates.len() {
        return Err(unexpected(&format!(
            "{} scores for {} candidates",
            rho.len(),
            candidates.len()
        )));
    }
    Ok(())
}

fn unexpected(what: &str) -> Error {
    Error::Worker(format!("the workers returned {what}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_split_covers_its_range_once_in_near_equal_pieces() {
        for (start, len, pieces) in [(0, 10, 3), (7, 100_000, 3), (5, 4096 * 3 + 1, 8), (9, 1, 4), (0, 0, 2)] {
            let ranges = split(start, len, pieces);
            let mut at = start;
            for &(s, n) in &ranges {
                assert_eq!(s, at);
                at += n;
            }
            assert_eq!(at, start + len, "{start} {len} {pieces}: {ranges:?}");
            assert!(ranges.len() <= pieces.max(1));
            let (lo, hi) = ranges.iter().fold((u64::MAX, 0), |(a, b), r| (a.min(r.1), b.max(r.1)));
            assert!(hi - lo <= 1, "{ranges:?}");
        }
        // Short rounds are not cut below MIN_TASK.
        assert_eq!(split(0, 5000, 8).len(), 2);
        assert_eq!(split(0, 4096, 8), vec![(0, 4096)]);
    }

    #[test]
    fn kept_holds_every_candidate_the_acceptance_and_near_counts_see() {
        let eps = 0.0123;
        for rho in [
            0.0,
            eps * 0.5,
            eps * (1.0 - 1e-5),
            eps,
            eps * (1.0 + 1e-5),
            eps * (1.0 + 1.5e-5),
        ] {
            assert!(kept(rho, eps), "{rho}");
        }
        assert!(!kept(eps * (1.0 + 3e-5), eps));
        assert!(!kept(f64::NAN, eps) && !kept(f64::NAN, f64::INFINITY));
        assert!(kept(1e300, f64::INFINITY));
    }
}
