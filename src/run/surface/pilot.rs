//! The pilot and the scout: prior simulations that scale the distance and classify the
//! check's records, and a short ABC-SMC on them that finds the strings near the record.

use super::*;

/// A simulated string's noise-free surface torque (N·m) and downhole summaries, kept whole so
/// that the record's noise, once estimated, can be added to it.
pub(super) struct Noiseless {
    /// The noise its own summaries get.
    key: NoiseKey,
    torque_nm: Vec<f64>,
    downhole: [f64; N_DOWNHOLE_SUMMARIES],
}

impl Noiseless {
    pub(super) fn of(model: &SurfaceModel, key: NoiseKey, run: OnClock) -> Self {
        Self {
            key,
            downhole: model.downhole_of(&run),
            torque_nm: run.surface_torque_nm,
        }
    }

    /// Its summaries with noise of `sd_nm` drawn under `key`.
    pub(super) fn summaries(&self, sd_nm: f64, period_s: f64, key: NoiseKey) -> Summaries {
        let mut noisy = self.torque_nm.clone();
        add_noise(&mut noisy, sd_nm, key);
        summaries(&noisy, period_s, &self.downhole)
    }
}

/// The entries of `all` that `active` marks (the summaries a distance compares), in order.
pub(super) fn compared<T: Clone>(all: &[T; N_SUMMARIES], active: &[bool; N_SUMMARIES]) -> Vec<T> {
    all.iter()
        .zip(active)
        .filter(|(_, a)| **a)
        .map(|(v, _)| v.clone())
        .collect()
}

/// The pilot: prior simulations, noise-free, kept whole so that the record's noise, once
/// estimated, can be added to them.
pub(super) struct Pilot {
    /// Per simulation that stayed in bounds: its law's slot and its string.
    runs: Vec<(usize, Noiseless)>,
    /// Each run's coordinates (SI; its box's count of them first), in the order of `runs`.
    coordinates: Vec<[f64; MAX_DIMS]>,
    /// Samples of the record's clock.
    samples: usize,
}

/// Share of the pilot, nearest the record, that semi-automatic ABC's regressions are fitted on.
pub const TRAINING_SHARE: f64 = 0.5;

/// The training strings of semi-automatic ABC out of a reference table of `table` strings.
pub(super) fn training_size(table: usize) -> usize {
    ((table as f64 * TRAINING_SHARE).ceil() as usize).max(1)
}

/// Pilot strings, and noise draws on each, that measure the summaries' spread under the noise.
pub(super) const NOISE_NEIGHBOURS: usize = 20;
pub(super) const NOISE_REPLICATES: usize = 5;

impl Pilot {
    pub(super) fn simulate(model: &SurfaceModel, prior: &Prior, seed: u64, count: usize) -> Result<Self> {
        let candidates: Vec<Candidate> = (0..count).map(|i| prior.candidate(seed, 0, i as u64)).collect();
        let simulated = model.simulate_candidates_noiseless(prior, &candidates)?;
        let (runs, coordinates): (Vec<(usize, Noiseless)>, Vec<[f64; MAX_DIMS]>) = candidates
            .iter()
            .zip(simulated)
            .filter(|(_, run)| !run.diverged)
            .map(|(c, run)| ((c.slot, Noiseless::of(model, NoiseKey::of(seed, c), run)), c.widened()))
            .unzip();
        if runs.len() < count / 2 {
            return Err(Error::Numerical(format!(
                "{} of the pilot's {count} prior strings left physical bounds: the prior boxes admit laws whose torque turns negative at speed; narrow them with a prior file{}",
                count - runs.len(),
                if model.string.is_some() {
                    ", or narrow the string's bounds (`omega_n_rad_s`, `damping_ratio`)"
                } else {
                    ""
                }
            )));
        }
        Ok(Self {
            runs,
            coordinates,
            samples: model.drive.omega_rad_s.len(),
        })
    }

    /// Semi-automatic ABC's regressions, fitted on the [`TRAINING_SHARE`] of the pilot's
    /// strings nearest the record under `distance` (its `table`, with the record's noise): the
    /// prior truncated to where the record lies, as Fearnhead & Prangle's pilot run does.
    pub(super) fn projection(
        &self,
        prior: &Prior,
        table: &[(usize, Summaries)],
        distance: &Distance,
    ) -> Option<Projection> {
        let mut near: Vec<(f64, usize)> = table.iter().enumerate().map(|(i, t)| (distance.rho(&t.1), i)).collect();
        near.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        near.truncate(training_size(table.len()));
        let training: Vec<Training<'_>> = near
            .iter()
            .map(|&(_, i)| Training {
                slot: table[i].0,
                coordinates: &self.coordinates[i][..prior.boxes[table[i].0].lower.len()],
                summaries: table[i].1,
            })
            .collect();
        let bounds: Vec<(Vec<f64>, Vec<f64>)> = prior
            .boxes
            .iter()
            .map(|b| {
                let widen = |v: &[f32]| v.iter().map(|&x| f64::from(x)).collect();
                (widen(&b.lower), widen(&b.upper))
            })
            .collect();
        let names: Vec<Vec<String>> = prior
            .boxes
            .iter()
            .map(|b| {
                let mut names: Vec<String> = b.law.params().iter().map(|p| p.name.to_string()).collect();
                names.extend(
                    STRING_COORDINATES
                        .into_iter()
                        .take(b.lower.len().saturating_sub(names.len()))
                        .map(str::to_string),
                );
                names
            })
            .collect();
        let laws: Vec<Law> = prior.laws().collect();
        Projection::learn(
            &training,
            &distance.observed,
            &distance.scales,
            &distance.active,
            &laws,
            &bounds,
            &names,
        )
    }

