//! `bitrock check-selection`: known answers of the confusion matrix (two laws the data cannot
//! tell apart, one that fits far better), a law that died out generating from its least-squares
//! estimate, replicates independent of the batch and of the backend, the prior file read from
//! the store, and bad input refused with nothing written.

use crate::gpu::{per_shape, require_gpu};
use crate::support::{bin, rng};
use bitrock::Law;
use bitrock::abc::Silent;
use bitrock::abc::rejection::RejectionConfig;
use bitrock::abc::schedule::Schedule;
use bitrock::data::{DataOptions, parse_field_data};
use bitrock::eval::Backend;
use bitrock::eval::gpu::{self, Shape};
use bitrock::run::selection::{self, CheckOptions, CheckedRun, ParamSource, SelectionCheck};
use bitrock::run::{self, abc::SamplerConfig};
use rand_distr::{Distribution, Normal};
use std::path::{Path, PathBuf};

/// A record in N·m and rad/s: `torque(w)` plus Gaussian noise of `sigma_nm`, 400 speeds
/// evenly spread over 1..20 rad/s, interleaved calibration and validation halves.
fn record(torque: impl Fn(f64) -> f64, sigma_nm: f64, seed: u64) -> bitrock::data::FieldData {
    let mut g = rng(seed);
    let noise = Normal::new(0.0, sigma_nm).unwrap();
    let mut csv = String::from("speed_rad_s,torque_nm\n");
    for i in 0..400 {
        let w = 1.0 + 19.0 * i as f64 / 399.0;
        csv.push_str(&format!("{w},{}\n", torque(w) + noise.sample(&mut g)));
    }
    let options = DataOptions {
        split: bitrock::data::SplitRule::Interleaved,
        ..DataOptions::default()
    };
    parse_field_data(csv.as_bytes(), Path::new("synthetic.csv"), &options).unwrap()
}

/// Runs rejection ABC of `laws` on `data` into `dir/run` (CPU, N particles, down to eps_min).
fn run_dir(
    dir: &Path,
    data: bitrock::data::FieldData,
    laws: &[Law],
    particles: usize,
    eps_min: f64,
    prior_file: Option<PathBuf>,
) -> PathBuf {
    let sampler = SamplerConfig::Rejection(RejectionConfig::from(Schedule {
        particles,
        eps_min,
        ..Schedule::default()
    }));
    run_dir_with(dir, data, laws, sampler, prior_file)
}

/// Runs ABC of `laws` on `data` with `sampler` into `dir/run` (CPU, seed 3).
fn run_dir_with(
    dir: &Path,
    data: bitrock::data::FieldData,
    laws: &[Law],
    sampler: SamplerConfig,
    prior_file: Option<PathBuf>,
) -> PathBuf {
    let path = dir.join("run");
    run::abc::Job {
        config: run::abc::Config {
            laws: laws.to_vec(),
            backend: Backend::Cpu,
            seed: 3,
            prior_file,
            sampler,
            ..run::abc::Config::default()
        },
        summary_population: None,
        out: Some(run::Dir {
            path: path.clone(),
            replace: false,
        }),
    }
    .run(data, Default::default(), &mut Silent)
    .unwrap();
    path
}

fn check(dir: &Path, replicates: usize, batch: Option<usize>) -> SelectionCheck {
    let run = CheckedRun::open(dir).unwrap();
    let options = CheckOptions {
        replicates,
        backend: None,
        batch,
    };
    let check = selection::check(&run, &options, &|_, _| {}, &mut |_| {}).unwrap();
    bitrock::report::write_selection(&run, &check).unwrap();
    check
}

/// m2 with a sharp decay (g = 1 s/rad) over 1..20 rad/s, 100 N·m of noise, against m4: the
/// cubic cannot follow the exponential (its best ρ lies near ε_min = 1e-3, so that only a few of
/// its candidates are ever accepted; m2's is about 2e-4).
fn m2_beats_m4(dir: &Path) -> PathBuf {
    let data = record(|w| 6.5e3 * (-w).exp() + 6.5e3, 100.0, 17);
    run_dir(dir, data, &[Law::M2, Law::M4], 200, 1e-3, None)
}

