//! What the live page draws of a window beyond its update: the window's torque-speed cloud,
//! the mixture posterior's band of torque curves with each law's MAP curve, and the
//! probability of stick-slip over a map of (Ω, W) around the operating point. Made by the
//! watch for every window (the latest is kept in the watch directory), small enough to send
//! to every viewer: at most [`CLOUD_POINTS`] samples, [`BAND_SPEEDS`] speeds and
//! [`MAP_SPEEDS_RPM`] × [`MAP_WEIGHTS`] cells.

use crate::data::{BitReading, BitSeen, Row};
use crate::laws::Law;
use crate::stability::map::{Criterion, LawSamples, mixture_probability_grid};
use crate::units::{RAD_S_PER_RPM, TorqueUnit};
use serde::{Deserialize, Serialize};

/// Samples of the window drawn, evenly strided.
pub const CLOUD_POINTS: usize = 600;
/// Speeds of the band and the curves, over the window's speeds.
pub const BAND_SPEEDS: usize = 60;
/// The band's level: the paper's predictive envelope's.
pub const BAND_LEVEL: f64 = crate::abc::posterior::ENVELOPE_LEVEL;
/// The map's top-drive speeds, rpm, and its weights on bit: the advice's.
pub use crate::run::advice::{SPEEDS_RPM as MAP_SPEEDS_RPM, WEIGHTS as MAP_WEIGHTS};

/// The picture of one window.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct View {
    pub window: usize,
    /// The unit of every torque here: the record's.
    pub torque_unit: TorqueUnit,
    /// The window's samples (at most [`CLOUD_POINTS`]): bit speed, rpm, and torque.
    pub speed_rpm: Vec<f64>,
    pub torque: Vec<f64>,
    /// The same samples' times along the record, s: the strip chart's axis. Empty where the
    /// record has no clock (and in views stored without them).
    #[serde(default)]
    pub time_s: Vec<f64>,
    /// What the window's bit speed shows, over all its samples: the share stuck, the
    /// severity, the mean speed and weight on bit (`None` in views stored without it); for a
    /// window of surface channels, the bit its strings imply.
    #[serde(default)]
    pub bit: Option<BitSeen>,
    /// The bit's depth over the window, m, first and last (where the record has a depth
    /// column: [`crate::data::depth_column`]).
    #[serde(default)]
    pub depth_m: Option<[f64; 2]>,
    /// The mixture posterior's curves; `None` before the first informative window.
    pub band: Option<Band>,
    /// P(stick-slip) over (Ω, W); `None` before the first informative window.
    pub map: Option<MapView>,
    /// A window of surface channels that went through the surface sampler: what the rig
    /// streamed and the bit speed its strings imply (the cloud and the bit's strip are then
    /// empty: the window has no bit channels).
    #[serde(default)]
    pub surface: Option<SurfaceStrip>,
}

/// A window of surface channels as the strip chart draws it, at most [`CLOUD_POINTS`] of its
/// samples, evenly strided.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SurfaceStrip {
    /// Time along the record, s.
    pub time_s: Vec<f64>,
    pub top_drive_rpm: Vec<f64>,
    /// In the view's torque unit.
    pub surface_torque: Vec<f64>,
    /// The bit speed the posterior's strings imply, rpm: 5 %, median and 95 % per sample;
    /// empty where a sample has none (every draw's string left physical bounds).
    pub bit_rpm: Vec<[f64; 3]>,
}

impl SurfaceStrip {
    /// The strip of `record` (a window's, its clock from the window's start at `start_s`
    /// along the record) with the implied bit speed `bit_rpm` per sample of it.
    pub(super) fn of(record: &crate::data::surface::SurfaceRecord, start_s: f64, bit_rpm: &[[f64; 3]]) -> Self {
        let stride = record.time_s.len().div_ceil(CLOUD_POINTS).max(1);
        let per_unit = record.torque_unit.newton_metres();
        let every = |values: &[f64], per: f64| -> Vec<f64> { values.iter().step_by(stride).map(|v| v / per).collect() };
        Self {
            time_s: record.time_s.iter().step_by(stride).map(|t| start_s + t).collect(),
            top_drive_rpm: every(&record.top_drive_rad_s, RAD_S_PER_RPM),
            surface_torque: every(&record.surface_torque_nm, per_unit),
            bit_rpm: if bit_rpm.iter().flatten().all(|v| v.is_finite()) {
                bit_rpm.iter().step_by(stride).copied().collect()
            } else {
                Vec::new()
            },
        }
    }
}

