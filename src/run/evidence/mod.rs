//! The model evidence of a record's laws in one call: least-squares fits (for the report and
//! for the paper's δ boxes), a prior, an evaluator, and the tempered samplers of
//! [`crate::abc::evidence`]. `bitrock evidence` is its caller.

use crate::abc::Observer;
use crate::abc::evidence::{self, Evidence, EvidenceConfig, NoiseEvidence, NoiseModel};
use crate::abc::shard::Workers;
use crate::data::FieldData;
use crate::error::Result;
use crate::eval::{Backend, Problem};
use crate::fit::{self, FitOptions, LawFit};
use crate::laws::Law;
use crate::prior::{PhysicalScales, Prior, PriorFile};
use crate::run::{Placement, Scoring};
use crate::separation;
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

mod analysis;
pub mod check;
pub mod dir;
pub mod settings;

pub use analysis::{EvidenceAnalysis, EvidenceWarning};
pub use check::{DEFAULT_REPLICATES, EvidenceCheck, check, check_replicates, check_size, replicates_asked};
pub use settings::{Boxes, Noise, Settings};

/// The default width of the physical boxes, in record scales ([`PhysicalScales`]).
pub const DEFAULT_PRIOR_SCALE: f64 = 10.0;

/// Which boxes the evidence integrates over.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "boxes", rename_all = "lowercase")]
pub enum EvidencePrior {
    /// From each parameter's physical bound, `scale` times the record's scale of its
    /// dimension: no fit involved ([`Prior::physical`]).
    Physical { scale: f64 },
    /// The paper's φ̂(1 ± δ) around the least-squares estimates of the same record: the data
    /// used twice (each box is centred where the data put its law), kept to compare with the
    /// paper's ABC on its own boxes.
    Delta { delta: f64 },
}

impl Default for EvidencePrior {
    fn default() -> Self {
        EvidencePrior::Physical {
            scale: DEFAULT_PRIOR_SCALE,
        }
    }
}

impl EvidencePrior {
    /// A sentence naming the boxes, for tables and reports.
    pub fn describe(&self) -> String {
        match *self {
            EvidencePrior::Physical { scale } => format!(
                "physical boxes: each parameter from its physical bound over {scale} times the record's scale of its unit (no fit involved); a law whose file sets prior_curve_within cut to the curves within that many times the record's largest torque"
            ),
            EvidencePrior::Delta { delta } => format!(
                "the paper's boxes φ̂(1 ± {delta}) around the least-squares estimates of this record (the data used twice)"
            ),
        }
    }
}

/// An evidence job: what to compare, over which prior, on which backend. An evidence directory
/// keeps it (without its warm start), to compute the evidence again for its check.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Job {
    pub laws: Vec<Law>,
    pub fit: FitOptions,
    pub prior: EvidencePrior,
    /// A prior file's explicit boxes and law weights, where it gives them.
    pub prior_file: Option<PathBuf>,
    /// The prior file's text, read once ([`Self::keep_prior_text`]): what the job's prior is
    /// made from, and what an evidence directory keeps of it, so that the directory's evidence
    /// is computed again from the file as it was.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub prior_text: Option<String>,
    pub backend: Backend,
    /// The samplers' settings; their `noise` is set from [`Self::noise`].
    pub sampler: EvidenceConfig,
    /// The noise model; `None`: every model's evidence is computed and the data choose (the
    /// model of the largest p(y | noise model) = Σ π(m)·Z_m is reported).
    pub noise: Option<NoiseModel>,
    /// Where the laws' samplers start instead of their boxes (a watch's previous window).
    #[serde(skip)]
    pub warm: Option<WarmStart>,
    /// Whether to find [`EvidenceAnalysis::separations`] (a least-squares fit of every law to
    /// every other's curve, one after the other): a watch's windows do without.
    pub separations: bool,
    /// The drill string the evidence's advice and maps are drawn for, where it was given one
    /// (`None`: the paper's 1-DOF string).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub string: Option<crate::run::stability::DrillStringSpec>,
}

