// Σ (y - r T(w))² of parameter vectors over a slice of the data, shared by the kernels that
// score candidates (residual.wgsl: regenerated from Philox; score_params.wgsl: uploaded by the
// host). Needs laws.wgsl. Declares bindings 2-4 of group 0 (the data columns); the kernels
// including it use the other bindings.
//
// On a SIMD driver such as lavapipe every invocation of a batch reads the same sample, and each
// storage load becomes a per-lane scalar loop, so loads, not arithmetic, bound the speed. Hence
// samples are read four at a time (vec4), and each invocation scores four candidates (register
// blocking): one loaded quad serves 16 evaluations. The ratio r is read only when the run scales
// by weight on bit (override HAS_RATIO).
//
// Accumulation is blocked: 64 samples per block (16 quads, a naive f32 sum), 64 blocks per
// group, groups summed per dispatch, dispatches (65,536 samples each) added in order, so no
// partial sum holds more than 64 terms for D up to 4 M (worst-case relative error about
// 4 x 64 ulps, typically a few) and no driver rewrite can undo it. The host splits the data
// into dispatches of 65,536 samples because lavapipe stops any loop after 65,535 iterations
// per invocation (gallivm's loop limiter, counting nested iterations within an outermost
// loop), which would silently drop the rest of the data.

// False when every sample has r = 1 (the paper's assumption): the ratio column is not read.
override HAS_RATIO: bool = true;

// Samples 4q..4q+3 of bit speed (rad/s), torque (N·m) and weight-on-bit ratio. The last quad
// is padded (w = 1) and its missing samples are masked out.
@group(0) @binding(2) var<storage, read> speed4: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read> torque4: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read> ratio4: array<vec4<f32>>;

const QUADS_PER_BLOCK: u32 = 16u;
const BLOCKS_PER_GROUP: u32 = 64u;

// Law id of an unused candidate slot: matches no law, scores 0.
const NO_LAW: u32 = 4u;

// The parameters of the four candidates of one invocation (unused ones 0).
alias Params4 = array<array<f32, 6>, 4>;

// One quad of data: speeds, torques, ratios and which samples exist.
struct Quad {
    w: vec4<f32>,
    y: vec4<f32>,
    r: vec4<f32>,
    valid: vec4<bool>,
}

fn load_quad(q: u32, end: u32) -> Quad {
    var d: Quad;
    d.w = speed4[q];
    d.y = torque4[q];
    if (HAS_RATIO) {
        d.r = ratio4[q];
    }
    d.valid = vec4<u32>(4u * q) + vec4<u32>(0u, 1u, 2u, 3u) < vec4<u32>(end);
    return d;
}

// Σ (y - r T)² over one quad, given the law's torques t at its speeds.
fn quad_sq(t: vec4<f32>, d: Quad) -> f32 {
    var e: vec4<f32>;
    if (HAS_RATIO) {
        e = d.y - d.r * t;
    } else {
        e = d.y - t;
    }
    e = select(vec4<f32>(0.0), e, d.valid);
    return dot(e, e);
}

fn quad_m1(p: array<f32, 6>, d: Quad) -> f32 {
    let w = d.w;
    return quad_sq(vec4<f32>(torque_m1(p[0], p[1], p[2], p[3], w.x), torque_m1(p[0], p[1], p[2], p[3], w.y),
                             torque_m1(p[0], p[1], p[2], p[3], w.z), torque_m1(p[0], p[1], p[2], p[3], w.w)), d);
}

fn quad_m2(p: array<f32, 6>, d: Quad) -> f32 {
    let w = d.w;
    return quad_sq(vec4<f32>(torque_m2(p[0], p[1], p[2], w.x), torque_m2(p[0], p[1], p[2], w.y),
                             torque_m2(p[0], p[1], p[2], w.z), torque_m2(p[0], p[1], p[2], w.w)), d);
}

fn quad_m3(p: array<f32, 6>, d: Quad) -> f32 {
    let w = d.w;
    return quad_sq(vec4<f32>(torque_m3(p[0], p[1], p[2], p[3], p[4], p[5], w.x),
                             torque_m3(p[0], p[1], p[2], p[3], p[4], p[5], w.y),
                             torque_m3(p[0], p[1], p[2], p[3], p[4], p[5], w.z),
                             torque_m3(p[0], p[1], p[2], p[3], p[4], p[5], w.w)), d);
}

