//! Which samples show the bit moving down, from its axial acceleration, where a record has no
//! axial speed: vibration tools log the bit's acceleration, and its sum drifts with the sensor's
//! offset and noise. A bit on bottom comes to rest again and again (held by its wear flats'
//! friction), and at rest its channel reads a constant: gravity's share and the sensor's offset.
//! So, as an inertial navigator zeroes a walker's speed where the foot stands still (zero-velocity
//! updates), the sum is zeroed at every rest: between two rests the speed is the acceleration
//! summed from the first less the share of the sum's end that its place takes (a Brownian
//! bridge, which takes a constant offset away exactly), and its spread is the noise's. A sample
//! moves down where its speed lies more than [`MOVING_SDS`] of that spread above zero (white
//! noise, sample by sample: one in 740 samples of a bit at rest between rests), so the samples
//! told moving are the bit's own whatever the noise on its weight; a noisier channel tells fewer.
//! A bit moving at a steady speed reads the rest too: its spells are taken for rests and its
//! speed there for zero, which shortens its travel and tells fewer of its samples moving.
//!
//! Speeds here are in the acceleration's unit times a sample period: the choice of samples is
//! the same whatever the period. Where the record has a clock, the bit's travel from its first
//! rest to its last must be the depth it cut meanwhile, which the rate of penetration gives (at
//! every rest it sits on the bottom it cut, whose height under the blades varies around the hole
//! by up to a turn's depth of cut): a channel that is not the acceleration's mean over
//! each sample period (one sampled too slowly without a filter) is found out there. Without a
//! clock, the travel must only lie clearly away from zero.

use serde::Serialize;

/// Share of the samples the rest's first estimate takes: the shortest interval of readings
/// holding it.
const REST_SHARE: f64 = 0.1;
/// Most rounds of the rest's estimate.
const MAX_REST_ROUNDS: usize = 40;
/// Fewest readings the rests are sought in.
const MIN_READINGS: usize = 20;
/// A sample reads the rest where it lies within this many of the noise's standard deviations.
const REST_SDS: f64 = 3.0;
/// The standard deviation of a normal distribution cut at ±[`REST_SDS`], as a share of its own.
const TRUNCATED_SD: f64 = 0.986_6;
/// A rest lasts at least this many samples: one sample reading the rest is a moving bit's
/// acceleration passing through it as often as a rest.
pub const MIN_REST_SAMPLES: usize = 2;
/// Rests the speed needs to be read.
const MIN_RESTS: usize = 3;
/// A sample moves down where its speed lies this many standard deviations above zero.
pub const MOVING_SDS: f64 = 3.0;
/// How many of its standard deviations the bit's travel summed between rests must lie from zero
/// for the channel's direction to be read off its sign, where the record has no clock.
const MIN_TRAVEL_SDS: f64 = 5.0;
/// The most the bit's travel from its first rest to its last may differ from the depth the rate
/// of penetration cut meanwhile, as a share of that depth, beyond a turn's depth of cut. On
/// simulated stick-slip records whose readings are each the acceleration's mean over their
/// period (10-50 Hz) they differ by 5-6 mm noise-free, 0.3 % of 120 s of drilling and 2 % of 20
/// s; noise makes rests of a moving bit's quiet readings and shortens the travel (to 0.97 of the
/// depth at 0.05 m/s² and 50 Hz, 0.85 at 10 Hz, 0.77 at 0.1 m/s² and 50 Hz, over 20 records of
/// 60 s each). The readings of a 50-Hz channel taken one in ten, as a logger without a filter
/// takes them, miss by 27 % over 120 s.
const MAX_TRAVEL_MISMATCH: f64 = 0.2;
/// The most the rest's reading may lie from the record's mean acceleration, as a share of the
/// readings' root mean square about the rest. A bit that comes back to rest accelerates over the
/// record by its speed's change over the record's length, on average: little beside its motion.
/// A bit off bottom in free flight reads a constant too (its drive over its mass), far from the
/// mean.
const MAX_REST_OFFSET_SHARE: f64 = 0.05;
/// Rounding's share of the readings' scale, below which a reading is the rest's where the rest
/// reads without noise.
const ROUNDING_SHARE: f64 = 1e-9;

