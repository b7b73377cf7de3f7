//! The model evidence against references computed another way: brute-force quadrature of a
//! nonlinear law's marginal likelihood, the same result from the same seed, the command line's
//! tables, JSON and refusals.

use crate::support::{bin, outcome, rng, samples};
use bitrock::Law;
use bitrock::abc::Silent;
use bitrock::abc::evidence::{self, EvidenceConfig, NoiseModel, Start, log_likelihood_constant};
use bitrock::abc::shard::Local;
use bitrock::eval::Backend;
use bitrock::eval::Problem;
use bitrock::eval::cpu::CpuEvaluator;
use bitrock::prior::{LawBox, Prior};
use bitrock::run;
use bitrock::run::evidence::{EvidenceAnalysis, EvidenceCheck, EvidenceWarning, check, fit_reference};
use bitrock::separation::UNDECIDED_NATS;
use rand_distr::{Distribution, Normal};

/// An m2 record: 60 speeds over 0.5-15 rad/s, tsb = 13 kN·m, tcb = 6.5 kN·m, g = 0.3 s/rad,
/// Gaussian noise of 1.5 kN·m (a short, noisy record, so that the posterior is wide enough
/// for a grid to resolve it).
fn noisy_m2() -> bitrock::data::Samples {
    let mut data = samples(Law::M2, &[13_000.0, 6_500.0, 0.3], 0.5, 15.0, 60);
    let noise = Normal::new(0.0, 1_500.0).unwrap();
    let mut g = rng(5);
    for y in &mut data.torque_nm {
        *y += noise.sample(&mut g);
    }
    data
}

/// ln Z of m2 on `data` over the box, and ⟨ln L⟩ over its posterior, by the midpoint rule on a
/// grid of `cells` per axis: (ln Z, ⟨ln L⟩). m2 is linear in (a, b) = (tsb − tcb, tcb) for a
/// fixed g, so S = Σ(y − a·e − b)² (e = exp(−g·w)) comes from six sums per g value and every
/// cell costs O(1).
fn quadrature(data: &bitrock::data::Samples, lower: [f64; 3], upper: [f64; 3], cells: usize) -> (f64, f64) {
    let n = data.len();
    let h: Vec<f64> = (0..3).map(|j| (upper[j] - lower[j]) / cells as f64).collect();
    let at = |j: usize, i: usize| lower[j] + (i as f64 + 0.5) * h[j];
    let (syy, sy) = (
        data.torque_nm.iter().map(|y| y * y).sum::<f64>(),
        data.torque_nm.iter().sum::<f64>(),
    );
    let half_n = n as f64 / 2.0;
    let mut terms = Vec::with_capacity(cells * cells * cells);
    for k in 0..cells {
        let g = at(2, k);
        let e: Vec<f64> = data.speed_rad_s.iter().map(|w| (-g * w).exp()).collect();
        let see: f64 = e.iter().map(|v| v * v).sum();
        let se: f64 = e.iter().sum();
        let sye: f64 = data.torque_nm.iter().zip(&e).map(|(y, v)| y * v).sum();
        for i in 0..cells {
            let tsb = at(0, i);
            for j in 0..cells {
                let tcb = at(1, j);
                let a = tsb - tcb;
                let b = tcb;
                let s = syy - 2.0 * a * sye - 2.0 * b * sy + a * a * see + 2.0 * a * b * se + b * b * n as f64;
                terms.push(-half_n * s.ln());
            }
        }
    }
    let max = terms.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let sum: f64 = terms.iter().map(|t| (t - max).exp()).sum();
    // (1/V)·Σ L·h³ = Σ L / cells³.
    let mean_l = max + (sum / (cells * cells * cells) as f64).ln();
    // The posterior's mean of ln L: each cell's ln L weighed by its L.
    let mean_ln_l = terms.iter().map(|t| (t - max).exp() * t).sum::<f64>() / sum;
    // The constant with Σy² = 1 (S, not ρ, is in the sum above).
    let constant = log_likelihood_constant(n, 1.0);
    (mean_l + constant, mean_ln_l + constant)
}

/// Asserts that `law`'s ln Z lies within three of its Monte-Carlo errors of the quadrature's
/// `reference`, an error that is positive and below 0.3 nats.
fn assert_within_errors(law: &evidence::LawEvidence, reference: f64) {
    assert!(law.ln_z_error > 0.0 && law.ln_z_error < 0.3, "{}", law.ln_z_error);
    assert!(
        (law.ln_z - reference).abs() < 3.0 * law.ln_z_error,
        "ln Z = {} ± {}, quadrature {reference}",
        law.ln_z,
        law.ln_z_error
    );
}

/// Asserts that `law`'s ln Z split into the data's part ⟨ln L⟩ and the boxes' part, the Occam
/// factor ln Z − ⟨ln L⟩, has each within 0.1 nats of the quadrature's (ln Z, ⟨ln L⟩).
fn assert_split(law: &evidence::LawEvidence, (ln_z, mean_ln_l): (f64, f64)) {
    let sampled = law.mean_ln_l.expect("a new evidence keeps ⟨ln L⟩");
    let (occam, reference_occam) = (law.ln_z - sampled, ln_z - mean_ln_l);
    eprintln!("⟨ln L⟩ = {sampled:.3} (quadrature {mean_ln_l:.3}), Occam {occam:.3} (quadrature {reference_occam:.3})");
    assert!((sampled - mean_ln_l).abs() < 0.1, "⟨ln L⟩ {sampled} vs {mean_ln_l}");
    assert!(
        (occam - reference_occam).abs() < 0.1,
        "Occam {occam} vs {reference_occam}"
    );
}

#[test]
fn the_evidence_of_a_nonlinear_law_matches_quadrature() {
    let data = noisy_m2();
    let lower = [4_000.0, 0.0, 0.02];
    let upper = [30_000.0, 12_000.0, 2.0];
    let (reference, reference_mean_ln_l) = quadrature(&data, lower, upper, 160);
    // The reference checks itself: doubling the grid moves it by far less than the tolerance.
    let (finer, finer_mean_ln_l) = quadrature(&data, lower, upper, 320);
    assert!((reference - finer).abs() < 0.01, "quadrature {reference} vs {finer}");
    assert!(
        (reference_mean_ln_l - finer_mean_ln_l).abs() < 0.01,
        "quadrature ⟨ln L⟩ {reference_mean_ln_l} vs {finer_mean_ln_l}"
    );
    let bx = LawBox::new(
        Law::M2,
        lower.iter().map(|&v| v as f32).collect(),
        upper.iter().map(|&v| v as f32).collect(),
    );
    let prior = Prior::new(vec![bx], vec![1.0]).unwrap();
    let evaluator = Local(Box::new(CpuEvaluator::new(Problem::new(prior, 1, &data, None))));
    let config = EvidenceConfig {
        particles: 400,
        islands: 8,
        seed: 11,
        ..EvidenceConfig::default()
    };
    let result = evidence::run(&evaluator, &config, &mut Silent).unwrap();
    let m2 = result.of(Law::M2).unwrap();
    eprintln!(
        "m2: ln Z = {:.3} ± {:.3}, quadrature {finer:.3}; stages {:?}",
        m2.ln_z, m2.ln_z_error, m2.stages
    );
    assert_within_errors(m2, finer);
    assert_split(m2, (finer, finer_mean_ln_l));
    // The posterior mean of the static torque lies where the likelihood puts it.
    let mean_tsb: f64 = m2.posterior.iter().map(|(p, w)| w * p[0]).sum();
    assert!((mean_tsb - 13_000.0).abs() < 3_000.0, "{mean_tsb}");

    // Started from the least-squares fit, as `bitrock evidence --start-from fit` starts: the same
    // integral, at the default particles and islands, in a fraction of the candidates.
    let fit = bitrock::fit::fit_law(Law::M2, &data, &Default::default(), &Default::default()).unwrap();
    let lag1 = bitrock::separation::residual_lag1(&fit, &data, &Default::default());
    let reference = fit_reference(&fit, NoiseModel::Iid, lag1).expect("m2's fit has a covariance");
    let from_fit_only = EvidenceConfig {
        start: Start::Fit,
        ..EvidenceConfig::default()
    };
    let started = evidence::run_from(
        &evaluator,
        &from_fit_only,
        std::slice::from_ref(&reference),
        None,
        &mut Silent,
    )
    .unwrap();
    let from_fit = started.of(Law::M2).unwrap();
    eprintln!(
        "m2 from its fit: ln Z = {:.3} ± {:.3}; stages {:?}, {} candidates against {}",
        from_fit.ln_z, from_fit.ln_z_error, from_fit.stages, from_fit.candidates_scored, m2.candidates_scored
    );
    assert_within_errors(from_fit, finer);
    // From the fit's reference too, its ln π − ln q taken back out of ⟨ln L⟩.
    assert_split(from_fit, (finer, finer_mean_ln_l));

    // From both, as `bitrock evidence` starts by default: each start's estimate, and the one
    // kept, the quadrature's.
    let both = evidence::run_from(&evaluator, &EvidenceConfig::default(), &[reference], None, &mut Silent).unwrap();
    let m2_both = both.of(Law::M2).unwrap();
    eprintln!(
        "m2 from both: ln Z = {:.3} ± {:.3}; {:?}",
        m2_both.ln_z, m2_both.ln_z_error, m2_both.starts
    );
    assert_eq!(m2_both.starts.len(), 2);
    for start in &m2_both.starts {
        assert!(
            (start.ln_z - finer).abs() < 3.0 * start.ln_z_error,
            "{start:?} against {finer}"
        );
    }
    assert_within_errors(m2_both, finer);
    assert_split(m2_both, (finer, finer_mean_ln_l));
}

