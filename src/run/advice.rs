//! What to do at an operating point, from a posterior: the one advice of the watch's windows,
//! `stability --run`, `evidence` and the report.
//!
//! - Where the bit turns steadily: the linear criterion (the paper's): P(steady rotation is
//!   unstable) there under the mixture, and the nearest top-drive speed and weight on bit that
//!   bring it below the risk.
//! - Where the bit is seen stick-slipping (stuck at least
//!   [`crate::data::STICK_SLIP_STUCK_SHARE`] of the time): never called steady. The linear
//!   criterion says when steady rotation *starts* to stick-slip, not what gets a stick-slipping
//!   bit out (the cycle persists far above its boundary), so the advice becomes the nearest
//!   higher speed and lighter weight that end the cycle *from the state the bit is in*, by
//!   simulated strings ([`crate::run::strings`]), each with P(it ends).

use super::strings::{
    OperatingPoint, Peaks, SimulatedSettings, Simulator, advice_speeds_rpm, advice_weights_kn, thinned,
};
use crate::data::BitSeen;
use crate::eval::Backend;
use crate::eval::surface::InferredString;
use crate::simulate::strings::Chain;
use crate::stability::map::{Criterion, LawSamples, mixture_probability_grid};
use serde::{Deserialize, Serialize};

/// The top-drive speeds the linear advice looks at (and the watch's map draws), rpm, as
/// (min, max, count).
pub const SPEEDS_RPM: (f64, f64, usize) = (10.0, 300.0, 59);
/// The weights on bit it looks at: 10 % to 200 % of the operating point's, in steps of 10 %.
pub const WEIGHTS: usize = 20;
/// Posterior samples per law behind the linear advice (and the watch's map).
pub const ADVICE_SAMPLES: usize = 200;
/// The risk the linear advice keeps below, by default.
pub const DEFAULT_RISK: f64 = 0.05;

/// The weights on bit the linear advice looks at around `wob_kn`, kN.
pub fn weights_kn(wob_kn: f64) -> Vec<f64> {
    (1..=WEIGHTS).map(|k| wob_kn * 0.1 * k as f64).collect()
}

/// The top-drive speeds the linear advice looks at, rpm.
pub fn speeds_rpm() -> Vec<f64> {
    let (lo, hi, count) = SPEEDS_RPM;
    crate::abc::posterior::speed_grid(lo, hi, count)
}

/// The way out scanned again along the posterior's spread of every parameter the record
/// leaves open: it must end the stick-slip in every string there.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SpreadAdvice {
    /// The parameters left open (`m2's g`).
    pub open: Vec<String>,
    /// The nearest top-drive speed (rpm) and lighter weight on bit (kN) that end it there;
    /// `None` where none scanned does.
    pub speed_rpm: Option<f64>,
    pub wob_kn: Option<f64>,
}

/// The advice at an operating point.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Advice {
    /// The operating point: top-drive speed (rpm; the mean bit speed where the record has no
    /// top-drive column) and weight on bit (kN).
    pub omega_rpm: f64,
    pub wob_kn: f64,
    /// P(unstable steady rotation) there, under the mixture posterior.
    pub p_unstable: f64,
    /// The nearest top-drive speed at this weight on bit with P below the risk; `None` where
    /// none within the speeds looked at (10–300 rpm).
    pub safe_omega_rpm: Option<f64>,
    /// The nearest weight on bit at this speed with P below the risk; `None` where none within
    /// 10 %–200 % of this one.
    pub safe_wob_kn: Option<f64>,
    /// The same in words.
    pub words: String,
    /// Share of the samples with the bit below 1 rpm (every sample, those under the fit's
    /// minimum speed included).
    #[serde(default)]
    pub stuck_share: f64,
    /// Stick-slip severity, (max − min) / (2·mean) of the bit speed.
    #[serde(default)]
    pub severity: Option<f64>,
    /// The bit was seen stick-slipping (stuck at least 1 % of the time): never called steady.
    #[serde(default)]
    pub stick_slip_now: bool,
    /// From the state the bit is in, by simulated strings: the nearest higher top-drive speed
    /// (rpm) that ends the stick-slip, with P(it ends).
    #[serde(default)]
    pub escape_omega_rpm: Option<(f64, f64)>,
    /// The nearest lighter weight on bit (kN) that ends it, with P(it ends).
    #[serde(default)]
    pub escape_wob_kn: Option<(f64, f64)>,
    /// Whether the posterior's strings reproduce the cycle the bit was seen in, where it
    /// stick-slipped and both are known.
    #[serde(default)]
    pub cycle: Option<CycleCheck>,
    /// Where the window leaves a law's parameter to its prior (a window of surface channels):
    /// the way out along the posterior's spread of it.
    #[serde(default)]
    pub spread: Option<SpreadAdvice>,
}

