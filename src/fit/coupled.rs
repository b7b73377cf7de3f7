//! The coupled bit (RGD) calibrated from a drilling record. While a blade cuts, the bit's weight
//! and torque are linear in the depth of cut per revolution d = 2π·ROP/Ω:
//!
//! ```text
//! W = a·ζ·ε·d + W_f,      T = ½·a²·ε·d + ½·a·μ·γ·W_f
//! ```
//!
//! so two straight lines through the cutting samples give every combination of the bit's
//! parameters that acts: ε from the torque line's slope (the radius known), ζ from the two
//! slopes, the wear flats' contact force W_f = a·l·σ from the weight line's intercept, and μ·γ
//! from the torque line's. l and σ apart, and μ and γ apart, no record can tell. The lines'
//! least-squares uncertainty (Gaussian, flat prior) gives the posterior draws the maps are
//! simulated for.
//!
//! Samples count as cutting where the bit turns (above the stuck threshold), penetrates and
//! moves down: a bit held or lifting carries only part of the wear flats' contact (W = a·ζ·ε·d +
//! g·W_f with g < 1), which would pull both lines' intercepts down. Where the record has the
//! bit's axial speed, its sign says which samples move down. Where it has its axial acceleration
//! instead, the speed summed from rest to rest says it ([`super::axial_rests`]). Where it has
//! neither, or the acceleration shows no rests, they are the upper edge of the weight against
//! the depth of cut: every turning sample lies on the weight line or below it, by the part of
//! the wear flats' contact it lacks, and the samples on it are those with the whole contact, as
//! a bit moving down has.

use super::axial_rests::{AxialRests, DepthCut, axial_rests};
use crate::data::STUCK_SPEED_RAD_S;
use crate::data::drilling::DrillingRecord;
use crate::error::{Error, Result};
use crate::numerics::quantile;
use crate::simulate::coupled::Bit;
use rand::SeedableRng;
use rand::rngs::StdRng;
use rand_distr::{Distribution, StandardNormal};
use serde::Serialize;

/// Fewest cutting samples a calibration takes.
pub const MIN_CUTTING_SAMPLES: usize = 20;

/// How far below the weight line (in the standard deviations of its residual averaged over its
/// neighbours) a sample still counts as on it when the upper edge is sought: one in 160
/// samples on the line falls further.
pub const EDGE_NOISE_SDS: f64 = 2.5;

/// How far above the weight's upper edge (in the noise's standard deviations, its own residual)
/// a sample is a spike, left out and averaged with no neighbour: one in 30,000 samples on the
/// edge lies further by its noise. So is a sample as far above both its neighbours, where they
/// agree (in the noise of a difference, √2 times the noise's): a spike on a held bit, which
/// can lift its weight onto the edge. The averages are cut as far above: where a held bit's
/// samples below the edge are kept, the edge's own upper tail kept too balances them.
pub const EDGE_SPIKE_SDS: f64 = 4.0;

/// The most scatter of the samples' deficits below the weight's upper edge (each read off the
/// weight and the torque, averaged over the sample's neighbours in its state; root mean square
/// over the samples), as a share of the wear flats' contact force, with which the edge's samples
/// are told from a held bit's: a held bit's weight lies below the edge by the share of the
/// contact it lacks, and noise blurs the two. On simulated stick-slip records (45 rpm, 150 kN,
/// 71.3 kN of contact force, 60 s at 50 Hz, 0.3 kN·m of noise on the torque; 20 of each), the
/// 90 % intervals held the truth as often as they should up to 20 kN of white noise on the
/// weight (a share of 0.054-0.063 at 10 kN and 0.059-0.068 at 12 kN, none warned; 0.063-0.075
/// at 15 kN, 7 warned; 0.065-0.083 at 20 kN, 13 warned), every estimate within 5 %; at 30 kN
/// (0.24-0.28, all warned) ε's in none. With 1 kN·m on the torque and 15 kN on the weight at 20
/// Hz, ε's held it in 2 of 20, all warned.
pub const MAX_EDGE_NOISE_SHARE: f64 = 0.07;

/// How many times less noise the upper edge found from above must read than the one found from the
/// samples above the line through every sample to be taken instead. On simulated stick-slip records
/// sampled at 1-5 Hz (45 rpm, 150 kN, 120 s), an edge settled about held samples read 14-28 kN for
/// noise of 3-7.5 kN; from above, a narrow band a little above the edge read down to half the noise
/// the first start read on the edge.
pub const EDGE_START_NOISE_RATIO: f64 = 2.0;

/// Most rounds of the upper edge's refit; it settles in a few.
const MAX_EDGE_ROUNDS: usize = 100;

/// The median of a half-normal variable, in its standard deviations (Φ⁻¹(0.75)).
const HALF_NORMAL_MEDIAN: f64 = 0.674_489_750_196_081_7;

/// The mean square of a half-normal variable no larger than [`EDGE_NOISE_SDS`] standard
/// deviations, in its variance: 1 − 2c·φ(c)/(2Φ(c) − 1) at c = 2.5.
const TRUNCATED_HALF_NORMAL_SQUARE: f64 = 0.911_256_360_935_391_9;

/// Least spread of the depth of cut (its coefficient of variation) that separates cutting from
/// friction: below it the lines' slopes and intercepts trade off freely.
pub const MIN_DEPTH_SPREAD: f64 = 0.05;

/// A straight line y = slope·x + intercept by least squares, with its uncertainty.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Line {
    pub slope: f64,
    pub intercept: f64,
    pub slope_sd: f64,
    pub intercept_sd: f64,
    /// Covariance of slope and intercept.
    pub covariance: f64,
    /// Share of y's variance the line explains.
    pub r_squared: f64,
}

impl Line {
    /// Whether the line exists: a slope and an intercept (the x spread).
    fn is_finite(&self) -> bool {
        self.slope.is_finite() && self.intercept.is_finite()
    }

    /// The least-squares line through (x, y).
    pub fn fit(x: &[f64], y: &[f64]) -> Self {
        let n = x.len() as f64;
        let mx = x.iter().sum::<f64>() / n;
        let my = y.iter().sum::<f64>() / n;
        let sxx: f64 = x.iter().map(|v| (v - mx).powi(2)).sum();
        let sxy: f64 = x.iter().zip(y).map(|(a, b)| (a - mx) * (b - my)).sum();
        let syy: f64 = y.iter().map(|v| (v - my).powi(2)).sum();
        let slope = sxy / sxx;
        let intercept = my - slope * mx;
        let ssr: f64 = x.iter().zip(y).map(|(a, b)| (b - slope * a - intercept).powi(2)).sum();
        let s2 = ssr / (n - 2.0);
        Self {
            slope,
            intercept,
            slope_sd: (s2 / sxx).sqrt(),
            intercept_sd: (s2 * (1.0 / n + mx * mx / sxx)).sqrt(),
            covariance: -mx * s2 / sxx,
            r_squared: if syy > 0.0 { 1.0 - ssr / syy } else { 1.0 },
        }
    }

