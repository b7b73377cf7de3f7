//! Runs `shaders/kernel_sums.wgsl`: the Gaussian kernel sums of the SMC importance weights,
//! S_i = Σ_j w_j exp(−|y_i − x_j|²/2), in f32 with blocked accumulation. The CPU twin is
//! [`crate::eval::cpu::kernel_sums`] (f64); tests/it/gpu.rs measures their agreement.

use super::{GpuContext, GpuError, STORAGE_READ, STORAGE_WRITE, UNIFORM, WORKGROUP_SIZE, buffer_entry};
use crate::eval::KernelSums;
use crate::laws::MAX_PARAMS;
use bytemuck::{Pod, Zeroable};
use std::sync::OnceLock;

/// Sources summed per dispatch. lavapipe ends any loop after 65,535 iterations per invocation,
/// and counts the iterations of a nested loop over the whole invocation (65,535 sources per
/// dispatch lost 3 % of the sum, 60,000 none): half of that keeps a margin.
const SOURCES_PER_DISPATCH: usize = 32_768;

/// Host twin of `SumsJob` in shaders/kernel_sums.wgsl. Keep in sync.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct SumsJob {
    count: u32,
    source_start: u32,
    source_end: u32,
    row_width: u32,
    accumulate: u32,
    _pad: [u32; 3],
}

/// The pipeline, built once per process.
static PIPELINE: OnceLock<Result<(wgpu::ComputePipeline, wgpu::BindGroupLayout), GpuError>> = OnceLock::new();

/// Two vec4 per point: coordinates 0-3, then 4-5, `extra` and 0.
fn pack(points: &[[f64; MAX_PARAMS]], extra: impl Fn(usize) -> f64) -> Vec<f32> {
    points
        .iter()
        .enumerate()
        .flat_map(|(i, p)| {
            let mut v = [0.0f32; 8];
            for (dst, &src) in v.iter_mut().zip(p) {
                *dst = src as f32;
            }
            v[6] = extra(i) as f32;
            v
        })
        .collect()
}

/// The kernel sums of `sums` on the GPU of `ctx`, into `out` (one per target).
pub fn kernel_sums(ctx: &GpuContext, sums: &KernelSums, out: &mut [f64]) -> Result<(), GpuError> {
    assert_eq!(sums.targets.len(), out.len(), "one sum per target");
    assert_eq!(sums.sources.len(), sums.weights.len(), "one weight per source");
    if out.is_empty() {
        return Ok(());
    }
    if sums.sources.is_empty() {
        out.fill(0.0);
        return Ok(());
    }
    let (pipeline, layout) = PIPELINE
        .get_or_init(|| {
            let entries = [
                buffer_entry(0, UNIFORM),
                buffer_entry(1, STORAGE_READ),
                buffer_entry(2, STORAGE_READ),
                buffer_entry(3, STORAGE_WRITE),
            ];
            ctx.pipeline("kernel_sums", &super::kernel_sums_source(), &entries, &[])
        })
        .as_ref()
        .map_err(Clone::clone)?;
    let sources = pack(sums.sources, |j| sums.weights[j]);
    let copy = wgpu::BufferUsages::COPY_DST;
    let source_buffer = ctx.buffer(
        "kernel sources",
        4 * sources.len() as u64,
        wgpu::BufferUsages::STORAGE | copy,
    )?;
    ctx.queue
        .write_buffer(&source_buffer, 0, bytemuck::cast_slice(&sources));
    // Targets per dispatch: within the binding limit (32 bytes each) and 2²² at most.
    let chunk = (ctx.limits.max_storage_buffer_binding_size / 32).clamp(1, 1 << 22) as usize;
    let chunk = chunk.min(out.len());
    let target_buffer = ctx.buffer("kernel targets", 32 * chunk as u64, wgpu::BufferUsages::STORAGE | copy)?;
    let sum_bytes = 4 * chunk as u64;
    let sum_buffer = ctx.buffer(
        "kernel sums",
        sum_bytes,
        wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
    )?;
    let staging = ctx.buffer("kernel sums staging", sum_bytes, wgpu::BufferUsages::MAP_READ | copy)?;
    let job_buffer = ctx.buffer(
        "kernel job",
        size_of::<SumsJob>() as u64,
        wgpu::BufferUsages::UNIFORM | copy,
    )?;
    let bind_group = ctx.bind_group(
        "kernel_sums",
        layout,
        &[&job_buffer, &target_buffer, &source_buffer, &sum_buffer],
    )?;
    let n_sources = sums.sources.len();
    for (targets, dst) in sums.targets.chunks(chunk).zip(out.chunks_mut(chunk)) {
        ctx.queue
            .write_buffer(&target_buffer, 0, bytemuck::cast_slice(&pack(targets, |_| 0.0)));
        let count = targets.len() as u32;
        let (x, y, row_width) = ctx.grid(count, WORKGROUP_SIZE);
        let mut encoder = ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("kernel_sums"),
        });
        for s0 in (0..n_sources).step_by(SOURCES_PER_DISPATCH) {
            let job = SumsJob {
                count,
                source_start: s0 as u32,
                source_end: (s0 + SOURCES_PER_DISPATCH).min(n_sources) as u32,
                row_width,
                accumulate: u32::from(s0 > 0),
                _pad: [0; 3],
            };
            ctx.queue.write_buffer(&job_buffer, 0, bytemuck::bytes_of(&job));
            super::encode_dispatch(&mut encoder, "kernel_sums", pipeline, &bind_group, (x, y));
            if s0 + SOURCES_PER_DISPATCH < n_sources {
                // The next slice rewrites the job uniform: submit this one first.
                ctx.scoped(|| ctx.queue.submit([encoder.finish()]))?;
                encoder = ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
                    label: Some("kernel_sums"),
                });
            }
        }
        let bytes = 4 * u64::from(count);
        encoder.copy_buffer_to_buffer(&sum_buffer, 0, &staging, 0, bytes);
        let raw = ctx.finish_and_read(encoder, &staging, bytes)?;
        let values: &[f32] = bytemuck::cast_slice(&raw);
        for (d, &v) in dst.iter_mut().zip(values) {
            *d = f64::from(v);
        }
    }
    Ok(())
}