#[test]
fn a_law_that_fits_far_better_is_recovered_in_every_replicate() {
    let dir = tempfile::tempdir().unwrap();
    let run = m2_beats_m4(dir.path());
    let c = check(&run, 4, None);
    let m2 = &c.rows[0];
    assert_eq!(m2.law, Law::M2);
    assert_eq!(m2.source, ParamSource::Posterior);
    assert_eq!(m2.first_share, vec![1.0, 0.0]);
    assert!(
        m2.replicates
            .iter()
            .all(|r| r.first == Law::M2 && r.probabilities[0] >= 0.9),
        "{:?}",
        m2.replicates
            .iter()
            .map(|r| (&r.probabilities, r.final_epsilon))
            .collect::<Vec<_>>()
    );
    // What was written is what was returned, and the report shows it.
    assert_eq!(selection::read(&run).unwrap().as_ref(), Some(&c));
    for name in ["matrix.csv", "replicates.csv", "confusion.svg", "confusion.png"] {
        assert!(run.join("selection").join(name).is_file(), "{name}");
    }
    let (setup, runs) = bitrock::report::read_run_dirs(std::slice::from_ref(&run)).unwrap();
    assert_eq!(
        runs[0].selection.as_ref(),
        Some(&(c.clone(), None)),
        "a fresh check is not stale"
    );
    let report =
        bitrock::report::write_paper_report(&dir.path().join("report"), &setup, &runs, None, Default::default())
            .unwrap();
    let md = std::fs::read_to_string(report.dir.join("report.md")).unwrap();
    assert!(md.contains("## Can the selection be trusted?"), "{md}");
    assert!(md.contains(&c.rows[0].verdict));
    assert!(report.figures.iter().any(|f| f.stem == "fig10_selection_1"));
}

#[test]
fn replicates_do_not_depend_on_the_batch() {
    let dir = tempfile::tempdir().unwrap();
    let run = m2_beats_m4(dir.path());
    let one_at_a_time = check(&run, 3, Some(1));
    let all_at_once = check(&run, 3, None);
    let replicates = |c: &SelectionCheck| c.rows.iter().map(|r| r.replicates.clone()).collect::<Vec<_>>();
    assert_eq!(replicates(&one_at_a_time), replicates(&all_at_once));
}

/// An SMC run's replicates are SMC runs: their perturbed proposals go through the batches as
/// explicit candidates, and the replicates do not depend on the batch either.
#[test]
fn an_smc_run_is_checked_with_smc_for_any_batch() {
    let dir = tempfile::tempdir().unwrap();
    let data = record(|w| 6.5e3 * (-w).exp() + 6.5e3, 100.0, 17);
    let sampler = SamplerConfig::Smc(bitrock::abc::smc::SmcConfig {
        schedule: Schedule {
            particles: 200,
            eps_min: 1e-3,
            ..Schedule::default()
        },
        ..Default::default()
    });
    let path = run_dir_with(dir.path(), data, &[Law::M2, Law::M4], sampler, None);
    let one_at_a_time = check(&path, 2, Some(1));
    let all_at_once = check(&path, 2, None);
    let replicates = |c: &SelectionCheck| c.rows.iter().map(|r| r.replicates.clone()).collect::<Vec<_>>();
    assert_eq!(replicates(&one_at_a_time), replicates(&all_at_once));
    // Every replicate ran SMC populations after its rejection population 0.
    for row in &all_at_once.rows {
        for r in &row.replicates {
            assert!(r.populations >= 2, "{r:?}");
        }
    }
    assert!(all_at_once.timing.batches >= 2);
}