/// The cycle the bit was seen in against the posterior's simulated strings at the same
/// operating point: a posterior that does not reproduce the record's cycle misdescribes the
/// torque where the cycle lives (the slow and stuck samples a fit leaves out), and its way out
/// may fall short.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct CycleCheck {
    /// The bit's peak speed seen, rpm.
    pub seen_peak_rpm: f64,
    /// The lowest and highest peak bit speed of the settled simulated strings, rpm.
    pub simulated_peak_rpm: (f64, f64),
    /// The posterior's share (by weight) of strings whose peak lies within [`PEAK_TOLERANCE`]
    /// of the seen one.
    pub reproducing_share: f64,
    /// At least [`REPRODUCING_SHARE`] of the posterior reproduces the seen peak.
    pub reproduced: bool,
    /// Where it is not reproduced, the ways out that the strings which do reproduce it advise
    /// (the posterior conditioned on the cycle): the nearest higher speed (rpm) and lighter
    /// weight (kN), each with P(it ends) among them.
    #[serde(default)]
    pub escape_omega_rpm: Option<(f64, f64)>,
    #[serde(default)]
    pub escape_wob_kn: Option<(f64, f64)>,
}

/// How far (a share) a simulated peak bit speed may lie from the seen one and still reproduce
/// it: room for a downhole tool's speed noise.
pub const PEAK_TOLERANCE: f64 = 0.1;
/// The share of the posterior that must reproduce the seen peak for the cycle to count as
/// reproduced.
pub const REPRODUCING_SHARE: f64 = 0.5;

impl CycleCheck {
    /// The check of `seen_peak_rpm` against the simulated `peaks`; `None` without a string.
    fn new(seen_peak_rpm: f64, peaks: &Peaks) -> Option<Self> {
        let simulated_peak_rpm = peaks.range()?;
        let reproducing_share = peaks.share_within(seen_peak_rpm, PEAK_TOLERANCE);
        Some(Self {
            seen_peak_rpm,
            simulated_peak_rpm,
            reproducing_share,
            reproduced: reproducing_share >= REPRODUCING_SHARE,
            escape_omega_rpm: None,
            escape_wob_kn: None,
        })
    }

    /// The check in words where it fails; empty where the cycle is reproduced.
    fn warning(&self) -> String {
        if self.reproduced {
            return String::new();
        }
        let (lo, hi) = self.simulated_peak_rpm;
        format!(
            "; but only {:.0} % of the posterior's simulated strings peak within {:.0} % of the bit's {:.0} rpm there \
             (they peak at {lo:.0}–{hi:.0} rpm): they do not reproduce its cycle, and their way out may fall short",
            100.0 * self.reproducing_share,
            100.0 * PEAK_TOLERANCE,
            self.seen_peak_rpm
        )
    }
}

/// How a stick-slipping bit's advice is simulated.
#[derive(Clone, Debug, PartialEq)]
pub struct EscapeSettings {
    /// The string simulated.
    pub chain: Chain,
    /// Where the posterior inferred the string: each sample's own instead
    /// ([`SimulatedSettings::string`]).
    pub string: Option<InferredString>,
    /// Posterior samples per law simulated (evenly spaced through each law's).
    pub samples: usize,
    /// Laws less probable than this are left out of the simulations.
    pub min_probability: f64,
    pub backend: Backend,
}

/// How advice is given.
#[derive(Clone, Debug)]
pub struct Adviser {
    /// The linear criterion of steady rotation.
    pub criterion: Criterion,
    /// The risk the linear advice keeps below.
    pub risk: f64,
    /// How a stick-slipping bit's way out is simulated; `None` where no string to simulate is
    /// known (a finite-element criterion given only as its critical damping): the advice then
    /// says the stick-slip and that the linear maps do not say what ends it.
    pub escape: Option<EscapeSettings>,
}

impl Adviser {
    /// The advice at `point` under the mixture `inputs`, whose torque parameters are for the
    /// reference weight on bit `w_ref_n` (N); `seen`: what the bit was seen doing there, where
    /// known, and over what (`"window"`, `"record"`).
    pub fn advise(
        &self,
        inputs: &[LawSamples],
        w_ref_n: f64,
        point: OperatingPoint,
        seen: Option<(&BitSeen, &str)>,
    ) -> Advice {
        let mut advice = self.linear(inputs, w_ref_n, point);
        if let Some((seen, span)) = seen {
            self.observed(&mut advice, inputs, w_ref_n, seen, span);
        }
        advice
    }

