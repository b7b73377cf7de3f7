//! ABC-SMC with model selection (Toni et al. 2009; Toni & Stumpf 2010): each population after
//! the first perturbs the previous one instead of drawing from the prior, and importance
//! weights correct for the proposal. By default the particles of population t − 1 below ε_t
//! stay in population t and new proposals top it up to N (adaptive population Monte Carlo,
//! Lenormand et al. 2013; [`Refill::Survivors`]), and laws are proposed by what they are worth
//! ([`LawProposal::Worth`]); `refill` fresh and `law_proposal` kernel give the classic sampler.
//!
//! **Population 0** is the rejection sampler's population 0 at ε_0 (∞ unless a start is
//! given): the same stream, so the same particles, each of weight 1/N.
//!
//! **Survivors.** With [`Refill::Survivors`], population t begins with the particles of
//! population t − 1 whose ρ is below ε_t, in their order and with their weights: restricted to
//! ρ < ε_t, a weighted sample of the ABC posterior at ε_{t−1} is one of the posterior at ε_t
//! (ρ is a deterministic function of the parameters). The N − S new particles follow.
//!
//! **Ancestors** of a law: its particles in population t − 1 below ε_t where it has any and
//! survivors are kept, otherwise all its particles in population t − 1.
//!
//! **Proposal i of population t ≥ 1** is a pure function of (seed, t, i), generated once, on
//! the host, from Philox blocks 0-2 of counter (i, t) (see [`crate::rng`]); u = (w + ½)·2⁻³²
//! turns a word w into a uniform on (0, 1):
//! 1. a law m, by inverse CDF (word 0) of
//!    - with [`LawProposal::Worth`]: q(m) = (1 − f)·P_<(m) + f/A over the A laws proposed, f =
//!      [`WORTH_FLOOR`], P_<(m) the law's share of the weight of the particles of t − 1 below
//!      ε_t (of all of them where none is below). A law is proposed when it has particles in
//!      t − 1 and either has one below ε_t or its best least-squares ρ is below ε_t (with
//!      the parity margin of [`super::shard::kept`]); were no law left, every law with
//!      particles is proposed;
//!    - with [`LawProposal::Kernel`]: the previous law probabilities P(m′), then the model
//!      kernel K_M: stay at m′ with probability `p_stay` (default 0.7), otherwise jump
//!      uniformly to another *alive* law (words 1, 2); with one alive law, always stay;
//! 2. an ancestor φ_j among the law's ancestors, by inverse CDF of their weights (word 3);
//! 3. φ = φ_j + L_m z, z ~ N(0, I) by Box–Muller from words 4-11 in pairs (w_a, w_b):
//!    u_a = (w_a + ½)·2⁻³², u_b = w_b·2⁻³², z = √(−2 ln u_a) (cos 2πu_b, sin 2πu_b), f64;
//! 4. φ rounded to f32 (what both backends score, and the particle's parameters). A proposal
//!    outside the law's prior (its box, and its curve's limit where the box is cut,
//!    [`crate::prior::CurveLimit`]) is *counted as rejected*: it is a draw of its law, is not
//!    scored, and is not accepted. (Equivalent to redrawing: the accepted particles are the
//!    first N − S in index order that are inside the prior and below ε.) The weights' prior
//!    density of a cut box is one over the volume its limit keeps.
//!
//! **Kernel**: per law, L_m L_mᵀ = Σ_m = `kernel_scale` · C_m + (10⁻⁴ · box width)² I, where C_m
//! is the weighted covariance (divisor Σw, no bias correction) of the law's ancestors.
//! The default scale 2 is Beaumont et al. (2009)'s choice, twice the covariance; the tiny
//! diagonal keeps Σ_m positive definite for a law with one particle or a parameter all its
//! particles share. Parameters with a zero-width box are fixed and take no part.
//!
//! **Weights** of a new particle (m, φ): w ∝ π(m) π(φ|m) / q(m, φ), with the proposal density
//! q(m, φ) = q(m) · Σ_{j ∈ ancestors(m)} (w_j / Σ w_ancestors) N(φ; φ_j, Σ_m) (q(m) the law's
//! proposal probability of step 1, with the kernel Σ_m′ P(m′) K_M(m|m′)), normalised over the
//! new particles. The survivors' weights, normalised over the survivors, and the new ones are
//! two importance samples of the same posterior; they are mixed in proportion to their
//! effective sample sizes (the least-variance mix were they independent; a consistent
//! heuristic here, since the new particles descend from the survivors), so that Σw = 1 over
//! the population. A law's probability is its share of the weight. The O(N²)
//! sums Σ_j w_j exp(−|L⁻¹(φ − φ_j)|²/2) are [`Evaluator::kernel_sums`] on whitened
//! coordinates.
//!
//! **Where the weights are computed, and why on the host by default.** Weights steer the next
//! population (law probabilities, ancestor choice by inverse CDF, kernel covariance), so a
//! difference in their last bits could pick another ancestor and from there change every later
//! population. With [`WeightsOn::Host`] (the default) they are the f64 CPU twin on every
//! backend: proposals and weights are then bit-identical across backends, and populations
//! differ only where a ρ within [`crate::eval::PARITY_TOLERANCE`] of ε is decided otherwise (counted in
//! `near_threshold`; tests/it/gpu.rs checks this on a whole run). [`WeightsOn::Evaluator`] uses
//! the evaluator's kernel (the GPU's f32 kernel, relative difference below 1e-6 from the twin):
//! faster for large N, but a GPU run then no longer reproduces the CPU run's later populations.
//!
//! **Tolerances**: ε_{t+1} = the *unweighted* median of population t's ρ (the paper's rule and
//! the rejection sampler's; it does not depend on the weights, so not on where they were
//! computed), or the user's schedule. Stopping rules are the rejection sampler's, in the same
//! order: eps_min, schedule, stall, max populations, minimum projected acceptance (the fraction of
//! population t below ε_{t+1} times its acceptance rate), max draws and wall time (the
//! population in progress is dropped). With survivors, a population's acceptance rate (its
//! record's and each law's) is the top-up's: new particles per proposal; `accepted` counts all
//! the population's particles.
//!
//! Populations do not depend on batch size, thread count or backend (up to near-threshold
//! decisions), and continuing from completed populations gives exactly what an uninterrupted
//! run gives: population t depends only on the seed, data, configuration and population t − 1
//! (particles and weights).

use super::fill::{Filling, Spent};
use super::rejection::{self, Mode, RejectionConfig};
use super::schedule::{Schedule, next_epsilon};
use super::shard::{self, Found, Local, Proposal, Proposed, Round, Task, Workers};
use super::{Observer, Particle, Population, Run, Silent, StopReason};
use crate::error::{Error, Result};
use crate::eval::{Evaluator, KernelSums, PARITY_TOLERANCE, Problem};
use crate::numerics::compensated_sum;
use crate::prior::{Candidate, MAX_DIMS, Prior};
use crate::rng::{box_muller, candidate_counter, key_of_seed, open_unit, philox4x32_10};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::ops::ControlFlow;
use std::sync::Arc;

/// Where the importance weights' kernel sums are computed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "lowercase")]
pub enum WeightsOn {
    /// The f64 CPU twin, whatever the evaluator: runs are identical across backends.
    Host,
    /// The evaluator's kernel (the GPU's when it scores): faster for large N, but GPU runs
    /// then differ from CPU runs after the first population.
    Evaluator,
}

/// How population t + 1 is filled.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "lowercase")]
pub enum Refill {
    /// N fresh proposals from the whole previous population (Toni et al. 2009; Beaumont et
    /// al. 2009).
    Fresh,
    /// The previous population's particles below the new ε stay, with their weights, and new
    /// proposals from them top the population up to N (Lenormand et al. 2013).
    Survivors,
}

/// How the law of a proposal is chosen.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "lowercase")]
pub enum LawProposal {
    /// A law drawn by its previous probability, then kept with probability `p_stay` or moved
    /// uniformly to another live law (Toni & Stumpf 2010).
    Kernel,
    /// A law drawn in proportion to its probability among the particles below the new ε,
    /// with a floor of [`WORTH_FLOOR`] shared by the laws; none for a law that cannot reach
    /// the new ε.
    Worth,
}

