//! The 1-DOF string driven on a surface record's clock, and the summaries of its surface
//! torque that simulation-based ABC compares with a rig's.
//!
//! **The drive.** The top drive turns at the record's Ω(t) and the bit carries the record's
//! weight ratio r(t), each sample's values held until the next sample. The string starts at
//! rest with the bit stuck (going on bottom), runs `settle_s` at the first sample's Ω and r so
//! that a limit cycle, where the law has one, is reached, and is then sampled on the record's
//! clock: its surface torque (what the rig measures) and its bit speed (what the rig does not).
//!
//! **The summaries** ([`SUMMARY_NAMES`]) are the stick-slip cycle seen from the surface, each
//! blind to the cycle's phase and, where it can be, to white noise: the torque's mean, its
//! signal's spread √γ(1) (the autocovariance one sample apart, which holds no white noise), its
//! quantiles, the share of samples at which it rises (the bit sticks while the string winds
//! up: the rise share tracks the stuck share), its autocovariance at 2, 4 and 6 s relative to
//! γ(1), the cycle's period (the first peak of the autocorrelation past its first zero,
//! refined by a parabola; 0 where there is none), its time asymmetry over 1 and 2 s (a
//! slow wind-up and a fast release) and its wind-up rate (the string's k·Ω while the bit is
//! held, less while it creeps). Where the rig also streams an MWD tool's downhole minimum or
//! maximum bit speed ([`DownholeExtremes`]), their summaries follow ([`downhole_summaries`]):
//! the surface tells a bit held still from one that creeps only by the wind-up rate, and only
//! where the string's stiffness is known; the minimum tells it outright.

use super::strings::{Chain, LANES, MAX_NODES, STUCK_SPEED_RAD_S, Steppers, StringJob, StringState, in_lanes, padded};
use crate::data::surface::SurfaceRecord;
use crate::laws::Law;
use crate::units::RAD_S_PER_RPM;

/// A record's drive of the string: top-drive speed and weight ratio per sample on a regular
/// clock.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Drive {
    /// Ω per sample (rad/s).
    pub omega_rad_s: Vec<f64>,
    /// r = W/W_ref per sample.
    pub ratio: Vec<f64>,
    /// The clock's period (s).
    pub period_s: f64,
}

/// How finely and after how long a settling the string is sampled.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Integration {
    /// Largest integration step (s): each sample period is split into equal steps no longer.
    pub dt_s: f64,
    /// Time simulated at the first sample's drive before the first sample (s).
    pub settle_s: f64,
}

impl Default for Integration {
    /// 20 ms steps (the stuck share of the paper's string is the same to three decimals from
    /// 1 ms to 20 ms, the events being located within the step) after 60 s, about six cycles of
    /// the paper's string.
    fn default() -> Self {
        Self {
            dt_s: 0.02,
            settle_s: 60.0,
        }
    }
}

/// A string sampled on a record's clock.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct OnClock {
    /// Surface torque per sample (N·m), noise-free.
    pub surface_torque_nm: Vec<f64>,
    /// Bit speed per sample (rad/s).
    pub bit_speed_rad_s: Vec<f64>,
    /// Per sample, the bit speed's least and greatest (rad/s) over the integration steps
    /// since the sample before, the sample's own included (the first sample's: its own): what
    /// an MWD tool's downhole minimum and maximum are taken from ([`DownholeExtremes`]).
    pub bit_least_rad_s: Vec<f64>,
    pub bit_greatest_rad_s: Vec<f64>,
    /// The motion left physical bounds (a law whose torque turns negative at speed): the
    /// samples stop there and mean nothing.
    pub diverged: bool,
}

/// One string of a batch on a record's clock: its law, parameters (N·m) and 1-DOF string.
#[derive(Clone, Copy, Debug)]
pub struct OnClockJob<'a> {
    pub law: Law,
    pub params_nm: &'a [f64],
    pub chain: &'a Chain,
}

/// The string `chain` (1-DOF) with `law` at the bit (parameters in N·m) driven by `drive`.
pub fn simulate_on_clock(
    chain: &Chain,
    drive: &Drive,
    law: Law,
    params_nm: &[f64],
    integration: Integration,
) -> OnClock {
    let [out] = on_clock_lanes([&OnClockJob { law, params_nm, chain }], drive, integration);
    out
}

/// Every string of `jobs` driven by `drive`, in order, on the CPU: [`LANES`] at a time
/// ([`in_lanes`]), each string's samples the same to the bit as [`simulate_on_clock`]'s.
pub fn simulate_on_clock_many(jobs: &[OnClockJob<'_>], drive: &Drive, integration: Integration) -> Vec<OnClock> {
    in_lanes(
        jobs,
        |job| job.law,
        |lanes| {
            #[cfg(target_arch = "x86_64")]
            if std::arch::is_x86_feature_detected!("avx2") {
                // SAFETY: the CPU supports AVX2, checked just above.
                return unsafe { on_clock_lanes_avx2(lanes, drive, integration) };
            }
            on_clock_lanes(lanes, drive, integration)
        },
    )
}

/// [`on_clock_lanes`] in AVX2's registers (the same operations: the same bits).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn on_clock_lanes_avx2(jobs: [&OnClockJob<'_>; LANES], drive: &Drive, integration: Integration) -> [OnClock; LANES] {
    on_clock_lanes(jobs, drive, integration)
}

