//! Can the evidence be trusted on records like this one? A confusion matrix by re-simulation,
//! as `check-selection` makes one for an ABC run.
//!
//! For every law, K synthetic records are made at the record's own calibration speeds (and
//! weight-on-bit ratios): parameters drawn by weight from the law's evidence posterior, plus
//! noise resampled with replacement from the law's least-squares residuals (the record's noise
//! level and distribution). Each synthetic record is fitted (starting from the record's own
//! estimates and the generating parameters) and its evidence computed over the *same* boxes
//! as the record's, with its own seed ([`crate::run::selection::replicate_seed`]).
//!
//! Each replicate's evidence is a lighter one than the record's ([`Job::for_replicates`]): at
//! most [`REPLICATE_PARTICLES`] particles in [`REPLICATE_ISLANDS`] islands per law, from the
//! replicate's own least-squares fit where the record's job starts from it, and no refinement.
//! The check asks whether the data decide, which a replicate's fits and its posterior's mean
//! log-likelihood say, not for each replicate's ln Z to a tenth of a nat; so at
//! [`DEFAULT_REPLICATES`] per law it costs a fraction of the record's own evidence (a fifth on
//! the embedded record), and runs by default wherever two laws or more are compared.
//!
//! A replicate's answer is the law of the largest posterior probability, and it is *decided*
//! when it beats every other law by at least positive odds beyond twice their error *and* by
//! the data ([`Strength::decides`]): its posterior's mean log-likelihood lies at least
//! [`DATA_DECIDES_NATS`](crate::abc::evidence::DATA_DECIDES_NATS) and its least-squares fit's
//! log-likelihood at least [`UNDECIDED_NATS`](crate::separation::UNDECIDED_NATS) above each
//! rival's, (n/2)·ln(ρ_rival / ρ_first). Otherwise it is
//! *undecided*: odds won with fits of equal quality are Occam factors, set by the priors (a
//! law that holds another, as m3 holds m2, fits any record of it as well and loses only by
//! the volume of its extra parameters). A trustworthy evidence is decided and right where the laws differ on the
//! record, and undecided (never decided and wrong) where they do not.

use super::{EvidenceAnalysis, Job};
use crate::abc::Observer;
use crate::abc::evidence::{NoiseModel, Start, Strength};
use crate::data::FieldData;
use crate::error::{Error, Result};
use crate::eval::Backend;
use crate::fit::residuals;
use crate::laws::Law;
use crate::run::selection::{draw_by_weight, replicate_seed, synthesize};
use crate::run::{Placement, Scoring};
use rand::SeedableRng;
use rand::rngs::StdRng;
use serde::{Deserialize, Serialize};
use std::time::Instant;

/// One synthetic record and what the evidence said about it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CheckReplicate {
    pub index: usize,
    /// Seed of its synthesis and of its samplers.
    pub seed: u64,
    /// The generating parameters, SI (torques N·m).
    pub params_si: Vec<f64>,
    /// ln Z and P(m | y) of each law of the check, in [`EvidenceCheck::laws`] order.
    pub ln_z: Vec<f64>,
    pub probabilities: Vec<f64>,
    /// The law of the largest probability (the first in law order among equals).
    pub first: Law,
    /// The law of the next largest, with ln of the posterior odds of `first` against it and
    /// that log's Monte-Carlo error; `None` with one law.
    pub runner_up: Option<Law>,
    pub ln_odds: f64,
    pub ln_odds_error: f64,
    /// The rival whose least-squares fit comes closest to `first`'s, and how far `first`'s
    /// log-likelihood lies above it, (n/2)·ln(ρ_rival / ρ_first), nats (negative where the
    /// rival fits better).
    pub closest_fit: Option<Law>,
    pub gap_nats: f64,
    /// True when, against every rival, the odds are at least positive beyond their error and
    /// the data, not the boxes, decide ([`Strength::decides`]).
    pub decided: bool,
}

/// The records made by one law.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CheckRow {
    pub law: Law,
    /// Mean P(m | y) of each law over the replicates.
    pub mean_probability: Vec<f64>,
    /// Share of the replicates in which each law ranks first.
    pub first_share: Vec<f64>,
    /// Shares of the replicates decided for this law, undecided, and decided for another.
    pub decided_right: f64,
    pub undecided: f64,
    pub decided_wrong: f64,
    /// One sentence for people.
    pub verdict: String,
    pub replicates: Vec<CheckReplicate>,
}

