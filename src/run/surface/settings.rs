//! A surface run's settings: as a user gives them ([`Settings`], the gate of
//! [`crate::run::settings`]) and as the run uses them ([`SurfaceSettings`]).

use super::*;

/// A surface run's settings as a user gives them (the command's flags, Python's keyword
/// arguments: the gate of [`crate::run::settings`]), validated once into the
/// [`SurfaceSettings`] it runs; [`Default`] is the command's defaults. The laws come beside
/// them, as for every kind of run.
#[derive(Clone, Debug, PartialEq, Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Settings {
    /// A prior file (TOML) with bounds per law and law weights, torques in the record's unit.
    pub prior_file: Option<std::path::PathBuf>,
    /// Width of the prior boxes: k of each parameter's scale from its physical bound.
    pub prior_scale: f64,
    /// The 1-DOF string's equivalent moment of inertia I_eq, kg·m² (the paper's where none
    /// is given).
    pub inertia_kg_m2: Option<f64>,
    /// The string's natural frequency ω_n, rad/s: a value, or bounds [lo, hi] within which it
    /// is inferred with the law (the paper's 0.85 where none is given).
    pub omega_n_rad_s: Option<ValueOrBounds>,
    /// The string's damping ratio ξ: a value, or bounds [lo, hi] within which it is inferred
    /// with the law (the paper's 0.25 where none is given).
    pub damping_ratio: Option<ValueOrBounds>,
    /// Reference weight on bit W_ref of the laws' parameters, kN; none: r = 1 throughout.
    pub w_ref_kn: Option<f64>,
    /// Standard deviation of the surface torque's noise, kN·m; none: estimated from the record.
    pub noise_sd_knm: Option<f64>,
    /// Particles per population.
    pub particles: usize,
    /// Most populations, the first included.
    pub max_populations: usize,
    /// Wall-time budget of the sampler, s (the population in progress is dropped).
    pub max_seconds: Option<f64>,
    /// Prior simulations that scale the distance (and train the semi-automatic regressions).
    pub pilot: usize,
    /// Records re-simulated per law to check the model choice.
    pub check_replicates: usize,
    /// Posterior draws simulated for the bit's predicted speed.
    pub predictive_draws: usize,
    /// Whether to simulate the escape advice where the bit stick-slips.
    pub advice: bool,
    /// Largest integration step of the simulated strings, s.
    pub dt_s: f64,
    /// Time each simulated string settles before the record's first sample, s.
    pub settle_s: f64,
    /// Seed of every stream: the same seed gives the same result.
    pub seed: u64,
    /// Where the strings are simulated: `auto` (the GPU where one can be set up, else the CPU,
    /// saying so), `gpu` or `cpu`.
    pub backend: Backend,
    /// Semi-automatic ABC (Fearnhead & Prangle 2012): the distance compares what linear
    /// regressions on the pilot strings nearest the record predict from the summaries (each
    /// law's parameters, the string's where inferred, and each law's probability) instead of
    /// the summaries themselves.
    pub semi_automatic: bool,
}

impl Default for Settings {
    fn default() -> Self {
        let run = SurfaceSettings::new(Vec::new());
        Self {
            prior_file: None,
            prior_scale: run.prior_scale,
            inertia_kg_m2: None,
            omega_n_rad_s: None,
            damping_ratio: None,
            w_ref_kn: None,
            noise_sd_knm: None,
            particles: run.smc.schedule.particles,
            max_populations: run.smc.schedule.max_populations,
            max_seconds: None,
            pilot: run.pilot,
            check_replicates: run.check_replicates,
            predictive_draws: run.predictive_draws,
            advice: run.advice,
            dt_s: run.integration.dt_s,
            settle_s: run.integration.settle_s,
            seed: 1,
            backend: run.backend,
            semi_automatic: run.semi_automatic,
        }
    }
}

/// A string parameter as given: a value, or bounds within which a run infers it.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, serde::Deserialize)]
#[serde(untagged, expecting = "a number, or bounds as a pair (low, high)")]
pub enum ValueOrBounds {
    Value(f64),
    Bounds([f64; 2]),
}

