//! A batch of simulated drill strings on the chosen backend: the kernel
//! ([`super::gpu::strings`]) or its CPU twin ([`crate::simulate::strings`]), the GPU falling back
//! to the CPU under `auto` and saying so.

use super::{Backend, fall_back_to_cpu, gpu};
use crate::error::Result;
use crate::simulate::strings::{self, Chain, Schedule, StringJob, StringState, Summary};

/// Strings a GPU integrates per call at most: memory on the host stays bounded (the jobs and
/// their results, under 1 kB a string) while each call keeps the device busy.
pub const STRINGS_PER_CALL: usize = 1 << 20;

/// Where a batch ran, for the notes and the benchmarks.
#[derive(Clone, Debug, PartialEq)]
pub enum Ran {
    Gpu(String),
    Cpu,
}

/// The batch's summaries and final states, in order, on `backend` (a GPU that cannot be set up
/// under `auto`: said through `note`, the CPU computes).
pub fn integrate(
    chain: &Chain,
    schedule: &Schedule,
    jobs: &[StringJob],
    backend: Backend,
    note: &mut dyn FnMut(String),
) -> Result<(Vec<(Summary, StringState)>, Ran)> {
    let on_gpu = |jobs: &[StringJob]| -> std::result::Result<Vec<(Summary, StringState)>, gpu::GpuError> {
        let mut out = Vec::with_capacity(jobs.len());
        for part in jobs.chunks(STRINGS_PER_CALL) {
            out.extend(gpu::strings::integrate_batch(chain, schedule, part)?);
        }
        Ok(out)
    };
    let adapter = || gpu::context().map(|c| c.describe());
    match backend {
        Backend::Cpu => Ok((strings::integrate_batch(chain, schedule, jobs), Ran::Cpu)),
        Backend::Gpu => {
            let name = adapter()?;
            Ok((on_gpu(jobs)?, Ran::Gpu(name)))
        }
        Backend::Auto => match adapter().and_then(|name| Ok((on_gpu(jobs)?, name))) {
            Ok((out, name)) => Ok((out, Ran::Gpu(name))),
            Err(e) => {
                fall_back_to_cpu(e, note)?;
                Ok((strings::integrate_batch(chain, schedule, jobs), Ran::Cpu))
            }
        },
    }
}
