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

impl std::fmt::Display for Ran {
    /// Where the batch ran, in words: `GPU <adapter>` or `CPU`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Ran::Gpu(name) => write!(f, "GPU {name}"),
            Ran::Cpu => write!(f, "CPU"),
        }
    }
}

/// The most nodes of a chain a software driver simulates under `auto`: lavapipe runs a short
/// chain faster than the CPU twin on the same cores and a longer one far slower, its arrays
/// spilled to memory. `bitrock stability --law m2 --params 13,6.5,0.3 --simulate --at-rpm 60
/// --at-kn 244.2 --structure fe` on two cores, `--backend gpu` against `cpu` (wall, the
/// kernel's compilation included): 2 nodes 0.96 s against 1.64 s, 4 nodes 1.56 against 2.06,
/// 6 nodes 3.12 against 2.34, 8 nodes 104 against 2.6; the 1-DOF string 7.1e5 string-s/s against
/// 3.8e5 and the ten-element one 2.0e3 against 6.7e4 (`bitrock bench --strings --quick
/// --backend gpu`, and `cpu`).
pub const SOFTWARE_GPU_MAX_NODES: usize = 4;

/// The software GPU that `auto` leaves a chain of `nodes` nodes to the CPU rather than take
/// (more than [`SOFTWARE_GPU_MAX_NODES`]), described; `None` where `auto` takes the GPU (or there
/// is none).
pub fn software_gpu_passed_over(nodes: usize) -> Option<String> {
    if nodes <= SOFTWARE_GPU_MAX_NODES {
        return None;
    }
    let ctx = gpu::context().ok()?;
    ctx.is_software().then(|| ctx.describe())
}

/// The batch's summaries and final states, in order, on `backend` (a GPU that cannot be set up
/// under `auto`: said through `note`, the CPU computes). Under `auto` a software driver takes a
/// chain of at most [`SOFTWARE_GPU_MAX_NODES`] nodes and leaves a longer one to the CPU, saying
/// so.
pub fn integrate(
    chain: &Chain,
    schedule: &Schedule,
    jobs: &[StringJob],
    backend: Backend,
    note: &mut dyn FnMut(String),
) -> Result<(Vec<(Summary, StringState)>, Ran)> {
    if backend == Backend::Auto
        && let Some(adapter) = software_gpu_passed_over(chain.nodes())
    {
        note(format!(
            "auto: simulated strings of {} nodes on the CPU rather than the software GPU {adapter}, which runs them on the same cores more slowly (`backend gpu` insists on it)",
            chain.nodes(),
        ));
        return Ok((strings::integrate_batch(chain, schedule, jobs), Ran::Cpu));
    }
    on_backend(
        backend,
        note,
        || {
            let mut out = Vec::with_capacity(jobs.len());
            for part in jobs.chunks(STRINGS_PER_CALL) {
                out.extend(gpu::strings::integrate_batch(chain, schedule, part)?);
            }
            Ok(out)
        },
        || strings::integrate_batch(chain, schedule, jobs),
    )
}

/// Where a surface run's strings go, decided once before it starts: [`Backend::Gpu`] or
/// [`Backend::Cpu`], and in words. `auto` takes a hardware GPU that can be set up, and the CPU
/// otherwise, saying so: a software driver (lavapipe) runs on the CPU's own cores, where the
/// CPU twin's lanes simulate a record's strings faster (docs/surface.md measures both); `gpu`
/// takes a software driver too.
pub fn resolve(backend: Backend, note: &mut dyn FnMut(String)) -> Result<(Backend, Ran)> {
    let on_gpu = |ctx: &gpu::GpuContext, note: &mut dyn FnMut(String)| {
        note(format!(
            "{}: {} (simulated strings)",
            super::GPU_BACKEND_NOTE,
            ctx.describe()
        ));
        (Backend::Gpu, Ran::Gpu(ctx.describe()))
    };
    match backend {
        Backend::Cpu => Ok((Backend::Cpu, Ran::Cpu)),
        Backend::Gpu => Ok(on_gpu(gpu::context()?, note)),
        Backend::Auto => match gpu::context() {
            Ok(ctx) if !ctx.is_software() => Ok(on_gpu(ctx, note)),
            Ok(ctx) => {
                note(format!(
                    "auto: simulated strings on the CPU rather than the software GPU {}, which runs on the same cores more slowly (`backend gpu` insists on it)",
                    ctx.describe()
                ));
                Ok((Backend::Cpu, Ran::Cpu))
            }
            Err(e) => {
                fall_back_to_cpu(e, note)?;
                Ok((Backend::Cpu, Ran::Cpu))
            }
        },
    }
}

/// `on_gpu` on `backend`'s GPU with the adapter's name, or `on_cpu`: under `auto` a GPU that
/// cannot be set up (or fails) is said through `note` and the CPU computes.
pub(crate) fn on_backend<T>(
    backend: Backend,
    note: &mut dyn FnMut(String),
    on_gpu: impl FnOnce() -> std::result::Result<T, gpu::GpuError>,
    on_cpu: impl FnOnce() -> T,
) -> Result<(T, Ran)> {
    let adapter = || gpu::context().map(|c| c.describe());
    match backend {
        Backend::Cpu => Ok((on_cpu(), Ran::Cpu)),
        Backend::Gpu => {
            let name = adapter()?;
            Ok((on_gpu()?, Ran::Gpu(name)))
        }
        Backend::Auto => match adapter().and_then(|name| Ok((on_gpu()?, name))) {
            Ok((out, name)) => Ok((out, Ran::Gpu(name))),
            Err(e) => {
                fall_back_to_cpu(e, note)?;
                Ok((on_cpu(), Ran::Cpu))
            }
        },
    }
}
