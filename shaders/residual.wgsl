// Scores candidates: invocation k regenerates candidates start + 16k .. start + 16k + 15 of the
// stream from (seed, population, index) and writes their SSR = Σ (y - r T(w))² over the job's
// slice of the data (shared/ssr.wgsl: 16 candidates per invocation); the host divides by Σy²
// (f64). Needs shared/philox.wgsl, shared/job.wgsl, shared/candidate.wgsl, shared/laws.wgsl,
// shared/ssr.wgsl (bindings 2-5).

@group(0) @binding(0) var<uniform> prior: Prior;
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
            let c = make_candidate(prior, job.population, add_index(job.start, first + j));
            laws[j / 4u][j % 4u] = prior.law_id[c.slot];
            p[j] = c.params;
        }
    }
    store_sums(first, job.count, job.accumulate == 1u, slice_ssr(laws, p, job.data_start, job.data_end));
}
