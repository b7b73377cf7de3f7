//! Time-domain stick-slip simulation of the paper's 1-DOF torsional model
//!
//! ```text
//! I θ'' + c θ' + k θ = k Ω t + c Ω − T_bit(θ')
//! ```
//!
//! with a bit-rock law scaled by r = W/W_ref. The linear analysis of [`crate::stability`] says
//! whether steady rotation is stable; this module shows what happens when it is not: the bit
//! stops, the string winds up, the bit slips and overshoots, which is what a downhole recorder
//! sees and what the laws are calibrated against. It doubles as a generator of synthetic field
//! data (measurement noise, a slowly fluctuating WOB) with a known answer.
//!
//! The state is the twist φ = Ωt − θ (rad) and the bit speed w = θ' (rad/s), so the equations
//! are autonomous and the angles stay bounded: φ' = Ω − w, I w' = D(φ, w) − T_bit with the
//! driving torque D = kφ + c(Ω − w).
//!
//! Friction is Karnopp-style with a true stick phase: while w = 0 the bit stays at rest as
//! long as the string's torque on it, kφ + cΩ, is at most the static torque T_s = r·T(0)
//! (clamped at ≥ 0); the torque on bit is then the reaction. The integrator is the batched
//! strings' ([`strings::Stepper`]): fixed-step RK4 on the smooth branch of the law for the
//! current direction, `dir·r·T(dir·w)`, a stop or a release inside a step located and the step
//! re-integrated to it, so that a trace here and a summary of the GPU's strings come from the
//! same steps. Integrating the smooth branch across the step (rather than the sign-switching
//! law) is what makes the end-of-step sign a reliable crossing test: with `sign(w)·T(|w|)` the
//! friction reverses inside the step and can push the speed back above zero, hiding the
//! crossing and replacing a clean stick by chatter.

pub mod coupled;
pub mod strings;
pub mod surface;
pub mod well;

use crate::error::{Error, Result};
use crate::laws::{Law, PAPER_W_REF_N};
use crate::stability::lumped::Lumped;
use crate::units::{RAD_S_PER_RPM, TorqueUnit};
use rand::SeedableRng;
use rand::rngs::StdRng;
use rand_distr::{Distribution, StandardNormal};
use strings::{Chain, MAX_NODES, Stepper, StringJob, StringState, padded, steady_start};
use surface::Extremes;

/// How the string starts at t = 0.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Initial {
    /// Steady rotation (bit speed Ω, twist r·T(Ω)/k that balances the torque on bit), plus a
    /// kick of the bit speed. A zero kick stays on the equilibrium; a small one probes its
    /// stability the way the linear analysis does.
    Equilibrium {
        /// Added to the bit speed at t = 0 (rad/s).
        speed_perturbation_rad_s: f64,
    },
    /// Everything at zero (no twist, bit at rest) while the top drive starts at Ω: a
    /// start-up from the bottom of the hole.
    Rest,
}

/// The bit-speed kick `bitrock simulate` starts on the equilibrium with, rpm: enough to show
/// whether the steady rotation is stable.
pub const DEFAULT_KICK_RPM: f64 = 5.0;
/// The seed `bitrock simulate` draws its noise from.
pub const DEFAULT_SEED: u64 = 1;

/// Everything a simulation depends on. The output is a pure function of this value.
#[derive(Clone, Debug, PartialEq)]
pub struct SimConfig {
    /// The bit-rock law.
    pub law: Law,
    /// The law's parameters with torques in N·m (SI): convert the paper's kN·m ones with
    /// `law.scale_torque(p, 1000.0)`.
    pub params_nm: Vec<f64>,
    /// The equivalent 1-DOF drill string.
    pub structure: Lumped,
    /// Top-drive speed Ω (rad/s).
    pub omega_rad_s: f64,
    /// Mean weight on bit W (N).
    pub wob_n: f64,
    /// Reference weight on bit W_ref (N): the law's torque is scaled by r = W/W_ref.
    pub w_ref_n: f64,
    /// Length of the recorded trace (s).
    pub duration_s: f64,
    /// How the trace is recorded: settling, clock, step, start, noise, WOB fluctuation, seed.
    pub recording: Recording,
}

/// How a simulated string is recorded, alike for one configuration and a well: the settling
/// before, the sample clock and integration step, the state it starts from, the noise on the
/// recorded channels, the slow fluctuation of the weight on bit, and the seed they are drawn
/// from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Recording {
    /// Time simulated before recording starts (s), to let transients die out.
    pub settle_s: f64,
    /// Recording rate (Hz); the paper's downhole recorder runs at 50 Hz.
    pub sample_hz: f64,
    /// Largest integration step (s); each sample period is split into equal steps no longer
    /// than this.
    pub dt_s: f64,
    /// Initial condition.
    pub initial: Initial,
    /// Standard deviation of the Gaussian noise added to the recorded torque (N·m).
    pub noise_torque_nm: f64,
    /// Standard deviation of the Gaussian noise added to the recorded bit speed (rad/s).
    pub noise_speed_rad_s: f64,
    /// Standard deviation of the slow Ornstein-Uhlenbeck fluctuation of the WOB (N). The paper
    /// suggests such fluctuations as the cause of its misfit at 50–120 rpm.
    pub wob_fluctuation_n: f64,
    /// Correlation time of the WOB fluctuation (s).
    pub wob_correlation_s: f64,
    /// Seed of the one generator that draws the WOB fluctuation and the measurement noise.
    pub seed: u64,
}

impl Default for Recording {
    /// 50 Hz after no settling, dt = 1 ms, starting on the equilibrium without a kick, no
    /// noise, no WOB fluctuation (correlation time 20 s, unused until one is set), seed 0.
    fn default() -> Self {
        Self {
            settle_s: 0.0,
            sample_hz: 50.0,
            dt_s: 1e-3,
            initial: Initial::Equilibrium {
                speed_perturbation_rad_s: 0.0,
            },
            noise_torque_nm: 0.0,
            noise_speed_rad_s: 0.0,
            wob_fluctuation_n: 0.0,
            wob_correlation_s: 20.0,
            seed: 0,
        }
    }
}

impl SimConfig {
    /// A noise-free configuration on the paper's drill string: W_ref = 244.2 kN, 60 s recorded
    /// at 50 Hz after no settling, dt = 1 ms, starting on the equilibrium without a kick,
    /// WOB correlation time 20 s (unused while the fluctuation is zero), seed 0.
    pub fn new(law: Law, params_nm: Vec<f64>, omega_rad_s: f64, wob_n: f64) -> Self {
        Self {
            law,
            params_nm,
            structure: Lumped::default(),
            omega_rad_s,
            wob_n,
            w_ref_n: PAPER_W_REF_N,
            duration_s: 60.0,
            recording: Recording::default(),
        }
    }

    /// Mean weight-on-bit ratio r = W/W_ref.
    pub fn weight_ratio(&self) -> f64 {
        self.wob_n / self.w_ref_n
    }

    /// Bit damping c_b = r·dT/dw(Ω) at the mean WOB (N·m·s/rad): compare it with
    /// [`Lumped::critical_bit_damping_nms`] to know whether steady rotation is stable.
    pub fn bit_damping_nms(&self) -> f64 {
        self.law
            .dtorque_dw(&self.params_nm, self.omega_rad_s, self.weight_ratio())
    }

