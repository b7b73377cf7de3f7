//! The candidate transform `uniform_between` against an independent exact reference (f64
//! arithmetic with an error-free sum), on 10⁷ hard (lo, hi, word) triples; and its WGSL twin
//! against the Rust one, bit for bit, on the GPU.

use bitrock::rng::{philox4x32_10, uniform_between};
use rayon::prelude::*;

/// The correctly rounded (to nearest, ties to even) f32 of lo + (hi − lo)·k·2⁻²⁴, k = word >> 8,
/// computed independently of the library: a = lo·(2²⁴ − k)·2⁻²⁴ and
/// b = hi·k·2⁻²⁴ are exact in f64 (24 × 24 significant bits, exponents far inside f64's range);
/// TwoSum gives s + t = a + b exactly with s = fl(a + b). Rounding s to f32 is then right unless
/// s is exactly a midpoint of two f32s (no midpoint lies strictly between s and s + t, or it
/// would be the nearer f64), where the sign of t says on which side a + b lies. An exact zero
/// is +0 (s = 0 only when a + b = 0: no f64 here underflows); a tiny nonzero value that rounds
/// to zero keeps its sign, as IEEE 754 rounding does.
fn reference(lo: f32, hi: f32, word: u32) -> f32 {
    let k = f64::from(word >> 8);
    let scale = 2f64.powi(-24);
    let a = f64::from(lo) * (16_777_216.0 - k) * scale;
    let b = f64::from(hi) * k * scale;
    let s = a + b;
    let bv = s - a;
    let t = (a - (s - bv)) + (b - bv);
    let r = s as f32;
    let rounded = if f64::from(r) == s || t == 0.0 {
        r
    } else {
        let (below, above) = if f64::from(r) < s {
            (r, r.next_up())
        } else {
            (r.next_down(), r)
        };
        if s == (f64::from(below) + f64::from(above)) / 2.0 {
            if t > 0.0 { above } else { below }
        } else {
            r
        }
    };
    if s == 0.0 { 0.0 } else { rounded }
}

/// Four random words for triple `i` of the hard set.
fn words(i: u64, block: u32) -> [u32; 4] {
    philox4x32_10([i as u32, (i >> 32) as u32, block, 0], [0x0b17_70c4, 0x5eed])
}

/// A finite f32 from random bits: every exponent (subnormals included) equally likely.
fn finite(bits: u32) -> f32 {
    let x = f32::from_bits(bits);
    if x.is_finite() {
        x
    } else {
        f32::from_bits(bits ^ 1 << 23)
    }
}

/// 10^(lo_exp .. hi_exp) log-uniformly from a word.
fn log_uniform(word: u32, lo_exp: f64, hi_exp: f64) -> f64 {
    10f64.powf(lo_exp + (hi_exp - lo_exp) * f64::from(word) / 4_294_967_296.0)
}

fn signed(x: f32, word: u32) -> f32 {
    if word & 1 == 1 { -x } else { x }
}

fn ordered(a: f32, b: f32) -> (f32, f32) {
    if a <= b { (a, b) } else { (b, a) }
}

/// Triple `i` of the hard set, one of eight kinds by i mod 8: any two finite f32s (every
/// exponent pair, so most sums align terms 75 and more binades apart); boxes of width
/// 10⁻³⁰..10³⁰ anywhere (negative, positive, around 0); boxes straddling 0 with ends of unrelated
/// magnitude; lo = hi; subnormal ends and results; ends a few ulps apart; exact ties between two
/// f32s broken by a term up to 100 binades below; and the ends of the word range on boxes of
/// the first kinds.
fn hard_triple(i: u64) -> (f32, f32, u32) {
    let w = words(i, 0);
    let v = words(i, 1);
    let word = v[3];
    match i % 8 {
        0 => {
            let (lo, hi) = ordered(finite(w[0]), finite(w[1]));
            (lo, hi, word)
        }
        1 => {
            let width = log_uniform(w[0], -30.0, 30.0);
            let centre = f64::from(signed(log_uniform(w[1], -30.0, 30.0) as f32, w[2]));
            let (lo, hi) = ordered((centre - width / 2.0) as f32, (centre + width / 2.0) as f32);
            (lo, hi, word)
        }
        2 => {
            let lo = -log_uniform(w[0], -45.0, 38.0) as f32;
            let hi = log_uniform(w[1], -45.0, 38.0) as f32;
            (lo, hi, word)
        }
        3 => {
            let x = finite(w[0]);
            (x, x, word)
        }
        4 => {
            // Subnormal ends, or ends around the smallest normal (1.18e-38).
            let a = signed(f32::from_bits(w[0] % (1 << 23)), w[2]);
            let b = if w[2] & 2 == 0 {
                signed(f32::from_bits(w[1] % (1 << 23)), w[2] >> 2)
            } else {
                signed(f32::from_bits(w[1] % (3 << 23)), w[2] >> 2)
            };
            let (lo, hi) = ordered(a, b);
            (lo, hi, word)
        }
        5 => {
            let lo = finite(w[0]);
            let mut hi = lo;
            for _ in 0..w[1] % 5 {
                if hi.next_up().is_finite() {
                    hi = hi.next_up();
                }
            }
            (lo, hi, word)
        }
        6 => {
            // An odd significand m with 3m of 25 bits: m·3·2^j·2⁻²⁴ (k or 2²⁴ − k = 3·2^j) is a
            // tie between two f32s, which the other end, 1..60 binades below the tie's last
            // bit and of either sign, must break.
            let m = (8_388_608 + w[0] % 2_796_202) | 1;
            let j = (w[1] % 23) as i32;
            let big = f64::from(m) * 2f64.powi((w[1] >> 8) as i32 % 130 - 30 - 23);
            let tie = big * 3.0 * 2f64.powi(j - 24);
            let mantissa = 1.0 + f64::from(v[0]) / 4_294_967_296.0;
            let far = 1 + (w[2] >> 8) as i32 % 60;
            let small = signed((mantissa * tie * 2f64.powi(-26 - far)) as f32, w[2]);
            let tie_k = 3u32 << j;
            if w[3] & 1 == 0 {
                (-big as f32, small, ((1 << 24) - tie_k) << 8 | (word & 0xFF))
            } else {
                (small, big as f32, tie_k << 8 | (word & 0xFF))
            }
        }
        _ => {
            const ENDS: [u32; 8] = [0, 0xFF, 0x100, 0x1FF, 0x7FFF_FFFF, 0x8000_0000, 0xFFFF_FF00, u32::MAX];
            let (lo, hi, _) = hard_triple(i - 7 + u64::from(w[3] % 6));
            (lo, hi, ENDS[(w[2] % 8) as usize])
        }
    }
}

