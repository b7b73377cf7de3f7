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

// A uniform f32 in [lo, hi], the twin of src/rng.rs uniform_between: the product is split so
// that every partial product is exact, which makes fused and unfused evaluation agree.
fn uniform_between(lo: f32, hi: f32, word: u32) -> f32 {
    let width = hi - lo;
    let wh = bitcast<f32>(bitcast<u32>(width) & 0xFFFFF000u);
    let wl = width - wh;
    let k = word >> 8u;
    let uh = f32(k & 0x00FFF000u) * (1.0 / 16777216.0);
    let ul = f32(k & 0x00000FFFu) * (1.0 / 16777216.0);
    // Rounding can carry the sum an ulp past hi: clamp (exact on every backend).
    return min(lo + (((wh * uh + wh * ul) + wl * uh) + wl * ul), hi);
}