fn quad_m4(p: array<f32, 6>, d: Quad) -> f32 {
    let w = d.w;
    return quad_sq(vec4<f32>(torque_m4(p[0], p[1], p[2], p[3], w.x), torque_m4(p[0], p[1], p[2], p[3], w.y),
                             torque_m4(p[0], p[1], p[2], p[3], w.z), torque_m4(p[0], p[1], p[2], p[3], w.w)), d);
}

// Σ (y - r T)² over quads q0..q1 of law `law` for all four parameter vectors; the switch sits
// outside the loops.
fn block_ssr(law: u32, p: Params4, q0: u32, q1: u32, end: u32) -> vec4<f32> {
    var s = vec4<f32>(0.0);
    switch law {
        case 0u: {
            for (var q = q0; q < q1; q = q + 1u) {
                let d = load_quad(q, end);
                s = s + vec4<f32>(quad_m1(p[0], d), quad_m1(p[1], d), quad_m1(p[2], d), quad_m1(p[3], d));
            }
        }
        case 1u: {
            for (var q = q0; q < q1; q = q + 1u) {
                let d = load_quad(q, end);
                s = s + vec4<f32>(quad_m2(p[0], d), quad_m2(p[1], d), quad_m2(p[2], d), quad_m2(p[3], d));
            }
        }
        case 2u: {
            for (var q = q0; q < q1; q = q + 1u) {
                let d = load_quad(q, end);
                s = s + vec4<f32>(quad_m3(p[0], d), quad_m3(p[1], d), quad_m3(p[2], d), quad_m3(p[3], d));
            }
        }
        default: {
            for (var q = q0; q < q1; q = q + 1u) {
                let d = load_quad(q, end);
                s = s + vec4<f32>(quad_m4(p[0], d), quad_m4(p[1], d), quad_m4(p[2], d), quad_m4(p[3], d));
            }
        }
    }
    return s;
}

// The four sums as if all four candidates followed law `law`, over samples
// data_start..data_end (data_start a multiple of 4), accumulated in blocks as described above.
fn law_slice_ssr(law: u32, p: Params4, data_start: u32, data_end: u32) -> vec4<f32> {
    let first = data_start / 4u;
    let quads = (data_end + 3u) / 4u;
    var total = vec4<f32>(0.0);
    var group = vec4<f32>(0.0);
    var blocks = 0u;
    for (var q0 = first; q0 < quads; q0 = q0 + QUADS_PER_BLOCK) {
        group = group + block_ssr(law, p, q0, min(q0 + QUADS_PER_BLOCK, quads), data_end);
        blocks = blocks + 1u;
        if (blocks == BLOCKS_PER_GROUP) {
            total = total + group;
            group = vec4<f32>(0.0);
            blocks = 0u;
        }
    }
    return total + group;
}

// Σ (y - r T)² of the four candidates with law ids `laws` (0 = m1 .. 3 = m4, NO_LAW for an
// unused slot) and parameters p over samples data_start..data_end. One pass per law present,
// keeping the sums of the candidates of that law: a single pass when all four share a law
// (single-law priors). With mixed laws a SIMD batch already ran every law present in it, one
// candidate per lane; now each pass serves four, so the work per candidate is no larger. The
// passes are written out, not looped, so that each pass's loop is outermost for the limiter.
fn slice_ssr(laws: vec4<u32>, p: Params4, data_start: u32, data_end: u32) -> vec4<f32> {
    var out = vec4<f32>(0.0);
    if (any(laws == vec4<u32>(0u))) {
        out = select(out, law_slice_ssr(0u, p, data_start, data_end), laws == vec4<u32>(0u));
    }
    if (any(laws == vec4<u32>(1u))) {
        out = select(out, law_slice_ssr(1u, p, data_start, data_end), laws == vec4<u32>(1u));
    }
    if (any(laws == vec4<u32>(2u))) {
        out = select(out, law_slice_ssr(2u, p, data_start, data_end), laws == vec4<u32>(2u));
    }
    if (any(laws == vec4<u32>(3u))) {
        out = select(out, law_slice_ssr(3u, p, data_start, data_end), laws == vec4<u32>(3u));
    }
    return out;
}
