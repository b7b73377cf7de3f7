//! Which structure a bit or surface record shows: a torsional law m1–m4 (a torque that falls with bit
//! speed, the weight on bit a constant) or the coupled axial-torsional bit (RGD: stick-slip from
//! the depth of cut, the weight on bit swinging with it).
//!
//! Every candidate's string is simulated at the record's drive (from the bit's channels, from
//! steady rotation kicked by the settings' kick; from the surface's, see [`surface_choice`]),
//! with white noise added to each channel until its apparent noise is the record's
//! ([`noise_variance_raw`]: what is not smooth at the record's clock, the coupled bit's
//! swings of weight between samples among it), and reduced to summaries of its bit speed,
//! torque and weight on bit ([`SUMMARIES`]). The reference table holds [`Settings::reference`]
//! candidates of each structure; a structure's probability is its share of the table's
//! candidates nearest the record (rejection ABC, each structure a fifth before the record, the
//! families a half each in [`FamilyChoice`]; the distance scales
//! each summary by its spread within the structures, as Prangle 2017 scales by a single
//! model's). Summaries are not sufficient for a model choice (Robert, Cornuet, Marin & Pillai
//! 2011), so the choice is always checked by re-simulation: records re-simulated from each
//! structure's accepted candidates are chosen for as the record was, and a structure is called
//! only where its own are recognised and no other's are taken for it
//! ([`crate::run::answer::resimulation_verdict`]). A structure none of whose candidates came
//! near the record escapes that check, so the table's own candidates are classified too, each
//! left out of its own vote ([`Choice::table_check`]): where another's are taken for the leader
//! too often nothing is called. A call also needs [`CALL_PROBABILITY`], and a structure is
//! called only where its family is; the two families weigh the same before the record
//! ([`FamilyChoice::torsional_probability`]).
//!
//! **From the surface** ([`surface_choice`]): the same choice on the surface torque's
//! summaries ([`SURFACE_SUMMARIES`]), every candidate at the record's steady top-drive speed
//! and on its clock; a law is never called from it (see [`surface_choice`]).
//!
//! **Priors.** A law's box is the paper's, φ̂(1 ± δ) around its least-squares fit to the
//! record's turning samples (δ = [`LAW_DELTA`]). The coupled bit's radius, contact stress, γ and
//! blades are the settings'; ε is drawn log-uniform over [`EPSILON_MPA`], ζ uniform over
//! [`ZETA`], the wear flats' contact force uniform over [`CONTACT_SHARE`] of the weight, and μ
//! is the one that makes steady drilling's torque the record's mean torque (a draw that needs μ
//! outside the bit's bounds is drawn again): both structures' candidates are centred on the
//! record, neither by a fit to its dynamics.

use super::answer::{CHECK_CONFUSED, resimulation_verdict};
use super::coupled::Settings;
use crate::data::STUCK_SPEED_RAD_S;
use crate::data::Samples;
use crate::data::drilling::DrillingRecord;
use crate::data::surface::SurfaceRecord;
use crate::error::{Error, Result};
use crate::eval::surface::{NoiseKey, add_noise};
use crate::fit::{FitOptions, fit_laws};
use crate::laws::Law;
use crate::numerics::quantile;
use crate::prior::{LawBox, Prior};
use crate::rng::{candidate_counter, key_of_seed, open_unit, philox4x32_10};
use crate::run::surface::{DEFAULT_PRIOR_SCALE, physical_scales};
use crate::simulate::coupled::{self, Axial, BIT_BOUNDS, Bit, CoupledJob, Schedule};
use crate::simulate::strings::Chain;
use crate::simulate::surface::{
    Drive, Integration, N_DOWNHOLE_SUMMARIES, N_TORQUE_SUMMARIES, SUMMARY_NAMES, noise_variance_raw, simulate_on_clock,
    summaries,
};
use crate::simulate::{Initial, Recording, SimConfig};
use crate::units::RAD_S_PER_RPM;
use rayon::prelude::*;
use serde::Serialize;

/// A structure a bit record may come from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Structure {
    /// A torsional law: torque on bit a function of bit speed, the weight on bit constant.
    Torsional(Law),
    /// The coupled axial-torsional bit (Richard, Germay & Detournay 2007).
    Coupled,
}

impl std::fmt::Display for Structure {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Torsional(law) => write!(f, "{law}"),
            Self::Coupled => f.write_str("RGD"),
        }
    }
}

impl Serialize for Structure {
    fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        s.collect_str(self)
    }
}

/// The summaries a record and every simulated string are compared by, in order (SI).
pub const SUMMARIES: [&str; 12] = [
    "stuck_share",
    "speed_sd_rad_s",
    "speed_p95_rad_s",
    "torque_mean_nm",
    "torque_sd_nm",
    "torque_p05_nm",
    "torque_p95_nm",
    "torque_above_median_speed_nm",
    "torque_below_median_speed_nm",
    "speed_torque_correlation",
    "wob_sd_n",
    "wob_torque_correlation",
];

/// The summaries of a record from the surface, in order: the surface sampler's torque
/// summaries (`bitrock surface`'s, [`crate::simulate::surface::summaries`]).
pub const SURFACE_SUMMARIES: [&str; N_TORQUE_SUMMARIES] = {
    let mut names = [""; N_TORQUE_SUMMARIES];
    let mut i = 0;
    while i < N_TORQUE_SUMMARIES {
        names[i] = SUMMARY_NAMES[i];
        i += 1;
    }
    names
};

/// A record's or a candidate's summaries: [`SUMMARIES`] of the bit's channels, or
/// [`SURFACE_SUMMARIES`] of the surface torque.
type Summaries = Vec<f64>;

/// Half-width of a law's prior box around its fit, relative (the paper's δ).
pub const LAW_DELTA: f64 = 0.4;
/// The coupled bit's prior range of the rock's intrinsic specific energy ε (MPa, log-uniform).
pub const EPSILON_MPA: (f64, f64) = (10.0, 300.0);
/// The coupled bit's prior range of ζ (uniform).
pub const ZETA: (f64, f64) = (0.2, 1.2);
/// The coupled bit's prior range of the wear flats' contact force, as shares of the weight on
/// the bit assembly (uniform).
pub const CONTACT_SHARE: (f64, f64) = (0.05, 0.95);
/// The least probability a structure or a family is called at (odds of 4 to 1), where the
/// checks allow it.
pub const CALL_PROBABILITY: f64 = 0.8;
/// Draws tried for one coupled candidate before its place in the table is left empty.
const MAX_ATTEMPTS: u32 = 64;
/// Integration step of the torsional laws' strings (s), the strings' twin's. Their RK4, with
/// the stop and the release located inside a step, has converged at it: on 30 s of each law's
/// cycle on the paper's string at 50 Hz, the stuck share and the speeds' and torques' means and
/// peaks are those of 1-ms steps to four digits.
const TORSIONAL_DT_S: f64 = 0.01;

/// The coupled bit's drawn parameters, in a candidate's order: the [`Bit`] fields they set.
pub const COUPLED_PARAMETERS: [(&str, &str); 4] = [
    ("intrinsic_energy_mpa", "MPa"),
    ("zeta", "1"),
    ("wear_flat_mm", "mm"),
    ("friction", "1"),
];

/// Which of a record's channels a choice compares.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Channels {
    /// Bit speed, torque on bit and weight on bit: a memory tool's or a laboratory rig's.
    Bit,
    /// The surface torque at a steady top-drive speed: what a rig streams.
    Surface,
}

/// Most a surface record's top-drive speed may stray from its mean, as a share of it: every
/// candidate is simulated at one speed.
pub const STEADY_TOP_DRIVE: f64 = 0.05;

/// The drive every candidate is simulated at, and the noise added to its channels.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ChoiceDrive {
    /// The channels compared.
    pub channels: Channels,
    /// The top drive's speed (rpm): as set, or a surface record's mean.
    pub omega_rpm: f64,
    /// The weight on the bit assembly (kN): as set, or the record's mean weight on bit.
    pub wob_kn: f64,
    /// Whether the weight is the record's mean.
    pub wob_from_record: bool,
    /// The record's length (s) at its sample rate, and its samples.
    pub duration_s: f64,
    pub samples: usize,
    /// The white noise the record's compared channels show, standard deviations (the root of
    /// their variance above a smooth signal's): torque (kN·m: on bit, or at the surface); bit
    /// speed (rpm) and weight on bit (kN) from the bit's channels (`None` from the surface).
    /// Each candidate's channels are topped up to it.
    pub noise_speed_rpm: Option<f64>,
    pub noise_torque_knm: f64,
    pub noise_wob_kn: Option<f64>,
}

