//! Along the well: a growing record followed window by window ([`window`], by its own time
//! stamps), each window's law probabilities from the model evidence, carried from window to
//! window with a forgetting factor and a floor, a change of formation noticed, and the
//! rotary speed and weight on bit that avoid stick-slip now.
//!
//! Per window: the samples below the minimum speed are dropped (as `fit` drops them); a
//! window with too few samples, whose bit turned at one speed (no law can be told from
//! another there) or whose torques are mostly not positive, is reported as such and updates
//! nothing. Otherwise the evidence of each law on the window ([`crate::pipeline::evidence`],
//! physical boxes; warm-started from the window before: its posterior's kernel density as
//! the samplers' reference, its estimates as the fits' starts, particles by each law's worth,
//! and a window that declares a change computed again from the boxes; or, by flag, the
//! paper's ABC on the window, [`WatchSettings::abc`]), then
//!
//! - **law probabilities** P_t(m) ∝ P_{t−1}(m)^λ · Z_t(m) (λ the forgetting factor: the
//!   previous windows' evidence counts λ, λ², … times), no law below the floor;
//! - **change**: the fits of the latest window that does not overlap this one, applied here,
//!   against this window's own (the log-likelihood the old formation's laws lose here,
//!   (n/2)·ln(ρ_old/ρ_new), the best of each); a loss beyond the threshold over its running
//!   level declares a change, and the probabilities restart from this window's. Windows that
//!   overlap the change's window are no reference (they may hold both formations): the next
//!   change can be declared two window lengths later;
//! - **advice**: the probability of unstable steady rotation at the window's operating point
//!   (mean top-drive speed, or mean bit speed without that column; mean weight on bit) under
//!   the mixture posterior (the paper's 1-DOF string, or a finite-element string's critical
//!   bit damping), and the nearest top-drive speed at this
//!   weight on bit, and the nearest weight on bit at this speed, below the risk threshold.

pub mod bench;
mod figures;
pub mod report;
pub mod serve;
pub mod source;
pub mod store;
pub mod view;
pub mod window;
pub mod wits;

use crate::abc::Observer;
use crate::abc::evidence::Reference;
use crate::abc::evidence::{EvidenceConfig, NoiseModel, Start};
use crate::data::{BitSeen, DataOptions, FieldData, Row};
use crate::error::Result;
use crate::eval::Backend;
use crate::fit::FitOptions;
use crate::laws::{Law, PAPER_W_REF_N};
use crate::pipeline::advice::{Adviser, EscapeSettings};
use crate::pipeline::evidence::{EvidenceAnalysis, EvidenceJob, EvidencePrior, WarmStart};
use crate::pipeline::strings::OperatingPoint;
use crate::simulate::strings::Chain;
use crate::stability::lumped::Lumped;
use crate::stability::map::Criterion;
use crate::units::RAD_S_PER_RPM;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use window::{Pushed, Window, Windows};

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
    /// The evidence sampler of each window.
    pub evidence: EvidenceConfig,
    /// Width of the physical boxes, in record scales.
    pub prior_scale: f64,
    /// λ in (0, 1]: the weight of the probabilities carried from the windows before.
    pub forgetting: f64,
    /// No law's carried probability goes below this: none is ruled out for good.
    pub floor: f64,
    /// Log-likelihood loss (nats) over its running level that declares a change.
    pub change_nats: f64,
    /// P(unstable) the advice keeps below.
    pub risk: f64,
    /// What decides stability for the advice: the 1-DOF model (default) or a finite-element
    /// string's critical bit damping ([`crate::pipeline::stability::criterion`]).
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
    /// by its worth: the same evidence, fewer candidates while the rock stays the same.
    pub warm_start: bool,
    /// The paper's ABC on each window instead of the evidence: this run's sampler, particles,
    /// δ and floor (its laws, seed and backend are the watch's; window k is seeded seed + k).
    /// Its law probabilities are ratios of the laws' prior volumes below ε, not evidence.
    pub abc: Option<crate::run::Config>,
}

impl Default for WatchSettings {
    fn default() -> Self {
        Self {
            laws: Law::ALL.to_vec(),
            data: DataOptions::default(),
            thin: None,
            window_s: None,
            step_s: None,
            evidence: EvidenceConfig {
                particles: 300,
                islands: 2,
                noise: NoiseModel::Iid,
                // Each window from the window before; a cold one (the first, or after a
                // change of rock) from the boxes.
                start: Start::Box,
                ..EvidenceConfig::default()
            },
            prior_scale: crate::pipeline::evidence::DEFAULT_PRIOR_SCALE,
            forgetting: 0.5,
            floor: 0.01,
            change_nats: 30.0,
            risk: crate::pipeline::advice::DEFAULT_RISK,
            criterion: Criterion::Lumped(Lumped::default()),
            fe_chain: None,
            w_ref_n: PAPER_W_REF_N,
            backend: Backend::Auto,
            min_samples: 100,
            min_speed_span_rpm: 5.0,
            wits: wits::WitsItems::default(),
            warm_start: true,
            abc: None,
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
    sampler: crate::run::Sampler,
    particles: Option<usize>,
    delta: Option<f64>,
    eps_min: Option<f64>,
) -> Result<crate::run::Config> {
    crate::run::Settings {
        sampler,
        particles: Some(particles.unwrap_or(ABC_PARTICLES)),
        delta,
        eps_min,
        ..crate::run::Settings::default()
    }
    .config()
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

/// One law in a window's update.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LawUpdate {
    pub law: Law,
    /// The carried probability P_t(m).
    pub probability: f64,
    /// This window's alone, P(m | window).
    pub window_probability: f64,
    /// The law's ln Z on the window and its Monte-Carlo error; none by the paper's ABC.
    pub ln_z: Option<f64>,
    pub ln_z_error: Option<f64>,
    /// Posterior mean, MAP (the mode of a kernel density of the particles, as a run's
    /// summary finds it) and 1 %, 99 % quantiles of each parameter, in the record's torque
    /// unit.
    pub mean: Vec<f64>,
    #[serde(default)]
    pub map: Vec<f64>,
    pub q01: Vec<f64>,
    pub q99: Vec<f64>,
    /// Kish's effective sample size of the law's weighted posterior particles.
    #[serde(default)]
    pub ess: f64,
}

/// The advice of a window.
pub use crate::pipeline::advice::Advice;

/// What a watch says of one window: one JSON line.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Update {
    pub window: usize,
    pub start_s: f64,
    pub end_s: f64,
    /// Samples in the window, and those used (above the minimum speed).
    pub samples: usize,
    pub samples_used: usize,
    /// Why the window informs nothing, where it does not.
    pub uninformative: Option<String>,
    /// The most probable law (carried probabilities).
    pub most_probable: Option<Law>,
    pub laws: Vec<LawUpdate>,
    /// Whether this window starts a new formation, and the log-likelihood (nats) the fits of
    /// the latest window sharing no time with it lose on it, beyond their running level.
    pub change: bool,
    pub change_nats: Option<f64>,
    pub advice: Option<Advice>,
    pub candidates_scored: u64,
    /// The tolerance the window's ABC ended at (the paper's procedure); none for the evidence.
    #[serde(default)]
    pub epsilon: Option<f64>,
    /// Seconds from the window's last sample arriving to this update.
    pub latency_s: f64,
}

/// A window's least-squares estimates by law (SI).
type Fits = Vec<(Law, Vec<f64>)>;

/// A window's model selection, by either procedure.
struct Selection {
    /// The window's least-squares fits: what its change was judged by, and what later windows
    /// compare with.
    fits: Vec<crate::fit::LawFit>,
    /// Each law compared, in the watch's order.
    laws: Vec<Selected>,
    candidates: u64,
    /// The ABC's last tolerance; `None` for the evidence.
    epsilon: Option<f64>,
    /// The W_ref (N) of the posterior's torque parameters where they are for the torque scaled
    /// by WOB / W_ref; `None` for the torque as the laws give it.
    w_ref_n: Option<f64>,
}

impl Selection {
    fn of(&self, law: Law) -> Option<&Selected> {
        self.laws.iter().find(|l| l.law == law)
    }
}

/// One law of a window's selection.
struct Selected {
    law: Law,
    /// P(m | window).
    probability: f64,
    /// Its posterior particles (SI), weighted within the law.
    posterior: Vec<crate::abc::Particle>,
    /// ln Z and its Monte-Carlo error (the evidence's; the paper's ABC has none).
    ln_z: Option<(f64, f64)>,
}

/// What the fits of the window before say of this one.
struct Judged {
    /// Nats of log-likelihood the earlier fits lose here; `None` without an earlier window.
    loss: Option<f64>,
    /// The running level of that loss since the last change.
    level: Option<f64>,
    change: bool,
}

/// A window's run says its notes through the watch's observer, but not the tolerance floor
/// it chose: each window's ε is in its update.
struct WindowNotes<'a>(&'a mut dyn Observer);