    /// A draw of (slope, intercept) from the line's Gaussian uncertainty.
    fn draw(&self, rng: &mut StdRng) -> (f64, f64) {
        let (z1, z2): (f64, f64) = (StandardNormal.sample(rng), StandardNormal.sample(rng));
        let l11 = self.slope_sd;
        let l21 = if l11 > 0.0 { self.covariance / l11 } else { 0.0 };
        let l22 = (self.intercept_sd.powi(2) - l21 * l21).max(0.0).sqrt();
        (self.slope + l11 * z1, self.intercept + l21 * z1 + l22 * z2)
    }
}

/// One calibrated quantity: its estimate and 90 % interval.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Estimate {
    pub name: &'static str,
    pub unit: &'static str,
    pub value: f64,
    pub lo: f64,
    pub hi: f64,
}

/// Names and units of a posterior draw's values, in order.
pub const CALIBRATED: [(&str, &str); 4] = [
    ("intrinsic_energy_mpa", "MPa"),
    ("zeta", "1"),
    ("contact_force_kn", "kN"),
    ("mu_gamma", "1"),
];

/// How the samples of a bit moving down were told from those of a held or lifting one.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum CuttingBy {
    /// The record's axial speed of the bit: positive (downward).
    AxialSpeed,
    /// The bit's axial speed summed from its axial acceleration between its rests: positive
    /// (downward) by 3 of its standard deviations.
    AxialAcceleration,
    /// The upper edge of the weight against the depth of cut: the record has no axial speed,
    /// and no axial acceleration that shows the bit's rests.
    WeightEdge,
}

impl CuttingBy {
    /// What the samples were chosen by, as said to the user.
    pub fn describe(self) -> &'static str {
        match self {
            Self::AxialSpeed => "moving down by the bit's axial speed",
            Self::AxialAcceleration => {
                "moving down by 3 standard deviations of the bit's axial speed summed from its axial acceleration between its rests"
            }
            Self::WeightEdge => {
                "on the upper edge of the weight against the depth of cut, the record having no axial speed"
            }
        }
    }
}

/// What a drilling record says of the bit.
#[derive(Clone, Debug, Serialize)]
pub struct CoupledCalibration {
    pub samples: usize,
    /// Samples where the bit was cutting, which the lines go through.
    pub cutting_samples: usize,
    /// How those samples were told from a held or lifting bit's.
    pub cutting_by: CuttingBy,
    /// The bit's rests on its axial acceleration, where they told the samples.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub axial_rests: Option<AxialRests>,
    /// Why the record's axial acceleration could not tell the samples, where it has one and
    /// the weight's upper edge told them instead.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub axial_acceleration_unused: Option<String>,
    /// Channels of the record the calibration could have used and were not read, and why.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub unread: Vec<String>,
    /// The weight's noise about its upper edge (kN, a standard deviation), where that told them.
    pub weight_edge_noise_kn: Option<f64>,
    /// The standard deviation the samples' deficits below the edge were told by, root mean
    /// square over them (kN): each deficit read off the weight and the torque, the scatter of
    /// those averaged over three neighbours in time where both were in the sample's state,
    /// √(3/n) times it for an average of n (the deficits' noise over √n where too few samples
    /// have both). The warning weighs it against [`MAX_EDGE_NOISE_SHARE`] of the contact force.
    pub weight_edge_scatter_kn: Option<f64>,
    /// The depth of cut per revolution's 5th and 95th percentiles (mm).
    pub depth_of_cut_mm: (f64, f64),
    /// Weight (N) against depth of cut (m): slope a·ζ·ε, intercept W_f.
    pub weight_line: Line,
    /// Torque (N·m) against depth of cut (m): slope ½·a²·ε, intercept ½·a·μ·γ·W_f.
    pub torque_line: Line,
    /// ε, ζ, W_f and μ·γ at the lines' estimates with 90 % intervals from the draws.
    pub estimates: Vec<Estimate>,
    /// Draws of (ε MPa, ζ, W_f kN, μ·γ) from the lines' uncertainty.
    pub draws: Vec<[f64; 4]>,
    /// Draws left out because they leave the physical bounds (a negative contact force...).
    pub draws_out_of_bounds: usize,
    /// Said where the record cannot tell a cutting bit from a held or lifting one.
    pub warning: Option<String>,
}

impl CoupledCalibration {
    /// What the user is told beside the estimates: why the record's axial acceleration was not
    /// used, and the warning.
    pub fn notes(&self) -> Vec<String> {
        let unread = self.unread.iter().map(|why| format!("note: not read: {why}"));
        let unused = self
            .axial_acceleration_unused
            .iter()
            .map(|why| format!("note: {why}; the weight's upper edge against the depth of cut told them instead"));
        unread
            .chain(unused)
            .chain(self.warning.iter().map(|w| format!("warning: {w}")))
            .collect()
    }
}

/// ε (MPa), ζ, W_f (kN) and μ·γ of a weight line's and a torque line's (slope, intercept).
fn derived(radius_m: f64, weight: (f64, f64), torque: (f64, f64)) -> [f64; 4] {
    let eps = 2.0 * torque.0 / (radius_m * radius_m);
    [
        eps / 1e6,
        weight.0 / (radius_m * eps),
        weight.1 / 1e3,
        2.0 * torque.1 / (radius_m * weight.1),
    ]
}

/// A refusal of `record`, saying `message`.
fn refusal(record: &DrillingRecord, message: String) -> Error {
    Error::Format {
        path: record.source.clone(),
        line: None,
        message,
    }
}

/// The weight's upper edge against the depth of cut: which samples lie on it, and the noise's
/// standard deviation about it (N).
struct Edge {
    on: Vec<bool>,
    noise_sd_n: f64,
    /// The standard deviation each sample was told by, root mean square over the samples (N):
    /// the scatter of its deficit below the edge (read off the weight and the torque) averaged
    /// over three neighbours in time where they were in its state, √3 times it where neither
    /// was (a held spell of a sample); the deficits' noise over √n, for an average of n, where
    /// too few samples have both.
    told_sd_n: f64,
    /// Whether the samples kept stayed the same, or came back to a set kept before, within
    /// [`MAX_EDGE_ROUNDS`].
    settled: bool,
}

/// The standard deviation of the noise whose positive half is `above` (N), robust to spikes:
/// the median's scale first, then the root mean square of the values within
/// [`EDGE_NOISE_SDS`] of it, for that estimate's efficiency. `floor` where there are none.
fn half_normal_scale(above: &[f64], floor: f64) -> f64 {
    let Some(median) = crate::numerics::median(above) else {
        return floor;
    };
    let rough = median / HALF_NORMAL_MEDIAN;
    let inner: Vec<f64> = above.iter().copied().filter(|r| *r <= EDGE_NOISE_SDS * rough).collect();
    let square = inner.iter().map(|r| r * r).sum::<f64>() / inner.len().max(1) as f64;
    (square / TRUNCATED_HALF_NORMAL_SQUARE).sqrt().max(floor)
}