#[test]
fn two_laws_the_data_cannot_tell_apart_give_a_symmetric_matrix() {
    // A constant torque of 10 kN·m with 300 N·m of noise. The prior file makes m2 and m4 the same
    // family of candidates: m2 decays within 1/50 rad/s (e^{-50} at the slowest sample) to its
    // dynamic torque tcb, m4's slope terms are below 1e-9, and tcb and c0 share one box.
    let dir = tempfile::tempdir().unwrap();
    let prior = dir.path().join("prior.toml");
    std::fs::write(
        &prior,
        "[m2]\ntsb = [9000.0, 11000.0]\ntcb = [9000.0, 11000.0]\ng = [50.0, 51.0]\n\
         [m4]\nc0 = [9000.0, 11000.0]\nc1 = [0.0, 1e-9]\nc2 = [0.0, 1e-9]\nc3 = [0.0, 1e-9]\n",
    )
    .unwrap();
    let data = record(|_| 1e4, 300.0, 5);
    // ε_min = 0.002 accepts |c − 10⁴| ≲ 330 N·m: a third of the box, so acceptance decides.
    let run = run_dir(dir.path(), data, &[Law::M2, Law::M4], 400, 0.002, Some(prior));
    let k = 8;
    let c = check(&run, k, None);
    // Each replicate's P(m2) is a binomial share of 400 particles (σ ≤ 0.025); a row's mean over
    // 8 replicates has σ ≤ 0.009 and the difference of two such means σ ≤ 0.013: 0.05 is ≥ 4σ.
    let m = |i: usize, j: usize| c.rows[i].mean_probability[j];
    assert!(
        (m(0, 1) - m(1, 0)).abs() < 0.05,
        "{:?}",
        c.rows.iter().map(|r| &r.mean_probability).collect::<Vec<_>>()
    );
    for i in 0..2 {
        for j in 0..2 {
            assert!((m(i, j) - 0.5).abs() < 0.05, "row {i} column {j}: {}", m(i, j));
        }
    }
}

/// Runs `bitrock args...`: (exit status, stderr).
fn run_bin(args: &[&str]) -> (i32, String) {
    let out = bin().args(args).output().unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// Every path under `dir`, sorted.
fn listing(dir: &Path) -> Vec<PathBuf> {
    let mut all: Vec<PathBuf> = std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().path()).collect();
    all.sort();
    all
}

#[test]
fn bad_input_is_refused_with_exit_2_and_nothing_written() {
    let dir = tempfile::tempdir().unwrap();
    // Not a run.
    let empty = dir.path().join("empty");
    std::fs::create_dir(&empty).unwrap();
    let (code, stderr) = run_bin(&["check-selection", empty.to_str().unwrap()]);
    assert_eq!(code, 2, "{stderr}");
    assert!(stderr.contains("not a bitrock run directory"), "{stderr}");
    assert!(listing(&empty).is_empty());
    // K = 0, on a real run.
    let run = m2_beats_m4(dir.path());
    let before = listing(&run);
    let (code, stderr) = run_bin(&["check-selection", run.to_str().unwrap(), "--replicates", "0"]);
    assert_eq!(code, 2, "{stderr}");
    assert!(stderr.contains("--replicates"), "{stderr}");
    assert_eq!(listing(&run), before);
    // A run whose laws all died before its first population (the draw budget ran out in it).
    let dead = dir.path().join("dead");
    let (code, stderr) = run_bin(&[
        "abc",
        "--out",
        dead.to_str().unwrap(),
        "--particles",
        "1000",
        "--start-epsilon",
        "0.0145",
        "--max-draws",
        "1000",
        "--backend",
        "cpu",
        "-q",
    ]);
    assert_eq!(code, 3, "{stderr}");
    let before = listing(&dead);
    let (code, stderr) = run_bin(&["check-selection", dead.to_str().unwrap()]);
    assert_eq!(code, 2, "{stderr}");
    assert!(stderr.contains("no completed population"), "{stderr}");
    assert_eq!(listing(&dead), before);
}