impl Observer for WindowNotes<'_> {
    fn note(&mut self, line: String) {
        if !crate::abc::floor::is_floor_note(&line) {
            self.0.note(line);
        }
    }
}

/// The running losses a change is measured against: those of the last this many windows.
const LOSS_MEMORY: usize = 120;

/// What a watch carries from window to window: all a watch directory needs to go on after
/// its last stored window as if it had never stopped. Bounded: a few windows' fits, the last
/// 120 losses and one posterior.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Carried {
    /// The last window given (informative or not).
    pub window: Option<usize>,
    /// Carried law probabilities, in `settings.laws` order; `None` before the first
    /// informative window.
    probabilities: Option<Vec<f64>>,
    /// The fits (SI parameters by law) of the recent informative windows, by window index:
    /// a window is compared with the latest one it does not overlap.
    recent_fits: std::collections::VecDeque<(usize, Fits)>,
    /// The weight on bit (N) each of `recent_fits` holds at, by window index: a fit to the
    /// torque scaled by WOB / W_ref holds at W_ref, one to the torque as the law gives it at its
    /// window's mean WOB. Empty for records without a WOB column and in stores written without
    /// it: their fits are compared as the laws give the torque.
    #[serde(default)]
    recent_wob_n: std::collections::VecDeque<(usize, f64)>,
    /// The window that declared the last change: no window overlapping it is a reference.
    last_change: Option<usize>,
    /// The last informative window's posterior particles (the mixture, weighted by the
    /// carried probabilities).
    #[serde(with = "posterior_json")]
    posterior: Option<Vec<crate::abc::Particle>>,
    /// Whether that posterior's torque parameters are for the torque scaled by WOB / W_ref.
    posterior_scaled: bool,
    /// The losses of the windows since the last change (their running level).
    losses: std::collections::VecDeque<f64>,
}

/// Posterior particles in JSON: the evidence's carry no ρ (NaN), which JSON has no number for.
mod posterior_json {
    use crate::abc::Particle;
    use crate::laws::Law;
    use serde::{Deserialize, Deserializer, Serialize, Serializer};

    #[derive(Serialize, Deserialize)]
    struct Written {
        law: Law,
        index: u64,
        params: Vec<f64>,
        #[serde(with = "crate::numerics::json_f64")]
        rho: f64,
        weight: f64,
    }

    pub fn serialize<S: Serializer>(value: &Option<Vec<Particle>>, out: S) -> Result<S::Ok, S::Error> {
        value
            .as_ref()
            .map(|ps| {
                ps.iter()
                    .map(|p| Written {
                        law: p.law,
                        index: p.index,
                        params: p.params.clone(),
                        rho: p.rho,
                        weight: p.weight,
                    })
                    .collect::<Vec<_>>()
            })
            .serialize(out)
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(input: D) -> Result<Option<Vec<Particle>>, D::Error> {
        let written = Option::<Vec<Written>>::deserialize(input)?;
        Ok(written.map(|ws| {
            ws.into_iter()
                .map(|w| Particle {
                    law: w.law,
                    index: w.index,
                    params: w.params,
                    rho: w.rho,
                    weight: w.weight,
                })
                .collect()
        }))
    }
}

/// A watch in progress.
pub struct Watch {
    settings: WatchSettings,
    windows: Windows,
    source: PathBuf,
    carried: Carried,
    /// When the newest row arrived.
    last_arrival: Option<std::time::Instant>,
    /// The time stamp at which the record's clock was last said to have stopped.
    stopped_at_s: Option<f64>,
    /// The record's sample period, s: how far past its last row the record's end reaches.
    period_s: f64,
    /// The unit of the record's torques, in which parameters are reported.
    torque_unit: crate::units::TorqueUnit,
    /// The picture of the latest window given.
    view: Option<view::View>,
}

impl Watch {
    /// A watch of `settings` over a record named `source` sampled at about `rate_hz`, its
    /// torques in `torque_unit`; the thinning, window and step taken from the rate where not
    /// given.
    pub fn new(
        settings: WatchSettings,
        source: PathBuf,
        rate_hz: f64,
        torque_unit: crate::units::TorqueUnit,
    ) -> Result<Self> {
        let thin = settings.thin.unwrap_or_else(|| default_thin(rate_hz));
        if thin == 0 {
            return Err(crate::Error::setting("thin", "must be at least 1 (1 uses every row)"));
        }
        let (length, step) = default_windows(rate_hz / thin as f64);
        let length = settings.window_s.unwrap_or(length);
        let step = settings.step_s.unwrap_or(step);
        for (field, v) in [("window_s", length), ("step_s", step)] {
            if !(v.is_finite() && v > 0.0) {
                return Err(crate::Error::setting(
                    field,
                    format!("must be a positive number of seconds, got {v}"),
                ));
            }
        }
        if step > length {
            return Err(crate::Error::setting(
                "step_s",
                format!("{step} s exceeds the window ({length} s): samples between windows would be lost"),
            ));
        }
        for (field, v, lo, hi) in [
            ("forgetting", settings.forgetting, 0.0, 1.0),
            ("floor", settings.floor, 0.0, 1.0 / settings.laws.len().max(1) as f64),
            ("risk", settings.risk, 0.0, 1.0),
        ] {
            if !(v > lo && v <= hi) {
                return Err(crate::Error::setting(
                    field,
                    format!("must lie in ({lo}, {hi}], got {v}"),
                ));
            }
        }
        match &settings.abc {
            Some(config) => config.validate()?,
            None => settings.evidence.validate()?,
        }
        Ok(Self {
            windows: Windows::new(length, step).thinned(thin),
            settings,
            source,
            carried: Carried::default(),
            last_arrival: None,
            stopped_at_s: None,
            period_s: 1.0 / rate_hz,
            torque_unit,
            view: None,
        })
    }

