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

// Largest exponent difference exact_sum aligns exactly (src/rng.rs MAX_ALIGNMENT).
const MAX_ALIGNMENT: i32 = 74;

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
// sign only, which rounds to the same f32 (src/rng.rs MAX_ALIGNMENT says why).
fn exact_sum(a: ExactTerm, b: ExactTerm) -> ExactTerm {
    if (wide_is_zero(b.value)) {
        return a;
    }
    if (wide_is_zero(a.value)) {
        return b;
    }
    var large = a;
    var small = b;
    if (a.exponent < b.exponent) {
        large = b;
        small = a;
    }
    let shift = large.exponent - small.exponent;
    var s: ExactTerm;
    if (shift <= MAX_ALIGNMENT) {
        s.value = wide_add(wide_shift_left(large.value, u32(shift)), small.value);
        s.exponent = small.exponent;
    } else {
        let sign = select(vec4<u32>(1u, 0u, 0u, 0u), vec4<u32>(0xFFFFFFFFu), wide_is_negative(small.value));
        s.value = wide_add(wide_shift_left(large.value, u32(MAX_ALIGNMENT)), sign);
        s.exponent = large.exponent - MAX_ALIGNMENT;
    }
    return s;
}

// sum * 2^exponent rounded once to the nearest f32, ties to even; a zero sum gives +0
// (src/rng.rs round_to_f32).
fn round_to_f32(sum: vec4<u32>, exponent: i32) -> f32 {
    let negative = wide_is_negative(sum);
    var magnitude = select(sum, wide_negate(sum), negative);
    var lead = -1;
    for (var i = 0; i < 4; i = i + 1) {
        if (magnitude[i] != 0u) {
            lead = 32 * i + i32(firstLeadingBit(magnitude[i]));
        }
    }
    if (lead < 0) {
        return 0.0;
    }
    // Bit position of the result's last significant bit: 24 significant bits, never below 2^-149.
    let cut = max(lead - 23, -149 - exponent);
    var significand: u32;
    if (cut <= 0) {
        significand = magnitude.x << u32(-cut);
    } else {
        significand = wide_shift_right(magnitude, u32(cut)).x;
        let round_bit = (wide_shift_right(magnitude, u32(cut - 1)).x & 1u) == 1u;
        let sticky = !wide_is_zero(wide_shift_left(magnitude, u32(129 - cut)));
        if (round_bit && (sticky || (significand & 1u) == 1u)) {
            significand = significand + 1u;
        }
    }
    // Biased exponent and fraction at once; a rounding carry moves into the next binade.
    let bits = (u32(cut + exponent + 149) << 23u) + significand;
    return bitcast<f32>(bits | select(0u, 0x80000000u, negative));
}

fn wide_is_zero(a: vec4<u32>) -> bool {
    return all(a == vec4<u32>(0u));
}

fn wide_is_negative(a: vec4<u32>) -> bool {
    return (a.w >> 31u) == 1u;
}

fn wide_add(a: vec4<u32>, b: vec4<u32>) -> vec4<u32> {
    var s = a + b;
    var carry = 0u;
    for (var i = 0; i < 4; i = i + 1) {
        let with_carry = s[i] + carry;
        carry = select(0u, 1u, s[i] < a[i]) + select(0u, 1u, with_carry < carry);
        s[i] = with_carry;
    }
    return s;
}

fn wide_negate(a: vec4<u32>) -> vec4<u32> {
    return wide_add(~a, vec4<u32>(1u, 0u, 0u, 0u));
}

// a << n for any n (0 from n = 128 on); WGSL shifts need amounts below 32.
fn wide_shift_left(a: vec4<u32>, n: u32) -> vec4<u32> {
    let words = n / 32u;
    let bits = n % 32u;
    var out = vec4<u32>(0u);
    for (var i = words; i < 4u; i = i + 1u) {
        let j = i - words;
        var w = a[j] << bits;
        if (bits > 0u && j > 0u) {
            w = w | (a[j - 1u] >> (32u - bits));
        }
        out[i] = w;
    }
    return out;
}

// a >> n (logical) for any n (0 from n = 128 on).
fn wide_shift_right(a: vec4<u32>, n: u32) -> vec4<u32> {
    let words = n / 32u;
    let bits = n % 32u;
    var out = vec4<u32>(0u);
    for (var i = words; i < 4u; i = i + 1u) {
        let j = i - words;
        var w = a[i] >> bits;
        if (bits > 0u && i + 1u < 4u) {
            w = w | (a[i + 1u] << (32u - bits));
        }
        out[j] = w;
    }
    return out;
}
