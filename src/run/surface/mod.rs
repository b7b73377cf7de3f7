//! Laws inferred from a surface record (top-drive speed and surface torque) through simulated
//! strings: simulation-based ABC-SMC, the model choice checked by re-simulation, and what the
//! surface implies at the bit.
//!
//! 1. **The record's noise**: given, or read from the surface torque ([`Noise::of`]): an
//!    estimate on a clock fine enough for the cycle; on a coarser one, read on the wind-ups
//!    where they are long enough, else an upper bound.
//! 2. **The prior**: per law, boxes k scales wide from the physical bounds ([`Prior::physical`]),
//!    the scales from the record (the largest surface torque; speeds from the top drive's, the
//!    bit's peaks taken as three times it), replaced where a prior file gives bounds, a law
//!    whose file sets `prior_curve_within` cut to its curves within the record's torques
//!    ([`Prior::with_curve_limits`], the evidence's physical prior); where
//!    the string's natural frequency or damping ratio is given as bounds, every box carries
//!    both after the law's parameters ([`Prior::with_coordinates`]; one given exactly spans no
//!    width), each candidate's string built from them.
//! 3. **The pilot and the scout**: prior simulations give first scales of the distance (and
//!    semi-automatic ABC's training strings); a short ABC-SMC on them finds the strings near the record,
//!    whose spread scales the main run's distance (see `Scout`).
//! 4. **ABC-SMC** ([`crate::abc::smc`]) on ρ = the scaled distance of summaries (or, with
//!    `semi_automatic`, of the predictions of regressions fitted on the half of the pilot
//!    nearest the record: [`crate::eval::projection`]), every candidate a string simulated on
//!    the record's clock ([`SurfaceEvaluator`]).
//! 5. **The check**: records re-simulated from each law's posterior are classified by their
//!    nearest neighbours among as many records simulated from each law's posterior
//!    (the `check` module). Summaries that are not sufficient can make
//!    ABC model choice inconsistent (Robert, Cornuet, Marin & Pillai 2011); the law is called
//!    only where its own re-simulations are recognised and the others' are not taken for it.
//! 6. **At the bit**: posterior draws simulated on the record's clock give the bit speed's
//!    median and 90 % band per sample, the stuck share and severity, and, where the bit
//!    stick-slips, the simulated escape advice.

mod bit;
mod check;
pub mod dir;
mod pilot;
mod settings;
mod warm;

pub(crate) use bit::spread_way_out;
use bit::*;
pub use bit::{implied_bit, mean_wob_n, unidentified_caveat};
use check::*;
use pilot::*;
pub use settings::*;
pub use warm::LAW_DEFENSIVE_SHARE;
use warm::*;

use crate::abc::smc::{self, SmcConfig};
use crate::abc::{Observer, Particle, Population, Run, StopReason};
use crate::data::surface::SurfaceRecord;
use crate::error::{Error, Result};
use crate::eval::projection::{Projection, Training, least_strings};
use crate::eval::surface::{Distance, InferredString, NoiseKey, Summaries, SurfaceEvaluator, SurfaceModel, add_noise};
use crate::eval::{Backend, Objective};
use crate::laws::Law;
use crate::numerics::weighted_quantile;
use crate::prior::{Candidate, MAX_DIMS, PhysicalScales, Prior, PriorFile};
use crate::run::{Placement, Scoring};
use crate::simulate::strings::{Chain, Summary};
use crate::simulate::surface::{
    DownholeExtremes, Drive, Integration, MEAN, N_DOWNHOLE_SUMMARIES, N_SUMMARIES, OnClock, PERIOD, PERIOD_STRENGTH,
    SUMMARY_NAMES, least_scales, noise_sd, summaries, wind_up_noise_sd,
};
use crate::stability::lumped::Lumped;
use crate::stability::map::LawSamples;
use crate::units::RAD_S_PER_RPM;
use rayon::prelude::*;
use serde::Serialize;

/// What the record's surface torque shows of a stick-slip cycle.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Cycle {
    /// The cycle's period (s), where one is seen.
    pub period_s: Option<f64>,
    /// Cycles the record holds at that period.
    pub cycles: f64,
    /// Autocorrelation of the surface torque at the period.
    pub strength: f64,
}

impl Cycle {
    fn of(observed: &Summaries, duration_s: f64) -> Self {
        let period = observed[PERIOD];
        let strength = observed[PERIOD_STRENGTH];
        let period_s = (period > 0.0 && strength >= MIN_CYCLE_STRENGTH).then_some(period);
        Self {
            period_s,
            cycles: period_s.map_or(0.0, |p| duration_s / p),
            strength,
        }
    }

    /// True when the record's dynamics can inform the law: a cycle seen, at least
    /// [`MIN_CYCLES`] times.
    pub fn informs(&self) -> bool {
        self.period_s.is_some() && self.cycles >= MIN_CYCLES
    }

    /// Why the dynamics of a `span` (`record`, `window`) cannot inform the law, where they
    /// cannot: no cycle, or too few.
    pub fn uninformative(&self, span: &str) -> Option<String> {
        if self.informs() {
            return None;
        }
        Some(match self.period_s {
            None => format!(
                "no stick-slip cycle in the surface torque: the {span} informs the law only through T(Ω) at its speed, not its shape"
            ),
            Some(p) => format!(
                "the {span} holds {:.1} cycles of {p:.1} s, fewer than {MIN_CYCLES}: too few to tell the laws apart",
                self.cycles
            ),
        })
    }

    /// What `record`'s surface torque shows, before any string is simulated.
    pub fn of_record(record: &SurfaceRecord) -> Self {
        let observed = summaries(
            &record.surface_torque_nm,
            record.sample_period_s,
            &DownholeExtremes::record_summaries(record),
        );
        Self::of(&observed, record.duration_s())
    }
}

/// One law's posterior: probability and, per parameter, the weighted median and central 90 %.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct LawPosterior {
    pub law: Law,
    pub probability: f64,
    pub particles: usize,
    pub params: Vec<ParamPosterior>,
    /// Where the law's prior is its box cut to the curves within the record's torques (its
    /// file's `prior_curve_within`); `None`: the box alone.
    pub prior_curve: Option<PriorCurve>,
}

