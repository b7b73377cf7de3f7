//! How far can a run's model selection be trusted? A confusion matrix by re-simulation.
//!
//! For every law of a run, K synthetic records are made at the run's own calibration and
//! validation speeds (and weight-on-bit ratios, when it scales by them): parameters drawn from
//! the law's posterior in the run's last population (its least-squares estimate when the law
//! died out), plus noise resampled with replacement from that law's calibration residuals (a
//! bootstrap that keeps the record's noise level and distribution). Each synthetic record goes
//! through the run's own pipeline ([`run::abc::start`] with the stored [`run::abc::Config`]: least squares
//! of every law, the same prior rule, δ and prior file, the same sampler and stopping rules)
//! with its own seed, [`replicate_seed`]. Its least-squares fits also start from the run's own
//! estimates and the generating parameters ([`crate::fit::fit_law_from`]): never worse than
//! the grid's starts alone, and far cheaper where a law crawls along a ridge. Row i of the
//! confusion matrix is what the pipeline says about data made by law i: the mean posterior
//! probability of every law, and the share of replicates in which each law ranks first.
//!
//! Replicates are independent runs, and each one's populations depend only on its record and
//! seed, so they are run `batch` at a time and give the same results for any `batch`, thread
//! count and order of completion. A batch runs in two phases, each over all its replicates at
//! once: the synthetic records and their least-squares fits (on the rayon pool), then the
//! samplers ([`run::abc::start`]), one thread each, whose candidates are scored
//! together: one GPU dispatch, or one rayon pass on the CPU, for the requests of all of them
//! ([`crate::eval::records`]). The check reports each phase's wall time ([`CheckTiming`]).
//!
//! The results are written to `DIR/selection/` (see [`write()`]) as one directory, whole or not
//! at all, under the run directory's lock; `bitrock report` shows them when present.

use crate::abc::Silent;
use crate::data::{FieldData, Samples};
use crate::error::{Error, Result};
use crate::eval::gpu::Shape;
use crate::eval::records::{RecordBatch, Seat};
use crate::eval::{Backend, Problem};
use crate::files;
use crate::fit::LawFit;
use crate::laws::Law;
use crate::numerics::quantile;
use crate::prior::{Prior, PriorFile, PriorRule};
use crate::run::{self};

use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::time::Instant;

pub use crate::run::dir::{SELECTION_DIR, SELECTION_JSON};

/// How to check a run's selection. [`Default`] is `bitrock check-selection`'s defaults.
#[derive(Clone, Debug, PartialEq)]
pub struct CheckOptions {
    /// Synthetic records per law, K.
    pub replicates: usize,
    /// Where ρ is computed; `None`: the run's backend.
    pub backend: Option<Backend>,
    /// Replicates run at once, their candidates scored together; `None`: all of them.
    pub batch: Option<usize>,
}

impl Default for CheckOptions {
    fn default() -> Self {
        Self {
            replicates: 20,
            backend: None,
            batch: None,
        }
    }
}

impl CheckOptions {
    /// Refuses, naming the flag, options that cannot run.
    pub fn validate(&self) -> Result<()> {
        if self.replicates == 0 {
            return Err(Error::setting("replicates", "must be at least 1"));
        }
        if self.batch == Some(0) {
            return Err(Error::setting("batch", "must be at least 1"));
        }
        Ok(())
    }
}

/// Refuses, naming `--replicates` or `--batch`, a check that cannot fit in memory (the
/// results of every replicate, and a batch of replicate runs held at once) or could not finish
/// in a day (every replicate draws at least its N particles against the whole record).
fn check_size(run: &CheckedRun, options: &CheckOptions) -> Result<()> {
    let laws = run.config.laws.len() as f64;
    let replicates = options.replicates as f64 * laws;
    let particles = run.config.sampler.schedule().particles as f64;
    let samples = run.stored.setup.data.calibration.len() as f64;
    let result_bytes = std::mem::size_of::<Replicate>() as f64 + (laws + crate::laws::MAX_PARAMS as f64) * 8.0;
    crate::limits::check_memory(
        "replicates",
        replicates * result_bytes,
        &format!("the results of {replicates} replicates"),
    )?;
    let batch = options.batch.map_or(replicates, |b| (b as f64).min(replicates));
    // A replicate run holds two populations and its synthetic record.
    let run_bytes =
        2.0 * particles * (std::mem::size_of::<crate::abc::Particle>() as f64 + 8.0 * crate::laws::MAX_PARAMS as f64)
            + samples * 4.0 * 8.0;
    crate::limits::check_memory(
        if options.batch.is_some() { "batch" } else { "replicates" },
        batch * run_bytes,
        &format!("{batch} replicate runs at once (N = {particles})"),
    )?;
    crate::limits::check_work(
        "replicates",
        replicates * particles * samples,
        crate::limits::FASTEST_EVALUATIONS_PER_S,
        &format!("{replicates} replicate runs of N = {particles} on {samples} samples"),
    )
}