/// The strings of `jobs` (one law) driven by `drive` together, lane by lane.
#[allow(clippy::needless_range_loop)]
#[inline(always)]
fn on_clock_lanes<const L: usize>(jobs: [&OnClockJob<'_>; L], drive: &Drive, integration: Integration) -> [OnClock; L] {
    let n = drive.omega_rad_s.len();
    let mut out: [OnClock; L] = std::array::from_fn(|_| OnClock {
        surface_torque_nm: Vec::with_capacity(n),
        bit_speed_rad_s: Vec::with_capacity(n),
        bit_least_rad_s: Vec::with_capacity(n),
        bit_greatest_rad_s: Vec::with_capacity(n),
        diverged: false,
    });
    if n == 0 {
        return out;
    }
    let rest = StringState {
        lag_rad: [0.0; MAX_NODES],
        speed_rad_s: [0.0; MAX_NODES],
        stuck: true,
    };
    let string_jobs = jobs.map(|job| StringJob {
        law: job.law,
        params_nm: padded(job.params_nm),
        omega_rad_s: drive.omega_rad_s[0],
        ratio: drive.ratio[0],
        start: rest,
    });
    let mut strings = Steppers::new(jobs.map(|job| job.chain), string_jobs.each_ref());
    // Each bit speed's extremes since the sample before (the first sample's: its own).
    let mut extremes = [Extremes::default(); L];
    if integration.settle_s > 0.0 {
        advance(
            &mut strings,
            integration,
            integration.settle_s,
            &mut [Extremes::default(); L],
            &mut out,
        );
    }
    for k in 0..n {
        if out.iter().all(|o| o.diverged) {
            break;
        }
        if k > 0 {
            strings.set_operating_point(drive.omega_rad_s[k - 1], drive.ratio[k - 1]);
            advance(&mut strings, integration, drive.period_s, &mut extremes, &mut out);
        }
        let (speeds, torques) = (strings.bit_speeds_rad_s(), strings.surface_torques_nm());
        for l in 0..L {
            if out[l].diverged {
                continue;
            }
            extremes[l].see(speeds[l]);
            out[l].surface_torque_nm.push(torques[l]);
            out[l].bit_speed_rad_s.push(speeds[l]);
            out[l].bit_least_rad_s.push(extremes[l].least);
            out[l].bit_greatest_rad_s.push(extremes[l].greatest);
            extremes[l] = Extremes::default();
        }
    }
    out
}

/// Advances every string by `span_s` (s), in equal steps no longer than the integration's,
/// each bit speed's extremes seen at every step; a string that leaves physical bounds is done.
#[allow(clippy::needless_range_loop)]
#[inline(always)]
fn advance<const L: usize>(
    strings: &mut Steppers<L>,
    integration: Integration,
    span_s: f64,
    extremes: &mut [Extremes; L],
    out: &mut [OnClock; L],
) {
    let steps = (span_s / integration.dt_s).ceil().max(1.0);
    let h = span_s / steps;
    for _ in 0..steps as u64 {
        strings.step(h);
        let speeds = strings.bit_speeds_rad_s();
        for l in 0..L {
            extremes[l].see(speeds[l]);
        }
    }
    for (l, inside) in strings.in_bounds().into_iter().enumerate() {
        if !inside && !out[l].diverged {
            out[l].diverged = true;
            strings.stop(l);
        }
    }
}

/// The least and greatest of the values seen.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Extremes {
    pub(crate) least: f64,
    pub(crate) greatest: f64,
}

impl Default for Extremes {
    fn default() -> Self {
        Self {
            least: f64::INFINITY,
            greatest: f64::NEG_INFINITY,
        }
    }
}

impl Extremes {
    pub(crate) fn see(&mut self, value: f64) {
        self.least = self.least.min(value);
        self.greatest = self.greatest.max(value);
    }
}

/// What an MWD tool streams of the bit's stick-slip, as a surface record carries it: the bit
/// speed's minimum and maximum (either or both) over a window of whole samples ending at each
/// sample. The tool takes them from its own fast sampling; a string takes them from its
/// integration steps ([`OnClock::bit_least_rad_s`]).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct DownholeExtremes {
    /// The window, in samples of the record's clock (1: since the sample before).
    pub window_samples: usize,
    /// The record holds the minimum, the maximum.
    pub least: bool,
    pub greatest: bool,
}

impl DownholeExtremes {
    /// The MWD channels `record` holds, if any.
    pub fn of(record: &SurfaceRecord) -> Option<Self> {
        record.downhole.as_ref().map(|d| Self {
            window_samples: d.window_samples,
            least: d.least_rad_s.is_some(),
            greatest: d.greatest_rad_s.is_some(),
        })
    }

    /// The summaries of `record`'s own downhole channels (zeros without them), from the
    /// sample its strings' are taken from ([`Self::first_whole`]).
    pub fn record_summaries(record: &SurfaceRecord) -> [f64; N_DOWNHOLE_SUMMARIES] {
        let (Some(d), Some(tool)) = (record.downhole.as_ref(), Self::of(record)) else {
            return [0.0; N_DOWNHOLE_SUMMARIES];
        };
        let from = tool.first_whole();
        downhole_summaries(
            d.least_rad_s.as_deref().map(|v| &v[from.min(v.len())..]),
            d.greatest_rad_s.as_deref().map(|v| &v[from.min(v.len())..]),
        )
    }