/// What the bit's travel from rest to rest is checked against.
pub struct DepthCut<'a> {
    /// The record's sample period (s).
    pub period_s: f64,
    /// The rate of penetration (m/s), a sample each.
    pub rop_m_s: &'a [f64],
    /// A turn's depth of cut (m) on the record, as the caller reads it: the bottom's height
    /// under the blades varies around the hole by up to it, at the first rest as at the last.
    pub turn_depth_m: f64,
}

/// The bit's rests found on its axial acceleration, and the samples of it moving down.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct AxialRests {
    /// The channel's reading at rest (m/s²): gravity's share and the sensor's offset.
    pub rest_m_s2: f64,
    /// The standard deviation of the channel's noise at rest (m/s²).
    pub noise_m_s2: f64,
    /// Spells at rest, each at least [`MIN_REST_SAMPLES`] samples long.
    pub rests: usize,
    /// Samples at rest.
    pub rest_samples: usize,
    /// Whether the channel reads upward positive: the bit, summed from rest to rest, went up.
    pub upward_positive: bool,
    /// The bit's travel from its first rest to its last (m, downward), where the record has a
    /// clock.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub travel_m: Option<f64>,
    /// The depth the rate of penetration cut from the first rest to the last (m), where the
    /// record has a clock.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub depth_cut_m: Option<f64>,
    /// Per sample: moving down, its speed more than [`MOVING_SDS`] standard deviations above
    /// zero.
    #[serde(skip)]
    pub moving_down: Vec<bool>,
}

