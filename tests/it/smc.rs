//! The SMC sampler: against closed forms and the rejection sampler (same ABC posterior at the
//! same ε, within Monte-Carlo error), determinism, continuation, dead laws.

use crate::support::paper_m2_problem;
use bitrock::Law;
use bitrock::abc::rejection::{self, RejectionConfig};
use bitrock::abc::schedule::Schedule;
use bitrock::abc::shard::Local;
use bitrock::abc::smc::{self, LawProposal, Perturbation, Refill, SmcConfig, WORTH_FLOOR};
use bitrock::abc::{Observer, Population, Run, StopReason, effective_sample_size};
use bitrock::data::{DataOptions, Samples, demo_field_data};
use bitrock::eval::Problem;
use bitrock::eval::cpu::CpuEvaluator;
use bitrock::fit::{FitOptions, fit_laws};
use bitrock::numerics::weighted_ks;
use bitrock::prior::{LawBox, Prior};

/// m4 with c0 ~ U[0, 2] and c1..c3 fixed at 0 against y ≡ 1 (ρ = (1 − c0)²), plus, with
/// prior weight `other`, an m2 law whose torque is ≥ 50 everywhere (ρ ≥ 49²): it cannot fit.
fn one_parameter_problem(seed: u64, other: Option<f64>) -> Problem {
    let mut boxes = vec![LawBox::new(Law::M4, vec![0.0, 0.0, 0.0, 0.0], vec![2.0, 0.0, 0.0, 0.0])];
    let mut weights = vec![1.0];
    if let Some(w) = other {
        boxes.push(LawBox::new(Law::M2, vec![50.0, 50.0, 0.1], vec![60.0, 60.0, 0.2]));
        weights.push(w);
    }
    let data = Samples::new((0..64).map(|i| 1.0 + i as f64 * 0.25).collect(), vec![1.0; 64]);
    Problem::new(Prior::new(boxes, weights).unwrap(), seed, &data, None)
}

/// sup |F − G| between the weighted empirical CDF of (x, w) and the CDF `g`.
fn weighted_ks_against(values: &[(f64, f64)], g: impl Fn(f64) -> f64) -> f64 {
    let mut v = values.to_vec();
    v.sort_by(|a, b| a.0.total_cmp(&b.0));
    let total: f64 = v.iter().map(|p| p.1).sum();
    let (mut below, mut d) = (0.0, 0.0f64);
    for &(x, w) in &v {
        d = d.max((below / total - g(x)).abs());
        below += w;
        d = d.max((below / total - g(x)).abs());
    }
    d
}

/// (c0, weight) of a population's particles.
fn c0(p: &Population) -> Vec<(f64, f64)> {
    p.particles.iter().map(|q| (q.params[0], q.weight)).collect()
}

fn ess(p: &Population) -> f64 {
    effective_sample_size(&p.particles.iter().map(|q| q.weight).collect::<Vec<_>>())
}

fn smc_config(particles: usize, epsilons: Option<Vec<f64>>, eps_min: f64) -> SmcConfig {
    SmcConfig {
        schedule: Schedule {
            particles,
            eps_min,
            epsilons,
            ..Schedule::default()
        },
        ..Default::default()
    }
}

type Scheme = (Refill, LawProposal, Perturbation);

/// Every refill with every law proposal (global perturbation), then the local perturbation
/// alone and with both: the classic sampler first, the default fourth.
const SCHEMES: [Scheme; 6] = [
    (Refill::Fresh, LawProposal::Kernel, Perturbation::Global),
    (Refill::Survivors, LawProposal::Kernel, Perturbation::Global),
    (Refill::Fresh, LawProposal::Worth, Perturbation::Global),
    (Refill::Survivors, LawProposal::Worth, Perturbation::Global),
    (Refill::Fresh, LawProposal::Kernel, Perturbation::Local),
    (Refill::Survivors, LawProposal::Worth, Perturbation::Local),
];

fn with_scheme(config: &SmcConfig, (refill, law_proposal, perturbation): Scheme) -> SmcConfig {
    SmcConfig {
        refill,
        law_proposal,
        perturbation,
        ..config.clone()
    }
}

