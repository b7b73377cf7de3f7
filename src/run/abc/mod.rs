//! The whole ABC job in one call: a loaded record → least-squares fits → prior → populations
//! → posterior summary → predictive envelopes, optionally written to a run directory
//! (run.sqlite as each population completes, then run.json, envelopes.csv and data.csv).
//! `bitrock abc` and `bitrock demo` are two callers of [`Job::run`] (the demo through
//! [`Job::run_fitted`], its three runs of one record fitted once) and [`resume`]; a program that
//! wants what `bitrock abc` does calls them too.

use crate::abc::posterior::{ENVELOPE_LEVEL, Envelope, PosteriorSummary, predictive_envelope, speed_grid, summarize};
use crate::abc::{Observer, Particle};
use crate::data::FieldData;
use crate::documents::{self, RunSummary};
use crate::error::{Error, Result};
use crate::files;
use crate::prior::PriorFile;

use crate::run::answer::{Answer, Method};
use crate::run::{self, Scoring};
use crate::separation::Separation;
use std::path::Path;

pub mod config;
pub mod populations;
pub mod store;

pub use config::{Config, Continuation, DEFAULT_PRIOR_K, PriorRuleName, Sampler, SamplerConfig, Settings};
pub use populations::{Outcome, Start, resume_advice, save, start};
pub use store::{Setup, State, Store, Stored};

/// Speeds of the predictive envelopes, evenly spaced over the record's range.
const ENVELOPE_SPEEDS: usize = 200;
/// A least-squares ρ below this is an exact fit (rounding of an exactly representable record).
const EXACT_FIT_RHO: f64 = 1e-12;
/// Fewer particles than this in the last population and its model probabilities are said to
/// be coarse: each particle moves a law's probability by 1/N (with one, a law gets 1).
pub const MIN_PARTICLES_FOR_PROBABILITIES: usize = 100;

/// An ABC job: what defines the run and what to summarise. [`Default`] is `bitrock abc`'s
/// defaults, in memory (no run directory).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Job {
    /// Laws, fits, prior width, seed, backend and sampler (stored with the run).
    pub config: Config,
    /// Population to summarise (statistics, MAP, envelopes); `None`: the last.
    pub summary_population: Option<usize>,
    /// The run directory to write; `None` keeps the run in memory.
    pub out: Option<run::Dir>,
}

/// A finished job: the run (configuration, record, fits, prior, populations) and the summary
/// of one population.
pub struct Analysis {
    pub outcome: Outcome,
    /// Index of the summarised population.
    pub summary_population: usize,
    pub posterior: PosteriorSummary,
    /// The 98 % predictive envelope of every law with particles in the summarised population.
    pub envelopes: Vec<Envelope>,
    /// What the record separates: every ordered pair of the laws' fits
    /// ([`crate::separation`]).
    pub separations: Vec<Separation>,
    /// The summarised population's answer to "which law, how sure"; `None` where no law
    /// holds a particle.
    pub answer: Option<Answer>,
}

impl Job {
    /// Refuses, naming the setting, a configuration that cannot run, and a run directory that
    /// would be overwritten without `replace`, before any work.
    pub fn validate(&self) -> Result<()> {
        self.config.validate()?;
        self.config.check_summary_population(self.summary_population)?;
        if let Some(out) = &self.out {
            run::dir::check_new(out, None)?;
        }
        Ok(())
    }

    /// Runs the job on `data`: validates, reads the prior file, fits, samples (scored where
    /// `scoring` says, reporting its progress and what the user should know, such as a
    /// fallback to the CPU, to `observer`), summarises, and writes the run directory when there
    /// is one. Nothing is written when something is refused. Workers elsewhere
    /// ([`Scoring::Workers`]) give the result scoring here gives.
    pub fn run(&self, data: FieldData, scoring: Scoring, observer: &mut dyn Observer) -> Result<Analysis> {
        self.run_fitted(data, None, scoring, observer)
    }

