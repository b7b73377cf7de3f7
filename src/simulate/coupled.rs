//! The coupled axial-torsional bit of Richard, Germay & Detournay (2007), "RGD": a drag bit whose
//! cutting and frictional forces are carried by the depth of cut, simulated for many strings at
//! once. This is the CPU twin (f64) of `shaders/coupled.wgsl` (f32): the same state, the same
//! step, the same contact rules, the same summary, loop for loop.
//!
//! Stick-slip is not put in here by a falling torque-speed curve. The bit's N blades each cut
//! the rock the blade before it left: the depth of cut is d = N·[U(t) − U(t − t_N)], with the
//! delay t_N set by the bit's own rotation, φ(t) − φ(t − t_N) = 2π/N. A bit that turns faster
//! cuts thinner, its cutting torque falls, and the coupling of the axial and angular motion
//! through that delay is what makes the bit stick, slip and bounce.
//!
//! ```text
//! M V' = F_a − W,   I Ω' = k u + c (Ω₀ − Ω) − T,   U' = V,   u' = Ω₀ − Ω
//! W = W_c + g_a·W_f,   T = T_c + g_t·T_f     (on bottom: d ≥ 0; off bottom W = T = 0)
//! W_c = a·ζ·ε·d,   T_c = ½·a²·ε·d,   W_f = a·l·σ,   T_f = ½·a·μ·γ·g_a·W_f
//! ```
//!
//! F_a is the axial drive: a constant weight W₀ (the hook held at a set weight), or a feed: the
//! top moving down at V_f on the string's axial stiffness and damping, F_a = K_a·z + C_a·(V_f − V)
//! with z' = V_f − V. The contact factors are set-valued where the bit is at rest: g_a = 1 while
//! the bit moves down, 0 while it lifts, and anything in [0, 1] that holds it (V = 0) between;
//! g_t = 1 while the bit turns forward, −1 backward (friction only: a blade cuts forward), and
//! anything that holds it (Ω = 0) while −T_f ≤ k u + c Ω₀ ≤ T_c + T_f.
//!
//! **The rock surface as a ring, not a history.** The depth of cut needs the bit's axial
//! position one blade-sector of rotation ago. Rather than a buffer of U(t) over the last delay
//! (which grows without bound while the bit is stuck, and costs ~100 kB a string at the step
//! needed), each string carries the rock surface itself: [`RING_CELLS`] cells spanning one
//! sector 2π/N, each holding the depth the last blade to pass cut to there. A blade reads the
//! surface ahead of it (linearly between the two cell centres around it; the one behind it as
//! it was before this pass crossed it) and, as the bit turns, writes the cells whose centres it
//! crosses: the deeper of the old surface and the blade's depth there (a blade lifted off the
//! rock removes nothing). Depths are kept relative to a reference that follows the bit (moved in
//! whole by [`REBASE_M`]), so that f32 keeps its digits on a bit that drills metres.
//!
//! The scheme: semi-implicit Euler at a fixed step (speeds first, then positions with the new
//! speeds), the contact decided at the step's start from the forces there; a speed that
//! crosses zero on bottom is set to rest and the contact holds it (or lets it go) from the next
//! step. First order in time at the events, which the step keeps far below the cycle's period.

use super::Profile;
use crate::error::{Error, Result};
use crate::stability::lumped::Lumped;

pub use super::strings::{STICK_SLIP_STUCK_SHARE, STUCK_SPEED_RAD_S};

pub mod well;

/// Cells of the rock-surface ring of one string: 240 f32 and the twelve words of the rest of
/// the state (one unused, so that the ring starts a line of four) make 1,008 B a string on the
/// device.
pub const RING_CELLS: usize = 240;

/// Depth by which the bit may move from its reference before the reference follows it (m).
pub const REBASE_M: f64 = 0.01;

/// Feed (m/h) of a string given neither a weight nor a feed.
pub const DEFAULT_FEED_M_H: f64 = 30.0;

/// How many times the top drive's speed a slipping bit reaches, for the step's check: a
/// stick-slip cycle peaks at two to three times it.
pub const PEAK_SPEED_FACTOR: f64 = 3.0;

/// Steps a blade sector must take at least at that speed ([`CoupledJob::check_step`]).
pub const MIN_STEPS_PER_SECTOR: f64 = 10.0;

/// A coupled record's clock and start where none is given: 50 Hz, steps of 1e-4 s (the stuck
/// share converges to about 1 % there), 30 s of settling, the bit kicked by 1 rpm.
pub const DEFAULT_SAMPLE_HZ: f64 = 50.0;
pub const DEFAULT_DT_S: f64 = 1e-4;
pub const DEFAULT_SETTLE_S: f64 = 30.0;
pub const DEFAULT_KICK_RPM: f64 = 1.0;

/// Share of the recorded samples off bottom from which a string is said to bounce.
pub const BOUNCE_SHARE: f64 = 0.01;

/// The bit and the rock: the RGD parameters, in the units drilling speaks (SI through the
/// methods). Flattened into a coupled run's settings, which refuse unknown names themselves;
/// a field not given is the public parameter set's.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct Bit {
    /// Bit radius a (m).
    pub radius_m: f64,
    /// Intrinsic specific energy ε of the rock (MPa).
    pub intrinsic_energy_mpa: f64,
    /// Ratio ζ of the cutting force's axial to its tangential component.
    pub zeta: f64,
    /// Contact stress σ on the blades' wear flats (MPa).
    pub contact_stress_mpa: f64,
    /// Total wear-flat length l of the blades (mm).
    pub wear_flat_mm: f64,
    /// Friction coefficient μ of the wear flats on the rock.
    pub friction: f64,
    /// Bit geometry factor γ (the spatial orientation of the wear flats).
    pub gamma: f64,
    /// Blades N.
    pub blades: u32,
}

impl Default for Bit {
    /// A public parameter set: a 8.5-in PDC bit with four blades in a 60-MPa rock.
    fn default() -> Self {
        Self {
            radius_m: 0.108,
            intrinsic_energy_mpa: 60.0,
            zeta: 0.6,
            contact_stress_mpa: 60.0,
            wear_flat_mm: 11.0,
            friction: 0.6,
            gamma: 1.0,
            blades: 4,
        }
    }
}

/// Names of the bit's parameters with their units, in [`Bit::values`]' order.
pub const BIT_PARAMETERS: [(&str, &str); 8] = [
    ("radius_m", "m"),
    ("intrinsic_energy_mpa", "MPa"),
    ("zeta", "1"),
    ("contact_stress_mpa", "MPa"),
    ("wear_flat_mm", "mm"),
    ("friction", "1"),
    ("gamma", "1"),
    ("blades", "1"),
];

