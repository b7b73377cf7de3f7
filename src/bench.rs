//! `bitrock bench` and `bitrock parity`: what a user runs on new hardware to know how fast
//! bitrock is there and whether to trust its GPU.

use crate::Law;
use crate::abc::rejection::{self, RejectionConfig};
use crate::abc::schedule::Schedule;
use crate::abc::smc::{self, SmcConfig};
use crate::data::{DataOptions, FieldData, Samples, demo_field_data};
use crate::error::{Error, Result};
use crate::eval::gpu::candidates::GpuCandidate;
use crate::eval::{Backend, Evaluator, PARITY_TOLERANCE, Problem, cpu::CpuEvaluator, evaluator, gpu};
use crate::fit::{FitOptions, LawFit, fit_record};
use crate::numerics::quantile;
use crate::prior::{LawBox, Prior};
use serde::Serialize;
use std::time::Instant;

pub mod coupled;
pub mod simulators;
pub mod smc_comparison;
pub mod strings;
pub mod surface;

/// Median, min and max of repeated measurements.
#[derive(Clone, Debug, Serialize)]
pub struct Spread {
    pub median: f64,
    pub min: f64,
    pub max: f64,
}

impl Spread {
    fn of(values: &[f64]) -> Self {
        Spread {
            median: quantile(values, 0.5),
            min: values.iter().copied().fold(f64::INFINITY, f64::min),
            max: values.iter().copied().fold(f64::NEG_INFINITY, f64::max),
        }
    }
}

/// How fast one backend simulated a batch of strings: the part every simulator bench shares.
#[derive(Clone, Debug, Serialize)]
pub struct SimulatedThroughput {
    pub backend: String,
    pub strings: usize,
    pub seconds_per_string: f64,
    /// Wall seconds, median and range over the repetitions.
    pub wall_s: Spread,
    /// String-seconds simulated per wall second (median).
    pub string_seconds_per_s: f64,
}

impl SimulatedThroughput {
    /// `strings` strings of `seconds_per_string` simulated s each, in `walls` wall seconds per
    /// repetition.
    fn of(backend: String, strings: usize, seconds_per_string: f64, walls: &[f64]) -> Self {
        let wall_s = Spread::of(walls);
        SimulatedThroughput {
            backend,
            strings,
            seconds_per_string,
            string_seconds_per_s: strings as f64 * seconds_per_string / wall_s.median,
            wall_s,
        }
    }
}

impl std::fmt::Display for SimulatedThroughput {
    /// The table's cells: backend, strings × seconds, the median wall time (min–max), the rate;
    /// `{:#}` the same unpadded, for a progress line.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if f.alternate() {
            return write!(
                f,
                "{}: {} × {} s in {:.3} s: {:.3e} string-s/s",
                self.backend, self.strings, self.seconds_per_string, self.wall_s.median, self.string_seconds_per_s
            );
        }
        write!(
            f,
            "{:<40} {:>8} strings × {:>5.1} s  {:>8.3} s ({:.3}–{:.3})  {:.3e} string-s/s",
            self.backend,
            self.strings,
            self.seconds_per_string,
            self.wall_s.median,
            self.wall_s.min,
            self.wall_s.max,
            self.string_seconds_per_s
        )
    }
}

/// Throughput of one backend and law at one size.
#[derive(Clone, Debug, Serialize)]
pub struct Throughput {
    pub backend: &'static str,
    pub law: Law,
    /// Candidates per call.
    pub n: usize,
    /// Data points.
    pub d: usize,
    /// The GPU scoring shape (the tuning's fastest at N); none on the CPU.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub shape: Option<gpu::Shape>,
    /// Candidate × data-point evaluations per second (median).
    pub evals_per_s: f64,
    /// The same, min and max over the repetitions.
    pub evals_per_s_spread: Spread,
}

/// A paper-scale run, end to end.
#[derive(Clone, Debug, Serialize)]
pub struct EndToEnd {
    pub backend: &'static str,
    /// Wall time of the sampler (median over repetitions), s.
    pub seconds: f64,
    pub seconds_spread: Spread,
    pub evaluations: u64,
    /// Candidate × data-point evaluations per second of the whole run (median seconds).
    pub evals_per_s: f64,
    pub populations: usize,
}

/// One sampler run to eps_min on the embedded record: the evaluations it needed.
#[derive(Clone, Debug, Serialize)]
pub struct SamplerRun {
    /// `rejection` (nested mode) or `smc`.
    pub sampler: &'static str,
    pub backend: &'static str,
    pub particles: usize,
    pub eps_min: f64,
    /// Candidate × data-point evaluations to reach eps_min.
    pub evaluations: u64,
    /// Wall time (median over up to 3 repetitions), s.
    pub seconds: f64,
    pub populations: usize,
    pub final_epsilon: Option<f64>,
}

/// Everything `bitrock bench` measures.
#[derive(Clone, Debug, Serialize)]
pub struct BenchReport {
    pub machine: String,
    pub cores: usize,
    /// The GPU adapter and driver, or why there is none.
    pub adapter: String,
    /// The GPU scoring shape of runs at the bench's default size (65,536 candidates per
    /// dispatch): measured, or `BITROCK_GPU_SHAPE`'s; none without a GPU.
    pub shape: Option<gpu::Shape>,
    /// The adapter's table of scoring shapes (see [`gpu::tune`]); none without a GPU, or where
    /// `BITROCK_GPU_SHAPE` names the shape or measuring is off.
    pub tuning: Option<TuningReport>,
    pub repetitions: usize,
    pub throughput: Vec<Throughput>,
    /// Time of one small call (64 candidates, 100 points), s: the fixed cost of a dispatch.
    pub small_call_seconds: Vec<(String, Spread)>,
    pub end_to_end: Vec<EndToEnd>,
    /// Rejection and SMC to the same eps_min with the same N on the embedded record: the
    /// paper's ε_min with the end-to-end N, and 1.1 × the smallest least-squares ρ with
    /// [`BenchOptions::floor_particles`].
    pub samplers: Vec<SamplerRun>,
    /// Stability grid on the GPU: cells × samples per second (median), with the grid size.
    pub stability: Option<StabilityThroughput>,
    /// `bitrock check-selection` of a run of each of [`SelectionRecord::ALL`] (measured with
    /// `--selection` only).
    pub selection: Vec<SelectionBench>,
    /// The SMC schemes against rejection near the noise floor (measured with `--smc` only).
    pub smc: Vec<smc_comparison::SmcComparison>,
}

/// The adapter's table of scoring shapes, as the bench found it.
#[derive(Clone, Debug, Serialize)]
pub struct TuningReport {
    /// `cached` (an earlier measurement) or `measured` (now).
    pub source: &'static str,
    /// The cache file it is kept in; none where it could not be kept.
    pub cache_file: Option<std::path::PathBuf>,
    #[serde(flatten)]
    pub tuning: gpu::tune::Tuning,
}