/// The evidence's confusion matrix on records like the one analysed.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EvidenceCheck {
    /// The laws: the columns (and rows) of the matrix.
    pub laws: Vec<Law>,
    /// Replicates per law, K.
    pub replicates: usize,
    /// How each replicate's evidence was sampled (absent from checks an earlier bitrock wrote).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sampler: Option<ReplicateSampler>,
    pub rows: Vec<CheckRow>,
    /// Candidates scored by all replicates' samplers.
    pub candidates_scored: u64,
    /// Wall time of the check, s.
    pub seconds: f64,
}

/// Log-likelihood within which a replicate's least-squares fits are polished, nats: far below
/// the nats that decide ([`crate::separation::UNDECIDED_NATS`],
/// [`DATA_DECIDES_NATS`](crate::abc::evidence::DATA_DECIDES_NATS)).
const FIT_RESOLUTION_NATS: f64 = 0.02;

/// Replicates per law of the check an evidence runs unless told otherwise.
pub const DEFAULT_REPLICATES: usize = 4;

/// Most particles of each island of a replicate's samplers.
pub const REPLICATE_PARTICLES: usize = 200;

/// Most islands per law and start of a replicate's samplers (two give its ln Z an error).
pub const REPLICATE_ISLANDS: usize = 2;

/// The replicates per law an evidence of `laws` laws is checked with, from what the user
/// asked: none asked, [`DEFAULT_REPLICATES`] where two laws or more are compared (a single law
/// has nothing to be told from); 0, no check.
pub fn replicates_asked(asked: Option<usize>, laws: usize) -> Option<usize> {
    match asked {
        None => (laws >= 2).then_some(DEFAULT_REPLICATES),
        Some(0) => None,
        Some(k) => Some(k),
    }
}

/// How each replicate's evidence was sampled, as the check's document says it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ReplicateSampler {
    pub particles: usize,
    pub islands: usize,
    pub start: Start,
}

impl Job {
    /// The evidence of each replicate: the record's job with at most [`REPLICATE_PARTICLES`]
    /// particles in [`REPLICATE_ISLANDS`] islands, from the replicate's own fit where the job
    /// starts from fits (a law whose fit has no covariance still starts from its box), not
    /// refined.
    pub fn for_replicates(&self) -> Job {
        let mut job = self.clone();
        let sampler = &mut job.sampler;
        sampler.particles = sampler.particles.min(REPLICATE_PARTICLES);
        for (_, n) in &mut sampler.law_particles {
            *n = (*n).min(REPLICATE_PARTICLES);
        }
        sampler.islands = sampler.islands.min(REPLICATE_ISLANDS);
        if sampler.start == Start::Both {
            sampler.start = Start::Fit;
        }
        sampler.refine_rounds = 0;
        job
    }
}

/// Refuses, naming `field`, a check of no replicates (before any work).
pub fn check_replicates(replicates: usize, field: &str) -> Result<()> {
    if replicates == 0 {
        return Err(Error::setting(field, "must be at least 1 replicate per law"));
    }
    Ok(())
}

/// Refuses, naming `field`, a check of `replicates` records per law whose results would not
/// fit in memory or that could not finish in a day (each record gets the replicates' evidence
/// ([`Job::for_replicates`]) on `data`'s calibration samples: at least two scored batches of
/// every island of every law), before any work.
pub fn check_size(replicates: usize, field: &str, job: &Job, data: &FieldData) -> Result<()> {
    check_replicates(replicates, field)?;
    let job = job.for_replicates();
    let sampler = &job.sampler;
    let starts = if sampler.start == Start::Both { 2.0 } else { 1.0 };
    let particles: f64 = job.laws.iter().map(|&law| sampler.particles_of(law) as f64).sum();
    let records = replicates as f64 * job.laws.len() as f64;
    let samples = data.calibration.len() as f64;
    // Every replicate's result is kept: its parameters, and each law's ln Z and probability.
    let params = job.laws.iter().map(|law| law.n_params()).max().unwrap_or(0);
    let per_record = std::mem::size_of::<CheckReplicate>() + 8 * (params + 2 * job.laws.len());
    crate::limits::check_memory(
        field,
        records * per_record as f64,
        &format!("the results of {records:.3e} synthetic records"),
    )?;
    crate::limits::check_work(
        field,
        records * particles * sampler.islands as f64 * starts * samples * 2.0,
        crate::limits::FASTEST_EVALUATIONS_PER_S,
        &format!("the evidence of {records:.3e} synthetic records ({samples} samples each)"),
    )
}

