//! The GPU evaluator: `shaders/residual.wgsl` regenerates each candidate from
//! (seed, population, index), 16 candidates per invocation ([`Shape::Blocked`]) or per
//! workgroup ([`Shape::Tiled`]), and returns its Σ(y − r·T)² in f32; the host divides by Σy²
//! (f64). Data, prior and bind group are set up once per evaluator, pipelines once per context.
//! `shaders/score_params.wgsl` scores explicit parameter vectors against the same data in the
//! same shape (set up on first use), and `shaders/kernel_sums.wgsl` computes the SMC weights'
//! kernel sums (see [`super::kernel_sums`]).

use super::shape::Source;
use super::{
    GpuContext, GpuError, GpuPrior, GpuProposal, Job, STORAGE_READ, STORAGE_WRITE, ScoringBuffers, Shape, UNIFORM,
    score_dispatch,
};
use crate::error::Result;
use crate::eval::{Evaluator, KernelSums, Problem};
use crate::prior::Candidate;
use std::sync::Mutex;

/// Buffers, pipeline and bind group of one run, created once.
struct Resources {
    job: wgpu::Buffer,
    ssr: wgpu::Buffer,
    staging: wgpu::Buffer,
    pipeline: wgpu::ComputePipeline,
    bind_group: wgpu::BindGroup,
    /// Speed, torque and ratio columns (bindings 2-4 of both scoring kernels).
    data: Vec<wgpu::Buffer>,
    has_ratio: bool,
    /// The explicit-parameter kernel, built on first use.
    params: Option<ParamsResources>,
}

/// Pipeline and buffers of `shaders/score_params.wgsl`.
struct ParamsResources {
    proposals: wgpu::Buffer,
    pipeline: wgpu::ComputePipeline,
    bind_group: wgpu::BindGroup,
    /// The same kernel's lag pass (override LAG), built on first use.
    lag: Option<(wgpu::ComputePipeline, wgpu::BindGroup)>,
}

/// Scores candidates on the GPU.
pub struct GpuEvaluator {
    problem: Problem,
    context: &'static GpuContext,
    shape: Shape,
    /// Where the shape came from.
    source: Source,
    data_len: u32,
    /// Candidates per dispatch at most.
    chunk: usize,
    /// Explicit candidates per dispatch at most (32 bytes each, within the binding limit).
    params_chunk: usize,
    resources: Mutex<Resources>,
    /// Buffers of the SMC kernel sums, reused across calls.
    kernel_sums: super::kernel_sums::Scratch,
}

impl GpuEvaluator {
    /// As [`GpuEvaluator::new`], scoring in `shape` whatever the adapter (tests, benchmarks).
    pub fn with_shape(problem: Problem, shape: Shape) -> std::result::Result<Self, GpuError> {
        Self::on(problem, shape, super::context()?)
    }

    /// As [`GpuEvaluator::with_shape`], on the GPU of `context`.
    pub fn on(problem: Problem, shape: Shape, context: &'static GpuContext) -> std::result::Result<Self, GpuError> {
        let d = problem.data_len();
        let quads = d.div_ceil(4);
        let columns = super::data_columns(&problem);
        let has_ratio = super::has_ratio(&problem);
        let column_bytes = 16 * quads.max(1) as u64;
        let max_binding = context.limits.max_storage_buffer_binding_size;
        if column_bytes > max_binding {
            return Err(GpuError::TooLarge(format!(
                "{d} data points need {column_bytes} bytes per column, the adapter binds at most {max_binding}"
            )));
        }
        let (chunk, params_chunk) = super::candidates_per_dispatch(d, &context.limits);
        let prior = GpuPrior::new(&problem.prior, problem.seed);
        let copy = wgpu::BufferUsages::COPY_DST;
        let prior_buffer = context.buffer(
            "prior",
            size_of::<GpuPrior>() as u64,
            wgpu::BufferUsages::UNIFORM | copy,
        )?;
        let job = context.buffer(
            "job",
            size_of::<Job>() as u64,
            wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::STORAGE | copy,
        )?;
        let mut data = Vec::new();
        for (name, column) in ["speed", "torque", "ratio"].iter().zip(&columns) {
            let buffer = context.buffer(name, column_bytes, wgpu::BufferUsages::STORAGE | copy)?;
            context.queue.write_buffer(&buffer, 0, bytemuck::cast_slice(column));
            data.push(buffer);
        }
        let ssr_bytes = 4 * chunk as u64;
        let (ssr, staging) = context.output_and_staging("ssr", ssr_bytes)?;
        context.queue.write_buffer(&prior_buffer, 0, bytemuck::bytes_of(&prior));
        let bindings = [
            UNIFORM,
            UNIFORM,
            STORAGE_READ,
            STORAGE_READ,
            STORAGE_READ,
            STORAGE_WRITE,
        ];
        shape.check_fits(context)?;
        let file_laws = crate::laws::file::among(problem.prior.laws());
        let kernel = context.kernel(
            &super::file_laws::label("residual", &file_laws),
            shape.entry_point(),
            || super::residual_source_for(&file_laws),
            &bindings,
            &shape.constants(has_ratio),
        )?;
        let bind_group = context.bind_group(
            "residual",
            &kernel.layout,
            &[&prior_buffer, &job, &data[0], &data[1], &data[2], &ssr],
        )?;
        Ok(Self {
            problem,
            context,
            shape,
            source: Source::Given,
            data_len: d as u32,
            chunk,
            params_chunk,
            resources: Mutex::new(Resources {
                job,
                ssr,
                staging,
                pipeline: kernel.pipeline,
                bind_group,
                data,
                has_ratio,
                params: None,
            }),
            kernel_sums: Default::default(),
        })
    }

