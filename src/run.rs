//! An ABC run from configuration to run directory: least-squares fits, the prior, the
//! evaluator, the sampler, and the run store that every completed population is written to.
//! [`start`] begins a run in a fresh directory; [`resume`] continues a killed or finished one
//! from its store and gives exactly the populations an uninterrupted run would.

use crate::abc::floor;
use crate::abc::rejection::{self, Mode, RejectionConfig};
use crate::abc::schedule::Schedule;
use crate::abc::shard::{self, Devices, Local, Workers};
use crate::abc::smc::{self, LawProposal, Perturbation, Refill, SmcConfig, WeightsOn};
use crate::abc::{Observer, Population, Progress, Run};
use crate::data::FieldData;
use crate::error::{Error, Result};
use crate::eval::gpu::{Shape, tune::ShapeWish};
use crate::eval::{AbcProblem, Backend, Evaluator};
use crate::files;
use crate::fit::{self, FitOptions};
use crate::laws::Law;
use crate::limits;
use crate::prior::{Prior, PriorFile, PriorRule};
use crate::store::{PendingPopulation, RunSetup, RunStore, STORE_FILE, StoreLayout, StoredRun};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Everything that defines a run besides its data: stored with the run, so that `--resume`
/// needs nothing else. [`Default`] is `bitrock abc`'s defaults (every law, bounded fits, δ =
/// 0.4, seed 1, the paper's rejection sampler with N = 25,000 down to ε = 0.014).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunConfig {
    /// Laws competing, in order (the prior's boxes follow it).
    pub laws: Vec<Law>,
    pub fit: FitOptions,
    /// Prior half-width δ.
    pub delta: f64,
    /// How the prior boxes are sized: the paper's δ rule or k standard errors (runs stored
    /// before the option read as the δ rule).
    #[serde(default)]
    pub prior_rule: PriorRule,
    /// The prior file the boxes were read from (provenance; the prior itself is stored).
    pub prior_file: Option<PathBuf>,
    pub seed: u64,
    pub backend: Backend,
    /// Every GPU of the machine or one (see [`Devices`]); the populations are the same.
    #[serde(default)]
    pub devices: Devices,
    /// The GPU scoring shape of the run's last GPU scoring: a resumed run and its selection
    /// check score in it too, unless `BITROCK_GPU_SHAPE` names another (see
    /// [`crate::eval::gpu::tune`]). `None` until a GPU scored.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gpu_shape: Option<Shape>,
    pub sampler: SamplerConfig,
    /// Replace the sampler's eps_min by the floor the record can reach ([`floor::resolve`]:
    /// the paper's 0.014 where reachable), in [`start`], and store the result. `bitrock abc`
    /// sets it when `--eps-min` is not given; [`Default`] leaves eps_min as given.
    #[serde(default)]
    pub eps_min_from_record: bool,
}

impl Default for RunConfig {
    fn default() -> Self {
        Self {
            laws: Law::ALL.to_vec(),
            fit: FitOptions::default(),
            delta: 0.4,
            prior_rule: PriorRule::Delta,
            prior_file: None,
            seed: 1,
            backend: Backend::Auto,
            devices: Devices::One,
            gpu_shape: None,
            sampler: SamplerConfig::Rejection(RejectionConfig::default()),
            eps_min_from_record: false,
        }
    }
}

impl RunConfig {
    /// The one gate of a run's settings: refuses, naming the setting, what cannot run (an empty
    /// law list, bad fit options, δ ≤ 0, sampler settings out of range), before any work.
    pub fn validate(&self) -> Result<()> {
        if self.laws.is_empty() {
            return Err(Error::setting("laws", "give at least one law"));
        }
        // Before any fit: the prior holds at most this many boxes.
        if self.laws.len() > crate::prior::MAX_LAWS {
            return Err(Error::setting(
                "laws",
                format!(
                    "{} laws given; a run compares at most {}",
                    self.laws.len(),
                    crate::prior::MAX_LAWS
                ),
            ));
        }
        self.fit.validate()?;
        if !(self.delta.is_finite() && self.delta > 0.0) {
            return Err(Error::setting(
                "delta",
                format!("must be a positive number, got {}", self.delta),
            ));
        }
        self.prior_rule.validate()?;
        self.sampler.validate()?;
        if let SamplerConfig::Smc(smc) = &self.sampler {
            let fewest_params = self.laws.iter().map(|l| l.params().len()).min().unwrap_or(0);
            smc.check_kernel_reach(fewest_params)?;
        }
        let particles = self.sampler.schedule().particles;
        limits::check_memory(
            "particles",
            POPULATIONS_HELD * particles as f64 * PARTICLE_BYTES as f64,
            &format!("holding {POPULATIONS_HELD} populations of {particles} particles"),
        )
    }
}

impl RunConfig {
    /// Takes the GPU scoring shape `workers` score in, where they name one (workers elsewhere
    /// do only once they have scored).
    fn take_shape_of(&mut self, workers: &dyn Workers) {
        self.gpu_shape = workers.gpu_shape().or(self.gpu_shape);
    }