    /// The summaries of `run`'s bit as this tool would report it: its extremes over the
    /// window, summarised by [`downhole_summaries`] from the sample [`Self::first_whole`] on.
    pub fn summaries_of(&self, run: &OnClock) -> [f64; N_DOWNHOLE_SUMMARIES] {
        let m = self.window_samples;
        let least = self.least.then(|| windowed(&run.bit_least_rad_s, m, |a, b| a <= b));
        let greatest = self
            .greatest
            .then(|| windowed(&run.bit_greatest_rad_s, m, |a, b| a >= b));
        let from = self.first_whole();
        downhole_summaries(
            least.as_deref().map(|v| &v[from.min(v.len())..]),
            greatest.as_deref().map(|v| &v[from.min(v.len())..]),
        )
    }

    /// The first sample summarised: the tool's windows before it reach back before the record
    /// starts, a string's do not (its first sample is its own speed alone), so a record and
    /// its strings are both summarised from here.
    pub fn first_whole(&self) -> usize {
        self.window_samples.max(1)
    }

    /// Which of the [`N_SUMMARIES`] summaries a record with these channels compares: the
    /// surface torque's, and the downhole ones of the channels it holds.
    pub fn active(this: Option<&Self>) -> [bool; N_SUMMARIES] {
        let mut active = [false; N_SUMMARIES];
        active[..N_TORQUE_SUMMARIES].fill(true);
        if let Some(d) = this {
            active[DOWNHOLE_LEAST] = d.least;
            active[DOWNHOLE_LEAST + 1] = d.least;
            active[DOWNHOLE_GREATEST] = d.greatest;
            active[DOWNHOLE_GREATEST + 1] = d.greatest;
        }
        active
    }
}

/// Per sample k, the extreme of `per_sample` over the `window` samples ending at k (fewer at
/// the start), the extreme being what `beats` every other (`a <= b`: the least): a monotone
/// queue, O(n) whatever the window.
fn windowed(per_sample: &[f64], window: usize, beats: fn(f64, f64) -> bool) -> Vec<f64> {
    let window = window.max(1);
    let mut queue = std::collections::VecDeque::new();
    let mut out = Vec::with_capacity(per_sample.len());
    for (k, &value) in per_sample.iter().enumerate() {
        // A candidate the new value beats can never be the window's extreme again.
        while queue.back().is_some_and(|&j: &usize| beats(value, per_sample[j])) {
            queue.pop_back();
        }
        queue.push_back(k);
        if queue.front().is_some_and(|&j| j + window <= k) {
            queue.pop_front();
        }
        out.push(per_sample[*queue.front().expect("k was pushed")]);
    }
    out
}

/// The downhole summaries of a tool's minimum and maximum bit speed per sample (rad/s), where
/// the record holds them (0 where not): the minimum's mean and the share of samples at which
/// it is below [`STUCK_SPEED_RAD_S`] (the bit held, or turned back, at some moment of the
/// window: the stuck share where the bit is seen), the maximum's mean and 90 % quantile (the
/// slips' peaks). A
/// law that only slows the bit (no static torque) leaves it creeping at a few rpm, which the
/// surface torque cannot tell from a bit held still. Medians are left out: with the bit stuck
/// about half the time a median flips between 0 and a slip's speed.
pub fn downhole_summaries(least_rad_s: Option<&[f64]>, greatest_rad_s: Option<&[f64]>) -> [f64; N_DOWNHOLE_SUMMARIES] {
    let mean = |values: &[f64]| values.iter().sum::<f64>() / values.len().max(1) as f64;
    let mut out = [0.0; N_DOWNHOLE_SUMMARIES];
    if let Some(least) = least_rad_s {
        out[0] = mean(least);
        out[1] = least.iter().filter(|w| **w < STUCK_SPEED_RAD_S).count() as f64 / least.len().max(1) as f64;
    }
    if let Some(greatest) = greatest_rad_s.filter(|g| !g.is_empty()) {
        let mut sorted = greatest.to_vec();
        sorted.sort_by(f64::total_cmp);
        out[2] = mean(greatest);
        out[3] = crate::numerics::quantile_of_sorted(&sorted, 0.9);
    }
    out
}

/// The least a downhole summary's scale may be: the MWD's speeds compared to within 0.1 rpm
/// (a tool's resolution), the share to within one sample of `samples`; 0 for the surface
/// torque's summaries, whose scales never fall below what the noise moves them. Strings that
/// turn steadily all read the top drive's speed, equal to rounding: a scale of their spread
/// would be rounding.
pub fn least_scales(samples: usize) -> Summaries {
    let mut least = [0.0; N_SUMMARIES];
    let resolution = 0.1 * RAD_S_PER_RPM;
    least[DOWNHOLE_LEAST] = resolution;
    least[DOWNHOLE_LEAST + 1] = 1.0 / samples.max(1) as f64;
    least[DOWNHOLE_GREATEST] = resolution;
    least[DOWNHOLE_GREATEST + 1] = resolution;
    least
}

/// How many summaries a surface torque record is reduced to.
pub const N_TORQUE_SUMMARIES: usize = 16;
/// How many summaries an MWD tool's downhole extremes add ([`downhole_summaries`]).
pub const N_DOWNHOLE_SUMMARIES: usize = 4;
/// Every summary a surface record may have: the torque's, then the downhole extremes'.
pub const N_SUMMARIES: usize = N_TORQUE_SUMMARIES + N_DOWNHOLE_SUMMARIES;
/// Where the downhole minimum's and maximum's summaries start.
const DOWNHOLE_LEAST: usize = N_TORQUE_SUMMARIES;
const DOWNHOLE_GREATEST: usize = N_TORQUE_SUMMARIES + 2;

