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
// A string's state in lines of four words: lag, speed, compression, axial speed; depth, phase,
// behind_old, the lag's fine part; the phase's, the speed's and the compression's fine parts,
// one unused; then the ring, four cells a line.
const STATE_LINES: u32 = 63u;
const RING_AT: u32 = 3u;
const RING_LINES: u32 = 60u;
const SUMMARY_WORDS: u32 = 24u;
const TAU: f32 = 6.283185307179586;
// The lag (rad), the bit speed (rad/s), the phase (rad) and the compression (m) are each carried
// as a whole part, a multiple of QUANTUM, and a fine part: see `carry`.
const QUANTUM: f32 = 0.0009765625;
const PER_QUANTUM: f32 = 1024.0;
const CARRY_STEPS: u32 = 64u;

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
// Per string: the state (STATE_LINES of four words): the host's start or written by the first
// slice, carried by the others.
@group(0) @binding(2) var<storage, read_write> states: array<vec4<f32>>;
// Per string: samples, stuck, onsets, first onset, last onset, off bottom, backward (u32 bits);
// speed min, max, sum (rad/s); axial speed sum (m/s); WOB min, max, sum (N); torque min, max,
// sum (N·m); diverged (u32 bits); then what the next slice carries on with: the open block's
// four sums and whether the last sample was stuck.
@group(0) @binding(3) var<storage, read_write> summaries: array<f32>;

// Where this invocation's ring starts in `states` (lines).
var<private> ring_at: u32;
// The ring's line (four cells) holding the cell just ahead of the bit, held here: read from
// storage when the bit reaches it and written back, where changed, when it leaves. The bit
// reads the cell ahead of it at every step and crosses a cell every ten steps or so at 60 rpm,
// so a line serves some forty steps. On a CPU driver each storage access of a lane-varying
// address is a loop over the lanes, run wherever it is written whether or not a lane takes it,
// and every branch runs for all lanes; so a step's code never reaches storage. Storage is read
// and written after the steps of the subgroup's fast loop (`main`), where one of its lanes needs
// it: `transport`'s passes, reading or writing only where the line changes. NO_LINE until read.
const NO_LINE: u32 = 0xffffffffu;
var<private> line_at: u32 = NO_LINE;
// The held line's first cell, as f32: cell indices are f32 (whole numbers, exact), so a step
// converts none to an integer (a conversion saturates on the way: three operations on the
// step's chain) and wraps them with selects; only a line's place in storage is an integer. A
// step into the line after moves it; `line_at` follows it after the fast loop (`sync_line_at`).
var<private> line_base: f32 = 0.0;
var<private> line: vec4<f32>;
var<private> line_changed: bool = false;
// The line after the held one, read ahead (`next_read`), and the line the bit left, to write
// back (`back_due`): a bit that turns forward steps from one line into the next in registers,
// and the storage passes that follow some lane's need write back and read ahead for all lanes.
// A step into the line after needs it read ahead, so a storage pass, which writes the line
// behind back, comes between any two: `back` is free at each step and written back before the
// kernel ends.
var<private> next: vec4<f32>;
var<private> next_read: bool = false;
var<private> back: vec4<f32>;
var<private> back_due: bool = false;

// How far (m) this dispatch's rebases took the heights in registers down: storage keeps the
// heights as they were, a height there being the one in registers plus `unrebased`, and the
// dispatch's end takes storage down by it. So a rebase needs no pass over the ring's sixty
// lines (on a CPU driver each line's read and write is a loop over the lanes), and storage's
// heights stay within a few centimetres of zero: a dispatch drills a slice of a second or so.
var<private> unrebased: f32 = 0.0;

// The line after line `l`.
fn line_after(l: u32) -> u32 {
    return select(l + 1u, 0u, l + 1u == RING_LINES);
}

// Writes the held line back where it changed.
fn flush_line() {
    if (line_changed) {
        states[ring_at + line_at] = line + vec4<f32>(unrebased);
        line_changed = false;
    }
}