    /// Refuses a summary population `g` the run can never have (at or beyond
    /// `--max-populations`), before the run rather than after it.
    pub fn check_summary_population(&self, g: Option<usize>) -> Result<()> {
        let max = self.sampler.schedule().max_populations;
        match g {
            Some(g) if g >= max => Err(Error::setting(
                "summary_population",
                format!("the run has at most {max} populations (0..={}), got {g}", max - 1),
            )),
            _ => Ok(()),
        }
    }
}

/// Which ABC sampler runs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "lowercase")]
pub enum Sampler {
    /// The paper's Algorithm 1 (see [`Mode`]).
    #[default]
    Rejection,
    /// ABC-SMC with model selection: population 0 from the prior, then perturbed,
    /// importance-weighted populations.
    Smc,
}

/// How prior boxes are sized, without the rule's k ([`PriorRule`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "lowercase")]
pub enum PriorRuleName {
    /// The paper's φ̂(1 ± δ).
    #[default]
    Delta,
    /// φ̂ ± k·σ̂ from the fit's standard errors.
    Stderr,
}

/// `prior_k` when not given: three standard errors each side, where a Gaussian estimate lies
/// with probability 99.7 %.
pub const DEFAULT_PRIOR_K: f64 = 3.0;

/// A new run's settings as a user gives them (the command line's flags, the Python package's
/// keyword arguments): every `None` takes the library's default, and [`Settings::config`]
/// turns them into the [`RunConfig`] the run stores, refusing settings that the run would
/// ignore.
#[derive(Clone, Debug, Default)]
pub struct Settings {
    /// Laws competing; `None` is every law.
    pub laws: Option<Vec<Law>>,
    pub fit: FitOptions,
    pub sampler: Sampler,
    pub particles: Option<usize>,
    pub delta: Option<f64>,
    pub prior_rule: PriorRuleName,
    pub prior_k: Option<f64>,
    pub prior_file: Option<PathBuf>,
    /// The floor ε_min; `None` is the record's reachable floor (the paper's 0.014 where the
    /// record reaches it), or 0 under a schedule.
    pub eps_min: Option<f64>,
    /// A tolerance schedule for populations 1, 2, …, which then ends the run.
    pub epsilons: Option<Vec<f64>>,
    pub start_epsilon: Option<f64>,
    pub max_populations: Option<usize>,
    pub max_draws: Option<u64>,
    pub min_acceptance: Option<f64>,
    pub max_seconds: Option<f64>,
    /// Rejection sampler only.
    pub mode: Option<Mode>,
    /// SMC only.
    pub p_stay: Option<f64>,
    /// SMC only.
    pub kernel_scale: Option<f64>,
    /// SMC only.
    pub smc_weights: Option<WeightsOn>,
    /// SMC only.
    pub refill: Option<Refill>,
    /// SMC only.
    pub law_proposal: Option<LawProposal>,
    /// SMC only.
    pub perturbation: Option<Perturbation>,
    pub seed: Option<u64>,
    pub backend: Option<Backend>,
    pub devices: Option<Devices>,
}

impl Settings {
    /// The run's configuration. A schedule is the user's: it ends the run where it ends (no
    /// floor below it unless `eps_min` is given) and has room for all its populations unless
    /// `max_populations` says less. Settings of the other sampler, and `prior_k` with the δ
    /// rule, are refused: the run would ignore them.
    pub fn config(&self) -> Result<RunConfig> {
        self.check_sampler_settings()?;
        if self.prior_rule == PriorRuleName::Delta && self.prior_k.is_some() {
            return Err(Error::setting(
                "prior_k",
                "applies only to `prior_rule` stderr, and this run sizes its prior boxes by δ (the default rule); add `prior_rule` stderr or leave it out",
            ));
        }
        let defaults = RunConfig::default();
        let shared = Schedule::default();
        let user_schedule = self.epsilons.as_ref().map(Vec::len);
        let schedule = Schedule {
            particles: self.particles.unwrap_or(shared.particles),
            eps_min: self
                .eps_min
                .unwrap_or(if user_schedule.is_some() { 0.0 } else { shared.eps_min }),
            max_populations: self
                .max_populations
                .unwrap_or(shared.max_populations.max(user_schedule.map_or(0, |n| n + 1))),
            max_draws: self.max_draws.unwrap_or(shared.max_draws),
            min_acceptance: self.min_acceptance.unwrap_or(shared.min_acceptance),
            start_epsilon: self.start_epsilon,
            epsilons: self.epsilons.clone(),
            max_seconds: self.max_seconds,
            ..shared
        };
        let sampler = match self.sampler {
            Sampler::Rejection => SamplerConfig::Rejection(RejectionConfig {
                schedule,
                mode: self.mode.unwrap_or(RejectionConfig::default().mode),
            }),
            Sampler::Smc => {
                let smc = SmcConfig::default();
                SamplerConfig::Smc(SmcConfig {
                    schedule,
                    p_stay: self.p_stay.unwrap_or(smc.p_stay),
                    kernel_scale: self.kernel_scale.unwrap_or(smc.kernel_scale),
                    weights_on: self.smc_weights.unwrap_or(smc.weights_on),
                    refill: self.refill.unwrap_or(smc.refill),
                    law_proposal: self.law_proposal.unwrap_or(smc.law_proposal),
                    perturbation: self.perturbation.unwrap_or(smc.perturbation),
                })
            }
        };
        Ok(RunConfig {
            laws: self.laws.clone().unwrap_or(defaults.laws),
            fit: self.fit,
            delta: self.delta.unwrap_or(defaults.delta),
            prior_rule: match self.prior_rule {
                PriorRuleName::Delta => PriorRule::Delta,
                PriorRuleName::Stderr => PriorRule::Stderr {
                    k: self.prior_k.unwrap_or(DEFAULT_PRIOR_K),
                },
            },
            prior_file: self.prior_file.clone(),
            seed: self.seed.unwrap_or(defaults.seed),
            backend: self.backend.unwrap_or(defaults.backend),
            devices: self.devices.unwrap_or(defaults.devices),
            gpu_shape: None,
            sampler,
            eps_min_from_record: self.eps_min.is_none() && user_schedule.is_none(),
        })
    }

