// Σ (y - r T(w))² of parameter vectors over a slice of the data, shared by the kernels that
// score candidates (residual.wgsl: regenerated from Philox; score_params.wgsl: uploaded by the
// host). Needs laws.wgsl and job.wgsl. Declares bindings 2-4 of group 0 (the data columns) and
// 5 (the sums out); the kernels including it use bindings 0-1 and define
// `job_candidate(job, k) -> JobCandidate`, candidate k of the job. Two shapes share this
// contract: the register-blocked one below (entry point `main`, for SIMD CPU drivers) and the
// tiled one of tile.wgsl (entry point `main_tiled`, for discrete GPUs).
//
// On a SIMD driver such as lavapipe every invocation of a batch reads the same sample, and each
// storage load becomes a per-lane scalar loop, so loads, not arithmetic, bound the speed. Hence
// samples are read four at a time (vec4), and each invocation scores 16 candidates (register
// blocking, in four vec4 groups): one loaded quad serves 64 evaluations (4 candidates per
// invocation: 2x the speed of 1; 16: 1.3x that of 4 for m3, 1.6x for m2). The ratio r is read
// only when the run scales by weight on bit (override HAS_RATIO).
//
// The same loops give the lag-1 sum Σ e_t e_(t-1) of the AR(1) noise model (override LAG, a
// second pass the host dispatches after the squares): each pair of consecutive samples of a
// record counts in the quad of its later sample, whose first lane reads the sample before it
// (the last of the previous quad) once more; one torque more per quad, in that pass only.
//
// Accumulation is blocked: 64 samples per block (16 quads, a naive f32 sum), 64 blocks per
// group, groups summed per dispatch, dispatches (32,768 samples each) added in order, so no
// partial sum holds more than 64 terms for D up to 4 M (worst-case relative error about
// 4 x 64 ulps, typically a few) and no driver rewrite can undo it. lavapipe stops loops once an
// invocation has run 65,535 iterations of all its loops together (gallivm's loop limiter),
// silently dropping the rest of the data; a dispatch makes up to four passes (one per law, see
// slice_ssr) of 8,192 quads in 512 blocks, 34,816 iterations, so the host slices the data into
// dispatches of 32,768 samples.

// False when every sample has r = 1 (the paper's assumption): the ratio column is not read.
override HAS_RATIO: bool = true;

// True for the lag pass: the kernel sums e_t e_(t-1) instead of e_t².
override LAG: bool = false;

// Samples 4q..4q+3 of bit speed (rad/s), torque (N·m) and weight-on-bit ratio. The last quad
// is padded (w = 1) and its missing samples are masked out.
@group(0) @binding(2) var<storage, read> speed4: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read> torque4: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read> ratio4: array<vec4<f32>>;
// SSR per candidate of the job (written, or added to when the data come in several dispatches).
@group(0) @binding(5) var<storage, read_write> ssr: array<f32>;

const QUADS_PER_BLOCK: u32 = 16u;
const BLOCKS_PER_GROUP: u32 = 64u;

// Law id of an unused candidate slot: matches no law, scores 0 (laws are 0 = m1 .. 3 = m4, then
// law files' laws from 4 on).
const NO_LAW: u32 = 4294967295u;

// Candidates per invocation (four groups of four). Keep in sync with CANDIDATES_PER_INVOCATION
// in src/eval/gpu/residual.rs.
const CANDIDATES: u32 = 16u;

// Parameters of the candidates of one invocation (unused ones 0); law ids and sums of
// candidate 4g + i at [g][i].
alias Params = array<array<f32, 6>, 16>;
alias Laws = array<vec4<u32>, 4>;
alias Sums = array<vec4<f32>, 4>;

// One quad of data: speeds, torques, ratios and which samples exist; in the lag pass also the
// sample before the quad's first (speed, torque, ratio), if the record has one.
struct Quad {
    w: vec4<f32>,
    y: vec4<f32>,
    r: vec4<f32>,
    valid: vec4<bool>,
    w_prev: f32,
    y_prev: f32,
    r_prev: f32,
    has_prev: bool,
}

// First quad of the record being scored: 0 for the single-record kernels; the multi-record
// kernel (records.wgsl) sets it per invocation, the records lying one after another in the
// columns. Quad indices q stay relative to the record.
var<private> record_quad: u32 = 0u;

fn load_quad(q: u32, end: u32) -> Quad {
    var d: Quad;
    d.w = speed4[record_quad + q];
    d.y = torque4[record_quad + q];
    if (HAS_RATIO) {
        d.r = ratio4[record_quad + q];
    }
    d.valid = vec4<u32>(4u * q) + vec4<u32>(0u, 1u, 2u, 3u) < vec4<u32>(end);
    if (LAG && q > 0u) {
        d.has_prev = true;
        d.w_prev = speed4[record_quad + q - 1u].w;
        d.y_prev = torque4[record_quad + q - 1u].w;
        d.r_prev = 1.0;
        if (HAS_RATIO) {
            d.r_prev = ratio4[record_quad + q - 1u].w;
        }
    }
    return d;
}

