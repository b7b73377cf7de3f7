//! Stick-slip maps by simulation and the advice drawn from them: for every posterior sample and
//! every cell of an (Ω, W) grid, a drill string integrated in time ([`crate::eval::strings`]).
//!
//! - **Onset**: from steady rotation at the cell, kicked by a share of Ω: does stick-slip
//!   develop? The simulated counterpart of the linear criterion, which it refines where the
//!   kick is large enough to reach the cycle's basin.
//! - **Escape**: from the state the bit is in at the operating point (the string started from
//!   rest there, settled into its cycle or its steady rotation), the top drive moved to the
//!   cell: does stick-slip persist? The driller's question.
//! - The **bistable band**: cells where steady rotation survives the kick but the cycle
//!   persists: stick-slip is not started there, but once in it the bit stays in it.
//!
//! A cell's probability weighs each law's samples by the law's probability (the mixture of
//! laws); a cell where any sample's string diverged is unknown (NaN), never stable.

use crate::error::{Error, Result};
use crate::eval::Backend;
use crate::eval::strings::Ran;
use crate::eval::surface::InferredString;
use crate::run::stability::Structure;
use crate::simulate::strings::{Chain, MAX_NODES, Schedule, StringJob, StringState, Summary, padded, steady_start};
use crate::stability::fe::DrillStringSettings;
use crate::stability::lumped::Lumped;
use crate::stability::map::LawSamples;
use crate::units::RAD_S_PER_RPM;

/// The integration step of the maps (s): step-size independent to the third decimal of the
/// stuck share on the paper's strings (1 ms to 20 ms, measured in the tests).
pub const DEFAULT_DT_S: f64 = 0.01;
/// The kick of the onset maps: a tenth of Ω added to the bit speed.
pub const DEFAULT_KICK: f64 = 0.1;
/// Time the string at the operating point settles from rest into its cycle (s).
pub const DEFAULT_SETTLE_S: f64 = 60.0;
/// Time after a change before the verdict window (s): the transient of a bit leaving its cycle.
pub const DEFAULT_TRANSIENT_S: f64 = 40.0;
/// The verdict window (s): stick-slip persists if the bit is stuck in it at least
/// [`crate::simulate::strings::STICK_SLIP_STUCK_SHARE`] of the time.
pub const DEFAULT_VERDICT_S: f64 = 20.0;
/// The simulated maps' grid of top-drive speeds, rpm, as MIN:MAX:COUNT.
pub const DEFAULT_OMEGA_RPM: &str = "20:220:21";
/// The simulated maps' grid of weights on bit, kN, as MIN:MAX:COUNT.
pub const DEFAULT_WOB_KN: &str = "20:700:18";
/// Posterior samples per law simulated in every cell.
pub const DEFAULT_SAMPLES: usize = 50;
/// Summary samples per second of simulated time.
const SAMPLE_HZ: f64 = 50.0;
/// Probability of ending stick-slip that advice asks of a change.
pub const ADVICE_CONFIDENCE: f64 = 0.9;
/// Strings per batch on the CPU: progress is said between batches.
const CPU_BATCH: usize = 2048;
/// Strings per batch on a GPU.
const GPU_BATCH: usize = 1 << 20;
/// Most string-steps any machine integrates per second: the day's-work bound is a lower one.
const FASTEST_STRING_STEPS_PER_S: f64 = 1e12;

/// How the simulated maps are made.
#[derive(Clone, Debug, PartialEq)]
pub struct SimulatedSettings {
    /// The string every sample is simulated on (where `string` is set, the samples' strings
    /// replace it).
    pub chain: Chain,
    /// Where the posterior inferred the string with the law: each sample carries its string's
    /// coordinates [ω_n, ξ] after its law's parameters and is simulated on its own 1-DOF string
    /// (the strings a record allows differ in where stick-slip ends, not only the laws).
    pub string: Option<InferredString>,
    /// Integration step (s).
    pub dt_s: f64,
    /// The onset maps' kick, a share of Ω.
    pub kick: f64,
    pub settle_s: f64,
    pub transient_s: f64,
    pub verdict_s: f64,
    /// Reference weight on bit W_ref of the laws' parameters (N).
    pub w_ref_n: f64,
    pub backend: Backend,
}

impl SimulatedSettings {
    /// The defaults on `chain`, for parameters referred to `w_ref_n`.
    pub fn new(chain: Chain, w_ref_n: f64, backend: Backend) -> Self {
        Self {
            chain,
            string: None,
            dt_s: DEFAULT_DT_S,
            kick: DEFAULT_KICK,
            settle_s: DEFAULT_SETTLE_S,
            transient_s: DEFAULT_TRANSIENT_S,
            verdict_s: DEFAULT_VERDICT_S,
            w_ref_n,
            backend,
        }
    }

    /// Refuses, naming the setting, a step the string's fastest mode forbids and durations
    /// that are not positive.
    pub fn validate(&self) -> Result<()> {
        self.chain.check_step(self.dt_s)?;
        if !(self.kick.is_finite() && self.kick >= 0.0) {
            return Err(Error::setting(
                "kick",
                format!("must be a share of Ω ≥ 0, got {}", self.kick),
            ));
        }
        if !(self.w_ref_n.is_finite() && self.w_ref_n > 0.0) {
            return Err(Error::setting(
                "w_ref_kn",
                format!("must be positive, got {}", self.w_ref_n / 1000.0),
            ));
        }
        self.after_change()?;
        self.settling(0.0)?;
        Ok(())
    }

