//! Degenerate results warn, once, in the output and in the run's record: a time column that
//! runs backwards, torques of the wrong sign, a record every law fits exactly, and populations
//! of a tiny effective sample size.

use super::{record, run_in};

fn warnings_of(dir: &std::path::Path) -> Vec<String> {
    let run: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.join("run.json")).unwrap()).unwrap();
    run["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .map(|w| w.as_str().unwrap().to_string())
        .collect()
}

#[test]
fn a_backwards_time_column_and_negative_torques_are_warned_once_and_recorded() {
    let tmp = tempfile::tempdir().unwrap();
    // The embedded record's columns: time_s, bit_speed_rpm, torque_knm, wob_kn. Time mirrored
    // (it runs backwards from the second row on) and torque negated.
    record(&tmp.path().join("odd.csv"), |v| vec![1e4 - v[0], v[1], -v[2], v[3]]);
    let (code, _, err) = run_in(tmp.path(), &["fit", "odd.csv", "--no-bounds"]);
    assert_eq!(code, 0, "{err}");
    assert_eq!(err.matches("runs backwards").count(), 1, "{err}");
    assert!(err.contains("odd.csv:3:"), "the first backwards row is named: {err}");
    assert_eq!(err.matches("torques used are negative").count(), 1, "{err}");
    // An ABC run says each once and keeps them in run.json.
    record(&tmp.path().join("back.csv"), |v| vec![1e4 - v[0], v[1], v[2], v[3]]);
    let (code, _, err) = run_in(
        tmp.path(),
        &[
            "abc",
            "back.csv",
            "--out",
            "R",
            "--particles",
            "200",
            "--max-populations",
            "2",
            "--backend",
            "cpu",
        ],
    );
    assert_eq!(code, 0, "{err}");
    assert_eq!(err.matches("runs backwards").count(), 1, "{err}");
    // Beside the record's warning, the run's own statement that at this ε its probabilities
    // are prior-volume ratios, once.
    let warnings = warnings_of(&tmp.path().join("R"));
    assert_eq!(warnings.len(), 2, "{warnings:?}");
    assert!(warnings[0].contains("runs backwards"));
    assert!(
        warnings[1].contains("ratios of the laws' prior volumes"),
        "{warnings:?}"
    );
    // A record in time order and of positive torque warns of nothing about the record.
    let (code, _, err) = run_in(
        tmp.path(),
        &[
            "abc",
            "--out",
            "Q",
            "--particles",
            "200",
            "--max-populations",
            "2",
            "--backend",
            "cpu",
        ],
    );
    assert_eq!(code, 0, "{err}");
    assert_eq!(err.matches("warning").count(), 1, "{err}");
    let warnings = warnings_of(&tmp.path().join("Q"));
    assert_eq!(warnings.len(), 1, "{warnings:?}");
    assert!(
        warnings[0].contains("ratios of the laws' prior volumes"),
        "{warnings:?}"
    );
}

#[test]
fn a_record_every_law_fits_exactly_is_warned_of() {
    let tmp = tempfile::tempdir().unwrap();
    // Constant torque at varying speed: m2 (tsb = tcb), m4 (c0) and the others fit it exactly.
    record(&tmp.path().join("flat.csv"), |v| vec![v[0], v[1], 10.0, v[3]]);
    let (code, _, err) = run_in(
        tmp.path(),
        &[
            "abc",
            "flat.csv",
            "--out",
            "R",
            "--particles",
            "200",
            "--max-populations",
            "2",
            "--backend",
            "cpu",
            "--laws",
            "m2,m4",
        ],
    );
    assert_eq!(code, 0, "{err}");
    assert_eq!(err.matches("fits the record exactly").count(), 1, "{err}");
    assert!(
        warnings_of(&tmp.path().join("R"))
            .iter()
            .any(|w| w.contains("fits the record exactly"))
    );
}

#[test]
fn probabilities_from_a_few_particles_and_collapsed_laws_are_warned_of() {
    let tmp = tempfile::tempdir().unwrap();
    let (code, _, err) = run_in(
        tmp.path(),
        &[
            "abc",
            "--out",
            "One",
            "--particles",
            "1",
            "--max-populations",
            "2",
            "--backend",
            "cpu",
            "-q",
        ],
    );
    assert_eq!(code, 0, "{err}");
    assert_eq!(err.matches("the last population has 1 particle(s)").count(), 1, "{err}");
    assert!(
        warnings_of(&tmp.path().join("One"))
            .iter()
            .any(|w| w.contains("1 particle(s)"))
    );
    // An SMC kernel far narrower than the posterior: a law's weight collapses onto a point.
    let (code, _, err) = run_in(
        tmp.path(),
        &[
            "abc",
            "--out",
            "Narrow",
            "--particles",
            "300",
            "--sampler",
            "smc",
            "--perturbation",
            "global",
            "--kernel-scale",
            "1e-30",
            "--backend",
            "cpu",
            "-q",
        ],
    );
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("law m4: effective sample size 1.0 of its"), "{err}");
    // The default kernel, and the paper's sampler, do not collapse.
    let (code, _, err) = run_in(
        tmp.path(),
        &[
            "abc",
            "--out",
            "Smc",
            "--particles",
            "300",
            "--sampler",
            "smc",
            "--backend",
            "cpu",
            "-q",
        ],
    );
    assert_eq!(code, 0, "{err}");
    assert!(!err.contains("effective sample size"), "{err}");
    let (code, _, err) = run_in(
        tmp.path(),
        &[
            "abc",
            "--out",
            "Wide",
            "--particles",
            "300",
            "--max-populations",
            "2",
            "--backend",
            "cpu",
            "-q",
        ],
    );
    assert_eq!(code, 0, "{err}");
    assert!(
        !err.contains("collapsed") && !err.contains("particle(s)") && !err.contains("effective"),
        "{err}"
    );
}

