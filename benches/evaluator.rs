//! CPU evaluator throughput: candidate × data-point evaluations per second for each law at
//! D = 5,000 (the targets on two cores: m3 ≥ 1.5e8/s, m2 ≥ 5e8/s).
//! `cargo bench --bench evaluator`; criterion's "thrpt" line is evaluations per second.

use bitrock::Law;
use bitrock::data::Samples;
use bitrock::eval::cpu::CpuEvaluator;
use bitrock::eval::{AbcProblem, Evaluator};
use bitrock::prior::{LawBox, Prior};
use criterion::{Criterion, Throughput, criterion_group, criterion_main};

const D: usize = 5_000;
const CANDIDATES: usize = 8_192;

/// One-law problem: data from the law at the paper's estimate (N·m), prior box ±40 %.
fn problem(law: Law) -> AbcProblem {
    let truth = law.scale_torque(law.paper_estimate(), 1000.0);
    let speed: Vec<f64> = (0..D).map(|i| 0.5 + 20.0 * i as f64 / D as f64).collect();
    let torque = speed.iter().map(|&w| law.torque(&truth, w, 1.0)).collect();
    let data = Samples {
        speed_rad_s: speed,
        torque_nm: torque,
        wob_n: None,
        time_s: None,
    };
    let (lower, upper) = truth
        .iter()
        .map(|&p| ((p * 0.6).min(p * 1.4) as f32, (p * 0.6).max(p * 1.4) as f32))
        .unzip();
    let prior = Prior::new(vec![LawBox { law, lower, upper }], vec![1.0]).expect("prior");
    AbcProblem::new(prior, 1, &data, None)
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
}

criterion_group!(evaluator, benches);
criterion_main!(evaluator);