/// Where the mean torque, the cycle's period and its autocorrelation stand among the summaries.
pub const MEAN: usize = 0;
pub const PERIOD: usize = 11;
pub const PERIOD_STRENGTH: usize = 12;

/// A record's summaries, in the order of [`SUMMARY_NAMES`].
pub type Summaries = [f64; N_SUMMARIES];

/// The summaries' names, in order (torques in N·m, times in s).
pub const SUMMARY_NAMES: [&str; N_SUMMARIES] = [
    "mean_nm",
    "signal_sd_nm",
    "q05_nm",
    "q25_nm",
    "q50_nm",
    "q75_nm",
    "q95_nm",
    "rise_share",
    "acf_2s",
    "acf_4s",
    "acf_6s",
    "period_s",
    "period_strength",
    "asymmetry_1s",
    "asymmetry_2s",
    "wind_up_nm_s",
    "downhole_min_mean_rad_s",
    "downhole_held_share",
    "downhole_max_mean_rad_s",
    "downhole_max_q90_rad_s",
];

/// The summaries of a surface torque record (N·m) sampled every `period_s` (see the module
/// documentation), then the `downhole` ones ([`downhole_summaries`]; zeros for a record
/// without downhole channels).
pub fn summaries(torque_nm: &[f64], period_s: f64, downhole: &[f64; N_DOWNHOLE_SUMMARIES]) -> Summaries {
    let n = torque_nm.len();
    let mean = torque_nm.iter().sum::<f64>() / n.max(1) as f64;
    let centred: Vec<f64> = torque_nm.iter().map(|y| y - mean).collect();
    let acf = Autocorrelation::of(&centred);
    let mut sorted = torque_nm.to_vec();
    sorted.sort_by(f64::total_cmp);
    let q = |p: f64| crate::numerics::quantile_of_sorted(&sorted, p);
    let rises = torque_nm.windows(2).filter(|w| w[1] > w[0]).count();
    let lag_of = |t: f64| ((t / period_s).round() as usize).max(1);
    // Autocovariances past lag 0 hold no white noise: the signal's spread and correlations
    // are read from them, relative to lag 1.
    let signal = acf.covariance(1).max(0.0);
    let relative = |t: f64| {
        if signal > 0.0 {
            acf.covariance(lag_of(t)) / signal
        } else {
            0.0
        }
    };
    let (cycle_s, strength) = cycle(&centred, period_s);
    [
        mean,
        signal.sqrt(),
        q(0.05),
        q(0.25),
        q(0.5),
        q(0.75),
        q(0.95),
        rises as f64 / (n.max(2) - 1) as f64,
        relative(2.0),
        relative(4.0),
        relative(6.0),
        cycle_s,
        strength,
        asymmetry(torque_nm, lag_of(1.0), signal),
        asymmetry(torque_nm, lag_of(2.0), signal),
        wind_up(torque_nm, period_s),
        downhole[0],
        downhole[1],
        downhole[2],
        downhole[3],
    ]
}

/// The time asymmetry of a record over `lag` samples: the mean cubed change over the lag, over
/// the signal's variance `signal` to the power 3/2. A slow rise and a fast drop (the string
/// winding up while the bit is stuck, unwinding as it slips) make it negative; white noise
/// adds nothing to it in expectation (its odd moments vanish, and the record's mean change is
/// nil over a stationary record).
fn asymmetry(torque_nm: &[f64], lag: usize, signal: f64) -> f64 {
    if signal <= 0.0 || torque_nm.len() <= lag {
        return 0.0;
    }
    let changes = &torque_nm[lag..];
    let cubes: f64 = changes.iter().zip(torque_nm).map(|(b, a)| (b - a).powi(3)).sum();
    cubes / changes.len() as f64 / signal.powf(1.5)
}

/// The time base the wind-up rate is read on (s): a finer clock is averaged in blocks of it,
/// so that a block's rise on a wind-up stands above the noise.
const WIND_UP_BLOCK_S: f64 = 1.0;

/// The rate (N·m/s) at which the torque climbs while the string winds up: the median change
/// from one block of [`WIND_UP_BLOCK_S`] to the next, over the changes picked as on a
/// wind-up by blocks that do not hold either end of the change (0 where none is): the change
/// two blocks before and the one two after rise, and so does the torque from three blocks
/// before to four after (which leaves out a slip's short drop between rising stretches). The
/// change's own noise plays no part in picking it, so on a straight wind-up white noise
/// spreads the picks without moving their median, as a pick by the change's own sign would.
/// A bit held still lets the string wind up at k·Ω; a bit that creeps (m1: no static torque)
/// slows it, more as the torque climbs. Where the string is known, this tells a law that holds
/// the bit from one that only slows it, which the cycle's shape barely does.
fn wind_up(torque_nm: &[f64], period_s: f64) -> f64 {
    let block = ((WIND_UP_BLOCK_S / period_s).round() as usize).max(1);
    let means: Vec<f64> = torque_nm
        .chunks_exact(block)
        .map(|c| c.iter().sum::<f64>() / block as f64)
        .collect();
    // b[3] to b[4] is the change; the others pick it.
    let mut picked: Vec<f64> = means
        .windows(8)
        .filter(|b| b[2] > b[1] && b[6] > b[5] && b[7] > b[0])
        .map(|b| b[4] - b[3])
        .collect();
    if picked.is_empty() {
        return 0.0;
    }
    picked.sort_by(f64::total_cmp);
    crate::numerics::quantile_of_sorted(&picked, 0.5) / (block as f64 * period_s)
}

