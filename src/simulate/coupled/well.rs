//! A well drilled with the coupled bit through formations: one string carried from segment to
//! segment (its lags, speeds and the rock surface its blades left), each segment with its own
//! rock and drive, for `bitrock coupled --well FILE`.
//!
//! ```toml
//! sample_hz = 50              # the recorder (default 50 Hz)
//! dt_s = 1e-4                 # integration step (default 1e-4 s)
//! settle_s = 30               # drilled at the first segment's drive before recording (default 30 s)
//! kick_rpm = 1                # the bit's speed kicked from steady drilling at the start (default 1 rpm)
//!
//! [bit]                       # one bit drills the well: radius_m, blades, wear_flat_mm, gamma
//! radius_m = 0.108            # (default: the public parameter set's)
//! blades = 4
//!
//! [string]                    # inertia_kg_m2, omega_n_rad_s, damping_ratio, mass_kg,
//! mass_kg = 40000             # axial_stiffness_kn_m, axial_damping_kns_m (default: the paper's
//!                             # torsional string over a 40-t assembly)
//! [[segment]]                 # in drilling order
//! name = "shale"              # the record's `segment` column (default: its number)
//! duration_s = 60
//! omega_rpm = 60              # a value, or [from, to]: a ramp over the segment
//! wob_kn = 100                # or feed_m_h = 30: every segment the same kind of drive (a
//!                             # value or a ramp)
//! intrinsic_energy_mpa = 40   # the rock: intrinsic_energy_mpa, zeta, contact_stress_mpa,
//! contact_stress_mpa = 40     # friction (default: the public parameter set's)
//! ```
//!
//! The bit is the well's: its radius and blades shape the ring of rock-surface cells the
//! string carries across every boundary. A new formation acts from its segment's first step,
//! on the surface the last one left. A ramp is applied at the samples and held between them.
//! Units are in the keys' names; every refusal names the file, the line and the column.

use super::{
    Assembly, Axial, Bit, CoupledJob, CoupledState, CoupledSummary, DEFAULT_DT_S, DEFAULT_FEED_M_H, DEFAULT_KICK_RPM,
    DEFAULT_SAMPLE_HZ, DEFAULT_SETTLE_S, Ramp, Sample, Schedule, integrate_ramped,
};
use crate::error::{Error, Result};
use crate::simulate::Profile;
use crate::simulate::well::ProfileFile;
use crate::stability::lumped::Lumped;
use crate::units::{M_S_PER_M_H, RAD_S_PER_RPM};
use serde::Deserialize;
use std::path::Path;
use toml::Spanned;

/// One stretch of the well: its rock and how the rig drives through it.
#[derive(Clone, Debug, PartialEq)]
pub struct CoupledSegment {
    /// The record's `segment` column.
    pub name: String,
    /// Time recorded in the segment as the file gives it (s); the record holds whole sample
    /// periods of it ([`SegmentRun::duration_s`]).
    pub duration_s: f64,
    /// The top drive's speed (rpm), and the weight (kN) or the feed (m/h), as the file gives
    /// them, each a value or a ramp (the feed at [`DEFAULT_FEED_M_H`] where it gives neither).
    pub omega_rpm: Profile,
    pub wob_kn: Option<Profile>,
    pub feed_m_h: Option<Profile>,
    /// The string of the segment: the well's bit in this rock, the top drive and the axial
    /// drive at the segment's start in SI (the kick applies to the first segment only, from
    /// steady drilling).
    pub job: CoupledJob,
    /// Where the segment ramps its drive: the ramps in SI.
    pub ramp: Option<Ramp>,
}

impl CoupledSegment {
    /// The segment's job with the drive at its end (the start's where nothing ramps).
    pub fn job_at_end(&self) -> CoupledJob {
        let Some(ramp) = &self.ramp else {
            return self.job;
        };
        let axial = match self.job.axial {
            Axial::Weight { .. } => Axial::Weight {
                wob_n: ramp.axial.at(1.0),
            },
            Axial::Feed { .. } => Axial::Feed {
                rate_m_s: ramp.axial.at(1.0),
            },
        };
        CoupledJob {
            omega_rad_s: ramp.omega_rad_s.at(1.0),
            axial,
            ..self.job
        }
    }