impl ValueOrBounds {
    /// The value a string is built with (the bounds' middle) and the bounds where inferred,
    /// each rounded to the f32 the candidates are drawn in.
    fn split(given: Option<Self>, paper: f64) -> (f64, Option<[f64; 2]>) {
        match given {
            None => (paper, None),
            Some(Self::Value(v)) => (v, None),
            // As candidates draw them: f32 (a coordinate of the prior box).
            Some(Self::Bounds(bounds)) => {
                let [lo, hi] = bounds.map(|b| f64::from(b as f32));
                let middle = if StringBounds::fixed([lo, hi]).is_some() {
                    lo
                } else {
                    lo + 0.5 * (hi - lo)
                };
                (middle, Some([lo, hi]))
            }
        }
    }
}

impl std::str::FromStr for ValueOrBounds {
    type Err = String;

    /// `VALUE` or `LO:HI`.
    fn from_str(text: &str) -> std::result::Result<Self, String> {
        let number = |t: &str| {
            t.trim()
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| format!("`{t}` is not a finite number (a value, or bounds LO:HI)"))
        };
        match text.split_once(':') {
            None => Ok(Self::Value(number(text)?)),
            Some((lo, hi)) => Ok(Self::Bounds([number(lo)?, number(hi)?])),
        }
    }
}

impl Settings {
    /// What these settings run for `laws`, validated and its prior file read: a setting it
    /// cannot run is refused here, by name, before any work.
    pub fn config(&self, laws: Vec<Law>) -> Result<SurfaceSettings> {
        let prior = self.prior_file.as_deref().map(PriorFile::read).transpose()?;
        self.config_with_prior(laws, prior)
    }

    /// [`Self::config`] with the prior file already read (a surface directory keeps its text).
    pub fn config_with_prior(&self, laws: Vec<Law>, prior: Option<PriorFile>) -> Result<SurfaceSettings> {
        let mut run = SurfaceSettings::new(laws);
        run.prior_file = prior;
        run.prior_scale = self.prior_scale;
        let paper = Lumped::default();
        let (omega_n_rad_s, omega_bounds) = ValueOrBounds::split(self.omega_n_rad_s, paper.omega_n_rad_s);
        let (damping_ratio, damping_bounds) = ValueOrBounds::split(self.damping_ratio, paper.damping_ratio);
        run.structure = Lumped {
            inertia_kg_m2: self.inertia_kg_m2.unwrap_or(paper.inertia_kg_m2),
            omega_n_rad_s,
            damping_ratio,
        };
        run.string_bounds = (omega_bounds.is_some() || damping_bounds.is_some()).then(|| StringBounds {
            omega_n_rad_s: omega_bounds.unwrap_or([omega_n_rad_s; 2]),
            damping_ratio: damping_bounds.unwrap_or([damping_ratio; 2]),
        });
        run.w_ref_n = self.w_ref_kn.map(|w| w * 1000.0);
        run.noise_sd_nm = self.noise_sd_knm.map(|n| n * 1000.0);
        run.pilot = self.pilot;
        run.check_replicates = self.check_replicates;
        run.predictive_draws = self.predictive_draws;
        run.advice = self.advice;
        run.integration = Integration {
            dt_s: self.dt_s,
            settle_s: self.settle_s,
        };
        run.smc.schedule.particles = self.particles;
        run.smc.schedule.max_populations = self.max_populations;
        run.smc.schedule.max_seconds = self.max_seconds;
        run.backend = self.backend;
        run.semi_automatic = self.semi_automatic;
        run.validate()?;
        Ok(run)
    }
}

/// The string's coordinates a candidate carries after its law's parameters where the run
/// infers the string, by the names the result gives them.
pub const STRING_COORDINATES: [&str; 2] = ["omega_n_rad_s", "damping_ratio"];

