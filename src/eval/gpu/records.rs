//! Many records' candidates in one dispatch (shaders/records.wgsl): the GPU side of
//! [`crate::eval::records`]. The records (of equal length) lie one after another in the data
//! columns and their priors in one array; a dispatch carries segments, one per request (or per
//! piece of a request too large for one dispatch), each starting on a tile of 16 candidates,
//! and for every tile the segment it belongs to. A candidate is scored by the same code, blocks
//! and slices as the single-record kernels use, in the pipeline they use for its record (with
//! or without a varying weight-on-bit ratio: the two are dispatched apart), so its SSR is the
//! one [`super::residual::GpuEvaluator`] gives for its record, bit for bit.

use super::{
    CANDIDATES_PER_TILE, GpuContext, GpuError, GpuPrior, GpuProposal, Job, STORAGE_READ, ScoringBuffers, Shape,
    score_dispatch,
};
use crate::eval::Problem;
use crate::eval::{Candidates, Request};
use crate::prior::Prior;
use bytemuck::{Pod, Zeroable};
use rayon::prelude::*;

/// Segments one dispatch carries at most (a flush of the selection check has one per
/// replicate; more start another dispatch).
const SEGMENTS_PER_DISPATCH: usize = 4096;

/// Host twin of `Segment` in shaders/records.wgsl. Keep in sync.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct GpuSegment {
    record: u32,
    /// 0: regenerated from the record's prior; 1: explicit proposals.
    kind: u32,
    population: u32,
    count: u32,
    start: [u32; 2],
    first: u32,
    quad: u32,
    /// First entry of the segment's stream offsets (kind 0).
    order: u32,
    _pad: u32,
}

/// Scores requests of many records on the GPU, the records' data and priors uploaded once.
pub struct GpuRecords {
    context: &'static GpuContext,
    shape: Shape,
    data_len: u32,
    /// Quads per record in the columns.
    quads: u32,
    /// Prior and seed of each record: the law of every candidate, to sort them by law.
    priors: Vec<(Prior, u64)>,
    /// Candidates (tiles padded) per dispatch at most; explicit ones at most `params_chunk`.
    chunk: usize,
    params_chunk: usize,
    buffers: Bindings,
    staging: wgpu::Buffer,
    /// Whether `buffers.proposals` holds `params_chunk` proposals yet (a placeholder until
    /// the first explicit request: a rejection check never needs it).
    proposals_built: bool,
    /// Whether each record scales by a weight-on-bit ratio that varies (override HAS_RATIO).
    ratio: Vec<bool>,
    /// The pipeline and bind group of records without a varying ratio (`[0]`) and with one
    /// (`[1]`), where there are such records. A record is always scored by the pipeline its
    /// own evaluator uses: a driver may round the two differently (NVIDIA's does, by an ulp),
    /// and a record's sums must not depend on what else shares the batch.
    kernels: [Option<(super::Kernel, wgpu::BindGroup)>; 2],
}

/// The buffers of bindings 0-8 of shaders/records.wgsl, in order.
struct Bindings {
    priors: wgpu::Buffer,
    job: wgpu::Buffer,
    /// Speed, torque and ratio of every record.
    columns: Vec<wgpu::Buffer>,
    ssr: wgpu::Buffer,
    segments: wgpu::Buffer,
    tile_segment: wgpu::Buffer,
    proposals: wgpu::Buffer,
    offsets: wgpu::Buffer,
}

impl Bindings {
    fn group(&self, ctx: &GpuContext, kernel: &super::Kernel) -> Result<wgpu::BindGroup, GpuError> {
        let c = &self.columns;
        ctx.bind_group(
            "records",
            &kernel.layout,
            &[
                &self.priors,
                &self.job,
                &c[0],
                &c[1],
                &c[2],
                &self.ssr,
                &self.segments,
                &self.tile_segment,
                &self.proposals,
                &self.offsets,
            ],
        )
    }
}

