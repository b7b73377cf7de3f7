//! The binary end to end: exit statuses, error messages that point at the problem, JSON keys,
//! and nothing half-written.

use crate::support::bin;
use std::io::Write;

fn run(args: &[&str]) -> (i32, String, String) {
    let out = bin().args(args).output().expect("run bitrock");
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// Runs bitrock, reads the first line of its stdout and closes the pipe, as `| head -1` does.
fn first_line_then_close(args: &[&str]) -> (String, std::process::Output) {
    use std::io::BufRead;
    let mut child = bin()
        .args(args)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("run bitrock");
    let mut first = String::new();
    std::io::BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut first)
        .unwrap();
    (first, child.wait_with_output().unwrap())
}

fn csv_file(text: &str) -> tempfile::NamedTempFile {
    let mut f = tempfile::Builder::new().suffix(".csv").tempfile().unwrap();
    f.write_all(text.as_bytes()).unwrap();
    f
}

#[test]
fn fit_json_on_the_embedded_record_keeps_its_keys() {
    let (code, stdout, stderr) = run(&["fit", "--json"]);
    assert_eq!(code, 0, "{stderr}");
    let v: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    assert!(v["rows_read"].as_u64().unwrap() > v["rows_used"].as_u64().unwrap());
    let fits = v["fits"].as_array().unwrap();
    assert_eq!(fits.len(), 4);
    for fit in fits {
        for key in ["law", "names", "params", "std_errors", "rho", "warnings"] {
            assert!(fit.get(key).is_some(), "missing {key} in {fit}");
        }
        let rho = fit["rho"].as_f64().unwrap();
        assert!(rho > 0.0 && rho < 0.1, "{fit}");
    }
    // The record is made from m3 at the paper's estimate (data/README.md): m3 fits it best.
    let best = fits
        .iter()
        .min_by(|a, b| a["rho"].as_f64().unwrap().total_cmp(&b["rho"].as_f64().unwrap()))
        .unwrap();
    assert_eq!(best["law"], "m3");
}

#[test]
fn bad_input_exits_2_and_names_the_place() {
    let (code, _, stderr) = run(&["fit", "/no/such/file.csv"]);
    assert_eq!(code, 2);
    assert!(
        stderr.contains("/no/such/file.csv") && stderr.contains("cannot read"),
        "{stderr}"
    );

    let f = csv_file("time_s,bit_speed_rpm,torque_knm\n0,60,10\n0.02,60,1O\n");
    let (code, _, stderr) = run(&["fit", f.path().to_str().unwrap()]);
    assert_eq!(code, 2);
    assert!(
        stderr.contains(":3:3: column 'torque_knm': '1O' is not a number"),
        "{stderr}"
    );

    let f = csv_file("time_s,w,torque_knm\n0,60,10\n");
    let (code, _, stderr) = run(&["fit", f.path().to_str().unwrap()]);
    assert_eq!(code, 2);
    assert!(stderr.contains("--speed-col"), "{stderr}");

    let (code, _, stderr) = run(&["fit", "--laws", "m7"]);
    assert_eq!(code, 2);
    assert!(stderr.contains("m7"), "{stderr}");

    let (code, _, stderr) = run(&["fit", "--calibration-fraction", "0"]);
    assert_eq!(code, 2);
    assert!(stderr.contains("--calibration-fraction"), "{stderr}");
}

