//! Runs `shaders/slopes.wgsl` then `shaders/stability.wgsl`: per cell of an (Ω, W) grid, how
//! many of S parameter samples are unstable, and the growth rate of the first. The GPU twin of
//! `crate::stability::map::probability_grid` and `growth_rate_grid`.

use super::{GpuError, STORAGE_READ, STORAGE_WRITE, UNIFORM, WORKGROUP_SIZE};
use crate::laws::Law;
use crate::stability::map::{Criterion, Grid};
use crate::units::RAD_S_PER_RPM;
use bytemuck::{Pod, Zeroable};

/// Host twin of `SlopeJob` in shaders/slopes.wgsl. Keep in sync.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct SlopeJob {
    n_omega: u32,
    n_samples: u32,
    law: u32,
    row_width: u32,
}

/// Host twin of `StabilityJob` in shaders/stability.wgsl. Keep in sync.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct StabilityJob {
    n_omega: u32,
    n_wob: u32,
    sample_start: u32,
    sample_end: u32,
    n_samples: u32,
    row_width: u32,
    mode: u32,
    accumulate: u32,
    inertia_kg_m2: f32,
    two_omega_n_xi: f32,
    omega_n_sq: f32,
    critical_nms: f32,
    w_ref_n: f32,
    _pad: [f32; 3],
}

/// Samples per dispatch: lavapipe ends loops after 65,535 iterations.
const SAMPLES_PER_DISPATCH: usize = 32_768;

/// The slopes pass: its kernel (for `law`) and bind group over `buffers` (job, speeds,
/// samples, slopes), its job written, and its grid, for `n_omega` speeds × `n_samples`.
fn slope_pass(
    ctx: &super::GpuContext,
    law: Law,
    buffers: [&wgpu::Buffer; 4],
    (n_omega, n_samples): (usize, usize),
) -> Result<(super::Kernel, wgpu::BindGroup, (u32, u32)), GpuError> {
    let slope_bindings = [UNIFORM, STORAGE_READ, STORAGE_READ, STORAGE_WRITE];
    let file_laws = crate::laws::file::among([law]);
    let slope_kernel = ctx.kernel(
        &super::file_laws::label("slopes", &file_laws),
        "main",
        || super::slopes_source_for(&file_laws),
        &slope_bindings,
        &[],
    )?;
    let slope_group = ctx.bind_group("slopes", &slope_kernel.layout, &buffers)?;
    let (sx, sy, slope_row) = ctx.grid((n_omega * n_samples) as u32, WORKGROUP_SIZE);
    let sjob = SlopeJob {
        n_omega: n_omega as u32,
        n_samples: n_samples as u32,
        law: law.index() as u32,
        row_width: slope_row,
    };
    ctx.queue.write_buffer(buffers[0], 0, bytemuck::bytes_of(&sjob));
    Ok((slope_kernel, slope_group, (sx, sy)))
}

/// The samples' parameters in f32, six words per sample (unused ones 0).
fn flat_samples(samples: &[Vec<f64>]) -> Vec<f32> {
    let mut flat = vec![0.0f32; 6 * samples.len()];
    for (s, p) in samples.iter().enumerate() {
        for (j, &v) in p.iter().enumerate() {
            flat[6 * s + j] = v as f32;
        }
    }
    flat
}

impl StabilityJob {
    /// The count kernel's job over the samples `slice` (first, end) of a grid of `n_omega` ×
    /// `n_wob` cells and `n_samples` samples, judged by `criterion`; a slice after the first
    /// adds to the counts.
    fn new(
        (start, end): (usize, usize),
        (n_omega, n_wob, n_samples): (usize, usize, usize),
        row_width: u32,
        criterion: Criterion,
        w_ref_n: f64,
    ) -> Self {
        let (mode, critical, inertia, two_omega_n_xi, omega_n_sq) = match criterion {
            Criterion::Lumped(l) => (
                0,
                0.0,
                l.inertia_kg_m2,
                2.0 * l.omega_n_rad_s * l.damping_ratio,
                l.omega_n_rad_s * l.omega_n_rad_s,
            ),
            Criterion::Critical(c) => (1, c, 1.0, 0.0, 0.0),
        };
        Self {
            n_omega: n_omega as u32,
            n_wob: n_wob as u32,
            sample_start: start as u32,
            sample_end: end as u32,
            n_samples: n_samples as u32,
            row_width,
            mode,
            accumulate: u32::from(start > 0),
            inertia_kg_m2: inertia as f32,
            two_omega_n_xi: two_omega_n_xi as f32,
            omega_n_sq: omega_n_sq as f32,
            critical_nms: critical as f32,
            w_ref_n: w_ref_n as f32,
            _pad: [0.0; 3],
        }
    }
}

