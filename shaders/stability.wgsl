// Stability over a grid of operating points (top-drive speed Ω × weight on bit W) for S
// parameter samples of one law: per cell, how many samples make steady rotation unstable, and
// for a single sample the growth rate (largest real part of the 1-DOF Jacobian's eigenvalues).
// The twin of `probability_grid` / `growth_rate_grid` in src/stability/map.rs.
// Needs shared/laws.wgsl. f32 throughout; SI units (rad/s, N, N·m·s/rad).

// Keep in sync with `StabilityJob` in src/eval/gpu/stability.rs.
struct StabilityJob {
    n_omega: u32,
    n_wob: u32,
    // Samples sample_start..sample_end are counted by this dispatch (lavapipe ends loops after
    // 65,535 iterations, so the host slices S).
    sample_start: u32,
    sample_end: u32,
    // Law id (0 = m1 .. 3 = m4) and cells per row of the (possibly 2-D) grid.
    law: u32,
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
@group(0) @binding(1) var<storage, read> omega_rad_s: array<f32>;
@group(0) @binding(2) var<storage, read> wob_n: array<f32>;
// Six parameters (SI, N·m) per sample.
@group(0) @binding(3) var<storage, read> samples: array<f32>;
@group(0) @binding(4) var<storage, read_write> unstable_count: array<u32>;
// Growth rate (1/s) of sample 0, for the single-sample map.
@group(0) @binding(5) var<storage, read_write> growth_rate: array<f32>;

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
    let omega = omega_rad_s[cell / job.n_wob];
    let r = wob_n[cell % job.n_wob] / job.w_ref_n;
    var count = 0u;
    for (var s = job.sample_start; s < job.sample_end; s = s + 1u) {
        let b = 6u * s;
        let p = array<f32, 6>(samples[b], samples[b + 1u], samples[b + 2u], samples[b + 3u], samples[b + 4u], samples[b + 5u]);
        let bit_damping = r * dtorque_dw(job.law, p, omega);
        var unstable: bool;
        if (job.mode == 0u) {
            let g = lumped_growth(bit_damping);
            unstable = g >= 0.0;
            if (s == 0u) {
                growth_rate[cell] = g;
            }
        } else {
            unstable = bit_damping <= job.critical_nms;
        }
        count = count + select(0u, 1u, unstable);
    }
    if (job.accumulate == 1u) {
        unstable_count[cell] = unstable_count[cell] + count;
    } else {
        unstable_count[cell] = count;
    }
}