/// A parameter's median over a structure's accepted candidates.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Estimate {
    pub name: &'static str,
    /// SI for a law's parameters (N·m for torques), the flag's unit for the coupled bit's.
    pub unit: String,
    pub median: f64,
}

/// One structure's part of the choice.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct StructureShare {
    pub structure: Structure,
    /// Its share of the accepted candidates.
    pub probability: f64,
    /// Its candidates in the table (fewer than asked where draws failed) and among the accepted.
    pub candidates: usize,
    pub accepted: usize,
    /// Its accepted candidates' medians (empty where none was accepted).
    pub estimates: Vec<Estimate>,
}

/// Records re-simulated from one structure and what the choice took them for.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ChoiceCheckRow {
    pub structure: Structure,
    /// The records classified, and those whose string diverged.
    pub replicates: usize,
    pub diverged: usize,
    /// How many were taken for each structure.
    pub classified_as: Vec<(Structure, usize)>,
    /// The share taken for their own structure.
    pub recognised: f64,
}

/// The structure a bit record shows, checked by re-simulation.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Choice {
    pub drive: ChoiceDrive,
    /// The record's summaries ([`SUMMARIES`] or [`SURFACE_SUMMARIES`]), in order.
    pub record_summaries: Vec<(&'static str, f64)>,
    /// Candidates in the table, and those nearest the record that decide.
    pub reference: usize,
    pub accepted: usize,
    pub structures: Vec<StructureShare>,
    pub check: Vec<ChoiceCheckRow>,
    /// The table's own candidates classified as the record is, each left out of its own vote
    /// (`replicates` the structure's candidates): what the summaries tell apart over the whole
    /// prior, where the check tells it near the record.
    pub table_check: Vec<ChoiceCheckRow>,
    /// The structure called, where the checks, [`CALL_PROBABILITY`], its family's call and the
    /// record's channels allow one (a law is never called from the surface).
    pub decided: Option<Structure>,
    pub verdict: String,
    /// The same choice between the two families: any torsional law, or the coupled bit.
    pub family: FamilyChoice,
    /// What the caller should know (a structure left out, the weight taken from the record).
    pub notes: Vec<String>,
}

/// A family of structures: the torsional laws together, or the coupled bit.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Family {
    Torsional,
    Coupled,
}

impl Family {
    pub fn of(structure: Structure) -> Self {
        match structure {
            Structure::Torsional(_) => Self::Torsional,
            Structure::Coupled => Self::Coupled,
        }
    }
}

impl std::fmt::Display for Family {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Torsional => "a torsional law",
            Self::Coupled => "the coupled bit",
        })
    }
}

/// The choice between the families, weighed the same before the record; their
/// re-simulations pooled.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FamilyChoice {
    /// P(a torsional law), the two families weighed equally before the record (the table
    /// holds a candidate of each law for each of the coupled bit's); the coupled bit's is the
    /// rest.
    pub torsional_probability: f64,
    /// The shares of each family's re-simulated records taken for its own family (`None`
    /// where it had no accepted candidate).
    pub torsional_recognised: Option<f64>,
    pub coupled_recognised: Option<f64>,
    pub decided: Option<Family>,
    pub verdict: String,
}

/// One candidate of the table: its structure's slot, its parameters (SI for a law, the
/// [`COUPLED_PARAMETERS`] for the coupled bit) and its summaries.
struct Member {
    slot: usize,
    params: Vec<f64>,
    summaries: Summaries,
}

/// What every candidate is simulated with.
struct Simulator<'a> {
    settings: &'a Settings,
    omega_rad_s: f64,
    wob_n: f64,
    duration_s: f64,
    /// The record's apparent noise variances ([`noise_variance_raw`]) of the compared
    /// channels: bit speed ((rad/s)²), torque ((N·m)²), weight on bit (N²); or the surface
    /// torque's ((N·m)²).
    noise_variance: Vec<f64>,
    /// Where the record is a surface record: the laws' strings on its clock.
    surface: Option<SurfaceStrings>,
}

/// The torsional laws' strings of a surface choice: the settings' string, from rest, at the
/// record's top-drive speed and clock.
struct SurfaceStrings {
    chain: Chain,
    drive: Drive,
    integration: Integration,
}