    /// Refuses values the simulation cannot use, naming the flag that set them (values in
    /// messages are in the flag's unit).
    pub fn validate(&self) -> Result<()> {
        self.structure.validate()?;
        // (flag, value in SI, SI per flag unit)
        let positive = [
            ("omega_rpm", self.omega_rad_s, RAD_S_PER_RPM),
            ("wob_kn", self.wob_n, 1000.0),
            ("w_ref_kn", self.w_ref_n, 1000.0),
            ("duration_s", self.duration_s, 1.0),
            ("sample_hz", self.recording.sample_hz, 1.0),
            ("dt_s", self.recording.dt_s, 1.0),
            ("wob_correlation_s", self.recording.wob_correlation_s, 1.0),
        ];
        for (field, value, unit) in positive {
            if !(value.is_finite() && value > 0.0) {
                return Err(Error::setting(
                    field,
                    format!("must be positive and finite, got {}", value / unit),
                ));
            }
        }
        let non_negative = [
            ("settle_s", self.recording.settle_s, 1.0),
            ("noise_torque_knm", self.recording.noise_torque_nm, 1000.0),
            ("noise_speed_rpm", self.recording.noise_speed_rad_s, RAD_S_PER_RPM),
            ("wob_fluctuation_kn", self.recording.wob_fluctuation_n, 1000.0),
        ];
        for (field, value, unit) in non_negative {
            if !(value.is_finite() && value >= 0.0) {
                return Err(Error::setting(
                    field,
                    format!("must be finite and not negative, got {}", value / unit),
                ));
            }
        }
        if self.duration_s * self.recording.sample_hz < 1.0 {
            return Err(Error::setting(
                "duration_s",
                format!(
                    "{} s at {} Hz records no sample; record at least one sample period",
                    self.duration_s, self.recording.sample_hz
                ),
            ));
        }
        let samples = self.duration_s * self.recording.sample_hz;
        crate::limits::check_memory(
            "duration_s",
            samples * TRACE_BYTES_PER_SAMPLE,
            &format!(
                "recording {samples:.3e} samples ({} s at {} Hz)",
                self.duration_s, self.recording.sample_hz
            ),
        )?;
        // RK4 steps of the settling and the recording: at most a day's work even at a rate
        // above any machine's (the steps themselves are serial).
        crate::limits::check_work(
            "dt_s",
            (self.recording.settle_s + self.duration_s) / self.recording.dt_s,
            FASTEST_STEPS_PER_S,
            &format!(
                "integrating {} s in steps of {} s",
                self.recording.settle_s + self.duration_s,
                self.recording.dt_s
            ),
        )?;
        if self.recording.dt_s > 1.0 / self.recording.sample_hz {
            return Err(Error::setting(
                "dt_s",
                format!(
                    "the integration step {} s exceeds the sample period {} s",
                    self.recording.dt_s,
                    1.0 / self.recording.sample_hz
                ),
            ));
        }
        if let Initial::Equilibrium {
            speed_perturbation_rad_s,
        } = self.recording.initial
            && !speed_perturbation_rad_s.is_finite()
        {
            return Err(Error::setting(
                "kick_rpm",
                format!("must be finite, got {}", speed_perturbation_rad_s / RAD_S_PER_RPM),
            ));
        }
        self.law.check_params(&self.params_nm, "params")
    }
}

/// A recorded trace, SI units, one entry per sample.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Trace {
    /// Sample times (s), 0 at the first sample (after the settling time).
    pub time_s: Vec<f64>,
    /// Bit speed with measurement noise (rad/s); exactly 0 during stick when noise is off.
    pub bit_speed_rad_s: Vec<f64>,
    /// Torque on bit with measurement noise (N·m): the reaction during stick, the law's torque
    /// during slip.
    pub torque_nm: Vec<f64>,
    /// Weight on bit in effect at each sample (N), fluctuation included.
    pub wob_n: Vec<f64>,
}

impl Trace {
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.time_s.len()
    }

    /// True when there is no sample.
    pub fn is_empty(&self) -> bool {
        self.time_s.is_empty()
    }

    /// Smallest and largest bit speed (rad/s) over samples at `from_s` or later, or `None`
    /// when there are none: the quickest reading of "steady", "decaying" or "stick-slip".
    pub fn speed_range_rad_s(&self, from_s: f64) -> Option<(f64, f64)> {
        self.time_s
            .iter()
            .zip(&self.bit_speed_rad_s)
            .filter(|(t, _)| **t >= from_s)
            .map(|(_, w)| *w)
            .fold(None, |acc, w| match acc {
                None => Some((w, w)),
                Some((lo, hi)) => Some((lo.min(w), hi.max(w))),
            })
    }
}

/// Writes a trace as CSV with the columns `time_s,bit_speed_rpm,torque_knm,wob_kn`, the units
/// of field data and of `bitrock`'s own readers. Precision: time 0.1 ms, speed 0.001 rpm,
/// torque 0.1 N·m, WOB 1 N — below the noise of any downhole recorder.
pub fn write_csv<W: std::io::Write>(trace: &Trace, out: W) -> std::io::Result<()> {
    write_csv_in(trace, TorqueUnit::KNm, out)
}

/// Writes a trace as CSV with torque and weight on bit in the scale of `unit`: kN·m and kN
/// (field records, see [`write_csv`]), or N·m and N for a laboratory rig, whose torques of a
/// few N·m need 0.1 mN·m (columns `torque_nm`, `wob_n`; WOB to 1 mN).
pub fn write_csv_in<W: std::io::Write>(trace: &Trace, unit: TorqueUnit, out: W) -> std::io::Result<()> {
    let columns = Columns::of(Channels::Bit, unit);
    let mut writer = csv::Writer::from_writer(out);
    writer.write_record(&columns.header)?;
    for i in 0..trace.len() {
        writer.write_record(columns.bit_row(trace, i))?;
    }
    writer.flush()
}

/// Writes a well's record as [`write_csv_in`] writes a trace, with two more columns: the
/// top-drive speed (`top_drive_rpm`, 0.001 rpm) and the segment's name (`segment`).
pub fn write_well_csv_in<W: std::io::Write>(
    record: &WellTrace,
    well: &Well,
    unit: TorqueUnit,
    out: W,
) -> std::io::Result<()> {
    write_record_csv(record, Some(well), Channels::Bit, unit, out)
}

/// Which channels a simulated record holds: what a downhole memory tool records, what a rig
/// streams from the surface, or both.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
pub enum Channels {
    /// Bit speed, torque on bit and weight on bit (`time_s,bit_speed_rpm,torque_knm,wob_kn`).
    #[default]
    Bit,
    /// Top-drive speed, surface torque and weight on bit
    /// (`time_s,top_drive_rpm,surface_torque_knm,wob_kn`).
    Surface,
    /// Both: the bit's columns, then `top_drive_rpm,surface_torque_knm`.
    All,
    /// What a rig streams with an MWD tool's stick-slip channels: the surface columns, then the
    /// bit speed's least and greatest since the sample before (`downhole_min_rpm,
    /// downhole_max_rpm`, over the integration steps, noise-free).
    Mwd,
}