/// The Gaussian perturbation of an ancestor.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "lowercase")]
pub enum Perturbation {
    /// One covariance per law: `kernel_scale` × the weighted covariance of its ancestors
    /// (Beaumont et al. 2009).
    Global,
    /// One covariance per ancestor, the locally optimal one of Filippi et al. (2013):
    /// Σ_j = Σ_k w_k (φ_k − φ_j)(φ_k − φ_j)ᵀ over the law's particles below the new ε, that is
    /// their covariance C plus (φ_j − μ)(φ_j − μ)ᵀ (over all the law's particles where none is
    /// below ε); narrow near the posterior's centre, wide at its edges, and wider still for an
    /// ancestor above ε (with [`Refill::Fresh`]). `kernel_scale` does not apply. A population
    /// after a thin one (effective sample size below [`super::MIN_ESS_SHARE`] of N) is drawn
    /// with the global kernels instead.
    Local,
}

/// The share of a population's proposals that [`LawProposal::Worth`] spreads evenly over
/// the laws it proposes, whatever their probabilities.
pub const WORTH_FLOOR: f64 = 0.05;

/// Configuration of an SMC run. Runs stored before `refill`, `law_proposal` and
/// `perturbation` existed read as `fresh`, `kernel` and `global`, which is how they were drawn.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(from = "Stored", into = "Stored")]
pub struct SmcConfig {
    /// N, tolerances, stopping rules, batch limit and wall time (population 0 is a rejection
    /// population).
    pub schedule: Schedule,
    /// Probability that the model kernel keeps the ancestor's law (`law_proposal` kernel).
    pub p_stay: f64,
    /// Perturbation covariance = kernel_scale × the weighted covariance of the law's ancestors.
    pub kernel_scale: f64,
    pub weights_on: WeightsOn,
    pub refill: Refill,
    pub law_proposal: LawProposal,
    pub perturbation: Perturbation,
}

/// [`SmcConfig`] as runs store it and workers receive it: the schedule under `base`, written
/// as the rejection sampler's settings (its `mode` unused), as bitrock has always stored it.
#[derive(Clone, Serialize, Deserialize)]
struct Stored {
    base: RejectionConfig,
    p_stay: f64,
    kernel_scale: f64,
    weights_on: WeightsOn,
    #[serde(default = "Refill::stored_default")]
    refill: Refill,
    #[serde(default = "LawProposal::stored_default")]
    law_proposal: LawProposal,
    #[serde(default = "Perturbation::stored_default")]
    perturbation: Perturbation,
}

impl From<Stored> for SmcConfig {
    fn from(s: Stored) -> Self {
        Self {
            schedule: s.base.schedule,
            p_stay: s.p_stay,
            kernel_scale: s.kernel_scale,
            weights_on: s.weights_on,
            refill: s.refill,
            law_proposal: s.law_proposal,
            perturbation: s.perturbation,
        }
    }
}

impl From<SmcConfig> for Stored {
    fn from(c: SmcConfig) -> Self {
        Self {
            base: RejectionConfig {
                schedule: c.schedule,
                mode: Mode::Nested,
            },
            p_stay: c.p_stay,
            kernel_scale: c.kernel_scale,
            weights_on: c.weights_on,
            refill: c.refill,
            law_proposal: c.law_proposal,
            perturbation: c.perturbation,
        }
    }
}

impl Perturbation {
    fn stored_default() -> Self {
        Perturbation::Global
    }
}

impl Refill {
    fn stored_default() -> Self {
        Refill::Fresh
    }
}

impl LawProposal {
    fn stored_default() -> Self {
        LawProposal::Kernel
    }
}

impl Default for SmcConfig {
    fn default() -> Self {
        Self {
            schedule: Schedule::default(),
            p_stay: 0.7,
            kernel_scale: 2.0,
            weights_on: WeightsOn::Host,
            refill: Refill::Survivors,
            law_proposal: LawProposal::Worth,
            perturbation: Perturbation::Local,
        }
    }
}

impl SmcConfig {
    /// Refuses configurations that cannot run, naming the setting, before any work.
    pub fn validate(&self) -> Result<()> {
        self.schedule.validate()?;
        if !(0.0..=1.0).contains(&self.p_stay) {
            return Err(Error::setting(
                "p_stay",
                format!("must lie in [0, 1], got {}", self.p_stay),
            ));
        }
        if !(self.kernel_scale.is_finite() && self.kernel_scale > 0.0) {
            return Err(Error::setting(
                "kernel_scale",
                format!("must be a positive number, got {}", self.kernel_scale),
            ));
        }
        Ok(())
    }
}

/// An upper bound on the share of population 1's proposals of a law with `dims` parameters
/// that land inside the prior box, when population 0 is the prior itself (no start ε): per
/// parameter, a uniform on a box of width w perturbed by a Gaussian of standard deviation
/// √S·w/√12 stays inside with probability ≤ w/(s√(2π)) = √(6/(πS)).
pub fn population_one_in_box_bound(kernel_scale: f64, dims: usize) -> f64 {
    (6.0 / (std::f64::consts::PI * kernel_scale))
        .sqrt()
        .min(1.0)
        .powi(dims as i32)
}

impl SmcConfig {
    /// Refuses a kernel scale that makes acceptance impossible: when even the law with the
    /// fewest parameters (`fewest_params`) would land fewer proposals inside its prior box than
    /// `--min-acceptance` stops at, or than the draw budget needs for N particles.
    pub fn check_kernel_reach(&self, fewest_params: usize) -> Result<()> {
        if self.schedule.start_epsilon.is_some() {
            return Ok(()); // population 0 is narrower than the prior: the bound does not apply
        }
        let share = population_one_in_box_bound(self.kernel_scale, fewest_params);
        let budget = self.schedule.particles as f64 / self.schedule.max_draws as f64;
        let needed = self.schedule.min_acceptance.max(budget);
        if share < needed {
            return Err(Error::setting(
                "kernel_scale",
                format!(
                    "{} makes the perturbation √{0}× as wide as the posterior: at most {share:.1e} of population 1's proposals of a {fewest_params}-parameter law land inside its prior box, below the {needed:.1e} the run needs (`min_acceptance`, or `particles`/`max_draws`); use a scale near 2",
                    self.kernel_scale
                ),
            ));
        }
        Ok(())
    }
}

/// Relative floor of the kernel's standard deviation: 10⁻⁴ of the prior box width.
const KERNEL_FLOOR: f64 = 1e-4;

/// The first index whose cumulative value exceeds `u` (inverse CDF; `cdf` ends at ≥ u).
#[inline]
pub(crate) fn inverse_cdf(cdf: &[f64], u: f64) -> usize {
    cdf.partition_point(|&c| c <= u).min(cdf.len() - 1)
}

/// The perturbation kernel of one alive law, built from the previous population.
#[derive(Clone, Debug)]
struct LawKernel {
    /// Parameters with a box of positive width (the others are fixed).
    free: Vec<usize>,
    /// Weighted mean of the free parameters (the centre of the whitened coordinates).
    mean: Vec<f64>,
    /// Lower-triangular Cholesky factor of Σ, row-major k × k (k = free.len()).
    chol: Vec<f64>,
    /// log det L = Σ log L_ii.
    log_det_l: f64,
    /// Indices of the law's ancestors in the previous population: its particles, or with
    /// [`Refill::Survivors`] those below the new ε where it has any.
    members: Vec<usize>,
    /// The ancestors' whitened coordinates, in the order of `members`: the kernel sums'
    /// sources, and each ancestor's e of the local perturbation.
    sources: Vec<[f64; MAX_DIMS]>,
    /// Cumulative weights of the ancestors, normalised to end at 1.
    cdf: Vec<f64>,
    /// The ancestors' share of the previous population's weight.
    member_weight: f64,
    /// log of 1 / prior box volume over the free parameters.
    log_prior_density: f64,
    /// [`Perturbation::Local`]: each ancestor's covariance is L (I + e eᵀ) Lᵀ, e its whitened
    /// coordinates (L and the mean are then those of the law's particles below ε).
    local: bool,
}

/// Weighted mean and covariance (divisor Σw) of `points` (k columns), compensated sums.
fn weighted_moments(points: &[Vec<f64>], weights: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let k = points.first().map_or(0, Vec::len);
    let total = compensated_sum(weights.iter().copied());
    let mean: Vec<f64> = (0..k)
        .map(|a| compensated_sum(points.iter().zip(weights).map(|(p, w)| w * p[a])) / total)
        .collect();
    let mut cov = vec![0.0; k * k];
    for a in 0..k {
        for b in 0..=a {
            let c = compensated_sum(
                points
                    .iter()
                    .zip(weights)
                    .map(|(p, w)| w * (p[a] - mean[a]) * (p[b] - mean[b])),
            ) / total;
            cov[a * k + b] = c;
            cov[b * k + a] = c;
        }
    }
    (mean, cov)
}