    /// The schedule after a change: the transient, then the verdict window.
    fn after_change(&self) -> Result<Schedule> {
        Schedule::new(self.dt_s, SAMPLE_HZ, self.transient_s, self.verdict_s)
    }

    /// The schedule of the operating point's settling, lengthened by `extra_s` (the phase of
    /// the cycle the change meets).
    fn settling(&self, extra_s: f64) -> Result<Schedule> {
        Schedule::new(self.dt_s, SAMPLE_HZ, self.settle_s + extra_s, self.verdict_s)
    }
}

/// Where the rig is: top-drive speed (rpm) and weight on bit (kN).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OperatingPoint {
    pub omega_rpm: f64,
    pub wob_kn: f64,
}

/// One weighted string model: a law's sample and its weight in the mixture.
#[derive(Clone, Debug)]
struct Member {
    law: crate::laws::Law,
    params_nm: [f64; 6],
    weight: f64,
    /// Its string: an index into the simulator's chains.
    chain: usize,
}

/// The mixture's members, each law's samples each weighing its law's probability over its
/// sample count, and the strings they are simulated on: `settings.chain` alone, or, where
/// the settings infer the string, each sample's own, one chain per distinct string (refused,
/// naming the setting, where a sample lacks its string's coordinates or its string's fastest
/// mode forbids the step).
fn members(settings: &SimulatedSettings, inputs: &[LawSamples]) -> Result<(Vec<Member>, Vec<Chain>)> {
    let total: f64 = inputs.iter().map(|i| i.probability).sum();
    let mut members = Vec::new();
    let mut chains = vec![settings.chain.clone()];
    for input in inputs
        .iter()
        .filter(|i| !i.samples_si.is_empty() && i.probability > 0.0)
    {
        let weight = input.probability / total / input.samples_si.len() as f64;
        for (k, p) in input.samples_si.iter().enumerate() {
            let chain = match &settings.string {
                None => 0,
                Some(inferred) => {
                    let Some(coordinates) = input.strings.get(k) else {
                        return Err(Error::setting(
                            "string",
                            format!(
                                "{} samples of {} carry their string's ω_n and ξ, of {}: each sample's is needed where the string was inferred",
                                input.strings.len(),
                                input.law,
                                input.samples_si.len()
                            ),
                        ));
                    };
                    let own = Chain::one_dof(&inferred.lumped(coordinates));
                    match chains.iter().position(|c| *c == own) {
                        Some(same) => same,
                        None => {
                            own.check_step(settings.dt_s)?;
                            chains.push(own);
                            chains.len() - 1
                        }
                    }
                }
            };
            members.push(Member {
                law: input.law,
                params_nm: padded(p),
                weight,
                chain,
            });
        }
    }
    Ok((members, chains))
}

/// Each law of `inputs` at least `min_probability` probable, with at most `count` of its
/// samples, evenly spaced: the strings simulated per cell cost in proportion.
pub fn thinned(inputs: &[LawSamples], count: usize, min_probability: f64) -> Vec<LawSamples> {
    inputs
        .iter()
        .filter(|i| i.probability >= min_probability)
        .map(|i| {
            let step = i.samples_si.len().div_ceil(count.max(1)).max(1);
            LawSamples {
                samples_si: i.samples_si.iter().step_by(step).cloned().collect(),
                strings: i.strings.iter().step_by(step).copied().collect(),
                ..i.clone()
            }
        })
        .collect()
}

/// Phases each member's cycle is met at: enough that a cell weighs at least 16 strings, at
/// most 8.
pub fn phases(members: usize) -> usize {
    16usize.div_ceil(members.max(1)).clamp(1, 8)
}

/// The axis an advice's scan runs along.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Axis {
    Speed,
    Weight,
}

/// Probabilities over a grid, row-major over (Ω, W): NaN where any member's string diverged.
#[derive(Clone, Debug, PartialEq)]
pub struct Grid {
    pub omega_rpm: Vec<f64>,
    pub wob_kn: Vec<f64>,
    pub probability: Vec<f64>,
    /// Per cell, the mixture's weight of the strings that stick-slipped and stayed in bounds:
    /// the probability where none diverged, its lower bound where some did.
    pub stick_slip_weight: Vec<f64>,
    /// Per cell, the mixture's weight of the strings that diverged (left physical bounds).
    pub diverged_weight: Vec<f64>,
    /// Strings that diverged (their cells unknown).
    pub diverged: usize,
}

impl Grid {
    /// Parts of one scan joined in order: along the speeds at the one weight `at` (kN), or
    /// along the weights at the one speed `at` (rpm).
    fn joined(parts: Vec<Grid>, along: Axis, at: f64) -> Grid {
        let (omega_rpm, wob_kn) = match along {
            Axis::Speed => (Vec::new(), vec![at]),
            Axis::Weight => (vec![at], Vec::new()),
        };
        let mut out = Grid {
            omega_rpm,
            wob_kn,
            probability: Vec::new(),
            stick_slip_weight: Vec::new(),
            diverged_weight: Vec::new(),
            diverged: 0,
        };
        for part in parts {
            match along {
                Axis::Speed => out.omega_rpm.extend(part.omega_rpm),
                Axis::Weight => out.wob_kn.extend(part.wob_kn),
            }
            out.probability.extend(part.probability);
            out.stick_slip_weight.extend(part.stick_slip_weight);
            out.diverged_weight.extend(part.diverged_weight);
            out.diverged += part.diverged;
        }
        out
    }