    /// The reference table with noise of `sd_nm`: each run's law slot and summaries.
    pub(super) fn table(&self, sd_nm: f64, period_s: f64) -> Vec<(usize, Summaries)> {
        self.runs
            .par_iter()
            .map(|(slot, run)| (*slot, run.summaries(sd_nm, period_s, run.key)))
            .collect()
    }

    /// The reference table with noise of `sd_nm` and the distance it scales, each scale no
    /// narrower than the summary's spread under the noise alone (see [`Pilot::noise_spread`]).
    pub(super) fn distance(
        &self,
        sd_nm: f64,
        period_s: f64,
        observed: &Summaries,
        active: [bool; N_SUMMARIES],
    ) -> (Vec<(usize, Summaries)>, Distance) {
        let table = self.table(sd_nm, period_s);
        let least = least_scales(self.samples);
        let pilot: Vec<Summaries> = table.iter().map(|t| t.1).collect();
        let mut distance = Distance::from_pilot(*observed, active, &least, &pilot);
        let mut near: Vec<(f64, usize)> = table.iter().enumerate().map(|(i, t)| (distance.rho(&t.1), i)).collect();
        let k = NOISE_NEIGHBOURS.min(near.len());
        near.select_nth_unstable_by(k - 1, |a, b| a.0.total_cmp(&b.0));
        let traces: Vec<&Noiseless> = near[..k].iter().map(|&(_, i)| &self.runs[i].1).collect();
        let spread = noise_spread(&traces, sd_nm, period_s);
        for (scale, spread) in distance.scales.iter_mut().zip(spread) {
            *scale = scale.max(spread);
        }
        (table, distance)
    }
}

/// Each summary's spread (standard deviation) over [`NOISE_REPLICATES`] draws of noise of
/// `sd_nm` on each noise-free torque of `traces`, averaged: how far a string's summaries move
/// by the noise alone. Differences below it say nothing of the law.
pub(super) fn noise_spread(traces: &[&Noiseless], sd_nm: f64, period_s: f64) -> Summaries {
    let mut spread = [0.0; N_SUMMARIES];
    if sd_nm <= 0.0 || traces.is_empty() {
        return spread;
    }
    let per_string: Vec<Summaries> = traces
        .par_iter()
        .map(|run| {
            let draws: Vec<Summaries> = (0..NOISE_REPLICATES as u64)
                .map(|r| run.summaries(sd_nm, period_s, run.key.redrawn(r + 1)))
                .collect();
            let mut sd = [0.0; N_SUMMARIES];
            for (j, sd) in sd.iter_mut().enumerate() {
                let mean = draws.iter().map(|d| d[j]).sum::<f64>() / draws.len() as f64;
                *sd = (draws.iter().map(|d| (d[j] - mean).powi(2)).sum::<f64>() / (draws.len() - 1) as f64).sqrt();
            }
            sd
        })
        .collect();
    for (j, spread) in spread.iter_mut().enumerate() {
        *spread = per_string.iter().map(|s| s[j]).sum::<f64>() / per_string.len() as f64;
    }
    spread
}

/// Particles and populations of the scout run.
pub(super) const SCOUT_PARTICLES: usize = 300;
pub(super) const SCOUT_POPULATIONS: usize = 4;
/// Posterior strings the scout keeps.
pub(super) const SCOUT_DRAWS: usize = 40;
/// The narrowest a scout's scale may be, as a share of the pilot's.
pub(super) const SCOUT_NARROWEST: f64 = 0.02;

/// A short ABC-SMC on the pilot's distance that finds the strings near the record: their
/// summaries, with the noise, scale the main run's distance (how candidates near the record
/// differ, as an adaptive distance's scales would be after its first populations; fixed for
/// the main run so that ρ stays a function of the parameters).
pub(super) struct Scout {
    /// The posterior strings and their laws.
    draws: Vec<(Law, Noiseless)>,
    pub(super) simulations: u64,
}