/// Lower-triangular L with L Lᵀ = `a` (row-major k × k); `None` unless positive definite.
fn cholesky(a: &[f64], k: usize) -> Option<Vec<f64>> {
    let mut l = vec![0.0; k * k];
    for i in 0..k {
        for j in 0..=i {
            let s = a[i * k + j] - (0..j).map(|m| l[i * k + m] * l[j * k + m]).sum::<f64>();
            if i == j {
                if !(s > 0.0 && s.is_finite()) {
                    return None;
                }
                l[i * k + i] = s.sqrt();
            } else {
                l[i * k + j] = s / l[j * k + j];
            }
        }
    }
    Some(l)
}

impl LawKernel {
    /// The kernel of law `slot` with ancestors `members` (indices into `previous`): global
    /// with `centre` `None`, the covariance `scale` × the ancestors'; local with `centre` the
    /// particles whose mean and covariance centre every ancestor's (see [`Perturbation`]).
    fn new(
        prior: &Prior,
        slot: usize,
        previous: &[Particle],
        members: Vec<usize>,
        scale: f64,
        centre: Option<&[usize]>,
    ) -> Result<Self> {
        let bx = &prior.boxes[slot];
        let free: Vec<usize> = (0..bx.lower.len()).filter(|&j| bx.upper[j] > bx.lower[j]).collect();
        let k = free.len();
        let weights: Vec<f64> = members.iter().map(|&i| previous[i].weight).collect();
        let moments_of = |set: &[usize]| {
            let points: Vec<Vec<f64>> = set
                .iter()
                .map(|&i| free.iter().map(|&j| previous[i].params[j]).collect())
                .collect();
            let weights: Vec<f64> = set.iter().map(|&i| previous[i].weight).collect();
            weighted_moments(&points, &weights)
        };
        let (mean, cov) = moments_of(centre.unwrap_or(&members));
        let scale = if centre.is_some() { 1.0 } else { scale };
        let mut sigma: Vec<f64> = cov.iter().map(|c| scale * c).collect();
        for (a, &j) in free.iter().enumerate() {
            let floor = KERNEL_FLOOR * (f64::from(bx.upper[j]) - f64::from(bx.lower[j]));
            sigma[a * k + a] += floor * floor;
        }
        let chol = cholesky(&sigma, k).ok_or_else(|| {
            Error::Numerical(format!(
                "the SMC kernel covariance of {} is not positive definite",
                bx.law
            ))
        })?;
        let log_det_l = (0..k).map(|a| chol[a * k + a].ln()).sum();
        let member_weight = compensated_sum(weights.iter().copied());
        let cdf = normalised_cdf(&weights);
        // Uniform on the box, or on the part of it its curve's limit keeps.
        let log_prior_density = -free
            .iter()
            .map(|&j| (f64::from(bx.upper[j]) - f64::from(bx.lower[j])).ln())
            .sum::<f64>()
            - bx.curve.as_ref().map_or(0.0, |c| c.ln_share);
        let mut kernel = Self {
            free,
            mean,
            chol,
            log_det_l,
            members,
            sources: Vec::new(),
            cdf,
            member_weight,
            log_prior_density,
            local: centre.is_some(),
        };
        kernel.sources = kernel
            .members
            .iter()
            .map(|&i| kernel.whiten(&previous[i].params))
            .collect();
        Ok(kernel)
    }

    /// Whitened coordinates L⁻¹(φ − mean) of the free parameters of `params`, zero-padded.
    fn whiten(&self, params: &[f64]) -> [f64; MAX_DIMS] {
        let k = self.free.len();
        let mut y = [0.0; MAX_DIMS];
        for a in 0..k {
            let s = (params[self.free[a]] - self.mean[a]) - (0..a).map(|b| self.chol[a * k + b] * y[b]).sum::<f64>();
            y[a] = s / self.chol[a * k + a];
        }
        y
    }
}

/// Whether `population` is thin ([`super::is_thin`]).
fn thin(population: &[Particle]) -> bool {
    let weights: Vec<f64> = population.iter().map(|p| p.weight).collect();
    super::is_thin(super::effective_sample_size(&weights), population.len())
}

/// Everything a population's proposals depend on: one kernel per law it proposes.
pub(crate) struct Kernels {
    /// Per prior slot: the law's kernel, `None` for a law that gets no proposal.
    laws: Vec<Option<LawKernel>>,
    /// Slots of the laws proposed, ascending.
    alive: Vec<usize>,
    /// Cumulative law probabilities over `alive` (the previous population's with
    /// [`LawProposal::Kernel`], the proposal probabilities with [`LawProposal::Worth`]),
    /// normalised to end at 1.
    law_cdf: Vec<f64>,
    /// Per prior slot, the probability that a proposal is of that law.
    proposal_probability: Vec<f64>,
    law_proposal: LawProposal,
    p_stay: f64,
}

impl Kernels {
    /// The kernels of the population after `previous`, drawn at `epsilon`; `can_reach(law)`
    /// is false for a law whose best least-squares ρ shows it cannot score below `epsilon`.
    pub(crate) fn new(
        prior: &Prior,
        previous: &[Particle],
        config: &SmcConfig,
        epsilon: f64,
        can_reach: &dyn Fn(crate::laws::Law) -> bool,
    ) -> Result<Self> {
        let mut members = vec![Vec::new(); prior.boxes.len()];
        for (i, p) in previous.iter().enumerate() {
            members[prior.slot_of(p.law)].push(i);
        }
        // Each law's share of the previous population's weight.
        let probability: Vec<f64> = members
            .iter()
            .map(|m| compensated_sum(m.iter().map(|&i| previous[i].weight)))
            .collect();
        // The particles below ε, where they carry weight (all of a law's may have underflowed).
        let below: Vec<Vec<usize>> = members
            .iter()
            .map(|m| {
                let below: Vec<usize> = m.iter().copied().filter(|&i| previous[i].rho < epsilon).collect();
                let weight = compensated_sum(below.iter().map(|&i| previous[i].weight));
                if weight > 0.0 { below } else { Vec::new() }
            })
            .collect();
        // A law is proposed when it has particles and, with `worth`, when it can still reach ε.
        let proposed: Vec<bool> = (0..members.len())
            .map(|s| {
                !members[s].is_empty()
                    && (config.law_proposal == LawProposal::Kernel || !below[s].is_empty() || can_reach(prior.law(s)))
            })
            .collect();
        // Were no law left (a schedule's ε below every particle and every fit), all with
        // particles are proposed rather than none.
        let proposed: Vec<bool> = if proposed.iter().any(|&p| p) {
            proposed
        } else {
            members.iter().map(|m| !m.is_empty()).collect()
        };
        // The effective-sample-size guard: after a thin population the local kernels, whose
        // narrow covariances near the centre are what thins the weights, give way to the
        // global ones for one population.
        let local = config.perturbation == Perturbation::Local && !thin(previous);
        let laws: Vec<Option<LawKernel>> = members
            .iter()
            .zip(&below)
            .enumerate()
            .map(|(slot, (all, below))| {
                // The local kernel is centred on the particles below ε (on all where none is).
                let near = if below.is_empty() { all } else { below };
                let ancestors = match config.refill {
                    Refill::Survivors => near.clone(),
                    Refill::Fresh => all.clone(),
                };
                let centre = local.then_some(near.as_slice());
                proposed[slot]
                    .then(|| LawKernel::new(prior, slot, previous, ancestors, config.kernel_scale, centre))
                    .transpose()
            })
            .collect::<Result<_>>()?;
        let alive: Vec<usize> = (0..laws.len()).filter(|&s| laws[s].is_some()).collect();
        let (law_weights, proposal_probability) =
            law_weights(config, &alive, laws.len(), &probability, &below, previous);
        let law_cdf = normalised_cdf(&law_weights);
        Ok(Self {
            laws,
            alive,
            law_cdf,
            proposal_probability,
            law_proposal: config.law_proposal,
            p_stay: config.p_stay,
        })
    }

    /// The probability that a proposal is of law `slot` (with [`LawProposal::Kernel`],
    /// Σ_m′ P(m′) K_M(m | m′)).
    fn law_proposal_probability(&self, slot: usize) -> f64 {
        self.proposal_probability[slot]
    }

    /// The law slot of a proposal from its first Philox block (steps 1 and 2 of the module
    /// documentation).
    fn slot_of_block(&self, b0: [u32; 4]) -> usize {
        let from = self.alive[inverse_cdf(&self.law_cdf, open_unit(b0[0]))];
        let a = self.alive.len();
        if self.law_proposal == LawProposal::Kernel && a > 1 && open_unit(b0[1]) >= self.p_stay {
            // Uniform among the other alive laws: the j-th of them, j = ⌊w·(a − 1) / 2³²⌋,
            // exact in integers (no list of them made per proposal).
            let j = ((u64::from(b0[2]) * (a as u64 - 1)) >> 32) as usize;
            let at = self
                .alive
                .iter()
                .position(|&s| s == from)
                .expect("the ancestor's law is alive");
            self.alive[if j < at { j } else { j + 1 }]
        } else {
            from
        }
    }