    /// Window length and step, s.
    pub fn windows(&self) -> (f64, f64) {
        self.windows.shape()
    }

    /// Every how many of the record's rows one is used.
    pub fn thin(&self) -> usize {
        self.windows.thin()
    }

    /// The picture of the latest window given (its cloud, band and map).
    pub fn view(&self) -> Option<&view::View> {
        self.view.as_ref()
    }

    /// What the watch carries to its next window.
    pub fn carried(&self) -> &Carried {
        &self.carried
    }

    /// Goes on from `carried` (stored after its window): the windows up to that one are
    /// not given again, and their rows not kept.
    pub fn resume(&mut self, carried: Carried) {
        if let Some(k) = carried.window {
            self.windows.skip_through(k);
        }
        self.carried = carried;
    }

    /// Takes a row that arrived at `arrived`; gives the updates of the windows it completes.
    /// A row whose time runs backwards, or without a time, is said through `observer` and
    /// skipped.
    pub fn push(&mut self, row: Row, arrived: std::time::Instant, observer: &mut dyn Observer) -> Result<Vec<Update>> {
        let pushed = self.windows.push(row);
        self.taken(pushed, arrived, observer)
    }

    /// The updates of what the windows did with a row that arrived at `arrived`.
    fn taken(
        &mut self,
        pushed: Pushed,
        arrived: std::time::Instant,
        observer: &mut dyn Observer,
    ) -> Result<Vec<Update>> {
        match pushed {
            Pushed::Kept(done) => {
                // The latency of the windows this row completes counts from its arrival.
                self.last_arrival = Some(arrived);
                let mut updates = Vec::new();
                for window in done {
                    updates.push(self.update(window, observer)?);
                }
                Ok(updates)
            }
            Pushed::Backwards { by_s } => {
                observer.note(format!(
                    "warning: a row {by_s:.3} s before the one read last (time runs backwards): skipped"
                ));
                Ok(Vec::new())
            }
            Pushed::NoTime => Err(crate::Error::setting(
                "time_column",
                "a watch cuts its windows by the record's time stamps: the record needs a time column",
            )),
            Pushed::Held => Ok(Vec::new()),
            Pushed::Stopped { at_s } => {
                // Said once per stop: the first row past the bound.
                if self.stopped_at_s.map(f64::to_bits) != Some(at_s.to_bits()) {
                    self.stopped_at_s = Some(at_s);
                    observer.note(format!(
                        "warning: the time column stopped at {at_s} s ({} rows with that stamp): rows with it are skipped until it moves",
                        crate::watch::window::MAX_ROWS_AT_ONE_STAMP
                    ));
                }
                Ok(Vec::new())
            }
            Pushed::Glitch { at_s, ahead_s, then } => {
                observer.note(format!(
                    "warning: a row stamped {at_s} s, {ahead_s:.3} s after the row before it, is followed by rows from before it: a glitch of the time column, skipped"
                ));
                self.taken(*then, arrived, observer)
            }
        }
    }

    /// At the record's end: the updates of the window that ends with it.
    pub fn finish(&mut self, observer: &mut dyn Observer) -> Result<Vec<Update>> {
        let (done, dropped) = self.windows.finish(self.period_s);
        if let Some(at_s) = dropped {
            observer.note(format!(
                "warning: the last row, stamped {at_s} s, jumps forward by more than a window and no row follows to tell a gap from a glitch of the time column: skipped"
            ));
        }
        done.into_iter().map(|window| self.update(window, observer)).collect()
    }

    /// The update of one complete window.
    fn update(&mut self, window: Window, observer: &mut dyn Observer) -> Result<Update> {
        if let Some(last) = self.carried.window
            && window.index > last + 1
        {
            let (skipped_from, skipped_to) = (last + 1, window.index - 1);
            observer.note(format!(
                "warning: no rows in window{} {skipped_from}{} (the record has a gap): not given",
                if skipped_to > skipped_from { "s" } else { "" },
                if skipped_to > skipped_from {
                    format!("–{skipped_to}")
                } else {
                    String::new()
                },
            ));
        }
        let samples = window.rows.len();
        let mut update = Update {
            window: window.index,
            start_s: window.start_s,
            end_s: window.end_s,
            samples,
            samples_used: 0,
            uninformative: None,
            most_probable: None,
            laws: Vec::new(),
            change: false,
            change_nats: None,
            advice: None,
            candidates_scored: 0,
            epsilon: None,
            latency_s: 0.0,
        };
        let data = match self.window_data(&window) {
            Ok(data) => data,
            Err(why) => {
                update.uninformative = Some(why);
                return Ok(self.completed(update, &window));
            }
        };
        update.samples_used = data.calibration.len();
        if let Some(why) = self.cannot_inform(&data) {
            update.uninformative = Some(why);
            return Ok(self.completed(update, &window));
        }
        let selected = match &self.settings.abc {
            None => self.by_evidence(&window, &data, observer)?,
            Some(config) => self.by_abc(config, &window, &data, observer)?,
        };
        let (selection, judged) = match selected {
            Ok(selected) => selected,
            Err(why) => {
                update.uninformative = Some(why);
                return Ok(self.completed(update, &window));
            }
        };
        let Judged { loss, level, change } = judged;
        update.candidates_scored = selection.candidates;
        update.epsilon = selection.epsilon;
        update.change = change;
        update.change_nats = loss.map(|l| l - level.unwrap_or(0.0));
        let fits_now: Fits = selection.fits.iter().map(|f| (f.law, f.params_si.clone())).collect();
        let span = self.windows.span();
        if change {
            self.carried.losses.clear();
            self.carried.last_change = Some(window.index);
        } else if let Some(loss) = loss {
            if self.carried.losses.len() == LOSS_MEMORY {
                self.carried.losses.pop_front();
            }
            self.carried.losses.push_back(loss);
        }
        self.carried.recent_fits.push_back((window.index, fits_now));
        while self.carried.recent_fits.len() > span + 1 {
            self.carried.recent_fits.pop_front();
        }
        if let Some(wob_n) = selection.w_ref_n.or_else(|| data.calibration.mean_wob_n()) {
            self.carried.recent_wob_n.push_back((window.index, wob_n));
        }
        let oldest = self.carried.recent_fits.front().map_or(window.index, |(k, _)| *k);
        self.carried.recent_wob_n.retain(|(k, _)| *k >= oldest);

        // Carried law probabilities: P_t ∝ P_{t−1}^λ · P(m | window), floored.
        let window_p: Vec<f64> = self
            .settings
            .laws
            .iter()
            .map(|&law| selection.of(law).map_or(0.0, |l| l.probability))
            .collect();
        let carried = match (&self.carried.probabilities, change) {
            (Some(before), false) => {
                let joint: Vec<f64> = before
                    .iter()
                    .zip(&window_p)
                    .map(|(b, w)| b.powf(self.settings.forgetting) * w)
                    .collect();
                normalise_with_floor(&joint, self.settings.floor)
            }
            _ => normalise_with_floor(&window_p, self.settings.floor),
        };
        let unit = data.torque_unit;
        for (k, &law) in self.settings.laws.iter().enumerate() {
            let Some(selected) = selection.of(law) else { continue };
            update.laws.push(law_update(selected, carried[k], unit));
        }
        update.most_probable = self
            .settings
            .laws
            .iter()
            .zip(&carried)
            .max_by(|a, b| a.1.total_cmp(b.1))
            .map(|(&law, _)| law);
        // The mixture posterior under the carried probabilities: each law's particles weighed
        // by its share of the window's posterior, then by its carried probability over it.
        let posterior: Vec<crate::abc::Particle> = selection
            .laws
            .into_iter()
            .filter_map(|selected| {
                let k = self.settings.laws.iter().position(|&l| l == selected.law)?;
                let (p, share) = (selected.probability, carried[k]);
                (p > 0.0).then(|| {
                    selected.posterior.into_iter().map(move |mut particle| {
                        particle.weight *= p;
                        particle.weight *= share / p;
                        particle
                    })
                })
            })
            .flatten()
            .collect();
        self.carried.probabilities = Some(carried);
        self.carried.posterior = Some(posterior);
        self.carried.posterior_scaled = selection.w_ref_n.is_some();
        Ok(self.completed(update, &window))
    }