/// `bitrock check-selection` of a run of one record: every law, K replicates each.
#[derive(Clone, Debug, Serialize)]
pub struct SelectionBench {
    pub record: SelectionRecord,
    /// The `bitrock simulate` command that makes the record (none for the embedded one).
    pub command: Option<&'static str>,
    /// Calibration samples of the record (each replicate's fits and runs see as many).
    pub calibration_samples: usize,
    /// Backend asked for, and the one that scored the candidates (`cpu`, `gpu`).
    pub backend_asked: Backend,
    pub backend: String,
    pub laws: usize,
    pub replicates_per_law: usize,
    /// Particles per population of the run and of every replicate.
    pub particles: usize,
    /// The run's last ε (the record's floor as `bitrock abc` sets it, where the run reached it).
    pub eps_min: f64,
    /// Wall time of the check (median over the repetitions), s.
    pub seconds: f64,
    pub seconds_spread: Spread,
    /// Replicates per second at the median.
    pub replicates_per_s: f64,
    /// The check's two phases (median over the repetitions), s: the synthetic records with
    /// their least-squares fits, and the samplers.
    pub fit_seconds: f64,
    /// The fits' share of the check's wall time.
    pub fit_share: f64,
    pub sampling_seconds: f64,
    /// How the fits' Levenberg-Marquardt runs ended (the same every repetition).
    pub fits: crate::run::selection::FitCounts,
    /// Of the sampling, the time spent scoring the replicates' batched requests (median), s.
    pub scoring_seconds: f64,
    /// Batches the replicates' requests were scored in, and GPU dispatches (the same every
    /// repetition).
    pub batches: u64,
    pub dispatches: u64,
    /// Candidate × data-point evaluations of all replicates (the same every repetition).
    pub evaluations: u64,
    pub repetitions: usize,
}

/// Throughput of the stability kernel.
#[derive(Clone, Debug, Serialize)]
pub struct StabilityThroughput {
    pub cells: usize,
    pub samples: usize,
    pub cell_samples_per_s: f64,
    pub cell_samples_per_s_spread: Spread,
}

/// What to measure.
#[derive(Clone, Debug)]
pub struct BenchOptions {
    pub repetitions: usize,
    pub laws: Vec<Law>,
    pub backends: Vec<Backend>,
    /// (candidates, data points) pairs.
    pub sizes: Vec<(usize, usize)>,
    /// Particles of the end-to-end run (the paper's 25,000).
    pub particles: usize,
    /// Particles of the samplers' comparison near the noise floor, where rejection from the
    /// prior accepts about one candidate in a thousand (5,000).
    pub floor_particles: usize,
    /// Stability grid (side, samples): 512 × 512 cells × 10,000 samples.
    pub stability: (usize, usize),
    /// Measure only `bitrock check-selection` ([`selection_checks`]) with (replicates per law,
    /// N), instead of the other sections: (20, [`SELECTION_PARTICLES`]) by default.
    pub selection: Option<(usize, usize)>,
    /// Measure the GPU scoring shapes again (and keep the new table) even where a table is
    /// cached.
    pub retune: bool,
    /// Measure only the SMC schemes against rejection ([`smc_comparison::compare`]) on these
    /// records, with (N, seeds), instead of the other sections.
    pub smc: Option<(Vec<SelectionRecord>, usize, u64)>,
}

impl Default for BenchOptions {
    fn default() -> Self {
        Self {
            repetitions: 5,
            laws: Law::ALL.to_vec(),
            backends: vec![Backend::Cpu, Backend::Gpu],
            // The last: the paper's N and the embedded record's length, the size users run.
            sizes: vec![(65_536, 5_000), (1_048_576, 5_000), (65_536, 100_000), (25_000, 2_687)],
            particles: 25_000,
            floor_particles: 5_000,
            stability: (512, 10_000),
            selection: None,
            retune: false,
            smc: None,
        }
    }
}

/// A single-law problem: `d` samples of the law at the paper's estimate (N·m) with a
/// deterministic ±5 % ripple, speeds 0.5-20 rad/s, and the paper's ±40 % prior box.
/// Panics for a law file's law without reference values.
pub fn synthetic_problem(law: Law, d: usize, seed: u64) -> Problem {
    let estimate = law.paper_estimate().expect("a law with reference values");
    let truth = law.scale_torque(estimate, 1000.0);
    let speed: Vec<f64> = (0..d)
        .map(|i| 0.5 + 19.5 * i as f64 / d.max(2).saturating_sub(1) as f64)
        .collect();
    let torque = speed
        .iter()
        .enumerate()
        .map(|(i, &w)| law.torque(&truth, w, 1.0) * (1.0 + 0.05 * ((i * 7919 % 101) as f64 / 50.0 - 1.0)))
        .collect();
    let data = Samples::new(speed, torque);
    let (lower, upper) = truth
        .iter()
        .map(|&p| ((p * 0.6).min(p * 1.4) as f32, (p * 0.6).max(p * 1.4) as f32))
        .unzip();
    let prior = Prior::new(vec![LawBox::new(law, lower, upper)], vec![1.0]).expect("one positive weight");
    Problem::new(prior, seed, &data, None)
}

/// The CPU model, from /proc/cpuinfo where there is one.
fn machine() -> String {
    std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("model name"))
                .map(|l| l.split(':').nth(1).unwrap_or("").trim().to_string())
        })
        .unwrap_or_else(|| std::env::consts::ARCH.to_string())
}

/// Times `f` `reps` times after one warm-up call; seconds per call.
fn time_calls(reps: usize, mut f: impl FnMut() -> Result<()>) -> Result<Vec<f64>> {
    f()?;
    (0..reps)
        .map(|_| {
            let t = Instant::now();
            f()?;
            Ok(t.elapsed().as_secs_f64())
        })
        .collect()
}

