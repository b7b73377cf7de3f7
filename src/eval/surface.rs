//! Scoring candidates by simulation: each candidate's string is driven on the surface record's
//! clock ([`crate::simulate::surface`]), the record's own noise added to its surface torque,
//! and ρ is the distance between its summaries and the record's.
//!
//! **Noise.** The simulated torque gets white Gaussian noise of the record's size, drawn from
//! Philox under a key made of the run's seed and the candidate's law and f32 parameters: ρ is
//! then a function of the parameters, as for a bit record, so that a particle keeps its ρ from
//! one population to the next and a run is reproduced exactly.
//!
//! **Distance.** ρ = √(mean_j ((s_j − s_j^obs)/σ_j)²) over the record's summaries (the
//! surface torque's, and the downhole extremes' where it holds them), σ_j
//! the median absolute deviation (×1.4826) of summary j over a pilot of prior simulations
//! (their standard deviation where the MAD is 0, 1 where both are): each summary counts by
//! how much it varies across the prior, not by its unit (Prangle 2017's scaling, fixed after
//! the pilot so that ρ stays a function of the parameters). Where the run asks for
//! semi-automatic summaries, ρ compares instead what regressions fitted on the pilot predict
//! from the scaled summaries ([`super::projection`]). A diverged string scores +∞.

use super::projection::{Feature, Projection};
use super::{Backend, Evaluator, Problem};
use crate::error::Result;
use crate::laws::{Law, MAX_PARAMS};
use crate::prior::{Candidate, MAX_DIMS, Prior};
use crate::rng::{box_muller, key_of_seed, philox4x32_10};
use crate::simulate::strings::{Chain, LANES};
use crate::simulate::surface::{
    DownholeExtremes, Drive, Integration, N_DOWNHOLE_SUMMARIES, N_SUMMARIES, OnClock, OnClockJob, simulate_on_clock,
    simulate_on_clock_many, summaries,
};
use crate::stability::lumped::Lumped;
use rayon::prelude::*;
use std::borrow::Cow;

pub use crate::simulate::surface::Summaries;

/// The string and drive every candidate is simulated with, and the noise added.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct SurfaceModel {
    /// The string as given; where [`Self::string`] is set, each candidate's own instead.
    pub chain: Chain,
    /// Where the run infers the string with the law: its natural frequency and damping ratio
    /// are every candidate's two coordinates after its law's parameters.
    pub string: Option<InferredString>,
    pub drive: Drive,
    pub integration: Integration,
    /// Standard deviation of the white noise on the surface torque (N·m).
    pub noise_sd_nm: f64,
    /// The MWD tool's downhole extremes the record holds, compared as the tool reports them
    /// (no noise is added to them).
    pub downhole: Option<DownholeExtremes>,
    /// Where the strings are simulated: [`Backend::Gpu`] (f32, the batch at once) or
    /// [`Backend::Cpu`] (f64, eight strings of a law at a time, the groups on rayon's threads),
    /// resolved before a run starts
    /// ([`Backend::Auto`] simulates on the CPU).
    pub backend: Backend,
}

/// Which noise a simulation gets: a candidate's own ([`NoiseKey::of`]) or a re-simulation's.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct NoiseKey(pub u64);

impl NoiseKey {
    /// The key of `candidate` under `seed`: its slot and f32 coordinates' bits mixed
    /// (splitmix64), the first [`MAX_PARAMS`] always and those past them only where set: a
    /// candidate of a law's parameters alone is keyed by those.
    pub fn of(seed: u64, candidate: &Candidate) -> Self {
        let mut h = splitmix(seed ^ 0x5355_5246);
        h = splitmix(h ^ candidate.slot as u64);
        let (law_room, beyond) = candidate.params.split_at(MAX_PARAMS);
        for p in law_room.iter().chain(beyond.iter().filter(|p| p.to_bits() != 0)) {
            h = splitmix(h ^ u64::from(p.to_bits()));
        }
        Self(h)
    }

