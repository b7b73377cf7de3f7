//! The batched string integrator: many independent drill strings, each from its own law,
//! parameters, operating point (Ω, W) and initial state, integrated with one fixed step and one
//! stick rule, reduced on the fly to a [`Summary`]. This is the CPU twin (f64) of
//! `shaders/strings.wgsl` (f32): the same chain, the same step, the same event rule, the same
//! summary, loop for loop.
//!
//! The string is a [`Chain`] of lumped inertias below the top drive, which turns at the imposed
//! Ω: one node for the paper's 1-DOF string, one per finite element for a string lumped from
//! `fe`'s (row sums of the consistent mass matrix, the same element stiffnesses, Rayleigh damping
//! C = αM + βK acting on the speeds relative to the top drive, so that steady rotation carries no
//! damping torque and the linearisation is the FE model's). In the lags u_j = Ωt − θ_j and bit
//! speeds w_j:
//!
//! ```text
//! u_j' = Ω − w_j,   m_j w_j' = F_j − [j = bit]·T_bit,   F = K u + C (Ω − w)
//! ```
//!
//! F at the bit is the torque the string drives the bit with. The stick rule (Karnopp): a bit at
//! rest stays at w = 0 while |F_bit| ≤ T_s = max(r·T(0), 0); its torque is then the reaction
//! F_bit. Slip is integrated with classical RK4 on the smooth branch `dir·r·T(dir·w)` of the
//! law for the current direction. Inside a step, a bit speed that crosses zero is located by one
//! secant on the step's two ends and the step re-integrated to it; a stuck bit's release is
//! located the same way on F_bit (exact for the 1-DOF string, where F grows linearly while
//! stuck). Both are well posed in f32: no stiff regularisation, no bisection to a tolerance.

use crate::error::{Error, Result};
use crate::laws::Law;
use crate::stability::fe::DrillString;
use crate::stability::lumped::Lumped;

/// Most nodes in a chain: the kernel's per-string arrays hold this many.
pub const MAX_NODES: usize = 16;

pub use crate::data::{STICK_SLIP_STUCK_SHARE, STUCK_SPEED_RAD_S};

/// Largest |λ|·dt of the chain's linear modes: inside RK4's stability region (2.83 on the
/// imaginary axis, 2.78 on the real one) with a margin.
pub const MAX_STEP_TIMES_RATE: f64 = 2.5;

/// Passes of the event rule in one step: a stop and a release, with room to spare.
const EVENT_PASSES: usize = 4;

/// A drill string as the batched integrator sees it: lumped inertias from the top down, the
/// last one the bit, joined by torsional springs (element j joins node j − 1 to node j, node 0
/// being the top drive), with Rayleigh damping C = αM + βK.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Chain {
    /// Lumped inertia of each node (kg·m²), top first, the bit last.
    pub inertia_kg_m2: Vec<f64>,
    /// Stiffness of each element (N·m/rad), element j above node j.
    pub stiffness_nm_per_rad: Vec<f64>,
    /// Mass-proportional damping α (1/s).
    pub alpha_per_s: f64,
    /// Stiffness-proportional damping β (s).
    pub beta_s: f64,
}

/// The chain's fastest linear mode, for the step-size rule.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FastestMode {
    /// 1-based mode number, ascending in frequency.
    pub mode: usize,
    /// Undamped frequency ω (rad/s).
    pub frequency_rad_s: f64,
    /// Modal damping ratio ξ = (α/ω + βω)/2.
    pub damping_ratio: f64,
    /// |λ| of the mode's fastest eigenvalue (1/s): ω when underdamped, ω(ξ + √(ξ² − 1)) when not.
    pub rate_per_s: f64,
}

impl Chain {
    /// The paper's 1-DOF string: one node of inertia I, one spring k, its damping c as βk (the
    /// damping acts on the twist rate Ω − w, as the paper's equation has it).
    pub fn one_dof(s: &Lumped) -> Self {
        let k = s.stiffness_nm_per_rad();
        Self {
            inertia_kg_m2: vec![s.inertia_kg_m2],
            stiffness_nm_per_rad: vec![k],
            alpha_per_s: 0.0,
            beta_s: s.damping_nms_per_rad() / k,
        }
    }

    /// The finite-element string lumped: each node's inertia half of each element it joins (the
    /// row sums of the consistent mass matrix), the element stiffnesses and Rayleigh
    /// coefficients kept.
    pub fn lumped_fe(s: &DrillString) -> Result<Self> {
        s.validate()?;
        let n = s.dofs();
        if n > MAX_NODES {
            return Err(Error::setting(
                "dp_elements",
                format!(
                    "the simulated string holds at most {MAX_NODES} elements, this one has {n} \
                     ({} in the drill pipe and {} in the BHA)",
                    s.dp_elements, s.bha_elements
                ),
            ));
        }
        let (_, _, k) = s.matrices();
        let inertia_kg_m2 = s.lumped_inertias_kg_m2();
        // K is tridiagonal with K[i][i+1] = −k_{i+1}; the bit's element is K[n−1][n−1] − k_{n−1}.
        let mut stiffness_nm_per_rad = vec![0.0; n];
        stiffness_nm_per_rad[n - 1] = if n == 1 { k[(0, 0)] } else { -k[(n - 2, n - 1)] };
        for j in (0..n - 1).rev() {
            stiffness_nm_per_rad[j] = k[(j, j)] - stiffness_nm_per_rad[j + 1];
        }
        Ok(Self {
            inertia_kg_m2,
            stiffness_nm_per_rad,
            alpha_per_s: s.alpha,
            beta_s: s.beta,
        })
    }

    /// Nodes (the bit included).
    pub fn nodes(&self) -> usize {
        self.inertia_kg_m2.len()
    }

    /// The bit's inertia (kg·m²).
    pub fn bit_inertia_kg_m2(&self) -> f64 {
        self.inertia_kg_m2[self.nodes() - 1]
    }

    /// Undamped frequencies of the chain's linear part (rad/s), ascending (M⁻¹K symmetrised by
    /// the diagonal M).
    pub fn frequencies_rad_s(&self) -> Vec<f64> {
        let n = self.nodes();
        let mut a = nalgebra::DMatrix::zeros(n, n);
        for j in 0..n {
            let below = self.stiffness_nm_per_rad.get(j + 1).copied().unwrap_or(0.0);
            a[(j, j)] = (self.stiffness_nm_per_rad[j] + below) / self.inertia_kg_m2[j];
            if j + 1 < n {
                let off = -below / (self.inertia_kg_m2[j] * self.inertia_kg_m2[j + 1]).sqrt();
                a[(j, j + 1)] = off;
                a[(j + 1, j)] = off;
            }
        }
        let mut omegas: Vec<f64> = a.symmetric_eigenvalues().iter().map(|l| l.max(0.0).sqrt()).collect();
        omegas.sort_by(f64::total_cmp);
        omegas
    }

