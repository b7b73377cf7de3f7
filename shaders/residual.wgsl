// Scores candidates regenerated from (seed, population, index): SSR = Σ (y - r T(w))² of
// candidates start .. start + count - 1 of the stream over the job's slice of the data; the
// host divides by Σy² (f64). Two entry points, one per scoring shape (shared/ssr.wgsl):
// `main`, invocation k scores candidates 16k .. 16k + 15 (register blocking, for SIMD CPU
// drivers), and `main_tiled`, workgroup k scores them (shared/tile.wgsl, for discrete GPUs).
// Needs shared/philox.wgsl, shared/job.wgsl, shared/candidate.wgsl, shared/laws.wgsl,
// shared/ssr.wgsl (bindings 2-5) and shared/tile.wgsl.

@group(0) @binding(0) var<uniform> prior: Prior;
@group(0) @binding(1) var<uniform> job: Job;

fn job_candidate(job: Job, k: u32) -> JobCandidate {
    let c = make_candidate(prior, job.population, add_index(job.start, k));
    return JobCandidate(slot_law(prior, c.slot), c.params);
}

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    score_blocked(job, CANDIDATES * (gid.x + gid.y * job.row_width));
}

@compute @workgroup_size(TILE_WORKGROUP)
fn main_tiled(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    score_tile(job, CANDIDATES * (wid.x + wid.y * job.row_width), lid);
}