#[test]
fn the_same_seed_gives_the_same_evidence_and_another_seed_agrees_within_its_error() {
    let data = noisy_m2();
    let bx = LawBox::new;
    let prior = Prior::new(
        vec![
            bx(Law::M2, vec![4e3, 0.0, 0.02], vec![3e4, 1.2e4, 2.0]),
            bx(Law::M4, vec![0.0, -4e3, -300.0, -15.0], vec![3e4, 4e3, 300.0, 15.0]),
        ],
        vec![1.0, 1.0],
    )
    .unwrap();
    let evaluator = Local(Box::new(CpuEvaluator::new(Problem::new(prior, 1, &data, None))));
    let config = |seed| EvidenceConfig {
        particles: 200,
        islands: 4,
        seed,
        ..EvidenceConfig::default()
    };
    let a = evidence::run(&evaluator, &config(2), &mut Silent).unwrap();
    let b = evidence::run(&evaluator, &config(2), &mut Silent).unwrap();
    let c = evidence::run(&evaluator, &config(3), &mut Silent).unwrap();
    for (x, y) in a.laws.iter().zip(&b.laws) {
        assert_eq!(x.ln_z.to_bits(), y.ln_z.to_bits(), "{}", x.law);
        assert_eq!(x.posterior, y.posterior, "{}", x.law);
    }
    for (x, z) in a.laws.iter().zip(&c.laws) {
        assert_ne!(
            x.ln_z.to_bits(),
            z.ln_z.to_bits(),
            "{}: another seed, other particles",
            x.law
        );
        let error = x.ln_z_error.hypot(z.ln_z_error);
        assert!(
            (x.ln_z - z.ln_z).abs() < 4.0 * error,
            "{}: {} vs {} (± {error})",
            x.law,
            x.ln_z,
            z.ln_z
        );
    }
    let total: f64 = a.laws.iter().map(|l| l.probability).sum();
    assert!((total - 1.0).abs() < 1e-12);
}

/// A record of m2 made by `bitrock simulate` in `dir`, thinned when read.
fn simulated_record(dir: &std::path::Path) -> std::path::PathBuf {
    let path = dir.join("m2.csv");
    let (code, _, err) = outcome(bin().args([
        "simulate",
        "--law",
        "m2",
        "--omega-rpm",
        "80",
        "--duration-s",
        "60",
        "--settle-s",
        "20",
        "--noise-torque-knm",
        "0.6",
        "--noise-speed-rpm",
        "0.5",
        "--seed",
        "3",
        "--out",
        path.to_str().unwrap(),
    ]));
    assert_eq!(code, 0, "{err}");
    path
}

#[test]
fn the_command_prints_the_evidence_as_json_and_tables_and_refuses_bad_settings() {
    let dir = tempfile::tempdir().unwrap();
    let record = simulated_record(dir.path());
    let args = |extra: &[&str]| {
        let mut cmd = bin();
        cmd.args(["evidence", record.to_str().unwrap(), "--laws", "m2,m4", "--thin", "4"]);
        cmd.args(["--backend", "cpu", "--particles", "100", "--islands", "3"]);
        cmd.args(extra);
        cmd
    };
    let posterior = dir.path().join("posterior.csv");
    let (code, json, err) = outcome(&mut args(&["--json", "--posterior-out", posterior.to_str().unwrap()]));
    assert_eq!(code, 0, "{err}");
    let doc: serde_json::Value = serde_json::from_str(&json).unwrap();
    let laws = doc["laws"].as_array().unwrap();
    assert_eq!(laws.len(), 2);
    // The posterior written maps with each law weighed by its P(m | y).
    let (code, maps, err) = outcome(
        bin()
            .args(["stability", "--posterior", posterior.to_str().unwrap()])
            .args([
                "--omega-rpm",
                "40:200:5",
                "--wob-kn",
                "50:500:4",
                "--samples",
                "50",
                "--backend",
                "cpu",
                "--json",
            ]),
    );
    assert_eq!(code, 0, "{err}");
    let maps: serde_json::Value = serde_json::from_str(&maps).unwrap();
    for law in laws {
        let p = law["probability"].as_f64().unwrap();
        let mapped = maps["boundaries"][law["law"].as_str().unwrap()]["probability"].as_f64();
        if p > 0.0 {
            assert!((mapped.unwrap() - p).abs() < 1e-9, "{law}: {mapped:?}");
        }
    }
    let total: f64 = laws.iter().map(|l| l["probability"].as_f64().unwrap()).sum();
    assert!((total - 1.0).abs() < 1e-12, "{total}");
    assert!(laws.iter().any(|l| l["starts"].as_array().unwrap().len() == 2));
    // Checked by default: 4 records per law, each through a lighter evidence (its islands'
    // particles capped, two islands, from its fit), and the answer says what the check said.
    let check = &doc["check"];
    assert_eq!(check["replicates"], 4);
    assert_eq!(
        check["sampler"],
        serde_json::json!({"particles": 100, "islands": 2, "start": "fit"})
    );
    assert_eq!(check["rows"].as_array().unwrap().len(), 2);
    assert_eq!(doc["answer"]["check"]["replicates"], 4, "{}", doc["answer"]);
    assert!(
        doc["answer"]["sentence"]
            .as_str()
            .unwrap()
            .contains("the check decided"),
        "{}",
        doc["answer"]
    );
    for law in laws {
        assert!(law["ln_z"].as_f64().unwrap().is_finite());
        assert!(law["ln_z_error"].as_f64().unwrap() > 0.0);
        // From both starts (the default), 3 islands each, those of each start kept; from the
        // box alone where the fit has no covariance (a parameter on its bound).
        let starts = law["starts"].as_array().unwrap();
        let kept = starts.iter().filter(|s| s["kept"].as_bool().unwrap()).count();
        assert!(starts.is_empty() || (starts.len() == 2 && kept >= 1), "{law}");
        assert_eq!(law["island_ln_z"].as_array().unwrap().len(), 3 * kept.max(1));
        let phi = law["residual_lag1"].as_f64().unwrap();
        assert!((-1.0..=1.0).contains(&phi), "{phi}");
    }
    // Both noise models compared (the record's weight on bit is constant: no scaling to
    // compare); the one reported is the more probable.
    let models = doc["noise_models"].as_array().unwrap();
    assert_eq!(models.len(), 2);
    let best = models
        .iter()
        .max_by(|a, b| {
            a["probability"]
                .as_f64()
                .unwrap()
                .total_cmp(&b["probability"].as_f64().unwrap())
        })
        .unwrap();
    assert_eq!(doc["noise_model"], best["model"]);
    assert!(doc["w_ref_kn"].is_null() && best["w_ref_kn"].is_null());
    let total: f64 = models.iter().map(|m| m["probability"].as_f64().unwrap()).sum();
    assert!((total - 1.0).abs() < 1e-12, "{total}");
    let (code, named, err) = outcome(&mut args(&["--json", "--noise", "ar1", "--check", "0"]));
    assert_eq!(code, 0, "{err}");
    let named: serde_json::Value = serde_json::from_str(&named).unwrap();
    assert!(
        named["check"].is_null() && named["answer"]["check"].is_null(),
        "{named}"
    );
    assert_eq!(named["noise_model"], "ar1");
    assert_eq!(named["noise_models"].as_array().unwrap().len(), 1);
    // Physical boxes: from the bound 0 of the static torque, in the record's kN·m.
    assert_eq!(laws[0]["lower"][0].as_f64(), Some(0.0));
    assert_eq!(doc["torque_unit"], "kN·m");
    let (code, tables, err) = outcome(&mut args(&["--check", "2"]));
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("evidence check: replicate 4/4"), "{err}");
    for row in ["m2 data: decided for m2 in", "m4 data: decided for m4 in"] {
        assert!(tables.contains(row), "{tables}");
    }
    let p_m2 = laws[0]["probability"].as_f64().unwrap();
    assert!(tables.contains(&format!("{p_m2:.4}")), "{tables}");
    assert!(tables.contains("Bayes factors of"), "{tables}");
    assert!(tables.contains("can this record tell the laws apart?"), "{tables}");
    assert!(
        tables.contains("residual lag-1 autocorrelation of the fits"),
        "{tables}"
    );
    // Both ordered pairs, each with a gap in nats and a probability of misranking; a rival of
    // fewer parameters (m2 against m4) gains less from the noise than the truth, and wins less
    // than half the records however small the gap.
    let separations = doc["separations"].as_array().unwrap();
    assert_eq!(separations.len(), 2);
    for s in separations {
        let (gap, misranking) = (s["gap_nats"].as_f64().unwrap(), s["misranking"].as_f64().unwrap());
        assert!(gap >= 0.0 && (0.0..=1.0).contains(&misranking), "{s}");
        if s["truth"] == "m4" {
            assert!(misranking < 0.5, "{s}");
        }
    }
    for (flag, value, named) in [
        ("--islands", "1", "--islands"),
        ("--prior-scale", "0", "--prior-scale"),
        ("--particles", "5", "--particles"),
        ("--max-stages", "0", "--max-stages"),
        ("--check", "two", "--check"),
        ("--noise", "ar2", "--noise"),
    ] {
        let (code, out, err) = outcome(&mut args(&[flag, value]));
        assert_eq!(code, 2, "{flag} {value}: {err}");
        assert!(out.is_empty(), "{out}");
        assert!(err.contains(named), "{flag} {value}: {err}");
    }
}