/// One dispatch being planned: its segments, tile map, proposals, and where each segment's
/// sums go (request, offset in it).
#[derive(Default)]
struct Plan {
    segments: Vec<GpuSegment>,
    tile_segment: Vec<u32>,
    proposals: Vec<GpuProposal>,
    offsets: Vec<u32>,
    /// (request, first of its candidates in law order, count, first candidate in the
    /// dispatch).
    pieces: Vec<(usize, usize, usize, usize)>,
    /// Candidates of the dispatch, tiles padded.
    padded: usize,
}

impl GpuRecords {
    /// Uploads `problems` (records of equal length; record i is `problems[i]`) on the process's
    /// GPU for scoring in `shape`, at most `max_candidates` per dispatch (`None`: as many as
    /// the single-record evaluator dispatches; tests set fewer to split requests).
    pub fn new(problems: &[&Problem], shape: Shape, max_candidates: Option<usize>) -> Result<Self, GpuError> {
        let context = super::context()?;
        let d = problems.first().map_or(0, |p| p.data_len());
        assert!(
            problems.iter().all(|p| p.data_len() == d),
            "records scored together have equal lengths"
        );
        let quads = d.div_ceil(4);
        let records = problems.len().max(1);
        let max_binding = context.limits.max_storage_buffer_binding_size;
        let column_bytes = (16 * quads.max(1) * records) as u64;
        if column_bytes > max_binding {
            return Err(GpuError::TooLarge(format!(
                "{records} records of {d} data points need {column_bytes} bytes per column, the adapter binds at most {max_binding}"
            )));
        }
        // As GpuEvaluator's limits, in whole tiles.
        let tile = CANDIDATES_PER_TILE as usize;
        let (chunk, params_chunk) = super::candidates_per_dispatch(d, &context.limits);
        let chunk = (chunk.min(max_candidates.unwrap_or(usize::MAX)) / tile).max(1) * tile;
        let params_chunk = params_chunk.min(chunk);
        let ratio: Vec<bool> = problems.iter().map(|p| super::has_ratio(p)).collect();
        let copy = wgpu::BufferUsages::COPY_DST;
        let storage = wgpu::BufferUsages::STORAGE | copy;
        let mut columns = Vec::new();
        for name in ["speed", "torque", "ratio"] {
            columns.push(context.buffer(name, column_bytes, storage)?);
        }
        for (i, p) in problems.iter().enumerate() {
            for (buffer, column) in columns.iter().zip(super::data_columns(p)) {
                context
                    .queue
                    .write_buffer(buffer, (16 * quads * i) as u64, bytemuck::cast_slice(&column));
            }
        }
        let priors_upload: Vec<GpuPrior> = problems.iter().map(|p| GpuPrior::new(&p.prior, p.seed)).collect();
        let file_laws = crate::laws::file::among(problems.iter().flat_map(|p| p.prior.laws()));
        let priors = context.buffer("priors", (size_of::<GpuPrior>() * records) as u64, storage)?;
        context
            .queue
            .write_buffer(&priors, 0, bytemuck::cast_slice(&priors_upload));
        let job = context.buffer("job", size_of::<Job>() as u64, wgpu::BufferUsages::STORAGE | copy)?;
        let ssr_bytes = 4 * chunk as u64;
        let (ssr, staging) = context.output_and_staging("ssr", ssr_bytes)?;
        let segments = context.buffer(
            "segments",
            (size_of::<GpuSegment>() * SEGMENTS_PER_DISPATCH) as u64,
            storage,
        )?;
        let tile_segment = context.buffer("tile segments", 4 * (chunk / tile) as u64, storage)?;
        // Then the segments, the tiles' segments, the proposals and the offsets.
        let bindings: Vec<_> = super::STORED_CANDIDATE_BINDINGS
            .into_iter()
            .chain([STORAGE_READ; 4])
            .collect();
        shape.check_fits(context)?;
        let buffers = Bindings {
            priors,
            job,
            columns,
            ssr,
            segments,
            tile_segment,
            proposals: context.buffer("no proposals", size_of::<GpuProposal>() as u64, storage)?,
            offsets: context.buffer("offsets", 4 * chunk as u64, storage)?,
        };
        let mut kernels = [None, None];
        for (class, slot) in kernels.iter_mut().enumerate() {
            if ratio.iter().any(|&r| usize::from(r) == class) {
                let kernel = context.kernel(
                    &super::file_laws::label("records", &file_laws),
                    shape.entry_point(),
                    || super::records_source_for(&file_laws),
                    &bindings,
                    &shape.constants(class == 1),
                )?;
                let group = buffers.group(context, &kernel)?;
                *slot = Some((kernel, group));
            }
        }
        Ok(Self {
            context,
            shape,
            data_len: d as u32,
            quads: quads as u32,
            priors: problems.iter().map(|p| (p.prior.clone(), p.seed)).collect(),
            chunk,
            params_chunk,
            buffers,
            staging,
            proposals_built: false,
            ratio,
            kernels,
        })
    }