    /// The loss of an earlier window's fits here, against this window's own `fits`: the
    /// latest window that does not overlap this one, and none that overlaps the last change's
    /// window (which may hold both formations); a change where it exceeds its running level
    /// by the threshold.
    fn judge(&self, window: &Window, fits: &[crate::fit::LawFit], samples: &crate::data::Samples) -> Judged {
        let span = self.windows.span();
        let reference = self
            .carried
            .recent_fits
            .iter()
            .rev()
            .find(|(k, _)| k + span <= window.index)
            .filter(|(k, _)| self.carried.last_change.is_none_or(|c| *k >= c + span));
        let loss = reference.and_then(|(k, before)| {
            let holds_at_n = self.carried.recent_wob_n.iter().find(|(i, _)| i == k).map(|(_, w)| *w);
            loss_nats(before, holds_at_n, fits, samples)
        });
        let level = median(&self.carried.losses.iter().copied().collect::<Vec<_>>());
        let change = match (loss, level) {
            (Some(loss), Some(level)) => loss - level > self.settings.change_nats,
            (Some(loss), None) => loss > self.settings.change_nats,
            _ => false,
        };
        Judged { loss, level, change }
    }

    /// The window's law probabilities by the evidence, warm-started from the window before
    /// where there is one; computed again from the boxes where the window declares a change
    /// or a law's warm samplers missed its posterior. `Err`: why the window cannot inform.
    fn by_evidence(
        &self,
        window: &Window,
        data: &FieldData,
        observer: &mut dyn Observer,
    ) -> Result<std::result::Result<(Selection, Judged), String>> {
        let warm = self.warm_start();
        // From the window before's estimates, the fits need only the grid's best starts
        // beside them (which still find a minimum that moved away with a change of rock).
        let fit = match &warm {
            Some(warm) if !warm.fits.is_empty() => FitOptions {
                starts: WARM_FIT_STARTS,
                ..FitOptions::default()
            },
            _ => FitOptions::default(),
        };
        let job = EvidenceJob {
            laws: self.settings.laws.clone(),
            fit,
            prior: EvidencePrior::Physical {
                scale: self.settings.prior_scale,
            },
            prior_file: None,
            prior_text: None,
            backend: self.settings.backend,
            sampler: EvidenceConfig {
                seed: self.settings.evidence.seed.wrapping_add(window.index as u64),
                ..self.settings.evidence.clone()
            },
            noise: Some(self.settings.evidence.noise),
            warm,
            separations: false,
        };
        let mut analysis = match of_window(job.run(data, crate::run::Scoring::Here, observer))? {
            Ok(analysis) => analysis,
            Err(why) => return Ok(Err(why)),
        };
        let mut candidates = analysis.evidence.candidates_scored;
        let judged = self.judge(window, &analysis.fits, &data.calibration);
        // The fits the change was judged by are the ones the next windows compare with.
        let fits = analysis.fits.clone();
        if (judged.change || missed_mode(&analysis, data.calibration.len())) && job.warm.is_some() {
            // A change of rock: what the window before carried describes another formation
            // (its improbable laws kept few particles, its posterior lies elsewhere), so this
            // window's evidence is found again from the boxes, every law with all its
            // particles, as the paper would. So too where a law's warm samplers missed the
            // posterior that its fit shows (a mode the window before did not have).
            let cold = EvidenceJob {
                fit: FitOptions::default(),
                sampler: EvidenceConfig {
                    law_particles: Vec::new(),
                    ..job.sampler.clone()
                },
                warm: None,
                ..job.clone()
            };
            match of_window(cold.run(data, crate::run::Scoring::Here, observer))? {
                Ok(fresh) => {
                    candidates += fresh.evidence.candidates_scored;
                    analysis = fresh;
                }
                Err(why) => return Ok(Err(why)),
            }
        }
        let laws = analysis
            .evidence
            .laws
            .iter()
            .map(|e| Selected {
                law: e.law,
                probability: e.probability,
                posterior: e
                    .posterior
                    .iter()
                    .enumerate()
                    .map(|(i, (params, weight))| crate::abc::Particle {
                        law: e.law,
                        index: i as u64,
                        params: params.clone(),
                        rho: f64::NAN,
                        weight: *weight,
                    })
                    .collect(),
                ln_z: Some((e.ln_z, e.ln_z_error)),
            })
            .collect();
        let selection = Selection {
            fits,
            laws,
            candidates,
            epsilon: None,
            w_ref_n: analysis.fit.w_ref_n,
        };
        Ok(Ok((selection, judged)))
    }

