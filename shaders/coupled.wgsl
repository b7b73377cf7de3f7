// The coupled axial-torsional bit (RGD) on the 1-DOF string: one string per invocation, its rock
// surface a ring of cells per blade sector, integrated with a fixed semi-implicit Euler step and
// reduced to a summary on the device. The twin of `src/simulate/coupled.rs` (f64), loop for
// loop: read its doc comment for the equations and the contact rules.
//
// A string is integrated over several dispatches, each a slice of its sample periods: its state
// (ring included) and its summary's running sums stay in storage between them. lavapipe stops
// an invocation's loops once they have run 65,535 iterations together (gallivm's loop limiter),
// so no dispatch may run more than a few thousand steps; the host slices, and runs a chunk
// again in shorter slices where the kernel tells it was cut. Needs shared/loop_limit.wgsl
// (loops_were_cut).

// Keep in sync with src/simulate/coupled.rs and src/eval/gpu/coupled.rs.
const RING_CELLS: u32 = 240u;
const REBASE_M: f32 = 0.01;
const SUM_BLOCK: u32 = 64u;
const INPUT_WORDS: u32 = 12u;
// lag, speed, compression, axial speed, depth, phase, behind_old, then the ring.
const STATE_WORDS: u32 = 247u;
const RING_AT: u32 = 7u;
const SUMMARY_WORDS: u32 = 24u;
const TAU: f32 = 6.283185307179586;

struct CoupledJob {
    first: u32,
    count: u32,
    row_width: u32,
    steps_per_sample: u32,
    settle_samples: u32,
    record_samples: u32,
    // 1 under a feed, 0 under a weight.
    feed: u32,
    // The slice of sample periods this dispatch integrates: [first_period, end_period).
    first_period: u32,
    end_period: u32,
    // 1 where the host wrote each string's start into `states`, 0 for steady drilling.
    start_given: u32,
    // The host's most steps a slice (read only to tell a cut invocation).
    slice_steps: u32,
    _pad2: u32,
    dt_s: f32,
    mass_kg: f32,
    inertia_kg_m2: f32,
    k_t: f32,
    c_t: f32,
    k_a: f32,
    c_a: f32,
    stuck_speed: f32,
}

@group(0) @binding(0) var<uniform> job: CoupledJob;
// Per string: radius (m), ε (MPa), ζ, σ (MPa), l (mm), μ, γ, N, Ω₀ (rad/s), the drive (W₀ in N
// or V_f in m/s), the kick (rad/s), unused.
@group(0) @binding(1) var<storage, read> inputs: array<f32>;
// Per string: the state (STATE_WORDS): the host's start or written by the first slice, carried
// by the others.
@group(0) @binding(2) var<storage, read_write> states: array<f32>;
// Per string: samples, stuck, onsets, first onset, last onset, off bottom, backward (u32 bits);
// speed min, max, sum (rad/s); axial speed sum (m/s); WOB min, max, sum (N); torque min, max,
// sum (N·m); diverged (u32 bits); then what the next slice carries on with: the open block's
// four sums and whether the last sample was stuck.
@group(0) @binding(3) var<storage, read_write> summaries: array<f32>;

// Where this invocation's ring starts in `states`.
var<private> ring_at: u32;
// The ring cell just ahead of the bit and its height: a cell a step reads about ten times before
// the bit crosses it, kept here rather than read from storage at every step (on a CPU driver a
// read per lane is a gather). Written through wherever the ring changes; NO_CELL until read.
const NO_CELL: u32 = 0xffffffffu;
var<private> ahead_cell: u32 = NO_CELL;
var<private> ahead_height: f32 = 0.0;

// Writes a ring cell, and the copy of it ahead of the bit where it is that cell.
fn set_cell(c: u32, height: f32) {
    states[ring_at + c] = height;
    if (c == ahead_cell) {
        ahead_height = height;
    }
}

struct Bit {
    blades: f32,
    sector: f32,
    cell: f32,
    cut_w: f32,
    cut_t: f32,
    contact_w: f32,
    arm: f32,
    omega: f32,
    drive: f32,
}

struct State {
    lag: f32,
    speed: f32,
    compression: f32,
    axial_speed: f32,
    depth: f32,
    phase: f32,
    behind_old: f32,
}