#[test]
fn refused_simulation_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("sim.csv");
    let (code, _, stderr) = run(&[
        "simulate",
        "--law",
        "m2",
        "--omega-rpm",
        "-5",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(code, 2, "{stderr}");
    assert!(stderr.contains("--omega-rpm"), "{stderr}");
    let (code, _, stderr) = run(&[
        "simulate",
        "--law",
        "m2",
        "--params",
        "13,6.5",
        "--omega-rpm",
        "60",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(code, 2, "{stderr}");
    assert!(stderr.contains("--params"), "{stderr}");
    assert!(!out.exists());
    assert_eq!(
        std::fs::read_dir(dir.path()).unwrap().count(),
        0,
        "a temporary file was left behind"
    );
}

#[test]
fn simulated_record_is_fitted_back() {
    // m2 at the paper's estimate, in stick-slip at 50 rpm, noise-free: the fit through the CSV
    // (4 decimals in kN·m) recovers the law to the precision of the file.
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("sim.csv");
    let (code, _, stderr) = run(&[
        "simulate",
        "--law",
        "m2",
        "--omega-rpm",
        "50",
        "--duration-s",
        "40",
        "--settle-s",
        "20",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{stderr}");
    let text = std::fs::read_to_string(&out).unwrap();
    assert!(text.starts_with("time_s,bit_speed_rpm,torque_knm,wob_kn\n"));
    assert_eq!(text.lines().count(), 1 + 40 * 50);
    let (code, stdout, stderr) = run(&[
        "fit",
        out.to_str().unwrap(),
        "--laws",
        "m2",
        "--calibration-fraction",
        "1",
        "--json",
    ]);
    assert_eq!(code, 0, "{stderr}");
    let v: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    let params: Vec<f64> = serde_json::from_value(v["fits"][0]["params"].clone()).unwrap();
    for (got, want) in params.iter().zip([13.0, 6.5, 0.3]) {
        assert!((got - want).abs() < 2e-3 * want, "{params:?}");
    }
}

#[test]
fn a_failure_that_stopped_the_work_exits_3() {
    // No adapter of that name: the GPU backend cannot start, which is not the input's fault
    // (the name may be right on another machine).
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    let result = bin()
        .args([
            "abc",
            "--backend",
            "gpu",
            "--particles",
            "100",
            "--out",
            out.to_str().unwrap(),
        ])
        .env("WGPU_ADAPTER_NAME", "no-such-adapter")
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&result.stderr);
    assert_eq!(result.status.code(), Some(3), "{stderr}");
    assert!(
        stderr.contains("error: no GPU for this process: WGPU_ADAPTER_NAME=no-such-adapter matches none of"),
        "{stderr}"
    );
    assert!(!out.exists());
}

/// The report's strings (the record's advice) go where `--backend` says: with no adapter, the
/// GPU's advice says it failed, the CPU's is computed, and auto's is the CPU's saying why.
#[test]
fn the_report_s_strings_run_on_the_backend_asked_and_auto_says_when_it_falls_back() {
    let dir = tempfile::tempdir().unwrap();
    let run_dir = dir.path().join("run");
    let run_dir = run_dir.to_str().unwrap();
    let (code, _, stderr) = run(&[
        "abc",
        "--thin",
        "4",
        "--particles",
        "200",
        "--max-populations",
        "2",
        "--backend",
        "cpu",
        "-q",
        "--out",
        run_dir,
    ]);
    assert_eq!(code, 0, "{stderr}");
    let advice = |backend: &str| -> String {
        let out = dir.path().join(format!("report-{backend}"));
        let result = bin()
            .args(["report", run_dir, "--backend", backend, "--out", out.to_str().unwrap()])
            .env("WGPU_ADAPTER_NAME", "no-such-adapter")
            .output()
            .unwrap();
        assert_eq!(
            result.status.code(),
            Some(0),
            "{}",
            String::from_utf8_lossy(&result.stderr)
        );
        let markdown = std::fs::read_to_string(out.join("report.md")).unwrap();
        let line = markdown
            .lines()
            .find(|l| l.starts_with("**Advice at the record's operating point**"));
        line.expect("the record's advice").to_string()
    };
    let cpu = advice("cpu");
    assert!(
        cpu.contains("stick-slip now") && cpu.contains("raise the top-drive speed to"),
        "{cpu}"
    );
    assert!(!cpu.contains("GPU"), "{cpu}");
    let gpu = advice("gpu");
    assert!(
        gpu.contains("the simulated strings failed (no GPU for this process: WGPU_ADAPTER_NAME=no-such-adapter"),
        "{gpu}"
    );
    let auto = advice("auto");
    let note = " [no usable GPU (no GPU for this process: WGPU_ADAPTER_NAME=no-such-adapter";
    let (before, after) = auto.split_once(note).expect(&auto);
    let (_, rest) = after.split_once("); computing on the CPU]").expect(&auto);
    assert_eq!(format!("{before}{rest}"), cpu);
}

#[test]
fn a_closed_pipe_ends_quietly_with_status_141() {
    // 600 s at 50 Hz: about 1 MB of CSV, far more than a pipe holds.
    let (first, out) = first_line_then_close(&["simulate", "--law", "m2", "--omega-rpm", "60", "--duration-s", "600"]);
    assert_eq!(first, "time_s,bit_speed_rpm,torque_knm,wob_kn\n");
    assert_eq!(out.status.code(), Some(141));
    assert_eq!(String::from_utf8_lossy(&out.stderr), "");
}

#[test]
fn demo_prints_fits_and_the_population_table() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("demo-run");
    // On the backend a user gets (auto: raced on a software driver, the GPU on a hardware one);
    // the GPU's own agreement with the CPU is tested in gpu.rs.
    let (code, stdout, stderr) = run(&["demo", "--particles", "1000", "--out", out.to_str().unwrap()]);
    assert_eq!(code, 0, "{stderr}");
    assert!(stdout.contains("synthetic"));
    for law in ["m1", "m2", "m3", "m4"] {
        assert!(stdout.contains(&format!("{law}  T = ")), "{stdout}");
        assert!(stdout.contains(&format!("P({law})")), "{stdout}");
    }
    assert!(
        stdout.contains("stopped: the tolerance reached the run's floor ε_min"),
        "{stdout}"
    );
    for delta in ["0.4", "0.6", "0.8"] {
        assert!(out.join(format!("delta-{delta}/run.json")).exists());
        assert!(out.join(format!("delta-{delta}/run.sqlite")).exists());
    }
    // The report of the three runs, and where it is.
    let report = out.join("report");
    assert!(
        stdout.contains(&format!("report: {}", report.join("report.md").display())),
        "{stdout}"
    );
    let markdown = std::fs::read_to_string(report.join("report.md")).unwrap();
    for delta in ["δ = 0.4", "δ = 0.6", "δ = 0.8"] {
        assert!(markdown.contains(delta), "{delta}");
        // Each run's answer, as its probabilities are: ratios of prior volumes at ε = 0.014.
        assert!(
            markdown.contains(&format!("**{delta}, answer:** m"))
                && markdown.contains("decided by the boxes (the paper's ABC"),
            "{markdown}"
        );
    }
    assert!(
        markdown.contains("## Model probabilities by the paper's ABC"),
        "{markdown}"
    );
    // The headline opens with the one answer that weighs the record, the evidence's, checked
    // by re-simulation (m3's records decided for it: the embedded record separates m3), and
    // gives each ABC run's beside its probabilities.
    let headline = stdout.split("== bitrock demo: headline ==").nth(1).unwrap();
    let answer = headline.trim_start().lines().next().unwrap();
    assert!(answer.starts_with("answer: m3 over "), "{headline}");
    assert!(
        answer.contains(": very strong (")
            && answer.contains("; the check decided ")
            && answer.contains(" records made by m3 for it"),
        "{answer}"
    );
    assert_eq!(headline.matches("    its answer: m").count(), 3, "{headline}");
    for stem in [
        "fig01_data_and_fits",
        "fig02_model_probabilities",
        "fig08_map_stochastic",
        "fig09_structures",
    ] {
        for ext in ["svg", "png"] {
            assert!(report.join(format!("figures/{stem}.{ext}")).exists(), "{stem}.{ext}");
        }
    }
}

/// The paper's ABC at the embedded record's ε = 0.014, thousands of likelihood scales above its
/// best fit, measures the laws' prior volumes: its one answer is decided by the boxes whatever
/// its probabilities, and every place they appear names them.
#[test]
fn the_paper_s_abc_answers_with_its_label_and_a_strength_its_tolerance_allows() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    let out = out.to_str().unwrap();
    let args = [
        "abc",
        "--particles",
        "1000",
        "--seed",
        "3",
        "--backend",
        "cpu",
        "--out",
        out,
    ];
    let (code, stdout, stderr) = run(&args);
    assert_eq!(code, 0, "{stderr}");
    assert!(stderr.contains("likelihood scales above the best fit"), "{stderr}");
    assert!(
        stdout.contains(
            "model probabilities by the paper's ABC, P(m | ρ < ε): the share of each law's prior box below ε"
        ),
        "{stdout}"
    );
    assert_eq!(stdout.matches("  P(m | ρ < ε) = ").count(), 4, "{stdout}");
    let document: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("run/run.json")).unwrap()).unwrap();
    let posterior = &document["posterior"];
    assert_eq!(posterior["label"], "the paper's ABC, P(m | ρ < ε)");
    let answer = &document["answer"];
    assert_eq!(
        (&answer["method"], &answer["strength"]),
        (&"paper_abc".into(), &"decided_by_the_boxes".into()),
        "{answer}"
    );
    // The law ranked first and the next are the population's two largest probabilities.
    let mut ranked: Vec<(String, f64)> = posterior["model_probabilities"]
        .as_object()
        .unwrap()
        .iter()
        .map(|(law, p)| (law.clone(), p.as_f64().unwrap()))
        .collect();
    ranked.sort_by(|a, b| b.1.total_cmp(&a.1));
    assert_eq!(answer["law"], ranked[0].0.as_str());
    assert_eq!(answer["runner_up"], ranked[1].0.as_str());
    assert_eq!(answer["probability"].as_f64(), Some(ranked[0].1));
    let expected = (ranked[0].1 / ranked[1].1).ln();
    assert!((answer["ln_b"].as_f64().unwrap() - expected).abs() < 1e-12, "{answer}");
    let sentence = answer["sentence"].as_str().unwrap();
    assert!(stdout.contains(&format!("\nanswer: {sentence}\n")), "{stdout}");
    assert!(
        sentence.contains("ratios of the laws' prior volumes below ε, not evidence"),
        "{sentence}"
    );
}

