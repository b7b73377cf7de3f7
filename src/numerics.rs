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

/// The median of `values` ([`quantile`] at ½), `None` for none.
pub fn median(values: &[f64]) -> Option<f64> {
    (!values.is_empty()).then(|| quantile(values, 0.5))
}

/// The q-quantile (0 ≤ q ≤ 1) of `values` by linear interpolation between order statistics
/// (type 7, as numpy's default). `values` need not be sorted; NaNs are not expected. O(n):
/// the two order statistics are found by selection, not by sorting.
pub fn quantile(values: &[f64], q: f64) -> f64 {
    assert!(!values.is_empty(), "quantile of an empty set");
    let mut v = values.to_vec();
    let (lo, hi, h) = type7_position(v.len(), q);
    let (_, &mut at_lo, above) = v.select_nth_unstable_by(lo, f64::total_cmp);
    // The next order statistic is the smallest of those above.
    let at_hi = if hi == lo {
        at_lo
    } else {
        above
            .iter()
            .copied()
            .reduce(|a, b| if b.total_cmp(&a).is_lt() { b } else { a })
            .expect("hi < n")
    };
    at_lo + (h - lo as f64) * (at_hi - at_lo)
}

/// [`quantile`] of values already sorted ascending (by `f64::total_cmp`): no copy, O(1).
pub fn quantile_of_sorted(sorted: &[f64], q: f64) -> f64 {
    assert!(!sorted.is_empty(), "quantile of an empty set");
    let (lo, hi, h) = type7_position(sorted.len(), q);
    sorted[lo] + (h - lo as f64) * (sorted[hi] - sorted[lo])
}

/// Type 7's position h = q (n − 1) and the order statistics (0-based) either side of it.
fn type7_position(n: usize, q: f64) -> (usize, usize, f64) {
    let h = q.clamp(0.0, 1.0) * (n - 1) as f64;
    (h.floor() as usize, h.ceil() as usize, h)
}

/// The q-quantile of `values` with non-negative `weights` (not all 0): type 7 generalised to
/// weights. Sorted by value, point k sits at position h_k = C_{k−1} / (W − w_last), where
/// C_{k−1} is the weight before it and W the total, so the first point is at 0, the last at
/// 1, and equal weights give type 7's positions (k − 1)/(n − 1); between positions the
/// quantile interpolates linearly. Continuous in the weights, so nearly equal weights give
/// nearly [`quantile`]'s values.
pub fn weighted_quantile(values: &[f64], weights: &[f64], q: f64) -> f64 {
    assert!(!values.is_empty(), "quantile of an empty set");
    assert_eq!(values.len(), weights.len(), "one weight per value");
    let mut order: Vec<usize> = (0..values.len()).collect();
    order.sort_by(|&a, &b| values[a].total_cmp(&values[b]));
    let total = compensated_sum(weights.iter().copied());
    let span = total - weights[order[order.len() - 1]];
    if span.is_nan() || span <= 0.0 {
        // One point carries all the weight.
        return values[order[order.len() - 1]];
    }
    let q = q.clamp(0.0, 1.0);
    let mut before = 0.0;
    let mut previous = (0.0, values[order[0]]);
    for &i in &order {
        let h = (before / span).min(1.0);
        if h >= q {
            let (h0, x0) = previous;
            return if h > h0 {
                x0 + (q - h0) / (h - h0) * (values[i] - x0)
            } else {
                values[i]
            };
        }
        previous = (h, values[i]);
        before += weights[i];
    }
    values[order[order.len() - 1]]
}

/// `count` values spaced geometrically from `lo` to `hi` inclusive (lo, hi > 0).
pub fn geomspace(lo: f64, hi: f64, count: usize) -> Vec<f64> {
    if count == 1 {
        return vec![lo];
    }
    let ratio = (hi / lo).powf(1.0 / (count - 1) as f64);
    (0..count).map(|i| lo * ratio.powi(i as i32)).collect()
}

/// exp(x) in f64 from only +, ×, min/max and bit operations, so that loops over data
/// vectorise (libm's exp is a scalar call). Cody-Waite reduction x = k ln2 + r, |r| ≤ ln2/2,
/// a degree-13 Taylor polynomial (truncation < 1e-17), and 2^k added to the exponent bits.
/// Within 2 ulp of the correctly rounded result for x in [-708, 709] (a test checks it); the
/// argument is clamped to that range, which is far beyond any law's use.
#[inline(always)]
pub fn exp(x: f64) -> f64 {
    const LOG2E: f64 = std::f64::consts::LOG2_E;
    // ln 2 split so that k · LN2_HI is exact for |k| < 2^11.
    const LN2_HI: f64 = 6.931_471_803_691_238e-1;
    const LN2_LO: f64 = 1.908_214_929_270_587_7e-10;
    // 1.5 · 2^52: adding it rounds to an integer held in the low mantissa bits.
    const SHIFT: f64 = 6_755_399_441_055_744.0;
    let x = x.clamp(-708.0, 709.0);
    let t = x * LOG2E + SHIFT;
    let k = t - SHIFT;
    let r = (x - k * LN2_HI) - k * LN2_LO;
    let mut p = 1.0 / 6_227_020_800.0;
    for c in [
        1.0 / 479_001_600.0,
        1.0 / 39_916_800.0,
        1.0 / 3_628_800.0,
        1.0 / 362_880.0,
        1.0 / 40_320.0,
        1.0 / 5_040.0,
        1.0 / 720.0,
        1.0 / 120.0,
        1.0 / 24.0,
        1.0 / 6.0,
        0.5,
        1.0,
        1.0,
    ] {
        p = p * r + c;
    }
    let k_bits = (t.to_bits() as i64).wrapping_sub(SHIFT.to_bits() as i64);
    f64::from_bits((p.to_bits() as i64).wrapping_add(k_bits << 52) as u64)
}