    /// The linear criterion's answer: P(unstable) at the point and the nearest safe speed and
    /// weight.
    fn linear(&self, inputs: &[LawSamples], w_ref_n: f64, point: OperatingPoint) -> Advice {
        let OperatingPoint { omega_rpm, wob_kn } = point;
        let map = |omega: &[f64], wob: &[f64]| mixture_probability_grid(inputs, omega, wob, self.criterion, w_ref_n);
        let p_unstable = map(&[omega_rpm], &[wob_kn])[0];
        let speeds = speeds_rpm();
        let by_speed = map(&speeds, &[wob_kn]);
        let weights = weights_kn(wob_kn);
        let by_weight = map(&[omega_rpm], &weights);
        let risk = self.risk;
        let nearest = |values: &[f64], p: &[f64], at: f64| {
            values
                .iter()
                .zip(p)
                .filter(|(_, p)| **p < risk)
                .map(|(v, _)| *v)
                .min_by(|a, b| (a - at).abs().total_cmp(&(b - at).abs()))
        };
        let safe_omega_rpm = nearest(&speeds, &by_speed, omega_rpm);
        let safe_wob_kn = nearest(&weights, &by_weight, wob_kn);
        let words = if p_unstable < risk {
            format!(
                "steady rotation at {omega_rpm:.0} rpm and {}: P(stick-slip) = {p_unstable:.2}, below {risk}",
                crate::units::kn_text(wob_kn)
            )
        } else {
            let mut ways = Vec::new();
            if let Some(o) = safe_omega_rpm {
                ways.push(format!(
                    "{} the top-drive speed to {o:.0} rpm",
                    if o > omega_rpm { "raise" } else { "lower" }
                ));
            }
            if let Some(w) = safe_wob_kn {
                ways.push(format!(
                    "{} the weight on bit to {}",
                    if w > wob_kn { "raise" } else { "lower" },
                    crate::units::kn_text(w)
                ));
            }
            let ways = if ways.is_empty() {
                "no speed of 10–300 rpm nor weight of 10–200 % of this one brings it below the risk".to_string()
            } else {
                ways.join(", or ")
            };
            format!(
                "stick-slip likely at {omega_rpm:.0} rpm and {} (P = {p_unstable:.2}): {ways}",
                crate::units::kn_text(wob_kn)
            )
        };
        Advice {
            omega_rpm,
            wob_kn,
            p_unstable,
            safe_omega_rpm,
            safe_wob_kn,
            words,
            stuck_share: 0.0,
            severity: None,
            stick_slip_now: false,
            escape_omega_rpm: None,
            escape_wob_kn: None,
            cycle: None,
            spread: None,
        }
    }

    /// What the bit was seen doing: a bit stuck at least 1 % of the time stick-slips whatever
    /// the linear criterion says of steady rotation there, and its advice becomes what ends
    /// the cycle from the state the bit is in, by simulated strings.
    fn observed(&self, advice: &mut Advice, inputs: &[LawSamples], w_ref_n: f64, seen: &BitSeen, span: &str) {
        advice.stuck_share = seen.stuck_share;
        advice.severity = seen.severity.filter(|v| v.is_finite());
        advice.stick_slip_now = seen.stick_slips();
        if !advice.stick_slip_now {
            return;
        }
        let point = OperatingPoint {
            omega_rpm: advice.omega_rpm,
            wob_kn: advice.wob_kn,
        };
        let now = format!(
            "stick-slip now at {:.0} rpm and {} (bit stuck {:.0} % of the {span}{})",
            point.omega_rpm,
            crate::units::kn_text(point.wob_kn),
            100.0 * advice.stuck_share,
            advice.severity.map_or(String::new(), |s| format!(", severity {s:.2}"))
        );
        let Some(escape) = &self.escape else {
            advice.words = format!("{now}: the maps of steady rotation do not say what ends it on this string");
            return;
        };
        let inputs = thinned(inputs, escape.samples, escape.min_probability);
        let settings = SimulatedSettings {
            string: escape.string,
            ..SimulatedSettings::new(escape.chain.clone(), w_ref_n, escape.backend)
        };
        // Auto's fallback to the CPU goes into the advice's words; the simulator's progress
        // lines do not (they depend on the machine's speed).
        let mut said = Vec::new();
        let mut say = |note: String| {
            if note.starts_with(crate::eval::NO_USABLE_GPU) {
                said.push(note);
            }
        };
        let (speeds, weights) = (advice_speeds_rpm(point.omega_rpm), advice_weights_kn(point.wob_kn));
        let simulated = Simulator::new(&settings, &inputs, &mut say).and_then(|mut sim| {
            let at = sim.at_point(point)?;
            let all = sim.escape_advice(&at, &speeds, &weights)?;
            let peaks = at.peaks();
            // Where most of the posterior misses the cycle the bit is in, the strings that
            // reproduce it (the posterior conditioned on the cycle) advise too.
            let conditioned = match seen.peak_speed_rpm {
                Some(peak) if peaks.share_within(peak, PEAK_TOLERANCE) < REPRODUCING_SHARE => at
                    .reproducing(peak, PEAK_TOLERANCE)
                    .map(|c| sim.escape_advice(&c, &speeds, &weights))
                    .transpose()?,
                _ => None,
            };
            Ok((all, peaks, conditioned))
        });
        match simulated {
            Ok((e, peaks, conditioned)) => {
                advice.escape_omega_rpm = e.speed_rpm.map(|w| (w.to, w.ends_probability));
                advice.escape_wob_kn = e.wob_kn.map(|w| (w.to, w.ends_probability));
                advice.cycle = seen.peak_speed_rpm.and_then(|seen| CycleCheck::new(seen, &peaks));
                if let (Some(cycle), Some(c)) = (advice.cycle.as_mut(), &conditioned) {
                    cycle.escape_omega_rpm = c.speed_rpm.map(|w| (w.to, w.ends_probability));
                    cycle.escape_wob_kn = c.wob_kn.map(|w| (w.to, w.ends_probability));
                }
                let among = conditioned.map_or(String::new(), |c| {
                    format!("; the strings that do reproduce it: {}", c.ways())
                });
                advice.words = format!(
                    "{now}: {}{}{among}",
                    e.ways(),
                    advice.cycle.map_or(String::new(), |c| c.warning())
                );
            }
            Err(e) => advice.words = format!("{now}: the simulated strings failed ({e})"),
        }
        said.dedup();
        for note in said {
            advice.words.push_str(&format!(" [{note}]"));
        }
    }
}