#[test]
fn smc_samples_the_closed_form_posterior_and_agrees_with_rejection() {
    // At ε the ABC posterior of c0 is uniform on (1 − √ε, 1 + √ε).
    let evaluator = CpuEvaluator::new(one_parameter_problem(8, None));
    // ε falls fourfold per population (the width of the accepted set halves) to 6.1e-5,
    // where a prior draw is accepted with probability √ε = 0.8 %.
    let schedule: Vec<f64> = (1..=7).map(|g| 0.25f64.powi(g)).collect();
    let rej = rejection::run(
        &evaluator,
        &smc_config(4000, Some(schedule.clone()), 0.0).schedule.into(),
    )
    .unwrap();
    for scheme in SCHEMES {
        closed_form_and_rejection_agree(&evaluator, &rej, scheme, &schedule);
    }
}

fn closed_form_and_rejection_agree(evaluator: &CpuEvaluator, rej: &Run, scheme: Scheme, schedule: &[f64]) {
    let config = with_scheme(&smc_config(4000, Some(schedule.to_vec()), 0.0), scheme);
    let smc_run = smc::run(evaluator, &config).unwrap();
    assert_eq!(smc_run.stop, StopReason::ScheduleExhausted);
    assert_eq!(smc_run.populations.len(), 8);
    for (g, (s, r)) in smc_run.populations.iter().zip(&rej.populations).enumerate().skip(1) {
        let eps = s.record.epsilon.unwrap();
        let h = eps.sqrt();
        let n_eff = ess(s);
        assert!(
            (s.record.ess - n_eff).abs() < 1e-9 && n_eff > 0.5 * 4000.0,
            "{scheme:?}: ESS {n_eff}"
        );
        // Weighted one-sample KS against the closed form, with the Kish ESS as sample size:
        // critical value at α = 0.001 is 1.95 / √ESS.
        let d = weighted_ks_against(&c0(s), |x| ((x - (1.0 - h)) / (2.0 * h)).clamp(0.0, 1.0));
        assert!(
            d < 1.95 / n_eff.sqrt(),
            "{scheme:?} population {g}: KS {d} (ESS {n_eff})"
        );
        // Two-sample against rejection at the same ε: 1.95 √(1/ESS + 1/N).
        let d2 = weighted_ks(&c0(s), &c0(r));
        assert!(
            d2 < 1.95 * (1.0 / n_eff + 1.0 / 4000.0).sqrt(),
            "{scheme:?} population {g}: KS {d2}"
        );
        // Weighted mean within 4 standard errors (σ = h/√3, n = ESS) of 1.
        let mean: f64 = c0(s).iter().map(|(x, w)| x * w).sum();
        assert!(
            (mean - 1.0).abs() < 4.0 * h / 3f64.sqrt() / n_eff.sqrt(),
            "{scheme:?} population {g}: {mean}"
        );
        assert!(s.particles.iter().all(|p| (p.params[0] - 1.0).abs() < h && p.rho < eps));
        let total: f64 = s.particles.iter().map(|p| p.weight).sum();
        assert!((total - 1.0).abs() < 1e-12);
    }
    // SMC scores far fewer candidates: each population accepts about a third of its
    // proposals (measured: see below), while rejection pays 1/0.8 % per particle.
    eprintln!(
        "one parameter to ε = 6.1e-5, {scheme:?}: SMC {} evaluations, rejection {}",
        smc_run.evaluations, rej.evaluations
    );
    assert!(
        smc_run.evaluations * 3 < rej.evaluations,
        "{} vs {}",
        smc_run.evaluations,
        rej.evaluations
    );
    // Population 0 is the rejection sampler's.
    let (a, b) = (&smc_run.populations[0], &rej.populations[0]);
    assert_eq!(a.particles, b.particles);
}

fn same_populations(a: &Run, b: &Run) {
    assert_eq!(a.populations.len(), b.populations.len());
    for (pa, pb) in a.populations.iter().zip(&b.populations) {
        assert_eq!(pa.record.epsilon.map(f64::to_bits), pb.record.epsilon.map(f64::to_bits));
        assert_eq!(pa.record.draws, pb.record.draws);
        assert_eq!(pa.record.per_law, pb.record.per_law);
        assert_eq!(pa.record.ess.to_bits(), pb.record.ess.to_bits());
        assert_eq!(pa.particles, pb.particles);
    }
}

