//! Along the well: a growing record followed window by window ([`window`], by its own time
//! stamps), each window's law probabilities from the model evidence, carried from window to
//! window with a forgetting factor and a floor, a change of formation noticed, and the
//! rotary speed and weight on bit that avoid stick-slip now.
//!
//! Per window: the samples below the minimum speed are dropped (as `fit` drops them); a
//! window with too few samples, whose bit turned at one speed (no law can be told from
//! another there) or whose torques are mostly not positive, is reported as such and updates
//! nothing. Otherwise the evidence of each law on the window ([`crate::run::evidence`],
//! physical boxes; warm-started from the window before: its posterior's kernel density as
//! the samplers' reference, its estimates as the fits' starts, particles by each law's worth,
//! and a window that declares a change computed again from the boxes; or, by flag, the
//! paper's ABC on the window, [`WatchSettings::abc`]), then
//!
//! - **law probabilities** P_t(m) ∝ P_{t−1}(m)^(λ^γ) · Z_t(m)^γ, γ = step / window (the share
//!   of a window its step brings in: overlapping windows count each sample once) and λ the
//!   forgetting factor (the evidence of one window length ago counts λ, of two λ², …), no law
//!   below the floor;
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
pub mod witsml;

use crate::abc::Observer;
use crate::abc::evidence::Reference;
use crate::abc::evidence::{EvidenceConfig, Start};
use crate::data::{BitReading, DataOptions, FieldData, Row, Samples};
use crate::error::Result;
use crate::eval::Backend;
use crate::fit::FitOptions;
use crate::laws::{Law, PAPER_W_REF_N};
use crate::run::advice::{Adviser, EscapeSettings};
use crate::run::evidence::{EvidenceAnalysis, WarmStart};
use crate::run::strings::{OperatingPoint, SimulatedSettings, thinned};
use crate::simulate::strings::Chain;
use crate::stability::lumped::Lumped;
use crate::stability::map::Criterion;
use crate::units::RAD_S_PER_RPM;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use window::{Pushed, Window, Windows};

mod advice;
mod carried;
mod change;
mod follow;
mod selection;
mod settings;
mod surface;
mod update;
pub use carried::*;
use change::*;
pub use follow::*;
use selection::*;
pub use settings::*;
pub use surface::{SURFACE_PARTICLES, default_surface_settings};
pub use update::*;

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
    /// The channels the source declared and their units: the record checks judge each window
    /// in them, and parameters are reported in its torque unit.
    declared: crate::data::Declared,
    /// The record checks' warnings said so far, their numbers left out: each said once.
    said: std::collections::HashSet<String>,
    /// The picture of the latest window given.
    view: Option<view::View>,
    /// Each window's evidence job as the evidence's settings make it ([`WatchSettings::evidence`],
    /// validated once); `None` where the watch runs the paper's ABC on each window.
    evidence: Option<crate::run::evidence::Job>,
    /// Each window's surface run, validated once, where the source holds surface channels
    /// alone ([`surface`]).
    surface: Option<crate::run::surface::SurfaceSettings>,
}