    /// Makes proposals `indexes` of `stream`, scores those inside the prior box with
    /// `evaluator`, and returns how many were scored, the (index, ρ) of those kept at
    /// `epsilon` ([`super::shard::kept`]) and every proposal's law slot: a
    /// [`super::shard::Task::Propose`].
    pub(crate) fn propose_and_score(
        &self,
        evaluator: &(impl Evaluator + ?Sized),
        previous: &[Particle],
        stream: u32,
        indexes: std::ops::Range<u64>,
        epsilon: f64,
    ) -> Result<Proposed> {
        let problem = evaluator.problem();
        let key = key_of_seed(problem.seed);
        let start = indexes.start;
        let proposals: Vec<(usize, Option<[f32; MAX_DIMS]>)> = (0..(indexes.end - start) as usize)
            .into_par_iter()
            .with_min_len(256)
            .map(|k| self.propose(&problem.prior, previous, key, stream, start + k as u64))
            .collect();
        let valid: Vec<(u64, Candidate)> = proposals
            .iter()
            .enumerate()
            .filter_map(|(k, &(slot, params))| params.map(|params| (start + k as u64, Candidate { slot, params })))
            .collect();
        let candidates: Vec<Candidate> = valid.iter().map(|&(_, c)| c).collect();
        let mut rho = vec![0.0; candidates.len()];
        evaluator.score_params(&candidates, &mut rho)?;
        let kept = valid
            .iter()
            .zip(&rho)
            .filter(|&(_, &r)| super::shard::kept(r, epsilon))
            .map(|(&(index, _), &r)| (index, r))
            .collect();
        let slots = proposals.iter().map(|&(slot, _)| slot as u8).collect();
        Ok(Proposed {
            scored: candidates.len() as u64,
            kept,
            slots,
        })
    }

    /// Proposal `index` of stream `stream`: its law slot, and its f32 parameters unless they
    /// fall outside the law's prior.
    fn propose(
        &self,
        prior: &Prior,
        previous: &[Particle],
        key: [u32; 2],
        stream: u32,
        index: u64,
    ) -> (usize, Option<[f32; MAX_DIMS]>) {
        let b0 = philox4x32_10(candidate_counter(stream, index, 0), key);
        let b1 = philox4x32_10(candidate_counter(stream, index, 1), key);
        let b2 = philox4x32_10(candidate_counter(stream, index, 2), key);
        let slot = self.slot_of_block(b0);
        let law = self.laws[slot].as_ref().expect("proposals go to alive laws");
        let at = inverse_cdf(&law.cdf, open_unit(b0[3]));
        let ancestor = &previous[law.members[at]];
        let words = [b1[0], b1[1], b1[2], b1[3], b2[0], b2[1], b2[2], b2[3]];
        let mut z = [0.0; MAX_DIMS];
        for pair in 0..MAX_DIMS / 2 {
            let [x, y] = box_muller(words[2 * pair], words[2 * pair + 1]);
            z[2 * pair] = x;
            z[2 * pair + 1] = y;
        }
        let k = law.free.len();
        if law.local {
            // The ancestor's own covariance L (I + e eᵀ) Lᵀ: z becomes (I + κ e eᵀ) z, the
            // symmetric square root of I + e eᵀ, κ = (√(1 + |e|²) − 1) / |e|².
            let e = &law.sources[at];
            let e2: f64 = e[..k].iter().map(|v| v * v).sum();
            if e2 > 0.0 {
                let kappa = ((1.0 + e2).sqrt() - 1.0) / e2;
                let ez: f64 = (0..k).map(|a| e[a] * z[a]).sum();
                for a in 0..k {
                    z[a] += kappa * e[a] * ez;
                }
            }
        }
        let bx = &prior.boxes[slot];
        let mut params = [0.0f32; MAX_DIMS];
        for (j, p) in params.iter_mut().enumerate().take(bx.lower.len()) {
            *p = ancestor.params[j] as f32;
        }
        for a in 0..k {
            let step: f64 = (0..=a).map(|b| law.chol[a * k + b] * z[b]).sum();
            let j = law.free[a];
            params[j] = (ancestor.params[j] + step) as f32;
        }
        let inside = bx.admits_f32(&params[..bx.lower.len()]);
        (slot, inside.then_some(params))
    }

    /// Log importance weights of `particles`, unnormalised (see the module documentation),
    /// with the kernel sums where `config.weights_on` says: a [`super::shard::Task::Weigh`].
    /// Each particle's weight depends on it and the previous population only, so the weights
    /// of any range of a population are those of the whole.
    pub(crate) fn log_weights(
        &self,
        evaluator: &(impl Evaluator + ?Sized),
        config: &SmcConfig,
        previous: &[Particle],
        particles: &[Particle],
    ) -> Result<Vec<f64>> {
        self.log_weights_with(
            &evaluator.problem().prior,
            previous,
            particles,
            &|sums, out| match config.weights_on {
                WeightsOn::Host => {
                    crate::eval::cpu::kernel_sums(sums, out);
                    Ok(())
                }
                WeightsOn::Evaluator => evaluator.kernel_sums(sums, out),
            },
        )
    }

    fn log_weights_with(
        &self,
        prior: &Prior,
        previous: &[Particle],
        particles: &[Particle],
        sums_on: &dyn Fn(&KernelSums, &mut [f64]) -> Result<()>,
    ) -> Result<Vec<f64>> {
        let mut log_w = vec![0.0; particles.len()];
        for (slot, law) in self.laws.iter().enumerate() {
            let Some(law) = law else { continue };
            let new: Vec<usize> = (0..particles.len())
                .filter(|&i| prior.slot_of(particles[i].law) == slot)
                .collect();
            if new.is_empty() {
                continue;
            }
            let targets: Vec<[f64; MAX_DIMS]> = new.iter().map(|&i| law.whiten(&particles[i].params)).collect();
            let mut weights: Vec<f64> = law
                .members
                .iter()
                .map(|&j| previous[j].weight / law.member_weight)
                .collect();
            // Local: source j's density carries det(I + e eᵀ)^(−½) = (1 + |e|²)^(−½).
            let rank_one: Option<Vec<f64>> = law.local.then(|| {
                law.sources
                    .iter()
                    .zip(&mut weights)
                    .map(|(e, w)| {
                        let stretch = 1.0 + e.iter().map(|v| v * v).sum::<f64>();
                        *w /= stretch.sqrt();
                        1.0 / stretch
                    })
                    .collect()
            });
            let mut sums = vec![0.0; new.len()];
            sums_on(
                &KernelSums {
                    targets: &targets,
                    sources: &law.sources,
                    weights: &weights,
                    rank_one: rank_one.as_deref(),
                },
                &mut sums,
            )?;
            let k = law.free.len() as f64;
            let log_model = self.law_proposal_probability(slot).ln();
            let log_prior = prior.weights[slot].ln() + law.log_prior_density;
            for (&i, &s) in new.iter().zip(&sums) {
                if !(s > 0.0 && s.is_finite()) {
                    return Err(Error::Numerical(format!(
                        "SMC kernel density {s} at particle {} of {}",
                        particles[i].index, particles[i].law
                    )));
                }
                let log_q = log_model + s.ln() - 0.5 * k * std::f64::consts::TAU.ln() - law.log_det_l;
                log_w[i] = log_prior - log_q;
            }
        }
        Ok(log_w)
    }
}

/// exp(log w − max), divided by its compensated sum: Σ w = 1 to rounding.
fn normalise_log_weights(log_w: &[f64]) -> Vec<f64> {
    let max = log_w.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let w: Vec<f64> = log_w.iter().map(|l| (l - max).exp()).collect();
    let total = compensated_sum(w.iter().copied());
    w.iter().map(|v| v / total).collect()
}

