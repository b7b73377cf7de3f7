//! The coupled axial-torsional bit's runs: one string simulated to its record and regime, a
//! regime map over top-drive speed and weight on bit (or feed), and a drilling record's
//! calibration with the regimes' probabilities over its posterior. The command and Python fill
//! one [`Settings`] and get the same reports.

use crate::data::drilling::DrillingRecord;
use crate::error::{Error, Result};
use crate::eval::Backend;
use crate::fit::coupled::{CoupledCalibration, bit_of, calibrate};
use crate::run::strings::ADVICE_CONFIDENCE;
use crate::simulate::Profile;
use crate::simulate::coupled::well::CoupledWell;
use crate::simulate::coupled::{
    self, Assembly, Axial, Bit, CoupledJob, CoupledState, CoupledSummary, Regime, Sample, Schedule, Steady,
};
use crate::stability::lumped::Lumped;
use crate::stability::map::parse_axis;
use crate::units::{M_S_PER_M_H, RAD_S_PER_RPM};
use serde::{Deserialize, Serialize};

pub use crate::simulate::coupled::DEFAULT_FEED_M_H;

/// Posterior draws a calibration's intervals are read from.
pub const CALIBRATION_DRAWS: usize = 4_000;

/// String steps per second above any machine's: a work estimate at this rate is a lower bound.
const FASTEST_STRING_STEPS_PER_S: f64 = 1e12;

/// Memory a string of a map holds at once on the host and the device (its job, summary and, on
/// the device, its state and ring), bytes, with room to spare.
const BYTES_PER_STRING: f64 = 2048.0;

/// Everything a coupled-bit run is made from, in the units the command and Python speak.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Settings {
    /// Top-drive speed Ω₀ (rpm).
    pub omega_rpm: f64,
    /// A constant weight on the bit assembly (kN); the drive where given.
    pub wob_kn: Option<f64>,
    /// The top fed down at this rate (m/h) where no weight is given ([`DEFAULT_FEED_M_H`] where
    /// neither is).
    pub feed_m_h: Option<f64>,
    /// The bit and the rock, its fields named as settings of their own (`radius_m`, `zeta`, …).
    #[serde(flatten)]
    pub bit: Bit,
    /// The string's equivalent inertia I (kg·m²).
    pub inertia_kg_m2: f64,
    /// The string's natural frequency ω_n (rad/s).
    pub omega_n_rad_s: f64,
    /// The string's torsional damping ratio ξ.
    pub damping_ratio: f64,
    /// Mass of the bit assembly M (kg).
    pub mass_kg: f64,
    /// Axial stiffness of the string K_a (kN/m), felt under a feed.
    pub axial_stiffness_kn_m: f64,
    /// Axial damping on the bit assembly C_a (kN·s/m).
    pub axial_damping_kns_m: f64,
    /// Recorded duration (s).
    pub duration_s: f64,
    /// Simulated time before recording (s).
    pub settle_s: f64,
    /// Sample rate of the record (Hz).
    pub sample_hz: f64,
    /// Integration step (s).
    pub dt_s: f64,
    /// Bit-speed kick from steady drilling at t = 0 (rpm).
    pub kick_rpm: f64,
    /// The map's top-drive speeds (rpm), MIN:MAX:COUNT.
    pub map_rpm: String,
    /// The map's weights on bit (kN), MIN:MAX:COUNT, under a weight.
    pub map_wob_kn: String,
    /// The map's feeds (m/h), MIN:MAX:COUNT, under a feed.
    pub map_feed_m_h: String,
    /// The map from where the bit is (at `omega_rpm` under the drive, settled): whether each
    /// cell ends the motion it is in, rather than whether steady drilling starts to vibrate.
    pub escape: bool,
    /// Posterior draws each cell of a calibrated map is simulated for.
    pub samples: usize,
    /// Candidates of each structure in a choice of structure's reference table.
    pub reference: usize,
    /// Records re-simulated from each structure to check a choice of structure.
    pub replicates: usize,
    /// Seed of the calibration's posterior draws and of a choice's candidates and noise.
    pub seed: u64,
    /// Where the map's strings are integrated.
    pub backend: Backend,
}

impl Default for Settings {
    fn default() -> Self {
        let assembly = Assembly::default();
        Self {
            omega_rpm: 60.0,
            wob_kn: None,
            feed_m_h: None,
            bit: Bit::default(),
            inertia_kg_m2: assembly.torsion.inertia_kg_m2,
            omega_n_rad_s: assembly.torsion.omega_n_rad_s,
            damping_ratio: assembly.torsion.damping_ratio,
            mass_kg: assembly.mass_kg,
            axial_stiffness_kn_m: assembly.axial_stiffness_n_per_m / 1e3,
            axial_damping_kns_m: assembly.axial_damping_ns_per_m / 1e3,
            duration_s: 60.0,
            settle_s: coupled::DEFAULT_SETTLE_S,
            sample_hz: coupled::DEFAULT_SAMPLE_HZ,
            dt_s: coupled::DEFAULT_DT_S,
            kick_rpm: coupled::DEFAULT_KICK_RPM,
            map_rpm: "20:200:10".into(),
            map_wob_kn: "80:280:9".into(),
            map_feed_m_h: "10:60:6".into(),
            escape: false,
            samples: 20,
            reference: 300,
            replicates: 10,
            seed: 1,
            backend: Backend::Auto,
        }
    }
}