    /// The fundamental (slowest) frequency (rad/s): the stick-slip cycle's time scale.
    pub fn fundamental_rad_s(&self) -> f64 {
        self.frequencies_rad_s()[0]
    }

    /// The mode with the fastest eigenvalue, for the step-size rule.
    pub fn fastest_mode(&self) -> FastestMode {
        let mut fastest = None::<FastestMode>;
        for (i, omega) in self.frequencies_rad_s().into_iter().enumerate() {
            let xi = 0.5 * (self.alpha_per_s / omega.max(f64::MIN_POSITIVE) + self.beta_s * omega);
            let rate = if xi <= 1.0 {
                omega
            } else {
                omega * (xi + (xi * xi - 1.0).sqrt())
            };
            if fastest.is_none_or(|f| rate > f.rate_per_s) {
                fastest = Some(FastestMode {
                    mode: i + 1,
                    frequency_rad_s: omega,
                    damping_ratio: xi,
                    rate_per_s: rate,
                });
            }
        }
        fastest.expect("a chain has a node")
    }

    /// Refuses a step that cannot resolve the chain's fastest mode, naming `dt_s` and the mode.
    pub fn check_step(&self, dt_s: f64) -> Result<()> {
        if !(dt_s.is_finite() && dt_s > 0.0) {
            return Err(Error::setting(
                "dt_s",
                format!("must be positive and finite, got {dt_s}"),
            ));
        }
        let f = self.fastest_mode();
        if dt_s * f.rate_per_s > MAX_STEP_TIMES_RATE {
            return Err(Error::setting(
                "dt_s",
                format!(
                    "a step of {dt_s} s cannot resolve the string's mode {} ({:.4} rad/s, damping \
                     ratio {:.3}): RK4 needs dt ≤ {:.3e} s for it",
                    f.mode,
                    f.frequency_rad_s,
                    f.damping_ratio,
                    MAX_STEP_TIMES_RATE / f.rate_per_s
                ),
            ));
        }
        Ok(())
    }

    /// Lags (rad) of steady rotation under a bit torque `torque_nm`: every element carries it.
    pub fn steady_lags_rad(&self, torque_nm: f64) -> Vec<f64> {
        self.stiffness_nm_per_rad
            .iter()
            .scan(0.0, |lag, k| {
                *lag += torque_nm / k;
                Some(*lag)
            })
            .collect()
    }
}

/// The state of one string: each node's lag u_j = Ωt − θ_j (rad) and speed w_j (rad/s), and
/// whether the bit is stuck. Nodes past the chain's are zero.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StringState {
    pub lag_rad: [f64; MAX_NODES],
    pub speed_rad_s: [f64; MAX_NODES],
    pub stuck: bool,
}

/// What one string is: its law and parameters (torques in N·m), operating point and start.
#[derive(Clone, Debug, PartialEq)]
pub struct StringJob {
    pub law: Law,
    /// Parameters, torques in N·m (SI); unused ones zero.
    pub params_nm: [f64; 6],
    /// Top-drive speed Ω (rad/s).
    pub omega_rad_s: f64,
    /// Weight-on-bit ratio r = W / W_ref.
    pub ratio: f64,
    pub start: StringState,
}

/// How long and how finely every string of a batch is integrated, and what is recorded.
#[derive(Clone, Debug, PartialEq)]
pub struct Schedule {
    /// Integration step (s).
    pub dt_s: f64,
    /// Steps per recorded sample.
    pub steps_per_sample: u32,
    /// Sample periods integrated before recording starts.
    pub settle_samples: u32,
    /// Samples recorded into the summary.
    pub record_samples: u32,
}

/// Most samples or settling periods in one schedule: lavapipe ends a loop after 65,535 passes.
pub const MAX_SAMPLES: u32 = 65_535;

impl Schedule {
    /// A schedule of `settle_s` then `record_s` at `sample_hz`, each sample period split into
    /// equal steps no longer than `dt_s`.
    pub fn new(dt_s: f64, sample_hz: f64, settle_s: f64, record_s: f64) -> Result<Self> {
        for (field, v) in [("dt_s", dt_s), ("sample_hz", sample_hz), ("record_s", record_s)] {
            if !(v.is_finite() && v > 0.0) {
                return Err(Error::setting(field, format!("must be positive and finite, got {v}")));
            }
        }
        if !(settle_s.is_finite() && settle_s >= 0.0) {
            return Err(Error::setting(
                "settle_s",
                format!("must be finite and not negative, got {settle_s}"),
            ));
        }
        let period = 1.0 / sample_hz;
        if dt_s > period {
            return Err(Error::setting(
                "dt_s",
                format!("the integration step {dt_s} s exceeds the sample period {period} s"),
            ));
        }
        let steps_per_sample = (period / dt_s).ceil();
        let settle_samples = (settle_s * sample_hz).round();
        let record_samples = (record_s * sample_hz).round().max(1.0);
        for (field, n) in [
            ("settle_s", settle_samples),
            ("record_s", record_samples),
            ("dt_s", steps_per_sample),
        ] {
            if n > MAX_SAMPLES as f64 {
                return Err(Error::setting(
                    field,
                    format!("{n} periods at {sample_hz} Hz: at most {MAX_SAMPLES} per string"),
                ));
            }
        }
        Ok(Self {
            dt_s: period / steps_per_sample,
            steps_per_sample: steps_per_sample as u32,
            settle_samples: settle_samples as u32,
            record_samples: record_samples as u32,
        })
    }

    /// Steps integrated per string.
    pub fn steps(&self) -> u64 {
        u64::from(self.steps_per_sample) * u64::from(self.settle_samples + self.record_samples)
    }

    /// Simulated seconds per string.
    pub fn seconds(&self) -> f64 {
        self.steps() as f64 * self.dt_s
    }

    /// Sample period (s).
    pub fn sample_period_s(&self) -> f64 {
        self.dt_s * f64::from(self.steps_per_sample)
    }
}

/// What a string did while recorded: the same reduction of a record's samples
/// ([`Summary::push`]) whether they come from a simulated string or from a rig.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Summary {
    pub samples: u32,
    /// Samples with |bit speed| below [`STUCK_SPEED_RAD_S`].
    pub stuck: u32,
    /// Stuck samples that follow a sample that was not: the stick phases begun.
    pub stick_onsets: u32,
    /// Sample index of the first and the last stick onset.
    pub first_onset: u32,
    pub last_onset: u32,
    pub speed_min_rad_s: f64,
    pub speed_max_rad_s: f64,
    pub speed_sum_rad_s: f64,
    pub bit_torque_min_nm: f64,
    pub bit_torque_max_nm: f64,
    pub surface_torque_min_nm: f64,
    pub surface_torque_max_nm: f64,
    /// The integration left physical bounds (a speed past the runaway limit, or not finite):
    /// every other field is then meaningless.
    pub diverged: bool,
    /// Whether the last sample pushed was stuck (for counting onsets).
    pub last_stuck: bool,
}