    /// The key of the `draw`-th other noise draw on the same string (`draw` ≥ 1).
    pub fn redrawn(self, draw: u64) -> Self {
        Self(self.0 ^ draw.wrapping_mul(0x9e37_79b9_7f4a_7c15))
    }

    /// Key `index` of a stream of re-simulations under `seed`.
    pub fn replicate(seed: u64, index: u64) -> Self {
        Self(splitmix(splitmix(seed ^ 0x5245_5349) ^ index))
    }
}

/// Adds white Gaussian noise of `sd_nm` drawn under `key` to a torque record (N·m).
pub fn add_noise(torque_nm: &mut [f64], sd_nm: f64, key: NoiseKey) {
    if sd_nm <= 0.0 {
        return;
    }
    let key = key_of_seed(key.0);
    for (pair, torque) in torque_nm.chunks_mut(2).enumerate() {
        let words = philox4x32_10([pair as u32, (pair >> 32) as u32, 0, 0], key);
        let z = box_muller(words[0], words[1]);
        for (t, z) in torque.iter_mut().zip(z) {
            *t += sd_nm * z;
        }
    }
}

fn splitmix(x: u64) -> u64 {
    let mut z = x.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// A 1-DOF string whose natural frequency and damping ratio a run infers with the law.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct InferredString {
    /// The equivalent inertia I_eq (kg·m²), given: the stiffness k = I_eq·ω_n² follows.
    pub inertia_kg_m2: f64,
    /// ω_n (rad/s) where given exactly (its coordinate then spans no width), else `None`.
    pub omega_n_rad_s: Option<f64>,
    /// ξ where given exactly, else `None`.
    pub damping_ratio: Option<f64>,
}

impl InferredString {
    /// The string of a candidate's two string coordinates [ω_n, ξ].
    pub fn lumped(&self, coordinates: &[f64]) -> Lumped {
        Lumped {
            inertia_kg_m2: self.inertia_kg_m2,
            omega_n_rad_s: self.omega_n_rad_s.unwrap_or(coordinates[0]),
            damping_ratio: self.damping_ratio.unwrap_or(coordinates[1]),
        }
    }
}