/// Physical bounds of each parameter, in [`BIT_PARAMETERS`]' order (closed): beyond them the
/// model describes no drag bit.
pub const BIT_BOUNDS: [(f64, f64); 8] = [
    (0.02, 0.5),
    (1.0, 1000.0),
    (0.1, 2.0),
    (1.0, 1000.0),
    (0.0, 100.0),
    (0.0, 2.0),
    (0.1, 3.0),
    (1.0, 12.0),
];

impl Bit {
    /// The parameters in [`BIT_PARAMETERS`]' order.
    pub fn values(&self) -> [f64; 8] {
        [
            self.radius_m,
            self.intrinsic_energy_mpa,
            self.zeta,
            self.contact_stress_mpa,
            self.wear_flat_mm,
            self.friction,
            self.gamma,
            f64::from(self.blades),
        ]
    }

    /// Refuses a parameter outside its physical bounds, naming it.
    pub fn validate(&self) -> Result<()> {
        for (((name, unit), (lo, hi)), v) in BIT_PARAMETERS.iter().zip(BIT_BOUNDS).zip(self.values()) {
            if !(v.is_finite() && v >= lo && v <= hi) {
                return Err(Error::setting(
                    *name,
                    format!("must lie in [{lo}, {hi}] {unit} for a drag bit, got {v}"),
                ));
            }
        }
        Ok(())
    }

    /// Axial cutting force per unit depth of cut a·ζ·ε (N/m).
    pub fn cutting_weight_n_per_m(&self) -> f64 {
        self.radius_m * self.zeta * self.intrinsic_energy_mpa * 1e6
    }

    /// Cutting torque per unit depth of cut ½·a²·ε (N·m/m).
    pub fn cutting_torque_nm_per_m(&self) -> f64 {
        0.5 * self.radius_m * self.radius_m * self.intrinsic_energy_mpa * 1e6
    }

    /// The wear flats' full contact force a·l·σ (N).
    pub fn contact_weight_n(&self) -> f64 {
        self.radius_m * self.wear_flat_mm * 1e-3 * self.contact_stress_mpa * 1e6
    }

    /// Frictional torque per unit wear-flat force ½·a·μ·γ (m).
    pub fn friction_arm_m(&self) -> f64 {
        0.5 * self.radius_m * self.friction * self.gamma
    }

    /// One blade sector 2π/N (rad).
    pub fn sector_rad(&self) -> f64 {
        std::f64::consts::TAU / f64::from(self.blades)
    }
}

/// What holds the bit down.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Axial {
    /// A constant weight W₀ (N) on the bit assembly.
    Weight { wob_n: f64 },
    /// The top fed down at a constant rate V_f (m/s) on the string's axial spring.
    Feed { rate_m_s: f64 },
}

impl Axial {
    /// The drive's value in its unit (N or m/s), as the kernel takes it.
    pub fn value(&self) -> f64 {
        match *self {
            Self::Weight { wob_n } => wob_n,
            Self::Feed { rate_m_s } => rate_m_s,
        }
    }

    /// Whether this is a feed.
    pub fn is_feed(&self) -> bool {
        matches!(self, Self::Feed { .. })
    }
}

/// The drill string above the bit, axially and torsionally.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Assembly {
    /// The torsional 1-DOF string (inertia, natural frequency, damping ratio).
    pub torsion: Lumped,
    /// Mass of the bit assembly M (kg).
    pub mass_kg: f64,
    /// The string's axial stiffness K_a (N/m), felt under a feed.
    pub axial_stiffness_n_per_m: f64,
    /// Axial damping C_a on the bit assembly (N·s/m): under a weight on its speed, under a
    /// feed on its speed relative to the top's.
    pub axial_damping_ns_per_m: f64,
}

impl Default for Assembly {
    /// The paper's torsional string over a 40-t bottom-hole assembly on 5 km of 5-in pipe
    /// (EA/L of steel: 1.4·10⁵ N/m), its axial motion damped at 5·10⁴ N·s/m (about 1.6 % of
    /// critical on the rock's contact stiffness N·a·ζ·ε). Undamped, the model pumps energy from
    /// the rotation into bit bounce without bound: the bit ends above where it started.
    fn default() -> Self {
        Self {
            torsion: Lumped::default(),
            mass_kg: 40_000.0,
            axial_stiffness_n_per_m: 1.4e5,
            axial_damping_ns_per_m: 5e4,
        }
    }
}

impl Assembly {
    /// The string from the units drilling speaks (the axial stiffness in kN/m, the damping in
    /// kN·s/m), validated.
    pub fn of_units(
        torsion: Lumped,
        mass_kg: f64,
        axial_stiffness_kn_m: f64,
        axial_damping_kns_m: f64,
    ) -> Result<Self> {
        let a = Self {
            torsion,
            mass_kg,
            axial_stiffness_n_per_m: axial_stiffness_kn_m * 1e3,
            axial_damping_ns_per_m: axial_damping_kns_m * 1e3,
        };
        a.validate()?;
        Ok(a)
    }

    /// Refuses non-positive masses or stiffnesses and negative damping, naming each.
    pub fn validate(&self) -> Result<()> {
        self.torsion.validate()?;
        for (name, v) in [
            ("mass_kg", self.mass_kg),
            ("axial_stiffness_n_per_m", self.axial_stiffness_n_per_m),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(Error::setting(name, format!("must be positive and finite, got {v}")));
            }
        }
        let c = self.axial_damping_ns_per_m;
        if !(c.is_finite() && c >= 0.0) {
            return Err(Error::setting(
                "axial_damping_ns_per_m",
                format!("must be finite and not negative, got {c}"),
            ));
        }
        Ok(())
    }
}

/// One string: its bit, the top drive's speed Ω₀ (rad/s), the axial drive, and the bit's
/// speed kick from steady drilling at t = 0 (rad/s).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CoupledJob {
    pub bit: Bit,
    pub omega_rad_s: f64,
    pub axial: Axial,
    pub kick_rad_s: f64,
}

/// Steady drilling at a job's drive: what the bit does when nothing vibrates.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Steady {
    /// Depth of cut per blade d_n (m); zero where the weight does not reach past the wear
    /// flats' contact (the bit rubs and does not drill).
    pub depth_per_blade_m: f64,
    /// Rate of penetration (m/s).
    pub rate_m_s: f64,
    /// Weight on bit (N).
    pub wob_n: f64,
    /// Torque on bit (N·m).
    pub torque_nm: f64,
}