impl Default for Job {
    fn default() -> Self {
        Self {
            laws: Vec::new(),
            fit: FitOptions::default(),
            prior: EvidencePrior::default(),
            prior_file: None,
            prior_text: None,
            backend: Backend::default(),
            sampler: EvidenceConfig::default(),
            noise: None,
            warm: None,
            separations: true,
            string: None,
        }
    }
}

/// A warm start of an evidence job: the references of its laws (each moved as its law's
/// least-squares estimate moved from `fits` to the job's own), the least-squares estimates
/// the job's fits start from besides their grid (SI, by law), and whether both are for the
/// torque scaled by WOB / W_ref (they start only the fits and samplers of the same scaling).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct WarmStart {
    pub references: Vec<evidence::Reference>,
    pub fits: Vec<(Law, Vec<f64>)>,
    pub scaled: bool,
    /// What each law was worth before (a watch's carried probabilities, by law): with them,
    /// each law's samplers get particles by what it is worth ([`particles_by_worth`]).
    pub worth: Vec<(Law, f64)>,
}

/// Least share of the sampler's particles a warm-started law keeps, however little it is
/// worth.
pub const LEAST_SHARE: f64 = 0.25;

/// Each law's particles by what it is worth: as many as `particles` for a law worth at least
/// an even share, down to [`LEAST_SHARE`] of them. A law is worth the larger of what it was
/// worth before (`before`) and the probability its least-squares fit gives it on these
/// samples (the Bayesian information criterion over `fits`, n samples): a law that was
/// improbable but fits the new samples best gets all its particles, since fewer particles
/// under-estimate ln Z (the tempered estimator errs downwards) exactly where it should rise.
pub fn particles_by_worth(particles: usize, before: &[(Law, f64)], fits: &[LawFit], n: usize) -> Vec<(Law, usize)> {
    let bic: Vec<f64> = fits
        .iter()
        .map(|f| -0.5 * n as f64 * f.rho.ln() - 0.5 * f.law.n_params() as f64 * (n as f64).ln())
        .collect();
    let top = bic
        .iter()
        .copied()
        .filter(|b| b.is_finite())
        .fold(f64::NEG_INFINITY, f64::max);
    let total: f64 = bic.iter().filter(|b| b.is_finite()).map(|b| (b - top).exp()).sum();
    let even = fits.len() as f64;
    fits.iter()
        .zip(&bic)
        .map(|(f, b)| {
            let here = if b.is_finite() { (b - top).exp() / total } else { 0.0 };
            let was = before.iter().find(|(l, _)| *l == f.law).map_or(1.0, |(_, p)| *p);
            let share = (even * here.max(was)).clamp(LEAST_SHARE, 1.0);
            let count = (particles as f64 * share).ceil() as usize;
            (
                f.law,
                count.clamp(evidence::MIN_ISLAND_PARTICLES.min(particles), particles),
            )
        })
        .collect()
}

/// An evidence under way: the samplers' state at the end of each part done (a torque scaling
/// under a noise model, in the order the job computes them) and the last one saved of the part
/// in progress ([`evidence::Checkpoints`]). An evidence directory keeps it while the evidence
/// is computed, and a resumed evidence ([`Job::run_saving`]) goes on from it to the
/// evidence the uninterrupted job gives, bit for bit.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Progress {
    pub done: Vec<Vec<u8>>,
    pub current: Option<Vec<u8>>,
}

/// Where an evidence's [`Progress`] is kept as it goes: from what, how often, by what.
pub struct Saving<'a> {
    pub progress: Progress,
    /// Where it is kept: named when a saved state is refused.
    pub origin: &'a std::path::Path,
    /// Least seconds between two saves within a part; each part done is saved at once.
    pub every_s: f64,
    pub save: &'a mut dyn FnMut(&Progress) -> Result<()>,
}