// Holds the ring's line `l`.
fn hold_line(l: u32) {
    if (l != line_at) {
        flush_line();
        line = states[ring_at + l] - vec4<f32>(unrebased);
        line_at = l;
        line_base = f32(4u * l);
    }
}

// `line_at` from `line_base`, after the fast loop's steps.
fn sync_line_at() {
    line_at = line_of(line_base);
}

// The ring's line holding cell `c`.
fn line_of(c: f32) -> u32 {
    return u32(c) >> 2u;
}

// The height (m) of ring cell `c`, in the held line.
fn held(c: f32) -> f32 {
    let k = c - line_base;
    return select(select(line.x, line.y, k == 1.0), select(line.z, line.w, k == 3.0), k >= 2.0);
}

// Sets ring cell `c`, in the held line.
fn put(c: f32, height: f32) {
    line = select(line, vec4<f32>(height), vec4<f32>(0.0, 1.0, 2.0, 3.0) == vec4<f32>(c - line_base));
    line_changed = true;
}

// The cell just ahead of the bit at `phase` (within the sector).
fn ahead_of(b: Bit, phase: f32) -> f32 {
    return wrapped(floor(phase * b.per_cell - 0.5) + 1.0);
}

struct Bit {
    blades: f32,
    sector: f32,
    // The sector as a multiple of QUANTUM and the rest: a wrapped phase keeps its whole part
    // a multiple of QUANTUM.
    sector_whole: f32,
    sector_rest: f32,
    cell: f32,
    // 1/cell, dt/mass and dt/inertia: a step multiplies by them (its one division is the cut's
    // depth where the bit crosses a cell).
    per_cell: f32,
    cut_w: f32,
    cut_t: f32,
    contact_w: f32,
    arm: f32,
    omega: f32,
    drive: f32,
    // The string's, from the job: read once here, not at every step (a CPU driver may gather a
    // uniform's field lane by lane inside a loop).
    feed: bool,
    dt: f32,
    dt_per_mass: f32,
    dt_per_inertia: f32,
    k_t: f32,
    c_t: f32,
    k_a: f32,
    c_a: f32,
}

struct State {
    lag: f32,
    lag_fine: f32,
    speed: f32,
    speed_fine: f32,
    compression: f32,
    compression_fine: f32,
    axial_speed: f32,
    depth: f32,
    phase: f32,
    phase_fine: f32,
    behind_old: f32,
}

// The lag, the bit speed, the phase and the compression are sums of a step's small increments on
// values large beside them: the lag grows by (Ω₀ − Ω)·dt, some 10⁻⁴ rad, on tens of radians, where
// an f32 ulp is 2-4·10⁻⁶ (rounded each step, the same way step after step, a stuck bit's torque
// rises up to a per cent or so fast or slow); the phase by Ω·dt on up to π/2; under a feed, the
// compression by (V_f − V)·dt, near steady drilling a few of its ulps or less than one, on some
// 0.6-0.9 m (summed so, a fed bit's weight and rate of penetration drift). Each is carried as a
// whole part, a multiple of QUANTUM, and a fine part that the steps add to; their sum, rounded
// once, is read where the value is needed. `carry_all` moves the fine part's whole quanta to the
// whole part, which takes them exactly (a floor and powers of two: no algebra a compiler may apply
// undoes it, as it could a compensated sum's), where the state is read and then every CARRY_STEPS
// steps and at the end of each sample period, so that the fine part stays small beside the whole
// (at most the increments of CARRY_STEPS steps beyond a quantum) and keeps the increments' low
// bits.
fn carry_all(s: ptr<function, State>) {
    let lag = carry((*s).lag, (*s).lag_fine);
    (*s).lag = lag.x;
    (*s).lag_fine = lag.y;
    let speed = carry((*s).speed, (*s).speed_fine);
    (*s).speed = speed.x;
    (*s).speed_fine = speed.y;
    let phase = carry((*s).phase, (*s).phase_fine);
    (*s).phase = phase.x;
    (*s).phase_fine = phase.y;
    let compression = carry((*s).compression, (*s).compression_fine);
    (*s).compression = compression.x;
    (*s).compression_fine = compression.y;
}

