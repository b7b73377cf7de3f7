//! A run's stored facts describe what was run: a resume that adds nothing changes nothing on
//! disk; a selection check records the run it describes and the report marks it once the run
//! moved on; an interrupted or budget-stopped run is said to be so; a store edited by hand is
//! refused on resume.

use super::{assert_refused, export, run_in, run_of};
use rusqlite::Connection;
use std::collections::BTreeMap;
use std::path::Path;

/// Every file under `dir` with its bytes (bitrock's lock aside, whose content is a PID).
fn snapshot(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    let mut out = BTreeMap::new();
    for entry in std::fs::read_dir(dir).unwrap() {
        let entry = entry.unwrap();
        let name = entry.file_name().to_string_lossy().into_owned();
        if entry.file_type().unwrap().is_file() && name != ".bitrock-lock" {
            out.insert(name, std::fs::read(entry.path()).unwrap());
        }
    }
    out
}

#[test]
fn a_resume_that_adds_no_population_changes_nothing_on_disk() {
    let tmp = tempfile::tempdir().unwrap();
    assert_eq!(run_of(tmp.path(), "B", "3", &[]).0, 0);
    let before = snapshot(&tmp.path().join("B"));
    assert!(before.contains_key("run.json") && before.contains_key("run.sqlite"));
    let (code, out, err) = run_in(
        tmp.path(),
        &["abc", "--resume", "B", "--max-populations", "2", "--json"],
    );
    assert_eq!(code, 0, "{err}");
    assert!(
        err.contains("no population added") && err.contains("is unchanged"),
        "{err}"
    );
    assert_eq!(
        snapshot(&tmp.path().join("B")),
        before,
        "a resume that added nothing rewrote files"
    );
    // What it prints describes the stored run, not the flags of this invocation.
    let printed: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(
        printed["config"]["sampler"]["max_populations"], 3,
        "{}",
        printed["config"]
    );
}

#[test]
fn a_selection_check_records_its_run_and_the_report_marks_it_once_the_run_moved_on() {
    let tmp = tempfile::tempdir().unwrap();
    assert_eq!(run_of(tmp.path(), "R", "2", &[]).0, 0);
    let (code, _, err) = run_in(
        tmp.path(),
        &["check-selection", "R", "--replicates", "1", "--backend", "cpu", "-q"],
    );
    assert_eq!(code, 0, "{err}");
    let check: serde_json::Value =
        serde_json::from_slice(&std::fs::read(tmp.path().join("R/selection/selection.json")).unwrap()).unwrap();
    assert_eq!(check["describes"]["populations"], 2, "{}", check["describes"]);
    let (code, _, err) = run_in(tmp.path(), &["report", "R", "--out", "Rep1"]);
    assert_eq!(code, 0, "{err}");
    let md = std::fs::read_to_string(tmp.path().join("Rep1/report.md")).unwrap();
    assert!(
        md.contains("Can the selection be trusted?") && !md.contains("**Stale:**"),
        "{md}"
    );
    // The run moves on: the check no longer describes it, and the report says so.
    let (code, _, err) = run_in(tmp.path(), &["abc", "--resume", "R", "--max-populations", "3", "-q"]);
    assert_eq!(code, 0, "{err}");
    let (code, _, err) = run_in(tmp.path(), &["report", "R", "--out", "Rep2"]);
    assert_eq!(code, 0, "{err}");
    let md = std::fs::read_to_string(tmp.path().join("Rep2/report.md")).unwrap();
    assert!(
        md.contains("**Stale:** this check describes the run at 2 populations") && md.contains("the run has 3 now"),
        "{md}"
    );
}

