//! What the surface implies at the bit: its speed on the record's clock from posterior draws,
//! and the simulated escape advice where it stick-slips.

use super::*;
use crate::run::advice::RECORD_ESCAPE_MIN_PROBABILITY;

/// The bit as the surface implies it: the posterior medians of its `stuck_share` and
/// `severity`, at the top drive's mean speed and the record's mean weight on bit (where
/// recorded): what the advice takes for the bit seen.
pub fn implied_bit(record: &SurfaceRecord, stuck_share: f64, severity: f64) -> crate::data::BitSeen {
    crate::data::BitSeen {
        samples: record.time_s.len(),
        stuck_share,
        severity: Some(severity),
        mean_speed_rpm: record.mean_top_drive_rad_s() / RAD_S_PER_RPM,
        peak_speed_rpm: None,
        mean_wob_kn: record.wob_n.is_some().then(|| mean_wob_n(record, None) / 1000.0),
    }
}

/// The bit's speed on the record's clock from posterior draws (see [`AtTheBit`]).
pub(super) fn at_the_bit(model: &SurfaceModel, particles: &[Particle], draws: usize, seed: u64) -> Result<AtTheBit> {
    let all: Vec<&Particle> = particles.iter().collect();
    let drawn = resample(&all, draws, seed ^ 0x4249_5400);
    // The bit's speed and stuck share carry no measurement noise: the strings as they are.
    let runs = model.simulate_noiseless_many(&strings_of(&drawn))?;
    let good: Vec<_> = runs.iter().filter(|r| !r.diverged).collect();
    let n = model.drive.omega_rad_s.len();
    let three = |mut v: Vec<f64>| -> [f64; 3] {
        if v.is_empty() {
            return [f64::NAN; 3];
        }
        v.sort_by(f64::total_cmp);
        [0.05, 0.5, 0.95].map(|q| crate::numerics::quantile_of_sorted(&v, q))
    };
    let speed_rpm = (0..n)
        .map(|k| three(good.iter().map(|r| r.bit_speed_rad_s[k] / RAD_S_PER_RPM).collect()))
        .collect();
    let reduced: Vec<(Law, Summary)> = drawn
        .iter()
        .zip(&runs)
        .filter(|(_, r)| !r.diverged)
        .map(|(p, r)| {
            let mut s = Summary::default();
            for (w, t) in r.bit_speed_rad_s.iter().zip(&r.surface_torque_nm) {
                s.push(*w, f64::NAN, *t);
            }
            (p.law, s)
        })
        .collect();
    let reductions: Vec<Summary> = reduced.iter().map(|r| r.1).collect();
    let mut laws: Vec<Law> = reduced.iter().map(|r| r.0).collect();
    laws.sort();
    laws.dedup();
    let stuck_share_by_law = laws
        .into_iter()
        .map(|law| {
            let shares: Vec<f64> = reduced
                .iter()
                .filter(|r| r.0 == law)
                .map(|r| r.1.stuck_share())
                .collect();
            (law, shares.len(), three(shares))
        })
        .collect();
    Ok(AtTheBit {
        draws: drawn.len(),
        speed_rpm,
        stuck_share: three(reductions.iter().map(Summary::stuck_share).collect()),
        severity: three(
            reductions
                .iter()
                .map(Summary::severity)
                .filter(|s| s.is_finite())
                .collect(),
        ),
        stick_slip_probability: reductions.iter().filter(|s| s.stick_slips()).count() as f64
            / reductions.len().max(1) as f64,
        stuck_share_by_law,
        diverged: runs.len() - good.len(),
        advice: None,
        spread_advice: None,
    })
}

/// Posterior samples per law for the simulated advice.
pub(super) const ADVICE_SAMPLES: usize = 20;

/// The record's mean weight on bit, N; without a WOB channel, `w_ref_n` or the paper's. Without
/// a reference weight the laws were inferred at r = 1: their parameters hold at this weight,
/// which is then their reference.
pub fn mean_wob_n(record: &SurfaceRecord, w_ref_n: Option<f64>) -> f64 {
    record.wob_n.as_ref().map_or_else(
        || w_ref_n.unwrap_or(crate::laws::PAPER_W_REF_N),
        |w| w.iter().sum::<f64>() / w.len() as f64,
    )
}