impl Watch {
    /// A watch of `settings` over a record named `source` sampled at about `rate_hz`, whose
    /// channels and units the source `declared`; the thinning, window and step taken from the
    /// rate where not given.
    pub fn new(
        settings: WatchSettings,
        source: PathBuf,
        rate_hz: f64,
        declared: crate::data::Declared,
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
        // Bounded before any work: a step shorter than the rows' period gives windows that
        // repeat the same rows, as many per second of record as the step is short.
        let period_s = thin as f64 / rate_hz;
        // A step of one period as the user writes it (0.05 s at 20 Hz) is one period, whatever
        // the last bits of the measured rate.
        if step < period_s * (1.0 - 1e-9) {
            return Err(crate::Error::setting(
                "step_s",
                format!(
                    "{} s is shorter than the record's sample period ({} s, one row in {thin} of \
                     {rate_hz:.1} Hz): windows would repeat the same rows",
                    crate::limits::readable(step),
                    crate::limits::readable(period_s)
                ),
            ));
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
        let evidence = match &settings.abc {
            Some(config) => {
                config.validate()?;
                None
            }
            None => {
                let mut job = settings.evidence.job(settings.laws.clone(), FitOptions::default())?;
                job.sampler.check_memory(&settings.laws)?;
                // Its backend is the watch's; the watch advises on its own string, once per
                // window, and judges a change by its own rule, not by the separations.
                job.backend = settings.backend;
                job.separations = false;
                Some(job)
            }
        };
        let surface = match declared.surface {
            Some(_) if settings.abc.is_some() => {
                return Err(crate::Error::setting(
                    "abc",
                    "the paper's ABC fits the bit's torque to its speed; a record of surface channels alone is inferred through simulated strings: drop it",
                ));
            }
            Some(_) => Some(Self::surface_settings(&settings)?),
            None => None,
        };
        Ok(Self {
            surface,
            windows: Windows::new(length, step).thinned(thin),
            settings,
            source,
            carried: Carried::default(),
            last_arrival: None,
            stopped_at_s: None,
            period_s: 1.0 / rate_hz,
            declared,
            said: Default::default(),
            view: None,
            evidence,
        })
    }

    /// A record whose stamps are whole ticks of `tick_s` (a rounded clock): its end reaches a
    /// tick past its last stamp, not one row's period, so that its last window is given.
    pub fn reach_past_last_stamp(&mut self, tick_s: f64) {
        self.period_s = self.period_s.max(tick_s);
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
        note_gap(self.carried.window, &window, observer);
        let glitch = advice::wob_glitch_share(&window.rows);
        if glitch > 0.0 {
            let (_, wob_kn) = advice::operating_point(&window.rows, self.settings.w_ref_n);
            observer.note(format!(
                "warning: window {}: {:.0} % of its weights on bit lie beyond three times their median or below a third of it (a glitch of the WOB channel?): its operating point takes the median, {wob_kn:.0} kN",
                window.index,
                100.0 * glitch
            ));
        }
        let mut update = Update::empty(&window);
        if let Some(config) = self.surface.clone() {
            return self.surface_update(&config, update, &window, observer);
        }
        let data = match self.window_data(&window) {
            Ok(data) => data,
            Err(why) => {
                update.uninformative = Some(why);
                return Ok(self.completed(update, &window, None));
            }
        };
        self.say_record_checks(&window, &data, observer);
        update.samples_used = data.calibration.len();
        if let Some(why) = self.cannot_inform(&data) {
            update.uninformative = Some(why);
            return Ok(self.completed(update, &window, None));
        }
        let selected = match &self.settings.abc {
            None => self.by_evidence(&window, &data, observer)?,
            Some(config) => self.by_abc(config, &window, &data, observer)?,
        };
        let (selection, judged) = match selected {
            Ok(selected) => selected,
            Err(why) => {
                update.uninformative = Some(why);
                return Ok(self.completed(update, &window, None));
            }
        };
        let Judged { loss, level, change } = judged;
        update.change = change;
        update.change_nats = loss.map(|l| l - level.unwrap_or(0.0));
        self.carry_window(&window, &selection, &data, (loss, change));
        self.carry_selection(&mut update, selection, data.torque_unit);
        Ok(self.completed(update, &window, None))
    }

    /// The update of a window of surface channels ([`surface`]): its laws through simulated
    /// strings, its advice from the bit they imply.
    fn surface_update(
        &mut self,
        config: &crate::run::surface::SurfaceSettings,
        mut update: Update,
        window: &Window,
        observer: &mut dyn Observer,
    ) -> Result<Update> {
        update.samples_used = window.rows.len();
        match self.by_surface(config, window, observer)? {
            Ok(selected) => {
                for warning in &selected.warnings {
                    self.say_once(&format!("window {}: {warning}", window.index), observer);
                }
                update.check = Some(selected.check);
                self.carry_selection(&mut update, selected.selection, self.declared.units.torque);
                let mut update = self.completed(update, window, Some(selected.bit));
                if let Some(view) = self.view.as_mut() {
                    view.bit = Some(selected.bit);
                    view.surface = Some(selected.strip);
                }
                // What the way out rests on that the window leaves to the prior, among the laws
                // the advice simulates (those carried at least ESCAPE_MIN_PROBABILITY likely).
                let taking_part = |law: Law| {
                    update
                        .laws
                        .iter()
                        .any(|l| l.law == law && l.probability >= advice::ESCAPE_MIN_PROBABILITY)
                };
                let caveat = crate::run::surface::unidentified_caveat(&selected.laws, &taking_part);
                if let (Some(advice), Some(caveat)) = (update.advice.as_mut(), caveat)
                    && advice.stick_slip_now
                {
                    if advice.escape_omega_rpm.is_some() || advice.escape_wob_kn.is_some() {
                        advice.words.push_str(&caveat);
                    }
                    self.spread_advice(advice, &selected.laws);
                }
                Ok(update)
            }
            Err(why) => {
                update.uninformative = Some(why);
                Ok(self.completed(update, window, None))
            }
        }
    }

    /// A window's selection into its update and what the watch carries: its law
    /// probabilities, P_t ∝ P_{t−1}^(λ^γ) · P(m | window)^γ, floored, γ the share of a window
    /// its step brings in (each sample counted once however the windows overlap; the evidence
    /// of a window length ago weighs λ), restarted at a change; each law's summary in `unit`;
    /// the mixture posterior.
    fn carry_selection(&mut self, update: &mut Update, selection: Selection, unit: crate::units::TorqueUnit) {
        update.candidates_scored = selection.candidates;
        update.epsilon = selection.epsilon;
        update.answer = selection.answer.clone();
        let window_p: Vec<f64> = self
            .settings
            .laws
            .iter()
            .map(|&law| selection.of(law).map_or(0.0, |l| l.probability))
            .collect();
        let carried = match (&self.carried.probabilities, update.change) {
            (Some(before), false) => {
                let (length, step) = self.windows.shape();
                let new_share = (step / length).min(1.0);
                let kept = self.settings.forgetting.powf(new_share);
                let joint: Vec<f64> = before
                    .iter()
                    .zip(&window_p)
                    .map(|(b, w)| b.powf(kept) * w.powf(new_share))
                    .collect();
                normalise_with_floor(&joint, self.settings.floor)
            }
            _ => normalise_with_floor(&window_p, self.settings.floor),
        };
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
        let posterior = mixture_posterior(selection.laws, &self.settings.laws, &carried);
        self.carried.probabilities = Some(carried);
        self.carried.posterior = Some(posterior);
        self.carried.posterior_scaled = selection.w_ref_n.is_some();
    }

    /// What the watch carries on from a window: its losses (cleared at a change), its fits
    /// and WOB among the recent windows the change rule compares with.
    fn carry_window(
        &mut self,
        window: &Window,
        selection: &Selection,
        data: &FieldData,
        (loss, change): (Option<f64>, bool),
    ) {
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
    }

    /// The record checks' warnings of a window's samples (`data`) and of its top-drive
    /// column, each said once, at the first window it fires in.
    fn say_record_checks(&mut self, window: &Window, data: &FieldData, observer: &mut dyn Observer) {
        let top_drive = self.declared.top_drive.as_ref().and_then(|(column, unit)| {
            let speeds: Vec<f64> = window.rows.iter().filter_map(|r| r.top_drive_rad_s).collect();
            let channel = crate::data::SpeedChannel {
                what: "top-drive speeds",
                column,
                unit: *unit,
                setting: None,
            };
            channel.unit_warning(&data.source.display().to_string(), &speeds)
        });
        for warning in data.warnings.iter().chain(&top_drive) {
            self.say_once(warning, observer);
        }
    }

    /// Says `warning` through `observer` unless one differing only by its numbers was said
    /// (the same check on another window).
    fn say_once(&mut self, warning: &str, observer: &mut dyn Observer) {
        if self
            .said
            .insert(warning.chars().filter(|c| !c.is_ascii_digit()).collect())
        {
            observer.note(format!("warning: {warning}"));
        }
    }

    /// The window's samples as a record: every sample above the minimum speed for
    /// calibration; `Err` says why there is none to use.
    fn window_data(&self, window: &Window) -> std::result::Result<FieldData, String> {
        let rows = &window.rows;
        if rows.is_empty() {
            return Err("no sample in the window (a gap in the record)".into());
        }
        // The rows are SI already: handed to the record's filters and checks as they are.
        let bit: Vec<BitReading> = rows.iter().filter_map(|r| r.bit).collect();
        let samples = Samples {
            speed_rad_s: bit.iter().map(|b| b.speed_rad_s).collect(),
            torque_nm: bit.iter().map(|b| b.torque_nm).collect(),
            wob_n: rows.iter().map(|r| r.wob_n).collect(),
            time_s: rows.iter().map(|r| r.time_s).collect(),
        };
        let opts = DataOptions {
            t_start_s: None,
            t_end_s: None,
            thin: 1,
            calibration_fraction: 1.0,
            ..self.settings.data.clone()
        };
        let source = PathBuf::from(format!("{} (window {})", self.source.display(), window.index));
        crate::data::field_data_from_samples(samples, &source, &self.declared, &opts).map_err(|e| e.to_string())
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

/// Says the windows a gap of the record skipped, between the `last` window given and `window`.
fn note_gap(last: Option<usize>, window: &Window, observer: &mut dyn Observer) {
    if let Some(last) = last
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
}

impl Update {
    /// The update of `window` before anything is known of it.
    fn empty(window: &Window) -> Self {
        Update {
            window: window.index,
            start_s: window.start_s,
            end_s: window.end_s,
            samples: window.rows.len(),
            samples_used: 0,
            uninformative: None,
            most_probable: None,
            answer: None,
            laws: Vec::new(),
            change: false,
            change_nats: None,
            advice: None,
            candidates_scored: 0,
            epsilon: None,
            check: None,
            latency_s: 0.0,
        }
    }
}

/// The mixture posterior under the `carried` probabilities of `laws`: each law's particles
/// weighed by its share of the window's posterior, then by its carried probability over it.
fn mixture_posterior(selected_laws: Vec<Selected>, laws: &[crate::Law], carried: &[f64]) -> Vec<crate::abc::Particle> {
    // The mixture posterior under the carried probabilities: each law's particles weighed
    // by its share of the window's posterior, then by its carried probability over it.
    selected_laws
        .into_iter()
        .filter_map(|selected| {
            let k = laws.iter().position(|&l| l == selected.law)?;
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
        .collect()
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
        let samples = crate::data::Samples::new(speed_rad_s, torque_nm);
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