/// Runs the benchmark, reporting progress lines through `log`: with
/// [`BenchOptions::selection`] only the selection check ([`selection_checks`]),
/// else each other section in turn: evaluator throughput, the small call, the paper-scale run
/// end to end, rejection against SMC, and the GPU stability grid.
pub fn run(opts: &BenchOptions, log: &mut dyn FnMut(String)) -> Result<BenchReport> {
    // Synthetic records are made from each law's reference values: refused before any work.
    if let Some(law) = opts.laws.iter().find(|l| l.paper_estimate().is_none()) {
        return Err(Error::setting(
            "laws",
            format!(
                "law {law} has no reference values, which the benchmark's synthetic records are made from: give every parameter of its law file a `reference`"
            ),
        ));
    }
    let embedded = EmbeddedRecord::fitted()?;
    let (adapter, shape, tuning) = gpu_adapter(&embedded.problem(), opts.retune, log)?;
    let reps = opts.repetitions.max(1);
    let report = BenchReport {
        machine: machine(),
        cores: std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1),
        adapter,
        shape,
        tuning,
        repetitions: reps,
        throughput: Vec::new(),
        small_call_seconds: Vec::new(),
        end_to_end: Vec::new(),
        samplers: Vec::new(),
        stability: None,
        selection: Vec::new(),
        smc: Vec::new(),
    };
    if let Some((records, particles, seeds)) = &opts.smc {
        return Ok(BenchReport {
            smc: smc_comparison::compare(records, *particles, *seeds, log)?,
            ..report
        });
    }
    if let Some((k, particles)) = opts.selection {
        let backend = match opts.backends.as_slice() {
            [only] => *only,
            _ => Backend::Auto,
        };
        return Ok(BenchReport {
            selection: selection_checks(&SelectionRecord::ALL, k, particles, backend, reps.min(3), log)?,
            ..report
        });
    }
    let throughput = measure_throughput(opts, reps, log)?;
    let small_call_seconds = measure_small_calls(&opts.backends, reps, log)?;
    let config = RejectionConfig::from(Schedule {
        particles: opts.particles,
        ..Schedule::default()
    });
    let end_to_end = measure_end_to_end(&opts.backends, reps, &embedded, &config, log)?;
    let samplers = compare_samplers(opts, reps, &embedded, config.schedule.eps_min, log)?;
    let stability = if opts.backends.contains(&Backend::Gpu) {
        Some(measure_stability(opts.stability, reps, log)?)
    } else {
        None
    };
    Ok(BenchReport {
        stability,
        throughput,
        small_call_seconds,
        end_to_end,
        samplers,
        ..report
    })
}

/// The GPU adapter's description, the scoring shape of the default size and the adapter's
/// table of shapes (measured on `problem` where none is cached, or with `retune`), logged; or
/// why there is no GPU, and no shape.
fn gpu_adapter(
    problem: &Problem,
    retune: bool,
    log: &mut dyn FnMut(String),
) -> Result<(String, Option<gpu::Shape>, Option<TuningReport>)> {
    use gpu::tune;
    let ctx = match gpu::context() {
        Ok(ctx) => ctx,
        Err(e) => return Ok((format!("none ({e})"), None, None)),
    };
    let adapter = ctx.describe();
    let wish = tune::ShapeWish::default();
    // Measured again first, so that the choice below reads the new table.
    let retuned = if retune && gpu::Shape::from_env(ctx)?.is_none() && tune::tuning_on()? {
        Some(tune::retune(ctx, problem)?)
    } else {
        None
    };
    let choice = tune::choose(ctx, problem, wish)?;
    let tuning = match (retuned, choice.source) {
        (Some((tuning, source)), _) => Some((source, tuning)),
        (None, tune::Source::Named | tune::Source::Guessed) => None,
        (None, source) => Some((source, tune::tuning(ctx, problem)?.0)),
    };
    log(format!("GPU: {adapter}, {} scoring ({})", choice.shape, choice.source));
    let report = tuning.map(|(source, tuning)| TuningReport {
        source: match source {
            tune::Source::Cached => "cached",
            _ => "measured",
        },
        cache_file: (source != tune::Source::MeasuredNotKept)
            .then(tune::cache_path)
            .flatten(),
        tuning,
    });
    Ok((adapter, Some(choice.shape), report))
}

/// Evaluator throughput of every backend, size and law, on [`synthetic_problem`]s: one call
/// scoring N candidates against D points, timed `reps` times.
fn measure_throughput(opts: &BenchOptions, reps: usize, log: &mut dyn FnMut(String)) -> Result<Vec<Throughput>> {
    let mut throughput = Vec::new();
    for &backend in &opts.backends {
        for &(n, d) in &opts.sizes {
            for &law in &opts.laws {
                let wish = gpu::tune::ShapeWish {
                    candidates: n,
                    ..Default::default()
                };
                let ev = evaluator(synthetic_problem(law, d, 1), backend, wish, &mut |_| {})?;
                let mut rho = vec![0.0; n];
                let times = time_calls(reps, || ev.score(0, 0, &mut rho))?;
                let rates: Vec<f64> = times.iter().map(|t| (n * d) as f64 / t).collect();
                let spread = Spread::of(&rates);
                log(format!(
                    "{:>3} {law} N = {n:>9} D = {d:>7}: {:.3e} evaluations/s",
                    ev.backend(),
                    spread.median
                ));
                throughput.push(Throughput {
                    backend: ev.backend(),
                    law,
                    n,
                    d,
                    shape: ev.gpu_shape(),
                    evals_per_s: spread.median,
                    evals_per_s_spread: spread,
                });
            }
        }
    }
    Ok(throughput)
}

/// The fixed cost of a call on each backend: 64 candidates against 100 points, timed at least
/// 20 times; seconds per call, by backend.
fn measure_small_calls(
    backends: &[Backend],
    reps: usize,
    log: &mut dyn FnMut(String),
) -> Result<Vec<(String, Spread)>> {
    let mut small_call_seconds = Vec::new();
    for &backend in backends {
        let ev = evaluator(
            synthetic_problem(Law::M2, 100, 1),
            backend,
            Default::default(),
            &mut |_| {},
        )?;
        let mut rho = vec![0.0; 64];
        let times = time_calls(reps.max(20), || ev.score(0, 0, &mut rho))?;
        let spread = Spread::of(&times);
        log(format!(
            "{:>3} small call (64 candidates, 100 points): {:.3e} s",
            ev.backend(),
            spread.median
        ));
        small_call_seconds.push((ev.backend().to_string(), spread));
    }
    Ok(small_call_seconds)
}

/// The embedded record with every law's least-squares fit and the prior built on them: what
/// the paper-scale runs and the sampler comparison sample.
struct EmbeddedRecord {
    data: FieldData,
    fits: Vec<LawFit>,
    prior: Prior,
}

impl EmbeddedRecord {
    /// Reads and fits the embedded record with default options; the prior is the fits' ±40 %
    /// box.
    fn fitted() -> Result<Self> {
        let data = demo_field_data(&DataOptions::default())?;
        let fits = fit_record(&Law::ALL, &data, &FitOptions::default())?;
        let prior = Prior::from_fits(&fits, 0.4, None, 1000.0)?;
        Ok(Self { data, fits, prior })
    }

    /// The record's calibration samples under the prior, seed 1.
    fn problem(&self) -> Problem {
        Problem::new(self.prior.clone(), 1, &self.data.calibration, None)
    }

    /// An evaluator of [`Self::problem`] on `backend`, for a run of `particles`.
    fn evaluator(&self, backend: Backend, particles: usize) -> Result<Box<dyn Evaluator>> {
        let wish = gpu::tune::ShapeWish::for_run(None, particles);
        evaluator(self.problem(), backend, wish, &mut |_| {})
    }
}