impl CoupledJob {
    /// Refuses a bit outside its bounds, a top drive that does not turn forward, and a drive
    /// that does not push the bit down, naming each.
    pub fn validate(&self) -> Result<()> {
        self.bit.validate()?;
        let rpm = self.omega_rad_s / crate::units::RAD_S_PER_RPM;
        if !(rpm.is_finite() && rpm > 0.0) {
            return Err(Error::setting(
                "omega_rpm",
                format!("the top drive must turn forward, got {rpm} rpm"),
            ));
        }
        if !self.kick_rad_s.is_finite() {
            return Err(Error::setting("kick_rpm", "must be finite"));
        }
        match self.axial {
            Axial::Weight { wob_n } if !(wob_n.is_finite() && wob_n > 0.0) => Err(Error::setting(
                "wob_kn",
                format!("the weight on bit must be positive, got {} kN", wob_n / 1e3),
            )),
            Axial::Feed { rate_m_s } if !(rate_m_s.is_finite() && rate_m_s > 0.0) => Err(Error::setting(
                "feed_m_h",
                format!("the feed must move the top down, got {} m/h", rate_m_s * 3600.0),
            )),
            _ => Ok(()),
        }
    }

    /// Refuses a step `dt_s` (s) at which a slipping bit, turning at [`PEAK_SPEED_FACTOR`] times
    /// the top drive's speed, crosses a blade sector in fewer than [`MIN_STEPS_PER_SECTOR`]
    /// steps: the depth of cut a blade reads would then be taken over much of the delay it
    /// stands for, and the rock surface is not resolved.
    pub fn check_step(&self, dt_s: f64) -> Result<()> {
        let per_step = PEAK_SPEED_FACTOR * self.omega_rad_s * dt_s;
        let sector = self.bit.sector_rad();
        if per_step * MIN_STEPS_PER_SECTOR <= sector {
            return Ok(());
        }
        Err(Error::setting(
            "dt_s",
            format!(
                "at {} rpm a slipping bit ({PEAK_SPEED_FACTOR} times the top drive) turns {per_step:.3} rad in a step of {dt_s} s, \
                 more than 1/{MIN_STEPS_PER_SECTOR} of the sector of its {} blades ({sector:.3} rad): the rock surface is not resolved; \
                 take a step of at most {:.1e} s",
                self.omega_rad_s / crate::units::RAD_S_PER_RPM,
                self.bit.blades,
                sector / (MIN_STEPS_PER_SECTOR * PEAK_SPEED_FACTOR * self.omega_rad_s)
            ),
        ))
    }

    /// Steady drilling at this drive on `assembly`: under a weight W₀, part of it spent on the
    /// axial damping at the rate of penetration, N·d_n·(a·ζ·ε + C_a·Ω₀/2π) = W₀ − a·l·σ, none
    /// where W₀ does not exceed the wear flats' contact; under a feed, d_n = 2π·V_f/(N·Ω₀).
    pub fn steady(&self, assembly: &Assembly) -> Steady {
        let b = &self.bit;
        let n = f64::from(b.blades);
        let turns_per_s = self.omega_rad_s / std::f64::consts::TAU;
        let depth = match self.axial {
            Axial::Weight { wob_n } => ((wob_n - b.contact_weight_n())
                / (n * (b.cutting_weight_n_per_m() + assembly.axial_damping_ns_per_m * turns_per_s)))
                .max(0.0),
            Axial::Feed { rate_m_s } => rate_m_s / (n * turns_per_s),
        };
        let d = n * depth;
        let rate_m_s = d * turns_per_s;
        let wob_n = match self.axial {
            Axial::Weight { wob_n } => wob_n - assembly.axial_damping_ns_per_m * rate_m_s,
            Axial::Feed { .. } => b.cutting_weight_n_per_m() * d + b.contact_weight_n(),
        };
        // The wear flats carry what the cutting does not (all of their contact where the bit
        // drills, the whole weight where it only rubs).
        let contact = wob_n - b.cutting_weight_n_per_m() * d;
        Steady {
            depth_per_blade_m: depth,
            rate_m_s,
            wob_n,
            torque_nm: b.cutting_torque_nm_per_m() * d + b.friction_arm_m() * contact,
        }
    }
}

/// What a string did while recorded.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CoupledSummary {
    pub samples: u32,
    /// Samples with |bit speed| below [`STUCK_SPEED_RAD_S`].
    pub stuck: u32,
    /// Stick phases begun, and the sample index of the first and the last onset.
    pub stick_onsets: u32,
    pub first_onset: u32,
    pub last_onset: u32,
    /// Samples with the bit off bottom (depth of cut < 0): bit bounce.
    pub off_bottom: u32,
    /// Samples with the bit turning backward.
    pub backward: u32,
    pub speed_min_rad_s: f64,
    pub speed_max_rad_s: f64,
    pub speed_sum_rad_s: f64,
    /// Sum of the bit's axial speed (m/s) over the samples: its mean is the rate of penetration.
    pub axial_speed_sum_m_s: f64,
    pub wob_min_n: f64,
    pub wob_max_n: f64,
    pub wob_sum_n: f64,
    pub torque_min_nm: f64,
    pub torque_max_nm: f64,
    pub torque_sum_nm: f64,
    /// The integration left physical bounds: every other field is then meaningless.
    pub diverged: bool,
}

/// The regime a string drills in.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Regime {
    /// Neither stuck nor off bottom (the bit may still vibrate).
    Steady,
    StickSlip,
    BitBounce,
    /// Stick-slip and bit bounce.
    Both,
    /// The integration ran away.
    Diverged,
}

impl Regime {
    pub fn name(self) -> &'static str {
        match self {
            Self::Steady => "steady",
            Self::StickSlip => "stick-slip",
            Self::BitBounce => "bit bounce",
            Self::Both => "stick-slip and bit bounce",
            Self::Diverged => "diverged",
        }
    }
}

impl CoupledSummary {
    fn share(&self, count: u32) -> f64 {
        f64::from(count) / f64::from(self.samples.max(1))
    }

    /// Share of the samples stuck.
    pub fn stuck_share(&self) -> f64 {
        self.share(self.stuck)
    }

    /// Share of the samples off bottom.
    pub fn off_bottom_share(&self) -> f64 {
        self.share(self.off_bottom)
    }

    /// Mean rate of penetration (m/s).
    pub fn rate_m_s(&self) -> f64 {
        self.axial_speed_sum_m_s / f64::from(self.samples.max(1))
    }

    /// Mean bit speed (rad/s).
    pub fn speed_mean_rad_s(&self) -> f64 {
        self.speed_sum_rad_s / f64::from(self.samples.max(1))
    }

    /// Mean weight on bit (N).
    pub fn wob_mean_n(&self) -> f64 {
        self.wob_sum_n / f64::from(self.samples.max(1))
    }

    /// Mean torque on bit (N·m).
    pub fn torque_mean_nm(&self) -> f64 {
        self.torque_sum_nm / f64::from(self.samples.max(1))
    }

    /// Stick-slip period (s) at `sample_hz`: the mean time between stick onsets.
    pub fn period_s(&self, sample_hz: f64) -> Option<f64> {
        (self.stick_onsets >= 2)
            .then(|| f64::from(self.last_onset - self.first_onset) / f64::from(self.stick_onsets - 1) / sample_hz)
    }