/// The rests of the bit whose axial acceleration (m/s², either sign downward, any constant
/// offset) is `acceleration`, one reading a sample; with `depth_cut`, the record's clock and rate
/// of penetration to check the bit's travel by. Why they cannot be found otherwise, as said to
/// the user.
pub fn axial_rests(acceleration: &[f64], depth_cut: Option<DepthCut<'_>>) -> Result<AxialRests, String> {
    if let Some(i) = acceleration.iter().position(|a| !a.is_finite()) {
        return Err(format!("its reading at data row {} is not a number", i + 1));
    }
    let (rest, noise, at_rest) = rest_reading(acceleration)?;
    let n = acceleration.len();
    let rests = (0..n).filter(|&i| at_rest[i] && (i == 0 || !at_rest[i - 1])).count();
    if rests < MIN_RESTS {
        return Err(format!(
            "it shows {rests} spells at rest (at least {MIN_REST_SAMPLES} samples within \
             {REST_SDS:.0} standard deviations of its noise of one reading): at least {MIN_RESTS} \
             are needed"
        ));
    }
    let rms = (acceleration.iter().map(|a| (a - rest).powi(2)).sum::<f64>() / n as f64).sqrt();
    let mean = acceleration.iter().sum::<f64>() / n as f64;
    if (mean - rest).abs() > MAX_REST_OFFSET_SHARE * rms {
        return Err(format!(
            "its quiet spells read {rest:.3} m/s², {:.3} m/s² from its mean over the record (more \
             than {:.0} % of its readings' {rms:.3} m/s² root mean square about them), where a \
             bit that comes back to rest reads its rest: they are no rests (a bit off bottom in \
             free flight reads a constant too), and a record sampled too slowly for a held spell \
             to last two samples shows none",
            (mean - rest).abs(),
            100.0 * MAX_REST_OFFSET_SHARE
        ));
    }
    let rest_samples = at_rest.iter().filter(|r| **r).count();
    let (speed, sd) = bridged_speeds(acceleration, rest, noise, &at_rest, rest_samples);
    // Between two rests a bit on bottom moves down by what it cuts: summed, the bridged speeds
    // are the depth it cut, positive where the channel reads downward positive.
    let (travel, travel_sd) = travel_between_rests(&speed, noise, &at_rest);
    if travel.abs() <= MIN_TRAVEL_SDS * travel_sd || travel == 0.0 {
        return Err(format!(
            "the bit's travel from rest to rest, summed, lies {:.1} standard deviations of its \
             noise from zero (more than {MIN_TRAVEL_SDS:.0} are needed): the channel does not \
             show a bit that moves down by what it cuts (an accelerometer's readings must each \
             be the mean over their sample period)",
            travel.abs() / travel_sd.max(f64::MIN_POSITIVE)
        ));
    }
    let travel_m = depth_cut.as_ref().map(|d| {
        let first = at_rest.iter().position(|r| *r).unwrap_or(0);
        let last = at_rest.iter().rposition(|r| *r).unwrap_or(0);
        let cut_m = d.rop_m_s[first..=last].iter().sum::<f64>() * d.period_s;
        (travel * d.period_s * d.period_s, cut_m)
    });
    if let (Some((moved, cut)), Some(d)) = (travel_m, &depth_cut)
        && !(cut > 0.0 && (moved.abs() - cut).abs() <= MAX_TRAVEL_MISMATCH * cut + d.turn_depth_m)
    {
        return Err(format!(
            "the bit's travel from its first rest (data row {}) to its last (data row {}), {:.3} \
             m by the acceleration summed at a sample period of {:.4} s, is not the depth the rate \
             of penetration cut meanwhile, {cut:.3} m (within {:.0} % and a turn's depth of cut, \
             {:.1} mm): the readings are not each the acceleration's mean over its sample period, \
             the clock is not the record's, or the rate of penetration is not the bit's",
            at_rest.iter().position(|r| *r).unwrap_or(0) + 1,
            at_rest.iter().rposition(|r| *r).unwrap_or(0) + 1,
            moved.abs(),
            d.period_s,
            100.0 * MAX_TRAVEL_MISMATCH,
            1e3 * d.turn_depth_m
        ));
    }
    let upward_positive = travel < 0.0;
    let sign = if upward_positive { -1.0 } else { 1.0 };
    let floor = ROUNDING_SHARE * rms;
    let moving_down = speed
        .iter()
        .zip(&sd)
        .map(|(v, s)| sign * v > MOVING_SDS * s + floor)
        .collect();
    Ok(AxialRests {
        rest_m_s2: rest,
        noise_m_s2: noise,
        rests,
        rest_samples,
        upward_positive,
        travel_m: travel_m.map(|(moved, _)| moved.abs()),
        depth_cut_m: travel_m.map(|(_, cut)| cut),
        moving_down,
    })
}