/// A rejection run on the embedded record to `config`'s ε_min with its N, on each backend,
/// timed `reps` times.
fn measure_end_to_end(
    backends: &[Backend],
    reps: usize,
    embedded: &EmbeddedRecord,
    config: &RejectionConfig,
    log: &mut dyn FnMut(String),
) -> Result<Vec<EndToEnd>> {
    let mut end_to_end = Vec::new();
    for &backend in backends {
        let ev = embedded.evaluator(backend, config.schedule.particles)?;
        let mut last = None;
        let times = time_calls(reps, || {
            last = Some(rejection::run(ev.as_ref(), config)?);
            Ok(())
        })?;
        let run = last.expect("at least one run");
        let spread = Spread::of(&times);
        let evals_per_s = run.evaluations as f64 / spread.median;
        log(format!(
            "{:>3} paper-scale run (N = {}, four laws, embedded record, to ε = {}): {:.3} s, {:.3e} evaluations, {evals_per_s:.3e} evaluations/s",
            ev.backend(),
            config.schedule.particles,
            config.schedule.eps_min,
            spread.median,
            run.evaluations as f64
        ));
        end_to_end.push(EndToEnd {
            backend: ev.backend(),
            seconds: spread.median,
            seconds_spread: spread,
            evaluations: run.evaluations,
            evals_per_s,
            populations: run.populations.len(),
        });
    }
    Ok(end_to_end)
}

/// Rejection and SMC to the same ε_min with the same N on each backend: at the paper's ε_min
/// (`paper_eps_min`) with the end-to-end N, and near the noise floor (1.1 × the smallest
/// least-squares ρ) with [`BenchOptions::floor_particles`].
fn compare_samplers(
    opts: &BenchOptions,
    reps: usize,
    embedded: &EmbeddedRecord,
    paper_eps_min: f64,
    log: &mut dyn FnMut(String),
) -> Result<Vec<SamplerRun>> {
    let mut samplers = Vec::new();
    let floor = embedded.fits.iter().map(|f| f.rho).fold(f64::INFINITY, f64::min);
    let targets = [(paper_eps_min, opts.particles), (1.1 * floor, opts.floor_particles)];
    for &backend in &opts.backends {
        let ev = embedded.evaluator(backend, opts.particles)?;
        for &(eps_min, particles) in &targets {
            let smc_config = SmcConfig {
                schedule: Schedule {
                    particles,
                    eps_min,
                    ..Schedule::default()
                },
                ..SmcConfig::default()
            };
            for sampler in ["rejection", "smc"] {
                samplers.push(time_sampler(ev.as_ref(), sampler, &smc_config, reps, log)?);
            }
        }
    }
    Ok(samplers)
}

/// One sampler (`rejection` or `smc`) run to `smc_config`'s ε_min with its N (rejection runs
/// its schedule), timed up to 3 times; the evaluations and populations of the last
/// run.
fn time_sampler(
    ev: &dyn Evaluator,
    sampler: &'static str,
    smc_config: &SmcConfig,
    reps: usize,
    log: &mut dyn FnMut(String),
) -> Result<SamplerRun> {
    let schedule = &smc_config.schedule;
    let (eps_min, particles) = (schedule.eps_min, schedule.particles);
    let rejection_config = RejectionConfig::from(schedule.clone());
    let mut last = None;
    let times = time_calls(reps.min(3), || {
        last = Some(match sampler {
            "rejection" => rejection::run(ev, &rejection_config)?,
            _ => smc::run(ev, smc_config)?,
        });
        Ok(())
    })?;
    let run = last.expect("at least one run");
    let seconds = Spread::of(&times).median;
    log(format!(
        "{:>3} {sampler:>9} to ε = {eps_min:.5} (N = {particles}): {:.3e} evaluations, {} populations, {seconds:.3} s",
        ev.backend(),
        run.evaluations as f64,
        run.populations.len(),
    ));
    Ok(SamplerRun {
        sampler,
        backend: ev.backend(),
        particles,
        eps_min,
        evaluations: run.evaluations,
        seconds,
        populations: run.populations.len(),
        final_epsilon: run.populations.last().and_then(|p| p.record.epsilon),
    })
}

/// Throughput of the GPU stability grid: m3 at the paper's estimate, `count` samples scaled
/// 0.8-1.2 of it, on a `side` × `side` grid of speed and weight on bit, timed `reps` times.
fn measure_stability(
    (side, count): (usize, usize),
    reps: usize,
    log: &mut dyn FnMut(String),
) -> Result<StabilityThroughput> {
    let omega: Vec<f64> = (0..side).map(|i| 20.0 + 200.0 * i as f64 / side as f64).collect();
    let wob: Vec<f64> = (0..side).map(|i| 20.0 + 600.0 * i as f64 / side as f64).collect();
    let base = Law::M3.scale_torque(Law::M3.paper_estimate().expect("a built-in law"), 1000.0);
    let samples: Vec<Vec<f64>> = (0..count)
        .map(|s| {
            base.iter()
                .map(|&p| p * (0.8 + 0.4 * (s as f64 + 0.5) / count as f64))
                .collect()
        })
        .collect();
    let criterion = crate::stability::map::Criterion::Lumped(crate::stability::lumped::Lumped::default());
    let times = time_calls(reps, || {
        gpu::stability::stability_grid(&crate::stability::map::Grid {
            law: Law::M3,
            samples: &samples,
            omega_rpm: &omega,
            wob_kn: &wob,
            criterion,
            w_ref_n: 244.2e3,
        })?;
        Ok(())
    })?;
    let rates: Vec<f64> = times.iter().map(|t| (side * side * count) as f64 / t).collect();
    let spread = Spread::of(&rates);
    log(format!(
        "gpu stability grid {side} × {side} cells × {count} samples: {:.3e} cell-samples/s",
        spread.median
    ));
    Ok(StabilityThroughput {
        cells: side * side,
        samples: count,
        cell_samples_per_s: spread.median,
        cell_samples_per_s_spread: spread,
    })
}

/// Particles of the selection benchmark's runs and of their replicates.
pub const SELECTION_PARTICLES: usize = 5_000;
/// [`SELECTION_PARTICLES`] of `bitrock bench --selection --quick`.
pub const SELECTION_QUICK_PARTICLES: usize = 1_000;

/// A record the selection benchmark checks a run of: the embedded one, or one `bitrock
/// simulate` makes (the command is [`SelectionRecord::command`]), read back from its CSV as
/// `bitrock abc` reads it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum SelectionRecord {
    /// The paper's field record (kN·m).
    Embedded,
    /// A laboratory rig: m3 in N·m on a light string at 100 rpm and 500 N, 0.15 N·m torque
    /// and 2 rpm speed noise, speeds from below zero to above 300 rpm, m2's dynamic torque on
    /// its bound.
    Rig,
    /// m2 at (13, 6.5 kN·m, 0.3 s/rad), 60 rpm, 1 kN·m torque noise (a floor above the paper's).
    M2,
    /// m4 at (11.8, −0.93, 0.057, −1.2e−3), 60 rpm, 1 kN·m torque noise.
    M4,
}

