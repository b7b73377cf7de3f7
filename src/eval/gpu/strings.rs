//! Runs `shaders/strings.wgsl`: a batch of drill strings, one per invocation, each from its own
//! law, parameters, operating point and start, to its summary and final state. The GPU twin of
//! [`crate::simulate::strings::integrate_batch`].

use super::string_batch::{Ended, Head, until_whole};
use super::{GpuError, STORAGE_READ, STORAGE_WRITE, UNIFORM};
use crate::laws::Law;
use crate::simulate::strings::{Chain, MAX_NODES, STUCK_SPEED_RAD_S, Schedule, StringJob, StringState, Summary};
use crate::simulate::surface::{Drive, Integration, OnClock};
use bytemuck::{Pod, Zeroable};

/// Words per string of the kernel's buffers. Keep in sync with shaders/strings.wgsl.
const INPUT_WORDS: usize = 12;
const STATE_WORDS: usize = 2 * MAX_NODES + 2;
const SUMMARY_WORDS: usize = 16;

/// Strings held on the device at once: memory stays bounded (448 B a string: inputs 48, state
/// 136, summary 64, and the read-back of state and summary) whatever the batch.
const STRINGS_PER_CHUNK: usize = 1 << 18;

/// Strings per dispatch: each dispatch is its own submission, so that no single one runs long
/// enough for a driver's watchdog.
const STRINGS_PER_DISPATCH: usize = 1 << 16;

/// Host twin of `StringsJob` in shaders/strings.wgsl. Keep in sync.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct StringsJob {
    head: Head,
    settle_steps: u32,
    drive_offset: u32,
    dt_s: f32,
    alpha: f32,
    beta: f32,
    stuck_speed: f32,
    settle_dt_s: f32,
    first_step: u32,
    end_step: u32,
    /// The most steps a dispatch integrates (the kernel reads it only to tell a cut
    /// invocation).
    slice_steps: u32,
    inertia: [f32; MAX_NODES],
    stiffness: [f32; MAX_NODES],
}

/// Integrates every string of `jobs` on the GPU: summaries and final states, in order.
pub fn integrate_batch(
    chain: &Chain,
    schedule: &Schedule,
    jobs: &[StringJob],
) -> Result<Vec<(Summary, StringState)>, GpuError> {
    integrate_batch_in_slices(chain, schedule, jobs, steps_per_slice(chain.nodes()))
}

/// [`integrate_batch`] from slices of `slice_steps` steps a dispatch (shortened where the
/// driver cuts them): the results are the same whatever the slices, which the tests check.
#[doc(hidden)]
pub fn integrate_batch_in_slices(
    chain: &Chain,
    schedule: &Schedule,
    jobs: &[StringJob],
    slice_steps: u32,
) -> Result<Vec<(Summary, StringState)>, GpuError> {
    let ctx = super::context()?;
    let mut out = Vec::with_capacity(jobs.len());
    let kernel = strings_kernel(ctx, "main", chain.nodes(), jobs.iter().map(|j| j.law))?;
    let mut job = StringsJob::zeroed();
    job.head = Head::sampling(
        schedule.steps_per_sample,
        schedule.settle_samples,
        schedule.record_samples,
    );
    job.dt_s = schedule.dt_s as f32;
    job.slice_steps = slice_steps.max(1);
    let periods = u64::from(schedule.settle_samples + schedule.record_samples);
    let steps = periods * u64::from(schedule.steps_per_sample);
    if steps > u64::from(u32::MAX) {
        return Err(GpuError::TooLarge(format!(
            "{steps} integration steps a string ({periods} sample periods of {}); at most {} on the GPU",
            schedule.steps_per_sample,
            u32::MAX
        )));
    }
    job.alpha = chain.alpha_per_s as f32;
    job.beta = chain.beta_s as f32;
    job.stuck_speed = STUCK_SPEED_RAD_S as f32;
    for j in 0..chain.nodes() {
        job.inertia[j] = chain.inertia_kg_m2[j] as f32;
        job.stiffness[j] = chain.stiffness_nm_per_rad[j] as f32;
    }
    let expected = schedule.record_samples;
    for chunk in jobs.chunks(STRINGS_PER_CHUNK) {
        let shorten = |job: &mut StringsJob| quarter_slice(&mut job.slice_steps);
        out.extend(until_whole(job, "string", expected, shorten, |job| {
            let (got, cut) = run_chunk(ctx, &kernel, job, chunk)?;
            let short_of = got.iter().find(|(s, _)| !s.diverged && s.samples != expected);
            let short_of = short_of.map(|(s, _)| s.samples);
            Ok((got, Ended { cut, short_of }))
        })?);
    }
    Ok(out)
}

