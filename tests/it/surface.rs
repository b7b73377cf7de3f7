//! Laws from surface records through simulated strings: records made by `bitrock simulate`
//! with both the bit's and the surface's channels, the surface channels inferred from, the
//! bit's kept as the truth the inference is judged by.

use super::support::{bin, outcome};
use bitrock::Law;
use bitrock::data::surface::{SurfaceOptions, SurfaceRecord};
use bitrock::run::surface::{SurfaceResult, SurfaceSettings, infer};
use bitrock::simulate::strings::Summary;
use bitrock::simulate::{self, Channels, Initial, Recording, SimConfig};
use bitrock::stability::lumped::Lumped;
use bitrock::units::{RAD_S_PER_RPM, TorqueUnit};
use std::path::PathBuf;

/// A record of `law` at its paper estimate at `rpm`, `seconds` long at `hz`, surface torque
/// noise `noise_knm`, written with all channels: the surface record and the bit's true speed.
fn record(
    law: Law,
    rpm: f64,
    seconds: f64,
    hz: f64,
    noise_knm: f64,
    seed: u64,
) -> (tempfile::TempDir, PathBuf, Vec<f64>) {
    record_on(Lumped::default(), law, rpm, seconds, hz, noise_knm, seed, Channels::All)
}

/// [`record`] on the 1-DOF string `structure`, written with `channels`.
#[allow(clippy::too_many_arguments)]
fn record_on(
    structure: Lumped,
    law: Law,
    rpm: f64,
    seconds: f64,
    hz: f64,
    noise_knm: f64,
    seed: u64,
    channels: Channels,
) -> (tempfile::TempDir, PathBuf, Vec<f64>) {
    let params = law.scale_torque(law.paper_estimate().unwrap(), 1000.0);
    let cfg = SimConfig {
        duration_s: seconds,
        recording: Recording {
            settle_s: 60.0,
            sample_hz: hz,
            dt_s: 2e-3,
            initial: Initial::Equilibrium {
                speed_perturbation_rad_s: 5.0 * RAD_S_PER_RPM,
            },
            noise_torque_nm: noise_knm * 1000.0,
            seed,
            ..Recording::default()
        },
        structure,
        ..SimConfig::new(law, params, rpm * RAD_S_PER_RPM, bitrock::laws::PAPER_W_REF_N)
    };
    let trace = simulate::simulate_record_with(&cfg, &mut |_, _| {}).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("rig.csv");
    let mut file = std::fs::File::create(&path).unwrap();
    simulate::write_record_csv(&trace, None, channels, TorqueUnit::KNm, &mut file).unwrap();
    (dir, path, trace.trace.bit_speed_rad_s)
}

/// Settings small enough for a test: 300 particles, 6 populations, a pilot of 300. On the CPU's
/// f64 strings on every machine: what these tests assert of the inference (intervals, verdicts,
/// a run through workers bit for bit) was measured on them, and `auto` takes a hardware GPU,
/// whose f32 strings are a realisation of their own (docs/surface.md "On the GPU"); the GPU's
/// strings are checked against their f64 twin in strings.rs.
fn small(laws: Vec<Law>) -> SurfaceSettings {
    let mut s = SurfaceSettings::new(laws);
    s.backend = bitrock::eval::Backend::Cpu;
    s.smc.schedule.particles = 300;
    s.smc.schedule.max_populations = 6;
    s.pilot = 300;
    s.check_replicates = 4;
    s.predictive_draws = 40;
    s.advice = false;
    s
}

/// Smaller still, for what is checked number for number: 150 particles, 3 populations, a
/// pilot of 100.
fn tiny(laws: Vec<Law>) -> SurfaceSettings {
    let mut s = small(laws);
    s.smc.schedule.particles = 150;
    s.smc.schedule.max_populations = 3;
    s.pilot = 100;
    s
}

fn read(path: &std::path::Path) -> SurfaceRecord {
    SurfaceRecord::read(path, &SurfaceOptions::default()).unwrap()
}

/// The surface run of `path`; every one is checked to call no law where its sampler stopped at
/// `UNCONVERGED_FACTOR` noise floors or more, saying so.
fn run(path: &std::path::Path, settings: &SurfaceSettings, seed: u64) -> SurfaceResult {
    let r = infer(&read(path), settings, seed, &mut |_| {}).unwrap();
    let epsilon = r.final_epsilon.unwrap_or(f64::INFINITY);
    if r.cycle.informs() && r.noise_floor > 0.0 && epsilon >= bitrock::run::surface::UNCONVERGED_FACTOR * r.noise_floor
    {
        assert_eq!(r.check.decided, None, "{}", r.check.verdict);
        assert!(
            r.check.verdict.contains("times the noise's own distance")
                && r.check
                    .verdict
                    .ends_with("no law is called (raise `max_populations` or `particles`)"),
            "{}",
            r.check.verdict
        );
    }
    r
}

#[test]
fn the_surface_of_a_stick_slipping_bit_gives_its_torques_and_its_stuck_share() {
    // m2 at 60 rpm, five minutes at 1 Hz with 0.2 kN·m of noise: the bit stuck about half the
    // time. The static and dynamic torques are found within their 90 % intervals; the decay
    // rate g, which the surface hardly sees, is either found or said to be the prior's.
    let (_dir, path, bit_speed) = record(Law::M2, 60.0, 300.0, 1.0, 0.2, 3);
    let record = read(&path);
    assert_eq!(
        record.columns.bit,
        ["bit_speed_rpm", "torque_knm"],
        "the bit's channels are not read"
    );
    let r = run(&path, &small(vec![Law::M2]), 1);
    assert!(r.cycle.informs(), "{:?}", r.cycle);
    assert!((r.cycle.period_s.unwrap() - 9.75).abs() < 0.3, "{:?}", r.cycle);
    let m2 = &r.laws[0];
    let truth = [13_000.0, 6_500.0, 0.3];
    for (p, truth) in m2.params.iter().zip(truth) {
        let covered = p.q05 <= truth && truth <= p.q95;
        if p.name == "g" {
            assert!(covered || !p.identified, "{p:?}");
        } else {
            assert!(covered && p.identified, "{p:?}");
        }
    }
    let mut seen = Summary::default();
    for w in &bit_speed {
        seen.push(*w, f64::NAN, f64::NAN);
    }
    let true_share = seen.stuck_share();
    assert!(true_share > 0.4, "{true_share}");
    let predicted = r.at_the_bit.stuck_share;
    assert!(
        (predicted[1] - true_share).abs() <= 0.05,
        "{predicted:?} against {true_share}"
    );
    assert!(
        predicted[0] <= true_share && true_share <= predicted[2],
        "{predicted:?} against {true_share}"
    );
    // The band is the bit speed's spread over the cycle (the simulated cycles' phases are the
    // record's only where its drive changes): it holds the true speed at most samples.
    let rpm: Vec<f64> = bit_speed.iter().map(|w| w / RAD_S_PER_RPM).collect();
    let inside = rpm
        .iter()
        .zip(&r.at_the_bit.speed_rpm)
        .filter(|(w, q)| q[0] - 0.5 <= **w && **w <= q[2] + 0.5)
        .count();
    assert!(inside as f64 >= 0.85 * rpm.len() as f64, "{inside} of {}", rpm.len());
}