impl Settings {
    /// The drill string, validated.
    pub fn assembly(&self) -> Result<Assembly> {
        let torsion = Lumped {
            inertia_kg_m2: self.inertia_kg_m2,
            omega_n_rad_s: self.omega_n_rad_s,
            damping_ratio: self.damping_ratio,
        };
        Assembly::of_units(
            torsion,
            self.mass_kg,
            self.axial_stiffness_kn_m,
            self.axial_damping_kns_m,
        )
    }

    /// The schedule, validated.
    pub fn schedule(&self) -> Result<Schedule> {
        Schedule::new(self.dt_s, self.sample_hz, self.settle_s, self.duration_s)
    }

    /// Whether the bit is fed (no weight given).
    pub fn is_feed(&self) -> bool {
        self.wob_kn.is_none()
    }

    /// The drive's value: the weight (kN), else the feed (m/h), [`DEFAULT_FEED_M_H`] where
    /// neither is given.
    pub fn drive(&self) -> f64 {
        self.wob_kn.or(self.feed_m_h).unwrap_or(DEFAULT_FEED_M_H)
    }

    /// A string of `bit` at `omega_rpm` under the drive, its value `drive` (kN or m/h) where
    /// given, else the settings' own; validated.
    pub fn job(&self, bit: Bit, omega_rpm: f64, drive: Option<f64>) -> Result<CoupledJob> {
        let value = drive.unwrap_or(self.drive());
        let axial = if self.is_feed() {
            Axial::Feed {
                rate_m_s: value * M_S_PER_M_H,
            }
        } else {
            Axial::Weight { wob_n: value * 1e3 }
        };
        let job = CoupledJob {
            bit,
            omega_rad_s: omega_rpm * RAD_S_PER_RPM,
            axial,
            kick_rad_s: self.kick_rpm * RAD_S_PER_RPM,
        };
        job.validate()?;
        job.check_step(self.dt_s)?;
        Ok(job)
    }

    /// The map's speeds (rpm) and its second axis: weights (kN) or feeds (m/h). The other
    /// drive's axis, set to other than its default, is refused: the drive decides which the
    /// map is over.
    pub fn axes(&self) -> Result<(Vec<f64>, Vec<f64>)> {
        let default = Settings::default();
        if self.is_feed() && self.map_wob_kn != default.map_wob_kn {
            return Err(Error::setting(
                "map_wob_kn",
                format!(
                    "maps weights on bit, which needs `wob_kn`: without it the string is fed \
                     (`feed_m_h`, {DEFAULT_FEED_M_H} m/h where not given) and the map is over \
                     `map_feed_m_h`"
                ),
            ));
        }
        if !self.is_feed() && self.map_feed_m_h != default.map_feed_m_h {
            return Err(Error::setting(
                "map_feed_m_h",
                "maps feeds, the drive without `wob_kn`: under `wob_kn` the map is over `map_wob_kn`",
            ));
        }
        let rpm = parse_axis(&self.map_rpm, "map_rpm")?;
        let axis = if self.is_feed() {
            parse_axis(&self.map_feed_m_h, "map_feed_m_h")?
        } else {
            parse_axis(&self.map_wob_kn, "map_wob_kn")?
        };
        Ok((rpm, axis))
    }
}

/// What a string did while recorded, in the units the command prints.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SummaryReport {
    pub regime: Regime,
    pub rop_m_h: f64,
    pub stuck_share: f64,
    pub off_bottom_share: f64,
    pub backward_share: f64,
    pub period_s: Option<f64>,
    pub bit_speed_rpm: Range,
    pub wob_kn: Range,
    pub torque_knm: Range,
    pub samples: u32,
    pub diverged: bool,
}

/// A channel's least, greatest and mean value over the recorded samples.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Range {
    pub min: f64,
    pub max: f64,
    pub mean: f64,
}

impl SummaryReport {
    pub fn of(s: &CoupledSummary, sample_hz: f64) -> Self {
        Self {
            regime: s.regime(),
            rop_m_h: s.rate_m_s() * 3600.0,
            stuck_share: s.stuck_share(),
            off_bottom_share: s.off_bottom_share(),
            backward_share: f64::from(s.backward) / f64::from(s.samples.max(1)),
            period_s: s.period_s(sample_hz),
            bit_speed_rpm: Range {
                min: s.speed_min_rad_s / RAD_S_PER_RPM,
                max: s.speed_max_rad_s / RAD_S_PER_RPM,
                mean: s.speed_mean_rad_s() / RAD_S_PER_RPM,
            },
            wob_kn: Range {
                min: s.wob_min_n / 1e3,
                max: s.wob_max_n / 1e3,
                mean: s.wob_mean_n() / 1e3,
            },
            torque_knm: Range {
                min: s.torque_min_nm / 1e3,
                max: s.torque_max_nm / 1e3,
                mean: s.torque_mean_nm() / 1e3,
            },
            samples: s.samples,
            diverged: s.diverged,
        }
    }
}

