// Stability over a grid of operating points (top-drive speed Ω × weight on bit W) for S
// parameter samples of one law: per cell, how many samples make steady rotation unstable, and
// for the first sample the growth rate (largest real part of the 1-DOF Jacobian's eigenvalues).
// The twin of `probability_grid` / `growth_rate_grid` in src/stability/map.rs. Reads the slopes
// dT/dw(Ω_i) of `slopes.wgsl`; the bit damping of sample s at cell (i, j) is c_b = r_j·slope.
// f32 throughout; SI units (rad/s, N, N·m·s/rad).
//
// The 1-DOF Jacobian [[0, 1], [-ω_n², -2ω_nξ - c_b/I]] has determinant ω_n² > 0, so both
// eigenvalues have negative real parts exactly when its trace is negative (Routh-Hurwitz): the
// closed-form criterion is trace ≥ 0 ⇔ unstable.

// Keep in sync with `StabilityJob` in src/eval/gpu/stability.rs.
struct StabilityJob {
    n_omega: u32,
    n_wob: u32,
    // Samples sample_start..sample_end are counted by this dispatch (lavapipe ends loops after
    // 65,535 iterations, so the host slices S).
    sample_start: u32,
    sample_end: u32,
    n_samples: u32,
    row_width: u32,
    // 0: the 1-DOF closed form; 1: unstable when c_b <= critical_nms (finite-element string).
    mode: u32,
    // 1: add to the counts of earlier dispatches.
    accumulate: u32,
    inertia_kg_m2: f32,
    // 2 ω_n ξ (1/s) and ω_n² (1/s²) of the 1-DOF model.
    two_omega_n_xi: f32,
    omega_n_sq: f32,
    critical_nms: f32,
    w_ref_n: f32,
    _pad0: f32,
    _pad1: f32,
    _pad2: f32,
}

@group(0) @binding(0) var<uniform> job: StabilityJob;
@group(0) @binding(1) var<storage, read> wob_n: array<f32>;
@group(0) @binding(2) var<storage, read> slope: array<f32>;
@group(0) @binding(3) var<storage, read_write> unstable_count: array<u32>;
// Growth rate (1/s) of sample 0, for the single-sample map.
@group(0) @binding(4) var<storage, read_write> growth_rate: array<f32>;

// Largest real part of the eigenvalues of [[0, 1], [-ω_n², -2ω_nξ - c_b / I]].
fn lumped_growth(bit_damping: f32) -> f32 {
    let half_trace = -0.5 * (job.two_omega_n_xi + bit_damping / job.inertia_kg_m2);
    let disc = half_trace * half_trace - job.omega_n_sq;
    return half_trace + select(0.0, sqrt(max(disc, 0.0)), disc > 0.0);
}

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let cell = gid.x + gid.y * job.row_width;
    if (cell >= job.n_omega * job.n_wob) {
        return;
    }
    let row = (cell / job.n_wob) * job.n_samples;
    let r = wob_n[cell % job.n_wob] / job.w_ref_n;
    // Unstable when r·slope crosses a threshold: the trace of the 1-DOF Jacobian reaches 0 at
    // c_b = -2ω_nξ I, the finite-element string at c_b*.
    var threshold = job.critical_nms;
    if (job.mode == 0u) {
        threshold = -job.two_omega_n_xi * job.inertia_kg_m2;
        if (job.accumulate == 0u) {
            growth_rate[cell] = lumped_growth(r * slope[row]);
        }
    }
    var count = 0u;
    for (var s = job.sample_start; s < job.sample_end; s = s + 1u) {
        count = count + select(0u, 1u, r * slope[row + s] <= threshold);
    }
    if (job.accumulate == 1u) {
        unstable_count[cell] = unstable_count[cell] + count;
    } else {
        unstable_count[cell] = count;
    }
}