    /// Records uploaded.
    pub fn records(&self) -> usize {
        self.priors.len()
    }

    /// Σ(y − r·T)² (f32, as the kernel returns it) of every request's candidates, one vector
    /// per request, in as few dispatches as the limits allow. Returns the dispatches made.
    pub fn sum_sq_residuals(&mut self, requests: &[Request]) -> Result<(Vec<Vec<f32>>, usize), GpuError> {
        if !self.proposals_built && requests.iter().any(|r| matches!(r.candidates, Candidates::Explicit(_))) {
            self.buffers.proposals = self.context.buffer(
                "proposals",
                (self.params_chunk * size_of::<GpuProposal>()) as u64,
                wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            )?;
            for (kernel, group) in self.kernels.iter_mut().flatten() {
                *group = self.buffers.group(self.context, kernel)?;
            }
            self.proposals_built = true;
        }
        let mut out: Vec<Vec<f32>> = requests.iter().map(|r| vec![0.0; r.candidates.len()]).collect();
        let orders: Vec<Vec<u32>> = requests.iter().map(|r| self.law_order(r)).collect();
        let mut dispatches = 0;
        // Records with and without a varying ratio go to their own pipelines, one after the other.
        for class in [false, true] {
            let of_class: Vec<usize> = (0..requests.len())
                .filter(|&i| self.ratio[requests[i].record] == class)
                .collect();
            if !of_class.is_empty() {
                dispatches += self.score_class(usize::from(class), requests, &of_class, &orders, &mut out)?;
            }
        }
        Ok((out, dispatches))
    }