impl Default for Summary {
    fn default() -> Self {
        Self {
            samples: 0,
            stuck: 0,
            stick_onsets: 0,
            first_onset: 0,
            last_onset: 0,
            speed_min_rad_s: f64::INFINITY,
            speed_max_rad_s: f64::NEG_INFINITY,
            speed_sum_rad_s: 0.0,
            bit_torque_min_nm: f64::INFINITY,
            bit_torque_max_nm: f64::NEG_INFINITY,
            surface_torque_min_nm: f64::INFINITY,
            surface_torque_max_nm: f64::NEG_INFINITY,
            diverged: false,
            last_stuck: false,
        }
    }
}

impl Summary {
    /// Adds one sample: bit speed (rad/s), torque on bit and surface torque (N·m; NaN where a
    /// record has no such channel, which then stays at ±∞).
    pub fn push(&mut self, speed_rad_s: f64, bit_torque_nm: f64, surface_torque_nm: f64) {
        let stuck = speed_rad_s.abs() < STUCK_SPEED_RAD_S;
        let was_stuck = self.samples > 0 && self.last_stuck;
        if stuck {
            if !was_stuck {
                if self.stick_onsets == 0 {
                    self.first_onset = self.samples;
                }
                self.last_onset = self.samples;
                self.stick_onsets += 1;
            }
            self.stuck += 1;
        }
        self.speed_min_rad_s = self.speed_min_rad_s.min(speed_rad_s);
        self.speed_max_rad_s = self.speed_max_rad_s.max(speed_rad_s);
        self.speed_sum_rad_s += speed_rad_s;
        self.bit_torque_min_nm = self.bit_torque_min_nm.min(bit_torque_nm);
        self.bit_torque_max_nm = self.bit_torque_max_nm.max(bit_torque_nm);
        self.surface_torque_min_nm = self.surface_torque_min_nm.min(surface_torque_nm);
        self.surface_torque_max_nm = self.surface_torque_max_nm.max(surface_torque_nm);
        self.samples += 1;
        self.last_stuck = stuck;
    }
}

impl Summary {
    /// Share of the samples stuck.
    pub fn stuck_share(&self) -> f64 {
        if self.samples == 0 {
            0.0
        } else {
            f64::from(self.stuck) / f64::from(self.samples)
        }
    }

    /// Mean bit speed (rad/s).
    pub fn speed_mean_rad_s(&self) -> f64 {
        self.speed_sum_rad_s / f64::from(self.samples.max(1))
    }

    /// Stick-slip severity (max − min) / (2·mean) of the bit speed: 0 for steady rotation, 1 or
    /// more for a bit that stops.
    pub fn severity(&self) -> f64 {
        if self.samples == 0 {
            return f64::NAN;
        }
        crate::data::severity(self.speed_min_rad_s, self.speed_max_rad_s, self.speed_mean_rad_s()).unwrap_or(f64::NAN)
    }

    /// Period of the stick-slip cycle (s) at `sample_hz`: the mean time between stick onsets,
    /// `None` with fewer than two.
    pub fn period_s(&self, sample_hz: f64) -> Option<f64> {
        (self.stick_onsets >= 2)
            .then(|| f64::from(self.last_onset - self.first_onset) / f64::from(self.stick_onsets - 1) / sample_hz)
    }

    /// True when the recorded string (or record) is stick-slipping: stuck at least
    /// [`STICK_SLIP_STUCK_SHARE`] of the time.
    pub fn stick_slips(&self) -> bool {
        !self.diverged && self.stuck_share() >= STICK_SLIP_STUCK_SHARE
    }
}

/// Strings integrated together: the batch's strings of one law go through the integrator
/// [`LANES`] at a time, every array holding one value per string, so that the arithmetic of
/// the RK4 stages and the law's exp and tanh run on the CPU's vector units. Each lane's
/// arithmetic is the one-string integrator's, operation for operation, so a string's summary
/// does not depend on which strings share its lanes.
pub const LANES: usize = 8;

/// The states of `L` strings of `N` nodes, string `l` in lane `l` of every array: lags (rad),
/// speeds (rad/s), and whether each bit is stuck. The 1-DOF string gets arrays of one node,
/// so that a step copies and zeroes L·16 bytes, not L·256.
#[derive(Clone, Copy)]
struct Nodes<const N: usize, const L: usize> {
    lag: [[f64; L]; N],
    speed: [[f64; L]; N],
    stuck: [bool; L],
}

impl<const N: usize, const L: usize> Nodes<N, L> {
    fn of(starts: [&StringState; L]) -> Self {
        Self {
            lag: std::array::from_fn(|j| std::array::from_fn(|l| starts[l].lag_rad[j])),
            speed: std::array::from_fn(|j| std::array::from_fn(|l| starts[l].speed_rad_s[j])),
            stuck: std::array::from_fn(|l| starts[l].stuck),
        }
    }

    /// String `l`'s state.
    fn lane(&self, l: usize) -> StringState {
        let mut s = StringState {
            lag_rad: [0.0; MAX_NODES],
            speed_rad_s: [0.0; MAX_NODES],
            stuck: self.stuck[l],
        };
        for j in 0..N {
            s.lag_rad[j] = self.lag[j][l];
            s.speed_rad_s[j] = self.speed[j][l];
        }
        s
    }

    /// String `l`'s state taken from `from`.
    fn take_lane(&mut self, from: &Self, l: usize) {
        for j in 0..N {
            self.lag[j][l] = from.lag[j][l];
            self.speed[j][l] = from.speed[j][l];
        }
        self.stuck[l] = from.stuck[l];
    }
}

/// What ends a lane's pass of the event rule short of the step's end.
#[derive(Clone, Copy, PartialEq)]
enum Event {
    /// None: the lane has finished its step (or had none to take).
    Done,
    /// The stuck bit is released inside the step.
    Release,
    /// The slipping bit's speed reaches zero inside the step.
    Stop,
}

