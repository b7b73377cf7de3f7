//! The change rule: when a window's rock is not the windows' before, and the carried law
//! probabilities that follow.

use super::*;

/// How far (nats of log-likelihood) a warm-started law's best particle may lie below its
/// window's least-squares fit: a posterior sampled where it lies comes within a few nats of
/// its peak, so a larger gap says the samplers started from the window before's posterior
/// missed this window's (and the law's evidence came out low, with an error that cannot show
/// it: a proposal blind to a mode is confident).
pub(super) const MISSED_NATS: f64 = 10.0;

/// Whether a law's warm samplers missed its posterior where it matters: its best particle
/// more than [`MISSED_NATS`] below its fit (a fit inside the law's box, which the samplers
/// can reach), and its evidence raised by about that gap would reach the best law's (a law
/// that stays below it cannot become the most probable; a law whose posterior is a funnel
/// keeps its best particle nats below its peak, which alone is no miss). `n`: the samples the
/// window's evidence used.
pub(super) fn missed_mode(analysis: &EvidenceAnalysis, n: usize) -> bool {
    let best = analysis
        .evidence
        .laws
        .iter()
        .map(|e| e.ln_z)
        .fold(f64::NEG_INFINITY, f64::max);
    analysis.fits.iter().any(|fit| {
        let Some(e) = analysis.evidence.of(fit.law) else {
            return false;
        };
        let reachable = analysis
            .prior
            .boxes
            .iter()
            .find(|b| b.law == fit.law)
            .is_some_and(|b| b.admits(&fit.params_si));
        let gap = n as f64 / 2.0 * (e.best_rho / fit.rho).ln();
        reachable && fit.rho > 0.0 && gap > MISSED_NATS && e.ln_z + gap >= best
    })
}

/// One law's line of a window's update: its selection (window probability, ln Z where the
/// evidence gave one), carried probability, and its posterior summarised by a run summary's
/// rule (mean, MAP, 1 % and 99 % quantiles, in the record's torque `unit`) with Kish's ESS of
/// its weighted particles.
pub(super) fn law_update(selected: &Selected, probability: f64, unit: crate::units::TorqueUnit) -> LawUpdate {
    let law = selected.law;
    let members: Vec<&crate::abc::Particle> = selected.posterior.iter().collect();
    let summary =
        (!members.is_empty()).then(|| crate::abc::posterior::summarize_law(law, &members, selected.probability));
    let weights: Vec<f64> = selected.posterior.iter().map(|p| p.weight).collect();
    let in_unit = |v: Option<&Vec<f64>>| match v {
        Some(v) => crate::documents::to_record_units(law, v, unit),
        None => vec![f64::NAN; law.n_params()],
    };
    LawUpdate {
        law,
        probability,
        window_probability: selected.probability,
        ln_z: selected.ln_z.map(|(ln_z, _)| ln_z),
        ln_z_error: selected.ln_z.map(|(_, error)| error),
        mean: in_unit(summary.as_ref().map(|s| &s.mean)),
        map: in_unit(summary.as_ref().map(|s| &s.map)),
        q01: in_unit(summary.as_ref().map(|s| &s.q01)),
        q99: in_unit(summary.as_ref().map(|s| &s.q99)),
        ess: crate::abc::effective_sample_size(&weights),
    }
}

/// The log-likelihood (nats) the earlier window's fits lose on this window: (n/2)·ln(ρ_then /
/// ρ_now), ρ_then the smallest ρ here of any law at its earlier fit, ρ_now the smallest of the
/// laws fitted here (among the laws fitted both times). The old formation is gone only where
/// none of its fitted laws still explains the samples: taking one law's fit alone (the best
/// here) calls a change whenever a law whose parameters lie on a ridge (m3, m4) moved along
/// it between two windows of the same rock. The earlier fits held at the weight on bit
/// `holds_at_n` (N): here their torque is scaled by each sample's WOB over it, as the
/// evidence's WOB-scaled model has it, so that a change of weight on bit in one rock is not a
/// change of rock.
pub(super) fn loss_nats(
    before: &Fits,
    holds_at_n: Option<f64>,
    now: &[crate::fit::LawFit],
    samples: &crate::data::Samples,
) -> Option<f64> {
    let sum_sq = samples.sum_sq_torque();
    let rho_now = now
        .iter()
        .filter(|f| f.rho.is_finite() && f.rho > 0.0)
        .filter(|f| before.iter().any(|(law, _)| *law == f.law))
        .map(|f| f.rho)
        .min_by(f64::total_cmp)?;
    let rho_then = before
        .iter()
        .filter(|(law, _)| now.iter().any(|f| f.law == *law))
        .map(|(law, old)| {
            let residuals = crate::fit::residuals(*law, old, samples, holds_at_n);
            residuals.iter().map(|e| e * e).sum::<f64>() / sum_sq
        })
        .filter(|rho| rho.is_finite())
        .min_by(f64::total_cmp)?;
    let n = samples.len() as f64;
    Some(0.5 * n * (rho_then / rho_now).ln())
}

/// `weights` normalised to sum 1 with none below `floor` (those raised to it, the others
/// scaled down to make room).
pub(super) fn normalise_with_floor(weights: &[f64], floor: f64) -> Vec<f64> {
    let total: f64 = weights.iter().sum();
    let mut p: Vec<f64> = if total > 0.0 && total.is_finite() {
        weights.iter().map(|w| w / total).collect()
    } else {
        vec![1.0 / weights.len() as f64; weights.len()]
    };
    // Raise the laws under the floor; take what they gain from the others in proportion.
    let low: f64 = p.iter().filter(|&&v| v < floor).count() as f64 * floor;
    let high: f64 = p.iter().filter(|&&v| v >= floor).sum();
    if high > 0.0 && low > 0.0 {
        for v in &mut p {
            *v = if *v < floor { floor } else { *v * (1.0 - low) / high };
        }
    }
    p
}
