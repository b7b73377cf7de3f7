//! Counter-based random numbers: Philox4x32-10 (Salmon et al., "Parallel random numbers: as easy
//! as 1, 2, 3", SC'11), the CPU twin of `shaders/shared/philox.wgsl`.
//!
//! A counter-based generator turns (counter, key) into random words with no state, so candidate
//! i of population g is a pure function of (seed, g, i): batching, thread count and backend
//! cannot change which candidates exist. The layout used by bitrock:
//!
//! - key = (seed mod 2³², seed div 2³²)
//! - counter of block b of candidate i in population g = (i mod 2³², i div 2³², g, b)
//!
//! Words become uniforms by one formula on every backend: [`unit_f32`] on [0, 1) and
//! [`uniform_between`] on a prior box.

/// Philox4x32 multipliers and Weyl key increments (Random123).
const M0: u32 = 0xD251_1F53;
const M1: u32 = 0xCD9E_8D57;
const W0: u32 = 0x9E37_79B9;
const W1: u32 = 0xBB67_AE85;

#[inline(always)]
fn mulhilo(a: u32, b: u32) -> (u32, u32) {
    let p = u64::from(a) * u64::from(b);
    ((p >> 32) as u32, p as u32)
}

/// Philox4x32 with 10 rounds: four random 32-bit words from a 128-bit counter and a 64-bit key.
#[inline]
pub fn philox4x32_10(counter: [u32; 4], key: [u32; 2]) -> [u32; 4] {
    let mut c = counter;
    let mut k = key;
    for round in 0..10 {
        if round > 0 {
            k[0] = k[0].wrapping_add(W0);
            k[1] = k[1].wrapping_add(W1);
        }
        let (hi0, lo0) = mulhilo(M0, c[0]);
        let (hi1, lo1) = mulhilo(M1, c[2]);
        c = [hi1 ^ c[1] ^ k[0], lo1, hi0 ^ c[3] ^ k[1], lo0];
    }
    c
}

/// The key of a run's streams.
#[inline]
pub fn key_of_seed(seed: u64) -> [u32; 2] {
    [seed as u32, (seed >> 32) as u32]
}

/// The counter of block `block` of candidate `index` in population `population`.
#[inline]
pub fn candidate_counter(population: u32, index: u64, block: u32) -> [u32; 4] {
    [index as u32, (index >> 32) as u32, population, block]
}

/// A word as a uniform f32 in [0, 1): the top 24 bits times 2⁻²⁴. Every value is exactly
/// representable in f32, so the WGSL twin produces the same bits.
#[inline]
pub fn unit_f32(word: u32) -> f32 {
    (word >> 8) as f32 * (1.0 / 16_777_216.0)
}

/// A uniform f32 in [lo, hi] from one word: lo + (hi − lo)·u with u = (word >> 8)·2⁻²⁴,
/// computed so that every backend gets the same bits.
///
/// A fused multiply-add cannot be relied on: lavapipe evaluates WGSL `fma` unfused, other
/// drivers may fuse a plain `a * b + c`. So the product is split until every partial product
/// is exact in f32 (12 × 12 significant bits): the width keeps its top 12 bits in `wh` and the
/// rest in `wl` (bit masking, exact), u its top and bottom 12 bits. With exact products, fused
/// and unfused evaluation round identically, and the fixed order of the additions does the rest.
#[inline]
pub fn uniform_between(lo: f32, hi: f32, word: u32) -> f32 {
    let width = hi - lo;
    let wh = f32::from_bits(width.to_bits() & 0xFFFF_F000);
    let wl = width - wh;
    let k = word >> 8;
    let uh = (k & 0x00FF_F000) as f32 * (1.0 / 16_777_216.0);
    let ul = (k & 0x0000_0FFF) as f32 * (1.0 / 16_777_216.0);
    // Rounding can carry the sum an ulp past hi: clamp (exact on every backend).
    (lo + (((wh * uh + wh * ul) + wl * uh) + wl * ul)).min(hi)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn random123_known_answers() {
        // Random123 kat_vectors, "philox4x32 10" lines: counter, key → output.
        let cases: [([u32; 4], [u32; 2], [u32; 4]); 3] = [
            ([0; 4], [0; 2], [0x6627_e8d5, 0xe169_c58d, 0xbc57_ac4c, 0x9b00_dbd8]),
            (
                [u32::MAX; 4],
                [u32::MAX; 2],
                [0x408f_276d, 0x41c8_3b0e, 0xa20b_c7c6, 0x6d54_51fd],
            ),
            (
                [0x243f_6a88, 0x85a3_08d3, 0x1319_8a2e, 0x0370_7344],
                [0xa409_3822, 0x299f_31d0],
                [0xd16c_fe09, 0x94fd_cceb, 0x5001_e420, 0x2412_6ea1],
            ),
        ];
        for (counter, key, expected) in cases {
            assert_eq!(philox4x32_10(counter, key), expected);
        }
    }

    #[test]
    fn uniforms_cover_zero_to_one_exclusive() {
        assert_eq!(unit_f32(0).to_bits(), 0.0f32.to_bits());
        assert_eq!(unit_f32(u32::MAX).to_bits(), (1.0f32 - 1.0 / 16_777_216.0).to_bits());
        assert_eq!(unit_f32(0x8000_0000).to_bits(), 0.5f32.to_bits());
    }

    #[test]
    fn uniforms_are_uniform() {
        // Mean and variance of 10⁶ uniforms against 1/2 and 1/12 (tolerance ≈ 5 σ).
        let n = 1_000_000u64;
        let (mut s, mut s2) = (0.0f64, 0.0f64);
        for i in 0..n / 4 {
            for w in philox4x32_10(candidate_counter(3, i, 0), key_of_seed(42)) {
                let u = f64::from(unit_f32(w));
                s += u;
                s2 += u * u;
            }
        }
        let mean = s / n as f64;
        let var = s2 / n as f64 - mean * mean;
        assert!((mean - 0.5).abs() < 5.0 * (1.0 / 12.0 / n as f64).sqrt(), "{mean}");
        assert!((var - 1.0 / 12.0).abs() < 5e-4, "{var}");
    }

    #[test]
    fn uniform_between_matches_the_plain_formula_to_rounding_and_spans_the_box() {
        let (lo, hi) = (-3.7f32, 12.9f32);
        assert_eq!(uniform_between(lo, hi, 0).to_bits(), lo.to_bits());
        for i in 0..100_000u32 {
            let word = i.wrapping_mul(2_654_435_761);
            let v = uniform_between(lo, hi, word);
            let exact = f64::from(lo) + (f64::from(hi) - f64::from(lo)) * f64::from(unit_f32(word));
            // The width and four sums round once each: at most 5 half-ulps of the largest
            // magnitude involved, |lo| + |hi| = 16.6 (ulp 2^-19).
            assert!(
                (f64::from(v) - exact).abs() <= 5.0 * 0.5 * 2f64.powi(-19),
                "{word}: {v} vs {exact}"
            );
            assert!(v >= lo && v <= hi);
        }
    }
}