    /// The adapter this evaluator runs on.
    pub fn adapter(&self) -> String {
        self.context.describe()
    }

    /// The GPU it runs on.
    pub fn context(&self) -> &'static GpuContext {
        self.context
    }

    /// Whether the adapter is a software driver on the CPU (lavapipe, SwiftShader).
    pub fn is_software(&self) -> bool {
        self.context.is_software()
    }

    /// The scoring shape this evaluator dispatches.
    pub fn shape(&self) -> Shape {
        self.shape
    }

    /// Where the scoring shape came from.
    pub fn shape_source(&self) -> Source {
        self.source
    }

    /// The evaluator, its shape said to come from `source` (the choice of [`super::tune`]).
    pub(super) fn chosen_by(self, source: Source) -> Self {
        Self { source, ..self }
    }

    /// Σ(y − r·T)² (f32, as the kernel returns it) of candidates `start ..` into `out`.
    pub fn sum_sq_residuals(&self, population: u32, start: u64, out: &mut [f32]) -> std::result::Result<(), GpuError> {
        let res = self.resources.lock().expect("GPU resources");
        for (c, chunk) in out.chunks_mut(self.chunk).enumerate() {
            let first = start + (c * self.chunk) as u64;
            self.dispatch_slices(&res, &res.pipeline, &res.bind_group, population, first, chunk)?;
        }
        Ok(())
    }

    /// Runs `pipeline` over `out.len()` candidates from `first` and reads back their SSR.
    fn dispatch_slices(
        &self,
        res: &Resources,
        pipeline: &wgpu::ComputePipeline,
        bind_group: &wgpu::BindGroup,
        population: u32,
        first: u64,
        out: &mut [f32],
    ) -> std::result::Result<(), GpuError> {
        let buffers = ScoringBuffers {
            pipeline,
            bind_group,
            job: &res.job,
            ssr: &res.ssr,
            staging: &res.staging,
        };
        let job = Job::new(population, first, out.len() as u32, 0);
        score_dispatch(self.context, self.shape, &buffers, job, self.data_len, out)
    }

    /// Builds the explicit-parameter pipeline on first use (a rejection run never needs it),
    /// and its lag pass when `lag` asks for it.
    fn params_resources<'a>(
        &self,
        res: &'a mut Resources,
        lag: bool,
    ) -> std::result::Result<&'a ParamsResources, GpuError> {
        // Built already (every call after the first): nothing to set up per dispatch.
        if res.params.as_ref().is_some_and(|p| !lag || p.lag.is_some()) {
            return Ok(res.params.as_ref().expect("checked just above"));
        }
        let bindings = super::STORED_CANDIDATE_BINDINGS;
        let file_laws = crate::laws::file::among(self.problem.prior.laws());
        let label = super::file_laws::label("score_params", &file_laws);
        if res.params.is_none() {
            let ctx = self.context;
            let proposals = ctx.buffer(
                "proposals",
                (self.params_chunk * size_of::<GpuProposal>()) as u64,
                wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            )?;
            let kernel = ctx.kernel(
                &label,
                self.shape.entry_point(),
                || super::score_params_source_for(&file_laws),
                &bindings,
                &self.shape.constants(res.has_ratio),
            )?;
            let bind_group = ctx.bind_group(
                "score_params",
                &kernel.layout,
                &[&proposals, &res.job, &res.data[0], &res.data[1], &res.data[2], &res.ssr],
            )?;
            res.params = Some(ParamsResources {
                proposals,
                pipeline: kernel.pipeline,
                bind_group,
                lag: None,
            });
        }
        let params = res.params.as_mut().expect("just built");
        if lag && params.lag.is_none() {
            let mut constants = self.shape.constants(res.has_ratio);
            constants.push(("LAG", 1.0));
            let kernel = self.context.kernel(
                &label,
                self.shape.entry_point(),
                || super::score_params_source_for(&file_laws),
                &bindings,
                &constants,
            )?;
            let bind_group = self.context.bind_group(
                "score_params lag",
                &kernel.layout,
                &[
                    &params.proposals,
                    &res.job,
                    &res.data[0],
                    &res.data[1],
                    &res.data[2],
                    &res.ssr,
                ],
            )?;
            params.lag = Some((kernel.pipeline, bind_group));
        }
        Ok(res.params.as_ref().expect("just built"))
    }

    /// Σ(y − r·T)² (f32) of explicit candidates into `out`.
    pub fn sum_sq_residuals_of(&self, candidates: &[Candidate], out: &mut [f32]) -> std::result::Result<(), GpuError> {
        self.explicit_sums(candidates, out, None)
    }

    /// Σ(y − r·T)² into `ssr` and the lag-1 sums Σ e_t·e_(t−1) into `lag` (f32) of explicit
    /// candidates, e = y − r·T over consecutive samples of the record (the AR(1) noise model's
    /// statistic): each chunk of candidates uploaded once for both passes.
    pub fn sums_with_lag_of(
        &self,
        candidates: &[Candidate],
        ssr: &mut [f32],
        lag: &mut [f32],
    ) -> std::result::Result<(), GpuError> {
        self.explicit_sums(candidates, ssr, Some(lag))
    }

    /// The squares' sums of explicit candidates into `ssr`, and where `lag` is given their
    /// lag-1 sums into it, from one upload per chunk.
    fn explicit_sums(
        &self,
        candidates: &[Candidate],
        ssr: &mut [f32],
        lag: Option<&mut [f32]>,
    ) -> std::result::Result<(), GpuError> {
        let mut guard = self.resources.lock().expect("GPU resources");
        self.params_resources(&mut guard, lag.is_some())?;
        let res = &*guard;
        let params = res.params.as_ref().expect("built above");
        let mut lag_chunks = lag.map(|l| l.chunks_mut(self.params_chunk));
        for (cands, chunk) in candidates
            .chunks(self.params_chunk)
            .zip(ssr.chunks_mut(self.params_chunk))
        {
            let upload: Vec<GpuProposal> = cands
                .iter()
                .map(|c| GpuProposal::new(self.problem.prior.law(c.slot), c.law_params()))
                .collect();
            self.context
                .queue
                .write_buffer(&params.proposals, 0, bytemuck::cast_slice(&upload));
            self.dispatch_slices(res, &params.pipeline, &params.bind_group, 0, 0, chunk)?;
            if let Some(chunks) = &mut lag_chunks {
                let (pipeline, bind_group) = params.lag.as_ref().expect("built above");
                let out = chunks.next().expect("one lag-1 sum per candidate");
                self.dispatch_slices(res, pipeline, bind_group, 0, 0, out)?;
            }
        }
        Ok(())
    }
}

