//! Only bitrock's own files are ever replaced, by every command that writes: one rule for
//! output files (never a lock, a temporary or a file inside a run; a file bitrock did not write,
//! or changed since it wrote it, only with `--force`; a symbolic link is written through) and one
//! for replacing a directory (anything bitrock did not write refuses it).

use super::{assert_refused, export, names, run_in, small_run};
use std::path::Path;

/// A small demo into `cwd/D`, without the evidence's check (the demo's own test has it), on the
/// backend a user gets.
fn demo(cwd: &Path) -> (i32, String, String) {
    run_in(cwd, &["demo", "--out", "D", "--particles", "200", "--check", "0"])
}

#[test]
fn demo_never_deletes_what_the_user_put_in_its_directory() {
    let tmp = tempfile::tempdir().unwrap();
    let (code, out, err) = demo(tmp.path());
    assert_eq!(code, 0, "{err}");
    // Without its check, the headline's answer is the evidence's alone.
    let answer = out
        .split("== bitrock demo: headline ==\n")
        .nth(1)
        .unwrap()
        .lines()
        .next()
        .unwrap();
    assert!(
        answer.starts_with("answer: m3 over ") && !answer.contains("check"),
        "{answer}"
    );
    let d = tmp.path().join("D");
    let report_before = std::fs::read(d.join("report/report.md")).unwrap();
    // Each of the user's files, wherever in the demo's tree, refuses the next demo before any
    // work, is named, and stays.
    for (rel, is_dir) in [
        ("notes.txt", false),
        ("mine", true),
        ("report/my-notes.md", false),
        ("report/figures/sketch.txt", false),
        ("delta-0.4/thesis.tex", false),
        ("delta-0.6/selection/mine.csv", false),
    ] {
        let path = d.join(rel);
        if is_dir {
            std::fs::create_dir(&path).unwrap();
        } else {
            std::fs::create_dir_all(path.parent().unwrap()).unwrap();
            std::fs::write(&path, "mine").unwrap();
        }
        let name = Path::new(rel).file_name().unwrap().to_str().unwrap();
        assert_refused(demo(tmp.path()), &["--out", name, "did not write"]);
        assert!(path.exists(), "{rel} was removed");
        assert_eq!(std::fs::read(d.join("report/report.md")).unwrap(), report_before);
        if is_dir {
            std::fs::remove_dir(&path).unwrap();
        } else {
            std::fs::remove_file(&path).unwrap();
        }
    }
    // A directory the demo did not write is refused as before.
    std::fs::create_dir(tmp.path().join("E")).unwrap();
    std::fs::write(tmp.path().join("E/x"), "mine").unwrap();
    assert_refused(
        run_in(tmp.path(), &["demo", "--out", "E", "--particles", "200"]),
        &["--out", "not written by `bitrock demo`"],
    );
    // With only its own files there, the demo replaces them.
    let (code, _, err) = demo(tmp.path());
    assert_eq!(code, 0, "{err}");
    assert_eq!(
        names(&d),
        ["bitrock-demo.txt", "delta-0.4", "delta-0.6", "delta-0.8", "report"]
    );
}

