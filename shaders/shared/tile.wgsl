// The tiled scoring shape, for discrete GPUs: a workgroup of TILE_WORKGROUP invocations scores a
// tile of CANDIDATES (16) candidates. Needs ssr.wgsl (its data bindings, Quad, the per-law quad
// sums, store_sums) and a `job_candidate` from the kernel.
//
// A GPU keeps hundreds of thousands of invocations resident; one invocation per 16 candidates
// (the register-blocked shape) leaves it mostly empty at the N users run (25,000-65,536). Here
// every 16 candidates get a whole workgroup:
// - the first 16 invocations each regenerate (or read) one candidate, once per tile, and sort
//   the tile by law in workgroup memory, so a group of four consecutive sorted candidates
//   mostly shares one law;
// - every invocation strides over the samples (quads lid, lid + TILE_WORKGROUP, ...: adjacent
//   invocations load adjacent quads, coalesced) and scores each group of four candidates once
//   per law present in the group (law passes are uniform across the workgroup: no divergence;
//   a tile of four laws costs about 7 group passes, not 16);
// - the TILE_WORKGROUP partial sums of each candidate meet in a fixed-order tree reduction in workgroup
//   memory (deterministic, no atomics).
// Accumulation stays blocked as in ssr.wgsl: an invocation sums blocks of QUADS_PER_BLOCK of its
// quads naively and adds the blocks (at most 8 per dispatch of 32,768 samples), the tree adds
// TILE_WORKGROUP partial sums pairwise, dispatches are added in order. Each loop of an invocation runs at
// most 7 passes x (8 blocks + 128 quads) iterations per dispatch, far under lavapipe's limit.

// Invocations per workgroup of `main_tiled` (the host dispatches whole workgroups, one per tile).
override TILE_WORKGROUP: u32 = 64u;

// Parameters of one group of four candidates.
alias Four = array<array<f32, 6>, 4>;

// Laws of the tile's candidates by position in the tile (NO_LAW past the job's end).
var<workgroup> tile_law_by_position: array<u32, 16>;
// The tile sorted by law (NO_LAW last): law, parameters and position in the tile of rank r.
var<workgroup> tile_law: array<u32, 16>;
var<workgroup> tile_params: array<array<f32, 6>, 16>;
var<workgroup> tile_position: array<u32, 16>;
// Partial sums of every invocation, by rank, for the tree reduction.
var<workgroup> tile_partial: array<Sums, TILE_WORKGROUP>;

// Σ (y - r T)² of four candidates of law `law` over quads lid, lid + TILE_WORKGROUP, ... of
// samples data_start..data_end (data_start a multiple of 4), in blocks.
fn strided_ssr(law: u32, p: Four, lid: u32, data_start: u32, data_end: u32) -> vec4<f32> {
    let quads = (data_end + 3u) / 4u;
    let span = QUADS_PER_BLOCK * TILE_WORKGROUP;
    var total = vec4<f32>();
    for (var b = data_start / 4u + lid; b < quads; b = b + span) {
        let block_end = min(b + span, quads);
        var block = vec4<f32>();
        switch law {
            // The build writes a case per built-in law (laws/*.toml), the host one per law
            // file's law, at the next line.
            // LAW_STRIDED
            default: {}
        }
        total = total + block;
    }
    return total;
}

// Scores the tile of candidates first..first+15 of `job` (called by every invocation of the
// workgroup, `lid` its local index) over the job's slice of the data and stores their sums.
fn score_tile(job: Job, first: u32, lid: u32) {
    // `first` depends on the workgroup only: the whole workgroup returns or none of it.
    if (first >= job.count) {
        return;
    }
    var law = NO_LAW;
    var params: array<f32, 6>;
    if (lid < CANDIDATES && first + lid < job.count) {
        let c = job_candidate(job, first + lid);
        law = c.law;
        params = c.params;
    }
    if (lid < CANDIDATES) {
        tile_law_by_position[lid] = law;
    }
    workgroupBarrier();
    // Rank by (law, position): a stable counting sort of 16.
    if (lid < CANDIDATES) {
        var rank = 0u;
        for (var k = 0u; k < CANDIDATES; k = k + 1u) {
            let other = tile_law_by_position[k];
            rank = rank + select(0u, 1u, other < law || (other == law && k < lid));
        }
        tile_law[rank] = law;
        tile_params[rank] = params;
        tile_position[rank] = lid;
    }
    workgroupBarrier();
    var laws: Laws;
    for (var r = 0u; r < CANDIDATES; r = r + 1u) {
        laws[r / 4u][r % 4u] = tile_law[r];
    }
    var sums: Sums;
    // law_ids: every law the kernel scores (the host declares it, law files' laws included).
    for (var i = 0u; i < LAW_COUNT; i = i + 1u) {
        let l = law_ids[i];
        for (var g = 0u; g < 4u; g = g + 1u) {
            let of_law = laws[g] == vec4<u32>(l);
            if (any(of_law)) {
                let p = Four(tile_params[4u * g], tile_params[4u * g + 1u], tile_params[4u * g + 2u],
                             tile_params[4u * g + 3u]);
                sums[g] = select(sums[g], strided_ssr(l, p, lid, job.data_start, job.data_end), of_law);
            }
        }
    }
    tile_partial[lid] = sums;
    workgroupBarrier();
    for (var stride = TILE_WORKGROUP / 2u; stride > 0u; stride = stride / 2u) {
        if (lid < stride) {
            tile_partial[lid] = add_sums(tile_partial[lid], tile_partial[lid + stride]);
        }
        workgroupBarrier();
    }
    if (lid == 0u) {
        var by_position: Sums;
        for (var r = 0u; r < CANDIDATES; r = r + 1u) {
            let k = tile_position[r];
            by_position[k / 4u][k % 4u] = tile_partial[0][r / 4u][r % 4u];
        }
        store_sums(first, job.count, job.accumulate == 1u, by_position);
    }
}
