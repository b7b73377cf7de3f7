// Σ (y - r T(w))² of one parameter vector over a slice of the data, shared by the kernels
// that score candidates (residual.wgsl: regenerated from Philox; score_params.wgsl: uploaded
// by the host). Needs laws.wgsl. Declares bindings 2-4 of group 0 (the data columns); the
// kernels including it use the other bindings.
//
// Samples are read four at a time (vec4): on a SIMD driver such as lavapipe every invocation
// of a batch reads the same sample, so loads, not arithmetic, bound the speed; the ratio r is
// read only when the run scales by weight on bit (override HAS_RATIO).
//
// Accumulation is blocked: 64 samples per block (16 quads, a naive f32 sum), 64 blocks per
// group, groups summed per dispatch, dispatches (65,536 samples each) added in order, so no
// partial sum holds more than 64 terms for D up to 4 M (worst-case relative error about
// 4 x 64 ulps, typically a few) and no driver rewrite can undo it. The host splits the data
// into dispatches of 65,536 samples because lavapipe stops any loop after 65,535 iterations
// per invocation (gallivm's loop limiter), which would silently drop the rest of the data.

// False when every sample has r = 1 (the paper's assumption): the ratio column is not read.
override HAS_RATIO: bool = true;

// Samples 4q..4q+3 of bit speed (rad/s), torque (N·m) and weight-on-bit ratio. The last quad
// is padded (w = 1) and its missing samples are masked out.
@group(0) @binding(2) var<storage, read> speed4: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read> torque4: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read> ratio4: array<vec4<f32>>;

const QUADS_PER_BLOCK: u32 = 16u;
const BLOCKS_PER_GROUP: u32 = 64u;

// y - r T for one quad, given the law's torques t at its speeds; 0 past the last sample.
fn residual(t: vec4<f32>, q: u32, end: u32) -> vec4<f32> {
    var e: vec4<f32>;
    if (HAS_RATIO) {
        e = torque4[q] - ratio4[q] * t;
    } else {
        e = torque4[q] - t;
    }
    let valid = vec4<u32>(4u * q) + vec4<u32>(0u, 1u, 2u, 3u) < vec4<u32>(end);
    return select(vec4<f32>(0.0), e, valid);
}

// Σ (y - r T)² over quads q0..q1 for the law `law`; the switch sits outside the loops.
fn block_ssr(law: u32, p: array<f32, 6>, q0: u32, q1: u32, end: u32) -> f32 {
    var s = 0.0;
    switch law {
        case 0u: {
            for (var q = q0; q < q1; q = q + 1u) {
                let w = speed4[q];
                let e = residual(vec4<f32>(torque_m1(p[0], p[1], p[2], p[3], w.x), torque_m1(p[0], p[1], p[2], p[3], w.y),
                                           torque_m1(p[0], p[1], p[2], p[3], w.z), torque_m1(p[0], p[1], p[2], p[3], w.w)), q, end);
                s = s + dot(e, e);
            }
        }
        case 1u: {
            for (var q = q0; q < q1; q = q + 1u) {
                let w = speed4[q];
                let e = residual(vec4<f32>(torque_m2(p[0], p[1], p[2], w.x), torque_m2(p[0], p[1], p[2], w.y),
                                           torque_m2(p[0], p[1], p[2], w.z), torque_m2(p[0], p[1], p[2], w.w)), q, end);
                s = s + dot(e, e);
            }
        }
        case 2u: {
            for (var q = q0; q < q1; q = q + 1u) {
                let w = speed4[q];
                let e = residual(vec4<f32>(torque_m3(p[0], p[1], p[2], p[3], p[4], p[5], w.x),
                                           torque_m3(p[0], p[1], p[2], p[3], p[4], p[5], w.y),
                                           torque_m3(p[0], p[1], p[2], p[3], p[4], p[5], w.z),
                                           torque_m3(p[0], p[1], p[2], p[3], p[4], p[5], w.w)), q, end);
                s = s + dot(e, e);
            }
        }
        default: {
            for (var q = q0; q < q1; q = q + 1u) {
                let w = speed4[q];
                let e = residual(vec4<f32>(torque_m4(p[0], p[1], p[2], p[3], w.x), torque_m4(p[0], p[1], p[2], p[3], w.y),
                                           torque_m4(p[0], p[1], p[2], p[3], w.z), torque_m4(p[0], p[1], p[2], p[3], w.w)), q, end);
                s = s + dot(e, e);
            }
        }
    }
    return s;
}

// Σ (y - r T)² of law `law` at parameters p over samples data_start..data_end (data_start a
// multiple of 4), accumulated in blocks as described above.
fn slice_ssr(law: u32, p: array<f32, 6>, data_start: u32, data_end: u32) -> f32 {
    let first = data_start / 4u;
    let quads = (data_end + 3u) / 4u;
    var total = 0.0;
    var group = 0.0;
    var blocks = 0u;
    for (var q0 = first; q0 < quads; q0 = q0 + QUADS_PER_BLOCK) {
        group = group + block_ssr(law, p, q0, min(q0 + QUADS_PER_BLOCK, quads), data_end);
        blocks = blocks + 1u;
        if (blocks == BLOCKS_PER_GROUP) {
            total = total + group;
            group = 0.0;
            blocks = 0u;
        }
    }
    return total + group;
}