/// A law's prior cut to the curves within a torque ([`crate::prior::CurveLimit`]), SI.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PriorCurve {
    /// The limit in multiples of the record's largest surface torque.
    pub within: f64,
    /// The limit, N·m, held from rest to `speed_high_rad_s`.
    pub limit_nm: f64,
    pub speed_high_rad_s: f64,
    /// The share of the box the limit keeps (Monte Carlo).
    pub share: f64,
}

/// One parameter's posterior, SI (torques N·m).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ParamPosterior {
    pub name: String,
    pub q05: f64,
    pub median: f64,
    pub q95: f64,
    /// False when the central 90 % still spans 0.7 of the prior box or more
    /// ([`crate::abc::posterior::identified`]; for a box cut to a curve, 0.7 of the width of
    /// the uniform whose central 90 % is the cut prior's): the record has not narrowed the
    /// prior, which then sets the interval.
    pub identified: bool,
}

/// The string the candidates were simulated with, as the run found it.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct StringPosterior {
    /// True where ω_n or ξ was inferred with the laws (their posterior over every law's
    /// particles), false where the string was given whole.
    pub inferred: bool,
    /// I_eq, kg·m² (given).
    pub inertia_kg_m2: f64,
    /// ω_n, rad/s, and ξ.
    pub omega_n_rad_s: StringParam,
    pub damping_ratio: StringParam,
    /// The torsional stiffness k = I_eq·ω_n², kN·m/rad: 5 %, median, 95 %.
    pub stiffness_knm_per_rad: [f64; 3],
}

/// A string parameter: given (its value at every quantile), or its posterior.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct StringParam {
    pub given: bool,
    #[serde(flatten)]
    pub posterior: ParamPosterior,
}

impl StringPosterior {
    /// The string of `settings` as the final population `particles` has it.
    fn of(settings: &SurfaceSettings, particles: &[Particle]) -> Self {
        let s = &settings.structure;
        let given = |name: &str, value: f64| StringParam {
            given: true,
            posterior: ParamPosterior {
                name: name.to_string(),
                q05: value,
                median: value,
                q95: value,
                identified: true,
            },
        };
        let inferred = |name: &str, value: f64, coordinate: usize, [lo, hi]: [f64; 2]| {
            if lo.to_bits() == hi.to_bits() {
                return given(name, value);
            }
            let values: Vec<f64> = particles
                .iter()
                .map(|p| p.params[p.law.n_params() + coordinate])
                .collect();
            let weights: Vec<f64> = particles.iter().map(|p| p.weight).collect();
            let q = |level: f64| weighted_quantile(&values, &weights, level);
            StringParam {
                given: false,
                posterior: ParamPosterior {
                    name: name.to_string(),
                    q05: q(0.05),
                    median: q(0.5),
                    q95: q(0.95),
                    identified: crate::abc::posterior::identified(q(0.05), q(0.95), lo, hi, 0.9),
                },
            }
        };
        let (omega, xi) = match &settings.string_bounds {
            None => (
                given("omega_n_rad_s", s.omega_n_rad_s),
                given("damping_ratio", s.damping_ratio),
            ),
            Some(b) => (
                inferred("omega_n_rad_s", s.omega_n_rad_s, 0, b.omega_n_rad_s),
                inferred("damping_ratio", s.damping_ratio, 1, b.damping_ratio),
            ),
        };
        let k = |omega: f64| s.inertia_kg_m2 * omega * omega / 1000.0;
        let w = &omega.posterior;
        Self {
            inferred: settings.string_bounds.is_some_and(|b| b.infers()),
            inertia_kg_m2: s.inertia_kg_m2,
            stiffness_knm_per_rad: [k(w.q05), k(w.median), k(w.q95)],
            omega_n_rad_s: omega,
            damping_ratio: xi,
        }
    }

    /// The string at the posterior medians.
    pub fn median(&self) -> Lumped {
        Lumped {
            inertia_kg_m2: self.inertia_kg_m2,
            omega_n_rad_s: self.omega_n_rad_s.posterior.median,
            damping_ratio: self.damping_ratio.posterior.median,
        }
    }
}

/// How the re-simulated records of one law were classified.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct CheckRow {
    /// The law the records were simulated from (its posterior).
    pub law: Law,
    pub replicates: usize,
    /// Per law of the prior (in its order), how many of them were classified as it.
    pub classified_as: Vec<(Law, usize)>,
    /// The share classified as `law` itself.
    pub recognised: f64,
}

/// The model choice's check and its verdict.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ModelCheck {
    /// Reference records (simulated from the laws' posteriors, those that did not diverge,
    /// and a lost law's pilot strings nearest the record), and the neighbours each
    /// classification takes at most.
    pub reference: usize,
    pub neighbours: usize,
    pub rows: Vec<CheckRow>,
    /// The law called, where the record and the check allow one.
    pub decided: Option<Law>,
    /// Why, in words.
    pub verdict: String,
}

/// What the surface implies at the bit.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct AtTheBit {
    pub draws: usize,
    /// Per sample of the record: the bit speed's 5 %, median and 95 % (rpm).
    pub speed_rpm: Vec<[f64; 3]>,
    /// The stuck share's 5 %, median and 95 % over the draws.
    pub stuck_share: [f64; 3],
    /// The severity's 5 %, median and 95 % over the draws.
    pub severity: [f64; 3],
    /// P(the bit stick-slips) over the draws.
    pub stick_slip_probability: f64,
    /// Per law drawn: its draws and their stuck share's 5 %, median and 95 % (laws that
    /// hold the bit and laws that only slow it agree at the surface and not at the bit).
    pub stuck_share_by_law: Vec<(Law, usize, [f64; 3])>,
    /// Draws whose string left physical bounds (not counted above).
    pub diverged: usize,
    /// What ends the stick-slip, by simulated strings (where the bit stick-slips).
    pub advice: Option<String>,
    /// Where the record leaves some of the laws' parameters to their prior boxes: the way out
    /// of strings along the posterior's spread of those parameters, tails included, which ends
    /// the stick-slip whichever of them is the bit's.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub spread_advice: Option<SpreadAdvice>,
}