#[test]
fn a_law_that_died_out_generates_from_its_least_squares_estimate() {
    // m4 has prior weight 1e-9 (one Philox word in 2³² picks it): no m4 candidate is ever
    // drawn, so m4 has no particle in the last population, in the run and in every replicate.
    let dir = tempfile::tempdir().unwrap();
    let prior = dir.path().join("prior.toml");
    std::fs::write(&prior, "[weights]\nm2 = 1.0\nm4 = 1e-9\n").unwrap();
    let data = record(|w| 6.5e3 * (-w).exp() + 6.5e3, 100.0, 17);
    let run = run_dir(dir.path(), data, &[Law::M2, Law::M4], 200, 1e-3, Some(prior));
    let checked = CheckedRun::open(&run).unwrap();
    let last = checked.stored.populations.last().unwrap();
    assert!(last.particles.iter().all(|p| p.law == Law::M2));
    let m4_estimate = checked
        .stored
        .setup
        .fits
        .iter()
        .find(|f| f.law == Law::M4)
        .unwrap()
        .params_si
        .clone();
    let options = CheckOptions {
        replicates: 3,
        ..CheckOptions::default()
    };
    let c = selection::check(&checked, &options, &|_, _| {}, &mut |_| {}).unwrap();
    let (m2, m4) = (&c.rows[0], &c.rows[1]);
    assert_eq!((m2.law, m2.source), (Law::M2, ParamSource::Posterior));
    assert_eq!((m4.law, m4.source), (Law::M4, ParamSource::LeastSquares));
    for r in &m4.replicates {
        assert_eq!(r.params_si, m4_estimate, "replicate {}", r.index);
        assert_eq!(r.probabilities[1], 0.0);
    }
    // m2's replicates are drawn from its particles: each one's parameters are a particle's.
    for r in &m2.replicates {
        assert_ne!(r.params_si, m4_estimate);
        assert!(
            last.particles.iter().any(|p| p.params == r.params_si),
            "replicate {}: {:?}",
            r.index,
            r.params_si
        );
    }
    // The table says so.
    drop(checked);
    let out = bin()
        .args(["check-selection", run.to_str().unwrap(), "--replicates", "1", "-q"])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(
        stdout.contains("(the law died out: its least-squares estimate made the data)"),
        "{stdout}"
    );
}

#[test]
fn the_prior_file_is_read_from_the_store_not_from_its_path() {
    let dir = tempfile::tempdir().unwrap();
    let prior = dir.path().join("prior.toml");
    let file = "[weights]\nm2 = 3.0\n[m2]\ng = [0.5, 2.0]\n[m4]\nc0 = [5000.0, 9000.0]\n";
    std::fs::write(&prior, file).unwrap();
    let data = record(|w| 6.5e3 * (-w).exp() + 6.5e3, 100.0, 17);
    let run = run_dir(dir.path(), data, &[Law::M2, Law::M4], 200, 1e-3, Some(prior.clone()));
    // What the store keeps rebuilds the run's prior from the run's fits exactly: the given
    // boxes, their rules, and the law thresholds the weights make.
    let checked = CheckedRun::open(&run).unwrap();
    let setup = &checked.stored.setup;
    let unit = setup.data.torque_unit.newton_metres();
    let stored = bitrock::prior::PriorFile::of_prior(&setup.prior, unit);
    let original = bitrock::prior::PriorFile::read(&prior).unwrap();
    let rebuild = |f| bitrock::prior::Prior::from_fits(&setup.fits, 0.4, Some(f), unit).unwrap();
    let (from_store, from_file) = (rebuild(&stored), rebuild(&original));
    assert_eq!(from_store.boxes, from_file.boxes);
    assert_eq!(from_store.rules, from_file.rules);
    assert_eq!(from_store.thresholds, from_file.thresholds);
    assert_eq!(from_store.thresholds, setup.prior.thresholds);
    let before = selection::check(
        &checked,
        &CheckOptions {
            replicates: 2,
            ..CheckOptions::default()
        },
        &|_, _| {},
        &mut |_| {},
    )
    .unwrap();
    drop(checked);
    // Moved away, then back with other contents: the check neither needs nor reads it.
    std::fs::rename(&prior, dir.path().join("moved.toml")).unwrap();
    let moved = check(&run, 2, None);
    std::fs::write(&prior, "[weights]\nm4 = 50.0\n").unwrap();
    let changed = check(&run, 2, None);
    let replicates = |c: &SelectionCheck| c.rows.iter().map(|r| r.replicates.clone()).collect::<Vec<_>>();
    assert_eq!(replicates(&moved), replicates(&before));
    assert_eq!(replicates(&changed), replicates(&before));
}