/// The way out where the record leaves a parameter open: m2 at 60 rpm seen from the surface
/// leaves g, how fast the torque falls with speed, to its prior, and the escape speed depends
/// on it (165 rpm at g = 0.1 s/rad, 125 at the truth's 0.3, 85 at 1). The advice's strings,
/// drawn from the posterior, find a way out that the true bit, stuck at 60 rpm, does not take;
/// the strings along the posterior's spread of g find one it takes.
#[test]
fn the_way_out_along_an_open_parameter_s_spread_gets_the_true_bit_out() {
    let (_dir, path, _) = record(Law::M2, 60.0, 300.0, 1.0, 0.2, 3);
    let mut settings = small(vec![Law::M2]);
    settings.advice = true;
    let r = run(&path, &settings, 1);
    let advice = r.at_the_bit.advice.as_deref().unwrap();
    let open = r.at_the_bit.spread_advice.as_ref().expect("g is left open");
    eprintln!("{advice}\n{open:?}");
    assert_eq!(open.open, ["m2's g"]);
    let drawn = drawn_speed_rpm(advice);
    let spread = open.speed_rpm.expect("a speed that ends it along g's spread");
    assert!(spread > drawn, "{spread} against {drawn}");
    // Applied to the true string, stuck at 60 rpm under the record's weight; and the lighter
    // weight at 60 rpm.
    let lighter = open.wob_kn.expect("a weight that ends it along g's spread");
    let (by_speed, by_weight) = true_bit_after(Lumped::default(), &[drawn, spread], &[lighter]);
    eprintln!("stick-slip persists at {drawn} and {spread} rpm: {by_speed:?}");
    assert_eq!(by_speed, [1.0, 0.0]);
    assert_eq!(by_weight, [0.0], "at {lighter} kN");
}

/// The top-drive speed (rpm) the drawn strings' advice raises the speed to.
fn drawn_speed_rpm(advice: &str) -> f64 {
    advice
        .split("raise the top-drive speed to ")
        .nth(1)
        .and_then(|rest| rest.split(' ').next())
        .and_then(|v| v.parse().ok())
        .expect("a speed that ends it in the drawn strings")
}

/// Semi-automatic ABC on the stick-slipping record above: the distance compares what the
/// regressions on the pilot's nearest strings predict. They predict the dynamic torque,
/// which sets the mean surface torque, almost exactly, the decay rate g, which the surface
/// hardly sees, least; the torques are found within their intervals and the bit's stuck
/// share within its 90 % range.
#[test]
fn semi_automatic_summaries_say_what_they_predict_and_find_the_torques() {
    let (_dir, path, bit_speed) = record(Law::M2, 60.0, 300.0, 1.0, 0.2, 3);
    let mut settings = small(vec![Law::M2]);
    settings.semi_automatic = true;
    let r = run(&path, &settings, 1);
    assert_eq!(r.distance, "semi-automatic");
    assert!(
        r.warnings.iter().all(|w| !w.contains("semi-automatic")),
        "{:?}",
        r.warnings
    );
    let projection = r.projection.as_ref().expect("a projection");
    // Half the pilot's strings that stayed in bounds (its reference table), the nearest.
    assert_eq!(projection.training, r.cost.pilot.div_ceil(2));
    let r2 = |name: &str| {
        projection
            .features
            .iter()
            .find(|f| f.name == name)
            .unwrap_or_else(|| panic!("{name} in {projection:?}"))
            .adjusted_r_squared
    };
    assert_eq!(
        projection.features.len(),
        3,
        "one law: its three parameters, no indicator"
    );
    eprintln!(
        "adjusted R²: tsb {:.3}, tcb {:.3}, g {:.3}",
        r2("m2.tsb"),
        r2("m2.tcb"),
        r2("m2.g")
    );
    assert!(r2("m2.tcb") > 0.95, "{projection:?}");
    assert!(r2("m2.g") < r2("m2.tsb") && r2("m2.g") < r2("m2.tcb"), "{projection:?}");
    let m2 = &r.laws[0];
    for (p, truth) in m2.params.iter().zip([13_000.0, 6_500.0]) {
        assert!(p.identified && p.q05 <= truth && truth <= p.q95, "{p:?}");
    }
    let mut seen = Summary::default();
    for w in &bit_speed {
        seen.push(*w, f64::NAN, f64::NAN);
    }
    let predicted = r.at_the_bit.stuck_share;
    eprintln!("stuck share {predicted:?} against {}", seen.stuck_share());
    assert!(
        predicted[0] <= seen.stuck_share() && seen.stuck_share() <= predicted[2],
        "{predicted:?}"
    );
}

#[test]
fn from_the_surface_alone_a_creeping_bit_is_told_from_a_held_one_where_the_string_is_known() {
    // m1 (no static torque: its bit creeps at 1-4 rpm where m2's is held) and m2 at 40 rpm on
    // the paper's string, ten minutes at 1 Hz with 0.2 kN·m of noise. The held bit lets the
    // string wind up at k·Ω, the creeping one slower: the wind-up rates differ by 5 %, the
    // noise is read on the wind-ups (the smooth estimate reads 0.42-0.48 kN·m there), m2
    // cannot wind the string up slower, so m1 leads on its records, and the check never calls
    // the other law. (m1 with a steep tanh nearly holds its bit: on m2's records at 1 Hz m2
    // leads seven times in ten at the command's budget, not asserted here.)
    let laws = vec![Law::M1, Law::M2];
    let wind_up = |r: &SurfaceResult| {
        let at = r.summary_names.iter().position(|n| *n == "wind_up_nm_s").unwrap();
        r.observed[at]
    };
    for seed in 1..=2 {
        let mut rates = Vec::new();
        for (slot, law) in laws.iter().enumerate() {
            let (_dir, path, _) = record(*law, 40.0, 600.0, 1.0, 0.2, seed);
            let r = run(&path, &small(laws.clone()), seed);
            let what = format!("{law}, seed {seed}");
            assert_eq!(r.noise.how, "wind_up", "{what}");
            assert!((r.noise.sd_nm - 200.0).abs() < 40.0, "{what}: noise {}", r.noise.sd_nm);
            if *law == Law::M1 {
                assert!(
                    r.laws[slot].probability > 0.5,
                    "{what}: {:?}",
                    r.laws.iter().map(|l| l.probability).collect::<Vec<_>>()
                );
            }
            assert!(r.check.decided.is_none_or(|d| d == *law), "{what}: {}", r.check.verdict);
            rates.push(wind_up(&r));
        }
        // k·Ω = 277 N·m/rad × 4.19 rad/s = 1,160 N·m/s for the held bit.
        assert!((rates[1] - 1160.0).abs() < 40.0, "seed {seed}: {rates:?}");
        assert!(rates[0] < 0.97 * rates[1], "seed {seed}: {rates:?}");
    }
}

