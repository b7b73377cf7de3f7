//! The tempered samplers' settings and where they start (the box, a reference, or both).

use super::*;

/// Fewest particles an island accepts: fewer give no usable effective sample size.
pub const MIN_ISLAND_PARTICLES: usize = 20;

/// Memory of one particle of an island, bytes: its f32 parameters, log-likelihood and weight,
/// its proposal and the candidate scored for it, and its share of the posterior returned.
pub const BYTES_PER_PARTICLE: f64 = 192.0;

/// The tempered samplers' settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EvidenceConfig {
    /// Particles of each island.
    pub particles: usize,
    /// Independent samplers per law and start; their spread is the Monte-Carlo error (at
    /// least 2).
    pub islands: usize,
    /// Seed of every stream.
    pub seed: u64,
    /// Share of the effective sample size each tempering step keeps, in (0, 1).
    pub ess_share: f64,
    /// Most Metropolis sweeps after one tempering step.
    pub max_sweeps: usize,
    /// Most tempering steps of one island: a sampler that needs more is refused, not
    /// reported.
    pub max_stages: usize,
    /// How the residuals are modelled.
    #[serde(default)]
    pub noise: NoiseModel,
    /// Particles of each island of these laws instead of `particles`: fewer where a law is
    /// known to be worth less (a watch's improbable laws), its ln Z then less precise (its
    /// error says by how much).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub law_particles: Vec<(Law, usize)>,
    /// Where each law's samplers start ([`Start::Both`] by default); a stored job that names
    /// none ran from the box, and reads so.
    #[serde(default)]
    pub start: Start,
    /// Most times a law's islands of one start are run again, each time with twice the
    /// particles, while their ln Z spread by more than [`REFINE_ABOVE_NATS`]: the budget
    /// spent on a posterior the first islands did not follow alike. A stored job that names
    /// none refined nothing, and reads so.
    #[serde(default)]
    pub refine_rounds: usize,
}

/// Islands of one law and start whose ln Z spread by more than this many nats are run again
/// with twice the particles (up to [`EvidenceConfig::refine_rounds`] times): a nat is where a
/// Bayes factor's word starts to depend on which island was lucky.
pub const REFINE_ABOVE_NATS: f64 = 1.0;

/// Most refinement rounds: the last round's islands hold 2^this times the particles.
pub const MAX_REFINE_ROUNDS: usize = 6;

/// Where a law's samplers start their tempered path to the posterior. Either way ln Z is the
/// evidence under the law's prior box: the start changes the cost and the variance, not what
/// is estimated. From the fit, the caller, who has the fit, makes the [`Reference`]; from
/// both, each start runs [`EvidenceConfig::islands`] and [`kept_start`] says which estimate
/// the law keeps. The variants' texts are the command line's help.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "lowercase")]
pub enum Start {
    /// From the prior box: the whole tempered path. A narrow curved posterior splits into
    /// modes that an island's particles lose as β grows, unless each holds thousands (ln Z then
    /// errs low, its islands disagreeing).
    #[default]
    Box,
    /// From a Gaussian at the law's least-squares estimate (the fit's covariance, twice as
    /// wide), mixed with the box: a few tempering steps, far fewer candidates, the posterior's
    /// mode found by the fit's many starts. Where the posterior is a funnel far wider than the
    /// fit's covariance (m3 on a record of a law it nests: its bump's amplitude near zero, its
    /// centre and width free) the path never reaches the funnel, and ln Z errs low with an
    /// error that does not show it. A law whose fit has no covariance starts from its box.
    Fit,
    /// From both, as many islands from each (the box's cost plus the fit's): weighed by their
    /// inverse variances where they agree, the higher ln Z kept where they do not (a start
    /// errs low where it misses part of the posterior; [`kept_start`]).
    Both,
}

impl Start {
    /// The start's name, as the command line and Python name it.
    pub fn name(self) -> &'static str {
        match self {
            Start::Box => "box",
            Start::Fit => "fit",
            Start::Both => "both",
        }
    }

    /// Where the samplers start, in words.
    pub fn describe(self) -> &'static str {
        match self {
            Start::Box => "from each law's box",
            Start::Fit => "from each law's least-squares fit",
            Start::Both => "from each law's box and as many from its fit, the higher kept where they differ",
        }
    }
}

/// The estimates of ln Z from each start of a law's samplers ([`Start::Both`]) differ by more
/// than this many of their joint Monte-Carlo errors where one of them missed part of the
/// posterior.
pub const STARTS_AGREE_ERRORS: f64 = 3.0;

/// One start's estimate of a law's ln Z ([`Start::Both`]).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct StartEstimate {
    pub start: Start,
    /// ln Z from this start's islands alone, N·m, and its Monte-Carlo error.
    pub ln_z: f64,
    pub ln_z_error: f64,
    /// Largest difference between two of its islands' ln Z, nats.
    pub island_spread: f64,
    /// Whether the law's reported ln Z includes these islands.
    pub kept: bool,
}

/// One law's estimates from each start and which were kept, in words ("from the box
/// −20852.17 ± 14.67 (islands 60.0 nats apart), from the fit …: the fit's kept"); `None`
/// where the law started from one.
pub fn describe_starts(starts: &[StartEstimate]) -> Option<String> {
    if starts.is_empty() {
        return None;
    }
    let estimates: Vec<String> = starts
        .iter()
        .map(|e| {
            format!(
                "from the {} {:.2} ± {:.2} (islands {:.1} nats apart)",
                e.start.name(),
                e.ln_z,
                e.ln_z_error,
                e.island_spread
            )
        })
        .collect();
    let verdict = match starts.iter().filter(|e| e.kept).collect::<Vec<_>>()[..] {
        [kept] => format!("the {}'s kept", kept.start.name()),
        _ => "both kept, weighed by their inverse variances".to_string(),
    };
    Some(format!("{}: {verdict}", estimates.join(", ")))
}