/// `L` strings of one law being integrated: each string's chain (all of the same number of
/// nodes, at most `N`), law parameters and operating point, and the states.
struct Integrator<const N: usize, const L: usize> {
    /// The chains' nodes (≤ N).
    n: usize,
    /// Each chain's lumped inertias (kg·m²), `inertia[j][l]` string `l`'s node `j`.
    inertia: [[f64; L]; N],
    /// Each chain's element stiffnesses (N·m/rad), element j above node j.
    stiffness: [[f64; L]; N],
    /// Each chain's Rayleigh damping: α (1/s) and β (s).
    alpha: [f64; L],
    beta: [f64; L],
    law: Law,
    /// The law's parameters (N·m), padded: `params[i][l]` is string `l`'s i-th; the law reads
    /// its first `n_params`.
    params: [[f64; L]; 6],
    omega: [f64; L],
    ratio: [f64; L],
    /// Static torque T_s = max(r·T(0), 0) (N·m).
    static_nm: [f64; L],
    /// Bit speed beyond which the motion has run away (rad/s): a thousand times the rotary
    /// speed, and never under 1,000 rad/s (≈ 9,550 rpm), far above any stick-slip peak (a few
    /// times Ω) yet far below where f64 overflows, so that a law whose torque turns negative at
    /// high speed is reported instead of producing a finite trace of absurd speeds.
    runaway: [f64; L],
    state: Nodes<N, L>,
    /// Direction of slip (±1) while not stuck.
    dir: [f64; L],
    /// Lanes still integrated: a string that has left physical bounds is not (its state stays
    /// as it was then, and its lane takes no part in the event rule).
    live: [bool; L],
}

// The lanes' loops index several arrays by lane at once, as a kernel's threads do.
#[allow(clippy::needless_range_loop)]
impl<const N: usize, const L: usize> Integrator<N, L> {
    /// The strings of `jobs`, all of one law, string `l` on `chains[l]` (all of as many nodes).
    fn new(chains: [&Chain; L], jobs: [&StringJob; L]) -> Self {
        let n = chains[0].nodes();
        debug_assert!(n <= N && chains.iter().all(|c| c.nodes() == n));
        let node = |values: fn(&Chain) -> &[f64]| -> [[f64; L]; N] {
            std::array::from_fn(|j| std::array::from_fn(|l| values(chains[l]).get(j).copied().unwrap_or(0.0)))
        };
        let law = jobs[0].law;
        debug_assert!(jobs.iter().all(|j| j.law == law));
        let bit = n - 1;
        let mut out = Self {
            n: if N == 1 { 1 } else { n },
            inertia: node(|c| &c.inertia_kg_m2),
            stiffness: node(|c| &c.stiffness_nm_per_rad),
            alpha: chains.map(|c| c.alpha_per_s),
            beta: chains.map(|c| c.beta_s),
            law,
            params: std::array::from_fn(|i| std::array::from_fn(|l| jobs[l].params_nm[i])),
            omega: [0.0; L],
            ratio: [0.0; L],
            static_nm: [0.0; L],
            runaway: [0.0; L],
            state: Nodes::of(jobs.map(|j| &j.start)),
            dir: jobs.map(|j| if j.start.speed_rad_s[bit] < 0.0 { -1.0 } else { 1.0 }),
            live: [true; L],
        };
        out.set_operating_point(jobs.map(|j| j.omega_rad_s), jobs.map(|j| j.ratio));
        out
    }

    /// The top drive's speed Ω (rad/s) and the weight ratio r of each string from now on.
    fn set_operating_point(&mut self, omega_rad_s: [f64; L], ratio: [f64; L]) {
        self.omega = omega_rad_s;
        self.ratio = ratio;
        self.static_nm = self.torque(&[0.0; L]).map(|t| t.max(0.0));
        self.runaway = omega_rad_s.map(|o| 1e3 * o.abs().max(1.0));
    }

    /// r·T(w) of each string, its law's torque at its weight (N·m).
    #[inline(always)]
    fn torque(&self, w: &[f64; L]) -> [f64; L] {
        self.law.torque_lanes(&self.params, w, &self.ratio)
    }

    /// F_j = (K u)_j + (C v)_j with v = Ω − w, at node `j` (N·m).
    #[inline(always)]
    fn string_torque(&self, u: &[[f64; L]; N], w: &[[f64; L]; N], j: usize) -> [f64; L] {
        let below = j + 1 < self.n;
        let mut out = [0.0; L];
        for l in 0..L {
            let (k, beta) = (self.stiffness[j][l], self.beta[l]);
            let (u_above, v_above) = if j == 0 {
                (0.0, 0.0)
            } else {
                (u[j - 1][l], self.omega[l] - w[j - 1][l])
            };
            let v = self.omega[l] - w[j][l];
            let mut f = k * (u[j][l] - u_above) + beta * k * (v - v_above) + self.alpha[l] * self.inertia[j][l] * v;
            if below {
                let kb = self.stiffness[j + 1][l];
                f -= kb * (u[j + 1][l] - u[j][l]) + beta * kb * ((self.omega[l] - w[j + 1][l]) - v);
            }
            out[l] = f;
        }
        out
    }

    /// The time derivative of (u, w): each bit held at rest where `stuck`, slipping in `dir`
    /// otherwise.
    #[inline(always)]
    fn derivative(&self, s: &Nodes<N, L>, stuck: &[bool; L], dir: &[f64; L]) -> ([[f64; L]; N], [[f64; L]; N]) {
        let n = self.n;
        let mut du = [[0.0; L]; N];
        let mut dw = [[0.0; L]; N];
        for j in 0..n {
            let f = self.string_torque(&s.lag, &s.speed, j);
            for l in 0..L {
                du[j][l] = self.omega[l] - s.speed[j][l];
            }
            if j == n - 1 {
                let mut along = [0.0; L];
                for l in 0..L {
                    along[l] = dir[l] * s.speed[j][l];
                }
                let torque = self.torque(&along);
                for l in 0..L {
                    dw[j][l] = if stuck[l] {
                        0.0
                    } else {
                        (f[l] - dir[l] * torque[l]) / self.inertia[j][l]
                    };
                }
            } else {
                for l in 0..L {
                    dw[j][l] = f[l] / self.inertia[j][l];
                }
            }
        }
        (du, dw)
    }

    /// One classical RK4 step from `s`, of `h[l]` (s) in lane `l`.
    #[inline(always)]
    fn rk4(&self, s: &Nodes<N, L>, stuck: &[bool; L], dir: &[f64; L], h: &[f64; L]) -> Nodes<N, L> {
        let n = self.n;
        let along = |d: &([[f64; L]; N], [[f64; L]; N]), f: &[f64; L]| {
            let mut t = *s;
            for j in 0..n {
                for l in 0..L {
                    t.lag[j][l] += f[l] * d.0[j][l];
                    t.speed[j][l] += f[l] * d.1[j][l];
                }
            }
            t
        };
        let mut half = [0.0; L];
        for l in 0..L {
            half[l] = 0.5 * h[l];
        }
        let k1 = self.derivative(s, stuck, dir);
        let k2 = self.derivative(&along(&k1, &half), stuck, dir);
        let k3 = self.derivative(&along(&k2, &half), stuck, dir);
        let k4 = self.derivative(&along(&k3, h), stuck, dir);
        let mut out = *s;
        for j in 0..n {
            for l in 0..L {
                out.lag[j][l] += h[l] / 6.0 * (k1.0[j][l] + 2.0 * (k2.0[j][l] + k3.0[j][l]) + k4.0[j][l]);
                out.speed[j][l] += h[l] / 6.0 * (k1.1[j][l] + 2.0 * (k2.1[j][l] + k3.1[j][l]) + k4.1[j][l]);
            }
        }
        out
    }