/// A record in N·m and rad/s at kN·m scale: `law` at `params` plus Gaussian noise of 0.6 kN·m
/// (the reference's noise floor), 400 speeds evenly spread over 0.2..20 rad/s, interleaved
/// calibration and validation halves.
fn noisy_record(law: Law, params: &[f64], seed: u64) -> bitrock::data::FieldData {
    let data = samples(law, params, 0.2, 20.0, 400);
    let noise = Normal::new(0.0, 600.0).unwrap();
    let mut g = rng(seed);
    let mut csv = String::from("speed_rad_s,torque_nm\n");
    for (w, y) in data.speed_rad_s.iter().zip(&data.torque_nm) {
        csv.push_str(&format!("{w},{}\n", y + noise.sample(&mut g)));
    }
    let options = bitrock::data::DataOptions {
        split: bitrock::data::SplitRule::Interleaved,
        ..Default::default()
    };
    bitrock::data::parse_field_data(csv.as_bytes(), std::path::Path::new("noisy.csv"), &options).unwrap()
}

/// The evidence of `laws` on `data` (CPU, physical boxes, 2 × 200 particles) and its check
/// with `replicates` records per law.
fn checked(laws: &[Law], data: &bitrock::data::FieldData, replicates: usize) -> (EvidenceAnalysis, EvidenceCheck) {
    let job = run::evidence::Job {
        laws: laws.to_vec(),
        backend: Backend::Cpu,
        sampler: EvidenceConfig {
            particles: 200,
            islands: 2,
            seed: 11,
            ..EvidenceConfig::default()
        },
        ..run::evidence::Job::default()
    };
    let analysis = job.run(data, Default::default(), &mut Silent).unwrap();
    let check = check(
        &job,
        data,
        &analysis,
        replicates,
        &mut Default::default(),
        &mut |_, _| {},
        &mut Silent,
    )
    .unwrap();
    (analysis, check)
}

fn gap(analysis: &EvidenceAnalysis, truth: Law, rival: Law) -> f64 {
    analysis
        .separations
        .iter()
        .find(|s| s.truth == truth && s.rival == rival)
        .unwrap()
        .gap_nats
}

#[test]
fn the_evidence_ranks_a_separated_generating_law_first_and_never_decides_an_inseparable_pair_wrongly() {
    // An m3 record with a bump of 4 kN·m at 6 rad/s: m2 (no bump) cannot follow it, by far
    // more than 20 nats, while m3 holds m2 exactly (a bump of no height), so records from m2's
    // posterior are not separated from m3. m3's replicates must rank m3 first in at least 90 %
    // of cases; m2's may be undecided, never decided for m3.
    let data = noisy_record(Law::M3, &[4_000.0, 0.5, 6.0, 12_000.0, 5_000.0, 0.3], 21);
    let (analysis, check_23) = checked(&[Law::M2, Law::M3], &data, 10);
    let gaps = (gap(&analysis, Law::M3, Law::M2), gap(&analysis, Law::M2, Law::M3));
    assert!(gaps.0 >= 20.0 && gaps.1 < UNDECIDED_NATS, "{gaps:?}");
    let (m2, m3) = (&check_23.rows[0], &check_23.rows[1]);
    assert!(m3.first_share[1] >= 0.9, "{}", m3.verdict);
    for row in [m2, m3] {
        assert_eq!(row.decided_wrong, 0.0, "{}", row.verdict);
        assert!((row.decided_right + row.undecided + row.decided_wrong - 1.0).abs() < 1e-12);
        for r in &row.replicates {
            let total: f64 = r.probabilities.iter().sum();
            assert!((total - 1.0).abs() < 1e-9, "{total}");
            // Decided only where the data, not the Occam factor, put the first law ahead.
            assert!(!r.decided || r.gap_nats >= UNDECIDED_NATS, "{r:?}");
        }
    }
    // Replicates are seeded by law and index alone: a shorter check is the same replicates.
    let (_, shorter) = checked(&[Law::M2, Law::M3], &data, 3);
    for (short, long) in shorter.rows.iter().zip(&check_23.rows) {
        assert_eq!(short.replicates[..], long.replicates[..3]);
    }
}

/// A record of m2 by `bitrock simulate` at 60 rpm with 0.6 kN·m of torque noise, `duration_s`
/// long at `sample_hz`, its weight on bit fluctuating by `wob_kn` with a 5 s correlation time
/// (torque follows it: residuals correlated from one sample to the next); its path in `dir`.
fn m2_record_with_wob(dir: &std::path::Path, wob_kn: &str, duration_s: &str, sample_hz: &str) -> std::path::PathBuf {
    let path = dir.join(format!("m2-wob-{wob_kn}-{duration_s}s.csv"));
    let (code, _, err) = outcome(bin().args([
        "simulate",
        "--law",
        "m2",
        "--omega-rpm",
        "60",
        "--duration-s",
        duration_s,
        "--sample-hz",
        sample_hz,
        "--noise-torque-knm",
        "0.6",
        "--wob-fluctuation-kn",
        wob_kn,
        "--wob-correlation-s",
        "5",
        "--seed",
        "3",
        "--out",
        path.to_str().unwrap(),
    ]));
    assert_eq!(code, 0, "{err}");
    path
}

