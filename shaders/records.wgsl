// Scores the candidates of many records in one dispatch (the selection check's replicates:
// records of equal length, each with its own prior, seed and data). The dispatch's candidates
// are segments laid one after another, each starting on a tile of CANDIDATES (16): a segment is
// one sampler's request (or the part of it that fits the dispatch), candidates regenerated from
// its record's prior as residual.wgsl does (`kind` 0) or explicit proposals as
// score_params.wgsl reads them (`kind` 1), in law order. Tile t belongs
// to segment tile_segment[t]; its record's data lie at quads record_quad.. of the columns.
// Every candidate is scored by the same code, blocks and slices as by the single-record
// kernels, so its SSR is theirs bit for bit. Entry points `main` and `main_tiled` as in
// residual.wgsl. Needs shared/philox.wgsl, shared/job.wgsl, shared/candidate.wgsl,
// shared/proposal.wgsl, shared/laws.wgsl, shared/ssr.wgsl (bindings 2-5) and shared/tile.wgsl.

// One request, its candidates in law order (the host sorts them: a tile of one law makes one
// pass over the data, a tile of four laws four). Keep in sync with `GpuSegment` in
// src/eval/gpu/records.rs.
struct Segment {
    // Index of the record's prior in `priors`.
    record: u32,
    // 0: candidates start + offsets[order + i] of stream `population`, regenerated from the
    // record's prior; 1: proposals start.x + i.
    kind: u32,
    population: u32,
    // Candidates of the request in this segment (the rest of its last tile scores nothing).
    count: u32,
    start: vec2<u32>,
    // First candidate of the segment in the dispatch (a multiple of CANDIDATES).
    first: u32,
    // First quad of the record's data in the columns.
    quad: u32,
    order: u32,
    _pad: u32,
}

@group(0) @binding(0) var<storage, read> priors: array<Prior>;
@group(0) @binding(1) var<storage, read> job: Job;
@group(0) @binding(6) var<storage, read> segments: array<Segment>;
@group(0) @binding(7) var<storage, read> tile_segment: array<u32>;
@group(0) @binding(8) var<storage, read> proposals: array<Proposal>;
// Stream offsets of the kind-0 segments' candidates, in law order.
@group(0) @binding(9) var<storage, read> offsets: array<u32>;

fn job_candidate(job: Job, k: u32) -> JobCandidate {
    let s = segments[tile_segment[k / CANDIDATES]];
    let local = k - s.first;
    if (local >= s.count) {
        return JobCandidate(NO_LAW, array<f32, 6>());
    }
    if (s.kind == 0u) {
        let prior = priors[s.record];
        let c = make_candidate(prior, s.population, add_index(s.start, offsets[s.order + local]));
        return JobCandidate(slot_law(prior, c.slot), c.params);
    }
    let p = proposals[s.start.x + local];
    return JobCandidate(p.law, p.params);
}

// Points the data loads at the record of the tile holding candidate `first`.
fn select_record(first: u32) {
    if (first < job.count) {
        record_quad = segments[tile_segment[first / CANDIDATES]].quad;
    }
}

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let first = CANDIDATES * (gid.x + gid.y * job.row_width);
    select_record(first);
    score_blocked(job, first);
}

@compute @workgroup_size(TILE_WORKGROUP)
fn main_tiled(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let first = CANDIDATES * (wid.x + wid.y * job.row_width);
    select_record(first);
    score_tile(job, first, lid);
}