#[test]
fn report_replaces_only_a_report_and_never_writes_into_a_run() {
    let tmp = tempfile::tempdir().unwrap();
    assert_eq!(small_run(tmp.path(), "R", &[]).0, 0);
    let (code, _, err) = run_in(tmp.path(), &["report", "R", "--out", "Rep"]);
    assert_eq!(code, 0, "{err}");
    let rep = tmp.path().join("Rep");
    // A stale figure of an earlier report (written, and marked, as bitrock writes its figures)
    // does not survive the next one: the directory is replaced as a whole.
    bitrock::files::write_own(&rep.join("figures/fig99_old.svg"), "out", |w| {
        std::io::Write::write_all(w, b"<svg/>")
    })
    .unwrap();
    assert_eq!(run_in(tmp.path(), &["report", "R", "--out", "Rep"]).0, 0);
    assert!(!rep.join("figures/fig99_old.svg").exists());
    for rel in ["my-notes.md", "figures/sketch.txt"] {
        std::fs::write(rep.join(rel), "mine").unwrap();
        assert_refused(run_in(tmp.path(), &["report", "R", "--out", "Rep"]), &["--out", rel]);
        assert_eq!(std::fs::read_to_string(rep.join(rel)).unwrap(), "mine");
        std::fs::remove_file(rep.join(rel)).unwrap();
    }
    // Into the run itself or a directory inside it: refused, the run untouched.
    let before = export(tmp.path(), "R");
    assert_refused(run_in(tmp.path(), &["report", "R", "--out", "R"]), &["--out"]);
    assert_refused(
        run_in(tmp.path(), &["report", "R", "--out", "R/rep"]),
        &["--out", "inside the run directory"],
    );
    assert!(!tmp.path().join("R/rep").exists());
    assert_eq!(export(tmp.path(), "R"), before);
}

#[test]
fn output_files_never_replace_a_lock_a_temporary_or_a_runs_own_file() {
    let tmp = tempfile::tempdir().unwrap();
    assert_eq!(small_run(tmp.path(), "R", &[]).0, 0);
    let run_json = std::fs::read(tmp.path().join("R/run.json")).unwrap();
    for (target, why) in [
        ("R/.bitrock-lock", "lock or temporary"),
        ("R/run.json", "inside the run directory"),
        ("R/notes.csv", "inside the run directory"),
        ("R/selection.csv", "inside the run directory"),
        (".bitrock-tmp-x", "lock or temporary"),
    ] {
        assert_refused(run_in(tmp.path(), &["export", "R", "-o", target]), &["--out", why]);
        assert_refused(
            run_in(
                tmp.path(),
                &[
                    "simulate",
                    "--law",
                    "m2",
                    "--omega-rpm",
                    "60",
                    "--duration-s",
                    "1",
                    "-o",
                    target,
                ],
            ),
            &["--out", why],
        );
    }
    assert!(!tmp.path().join("R/notes.csv").exists());
    assert_eq!(std::fs::read(tmp.path().join("R/run.json")).unwrap(), run_json);
    // While a writer holds the lock, a second is still refused (the lock file was not replaced).
    let _held = bitrock::files::DirLock::acquire(&tmp.path().join("R")).unwrap();
    assert_refused(small_run(tmp.path(), "R", &["--force"]), &["in use by another process"]);
}

#[test]
fn an_output_through_a_symbolic_link_writes_the_file_it_points_to() {
    let tmp = tempfile::tempdir().unwrap();
    assert_eq!(small_run(tmp.path(), "R", &[]).0, 0);
    std::fs::create_dir(tmp.path().join("results")).unwrap();
    std::fs::write(tmp.path().join("results/particles.csv"), "old").unwrap();
    std::os::unix::fs::symlink("results/particles.csv", tmp.path().join("latest.csv")).unwrap();
    // The file it points to is the user's: replaced only with --force.
    assert_refused(
        run_in(tmp.path(), &["export", "R", "-o", "latest.csv"]),
        &["--out", "not a file bitrock wrote", "--force"],
    );
    assert_eq!(
        std::fs::read_to_string(tmp.path().join("results/particles.csv")).unwrap(),
        "old"
    );
    let (code, _, err) = run_in(tmp.path(), &["export", "R", "-o", "latest.csv", "--force"]);
    assert_eq!(code, 0, "{err}");
    let link = tmp.path().join("latest.csv");
    assert!(
        std::fs::symlink_metadata(&link).unwrap().file_type().is_symlink(),
        "the link stays a link"
    );
    assert_eq!(
        std::fs::read_to_string(tmp.path().join("results/particles.csv")).unwrap(),
        export(tmp.path(), "R")
    );
    // A link into a run is judged by where it leads.
    std::os::unix::fs::symlink("R/run.json", tmp.path().join("sneaky.json")).unwrap();
    assert_refused(
        run_in(tmp.path(), &["export", "R", "-o", "sneaky.json"]),
        &["--out", "inside the run directory"],
    );
}

