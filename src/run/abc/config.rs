//! A run's configuration: everything that defines a run besides its data, validated once,
//! where it is built ([`Settings::config`] for a user's settings, [`Config::validate`] for a
//! program's), and stored with the run so that a resume needs nothing else.

use crate::abc::rejection::{Mode, RejectionConfig};
use crate::abc::schedule::Schedule;
use crate::abc::shard::{Devices, Workers};
use crate::abc::smc::{LawProposal, Perturbation, Refill, SmcConfig, WeightsOn};
use crate::error::{Error, Result};
use crate::eval::Backend;
use crate::eval::gpu::Shape;
use crate::fit::FitOptions;
use crate::laws::Law;
use crate::limits;
use crate::prior::PriorRule;
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// Everything that defines a run besides its data: stored with the run, so that `--resume`
/// needs nothing else. [`Default`] is `bitrock abc`'s defaults (every law, bounded fits, δ =
/// 0.4, seed 1, the paper's rejection sampler with N = 25,000 down to ε = 0.014).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Config {
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
    /// Replace the sampler's eps_min by the floor the record can reach ([`crate::abc::floor::resolve`]:
    /// the paper's 0.014 where reachable), in [`super::start`], and store the result. `bitrock abc`
    /// sets it when `--eps-min` is not given; [`Default`] leaves eps_min as given.
    #[serde(default)]
    pub eps_min_from_record: bool,
    /// The drill string the run's maps and advice are drawn for, where the run was given one
    /// (`None`: the paper's 1-DOF string).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub string: Option<crate::run::stability::DrillStringSpec>,
}

impl Default for Config {
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
            string: None,
        }
    }
}

impl Config {
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

impl Config {
    /// Takes the GPU scoring shape `workers` score in, where they name one (workers elsewhere
    /// do only once they have scored).
    pub(super) fn take_shape_of(&mut self, workers: &dyn Workers) {
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
/// keyword arguments, a watch's window; the gate of [`crate::run::settings`]): every `None`
/// takes the library's default, and [`Settings::config`] turns them, with the laws and the
/// least squares' options every kind shares, into the [`Config`] the run stores, refusing
/// settings that the run would ignore.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Settings {
    /// The sampler: the paper's rejection or ABC-SMC.
    pub sampler: Sampler,
    /// Particles of each population.
    pub particles: Option<usize>,
    /// Half-width of the paper's prior boxes φ̂(1 ± δ).
    pub delta: Option<f64>,
    /// How the prior boxes are sized around the least-squares estimates.
    pub prior_rule: PriorRuleName,
    /// Standard errors each side with `prior_rule` stderr.
    pub prior_k: Option<f64>,
    /// Prior file (TOML) with explicit bounds or law weights.
    pub prior_file: Option<PathBuf>,
    /// The floor ε_min; `None` is the record's reachable floor (the paper's 0.014 where the
    /// record reaches it), or 0 under a schedule.
    pub eps_min: Option<f64>,
    /// A tolerance schedule for populations 1, 2, …, which then ends the run.
    pub epsilons: Option<Vec<f64>>,
    /// ε of population 0 (∞ when `None`).
    pub start_epsilon: Option<f64>,
    /// Most populations (including population 0).
    pub max_populations: Option<usize>,
    /// Most candidates scored over the whole run.
    pub max_draws: Option<u64>,
    /// Stop when the projected acceptance rate of the next population is below this.
    pub min_acceptance: Option<f64>,
    /// Wall-time budget of one invocation, seconds; the population in progress is dropped.
    pub max_seconds: Option<f64>,
    /// Rejection sampler only: nested or as published.
    pub mode: Option<Mode>,
    /// SMC only: probability that the model kernel keeps the ancestor's law.
    pub p_stay: Option<f64>,
    /// SMC only: the perturbation's covariance over the weighted covariance of the law's
    /// ancestors.
    pub kernel_scale: Option<f64>,
    /// SMC only: what the importance weights are computed on.
    pub smc_weights: Option<WeightsOn>,
    /// SMC only: how a population is filled.
    pub refill: Option<Refill>,
    /// SMC only: how a candidate's law is proposed.
    pub law_proposal: Option<LawProposal>,
    /// SMC only: how a candidate's parameters are perturbed.
    pub perturbation: Option<Perturbation>,
    /// Seed of every stream: the same seed gives the same run.
    pub seed: Option<u64>,
    /// Where ρ is computed.
    pub backend: Option<Backend>,
    /// Which of this machine's GPUs score.
    pub devices: Option<Devices>,
}

impl Settings {
    /// The run's configuration. A schedule is the user's: it ends the run where it ends (no
    /// floor below it unless `eps_min` is given) and has room for all its populations unless
    /// `max_populations` says less. Settings of the other sampler, and `prior_k` with the δ
    /// rule, are refused: the run would ignore them.
    pub fn config(&self, laws: Option<Vec<Law>>, fit: FitOptions) -> Result<Config> {
        self.check_sampler_settings()?;
        if self.prior_rule == PriorRuleName::Delta && self.prior_k.is_some() {
            return Err(Error::setting(
                "prior_k",
                "applies only to `prior_rule` stderr, and this run sizes its prior boxes by δ (the default rule); add `prior_rule` stderr or leave it out",
            ));
        }
        let defaults = Config::default();
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
        Ok(Config {
            laws: laws.unwrap_or(defaults.laws),
            fit,
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
            // Given beside the settings ([`crate::run::stability::StringGiven::spec`]).
            string: None,
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

    pub(super) fn apply(&mut self, more: &Continuation) {
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