/// Steady drilling at a string's drive.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct SteadyReport {
    pub depth_of_cut_mm: f64,
    pub rop_m_h: f64,
    pub wob_kn: f64,
    pub torque_knm: f64,
}

impl SteadyReport {
    fn of(s: &Steady, blades: u32) -> Self {
        Self {
            depth_of_cut_mm: 1e3 * f64::from(blades) * s.depth_per_blade_m,
            rop_m_h: s.rate_m_s * 3600.0,
            wob_kn: s.wob_n / 1e3,
            torque_knm: s.torque_nm / 1e3,
        }
    }
}

/// One string: what it did and what steady drilling would have been.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct One {
    #[serde(flatten)]
    pub summary: SummaryReport,
    pub steady: SteadyReport,
    /// Said where the bit was off bottom nearly throughout ([`off_bottom_warning`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub warning: Option<String>,
}

/// Share of a record off bottom from which the bit is said to have bounced clear of the rock
/// nearly throughout (the rest are landings).
pub const OFF_BOTTOM_THROUGHOUT: f64 = 0.9;

/// What a record spent off bottom nearly throughout is worth, said where the bit was off
/// bottom for at least [`OFF_BOTTOM_THROUGHOUT`] of it (`None` otherwise).
pub fn off_bottom_warning(summary: &SummaryReport) -> Option<String> {
    (summary.samples > 0 && summary.off_bottom_share >= OFF_BOTTOM_THROUGHOUT).then(|| {
        format!(
            "the bit was off bottom for {:.0} % of the record: it bounced clear of the rock nearly throughout, \
             and its forces and rate of penetration are those of its landings, not of cutting",
            100.0 * summary.off_bottom_share
        )
    })
}

/// One string at the settings' speed and drive, each recorded sample given to `on_sample`.
pub fn one(settings: &Settings, on_sample: &mut dyn FnMut(&Sample)) -> Result<One> {
    check_escape_start(settings, false, false, true)?;
    let assembly = settings.assembly()?;
    let schedule = settings.schedule()?;
    let job = settings.job(settings.bit, settings.omega_rpm, None)?;
    let summary = SummaryReport::of(
        &coupled::integrate_with(&assembly, &schedule, &job, on_sample),
        settings.sample_hz,
    );
    Ok(One {
        warning: off_bottom_warning(&summary),
        summary,
        steady: SteadyReport::of(&job.steady(&assembly), job.bit.blades),
    })
}

/// One segment of a well: where it starts, its drive, what the bit did and what steady
/// drilling there would have been.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct WellSegment {
    pub name: String,
    /// First recorded time of the segment (s from the record's start).
    pub start_s: f64,
    /// Time recorded (s): whole sample periods.
    pub duration_s: f64,
    /// The top drive's speed (rpm): a value, or a ramp `{from, to}`.
    pub omega_rpm: Profile,
    /// The weight (kN) or the feed (m/h) the segment is drilled under, each likewise.
    pub drive: WellDrive,
    #[serde(flatten)]
    pub summary: SummaryReport,
    /// Steady drilling at the segment's drive (at its end, where it ramps).
    pub steady: SteadyReport,
    /// Said where the bit was off bottom nearly throughout the segment.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub warning: Option<String>,
}

/// What holds a segment's bit down, as the well file gives it.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct WellDrive {
    #[serde(skip_serializing_if = "Option::is_none")]
    pub wob_kn: Option<Profile>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub feed_m_h: Option<Profile>,
}

/// A well drilled by one string through its segments, each recorded sample given to
/// `on_sample` with its segment's index. Segments after one whose bit ran away are not drilled
/// (the report ends with that one, `diverged`).
pub fn well(well: &CoupledWell, on_sample: &mut dyn FnMut(usize, &Sample)) -> Result<Vec<WellSegment>> {
    let runs = well.simulate(on_sample)?;
    Ok(runs
        .iter()
        .zip(&well.segments)
        .map(|(run, segment)| {
            let summary = SummaryReport::of(&run.summary, well.sample_hz);
            WellSegment {
                name: segment.name.clone(),
                start_s: run.start_s,
                duration_s: run.duration_s,
                omega_rpm: segment.omega_rpm,
                drive: WellDrive {
                    wob_kn: segment.wob_kn,
                    feed_m_h: segment.feed_m_h,
                },
                warning: off_bottom_warning(&summary),
                summary,
                steady: SteadyReport::of(&segment.job_at_end().steady(&well.assembly), segment.job.bit.blades),
            }
        })
        .collect())
}