impl SurfaceModel {
    /// The string a candidate of `law` with coordinates `params` drives: the given one, or the
    /// one its string coordinates make.
    pub fn chain_of(&self, law: Law, params: &[f64]) -> Cow<'_, Chain> {
        match &self.string {
            None => Cow::Borrowed(&self.chain),
            Some(string) => {
                let n = law.n_params();
                Cow::Owned(Chain::one_dof(&string.lumped(&params[n..n + 2])))
            }
        }
    }

    /// The string of `law` with coordinates `params` (its parameters SI, then the string's
    /// where inferred) on the record's clock, noise-free.
    pub fn simulate_noiseless(&self, law: Law, params: &[f64]) -> OnClock {
        let chain = self.chain_of(law, params);
        simulate_on_clock(&chain, &self.drive, law, &params[..law.n_params()], self.integration)
    }

    /// [`Self::simulate_noiseless`] for every `(law, coordinates)` of `strings`, in order, on
    /// the model's backend: the GPU simulates the batch at once.
    pub fn simulate_noiseless_many(&self, strings: &[(Law, &[f64])]) -> Result<Vec<OnClock>> {
        let chains: Vec<Cow<'_, Chain>> = strings.iter().map(|(law, p)| self.chain_of(*law, p)).collect();
        let jobs: Vec<OnClockJob<'_>> = strings
            .iter()
            .zip(&chains)
            .map(|((law, params), chain)| OnClockJob {
                law: *law,
                params_nm: &params[..law.n_params()],
                chain,
            })
            .collect();
        if self.backend != Backend::Gpu {
            return Ok(simulate_on_clock_many(&jobs, &self.drive, self.integration));
        }
        Ok(super::gpu::strings::on_clock_batch(
            &self.drive,
            self.integration,
            &jobs,
        )?)
    }

    /// Adds the model's noise, drawn under `key`, to a simulated string's surface torque (none
    /// to a string that diverged).
    pub fn add_noise(&self, run: &mut OnClock, key: NoiseKey) {
        if !run.diverged {
            add_noise(&mut run.surface_torque_nm, self.noise_sd_nm, key);
        }
    }

    /// The noise-free strings of `candidates` (candidates of `prior`), in order, on the
    /// model's backend.
    pub fn simulate_candidates_noiseless(&self, prior: &Prior, candidates: &[Candidate]) -> Result<Vec<OnClock>> {
        let widened: Vec<_> = candidates.iter().map(|c| coordinates(prior, c)).collect();
        let strings: Vec<(Law, &[f64])> = widened.iter().map(|(law, p, dims)| (*law, &p[..*dims])).collect();
        self.simulate_noiseless_many(&strings)
    }

    /// The summaries of a simulated string, its surface torque as it stands.
    pub fn summaries_of_run(&self, run: &OnClock) -> Summaries {
        summaries(&run.surface_torque_nm, self.drive.period_s, &self.downhole_of(run))
    }

    /// The downhole summaries the record's tool would give of `run` (zeros without one).
    pub fn downhole_of(&self, run: &OnClock) -> [f64; N_DOWNHOLE_SUMMARIES] {
        self.downhole
            .map_or([0.0; N_DOWNHOLE_SUMMARIES], |d| d.summaries_of(run))
    }

    /// Which summaries the distance compares.
    pub fn active(&self) -> [bool; N_SUMMARIES] {
        DownholeExtremes::active(self.downhole.as_ref())
    }
}

/// The distance between summaries, scaled per summary (see the module documentation).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Distance {
    pub observed: Summaries,
    pub scales: Summaries,
    /// The summaries compared: the record's (a record without downhole channels leaves
    /// theirs out).
    pub active: [bool; N_SUMMARIES],
    /// Where set, what the distance compares instead of the scaled summaries: the
    /// predictions of semi-automatic ABC's regressions.
    pub projection: Option<Projection>,
}

impl Distance {
    /// Scales from the summaries of a pilot's simulations that did not diverge: first over the
    /// whole pilot, then, [`LOCAL_ROUNDS`] times, over its [`LOCAL_SHARE`] nearest the record
    /// (a summary that does not vary there keeps its scale of the round before; none narrower
    /// than [`LOCAL_NARROWEST`] of the whole pilot's, nor than `least`). A prior is
    /// mostly strings far from the record (steady ones, for a stick-slipping record): scales
    /// over all of it would measure how steady strings differ from stick-slipping ones, not
    /// how candidates near the record differ from each other.
    pub fn from_pilot(
        observed: Summaries,
        active: [bool; N_SUMMARIES],
        least: &Summaries,
        pilot: &[Summaries],
    ) -> Self {
        let mut global = scales_over(pilot.iter(), &[1.0; N_SUMMARIES]);
        for (scale, least) in global.iter_mut().zip(least) {
            *scale = scale.max(*least);
        }
        let mut distance = Self {
            observed,
            scales: global,
            active,
            projection: None,
        };
        let keep = ((pilot.len() as f64 * LOCAL_SHARE) as usize)
            .max(LOCAL_LEAST)
            .min(pilot.len());
        for _ in 0..LOCAL_ROUNDS {
            if keep == 0 {
                break;
            }
            let mut near: Vec<(f64, &Summaries)> = pilot.iter().map(|s| (distance.rho(s), s)).collect();
            near.select_nth_unstable_by(keep - 1, |a, b| a.0.total_cmp(&b.0));
            let local = scales_over(near[..keep].iter().map(|n| n.1), &distance.scales);
            for j in 0..N_SUMMARIES {
                distance.scales[j] = local[j].max(LOCAL_NARROWEST * global[j]).max(least[j]);
            }
        }
        distance
    }