impl Simulator<'_> {
    /// The coupled bit of a candidate's parameters.
    fn bit(&self, params: &[f64]) -> Bit {
        Bit {
            intrinsic_energy_mpa: params[0],
            zeta: params[1],
            wear_flat_mm: params[2],
            friction: params[3],
            ..self.settings.bit
        }
    }

    fn job(&self, bit: Bit) -> CoupledJob {
        CoupledJob {
            bit,
            omega_rad_s: self.omega_rad_s,
            axial: Axial::Weight { wob_n: self.wob_n },
            kick_rad_s: self.settings.kick_rpm * RAD_S_PER_RPM,
        }
    }

    /// The summaries of `structure`'s string with `params`, its noise drawn under `key`;
    /// `None` where the string diverged.
    fn summaries(&self, structure: Structure, params: &[f64], key: NoiseKey) -> Option<Summaries> {
        self.summaries_of(structure, &[(params, key)]).pop().flatten()
    }

    /// [`Self::summaries`] of several candidates of `structure`, in their order: the coupled
    /// bit's strings integrated side by side ([`coupled::integrate_lanes`]), each as if alone.
    fn summaries_of(&self, structure: Structure, candidates: &[(&[f64], NoiseKey)]) -> Vec<Option<Summaries>> {
        let channels: Vec<Option<Vec<Vec<f64>>>> = match structure {
            Structure::Coupled => self.coupled_channels(candidates.iter().map(|c| c.0)),
            Structure::Torsional(law) => candidates.iter().map(|c| self.law_channels(law, c.0)).collect(),
        };
        channels
            .into_iter()
            .zip(candidates)
            .map(|(channels, &(_, key))| self.summarised(channels?, key))
            .collect()
    }

    /// The coupled bit's compared channels with each of `candidates`' parameters (`None`
    /// where its string diverged): its surface torque from a surface record, else its bit
    /// speed, torque and weight on bit.
    fn coupled_channels<'p>(&self, candidates: impl Iterator<Item = &'p [f64]>) -> Vec<Option<Vec<Vec<f64>>>> {
        let s = self.settings;
        let surface = self.surface.is_some();
        let (Ok(schedule), Ok(assembly)) = (
            Schedule::new(s.dt_s, s.sample_hz, s.settle_s, self.duration_s),
            s.assembly(),
        ) else {
            return candidates.map(|_| None).collect();
        };
        let jobs: Vec<CoupledJob> = candidates.map(|params| self.job(self.bit(params))).collect();
        let mut channels = vec![vec![Vec::new(); if surface { 1 } else { 3 }]; jobs.len()];
        let ends = coupled::integrate_lanes(&assembly, &schedule, &jobs, None, None, &mut |i, x| {
            let lane = &mut channels[i];
            if surface {
                lane[0].push(x.surface_torque_nm);
            } else {
                lane[0].push(x.bit_speed_rad_s);
                lane[1].push(x.torque_nm);
                lane[2].push(x.wob_n);
            }
        });
        channels
            .into_iter()
            .zip(ends)
            .map(|(lane, (summary, _))| (!summary.diverged).then_some(lane))
            .collect()
    }

    /// A law's compared channels with `params` (`None` where its string diverged): its
    /// surface torque from a surface record, else its bit speed, torque and weight on bit.
    fn law_channels(&self, law: Law, params: &[f64]) -> Option<Vec<Vec<f64>>> {
        let s = self.settings;
        Some(match &self.surface {
            Some(strings) => {
                let run = simulate_on_clock(&strings.chain, &strings.drive, law, params, strings.integration);
                if run.diverged {
                    return None;
                }
                vec![run.surface_torque_nm]
            }
            None => {
                let cfg = SimConfig {
                    law,
                    params_nm: params.to_vec(),
                    structure: s.assembly().ok()?.torsion,
                    omega_rad_s: self.omega_rad_s,
                    wob_n: self.wob_n,
                    w_ref_n: self.wob_n,
                    duration_s: self.duration_s,
                    recording: Recording {
                        settle_s: s.settle_s,
                        sample_hz: s.sample_hz,
                        dt_s: TORSIONAL_DT_S.min(1.0 / s.sample_hz),
                        initial: Initial::Equilibrium {
                            speed_perturbation_rad_s: s.kick_rpm * RAD_S_PER_RPM,
                        },
                        ..Recording::default()
                    },
                };
                // A law whose torque turns negative at speed runs the bit away: no record.
                let trace = crate::simulate::simulate(&cfg).ok()?;
                vec![trace.bit_speed_rad_s, trace.torque_nm, trace.wob_n]
            }
        })
    }

    /// The summaries of a string's compared `channels`, its noise drawn under `key`; `None`
    /// where one is not finite.
    fn summarised(&self, mut channels: Vec<Vec<f64>>, key: NoiseKey) -> Option<Summaries> {
        // Each channel's noise makes its apparent noise the record's: a string whose signal is
        // not smooth at the record's clock (the coupled bit's weight swings between samples)
        // shows part of it as noise already, and the record shows the same.
        for (r, (channel, record)) in channels.iter_mut().zip(&self.noise_variance).enumerate() {
            let sd = (record - noise_variance_raw(channel)).max(0.0).sqrt();
            add_noise(channel, sd, key.redrawn(r as u64 + 1));
        }
        let out = match &self.surface {
            Some(strings) => surface_summaries(&channels[0], strings.drive.period_s),
            None => bit_summaries(&channels[0], &channels[1], &channels[2]).to_vec(),
        };
        out.iter().all(|v| v.is_finite()).then_some(out)
    }

    /// The `index`-th candidate of `law` for a surface record under `seed`: drawn from
    /// `prior` (`bitrock surface`'s), its torques scaled so that its torque at the top
    /// drive's speed is `torque_nm`, as the coupled bit's friction is chosen; `None` where no
    /// draw of [`MAX_ATTEMPTS`] has a positive torque there.
    fn surface_law_candidate(&self, prior: &Prior, seed: u64, index: u64, torque_nm: f64) -> Option<Vec<f64>> {
        let law = prior.law(0);
        for attempt in 0..MAX_ATTEMPTS {
            let c = prior.candidate(seed, attempt, index);
            let params: Vec<f64> = c.params[..law.n_params()].iter().map(|&v| f64::from(v)).collect();
            let at_drive = law.torque(&params, self.omega_rad_s, 1.0);
            if at_drive.is_finite() && at_drive > 0.0 {
                return Some(law.scale_torque(&params, torque_nm / at_drive));
            }
        }
        None
    }

    /// The `index`-th coupled candidate under `seed`: ε, ζ and the contact force drawn, μ
    /// making steady drilling's torque `torque_nm`; `None` where no draw of
    /// [`MAX_ATTEMPTS`] needs a μ within the bit's bounds.
    fn coupled_candidate(&self, seed: u64, index: u64, torque_nm: f64) -> Option<Vec<f64>> {
        let key = key_of_seed(NoiseKey::replicate(seed ^ 0x5247_4421, 0).0);
        let assembly = self.settings.assembly().ok()?;
        let (mu_lo, mu_hi) = BIT_BOUNDS[5];
        for attempt in 0..MAX_ATTEMPTS {
            let u = philox4x32_10(candidate_counter(attempt, index, 0), key).map(open_unit);
            let epsilon = (EPSILON_MPA.0.ln() + u[0] * (EPSILON_MPA.1 / EPSILON_MPA.0).ln()).exp();
            let zeta = ZETA.0 + u[1] * (ZETA.1 - ZETA.0);
            let contact_n = self.wob_n * (CONTACT_SHARE.0 + u[2] * (CONTACT_SHARE.1 - CONTACT_SHARE.0));
            let b = self.settings.bit;
            let wear_flat_mm = 1e3 * contact_n / (b.radius_m * b.contact_stress_mpa * 1e6);
            let torque_at = |friction: f64| {
                self.job(self.bit(&[epsilon, zeta, wear_flat_mm, friction]))
                    .steady(&assembly)
                    .torque_nm
            };
            let (t0, t1) = (torque_at(0.0), torque_at(1.0));
            let friction = (torque_nm - t0) / (t1 - t0);
            let params = vec![epsilon, zeta, wear_flat_mm, friction];
            if friction > mu_lo && friction <= mu_hi && self.bit(&params).validate().is_ok() {
                return Some(params);
            }
        }
        None
    }
}

/// The summaries of a record's (or a simulation's) bit speed (rad/s), torque (N·m) and weight
/// on bit (N), in [`SUMMARIES`]' order.
fn bit_summaries(speed: &[f64], torque: &[f64], wob: &[f64]) -> [f64; SUMMARIES.len()] {
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
    let sd = |v: &[f64]| {
        let m = mean(v);
        (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / v.len().max(1) as f64).sqrt()
    };
    let correlation = |a: &[f64], b: &[f64]| {
        let (ma, mb, sa, sb) = (mean(a), mean(b), sd(a), sd(b));
        if sa * sb > 0.0 {
            a.iter().zip(b).map(|(x, y)| (x - ma) * (y - mb)).sum::<f64>() / (a.len() as f64 * sa * sb)
        } else {
            0.0
        }
    };
    let stuck = speed.iter().filter(|w| w.abs() < STUCK_SPEED_RAD_S).count() as f64 / speed.len() as f64;
    let median_speed = quantile(speed, 0.5);
    let torque_where = |above: bool| {
        let picked: Vec<f64> = speed
            .iter()
            .zip(torque)
            .filter(|(w, _)| (**w > median_speed) == above)
            .map(|(_, t)| *t)
            .collect();
        if picked.is_empty() { mean(torque) } else { mean(&picked) }
    };
    [
        stuck,
        sd(speed),
        quantile(speed, 0.95),
        mean(torque),
        sd(torque),
        quantile(torque, 0.05),
        quantile(torque, 0.95),
        torque_where(true),
        torque_where(false),
        correlation(speed, torque),
        sd(wob),
        correlation(wob, torque),
    ]
}

/// The summaries of a surface torque (N·m) sampled every `period_s`, in
/// [`SURFACE_SUMMARIES`]' order.
fn surface_summaries(torque_nm: &[f64], period_s: f64) -> Summaries {
    summaries(torque_nm, period_s, &[0.0; N_DOWNHOLE_SUMMARIES])[..N_TORQUE_SUMMARIES].to_vec()
}

/// Each summary's spread within a structure: the mean over the structures of its 10-90 %
/// range among their own candidates, as a normal standard deviation (÷2.5631); its standard
/// deviation over the table where that is 0, 1 where both are. Pooled over the whole table a
/// MAD would be the majority's: four laws whose weight on bit is the noise alone would make a
/// summary of the weight a wall that no candidate of the coupled bit passes. A MAD within each
/// structure is its steady candidates' where most are steady, a wall again for a record that
/// stick-slips; the 10-90 % range sees both.
fn scales(table: &[Member], structures: usize) -> Summaries {
    let spread = |v: &[f64]| (quantile(v, 0.9) - quantile(v, 0.1)) / 2.5631;
    let mut out = vec![1.0; table.first().map_or(0, |m| m.summaries.len())];
    for (j, scale) in out.iter_mut().enumerate() {
        let within: Vec<f64> = (0..structures)
            .filter_map(|slot| {
                let v: Vec<f64> = table
                    .iter()
                    .filter(|m| m.slot == slot)
                    .map(|m| m.summaries[j])
                    .collect();
                (v.len() >= 2).then(|| spread(&v))
            })
            .collect();
        let within = within.iter().sum::<f64>() / within.len().max(1) as f64;
        let v: Vec<f64> = table.iter().map(|m| m.summaries[j]).collect();
        let mean = v.iter().sum::<f64>() / v.len() as f64;
        let sd = (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / v.len() as f64).sqrt();
        *scale = if within > 0.0 {
            within
        } else if sd > 0.0 {
            sd
        } else {
            1.0
        };
    }
    out
}

fn distance(a: &[f64], b: &[f64], scales: &[f64]) -> f64 {
    let sum: f64 = a
        .iter()
        .zip(b)
        .zip(scales)
        .map(|((x, y), s)| ((x - y) / s).powi(2))
        .sum();
    (sum / a.len() as f64).sqrt()
}