pub use crate::run::advice::SpreadAdvice;

/// Everything a surface inference finds.
#[derive(Clone, Debug, Serialize)]
pub struct SurfaceResult {
    pub roles: String,
    /// Where the strings were simulated: `CPU` or `GPU <adapter>`.
    pub backend: String,
    pub noise: Noise,
    pub summary_names: Vec<&'static str>,
    pub observed: Vec<f64>,
    pub scales: Vec<f64>,
    /// What the distance compared: `scaled summaries`, or `semi-automatic` predictions.
    pub distance: &'static str,
    /// Semi-automatic ABC's predictions, each with the adjusted R² of its regression on the
    /// training strings: a parameter the summaries do not predict is one the record does not
    /// inform through them.
    pub projection: Option<Projection>,
    pub cycle: Cycle,
    /// T(Ω) the mean surface torque states (N·m at r = 1) and the speed (rpm).
    pub mean_torque_nm: f64,
    pub mean_top_drive_rpm: f64,
    pub laws: Vec<LawPosterior>,
    /// The string the candidates were simulated with: given, or inferred with the laws.
    pub string: StringPosterior,
    pub check: ModelCheck,
    pub at_the_bit: AtTheBit,
    pub populations: usize,
    /// ε of each population (`None` for ∞) and the strings it simulated.
    pub epsilons: Vec<Option<f64>>,
    pub strings_per_population: Vec<u64>,
    pub final_epsilon: Option<f64>,
    pub stop: String,
    /// Strings simulated in all (pilot, scout, sampler, check, predictive).
    pub simulations: u64,
    pub cost: Cost,
    /// ρ between two noise draws on one string near the record: the least a tolerance can
    /// usefully reach, since the record itself is one such draw.
    pub noise_floor: f64,
    /// What the user should know about the result (a sampler stopped far above the floor).
    pub warnings: Vec<String>,
    pub seconds: f64,
    #[serde(skip)]
    pub run: Option<Run>,
}

/// Samples per cycle from which the noise estimate reads noise, not signal.
pub const FINE_CLOCK_SAMPLES_PER_CYCLE: f64 = 20.0;

/// The surface torque's noise the simulations get, and how it was found.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Noise {
    /// Standard deviation (N·m).
    pub sd_nm: f64,
    /// `given`, `estimated` (from a clock fine enough for the cycle), `wind_up` (a coarse
    /// clock, read on the string's wind-ups) or `bounded` (a coarse clock without wind-ups
    /// enough, where the estimate also holds part of the signal: an upper bound).
    pub how: &'static str,
}

impl Noise {
    /// The noise given, or read from the record by [`noise_sd`]: an estimate where the clock
    /// gives the cycle [`FINE_CLOCK_SAMPLES_PER_CYCLE`] samples or more (or shows none). On a
    /// coarser clock that holds part of the signal, and the noise is read on the wind-ups
    /// ([`wind_up_noise_sd`]) where they give less; else it stays an upper bound. More noise
    /// in the simulations than in the record widens the posterior, and moves the summaries
    /// that noise moves (the quantiles' spread, the wind-up rate), so the bound is the last
    /// resort.
    pub fn of(given: Option<f64>, torque_nm: &[f64], cycle: &Cycle, period_s: f64) -> Self {
        if let Some(sd_nm) = given {
            return Self { sd_nm, how: "given" };
        }
        let sd_nm = noise_sd(torque_nm);
        let fine = cycle
            .period_s
            .is_none_or(|p| p / period_s >= FINE_CLOCK_SAMPLES_PER_CYCLE);
        if fine {
            return Self {
                sd_nm,
                how: "estimated",
            };
        }
        match wind_up_noise_sd(torque_nm) {
            Some(wind_up) if wind_up < sd_nm => Self {
                sd_nm: wind_up,
                how: "wind_up",
            },
            _ => Self { sd_nm, how: "bounded" },
        }
    }
}

/// What the final population cost, against rejection ABC on the same distance.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Cost {
    /// Strings the sampler simulated per particle of its final population.
    pub strings_per_particle: f64,
    /// Prior strings per particle that rejection ABC would simulate to the same ε: one over
    /// the share of the pilot below it. `None` where no pilot string is (more than the pilot).
    pub rejection_strings_per_particle: Option<f64>,
    /// Pilot strings below the final ε, of the pilot's.
    pub pilot_below: usize,
    pub pilot: usize,
}

impl Cost {
    fn of(
        sampler_strings: u64,
        last: &crate::abc::Population,
        table: &[(usize, Summaries)],
        distance: &Distance,
    ) -> Self {
        let epsilon = last.record.epsilon.unwrap_or(f64::INFINITY);
        let below = table.iter().filter(|t| distance.rho(&t.1) < epsilon).count();
        Self {
            strings_per_particle: sampler_strings as f64 / last.particles.len().max(1) as f64,
            rejection_strings_per_particle: (below > 0).then(|| table.len() as f64 / below as f64),
            pilot_below: below,
            pilot: table.len(),
        }
    }
}

impl SurfaceResult {
    /// The bit as this result implies it on `record` ([`implied_bit`]).
    pub fn bit_seen(&self, record: &SurfaceRecord) -> crate::data::BitSeen {
        implied_bit(record, self.at_the_bit.stuck_share[1], self.at_the_bit.severity[1])
    }

    /// The bit's predicted speed per sample of `record` (time_s, bit_speed_rpm_p05, _p50,
    /// _p95) as CSV.
    pub fn bit_csv(&self, record: &SurfaceRecord, out: &mut dyn std::io::Write) -> std::io::Result<()> {
        let mut writer = csv::Writer::from_writer(out);
        writer.write_record(["time_s", "bit_speed_rpm_p05", "bit_speed_rpm_p50", "bit_speed_rpm_p95"])?;
        for (t, q) in record.time_s.iter().zip(&self.at_the_bit.speed_rpm) {
            writer.write_record([t, &q[0], &q[1], &q[2]].map(|v| format!("{v:.4}")))?;
        }
        writer.flush()
    }

