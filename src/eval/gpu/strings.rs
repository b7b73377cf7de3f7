//! Runs `shaders/strings.wgsl`: a batch of drill strings, one per invocation, each from its own
//! law, parameters, operating point and start, to its summary and final state. The GPU twin of
//! [`crate::simulate::strings::integrate_batch`].

use super::string_batch::Head;
use super::{GpuError, STORAGE_READ, STORAGE_WRITE, UNIFORM};
use crate::simulate::strings::{Chain, MAX_NODES, STUCK_SPEED_RAD_S, Schedule, StringJob, StringState, Summary};
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
    _pad0: u32,
    _pad1: u32,
    dt_s: f32,
    alpha: f32,
    beta: f32,
    stuck_speed: f32,
    inertia: [f32; MAX_NODES],
    stiffness: [f32; MAX_NODES],
}

/// Integrates every string of `jobs` on the GPU: summaries and final states, in order.
pub fn integrate_batch(
    chain: &Chain,
    schedule: &Schedule,
    jobs: &[StringJob],
) -> Result<Vec<(Summary, StringState)>, GpuError> {
    let ctx = super::context()?;
    let mut out = Vec::with_capacity(jobs.len());
    let laws = crate::laws::file::among(jobs.iter().map(|j| j.law));
    let bindings = [UNIFORM, STORAGE_READ, STORAGE_WRITE, STORAGE_WRITE];
    let nodes = chain.nodes();
    // One law for the whole batch (the usual case) is compiled in.
    let single = jobs
        .first()
        .map(|j| j.law)
        .filter(|law| jobs.iter().all(|j| j.law == *law));
    let law_override = single.map_or(f64::from(u32::MAX), |l| l.index() as f64);
    let kernel = ctx.kernel(
        &format!(
            "{} ({nodes} nodes, law {})",
            super::file_laws::label("strings", &laws),
            single.map_or("any".to_string(), |l| l.index().to_string())
        ),
        "main",
        || super::strings_source_for(&laws, nodes),
        &bindings,
        &[("NODES", nodes as f64), ("LAW", law_override)],
    )?;
    let mut job = StringsJob::zeroed();
    job.head = Head::sampling(
        schedule.steps_per_sample,
        schedule.settle_samples,
        schedule.record_samples,
    );
    job.dt_s = schedule.dt_s as f32;
    job.alpha = chain.alpha_per_s as f32;
    job.beta = chain.beta_s as f32;
    job.stuck_speed = STUCK_SPEED_RAD_S as f32;
    for j in 0..chain.nodes() {
        job.inertia[j] = chain.inertia_kg_m2[j] as f32;
        job.stiffness[j] = chain.stiffness_nm_per_rad[j] as f32;
    }
    for chunk in jobs.chunks(STRINGS_PER_CHUNK) {
        out.extend(run_chunk(ctx, &kernel, job, chunk)?);
    }
    Ok(out)
}

impl super::string_batch::StringsUniform for StringsJob {
    fn head(&mut self) -> &mut Head {
        &mut self.head
    }
}

fn run_chunk(
    ctx: &super::GpuContext,
    kernel: &super::Kernel,
    job: StringsJob,
    jobs: &[StringJob],
) -> Result<Vec<(Summary, StringState)>, GpuError> {
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
    Ok((0..n)
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
        .collect())
}