// Σ e² over one quad, e = y - r T, given the law's torques t at its speeds; in the lag pass
// Σ e_t e_(t-1) of the pairs whose later sample lies in the quad, given also the torque t_prev
// at the sample before it.
fn quad_sq(t: vec4<f32>, t_prev: f32, d: Quad) -> f32 {
    var e: vec4<f32>;
    if (HAS_RATIO) {
        e = d.y - d.r * t;
    } else {
        e = d.y - t;
    }
    e = select(vec4<f32>(0.0), e, d.valid);
    if (LAG) {
        let e_prev = select(0.0, d.y_prev - d.r_prev * t_prev, d.has_prev);
        return dot(e, vec4<f32>(e_prev, e.x, e.y, e.z));
    }
    return dot(e, e);
}

// Σ (y - r T)² over quads q0..q1 of law `law` for all 16 parameter vectors; the switch sits
// outside the loops, each loaded quad serves every candidate.
fn block_ssr(law: u32, p: Params, q0: u32, q1: u32, end: u32) -> Sums {
    var s: Sums;
    switch law {
        // The build writes a case per built-in law (laws/*.toml), the host one per law file's
        // law, at the next line.
        // LAW_BLOCKS
        default: {}
    }
    return s;
}

fn add_sums(a: Sums, b: Sums) -> Sums {
    return Sums(a[0] + b[0], a[1] + b[1], a[2] + b[2], a[3] + b[3]);
}

// The sums as if every candidate followed law `law`, over samples data_start..data_end
// (data_start a multiple of 4), accumulated in blocks as described above.
fn law_slice_ssr(law: u32, p: Params, data_start: u32, data_end: u32) -> Sums {
    let first = data_start / 4u;
    let quads = (data_end + 3u) / 4u;
    var total: Sums;
    var group: Sums;
    var blocks = 0u;
    for (var q0 = first; q0 < quads; q0 = q0 + QUADS_PER_BLOCK) {
        group = add_sums(group, block_ssr(law, p, q0, min(q0 + QUADS_PER_BLOCK, quads), data_end));
        blocks = blocks + 1u;
        if (blocks == BLOCKS_PER_GROUP) {
            total = add_sums(total, group);
            group = Sums();
            blocks = 0u;
        }
    }
    return add_sums(total, group);
}

// One pass for law `law` if any candidate follows it: `out` with that law's candidates' sums.
fn law_pass(law: u32, laws: Laws, p: Params, data_start: u32, data_end: u32, out: Sums) -> Sums {
    let l = vec4<u32>(law);
    if (!(any(laws[0] == l) || any(laws[1] == l) || any(laws[2] == l) || any(laws[3] == l))) {
        return out;
    }
    let s = law_slice_ssr(law, p, data_start, data_end);
    return Sums(select(out[0], s[0], laws[0] == l), select(out[1], s[1], laws[1] == l),
                select(out[2], s[2], laws[2] == l), select(out[3], s[3], laws[3] == l));
}

// Σ (y - r T)² of the candidates with law ids `laws` (0 = m1 .. 3 = m4, NO_LAW for an unused
// slot) and parameters p over samples data_start..data_end: one pass per law present, a single
// one when all share a law (single-law priors). With mixed laws a SIMD batch already ran every
// law present in it, one candidate per lane; now each pass serves 16, so the work per candidate
// is no larger.
fn slice_ssr(laws: Laws, p: Params, data_start: u32, data_end: u32) -> Sums {
    var out: Sums;
    // The build writes a pass per built-in law (laws/*.toml), the host one per law file's law,
    // at the next line.
    // LAW_PASSES
    return out;
}

// Law id (0 = m1 .. 3 = m4) and parameters (unused ones 0) of one candidate of a job.
struct JobCandidate {
    law: u32,
    params: array<f32, 6>,
}

// The register-blocked shape: the invocation scoring candidates first..first+15 of `job`
// fetches them, scores them over the job's slice of the data and stores their sums.
fn score_blocked(job: Job, first: u32) {
    if (first >= job.count) {
        return;
    }
    var laws = Laws(vec4<u32>(NO_LAW), vec4<u32>(NO_LAW), vec4<u32>(NO_LAW), vec4<u32>(NO_LAW));
    var p: Params;
    for (var j = 0u; j < CANDIDATES; j = j + 1u) {
        if (first + j < job.count) {
            let c = job_candidate(job, first + j);
            laws[j / 4u][j % 4u] = c.law;
            p[j] = c.params;
        }
    }
    store_sums(first, job.count, job.accumulate == 1u, slice_ssr(laws, p, job.data_start, job.data_end));
}

// Writes (or, with `accumulate`, adds) the sums of candidates first..first+15 of the job, those
// below `count`.
fn store_sums(first: u32, count: u32, accumulate: bool, sums: Sums) {
    for (var j = 0u; j < CANDIDATES; j = j + 1u) {
        let k = first + j;
        if (k < count) {
            if (accumulate) {
                ssr[k] = ssr[k] + sums[j / 4u][j % 4u];
            } else {
                ssr[k] = sums[j / 4u][j % 4u];
            }
        }
    }
}