/// m2 at the paper's estimate with 5 % noise against all four laws (priors from least

#[test]
fn smc_populations_do_not_depend_on_threads_or_batch_size() {
    let (problem, rho) = paper_m2_problem(77);
    let evaluator = CpuEvaluator::new(problem);
    let single = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
    let double = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();
    for scheme in SCHEMES {
        let config = with_scheme(&smc_config(500, None, rho * 1.5), scheme);
        let a = single.install(|| smc::run(&evaluator, &config)).unwrap();
        let mut small = config.clone();
        small.schedule.max_batch = 300;
        let b = double.install(|| smc::run(&evaluator, &small)).unwrap();
        assert_eq!(a.stop, StopReason::EpsMin, "{scheme:?}");
        assert!(a.populations.len() >= 4, "{scheme:?}: {}", a.populations.len());
        same_populations(&a, &b);
    }
}

/// Keeps every completed population, as a run store would.
#[derive(Default)]
struct Keep(Vec<Population>);

impl Observer for Keep {
    fn population_done(&mut self, p: &Population, _previous: Option<&Population>) -> bitrock::Result<()> {
        self.0.push(p.clone());
        Ok(())
    }
}

#[test]
fn continuing_from_completed_populations_equals_an_uninterrupted_run() {
    let (problem, rho) = paper_m2_problem(5);
    let evaluator = CpuEvaluator::new(problem);
    for scheme in SCHEMES {
        continuing_equals_uninterrupted(&evaluator, &with_scheme(&smc_config(400, None, rho * 1.5), scheme));
    }
}

fn continuing_equals_uninterrupted(evaluator: &CpuEvaluator, config: &SmcConfig) {
    let mut seen = Keep::default();
    let whole = smc::run_on(&Local(evaluator), config, Vec::new(), &mut seen).unwrap();
    assert_eq!(seen.0.len(), whole.populations.len());
    assert!(whole.populations.len() >= 4);
    for cut in [1, 3] {
        let mut limited = config.clone();
        limited.schedule.max_populations = cut;
        let first = smc::run(evaluator, &limited).unwrap();
        assert_eq!((first.populations.len(), first.stop), (cut, StopReason::MaxPopulations));
        let rest = smc::run_on(&Local(evaluator), config, first.populations, &mut Keep::default()).unwrap();
        assert_eq!(rest.stop, whole.stop);
        same_populations(&rest, &whole);
    }
}

#[test]
fn a_law_that_dies_is_recorded_dead_and_gets_no_more_proposals() {
    // m2 holds 30 % of the prior and ρ ≥ 2401, m4 ρ ≤ 1: the median of population 0 lies
    // among m4's particles, so population 1 has no m2 particle.
    let evaluator = CpuEvaluator::new(one_parameter_problem(3, Some(3.0 / 7.0)));
    let run = smc::run(&evaluator, &smc_config(1000, None, 1e-3)).unwrap();
    assert_eq!(run.stop, StopReason::EpsMin);
    let m2 = |p: &Population| p.record.per_law.iter().find(|l| l.law == Law::M2).unwrap().clone();
    let first = m2(&run.populations[0]);
    assert!(
        first.alive && first.accepted > 200 && first.probability > 0.2,
        "{first:?}"
    );
    let died = m2(&run.populations[1]);
    assert!(!died.alive && died.accepted == 0 && died.draws > 0, "{died:?}");
    assert_eq!(died.probability.to_bits(), 0.0f64.to_bits());
    for p in &run.populations[2..] {
        let l = m2(p);
        assert_eq!(
            (l.alive, l.draws, l.accepted),
            (false, 0, 0),
            "population {}",
            p.record.index
        );
        assert_eq!(l.probability.to_bits(), 0.0f64.to_bits());
        let m4 = p.record.per_law.iter().find(|l| l.law == Law::M4).unwrap();
        assert!(m4.alive && (m4.probability - 1.0).abs() < 1e-12);
    }
}