/// How a surface record is read into laws.
#[derive(Clone, Debug)]
pub struct SurfaceSettings {
    pub laws: Vec<Law>,
    /// Bounds replacing the physical boxes (torques in the record's unit).
    pub prior_file: Option<PriorFile>,
    /// k: each box spans k of its parameter's scales from its physical bound.
    pub prior_scale: f64,
    /// The 1-DOF string (an inferred parameter at its bounds' middle).
    pub structure: Lumped,
    /// Where the string's natural frequency and damping ratio are inferred with the law, their
    /// bounds; `None`: the string as given.
    pub string_bounds: Option<StringBounds>,
    /// Reference weight on bit of the laws' parameters (N); `None`: r = 1 throughout.
    pub w_ref_n: Option<f64>,
    pub integration: Integration,
    /// Standard deviation of the surface torque's noise (N·m); `None`: estimated.
    pub noise_sd_nm: Option<f64>,
    /// Prior simulations of the pilot (the distance's first scales, the semi-automatic
    /// regressions' training strings, and a lost law's reference in the check).
    pub pilot: usize,
    /// Re-simulated records per law for the check.
    pub check_replicates: usize,
    /// Posterior draws simulated for the bit's predictive band.
    pub predictive_draws: usize,
    pub smc: SmcConfig,
    /// Whether to simulate the escape advice where the bit stick-slips.
    pub advice: bool,
    /// Where the strings are simulated ([`Backend::Auto`]: the GPU where one can be set up).
    pub backend: Backend,
    /// Whether the distance compares the predictions of regressions learned on the pilot
    /// (semi-automatic ABC, [`crate::eval::projection`]) instead of the scaled summaries.
    pub semi_automatic: bool,
    /// Whether a law whose file sets `prior_curve_within` has its box cut to the curves within
    /// that many times the record's largest torque ([`Prior::with_curve_limits`], the
    /// evidence's physical prior). Always, but in a surface directory whose job does not say
    /// so, whose stored populations were drawn from the boxes alone.
    pub curve_limits: bool,
}

/// Bounds of the string's natural frequency (rad/s) and damping ratio within which a run
/// infers them with the law, uniform, as the f32 the candidates are drawn in; a parameter
/// given exactly has equal bounds.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct StringBounds {
    pub omega_n_rad_s: [f64; 2],
    pub damping_ratio: [f64; 2],
}

impl StringBounds {
    /// True where some bound spans a width: a coordinate the run infers.
    pub fn infers(&self) -> bool {
        [self.omega_n_rad_s, self.damping_ratio]
            .iter()
            .any(|b| Self::fixed(*b).is_none())
    }

    /// The value of a parameter with equal bounds (given exactly), else `None`.
    pub(super) fn fixed(bounds: [f64; 2]) -> Option<f64> {
        (bounds[0].to_bits() == bounds[1].to_bits()).then_some(bounds[0])
    }

    /// The strings at the corners of the bounds, with the inertia `inertia_kg_m2`.
    pub(super) fn corners(&self, inertia_kg_m2: f64) -> impl Iterator<Item = Lumped> + '_ {
        self.omega_n_rad_s.into_iter().flat_map(move |omega_n_rad_s| {
            self.damping_ratio.into_iter().map(move |damping_ratio| Lumped {
                inertia_kg_m2,
                omega_n_rad_s,
                damping_ratio,
            })
        })
    }
}

/// The default prior scale k: as wide as the evidence's boxes.
pub const DEFAULT_PRIOR_SCALE: f64 = crate::run::evidence::DEFAULT_PRIOR_SCALE;
/// Most populations by default, the first included.
pub const DEFAULT_MAX_POPULATIONS: usize = 8;
/// Pilot simulations by default.
pub const DEFAULT_PILOT: usize = 1000;
/// Re-simulations per law by default: a small check, run always.
pub const DEFAULT_CHECK_REPLICATES: usize = 10;
/// Posterior draws for the predictive band by default.
pub const DEFAULT_PREDICTIVE_DRAWS: usize = 100;
/// Fewest cycles a record must show for its dynamics to inform the law.
pub const MIN_CYCLES: f64 = 3.0;
/// Least autocorrelation at the cycle's period for the cycle to count as seen.
pub const MIN_CYCLE_STRENGTH: f64 = 0.3;
pub use crate::run::answer::{CHECK_CONFUSED, CHECK_RECOGNISED};