    /// The probability at speed index `i` and weight index `j`.
    pub fn at(&self, i: usize, j: usize) -> f64 {
        self.probability[i * self.wob_kn.len() + j]
    }

    /// Per speed, the lightest weight on bit at which the probability reaches `p` (`None`: none
    /// on the grid; NaN: unknown). A cell with strings that left physical bounds holds a
    /// probability between its stick-slipping strings' weight and that plus theirs: it reaches
    /// `p` when the lower bound does, and is unknown only when the bounds straddle `p`.
    pub fn boundary_wob_kn(&self, p: f64) -> Vec<Option<f64>> {
        let n = self.wob_kn.len();
        (0..self.omega_rpm.len())
            .map(|i| {
                (0..n).find_map(|j| {
                    let lower = self.stick_slip_weight[i * n + j];
                    let upper = lower + self.diverged_weight[i * n + j];
                    if lower >= p {
                        Some(self.wob_kn[j])
                    } else if upper >= p {
                        Some(f64::NAN)
                    } else {
                        None
                    }
                })
            })
            .collect()
    }
}

/// The string the strings are simulated on: the 1-DOF model `lumped`, or the finite-element
/// string `fe` describes, lumped.
pub fn chain(structure: Structure, lumped: &Lumped, fe: &DrillStringSettings) -> Result<Chain> {
    match structure {
        Structure::Lumped => {
            lumped.validate()?;
            Ok(Chain::one_dof(lumped))
        }
        Structure::Fe => Chain::lumped_fe(&fe.drill_string()?),
    }
}

/// The simulated maps of a posterior: what `stability --simulate` and Python's
/// `stability(simulate=True)` ask for.
#[derive(Clone, Debug)]
pub struct SimulatedJob {
    pub settings: SimulatedSettings,
    /// The grid, rpm and kN.
    pub omega_rpm: Vec<f64>,
    pub wob_kn: Vec<f64>,
    /// Posterior samples per law simulated in every cell.
    pub samples: usize,
    /// Where the bit is now: the escape map and the advice start there.
    pub at: Option<OperatingPoint>,
}

/// The maps of a [`SimulatedJob`].
#[derive(Clone, Debug)]
pub struct SimulatedMaps {
    pub onset: Grid,
    /// The escape map and the advice, where the job has an operating point.
    pub escape: Option<(Grid, EscapeAdvice)>,
    /// Strings integrated, their simulated seconds, the wall time and where they ran.
    pub strings: u64,
    pub simulated_s: f64,
    pub wall_s: f64,
    pub ran: Option<Ran>,
}

impl SimulatedJob {
    /// Refuses, naming the setting, what cannot be simulated.
    pub fn validate(&self) -> Result<()> {
        if self.samples == 0 {
            return Err(Error::setting("sim_samples", "must be at least 1"));
        }
        if let Some(at) = self.at {
            for (field, v) in [("at_rpm", at.omega_rpm), ("at_kn", at.wob_kn)] {
                if !(v.is_finite() && v > 0.0) {
                    return Err(Error::setting(field, format!("must be positive, got {v}")));
                }
            }
        }
        self.settings.validate()
    }

    /// The maps of `inputs` (each law's samples thinned to the job's count).
    pub fn run(&self, inputs: &[LawSamples], note: &mut dyn FnMut(String)) -> Result<SimulatedMaps> {
        self.validate()?;
        let inputs = thinned(inputs, self.samples, 0.0);
        let started = std::time::Instant::now();
        let mut sim = Simulator::new(&self.settings, &inputs, note)?;
        let onset = sim.onset(&self.omega_rpm, &self.wob_kn)?;
        let escape = match self.at {
            Some(at) => {
                let state = sim.at_point(at)?;
                let grid = sim.escape(&state, &self.omega_rpm, &self.wob_kn)?;
                let advice =
                    sim.escape_advice(&state, &advice_speeds_rpm(at.omega_rpm), &advice_weights_kn(at.wob_kn))?;
                Some((grid, advice))
            }
            None => None,
        };
        Ok(SimulatedMaps {
            onset,
            escape,
            strings: sim.strings,
            simulated_s: sim.simulated_s,
            wall_s: started.elapsed().as_secs_f64(),
            ran: sim.ran.clone(),
        })
    }
}

/// The state the bit is in at the operating point, per member and phase (settled from rest).
pub struct AtPoint {
    pub point: OperatingPoint,
    /// P(stick-slip at the operating point) under the mixture.
    pub stick_slip_probability: f64,
    /// The members, each once per phase.
    replicas: Vec<Member>,
    /// Their states when the driller changes something.
    states: Vec<StringState>,
    /// Their peak bit speeds (rpm) settled there; `None` for a string that left bounds.
    replica_peaks: Vec<Option<f64>>,
    /// Whether each stick-slips there.
    replica_stick_slips: Vec<bool>,
}