#[test]
fn an_mwd_tool_s_downhole_minimum_tells_a_bit_held_still_from_one_that_creeps() {
    // m2 at 60 rpm, five minutes at 1 Hz. From the surface torque alone m1, whose bit creeps
    // at 1-3 rpm where m2's is held, draws the same cycle: the check calls neither. With an MWD
    // tool's downhole minimum and maximum since the sample before (the same simulation, the
    // same surface torque), m1's strings do not reach the record's minimum of 0 and m2 is
    // called, its torques within their 90 % intervals. Only m1's corner of a tanh steep enough
    // to hold the bit can, and its re-simulations are m2's: a few of its particles may survive
    // six populations (the check then rightly says undecided). Ten bring the sampler within
    // four noise floors of the record (the noise read on the wind-ups makes the floor tight).
    let laws = vec![Law::M1, Law::M2];
    let (_dir, surface_only, _) = record(Law::M2, 60.0, 300.0, 1.0, 0.2, 3);
    let blind = run(&surface_only, &small(laws.clone()), 1);
    assert_eq!(blind.check.decided, None, "{}", blind.check.verdict);
    let (_dir, path, bit_speed) = record_on(Lumped::default(), Law::M2, 60.0, 300.0, 1.0, 0.2, 3, Channels::Mwd);
    let mwd = read(&path);
    assert_eq!(
        mwd.surface_torque_nm,
        read(&surface_only).surface_torque_nm,
        "the same surface channels"
    );
    let mut settings = small(laws);
    settings.smc.schedule.max_populations = 10;
    let r = run(&path, &settings, 1);
    assert!(
        r.summary_names.contains(&"downhole_held_share"),
        "{:?}",
        r.summary_names
    );
    assert_eq!(r.check.decided, Some(Law::M2), "{}", r.check.verdict);
    let m2 = &r.laws[1];
    assert!(m2.probability > 0.9, "{:?}", r.laws);
    for (p, truth) in m2.params.iter().zip([13_000.0, 6_500.0]) {
        assert!(p.q05 <= truth && truth <= p.q95, "{p:?}");
    }
    // At the bit: the stuck share the laws disagreed on is the bit's.
    let mut seen = Summary::default();
    for w in &bit_speed {
        seen.push(*w, f64::NAN, f64::NAN);
    }
    let (truth, predicted) = (seen.stuck_share(), r.at_the_bit.stuck_share);
    assert!((predicted[1] - truth).abs() <= 0.05, "{predicted:?} against {truth}");
    assert!(
        predicted[0] <= truth && truth <= predicted[2],
        "{predicted:?} against {truth}"
    );
}

/// The bit's stuck share over a true speed record.
fn stuck_share(bit_speed: &[f64]) -> f64 {
    let mut seen = Summary::default();
    for w in bit_speed {
        seen.push(*w, f64::NAN, f64::NAN);
    }
    seen.stuck_share()
}

#[test]
fn a_string_s_natural_frequency_and_damping_are_inferred_with_the_law_within_their_bounds() {
    // m2 at its paper estimate on a string stiffer and less damped than the paper's (ω_n 1.2
    // rad/s and ξ 0.15 for 0.85 and 0.25): 60 rpm, five minutes at 1 Hz, 0.2 kN·m of noise.
    let string = Lumped {
        omega_n_rad_s: 1.2,
        damping_ratio: 0.15,
        ..Lumped::default()
    };
    let (_dir, path, bit_speed) = record_on(string, Law::M2, 60.0, 300.0, 1.0, 0.2, 3, Channels::All);
    let true_share = stuck_share(&bit_speed);
    let infer = |string: &[&str]| {
        let mut args = vec![
            "surface",
            path.to_str().unwrap(),
            "--laws",
            "m2",
            "--particles",
            "300",
            "--max-populations",
            "6",
            "--pilot",
            "300",
            "--check-replicates",
            "4",
            "--predictive-draws",
            "40",
            "--no-advice",
            "--backend",
            "cpu",
            "--json",
        ];
        args.extend(string);
        let (code, out, err) = outcome(bin().args(&args));
        assert_eq!(code, 0, "{err}");
        (serde_json::from_str::<serde_json::Value>(&out).unwrap(), err)
    };
    let posterior = path.with_file_name("posterior.csv");
    let out_dir = path.with_file_name("run");
    let (inferred, err) = infer(&[
        "--omega-n-rad-s",
        "0.6:1.8",
        "--damping-ratio",
        "0.05:0.5",
        "--posterior-out",
        posterior.to_str().unwrap(),
        "--out",
        out_dir.to_str().unwrap(),
    ]);
    // The damping ratio, weakly told by the surface, is said to be so.
    assert!(
        err.contains("damping ratio is inferred") && err.contains("--damping-ratio"),
        "{err}"
    );
    let s = &inferred["string"];
    assert_eq!(
        (&s["inferred"], &s["omega_n_rad_s"]["given"]),
        (&true.into(), &false.into())
    );
    for (name, truth, [lo, hi]) in [("omega_n_rad_s", 1.2, [0.6, 1.8]), ("damping_ratio", 0.15, [0.05, 0.5])] {
        let p = &s[name];
        let (q05, q95) = (p["q05"].as_f64().unwrap(), p["q95"].as_f64().unwrap());
        assert!(q05 <= truth && truth <= q95, "{name}: {p}");
        assert!(lo <= q05 && q95 <= hi, "{name}: {p}");
    }
    // The natural frequency is identified: its interval well inside its bounds.
    let omega = &s["omega_n_rad_s"];
    assert_eq!(omega["identified"], true, "{omega}");
    assert!(
        omega["q95"].as_f64().unwrap() - omega["q05"].as_f64().unwrap() < 0.5 * 1.2,
        "{omega}"
    );
    // The final population as particles: the string's coordinates after the law's
    // parameters, their weighted median the result's; `stability --posterior` maps them.
    let text = std::fs::read_to_string(&posterior).unwrap();
    let mut lines = text.lines();
    assert_eq!(
        lines.next().unwrap(),
        "population,law,candidate,rho,weight,m2.tsb [kN·m],m2.tcb [kN·m],m2.g [s/rad],string.omega_n [rad/s],string.damping_ratio [1]"
    );
    let rows: Vec<Vec<f64>> = lines
        .map(|l| l.split(',').skip(4).map(|v| v.parse().unwrap()).collect())
        .collect();
    assert_eq!(rows.len(), 300);
    let weights: Vec<f64> = rows.iter().map(|r| r[0]).collect();
    assert!((weights.iter().sum::<f64>() - 1.0).abs() < 1e-9);
    for (column, name) in [(4, "omega_n_rad_s"), (5, "damping_ratio")] {
        let values: Vec<f64> = rows.iter().map(|r| r[column]).collect();
        let median = bitrock::numerics::weighted_quantile(&values, &weights, 0.5);
        assert_eq!(
            median.to_bits(),
            s[name]["median"].as_f64().unwrap().to_bits(),
            "{name}"
        );
    }
    let (code, _, err) = outcome(
        bin()
            .args([
                "stability",
                "--json",
                "--omega-n-rad-s",
                "1.2",
                "--damping-ratio",
                "0.15",
                "--posterior",
            ])
            .arg(&posterior),
    );
    assert_eq!(code, 0, "{err}");
    // The directory mapped: its simulated strings each on its sample's own string, unless a
    // string is given.
    let map = |string: &[&str]| {
        let mut args = vec![
            "stability",
            "--run",
            out_dir.to_str().unwrap(),
            "--simulate",
            "--sim-omega-rpm",
            "60:120:2",
            "--sim-wob-kn",
            "200:244:2",
            "--sim-samples",
            "2",
        ];
        args.extend(string);
        let (code, _, err) = outcome(bin().args(&args));
        assert_eq!(code, 0, "{err}");
        err
    };
    let own = "the simulated strings each sample's own";
    let err = map(&[]);
    assert!(err.contains(own), "{err}");
    let err = map(&["--omega-n-rad-s", "1.2"]);
    assert!(!err.contains(own), "{err}");
    let k = s["stiffness_knm_per_rad"][1].as_f64().unwrap();
    let median = omega["median"].as_f64().unwrap();
    assert_eq!(k.to_bits(), (383.33 * median * median / 1000.0).to_bits());
    let share = |r: &serde_json::Value| r["at_the_bit"]["stuck_share"][1].as_f64().unwrap();
    assert!(
        (share(&inferred) - true_share).abs() <= 0.1,
        "{} for {true_share}",
        share(&inferred)
    );
    // The paper's string given in its place: the strings cannot reproduce the record, the
    // warning says so and names the string's bounds as the way out.
    let (given, err) = infer(&[]);
    assert_eq!(given["string"]["inferred"], false);
    assert_eq!(given["string"]["damping_ratio"]["given"], true);
    assert_eq!(given["string"]["omega_n_rad_s"]["median"], 0.85);
    assert!(err.contains("--omega-n-rad-s"), "{err}");
    assert!(
        (share(&given) - true_share).abs() > (share(&inferred) - true_share).abs(),
        "{} against {} for {true_share}",
        share(&given),
        share(&inferred)
    );
}