/// [`m2_record_with_wob`] over 240 s at 10 Hz, read.
fn m2_with_fluctuating_wob(dir: &std::path::Path, wob_kn: &str) -> bitrock::data::FieldData {
    let path = m2_record_with_wob(dir, wob_kn, "240", "10");
    bitrock::data::read_field_data(&path, &Default::default()).unwrap()
}

/// The model of the residuals chosen by its evidence: i.i.d. where they are independent; where
/// a fluctuating weight on bit drives the torque, the torque scaled by the record's weight on
/// bit, by tens of nats, and without that scaling AR(1) before i.i.d., again by many nats (the
/// i.i.d. model counts every sample as independent information). An i.i.d. evidence asked of
/// residuals the data would model as AR(1) is said to be so, by the data's preference, not by
/// a fixed lag-1 (the weight on bit unseen: lag-1 about 0.24, AR(1) preferred by 15 nats);
/// one of independent residuals is not.
#[test]
fn the_data_choose_the_model_of_the_residuals() {
    let dir = tempfile::tempdir().unwrap();
    let job = run::evidence::Job {
        laws: vec![Law::M2, Law::M3],
        backend: Backend::Cpu,
        sampler: EvidenceConfig {
            particles: 200,
            islands: 3,
            seed: 2,
            ..EvidenceConfig::default()
        },
        ..run::evidence::Job::default()
    };
    let steady = job
        .run(
            &m2_with_fluctuating_wob(dir.path(), "0"),
            Default::default(),
            &mut Silent,
        )
        .unwrap();
    // A constant weight on bit scales nothing: the two noise models alone.
    let rows = &steady.noise_models;
    assert_eq!(rows.len(), 2);
    assert_eq!((rows[0].model, rows[1].model), (NoiseModel::Iid, NoiseModel::Ar1));
    assert!(rows.iter().all(|r| r.w_ref_kn.is_none()));
    // φ's Occam factor, about 4 nats at this length, less what chance correlation buys back.
    let gap = rows[1].ln_evidence - rows[0].ln_evidence;
    assert!(gap < -2.0, "{gap}");
    assert_eq!(steady.evidence.config.noise, NoiseModel::Iid);
    assert_eq!(steady.fit.w_ref_n, None);
    assert!(
        steady.ar1_preference_nats.iter().all(|&n| n < 0.0),
        "{:?}",
        steady.ar1_preference_nats
    );
    let autocorrelated = |analysis: &EvidenceAnalysis| {
        analysis.warnings().into_iter().find_map(|w| match w {
            EvidenceWarning::Autocorrelated { nats, lag1 } => Some((nats, lag1)),
            _ => None,
        })
    };
    assert_eq!(autocorrelated(&steady), None);

    let driven_data = m2_with_fluctuating_wob(dir.path(), "12");
    let driven = job.run(&driven_data, Default::default(), &mut Silent).unwrap();
    let rows = &driven.noise_models;
    for row in rows {
        eprintln!(
            "{} {:?}: ln p(y | model) = {:.2} ± {:.2}, P = {:.4}",
            row.model, row.w_ref_kn, row.ln_evidence, row.ln_evidence_error, row.probability
        );
    }
    assert_eq!(rows.len(), 4);
    let (plain_iid, plain_ar1, scaled_iid) = (&rows[0], &rows[1], &rows[2]);
    assert!(plain_iid.w_ref_kn.is_none() && scaled_iid.w_ref_kn.is_some());
    assert!(
        driven.residual_lag1.iter().all(|&phi| phi.abs() < 0.15),
        "{:?}",
        driven.residual_lag1
    );
    assert!(plain_ar1.ln_evidence - plain_iid.ln_evidence > 10.0);
    assert!(scaled_iid.ln_evidence - plain_ar1.ln_evidence > 10.0);
    let w_ref_kn = driven.fit.w_ref_n.expect("the scaled torque reported") / 1000.0;
    assert_eq!(Some(w_ref_kn), scaled_iid.w_ref_kn);
    assert!((200.0..300.0).contains(&w_ref_kn), "{w_ref_kn}");
    // The reported model (the scaled torque) leaves independent residuals: nothing to say.
    assert_eq!(autocorrelated(&driven), None);

    let mut unseen = driven_data;
    unseen.calibration.wob_n = None;
    unseen.validation.wob_n = None;
    let forced = run::evidence::Job {
        noise: Some(NoiseModel::Iid),
        ..job
    }
    .run(&unseen, Default::default(), &mut Silent)
    .unwrap();
    let (nats, lag1) = autocorrelated(&forced).expect("the i.i.d. model said to be misspecified");
    // Decisive for AR(1), at a lag-1 below the 0.3 that a rule of lag-1 alone would wait for.
    assert!(nats > 10.0 && lag1 < 0.3, "{nats} nats, lag-1 {lag1}");
}

/// Which backend scores is said once, however many models of the residuals the evidence
/// compares (four on a record whose weight on bit varies, on two evaluators).
#[test]
fn the_backend_is_said_once() {
    let dir = tempfile::tempdir().unwrap();
    let path = m2_record_with_wob(dir.path(), "12", "60", "5");
    let (code, out, err) = outcome(bin().env("NODEVICE_SELECT", "1").args([
        "evidence",
        path.to_str().unwrap(),
        "--laws",
        "m2",
        "--particles",
        "40",
        "--islands",
        "2",
        "--quiet",
        "--json",
    ]));
    assert_eq!(code, 0, "{err}");
    let doc: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(doc["noise_models"].as_array().unwrap().len(), 4);
    // The GPU, the fallback to the CPU, or the race of a software GPU against the CPU.
    let said = err.matches("GPU backend").count()
        + err.matches("computing on the CPU").count()
        + err.matches("auto: scoring on").count();
    assert_eq!(said, 1, "{err}");
}