#[test]
fn a_run_stopped_on_its_budget_or_interrupted_is_said_so_in_what_is_made_from_it() {
    let tmp = tempfile::tempdir().unwrap();
    // A draw budget that ends the run inside its second population.
    let (code, _, err) = run_of(tmp.path(), "R", "4", &["--max-draws", "700"]);
    assert_eq!(code, 0, "{err}");
    let run: serde_json::Value =
        serde_json::from_slice(&std::fs::read(tmp.path().join("R/run.json")).unwrap()).unwrap();
    assert_eq!(run["stop_reason"], "max_draws", "{}", run["stop_reason"]);
    let (code, _, err) = run_in(tmp.path(), &["report", "R", "--out", "Rep"]);
    assert_eq!(code, 0, "{err}");
    let md = std::fs::read_to_string(tmp.path().join("Rep/report.md")).unwrap();
    assert!(md.contains("the run stopped early: `max_draws`"), "{md}");
    let stability = [
        "stability",
        "--run",
        "R",
        "--omega-rpm",
        "20:220:3",
        "--wob-kn",
        "20:700:3",
        "--backend",
        "cpu",
    ];
    let (code, _, err) = run_in(tmp.path(), &stability);
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("the run stopped early"), "{err}");
    // An invocation that never finished (the process was killed) reads as interrupted.
    let db = Connection::open(tmp.path().join("R/run.sqlite")).unwrap();
    db.execute("UPDATE invocations SET stop_reason = NULL, finished_unix_s = NULL", [])
        .unwrap();
    drop(db);
    let (code, _, err) = run_in(tmp.path(), &stability);
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("the run was interrupted"), "{err}");
}

#[test]
fn a_store_edited_by_hand_is_refused_on_resume_naming_the_population() {
    let edits = [
        (
            "UPDATE particle_rows SET rho = 5.0 WHERE rowid = (SELECT MAX(rowid) FROM particle_rows)",
            "not below its ε",
        ),
        (
            "UPDATE populations SET record_json = json_set(record_json, '$.epsilon', 10.0) WHERE population = 2",
            "not below the previous population",
        ),
        (
            "UPDATE populations SET record_json = json_set(record_json, '$.accepted', 150) WHERE population = 0",
            "particles where the run draws 200",
        ),
    ];
    for (sql, needle) in edits {
        let tmp = tempfile::tempdir().unwrap();
        assert_eq!(run_of(tmp.path(), "R", "3", &[]).0, 0);
        let db = Connection::open(tmp.path().join("R/run.sqlite")).unwrap();
        let changed = db.execute(sql, []).unwrap_or_else(|e| panic!("{sql}: {e}"));
        assert!(changed > 0, "{sql} changed nothing");
        drop(db);
        let before = export(tmp.path(), "R");
        assert_refused(
            run_in(tmp.path(), &["abc", "--resume", "R", "--max-populations", "4", "-q"]),
            &["run.sqlite", "population", needle, "altered"],
        );
        assert_eq!(export(tmp.path(), "R"), before);
    }
}

#[test]
fn a_run_another_process_is_writing_is_named_as_such_not_as_interrupted() {
    let tmp = tempfile::tempdir().unwrap();
    assert_eq!(run_of(tmp.path(), "R", "2", &[]).0, 0);
    // Its last invocation has not finished, and another process holds the run's lock.
    let db = Connection::open(tmp.path().join("R/run.sqlite")).unwrap();
    db.execute("UPDATE invocations SET stop_reason = NULL, finished_unix_s = NULL", [])
        .unwrap();
    drop(db);
    std::fs::write(tmp.path().join("R/.bitrock-lock"), "4242").unwrap();
    // `-o`: the lock is held by flock itself, not by the sleep it runs, so killing it frees it.
    let mut holder = std::process::Command::new("flock")
        .arg("-o")
        .arg(tmp.path().join("R/.bitrock-lock"))
        .args(["sleep", "60"])
        .spawn()
        .expect("flock(1) from util-linux");
    const STABILITY: [&str; 9] = [
        "stability",
        "--run",
        "R",
        "--omega-rpm",
        "20:220:3",
        "--wob-kn",
        "20:700:3",
        "--backend",
        "cpu",
    ];
    while bitrock::files::DirLock::is_free(&tmp.path().join("R")) {
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
    let (code, _, err) = run_in(tmp.path(), &STABILITY);
    let (report_code, _, report_err) = run_in(tmp.path(), &["report", "R", "--out", "Rep"]);
    holder.kill().unwrap();
    holder.wait().unwrap();
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("being written by another process (PID 4242)"), "{err}");
    assert!(!err.contains("interrupted"), "{err}");
    assert_eq!(report_code, 0, "{report_err}");
    let md = std::fs::read_to_string(tmp.path().join("Rep/report.md")).unwrap();
    assert!(md.contains("being written by another process"), "{md}");
    // Once the writer is gone, the unfinished invocation is an interruption again.
    let (_, _, err) = run_in(tmp.path(), &STABILITY);
    assert!(err.contains("the run was interrupted"), "{err}");
}