/// The upper edge of `weight` against `depth`. The least-squares line through every sample is
/// pulled down by the samples below the edge, so the samples above it, which the edge's own samples
/// are most of, give a first line (every sample, where fewer than [`MIN_CUTTING_SAMPLES`] are
/// above); the samples above the line through those above, and so on down to an eighth of the
/// samples, give a second start, from above (the two starts weighed by [`EDGE_START_NOISE_RATIO`]).
/// Then, until the samples kept stay the same (or come back to a set kept before), the line is
/// fitted through the samples on it. A sample is told by its deficit below the line, read off its
/// weight's residual and its torque's about the torque's line through the same samples
/// ([`joint_residuals`]), averaged over its neighbours in time (`follows[k]`: sample k is the
/// record's next after sample k − 1) that are in its state: a held bit stays held for a spell,
/// white noise does not, so the average shrinks the noise and keeps a held bit's deficit. A
/// neighbour whose deficit differs from the sample's by more than [`EDGE_NOISE_SDS`] times the
/// difference's noise (√2 times the deficits') is in another state and left out: in a record
/// sampled so slowly that a held spell lasts a sample or two, averaging across the change would
/// pull the edge's samples below it and lift the held ones onto it. It is on the line where that
/// average is no further below it than [`EDGE_NOISE_SDS`] times the averages' scatter (scaled by
/// √(3/n) for an average of n) nor above it than [`EDGE_SPIKE_SDS`] times, and it is no spike
/// ([`EDGE_SPIKE_SDS`]). The noises and the scatter are read above the lines, where only the edge's
/// samples lie: those residuals are half-normal ([`half_normal_scale`]).
fn upper_edge(depth: &[f64], weight: &[f64], torque: &[f64], follows: &[bool]) -> Edge {
    // Noise-free, the samples on the line differ from it by rounding alone.
    let floor = 1e-9 * weight.iter().fold(0.0_f64, |m, w| m.max(w.abs()));
    let residuals_to = |line: &Line| residuals(depth, weight, line);
    let every = vec![true; depth.len()];
    let first = Line::fit(depth, weight);
    if !first.is_finite() {
        // No line through the samples (no spread of the depth): none is told from another.
        return Edge {
            on: every,
            noise_sd_n: f64::NAN,
            told_sd_n: f64::NAN,
            settled: true,
        };
    }
    // Each residual averaged with its neighbours in time that are not spikes and whose
    // residuals lie within `close` of its own (further, a neighbour is in another state: the
    // bit held where the sample moves down, or the other way): the average and how many
    // samples it holds.
    let smooth = |r: &[f64], spike: &[bool], close: f64| -> Vec<(f64, u8)> {
        let joins = |k: usize, j: usize| follows[k.max(j)] && !spike[j] && !spike[k] && (r[j] - r[k]).abs() <= close;
        (0..r.len())
            .map(|k| {
                let (mut sum, mut n) = (r[k], 1_u8);
                for j in [k.checked_sub(1), Some(k + 1)].into_iter().flatten() {
                    if j < r.len() && joins(k, j) {
                        sum += r[j];
                        n += 1;
                    }
                }
                (sum / f64::from(n), n)
            })
            .collect()
    };
    let fit_through = |set: &[bool]| line_through(depth, weight, set);
    // The first start: the samples above the line through all of them.
    let none = vec![false; depth.len()];
    let mut above_first: Vec<bool> = smooth(&residuals_to(&first), &none, f64::INFINITY)
        .iter()
        .map(|(r, _)| *r >= 0.0)
        .collect();
    if count(&above_first) < MIN_CUTTING_SAMPLES {
        above_first = every.clone();
    }
    // The second start, from above: the samples above the line through those above, and so on
    // while an eighth of the samples remain. Where a held spell lasts a sample or two, the
    // first start's line lies among the held samples, and the refits can settle about it with
    // a scatter that takes them in; from above they come down to the edge.
    let fewest = MIN_CUTTING_SAMPLES.max(depth.len() / 8);
    let mut peeled = above_first.clone();
    loop {
        let line = fit_through(&peeled);
        if !line.is_finite() {
            break;
        }
        let higher: Vec<bool> = residuals_to(&line)
            .iter()
            .zip(&peeled)
            .map(|(r, k)| *k && *r >= 0.0)
            .collect();
        if count(&higher) < fewest || higher == peeled {
            break;
        }
        peeled = higher;
    }
    // Each start settled. A start that settled about held samples reads their deficits as
    // noise, several times the noise; from above, the refits can come to rest a little above
    // the edge, in a narrower band. The first start's edge is kept unless the second's is
    // settled and reads less than [`EDGE_START_NOISE_RATIO`] times less noise.
    // Where peeling kept the first start, it is settled once.
    let settle = |on: Vec<bool>| settle_edge(on, [depth, weight, torque], follows, smooth, floor);
    let from_above = (peeled != above_first).then(|| settle(peeled));
    let from_first = settle(above_first);
    match from_above {
        Some(edge)
            if edge.settled
                && (!from_first.settled || EDGE_START_NOISE_RATIO * edge.noise_sd_n < from_first.noise_sd_n) =>
        {
            edge
        }
        _ => from_first,
    }
}