#[test]
fn an_evidence_directory_holds_the_document_and_its_posterior_and_stability_maps_it() {
    let dir = tempfile::tempdir().unwrap();
    // A weight on bit that fluctuates by 20 kN: the torque scaled by WOB / W_ref is compared
    // (and chosen where the data favour it), so the posterior may be for a W_ref of its own.
    let record = m2_record_with_wob(dir.path(), "20", "120", "10");
    let out = dir.path().join("ev");
    let evidence = |extra: &[&str]| {
        let mut cmd = bin();
        cmd.args([
            "evidence",
            record.to_str().unwrap(),
            "--laws",
            "m2,m3",
            "--noise",
            "iid",
        ]);
        cmd.args(["--backend", "cpu", "--particles", "100", "--islands", "2", "--quiet"]);
        cmd.args(extra);
        outcome(&mut cmd)
    };
    let (code, json, err) = evidence(&["--json", "--check", "0", "--out", out.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    let printed: serde_json::Value = serde_json::from_str(&json).unwrap();
    let stored: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("evidence.json")).unwrap()).unwrap();
    // The stored document is the printed one with each law's posterior sets added.
    let mut without_sets = stored.clone();
    for law in without_sets["laws"].as_array_mut().unwrap() {
        let sets = law
            .as_object_mut()
            .unwrap()
            .remove("posterior")
            .expect("posterior sets stored");
        let weights: f64 = sets["weights"]
            .as_array()
            .unwrap()
            .iter()
            .map(|w| w.as_f64().unwrap())
            .sum();
        assert!((weights - 1.0).abs() < 1e-9, "{} weights sum to {weights}", law["law"]);
    }
    assert_eq!(without_sets, printed);

    // `stability --run` on the directory is `--posterior` on its posterior.csv at the W_ref
    // its evidence chose (the paper's where it scaled nothing).
    let maps = |source: &[&str], w_ref: Option<String>| {
        let mut cmd = bin();
        cmd.args(["stability", "--json", "--backend", "cpu", "--samples", "50"]);
        cmd.args(["--omega-rpm", "40:160:4", "--wob-kn", "100:300:3"]);
        cmd.args(source);
        if let Some(w) = w_ref {
            cmd.args(["--w-ref-kn", &w]);
        }
        let (code, stdout, err) = outcome(&mut cmd);
        assert_eq!(code, 0, "{err}");
        (serde_json::from_str::<serde_json::Value>(&stdout).unwrap(), err)
    };
    let w_ref = stored["w_ref_kn"].as_f64().map(|w| w.to_string());
    let (mut from_dir, said) = maps(&["--run", out.to_str().unwrap()], None);
    let posterior = out.join("posterior.csv");
    let (from_csv, _) = maps(&["--posterior", posterior.to_str().unwrap()], w_ref.clone());
    // The directory keeps its record: the advice at the record's operating point comes with
    // the maps, which are the posterior's.
    let bit = from_dir
        .as_object_mut()
        .unwrap()
        .remove("record")
        .expect("the record's bit");
    let advice = from_dir
        .as_object_mut()
        .unwrap()
        .remove("advice")
        .expect("the record's advice");
    assert!(bit["samples"].as_u64().unwrap() > 0, "{bit}");
    assert!(advice["words"].as_str().is_some(), "{advice}");
    assert_eq!(from_dir, from_csv);
    assert_eq!(said.contains("mapped at that reference"), w_ref.is_some(), "{said}");

    // `bitrock report` draws it: each law's ln Z and P(m | y) as the document says them, the
    // posterior envelopes over the samples of data.csv, and P(m | y).
    let report = dir.path().join("report");
    let (code, _, err) = outcome(bin().args(["report", out.to_str().unwrap(), "--out", report.to_str().unwrap()]));
    assert_eq!(code, 0, "{err}");
    let md = std::fs::read_to_string(report.join("report.md")).unwrap();
    for law in stored["laws"].as_array().unwrap() {
        let line = format!(
            "| {} | {:.3} | {:.3} | {:.4} |",
            law["law"].as_str().unwrap(),
            law["ln_z"].as_f64().unwrap(),
            law["ln_z_error"].as_f64().unwrap(),
            law["probability"].as_f64().unwrap()
        );
        assert!(md.contains(&line), "{line} not in\n{md}");
    }
    let data = std::fs::read_to_string(out.join("data.csv")).unwrap();
    assert_eq!(
        data.lines().filter(|l| l.starts_with("calibration,")).count() as u64,
        stored["data_points"].as_u64().unwrap()
    );
    assert!(!md.contains("## Check by re-simulation"), "no check ran: {md}");
    for stem in ["fig01_evidence_envelopes", "fig02_evidence"] {
        for ext in ["svg", "png"] {
            assert!(
                report.join("figures").join(format!("{stem}.{ext}")).is_file(),
                "{stem}.{ext}"
            );
        }
    }
    // An evidence is reported alone.
    let (code, _, err) = outcome(bin().args(["report", out.to_str().unwrap(), record.to_str().unwrap()]));
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("is an evidence directory") && err.contains("reported alone"),
        "{err}"
    );

    // An evidence directory is not replaced without --force, and with it holds the new one.
    let (code, _, err) = evidence(&["--out", out.to_str().unwrap(), "--seed", "2"]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("--out") && err.contains("force"), "{err}");
    let (code, _, err) = evidence(&["--out", out.to_str().unwrap(), "--seed", "2", "--force"]);
    assert_eq!(code, 0, "{err}");
    let replaced: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("evidence.json")).unwrap()).unwrap();
    assert_eq!(replaced["sampler"]["seed"], 2);
    // Files bitrock did not write there are never replaced, even with --force.
    std::fs::write(out.join("notes.txt"), "mine").unwrap();
    let (code, _, err) = evidence(&["--out", out.to_str().unwrap(), "--force"]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("notes.txt"), "{err}");
    assert_eq!(std::fs::read_to_string(out.join("notes.txt")).unwrap(), "mine");
    assert_eq!(
        std::fs::read_to_string(out.join("evidence.json")).unwrap(),
        serde_json::to_string_pretty(&replaced).unwrap() + "\n"
    );
}

#[test]
fn an_evidence_directory_of_a_law_file_s_law_is_read_reported_and_mapped_without_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let law_file = dir.path().join("mine.toml");
    std::fs::copy(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/laws/stribeck.toml"),
        &law_file,
    )
    .unwrap();
    let out = dir.path().join("ev");
    let (code, _, err) = outcome(bin().args([
        "evidence",
        "--law-file",
        law_file.to_str().unwrap(),
        "--laws",
        "m2,stribeck",
        "--thin",
        "4",
        "--backend",
        "cpu",
        "--particles",
        "100",
        "--islands",
        "2",
        "--quiet",
        "--out",
        out.to_str().unwrap(),
    ]));
    assert_eq!(code, 0, "{err}");
    // The law file is gone: the directory holds its text.
    let source = std::fs::read_to_string(&law_file).unwrap();
    std::fs::remove_file(&law_file).unwrap();
    let stored: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("job.json")).unwrap()).unwrap();
    assert_eq!(stored["law_files"]["stribeck"].as_str(), Some(source.as_str()));
    assert_eq!(
        stored["law_files"].as_object().unwrap().len(),
        1,
        "only law files' laws"
    );
    let report = dir.path().join("report");
    let (code, _, err) = outcome(bin().args(["report", out.to_str().unwrap(), "--out", report.to_str().unwrap()]));
    assert_eq!(code, 0, "{err}");
    let markdown = std::fs::read_to_string(report.join("report.md")).unwrap();
    assert!(markdown.contains("stribeck"), "{markdown}");
    let (code, json, err) = outcome(bin().args([
        "stability",
        "--run",
        out.to_str().unwrap(),
        "--backend",
        "cpu",
        "--json",
    ]));
    assert_eq!(code, 0, "{err}");
    let maps: serde_json::Value = serde_json::from_str(&json).unwrap();
    assert!(maps["boundaries"].get("stribeck").is_some(), "{}", maps["boundaries"]);
    // A stored law file that no longer compiles is refused, naming the file in the directory.
    let mut broken = stored.clone();
    broken["law_files"]["stribeck"] = "name = \"stribeck\"\ntorque = \"r * (\"\n".into();
    std::fs::write(out.join("job.json"), serde_json::to_string(&broken).unwrap()).unwrap();
    let (code, _, err) = outcome(bin().args(["report", out.to_str().unwrap(), "--out", report.to_str().unwrap()]));
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("law_files/stribeck"), "{err}");
}

#[test]
fn check_selection_of_an_evidence_directory_is_the_evidence_s_own_check() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("ev");
    let evidence = |extra: &[&str]| {
        let mut cmd = bin();
        cmd.args(["evidence", "--laws", "m2,m3", "--thin", "4", "--backend", "cpu"]);
        cmd.args(["--particles", "100", "--islands", "2", "--quiet"]);
        cmd.args(extra);
        outcome(&mut cmd)
    };
    let (code, direct, err) = evidence(&["--check", "2", "--json"]);
    assert_eq!(code, 0, "{err}");
    let (code, _, err) = evidence(&["--out", out.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    let posterior = std::fs::read(out.join("posterior.csv")).unwrap();
    let check = |extra: &[&str]| {
        let mut cmd = bin();
        cmd.args(["check-selection", out.to_str().unwrap(), "--replicates", "2", "--quiet"]);
        cmd.args(extra);
        outcome(&mut cmd)
    };
    let (code, json, err) = check(&["--json"]);
    assert_eq!(code, 0, "{err}");
    // The check of the directory is the one `evidence --check` makes at the start, replicate
    // for replicate (its seconds aside), and it is written into the directory's document.
    let without_seconds = |mut v: serde_json::Value| {
        v.as_object_mut().unwrap().remove("seconds");
        v
    };
    let direct: serde_json::Value = serde_json::from_str(&direct).unwrap();
    let printed: serde_json::Value = serde_json::from_str(&json).unwrap();
    assert_eq!(
        without_seconds(direct["check"].clone()),
        without_seconds(printed.clone())
    );
    let stored: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("evidence.json")).unwrap()).unwrap();
    assert_eq!(stored["check"], printed);
    assert_eq!(
        std::fs::read(out.join("posterior.csv")).unwrap(),
        posterior,
        "the rest is kept"
    );
    // The report shows the check, a row per law that made the records, and the answer the
    // check weighed.
    let report = dir.path().join("report");
    let (code, _, err) = outcome(bin().args(["report", out.to_str().unwrap(), "--out", report.to_str().unwrap()]));
    assert_eq!(code, 0, "{err}");
    let md = std::fs::read_to_string(report.join("report.md")).unwrap();
    assert!(
        md.contains("## Check by re-simulation\n\n2 synthetic records per law"),
        "{md}"
    );
    for row in stored["check"]["rows"].as_array().unwrap() {
        let line = format!(
            "| {} | {:.0} % | {:.0} % | {:.0} % | {} |",
            row["law"].as_str().unwrap(),
            100.0 * row["decided_right"].as_f64().unwrap(),
            100.0 * row["undecided"].as_f64().unwrap(),
            100.0 * row["decided_wrong"].as_f64().unwrap(),
            row["verdict"].as_str().unwrap()
        );
        assert!(md.contains(&line), "{line} not in\n{md}");
    }
    let answer = stored["answer"]["sentence"].as_str().unwrap();
    assert!(md.contains(&format!("**Answer:** {answer}.")), "{md}");
    // The directory is still bitrock's own: replaced with --force, reported.
    let (code, _, err) = evidence(&["--out", out.to_str().unwrap(), "--force", "--seed", "9"]);
    assert_eq!(code, 0, "{err}");
    // Settings the evidence's check does not have are refused, naming them.
    let (code, _, err) = check(&["--batch", "2"]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("--batch"), "{err}");
    // A directory without its job (an earlier bitrock's) is refused, naming the file.
    std::fs::remove_file(out.join("job.json")).unwrap();
    let (code, _, err) = check(&[]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("job.json") && err.contains("without its job"), "{err}");
}