/// The band of the mixture's torque curves T(w) at the window's weight on bit.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Band {
    pub speed_rpm: Vec<f64>,
    /// The central `level` interval and the median over the mixture posterior's samples
    /// (each law weighted by its carried probability), pointwise per speed.
    pub lower: Vec<f64>,
    pub median: Vec<f64>,
    pub upper: Vec<f64>,
    pub level: f64,
    /// Each law's curve at its MAP (the mode of its posterior), with its probability.
    pub curves: Vec<Curve>,
}

/// One law's MAP curve.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Curve {
    pub law: Law,
    pub probability: f64,
    pub torque: Vec<f64>,
}

/// The mixture's probability of unstable steady rotation over top-drive speed and weight on
/// bit (the watch's criterion), with the risk the advice keeps below.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MapView {
    pub omega_rpm: Vec<f64>,
    pub wob_kn: Vec<f64>,
    /// Row-major over Ω; `None` where a sample's torque has no slope (unknown, not stable).
    pub p_unstable: Vec<Option<f64>>,
    pub risk: f64,
}

pub use crate::run::advice::{speeds_rpm as map_speeds_rpm, weights_kn as map_weights_kn};

/// What the view is made from besides the window's rows.
pub(super) struct Posterior<'a> {
    /// The mixture's laws: probability, MAP and samples (SI, at the window's weight on bit).
    pub inputs: &'a [LawSamples],
    pub criterion: Criterion,
    /// The operating weight on bit, kN: the map's axis is around it and the parameters hold
    /// there (W_ref of the map).
    pub wob_kn: f64,
    pub risk: f64,
}

/// The view of window `window` from its rows (speeds in rad/s, torques in N·m) and, after
/// the first informative window, the latest posterior.
pub(super) fn view(window: usize, rows: &[Row], unit: TorqueUnit, posterior: Option<Posterior<'_>>) -> View {
    let per_unit = unit.newton_metres();
    let stride = rows.len().div_ceil(CLOUD_POINTS).max(1);
    let cloud: Vec<&Row> = rows.iter().step_by(stride).collect();
    // The bit's channels only: a surface record's torque is never drawn as the bit's.
    let readings: Vec<BitReading> = cloud.iter().filter_map(|r| r.bit).collect();
    let speed_rpm: Vec<f64> = readings.iter().map(|b| b.speed_rad_s / RAD_S_PER_RPM).collect();
    let torque: Vec<f64> = readings.iter().map(|b| b.torque_nm / per_unit).collect();
    let time_s: Vec<f64> = cloud
        .iter()
        .filter(|r| r.bit.is_some())
        .map(|r| r.time_s)
        .collect::<Option<_>>()
        .unwrap_or_default();
    let speeds: Vec<f64> = rows.iter().filter_map(|r| r.bit).map(|b| b.speed_rad_s).collect();
    let wob_n: Option<Vec<f64>> = rows.iter().map(|r| r.wob_n).collect();
    let bit = BitSeen::of(&speeds, wob_n.as_deref());
    let mut depths = rows.iter().filter_map(|r| r.depth_m);
    let depth_m = depths.next().map(|first| [first, depths.next_back().unwrap_or(first)]);
    let (band, map) = match posterior {
        Some(p) if !p.inputs.is_empty() => {
            let (lo, hi) = rows
                .iter()
                .filter_map(|r| r.bit)
                .map(|b| b.speed_rad_s)
                .filter(|w| w.is_finite())
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), w| (a.min(w), b.max(w)));
            let band = (lo < hi).then(|| {
                band(
                    p.inputs,
                    &crate::abc::posterior::speed_grid(lo, hi, BAND_SPEEDS),
                    per_unit,
                )
            });
            let (omega_rpm, wob_kn) = (map_speeds_rpm(), map_weights_kn(p.wob_kn));
            let grid = mixture_probability_grid(p.inputs, &omega_rpm, &wob_kn, p.criterion, p.wob_kn * 1000.0);
            let map = MapView {
                omega_rpm,
                wob_kn,
                p_unstable: grid.into_iter().map(|p| p.is_finite().then_some(p)).collect(),
                risk: p.risk,
            };
            (band, Some(map))
        }
        _ => (None, None),
    };
    View {
        window,
        torque_unit: unit,
        speed_rpm,
        torque,
        time_s,
        bit,
        depth_m,
        band,
        map,
        surface: None,
    }
}