struct Forces {
    wob: f32,
    torque: f32,
    dn: f32,
}

// A cell index k into the ring: k mod RING_CELLS. The indices met lie in [-2·RING_CELLS,
// 2·RING_CELLS) (a step crosses at most RING_CELLS cells from a phase within one sector), so
// selects do it; an integer modulo has no vector form on a CPU driver and costs a division per
// lane.
fn wrap(k: f32) -> u32 {
    let m = i32(RING_CELLS);
    var j = i32(k);
    j = select(j, j + m, j < 0);
    j = select(j, j + m, j < 0);
    j = select(j, j - m, j >= m);
    return u32(j);
}

fn surface(b: Bit, s: State) -> f32 {
    let x = s.phase / b.cell - 0.5;
    let behind = floor(x);
    let frac = x - behind;
    let c = wrap(behind + 1.0);
    if (c != ahead_cell) {
        ahead_cell = c;
        ahead_height = states[ring_at + c];
    }
    return s.behind_old + frac * (ahead_height - s.behind_old);
}

fn transport(b: Bit, s_in: State, turn: f32, depth_from: f32, depth_to: f32) -> State {
    var s = s_in;
    let start = s.phase;
    let end = start + turn;
    if (turn > 0.0) {
        var k = floor(start / b.cell - 0.5) + 1.0;
        var crossed = 0u;
        loop {
            let at = (k + 0.5) * b.cell;
            if (!(at <= end && crossed < RING_CELLS)) {
                break;
            }
            let depth = depth_from + (depth_to - depth_from) * (at - start) / turn;
            let c = wrap(k);
            s.behind_old = states[ring_at + c];
            set_cell(c, max(s.behind_old, depth));
            k = k + 1.0;
            crossed = crossed + 1u;
        }
    } else if (turn < 0.0) {
        var k = floor(start / b.cell - 0.5);
        var crossed = 0u;
        loop {
            if (!((k + 0.5) * b.cell > end && crossed < RING_CELLS)) {
                break;
            }
            let c = wrap(k);
            let before = wrap(k - 1.0);
            set_cell(c, s.behind_old);
            s.behind_old = states[ring_at + before];
            k = k - 1.0;
            crossed = crossed + 1u;
        }
    }
    // end.rem_euclid(sector)
    s.phase = end - b.sector * floor(end / b.sector);
    return s;
}

struct Stepped {
    s: State,
    f: Forces,
}