#[test]
fn abc_writes_a_run_directory_and_json_with_its_keys() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    let args = [
        "abc",
        "--particles",
        "1000",
        "--seed",
        "3",
        "--out",
        out.to_str().unwrap(),
        "--json",
    ];
    let (code, stdout, stderr) = run(&args);
    assert_eq!(code, 0, "{stderr}");
    let v: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    for key in ["populations", "posterior", "evaluations", "seconds", "backend"] {
        assert!(v.get(key).is_some(), "missing {key}");
    }
    let pops = v["populations"].as_array().unwrap();
    for p in pops {
        for key in ["index", "epsilon", "draws", "accepted", "model_probabilities"] {
            assert!(p.get(key).is_some(), "missing {key} in {p}");
        }
        let total: f64 = p["model_probabilities"]
            .as_object()
            .unwrap()
            .values()
            .map(|x| x.as_f64().unwrap())
            .sum();
        assert!((total - 1.0).abs() < 1e-12);
    }
    assert!(pops[0]["epsilon"].is_null(), "ε_0 = ∞ is null");
    assert_eq!(
        pops[0]["near_threshold"], 0,
        "no candidate is near an infinite tolerance"
    );
    let eps_last = pops.last().unwrap()["epsilon"].as_f64().unwrap();
    assert!((eps_last - 0.014).abs() < 1e-15, "{eps_last}");
    // The run directory holds the same JSON, the store and the envelopes; `export` gives
    // every population's particles.
    let stored: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("run.json")).unwrap()).unwrap();
    assert_eq!(stored, v);
    assert!(out.join("run.sqlite").exists());
    for g in 0..pops.len() {
        let (code, csv, stderr) = run(&["export", out.to_str().unwrap(), "--population", &g.to_string()]);
        assert_eq!(code, 0, "{stderr}");
        assert_eq!(csv.lines().count(), 1001);
        assert!(
            csv.starts_with("population,law,candidate,rho,weight,m1.b0 [kN·m],m1.b1 [s/rad]"),
            "{}",
            &csv[..80]
        );
        assert!(csv.lines().skip(1).all(|l| l.starts_with(&format!("{g},"))));
    }
    // Every population's particles (several hundred kB) into a pipe closed after one line.
    let (first, export) = first_line_then_close(&["export", out.to_str().unwrap()]);
    assert!(first.starts_with("population,law,candidate"), "{first}");
    assert_eq!(export.status.code(), Some(141));
    assert_eq!(String::from_utf8_lossy(&export.stderr), "");
    let envelopes = std::fs::read_to_string(out.join("envelopes.csv")).unwrap();
    assert!(envelopes.starts_with("law,speed_rad_s,lower_knm,median_knm,upper_knm"));
    assert!(out.join("data.csv").exists());

    // Same seed, same backend, same populations. (`auto` measures which backend is faster
    // where the GPU is a software driver, and a busy machine may measure the other way: the
    // second run asks for the backend the first one used.)
    let again = dir.path().join("again");
    let backend = v["backend"].as_str().unwrap();
    let (code, stdout2, stderr) = run(&[
        "abc",
        "--particles",
        "1000",
        "--seed",
        "3",
        "--backend",
        backend,
        "--out",
        again.to_str().unwrap(),
        "--json",
    ]);
    assert_eq!(code, 0, "{stderr}");
    let w: serde_json::Value = serde_json::from_str(&stdout2).unwrap();
    assert_eq!(w["backend"], backend);
    for (a, b) in pops.iter().zip(w["populations"].as_array().unwrap()) {
        assert_eq!(
            (&a["epsilon"], &a["draws"], &a["model_probabilities"]),
            (&b["epsilon"], &b["draws"], &b["model_probabilities"])
        );
    }

    // A non-empty directory is not overwritten without --force, and nothing is computed.
    let (code, _, stderr) = run(&args);
    assert_eq!(code, 2);
    assert!(stderr.contains("--force"), "{stderr}");
    let (code, _, stderr) = run(&[&args[..], &["--force"]].concat());
    assert_eq!(code, 0, "{stderr}");
}