    /// The window's law probabilities by the paper's ABC: `config`'s sampler on δ boxes around
    /// the window's fits (started from the window before's estimates beside the grid's best),
    /// down to the floor the window reaches; seeded by the watch's seed + the window's index.
    /// `Err`: why the window cannot inform.
    fn by_abc(
        &self,
        config: &crate::run::Config,
        window: &Window,
        data: &FieldData,
        observer: &mut dyn Observer,
    ) -> Result<std::result::Result<(Selection, Judged), String>> {
        let known: Fits = match self.settings.warm_start {
            true => self
                .carried
                .recent_fits
                .back()
                .map(|(_, f)| f.clone())
                .unwrap_or_default(),
            false => Vec::new(),
        };
        let fit = match known.is_empty() {
            true => config.fit,
            false => FitOptions {
                starts: WARM_FIT_STARTS,
                ..config.fit
            },
        };
        let fits = match of_window(crate::fit::fit_record_from(&self.settings.laws, data, &fit, &known))? {
            Ok(fits) => fits,
            Err(why) => return Ok(Err(why)),
        };
        let judged = self.judge(window, &fits, &data.calibration);
        let config = crate::run::Config {
            laws: self.settings.laws.clone(),
            seed: self.settings.evidence.seed.wrapping_add(window.index as u64),
            backend: self.settings.backend,
            ..config.clone()
        };
        let backend = config.backend;
        let w_ref_n = config.fit.w_ref_n;
        let mut evaluator =
            |problem, note: &mut dyn FnMut(String)| crate::eval::evaluator(problem, backend, Default::default(), note);
        let how = crate::run::Start {
            fits: Some(fits.clone()),
            scoring: crate::run::Scoring::Evaluator(&mut evaluator),
            ..Default::default()
        };
        let outcome = crate::run::start(data.clone(), config, how, &mut WindowNotes(observer));
        let outcome = match of_window(outcome)? {
            Ok(outcome) => outcome,
            Err(why) => return Ok(Err(why)),
        };
        let run = outcome.run;
        let candidates = run.populations.iter().map(|p| p.record.candidates_scored).sum();
        let Some(last) = run.populations.into_iter().last() else {
            return Ok(Err(format!(
                "no population of its ABC completed ({})",
                run.stop.describe()
            )));
        };
        let laws = self
            .settings
            .laws
            .iter()
            .map(|&law| {
                let probability = last.record.probability_of(law);
                Selected {
                    law,
                    probability,
                    // Weights relative to the law's own: its share of the population's.
                    posterior: last
                        .particles
                        .iter()
                        .filter(|p| p.law == law)
                        .map(|p| crate::abc::Particle {
                            weight: p.weight / probability,
                            ..p.clone()
                        })
                        .collect(),
                    ln_z: None,
                }
            })
            .collect();
        let selection = Selection {
            fits,
            laws,
            candidates,
            epsilon: last.record.epsilon,
            w_ref_n,
        };
        Ok(Ok((selection, judged)))
    }

    /// Each law's reference from the last informative window's posterior (a kernel density
    /// of its particles, mixed with its box): its evidence samplers start there instead of
    /// from the box, its fit from that window's estimate as well as from the grid, and its
    /// particles go by its carried probability. `None` with `warm_start` off or before the
    /// first informative window.
    fn warm_start(&self) -> Option<WarmStart> {
        let posterior = self.carried.posterior.as_ref().filter(|_| self.settings.warm_start)?;
        let references = self
            .settings
            .laws
            .iter()
            .filter_map(|&law| {
                let own: Vec<(&[f64], f64)> = posterior
                    .iter()
                    .filter(|p| p.law == law)
                    .map(|p| (p.params.as_slice(), p.weight))
                    .collect();
                Reference::from_posterior(law, &own)
            })
            .collect();
        Some(WarmStart {
            references,
            fits: self
                .carried
                .recent_fits
                .back()
                .map(|(_, fits)| fits.clone())
                .unwrap_or_default(),
            scaled: self.carried.posterior_scaled,
            worth: self
                .settings
                .laws
                .iter()
                .copied()
                .zip(self.carried.probabilities.iter().flatten().copied())
                .collect(),
        })
    }

    /// The windows' advice: the watch's criterion and risk; a stick-slipping window's way out
    /// by its string simulated for a few samples of the likely laws, on the CPU (within the
    /// window's latency).
    fn adviser(&self) -> Adviser {
        let criterion = self.settings.criterion;
        Adviser {
            criterion,
            risk: self.settings.risk,
            escape: match criterion {
                Criterion::Lumped(lumped) => Some(Chain::one_dof(&lumped)),
                Criterion::Critical(_) => self.settings.fe_chain.clone(),
            }
            .map(|chain| EscapeSettings {
                chain,
                samples: ESCAPE_SAMPLES,
                min_probability: ESCAPE_MIN_PROBABILITY,
                backend: Backend::Cpu,
            }),
        }
    }

    /// Adds the advice (from the latest posterior), the window's picture and the latency.
    fn completed(&mut self, mut update: Update, window: &Window) -> Update {
        self.carried.window = Some(window.index);
        let (omega_rpm, wob_kn) = operating_point(&window.rows, self.settings.w_ref_n);
        let inputs =
            self.carried.posterior.as_ref().map(|posterior| {
                crate::abc::posterior::map_inputs_of(posterior, crate::pipeline::advice::ADVICE_SAMPLES)
            });
        if let Some(inputs) = &inputs {
            let speeds: Vec<f64> = window.rows.iter().map(|r| r.speed_rad_s).collect();
            let seen = BitSeen::of(&speeds, None);
            // The parameters describe the torque at the window's own weight on bit: that
            // weight is the advice's W_ref.
            update.advice = Some(self.adviser().advise(
                inputs,
                wob_kn * 1000.0,
                OperatingPoint { omega_rpm, wob_kn },
                seen.as_ref().map(|s| (s, "window")),
            ));
        }
        let posterior = inputs.as_deref().map(|inputs| view::Posterior {
            inputs,
            criterion: self.settings.criterion,
            wob_kn,
            risk: self.settings.risk,
        });
        self.view = Some(view::view(window.index, &window.rows, self.torque_unit, posterior));
        update.latency_s = self.last_arrival.map_or(0.0, |t| t.elapsed().as_secs_f64());
        update
    }

    /// The window's samples as a record: every sample above the minimum speed for
    /// calibration; `Err` says why there is none to use.
    fn window_data(&self, window: &Window) -> std::result::Result<FieldData, String> {
        let rows = &window.rows;
        if rows.is_empty() {
            return Err("no sample in the window (a gap in the record)".into());
        }
        let column = |f: &dyn Fn(&Row) -> f64| rows.iter().map(f).collect::<Vec<f64>>();
        let time = column(&|r| r.time_s.unwrap_or(f64::NAN));
        let speed = column(&|r| r.speed_rad_s);
        let torque = column(&|r| r.torque_nm);
        let wob: Option<Vec<f64>> = rows.iter().map(|r| r.wob_n).collect();
        let mut names = vec!["time_s".to_string(), "speed_rad_s".into(), "torque_nm".into()];
        let mut columns: Vec<Option<&[f64]>> = vec![Some(&time), Some(&speed), Some(&torque)];
        if let Some(wob) = &wob {
            names.push("wob_n".into());
            columns.push(Some(wob));
        }
        let opts = DataOptions {
            speed_column: None,
            torque_column: None,
            wob_column: None,
            time_column: None,
            speed_unit: None,
            torque_unit: None,
            wob_unit: None,
            t_start_s: None,
            t_end_s: None,
            thin: 1,
            calibration_fraction: 1.0,
            ..self.settings.data.clone()
        };
        let source = PathBuf::from(format!("{} (window {})", self.source.display(), window.index));
        let mut data =
            crate::data::field_data_from_columns(&names, &columns, &source, &opts).map_err(|e| e.to_string())?;
        // Samples are SI; parameters are reported in the record's own torque unit.
        data.torque_unit = self.torque_unit;
        Ok(data)
    }