#[test]
fn a_string_s_bounds_are_refused_by_their_flag_when_they_cannot_be_run() {
    let (_dir, path, _) = record(Law::M2, 60.0, 60.0, 1.0, 0.2, 3);
    let path = path.to_str().unwrap();
    for (args, names) in [
        (vec!["--omega-n-rad-s", "1.8:0.6"], "--omega-n-rad-s"),
        (vec!["--damping-ratio", "0:0.5"], "--damping-ratio"),
        (vec!["--omega-n-rad-s", "0.6:x"], "--omega-n-rad-s"),
        // The stiffest string the bounds admit must be resolved by the step.
        (vec!["--omega-n-rad-s", "0.5:400", "--dt-s", "0.02"], "--dt-s"),
    ] {
        let (code, out, err) = outcome(bin().args(["surface", path]).args(&args));
        assert_eq!(code, 2, "{args:?}: {err}");
        assert!(out.is_empty(), "{args:?}: {out}");
        assert!(err.contains(names), "{args:?}: {err}");
    }
}

#[test]
fn a_steady_record_informs_the_law_only_through_its_mean_torque() {
    // m2 at 150 rpm turns steadily: the surface torque is T(Ω) plus noise, no cycle, and no law
    // is called whatever the probabilities.
    let (_dir, path, _) = record(Law::M2, 150.0, 300.0, 1.0, 0.1, 5);
    let r = run(&path, &small(vec![Law::M1, Law::M2]), 1);
    assert!(!r.cycle.informs() && r.cycle.period_s.is_none(), "{:?}", r.cycle);
    assert_eq!(r.check.decided, None);
    assert!(r.check.verdict.contains("only through T(Ω)"), "{}", r.check.verdict);
    let p = Law::M2.scale_torque(Law::M2.paper_estimate().unwrap(), 1000.0);
    let t = Law::M2.torque(&p, 150.0 * RAD_S_PER_RPM, 1.0);
    assert!(
        (r.mean_torque_nm - t).abs() < 0.01 * t,
        "{} against T(Ω) = {t}",
        r.mean_torque_nm
    );
    // The noise, read from a record without a cycle, is the noise: the estimator's standard
    // error on 300 white samples is 1.9σ²/√300 in σ², 5.5 % in σ; allowed 3.6 of them.
    assert_eq!(r.noise.how, "estimated");
    assert!((r.noise.sd_nm - 100.0).abs() < 20.0, "{:?}", r.noise);
}

#[test]
fn the_same_seed_gives_the_same_inference() {
    let (_dir, path, _) = record(Law::M2, 60.0, 120.0, 1.0, 0.2, 7);
    let settings = tiny(vec![Law::M1, Law::M2]);
    let a = run(&path, &settings, 11);
    let b = run(&path, &settings, 11);
    let text = |r: &SurfaceResult| {
        let mut v = serde_json::to_value(r).unwrap();
        v.as_object_mut().unwrap().remove("seconds");
        v.to_string()
    };
    assert_eq!(text(&a), text(&b));
    let c = run(&path, &settings, 12);
    assert_ne!(text(&a), text(&c), "another seed draws other candidates");
}

#[test]
fn surface_and_bit_records_each_go_to_their_own_command() {
    let (_dir, path, _) = record(Law::M2, 60.0, 60.0, 1.0, 0.0, 1);
    let dir = path.parent().unwrap();
    // 40 s of m2 at 60 rpm at 1 Hz, with `channels`.
    let simulated = |channels: &str, name: &str| {
        let path = dir.join(name);
        let (code, _, err) = outcome(
            bin()
                .args(["simulate", "--law", "m2", "--omega-rpm", "60", "--duration-s", "40"])
                .args(["--sample-hz", "1", "--channels", channels, "--out"])
                .arg(&path),
        );
        assert_eq!(code, 0, "{err}");
        path
    };
    // A surface-only record: `fit` finds no bit torque in it.
    let surface = simulated("surface", "surface.csv");
    let header = std::fs::read_to_string(&surface).unwrap();
    assert!(
        header.starts_with("time_s,top_drive_rpm,surface_torque_knm,wob_kn\n"),
        "{header}"
    );
    let (code, _, err) = outcome(bin().arg("fit").arg(&surface));
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("holds surface channels (top_drive_rpm, surface_torque_knm)") && err.contains("bitrock surface"),
        "{err}"
    );
    // Named as the bit's speed, a top-drive column still leaves the torque to be found: the
    // surface torque is not taken for it.
    let (code, _, err) = outcome(bin().arg("fit").arg(&surface).args(["--speed-col", "top_drive_rpm"]));
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("'surface_torque_knm' is a surface channel"), "{err}");
    // A bit record: `surface` finds no top drive in it, and names the flag.
    let bit = simulated("bit", "bit.csv");
    let (code, _, err) = outcome(bin().arg("surface").arg(&bit));
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("top-drive speed") && err.contains("--top-drive-col"),
        "{err}"
    );
    // A setting out of range is named by its flag before any simulation.
    let (code, _, err) = outcome(bin().arg("surface").arg(&path).args(["--pilot", "10"]));
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("--pilot"), "{err}");
}