    /// Refuses a setting of the other sampler, or of an SMC scheme the run does not use, naming
    /// it and what the run uses.
    fn check_sampler_settings(&self) -> Result<()> {
        match self.sampler {
            Sampler::Rejection => {
                let smc_only = [
                    ("p_stay", self.p_stay.is_some()),
                    ("kernel_scale", self.kernel_scale.is_some()),
                    ("smc_weights", self.smc_weights.is_some()),
                    ("refill", self.refill.is_some()),
                    ("law_proposal", self.law_proposal.is_some()),
                    ("perturbation", self.perturbation.is_some()),
                ];
                match smc_only.into_iter().find(|&(_, given)| given) {
                    Some((field, _)) => Err(Error::setting(
                        field,
                        "applies only to `sampler` smc, and this run uses the rejection sampler (the default); add `sampler` smc or leave it out",
                    )),
                    None => Ok(()),
                }
            }
            Sampler::Smc if self.mode.is_some() => Err(Error::setting(
                "mode",
                "applies only to the rejection sampler, and this run uses `sampler` smc, which perturbs each population into the next instead of drawing streams; drop `mode`",
            )),
            Sampler::Smc
                if self.p_stay.is_some()
                    && self.law_proposal.unwrap_or(SmcConfig::default().law_proposal) == LawProposal::Worth =>
            {
                Err(Error::setting(
                    "p_stay",
                    "applies only to `law_proposal` kernel, and this run proposes laws by their worth; drop `p_stay` or use `law_proposal` kernel",
                ))
            }
            Sampler::Smc
                if self.kernel_scale.is_some()
                    && self.perturbation.unwrap_or(SmcConfig::default().perturbation) == Perturbation::Local =>
            {
                Err(Error::setting(
                    "kernel_scale",
                    "applies only to `perturbation` global; the local perturbation takes each ancestor's own covariance; drop `kernel_scale` or use `perturbation` global",
                ))
            }
            Sampler::Smc => Ok(()),
        }
    }
}

/// Populations a sampler holds at least while drawing: the last one and the one being drawn.
const POPULATIONS_HELD: f64 = 2.0;
/// Memory of one particle: the struct and its parameters on the heap.
const PARTICLE_BYTES: usize = std::mem::size_of::<crate::abc::Particle>() + crate::laws::MAX_PARAMS * 8;

/// The sampler and its settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "sampler", rename_all = "lowercase")]
pub enum SamplerConfig {
    /// The paper's rejection sampler (Algorithm 1), nested or as published.
    Rejection(RejectionConfig),
    /// ABC-SMC with model selection (Toni et al. 2009).
    Smc(SmcConfig),
}

impl SamplerConfig {
    /// Refuses settings that cannot run, naming the setting.
    pub fn validate(&self) -> Result<()> {
        match self {
            SamplerConfig::Rejection(c) => c.validate(),
            SamplerConfig::Smc(c) => c.validate(),
        }
    }

    /// The stopping rules and tolerances every sampler shares.
    pub fn schedule(&self) -> &Schedule {
        match self {
            SamplerConfig::Rejection(c) => &c.schedule,
            SamplerConfig::Smc(c) => &c.schedule,
        }
    }

    /// The stopping rules and tolerances every sampler shares, to change.
    pub fn schedule_mut(&mut self) -> &mut Schedule {
        match self {
            SamplerConfig::Rejection(c) => &mut c.schedule,
            SamplerConfig::Smc(c) => &mut c.schedule,
        }
    }

    fn apply(&mut self, more: &Continuation) {
        let c = self.schedule_mut();
        c.eps_min = more.eps_min.unwrap_or(c.eps_min);
        c.max_populations = more.max_populations.unwrap_or(c.max_populations);
        c.max_draws = more.max_draws.unwrap_or(c.max_draws);
        c.min_acceptance = more.min_acceptance.unwrap_or(c.min_acceptance);
        // A wall-time budget belongs to one invocation, not to the run.
        c.max_seconds = more.max_seconds;
    }
}