/// tanh(x) = sign(x) (1 − 2 / (exp(2|x|) + 1)) through [`exp`], vectorisable. Relative error
/// below 4e-16 · max(1, 1/|x|) (the subtraction cancels for small |x|); the laws' tanh
/// arguments (rate × bit speed ≥ 0.04 for the paper's laws above 5 rpm) keep it below 1e-14,
/// far under any tolerance ρ is judged by.
#[inline(always)]
pub fn tanh(x: f64) -> f64 {
    let a = 1.0 - 2.0 / (exp(2.0 * x.abs()) + 1.0);
    a.copysign(x)
}

/// sup |F − G| between two weighted empirical CDFs of (value, weight) pairs.
pub fn weighted_ks(a: &[(f64, f64)], b: &[(f64, f64)]) -> f64 {
    let total = |v: &[(f64, f64)]| v.iter().map(|p| p.1).sum::<f64>();
    let (ta, tb) = (total(a), total(b));
    let mut all: Vec<(f64, f64, f64)> = a
        .iter()
        .map(|p| (p.0, p.1 / ta, 0.0))
        .chain(b.iter().map(|p| (p.0, 0.0, p.1 / tb)))
        .collect();
    all.sort_by(|x, y| x.0.total_cmp(&y.0));
    let (mut fa, mut fb, mut d) = (0.0, 0.0, 0.0f64);
    let mut i = 0;
    while i < all.len() {
        // Ties step together: equal values are one point of both CDFs.
        let x = all[i].0;
        while i < all.len() && all[i].0.to_bits() == x.to_bits() {
            fa += all[i].1;
            fb += all[i].2;
            i += 1;
        }
        d = d.max((fa - fb).abs());
    }
    d
}