/// Checks `analysis`, the evidence `job` computed on `data`: `replicates` synthetic records
/// per law, each through the replicates' lighter job ([`Job::for_replicates`]) over the same
/// boxes, its samplers scored where
/// `scoring` says (the same check here or on a pool of workers). `progress(done, total)` hears
/// each finished replicate; `observer` is asked whether to stop between and within replicates.
pub fn check(
    job: &Job,
    data: &FieldData,
    analysis: &EvidenceAnalysis,
    replicates: usize,
    scoring: &mut Scoring,
    progress: &mut dyn FnMut(usize, usize),
    observer: &mut dyn Observer,
) -> Result<EvidenceCheck> {
    check_size(replicates, "check", job, data)?;
    let job = &job.for_replicates();
    let started = Instant::now();
    let laws: Vec<Law> = analysis.evidence.laws.iter().map(|l| l.law).collect();
    // The backend the analysis ended on: a fallback to the CPU is said once, not per replicate.
    let backend = if analysis.evidence.backend == "gpu" {
        Backend::Gpu
    } else {
        Backend::Cpu
    };
    let total = laws.len() * replicates;
    let mut candidates_scored = 0;
    let mut rows = Vec::with_capacity(laws.len());
    for (slot, &law) in laws.iter().enumerate() {
        let mut made = Vec::with_capacity(replicates);
        for index in 0..replicates {
            if observer.interrupted() {
                return Err(Error::Interrupted);
            }
            let seed = replicate_seed(job.sampler.seed, slot, index);
            let (replicate, scored) = replicate_of(job, data, analysis, slot, index, seed, backend, scoring, observer)?;
            candidates_scored += scored;
            made.push(replicate);
            progress(slot * replicates + index + 1, total);
        }
        rows.push(summarize(law, &laws, made));
    }
    Ok(EvidenceCheck {
        laws,
        replicates,
        sampler: Some(ReplicateSampler {
            particles: job.sampler.particles,
            islands: job.sampler.islands,
            start: job.sampler.start,
        }),
        rows,
        candidates_scored,
        seconds: started.elapsed().as_secs_f64(),
    })
}

/// Replicate `index` of the law in `slot`: its record, fits and evidence; with the candidates
/// its samplers scored.
#[allow(clippy::too_many_arguments)]
fn replicate_of(
    job: &Job,
    data: &FieldData,
    analysis: &EvidenceAnalysis,
    slot: usize,
    index: usize,
    seed: u64,
    backend: Backend,
    scoring: &mut Scoring,
    observer: &mut dyn Observer,
) -> Result<(CheckReplicate, u64)> {
    let evidence = &analysis.evidence.laws[slot];
    let law = evidence.law;
    let fit = analysis
        .fits
        .iter()
        .find(|f| f.law == law)
        .ok_or_else(|| Error::Numerical(format!("the evidence check has no least-squares fit of {law}")))?;
    let mut rng = StdRng::seed_from_u64(seed);
    let sets = evidence.posterior.iter().map(|(p, w)| (p.as_slice(), *w));
    let params_si = draw_by_weight(sets, &mut rng).unwrap_or_else(|| fit.params_si.clone());
    let w_ref_n = analysis.fit.w_ref_n;
    let noise_model = analysis.evidence.config.noise;
    let synthetic = synthetic_record(
        data,
        (law, &fit.params_si, &params_si),
        w_ref_n,
        noise_model,
        index,
        &mut rng,
    );
    let known: Vec<(Law, Vec<f64>)> = std::iter::once((law, params_si.clone()))
        .chain(analysis.fits.iter().map(|f| (f.law, f.params_si.clone())))
        .collect();
    // A replicate's fits decide by whole nats: each is polished only while it gains more
    // than [`FIT_RESOLUTION_NATS`] of log-likelihood, at the generating law's noise level
    // ((n/2)·ΔS/S nats for a change ΔS of the sum of squares S).
    let n = synthetic.calibration.len().max(1) as f64;
    let resolution_nm2 = 2.0 * FIT_RESOLUTION_NATS * fit.rho * data.calibration.sum_sq_torque() / n;
    let basis = super::Basis::new(
        crate::fit::fit_record_within(&job.laws, &synthetic, &analysis.fit, &known, resolution_nm2)?,
        analysis.prior.clone(),
        analysis.fit,
        &synthetic,
    );
    let placement = Placement {
        backend,
        ..job.placement()
    };
    let problem = Job::problem(&synthetic, &basis, seed);
    let workers = scoring.workers(problem, &placement, &mut |line| observer.note(line))?;
    let outcome = job
        .sample(basis, workers.as_ref(), noise_model, None, observer)
        .map_err(|e| match e {
            Error::Numerical(m) => Error::Numerical(format!("{law} replicate {index}: {m}")),
            other => other,
        })?;
    let laws = &outcome.evidence.laws;
    let probabilities: Vec<f64> = laws.iter().map(|l| l.probability).collect();
    let mut order: Vec<usize> = (0..laws.len()).collect();
    // Largest first; among equals the first in law order.
    order.sort_by(|&a, &b| probabilities[b].total_cmp(&probabilities[a]).then(a.cmp(&b)));
    let first = &laws[order[0]];
    let rivals = rivals_of(laws, &order, &outcome.fits, synthetic.calibration.len());
    // A NaN gap (a fit with no value) decides nothing.
    let decided = rivals.iter().all(|r| r.4.decides());
    let (runner_up, ln_odds, ln_odds_error) = rivals
        .first()
        .map_or((None, f64::INFINITY, 0.0), |&(law, odds, error, _, _)| {
            (Some(law), odds, error)
        });
    let closest = rivals.iter().min_by(|a, b| a.3.total_cmp(&b.3));
    let (closest_fit, gap_nats) = closest.map_or((None, f64::INFINITY), |&(law, _, _, gap, _)| (Some(law), gap));
    Ok((
        CheckReplicate {
            index,
            seed,
            params_si,
            ln_z: laws.iter().map(|l| l.ln_z).collect(),
            probabilities,
            first: first.law,
            runner_up,
            ln_odds,
            ln_odds_error,
            closest_fit,
            gap_nats,
            decided,
        },
        outcome.evidence.candidates_scored,
    ))
}

