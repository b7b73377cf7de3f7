//! An evidence's settings as a user gives them (the command's flags, Python's keyword
//! arguments, a watch's window), validated once into the [`Job`] they describe.

use super::{DEFAULT_PRIOR_SCALE, EvidencePrior, Job};
use crate::abc::evidence::{EvidenceConfig, NoiseModel, Start};
use crate::error::Result;
use crate::eval::Backend;
use crate::fit::FitOptions;
use crate::laws::Law;
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// Which boxes the evidence integrates over. The variants' texts are the command line's help.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "lowercase")]
pub enum Boxes {
    /// From each parameter's physical bound over the prior scale times the record's scale of
    /// its unit (largest torque; slowest and fastest speeds): no fit involved.
    #[default]
    Physical,
    /// The paper's φ̂(1 ± δ) around the least-squares estimates: the data used twice.
    Delta,
}

/// The residuals' noise model, or the data's choice among them. The variants' texts are the
/// command line's help.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "lowercase")]
pub enum Noise {
    /// Every model's evidence; the data choose (the largest p(y | model)).
    #[default]
    Auto,
    /// Independent Gaussian residuals.
    Iid,
    /// AR(1) Gaussian residuals (correlated from one sample to the next), φ integrated out.
    Ar1,
}

impl Noise {
    /// The model named, or `None` for the data's choice.
    pub fn model(self) -> Option<NoiseModel> {
        match self {
            Noise::Auto => None,
            Noise::Iid => Some(NoiseModel::Iid),
            Noise::Ar1 => Some(NoiseModel::Ar1),
        }
    }
}

/// An evidence's settings; [`Default`] is the command's defaults. The laws and the least
/// squares' options ([`FitOptions`]), which every kind of run shares, come beside them.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Settings {
    /// The prior boxes integrated over.
    pub boxes: Boxes,
    /// Width of the physical boxes, in record scales.
    pub prior_scale: f64,
    /// Half-width of the paper's boxes, with `boxes` delta.
    pub delta: f64,
    /// Prior file (TOML) with explicit bounds or law weights; it overrides the boxes where it
    /// speaks.
    pub prior: Option<PathBuf>,
    /// The residuals' noise model; `auto` computes the evidence under each and reports the
    /// one the data favour.
    pub noise: Noise,
    /// Where each law's samplers start their tempered path (the evidence is of the boxes
    /// either way).
    pub start_from: Start,
    /// Particles of each independent sampler (island).
    pub particles: usize,
    /// Independent samplers per law and start; their spread gives ln Z's Monte-Carlo error.
    pub islands: usize,
    /// Most tempering steps of one island.
    pub max_stages: usize,
    /// Share of the particles' effective sample size each tempering step keeps, in (0, 1).
    pub ess_share: f64,
    /// Most Metropolis sweeps after each tempering step.
    pub max_sweeps: usize,
    /// Most times a law's islands of one start are run again with twice the particles while
    /// they spread by more than a nat and the law's ln Z is uncertain by more than half a nat.
    pub refine_rounds: usize,
    /// Seed of the samplers' streams: the same seed gives the same result.
    pub seed: u64,
    /// Where ρ is computed.
    pub backend: Backend,
}

impl Default for Settings {
    fn default() -> Self {
        let sampler = EvidenceConfig::default();
        Self {
            boxes: Boxes::default(),
            prior_scale: DEFAULT_PRIOR_SCALE,
            delta: crate::run::abc::Config::default().delta,
            prior: None,
            noise: Noise::default(),
            start_from: sampler.start,
            particles: sampler.particles,
            islands: sampler.islands,
            max_stages: sampler.max_stages,
            ess_share: sampler.ess_share,
            max_sweeps: sampler.max_sweeps,
            refine_rounds: sampler.refine_rounds,
            seed: sampler.seed,
            backend: Backend::default(),
        }
    }
}

impl Settings {
    /// The job these settings describe for `laws` and the least squares' `fit`, validated, its
    /// prior file read: a setting it cannot run is refused here, by name, before any work.
    pub fn job(&self, laws: Vec<Law>, fit: FitOptions) -> Result<Job> {
        let mut job = Job {
            laws,
            fit,
            prior: match self.boxes {
                Boxes::Physical => EvidencePrior::Physical {
                    scale: self.prior_scale,
                },
                Boxes::Delta => EvidencePrior::Delta { delta: self.delta },
            },
            prior_file: self.prior.clone(),
            prior_text: None,
            backend: self.backend,
            sampler: EvidenceConfig {
                particles: self.particles,
                islands: self.islands,
                seed: self.seed,
                max_stages: self.max_stages,
                ess_share: self.ess_share,
                max_sweeps: self.max_sweeps,
                refine_rounds: self.refine_rounds,
                start: self.start_from,
                ..EvidenceConfig::default()
            },
            noise: self.noise.model(),
            // Given beside the settings ([`crate::run::stability::StringGiven::spec`]).
            string: None,
            warm: None,
            separations: true,
        };
        job.sampler.validate()?;
        job.keep_prior_text()?;
        Ok(job)
    }
}
