//! Many records scored together (bitrock::eval::records, shaders/records.wgsl): every record's
//! ρ are exactly those of its own evaluator of the same backend and scoring shape, whatever
//! else shares the dispatch, however requests are split over dispatches, and whichever
//! samplers leave early. The GPU tests need an adapter, as in gpu.rs.

use super::gpu::{per_shape, require_gpu};
use bitrock::Law;
use bitrock::data::{DataOptions, demo_field_data};
use bitrock::eval::cpu::CpuEvaluator;
use bitrock::eval::gpu::records::GpuRecords;
use bitrock::eval::gpu::{Shape, residual::GpuEvaluator};
use bitrock::eval::records::RecordBatch;
use bitrock::eval::{Backend, Evaluator, PARITY_TOLERANCE, Problem};
use bitrock::eval::{Candidates, Request};
use bitrock::fit::{FitOptions, fit_laws};
use bitrock::prior::{Candidate, Prior};

/// Five records of the demo record's length and speeds, each its own: torques scaled by
/// 1 + 2 % per record, seeds, δ (0.4, 0.6) and so the four laws' boxes; record 2 scales by a
/// weight-on-bit ratio that varies from sample to sample (the others have r = 1).
fn mixed_records() -> Vec<Problem> {
    let data = demo_field_data(&DataOptions::default()).unwrap();
    let fits = fit_laws(&Law::ALL, &data.calibration, &data.validation, &FitOptions::default()).unwrap();
    (0..5)
        .map(|r| {
            let delta = if r % 2 == 0 { 0.4 } else { 0.6 };
            let prior = Prior::from_fits(&fits, delta, None, 1000.0).unwrap();
            let mut problem = Problem::new(prior, 1000 + r as u64, &data.calibration, None);
            for y in &mut problem.torque_nm {
                *y *= 1.0 + 0.02 * r as f64;
            }
            if r == 2 {
                for (i, ratio) in problem.wob_ratio.iter_mut().enumerate() {
                    *ratio = 0.9 + 0.2 * ((i % 7) as f64 / 6.0);
                }
            }
            problem.sum_sq_torque = problem.torque_nm.iter().map(|y| y * y).sum();
            problem
        })
        .collect()
}

fn stream_candidates(problem: &Problem, population: u32, start: u64, count: usize) -> Vec<Candidate> {
    (0..count as u64)
        .map(|k| problem.prior.candidate(problem.seed, population, start + k))
        .collect()
}

/// Requests of every kind and awkward size: stream ranges of 1, 15, 16, 1,000 and 3,333
/// candidates (one per record, on its own population and start), and two explicit requests,
/// one of them a second request of record 3.
fn requests(problems: &[Problem]) -> Vec<Request> {
    let sizes = [1, 15, 16, 1000, 3333];
    let mut requests: Vec<Request> = sizes
        .iter()
        .enumerate()
        .map(|(r, &len)| Request {
            record: r,
            candidates: Candidates::Stream {
                population: r as u32 + 1,
                start: 1000 * r as u64 + 7,
                len,
            },
        })
        .collect();
    for (record, len) in [(0, 17), (3, 500)] {
        requests.push(Request {
            record,
            candidates: Candidates::Explicit(stream_candidates(&problems[record], 9, 50, len)),
        });
    }
    requests
}

/// SSR of `request` from the record's own GPU evaluator.
fn own_ssr(problem: &Problem, shape: Shape, request: &Request) -> Vec<f32> {
    let gpu = GpuEvaluator::with_shape(problem.clone(), shape).unwrap();
    let mut out = vec![0.0f32; request.candidates.len()];
    match &request.candidates {
        Candidates::Stream { population, start, .. } => gpu.sum_sq_residuals(*population, *start, &mut out).unwrap(),
        Candidates::Explicit(c) => gpu.sum_sq_residuals_of(c, &mut out).unwrap(),
    }
    out
}

/// ρ of `request` from the CPU reference.
fn cpu_rho(problem: &Problem, request: &Request) -> Vec<f64> {
    let cpu = CpuEvaluator::new(problem.clone());
    let mut out = vec![0.0; request.candidates.len()];
    match &request.candidates {
        Candidates::Stream { population, start, .. } => cpu.score(*population, *start, &mut out).unwrap(),
        Candidates::Explicit(c) => cpu.score_params(c, &mut out).unwrap(),
    }
    out
}

per_shape! {
/// One dispatch per ratio class, and then dispatches of at most 64 candidates (every request
/// split, segments ending mid-tile): each record's sums are its own evaluator's, bit for bit,
/// and within the parity tolerance of the CPU.
fn a_dispatch_of_many_records_scores_each_as_its_own_evaluator(shape: Shape) {
    require_gpu();
    let problems = mixed_records();
    let refs: Vec<&Problem> = problems.iter().collect();
    let requests = requests(&problems);
    let own: Vec<Vec<f32>> = requests.iter().map(|r| own_ssr(&problems[r.record], shape, r)).collect();
    for max_candidates in [None, Some(64)] {
        let mut records = GpuRecords::new(&refs, shape, max_candidates).unwrap();
        let (ssr, dispatches) = records.sum_sq_residuals(&requests).unwrap();
        let total: usize = requests.iter().map(|r| r.candidates.len()).sum();
        match max_candidates {
            // Records with a varying weight-on-bit ratio (record 2) and without it go to their
            // own pipelines: one dispatch each.
            None => assert_eq!(dispatches, 2),
            Some(max) => assert!(dispatches >= total.div_ceil(max), "{dispatches} dispatches"),
        }
        let mut worst = 0.0f64;
        for ((request, batched), own) in requests.iter().zip(&ssr).zip(&own) {
            let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(batched), bits(own), "record {} ({max_candidates:?})", request.record);
            let problem = &problems[request.record];
            for (s, c) in batched.iter().zip(cpu_rho(problem, request)) {
                worst = worst.max((f64::from(*s) / problem.sum_sq_torque - c).abs() / c);
            }
        }
        eprintln!("{shape}, {dispatches} dispatches: largest relative difference of rho from the CPU {worst:.2e}");
        assert!(worst <= PARITY_TOLERANCE, "{worst:e}");
    }
}