/// Where a generating law's parameters come from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ParamSource {
    /// Particles of the law in the run's last population, drawn by weight.
    Posterior,
    /// The law has no particle in the last population: its least-squares estimate.
    LeastSquares,
}

/// One synthetic record and what the pipeline concluded from it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Replicate {
    pub index: usize,
    /// Seed of its synthesis and of its ABC run ([`replicate_seed`]).
    pub seed: u64,
    /// The generating parameters, SI (torques N·m).
    pub params_si: Vec<f64>,
    /// Posterior probability of each law of the check, in [`SelectionCheck::laws`] order.
    pub probabilities: Vec<f64>,
    /// The law with the highest probability (the first in law order among equals).
    pub first: Law,
    /// ε of the last population (`None`: ∞).
    pub final_epsilon: Option<f64>,
    pub populations: usize,
    /// Candidates of all its populations whose ρ lay within the CPU/GPU parity tolerance of ε:
    /// where none did, the other backend gives the same populations.
    #[serde(default)]
    pub near_threshold: u64,
}

/// Quantiles of the generating law's own probability over its replicates.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Quantiles {
    pub min: f64,
    pub q10: f64,
    pub q25: f64,
    pub median: f64,
    pub q75: f64,
    pub q90: f64,
    pub max: f64,
}

impl Quantiles {
    fn of(values: &[f64]) -> Self {
        Self {
            min: quantile(values, 0.0),
            q10: quantile(values, 0.1),
            q25: quantile(values, 0.25),
            median: quantile(values, 0.5),
            q75: quantile(values, 0.75),
            q90: quantile(values, 0.9),
            max: quantile(values, 1.0),
        }
    }
}

/// One row of the confusion matrix: the records made by one law.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GeneratingLaw {
    pub law: Law,
    pub source: ParamSource,
    /// Mean posterior probability of each law over the replicates.
    pub mean_probability: Vec<f64>,
    /// Share of the replicates in which each law ranks first.
    pub first_share: Vec<f64>,
    /// The distribution of P(this law) over its replicates.
    pub own_probability: Quantiles,
    /// One sentence for people.
    pub verdict: String,
    pub replicates: Vec<Replicate>,
}

/// A run's selection check: the confusion matrix and how it was made.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SelectionCheck {
    /// The run directory checked; `None` for a run kept in memory (Python).
    pub run_dir: Option<PathBuf>,
    /// The run's laws: the columns (and rows) of the matrix.
    pub laws: Vec<Law>,
    /// Replicates per law, K.
    pub replicates: usize,
    /// The run's prior rule and δ, which every replicate uses too.
    pub prior_rule: PriorRule,
    pub delta: f64,
    /// The run's seed, from which every replicate's is derived.
    pub run_seed: u64,
    /// Particles per population of every replicate.
    pub particles: usize,
    /// Backend that scored the candidates (`cpu`, `gpu`).
    pub backend: String,
    /// The GPU scoring shape, where the GPU scored (the run's recorded one when it has one).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gpu_shape: Option<Shape>,
    pub rows: Vec<GeneratingLaw>,
    /// Wall time of the check, s.
    pub seconds: f64,
    /// Where the replicates' time went (checks written before it read as zeros).
    #[serde(default)]
    pub timing: CheckTiming,
    /// The state of the run the check describes: a check whose run has moved on since (a
    /// resume added populations or changed its settings) is stale ([`SelectionCheck::stale`]).
    /// `None` for checks written before it was recorded.
    #[serde(default)]
    pub describes: Option<run::abc::State>,
}

/// Where the check's wall time went. Every batch first synthesises and fits its replicates'
/// records side by side, then runs their samplers side by side: the two phases' wall times.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct CheckTiming {
    /// Synthetic records and the least-squares fits of every law to them, s.
    pub fit_seconds: f64,
    /// The replicates' ABC runs (prior, evaluator, populations), s.
    pub sampling_seconds: f64,
    /// Candidate × data-point evaluations of all replicates.
    pub evaluations: u64,
    /// Times the waiting replicates' candidates were scored together, and the GPU dispatches
    /// that took (0 on the CPU; see [`crate::eval::records`]).
    #[serde(default)]
    pub batches: u64,
    #[serde(default)]
    pub dispatches: u64,
    /// Of the sampling, the wall time spent scoring the batches, s.
    #[serde(default)]
    pub scoring_seconds: f64,
    /// How the replicates' least-squares fits went.
    #[serde(default)]
    pub fits: FitCounts,
}