/// What `--resume` may change: the stopping rules and the backend. Everything else defines
/// the populations and is taken from the store.
#[derive(Clone, Debug, Default)]
pub struct Continuation {
    pub eps_min: Option<f64>,
    pub max_populations: Option<usize>,
    pub max_draws: Option<u64>,
    pub min_acceptance: Option<f64>,
    pub max_seconds: Option<f64>,
    pub backend: Option<Backend>,
    pub devices: Option<Devices>,
    /// The population this invocation summarises (default: the last), checked against the
    /// continued run's `max_populations` before any population is drawn.
    pub summary_population: Option<usize>,
}

/// A run after an invocation: its set-up, every population, and why it stopped.
pub struct Outcome {
    pub config: RunConfig,
    pub setup: RunSetup,
    pub run: Run,
    /// Backend that scored this invocation's candidates (`cpu`, `gpu`).
    pub backend: &'static str,
    /// The run directory's lock, held while the outcome lives (its summary files are written
    /// under it); `None` for a run in memory.
    pub lock: Option<files::DirLock>,
    /// Populations this invocation added (a resume whose stopping rules already end the run
    /// adds none, and then changes nothing: `config` is the stored one).
    pub added: usize,
}

/// Where a run is written.
#[derive(Clone, Debug, PartialEq)]
pub struct RunDir {
    pub path: PathBuf,
    /// Replace the bitrock run the directory holds (`--force`); without it such a directory
    /// is refused before any work. A directory holding anything bitrock did not write is
    /// refused either way.
    pub replace: bool,
}

/// What a run directory holds, once [`check_new_run_dir`] accepted it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DirState {
    /// Missing, empty, or holding only bitrock's temporaries: the run is written in place.
    Fresh,
    /// A bitrock run, to be replaced (`--force`) once the new run's first population is stored.
    Replace,
}

/// Refuses, before any work and naming `--out`, a run directory that cannot be written: one
/// that holds anything bitrock did not write (even with `replace`), the current directory or
/// one holding the record `input` (the record is never deleted), a bitrock run without
/// `replace`, a store that is not a bitrock store.
pub fn check_new_run_dir(dir: &RunDir, input: Option<&Path>) -> Result<DirState> {
    let path = dir.path.as_path();
    files::check_output_dir(path, "out")?;
    files::refuse_inside_run(path, "out")?;
    let refuse = |why: String| Err(Error::setting("out", format!("{}: {why}", path.display())));
    let Ok(real) = path.canonicalize() else {
        return Ok(DirState::Fresh);
    };
    if let Some(input) = input.and_then(|i| i.canonicalize().ok())
        && input.starts_with(&real)
    {
        return refuse(format!(
            "holds the record {}; write the run to a directory of its own",
            input.display()
        ));
    }
    let has_store = crate::rundir::is_run_dir(path);
    // Without a store nothing in the directory is a run's: only bitrock's temporaries may be there.
    files::refuse_foreign(path, "out", &|rel, is_dir| {
        has_store && crate::rundir::Owned::Run.owns(rel, is_dir)
    })?;
    if !has_store {
        return Ok(DirState::Fresh);
    }
    if let Err(e) = RunStore::open(path) {
        return refuse(format!(
            "its {STORE_FILE} cannot be read as a bitrock run ({e}); remove the directory yourself if it can go"
        ));
    }
    if !dir.replace {
        return refuse("holds a bitrock run; pass `force` to replace it".into());
    }
    if std::env::current_dir().is_ok_and(|cwd| cwd.canonicalize().is_ok_and(|cwd| cwd == real)) {
        return refuse(
            "is the current directory, which is never replaced; give the run directory's path from its parent".into(),
        );
    }
    Ok(DirState::Replace)
}

/// Fits, builds the prior and the evaluator, then samples. With a `dir`, the run directory is
/// claimed (locked, one writer at a time) with its store first, and every population is
/// stored as it completes; without one the run lives in memory only. A run replacing another
/// ([`DirState::Replace`]) is staged beside it and swapped in once its first population is
/// stored, so that the directory holds the old run or the new one at every moment.
/// `prior_file` is the parsed `config.prior_file`. The directory is created only once
/// everything that can be refused has been.
pub fn start(
    dir: Option<&RunDir>,
    data: FieldData,
    config: RunConfig,
    prior_file: Option<&PriorFile>,
    observer: &mut dyn Observer,
) -> Result<Outcome> {
    start_on(dir, data, config, prior_file, &mut here, observer)
}

/// [`start`] with the populations' tasks run by the workers `make_workers` makes from the
/// run's problem (a pool of processes or machines: [`crate::abc::shard`]); the result is the
/// one [`start`] gives.
pub fn start_on(
    dir: Option<&RunDir>,
    data: FieldData,
    config: RunConfig,
    prior_file: Option<&PriorFile>,
    make_workers: &mut MakeWorkers,
    observer: &mut dyn Observer,
) -> Result<Outcome> {
    config.validate()?;
    if let Some(dir) = dir {
        check_new_run_dir(dir, Some(&data.source))?;
    }
    let fits = fit::fit_record(&config.laws, &data, &config.fit)?;
    start_with_fits(dir, data, config, fits, prior_file, make_workers, observer)
}

/// Makes a run's evaluator from its problem, saying what the user should know through the
/// second argument ([`crate::eval::evaluator`] of the run's backend, unless the caller scores
/// elsewhere).
pub type MakeEvaluator<'a> = dyn FnMut(AbcProblem, &mut dyn FnMut(String)) -> Result<Box<dyn Evaluator>> + 'a;

