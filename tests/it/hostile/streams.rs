//! Output streams fail as errors, not panics: a full standard error loses its lines and
//! nothing else (no panic, no hot journal, the documented exit status).

use super::{export, small_run};
use std::fs::File;

/// Runs bitrock in `cwd` with standard error on /dev/full; (status, stdout).
fn with_full_stderr(cwd: &std::path::Path, args: &[&str]) -> (i32, String) {
    let out = crate::support::bin()
        .current_dir(cwd)
        .args(args)
        .stderr(File::create("/dev/full").unwrap())
        .output()
        .unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
    )
}

#[test]
fn a_full_standard_error_never_panics_and_keeps_the_exit_status() {
    let tmp = tempfile::tempdir().unwrap();
    // A run whose progress and notes cannot be written: it runs to the end, whole.
    let args = [
        "abc",
        "--out",
        "F",
        "--thin",
        "4",
        "--particles",
        "200",
        "--max-populations",
        "2",
        "--backend",
        "cpu",
    ];
    let (code, _) = with_full_stderr(tmp.path(), &args);
    assert_eq!(code, 0);
    assert!(
        !tmp.path().join("F/run.sqlite-journal").exists(),
        "a hot journal was left"
    );
    assert_eq!(small_run(tmp.path(), "G", &[]).0, 0);
    assert_eq!(export(tmp.path(), "F"), export(tmp.path(), "G"));
    // Bad input still exits 2, the failure 3, with their message lost.
    assert_eq!(with_full_stderr(tmp.path(), &["fit", "missing.csv"]).0, 2);
    assert_eq!(with_full_stderr(tmp.path(), &["export", "missing-run"]).0, 2);
    let (code, _) = with_full_stderr(
        tmp.path(),
        &["abc", "--resume", "F", "--max-populations", "3", "--backend", "gpu"],
    );
    assert!(code == 0 || code == 3, "exit {code}");
}

#[test]
fn help_and_version_that_cannot_be_written_fail_naming_standard_output() {
    for args in [&["--help"][..], &["--version"], &["abc", "--help"]] {
        let out = crate::support::bin()
            .args(args)
            .stdout(std::fs::File::create("/dev/full").unwrap())
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(3), "{args:?}: {err}");
        assert!(err.contains("standard output: cannot write"), "{err}");
    }
    // Written, they exit 0; a usage error still exits 2.
    let (code, _, _) = crate::support::outcome(crate::support::bin().arg("--version"));
    assert_eq!(code, 0);
    let (code, _, err) = crate::support::outcome(crate::support::bin().arg("--no-such-flag"));
    assert_eq!(code, 2, "{err}");
}