#[test]
fn refused_abc_configurations_error_before_any_work() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    let o = out.to_str().unwrap();
    for (args, flag) in [
        (vec!["abc", "--particles", "0", "--out", o], "--particles"),
        (vec!["abc", "--delta", "0", "--out", o], "--delta"),
        (vec!["abc", "--delta", "-0.2", "--out", o], "--delta"),
        (vec!["abc", "--laws", "m2,m9", "--out", o], "m9"),
        (vec!["abc", "--epsilons", "0.05,0.07", "--out", o], "--epsilons"),
        (vec!["abc", "--prior", "/no/such/prior.toml", "--out", o], "prior.toml"),
    ] {
        let (code, _, stderr) = run(&args);
        assert_eq!(code, 2, "{args:?}: {stderr}");
        assert!(stderr.contains(flag), "{args:?}: {stderr}");
        assert!(!out.exists(), "{args:?} wrote {o}");
    }
    let bad = dir.path().join("prior.toml");
    std::fs::write(&bad, "[m2]\ntsb = [10, 20]\ngamma = [1, 2]\n").unwrap();
    let (code, _, stderr) = run(&["abc", "--prior", bad.to_str().unwrap(), "--out", o]);
    assert_eq!(code, 2);
    assert!(stderr.contains("no parameter 'gamma'"), "{stderr}");
}