/// Records past the 32,768-sample slicing: each record's data are found at its own offset in
/// every slice.
fn long_records_are_scored_slice_by_slice_at_their_own_offsets(shape: Shape) {
    require_gpu();
    let problems: Vec<Problem> = [(Law::M3, 1), (Law::M1, 2), (Law::M3, 3)]
        .iter()
        .map(|&(law, seed)| bitrock::bench::synthetic_problem(law, 40_000, seed))
        .collect();
    let refs: Vec<&Problem> = problems.iter().collect();
    let requests: Vec<Request> = (0..3)
        .map(|record| Request {
            record,
            candidates: Candidates::Stream {
                population: 0,
                start: 0,
                len: 100,
            },
        })
        .collect();
    let (ssr, _) = GpuRecords::new(&refs, shape, None).unwrap().sum_sq_residuals(&requests).unwrap();
    for (request, batched) in requests.iter().zip(&ssr) {
        let own = own_ssr(&problems[request.record], shape, request);
        assert_eq!(batched, &own, "record {}", request.record);
    }
}

/// Samplers on threads through a batch of the GPU: as `samplers_that_wait_and_leave_…` on
/// the CPU, with requests split over dispatches of at most 256 candidates.
fn samplers_on_the_gpu_get_their_own_evaluators_results(shape: Shape) {
    require_gpu();
    let problems = mixed_records();
    let batch = RecordBatch::on_gpu(shape, Some(256));
    let results = run_samplers(&batch, &problems);
    for (r, calls) in results.iter().take(5).enumerate() {
        assert_eq!(calls.len(), r + 1);
        let gpu = GpuEvaluator::with_shape(problems[r].clone(), shape).unwrap();
        for (k, got) in calls.iter().enumerate() {
            assert_eq!(got, &expected_call(&gpu, r, k), "record {r}, call {k}");
        }
    }
    let counts = batch.counts();
    assert_eq!((counts.batches, counts.requests), (5, 15));
    assert!(counts.dispatches > counts.batches, "{counts:?}");
}
}

/// Call `k` of sampler `r`: a stream range (even k) or explicit candidates (odd k) of a size
/// that differs by sampler and call.
fn call(problem: &Problem, r: usize, k: usize) -> Candidates {
    let len = 37 * (r + 1) + 101 * k;
    if k.is_multiple_of(2) {
        Candidates::Stream {
            population: k as u32,
            start: 13 * r as u64,
            len,
        }
    } else {
        Candidates::Explicit(stream_candidates(problem, 40 + k as u32, 0, len))
    }
}

/// What `evaluator` (of sampler r's record) says about call k.
fn expected_call(evaluator: &dyn Evaluator, r: usize, k: usize) -> Vec<f64> {
    let candidates = call(evaluator.problem(), r, k);
    let mut out = vec![0.0; candidates.len()];
    match &candidates {
        Candidates::Stream { population, start, .. } => evaluator.score(*population, *start, &mut out).unwrap(),
        Candidates::Explicit(c) => evaluator.score_params(c, &mut out).unwrap(),
    }
    out
}

/// Five samplers on threads, sampler r making r + 1 calls and leaving, and a sixth seat given
/// up before registering (a run refused before its evaluator): every sampler's results.
fn run_samplers(batch: &std::sync::Arc<RecordBatch>, problems: &[Problem]) -> Vec<Vec<Vec<f64>>> {
    let seats: Vec<_> = (0..6).map(|_| batch.seat()).collect();
    std::thread::scope(|scope| {
        let threads: Vec<_> = seats
            .into_iter()
            .enumerate()
            .map(|(r, seat)| {
                scope.spawn(move || {
                    if r == 5 {
                        return Vec::new();
                    }
                    let evaluator = seat.evaluator(problems[r].clone());
                    (0..=r).map(|k| expected_call(&evaluator, r, k)).collect()
                })
            })
            .collect();
        threads.into_iter().map(|t| t.join().unwrap()).collect()
    })
}

/// Samplers on threads through a batch of the CPU, sampler r making r + 1 calls of its own sizes
/// and leaving, one seat given up unused: each gets what its own CPU evaluator gives, bit for
/// bit, and the calls went in five batches (one per round, fewer samplers each time).
#[test]
fn samplers_that_wait_and_leave_get_their_own_evaluators_results() {
    let problems = mixed_records();
    let batch = RecordBatch::new(
        Backend::Cpu,
        Default::default(),
        &problems[0],
        problems.len(),
        &mut |_| {},
    )
    .unwrap();
    assert_eq!(batch.backend(), "cpu");
    let results = run_samplers(&batch, &problems);
    for (r, calls) in results.iter().take(5).enumerate() {
        assert_eq!(calls.len(), r + 1);
        let cpu = CpuEvaluator::new(problems[r].clone());
        for (k, got) in calls.iter().enumerate() {
            let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(got), bits(&expected_call(&cpu, r, k)), "record {r}, call {k}");
        }
    }
    let counts = batch.counts();
    assert_eq!((counts.batches, counts.requests, counts.dispatches), (5, 15, 0));
}