impl Scout {
    /// The scout of `model` (its noise set) on the pilot's `distance`.
    pub(super) fn run(
        model: &SurfaceModel,
        prior: &Prior,
        settings: &SurfaceSettings,
        seed: u64,
        distance: &Distance,
    ) -> Result<Self> {
        let mut short = settings.smc.clone();
        short.schedule.particles = SCOUT_PARTICLES.min(settings.smc.schedule.particles);
        short.schedule.max_populations = SCOUT_POPULATIONS;
        short.schedule.max_seconds = None;
        let evaluator = SurfaceEvaluator::new(prior.clone(), seed ^ SCOUT_STREAM, model.clone(), distance.clone());
        let run = smc::run(&evaluator, &short)?;
        let scored: u64 = run.populations.iter().map(|p| p.record.candidates_scored).sum();
        let particles: Vec<&Particle> = run
            .populations
            .last()
            .map(|p| p.particles.iter().collect())
            .unwrap_or_default();
        let drawn = resample(&particles, SCOUT_DRAWS, seed ^ SCOUT_STREAM);
        let runs = model.simulate_noiseless_many(&strings_of(&drawn))?;
        let draws: Vec<(Law, Noiseless)> = drawn
            .iter()
            .zip(runs)
            .enumerate()
            .filter_map(|(k, (p, run))| {
                let key = NoiseKey::replicate(seed ^ SCOUT_STREAM, k as u64);
                (!run.diverged).then(|| (p.law, Noiseless::of(model, key, run)))
            })
            .collect();
        Ok(Self {
            draws,
            simulations: scored + drawn.len() as u64,
        })
    }

    /// The median ρ between two noise draws on each of the scout's strings (see
    /// [`SurfaceResult::noise_floor`]); 0 without strings or noise.
    pub(super) fn noise_floor(&self, distance: &Distance, sd_nm: f64, period_s: f64) -> f64 {
        let apart: Vec<f64> = self
            .draws
            .par_iter()
            .map(|(_, run)| {
                let draw = |r: u64| run.summaries(sd_nm, period_s, run.key.redrawn(r));
                distance.between(&draw(1), &draw(2))
            })
            .collect();
        crate::numerics::median(&apart).unwrap_or(0.0)
    }

    /// The main run's distance: the spread of the scout's strings' summaries with noise of
    /// `sd_nm` within each law, pooled ([`within_laws`]), none narrower than
    /// [`SCOUT_NARROWEST`] of `pilot`'s.
    pub(super) fn distance(&self, pilot: &Distance, sd_nm: f64, period_s: f64) -> Distance {
        if self.draws.len() < 10 {
            return pilot.clone();
        }
        let set: Vec<(Law, Summaries)> = self
            .draws
            .iter()
            .map(|(law, run)| (*law, run.summaries(sd_nm, period_s, run.key)))
            .collect();
        let mut scales = crate::eval::surface::scales_over(within_laws(&set).iter(), &pilot.scales);
        let traces: Vec<&Noiseless> = self.draws.iter().map(|(_, run)| run).collect();
        let spread = noise_spread(&traces, sd_nm, period_s);
        let least = least_scales(self.draws[0].1.torque_nm.len());
        for j in 0..N_SUMMARIES {
            scales[j] = scales[j]
                .max(SCOUT_NARROWEST * pilot.scales[j])
                .max(spread[j])
                .max(least[j]);
        }
        Distance {
            observed: pilot.observed,
            scales,
            active: pilot.active,
            projection: None,
        }
    }
}

/// Each set of summaries less its law's medians: their spread is the spread within a law,
/// pooled over the laws. A summary in which the laws differ and each law's strings agree (an
/// MWD's minimum bit speed: 0 for a law that holds the bit, a creep for one that does not)
/// then weighs by how little it varies within a law, not by how far the laws lie apart;
/// with one law it is the summaries' own spread.
pub(super) fn within_laws(set: &[(Law, Summaries)]) -> Vec<Summaries> {
    let mut medians: Vec<(Law, Summaries)> = Vec::new();
    for &(law, _) in set {
        if medians.iter().any(|(l, _)| *l == law) {
            continue;
        }
        let mut median = [0.0; N_SUMMARIES];
        for (j, m) in median.iter_mut().enumerate() {
            let values: Vec<f64> = set.iter().filter(|(l, _)| *l == law).map(|(_, s)| s[j]).collect();
            *m = crate::numerics::median(&values).expect("the law has a draw");
        }
        medians.push((law, median));
    }
    set.iter()
        .map(|(law, s)| {
            let median = &medians.iter().find(|(l, _)| l == law).expect("every law's median").1;
            std::array::from_fn(|j| s[j] - median[j])
        })
        .collect()
}

/// Seed offset of the scout run.
pub(super) const SCOUT_STREAM: u64 = 0x5343_4f55_5400_0000;
