//! Laws inferred from a surface record (top-drive speed and surface torque) through simulated
//! strings: simulation-based ABC-SMC, the model choice checked by re-simulation, and what the
//! surface implies at the bit.
//!
//! 1. **The record's noise**: given, or estimated from the surface torque ([`noise_sd`]).
//! 2. **The prior**: per law, boxes k scales wide from the physical bounds ([`Prior::physical`]),
//!    the scales from the record (the largest surface torque; speeds from the top drive's, the
//!    bit's peaks taken as three times it), replaced where a prior file gives bounds.
//! 3. **The pilot**: prior simulations that scale the distance per summary
//!    ([`Distance::from_pilot`]) and form the reference table of the check.
//! 4. **ABC-SMC** ([`crate::abc::smc`]) on ρ = the scaled distance of summaries, every candidate a
//!    string simulated on the record's clock ([`SurfaceEvaluator`]).
//! 5. **The check**: records re-simulated from each law's posterior are classified by their
//!    nearest neighbours in the reference table. Summaries that are not sufficient can make
//!    ABC model choice inconsistent (Robert, Cornuet, Marin & Pillai 2011); the law is called
//!    only where its own re-simulations are recognised and the others' are not taken for it.
//! 6. **At the bit**: posterior draws simulated on the record's clock give the bit speed's
//!    median and 90 % band per sample, the stuck share and severity, and, where the bit
//!    stick-slips, the simulated escape advice.

use crate::abc::smc::{self, SmcConfig};
use crate::abc::{Particle, Run};
use crate::data::surface::SurfaceRecord;
use crate::error::{Error, Result};
use crate::eval::Backend;
use crate::eval::surface::{Distance, NoiseKey, SurfaceEvaluator, SurfaceModel, Summaries, add_noise};
use crate::laws::Law;
use crate::numerics::weighted_quantile;
use crate::prior::{PhysicalScales, Prior, PriorFile};
use crate::simulate::strings::{Chain, Summary};
use crate::simulate::surface::{Drive, Integration, N_SUMMARIES, SUMMARY_NAMES, noise_variance_raw, summaries};
use crate::stability::lumped::Lumped;
use crate::stability::map::LawSamples;
use crate::units::RAD_S_PER_RPM;
use rayon::prelude::*;
use serde::Serialize;

/// How a surface record is read into laws.
#[derive(Clone, Debug)]
pub struct SurfaceSettings {
    pub laws: Vec<Law>,
    /// Bounds replacing the physical boxes (torques in the record's unit).
    pub prior_file: Option<PriorFile>,
    /// k: each box spans k of its parameter's scales from its physical bound.
    pub prior_scale: f64,
    /// The 1-DOF string.
    pub structure: Lumped,
    /// Reference weight on bit of the laws' parameters (N); `None`: r = 1 throughout.
    pub w_ref_n: Option<f64>,
    pub integration: Integration,
    /// Standard deviation of the surface torque's noise (N·m); `None`: estimated.
    pub noise_sd_nm: Option<f64>,
    /// Prior simulations of the pilot (scales and reference table).
    pub pilot: usize,
    /// Re-simulated records per law for the check.
    pub check_replicates: usize,
    /// Posterior draws simulated for the bit's predictive band.
    pub predictive_draws: usize,
    pub smc: SmcConfig,
    /// Whether to simulate the escape advice where the bit stick-slips.
    pub advice: bool,
}

/// The default prior scale k: as wide as the evidence's boxes.
pub const DEFAULT_PRIOR_SCALE: f64 = crate::run::evidence::DEFAULT_PRIOR_SCALE;
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
/// A law is called when its own re-simulations are recognised at least this often and no
/// other plausible law's are taken for it more often than `1 −` this.
pub const CHECK_RECOGNISED: f64 = 0.8;
/// A law at least this probable takes part in the verdict.
pub const PLAUSIBLE: f64 = 0.05;