/// The strings kernel's entry point `entry` for a chain of `nodes` and the laws of a batch: one
/// law for the whole batch (the usual case) is compiled in.
fn strings_kernel(
    ctx: &super::GpuContext,
    entry: &str,
    nodes: usize,
    laws_of_batch: impl Iterator<Item = Law> + Clone,
) -> Result<super::Kernel, GpuError> {
    let laws = crate::laws::file::among(laws_of_batch.clone());
    let bindings = [UNIFORM, STORAGE_READ, STORAGE_WRITE, STORAGE_WRITE];
    let mut all = laws_of_batch;
    let first = all.next();
    let single = first.filter(|law| all.all(|l| l == *law));
    let law_override = single.map_or(f64::from(u32::MAX), |l| l.index() as f64);
    ctx.kernel(
        &format!(
            "{} {entry} ({nodes} nodes, law {})",
            super::file_laws::label("strings", &laws),
            single.map_or("any".to_string(), |l| l.index().to_string())
        ),
        entry,
        || super::strings_source_for(&laws, nodes),
        &bindings,
        &[("NODES", nodes as f64), ("LAW", law_override)],
    )
}

pub use crate::simulate::surface::OnClockJob;

/// Bytes of trace a chunk of strings on a record's clock holds at most on the device: the
/// storage-buffer bindings every adapter allows.
const TRACE_BYTES_PER_CHUNK: usize = 64 << 20;

/// Words of state per string on a record's clock. Keep in sync with shaders/strings.wgsl.
const CLOCK_STATE_WORDS: usize = 8;

/// Most steps a string of `nodes` nodes integrates per dispatch at first: lavapipe ends an
/// invocation's loops after 65,535 iterations together, its loops over the nodes counted too,
/// and runs eight strings as one: a step is a pass of the step loop and of the event loop and,
/// where some of the eight are stuck and some slip, both branches' RK4 steps, each eight loops
/// over the nodes (four derivatives, three intermediate states, the update). 60,000 iterations
/// of those leave the rest for stops and releases: 370 steps for ten nodes. A one-node chain's
/// loops unroll away, and its 6,000 steps are what every 1-DOF string has run at. A chunk the
/// driver still cuts runs again in shorter slices ([`integrate_batch`]).
fn steps_per_slice(nodes: usize) -> u32 {
    if nodes == 1 {
        return 6_000;
    }
    60_000 / (2 + 16 * nodes as u32)
}

/// The shortest slice a cut chunk is run again in: below it the driver is not cutting long
/// slices but failing, and the error says so.
const SHORTEST_SLICE_STEPS: u32 = 16;

/// A cut chunk's next slice length, a quarter of `slice_steps`; false below
/// [`SHORTEST_SLICE_STEPS`] (for [`until_whole`]).
fn quarter_slice(slice_steps: &mut u32) -> bool {
    *slice_steps /= 4;
    *slice_steps >= SHORTEST_SLICE_STEPS
}

/// A job on a record's clock, sliced: each slice a span of its steps.
#[repr(transparent)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct OnClockUniform(StringsJob);

impl OnClockUniform {
    /// Steps in all: the settling's, then each sample's after the first.
    /// (At most `u32::MAX`: [`on_clock_batch`] refuses longer strings.)
    fn steps(&self) -> u32 {
        let j = &self.0;
        j.settle_steps + j.head.record_samples.saturating_sub(1) * j.head.steps_per_sample
    }
}

impl super::string_batch::StringsUniform for OnClockUniform {
    fn head(&mut self) -> &mut Head {
        &mut self.0.head
    }

    fn rewind(&mut self) {
        (self.0.first_step, self.0.end_step) = (0, 0);
    }

    fn next_slice(&mut self) -> bool {
        let total = self.steps();
        let j = &mut self.0;
        if j.end_step >= total {
            return false;
        }
        j.first_step = j.end_step;
        j.end_step = j.first_step.saturating_add(j.slice_steps).min(total);
        true
    }
}

