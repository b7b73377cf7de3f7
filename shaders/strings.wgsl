// The batched string integrator: one drill string per invocation, integrated with a fixed step
// and the Karnopp stick rule, reduced to a summary on the device. The twin of
// `src/simulate/strings.rs` (f64), loop for loop: read its doc comment for the equations.
// Needs shared/laws.wgsl (torque_at) and shared/loop_limit.wgsl (loops_were_cut).

const MAX_NODES: u32 = 16u;
// Words per string of the inputs, the state and the summary. Keep in sync with
// src/eval/gpu/strings.rs.
const INPUT_WORDS: u32 = 12u;
const STATE_WORDS: u32 = 34u;
const SUMMARY_WORDS: u32 = 16u;
const EVENT_PASSES: u32 = 4u;

// Nodes of the chain (the bit the last): fixed per pipeline, so that the loops over nodes
// unroll. The state's arrays are as long as the chain (the host writes its length here when it
// builds the pipeline), so that a short chain's state lives in registers, not in memory.
override NODES: u32 = 1u;
const CHAIN_NODES: u32 = 16u;
// The law of every string of the batch where they share one (its index), so that the law's
// switch folds away; ANY_LAW where they differ.
const ANY_LAW: u32 = 4294967295u;
override LAW: u32 = ANY_LAW;

// Keep in sync with `StringsJob` in src/eval/gpu/strings.rs.
struct StringsJob {
    first: u32,
    count: u32,
    row_width: u32,
    steps_per_sample: u32,
    settle_samples: u32,
    record_samples: u32,
    // On a record's clock (`on_clock`): the settling's steps and where the drive starts in
    // the inputs.
    settle_steps: u32,
    drive_offset: u32,
    dt_s: f32,
    alpha: f32,
    beta: f32,
    stuck_speed: f32,
    // On a record's clock: the settling's step (s). The slice this dispatch integrates: of the
    // steps counted from the first settling step.
    settle_dt_s: f32,
    first_step: u32,
    end_step: u32,
    // The host's most steps a slice (read only to tell a cut invocation).
    slice_steps: u32,
    inertia: array<vec4<f32>, 4>,
    stiffness: array<vec4<f32>, 4>,
}

@group(0) @binding(0) var<uniform> job: StringsJob;
// Per string: law id (bits), Ω (rad/s), r, unused, six parameters (N·m), then, on a record's
// clock, the top element's stiffness (N·m/rad) and β (s). On a record's clock the drive
// follows the strings' inputs from `drive_offset`: Ω (rad/s) and r per sample.
@group(0) @binding(1) var<storage, read> inputs: array<f32>;
// Per string: 16 lags (rad), 16 speeds (rad/s), stuck (0/1), slip direction (±1); read as the
// start, written back as the end.
@group(0) @binding(2) var<storage, read_write> states: array<f32>;
// Per string: samples, stuck, onsets, first onset, last onset (u32 bits), speed min, max, sum
// (rad/s), bit torque min, max, surface torque min, max (N·m), diverged, last stuck, cut by
// the driver (u32 bits).
// On a record's clock: per sample the surface torque (N·m), the bit speed and its least and
// greatest since the sample before (rad/s), then the samples reached, whether the string
// diverged and whether the driver cut its loops (u32 bits).
@group(0) @binding(3) var<storage, read_write> summaries: array<f32>;

struct State {
    u: array<f32, CHAIN_NODES>,
    w: array<f32, CHAIN_NODES>,
}

struct Deriv {
    du: array<f32, CHAIN_NODES>,
    dw: array<f32, CHAIN_NODES>,
}

var<private> law: u32;
var<private> params: array<f32, 6>;
var<private> omega: f32;
var<private> ratio: f32;
var<private> static_nm: f32;
// The top element's stiffness and the stiffness-proportional damping β: the job's, or, on a
// record's clock, each string's own (a run that infers the string gives every candidate its
// own).
var<private> top_stiffness: f32;
var<private> beta: f32;

fn inertia(j: u32) -> f32 {
    return job.inertia[j / 4u][j % 4u];
}

fn stiffness(j: u32) -> f32 {
    if (j == 0u) {
        return top_stiffness;
    }
    return job.stiffness[j / 4u][j % 4u];
}