/// A population's survivors and the normalised weights of its new particles, combined: two
/// importance samples of the same target, each normalised on its own and mixed in proportion
/// to its effective sample size (the variance-minimising mix were they independent; the new
/// particles descend from the survivors, so it is a heuristic, consistent as both samples are).
/// Returns the survivors and the weights of all particles, survivors first; Σ w = 1.
fn combine_survivors(mut survivors: Vec<Particle>, new: Vec<f64>) -> (Vec<Particle>, Vec<f64>) {
    if survivors.is_empty() {
        return (survivors, new);
    }
    let total = compensated_sum(survivors.iter().map(|p| p.weight));
    // Survivors whose weights all underflowed to 0 carry no weight (and no ESS).
    let old: Vec<f64> = survivors
        .iter()
        .map(|p| if total > 0.0 { p.weight / total } else { 0.0 })
        .collect();
    let (ess_old, ess_new) = (
        super::effective_sample_size(&old),
        if new.is_empty() {
            0.0
        } else {
            super::effective_sample_size(&new)
        },
    );
    let share = ess_old / (ess_old + ess_new);
    let weights: Vec<f64> = old
        .iter()
        .map(|w| share * w)
        .chain(new.iter().map(|w| (1.0 - share) * w))
        .collect();
    for (p, w) in survivors.iter_mut().zip(&weights) {
        p.weight = *w;
    }
    (survivors, weights)
}

/// An SMC population's proposal distribution: the previous population and the kernel
/// settings, with the kernels built from them once.
pub struct Context {
    /// The tolerance of the population being drawn.
    epsilon: f64,
    particles: Vec<Particle>,
    config: SmcConfig,
    kernels: Kernels,
}

/// The name workers know SMC's proposals by ([`super::worker`]).
pub const SAMPLER: &str = "smc";

impl Context {
    /// The proposal distribution of the population after `particles` (with their weights),
    /// drawn at `epsilon`.
    pub fn new(problem: &Problem, particles: Vec<Particle>, config: SmcConfig, epsilon: f64) -> Result<Self> {
        // A law is out of reach only when its best least-squares ρ is above ε by more than the
        // margin a GPU's f32 ρ may differ by (as `kept` keeps candidates).
        let kernels = Kernels::new(&problem.prior, &particles, &config, epsilon, &|law| {
            problem.can_reach(law, epsilon * (1.0 + 2.0 * PARITY_TOLERANCE))
        })?;
        Ok(Self {
            epsilon,
            particles,
            config,
            kernels,
        })
    }

    /// The proposal [`Proposal::encode`] wrote, for `problem`.
    pub fn decode(problem: &Problem, bytes: &[u8]) -> Result<Self> {
        let payload: Payload = shard::wire::decode(bytes, "SMC proposal")?;
        Self::new(problem, payload.particles, payload.config, payload.epsilon)
    }
}

/// What a worker rebuilds a [`Context`] from: the previous population and the kernel settings.
#[derive(Serialize, Deserialize)]
struct Payload {
    particles: Vec<Particle>,
    config: SmcConfig,
    epsilon: f64,
}

/// [`Payload`] borrowed, for encoding without a copy.
#[derive(Serialize)]
struct PayloadRef<'a> {
    particles: &'a [Particle],
    config: &'a SmcConfig,
    epsilon: f64,
}

impl Proposal for Context {
    fn propose_and_score(
        &self,
        evaluator: &dyn Evaluator,
        stream: u32,
        indexes: std::ops::Range<u64>,
        epsilon: f64,
    ) -> Result<Proposed> {
        self.kernels
            .propose_and_score(evaluator, &self.particles, stream, indexes, epsilon)
    }

    fn log_weights(&self, evaluator: &dyn Evaluator, particles: &[Particle]) -> Result<Vec<f64>> {
        self.kernels
            .log_weights(evaluator, &self.config, &self.particles, particles)
    }

    fn encode(&self) -> (&'static str, Vec<u8>) {
        let payload = PayloadRef {
            particles: &self.particles,
            config: &self.config,
            epsilon: self.epsilon,
        };
        (SAMPLER, shard::wire::encode(&payload))
    }
}

/// Runs ABC-SMC with `evaluator` (which fixes prior, seed and data).
pub fn run(evaluator: &dyn Evaluator, config: &SmcConfig) -> Result<Run> {
    run_on(&Local(evaluator), config, Vec::new(), &mut Silent)
}

/// Goes through the proposals of a round in index order (`found` holds those inside the
/// prior box that the acceptance and near-threshold rules look at): accepts those below ε
/// until N, and counts every proposal up to the last one considered as a draw of its law. The
/// accepted proposals are made again here, in parallel, from their indices.
fn accept_found(problem: &Problem, fill: &mut Filling, context: &Context, found: &Found) {
    let prior = &problem.prior;
    let key = key_of_seed(problem.seed);
    let from = fill.position;
    let (accepted, consumed) = fill.pick_below_epsilon(&found.kept, found.end());
    let stream = fill.stream;
    let kernels = &context.kernels;
    let particles: Vec<Particle> = accepted
        .into_par_iter()
        .map(|(index, rho)| {
            let (slot, params) = kernels.propose(prior, &context.particles, key, stream, index);
            let law = prior.law(slot);
            let params = params.expect("a scored proposal lies inside the prior box");
            Particle {
                law,
                index,
                params: params[..prior.boxes[slot].lower.len()]
                    .iter()
                    .map(|&v| f64::from(v))
                    .collect(),
                rho,
                weight: 0.0,
            }
        })
        .collect();
    for p in &particles {
        fill.law_accepted[prior.slot_of(p.law)] += 1;
    }
    fill.particles.extend(particles);
    found.add_draws(from, consumed, &mut fill.law_draws);
    fill.position = consumed;
}

/// The normalised importance weights of a population's `particles`, computed in tasks by
/// `workers` against the previous population in `context`.
fn weigh(workers: &dyn Workers, population: usize, context: &Arc<Context>, particles: &[Particle]) -> Result<Vec<f64>> {
    let round = Round {
        population,
        context: Some(context.as_ref()),
        tasks: shard::split(0, particles.len() as u64, workers.parallelism())
            .into_iter()
            .map(|(first, len)| Task::Weigh {
                first: first as usize,
                particles: particles[first as usize..(first + len) as usize].to_vec(),
            })
            .collect(),
    };
    Ok(normalise_log_weights(&shard::run_log_weights(
        workers,
        &round,
        particles.len(),
    )?))
}

/// As [`run`], with every round's tasks run by `workers` (see [`super::shard`]), continuing
/// after the completed populations `previous` (empty for a fresh run) and reporting to
/// `observer`. Continuing gives exactly the populations an uninterrupted run with `config`
/// gives.
pub fn run_on(
    workers: &dyn Workers,
    config: &SmcConfig,
    previous: Vec<Population>,
    observer: &mut dyn Observer,
) -> Result<Run> {
    config.validate()?;
    let problem = workers.problem();
    let prior = &problem.prior;
    let schedule = &config.schedule;
    let n = schedule.particles;
    let d = problem.data_len() as u64;
    let mut populations = previous;
    let mut spent = Spent::after(&populations);
    if populations.is_empty() {
        let run = first_population(workers, schedule, observer)?;
        spent.scored += run.populations.iter().map(|p| p.record.candidates_scored).sum::<u64>();
        if matches!(run.stop, StopReason::MaxDraws | StopReason::WallTime) {
            return Ok(spent.finish(run.populations, run.stop, d));
        }
        populations = run.populations;
    }
    let stop = loop {
        let epsilon = match next_epsilon(&populations, schedule) {
            Ok(e) => e,
            Err(stop) => break stop,
        };
        let t = populations.len();
        let stream = t as u32;
        let previous = &mut populations[t - 1];
        // With survivors, the previous particles below ε stay (in their order, with their
        // weights) and new proposals top the population up to N.
        let survivors: Vec<Particle> = match config.refill {
            Refill::Fresh => Vec::new(),
            Refill::Survivors => previous.particles.iter().filter(|p| p.rho < epsilon).cloned().collect(),
        };
        let mut fill = Filling::new(t, stream, epsilon, n - survivors.len(), prior, d);
        let previous_rate = previous.record.acceptance_rate;
        // The context holds the previous population's particles while this one is drawn.
        let context = Arc::new(Context::new(
            problem,
            std::mem::take(&mut previous.particles),
            config.clone(),
            epsilon,
        )?);
        // The acceptance rate the first batch is sized by: the last SMC population's, or a
        // guess for the first one. Later batches use this population's own.
        let mut rate = if t >= 2 { previous_rate } else { 0.25 };
        let interrupted = fill.fill(schedule, &spent, observer, |fill, budget| {
            if budget == 0 {
                return Ok(ControlFlow::Break(StopReason::MaxDraws));
            }
            let missing = (fill.target - fill.particles.len()) as f64;
            let size = ((1.05 * missing / rate.max(1e-4)).ceil() as u64 + 16)
                .min(schedule.max_batch as u64)
                .min(budget);
            let tasks = shard::split_for(workers, fill.position, size);
            let round = Round {
                population: t,
                context: Some(context.as_ref()),
                tasks: proposals(stream, epsilon, tasks),
            };
            let found = shard::run_found(workers, &round, fill.position, size)?;
            fill.scored += found.scored;
            accept_found(problem, fill, &context, &found);
            rate = fill.particles.len().max(1) as f64 / fill.position as f64;
            Ok(ControlFlow::Continue(()))
        })?;
        spent.scored += fill.scored;
        let weights = match interrupted {
            None if fill.particles.is_empty() => Some(Vec::new()),
            None => Some(weigh(workers, t, &context, &fill.particles)?),
            Some(_) => None,
        };
        // The previous population gets its particles back (a run returns the last one's).
        populations[t - 1].particles = match Arc::try_unwrap(context) {
            Ok(context) => context.particles,
            Err(shared) => shared.particles.clone(),
        };
        let Some(weights) = weights else {
            break interrupted.expect("a population without weights was interrupted");
        };
        let population = population_of(fill, survivors, weights, config, problem, previous_rate);
        super::complete_population(&mut populations, population, observer)?;
    };
    Ok(spent.finish(populations, stop, d))
}

