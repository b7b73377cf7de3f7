//! Approximate Bayesian Computation with model selection: the paper's rejection sampler
//! (Algorithm 1), the records every sampler shares, and the posterior summaries a user reads
//! off a population.
//!
//! A sampler runs populations one after another and hands each finished [`Population`] to an
//! [`Observer`] (the run store writes it in one transaction), so a run can be continued from
//! the populations it already has: given the same configuration and the same completed
//! populations, a sampler continues exactly as an uninterrupted run would.

pub mod evidence;
mod fill;
pub mod floor;
pub mod posterior;
pub mod rejection;
pub mod schedule;
pub mod shard;
pub mod smc;
pub mod worker;

use crate::error::Result;
use crate::eval::Problem;
use crate::laws::Law;
use serde::{Deserialize, Serialize};

/// One accepted particle: a law, its parameters (SI; for the rejection sampler the f32 values
/// the candidate generator produced, widened exactly to f64), its misfit ρ and its importance
/// weight.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Particle {
    pub law: Law,
    /// Candidate index within its stream: with the seed and population it regenerates the
    /// particle (see `crate::rng`).
    pub index: u64,
    /// The law's parameters (SI), then any coordinates its prior box carries past them (the
    /// string's natural frequency and damping ratio of a run that infers them).
    pub params: Vec<f64>,
    pub rho: f64,
    /// Importance weight, normalised over the population (Σ w = 1). Rejection sampling gives
    /// every particle 1/N.
    pub weight: f64,
}

/// Per-law counts of one population.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LawRecord {
    pub law: Law,
    /// Candidates of this law considered.
    pub draws: u64,
    pub accepted: usize,
    pub acceptance_rate: f64,
    /// Posterior probability of the law in this population: its share of the weight.
    pub probability: f64,
    /// Whether the sampler proposes this law in the next population. Rejection draws every
    /// law from the prior (always true); in SMC a law with no particle here is dead: it gets
    /// no more proposals, and later records keep it with 0 draws, 0 accepted, probability 0.
    #[serde(default = "true_by_default")]
    pub alive: bool,
    /// Whether the law can reach the population's ε at all. When its best least-squares ρ on
    /// the calibration data is at or above ε (and none of its candidates was accepted), no
    /// candidate of it can be accepted: its probability is 0 by construction, not evidence
    /// against it.
    #[serde(default = "true_by_default")]
    pub reachable: bool,
}

impl LawRecord {
    /// The record of a law with `accepted` of `draws` candidates accepted (rate 0 when none
    /// was drawn) in a population at tolerance `epsilon` of `problem`.
    pub fn new(
        law: Law,
        draws: u64,
        accepted: usize,
        probability: f64,
        alive: bool,
        problem: &Problem,
        epsilon: f64,
    ) -> Self {
        Self {
            law,
            draws,
            accepted,
            acceptance_rate: if draws > 0 { accepted as f64 / draws as f64 } else { 0.0 },
            probability,
            alive,
            reachable: accepted > 0 || problem.can_reach(law, epsilon),
        }
    }

    /// True when the law's probability is 0 because no candidate of it can reach ε.
    pub fn zero_by_construction(&self) -> bool {
        !self.reachable
    }
}

fn true_by_default() -> bool {
    true
}

/// What happened in one population.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PopulationRecord {
    pub index: usize,
    /// ε_g; `None` for ∞.
    pub epsilon: Option<f64>,
    /// Candidates considered (stream positions scanned), what a fresh rejection sample costs.
    pub draws: u64,
    pub accepted: usize,
    pub acceptance_rate: f64,
    pub per_law: Vec<LawRecord>,
    /// New candidates scored in this population.
    pub candidates_scored: u64,
    /// candidates_scored × data points.
    pub evaluations: u64,
    /// Candidates considered whose ρ lies within the CPU/GPU parity tolerance of ε
    /// ([`crate::eval::PARITY_TOLERANCE`]): the only ones another backend may decide otherwise.
    pub near_threshold: u64,
    /// Kish effective sample size (Σw)²/Σw² of the particles' weights; N for equal weights.
    pub ess: f64,
    pub seconds: f64,
    /// The candidate stream (population counter) the particles come from.
    pub stream: u32,
}

/// A population whose effective sample size is below this share of its particles is thin: its
/// estimates rest on a few heavily weighted particles, and every output says so.
pub const MIN_ESS_SHARE: f64 = 0.1;

/// True when `ess` is below [`MIN_ESS_SHARE`] of `particles` (never for an empty population).
pub fn is_thin(ess: f64, particles: usize) -> bool {
    particles > 0 && ess < MIN_ESS_SHARE * particles as f64
}

impl PopulationRecord {
    /// True when the effective sample size is below [`MIN_ESS_SHARE`] of the particles.
    pub fn thin(&self) -> bool {
        is_thin(self.ess, self.accepted)
    }

    /// P(`law`) in this population; 0 for a law not in it.
    pub fn probability_of(&self, law: Law) -> f64 {
        self.per_law
            .iter()
            .find(|r| r.law == law)
            .map_or(0.0, |r| r.probability)
    }