/// Makes the workers that run a run's tasks from its problem and configuration (a continued
/// run's with the continuation's backend and devices), saying what the user should know
/// through the third argument.
pub type MakeWorkers<'a> =
    dyn FnMut(AbcProblem, &RunConfig, &mut dyn FnMut(String)) -> Result<Box<dyn Workers + 'a>> + 'a;

/// The workers of this process for a run of `config`: [`shard::here`] with its backend,
/// devices and GPU scoring shape.
pub fn here(problem: AbcProblem, config: &RunConfig, note: &mut dyn FnMut(String)) -> Result<Box<dyn Workers>> {
    shard::here(problem, config.backend, config.devices, shape_wish(config), note)
}

/// What a run of `config` asks of the GPU scoring shape: its recorded one, for dispatches of
/// its size.
pub fn shape_wish(config: &RunConfig) -> ShapeWish {
    ShapeWish::for_run(config.gpu_shape, config.sampler.schedule().particles)
}

/// [`start`] of a run in memory whose record's least-squares fits the caller made
/// (`fit::fit_record(&config.laws, &data, &config.fit)`) and whose evaluator the caller makes
/// from the run's problem: the selection check fits all its replicates' records before
/// sampling any, and scores their candidates together ([`crate::eval::records`]).
pub fn start_fitted_in_memory(
    data: FieldData,
    config: RunConfig,
    fits: Vec<fit::LawFit>,
    prior_file: Option<&PriorFile>,
    make_evaluator: &mut MakeEvaluator,
    observer: &mut dyn Observer,
) -> Result<Outcome> {
    config.validate()?;
    let mut here = |problem, _: &RunConfig, note: &mut dyn FnMut(String)| -> Result<Box<dyn Workers + '_>> {
        Ok(Box::new(Local(make_evaluator(problem, note)?)))
    };
    start_with_fits(None, data, config, fits, prior_file, &mut here, observer)
}

/// [`start`] after the fits: the floor, the prior, the evaluator, the sampler.
fn start_with_fits(
    dir: Option<&RunDir>,
    data: FieldData,
    mut config: RunConfig,
    fits: Vec<fit::LawFit>,
    prior_file: Option<&PriorFile>,
    make_workers: &mut MakeWorkers,
    observer: &mut dyn Observer,
) -> Result<Outcome> {
    let input = data.source.clone();
    let base = config.sampler.schedule_mut();
    let floor = floor::resolve(&fits, (!config.eps_min_from_record).then_some(base.eps_min))?;
    base.eps_min = floor.eps_min;
    floor::check_start_epsilon(&fits, base.start_epsilon)?;
    // A schedule ends the run itself: a floor out of reach says nothing then.
    if let Some(line) = &floor.note
        && base.epsilons.is_none()
    {
        observer.note(line.clone());
    }
    let prior = Prior::from_fits_by(
        &fits,
        config.prior_rule,
        config.delta,
        prior_file,
        data.torque_unit.newton_metres(),
    )?;
    let problem =
        AbcProblem::new(prior.clone(), config.seed, &data.calibration, config.fit.w_ref_n).with_best_rho(&fits);
    let evaluator = make_workers(problem, &config, &mut |line| observer.note(line))?;
    config.take_shape_of(evaluator.as_ref());
    let mut setup = RunSetup {
        config: serde_json::to_value(&config).expect("the configuration serialises"),
        data,
        fits,
        prior,
    };
    let (run, lock) = match dir {
        Some(dir) => {
            let mut claim = Claim::new(dir, Some(&input))?;
            let store = RunStore::create(claim.store_dir(), &setup)?;
            let run = sample(
                Some(store),
                Some(&mut claim),
                "start",
                &config,
                evaluator.as_ref(),
                Vec::new(),
                observer,
            )?;
            (run, Some(claim.finish()?))
        }
        None => (
            sample(None, None, "start", &config, evaluator.as_ref(), Vec::new(), observer)?,
            None,
        ),
    };
    let added = run.populations.len();
    // Workers elsewhere name their shape only once they have scored.
    config.take_shape_of(evaluator.as_ref());
    setup.config = serde_json::to_value(&config).expect("the configuration serialises");
    Ok(Outcome {
        config,
        setup,
        run,
        backend: evaluator.backend(),
        lock,
        added,
    })
}

/// A run directory being written: its lock, and for a replacement the staging directory beside
/// it that the new run is written to until its first population is stored.
struct Claim {
    dir: PathBuf,
    /// The run directory's lock; `None` once handed to the outcome.
    lock: Option<files::DirLock>,
    /// The new run's directory and lock while it is staged; `None` once in place.
    staged: Option<(PathBuf, files::DirLock)>,
}

