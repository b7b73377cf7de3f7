//! What a finished evidence says and what it does not: its analysis (fits, prior, evidence,
//! separations, residual checks), the warnings said beside its numbers, its answer, advice and
//! documents.

use super::{EvidenceCheck, Job};
use crate::abc::evidence::{self, Evidence, NoiseEvidence, NoiseModel};
use crate::data::FieldData;
use crate::error::Result;
use crate::fit::{FitOptions, LawFit};
use crate::laws::Law;
use crate::prior::Prior;
use crate::run::answer::{Answer, AnswerCheck};
use crate::separation::Separation;
use serde::{Deserialize, Serialize};

/// A finished evidence job.
#[derive(Clone, Debug)]
pub struct EvidenceAnalysis {
    /// The least-squares fits on the calibration samples (the data the evidence uses).
    pub fits: Vec<LawFit>,
    /// The boxes and law weights integrated over.
    pub prior: Prior,
    /// The fit options of the reported evidence: the job's, or with each torque scaled by
    /// WOB / W_ref where the data chose that ([`Job::noise`]); the posterior's torque
    /// parameters are for W = W_ref then.
    pub fit: FitOptions,
    pub evidence: Evidence,
    /// What the fits alone say about telling the laws apart on these samples.
    pub separations: Vec<Separation>,
    /// The lag-1 autocorrelation of each fit's residuals in time order, in `fits` order
    /// ([`crate::separation::residual_lag1`]).
    pub residual_lag1: Vec<f64>,
    /// The nats by which the data prefer AR(1) residuals to i.i.d. ones at each fit, in `fits`
    /// order ([`evidence::noise::ar1_preference_nats`]): the check on the i.i.d. noise model.
    pub ar1_preference_nats: Vec<f64>,
    /// Every noise model compared, or the one named ([`Job::noise`]); `evidence` is
    /// the one of the largest probability.
    pub noise_models: Vec<NoiseEvidence>,
}

/// What the evidence's numbers do not say by themselves, said beside them: in the command's
/// table, the JSON's `warnings` (an evidence directory's document too) and Python's warnings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum EvidenceWarning {
    /// Under the i.i.d. model, the data prefer AR(1) residuals at every fit by more than
    /// [`evidence::noise::AR1_PREFERRED_NATS`] (the least of those preferences, and the least
    /// lag-1 autocorrelation of the residuals).
    Autocorrelated { nats: f64, lag1: f64 },
    /// A law's islands disagree beyond [`evidence::ISLANDS_AGREE_NATS`].
    IslandsDisagree { law: Law, nats: f64 },
    /// A law's posterior reaches box ends that are not physical bounds.
    CutByBox { law: Law, ends: Vec<String> },
    /// The first law leads a rival by the boxes' Occam factors, not by the data.
    DecidedByTheBoxes {
        favoured: Law,
        against: Law,
        ln_b: f64,
        data_nats: Option<f64>,
    },
}

impl std::fmt::Display for EvidenceWarning {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Autocorrelated { nats, lag1 } => write!(
                f,
                "the data prefer AR(1) residuals to i.i.d. ones by at least {nats:.1} nats at every law's best fit \
                 (lag-1 autocorrelation at least {lag1:.2}): the i.i.d. noise model counts each sample as independent \
                 and overstates every Bayes factor, by about (1 + φ)/(1 − φ) = {:.1} times in nats; the AR(1) model \
                 accounts for it",
                (1.0 + lag1) / (1.0 - lag1)
            ),
            Self::IslandsDisagree { law, nats } => write!(
                f,
                "the islands of {law} disagree by {nats:.1} nats: its samplers have not converged alike, and its ln Z \
                 is uncertain by about that much"
            ),
            Self::CutByBox { law, ends } => write!(
                f,
                "the posterior of {law} reaches the end of its box ({}): its ln Z depends on where that box ends",
                ends.join(", ")
            ),
            Self::DecidedByTheBoxes {
                favoured,
                against,
                ln_b,
                data_nats,
            } => write!(
                f,
                "{favoured} leads {against} by ln B = {ln_b:.2} through the boxes, not the data{}: with other boxes the \
                 order may change",
                data_nats.map_or(String::new(), |d| format!(" (the data's part {d:.2} nats)"))
            ),
        }
    }
}