    /// ρ of summaries `s`.
    pub fn rho(&self, s: &Summaries) -> f64 {
        self.between(s, &self.observed)
    }

    /// The scaled distance between two sets of summaries, or between their predictions where
    /// the distance has a projection.
    pub fn between(&self, a: &Summaries, b: &Summaries) -> f64 {
        if let Some(projection) = &self.projection {
            let d = std::array::from_fn(|j| {
                if self.active[j] {
                    (a[j] - b[j]) / self.scales[j]
                } else {
                    0.0
                }
            });
            return projection.rho(&d);
        }
        let compared = (0..N_SUMMARIES).filter(|&j| self.active[j]);
        let sum: f64 = compared.clone().map(|j| ((a[j] - b[j]) / self.scales[j]).powi(2)).sum();
        (sum / compared.count().max(1) as f64).sqrt()
    }
}

/// Share of the pilot nearest the record whose spread scales the distance.
pub const LOCAL_SHARE: f64 = 0.2;
/// Fewest pilot strings the local scales are taken over.
pub const LOCAL_LEAST: usize = 50;
/// Rounds of the local scales.
pub const LOCAL_ROUNDS: usize = 2;
/// The narrowest a local scale may be, as a share of the whole pilot's: strings near the
/// record may agree on a summary (a steady string's steps are all 0), and a scale of 0 would
/// make that summary the whole distance.
pub const LOCAL_NARROWEST: f64 = 0.1;

/// Each summary's spread over `set`: its MAD (×1.4826), its standard deviation where the MAD
/// is 0, and `fallback`'s where both are.
pub fn scales_over<'a>(set: impl Iterator<Item = &'a Summaries> + Clone, fallback: &Summaries) -> Summaries {
    let mut scales = *fallback;
    for (j, scale) in scales.iter_mut().enumerate() {
        let values: Vec<f64> = set.clone().map(|s| s[j]).collect();
        let Some(median) = crate::numerics::median(&values) else {
            continue;
        };
        let deviations: Vec<f64> = values.iter().map(|v| (v - median).abs()).collect();
        let mad = 1.4826 * crate::numerics::median(&deviations).unwrap_or(0.0);
        let mean = values.iter().sum::<f64>() / values.len() as f64;
        let sd = (values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / values.len() as f64).sqrt();
        if mad > 0.0 {
            *scale = mad;
        } else if sd > 0.0 {
            *scale = sd;
        }
    }
    scales
}

/// A candidate of `prior`'s law and coordinates (its parameters SI, then the string's where
/// its box carries them).
/// The coordinates are the first `dims` of the array, kept on the stack.
fn coordinates(prior: &Prior, candidate: &Candidate) -> (Law, [f64; MAX_DIMS], usize) {
    let dims = prior.boxes[candidate.slot].lower.len();
    (prior.law(candidate.slot), candidate.widened(), dims)
}

/// Samples of trace (each four f64 channels) a batch of the evaluator holds on the host at
/// once: 128 MB.
const TRACE_VALUES: usize = 1 << 22;

/// Scores candidates by simulating their strings on the record's clock, in batches (on the
/// GPU, or on the CPU eight strings of a law at a time).
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
#[serde(into = "Shipped", from = "Shipped")]
pub struct SurfaceEvaluator {
    problem: Problem,
    model: SurfaceModel,
    distance: Distance,
}

/// A [`SurfaceEvaluator`] as it travels to a worker: its parts, the projection's weights
/// included (a result's JSON leaves them out).
#[derive(serde::Serialize, serde::Deserialize)]
struct Shipped {
    problem: Problem,
    model: SurfaceModel,
    observed: Summaries,
    scales: Summaries,
    active: [bool; N_SUMMARIES],
    /// The features (name, weights, adjusted R², strings), the training strings, the laws
    /// left unregressed.
    projection: Option<(Vec<ShippedFeature>, usize, Vec<Law>)>,
}