impl SelectionRecord {
    pub const ALL: [SelectionRecord; 4] = [Self::Embedded, Self::Rig, Self::M2, Self::M4];

    /// Its name in the report.
    pub fn name(self) -> &'static str {
        match self {
            Self::Embedded => "embedded",
            Self::Rig => "rig",
            Self::M2 => "m2",
            Self::M4 => "m4",
        }
    }

    /// The `bitrock simulate` command that writes the record; `None` for the embedded one.
    pub fn command(self) -> Option<&'static str> {
        match self {
            Self::Embedded => None,
            Self::Rig => Some(
                "bitrock simulate --law m3 --params 0.3,1.0,0.5,3.0,2.95,0.03 --param-torque-unit nm --inertia-kg-m2 0.02 --omega-n-rad-s 5 --damping-ratio 0.1 --omega-rpm 100 --wob-kn 0.5 --w-ref-kn 0.5 --settle-s 10 --kick-rpm 0 --noise-torque-knm 0.00015 --noise-speed-rpm 2 --wob-fluctuation-kn 0.1 --wob-correlation-s 5 --seed 7 --torque-unit nm",
            ),
            Self::M2 => Some(
                "bitrock simulate --law m2 --params 13,6.5,0.3 --omega-rpm 60 --duration-s 180 --settle-s 40 --noise-torque-knm 1 --wob-fluctuation-kn 12.2 --seed 2024",
            ),
            Self::M4 => Some(
                "bitrock simulate --law m4 --params 11.8,-0.93,0.057,-1.2e-3 --omega-rpm 60 --duration-s 180 --settle-s 40 --noise-torque-knm 1 --wob-fluctuation-kn 12.2 --seed 2025",
            ),
        }
    }

    /// The record, as `bitrock abc` reads it with its defaults.
    pub fn field_data(self) -> Result<FieldData> {
        match self.csv()? {
            None => demo_field_data(&DataOptions::default()),
            Some(csv) => {
                let name = format!("{}.csv", self.name());
                crate::data::parse_field_data(csv.as_slice(), std::path::Path::new(&name), &DataOptions::default())
            }
        }
    }

    /// The CSV file [`Self::command`] writes; `None` for the embedded record.
    pub fn csv(self) -> Result<Option<Vec<u8>>> {
        use crate::simulate::{self, Initial, SimConfig};
        use crate::stability::lumped::Lumped;
        use crate::units::{RAD_S_PER_RPM, TorqueUnit};
        let kick = Initial::Equilibrium {
            speed_perturbation_rad_s: simulate::DEFAULT_KICK_RPM * RAD_S_PER_RPM,
        };
        let field = |law: Law, params_knm: &[f64], seed: u64| {
            let mut c = SimConfig::new(
                law,
                law.scale_torque(params_knm, 1000.0),
                60.0 * RAD_S_PER_RPM,
                244_200.0,
            );
            c.duration_s = 180.0;
            c.recording.settle_s = 40.0;
            c.recording.initial = kick;
            c.recording.noise_torque_nm = 1000.0;
            c.recording.wob_fluctuation_n = 12_200.0;
            c.recording.seed = seed;
            (c, TorqueUnit::KNm)
        };
        let (config, unit) = match self {
            Self::Embedded => return Ok(None),
            Self::Rig => {
                let mut c = SimConfig::new(
                    Law::M3,
                    vec![0.3, 1.0, 0.5, 3.0, 2.95, 0.03],
                    100.0 * RAD_S_PER_RPM,
                    500.0,
                );
                c.structure = Lumped {
                    inertia_kg_m2: 0.02,
                    omega_n_rad_s: 5.0,
                    damping_ratio: 0.1,
                };
                c.w_ref_n = 500.0;
                c.recording.settle_s = 10.0;
                c.recording.noise_torque_nm = 0.15;
                c.recording.noise_speed_rad_s = 2.0 * RAD_S_PER_RPM;
                c.recording.wob_fluctuation_n = 100.0;
                c.recording.wob_correlation_s = 5.0;
                c.recording.seed = 7;
                (c, TorqueUnit::Nm)
            }
            Self::M2 => field(Law::M2, &[13.0, 6.5, 0.3], 2024),
            Self::M4 => field(Law::M4, &[11.8, -0.93, 0.057, -1.2e-3], 2025),
        };
        let trace = simulate::simulate(&config)?;
        let mut csv = Vec::new();
        simulate::write_csv_in(&trace, unit, &mut csv).expect("writing to memory");
        Ok(Some(csv))
    }
}

/// Times `bitrock check-selection` `reps` times on each of `records`: a rejection run of every
/// law (N = `particles`, down to the record's floor as `bitrock abc` sets it, `backend`)
/// written to a temporary directory, then K = `replicates` per law checked with the same
/// backend. The results are the same every repetition; the time is not.
pub fn selection_checks(
    records: &[SelectionRecord],
    replicates: usize,
    particles: usize,
    backend: Backend,
    reps: usize,
    log: &mut dyn FnMut(String),
) -> Result<Vec<SelectionBench>> {
    records
        .iter()
        .map(|&record| selection_check(record, replicates, particles, backend, reps, log))
        .collect()
}

fn selection_check(
    record: SelectionRecord,
    replicates: usize,
    particles: usize,
    backend: Backend,
    reps: usize,
    log: &mut dyn FnMut(String),
) -> Result<SelectionBench> {
    use crate::run::selection::{CheckOptions, CheckedRun};
    use crate::run::{self, abc::SamplerConfig};
    let dir =
        tempfile::tempdir().map_err(|source| crate::error::Error::output("TMPDIR", &std::env::temp_dir(), source))?;
    let run_dir = dir.path().join("run");
    let sampler = RejectionConfig::from(Schedule {
        particles,
        ..Schedule::default()
    });
    let config = run::abc::Config {
        backend,
        sampler: SamplerConfig::Rejection(sampler),
        eps_min_from_record: true,
        ..run::abc::Config::default()
    };
    let laws = config.laws.len();
    let data = record.field_data()?;
    let samples = data.calibration.len();
    run::abc::Job {
        config,
        summary_population: None,
        out: Some(run::Dir {
            path: run_dir.clone(),
            replace: false,
        }),
    }
    .run(data, Default::default(), &mut crate::abc::Silent)?;
    let run = CheckedRun::open(&run_dir)?;
    let eps_min = run
        .stored
        .populations
        .last()
        .and_then(|p| p.record.epsilon)
        .unwrap_or(f64::INFINITY);
    let options = CheckOptions {
        replicates,
        backend: Some(backend),
        batch: None,
    };
    let name = record.name();
    let mut checks = Vec::new();
    for rep in 0..reps.max(1) {
        let check = crate::run::selection::check(&run, &options, &|_, _| {}, &mut |_| {})?;
        let f = &check.timing.fits;
        log(format!(
            "check-selection of the {name} record ({}/{}): {laws} laws × {replicates} replicates, N = {particles}, to ε = {eps_min:.4}, backend {}: {:.2} s (records and fits {:.2} s, sampling {:.2} s, of which scoring {:.2} s); {} of {} fits had a run out of patience",
            rep + 1,
            reps.max(1),
            check.backend,
            check.seconds,
            check.timing.fit_seconds,
            check.timing.sampling_seconds,
            check.timing.scoring_seconds,
            f.fits_out_of_patience,
            f.fits,
        ));
        checks.push(check);
    }
    let median = |f: &dyn Fn(&crate::run::selection::SelectionCheck) -> f64| {
        quantile(&checks.iter().map(f).collect::<Vec<_>>(), 0.5)
    };
    let seconds_spread = Spread::of(&checks.iter().map(|c| c.seconds).collect::<Vec<_>>());
    let seconds = seconds_spread.median;
    let fit_seconds = median(&|c| c.timing.fit_seconds);
    Ok(SelectionBench {
        record,
        command: record.command(),
        calibration_samples: samples,
        backend_asked: backend,
        backend: checks[0].backend.clone(),
        laws,
        replicates_per_law: replicates,
        particles,
        eps_min,
        seconds,
        seconds_spread,
        replicates_per_s: (laws * replicates) as f64 / seconds,
        fit_seconds,
        fit_share: fit_seconds / seconds,
        sampling_seconds: median(&|c| c.timing.sampling_seconds),
        scoring_seconds: median(&|c| c.timing.scoring_seconds),
        fits: checks[0].timing.fits.clone(),
        batches: checks[0].timing.batches,
        dispatches: checks[0].timing.dispatches,
        evaluations: checks[0].timing.evaluations,
        repetitions: checks.len(),
    })
}