#[test]
fn refusals_name_the_flag() {
    let evaluator = CpuEvaluator::new(one_parameter_problem(1, None));
    for (config, flag) in [
        (
            SmcConfig {
                p_stay: 1.5,
                ..Default::default()
            },
            "`p_stay`:",
        ),
        (
            SmcConfig {
                kernel_scale: 0.0,
                ..Default::default()
            },
            "`kernel_scale`:",
        ),
    ] {
        let e = smc::run(&evaluator, &config).unwrap_err().to_string();
        assert!(e.starts_with(flag), "{e}");
    }
}

/// Law probabilities of a population by law.
fn probabilities(p: &Population) -> Vec<(Law, f64)> {
    p.record.per_law.iter().map(|l| (l.law, l.probability)).collect()
}

#[test]
fn on_the_embedded_record_both_samplers_give_the_same_law_probabilities() {
    let data = demo_field_data(&DataOptions::default()).unwrap();
    let fits = fit_laws(&Law::ALL, &data.calibration, &data.validation, &FitOptions::default()).unwrap();
    let prior = Prior::from_fits(&fits, 0.4, None, 1000.0).unwrap();
    let evaluator = CpuEvaluator::new(Problem::new(prior, 12, &data.calibration, None).with_best_rho(&fits));
    let n = 1500;
    // The rejection run's median schedule, given to both: the same ε in every population.
    let rej = rejection::run(
        &evaluator,
        &RejectionConfig::from(Schedule {
            particles: n,
            eps_min: 0.02,
            ..Schedule::default()
        }),
    )
    .unwrap();
    let schedule: Vec<f64> = rej.populations[1..].iter().map(|p| p.record.epsilon.unwrap()).collect();
    for scheme in [SCHEMES[0], SCHEMES[3], SCHEMES[5]] {
        let config = with_scheme(&smc_config(n, Some(schedule.clone()), 0.02), scheme);
        law_probabilities_agree(&evaluator, &rej, &config, n);
    }
}

fn law_probabilities_agree(evaluator: &CpuEvaluator, rej: &Run, config: &SmcConfig, n: usize) {
    let smc_run = smc::run(evaluator, config).unwrap();
    assert_eq!(smc_run.populations.len(), rej.populations.len());
    let (s, r) = (smc_run.populations.last().unwrap(), rej.populations.last().unwrap());
    assert_eq!(s.record.epsilon.map(f64::to_bits), r.record.epsilon.map(f64::to_bits));
    // Per law: |p_smc − p_rej| ≤ 4 √(p(1 − p) (1/ESS + 1/N)), p the pooled estimate.
    let n_eff = s.record.ess;
    for ((law, ps), (_, pr)) in probabilities(s).into_iter().zip(probabilities(r)) {
        let p = (ps + pr) / 2.0;
        let se = (p * (1.0 - p) * (1.0 / n_eff + 1.0 / n as f64)).sqrt();
        eprintln!("{law}: SMC {ps:.4} rejection {pr:.4} (4 SE {:.4})", 4.0 * se);
        assert!(
            (ps - pr).abs() <= 4.0 * se.max(1e-3),
            "{:?} {law}: {ps} vs {pr} (SE {se})",
            (config.refill, config.law_proposal, config.perturbation)
        );
    }
    eprintln!(
        "N = {n}, {:?}, {} populations to ε = {:.4}: SMC {:.3e} evaluations, rejection {:.3e}",
        (config.refill, config.law_proposal, config.perturbation),
        s.record.index + 1,
        s.record.epsilon.unwrap(),
        smc_run.evaluations as f64,
        rej.evaluations as f64
    );
}