impl Claim {
    /// Locks `dir` (creating it) and checks again under the lock what it holds; stages the new
    /// run beside a run it replaces.
    fn new(dir: &RunDir, input: Option<&Path>) -> Result<Self> {
        let path = dir.path.clone();
        std::fs::create_dir_all(&path).map_err(|source| Error::output("out", &path, source))?;
        let lock = files::DirLock::acquire(&path)?;
        // Another process may have written a run here since the first check.
        let state = check_new_run_dir(dir, input)?;
        files::remove_stale(&path);
        let staged = match state {
            DirState::Fresh => None,
            DirState::Replace => {
                let parent = files::parent_dir(&path);
                files::remove_stale(parent);
                let staging = tempfile::Builder::new()
                    .prefix(files::STAGING_PREFIX)
                    .tempdir_in(parent)
                    .map_err(|source| Error::output("out", &path, source))?
                    .keep();
                let staging_lock = files::DirLock::acquire(&staging)?;
                Some((staging, staging_lock))
            }
        };
        Ok(Self {
            dir: path,
            lock: Some(lock),
            staged,
        })
    }

    /// Where the store is created: the staging directory, or the run directory itself.
    fn store_dir(&self) -> &Path {
        self.staged.as_ref().map_or(&self.dir, |(staging, _)| staging)
    }

    /// Swaps a staged run into place (its first population is stored) and removes the old
    /// run; the store must then be reopened at its new place. No-op for a run in place.
    /// True while the new run is staged beside the run it replaces.
    fn is_staged(&self) -> bool {
        self.staged.is_some()
    }

    fn put_in_place(&mut self) -> Result<bool> {
        let Some((staging, staging_lock)) = self.staged.take() else {
            return Ok(false);
        };
        files::exchange_dirs(&self.dir, &staging).map_err(|source| Error::output("out", &self.dir, source))?;
        files::sync_dir(files::parent_dir(&self.dir));
        // The staging name now holds the old run, still locked by us: gone before the lock is.
        let old_lock = self.lock.replace(staging_lock);
        std::fs::remove_dir_all(&staging).map_err(|source| Error::output("out", &staging, source))?;
        drop(old_lock);
        Ok(true)
    }

    /// The lock of the run directory once sampling ended. A staged run that stored no
    /// population is discarded: the old run stays.
    fn finish(&mut self) -> Result<files::DirLock> {
        if let Some((staging, staging_lock)) = self.staged.take() {
            let _ = std::fs::remove_dir_all(&staging);
            drop(staging_lock);
            return Err(Error::Incomplete(format!(
                "the new run stored no population; {} still holds the run it held",
                self.dir.display()
            )));
        }
        Ok(self.lock.take().expect("the lock is handed over once"))
    }
}

impl Drop for Claim {
    /// A staged run abandoned by an error is removed; the old run stays.
    fn drop(&mut self) {
        if let Some((staging, _)) = &self.staged {
            let _ = std::fs::remove_dir_all(staging);
        }
    }
}

/// The first store schema written by bitrock with the integer-exact candidate transform
/// ([`crate::rng::uniform_between`]); runs of older stores cannot be continued exactly.
const FIRST_EXACT_CANDIDATES_SCHEMA: i64 = 2;

/// Continues the run in `dir` after its last stored population with the stopping rules of
/// `more`; the populations are those an uninterrupted run with the same settings gives.
pub fn resume(dir: &Path, more: &Continuation, observer: &mut dyn Observer) -> Result<Outcome> {
    resume_on(dir, more, &mut here, observer)
}

/// [`resume`] with the new populations' tasks run by the workers `make_workers` makes.
pub fn resume_on(
    dir: &Path,
    more: &Continuation,
    make_workers: &mut MakeWorkers,
    observer: &mut dyn Observer,
) -> Result<Outcome> {
    let store = RunStore::open(dir)?;
    if store.schema_version() < FIRST_EXACT_CANDIDATES_SCHEMA {
        return Err(Error::Data {
            path: store.path().to_path_buf(),
            message: format!(
                "written by an older bitrock (store schema {}), whose candidate parameters were rounded differently (by an ulp in some candidates): continuing it would not reproduce an uninterrupted run; start a new run (export and report still read this one)",
                store.schema_version()
            ),
        });
    }
    let lock = files::DirLock::acquire(dir)?;
    files::remove_stale(dir);
    let StoredRun { setup, populations } = store.load_with_last_particles()?;

    let mut config: RunConfig = serde_json::from_value(setup.config.clone()).map_err(|e| Error::Store {
        path: dir.join(STORE_FILE),
        message: format!("the stored configuration is not one this bitrock reads: {e}"),
    })?;
    check_stored_run(dir, &config, &setup.prior, &populations)?;
    let stored_config = config.clone();
    config.sampler.apply(more);
    config.backend = more.backend.unwrap_or(config.backend);
    config.devices = more.devices.unwrap_or(config.devices);
    config.validate()?;
    config.check_summary_population(more.summary_population)?;
    let problem = AbcProblem::new(
        setup.prior.clone(),
        config.seed,
        &setup.data.calibration,
        config.fit.w_ref_n,
    )
    .with_best_rho(&setup.fits);
    let evaluator = make_workers(problem, &config, &mut |line| observer.note(line))?;
    config.take_shape_of(evaluator.as_ref());
    let stored = populations.len();
    observer.note(format!(
        "continuing {} after population {} ({} stored)",
        dir.display(),
        stored.saturating_sub(1),
        stored
    ));
    let run = sample(
        Some(store),
        None,
        "resume",
        &config,
        evaluator.as_ref(),
        populations,
        observer,
    )?;
    let added = run.populations.len() - stored;
    config.take_shape_of(evaluator.as_ref());
    if added == 0 {
        // Nothing was run: the stored facts stand, and so does every file made from them.
        config = stored_config;
    }
    let setup = RunSetup {
        config: serde_json::to_value(&config).expect("the configuration serialises"),
        ..setup
    };
    Ok(Outcome {
        config,
        setup,
        run,
        backend: evaluator.backend(),
        lock: Some(lock),
        added,
    })
}