/// What the samplers of one torque scaling start from: the least-squares fits, the boxes, the
/// fit options they were made with, and the lag-1 autocorrelation of each fit's residuals and
/// the data's preference for AR(1) residuals there.
#[derive(Clone, Debug)]
struct Basis {
    fits: Vec<LawFit>,
    prior: Prior,
    fit: FitOptions,
    residual_lag1: Vec<f64>,
    ar1_preference_nats: Vec<f64>,
}

impl Basis {
    /// The basis of `fits` on `data`'s calibration samples.
    fn new(fits: Vec<LawFit>, prior: Prior, fit: FitOptions, data: &FieldData) -> Self {
        // Each fit's residuals once, for both checks on the noise model.
        let sum_sq = crate::numerics::compensated_sum(data.calibration.torque_nm.iter().map(|y| y * y));
        let (residual_lag1, ar1_preference_nats) = fits
            .iter()
            .map(|f| {
                let e = crate::fit::residuals(f.law, &f.params_si, &data.calibration, fit.w_ref_n);
                (
                    separation::lag1_of(&e),
                    evidence::noise::ar1_preference_nats(&e, sum_sq),
                )
            })
            .unzip();
        Self {
            fits,
            prior,
            fit,
            residual_lag1,
            ar1_preference_nats,
        }
    }
}

/// How much wider (in standard deviations) than the fit's Laplace approximation of the
/// posterior a fit's reference is ([`fit_reference`]): the approximation misses the curvature
/// of a nonlinear law's posterior and σ's uncertainty, and a reference narrower than the
/// posterior gives heavy-tailed weights, a wider one only a tempering step more.
pub const FIT_REFERENCE_WIDTH: f64 = 2.0;

/// Most lag-1 autocorrelation of the residuals the reference of an AR(1) evidence widens for.
const MOST_LAG1: f64 = 0.9;

/// The reference a law's samplers start from ([`evidence::Start::Fit`]): a Gaussian at its
/// least-squares estimate whose covariance is the fit's, [`FIT_REFERENCE_WIDTH`] times as
/// wide, and under AR(1) residuals of lag-1 autocorrelation φ̂ (`lag1`) (1 + φ̂)/(1 − φ̂) times
/// the variance more (correlated residuals hold less information about a smooth curve than
/// as many independent ones); `None` where the fit gives no covariance (a parameter on its
/// bound, a singular Jacobian): that law starts from its box.
pub fn fit_reference(fit: &LawFit, noise: NoiseModel, lag1: f64) -> Option<evidence::Reference> {
    let d = fit.law.n_params();
    let sd: Vec<f64> = (0..d)
        .map(|j| fit.std_errors_si.get(j).copied().flatten())
        .collect::<Option<_>>()?;
    let correlation = |j: usize, k: usize| match j == k {
        true => Some(1.0),
        false => fit.correlations.get(j).and_then(|row| row.get(k)).copied().flatten(),
    };
    let phi = if noise == NoiseModel::Ar1 && lag1.is_finite() {
        lag1.clamp(0.0, MOST_LAG1)
    } else {
        0.0
    };
    let widen = FIT_REFERENCE_WIDTH * FIT_REFERENCE_WIDTH * (1.0 + phi) / (1.0 - phi);
    let mut covariance = Vec::with_capacity(d * d);
    for j in 0..d {
        for k in 0..d {
            covariance.push(correlation(j, k)? * sd[j] * sd[k] * widen);
        }
    }
    let usable = sd.iter().chain(&fit.params_si).all(|v| v.is_finite()) && sd.iter().all(|&v| v > 0.0);
    usable.then(|| evidence::Reference::gaussian(fit.law, fit.params_si.clone(), &covariance))
}

impl Job {
    /// Fits, builds the prior and scores the tempered samplers on `data`'s calibration
    /// samples where `scoring` says (here, on the job's backend, or on a pool of workers: the
    /// same evidence); a fallback to the CPU is said through `observer`.
    pub fn run(&self, data: &FieldData, scoring: Scoring, observer: &mut dyn Observer) -> Result<EvidenceAnalysis> {
        self.run_saving(data, scoring, None, observer)
    }