/// The `k` members nearest `s`, `skip` left out.
fn nearest<'t>(table: &'t [Member], s: &[f64], scales: &[f64], k: usize, skip: Option<&Member>) -> Vec<&'t Member> {
    let mut near: Vec<(f64, &Member)> = table
        .iter()
        .filter(|m| !skip.is_some_and(|x| std::ptr::eq(x, *m)))
        .map(|m| (distance(s, &m.summaries, scales), m))
        .collect();
    let k = k.min(near.len());
    if k == 0 {
        return Vec::new();
    }
    near.select_nth_unstable_by(k - 1, |a, b| a.0.total_cmp(&b.0));
    near.truncate(k);
    near.into_iter().map(|(_, m)| m).collect()
}

/// The structure most of the `k` members nearest `s` come from (ties to the earlier one),
/// `source`, the member `s` was re-simulated from, left out: it is the record's twin but for
/// the noise, and would vote for its own structure.
fn classify(table: &[Member], s: &[f64], scales: &[f64], k: usize, structures: usize, source: &Member) -> usize {
    let mut votes = vec![0usize; structures];
    for m in nearest(table, s, scales, k, Some(source)) {
        votes[m.slot] += 1;
    }
    (0..structures)
        .max_by_key(|&i| (votes[i], std::cmp::Reverse(i)))
        .expect("a structure")
}

/// The structures a choice weighs: the built-in laws and the coupled bit.
pub fn structures() -> Vec<Structure> {
    Law::ALL
        .into_iter()
        .map(Structure::Torsional)
        .chain([Structure::Coupled])
        .collect()
}

/// What a choice decides from: the record's summaries, how each structure's candidates are
/// drawn and simulated, and what the caller was told so far.
struct Prepared<'a> {
    simulator: Simulator<'a>,
    laws: LawDraws,
    /// The record's mean torque (N·m), on bit or at the surface: every candidate is centred
    /// on it.
    torque_nm: f64,
    observed: Summaries,
    names: &'static [&'static str],
    /// Whether a law may be called: from a surface record, each law's candidates are spread
    /// over `bitrock surface`'s prior, too thin near the record to tell the laws apart (its
    /// sampler draws each law where the record is); the family is called as from the bit.
    call_laws: bool,
    drive: ChoiceDrive,
    notes: Vec<String>,
    left_out: Vec<Structure>,
    source: std::path::PathBuf,
}

/// How a law's candidates are drawn.
enum LawDraws {
    /// Per law, its box around its fit to the record's turning samples (`None`: left out).
    Fitted(Vec<Option<LawBox>>),
    /// Per law, `bitrock surface`'s prior of it, each candidate scaled to the record's torque.
    Scaled(Vec<Prior>),
}

/// Refuses the settings a choice cannot run with, by name.
fn check_settings(settings: &Settings) -> Result<()> {
    if settings.reference < 10 {
        return Err(Error::setting(
            "reference",
            format!("must be at least 10, got {}", settings.reference),
        ));
    }
    if settings.replicates == 0 {
        return Err(Error::setting("replicates", "must be at least 1"));
    }
    settings.assembly()?;
    settings.bit.validate()?;
    if let Some(w) = settings.wob_kn
        && !(w.is_finite() && w > 0.0)
    {
        return Err(Error::setting("wob_kn", format!("must be positive, got {w} kN")));
    }
    Ok(())
}

/// Refuses a record of more samples than a simulated string records
/// ([`crate::simulate::strings::MAX_SAMPLES`]): every candidate is simulated on its clock.
fn refuse_long(n: usize, refuse: &dyn Fn(String) -> Error) -> Result<()> {
    use crate::simulate::strings::MAX_SAMPLES;
    if n > MAX_SAMPLES as usize {
        return Err(refuse(format!(
            "the record holds {n} samples, and a candidate's string records at most {MAX_SAMPLES}: choose from a stretch of at most that many"
        )));
    }
    Ok(())
}

/// The record's refusal: `message` about the file at `path`.
fn refusal(path: &std::path::Path, message: String) -> Error {
    Error::Format {
        path: path.to_path_buf(),
        line: None,
        message,
    }
}

/// The structure `record` shows (see the module documentation), the drive and the string from
/// `settings`: `omega_rpm` the top drive's speed while recorded, `wob_kn` where given (the
/// record's mean weight on bit otherwise), `sample_hz` the record's rate.
pub fn choice(record: &DrillingRecord, settings: &Settings, note: &mut dyn FnMut(String)) -> Result<Choice> {
    check_settings(settings)?;
    if !(settings.omega_rpm.is_finite() && settings.omega_rpm > 0.0) {
        return Err(Error::setting(
            "omega_rpm",
            format!("the top drive must turn forward, got {} rpm", settings.omega_rpm),
        ));
    }
    let n = record.len();
    let refuse = |message: String| refusal(&record.source, message);
    refuse_long(n, &refuse)?;
    let duration_s = n as f64 / settings.sample_hz;
    Schedule::new(settings.dt_s, settings.sample_hz, settings.settle_s, duration_s)?;
    if n < 50 {
        return Err(refuse(format!(
            "the record holds {n} samples: its bit speed, torque and weight on bit need at least 50 to be summarised"
        )));
    }
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    let wob_from_record = settings.wob_kn.is_none();
    let wob_n = settings.wob_kn.map_or_else(|| mean(&record.wob_n), |w| w * 1e3);
    if !(wob_n.is_finite() && wob_n > 0.0) {
        return Err(refuse(format!(
            "its mean weight on bit is {:.3} kN: the bit is not pushed onto the rock",
            wob_n / 1e3
        )));
    }
    let torque_nm = mean(&record.torque_nm);
    let omega_rad_s = settings.omega_rpm * RAD_S_PER_RPM;
    let noise_variance = vec![
        noise_variance_raw(&record.speed_rad_s),
        noise_variance_raw(&record.torque_nm),
        noise_variance_raw(&record.wob_n),
    ];
    let drive = ChoiceDrive {
        channels: Channels::Bit,
        omega_rpm: settings.omega_rpm,
        wob_kn: wob_n / 1e3,
        wob_from_record,
        duration_s,
        samples: n,
        noise_speed_rpm: Some(noise_variance[0].max(0.0).sqrt() / RAD_S_PER_RPM),
        noise_torque_knm: noise_variance[1].max(0.0).sqrt() / 1e3,
        noise_wob_kn: Some(noise_variance[2].max(0.0).sqrt() / 1e3),
    };
    let simulator = Simulator {
        settings,
        omega_rad_s,
        wob_n,
        duration_s,
        noise_variance,
        surface: None,
    };
    let mut notes = Vec::new();
    if wob_from_record {
        notes.push(format!(
            "the weight on the bit assembly is the record's mean weight on bit, {:.1} kN",
            wob_n / 1e3
        ));
    }

    // The laws' boxes around their fits to the turning samples.
    let turning: Vec<usize> = (0..n).filter(|&i| record.speed_rad_s[i] > STUCK_SPEED_RAD_S).collect();
    let calibration = Samples::new(
        turning.iter().map(|&i| record.speed_rad_s[i]).collect(),
        turning.iter().map(|&i| record.torque_nm[i]).collect(),
    );
    // A law the turning samples cannot fit (too few of them, too few speeds) or fit only
    // degenerately (a parameter beyond what a candidate holds) is left out, said.
    // One box per law in `structures()`' order, which lists the laws first.
    let mut left_out = Vec::new();
    let boxes: Vec<Option<LawBox>> = Law::ALL
        .into_iter()
        .map(|law| {
            let none = Samples::new(Vec::new(), Vec::new());
            let fitted = fit_laws(&[law], &calibration, &none, &FitOptions::default())
                .and_then(|fits| Prior::from_fits(&fits, LAW_DELTA, None, 1.0));
            match fitted {
                Ok(prior) => Some(prior.boxes[0].clone()),
                Err(e) => {
                    left_out.push(Structure::Torsional(law));
                    notes.push(format!(
                        "{law}: left out, the record's turning samples give its least-squares fit no box ({e})"
                    ));
                    None
                }
            }
        })
        .collect();
    let prepared = Prepared {
        observed: bit_summaries(&record.speed_rad_s, &record.torque_nm, &record.wob_n).to_vec(),
        names: &SUMMARIES,
        call_laws: true,
        simulator,
        laws: LawDraws::Fitted(boxes),
        torque_nm,
        drive,
        notes,
        left_out,
        source: record.source.clone(),
    };
    decide(prepared, note)
}

