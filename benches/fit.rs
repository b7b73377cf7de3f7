//! Least-squares calibration and misfit evaluation on the embedded demo record.
//! `cargo bench --bench fit`

use bitrock::Law;
use bitrock::data::{DataOptions, demo_field_data};
use bitrock::fit::{FitOptions, fit_law, misfit};
use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use std::hint::black_box;

fn benches(c: &mut Criterion) {
    let data = demo_field_data(&DataOptions::default()).expect("embedded record");
    let cal = &data.calibration;
    let ones = vec![1.0; cal.len()];
    let sum_y2 = cal.sum_sq_torque();

    let mut group = c.benchmark_group("misfit");
    group.throughput(Throughput::Elements(cal.len() as u64));
    for law in Law::ALL {
        let p = law.scale_torque(law.paper_estimate().unwrap(), 1000.0);
        group.bench_function(law.name(), |b| {
            b.iter(|| misfit(law, black_box(&p), &cal.speed_rad_s, &cal.torque_nm, &ones, sum_y2))
        });
    }
    group.finish();

    let mut group = c.benchmark_group("fit");
    group.sample_size(10);
    for law in Law::ALL {
        group.bench_function(law.name(), |b| {
            b.iter(|| fit_law(law, cal, &data.validation, &FitOptions::default()).expect("fit"))
        });
    }
    group.finish();
}

criterion_group!(fit, benches);
criterion_main!(fit);