impl Evaluator for GpuEvaluator {
    fn backend(&self) -> &'static str {
        "gpu"
    }

    fn problem(&self) -> &Problem {
        &self.problem
    }

    fn gpu_shape(&self) -> Option<Shape> {
        Some(self.shape)
    }

    fn score(&self, population: u32, start: u64, out: &mut [f64]) -> Result<()> {
        let mut ssr = vec![0.0f32; out.len()];
        self.sum_sq_residuals(population, start, &mut ssr)?;
        for (rho, s) in out.iter_mut().zip(ssr) {
            *rho = crate::eval::rho_of_sum(f64::from(s), self.problem.sum_sq_torque);
        }
        Ok(())
    }

    fn score_params(&self, candidates: &[Candidate], out: &mut [f64]) -> Result<()> {
        assert_eq!(candidates.len(), out.len(), "one ρ per candidate");
        let mut ssr = vec![0.0f32; out.len()];
        self.sum_sq_residuals_of(candidates, &mut ssr)?;
        for (rho, s) in out.iter_mut().zip(ssr) {
            *rho = crate::eval::rho_of_sum(f64::from(s), self.problem.sum_sq_torque);
        }
        Ok(())
    }

    fn score_params_lagged(&self, candidates: &[Candidate], rho: &mut [f64], lag: &mut [f64]) -> Result<()> {
        assert_eq!(candidates.len(), rho.len(), "one ρ per candidate");
        assert_eq!(candidates.len(), lag.len(), "one lag-1 sum per candidate");
        let (mut ssr, mut lags) = (vec![0.0f32; rho.len()], vec![0.0f32; lag.len()]);
        self.sums_with_lag_of(candidates, &mut ssr, &mut lags)?;
        for (out, sums) in [(rho, ssr), (lag, lags)] {
            for (value, s) in out.iter_mut().zip(sums) {
                *value = crate::eval::rho_of_sum(f64::from(s), self.problem.sum_sq_torque);
            }
        }
        Ok(())
    }

    fn kernel_sums(&self, sums: &KernelSums, out: &mut [f64]) -> Result<()> {
        self.kernel_sums.run(self.context, sums, out)?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_kernels_score_as_many_candidates_per_tile_as_the_host_dispatches_for() {
        let line = format!("const CANDIDATES: u32 = {}u;", super::super::CANDIDATES_PER_TILE);
        assert!(
            include_str!("../../../shaders/shared/ssr.wgsl").contains(&line),
            "shaders/shared/ssr.wgsl lacks `{line}`"
        );
    }
}