    /// The final population's particles as CSV in the layout `bitrock stability --posterior`
    /// reads (each law's share of the weight is its probability; torques in `unit`), with the
    /// string's natural frequency and damping ratio after the laws' parameters where the run
    /// inferred them. `None` for a result without its run.
    pub fn posterior_csv(&self, laws: &[Law], unit: crate::units::TorqueUnit) -> Option<Vec<u8>> {
        let last = self.run.as_ref()?.populations.last()?;
        let string: &[(&str, usize)] = if self.string.inferred {
            &[("string.omega_n [rad/s]", 0), ("string.damping_ratio [1]", 1)]
        } else {
            &[]
        };
        Some(crate::documents::particle_groups_csv_with(
            &[(last.record.index, &last.particles)],
            laws,
            unit,
            string,
        ))
    }
}

/// The model a record drives: its string, its clock and its noise.
fn model(record: &SurfaceRecord, settings: &SurfaceSettings, noise_sd_nm: f64) -> SurfaceModel {
    SurfaceModel {
        chain: Chain::one_dof(&settings.structure),
        string: settings.string_bounds.map(|b| InferredString {
            inertia_kg_m2: settings.structure.inertia_kg_m2,
            omega_n_rad_s: StringBounds::fixed(b.omega_n_rad_s),
            damping_ratio: StringBounds::fixed(b.damping_ratio),
        }),
        drive: Drive {
            omega_rad_s: record.top_drive_rad_s.clone(),
            ratio: record.wob_ratio(settings.w_ref_n),
            period_s: record.sample_period_s,
        },
        integration: settings.integration,
        noise_sd_nm,
        downhole: DownholeExtremes::of(record),
        backend: settings.backend,
    }
}

/// The `(law, coordinates)` of each particle, for [`SurfaceModel::simulate_noiseless_many`].
fn strings_of<'p>(particles: &[&'p Particle]) -> Vec<(Law, &'p [f64])> {
    particles.iter().map(|p| (p.law, p.params.as_slice())).collect()
}

/// The prior's scales from a surface record: its largest torque, and speeds from the top
/// drive's (a stick-slipping bit peaks at two to three times it).
pub fn physical_scales(record: &SurfaceRecord) -> PhysicalScales {
    let torque_max = record.surface_torque_nm.iter().fold(0.0f64, |m, y| m.max(y.abs()));
    let omega_max = record.top_drive_rad_s.iter().fold(0.0f64, |m, w| m.max(w.abs()));
    let omega_mean = record.mean_top_drive_rad_s().abs();
    PhysicalScales {
        torque_max: torque_max.max(f64::MIN_POSITIVE),
        speed_low: (0.1 * omega_mean).max(1e-3),
        speed_high: (3.0 * omega_max).max(1e-3),
    }
}

/// Seed offset of the pilot's candidates, apart from the sampler's streams.
const PILOT_STREAM: u64 = 0x5049_4c4f_5400_0000;

/// Infers the laws from `record` (see the module documentation); `note` hears what the user
/// should know as it happens.
pub fn infer(
    record: &SurfaceRecord,
    settings: &SurfaceSettings,
    seed: u64,
    note: &mut dyn FnMut(String),
) -> Result<SurfaceResult> {
    let mut keep = |_: &[Population]| Ok(());
    let sampling = Sampling {
        previous: Vec::new(),
        stopped: None,
        keep: &mut keep,
        warm: &[],
        scoring: Scoring::Here,
    };
    infer_continuing(record, settings, seed, sampling, note)
}

/// Where a surface run's sampler starts and what it hands on: what a surface directory
/// ([`dir`]) stores and continues.
pub struct Sampling<'a, 'w> {
    /// The populations completed before (empty: the sampler starts from the prior). The run
    /// continued after them gives exactly the populations an uninterrupted one gives.
    pub previous: Vec<Population>,
    /// Where the run has ended already (`previous` not empty): the sampler does not run, and
    /// the stored populations are the run's, ended for this reason (a check made again).
    pub stopped: Option<StopReason>,
    /// Hears every population as it completes, with all before it.
    pub keep: &'a mut dyn FnMut(&[Population]) -> Result<()>,
    /// An earlier posterior (a watch's window before) to start from where `previous` is empty:
    /// population 0 drawn near it and weighted back to the prior (see `warm`); empty: from the
    /// prior.
    pub warm: &'a [Particle],
    /// Where the sampler's strings are simulated: here, or by workers elsewhere (the
    /// populations are the same).
    pub scoring: Scoring<'a, 'w>,
}

/// The sampler's observer that hands every completed population to [`Sampling::keep`].
struct Keeping<'a> {
    populations: Vec<Population>,
    keep: &'a mut dyn FnMut(&[Population]) -> Result<()>,
    note: &'a mut dyn FnMut(String),
}

impl Observer for Keeping<'_> {
    fn population_done(&mut self, population: &Population, _previous: Option<&Population>) -> Result<()> {
        self.populations.push(population.clone());
        (self.keep)(&self.populations)
    }

    fn note(&mut self, line: String) {
        (self.note)(line)
    }
}