/// An evidence whose boxes and law weights come from a prior file keeps the file's text: its
/// directory is checked from it as `--check` checks it at the start, after the file is gone.
#[test]
fn an_evidence_directory_keeps_its_prior_file_and_is_checked_without_it() {
    let dir = tempfile::tempdir().unwrap();
    let prior = dir.path().join("prior.toml");
    std::fs::write(&prior, "[weights]\nm2 = 3.0\nm3 = 1.0\n[m2]\ng = [0.05, 2.0]\n").unwrap();
    let out = dir.path().join("ev");
    let evidence = |extra: &[&str]| {
        let mut cmd = bin();
        cmd.args([
            "evidence",
            "--laws",
            "m2,m3",
            "--thin",
            "4",
            "--backend",
            "cpu",
            "--noise",
            "iid",
        ]);
        cmd.args([
            "--particles",
            "100",
            "--islands",
            "2",
            "--quiet",
            "--prior",
            prior.to_str().unwrap(),
        ]);
        cmd.args(extra);
        outcome(&mut cmd)
    };
    let (code, direct, err) = evidence(&["--check", "2", "--json"]);
    assert_eq!(code, 0, "{err}");
    let (code, _, err) = evidence(&["--out", out.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    let job: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(out.join("job.json")).unwrap()).unwrap();
    assert_eq!(
        job["job"]["prior_text"],
        std::fs::read_to_string(&prior).unwrap().as_str()
    );
    // The file changes after the evidence: what the directory computes again is the one it
    // was made with.
    std::fs::write(&prior, "[weights]\nm2 = 1.0\n").unwrap();
    let (code, json, err) =
        outcome(bin().args(["check-selection", out.to_str().unwrap(), "--replicates", "2", "--json"]));
    assert_eq!(code, 0, "{err}");
    let direct: serde_json::Value = serde_json::from_str(&direct).unwrap();
    let mut printed: serde_json::Value = serde_json::from_str(&json).unwrap();
    let mut expected = direct["check"].clone();
    printed.as_object_mut().unwrap().remove("seconds");
    expected.as_object_mut().unwrap().remove("seconds");
    assert_eq!(printed, expected);
    assert!(!err.contains("differs"), "{err}");
}

/// The document of the evidence directory `out`, without its wall-clock seconds (the one thing
/// two computations of an evidence do not share).
fn stored_evidence(out: &std::path::Path) -> serde_json::Value {
    fn without_seconds(v: &mut serde_json::Value) {
        match v {
            serde_json::Value::Object(map) => {
                map.remove("seconds");
                map.values_mut().for_each(without_seconds);
            }
            serde_json::Value::Array(items) => items.iter_mut().for_each(without_seconds),
            _ => {}
        }
    }
    let text = std::fs::read_to_string(out.join("evidence.json")).unwrap();
    let mut stored: serde_json::Value = serde_json::from_str(&text).unwrap();
    without_seconds(&mut stored);
    stored
}

/// Counts an evidence's scored batches, and stops it after `stop` of them as a kill would (the
/// batch just scored lost, what was saved before it kept); `stop` 0 lets it run.
struct StopAfter {
    stop: usize,
    scored: usize,
}

impl StopAfter {
    fn new(stop: usize) -> Self {
        Self { stop, scored: 0 }
    }
}

impl bitrock::abc::Observer for StopAfter {
    fn interrupted(&mut self) -> bool {
        self.scored += 1;
        self.scored == self.stop
    }
}

/// The evidence job the resume tests stop and continue: m2 and m3 on the CPU, 2 × 100
/// particles, seed 4, each law's samplers started from `start`.
fn resumable_job(start: bitrock::abc::evidence::Start) -> run::evidence::Job {
    run::evidence::Job {
        laws: vec![Law::M2, Law::M3],
        backend: Backend::Cpu,
        sampler: EvidenceConfig {
            particles: 100,
            islands: 2,
            seed: 4,
            start,
            ..EvidenceConfig::default()
        },
        ..run::evidence::Job::default()
    }
}

/// Opens the evidence of `job` under way in `out`, saves it after every batch and stops it
/// after `batches` of them.
fn stop_after(out: &std::path::Path, job: &run::evidence::Job, batches: usize) {
    use bitrock::run::evidence::dir::Unfinished;
    let (mut unfinished, stored_job, stored_data, progress) = Unfinished::open(out).unwrap();
    assert_eq!(&stored_job, job);
    unfinished.every_s = 0.0;
    let stopped = unfinished.run(
        job,
        &stored_data,
        progress,
        Default::default(),
        &mut StopAfter::new(batches),
    );
    assert!(matches!(stopped, Err(bitrock::Error::Interrupted)), "{stopped:?}");
}

/// Writes `analysis` of `job` on `data` into the directory under way in `out`, and returns
/// the stored evidence.
fn finish(
    out: &std::path::Path,
    unfinished: bitrock::run::evidence::dir::Unfinished,
    analysis: &EvidenceAnalysis,
    job: &run::evidence::Job,
    data: &bitrock::data::FieldData,
) -> serde_json::Value {
    // As `bitrock evidence --out` writes it: with the advice at the record's operating point.
    let advice = analysis.record_advice(data, job, &mut |_| {}).unwrap();
    let document = EvidenceAnalysis::with_advice(
        analysis.document(data, &job.prior.describe(), true),
        data,
        advice.as_ref(),
    );
    unfinished.finish(&document, analysis, job, data).unwrap();
    stored_evidence(out)
}

/// An evidence stopped part-way keeps what it did in its directory, and `--resume` continues it
/// to the evidence of the uninterrupted job, bit for bit: stopped in its first part (one of
/// four: two models of the residuals, the torque scaled by the weight on bit or not), then
/// again in a later one, its state saved after every batch, then finished, scoring only the
/// batches not done (one lost per stop); stopped once and finished by the command. The
/// directory under way is refused as a new evidence's `--out`, and a finished one by
/// `--resume`; a progress file that does not read is named.
#[test]
fn an_evidence_stopped_part_way_and_resumed_is_the_uninterrupted_evidence() {
    use bitrock::run::evidence::dir::Unfinished;
    let dir = tempfile::tempdir().unwrap();
    let record = m2_record_with_wob(dir.path(), "20", "60", "10");
    let data = bitrock::data::read_field_data(&record, &Default::default()).unwrap();
    let job = resumable_job(bitrock::abc::evidence::Start::Box);
    let finished = |out: &std::path::Path, unfinished: Unfinished, analysis: &EvidenceAnalysis| {
        finish(out, unfinished, analysis, &job, &data)
    };

    let whole = dir.path().join("whole");
    let unfinished = Unfinished::start(&whole, false, &job, &data).unwrap();
    let mut all = StopAfter::new(0);
    let analysis = unfinished
        .run(&job, &data, Default::default(), Default::default(), &mut all)
        .unwrap();
    assert_eq!(analysis.noise_models.len(), 4);
    let uninterrupted = finished(&whole, unfinished, &analysis);
    assert!(!whole.join("unfinished").exists());

    // Stopped after 5 batches, then after 300 more, then finished.
    let stop = |out: &std::path::Path, batches: usize| stop_after(out, &job, batches);
    let twice = dir.path().join("twice");
    drop(Unfinished::start(&twice, false, &job, &data).unwrap());
    stop(&twice, 5);
    let progress = |out: &std::path::Path| Unfinished::open(out).unwrap().3;
    assert!(progress(&twice).done.is_empty() && progress(&twice).current.is_some());
    stop(&twice, 300);
    let done = progress(&twice).done.len();
    assert!((1..4).contains(&done), "stopped in part {} of 4", done + 1);
    let (unfinished, _, _, saved) = Unfinished::open(&twice).unwrap();
    let mut rest = StopAfter::new(0);
    let analysis = unfinished
        .run(&job, &data, saved, Default::default(), &mut rest)
        .unwrap();
    assert_eq!(finished(&twice, unfinished, &analysis), uninterrupted);
    assert_eq!(
        rest.scored,
        all.scored - (5 - 1) - (300 - 1),
        "{} batches in all",
        all.scored
    );

    // Stopped, then finished by the command.
    let out = dir.path().join("ev");
    drop(Unfinished::start(&out, false, &job, &data).unwrap());
    stop(&out, 40);

    // Under way: not a new evidence's --out, nor read as an evidence.
    let (code, _, err) = outcome(bin().args(["evidence", record.to_str().unwrap(), "--out", out.to_str().unwrap()]));
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("under way") && err.contains("--resume"), "{err}");
    let (code, _, err) = outcome(bin().args(["evidence", "--resume", out.to_str().unwrap(), "--seed", "3"]));
    assert_eq!(code, 2, "{err}");
    let (code, _, err) = outcome(bin().args(["stability", "--run", out.to_str().unwrap()]));
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("under way") && err.contains("--resume"), "{err}");

    let (code, json, err) = outcome(bin().args([
        "evidence",
        "--resume",
        out.to_str().unwrap(),
        "--json",
        "--quiet",
        "--check",
        "0",
    ]));
    assert_eq!(code, 0, "{err}");
    let printed: serde_json::Value = serde_json::from_str(&json).unwrap();
    assert_eq!(printed["laws"].as_array().unwrap().len(), 2);
    let resumed = stored_evidence(&out);
    assert_eq!(resumed, uninterrupted);
    assert!(!out.join("unfinished").exists());
    for file in ["posterior.csv", "data.csv", "record.json", "job.json"] {
        assert_eq!(
            std::fs::read(out.join(file)).unwrap(),
            std::fs::read(whole.join(file)).unwrap(),
            "{file}"
        );
    }
    let (code, _, err) = outcome(bin().args(["evidence", "--resume", out.to_str().unwrap()]));
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("finished evidence"), "{err}");

    // A progress file that does not read is named.
    let broken = dir.path().join("broken");
    let unfinished = Unfinished::start(&broken, false, &job, &data).unwrap();
    drop(unfinished);
    std::fs::write(broken.join("unfinished/progress.bin"), b"\x05not postcard").unwrap();
    let (code, _, err) = outcome(bin().args(["evidence", "--resume", broken.to_str().unwrap()]));
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("progress.bin"), "{err}");
}

