//! The figures of an evidence directory's report: each law's 98 % posterior predictive
//! envelope over the samples, and the posterior law probabilities.

use super::fits::{Envelopes, envelope_panel};
use super::probabilities::FinalProbabilities;
use super::*;
use crate::abc::Particle;
use crate::run::evidence::dir::StoredSamples;

/// What the evidence's figures are drawn from.
pub(crate) struct EvidenceFigures<'a> {
    /// The posterior (SI), every law's sets weighed by its P(m | y).
    pub particles: &'a [Particle],
    /// Each law and its P(m | y), in the evidence's order.
    pub laws: Vec<(Law, f64)>,
    pub samples: &'a StoredSamples,
    /// Where the evidence scaled each torque by WOB / W_ref: that W_ref, kN.
    pub w_ref_kn: Option<f64>,
}

/// The evidence's two figures.
pub(crate) fn render_evidence(input: &EvidenceFigures) -> Result<Vec<Rendered>> {
    let samples = input.samples;
    let speeds = samples.calibration.iter().chain(&samples.validation).map(|s| s.0);
    let (lo, hi) = super::super::plot::extent(speeds).unwrap_or((0.0, 1.0));
    let grid = speed_grid(lo, hi, CURVE_POINTS);
    let points = |set: &[(f64, f64)]| set.iter().map(|&(w, t)| (super::super::rpm(w), t)).collect::<Vec<_>>();
    let envelopes = Envelopes {
        panels: input
            .laws
            .iter()
            .filter_map(|&(law, probability)| {
                envelope_panel(input.particles, law, probability, &grid, samples.unit.newton_metres())
            })
            .take(4)
            .collect(),
        cal: points(&samples.calibration),
        val: points(&samples.validation),
        unit: samples.unit.label(),
        run: "the evidence's posterior".into(),
    };
    let scaled = input.w_ref_kn.map_or(String::new(), |w| {
        format!(" The torque is the laws' at W_ref = {w:.1} kN (the evidence scaled each torque by WOB / W_ref).")
    });
    let probabilities = FinalProbabilities {
        laws: input.laws.iter().map(|l| l.0).collect(),
        runs: vec![("evidence".into(), input.laws.iter().map(|l| l.1).collect())],
        zero_by_construction: vec![vec![false; input.laws.len()]],
    };
    Ok(vec![
        render_one(
            "fig01_evidence_envelopes".into(),
            format!(
                "98 % posterior predictive envelopes of each law's torque (grey band) and its median (black), \
                 with the calibration (red circles) and validation (blue dots) samples.{scaled}"
            ),
            FIGURE_SIZE,
            &envelopes,
        )?,
        render_one(
            "fig02_evidence_probabilities".into(),
            "Posterior law probabilities P(m | y) from the evidence.".into(),
            FIGURE_SIZE,
            &probabilities,
        )?,
    ])
}