    /// The laws whose probability in this population is 0 by construction (see
    /// [`LawRecord::reachable`]).
    pub fn unreachable_laws(&self) -> Vec<Law> {
        self.per_law
            .iter()
            .filter(|l| l.zero_by_construction())
            .map(|l| l.law)
            .collect()
    }

    /// What a reader of this population's model probabilities must be told, in sentences:
    /// which probabilities are 0 by construction, and when the ranking is decided by the laws'
    /// best least-squares ρ alone (a single law can reach ε). Empty when every law can.
    pub fn probability_caveats(&self) -> Vec<String> {
        let unreachable = self.unreachable_laws();
        if unreachable.is_empty() {
            return Vec::new();
        }
        let names: Vec<&str> = unreachable.iter().map(|l| l.name()).collect();
        let epsilon = self.epsilon.map_or("∞".to_string(), |e| format!("{e:.5}"));
        let mut caveats = vec![format!(
            "P = 0 by construction for {}: ε = {epsilon} is at or below {} best least-squares ρ, so no candidate of {} could be accepted; this is not evidence against {}.",
            names.join(", "),
            if names.len() == 1 { "its" } else { "their" },
            if names.len() == 1 { "it" } else { "them" },
            if names.len() == 1 { "it" } else { "them" },
        )];
        let reachable: Vec<&str> = self
            .per_law
            .iter()
            .filter(|l| l.reachable)
            .map(|l| l.law.name())
            .collect();
        if let [only] = reachable.as_slice() {
            caveats.push(format!(
                "Only {only} can reach ε = {epsilon}: its probability 1 says that its best least-squares ρ is the lowest, and nothing more; the ranking is decided by best-fit ρ alone."
            ));
        }
        caveats
    }
}

/// A tolerance more than this many likelihood scales ρ_best/n above the best fit's ρ_best makes
/// ABC's model probabilities ratios of prior volumes: ε − ρ_best > 10·ρ_best/n is an
/// acceptance region about (n/2)·ln(ε/ρ_best) ≥ 5 nats deep in the log-likelihood
/// −(n/2)·ln ρ, all of it accepted alike.
pub const LIKELIHOOD_SCALES: f64 = 10.0;

/// What a reader of ABC's model probabilities at tolerance `epsilon` must be told when it lies
/// far above the likelihood's scale (see [`LIKELIHOOD_SCALES`]); `best_rho` is the best
/// least-squares ρ of the laws compared on the `data_len` calibration samples.
pub fn prior_volume_caveat(epsilon: f64, best_rho: f64, data_len: usize) -> Option<String> {
    let n = data_len as f64;
    let scale = best_rho / n;
    if !(best_rho > 0.0 && epsilon - best_rho > LIKELIHOOD_SCALES * scale) {
        return None;
    }
    let depth = n / 2.0 * (epsilon / best_rho).ln();
    Some(format!(
        "ε = {epsilon:.5} lies {:.0} likelihood scales above the best fit (ρ_best = {best_rho:.5}, ρ_best/n = {scale:.2e}): every candidate within about {depth:.0} nats of the best likelihood is accepted alike, so these model probabilities are ratios of the laws' prior volumes below ε, not evidence; the model evidence (`bitrock evidence`, `bitrock.evidence` in Python) weighs each candidate by its likelihood",
        (epsilon - best_rho) / scale
    ))
}

/// One population: its record and particles in index order.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Population {
    pub record: PopulationRecord,
    pub particles: Vec<Particle>,
}

/// Why a run ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StopReason {
    /// ε reached the floor eps_min.
    EpsMin,
    /// The user's ε schedule ran out.
    ScheduleExhausted,
    MaxPopulations,
    /// The projected acceptance of the next population fell below the floor.
    AcceptanceFloor,
    /// The draw budget ran out inside a population (which was dropped).
    MaxDraws,
    /// The wall-time budget ran out inside a population (which was dropped).
    WallTime,
    /// The median rule lowered ε by less than [`schedule::STALL_FRACTION`]: ε is near the
    /// best ρ the laws can attain, and each further population would cost more draws for
    /// almost no change.
    Stalled,
}

impl StopReason {
    /// A sentence for people.
    pub fn describe(self) -> &'static str {
        match self {
            StopReason::EpsMin => "the tolerance reached the run's floor ε_min",
            StopReason::ScheduleExhausted => "the `epsilons` schedule ran out",
            StopReason::MaxPopulations => "`max_populations` populations were drawn",
            StopReason::AcceptanceFloor => {
                "the projected acceptance of the next population's new candidates (for SMC with survivors, of its top-up) fell below `min_acceptance`"
            }
            StopReason::MaxDraws => "`max_draws` candidates were scored (the last population was incomplete)",
            StopReason::WallTime => "`max_seconds` ran out (the last population was incomplete)",
            StopReason::Stalled => {
                "the tolerance stalled (the median rule lowered it by less than 1 %): it is near the best ρ the laws can attain"
            }
        }
    }
}