/// A well's record, the command's CSV and Python's `record`: each sample's segment (its index
/// in the well), and the string's columns ([`record_columns`]), the top-drive speed (rpm) of
/// each the one that drove the sample's period.
pub fn well_record_columns(
    well: &CoupledWell,
    samples: &[(usize, Sample)],
) -> (Vec<usize>, Vec<(&'static str, Vec<f64>)>) {
    let record: Vec<Sample> = samples.iter().map(|(_, s)| *s).collect();
    let mut in_segment = (usize::MAX, 0u32);
    let top_drive: Vec<f64> = samples
        .iter()
        .map(|(i, _)| {
            in_segment = if in_segment.0 == *i {
                (*i, in_segment.1 + 1)
            } else {
                (*i, 0)
            };
            well.segments[*i].top_drive_rpm(in_segment.1)
        })
        .collect();
    let columns = record_columns(&record, &|k| top_drive[k]);
    (samples.iter().map(|(i, _)| *i).collect(), columns)
}

/// A string's record as named columns in the units their names carry, the command's CSV and
/// Python's `record`: what a rig streams from the surface (the top drive's speed of sample `k`,
/// `top_drive_rpm(k)`, and the surface torque), then the bit's channels.
pub fn record_columns(samples: &[Sample], top_drive_rpm: &dyn Fn(usize) -> f64) -> Vec<(&'static str, Vec<f64>)> {
    let column = |f: &dyn Fn(&Sample) -> f64| samples.iter().map(f).collect::<Vec<f64>>();
    vec![
        ("time_s", column(&|s| s.time_s)),
        ("top_drive_rpm", (0..samples.len()).map(top_drive_rpm).collect()),
        ("surface_torque_knm", column(&|s| s.surface_torque_nm / 1e3)),
        ("bit_speed_rpm", column(&|s| s.bit_speed_rad_s / RAD_S_PER_RPM)),
        ("torque_on_bit_knm", column(&|s| s.torque_nm / 1e3)),
        ("wob_kn", column(&|s| s.wob_n / 1e3)),
        ("axial_speed_m_h", column(&|s| s.axial_speed_m_s * 3600.0)),
        ("axial_acceleration_m_s2", column(&|s| s.axial_acceleration_m_s2)),
        ("rop_m_h", column(&|s| s.cutting_rate_m_s * 3600.0)),
        ("depth_of_cut_mm", column(&|s| s.depth_per_blade_m * 1e3)),
    ]
}

/// The map's axes and where its strings ran.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Axes {
    pub omega_rpm: Vec<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub wob_kn: Option<Vec<f64>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub feed_m_h: Option<Vec<f64>>,
    /// Strings simulated.
    pub strings: usize,
    pub backend: String,
}

impl Axes {
    /// The second axis' values.
    pub fn drive(&self) -> &[f64] {
        self.wob_kn.as_deref().or(self.feed_m_h.as_deref()).unwrap_or_default()
    }

    /// The second axis' name and unit: `wob_kn`, kN, or `feed_m_h`, m/h.
    pub fn drive_axis(&self) -> (&'static str, &'static str) {
        if self.wob_kn.is_some() {
            ("wob_kn", "kN")
        } else {
            ("feed_m_h", "m/h")
        }
    }
}

/// A regime map: one string per cell, speeds down, drives across.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Map {
    #[serde(flatten)]
    pub axes: Axes,
    pub cells: Vec<Vec<SummaryReport>>,
}

/// Each regime's probability in a cell of a calibrated map.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct CellProbabilities {
    pub steady: f64,
    pub stick_slip: f64,
    pub bit_bounce: f64,
    pub both: f64,
    pub diverged: f64,
    /// The median of the draws' rates of penetration (m/h).
    pub rop_median_m_h: f64,
}

impl CellProbabilities {
    /// The regimes' shares among the strings of `draws`, one a posterior draw.
    fn of<'a>(draws: impl ExactSizeIterator<Item = &'a CoupledSummary> + Clone) -> Self {
        let n = draws.len() as f64;
        let share = |regime: Regime| draws.clone().filter(|s| s.regime() == regime).count() as f64 / n;
        let rates: Vec<f64> = draws.clone().map(|s| s.rate_m_s() * 3600.0).collect();
        Self {
            steady: share(Regime::Steady),
            stick_slip: share(Regime::StickSlip),
            bit_bounce: share(Regime::BitBounce),
            both: share(Regime::Both),
            diverged: share(Regime::Diverged),
            rop_median_m_h: crate::numerics::quantile(&rates, 0.5),
        }
    }

    /// The probability the bit vibrates: stick-slip, bounce, both (or runs away).
    pub fn vibrating(&self) -> f64 {
        self.stick_slip + self.bit_bounce + self.both + self.diverged
    }
}

/// A calibrated map: each cell simulated for every posterior draw.
#[derive(Clone, Debug, Serialize)]
pub struct PosteriorMap {
    #[serde(flatten)]
    pub axes: Axes,
    pub samples: usize,
    pub probabilities: Vec<Vec<CellProbabilities>>,
}