    /// Why a window's samples cannot tell the laws apart, if they cannot.
    fn cannot_inform(&self, data: &FieldData) -> Option<String> {
        let n = data.calibration.len();
        if n < self.settings.min_samples {
            return Some(format!(
                "{n} samples above the minimum speed, fewer than {}",
                self.settings.min_samples
            ));
        }
        // Every law gives a positive torque on bit while the bit turns: a window mostly below
        // zero is a sign or column mix-up, which a fit would only describe by its bounds.
        let not_positive = data.calibration.torque_nm.iter().filter(|&&t| t <= 0.0).count();
        if 2 * not_positive > n {
            return Some(format!(
                "{not_positive} of its {n} torques are zero or negative: no law describes them (a torque of the wrong sign, or the wrong column?)"
            ));
        }
        let mut speeds = data.calibration.speed_rad_s.clone();
        speeds.sort_by(f64::total_cmp);
        let span_rpm =
            (crate::numerics::quantile(&speeds, 0.95) - crate::numerics::quantile(&speeds, 0.05)) / RAD_S_PER_RPM;
        (span_rpm < self.settings.min_speed_span_rpm).then(|| {
            format!(
                "the bit turned at one speed (5–95 % of its speeds within {span_rpm:.1} rpm): no law can be told from another here"
            )
        })
    }
}

/// Grid starts of each law's fit beside the window before's estimate.
const WARM_FIT_STARTS: usize = 2;

/// Posterior samples per law simulated for the escape advice of a stick-slipping window.
const ESCAPE_SAMPLES: usize = 4;
/// Laws less probable than this are left out of the escape advice's simulations.
const ESCAPE_MIN_PROBABILITY: f64 = 0.05;

/// A window's operating point: the mean top-drive speed (the mean bit speed where the
/// record has no top-drive column), rpm, and the mean weight on bit (`w_ref_n` where the
/// record has no column for it), kN; each at least 1.
fn operating_point(rows: &[Row], w_ref_n: f64) -> (f64, f64) {
    let n = rows.len().max(1) as f64;
    let omega_rpm = rows
        .iter()
        .map(|r| r.top_drive_rad_s.unwrap_or(r.speed_rad_s))
        .sum::<f64>()
        / n
        / RAD_S_PER_RPM;
    let wob_kn = rows.iter().map(|r| r.wob_n.unwrap_or(w_ref_n)).sum::<f64>() / n / 1000.0;
    (omega_rpm.max(1.0), wob_kn.max(1.0))
}

/// Rows read before the watch starts, to measure the record's rate (its median time step).
const RATE_ROWS: usize = 64;

/// How a watch ended.
#[derive(Clone, Debug, Serialize)]
pub struct Ended {
    /// Windows given by this watch (a resumed one: since it resumed).
    pub windows: usize,
    /// Lines of the source skipped (not rows of the record).
    pub skipped_lines: u64,
    /// Window length and step, s.
    pub window_s: f64,
    pub step_s: f64,
    /// Whether it was stopped (`stop` set) before the source ended.
    pub stopped: bool,
}

/// Where a watch keeps its windows and how it is stopped.
#[derive(Clone, Copy, Default)]
pub struct FollowOptions<'a> {
    /// A watch directory ([`store`]): each window is stored before it is given.
    pub dir: Option<&'a Path>,
    /// Go on with the watch stored in `dir`, after its last window: the same settings, the
    /// same source read again from its start (its rows up to that window are read, not
    /// computed).
    pub resume: bool,
    /// Asked between rows (and while a followed file is silent); true (after Ctrl-C) ends the
    /// watch: the window in progress is finished and stored, the rest of the source not read.
    pub stop: Option<&'a dyn Fn() -> bool>,
    /// The live page's server: told the watch's meta when its windows are known, and each
    /// window as it is given.
    pub serve: Option<&'a serve::Server>,
}

/// Follows `rows` to their end: measures the record's rate on its first rows (for the
/// default window), then gives each window's update to `on_update` as soon as the window is
/// complete (and stored, with `options.dir`). Skipped lines and what the user should know go
/// to `observer`, each once.
pub fn follow(
    rows: &mut source::Rows,
    mut settings: WatchSettings,
    options: FollowOptions<'_>,
    observer: &mut dyn Observer,
    on_update: &mut dyn FnMut(&Update) -> Result<()>,
) -> Result<Ended> {
    let source = rows.name().to_path_buf();
    let stopped = || options.stop.is_some_and(|stop| stop());
    // A resumed watch: its store, checked against these settings, and where it stopped.
    let mut resumed: Option<(store::WatchStore, store::StoredWatch)> = None;
    if options.resume {
        let dir = options
            .dir
            .ok_or_else(|| crate::Error::setting("resume", "needs the watch directory (`out`) to go on with"))?;
        let (kept, stored) = store::WatchStore::resume(dir)?;
        check_same_watch(&stored.meta, &settings, dir)?;
        settings.window_s = Some(stored.meta.window_s);
        settings.step_s = Some(stored.meta.step_s);
        if let Some(last) = stored.updates.last() {
            rows.replay_from(last.start_s + stored.meta.step_s);
            observer.note(format!(
                "going on with the watch in {} after window {} (t = {} s)",
                dir.display(),
                last.window,
                last.end_s
            ));
        }
        resumed = Some((kept, stored));
    }
    let mut kept: Option<store::WatchStore> = None;
    let mut first: Vec<(Row, std::time::Instant)> = Vec::new();
    let mut watch: Option<Watch> = None;
    let mut given = 0;
    let mut interrupted = false;
    loop {
        if stopped() {
            interrupted = true;
            break;
        }
        let next = rows.next_row()?;
        let ended = matches!(next, source::Next::End);
        match next {
            source::Next::Row(row, arrived) => first.push((row, arrived)),
            source::Next::Skipped(why) => observer.note(format!("warning: {why}: line skipped")),
            source::Next::Said(what) => observer.note(format!("warning: {what}")),
            source::Next::Stalled(silent) => observer.note(format!(
                "warning: {}: no row for {:.0} s: the feed has stalled (still following)",
                source.display(),
                silent.as_secs_f64()
            )),
            source::Next::Waiting | source::Next::End => {}
        }
        if watch.is_none() && (first.len() >= RATE_ROWS || (ended && !first.is_empty())) {
            let times: Vec<f64> = first.iter().filter_map(|(r, _)| r.time_s).collect();
            let mut steps: Vec<f64> = times.windows(2).map(|w| w[1] - w[0]).filter(|d| *d > 0.0).collect();
            steps.sort_by(f64::total_cmp);
            let measured_hz = median(&steps).map_or(1.0, |dt| 1.0 / dt);
            let rate_hz = resumed.as_ref().map_or(measured_hz, |(_, s)| s.meta.rate_hz);
            let unit = rows.torque_unit();
            let mut made = Watch::new(settings.clone(), source.clone(), rate_hz, unit)?;
            let (length, step) = made.windows();
            let thin = made.thin();
            if settings.thin.is_none() && thin > 1 {
                observer.note(format!(
                    "one row in {thin} used ({rate_hz:.1} Hz thinned to {:.1} Hz); `thin` sets it",
                    rate_hz / thin as f64
                ));
            }
            if let Some(config) = &settings.abc {
                observer.note(format!(
                    "each window's law probabilities by the paper's ABC ({} sampler, {} particles, δ = {}): ratios of the laws' prior volumes below each window's ε, not evidence",
                    match config.sampler {
                        crate::run::SamplerConfig::Rejection(_) => "rejection",
                        crate::run::SamplerConfig::Smc(_) => "SMC",
                    },
                    config.sampler.schedule().particles,
                    config.delta
                ));
            }
            if settings.window_s.is_none() || settings.step_s.is_none() {
                observer.note(format!(
                    "windows of {length} s every {step} s (the record's rate: {rate_hz:.1} Hz); `window_s` and `step_s` set them"
                ));
            }
            match resumed.take() {
                Some((store, stored)) => {
                    if let Some(server) = options.serve {
                        server.set_meta(&serve::page_meta(&stored.meta));
                        let last = stored.updates.last().map(|u| u.window);
                        let view = stored.view.as_ref().filter(|v| Some(v.window) == last);
                        for update in &stored.updates {
                            server.publish(update, view.filter(|_| Some(update.window) == last));
                        }
                    }
                    if unit != stored.meta.torque_unit {
                        return Err(crate::Error::setting(
                            "resume",
                            format!(
                                "the record's torques are in {}, the watch's were in {}",
                                unit.label(),
                                stored.meta.torque_unit.label()
                            ),
                        ));
                    }
                    if let Some(carried) = stored.carried {
                        made.resume(carried);
                    }
                    kept = Some(store);
                }
                None => {
                    let meta = store::WatchMeta {
                        source: source.display().to_string(),
                        settings: store::settings_json(&settings),
                        window_s: length,
                        step_s: step,
                        rate_hz,
                        torque_unit: unit,
                        bitrock_version: env!("CARGO_PKG_VERSION").to_string(),
                    };
                    if let Some(dir) = options.dir {
                        kept = Some(store::WatchStore::create(dir, &meta)?);
                    }
                    if let Some(server) = options.serve {
                        server.set_meta(&serve::page_meta(&meta));
                    }
                }
            }
            watch = Some(made);
        }
        if let Some(watch) = watch.as_mut() {
            let mut give = |update: Update, watch: &Watch| -> Result<()> {
                if let Some(store) = kept.as_mut() {
                    store.append(&update, watch.carried(), watch.view())?;
                }
                given += 1;
                on_update(&update)?;
                if let Some(server) = options.serve {
                    server.publish(&update, watch.view());
                }
                Ok(())
            };
            for (row, arrived) in first.drain(..) {
                for update in watch.push(row, arrived, observer)? {
                    give(update, watch)?;
                }
                if stopped() {
                    break;
                }
            }
            if ended && !stopped() {
                for update in watch.finish(observer)? {
                    give(update, watch)?;
                }
            }
        }
        if ended {
            break;
        }
    }
    let (window_s, step_s) = watch.as_ref().map_or((0.0, 0.0), Watch::windows);
    Ok(Ended {
        windows: given,
        skipped_lines: rows.skipped,
        window_s,
        step_s,
        stopped: interrupted || stopped(),
    })
}