/// An evidence whose samplers start from the fits is saved and resumed alike: its references
/// are not saved but made again from the job, and the resumed evidence is the uninterrupted
/// one, bit for bit, having scored only the batches not done before.
#[test]
fn an_evidence_started_from_the_fits_resumes_to_the_uninterrupted_evidence() {
    use bitrock::abc::evidence::Start;
    use bitrock::run::evidence::dir::Unfinished;
    let dir = tempfile::tempdir().unwrap();
    let record = m2_record_with_wob(dir.path(), "20", "60", "10");
    let data = bitrock::data::read_field_data(&record, &Default::default()).unwrap();
    let job = resumable_job(Start::Fit);
    let whole = dir.path().join("whole");
    let unfinished = Unfinished::start(&whole, false, &job, &data).unwrap();
    let mut all = StopAfter::new(0);
    let analysis = unfinished
        .run(&job, &data, Default::default(), Default::default(), &mut all)
        .unwrap();
    // From the fits: a few tempering steps per island.
    assert!(
        analysis.evidence.laws.iter().all(|l| l.stages.iter().all(|&s| s <= 6)),
        "{:?}",
        analysis.evidence.laws.iter().map(|l| &l.stages).collect::<Vec<_>>()
    );
    let uninterrupted = finish(&whole, unfinished, &analysis, &job, &data);

    let twice = dir.path().join("twice");
    drop(Unfinished::start(&twice, false, &job, &data).unwrap());
    let later = all.scored / 2;
    for batches in [3, later] {
        stop_after(&twice, &job, batches);
    }
    let (unfinished, _, _, saved) = Unfinished::open(&twice).unwrap();
    assert!(!saved.done.is_empty(), "the second stop lies past the first part");
    let mut rest = StopAfter::new(0);
    let analysis = unfinished
        .run(&job, &data, saved, Default::default(), &mut rest)
        .unwrap();
    assert_eq!(finish(&twice, unfinished, &analysis, &job, &data), uninterrupted);
    assert_eq!(
        rest.scored,
        all.scored - (3 - 1) - (later - 1),
        "{} batches in all",
        all.scored
    );
}