impl AtPoint {
    /// The settled strings' peak bit speeds there (rpm), each with its weight in the mixture,
    /// of the strings that stayed in bounds: what the posterior says the bit's cycle looks like.
    pub fn peaks(&self) -> Peaks {
        Peaks(
            self.replica_peaks
                .iter()
                .zip(&self.replicas)
                .filter_map(|(p, m)| p.map(|p| (p, m.weight)))
                .collect(),
        )
    }

    /// The strings whose settled peak bit speed lies within `tolerance` (a share) of
    /// `seen_rpm`, their weights scaled to one: the posterior conditioned on the cycle the
    /// bit was seen in. `None` where no string reproduces it.
    pub fn reproducing(&self, seen_rpm: f64, tolerance: f64) -> Option<AtPoint> {
        let keep: Vec<usize> = (0..self.replicas.len())
            .filter(|&i| self.replica_peaks[i].is_some_and(|v| near(v, seen_rpm, tolerance)))
            .collect();
        let total = keep.iter().fold(0.0, |sum, &i| sum + self.replicas[i].weight);
        if keep.is_empty() || total <= 0.0 {
            return None;
        }
        let replicas: Vec<Member> = keep
            .iter()
            .map(|&i| Member {
                weight: self.replicas[i].weight / total,
                ..self.replicas[i].clone()
            })
            .collect();
        let replica_peaks: Vec<Option<f64>> = keep.iter().map(|&i| self.replica_peaks[i]).collect();
        let replica_stick_slips: Vec<bool> = keep.iter().map(|&i| self.replica_stick_slips[i]).collect();
        Some(AtPoint {
            point: self.point,
            stick_slip_probability: replicas
                .iter()
                .zip(&replica_stick_slips)
                .filter(|(_, s)| **s)
                .fold(0.0, |p, (m, _)| p + m.weight)
                .min(1.0),
            states: keep.iter().map(|&i| self.states[i]).collect(),
            replicas,
            replica_peaks,
            replica_stick_slips,
        })
    }
}

/// Whether the peak `v` lies within `tolerance` (a share) of `seen`.
fn near(v: f64, seen: f64, tolerance: f64) -> bool {
    (v - seen).abs() <= tolerance * seen.abs()
}

/// Peak bit speeds of simulated strings (rpm), each with its weight in the mixture.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Peaks(pub Vec<(f64, f64)>);

impl Peaks {
    /// The lowest and the highest peak; `None` without a string.
    pub fn range(&self) -> Option<(f64, f64)> {
        self.0.iter().fold(None, |range, (v, _)| {
            Some(range.map_or((*v, *v), |(lo, hi): (f64, f64)| (lo.min(*v), hi.max(*v))))
        })
    }

    /// The share of the weight whose peak lies within `tolerance` (a share) of `seen_rpm`.
    pub fn share_within(&self, seen_rpm: f64, tolerance: f64) -> f64 {
        let weight =
            |near: &dyn Fn(f64) -> bool| self.0.iter().filter(|(v, _)| near(*v)).fold(0.0, |sum, (_, w)| sum + w);
        let total = weight(&|_| true);
        if total <= 0.0 {
            return 0.0;
        }
        weight(&|v| near(v, seen_rpm, tolerance)) / total
    }
}

/// Every simulated map of a posterior.
pub struct Simulator<'a> {
    settings: &'a SimulatedSettings,
    members: Vec<Member>,
    /// The strings the members are simulated on ([`Member::chain`]).
    chains: Vec<Chain>,
    note: &'a mut dyn FnMut(String),
    /// Where the next batch goes: the settings' backend until `auto` has once settled on the
    /// CPU (said once, not per batch).
    backend: Backend,
    /// Where the last batch ran.
    pub ran: Option<Ran>,
    /// Strings integrated so far, and their simulated seconds.
    pub strings: u64,
    pub simulated_s: f64,
}

impl<'a> Simulator<'a> {
    /// The mixture of `inputs` on `settings`, checked.
    pub fn new(
        settings: &'a SimulatedSettings,
        inputs: &[LawSamples],
        note: &'a mut dyn FnMut(String),
    ) -> Result<Self> {
        settings.validate()?;
        let (members, chains) = members(settings, inputs)?;
        if members.is_empty() {
            return Err(Error::setting("samples", "no posterior sample to simulate"));
        }
        Ok(Self {
            settings,
            members,
            chains,
            note,
            backend: settings.backend,
            ran: None,
            strings: 0,
            simulated_s: 0.0,
        })
    }

    /// The member's string at (`omega_rpm`, `wob_kn`) from `start`, or kicked from steady
    /// rotation there.
    fn job(&self, m: &Member, omega_rpm: f64, wob_kn: f64, start: Option<StringState>) -> StringJob {
        let omega = omega_rpm * RAD_S_PER_RPM;
        let ratio = wob_kn * 1000.0 / self.settings.w_ref_n;
        let start = start.unwrap_or_else(|| {
            steady_start(
                &self.chains[m.chain],
                m.law,
                &m.params_nm,
                omega,
                ratio,
                self.settings.kick * omega,
            )
        });
        StringJob {
            law: m.law,
            params_nm: m.params_nm,
            omega_rad_s: omega,
            ratio,
            start,
        }
    }