    /// The torque the string drives each bit with (N·m).
    #[inline(always)]
    fn bit_drive(&self, s: &Nodes<N, L>) -> [f64; L] {
        self.string_torque(&s.lag, &s.speed, self.n - 1)
    }

    /// Stuck or slipping, for bit `l` at rest, driven by the string's torque `drive` (N·m).
    #[inline(always)]
    fn settle_at_rest(&mut self, l: usize, drive: f64) {
        self.state.stuck[l] = drive.abs() <= self.static_nm[l];
        if !self.state.stuck[l] {
            self.dir[l] = if drive > 0.0 { 1.0 } else { -1.0 };
        }
    }

    /// Advances every live string one step of `h` (s): a pass integrates each lane to the end
    /// of what remains of its step, or, where its bit stops or is released inside it, to that
    /// event (one more RK4 from the pass's start, for the lanes that need it), and goes on from
    /// there in the next pass.
    #[inline(always)]
    fn step(&mut self, h: f64) {
        let bit = self.n - 1;
        let mut remaining = [0.0; L];
        for l in 0..L {
            if self.live[l] {
                remaining[l] = h;
            }
        }
        for _ in 0..EVENT_PASSES {
            if remaining.iter().all(|&r| r <= 0.0) {
                break;
            }
            let start = self.state;
            let stuck = start.stuck;
            let dir = self.dir;
            let end = self.rk4(&start, &stuck, &dir, &remaining);
            let (f0, f1) = (self.bit_drive(&start), self.bit_drive(&end));
            let mut to_event = [0.0; L];
            let mut event = [Event::Done; L];
            for l in 0..L {
                if remaining[l] <= 0.0 {
                    continue;
                }
                if stuck[l] {
                    if f1[l].abs() <= self.static_nm[l] {
                        self.state.take_lane(&end, l);
                        remaining[l] = 0.0;
                        continue;
                    }
                    // Released inside the step, where F_bit reaches ±T_s (linear in between).
                    let bound = if f1[l] > 0.0 {
                        self.static_nm[l]
                    } else {
                        -self.static_nm[l]
                    };
                    let fraction = if (f1[l] - f0[l]).abs() > 0.0 {
                        ((bound - f0[l]) / (f1[l] - f0[l])).clamp(0.0, 1.0)
                    } else {
                        0.0
                    };
                    to_event[l] = fraction * remaining[l];
                    event[l] = Event::Release;
                } else {
                    let (w0, w1) = (dir[l] * start.speed[bit][l], dir[l] * end.speed[bit][l]);
                    if w1 > 0.0 {
                        self.state.take_lane(&end, l);
                        remaining[l] = 0.0;
                        continue;
                    }
                    self.state.take_lane(&end, l);
                    if w0 <= 0.0 {
                        // Released at rest, yet not moving forward at the step's end: at rest again.
                        self.state.speed[bit][l] = 0.0;
                        let drive = self.bit_drive(&self.state)[l];
                        self.settle_at_rest(l, drive);
                        remaining[l] = 0.0;
                        continue;
                    }
                    // The bit speed crosses zero inside the step: one secant, then re-integrate to it.
                    to_event[l] = remaining[l] * w0 / (w0 - w1);
                    event[l] = Event::Stop;
                }
            }
            if event.iter().all(|&e| e == Event::Done) {
                continue;
            }
            let part = self.rk4(&start, &stuck, &dir, &to_event);
            for l in 0..L {
                match event[l] {
                    Event::Done => {}
                    Event::Release => {
                        self.state.take_lane(&part, l);
                        self.state.stuck[l] = false;
                        self.dir[l] = if f1[l] > 0.0 { 1.0 } else { -1.0 };
                        remaining[l] -= to_event[l];
                    }
                    Event::Stop => {
                        self.state.take_lane(&part, l);
                        self.state.speed[bit][l] = 0.0;
                        remaining[l] -= to_event[l];
                        let drive = self.bit_drive(&self.state)[l];
                        self.settle_at_rest(l, drive);
                    }
                }
            }
        }
    }

    /// Whether each string's motion stays within physical bounds (checked once per sample
    /// period, as the kernel does).
    #[inline(always)]
    fn in_bounds(&self) -> [bool; L] {
        let bit = self.n - 1;
        let mut inside = [false; L];
        for l in 0..L {
            inside[l] = self.state.speed[bit][l].abs() <= self.runaway[l] && self.state.lag[bit][l].abs() < 3.0e38;
        }
        inside
    }

    /// Torque on each bit (N·m): the reaction while stuck, the law's torque while slipping.
    #[inline(always)]
    fn bit_torque(&self) -> [f64; L] {
        let bit = self.n - 1;
        let drive = self.bit_drive(&self.state);
        let mut along = [0.0; L];
        for l in 0..L {
            along[l] = self.dir[l] * self.state.speed[bit][l];
        }
        let torque = self.torque(&along);
        let mut out = [0.0; L];
        for l in 0..L {
            out[l] = if self.state.stuck[l] {
                drive[l].clamp(-self.static_nm[l], self.static_nm[l])
            } else {
                self.dir[l] * torque[l]
            };
        }
        out
    }

    /// Torque the top drive applies to each string (N·m): the top element's spring and its
    /// β-damping.
    #[inline(always)]
    fn surface_torque(&self) -> [f64; L] {
        let mut out = [0.0; L];
        for l in 0..L {
            let k = self.stiffness[0][l];
            out[l] = k * self.state.lag[0][l] + self.beta[l] * k * (self.omega[l] - self.state.speed[0][l]);
        }
        out
    }

    /// Integrates the strings through `schedule`: each one's summary and final state.
    #[inline(always)]
    fn run(mut self, schedule: &Schedule) -> [(Summary, StringState); L] {
        let mut summaries = [Summary::default(); L];
        let h = schedule.dt_s;
        let bit = self.n - 1;
        let mut ended: [Option<StringState>; L] = [None; L];
        for period in 0..schedule.settle_samples + schedule.record_samples {
            for _ in 0..schedule.steps_per_sample {
                self.step(h);
            }
            for (l, inside) in self.in_bounds().into_iter().enumerate() {
                if self.live[l] && !inside {
                    summaries[l].diverged = true;
                    ended[l] = Some(self.state.lane(l));
                    self.live[l] = false;
                }
            }
            if !self.live.contains(&true) {
                break;
            }
            if period >= schedule.settle_samples {
                let (bit_torque, surface_torque) = (self.bit_torque(), self.surface_torque());
                for l in (0..L).filter(|&l| self.live[l]) {
                    summaries[l].push(self.state.speed[bit][l], bit_torque[l], surface_torque[l]);
                }
            }
        }
        std::array::from_fn(|l| (summaries[l], ended[l].unwrap_or_else(|| self.state.lane(l))))
    }
}

