//! Small numerical building blocks shared by the fit, the samplers and the reports.

/// Neumaier's compensated sum: the error stays O(ε) instead of growing with the count, which
/// keeps ρ = Σ(y − T)² / Σy² exact to the last digits over 10⁶ samples.
pub fn compensated_sum(values: impl IntoIterator<Item = f64>) -> f64 {
    let mut sum = 0.0f64;
    let mut carry = 0.0f64;
    for v in values {
        let t = sum + v;
        if sum.abs() >= v.abs() {
            carry += (sum - t) + v;
        } else {
            carry += (v - t) + sum;
        }
        sum = t;
    }
    sum + carry
}

/// The q-quantile (0 ≤ q ≤ 1) of `values` by linear interpolation between order statistics
/// (type 7, as numpy's default). `values` need not be sorted; NaNs are not expected.
pub fn quantile(values: &[f64], q: f64) -> f64 {
    assert!(!values.is_empty(), "quantile of an empty set");
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    let h = q.clamp(0.0, 1.0) * (v.len() - 1) as f64;
    let lo = h.floor() as usize;
    let hi = h.ceil() as usize;
    v[lo] + (h - lo as f64) * (v[hi] - v[lo])
}

/// `count` values spaced geometrically from `lo` to `hi` inclusive (lo, hi > 0).
pub fn geomspace(lo: f64, hi: f64, count: usize) -> Vec<f64> {
    if count == 1 {
        return vec![lo];
    }
    let ratio = (hi / lo).powf(1.0 / (count - 1) as f64);
    (0..count).map(|i| lo * ratio.powi(i as i32)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn compensation_recovers_what_naive_summation_loses() {
        // 1 + 10⁶ × 1e-16: the naive sum stays at 1, the exact answer is 1 + 1e-10.
        let values = std::iter::once(1.0).chain(std::iter::repeat_n(1e-16, 1_000_000));
        let s = compensated_sum(values);
        assert!((s - (1.0 + 1e-10)).abs() < 1e-15, "{s}");
    }

    #[test]
    fn quantiles_interpolate() {
        let v = [3.0, 1.0, 2.0, 4.0];
        assert!((quantile(&v, 0.5) - 2.5).abs() < 1e-15);
        assert!((quantile(&v, 0.0) - 1.0).abs() < 1e-15);
        assert!((quantile(&v, 1.0) - 4.0).abs() < 1e-15);
        assert!((quantile(&v, 1.0 / 3.0) - 2.0).abs() < 1e-15);
    }

    #[test]
    fn geomspace_hits_both_ends() {
        let g = geomspace(0.1, 10.0, 3);
        assert!((g[1] - 1.0).abs() < 1e-12 && (g[2] - 10.0).abs() < 1e-12);
    }
}