/// Agreement of one law's ρ between backends.
#[derive(Clone, Debug, Serialize)]
pub struct LawParity {
    pub law: Law,
    pub candidates: usize,
    pub d: usize,
    pub max_rel_diff: f64,
    pub median_rel_diff: f64,
    /// Tolerance the decisions were compared at (the CPU median ρ unless given).
    pub epsilon: f64,
    /// Candidates accepted by one backend only.
    pub decisions_differ: usize,
    /// Of those, how many lie within the parity tolerance of ε (expected exceptions).
    pub decisions_differ_near_threshold: usize,
    /// For a law file's law: the largest relative difference of ρ between f32 and f64
    /// arithmetic, both on the CPU, over the first [`F32_PROBE_CANDIDATES`] candidates: what the
    /// law itself loses in f32, whatever the GPU ([`Law::f32_rho_error`]).
    pub f32_rel_diff: Option<f64>,
    /// The GPU disagrees, the law loses beyond the tolerance in f32 on the CPU too, and on the
    /// probed candidates the GPU differs within [`F32_EXPLAINS`] × that: the law is
    /// ill-conditioned in f32 and belongs on the CPU; the GPU is not at fault.
    pub ill_conditioned_in_f32: bool,
}

/// Candidates per law whose ρ `bitrock parity` recomputes in f32 on the CPU.
pub const F32_PROBE_CANDIDATES: usize = 256;
/// A GPU's difference on a law ill-conditioned in f32 is the law's when, on the probed
/// candidates, it stays within this factor of what f32 arithmetic on the CPU loses (the GPU's
/// own exp, tanh and rounding order add to it).
pub const F32_EXPLAINS: f64 = 10.0;

/// Bit-for-bit agreement of the candidate generator.
#[derive(Clone, Debug, Serialize)]
pub struct PhiloxParity {
    pub words_compared: usize,
    pub words_differ: usize,
    pub candidates_compared: usize,
    pub candidates_differ: usize,
    /// The first [`DIFFERENCES_SHOWN`] differences in index order: evidence for a driver bug
    /// report.
    pub first_differences: Vec<CandidateDifference>,
}

/// Differences of candidates that `bitrock parity` keeps and prints.
pub const DIFFERENCES_SHOWN: usize = 8;

/// How one candidate differs between backends.
#[derive(Clone, Debug, PartialEq, Serialize)]
#[serde(tag = "differs", rename_all = "snake_case")]
pub enum CandidateDifference {
    /// The backends chose different laws (`gpu` is `None` for a slot outside the prior).
    Law {
        population: u32,
        index: u64,
        cpu: Law,
        gpu: Option<Law>,
    },
    /// The same law, a different value of one parameter (SI units, f32 as the backends hold it).
    Parameter {
        population: u32,
        index: u64,
        law: Law,
        parameter: &'static str,
        cpu: f32,
        gpu: f32,
        /// The f32 bits, as hexadecimal.
        cpu_bits: String,
        gpu_bits: String,
        /// gpu − cpu in units in the last place (signed; counts across zero).
        ulps: i64,
    },
}

impl std::fmt::Display for CandidateDifference {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Law {
                population,
                index,
                cpu,
                gpu,
            } => {
                let gpu = gpu.map_or("a slot outside the prior".to_string(), |l| l.to_string());
                write!(
                    f,
                    "population {population} candidate {index}: law {cpu} on the cpu, {gpu} on the gpu"
                )
            }
            Self::Parameter {
                population,
                index,
                law,
                parameter,
                cpu,
                gpu,
                cpu_bits,
                gpu_bits,
                ulps,
            } => write!(
                f,
                "population {population} candidate {index}: {law}.{parameter} (SI) cpu {cpu:e} [{cpu_bits}], gpu {gpu:e} [{gpu_bits}], {ulps:+} ulp"
            ),
        }
    }
}

/// Signed distance b − a in f32 units in the last place: the bit patterns mapped to integers
/// that are monotone in the value (−0 and +0 both 0).
pub fn ulp_distance(a: f32, b: f32) -> i64 {
    let ordinal = |x: f32| {
        let bits = x.to_bits();
        let magnitude = i64::from(bits & 0x7FFF_FFFF);
        if bits >> 31 == 1 { -magnitude } else { magnitude }
    };
    ordinal(b) - ordinal(a)
}

