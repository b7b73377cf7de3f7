//! An ABC run from configuration to run directory: least-squares fits, the prior, the
//! evaluator, the sampler, and the run store that every completed population is written to.
//! [`start`] begins a run in a fresh directory; [`resume`] continues a killed or finished one
//! from its store and gives exactly the populations an uninterrupted run would.

use crate::abc::floor;
use crate::abc::rejection::{self, RejectionConfig};
use crate::abc::smc::{self, SmcConfig};
use crate::abc::{Observer, Population, Progress, Run};
use crate::data::FieldData;
use crate::error::{Error, Result};
use crate::eval::{AbcProblem, Backend, Evaluator};
use crate::fit::{self, FitOptions};
use crate::laws::Law;
use crate::prior::{Prior, PriorFile};
use crate::store::{RunSetup, RunStore, STORE_FILE, StoredRun};
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
    /// The prior file the boxes were read from (provenance; the prior itself is stored).
    pub prior_file: Option<PathBuf>,
    pub seed: u64,
    pub backend: Backend,
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
            prior_file: None,
            seed: 1,
            backend: Backend::Auto,
            sampler: SamplerConfig::Rejection(RejectionConfig::default()),
            eps_min_from_record: false,
        }
    }
}

impl RunConfig {
    /// The one gate of a run's settings: refuses, naming the flag, what cannot run (an empty
    /// law list, bad fit options, δ ≤ 0, sampler settings out of range), before any work.
    pub fn validate(&self) -> Result<()> {
        if self.laws.is_empty() {
            return Err(Error::arg("--laws", "give at least one law"));
        }
        self.fit.validate()?;
        if !(self.delta.is_finite() && self.delta > 0.0) {
            return Err(Error::arg(
                "--delta",
                format!("must be a positive number, got {}", self.delta),
            ));
        }
        self.sampler.validate()
    }
}

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
    /// Refuses settings that cannot run, naming the flag.
    pub fn validate(&self) -> Result<()> {
        match self {
            SamplerConfig::Rejection(c) => c.validate(),
            SamplerConfig::Smc(c) => c.validate(),
        }
    }

    /// The stopping rules and tolerances every sampler shares.
    pub fn base_mut(&mut self) -> &mut RejectionConfig {
        match self {
            SamplerConfig::Rejection(c) => c,
            SamplerConfig::Smc(c) => &mut c.base,
        }
    }

    fn apply(&mut self, more: &Continuation) {
        let c = self.base_mut();
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
}

/// A run after an invocation: its set-up, every population, and why it stopped.
pub struct Outcome {
    pub config: RunConfig,
    pub setup: RunSetup,
    pub run: Run,
    /// Backend that scored this invocation's candidates (`cpu`, `gpu`).
    pub backend: &'static str,
}

/// Refuses a run directory that would be overwritten without `force`, before any work.
pub fn check_new_run_dir(dir: &Path, force: bool) -> Result<()> {
    if dir.exists() {
        if !dir.is_dir() {
            return Err(Error::arg(
                "--out",
                format!("{} exists and is not a directory", dir.display()),
            ));
        }
        let non_empty = std::fs::read_dir(dir)
            .map_err(|source| Error::Read {
                path: dir.to_path_buf(),
                source,
            })?
            .next()
            .is_some();
        if non_empty && !force {
            return Err(Error::arg(
                "--out",
                format!("{} is not empty; pass --force to replace it", dir.display()),
            ));
        }
    }
    Ok(())
}

/// Fits, builds the prior and the evaluator, then samples. With a `dir`, creates it
/// (replacing it) with its store first, and every population is stored as it completes;
/// without one the run lives in memory only. `prior_file` is the parsed `config.prior_file`.
/// The directory is created only once everything that can be refused has been.
pub fn start(
    dir: Option<&Path>,
    data: FieldData,
    mut config: RunConfig,
    prior_file: Option<&PriorFile>,
    observer: &mut dyn Observer,
    note: &mut dyn FnMut(String),
) -> Result<Outcome> {
    config.validate()?;
    let fits = fit::fit_laws(&config.laws, &data.calibration, &data.validation, &config.fit)?;
    let base = config.sampler.base_mut();
    let floor = floor::resolve(&fits, (!config.eps_min_from_record).then_some(base.eps_min))?;
    base.eps_min = floor.eps_min;
    floor::check_start_epsilon(&fits, base.start_epsilon)?;
    if let Some(line) = &floor.note {
        note(line.clone());
    }
    let prior = Prior::from_fits(&fits, config.delta, prior_file, data.torque_unit.newton_metres())?;
    let problem =
        AbcProblem::new(prior.clone(), config.seed, &data.calibration, config.fit.w_ref_n).with_best_rho(&fits);
    let evaluator = crate::eval::evaluator(problem, config.backend, note)?;
    let setup = RunSetup {
        config: serde_json::to_value(&config).expect("the configuration serialises"),
        data,
        fits,
        prior,
    };
    let run = match dir {
        Some(dir) => {
            replace_dir(dir)?;
            let mut store = RunStore::create(dir, &setup)?;
            sample(
                Some(&mut store),
                "start",
                &config,
                evaluator.as_ref(),
                Vec::new(),
                observer,
            )?
        }
        None => sample(None, "start", &config, evaluator.as_ref(), Vec::new(), observer)?,
    };
    Ok(Outcome {
        config,
        setup,
        run,
        backend: evaluator.backend(),
    })
}