impl SurfaceSettings {
    /// The defaults for `laws`: N = 2,000 particles, at most 8 populations, the sampler's
    /// defaults otherwise.
    pub fn new(laws: Vec<Law>) -> Self {
        let mut smc = SmcConfig::default();
        smc.schedule.particles = 2000;
        smc.schedule.eps_min = 0.0;
        smc.schedule.max_populations = 8;
        smc.schedule.min_acceptance = 0.01;
        smc.schedule.max_batch = 4096;
        Self {
            laws,
            prior_file: None,
            prior_scale: DEFAULT_PRIOR_SCALE,
            structure: Lumped::default(),
            w_ref_n: None,
            integration: Integration::default(),
            noise_sd_nm: None,
            pilot: DEFAULT_PILOT,
            check_replicates: DEFAULT_CHECK_REPLICATES,
            predictive_draws: DEFAULT_PREDICTIVE_DRAWS,
            smc,
            advice: true,
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
            return Err(Error::setting("noise_sd", format!("must be ≥ 0, got {s}")));
        }
        if let Some(w) = self.w_ref_n
            && !(w.is_finite() && w > 0.0)
        {
            return Err(Error::setting("w_ref_kn", format!("must be positive, got {}", w / 1000.0)));
        }
        if !(self.integration.dt_s.is_finite() && self.integration.dt_s > 0.0) {
            return Err(Error::setting("dt_s", format!("must be positive, got {}", self.integration.dt_s)));
        }
        if !(self.integration.settle_s.is_finite() && self.integration.settle_s >= 0.0) {
            return Err(Error::setting(
                "settle_s",
                format!("must be ≥ 0, got {}", self.integration.settle_s),
            ));
        }
        self.structure.validate()
    }
}

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
        let period = observed[11];
        let strength = observed[12];
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
}

/// One law's posterior: probability and, per parameter, the weighted median and central 90 %.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct LawPosterior {
    pub law: Law,
    pub probability: f64,
    pub particles: usize,
    /// (name, 5 %, median, 95 %), SI (torques N·m).
    pub params: Vec<(String, f64, f64, f64)>,
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
    /// Prior simulations in the reference table, and the neighbours each classification uses.
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
    /// Draws whose string left physical bounds (not counted above).
    pub diverged: usize,
    /// What ends the stick-slip, by simulated strings (where the bit stick-slips).
    pub advice: Option<String>,
}

/// Everything a surface inference finds.
#[derive(Clone, Debug, Serialize)]
pub struct SurfaceResult {
    pub roles: String,
    pub noise_sd_nm: f64,
    /// Whether the noise was estimated from the record.
    pub noise_estimated: bool,
    pub summary_names: Vec<&'static str>,
    pub observed: Vec<f64>,
    pub scales: Vec<f64>,
    pub cycle: Cycle,
    /// T(Ω) the mean surface torque states (N·m at r = 1) and the speed (rpm).
    pub mean_torque_nm: f64,
    pub mean_top_drive_rpm: f64,
    pub laws: Vec<LawPosterior>,
    pub check: ModelCheck,
    pub at_the_bit: AtTheBit,
    pub populations: usize,
    pub final_epsilon: Option<f64>,
    pub stop: String,
    /// Strings simulated in all (pilot, sampler, check, predictive).
    pub simulations: u64,
    pub seconds: f64,
    #[serde(skip)]
    pub run: Option<Run>,
}

/// The model a record drives: its string, its clock and its noise.
fn model(record: &SurfaceRecord, settings: &SurfaceSettings, noise_sd_nm: f64) -> SurfaceModel {
    SurfaceModel {
        chain: Chain::one_dof(&settings.structure),
        drive: Drive {
            omega_rad_s: record.top_drive_rad_s.clone(),
            ratio: record.wob_ratio(settings.w_ref_n),
            period_s: record.sample_period_s,
        },
        integration: settings.integration,
        noise_sd_nm,
    }
}