/// Every string of `jobs` on the settings' backend, from steady drilling or `start` (a GPU
/// fallback said through `note`).
fn integrate(
    settings: &Settings,
    assembly: &Assembly,
    schedule: &Schedule,
    jobs: &[CoupledJob],
    start: Option<&CoupledState>,
    note: &mut dyn FnMut(String),
) -> Result<(Vec<CoupledSummary>, String)> {
    let (summaries, ran) = crate::eval::coupled::integrate(assembly, schedule, jobs, start, settings.backend, note)?;
    Ok((summaries, ran.to_string()))
}

/// The map's jobs for each of `bits`, cell by cell (speeds outer, drives inner, bits innermost),
/// an `escape` map's axes holding the start's speed and drive; refused before they are made
/// where they would take more than a day even at [`FASTEST_STRING_STEPS_PER_S`], or more memory
/// than there is.
fn map_jobs(settings: &Settings, bits: &[Bit], escape: bool) -> Result<(Vec<f64>, Vec<f64>, Vec<CoupledJob>)> {
    let (mut rpm, mut axis) = settings.axes()?;
    if escape {
        // The way out is read at the start's own speed and drive.
        with_value(&mut rpm, settings.omega_rpm);
        with_value(&mut axis, settings.drive());
    }
    let strings = (rpm.len() * axis.len() * bits.len()) as f64;
    let schedule = settings.schedule()?;
    let what = format!("simulating {strings} coupled strings of {} s", schedule.seconds());
    crate::limits::check_work(
        "map_rpm",
        strings * schedule.steps() as f64,
        FASTEST_STRING_STEPS_PER_S,
        &what,
    )?;
    crate::limits::check_memory("map_rpm", strings * BYTES_PER_STRING, &what)?;
    let mut jobs = Vec::with_capacity(rpm.len() * axis.len() * bits.len());
    for &r in &rpm {
        for &a in &axis {
            for b in bits {
                jobs.push(settings.job(*b, r, Some(a))?);
            }
        }
    }
    Ok((rpm, axis, jobs))
}

/// `axis` (ascending) with `value` in its place, where it is not there already.
fn with_value(axis: &mut Vec<f64>, value: f64) {
    if !axis.iter().any(|v| (v - value).abs() <= 1e-9 * value.abs().max(1.0)) {
        let at = axis.partition_point(|v| *v < value);
        axis.insert(at, value);
    }
}

fn axes(settings: &Settings, omega_rpm: Vec<f64>, axis: Vec<f64>, strings: usize, backend: String) -> Axes {
    let (wob_kn, feed_m_h) = if settings.is_feed() {
        (None, Some(axis))
    } else {
        (Some(axis), None)
    };
    Axes {
        omega_rpm,
        wob_kn,
        feed_m_h,
        strings,
        backend,
    }
}

/// The regime map of the settings' bit.
pub fn map(settings: &Settings, note: &mut dyn FnMut(String)) -> Result<Map> {
    let assembly = settings.assembly()?;
    let schedule = settings.schedule()?;
    let (rpm, axis, jobs) = map_jobs(settings, &[settings.bit], false)?;
    let (summaries, ran) = integrate(settings, &assembly, &schedule, &jobs, None, note)?;
    Ok(Map {
        cells: rows(&summaries, axis.len(), settings.sample_hz),
        axes: axes(settings, rpm, axis, jobs.len(), ran),
    })
}

/// The summaries of a map's cells as rows of `width` reports.
fn rows(summaries: &[CoupledSummary], width: usize, sample_hz: f64) -> Vec<Vec<SummaryReport>> {
    summaries
        .chunks(width)
        .map(|row| row.iter().map(|s| SummaryReport::of(s, sample_hz)).collect())
        .collect()
}

/// The bit calibrated on `record` (its radius the settings'), with the settings' seed.
pub fn calibration(record: &DrillingRecord, settings: &Settings) -> Result<CoupledCalibration> {
    settings.bit.validate()?;
    calibrate(record, settings.bit.radius_m, CALIBRATION_DRAWS, settings.seed)
}

/// The regimes' probabilities per cell over the first `samples` of the calibration's draws that
/// make a bit within bounds (its radius, contact stress, γ and blades the settings').
pub fn posterior_map(
    settings: &Settings,
    calibration: &CoupledCalibration,
    note: &mut dyn FnMut(String),
) -> Result<PosteriorMap> {
    if settings.escape {
        return Err(Error::setting(
            "escape",
            "a calibrated map from steady drilling has no way out to read; the escape map is posterior_escape_map's",
        ));
    }
    let bits = posterior_bits(settings, calibration)?;
    let assembly = settings.assembly()?;
    let schedule = settings.schedule()?;
    let (rpm, axis, jobs) = map_jobs(settings, &bits, false)?;
    let (summaries, ran) = integrate(settings, &assembly, &schedule, &jobs, None, note)?;
    let cells: Vec<CellProbabilities> = summaries
        .chunks(bits.len())
        .map(|draws| CellProbabilities::of(draws.iter()))
        .collect();
    Ok(PosteriorMap {
        samples: bits.len(),
        probabilities: cells.chunks(axis.len()).map(<[CellProbabilities]>::to_vec).collect(),
        axes: axes(settings, rpm, axis, jobs.len(), ran),
    })
}

