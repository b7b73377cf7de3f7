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
    let warnings = warnings_of(&tmp.path().join("R"));
    assert_eq!(warnings.len(), 1, "{warnings:?}");
    assert!(warnings[0].contains("runs backwards"));
    // A record in time order and of positive torque warns of nothing.
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
    assert!(!err.contains("warning"), "{err}");
    assert!(warnings_of(&tmp.path().join("Q")).is_empty());
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
