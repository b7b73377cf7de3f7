//! Runs `shaders/candidates.wgsl`: the raw Philox blocks and the candidates the GPU generates,
//! for bit-for-bit comparison with the CPU (tests, `bitrock parity`); and
//! `shaders/test_uniform_between.wgsl`, the WGSL candidate transform on arbitrary inputs (tests).

use super::{GpuError, GpuPrior, Job, STORAGE_READ, STORAGE_WRITE, UNIFORM, WORKGROUP_SIZE};
use crate::prior::Prior;

/// What the GPU made of one candidate index.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct GpuCandidate {
    /// Philox blocks 0 and 1 of the candidate's counter.
    pub philox: [u32; 8],
    /// Prior slot (law) chosen.
    pub slot: u32,
    /// Parameters as f32 bits (unused ones 0).
    pub param_bits: [u32; 6],
}

/// Generates candidates `start .. start + count` of `population` on the GPU.
pub fn generate(
    prior: &Prior,
    seed: u64,
    population: u32,
    start: u64,
    count: u32,
) -> Result<Vec<GpuCandidate>, GpuError> {
    let ctx = super::context()?;
    let usage = wgpu::BufferUsages::COPY_DST;
    let prior_buffer = ctx.buffer(
        "prior",
        size_of::<GpuPrior>() as u64,
        wgpu::BufferUsages::UNIFORM | usage,
    )?;
    let job_buffer = ctx.buffer("job", size_of::<Job>() as u64, wgpu::BufferUsages::UNIFORM | usage)?;
    let bytes = 64 * u64::from(count);
    let out = ctx.buffer(
        "candidates",
        bytes,
        wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
    )?;
    let staging = ctx.buffer("candidates staging", bytes, wgpu::BufferUsages::MAP_READ | usage)?;
    let (x, y, row_width) = ctx.grid(count, WORKGROUP_SIZE);
    ctx.queue
        .write_buffer(&prior_buffer, 0, bytemuck::bytes_of(&GpuPrior::new(prior, seed)));
    ctx.queue.write_buffer(
        &job_buffer,
        0,
        bytemuck::bytes_of(&Job::new(population, start, count, row_width)),
    );
    let bindings = [UNIFORM, UNIFORM, STORAGE_WRITE];
    let kernel = ctx.kernel("candidates", "main", super::candidates_source, &bindings, &[])?;
    let bind_group = ctx.bind_group("candidates", &kernel.layout, &[&prior_buffer, &job_buffer, &out])?;
    let mut encoder = ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
        label: Some("candidates"),
    });
    super::encode_dispatch(&mut encoder, "candidates", &kernel.pipeline, &bind_group, (x, y));
    encoder.copy_buffer_to_buffer(&out, 0, &staging, 0, bytes);
    let raw = ctx.finish_and_read(encoder, &staging, bytes)?;
    let words: &[u32] = bytemuck::cast_slice(&raw);
    Ok(words
        .chunks_exact(16)
        .map(|w| GpuCandidate {
            philox: w[..8].try_into().expect("8 words"),
            slot: w[8],
            param_bits: w[9..15].try_into().expect("6 words"),
        })
        .collect())
}

/// `uniform_between` of shaders/shared/philox.wgsl on each (lo, hi, word), computed by
/// `shaders/test_uniform_between.wgsl`: the WGSL twin's results, for comparing its bits with
/// [`crate::rng::uniform_between`] on inputs no prior box produces.
pub fn uniform_between(triples: &[(f32, f32, u32)]) -> Result<Vec<f32>, GpuError> {
    let ctx = super::context()?;
    let bindings = [STORAGE_READ, STORAGE_WRITE];
    let kernel = ctx.kernel(
        "test_uniform_between",
        "main",
        super::test_uniform_between_source,
        &bindings,
        &[],
    )?;
    // Chunks of 2²⁰ triples (16 MiB) stay inside every adapter's storage-binding limit.
    let mut results = Vec::with_capacity(triples.len());
    for chunk in triples.chunks(1 << 20) {
        let packed: Vec<[u32; 4]> = chunk
            .iter()
            .map(|&(lo, hi, word)| [lo.to_bits(), hi.to_bits(), word, 0])
            .collect();
        let raw = ctx.map_elements(
            "test_uniform_between",
            &kernel,
            bytemuck::cast_slice(&packed),
            chunk.len() as u32,
            4 * chunk.len() as u64,
        )?;
        results.extend(bytemuck::cast_slice::<u8, u32>(&raw).iter().map(|&b| f32::from_bits(b)));
    }
    Ok(results)
}