#[test]
fn survivors_stay_with_their_weights_and_the_rates_are_the_top_ups() {
    let (problem, rho) = paper_m2_problem(9);
    let evaluator = CpuEvaluator::new(problem);
    let n = 600;
    let config = with_scheme(
        &smc_config(n, None, rho * 1.5),
        (Refill::Survivors, LawProposal::Kernel, Perturbation::Global),
    );
    let run = smc::run(&evaluator, &config).unwrap();
    assert!(run.populations.len() >= 4);
    for pair in run.populations.windows(2) {
        let (before, after) = (&pair[0], &pair[1]);
        let eps = after.record.epsilon.unwrap();
        let survivors: Vec<_> = before.particles.iter().filter(|p| p.rho < eps).collect();
        let s = survivors.len();
        assert!(s > 0 && s < n, "{s}");
        assert_eq!(after.particles.len(), n);
        assert_eq!(after.record.accepted, n);
        // The leading particles are the survivors, in their order, weights scaled by one factor.
        let factor = after.particles[0].weight / survivors[0].weight;
        for (p, q) in after.particles.iter().zip(&survivors) {
            assert_eq!((p.law, p.index, p.rho.to_bits()), (q.law, q.index, q.rho.to_bits()));
            assert_eq!(p.params, q.params);
            assert!(
                (p.weight / q.weight - factor).abs() < 1e-12 * factor,
                "{} {}",
                p.weight,
                q.weight
            );
        }
        // The new particles lie below ε too; all weights sum to 1.
        assert!(after.particles.iter().all(|p| p.rho < eps));
        let total: f64 = after.particles.iter().map(|p| p.weight).sum();
        assert!((total - 1.0).abs() < 1e-12, "{total}");
        // The survivors' share of the weight is their ESS's share of the two ESSs.
        let ess_of = |w: Vec<f64>| effective_sample_size(&w);
        let (ess_old, ess_new) = (
            ess_of(survivors.iter().map(|p| p.weight).collect()),
            ess_of(after.particles[s..].iter().map(|p| p.weight).collect()),
        );
        let share: f64 = after.particles[..s].iter().map(|p| p.weight).sum();
        assert!((share - ess_old / (ess_old + ess_new)).abs() < 1e-9, "{share}");
        // The acceptance rates are the top-up's.
        let new = (n - s) as f64;
        assert!((after.record.acceptance_rate - new / after.record.draws as f64).abs() < 1e-15);
        let per_law_new: usize = after
            .record
            .per_law
            .iter()
            .map(|l| (l.acceptance_rate * l.draws as f64).round() as usize)
            .sum();
        assert_eq!(per_law_new, n - s);
        assert_eq!(after.record.per_law.iter().map(|l| l.accepted).sum::<usize>(), n);
    }
}

#[test]
fn worth_proposes_no_law_that_cannot_reach_epsilon_and_floors_the_others() {
    // m2 cannot fit (ρ ≥ 49²) and its best least-squares ρ says so: proposed by worth, it gets
    // no proposal after population 0; the model kernel still proposes it half the time.
    let mut problem = one_parameter_problem(3, Some(1.0));
    problem.best_rho.insert(Law::M2, 49.0 * 49.0);
    let evaluator = CpuEvaluator::new(problem);
    let draws_of = |run: &Run, g: usize, law: Law| {
        run.populations[g]
            .record
            .per_law
            .iter()
            .find(|l| l.law == law)
            .unwrap()
            .draws
    };
    let config = smc_config(1000, Some(vec![0.5, 0.1]), 0.0);
    let worth = smc::run(
        &evaluator,
        &with_scheme(&config, (Refill::Fresh, LawProposal::Worth, Perturbation::Global)),
    )
    .unwrap();
    assert_eq!(draws_of(&worth, 1, Law::M2), 0);
    let kernel = smc::run(
        &evaluator,
        &with_scheme(&config, (Refill::Fresh, LawProposal::Kernel, Perturbation::Global)),
    )
    .unwrap();
    let (m2, all) = (draws_of(&kernel, 1, Law::M2), kernel.populations[1].record.draws);
    // P(m2) ≈ ½ in population 0: a proposal is m2 with probability ½·0.7 + ½·0.3 = ½.
    assert!((m2 as f64 / all as f64 - 0.5).abs() < 0.1, "{m2} of {all}");
    // With two laws that can both reach ε, worth gives the one with no particle below ε its
    // floor share of the proposals: WORTH_FLOOR / 2.
    let mut reachable = one_parameter_problem(4, Some(1.0));
    reachable.best_rho.clear();
    let run = smc::run(
        &CpuEvaluator::new(reachable),
        &with_scheme(&config, (Refill::Fresh, LawProposal::Worth, Perturbation::Global)),
    )
    .unwrap();
    let (m2, all) = (draws_of(&run, 1, Law::M2), run.populations[1].record.draws);
    let expected = WORTH_FLOOR / 2.0;
    let sd = (expected * (1.0 - expected) / all as f64).sqrt();
    assert!((m2 as f64 / all as f64 - expected).abs() < 5.0 * sd, "{m2} of {all}");
}

