// Scores explicit parameter vectors uploaded by the host (the SMC sampler's perturbed
// proposals, which need log/cos/sqrt and are therefore generated once, on the host): invocation
// k writes SSR = Σ (y - r T(w))² of proposals job.start.x + 16k .. job.start.x + 16k + 15 over
// the job's slice of the data (shared/ssr.wgsl: 16 candidates per invocation); the host divides
// by Σy² (f64). Needs shared/job.wgsl, shared/laws.wgsl, shared/ssr.wgsl (bindings 2-5).

// One proposal: law id (0 = m1 .. 3 = m4) and its parameters (unused ones 0). Keep in sync
// with `GpuProposal` in src/eval/gpu/residual.rs.
struct Proposal {
    law: u32,
    params: array<f32, 6>,
    _pad: u32,
}

@group(0) @binding(0) var<storage, read> proposals: array<Proposal>;
@group(0) @binding(1) var<uniform> job: Job;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let first = CANDIDATES * (gid.x + gid.y * job.row_width);
    if (first >= job.count) {
        return;
    }
    var laws = Laws(vec4<u32>(NO_LAW), vec4<u32>(NO_LAW), vec4<u32>(NO_LAW), vec4<u32>(NO_LAW));
    var p: Params;
    for (var j = 0u; j < CANDIDATES; j = j + 1u) {
        if (first + j < job.count) {
            let proposal = proposals[job.start.x + first + j];
            laws[j / 4u][j % 4u] = proposal.law;
            p[j] = proposal.params;
        }
    }
    store_sums(first, job.count, job.accumulate == 1u, slice_ssr(laws, p, job.data_start, job.data_end));
}