/// The mixture's band and each law's MAP curve over `speeds_rad_s`, torques in the record's
/// unit (`per_unit` N·m each).
fn band(inputs: &[LawSamples], speeds_rad_s: &[f64], per_unit: f64) -> Band {
    let total: f64 = inputs.iter().map(|m| m.probability).sum();
    // Each sample weighs its law's share over its law's samples.
    let weights: Vec<f64> = inputs
        .iter()
        .flat_map(|m| {
            std::iter::repeat_n(
                m.probability / total / m.samples_si.len().max(1) as f64,
                m.samples_si.len(),
            )
        })
        .collect();
    let (q_lo, q_hi) = ((1.0 - BAND_LEVEL) / 2.0, (1.0 + BAND_LEVEL) / 2.0);
    let mut lower = Vec::with_capacity(speeds_rad_s.len());
    let mut median = Vec::with_capacity(speeds_rad_s.len());
    let mut upper = Vec::with_capacity(speeds_rad_s.len());
    for &w in speeds_rad_s {
        let t: Vec<f64> = inputs
            .iter()
            .flat_map(|m| m.samples_si.iter().map(move |s| m.law.torque(s, w, 1.0) / per_unit))
            .collect();
        let q = |level| crate::numerics::weighted_quantile(&t, &weights, level);
        let mid = q(0.5);
        median.push(mid);
        lower.push(q(q_lo).min(mid));
        upper.push(q(q_hi).max(mid));
    }
    let curves = inputs
        .iter()
        .map(|m| Curve {
            law: m.law,
            probability: m.probability / total,
            torque: speeds_rad_s
                .iter()
                .map(|&w| m.law.torque(&m.map_si, w, 1.0) / per_unit)
                .collect(),
        })
        .collect();
    Band {
        speed_rpm: speeds_rad_s.iter().map(|w| w / RAD_S_PER_RPM).collect(),
        lower,
        median,
        upper,
        level: BAND_LEVEL,
        curves,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stability::lumped::Lumped;

    fn row(w: f64, t: f64) -> Row {
        Row {
            time_s: Some(w),
            bit: Some(crate::data::BitReading {
                speed_rad_s: w,
                torque_nm: t,
            }),
            wob_n: None,
            top_drive_rad_s: None,
            surface_torque_nm: None,
            depth_m: None,
        }
    }

    #[test]
    fn one_law_at_one_point_gives_its_curve_as_the_band_and_the_cloud_in_the_record_s_unit() {
        // m4 at constant torque 5 kN·m: every sample the same, so band = median = curve.
        let params = vec![5000.0, 0.0, 0.0, 0.0];
        let inputs = [LawSamples {
            law: Law::M4,
            probability: 1.0,
            map_si: params.clone(),
            samples_si: vec![params.clone(); 10],
            strings: Vec::new(),
        }];
        let rows: Vec<Row> = (0..1500).map(|i| row(1.0 + i as f64 / 100.0, 5000.0)).collect();
        let v = view(
            3,
            &rows,
            TorqueUnit::KNm,
            Some(Posterior {
                inputs: &inputs,
                criterion: Criterion::Lumped(Lumped::default()),
                wob_kn: 100.0,
                risk: 0.05,
            }),
        );
        assert_eq!(v.window, 3);
        assert_eq!(v.speed_rpm.len(), 500, "every third of 1,500 samples");
        assert_eq!(v.torque, vec![5.0; 500], "kN·m");
        let band = v.band.unwrap();
        assert_eq!(band.speed_rpm.len(), BAND_SPEEDS);
        assert!((band.speed_rpm[0] - 1.0 / RAD_S_PER_RPM).abs() < 1e-9);
        for k in 0..BAND_SPEEDS {
            assert_eq!((band.lower[k], band.median[k], band.upper[k]), (5.0, 5.0, 5.0));
        }
        assert_eq!(band.curves[0].torque, vec![5.0; BAND_SPEEDS]);
        // A flat law has zero slope: the bit damps nothing, so the 1-DOF string is
        // unstable or stable the same at every W (its own damping decides).
        let map = v.map.unwrap();
        assert_eq!(map.p_unstable.len(), 59 * MAP_WEIGHTS);
        assert!(
            (map.wob_kn[9] - 100.0).abs() < 1e-12,
            "the window's own weight is on the map"
        );
        let first = map.p_unstable[0];
        assert!(map.p_unstable.iter().all(|p| *p == first));
    }

    #[test]
    fn before_any_posterior_only_the_cloud_and_the_strip() {
        let rows: Vec<Row> = (0..10).map(|i| row(i as f64, 1.0)).collect();
        let v = view(0, &rows, TorqueUnit::Nm, None);
        assert_eq!(v.speed_rpm.len(), 10);
        assert_eq!(v.torque, vec![1.0; 10]);
        assert_eq!(v.time_s, (0..10).map(f64::from).collect::<Vec<_>>());
        assert!(v.band.is_none() && v.map.is_none());
        // Speeds 0..9 rad/s: one sample (0) below 1 rpm; severity (9 − 0) / (2 · 4.5) = 1.
        let bit = v.bit.unwrap();
        assert_eq!((bit.samples, bit.stuck_share), (10, 0.1));
        assert!((bit.severity.unwrap() - 1.0).abs() < 1e-12);
        assert_eq!(bit.mean_wob_kn, None);
    }

    #[test]
    fn the_strip_is_every_sample_s_time_and_the_bit_is_seen_over_all_of_them() {
        // 1,500 samples, every third drawn; the bit stuck in the first 300 (0 rad/s), at 10 kN.
        let rows: Vec<Row> = (0..1500)
            .map(|i| Row {
                time_s: Some(100.0 + i as f64 * 0.02),
                wob_n: Some(10_000.0),
                ..row(if i < 300 { 0.0 } else { 6.0 }, 1.0)
            })
            .collect();
        let v = view(1, &rows, TorqueUnit::Nm, None);
        assert_eq!(v.time_s.len(), 500);
        assert_eq!((v.time_s[0], v.time_s[1]), (100.0, 100.06));
        let bit = v.bit.unwrap();
        assert_eq!((bit.samples, bit.stuck_share, bit.mean_wob_kn), (1500, 0.2, Some(10.0)));
        assert_eq!(v.depth_m, None);
        // The depth's first and last over the window, where rows carry one.
        let drilling: Vec<Row> = rows
            .iter()
            .enumerate()
            .map(|(i, r)| Row {
                depth_m: (i % 7 != 0).then_some(1500.0 + i as f64 * 0.001),
                ..*r
            })
            .collect();
        assert_eq!(
            view(1, &drilling, TorqueUnit::Nm, None).depth_m,
            Some([1500.001, 1501.499])
        );
        // A record without a clock draws no strip.
        let clockless: Vec<Row> = rows.iter().map(|r| Row { time_s: None, ..*r }).collect();
        assert!(view(1, &clockless, TorqueUnit::Nm, None).time_s.is_empty());
    }
}