    /// [`Self::run`], its progress kept by `saving` and resumed from its `progress` (a job
    /// without a warm start: a warm start's samplers are not saved).
    pub fn run_saving(
        &self,
        data: &FieldData,
        mut scoring: Scoring,
        mut saving: Option<Saving>,
        observer: &mut dyn Observer,
    ) -> Result<EvidenceAnalysis> {
        self.sampler.validate()?;
        self.sampler.check_memory(&self.laws)?;
        if saving.is_some() && self.warm.is_some() {
            return Err(crate::error::Error::Numerical(
                "an evidence started from a previous posterior is not saved as it goes".into(),
            ));
        }
        self.fit.validate_for(&data.calibration)?;
        let file = self.prior()?;
        let models = match self.noise {
            Some(model) => vec![model],
            None => NoiseModel::ALL.to_vec(),
        };
        let mut analyses = Vec::new();
        let mut said: Vec<String> = Vec::new();
        // Parts (a torque scaling under a noise model) in the order computed: what a saved
        // progress counts.
        let mut part = 0;
        for fit_options in self.scalings(data) {
            let known = match &self.warm {
                Some(warm) if warm.scaled == fit_options.w_ref_n.is_some() => warm.fits.as_slice(),
                _ => &[],
            };
            let fits = fit::fit_record_from(&self.laws, data, &fit_options, known)?;
            let unit = data.torque_unit.newton_metres();
            let prior = match self.prior {
                EvidencePrior::Physical { scale } => {
                    let scales = PhysicalScales::of(&data.calibration);
                    Prior::physical(&self.laws, &scales, scale, file.as_ref(), unit)?.with_curve_limits(&scales)?
                }
                EvidencePrior::Delta { delta } => Prior::from_fits(&fits, delta, file.as_ref(), unit)?,
            };
            let basis = Basis::new(fits, prior, fit_options, data);
            // One evaluator for every noise model of this scaling (the same data, the same ρ);
            // what choosing it says (the backend) is said once for all scalings.
            let problem = Self::problem(data, &basis, self.sampler.seed);
            let workers = scoring.workers(problem, &self.placement(), &mut |line| {
                if !said.contains(&line) {
                    said.push(line.clone());
                    observer.note(line);
                }
            })?;
            for &model in &models {
                let mut analysis =
                    self.sample_saved(basis.clone(), workers.as_ref(), model, part, saving.as_mut(), observer)?;
                part += 1;
                analysis.residual_lag1 = basis.residual_lag1.clone();
                analysis.ar1_preference_nats = basis.ar1_preference_nats.clone();
                analyses.push(analysis);
            }
        }
        let compared: Vec<(&Evidence, Option<f64>)> = analyses.iter().map(|a| (&a.evidence, a.fit.w_ref_n)).collect();
        let noise_models = NoiseEvidence::compare(&compared);
        let chosen = noise_models
            .iter()
            .enumerate()
            .max_by(|(_, a), (_, b)| a.probability.total_cmp(&b.probability))
            .map(|(i, _)| i)
            .expect("at least one noise model");
        let mut analysis = analyses.swap_remove(chosen);
        analysis.noise_models = noise_models;
        if self.separations {
            analysis.separations = separation::separations(&analysis.fits, &data.calibration, &analysis.fit)?;
        }
        Ok(analysis)
    }

    /// Reads the prior file's text into the job ([`Self::prior_text`]), where it names one.
    pub fn keep_prior_text(&mut self) -> Result<()> {
        if let Some(path) = &self.prior_file
            && self.prior_text.is_none()
        {
            self.prior_text = Some(PriorFile::read_text(path)?);
        }
        Ok(())
    }

    /// The prior file of the job, from its kept text where it has it.
    fn prior(&self) -> Result<Option<PriorFile>> {
        match (&self.prior_text, &self.prior_file) {
            (Some(text), path) => {
                let path = path.as_deref().unwrap_or(std::path::Path::new("the prior file kept"));
                PriorFile::parse(text, path).map(Some)
            }
            (None, Some(path)) => PriorFile::read(path).map(Some),
            (None, None) => Ok(None),
        }
    }