/// [`infer`], its sampler continuing after `sampling`'s populations and handing on each new
/// one.
pub fn infer_continuing(
    record: &SurfaceRecord,
    settings: &SurfaceSettings,
    seed: u64,
    sampling: Sampling,
    note: &mut dyn FnMut(String),
) -> Result<SurfaceResult> {
    settings.validate()?;
    let started = std::time::Instant::now();
    Chain::one_dof(&settings.structure).check_step(settings.integration.dt_s)?;
    let observed = summaries(
        &record.surface_torque_nm,
        record.sample_period_s,
        &DownholeExtremes::record_summaries(record),
    );
    let cycle = Cycle::of(&observed, record.duration_s());
    let mut prior = Prior::physical(
        &settings.laws,
        &physical_scales(record),
        settings.prior_scale,
        settings.prior_file.as_ref(),
        record.torque_unit.newton_metres(),
    )?;
    if settings.curve_limits {
        prior = prior.with_curve_limits(&physical_scales(record))?;
    }
    if let Some(b) = &settings.string_bounds {
        let [omega, xi] = [b.omega_n_rad_s, b.damping_ratio];
        prior = prior.with_coordinates(&[omega[0] as f32, xi[0] as f32], &[omega[1] as f32, xi[1] as f32]);
    }
    let (backend, ran) = crate::eval::strings::resolve(settings.backend, note)?;
    let mut model = model(record, settings, 0.0);
    model.backend = backend;
    let mut simulations = settings.pilot as u64;
    let pilot = Pilot::simulate(&model, &prior, seed ^ PILOT_STREAM, settings.pilot)?;
    let period_s = model.drive.period_s;
    let noise = Noise::of(settings.noise_sd_nm, &record.surface_torque_nm, &cycle, period_s);
    let noise_sd_nm = noise.sd_nm;
    model.noise_sd_nm = noise_sd_nm;
    let (table, pilot_distance) = pilot.distance(noise_sd_nm, period_s, &observed, model.active());
    let scout = Scout::run(&model, &prior, settings, seed, &pilot_distance)?;
    simulations += scout.simulations;
    let mut distance = scout.distance(&pilot_distance, noise_sd_nm, period_s);
    let mut warnings = Vec::new();
    if settings.semi_automatic {
        distance.projection = pilot.projection(&prior, &table, &distance);
        let least = least_strings(&distance.active);
        match &distance.projection {
            None => warnings.push(format!(
                "semi-automatic summaries: no regression could be fitted on the {} pilot strings nearest the record (a law's coordinates need {least} of its own); the scaled summaries were compared: raise `pilot`",
                training_size(table.len()),
            )),
            Some(p) if !p.unregressed.is_empty() => {
                let laws: Vec<String> = p.unregressed.iter().map(|l| l.to_string()).collect();
                warnings.push(format!(
                    "semi-automatic summaries: {} had fewer than {least} of the {} pilot strings nearest the record, too few to regress {} parameters on; they are compared only through the other predictions: raise `pilot`",
                    laws.join(", "),
                    p.training,
                    if laws.len() == 1 { "its" } else { "their" }
                ));
            }
            Some(_) => {}
        }
    }
    let noise_floor = scout.noise_floor(&distance, noise_sd_nm, period_s);

    let evaluator = SurfaceEvaluator::new(prior.clone(), seed, model.clone(), distance.clone());
    let mut sampling = sampling;
    if sampling.previous.is_empty()
        && !sampling.warm.is_empty()
        && can_warm_start(&prior)
        && let Some(start) = warm_population(&evaluator, sampling.warm, settings.smc.schedule.particles, seed)?
    {
        (sampling.keep)(std::slice::from_ref(&start))?;
        sampling.previous = vec![start];
    }
    let run = match sampling.stopped {
        Some(stop) if !sampling.previous.is_empty() => Run {
            populations: sampling.previous,
            stop,
            evaluations: 0,
            seconds: 0.0,
        },
        _ => {
            let mut keeping = Keeping {
                populations: sampling.previous.clone(),
                keep: sampling.keep,
                note,
            };
            // Workers simulate on the backend resolved here, as the rest of the run does: a
            // run's strings on one backend, its result saying which.
            let placement = Placement {
                backend,
                ..Placement::default()
            };
            let objective = Objective::Surface(Box::new(evaluator));
            let workers = sampling.scoring.workers(objective, &placement, keeping.note)?;
            let run = smc::run_on(&*workers, &settings.smc, sampling.previous, &mut keeping)?;
            let here = if backend == Backend::Gpu { "gpu" } else { "cpu" };
            if workers.backend() != here {
                warnings.push(format!(
                    "the sampler's strings were simulated on {} by its workers (a worker's BITROCK_WORKER_BACKEND), the rest of the run on {}: its populations are not those of one process",
                    workers.backend(),
                    ran
                ));
            }
            run
        }
    };
    let sampler_strings: u64 = run.populations.iter().map(|p| p.record.candidates_scored).sum();
    simulations += sampler_strings;
    let last = run.populations.last().expect("a run has a population");
    let cost = Cost::of(sampler_strings, last, &table, &distance);
    let particles = &last.particles;
    let laws = posteriors(&prior, particles);
    let string = StringPosterior::of(settings, particles);

    let (check, simulated_reference) = check(
        &prior,
        &model,
        &distance,
        &table,
        &laws,
        particles,
        settings.check_replicates,
        seed,
        &cycle,
        unconverged(last.record.epsilon, noise_floor),
    )?;
    simulations += simulated_reference + check.rows.iter().map(|r| r.replicates as u64).sum::<u64>();
    let mut at_the_bit = at_the_bit(&model, particles, settings.predictive_draws, seed)?;
    simulations += at_the_bit.draws as u64;
    if settings.advice && at_the_bit.stick_slip_probability >= 0.5 {
        let chain = Chain::one_dof(&string.median());
        let (advice, open) = escape_advice(record, settings, backend, &chain, model.string, &laws, particles, note)?;
        at_the_bit.advice = Some(advice);
        at_the_bit.spread_advice = open;
    }
    let ratio_mean = model.drive.ratio.iter().sum::<f64>() / model.drive.ratio.len() as f64;
    Ok(SurfaceResult {
        roles: record.roles_text(),
        backend: ran.to_string(),
        noise,
        summary_names: compared(&SUMMARY_NAMES, &distance.active),
        observed: compared(&observed, &distance.active),
        scales: compared(&distance.scales, &distance.active),
        cycle,
        mean_torque_nm: observed[MEAN] / ratio_mean,
        mean_top_drive_rpm: record.mean_top_drive_rad_s() / RAD_S_PER_RPM,
        laws,
        string,
        check,
        at_the_bit,
        populations: run.populations.len(),
        epsilons: run.populations.iter().map(|p| p.record.epsilon).collect(),
        strings_per_population: run.populations.iter().map(|p| p.record.candidates_scored).collect(),
        final_epsilon: last.record.epsilon,
        stop: run.stop.describe().to_string(),
        simulations,
        cost,
        noise_floor,
        distance: if distance.projection.is_some() {
            "semi-automatic"
        } else {
            "scaled summaries"
        },
        projection: distance.projection.clone(),
        warnings: warnings
            .into_iter()
            .chain(convergence_warning(
                last.record.epsilon,
                noise_floor,
                !settings.string_bounds.is_some_and(|b| b.infers()),
            ))
            .chain(damping_warning(settings.string_bounds.as_ref()))
            .collect(),
        seconds: started.elapsed().as_secs_f64(),
        run: Some(run),
    })
}