/// The header of a record's channels and how each row is written.
struct Columns {
    channels: Channels,
    header: Vec<String>,
    /// N·m per unit of the torque columns.
    per_unit: f64,
    /// N per unit of the weight column.
    wob_per_unit: f64,
}

impl Columns {
    fn of(channels: Channels, unit: TorqueUnit) -> Self {
        let torque = format!("torque_{}", unit.suffix());
        let surface_torque = format!("surface_torque_{}", unit.suffix());
        let wob = format!("wob_{}", unit.force_unit().suffix());
        let named = |names: &[&str]| names.iter().map(|n| n.to_string()).collect();
        let header = match channels {
            Channels::Bit => named(&["time_s", "bit_speed_rpm", &torque, &wob]),
            Channels::Surface => named(&["time_s", "top_drive_rpm", &surface_torque, &wob]),
            Channels::All => named(&[
                "time_s",
                "bit_speed_rpm",
                &torque,
                &wob,
                "top_drive_rpm",
                &surface_torque,
            ]),
            Channels::Mwd => named(&[
                "time_s",
                "top_drive_rpm",
                &surface_torque,
                &wob,
                "downhole_min_rpm",
                "downhole_max_rpm",
            ]),
        };
        Self {
            channels,
            header,
            per_unit: unit.newton_metres(),
            wob_per_unit: unit.force_unit().newtons(),
        }
    }

    /// Sample `i`'s time, bit speed, torque and WOB.
    fn bit_row(&self, trace: &Trace, i: usize) -> Vec<String> {
        vec![
            format!("{:.4}", trace.time_s[i]),
            format!("{:.3}", trace.bit_speed_rad_s[i] / RAD_S_PER_RPM),
            format!("{:.4}", trace.torque_nm[i] / self.per_unit),
            format!("{:.3}", trace.wob_n[i] / self.wob_per_unit),
        ]
    }

    /// Sample `i` of a record in these columns.
    fn row(&self, record: &WellTrace, i: usize) -> Vec<String> {
        let trace = &record.trace;
        let top_drive = format!("{:.3}", record.top_drive_rad_s[i] / RAD_S_PER_RPM);
        let surface = format!("{:.4}", record.surface_torque_nm[i] / self.per_unit);
        let surface_row = || {
            vec![
                format!("{:.4}", trace.time_s[i]),
                top_drive.clone(),
                surface.clone(),
                format!("{:.3}", trace.wob_n[i] / self.wob_per_unit),
            ]
        };
        match self.channels {
            Channels::Bit => self.bit_row(trace, i),
            Channels::Surface => surface_row(),
            Channels::Mwd => {
                let mut row = surface_row();
                row.extend(
                    [record.bit_least_rad_s[i], record.bit_greatest_rad_s[i]]
                        .map(|w| format!("{:.3}", w / RAD_S_PER_RPM)),
                );
                row
            }
            Channels::All => {
                let mut row = self.bit_row(trace, i);
                row.extend([top_drive, surface]);
                row
            }
        }
    }
}

/// Writes a record's `channels` as CSV, torques and WOB in the scale of `unit` (see
/// [`write_csv_in`]; surface torque at 0.1 N·m in kN·m), with the segment's name (`segment`)
/// where a `well` is given, and then the top-drive speed with the bit's channels too, since a
/// well's speed changes.
pub fn write_record_csv<W: std::io::Write>(
    record: &WellTrace,
    well: Option<&Well>,
    channels: Channels,
    unit: TorqueUnit,
    out: W,
) -> std::io::Result<()> {
    let columns = Columns::of(channels, unit);
    let mut writer = csv::Writer::from_writer(out);
    let mut header = columns.header.clone();
    let bit_only = channels == Channels::Bit;
    if well.is_some() {
        if bit_only {
            header.push("top_drive_rpm".into());
        }
        header.push("segment".into());
    }
    writer.write_record(&header)?;
    for i in 0..record.trace.len() {
        let mut row = columns.row(record, i);
        if let Some(well) = well {
            if bit_only {
                row.push(format!("{:.3}", record.top_drive_rad_s[i] / RAD_S_PER_RPM));
            }
            row.push(well.segments[record.segment[i]].name.clone());
        }
        writer.write_record(&row)?;
    }
    writer.flush()
}

/// Integration steps of one string per second above any machine's: a time estimate from it is
/// a lower bound.
pub(crate) const FASTEST_STEPS_PER_S: f64 = 1e9;
/// Memory of one recorded sample: time, bit speed, torque, weight on bit, top-drive speed and
/// torque, the bit speed's least and greatest since the sample before, and the segment, 8
/// bytes each.
const TRACE_BYTES_PER_SAMPLE: f64 = 9.0 * 8.0;

/// Simulates the configuration and returns the recorded trace.
///
/// Random draws, all standard normal from one `StdRng` seeded with `cfg.recording.seed`, in this fixed
/// order: the initial WOB fluctuation; then, at each sample, speed noise and torque noise; and
/// after each integration step, the WOB fluctuation update. Draws happen whatever the standard
/// deviations, so switching measurement noise on or off does not change the dynamics.
pub fn simulate(cfg: &SimConfig) -> Result<Trace> {
    simulate_with(cfg, &mut |_, _| {})
}

/// [`simulate`], reporting `(steps done, steps in all)` to `progress` every quarter second
/// and refusing, once the first 20 ms have measured this machine's pace, a simulation that
/// could not finish in a day here (naming `dt_s`).
pub fn simulate_with(cfg: &SimConfig, progress: &mut dyn FnMut(u64, u64)) -> Result<Trace> {
    Ok(simulate_record_with(cfg, progress)?.trace)
}

/// [`simulate_with`], the record with its surface channels (top-drive speed and torque).
pub fn simulate_record_with(cfg: &SimConfig, progress: &mut dyn FnMut(u64, u64)) -> Result<WellTrace> {
    cfg.validate()?;
    record(&Well::of(cfg), progress)
}

/// Added to a simulation's seed for the generator of its surface torque's noise.
const SURFACE_NOISE_STREAM: u64 = 0x5355_5246_4143_4521;

/// A well drilled through formations: segments of record, each with its own law at the bit,
/// parameters, top-drive speed and mean weight on bit (constant or ramped), simulated as one
/// continuous string (the state runs on across segment boundaries), with the noise, the WOB
/// fluctuation and the sample clock of the whole well. What `bitrock simulate --well` reads
/// from a well file ([`well`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Well {
    pub segments: Vec<Segment>,
    pub structure: Lumped,
    /// Reference weight on bit W_ref (N) of every segment's parameters.
    pub w_ref_n: f64,
    /// How the well is recorded (its settling with the first segment's inputs).
    pub recording: Recording,
}

/// One stretch of a well: a formation (law and parameters) and how the rig drives through it.
#[derive(Clone, Debug, PartialEq)]
pub struct Segment {
    /// What the record's `segment` column says during it.
    pub name: String,
    pub duration_s: f64,
    pub law: Law,
    /// Torques in N·m (SI).
    pub params_nm: Vec<f64>,
    /// Top-drive speed Ω (rad/s).
    pub omega_rad_s: Profile,
    /// Mean weight on bit (N).
    pub wob_n: Profile,
}