/// The structure a surface record shows: [`choice`] on the record's surface torque alone, its
/// top drive's mean speed the drive (refused where the speed strays more than
/// [`STEADY_TOP_DRIVE`] from it), `wob_kn` where given (the record's mean weight on bit
/// otherwise, refused where it has none), the record's clock the rate. Each law's
/// candidates are drawn from `bitrock surface`'s prior of it (its physical box, m4's cut to
/// its curves) and scaled to the record's mean torque at the drive, as the coupled bit's
/// friction is chosen; every torsional string starts from rest on the settings' string, the
/// coupled bit's from steady drilling kicked by `kick_rpm`, both settling `settle_s`.
pub fn surface_choice(record: &SurfaceRecord, settings: &Settings, note: &mut dyn FnMut(String)) -> Result<Choice> {
    check_settings(settings)?;
    let refuse = |message: String| refusal(&record.source, message);
    let n = record.len();
    refuse_long(n, &refuse)?;
    if n < 50 {
        return Err(refuse(format!(
            "the record holds {n} samples: its surface torque needs at least 50 to be summarised"
        )));
    }
    let omega_rad_s = record.mean_top_drive_rad_s();
    let rpm = |w: f64| w / RAD_S_PER_RPM;
    if !(omega_rad_s.is_finite() && omega_rad_s > 0.0) {
        return Err(refuse(format!(
            "its top drive turns at {:.2} rpm on average: the choice needs it turning forward",
            rpm(omega_rad_s)
        )));
    }
    let (lo, hi) = record
        .top_drive_rad_s
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), w| {
            (lo.min(*w), hi.max(*w))
        });
    if (hi - omega_rad_s).max(omega_rad_s - lo) > STEADY_TOP_DRIVE * omega_rad_s {
        return Err(refuse(format!(
            "its top drive turns from {:.1} to {:.1} rpm, more than {:.0} % from its mean {:.1} rpm: every candidate is simulated at one speed; give a stretch of steady drive",
            rpm(lo),
            rpm(hi),
            100.0 * STEADY_TOP_DRIVE,
            rpm(omega_rad_s)
        )));
    }
    let wob_from_record = settings.wob_kn.is_none();
    let wob_n = match (settings.wob_kn, &record.wob_n) {
        (Some(w), _) => w * 1e3,
        (None, Some(wob)) => wob.iter().sum::<f64>() / wob.len().max(1) as f64,
        (None, None) => {
            return Err(Error::setting(
                "wob_kn",
                format!(
                    "{} holds no weight on bit: give the weight on the bit assembly",
                    record.source.display()
                ),
            ));
        }
    };
    if !(wob_n.is_finite() && wob_n > 0.0) {
        return Err(refuse(format!(
            "its mean weight on bit is {:.3} kN: the bit is not pushed onto the rock",
            wob_n / 1e3
        )));
    }
    let period_s = record.sample_period_s;
    let settings = &Settings {
        omega_rpm: rpm(omega_rad_s),
        sample_hz: 1.0 / period_s,
        ..settings.clone()
    };
    let duration_s = record.duration_s();
    Schedule::new(settings.dt_s, settings.sample_hz, settings.settle_s, duration_s)?;
    let integration = Integration {
        dt_s: TORSIONAL_DT_S.min(period_s),
        settle_s: settings.settle_s,
    };
    let chain = Chain::one_dof(&settings.assembly()?.torsion);
    // The step is fixed here: a string it cannot resolve is too stiff for the choice.
    chain.check_step(integration.dt_s).map_err(|e| match e {
        Error::InvalidSetting { message, .. } => Error::setting(
            "omega_n_rad_s",
            format!(
                "the choice steps the torsional string at {} s, which cannot resolve it ({message}): give a softer or less damped string (`omega_n_rad_s`, `damping_ratio`)",
                integration.dt_s
            ),
        ),
        other => other,
    })?;
    let torque = &record.surface_torque_nm;
    let torque_nm = torque.iter().sum::<f64>() / n as f64;
    let noise_variance = vec![noise_variance_raw(torque)];
    let drive = ChoiceDrive {
        channels: Channels::Surface,
        omega_rpm: settings.omega_rpm,
        wob_kn: wob_n / 1e3,
        wob_from_record,
        duration_s,
        samples: n,
        noise_speed_rpm: None,
        noise_torque_knm: noise_variance[0].max(0.0).sqrt() / 1e3,
        noise_wob_kn: None,
    };
    let scales = physical_scales(record);
    let priors = Law::ALL
        .into_iter()
        .map(|law| Prior::physical(&[law], &scales, DEFAULT_PRIOR_SCALE, None, 1.0)?.with_curve_limits(&scales))
        .collect::<Result<Vec<Prior>>>()?;
    let mut notes = Vec::new();
    if wob_from_record {
        notes.push(format!(
            "the weight on the bit assembly is the record's mean weight on bit, {:.1} kN",
            wob_n / 1e3
        ));
    }
    let simulator = Simulator {
        settings,
        omega_rad_s,
        wob_n,
        duration_s,
        noise_variance,
        surface: Some(SurfaceStrings {
            chain,
            drive: Drive {
                omega_rad_s: vec![omega_rad_s; n],
                ratio: vec![1.0; n],
                period_s,
            },
            integration,
        }),
    };
    let prepared = Prepared {
        observed: surface_summaries(torque, period_s),
        names: &SURFACE_SUMMARIES,
        call_laws: false,
        simulator,
        laws: LawDraws::Scaled(priors),
        torque_nm,
        drive,
        notes,
        left_out: Vec::new(),
        source: record.source.clone(),
    };
    decide(prepared, note)
}

