//! Stability maps: the reduction to a critical weight on bit against brute-force eigenvalues
//! of the finite-element string, against the time-domain simulator, and the commands.

use crate::support::bin;
use bitrock::Law;
use bitrock::run;
use bitrock::simulate::{Initial, Recording, SimConfig, simulate};
use bitrock::stability::fe::DrillString;
use bitrock::stability::lumped::Lumped;
use bitrock::stability::map::{critical_wob_n, parse_axis};
use bitrock::units::RAD_S_PER_RPM;

const W_REF_N: f64 = 244.2e3;

#[test]
fn the_reduction_matches_brute_force_fe_eigenvalues_on_every_cell() {
    let string = DrillString::default();
    let critical = string.critical_bit_damping().unwrap().critical_bit_damping_nms;
    let omega = parse_axis("20:200:10", "x").unwrap();
    let wob = parse_axis("20:600:10", "y").unwrap();
    for law in [Law::M2, Law::M3] {
        let p = law.scale_torque(law.paper_estimate().unwrap(), 1000.0);
        for &rpm in &omega {
            let w_star = critical_wob_n(law, &p, rpm * RAD_S_PER_RPM, critical, W_REF_N);
            for &kn in &wob {
                let bit_damping = kn * 1000.0 / W_REF_N * law.dtorque_dw(&p, rpm * RAD_S_PER_RPM, 1.0);
                let growth = string.max_real_eigenvalue(bit_damping);
                let by_reduction = w_star.is_some_and(|w| kn * 1000.0 >= w);
                // Cells within 1e-6 of the boundary are decided by rounding; none is on this grid.
                assert_eq!(
                    growth >= 0.0,
                    by_reduction,
                    "{law} at ({rpm} rpm, {kn} kN): growth {growth}"
                );
            }
        }
    }
}

#[test]
fn the_simulator_confirms_the_deterministic_boundary() {
    // Just below the boundary (90 % of W*) a kick decays; just above (110 %) stick-slip grows
    // until the bit stops.
    let lumped = Lumped::default();
    let c = lumped.critical_bit_damping_nms();
    for (law, rpm) in [(Law::M2, 60.0), (Law::M3, 80.0)] {
        let p = law.scale_torque(law.paper_estimate().unwrap(), 1000.0);
        let omega = rpm * RAD_S_PER_RPM;
        let w_star = critical_wob_n(law, &p, omega, c, W_REF_N).unwrap();
        for (factor, unstable) in [(0.9, false), (1.1, true)] {
            let cfg = SimConfig {
                duration_s: 20.0,
                recording: Recording {
                    settle_s: 280.0,
                    initial: Initial::Equilibrium {
                        speed_perturbation_rad_s: 0.2,
                    },
                    ..Recording::default()
                },
                ..SimConfig::new(law, p.clone(), omega, factor * w_star)
            };
            let trace = simulate(&cfg).unwrap();
            let (lo, hi) = trace.speed_range_rad_s(0.0).unwrap();
            if unstable {
                assert!(lo <= 0.0, "{law} at {factor} W*: bit never stops (min {lo})");
            } else {
                assert!(
                    hi - lo < 0.02 * omega,
                    "{law} at {factor} W*: oscillation {lo}..{hi} did not decay"
                );
            }
        }
    }
}