/// A value over a segment: constant, or a linear ramp from its start to its end (applied at
/// the samples and held between them).
///
/// Written as the well files give it: a number, or `{"from": …, "to": …}`.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
#[serde(untagged)]
pub enum Profile {
    Constant(f64),
    Ramp { from: f64, to: f64 },
}

impl Profile {
    /// The profile in another unit: each value times `per_unit`.
    pub fn scaled(self, per_unit: f64) -> Profile {
        match self {
            Profile::Constant(v) => Profile::Constant(v * per_unit),
            Profile::Ramp { from, to } => Profile::Ramp {
                from: from * per_unit,
                to: to * per_unit,
            },
        }
    }

    /// The value at `fraction` (0 at the segment's start, 1 at its end).
    pub fn at(self, fraction: f64) -> f64 {
        match self {
            Profile::Constant(v) => v,
            Profile::Ramp { from, to } => from + (to - from) * fraction,
        }
    }

    /// Both ends (equal for a constant).
    pub fn ends(self) -> [f64; 2] {
        match self {
            Profile::Constant(v) => [v, v],
            Profile::Ramp { from, to } => [from, to],
        }
    }
}

impl std::fmt::Display for Profile {
    /// The value, or `from→to` for a ramp (padded as a number is).
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Profile::Constant(v) => f.pad(&v.to_string()),
            Profile::Ramp { from, to } => f.pad(&format!("{from}→{to}")),
        }
    }
}

/// A recorded well: the trace, and per sample the top-drive speed (rad/s) and the segment.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct WellTrace {
    pub trace: Trace,
    pub top_drive_rad_s: Vec<f64>,
    /// Torque the top drive applies (N·m), with its own measurement noise of the torque
    /// noise's size, drawn from a generator of its own so that the bit channels do not change.
    pub surface_torque_nm: Vec<f64>,
    /// Index into [`Well::segments`] of each sample.
    pub segment: Vec<usize>,
    /// The bit speed's least and greatest (rad/s, noise-free) over the integration steps since
    /// the sample before, the sample's own included (the first sample's: its own): what an MWD
    /// tool's downhole minimum and maximum read.
    pub bit_least_rad_s: Vec<f64>,
    pub bit_greatest_rad_s: Vec<f64>,
}

impl Well {
    /// Each segment's start in recorded time, s.
    fn segment_starts_s(&self) -> Vec<f64> {
        self.segments
            .iter()
            .scan(0.0, |start, s| {
                let this = *start;
                *start += s.duration_s;
                Some(this)
            })
            .collect()
    }

    /// The one-segment well a configuration describes.
    fn of(cfg: &SimConfig) -> Self {
        Self {
            segments: vec![Segment {
                name: cfg.law.name().to_string(),
                duration_s: cfg.duration_s,
                law: cfg.law,
                params_nm: cfg.params_nm.clone(),
                omega_rad_s: Profile::Constant(cfg.omega_rad_s),
                wob_n: Profile::Constant(cfg.wob_n),
            }],
            structure: cfg.structure,
            w_ref_n: cfg.w_ref_n,
            recording: cfg.recording,
        }
    }

    /// Recorded length (s): the segments' durations.
    pub fn duration_s(&self) -> f64 {
        self.segments.iter().map(|s| s.duration_s).sum()
    }

    /// Each segment checked as `simulate` checks its configuration (law parameters, Ω and WOB
    /// at both ends of a ramp), naming the segment; the well's own settings with it.
    pub fn validate(&self) -> Result<()> {
        if self.segments.is_empty() {
            return Err(Error::setting("segment", "the well has no segment"));
        }
        (0..self.segments.len()).try_for_each(|i| {
            self.check_segment(i).map_err(|e| {
                let message = e.keyed();
                Error::setting(
                    "segment",
                    format!("segment {} ({}): {message}", i + 1, self.segments[i].name),
                )
            })
        })
    }

    /// Segment `i` and the well's settings, checked as `simulate` checks one configuration.
    fn check_segment(&self, i: usize) -> Result<()> {
        let segment = &self.segments[i];
        for (omega, wob) in segment.omega_rad_s.ends().into_iter().zip(segment.wob_n.ends()) {
            SimConfig {
                structure: self.structure,
                w_ref_n: self.w_ref_n,
                duration_s: segment.duration_s,
                recording: self.recording,
                ..SimConfig::new(segment.law, segment.params_nm.clone(), omega, wob)
            }
            .validate()?;
        }
        Ok(())
    }
}

/// Simulates the well and returns its record (see [`simulate`] for the random draws, which a
/// one-segment well makes exactly as a configuration does).
pub fn simulate_well_with(well: &Well, progress: &mut dyn FnMut(u64, u64)) -> Result<WellTrace> {
    well.validate()?;
    record(well, progress)
}