/// The channel's reading at rest, its noise's standard deviation and the samples at rest: the
/// middle of the shortest interval holding [`REST_SHARE`] of the readings first, its half-width
/// taken as [`REST_SDS`] of the noise's standard deviation (too little where the rest holds more
/// of the samples, as it does); then, until they stay the same, the samples within [`REST_SDS`]
/// of it in runs of at least [`MIN_REST_SAMPLES`], their mean and their spread (a spread cut
/// short grows by about three quarters a round).
fn rest_reading(acceleration: &[f64]) -> Result<(f64, f64, Vec<bool>), String> {
    let n = acceleration.len();
    let mut sorted = acceleration.to_vec();
    sorted.sort_by(f64::total_cmp);
    let held = ((REST_SHARE * n as f64) as usize).max(MIN_REST_SAMPLES);
    if n < MIN_READINGS {
        return Err(format!("it has {n} readings: at least {MIN_READINGS} are needed"));
    }
    let (start, width) = (0..=n - held)
        .map(|i| (i, sorted[i + held - 1] - sorted[i]))
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .expect("at least one interval");
    let mut rest = sorted[start] + 0.5 * width;
    let mut noise = 0.5 * width / REST_SDS;
    let scale = acceleration.iter().map(|a| (a - rest).abs()).fold(0.0, f64::max);
    if scale == 0.0 {
        return Err("it reads one value throughout: the bit never moved".into());
    }
    let mut at_rest = vec![false; n];
    for round in 0..=MAX_REST_ROUNDS {
        let within = (REST_SDS * noise).max(ROUNDING_SHARE * scale);
        let quiet: Vec<bool> = acceleration.iter().map(|a| (a - rest).abs() <= within).collect();
        let next = runs_of_at_least(&quiet, MIN_REST_SAMPLES);
        if next == at_rest {
            break;
        }
        if round == MAX_REST_ROUNDS {
            return Err(format!(
                "its rests did not settle in {MAX_REST_ROUNDS} rounds (the samples within \
                 {REST_SDS:.0} standard deviations of its noise of one reading kept changing)"
            ));
        }
        at_rest = next;
        let readings: Vec<f64> = (0..n).filter(|&i| at_rest[i]).map(|i| acceleration[i]).collect();
        if readings.is_empty() {
            break;
        }
        rest = readings.iter().sum::<f64>() / readings.len() as f64;
        let square = readings.iter().map(|a| (a - rest).powi(2)).sum::<f64>() / readings.len() as f64;
        noise = square.sqrt() / TRUNCATED_SD;
    }
    Ok((rest, noise, at_rest))
}

/// `flags` kept only where they stand in runs of at least `length`.
fn runs_of_at_least(flags: &[bool], length: usize) -> Vec<bool> {
    let mut out = vec![false; flags.len()];
    let mut i = 0;
    while i < flags.len() {
        let end = flags[i..].iter().position(|f| !f).map_or(flags.len(), |k| i + k);
        if end - i >= length {
            out[i..end].fill(true);
        }
        i = end.max(i + 1);
    }
    out
}

/// The bit's travel from rest to rest, summed over the spells between two rests (the
/// acceleration's unit times a period squared), and its standard deviation: a bridge of L
/// samples sums to a travel whose variance is `noise`²·L·(L² − 1)/12.
fn travel_between_rests(speed: &[f64], noise: f64, at_rest: &[bool]) -> (f64, f64) {
    let (mut travel, mut variance) = (0.0, 0.0);
    let first = at_rest.iter().position(|r| *r);
    let last = at_rest.iter().rposition(|r| *r);
    let (Some(first), Some(last)) = (first, last) else {
        return (0.0, 0.0);
    };
    let mut i = first;
    while i < last {
        if at_rest[i] {
            i += 1;
            continue;
        }
        let end = at_rest[i..].iter().position(|r| *r).map_or(last, |k| i + k);
        let length = (end - i) as f64;
        travel += speed[i..end].iter().sum::<f64>();
        variance += noise * noise * length * (length * length - 1.0) / 12.0;
        i = end;
    }
    (travel, variance.sqrt())
}