/// Refuses a store whose populations no longer match its settings (rows deleted or edited by
/// hand): the sampler continues from the last population and would otherwise silently give a
/// run that no settings produce. Earlier populations are loaded without particles
/// (`load_with_last_particles`), so their records are checked, and the last one's particles:
/// the count, each particle's law, parameters inside the stored prior, ρ below its ε, and
/// weights that sum to 1.
fn check_stored_run(dir: &Path, config: &RunConfig, prior: &Prior, populations: &[Population]) -> Result<()> {
    let refuse = |g: usize, what: String| Error::Data {
        path: dir.join(STORE_FILE),
        message: format!(
            "population {g} {what}; the store was altered and this run cannot be continued (start a new run)"
        ),
    };
    let n = config.sampler.schedule().particles;
    let mut previous_epsilon = f64::INFINITY;
    for (g, p) in populations.iter().enumerate() {
        let r = &p.record;
        if r.index != g {
            return Err(refuse(g, format!("is stored as population {}", r.index)));
        }
        if r.accepted != n {
            return Err(refuse(
                g,
                format!("holds {} particles where the run draws {n}", r.accepted),
            ));
        }
        let epsilon = r.epsilon.unwrap_or(f64::INFINITY);
        if g > 0 && epsilon.partial_cmp(&previous_epsilon) != Some(std::cmp::Ordering::Less) {
            return Err(refuse(
                g,
                format!("has ε = {epsilon}, not below the previous population's {previous_epsilon}"),
            ));
        }
        previous_epsilon = epsilon;
    }
    let Some(last) = populations.last() else {
        return Ok(());
    };
    let g = last.record.index;
    if last.particles.len() != last.record.accepted {
        return Err(refuse(
            g,
            format!("has {} of its {} particles", last.particles.len(), last.record.accepted),
        ));
    }
    let epsilon = last.record.epsilon.unwrap_or(f64::INFINITY);
    for particle in &last.particles {
        let Some(law_box) = prior.boxes.iter().find(|b| b.law == particle.law) else {
            return Err(refuse(
                g,
                format!("holds a particle of {}, a law the run does not compete", particle.law),
            ));
        };
        if particle.params.len() != particle.law.n_params() || !law_box.contains(&particle.params) {
            return Err(refuse(
                g,
                format!(
                    "holds a {} particle (index {}) outside the run's prior",
                    particle.law, particle.index
                ),
            ));
        }
        if particle.rho.partial_cmp(&epsilon) != Some(std::cmp::Ordering::Less) {
            return Err(refuse(
                g,
                format!(
                    "holds a particle (index {}) with ρ = {} not below its ε = {epsilon}",
                    particle.index, particle.rho
                ),
            ));
        }
    }
    let total: f64 = last.particles.iter().map(|p| p.weight).sum();
    if !last.particles.iter().all(|p| p.weight.is_finite() && p.weight >= 0.0) || (total - 1.0).abs() > 1e-6 {
        return Err(refuse(g, format!("has particle weights summing to {total}, not 1")));
    }
    Ok(())
}

/// Runs the sampler after `previous`, writing each new population to `store` when there is
/// one, and putting a staged run in place once its first population is stored.
fn sample(
    store: Option<RunStore>,
    claim: Option<&mut Claim>,
    kind: &'static str,
    config: &RunConfig,
    evaluator: &dyn Workers,
    previous: Vec<Population>,
    observer: &mut dyn Observer,
) -> Result<Run> {
    let Some(store) = store else {
        return run_sampler(config, evaluator, previous, observer);
    };
    let invocation = Invocation {
        kind,
        backend: evaluator.backend(),
        config: serde_json::to_value(config).expect("the configuration serialises"),
        id: None,
    };
    let mut storing = Storing {
        store: Writer::Here(store),
        claim,
        inner: observer,
        invocation,
    };
    // A new run's invocation is stored at once; a resumed run's with its first new population,
    // so that a resume which adds none leaves the store as it was.
    if kind == "start" {
        storing.begin_invocation()?;
    }
    let run = run_sampler(config, evaluator, previous, &mut storing);
    let invocation = storing.invocation.id;
    // Every population handed over is written before the run is reported (or its error).
    let store = storing.store.finish();
    let run = run?;
    let mut store = store?;
    if let Some(invocation) = invocation {
        let stop = serde_json::to_value(run.stop).expect("a stop reason serialises");
        // The backends that scored, as the workers reported them (a pool may mix them), and
        // the GPU scoring shape, which workers elsewhere name only once they have scored.
        let mut finished = config.clone();
        finished.take_shape_of(evaluator);
        store.finish_invocation(
            invocation,
            stop.as_str().unwrap_or_default(),
            evaluator.backend(),
            &serde_json::to_value(&finished).expect("the configuration serialises"),
        )?;
    }
    Ok(run)
}