impl EvidenceAnalysis {
    /// What the reported evidence's numbers do not say by themselves ([`EvidenceWarning`]).
    pub fn warnings(&self) -> Vec<EvidenceWarning> {
        let evidence = &self.evidence;
        let mut warnings = Vec::new();
        let least = |values: &[f64]| values.iter().copied().filter(|v| v.is_finite()).reduce(f64::min);
        if evidence.config.noise == NoiseModel::Iid
            && let Some(nats) = least(&self.ar1_preference_nats).filter(|&n| n > evidence::noise::AR1_PREFERRED_NATS)
        {
            let lag1 = least(&self.residual_lag1).unwrap_or(f64::NAN);
            warnings.push(EvidenceWarning::Autocorrelated { nats, lag1 });
        }
        warnings.extend(
            evidence
                .laws
                .iter()
                .filter(|l| !l.converged())
                .map(|l| EvidenceWarning::IslandsDisagree {
                    law: l.law,
                    nats: l.island_spread,
                }),
        );
        warnings.extend(
            evidence
                .laws
                .iter()
                .filter(|l| !l.cut_by_box.is_empty())
                .map(|l| EvidenceWarning::CutByBox {
                    law: l.law,
                    ends: l.cut_by_box.clone(),
                }),
        );
        warnings.extend(
            evidence
                .bayes_factors(&self.separations)
                .into_iter()
                .filter(|f| f.strength == evidence::Strength::DecidedByTheBoxes)
                .map(|f| EvidenceWarning::DecidedByTheBoxes {
                    favoured: f.favoured,
                    against: f.against,
                    ln_b: f.ln_b,
                    data_nats: f.data_nats,
                }),
        );
        warnings
    }

    /// The advice at `data`'s own operating point from the posterior, on `job`'s drill string
    /// (the paper's 1-DOF string where it has none; its way out of stick-slip simulated on
    /// `job`'s backend); `None` where the record keeps no account of its bit. A
    /// finite-element string's critical bit damping is found here (said through `note`).
    pub fn record_advice(
        &self,
        data: &FieldData,
        job: &Job,
        note: &mut dyn FnMut(String),
    ) -> Result<Option<crate::run::advice::Advice>> {
        use crate::run::advice::{Adviser, params_w_ref_n};
        let Some(seen) = data.bit else {
            return Ok(None);
        };
        let (structure, lumped, fe) = crate::run::stability::StringGiven::default().over(job.string.as_ref());
        let criterion = crate::run::stability::criterion(structure, lumped, &fe, note)?;
        // A string the simulator cannot hold leaves the advice to the linear maps.
        let chain = crate::run::strings::chain(structure, &lumped, &fe).ok();
        let adviser = Adviser::for_record(criterion, chain, job.backend);
        let inputs =
            crate::abc::posterior::map_inputs_of(&self.evidence.particles(), crate::run::advice::ADVICE_SAMPLES);
        let w_ref_n = params_w_ref_n(self.fit.w_ref_n, &seen, crate::laws::PAPER_W_REF_N);
        Ok(Some(adviser.advise_record(&inputs, w_ref_n, &seen)))
    }

    /// `document` with what `data`'s bit did (`"record_bit"`) and `advice` (from
    /// [`record_advice`](Self::record_advice)) where there is one: what `bitrock evidence
    /// --json` prints, an evidence directory keeps and Python's `Evidence.document` holds.
    pub fn with_advice(
        mut document: serde_json::Value,
        data: &FieldData,
        advice: Option<&crate::run::advice::Advice>,
    ) -> serde_json::Value {
        if let Some(advice) = advice {
            document["record_bit"] = serde_json::to_value(data.bit).expect("a record's bit serialises");
            document["advice"] = serde_json::to_value(advice).expect("advice serialises");
        }
        document
    }

