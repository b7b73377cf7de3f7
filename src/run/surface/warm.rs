//! A sampler warm-started from an earlier posterior (a watch's window before): population 0
//! drawn near it, weighted back to the prior.
//!
//! Population 0 is an importance sample of the prior: N candidates inside the laws' priors
//! (their boxes, cut to the curves within the record's torques where a law's is) from
//! q(m, θ) = q(m)·q_m(θ), each weighted π(m)·π(θ|m) / q(m, θ) and normalised. The law is drawn
//! by q(m) = (1 − f)·P_before(m) + f·π(m), f = [`LAW_DEFENSIVE_SHARE`]: every law keeps
//! draws, so a law the window before ruled out can return. A law's θ comes from the kernel
//! density of its earlier particles mixed with its box ([`Kernels`], the evidence's warm start:
//! a tenth from the box), or from its box alone where it had too few particles. Restricted to
//! ρ < ε a weighted sample of the prior is one of the ABC posterior at ε, so the SMC goes on
//! from it as from a population drawn from the prior: its survivors and kernels simply start
//! where the earlier posterior was. Where the rock has changed, the box's share keeps the
//! weights bounded and the sampler finds the new posterior from there.

use super::*;
use crate::abc::evidence::{DEFENSIVE_SHARE, Kernels, Reference, Stream};
use crate::eval::Evaluator;

/// Share of population 0's laws drawn by the prior's law weights rather than the earlier
/// posterior's.
pub const LAW_DEFENSIVE_SHARE: f64 = 0.1;

/// Seed offset of population 0's draws, apart from every other stream of a run.
const WARM_STREAM: u64 = 0x5741_524d_0000_0000;

/// Whether a run of `prior` can be warm-started: boxes holding a law's parameters alone.
pub(super) fn can_warm_start(prior: &Prior) -> bool {
    prior.boxes.iter().all(|b| b.lower.len() == b.law.n_params())
}

/// Population 0 of up to `n` particles near `before` (an earlier posterior, weights summing
/// to any positive total), scored by `evaluator` (see the module documentation); `None` where
/// every string left physical bounds (the sampler then starts from the prior).
pub(super) fn warm_population(
    evaluator: &SurfaceEvaluator,
    before: &[Particle],
    n: usize,
    seed: u64,
) -> Result<Option<Population>> {
    let started = std::time::Instant::now();
    let problem = evaluator.problem();
    let prior = &problem.prior;
    let slots = prior.boxes.len();
    let Drawn {
        candidates,
        ln_weights,
        drawn,
        draws,
    } = draw_near(prior, before, n, seed);
    let mut rhos = vec![0.0; candidates.len()];
    evaluator.score_params(&candidates, &mut rhos)?;
    // A string that left physical bounds never lies below a tolerance: weight 0.
    let kept: Vec<usize> = (0..candidates.len()).filter(|&i| rhos[i].is_finite()).collect();
    if kept.is_empty() {
        return Ok(None);
    }
    let top = kept.iter().map(|&i| ln_weights[i]).fold(f64::NEG_INFINITY, f64::max);
    let raw: Vec<f64> = kept.iter().map(|&i| (ln_weights[i] - top).exp()).collect();
    let sum: f64 = raw.iter().sum();
    let particles: Vec<Particle> = kept
        .iter()
        .zip(&raw)
        .map(|(&i, w)| {
            let c = &candidates[i];
            let d = prior.boxes[c.slot].lower.len();
            Particle {
                law: prior.law(c.slot),
                index: i as u64,
                params: c.widened()[..d].to_vec(),
                rho: rhos[i],
                weight: w / sum,
            }
        })
        .collect();
    let weights: Vec<f64> = particles.iter().map(|p| p.weight).collect();
    let per_law = (0..slots)
        .map(|s| {
            let law = prior.law(s);
            let own = particles.iter().filter(|p| p.law == law);
            let accepted = own.clone().count();
            let probability = own.map(|p| p.weight).sum();
            crate::abc::LawRecord::new(
                law,
                drawn[s],
                accepted,
                probability,
                accepted > 0,
                problem,
                f64::INFINITY,
            )
        })
        .collect();
    let scored = candidates.len() as u64;
    Ok(Some(Population {
        record: crate::abc::PopulationRecord {
            index: 0,
            epsilon: None,
            draws,
            accepted: particles.len(),
            acceptance_rate: particles.len() as f64 / draws as f64,
            per_law,
            candidates_scored: scored,
            evaluations: scored * problem.data_len() as u64,
            near_threshold: 0,
            ess: crate::abc::effective_sample_size(&weights),
            seconds: started.elapsed().as_secs_f64(),
            stream: 0,
        },
        particles,
    }))
}

/// Candidates drawn near an earlier posterior, with their log importance weights
/// ln π(m, θ) − ln q(m, θ) (unnormalised).
struct Drawn {
    candidates: Vec<Candidate>,
    ln_weights: Vec<f64>,
    /// Candidates drawn per prior slot (inside their box or not), and in all.
    drawn: Vec<u64>,
    draws: u64,
}