#[test]
fn abc_runs_the_smc_sampler_and_refuses_its_bad_flags() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("smc");
    let (code, stdout, stderr) = run(&[
        "abc",
        "--sampler",
        "smc",
        "--particles",
        "400",
        "--eps-min",
        "0.02",
        "--backend",
        "cpu",
        "--out",
        out.to_str().unwrap(),
        "--json",
    ]);
    assert_eq!(code, 0, "{stderr}");
    let v: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    assert_eq!(v["config"]["sampler"]["sampler"], "smc");
    assert!((v["config"]["sampler"]["p_stay"].as_f64().unwrap() - 0.7).abs() < 1e-15);
    let pops = v["populations"].as_array().unwrap();
    assert!(pops.len() >= 3, "{}", pops.len());
    for p in &pops[1..] {
        // Weighted populations: ESS below N, weights summing to 1 in the particle CSV.
        let ess = p["ess"].as_f64().unwrap();
        assert!(ess > 0.0 && ess <= 400.0 + 1e-9, "{ess}");
        assert!(
            p["per_law"]
                .as_array()
                .unwrap()
                .iter()
                .all(|l| l.get("alive").is_some())
        );
    }
    let g = pops.len() - 1;
    let (code, csv, stderr) = run(&["export", out.to_str().unwrap(), "--population", &g.to_string()]);
    assert_eq!(code, 0, "{stderr}");
    let total: f64 = csv
        .lines()
        .skip(1)
        .map(|l| l.split(',').nth(4).unwrap().parse::<f64>().unwrap())
        .sum();
    assert!((total - 1.0).abs() < 1e-9, "{total}");
    // An SMC run continues as a rejection run does: one more population after the stored ones.
    let (code, stdout, stderr) = run(&[
        "abc",
        "--resume",
        out.to_str().unwrap(),
        "--eps-min",
        "0.015",
        "--json",
        "--quiet",
    ]);
    assert_eq!(code, 0, "{stderr}");
    let w: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    assert!(w["populations"].as_array().unwrap().len() > pops.len());
    assert_eq!(&w["populations"].as_array().unwrap()[..pops.len()], &pops[..]);
    for (flag, value) in [("--p-stay", "1.5"), ("--kernel-scale", "-1")] {
        let (code, _, stderr) = run(&[
            "abc",
            "--sampler",
            "smc",
            flag,
            value,
            "--out",
            dir.path().join("bad").to_str().unwrap(),
        ]);
        assert_eq!(code, 2, "{stderr}");
        assert!(stderr.contains(flag), "{stderr}");
    }
}