    /// The regime: stick-slip from [`STICK_SLIP_STUCK_SHARE`] of the time stuck, bit bounce
    /// from [`BOUNCE_SHARE`] off bottom.
    pub fn regime(&self) -> Regime {
        if self.diverged {
            return Regime::Diverged;
        }
        match (
            self.stuck_share() >= STICK_SLIP_STUCK_SHARE,
            self.off_bottom_share() >= BOUNCE_SHARE,
        ) {
            (false, false) => Regime::Steady,
            (true, false) => Regime::StickSlip,
            (false, true) => Regime::BitBounce,
            (true, true) => Regime::Both,
        }
    }
}

/// One recorded sample of a string (SI).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sample {
    pub time_s: f64,
    pub bit_speed_rad_s: f64,
    pub torque_nm: f64,
    /// The torque the top drive turns the string with (N·m): the string's spring and damping,
    /// k·u + c·(Ω₀ − Ω). The string carries no inertia of its own, so it is the torque it
    /// drives the bit with: equal to the torque on bit in steady drilling, winding up at k·Ω₀
    /// while the bit is held. What a rig's surface torque reads.
    pub surface_torque_nm: f64,
    pub wob_n: f64,
    /// The bit's axial speed (m/s, downward positive).
    pub axial_speed_m_s: f64,
    /// The bit's axial acceleration (m/s², downward positive), its mean over the sample period
    /// (the change of axial speed since the sample before over the period): what an
    /// accelerometer on the bit filtered over its period reads, the contact's stops included.
    pub axial_acceleration_m_s2: f64,
    /// Rate at which the blades deepen the hole: N·d_n·Ω/2π while cutting (m/s).
    pub cutting_rate_m_s: f64,
    /// Depth of cut per blade (m); negative off bottom.
    pub depth_per_blade_m: f64,
}

/// Where a string is: what carries its motion on when its drive changes (its lags, speeds
/// and the rock surface its blades left), in SI. Depths are below the string's own reference.
#[derive(Clone, Debug, PartialEq)]
pub struct CoupledState {
    /// Torsional lag Ω₀t − φ (rad) and bit speed (rad/s).
    pub lag_rad: f64,
    pub speed_rad_s: f64,
    /// Axial spring compression (m; under a feed) and axial speed (m/s).
    pub compression_m: f64,
    pub axial_speed_m_s: f64,
    /// The bit's depth below the reference, and the blades' phase in their sector (rad).
    pub depth_m: f64,
    pub phase_rad: f64,
    /// The surface just behind the blade before this pass, and the ring's cells (m).
    pub behind_old_m: f64,
    pub ring_m: Vec<f64>,
}

/// The forces of one step and the depth they came from.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Forces {
    wob_n: f64,
    torque_nm: f64,
    depth_per_blade_m: f64,
}

/// One string being integrated: the job's constants and the state.
struct CoupledString {
    // Constants of the job.
    omega: f64,
    feed: bool,
    drive: f64,
    blades: f64,
    sector: f64,
    cell: f64,
    cut_w: f64,
    cut_t: f64,
    contact_w: f64,
    arm: f64,
    mass: f64,
    inertia: f64,
    k_t: f64,
    c_t: f64,
    k_a: f64,
    c_a: f64,
    runaway: f64,
    // The state.
    /// Torsional lag u = Ω₀t − φ (rad) and bit speed Ω (rad/s).
    lag: f64,
    speed: f64,
    /// Axial spring compression z (m; under a feed) and bit axial speed V (m/s).
    compression: f64,
    axial_speed: f64,
    /// Bit depth below the reference (m).
    depth: f64,
    /// The blades' phase in their sector, [0, 2π/N) (rad).
    phase: f64,
    /// The surface the last pass left in the cell just behind the blade, before this pass
    /// crossed it.
    behind_old: f64,
    ring: [f64; RING_CELLS],
}

impl CoupledString {
    /// A string drilling steadily at its drive, its bit speed kicked by the job's kick.
    fn new(assembly: &Assembly, job: &CoupledJob) -> Self {
        let b = &job.bit;
        let steady = job.steady(assembly);
        let sector = b.sector_rad();
        let cell = sector / RING_CELLS as f64;
        let k_t = assembly.torsion.stiffness_nm_per_rad();
        let mut s = Self {
            omega: job.omega_rad_s,
            feed: job.axial.is_feed(),
            drive: job.axial.value(),
            blades: f64::from(b.blades),
            sector,
            cell,
            cut_w: b.cutting_weight_n_per_m(),
            cut_t: b.cutting_torque_nm_per_m(),
            contact_w: b.contact_weight_n(),
            arm: b.friction_arm_m(),
            mass: assembly.mass_kg,
            inertia: assembly.torsion.inertia_kg_m2,
            k_t,
            c_t: assembly.torsion.damping_nms_per_rad(),
            k_a: assembly.axial_stiffness_n_per_m,
            c_a: assembly.axial_damping_ns_per_m,
            runaway: 1e3 * job.omega_rad_s.max(1.0),
            lag: steady.torque_nm / k_t,
            speed: job.omega_rad_s + job.kick_rad_s,
            compression: steady.wob_n / assembly.axial_stiffness_n_per_m,
            axial_speed: steady.rate_m_s,
            depth: 0.0,
            phase: 0.0,
            behind_old: 0.0,
            ring: [0.0; RING_CELLS],
        };
        // The surface of steady drilling: the previous blade crossed the point δ ahead of the
        // blade (0 < δ ≤ 2π/N) a time (2π/N − δ)/Ω₀ ago, d_n·(1 − δ·N/2π) above the bit.
        let dn = steady.depth_per_blade_m;
        for (k, h) in s.ring.iter_mut().enumerate() {
            let ahead = (k as f64 + 0.5) * cell;
            *h = -dn * (1.0 - ahead / sector);
        }
        // The cell behind the blade (its centre half a cell back), before this pass crossed it.
        s.behind_old = -dn * (1.0 + 0.5 * cell / sector);
        s
    }

    /// A string of `job` on `assembly` that carries on from `state` (left by a string of the
    /// same bit): the top drive and the axial drive change, the motion and the rock do not.
    fn resume(assembly: &Assembly, job: &CoupledJob, state: &CoupledState) -> Self {
        let mut s = Self::new(assembly, job);
        s.lag = state.lag_rad;
        s.speed = state.speed_rad_s;
        s.compression = state.compression_m;
        s.axial_speed = state.axial_speed_m_s;
        s.depth = state.depth_m;
        s.phase = state.phase_rad;
        s.behind_old = state.behind_old_m;
        s.ring.copy_from_slice(&state.ring_m);
        s
    }

    /// The top drive's speed (rad/s) and the axial drive (the job's kind: a weight, N, or a
    /// feed, m/s) from now on: what a string resumed under a job of these does.
    fn set_drive(&mut self, omega_rad_s: f64, axial: f64) {
        self.omega = omega_rad_s;
        self.drive = axial;
        self.runaway = 1e3 * omega_rad_s.max(1.0);
    }