/// Compares what the GPU generated for candidates `start ..` of `population` (`got`, in index
/// order) with the CPU's Philox words and candidates of `prior` and `seed`.
pub fn compare_candidates(prior: &Prior, seed: u64, population: u32, start: u64, got: &[GpuCandidate]) -> PhiloxParity {
    let key = crate::rng::key_of_seed(seed);
    let (mut words_differ, mut candidates_differ) = (0, 0);
    let mut first_differences = Vec::new();
    for (k, g) in got.iter().enumerate() {
        let index = start + k as u64;
        for b in 0..2u32 {
            let want = crate::rng::philox4x32_10(crate::rng::candidate_counter(population, index, b), key);
            let have = &g.philox[4 * b as usize..4 * b as usize + 4];
            words_differ += want.iter().zip(have).filter(|(a, b)| a != b).count();
        }
        let c = prior.candidate(seed, population, index);
        let law = prior.law(c.slot);
        let differences: Vec<CandidateDifference> = if g.slot as usize != c.slot {
            vec![CandidateDifference::Law {
                population,
                index,
                cpu: law,
                gpu: prior.boxes.get(g.slot as usize).map(|b| b.law),
            }]
        } else {
            law.param_names()
                .into_iter()
                .enumerate()
                .filter(|&(j, _)| g.param_bits[j] != c.params[j].to_bits())
                .map(|(j, parameter)| {
                    let gpu = f32::from_bits(g.param_bits[j]);
                    CandidateDifference::Parameter {
                        population,
                        index,
                        law,
                        parameter,
                        cpu: c.params[j],
                        gpu,
                        cpu_bits: format!("{:#010x}", c.params[j].to_bits()),
                        gpu_bits: format!("{:#010x}", g.param_bits[j]),
                        ulps: ulp_distance(c.params[j], gpu),
                    }
                })
                .collect()
        };
        candidates_differ += usize::from(!differences.is_empty());
        let room = DIFFERENCES_SHOWN - first_differences.len();
        first_differences.extend(differences.into_iter().take(room));
    }
    PhiloxParity {
        words_compared: 8 * got.len(),
        words_differ,
        candidates_compared: got.len(),
        candidates_differ,
        first_differences,
    }
}

/// What `bitrock parity` reports.
#[derive(Clone, Debug, Serialize)]
pub struct ParityReport {
    pub adapter: String,
    pub tolerance: f64,
    pub laws: Vec<LawParity>,
    pub philox: PhiloxParity,
    /// The torsional strings' simulator: the kernel against its CPU twin.
    pub strings: simulators::StringsParity,
    /// The coupled bit's simulator: the kernel against its CPU twin.
    pub coupled: simulators::CoupledParity,
    /// Every check within tolerance: ρ, decisions away from ε, Philox and candidates exact, the
    /// simulated strings within their rules.
    pub pass: bool,
    /// The GPU agrees with the CPU wherever the laws are well-conditioned in f32, and on the
    /// simulated strings: a failure of `pass` alone is the laws' (see
    /// [`LawParity::ill_conditioned_in_f32`]), not the GPU's.
    pub gpu_agrees: bool,
}

/// Candidates per law `bitrock parity` compares by default.
pub const PARITY_CANDIDATES: usize = 100_000;
/// The seed `bitrock parity` draws its candidates from by default.
pub const PARITY_SEED: u64 = 1;

/// [`parity`] on a record, as `bitrock parity` runs it: candidates drawn from the prior δ
/// around the least-squares fits of `laws` (the run's default δ) with `seed`. Refuses no
/// candidates, a tolerance that is not a positive number, and a record the prior cannot be
/// built from.
pub fn parity_on(
    data: &FieldData,
    laws: &[Law],
    candidates: usize,
    epsilon: Option<f64>,
    seed: u64,
) -> Result<ParityReport> {
    if candidates == 0 {
        return Err(Error::setting("candidates", "must be at least 1"));
    }
    if let Some(e) = epsilon
        && !(e.is_finite() && e > 0.0)
    {
        return Err(Error::setting("epsilon", format!("must be a positive number, got {e}")));
    }
    let fits = fit_record(laws, data, &FitOptions::default())?;
    let delta = crate::run::abc::Config::default().delta;
    let prior = Prior::from_fits(&fits, delta, None, data.torque_unit.newton_metres()).map_err(|e| {
        // Parity has no δ or prior file of its own: the record is what the prior cannot be built from.
        Error::Data {
            path: data.source.clone(),
            message: format!("the prior parity draws from (δ = {delta} around the fits) cannot be built: {e}"),
        }
    })?;
    parity(&Problem::new(prior, seed, &data.calibration, None), candidates, epsilon)
}

