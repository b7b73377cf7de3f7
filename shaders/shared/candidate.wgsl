// Candidates from the prior, the twin of Prior::candidate in src/prior.rs. Needs philox.wgsl.
// A candidate is a pure function of (seed, population, index): counter block b of candidate i
// is (i mod 2^32, i div 2^32, population, b), the key is the seed's two words.

// The prior of a run. Keep in sync with `GpuPrior` in src/eval/gpu/mod.rs.
struct Prior {
    // Philox key: the seed's low and high words.
    key: vec2<u32>,
    // Number of laws in the prior (1..8).
    n_laws: u32,
    _pad0: u32,
    // Law slot k is chosen when the first word is below thresholds[k] (k < n_laws - 1);
    // otherwise the last slot. Per-slot values of slot k sit at [k / 4][k % 4].
    thresholds: array<vec4<u32>, 2>,
    // Law id (0 = m1 .. 3 = m4, then law files' laws) and parameter count of each slot.
    law_id: array<vec4<u32>, 2>,
    n_params: array<vec4<u32>, 2>,
    // Box of slot k: lower[2k], lower[2k + 1] hold parameters 0..3 and 4..7.
    lower: array<vec4<f32>, 16>,
    upper: array<vec4<f32>, 16>,
}

// The law id of slot `slot`.
fn slot_law(prior: Prior, slot: u32) -> u32 {
    return prior.law_id[slot / 4u][slot % 4u];
}

struct Candidate {
    slot: u32,
    params: array<f32, 6>,
}

fn add_index(start: vec2<u32>, offset: u32) -> vec2<u32> {
    let lo = start.x + offset;
    return vec2<u32>(lo, start.y + select(0u, 1u, lo < start.x));
}

fn box_value(bounds: array<vec4<f32>, 16>, slot: u32, j: u32) -> f32 {
    return bounds[2u * slot + j / 4u][j % 4u];
}

fn make_candidate(prior: Prior, population: u32, index: vec2<u32>) -> Candidate {
    let b0 = philox4x32_10(vec4<u32>(index.x, index.y, population, 0u), prior.key);
    var slot = prior.n_laws - 1u;
    for (var s = 0u; s + 1u < prior.n_laws; s = s + 1u) {
        if (b0.x < prior.thresholds[s / 4u][s % 4u]) {
            slot = s;
            break;
        }
    }
    let n = prior.n_params[slot / 4u][slot % 4u];
    var words = array<u32, 6>(b0.y, b0.z, b0.w, 0u, 0u, 0u);
    if (n > 3u) {
        let b1 = philox4x32_10(vec4<u32>(index.x, index.y, population, 1u), prior.key);
        words[3] = b1.x;
        words[4] = b1.y;
        words[5] = b1.z;
    }
    var c: Candidate;
    c.slot = slot;
    for (var j = 0u; j < 6u; j = j + 1u) {
        if (j < n) {
            c.params[j] = uniform_between(box_value(prior.lower, slot, j), box_value(prior.upper, slot, j), words[j]);
        } else {
            c.params[j] = 0.0;
        }
    }
    return c;
}