    /// Where the string is now.
    fn state(&self) -> CoupledState {
        CoupledState {
            lag_rad: self.lag,
            speed_rad_s: self.speed,
            compression_m: self.compression,
            axial_speed_m_s: self.axial_speed,
            depth_m: self.depth,
            phase_rad: self.phase,
            behind_old_m: self.behind_old,
            ring_m: self.ring.to_vec(),
        }
    }

    /// The blade's position among the cell centres, `phase / cell − 0.5`, and the number of
    /// the centre at or behind it: the surface and the transport both start from them.
    fn blade_position(&self) -> (f64, f64) {
        let x = self.phase / self.cell - 0.5;
        (x, x.floor())
    }

    /// The surface the last pass left under the blade (m, below the reference): linear between
    /// the cell centres around the blade (`position` is [`Self::blade_position`]).
    fn surface(&self, (x, behind): (f64, f64)) -> f64 {
        let frac = x - behind;
        self.behind_old + frac * (self.ring[cell_index(behind + 1.0)] - self.behind_old)
    }

    /// Advances one step of `dt` (s), returning the step's forces.
    fn step(&mut self, dt: f64) -> Forces {
        let position = self.blade_position();
        let dn = self.depth - self.surface(position);
        let on_bottom = dn >= 0.0;
        let d = if on_bottom { self.blades * dn } else { 0.0 };
        let wc = self.cut_w * d;
        let tc = self.cut_t * d;
        let wf = if on_bottom { self.contact_w } else { 0.0 };
        let fa = if self.feed {
            self.k_a * self.compression + self.c_a * (self.drive - self.axial_speed)
        } else {
            self.drive - self.c_a * self.axial_speed
        };

        // Axial: moving down (all the contact), lifting (none), or held by what it takes.
        let v = self.axial_speed;
        let (wob, held) = if v > 0.0 || (v == 0.0 && (!on_bottom || fa > wc + wf)) {
            (wc + wf, false)
        } else if v < 0.0 || fa < wc {
            (wc, false)
        } else {
            (fa, true)
        };
        let mut v_new = if held { 0.0 } else { v + (fa - wob) / self.mass * dt };
        if on_bottom && v != 0.0 && (v_new * v <= 0.0) {
            v_new = 0.0;
        }

        // Torsion: the friction the wear flats can give is what they carry axially.
        // g_a·W_f is the weight beyond the cutting's: W_f moving down, none lifting, and
        // W − W_c (between 0 and W_f) held.
        let tf = self.arm * (wob - wc);
        let tau = self.k_t * self.lag + self.c_t * (self.omega - self.speed);
        let w = self.speed;
        let (torque, stuck) = if w > 0.0 || (w == 0.0 && tau > tc + tf) {
            (tc + tf, false)
        } else if w < 0.0 || tau < -tf {
            (-tf, false)
        } else {
            (tau, true)
        };
        let mut w_new = if stuck {
            0.0
        } else {
            w + (tau - torque) / self.inertia * dt
        };
        if on_bottom && w != 0.0 && (w_new * w <= 0.0) {
            w_new = 0.0;
        }

        // Positions with the new speeds; the blades cut the cells they cross.
        let depth_new = self.depth + v_new * dt;
        if self.feed {
            self.compression += (self.drive - v_new) * dt;
        }
        self.lag += (self.omega - w_new) * dt;
        self.transport(w_new * dt, self.depth, depth_new, position.1);
        self.depth = depth_new;
        self.axial_speed = v_new;
        self.speed = w_new;
        if self.depth.abs() > REBASE_M {
            self.rebase();
        }
        Forces {
            wob_n: wob,
            torque_nm: torque,
            depth_per_blade_m: dn,
        }
    }

    /// Turns the blades by `turn` (rad) while the bit moves from `from` to `to` (m): each cell
    /// centre crossed forward takes the deeper of its surface and the blade's depth there (the
    /// depth linear over the step). The last cell crossed forward gets back the surface it had
    /// when crossed backward; cells before it keep what this pass cut (a bit turning backward
    /// is rare and is counted in the summary). `behind` is the number of the centre at or
    /// behind the blade ([`Self::blade_position`]).
    fn transport(&mut self, turn: f64, from: f64, to: f64, behind: f64) {
        let start = self.phase;
        let end = start + turn;
        if turn > 0.0 {
            // Centres in (start, end]: the first is the one after the blade's.
            let mut k = behind + 1.0;
            let mut crossed = 0;
            while (k + 0.5) * self.cell <= end && crossed < RING_CELLS {
                let at = (k + 0.5) * self.cell;
                let depth = from + (to - from) * (at - start) / turn;
                let c = cell_index(k);
                self.behind_old = self.ring[c];
                self.ring[c] = self.ring[c].max(depth);
                k += 1.0;
                crossed += 1;
            }
        } else if turn < 0.0 {
            // Centres in [end, start) crossed backward: the cell behind becomes the one ahead.
            let mut k = behind;
            let mut crossed = 0;
            while (k + 0.5) * self.cell > end && crossed < RING_CELLS {
                let c = cell_index(k);
                self.ring[c] = self.behind_old;
                self.behind_old = self.ring[cell_index(k - 1.0)];
                k -= 1.0;
                crossed += 1;
            }
        }
        self.phase = end.rem_euclid(self.sector);
    }

    /// Moves the reference to the bit: every depth relative to it shifts by the same amount.
    fn rebase(&mut self) {
        let by = self.depth;
        for h in &mut self.ring {
            *h -= by;
        }
        self.behind_old -= by;
        self.depth = 0.0;
    }

    /// The sample of the state after a step with `forces`.
    fn sample(&self, time_s: f64, forces: Forces, axial_acceleration_m_s2: f64) -> Sample {
        let dn = forces.depth_per_blade_m;
        let cutting = dn > 0.0 && self.speed > 0.0;
        Sample {
            time_s,
            bit_speed_rad_s: self.speed,
            torque_nm: forces.torque_nm,
            surface_torque_nm: self.k_t * self.lag + self.c_t * (self.omega - self.speed),
            wob_n: forces.wob_n,
            axial_speed_m_s: self.axial_speed,
            axial_acceleration_m_s2,
            cutting_rate_m_s: if cutting {
                self.blades * dn * self.speed / std::f64::consts::TAU
            } else {
                0.0
            },
            depth_per_blade_m: dn,
        }
    }

    fn runaway(&self) -> bool {
        !(self.speed.abs() <= self.runaway && self.axial_speed.abs() < 1e3 && self.lag.abs() < 1e30)
    }
}

/// The ring's cell of centre number `k` (whole, any sign: the ring wraps).
fn cell_index(k: f64) -> usize {
    (k as i64).rem_euclid(RING_CELLS as i64) as usize
}