/// The cumulative sums of `weights` over their total, the last exactly 1: what a draw by
/// weight searches. `weights` is not empty (an alive law has a particle; a population, a law).
pub(crate) fn normalised_cdf(weights: &[f64]) -> Vec<f64> {
    let mut running = 0.0;
    let mut cdf: Vec<f64> = weights
        .iter()
        .map(|w| {
            running += w;
            running
        })
        .collect();
    let last = *cdf.last().expect("weights to draw by");
    for c in &mut cdf {
        *c /= last;
    }
    cdf
}

/// The weights the alive laws are drawn by, and each slot's probability that a proposal is
/// of its law (0 for the laws not proposed): the previous population's law probabilities
/// through the model kernel, or the laws' shares of the weight below ε with an even floor.
fn law_weights(
    config: &SmcConfig,
    alive: &[usize],
    slots: usize,
    probability: &[f64],
    below: &[Vec<usize>],
    previous: &[Particle],
) -> (Vec<f64>, Vec<f64>) {
    let mut proposal_probability = vec![0.0; slots];
    let law_weights: Vec<f64> = match config.law_proposal {
        LawProposal::Kernel => {
            let total: f64 = alive.iter().map(|&s| probability[s]).sum();
            let a = alive.len();
            let model_kernel = |to: usize, from: usize| match (a, to == from) {
                (1, _) => 1.0,
                (_, true) => config.p_stay,
                (_, false) => (1.0 - config.p_stay) / (a - 1) as f64,
            };
            for &to in alive {
                proposal_probability[to] = compensated_sum(
                    alive
                        .iter()
                        .map(|&from| probability[from] / total * model_kernel(to, from)),
                );
            }
            alive.iter().map(|&s| probability[s]).collect()
        }
        LawProposal::Worth => {
            // The laws' shares of the weight below ε (of all the weight where none is
            // below), mixed with an even floor.
            let below_weight: Vec<f64> = alive
                .iter()
                .map(|&s| compensated_sum(below[s].iter().map(|&i| previous[i].weight)))
                .collect();
            let shares = if below_weight.iter().any(|&w| w > 0.0) {
                below_weight
            } else {
                alive.iter().map(|&s| probability[s]).collect()
            };
            let total = compensated_sum(shares.iter().copied());
            let floor = WORTH_FLOOR / alive.len() as f64;
            for (&s, share) in alive.iter().zip(&shares) {
                proposal_probability[s] = (1.0 - WORTH_FLOOR) * share / total + floor;
            }
            alive.iter().map(|&s| proposal_probability[s]).collect()
        }
    };
    (law_weights, proposal_probability)
}

/// The proposal tasks of a round: each share of candidates (start, count) on the
/// population's `stream`, scored against `epsilon`.
fn proposals(stream: u32, epsilon: f64, shares: Vec<(u64, u64)>) -> Vec<Task> {
    shares
        .into_iter()
        .map(|(start, len)| Task::Propose {
            stream,
            start,
            len,
            epsilon,
        })
        .collect()
}

/// Population 0 of an SMC run: the rejection sampler's, from the prior at ε_0 (the schedule's
/// tolerances start with population 1).
fn first_population(workers: &dyn Workers, schedule: &Schedule, observer: &mut dyn Observer) -> Result<Run> {
    let first = RejectionConfig {
        schedule: Schedule {
            max_populations: 1,
            epsilons: None,
            ..schedule.clone()
        },
        mode: Mode::Nested,
    };
    rejection::run_on(workers, &first, Vec::new(), observer)
}

