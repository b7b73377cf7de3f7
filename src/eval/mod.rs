//! Scoring candidates: the [`Evaluator`] trait the samplers call, and the [`Problem`] every
//! backend scores against. The CPU evaluator (f64) is the reference; the GPU one must match it.
//! What a run's candidates are scored against travels to workers as an [`Objective`].

pub mod auto;
pub mod coupled;
pub mod cpu;
pub mod gpu;
mod problem;
pub mod projection;
pub mod records;
pub mod strings;
pub mod surface;

pub use problem::Problem;

use crate::error::Result;
use crate::prior::{Candidate, MAX_DIMS};

/// Largest relative difference of ρ between the GPU (f32) and the CPU (f64) that bitrock
/// accepts; candidates whose ρ lies this close to ε may be accepted by one backend only.
/// Measured on lavapipe: about 1e-6 on the embedded record (tests/it/gpu.rs prints it).
pub const PARITY_TOLERANCE: f64 = 1e-5;

/// ρ of a sum of squared residuals `ssr` (a kernel's f32 sum, or the CPU's): `ssr /
/// sum_sq_torque`, and +∞ where the sum has no value (a torque overflowing, a law file's taking a
/// logarithm of a negative number), so that such a candidate is rejected on every backend and
/// never poisons a sum.
pub(crate) fn rho_of_sum(ssr: f64, sum_sq_torque: f64) -> f64 {
    if ssr.is_nan() {
        f64::INFINITY
    } else {
        ssr / sum_sq_torque
    }
}

/// Gaussian kernel sums S_i = Σ_j w_j exp(−(|d_ij|² − c_j (d_ij·x_j)²)/2), d_ij = y_i − x_j,
/// between targets y_i and weighted sources x_j, in whitened coordinates (unused coordinates
/// 0): the O(N²) part of the SMC importance weights (see [`crate::abc::smc`]). With c_j = 0
/// every source has the whitening's covariance; c_j = 1/(1 + |x_j|²) gives source j the
/// covariance I + x_j x_jᵀ (the locally optimal kernel, whose whitening is centred on the
/// particles below ε).
#[derive(Clone, Copy, Debug)]
pub struct KernelSums<'a> {
    pub targets: &'a [[f64; MAX_DIMS]],
    pub sources: &'a [[f64; MAX_DIMS]],
    /// w_j, one per source.
    pub weights: &'a [f64],
    /// c_j, one per source; `None`: all 0.
    pub rank_one: Option<&'a [f64]>,
}

impl KernelSums<'_> {
    /// True where every point's coordinates past a law's parameters are 0: a run that does
    /// not infer the string with the law.
    pub fn law_only(&self) -> bool {
        self.targets
            .iter()
            .chain(self.sources)
            .all(|p| p[crate::laws::MAX_PARAMS..].iter().all(|v| v.to_bits() == 0))
    }
}

/// Scores candidates: contiguous ranges of the prior's candidate streams, or explicit
/// parameter vectors. Implementations must return, for candidate i of population g, ρ of
/// `problem.prior.candidate(seed, g, i)` against the data.
pub trait Evaluator: Send + Sync {
    /// Backend name for records (`cpu`, `gpu`).
    fn backend(&self) -> &'static str;
    /// The problem being scored.
    fn problem(&self) -> &Problem;
    /// Writes ρ of candidates `start .. start + out.len()` of `population` into `out`.
    fn score(&self, population: u32, start: u64, out: &mut [f64]) -> Result<()>;
    /// Writes ρ of explicit candidates (prior slot and f32 parameters, unused ones 0) into
    /// `out` (as long as `candidates`). Every backend scores the same f32 values, so the
    /// parity of [`Evaluator::score`] holds here too.
    fn score_params(&self, candidates: &[Candidate], out: &mut [f64]) -> Result<()>;
    /// Writes ρ of explicit candidates into `rho` and λ = Σ e_t·e_(t−1) / Σy² into `lag`: the
    /// lag-1 sum of their residuals e = y − r·T(w) over consecutive samples of the record, the
    /// statistic of the AR(1) noise model ([`crate::abc::evidence::NoiseModel`]). λ is held to
    /// the parity contract relative to ρ (it may be near 0 where ρ is not). The default computes
    /// λ with the CPU twin, [`cpu::lag_sums`].
    fn score_params_lagged(&self, candidates: &[Candidate], rho: &mut [f64], lag: &mut [f64]) -> Result<()> {
        self.score_params(candidates, rho)?;
        cpu::lag_sums(self.problem(), candidates, lag);
        Ok(())
    }
    /// Writes the kernel sums of `sums` (one per target) into `out`. The default is the CPU
    /// twin in f64, [`cpu::kernel_sums`].
    fn kernel_sums(&self, sums: &KernelSums, out: &mut [f64]) -> Result<()> {
        cpu::kernel_sums(sums, out);
        Ok(())
    }
    /// The GPU scoring shape, for a GPU evaluator: its f32 sums depend on it (within the
    /// parity tolerance), so a run records it.
    fn gpu_shape(&self) -> Option<gpu::Shape> {
        None
    }
}

