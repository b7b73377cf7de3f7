// dT/dw of every parameter sample at every top-drive speed: slope[i * S + s] for speed i and
// sample s (N·m·s/rad, r = 1). The first stage of a stability grid: the slopes do not depend on
// the weight on bit, so `stability.wgsl` reads them instead of re-evaluating the law per cell.
// Needs shared/laws.wgsl.

// Keep in sync with `SlopeJob` in src/eval/gpu/stability.rs.
struct SlopeJob {
    n_omega: u32,
    n_samples: u32,
    law: u32,
    row_width: u32,
}

@group(0) @binding(0) var<uniform> job: SlopeJob;
@group(0) @binding(1) var<storage, read> omega_rad_s: array<f32>;
// Six parameters (SI, N·m) per sample.
@group(0) @binding(2) var<storage, read> samples: array<f32>;
@group(0) @binding(3) var<storage, read_write> slope: array<f32>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let k = gid.x + gid.y * job.row_width;
    if (k >= job.n_omega * job.n_samples) {
        return;
    }
    let s = k % job.n_samples;
    let b = 6u * s;
    let p = array<f32, 6>(samples[b], samples[b + 1u], samples[b + 2u], samples[b + 3u], samples[b + 4u], samples[b + 5u]);
    slope[k] = dtorque_dw(job.law, p, omega_rad_s[k / job.n_samples]);
}
