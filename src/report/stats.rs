//! Weight-aware views of a population for the figures. The posterior summaries and the maps of
//! the library take particles or parameter sets as equally weighted; a population with unequal
//! weights (ABC-SMC) is handed to them as a deterministic systematic resample, and histograms
//! add the weights directly.

use crate::abc::Particle;
use crate::laws::Law;
use std::borrow::Cow;

/// True when every weight equals the first within rounding (rejection sampling gives 1/N to
/// every particle; an empty or single-particle set is trivially equal).
pub(crate) fn equal_weights<'a>(weights: impl IntoIterator<Item = &'a f64>) -> bool {
    let mut weights = weights.into_iter();
    let Some(&first) = weights.next() else {
        return true;
    };
    weights.all(|&w| (w - first).abs() <= 1e-12 * first.abs())
}

/// `count` indices drawn from `weights` by systematic resampling with the fixed offset 1/2
/// (deterministic: the same weights give the same indices). Indices come out ascending.
pub(crate) fn systematic(weights: &[f64], count: usize) -> Vec<usize> {
    let total: f64 = crate::numerics::compensated_sum(weights.iter().copied());
    let mut out = Vec::with_capacity(count);
    if total.is_nan() || total <= 0.0 || weights.is_empty() {
        return out;
    }
    let (mut i, mut cumulative) = (0, weights[0]);
    for j in 0..count {
        let u = (j as f64 + 0.5) / count as f64 * total;
        while cumulative < u && i + 1 < weights.len() {
            i += 1;
            cumulative += weights[i];
        }
        out.push(i);
    }
    out
}

/// The population as equally weighted particles: itself when its weights are equal, else a
/// systematic resample of the same size. What [`crate::abc::posterior::summarize`] and
/// [`crate::abc::posterior::predictive_envelope`] are given.
pub(crate) fn equally_weighted(particles: &[Particle]) -> Cow<'_, [Particle]> {
    if equal_weights(particles.iter().map(|p| &p.weight)) {
        return Cow::Borrowed(particles);
    }
    let weights: Vec<f64> = particles.iter().map(|p| p.weight).collect();
    let n = particles.len();
    Cow::Owned(
        systematic(&weights, n)
            .into_iter()
            .map(|i| Particle {
                weight: 1.0 / n as f64,
                ..particles[i].clone()
            })
            .collect(),
    )
}

/// Up to `count` parameter sets of `law` standing for its posterior: with equal weights the
/// first `count` particles in index order (what `bitrock stability --run` takes), else a
/// systematic resample by weight.
pub(crate) fn law_samples(particles: &[Particle], law: Law, count: usize) -> Vec<&Particle> {
    let members: Vec<&Particle> = particles.iter().filter(|p| p.law == law).collect();
    if equal_weights(members.iter().map(|p| &p.weight)) {
        return members.into_iter().take(count).collect();
    }
    let weights: Vec<f64> = members.iter().map(|p| p.weight).collect();
    systematic(&weights, count.min(members.len()))
        .into_iter()
        .map(|i| members[i])
        .collect()
}

/// A weighted histogram normalised as a density (Σ density · width = 1) over `bins` equal bins
/// of [lo, hi]; values outside fall into the end bins. All zeros when the weights sum to 0.
pub(crate) fn density_histogram(values: &[f64], weights: &[f64], lo: f64, hi: f64, bins: usize) -> Vec<f64> {
    let mut sums = vec![0.0; bins];
    let width = (hi - lo) / bins as f64;
    for (&v, &w) in values.iter().zip(weights) {
        let k = (((v - lo) / width).floor().max(0.0) as usize).min(bins - 1);
        sums[k] += w;
    }
    let total: f64 = crate::numerics::compensated_sum(sums.iter().copied());
    if total > 0.0 {
        for s in &mut sums {
            *s /= total * width;
        }
    }
    sums
}

/// Weighted Pearson correlation of two columns; `None` when either does not vary.
pub(crate) fn weighted_correlation(x: &[f64], y: &[f64], w: &[f64]) -> Option<f64> {
    let total: f64 = w.iter().sum();
    if total.is_nan() || total <= 0.0 {
        return None;
    }
    let mx = x.iter().zip(w).map(|(a, w)| a * w).sum::<f64>() / total;
    let my = y.iter().zip(w).map(|(b, w)| b * w).sum::<f64>() / total;
    let (mut sxy, mut sxx, mut syy) = (0.0, 0.0, 0.0);
    for ((a, b), w) in x.iter().zip(y).zip(w) {
        sxy += w * (a - mx) * (b - my);
        sxx += w * (a - mx) * (a - mx);
        syy += w * (b - my) * (b - my);
    }
    (sxx > 0.0 && syy > 0.0).then(|| (sxy / (sxx.sqrt() * syy.sqrt())).clamp(-1.0, 1.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn systematic_resampling_follows_the_weights() {
        assert_eq!(systematic(&[1.0, 1.0, 1.0, 1.0], 4), vec![0, 1, 2, 3]);
        let idx = systematic(&[0.0, 3.0, 1.0], 8);
        assert_eq!(idx.iter().filter(|&&i| i == 1).count(), 6);
        assert_eq!(idx.iter().filter(|&&i| i == 2).count(), 2);
        assert!(systematic(&[0.0, 0.0], 3).is_empty());
    }

    #[test]
    fn histograms_are_densities_and_count_weights() {
        let h = density_histogram(&[0.1, 0.2, 0.9], &[1.0, 1.0, 2.0], 0.0, 1.0, 2);
        assert!((h[0] - 1.0).abs() < 1e-12 && (h[1] - 1.0).abs() < 1e-12, "{h:?}");
        let r = weighted_correlation(&[1.0, 2.0, 3.0], &[2.0, 4.0, 6.5], &[1.0, 1.0, 1.0]).unwrap();
        assert!(r > 0.99);
        assert!(weighted_correlation(&[1.0, 1.0], &[1.0, 2.0], &[1.0, 1.0]).is_none());
    }
}
