// Philox4x32-10 (Salmon et al. 2011), the twin of src/rng.rs: identical bits on every backend.
// WGSL has no 64-bit integers, so the 32x32 -> 64 bit product is built from 16-bit halves.

const PHILOX_M0: u32 = 0xD2511F53u;
const PHILOX_M1: u32 = 0xCD9E8D57u;
const PHILOX_W0: u32 = 0x9E3779B9u;
const PHILOX_W1: u32 = 0xBB67AE85u;

// (high, low) words of the 64-bit product a * b.
fn mulhilo(a: u32, b: u32) -> vec2<u32> {
    let a_lo = a & 0xFFFFu;
    let a_hi = a >> 16u;
    let b_lo = b & 0xFFFFu;
    let b_hi = b >> 16u;
    let ll = a_lo * b_lo;
    let lh = a_lo * b_hi;
    let hl = a_hi * b_lo;
    let hh = a_hi * b_hi;
    let mid = (ll >> 16u) + (lh & 0xFFFFu) + (hl & 0xFFFFu);
    let hi = hh + (lh >> 16u) + (hl >> 16u) + (mid >> 16u);
    return vec2<u32>(hi, a * b);
}

fn philox4x32_10(counter: vec4<u32>, key: vec2<u32>) -> vec4<u32> {
    var c = counter;
    var k = key;
    for (var round = 0u; round < 10u; round = round + 1u) {
        if (round > 0u) {
            k = k + vec2<u32>(PHILOX_W0, PHILOX_W1);
        }
        let p0 = mulhilo(PHILOX_M0, c.x);
        let p1 = mulhilo(PHILOX_M1, c.z);
        c = vec4<u32>(p1.x ^ c.y ^ k.x, p1.y, p0.x ^ c.w ^ k.y, p0.y);
    }
    return c;
}

// A word as a uniform f32 in [0, 1): the top 24 bits times 2^-24 (src/rng.rs unit_f32).
fn unit_f32(word: u32) -> f32 {
    return f32(word >> 8u) * (1.0 / 16777216.0);
}

// A uniform f32 in [lo, hi] (finite, lo <= hi), the twin of src/rng.rs uniform_between: the
// correctly rounded (nearest, ties to even) f32 of the exact real lo + (hi - lo) * k * 2^-24,
// k = word >> 8, in integer arithmetic up to the final bitcast, so that no driver's float
// contraction or reassociation can change a bit. The steps and the argument are documented in
// src/rng.rs; 128-bit integers here are vec4<u32> in two's complement, least significant word x.
fn uniform_between(lo: f32, hi: f32, word: u32) -> f32 {
    let k = word >> 8u;
    let sum = exact_sum(exact_term(lo, 16777216u - k), exact_term(hi, k));
    return round_to_f32(sum.value, sum.exponent - 24);
}

// The value `value * 2^exponent`, value a signed 128-bit integer (src/rng.rs ExactTerm).
struct ExactTerm {
    value: vec4<u32>,
    exponent: i32,
}

// Largest exponent difference exact_sum aligns exactly (src/rng.rs MAX_ALIGNMENT), and the
// exponent a zero term counts with: further below any f32's than that (src/rng.rs).
const MAX_ALIGNMENT: i32 = 74;
const ZERO_EXPONENT: i32 = -1000;

// Straight-line code throughout (select, no loops, no per-invocation vector indexing): a SIMD
// driver such as lavapipe runs every branch side and turns a varying index into a per-lane loop.

// x * factor exactly for a finite f32 x and factor <= 2^24: the signed integer significand
// (|m| < 2^24, subnormals with exponent -149) times factor, below 2^48 in magnitude.
fn exact_term(x: f32, factor: u32) -> ExactTerm {
    let bits = bitcast<u32>(x);
    let biased = (bits >> 23u) & 0xFFu;
    let fraction = bits & 0x7FFFFFu;
    let significand = select(fraction | 0x800000u, fraction, biased == 0u);
    let product = mulhilo(significand, factor);
    let magnitude = vec4<u32>(product.y, product.x, 0u, 0u);
    var t: ExactTerm;
    t.value = select(magnitude, wide_negate(magnitude), (bits >> 31u) == 1u);
    t.exponent = select(i32(biased) - 150, -149, biased == 0u);
    return t;
}