// `x` plus `fine` as a whole part, a multiple of QUANTUM, and a fine part in [0, QUANTUM).
// Where `x` is a multiple of QUANTUM already (the steps keep it so), `x − whole` is 0.
fn carry(x: f32, fine: f32) -> vec2<f32> {
    let whole = floor(x * PER_QUANTUM) * QUANTUM;
    let rest = (x - whole) + fine;
    let q = floor(rest * PER_QUANTUM) * QUANTUM;
    return vec2<f32>(whole + q, rest - q);
}

struct Forces {
    wob: f32,
    torque: f32,
    dn: f32,
}

// A cell index k into the ring, k mod RING_CELLS, for k in [-RING_CELLS, 2·RING_CELLS): the
// cells around a phase within the sector, as a step meets them. Selects do it; an integer
// modulo has no vector form on a CPU driver and costs a division per lane.
fn wrapped(k: f32) -> f32 {
    let m = f32(RING_CELLS);
    let j = select(k, k + m, k < 0.0);
    return select(j, j - m, j >= m);
}

// `wrapped` for k in [-2·RING_CELLS, 2·RING_CELLS): `transport` crosses up to RING_CELLS cells
// from a phase within one sector.
fn wrapped_wide(k: f32) -> f32 {
    return wrapped(select(k, k + f32(RING_CELLS), k < 0.0));
}

// Where the bit is among the ring's cells: the cell just ahead of it (f32, not wrapped: in
// [0, RING_CELLS] for a phase within the sector) and how far it is from the middle of the cell
// behind to that of the one ahead (0 to 1). Set by `locate` from the phase each step leaves, so
// that the next step reads it, not works it out again.
var<private> ahead_k: f32;
var<private> ahead_frac: f32;

fn locate(b: Bit, phase: f32) {
    let x = phase * b.per_cell - 0.5;
    let behind = floor(x);
    ahead_k = behind + 1.0;
    ahead_frac = x - behind;
}

// The rock surface's height (m) under the bit (`locate`d), from the cell behind it and the one
// ahead, held since the last step.
fn surface(s: State) -> f32 {
    return s.behind_old + ahead_frac * (held(wrapped(ahead_k)) - s.behind_old);
}

// What a pass of `transport` does to its cell.
const HOLD: u32 = 0u;
const CUT: u32 = 1u;
const RESTORE: u32 = 2u;
const READ_BEHIND: u32 = 3u;

