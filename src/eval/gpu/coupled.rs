//! Runs `shaders/coupled.wgsl`: a batch of coupled axial-torsional strings (RGD), one per
//! invocation, each from its own bit, top-drive speed and axial drive, to its summary. The GPU
//! twin of [`crate::simulate::coupled::integrate_batch`].

use super::string_batch::Head;
use super::{GpuError, STORAGE_READ, STORAGE_WRITE, UNIFORM};
use crate::simulate::coupled::{Assembly, CoupledJob, CoupledState, CoupledSummary, STUCK_SPEED_RAD_S, Schedule};
use bytemuck::{Pod, Zeroable};

/// Words per string of the kernel's buffers. Keep in sync with shaders/coupled.wgsl.
const INPUT_WORDS: usize = 12;
/// The state: eleven words (the lag, the bit speed, the phase and the compression each in two
/// parts), one unused, then the ring; the kernel reads it in lines of four.
const STATE_WORDS: usize = 12 + crate::simulate::coupled::RING_CELLS;
const _: () = assert!(crate::simulate::coupled::RING_CELLS.is_multiple_of(4));
const SUMMARY_WORDS: usize = 24;

/// Strings held on the device at once: 1,152 B a string (inputs 48, state and ring 1,008,
/// summary 96), 302 MB for the chunk.
const STRINGS_PER_CHUNK: usize = 1 << 18;

/// Most steps one invocation integrates per dispatch at first: lavapipe stops an invocation's
/// loops after 65,535 iterations together, and a step runs one, and more where some lane of
/// its subgroup needs storage after it (a pass of the sample's loop and one or more of the
/// ring's: two per cell crossed backward, one per cell forward), and 60 at the dispatch's end
/// (the ring taken down by its rebases), so each dispatch integrates a slice of the sample
/// periods;
/// a chunk the driver still cuts short runs again in shorter slices ([`integrate_batch`]).
pub const STEPS_PER_SLICE: u32 = 6_000;

/// Strings per dispatch: each dispatch is its own submission, so that no single one runs long
/// enough for a driver's watchdog.
const STRINGS_PER_DISPATCH: usize = 1 << 14;

/// Host twin of `CoupledJob` in shaders/coupled.wgsl. Keep in sync.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct KernelJob {
    head: Head,
    feed: u32,
    first_period: u32,
    end_period: u32,
    start_given: u32,
    /// The most steps a dispatch integrates (the kernel reads it only to tell a cut
    /// invocation).
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

/// How the kernel's lanes leave the steps that stay in their held ring line (shaders/coupled.wgsl,
/// `any_lane`). The summaries are the same either way.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Lanes {
    /// A subgroup's lanes together, where the device has subgroup operations (else as `Each`):
    /// a CPU driver then runs the ring's storage passes once for the subgroup.
    Together,
    /// Each lane for itself, as on a device without subgroup operations.
    Each,
}

/// Integrates every string of `jobs` on the GPU from steady drilling or, where given, from
/// `start`: their summaries, in order. Every job must share one kind of axial drive (a weight
/// or a feed).
pub fn integrate_batch(
    assembly: &Assembly,
    schedule: &Schedule,
    jobs: &[CoupledJob],
    start: Option<&CoupledState>,
) -> Result<Vec<CoupledSummary>, GpuError> {
    integrate_batch_with(assembly, schedule, jobs, start, Lanes::Together)
}

/// [`integrate_batch`] with the kernel's `lanes`.
pub fn integrate_batch_with(
    assembly: &Assembly,
    schedule: &Schedule,
    jobs: &[CoupledJob],
    start: Option<&CoupledState>,
    lanes: Lanes,
) -> Result<Vec<CoupledSummary>, GpuError> {
    let feed = jobs.first().is_some_and(|j| j.axial.is_feed());
    assert!(
        jobs.iter().all(|j| j.axial.is_feed() == feed),
        "one batch, one kind of axial drive"
    );
    if schedule.steps_per_sample > STEPS_PER_SLICE {
        return Err(GpuError::TooLarge(format!(
            "{} steps per sample period: the GPU integrates at most {STEPS_PER_SLICE} per \
             dispatch; sample more often or take a longer step",
            schedule.steps_per_sample
        )));
    }
    let ctx = super::context()?;
    let bindings = [UNIFORM, STORAGE_READ, STORAGE_WRITE, STORAGE_WRITE];
    let kernel = if lanes == Lanes::Together && ctx.has_subgroups() {
        ctx.kernel("coupled", "main", super::coupled_source, &bindings, &[])?
    } else {
        let source = super::coupled_without_subgroups_source;
        ctx.kernel("coupled_without_subgroups", "main", source, &bindings, &[])?
    };
    let t = &assembly.torsion;
    let job = KernelJob {
        head: Head::sampling(
            schedule.steps_per_sample,
            schedule.settle_samples,
            schedule.record_samples,
        ),
        feed: u32::from(feed),
        dt_s: schedule.dt_s as f32,
        mass_kg: assembly.mass_kg as f32,
        inertia_kg_m2: t.inertia_kg_m2 as f32,
        k_t: t.stiffness_nm_per_rad() as f32,
        c_t: t.damping_nms_per_rad() as f32,
        k_a: assembly.axial_stiffness_n_per_m as f32,
        c_a: assembly.axial_damping_ns_per_m as f32,
        stuck_speed: STUCK_SPEED_RAD_S as f32,
        start_given: u32::from(start.is_some()),
        slice_steps: STEPS_PER_SLICE,
        ..KernelJob::zeroed()
    };
    let expected = schedule.record_samples;
    let mut out = Vec::with_capacity(jobs.len());
    for chunk in jobs.chunks(STRINGS_PER_CHUNK) {
        // Down to one sample period a slice.
        let shorten = |job: &mut KernelJob| {
            let longer = job.slice_steps / schedule.steps_per_sample > 1;
            job.slice_steps = (job.slice_steps / 4).max(schedule.steps_per_sample);
            longer
        };
        out.extend(super::string_batch::until_whole(
            job,
            "coupled string",
            expected,
            shorten,
            |job| {
                let (got, cut) = run_chunk(ctx, &kernel, job, chunk, start)?;
                let short_of = got
                    .iter()
                    .find(|s| !s.diverged && s.samples != expected)
                    .map(|s| s.samples);
                Ok((got, super::string_batch::Ended { cut, short_of }))
            },
        )?);
    }
    Ok(out)
}