/// The bits of the first `samples` of the calibration's draws that are within bounds (their
/// radius, contact stress, γ and blades the settings').
fn posterior_bits(settings: &Settings, calibration: &CoupledCalibration) -> Result<Vec<Bit>> {
    if settings.samples == 0 {
        return Err(Error::setting("samples", "must be at least 1"));
    }
    let template = settings.bit;
    let bits: Vec<Bit> = calibration
        .draws
        .iter()
        .map(|d| bit_of(d, &template))
        .filter(|b| b.validate().is_ok())
        .take(settings.samples)
        .collect();
    if bits.len() < settings.samples {
        return Err(Error::setting(
            "samples",
            format!(
                "the calibration's draws give only {} bits within the physical bounds",
                bits.len()
            ),
        ));
    }
    Ok(bits)
}

/// Where a calibrated escape map starts: the operating point, and the regimes' probabilities
/// there over the posterior's draws.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PosteriorEscapeFrom {
    pub omega_rpm: f64,
    /// The drive there: kN under a weight, m/h under a feed.
    pub drive: f64,
    pub probabilities: CellProbabilities,
}

/// The way out read off a calibrated escape map. A change ends the motion where the draws'
/// strings, each continued from the state its own bit is in at the start, drill steadily with
/// at least [`ADVICE_CONFIDENCE`] (a string that left physical bounds has not ended it); as on
/// one bit's escape map, from that speed (or drive) on, every cell of the start's column (or
/// row) must, so the advice never lands in a band where a faster or lighter change keeps it.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PosteriorEscapeAdvice {
    /// The probability a way out ends the motion with, at least.
    pub confidence: f64,
    /// The draws drill steadily at the start with that probability already.
    pub steady_already: bool,
    /// The slowest speed above the start's, in the start's drive column (an escape map holds
    /// the start's speed and drive), from which on the column ends it: (rpm, the probability it
    /// ends there).
    pub faster_rpm: Option<(f64, f64)>,
    /// The drive nearest the start's, below it, in the start's speed row, from which down the
    /// row ends it: (kN or m/h, the probability).
    pub lighter_drive: Option<(f64, f64)>,
    pub words: String,
}

/// A calibrated escape map: each posterior draw's bit settled at the start, then continued
/// from there in every cell.
#[derive(Clone, Debug, Serialize)]
pub struct PosteriorEscapeMap {
    #[serde(flatten)]
    pub map: PosteriorMap,
    pub from: PosteriorEscapeFrom,
    pub advice: PosteriorEscapeAdvice,
}

/// Refuses an escape map with no start to read: `escape` without `map`, and a calibrated
/// bit's without the top drive's speed (`speed_given`: given, not defaulted) and the weight or
/// feed the record's bit was drilling at, which no default knows.
pub fn check_escape_start(settings: &Settings, map: bool, calibrated: bool, speed_given: bool) -> Result<()> {
    if !settings.escape {
        return Ok(());
    }
    let needs = "the calibrated escape map starts where the record's bit was drilling";
    if !map {
        Err(Error::setting("escape", "an escape map is a map: ask for the map too"))
    } else if calibrated && !speed_given {
        Err(Error::setting(
            "omega_rpm",
            format!("{needs}: give the top drive's speed then"),
        ))
    } else if calibrated && settings.wob_kn.is_none() && settings.feed_m_h.is_none() {
        Err(Error::setting(
            "wob_kn",
            format!("{needs}: give the weight on bit (`wob_kn`) or the feed (`feed_m_h`) then"),
        ))
    } else {
        Ok(())
    }
}

/// The calibrated escape map from the settings' `omega_rpm` under its drive: every draw's bit
/// settled there (steady drilling first, `settle_s` + `duration_s`, the rock surface
/// included), then each cell continued from the state that bit is in.
pub fn posterior_escape_map(
    settings: &Settings,
    calibration: &CoupledCalibration,
    note: &mut dyn FnMut(String),
) -> Result<PosteriorEscapeMap> {
    let bits = posterior_bits(settings, calibration)?;
    let assembly = settings.assembly()?;
    let schedule = settings.schedule()?;
    let (rpm, axis, _) = map_jobs(settings, &bits, true)?;
    let starts = bits
        .iter()
        .map(|bit| settings.job(*bit, settings.omega_rpm, None))
        .collect::<Result<Vec<_>>>()?;
    let (at_start, states): (Vec<CoupledSummary>, Vec<CoupledState>) = {
        use rayon::prelude::*;
        starts
            .par_iter()
            .map(|here| coupled::integrate_from(&assembly, &schedule, here, None, &mut |_| {}))
            .unzip()
    };
    let mut per_bit = Vec::with_capacity(bits.len());
    let mut ran = String::new();
    // Each draw's map runs on its own; what the backend says is said once.
    let mut said = std::collections::HashSet::new();
    let mut once = |line: String| {
        if said.insert(line.clone()) {
            note(line);
        }
    };
    for (bit, state) in bits.iter().zip(&states) {
        let (_, _, jobs) = map_jobs(settings, &[*bit], true)?;
        let (summaries, backend) = integrate(settings, &assembly, &schedule, &jobs, Some(state), &mut once)?;
        per_bit.push(summaries);
        ran = backend;
    }
    let cells = rpm.len() * axis.len();
    let probabilities: Vec<CellProbabilities> = (0..cells)
        .map(|c| CellProbabilities::of(per_bit.iter().map(|summaries| &summaries[c])))
        .collect();
    let from = PosteriorEscapeFrom {
        omega_rpm: settings.omega_rpm,
        drive: settings.drive(),
        probabilities: CellProbabilities::of(at_start.iter()),
    };
    let rows: Vec<Vec<CellProbabilities>> = probabilities.chunks(axis.len()).map(<[_]>::to_vec).collect();
    let advice = advise_posterior(settings, &rpm, &axis, &rows, &from, bits.len());
    Ok(PosteriorEscapeMap {
        map: PosteriorMap {
            samples: bits.len(),
            probabilities: rows,
            axes: axes(settings, rpm, axis, cells * bits.len(), ran),
        },
        from,
        advice,
    })
}