    /// [`Job::run`] with the record's least-squares fits where the caller has made them
    /// ([`Start::fits`]: several runs of one record fit it once); `None`: fitted
    /// here.
    pub fn run_fitted(
        &self,
        data: FieldData,
        fits: Option<Vec<crate::fit::LawFit>>,
        scoring: Scoring,
        observer: &mut dyn Observer,
    ) -> Result<Analysis> {
        self.config.validate()?;
        self.config.check_summary_population(self.summary_population)?;
        let prior_file = self.config.prior_file.as_deref().map(PriorFile::read).transpose()?;
        if let Some(out) = &self.out {
            run::dir::check_new(out, Some(&data.source))?;
        }
        let how = Start {
            dir: self.out.as_ref(),
            prior_file: prior_file.as_ref(),
            fits,
            scoring,
        };
        let outcome = start(data, self.config.clone(), how, observer)?;
        let dir = self.out.as_ref().map(|out| out.path.as_path());
        let mut analysis = Analysis::new(outcome, self.summary_population, dir)?;
        if let Some(dir) = dir {
            analysis.write_summary(dir)?;
        }
        analysis.outcome.lock = None; // the directory is complete: the next writer may come
        Ok(analysis)
    }
}

/// Continues the run in `dir` ([`populations::resume`], scored where `scoring` says), then summarises
/// population `more.summary_population` (default: the last) and rewrites the directory's
/// summary files. A resume that adds no population changes nothing on disk (the summary is
/// only returned).
pub fn resume(dir: &Path, more: &Continuation, scoring: Scoring, observer: &mut dyn Observer) -> Result<Analysis> {
    let outcome = populations::resume(dir, more, scoring, observer)?;
    let unchanged = outcome.added == 0 && dir.join(run::dir::RUN_JSON).is_file();
    let mut analysis = Analysis::new(outcome, more.summary_population, Some(dir))?;
    if unchanged {
        observer.note(format!(
            "no population added ({}); {} is unchanged",
            analysis.outcome.run.stop.describe(),
            dir.display()
        ));
    } else {
        analysis.write_summary(dir)?;
    }
    analysis.outcome.lock = None; // the directory is complete: the next writer may come
    Ok(analysis)
}

impl Analysis {
    /// Summarises population `summary_population` (default: the last) of `outcome`: posterior
    /// statistics and MAP, and the predictive envelopes over the record's speed range. `dir`
    /// only names the run in the message of a run stopped before its first population.
    pub fn new(outcome: Outcome, summary_population: Option<usize>, dir: Option<&Path>) -> Result<Self> {
        let populations = &outcome.run.populations;
        let last = match summary_population {
            None => populations.last().ok_or_else(|| no_population(&outcome, dir))?,
            Some(g) => populations.get(g).ok_or_else(|| {
                Error::setting(
                    "summary_population",
                    format!("the run has populations 0..={}", populations.len().saturating_sub(1)),
                )
            })?,
        };
        let laws = &outcome.config.laws;
        // A stored run keeps only its last population's particles in memory.
        let stored;
        let particles = match dir {
            Some(dir) if last.particles.is_empty() && last.record.accepted > 0 => {
                stored = Store::open(dir)?.load_particles(last.record.index)?;
                &stored
            }
            _ => &last.particles,
        };
        let mut posterior = summarize(particles, laws);
        posterior.mark_identified(&outcome.setup.prior);
        let setup = &outcome.setup;
        let envelopes = envelopes(particles, laws, &setup.data);
        let (separations, answer) = answer(setup, &outcome.config.fit, &last.record, &posterior.model_probabilities)?;
        Ok(Self {
            summary_population: last.record.index,
            posterior,
            envelopes,
            separations,
            answer,
            outcome,
        })
    }

    /// Writes a run made in memory to the run directory `dir`, store and summary files, as
    /// [`Job::run`] with `out` would have written it ([`save`]).
    pub fn save(&self, dir: &run::Dir) -> Result<()> {
        let _lock = save(dir, &self.outcome)?;
        self.write_summary(&dir.path)
    }

    /// What the user must know about a result that ran but says less than it seems to: the
    /// record's warnings, every law fitting it exactly (ρ = 0: a constant torque, which no
    /// tolerance can tell the laws apart on), and populations whose effective sample size is a
    /// small share of their particles (their estimates rest on a few heavy particles). Said
    /// once each, by the command and in run.json (`warnings`).
    pub fn warnings(&self) -> Vec<String> {
        let mut out = self.outcome.setup.data.warnings.clone();
        out.extend(self.run_warnings());
        out
    }