fn step(b: Bit, s_in: State, dt: f32) -> Stepped {
    var s = s_in;
    let dn = s.depth - surface(b, s);
    let on_bottom = dn >= 0.0;
    let d = select(0.0, b.blades * dn, on_bottom);
    let wc = b.cut_w * d;
    let tc = b.cut_t * d;
    let wf = select(0.0, b.contact_w, on_bottom);
    var fa = b.drive - job.c_a * s.axial_speed;
    if (job.feed != 0u) {
        fa = job.k_a * s.compression + job.c_a * (b.drive - s.axial_speed);
    }

    let v = s.axial_speed;
    var wob = fa;
    var mobilised = 0.0;
    var held = false;
    if (v > 0.0 || (v == 0.0 && (!on_bottom || fa > wc + wf))) {
        wob = wc + wf;
        mobilised = 1.0;
    } else if (v < 0.0 || fa < wc) {
        wob = wc;
    } else {
        mobilised = select(0.0, (fa - wc) / wf, wf > 0.0);
        held = true;
    }
    var v_new = select(v + (fa - wob) / job.mass_kg * dt, 0.0, held);
    if (on_bottom && v != 0.0 && v_new * v <= 0.0) {
        v_new = 0.0;
    }

    let tf = b.arm * mobilised * wf;
    let tau = job.k_t * s.lag + job.c_t * (b.omega - s.speed);
    let w = s.speed;
    var torque = tau;
    var stuck = false;
    if (w > 0.0 || (w == 0.0 && tau > tc + tf)) {
        torque = tc + tf;
    } else if (w < 0.0 || tau < -tf) {
        torque = -tf;
    } else {
        stuck = true;
    }
    var w_new = select(w + (tau - torque) / job.inertia_kg_m2 * dt, 0.0, stuck);
    if (on_bottom && w != 0.0 && w_new * w <= 0.0) {
        w_new = 0.0;
    }

    let depth_new = s.depth + v_new * dt;
    if (job.feed != 0u) {
        s.compression = s.compression + (b.drive - v_new) * dt;
    }
    s.lag = s.lag + (b.omega - w_new) * dt;
    s = transport(b, s, w_new * dt, s.depth, depth_new);
    s.depth = depth_new;
    s.axial_speed = v_new;
    s.speed = w_new;
    if (abs(s.depth) > REBASE_M) {
        let by = s.depth;
        for (var c = 0u; c < RING_CELLS; c = c + 1u) {
            states[ring_at + c] = states[ring_at + c] - by;
        }
        ahead_height = ahead_height - by;
        s.behind_old = s.behind_old - by;
        s.depth = 0.0;
    }
    return Stepped(s, Forces(wob, torque, dn));
}

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let local = gid.x + gid.y * job.row_width;
    if (local >= job.count) {
        return;
    }
    let i = job.first + local;
    let p = INPUT_WORDS * i;
    let radius = inputs[p];
    let eps = inputs[p + 1u] * 1.0e6;
    let zeta = inputs[p + 2u];
    let sigma = inputs[p + 3u] * 1.0e6;
    let wear = inputs[p + 4u] * 1.0e-3;
    let mu = inputs[p + 5u];
    let gamma = inputs[p + 6u];
    let blades = inputs[p + 7u];
    let omega = inputs[p + 8u];
    let drive = inputs[p + 9u];
    let kick = inputs[p + 10u];
    let sector = TAU / blades;
    let b = Bit(
        blades,
        sector,
        sector / f32(RING_CELLS),
        radius * zeta * eps,
        0.5 * radius * radius * eps,
        radius * wear * sigma,
        0.5 * radius * mu * gamma,
        omega,
        drive,
    );
    let sb = STATE_WORDS * i;
    ring_at = sb + RING_AT;
    let o = SUMMARY_WORDS * i;

    var s = State(states[sb], states[sb + 1u], states[sb + 2u], states[sb + 3u], states[sb + 4u], states[sb + 5u], states[sb + 6u]);
    if (job.first_period == 0u && job.start_given == 0u) {
        // Steady drilling at the drive (CoupledJob::steady), its surface in the ring.
        let turns = omega / TAU;
        var dn0 = drive / (blades * turns);
        if (job.feed == 0u) {
            dn0 = max((drive - b.contact_w) / (blades * (b.cut_w + job.c_a * turns)), 0.0);
        }
        let d0 = blades * dn0;
        let rate0 = d0 * turns;
        var wob0 = b.cut_w * d0 + b.contact_w;
        if (job.feed == 0u) {
            wob0 = drive - job.c_a * rate0;
        }
        let torque0 = b.cut_t * d0 + b.arm * (wob0 - b.cut_w * d0);
        s = State(torque0 / job.k_t, omega + kick, wob0 / job.k_a, rate0, 0.0, 0.0, 0.0);
        for (var k = 0u; k < RING_CELLS; k = k + 1u) {
            let ahead = (f32(k) + 0.5) * b.cell;
            states[ring_at + k] = -dn0 * (1.0 - ahead / sector);
        }
        s.behind_old = -dn0 * (1.0 + 0.5 * b.cell / sector);
    }
    if (job.first_period == 0u) {
        for (var k = 0u; k < SUMMARY_WORDS; k = k + 1u) {
            summaries[o + k] = 0.0;
        }
        summaries[o + 7u] = 3.0e38;
        summaries[o + 8u] = -3.0e38;
        summaries[o + 11u] = 3.0e38;
        summaries[o + 12u] = -3.0e38;
        summaries[o + 14u] = 3.0e38;
        summaries[o + 15u] = -3.0e38;
    }
    var diverged = bitcast<u32>(summaries[o + 17u]) != 0u;
    if (diverged) {
        return;
    }
    let runaway = 1000.0 * max(omega, 1.0);

    var samples = bitcast<u32>(summaries[o]);
    var stuck_count = bitcast<u32>(summaries[o + 1u]);
    var onsets = bitcast<u32>(summaries[o + 2u]);
    var first_onset = bitcast<u32>(summaries[o + 3u]);
    var last_onset = bitcast<u32>(summaries[o + 4u]);
    var off_bottom = bitcast<u32>(summaries[o + 5u]);
    var backward = bitcast<u32>(summaries[o + 6u]);
    var speed_min = summaries[o + 7u];
    var speed_max = summaries[o + 8u];
    var total = vec4<f32>(summaries[o + 9u], summaries[o + 10u], summaries[o + 13u], summaries[o + 16u]);
    var wob_min = summaries[o + 11u];
    var wob_max = summaries[o + 12u];
    var torque_min = summaries[o + 14u];
    var torque_max = summaries[o + 15u];
    var block = vec4<f32>(summaries[o + 18u], summaries[o + 19u], summaries[o + 20u], summaries[o + 21u]);
    var last_stuck = bitcast<u32>(summaries[o + 22u]) != 0u;
    var f = Forces(0.0, 0.0, 0.0);
    for (var period = job.first_period; period < job.end_period; period = period + 1u) {
        for (var k = 0u; k < job.steps_per_sample; k = k + 1u) {
            let out = step(b, s, job.dt_s);
            s = out.s;
            f = out.f;
        }
        // A NaN fails every comparison: diverged.
        if (!(abs(s.speed) <= runaway && abs(s.axial_speed) < 1000.0 && abs(s.lag) < 1.0e30)) {
            diverged = true;
            break;
        }
        if (period >= job.settle_samples) {
            let stuck = abs(s.speed) < job.stuck_speed;
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
            last_stuck = stuck;
            off_bottom = off_bottom + select(0u, 1u, f.dn < 0.0);
            backward = backward + select(0u, 1u, s.speed < 0.0);
            speed_min = min(speed_min, s.speed);
            speed_max = max(speed_max, s.speed);
            wob_min = min(wob_min, f.wob);
            wob_max = max(wob_max, f.wob);
            torque_min = min(torque_min, f.torque);
            torque_max = max(torque_max, f.torque);
            block = block + vec4<f32>(s.speed, s.axial_speed, f.wob, f.torque);
            samples = samples + 1u;
            if (samples % SUM_BLOCK == 0u) {
                total = total + block;
                block = vec4<f32>(0.0);
            }
        }
    }
    let cut = bitcast<u32>(summaries[o + 23u]) != 0u || loops_were_cut(job.slice_steps >> 31u);
    let last_slice = job.end_period == job.settle_samples + job.record_samples;
    if (last_slice || diverged) {
        // The open block joins the total once, at the end (as the CPU's `finish`).
        total = total + block;
        block = vec4<f32>(0.0);
    }
    states[sb] = s.lag;
    states[sb + 1u] = s.speed;
    states[sb + 2u] = s.compression;
    states[sb + 3u] = s.axial_speed;
    states[sb + 4u] = s.depth;
    states[sb + 5u] = s.phase;
    states[sb + 6u] = s.behind_old;
    summaries[o] = bitcast<f32>(samples);
    summaries[o + 1u] = bitcast<f32>(stuck_count);
    summaries[o + 2u] = bitcast<f32>(onsets);
    summaries[o + 3u] = bitcast<f32>(first_onset);
    summaries[o + 4u] = bitcast<f32>(last_onset);
    summaries[o + 5u] = bitcast<f32>(off_bottom);
    summaries[o + 6u] = bitcast<f32>(backward);
    summaries[o + 7u] = speed_min;
    summaries[o + 8u] = speed_max;
    summaries[o + 9u] = total.x;
    summaries[o + 10u] = total.y;
    summaries[o + 11u] = wob_min;
    summaries[o + 12u] = wob_max;
    summaries[o + 13u] = total.z;
    summaries[o + 14u] = torque_min;
    summaries[o + 15u] = torque_max;
    summaries[o + 16u] = total.w;
    summaries[o + 17u] = bitcast<f32>(select(0u, 1u, diverged));
    summaries[o + 18u] = block.x;
    summaries[o + 19u] = block.y;
    summaries[o + 20u] = block.z;
    summaries[o + 21u] = block.w;
    summaries[o + 22u] = bitcast<f32>(select(0u, 1u, last_stuck));
    summaries[o + 23u] = bitcast<f32>(select(0u, 1u, cut));
}