    /// Integrates `jobs` (job `i` on the string `keys[i]` indexes) in batches on the settings'
    /// backend, one string's jobs at a time, saying the progress of long runs; the results in
    /// the jobs' order. Jobs all on one string go as they are, uncopied.
    fn integrate(
        &mut self,
        schedule: &Schedule,
        jobs: &[StringJob],
        keys: &[usize],
    ) -> Result<Vec<(Summary, StringState)>> {
        let steps = jobs.len() as f64 * schedule.steps() as f64;
        crate::limits::check_work(
            "sim_omega_rpm",
            steps,
            FASTEST_STRING_STEPS_PER_S,
            &format!("simulating {} strings of {} s", jobs.len(), schedule.seconds()),
        )?;
        let start = std::time::Instant::now();
        let mut last = start;
        let mut out: Vec<Option<(Summary, StringState)>> = vec![None; jobs.len()];
        let mut done = 0;
        let batch = if self.backend == Backend::Cpu {
            CPU_BATCH
        } else {
            GPU_BATCH
        };
        let one_string = keys.windows(2).all(|w| w[0] == w[1]);
        let mut order: Vec<usize> = (0..jobs.len()).collect();
        if !one_string {
            order.sort_by_key(|&i| keys[i]);
        }
        let parts = order
            .chunk_by(|&a, &b| keys[a] == keys[b])
            .flat_map(|same| same.chunks(batch));
        for part in parts {
            let chain = &self.chains[keys[part[0]]];
            // On one string the order is the jobs' own: each part is a run of them.
            let gathered: Vec<StringJob>;
            let part_jobs = if one_string {
                &jobs[part[0]..part[0] + part.len()]
            } else {
                gathered = part.iter().map(|&i| jobs[i].clone()).collect();
                &gathered
            };
            let (results, ran) = crate::eval::strings::integrate(chain, schedule, part_jobs, self.backend, self.note)?;
            if ran == Ran::Cpu {
                self.backend = Backend::Cpu;
            }
            self.ran = Some(ran);
            for (&i, result) in part.iter().zip(results) {
                out[i] = Some(result);
            }
            done += part.len();
            let elapsed = start.elapsed().as_secs_f64();
            if elapsed > 2.0 && last.elapsed().as_secs_f64() >= 10.0 {
                last = std::time::Instant::now();
                let done = done as f64 / jobs.len() as f64;
                (self.note)(format!(
                    "simulated strings: {:.0} % of {} after {} (about {} to go)",
                    100.0 * done,
                    jobs.len(),
                    crate::limits::human_seconds(elapsed),
                    crate::limits::human_seconds(elapsed * (1.0 - done) / done.max(1e-9))
                ));
            }
        }
        self.strings += jobs.len() as u64;
        self.simulated_s += jobs.len() as f64 * schedule.seconds();
        Ok(out.into_iter().map(|r| r.expect("every job is in a part")).collect())
    }

    /// The strings of `count` jobs laid out cell-major over `members` (members inner).
    fn keys(members: &[Member], count: usize) -> Vec<usize> {
        members.iter().map(|m| m.chain).cycle().take(count).collect()
    }

    /// Weighted probability of stick-slip over the members, cell by cell, on the grid
    /// (`omega_rpm`, `wob_kn`): `summaries` is cell-major, members inner.
    fn grid(members: &[Member], summaries: &[Summary], omega_rpm: &[f64], wob_kn: &[f64]) -> Grid {
        let n = members.len();
        let cells = omega_rpm.len() * wob_kn.len();
        let mut grid = Grid {
            omega_rpm: omega_rpm.to_vec(),
            wob_kn: wob_kn.to_vec(),
            probability: Vec::with_capacity(cells),
            stick_slip_weight: Vec::with_capacity(cells),
            diverged_weight: Vec::with_capacity(cells),
            diverged: 0,
        };
        for cell in summaries.chunks(n).take(cells) {
            let weight_of = |keep: &dyn Fn(&Summary) -> bool| {
                cell.iter()
                    .zip(members)
                    .filter(|(s, _)| keep(s))
                    .fold(0.0, |p, (_, m)| p + m.weight)
                    .min(1.0)
            };
            let stick_slip = weight_of(&|s| s.stick_slips());
            let diverged = weight_of(&|s| s.diverged);
            grid.diverged += cell.iter().filter(|s| s.diverged).count();
            grid.probability
                .push(if diverged > 0.0 { f64::NAN } else { stick_slip });
            grid.stick_slip_weight.push(stick_slip);
            grid.diverged_weight.push(diverged);
        }
        grid
    }

    /// The onset map: P(stick-slip develops from steady rotation kicked) per cell.
    pub fn onset(&mut self, omega_rpm: &[f64], wob_kn: &[f64]) -> Result<Grid> {
        let schedule = self.settings.after_change()?;
        let mut jobs = Vec::with_capacity(omega_rpm.len() * wob_kn.len() * self.members.len());
        for &o in omega_rpm {
            for &w in wob_kn {
                jobs.extend(self.members.iter().map(|m| self.job(m, o, w, None)));
            }
        }
        let keys = Self::keys(&self.members, jobs.len());
        let summaries: Vec<Summary> = self
            .integrate(&schedule, &jobs, &keys)?
            .into_iter()
            .map(|r| r.0)
            .collect();
        Ok(Self::grid(&self.members, &summaries, omega_rpm, wob_kn))
    }