/// On a record made by m4 (its paper estimate, 60 rpm, 0.6 kN·m of noise, a fluctuating weight
/// on bit) m2 has the larger evidence, but only through its boxes: m4's curves follow the record
/// better (the data's part points to m4), and m2's smaller Occam penalty outweighs that. The
/// pair is "decided by the boxes", and no law is given more than 0.9; m2 against m1, which
/// cannot follow the record, is decided by the data. m4's prior is its box cut to the cubics
/// within twice the record's largest torque, and a box change reweighted there is what
/// sampling again with the changed box gives.
#[test]
fn a_bayes_factor_the_boxes_make_is_said_to_be_theirs() {
    let dir = tempfile::tempdir().unwrap();
    let record = dir.path().join("m4.csv");
    let (code, _, err) = outcome(bin().args([
        "simulate",
        "--law",
        "m4",
        "--omega-rpm",
        "60",
        "--duration-s",
        "240",
        "--sample-hz",
        "10",
        "--noise-torque-knm",
        "0.6",
        "--wob-fluctuation-kn",
        "10",
        "--wob-correlation-s",
        "5",
        "--seed",
        "1",
        "--out",
        record.to_str().unwrap(),
    ]));
    assert_eq!(code, 0, "{err}");
    let args = [
        "evidence",
        "--backend",
        "cpu",
        "--noise",
        "iid",
        "--scale-by-wob",
        "--laws",
        "m1,m2,m4",
    ];
    let (code, stdout, err) = outcome(bin().args(args).arg(&record).arg("--json"));
    assert_eq!(code, 0, "{err}");
    let document: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    let factors = document["bayes_factors"].as_array().unwrap();
    let pair = |against: &str| factors.iter().find(|f| f["against"] == against).unwrap();
    let number = |f: &serde_json::Value, key: &str| f[key].as_f64().unwrap();
    for f in factors {
        assert_eq!(f["favoured"], "m2", "{f}");
        // The parts add up to ln B, and each law's Occam factor is its ln Z less its ⟨ln L⟩.
        assert!(
            (number(f, "data_nats") + number(f, "boxes_nats") - number(f, "ln_b")).abs() < 1e-9,
            "{f}"
        );
    }
    for law in document["laws"].as_array().unwrap() {
        let (ln_z, mean_ln_l, occam) = (number(law, "ln_z"), number(law, "mean_ln_l"), number(law, "occam_nats"));
        assert!((ln_z - mean_ln_l - occam).abs() < 1e-9 && occam < 0.0, "{law}");
    }
    let m4 = pair("m4");
    assert!(number(m4, "ln_b") >= 1.0, "{m4}");
    assert!(number(m4, "data_nats") < -1.0 && number(m4, "boxes_nats") > 1.0, "{m4}");
    assert_eq!(m4["strength"], "decided_by_the_boxes", "{m4}");
    // Said as a warning, with its words, beside the numbers.
    let warned: Vec<&serde_json::Value> = document["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|w| w["kind"] == "decided_by_the_boxes")
        .collect();
    assert_eq!(warned.len(), 1, "{}", document["warnings"]);
    assert_eq!(
        (&warned[0]["favoured"], &warned[0]["against"]),
        (&"m2".into(), &"m4".into())
    );
    assert!(
        warned[0]["message"]
            .as_str()
            .unwrap()
            .contains("m2 leads m4 by ln B = "),
        "{}",
        warned[0]
    );
    let m1 = pair("m1");
    assert!(number(m1, "data_nats") >= 5.0, "{m1}");
    assert_eq!(m1["strength"], "very_strong", "{m1}");
    let laws = document["laws"].as_array().unwrap();
    for law in laws {
        assert!(number(law, "probability") <= 0.9, "{law}");
        // m4's prior alone is cut, keeping the box's share that the box's shape gives it on
        // any record (a grid over the unit box gives ln 0.090 = −2.41).
        let curve = &law["prior_curve"];
        if law["law"] == "m4" {
            assert_eq!(number(curve, "within"), 2.0, "{curve}");
            assert!((number(curve, "ln_share") + 2.412).abs() < 0.03, "{curve}");
            assert!(number(curve, "ln_share_error") < 0.02, "{curve}");
            // From rest to the calibration's fastest bit speed: the stick-slip's peak, above
            // 60 rpm (6.3 rad/s), on 33 speeds.
            assert_eq!(curve["speeds"], 33, "{curve}");
            assert!(curve["speeds_rad_s"][1].as_f64().unwrap() > 6.3, "{curve}");
        } else {
            assert!(curve.is_null(), "{law}");
        }
    }
    // The one answer is the pair's, with the boxes' word and why, however large ln B is.
    let answer = &document["answer"];
    assert_eq!(
        (&answer["law"], &answer["runner_up"], &answer["strength"]),
        (&"m2".into(), &"m4".into(), &"decided_by_the_boxes".into()),
        "{answer}"
    );
    assert_eq!(number(answer, "ln_b"), number(m4, "ln_b"), "{answer}");
    // The fits' gap of the pair is below 5 nats: the record cannot separate them at all.
    let why = answer["why"].as_str().unwrap();
    assert!(number(m4, "separation_nats") < 5.0, "{m4}");
    assert!(
        why.starts_with("the record does not separate m2 from m4 (the fits' gap ")
            && why.ends_with("the priors decide"),
        "{why}"
    );
    // The table says the same, with both parts beside the word, and ends with the answer.
    let (code, stdout, err) = outcome(bin().args(args).arg(&record));
    assert_eq!(code, 0, "{err}");
    let last = stdout.lines().last().unwrap();
    assert_eq!(last, format!("answer: {}", answer["sentence"].as_str().unwrap()));
    assert!(
        last.starts_with("answer: m2 over m4: decided by the boxes (the model evidence, P(m | y): "),
        "{last}"
    );
    let line = stdout.lines().find(|l| l.trim_start().starts_with("m2 vs m4")).unwrap();
    assert!(
        line.contains("decided by the boxes") && line.contains("data -") && line.contains("boxes "),
        "{line}"
    );
    assert!(
        stdout.contains("warning: m2 leads m4 by ln B = ") && stdout.contains("through the boxes, not the data"),
        "{stdout}"
    );
    // One box changed at a time, by reweighting the posterior: a single box of m2 changed
    // brings the pair within half a nat, a box of m1 does not reach m2.
    let range = &m4["sensitivity"];
    assert!(
        number(range, "lowest") < number(m4, "ln_b") && number(range, "highest") > number(m4, "ln_b"),
        "{range}"
    );
    assert!(number(&m1["sensitivity"], "lowest") > 10.0, "{m1}");

    // The reweighted changes are what sampling again with the changed box gives: m1's b3 box
    // narrowed (it cuts the posterior: ln 2 plus the log of the mass kept) and m2's decay
    // rate's widened (−ln 2), each sampled again from a prior file.
    let change = |law: &'static str, parameter: &str, factor: f64| {
        let of_law = laws.iter().find(|l| l["law"] == law).unwrap();
        let c = of_law["box_changes"]
            .as_array()
            .unwrap()
            .iter()
            .find(|c| c["parameter"] == parameter && c["factor"] == factor)
            .unwrap()
            .clone();
        (law, of_law, c)
    };
    for (law, before, c) in [change("m1", "b3", 0.5), change("m2", "g", 2.0)] {
        let shift = number(&c, "ln_z_shift");
        let prior = dir
            .path()
            .join(format!("{law}-{}.toml", c["parameter"].as_str().unwrap()));
        std::fs::write(
            &prior,
            format!(
                "[{law}]\n{} = [{}, {}]\n",
                c["parameter"].as_str().unwrap(),
                c["lower"],
                c["upper"]
            ),
        )
        .unwrap();
        let (code, stdout, err) = outcome(bin().args(args).arg(&record).arg("--json").arg("--prior").arg(&prior));
        assert_eq!(code, 0, "{err}");
        let again: serde_json::Value = serde_json::from_str(&stdout).unwrap();
        let law_again = again["laws"]
            .as_array()
            .unwrap()
            .iter()
            .find(|l| l["law"] == law)
            .unwrap();
        let sampled = number(law_again, "ln_z") - number(before, "ln_z");
        let error = number(law_again, "ln_z_error").hypot(number(before, "ln_z_error"));
        eprintln!("{law} {c}: reweighted {shift:.3}, sampled again {sampled:.3} ± {error:.3}");
        assert!(
            (sampled - shift).abs() < 0.1 + 3.0 * error,
            "{law} {c}: sampled again {sampled} ± {error}"
        );
    }
    assert!(
        number(&change("m1", "b3", 0.5).2, "ln_z_shift") < 0.67,
        "the narrowed box cuts the posterior"
    );

    // m4's c1 box halved: the cut keeps another share of the new box, and the reweighted shift
    // (ln 2, the posterior mass kept, and the shares' ratio) is what m4 alone sampled again
    // over the changed box gives, against m4 alone over its own.
    let m4 = laws.iter().find(|l| l["law"] == "m4").unwrap();
    let c1 = m4["box_changes"]
        .as_array()
        .unwrap()
        .iter()
        .find(|c| c["parameter"] == "c1" && c["factor"] == 0.5)
        .unwrap();
    let shift = number(c1, "ln_z_shift");
    let prior = dir.path().join("c1.toml");
    std::fs::write(&prior, format!("[m4]\nc1 = [{}, {}]\n", c1["lower"], c1["upper"])).unwrap();
    // The same command with m4 alone (`--laws` is its last flag).
    let mut m4_args = args.to_vec();
    *m4_args.last_mut().unwrap() = "m4";
    let alone = |extra: &[&std::ffi::OsStr]| {
        let mut cmd = bin();
        cmd.args(&m4_args).arg("--json").arg(&record).args(extra);
        let (code, stdout, err) = outcome(&mut cmd);
        assert_eq!(code, 0, "{err}");
        let doc: serde_json::Value = serde_json::from_str(&stdout).unwrap();
        doc["laws"][0].clone()
    };
    let (own, again) = (alone(&[]), alone(&["--prior".as_ref(), prior.as_os_str()]));
    assert!(
        number(&again["prior_curve"], "ln_share") > number(&own["prior_curve"], "ln_share"),
        "a narrower c1 keeps more of its box within the limit: {again}"
    );
    let sampled = number(&again, "ln_z") - number(&own, "ln_z");
    let error = number(&again, "ln_z_error").hypot(number(&own, "ln_z_error"));
    eprintln!("m4 c1 ×0.5: reweighted {shift:.3}, sampled again {sampled:.3} ± {error:.3}");
    assert!(
        (sampled - shift).abs() < 0.1 + 3.0 * error,
        "sampled again {sampled} ± {error}, reweighted {shift}"
    );
}