/// The first law (`order[0]`) against every rival, in `order`: the posterior log-odds with
/// their error, how far the first law's fit lies above the rival's over `n` samples (nats),
/// and the strength these give.
fn rivals_of(
    laws: &[crate::abc::evidence::LawEvidence],
    order: &[usize],
    fits: &[crate::fit::LawFit],
    n: usize,
) -> Vec<(Law, f64, f64, f64, Strength)> {
    let first = &laws[order[0]];
    let n = n as f64;
    let rho = |law: Law| fits.iter().find(|f| f.law == law).map_or(f64::NAN, |f| f.rho);
    // Against every rival: the posterior log-odds with their error, and how far the first
    // law's fit lies above the rival's.
    order[1..]
        .iter()
        .map(|&k| {
            let rival = &laws[k];
            let ln_odds = (first.ln_z + first.prior_probability.ln()) - (rival.ln_z + rival.prior_probability.ln());
            let gap = n / 2.0 * (rho(rival.law) / rho(first.law)).ln();
            let data = first.mean_ln_l.zip(rival.mean_ln_l).map(|(a, b)| a - b);
            let error = first.ln_z_error.hypot(rival.ln_z_error);
            (
                rival.law,
                ln_odds,
                error,
                gap,
                Strength::of(ln_odds, error, data, Some(gap)),
            )
        })
        .collect()
}

/// Replicate `index` of `law` at `params_si`: its model on the record's speeds plus noise
/// drawn from the residuals of the law's fit (`fit_si`) to `data`; under the AR(1) model the
/// noise keeps the residuals' lag-1 correlation (their innovations resampled and filtered
/// again).
fn synthetic_record(
    data: &FieldData,
    (law, fit_si, params_si): (Law, &[f64], &[f64]),
    w_ref_n: Option<f64>,
    noise_model: NoiseModel,
    index: usize,
    rng: &mut StdRng,
) -> FieldData {
    let e = residuals(law, fit_si, &data.calibration, w_ref_n);
    // Under the AR(1) model the noise keeps the residuals' lag-1 correlation: its innovations
    // are resampled and filtered again.
    let phi = match noise_model {
        NoiseModel::Iid => 0.0,
        NoiseModel::Ar1 => Some(crate::separation::lag1_of(&e))
            .filter(|phi| phi.is_finite())
            .map_or(0.0, |phi| phi.clamp(-0.99, 0.99)),
    };
    let draws: Vec<f64> = if phi == 0.0 {
        e
    } else {
        e.windows(2).map(|pair| pair[1] - phi * pair[0]).collect()
    };
    FieldData {
        source: data.source.join(format!("evidence-check/{law}-replicate-{index}")),
        calibration: synthesize(law, params_si, &data.calibration, w_ref_n, &draws, phi, rng),
        validation: synthesize(law, params_si, &data.validation, w_ref_n, &draws, phi, rng),
        warnings: Vec::new(),
        bit: None,
        ..data.clone()
    }
}