    /// Each member's string at the operating point, started from rest (a bit on bottom at the
    /// start of rotation: the cycle's basin where the cycle exists) and settled. A change meets
    /// the cycle at any phase, and near the escape boundary the phase decides: each member is
    /// settled [`phases`] times, for lengths spread over one period of its string's fundamental
    /// mode, and the probabilities weigh the phases alike.
    pub fn at_point(&mut self, point: OperatingPoint) -> Result<AtPoint> {
        let rest = StringState {
            lag_rad: [0.0; MAX_NODES],
            speed_rad_s: [0.0; MAX_NODES],
            stuck: true,
        };
        let phases = phases(self.members.len());
        let replicas: Vec<Member> = self
            .members
            .iter()
            .flat_map(|m| {
                (0..phases).map(move |_| Member {
                    weight: m.weight / phases as f64,
                    ..m.clone()
                })
            })
            .collect();
        let mut summaries = vec![Summary::default(); replicas.len()];
        let mut states = vec![rest; replicas.len()];
        let periods_s: Vec<f64> = self
            .chains
            .iter()
            .map(|chain| 2.0 * std::f64::consts::PI / chain.fundamental_rad_s())
            .collect();
        for (c, period_s) in periods_s.into_iter().enumerate() {
            for phase in 0..phases {
                let schedule = self.settings.settling(period_s * phase as f64 / phases as f64)?;
                let idx: Vec<usize> = (phase..replicas.len())
                    .step_by(phases)
                    .filter(|&i| replicas[i].chain == c)
                    .collect();
                if idx.is_empty() {
                    continue;
                }
                let jobs: Vec<StringJob> = idx
                    .iter()
                    .map(|&i| self.job(&replicas[i], point.omega_rpm, point.wob_kn, Some(rest)))
                    .collect();
                for (k, (s, state)) in self
                    .integrate(&schedule, &jobs, &vec![c; jobs.len()])?
                    .into_iter()
                    .enumerate()
                {
                    summaries[idx[k]] = s;
                    states[idx[k]] = state;
                }
            }
        }
        let here = Self::grid(&replicas, &summaries, &[point.omega_rpm], &[point.wob_kn]);
        let replica_peaks: Vec<Option<f64>> = summaries
            .iter()
            .map(|s| (!s.diverged && s.samples > 0).then(|| s.speed_max_rad_s / RAD_S_PER_RPM))
            .collect();
        Ok(AtPoint {
            point,
            stick_slip_probability: here.probability[0],
            replica_stick_slips: summaries.iter().map(Summary::stick_slips).collect(),
            replicas,
            states,
            replica_peaks,
        })
    }

    /// The escape map: from the state at the operating point, P(stick-slip persists) once the
    /// top drive is at each cell's Ω and the weight on bit at its W.
    pub fn escape(&mut self, from: &AtPoint, omega_rpm: &[f64], wob_kn: &[f64]) -> Result<Grid> {
        let schedule = self.settings.after_change()?;
        let mut jobs = Vec::with_capacity(omega_rpm.len() * wob_kn.len() * from.replicas.len());
        for &o in omega_rpm {
            for &w in wob_kn {
                jobs.extend(
                    from.replicas
                        .iter()
                        .zip(&from.states)
                        .map(|(m, s)| self.job(m, o, w, Some(*s))),
                );
            }
        }
        let keys = Self::keys(&from.replicas, jobs.len());
        let summaries: Vec<Summary> = self
            .integrate(&schedule, &jobs, &keys)?
            .into_iter()
            .map(|r| r.0)
            .collect();
        Ok(Self::grid(&from.replicas, &summaries, omega_rpm, wob_kn))
    }

    /// What ends stick-slip from the operating point: the nearest top-drive speed above it (at
    /// the same weight) and the nearest weight on bit below it (at the same speed) whose
    /// P(stick-slip ends) reaches [`ADVICE_CONFIDENCE`], each with that probability, searched
    /// on `speeds_rpm` and `weights_kn`.
    ///
    /// The scans go nearest first, and on the CPU a few cells at a time: they stop after the
    /// cells in which a change first ends it, since the cells beyond cannot be nearer (the
    /// advice is the same as from the whole scan, with fewer strings). A GPU takes each scan in
    /// one batch.
    pub fn escape_advice(&mut self, from: &AtPoint, speeds_rpm: &[f64], weights_kn: &[f64]) -> Result<EscapeAdvice> {
        self.escape_advice_with(from, speeds_rpm, weights_kn, ADVICE_CONFIDENCE)
    }