/// Every string of `jobs` (1-DOF strings sharing their inertia) driven by `drive` on its clock,
/// on the GPU: the twin of [`crate::simulate::surface::simulate_on_clock`] in f32, in order.
pub fn on_clock_batch(
    drive: &Drive,
    integration: Integration,
    jobs: &[OnClockJob<'_>],
) -> Result<Vec<OnClock>, GpuError> {
    on_clock_batch_in_slices(drive, integration, jobs, steps_per_slice(1))
}

/// [`on_clock_batch`] from slices of `slice_steps` steps a dispatch (shortened where the
/// driver cuts them): the results are the same whatever the slices, which the tests check.
#[doc(hidden)]
pub fn on_clock_batch_in_slices(
    drive: &Drive,
    integration: Integration,
    jobs: &[OnClockJob<'_>],
    slice_steps: u32,
) -> Result<Vec<OnClock>, GpuError> {
    let Some(first) = jobs.first() else {
        return Ok(Vec::new());
    };
    let samples = drive.omega_rad_s.len();
    if samples == 0 {
        return Ok(jobs.iter().map(|_| OnClock::default()).collect());
    }
    // The kernel reads each string's stiffness and β, the batch's inertia, and no α.
    let fits = |c: &Chain| c.nodes() == 1 && c.inertia_kg_m2 == first.chain.inertia_kg_m2 && c.alpha_per_s == 0.0;
    if !jobs.iter().all(|j| fits(j.chain)) {
        return Err(GpuError::Validation(
            "strings on a record's clock must be 1-DOF strings of one inertia without mass-proportional damping".into(),
        ));
    }
    let ctx = super::context()?;
    let kernel = strings_kernel(ctx, "on_clock", 1, jobs.iter().map(|j| j.law))?;
    // The twin's steps: each span split into equal steps no longer than dt.
    let steps_of = |span_s: f64| {
        let steps = (span_s / integration.dt_s).ceil().max(1.0);
        (steps as u32, (span_s / steps) as f32)
    };
    let mut job = StringsJob::zeroed();
    let (sample_steps, sample_h) = steps_of(drive.period_s);
    job.head = Head::sampling(sample_steps, 0, samples as u32);
    job.dt_s = sample_h;
    if integration.settle_s > 0.0 {
        (job.settle_steps, job.settle_dt_s) = steps_of(integration.settle_s);
    }
    job.stuck_speed = STUCK_SPEED_RAD_S as f32;
    job.slice_steps = slice_steps.max(1);
    job.inertia[0] = first.chain.inertia_kg_m2[0] as f32;
    let steps = u64::from(job.settle_steps) + (samples as u64 - 1) * u64::from(sample_steps);
    if steps > u64::from(u32::MAX) {
        return Err(GpuError::TooLarge(format!(
            "{steps} integration steps a string (the settling and {samples} samples of {sample_steps}); at most {} on the GPU",
            u32::MAX
        )));
    }
    let mut job = OnClockUniform(job);
    let trace_words = 4 * samples + 3;
    let per_chunk = (TRACE_BYTES_PER_CHUNK / (4 * trace_words)).clamp(1, STRINGS_PER_CHUNK);
    let mut out = Vec::with_capacity(jobs.len());
    for chunk in jobs.chunks(per_chunk) {
        let n = chunk.len();
        job.0.drive_offset = (INPUT_WORDS * n) as u32;
        let mut inputs = vec![0.0f32; INPUT_WORDS * n + 2 * samples];
        for (i, j) in chunk.iter().enumerate() {
            let b = INPUT_WORDS * i;
            inputs[b] = f32::from_bits(j.law.index() as u32);
            for (k, &p) in j.params_nm.iter().take(6).enumerate() {
                inputs[b + 4 + k] = p as f32;
            }
            inputs[b + 10] = j.chain.stiffness_nm_per_rad[0] as f32;
            inputs[b + 11] = j.chain.beta_s as f32;
        }
        let drive_words = &mut inputs[INPUT_WORDS * n..];
        for (k, (omega, ratio)) in drive.omega_rad_s.iter().zip(&drive.ratio).enumerate() {
            drive_words[2 * k] = *omega as f32;
            drive_words[2 * k + 1] = *ratio as f32;
        }
        let layout = super::string_batch::Chunk {
            label: "strings on a clock",
            strings: n,
            inputs: &inputs,
            state_words: CLOCK_STATE_WORDS,
            states: None,
            summary_words: trace_words,
            strings_per_dispatch: STRINGS_PER_DISPATCH,
            read_states: false,
        };
        let shorten = |job: &mut OnClockUniform| quarter_slice(&mut job.0.slice_steps);
        let expected = samples as u32;
        out.extend(until_whole(job, "string", expected, shorten, |job| {
            let traces = super::string_batch::integrate_chunk(ctx, &kernel, job, &layout)?.summaries;
            let mut ended = Ended {
                cut: false,
                short_of: None,
            };
            let mut strings = Vec::with_capacity(n);
            for t in traces.chunks_exact(trace_words) {
                let reached = t[4 * samples].to_bits() as usize;
                let diverged = t[4 * samples + 1].to_bits() != 0;
                ended.cut |= t[4 * samples + 2].to_bits() != 0;
                // A driver that ends a kernel's loops early must not pass for a shorter record.
                if reached < samples && !diverged && ended.short_of.is_none() {
                    ended.short_of = Some(reached as u32);
                }
                let column = |c: usize| -> Vec<f64> { (0..reached).map(|k| f64::from(t[4 * k + c])).collect() };
                strings.push(OnClock {
                    surface_torque_nm: column(0),
                    bit_speed_rad_s: column(1),
                    bit_least_rad_s: column(2),
                    bit_greatest_rad_s: column(3),
                    diverged,
                });
            }
            Ok((strings, ended))
        })?);
    }
    Ok(out)
}

impl StringsJob {
    /// Steps in all, the settling's first (at most `u32::MAX`: [`integrate_batch`] refuses
    /// longer schedules).
    fn steps(&self) -> u32 {
        (self.head.settle_samples + self.head.record_samples) * self.head.steps_per_sample
    }
}

impl super::string_batch::StringsUniform for StringsJob {
    fn head(&mut self) -> &mut Head {
        &mut self.head
    }

    fn rewind(&mut self) {
        (self.first_step, self.end_step) = (0, 0);
    }

    /// The next slice of the steps (the settling's first), `slice_steps` of them.
    fn next_slice(&mut self) -> bool {
        let total = self.steps();
        if self.end_step >= total {
            return false;
        }
        self.first_step = self.end_step;
        self.end_step = self.first_step.saturating_add(self.slice_steps).min(total);
        true
    }
}

/// The chunk's summaries and final states, and whether the driver cut any string's loops.
fn run_chunk(
    ctx: &super::GpuContext,
    kernel: &super::Kernel,
    job: StringsJob,
    jobs: &[StringJob],
) -> Result<(Vec<(Summary, StringState)>, bool), GpuError> {
    let n = jobs.len();
    let mut inputs = vec![0.0f32; INPUT_WORDS * n];
    let mut states = vec![0.0f32; STATE_WORDS * n];
    for (i, j) in jobs.iter().enumerate() {
        let b = INPUT_WORDS * i;
        inputs[b] = f32::from_bits(j.law.index() as u32);
        inputs[b + 1] = j.omega_rad_s as f32;
        inputs[b + 2] = j.ratio as f32;
        for (k, &p) in j.params_nm.iter().enumerate() {
            inputs[b + 4 + k] = p as f32;
        }
        let s = STATE_WORDS * i;
        for k in 0..MAX_NODES {
            states[s + k] = j.start.lag_rad[k] as f32;
            states[s + MAX_NODES + k] = j.start.speed_rad_s[k] as f32;
        }
        states[s + 2 * MAX_NODES] = if j.start.stuck { 1.0 } else { 0.0 };
    }
    let chunk = super::string_batch::Chunk {
        label: "strings",
        strings: n,
        inputs: &inputs,
        state_words: STATE_WORDS,
        states: Some(&states),
        summary_words: SUMMARY_WORDS,
        strings_per_dispatch: STRINGS_PER_DISPATCH,
        read_states: true,
    };
    let out = super::string_batch::integrate_chunk(ctx, kernel, job, &chunk)?;
    let (states, sums) = (&out.states, &out.summaries);
    let cut = sums.chunks(SUMMARY_WORDS).any(|o| o[14].to_bits() != 0);
    let results = (0..n)
        .map(|i| {
            let s = &states[STATE_WORDS * i..STATE_WORDS * (i + 1)];
            let mut state = StringState {
                lag_rad: [0.0; MAX_NODES],
                speed_rad_s: [0.0; MAX_NODES],
                stuck: s[2 * MAX_NODES] != 0.0,
            };
            for k in 0..MAX_NODES {
                state.lag_rad[k] = f64::from(s[k]);
                state.speed_rad_s[k] = f64::from(s[MAX_NODES + k]);
            }
            let o = &sums[SUMMARY_WORDS * i..SUMMARY_WORDS * (i + 1)];
            let count = |k: usize| o[k].to_bits();
            let value = |k: usize| f64::from(o[k]);
            let summary = Summary {
                samples: count(0),
                stuck: count(1),
                stick_onsets: count(2),
                first_onset: count(3),
                last_onset: count(4),
                speed_min_rad_s: value(5),
                speed_max_rad_s: value(6),
                speed_sum_rad_s: value(7),
                bit_torque_min_nm: value(8),
                bit_torque_max_nm: value(9),
                surface_torque_min_nm: value(10),
                surface_torque_max_nm: value(11),
                diverged: count(12) != 0,
                last_stuck: count(13) != 0,
            };
            (summary, state)
        })
        .collect();
    Ok((results, cut))
}