/// Population `fill` completed: the survivors kept before the new particles, every particle
/// weighed (`weights`: the survivors' then the new ones'), the laws' records, and, with
/// survivors, the acceptance rates of the top-up (new particles per proposal; a population
/// that needed none keeps `previous_rate`).
fn population_of(
    mut fill: Filling,
    survivors: Vec<Particle>,
    weights: Vec<f64>,
    config: &SmcConfig,
    problem: &Problem,
    previous_rate: f64,
) -> Population {
    let prior = &problem.prior;
    let n = config.schedule.particles;
    let (kept, weights) = combine_survivors(survivors, weights);
    for (p, w) in fill.particles.iter_mut().zip(&weights[kept.len()..]) {
        p.weight = *w;
    }
    let new = fill.particles.len();
    for p in &kept {
        fill.law_accepted[prior.slot_of(p.law)] += 1;
    }
    fill.particles.splice(0..0, kept);
    let per_law = fill.law_records(problem, |s| {
        let law = prior.law(s);
        let probability = compensated_sum(fill.particles.iter().filter(|p| p.law == law).map(|p| p.weight));
        (probability, fill.law_accepted[s] > 0)
    });
    let draws = fill.position;
    let mut population = fill.into_population(per_law, super::effective_sample_size(&weights));
    if config.refill == Refill::Survivors {
        // The acceptance rates are the top-up's: new particles per proposal. A population
        // that needed none (every particle survived a schedule's ε) keeps the last rate.
        population.record.acceptance_rate = if draws > 0 {
            new as f64 / draws as f64
        } else {
            previous_rate
        };
        let accepted_new = |law| population.particles[n - new..].iter().filter(|p| p.law == law).count();
        for r in &mut population.record.per_law {
            r.acceptance_rate = if r.draws > 0 {
                accepted_new(r.law) as f64 / r.draws as f64
            } else {
                0.0
            };
        }
    }
    population
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::laws::Law;
    use crate::prior::LawBox;

    /// The classic sampler: fresh refill, the model kernel, the global perturbation.
    fn classic() -> SmcConfig {
        SmcConfig {
            refill: Refill::Fresh,
            law_proposal: LawProposal::Kernel,
            ..SmcConfig::default()
        }
    }

    #[test]
    fn box_muller_gives_standard_normals() {
        // 2 × 200,000 normals from Philox words: mean 0 ± 5σ/√n, variance 1 ± 5·√(2/n),
        // fourth moment 3 ± 5·√(96/n).
        let n = 400_000.0;
        let (mut s1, mut s2, mut s4) = (0.0, 0.0, 0.0);
        for i in 0..200_000u64 {
            let w = philox4x32_10(candidate_counter(1, i, 1), key_of_seed(3));
            for z in box_muller(w[0], w[1]) {
                s1 += z;
                s2 += z * z;
                s4 += z * z * z * z;
            }
        }
        let (mean, var, m4) = (s1 / n, s2 / n, s4 / n);
        assert!(mean.abs() < 5.0 / f64::sqrt(n), "{mean}");
        assert!((var - 1.0).abs() < 5.0 * (2.0 / n).sqrt(), "{var}");
        assert!((m4 - 3.0).abs() < 5.0 * (96.0 / n).sqrt(), "{m4}");
        // The extreme words stay finite: u_a ∈ (0, 1) never reaches ln 0.
        assert!(box_muller(0, 0)[0].is_finite() && box_muller(u32::MAX, u32::MAX)[1].is_finite());
    }

    fn particle(law: Law, index: u64, params: &[f64], weight: f64) -> Particle {
        Particle {
            law,
            index,
            params: params.to_vec(),
            rho: 0.1,
            weight,
        }
    }

    /// m2 and m4 boxes; m4's last two parameters fixed (zero width).
    fn two_law_prior() -> Prior {
        m2_and_m4(
            [[0.0, 0.0, 0.0], [10.0, 10.0, 1.0]],
            [[0.0, -1.0, 0.5, 0.0], [4.0, 1.0, 0.5, 0.0]],
        )
    }

    /// Equally likely m2 and m4 on the boxes `[lower, upper]` given.
    fn m2_and_m4(m2: [[f32; 3]; 2], m4: [[f32; 4]; 2]) -> Prior {
        let law_box = |law, [lower, upper]: [&[f32]; 2]| LawBox::new(law, lower.to_vec(), upper.to_vec());
        Prior::new(
            vec![law_box(Law::M2, [&m2[0], &m2[1]]), law_box(Law::M4, [&m4[0], &m4[1]])],
            vec![1.0, 1.0],
        )
        .unwrap()
    }

    #[test]
    fn kernel_covariance_is_twice_the_weighted_covariance() {
        // Three m2 particles with weights 0.5, 0.25, 0.25 (within the law): mean of tsb =
        // 0.5·1 + 0.25·2 + 0.25·5 = 2.25, weighted variance 0.5·1.5625 + 0.25·0.0625 +
        // 0.25·7.5625 = 2.6875; covariance with tcb (2, 2, 4): mean 2.5, 0.5·(−1.25)(−0.5) +
        // 0.25·(−0.25)(−0.5) + 0.25·(2.75)(1.5) = 1.375.
        let prior = two_law_prior();
        let previous = vec![
            particle(Law::M2, 0, &[1.0, 2.0, 0.5], 0.4),
            particle(Law::M4, 1, &[1.0, 0.0, 0.5, 0.0], 0.2),
            particle(Law::M2, 2, &[2.0, 2.0, 0.5], 0.2),
            particle(Law::M2, 3, &[5.0, 4.0, 0.5], 0.2),
        ];
        let k = LawKernel::new(&prior, 0, &previous, vec![0, 2, 3], 2.0, None).unwrap();
        assert_eq!(k.free, vec![0, 1, 2]);
        assert!((k.member_weight - 0.8).abs() < 1e-15);
        assert!((k.mean[0] - 2.25).abs() < 1e-15 && (k.mean[1] - 2.5).abs() < 1e-15);
        // Σ = L Lᵀ: 2 × covariance plus the floor (10⁻⁴ · width)² on the diagonal.
        let l = &k.chol;
        let sigma = |a: usize, b: usize| (0..3).map(|m| l[a * 3 + m] * l[b * 3 + m]).sum::<f64>();
        assert!((sigma(0, 0) - (2.0 * 2.6875 + 1e-6)).abs() < 1e-12, "{}", sigma(0, 0));
        assert!((sigma(0, 1) - 2.0 * 1.375).abs() < 1e-12, "{}", sigma(0, 1));
        // g is the same in every particle: only the floor (10⁻⁴ · 1)² remains.
        assert!((sigma(2, 2) - 1e-8).abs() < 1e-20, "{}", sigma(2, 2));
        assert!((k.cdf[2] - 1.0).abs() < 1e-15 && (k.cdf[0] - 0.5).abs() < 1e-15);
        // m4 has one particle and two fixed parameters: a floor-only kernel on c0, c1.
        let k4 = LawKernel::new(&prior, 1, &previous, vec![1], 2.0, None).unwrap();
        assert_eq!(k4.free, vec![0, 1]);
        assert!((k4.chol[0] - 4e-4).abs() < 1e-18 && (k4.chol[3] - 2e-4).abs() < 1e-18);
    }

    #[test]
    fn weights_are_normalised_and_follow_prior_over_proposal() {
        let w = normalise_log_weights(&[-1000.0, -1000.0 + 2f64.ln(), -1000.0 + 5f64.ln()]);
        let total = compensated_sum(w.iter().copied());
        assert!((total - 1.0).abs() < 1e-15, "{total} {w:?}");
        // −1000 + ln 2 holds ln 2 to an ulp of 1000 (1.1e-13): the ratios are that exact.
        assert!(
            (w[0] - 1.0 / 8.0).abs() < 1e-12 && (w[2] - 5.0 / 8.0).abs() < 1e-12,
            "{w:?}"
        );
        // One law, one free parameter, previous particles at 1 and 3 with equal weight, kernel
        // σ² = 2·1 + (10⁻⁴·4)²: a new particle at x has q ∝ N(x; 1, σ²) + N(x; 3, σ²), so
        // its weight is ∝ 1 / q(x).
        let (_, _, _, w) = two_ancestors(&classic());
        assert!((w[0] - two_ancestors_expected()).abs() < 1e-12, "{w:?}");
        assert!((w[0] + w[1] - 1.0).abs() < 1e-15);
    }

    /// The host's kernel sums, as `WeightsOn::Host` computes them.
    fn host_sums(s: &KernelSums, out: &mut [f64]) -> Result<()> {
        crate::eval::cpu::kernel_sums(s, out);
        Ok(())
    }

    /// m4 with its first parameter free on [0, 4] and the others fixed at 0.
    fn one_free_parameter_prior() -> Prior {
        Prior::new(
            vec![LawBox::new(Law::M4, vec![0.0, 0.0, 0.0, 0.0], vec![4.0, 0.0, 0.0, 0.0])],
            vec![1.0],
        )
        .unwrap()
    }

    /// One law with one free parameter on [0, 4], ancestors at 1 and 3 of equal weight (all
    /// below ε), the kernels `config` makes of them, and the normalised weights of new
    /// particles at 2 and 0.5.
    fn two_ancestors(config: &SmcConfig) -> (Prior, Vec<Particle>, Kernels, Vec<f64>) {
        let prior = one_free_parameter_prior();
        let previous = vec![
            particle(Law::M4, 0, &[1.0, 0.0, 0.0, 0.0], 0.5),
            particle(Law::M4, 1, &[3.0, 0.0, 0.0, 0.0], 0.5),
        ];
        let kernels = Kernels::new(&prior, &previous, config, f64::INFINITY, &|_| true).unwrap();
        let new = [
            particle(Law::M4, 0, &[2.0, 0.0, 0.0, 0.0], 0.0),
            particle(Law::M4, 1, &[0.5, 0.0, 0.0, 0.0], 0.0),
        ];
        let w = normalise_log_weights(&kernels.log_weights_with(&prior, &previous, &new, &host_sums).unwrap());
        assert!((w[0] + w[1] - 1.0).abs() < 1e-15);
        (prior, previous, kernels, w)
    }

    /// The weight of the particle at 2 of [`two_ancestors`] when each ancestor's kernel has
    /// variance 2 + (10⁻⁴·4)²: q(x) ∝ N(x; 1, σ²) + N(x; 3, σ²), w ∝ 1 / q.
    fn two_ancestors_expected() -> f64 {
        let s2 = 2.0 + 1.6e-7;
        let q = |x: f64| (-(x - 1.0f64).powi(2) / (2.0 * s2)).exp() + (-(x - 3.0f64).powi(2) / (2.0 * s2)).exp();
        (1.0 / q(2.0)) / (1.0 / q(2.0) + 1.0 / q(0.5))
    }

    #[test]
    fn the_local_kernel_gives_each_ancestor_the_covariance_around_it() {
        // Ancestors at 1 and 3, all below ε: centre 2, C = 1 + (10⁻⁴·4)²; each ancestor's
        // variance is C + (φ_j − 2)² = 2 + 1.6e-7, the same as the global kernel's 2·C here.
        let config = SmcConfig {
            perturbation: Perturbation::Local,
            ..classic()
        };
        let (prior, previous, kernels, w) = two_ancestors(&config);
        assert!((w[0] - two_ancestors_expected()).abs() < 1e-12, "{w:?}");
        let s2 = 2.0 + 1.6e-7;
        // Proposals: a mixture of N(1, s2) and N(3, s2), variance 1 + s2 (inside the box or not).
        let key = key_of_seed(5);
        let n = 200_000u64;
        let mut steps = Vec::with_capacity(n as usize);
        for i in 0..n {
            let b0 = philox4x32_10(candidate_counter(1, i, 0), key);
            let ancestor = if open_unit(b0[3]) < 0.5 { 1.0 } else { 3.0 };
            let b1 = philox4x32_10(candidate_counter(1, i, 1), key);
            let z = box_muller(b1[0], b1[1])[0];
            // The step the kernel takes for this z: L (1 + κ e²) z, e = (φ_j − 2)/√C.
            let c: f64 = 1.0 + 1.6e-7;
            let e2 = (ancestor - 2.0f64).powi(2) / c;
            let kappa = ((1.0 + e2).sqrt() - 1.0) / e2;
            steps.push(ancestor + c.sqrt() * (1.0 + kappa * e2) * z);
            if i < 2_000 {
                let (_, params) = kernels.propose(&prior, &previous, key, 1, i);
                if let Some(p) = params {
                    assert_eq!(
                        p[0].to_bits(),
                        (*steps.last().unwrap() as f32).to_bits(),
                        "proposal {i}"
                    );
                }
            }
        }
        let mean = steps.iter().sum::<f64>() / n as f64;
        let var = steps.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n as f64;
        // Var of the sample variance of a two-normal mixture: below 5·(2·var²/n)^½.
        assert!((var - (1.0 + s2)).abs() < 5.0 * (2.0 * 9.0 / n as f64).sqrt(), "{var}");
    }

    #[test]
    fn after_a_thin_population_the_local_kernel_gives_way_to_the_global_one() {
        // Twenty m4 ancestors on [0, 4] at 0.1, 0.3, …, 3.9. With equal weights (ESS 20) the
        // kernels are local; with one weight 0.9 and the rest 0.1 / 19 each, ESS = 1 / (0.81 +
        // 19·(0.1/19)²) ≈ 1.23, below 0.1·20: the global kernel with its scale 2 takes over.
        let prior = one_free_parameter_prior();
        let population = |heavy: Option<f64>| -> Vec<Particle> {
            (0..20)
                .map(|i| {
                    let w = match heavy {
                        None => 1.0 / 20.0,
                        Some(h) if i == 7 => h,
                        Some(h) => (1.0 - h) / 19.0,
                    };
                    particle(Law::M4, i, &[0.1 + 0.2 * i as f64, 0.0, 0.0, 0.0], w)
                })
                .collect()
        };
        let local = SmcConfig {
            perturbation: Perturbation::Local,
            ..classic()
        };
        let kernel = |previous: &[Particle], config: &SmcConfig| {
            let kernels = Kernels::new(&prior, previous, config, f64::INFINITY, &|_| true).unwrap();
            let k = kernels.laws[0].as_ref().unwrap();
            (k.local, k.chol.clone())
        };
        let even = population(None);
        assert!(!thin(&even));
        assert!(kernel(&even, &local).0);
        let heavy = population(Some(0.9));
        assert!(thin(&heavy));
        let (is_local, chol) = kernel(&heavy, &local);
        assert!(!is_local);
        assert_eq!(chol, kernel(&heavy, &classic()).1);
        // Exactly at the share, ESS 2 of 20, the population is not thin: weights 1/2 on two
        // particles and 0 elsewhere.
        let mut two = population(None);
        for (i, p) in two.iter_mut().enumerate() {
            p.weight = if i < 2 { 0.5 } else { 0.0 };
        }
        assert!(!thin(&two));
    }

    /// m2 and m4 with one free parameter each on [0, 4] (the rest fixed).
    fn model_kernel_prior() -> Prior {
        m2_and_m4(
            [[0.0, 1.0, 1.0], [4.0, 1.0, 1.0]],
            [[0.0, 0.0, 0.0, 0.0], [4.0, 0.0, 0.0, 0.0]],
        )
    }

    /// On `prior` (of [`model_kernel_prior`]'s shape): a previous population with 90 % of its
    /// weight in m2, ancestors at 1 and 3 in each law, its kernels, and the normalised weights
    /// of an m2 and an m4 particle, each at 2.
    fn model_kernel_case(prior: &Prior) -> (Vec<Particle>, Kernels, Vec<f64>) {
        let previous = vec![
            particle(Law::M2, 0, &[1.0, 1.0, 1.0], 0.45),
            particle(Law::M2, 1, &[3.0, 1.0, 1.0], 0.45),
            particle(Law::M4, 2, &[1.0, 0.0, 0.0, 0.0], 0.05),
            particle(Law::M4, 3, &[3.0, 0.0, 0.0, 0.0], 0.05),
        ];
        let kernels = Kernels::new(prior, &previous, &classic(), f64::INFINITY, &|_| true).unwrap();
        let new = [
            particle(Law::M2, 0, &[2.0, 1.0, 1.0], 0.0),
            particle(Law::M4, 1, &[2.0, 0.0, 0.0, 0.0], 0.0),
        ];
        let w = normalise_log_weights(&kernels.log_weights_with(prior, &previous, &new, &host_sums).unwrap());
        (previous, kernels, w)
    }

    #[test]
    fn a_box_cut_to_a_curve_rejects_proposals_outside_it_and_weighs_by_what_it_keeps() {
        // The model kernel's setup below, with m4's box (c0 in [0, 4], the rest 0) cut to the
        // curves within 3: a constant torque c0, so the cut keeps c0 ≤ 3, three quarters of
        // the box (estimated by Monte Carlo). The density of m4's prior is then one over that
        // volume: the weight of an m4 particle grows by exp(−ln share) against the uncut
        // setup's, the m2 one's stays.
        let mut prior = model_kernel_prior();
        let m4 = &mut prior.boxes[1];
        let limit = crate::prior::CurveLimit::new(Law::M4, 3.0, 1.0, 1.0, (&m4.lower, &m4.upper)).unwrap();
        assert!(
            (limit.ln_share.exp() - 0.75).abs() < 4.0 * 0.75 * limit.ln_share_error,
            "{}",
            limit.ln_share
        );
        let ln_share = limit.ln_share;
        m4.curve = Some(limit);
        let (previous, kernels, w) = model_kernel_case(&prior);
        let expected = 0.66 / 0.34 * (-ln_share).exp();
        assert!((w[1] / w[0] - expected).abs() < 1e-12 * expected, "{w:?}");
        // Proposals of m4 land inside the cut or are rejected; both happen.
        let key = key_of_seed(11);
        let (mut inside, mut rejected) = (0, 0);
        for i in 0..2_000 {
            match kernels.propose(&prior, &previous, key, 1, i) {
                (1, Some(p)) => {
                    assert!((0.0..=3.0).contains(&p[0]), "{p:?}");
                    inside += 1;
                }
                (1, None) => rejected += 1,
                _ => {}
            }
        }
        assert!(inside > 100 && rejected > 20, "{inside} inside, {rejected} rejected");
    }

    #[test]
    fn the_model_kernel_term_enters_the_weights() {
        // Two laws with one free parameter each and the same kernel shape; the previous
        // population holds 90 % of the weight in m2. With p_stay = 0.7 a proposal is m2 with
        // probability 0.9·0.7 + 0.1·0.3 = 0.66, m4 with 0.34; with equal priors, identical
        // boxes and identical relative positions, the weights differ by 0.66 / 0.34 only
        // through that term and P(m) inside the within-law density.
        let (_, kernels, w) = model_kernel_case(&model_kernel_prior());
        assert!((kernels.law_proposal_probability(0) - 0.66).abs() < 1e-15);
        assert!((kernels.law_proposal_probability(1) - 0.34).abs() < 1e-15);
        assert!((w[1] / w[0] - 0.66 / 0.34).abs() < 1e-12, "{w:?}");
    }

    #[test]
    fn proposals_are_pure_stay_inside_alive_laws_and_follow_the_model_kernel() {
        let prior = two_law_prior();
        // m4 holds 30 % of the weight; no law dead.
        let previous = vec![
            particle(Law::M2, 0, &[5.0, 5.0, 0.5], 0.35),
            particle(Law::M2, 1, &[6.0, 4.0, 0.4], 0.35),
            particle(Law::M4, 2, &[2.0, 0.0, 0.5, 0.0], 0.3),
        ];
        let config = classic();
        let kernels = Kernels::new(&prior, &previous, &config, f64::INFINITY, &|_| true).unwrap();
        let key = key_of_seed(17);
        let n = 100_000;
        let mut m4 = 0usize;
        for i in 0..n {
            let (slot, params) = kernels.propose(&prior, &previous, key, 1, i);
            assert_eq!((slot, params), kernels.propose(&prior, &previous, key, 1, i));
            m4 += usize::from(slot == 1);
            if let (1, Some(p)) = (slot, params) {
                // Fixed parameters keep their value.
                assert_eq!((p[2].to_bits(), p[3].to_bits()), (0.5f32.to_bits(), 0.0f32.to_bits()));
            }
        }
        // P(m4) = 0.3·0.7 + 0.7·0.3 = 0.42; binomial σ = 156.
        assert!((m4 as f64 - 0.42 * n as f64).abs() < 5.0 * 156.0, "{m4}");
        // A dead law gets no proposal.
        let only_m2 = &previous[..2];
        let kernels = Kernels::new(&prior, only_m2, &config, f64::INFINITY, &|_| true).unwrap();
        assert_eq!(kernels.alive, vec![0]);
        assert!(kernels.laws[1].is_none());
        assert!((0..10_000).all(|i| kernels.propose(&prior, only_m2, key, 1, i).0 == 0));
        assert!((kernels.law_proposal_probability(0) - 1.0).abs() < 1e-15);
    }
}