    /// Scores the requests `of_class` (indices into `requests`), all of records of ratio class
    /// `class`, into `out`; returns the dispatches made.
    fn score_class(
        &self,
        class: usize,
        requests: &[Request],
        of_class: &[usize],
        orders: &[Vec<u32>],
        out: &mut [Vec<f32>],
    ) -> Result<usize, GpuError> {
        let tile = CANDIDATES_PER_TILE as usize;
        let mut plan = Plan::default();
        let mut dispatches = 0;
        for &index in of_class {
            let request = &requests[index];
            let len = request.candidates.len();
            let explicit = matches!(request.candidates, Candidates::Explicit(_));
            let order = &orders[index];
            let mut done = 0;
            while done < len {
                let room = self.chunk - plan.padded;
                let proposal_room = if explicit {
                    self.params_chunk - plan.proposals.len()
                } else {
                    usize::MAX
                };
                if room < tile || proposal_room == 0 || plan.segments.len() == SEGMENTS_PER_DISPATCH {
                    self.run(class, &plan, orders, out)?;
                    dispatches += 1;
                    plan = Plan::default();
                    continue;
                }
                let take = (len - done).min(room).min(proposal_room);
                let first = plan.padded;
                let piece = &order[done..done + take];
                let (kind, population, start) = match &request.candidates {
                    Candidates::Stream { population, start, .. } => {
                        plan.offsets.extend_from_slice(piece);
                        (0, *population, *start)
                    }
                    Candidates::Explicit(candidates) => {
                        let prior = &self.priors[request.record].0;
                        plan.proposals.extend(piece.iter().map(|&o| {
                            let c = &candidates[o as usize];
                            GpuProposal::new(prior.law(c.slot), c.law_params())
                        }));
                        (1, 0, (plan.proposals.len() - take) as u64)
                    }
                };
                plan.tile_segment
                    .extend(std::iter::repeat_n(plan.segments.len() as u32, take.div_ceil(tile)));
                plan.segments.push(GpuSegment {
                    record: request.record as u32,
                    kind,
                    population,
                    count: take as u32,
                    start: [start as u32, (start >> 32) as u32],
                    first: first as u32,
                    quad: request.record as u32 * self.quads,
                    order: (plan.offsets.len() - if kind == 0 { take } else { 0 }) as u32,
                    _pad: 0,
                });
                plan.pieces.push((index, done, take, first));
                plan.padded += take.div_ceil(tile) * tile;
                done += take;
            }
        }
        if !plan.segments.is_empty() {
            self.run(class, &plan, orders, out)?;
            dispatches += 1;
        }
        Ok(dispatches)
    }

    /// The request's candidates (offsets from its first) in law order, stable: scored in this
    /// order, the tiles of 16 mostly hold one law. A stream candidate's law is read from the
    /// first Philox block, as the kernel draws it.
    fn law_order(&self, request: &Request) -> Vec<u32> {
        let (prior, seed) = &self.priors[request.record];
        let laws: Vec<usize> = match &request.candidates {
            Candidates::Stream { population, start, len } => (0..*len as u64)
                .into_par_iter()
                .map(|o| prior.law(prior.candidate_slot(*seed, *population, start + o)).index())
                .collect(),
            Candidates::Explicit(c) => c.iter().map(|c| prior.law(c.slot).index()).collect(),
        };
        // A stable sort by law id: the candidates of each law in their own order.
        let mut order: Vec<u32> = (0..laws.len() as u32).collect();
        order.sort_by_key(|&o| laws[o as usize]);
        order
    }

    /// One dispatch of `plan` with the pipeline of ratio class `class`, its sums put back in
    /// the requests' own order.
    fn run(&self, class: usize, plan: &Plan, orders: &[Vec<u32>], out: &mut [Vec<f32>]) -> Result<(), GpuError> {
        let (kernel, bind_group) = self.kernels[class]
            .as_ref()
            .expect("a pipeline for every class present");
        let queue = &self.context.queue;
        let b = &self.buffers;
        queue.write_buffer(&b.segments, 0, bytemuck::cast_slice(&plan.segments));
        queue.write_buffer(&b.tile_segment, 0, bytemuck::cast_slice(&plan.tile_segment));
        if !plan.proposals.is_empty() {
            queue.write_buffer(&b.proposals, 0, bytemuck::cast_slice(&plan.proposals));
        }
        if !plan.offsets.is_empty() {
            queue.write_buffer(&b.offsets, 0, bytemuck::cast_slice(&plan.offsets));
        }
        let buffers = ScoringBuffers {
            pipeline: &kernel.pipeline,
            bind_group,
            job: &b.job,
            ssr: &b.ssr,
            staging: &self.staging,
        };
        let mut ssr = vec![0.0f32; plan.padded];
        let job = Job::new(0, 0, plan.padded as u32, 0);
        score_dispatch(self.context, self.shape, &buffers, job, self.data_len, &mut ssr)?;
        for &(request, from, count, first) in &plan.pieces {
            for (&o, &v) in orders[request][from..from + count]
                .iter()
                .zip(&ssr[first..first + count])
            {
                out[request][o as usize] = v;
            }
        }
        Ok(())
    }
}