/// Largest |correlation| between two parameters of `law`'s particles in `p` (weighted).
fn largest_correlation(p: &Population, law: Law) -> f64 {
    let members: Vec<_> = p.particles.iter().filter(|q| q.law == law).collect();
    let total: f64 = members.iter().map(|q| q.weight).sum();
    let d = law.n_params();
    let mean: Vec<f64> = (0..d)
        .map(|j| members.iter().map(|q| q.weight * q.params[j]).sum::<f64>() / total)
        .collect();
    let cov = |a: usize, b: usize| {
        members
            .iter()
            .map(|q| q.weight * (q.params[a] - mean[a]) * (q.params[b] - mean[b]))
            .sum::<f64>()
            / total
    };
    let mut largest: f64 = 0.0;
    for a in 0..d {
        for b in a + 1..d {
            largest = largest.max((cov(a, b) / (cov(a, a) * cov(b, b)).sqrt()).abs());
        }
    }
    largest
}

#[test]
fn near_the_floor_smc_keeps_a_ridge_law_as_rejection_does() {
    // An m1 record with stick-slip (bitrock simulate's m1 at the paper's estimate, 60 rpm, 240 s
    // at 10 Hz, 0.6 kN·m torque noise). m3 follows it within 0.3 % of ρ along a ridge of its δ
    // box, and near the floor (ε = 1.02 × the best least-squares ρ) it holds about a third of
    // the rejection sampler's particles: SMC, the default scheme, must keep it there too.
    let mut sim = bitrock::simulate::SimConfig::new(
        Law::M1,
        Law::M1.scale_torque(Law::M1.paper_estimate().unwrap(), 1000.0),
        60.0 * bitrock::units::RAD_S_PER_RPM,
        bitrock::laws::PAPER_W_REF_N,
    );
    sim.duration_s = 240.0;
    sim.recording.sample_hz = 10.0;
    sim.recording.noise_torque_nm = 600.0;
    sim.recording.initial = bitrock::simulate::Initial::Equilibrium {
        speed_perturbation_rad_s: bitrock::simulate::DEFAULT_KICK_RPM * bitrock::units::RAD_S_PER_RPM,
    };
    sim.recording.seed = 3;
    let trace = bitrock::simulate::simulate(&sim).unwrap();
    let mut csv = Vec::new();
    bitrock::simulate::write_csv(&trace, &mut csv).unwrap();
    let data = bitrock::data::parse_field_data(csv.as_slice(), std::path::Path::new("m1.csv"), &DataOptions::default())
        .unwrap();
    let fits = fit_laws(&Law::ALL, &data.calibration, &data.validation, &FitOptions::default()).unwrap();
    let best = fits.iter().map(|f| f.rho).fold(f64::INFINITY, f64::min);
    let prior = Prior::from_fits(&fits, 0.4, None, 1000.0).unwrap();
    let evaluator = CpuEvaluator::new(Problem::new(prior, 5, &data.calibration, None).with_best_rho(&fits));
    let n = 600;
    let schedule = vec![0.02, 0.0095, 0.0075, 0.007, 1.02 * best];
    let rej = rejection::run(
        &evaluator,
        &RejectionConfig::from(Schedule {
            particles: n,
            epsilons: Some(schedule.clone()),
            eps_min: 0.0,
            ..Schedule::default()
        }),
    )
    .unwrap();
    let last = rej.populations.last().unwrap();
    let m3 = last.record.probability_of(Law::M3);
    assert!(m3 > 0.15, "the premise: m3 holds a share near the floor ({m3})");
    assert!(
        largest_correlation(last, Law::M3) > 0.9,
        "the premise: m3's box is a ridge"
    );
    law_probabilities_agree(&evaluator, &rej, &smc_config(n, Some(schedule), 0.0), n);
}