/// A borrowed evaluator is an evaluator: code generic over owners (`Box`, `Arc`, `&`) hands
/// any of them on as `&dyn Evaluator`.
impl<T: Evaluator + ?Sized> Evaluator for &T {
    fn backend(&self) -> &'static str {
        (**self).backend()
    }

    fn problem(&self) -> &Problem {
        (**self).problem()
    }

    fn score(&self, population: u32, start: u64, out: &mut [f64]) -> Result<()> {
        (**self).score(population, start, out)
    }

    fn score_params(&self, candidates: &[Candidate], out: &mut [f64]) -> Result<()> {
        (**self).score_params(candidates, out)
    }

    fn score_params_lagged(&self, candidates: &[Candidate], rho: &mut [f64], lag: &mut [f64]) -> Result<()> {
        (**self).score_params_lagged(candidates, rho, lag)
    }

    fn kernel_sums(&self, sums: &KernelSums, out: &mut [f64]) -> Result<()> {
        (**self).kernel_sums(sums, out)
    }

    fn gpu_shape(&self) -> Option<gpu::Shape> {
        (**self).gpu_shape()
    }
}

/// Which evaluator computes ρ.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "lowercase")]
pub enum Backend {
    /// The GPU when an adapter exists, else the CPU (saying so).
    #[default]
    Auto,
    /// The GPU (WGSL through wgpu); an error when there is no adapter.
    Gpu,
    /// The CPU reference (f64, rayon).
    Cpu,
}

/// How every line that names the GPU scoring a run (adapter, shape) begins.
pub(crate) const GPU_BACKEND_NOTE: &str = "GPU backend";

/// A GPU named with the shape it scores in and where that shape came from, as the notes that
/// say which backend scores a run name it.
pub(crate) fn gpu_named(adapter: &str, shape: gpu::Shape, source: gpu::tune::Source) -> String {
    format!("{adapter} ({shape} scoring, {source})")
}

/// True for a note that only informs (which GPU scores, in which shape): front ends may log
/// it rather than warn. Every other note names something the user should act on or know about
/// the result (a fallback to the CPU, a moved floor, a resume).
pub fn is_information(note: &str) -> bool {
    note.starts_with(GPU_BACKEND_NOTE) || note.starts_with(auto::AUTO_NOTE)
}

/// What a run's candidates are scored against, from which one process, or a worker elsewhere,
/// makes its evaluator ([`Objective::evaluator`]).
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub enum Objective {
    /// ρ of each candidate's torque against a record's bit speed and torque.
    Record(Problem),
    /// The distance of each candidate's simulated string from a surface record's summaries,
    /// its strings on the backend the run resolved (the one its workers are asked to use).
    Surface(Box<surface::SurfaceEvaluator>),
}

impl Objective {
    /// The problem: the prior and the seed the candidates come from (and, for a record, its
    /// data).
    pub fn problem(&self) -> &Problem {
        match self {
            Objective::Record(problem) => problem,
            Objective::Surface(strings) => strings.problem(),
        }
    }