/// The resolution the cycle's period is sought at (s): a finer clock is averaged in blocks to it.
const CYCLE_RESOLUTION_S: f64 = 0.25;
/// The longest cycle sought (s): torsional stick-slip cycles last seconds to tens of seconds.
pub const MAX_CYCLE_S: f64 = 120.0;

/// The cycle's period (s) and the autocorrelation there, (0, 0) where none is seen: sought on
/// block means at [`CYCLE_RESOLUTION_S`] up to [`MAX_CYCLE_S`] (the search costs the record's
/// length times the lags).
fn cycle(centred: &[f64], period_s: f64) -> (f64, f64) {
    let block = ((CYCLE_RESOLUTION_S / period_s).round() as usize).max(1);
    let means: Vec<f64> = centred
        .chunks_exact(block)
        .map(|c| c.iter().sum::<f64>() / block as f64)
        .collect();
    let block_s = block as f64 * period_s;
    let longest = (MAX_CYCLE_S / block_s) as usize;
    Autocorrelation::of(&means)
        .first_peak(longest)
        .map_or((0.0, 0.0), |(lags, strength)| (lags * block_s, strength))
}

/// The standard deviation of white noise on a smooth record (N·m): the record's variance less
/// its signal's, the signal's autocovariance at lag 0 extrapolated from lags 1 to 3 by its
/// even Taylor series, γ_s(0) ≈ (15γ(1) − 6γ(2) + γ(3))/10 (exact for an autocovariance
/// a + bh² + ch⁴ over three samples). A string's torque is smooth between samples a cycle's
/// twentieth or less apart; on a coarser clock the estimate carries part of the signal.
pub fn noise_sd(torque_nm: &[f64]) -> f64 {
    noise_variance_raw(torque_nm).max(0.0).sqrt()
}

/// Fewest picks [`wind_up_noise_sd`] reads the noise from.
pub const WIND_UP_NOISE_LEAST: usize = 30;

/// The standard deviation of white noise read on the record's wind-ups (N·m), None where fewer
/// than [`WIND_UP_NOISE_LEAST`] samples are picked: the root mean square of the second
/// differences τ(i+1) − 2τ(i) + τ(i−1) over √6, at the samples picked as on a wind-up by
/// samples that are not among the three (the torque rising from i−3 to i−2 and from i+2 to
/// i+3, and from i−4 to i+4). While the bit is held the string winds up at a constant rate,
/// so there the second differences are the noise's alone, however coarse the clock; a curved
/// or broken stretch picked adds to them, so the estimate is an upper bound in expectation,
/// tight where the bit is held. On the paper's string at 1 Hz it reads 0.17-0.23 kN·m for
/// 0.2 where [`noise_sd`] reads 0.42-0.48.
pub fn wind_up_noise_sd(torque_nm: &[f64]) -> Option<f64> {
    let (sum, picks) = torque_nm
        .windows(9)
        .filter(|t| t[2] > t[1] && t[7] > t[6] && t[8] > t[0])
        .fold((0.0, 0usize), |(sum, picks), t| {
            let second = t[5] - 2.0 * t[4] + t[3];
            (sum + second * second, picks + 1)
        });
    (picks >= WIND_UP_NOISE_LEAST).then(|| (sum / picks as f64 / 6.0).sqrt())
}

/// The variance [`noise_sd`] squares, before it is floored at 0 ((N·m)²): linear in the
/// record's autocovariances, so that for a signal plus independent noise it is the signal's
/// part plus the noise's variance.
pub fn noise_variance_raw(torque_nm: &[f64]) -> f64 {
    let n = torque_nm.len();
    if n < 5 {
        return 0.0;
    }
    let mean = torque_nm.iter().sum::<f64>() / n as f64;
    let centred: Vec<f64> = torque_nm.iter().map(|y| y - mean).collect();
    let gamma = |lag: usize| centred.iter().zip(&centred[lag..]).map(|(a, b)| a * b).sum::<f64>() / (n - lag) as f64;
    let signal = (15.0 * gamma(1) - 6.0 * gamma(2) + gamma(3)) / 10.0;
    gamma(0) - signal
}

/// The sample autocorrelation of a centred record.
struct Autocorrelation<'a> {
    centred: &'a [f64],
    /// Variance (divisor n).
    variance: f64,
}

impl<'a> Autocorrelation<'a> {
    fn of(centred: &'a [f64]) -> Self {
        let n = centred.len().max(1) as f64;
        Self {
            centred,
            variance: centred.iter().map(|y| y * y).sum::<f64>() / n,
        }
    }

    /// γ(lag) (divisor n, the usual biased estimate that keeps the sequence positive
    /// definite); 0 for a lag past half of the record.
    fn covariance(&self, lag: usize) -> f64 {
        let n = self.centred.len();
        if lag >= n / 2 {
            return 0.0;
        }
        let sum: f64 = self.centred.iter().zip(&self.centred[lag..]).map(|(a, b)| a * b).sum();
        sum / n as f64
    }

    /// ρ(lag) = γ(lag)/γ(0); 0 for a constant record.
    fn at(&self, lag: usize) -> f64 {
        if self.variance <= 0.0 {
            return 0.0;
        }
        self.covariance(lag) / self.variance
    }