    /// The top drive's speed (rpm) over the sample period ending in recorded sample `j`.
    pub fn top_drive_rpm(&self, j: u32) -> f64 {
        match &self.ramp {
            Some(ramp) => ramp.drive_at(j).0 / RAD_S_PER_RPM,
            None => self.omega_rpm.at(0.0),
        }
    }
}

/// A well of [`CoupledSegment`]s drilled by one string.
#[derive(Clone, Debug, PartialEq)]
pub struct CoupledWell {
    pub segments: Vec<CoupledSegment>,
    pub assembly: Assembly,
    /// Drilled at the first segment's drive before recording starts (s).
    pub settle_s: f64,
    pub sample_hz: f64,
    pub dt_s: f64,
}

/// What one segment did while recorded.
#[derive(Clone, Debug, PartialEq)]
pub struct SegmentRun {
    pub summary: CoupledSummary,
    /// The segment's first recorded time (s from the record's start).
    pub start_s: f64,
    /// The time it recorded: its samples over the sample rate (s).
    pub duration_s: f64,
}

/// Bytes a recorded sample of a well holds where the caller keeps them (its segment and its
/// channels, with room for the columns written from them).
pub const BYTES_PER_RECORDED_SAMPLE: f64 = 256.0;

impl CoupledWell {
    /// Reads and checks the well file at `path`.
    pub fn load(path: &Path) -> Result<Self> {
        let text = crate::files::read_text(path, "a well file", crate::simulate::well::MAX_FILE_BYTES)?;
        Self::parse(&text, path)
    }

    /// The well the file text `source` describes; `path` names it in refusals.
    pub fn parse(source: &str, path: &Path) -> Result<Self> {
        let text = crate::files::UserFile { source, path };
        let at = |offset: usize, message: String| text.at(offset, message);
        let file: WellFile = text.toml()?;
        let Some(first) = file.segment.first() else {
            return Err(at(0, "the well has no [[segment]]".into()));
        };
        // The well's own keys, each refused where it stands (the start of the file where it
        // is not given).
        let key = |v: &Option<Spanned<f64>>, default: f64| v.as_ref().map_or(default, |s| *s.get_ref());
        let key_at = |v: &Option<Spanned<f64>>| v.as_ref().map_or(0, |s| s.span().start);
        let (sample_hz, dt_s, settle_s, kick_rpm) = (
            key(&file.sample_hz, DEFAULT_SAMPLE_HZ),
            key(&file.dt_s, DEFAULT_DT_S),
            key(&file.settle_s, DEFAULT_SETTLE_S),
            key(&file.kick_rpm, DEFAULT_KICK_RPM),
        );
        Schedule::new(dt_s, sample_hz, settle_s, 1.0 / sample_hz).map_err(|e| {
            let place = match &e {
                Error::InvalidSetting { field, .. } if field == "sample_hz" => key_at(&file.sample_hz),
                Error::InvalidSetting { field, .. } if field == "settle_s" => key_at(&file.settle_s),
                _ => key_at(&file.dt_s),
            };
            at(place, e.keyed())
        })?;
        if !kick_rpm.is_finite() {
            return Err(at(key_at(&file.kick_rpm), "kick_rpm: must be finite".into()));
        }
        let bit = file.bit.as_ref().map_or_else(Bit::default, |b| b.get_ref().bit());
        let bit_at = file.bit.as_ref().map_or(0, |b| b.span().start);
        bit.validate()
            .map_err(|e| at(bit_at, format!("[bit]: {}", e.keyed())))?;
        let string = file.string.as_ref();
        let assembly = string
            .map_or_else(|| Ok(Assembly::default()), |s| s.get_ref().assembly())
            .map_err(|e| at(string.map_or(0, |s| s.span().start), format!("[string]: {}", e.keyed())))?;
        let shared = Shared {
            bit,
            feed: first.get_ref().wob_kn.is_none(),
            kick_rpm,
            dt_s,
            sample_hz,
            settle_s,
        };
        let mut segments = Vec::with_capacity(file.segment.len());
        let mut steps = 0.0;
        for (i, spanned) in file.segment.iter().enumerate() {
            let (segment, cost) = spanned
                .get_ref()
                .segment(i, &shared)
                .map_err(|message| at(spanned.span().start, format!("segment {}: {message}", i + 1)))?;
            steps += cost;
            segments.push(segment);
        }
        // One string, step after step: at most a day's work even at a rate above any machine's.
        crate::limits::check_work(
            "segment",
            steps,
            crate::simulate::FASTEST_STEPS_PER_S,
            &format!("drilling the well's {} segments in steps of {dt_s} s", segments.len()),
        )
        .map_err(|e| at(0, e.keyed()))?;
        Ok(Self {
            segments,
            assembly,
            settle_s,
            sample_hz,
            dt_s,
        })
    }

