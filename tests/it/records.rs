//! Records like a public laboratory test rig (issue 14), which break the paper's defaults:
//! torque of a few N·m and weight on bit of a few hundred N, bit speed from below zero (speed
//! noise while the bit sticks) to a few hundred rpm, a least-squares estimate on its physical
//! bound (m2's dynamic torque tcb) and a noise floor far above the paper's ε = 0.014.

use crate::support::bin;
use bitrock::bench::SelectionRecord;
use std::io::Write;
use std::sync::OnceLock;

/// The rig's light string: the one its record was simulated on.
const RIG_STRING: [&str; 6] = [
    "--inertia-kg-m2",
    "0.02",
    "--omega-n-rad-s",
    "5",
    "--damping-ratio",
    "0.1",
];

/// The rig record as a CSV file in N·m and N, written once per test binary: the selection
/// benchmark's rig ([`SelectionRecord::Rig`], the new law m3 with a nearly linear velocity
/// weakening on a light string at 100 rpm and 500 N, r = 1, with 0.15 N·m torque noise and
/// 2 rpm speed noise).
fn rig_record() -> &'static std::path::Path {
    static FILE: OnceLock<tempfile::TempPath> = OnceLock::new();
    FILE.get_or_init(|| {
        let csv = SelectionRecord::Rig.csv().unwrap().unwrap();
        let speeds_rpm: Vec<f64> = std::str::from_utf8(&csv)
            .unwrap()
            .lines()
            .skip(1)
            .map(|line| line.split(',').nth(1).unwrap().parse().unwrap())
            .collect();
        let lo = speeds_rpm.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = speeds_rpm.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        assert!(lo < 0.0 && hi > 300.0, "not the rig's range: {lo}..{hi} rpm");
        let mut file = tempfile::Builder::new().suffix(".csv").tempfile().unwrap();
        file.write_all(&csv).unwrap();
        file.into_temp_path()
    })
}