    /// The first peak past the first zero crossing within a third of the record and `longest`
    /// lags: its lag (samples, refined by the parabola through the peak and its neighbours) and
    /// height.
    fn first_peak(&self, longest: usize) -> Option<(f64, f64)> {
        let last = (self.centred.len() / 3).min(longest);
        if last < 2 {
            return None;
        }
        let values: Vec<f64> = (0..=last + 1).map(|lag| self.at(lag)).collect();
        let zero = values.iter().position(|&v| v < 0.0)?;
        let peak = (zero.max(1)..last)
            .find(|&k| values[k] > 0.0 && values[k] >= values[k - 1] && values[k] > values[k + 1])?;
        let (a, b, c) = (values[peak - 1], values[peak], values[peak + 1]);
        let curvature = a - 2.0 * b + c;
        let shift = if curvature < 0.0 {
            0.5 * (a - c) / curvature
        } else {
            0.0
        };
        Some((peak as f64 + shift.clamp(-0.5, 0.5), b))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stability::lumped::Lumped;

    /// `clean` with white Gaussian noise of `sd` added, drawn as the simulations' is (Philox).
    fn with_noise(clean: &[f64], sd: f64, seed: u64) -> Vec<f64> {
        let mut noisy = clean.to_vec();
        crate::eval::surface::add_noise(&mut noisy, sd, crate::eval::surface::NoiseKey(seed));
        noisy
    }

    #[test]
    fn a_sawtooth_s_summaries_are_its_closed_forms() {
        // Rises for 8 samples, falls in 2: a 10-sample cycle at 1 Hz, 100 cycles.
        let torque: Vec<f64> = (0..1000)
            .map(|k| {
                let phase = k % 10;
                if phase < 8 {
                    phase as f64
                } else {
                    8.0 * (10 - phase) as f64 / 2.0
                }
            })
            .collect();
        let s = summaries(&torque, 1.0, &[0.0; N_DOWNHOLE_SUMMARIES]);
        let mean = torque.iter().sum::<f64>() / 1000.0;
        assert!((s[0] - mean).abs() < 1e-12);
        // 8 rises in each 10 differences (the last difference of the record is a rise too).
        assert!((s[7] - 800.0 / 999.0).abs() < 1e-12, "{}", s[7]);
        assert!((s[11] - 10.0).abs() < 1e-9, "period {}", s[11]);
        assert!(s[12] > 0.9, "strength {}", s[12]);
        assert!((s[4] - 4.0).abs() < 1e-12, "median {}", s[4]);
        // Eight rises of 1 and two drops of 4 per cycle: cubes 8 − 128 per whole cycle, 99 of
        // them and the last cycle's eight rises and first drop (8 − 64) over 999 changes.
        let centred: Vec<f64> = torque.iter().map(|y| y - mean).collect();
        let gamma1 = centred.iter().zip(&centred[1..]).map(|(a, b)| a * b).sum::<f64>() / 1000.0;
        assert!((s[1] - gamma1.sqrt()).abs() < 1e-12);
        let expected = (99.0 * (8.0 - 128.0) + (8.0 - 64.0)) / 999.0 / gamma1.powf(1.5);
        assert!((s[13] - expected).abs() < 1e-9 * expected.abs(), "{} {expected}", s[13]);
    }

    #[test]
    fn the_wind_up_rate_is_a_sawtooth_s_rise_whatever_the_noise_and_clock() {
        // Rises by 1 N·m/s for 8 s, drops in 2 s: the slips' drops are not picked, and white
        // noise of half the rise per second pulls the median neither down (as the drops would:
        // to about 0.5) nor up (as a pick by the change's own sign would).
        let saw = |t: f64| {
            let phase = t.rem_euclid(10.0);
            if phase < 8.0 { phase } else { 4.0 * (10.0 - phase) }
        };
        for (period_s, sd) in [(1.0, 0.0), (1.0, 0.5), (0.05, 0.0), (0.05, 2.0)] {
            let n = (20_000.0 / period_s) as usize;
            let clean: Vec<f64> = (0..n).map(|k| saw(k as f64 * period_s)).collect();
            let torque = with_noise(&clean, sd, 7);
            let rate = wind_up(&torque, period_s);
            // About 8,000 picks: the median's standard error is 0.01 at the noisier clocks.
            assert!((rate - 1.0).abs() < 0.03, "every {period_s} s, noise {sd}: {rate}");
        }
        // A flat record has no wind-up; a steady rise is all wind-up, at its slope.
        assert!(wind_up(&[3.0; 100], 1.0).abs() < f64::MIN_POSITIVE, "no pick: 0");
        let ramp: Vec<f64> = (0..100).map(|k| 2.5 * k as f64).collect();
        assert!((wind_up(&ramp, 0.5) - 5.0).abs() < 1e-12);
    }

    #[test]
    fn the_noise_is_read_on_the_wind_ups_however_coarse_the_clock() {
        // A 10-s sawtooth at 1 Hz (8 samples a wind-up): the smooth estimate takes the drops
        // for noise, the wind-ups' second differences do not.
        let saw = |k: usize| {
            let phase = (k % 10) as f64;
            if phase < 8.0 {
                1000.0 * phase
            } else {
                4000.0 * (10.0 - phase)
            }
        };
        let clean: Vec<f64> = (0..600).map(saw).collect();
        assert!(wind_up_noise_sd(&clean).unwrap() < 1e-9);
        let noisy = with_noise(&clean, 200.0, 11);
        let read = wind_up_noise_sd(&noisy).unwrap();
        assert!((read - 200.0).abs() < 30.0, "{read}");
        assert!(noise_sd(&noisy) > 2.0 * read, "{}", noise_sd(&noisy));
        // White noise alone is picked at random and read whole.
        let white = with_noise(&[0.0; 6000], 200.0, 12);
        let read = wind_up_noise_sd(&white).unwrap();
        assert!((read - 200.0).abs() < 10.0, "{read}");
        // Too short a record to pick from says so.
        assert_eq!(wind_up_noise_sd(&noisy[..30]), None);
    }

    #[test]
    fn white_noise_on_a_smooth_record_is_measured() {
        // A 10-s sine at 20 Hz with noise of 0.3: the estimate within 5 %.
        let sine: Vec<f64> = (0..20_000)
            .map(|k| 5.0 * (std::f64::consts::TAU * k as f64 / 200.0).sin())
            .collect();
        let torque = with_noise(&sine, 0.3, 1);
        let sd = noise_sd(&torque);
        assert!((sd - 0.3).abs() < 0.015, "{sd}");
        let smooth: Vec<f64> = (0..20_000).map(|k| (k as f64 / 200.0).sin()).collect();
        assert!(noise_sd(&smooth) < 1e-3, "{}", noise_sd(&smooth));
    }

    #[test]
    fn the_string_on_a_clock_carries_the_bit_s_mean_torque_to_the_surface() {
        // m2 at 60 rpm stick-slips: over whole cycles the string's torque at the top and at
        // the bit have the same mean (the bit's inertia stores no torque over a cycle); the
        // mean is then r·T averaged over the cycle, between the law at rest and at speed.
        let law = Law::M2;
        let params = law.scale_torque(law.paper_estimate().unwrap(), 1000.0);
        let chain = Chain::one_dof(&Lumped::default());
        let omega = 60.0 * RAD_S_PER_RPM;
        let drive = Drive {
            omega_rad_s: vec![omega; 600],
            ratio: vec![1.0; 600],
            period_s: 1.0,
        };
        let run = simulate_on_clock(&chain, &drive, law, &params, Integration::default());
        assert!(!run.diverged && run.surface_torque_nm.len() == 600);
        let stuck = run
            .bit_speed_rad_s
            .iter()
            .filter(|w| w.abs() < crate::simulate::strings::STUCK_SPEED_RAD_S)
            .count() as f64
            / 600.0;
        assert!((stuck - 0.475).abs() < 0.03, "stuck share {stuck}");
        let s = summaries(&run.surface_torque_nm, 1.0, &[0.0; N_DOWNHOLE_SUMMARIES]);
        // The cycle of the paper's string at 60 rpm: 9.7-9.8 s (measured at 10 Hz).
        assert!((s[11] - 9.75).abs() < 0.3, "period {}", s[11]);
        let static_nm = law.torque(&params, 0.0, 1.0);
        let at_speed = law.torque(&params, omega, 1.0);
        assert!(
            s[0] > at_speed && s[0] < static_nm,
            "{} in ({at_speed}, {static_nm})",
            s[0]
        );
        // More rises than falls: the string winds up slowly while the bit is stuck.
        assert!(s[7] > 0.5, "rise share {}", s[7]);
    }

    #[test]
    fn strings_simulated_together_are_each_the_string_simulated_alone() {
        // Eleven strings of three laws on strings of their own stiffness and damping, under a
        // drive that steps from 60 to 120 rpm; one (m4 turning negative at speed) runs away.
        // Simulated together, each gives to the bit what it gives alone.
        let omega = 60.0 * RAD_S_PER_RPM;
        let drive = Drive {
            omega_rad_s: (0..60).map(|k| if k < 30 { omega } else { 2.0 * omega }).collect(),
            ratio: vec![1.0; 60],
            period_s: 1.0,
        };
        let chains: Vec<Chain> = (0..11)
            .map(|k| {
                Chain::one_dof(&Lumped {
                    omega_n_rad_s: 0.6 + 0.1 * k as f64,
                    damping_ratio: 0.05 + 0.02 * k as f64,
                    ..Lumped::default()
                })
            })
            .collect();
        let paper = |law: Law| law.scale_torque(law.paper_estimate().unwrap(), 1000.0);
        let runaway = vec![5000.0, 0.0, 0.0, -2000.0];
        let params: Vec<(Law, Vec<f64>)> = (0..11)
            .map(|k| match k {
                3 => (Law::M4, runaway.clone()),
                k if k % 3 == 0 => (Law::M3, paper(Law::M3)),
                _ => (
                    Law::M2,
                    paper(Law::M2).iter().map(|p| p * (0.8 + 0.05 * k as f64)).collect(),
                ),
            })
            .collect();
        let jobs: Vec<OnClockJob<'_>> = params
            .iter()
            .zip(&chains)
            .map(|((law, p), chain)| OnClockJob {
                law: *law,
                params_nm: p,
                chain,
            })
            .collect();
        let together = simulate_on_clock_many(&jobs, &drive, Integration::default());
        for (k, (job, run)) in jobs.iter().zip(&together).enumerate() {
            let alone = simulate_on_clock(job.chain, &drive, job.law, job.params_nm, Integration::default());
            assert_eq!(format!("{run:?}"), format!("{alone:?}"), "string {k}");
        }
        let diverged: Vec<bool> = together.iter().map(|r| r.diverged).collect();
        assert_eq!(diverged.iter().filter(|&&d| d).count(), 1, "{diverged:?}");
        assert!(diverged[3]);
    }

    #[test]
    fn a_string_s_downhole_extremes_are_those_of_its_every_step() {
        // The same string on a clock of one step (20 ms) and on one of fifty (1 s): the same
        // steps, so each coarse sample's least and greatest bit speed are those of the fine
        // samples since the coarse sample before, to the bit. m2 sticks (least 0), m1 creeps.
        let chain = Chain::one_dof(&Lumped::default());
        let omega = 60.0 * RAD_S_PER_RPM;
        let on = |law: Law, period_s: f64, n: usize| {
            let params = law.scale_torque(law.paper_estimate().unwrap(), 1000.0);
            let drive = Drive {
                omega_rad_s: vec![omega; n],
                ratio: vec![1.0; n],
                period_s,
            };
            simulate_on_clock(&chain, &drive, law, &params, Integration::default())
        };
        for law in [Law::M1, Law::M2] {
            let coarse = on(law, 1.0, 40);
            let fine = on(law, 0.02, 39 * 50 + 1);
            assert_eq!(coarse.bit_speed_rad_s[0].to_bits(), fine.bit_speed_rad_s[0].to_bits());
            assert_eq!(coarse.bit_least_rad_s[0].to_bits(), coarse.bit_speed_rad_s[0].to_bits());
            for k in 1..40 {
                let since = &fine.bit_speed_rad_s[50 * (k - 1) + 1..=50 * k];
                let least = since.iter().copied().fold(f64::INFINITY, f64::min);
                let greatest = since.iter().copied().fold(f64::NEG_INFINITY, f64::max);
                assert_eq!(coarse.bit_least_rad_s[k].to_bits(), least.to_bits(), "{law} sample {k}");
                assert_eq!(
                    coarse.bit_greatest_rad_s[k].to_bits(),
                    greatest.to_bits(),
                    "{law} sample {k}"
                );
            }
            let least = coarse.bit_least_rad_s.iter().copied().fold(f64::INFINITY, f64::min);
            match law {
                Law::M2 => assert!(least.abs() < 1e-12, "m2 holds its bit: least {least}"),
                _ => assert!(least > 0.5 * RAD_S_PER_RPM, "m1 lets its bit creep: least {least}"),
            }
            // Over a window of 3 samples the tool reads the extremes of the last three.
            let tool = DownholeExtremes {
                window_samples: 3,
                least: true,
                greatest: true,
            };
            let windowed: Vec<f64> = (0..40)
                .map(|k| {
                    coarse.bit_least_rad_s[k.max(2) - 2..=k]
                        .iter()
                        .copied()
                        .fold(f64::INFINITY, f64::min)
                })
                .collect();
            let greatest: Vec<f64> = (0..40)
                .map(|k| {
                    coarse.bit_greatest_rad_s[k.max(2) - 2..=k]
                        .iter()
                        .copied()
                        .fold(f64::NEG_INFINITY, f64::max)
                })
                .collect();
            assert_eq!(
                tool.summaries_of(&coarse).map(f64::to_bits),
                downhole_summaries(Some(&windowed[3..]), Some(&greatest[3..])).map(f64::to_bits)
            );
        }
    }

    #[test]
    fn a_window_s_extremes_by_the_monotone_queue_are_the_brute_force_ones() {
        // Values from a small set (ties) drawn from Philox, windows of 1 to 9 samples.
        let values: Vec<f64> = (0..300u32)
            .map(|i| f64::from(crate::rng::philox4x32_10([i, 0, 0, 0], [7, 7])[0] % 7) - 2.0)
            .collect();
        for window in 1..10 {
            let least = windowed(&values, window, |a, b| a <= b);
            let greatest = windowed(&values, window, |a, b| a >= b);
            for k in 0..values.len() {
                let span = &values[(k + 1).saturating_sub(window)..=k];
                let bits = |v: f64| v.to_bits();
                assert_eq!(bits(least[k]), bits(span.iter().copied().fold(f64::INFINITY, f64::min)));
                assert_eq!(
                    bits(greatest[k]),
                    bits(span.iter().copied().fold(f64::NEG_INFINITY, f64::max))
                );
            }
        }
    }

    #[test]
    fn downhole_summaries_are_the_channels_means_held_share_and_peaks() {
        // Two of four minima below 1 rpm (0.1 rad/s): held half the time.
        // A minimum below 0 (the bit turned back) is held too.
        let least = [-0.0625, 0.0625, 3.0, 1.0];
        let greatest: Vec<f64> = (1..=11).map(|k| 10.0 * k as f64).collect();
        let bits = |s: [f64; N_DOWNHOLE_SUMMARIES]| s.map(f64::to_bits);
        // The 90 % quantile of 10, 20, …, 110 (linear between order statistics): 100.
        assert_eq!(
            bits(downhole_summaries(Some(&least), Some(&greatest))),
            bits([1.0, 0.5, 60.0, 100.0])
        );
        assert_eq!(
            bits(downhole_summaries(None, Some(&greatest))),
            bits([0.0, 0.0, 60.0, 100.0])
        );
        let active = DownholeExtremes::active(Some(&DownholeExtremes {
            window_samples: 1,
            least: true,
            greatest: false,
        }));
        assert_eq!(active.iter().filter(|a| **a).count(), N_TORQUE_SUMMARIES + 2);
        assert!(active[N_TORQUE_SUMMARIES] && !active[N_SUMMARIES - 1]);
        assert_eq!(
            DownholeExtremes::active(None).iter().filter(|a| **a).count(),
            N_TORQUE_SUMMARIES
        );
    }
}