/// A final tolerance this many times the noise floor or more: the posterior is still wider
/// than the record allows.
pub const UNCONVERGED_FACTOR: f64 = 4.0;

/// The warning of a run that infers the string's damping ratio: the surface's cycle tells it
/// weakly (docs/surface.md: on simulated records a well-damped string was taken for a less
/// damped one with a higher dynamic torque, at 1 Hz and at 20 Hz, converged or not).
fn damping_warning(bounds: Option<&StringBounds>) -> Option<String> {
    bounds
        .filter(|b| StringBounds::fixed(b.damping_ratio).is_none())
        .map(|_| {
            "the string's damping ratio is inferred, and the surface's cycle tells it weakly: a well-damped string can be taken for a less damped one with a higher dynamic torque, overstating the bit's stuck share; bound it as tightly as it is known (`damping_ratio`)".to_string()
        })
}

/// How many times the noise floor the sampler's final tolerance `epsilon` lies, where that is
/// [`UNCONVERGED_FACTOR`] or more: its strings do not yet reproduce the record.
fn unconverged(epsilon: Option<f64>, floor: f64) -> Option<f64> {
    let epsilon = epsilon.unwrap_or(f64::INFINITY);
    (floor > 0.0 && epsilon >= UNCONVERGED_FACTOR * floor).then_some(epsilon / floor)
}

/// The warning of a sampler that stopped at `epsilon` far above the noise floor; where the
/// string was given whole, a wrong string is the other cause named.
fn convergence_warning(epsilon: Option<f64>, floor: f64, string_given: bool) -> Option<String> {
    unconverged(epsilon, floor).map(|times| {
        format!(
            "the sampler stopped at ε = {:.3}, {times:.1} times the noise's own distance {floor:.3}: the strings do not yet reproduce the record, and the posterior and the bit's figures are wider or further off than the record allows; raise `max_populations` or `particles`{}",
            epsilon.unwrap_or(f64::INFINITY),
            if string_given {
                ", or, where the string's natural frequency or damping is not known, infer it by giving bounds for it (`omega_n_rad_s`, `damping_ratio`)"
            } else {
                ""
            }
        )
    })
}

/// Each law's probability and parameter quantiles in the final population.
fn posteriors(prior: &Prior, particles: &[Particle]) -> Vec<LawPosterior> {
    prior
        .laws()
        .map(|law| {
            let own: Vec<&Particle> = particles.iter().filter(|p| p.law == law).collect();
            let weights: Vec<f64> = own.iter().map(|p| p.weight).collect();
            let bx = &prior.boxes[prior.slot_of(law)];
            // What the prior alone spans per parameter: the box, or for a box cut to a curve
            // the width of the uniform whose central 90 % is the cut prior's.
            let lower: Vec<f64> = bx.lower.iter().map(|&v| f64::from(v)).collect();
            let upper: Vec<f64> = bx.upper.iter().map(|&v| f64::from(v)).collect();
            let spans: Vec<f64> = match &bx.curve {
                Some(c) if !own.is_empty() => c
                    .central_intervals(law, &lower, &upper, 0.9)
                    .iter()
                    .map(|(lo, hi)| (hi - lo) / 0.9)
                    .collect(),
                _ => lower.iter().zip(&upper).map(|(lo, hi)| hi - lo).collect(),
            };
            let params = law
                .params()
                .iter()
                .enumerate()
                .filter(|_| !own.is_empty())
                .map(|(j, spec)| {
                    let values: Vec<f64> = own.iter().map(|p| p.params[j]).collect();
                    let q = |p: f64| weighted_quantile(&values, &weights, p);
                    ParamPosterior {
                        name: spec.name.to_string(),
                        q05: q(0.05),
                        median: q(0.5),
                        q95: q(0.95),
                        identified: crate::abc::posterior::identified(q(0.05), q(0.95), 0.0, spans[j], 0.9),
                    }
                })
                .collect();
            LawPosterior {
                law,
                // Σ of no weights is −0 under IEEE addition order; a law without particles has 0.
                probability: weights.iter().sum::<f64>() + 0.0,
                particles: own.len(),
                params,
                prior_curve: bx.curve.as_ref().map(|c| PriorCurve {
                    within: c.within,
                    limit_nm: c.limit_nm,
                    speed_high_rad_s: c.speeds_rad_s.last().copied().unwrap_or(0.0),
                    share: c.ln_share.exp(),
                }),
            }
        })
        .collect()
}

