//! The population loop the samplers share: batches until N particles are accepted or a run
//! budget (wall time, draws) interrupts, progress after every batch, and the population's
//! record. What a batch is (a scan of a candidate stream, or kernel proposals) is the
//! sampler's own.

use super::{LawRecord, Observer, Particle, Population, PopulationRecord, Progress, StopReason};
use crate::error::Result;
use crate::eval::{PARITY_TOLERANCE, Problem};
use crate::prior::Prior;
use std::ops::ControlFlow;
use std::time::Instant;

/// A population being filled: its particles so far and its per-law counts.
pub(crate) struct Filling {
    pub index: usize,
    pub stream: u32,
    /// ε of this population; ∞ for population 0 without a start.
    pub epsilon: f64,
    /// Particles wanted, N.
    pub target: usize,
    pub particles: Vec<Particle>,
    /// Candidates considered, per prior slot.
    pub law_draws: Vec<u64>,
    /// Particles accepted, per prior slot.
    pub law_accepted: Vec<usize>,
    /// Candidates considered (stream positions for the rejection sampler).
    pub position: u64,
    /// Candidates with ρ within the parity tolerance of ε.
    pub near: u64,
    /// Candidates scored by this population.
    pub scored: u64,
    data_len: u64,
    started: Instant,
}

/// What a run has spent before the population in progress: the limits its budgets apply to.
pub(crate) struct Spent {
    pub started: Instant,
    pub scored: u64,
}

impl Spent {
    /// A run starting now after the completed populations `previous`, whose candidates count.
    pub fn after(previous: &[Population]) -> Self {
        Spent {
            started: Instant::now(),
            scored: previous.iter().map(|p| p.record.candidates_scored).sum(),
        }
    }

    /// The run's result: its `populations`, why it stopped, its evaluations (candidates
    /// scored × `data_len`) and its wall time.
    pub fn finish(&self, populations: Vec<Population>, stop: StopReason, data_len: u64) -> super::Run {
        super::Run {
            populations,
            stop,
            evaluations: self.scored * data_len,
            seconds: self.started.elapsed().as_secs_f64(),
        }
    }
}

impl Filling {
    pub fn new(index: usize, stream: u32, epsilon: f64, target: usize, prior: &Prior, data_len: u64) -> Self {
        Filling {
            index,
            stream,
            epsilon,
            target,
            particles: Vec::with_capacity(target),
            law_draws: vec![0; prior.boxes.len()],
            law_accepted: vec![0; prior.boxes.len()],
            position: 0,
            near: 0,
            scored: 0,
            data_len,
            started: Instant::now(),
        }
    }

    /// Whether `rho` lies within the CPU/GPU parity tolerance of ε, where the backends could
    /// decide differently; ε = ∞ decides nothing near a threshold.
    pub fn near_threshold(&self, rho: f64) -> bool {
        self.epsilon.is_finite() && (rho - self.epsilon).abs() <= PARITY_TOLERANCE * self.epsilon
    }

    /// Goes through `kept` (candidates in index order, each with its ρ): counts those near ε,
    /// picks those below ε until N particles would be reached. Returns the picked (index, ρ)
    /// and the index one past the last candidate considered (`end` when all of them were).
    pub fn pick_below_epsilon(&mut self, kept: &[(u64, f64)], end: u64) -> (Vec<(u64, f64)>, u64) {
        let mut picked = Vec::new();
        for &(index, rho) in kept {
            self.near += u64::from(self.near_threshold(rho));
            if rho < self.epsilon {
                picked.push((index, rho));
                if self.particles.len() + picked.len() == self.target {
                    return (picked, index + 1);
                }
            }
        }
        (picked, end)
    }

    /// Calls `batch` with the draw budget left until N particles are accepted; stops early,
    /// with the reason, when the run's wall time or draw budget runs out (`batch` decides
    /// whether a budget of 0 stops it: it may still hold scored candidates). The observer sees
    /// the progress after every batch, and may interrupt the run there.
    pub fn fill(
        &mut self,
        limits: &super::schedule::Schedule,
        spent: &Spent,
        observer: &mut dyn Observer,
        mut batch: impl FnMut(&mut Self, u64) -> Result<ControlFlow<StopReason>>,
    ) -> Result<Option<StopReason>> {
        while self.particles.len() < self.target {
            if let Some(limit) = limits.max_seconds
                && spent.started.elapsed().as_secs_f64() > limit
            {
                return Ok(Some(StopReason::WallTime));
            }
            let budget = limits.max_draws.saturating_sub(spent.scored + self.scored);
            if let ControlFlow::Break(stop) = batch(self, budget)? {
                return Ok(Some(stop));
            }
            observer.progress(&Progress {
                population: self.index,
                epsilon: self.epsilon_shown(),
                accepted: self.particles.len(),
                target: self.target,
                draws: self.position,
                scored: self.scored,
                data_len: self.data_len as usize,
                seconds: self.started.elapsed().as_secs_f64(),
            });
            if observer.interrupted() {
                return Err(crate::Error::Interrupted);
            }
        }
        Ok(None)
    }

    /// ε as records show it: `None` for ∞.
    fn epsilon_shown(&self) -> Option<f64> {
        self.epsilon.is_finite().then_some(self.epsilon)
    }

    /// Each law's record, with the probability and liveness `of_slot` gives for its slot.
    pub fn law_records(&self, problem: &Problem, of_slot: impl Fn(usize) -> (f64, bool)) -> Vec<LawRecord> {
        let prior = &problem.prior;
        prior
            .boxes
            .iter()
            .enumerate()
            .map(|(s, b)| {
                let (probability, alive) = of_slot(s);
                LawRecord::new(
                    b.law,
                    self.law_draws[s],
                    self.law_accepted[s],
                    probability,
                    alive,
                    problem,
                    self.epsilon,
                )
            })
            .collect()
    }

    /// The completed population with its per-law records and effective sample size.
    pub fn into_population(self, per_law: Vec<LawRecord>, ess: f64) -> Population {
        let n = self.particles.len();
        let record = PopulationRecord {
            index: self.index,
            epsilon: self.epsilon_shown(),
            draws: self.position,
            accepted: n,
            acceptance_rate: n as f64 / self.position as f64,
            per_law,
            candidates_scored: self.scored,
            evaluations: self.scored * self.data_len,
            near_threshold: self.near,
            ess,
            seconds: self.started.elapsed().as_secs_f64(),
            stream: self.stream,
        };
        Population {
            record,
            particles: self.particles,
        }
    }
}