/// The weight's residuals `residual_w` (noise `noise_w`; `spike` marks its spikes) joined with the
/// torque's about its own line through the samples `on`: a held bit's torque lies below its line by
/// κ = ½·a·μ·γ times its weight's deficit, so each sample's deficit is weighed from both, by their
/// noises (taken as independent: noises that move together would be read as smaller than they are).
/// κ is the torque's residuals' regression on the weight's (through the origin), so that a torque
/// that does not fall with the weight (κ ≤ 0) leaves the weight's residuals as they are. In weight
/// units (N), with their noise.
fn joint_residuals(
    residual_w: &[f64],
    noise_w: f64,
    [depth, torque]: [&[f64]; 2],
    on: &[bool],
    spike: &[bool],
) -> (Vec<f64>, f64) {
    let residual_t = residuals(depth, torque, &line_through(depth, torque, on));
    // κ from the samples that are no spikes of the weight. The weight's noise is taken out of
    // its residuals' spread (errors in the regressor would shrink κ, most where the weight is
    // noisiest and the torque helps most). Where the deficits spread less than the noise, κ is
    // not read, and the weight is told alone.
    let pairs = || {
        residual_w
            .iter()
            .zip(&residual_t)
            .zip(spike)
            .filter(|(_, s)| !**s)
            .map(|(p, _)| p)
    };
    let noise_square = pairs().count() as f64 * noise_w * noise_w;
    let spread_w = pairs().map(|(w, _)| w * w).sum::<f64>() - noise_square;
    let kappa = if spread_w >= noise_square {
        pairs().map(|(w, t)| w * t).sum::<f64>() / spread_w
    } else {
        0.0
    };
    // The torque's noise about its line, read above it as the weight's is.
    let above: Vec<f64> = residual_t.iter().copied().filter(|r| *r > 0.0).collect();
    // Noise-free, the samples on the line differ from it by rounding alone.
    let floor = 1e-9 * torque.iter().fold(0.0_f64, |m, t| m.max(t.abs()));
    let noise_t = half_normal_scale(&above, floor);
    if !(kappa > 0.0 && kappa.is_finite() && noise_t > 0.0 && noise_w > 0.0) {
        return (residual_w.to_vec(), noise_w);
    }
    // Inverse-variance weights of the two reads of a sample's deficit: r_w, and r_t/κ.
    let (ww, wt) = (noise_w.powi(-2), (noise_t / kappa).powi(-2));
    let joint = residual_w
        .iter()
        .zip(&residual_t)
        .map(|(rw, rt)| (ww * rw + wt * rt / kappa) / (ww + wt))
        .collect();
    (joint, (ww + wt).sqrt().recip())
}

/// A straight line through `y` against `x` at the samples in `set`.
fn line_through(x: &[f64], y: &[f64], set: &[bool]) -> Line {
    Line::fit(&kept(x, set), &kept(y, set))
}

/// `values` at the samples in `set`.
fn kept(values: &[f64], set: &[bool]) -> Vec<f64> {
    values.iter().zip(set).filter(|(_, k)| **k).map(|(v, _)| *v).collect()
}

/// How many samples `set` holds.
fn count(set: &[bool]) -> usize {
    set.iter().filter(|k| **k).count()
}

/// `y`'s residuals about `line` against `x`.
fn residuals(x: &[f64], y: &[f64], line: &Line) -> Vec<f64> {
    x.iter()
        .zip(y)
        .map(|(x, y)| y - line.slope * x - line.intercept)
        .collect()
}

/// The refits of the upper edge from the samples `on` until the samples kept stay the same (or
/// come back to a set kept before), as [`upper_edge`] says.
fn settle_edge(
    mut on: Vec<bool>,
    [depth, weight, torque]: [&[f64]; 3],
    follows: &[bool],
    smooth: impl Fn(&[f64], &[bool], f64) -> Vec<(f64, u8)>,
    floor: f64,
) -> Edge {
    let (mut noise_sd_n, mut told_sd_n) = (f64::NAN, f64::NAN);
    // A set kept before comes back where samples at the band's border take turns: the edge
    // has settled as far as the noise lets it.
    // (Each set kept by its hash: a few bytes a round, however long the record.)
    let hash = |set: &[bool]| {
        use std::hash::{Hash, Hasher};
        let mut h = std::hash::DefaultHasher::new();
        set.hash(&mut h);
        h.finish()
    };
    let mut seen: Vec<u64> = Vec::new();
    for _ in 0..MAX_EDGE_ROUNDS {
        let line = line_through(depth, weight, &on);
        if count(&on) < MIN_CUTTING_SAMPLES || !line.is_finite() {
            break;
        }
        let residuals = residuals(depth, weight, &line);
        let above: Vec<f64> = residuals.iter().copied().filter(|r| *r > 0.0).collect();
        noise_sd_n = half_normal_scale(&above, floor);
        let jump = EDGE_SPIKE_SDS * std::f64::consts::SQRT_2 * noise_sd_n;
        // Spikes, left out and averaged with none: samples above the line by more than
        // [`EDGE_SPIKE_SDS`] times the noise, and samples that jump as far above both their
        // neighbours where those agree (a spike on a held bit, which can lift it onto the line).
        let r = &residuals;
        let spike: Vec<bool> = (0..r.len())
            .map(|k| {
                let isolated = k > 0
                    && k + 1 < r.len()
                    && follows[k]
                    && follows[k + 1]
                    && (r[k - 1] - r[k + 1]).abs() <= jump * EDGE_NOISE_SDS / EDGE_SPIKE_SDS
                    && r[k] - r[k - 1].max(r[k + 1]) > jump;
                r[k] > EDGE_SPIKE_SDS * noise_sd_n || isolated
            })
            .collect();
        // Each sample is told by its deficit read off both lines.
        let (told_by, told_noise) = joint_residuals(&residuals, noise_sd_n, [depth, torque], &on, &spike);
        // Two samples in one state differ by noise of √2 times the noise's standard deviation.
        let close = EDGE_NOISE_SDS * std::f64::consts::SQRT_2 * told_noise;
        let smoothed = smooth(&told_by, &spike, close);
        // The scatter of the averages of three; a sample averaged over n is told against
        // √(3/n) times it. Without enough of them, by the samples' own noise.
        let whole: Vec<f64> = smoothed
            .iter()
            .filter(|(r, n)| *n == 3 && *r > 0.0)
            .map(|(r, _)| *r)
            .collect();
        let (scatter, of) = if whole.len() >= MIN_CUTTING_SAMPLES {
            (half_normal_scale(&whole, floor), 3.0)
        } else {
            (told_noise, 1.0)
        };
        let told: Vec<f64> = smoothed
            .iter()
            .zip(&spike)
            .filter(|(_, spike)| !**spike)
            .map(|((_, n), _)| scatter * scatter * of / f64::from(*n))
            .collect();
        told_sd_n = (told.iter().sum::<f64>() / told.len().max(1) as f64).sqrt();
        let next: Vec<bool> = smoothed
            .iter()
            .zip(&spike)
            .map(|((r, n), spike)| {
                let sd = scatter * (of / f64::from(*n)).sqrt();
                !spike && *r >= -EDGE_NOISE_SDS * sd && *r <= EDGE_SPIKE_SDS * sd
            })
            .collect();
        if next == on || seen.contains(&hash(&next)) {
            return Edge {
                on,
                noise_sd_n,
                told_sd_n,
                settled: true,
            };
        }
        seen.push(hash(&on));
        on = next;
    }
    Edge {
        on,
        noise_sd_n,
        told_sd_n,
        settled: false,
    }
}

/// The samples cutting, as the lines are fitted through them (SI).
struct Cutting {
    /// Depth of cut per revolution (m).
    depth: Vec<f64>,
    weight: Vec<f64>,
    torque: Vec<f64>,
    /// How the samples were told.
    by: CuttingBy,
    /// The weight's upper edge, where that told the samples.
    edge: Option<Edge>,
    /// The bit's rests, where they told the samples.
    rests: Option<AxialRests>,
    /// Why the axial acceleration could not tell them, where the record has one.
    rests_unused: Option<String>,
}