    /// The fit options of each torque scaling compared: the job's own, and where it leaves
    /// the weight on bit out of a record that has it, also each torque scaled by WOB / W̄ (W̄
    /// the calibration samples' mean weight on bit, so that the torque parameters keep the
    /// record's scale and its boxes fit both): torque proportional to the weight on bit is a
    /// model of the residuals as much as their noise is, and the evidence judges it alike. A
    /// constant weight on bit is not compared: it scales nothing.
    fn scalings(&self, data: &FieldData) -> Vec<FitOptions> {
        let mut scalings = vec![self.fit];
        // A weight on bit that never changes scales nothing.
        if self.fit.w_ref_n.is_none()
            && let Some(mean) = data.calibration.mean_wob_n().filter(|_| data.calibration.wob_varies())
        {
            scalings.push(FitOptions {
                w_ref_n: Some(mean),
                ..self.fit
            });
        }
        scalings
    }

    /// The problem of `basis`' prior on `data`'s calibration samples, its candidates seeded
    /// `seed`.
    fn problem(data: &FieldData, basis: &Basis, seed: u64) -> Problem {
        Problem::new(basis.prior.clone(), seed, &data.calibration, basis.fit.w_ref_n).with_best_rho(&basis.fits)
    }

    /// Where the job's candidates are scored: on its backend, one device, the default GPU
    /// scoring shape, for dispatches of every island's particles at once, explicit candidates
    /// (what `auto` races on a software driver).
    fn placement(&self) -> Placement {
        let starts = if self.sampler.start == crate::abc::evidence::Start::Both {
            2
        } else {
            1
        };
        let particles: usize = self.laws.iter().map(|&law| self.sampler.particles_of(law)).sum();
        Placement {
            backend: self.backend,
            shape: crate::eval::gpu::tune::ShapeWish {
                candidates: particles.saturating_mul(starts * self.sampler.islands).max(1),
                explicit: true,
                // Every noise model's evidence but the iid one's scores the lag-1 sums too.
                lagged: self.noise != Some(NoiseModel::Iid),
                ..Default::default()
            },
            ..Placement::default()
        }
    }

    /// [`Self::sample`] of part `part` of the job, saved by `saving` where given: a part done
    /// before is read from its final state (nothing scored), the part under way goes on from
    /// its last state, and each is saved as it goes and once done.
    fn sample_saved(
        &self,
        basis: Basis,
        workers: &dyn Workers,
        noise: NoiseModel,
        part: usize,
        saving: Option<&mut Saving>,
        observer: &mut dyn Observer,
    ) -> Result<EvidenceAnalysis> {
        let Some(Saving {
            progress,
            origin,
            every_s,
            save,
        }) = saving
        else {
            return self.sample(basis, workers, noise, None, observer);
        };
        if let Some(state) = progress.done.get(part) {
            let checkpoints = evidence::Checkpoints {
                from: Some(state),
                origin,
                every_s: f64::INFINITY,
                save: &mut |_| Ok(()),
            };
            return self.sample(basis, workers, noise, Some(checkpoints), observer);
        }
        let from = progress.current.take();
        let checkpoints = evidence::Checkpoints {
            from: from.as_deref(),
            origin,
            every_s: *every_s,
            save: &mut |bytes| {
                progress.current = Some(bytes.to_vec());
                save(progress)
            },
        };
        let analysis = self.sample(basis, workers, noise, Some(checkpoints), observer)?;
        let last = progress.current.take().expect("a finished sampling saves its state");
        progress.done.push(last);
        save(progress)?;
        Ok(analysis)
    }