per_shape! {
/// The check on the GPU (the shape through BITROCK_GPU_SHAPE) against the CPU: every replicate
/// whose populations had no candidate within the parity tolerance of ε on either backend has
/// the same probabilities, first law and number of populations, and its last ε within PARITY_TOLERANCE
/// (the GPU's f32 ρ sets the quantiles); a replicate with such a candidate may diverge.
fn the_check_does_not_depend_on_the_backend(shape: Shape) {
    require_gpu();
    let dir = tempfile::tempdir().unwrap();
    // m2_beats_m4's record, its run stopped at ε_min = 1.5e-3: a software driver (CI's) scores
    // the tiled shape slowly, and the agreement needs no deep tolerance.
    let data = record(|w| 6.5e3 * (-w).exp() + 6.5e3, 100.0, 17);
    let run = run_dir(dir.path(), data, &[Law::M2, Law::M4], 200, 1.5e-3, None);
    let mut checks = Vec::new();
    for backend in ["cpu", "gpu"] {
        let out = bin()
            .env(gpu::SHAPE_VAR, shape.name())
            .args(["check-selection", run.to_str().unwrap(), "--replicates", "2", "--backend", backend, "--json", "-q"])
            .output()
            .unwrap();
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        let c: SelectionCheck = serde_json::from_slice(&out.stdout).unwrap();
        assert_eq!(c.backend, backend);
        checks.push(c);
    }
    let (cpu, gpu) = (&checks[0], &checks[1]);
    let mut compared = 0;
    for (rc, rg) in cpu.rows.iter().zip(&gpu.rows) {
        for (a, b) in rc.replicates.iter().zip(&rg.replicates) {
            // The synthetic record and its fits are made on the CPU in f64: the same parameters.
            assert_eq!((a.seed, &a.params_si), (b.seed, &b.params_si));
            if a.near_threshold == 0 && b.near_threshold == 0 {
                compared += 1;
                assert_eq!((&a.probabilities, a.first, a.populations), (&b.probabilities, b.first, b.populations));
                let (ea, eb) = (a.final_epsilon.unwrap(), b.final_epsilon.unwrap());
                assert!(((ea - eb) / ea).abs() <= bitrock::eval::PARITY_TOLERANCE, "{ea} vs {eb}");
            }
        }
    }
    // Two replicates per law: a software driver (CI's) scores the tiled shape slowly.
    let populations: Vec<usize> = cpu.rows.iter().flat_map(|r| r.replicates.iter().map(|a| a.populations)).collect();
    eprintln!("{shape}: {compared} of 4 replicates had no candidate near ε on either backend; populations {populations:?}");
    assert!(compared >= 2, "only {compared} of 4 replicates comparable");
}
}

/// `auto` on a software GPU (lavapipe: CI's) scores the check's batches where the race at the
/// batch's size says, and says so; the CPU's check is then the CPU backend's exactly. A real
/// GPU is kept without a race.
#[test]
#[cfg_attr(skip_gpu_tests, ignore = "BITROCK_SKIP_GPU_TESTS=1")]
fn auto_races_the_check_s_batches_on_a_software_gpu() {
    require_gpu();
    let software = gpu::context().unwrap().info.device_type == wgpu::DeviceType::Cpu;
    let dir = tempfile::tempdir().unwrap();
    let data = record(|w| 6.5e3 * (-w).exp() + 6.5e3, 100.0, 17);
    let run = run_dir(dir.path(), data, &[Law::M2, Law::M4], 200, 1.5e-3, None);
    let check = |backend: &str| {
        let out = bin()
            .env("BITROCK_CACHE_DIR", dir.path())
            .args([
                "check-selection",
                run.to_str().unwrap(),
                "--replicates",
                "2",
                "--backend",
                backend,
                "--json",
            ])
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
        assert!(out.status.success(), "{stderr}");
        (serde_json::from_slice::<SelectionCheck>(&out.stdout).unwrap(), stderr)
    };
    let (auto, said) = check("auto");
    if !software {
        assert!(!said.contains("auto: scoring on") && auto.backend == "gpu", "{said}");
        return;
    }
    // Four records (two laws, two replicates) of 4,096 candidates a request: one race, at 16,384.
    assert_eq!(said.matches("auto: scoring on").count(), 1, "{said}");
    assert!(said.contains("a dispatch of 16384 candidates"), "{said}");
    let cpu_won = said.contains("auto: scoring on the CPU rather than");
    assert_eq!(auto.backend, if cpu_won { "cpu" } else { "gpu" }, "{said}");
    if cpu_won {
        let (cpu, _) = check("cpu");
        let replicates = |c: &SelectionCheck| c.rows.iter().map(|r| r.replicates.clone()).collect::<Vec<_>>();
        assert_eq!(replicates(&auto), replicates(&cpu));
    }
    // The race is kept beside the scoring shapes: the next check reads it, measuring nothing.
    let kept = std::fs::read_to_string(dir.path().join("gpu-shapes.json")).unwrap();
    assert!(kept.contains("16384 candidates | streams"), "{kept}");
}