/// The row of `law` from its replicates.
fn summarize(law: Law, laws: &[Law], replicates: Vec<CheckReplicate>) -> CheckRow {
    let k = replicates.len() as f64;
    let share = |keep: &dyn Fn(&CheckReplicate) -> bool| replicates.iter().filter(|r| keep(r)).count() as f64 / k;
    let mean_probability = (0..laws.len())
        .map(|j| replicates.iter().map(|r| r.probabilities[j]).sum::<f64>() / k)
        .collect();
    let first_share: Vec<f64> = laws.iter().map(|&l| share(&|r| r.first == l)).collect();
    let decided_right = share(&|r| r.decided && r.first == law);
    let decided_wrong = share(&|r| r.decided && r.first != law);
    let undecided = share(&|r| !r.decided);
    let count = |s: f64| (s * k).round() as usize;
    let mut verdict = format!(
        "{law} data: decided for {law} in {} of {}, undecided in {}",
        count(decided_right),
        replicates.len(),
        count(undecided)
    );
    if decided_wrong > 0.0 {
        let mut wrong: Vec<(Law, usize)> = laws
            .iter()
            .filter(|&&l| l != law)
            .map(|&l| (l, replicates.iter().filter(|r| r.decided && r.first == l).count()))
            .filter(|&(_, c)| c > 0)
            .collect();
        wrong.sort_by_key(|&(_, c)| std::cmp::Reverse(c));
        let named: Vec<String> = wrong.iter().map(|(l, c)| format!("{l} in {c}")).collect();
        verdict.push_str(&format!(", decided wrongly for {}", named.join(", ")));
    }
    verdict.push('.');
    CheckRow {
        law,
        mean_probability,
        first_share,
        decided_right,
        undecided,
        decided_wrong,
        verdict,
        replicates,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_check_runs_by_default_where_two_laws_or_more_are_compared_and_0_turns_it_off() {
        assert_eq!(replicates_asked(None, 4), Some(DEFAULT_REPLICATES));
        assert_eq!(replicates_asked(None, 1), None);
        assert_eq!(replicates_asked(Some(0), 4), None);
        assert_eq!(replicates_asked(Some(7), 1), Some(7));
    }

    #[test]
    fn a_replicate_s_evidence_is_lighter_and_starts_from_its_fit() {
        let mut job = Job::default();
        job.sampler.particles = 500;
        job.sampler.islands = 4;
        job.sampler.law_particles = vec![(Law::M3, 1000), (Law::M1, 50)];
        job.sampler.start = Start::Both;
        job.sampler.refine_rounds = 2;
        let light = job.for_replicates().sampler;
        assert_eq!(
            (light.particles, light.islands),
            (REPLICATE_PARTICLES, REPLICATE_ISLANDS)
        );
        assert_eq!(light.law_particles, vec![(Law::M3, REPLICATE_PARTICLES), (Law::M1, 50)]);
        assert_eq!((light.start, light.refine_rounds), (Start::Fit, 0));
        // Already light, and from the box as asked: kept.
        job.sampler.particles = 60;
        job.sampler.islands = 2;
        job.sampler.start = Start::Box;
        let light = job.for_replicates().sampler;
        assert_eq!((light.particles, light.islands, light.start), (60, 2, Start::Box));
    }

    #[test]
    fn a_check_whose_results_would_not_fit_in_memory_is_refused_by_name() {
        let data = crate::data::demo_field_data(&Default::default()).unwrap();
        let job = Job {
            laws: Law::ALL.to_vec(),
            ..Job::default()
        };
        assert!(check_size(DEFAULT_REPLICATES, "check", &job, &data).is_ok());
        let memory = check_size(usize::MAX / 16, "check", &job, &data)
            .unwrap_err()
            .to_string();
        assert!(
            memory.contains("check") && memory.contains("synthetic records") && memory.contains("of memory"),
            "{memory}"
        );
        let none = check_size(0, "check", &job, &data).unwrap_err().to_string();
        assert!(none.contains("check") && none.contains("at least 1"), "{none}");
    }

    #[test]
    fn a_check_an_earlier_bitrock_wrote_reads_without_its_sampler() {
        let check: EvidenceCheck = serde_json::from_value(serde_json::json!({
            "laws": ["m2", "m3"], "replicates": 1, "rows": [], "candidates_scored": 0, "seconds": 0.5,
        }))
        .unwrap();
        assert_eq!(check.sampler, None);
    }
}
