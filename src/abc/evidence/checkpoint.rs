//! The samplers' state saved between scored batches and resumed bit for bit.

use super::*;

/// Where the samplers save their state as they go, and the state an interrupted sampling of
/// the same job resumes from: the islands between two scored batches (particles, weights,
/// tempering, proposal scales, each island's position in its random stream), so that a
/// resumed sampling scores the very candidates the uninterrupted one would, and ends with its
/// evidence bit for bit.
pub struct Checkpoints<'a> {
    /// The bytes [`Checkpoints::save`] was last given by an interrupted sampling of the same
    /// job (prior, seed, settings and references); `None`: from the start.
    pub from: Option<&'a [u8]>,
    /// Where the saved state is kept: named when the state is refused.
    pub origin: &'a std::path::Path,
    /// Least seconds between two saves; the state with every sampler done is always saved.
    pub every_s: f64,
    /// Keeps the state's bytes (an evidence directory writes them to disk).
    pub save: &'a mut dyn FnMut(&[u8]) -> Result<()>,
}

/// Whether a saved island started from a reference: it then keeps each particle's (or first
/// draw's) reference density.
pub(super) fn started_from_reference(island: &Island) -> bool {
    !island.ln_q.is_empty() || !island.proposal_ln_q.is_empty()
}

/// The state [`Checkpoints::save`] is given: seconds spent so far and the islands.
pub(super) fn encode_state(seconds: f64, islands: &[Island]) -> Vec<u8> {
    postcard::to_stdvec(&(seconds, islands)).expect("the samplers' state serialises")
}

/// The islands of a saved state (kept in `origin`), checked against `fresh` (those the job
/// makes at its start): the same laws, slots, streams and particle counts, or the state is
/// another job's. Islands beyond `fresh` are refinements ([`refine`](super::refine)), each
/// checked against the first-round island it refines (`span` streams a round, at most
/// `rounds` rounds), each stream once.
pub(super) fn decode_state(
    bytes: &[u8],
    origin: &std::path::Path,
    fresh: &[Island],
    (span, rounds): (u32, usize),
) -> Result<(f64, Vec<Island>)> {
    let refuse = |why: &str| Error::Data {
        path: origin.to_path_buf(),
        message: format!("the saved state of the evidence's samplers is not this job's: {why}"),
    };
    let (seconds, mut islands): (f64, Vec<Island>) =
        postcard::from_bytes(bytes).map_err(|e| refuse(&format!("it does not read ({e})")))?;
    if islands.len() < fresh.len() {
        return Err(refuse(&format!(
            "{} samplers where the job runs {}",
            islands.len(),
            fresh.len()
        )));
    }
    let mut streams = std::collections::HashSet::new();
    for (k, saved) in islands.iter_mut().enumerate() {
        let (round, first) = super::refine::round_of(saved, span);
        if round > rounds || !streams.insert(saved.stream.stream) {
            return Err(refuse(&format!(
                "its sampler {} is not one of the job's refinements",
                saved.stream.stream
            )));
        }
        let new = match fresh.get(k) {
            Some(new) if round == 0 => new,
            None if round > 0 => fresh.iter().find(|f| f.stream.stream == first).ok_or_else(|| {
                refuse(&format!(
                    "its sampler {} refines none of the job's",
                    saved.stream.stream
                ))
            })?,
            _ => return Err(refuse(&format!("its sampler {} is out of order", saved.stream.stream))),
        };
        let particles = |i: &Island| i.theta.len().max(i.proposals.len());
        let let_go = saved.let_go_of();
        if saved.law != new.law
            || saved.slot != new.slot
            || saved.dims != new.dims
            || saved.lower.map(f32::to_bits) != new.lower.map(f32::to_bits)
            || saved.upper.map(f32::to_bits) != new.upper.map(f32::to_bits)
            || saved.stream.seed != new.stream.seed
            || first != new.stream.stream
            || (!let_go && particles(saved) != particles(new) << round)
            || (!let_go && started_from_reference(saved) != new.reference.is_some())
        {
            return Err(refuse(&format!(
                "its sampler {} of law {} differs",
                saved.stream.stream, saved.law
            )));
        }
        // A law's prior cut to the record's torques is not saved either: a state whose scored
        // particles lie outside the cut was sampled under another prior (the whole box).
        if let Some(curve) = &new.curve {
            let outside = saved
                .theta
                .iter()
                .zip(&saved.loglik)
                .any(|(p, l)| *l > f64::NEG_INFINITY && !curve.holds(saved.law, &p[..saved.dims]));
            if outside {
                return Err(refuse(&format!(
                    "its sampler {} of law {} holds particles outside the law's prior (its box cut to the curves within the record's torques): it was sampled under another prior",
                    saved.stream.stream, saved.law
                )));
            }
        }
        // The reference is not saved: the job makes it again, the same.
        saved.reference = new.reference.clone();
        saved.curve = new.curve.clone();
    }
    Ok((seconds, islands))
}