#[test]
fn bench_selection_times_the_check_and_splits_its_phases() {
    let out = bin()
        .args([
            "bench",
            "--selection",
            "--quick",
            "--backend",
            "cpu",
            "--reps",
            "1",
            "--json",
        ])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let records: Vec<&str> = v["selection"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["record"].as_str().unwrap())
        .collect();
    assert_eq!(records, ["embedded", "rig", "m2", "m4"]);
    for s in v["selection"].as_array().unwrap() {
        assert_eq!(s["backend"], "cpu");
        assert_eq!(
            (
                s["laws"].as_u64(),
                s["replicates_per_law"].as_u64(),
                s["particles"].as_u64()
            ),
            (Some(4), Some(2), Some(1000))
        );
        // The embedded record keeps the paper's floor; the others' noise puts theirs above it.
        let eps_min = s["eps_min"].as_f64().unwrap();
        if s["record"] == "embedded" {
            assert_eq!(eps_min, 0.014, "{s}");
        } else {
            assert!(eps_min > 0.014, "{s}");
        }
        let seconds = s["seconds"].as_f64().unwrap();
        assert!(
            (s["replicates_per_s"].as_f64().unwrap() * seconds - 8.0).abs() < 1e-9,
            "{s}"
        );
        // The two phases are parts of the check's wall time.
        let fit_seconds = s["fit_seconds"].as_f64().unwrap();
        let phases = fit_seconds + s["sampling_seconds"].as_f64().unwrap();
        assert!(phases > 0.0 && phases <= seconds, "{s}");
        assert!(
            (s["fit_share"].as_f64().unwrap() - fit_seconds / seconds).abs() < 1e-12,
            "{s}"
        );
        assert!(s["evaluations"].as_u64().unwrap() > 0);
        // Every law is fitted to every replicate's record, from at least one start each.
        let fits = &s["fits"];
        assert_eq!(fits["fits"].as_u64(), Some(4 * 8), "{s}");
        assert!(fits["runs"].as_u64().unwrap() >= 32, "{s}");
        assert!(fits["fits_out_of_patience"].as_u64() <= fits["fits"].as_u64(), "{s}");
        // Scoring is part of the sampling; the replicates' requests go in several batches,
        // which the CPU scores without dispatches.
        let scoring = s["scoring_seconds"].as_f64().unwrap();
        assert!(
            scoring > 0.0 && scoring <= s["sampling_seconds"].as_f64().unwrap(),
            "{s}"
        );
        assert!(s["batches"].as_u64().unwrap() >= 2, "{s}");
        assert_eq!(s["dispatches"].as_u64(), Some(0), "{s}");
        assert_eq!(s["command"].is_null(), s["record"] == "embedded", "{s}");
    }
    // Only the selection section is measured.
    assert_eq!(v["throughput"], serde_json::json!([]));
}

/// The benchmark's simulated records are what its `bitrock simulate` commands write, byte for
/// byte: a user can make them and check them by hand.
#[test]
fn the_bench_records_are_what_their_simulate_commands_write() {
    use bitrock::bench::SelectionRecord;
    for record in SelectionRecord::ALL {
        let Some(command) = record.command() else {
            assert!(record.csv().unwrap().is_none());
            continue;
        };
        let args: Vec<&str> = command.split_whitespace().skip(1).collect();
        let out = bin().args(&args).output().unwrap();
        assert!(
            out.status.success(),
            "{command}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        assert!(out.stdout == record.csv().unwrap().unwrap(), "{command}");
    }
    let rig = String::from_utf8(SelectionRecord::Rig.csv().unwrap().unwrap()).unwrap();
    assert!(
        rig.starts_with("time_s,bit_speed_rpm,torque_nm,wob_n\n"),
        "{}",
        &rig[..80]
    );
}