    /// Segment `i`'s schedule: the settling before the first, none before the others.
    pub fn schedule(&self, i: usize) -> Result<Schedule> {
        let settle_s = if i == 0 { self.settle_s } else { 0.0 };
        Schedule::new(self.dt_s, self.sample_hz, settle_s, self.segments[i].duration_s)
    }

    /// Samples the well records, all its segments together.
    pub fn recorded_samples(&self) -> Result<u64> {
        (0..self.segments.len()).try_fold(0, |n, i| Ok(n + u64::from(self.schedule(i)?.record_samples)))
    }

    /// Refuses to keep the whole record where it would not fit in memory (`bitrock coupled
    /// --well --out`, Python's `record=True`).
    pub fn check_record_memory(&self) -> Result<()> {
        let samples = self.recorded_samples()? as f64;
        crate::limits::check_memory(
            "well",
            samples * BYTES_PER_RECORDED_SAMPLE,
            &format!("keeping the well's record ({samples:.3e} samples)"),
        )
    }

    /// Drills the well: the first segment from steady drilling at its drive (kicked), each
    /// next from where the one before left the string; `on_sample` hears every recorded
    /// sample with its segment's index, times from the record's start.
    pub fn simulate(&self, on_sample: &mut dyn FnMut(usize, &Sample)) -> Result<Vec<SegmentRun>> {
        let mut runs = Vec::with_capacity(self.segments.len());
        let mut state: Option<CoupledState> = None;
        let mut start_s = 0.0;
        for (i, segment) in self.segments.iter().enumerate() {
            let schedule = self.schedule(i)?;
            let ramp = segment.ramp.as_ref();
            let (summary, end) = integrate_ramped(
                &self.assembly,
                &schedule,
                &segment.job,
                state.as_ref(),
                ramp,
                &mut |s| {
                    let mut s = *s;
                    s.time_s += start_s;
                    on_sample(i, &s);
                },
            );
            let diverged = summary.diverged;
            let duration_s = f64::from(schedule.record_samples) / self.sample_hz;
            runs.push(SegmentRun {
                summary,
                start_s,
                duration_s,
            });
            if diverged {
                // The bit ran away: the segments after it would start from nonsense.
                break;
            }
            start_s += duration_s;
            state = Some(end);
        }
        Ok(runs)
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct WellFile {
    sample_hz: Option<Spanned<f64>>,
    dt_s: Option<Spanned<f64>>,
    settle_s: Option<Spanned<f64>>,
    kick_rpm: Option<Spanned<f64>>,
    bit: Option<Spanned<BitFile>>,
    string: Option<Spanned<StringFile>>,
    segment: Vec<Spanned<SegmentFile>>,
}

/// The well's bit: its geometry and wear, the public set's where not given.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct BitFile {
    radius_m: Option<f64>,
    blades: Option<u32>,
    wear_flat_mm: Option<f64>,
    gamma: Option<f64>,
}

impl BitFile {
    /// The bit in the public set's rock.
    fn bit(&self) -> Bit {
        let public = Bit::default();
        Bit {
            radius_m: self.radius_m.unwrap_or(public.radius_m),
            blades: self.blades.unwrap_or(public.blades),
            wear_flat_mm: self.wear_flat_mm.unwrap_or(public.wear_flat_mm),
            gamma: self.gamma.unwrap_or(public.gamma),
            ..public
        }
    }
}

/// The string: any of its values, the default assembly's where not given.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct StringFile {
    inertia_kg_m2: Option<f64>,
    omega_n_rad_s: Option<f64>,
    damping_ratio: Option<f64>,
    mass_kg: Option<f64>,
    axial_stiffness_kn_m: Option<f64>,
    axial_damping_kns_m: Option<f64>,
}