/// The first `n` hard triples.
pub(crate) fn hard_triples(n: u64) -> Vec<(f32, f32, u32)> {
    (0..n).into_par_iter().map(hard_triple).collect()
}

#[test]
fn uniform_between_is_the_correctly_rounded_exact_value_on_ten_million_hard_triples() {
    let n = 10_000_000u64;
    // Coverage the test relies on, counted from the inputs: terms more than 74 binades apart
    // (the sign-only path), subnormal results, ties broken by the far term.
    #[derive(Default, Clone, Copy)]
    struct Seen {
        far_terms: u64,
        subnormal: u64,
        ties_broken: u64,
        wrong: u64,
    }
    let exponent = |x: f32| -> i32 {
        let biased = ((x.to_bits() >> 23) & 0xFF) as i32;
        if biased == 0 { -149 } else { biased - 150 }
    };
    let seen = (0..n)
        .into_par_iter()
        .map(|i| {
            let (lo, hi, word) = hard_triple(i);
            let got = uniform_between(lo, hi, word);
            let want = reference(lo, hi, word);
            assert!(lo <= got && got <= hi, "triple {i}: {got:e} outside [{lo:e}, {hi:e}]");
            let k = word >> 8;
            let both = lo != 0.0 && hi != 0.0 && k != 0;
            let far = both && (exponent(lo) - exponent(hi)).abs() > 74;
            let subnormal = got != 0.0 && !got.is_normal();
            // A tie broken toward the odd neighbour: the big end alone rounds to the even one.
            let big_alone = if lo.abs() > hi.abs() { reference(lo, 0.0, word) } else { reference(0.0, hi, word) };
            let tie = i % 8 == 6 && got.to_bits() != big_alone.to_bits();
            if got.to_bits() != want.to_bits() {
                eprintln!(
                    "triple {i}: uniform_between({lo:e} [{:#010x}], {hi:e} [{:#010x}], {word:#010x}) = {got:e} [{:#010x}], exact {want:e} [{:#010x}]",
                    lo.to_bits(),
                    hi.to_bits(),
                    got.to_bits(),
                    want.to_bits()
                );
            }
            Seen {
                far_terms: u64::from(far),
                subnormal: u64::from(subnormal),
                ties_broken: u64::from(tie),
                wrong: u64::from(got.to_bits() != want.to_bits()),
            }
        })
        .reduce(Seen::default, |a, b| Seen {
            far_terms: a.far_terms + b.far_terms,
            subnormal: a.subnormal + b.subnormal,
            ties_broken: a.ties_broken + b.ties_broken,
            wrong: a.wrong + b.wrong,
        });
    eprintln!(
        "{n} triples: {} with terms > 74 binades apart, {} subnormal results, {} ties broken by the far term",
        seen.far_terms, seen.subnormal, seen.ties_broken
    );
    assert_eq!(
        seen.wrong, 0,
        "{} of {n} triples differ from the exact reference",
        seen.wrong
    );
    assert!(seen.far_terms > n / 10, "{}", seen.far_terms);
    assert!(seen.subnormal > n / 100, "{}", seen.subnormal);
    assert!(seen.ties_broken > n / 100, "{}", seen.ties_broken);
}

#[test]
#[cfg_attr(skip_gpu_tests, ignore = "BITROCK_SKIP_GPU_TESTS=1")]
fn the_wgsl_twin_gives_the_same_bits_on_four_million_hard_triples() {
    crate::gpu::require_gpu();
    let triples = hard_triples(1 << 22);
    let gpu = bitrock::eval::gpu::candidates::uniform_between(&triples).unwrap();
    assert_eq!(gpu.len(), triples.len());
    let differ: Vec<usize> = (0..triples.len())
        .into_par_iter()
        .filter(|&i| {
            let (lo, hi, word) = triples[i];
            gpu[i].to_bits() != uniform_between(lo, hi, word).to_bits()
        })
        .collect();
    for &i in differ.iter().take(10) {
        let (lo, hi, word) = triples[i];
        eprintln!(
            "triple {i}: ({lo:e}, {hi:e}, {word:#010x}): gpu {:e} [{:#010x}], cpu {:e} [{:#010x}]",
            gpu[i],
            gpu[i].to_bits(),
            uniform_between(lo, hi, word),
            uniform_between(lo, hi, word).to_bits()
        );
    }
    assert!(
        differ.is_empty(),
        "{} of {} triples differ",
        differ.len(),
        triples.len()
    );
}