#[test]
fn a_surface_directory_continues_to_the_populations_an_uninterrupted_run_gives() {
    let (tmp, path, _) = record(Law::M2, 60.0, 120.0, 1.0, 0.2, 7);
    let dir = tmp.path().join("run");
    // m4's prior is its box cut to the curves within twice the record's largest torque: the
    // cut's draws and weights continue as the rest do.
    let args = |extra: &[&str]| {
        let mut args = vec![
            "surface",
            path.to_str().unwrap(),
            "--laws",
            "m2,m4",
            "--particles",
            "150",
            "--pilot",
            "100",
            "--check-replicates",
            "4",
            "--predictive-draws",
            "40",
            "--no-advice",
            "--backend",
            "cpu",
            "--seed",
            "11",
            "--json",
        ];
        args.extend(extra);
        args.into_iter().map(String::from).collect::<Vec<_>>()
    };
    let document = |out: &str| {
        let mut v: serde_json::Value = serde_json::from_str(out).unwrap();
        v.as_object_mut().unwrap().remove("seconds");
        v
    };
    let (code, _, err) = outcome(bin().args(args(&["--max-populations", "2", "--out", dir.to_str().unwrap()])));
    assert_eq!(code, 0, "{err}");
    let mut names: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .filter(|n| !n.starts_with('.'))
        .collect();
    names.sort();
    assert_eq!(
        names,
        [
            "bit.csv",
            "populations.bin",
            "posterior.csv",
            "record.csv",
            "surface-job.json",
            "surface.json"
        ]
    );
    assert_eq!(
        std::fs::read(&path).unwrap(),
        std::fs::read(dir.join("record.csv")).unwrap()
    );
    let two: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.join("surface.json")).unwrap()).unwrap();
    assert_eq!(two["populations"], 2);

    // Continued to three populations, from the directory alone (the record moved away):
    // exactly the uninterrupted run of three.
    let moved = path.with_file_name("moved.csv");
    std::fs::rename(&path, &moved).unwrap();
    let (code, continued, err) = outcome(bin().args([
        "surface",
        "--resume",
        dir.to_str().unwrap(),
        "--max-populations",
        "3",
        "--json",
    ]));
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("after population 1 (2 stored)"), "{err}");
    std::fs::rename(&moved, &path).unwrap();
    let (code, whole, err) = outcome(bin().args(args(&["--max-populations", "3"])));
    assert_eq!(code, 0, "{err}");
    let (continued, whole) = (document(&continued), document(&whole));
    assert_eq!(continued["populations"], 3);
    assert_eq!(continued, whole);
    assert!(whole["laws"][0]["prior_curve"].is_null(), "{whole}");
    assert_eq!(whole["laws"][1]["prior_curve"]["within"], 2.0, "{whole}");
    let written: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.join("surface.json")).unwrap()).unwrap();
    assert_eq!(written["epsilons"], whole["epsilons"]);

    // A run already there is not replaced unless asked, a directory of the user's never, and a
    // directory without a surface run is not continued.
    let (code, _, err) = outcome(bin().args(args(&["--out", dir.to_str().unwrap()])));
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("--out") && err.contains("--resume"), "{err}");
    let theirs = tmp.path().join("theirs");
    std::fs::create_dir(&theirs).unwrap();
    std::fs::write(theirs.join("notes.txt"), "mine").unwrap();
    let (code, _, err) = outcome(bin().args(args(&["--out", theirs.to_str().unwrap(), "--force"])));
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("notes.txt"), "{err}");
    assert_eq!(std::fs::read_to_string(theirs.join("notes.txt")).unwrap(), "mine");
    let (code, _, err) = outcome(bin().args(["surface", "--resume", theirs.to_str().unwrap()]));
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("--resume") && err.contains("holds no surface run"),
        "{err}"
    );
    // The record and the laws are the run's own when it continues.
    let (code, _, err) = outcome(bin().args(["surface", "--resume", dir.to_str().unwrap(), "--laws", "m2"]));
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("--laws"), "{err}");
    let (code, _, err) = outcome(bin().args(["surface", "--resume", dir.to_str().unwrap(), "--seed", "3"]));
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("--seed"), "{err}");
    let (code, _, err) = outcome(bin().args(["surface", "--resume", dir.to_str().unwrap(), "--max-populations", "2"]));
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("--max-populations") && err.contains("holds 3 populations"),
        "{err}"
    );

    // Its posterior mapped on its own string, at the record's mean weight (the laws inferred
    // at r = 1 hold there), with the advice at its operating point from the bit it implies.
    let (code, out, err) = outcome(bin().args(["stability", "--run", dir.to_str().unwrap(), "--json"]));
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("the run's own drill string"), "{err}");
    let maps: serde_json::Value = serde_json::from_str(&out).unwrap();
    let at_the_bit = &written["at_the_bit"];
    assert_eq!(maps["record"]["stuck_share"], at_the_bit["stuck_share"][1]);
    assert_eq!(maps["record"]["severity"], at_the_bit["severity"][1]);
    let mean_rpm = maps["record"]["mean_speed_rpm"].as_f64().unwrap();
    assert!((mean_rpm - 60.0).abs() < 1e-9, "{mean_rpm}");
    let wob_kn = maps["record"]["mean_wob_kn"].as_f64().unwrap();
    assert!(
        (wob_kn - bitrock::laws::PAPER_W_REF_N / 1000.0).abs() < 1e-6,
        "{wob_kn}"
    );
    assert!(maps["advice"]["words"].as_str().is_some(), "{out}");
    // Checked again with more records per law: the populations as they were.
    let (code, out, err) =
        outcome(bin().args(["check-selection", dir.to_str().unwrap(), "--replicates", "6", "--json"]));
    assert_eq!(code, 0, "{err}");
    let check: serde_json::Value = serde_json::from_str(&out).unwrap();
    let rechecked: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("surface.json")).unwrap()).unwrap();
    assert_eq!(rechecked["check"], check);
    for row in check["rows"].as_array().unwrap() {
        assert_eq!(row["replicates"], 6, "{check}");
    }
    assert_eq!(rechecked["epsilons"], whole["epsilons"]);
    assert_eq!(rechecked["laws"], whole["laws"]);
    // Reported: the laws with the check as the document has them, and the figure.
    let report = tmp.path().join("report");
    let (code, _, err) = outcome(bin().args(["report", dir.to_str().unwrap(), "--out", report.to_str().unwrap()]));
    assert_eq!(code, 0, "{err}");
    let md = std::fs::read_to_string(report.join("report.md")).unwrap();
    assert!(md.contains(rechecked["check"]["verdict"].as_str().unwrap()), "{md}");
    for law in rechecked["laws"].as_array().unwrap() {
        let line = format!(
            "| {} | {:.3} |",
            law["law"].as_str().unwrap(),
            law["probability"].as_f64().unwrap()
        );
        assert!(md.contains(&line), "{line}: {md}");
    }
    for ext in ["svg", "png"] {
        assert!(report.join(format!("figures/fig01_surface_and_bit.{ext}")).is_file());
    }
    // A run killed after storing its populations, before its results: said where its
    // results are asked for, and continued to them.
    for name in ["surface.json", "posterior.csv", "bit.csv"] {
        std::fs::remove_file(dir.join(name)).unwrap();
    }
    let (code, _, err) = outcome(bin().args(["stability", "--run", dir.to_str().unwrap()]));
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("under way") && err.contains("--resume"), "{err}");
    let (code, out, err) = outcome(bin().args(["surface", "--resume", dir.to_str().unwrap(), "--json"]));
    assert_eq!(code, 0, "{err}");
    assert_eq!(document(&out)["epsilons"], whole["epsilons"]);
    assert!(dir.join("surface.json").is_file());
    // What reads ABC runs only says what the directory is.
    let (code, _, err) = outcome(bin().args(["export", dir.to_str().unwrap()]));
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("holds a surface run"), "{err}");
}