/// Each sample's speed (the acceleration's unit times a period; zero at rest) and its standard
/// deviation: summed from the rest before and bridged to the rest after (a Brownian bridge: its
/// spread `noise`·√(m·(L − m)/L) at the m-th of L samples, the rest's reading's error cancelled),
/// summed from the rest before only or back from the rest after only at the record's ends (the
/// rest's reading's error, `noise` over √`rest_samples`, then adding m times itself); no speed
/// (an infinite spread) where neither is.
fn bridged_speeds(
    acceleration: &[f64],
    rest: f64,
    noise: f64,
    at_rest: &[bool],
    rest_samples: usize,
) -> (Vec<f64>, Vec<f64>) {
    let n = acceleration.len();
    let mut speed = vec![0.0; n];
    let mut sd = vec![0.0; n];
    let rest_error_sq = noise * noise / rest_samples.max(1) as f64;
    let mut i = 0;
    while i < n {
        if at_rest[i] {
            i += 1;
            continue;
        }
        let end = at_rest[i..].iter().position(|r| *r).map_or(n, |k| i + k);
        let length = end - i;
        let mut sums = Vec::with_capacity(length);
        let mut sum = 0.0;
        for a in &acceleration[i..end] {
            sum += a - rest;
            sums.push(sum);
        }
        let total = sum;
        let (before, after) = (i > 0, end < n);
        for (k, s) in sums.iter().enumerate() {
            let m = (k + 1) as f64;
            let l = length as f64;
            let (v, var) = match (before, after) {
                (true, true) => (s - m / l * total, noise * noise * m * (l - m) / l),
                (true, false) => (*s, noise * noise * m + m * m * rest_error_sq),
                (false, true) => (s - total, noise * noise * (l - m) + (l - m).powi(2) * rest_error_sq),
                (false, false) => (0.0, f64::INFINITY),
            };
            speed[i + k] = v;
            sd[i + k] = var.sqrt();
        }
        i = end;
    }
    (speed, sd)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand::rngs::StdRng;
    use rand_distr::{Distribution, Normal};

    /// A bit that rests for `rest` samples, then moves down for ten, its speed (in a period's
    /// worth of acceleration) 8·sin(π·k/10) at the end of the k-th, `cycles` times: each
    /// sample's acceleration and whether it moves down at its end.
    fn stick_slip(cycles: usize, rest: usize) -> (Vec<f64>, Vec<bool>) {
        let speed = |k: usize| 8.0 * (std::f64::consts::PI * k as f64 / 10.0).sin();
        let (mut a, mut moving) = (Vec::new(), Vec::new());
        for _ in 0..cycles {
            a.extend(std::iter::repeat_n(0.0, rest));
            moving.extend(std::iter::repeat_n(false, rest));
            for k in 1..=10 {
                let end = if k == 10 { 0.0 } else { speed(k) };
                a.push(end - speed(k - 1));
                moving.push(k < 10);
            }
        }
        (a, moving)
    }

    #[test]
    fn the_cut_normal_s_spread_is_its_closed_form() {
        // √(1 − 2·k·φ(k)/(2Φ(k) − 1)) at k = 3, Φ by Simpson's rule over the density.
        let k = REST_SDS;
        let density = |x: f64| (-0.5 * x * x).exp() / (2.0 * std::f64::consts::PI).sqrt();
        let mass = crate::numerics::simpson(density, -k, k, 10_000);
        let exact = (1.0 - 2.0 * k * density(k) / mass).sqrt();
        assert!((exact - TRUNCATED_SD).abs() < 1e-4, "{exact}");
    }

    #[test]
    fn noise_free_the_samples_moving_down_are_the_bit_s_own_whatever_the_offset_and_sign() {
        let (a, moving) = stick_slip(20, 6);
        for (offset, sign) in [(0.0, 1.0), (9.81, 1.0), (-3.0, -1.0)] {
            let read: Vec<f64> = a.iter().map(|x| offset + sign * x).collect();
            let r = axial_rests(&read, None).unwrap();
            assert_eq!(r.moving_down, moving, "offset {offset}, sign {sign}");
            assert_eq!((r.rests, r.upward_positive), (20, sign < 0.0));
            assert!((r.rest_m_s2 - offset).abs() < 1e-12 && r.noise_m_s2 < 1e-12, "{r:?}");
        }
    }

    #[test]
    fn with_noise_every_sample_told_moving_moves_and_most_that_move_are_told() {
        let (a, moving) = stick_slip(200, 6);
        let truly = moving.iter().filter(|m| **m).count();
        for (sd, share) in [(0.01, 0.95), (0.05, 0.95), (0.1, 0.9)] {
            let mut rng = StdRng::seed_from_u64(7);
            let noise = Normal::new(0.0, sd).unwrap();
            let read: Vec<f64> = a.iter().map(|x| 0.3 + x + noise.sample(&mut rng)).collect();
            let r = axial_rests(&read, None).unwrap();
            let told = r.moving_down.iter().filter(|m| **m).count();
            let wrong = r.moving_down.iter().zip(&moving).filter(|(t, m)| **t && !**m).count();
            // The bridge's three standard deviations: one in 700 wrong expected, more beside a
            // rest that a reading beyond three standard deviations cut short (1 of 1,801 at
            // each noise here: the same draws, scaled).
            assert!(wrong <= told / 200, "noise {sd}: {wrong} of {told} wrong");
            assert!(told as f64 >= share * truly as f64, "noise {sd}: {told} of {truly}");
            let (rest, noise) = (r.rest_m_s2, r.noise_m_s2);
            assert!((noise - sd).abs() < 0.1 * sd, "noise {sd}: {noise}");
            assert!((rest - 0.3).abs() < 0.1 * sd, "noise {sd}: {rest}");
        }
    }

    #[test]
    fn the_bit_s_travel_from_rest_to_rest_is_checked_against_the_depth_cut() {
        // A sample period of 0.02 s: the speeds 8·sin(π·k/10) are in 0.02 m/s² times 0.02 s.
        let (a, moving) = stick_slip(20, 6);
        let period = 0.02;
        let speed: Vec<f64> = a
            .iter()
            .scan(0.0, |v, x| {
                *v += x * period;
                Some(*v)
            })
            .collect();
        // The bit cuts as fast as it moves down: its rate of penetration is its speed.
        let rop: Vec<f64> = speed.iter().map(|v| v.max(0.0)).collect();
        let depth_cut = |rop_m_s| DepthCut {
            period_s: period,
            rop_m_s,
            turn_depth_m: 0.0,
        };
        let r = axial_rests(&a, Some(depth_cut(&rop))).unwrap();
        let (moved, cut) = (r.travel_m.unwrap(), r.depth_cut_m.unwrap());
        assert!((moved - cut).abs() < 1e-9 * cut, "{moved} m for {cut} m");
        assert_eq!(r.moving_down, moving);
        // A rate of penetration a third lower: the sums are not the bit's travel.
        let slower: Vec<f64> = rop.iter().map(|v| v / 1.5).collect();
        let e = axial_rests(&a, Some(depth_cut(&slower))).unwrap_err();
        assert!(e.contains("not the depth"), "{e}");
    }

    #[test]
    fn without_rests_nothing_is_told_and_the_reason_is_said() {
        // Sampled too slowly for a rest to last two samples: a moving bit's quiet readings are
        // taken for rests, and found out.
        let (a, _) = stick_slip(30, 1);
        let e = axial_rests(&a, None).unwrap_err();
        assert!(e.contains("no rests") && e.contains("sampled too slowly"), "{e}");
        let alternating: Vec<f64> = (0..100).map(|i| if i % 2 == 0 { 1.0 } else { -1.0 }).collect();
        let e = axial_rests(&alternating, None).unwrap_err();
        assert!(e.contains("0 spells at rest"), "{e}");
        // A bit in free flight half the time reads its drive over its mass, a constant: its
        // quiet spells lie far from the mean.
        let mut flight = Vec::new();
        for _ in 0..30 {
            flight.extend([4.0; 8]);
            flight.extend([-6.0, -2.0, -10.0, -5.0]);
        }
        let e = axial_rests(&flight, None).unwrap_err();
        assert!(e.contains("no rests"), "{e}");
        let e = axial_rests(&[1.0; 50], None).unwrap_err();
        assert!(e.contains("never moved"), "{e}");
        let e = axial_rests(&[0.0, 0.0, f64::NAN, 1.0], None).unwrap_err();
        assert!(e.contains("data row 3"), "{e}");
    }
}