    /// The evaluator on `backend` ([`evaluator`] for a record; for strings, the backend
    /// resolved as a surface run resolves it, [`strings::resolve`]).
    pub fn evaluator(
        self,
        backend: Backend,
        wish: gpu::tune::ShapeWish,
        note: &mut dyn FnMut(String),
    ) -> Result<Box<dyn Evaluator>> {
        match self {
            Objective::Record(problem) => evaluator(problem, backend, wish, note),
            Objective::Surface(strings) => {
                let (backend, _) = strings::resolve(backend, note)?;
                Ok(Box::new(strings.on(backend)))
            }
        }
    }
}

impl From<Problem> for Objective {
    fn from(problem: Problem) -> Self {
        Objective::Record(problem)
    }
}

/// The evaluator for `backend`, a GPU one in the shape `wish` leads to (see
/// [`gpu::tune::choose`]). With `Auto`, a GPU that cannot be set up is reported through `note`
/// and the CPU is used instead.
pub fn evaluator(
    problem: Problem,
    backend: Backend,
    wish: gpu::tune::ShapeWish,
    note: &mut dyn FnMut(String),
) -> Result<Box<dyn Evaluator>> {
    let said = |gpu: &gpu::residual::GpuEvaluator| {
        format!(
            "{GPU_BACKEND_NOTE}: {}",
            gpu_named(&gpu.adapter(), gpu.shape(), gpu.shape_source())
        )
    };
    match backend {
        Backend::Cpu => Ok(Box::new(cpu::CpuEvaluator::new(problem))),
        Backend::Gpu => {
            let gpu = gpu::residual::GpuEvaluator::wished(problem, wish)?;
            note(said(&gpu));
            Ok(Box::new(gpu))
        }
        Backend::Auto => {
            // A software driver runs on the CPU's own cores: the faster of the two is kept.
            let software = gpu::context().and_then(|ctx| Ok((ctx, gpu::tune::choose(ctx, &problem, wish)?)));
            let mut kept_said = false;
            if let Ok((ctx, choice)) = software
                && ctx.is_software()
            {
                match auto::cpu_beats(ctx, &problem, choice, wish, note)? {
                    auto::Kept::Cpu => return Ok(Box::new(cpu::CpuEvaluator::new(problem))),
                    auto::Kept::Gpu { said } => kept_said = said,
                }
            }
            match gpu::residual::GpuEvaluator::wished(problem.clone(), wish) {
                Ok(gpu) => {
                    if !kept_said {
                        note(said(&gpu));
                    }
                    Ok(Box::new(gpu))
                }
                Err(e) => {
                    fall_back_to_cpu(e, note)?;
                    Ok(Box::new(cpu::CpuEvaluator::new(problem)))
                }
            }
        }
    }
}

/// What a GPU that cannot be set up means under `auto`: a refused setting is the user's to fix
/// (the error), anything else is said through `note` and the CPU computes instead.
pub(crate) fn fall_back_to_cpu(e: gpu::GpuError, note: &mut dyn FnMut(String)) -> Result<()> {
    if let gpu::GpuError::Setting { .. } = e {
        return Err(e.into());
    }
    note(no_usable_gpu(&e));
    Ok(())
}

/// What `auto` says when the GPU it found fails: the CPU computes instead.
pub(crate) fn no_usable_gpu(e: &dyn std::fmt::Display) -> String {
    format!("{NO_USABLE_GPU} ({e}); computing on the CPU")
}

/// How [`no_usable_gpu`]'s words begin: what tells auto's fallback from other notes.
pub(crate) const NO_USABLE_GPU: &str = "no usable GPU";

// The requests of the batched scoring ([`records`]), shared by its CPU and GPU scorers.

/// Which candidates of a record to score.
#[derive(Clone, Debug)]
pub enum Candidates {
    /// Candidates `start .. start + len` of stream `population` of the record's prior.
    Stream { population: u32, start: u64, len: usize },
    /// Explicit candidates (prior slot and f32 parameters).
    Explicit(Vec<Candidate>),
}

impl Candidates {
    pub fn len(&self) -> usize {
        match self {
            Candidates::Stream { len, .. } => *len,
            Candidates::Explicit(c) => c.len(),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// One scoring call of one record's sampler.
#[derive(Clone, Debug)]
pub struct Request {
    /// The record's index in its [`records::RecordBatch`] (the order seats registered).
    pub record: usize,
    pub candidates: Candidates,
}