/// What a surface run's way out rests on that its record does not tell: the parameters of the
/// laws the advice simulates (`taking_part`) that the record leaves to their prior boxes. The
/// cycle at one top-drive speed does not say how the torque falls with speed (m2's g): strings
/// whose cycle matches the record's may leave it at speeds far apart. `None` where every such
/// parameter is identified.
pub fn unidentified_caveat(laws: &[LawPosterior], taking_part: &dyn Fn(Law) -> bool) -> Option<String> {
    let named = open_parameters(laws, taking_part);
    (!named.is_empty()).then(|| {
        format!(
            "; but the record leaves {} to the prior, and the way out depends on {}: the speed or weight that ends the stick-slip may lie further (the cycle seen at a second top-drive speed, or a downhole record, tells)",
            named.join(", "),
            if named.len() == 1 { "it" } else { "them" }
        )
    })
}

/// The parameters of the laws with particles and `taking_part` that the record leaves to
/// their prior boxes, named as `m2's g`.
fn open_parameters(laws: &[LawPosterior], taking_part: &dyn Fn(Law) -> bool) -> Vec<String> {
    laws.iter()
        .filter(|l| l.particles > 0 && taking_part(l.law))
        .flat_map(|l| {
            l.params
                .iter()
                .filter(|p| !p.identified)
                .map(move |p| format!("{}'s {}", l.law, p.name))
        })
        .collect()
}

/// Where along each parameter the record leaves open a way out is scanned: the posterior's
/// quantiles there, dense in its tails, where the escape changes fastest (m2's between g = 0.1
/// and 1 s/rad: on a string inferred with the law, the 2 %, quartiles and 98 % alone miss the
/// g of a bit their advice leaves stuck; docs/surface.md, item 9).
const OPEN_QUANTILES: [f64; 11] = [0.01, 0.02, 0.05, 0.1, 0.25, 0.5, 0.75, 0.9, 0.95, 0.98, 0.99];

/// For each law at least [`RECORD_ESCAPE_MIN_PROBABILITY`] likely whose parameters the
/// record leaves to their prior boxes (`laws`' unidentified ones), the posterior particles
/// at the [`OPEN_QUANTILES`] of each such parameter (the first particle, in the parameter's
/// order, whose share of the law's weight up to it exceeds the quantile: the inverse of the
/// posterior's distribution, a particle's own value), each as many
/// strings of the law's probability; such a law the record identifies whole keeps its drawn
/// samples. A way out must end every one of these strings: the record cannot say which of them
/// is the bit's (the escape speed need not grow toward a box's end: m2's stick-slip at 60 rpm
/// needs 165 rpm at g = 0.1 s/rad, 85 rpm at 1 and vanishes at 0.02 and 10). Empty where the
/// record leaves nothing open.
fn along_open_parameters(inputs: &[LawSamples], laws: &[LawPosterior], particles: &[Particle]) -> Vec<LawSamples> {
    let open_of = |law: Law| -> Vec<usize> {
        laws.iter()
            .find(|l| l.law == law)
            .map(|l| (0..l.params.len()).filter(|&j| !l.params[j].identified).collect())
            .unwrap_or_default()
    };
    if inputs.iter().all(|input| open_of(input.law).is_empty()) {
        return Vec::new();
    }
    inputs
        .iter()
        .filter(|input| input.probability >= RECORD_ESCAPE_MIN_PROBABILITY)
        .map(|input| {
            let open = open_of(input.law);
            let own: Vec<&Particle> = particles.iter().filter(|p| p.law == input.law).collect();
            if open.is_empty() || own.is_empty() {
                return input.clone();
            }
            let mut chosen: Vec<&Particle> = Vec::new();
            for &j in &open {
                let mut sorted = own.clone();
                sorted.sort_by(|a, b| a.params[j].total_cmp(&b.params[j]));
                let weights: Vec<f64> = sorted.iter().map(|p| p.weight).collect();
                let cdf = crate::abc::smc::normalised_cdf(&weights);
                for q in OPEN_QUANTILES {
                    chosen.push(sorted[crate::abc::smc::inverse_cdf(&cdf, q)]);
                }
            }
            crate::abc::posterior::law_samples_of(input.law, input.probability, input.map_si.clone(), &chosen)
        })
        .collect()
}