#[test]
fn a_map_where_the_torque_has_no_value_is_unknown_never_stable() {
    let tmp = tempfile::tempdir().unwrap();
    // ln(g·w − 1) has no value below w = 1/g = 5 rad/s (47.7 rpm).
    std::fs::write(
        tmp.path().join("nolog.toml"),
        "name = \"nolog\"\ntorque = \"r * tc * (1 + 0.1 * ln(g * w - 1))\"\n\n[[parameter]]\nname = \"tc\"\nunit = \"N·m\"\nlower = 0\n\n\
         [[parameter]]\nname = \"g\"\nunit = \"s/rad\"\nlower = 0\n",
    )
    .unwrap();
    let args = [
        "stability",
        "--law-file",
        "nolog.toml",
        "--law",
        "nolog",
        "--params",
        "6.5,0.2",
        "--omega-rpm",
        "20:200:10",
        "--wob-kn",
        "50:300:5",
        "--backend",
        "cpu",
    ];
    let (code, out, err) = run_in(tmp.path(), &[&args[..], &["-o", "map.csv", "--json"]].concat());
    assert_eq!(code, 0, "{err}");
    assert_eq!(
        err.matches("its torque has no value at 2 of the 10 speeds").count(),
        1,
        "{err}"
    );
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(
        v["boundaries"]["nolog"]["unknown_omega_rpm"],
        serde_json::json!([20.0, 40.0])
    );
    // Every cell of an unknown speed is unknown (null), none of them stable (0).
    let grid = v["probability_unstable"]["nolog"].as_array().unwrap();
    assert!(grid[0].as_array().unwrap().iter().all(|c| c.is_null()), "{}", grid[0]);
    assert!(grid[2].as_array().unwrap().iter().all(|c| c.is_number()), "{}", grid[2]);
    let csv = std::fs::read_to_string(tmp.path().join("map.csv")).unwrap();
    assert!(csv.lines().nth(1).unwrap().ends_with(",unknown,unknown"), "{csv}");
    let (_, table, _) = run_in(tmp.path(), &args);
    assert_eq!(table.matches("unknown").count(), 4, "{table}");
}

#[test]
fn units_off_by_a_factor_and_flipped_speeds_are_warned_of_naming_the_column() {
    let tmp = tempfile::tempdir().unwrap();
    // The embedded record's columns: time_s, bit_speed_rpm, torque_knm, wob_kn.
    /// A record's file, how each row is changed, and the words of the warning it raises.
    type Case = (&'static str, fn(&[f64]) -> Vec<f64>, &'static str);
    let cases: [Case; 4] = [
        (
            "nm.csv",
            |v| vec![v[0], v[1], v[2] * 1000.0, v[3]],
            "column 'torque_knm' read in kN·m",
        ),
        (
            "rad.csv",
            |v| vec![v[0], v[1] * 0.104_719_755, v[2], v[3]],
            "column 'bit_speed_rpm' read in rpm",
        ),
        (
            "n.csv",
            |v| vec![v[0], v[1], v[2], v[3] * 1000.0],
            "column 'wob_kn' read in kN",
        ),
        (
            "flip.csv",
            |v| vec![v[0], -v[1], v[2], v[3]],
            "bit speeds of column 'bit_speed_rpm' are negative",
        ),
    ];
    for (name, transform, words) in cases {
        record(&tmp.path().join(name), transform);
        let (code, _, err) = run_in(tmp.path(), &["fit", name, "--laws", "m2"]);
        assert_eq!(code, 0, "{err}");
        assert_eq!(err.matches(words).count(), 1, "{name}: {err}");
        assert_eq!(
            err.matches("warning: ").count() - err.matches("    warning: ").count(),
            1,
            "{name}: {err}"
        );
    }
    // The embedded record, in its stated units, raises none.
    record(&tmp.path().join("same.csv"), |v| v.to_vec());
    let (_, _, err) = run_in(tmp.path(), &["fit", "same.csv", "--laws", "m2"]);
    assert!(!err.contains("warning"), "{err}");
}