    /// [`Self::warnings`] of the run itself, without the record's (which the command that
    /// read the record has said).
    pub fn run_warnings(&self) -> Vec<String> {
        let setup = &self.outcome.setup;
        let mut out = Vec::new();
        if !setup.fits.is_empty() && setup.fits.iter().all(|f| f.rho < EXACT_FIT_RHO) {
            out.push(format!(
                "every law fits the record exactly (ρ < {EXACT_FIT_RHO:e}): the torque does not depend on the bit speed here (a constant record?), and the model probabilities say nothing"
            ));
        }
        if let Some(last) = self.outcome.run.populations.last()
            && let Some(epsilon) = last.record.epsilon
        {
            out.extend(prior_volume_caveat(setup, epsilon));
        }
        let thin: Vec<String> = self
            .outcome
            .run
            .populations
            .iter()
            .filter(|p| p.record.thin())
            .map(|p| format!("{} ({:.0} of {})", p.record.index, p.record.ess, p.record.accepted))
            .collect();
        if !thin.is_empty() {
            out.push(format!(
                "effective sample size below {:.0} % of the particles in population(s) {}: those estimates rest on a few heavily weighted particles (more particles or a wider SMC kernel help)",
                crate::abc::MIN_ESS_SHARE * 100.0,
                thin.join(", ")
            ));
        }
        if self.outcome.backend == "gpu" {
            let cal = &setup.data.calibration;
            for fit in &setup.fits {
                let Some(error) = fit.law.f32_rho_error(&fit.params_si, &cal.speed_rad_s, &cal.torque_nm) else {
                    continue;
                };
                if error > crate::eval::PARITY_TOLERANCE {
                    out.push(format!(
                        "law {}: its torque loses digits in f32, the GPU's float: at its least-squares fit, ρ computed in f32 differs from f64 by {error:.2e} (relative), beyond the {:e} the CPU/GPU parity tolerance allows, so this run's GPU scores of it differ from the CPU's; score it with `backend` cpu, or rewrite the torque to avoid cancellation",
                        fit.law,
                        crate::eval::PARITY_TOLERANCE
                    ));
                }
            }
        }
        if let Some(last) = self.outcome.run.populations.last() {
            let n = last.particles.len();
            if n < MIN_PARTICLES_FOR_PROBABILITIES {
                out.push(format!(
                    "the last population has {n} particle(s): each moves a law's probability by 1/{n}, so the model probabilities are that coarse (at least {MIN_PARTICLES_FOR_PROBABILITIES} particles give probabilities worth reading)"
                ));
            }
            for (law, count, ess) in thin_laws(&last.particles, &setup.prior) {
                out.push(format!(
                    "law {law}: effective sample size {ess:.1} of its {count} particles in the last population: its posterior rests on a few heavily weighted particles, and its spread and intervals say little (more particles, a wider SMC kernel, `kernel_scale`, or the local perturbation help)"
                ));
            }
        }
        out
    }

    /// The run.json document (also what `abc --json` prints).
    pub fn json(&self) -> serde_json::Value {
        let outcome = &self.outcome;
        let mut config = serde_json::to_value(&outcome.config).expect("the configuration serialises");
        config["threads"] = rayon::current_num_threads().into();
        let mut document = RunSummary {
            data: &outcome.setup.data,
            fits: &outcome.setup.fits,
            prior: &outcome.setup.prior,
            run: &outcome.run,
            posterior: &self.posterior,
            summary_population: self.summary_population,
            config,
            seed: outcome.config.seed,
            backend: outcome.backend,
        }
        .json(self.warnings());
        document["posterior"]["label"] = Method::PaperAbc.label().into();
        document["answer"] = self.answer.as_ref().map_or(serde_json::Value::Null, Answer::json);
        document
    }