/// How many least-squares fits (one law on one record) were made, and how their
/// Levenberg-Marquardt runs (one per starting point) ended.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct FitCounts {
    pub fits: u64,
    /// Fits in which at least one run spent its whole patience still improving.
    pub fits_out_of_patience: u64,
    /// Fits whose estimate itself comes from such a run (it did not converge).
    pub estimates_out_of_patience: u64,
    /// Runs made, runs that spent their patience, and runs stopped early because they could
    /// not beat the misfit of a run already finished ([`crate::fit::fit_law_from`]).
    pub runs: u64,
    pub runs_out_of_patience: u64,
    pub runs_abandoned: u64,
}

impl FitCounts {
    fn count(&mut self, fit: &LawFit) {
        self.fits += 1;
        let endings = &fit.endings;
        self.fits_out_of_patience += u64::from(endings.out_of_patience > 0);
        self.estimates_out_of_patience += u64::from(endings.estimate_out_of_patience);
        self.runs += fit.starts as u64;
        self.runs_out_of_patience += endings.out_of_patience as u64;
        self.runs_abandoned += endings.abandoned as u64;
    }
}

impl SelectionCheck {
    /// Why this check no longer describes the run now in `now`, in a sentence; `None` when it
    /// does. A check that did not record its run's state is said to be of unknown age.
    pub fn stale(&self, now: &run::abc::State) -> Option<String> {
        let Some(then) = &self.describes else {
            return Some("this check does not record which populations it describes (written by an older bitrock); run `bitrock check-selection` again".into());
        };
        if then.populations != now.populations || then.config != now.config {
            return Some(format!(
                "this check describes the run at {} populations (ε {}); the run has {} now (ε {}) or other settings: run `bitrock check-selection` again",
                then.populations,
                then.last_epsilon.map_or("-".into(), |e| format!("{e:.4}")),
                now.populations,
                now.last_epsilon.map_or("-".into(), |e| format!("{e:.4}")),
            ));
        }
        None
    }

    /// The confusion matrix as CSV: one line per (generating law, column law) with the mean
    /// probability and the share ranked first.
    pub fn matrix_csv(&self) -> Vec<u8> {
        let mut text = String::from("generating_law,law,mean_probability,first_share\n");
        for row in &self.rows {
            for (j, law) in self.laws.iter().enumerate() {
                text.push_str(&format!(
                    "{},{law},{},{}\n",
                    row.law, row.mean_probability[j], row.first_share[j]
                ));
            }
        }
        text.into_bytes()
    }

    /// Every replicate as CSV: its seed, the probability of each law, the law ranked first.
    pub fn replicates_csv(&self) -> Vec<u8> {
        let mut text = String::from("generating_law,replicate,seed");
        for law in &self.laws {
            text.push_str(&format!(",p_{law}"));
        }
        text.push_str(",first,final_epsilon,populations\n");
        for row in &self.rows {
            for r in &row.replicates {
                text.push_str(&format!("{},{},{}", row.law, r.index, r.seed));
                for p in &r.probabilities {
                    text.push_str(&format!(",{p}"));
                }
                let eps = r.final_epsilon.map_or(String::new(), |e| e.to_string());
                text.push_str(&format!(",{},{eps},{}\n", r.first, r.populations));
            }
        }
        text.into_bytes()
    }
}

/// The seed of replicate `replicate` of law slot `law_slot` of a run seeded `run_seed`: a
/// SplitMix64 mix of the three, so that neighbouring replicates get unrelated streams and the
/// result depends on nothing else (not on the batch, the thread or the backend).
pub fn replicate_seed(run_seed: u64, law_slot: usize, replicate: usize) -> u64 {
    let mix = |mut z: u64| {
        z = z.wrapping_add(0x9e37_79b9_7f4a_7c15);
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    };
    mix(run_seed ^ mix(((law_slot as u64) << 32) | replicate as u64))
}

/// A run to check: its stored set-up and last population, read and refused before any work.
pub struct CheckedRun {
    /// The run directory; `None` for a run kept in memory, whose check is returned, not written.
    pub dir: Option<PathBuf>,
    pub config: run::abc::Config,
    pub stored: run::abc::Stored,
    prior_file: Option<PriorFile>,
    /// The run directory's lock, held from [`CheckedRun::open`] until the check is written:
    /// the run cannot be continued or replaced under the check.
    _lock: Option<files::DirLock>,
}