/// Scores the same candidates on both backends for each law's prior in `prior` (one law at a
/// time), compares the candidate generators bit for bit, and the simulators' strings by their
/// rules ([`simulators`]).
pub fn parity(problem: &Problem, candidates: usize, epsilon: Option<f64>) -> Result<ParityReport> {
    // ρ on both backends, their relative differences and a sorted copy for the median.
    crate::limits::check_memory(
        "candidates",
        candidates as f64 * 4.0 * 8.0,
        &format!("comparing {candidates} candidates"),
    )?;
    crate::limits::check_work(
        "candidates",
        candidates as f64 * problem.data_len() as f64 * problem.prior.boxes.len() as f64,
        1e12,
        &format!("{candidates} candidates on {} samples per law", problem.data_len()),
    )?;
    let ctx = gpu::context()?;
    let mut laws = Vec::new();
    for (slot, bx) in problem.prior.boxes.iter().enumerate() {
        let single = Problem {
            prior: Prior::new(vec![bx.clone()], vec![problem.prior.weights[slot]])?,
            ..problem.clone()
        };
        let gpu = gpu::residual::GpuEvaluator::new(single.clone())?;
        let cpu = CpuEvaluator::new(single.clone());
        let (mut g, mut c) = (vec![0.0; candidates], vec![0.0; candidates]);
        gpu.score(0, 0, &mut g)?;
        cpu.score(0, 0, &mut c)?;
        let rel: Vec<f64> = g.iter().zip(&c).map(|(g, c)| ((g - c) / c).abs()).collect();
        let eps = epsilon.unwrap_or_else(|| quantile(&c, 0.5));
        let differ: Vec<usize> = (0..candidates).filter(|&i| (g[i] < eps) != (c[i] < eps)).collect();
        let near = differ
            .iter()
            .filter(|&&i| (c[i] - eps).abs() <= PARITY_TOLERANCE * eps)
            .count();
        let probed = candidates.min(F32_PROBE_CANDIDATES);
        let f32_rel_diff = (0..probed as u64)
            .map(|i| {
                let c = single.prior.candidate(single.seed, 0, i);
                let p: Vec<f64> = c.params[..bx.law.n_params()].iter().map(|&v| f64::from(v)).collect();
                bx.law.f32_rho_error(&p, &single.speed_rad_s, &single.torque_nm)
            })
            .try_fold(0.0f64, |acc, e| e.map(|e| acc.max(e)));
        let max_rel_diff = rel.iter().copied().fold(0.0, f64::max);
        let agrees = max_rel_diff <= PARITY_TOLERANCE && differ.len() == near;
        // On the same candidates, the GPU differs by no more than f32 arithmetic explains.
        let probed_gpu_diff = rel[..probed].iter().copied().fold(0.0, f64::max);
        let ill_conditioned_in_f32 =
            !agrees && f32_rel_diff.is_some_and(|e| e > PARITY_TOLERANCE && probed_gpu_diff <= F32_EXPLAINS * e);
        laws.push(LawParity {
            law: bx.law,
            candidates,
            d: problem.data_len(),
            max_rel_diff,
            median_rel_diff: quantile(&rel, 0.5),
            epsilon: eps,
            decisions_differ: differ.len(),
            decisions_differ_near_threshold: near,
            f32_rel_diff,
            ill_conditioned_in_f32,
        });
    }
    // 2¹⁷ candidates × 8 words = 1,048,576 Philox words, starting below 2³² so that the high
    // counter word changes inside the range.
    let count = 131_072u32;
    let start = (1u64 << 32) - u64::from(count) / 2;
    let got = gpu::candidates::generate(&problem.prior, problem.seed, 1, start, count)?;
    let philox = compare_candidates(&problem.prior, problem.seed, 1, start, &got);
    let strings = simulators::strings_parity()?;
    let coupled = simulators::coupled_parity()?;
    // A law ill-conditioned in f32 fails the check but does not blame the GPU.
    let gpu_agrees = strings.pass
        && coupled.pass
        && philox.words_differ == 0
        && philox.candidates_differ == 0
        && laws.iter().all(|l| {
            l.ill_conditioned_in_f32
                || (l.max_rel_diff <= PARITY_TOLERANCE && l.decisions_differ == l.decisions_differ_near_threshold)
        });
    let pass = gpu_agrees && !laws.iter().any(|l| l.ill_conditioned_in_f32);
    Ok(ParityReport {
        adapter: ctx.describe(),
        tolerance: PARITY_TOLERANCE,
        laws,
        philox,
        strings,
        coupled,
        pass,
        gpu_agrees,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ulp_distance_counts_representable_steps_across_zero() {
        assert_eq!(ulp_distance(1.0, 1.0f32.next_up()), 1);
        assert_eq!(ulp_distance(1.0f32.next_up(), 1.0), -1);
        assert_eq!(ulp_distance(1.0, 1.0f32.next_down()), -1);
        assert_eq!(ulp_distance(-0.0, 0.0), 0);
        assert_eq!(ulp_distance(-f32::from_bits(1), f32::from_bits(2)), 3);
        assert_eq!(ulp_distance(2.0, 4.0), 1 << 23);
    }

    /// What a GPU that agrees with the CPU returns for candidates `start .. start + count`.
    fn cpu_as_gpu(prior: &Prior, seed: u64, population: u32, start: u64, count: u64) -> Vec<GpuCandidate> {
        let key = crate::rng::key_of_seed(seed);
        (start..start + count)
            .map(|index| {
                let c = prior.candidate(seed, population, index);
                let b0 = crate::rng::philox4x32_10(crate::rng::candidate_counter(population, index, 0), key);
                let b1 = crate::rng::philox4x32_10(crate::rng::candidate_counter(population, index, 1), key);
                GpuCandidate {
                    philox: [b0, b1].concat().try_into().expect("8 words"),
                    slot: c.slot as u32,
                    // Unused parameters are 0 on both backends.
                    param_bits: c.law_params().map(f32::to_bits),
                }
            })
            .collect()
    }

    #[test]
    fn compare_candidates_names_each_difference_with_its_ulps() {
        let prior = synthetic_problem(Law::M3, 10, 1).prior;
        let two_laws = Prior::new(
            vec![
                synthetic_problem(Law::M2, 10, 1).prior.boxes[0].clone(),
                prior.boxes[0].clone(),
            ],
            vec![1.0, 1.0],
        )
        .unwrap();
        let (seed, population, start) = (7, 3, 1000);
        let mut got = cpu_as_gpu(&two_laws, seed, population, start, 500);
        let clean = compare_candidates(&two_laws, seed, population, start, &got);
        assert_eq!((clean.words_differ, clean.candidates_differ), (0, 0));
        assert_eq!(clean.words_compared, 4000);
        assert!(clean.first_differences.is_empty());

        // Candidate 10: one parameter one ulp up; candidate 20: the other law; candidate 30: a
        // Philox word and two parameters (-2 ulp, and a sign flip).
        let slot_of = |g: &GpuCandidate| g.slot as usize;
        let p10 = f32::from_bits(got[10].param_bits[1]);
        got[10].param_bits[1] = p10.next_up().to_bits();
        let law20 = two_laws.law(slot_of(&got[20]));
        got[20].slot = 1 - got[20].slot;
        got[30].philox[5] ^= 1;
        let p30 = [
            f32::from_bits(got[30].param_bits[0]),
            f32::from_bits(got[30].param_bits[2]),
        ];
        got[30].param_bits[0] = p30[0].next_down().next_down().to_bits();
        got[30].param_bits[2] = (-p30[1]).to_bits();
        let report = compare_candidates(&two_laws, seed, population, start, &got);
        assert_eq!(report.words_differ, 1);
        assert_eq!(report.candidates_differ, 3);
        let d = &report.first_differences;
        assert_eq!(d.len(), 4, "{d:#?}");
        let law10 = two_laws.law(slot_of(&got[10]));
        assert_eq!(
            d[0],
            CandidateDifference::Parameter {
                population,
                index: start + 10,
                law: law10,
                parameter: law10.param_names()[1],
                cpu: p10,
                gpu: p10.next_up(),
                cpu_bits: format!("{:#010x}", p10.to_bits()),
                gpu_bits: format!("{:#010x}", p10.next_up().to_bits()),
                ulps: 1,
            }
        );
        assert_eq!(
            d[1],
            CandidateDifference::Law {
                population,
                index: start + 20,
                cpu: law20,
                gpu: Some(two_laws.law(1 - two_laws.boxes.iter().position(|b| b.law == law20).unwrap())),
            }
        );
        let law30 = two_laws.law(slot_of(&got[30]));
        match (&d[2], &d[3]) {
            (
                CandidateDifference::Parameter {
                    index: i0,
                    parameter: n0,
                    ulps: u0,
                    ..
                },
                CandidateDifference::Parameter {
                    index: i2,
                    parameter: n2,
                    ulps: u2,
                    gpu,
                    ..
                },
            ) => {
                assert_eq!((*i0, *n0, *u0), (start + 30, law30.param_names()[0], -2));
                assert_eq!((*i2, *n2), (start + 30, law30.param_names()[2]));
                assert_eq!(gpu.to_bits(), (-p30[1]).to_bits());
                assert_eq!(*u2, ulp_distance(p30[1], -p30[1]));
            }
            other => panic!("{other:?}"),
        }
        let line = d[0].to_string();
        assert!(line.contains(&format!("candidate {}", start + 10)), "{line}");
        assert!(
            line.contains("+1 ulp") && line.contains(&format!("{:#010x}", p10.to_bits())),
            "{line}"
        );
        assert!(
            d[1].to_string().contains(&format!("law {law20} on the cpu")),
            "{}",
            d[1]
        );

        // Only the first DIFFERENCES_SHOWN are kept; all are counted.
        for g in got.iter_mut().skip(100).take(20) {
            g.param_bits[0] ^= 1;
        }
        let report = compare_candidates(&two_laws, seed, population, start, &got);
        assert_eq!(report.candidates_differ, 23);
        assert_eq!(report.first_differences.len(), DIFFERENCES_SHOWN);
    }
}
