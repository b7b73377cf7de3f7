//! The rejection sampler: determinism, a case with a closed-form accepted set, the tolerance
//! schedule, model selection and coverage.

use crate::support::{paper_m2_problem, rng, samples};
use bitrock::Law;
use bitrock::abc::rejection::{self, Mode, RejectionConfig};
use bitrock::abc::schedule::Schedule;
use bitrock::abc::{Run, StopReason};
use bitrock::data::Samples;
use bitrock::eval::cpu::CpuEvaluator;
use bitrock::eval::{Evaluator, Problem};
use bitrock::fit::{FitOptions, fit_laws};
use bitrock::prior::{LawBox, Prior};
use rand_distr::{Distribution, Normal};

/// One free parameter: m4 with c0 ~ U[0, 2] and c1..c3 fixed at 0, against y ≡ 1 N·m, so
/// ρ(c0) = (1 − c0)² and the accepted set at ε is |c0 − 1| < √ε.
fn one_parameter_problem(seed: u64) -> Problem {
    let prior = Prior::new(
        vec![LawBox::new(Law::M4, vec![0.0, 0.0, 0.0, 0.0], vec![2.0, 0.0, 0.0, 0.0])],
        vec![1.0],
    )
    .unwrap();
    let data = Samples::new((0..64).map(|i| 1.0 + i as f64 * 0.25).collect(), vec![1.0; 64]);
    Problem::new(prior, seed, &data, None)
}

fn same_populations(a: &Run, b: &Run) {
    assert_eq!(a.populations.len(), b.populations.len());
    for (pa, pb) in a.populations.iter().zip(&b.populations) {
        assert_eq!(pa.record.epsilon.map(f64::to_bits), pb.record.epsilon.map(f64::to_bits));
        assert_eq!(pa.record.draws, pb.record.draws);
        assert_eq!(pa.particles.len(), pb.particles.len());
        for (x, y) in pa.particles.iter().zip(&pb.particles) {
            assert_eq!((x.law, x.index, x.rho.to_bits()), (y.law, y.index, y.rho.to_bits()));
        }
    }
}

/// m2 at the paper's estimate with 5 % noise, speeds 0.1-20 rad/s (where m1, whose torque

#[test]
fn populations_do_not_depend_on_threads_or_batch_size() {
    let (problem, rho) = paper_m2_problem(77);
    let config = RejectionConfig::from(Schedule {
        particles: 600,
        eps_min: rho * 1.5,
        max_batch: 1 << 20,
        ..Schedule::default()
    });
    let single = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
    let double = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();
    let evaluator = CpuEvaluator::new(problem);
    let a = single.install(|| rejection::run(&evaluator, &config)).unwrap();
    let b = double
        .install(|| {
            rejection::run(
                &evaluator,
                &RejectionConfig::from(Schedule {
                    max_batch: 1000,
                    ..config.schedule.clone()
                }),
            )
        })
        .unwrap();
    assert!(a.populations.len() >= 3, "{}", a.populations.len());
    same_populations(&a, &b);
}

#[test]
fn the_accepted_set_is_the_closed_form_one_and_the_schedule_is_the_median() {
    for mode in [Mode::Nested, Mode::Paper] {
        let problem = one_parameter_problem(5);
        let evaluator = CpuEvaluator::new(problem.clone());
        let config = RejectionConfig {
            schedule: Schedule {
                particles: 501,
                eps_min: 1e-6,
                max_populations: 6,
                ..Schedule::default()
            },
            mode,
        };
        let run = rejection::run(&evaluator, &config).unwrap();
        assert_eq!(run.populations.len(), 6);
        assert_eq!(run.stop, StopReason::MaxPopulations);
        for (g, pop) in run.populations.iter().enumerate() {
            let eps = pop.record.epsilon.unwrap_or(f64::INFINITY);
            // Regenerate the stream independently: the population is exactly the first N
            // candidates with |c0 − 1| < √ε.
            let stream = pop.record.stream;
            let expected: Vec<u64> = (0u64..)
                .filter(|&i| {
                    let c0 = f64::from(problem.prior.candidate(problem.seed, stream, i).params[0]);
                    (1.0 - c0) * (1.0 - c0) < eps
                })
                .take(501)
                .collect();
            let got: Vec<u64> = pop.particles.iter().map(|p| p.index).collect();
            assert_eq!(got, expected, "population {g} ({mode:?})");
            for p in &pop.particles {
                assert!((p.rho - (1.0 - p.params[0]).powi(2)).abs() <= 1e-15);
            }
            assert_eq!(pop.record.draws, expected.last().unwrap() + 1);
            if g > 0 {
                // ε_g is exactly the median of population g-1 (N odd: the middle value).
                let mut previous: Vec<f64> = run.populations[g - 1].particles.iter().map(|p| p.rho).collect();
                previous.sort_by(f64::total_cmp);
                assert_eq!(eps.to_bits(), previous[250].to_bits(), "population {g}");
            }
        }
    }
}

/// Two-sample Kolmogorov-Smirnov statistic.
fn ks_statistic(a: &[f64], b: &[f64]) -> f64 {
    let (mut a, mut b) = (a.to_vec(), b.to_vec());
    a.sort_by(f64::total_cmp);
    b.sort_by(f64::total_cmp);
    let (mut i, mut j, mut d) = (0, 0, 0.0f64);
    while i < a.len() && j < b.len() {
        if a[i] <= b[j] {
            i += 1;
        } else {
            j += 1;
        }
        d = d.max((i as f64 / a.len() as f64 - j as f64 / b.len() as f64).abs());
    }
    d
}

