//! The model choice checked by re-simulation: records re-simulated from each law's posterior,
//! classified by their nearest neighbours among other records simulated from the laws'
//! posteriors, as many for each law, and the verdict.
//!
//! The reference is each law's posterior, not the prior: the question is whether the summaries
//! tell the laws' records apart where the record lies. A prior's reference table is mostly
//! strings far from the record (6 of the pilot's 888 within the sampler's final tolerance on
//! a ten-minute record of m1 at 40 rpm), so the votes of its nearest twentieth would say which
//! law's prior puts more strings somewhere around the record, and a law whose posterior is a
//! small corner of its box would be taken for another whose box is wider there. Each law gets
//! as many reference records, so that a law's votes are how near its records lie, not its
//! probability (which is what the check checks), and a re-simulation never counts its own
//! particle's reference record: a law of a handful of particles would otherwise recognise
//! itself by its parameters alone. A law lost from the populations is represented by its
//! pilot strings nearest the record, so that a law left alone is still asked whether its
//! records could be the others'.

use super::*;

/// Records simulated from each law's posterior as the check's reference.
pub const REFERENCE_PER_LAW: usize = 60;
/// Neighbours each classification takes among the reference records.
pub const CHECK_NEIGHBOURS: usize = 10;

/// What keys the reference records' resampling and noise apart from the re-simulations'.
const REFERENCE_TAG: u64 = 0x5245_4653;