    /// The evidence of `basis`' laws under the `noise` model, scored by `workers` (made for
    /// [`Self::problem`] of `basis`; the samplers take its seed), without the separations,
    /// residual autocorrelations and models' comparison, which the caller adds where it wants
    /// them.
    fn sample(
        &self,
        basis: Basis,
        workers: &dyn Workers,
        noise: NoiseModel,
        checkpoints: Option<evidence::Checkpoints>,
        observer: &mut dyn Observer,
    ) -> Result<EvidenceAnalysis> {
        let Basis {
            fits,
            prior,
            fit,
            residual_lag1,
            ..
        } = basis;
        let law_particles = match &self.warm {
            Some(warm) if !warm.worth.is_empty() => {
                particles_by_worth(self.sampler.particles, &warm.worth, &fits, workers.problem().data_len())
            }
            _ => self.sampler.law_particles.clone(),
        };
        let sampler = EvidenceConfig {
            seed: workers.problem().seed,
            noise,
            law_particles,
            ..self.sampler.clone()
        };
        // Each reference moved as its law's least-squares estimate moved from the window
        // before to this record: the window before gives the posterior's shape, the estimates
        // how far it went.
        let mut references: Vec<evidence::Reference> = match &self.warm {
            Some(warm) if warm.scaled == fit.w_ref_n.is_some() => warm
                .references
                .iter()
                .map(|r| {
                    let now = fits.iter().find(|f| f.law == r.law).map(|f| &f.params_si);
                    let before = warm.fits.iter().find(|(law, _)| *law == r.law).map(|(_, p)| p);
                    match (now, before) {
                        (Some(now), Some(before))
                            if now.len() == before.len() && now.iter().chain(before).all(|v| v.is_finite()) =>
                        {
                            let by: Vec<f64> = now.iter().zip(before).map(|(a, b)| a - b).collect();
                            r.clone().shifted(&by)
                        }
                        _ => r.clone(),
                    }
                })
                .collect(),
            _ => Vec::new(),
        };
        // The other laws start from their fits, where the job says so.
        if matches!(sampler.start, evidence::Start::Fit | evidence::Start::Both) {
            for (fit, &lag1) in fits.iter().zip(&residual_lag1) {
                if !references.iter().any(|r| r.law == fit.law)
                    && let Some(reference) = fit_reference(fit, noise, lag1)
                {
                    references.push(reference);
                }
            }
        }
        let evidence = evidence::run_from(workers, &sampler, &references, checkpoints, observer)?;
        Ok(EvidenceAnalysis {
            fits,
            prior,
            fit,
            evidence,
            separations: Vec::new(),
            residual_lag1: Vec::new(),
            ar1_preference_nats: Vec::new(),
            noise_models: Vec::new(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fit(law: Law, rho: f64) -> LawFit {
        let mut fit: LawFit = serde_json::from_value(serde_json::json!({
            "law": law, "params_si": vec![1.0; law.n_params()], "std_errors_si": [], "rho": 1.0,
            "validation_rho": null, "condition_number": 1.0, "correlations": [], "warnings": [], "starts": 1,
        }))
        .unwrap();
        fit.rho = rho;
        fit
    }

    #[test]
    fn a_law_improbable_before_that_fits_best_here_keeps_all_its_particles() {
        // 500 samples: m1 fits best here by about 24 nats, m2 was the carried favourite, m3 is
        // worth little on both counts.
        let fits = [fit(Law::M1, 0.010), fit(Law::M2, 0.011), fit(Law::M3, 0.02)];
        let before = [(Law::M1, 0.01), (Law::M2, 0.98), (Law::M3, 0.01)];
        assert_eq!(
            particles_by_worth(300, &before, &fits, 500),
            vec![(Law::M1, 300), (Law::M2, 300), (Law::M3, 75)]
        );
        // A law the fits cannot score (no finite ρ) keeps what it was worth before; none goes
        // below the sampler's least island.
        let fits = [fit(Law::M1, f64::NAN), fit(Law::M2, 0.011)];
        assert_eq!(
            particles_by_worth(40, &[(Law::M1, 0.3), (Law::M2, 0.7)], &fits, 500),
            vec![(Law::M1, 24), (Law::M2, 40)]
        );
    }
}