/// Unstable counts (row-major over Ω, W) and the growth rates of the first sample (1-DOF
/// criterion only; zeros otherwise). Speeds rpm, weights kN, samples SI. Two kernels: the
/// slopes dT/dw per (speed, sample), then the count per cell.
pub fn stability_grid(grid: &Grid) -> Result<(Vec<u32>, Vec<f32>), GpuError> {
    let Grid {
        law,
        samples,
        omega_rpm,
        wob_kn,
        criterion,
        w_ref_n,
    } = *grid;
    let ctx = super::context()?;
    let cells = omega_rpm.len() * wob_kn.len();
    if samples.is_empty() || cells == 0 {
        return Ok((vec![0; cells], vec![0.0; cells]));
    }
    let omega: Vec<f32> = omega_rpm.iter().map(|&r| (r * RAD_S_PER_RPM) as f32).collect();
    let wob: Vec<f32> = wob_kn.iter().map(|&k| (k * 1000.0) as f32).collect();
    let flat = flat_samples(samples);
    let slope_count = omega.len() * samples.len();
    let slope_bytes = 4 * slope_count as u64;
    if slope_bytes > ctx.limits.max_storage_buffer_binding_size {
        return Err(GpuError::TooLarge(format!(
            "{} speeds × {} samples of slopes need {slope_bytes} bytes, the adapter binds at most {}",
            omega.len(),
            samples.len(),
            ctx.limits.max_storage_buffer_binding_size
        )));
    }
    let copy = wgpu::BufferUsages::COPY_DST;
    let storage = wgpu::BufferUsages::STORAGE;
    let uniform = wgpu::BufferUsages::UNIFORM | copy;
    let slope_job = ctx.buffer("slope job", size_of::<SlopeJob>() as u64, uniform)?;
    let job_buffer = ctx.buffer("stability job", size_of::<StabilityJob>() as u64, uniform)?;
    let omega_buffer = ctx.buffer("omega", 4 * omega.len() as u64, storage | copy)?;
    let wob_buffer = ctx.buffer("wob", 4 * wob.len() as u64, storage | copy)?;
    let sample_buffer = ctx.buffer("samples", 4 * flat.len() as u64, storage | copy)?;
    let slopes = ctx.buffer("slopes", slope_bytes, storage)?;
    let bytes = 4 * cells as u64;
    let counts = ctx.buffer("unstable counts", bytes, storage | wgpu::BufferUsages::COPY_SRC)?;
    let growth = ctx.buffer("growth rates", bytes, storage | wgpu::BufferUsages::COPY_SRC)?;
    let staging = ctx.buffer("stability staging", 2 * bytes, wgpu::BufferUsages::MAP_READ | copy)?;
    ctx.queue.write_buffer(&omega_buffer, 0, bytemuck::cast_slice(&omega));
    ctx.queue.write_buffer(&wob_buffer, 0, bytemuck::cast_slice(&wob));
    ctx.queue.write_buffer(&sample_buffer, 0, bytemuck::cast_slice(&flat));

    let (slope_kernel, slope_group, (sx, sy)) = slope_pass(
        ctx,
        law,
        [&slope_job, &omega_buffer, &sample_buffer, &slopes],
        (omega.len(), samples.len()),
    )?;

    let bindings = [UNIFORM, STORAGE_READ, STORAGE_READ, STORAGE_WRITE, STORAGE_WRITE];
    let kernel = ctx.kernel("stability", "main", super::stability_source, &bindings, &[])?;
    let bind_group = ctx.bind_group(
        "stability",
        &kernel.layout,
        &[&job_buffer, &wob_buffer, &slopes, &counts, &growth],
    )?;
    let (x, y, row_width) = ctx.grid(cells as u32, WORKGROUP_SIZE);
    let mut encoder = ctx.encoder("stability");
    super::encode_dispatch(&mut encoder, "slopes", &slope_kernel.pipeline, &slope_group, (sx, sy));
    for s0 in (0..samples.len()).step_by(SAMPLES_PER_DISPATCH) {
        let slice = (s0, (s0 + SAMPLES_PER_DISPATCH).min(samples.len()));
        let job = StabilityJob::new(
            slice,
            (omega.len(), wob.len(), samples.len()),
            row_width,
            criterion,
            w_ref_n,
        );
        let more = slice.1 < samples.len();
        ctx.dispatch_job(
            &mut encoder,
            "stability",
            &kernel,
            &bind_group,
            (&job_buffer, &job),
            (x, y),
            more,
        )?;
    }
    encoder.copy_buffer_to_buffer(&counts, 0, &staging, 0, bytes);
    encoder.copy_buffer_to_buffer(&growth, 0, &staging, bytes, bytes);
    let raw = ctx.finish_and_read(encoder, &staging, 2 * bytes)?;
    let counts: Vec<u32> = bytemuck::cast_slice(&raw[..bytes as usize]).to_vec();
    let growth: Vec<f32> = bytemuck::cast_slice(&raw[bytes as usize..]).to_vec();
    Ok((counts, growth))
}