/// The one integration loop: settles with the first segment's inputs at t = 0, then records
/// the samples, the inputs of each interval between samples those at its first sample.
fn record(well: &Well, progress: &mut dyn FnMut(u64, u64)) -> Result<WellTrace> {
    let rec = well.recording;
    let total_s = rec.settle_s + well.duration_s();
    let total_steps = (total_s / rec.dt_s).ceil().max(1.0) as u64;
    let mut pace = crate::limits::Pace::new(
        "dt_s",
        format!(
            "integrating {total_s} s in steps of {} s ({total_steps:.3e} steps)",
            rec.dt_s
        ),
        total_steps,
        progress,
    );
    // The segment and the fraction of it elapsed at recorded time t.
    let starts = well.segment_starts_s();
    let segment_at = |t_s: f64| -> (usize, f64) {
        let i = starts.iter().rposition(|&start| start <= t_s).unwrap_or(0);
        let s = &well.segments[i];
        (i, ((t_s - starts[i]) / s.duration_s).clamp(0.0, 1.0))
    };
    // The segment at recorded time t: its index, law, parameters, Ω and mean WOB there.
    let drive = |t_s: f64| -> (usize, &Segment, f64, f64) {
        let (i, fraction) = segment_at(t_s);
        let s = &well.segments[i];
        (i, s, s.omega_rad_s.at(fraction), s.wob_n.at(fraction))
    };

    let mut rng = StdRng::seed_from_u64(rec.seed);
    let mut surface_rng = StdRng::seed_from_u64(rec.seed ^ SURFACE_NOISE_STREAM);
    let (_, first, omega0, wob_mean_n) = drive(0.0);
    let mut wob = Wob::new(wob_mean_n, rec.wob_fluctuation_n, rec.wob_correlation_s, &mut rng);
    let r0 = wob.ratio(well.w_ref_n);
    let chain = Chain::one_dof(&well.structure);
    let job = first_job(well, &chain, first, omega0, r0);
    let mut sim = Stepper::new(&chain, &job);
    let mut segment_now = 0;

    // Integrates `span_s`, noting the bit speed's extremes.
    let mut advance = |sim: &mut Stepper,
                       wob: &mut Wob,
                       rng: &mut StdRng,
                       extremes: &mut Extremes,
                       span_s: f64,
                       t_s: f64,
                       omega: f64| {
        if span_s <= 0.0 {
            return Ok(());
        }
        let steps = (span_s / rec.dt_s).ceil().max(1.0);
        let h = span_s / steps;
        for _ in 0..steps as u64 {
            pace.advance(1)?;
            sim.set_operating_point(omega, wob.ratio(well.w_ref_n));
            sim.step(h);
            extremes.see(sim.bit_speed_rad_s());
            if !sim.in_bounds() {
                // A law whose torque turns negative at high speed (m4's cubic beyond its
                // fitted range) accelerates the bit without bound.
                return Err(Error::Numerical(format!(
                    "the bit speed diverged: does the law's torque turn negative at high speed? \
                     (simulated time ≤ {t_s} s, Ω = {omega} rad/s)"
                )));
            }
            wob.step(h, rng);
        }
        Ok(())
    };

    let mut omega = omega0;
    // The bit speed's extremes since the sample before (the first sample's: its own).
    let mut extremes = Extremes::default();
    advance(
        &mut sim,
        &mut wob,
        &mut rng,
        &mut extremes,
        rec.settle_s,
        rec.settle_s,
        omega,
    )?;
    extremes = Extremes::default();
    // Samples at k / sample_hz for k = 0, 1, ...: duration × sample_hz of them, end excluded.
    let n_samples = (well.duration_s() * rec.sample_hz * (1.0 + 1e-12)).floor() as usize;
    let mut out = WellTrace::with_capacity(n_samples);
    let mut previous_s = 0.0;
    for k in 0..n_samples {
        let t_s = k as f64 / rec.sample_hz;
        advance(
            &mut sim,
            &mut wob,
            &mut rng,
            &mut extremes,
            t_s - previous_s,
            rec.settle_s + t_s,
            omega,
        )?;
        previous_s = t_s;
        // The inputs from this sample on (a one-segment, constant well keeps its own).
        let (segment, s, omega_now, wob_mean_n) = drive(t_s);
        if segment != segment_now {
            sim.set_law(s.law, &s.params_nm);
            segment_now = segment;
        }
        omega = omega_now;
        wob.mean_n = wob_mean_n;
        sim.set_operating_point(omega, wob.ratio(well.w_ref_n));
        let z_speed: f64 = StandardNormal.sample(&mut rng);
        let z_torque: f64 = StandardNormal.sample(&mut rng);
        let z_surface: f64 = StandardNormal.sample(&mut surface_rng);
        extremes.see(sim.bit_speed_rad_s());
        out.bit_least_rad_s.push(extremes.least);
        out.bit_greatest_rad_s.push(extremes.greatest);
        extremes = Extremes::default();
        out.push(
            t_s,
            sim.bit_speed_rad_s() + rec.noise_speed_rad_s * z_speed,
            sim.bit_torque_nm() + rec.noise_torque_nm * z_torque,
            wob.current_n(),
            (
                omega,
                sim.surface_torque_nm() + rec.noise_torque_nm * z_surface,
                segment,
            ),
        );
    }
    Ok(out)
}

/// The string's first job: the first segment's law at its speed and WOB ratio `r0`, from the
/// well's initial state (steady rotation, perturbed, or a bit at rest on bottom).
fn first_job(well: &Well, chain: &Chain, first: &Segment, omega0: f64, r0: f64) -> StringJob {
    let start = match well.recording.initial {
        Initial::Equilibrium {
            speed_perturbation_rad_s,
        } => steady_start(chain, first.law, &first.params_nm, omega0, r0, speed_perturbation_rad_s),
        // A bit on bottom at rest: held there while the string's torque stays within T_s.
        Initial::Rest => StringState {
            lag_rad: [0.0; MAX_NODES],
            speed_rad_s: [0.0; MAX_NODES],
            stuck: true,
        },
    };
    StringJob {
        law: first.law,
        params_nm: padded(&first.params_nm),
        omega_rad_s: omega0,
        ratio: r0,
        start,
    }
}

impl WellTrace {
    /// An empty trace with room for `n` samples.
    fn with_capacity(n: usize) -> Self {
        Self {
            trace: Trace {
                time_s: Vec::with_capacity(n),
                bit_speed_rad_s: Vec::with_capacity(n),
                torque_nm: Vec::with_capacity(n),
                wob_n: Vec::with_capacity(n),
            },
            top_drive_rad_s: Vec::with_capacity(n),
            surface_torque_nm: Vec::with_capacity(n),
            segment: Vec::with_capacity(n),
            bit_least_rad_s: Vec::with_capacity(n),
            bit_greatest_rad_s: Vec::with_capacity(n),
        }
    }

    /// One sample: at `t_s`, the bit's speed and torque (noise added), the WOB, and the top
    /// drive's speed and torque (noise added) with the segment it belongs to.
    fn push(
        &mut self,
        t_s: f64,
        bit_speed_rad_s: f64,
        torque_nm: f64,
        wob_n: f64,
        (omega_rad_s, surface_torque_nm, segment): (f64, f64, usize),
    ) {
        self.surface_torque_nm.push(surface_torque_nm);
        self.trace.time_s.push(t_s);
        self.trace.bit_speed_rad_s.push(bit_speed_rad_s);
        self.trace.torque_nm.push(torque_nm);
        self.trace.wob_n.push(wob_n);
        self.top_drive_rad_s.push(omega_rad_s);
        self.segment.push(segment);
    }
}

/// The weight on bit: a mean plus a stationary Ornstein-Uhlenbeck fluctuation, held constant
/// over each integration step and advanced with the exact discretisation (valid for any step).
struct Wob {
    mean_n: f64,
    std_n: f64,
    correlation_s: f64,
    fluctuation_n: f64,
}

impl Wob {
    fn new(mean_n: f64, std_n: f64, correlation_s: f64, rng: &mut StdRng) -> Self {
        let z: f64 = StandardNormal.sample(rng);
        Self {
            mean_n,
            std_n,
            correlation_s,
            // Start in the stationary distribution, so the trace has no start-up drift.
            fluctuation_n: std_n * z,
        }
    }

    /// Current WOB (N), clamped at zero: a bit lifted off bottom has no torque, not a negative
    /// one.
    fn current_n(&self) -> f64 {
        (self.mean_n + self.fluctuation_n).max(0.0)
    }

    fn ratio(&self, w_ref_n: f64) -> f64 {
        self.current_n() / w_ref_n
    }

