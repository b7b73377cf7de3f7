//! The model evidence of a record's laws in one call: least-squares fits (for the report and
//! for the paper's δ boxes), a prior, an evaluator, and the tempered samplers of
//! [`crate::abc::evidence`]. `bitrock evidence` is its caller.

use crate::abc::Observer;
use crate::abc::evidence::{self, Evidence, EvidenceConfig};
use crate::data::FieldData;
use crate::error::Result;
use crate::eval::{self, AbcProblem, Backend};
use crate::fit::{self, FitOptions, LawFit};
use crate::laws::Law;
use crate::prior::{PhysicalScales, Prior, PriorFile};
use crate::separation::{self, Separation};
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

pub mod check;

pub use check::{EvidenceCheck, check, check_replicates};

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
                "physical boxes: each parameter from its physical bound over {scale} times the record's scale of its unit (no fit involved)"
            ),
            EvidencePrior::Delta { delta } => format!(
                "the paper's boxes φ̂(1 ± {delta}) around the least-squares estimates of this record (the data used twice)"
            ),
        }
    }
}

/// An evidence job: what to compare, over which prior, on which backend.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct EvidenceJob {
    pub laws: Vec<Law>,
    pub fit: FitOptions,
    pub prior: EvidencePrior,
    /// A prior file's explicit boxes and law weights, where it gives them.
    pub prior_file: Option<PathBuf>,
    pub backend: Backend,
    pub sampler: EvidenceConfig,
}

/// A finished evidence job.
#[derive(Clone, Debug)]
pub struct EvidenceAnalysis {
    /// The least-squares fits on the calibration samples (the data the evidence uses).
    pub fits: Vec<LawFit>,
    /// The boxes and law weights integrated over.
    pub prior: Prior,
    pub evidence: Evidence,
    /// What the fits alone say about telling the laws apart on these samples.
    pub separations: Vec<Separation>,
    /// The lag-1 autocorrelation of each fit's residuals in time order, in `fits` order
    /// ([`separation::residual_lag1`]): the check on the i.i.d. noise model.
    pub residual_lag1: Vec<f64>,
}

impl EvidenceJob {
    /// Fits, builds the prior and scores the tempered samplers on `data`'s calibration
    /// samples; a fallback to the CPU is said through `observer`.
    pub fn run(&self, data: &FieldData, observer: &mut dyn Observer) -> Result<EvidenceAnalysis> {
        self.sampler.validate()?;
        self.fit.validate_for(&data.calibration)?;
        let file = self.prior_file.as_deref().map(PriorFile::read).transpose()?;
        let fits = fit::fit_record(&self.laws, data, &self.fit)?;
        let unit = data.torque_unit.newton_metres();
        let prior = match self.prior {
            EvidencePrior::Physical { scale } => Prior::physical(
                &self.laws,
                &PhysicalScales::of(&data.calibration),
                scale,
                file.as_ref(),
                unit,
            )?,
            EvidencePrior::Delta { delta } => Prior::from_fits(&fits, delta, file.as_ref(), unit)?,
        };
        let separations = separation::separations(&fits, &data.calibration, &self.fit)?;
        let residual_lag1 = fits
            .iter()
            .map(|fit| separation::residual_lag1(fit, &data.calibration, &self.fit))
            .collect();
        let mut analysis = self.sample(data, fits, prior, self.backend, self.sampler.seed, observer)?;
        analysis.separations = separations;
        analysis.residual_lag1 = residual_lag1;
        Ok(analysis)
    }

    /// The evidence of `fits`' laws on `data` over `prior`, the samplers seeded `seed`
    /// (without the separations and residual autocorrelations, which the caller adds where it
    /// wants them).
    fn sample(
        &self,
        data: &FieldData,
        fits: Vec<LawFit>,
        prior: Prior,
        backend: Backend,
        seed: u64,
        observer: &mut dyn Observer,
    ) -> Result<EvidenceAnalysis> {
        let problem = AbcProblem::new(prior.clone(), seed, &data.calibration, self.fit.w_ref_n).with_best_rho(&fits);
        let evaluator = eval::evaluator(problem, backend, Default::default(), &mut |line| observer.note(line))?;
        let sampler = EvidenceConfig {
            seed,
            ..self.sampler.clone()
        };
        let evidence = evidence::run(evaluator.as_ref(), &sampler, observer)?;
        Ok(EvidenceAnalysis {
            fits,
            prior,
            evidence,
            separations: Vec::new(),
            residual_lag1: Vec::new(),
        })
    }
}