#[test]
fn check_selection_refuses_a_selection_directory_holding_the_users_files_before_any_work() {
    let tmp = tempfile::tempdir().unwrap();
    assert_eq!(small_run(tmp.path(), "R", &[]).0, 0);
    let sel = tmp.path().join("R/selection");
    std::fs::create_dir(&sel).unwrap();
    std::fs::write(sel.join("my-matrix.xlsx"), "mine").unwrap();
    assert_refused(
        run_in(
            tmp.path(),
            &["check-selection", "R", "--replicates", "1", "--backend", "cpu", "-q"],
        ),
        &["RUN_DIR", "my-matrix.xlsx"],
    );
    assert_eq!(names(&sel), ["my-matrix.xlsx"]);
}

/// The commands that write one output file, each as (arguments before `-o FILE`).
fn file_writers() -> Vec<Vec<&'static str>> {
    vec![
        vec!["simulate", "--law", "m2", "--omega-rpm", "60", "--duration-s", "1"],
        vec!["export", "R"],
        vec![
            "stability",
            "--run",
            "R",
            "--omega-rpm",
            "40:120:3",
            "--wob-kn",
            "50:300:3",
            "--samples",
            "20",
            "--backend",
            "cpu",
        ],
    ]
}

#[test]
fn no_output_file_replaces_a_users_file_without_force() {
    let tmp = tempfile::tempdir().unwrap();
    assert_eq!(small_run(tmp.path(), "R", &[]).0, 0);
    let record = std::fs::read(Path::new(env!("CARGO_MANIFEST_DIR")).join("data/demo.csv")).unwrap();
    for args in file_writers() {
        let with = |target: &str, force: bool| {
            let mut a = args.clone();
            a.extend(["-o", target]);
            if force {
                a.push("--force");
            }
            run_in(tmp.path(), &a)
        };
        let what = args[0];
        // The user's record: refused, named, untouched, nothing beside it.
        std::fs::write(tmp.path().join("data.csv"), &record).unwrap();
        assert_refused(
            with("data.csv", false),
            &["--out", "data.csv", "not a file bitrock wrote", "--force"],
        );
        assert_eq!(std::fs::read(tmp.path().join("data.csv")).unwrap(), record, "{what}");
        assert_eq!(names(tmp.path()), ["R", "data.csv"], "{what}");
        // An empty file of the user's is the user's too.
        std::fs::write(tmp.path().join("empty.csv"), "").unwrap();
        assert_refused(with("empty.csv", false), &["--out", "empty.csv"]);
        assert_eq!(std::fs::read(tmp.path().join("empty.csv")).unwrap(), b"", "{what}");
        std::fs::remove_file(tmp.path().join("empty.csv")).unwrap();
        // A new file is written; written again, it is bitrock's own and is replaced.
        let (code, _, err) = with("out.csv", false);
        assert_eq!(code, 0, "{what}: {err}");
        let first = std::fs::read(tmp.path().join("out.csv")).unwrap();
        assert_eq!(
            bitrock::files::authorship(&tmp.path().join("out.csv")),
            bitrock::files::Authorship::Own,
            "{what}"
        );
        let (code, _, err) = with("out.csv", false);
        assert_eq!(code, 0, "{what}: {err}");
        assert_eq!(
            std::fs::read(tmp.path().join("out.csv")).unwrap(),
            first,
            "{what}: same inputs, same file"
        );
        // Edited since (one byte appended, or one byte changed in place): the user's now.
        let mut edited = first.clone();
        edited.push(b'\n');
        std::fs::write(tmp.path().join("out.csv"), &edited).unwrap();
        assert_refused(with("out.csv", false), &["--out", "changed since", "--force"]);
        assert_eq!(std::fs::read(tmp.path().join("out.csv")).unwrap(), edited, "{what}");
        let mut same_length = first.clone();
        same_length[0] ^= 1;
        std::fs::write(tmp.path().join("out.csv"), &same_length).unwrap();
        assert_refused(with("out.csv", false), &["--out", "changed since"]);
        // --force replaces the user's file, and the new file is bitrock's again.
        let (code, _, err) = with("data.csv", true);
        assert_eq!(code, 0, "{what}: {err}");
        assert_ne!(std::fs::read(tmp.path().join("data.csv")).unwrap(), record, "{what}");
        assert_eq!(with("data.csv", false).0, 0, "{what}");
        std::fs::remove_file(tmp.path().join("data.csv")).unwrap();
        std::fs::remove_file(tmp.path().join("out.csv")).unwrap();
    }
    // --force alone, with nothing to write to, is a mistake of the command line.
    let (code, _, err) = run_in(tmp.path(), &["export", "R", "--force"]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("--out"), "{err}");
}