// a + b, exact except that a term more than MAX_ALIGNMENT binades below the other counts as its
// sign only (a zero term as 0), which rounds to the same f32 (src/rng.rs MAX_ALIGNMENT says why).
fn exact_sum(a: ExactTerm, b: ExactTerm) -> ExactTerm {
    let ea = select(a.exponent, ZERO_EXPONENT, wide_is_zero(a.value));
    let eb = select(b.exponent, ZERO_EXPONENT, wide_is_zero(b.value));
    let a_large = ea >= eb;
    let large = select(b.value, a.value, a_large);
    let small = select(a.value, b.value, a_large);
    let shift = max(ea, eb) - min(ea, eb);
    let aligned = min(shift, MAX_ALIGNMENT);
    let sign = select(
        select(vec4<u32>(1u, 0u, 0u, 0u), vec4<u32>(0xFFFFFFFFu), wide_is_negative(small)),
        vec4<u32>(0u),
        wide_is_zero(small)
    );
    var s: ExactTerm;
    s.value = wide_add(wide_shift_left(large, u32(aligned)), select(small, sign, shift > MAX_ALIGNMENT));
    s.exponent = select(b.exponent, a.exponent, a_large) - aligned;
    return s;
}

// sum * 2^exponent rounded once to the nearest f32, ties to even; a zero sum gives +0
// (src/rng.rs round_to_f32).
fn round_to_f32(sum: vec4<u32>, exponent: i32) -> f32 {
    let negative = wide_is_negative(sum);
    let magnitude = select(sum, wide_negate(sum), negative);
    // Position of the leading bit (-1 for zero).
    let top = vec4<i32>(firstLeadingBit(magnitude)) + vec4<i32>(0, 32, 64, 96);
    let lead = select(select(select(select(-1, top.x, magnitude.x != 0u), top.y, magnitude.y != 0u), top.z, magnitude.z != 0u), top.w, magnitude.w != 0u);
    // Bit position of the result's last significant bit: 24 significant bits, never below 2^-149.
    let cut = max(lead - 23, -149 - exponent);
    let right = u32(max(cut, 0));
    let kept = select(wide_shift_right(magnitude, right).x, magnitude.x << u32(max(-cut, 0)), cut <= 0);
    // Round bit (bit cut - 1) and sticky bits (below it); none when nothing is cut off.
    let round_bit = (cut > 0) & ((wide_shift_right(magnitude, u32(max(cut - 1, 0))).x & 1u) == 1u);
    let sticky = !wide_is_zero(wide_shift_left(magnitude, u32(clamp(129 - cut, 0, 128))));
    let significand = kept + select(0u, 1u, round_bit & (sticky | ((kept & 1u) == 1u)));
    // Biased exponent and fraction at once; a rounding carry moves into the next binade.
    let bits = (u32(select(cut + exponent + 149, 0, lead < 0)) << 23u) + select(significand, 0u, lead < 0);
    return bitcast<f32>(bits | select(0u, 0x80000000u, negative));
}

fn wide_is_zero(a: vec4<u32>) -> bool {
    return all(a == vec4<u32>(0u));
}

fn wide_is_negative(a: vec4<u32>) -> bool {
    return (a.w >> 31u) == 1u;
}

// a + b modulo 2^128.
fn wide_add(a: vec4<u32>, b: vec4<u32>) -> vec4<u32> {
    let s = a + b;
    let carry = select(vec4<u32>(0u), vec4<u32>(1u), s < a);
    let y = s.y + carry.x;
    let carry_y = carry.y + select(0u, 1u, y < carry.x);
    let z = s.z + carry_y;
    let carry_z = carry.z + select(0u, 1u, z < carry_y);
    return vec4<u32>(s.x, y, z, s.w + carry_z);
}

fn wide_negate(a: vec4<u32>) -> vec4<u32> {
    return wide_add(~a, vec4<u32>(1u, 0u, 0u, 0u));
}

// a << n for n <= 128 (0 at 128). Word moves by select; every shift amount stays below 32
// (WGSL's rule): x >> (32 - b) is written (x >> 1) >> (31 - b), 0 at b = 0.
fn wide_shift_left(a: vec4<u32>, n: u32) -> vec4<u32> {
    let by64 = select(a, vec4<u32>(0u, 0u, a.x, a.y), (n & 64u) != 0u);
    let v = select(by64, vec4<u32>(0u, by64.x, by64.y, by64.z), (n & 32u) != 0u);
    let b = vec4<u32>(n & 31u);
    let carried = (vec4<u32>(0u, v.x, v.y, v.z) >> vec4<u32>(1u)) >> (vec4<u32>(31u) - b);
    return select((v << b) | carried, vec4<u32>(0u), n >= 128u);
}

// a >> n (logical) for n <= 128 (0 at 128), as wide_shift_left.
fn wide_shift_right(a: vec4<u32>, n: u32) -> vec4<u32> {
    let by64 = select(a, vec4<u32>(a.z, a.w, 0u, 0u), (n & 64u) != 0u);
    let v = select(by64, vec4<u32>(by64.y, by64.z, by64.w, 0u), (n & 32u) != 0u);
    let b = vec4<u32>(n & 31u);
    let carried = (vec4<u32>(v.y, v.z, v.w, 0u) << vec4<u32>(1u)) << (vec4<u32>(31u) - b);
    return select((v >> b) | carried, vec4<u32>(0u), n >= 128u);
}