#[test]
fn nested_and_paper_modes_sample_the_same_distribution_with_fewer_evaluations() {
    let problem = one_parameter_problem(8);
    let evaluator = CpuEvaluator::new(problem);
    let epsilons = Some(vec![0.25, 0.04, 0.01]);
    let base = RejectionConfig::from(Schedule {
        particles: 4000,
        eps_min: 0.0,
        epsilons,
        ..Schedule::default()
    });
    let nested = rejection::run(
        &evaluator,
        &RejectionConfig {
            schedule: Schedule {
                ..base.schedule.clone()
            },
            mode: Mode::Nested,
        },
    )
    .unwrap();
    let paper = rejection::run(
        &evaluator,
        &RejectionConfig {
            schedule: Schedule { ..base.schedule },
            mode: Mode::Paper,
        },
    )
    .unwrap();
    assert_eq!(nested.stop, StopReason::ScheduleExhausted);
    let last = |r: &Run| {
        r.populations
            .last()
            .unwrap()
            .particles
            .iter()
            .map(|p| p.params[0])
            .collect::<Vec<_>>()
    };
    let (a, b) = (last(&nested), last(&paper));
    // KS at α = 0.001 for n = m = 4000: critical value 1.95 √(2/4000) ≈ 0.0436.
    let d = ks_statistic(&a, &b);
    assert!(d < 0.0436, "KS statistic {d}");
    // Both are uniform on (0.9, 1.1): compare with an exact uniform grid the same way.
    let uniform: Vec<f64> = (0..4000).map(|i| 0.9 + 0.2 * (i as f64 + 0.5) / 4000.0).collect();
    assert!(ks_statistic(&a, &uniform) < 0.0436 && ks_statistic(&b, &uniform) < 0.0436);
    // The prior is (0, 2) and ρ = (c − 1)²: the last tolerance 0.01 keeps |c − 1| ≤ 0.1.
    assert!(a.iter().chain(&b).all(|&c| (c - 1.0).abs() <= 0.1));
    // The nested run scores each candidate once.
    assert!(
        nested.evaluations < paper.evaluations,
        "{} vs {}",
        nested.evaluations,
        paper.evaluations
    );
}

#[test]
fn model_selection_prefers_the_generating_law() {
    let (problem, rho) = paper_m2_problem(3);
    let evaluator = CpuEvaluator::new(problem);
    let config = RejectionConfig::from(Schedule {
        particles: 2000,
        eps_min: rho * 1.5,
        ..Schedule::default()
    });
    let run = rejection::run(&evaluator, &config).unwrap();
    let last = run.populations.last().unwrap();
    let prob = |law: Law| last.record.per_law.iter().find(|l| l.law == law).unwrap().probability;
    let p2 = prob(Law::M2);
    for other in [Law::M1, Law::M3, Law::M4] {
        assert!(
            p2 > prob(other),
            "m2 {p2} vs {other} {}: {:?}",
            prob(other),
            last.record.per_law
        );
    }
    let total: f64 = last.record.per_law.iter().map(|l| l.probability).sum();
    assert!((total - 1.0).abs() < 1e-12);
}

#[test]
fn posterior_intervals_cover_the_generating_parameters() {
    for law in Law::ALL {
        let truth = law.scale_torque(law.paper_estimate().unwrap(), 1000.0);
        let mut data = samples(law, &truth, 0.5, 20.0, 600);
        let mut g = rng(31 + law.index() as u64);
        let noise = Normal::new(0.0, 200.0).unwrap();
        for y in &mut data.torque_nm {
            *y += noise.sample(&mut g);
        }
        let fits = fit_laws(&[law], &data, &Samples::default(), &FitOptions::default()).unwrap();
        let prior = Prior::from_fits(&fits, 0.4, None, 1000.0).unwrap();
        let rho_fit = fits[0].rho;
        let evaluator = CpuEvaluator::new(Problem::new(prior, 4, &data, None));
        let config = RejectionConfig::from(Schedule {
            particles: 2000,
            eps_min: rho_fit * 1.3,
            ..Schedule::default()
        });
        let run = rejection::run(&evaluator, &config).unwrap();
        let particles = &run.populations.last().unwrap().particles;
        for (j, &t) in truth.iter().enumerate() {
            let v: Vec<f64> = particles.iter().map(|p| p.params[j]).collect();
            let (lo, hi) = (
                bitrock::numerics::quantile(&v, 0.01),
                bitrock::numerics::quantile(&v, 0.99),
            );
            assert!(
                lo <= t && t <= hi,
                "{law}.{}: truth {t} outside [{lo}, {hi}]",
                law.params()[j].name
            );
        }
    }
}

#[test]
fn cpu_rho_agrees_with_the_reference_misfit() {
    let (problem, _) = paper_m2_problem(9);
    let evaluator = CpuEvaluator::new(problem.clone());
    let mut rho = vec![0.0; 2000];
    evaluator.score(4, 1000, &mut rho).unwrap();
    for (k, &r) in rho.iter().enumerate() {
        let c = problem.prior.candidate(problem.seed, 4, 1000 + k as u64);
        let law = problem.prior.law(c.slot);
        let p: Vec<f64> = c.params[..law.n_params()].iter().map(|&v| f64::from(v)).collect();
        let reference = bitrock::fit::misfit(
            law,
            &p,
            &problem.speed_rad_s,
            &problem.torque_nm,
            &problem.wob_ratio,
            problem.sum_sq_torque,
        );
        assert!((r - reference).abs() <= 1e-13 * reference, "{law}: {r} vs {reference}");
    }
}
