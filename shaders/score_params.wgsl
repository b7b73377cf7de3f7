// Scores explicit parameter vectors uploaded by the host (the SMC sampler's perturbed
// proposals, which need log/cos/sqrt and are therefore generated once, on the host): SSR =
// Σ (y - r T(w))² of proposals job.start.x .. job.start.x + count - 1 over the job's slice of
// the data; the host divides by Σy² (f64). Entry points `main` and `main_tiled` as in
// residual.wgsl. Needs shared/job.wgsl, shared/proposal.wgsl, shared/laws.wgsl, shared/ssr.wgsl (bindings 2-5) and
// shared/tile.wgsl.

@group(0) @binding(0) var<storage, read> proposals: array<Proposal>;
@group(0) @binding(1) var<storage, read> job: Job;

fn job_candidate(job: Job, k: u32) -> JobCandidate {
    let proposal = proposals[job.start.x + k];
    return JobCandidate(proposal.law, proposal.params);
}

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    score_blocked(job, CANDIDATES * (gid.x + gid.y * job.row_width));
}

@compute @workgroup_size(TILE_WORKGROUP)
fn main_tiled(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    score_tile(job, CANDIDATES * (wid.x + wid.y * job.row_width), lid);
}