/// Creates `dir` empty, removing what was there.
fn replace_dir(dir: &Path) -> Result<()> {
    if dir.exists() {
        std::fs::remove_dir_all(dir).map_err(|source| Error::Write {
            path: dir.to_path_buf(),
            source,
        })?;
    }
    std::fs::create_dir_all(dir).map_err(|source| Error::Write {
        path: dir.to_path_buf(),
        source,
    })
}

/// Continues the run in `dir` after its last stored population with the stopping rules of
/// `more`; the populations are those an uninterrupted run with the same settings gives.
pub fn resume(
    dir: &Path,
    more: &Continuation,
    observer: &mut dyn Observer,
    note: &mut dyn FnMut(String),
) -> Result<Outcome> {
    let mut store = RunStore::open(dir)?;
    let StoredRun { setup, populations } = store.load_with_last_particles()?;
    let mut config: RunConfig = serde_json::from_value(setup.config.clone()).map_err(|e| Error::Store {
        path: dir.join(STORE_FILE),
        message: format!("the stored configuration is not one this bitrock reads: {e}"),
    })?;
    config.sampler.apply(more);
    config.backend = more.backend.unwrap_or(config.backend);
    config.validate()?;
    let problem = AbcProblem::new(
        setup.prior.clone(),
        config.seed,
        &setup.data.calibration,
        config.fit.w_ref_n,
    )
    .with_best_rho(&setup.fits);
    let evaluator = crate::eval::evaluator(problem, config.backend, note)?;
    note(format!(
        "continuing {} after population {} ({} stored)",
        dir.display(),
        populations.len().saturating_sub(1),
        populations.len()
    ));
    let run = sample(
        Some(&mut store),
        "resume",
        &config,
        evaluator.as_ref(),
        populations,
        observer,
    )?;
    let setup = RunSetup {
        config: serde_json::to_value(&config).expect("the configuration serialises"),
        ..setup
    };
    Ok(Outcome {
        config,
        setup,
        run,
        backend: evaluator.backend(),
    })
}

/// Runs the sampler after `previous`, writing each new population to `store` when there is
/// one.
fn sample(
    store: Option<&mut RunStore>,
    kind: &str,
    config: &RunConfig,
    evaluator: &dyn Evaluator,
    previous: Vec<Population>,
    observer: &mut dyn Observer,
) -> Result<Run> {
    let Some(store) = store else {
        return run_sampler(config, evaluator, previous, observer);
    };
    let json = serde_json::to_value(config).expect("the configuration serialises");
    let invocation = store.begin_invocation(kind, evaluator.backend(), &json)?;
    let run = run_sampler(
        config,
        evaluator,
        previous,
        &mut Storing {
            store: &mut *store,
            inner: observer,
        },
    )?;
    let stop = serde_json::to_value(run.stop).expect("a stop reason serialises");
    store.finish_invocation(invocation, stop.as_str().unwrap_or_default())?;
    Ok(run)
}

/// The configured sampler from `previous` on.
fn run_sampler(
    config: &RunConfig,
    evaluator: &dyn Evaluator,
    previous: Vec<Population>,
    observer: &mut dyn Observer,
) -> Result<Run> {
    match &config.sampler {
        SamplerConfig::Rejection(c) => rejection::run_observed(evaluator, c, previous, observer),
        SamplerConfig::Smc(c) => smc::run_observed(evaluator, c, previous, observer),
    }
}

/// Writes every completed population to the store before the caller's observer sees it.
struct Storing<'a> {
    store: &'a mut RunStore,
    inner: &'a mut dyn Observer,
}

impl Observer for Storing<'_> {
    fn progress(&mut self, progress: &Progress) {
        self.inner.progress(progress);
    }

    fn population_done(&mut self, population: &Population, previous: Option<&Population>) -> Result<()> {
        self.store.append_population(population, previous)?;
        self.inner.population_done(population, previous)
    }

    /// The store holds every population's particles.
    fn keeps_particles(&self) -> bool {
        true
    }
}