    /// Writes run.json, envelopes.csv and data.csv into the run directory `dir`, each whole or
    /// not at all ([`files::write_own`]).
    pub fn write_summary(&self, dir: &Path) -> Result<()> {
        let run_json = serde_json::to_string_pretty(&self.json()).expect("JSON into memory") + "\n";
        let data = &self.outcome.setup.data;
        let files = [
            (run::dir::RUN_JSON, run_json.into_bytes()),
            (
                run::dir::ENVELOPES_CSV,
                documents::envelopes_csv(&self.envelopes, data.torque_unit),
            ),
            (run::dir::DATA_CSV, documents::data_csv(data)),
        ];
        for (name, bytes) in &files {
            files::write_own(&dir.join(name), "out", |out| out.write_all(bytes))?;
        }
        Ok(())
    }
}

/// A population's answer to "which law, how sure" ([`Answer::of_abc`]) from its `record`
/// and model `probabilities`, with the fits' separations it weighs them by (the run's fits
/// under its fit options `fit`).
pub fn answer(
    setup: &Setup,
    fit: &crate::fit::FitOptions,
    record: &crate::abc::PopulationRecord,
    probabilities: &[(crate::Law, f64)],
) -> Result<(Vec<Separation>, Option<Answer>)> {
    let separations = crate::separation::separations(&setup.fits, &setup.data.calibration, fit)?;
    let prior_volumes = record
        .epsilon
        .is_some_and(|eps| prior_volume_caveat(setup, eps).is_some());
    let answer = Answer::of_abc(
        probabilities,
        &setup.prior.weights,
        record.ess,
        prior_volumes,
        &separations,
    );
    Ok((separations, answer))
}

/// The caveat a run's model probabilities at tolerance `epsilon` earn where ε lies far
/// above the record's likelihood scale ([`crate::abc::prior_volume_caveat`]). An exact fit has
/// no likelihood scale: the warning of exact fits says what matters there. One law has no
/// probabilities to misread.
fn prior_volume_caveat(setup: &Setup, epsilon: f64) -> Option<String> {
    let best = setup.fits.iter().map(|f| f.rho).fold(f64::INFINITY, f64::min);
    (best >= EXACT_FIT_RHO && setup.fits.len() > 1)
        .then(|| crate::abc::prior_volume_caveat(epsilon, best, setup.data.calibration.len()))
        .flatten()
}

/// The refusal of a run stopped before its first population, saying how to continue it.
fn no_population(outcome: &Outcome, dir: Option<&Path>) -> Error {
    let stop = outcome.run.stop.describe();
    Error::Incomplete(match dir {
        Some(dir) => format!("no population completed: {stop}; {}", resume_advice(dir)),
        None => format!("no population completed: {stop}"),
    })
}

/// The predictive envelopes of a population's laws over the record's speed range.
fn envelopes(particles: &[Particle], laws: &[crate::Law], data: &FieldData) -> Vec<Envelope> {
    let all_speeds = data.calibration.speed_rad_s.iter().chain(&data.validation.speed_rad_s);
    let (lo, hi) = all_speeds.fold((f64::INFINITY, 0.0f64), |(a, b), &w| (a.min(w), b.max(w)));
    let grid = speed_grid(lo, hi, ENVELOPE_SPEEDS);
    laws.iter()
        .filter_map(|&law| predictive_envelope(particles, law, &grid, ENVELOPE_LEVEL, 1.0))
        .collect()
}

/// The laws of the last population whose own effective sample size (of their weights) is
/// below [`crate::abc::MIN_ESS_SHARE`] of their particles, or below 2 with at least two
/// particles: (law, particles, ESS). The population's ESS can be fine while one law's mass
/// sits on one particle.
fn thin_laws(particles: &[Particle], prior: &crate::prior::Prior) -> Vec<(crate::Law, usize, f64)> {
    prior
        .boxes
        .iter()
        .filter_map(|bx| {
            let weights: Vec<f64> = particles.iter().filter(|p| p.law == bx.law).map(|p| p.weight).collect();
            let ess = crate::abc::effective_sample_size(&weights);
            let n = weights.len();
            (n >= 2 && (ess < 2.0 || ess < crate::abc::MIN_ESS_SHARE * n as f64)).then_some((bx.law, n, ess))
        })
        .collect()
}