impl super::string_batch::StringsUniform for KernelJob {
    fn head(&mut self) -> &mut Head {
        &mut self.head
    }

    fn rewind(&mut self) {
        (self.first_period, self.end_period) = (0, 0);
    }

    fn next_slice(&mut self) -> bool {
        let periods = self.head.settle_samples + self.head.record_samples;
        if self.end_period >= periods {
            return false;
        }
        let per_slice = (self.slice_steps / self.head.steps_per_sample).max(1);
        self.first_period = self.end_period;
        self.end_period = (self.first_period + per_slice).min(periods);
        true
    }
}

/// The chunk's summaries, and whether the driver cut any string's loops.
fn run_chunk(
    ctx: &super::GpuContext,
    kernel: &super::Kernel,
    job: KernelJob,
    jobs: &[CoupledJob],
    start: Option<&CoupledState>,
) -> Result<(Vec<CoupledSummary>, bool), GpuError> {
    let n = jobs.len();
    let mut inputs = vec![0.0f32; INPUT_WORDS * n];
    for (j, row) in jobs.iter().zip(inputs.chunks_mut(INPUT_WORDS)) {
        for (slot, v) in row.iter_mut().zip(j.bit.values()) {
            *slot = v as f32;
        }
        row[8] = j.omega_rad_s as f32;
        row[9] = j.axial.value() as f32;
        row[10] = j.kick_rad_s as f32;
    }
    // Without a start the kernel begins each string from steady drilling (`start_given` 0)
    // and reads no state.
    let states: Option<Vec<f32>> = start.map(|start| {
        // The lag, the phase, the bit speed and the compression as f32 and what that rounding
        // left out: the kernel carries each in two parts.
        let (lag, lag_fine) = f32_and_rest(start.lag_rad);
        let (phase, phase_fine) = f32_and_rest(start.phase_rad);
        let (speed, speed_fine) = f32_and_rest(start.speed_rad_s);
        let (compression, compression_fine) = f32_and_rest(start.compression_m);
        let mut one = vec![
            lag,
            speed,
            compression,
            start.axial_speed_m_s as f32,
            start.depth_m as f32,
            phase,
            start.behind_old_m as f32,
            lag_fine,
            phase_fine,
            speed_fine,
            compression_fine,
            0.0,
        ];
        one.extend(start.ring_m.iter().map(|&h| h as f32));
        debug_assert_eq!(one.len(), STATE_WORDS);
        std::iter::repeat_n(one, n).flatten().collect()
    });
    let chunk = super::string_batch::Chunk {
        label: "coupled",
        strings: n,
        inputs: &inputs,
        state_words: STATE_WORDS,
        states: states.as_deref(),
        summary_words: SUMMARY_WORDS,
        strings_per_dispatch: STRINGS_PER_DISPATCH,
        read_states: false,
    };
    let sums = super::string_batch::integrate_chunk(ctx, kernel, job, &chunk)?.summaries;
    let cut = sums.chunks(SUMMARY_WORDS).any(|o| o[23].to_bits() != 0);
    let summaries = sums
        .chunks(SUMMARY_WORDS)
        .map(|o| {
            let count = |k: usize| o[k].to_bits();
            let value = |k: usize| f64::from(o[k]);
            CoupledSummary {
                samples: count(0),
                stuck: count(1),
                stick_onsets: count(2),
                first_onset: count(3),
                last_onset: count(4),
                off_bottom: count(5),
                backward: count(6),
                speed_min_rad_s: value(7),
                speed_max_rad_s: value(8),
                speed_sum_rad_s: value(9),
                axial_speed_sum_m_s: value(10),
                wob_min_n: value(11),
                wob_max_n: value(12),
                wob_sum_n: value(13),
                torque_min_nm: value(14),
                torque_max_nm: value(15),
                torque_sum_nm: value(16),
                diverged: count(17) != 0,
            }
        })
        .collect();
    Ok((summaries, cut))
}

/// `x` as f32 and the f32 nearest what that rounding left out.
fn f32_and_rest(x: f64) -> (f32, f32) {
    let near = x as f32;
    (near, (x - f64::from(near)) as f32)
}