impl StringFile {
    fn assembly(&self) -> Result<Assembly> {
        let d = Assembly::default();
        let torsion = Lumped {
            inertia_kg_m2: self.inertia_kg_m2.unwrap_or(d.torsion.inertia_kg_m2),
            omega_n_rad_s: self.omega_n_rad_s.unwrap_or(d.torsion.omega_n_rad_s),
            damping_ratio: self.damping_ratio.unwrap_or(d.torsion.damping_ratio),
        };
        Assembly::of_units(
            torsion,
            self.mass_kg.unwrap_or(d.mass_kg),
            self.axial_stiffness_kn_m.unwrap_or(d.axial_stiffness_n_per_m / 1e3),
            self.axial_damping_kns_m.unwrap_or(d.axial_damping_ns_per_m / 1e3),
        )
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SegmentFile {
    name: Option<String>,
    duration_s: f64,
    omega_rpm: ProfileFile,
    wob_kn: Option<ProfileFile>,
    feed_m_h: Option<ProfileFile>,
    intrinsic_energy_mpa: Option<f64>,
    zeta: Option<f64>,
    contact_stress_mpa: Option<f64>,
    friction: Option<f64>,
}

/// What every segment of a well shares: its bit, whether it is drilled under a feed (or a
/// weight), its kick and its clock.
struct Shared {
    bit: Bit,
    feed: bool,
    kick_rpm: f64,
    dt_s: f64,
    sample_hz: f64,
    settle_s: f64,
}

impl SegmentFile {
    /// Segment `i` (from 0) of a well, checked against what the well's segments share, with
    /// the integration steps it costs; a refusal is its message, placed by the caller.
    fn segment(&self, i: usize, shared: &Shared) -> std::result::Result<(CoupledSegment, f64), String> {
        let feed = shared.feed;
        if self.wob_kn.is_some() && self.feed_m_h.is_some() {
            return Err("give wob_kn or feed_m_h, not both".into());
        }
        if self.wob_kn.is_none() != feed {
            return Err(format!(
                "the well is drilled under {} from its first segment: every segment gives {}",
                if feed { "a feed" } else { "a weight" },
                if feed {
                    format!("feed_m_h (or neither: {DEFAULT_FEED_M_H} m/h)")
                } else {
                    "wob_kn".to_string()
                },
            ));
        }
        let omega_rpm = self.omega_rpm.profile(1.0);
        let wob_kn = self.wob_kn.map(|w| w.profile(1.0));
        // The axial drive also in SI, a weight (N) or a feed (m/s).
        let (feed_m_h, axial) = match wob_kn {
            Some(w) => (None, w.scaled(1e3)),
            None => {
                let f = self
                    .feed_m_h
                    .map_or(Profile::Constant(DEFAULT_FEED_M_H), |f| f.profile(1.0));
                (Some(f), f.scaled(M_S_PER_M_H))
            }
        };
        let job_at = |fraction: f64| CoupledJob {
            bit: self.in_rock(shared.bit),
            omega_rad_s: omega_rpm.at(fraction) * RAD_S_PER_RPM,
            axial: if feed {
                Axial::Feed {
                    rate_m_s: axial.at(fraction),
                }
            } else {
                Axial::Weight {
                    wob_n: axial.at(fraction),
                }
            },
            kick_rad_s: shared.kick_rpm * RAD_S_PER_RPM,
        };
        let job = job_at(0.0);
        let ramped = matches!(omega_rpm, Profile::Ramp { .. }) || matches!(axial, Profile::Ramp { .. });
        // Both ends of a ramp are drives the string can be given (what lies between is too).
        for (fraction, end) in [(0.0, ""), (1.0, "the ramp's end: ")]
            .into_iter()
            .take(if ramped { 2 } else { 1 })
        {
            let at = job_at(fraction);
            at.validate()
                .and_then(|()| at.check_step(shared.dt_s))
                .map_err(|e| format!("{end}{}", e.keyed()))?;
        }
        if !(self.duration_s.is_finite() && self.duration_s > 0.0) {
            return Err(format!(
                "duration_s: must be positive and finite, got {}",
                self.duration_s
            ));
        }
        let settle_s = if i == 0 { shared.settle_s } else { 0.0 };
        let schedule = Schedule::new(shared.dt_s, shared.sample_hz, settle_s, self.duration_s)
            .map_err(|e| e.keyed().replacen("record_s", "duration_s", 1))?;
        let segment = CoupledSegment {
            name: self.name.clone().unwrap_or_else(|| (i + 1).to_string()),
            duration_s: self.duration_s,
            omega_rpm,
            wob_kn,
            feed_m_h,
            job,
            ramp: ramped.then_some(Ramp {
                omega_rad_s: omega_rpm.scaled(RAD_S_PER_RPM),
                axial,
                duration_s: self.duration_s,
                period_s: schedule.sample_period_s(),
            }),
        };
        Ok((segment, schedule.steps() as f64))
    }

    /// `bit` in this segment's rock (the values it gives in place of the bit's).
    fn in_rock(&self, bit: Bit) -> Bit {
        Bit {
            intrinsic_energy_mpa: self.intrinsic_energy_mpa.unwrap_or(bit.intrinsic_energy_mpa),
            zeta: self.zeta.unwrap_or(bit.zeta),
            contact_stress_mpa: self.contact_stress_mpa.unwrap_or(bit.contact_stress_mpa),
            friction: self.friction.unwrap_or(bit.friction),
            ..bit
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::simulate::coupled::{Regime, integrate_with};

    fn parse(text: &str) -> Result<CoupledWell> {
        CoupledWell::parse(text, Path::new("well.toml"))
    }

    fn drilled(well: &CoupledWell) -> (Vec<SegmentRun>, Vec<(usize, Sample)>) {
        let mut samples = Vec::new();
        let runs = well.simulate(&mut |i, s| samples.push((i, *s))).unwrap();
        (runs, samples)
    }

    #[test]
    fn a_well_of_one_rock_and_drive_is_the_single_string_carried_on() {
        // Stick-slipping (the public bit at 60 rpm under 150 kN): the state crosses the
        // boundary mid-cycle, ring and all.
        let well = parse(
            "settle_s = 10\n[[segment]]\nduration_s = 10\nomega_rpm = 60\nwob_kn = 150\n\
             [[segment]]\nname = \"on\"\nduration_s = 15\nomega_rpm = 60\nwob_kn = 150\n",
        )
        .unwrap();
        let (runs, samples) = drilled(&well);
        assert_eq!((runs.len(), runs[1].start_s), (2, 10.0));
        let schedule = Schedule::new(1e-4, 50.0, 10.0, 25.0).unwrap();
        let mut single = Vec::new();
        let whole = integrate_with(&well.assembly, &schedule, &well.segments[0].job, &mut |s| {
            single.push(*s)
        });
        assert!(whole.stuck > 0, "the test string stick-slips");
        assert_eq!(samples.len(), single.len());
        for (k, ((segment, a), b)) in samples.iter().zip(&single).enumerate() {
            assert_eq!(*segment, usize::from(k >= 500));
            assert!((a.time_s - b.time_s).abs() < 1e-9, "{a:?} {b:?}");
            assert_eq!(Sample { time_s: b.time_s, ..*a }, *b, "sample {k}");
        }
        assert_eq!(runs[0].summary.stuck + runs[1].summary.stuck, whole.stuck);
    }

    #[test]
    fn each_formation_drills_at_its_own_steady_rate_once_the_bit_turns_fast() {
        // Stuck and slipping at 60 rpm; at 180 rpm the bit settles to steady drilling, at the
        // closed form's rate of penetration in each rock: slower in the harder one.
        let well = parse(
            "settle_s = 5\n\
             [[segment]]\nduration_s = 20\nomega_rpm = 60\nwob_kn = 150\n\
             [[segment]]\nduration_s = 40\nomega_rpm = 180\nwob_kn = 150\n\
             [[segment]]\nduration_s = 40\nomega_rpm = 180\nwob_kn = 150\nintrinsic_energy_mpa = 90\nfriction = 0.5\n",
        )
        .unwrap();
        let (runs, samples) = drilled(&well);
        assert_eq!(runs[0].summary.regime(), Regime::StickSlip);
        let mut rates = Vec::new();
        for (i, (run, segment)) in runs.iter().zip(&well.segments).enumerate().skip(1) {
            let steady = segment.job.steady(&well.assembly);
            // The last ten seconds: the segment's start holds the way out of the cycle (the
            // bit stuck at first, while the string winds up to the new speed).
            let own: Vec<&Sample> = samples.iter().filter(|(k, _)| *k == i).map(|(_, s)| s).collect();
            assert_eq!((own.len(), run.duration_s), (2000, segment.duration_s));
            let tail = &own[own.len() - 500..];
            assert!(tail.iter().all(|s| s.bit_speed_rad_s > 0.9 * segment.job.omega_rad_s));
            let rate = tail.iter().map(|s| s.cutting_rate_m_s).sum::<f64>() / tail.len() as f64;
            assert!(
                (rate - steady.rate_m_s).abs() < 1e-3 * steady.rate_m_s,
                "{rate} vs {steady:?}"
            );
            rates.push(rate);
        }
        assert!(rates[1] < 0.8 * rates[0], "{rates:?}");
    }

    /// A ramp of the top drive from 60 to 180 rpm and of `drive` (`wob_kn` or `feed_m_h`)
    /// from `from` to `to` over 2 s at 50 Hz, from stick-slip, against the same string given a
    /// segment per sample at the ramps' values there: every channel agrees to 10⁻⁹ (the drive's
    /// values agree to rounding: the ramp scales to SI before it interpolates).
    fn assert_ramp_is_one_sample_segments(drive: &str, from: f64, to: f64) -> CoupledWell {
        let ramped = parse(&format!(
            "settle_s = 10\n[[segment]]\nduration_s = 2\nomega_rpm = [60, 180]\n{drive} = [{from}, {to}]\n"
        ))
        .unwrap();
        let (runs, samples) = drilled(&ramped);
        assert_eq!(samples.len(), 100);
        assert!(runs[0].summary.samples > 0);
        let mut steps = String::from("settle_s = 10\n");
        for j in 0..100 {
            let fraction = f64::from(j) / 50.0 / 2.0;
            steps.push_str(&format!(
                "[[segment]]\nduration_s = 0.02\nomega_rpm = {}\n{drive} = {}\n",
                60.0 + 120.0 * fraction,
                from + (to - from) * fraction
            ));
        }
        let (_, stepped) = drilled(&parse(&steps).unwrap());
        assert_eq!(stepped.len(), 100);
        let mut moved = false;
        for (k, ((_, a), (_, b))) in samples.iter().zip(&stepped).enumerate() {
            assert!((a.time_s - b.time_s).abs() < 1e-9, "{a:?} {b:?}");
            for (x, y) in [
                (a.bit_speed_rad_s, b.bit_speed_rad_s),
                (a.torque_nm, b.torque_nm),
                (a.wob_n, b.wob_n),
                (a.axial_speed_m_s, b.axial_speed_m_s),
                (a.axial_acceleration_m_s2, b.axial_acceleration_m_s2),
                (a.cutting_rate_m_s, b.cutting_rate_m_s),
                (a.depth_per_blade_m, b.depth_per_blade_m),
            ] {
                assert!(
                    (x - y).abs() <= 1e-9 * (1.0 + x.abs()),
                    "{drive}, sample {k}: {a:?} {b:?}"
                );
            }
            moved |= a.bit_speed_rad_s > 100.0 * RAD_S_PER_RPM;
        }
        assert!(moved, "{drive}: the ramp drives the bit past 100 rpm");
        ramped
    }

    #[test]
    fn a_ramp_is_the_string_carried_through_one_sample_segments_of_its_values() {
        let ramped = assert_ramp_is_one_sample_segments("wob_kn", 150.0, 100.0);
        assert_ramp_is_one_sample_segments("feed_m_h", 40.0, 80.0);
        // The record's top drive follows the ramp; steady drilling is the end's.
        let segment = &ramped.segments[0];
        assert_eq!(segment.top_drive_rpm(0).to_bits(), 60f64.to_bits());
        assert!((segment.top_drive_rpm(50) - 120.0).abs() < 1e-12);
        let end = segment.job_at_end();
        assert!((end.omega_rad_s - 180.0 * RAD_S_PER_RPM).abs() < 1e-12);
        assert!(matches!(end.axial, Axial::Weight { wob_n } if (wob_n - 100e3).abs() < 1e-9));
    }

    #[test]
    fn a_ramp_from_a_value_to_itself_is_the_constant_segment() {
        let constant = parse("settle_s = 5\n[[segment]]\nduration_s = 4\nomega_rpm = 60\nfeed_m_h = 40\n").unwrap();
        let ramp =
            parse("settle_s = 5\n[[segment]]\nduration_s = 4\nomega_rpm = [60, 60]\nfeed_m_h = [40, 40]\n").unwrap();
        assert!(ramp.segments[0].ramp.is_some() && constant.segments[0].ramp.is_none());
        let ((a_runs, a), (b_runs, b)) = (drilled(&constant), drilled(&ramp));
        assert_eq!(a, b, "sample for sample, bit for bit");
        assert_eq!(a_runs, b_runs);
    }

    #[test]
    fn a_bad_well_is_refused_where_it_is_wrong() {
        let refused = |text: &str| parse(text).unwrap_err().to_string();
        let segment = "[[segment]]\nduration_s = 10\nomega_rpm = 60\n";
        let e = refused(&format!("{segment}zetta = 0.7\n"));
        assert!(
            e.starts_with("well.toml:4:1:") && e.contains("unknown field `zetta`"),
            "{e}"
        );
        let e = refused(&format!("{segment}zeta = \"x\"\n"));
        assert!(e.starts_with("well.toml:4:8:") && e.contains("expected f64"), "{e}");
        let e = refused(&format!("{segment}radius_m = 0.1\n"));
        assert!(
            e.contains("well.toml:4:1:") && e.contains("unknown field `radius_m`"),
            "{e}"
        );
        let e = refused(&format!("{segment}zeta = 5\n"));
        assert!(
            e.starts_with("well.toml:1:1:") && e.contains("segment 1: zeta: must lie in [0.1, 2]"),
            "{e}"
        );
        let e = refused(&format!("{segment}wob_kn = 100\nfeed_m_h = 20\n"));
        assert!(e.contains("segment 1: give wob_kn or feed_m_h, not both"), "{e}");
        let e = refused(&format!("{segment}wob_kn = 100\n{segment}feed_m_h = 20\n"));
        assert!(
            e.starts_with("well.toml:5:1:") && e.contains("segment 2: the well is drilled under a weight"),
            "{e}"
        );
        let e = refused(&format!("{segment}duration_s = 0\n"));
        assert!(e.contains("duplicate key"), "{e}");
        let e = refused("[[segment]]\nduration_s = 0\nomega_rpm = 60\n");
        assert!(e.contains("segment 1: duration_s: must be positive"), "{e}");
        let e = refused(&format!("sample_hz = 50\n[bit]\nblades = 0\n{segment}"));
        assert!(
            e.starts_with("well.toml:2:1: [bit]: blades: must lie in [1, 12]"),
            "{e}"
        );
        let e = refused(&format!("sample_hz = 50\n[string]\nmass_kg = -1\n{segment}"));
        assert!(
            e.starts_with("well.toml:2:1: [string]: mass_kg: must be positive"),
            "{e}"
        );
        let e = refused(&format!("sample_hz = 50\ndt_s = 0.5\n{segment}"));
        assert!(
            e.starts_with("well.toml:2:8: dt_s: the integration step 0.5 s exceeds"),
            "{e}"
        );
        let e = refused(&format!("settle_s = -1\n{segment}"));
        assert!(
            e.starts_with("well.toml:1:12: settle_s: must be finite and not negative"),
            "{e}"
        );
        let e = refused(&format!("kick_rpm = inf\n{segment}"));
        assert!(e.starts_with("well.toml:1:12: kick_rpm: must be finite"), "{e}");
        let e = refused(&format!(
            "dt_s = 0.005\n{segment}[[segment]]\nduration_s = 10\nomega_rpm = 200\n"
        ));
        assert!(
            e.starts_with("well.toml:5:1: segment 2: dt_s: at 200 rpm a slipping bit"),
            "{e}"
        );
        let e = refused(&format!("{segment}[[segment]]\nduration_s = 2000\nomega_rpm = 60\n"));
        assert!(
            e.contains("well.toml:4:1: segment 2: duration_s: 100000 periods at 50 Hz"),
            "{e}"
        );
        let e = refused("[[segment]]\nduration_s = 10\nomega_rpm = [60, -5]\n");
        assert!(
            e.starts_with("well.toml:1:1: segment 1: the ramp's end: omega_rpm"),
            "{e}"
        );
        let e = refused("[[segment]]\nduration_s = 10\nomega_rpm = 60\nwob_kn = [150, 0]\n");
        assert!(e.contains("segment 1: the ramp's end: wob_kn"), "{e}");
        let e = refused("[[segment]]\nduration_s = 10\nomega_rpm = [60]\n");
        assert!(e.starts_with("well.toml:3:13:"), "{e}");
        let e = refused("sample_hz = 50\n");
        assert!(e.contains("missing field `segment`"), "{e}");
        let e = refused("segment = []\n");
        assert!(e.contains("the well has no [[segment]]"), "{e}");
    }
}