/// How long and how finely a batch is integrated: the torsional strings' [`Schedule`].
pub use super::strings::Schedule;

/// Integrates one string on `schedule`, calling `on_sample` with each recorded sample (after
/// the settling), and returns its summary.
pub fn integrate_with(
    assembly: &Assembly,
    schedule: &Schedule,
    job: &CoupledJob,
    on_sample: &mut dyn FnMut(&Sample),
) -> CoupledSummary {
    integrate_from(assembly, schedule, job, None, on_sample).0
}

/// Integrates one string on `schedule` from `start` (steady drilling at the job's drive where
/// `None`), calling `on_sample` with each recorded sample: its summary and where it ended.
pub fn integrate_from(
    assembly: &Assembly,
    schedule: &Schedule,
    job: &CoupledJob,
    start: Option<&CoupledState>,
    on_sample: &mut dyn FnMut(&Sample),
) -> (CoupledSummary, CoupledState) {
    integrate_ramped(assembly, schedule, job, start, None, on_sample)
}

/// The drive of a recorded stretch ramped from its start to its end: the top drive's speed
/// (rad/s) and the axial drive (the job's kind: N or m/s), the sample period that ends in
/// recorded sample j driven by the ramps' values at j·`period_s` / `duration_s` (so the last
/// period runs one period short of the ramps' end).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ramp {
    pub omega_rad_s: Profile,
    pub axial: Profile,
    /// The stretch's length as given (s) and its schedule's sample period (s).
    pub duration_s: f64,
    pub period_s: f64,
}

impl Ramp {
    /// The top drive's speed (rad/s) and the axial drive over the period ending in recorded
    /// sample `j`.
    pub fn drive_at(&self, j: u32) -> (f64, f64) {
        let fraction = (f64::from(j) * self.period_s / self.duration_s).clamp(0.0, 1.0);
        (self.omega_rad_s.at(fraction), self.axial.at(fraction))
    }
}

/// [`integrate_from`] with the recorded samples' drive ramped (the settling keeps the job's):
/// the string carried through one-sample stretches at the ramps' values, sample for sample.
pub fn integrate_ramped(
    assembly: &Assembly,
    schedule: &Schedule,
    job: &CoupledJob,
    start: Option<&CoupledState>,
    ramp: Option<&Ramp>,
    on_sample: &mut dyn FnMut(&Sample),
) -> (CoupledSummary, CoupledState) {
    integrate_lanes(
        assembly,
        schedule,
        std::slice::from_ref(job),
        start,
        ramp,
        &mut |_, s| on_sample(s),
    )
    .pop()
    .expect("one string")
}

/// The strings a core integrates side by side ([`integrate_lanes`]).
pub const LANES: usize = 4;

/// [`integrate_ramped`] for several strings at once, each as if alone (the same operations
/// in the same order: the same numbers), `on_sample` called with the string's index. A step
/// is a chain of dependent operations (a division, the ring's cell, the contacts' branches)
/// that leaves a core mostly waiting; the steps of independent strings, interleaved, fill
/// it (up to [`LANES`] strings; more gain nothing).
pub fn integrate_lanes(
    assembly: &Assembly,
    schedule: &Schedule,
    jobs: &[CoupledJob],
    start: Option<&CoupledState>,
    ramp: Option<&Ramp>,
    on_sample: &mut dyn FnMut(usize, &Sample),
) -> Vec<(CoupledSummary, CoupledState)> {
    let mut strings: Vec<CoupledString> = jobs
        .iter()
        .map(|job| match start {
            Some(state) => CoupledString::resume(assembly, job, state),
            None => CoupledString::new(assembly, job),
        })
        .collect();
    let mut sums: Vec<Accumulator> = jobs.iter().map(|_| Accumulator::default()).collect();
    let mut forces = vec![Forces::default(); jobs.len()];
    let mut axial_speed_before = vec![0.0; jobs.len()];
    // The strings still integrated: one that ran away stops where it did.
    let mut running: Vec<usize> = (0..jobs.len()).collect();
    let periods = schedule.settle_samples + schedule.record_samples;
    let period_s = schedule.sample_period_s();
    for period in 0..periods {
        if running.is_empty() {
            break;
        }
        for &i in &running {
            if let Some(ramp) = ramp.filter(|_| period >= schedule.settle_samples) {
                let (omega_rad_s, axial) = ramp.drive_at(period - schedule.settle_samples);
                strings[i].set_drive(omega_rad_s, axial);
            }
            axial_speed_before[i] = strings[i].axial_speed;
        }
        for _ in 0..schedule.steps_per_sample {
            for &i in &running {
                forces[i] = strings[i].step(schedule.dt_s);
            }
        }
        running.retain(|&i| {
            let ran_away = strings[i].runaway();
            sums[i].out.diverged |= ran_away;
            !ran_away
        });
        if period >= schedule.settle_samples {
            let t = f64::from(period - schedule.settle_samples) * period_s;
            for &i in &running {
                let s = &strings[i];
                let sample = s.sample(t, forces[i], (s.axial_speed - axial_speed_before[i]) / period_s);
                sums[i].push(&sample);
                on_sample(i, &sample);
            }
        }
    }
    sums.into_iter()
        .zip(&strings)
        .map(|(sum, s)| (sum.finish(), s.state()))
        .collect()
}

/// Integrates one string on `schedule` to its summary.
pub fn integrate(assembly: &Assembly, schedule: &Schedule, job: &CoupledJob) -> CoupledSummary {
    integrate_with(assembly, schedule, job, &mut |_| {})
}

/// Every string of a batch on the CPU (rayon), in the batch's order, from steady drilling or,
/// where `start` is given, from that state.
pub fn integrate_batch(
    assembly: &Assembly,
    schedule: &Schedule,
    jobs: &[CoupledJob],
    start: Option<&CoupledState>,
) -> Vec<CoupledSummary> {
    use rayon::prelude::*;
    // Side by side where the batch fills every core so; a small batch keeps its cores busy.
    let lanes = LANES.min(jobs.len().div_ceil(rayon::current_num_threads())).max(1);
    jobs.par_chunks(lanes)
        .flat_map_iter(|lanes| {
            integrate_lanes(assembly, schedule, lanes, start, None, &mut |_, _| {})
                .into_iter()
                .map(|(summary, _)| summary)
        })
        .collect()
}

/// Samples summed in blocks of this many before the block joins the total, as the kernel sums.
pub const SUM_BLOCK: u32 = 64;

/// The summary being reduced, its sums in blocks of [`SUM_BLOCK`] samples.
struct Accumulator {
    out: CoupledSummary,
    last_stuck: bool,
    block: [f64; 4],
}