// Turns the bit by `turn` (rad) while its depth goes from `depth_from` to `depth_to` (m): the
// cells it crosses forward are cut to the depth there; backward, it leaves the surface as it
// was. Where the depth passes REBASE_M, every height is taken down by it (f32 keeps its
// resolution near zero): those in registers here, those in storage by `unrebased`. One cell a
// pass, each through the held line, and a last pass where the cell ahead of the bit lies in
// another line, to hold it: the sequence of reads and writes of the CPU twin's `transport`.
fn transport(b: Bit, s_in: State, turn: f32, depth_from: f32, depth_to: f32, wrap_phase: bool) -> State {
    var s = s_in;
    let start = s.phase + s.phase_fine;
    var whole = s.phase;
    var fine = s.phase_fine + turn;
    let end = whole + fine;
    // end.rem_euclid(sector), unless the step wrapped it already.
    let sectors = select(0.0, floor(end / b.sector), wrap_phase);
    whole = whole - sectors * b.sector_whole;
    fine = fine - sectors * b.sector_rest;
    let phase = whole + fine;
    let ahead = ahead_of(b, phase);
    let rebase = abs(depth_to) > REBASE_M;
    var k = floor(start * b.per_cell - 0.5) + select(0.0, 1.0, turn > 0.0);
    var crossed = 0u;
    var behind_next = false;
    loop {
        var c = ahead;
        var op = HOLD;
        if (turn > 0.0 && (k + 0.5) * b.cell <= end && crossed < RING_CELLS) {
            c = wrapped_wide(k);
            op = CUT;
        } else if (turn < 0.0 && behind_next) {
            c = wrapped_wide(k - 1.0);
            op = READ_BEHIND;
        } else if (turn < 0.0 && (k + 0.5) * b.cell > end && crossed < RING_CELLS) {
            c = wrapped_wide(k);
            op = RESTORE;
        } else if (line_of(ahead) == line_at) {
            break;
        }
        hold_line(line_of(c));
        if (op == HOLD) {
            break;
        }
        if (op == CUT) {
            let depth = depth_from + (depth_to - depth_from) * ((k + 0.5) * b.cell - start) / turn;
            s.behind_old = held(c);
            put(c, max(s.behind_old, depth));
            k = k + 1.0;
            crossed = crossed + 1u;
        } else if (op == RESTORE) {
            put(c, s.behind_old);
            behind_next = true;
        } else {
            s.behind_old = held(c);
            behind_next = false;
            k = k - 1.0;
            crossed = crossed + 1u;
        }
    }
    s.phase = whole;
    s.phase_fine = fine;
    if (rebase) {
        s.behind_old = s.behind_old - depth_to;
        line = line - vec4<f32>(depth_to);
        unrebased = unrebased + depth_to;
    }
    return s;
}

struct Stepped {
    f: Forces,
    // Whether the ring's work of the step is left to `transport`, from the state the step
    // left, over `turn` (rad) while the depth goes from `depth_from` to `depth_to` (m):
    // `whole`, with the phase and the height behind the bit still those before the step; else
    // only the holding of the line ahead, the phase wrapped (a turn of zero).
    slow: bool,
    whole: bool,
    turn: f32,
    depth_from: f32,
    depth_to: f32,
}