    /// The evidence's answer to "which law, how sure" ([`Answer::of_evidence`]), weighed by
    /// its `check` where one ran ([`Answer::checked`]).
    pub fn answer(&self, check: Option<&EvidenceCheck>) -> Option<Answer> {
        let answer = Answer::of_evidence(&self.evidence, &self.separations)?;
        // One law compared: nothing to tell it from.
        let Some(check) = check.filter(|_| answer.runner_up.is_some()) else {
            return Some(answer);
        };
        // Records made by `made_by` that the check decided for the answer's law.
        let decided_for_law = |made_by: Law| {
            let row = check.rows.iter().find(|r| r.law == made_by)?;
            Some(
                row.replicates
                    .iter()
                    .filter(|r| r.decided && r.first == answer.law)
                    .count(),
            )
        };
        let Some(decided_right) = decided_for_law(answer.law) else {
            return Some(answer);
        };
        let runner_up_decided_for_law = answer.runner_up.and_then(decided_for_law);
        Some(answer.checked(AnswerCheck {
            replicates: check.replicates,
            decided_right,
            runner_up_decided_for_law,
        }))
    }

    /// `document` (from [`document`](Self::document)) with the evidence's `check` and the
    /// answer it weighs.
    pub fn with_check(&self, document: &mut serde_json::Value, check: &EvidenceCheck) {
        document["check"] = serde_json::to_value(check).expect("a check serialises");
        document["answer"] = self.answer(Some(check)).map_or(serde_json::Value::Null, |a| a.json());
    }

    /// `bitrock evidence --json`'s document of the analysis of `data` (`prior` describing its
    /// boxes); with `posterior_sets`, each law's posterior sets too (`"posterior": {"params",
    /// "weights", "island"}`, in the record's torque unit, each set's island beside it), as an
    /// evidence directory and Python keep it.
    pub fn document(&self, data: &FieldData, prior: &str, posterior_sets: bool) -> serde_json::Value {
        let mut document = crate::documents::evidence_json(
            data,
            &self.fits,
            &self.prior,
            &self.evidence,
            &self.separations,
            &self.residual_lag1,
            &self.ar1_preference_nats,
            &self.noise_models,
            prior,
        );
        document["answer"] = self.answer(None).map_or(serde_json::Value::Null, |a| a.json());
        // Each warning with its words (`message`) beside its fields.
        document["warnings"] = self
            .warnings()
            .iter()
            .map(|w| {
                let mut entry = serde_json::to_value(w).expect("a warning serialises");
                entry["message"] = w.to_string().into();
                entry
            })
            .collect();
        if posterior_sets {
            for (entry, law) in document["laws"]
                .as_array_mut()
                .expect("the document lists its laws")
                .iter_mut()
                .zip(&self.evidence.laws)
            {
                let params: Vec<Vec<f64>> = law
                    .posterior
                    .iter()
                    .map(|(p, _)| crate::documents::to_record_units(law.law, p, data.torque_unit))
                    .collect();
                let weights: Vec<f64> = law.posterior.iter().map(|(_, w)| *w).collect();
                entry["posterior"] = serde_json::json!({"params": params, "weights": weights});
                if !law.posterior_island.is_empty() {
                    entry["posterior"]["island"] = serde_json::json!(law.posterior_island);
                }
            }
        }
        document
    }

    /// The posterior particles (every law's sets weighed by its P(m | y)) as the particle CSV
    /// `bitrock stability --posterior` reads, parameters in the record's torque unit.
    pub fn posterior_csv(&self, laws: &[Law], data: &FieldData) -> Vec<u8> {
        let particles = self.evidence.particles();
        crate::documents::particle_groups_csv(&[(0, &particles)], laws, data.torque_unit)
    }
}