impl CheckedRun {
    /// Reads the run in `dir` and takes its lock; refuses a directory that is not a run, a run without a completed
    /// population (no law has a posterior to draw from), and a run whose every law lacks both
    /// particles and a finite least-squares fit.
    pub fn open(dir: &Path) -> Result<Self> {
        let stored = run::abc::Store::open(dir)?.load_with_last_particles()?;
        // Refused before any work: the check replaces only a check of its own.
        let selection = dir.join(SELECTION_DIR);
        files::refuse_foreign(&selection, "RUN_DIR", &|rel, is_dir| {
            crate::run::dir::owns_unchanged(crate::run::dir::Owned::Selection, &selection, rel, is_dir)
        })?;
        let config: run::abc::Config =
            serde_json::from_value(stored.setup.config.clone()).map_err(|e| Error::Data {
                path: dir.to_path_buf(),
                message: format!("the stored configuration is not one this bitrock reads: {e}"),
            })?;
        let prior_file = match &config.prior_file {
            Some(path) => Some(stored_prior_file(dir, path, &stored, &config)?),
            None => None,
        };
        let lock = files::DirLock::acquire(dir)?;
        Self::checked(Some(dir.to_path_buf()), config, stored, prior_file, Some(lock))
    }

    /// A run kept in memory (its configuration, and its set-up and populations as a store
    /// would hold them), checked as [`CheckedRun::open`] checks a stored one; its check is
    /// returned, not written.
    pub fn in_memory(config: run::abc::Config, stored: run::abc::Stored) -> Result<Self> {
        let prior_file = config
            .prior_file
            .as_ref()
            .map(|_| PriorFile::of_prior(&stored.setup.prior, stored.setup.data.torque_unit.newton_metres()));
        Self::checked(None, config, stored, prior_file, None)
    }

    /// The refusals shared by a stored run and one in memory.
    fn checked(
        dir: Option<PathBuf>,
        config: run::abc::Config,
        stored: run::abc::Stored,
        prior_file: Option<PriorFile>,
        lock: Option<files::DirLock>,
    ) -> Result<Self> {
        let source = stored.setup.data.source.clone();
        let refuse = |message: String| Error::Data {
            path: dir.clone().unwrap_or(source.clone()),
            message,
        };
        let Some(last) = stored.populations.last() else {
            return Err(refuse(
                "the run has no completed population: its laws all died out before one, so none has a posterior to draw synthetic records from".into(),
            ));
        };
        let usable = config.laws.iter().any(|&law| {
            last.particles.iter().any(|p| p.law == law)
                || fit_of(&stored.setup.fits, law).is_some_and(|f| f.rho.is_finite())
        });
        if !usable {
            return Err(refuse(
                "every law of the run died out and none has a finite least-squares fit to draw synthetic records from"
                    .into(),
            ));
        }
        Ok(Self {
            dir,
            config,
            stored,
            prior_file,
            _lock: lock,
        })
    }
}

/// The `--prior` file a run was made with, as its store keeps it ([`PriorFile::of_prior`]),
/// never read from `path`, where it may have moved or changed since. Accepted once it rebuilds
/// the run's own prior from the run's own fits exactly (boxes, rules and law thresholds); a
/// store that does not record which boxes the file gave (schema 1) cannot, and is refused.
fn stored_prior_file(
    dir: &Path,
    path: &Path,
    stored: &run::abc::Stored,
    config: &run::abc::Config,
) -> Result<PriorFile> {
    let prior = &stored.setup.prior;
    let unit = stored.setup.data.torque_unit.newton_metres();
    let file = PriorFile::of_prior(prior, unit);
    let rebuilt = Prior::from_fits_by(&stored.setup.fits, config.prior_rule, config.delta, Some(&file), unit);
    match rebuilt {
        Ok(p) if p.boxes == prior.boxes && p.rules == prior.rules && p.thresholds == prior.thresholds => Ok(file),
        _ => Err(Error::Data {
            path: dir.to_path_buf(),
            message: format!(
                "the run was made with the prior file {}, and its store does not record that file's boxes in a form the check can reuse (a store written by an older bitrock); start the run again with that prior file (`bitrock abc --prior {}`, or `prior_file=` in Python) and check the new run",
                path.display(),
                path.display()
            ),
        }),
    }
}

fn fit_of(fits: &[LawFit], law: Law) -> Option<&LawFit> {
    fits.iter().find(|f| f.law == law)
}

/// One replicate to run: its generating law (slot in the run's laws) and index.
#[derive(Clone, Copy)]
struct Job {
    slot: usize,
    replicate: usize,
}