fn run(args: &[&str]) -> (i32, String, String) {
    let out = bin().args(args).output().expect("run bitrock");
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn json(text: &str) -> serde_json::Value {
    serde_json::from_str(text).unwrap_or_else(|e| panic!("{e}: {text}"))
}

/// Best least-squares ρ per law, from `fit --json`.
fn best_rho(fit: &serde_json::Value) -> Vec<(String, f64)> {
    fit["fits"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| (f["law"].as_str().unwrap().to_string(), f["rho"].as_f64().unwrap()))
        .collect()
}

#[test]
fn fit_warns_about_the_estimate_on_its_bound_and_the_noise_floor_is_above_the_papers() {
    let path = rig_record().to_str().unwrap();
    let (code, stdout, stderr) = run(&["fit", path, "--json"]);
    assert_eq!(code, 0, "{stderr}");
    let fit = json(&stdout);
    assert_eq!(fit["torque_unit"], "N·m");
    let m2 = &fit["fits"][1];
    assert_eq!(m2["law"], "m2");
    let warnings = m2["warnings"].to_string();
    assert!(warnings.contains("tcb sits on its physical bound"), "{warnings}");
    let tcb = m2["params"][1].as_f64().unwrap();
    assert!((0.0..1e-5).contains(&tcb), "tcb = {tcb} N·m");
    for (law, rho) in best_rho(&fit) {
        assert!(
            rho > 2.0 * 0.014,
            "{law}: ρ = {rho}: not a record with a high noise floor"
        );
    }
}

#[test]
fn abc_with_every_default_samples_all_laws_to_a_reachable_floor_and_marks_the_rest() {
    let path = rig_record().to_str().unwrap();
    let (_, stdout, _) = run(&["fit", path, "--json"]);
    let fits = best_rho(&json(&stdout));
    let best = fits.iter().map(|f| f.1).fold(f64::INFINITY, f64::min);
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    let out_s = out.to_str().unwrap();
    let (code, _, stderr) = run(&["abc", path, "--particles", "2000", "--backend", "cpu", "--out", out_s]);
    assert_eq!(code, 0, "{stderr}");
    // One line says why the floor is not the paper's.
    assert!(
        stderr.contains("ε floor") && stderr.contains("1.1 × the best least-squares ρ"),
        "{stderr}"
    );
    let run_json = json(&std::fs::read_to_string(out.join("run.json")).unwrap());
    let eps_min = run_json["config"]["sampler"]["eps_min"].as_f64().unwrap();
    assert_eq!(eps_min.to_bits(), (1.1 * best).to_bits());
    assert_eq!(run_json["stop_reason"], "eps_min");
    // Every law is in the prior; m2's tcb (on its bound) has a box of the record's scale.
    let priors = run_json["priors"].as_array().unwrap();
    assert_eq!(priors.len(), 4);
    assert_eq!(priors[1]["law"], "m2");
    assert_eq!(priors[1]["rules"][1], "record_scale");
    assert_eq!(priors[1]["lower"][1].as_f64().unwrap().to_bits(), 0.0f64.to_bits());
    let populations = run_json["populations"].as_array().unwrap();
    assert!(populations.len() <= 12, "{} populations", populations.len());
    // A law is unreachable exactly when its best ρ is at or above ε and none was accepted;
    // then its probability is 0 by construction.
    let mut marked = 0;
    for p in populations {
        let epsilon = p["epsilon"].as_f64().unwrap_or(f64::INFINITY);
        for l in p["per_law"].as_array().unwrap() {
            let law = l["law"].as_str().unwrap();
            let rho = fits.iter().find(|f| f.0 == law).unwrap().1;
            let accepted = l["accepted"].as_u64().unwrap();
            let reachable = l["reachable"].as_bool().unwrap();
            assert_eq!(reachable, accepted > 0 || rho < epsilon, "{law} at ε = {epsilon}: {l}");
            if !reachable {
                assert_eq!(l["probability"].as_f64().unwrap().to_bits(), 0.0f64.to_bits());
                marked += 1;
            }
        }
    }
    assert!(
        marked > 0,
        "the worst law (best ρ well above the floor) is never marked"
    );
}

#[test]
fn stability_of_the_rig_run_agrees_with_the_closed_form_and_the_simulated_stick_slip() {
    let path = rig_record().to_str().unwrap();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    let out_s = out.to_str().unwrap();
    // The rig's own light string, given to the run and kept with it.
    let mut args = vec![
        "abc",
        path,
        "--particles",
        "1000",
        "--backend",
        "cpu",
        "--out",
        out_s,
        "--quiet",
    ];
    args.extend_from_slice(&RIG_STRING);
    let (code, _, stderr) = run(&args);
    assert_eq!(code, 0, "{stderr}");
    let document = json(&std::fs::read_to_string(out.join("run.json")).unwrap());
    assert_eq!(
        document["config"]["string"],
        serde_json::json!({"structure": "1dof", "lumped": {"inertia_kg_m2": 0.02, "omega_n_rad_s": 5.0, "damping_ratio": 0.1}})
    );
    // Mapped on the run's own string without naming it again.
    let (code, stdout, stderr) = run(&[
        "stability",
        "--run",
        out_s,
        "--w-ref-kn",
        "0.5",
        "--omega-rpm",
        "100:120:3",
        "--wob-kn",
        "0.05:0.5:2",
        "--backend",
        "cpu",
        "--json",
    ]);
    assert_eq!(code, 0, "{stderr}");
    let map = json(&stdout);
    assert!(
        stderr.contains("note: the run's own drill string: 1-DOF string I_eq = 0.02 kg·m², ω_n = 5 rad/s, ξ = 0.1"),
        "{stderr}"
    );
    // 1-DOF: c_b* = −c_eq = −2 ξ ω_n I = −0.02 N·m·s/rad.
    let critical = map["critical_bit_damping_nms"].as_f64().unwrap();
    assert!((critical + 0.02).abs() < 1e-12, "{critical}");
    // The record shows stick-slip at 100 rpm and 500 N, so the law it was made from is unstable
    // there; at 50 N (r = 0.1) its damping r·dT/dw ≈ −0.008 lies above c_b*: stable.
    let p: Vec<f64> = map["probability_unstable"]["m3"]
        .as_array()
        .unwrap()
        .iter()
        .flat_map(|row| row.as_array().unwrap().iter().map(|v| v.as_f64().unwrap()))
        .collect();
    // Layout [Ω][W] or [W][Ω]: Ω = 100 rpm comes first either way, W = 50 N before 500 N.
    let omega = map["omega_rpm"].as_array().unwrap();
    assert_eq!((omega.len(), p.len()), (3, 6));
    let at = |o: usize, w: usize| {
        let rows = map["probability_unstable"]["m3"].as_array().unwrap();
        if rows.len() == omega.len() {
            p[2 * o + w]
        } else {
            p[2 * w + o]
        }
    };
    assert!(
        at(0, 0) <= 0.01 && at(0, 1) >= 0.99,
        "P(unstable) at 100 rpm, 50 N and 500 N: {p:?}"
    );

    // The same run on the paper's field string (flags over the run's own) and map: its torques
    // of a few N·m put every boundary hundreds of times above the map's 700 kN. Said, with
    // where it lies, not drawn blank in silence.
    let paper_string = [
        "--inertia-kg-m2",
        "383.33",
        "--omega-n-rad-s",
        "0.85",
        "--damping-ratio",
        "0.25",
    ];
    let mut args = vec!["stability", "--run", out_s, "--backend", "cpu", "--samples", "50"];
    args.extend_from_slice(&paper_string);
    let (code, _, stderr) = run(&args);
    assert_eq!(code, 0, "{stderr}");
    assert!(
        stderr.contains(
            "warning: law m3's MAP boundary lies above the map's highest weight on bit (700 kN) at every speed (lowest "
        ) && stderr.contains("the paper's 5 km field string"),
        "{stderr}"
    );
    // The report says so too, and takes the run's own string: then m3's boundary lies on its
    // map.
    let report = |dir: &str, string: &[&str]| {
        let report = out.parent().unwrap().join(dir);
        let mut args = vec!["report", out_s, "--out", report.to_str().unwrap()];
        args.extend_from_slice(string);
        let (code, _, stderr) = run(&args);
        assert_eq!(code, 0, "{stderr}");
        std::fs::read_to_string(report.join("report.md")).unwrap()
    };
    let paper = report("paper", &paper_string);
    assert!(
        paper.contains("> **Off the map:** law m3's MAP boundary lies above"),
        "{paper}"
    );
    assert!(
        paper.contains("Some boundaries lie wholly off this map and are not drawn"),
        "{paper}"
    );
    let rig = report("rig", &[]);
    assert!(rig.contains("| 1-DOF (ω_n = 5 rad/s, ξ = 0.1) | -0.02 |"), "{rig}");
    assert!(!rig.contains("law m3's MAP boundary lies"), "{rig}");
}

/// An evidence given the rig's string keeps it: its advice is drawn on it and said to be, and
/// its map is the rig's without naming the string again.
#[test]
fn the_evidence_keeps_its_drill_string_for_its_advice_and_maps() {
    let path = rig_record().to_str().unwrap();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("evidence");
    let out_s = out.to_str().unwrap();
    let mut args = vec![
        "evidence",
        path,
        "--laws",
        "m2,m3",
        "--particles",
        "100",
        "--islands",
        "2",
        "--noise",
        "iid",
        "--check",
        "0",
        "--backend",
        "cpu",
        "--out",
        out_s,
        "-q",
    ];
    args.extend_from_slice(&RIG_STRING);
    let (code, stdout, stderr) = run(&args);
    assert_eq!(code, 0, "{stderr}");
    assert!(
        stdout.contains(
            "advice at the record's operating point (1-DOF string I_eq = 0.02 kg·m², ω_n = 5 rad/s, ξ = 0.1): "
        ),
        "{stdout}"
    );
    // At the rig's own weight on bit (about 500 N), in the digits it needs.
    assert!(
        stdout.contains("stick-slip now at 99 rpm and 0.52 kN (bit stuck "),
        "{stdout}"
    );
    let job = json(&std::fs::read_to_string(out.join("job.json")).unwrap());
    assert_eq!(job["job"]["string"]["lumped"]["inertia_kg_m2"], 0.02, "{job}");
    let (code, stdout, stderr) = run(&[
        "stability",
        "--run",
        out_s,
        "--backend",
        "cpu",
        "--samples",
        "20",
        "--json",
    ]);
    assert_eq!(code, 0, "{stderr}");
    assert!(
        stderr.contains("note: the run's own drill string: 1-DOF string I_eq = 0.02 kg·m²"),
        "{stderr}"
    );
    let critical = json(&stdout)["critical_bit_damping_nms"].as_f64().unwrap();
    assert!((critical + 0.02).abs() < 1e-12, "{critical}");
    // A resumed evidence keeps its own string: a string given with --resume is refused.
    let (code, _, stderr) = run(&["evidence", "--resume", out_s, "--damping-ratio", "0.2"]);
    assert_eq!(code, 2, "{stderr}");
    assert!(stderr.contains("--damping-ratio"), "{stderr}");
}

/// A time column in milliseconds: read as such where its name says so (its time window set in
/// seconds as always), and hinted at where a name without a unit steps by tens of "seconds".
#[test]
fn a_time_column_in_milliseconds_is_read_by_its_name_and_hinted_at_without_one() {
    use bitrock::data::{DataOptions, parse_field_data};
    let rows: String = (0..400)
        .map(|k| {
            let w = 40.0 + 40.0 * (k as f64 * 0.05).sin().abs();
            format!("{},{w},{}\n", 50 * k, 8.0 + 4.0 / (1.0 + w / 20.0))
        })
        .collect();
    let path = std::path::Path::new("logger.csv");
    let within = DataOptions {
        t_start_s: Some(5.0),
        t_end_s: Some(10.0),
        ..DataOptions::default()
    };
    let named = format!("time_ms,bit_speed_rpm,torque_knm\n{rows}");
    let data = parse_field_data(named.as_bytes(), path, &within).unwrap();
    // Rows at 5.00, 5.05, …, 10.00 s: 101 of them, stamped 5000 … 10000 ms.
    assert_eq!(data.rows_used, 101);
    let times = data.calibration.time_s.iter().chain(&data.validation.time_s).flatten();
    assert!(
        times.clone().all(|t| (5.0..=10.0).contains(t)),
        "{:?}",
        times.collect::<Vec<_>>()
    );
    assert!(
        data.warnings.iter().all(|w| !w.contains("milliseconds")),
        "{:?}",
        data.warnings
    );
    let unnamed = format!("time,bit_speed_rpm,torque_knm\n{rows}");
    let data = parse_field_data(unnamed.as_bytes(), path, &DataOptions::default()).unwrap();
    assert!(
        data.warnings
            .iter()
            .any(|w| w.contains("step by 50 s") && w.contains("name it 'time_ms'")),
        "{:?}",
        data.warnings
    );
}

/// A rig's export of the embedded record: ISO 8601 stamps with a zone, epoch milliseconds,
/// mnemonics for names, imperial units, units in brackets. Each reads as the same record in
/// SI, its times counted from midnight UTC of its first day (13:30 UTC = 48,600 s).
#[test]
fn rig_exports_with_stamps_mnemonics_and_imperial_units_read_as_the_record_in_si() {
    use bitrock::data::{DEMO_CSV, DataOptions, parse_field_data};
    use bitrock::units::{ForceUnit, TorqueUnit};
    let rows = demo_rows();
    let lbf = ForceUnit::Lbf.newtons();
    let kftlbf = TorqueUnit::KFtLbf.newton_metres();
    let stamped = std::iter::once("TIME,RPM_DH,TQ_kNm,WOB [klbf]".to_string())
        .chain(
            rows.iter()
                .map(|r| format!("{},{},{},{:e}", stamp(r[0], "", "+01:00"), r[1], r[2], r[3] / lbf)),
        )
        .collect::<Vec<_>>()
        .join("\n");
    let epoch = std::iter::once("TIME,DH RPM (rpm),TOB (kft.lbf),DWOB [lbf]".to_string())
        .chain(rows.iter().map(|r| {
            let ms = 1_795_959_000_000 + (r[0] * 1000.0).round() as u64;
            format!("{ms},{},{:e},{:e}", r[1], r[2] * 1e3 / kftlbf, r[3] * 1e3 / lbf)
        }))
        .collect::<Vec<_>>()
        .join("\n");
    let path = std::path::Path::new("rig.csv");
    let si = parse_field_data(DEMO_CSV.as_bytes(), path, &DataOptions::default()).unwrap();
    for text in [&stamped, &epoch] {
        let data = parse_field_data(text.as_bytes(), path, &DataOptions::default()).unwrap();
        assert_reads_as(&data, &si, 48_600.0);
        assert!(
            data.clock_note().unwrap().contains("2026-11-29 00:00 UTC"),
            "{:?}",
            data.clock_note()
        );
        // The time window in those seconds.
        let window = DataOptions {
            t_start_s: Some(48_610.0),
            t_end_s: Some(48_620.0),
            ..DataOptions::default()
        };
        let part = parse_field_data(text.as_bytes(), path, &window).unwrap();
        let si_window = DataOptions {
            t_start_s: Some(10.0),
            t_end_s: Some(20.0),
            ..DataOptions::default()
        };
        assert_eq!(
            part.rows_used,
            parse_field_data(DEMO_CSV.as_bytes(), path, &si_window)
                .unwrap()
                .rows_used
        );
    }
    // The bare `TQ` is said (rig logs name surface torque so); `TOB` is not.
    let said = |text: &str| {
        parse_field_data(text.as_bytes(), path, &DataOptions::default())
            .unwrap()
            .warnings
    };
    assert!(
        said(&stamped)
            .iter()
            .any(|w| w.contains("'TQ_kNm' is read as the bit's torque"))
    );
    assert!(
        said(&epoch).iter().all(|w| !w.contains("is read as the bit's")),
        "{:?}",
        said(&epoch)
    );

    // A stamp that is no time is refused naming its line and column, exit 2, by the command.
    let mut bad = stamped.lines().take(50).collect::<Vec<_>>().join("\n");
    bad.push_str("\n2026-11-29T25:00:00Z,60,7,54\n");
    let file = tempfile::Builder::new().suffix(".csv").tempfile().unwrap();
    std::fs::write(file.path(), bad).unwrap();
    let (code, _, err) = run(&["fit", file.path().to_str().unwrap()]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains(":51:1: column 'TIME'") && err.contains("ISO 8601"),
        "{err}"
    );
}

/// The embedded record's rows: time (s), bit speed (rpm), torque (kN·m), WOB (kN).
fn demo_rows() -> Vec<Vec<f64>> {
    bitrock::data::DEMO_CSV
        .lines()
        .skip(1)
        .map(|line| line.split(',').map(|v| v.parse().unwrap()).collect())
        .collect()
}

/// A demo row's time `t` as an ISO 8601 stamp: 14:30 on 2026-11-29 in `zone` plus `t`, its
/// hundredths of a second (the demo's stamps are whole ones) followed by `pad` (`"00000"`: the
/// seven decimals servers write).
fn stamp(t: f64, pad: &str, zone: &str) -> String {
    let cs = (t * 100.0).round() as u64;
    format!(
        "2026-11-29T14:{:02}:{:02}.{:02}{pad}{zone}",
        30 + cs / 6000,
        (cs / 100) % 60,
        cs % 100
    )
}

/// `data` holds the samples of `si` (the embedded record in SI): the same rows used, speeds bit
/// for bit, torques and weights within 1e-12 relative (through other units and back), times
/// later by `shift_s` within 1e-9 s (a wall clock counted from its midnight UTC).
fn assert_reads_as(data: &bitrock::data::FieldData, si: &bitrock::data::FieldData, shift_s: f64) {
    assert_eq!(data.rows_used, si.rows_used);
    let close = |a: &[f64], b: &[f64], tol: f64| a.iter().zip(b).all(|(x, y)| (x - y).abs() <= tol * y.abs().max(1.0));
    for (got, want) in [(&data.calibration, &si.calibration), (&data.validation, &si.validation)] {
        assert_eq!(got.speed_rad_s, want.speed_rad_s);
        assert!(close(&got.torque_nm, &want.torque_nm, 1e-12));
        assert!(close(got.wob_n.as_ref().unwrap(), want.wob_n.as_ref().unwrap(), 1e-12));
        let shifted: Vec<f64> = want.time_s.as_ref().unwrap().iter().map(|t| t + shift_s).collect();
        let times = got.time_s.as_ref().unwrap();
        assert!(close(times, &shifted, 1e-9), "{:?}", &times[..3]);
    }
}

/// The embedded record as a WITSML 1.4.1.1 time log written the way servers write them: a
/// default namespace and unused prefixes, curve infos in another order than the data's
/// mnemonics, surface channels beside the bit's, the index's unit left empty, a log-level null
/// value and an empty trailing value, torque in kft·lbf and weight in klbf.
fn witsml_141(rows: &[Vec<f64>]) -> String {
    let kftlbf = bitrock::units::TorqueUnit::KFtLbf.newton_metres();
    let klbf = bitrock::units::ForceUnit::KLbf.newtons();
    let mut xml = String::from(
        r#"<?xml version="1.0" encoding="utf-8"?>
<logs xmlns="http://www.witsml.org/schemas/1series" xmlns:gml="http://www.opengis.net/gml/3.2" xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance" version="1.4.1.1">
  <log uidWell="W-1" uidWellbore="B-1" uid="L-1">
    <nameWell>Well 1</nameWell>
    <nameWellbore>Wellbore 1</nameWellbore>
    <name>Downhole 50 Hz</name>
    <objectGrowing>false</objectGrowing>
    <indexType>date time</indexType>
    <direction>increasing</direction>
    <indexCurve>RIGTIME</indexCurve>
    <nullValue>-999.25</nullValue>
    <logCurveInfo uid="TOB"><mnemonic>TOB</mnemonic><unit>kft.lbf</unit><typeLogData>double</typeLogData></logCurveInfo>
    <logCurveInfo uid="RIGTIME"><mnemonic>RIGTIME</mnemonic><unit>s</unit><typeLogData>date time</typeLogData></logCurveInfo>
    <logCurveInfo uid="DRPM"><mnemonic>DRPM</mnemonic><unit>rpm</unit><typeLogData>double</typeLogData></logCurveInfo>
    <logCurveInfo uid="DWOB"><mnemonic>DWOB</mnemonic><unit>klbf</unit><typeLogData>double</typeLogData></logCurveInfo>
    <logCurveInfo uid="TQA"><mnemonic>TQA</mnemonic><unit>kft.lbf</unit><typeLogData>double</typeLogData></logCurveInfo>
    <logCurveInfo uid="RPMA"><mnemonic>RPMA</mnemonic><unit>rpm</unit><typeLogData>double</typeLogData></logCurveInfo>
    <logData>
      <mnemonicList>RIGTIME,DRPM,TOB,DWOB,TQA,RPMA</mnemonicList>
      <unitList>,rpm,kft.lbf,klbf,kft.lbf,rpm</unitList>
"#,
    );
    for (k, r) in rows.iter().enumerate() {
        // The surface channels' nulls (-999.25, empty) touch no row the record reads.
        let surface = if k % 7 == 0 {
            "-999.25,".to_string()
        } else {
            format!("{:.3},120", r[2] * 1e3 / kftlbf + 2.0)
        };
        xml.push_str(&format!(
            "      <data>{},{},{:e},{:e},{surface}</data>\n",
            stamp(r[0], "00000", "-05:00"),
            r[1],
            r[2] * 1e3 / kftlbf,
            r[3] * 1e3 / klbf
        ));
    }
    xml.push_str("    </logData>\n  </log>\n</logs>\n");
    xml
}

/// The embedded record as a WITSML 2.0 channel set: prefixed common elements, an index of
/// stamps, a channel with point metadata (`[value, flag]`), JSON rows across lines with a
/// trailing comma, a surface channel with `null`s.
fn witsml_20(rows: &[Vec<f64>]) -> String {
    let mut xml = String::from(
        r#"<?xml version="1.0" encoding="utf-8"?>
<Log xmlns="http://www.energistics.org/energyml/data/witsmlv2" xmlns:eml="http://www.energistics.org/energyml/data/commonv2" schemaVersion="2.0" uuid="0b6b3c1e-0000-4000-8000-000000000001">
  <eml:Citation><eml:Title>Downhole 50 Hz</eml:Title><eml:Originator>rig</eml:Originator></eml:Citation>
  <ChannelSet uuid="0b6b3c1e-0000-4000-8000-000000000002">
    <eml:Citation><eml:Title>Bit</eml:Title></eml:Citation>
    <Index><IndexType>date time</IndexType><Uom>s</Uom><Direction>increasing</Direction><Mnemonic>TIME</Mnemonic></Index>
    <Channel uuid="c1"><Mnemonic>RPM_DH</Mnemonic><DataType>double</DataType><Uom>rpm</Uom></Channel>
    <Channel uuid="c2"><Mnemonic>TOB</Mnemonic><DataType>double</DataType><Uom>kN.m</Uom></Channel>
    <Channel uuid="c3"><Mnemonic>DWOB</Mnemonic><DataType>double</DataType><Uom>kN</Uom></Channel>
    <Channel uuid="c4"><Mnemonic>Surf RPM</Mnemonic><DataType>double</DataType><Uom>rpm</Uom></Channel>
    <Data>
      <Data>[
"#,
    );
    for (k, r) in rows.iter().enumerate() {
        let surface = if k % 5 == 0 {
            "null".to_string()
        } else {
            "120.0".to_string()
        };
        xml.push_str(&format!(
            "        [[\"{}\"], [{}, [{}, true], {}, {surface}]],\n",
            stamp(r[0], "00000", "-05:00"),
            r[1],
            r[2],
            r[3]
        ));
    }
    xml.push_str("      ]</Data>\n    </Data>\n  </ChannelSet>\n</Log>\n");
    xml
}

/// WITSML 1.4.1 and 2.0 time logs read as the record they hold, by the library and by `fit`,
/// their stamps counted from midnight UTC (14:30 at −05:00 = 19:30 UTC = 70,200 s); a null in
/// a channel read leaves its row out and is said; a malformed log is refused naming its line.
#[test]
fn witsml_time_logs_read_as_the_record_they_hold() {
    use bitrock::data::{DEMO_CSV, DataOptions, parse_field_data};
    let rows = demo_rows();
    let path = std::path::Path::new("log.xml");
    let si = parse_field_data(DEMO_CSV.as_bytes(), path, &DataOptions::default()).unwrap();
    for xml in [witsml_141(&rows), witsml_20(&rows)] {
        let data = parse_field_data(xml.as_bytes(), path, &DataOptions::default()).unwrap();
        assert_eq!(data.rows_read, rows.len());
        assert_reads_as(&data, &si, 70_200.0);
        assert!(data.warnings.is_empty(), "{:?}", data.warnings);
        assert!(
            data.clock_note()
                .unwrap()
                .contains("ISO 8601 stamps, s since 2026-11-29 00:00 UTC")
        );
    }

    // A null where the record reads: the row left out and said with its line.
    let mut xml = witsml_141(&rows[..400]);
    xml = xml.replacen(&format!(",{},", rows[10][1]), ",-999.25,", 1);
    let data = parse_field_data(xml.as_bytes(), path, &DataOptions::default()).unwrap();
    assert_eq!(data.rows_read, 399);
    assert!(
        data.warnings[0].contains(
            "1 of 400 rows hold no value in a channel read (RIGTIME, DRPM [rpm], TOB [kft.lbf], DWOB [klbf])"
        ) && data.warnings[0].contains("line 31"),
        "{:?}",
        data.warnings
    );

    // By the command: the same fit as the embedded record's, to the printed digits.
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("log.xml");
    std::fs::write(&file, witsml_20(&rows)).unwrap();
    let (code, out, err) = run(&["fit", file.to_str().unwrap(), "--json"]);
    assert_eq!(code, 0, "{err}");
    let (code, demo, err) = run(&["fit", "--json"]);
    assert_eq!(code, 0, "{err}");
    assert_eq!(best_rho(&json(&out)), best_rho(&json(&demo)));

    // Malformed: a row of the wrong length, XML that does not parse, another root, two logs
    // in one file (the second on line 73: 20 lines of header, 50 rows, the first's end).
    let short = witsml_141(&rows[..50]).replacen("</data>", ",1</data>", 1);
    let bad_xml = witsml_20(&rows[..50]).replacen("</Channel>", "</Chanel>", 1);
    let one = witsml_141(&rows[..50]);
    let log = &one[one.find("  <log ").unwrap()..one.find("</logs>").unwrap()];
    let two = one.replacen("</logs>", &format!("{log}</logs>"), 1);
    for (text, want) in [
        (short, "log.xml:21: a row of 7 values for 6 mnemonics"),
        (two, "log.xml:73: the WITSML <logs> holds 2 <log> elements"),
        (
            bad_xml,
            "log.xml:7: column 92: the XML does not parse: expected 'Channel' tag, not 'Chanel'\n",
        ),
        (
            "<?xml version=\"1.0\"?>\n<well/>".to_string(),
            "log.xml:2: an XML file whose root is <well>",
        ),
    ] {
        std::fs::write(&file, &text).unwrap();
        let (code, _, err) = run(&["fit", file.to_str().unwrap()]);
        assert_eq!(code, 2, "{err}");
        assert!(err.contains(want), "{want}: {err}");
    }
}

/// A rig whose channels no name rule finds: a column map file names them and their units; a
/// flag beside it wins; a unit it names that bitrock does not read, or a key it does not know,
/// is refused naming the file (and the key or line), exit 2.
#[test]
fn a_column_map_file_names_a_rig_s_channels_and_units() {
    let rows = demo_rows();
    let dir = tempfile::tempdir().unwrap();
    let record = dir.path().join("rig.csv");
    let kftlbf = bitrock::units::TorqueUnit::KFtLbf.newton_metres();
    let text: String = std::iter::once("T,CH1,CH2,CH3\n".to_string())
        .chain(
            rows.iter()
                .map(|r| format!("{},{},{:e},{}\n", r[0], r[1], r[2] * 1e3 / kftlbf, r[3])),
        )
        .collect();
    std::fs::write(&record, text).unwrap();
    let map = dir.path().join("rig.toml");
    std::fs::write(
        &map,
        "# the rig's memory tool\nspeed = \"CH1\"\nspeed_unit = \"rpm\"\ntorque = \"CH2\"\ntorque_unit = \"kft.lbf\"\nwob = \"CH3\"\nwob_unit = \"kN\"\ntime = \"T\"\n",
    )
    .unwrap();
    let (code, demo, err) = run(&["fit", "--json"]);
    assert_eq!(code, 0, "{err}");
    let (code, out, err) = run(&[
        "fit",
        record.to_str().unwrap(),
        "--column-map",
        map.to_str().unwrap(),
        "--json",
    ]);
    assert_eq!(code, 0, "{err}");
    // The torque through kft·lbf and back: the same fits to the last digits.
    for ((law, rho), (want_law, want)) in best_rho(&json(&out)).into_iter().zip(best_rho(&json(&demo))) {
        assert_eq!(law, want_law);
        assert!((rho - want).abs() <= 1e-12 * want, "{law}: {rho} vs {want}");
    }
    // A flag wins over the map: the torque read as kN·m is off by the unit's factor.
    let (code, out, err) = run(&[
        "fit",
        record.to_str().unwrap(),
        "--column-map",
        map.to_str().unwrap(),
        "--torque-unit",
        "knm",
        "--json",
    ]);
    assert_eq!(code, 0, "{err}");
    assert_eq!(json(&out)["torque_unit"], "kN·m", "{out}");

    for (text, want) in [
        (
            "speed = \"CH1\"\ntorque_unit = \"daN.m\"\n",
            "rig.toml: torque_unit = \"daN.m\": a unit bitrock does not read",
        ),
        ("speed = \"CH1\"\nrpm = \"CH1\"\n", "rig.toml:2"),
    ] {
        std::fs::write(&map, text).unwrap();
        let (code, _, err) = run(&["fit", record.to_str().unwrap(), "--column-map", map.to_str().unwrap()]);
        assert_eq!(code, 2, "{err}");
        assert!(err.contains(want), "{want}: {err}");
    }
}

/// A parameter whose posterior is still its prior box is marked wherever its estimate is
/// printed: population 0 alone (the prior's draws) leaves every one marked in the table and
/// run.json; the paper's run on the embedded record narrows m2's dynamic torque tcb (1 % to
/// 99 % over 4.3–6.4 kN·m in its box of 3.4–7.8 kN·m) and leaves it unmarked.
#[test]
fn estimates_the_record_leaves_to_the_prior_box_are_marked_in_the_table_and_run_json() {
    let dir = tempfile::tempdir().unwrap();
    let prior_only = dir.path().join("prior");
    let (code, out, err) = run(&[
        "abc",
        "--laws",
        "m2",
        "--max-populations",
        "1",
        "--backend",
        "cpu",
        "--out",
        prior_only.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    assert_eq!(
        out.matches("(not identified: its 98 % interval spans most of its prior box)")
            .count(),
        3,
        "{out}"
    );
    let doc: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(prior_only.join("run.json")).unwrap()).unwrap();
    assert_eq!(
        doc["posterior"]["laws"][0]["identified"],
        serde_json::json!([false, false, false])
    );

    let paper = dir.path().join("paper");
    let (code, out, err) = run(&[
        "abc",
        "--laws",
        "m2",
        "--backend",
        "cpu",
        "--out",
        paper.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    let tcb = out.lines().find(|l| l.trim_start().starts_with("tcb")).unwrap();
    assert!(!tcb.contains("not identified"), "{out}");
    let doc: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(paper.join("run.json")).unwrap()).unwrap();
    assert_eq!(doc["posterior"]["laws"][0]["identified"][1], true);
}