#[test]
fn a_report_directory_holding_a_users_report_is_not_replaced() {
    let tmp = tempfile::tempdir().unwrap();
    assert_eq!(small_run(tmp.path(), "R", &[]).0, 0);
    // A directory of the user's that happens to hold a report.md and figures/ by those names.
    let docs = tmp.path().join("docs");
    std::fs::create_dir_all(docs.join("figures")).unwrap();
    std::fs::write(docs.join("report.md"), "# my own report\n").unwrap();
    std::fs::write(docs.join("figures/plot.svg"), "<svg/>").unwrap();
    assert_refused(
        run_in(tmp.path(), &["report", "R", "--out", "docs"]),
        &["--out", "report.md", "figures/plot.svg"],
    );
    assert_eq!(
        std::fs::read_to_string(docs.join("report.md")).unwrap(),
        "# my own report\n"
    );
    // A report bitrock wrote is replaced; once edited, it is the user's.
    assert_eq!(run_in(tmp.path(), &["report", "R", "--out", "Rep"]).0, 0);
    assert_eq!(run_in(tmp.path(), &["report", "R", "--out", "Rep"]).0, 0);
    let md = tmp.path().join("Rep/report.md");
    let mut text = std::fs::read_to_string(&md).unwrap();
    text.push_str("\nMy conclusions.\n");
    std::fs::write(&md, &text).unwrap();
    assert_refused(
        run_in(tmp.path(), &["report", "R", "--out", "Rep"]),
        &["--out", "report.md"],
    );
    assert_eq!(std::fs::read_to_string(&md).unwrap(), text);
}

#[test]
fn no_run_is_placed_inside_another_run() {
    let tmp = tempfile::tempdir().unwrap();
    assert_eq!(small_run(tmp.path(), "R", &[]).0, 0);
    let before = export(tmp.path(), "R");
    let files_before = names(&tmp.path().join("R"));
    for inside in ["R/selection", "R/sub", "R/selection/x"] {
        assert_refused(
            small_run(tmp.path(), inside, &[]),
            &["--out", "inside the run directory"],
        );
    }
    assert_refused(
        run_in(
            tmp.path(),
            &["demo", "--out", "R/demo", "--particles", "200", "--backend", "cpu"],
        ),
        &["--out", "inside the run directory"],
    );
    assert_eq!(names(&tmp.path().join("R")), files_before);
    assert_eq!(export(tmp.path(), "R"), before);
    // The run's own check still has its place.
    let (code, _, err) = run_in(
        tmp.path(),
        &["check-selection", "R", "--replicates", "1", "--backend", "cpu", "-q"],
    );
    assert_eq!(code, 0, "{err}");
}