    fn step(&mut self, h_s: f64, rng: &mut StdRng) {
        let z: f64 = StandardNormal.sample(rng);
        let rho = (-h_s / self.correlation_s).exp();
        self.fluctuation_n = rho * self.fluctuation_n + self.std_n * (1.0 - rho * rho).sqrt() * z;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    fn paper_nm(law: Law) -> Vec<f64> {
        law.scale_torque(law.paper_estimate().unwrap(), 1000.0)
    }

    fn rpm(v: f64) -> f64 {
        v * RAD_S_PER_RPM
    }

    /// Ω where c_eq + r·dT/dw(Ω) = 0 at r = 1, by bisection between an unstable and a stable
    /// speed.
    fn linear_boundary_rad_s(law: Law, lo: f64, hi: f64) -> f64 {
        let p = paper_nm(law);
        let s = Lumped::default();
        let f = |w: f64| s.damping_nms_per_rad() + law.dtorque_dw(&p, w, 1.0);
        let (mut lo, mut hi) = (lo, hi);
        assert!(f(lo) < 0.0 && f(hi) > 0.0);
        for _ in 0..100 {
            let mid = 0.5 * (lo + hi);
            if f(mid) < 0.0 { lo = mid } else { hi = mid }
        }
        0.5 * (lo + hi)
    }

    fn kicked(law: Law, omega_rad_s: f64) -> SimConfig {
        SimConfig {
            recording: Recording {
                initial: Initial::Equilibrium {
                    speed_perturbation_rad_s: 2.0,
                },
                ..Recording::default()
            },
            ..SimConfig::new(law, paper_nm(law), omega_rad_s, PAPER_W_REF_N)
        }
    }

    fn count_stuck(trace: &Trace) -> usize {
        trace.bit_speed_rad_s.iter().filter(|w| **w == 0.0).count()
    }

    #[test]
    fn linear_boundaries_match_the_paper_estimates() {
        let m3 = linear_boundary_rad_s(Law::M3, 2.0, 30.0);
        let m2 = linear_boundary_rad_s(Law::M2, 1.0, 30.0);
        assert!((m3 - 10.86).abs() < 0.01, "M3 boundary {m3}");
        assert!((m2 - 8.27).abs() < 0.01, "M2 boundary {m2}");
    }

    #[test]
    fn equilibrium_without_a_kick_stays_put() {
        let law = Law::M3;
        let omega = rpm(150.0);
        let cfg = SimConfig {
            duration_s: 10.0,
            wob_n: 0.8 * PAPER_W_REF_N,
            ..SimConfig::new(law, paper_nm(law), omega, 0.0)
        };
        let trace = simulate(&cfg).unwrap();
        let expected_nm = law.torque(&cfg.params_nm, omega, 0.8);
        for i in 0..trace.len() {
            assert!((trace.bit_speed_rad_s[i] - omega).abs() < 1e-9);
            assert!((trace.torque_nm[i] - expected_nm).abs() < 1e-6);
            assert!((trace.wob_n[i] - cfg.wob_n).abs() < 1e-9);
        }
        assert_eq!(trace.len(), 500, "10 s at 50 Hz, end excluded");
        assert!((trace.time_s[499] - 9.98).abs() < 1e-12);
    }

    #[test]
    fn stable_speeds_damp_a_kick_back_to_steady_rotation() {
        // M3 at 150 rpm: c_b = −88.7 N·m·s/rad, growth rate −0.097/s: the 2 rad/s kick is still
        // 5e-3 rad/s at 60 s, 7.5e-4 at 80 s and 1.2e-4 over 100..120 s (measured), so M3
        // settles 100 s. M2 at 150 rpm (c_b = −17.5, growth −0.19/s): 2.2e-5 over 60..80 s.
        for (law, settle_s) in [(Law::M3, 100.0), (Law::M2, 60.0)] {
            let omega = rpm(150.0);
            let cfg = SimConfig {
                duration_s: 20.0,
                recording: Recording {
                    settle_s,
                    ..kicked(law, omega).recording
                },
                ..kicked(law, omega)
            };
            assert!(cfg.bit_damping_nms() > cfg.structure.critical_bit_damping_nms());
            let trace = simulate(&cfg).unwrap();
            let (lo, hi) = trace.speed_range_rad_s(0.0).unwrap();
            assert!(
                (lo - omega).abs() < 1e-3 && (hi - omega).abs() < 1e-3,
                "{law}: {lo}..{hi}"
            );
            assert_eq!(count_stuck(&trace), 0);
        }
    }

    #[test]
    fn unstable_speeds_develop_stick_slip() {
        for law in [Law::M3, Law::M2] {
            let omega = rpm(60.0);
            let cfg = SimConfig {
                duration_s: 120.0,
                ..kicked(law, omega)
            };
            assert!(cfg.bit_damping_nms() < cfg.structure.critical_bit_damping_nms());
            let trace = simulate(&cfg).unwrap();
            let (lo, hi) = trace.speed_range_rad_s(60.0).unwrap();
            assert!(lo == 0.0, "{law}: never stuck, min speed {lo}");
            assert!(hi > 1.5 * omega, "{law}: max speed {hi} vs Ω = {omega}");
            assert!(count_stuck(&trace) > 100, "{law}");
        }
    }

    #[test]
    fn stick_records_the_reaction_not_the_law() {
        // From rest the twist is φ = Ωt until the first release, so the reaction is kΩt + cΩ,
        // far below the static torque r·T(0) the law would give.
        let law = Law::M3;
        let omega = rpm(60.0);
        let cfg = SimConfig {
            duration_s: 40.0,
            recording: Recording {
                initial: Initial::Rest,
                ..Recording::default()
            },
            ..SimConfig::new(law, paper_nm(law), omega, PAPER_W_REF_N)
        };
        let s = cfg.structure;
        let (k, c) = (s.stiffness_nm_per_rad(), s.damping_nms_per_rad());
        let ts = law.torque(&cfg.params_nm, 0.0, 1.0);
        let release_s = (ts - c * omega) / (k * omega);
        let trace = simulate(&cfg).unwrap();
        let mut checked = 0;
        for i in 0..trace.len() {
            let t = trace.time_s[i];
            if t < release_s {
                assert!(trace.bit_speed_rad_s[i] == 0.0);
                let reaction = k * omega * t + c * omega;
                assert!((trace.torque_nm[i] - reaction).abs() < 1e-9 * ts, "t={t}");
                checked += 1;
            }
        }
        assert!(checked > 100);
        assert!(trace.torque_nm[0] < 0.1 * ts);
        // Every later stick phase: the torque rises at kΩ between consecutive stuck samples.
        let dt = 1.0 / cfg.recording.sample_hz;
        let mut later = 0;
        for i in 1..trace.len() {
            if trace.time_s[i - 1] > release_s && trace.bit_speed_rad_s[i - 1] == 0.0 && trace.bit_speed_rad_s[i] == 0.0
            {
                let slope = (trace.torque_nm[i] - trace.torque_nm[i - 1]) / dt;
                assert!((slope - k * omega).abs() < 1e-6 * k * omega, "t={}", trace.time_s[i]);
                assert!(trace.torque_nm[i] <= ts * (1.0 + 1e-12));
                later += 1;
            }
        }
        assert!(later > 50, "{later}");
    }

    #[test]
    fn step_refinement_converges() {
        let law = Law::M3;
        let run = |dt_s: f64| {
            let cfg = SimConfig {
                duration_s: 20.0,
                recording: Recording {
                    initial: Initial::Rest,
                    dt_s,
                    ..Recording::default()
                },
                ..SimConfig::new(law, paper_nm(law), rpm(60.0), PAPER_W_REF_N)
            };
            simulate(&cfg).unwrap().bit_speed_rad_s
        };
        let max_diff = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max);
        let (coarse, mid, fine) = (run(2e-3), run(1e-3), run(5e-4));
        assert!(
            mid.iter().filter(|w| **w == 0.0).count() > 100,
            "the run must contain stick phases"
        );
        let d_coarse = max_diff(&coarse, &mid);
        let d_fine = max_diff(&mid, &fine);
        // Measured: d(2e-3, 1e-3) = 1.69e-9 rad/s, d(1e-3, 5e-4) = 1.07e-10 rad/s, ratio 15.7,
        // i.e. RK4's fourth order (16) survives the stick/slip switching because stops and
        // releases are located inside the step (one secant: the state at a stop has w = 0,
        // where the located time's error moves the twist by w·δt ≈ 0; a release is exact). The run has a release at 6.44 s,
        // a stop at 11.66 s and a release at 16.0 s; peak speed 20.4 rad/s.
        assert!(d_coarse / d_fine > 12.0, "{d_coarse:e} / {d_fine:e}");
        assert!(d_fine < 1e-9, "{d_fine:e}");
    }