/// The check's rows: per generating law its `k` replicates (in `results`, law after law),
/// their parameters from the posterior where the run's last population has the law, else from
/// its least squares.
fn rows_of(results: Vec<Replicate>, laws: &[Law], k: usize, run: &CheckedRun) -> Vec<GeneratingLaw> {
    let mut results = results.into_iter();
    let last = run.stored.populations.last().expect("checked by CheckedRun::open");
    laws.iter()
        .map(|&law| {
            let replicates: Vec<Replicate> = results.by_ref().take(k).collect();
            let source = if last.particles.iter().any(|p| p.law == law) {
                ParamSource::Posterior
            } else {
                ParamSource::LeastSquares
            };
            summarize_row(law, source, laws, replicates)
        })
        .collect()
}

/// Samples the `fitted` replicates of a batch, one thread each on its `seats` of the batched
/// scorer; each finished replicate counts up `done` (of `total`) and is reported to
/// `progress` under its lock, one call at a time.
fn sample_batch(
    run: &CheckedRun,
    options: &CheckOptions,
    fitted: Vec<Fitted>,
    seats: Vec<Seat>,
    (done, total): (&std::sync::Mutex<usize>, usize),
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Vec<Result<ReplicateOutcome>> {
    std::thread::scope(|scope| {
        let threads: Vec<_> = fitted
            .into_iter()
            .zip(seats)
            .map(|(fitted, seat)| {
                scope.spawn(move || {
                    let result = sample_replicate(run, options, fitted, &seat);
                    drop(seat);
                    let mut count = done.lock().unwrap_or_else(|p| p.into_inner());
                    *count += 1;
                    progress(*count, total);
                    drop(count);
                    result
                })
            })
            .collect();
        threads
            .into_iter()
            .map(|t| t.join().unwrap_or_else(|panic| std::panic::resume_unwind(panic)))
            .collect()
    })
}

/// Checks the selection of `run`: K replicates per law, each through the run's pipeline.
/// `progress(done, total)` is called as replicates finish, one call at a time with `done`
/// counting up 1, 2, … `total` (from whichever thread finished); `note` hears what
/// the user should know (the backend, a fallback to the CPU), each line once.
pub fn check(
    run: &CheckedRun,
    options: &CheckOptions,
    progress: &(dyn Fn(usize, usize) + Sync),
    note: &mut dyn FnMut(String),
) -> Result<SelectionCheck> {
    options.validate()?;
    let started = Instant::now();
    let config = &run.config;
    let laws = &config.laws;
    let k = options.replicates;
    check_size(run, options)?;
    let jobs: Vec<Job> = (0..laws.len())
        .flat_map(|slot| (0..k).map(move |replicate| Job { slot, replicate }))
        .collect();
    let batch = options.batch.unwrap_or(jobs.len()).max(1);
    // Counted and reported under one lock: a progress bar sees one call at a time, in order.
    let done = std::sync::Mutex::new(0usize);
    let mut results: Vec<Replicate> = Vec::with_capacity(jobs.len());
    let mut backend = "cpu";
    let mut gpu_shape = None;
    let mut timing = CheckTiming::default();
    let mut notes: Vec<String> = Vec::new();
    // The GPU scoring shape is measured (where this adapter never was) on the run's problem.
    let problem = Problem::new(
        run.stored.setup.prior.clone(),
        config.seed,
        &run.stored.setup.data.calibration,
        config.fit.w_ref_n,
    );
    for chunk in jobs.chunks(batch) {
        let fitting = Instant::now();
        let fitted: Vec<Result<Fitted>> = chunk.par_iter().map(|&job| fit_replicate(run, job)).collect();
        timing.fit_seconds += fitting.elapsed().as_secs_f64();
        let fitted: Vec<Fitted> = fitted.into_iter().collect::<Result<_>>()?;
        for fit in fitted.iter().flat_map(|f| &f.fits) {
            timing.fits.count(fit);
        }
        let sampling = Instant::now();
        let mut batch_notes = Vec::new();
        let records = RecordBatch::new(
            options.backend.unwrap_or(config.backend),
            run::scoring::shape_wish(config),
            &problem,
            chunk.len(),
            &mut |line| batch_notes.push(line),
        )?;
        // Every seat is taken before any sampler starts (see RecordBatch::seat).
        let seats: Vec<Seat> = fitted.iter().map(|_| records.seat()).collect();
        let outcomes = sample_batch(run, options, fitted, seats, (&done, jobs.len()), progress);
        timing.sampling_seconds += sampling.elapsed().as_secs_f64();
        batch_notes.extend(records.take_notes());
        let counts = records.counts();
        timing.batches += counts.batches;
        timing.dispatches += counts.dispatches;
        timing.scoring_seconds += counts.seconds;
        for line in batch_notes {
            if !notes.contains(&line) {
                note(line.clone());
                notes.push(line);
            }
        }
        if results.is_empty() {
            backend = records.backend();
            gpu_shape = records.gpu_shape();
        }
        for outcome in outcomes {
            let outcome = outcome?;
            timing.evaluations += outcome.evaluations;
            results.push(outcome.replicate);
        }
    }
    let rows = rows_of(results, laws, k, run);
    Ok(SelectionCheck {
        run_dir: run.dir.clone(),
        laws: laws.clone(),
        replicates: k,
        prior_rule: config.prior_rule,
        delta: config.delta,
        run_seed: config.seed,
        particles: config.sampler.schedule().particles,
        backend: backend.to_string(),
        gpu_shape,
        rows,
        seconds: started.elapsed().as_secs_f64(),
        timing,
        describes: Some(run.stored.state()),
    })
}

/// The row of `law` from its replicates.
fn summarize_row(law: Law, source: ParamSource, laws: &[Law], replicates: Vec<Replicate>) -> GeneratingLaw {
    let k = replicates.len() as f64;
    let own = laws.iter().position(|&l| l == law).expect("a law of the run");
    let mean_probability = (0..laws.len())
        .map(|j| replicates.iter().map(|r| r.probabilities[j]).sum::<f64>() / k)
        .collect();
    let firsts: Vec<usize> = (0..laws.len())
        .map(|j| replicates.iter().filter(|r| r.first == laws[j]).count())
        .collect();
    let own_values: Vec<f64> = replicates.iter().map(|r| r.probabilities[own]).collect();
    let own_probability = Quantiles::of(&own_values);
    let verdict = verdict(law, laws, &firsts, replicates.len(), own_probability.median);
    GeneratingLaw {
        law,
        source,
        mean_probability,
        first_share: firsts.iter().map(|&c| c as f64 / k).collect(),
        own_probability,
        verdict,
        replicates,
    }
}

/// "m2 data rank m2 first in 6 of 20 replicates and m1 in 14; median P(m2) = 0.43."
fn verdict(law: Law, laws: &[Law], firsts: &[usize], k: usize, median_own: f64) -> String {
    let own = firsts[laws.iter().position(|&l| l == law).expect("a law of the run")];
    let mut others: Vec<(Law, usize)> = laws
        .iter()
        .zip(firsts)
        .filter(|&(&l, &c)| l != law && c > 0)
        .map(|(&l, &c)| (l, c))
        .collect();
    others.sort_by_key(|&(_, count)| std::cmp::Reverse(count));
    let head = if own == k {
        format!("{law} data are recovered as {law} in all {k} replicates")
    } else if let Some(&(top, count)) = others.first()
        && count > own
    {
        format!("{law} data are assigned to {top} in {count} of {k} replicates ({law} ranks first in {own})")
    } else {
        format!("{law} data rank {law} first in {own} of {k} replicates")
    };
    let named_first = usize::from(others.first().is_some_and(|&(_, c)| c > own));
    let rest: Vec<String> = others[named_first..].iter().map(|(l, c)| format!("{l} {c}")).collect();
    let rest = if rest.is_empty() || own == k {
        String::new()
    } else {
        format!("; first elsewhere: {}", rest.join(", "))
    };
    format!("{head}{rest}; median P({law}) = {median_own:.2}.")
}

/// A replicate's synthetic record, fitted: the first phase of a replicate.
struct Fitted {
    job: Job,
    seed: u64,
    /// The generating parameters, SI.
    params_si: Vec<f64>,
    data: FieldData,
    fits: Vec<LawFit>,
}

/// One replicate run, with what the check reports besides it.
struct ReplicateOutcome {
    replicate: Replicate,
    /// Candidate × data-point evaluations of its sampler.
    evaluations: u64,
}

/// Makes replicate `job`'s synthetic record and fits every law of the run to it.
fn fit_replicate(run: &CheckedRun, job: Job) -> Result<Fitted> {
    let config = &run.config;
    let law = config.laws[job.slot];
    let seed = replicate_seed(config.seed, job.slot, job.replicate);
    let data = &run.stored.setup.data;
    let mut rng = StdRng::seed_from_u64(seed);
    let params_si = generating_params(run, law, &mut rng);
    let fit = fit_of(&run.stored.setup.fits, law).ok_or_else(|| Error::Data {
        path: run.dir.clone().unwrap_or(data.source.clone()),
        message: format!("the run has no least-squares fit of {law}"),
    })?;
    let w_ref_n = config.fit.w_ref_n;
    let residuals = crate::fit::residuals(law, &fit.params_si, &data.calibration, w_ref_n);
    let synthetic = FieldData {
        source: run
            .dir
            .as_deref()
            .unwrap_or(&data.source)
            .join(format!("{SELECTION_DIR}/{law}-replicate-{}", job.replicate)),
        calibration: synthesize(law, &params_si, &data.calibration, w_ref_n, &residuals, 0.0, &mut rng),
        validation: synthesize(law, &params_si, &data.validation, w_ref_n, &residuals, 0.0, &mut rng),
        warnings: Vec::new(),
        bit: None,
        ..data.clone()
    };
    // The fits start where the answers are believed to be, as well as on the grid: the run's
    // own estimates, and the generating parameters for the generating law.
    let known: Vec<(Law, Vec<f64>)> = std::iter::once((law, params_si.clone()))
        .chain(run.stored.setup.fits.iter().map(|f| (f.law, f.params_si.clone())))
        .collect();
    let fits = crate::fit::fit_record_from(&config.laws, &synthetic, &config.fit, &known)?;
    Ok(Fitted {
        job,
        seed,
        params_si,
        data: synthetic,
        fits,
    })
}

/// Runs the run's pipeline after the fits on a fitted replicate, in memory, its candidates
/// scored through `seat` with the other replicates'.
fn sample_replicate(run: &CheckedRun, options: &CheckOptions, fitted: Fitted, seat: &Seat) -> Result<ReplicateOutcome> {
    let config = &run.config;
    let Fitted {
        job,
        seed,
        params_si,
        data,
        fits,
    } = fitted;
    let law = config.laws[job.slot];
    let mut replicate_config = config.clone();
    replicate_config.seed = seed;
    replicate_config.backend = options.backend.unwrap_or(config.backend);
    replicate_config.sampler.schedule_mut().max_seconds = None;
    let mut evaluator = |problem, _: &mut dyn FnMut(String)| -> Result<Box<dyn crate::eval::Evaluator>> {
        Ok(Box::new(seat.evaluator(problem)))
    };
    let how = run::abc::Start {
        dir: None,
        prior_file: run.prior_file.as_ref(),
        fits: Some(fits),
        scoring: run::Scoring::Evaluator(&mut evaluator),
    };
    // Notes about the synthetic record's own floor differ per replicate and are not repeated;
    // the backend's come from the batch.
    let outcome =
        run::abc::start(data, replicate_config, how, &mut Silent).map_err(|e| in_replicate(law, job.replicate, e))?;
    let last = outcome.run.populations.last().ok_or_else(|| {
        Error::Incomplete(format!(
            "{law} replicate {}: no population completed ({})",
            job.replicate,
            outcome.run.stop.describe()
        ))
    })?;
    let probabilities: Vec<f64> = config.laws.iter().map(|&l| last.record.probability_of(l)).collect();
    let first = config.laws[first_index(&probabilities)];
    Ok(ReplicateOutcome {
        replicate: Replicate {
            index: job.replicate,
            seed,
            params_si,
            probabilities,
            first,
            final_epsilon: last.record.epsilon,
            populations: outcome.run.populations.len(),
            near_threshold: outcome.run.populations.iter().map(|p| p.record.near_threshold).sum(),
        },
        evaluations: outcome.run.evaluations,
    })
}

/// The index of the largest probability, the first among equals.
fn first_index(probabilities: &[f64]) -> usize {
    let mut best = 0;
    for (j, &p) in probabilities.iter().enumerate() {
        if p > probabilities[best] {
            best = j;
        }
    }
    best
}

/// An error of one replicate, saying which.
fn in_replicate(law: Law, replicate: usize, e: Error) -> Error {
    match e {
        Error::Numerical(m) => Error::Numerical(format!("{law} replicate {replicate}: {m}")),
        Error::Incomplete(m) => Error::Incomplete(format!("{law} replicate {replicate}: {m}")),
        other => other,
    }
}

/// Parameters of a replicate of `law`: a particle of its posterior drawn by weight, or its
/// least-squares estimate when it has none.
fn generating_params(run: &CheckedRun, law: Law, rng: &mut StdRng) -> Vec<f64> {
    let last = run.stored.populations.last().expect("checked by CheckedRun::open");
    let members = last
        .particles
        .iter()
        .filter(|p| p.law == law)
        .map(|p| (p.params.as_slice(), p.weight));
    draw_by_weight(members, rng).unwrap_or_else(|| {
        fit_of(&run.stored.setup.fits, law)
            .map(|f| f.params_si.clone())
            .unwrap_or_default()
    })
}

/// One parameter set of weighted `sets` drawn by weight; `None` when there are none.
pub(crate) fn draw_by_weight<'a>(
    sets: impl Iterator<Item = (&'a [f64], f64)> + Clone,
    rng: &mut StdRng,
) -> Option<Vec<f64>> {
    // Nothing to draw from takes nothing from the stream.
    sets.clone().next()?;
    let total: f64 = sets.clone().map(|(_, w)| w).sum();
    let mut u = rng.random::<f64>() * total;
    let mut last = None;
    for (params, w) in sets {
        u -= w;
        if u < 0.0 {
            return Some(params.to_vec());
        }
        last = Some(params);
    }
    last.map(<[f64]>::to_vec)
}

/// `samples` with its torque replaced by r·T(w) of `law` at `params` plus noise e_t drawn
/// with replacement from `draws`; with `phi` ≠ 0 the draws are the innovations of an AR(1)
/// filter, e_t = φ·e_(t−1) + u_t, its first value scaled to the stationary spread (a sieve
/// bootstrap: the residuals' distribution and their lag-1 correlation kept). `phi` = 0 gives
/// i.i.d. resampling.
pub(crate) fn synthesize(
    law: Law,
    params: &[f64],
    samples: &Samples,
    w_ref_n: Option<f64>,
    draws: &[f64],
    phi: f64,
    rng: &mut StdRng,
) -> Samples {
    let r = samples.wob_ratio(w_ref_n);
    let mut previous: Option<f64> = None;
    let torque_nm = samples
        .speed_rad_s
        .iter()
        .zip(&r)
        .map(|(&w, &r)| {
            let u = draws[rng.random_range(0..draws.len())];
            let e = match previous {
                None => u / (1.0 - phi * phi).sqrt(),
                Some(e) => phi * e + u,
            };
            previous = Some(e);
            law.torque(params, w, r) + e
        })
        .collect();
    Samples {
        torque_nm,
        ..samples.clone()
    }
}

/// Writes the check into `DIR/selection/`: selection.json, matrix.csv, replicates.csv and
/// its heat map as drawn by the report (`svg`, `png`: [`crate::report::write_selection`] draws
/// and writes). The files are written into a staging directory beside it and swapped in by one
/// rename, under the run directory's lock, so the directory holds the previous check or this
/// one, whole, at every moment.
pub fn write(run: &CheckedRun, check: &SelectionCheck, svg: String, png: Vec<u8>) -> Result<PathBuf> {
    let Some(dir) = run.dir.as_deref() else {
        return Err(Error::setting(
            "source",
            "a run kept in memory has no directory to write its check into; save it first",
        ));
    };
    let json = serde_json::to_string_pretty(check).expect("the check serialises") + "\n";
    let names = crate::run::dir::SELECTION_FILES;
    let bodies = [
        json.into_bytes(),
        check.matrix_csv(),
        check.replicates_csv(),
        svg.into_bytes(),
        png,
    ];
    let contents: Vec<(PathBuf, Vec<u8>)> = names.iter().map(PathBuf::from).zip(bodies).collect();
    let target = dir.join(SELECTION_DIR);
    files::replace_dir(
        &target,
        "RUN_DIR",
        &|rel, is_dir| crate::run::dir::owns_unchanged(crate::run::dir::Owned::Selection, &target, rel, is_dir),
        &contents,
    )?;
    Ok(target)
}

/// The check stored in run directory `dir`, if it holds one.
pub fn read(dir: &Path) -> Result<Option<SelectionCheck>> {
    let path = dir.join(SELECTION_DIR).join(SELECTION_JSON);
    let text = match std::fs::read_to_string(&path) {
        Ok(text) => text,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(source) => return Err(Error::Read { path, source }),
    };
    serde_json::from_str(&text).map(Some).map_err(|e| Error::Format {
        path,
        line: Some(e.line() as u64),
        message: format!("not a selection check this bitrock reads: {e}"),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn replicate_seeds_differ_by_law_replicate_and_run() {
        let mut seen = std::collections::HashSet::new();
        for run in [1u64, 2] {
            for slot in 0..4 {
                for r in 0..50 {
                    assert!(seen.insert(replicate_seed(run, slot, r)));
                }
            }
        }
        assert_eq!(replicate_seed(7, 2, 3), replicate_seed(7, 2, 3));
    }

    #[test]
    fn verdicts_name_the_winner() {
        let laws = [Law::M1, Law::M2, Law::M4];
        assert_eq!(
            verdict(Law::M2, &laws, &[14, 6, 0], 20, 0.43),
            "m2 data are assigned to m1 in 14 of 20 replicates (m2 ranks first in 6); median P(m2) = 0.43."
        );
        assert_eq!(
            verdict(Law::M1, &laws, &[10, 7, 3], 20, 0.5),
            "m1 data rank m1 first in 10 of 20 replicates; first elsewhere: m2 7, m4 3; median P(m1) = 0.50."
        );
        assert_eq!(
            verdict(Law::M4, &laws, &[0, 0, 20], 20, 0.9),
            "m4 data are recovered as m4 in all 20 replicates; median P(m4) = 0.90."
        );
        assert_eq!(first_index(&[0.25, 0.5, 0.5]), 1);
    }
}