/// The way out read off a calibrated escape map's cells.
fn advise_posterior(
    settings: &Settings,
    rpm: &[f64],
    axis: &[f64],
    cells: &[Vec<CellProbabilities>],
    from: &PosteriorEscapeFrom,
    draws: usize,
) -> PosteriorEscapeAdvice {
    let ends = |i: usize, j: usize| cells[i][j].steady >= ADVICE_CONFIDENCE;
    let (column, row) = (nearest(axis, from.drive), nearest(rpm, from.omega_rpm));
    let (unit, drive_name, lighter) = drive_words(settings);
    let of_draws = |p: f64| format!("{} of {draws} draws", (p * draws as f64).round());
    let p = &from.probabilities;
    let left = if p.diverged > 0.0 {
        format!(", out of physical bounds {:.2}", p.diverged)
    } else {
        String::new()
    };
    let motion = format!(
        "the calibrated bit vibrates at {} rpm and {} {unit} with P = {:.2} (stick-slip {:.2}, bounce {:.2}, both {:.2}{left})",
        from.omega_rpm,
        from.drive,
        p.vibrating(),
        p.stick_slip,
        p.bit_bounce,
        p.both
    );
    if from.probabilities.steady >= ADVICE_CONFIDENCE {
        return PosteriorEscapeAdvice {
            confidence: ADVICE_CONFIDENCE,
            steady_already: true,
            faster_rpm: None,
            lighter_drive: None,
            words: format!(
                "the calibrated bit drills steadily at {} rpm and {} {unit} with P = {:.2}: nothing to escape",
                from.omega_rpm, from.drive, from.probabilities.steady
            ),
        };
    }
    let faster_rpm = (0..rpm.len())
        .filter(|&i| i > row)
        .find(|&i| (i..rpm.len()).all(|k| ends(k, column)))
        .map(|i| (rpm[i], cells[i][column].steady));
    let lighter_drive = (0..axis.len())
        .rev()
        .filter(|&j| j < column)
        .find(|&j| (0..=j).all(|k| ends(row, k)))
        .map(|j| (axis[j], cells[row][j].steady));
    let mut ways = Vec::new();
    if let Some((r, p)) = faster_rpm {
        ways.push(format!("turning at {r} rpm (it ends for {})", of_draws(p)));
    }
    if let Some((d, p)) = lighter_drive {
        ways.push(format!(
            "lowering {drive_name} to {d} {unit} (it ends for {})",
            of_draws(p)
        ));
    }
    let words = if ways.is_empty() {
        format!("{motion}, and no speed or {lighter} on this map ends it with P ≥ {ADVICE_CONFIDENCE}")
    } else {
        format!("{motion}: {} ends it", ways.join(", or "))
    };
    PosteriorEscapeAdvice {
        confidence: ADVICE_CONFIDENCE,
        steady_already: false,
        faster_rpm,
        lighter_drive,
        words,
    }
}

/// The drive's unit, its name and its lighter change, in words.
fn drive_words(settings: &Settings) -> (&'static str, &'static str, &'static str) {
    if settings.is_feed() {
        ("m/h", "the feed", "slower feed")
    } else {
        ("kN", "the weight on bit", "lighter weight")
    }
}

/// Where an escape map starts: the bit's operating point, what it does there.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct EscapeFrom {
    pub omega_rpm: f64,
    /// The drive there: kN under a weight, m/h under a feed.
    pub drive: f64,
    pub summary: SummaryReport,
}

/// The way out of the motion at the start read off an escape map: the slowest speed at the
/// start's drive, and the lightest change of the drive at the start's speed, where the bit
/// drills steadily.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct EscapeAdvice {
    /// The start's speed and drive are steady already.
    pub steady_already: bool,
    /// The slowest speed of the map above the start's, in the start's drive column (an escape
    /// map holds the start's speed and drive), from which on the column drills steadily (rpm).
    pub faster_rpm: Option<f64>,
    /// The drive of the map nearest the start's, below it, in the start's speed row, from which
    /// down the row drills steadily (kN or m/h).
    pub lighter_drive: Option<f64>,
    pub words: String,
}