/// The samples that show the bit cutting (turning, penetrating and moving down, by the axial
/// speed, the axial acceleration's rests or the weight's upper edge): each one's depth of cut (m
/// a turn), weight on bit (N) and torque (N·m); refused where too few do.
fn cutting(record: &DrillingRecord) -> Result<Cutting> {
    let refuse = |message: String| refusal(record, message);
    let Some(rop_m_s) = record.rop_m_s.as_deref() else {
        return Err(refuse(
            "no column is a rate of penetration (a name holding 'rop' or 'penetration'), which the \
             depth of cut is read from; name it with `rop_column`"
                .into(),
        ));
    };
    let (mut rests, mut rests_unused) = match (&record.axial_speed_m_s, &record.axial_acceleration_m_s2) {
        (None, Some(acceleration)) => match axial_rests(acceleration, depth_cut(record, rop_m_s)) {
            Ok(rests) => (Some(rests), None),
            Err(why) => (None, Some(why)),
        },
        _ => (None, None),
    };
    let mut turning = turning_samples(record, rop_m_s, &|i| match (&record.axial_speed_m_s, &rests) {
        (Some(v), _) => v[i] > 0.0,
        (None, Some(r)) => r.moving_down[i],
        (None, None) => true,
    });
    if rests.is_some() && turning.depth.len() < MIN_CUTTING_SAMPLES {
        rests_unused = Some(format!(
            "it tells {} samples of the bit moving down, turning and penetrating: at least \
             {MIN_CUTTING_SAMPLES} are needed",
            turning.depth.len()
        ));
        rests = None;
        turning = turning_samples(record, rop_m_s, &|_| true);
    }
    let rests_unused = rests_unused.map(|why| {
        format!(
            "the axial acceleration ('{}') cannot tell the bit moving down: {why}",
            record.columns.axial_acceleration.as_deref().unwrap_or_default()
        )
    });
    let by = match (&record.axial_speed_m_s, &rests) {
        (Some(_), _) => CuttingBy::AxialSpeed,
        (None, Some(_)) => CuttingBy::AxialAcceleration,
        (None, None) => CuttingBy::WeightEdge,
    };
    let Turning {
        mut depth,
        mut weight,
        mut torque,
        follows,
    } = turning;
    let mut edge_found = None;
    // Without the depth's spread no edge is found, and the calibration refuses for the spread.
    if by == CuttingBy::WeightEdge && depth.len() >= MIN_CUTTING_SAMPLES && spread(&depth).is_ok() {
        let edge = upper_edge(&depth, &weight, &torque, &follows);
        (depth, weight, torque) = (kept(&depth, &edge.on), kept(&weight, &edge.on), kept(&torque, &edge.on));
        edge_found = Some(edge);
    }
    if depth.len() < MIN_CUTTING_SAMPLES {
        return Err(refuse(format!(
            "{} of its {} samples show the bit cutting (turning, penetrating, {}): at least \
             {MIN_CUTTING_SAMPLES} are needed{}",
            depth.len(),
            record.len(),
            by.describe(),
            rests_unused.as_ref().map_or(String::new(), |why| format!(" ({why})"))
        )));
    }
    Ok(Cutting {
        depth,
        weight,
        torque,
        by,
        edge: edge_found,
        rests,
        rests_unused,
    })
}

/// A record's turning, penetrating samples that `moving_down` keeps: each one's depth of cut (m
/// a turn), weight (N) and torque (N·m), and whether it follows the one before in the record.
struct Turning {
    depth: Vec<f64>,
    weight: Vec<f64>,
    torque: Vec<f64>,
    follows: Vec<bool>,
}

/// The samples of `record` (its rate of penetration `rop_m_s`) turning above the stuck speed,
/// penetrating and moving down by `moving_down`.
fn turning_samples(record: &DrillingRecord, rop_m_s: &[f64], moving_down: &dyn Fn(usize) -> bool) -> Turning {
    let mut out = Turning {
        depth: Vec::new(),
        weight: Vec::new(),
        torque: Vec::new(),
        follows: Vec::new(),
    };
    let mut last = None;
    for (i, (&w, &rop)) in record.speed_rad_s.iter().zip(rop_m_s).enumerate() {
        if w > STUCK_SPEED_RAD_S && rop > 0.0 && moving_down(i) {
            out.depth.push(std::f64::consts::TAU * rop / w);
            out.weight.push(record.wob_n[i]);
            out.torque.push(record.torque_nm[i]);
            out.follows.push(last.is_some_and(|l| l + 1 == i));
            last = Some(i);
        }
    }
    out
}

/// Where the weight's upper edge is not clear: the standard deviation its samples were told by,
/// `scatter_n`, more than [`MAX_EDGE_NOISE_SHARE`] of the wear flats' contact force `contact_n`
/// (both N), no positive contact force, or an edge that did not settle. What such a record cannot
/// tell, as said to the user.
fn blurred_edge(scatter_n: f64, settled: bool, contact_n: f64) -> Option<String> {
    if !settled {
        return Some(format!(
            "the record has no axial speed of the bit, and the weight's upper edge against the \
             depth of cut did not settle in {MAX_EDGE_ROUNDS} refits: the estimates can be \
             biased; a record with the bit's axial speed tells a bit moving down from one held"
        ));
    }
    if contact_n <= 0.0 {
        return Some(format!(
            "the record has no axial speed of the bit, and the weight's upper edge meets zero \
             depth of cut at {:.1} kN, no contact force: the edge was not found; a record with \
             the bit's axial speed tells a bit moving down from one held",
            contact_n / 1e3
        ));
    }
    let clear = scatter_n <= MAX_EDGE_NOISE_SHARE * contact_n;
    (!clear).then(|| {
        format!(
            "the record has no axial speed of the bit, and the samples' deficits below the \
             weight's upper edge (read off the weight and the torque, averaged over neighbours \
             in one state) scatter by {:.1} kN, more than {:.0} % of the wear flats' contact \
             force ({:.1} kN): a bit held or lifting blurs into one moving down, and the \
             estimates can be biased; a record with the bit's axial speed tells them apart",
            scatter_n / 1e3,
            100.0 * MAX_EDGE_NOISE_SHARE,
            contact_n / 1e3
        )
    })
}

/// What the bit's travel from rest to rest on `record` is checked against, where it has a clock:
/// the depth its rate of penetration `rop_m_s` cut, within a turn's depth of cut (2π·ROP/Ω, the
/// 95th percentile over the turning, penetrating samples: a rate of penetration smoothed over a
/// stick gives a bit barely turning a depth it never cut).
fn depth_cut<'a>(record: &DrillingRecord, rop_m_s: &'a [f64]) -> Option<DepthCut<'a>> {
    let depths = turning_samples(record, rop_m_s, &|_| true).depth;
    let turn_depth_m = if depths.is_empty() {
        0.0
    } else {
        quantile(&depths, 0.95)
    };
    record.sample_period_s.map(|period_s| DepthCut {
        period_s,
        rop_m_s,
        turn_depth_m,
    })
}