impl SurfaceSettings {
    /// The defaults for `laws`: N = 2,000 particles, at most 8 populations, the sampler's
    /// defaults otherwise.
    pub fn new(laws: Vec<Law>) -> Self {
        let mut smc = SmcConfig::default();
        smc.schedule.particles = 2000;
        smc.schedule.eps_min = 0.0;
        smc.schedule.max_populations = DEFAULT_MAX_POPULATIONS;
        smc.schedule.min_acceptance = 0.01;
        smc.schedule.max_batch = 4096;
        Self {
            laws,
            prior_file: None,
            prior_scale: DEFAULT_PRIOR_SCALE,
            structure: Lumped::default(),
            string_bounds: None,
            w_ref_n: None,
            integration: Integration::default(),
            noise_sd_nm: None,
            pilot: DEFAULT_PILOT,
            check_replicates: DEFAULT_CHECK_REPLICATES,
            predictive_draws: DEFAULT_PREDICTIVE_DRAWS,
            smc,
            advice: true,
            backend: Backend::Auto,
            semi_automatic: false,
            curve_limits: true,
        }
    }

    /// Refuses settings that cannot run, naming the setting.
    pub fn validate(&self) -> Result<()> {
        self.smc.validate()?;
        if self.laws.is_empty() {
            return Err(Error::setting("laws", "no law to infer"));
        }
        for (field, n, least) in [
            ("pilot", self.pilot, 50),
            ("check_replicates", self.check_replicates, 2),
            ("predictive_draws", self.predictive_draws, 10),
        ] {
            if n < least {
                return Err(Error::setting(field, format!("must be at least {least}, got {n}")));
            }
        }
        if let Some(s) = self.noise_sd_nm
            && !(s.is_finite() && s >= 0.0)
        {
            return Err(Error::setting(
                "noise_sd_knm",
                format!("must be ≥ 0, got {}", s / 1000.0),
            ));
        }
        if let Some(w) = self.w_ref_n
            && !(w.is_finite() && w > 0.0)
        {
            return Err(Error::setting(
                "w_ref_kn",
                format!("must be positive, got {}", w / 1000.0),
            ));
        }
        if !(self.integration.dt_s.is_finite() && self.integration.dt_s > 0.0) {
            return Err(Error::setting(
                "dt_s",
                format!("must be positive, got {}", self.integration.dt_s),
            ));
        }
        if !(self.integration.settle_s.is_finite() && self.integration.settle_s >= 0.0) {
            return Err(Error::setting(
                "settle_s",
                format!("must be ≥ 0, got {}", self.integration.settle_s),
            ));
        }
        if let Some(bounds) = &self.string_bounds {
            for (field, [lo, hi]) in [
                ("omega_n_rad_s", bounds.omega_n_rad_s),
                ("damping_ratio", bounds.damping_ratio),
            ] {
                // A value given exactly is the string's own, checked with it below.
                if StringBounds::fixed([lo, hi]).is_none()
                    && !(lo.is_finite() && hi.is_finite() && lo > 0.0 && lo <= hi)
                {
                    return Err(Error::setting(
                        field,
                        format!(
                            "bounds must be positive, finite (as f32) and low to high, got {} to {}",
                            lo as f32, hi as f32
                        ),
                    ));
                }
            }
        }
        self.structure.validate()?;
        if let Some(bounds) = &self.string_bounds {
            // The step must resolve the stiffest string the bounds admit.
            for corner in bounds.corners(self.structure.inertia_kg_m2) {
                Chain::one_dof(&corner).check_step(self.integration.dt_s).map_err(|e| match e {
                    Error::InvalidSetting { field, message } => Error::setting(
                        field,
                        format!(
                            "{message}: the string at the bounds' corner ω_n {} rad/s, ξ {} (`omega_n_rad_s`, `damping_ratio`)",
                            corner.omega_n_rad_s as f32, corner.damping_ratio as f32
                        ),
                    ),
                    other => other,
                })?;
            }
        }
        Ok(())
    }
}