    /// [`Self::escape_advice`] with the ways that end the stick-slip with P ≥ `confidence`
    /// (1: in every string).
    pub fn escape_advice_with(
        &mut self,
        from: &AtPoint,
        speeds_rpm: &[f64],
        weights_kn: &[f64],
        confidence: f64,
    ) -> Result<EscapeAdvice> {
        let p = from.point;
        let cells = self.cells_per_scan_batch(from.replicas.len(), speeds_rpm.len().max(weights_kn.len()));
        let mut speed_parts = Vec::new();
        for part in speeds_rpm.chunks(cells) {
            let grid = self.escape(from, part, &[p.wob_kn])?;
            let ends = Way::nearest(part, &grid, false, confidence).is_some();
            speed_parts.push(grid);
            if ends {
                break;
            }
        }
        // The weights ascend: the nearest below the operating point is the last.
        let mut weight_parts = Vec::new();
        for part in weights_kn.rchunks(cells) {
            let grid = self.escape(from, &[p.omega_rpm], part)?;
            let ends = Way::nearest(part, &grid, true, confidence).is_some();
            weight_parts.push(grid);
            if ends {
                break;
            }
        }
        weight_parts.reverse();
        let by_speed = Grid::joined(speed_parts, Axis::Speed, p.wob_kn);
        let by_weight = Grid::joined(weight_parts, Axis::Weight, p.omega_rpm);
        Ok(EscapeAdvice {
            point: p,
            stick_slip_probability: from.stick_slip_probability,
            speed_rpm: Way::nearest(&by_speed.omega_rpm, &by_speed, false, confidence),
            wob_kn: Way::nearest(&by_weight.wob_kn, &by_weight, true, confidence),
            speed_scan: by_speed,
            wob_scan: by_weight,
        })
    }

    /// Cells of an advice's scan integrated together: enough strings to keep every CPU
    /// thread busy (a group of lanes each), all of them where a GPU integrates.
    fn cells_per_scan_batch(&self, strings_per_cell: usize, cells: usize) -> usize {
        let on_cpu = self.settings.backend == Backend::Cpu || self.ran == Some(Ran::Cpu);
        if on_cpu {
            (crate::simulate::strings::LANES * rayon::current_num_threads())
                .div_ceil(strings_per_cell.max(1))
                .max(1)
        } else {
            cells.max(1)
        }
    }
}

/// A change that ends stick-slip: where to, and how surely.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Way {
    /// The top-drive speed (rpm) or weight on bit (kN) to change to.
    pub to: f64,
    /// P(stick-slip ends) there: the mixture's weight of the strings that settled out of it.
    /// A string that left physical bounds has not been seen to end it, so where some did this
    /// is a lower bound.
    pub ends_probability: f64,
    /// The mixture's weight of the strings that left physical bounds there.
    pub diverged_share: f64,
}

impl Way {
    /// The first value of `axis` (the scan `grid` along it, in its order, or `reversed`) whose
    /// P(it ends) reaches `confidence` ([`ADVICE_CONFIDENCE`] for the advice).
    fn nearest(axis: &[f64], grid: &Grid, reversed: bool, confidence: f64) -> Option<Way> {
        let mut cells: Vec<Way> = axis
            .iter()
            .zip(grid.stick_slip_weight.iter().zip(&grid.diverged_weight))
            .map(|(v, (s, d))| Way {
                to: *v,
                ends_probability: (1.0 - s - d).max(0.0),
                diverged_share: *d,
            })
            .collect();
        if reversed {
            cells.reverse();
        }
        cells.into_iter().find(|w| w.ends_probability >= confidence)
    }

    /// P(it ends) in words: "P(it ends) = 0.97", or a lower bound with the strings that left
    /// physical bounds.
    fn probability_text(&self) -> String {
        if self.diverged_share > 0.0 {
            format!(
                "P(it ends) ≥ {:.2}; {:.0} % of the strings left physical bounds there",
                self.ends_probability,
                100.0 * self.diverged_share
            )
        } else {
            format!("P(it ends) = {:.2}", self.ends_probability)
        }
    }
}

/// What ends stick-slip from an operating point, by simulation.
#[derive(Clone, Debug)]
pub struct EscapeAdvice {
    pub point: OperatingPoint,
    /// P(the bit stick-slips at the operating point), simulated.
    pub stick_slip_probability: f64,
    /// The nearest speed (rpm) that ends it; `None` when none scanned does.
    pub speed_rpm: Option<Way>,
    /// The nearest lighter weight (kN) that ends it.
    pub wob_kn: Option<Way>,
    /// P(stick-slip persists) along the speeds at the operating weight: every speed where
    /// none ends it, otherwise at least those up to the nearest that does.
    pub speed_scan: Grid,
    /// P(stick-slip persists) along the weights at the operating speed, likewise (from the
    /// nearest down).
    pub wob_scan: Grid,
}

impl EscapeAdvice {
    /// What ends it, as a driller reads it: the speed, then the weight, each with P(it ends);
    /// where neither does, how far the scans went.
    pub fn ways(&self) -> String {
        let mut ways = Vec::new();
        if let Some(w) = self.speed_rpm {
            ways.push(format!(
                "raise the top-drive speed to {:.0} rpm ({})",
                w.to,
                w.probability_text()
            ));
        }
        if let Some(w) = self.wob_kn {
            ways.push(format!(
                "lower the weight on bit to {} ({})",
                crate::units::kn_text(w.to),
                w.probability_text()
            ));
        }
        if ways.is_empty() {
            let p = self.point;
            return format!(
                "no top-drive speed up to {:.0} rpm nor weight on bit down to {} ends it in the simulated strings",
                self.speed_scan.omega_rpm.last().copied().unwrap_or(p.omega_rpm),
                crate::units::kn_text(self.wob_scan.wob_kn.iter().copied().fold(p.wob_kn, f64::min))
            );
        }
        ways.join(", or ")
    }