// dir·r·T(dir·w): the smooth branch of the law for the direction of slip.
fn law_torque(dir: f32, w: f32) -> f32 {
    return dir * ratio * torque_at(law, params, dir * w);
}

// F_j = (K u)_j + (C v)_j with v = Ω − w.
fn string_torque(s: State, j: u32) -> f32 {
    var u_above = 0.0;
    var v_above = 0.0;
    if (j > 0u) {
        u_above = s.u[j - 1u];
        v_above = omega - s.w[j - 1u];
    }
    let v = omega - s.w[j];
    let k = stiffness(j);
    var f = k * (s.u[j] - u_above) + beta * k * (v - v_above) + job.alpha * inertia(j) * v;
    if (j + 1u < NODES) {
        let kb = stiffness(j + 1u);
        f = f - (kb * (s.u[j + 1u] - s.u[j]) + beta * kb * ((omega - s.w[j + 1u]) - v));
    }
    return f;
}

fn derivative(s: State, stuck: bool, dir: f32) -> Deriv {
    var d: Deriv;
    for (var j = 0u; j < NODES; j = j + 1u) {
        d.du[j] = omega - s.w[j];
        var f = string_torque(s, j);
        if (j == NODES - 1u) {
            if (stuck) {
                d.dw[j] = 0.0;
                continue;
            }
            f = f - law_torque(dir, s.w[j]);
        }
        d.dw[j] = f / inertia(j);
    }
    return d;
}

fn along(s: State, d: Deriv, f: f32) -> State {
    var t = s;
    for (var j = 0u; j < NODES; j = j + 1u) {
        t.u[j] = s.u[j] + f * d.du[j];
        t.w[j] = s.w[j] + f * d.dw[j];
    }
    return t;
}

fn rk4(s: State, stuck: bool, dir: f32, h: f32) -> State {
    let k1 = derivative(s, stuck, dir);
    let k2 = derivative(along(s, k1, 0.5 * h), stuck, dir);
    let k3 = derivative(along(s, k2, 0.5 * h), stuck, dir);
    let k4 = derivative(along(s, k3, h), stuck, dir);
    var out = s;
    for (var j = 0u; j < NODES; j = j + 1u) {
        out.u[j] = s.u[j] + h / 6.0 * (k1.du[j] + 2.0 * (k2.du[j] + k3.du[j]) + k4.du[j]);
        out.w[j] = s.w[j] + h / 6.0 * (k1.dw[j] + 2.0 * (k2.dw[j] + k3.dw[j]) + k4.dw[j]);
    }
    return out;
}

fn bit_drive(s: State) -> f32 {
    return string_torque(s, NODES - 1u);
}

struct Motion {
    s: State,
    stuck: bool,
    dir: f32,
}

// A bit at rest: stuck while the string's torque is within ±T_s, else slipping its way.
fn at_rest(m: Motion) -> Motion {
    var out = m;
    let f = bit_drive(m.s);
    out.stuck = abs(f) <= static_nm;
    if (!out.stuck) {
        out.dir = select(-1.0, 1.0, f > 0.0);
    }
    return out;
}

// One step of h through any stop or release inside it.
fn step(m0: Motion, h: f32) -> Motion {
    let bit = NODES - 1u;
    var m = m0;
    var remaining = h;
    for (var event = 0u; event < EVENT_PASSES; event = event + 1u) {
        if (remaining <= 0.0) {
            break;
        }
        let start = m.s;
        if (m.stuck) {
            let end = rk4(start, true, m.dir, remaining);
            let f0 = bit_drive(start);
            let f1 = bit_drive(end);
            if (abs(f1) <= static_nm) {
                m.s = end;
                break;
            }
            let bound = select(-static_nm, static_nm, f1 > 0.0);
            var fraction = 0.0;
            if (abs(f1 - f0) > 0.0) {
                fraction = clamp((bound - f0) / (f1 - f0), 0.0, 1.0);
            }
            let to_release = fraction * remaining;
            m.s = rk4(start, true, m.dir, to_release);
            m.stuck = false;
            m.dir = select(-1.0, 1.0, f1 > 0.0);
            remaining = remaining - to_release;
        } else {
            let end = rk4(start, false, m.dir, remaining);
            let w0 = m.dir * start.w[bit];
            let w1 = m.dir * end.w[bit];
            if (w1 > 0.0) {
                m.s = end;
                break;
            }
            if (w0 <= 0.0) {
                m.s = end;
                m.s.w[bit] = 0.0;
                m = at_rest(m);
                break;
            }
            let to_zero = remaining * w0 / (w0 - w1);
            m.s = rk4(start, false, m.dir, to_zero);
            m.s.w[bit] = 0.0;
            remaining = remaining - to_zero;
            m = at_rest(m);
        }
    }
    return m;
}

