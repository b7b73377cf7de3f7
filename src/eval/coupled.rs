//! A batch of coupled axial-torsional strings on the chosen backend: the kernel
//! ([`super::gpu::coupled`]) or its CPU twin ([`crate::simulate::coupled`]), the GPU falling
//! back to the CPU under `auto` and saying so.

use super::strings::{Ran, STRINGS_PER_CALL, on_backend};
use super::{Backend, gpu};
use crate::error::Result;
use crate::simulate::coupled::{self, Assembly, CoupledJob, CoupledState, CoupledSummary, Schedule};

/// The batch's summaries, in order, on `backend` (a GPU that cannot be set up under `auto`:
/// said through `note`, the CPU computes), every string from steady drilling at its drive or,
/// where given, from `start`. The kernel takes one kind of axial drive per batch: a batch that
/// mixes weights and feeds runs in two.
pub fn integrate(
    assembly: &Assembly,
    schedule: &Schedule,
    jobs: &[CoupledJob],
    start: Option<&CoupledState>,
    backend: Backend,
    note: &mut dyn FnMut(String),
) -> Result<(Vec<CoupledSummary>, Ran)> {
    on_backend(
        backend,
        note,
        || {
            let mut out = vec![None; jobs.len()];
            for feed in [false, true] {
                let (index, kind): (Vec<usize>, Vec<CoupledJob>) = jobs
                    .iter()
                    .enumerate()
                    .filter(|(_, j)| j.axial.is_feed() == feed)
                    .map(|(i, j)| (i, *j))
                    .unzip();
                for (part, at) in kind.chunks(STRINGS_PER_CALL).zip(index.chunks(STRINGS_PER_CALL)) {
                    for (summary, &i) in gpu::coupled::integrate_batch(assembly, schedule, part, start)?
                        .into_iter()
                        .zip(at)
                    {
                        out[i] = Some(summary);
                    }
                }
            }
            Ok(out.into_iter().map(|s| s.expect("every string integrated")).collect())
        },
        || coupled::integrate_batch(assembly, schedule, jobs, start),
    )
}