/// What a window's fits, evidence or ABC give, or why its samples cannot give it (a fit, a
/// finite likelihood, boxes a sampler reaches): that ends the window, not the watch, since the
/// next window may be fine. Any other error ends the watch.
fn of_window<T>(result: Result<T>) -> Result<std::result::Result<T, String>> {
    match result {
        Ok(value) => Ok(Ok(value)),
        Err(e @ (crate::Error::Data { .. } | crate::Error::Fit { .. } | crate::Error::Numerical(_))) => {
            Ok(Err(e.to_string()))
        }
        Err(crate::Error::InvalidSetting { field, message }) if field == "prior" || field == "max_stages" => {
            Ok(Err(message))
        }
        Err(e) => Err(e),
    }
}

/// Refuses to go on with a stored watch under other settings: its windows would not be the
/// ones it would have given.
fn check_same_watch(meta: &store::WatchMeta, settings: &WatchSettings, dir: &Path) -> Result<()> {
    let now = store::settings_json(settings);
    let defaults = store::settings_json(&WatchSettings::default());
    let (Some(stored), Some(now)) = (meta.settings.as_object(), now.as_object()) else {
        return Ok(());
    };
    for (field, value) in now {
        let was = match field.as_str() {
            // Window and step: those the watch used (given or its defaults); left out here,
            // the watch's own.
            "window_s" if !value.is_null() => &serde_json::json!(meta.window_s),
            "step_s" if !value.is_null() => &serde_json::json!(meta.step_s),
            "window_s" | "step_s" => continue,
            // A setting a watch stored without had the value it has by default then.
            _ => match stored.get(field) {
                Some(was) => was,
                None => &defaults[field],
            },
        };
        if was != value {
            return Err(crate::Error::setting(
                field,
                format!(
                    "is {value} here, {was} in the watch in {} (a watch goes on with its own settings)",
                    dir.display()
                ),
            ));
        }
    }
    Ok(())
}

/// How far (nats of log-likelihood) a warm-started law's best particle may lie below its
/// window's least-squares fit: a posterior sampled where it lies comes within a few nats of
/// its peak, so a larger gap says the samplers started from the window before's posterior
/// missed this window's (and the law's evidence came out low, with an error that cannot show
/// it: a proposal blind to a mode is confident).
const MISSED_NATS: f64 = 10.0;

/// Whether a law's warm samplers missed its posterior where it matters: its best particle
/// more than [`MISSED_NATS`] below its fit (a fit inside the law's box, which the samplers
/// can reach), and its evidence raised by about that gap would reach the best law's (a law
/// that stays below it cannot become the most probable; a law whose posterior is a funnel
/// keeps its best particle nats below its peak, which alone is no miss). `n`: the samples the
/// window's evidence used.
fn missed_mode(analysis: &EvidenceAnalysis, n: usize) -> bool {
    let best = analysis
        .evidence
        .laws
        .iter()
        .map(|e| e.ln_z)
        .fold(f64::NEG_INFINITY, f64::max);
    analysis.fits.iter().any(|fit| {
        let Some(e) = analysis.evidence.of(fit.law) else {
            return false;
        };
        let reachable = analysis
            .prior
            .boxes
            .iter()
            .find(|b| b.law == fit.law)
            .is_some_and(|b| b.contains(&fit.params_si));
        let gap = n as f64 / 2.0 * (e.best_rho / fit.rho).ln();
        reachable && fit.rho > 0.0 && gap > MISSED_NATS && e.ln_z + gap >= best
    })
}

/// One law's line of a window's update: its selection (window probability, ln Z where the
/// evidence gave one), carried probability, and its posterior summarised by a run summary's
/// rule (mean, MAP, 1 % and 99 % quantiles, in the record's torque `unit`) with Kish's ESS of
/// its weighted particles.
fn law_update(selected: &Selected, probability: f64, unit: crate::units::TorqueUnit) -> LawUpdate {
    let law = selected.law;
    let members: Vec<&crate::abc::Particle> = selected.posterior.iter().collect();
    let summary =
        (!members.is_empty()).then(|| crate::abc::posterior::summarize_law(law, &members, selected.probability));
    let weights: Vec<f64> = selected.posterior.iter().map(|p| p.weight).collect();
    let in_unit = |v: Option<&Vec<f64>>| match v {
        Some(v) => crate::documents::to_record_units(law, v, unit),
        None => vec![f64::NAN; law.n_params()],
    };
    LawUpdate {
        law,
        probability,
        window_probability: selected.probability,
        ln_z: selected.ln_z.map(|(ln_z, _)| ln_z),
        ln_z_error: selected.ln_z.map(|(_, error)| error),
        mean: in_unit(summary.as_ref().map(|s| &s.mean)),
        map: in_unit(summary.as_ref().map(|s| &s.map)),
        q01: in_unit(summary.as_ref().map(|s| &s.q01)),
        q99: in_unit(summary.as_ref().map(|s| &s.q99)),
        ess: crate::abc::effective_sample_size(&weights),
    }
}