/// The choice from `prepared`: the table drawn and simulated, the structures' shares of the
/// candidates nearest the record, the check by re-simulation, the verdicts.
fn decide(prepared: Prepared<'_>, note: &mut dyn FnMut(String)) -> Result<Choice> {
    let Prepared {
        simulator,
        laws,
        torque_nm,
        observed,
        names: summary_names,
        call_laws,
        drive,
        mut notes,
        left_out,
        source,
    } = prepared;
    let settings = simulator.settings;
    // The coupled bit's candidates are stepped at `dt_s`: it must resolve the rock surface at
    // the record's drive.
    simulator.job(settings.bit).check_step(settings.dt_s)?;
    let structures = structures();
    let strings = (settings.reference as f64 + settings.replicates as f64) * structures.len() as f64;
    crate::limits::check_work(
        "reference",
        strings * (settings.settle_s + drive.duration_s) / settings.dt_s,
        crate::simulate::FASTEST_STEPS_PER_S,
        &format!(
            "simulating {strings} strings of {:.0} s",
            settings.settle_s + drive.duration_s
        ),
    )?;
    let refuse = |message: String| refusal(&source, message);

    // The table: each structure's candidates, drawn and simulated.
    let seed = settings.seed;
    let drawn: Vec<(usize, u64, Option<Vec<f64>>)> = (0..structures.len())
        .flat_map(|slot| (0..settings.reference as u64).map(move |i| (slot, i)))
        .collect::<Vec<_>>()
        .into_par_iter()
        .map(|(slot, i)| {
            let params = match structures[slot] {
                Structure::Torsional(law) => match &laws {
                    LawDraws::Fitted(boxes) => boxes[slot].as_ref().map(|bx| {
                        let key = key_of_seed(NoiseKey::replicate(seed ^ 0x4341_4e44, slot as u64).0);
                        let u = philox4x32_10(candidate_counter(0, i, 0), key);
                        let u2 = philox4x32_10(candidate_counter(0, i, 1), key);
                        let words = [u[0], u[1], u[2], u[3], u2[0], u2[1]];
                        (0..law.n_params())
                            .map(|j| {
                                let (lo, hi) = (f64::from(bx.lower[j]), f64::from(bx.upper[j]));
                                lo + open_unit(words[j]) * (hi - lo)
                            })
                            .collect()
                    }),
                    LawDraws::Scaled(priors) => {
                        let stream = NoiseKey::replicate(seed ^ 0x5355_5246, slot as u64).0;
                        simulator.surface_law_candidate(&priors[slot], stream, i, torque_nm)
                    }
                },
                Structure::Coupled => simulator.coupled_candidate(seed, i, torque_nm),
            };
            (slot, i, params)
        })
        .collect();
    // The coupled bit's candidates go to a core a few at a time, integrated side by side.
    let drawn_params: Vec<(usize, u64, Vec<f64>)> = drawn
        .into_iter()
        .filter_map(|(slot, i, params)| Some((slot, i, params?)))
        .collect();
    let chunks: Vec<&[(usize, u64, Vec<f64>)]> = drawn_params
        .chunk_by(|a, b| a.0 == b.0)
        .flat_map(|same| {
            let lanes = if structures[same[0].0] == Structure::Coupled {
                coupled::LANES
            } else {
                1
            };
            same.chunks(lanes)
        })
        .collect();
    let table: Vec<Member> = chunks
        .into_par_iter()
        .with_max_len(1)
        .flat_map_iter(|chunk| {
            let candidates: Vec<(&[f64], NoiseKey)> = chunk
                .iter()
                .map(|(slot, i, params)| {
                    let key = NoiseKey::replicate(seed ^ 0x5441_424c, (slot * settings.reference) as u64 + i);
                    (params.as_slice(), key)
                })
                .collect();
            let summaries = simulator.summaries_of(structures[chunk[0].0], &candidates);
            summaries
                .into_iter()
                .zip(chunk)
                .filter_map(|(summaries, (slot, _, params))| {
                    Some(Member {
                        slot: *slot,
                        params: params.clone(),
                        summaries: summaries?,
                    })
                })
                .collect::<Vec<_>>()
        })
        .collect();
    let counts: Vec<usize> = (0..structures.len())
        .map(|slot| table.iter().filter(|m| m.slot == slot).count())
        .collect();
    for (structure, count) in structures.iter().zip(&counts) {
        if *count < settings.reference && !left_out.contains(structure) {
            notes.push(format!(
                "{structure}: {count} of its {} candidates simulated (the rest {}: they cannot make the record, and count as rejected)",
                settings.reference,
                if *structure == Structure::Coupled {
                    "needed a friction outside the bit's bounds to make the record's mean torque, or diverged"
                } else {
                    "diverged"
                }
            ));
        }
    }
    if table.len() < 10 {
        return Err(refuse(format!(
            "only {} candidates could be simulated at {:.1} rpm and {:.1} kN",
            table.len(),
            settings.omega_rpm,
            drive.wob_kn
        )));
    }
    for line in &notes {
        note(line.clone());
    }

    // The choice: the structures' shares of the nearest candidates.
    let scales = scales(&table, structures.len());
    let k = (table.len() / 50).max(10).min(table.len());
    let accepted = nearest(&table, &observed, &scales, k, None);
    let shares: Vec<StructureShare> = structures
        .iter()
        .enumerate()
        .map(|(slot, &structure)| {
            let own: Vec<&Member> = accepted.iter().copied().filter(|m| m.slot == slot).collect();
            StructureShare {
                structure,
                probability: own.len() as f64 / k as f64,
                candidates: counts[slot],
                accepted: own.len(),
                estimates: estimates(structure, &own),
            }
        })
        .collect();

    // The check: records re-simulated from each structure's accepted candidates.
    let jobs: Vec<(usize, usize, &Member)> = (0..structures.len())
        .flat_map(|slot| {
            let own: Vec<&Member> = accepted.iter().copied().filter(|m| m.slot == slot).collect();
            let replicates = if own.is_empty() { 0 } else { settings.replicates };
            (0..replicates)
                .map(|r| (slot, r, own[r % own.len()]))
                .collect::<Vec<_>>()
        })
        .collect();
    let classes: Vec<(usize, Option<usize>)> = jobs
        .into_par_iter()
        .with_max_len(1)
        .map(|(slot, r, member)| {
            let key = NoiseKey::replicate(seed ^ 0x4348_4543, (slot * settings.replicates + r) as u64);
            let class = simulator
                .summaries(structures[slot], &member.params, key)
                .map(|s| classify(&table, &s, &scales, k, structures.len(), member));
            (slot, class)
        })
        .collect();
    let check: Vec<ChoiceCheckRow> = (0..structures.len())
        .filter(|&slot| shares[slot].accepted > 0)
        .map(|slot| {
            let own: Vec<usize> = classes.iter().filter(|c| c.0 == slot).filter_map(|c| c.1).collect();
            let count = |target: usize| own.iter().filter(|&&c| c == target).count();
            ChoiceCheckRow {
                structure: structures[slot],
                replicates: own.len(),
                diverged: settings.replicates - own.len(),
                classified_as: structures.iter().enumerate().map(|(t, &s)| (s, count(t))).collect(),
                recognised: count(slot) as f64 / own.len().max(1) as f64,
            }
        })
        .collect();
    // Ties go to the earlier structure, as in `classify`.
    let best = shares
        .iter()
        .rev()
        .max_by(|a, b| a.probability.total_cmp(&b.probability))
        .expect("a structure");
    let taken_for_best = |row: &ChoiceCheckRow| {
        let all: usize = row.classified_as.iter().map(|c| c.1).sum();
        let taken = row
            .classified_as
            .iter()
            .find(|c| c.0 == best.structure)
            .map_or(0, |c| c.1);
        taken as f64 / all.max(1) as f64
    };
    let confused: Vec<Structure> = check
        .iter()
        .filter(|r| r.structure != best.structure && taken_for_best(r) > CHECK_CONFUSED)
        .map(|r| r.structure)
        .collect();
    let recognised = check
        .iter()
        .find(|r| r.structure == best.structure)
        .map_or(0.0, |r| r.recognised);
    let (mut decided, mut verdict) =
        resimulation_verdict(best.structure, best.probability, recognised, &confused, "structure");
    let table_check = table_check(&table, &scales, k, &structures);
    let taken_in_table: Vec<(Structure, f64)> = table_check
        .iter()
        .filter(|r| r.structure != best.structure)
        .map(|r| (r.structure, taken_for_best(r)))
        .filter(|(_, share)| *share > CHECK_CONFUSED)
        .collect();
    if decided.is_some() && !taken_in_table.is_empty() {
        decided = None;
        verdict = table_verdict(best.structure, best.probability, &taken_in_table);
    }
    if decided.is_some() && best.probability < CALL_PROBABILITY {
        decided = None;
        verdict = weak_verdict(best.structure, best.probability);
    }
    // From the surface no law is called: one that passed every check is said not called
    // here, one that did not keeps its own reason.
    let not_here =
        "which law a surface record shows is `bitrock surface`'s to say (its sampler draws each law near the record)";
    if let (Structure::Torsional(law), false) = (best.structure, call_laws) {
        verdict = if decided.is_some() {
            format!("{law} leads (P = {:.2}): {not_here}; not called here", best.probability)
        } else {
            format!("{verdict} (and {not_here})")
        };
        decided = None;
    }
    // Each family's prior share: its structures' drawn candidates (a law left out drew none).
    let drawn = |family: Family| {
        structures
            .iter()
            .filter(|s| Family::of(**s) == family && !left_out.contains(s))
            .count() as f64
    };
    let torsional_prior = drawn(Family::Torsional) / (drawn(Family::Torsional) + drawn(Family::Coupled));
    let mut family = family_choice(&shares, &check, torsional_prior);
    if let Some(called) = family.decided {
        let other = match called {
            Family::Torsional => Family::Coupled,
            Family::Coupled => Family::Torsional,
        };
        let (mut members, mut taken) = (0, 0);
        for row in table_check.iter().filter(|r| Family::of(r.structure) == other) {
            members += row.replicates;
            taken += row
                .classified_as
                .iter()
                .filter(|c| Family::of(c.0) == called)
                .map(|c| c.1)
                .sum::<usize>();
        }
        let share = taken as f64 / members.max(1) as f64;
        let probability = match called {
            Family::Torsional => family.torsional_probability,
            Family::Coupled => 1.0 - family.torsional_probability,
        };
        if share > CHECK_CONFUSED {
            family.decided = None;
            family.verdict = table_verdict(called, probability, &[(other, share)]);
        } else if probability < CALL_PROBABILITY {
            family.decided = None;
            family.verdict = weak_verdict(called, probability);
        }
    }
    // A structure is called only within its family: a law's share of the accepted candidates
    // (each structure a fifth before the record) can reach the call while the families,
    // weighed half and half, leave the torsional one undecided.
    if let Some(structure) = decided
        && family.decided != Some(Family::of(structure))
    {
        decided = None;
        verdict = format!(
            "{structure} leads (P = {:.2}) and passes the checks, but whether the record shows {} is undecided: not called",
            best.probability,
            Family::of(structure)
        );
    }
    // A structure without a candidate was not compared: without the coupled bit, or without
    // any law, neither the structure nor the family is called; without some laws, the verdict
    // says among which it was made.
    let missing: Vec<Structure> = structures
        .iter()
        .zip(&counts)
        .filter(|(_, count)| **count == 0)
        .map(|(structure, _)| *structure)
        .collect();
    let names = |list: &[Structure]| list.iter().map(|s| s.to_string()).collect::<Vec<_>>().join(", ");
    let no_family = missing.contains(&Structure::Coupled) || counts[..Law::ALL.len()].iter().all(|c| *c == 0);
    if no_family {
        let why = format!(
            "{} had no candidate to compare (see the notes): undecided",
            names(&missing)
        );
        decided = None;
        verdict = why.clone();
        family.decided = None;
        family.verdict = why;
    } else if !missing.is_empty() {
        let compared: Vec<Structure> = structures.iter().copied().filter(|s| !missing.contains(s)).collect();
        verdict = format!(
            "{verdict} (among {}; {} could not be compared)",
            names(&compared),
            names(&missing)
        );
    }
    Ok(Choice {
        drive,
        record_summaries: summary_names.iter().copied().zip(observed).collect(),
        reference: table.len(),
        accepted: k,
        structures: shares,
        check,
        table_check,
        decided,
        verdict,
        family,
        notes,
    })
}