/// Through workers that answer in any order, lose replies and run tasks twice (the transport
/// `shard.rs` tests record runs with): the surface run of one process, number for number. Two
/// laws, the string's natural frequency inferred with them and semi-automatic summaries, so
/// that the string's coordinates and the regressions' weights travel too.
#[test]
fn a_surface_run_through_workers_is_the_one_process_run() {
    use bitrock::abc::Population;
    use bitrock::abc::shard::{Remote, Workers};
    use bitrock::run::surface::{Sampling, StringBounds, infer_continuing};
    use bitrock::run::{MakeWorkers, Placement, Scoring};
    use std::sync::atomic::Ordering;
    let (_dir, path, _) = record(Law::M2, 60.0, 120.0, 1.0, 0.2, 5);
    let mut settings = tiny(vec![Law::M1, Law::M2]);
    // The regressions need 51 training strings of a law: the nearest 60 of 120.
    settings.pilot = 120;
    settings.semi_automatic = true;
    settings.string_bounds = Some(StringBounds {
        omega_n_rad_s: [0.6, 0.9],
        damping_ratio: [0.05, 0.05],
    });
    let record = read(&path);
    let text = |r: &SurfaceResult| {
        let mut v = serde_json::to_value(r).unwrap();
        v.as_object_mut().unwrap().remove("seconds");
        v.to_string()
    };
    let here = infer(&record, &settings, 4, &mut |_| {}).unwrap();
    assert!(here.projection.is_some() && here.string.inferred);
    let workers = super::shard::Scrambling::new(3, 8);
    let mut make = |objective, placement: &Placement, _: &mut dyn FnMut(String)| {
        let remote = Remote::new(objective, placement.backend, placement.shape, &workers);
        Ok(Box::new(remote) as Box<dyn Workers + '_>)
    };
    let mut ignore = |_: &[Population]| Ok(());
    let sampling = Sampling {
        previous: Vec::new(),
        stopped: None,
        keep: &mut ignore,
        warm: &[],
        scoring: Scoring::Workers(&mut make as &mut MakeWorkers),
    };
    let there = infer_continuing(&record, &settings, 4, sampling, &mut |_| {}).unwrap();
    assert!(workers.lost.load(Ordering::Relaxed) > 0 && workers.asked.load(Ordering::Relaxed) > 0);
    assert_eq!(text(&there), text(&here));
}

#[test]
fn the_populations_kept_as_they_complete_continue_to_the_uninterrupted_run() {
    use bitrock::abc::Population;
    use bitrock::run::Scoring;
    use bitrock::run::surface::{Sampling, infer_continuing};
    let (_dir, path, _) = record(Law::M2, 60.0, 120.0, 1.0, 0.2, 7);
    let settings = tiny(vec![Law::M1, Law::M2]);
    let record = read(&path);
    let text = |r: &SurfaceResult| {
        let mut v = serde_json::to_value(r).unwrap();
        v.as_object_mut().unwrap().remove("seconds");
        v.to_string()
    };
    // Each population handed on as it completes, with all before it: what a directory stores.
    let mut kept: Vec<Vec<Population>> = Vec::new();
    let whole = {
        let mut keep = |populations: &[Population]| {
            kept.push(populations.to_vec());
            Ok(())
        };
        let sampling = Sampling {
            previous: Vec::new(),
            stopped: None,
            keep: &mut keep,
            warm: &[],
            scoring: Scoring::Here,
        };
        infer_continuing(&record, &settings, 11, sampling, &mut |_| {}).unwrap()
    };
    let run = whole.run.as_ref().unwrap();
    assert_eq!(run.populations.len(), 3);
    assert_eq!(kept.len(), 3);
    for (k, populations) in kept.iter().enumerate() {
        assert_eq!(populations.as_slice(), &run.populations[..=k]);
    }
    // What a run killed after its first population leaves, continued: the same result.
    let mut ignore = |_: &[Population]| Ok(());
    let sampling = Sampling {
        previous: kept[0].clone(),
        stopped: None,
        keep: &mut ignore,
        warm: &[],
        scoring: Scoring::Here,
    };
    let continued = infer_continuing(&record, &settings, 11, sampling, &mut |_| {}).unwrap();
    assert_eq!(text(&continued), text(&whole));
    // Warm-started from that run's posterior (as a watch's next window is): population 0 is
    // drawn near it and weighted back to the prior, and the same three populations end nearer
    // the record, the torques found within the cold run's intervals.
    let last = &run.populations.last().unwrap().particles;
    let sampling = Sampling {
        previous: Vec::new(),
        stopped: None,
        keep: &mut ignore,
        warm: last,
        scoring: Scoring::Here,
    };
    let warm = infer_continuing(&record, &settings, 12, sampling, &mut |_| {}).unwrap();
    let warm_run = warm.run.as_ref().unwrap();
    assert_eq!(warm_run.populations.len(), 3);
    assert_eq!(warm_run.populations[0].record.epsilon, None);
    assert!(
        warm.final_epsilon.unwrap() < whole.final_epsilon.unwrap(),
        "{:?} against {:?}",
        warm.final_epsilon,
        whole.final_epsilon
    );
    let m2 = |r: &SurfaceResult| r.laws.iter().find(|l| l.law == Law::M2).unwrap().params.clone();
    for (w, c) in m2(&warm).iter().zip(m2(&whole)) {
        assert!(c.q05 <= w.median && w.median <= c.q95, "{w:?} against {c:?}");
    }
}

/// A watch of a record of surface channels alone: each window through simulated strings,
/// the same inference as `bitrock surface` on the window's rows (window k seeded seed + k),
/// its model choice checked, and its advice from the bit the surface implies.
#[test]
fn a_watch_of_surface_channels_infers_each_window_through_simulated_strings() {
    // m2 at 60 rpm, four minutes at 1 Hz, surface channels only: the bit stuck about half the
    // time.
    let (dir, path, bit_speed) = record_on(Lumped::default(), Law::M2, 60.0, 240.0, 1.0, 0.2, 3, Channels::Surface);
    let watch = |path: &std::path::Path, laws: &str, extra: &[&str]| {
        let (code, out, err) = outcome(
            bin()
                .arg("watch")
                .arg(path)
                .args([
                    "--laws",
                    laws,
                    "--window-s",
                    "120",
                    "--step-s",
                    "60",
                    "--backend",
                    "cpu",
                ])
                .args(["--seed", "7", "--json"])
                .args(extra),
        );
        let updates: Vec<serde_json::Value> = out.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
        (code, updates, err)
    };
    let stored = dir.path().join("m2-watch");
    let (code, updates, err) = watch(&path, "m2", &["--out", stored.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    assert_eq!(updates.len(), 3, "{err}");
    assert!(
        err.contains("a record of surface channels alone (top-drive speed top_drive_rpm"),
        "{err}"
    );
    for u in &updates {
        assert!(u["uninformative"].is_null(), "{u}");
        assert_eq!(u["check"]["decided"], "m2", "{u}");
        // The bit's stuck share over the window, as its surface implies it, against the truth.
        let (from, to) = (
            u["start_s"].as_f64().unwrap() as usize,
            u["end_s"].as_f64().unwrap() as usize,
        );
        let mut seen = Summary::default();
        for w in &bit_speed[from..to] {
            seen.push(*w, f64::NAN, f64::NAN);
        }
        let advice = &u["advice"];
        let implied = advice["stuck_share"].as_f64().unwrap();
        assert!(seen.stuck_share() > 0.4, "{}", seen.stuck_share());
        assert!(
            (implied - seen.stuck_share()).abs() <= 0.06,
            "{implied} against {}",
            seen.stuck_share()
        );
        assert_eq!(advice["stick_slip_now"], true, "{advice}");
        assert!(advice["escape_omega_rpm"][0].as_f64().unwrap() > 60.0, "{advice}");
        // The window leaves g open: the way out along its spread too.
        assert_eq!(advice["spread"]["open"], serde_json::json!(["m2's g"]), "{advice}");
    }
    // Applied to the true string stuck at 60 rpm: the last window's drawn strings end the
    // stick-slip at a speed and a weight its bit does not (70 rpm and 195 kN, measured), the
    // strings along g's spread at ones it does: each window's lighter weight (73-85 kN), and
    // a higher speed where every string of the spread ends at one of the speeds scanned (140
    // and 165 rpm in the first two windows; in the last, g's 1 % quantile lies at the foot of
    // its box, 0.1 s/rad, whose string is still stuck at every speed scanned, and no speed is
    // advised, only the weight).
    let number = |v: &serde_json::Value| v.as_f64().unwrap();
    let last = &updates.last().unwrap()["advice"];
    let (mut speeds, mut weights) = (
        vec![number(&last["escape_omega_rpm"][0])],
        vec![number(&last["escape_wob_kn"][0])],
    );
    for u in &updates {
        let spread = &u["advice"]["spread"];
        speeds.extend(spread["speed_rpm"].as_f64());
        weights.push(number(&spread["wob_kn"]));
    }
    assert!(speeds.len() > 1, "no window's spread gives a speed: {updates:?}");
    let (by_speed, by_weight) = true_bit_after(Lumped::default(), &speeds, &weights);
    let persists = |n: usize| {
        std::iter::once(1.0)
            .chain(std::iter::repeat_n(0.0, n - 1))
            .collect::<Vec<f64>>()
    };
    assert_eq!(
        (by_speed, by_weight),
        (persists(speeds.len()), persists(weights.len())),
        "{speeds:?} and {weights:?}"
    );
    // The page's picture of the last window: no bit channels to draw, the surface channels
    // and the bit speed the strings imply, sample for sample on the window's stretch of the
    // record, the median band stuck about as often as the bit was.
    let view = bitrock::watch::store::read(&stored).unwrap().view.unwrap();
    assert!(view.speed_rpm.is_empty() && view.band.is_none(), "{view:?}");
    let strip = view.surface.expect("a surface window's strip");
    let last = updates.last().unwrap();
    let (from, to) = (last["start_s"].as_f64().unwrap(), last["end_s"].as_f64().unwrap());
    assert_eq!(strip.time_s.len(), 120);
    assert_eq!((strip.time_s[0], *strip.time_s.last().unwrap()), (from, to - 1.0));
    assert_eq!(strip.bit_rpm.len(), strip.time_s.len());
    assert!(strip.top_drive_rpm.iter().all(|w| (w - 60.0).abs() < 1e-6));
    let record_torque: Vec<f64> = {
        let record = read(&path);
        record.surface_torque_nm[from as usize..to as usize]
            .iter()
            .map(|t| t / 1000.0)
            .collect()
    };
    assert_eq!(strip.surface_torque, record_torque, "kN·m, the record's unit");
    assert!(strip.bit_rpm.iter().all(|q| q[0] <= q[1] && q[1] <= q[2]));
    let stuck = strip.bit_rpm.iter().filter(|q| q[1].abs() < 1.0).count() as f64 / 120.0;
    let mut seen = Summary::default();
    for w in &bit_speed[from as usize..to as usize] {
        seen.push(*w, f64::NAN, f64::NAN);
    }
    assert!(
        (stuck - seen.stuck_share()).abs() <= 0.15,
        "{stuck} against {}",
        seen.stuck_share()
    );
    // Window 0 is `bitrock surface` on its 120 rows with the watch's settings and seed.
    let text = std::fs::read_to_string(&path).unwrap();
    let first = dir.path().join("first.csv");
    std::fs::write(&first, text.lines().take(121).collect::<Vec<_>>().join("\n") + "\n").unwrap();
    let (code, out, err) = outcome(
        bin()
            .arg("surface")
            .arg(&first)
            .args(["--laws", "m2", "--backend", "cpu", "--seed", "7", "--particles", "300"])
            .args(["--max-populations", "6", "--pilot", "300", "--check-replicates", "10"])
            .args(["--predictive-draws", "40", "--no-advice", "--json"]),
    );
    assert_eq!(code, 0, "{err}");
    let alone: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(
        updates[0]["advice"]["stuck_share"],
        alone["at_the_bit"]["stuck_share"][1]
    );
    assert_eq!(updates[0]["epsilon"], alone["final_epsilon"]);
    assert_eq!(updates[0]["candidates_scored"], alone["simulations"]);

    // The same record as a rig's WITS feed of surface channels (item 0999 its seconds, 0120
    // the rotary speed, 0118 the rotary torque, 0116 the WOB): the same windows, number for
    // number.
    let wits = dir.path().join("rig.wits");
    let blocks: String = text
        .lines()
        .skip(1)
        .map(|line| {
            let cells: Vec<&str> = line.split(',').collect();
            format!(
                "&&\n0999{}\n0120{}\n0118{}\n0116{}\n!!\n",
                cells[0], cells[1], cells[2], cells[3]
            )
        })
        .collect();
    std::fs::write(&wits, blocks).unwrap();
    let items = [
        "--wits-items",
        "seconds=0999,surface_torque=0118",
        "--torque-unit",
        "knm",
        "--wob-unit",
        "kn",
    ];
    let (code, fed, err) = watch(&wits, "m2", &items);
    assert_eq!(code, 0, "{err}");
    assert_eq!(fed.len(), updates.len());
    for (fed, read) in fed.iter().zip(&updates) {
        for field in ["epsilon", "candidates_scored", "laws", "advice", "check"] {
            assert_eq!(fed[field], read[field], "{field}");
        }
    }

    // A bit that turns steadily (150 rpm): its surface torque shows no cycle, and no window
    // is taken to inform the law.
    let (_steady_dir, steady, _) = record_on(Lumped::default(), Law::M2, 150.0, 240.0, 1.0, 0.1, 5, Channels::Surface);
    let kept = dir.path().join("steady-watch");
    let out = ["--out", kept.to_str().unwrap()];
    let (code, updates, err) = watch(&steady, "m1,m2", &out);
    assert_eq!(code, 0, "{err}");
    assert_eq!(updates.len(), 3);
    for u in &updates {
        let why = u["uninformative"].as_str().unwrap_or_default();
        assert!(why.contains("only through T(Ω)"), "{u}");
        assert!(u["laws"].as_array().unwrap().is_empty() && u["advice"].is_null(), "{u}");
    }
    // A watch of surface channels goes on with surface channels only.
    let (_bit_dir, bit, _) = record_on(Lumped::default(), Law::M2, 60.0, 60.0, 1.0, 0.1, 5, Channels::Bit);
    let (code, _, err) = watch(&bit, "m1,m2", &[&out[..], &["--resume"]].concat());
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("--resume") && err.contains("read surface channels alone"),
        "{err}"
    );
    // A record of surface channels without a clock is refused in the surface record's words.
    let clockless = dir.path().join("clockless.csv");
    let text_without_time: String = text
        .lines()
        .map(|line| line.split(',').skip(1).collect::<Vec<_>>().join(",") + "\n")
        .collect();
    std::fs::write(&clockless, text_without_time).unwrap();
    let (code, _, err) = watch(&clockless, "m2", &[]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("time") && !err.contains("bitrock surface"), "{err}");
    // The paper's ABC fits the bit's torque: refused on surface channels, by its flag.
    let (code, _, err) = watch(&path, "m2", &["--abc"]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("--abc") && err.contains("simulated strings"), "{err}");
}

/// The true string's m2 at its paper estimate, settled stuck at 60 rpm under the paper's
/// W_ref: P(stick-slip persists) at each of `speeds_rpm` (at that weight), then at each of
/// `weights_kn` (at 60 rpm).
fn true_bit_after(string: Lumped, speeds_rpm: &[f64], weights_kn: &[f64]) -> (Vec<f64>, Vec<f64>) {
    use bitrock::run::strings::{OperatingPoint, SimulatedSettings, Simulator};
    use bitrock::simulate::strings::Chain;
    use bitrock::stability::map::LawSamples;
    let truth = Law::M2.scale_torque(Law::M2.paper_estimate().unwrap(), 1000.0);
    let inputs = vec![LawSamples {
        law: Law::M2,
        probability: 1.0,
        map_si: truth.clone(),
        samples_si: vec![truth],
        strings: Vec::new(),
    }];
    let wob_kn = bitrock::laws::PAPER_W_REF_N / 1000.0;
    let simulated = SimulatedSettings::new(Chain::one_dof(&string), wob_kn * 1000.0, bitrock::eval::Backend::Cpu);
    let mut quiet = |_| {};
    let mut simulator = Simulator::new(&simulated, &inputs, &mut quiet).unwrap();
    let at = simulator
        .at_point(OperatingPoint {
            omega_rpm: 60.0,
            wob_kn,
        })
        .unwrap();
    assert_eq!(at.stick_slip_probability, 1.0);
    let by_speed = simulator.escape(&at, speeds_rpm, &[wob_kn]).unwrap().probability;
    let by_weight = if weights_kn.is_empty() {
        Vec::new()
    } else {
        simulator.escape(&at, &[60.0], weights_kn).unwrap().probability
    };
    (by_speed, by_weight)
}

#[test]
fn on_a_string_inferred_with_the_law_the_way_out_along_the_spread_gets_the_true_bit_out() {
    use bitrock::run::surface::StringBounds;
    // m2 at its paper estimate on a softer string than the paper's (ω_n 0.6 rad/s): its bit
    // stays stuck at 60 rpm until 165 rpm (P(persists) 0.625 at 150), or until the weight is
    // lowered to 60 kN (still stuck at 80).
    let string = Lumped {
        omega_n_rad_s: 0.6,
        ..Lumped::default()
    };
    let (_dir, path, _) = record_on(string, Law::M2, 60.0, 300.0, 1.0, 0.2, 3, Channels::All);
    let mut settings = SurfaceSettings::new(vec![Law::M2]);
    settings.backend = bitrock::eval::Backend::Cpu;
    settings.advice = true;
    settings.string_bounds = Some(StringBounds {
        omega_n_rad_s: [0.4, 1.8],
        damping_ratio: [0.25, 0.25],
    });
    let r = run(&path, &settings, 1);
    let omega = &r.string.omega_n_rad_s.posterior;
    assert!(omega.q05 <= 0.6 && 0.6 <= omega.q95, "{omega:?}");
    let open = r.at_the_bit.spread_advice.as_ref().expect("g is left open");
    let advice = r.at_the_bit.advice.as_deref().unwrap();
    eprintln!("{advice}\n{open:?}");
    assert_eq!(open.open, ["m2's g"]);
    let lighter = open.wob_kn.expect("a weight that ends it along g's spread");
    let drawn = drawn_speed_rpm(advice);
    let (persists, _) = true_bit_after(string, &[drawn], &[]);
    assert_eq!(
        persists,
        [1.0],
        "the drawn strings' {drawn} rpm leaves the true bit stuck"
    );
    let speeds = [open.speed_rpm.expect("a speed that ends it along g's spread")];
    let (by_speed, by_weight) = true_bit_after(string, &speeds, &[lighter]);
    eprintln!("the true bit after {speeds:?} rpm: {by_speed:?}; after {lighter} kN: {by_weight:?}");
    assert!(by_speed.iter().all(|p| *p == 0.0), "{by_speed:?} at {speeds:?} rpm");
    assert_eq!(by_weight, [0.0], "at {lighter} kN");
}
