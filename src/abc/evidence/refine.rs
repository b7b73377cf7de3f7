//! Refinement: where a law's reported ln Z is uncertain by more than half of
//! [`REFINE_ABOVE_NATS`] because the islands of a start it keeps spread by more than that,
//! those islands are run again, each from its own fresh stream, with twice the particles, up
//! to [`EvidenceConfig::refine_rounds`] times. The islands refined are let go
//! (their particles dropped, their counts kept), and the law reports its latest round.
//!
//! Every first-round island has a stream below [`round_span`]; its refinement in round r runs
//! on r·span + that stream, so that a round and a start are read off any island's stream, and
//! a resumed sampling remakes the same islands.

use super::*;

/// Streams of one round: one per (start, law, island) that the first round can hold.
pub(super) fn round_span(laws: usize, config: &EvidenceConfig) -> u32 {
    (2 * laws * config.islands) as u32
}

/// An island's round (0: the first) and its first-round stream.
pub(super) fn round_of(island: &Island, span: u32) -> (usize, u32) {
    ((island.stream.stream / span) as usize, island.stream.stream % span)
}

/// The starts of a law's islands, in the order of their streams: the box's, then the
/// reference's where there is one and both are asked for.
pub(super) fn starts_of<'a>(config: &EvidenceConfig, reference: Option<&'a Reference>) -> Vec<Option<&'a Reference>> {
    match (config.start, reference) {
        (Start::Both, Some(reference)) => vec![None, Some(reference)],
        (_, reference) => vec![reference],
    }
}

/// The reference `law`'s samplers may start from (one whose covariance fits the law).
pub(super) fn reference_of(references: &[Reference], law: Law) -> Option<&Reference> {
    references
        .iter()
        .find(|r| r.law == law && r.covariance.len() == law.n_params().pow(2))
}

/// The islands of prior slot `slot` that its evidence is read from: of each start, those of
/// its latest round.
pub(super) fn current(islands: &[Island], slot: usize, span: u32, per_start: u32) -> Vec<&Island> {
    let start_of = |i: &Island| round_of(i, span).1 / per_start;
    let latest = |start: u32| {
        islands
            .iter()
            .filter(|i| i.slot == slot && start_of(i) == start)
            .map(|i| round_of(i, span).0)
            .max()
    };
    islands
        .iter()
        .filter(|i| i.slot == slot && Some(round_of(i, span).0) == latest(start_of(i)))
        .collect()
}

/// Adds to `islands` (all done) the next round of every law's start whose latest islands'
/// ln Z spread by more than [`REFINE_ABOVE_NATS`] with rounds left, and lets go of those they
/// refine. False where nothing needs refining.
pub(super) fn refine(
    islands: &mut Vec<Island>,
    prior: &crate::prior::Prior,
    config: &EvidenceConfig,
    references: &[Reference],
) -> bool {
    let laws = prior.boxes.len();
    let span = round_span(laws, config);
    let per_start = (laws * config.islands) as u32;
    // (stream to let go, its refinement's law slot, stream, round and reference): all of them
    // let go before any refinement is made, so that memory holds one round at a time.
    let mut planned = Vec::new();
    for (slot, bx) in prior.boxes.iter().enumerate() {
        let now = current(islands, slot, span, per_start);
        // A law whose reported ln Z is already this precise (its kept start's islands agree,
        // or a precise start outweighs a scattered one) spends nothing more.
        let kept = kept_estimate(&now, config, 0.0);
        if kept.ln_z_error <= REFINE_ABOVE_NATS / 2.0 {
            continue;
        }
        let starts = starts_of(config, reference_of(references, bx.law));
        for (start, reference) in starts.into_iter().enumerate() {
            // A start whose estimate the law does not keep (the lower of two that disagree)
            // spends nothing more either: refining it would not make the law's ln Z surer.
            if kept.starts.get(start).is_some_and(|s| !s.kept) {
                continue;
            }
            let latest: Vec<&Island> = now
                .iter()
                .copied()
                .filter(|i| round_of(i, span).1 / per_start == start as u32)
                .collect();
            let Some(round) = latest.first().map(|i| round_of(i, span).0) else {
                continue;
            };
            let ln_z: Vec<f64> = latest.iter().map(|i| i.ln_z).collect();
            if round >= config.refine_rounds || spread_of(&ln_z) <= REFINE_ABOVE_NATS {
                continue;
            }
            for island in latest {
                let first = round_of(island, span).1;
                let stream = (round as u32 + 1) * span + first;
                planned.push((island.stream.stream, slot, stream, round + 1, reference));
            }
        }
    }
    for island in islands.iter_mut() {
        if planned.iter().any(|&(old, ..)| old == island.stream.stream) {
            island.let_go();
        }
    }
    let any = !planned.is_empty();
    for (_, slot, stream, round, reference) in planned {
        let bx = &prior.boxes[slot];
        let next = config.of_round(round);
        islands.push(Island::new(slot, bx, &next, stream, reference));
    }
    any
}
