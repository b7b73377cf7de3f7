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

/// A word as a uniform on (0, 1), f64: (w + ½)·2⁻³² (never 0, so its logarithm is finite).
#[inline]
pub fn open_unit(word: u32) -> f64 {
    (f64::from(word) + 0.5) * (1.0 / 4_294_967_296.0)
}

/// Two standard normals from two words by Box–Muller.
#[inline]
pub fn box_muller(a: u32, b: u32) -> [f64; 2] {
    let r = (-2.0 * open_unit(a).ln()).sqrt();
    let angle = std::f64::consts::TAU * (f64::from(b) * (1.0 / 4_294_967_296.0));
    [r * angle.cos(), r * angle.sin()]
}

/// A word as a uniform f32 in [0, 1): the top 24 bits times 2⁻²⁴. Every value is exactly
/// representable in f32, so the WGSL twin produces the same bits.
#[inline]
pub fn unit_f32(word: u32) -> f32 {
    (word >> 8) as f32 * (1.0 / 16_777_216.0)
}

/// A uniform f32 in [lo, hi] from one word: the correctly rounded (to nearest, ties to even)
/// f32 of the exact real number lo + (hi − lo)·k·2⁻²⁴ with k = word >> 8, for finite lo ≤ hi.
/// An exact zero gives +0; a nonzero value that rounds to zero keeps its sign (IEEE 754).
///
/// Drivers may contract `a*b + c` into a fused multiply-add and reassociate sums of floats, so
/// no float formula is bit-identical across GPUs. This one is integer arithmetic up to the final
/// bitcast, which no compiler may rewrite, and is the twin of `uniform_between` in
/// shaders/shared/philox.wgsl (the same steps on 4 × u32 words there, i128 here):
///
/// 1. lo = m_lo·2^e_lo and hi = m_hi·2^e_hi with integer significands |m| < 2²⁴ (`exact_term`);
/// 2. 2²⁴ times the value is m_lo·(2²⁴ − k)·2^e_lo + m_hi·k·2^e_hi: two exact products below
///    2⁴⁸, summed exactly in 128 bits (`exact_sum`; a term more than `MAX_ALIGNMENT` binades
///    below the other is replaced by its sign, which cannot change the rounding);
/// 3. one rounding to nearest-even at 24 significant bits or at 2⁻¹⁴⁹, whichever is coarser,
///    assembled as f32 bits (`round_to_f32`).
///
/// Rounding is monotone and lo, hi are representable, so the result lies in [lo, hi]: no clamp.
#[inline]
pub fn uniform_between(lo: f32, hi: f32, word: u32) -> f32 {
    let k = i64::from(word >> 8);
    let (sum, exponent) = exact_sum(exact_term(lo, (1 << 24) - k), exact_term(hi, k));
    round_to_f32(sum, exponent - 24)
}

/// A term of an exact sum: the value `.0 · 2^.1`.
type ExactTerm = (i64, i32);

/// `x · factor` exactly for a finite f32 x and 0 ≤ factor ≤ 2²⁴: the significand of x as a signed
/// integer (|m| < 2²⁴, subnormals with exponent −149) times the factor, below 2⁴⁸ in magnitude.
#[inline]
fn exact_term(x: f32, factor: i64) -> ExactTerm {
    let bits = x.to_bits();
    let biased = ((bits >> 23) & 0xFF) as i32;
    let fraction = i64::from(bits & 0x7F_FFFF);
    let (significand, exponent) = if biased == 0 {
        (fraction, -149)
    } else {
        (fraction | 1 << 23, biased - 150)
    };
    let magnitude = significand * factor;
    (if bits >> 31 == 1 { -magnitude } else { magnitude }, exponent)
}

/// Largest exponent difference [`exact_sum`] aligns exactly (binades).
///
/// Why a smaller term further below may be replaced by its sign: count in units of 2^(e − 74),
/// e the larger term's exponent. The larger term is then L = m·2⁷⁴ with m ≠ 0 an integer, so
/// |L + s| > 2⁷³ for any |s| < 2⁴⁹, and the f32 grid near it (24 significant bits, or coarser
/// among subnormals) has its points and midpoints on multiples of 2⁴⁹, like L itself. A true
/// smaller term d binades further down (d > 74) has |s| < 2⁴⁸·2^(74 − d) < 2⁴⁸, and its sign
/// as replacement has |s| = 1: both put L + s strictly inside the same open interval between
/// consecutive multiples of 2⁴⁹ on the same side of L, where nothing rounds differently.
/// 74 keeps |sum| < 2⁴⁸·2⁷⁴ + 2⁴⁸ < 2¹²³: four 32-bit words on the GPU.
const MAX_ALIGNMENT: i32 = 74;

/// The exponent a zero term counts with in `exact_sum`: more than `MAX_ALIGNMENT` below every
/// f32's (−149), so the other term stays exact and the zero one adds its sign, 0.
const ZERO_EXPONENT: i32 = -1000;

/// a + b as `sum · 2^exponent`: exact, except that a term more than `MAX_ALIGNMENT` binades
/// below the other counts as its sign only, which rounds to the same f32 (see there).
#[inline]
fn exact_sum(a: ExactTerm, b: ExactTerm) -> (i128, i32) {
    let effective = |t: ExactTerm| if t.0 == 0 { ZERO_EXPONENT } else { t.1 };
    let (large, small) = if effective(a) >= effective(b) { (a, b) } else { (b, a) };
    let shift = effective(large) - effective(small);
    let aligned = shift.min(MAX_ALIGNMENT);
    let small_kept = if shift > MAX_ALIGNMENT {
        small.0.signum()
    } else {
        small.0
    };
    (
        (i128::from(large.0) << aligned) + i128::from(small_kept),
        large.1 - aligned,
    )
}