impl Default for Accumulator {
    fn default() -> Self {
        Self {
            out: CoupledSummary {
                samples: 0,
                stuck: 0,
                stick_onsets: 0,
                first_onset: 0,
                last_onset: 0,
                off_bottom: 0,
                backward: 0,
                speed_min_rad_s: f64::INFINITY,
                speed_max_rad_s: f64::NEG_INFINITY,
                speed_sum_rad_s: 0.0,
                axial_speed_sum_m_s: 0.0,
                wob_min_n: f64::INFINITY,
                wob_max_n: f64::NEG_INFINITY,
                wob_sum_n: 0.0,
                torque_min_nm: f64::INFINITY,
                torque_max_nm: f64::NEG_INFINITY,
                torque_sum_nm: 0.0,
                diverged: false,
            },
            last_stuck: false,
            block: [0.0; 4],
        }
    }
}

impl Accumulator {
    fn push(&mut self, s: &Sample) {
        let o = &mut self.out;
        let stuck = s.bit_speed_rad_s.abs() < STUCK_SPEED_RAD_S;
        if stuck {
            if !(o.samples > 0 && self.last_stuck) {
                if o.stick_onsets == 0 {
                    o.first_onset = o.samples;
                }
                o.last_onset = o.samples;
                o.stick_onsets += 1;
            }
            o.stuck += 1;
        }
        self.last_stuck = stuck;
        o.off_bottom += u32::from(s.depth_per_blade_m < 0.0);
        o.backward += u32::from(s.bit_speed_rad_s < 0.0);
        o.speed_min_rad_s = o.speed_min_rad_s.min(s.bit_speed_rad_s);
        o.speed_max_rad_s = o.speed_max_rad_s.max(s.bit_speed_rad_s);
        o.wob_min_n = o.wob_min_n.min(s.wob_n);
        o.wob_max_n = o.wob_max_n.max(s.wob_n);
        o.torque_min_nm = o.torque_min_nm.min(s.torque_nm);
        o.torque_max_nm = o.torque_max_nm.max(s.torque_nm);
        for (b, v) in self
            .block
            .iter_mut()
            .zip([s.bit_speed_rad_s, s.axial_speed_m_s, s.wob_n, s.torque_nm])
        {
            *b += v;
        }
        o.samples += 1;
        if o.samples.is_multiple_of(SUM_BLOCK) {
            self.flush();
        }
    }

    fn flush(&mut self) {
        let o = &mut self.out;
        for (total, b) in [
            &mut o.speed_sum_rad_s,
            &mut o.axial_speed_sum_m_s,
            &mut o.wob_sum_n,
            &mut o.torque_sum_nm,
        ]
        .into_iter()
        .zip(&mut self.block)
        {
            *total += *b;
            *b = 0.0;
        }
    }

