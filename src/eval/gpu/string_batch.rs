//! The one way a batch of simulated strings is integrated on the GPU, whatever the string
//! model: a kernel bound to (job uniform, inputs, states, summaries), one invocation a string,
//! dispatched block by block and, where the kernel integrates its span in slices of time, slice
//! by slice; states and summaries read back.

use super::{GpuContext, GpuError, Kernel, WORKGROUP_SIZE};

/// The words every string kernel's job uniform opens with: the block of strings a dispatch
/// integrates (`first..first + count`, in rows of `row_width`) and the sampling of the span.
/// Keep in sync with the kernels' job structs.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub(super) struct Head {
    pub first: u32,
    pub count: u32,
    pub row_width: u32,
    pub steps_per_sample: u32,
    pub settle_samples: u32,
    pub record_samples: u32,
}

impl Head {
    /// A head sampling every `steps_per_sample` steps, `settle` periods unrecorded then `record`.
    pub fn sampling(steps_per_sample: u32, settle: u32, record: u32) -> Self {
        Self {
            first: 0,
            count: 0,
            row_width: 0,
            steps_per_sample,
            settle_samples: settle,
            record_samples: record,
        }
    }
}

/// The job uniform of a string kernel: which strings a dispatch integrates and, where the
/// kernel integrates its span in slices, which slice.
pub(super) trait StringsUniform: bytemuck::Pod {
    /// The words it opens with.
    fn head(&mut self) -> &mut Head;

    /// Moves the job to its next slice of time; false where its last slice has run. A kernel
    /// that integrates the whole span in one dispatch has one slice.
    fn next_slice(&mut self) -> bool {
        false
    }

    /// Moves the job back to before its first slice (then [`Self::next_slice`] gives it).
    fn rewind(&mut self) {}
}

/// How a chunk came back: whether its kernel told that the driver cut any string's loops, and
/// the samples of the first string short of its record without having diverged.
pub(super) struct Ended {
    pub cut: bool,
    pub short_of: Option<u32>,
}

/// A chunk run by `run` from `job`'s first slice, again in the shorter slices `shorten` makes
/// (false where it has none shorter) while the driver cuts it: a driver that ends a kernel's
/// loops early must not pass for a shorter record or a cut step, and slicing changes no result.
/// An error, naming `what` and the `expected` samples, where even the shortest slices are cut.
pub(super) fn until_whole<J: StringsUniform, T>(
    mut job: J,
    what: &str,
    expected: u32,
    mut shorten: impl FnMut(&mut J) -> bool,
    mut run: impl FnMut(J) -> Result<(T, Ended), GpuError>,
) -> Result<T, GpuError> {
    loop {
        job.rewind();
        job.next_slice();
        let (got, ended) = run(job)?;
        if !ended.cut && ended.short_of.is_none() {
            return Ok(got);
        }
        if !shorten(&mut job) {
            return Err(GpuError::Readback(match ended.short_of {
                Some(samples) => format!(
                    "a {what} came back with {samples} of its {expected} samples and no divergence: the driver ended its integration early"
                ),
                None => format!("the driver ended the {what}s' integration early even in their shortest slices"),
            }));
        }
    }
}

/// A chunk of `strings` strings laid out for a kernel: their `inputs` and starting `states`,
/// and the words of summary each writes.
pub(super) struct Chunk<'a> {
    pub label: &'a str,
    pub strings: usize,
    pub inputs: &'a [f32],
    /// Words of state per string, and the starting states where the kernel reads them (a
    /// kernel told to start from steady conditions gets a zeroed buffer, uploaded from nothing).
    pub state_words: usize,
    pub states: Option<&'a [f32]>,
    pub summary_words: usize,
    pub strings_per_dispatch: usize,
    /// Whether the final states come back (for a run that goes on from them).
    pub read_states: bool,
}

/// What came back: each string's final state (empty unless asked for) and summary words.
pub(super) struct ChunkOut {
    pub states: Vec<f32>,
    pub summaries: Vec<f32>,
}

/// Integrates `chunk` with `kernel` from `job` (whose first slice it is): uploads, dispatches
/// every block of every slice, reads back.
pub(super) fn integrate_chunk<J: StringsUniform>(
    ctx: &GpuContext,
    kernel: &Kernel,
    mut job: J,
    chunk: &Chunk<'_>,
) -> Result<ChunkOut, GpuError> {
    let strings = chunk.strings;
    let label = chunk.label;
    let copy = wgpu::BufferUsages::COPY_DST;
    let storage = wgpu::BufferUsages::STORAGE;
    let src = wgpu::BufferUsages::COPY_SRC;
    let state_bytes = 4 * (chunk.state_words * strings) as u64;
    let read_state_bytes = if chunk.read_states { state_bytes } else { 0 };
    let summary_bytes = 4 * (chunk.summary_words * strings) as u64;
    let job_buffer = ctx.buffer(
        &format!("{label} job"),
        size_of::<J>() as u64,
        wgpu::BufferUsages::UNIFORM | copy,
    )?;
    let input_buffer = ctx.buffer(
        &format!("{label} inputs"),
        4 * chunk.inputs.len() as u64,
        storage | copy,
    )?;
    let state_buffer = ctx.buffer(&format!("{label} states"), state_bytes, storage | copy | src)?;
    let summary_buffer = ctx.buffer(&format!("{label} summaries"), summary_bytes, storage | src)?;
    let staging = ctx.buffer(
        &format!("{label} staging"),
        read_state_bytes + summary_bytes,
        wgpu::BufferUsages::MAP_READ | copy,
    )?;
    ctx.queue
        .write_buffer(&input_buffer, 0, bytemuck::cast_slice(chunk.inputs));
    if let Some(states) = chunk.states {
        debug_assert_eq!(states.len(), chunk.state_words * strings);
        ctx.queue.write_buffer(&state_buffer, 0, bytemuck::cast_slice(states));
    }
    let group = ctx.bind_group(
        label,
        &kernel.layout,
        &[&job_buffer, &input_buffer, &state_buffer, &summary_buffer],
    )?;
    let mut encoder = ctx.encoder(label);
    loop {
        let mut next = job;
        let last_slice = !next.next_slice();
        for first in (0..strings).step_by(chunk.strings_per_dispatch) {
            let count = chunk.strings_per_dispatch.min(strings - first);
            let (x, y, row_width) = ctx.grid(count as u32, WORKGROUP_SIZE);
            let head = job.head();
            (head.first, head.count, head.row_width) = (first as u32, count as u32, row_width);
            let more = !last_slice || first + count < strings;
            ctx.dispatch_job(&mut encoder, label, kernel, &group, (&job_buffer, &job), (x, y), more)?;
        }
        if last_slice {
            break;
        }
        job = next;
    }
    if chunk.read_states {
        encoder.copy_buffer_to_buffer(&state_buffer, 0, &staging, 0, state_bytes);
    }
    encoder.copy_buffer_to_buffer(&summary_buffer, 0, &staging, read_state_bytes, summary_bytes);
    let raw = ctx.finish_and_read(encoder, &staging, read_state_bytes + summary_bytes)?;
    let (states, summaries) = raw.split_at(read_state_bytes as usize);
    Ok(ChunkOut {
        states: bytemuck::pod_collect_to_vec(states),
        summaries: bytemuck::pod_collect_to_vec(summaries),
    })
}
