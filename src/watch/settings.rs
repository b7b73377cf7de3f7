//! What a watch does besides its source, and the defaults that follow from a record's rate.

use super::*;

/// What a watch does, besides its source.
#[derive(Clone, Debug)]
pub struct WatchSettings {
    pub laws: Vec<Law>,
    /// Columns, units and the minimum speed, as `fit` reads them (the split is not used:
    /// every sample of a window informs it).
    pub data: DataOptions,
    /// Every how many rows one is used; `None`: from the record's rate ([`default_thin`]).
    pub thin: Option<usize>,
    /// Window length and step, s; `None`: from the record's rate, thinned ([`default_windows`]).
    pub window_s: Option<f64>,
    pub step_s: Option<f64>,
    /// The evidence of each window, through the evidence's own settings (its gate, validated
    /// once when the watch starts): physical boxes `prior_scale` wide, its particles, islands,
    /// seed (window k's: seed + k) and noise model; its backend is the watch's.
    pub evidence: crate::run::evidence::Settings,
    /// λ in (0, 1]: the weight of the probabilities carried from one window length before
    /// (overlapping windows each bring in their step's share of it).
    pub forgetting: f64,
    /// No law's carried probability goes below this: none is ruled out for good.
    pub floor: f64,
    /// Log-likelihood loss (nats) over its running level that declares a change.
    pub change_nats: f64,
    /// P(unstable) the advice keeps below.
    pub risk: f64,
    /// What decides stability for the advice: the 1-DOF model (default) or a finite-element
    /// string's critical bit damping ([`crate::run::stability::criterion`]).
    pub criterion: Criterion,
    /// The string a stick-slipping window's way out is simulated on where the criterion is a
    /// finite-element string's critical damping: that string lumped ([`Chain::lumped_fe`]);
    /// `None` there: no way out is simulated. A 1-DOF criterion's own string otherwise.
    pub fe_chain: Option<Chain>,
    /// Reference weight on bit of the laws' parameters, N.
    pub w_ref_n: f64,
    pub backend: Backend,
    /// Fewest samples (after the speed filter) a window needs to inform.
    pub min_samples: usize,
    /// Least spread of bit speeds (5th to 95th percentile, rpm) a window needs to inform.
    pub min_speed_span_rpm: f64,
    /// The item codes of a source that sends WITS blocks.
    pub wits: wits::WitsItems,
    /// Each window's evidence samplers start from the last informative window's posterior
    /// (its kernel density, mixed with the box) instead of the boxes, each law with particles
    /// by its worth: the same evidence, fewer candidates while the rock stays the same. A
    /// window of surface channels: its sampler's population 0 drawn near that posterior and
    /// weighted back to the prior ([`crate::run::surface::Sampling::warm`]).
    pub warm_start: bool,
    /// The paper's ABC on each window instead of the evidence: this run's sampler, particles,
    /// δ and floor (its laws, seed and backend are the watch's; window k is seeded seed + k).
    /// Its law probabilities are ratios of the laws' prior volumes below ε, not evidence.
    pub abc: Option<crate::run::abc::Config>,
    /// Each window of a record of surface channels alone, through the surface run's own
    /// settings (its gate, validated once when the watch starts): particles, populations,
    /// pilot, check and prior. Its laws, string, backend and seed (window k's: the watch's
    /// seed + k) are the watch's.
    pub surface: crate::run::surface::Settings,
}

impl Default for WatchSettings {
    fn default() -> Self {
        Self {
            laws: Law::ALL.to_vec(),
            data: DataOptions::default(),
            thin: None,
            window_s: None,
            step_s: None,
            evidence: crate::run::evidence::Settings {
                particles: 300,
                islands: 2,
                noise: crate::run::evidence::Noise::Iid,
                // Each window from the window before; a cold one (the first, or after a
                // change of rock) from the boxes.
                start_from: Start::Box,
                // A window's latency matters more than half a nat of its ln Z, which later
                // windows weigh and forget: its islands are not run again, and their spread is
                // its error.
                refine_rounds: 0,
                ..Default::default()
            },
            forgetting: 0.5,
            floor: 0.01,
            change_nats: 30.0,
            risk: crate::run::advice::DEFAULT_RISK,
            criterion: Criterion::Lumped(Lumped::default()),
            fe_chain: None,
            w_ref_n: PAPER_W_REF_N,
            backend: Backend::Auto,
            min_samples: 100,
            min_speed_span_rpm: 5.0,
            wits: wits::WitsItems::default(),
            warm_start: true,
            abc: None,
            surface: super::default_surface_settings(),
        }
    }
}

/// Particles of a window's ABC population by default: its law probabilities to within
/// 0.008 (one binomial standard error, √(p(1 − p)/N) at p = ½).
pub const ABC_PARTICLES: usize = 4_000;

/// The run configuration of the paper's ABC on each window ([`WatchSettings::abc`]): `sampler`
/// with `particles` (default [`ABC_PARTICLES`]), prior half-width `delta` (default 0.4) and
/// floor `eps_min` (default: the paper's 0.014 where the window reaches it, else 1.1 × its
/// best least-squares ρ).
pub fn abc_config(
    sampler: crate::run::abc::Sampler,
    particles: Option<usize>,
    delta: Option<f64>,
    eps_min: Option<f64>,
) -> Result<crate::run::abc::Config> {
    crate::run::abc::Settings {
        sampler,
        particles: Some(particles.unwrap_or(ABC_PARTICLES)),
        delta,
        eps_min,
        ..crate::run::abc::Settings::default()
    }
    .config(None, crate::fit::FitOptions::default())
}

/// The rate a fast record is thinned to by default, Hz: the paper's, which resolves the
/// stick-slip cycles (seconds long) many times over.
pub const THINNED_RATE_HZ: f64 = 50.0;

/// Every how many rows a record sampled at `rate_hz` is used by default: a record faster
/// than twice [`THINNED_RATE_HZ`] is thinned to at most that rate (a 1 kHz logger's to 50 Hz:
/// the same windows at a twentieth of the cost); slower ones are used whole.
pub fn default_thin(rate_hz: f64) -> usize {
    let ratio = rate_hz / THINNED_RATE_HZ;
    // A rate measured from rounded time stamps is not exact: 1000.0000001 Hz is 1 kHz.
    if ratio.is_finite() && ratio >= 2.0 - 1e-6 {
        (ratio - 1e-6).ceil() as usize
    } else {
        1
    }
}

/// Window length and step for a record sampled at `rate_hz`: at least 500 samples and 10 s
/// per window, a step of a fifth of it, both to 0.1 s.
pub fn default_windows(rate_hz: f64) -> (f64, f64) {
    // To 0.1 s: a rate measured from rounded time stamps is not exact.
    let length = ((500.0 / rate_hz).max(10.0) * 10.0).round() / 10.0;
    (length, (length / 5.0 * 10.0).round().max(1.0) / 10.0)
}