/// The prior's scales from a surface record: its largest torque, and speeds from the top
/// drive's (a stick-slipping bit peaks at two to three times it).
fn scales(record: &SurfaceRecord) -> PhysicalScales {
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
pub fn infer(record: &SurfaceRecord, settings: &SurfaceSettings, seed: u64, note: &mut dyn FnMut(String)) -> Result<SurfaceResult> {
    settings.validate()?;
    let started = std::time::Instant::now();
    let chain = Chain::one_dof(&settings.structure);
    chain.check_step(settings.integration.dt_s)?;
    let observed = summaries(&record.surface_torque_nm, record.sample_period_s);
    let cycle = Cycle::of(&observed, record.duration_s());
    let prior = Prior::physical(
        &settings.laws,
        &scales(record),
        settings.prior_scale,
        settings.prior_file.as_ref(),
        record.torque_unit.newton_metres(),
    )?;
    let mut model = model(record, settings, 0.0);
    let mut simulations = settings.pilot as u64;
    let pilot = Pilot::simulate(&model, &prior, seed ^ PILOT_STREAM, settings.pilot)?;
    let (noise_sd_nm, noise_estimated) = match settings.noise_sd_nm {
        Some(s) => (s, false),
        None => {
            let first = pilot.noise_sd_nm(&record.surface_torque_nm, &observed, model.drive.period_s);
            let (refined, spent) = refine_noise(record, &pilot, &model, &prior, settings, seed, first, &observed)?;
            simulations += spent;
            (refined, true)
        }
    };
    model.noise_sd_nm = noise_sd_nm;
    let table = pilot.table(noise_sd_nm, model.drive.period_s);
    let summaries_only: Vec<Summaries> = table.iter().map(|t| t.1).collect();
    let distance = Distance::from_pilot(observed, &summaries_only);

    let evaluator = SurfaceEvaluator::new(prior.clone(), seed, model.clone(), distance.clone());
    let run = smc::run(&evaluator, &settings.smc)?;
    simulations += run.populations.iter().map(|p| p.record.candidates_scored).sum::<u64>();
    let last = run.populations.last().expect("a run has a population");
    let particles = &last.particles;
    let laws = posteriors(&prior, particles);

    let check = check(&prior, &model, &distance, &table, &laws, particles, settings.check_replicates, seed, &cycle);
    simulations += check.rows.iter().map(|r| r.replicates as u64).sum::<u64>();
    let mut at_the_bit = at_the_bit(&model, particles, settings.predictive_draws, seed);
    simulations += at_the_bit.draws as u64;
    if settings.advice && at_the_bit.stick_slip_probability >= 0.5 {
        at_the_bit.advice = Some(escape_advice(record, settings, &chain, &laws, particles, note)?);
    }
    let ratio_mean = model.drive.ratio.iter().sum::<f64>() / model.drive.ratio.len() as f64;
    Ok(SurfaceResult {
        roles: record.roles_text(),
        noise_sd_nm,
        noise_estimated,
        summary_names: SUMMARY_NAMES.to_vec(),
        observed: observed.to_vec(),
        scales: distance.scales.to_vec(),
        cycle,
        mean_torque_nm: observed[0] / ratio_mean,
        mean_top_drive_rpm: record.mean_top_drive_rad_s() / RAD_S_PER_RPM,
        laws,
        check,
        at_the_bit,
        populations: run.populations.len(),
        final_epsilon: last.record.epsilon,
        stop: run.stop.describe().to_string(),
        simulations,
        seconds: started.elapsed().as_secs_f64(),
        run: Some(run),
    })
}

/// The pilot: prior simulations, noise-free, kept whole so that the record's noise, once
/// estimated, can be added to them.
struct Pilot {
    /// Per simulation that stayed in bounds: its law's slot, its candidate's noise key and its
    /// noise-free surface torque (N·m).
    runs: Vec<(usize, NoiseKey, Vec<f64>)>,
}

/// Rounds of the noise estimate: each finds the pilot strings nearest the record with the
/// noise of the round before.
const NOISE_ROUNDS: usize = 2;

impl Pilot {
    fn simulate(model: &SurfaceModel, prior: &Prior, seed: u64, count: usize) -> Result<Self> {
        let runs: Vec<Option<(usize, NoiseKey, Vec<f64>)>> = (0..count)
            .into_par_iter()
            .with_max_len(1)
            .map(|i| {
                let c = prior.candidate(seed, 0, i as u64);
                let law = prior.law(c.slot);
                let params = c.widened();
                let run = model.simulate(law, &params[..law.n_params()], NoiseKey::of(seed, &c));
                (!run.diverged).then(|| (c.slot, NoiseKey::of(seed, &c), run.surface_torque_nm))
            })
            .collect();
        let runs: Vec<_> = runs.into_iter().flatten().collect();
        if runs.len() < count / 2 {
            return Err(Error::Numerical(format!(
                "{} of the pilot's {count} prior strings left physical bounds: the prior boxes admit laws whose torque turns negative at speed; narrow them with a prior file",
                count - runs.len()
            )));
        }
        Ok(Self { runs })
    }

    /// The reference table with noise of `sd_nm`: each run's law slot and summaries.
    fn table(&self, sd_nm: f64, period_s: f64) -> Vec<(usize, Summaries)> {
        self.runs
            .par_iter()
            .map(|(slot, key, torque)| {
                let mut noisy = torque.clone();
                add_noise(&mut noisy, sd_nm, *key);
                (*slot, summaries(&noisy, period_s))
            })
            .collect()
    }

    /// The record's noise (N·m): the estimator of [`noise_variance_raw`] on the record less
    /// what it reads as noise on the pilot strings nearest the record, which are noise-free:
    /// the share of a coarse clock's signal it takes for noise.
    fn noise_sd_nm(&self, torque_nm: &[f64], observed: &Summaries, period_s: f64) -> f64 {
        let raw = noise_variance_raw(torque_nm);
        let leaks: Vec<f64> = self.runs.par_iter().map(|r| noise_variance_raw(&r.2)).collect();
        let neighbours = (self.runs.len() / 20).max(10).min(self.runs.len());
        let mut sd = 0.0;
        for _ in 0..NOISE_ROUNDS {
            let table = self.table(sd, period_s);
            let distance = Distance::from_pilot(*observed, &table.iter().map(|t| t.1).collect::<Vec<_>>());
            let mut near: Vec<(f64, usize)> = table.iter().enumerate().map(|(i, t)| (distance.rho(&t.1), i)).collect();
            near.select_nth_unstable_by(neighbours - 1, |a, b| a.0.total_cmp(&b.0));
            let leak: Vec<f64> = near[..neighbours].iter().map(|&(_, i)| leaks[i]).collect();
            let leak = crate::numerics::median(&leak).unwrap_or(0.0);
            sd = (raw - leak).max(0.0).sqrt();
        }
        sd
    }
}

/// Particles and populations of the short run that refines the noise estimate.
const NOISE_RUN_PARTICLES: usize = 300;
const NOISE_RUN_POPULATIONS: usize = 4;
/// Posterior strings whose noise-free torque measures the estimator's share of signal.
const NOISE_RUN_DRAWS: usize = 40;

/// The record's noise refined at the posterior: a short ABC-SMC with the pilot's estimate
/// `first` finds the strings near the record, and the estimator's reading of their noise-free
/// torque is taken off its reading of the record (see [`noise_variance_raw`]). Returns the
/// noise (N·m) and the strings simulated.
#[allow(clippy::too_many_arguments)]
fn refine_noise(
    record: &SurfaceRecord,
    pilot: &Pilot,
    model: &SurfaceModel,
    prior: &Prior,
    settings: &SurfaceSettings,
    seed: u64,
    first: f64,
    observed: &Summaries,
) -> Result<(f64, u64)> {
    let period_s = model.drive.period_s;
    let table = pilot.table(first, period_s);
    let distance = Distance::from_pilot(*observed, &table.iter().map(|t| t.1).collect::<Vec<_>>());
    let noisy = SurfaceModel {
        noise_sd_nm: first,
        ..model.clone()
    };
    let mut short = settings.smc.clone();
    short.schedule.particles = NOISE_RUN_PARTICLES.min(settings.smc.schedule.particles);
    short.schedule.max_populations = NOISE_RUN_POPULATIONS;
    short.schedule.max_seconds = None;
    let evaluator = SurfaceEvaluator::new(prior.clone(), seed ^ NOISE_STREAM, noisy, distance);
    let run = smc::run(&evaluator, &short)?;
    let spent: u64 = run.populations.iter().map(|p| p.record.candidates_scored).sum();
    let particles: Vec<&Particle> = run.populations.last().map(|p| p.particles.iter().collect()).unwrap_or_default();
    let drawn = resample(&particles, NOISE_RUN_DRAWS, seed ^ NOISE_STREAM);
    let leaks: Vec<f64> = drawn
        .par_iter()
        .with_max_len(1)
        .filter_map(|p| {
            let run = crate::simulate::surface::simulate_on_clock(&model.chain, &model.drive, p.law, &p.params, model.integration);
            (!run.diverged).then(|| noise_variance_raw(&run.surface_torque_nm))
        })
        .collect();
    let Some(leak) = crate::numerics::median(&leaks) else {
        return Ok((first, spent));
    };
    let raw = noise_variance_raw(&record.surface_torque_nm);
    Ok(((raw - leak).max(0.0).sqrt(), spent + drawn.len() as u64))
}

/// Seed offset of the noise's short run.
const NOISE_STREAM: u64 = 0x4e4f_4953_4500_0000;

/// Each law's probability and parameter quantiles in the final population.
fn posteriors(prior: &Prior, particles: &[Particle]) -> Vec<LawPosterior> {
    prior
        .laws()
        .map(|law| {
            let own: Vec<&Particle> = particles.iter().filter(|p| p.law == law).collect();
            let weights: Vec<f64> = own.iter().map(|p| p.weight).collect();
            let params = law
                .params()
                .iter()
                .enumerate()
                .filter(|_| !own.is_empty())
                .map(|(j, spec)| {
                    let values: Vec<f64> = own.iter().map(|p| p.params[j]).collect();
                    let q = |p: f64| weighted_quantile(&values, &weights, p);
                    (spec.name.to_string(), q(0.05), q(0.5), q(0.95))
                })
                .collect();
            LawPosterior {
                law,
                probability: weights.iter().sum(),
                particles: own.len(),
                params,
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
    let offset = crate::rng::open_unit(crate::rng::philox4x32_10([0, 0, 0, 0x5245_5341], crate::rng::key_of_seed(seed))[0]);
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

/// The model choice checked by re-simulation (see the module documentation).
#[allow(clippy::too_many_arguments)]
fn check(
    prior: &Prior,
    model: &SurfaceModel,
    distance: &Distance,
    table: &[(usize, Summaries)],
    laws: &[LawPosterior],
    particles: &[Particle],
    replicates: usize,
    seed: u64,
    cycle: &Cycle,
) -> ModelCheck {
    let neighbours = (table.len() / 20).max(10).min(table.len());
    let classify = |s: &Summaries| -> usize {
        let mut near: Vec<(f64, usize)> = table.iter().map(|(slot, t)| (distance.between(s, t), *slot)).collect();
        near.select_nth_unstable_by(neighbours - 1, |a, b| a.0.total_cmp(&b.0));
        let mut votes = vec![0usize; prior.boxes.len()];
        for (_, slot) in &near[..neighbours] {
            votes[*slot] += 1;
        }
        // Ties go to the earlier law: deterministic.
        (0..votes.len()).max_by_key(|&k| (votes[k], std::cmp::Reverse(k))).expect("a law")
    };
    let mut rows = Vec::new();
    for (slot, posterior) in laws.iter().enumerate() {
        if posterior.particles == 0 {
            continue;
        }
        let own: Vec<&Particle> = particles.iter().filter(|p| p.law == posterior.law).collect();
        let drawn = resample(&own, replicates, seed ^ (slot as u64 + 1));
        let classes: Vec<Option<usize>> = drawn
            .par_iter()
            .enumerate()
            .with_max_len(1)
            .map(|(k, p)| {
                let run = model.simulate(p.law, &p.params, NoiseKey::replicate(seed, (slot * replicates + k) as u64));
                (!run.diverged).then(|| classify(&summaries(&run.surface_torque_nm, model.drive.period_s)))
            })
            .collect();
        let mut counts = vec![0usize; prior.boxes.len()];
        for c in classes.iter().flatten() {
            counts[*c] += 1;
        }
        let seen = classes.iter().flatten().count().max(1);
        rows.push(CheckRow {
            law: posterior.law,
            replicates: drawn.len(),
            classified_as: prior.laws().zip(counts.iter().copied()).collect(),
            recognised: counts[slot] as f64 / seen as f64,
        });
    }
    let (decided, verdict) = verdict(laws, &rows, cycle);
    ModelCheck {
        reference: table.len(),
        neighbours,
        rows,
        decided,
        verdict,
    }
}

/// The law called and why (see [`CHECK_RECOGNISED`]).
fn verdict(laws: &[LawPosterior], rows: &[CheckRow], cycle: &Cycle) -> (Option<Law>, String) {
    if !cycle.informs() {
        return (
            None,
            match cycle.period_s {
                None => "no stick-slip cycle in the surface torque: the record informs the law only through T(Ω) at its speed, not its shape; no law is called".into(),
                Some(p) => format!(
                    "the record holds {:.1} cycles of {p:.1} s, fewer than {MIN_CYCLES}: too few to tell the laws apart; no law is called",
                    cycle.cycles
                ),
            },
        );
    }
    let Some(best) = laws.iter().max_by(|a, b| a.probability.total_cmp(&b.probability)) else {
        return (None, "no law has particles".into());
    };
    let recognised = |law: Law| rows.iter().find(|r| r.law == law).map_or(0.0, |r| r.recognised);
    let taken_for_best = |r: &CheckRow| {
        let n: usize = r.classified_as.iter().map(|c| c.1).sum();
        r.classified_as.iter().find(|c| c.0 == best.law).map_or(0.0, |c| c.1 as f64 / n.max(1) as f64)
    };
    let confused: Vec<Law> = rows
        .iter()
        .filter(|r| r.law != best.law)
        .filter(|r| laws.iter().any(|l| l.law == r.law && l.probability >= PLAUSIBLE))
        .filter(|r| taken_for_best(r) > 1.0 - CHECK_RECOGNISED)
        .map(|r| r.law)
        .collect();
    let own = recognised(best.law);
    if own < CHECK_RECOGNISED {
        return (
            None,
            format!(
                "{} leads (P = {:.2}), but only {:.0} % of the records re-simulated from it are recognised as it: the summaries do not tell it apart; undecided",
                best.law,
                best.probability,
                100.0 * own
            ),
        );
    }
    if !confused.is_empty() {
        let names: Vec<String> = confused.iter().map(|l| l.to_string()).collect();
        return (
            None,
            format!(
                "{} leads (P = {:.2}), but records re-simulated from {} are taken for it too: undecided between {} and {}",
                best.law,
                best.probability,
                names.join(", "),
                best.law,
                names.join(", ")
            ),
        );
    }
    (
        Some(best.law),
        format!(
            "{} (P = {:.2}); {:.0} % of the records re-simulated from it are recognised as it, and no other plausible law's are taken for it",
            best.law,
            best.probability,
            100.0 * own
        ),
    )
}

/// The bit's speed on the record's clock from posterior draws (see [`AtTheBit`]).
fn at_the_bit(model: &SurfaceModel, particles: &[Particle], draws: usize, seed: u64) -> AtTheBit {
    let all: Vec<&Particle> = particles.iter().collect();
    let drawn = resample(&all, draws, seed ^ 0x4249_5400);
    let runs: Vec<_> = drawn
        .par_iter()
        .with_max_len(1)
        .map(|p| model.simulate(p.law, &p.params, NoiseKey::replicate(seed ^ 0x4249_5400, p.index)))
        .collect();
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
    let reductions: Vec<Summary> = good
        .iter()
        .map(|r| {
            let mut s = Summary::default();
            for (w, t) in r.bit_speed_rad_s.iter().zip(&r.surface_torque_nm) {
                s.push(*w, f64::NAN, *t);
            }
            s
        })
        .collect();
    AtTheBit {
        draws: drawn.len(),
        speed_rpm,
        stuck_share: three(reductions.iter().map(Summary::stuck_share).collect()),
        severity: three(reductions.iter().map(Summary::severity).filter(|s| s.is_finite()).collect()),
        stick_slip_probability: reductions.iter().filter(|s| s.stick_slips()).count() as f64 / reductions.len().max(1) as f64,
        diverged: runs.len() - good.len(),
        advice: None,
    }
}

/// Posterior samples per law for the simulated advice.
const ADVICE_SAMPLES: usize = 20;

/// The simulated escape advice from the record's mean operating point.
fn escape_advice(
    record: &SurfaceRecord,
    settings: &SurfaceSettings,
    chain: &Chain,
    laws: &[LawPosterior],
    particles: &[Particle],
    note: &mut dyn FnMut(String),
) -> Result<String> {
    use crate::run::strings::{OperatingPoint, SimulatedSettings, Simulator, advice_speeds_rpm, advice_weights_kn};
    let w_ref_n = settings.w_ref_n.unwrap_or(crate::laws::PAPER_W_REF_N);
    let wob_n = record
        .wob_n
        .as_ref()
        .map_or(w_ref_n, |w| w.iter().sum::<f64>() / w.len() as f64);
    let inputs: Vec<LawSamples> = laws
        .iter()
        .filter(|l| l.particles > 0)
        .map(|l| {
            let own: Vec<&Particle> = particles.iter().filter(|p| p.law == l.law).collect();
            let samples_si = resample(&own, ADVICE_SAMPLES, 0x4144_5649).iter().map(|p| p.params.clone()).collect();
            LawSamples {
                law: l.law,
                probability: l.probability,
                map_si: l.params.iter().map(|p| p.2).collect(),
                samples_si,
            }
        })
        .collect();
    let simulated = SimulatedSettings::new(chain.clone(), w_ref_n, Backend::Cpu);
    let mut simulator = Simulator::new(&simulated, &inputs, note)?;
    let point = OperatingPoint {
        omega_rpm: record.mean_top_drive_rad_s() / RAD_S_PER_RPM,
        wob_kn: wob_n / 1000.0,
    };
    let at = simulator.at_point(point)?;
    let advice = simulator.escape_advice(&at, &advice_speeds_rpm(point.omega_rpm), &advice_weights_kn(point.wob_kn))?;
    Ok(advice.text())
}

/// The summaries' names with the record's values and scales, for reports.
pub fn summary_table(result: &SurfaceResult) -> Vec<(&'static str, f64, f64)> {
    (0..N_SUMMARIES)
        .map(|j| (SUMMARY_NAMES[j], result.observed[j], result.scales[j]))
        .collect()
}