/// ∫ f over [a, b] by Simpson's rule on `steps` (even) intervals: tests' closed forms.
#[cfg(test)]
pub(crate) fn simpson(f: impl Fn(f64) -> f64, a: f64, b: f64, steps: u32) -> f64 {
    let h = (b - a) / f64::from(steps);
    let inner: f64 = (1..steps)
        .map(|i| if i % 2 == 1 { 4.0 } else { 2.0 } * f(a + h * f64::from(i)))
        .sum();
    (f(a) + inner + f(b)) * h / 3.0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn non_finite_numbers_survive_json() {
        #[derive(serde::Serialize, serde::Deserialize)]
        struct Holder(#[serde(with = "json_f64")] f64);
        for v in [0.1 + 0.2, -0.0, f64::MAX, f64::INFINITY, f64::NEG_INFINITY, f64::NAN] {
            let text = serde_json::to_string(&Holder(v)).unwrap();
            let back: Holder = serde_json::from_str(&text).unwrap();
            assert_eq!(back.0.to_bits(), v.to_bits(), "{v} as {text}");
        }
        assert!(serde_json::from_str::<Holder>("\"infinite\"").is_err());
    }

    #[test]
    fn weighted_ks_is_the_largest_gap_between_the_weighted_cdfs() {
        // F jumps ½ at 0 and at 1; G ½ at 0 and at 2: the gap is ½ on [1, 2).
        let d = weighted_ks(&[(0.0, 1.0), (1.0, 1.0)], &[(0.0, 3.0), (2.0, 3.0)]);
        assert!((d - 0.5).abs() < 1e-15, "{d}");
        // Ties step together: the same points with any weights' normalisation give 0.
        assert!(weighted_ks(&[(1.0, 2.0), (1.0, 2.0)], &[(1.0, 5.0)]).abs() < 1e-15);
        // Weights count: 0.9 of F's mass at 0 against G's 0.1.
        let d = weighted_ks(&[(0.0, 0.9), (1.0, 0.1)], &[(0.0, 0.1), (1.0, 0.9)]);
        assert!((d - 0.8).abs() < 1e-12, "{d}");
    }

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
    fn selection_quantiles_equal_those_of_the_sorted_values_to_the_bit() {
        // Ties, signed zeros and an even count: the selection's order statistics are the
        // sort's.
        let mut state = 12345u64;
        let values: Vec<f64> = (0..10_001)
            .map(|i| {
                state = state
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                match i % 97 {
                    0 => 0.0,
                    1 => -0.0,
                    2 => 1.5,
                    _ => (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5,
                }
            })
            .collect();
        for values in [&values[..], &values[..10_000], &values[..1], &values[..2]] {
            let mut sorted = values.to_vec();
            sorted.sort_by(f64::total_cmp);
            for q in [0.0, 0.01, 0.25, 1.0 / 3.0, 0.5, 0.75, 0.99, 1.0] {
                let (a, b) = (quantile(values, q), quantile_of_sorted(&sorted, q));
                assert_eq!(a.to_bits(), b.to_bits(), "n {} q {q}", values.len());
            }
        }
    }

    #[test]
    fn weighted_quantiles_generalise_type_7() {
        let v = [3.0, 1.0, 2.0, 4.0];
        for q in [0.0, 0.01, 1.0 / 3.0, 0.5, 0.77, 0.99, 1.0] {
            let (a, b) = (weighted_quantile(&v, &[0.25; 4], q), quantile(&v, q));
            assert!((a - b).abs() < 1e-15, "{q}: {a} vs {b}");
        }
        // Weights 1, 1, 2 on 1, 2, 3: positions 0, 1/2, 1 (W − w_last = 2).
        let (v, w) = ([3.0, 1.0, 2.0], [2.0, 1.0, 1.0]);
        assert!((weighted_quantile(&v, &w, 0.25) - 1.5).abs() < 1e-15);
        assert!((weighted_quantile(&v, &w, 0.75) - 2.5).abs() < 1e-15);
        assert!((weighted_quantile(&[1.0, 9.0], &[1.0, 1.0], 0.3) - 3.4).abs() < 1e-15);
        // All the weight on one point: that point.
        assert!((weighted_quantile(&[5.0], &[1.0], 0.3) - 5.0).abs() < 1e-15);
        assert!((weighted_quantile(&[1.0, 9.0], &[0.0, 1.0], 0.3) - 9.0).abs() < 1e-15);
    }

    #[test]
    fn geomspace_hits_both_ends() {
        let g = geomspace(0.1, 10.0, 3);
        assert!((g[1] - 1.0).abs() < 1e-12 && (g[2] - 10.0).abs() < 1e-12);
    }

    #[test]
    fn vectorisable_exp_is_within_two_ulp() {
        let mut worst = 0.0f64;
        for i in 0..=200_000 {
            let x = -708.0 + 1417.0 * i as f64 / 200_000.0;
            let (got, want) = (exp(x), x.exp());
            worst = worst.max(((got - want) / want).abs());
        }
        for x in [0.0, 1e-300, -1e-12, 0.5, -0.3466, 0.3466, 1.0, -1.0] {
            assert!(((exp(x) - x.exp()) / x.exp()).abs() <= 2.0 * f64::EPSILON, "{x}");
        }
        assert!(worst <= 2.0 * f64::EPSILON, "worst relative error {worst:e}");
    }

    #[test]
    fn vectorisable_tanh_is_accurate_where_the_laws_use_it() {
        for i in 0..100_000 {
            let x = -40.0 + 80.0 * (i as f64 + 0.5) / 100_000.0;
            let (got, want) = (tanh(x), x.tanh());
            let tol = 4e-16 * (1.0 / x.abs()).max(1.0);
            assert!((got - want).abs() <= tol * want.abs(), "{x}: {got} vs {want}");
        }
        assert_eq!(tanh(0.0).to_bits(), 0.0f64.to_bits());
    }
}

/// Serde for an `f64` that may be infinite or NaN, in JSON (which has no number for them and
/// which serde_json writes as `null`): finite values as numbers, the others as the strings
/// `"inf"`, `"-inf"` and `"NaN"`; read back exactly.
pub mod json_f64 {
    use serde::de::Error as _;
    use serde::{Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(value: &f64, out: S) -> Result<S::Ok, S::Error> {
        match *value {
            v if v.is_finite() => out.serialize_f64(v),
            v if v.is_nan() => out.serialize_str("NaN"),
            v if v > 0.0 => out.serialize_str("inf"),
            _ => out.serialize_str("-inf"),
        }
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(input: D) -> Result<f64, D::Error> {
        #[derive(Deserialize)]
        #[serde(untagged)]
        enum Written {
            Number(f64),
            Text(String),
        }
        match Written::deserialize(input)? {
            Written::Number(v) => Ok(v),
            Written::Text(t) => match t.as_str() {
                "inf" => Ok(f64::INFINITY),
                "-inf" => Ok(f64::NEG_INFINITY),
                "NaN" => Ok(f64::NAN),
                other => Err(D::Error::custom(format!(
                    "expected a number, \"inf\", \"-inf\" or \"NaN\", got {other:?}"
                ))),
            },
        }
    }
}
