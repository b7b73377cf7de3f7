// Gaussian kernel sums of the SMC importance weights: invocation i writes
// S_i = Σ_j w_j exp(-(|d|² - c_j (d·x_j)²) / 2), d = y_i - x_j, over the job's slice of
// sources j, where y (targets, the new particles) and x (sources, the previous population)
// are whitened coordinates computed on the host (L⁻¹ (φ - μ), unused coordinates 0) and c_j
// gives source j the covariance I + x_j x_jᵀ (0: the identity). The CPU twin is
// `kernel_sums` in src/eval/cpu.rs. Needs shared/laws.wgsl (exp_f32).
//
// Accumulation is blocked as in shared/ssr.wgsl: 64 terms per block, 64 blocks per group,
// groups summed per dispatch and dispatches (32,768 sources each: lavapipe stops a loop after
// 65,535 iterations per invocation, counting a nested loop's iterations over all its entries)
// added in order.

// Keep in sync with `SumsJob` in src/eval/gpu/kernel_sums.rs.
struct SumsJob {
    // Targets in the dispatch.
    count: u32,
    // Sources source_start..source_end are summed by this dispatch.
    source_start: u32,
    source_end: u32,
    // Targets per row of the (possibly 2-D) dispatch grid.
    row_width: u32,
    // 0: write the dispatch's sum; 1: add it to what earlier dispatches wrote.
    accumulate: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

@group(0) @binding(0) var<uniform> job: SumsJob;
// Two vec4 per target: coordinates 0-3, then 4-5 and two zeros.
@group(0) @binding(1) var<storage, read> targets: array<vec4<f32>>;
// Two vec4 per source: coordinates 0-3, then 4-5, the weight w_j and c_j.
@group(0) @binding(2) var<storage, read> sources: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read_write> sums: array<f32>;

const TERMS_PER_BLOCK: u32 = 64u;
const BLOCKS_PER_GROUP: u32 = 64u;

fn term(a: vec4<f32>, b: vec4<f32>, j: u32) -> f32 {
    let x = sources[2u * j];
    let xw = sources[2u * j + 1u];
    let d0 = a - x;
    let d1 = b.xy - xw.xy;
    let along = dot(d0, x) + dot(d1, xw.xy);
    // The difference of two near-equal squares can round below 0.
    let r2 = max(dot(d0, d0) + dot(d1, d1) - xw.w * along * along, 0.0);
    return xw.z * exp_f32(-0.5 * r2);
}

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.x + gid.y * job.row_width;
    if (i >= job.count) {
        return;
    }
    let a = targets[2u * i];
    let b = targets[2u * i + 1u];
    var total = 0.0;
    var group = 0.0;
    var blocks = 0u;
    for (var j0 = job.source_start; j0 < job.source_end; j0 = j0 + TERMS_PER_BLOCK) {
        var s = 0.0;
        let j1 = min(j0 + TERMS_PER_BLOCK, job.source_end);
        for (var j = j0; j < j1; j = j + 1u) {
            s = s + term(a, b, j);
        }
        group = group + s;
        blocks = blocks + 1u;
        if (blocks == BLOCKS_PER_GROUP) {
            total = total + group;
            group = 0.0;
            blocks = 0u;
        }
    }
    let sum = total + group;
    if (job.accumulate == 1u) {
        sums[i] = sums[i] + sum;
    } else {
        sums[i] = sum;
    }
}
