//! Every number a command takes is checked where it enters (NaN, infinities, signs, the order
//! of a schedule), the same rule on every command; a schedule the user gave is run as given or
//! refused.

use super::{assert_refused, run_in, run_of, small_run};

#[test]
fn nan_and_infinities_are_refused_by_every_command_naming_the_flag() {
    let tmp = tempfile::tempdir().unwrap();
    let cases: [&[&str]; 8] = [
        &["stability", "--law", "m2", "--params", "13,NaN,0.3"],
        &[
            "stability",
            "--law",
            "m2",
            "--params",
            "13,6.5,0.3",
            "--percentile",
            "nan",
        ],
        &["simulate", "--law", "m2", "--omega-rpm", "60", "--params", "13,inf,0.3"],
        &["simulate", "--law", "m2", "--omega-rpm=-inf"],
        &["fit", "--min-speed-rpm", "NaN"],
        &["abc", "--out", "R", "--delta", "inf"],
        &["abc", "--out", "R", "--epsilons", "0.05,NaN"],
        &["parity", "--epsilon", "nan"],
    ];
    for args in cases {
        let (code, _, err) = run_in(tmp.path(), args);
        assert_eq!(code, 2, "{args:?}: {err}");
        assert!(err.contains("not a finite number"), "{args:?}: {err}");
    }
    assert!(!tmp.path().join("R").exists());
    // Finite values out of range are refused by the same commands, naming the flag.
    assert_refused(
        run_in(tmp.path(), &["stability", "--law", "m2", "--params", "13,-6.5,0.3"]),
        &["--params", "tcb", "physical bound"],
    );
}

#[test]
fn a_schedule_is_run_as_given_or_refused() {
    let tmp = tempfile::tempdir().unwrap();
    // Without --eps-min the schedule ends the run: every tolerance is used, none replaced.
    let (code, out, err) = run_of(tmp.path(), "S", "5", &["--epsilons", "0.05,0.02,0.01,0.008", "--json"]);
    assert_eq!(code, 0, "{err}");
    // No floor is in play, so none is said to be out of reach.
    let (code, _, err) = run_in(
        tmp.path(),
        &[
            "abc",
            "--out",
            "N",
            "--particles",
            "200",
            "--backend",
            "cpu",
            "--epsilons",
            "0.05,0.03",
        ],
    );
    assert_eq!(code, 0, "{err}");
    assert!(
        err.contains("population  2: ε = 0.03000") && !err.contains("eps-min"),
        "{err}"
    );
    let run: serde_json::Value = serde_json::from_str(&out).unwrap();
    let epsilons: Vec<f64> = run["populations"]
        .as_array()
        .unwrap()
        .iter()
        .skip(1)
        .map(|p| p["epsilon"].as_f64().unwrap())
        .collect();
    assert_eq!(epsilons, [0.05, 0.02, 0.01, 0.008]);
    assert_eq!(run["stop_reason"], "schedule_exhausted");
    assert_eq!(run["stop_description"], "the --epsilons schedule ran out");
    // A schedule that --eps-min or --max-populations would cut is refused, not cut.
    assert_refused(
        small_run(tmp.path(), "T", &["--epsilons", "0.05,0.01,0.008", "--eps-min", "0.01"]),
        &["--epsilons", "0.008", "below --eps-min 0.01"],
    );
    assert_refused(
        small_run(tmp.path(), "T", &["--epsilons", "0.05,0.02,0.01"]),
        &["--max-populations", "3 tolerances"],
    );
    assert!(!tmp.path().join("T").exists());
}