/// One invocation of a run (`start` or `resume`) as the store records it.
struct Invocation {
    kind: &'static str,
    backend: &'static str,
    config: serde_json::Value,
    /// Its row in the store, once begun.
    id: Option<i64>,
}

/// The configured sampler from `previous` on.
fn run_sampler(
    config: &RunConfig,
    workers: &dyn Workers,
    previous: Vec<Population>,
    observer: &mut dyn Observer,
) -> Result<Run> {
    match &config.sampler {
        SamplerConfig::Rejection(c) => rejection::run_on(workers, c, previous, observer),
        SamplerConfig::Smc(c) => smc::run_on(workers, c, previous, observer),
    }
}

/// Writes every completed population to the store; the first one stored puts a staged run in
/// place. Once the run is in place, populations are written by a thread of their own while
/// the sampler draws the next one (at N = 10⁶ the writes are seconds: on a GPU, longer than
/// the scoring), one at a time and in order; a failed write ends the run with its error at
/// the next population or at the end.
struct Storing<'a> {
    store: Writer,
    claim: Option<&'a mut Claim>,
    inner: &'a mut dyn Observer,
    invocation: Invocation,
}

impl Storing<'_> {
    /// Records the invocation in the store (once; the store is still on this thread then).
    fn begin_invocation(&mut self) -> Result<()> {
        if self.invocation.id.is_some() {
            return Ok(());
        }
        let Writer::Here(store) = &mut self.store else {
            return Err(Error::Incomplete(
                "the invocation is recorded before any population is written".into(),
            ));
        };
        let inv = &self.invocation;
        self.invocation.id = Some(store.begin_invocation(inv.kind, inv.backend, &inv.config)?);
        Ok(())
    }
}

/// The run store, written on this thread or by a thread of its own.
enum Writer {
    Here(RunStore),
    Thread {
        layout: StoreLayout,
        /// A rendezvous channel: a population is handed over when the thread has written the
        /// one before, so at most one population's copy waits (memory stays O(N)).
        queue: std::sync::mpsc::SyncSender<PendingPopulation>,
        thread: std::thread::JoinHandle<Result<RunStore>>,
    },
    /// The thread failed, and its error was returned.
    Failed,
}

impl Writer {
    /// Hands `population` to the writing thread, starting it the first time.
    fn hand_over(&mut self, population: &Population, previous: Option<&Population>) -> Result<()> {
        if let Writer::Here(store) = self {
            let layout = store.layout();
            let Writer::Here(mut store) = std::mem::replace(self, Writer::Failed) else {
                unreachable!("matched above")
            };
            let (queue, receive) = std::sync::mpsc::sync_channel::<PendingPopulation>(0);
            let thread = std::thread::Builder::new()
                .name("bitrock-store".into())
                .spawn(move || {
                    for pending in receive {
                        store.write_pending(pending)?;
                    }
                    Ok(store)
                })
                .map_err(|e| Error::Incomplete(format!("cannot start the store's writing thread: {e}")))?;
            *self = Writer::Thread { layout, queue, thread };
        }
        let Writer::Thread { layout, queue, .. } = self else {
            return Err(Error::Incomplete("the run store's writer failed before".into()));
        };
        if queue.send(layout.prepare(population, previous)).is_err() {
            // The thread stopped at a failed write: its error ends the run.
            return std::mem::replace(self, Writer::Failed).finish().map(|_| ());
        }
        Ok(())
    }

    /// The store once every population handed over is written, or the first write's error.
    fn finish(self) -> Result<RunStore> {
        match self {
            Writer::Here(store) => Ok(store),
            Writer::Thread { queue, thread, .. } => {
                drop(queue);
                match thread.join() {
                    Ok(result) => result,
                    Err(panic) => std::panic::resume_unwind(panic),
                }
            }
            Writer::Failed => Err(Error::Incomplete("the run store's writer failed before".into())),
        }
    }
}

impl Observer for Storing<'_> {
    fn progress(&mut self, progress: &Progress) {
        self.inner.progress(progress);
    }

    fn population_done(&mut self, population: &Population, previous: Option<&Population>) -> Result<()> {
        self.begin_invocation()?;
        match (&mut self.store, self.claim.as_deref_mut()) {
            // A staged run is put in place once its first population is stored: written here.
            (Writer::Here(store), Some(claim)) if claim.is_staged() => {
                store.append_population(population, previous)?;
                claim.put_in_place()?;
                // SQLite names its journal after the path it opened: reopen at the new place.
                self.store = Writer::Here(RunStore::open(&claim.dir)?);
            }
            (store, _) => store.hand_over(population, previous)?,
        }
        self.inner.population_done(population, previous)
    }

    /// The store holds every population's particles.
    fn keeps_particles(&self) -> bool {
        true
    }

    fn note(&mut self, line: String) {
        self.inner.note(line);
    }

    fn interrupted(&mut self) -> bool {
        self.inner.interrupted()
    }
}
