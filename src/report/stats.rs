//! Weighted histograms and correlations for the figures (the posterior summaries weigh
//! particles themselves; see [`crate::abc::posterior`]).

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
    fn histograms_are_densities_and_count_weights() {
        let h = density_histogram(&[0.1, 0.2, 0.9], &[1.0, 1.0, 2.0], 0.0, 1.0, 2);
        assert!((h[0] - 1.0).abs() < 1e-12 && (h[1] - 1.0).abs() < 1e-12, "{h:?}");
        let r = weighted_correlation(&[1.0, 2.0, 3.0], &[2.0, 4.0, 6.5], &[1.0, 1.0, 1.0]).unwrap();
        assert!(r > 0.99);
        assert!(weighted_correlation(&[1.0, 1.0], &[1.0, 2.0], &[1.0, 1.0]).is_none());
    }
}