/// The simulated escape advice from the record's mean operating point, in words, and, where
/// the record leaves parameters of the laws to their prior boxes, the way out scanned again
/// along the posterior's spread of them ([`along_open_parameters`]). Where the run inferred
/// the string (`string`), every sample is simulated on its own, not on `chain`.
#[allow(clippy::too_many_arguments)]
pub(super) fn escape_advice(
    record: &SurfaceRecord,
    settings: &SurfaceSettings,
    backend: Backend,
    chain: &Chain,
    string: Option<InferredString>,
    laws: &[LawPosterior],
    particles: &[Particle],
    note: &mut dyn FnMut(String),
) -> Result<(String, Option<SpreadAdvice>)> {
    use crate::run::strings::{OperatingPoint, SimulatedSettings, Simulator, advice_speeds_rpm, advice_weights_kn};
    let wob_n = mean_wob_n(record, settings.w_ref_n);
    let w_ref_n = settings.w_ref_n.unwrap_or(wob_n);
    let inputs: Vec<LawSamples> = laws
        .iter()
        .filter(|l| l.particles > 0)
        .map(|l| {
            let own: Vec<&Particle> = particles.iter().filter(|p| p.law == l.law).collect();
            crate::abc::posterior::law_samples_of(
                l.law,
                l.probability,
                l.params.iter().map(|p| p.median).collect(),
                &resample(&own, ADVICE_SAMPLES, 0x4144_5649),
            )
        })
        .collect();
    let simulated = SimulatedSettings {
        string,
        ..SimulatedSettings::new(chain.clone(), w_ref_n, backend)
    };
    let mut simulator = Simulator::new(&simulated, &inputs, note)?;
    let point = OperatingPoint {
        omega_rpm: record.mean_top_drive_rad_s() / RAD_S_PER_RPM,
        wob_kn: wob_n / 1000.0,
    };
    let at = simulator.at_point(point)?;
    let advice = simulator.escape_advice(
        &at,
        &advice_speeds_rpm(point.omega_rpm),
        &advice_weights_kn(point.wob_kn),
    )?;
    // Every law with particles is simulated (`inputs` above).
    let caveat = unidentified_caveat(laws, &|_| true).filter(|_| advice.speed_rpm.is_some() || advice.wob_kn.is_some());
    let mut text = advice.text() + caveat.as_deref().unwrap_or("");
    match spread_way_out(&simulated, &inputs, laws, particles, point, note)? {
        Some((words, spread)) => {
            text.push_str(&words);
            Ok((text, Some(spread)))
        }
        None => Ok((text, None)),
    }
}

/// The way out from `point` on `simulated` along the posterior's spread of what `laws` leave
/// open ([`along_open_parameters`] of the drawn `inputs` and the `particles` they were drawn
/// from): the words the advice adds and the advice; `None` where the laws taking part leave
/// nothing open. Every string must end: the record cannot say which of them is the bit's.
pub(crate) fn spread_way_out(
    simulated: &crate::run::strings::SimulatedSettings,
    inputs: &[LawSamples],
    laws: &[LawPosterior],
    particles: &[Particle],
    point: crate::run::strings::OperatingPoint,
    note: &mut dyn FnMut(String),
) -> Result<Option<(String, SpreadAdvice)>> {
    use crate::run::strings::{Simulator, advice_speeds_rpm, advice_weights_kn};
    let spread = along_open_parameters(inputs, laws, particles);
    let names = open_parameters(laws, &|law| spread.iter().any(|s| s.law == law));
    if names.is_empty() {
        return Ok(None);
    }
    let mut simulator = Simulator::new(simulated, &spread, note)?;
    let at = simulator.at_point(point)?;
    let open = simulator.escape_advice_with(
        &at,
        &advice_speeds_rpm(point.omega_rpm),
        &advice_weights_kn(point.wob_kn),
        1.0,
    )?;
    let words = format!(
        "; to end it in every string along the posterior's spread of {} ({} of its quantiles, {} % to {} %): {}",
        names.join(", "),
        OPEN_QUANTILES.len(),
        100.0 * OPEN_QUANTILES[0],
        100.0 * OPEN_QUANTILES[OPEN_QUANTILES.len() - 1],
        open.ways()
    );
    Ok(Some((
        words,
        SpreadAdvice {
            open: names,
            speed_rpm: open.speed_rpm.map(|w| w.to),
            wob_kn: open.wob_kn.map(|w| w.to),
        },
    )))
}