fn bit_torque(m: Motion) -> f32 {
    if (m.stuck) {
        return clamp(bit_drive(m.s), -static_nm, static_nm);
    }
    return law_torque(m.dir, m.s.w[NODES - 1u]);
}

fn surface_torque(m: Motion) -> f32 {
    let k = stiffness(0u);
    return k * m.s.u[0] + beta * k * (omega - m.s.w[0]);
}

// The law (the batch's where it is compiled in) and parameters of the string whose inputs
// start at `b`.
fn read_law(b: u32) {
    law = select(bitcast<u32>(inputs[b]), LAW, LAW != ANY_LAW);
    params = array<f32, 6>(inputs[b + 4u], inputs[b + 5u], inputs[b + 6u], inputs[b + 7u], inputs[b + 8u], inputs[b + 9u]);
}

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let local = gid.x + gid.y * job.row_width;
    if (local >= job.count) {
        return;
    }
    let i = job.first + local;
    let b = INPUT_WORDS * i;
    read_law(b);
    omega = inputs[b + 1u];
    ratio = inputs[b + 2u];
    static_nm = max(ratio * torque_at(law, params, 0.0), 0.0);
    top_stiffness = job.stiffness[0].x;
    beta = job.beta;
    let runaway = 1000.0 * max(abs(omega), 1.0);

    let sb = STATE_WORDS * i;
    var m: Motion;
    for (var j = 0u; j < NODES; j = j + 1u) {
        m.s.u[j] = states[sb + j];
        m.s.w[j] = states[sb + MAX_NODES + j];
    }
    m.stuck = states[sb + 2u * MAX_NODES] != 0.0;
    // A string's slip direction from its speed at its start (the twin's), from where it was
    // left on a later slice.
    m.dir = select(1.0, -1.0, m.s.w[NODES - 1u] < 0.0);
    if (job.first_step > 0u) {
        m.dir = states[sb + 2u * MAX_NODES + 1u];
    }

    var samples = 0u;
    var stuck_count = 0u;
    var onsets = 0u;
    var first_onset = 0u;
    var last_onset = 0u;
    var last_stuck = false;
    var speed_min = 3.0e38;
    var speed_max = -3.0e38;
    var speed_sum = 0.0;
    var bit_min = 3.0e38;
    var bit_max = -3.0e38;
    var surface_min = 3.0e38;
    var surface_max = -3.0e38;
    var diverged = false;
    var cut = false;
    // A slice after the first goes on from the summary so far (the state is in `states`).
    let o = SUMMARY_WORDS * i;
    if (job.first_step > 0u) {
        samples = bitcast<u32>(summaries[o]);
        stuck_count = bitcast<u32>(summaries[o + 1u]);
        onsets = bitcast<u32>(summaries[o + 2u]);
        first_onset = bitcast<u32>(summaries[o + 3u]);
        last_onset = bitcast<u32>(summaries[o + 4u]);
        speed_min = summaries[o + 5u];
        speed_max = summaries[o + 6u];
        speed_sum = summaries[o + 7u];
        bit_min = summaries[o + 8u];
        bit_max = summaries[o + 9u];
        surface_min = summaries[o + 10u];
        surface_max = summaries[o + 11u];
        diverged = bitcast<u32>(summaries[o + 12u]) != 0u;
        last_stuck = bitcast<u32>(summaries[o + 13u]) != 0u;
        cut = bitcast<u32>(summaries[o + 14u]) != 0u;
        if (diverged) {
            return;
        }
    }
    // This dispatch's slice of the steps, counted from the settling's first: lavapipe ends an
    // invocation's loops after 65,535 iterations together (the loops over the nodes counted
    // too), so the host slices, inside a sample period where a period holds too many steps.
    var k = job.first_step % job.steps_per_sample;
    var period = job.first_step / job.steps_per_sample;
    for (var s = job.first_step; s < job.end_step; s = s + 1u) {
        m = step(m, job.dt_s);
        k = k + 1u;
        if (k < job.steps_per_sample) {
            continue;
        }
        k = 0u;
        let w = m.s.w[NODES - 1u];
        // A NaN fails both comparisons: diverged.
        if (!(abs(w) <= runaway) || !(abs(m.s.u[NODES - 1u]) < 3.0e38)) {
            diverged = true;
            break;
        }
        if (period >= job.settle_samples) {
            let stuck = abs(w) < job.stuck_speed;
            if (stuck) {
                if (!(samples > 0u && last_stuck)) {
                    if (onsets == 0u) {
                        first_onset = samples;
                    }
                    last_onset = samples;
                    onsets = onsets + 1u;
                }
                stuck_count = stuck_count + 1u;
            }
            let tb = bit_torque(m);
            let ts = surface_torque(m);
            speed_min = min(speed_min, w);
            speed_max = max(speed_max, w);
            speed_sum = speed_sum + w;
            bit_min = min(bit_min, tb);
            bit_max = max(bit_max, tb);
            surface_min = min(surface_min, ts);
            surface_max = max(surface_max, ts);
            samples = samples + 1u;
            last_stuck = stuck;
        }
        period = period + 1u;
    }

    // The nodes past the chain's keep what they held.
    for (var j = 0u; j < NODES; j = j + 1u) {
        states[sb + j] = m.s.u[j];
        states[sb + MAX_NODES + j] = m.s.w[j];
    }
    // After the last loop that writes: a write-back cut short is told too.
    cut = cut || loops_were_cut(job.slice_steps >> 31u);
    states[sb + 2u * MAX_NODES] = select(0.0, 1.0, m.stuck);
    states[sb + 2u * MAX_NODES + 1u] = m.dir;
    summaries[o] = bitcast<f32>(samples);
    summaries[o + 1u] = bitcast<f32>(stuck_count);
    summaries[o + 2u] = bitcast<f32>(onsets);
    summaries[o + 3u] = bitcast<f32>(first_onset);
    summaries[o + 4u] = bitcast<f32>(last_onset);
    summaries[o + 5u] = speed_min;
    summaries[o + 6u] = speed_max;
    summaries[o + 7u] = speed_sum;
    summaries[o + 8u] = bit_min;
    summaries[o + 9u] = bit_max;
    summaries[o + 10u] = surface_min;
    summaries[o + 11u] = surface_max;
    summaries[o + 12u] = bitcast<f32>(select(0u, 1u, diverged));
    summaries[o + 13u] = bitcast<f32>(select(0u, 1u, last_stuck));
    summaries[o + 14u] = bitcast<f32>(select(0u, 1u, cut));
}

