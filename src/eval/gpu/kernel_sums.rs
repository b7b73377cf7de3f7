//! Runs `shaders/kernel_sums.wgsl`: the Gaussian kernel sums of the SMC importance weights,
//! S_i = Σ_j w_j exp(−|y_i − x_j|²/2), in f32 with blocked accumulation. The CPU twin is
//! [`crate::eval::cpu::kernel_sums`] (f64); tests/it/gpu.rs measures their agreement.

use super::{GpuContext, GpuError, STORAGE_READ, STORAGE_WRITE, UNIFORM, WORKGROUP_SIZE};
use crate::eval::KernelSums;
use crate::laws::MAX_PARAMS;
use crate::prior::MAX_DIMS;
use bytemuck::{Pod, Zeroable};
use std::sync::Mutex;

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

/// Two vec4 per point: coordinates 0-3, then 4-5 and the two numbers of `extra` (a source's
/// weight and rank-one coefficient; zeros for a target). The kernel takes a law's parameters
/// only: a run that infers the string with the law weighs its particles on the CPU.
fn pack(points: &[[f64; MAX_DIMS]], extra: impl Fn(usize) -> [f64; 2]) -> Vec<f32> {
    points
        .iter()
        .enumerate()
        .flat_map(|(i, p)| {
            let mut v = [0.0f32; 8];
            for (dst, &src) in v.iter_mut().zip(&p[..MAX_PARAMS]) {
                *dst = src as f32;
            }
            let [a, b] = extra(i);
            v[6] = a as f32;
            v[7] = b as f32;
            v
        })
        .collect()
}

/// Buffers sized for the largest call so far, reused by later calls (an SMC run computes the
/// kernel sums of every population with about the same N).
#[derive(Default)]
pub struct Scratch(Mutex<Option<Buffers>>);

struct Buffers {
    /// Sources and targets (points) each buffer holds.
    sources: usize,
    targets: usize,
    source: wgpu::Buffer,
    target: wgpu::Buffer,
    sum: wgpu::Buffer,
    staging: wgpu::Buffer,
    job: wgpu::Buffer,
    bind_group: wgpu::BindGroup,
}

/// The kernel's buffers: its job, the particles, the targets, the sums it writes.
const BINDINGS: [wgpu::BufferBindingType; 4] = [UNIFORM, STORAGE_READ, STORAGE_READ, STORAGE_WRITE];

impl Buffers {
    fn new(ctx: &GpuContext, layout: &wgpu::BindGroupLayout, sources: usize, targets: usize) -> Result<Self, GpuError> {
        let copy = wgpu::BufferUsages::COPY_DST;
        let source = ctx.buffer(
            "kernel sources",
            32 * sources as u64,
            wgpu::BufferUsages::STORAGE | copy,
        )?;
        let target = ctx.buffer(
            "kernel targets",
            32 * targets as u64,
            wgpu::BufferUsages::STORAGE | copy,
        )?;
        let sum_bytes = 4 * targets as u64;
        let sum = ctx.buffer(
            "kernel sums",
            sum_bytes,
            wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        )?;
        let staging = ctx.buffer("kernel sums staging", sum_bytes, wgpu::BufferUsages::MAP_READ | copy)?;
        let job = ctx.buffer(
            "kernel job",
            size_of::<SumsJob>() as u64,
            wgpu::BufferUsages::UNIFORM | copy,
        )?;
        let bind_group = ctx.bind_group("kernel_sums", layout, &[&job, &target, &source, &sum])?;
        Ok(Self {
            sources,
            targets,
            source,
            target,
            sum,
            staging,
            job,
            bind_group,
        })
    }
}

impl Scratch {
    /// The kernel sums of `sums` on the GPU of `ctx`, into `out` (one per target).
    pub fn run(&self, ctx: &GpuContext, sums: &KernelSums, out: &mut [f64]) -> Result<(), GpuError> {
        assert_eq!(sums.targets.len(), out.len(), "one sum per target");
        assert_eq!(sums.sources.len(), sums.weights.len(), "one weight per source");
        if out.is_empty() {
            return Ok(());
        }
        if sums.sources.is_empty() {
            out.fill(0.0);
            return Ok(());
        }
        if !sums.law_only() {
            return Err(GpuError::Validation(format!(
                "the kernel sums take at most {MAX_PARAMS} coordinates; a run with more weighs on the CPU"
            )));
        }
        let kernel = ctx.kernel("kernel_sums", "main", super::kernel_sums_source, &BINDINGS, &[])?;
        // Targets per dispatch: within the binding limit (32 bytes each) and 2²² at most.
        let chunk = (ctx.limits.max_storage_buffer_binding_size / 32).clamp(1, 1 << 22) as usize;
        let chunk = chunk.min(out.len());
        let n_sources = sums.sources.len();
        let mut guard = self.0.lock().expect("kernel-sum buffers");
        if guard
            .as_ref()
            .is_none_or(|b| b.sources < n_sources || b.targets < chunk)
        {
            let (old_sources, old_targets) = guard.as_ref().map_or((0, 0), |b| (b.sources, b.targets));
            *guard = Some(Buffers::new(
                ctx,
                &kernel.layout,
                n_sources.max(old_sources),
                chunk.max(old_targets),
            )?);
        }
        let buffers = guard.as_ref().expect("sized above");
        let sources = pack(sums.sources, |j| [sums.weights[j], sums.rank_one.map_or(0.0, |c| c[j])]);
        ctx.queue
            .write_buffer(&buffers.source, 0, bytemuck::cast_slice(&sources));
        for (targets, dst) in sums.targets.chunks(chunk).zip(out.chunks_mut(chunk)) {
            ctx.queue
                .write_buffer(&buffers.target, 0, bytemuck::cast_slice(&pack(targets, |_| [0.0, 0.0])));
            let count = targets.len() as u32;
            let (x, y, row_width) = ctx.grid(count, WORKGROUP_SIZE);
            let mut encoder = ctx.encoder("kernel_sums");
            for s0 in (0..n_sources).step_by(SOURCES_PER_DISPATCH) {
                let source_end = (s0 + SOURCES_PER_DISPATCH).min(n_sources);
                let job = SumsJob {
                    count,
                    source_start: s0 as u32,
                    source_end: source_end as u32,
                    row_width,
                    accumulate: u32::from(s0 > 0),
                    _pad: [0; 3],
                };
                ctx.dispatch_job(
                    &mut encoder,
                    "kernel_sums",
                    &kernel,
                    &buffers.bind_group,
                    (&buffers.job, &job),
                    (x, y),
                    source_end < n_sources,
                )?;
            }
            let bytes = 4 * u64::from(count);
            encoder.copy_buffer_to_buffer(&buffers.sum, 0, &buffers.staging, 0, bytes);
            let raw = ctx.finish_and_read(encoder, &buffers.staging, bytes)?;
            let values: &[f32] = bytemuck::cast_slice(&raw);
            for (d, &v) in dst.iter_mut().zip(values) {
                *d = f64::from(v);
            }
        }
        Ok(())
    }
}