/// Integrates the strings of `jobs` (one law, [`LANES`] of them) through `schedule` together,
/// with AVX2 where the CPU has it (the same operations, in wider registers: the same bits).
fn integrate_lanes<const N: usize>(
    chain: &Chain,
    schedule: &Schedule,
    jobs: [&StringJob; LANES],
) -> [(Summary, StringState); LANES] {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU supports AVX2, checked just above.
        return unsafe { integrate_lanes_avx2::<N>(chain, schedule, jobs) };
    }
    Integrator::<N, LANES>::new([chain; LANES], jobs).run(schedule)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn integrate_lanes_avx2<const N: usize>(
    chain: &Chain,
    schedule: &Schedule,
    jobs: [&StringJob; LANES],
) -> [(Summary, StringState); LANES] {
    Integrator::<N, LANES>::new([chain; LANES], jobs).run(schedule)
}

/// Integrates one string through `schedule`: its summary and its final state. The 1-DOF
/// string runs on arrays of one node, a chain on arrays of [`MAX_NODES`]; the arithmetic is
/// the same.
pub fn integrate(chain: &Chain, schedule: &Schedule, job: &StringJob) -> (Summary, StringState) {
    let [out] = if chain.nodes() == 1 {
        Integrator::<1, 1>::new([chain], [job]).run(schedule)
    } else {
        Integrator::<MAX_NODES, 1>::new([chain], [job]).run(schedule)
    };
    out
}

/// The 1-DOF string integrated step by step, its law, parameters and operating point
/// changeable between steps: what `simulate` records a trace with, where the batch summarises
/// the same steps ([`integrate`]).
pub struct Stepper(Integrator<1, 1>);

impl Stepper {
    /// The string of `job` on `chain`, a chain of one node ([`Chain::one_dof`]), at its start.
    pub fn new(chain: &Chain, job: &StringJob) -> Self {
        assert_eq!(chain.nodes(), 1, "a stepper integrates the 1-DOF string");
        Self(Integrator::new([chain], [job]))
    }

    /// The top drive's speed Ω (rad/s) and the weight ratio r = W/W_ref from now on.
    pub fn set_operating_point(&mut self, omega_rad_s: f64, ratio: f64) {
        self.0.set_operating_point([omega_rad_s], [ratio]);
    }

    /// The law at the bit and its parameters (torques in N·m) from now on.
    pub fn set_law(&mut self, law: Law, params_nm: &[f64]) {
        let padded = padded(params_nm);
        self.0.law = law;
        self.0.params = std::array::from_fn(|i| [padded[i]]);
        self.0.set_operating_point(self.0.omega, self.0.ratio);
    }

    /// Advances one step of `h_s` (s) through any stop or release inside it.
    pub fn step(&mut self, h_s: f64) {
        self.0.step(h_s);
    }

    /// False once the motion has left physical bounds (a bit speed past a thousand times the
    /// rotary speed, or a state no longer finite).
    pub fn in_bounds(&self) -> bool {
        self.0.in_bounds()[0]
    }

    /// The bit's speed (rad/s).
    pub fn bit_speed_rad_s(&self) -> f64 {
        self.0.state.speed[0][0]
    }

    /// Torque on bit (N·m): the reaction while stuck, the law's torque while slipping.
    pub fn bit_torque_nm(&self) -> f64 {
        self.0.bit_torque()[0]
    }

    /// Torque the top drive applies to the string (N·m): what a rig's surface torque channel
    /// measures.
    pub fn surface_torque_nm(&self) -> f64 {
        self.0.surface_torque()[0]
    }
}

/// `L` 1-DOF strings of one law integrated step by step together, each on its own chain, under
/// one drive: [`Stepper`]'s steps lane by lane, what a surface run's candidates are simulated
/// with on the CPU. A lane once stopped ([`Steppers::stop`]) keeps its state.
pub struct Steppers<const L: usize>(Integrator<1, L>);

impl<const L: usize> Steppers<L> {
    /// The strings of `jobs` (all of one law), string `l` on `chains[l]`, each a chain of one
    /// node.
    #[inline(always)]
    pub fn new(chains: [&Chain; L], jobs: [&StringJob; L]) -> Self {
        assert!(
            chains.iter().all(|c| c.nodes() == 1),
            "steppers integrate the 1-DOF string"
        );
        Self(Integrator::new(chains, jobs))
    }

    /// Every string's top-drive speed Ω (rad/s) and weight ratio r = W/W_ref from now on.
    #[inline(always)]
    pub fn set_operating_point(&mut self, omega_rad_s: f64, ratio: f64) {
        self.0.set_operating_point([omega_rad_s; L], [ratio; L]);
    }

    /// Advances every string not stopped one step of `h_s` (s).
    #[inline(always)]
    pub fn step(&mut self, h_s: f64) {
        self.0.step(h_s);
    }

    /// Integrates lane `l` no further.
    #[inline(always)]
    pub fn stop(&mut self, l: usize) {
        self.0.live[l] = false;
    }

    /// Whether each string's motion is within physical bounds ([`Stepper::in_bounds`]).
    #[inline(always)]
    pub fn in_bounds(&self) -> [bool; L] {
        self.0.in_bounds()
    }

    /// Each bit's speed (rad/s).
    #[inline(always)]
    pub fn bit_speeds_rad_s(&self) -> [f64; L] {
        self.0.state.speed[0]
    }

    /// Torque the top drive applies to each string (N·m).
    #[inline(always)]
    pub fn surface_torques_nm(&self) -> [f64; L] {
        self.0.surface_torque()
    }
}

/// The state of steady rotation at Ω under the law's torque r·T(Ω), its bit speed kicked by
/// `kick_rad_s` (a kick of zero stays on the equilibrium).
pub fn steady_start(
    chain: &Chain,
    law: Law,
    params_nm: &[f64],
    omega_rad_s: f64,
    ratio: f64,
    kick_rad_s: f64,
) -> StringState {
    // The integrator's own torque, so that a kick of zero starts exactly on its equilibrium.
    let p = padded(&params_nm[..law.n_params()]);
    let [torque] = law.torque_lanes(&p.map(|v| [v]), &[omega_rad_s], &[ratio]);
    let mut state = StringState {
        lag_rad: [0.0; MAX_NODES],
        speed_rad_s: [0.0; MAX_NODES],
        stuck: false,
    };
    for (j, lag) in chain.steady_lags_rad(torque).into_iter().enumerate() {
        state.lag_rad[j] = lag;
        state.speed_rad_s[j] = omega_rad_s;
    }
    state.speed_rad_s[chain.nodes() - 1] += kick_rad_s;
    state
}