/// Posterior samples per law simulated for a record's advice.
pub const RECORD_ESCAPE_SAMPLES: usize = 16;
/// Laws less probable than this are left out of a record's simulated advice.
pub const RECORD_ESCAPE_MIN_PROBABILITY: f64 = 0.05;

/// A record's operating point: its mean bit speed (over a stick-slip cycle the bit turns on
/// average as fast as the top drive), rpm, and its mean weight on bit (`w_ref_n` where it has
/// no column for it), kN; at least 1 rpm and 1 N (a laboratory rig's weight is hundreds of
/// newtons).
pub fn record_point(seen: &BitSeen, w_ref_n: f64) -> OperatingPoint {
    OperatingPoint {
        omega_rpm: seen.mean_speed_rpm.max(1.0),
        wob_kn: seen.mean_wob_kn.unwrap_or(w_ref_n / 1000.0).max(1e-3),
    }
}

/// The W_ref (N) a posterior's torque parameters are for at a record: `scaled` where its fit
/// scaled each torque by WOB / W_ref (or the user says so); otherwise the record's own mean
/// weight on bit (the parameters describe the torque as the record drilled, r = 1), or
/// `fallback_n` where it has none.
pub fn params_w_ref_n(scaled: Option<f64>, seen: &BitSeen, fallback_n: f64) -> f64 {
    scaled
        .or(seen.mean_wob_kn.map(|kn| kn * 1000.0))
        .filter(|w| w.is_finite() && *w > 0.0)
        .unwrap_or(fallback_n)
}

impl Adviser {
    /// The advice for a whole record under `criterion`: a stick-slipping record's way out by
    /// `chain` simulated for [`RECORD_ESCAPE_SAMPLES`] samples of the likely laws on `backend`
    /// (none where the string cannot be simulated: longer than the simulator's chains).
    pub fn for_record(criterion: Criterion, chain: Option<Chain>, backend: Backend) -> Self {
        Self {
            criterion,
            risk: DEFAULT_RISK,
            escape: chain.map(|chain| EscapeSettings {
                chain,
                string: None,
                samples: RECORD_ESCAPE_SAMPLES,
                min_probability: RECORD_ESCAPE_MIN_PROBABILITY,
                backend,
            }),
        }
    }

    /// The adviser whose simulated strings are each sample's own where `string` is set (a
    /// posterior that inferred the string with the law).
    pub fn with_sample_strings(mut self, string: Option<InferredString>) -> Self {
        if let Some(escape) = &mut self.escape {
            escape.string = string;
        }
        self
    }

    /// The advice at the record's own operating point ([`record_point`]), from what its bit
    /// was seen doing.
    pub fn advise_record(&self, inputs: &[LawSamples], w_ref_n: f64, seen: &BitSeen) -> Advice {
        self.advise(inputs, w_ref_n, record_point(seen, w_ref_n), Some((seen, "record")))
    }
}