/// A projection's feature as it travels: name, weights, adjusted R², strings.
type ShippedFeature = (String, Summaries, f64, usize);

impl From<SurfaceEvaluator> for Shipped {
    fn from(e: SurfaceEvaluator) -> Self {
        let Distance {
            observed,
            scales,
            active,
            projection,
        } = e.distance;
        Self {
            problem: e.problem,
            model: e.model,
            observed,
            scales,
            active,
            projection: projection.map(|p| {
                let features = p
                    .features
                    .into_iter()
                    .map(|f| (f.name, f.weights, f.adjusted_r_squared, f.strings))
                    .collect();
                (features, p.training, p.unregressed)
            }),
        }
    }
}

impl From<Shipped> for SurfaceEvaluator {
    fn from(s: Shipped) -> Self {
        let projection = s.projection.map(|(features, training, unregressed)| Projection {
            features: features
                .into_iter()
                .map(|(name, weights, adjusted_r_squared, strings)| Feature {
                    name,
                    weights,
                    adjusted_r_squared,
                    strings,
                })
                .collect(),
            training,
            unregressed,
        });
        Self {
            problem: s.problem,
            model: s.model,
            distance: Distance {
                observed: s.observed,
                scales: s.scales,
                active: s.active,
                projection,
            },
        }
    }
}

impl SurfaceEvaluator {
    /// The evaluator of candidates of `prior` under `seed`.
    pub fn new(prior: Prior, seed: u64, model: SurfaceModel, distance: Distance) -> Self {
        Self {
            problem: Problem {
                prior,
                seed,
                speed_rad_s: Vec::new(),
                torque_nm: Vec::new(),
                wob_ratio: Vec::new(),
                sum_sq_torque: 1.0,
                best_rho: Default::default(),
            },
            model,
            distance,
        }
    }

    /// The same evaluator, its strings simulated on `backend` ([`Backend::Gpu`] or
    /// [`Backend::Cpu`]).
    pub fn on(mut self, backend: Backend) -> Self {
        self.model.backend = backend;
        self
    }
}

impl Evaluator for SurfaceEvaluator {
    fn backend(&self) -> &'static str {
        if self.model.backend == Backend::Gpu {
            "gpu"
        } else {
            "cpu"
        }
    }

    fn problem(&self) -> &Problem {
        &self.problem
    }

    fn score(&self, population: u32, start: u64, out: &mut [f64]) -> Result<()> {
        let p = &self.problem;
        let candidates: Vec<Candidate> = (0..out.len() as u64)
            .map(|i| p.prior.candidate(p.seed, population, start + i))
            .collect();
        self.score_params(&candidates, out)
    }

    fn score_params(&self, candidates: &[Candidate], out: &mut [f64]) -> Result<()> {
        let p = &self.problem;
        let rho_of = |mut run: OnClock, c: &Candidate| {
            self.model.add_noise(&mut run, NoiseKey::of(p.seed, c));
            if run.diverged {
                f64::INFINITY
            } else {
                self.distance.rho(&self.model.summaries_of_run(&run))
            }
        };
        // In batches whose traces stay a bounded share of memory, yet keep every CPU thread busy
        // (the CPU simulates a batch's strings of one law eight at a time, the GPU all at once).
        let per_batch =
            (TRACE_VALUES / self.model.drive.omega_rad_s.len().max(1)).max(LANES * rayon::current_num_threads());
        for (part, rhos) in candidates.chunks(per_batch).zip(out.chunks_mut(per_batch)) {
            let runs = self.model.simulate_candidates_noiseless(&p.prior, part)?;
            runs.into_par_iter()
                .zip(part)
                .zip(rhos.par_iter_mut())
                .for_each(|((run, c), rho)| *rho = rho_of(run, c));
        }
        Ok(())
    }
}