/// Parameters padded to the kernels' six.
pub fn padded(params_nm: &[f64]) -> [f64; 6] {
    let mut p = [0.0; 6];
    p[..params_nm.len()].copy_from_slice(params_nm);
    p
}

/// Every string of a batch on the CPU, in the batch's order, [`LANES`] at a time
/// ([`in_lanes`]).
pub fn integrate_batch(chain: &Chain, schedule: &Schedule, jobs: &[StringJob]) -> Vec<(Summary, StringState)> {
    in_lanes(
        jobs,
        |job| job.law,
        |lanes| {
            if chain.nodes() == 1 {
                integrate_lanes::<1>(chain, schedule, lanes)
            } else {
                integrate_lanes::<MAX_NODES>(chain, schedule, lanes)
            }
        },
    )
}

/// `run` over `items` [`LANES`] at a time, the results in the items' order: each law's items
/// in groups of [`LANES`] (a last, short group padded with copies of its first item, whose
/// results are dropped), the groups on rayon's threads.
pub fn in_lanes<T: Sync, R: Send>(
    items: &[T],
    law_of: impl Fn(&T) -> Law,
    run: impl Fn([&T; LANES]) -> [R; LANES] + Sync,
) -> Vec<R> {
    use rayon::prelude::*;
    let mut order: Vec<usize> = (0..items.len()).collect();
    order.sort_by_key(|&i| law_of(&items[i]));
    let groups: Vec<&[usize]> = order
        .chunk_by(|&a, &b| law_of(&items[a]) == law_of(&items[b]))
        .flat_map(|law| law.chunks(LANES))
        .collect();
    let results: Vec<[R; LANES]> = groups
        .par_iter()
        .with_max_len(1)
        .map(|group| {
            run(std::array::from_fn(|l| {
                &items[group.get(l).copied().unwrap_or(group[0])]
            }))
        })
        .collect();
    let mut out: Vec<Option<R>> = std::iter::repeat_with(|| None).take(items.len()).collect();
    for (group, lanes) in groups.iter().zip(results) {
        for (&i, result) in group.iter().zip(lanes) {
            out[i] = Some(result);
        }
    }
    out.into_iter().map(|r| r.expect("every item is in a group")).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::laws::PAPER_W_REF_N;
    use crate::units::RAD_S_PER_RPM;

    fn paper_nm(law: Law) -> [f64; 6] {
        padded(&law.scale_torque(law.paper_estimate().unwrap(), 1000.0))
    }

    fn job(law: Law, chain: &Chain, rpm: f64, ratio: f64, kick: f64) -> StringJob {
        let p = paper_nm(law);
        let omega = rpm * RAD_S_PER_RPM;
        StringJob {
            law,
            params_nm: p,
            omega_rad_s: omega,
            ratio,
            start: steady_start(chain, law, &p, omega, ratio, kick * omega),
        }
    }

    /// From the settled cycle of m2 at 60 rpm and 244 kN, the top drive moved: the stuck share
    /// of the minute after the first, at each step size.
    fn after_switch(dt: f64, rpm: f64, ratio: f64) -> f64 {
        let chain = Chain::one_dof(&Lumped::default());
        let settle = Schedule::new(dt, 50.0, 60.0, 20.0).unwrap();
        let (s, state) = integrate(&chain, &settle, &job(Law::M2, &chain, 60.0, 1.0, 0.1));
        assert!(s.stuck_share() > 0.4 && s.stick_slips(), "{s:?}");
        let after = Schedule::new(dt, 50.0, 60.0, 60.0).unwrap();
        let mut j = job(Law::M2, &chain, rpm, ratio, 0.0);
        j.start = state;
        integrate(&chain, &after, &j).0.stuck_share()
    }

    #[test]
    fn the_stuck_share_does_not_depend_on_the_step() {
        // Measured: 0.360, 0.158 and 0.000 at 85, 120 and 150 rpm, 0.243 at half the weight,
        // the same to three decimals from 1 ms to 20 ms (the events are located within the step).
        for (rpm, ratio, expected) in [
            (85.0, 1.0, 0.36),
            (120.0, 1.0, 0.158),
            (150.0, 1.0, 0.0),
            (60.0, 0.5, 0.243),
        ] {
            for dt in [1e-3, 4e-3, 1e-2, 2e-2] {
                let share = after_switch(dt, rpm, ratio);
                assert!(
                    (share - expected).abs() <= 0.002,
                    "{rpm} rpm, r {ratio}, dt {dt}: {share}"
                );
            }
        }
    }

    #[test]
    fn simulate_records_the_steps_the_batch_summarises() {
        // One integrator: `simulate`'s trace at the batch's step, summarised, is the batch's
        // summary (its first sample is the settled state, one period before the batch's first).
        let omega = 60.0 * RAD_S_PER_RPM;
        let p = paper_nm(Law::M2);
        let cfg = crate::simulate::SimConfig {
            duration_s: 60.02,
            recording: crate::simulate::Recording {
                settle_s: 60.0,
                dt_s: 0.01,
                initial: crate::simulate::Initial::Equilibrium {
                    speed_perturbation_rad_s: 0.1 * omega,
                },
                ..crate::simulate::Recording::default()
            },
            ..crate::simulate::SimConfig::new(Law::M2, p[..3].to_vec(), omega, PAPER_W_REF_N)
        };
        let trace = crate::simulate::simulate(&cfg).unwrap();
        assert_eq!(trace.len(), 3001);
        let mut recorded = Summary::default();
        for (w, t) in trace.bit_speed_rad_s.iter().zip(&trace.torque_nm).skip(1) {
            recorded.push(*w, *t, f64::NAN);
        }
        let chain = Chain::one_dof(&Lumped::default());
        let schedule = Schedule::new(0.01, 50.0, 60.0, 60.0).unwrap();
        let (s, _) = integrate(&chain, &schedule, &job(Law::M2, &chain, 60.0, 1.0, 0.1));
        assert!(s.stick_slips(), "{s:?}");
        assert_eq!((recorded.stuck, recorded.stick_onsets), (s.stuck, s.stick_onsets));
        assert_eq!(
            (recorded.first_onset, recorded.last_onset),
            (s.first_onset, s.last_onset)
        );
        // The sample clock's spans differ from the batch's step in the last bits (measured:
        // 2.5e-9 relative on the peak speed).
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-7 * b.abs().max(1.0);
        assert!(close(recorded.speed_max_rad_s, s.speed_max_rad_s), "{recorded:?} {s:?}");
        assert!(close(recorded.speed_sum_rad_s, s.speed_sum_rad_s), "{recorded:?} {s:?}");
        assert!(
            close(recorded.bit_torque_max_nm, s.bit_torque_max_nm),
            "{recorded:?} {s:?}"
        );
    }

    #[test]
    fn the_lumped_fe_string_keeps_the_fe_string_s_inertia_and_static_stiffness() {
        let fe = DrillString {
            dp_elements: 8,
            bha_elements: 2,
            ..DrillString::default()
        };
        let chain = Chain::lumped_fe(&fe).unwrap();
        let (_, _, k) = fe.matrices();
        assert_eq!(chain.nodes(), 10);
        // Half of each element's inertia to each of its nodes: the string's inertia less the
        // half of the top element that the rotary table carries.
        let inertia = |length_m: f64, outer: f64, inner: f64| {
            fe.density_kg_m3 * std::f64::consts::PI / 32.0 * (outer.powi(4) - inner.powi(4)) * length_m
        };
        let dp = inertia(fe.dp_length_m, fe.dp_outer_m, fe.dp_inner_m);
        let bha = inertia(fe.bha_length_m, fe.bha_outer_m, fe.bha_inner_m);
        let total: f64 = chain.inertia_kg_m2.iter().sum();
        assert!((total - (dp + bha - dp / 16.0)).abs() < 1e-9 * total, "{total}");
        assert!((chain.bit_inertia_kg_m2() - bha / 4.0).abs() < 1e-9 * bha);
        // The chain's tridiagonal K is the FE one, entry by entry.
        for i in 0..10 {
            let below = chain.stiffness_nm_per_rad.get(i + 1).copied().unwrap_or(0.0);
            assert!((chain.stiffness_nm_per_rad[i] + below - k[(i, i)]).abs() < 1e-9 * k[(i, i)]);
        }
        // Steady rotation: every element twisted by T/k, so the bit's lag is T times the
        // series compliance, that of the whole string's static stiffness.
        let lags = chain.steady_lags_rad(1000.0);
        let compliance: f64 = chain.stiffness_nm_per_rad.iter().map(|k| 1.0 / k).sum();
        assert!((lags[9] - 1000.0 * compliance).abs() < 1e-12 * lags[9]);
    }

    #[test]
    fn a_step_too_long_for_the_fastest_mode_is_refused_naming_the_flag_and_the_mode() {
        let fe = DrillString {
            dp_elements: 8,
            bha_elements: 8,
            ..DrillString::default()
        };
        let chain = Chain::lumped_fe(&fe).unwrap();
        let fastest = chain.fastest_mode();
        let limit = MAX_STEP_TIMES_RATE / fastest.rate_per_s;
        assert!(chain.check_step(0.99 * limit).is_ok());
        let e = chain.check_step(1.01 * limit).unwrap_err().to_string();
        assert!(
            e.contains("dt_s") && e.contains(&format!("mode {}", fastest.mode)),
            "{e}"
        );
        // The 1-DOF string's only mode allows steps of seconds.
        assert!(Chain::one_dof(&Lumped::default()).check_step(1.0).is_ok());
    }

    #[test]
    fn a_runaway_law_is_reported_diverged() {
        // m4's cubic turns negative at high speed: from 400 rpm the bit runs away.
        let chain = Chain::one_dof(&Lumped::default());
        let schedule = Schedule::new(0.01, 50.0, 0.0, 60.0).unwrap();
        let (s, _) = integrate(&chain, &schedule, &job(Law::M4, &chain, 400.0, 1.0, 0.1));
        assert!(s.diverged && !s.stick_slips(), "{s:?}");
    }

    #[test]
    fn a_string_s_result_does_not_depend_on_the_strings_sharing_its_lanes() {
        // Fourteen 1-DOF strings of four laws (a full group of eight, short groups padded), one
        // of which runs away, and nine strings on a lumped FE chain: the batch gives each string,
        // to the bit, what integrating it alone gives.
        let one = Chain::one_dof(&Lumped::default());
        let fe = Chain::lumped_fe(&DrillString {
            dp_elements: 4,
            bha_elements: 2,
            ..DrillString::default()
        })
        .unwrap();
        let schedule = |chain: &Chain| {
            let dt = (MAX_STEP_TIMES_RATE / chain.fastest_mode().rate_per_s).min(0.01);
            Schedule::new(dt, 20.0, 20.0, 20.0).unwrap()
        };
        let mut jobs = Vec::new();
        for rpm in [40.0, 60.0, 80.0, 100.0, 120.0, 140.0, 160.0, 180.0, 200.0] {
            jobs.push(job(Law::M2, &one, rpm, 1.0, 0.1));
        }
        jobs.push(job(Law::M4, &one, 400.0, 1.0, 0.1));
        jobs.push(job(Law::M3, &one, 60.0, 0.8, 0.1));
        jobs.push(job(Law::M1, &one, 60.0, 1.0, 0.1));
        jobs.push(job(Law::M3, &one, 90.0, 1.2, -0.1));
        jobs.push(job(Law::M2, &one, 50.0, 0.5, 0.0));
        let fe_jobs: Vec<StringJob> = [30.0, 45.0, 60.0, 75.0, 90.0, 105.0, 120.0, 135.0, 150.0]
            .into_iter()
            .map(|rpm| job(Law::M2, &fe, rpm, 1.0, 0.1))
            .collect();
        let mut diverged = Vec::new();
        for (chain, jobs) in [(&one, &jobs), (&fe, &fe_jobs)] {
            let schedule = schedule(chain);
            let batch = integrate_batch(chain, &schedule, jobs);
            for (k, (job, together)) in jobs.iter().zip(&batch).enumerate() {
                let alone = integrate(chain, &schedule, job);
                assert_eq!(format!("{together:?}"), format!("{alone:?}"), "string {k}");
            }
            assert!(batch.iter().any(|(s, _)| s.stick_slips()));
            if diverged.is_empty() {
                diverged = batch.iter().map(|(s, _)| s.diverged).collect();
            }
        }
        assert_eq!(diverged.iter().filter(|&&d| d).count(), 1, "{diverged:?}");
        assert!(diverged[9]);
    }

    #[test]
    fn a_record_s_summary_counts_stick_phases_and_their_period() {
        // 10 s at 50 Hz: stuck for 1 s every 2.5 s (four phases), 8 rad/s between.
        let mut s = Summary::default();
        for k in 0..500 {
            let t = k as f64 / 50.0;
            let w = if t % 2.5 < 1.0 { 0.0 } else { 8.0 };
            s.push(w, 1.0, 2.0);
        }
        assert_eq!(s.stick_onsets, 4);
        assert!((s.stuck_share() - 0.4).abs() < 1e-12);
        assert!((s.period_s(50.0).unwrap() - 2.5).abs() < 1e-12);
        assert!((s.severity() - 8.0 / (2.0 * 4.8)).abs() < 1e-12);
        assert!(s.stick_slips());
    }
}