    #[test]
    fn same_seed_same_trace_other_seed_other_noise() {
        let law = Law::M2;
        let cfg = SimConfig {
            duration_s: 10.0,
            recording: Recording {
                noise_speed_rad_s: 0.1,
                noise_torque_nm: 200.0,
                wob_fluctuation_n: 10e3,
                seed: 7,
                ..kicked(law, rpm(60.0)).recording
            },
            ..kicked(law, rpm(60.0))
        };
        let a = simulate(&cfg).unwrap();
        let b = simulate(&cfg).unwrap();
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&a.bit_speed_rad_s), bits(&b.bit_speed_rad_s));
        assert_eq!(bits(&a.torque_nm), bits(&b.torque_nm));
        assert_eq!(bits(&a.wob_n), bits(&b.wob_n));
        let c = simulate(&SimConfig {
            recording: Recording {
                seed: 8,
                ..cfg.recording
            },
            ..cfg.clone()
        })
        .unwrap();
        let differing = a
            .torque_nm
            .iter()
            .zip(&c.torque_nm)
            .filter(|(x, y)| x.to_bits() != y.to_bits())
            .count();
        assert_eq!(differing, a.len());
        // The WOB wanders around its mean with about the requested spread.
        let mean = a.wob_n.iter().sum::<f64>() / a.len() as f64;
        assert!((mean - cfg.wob_n).abs() < 4.0 * cfg.recording.wob_fluctuation_n);
    }

    #[test]
    fn a_runaway_law_is_a_numerical_error_not_a_hang() {
        // M4's cubic turns negative above ≈ 32 rad/s; stick-slip at 150 rpm overshoots there.
        let law = Law::M4;
        let cfg = SimConfig {
            recording: Recording {
                initial: Initial::Rest,
                ..Recording::default()
            },
            ..SimConfig::new(law, paper_nm(law), rpm(150.0), PAPER_W_REF_N)
        };
        let err = simulate(&cfg).unwrap_err();
        assert!(matches!(err, Error::Numerical(_)) && !err.is_bad_input());
        assert!(err.to_string().contains("diverged"), "{err}");
    }

    #[test]
    fn a_runaway_to_finite_but_absurd_speeds_is_an_error_too() {
        // A light string driving a law whose torque falls with speed (c1 < 0): the bit
        // accelerated to 1e227 rpm while every number stayed finite, and a trace was written.
        let cfg = SimConfig {
            structure: Lumped {
                inertia_kg_m2: 0.01,
                omega_n_rad_s: 5.0,
                damping_ratio: 0.1,
            },
            w_ref_n: 500.0,
            recording: Recording {
                initial: Initial::Equilibrium {
                    speed_perturbation_rad_s: rpm(10.0),
                },
                ..Recording::default()
            },
            ..SimConfig::new(Law::M4, vec![3.0, -0.12, 0.0, 0.0], rpm(100.0), 500.0)
        };
        let err = simulate(&cfg).unwrap_err();
        assert!(err.to_string().contains("diverged"), "{err}");
    }

    #[test]
    fn validation_names_the_setting() {
        let base = SimConfig::new(Law::M2, paper_nm(Law::M2), 6.0, 244.2e3);
        assert!(base.validate().is_ok());
        let flag_of = |cfg: SimConfig| match cfg.validate().unwrap_err() {
            Error::InvalidSetting { field, .. } => field,
            other => panic!("{other}"),
        };
        let cases: Vec<(&str, SimConfig)> = vec![
            (
                "omega_rpm",
                SimConfig {
                    omega_rad_s: 0.0,
                    ..base.clone()
                },
            ),
            (
                "wob_kn",
                SimConfig {
                    wob_n: f64::NAN,
                    ..base.clone()
                },
            ),
            (
                "duration_s",
                SimConfig {
                    duration_s: -1.0,
                    ..base.clone()
                },
            ),
            (
                "sample_hz",
                SimConfig {
                    recording: Recording {
                        sample_hz: f64::INFINITY,
                        ..base.recording
                    },
                    ..base.clone()
                },
            ),
            (
                "dt_s",
                SimConfig {
                    recording: Recording {
                        dt_s: 0.0,
                        ..base.recording
                    },
                    ..base.clone()
                },
            ),
            (
                "dt_s",
                SimConfig {
                    recording: Recording {
                        dt_s: 0.05,
                        ..base.recording
                    },
                    ..base.clone()
                },
            ),
            (
                "settle_s",
                SimConfig {
                    recording: Recording {
                        settle_s: -1.0,
                        ..base.recording
                    },
                    ..base.clone()
                },
            ),
            (
                "noise_torque_knm",
                SimConfig {
                    recording: Recording {
                        noise_torque_nm: -1.0,
                        ..base.recording
                    },
                    ..base.clone()
                },
            ),
            (
                "noise_speed_rpm",
                SimConfig {
                    recording: Recording {
                        noise_speed_rad_s: f64::NAN,
                        ..base.recording
                    },
                    ..base.clone()
                },
            ),
            (
                "wob_fluctuation_kn",
                SimConfig {
                    recording: Recording {
                        wob_fluctuation_n: -1.0,
                        ..base.recording
                    },
                    ..base.clone()
                },
            ),
            (
                "wob_correlation_s",
                SimConfig {
                    recording: Recording {
                        wob_correlation_s: 0.0,
                        ..base.recording
                    },
                    ..base.clone()
                },
            ),
            (
                "params",
                SimConfig {
                    params_nm: vec![1.0, 2.0],
                    ..base.clone()
                },
            ),
            (
                "params",
                SimConfig {
                    params_nm: vec![13e3, 6.5e3, -0.3],
                    ..base.clone()
                },
            ),
            (
                "params",
                SimConfig {
                    params_nm: vec![13e3, f64::NAN, 0.3],
                    ..base.clone()
                },
            ),
            (
                "damping_ratio",
                SimConfig {
                    structure: Lumped {
                        damping_ratio: 0.0,
                        ..Lumped::default()
                    },
                    ..base.clone()
                },
            ),
        ];
        for (field, cfg) in cases {
            assert_eq!(flag_of(cfg), field);
        }
        // Messages speak the flag's unit, not SI.
        let msg = SimConfig {
            wob_n: -5e3,
            ..base.clone()
        }
        .validate()
        .unwrap_err()
        .to_string();
        assert_eq!(msg, "`wob_kn`: must be positive and finite, got -5");
    }

    #[test]
    fn csv_has_the_field_columns_and_units() {
        let trace = Trace {
            time_s: vec![0.0, 0.02],
            bit_speed_rad_s: vec![2.0 * std::f64::consts::PI, 0.0],
            torque_nm: vec![12_345.67, -1.0],
            wob_n: vec![244_200.0, 0.0],
        };
        let mut out = Vec::new();
        write_csv(&trace, &mut out).unwrap();
        let text = String::from_utf8(out).unwrap();
        assert_eq!(
            text,
            "time_s,bit_speed_rpm,torque_knm,wob_kn\n0.0000,60.000,12.3457,244.200\n0.0200,0.000,-0.0010,0.000\n"
        );
        // A laboratory rig's torques of a few N·m keep their digits in N·m.
        let rig = Trace {
            torque_nm: vec![3.25438, -0.00004],
            wob_n: vec![512.3456, 0.0],
            ..trace
        };
        let mut out = Vec::new();
        write_csv_in(&rig, TorqueUnit::Nm, &mut out).unwrap();
        assert_eq!(
            String::from_utf8(out).unwrap(),
            "time_s,bit_speed_rpm,torque_nm,wob_n\n0.0000,60.000,3.2544,512.346\n0.0200,0.000,-0.0000,0.000\n"
        );
    }

    /// m2 at 60 rpm with noise on both channels and a fluctuating weight on bit.
    fn noisy_m2() -> SimConfig {
        SimConfig {
            recording: Recording {
                noise_torque_nm: 300.0,
                noise_speed_rad_s: 0.05,
                wob_fluctuation_n: 5_000.0,
                seed: 9,
                ..Recording::default()
            },
            ..SimConfig::new(Law::M2, paper_nm(Law::M2), rpm(60.0), PAPER_W_REF_N)
        }
    }

    fn well_of(segments: Vec<Segment>) -> Well {
        Well {
            segments,
            ..Well::of(&noisy_m2())
        }
    }

    fn segment(law: Law, duration_s: f64, omega_rpm: Profile, wob_kn: f64) -> Segment {
        Segment {
            name: law.name().to_string(),
            duration_s,
            law,
            params_nm: paper_nm(law),
            omega_rad_s: match omega_rpm {
                Profile::Constant(v) => Profile::Constant(rpm(v)),
                Profile::Ramp { from, to } => Profile::Ramp {
                    from: rpm(from),
                    to: rpm(to),
                },
            },
            wob_n: Profile::Constant(wob_kn * 1000.0),
        }
    }

    #[test]
    fn a_well_runs_on_across_its_segments() {
        // Two identical segments are one segment of their summed length, bit for bit: the
        // string's state, the WOB fluctuation and the noise run on across the boundary.
        let one = well_of(vec![segment(Law::M2, 20.0, Profile::Constant(60.0), 200.0)]);
        let two = well_of(vec![
            segment(Law::M2, 8.0, Profile::Constant(60.0), 200.0),
            segment(Law::M2, 12.0, Profile::Constant(60.0), 200.0),
        ]);
        let (a, b) = (
            simulate_well_with(&one, &mut |_, _| {}).unwrap(),
            simulate_well_with(&two, &mut |_, _| {}).unwrap(),
        );
        assert_eq!(a.trace, b.trace);
        assert_eq!(a.trace.len(), 1000);
        assert_eq!(b.segment.iter().filter(|&&s| s == 0).count(), 400);
        // A one-segment well is the configuration it was made from.
        let cfg = SimConfig {
            duration_s: 20.0,
            wob_n: 200_000.0,
            ..noisy_m2()
        };
        assert_eq!(simulate(&cfg).unwrap(), a.trace);
    }

    #[test]
    fn a_formation_change_changes_the_torque_law_and_ramps_follow_the_clock() {
        let well = well_of(vec![
            segment(Law::M2, 10.0, Profile::Constant(120.0), 200.0),
            segment(Law::M3, 10.0, Profile::Ramp { from: 120.0, to: 60.0 }, 200.0),
        ]);
        let record = simulate_well_with(&well, &mut |_, _| {}).unwrap();
        assert_eq!(record.trace.len(), 1000);
        for (k, &t) in record.trace.time_s.iter().enumerate() {
            let expected_rpm = if t < 10.0 {
                120.0
            } else {
                120.0 - 60.0 * (t - 10.0) / 10.0
            };
            assert!((record.top_drive_rad_s[k] - rpm(expected_rpm)).abs() < 1e-9, "t = {t}");
            assert_eq!(record.segment[k], usize::from(t >= 10.0));
        }
        let mut csv = Vec::new();
        write_well_csv_in(&record, &well, TorqueUnit::KNm, &mut csv).unwrap();
        let text = String::from_utf8(csv).unwrap();
        let mut lines = text.lines();
        assert_eq!(
            lines.next(),
            Some("time_s,bit_speed_rpm,torque_knm,wob_kn,top_drive_rpm,segment")
        );
        assert!(lines.next().unwrap().ends_with(",120.000,m2"));
        assert!(text.lines().last().unwrap().ends_with(",m3"));
    }

    #[test]
    fn a_well_file_reads_and_its_refusals_point_into_it() {
        let path = Path::new("well.toml");
        let well = Well::parse(
            "seed = 3\nnoise_torque_knm = 0.6\n[[segment]]\nduration_s = 30\nlaw = \"m2\"\nomega_rpm = 80\n\n[[segment]]\nname = \"hard\"\nduration_s = 20\nlaw = \"m3\"\nomega_rpm = [80, 120]\nwob_kn = 180\n",
            path,
        )
        .unwrap();
        assert_eq!(well.segments.len(), 2);
        assert_eq!(well.segments[1].name, "hard");
        assert_eq!(well.segments[0].params_nm, paper_nm(Law::M2));
        assert_eq!(
            well.segments[1].omega_rad_s,
            Profile::Ramp {
                from: rpm(80.0),
                to: rpm(120.0)
            }
        );
        assert_eq!(well.segments[1].wob_n, Profile::Constant(180_000.0));
        assert_eq!((well.recording.seed, well.recording.noise_torque_nm), (3, 600.0));
        let refused = |text: &str| Well::parse(text, path).unwrap_err().to_string();
        let e = refused("[[segment]]\nduration_s = 30\nlaw = \"m2\"\nomega_rpm = 80\nspeed = 3\n");
        assert!(
            e.starts_with("well.toml:5:1:") && e.contains("unknown field `speed`"),
            "{e}"
        );
        let e = refused("[[segment]]\nduration_s = 30\nlaw = \"m9\"\nomega_rpm = 80\n");
        assert!(e.starts_with("well.toml:3:7:") && e.contains("m9"), "{e}");
        let e = refused("[[segment]]\nduration_s = 30\nlaw = \"m2\"\nparams = [13, 6.5]\nomega_rpm = 80\n");
        assert!(e.starts_with("well.toml:4:10:") && e.contains("params"), "{e}");
        let e = refused("[[segment]]\nduration_s = 30\nlaw = \"m2\"\nparams = [13000, 6500, 0.3]\nomega_rpm = 80\n");
        assert!(
            e.starts_with("well.toml:4:10:") && e.contains("param_torque_unit"),
            "{e}"
        );
        let e = refused("seed = 1\n[[segment]]\nduration_s = -30\nlaw = \"m2\"\nomega_rpm = 80\n");
        assert!(
            e.starts_with("well.toml:2:1:") && e.contains("segment 1: duration_s"),
            "{e}"
        );
        let e = refused("seed = 1\n");
        assert!(e.contains("segment"), "{e}");
    }
}