fn step(b: Bit, s_at: ptr<function, State>) -> Stepped {
    let dt = b.dt;
    var s = *s_at;
    let dn = s.depth - surface(s);
    let on_bottom = dn >= 0.0;
    let d = select(0.0, b.blades * dn, on_bottom);
    let wc = b.cut_w * d;
    let tc = b.cut_t * d;
    let wf = select(0.0, b.contact_w, on_bottom);
    var fa = b.drive - b.c_a * s.axial_speed;
    if (b.feed) {
        fa = b.k_a * (s.compression + s.compression_fine) + b.c_a * (b.drive - s.axial_speed);
    }

    let v = s.axial_speed;
    var wob = fa;
    var axially_held = false;
    if (v > 0.0 || (v == 0.0 && (!on_bottom || fa > wc + wf))) {
        wob = wc + wf;
    } else if (v < 0.0 || fa < wc) {
        wob = wc;
    } else {
        axially_held = true;
    }
    var v_new = select(v + (fa - wob) * b.dt_per_mass, 0.0, axially_held);
    if (on_bottom && v != 0.0 && v_new * v <= 0.0) {
        v_new = 0.0;
    }

    let tf = b.arm * (wob - wc);
    let w = s.speed + s.speed_fine;
    let tau = b.k_t * (s.lag + s.lag_fine) + b.c_t * (b.omega - w);
    var torque = tau;
    var stuck = false;
    if (w > 0.0 || (w == 0.0 && tau > tc + tf)) {
        torque = tc + tf;
    } else if (w < 0.0 || tau < -tf) {
        torque = -tf;
    } else {
        stuck = true;
    }
    var w_fine = s.speed_fine + (tau - torque) * b.dt_per_inertia;
    var w_new = s.speed + w_fine;
    if (stuck || (on_bottom && w != 0.0 && w_new * w <= 0.0)) {
        s.speed = 0.0;
        w_fine = 0.0;
        w_new = 0.0;
    }

    let depth_new = s.depth + v_new * dt;
    if (b.feed) {
        s.compression_fine = s.compression_fine + (b.drive - v_new) * dt;
    }
    s.lag_fine = s.lag_fine + (b.omega - w_new) * dt;

    // The ring's work done here, in the held line: a turn forward that crosses at most the cell
    // ahead (held), with no rebase; the same operations as `transport`'s on that path. Where the
    // next cell ahead lies in the line after, read ahead, the bit steps into it; in any other,
    // `transport` only holds it (a turn of zero). Any other step is left to `transport` whole.
    let turn = w_new * dt;
    let start = s.phase + s.phase_fine;
    let fine = s.phase_fine + turn;
    let end = s.phase + fine;
    let k = ahead_k;
    let crosses = turn > 0.0 && (k + 0.5) * b.cell <= end;
    let whole = turn < 0.0 || abs(depth_new) > REBASE_M || (crosses && (k + 1.5) * b.cell <= end);
    var left = turn;
    var depth_from = s.depth;
    if (!whole) {
        if (crosses) {
            let c = wrapped(k);
            let depth = s.depth + (depth_new - s.depth) * ((k + 0.5) * b.cell - start) / turn;
            s.behind_old = held(c);
            put(c, max(s.behind_old, depth));
        }
        // A turn forward of at most two cells from a phase within the sector: end − sector
        // where it passes the sector, without a division on the step's chain (the whole part
        // less the sector is exact; an end a rounding left just below zero stays there, and
        // reads the cells end.rem_euclid(sector) would).
        let wraps = end >= b.sector;
        s.phase = select(s.phase, s.phase - b.sector_whole, wraps);
        s.phase_fine = select(fine, fine - b.sector_rest, wraps);
        left = 0.0;
        depth_from = depth_new;
    }
    // The next cell ahead in the line read ahead: step into it, leaving this one to write back.
    var slow = whole;
    locate(b, s.phase + s.phase_fine);
    let ahead = wrapped(ahead_k) - line_base;
    if (!whole && !(ahead >= 0.0 && ahead < 4.0)) {
        let next_base = select(line_base + 4.0, 0.0, line_base + 4.0 == f32(RING_CELLS));
        let ahead_next = ahead + line_base - next_base;
        if (ahead_next >= 0.0 && ahead_next < 4.0 && next_read) {
            back = line;
            back_due = line_changed;
            line = next;
            line_base = next_base;
            line_changed = false;
            next_read = false;
        } else {
            slow = true;
        }
    }
    s.depth = depth_new;
    s.axial_speed = v_new;
    s.speed_fine = w_fine;
    *s_at = s;
    return Stepped(Forces(wob, torque, dn), slow, whole, left, depth_from, depth_new);
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
        floor(sector * PER_QUANTUM) * QUANTUM,
        sector - floor(sector * PER_QUANTUM) * QUANTUM,
        sector / f32(RING_CELLS),
        f32(RING_CELLS) / sector,
        radius * zeta * eps,
        0.5 * radius * radius * eps,
        radius * wear * sigma,
        0.5 * radius * mu * gamma,
        omega,
        drive,
        job.feed != 0u,
        job.dt_s,
        job.dt_s / job.mass_kg,
        job.dt_s / job.inertia_kg_m2,
        job.k_t,
        job.c_t,
        job.k_a,
        job.c_a,
    );
    let sb = STATE_LINES * i;
    ring_at = sb + RING_AT;
    let o = SUMMARY_WORDS * i;

    let head = states[sb];
    let tail = states[sb + 1u];
    let fine = states[sb + 2u];
    var s = State(head.x, tail.w, head.y, fine.y, head.z, fine.z, head.w, tail.x, tail.y, fine.x, tail.z);
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
        s = State(torque0 / job.k_t, 0.0, omega, kick, wob0 / job.k_a, 0.0, rate0, 0.0, 0.0, 0.0, 0.0);
        for (var l = 0u; l < RING_LINES; l = l + 1u) {
            let ahead = (f32(4u * l) + vec4<f32>(0.5, 1.5, 2.5, 3.5)) * b.cell;
            states[ring_at + l] = -dn0 * (1.0 - ahead / sector);
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
    carry_all(&s);
    hold_line(line_of(ahead_of(b, s.phase + s.phase_fine)));
    let steps = job.steps_per_sample;
    for (var period = job.first_period; period < job.end_period; period = period + 1u) {
        var k = 0u;
        loop {
            if (k >= steps) {
                break;
            }
            // Steps whose ring work needs no storage, until one of the subgroup's strings needs
            // it: a CPU driver runs every branch for all its lanes, so the storage passes below
            // run only after such a step, not after every one.
            var out: Stepped;
            locate(b, s.phase + s.phase_fine);
            loop {
                out = step(b, &s);
                k = k + 1u;
                if (any_lane(out.slow) || k >= steps || k % CARRY_STEPS == 0u) {
                    break;
                }
            }
            // Every CARRY_STEPS steps of the string's own (its results are its own, whichever
            // lanes leave the loop with it), here, not in the loop: a CPU driver runs a branch's
            // body at every step, masked.
            if (k % CARRY_STEPS == 0u) {
                carry_all(&s);
            }
            // The storage passes, for every lane that has one due (`transport` may change
            // any line, so the line after is read after it).
            sync_line_at();
            if (back_due) {
                // The line before the held one: a step into the line after needs it read
                // ahead, so no other step comes between.
                let back_at = select(line_at - 1u, RING_LINES - 1u, line_at == 0u);
                states[ring_at + back_at] = back + vec4<f32>(unrebased);
                back_due = false;
            }
            if (out.slow) {
                s = transport(b, s, out.turn, out.depth_from, out.depth_to, out.whole);
                s.depth = select(s.depth, 0.0, abs(s.depth) > REBASE_M);
                next_read = false;
            }
            if (!next_read) {
                next = states[ring_at + line_after(line_at)] - vec4<f32>(unrebased);
                next_read = true;
            }
            f = out.f;
        }
        carry_all(&s);
        // A NaN fails every comparison: diverged.
        let speed = s.speed + s.speed_fine;
        if (!(abs(speed) <= runaway && abs(s.axial_speed) < 1000.0 && abs(s.lag + s.lag_fine) < 1.0e30)) {
            diverged = true;
            break;
        }
        if (period >= job.settle_samples) {
            let stuck = abs(speed) < job.stuck_speed;
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
            backward = backward + select(0u, 1u, speed < 0.0);
            speed_min = min(speed_min, speed);
            speed_max = max(speed_max, speed);
            wob_min = min(wob_min, f.wob);
            wob_max = max(wob_max, f.wob);
            torque_min = min(torque_min, f.torque);
            torque_max = max(torque_max, f.torque);
            block = block + vec4<f32>(speed, s.axial_speed, f.wob, f.torque);
            samples = samples + 1u;
            if (samples % SUM_BLOCK == 0u) {
                total = total + block;
                block = vec4<f32>(0.0);
            }
        }
    }
    flush_line();
    // Storage takes the dispatch's rebases: the next slice and the host read heights from the
    // bit's datum.
    if (unrebased != 0.0) {
        for (var l = 0u; l < RING_LINES; l = l + 1u) {
            states[ring_at + l] = states[ring_at + l] - vec4<f32>(unrebased);
        }
    }
    let cut = bitcast<u32>(summaries[o + 23u]) != 0u || loops_were_cut(job.slice_steps >> 31u);
    let last_slice = job.end_period == job.settle_samples + job.record_samples;
    if (last_slice || diverged) {
        // The open block joins the total once, at the end (as the CPU's `finish`).
        total = total + block;
        block = vec4<f32>(0.0);
    }
    states[sb] = vec4<f32>(s.lag, s.speed, s.compression, s.axial_speed);
    states[sb + 1u] = vec4<f32>(s.depth, s.phase, s.behind_old, s.lag_fine);
    states[sb + 2u] = vec4<f32>(s.phase_fine, s.speed_fine, s.compression_fine, 0.0);
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