// Words of state per string on a record's clock, between slices: lag, speed (rad/s), stuck
// (0/1), slip direction, the bit speed's least and greatest since the sample before, samples
// written (u32 bits), and 0 while running, 1 once done, 2 once diverged.
const CLOCK_STATE_WORDS: u32 = 8u;

// The drive of sample `k` of a record's clock from now on (the twin's set_operating_point).
fn drive_at(k: u32) {
    let d = job.drive_offset + 2u * k;
    omega = inputs[d];
    ratio = inputs[d + 1u];
    static_nm = max(ratio * torque_at(law, params, 0.0), 0.0);
}

// Still within physical bounds under the current drive (the twin's in_bounds).
fn in_bounds(m: Motion) -> bool {
    let bit = NODES - 1u;
    let runaway = 1000.0 * max(abs(omega), 1.0);
    return abs(m.s.w[bit]) <= runaway && abs(m.s.u[bit]) < 3.0e38;
}

// One 1-DOF string on a record's clock, the twin of `simulate_on_clock` in
// src/simulate/surface.rs: from rest with the bit stuck, settled for `settle_steps` steps of
// `settle_dt_s` at the first sample's drive, then `steps_per_sample` steps of `dt_s` to each
// next sample under the sample before's drive; per sample the surface torque, the bit speed
// and the bit speed's extremes over the steps since the sample before. The steps are counted
// from the settling's first, and each dispatch integrates the slice [first_step, end_step):
// lavapipe ends an invocation's loops after 65,535 iterations together, so the host slices,
// and runs a chunk again in shorter slices where the kernel tells it was cut.
@compute @workgroup_size(64)
fn on_clock(@builtin(global_invocation_id) gid: vec3<u32>) {
    let local = gid.x + gid.y * job.row_width;
    if (local >= job.count) {
        return;
    }
    let i = job.first + local;
    let b = INPUT_WORDS * i;
    read_law(b);
    top_stiffness = inputs[b + 10u];
    beta = inputs[b + 11u];
    let bit = NODES - 1u;
    let samples = job.record_samples;
    let settle = job.settle_steps;
    let per_sample = job.steps_per_sample;
    let o = (4u * samples + 3u) * i;
    let sb = CLOCK_STATE_WORDS * i;

    var m: Motion;
    var least = 3.0e38;
    var greatest = -3.0e38;
    var reached = 0u;
    var done = false;
    var diverged = false;
    if (job.first_step == 0u) {
        m.s.u[bit] = 0.0;
        m.s.w[bit] = 0.0;
        m.stuck = true;
        m.dir = 1.0;
    } else {
        m.s.u[bit] = states[sb];
        m.s.w[bit] = states[sb + 1u];
        m.stuck = states[sb + 2u] != 0.0;
        m.dir = states[sb + 3u];
        least = states[sb + 4u];
        greatest = states[sb + 5u];
        reached = bitcast<u32>(states[sb + 6u]);
        done = states[sb + 7u] != 0.0;
        diverged = states[sb + 7u] == 2.0;
    }
    if (done) {
        return;
    }
    // The sample whose drive is in force (sample 0's through the settling).
    var driven = 0u;
    drive_at(0u);
    // Without a settling the first sample is the string at rest.
    if (job.first_step == 0u && settle == 0u) {
        summaries[o] = surface_torque(m);
        summaries[o + 1u] = m.s.w[bit];
        summaries[o + 2u] = m.s.w[bit];
        summaries[o + 3u] = m.s.w[bit];
        reached = 1u;
    }
    // A pass per sample period (the settling one), its steps in a loop of their own: on a CPU
    // driver what a loop's pass holds runs for every lane whether or not a lane takes it, so
    // the drive's change (a torque of the law) and the sample's writes are reached once a
    // period, not once a step.
    var g = job.first_step;
    loop {
        if (!(g < job.end_step && reached < samples)) {
            break;
        }
        let settling = g < settle;
        var ends_at = settle;
        var dt = job.settle_dt_s;
        if (!settling) {
            // Toward sample n under sample n − 1's drive.
            let n = (g - settle) / per_sample + 1u;
            if (driven != n - 1u) {
                driven = n - 1u;
                drive_at(driven);
            }
            ends_at = settle + n * per_sample;
            dt = job.dt_s;
        }
        let stop = min(ends_at, job.end_step);
        for (; g < stop; g = g + 1u) {
            m = step(m, dt);
            if (!settling) {
                least = min(least, m.s.w[bit]);
                greatest = max(greatest, m.s.w[bit]);
            }
        }
        if (g == ends_at) {
            if (!in_bounds(m)) {
                diverged = true;
                break;
            }
            let w = m.s.w[bit];
            let at = o + 4u * reached;
            summaries[at] = surface_torque(m);
            summaries[at + 1u] = w;
            summaries[at + 2u] = min(least, w);
            summaries[at + 3u] = max(greatest, w);
            least = 3.0e38;
            greatest = -3.0e38;
            reached = reached + 1u;
        }
    }
    done = diverged || reached >= samples;
    // After the last loop that writes (the trace's samples): a cut slice is run again.
    let cut = bitcast<u32>(summaries[o + 4u * samples + 2u]) != 0u || loops_were_cut(job.slice_steps >> 31u);
    states[sb] = m.s.u[bit];
    states[sb + 1u] = m.s.w[bit];
    states[sb + 2u] = select(0.0, 1.0, m.stuck);
    states[sb + 3u] = m.dir;
    states[sb + 4u] = least;
    states[sb + 5u] = greatest;
    states[sb + 6u] = bitcast<f32>(reached);
    states[sb + 7u] = select(select(0.0, 1.0, done), 2.0, diverged);
    summaries[o + 4u * samples] = bitcast<f32>(reached);
    summaries[o + 4u * samples + 1u] = bitcast<f32>(select(0u, 1u, diverged));
    summaries[o + 4u * samples + 2u] = bitcast<f32>(select(0u, 1u, cut));
}
