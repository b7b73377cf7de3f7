//! `bitrock bench --smc`: the SMC schemes against the rejection sampler near the noise floor,
//! on the same records, ε_min, N, laws, prior boxes and model prior, over several seeds. The
//! primary figure is candidates scored (population 0 included) per final effective sample
//! size; beside it, the agreement of each SMC run with the rejection run of the same seed at
//! the same final ε: law probabilities in standard errors, and per parameter a weighted
//! two-sample Kolmogorov–Smirnov statistic against its critical value at α = 0.001.

use super::SelectionRecord;
use crate::abc::schedule::Schedule;
use crate::abc::smc::{LawProposal, Perturbation, Refill, SmcConfig};
use crate::abc::{Population, Silent};
use crate::error::Result;
use crate::eval::{Backend, gpu::tune::ShapeWish};
use crate::fit;
use crate::laws::Law;
use crate::numerics::{quantile, weighted_ks};
use crate::run::{self, abc::SamplerConfig};
use serde::Serialize;

/// A sampler of the comparison: the rejection sampler, or SMC with a refill and a law proposal.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Scheme {
    pub name: &'static str,
    /// `None`: the rejection sampler (nested).
    pub smc: Option<(Refill, LawProposal, Perturbation)>,
}

/// The schemes compared: rejection, the classic SMC, each change alone, survivors and worth
/// together, and all three (the default).
pub const SCHEMES: [Scheme; 7] = [
    Scheme {
        name: "rejection",
        smc: None,
    },
    Scheme {
        name: "smc fresh+kernel",
        smc: Some((Refill::Fresh, LawProposal::Kernel, Perturbation::Global)),
    },
    Scheme {
        name: "smc survivors",
        smc: Some((Refill::Survivors, LawProposal::Kernel, Perturbation::Global)),
    },
    Scheme {
        name: "smc worth",
        smc: Some((Refill::Fresh, LawProposal::Worth, Perturbation::Global)),
    },
    Scheme {
        name: "smc local",
        smc: Some((Refill::Fresh, LawProposal::Kernel, Perturbation::Local)),
    },
    Scheme {
        name: "smc survivors+worth",
        smc: Some((Refill::Survivors, LawProposal::Worth, Perturbation::Global)),
    },
    Scheme {
        name: "smc all three",
        smc: Some((Refill::Survivors, LawProposal::Worth, Perturbation::Local)),
    },
];

/// ε_min of the comparison: this many times the smallest least-squares ρ of the record.
pub const FLOOR_FACTOR: f64 = 1.1;

/// One run of one scheme with one seed.
#[derive(Clone, Debug, Serialize)]
pub struct SchemeRun {
    pub seed: u64,
    /// Candidates scored, every population included.
    pub scored: u64,
    pub final_ess: f64,
    pub scored_per_ess: f64,
    pub populations: usize,
    pub final_epsilon: Option<f64>,
    pub probabilities: Vec<(Law, f64)>,
    /// Against the rejection run of the same seed: the largest |ΔP(law)| in standard errors
    /// √(p(1 − p)(1/ESS + 1/N)), p pooled (0 for rejection itself; NaN where the two runs
    /// ended at different ε, and are not compared).
    pub probability_z: f64,
    /// Against the rejection run of the same seed: the largest weighted two-sample KS statistic
    /// of a parameter over its critical value 1.95 √(1/ESS₁ + 1/ESS₂) (α = 0.001), over the
    /// laws holding at least 5 % of both runs' weight (0 for rejection itself).
    pub ks_ratio: f64,
    pub seconds: f64,
}

/// A scheme on a record, over the seeds.
#[derive(Clone, Debug, Serialize)]
pub struct SchemeSummary {
    pub scheme: Scheme,
    pub runs: Vec<SchemeRun>,
    /// Median over the seeds of candidates scored per final ESS.
    pub scored_per_ess: f64,
    /// Median over the seeds of the rejection run's scored per ESS over this one's.
    pub fewer_than_rejection: f64,
    pub max_probability_z: f64,
    pub max_ks_ratio: f64,
}

/// The comparison on one record.
#[derive(Clone, Debug, Serialize)]
pub struct SmcComparison {
    pub record: SelectionRecord,
    pub command: Option<&'static str>,
    pub calibration_samples: usize,
    pub best_least_squares_rho: f64,
    pub eps_min: f64,
    pub particles: usize,
    pub schemes: Vec<SchemeSummary>,
}

/// The comparison on each of `records` with N = `particles`, seeds 1..=`seeds`, scored on the
/// CPU (candidates scored do not depend on the backend).
pub fn compare(
    records: &[SelectionRecord],
    particles: usize,
    seeds: u64,
    log: &mut dyn FnMut(String),
) -> Result<Vec<SmcComparison>> {
    records.iter().map(|&r| compare_on(r, particles, seeds, log)).collect()
}