/// The table's own candidates classified as a record is ([`classify`], each left out of its
/// own vote), counted per structure as [`ChoiceCheckRow`]s.
fn table_check(table: &[Member], scales: &[f64], k: usize, structures: &[Structure]) -> Vec<ChoiceCheckRow> {
    let classes: Vec<usize> = table
        .par_iter()
        .map(|m| classify(table, &m.summaries, scales, k, structures.len(), m))
        .collect();
    (0..structures.len())
        .filter_map(|slot| {
            let own: Vec<usize> = table
                .iter()
                .zip(&classes)
                .filter(|(m, _)| m.slot == slot)
                .map(|(_, c)| *c)
                .collect();
            if own.is_empty() {
                return None;
            }
            let count = |target: usize| own.iter().filter(|&&c| c == target).count();
            Some(ChoiceCheckRow {
                structure: structures[slot],
                replicates: own.len(),
                diverged: 0,
                classified_as: structures.iter().enumerate().map(|(t, &s)| (s, count(t))).collect(),
                recognised: count(slot) as f64 / own.len() as f64,
            })
        })
        .collect()
}

/// The verdict on `best`, which passed the check near the record, where the table's own
/// candidates of other structures or families (`taken`: each with the share of its candidates
/// taken for `best`) are taken for it more often than [`CHECK_CONFUSED`]: the table's draws
/// near the record may have missed theirs, so nothing is called.
fn table_verdict<L: std::fmt::Display>(best: L, probability: f64, taken: &[(L, f64)]) -> String {
    let names: Vec<String> = taken.iter().map(|(l, _)| l.to_string()).collect();
    let most = taken.iter().map(|t| t.1).fold(0.0, f64::max);
    format!(
        "{best} leads (P = {probability:.2}) and passes the check near the record, but the table's own candidates of {} are taken for it too (up to {:.0} %): undecided between {best} and {}",
        names.join(", "),
        100.0 * most,
        names.join(", ")
    )
}

/// The verdict on `best`, which passed the checks, where its probability is below
/// [`CALL_PROBABILITY`].
fn weak_verdict<L: std::fmt::Display>(best: L, probability: f64) -> String {
    format!(
        "{best} leads (P = {probability:.2}) and passes the checks, but a call needs P of at least {CALL_PROBABILITY}: undecided"
    )
}

/// The choice between the families (see [`FamilyChoice`]): `torsional_prior` is the
/// torsional laws' share of the table's draws, divided out of their share of the accepted
/// candidates so that the families weigh the same before the record (four laws to one
/// coupled bit would otherwise make P(a torsional law) 0.8 of a record that tells nothing).
fn family_choice(shares: &[StructureShare], check: &[ChoiceCheckRow], torsional_prior: f64) -> FamilyChoice {
    let accepted_torsional: f64 = shares
        .iter()
        .filter(|s| Family::of(s.structure) == Family::Torsional)
        .map(|s| s.probability)
        .sum();
    let torsional_probability = if torsional_prior > 0.0 && torsional_prior < 1.0 {
        let torsional = accepted_torsional / torsional_prior;
        let coupled = (1.0 - accepted_torsional) / (1.0 - torsional_prior);
        torsional / (torsional + coupled)
    } else {
        accepted_torsional
    };
    // Of `from`'s re-simulated records, the share taken for a structure of `taken_for`: each
    // structure's rows weighted by its probability, as the family's records would be drawn.
    let probability = |structure: Structure| {
        shares
            .iter()
            .find(|s| s.structure == structure)
            .map_or(0.0, |s| s.probability)
    };
    let share = |from: Family, taken_for: Family| {
        let (mut weight, mut taken) = (0.0, 0.0);
        for row in check
            .iter()
            .filter(|r| Family::of(r.structure) == from && r.replicates > 0)
        {
            let w = probability(row.structure);
            let hits: usize = row
                .classified_as
                .iter()
                .filter(|c| Family::of(c.0) == taken_for)
                .map(|c| c.1)
                .sum();
            weight += w;
            taken += w * hits as f64 / row.replicates as f64;
        }
        (weight > 0.0).then(|| taken / weight)
    };
    let (best, probability, other) = if torsional_probability >= 0.5 {
        (Family::Torsional, torsional_probability, Family::Coupled)
    } else {
        (Family::Coupled, 1.0 - torsional_probability, Family::Torsional)
    };
    let confused: Vec<Family> = share(other, best)
        .filter(|s| *s > CHECK_CONFUSED)
        .map(|_| other)
        .into_iter()
        .collect();
    let (decided, verdict) =
        resimulation_verdict(best, probability, share(best, best).unwrap_or(0.0), &confused, "family");
    FamilyChoice {
        torsional_probability,
        torsional_recognised: share(Family::Torsional, Family::Torsional),
        coupled_recognised: share(Family::Coupled, Family::Coupled),
        decided,
        verdict,
    }
}