/// The result of a run: every population (those it was continued from included). A run
/// written to a store holds only the last population's particles (see
/// `complete_population`); read the others with [`crate::run::abc::Store::load_particles`].
#[derive(Clone, Debug)]
pub struct Run {
    pub populations: Vec<Population>,
    pub stop: StopReason,
    /// Candidate × data-point evaluations over the run (all populations).
    pub evaluations: u64,
    /// Seconds of this invocation (a continued run counts only its own time).
    pub seconds: f64,
}

/// Where a population in progress stands, for progress bars and logs.
#[derive(Clone, Copy, Debug)]
pub struct Progress {
    pub population: usize,
    /// ε of the population being filled; `None` for ∞.
    pub epsilon: Option<f64>,
    pub accepted: usize,
    /// Particles wanted, N.
    pub target: usize,
    /// Candidates considered so far in this population.
    pub draws: u64,
    /// Candidates scored so far in this population.
    pub scored: u64,
    /// Data points per candidate, D.
    pub data_len: usize,
    /// Seconds since the population started.
    pub seconds: f64,
}

/// Watches a run: its progress, its finished populations and what the user should know
/// about it. Every method has a default that does nothing.
pub trait Observer {
    /// After every scored batch of a population in progress.
    fn progress(&mut self, _progress: &Progress) {}
    /// When a population is complete, before the next one starts; `previous` is the
    /// population before it (`None` for population 0). An error (the store could not write
    /// it, say) ends the run with that error.
    fn population_done(&mut self, _population: &Population, _previous: Option<&Population>) -> Result<()> {
        Ok(())
    }
    /// True when the observer keeps every completed population's particles itself (the run
    /// store does): the sampler then releases them once no population needs them, so that a
    /// run holds the particles of two populations at most (see `complete_population`).
    fn keeps_particles(&self) -> bool {
        false
    }
    /// A line for the user, said once: a fallback to the CPU, a tolerance floor moved to the
    /// record's reach, a resume that added nothing.
    fn note(&mut self, _line: String) {}
    /// Asked after every batch: true stops the run with [`crate::Error::Interrupted`], the
    /// population in progress dropped and those completed kept (stored, for a run directory).
    fn interrupted(&mut self) -> bool {
        false
    }
}

/// Hands a finished `population` to `observer` and appends it to `populations`. When the
/// observer keeps the particles ([`Observer::keeps_particles`]), those of the population
/// before it are released: a sampler needs only the last population's, so memory stays at
/// the particles of two populations (the last and the one being drawn) instead of growing
/// with every population; [`Run::populations`] then holds all records and only the last
/// population's particles.
pub(crate) fn complete_population(
    populations: &mut Vec<Population>,
    population: Population,
    observer: &mut dyn Observer,
) -> Result<()> {
    observer.population_done(&population, populations.last())?;
    if observer.keeps_particles()
        && let Some(previous) = populations.last_mut()
    {
        previous.particles = Vec::new();
    }
    populations.push(population);
    Ok(())
}

/// An observer that watches nothing.
pub struct Silent;

impl Observer for Silent {}

/// Kish's effective sample size (Σw)²/Σw²; 0 for no weights.
pub fn effective_sample_size(weights: &[f64]) -> f64 {
    let sum = crate::numerics::compensated_sum(weights.iter().copied());
    let sum_sq = crate::numerics::compensated_sum(weights.iter().map(|w| w * w));
    if sum_sq > 0.0 { sum * sum / sum_sq } else { 0.0 }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_tolerance_far_above_the_likelihood_scale_is_said_to_give_prior_volume_ratios() {
        // n = 1000, ρ_best = 0.01: the scale is 1e-5, ten of them 1e-4.
        assert!(prior_volume_caveat(0.0100999, 0.01, 1000).is_none());
        let said = prior_volume_caveat(0.014, 0.01, 1000).unwrap();
        // (n/2)·ln(1.4) = 168 nats deep; 400 scales above.
        assert!(
            said.contains("400 likelihood scales") && said.contains("168 nats"),
            "{said}"
        );
        assert!(prior_volume_caveat(0.014, 0.0, 1000).is_none());
    }

    #[test]
    fn a_population_is_thin_below_a_tenth_of_its_particles_in_effective_size() {
        let record = |accepted: usize, ess: f64| PopulationRecord {
            index: 1,
            epsilon: Some(0.1),
            draws: 10 * accepted as u64,
            accepted,
            acceptance_rate: 0.1,
            per_law: Vec::new(),
            candidates_scored: 0,
            evaluations: 0,
            near_threshold: 0,
            ess,
            seconds: 0.0,
            stream: 1,
        };
        assert!(record(1000, 99.9).thin());
        assert!(!record(1000, 100.0).thin());
        assert!(!record(1000, 1000.0).thin());
        // An empty population has no particles to be thin about.
        assert!(!record(0, 0.0).thin());
        // Equal weights: ESS = N.
        assert!((effective_sample_size(&[0.25; 4]) - 4.0).abs() < 1e-12);
        assert!((effective_sample_size(&[0.97, 0.01, 0.01, 0.01]) - 1.0 / 0.9412).abs() < 1e-12);
    }
}