#[test]
fn a_selection_check_replaces_its_own_files_but_not_ones_edited_since() {
    let tmp = tempfile::tempdir().unwrap();
    assert_eq!(small_run(tmp.path(), "R", &[]).0, 0);
    let check = ["check-selection", "R", "--replicates", "1", "--backend", "cpu", "-q"];
    // A check written before files carried marks (its names, no mark) is replaced.
    let sel = tmp.path().join("R/selection");
    std::fs::create_dir(&sel).unwrap();
    std::fs::write(sel.join("matrix.csv"), "old check").unwrap();
    let (code, _, err) = run_in(tmp.path(), &check);
    assert_eq!(code, 0, "{err}");
    assert_ne!(std::fs::read_to_string(sel.join("matrix.csv")).unwrap(), "old check");
    // Its own check, unchanged, is replaced; once edited, it is the user's.
    assert_eq!(run_in(tmp.path(), &check).0, 0);
    let mut edited = std::fs::read_to_string(sel.join("selection.json")).unwrap();
    edited.push(' ');
    std::fs::write(sel.join("selection.json"), &edited).unwrap();
    assert_refused(run_in(tmp.path(), &check), &["RUN_DIR", "selection.json"]);
    assert_eq!(std::fs::read_to_string(sel.join("selection.json")).unwrap(), edited);
}

/// Every file of `dir` (one level) with its bytes.
fn contents(dir: &Path) -> Vec<(String, Vec<u8>)> {
    names(dir)
        .into_iter()
        .map(|n| {
            let bytes = std::fs::read(dir.join(&n)).unwrap_or_default();
            (n, bytes)
        })
        .collect()
}

#[test]
fn no_output_lands_inside_an_evidence_or_a_watch_directory_even_with_force() {
    let tmp = tempfile::tempdir().unwrap();
    let (code, _, err) = run_in(
        tmp.path(),
        &[
            "simulate",
            "--law",
            "m2",
            "--omega-rpm",
            "60",
            "--duration-s",
            "40",
            "--sample-hz",
            "20",
            "-o",
            "rec.csv",
        ],
    );
    assert_eq!(code, 0, "{err}");
    let (code, _, err) = run_in(
        tmp.path(),
        &[
            "evidence",
            "rec.csv",
            "--laws",
            "m2",
            "--particles",
            "60",
            "--islands",
            "2",
            "--noise",
            "iid",
            "--backend",
            "cpu",
            "--out",
            "EV",
            "-q",
        ],
    );
    assert_eq!(code, 0, "{err}");
    let (code, _, err) = run_in(
        tmp.path(),
        &[
            "watch",
            "rec.csv",
            "--laws",
            "m2",
            "--particles",
            "60",
            "--backend",
            "cpu",
            "--out",
            "W",
            "--window-s",
            "20",
            "--step-s",
            "20",
        ],
    );
    assert_eq!(code, 0, "{err}");
    let (evidence, watch) = (contents(&tmp.path().join("EV")), contents(&tmp.path().join("W")));
    let simulate = |target: &str| {
        let args = [&file_writers()[0][..], &["-o", target, "--force"]].concat();
        run_in(tmp.path(), &args)
    };
    for (target, kind) in [
        ("W/watch.sqlite", "watch"),
        ("W/notes.csv", "watch"),
        ("EV/posterior.csv", "evidence"),
        ("EV/evidence.json", "evidence"),
        ("EV/new.csv", "evidence"),
    ] {
        let refused = simulate(target);
        // Refused by name, and never with the advice that would destroy.
        assert!(!refused.2.contains("--force"), "{}", refused.2);
        assert_refused(refused, &["--out", &format!("inside the {kind} directory")]);
    }
    for inside in ["EV/report", "W/report"] {
        assert_refused(
            run_in(tmp.path(), &["report", "EV", "--out", inside]),
            &["--out", "inside the"],
        );
    }
    assert_refused(
        run_in(
            tmp.path(),
            &[
                "evidence",
                "rec.csv",
                "--laws",
                "m2",
                "--particles",
                "60",
                "--backend",
                "cpu",
                "--out",
                "W/ev",
            ],
        ),
        &["--out", "inside the watch directory"],
    );
    assert_eq!(contents(&tmp.path().join("EV")), evidence);
    assert_eq!(contents(&tmp.path().join("W")), watch);
}