/// An escape map: every cell continued from the state the bit is in at the start.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct EscapeMap {
    #[serde(flatten)]
    pub map: Map,
    pub from: EscapeFrom,
    pub advice: EscapeAdvice,
}

/// The index of the value of `axis` nearest `v`.
fn nearest(axis: &[f64], v: f64) -> usize {
    (0..axis.len())
        .min_by(|&a, &b| (axis[a] - v).abs().total_cmp(&(axis[b] - v).abs()))
        .expect("an axis has values")
}

/// The escape map of the settings' bit from where it is at `omega_rpm` under its drive.
pub fn escape_map(settings: &Settings, note: &mut dyn FnMut(String)) -> Result<EscapeMap> {
    let assembly = settings.assembly()?;
    let schedule = settings.schedule()?;
    let bit = settings.bit;
    let here = settings.job(bit, settings.omega_rpm, None)?;
    let (at_start, state) = coupled::integrate_from(&assembly, &schedule, &here, None, &mut |_| {});
    let (rpm, axis, jobs) = map_jobs(settings, &[bit], true)?;
    let (summaries, ran) = integrate(settings, &assembly, &schedule, &jobs, Some(&state), note)?;
    let cells = rows(&summaries, axis.len(), settings.sample_hz);
    let from = EscapeFrom {
        omega_rpm: settings.omega_rpm,
        drive: settings.drive(),
        summary: SummaryReport::of(&at_start, settings.sample_hz),
    };
    let advice = advise(settings, &rpm, &axis, &cells, &from);
    Ok(EscapeMap {
        map: Map {
            cells,
            axes: axes(settings, rpm, axis, jobs.len(), ran),
        },
        from,
        advice,
    })
}

/// The way out read off the escape map's cells.
fn advise(
    settings: &Settings,
    rpm: &[f64],
    axis: &[f64],
    cells: &[Vec<SummaryReport>],
    from: &EscapeFrom,
) -> EscapeAdvice {
    let steady = |i: usize, j: usize| cells[i][j].regime == Regime::Steady;
    let (column, row) = (nearest(axis, from.drive), nearest(rpm, from.omega_rpm));
    let (unit, drive_name, lighter) = drive_words(settings);
    if from.summary.regime == Regime::Steady {
        return EscapeAdvice {
            steady_already: true,
            faster_rpm: None,
            lighter_drive: None,
            words: format!(
                "the bit drills steadily at {} rpm and {} {unit}: nothing to escape",
                from.omega_rpm, from.drive
            ),
        };
    }
    // The first speed above the start's from which the whole column is steady.
    let faster_rpm = (0..rpm.len())
        .filter(|&i| i > row)
        .find(|&i| (i..rpm.len()).all(|k| steady(k, column)))
        .map(|i| rpm[i]);
    let lighter_drive = (0..axis.len())
        .rev()
        .filter(|&j| j < column)
        .find(|&j| (0..=j).all(|k| steady(row, k)))
        .map(|j| axis[j]);
    let mut ways = Vec::new();
    if let Some(r) = faster_rpm {
        ways.push(format!("turning at {r} rpm"));
    }
    if let Some(d) = lighter_drive {
        ways.push(format!("lowering {drive_name} to {d} {unit}"));
    }
    let words = if ways.is_empty() {
        format!(
            "the bit is in {} at {} rpm and {} {unit}, and no speed or {lighter} on this map ends it",
            from.summary.regime.name(),
            from.omega_rpm,
            from.drive,
        )
    } else {
        format!(
            "the bit is in {} at {} rpm and {} {unit}: {} ends it",
            from.summary.regime.name(),
            from.omega_rpm,
            from.drive,
            ways.join(", or ")
        )
    };
    EscapeAdvice {
        steady_already: false,
        faster_rpm,
        lighter_drive,
        words,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_bits_fields_are_settings_of_their_own_and_unknown_names_are_refused() {
        let fields = crate::run::settings::fields::<Settings>();
        for name in [
            "radius_m",
            "intrinsic_energy_mpa",
            "zeta",
            "contact_stress_mpa",
            "wear_flat_mm",
            "friction",
            "gamma",
            "blades",
        ] {
            assert!(fields.iter().any(|f| f == name), "{name} in {fields:?}");
        }
        assert!(!fields.iter().any(|f| f == "bit"));
        let s: Settings = serde_json::from_str(r#"{"radius_m": 0.1, "blades": 5, "omega_rpm": 90}"#).unwrap();
        let given = Bit {
            radius_m: 0.1,
            blades: 5,
            ..Bit::default()
        };
        assert_eq!((s.bit, s.omega_rpm.to_bits()), (given, 90f64.to_bits()));
        let unknown = serde_json::from_str::<Settings>(r#"{"radius_m": 0.1, "radius": 0.2}"#);
        assert!(unknown.unwrap_err().to_string().contains("radius"));
    }
}