    fn finish(mut self) -> CoupledSummary {
        self.flush();
        self.out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::units::RAD_S_PER_RPM;

    fn job(rpm: f64, axial: Axial, kick_rpm: f64) -> CoupledJob {
        CoupledJob {
            bit: Bit::default(),
            omega_rad_s: rpm * RAD_S_PER_RPM,
            axial,
            kick_rad_s: kick_rpm * RAD_S_PER_RPM,
        }
    }

    const FEED_30_M_H: Axial = Axial::Feed {
        rate_m_s: 30.0 / 3600.0,
    };

    #[test]
    fn strings_integrated_side_by_side_are_each_the_string_integrated_alone() {
        // Stick-slip at 45 rpm, a string run away at once (kicked far past the bound), steady
        // drilling at 120 rpm, a feed at 30 rpm and 160 kN at 60 rpm: five, so one lane of
        // four and one alone.
        let weight = |kn: f64| Axial::Weight { wob_n: kn * 1e3 };
        let jobs = [
            job(45.0, weight(150.0), 1.0),
            job(45.0, weight(150.0), 1e6),
            job(120.0, weight(150.0), 1.0),
            job(30.0, FEED_30_M_H, 1.0),
            job(60.0, weight(160.0), 1.0),
        ];
        let assembly = Assembly::default();
        let schedule = Schedule::new(1e-4, 50.0, 1.0, 4.0).unwrap();
        let mut samples: Vec<Vec<Sample>> = vec![Vec::new(); jobs.len()];
        let lanes = integrate_lanes(&assembly, &schedule, &jobs, None, None, &mut |i, x| samples[i].push(*x));
        let batch = integrate_batch(&assembly, &schedule, &jobs, None);
        for (i, job) in jobs.iter().enumerate() {
            let mut alone_samples = Vec::new();
            let alone = integrate_from(&assembly, &schedule, job, None, &mut |x| alone_samples.push(*x));
            assert_eq!(lanes[i], alone, "string {i}");
            assert_eq!(batch[i], alone.0, "string {i}");
            assert_eq!(samples[i], alone_samples, "string {i}");
        }
        // The run-away string stopped in the settling, the others recorded every sample.
        assert!(lanes[1].0.diverged && lanes[1].0.samples == 0);
        assert!(lanes.iter().enumerate().all(|(i, l)| i == 1 || l.0.samples == 200));
        assert!(lanes[0].0.stuck > 0 && lanes[2].0.stuck == 0);
    }

    #[test]
    fn steady_drilling_has_the_closed_form_forces_and_stays() {
        // The public set at 30 rpm and 30 m/h: d = 2π·V/Ω₀ = 16.67 mm a turn.
        let j = job(30.0, FEED_30_M_H, 0.0);
        let s = j.steady(&Assembly::default());
        let d = 4.0 * s.depth_per_blade_m;
        assert!((d - 0.016_667).abs() < 1e-6, "{d}");
        let b = Bit::default();
        assert!((s.wob_n - (0.108 * 0.6 * 60e6 * d + 0.108 * 0.011 * 60e6)).abs() < 1e-6);
        assert!(
            (s.torque_nm - (0.5 * 0.108 * 0.108 * 60e6 * d + 0.5 * 0.108 * 0.6 * b.contact_weight_n())).abs() < 1e-6
        );
        // Unperturbed, the integrator holds steady drilling (to rounding) over a few steps.
        let mut string = CoupledString::new(&Assembly::default(), &j);
        for _ in 0..50 {
            let f = string.step(1e-4);
            assert!((f.wob_n - s.wob_n).abs() < 1e-6 * s.wob_n, "{f:?} vs {s:?}");
            assert!((f.torque_nm - s.torque_nm).abs() < 1e-6 * s.torque_nm, "{f:?}");
            assert!((f.depth_per_blade_m - s.depth_per_blade_m).abs() < 1e-9);
        }
        // A weight gives back the depth its feed gave, undamped.
        let undamped = Assembly {
            axial_damping_ns_per_m: 0.0,
            ..Assembly::default()
        };
        let w = job(30.0, Axial::Weight { wob_n: s.wob_n }, 0.0).steady(&undamped);
        assert!((w.depth_per_blade_m - s.depth_per_blade_m).abs() < 1e-12);
        assert!((w.rate_m_s - 30.0 / 3600.0).abs() < 1e-12);
    }

    /// The surface torque is what the string drives the bit with: the torque on bit in steady
    /// drilling; while the bit is held, the string winding up at k·Ω₀; while it slips, the
    /// torque on bit plus I·Ω′ at every step; and over a stick-slip record, the torque on bit on
    /// average plus the change of the bit's angular momentum over the record's length.
    #[test]
    fn the_surface_torque_is_what_the_string_drives_the_bit_with() {
        let assembly = Assembly::default();
        let (k, inertia) = (assembly.torsion.stiffness_nm_per_rad(), assembly.torsion.inertia_kg_m2);
        let weight = Axial::Weight { wob_n: 150e3 };
        let steady = job(120.0, weight, 0.0);
        let at = steady.steady(&assembly);
        let schedule = Schedule::new(1e-4, 50.0, 0.0, 1.0).unwrap();
        integrate_with(&assembly, &schedule, &steady, &mut |s| {
            assert!(
                (s.surface_torque_nm - at.torque_nm).abs() < 1e-6 * at.torque_nm,
                "{s:?} against {at:?}"
            );
        });
        // Stick-slip at 45 rpm: 20 s to its cycle, then every step of 6 s recorded.
        let (dt, duration_s) = (1e-4, 6.0);
        let stick_slip = job(45.0, weight, 1.0);
        let to_cycle = Schedule::new(dt, 50.0, 20.0, 1.0).unwrap();
        let (_, state) = integrate_from(&assembly, &to_cycle, &stick_slip, None, &mut |_| {});
        let schedule = Schedule::new(dt, 1.0 / dt, 0.0, duration_s).unwrap();
        let mut samples = Vec::new();
        let (summary, _) = integrate_from(&assembly, &schedule, &stick_slip, Some(&state), &mut |s| {
            samples.push(*s)
        });
        assert_eq!(summary.regime(), Regime::StickSlip, "{summary:?}");
        let wind = k * stick_slip.omega_rad_s * dt;
        let mut held = 0;
        for pair in samples.windows(2) {
            if pair[0].bit_speed_rad_s == 0.0 && pair[1].bit_speed_rad_s == 0.0 {
                held += 1;
                let rise = pair[1].surface_torque_nm - pair[0].surface_torque_nm;
                assert!(
                    (rise - wind).abs() < 1e-6 * wind,
                    "{rise} against k·Ω₀·dt {wind}: {pair:?}"
                );
            }
        }
        assert!(held > 1_000, "{held} steps held");
        // Slipping, step by step: I·(Ω_k − Ω_{k−1})/dt is the string's torque at the step's
        // start less the bit's torque of that step (the speeds first, semi-implicit).
        let mut slipping = 0;
        for pair in samples.windows(2) {
            if pair[0].bit_speed_rad_s > 0.0 && pair[1].bit_speed_rad_s > 0.0 {
                slipping += 1;
                let accelerating = inertia * (pair[1].bit_speed_rad_s - pair[0].bit_speed_rad_s) / dt;
                let net = pair[0].surface_torque_nm - pair[1].torque_nm;
                assert!(
                    (accelerating - net).abs() < 1e-6 * pair[1].torque_nm,
                    "I·ΔΩ/dt {accelerating} N·m against {net}: {pair:?}"
                );
            }
        }
        assert!(slipping > 1_000, "{slipping} steps slipping");
        let n = samples.len() as f64;
        let mean = |f: &dyn Fn(&Sample) -> f64| samples.iter().map(f).sum::<f64>() / n;
        let (surface, bit) = (mean(&|s| s.surface_torque_nm), mean(&|s| s.torque_nm));
        let momentum = inertia * (samples[samples.len() - 1].bit_speed_rad_s - samples[0].bit_speed_rad_s);
        // The record ends where the bit's momentum differs from its start's, so that the balance
        // tells the surface torque from the torque on bit.
        assert!(momentum.abs() / duration_s > 1e-3 * bit, "{momentum}");
        assert!(
            (surface - bit - momentum / duration_s).abs() < 1e-4 * bit,
            "surface {surface} N·m, bit {bit} N·m, I·ΔΩ/T {}",
            momentum / duration_s
        );
    }

    #[test]
    fn a_weight_within_the_wear_flats_contact_does_not_drill() {
        let b = Bit::default();
        let j = job(
            60.0,
            Axial::Weight {
                wob_n: 0.5 * b.contact_weight_n(),
            },
            0.0,
        );
        let st = j.steady(&Assembly::default());
        assert!(st.depth_per_blade_m == 0.0 && st.rate_m_s == 0.0);
        let sched = Schedule::new(1e-3, 10.0, 1.0, 5.0).unwrap();
        let s = integrate(&Assembly::default(), &sched, &j);
        assert!(s.rate_m_s().abs() < 1e-9, "{s:?}");
        // The bit rubs: its torque is the friction of the weight it carries.
        assert!(
            (s.torque_mean_nm() - b.friction_arm_m() * 0.5 * b.contact_weight_n()).abs() < 1e-6 * s.torque_mean_nm()
        );
    }

    #[test]
    fn the_ring_carries_the_delay_of_a_bit_driven_at_constant_speeds() {
        // Bit speeds imposed (the ring's transport alone): after the bit changes speed, the
        // depth of cut is V·t_N of the new turn rate once a whole sector has been cut again.
        let j = job(30.0, FEED_30_M_H, 0.0);
        let mut s = CoupledString::new(&Assembly::default(), &j);
        let (w, v) = (5.0, 0.01);
        let dt = 1e-4;
        let sector = s.sector;
        let mut t = 0.0;
        while t < 2.0 * sector / w {
            let from = s.depth;
            let behind = s.blade_position().1;
            s.transport(w * dt, from, from + v * dt, behind);
            s.depth = from + v * dt;
            if s.depth.abs() > REBASE_M {
                s.rebase();
            }
            t += dt;
        }
        let dn = s.depth - s.surface(s.blade_position());
        let expected = v * sector / w;
        assert!((dn - expected).abs() < 1e-6 * expected.max(1e-3), "{dn} vs {expected}");
    }

    #[test]
    fn parameters_outside_their_bounds_are_refused_by_name() {
        let mut j = job(30.0, FEED_30_M_H, 0.0);
        j.bit.zeta = -0.1;
        let e = j.validate().unwrap_err().to_string();
        assert!(e.contains("zeta"), "{e}");
        let mut j = job(30.0, FEED_30_M_H, 0.0);
        j.omega_rad_s = -1.0;
        let e = j.validate().unwrap_err().to_string();
        assert!(e.contains("omega_rpm") && e.contains("got -9.549"), "{e}");
        let j = job(30.0, Axial::Weight { wob_n: 0.0 }, 0.0);
        assert!(j.validate().unwrap_err().to_string().contains("wob_kn"));
    }
}
