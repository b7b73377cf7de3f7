//! Evaluator throughput: candidate × data-point evaluations per second for each law at
//! D = 5,000, on the CPU (8,192 candidates per call) and, when an adapter exists, on the GPU
//! (65,536 candidates per call). `cargo bench --bench evaluator`; criterion's "thrpt" line is
//! evaluations per second. `bitrock bench` measures the same kernels at more sizes.

use bitrock::Law;
use bitrock::eval::cpu::CpuEvaluator;
use bitrock::eval::gpu::residual::GpuEvaluator;
use bitrock::eval::{Evaluator, Problem};
use criterion::{Criterion, Throughput, criterion_group, criterion_main};

const D: usize = 5_000;
const CANDIDATES: usize = 8_192;

/// One-law problem: the paper's estimate with a ±5 % ripple, ±40 % prior box.
fn problem(law: Law) -> Problem {
    bitrock::bench::synthetic_problem(law, D, 1)
}

fn benches(c: &mut Criterion) {
    let mut group = c.benchmark_group("cpu_evaluator_d5000");
    group.throughput(Throughput::Elements((D * CANDIDATES) as u64));
    group.sample_size(10);
    for law in Law::ALL {
        let evaluator = CpuEvaluator::new(problem(law));
        let mut rho = vec![0.0; CANDIDATES];
        group.bench_function(law.name(), |b| {
            b.iter(|| evaluator.score(0, 0, &mut rho).expect("score"))
        });
    }
    group.finish();

    match bitrock::eval::gpu::context() {
        Err(e) => eprintln!("no GPU adapter ({e}): GPU benchmarks skipped"),
        Ok(ctx) => {
            eprintln!("GPU: {}", ctx.describe());
            const GPU_CANDIDATES: usize = 65_536;
            let mut group = c.benchmark_group("gpu_evaluator_d5000");
            group.throughput(Throughput::Elements((D * GPU_CANDIDATES) as u64));
            group.sample_size(10);
            for law in Law::ALL {
                let evaluator = GpuEvaluator::new(problem(law)).expect("GPU evaluator");
                let mut rho = vec![0.0; GPU_CANDIDATES];
                group.bench_function(law.name(), |b| {
                    b.iter(|| evaluator.score(0, 0, &mut rho).expect("score"))
                });
            }
            group.finish();
        }
    }
}

criterion_group!(evaluator, benches);
criterion_main!(evaluator);
