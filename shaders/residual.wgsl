// Scores candidates: invocation k regenerates candidate start + k of the stream from
// (seed, population, index) and writes SSR = Σ (y - r T(w))² over the job's slice of the data
// (shared/ssr.wgsl); the host divides by Σy² (f64). Needs shared/philox.wgsl, shared/job.wgsl,
// shared/candidate.wgsl, shared/laws.wgsl, shared/ssr.wgsl (bindings 2-4).

@group(0) @binding(0) var<uniform> prior: Prior;
@group(0) @binding(1) var<uniform> job: Job;
@group(0) @binding(5) var<storage, read_write> ssr: array<f32>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let k = gid.x + gid.y * job.row_width;
    if (k >= job.count) {
        return;
    }
    let c = make_candidate(prior, job.population, add_index(job.start, k));
    let sum = slice_ssr(prior.law_id[c.slot], c.params, job.data_start, job.data_end);
    if (job.accumulate == 1u) {
        ssr[k] = ssr[k] + sum;
    } else {
        ssr[k] = sum;
    }
}