/// `sum · 2^exponent` rounded once to the nearest f32, ties to even, for sums whose value is
/// within the f32 range (every sum here lies between two f32s). A zero sum gives +0.
#[inline]
fn round_to_f32(sum: i128, exponent: i32) -> f32 {
    if sum == 0 {
        return 0.0;
    }
    let sign = if sum < 0 { 1 << 31 } else { 0 };
    let magnitude = sum.unsigned_abs();
    let lead = 127 - magnitude.leading_zeros() as i32;
    // Bit position of the result's last significant bit: 24 significant bits, never below 2⁻¹⁴⁹.
    let cut = (lead - 23).max(-149 - exponent);
    let significand = if cut <= 0 {
        (magnitude << -cut) as u32
    } else {
        let kept = (magnitude >> cut) as u32;
        let round_bit = (magnitude >> (cut - 1)) & 1 == 1;
        let sticky = magnitude & ((1 << (cut - 1)) - 1) != 0;
        kept + u32::from(round_bit && (sticky || kept & 1 == 1))
    };
    // A normal result has significand 2²³ + fraction and biased exponent (ulp exponent + 150);
    // adding the significand to (ulp exponent + 149) << 23 sets both, moves a rounding carry
    // (significand 2²⁴) into the next binade and leaves subnormals (ulp exponent −149) as they are.
    let ulp_exponent = cut + exponent;
    f32::from_bits(sign | ((((ulp_exponent + 149) as u32) << 23) + significand))
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
    fn uniform_between_on_the_unit_box_is_unit_f32() {
        for k in (0..1u32 << 24).step_by(7).chain([(1 << 24) - 1]) {
            let word = k << 8 | (k & 0xFF);
            assert_eq!(
                uniform_between(0.0, 1.0, word).to_bits(),
                unit_f32(word).to_bits(),
                "{word:#x}"
            );
        }
    }

    /// Bit-for-bit equality, which also tells +0 from −0.
    #[track_caller]
    fn assert_same_bits(got: f32, want: f32) {
        assert_eq!(got.to_bits(), want.to_bits(), "{got:e} vs {want:e}");
    }

    #[test]
    fn uniform_between_known_values() {
        assert_same_bits(uniform_between(1.0, 2.0, 0x8000_0000), 1.5);
        assert_same_bits(uniform_between(-3.7, 12.9, 0), -3.7);
        assert_same_bits(uniform_between(-3.7, 12.9, 0xFF), -3.7);
        // An exact zero is +0.
        assert_same_bits(uniform_between(-1.0, 1.0, 0x8000_0000), 0.0);
        assert_same_bits(uniform_between(-0.0, -0.0, 0x1234_5678), 0.0);
        // lo = hi is that value for every word.
        for word in [0, 1 << 8, 0x8000_0000, u32::MAX] {
            assert_same_bits(uniform_between(-7.25e-40, -7.25e-40, word), -7.25e-40);
            assert_same_bits(uniform_between(3.0e38, 3.0e38, word), 3.0e38);
        }
        // [0, smallest subnormal]: k·2⁻²⁴·2⁻¹⁴⁹ rounds to 0 below k = 2²³, ties to even (0) at
        // 2²³ and to 2⁻¹⁴⁹ above.
        let tiny = f32::from_bits(1);
        assert_same_bits(uniform_between(0.0, tiny, (1 << 31) - 256), 0.0);
        assert_same_bits(uniform_between(0.0, tiny, 1 << 31), 0.0);
        assert_same_bits(uniform_between(0.0, tiny, (1 << 31) + 256), tiny);
        assert_same_bits(uniform_between(0.0, tiny, u32::MAX), tiny);
    }

    #[test]
    fn a_term_far_below_the_other_breaks_a_tie() {
        // lo·3·2⁻²⁴ with lo = −(2²³ + 1) is −(2²⁴ + 2²³ + 3)·2⁻²⁴: 25 significant bits, a tie
        // between −(2²⁴ + 2²³ + 2)·2⁻²⁴ and the even −(2²⁴ + 2²³ + 4)·2⁻²⁴. With k = 2²⁴ − 3 the
        // hi term decides: 2⁻¹⁰⁰ (123 binades below lo) pulls toward zero, −2⁻¹⁰⁰ away from it,
        // 0 leaves the tie to the even neighbour.
        let lo = -8_388_609.0f32;
        let word = ((1 << 24) - 3) << 8;
        let toward_zero = -25_165_826.0 / 16_777_216.0;
        let away = -25_165_828.0 / 16_777_216.0;
        assert_same_bits(uniform_between(lo, 2f32.powi(-100), word), toward_zero);
        assert_same_bits(uniform_between(lo, -(2f32.powi(-100)), word), away);
        assert_same_bits(uniform_between(lo, 0.0, word), away);
        // The same with the roles of lo and hi swapped (k = 3).
        let hi = 8_388_609.0f32;
        assert_same_bits(uniform_between(-(2f32.powi(-100)), hi, 3 << 8), -toward_zero);
        assert_same_bits(uniform_between(2f32.powi(-100), hi, 3 << 8), -away);
    }
}