    /// The advice as a driller reads it.
    pub fn text(&self) -> String {
        let p = self.point;
        format!(
            "stick-slip at {:.0} rpm and {} (simulated P = {:.2}): {}",
            p.omega_rpm,
            crate::units::kn_text(p.wob_kn),
            self.stick_slip_probability,
            self.ways()
        )
    }
}

/// The speeds advice scans above `omega_rpm`: every 5 rpm up to three times it (and at least
/// 60 rpm more), at most 400 rpm.
pub fn advice_speeds_rpm(omega_rpm: f64) -> Vec<f64> {
    let top = (3.0 * omega_rpm).max(omega_rpm + 60.0).min(400.0);
    let mut v = Vec::new();
    let mut s = (omega_rpm / 5.0).floor() * 5.0 + 5.0;
    while s <= top + 1e-9 {
        v.push(s);
        s += 5.0;
    }
    v
}

/// The weights advice scans below `wob_kn`: every 5 % of it down to a fifth of it.
pub fn advice_weights_kn(wob_kn: f64) -> Vec<f64> {
    (4..20).map(|k| wob_kn * f64::from(k) / 20.0).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One speed, four weights: stick-slip weights and diverged weights per cell.
    fn grid(stick_slip: [f64; 4], diverged: [f64; 4]) -> Grid {
        Grid {
            omega_rpm: vec![100.0],
            wob_kn: vec![100.0, 200.0, 300.0, 400.0],
            probability: stick_slip
                .iter()
                .zip(&diverged)
                .map(|(s, d)| if *d > 0.0 { f64::NAN } else { *s })
                .collect(),
            stick_slip_weight: stick_slip.to_vec(),
            diverged_weight: diverged.to_vec(),
            diverged: diverged.iter().filter(|d| **d > 0.0).count(),
        }
    }

    #[test]
    fn a_boundary_is_decided_by_the_bounds_strings_that_left_physical_bounds_leave() {
        // 300 kN: at least 0.6 stick-slip whatever the diverged 0.1 did: the boundary.
        let g = grid([0.0, 0.2, 0.6, 1.0], [0.0, 0.1, 0.1, 0.0]);
        assert_eq!(g.boundary_wob_kn(0.5), vec![Some(300.0)]);
        // 200 kN: between 0.45 and 0.55: unknown, and it comes first.
        let g = grid([0.0, 0.45, 0.6, 1.0], [0.0, 0.1, 0.0, 0.0]);
        assert!(g.boundary_wob_kn(0.5)[0].unwrap().is_nan());
        // Nowhere reaching it, even with every diverged string counted: none.
        let g = grid([0.0, 0.1, 0.2, 0.3], [0.0, 0.1, 0.1, 0.1]);
        assert_eq!(g.boundary_wob_kn(0.5), vec![None]);
    }

    #[test]
    fn a_way_out_counts_strings_that_left_physical_bounds_as_not_ending_it() {
        // P(it ends) = 1 − stick-slip − diverged: 0.85 at 200 kN (below 0.9), 0.95 at 100 kN.
        let g = grid([0.0, 0.05, 0.6, 1.0], [0.05, 0.1, 0.0, 0.0]);
        let axis = g.wob_kn.clone();
        let way = Way::nearest(&axis, &g, true, ADVICE_CONFIDENCE).unwrap();
        // The values are the grid's own, copied: compared bit for bit.
        assert_eq!(way.to.to_bits(), 100f64.to_bits());
        assert!((way.ends_probability - 0.95).abs() < 1e-12, "{way:?}");
        assert_eq!(way.diverged_share.to_bits(), 0.05f64.to_bits());
        assert!(
            way.probability_text().starts_with("P(it ends) ≥ 0.95; 5 %"),
            "{}",
            way.probability_text()
        );
        // Scanned upwards from the lightest, the first that ends it is the same here.
        assert_eq!(
            Way::nearest(&axis, &g, false, ADVICE_CONFIDENCE).unwrap().to.to_bits(),
            100f64.to_bits()
        );
        assert_eq!(
            Way::nearest(
                &axis[2..],
                &grid([0.6, 1.0, 0.6, 1.0], [0.0; 4]),
                false,
                ADVICE_CONFIDENCE
            ),
            None
        );
    }

    #[test]
    fn peaks_are_weighed_by_the_mixture() {
        let peaks = Peaks(vec![(200.0, 0.25), (215.0, 0.25), (250.0, 0.5)]);
        assert_eq!(peaks.range(), Some((200.0, 250.0)));
        // Within 10 % of 220 rpm: 200 and 215 (22 rpm of room), a half of the weight.
        assert!((peaks.share_within(220.0, 0.1) - 0.5).abs() < 1e-15);
        assert!((peaks.share_within(250.0, 0.01) - 0.5).abs() < 1e-15);
        assert_eq!(peaks.share_within(100.0, 0.1).to_bits(), 0f64.to_bits(), "+0, never −0");
        assert_eq!(Peaks::default().range(), None);
        assert_eq!(Peaks::default().share_within(100.0, 0.1).to_bits(), 0f64.to_bits());
    }
}