/// `n` candidates inside the boxes of `prior` from q(m, θ) near `before` (see the module
/// documentation).
fn draw_near(prior: &Prior, before: &[Particle], n: usize, seed: u64) -> Drawn {
    let slots = prior.boxes.len();
    let total: f64 = before.iter().map(|p| p.weight).sum();
    let share = |law: Law| before.iter().filter(|p| p.law == law).map(|p| p.weight).sum::<f64>() / total;
    let q_law: Vec<f64> = (0..slots)
        .map(|s| (1.0 - LAW_DEFENSIVE_SHARE) * share(prior.law(s)) + LAW_DEFENSIVE_SHARE * prior.weights[s])
        .collect();
    let law_cdf = crate::abc::smc::normalised_cdf(&q_law);
    let kernels: Vec<Option<Kernels>> = prior
        .boxes
        .iter()
        .map(|b| {
            let own: Vec<(&[f64], f64)> = before
                .iter()
                .filter(|p| p.law == b.law)
                .map(|p| (p.params.as_slice(), p.weight))
                .collect();
            Reference::from_posterior(b.law, &own).map(|r| Kernels::new(&r, &b.lower, &b.upper))
        })
        .collect();
    // ln of each box's volume: the density of a draw uniform on it is its negative.
    let ln_box_volume: Vec<f64> = prior
        .boxes
        .iter()
        .map(|b| {
            b.lower
                .iter()
                .zip(&b.upper)
                .map(|(lo, hi)| (f64::from(*hi) - f64::from(*lo)).ln())
                .sum::<f64>()
        })
        .collect();
    // ln of the volume each law's prior is uniform on, the box's or the part of it its curve's
    // limit keeps: the prior's density is its negative there.
    let ln_prior_volume: Vec<f64> = prior
        .boxes
        .iter()
        .zip(&ln_box_volume)
        .map(|(b, v)| v + b.curve.as_ref().map_or(0.0, |c| c.ln_share))
        .collect();
    let mut stream = Stream {
        seed: seed ^ WARM_STREAM,
        stream: 0,
        next: 0,
    };
    let mut candidates = Vec::with_capacity(n);
    let mut ln_weights = Vec::with_capacity(n);
    let mut drawn = vec![0u64; slots];
    let mut draws = 0u64;
    // Every law's draws are its box's at least DEFENSIVE_SHARE of the time, all inside it and a
    // share of them inside its curve's limit: the loop ends.
    while candidates.len() < n {
        draws += 1;
        let slot = crate::abc::smc::inverse_cdf(&law_cdf, stream.uniform());
        drawn[slot] += 1;
        let b = &prior.boxes[slot];
        let d = b.lower.len();
        let mut params = [0.0f32; MAX_DIMS];
        match &kernels[slot] {
            Some(k) if stream.uniform() >= DEFENSIVE_SHARE => k.draw(&mut stream, &mut params),
            _ => stream.uniform_in(&b.lower, &b.upper, &mut params),
        }
        if !b.admits_f32(&params[..d]) {
            continue; // the prior's density is 0 there: weight 0
        }
        // q is the density the draw was made from, on the whole box (a draw outside the cut is
        // dropped above: that leaves every kept draw's density divided by one constant).
        let ln_q_theta = match &kernels[slot] {
            Some(k) => k.ln_q(&params[..d], true),
            None => -ln_box_volume[slot],
        };
        ln_weights.push(prior.weights[slot].ln() - ln_prior_volume[slot] - q_law[slot].ln() - ln_q_theta);
        candidates.push(Candidate { slot, params });
    }
    Drawn {
        candidates,
        ln_weights,
        drawn,
        draws,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::prior::LawBox;

    /// `n` particles of `law` of equal weight, each parameter its `centre` plus a uniform
    /// jitter of `width` (a linear congruential generator seeded by `seed`).
    fn cloud(law: Law, centre: &[f64], width: &[f64], n: u64, seed: u64) -> Vec<Particle> {
        let mut state = seed;
        let mut jitter = || {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        (0..n)
            .map(|index| Particle {
                law,
                index,
                params: centre.iter().zip(width).map(|(c, w)| c + w * jitter()).collect(),
                rho: 0.0,
                weight: 1.0 / n as f64,
            })
            .collect()
    }

    /// Weighted, population 0 is the prior: its law shares are the prior's law weights and
    /// each coordinate's weighted mean is its box's middle, though most draws lie near the
    /// earlier posterior.
    #[test]
    fn population_0_near_an_earlier_posterior_is_weighted_back_to_the_prior() {
        let prior = Prior::new(
            vec![
                LawBox::new(Law::M1, vec![0.0, 0.0, 0.0, 0.0], vec![10.0, 5.0, 5.0, 5.0]),
                LawBox::new(Law::M2, vec![1000.0, 500.0, 0.0], vec![20_000.0, 10_000.0, 10.0]),
            ],
            vec![0.5, 0.5],
        )
        .unwrap();
        // The earlier posterior: m2 alone, tight around (13,000, 6,500, 0.3).
        let before = cloud(Law::M2, &[13_000.0, 6_500.0, 0.3], &[400.0, 200.0, 0.1], 300, 7);
        let n = 20_000;
        let drawn = draw_near(&prior, &before, n, 3);
        assert_eq!(drawn.candidates.len(), n);
        let top = drawn.ln_weights.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let w: Vec<f64> = drawn.ln_weights.iter().map(|l| (l - top).exp()).collect();
        let total: f64 = w.iter().sum();
        let of = |slot: usize| drawn.candidates.iter().zip(&w).filter(move |(c, _)| c.slot == slot);
        let m2_share = of(1).map(|(_, w)| w).sum::<f64>() / total;
        assert!((m2_share - 0.5).abs() < 0.05, "{m2_share}");
        let m2_weight: f64 = of(1).map(|(_, w)| w).sum();
        for (j, (lo, hi)) in [(1000.0, 20_000.0), (500.0, 10_000.0), (0.0, 10.0)]
            .into_iter()
            .enumerate()
        {
            let mean = of(1).map(|(c, w)| w * f64::from(c.params[j])).sum::<f64>() / m2_weight;
            let middle = 0.5 * (lo + hi);
            assert!(
                (mean - middle).abs() < 0.06 * (hi - lo),
                "coordinate {j}: {mean} against {middle}"
            );
        }
        // Most draws are m2's, near the earlier posterior.
        let near = drawn
            .candidates
            .iter()
            .filter(|c| c.slot == 1 && (f64::from(c.params[0]) - 13_000.0).abs() < 2_000.0)
            .count();
        assert!(near as f64 > 0.6 * n as f64, "{near} of {n}");
        // Every law keeps draws: one the earlier posterior ruled out can return.
        assert!(drawn.drawn[0] as f64 > 0.03 * n as f64, "{:?}", drawn.drawn);
    }

    /// A law whose box is cut to a curve is drawn inside the cut and weighted by its prior's
    /// density there (one over the volume the cut keeps): weighted, its share is still its
    /// prior weight and its draws are uniform on the cut.
    #[test]
    fn population_0_keeps_a_cut_law_s_draws_inside_its_cut_and_weighs_them_by_it() {
        // m4 nearly c0 + c1·w over speeds 0..1 (c2 and c3 within a hundredth), cut to
        // |T| ≤ 3 (about half its box); the earlier posterior m4 alone, tight near c0 = 1,
        // c1 = 1, or m2 alone.
        let mut prior = Prior::new(
            vec![
                LawBox::new(Law::M2, vec![1.0, 0.5, 0.0], vec![2.0, 1.0, 1.0]),
                LawBox::new(Law::M4, vec![0.0, -4.0, 0.0, 0.0], vec![4.0, 4.0, 0.01, 0.01]),
            ],
            vec![0.5, 0.5],
        )
        .unwrap();
        let m4 = &mut prior.boxes[1];
        m4.curve = Some(crate::prior::CurveLimit::new(Law::M4, 3.0, 1.0, 1.0, (&m4.lower, &m4.upper)).unwrap());
        assert!(can_warm_start(&prior));
        let before = cloud(Law::M4, &[1.0, 1.0, 0.005, 0.005], &[0.2, 0.2, 0.002, 0.002], 200, 11);
        // c0's mean on the cut, from the prior's own draws.
        let (mut sum, mut count) = (0.0, 0usize);
        for i in 0..40_000 {
            let c = prior.candidate(8, 0, i);
            if c.slot == 1 {
                sum += f64::from(c.params[0]);
                count += 1;
            }
        }
        let on_cut = sum / count as f64;
        // m4 drawn near its earlier particles (a kernel), then from its box alone (the
        // earlier posterior m2's: too few of m4's for a kernel).
        let m2_before = cloud(Law::M2, &[1.5, 0.75, 0.5], &[0.2, 0.1, 0.2], 200, 13);
        for before in [before, m2_before] {
            let n = 40_000;
            let drawn = draw_near(&prior, &before, n, 5);
            let top = drawn.ln_weights.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            let w: Vec<f64> = drawn.ln_weights.iter().map(|l| (l - top).exp()).collect();
            let total: f64 = w.iter().sum();
            let m4_draws = || drawn.candidates.iter().zip(&w).filter(|(c, _)| c.slot == 1);
            for (c, _) in m4_draws() {
                assert!(prior.boxes[1].admits_f32(&c.params[..4]), "{c:?}");
            }
            let m4_weight: f64 = m4_draws().map(|(_, w)| w).sum();
            assert!((m4_weight / total - 0.5).abs() < 0.05, "{}", m4_weight / total);
            // c0's weighted mean against its mean on the cut.
            let mean = m4_draws().map(|(c, w)| w * f64::from(c.params[0])).sum::<f64>() / m4_weight;
            assert!((mean - on_cut).abs() < 0.1, "{mean} against {on_cut}");
        }
    }
}