/// Which start's islands a law's evidence keeps, given the box's and the fit's estimates:
/// `None` where both converged ([`ISLANDS_AGREE_NATS`]) and they agree within
/// [`STARTS_AGREE_ERRORS`] of their joint error (both kept: ln Z their inverse-variance mean,
/// the posterior every island's), else the higher. A start's mean of its islands' Z is
/// unbiased, so by Markov's inequality it over-estimates ln Z by t nats with probability at
/// most e^(−t), while a start that misses part of the posterior (a mode some of its islands
/// lost, a funnel its reference never reached) under-estimates it by nats, with an error that
/// need not show it: the higher estimate is the one to trust, and islands that disagree among
/// themselves are not weighed with a start that converged. The price: where both converged
/// and differ by chance (an error from a few islands is rough), the higher keeps its upward
/// scatter (measured in docs/evidence.md).
pub fn kept_start(from_box: &StartEstimate, from_fit: &StartEstimate) -> Option<Start> {
    let gap = from_fit.ln_z - from_box.ln_z;
    let joint = from_box.ln_z_error.hypot(from_fit.ln_z_error);
    let converged = |e: &StartEstimate| e.island_spread <= ISLANDS_AGREE_NATS;
    if converged(from_box) && converged(from_fit) && gap.abs() <= STARTS_AGREE_ERRORS * joint {
        None
    } else if gap > 0.0 {
        Some(Start::Fit)
    } else {
        Some(Start::Box)
    }
}

impl Default for EvidenceConfig {
    fn default() -> Self {
        Self {
            particles: 500,
            islands: 4,
            seed: 1,
            ess_share: 0.5,
            max_sweeps: 30,
            max_stages: 500,
            noise: NoiseModel::Iid,
            law_particles: Vec::new(),
            start: Start::Both,
            refine_rounds: 2,
        }
    }
}

impl EvidenceConfig {
    /// Particles of each island of `law`.
    pub fn particles_of(&self, law: Law) -> usize {
        self.law_particles
            .iter()
            .find(|(l, _)| *l == law)
            .map_or(self.particles, |(_, n)| *n)
    }

    /// The settings of refinement round `round` (0: the first islands): every particle count
    /// 2^round times.
    pub(super) fn of_round(&self, round: usize) -> Self {
        let times = 1usize << round;
        Self {
            particles: self.particles * times,
            law_particles: self.law_particles.iter().map(|&(l, n)| (l, n * times)).collect(),
            ..self.clone()
        }
    }

    /// Refuses, naming the setting, samplers whose particles for `laws` laws would not fit in
    /// this machine's memory (estimated at [`BYTES_PER_PARTICLE`] each, every island of every
    /// law and start held at once), before any work.
    pub fn check_memory(&self, laws: &[Law]) -> Result<()> {
        let starts = if self.start == Start::Both { 2.0 } else { 1.0 };
        let first: f64 =
            laws.iter().map(|&law| self.particles_of(law) as f64).sum::<f64>() * self.islands as f64 * starts;
        let field = if self.islands > self.particles {
            "islands"
        } else {
            "particles"
        };
        crate::limits::check_memory(
            field,
            first * BYTES_PER_PARTICLE,
            &format!(
                "{first:.3e} particles ({} per island, {} islands per law and start, {} laws)",
                self.particles,
                self.islands,
                laws.len()
            ),
        )?;
        // Refined islands replace those they refine, which are let go: at worst every law and
        // start in its last round at once.
        let times = 1u64 << self.refine_rounds.min(MAX_REFINE_ROUNDS);
        crate::limits::check_memory(
            "refine_rounds",
            first * times as f64 * BYTES_PER_PARTICLE,
            &format!(
                "{} refinement rounds ({} times the {first:.3e} particles at worst)",
                self.refine_rounds, times
            ),
        )
    }

    /// Refuses, naming the setting, values that give no estimate.
    pub fn validate(&self) -> Result<()> {
        for n in std::iter::once(self.particles).chain(self.law_particles.iter().map(|(_, n)| *n)) {
            if n < MIN_ISLAND_PARTICLES {
                return Err(Error::setting(
                    "particles",
                    format!("an island needs at least {MIN_ISLAND_PARTICLES} particles, got {n}"),
                ));
            }
        }
        if self.islands < 2 {
            return Err(Error::setting(
                "islands",
                format!(
                    "at least 2 independent islands per law are needed to estimate the Monte-Carlo error, got {}",
                    self.islands
                ),
            ));
        }
        if !(self.ess_share > 0.0 && self.ess_share < 1.0) {
            return Err(Error::setting(
                "ess_share",
                format!("must lie in (0, 1), got {}", self.ess_share),
            ));
        }
        if self.max_stages == 0 {
            return Err(Error::setting("max_stages", "must be at least 1"));
        }
        if self.max_sweeps == 0 {
            return Err(Error::setting("max_sweeps", "must be at least 1"));
        }
        if self.refine_rounds > MAX_REFINE_ROUNDS {
            return Err(Error::setting(
                "refine_rounds",
                format!(
                    "at most {MAX_REFINE_ROUNDS} (each round doubles the particles), got {}",
                    self.refine_rounds
                ),
            ));
        }
        Ok(())
    }
}