/// The model choice checked by re-simulation (see the module documentation).
#[allow(clippy::too_many_arguments)]
pub(super) fn check(
    prior: &Prior,
    model: &SurfaceModel,
    distance: &Distance,
    table: &[(usize, Summaries)],
    laws: &[LawPosterior],
    particles: &[Particle],
    replicates: usize,
    seed: u64,
    cycle: &Cycle,
    unconverged: Option<f64>,
) -> Result<(ModelCheck, u64)> {
    let own_of = |law: Law| -> Vec<&Particle> { particles.iter().filter(|p| p.law == law).collect() };
    // Each reference record's law, the particle it was simulated from (none for a pilot
    // string), and its summaries.
    let mut reference: Vec<(usize, Option<&Particle>, Summaries)> = Vec::new();
    let mut simulated_reference = 0u64;
    for (slot, posterior) in laws.iter().enumerate() {
        if posterior.particles == 0 {
            // A law lost from the populations: its pilot strings nearest the record.
            let mut nearest: Vec<(f64, &Summaries)> = table
                .iter()
                .filter(|(s, _)| *s == slot)
                .map(|(_, summaries)| (distance.rho(summaries), summaries))
                .collect();
            nearest.sort_by(|a, b| a.0.total_cmp(&b.0));
            reference.extend(nearest.iter().take(REFERENCE_PER_LAW).map(|(_, s)| (slot, None, **s)));
            continue;
        }
        let drawn = resample(
            &own_of(posterior.law),
            REFERENCE_PER_LAW,
            seed ^ REFERENCE_TAG ^ (slot as u64 + 1),
        );
        let runs = model.simulate_noiseless_many(&strings_of(&drawn))?;
        simulated_reference += runs.len() as u64;
        let simulated: Vec<Option<Summaries>> = runs
            .into_par_iter()
            .enumerate()
            .with_max_len(1)
            .map(|(k, mut run)| {
                let key = NoiseKey::replicate(seed ^ REFERENCE_TAG, (slot * REFERENCE_PER_LAW + k) as u64);
                model.add_noise(&mut run, key);
                (!run.diverged).then(|| model.summaries_of_run(&run))
            })
            .collect();
        for (particle, summaries) in drawn.into_iter().zip(simulated) {
            if let Some(summaries) = summaries {
                reference.push((slot, Some(particle), summaries));
            }
        }
    }
    let neighbours = CHECK_NEIGHBOURS.min(reference.len());
    // The law most of the re-simulation's nearest reference records were simulated from, none
    // of them from its own particle; None where no reference record is left.
    let classify = |s: &Summaries, source: &Particle| -> Option<usize> {
        let mut near: Vec<(f64, usize)> = reference
            .iter()
            .filter(|(_, particle, _)| particle.is_none_or(|p| !std::ptr::eq(p, source)))
            .map(|(slot, _, r)| (distance.between(s, r), *slot))
            .collect();
        let neighbours = neighbours.min(near.len());
        if neighbours == 0 {
            return None;
        }
        near.select_nth_unstable_by(neighbours - 1, |a, b| a.0.total_cmp(&b.0));
        let mut votes = vec![0usize; prior.boxes.len()];
        for (_, slot) in &near[..neighbours] {
            votes[*slot] += 1;
        }
        // Ties go to the earlier law: deterministic.
        (0..votes.len()).max_by_key(|&k| (votes[k], std::cmp::Reverse(k)))
    };
    let mut rows = Vec::new();
    for (slot, posterior) in laws.iter().enumerate() {
        if posterior.particles == 0 {
            continue;
        }
        let drawn = resample(&own_of(posterior.law), replicates, seed ^ (slot as u64 + 1));
        let runs = model.simulate_noiseless_many(&strings_of(&drawn))?;
        let classes: Vec<Option<usize>> = runs
            .into_par_iter()
            .zip(drawn.par_iter())
            .enumerate()
            .with_max_len(1)
            .map(|(k, (mut run, source))| {
                let key = NoiseKey::replicate(seed, (slot * replicates + k) as u64);
                model.add_noise(&mut run, key);
                if run.diverged {
                    return None;
                }
                classify(&model.summaries_of_run(&run), source)
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
    let (decided, verdict) = verdict(laws, &rows, cycle, unconverged);
    let check = ModelCheck {
        reference: reference.len(),
        neighbours,
        rows,
        decided,
        verdict,
    };
    Ok((check, simulated_reference))
}

/// The law called and why (see [`CHECK_RECOGNISED`]). None is called while the sampler's
/// strings do not reproduce the record (`unconverged`: its final tolerance, in noise floors, at
/// [`UNCONVERGED_FACTOR`] or more): the leader is then only the least wrong of the laws tried,
/// and a law the sampler has not yet found near the record (a wide box, a law lost from the
/// populations, which then takes no part in the check) may be the one that made it.
pub(super) fn verdict(
    laws: &[LawPosterior],
    rows: &[CheckRow],
    cycle: &Cycle,
    unconverged: Option<f64>,
) -> (Option<Law>, String) {
    if let Some(why) = cycle.uninformative("record") {
        return (None, format!("{why}; no law is called"));
    }
    let Some(best) = laws.iter().max_by(|a, b| a.probability.total_cmp(&b.probability)) else {
        return (None, "no law has particles".into());
    };
    if let Some(times) = unconverged {
        return (
            None,
            format!(
                "{} leads (P = {:.2}), but the sampler stopped at {times:.1} times the noise's own distance: its strings do not yet reproduce the record, and a law it has not found near the record may be the one that made it; no law is called (raise `max_populations` or `particles`)",
                best.law, best.probability
            ),
        );
    }
    let recognised = |law: Law| rows.iter().find(|r| r.law == law).map_or(0.0, |r| r.recognised);
    let taken_for_best = |r: &CheckRow| {
        let n: usize = r.classified_as.iter().map(|c| c.1).sum();
        r.classified_as
            .iter()
            .find(|c| c.0 == best.law)
            .map_or(0.0, |c| c.1 as f64 / n.max(1) as f64)
    };
    let confused: Vec<Law> = rows
        .iter()
        .filter(|r| r.law != best.law)
        .filter(|r| taken_for_best(r) > CHECK_CONFUSED)
        .map(|r| r.law)
        .collect();
    let (decided, text) =
        crate::run::answer::resimulation_verdict(best.law, best.probability, recognised(best.law), &confused, "law");
    // A law the sampler lost has no records to re-simulate: the call holds for the laws it kept,
    // and says which it could not test (a wide box can lose the law that made the record).
    let lost: Vec<String> = laws
        .iter()
        .filter(|l| l.particles == 0)
        .map(|l| l.law.to_string())
        .collect();
    match decided {
        Some(_) if !lost.is_empty() => (
            decided,
            format!(
                "{text}; {} left the populations and could not be tested",
                lost.join(", ")
            ),
        ),
        _ => (decided, text),
    }
}