fn run(args: &[&str]) -> (i32, String, String) {
    let out = bin()
        .env("NODEVICE_SELECT", "1")
        .args(args)
        .output()
        .expect("run bitrock");
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn fe_json_reproduces_the_appendix() {
    // The 2-DOF string: ω = {0.85, 15.60} rad/s, ξ = {0.30, 0.06} (the paper rounds to two
    // decimals; the module's tests check the 10-DOF tables).
    let (code, stdout, stderr) = run(&["fe", "--json"]);
    assert_eq!(code, 0, "{stderr}");
    let v: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    let w: Vec<f64> = serde_json::from_value(v["frequencies_rad_s"].clone()).unwrap();
    let xi: Vec<f64> = serde_json::from_value(v["damping_ratios"].clone()).unwrap();
    for (got, want) in w.iter().zip([0.85, 15.60]) {
        assert!(
            (got - want).abs() <= 0.005 * want || (got - want).abs() <= 0.005,
            "{got} vs {want}"
        );
    }
    for (got, want) in xi.iter().zip([0.30, 0.06]) {
        assert!((got - want).abs() <= 0.005, "{got} vs {want}");
    }
    assert_eq!(v["sign_changes"], 1);
    assert!(v["critical_bit_damping_nms"].as_f64().unwrap() < 0.0);
    // --match-1dof brings the string's critical damping to the 1-DOF model's.
    let (code, stdout, _) = run(&[
        "fe",
        "--dp-elements",
        "8",
        "--bha-elements",
        "2",
        "--match-1dof",
        "--json",
    ]);
    assert_eq!(code, 0);
    let v: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    let (fe, one) = (
        v["critical_bit_damping_nms"].as_f64().unwrap(),
        v["critical_bit_damping_1dof_nms"].as_f64().unwrap(),
    );
    assert!((fe - one).abs() < 1e-6 * one.abs(), "{fe} vs {one}");
}

#[test]
fn stability_runs_on_an_abc_run_and_on_a_law() {
    let dir = tempfile::tempdir().unwrap();
    let run_dir = dir.path().join("run");
    let (code, _, stderr) = run(&[
        "abc",
        "--particles",
        "2000",
        "--out",
        run_dir.to_str().unwrap(),
        "--backend",
        "cpu",
    ]);
    assert_eq!(code, 0, "{stderr}");
    let csv = dir.path().join("map.csv");
    let (code, stdout, stderr) = run(&[
        "stability",
        "--run",
        run_dir.to_str().unwrap(),
        "--omega-rpm",
        "40:200:17",
        "--wob-kn",
        "50:500:10",
        "--json",
        "--out",
        csv.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{stderr}");
    let v: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    assert_eq!(v["omega_rpm"].as_array().unwrap().len(), 17);
    let b = &v["boundaries"];
    assert!(b["mixture"]["p_wob_kn"].as_array().unwrap().len() == 17);
    for law in ["m2", "m3"] {
        let map: Vec<Option<f64>> = serde_json::from_value(b[law]["map_wob_kn"].clone()).unwrap();
        let p2: Vec<Option<f64>> = serde_json::from_value(b[law]["p_wob_kn"].clone()).unwrap();
        // The 2 % boundary is more conservative than the MAP one wherever both exist (the
        // paper's "safety factor"), and the boundary rises with speed for this record.
        for (m, s) in map.iter().zip(&p2) {
            if let (Some(m), Some(s)) = (m, s) {
                assert!(s <= m, "{law}: p2 {s} above MAP {m}");
            }
        }
        assert!(map[16].unwrap() > map[0].unwrap());
        assert_eq!(v["probability_unstable"][law].as_array().unwrap().len(), 17);
    }
    assert!(std::fs::read_to_string(&csv).unwrap().starts_with("omega_rpm,"));

    // The run's last population exported as particles maps as the run does (to the rounding of
    // the kN·m round trip).
    let (code, export, stderr) = run(&["export", run_dir.to_str().unwrap(), "--format", "json"]);
    assert_eq!(code, 0, "{stderr}");
    let last = serde_json::from_str::<serde_json::Value>(&export).unwrap()["populations"]
        .as_array()
        .unwrap()
        .len()
        - 1;
    let particles = dir.path().join("last.csv");
    let (code, _, stderr) = run(&[
        "export",
        run_dir.to_str().unwrap(),
        "--population",
        &last.to_string(),
        "--out",
        particles.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{stderr}");
    let (code, stdout, stderr) = run(&[
        "stability",
        "--posterior",
        particles.to_str().unwrap(),
        "--omega-rpm",
        "40:200:17",
        "--wob-kn",
        "50:500:10",
        "--json",
    ]);
    assert_eq!(code, 0, "{stderr}");
    let w: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    assert_eq!(w["probability_unstable"], v["probability_unstable"]);
    for law in ["m2", "m3"] {
        assert_eq!(w["boundaries"][law]["probability"], v["boundaries"][law]["probability"]);
        for key in ["map_wob_kn", "p_wob_kn"] {
            let (a, b): (Vec<Option<f64>>, Vec<Option<f64>>) = (
                serde_json::from_value(w["boundaries"][law][key].clone()).unwrap(),
                serde_json::from_value(v["boundaries"][law][key].clone()).unwrap(),
            );
            for (a, b) in a.iter().zip(&b) {
                assert_eq!(a.is_some(), b.is_some(), "{law} {key}");
                if let (Some(a), Some(b)) = (a, b) {
                    assert!((a - b).abs() <= 1e-9 * b.abs(), "{law} {key}: {a} against {b}");
                }
            }
        }
    }
    // A particle file that cannot be read is refused naming the file, line and column.
    let all = dir.path().join("all.csv");
    let (code, _, stderr) = run(&["export", run_dir.to_str().unwrap(), "--out", all.to_str().unwrap()]);
    assert_eq!(code, 0, "{stderr}");
    let text = std::fs::read_to_string(&particles).unwrap();
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    let broken = dir.path().join("broken.csv");
    lines[2] = lines[2].replacen(",m", ",mx", 1);
    std::fs::write(&broken, lines.join("\n")).unwrap();
    let no_weight = dir.path().join("no-weight.csv");
    std::fs::write(&no_weight, text.replacen("weight", "w", 1)).unwrap();
    for (file, says) in [
        (
            &all,
            "column 'population': the file holds population 0 and 1".to_string(),
        ),
        (&broken, format!("{}:3:2: column 'law'", broken.display())),
        (
            &no_weight,
            ":1: a particle file needs the columns 'law' and 'weight'".to_string(),
        ),
    ] {
        let (code, out, err) = run(&["stability", "--posterior", file.to_str().unwrap()]);
        assert_eq!(code, 2, "{err}");
        assert!(out.is_empty() && err.contains(&says), "{says}: {err}");
    }

    // A what-if map from a law, and the same map's boundary from the closed form.
    let (code, stdout, stderr) = run(&[
        "stability",
        "--law",
        "m2",
        "--params",
        "13,6.5,0.3",
        "--omega-rpm",
        "30:90:3",
        "--wob-kn",
        "50:500:4",
        "--json",
    ]);
    assert_eq!(code, 0, "{stderr}");
    let v: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    let b: Vec<f64> = serde_json::from_value(v["boundaries"]["m2"]["map_wob_kn"].clone()).unwrap();
    let c = Lumped::default().critical_bit_damping_nms();
    let p = Law::M2.scale_torque(&[13.0, 6.5, 0.3], 1000.0);
    for (got, rpm) in b.iter().zip([30.0, 60.0, 90.0]) {
        let want = critical_wob_n(Law::M2, &p, rpm * RAD_S_PER_RPM, c, W_REF_N).unwrap() / 1000.0;
        assert!((got - want).abs() < 1e-9 * want);
    }

    // Not a run directory: a clear error, exit status 2.
    let (code, _, stderr) = run(&["stability", "--run", dir.path().to_str().unwrap()]);
    assert_eq!(code, 2);
    assert!(stderr.contains("not a bitrock run directory"), "{stderr}");
    let (code, _, stderr) = run(&["stability", "--law", "m2", "--params", "13,6.5"]);
    assert_eq!(code, 2);
    assert!(stderr.contains("--params"), "{stderr}");
}

/// A stability job on the paper's 1-DOF string over a small grid, CPU.
fn job_of(source: bitrock::run::stability::MapSource) -> bitrock::run::stability::StabilityJob {
    bitrock::run::stability::StabilityJob {
        source,
        omega_rpm: parse_axis("20:220:11", "omega_rpm").unwrap(),
        wob_kn: parse_axis("20:700:9", "wob_kn").unwrap(),
        criterion: bitrock::stability::map::Criterion::Lumped(Lumped::default()),
        w_ref_n: W_REF_N,
        percentile: 0.02,
        samples: 50,
        backend: bitrock::eval::Backend::Cpu,
    }
}

fn particle(law: Law, params: &[f64], weight: f64) -> bitrock::abc::Particle {
    bitrock::abc::Particle {
        law,
        index: 0,
        params: params.to_vec(),
        rho: f64::NAN,
        weight,
    }
}

#[test]
fn a_posterior_in_memory_maps_as_its_laws_do() {
    use bitrock::run::stability::MapSource;
    // One particle of m2 is the law at those parameters: the same boundaries and grid.
    let m2 = [13_000.0, 6_500.0, 0.3];
    let alone = job_of(MapSource::Posterior(vec![particle(Law::M2, &m2, 1.0)]))
        .run(&mut |_| {})
        .unwrap();
    let law = job_of(MapSource::Law {
        law: Law::M2,
        params_si: m2.to_vec(),
    })
    .run(&mut |_| {})
    .unwrap();
    assert_eq!(alone.grids, law.grids);
    assert_eq!(alone.boundaries.laws[0].map_wob_kn, law.boundaries.laws[0].map_wob_kn);
    assert_eq!(alone.boundaries.laws[0].p_wob_kn, law.boundaries.laws[0].p_wob_kn);
    // Two laws: each law's probability is its share of the weight, whatever the weights'
    // total, and the mixture boundary is drawn.
    let m4 = [11_000.0, -900.0, 40.0, -0.5];
    let mixed = job_of(MapSource::Posterior(vec![
        particle(Law::M2, &m2, 0.5),
        particle(Law::M4, &m4, 1.0),
        particle(Law::M4, &m4, 0.5),
    ]))
    .run(&mut |_| {})
    .unwrap();
    let shares: Vec<(Law, f64)> = mixed.inputs.iter().map(|i| (i.law, i.probability)).collect();
    assert_eq!(shares, vec![(Law::M2, 0.25), (Law::M4, 0.75)]);
    assert!(mixed.boundaries.mixture_wob_kn.is_some());
    assert_eq!(mixed.grids[0], law.grids[0]);
    // What cannot be mapped is refused by name.
    for (particles, says) in [
        (vec![], "no particles"),
        (vec![particle(Law::M2, &m2, f64::NAN)], "weight NaN"),
        (vec![particle(Law::M2, &m2, 0.0)], "weight 0"),
        (vec![particle(Law::M2, &m2[..2], 1.0)], "source"),
    ] {
        let e = job_of(MapSource::Posterior(particles))
            .run(&mut |_| {})
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("source") && e.contains(says), "{e}");
    }
}

#[test]
fn the_evidence_posterior_maps_with_its_law_probabilities() {
    use bitrock::abc::evidence::EvidenceConfig;
    use bitrock::run::stability::MapSource;
    let data = bitrock::data::demo_field_data(&bitrock::data::DataOptions {
        thin: 8,
        ..Default::default()
    })
    .unwrap();
    let analysis = run::evidence::Job {
        laws: vec![Law::M2, Law::M4],
        backend: bitrock::eval::Backend::Cpu,
        sampler: EvidenceConfig {
            particles: 100,
            islands: 2,
            ..EvidenceConfig::default()
        },
        ..run::evidence::Job::default()
    }
    .run(&data, Default::default(), &mut bitrock::abc::Silent)
    .unwrap();
    let particles = analysis.evidence.particles();
    let total: f64 = particles.iter().map(|p| p.weight).sum();
    assert!((total - 1.0).abs() < 1e-9, "{total}");
    let maps = job_of(MapSource::Posterior(particles)).run(&mut |_| {}).unwrap();
    for input in &maps.inputs {
        let p = analysis.evidence.of(input.law).unwrap().probability;
        assert!(
            (input.probability - p).abs() < 1e-9,
            "{} {} {p}",
            input.law,
            input.probability
        );
        assert_eq!(input.samples_si.len(), 50);
    }
    for grid in &maps.grids {
        assert!(grid.iter().all(|&v| v.is_nan() || (0.0..=1.0).contains(&v)));
    }
}

/// Parameters in N·m read as kN·m put every torque a thousand times too high: the map is still
/// drawn (the values are legal), but never silently. The same values in N·m, said so, map the
/// boundary a thousand times higher in weight on bit and warn of nothing.
#[test]
fn torques_beyond_any_drill_bit_are_said_to_be_in_the_wrong_unit() {
    let grid = ["--omega-rpm", "60:180:3", "--wob-kn", "20:600:5", "--json"];
    let map = |extra: &[&str]| {
        let mut args = vec!["stability", "--law", "m2", "--params", "13000,6500,0.3"];
        args.extend_from_slice(extra);
        args.extend_from_slice(&grid);
        let (code, out, err) = run(&args);
        assert_eq!(code, 0, "{err}");
        let doc: serde_json::Value = serde_json::from_str(&out).unwrap();
        (doc["boundaries"]["m2"]["map_wob_kn"].clone(), err)
    };
    let (as_knm, warned) = map(&[]);
    assert!(
        warned.contains("warning: tsb = 13000 kN·m lies beyond any drill bit's torque")
            && warned.contains("--torque-unit nm"),
        "{warned}"
    );
    let (as_nm, quiet) = map(&["--torque-unit", "nm"]);
    assert!(!quiet.contains("warning"), "{quiet}");
    // The critical weight on bit scales with the torque: the wrong unit moves it a thousandfold.
    let (a, b) = (as_knm[0].as_f64().unwrap(), as_nm[0].as_f64().unwrap());
    assert!((b / a - 1000.0).abs() < 1e-6 * 1000.0, "{a} kN against {b} kN");
}