/// The log-likelihood (nats) the earlier window's fits lose on this window: (n/2)·ln(ρ_then /
/// ρ_now), ρ_then the smallest ρ here of any law at its earlier fit, ρ_now the smallest of the
/// laws fitted here (among the laws fitted both times). The old formation is gone only where
/// none of its fitted laws still explains the samples: taking one law's fit alone (the best
/// here) calls a change whenever a law whose parameters lie on a ridge (m3, m4) moved along
/// it between two windows of the same rock. The earlier fits held at the weight on bit
/// `holds_at_n` (N): here their torque is scaled by each sample's WOB over it, as the
/// evidence's WOB-scaled model has it, so that a change of weight on bit in one rock is not a
/// change of rock.
fn loss_nats(
    before: &Fits,
    holds_at_n: Option<f64>,
    now: &[crate::fit::LawFit],
    samples: &crate::data::Samples,
) -> Option<f64> {
    let sum_sq = samples.sum_sq_torque();
    let rho_now = now
        .iter()
        .filter(|f| f.rho.is_finite() && f.rho > 0.0)
        .filter(|f| before.iter().any(|(law, _)| *law == f.law))
        .map(|f| f.rho)
        .min_by(f64::total_cmp)?;
    let rho_then = before
        .iter()
        .filter(|(law, _)| now.iter().any(|f| f.law == *law))
        .map(|(law, old)| {
            let residuals = crate::fit::residuals(*law, old, samples, holds_at_n);
            residuals.iter().map(|e| e * e).sum::<f64>() / sum_sq
        })
        .filter(|rho| rho.is_finite())
        .min_by(f64::total_cmp)?;
    let n = samples.len() as f64;
    Some(0.5 * n * (rho_then / rho_now).ln())
}

fn median(values: &[f64]) -> Option<f64> {
    if values.is_empty() {
        return None;
    }
    let mut sorted = values.to_vec();
    sorted.sort_by(f64::total_cmp);
    Some(crate::numerics::quantile(&sorted, 0.5))
}

/// `weights` normalised to sum 1 with none below `floor` (those raised to it, the others
/// scaled down to make room).
fn normalise_with_floor(weights: &[f64], floor: f64) -> Vec<f64> {
    let total: f64 = weights.iter().sum();
    let mut p: Vec<f64> = if total > 0.0 && total.is_finite() {
        weights.iter().map(|w| w / total).collect()
    } else {
        vec![1.0 / weights.len() as f64; weights.len()]
    };
    // Raise the laws under the floor; take what they gain from the others in proportion.
    let low: f64 = p.iter().filter(|&&v| v < floor).count() as f64 * floor;
    let high: f64 = p.iter().filter(|&&v| v >= floor).sum();
    if high > 0.0 && low > 0.0 {
        for v in &mut p {
            *v = if *v < floor { floor } else { *v * (1.0 - low) / high };
        }
    }
    p
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn no_law_goes_below_the_floor_and_the_probabilities_sum_to_one() {
        let p = normalise_with_floor(&[0.97, 0.03, 0.0, 0.0], 0.01);
        assert!((p.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        assert!((p[2] - 0.01).abs() < 1e-15 && (p[3] - 0.01).abs() < 1e-15);
        assert!(p[1] > 0.01 && p[0] > 0.9);
        assert_eq!(normalise_with_floor(&[1.0, 3.0], 0.01), vec![0.25, 0.75]);
    }

    #[test]
    fn a_change_is_where_none_of_the_earlier_fits_explains_the_window() {
        // m2 samples with a small wiggle, N·m.
        let m2 = [13_000.0, 6_500.0, 0.3];
        let speed_rad_s: Vec<f64> = (1..=200).map(|i| 0.1 * i as f64).collect();
        let torque_nm = speed_rad_s
            .iter()
            .enumerate()
            .map(|(i, &w)| Law::M2.torque(&m2, w, 1.0) + 50.0 * (1.7 * i as f64).sin())
            .collect();
        let samples = crate::data::Samples {
            speed_rad_s,
            torque_nm,
            wob_n: None,
            time_s: None,
        };
        let fits = crate::fit::fit_laws(
            &[Law::M2, Law::M3],
            &samples,
            &crate::data::Samples::default(),
            &FitOptions::default(),
        )
        .unwrap();
        let fitted = |law: Law| fits.iter().find(|f| f.law == law).unwrap();
        let n = samples.len() as f64;
        let gap = 0.5 * n * (fitted(Law::M3).rho / fitted(Law::M2).rho).ln();
        assert!(gap > 0.0, "m2 is the best law here");
        // The earlier window's m2 lay elsewhere (its static torque 30 % up); its m3, as fitted
        // then, still explains these samples: no change, the loss is m3's own gap to m2.
        let mut m2_elsewhere = m2.to_vec();
        m2_elsewhere[0] *= 1.3;
        let before = vec![
            (Law::M2, m2_elsewhere.clone()),
            (Law::M3, fitted(Law::M3).params_si.clone()),
        ];
        let loss = loss_nats(&before, None, &fits, &samples).unwrap();
        assert!((loss - gap).abs() < 1e-9, "{loss} nats against {gap}");
        // Neither explains them: hundreds of nats.
        let mut m3_elsewhere = fitted(Law::M3).params_si.clone();
        m3_elsewhere[3] *= 1.3;
        let before = vec![(Law::M2, m2_elsewhere), (Law::M3, m3_elsewhere)];
        let loss = loss_nats(&before, None, &fits, &samples).unwrap();
        assert!(loss > 100.0 + gap, "{loss} nats");
    }

    #[test]
    fn default_windows_hold_500_samples_and_10_seconds() {
        assert_eq!(default_windows(50.0), (10.0, 2.0));
        assert_eq!(default_windows(1.0 / 0.020000000000000004), (10.0, 2.0));
        assert_eq!(default_windows(20.000000000000004), (25.0, 5.0));
        assert_eq!(default_windows(1.0), (500.0, 100.0));
    }

    #[test]
    fn records_faster_than_100_hz_are_thinned_to_at_most_50_hz() {
        for (rate, thin) in [
            (20.0, 1),
            (50.0, 1),
            (99.9, 1),
            (100.0, 2),
            (1.0 / 0.005000000000000001, 4),
            (1000.0, 20),
            (1000.0000001, 20),
            (999.5, 20),
            (150.0, 3),
        ] {
            assert_eq!(default_thin(rate), thin, "at {rate} Hz");
            assert!(
                rate / thin as f64 <= THINNED_RATE_HZ * (1.0 + 1e-6) || thin == 1,
                "at {rate} Hz"
            );
        }
        assert_eq!(default_thin(f64::NAN), 1);
        assert_eq!(default_thin(f64::INFINITY), 1);
    }
}