/// `count` particles drawn by weight (systematic resampling at a seeded offset), in order.
fn resample<'a>(particles: &[&'a Particle], count: usize, seed: u64) -> Vec<&'a Particle> {
    let total: f64 = particles.iter().map(|p| p.weight).sum();
    if particles.is_empty() || total <= 0.0 {
        return Vec::new();
    }
    let offset =
        crate::rng::open_unit(crate::rng::philox4x32_10([0, 0, 0, 0x5245_5341], crate::rng::key_of_seed(seed))[0]);
    let mut out = Vec::with_capacity(count);
    let mut cumulative = 0.0;
    let mut i = 0;
    for k in 0..count {
        let target = (k as f64 + offset) / count as f64 * total;
        while i + 1 < particles.len() && cumulative + particles[i].weight < target {
            cumulative += particles[i].weight;
            i += 1;
        }
        out.push(particles[i]);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// m4 nearly a constant c0 in [0, 4] (c1..c3 within a hundredth) cut to |T| ≤ 1 over
    /// speeds 0..1: the cut prior holds c0 within about [0, 1]. Particles over all of that
    /// leave c0 to the prior (against the box they would seem to narrow it); particles over
    /// a fifth of it narrow it.
    #[test]
    fn a_cut_law_s_parameters_are_judged_against_what_the_cut_prior_spans() {
        let mut bx = crate::prior::LawBox::new(Law::M4, vec![0.0; 4], vec![4.0, 0.01, 0.01, 0.01]);
        bx.curve = Some(crate::prior::CurveLimit::new(Law::M4, 1.0, 1.0, 1.0, (&bx.lower, &bx.upper)).unwrap());
        let prior = Prior::new(vec![bx], vec![1.0]).unwrap();
        let particles = |from: f64, to: f64| -> Vec<Particle> {
            (0..101)
                .map(|i| Particle {
                    law: Law::M4,
                    index: i,
                    params: vec![from + (to - from) * i as f64 / 100.0, 0.005, 0.005, 0.005],
                    rho: 0.0,
                    weight: 1.0 / 101.0,
                })
                .collect()
        };
        let c0_identified = |ps: &[Particle]| posteriors(&prior, ps)[0].params[0].identified;
        assert!(!c0_identified(&particles(0.0, 0.97)));
        assert!(c0_identified(&particles(0.4, 0.6)));
        // The cut prior's central 90 % is about [0.05, 0.94]: the span is that over 0.9, 0.99,
        // and a posterior 90 % narrower than 0.7 of it (0.69) is narrowed: 0.66 is (against
        // 0.89 itself the bound would be 0.62, and it would not be).
        assert!(c0_identified(&particles(0.0, 0.73)));
    }

    #[test]
    fn a_string_value_is_a_number_or_bounds_lo_hi_in_text_and_in_json() {
        assert_eq!("0.85".parse(), Ok(ValueOrBounds::Value(0.85)));
        assert_eq!(" 0.5 : 1.5".parse(), Ok(ValueOrBounds::Bounds([0.5, 1.5])));
        for bad in ["", "x", "0.5:", "0.5:nan", "0.5:1:2", "inf"] {
            let error = bad.parse::<ValueOrBounds>().unwrap_err();
            assert!(error.contains("not a finite number"), "{bad}: {error}");
        }
        let parsed: Vec<ValueOrBounds> = serde_json::from_str("[0.85, [0.5, 1.5]]").unwrap();
        assert_eq!(parsed, [ValueOrBounds::Value(0.85), ValueOrBounds::Bounds([0.5, 1.5])]);
    }

    #[test]
    fn string_bounds_infer_what_they_bound_and_hold_a_given_value() {
        let settings = Settings {
            omega_n_rad_s: Some(ValueOrBounds::Bounds([0.6, 1.8])),
            damping_ratio: Some(ValueOrBounds::Value(0.1)),
            ..Settings::default()
        };
        let run = settings.config(vec![Law::M2]).unwrap();
        let bounds = run.string_bounds.unwrap();
        // Bounds as the f32 the candidates are drawn in; a value as given.
        let (lo, hi) = (f64::from(0.6f32), f64::from(1.8f32));
        assert_eq!((bounds.omega_n_rad_s, bounds.damping_ratio), ([lo, hi], [0.1, 0.1]));
        assert_eq!(run.structure.omega_n_rad_s.to_bits(), (lo + 0.5 * (hi - lo)).to_bits());
        assert_eq!(run.structure.damping_ratio.to_bits(), 0.1f64.to_bits());
        assert_eq!(StringBounds::fixed(bounds.omega_n_rad_s), None);
        assert_eq!(StringBounds::fixed(bounds.damping_ratio), Some(0.1));
        assert!(bounds.infers());
        // Given whole, nothing is inferred; bounds of no width infer nothing either.
        let run = Settings::default().config(vec![Law::M2]).unwrap();
        assert_eq!(run.string_bounds, None);
        let settings = Settings {
            omega_n_rad_s: Some(ValueOrBounds::Bounds([1.0, 1.0])),
            ..Settings::default()
        };
        assert!(!settings.config(vec![Law::M2]).unwrap().string_bounds.unwrap().infers());
        for (omega, xi, field) in [
            ([1.8, 0.6], [0.1, 0.2], "omega_n_rad_s"),
            ([-1.0, 0.5], [0.1, 0.2], "omega_n_rad_s"),
            ([0.6, 1.8], [0.0, 0.2], "damping_ratio"),
            // Positive in f64, 0 in f32.
            ([0.6, 1.8], [1e-46, 0.2], "damping_ratio"),
            ([0.6, 1.8], [0.1, f64::INFINITY], "damping_ratio"),
            ([1e308, 1.7e308], [0.1, 0.2], "omega_n_rad_s"),
        ] {
            let settings = Settings {
                omega_n_rad_s: Some(ValueOrBounds::Bounds(omega)),
                damping_ratio: Some(ValueOrBounds::Bounds(xi)),
                ..Settings::default()
            };
            let error = settings.config(vec![Law::M2]).unwrap_err().to_string();
            assert!(error.contains(field), "{omega:?} {xi:?}: {error}");
        }
    }

    #[test]
    fn the_spread_within_laws_is_each_law_s_own_pooled() {
        // Summary 0 tells the laws apart (0 for m2, 10 + a little for m1) and varies little
        // within each; summary 1 varies alike in both. Within the laws summary 0's spread is
        // m1's small one, not the gap between the laws; summary 1's is unchanged.
        let summaries = |a: f64, b: f64| {
            let mut s = [0.0; N_SUMMARIES];
            s[0] = a;
            s[1] = b;
            s
        };
        let set: Vec<(Law, Summaries)> = (0..5)
            .map(|k| (Law::M2, summaries(0.0, k as f64)))
            .chain((0..5).map(|k| (Law::M1, summaries(10.0 + 0.1 * k as f64, k as f64))))
            .collect();
        let pooled = crate::eval::surface::scales_over(set.iter().map(|(_, s)| s), &[1.0; N_SUMMARIES]);
        let within = crate::eval::surface::scales_over(within_laws(&set).iter(), &[1.0; N_SUMMARIES]);
        assert!(pooled[0] > 5.0, "{}", pooled[0]);
        assert!(within[0] < 0.2, "{}", within[0]);
        assert_eq!(within[1].to_bits(), pooled[1].to_bits());
        // One law: its own spread, to rounding.
        let one: Vec<(Law, Summaries)> = set.iter().filter(|(l, _)| *l == Law::M1).copied().collect();
        let own = crate::eval::surface::scales_over(one.iter().map(|(_, s)| s), &[1.0; N_SUMMARIES]);
        let within_one = crate::eval::surface::scales_over(within_laws(&one).iter(), &[1.0; N_SUMMARIES]);
        for j in 0..N_SUMMARIES {
            assert!(
                (own[j] - within_one[j]).abs() <= 1e-12 * own[j].abs(),
                "{j}: {} {}",
                own[j],
                within_one[j]
            );
        }
    }

    fn posterior(law: Law, probability: f64) -> LawPosterior {
        LawPosterior {
            law,
            probability,
            particles: 1,
            params: Vec::new(),
            prior_curve: None,
        }
    }

    fn row(law: Law, as_m1: usize, as_m2: usize) -> CheckRow {
        let n = as_m1 + as_m2;
        CheckRow {
            law,
            replicates: n,
            classified_as: vec![(Law::M1, as_m1), (Law::M2, as_m2)],
            recognised: if law == Law::M1 { as_m1 } else { as_m2 } as f64 / n as f64,
        }
    }

    const CYCLING: Cycle = Cycle {
        period_s: Some(9.75),
        cycles: 60.0,
        strength: 0.9,
    };

    #[test]
    fn an_improbable_law_taken_for_the_leader_leaves_the_choice_undecided() {
        // m1 holds 0.97 and its own records are all recognised, but m2's are all taken for m1:
        // the probabilities cannot excuse m2 from the check.
        let laws = [posterior(Law::M1, 0.97), posterior(Law::M2, 0.03)];
        let (decided, text) = verdict(&laws, &[row(Law::M1, 10, 0), row(Law::M2, 10, 0)], &CYCLING, None);
        assert_eq!(decided, None, "{text}");
        assert!(text.contains("undecided between m1 and m2"), "{text}");
        // With m2's records recognised as m2 (two of ten taken for m1), m1 is called.
        let (decided, text) = verdict(&laws, &[row(Law::M1, 10, 0), row(Law::M2, 2, 8)], &CYCLING, None);
        assert_eq!(decided, Some(Law::M1), "{text}");
        // A leader whose own records are recognised seven times in ten is not called.
        let (decided, _) = verdict(&laws, &[row(Law::M1, 7, 3), row(Law::M2, 0, 10)], &CYCLING, None);
        assert_eq!(decided, None);
    }

    #[test]
    fn a_sampler_whose_strings_do_not_reproduce_the_record_calls_no_law() {
        // m1's records recognised, m2's never taken for it: called where the sampler reached
        // the record, not where it stopped at four noise floors or more (UNCONVERGED_FACTOR).
        let laws = [posterior(Law::M1, 0.97), posterior(Law::M2, 0.03)];
        let rows = [row(Law::M1, 10, 0), row(Law::M2, 0, 10)];
        let converged = unconverged(Some(0.39), 0.1);
        assert_eq!(converged, None);
        assert_eq!(verdict(&laws, &rows, &CYCLING, converged).0, Some(Law::M1));
        let far = unconverged(Some(0.58), 0.1);
        assert!(far.is_some_and(|t| (t - 5.8).abs() < 1e-12), "{far:?}");
        let (decided, text) = verdict(&laws, &rows, &CYCLING, far);
        assert_eq!(decided, None, "{text}");
        assert!(
            text.starts_with("m1 leads (P = 0.97), but the sampler stopped at 5.8 times the noise's own distance")
                && text.contains("no law is called"),
            "{text}"
        );
        // A sampler that never got a finite tolerance has reproduced nothing.
        assert_eq!(unconverged(None, 0.1), Some(f64::INFINITY));
    }

    #[test]
    fn a_call_names_the_laws_the_sampler_lost() {
        let lost = LawPosterior {
            particles: 0,
            ..posterior(Law::M2, 0.0)
        };
        let laws = [posterior(Law::M1, 1.0), lost];
        let (decided, text) = verdict(&laws, &[row(Law::M1, 10, 0)], &CYCLING, None);
        assert_eq!(decided, Some(Law::M1), "{text}");
        assert!(
            text.ends_with("and no other law's are taken for it; m2 left the populations and could not be tested"),
            "{text}"
        );
    }

    #[test]
    fn a_record_without_enough_cycles_calls_no_law() {
        let laws = [posterior(Law::M1, 0.97), posterior(Law::M2, 0.03)];
        let rows = [row(Law::M1, 10, 0), row(Law::M2, 0, 10)];
        let few = Cycle {
            period_s: Some(40.0),
            cycles: 2.5,
            strength: 0.9,
        };
        let (decided, text) = verdict(&laws, &rows, &few, None);
        assert_eq!(decided, None);
        assert!(text.contains("2.5 cycles") && text.contains("fewer than 3"), "{text}");
        let none = Cycle {
            period_s: None,
            cycles: 0.0,
            strength: 0.1,
        };
        assert!(verdict_text(&laws, &rows, &none).contains("only through T(Ω)"));
    }

    fn verdict_text(laws: &[LawPosterior], rows: &[CheckRow], cycle: &Cycle) -> String {
        verdict(laws, rows, cycle, None).1
    }
}