fn compare_on(
    record: SelectionRecord,
    particles: usize,
    seeds: u64,
    log: &mut dyn FnMut(String),
) -> Result<SmcComparison> {
    let data = record.field_data()?;
    let base_config = run::abc::Config::default();
    let fits = fit::fit_record(&base_config.laws, &data, &base_config.fit)?;
    let best = fits.iter().map(|f| f.rho).fold(f64::INFINITY, f64::min);
    let eps_min = FLOOR_FACTOR * best;
    let schedule = Schedule {
        particles,
        eps_min,
        ..Schedule::default()
    };
    let mut schemes: Vec<SchemeSummary> = Vec::new();
    let mut rejection_runs: Vec<Population> = Vec::new();
    for scheme in SCHEMES {
        let mut runs = Vec::new();
        for seed in 1..=seeds {
            let sampler = match scheme.smc {
                None => SamplerConfig::Rejection(schedule.clone().into()),
                Some((refill, law_proposal, perturbation)) => SamplerConfig::Smc(SmcConfig {
                    schedule: schedule.clone(),
                    refill,
                    law_proposal,
                    perturbation,
                    ..SmcConfig::default()
                }),
            };
            let config = run::abc::Config {
                seed,
                backend: Backend::Cpu,
                sampler,
                eps_min_from_record: false,
                ..run::abc::Config::default()
            };
            let started = std::time::Instant::now();
            let mut evaluator = |problem, note: &mut dyn FnMut(String)| {
                crate::eval::evaluator(problem, Backend::Cpu, ShapeWish::default(), note)
            };
            let how = run::abc::Start {
                fits: Some(fits.clone()),
                scoring: run::Scoring::Evaluator(&mut evaluator),
                ..Default::default()
            };
            let outcome = run::abc::start(data.clone(), config, how, &mut Silent)?;
            let seconds = started.elapsed().as_secs_f64();
            let populations = &outcome.run.populations;
            let last = populations.last().expect("a run to ε_min has populations").clone();
            let scored: u64 = populations.iter().map(|p| p.record.candidates_scored).sum();
            let (probability_z, ks_ratio) = match rejection_runs.get(seed as usize - 1) {
                Some(reference) if scheme.smc.is_some() => {
                    let at = |p: &Population| p.record.epsilon.map(f64::to_bits);
                    if at(&last) == at(reference) {
                        agreement(&last, reference, &base_config.laws)
                    } else {
                        (f64::NAN, f64::NAN)
                    }
                }
                _ => (0.0, 0.0),
            };
            let run = SchemeRun {
                seed,
                scored,
                final_ess: last.record.ess,
                scored_per_ess: scored as f64 / last.record.ess,
                populations: populations.len(),
                final_epsilon: last.record.epsilon,
                probabilities: base_config
                    .laws
                    .iter()
                    .map(|&l| (l, last.record.probability_of(l)))
                    .collect(),
                probability_z,
                ks_ratio,
                seconds,
            };
            log(format!(
                "{:<8} {:<20} seed {seed}: {scored} scored, ESS {:.0}, {:.1} per ESS, {} populations, ΔP {:.1} SE, KS/critical {:.2}",
                record.name(),
                scheme.name,
                run.final_ess,
                run.scored_per_ess,
                run.populations,
                probability_z,
                ks_ratio
            ));
            if scheme.smc.is_none() {
                rejection_runs.push(last);
            }
            runs.push(run);
        }
        schemes.push(summarise(scheme, runs, schemes.first()));
    }
    Ok(SmcComparison {
        record,
        command: record.command(),
        calibration_samples: data.calibration.speed_rad_s.len(),
        best_least_squares_rho: best,
        eps_min,
        particles,
        schemes,
    })
}

fn summarise(scheme: Scheme, runs: Vec<SchemeRun>, rejection: Option<&SchemeSummary>) -> SchemeSummary {
    let per_ess: Vec<f64> = runs.iter().map(|r| r.scored_per_ess).collect();
    let ratios: Vec<f64> = match rejection {
        Some(rej) => rej
            .runs
            .iter()
            .zip(&runs)
            .map(|(r, s)| r.scored_per_ess / s.scored_per_ess)
            .collect(),
        None => vec![1.0],
    };
    SchemeSummary {
        scheme,
        scored_per_ess: quantile(&per_ess, 0.5),
        fewer_than_rejection: quantile(&ratios, 0.5),
        max_probability_z: worst(runs.iter().map(|r| r.probability_z)),
        max_ks_ratio: worst(runs.iter().map(|r| r.ks_ratio)),
        runs,
    }
}

/// The largest of `values`, NaN if any is (a run not compared shows in the summary).
fn worst(values: impl Iterator<Item = f64>) -> f64 {
    values.fold(
        0.0,
        |a: f64, b| if a.is_nan() || b.is_nan() { f64::NAN } else { a.max(b) },
    )
}

/// (largest |ΔP| in standard errors, largest KS statistic over its critical value) of `smc`
/// against `rejection` (see [`SchemeRun`]).
fn agreement(smc: &Population, rejection: &Population, laws: &[Law]) -> (f64, f64) {
    let ess = |p: &Population, law: Option<Law>| {
        let w: Vec<f64> = p
            .particles
            .iter()
            .filter(|q| law.is_none_or(|l| q.law == l))
            .map(|q| q.weight)
            .collect();
        crate::abc::effective_sample_size(&w)
    };
    let (ess_s, ess_r) = (ess(smc, None), ess(rejection, None));
    let mut z = 0.0f64;
    let mut ks = 0.0f64;
    for &law in laws {
        let (ps, pr) = (smc.record.probability_of(law), rejection.record.probability_of(law));
        let p = (ps + pr) / 2.0;
        let se = (p * (1.0 - p) * (1.0 / ess_s + 1.0 / ess_r)).sqrt();
        if se > 0.0 {
            z = z.max((ps - pr).abs() / se);
        }
        if ps < 0.05 || pr < 0.05 {
            continue;
        }
        let (es, er) = (ess(smc, Some(law)), ess(rejection, Some(law)));
        let critical = 1.95 * (1.0 / es + 1.0 / er).sqrt();
        for j in 0..law.n_params() {
            let column = |p: &Population| -> Vec<(f64, f64)> {
                p.particles
                    .iter()
                    .filter(|q| q.law == law)
                    .map(|q| (q.params[j], q.weight))
                    .collect()
            };
            ks = ks.max(weighted_ks(&column(smc), &column(rejection)) / critical);
        }
    }
    (z, ks)
}