/// The medians of `members`' parameters, named (none without a member).
fn estimates(structure: Structure, members: &[&Member]) -> Vec<Estimate> {
    if members.is_empty() {
        return Vec::new();
    }
    let median = |j: usize| quantile(&members.iter().map(|m| m.params[j]).collect::<Vec<_>>(), 0.5);
    match structure {
        Structure::Torsional(law) => law
            .params()
            .iter()
            .enumerate()
            .map(|(j, p)| Estimate {
                name: p.name,
                unit: p.unit("N·m"),
                median: median(j),
            })
            .collect(),
        Structure::Coupled => COUPLED_PARAMETERS
            .iter()
            .enumerate()
            .map(|(j, (name, unit))| Estimate {
                name,
                unit: (*unit).to_string(),
                median: median(j),
            })
            .collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::prior::PhysicalScales;

    #[test]
    fn summaries_of_a_known_record_are_its_closed_forms() {
        // Half the samples stuck at 0 with 12 kN·m, half turning at 2 rad/s with 8 kN·m; the
        // weight on bit constant.
        let speed: Vec<f64> = (0..100).map(|i| if i % 2 == 0 { 0.0 } else { 2.0 }).collect();
        let torque: Vec<f64> = speed.iter().map(|w| if *w > 0.0 { 8e3 } else { 12e3 }).collect();
        let wob = vec![1.5e5; 100];
        let s = bit_summaries(&speed, &torque, &wob);
        let want = [0.5, 1.0, 2.0, 10e3, 2e3, 8e3, 12e3, 8e3, 12e3, -1.0, 0.0, 0.0];
        for ((name, got), want) in SUMMARIES.iter().zip(s).zip(want) {
            assert!(
                (got - want).abs() < 1e-9 * want.abs().max(1.0),
                "{name}: {got} for {want}"
            );
        }
    }

    #[test]
    fn a_re_simulation_is_classified_without_the_member_it_came_from() {
        let member = |slot: usize, x: f64| Member {
            slot,
            params: Vec::new(),
            summaries: vec![x; SUMMARIES.len()],
        };
        // The source (slot 0) sits on the re-simulation; slot 1's two members are next.
        let table = vec![member(0, 0.0), member(1, 1.0), member(1, 1.5), member(0, 5.0)];
        let scales = [1.0; SUMMARIES.len()];
        let s = [0.1; SUMMARIES.len()];
        assert_eq!(classify(&table, &s, &scales, 1, 2, &table[0]), 1);
        assert_eq!(nearest(&table, &s, &scales, 1, None)[0].slot, 0);
        // k beyond the table left is the whole of it.
        assert_eq!(nearest(&table, &s, &scales, 9, Some(&table[0])).len(), 3);
    }

    #[test]
    fn a_surface_choice_s_law_candidates_are_drawn_from_the_surface_prior_and_turn_at_the_record_s_torque() {
        // Each law's candidates, as a surface choice draws them at 45 rpm for a record whose
        // mean torque is 10 kN·m: the law's torque at the drive is that torque, the shape
        // (every parameter but the torques) is the prior's draw, and the scaling factor is
        // the one the draw's torque at the drive asks for.
        let settings = Settings::default();
        let omega_rad_s = 45.0 * RAD_S_PER_RPM;
        let simulator = Simulator {
            settings: &settings,
            omega_rad_s,
            wob_n: 150e3,
            duration_s: 60.0,
            noise_variance: vec![0.0],
            surface: None,
        };
        let scales = PhysicalScales {
            torque_max: 14e3,
            speed_low: 0.1 * omega_rad_s,
            speed_high: 3.0 * omega_rad_s,
        };
        for law in Law::ALL {
            let prior = Prior::physical(&[law], &scales, DEFAULT_PRIOR_SCALE, None, 1.0)
                .and_then(|p| p.with_curve_limits(&scales))
                .unwrap();
            let n = law.n_params();
            for i in 0..20 {
                let params = simulator.surface_law_candidate(&prior, 7, i, 10e3).unwrap();
                let torque = law.torque(&params, omega_rad_s, 1.0);
                assert!((torque - 10e3).abs() < 1e-9 * 10e3, "{law} #{i}: {torque} N·m");
                // The first draw of positive torque at the drive, scaled by one factor.
                let drawn = (0..MAX_ATTEMPTS)
                    .map(|attempt| prior.candidate(7, attempt, i))
                    .map(|c| c.params[..n].iter().map(|&v| f64::from(v)).collect::<Vec<f64>>())
                    .find(|p| law.torque(p, omega_rad_s, 1.0) > 0.0)
                    .unwrap();
                let factor = 10e3 / law.torque(&drawn, omega_rad_s, 1.0);
                assert!(factor > 0.0);
                for (j, spec) in law.params().iter().enumerate() {
                    let want = if spec.torque_power == 1 {
                        drawn[j] * factor
                    } else {
                        drawn[j]
                    };
                    assert!(
                        (params[j] - want).abs() <= 1e-12 * want.abs(),
                        "{law}.{}: {} for {want}",
                        spec.name,
                        params[j]
                    );
                }
            }
        }
    }

    #[test]
    fn a_surface_record_s_summaries_are_the_surface_sampler_s_torque_summaries() {
        let torque: Vec<f64> = (0..600).map(|i| 10e3 + 2e3 * (f64::from(i) * 0.8).sin()).collect();
        let all = summaries(&torque, 0.1, &[0.0; N_DOWNHOLE_SUMMARIES]);
        let ours = surface_summaries(&torque, 0.1);
        assert_eq!(ours.len(), SURFACE_SUMMARIES.len());
        assert_eq!(ours[..], all[..N_TORQUE_SUMMARIES]);
        assert_eq!(SURFACE_SUMMARIES[..], SUMMARY_NAMES[..N_TORQUE_SUMMARIES]);
        // The mean first, as named.
        assert_eq!(SURFACE_SUMMARIES[crate::simulate::surface::MEAN], "mean_nm");
        assert!((ours[crate::simulate::surface::MEAN] - 10e3).abs() < 20.0);
    }

    #[test]
    fn the_families_weigh_the_same_before_the_record() {
        // Four laws and the coupled bit, each with as many candidates: accepted shares of 0.8
        // for the laws together and 0.2 for the coupled bit are the table's own proportions,
        // a record that tells nothing (P = 1/2).
        let share = |structure: Structure, probability: f64| StructureShare {
            structure,
            probability,
            candidates: 100,
            accepted: 0,
            estimates: Vec::new(),
        };
        let shares = |laws: f64| {
            let mut v: Vec<StructureShare> = Law::ALL
                .into_iter()
                .map(|law| share(Structure::Torsional(law), laws / 4.0))
                .collect();
            v.push(share(Structure::Coupled, 1.0 - laws));
            v
        };
        let p = |laws: f64, prior: f64| family_choice(&shares(laws), &[], prior).torsional_probability;
        assert!((p(0.8, 0.8) - 0.5).abs() < 1e-12);
        // Odds (0.9/0.8)/(0.1/0.2) = 2.25: P = 2.25/3.25.
        assert!((p(0.9, 0.8) - 2.25 / 3.25).abs() < 1e-12);
        assert!((p(1.0, 0.8) - 1.0).abs() < 1e-12 && p(0.0, 0.8).abs() < 1e-12);
        // Three laws compared (one left out): their prior share is 3/4.
        assert!((p(0.75, 0.75) - 0.5).abs() < 1e-12);
        // Without a check nothing is recognised: nothing is called.
        assert_eq!(family_choice(&shares(1.0), &[], 0.8).decided, None);
    }

    #[test]
    fn the_table_check_counts_every_candidate_of_each_structure_once() {
        // Two structures in two clumps but for one member of slot 0 inside slot 1's: it is
        // taken for slot 1, every other member for its own.
        let member = |slot: usize, x: f64| Member {
            slot,
            params: Vec::new(),
            summaries: vec![x; 3],
        };
        let mut table: Vec<Member> = (0..12).map(|i| member(0, f64::from(i) * 0.01)).collect();
        table.extend((0..12).map(|i| member(1, 10.0 + f64::from(i) * 0.01)));
        table.push(member(0, 10.05));
        let structures = [Structure::Torsional(Law::ALL[0]), Structure::Coupled];
        let rows = table_check(&table, &[1.0; 3], 3, &structures);
        assert_eq!(rows.len(), 2);
        assert_eq!((rows[0].replicates, rows[1].replicates), (13, 12));
        assert_eq!(rows[0].classified_as, vec![(structures[0], 12), (structures[1], 1)]);
        assert_eq!(rows[1].classified_as, vec![(structures[0], 0), (structures[1], 12)]);
        assert!((rows[0].recognised - 12.0 / 13.0).abs() < 1e-12);
    }

    #[test]
    fn a_record_longer_than_a_string_records_and_a_step_that_cannot_resolve_the_rock_are_refused() {
        // Records as a rig writes them: `rows` samples of a turning bit.
        let dir = tempfile::tempdir().unwrap();
        let record = |name: &str, rows: usize| {
            let path = dir.path().join(name);
            let mut text = String::from("bit_speed_rpm,torque_knm,wob_kn\n");
            for i in 0..rows {
                text.push_str(&format!("{},10,150\n", 57 + i % 7));
            }
            std::fs::write(&path, text).unwrap();
            DrillingRecord::read(&path, &Default::default()).unwrap()
        };
        let settings = Settings {
            omega_rpm: 60.0,
            ..Settings::default()
        };
        let long = record("long.csv", crate::simulate::strings::MAX_SAMPLES as usize + 1);
        let e = choice(&long, &settings, &mut |_| {}).unwrap_err().to_string();
        assert!(e.contains("long.csv") && e.contains("65536 samples"), "{e}");
        // A minute at 50 Hz, with the coupled bit's step too coarse at 60 rpm: refused by that
        // setting before any string is simulated.
        let minute = record("minute.csv", 3000);
        let coarse = Settings { dt_s: 0.01, ..settings };
        match choice(&minute, &coarse, &mut |_| {}) {
            Err(Error::InvalidSetting { field, message }) => {
                assert_eq!(field, "dt_s", "{message}");
                assert!(message.contains("rock surface is not resolved"), "{message}");
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn a_structure_is_named_as_the_user_writes_it() {
        assert_eq!(Structure::Torsional(Law::ALL[1]).to_string(), "m2");
        assert_eq!(serde_json::to_string(&Structure::Coupled).unwrap(), "\"RGD\"");
    }
}
