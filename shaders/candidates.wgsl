// Writes, for candidate k of the dispatch, its raw Philox blocks and the candidate itself, so
// tests and `bitrock parity` can compare them bit for bit with the CPU.
// Needs shared/philox.wgsl, shared/candidate.wgsl and shared/job.wgsl.
@group(0) @binding(0) var<uniform> prior: Prior;
@group(0) @binding(1) var<uniform> job: Job;
// 16 words per candidate: block 0 (4), block 1 (4), slot, parameters 0..5 as f32 bits, 0.
@group(0) @binding(2) var<storage, read_write> out: array<u32>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let k = gid.x + gid.y * job.row_width;
    if (k >= job.count) {
        return;
    }
    let index = add_index(job.start, k);
    let b0 = philox4x32_10(vec4<u32>(index.x, index.y, job.population, 0u), prior.key);
    let b1 = philox4x32_10(vec4<u32>(index.x, index.y, job.population, 1u), prior.key);
    let c = make_candidate(prior, job.population, index);
    let base = 16u * k;
    for (var i = 0u; i < 4u; i = i + 1u) {
        out[base + i] = b0[i];
        out[base + 4u + i] = b1[i];
    }
    out[base + 8u] = c.slot;
    for (var j = 0u; j < 6u; j = j + 1u) {
        out[base + 9u + j] = bitcast<u32>(c.params[j]);
    }
    out[base + 15u] = 0u;
}