/// Whether the depths of cut `depth` spread at least [`MIN_DEPTH_SPREAD`]; their mean and
/// standard deviation where they do not.
fn spread(depth: &[f64]) -> std::result::Result<(), (f64, f64)> {
    let mean = depth.iter().sum::<f64>() / depth.len() as f64;
    let sd = (depth.iter().map(|d| (d - mean).powi(2)).sum::<f64>() / depth.len() as f64).sqrt();
    if sd < MIN_DEPTH_SPREAD * mean {
        Err((mean, sd))
    } else {
        Ok(())
    }
}

/// Calibrates the bit of radius `radius_m` on `record`, with `draws` posterior draws from `seed`.
pub fn calibrate(record: &DrillingRecord, radius_m: f64, draws: usize, seed: u64) -> Result<CoupledCalibration> {
    let refuse = |message: String| refusal(record, message);
    let Cutting {
        depth,
        weight,
        torque,
        by,
        edge,
        rests,
        rests_unused,
    } = cutting(record)?;
    if let Err((mean, sd)) = spread(&depth) {
        return Err(refuse(format!(
            "the depth of cut hardly varies ({:.2} mm a turn ± {:.1} %): cutting cannot be told \
             from the wear flats' friction; record several weights on bit, or stick-slip",
            1e3 * mean,
            100.0 * sd / mean
        )));
    }
    let weight_line = Line::fit(&depth, &weight);
    let torque_line = Line::fit(&depth, &torque);
    // ε and ζ within the bit's bounds, a contact force, and μ·γ no more than the largest μ
    // times the largest γ.
    let b = crate::simulate::coupled::BIT_BOUNDS;
    let bounds = [b[1], b[2], (0.0, f64::INFINITY), (0.0, b[5].1 * b[6].1)];
    let inside = |v: &[f64; 4]| {
        v.iter()
            .zip(bounds)
            .all(|(x, (lo, hi))| x.is_finite() && *x > lo && *x <= hi)
    };
    let mut rng = StdRng::seed_from_u64(seed);
    let mut kept = Vec::with_capacity(draws);
    let mut out_of_bounds = 0;
    for _ in 0..draws {
        let v = derived(radius_m, weight_line.draw(&mut rng), torque_line.draw(&mut rng));
        if inside(&v) {
            kept.push(v);
        } else {
            out_of_bounds += 1;
        }
    }
    let point = derived(
        radius_m,
        (weight_line.slope, weight_line.intercept),
        (torque_line.slope, torque_line.intercept),
    );
    let q = |values: &[f64], p: f64| {
        if values.is_empty() {
            f64::NAN
        } else {
            quantile(values, p)
        }
    };
    let estimates = CALIBRATED
        .iter()
        .enumerate()
        .map(|(k, (name, unit))| {
            let column: Vec<f64> = kept.iter().map(|v| v[k]).collect();
            Estimate {
                name,
                unit,
                value: point[k],
                lo: q(&column, 0.05),
                hi: q(&column, 0.95),
            }
        })
        .collect();
    Ok(CoupledCalibration {
        samples: record.len(),
        cutting_samples: depth.len(),
        cutting_by: by,
        axial_rests: rests,
        axial_acceleration_unused: rests_unused,
        unread: record.unread.clone(),
        weight_edge_noise_kn: edge.as_ref().map(|e| e.noise_sd_n / 1e3),
        weight_edge_scatter_kn: edge.as_ref().map(|e| e.told_sd_n / 1e3),
        depth_of_cut_mm: (1e3 * quantile(&depth, 0.05), 1e3 * quantile(&depth, 0.95)),
        weight_line,
        torque_line,
        estimates,
        draws: kept,
        draws_out_of_bounds: out_of_bounds,
        warning: edge.and_then(|e| blurred_edge(e.told_sd_n, e.settled, weight_line.intercept)),
    })
}

