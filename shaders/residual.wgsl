// Scores candidates: invocation k regenerates candidates start + 4k .. start + 4k + 3 of the
// stream from (seed, population, index) and writes their SSR = Σ (y - r T(w))² over the job's
// slice of the data (shared/ssr.wgsl: four candidates per invocation); the host divides by Σy²
// (f64). Needs shared/philox.wgsl, shared/job.wgsl, shared/candidate.wgsl, shared/laws.wgsl,
// shared/ssr.wgsl (bindings 2-4).

@group(0) @binding(0) var<uniform> prior: Prior;
@group(0) @binding(1) var<uniform> job: Job;
@group(0) @binding(5) var<storage, read_write> ssr: array<f32>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let first = 4u * (gid.x + gid.y * job.row_width);
    if (first >= job.count) {
        return;
    }
    var laws = vec4<u32>(NO_LAW);
    var p: Params4;
    for (var j = 0u; j < 4u; j = j + 1u) {
        if (first + j < job.count) {
            let c = make_candidate(prior, job.population, add_index(job.start, first + j));
            laws[j] = prior.law_id[c.slot];
            p[j] = c.params;
        }
    }
    let sums = slice_ssr(laws, p, job.data_start, job.data_end);
    for (var j = 0u; j < 4u; j = j + 1u) {
        let k = first + j;
        if (k < job.count) {
            if (job.accumulate == 1u) {
                ssr[k] = ssr[k] + sums[j];
            } else {
                ssr[k] = sums[j];
            }
        }
    }
}