/// `template` with a calibrated draw's ε, ζ and, through its contact stress and geometry factor,
/// the wear-flat length l = W_f/(a·σ) and friction μ = μγ/γ.
pub fn bit_of(draw: &[f64; 4], template: &Bit) -> Bit {
    Bit {
        intrinsic_energy_mpa: draw[0],
        zeta: draw[1],
        wear_flat_mm: 1e3 * draw[2] * 1e3 / (template.radius_m * template.contact_stress_mpa * 1e6),
        friction: draw[3] / template.gamma,
        ..*template
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_line_through_exact_points_is_recovered_with_no_uncertainty() {
        let x: Vec<f64> = (0..10).map(|i| 1.0 + i as f64).collect();
        let y: Vec<f64> = x.iter().map(|v| 3.0 * v + 2.0).collect();
        let l = Line::fit(&x, &y);
        assert!((l.slope - 3.0).abs() < 1e-12 && (l.intercept - 2.0).abs() < 1e-12);
        assert!(l.slope_sd < 1e-6 && (l.r_squared - 1.0).abs() < 1e-12);
    }

    /// A torque that tells nothing of the weight's deficits: the weight's edge alone.
    fn silent(n: usize) -> Vec<f64> {
        vec![0.0; n]
    }

    #[test]
    fn the_upper_edge_is_the_line_the_samples_below_it_lack_part_of() {
        // Half the samples on W = 2e6·d + 7e4, the rest below it by up to the whole 7e4.
        let depth: Vec<f64> = (0..2000).map(|i| 0.005 + 0.03 * f64::from(i % 97) / 97.0).collect();
        let lacking = |i: usize| {
            if i.is_multiple_of(2) {
                0.0
            } else {
                7e4 * ((i * 7919) % 1000) as f64 / 1000.0
            }
        };
        let weight: Vec<f64> = depth
            .iter()
            .enumerate()
            .map(|(i, d)| 2e6 * d + 7e4 - lacking(i))
            .collect();
        let edge = upper_edge(&depth, &weight, &silent(depth.len()), &vec![false; depth.len()]);
        for (i, on) in edge.on.iter().enumerate() {
            assert_eq!(*on, lacking(i) == 0.0, "sample {i}");
        }
        assert!(edge.noise_sd_n < 1e-3, "{}", edge.noise_sd_n);
        // Gaussian noise and no sample below: nearly all kept (one in 160 falls 2.5 standard
        // deviations below), the noise read within 6 %.
        for seed in 0..10 {
            let mut rng = StdRng::seed_from_u64(seed);
            let noisy: Vec<f64> = depth
                .iter()
                .map(|d| {
                    let z: f64 = StandardNormal.sample(&mut rng);
                    2e6 * d + 7e4 + 5e3 * z
                })
                .collect();
            let edge = upper_edge(&depth, &noisy, &silent(depth.len()), &vec![false; depth.len()]);
            let kept = edge.on.iter().filter(|on| **on).count();
            assert!(
                kept >= 1960 && (edge.noise_sd_n - 5e3).abs() < 300.0,
                "seed {seed}: {kept} {}",
                edge.noise_sd_n
            );
        }
    }

    #[test]
    fn spikes_above_the_edge_are_left_out_and_do_not_inflate_its_noise() {
        let depth: Vec<f64> = (0..2000).map(|i| 0.005 + 0.03 * f64::from(i % 97) / 97.0).collect();
        let spike = |i: usize| i % 100 == 37;
        for seed in 0..10 {
            let mut rng = StdRng::seed_from_u64(seed);
            let weight: Vec<f64> = depth
                .iter()
                .enumerate()
                .map(|(i, d)| {
                    let z: f64 = StandardNormal.sample(&mut rng);
                    2e6 * d + 7e4 + 5e3 * z + if spike(i) { 6e4 } else { 0.0 }
                })
                .collect();
            // Alone and with their neighbours in time: a spike is told by its own residual, and
            // averaged with none.
            for follows in [vec![false; 2000], (0..2000).map(|i| i > 0).collect()] {
                let edge = upper_edge(&depth, &weight, &silent(depth.len()), &follows);
                assert!(
                    edge.settled && (edge.noise_sd_n - 5e3).abs() < 300.0,
                    "seed {seed}: {}",
                    edge.noise_sd_n
                );
                assert!((0..2000).filter(|i| spike(*i)).all(|i| !edge.on[i]), "seed {seed}");
            }
        }
    }

    #[test]
    fn the_truncated_half_normal_s_constants_are_its_own() {
        // Simpson's rule on the standard normal density from 0 to the edge's cut.
        let density = |x: f64| (-0.5 * x * x).exp();
        let mass = crate::numerics::simpson(density, 0.0, EDGE_NOISE_SDS, 10_000);
        let square = crate::numerics::simpson(|x| x * x * density(x), 0.0, EDGE_NOISE_SDS, 10_000);
        assert!((square / mass - TRUNCATED_HALF_NORMAL_SQUARE).abs() < 1e-9);
        // Half the normal's mass lies within its median's distance of zero.
        let normal = rand_distr::Normal::new(0.0, 1.0).unwrap();
        let mut rng = StdRng::seed_from_u64(5);
        let n = 200_000;
        let inside = (0..n)
            .filter(|_| f64::abs(normal.sample(&mut rng)) <= HALF_NORMAL_MEDIAN)
            .count();
        assert!((inside as f64 / f64::from(n) - 0.5).abs() < 0.005, "{inside}");
    }

    #[test]
    fn a_spike_that_lifts_a_held_bit_onto_the_edge_is_left_out() {
        // Runs of 20 samples on the edge and 20 held 40 kN below it, under 2 kN of noise; in the
        // middle of each held run a spike of 40 kN puts one sample back on the line, where its
        // own residual would keep it (its neighbours, 40 kN away, are in another state).
        let n = 2000;
        let depth: Vec<f64> = (0..n).map(|i| 0.005 + 0.03 * f64::from(i as u32 % 97) / 97.0).collect();
        let held = |i: usize| (i / 20) % 2 == 1;
        let spiked = |i: usize| i % 40 == 30;
        let mut rng = StdRng::seed_from_u64(11);
        let weight: Vec<f64> = (0..n)
            .map(|i| {
                let z: f64 = StandardNormal.sample(&mut rng);
                let lacking = if held(i) && !spiked(i) { 4e4 } else { 0.0 };
                2e6 * depth[i] + 7e4 - lacking + 2e3 * z
            })
            .collect();
        let follows: Vec<bool> = (0..n).map(|i| i > 0).collect();
        let edge = upper_edge(&depth, &weight, &silent(n), &follows);
        let kept_spiked = (0..n).filter(|&i| spiked(i) && edge.on[i]).count();
        assert!(kept_spiked <= 2, "{kept_spiked} of 50 spiked samples kept");
        let kept_on_edge = (0..n).filter(|&i| !held(i) && edge.on[i]).count();
        assert!(
            kept_on_edge * 10 >= n / 2 * 9,
            "{kept_on_edge} of {} on the edge kept",
            n / 2
        );
    }

    #[test]
    fn neighbours_in_time_tell_a_held_bit_through_noise() {
        // Runs of 20 samples on the edge and 20 held below it by 0.2 to 1.0 of the 70 kN
        // contact, under 8 kN of noise.
        let n = 4000;
        let depth: Vec<f64> = (0..n).map(|i| 0.005 + 0.03 * f64::from(i as u32 % 97) / 97.0).collect();
        let held = |i: usize| (i / 20) % 2 == 1;
        let mut rng = StdRng::seed_from_u64(3);
        let weight: Vec<f64> = (0..n)
            .map(|i| {
                let z: f64 = StandardNormal.sample(&mut rng);
                let lacking = if held(i) {
                    7e4 * (0.2 + 0.8 * ((i * 7919) % 1000) as f64 / 1000.0)
                } else {
                    0.0
                };
                2e6 * depth[i] + 7e4 - lacking + 8e3 * z
            })
            .collect();
        let kept = |follows: &[bool], of_held: bool| {
            let edge = upper_edge(&depth, &weight, &silent(depth.len()), follows);
            (0..n).filter(|&i| held(i) == of_held && edge.on[i]).count()
        };
        let in_runs: Vec<bool> = (0..n).map(|i| i > 0).collect();
        let (alone, in_time) = (kept(&vec![false; n], true), kept(&in_runs, true));
        // The edge's own samples are kept all the same, but some beside a held run.
        let on_edge = kept(&in_runs, false);
        assert!(on_edge * 10 >= n / 2 * 9, "{on_edge} of {} on the edge kept", n / 2);
        assert!(
            in_time * 10 < alone,
            "held samples kept: {in_time} with their neighbours, {alone} alone"
        );
    }

    #[test]
    fn a_held_bit_s_deficit_is_read_off_the_weight_and_the_torque_by_their_noises() {
        // Half the samples on the lines, the rest lacking up to 70 kN of the contact; the torque
        // lacks κ = 0.0324 m times as much. 8 kN on the weight, 0.3 kN·m on the torque: the
        // torque's read of a deficit (0.3/0.0324 = 9.3 kN) and the weight's weigh about alike.
        let n = 4000;
        let kappa = 0.0324;
        let depth: Vec<f64> = (0..n).map(|i| 0.005 + 0.03 * f64::from(i as u32 % 97) / 97.0).collect();
        let deficit = |i: usize| {
            if i.is_multiple_of(2) {
                0.0
            } else {
                7e4 * ((i * 7919) % 1000) as f64 / 1000.0
            }
        };
        let mut rng = StdRng::seed_from_u64(5);
        let mut normal = |sd: f64| -> f64 {
            let z: f64 = StandardNormal.sample(&mut rng);
            sd * z
        };
        let residual_w: Vec<f64> = (0..n).map(|i| -deficit(i) + normal(8e3)).collect();
        let torque: Vec<f64> = (0..n)
            .map(|i| 3e5 * depth[i] + kappa * (7e4 - deficit(i)) + normal(300.0))
            .collect();
        let on: Vec<bool> = (0..n).map(|i| deficit(i) == 0.0).collect();
        let (joint, noise) = joint_residuals(&residual_w, 8e3, [&depth, &torque], &on, &vec![false; n]);
        let expected = (8e3_f64.powi(-2) + (kappa / 300.0).powi(2)).sqrt().recip();
        assert!((noise - expected).abs() < 0.05 * expected, "{noise} for {expected}");
        // Each deficit read within its noise: the errors' spread is the joint noise's.
        let errors: Vec<f64> = (0..n).map(|i| joint[i] + deficit(i)).collect();
        let sd = (errors.iter().map(|e| e * e).sum::<f64>() / n as f64).sqrt();
        assert!((sd - expected).abs() < 0.1 * expected, "{sd} for {expected}");
        // A torque that does not fall with the weight leaves the weight's read nearly alone, and
        // one with no noise either (an empty channel) leaves it exactly.
        let flat: Vec<f64> = (0..n).map(|i| 3e5 * depth[i] + 2e3 + normal(300.0)).collect();
        let (joint, noise) = joint_residuals(&residual_w, 8e3, [&depth, &flat], &on, &vec![false; n]);
        assert!(noise > 0.95 * 8e3, "{noise}");
        let moved = (0..n).map(|i| (joint[i] - residual_w[i]).abs()).fold(0.0, f64::max);
        assert!(moved < 0.2 * 8e3, "{moved}");
        assert_eq!(
            joint_residuals(&residual_w, 8e3, [&depth, &silent(n)], &on, &vec![false; n]),
            (residual_w.clone(), 8e3)
        );
    }

    #[test]
    fn a_short_record_on_one_line_keeps_every_sample() {
        // 30 samples on the edge: those above the least-squares line are fewer than a
        // calibration takes, and the edge starts from all of them.
        let depth: Vec<f64> = (0..30).map(|i| 0.005 + 0.001 * f64::from(i)).collect();
        // Half a newton above and below in turn: 15 above the line.
        let weight: Vec<f64> = depth
            .iter()
            .enumerate()
            .map(|(i, d)| 2e6 * d + 7e4 + if i % 2 == 0 { 0.5 } else { -0.5 })
            .collect();
        for follows in [vec![false; 30], (0..30).map(|i| i > 0).collect()] {
            let edge = upper_edge(&depth, &weight, &silent(depth.len()), &follows);
            assert!(edge.settled && edge.on.iter().all(|on| *on), "{:?}", edge.on);
        }
    }

    /// A record of `n` samples at 6 rad/s without the bit's axial speed, with rate of
    /// penetration `rop(i)` (m/s) and weight `wob(i)` (N).
    fn blind_record(n: usize, rop: impl Fn(usize) -> f64, wob: impl Fn(usize) -> f64) -> DrillingRecord {
        DrillingRecord {
            source: "bit.csv".into(),
            columns: crate::data::drilling::DrillingColumns {
                speed: "bit_speed_rpm".into(),
                torque: "torque_knm".into(),
                wob: "wob_kn".into(),
                rop: Some("rop_m_h".into()),
                axial_speed: None,
                axial_acceleration: None,
                time: None,
            },
            speed_rad_s: vec![6.0; n],
            torque_nm: vec![1e4; n],
            wob_n: (0..n).map(wob).collect(),
            rop_m_s: Some((0..n).map(rop).collect()),
            axial_speed_m_s: None,
            axial_acceleration_m_s2: None,
            sample_period_s: None,
            unread: Vec::new(),
        }
    }

    #[test]
    fn a_record_without_axial_speed_or_depth_spread_is_refused_for_the_spread() {
        let record = blind_record(100, |_| 0.005, |i| 1.5e5 + f64::from(i as u32 % 7));
        let e = calibrate(&record, 0.108, 10, 1).unwrap_err().to_string();
        assert!(e.contains("bit.csv") && e.contains("hardly varies"), "{e}");
    }

    #[test]
    fn an_edge_without_contact_force_is_said_to_be_lost() {
        // The weight through zero depth of cut at -20 kN: no wear flats' contact there.
        let rop = |i: usize| 0.002 + 0.0001 * (i % 40) as f64;
        let record = blind_record(200, rop, |i| 2e6 * std::f64::consts::TAU * rop(i) / 6.0 - 2e4);
        let c = calibrate(&record, 0.108, 10, 1).unwrap();
        let warning = c.warning.unwrap_or_default();
        assert!(
            warning.contains("no contact force") && warning.contains("axial speed"),
            "{warning}"
        );
    }

    #[test]
    fn the_bit_s_own_lines_give_its_parameters_back() {
        let b = Bit::default();
        let a = b.radius_m;
        let weight = (b.cutting_weight_n_per_m(), b.contact_weight_n());
        let torque = (b.cutting_torque_nm_per_m(), b.friction_arm_m() * b.contact_weight_n());
        let v = derived(a, weight, torque);
        for (got, want) in v.iter().zip([60.0, 0.6, b.contact_weight_n() / 1e3, 0.6]) {
            assert!((got - want).abs() < 1e-9 * want, "{v:?}");
        }
        let back = bit_of(&v, &b);
        assert!((back.wear_flat_mm - 11.0).abs() < 1e-9 && (back.friction - 0.6).abs() < 1e-12);
    }

    #[test]
    fn a_record_without_a_rate_of_penetration_is_refused_naming_the_role() {
        let record = DrillingRecord {
            source: "bit.csv".into(),
            columns: crate::data::drilling::DrillingColumns {
                speed: "bit_speed_rpm".into(),
                torque: "torque_knm".into(),
                wob: "wob_kn".into(),
                rop: None,
                axial_speed: None,
                axial_acceleration: None,
                time: None,
            },
            speed_rad_s: vec![6.0; 100],
            torque_nm: vec![1e4; 100],
            wob_n: vec![1.5e5; 100],
            rop_m_s: None,
            axial_speed_m_s: None,
            axial_acceleration_m_s2: None,
            sample_period_s: None,
            unread: Vec::new(),
        };
        let e = calibrate(&record, 0.108, 10, 1).unwrap_err().to_string();
        assert!(
            e.contains("bit.csv") && e.contains("rate of penetration") && e.contains("rop_column"),
            "{e}"
        );
    }
}
