//! Hostile but realistic use: `--force` never deletes what bitrock did not write, every file
//! is written whole or not at all, one writer per run directory, no flag hangs or exhausts the
//! machine, and data or targets that cannot work exit 2 naming the file or flag. The modules
//! below hold one class of failure each. Every run is small (the embedded record, a few hundred
//! particles, the CPU; the demo's on the backend a user gets).

mod bounds;
mod degenerate;
mod laws;
mod numbers;
mod outputs;
mod stale;
mod streams;

use crate::support::bin;
use bitrock::files::{DirLock, TEMP_PREFIX};
use std::path::{Path, PathBuf};
use std::process::Output;

/// Runs bitrock in `cwd`; (status, stdout, stderr).
pub(super) fn run_in(cwd: &Path, args: &[&str]) -> (i32, String, String) {
    let out: Output = bin().current_dir(cwd).args(args).output().expect("run bitrock");
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// A small finished run into `dir` (relative to `cwd`), with `extra` flags.
pub(super) fn small_run(cwd: &Path, dir: &str, extra: &[&str]) -> (i32, String, String) {
    run_of(cwd, dir, "2", extra)
}

/// A small run of at most `populations` populations into `dir`, with `extra` flags: on the
/// embedded record thinned by 4 (the runs here test what is written, refused and kept; the
/// record's fits, a second of each run whole, take a quarter of it).
pub(super) fn run_of(cwd: &Path, dir: &str, populations: &str, extra: &[&str]) -> (i32, String, String) {
    let mut args = vec![
        "abc",
        "--out",
        dir,
        "--thin",
        "4",
        "--particles",
        "200",
        "--max-populations",
        populations,
        "--backend",
        "cpu",
        "-q",
    ];
    args.extend_from_slice(extra);
    run_in(cwd, &args)
}

/// The particles of a run as CSV (what `export` prints).
pub(super) fn export(cwd: &Path, dir: &str) -> String {
    let (code, out, err) = run_in(cwd, &["export", dir]);
    assert_eq!(code, 0, "{err}");
    out
}

/// Names in `dir`, sorted.
pub(super) fn names(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

/// The embedded record as a file at `path`, its rows changed by `row`.
pub(super) fn record(path: &Path, row: impl Fn(&[f64]) -> Vec<f64>) -> PathBuf {
    let mut text = String::new();
    for (i, line) in bitrock::data::DEMO_CSV.lines().enumerate() {
        if i == 0 || line.starts_with('#') {
            text.push_str(line);
        } else {
            let values: Vec<f64> = line.split(',').map(|v| v.parse().unwrap()).collect();
            let changed: Vec<String> = row(&values).iter().map(|v| format!("{v:e}")).collect();
            text.push_str(&changed.join(","));
        }
        text.push('\n');
    }
    std::fs::write(path, text).unwrap();
    path.to_path_buf()
}

pub(super) fn assert_refused(result: (i32, String, String), needles: &[&str]) {
    let (code, _, err) = result;
    assert_eq!(code, 2, "{err}");
    for needle in needles {
        assert!(err.contains(needle), "'{needle}' not in: {err}");
    }
}

// 1. --force replaces only what bitrock wrote.

#[test]
fn force_refuses_a_directory_bitrock_did_not_write() {
    let tmp = tempfile::tempdir().unwrap();
    let notes = tmp.path().join("notes");
    std::fs::create_dir(&notes).unwrap();
    std::fs::write(notes.join("thesis.tex"), "mine").unwrap();
    assert_refused(small_run(tmp.path(), "notes", &["--force"]), &["--out", "thesis.tex"]);
    // From inside it, as `--out .`: refused the same way.
    assert_refused(small_run(&notes, ".", &["--force"]), &["--out", "thesis.tex"]);
    assert_eq!(names(&notes), ["thesis.tex"]);
    // A run directory with a file of the user's in it is not replaced either.
    assert_eq!(small_run(tmp.path(), "R", &[]).0, 0);
    std::fs::write(tmp.path().join("R/notes.txt"), "mine").unwrap();
    assert_refused(small_run(tmp.path(), "R", &["--force"]), &["notes.txt"]);
    assert!(tmp.path().join("R/notes.txt").exists());
}

#[test]
fn force_refuses_the_current_directory_and_any_holding_the_record() {
    let tmp = tempfile::tempdir().unwrap();
    assert_eq!(small_run(tmp.path(), "R", &[]).0, 0);
    let before = export(tmp.path(), "R");
    let r = tmp.path().join("R");
    assert_refused(small_run(&r, ".", &["--force"]), &["--out", "current directory"]);
    assert_eq!(export(tmp.path(), "R"), before);

    let w = tmp.path().join("W");
    std::fs::create_dir_all(w.join("sub")).unwrap();
    let rec = record(&w.join("sub/my_record.csv"), |v| v.to_vec());
    for out in ["W", "W/sub"] {
        let (code, _, err) = run_in(
            tmp.path(),
            &[
                "abc",
                rec.to_str().unwrap(),
                "--out",
                out,
                "--force",
                "--particles",
                "100",
                "-q",
            ],
        );
        assert_eq!(code, 2, "{err}");
        assert!(err.contains("holds the record"), "{err}");
    }
    assert!(rec.exists());
}

#[test]
fn force_replaces_a_run_with_a_new_one_and_leaves_nothing_beside_it() {
    let tmp = tempfile::tempdir().unwrap();
    assert_eq!(small_run(tmp.path(), "R", &[]).0, 0);
    let old = export(tmp.path(), "R");
    assert_refused(small_run(tmp.path(), "R", &[]), &["--force"]);
    assert_eq!(small_run(tmp.path(), "R", &["--force", "--seed", "2"]).0, 0);
    let new = export(tmp.path(), "R");
    assert_ne!(old, new);
    assert_eq!(names(tmp.path()), ["R"]);
}

/// When to SIGKILL `abc --out R --force` in [`a_kill_during_force_leaves_the_old_run_or_the_new_one`].
#[cfg(target_os = "linux")]
#[derive(Clone, Copy, Debug)]
enum KillAt {
    /// This long after the start: before the fits end, however loaded the machine.
    Start(u64),
    /// This long after the new run is swapped into R (R's inode changes).
    Swap(u64),
}

/// True when `part` is the export of a run stopped after a whole population of the run whose
/// export is `whole`: its header and populations 0..=k, each identical, for some k ≥ 0.
#[cfg(target_os = "linux")]
fn whole_populations_of(part: &str, whole: &str) -> bool {
    let population = |line: Option<&str>| line.and_then(|l| l.split(',').next().map(str::to_string));
    let Some(rest) = whole.strip_prefix(part) else {
        return false;
    };
    let holds_population_0 = part.lines().nth(1).is_some_and(|l| l.starts_with("0,"));
    let ends_at_a_population = rest.is_empty() || population(rest.lines().next()) != population(part.lines().last());
    holds_population_0 && part.ends_with('\n') && ends_at_a_population
}

#[cfg(target_os = "linux")]
#[test]
fn a_kill_during_force_leaves_the_old_run_or_the_new_one() {
    use std::os::unix::fs::MetadataExt;
    use std::time::{Duration, Instant};
    let tmp = tempfile::tempdir().unwrap();
    let new_run = [
        "--seed",
        "3",
        "--particles",
        "4000",
        "--max-populations",
        "4",
        "--backend",
        "cpu",
        "-q",
    ];
    // The new run, uninterrupted: what R must hold, population by population, once swapped.
    let mut args = vec!["abc", "--out", "NEW"];
    args.extend_from_slice(&new_run);
    assert_eq!(run_in(tmp.path(), &args).0, 0);
    let new = export(tmp.path(), "NEW");
    std::fs::remove_dir_all(tmp.path().join("NEW")).unwrap();
    // The judge itself: whole populations pass; no population, or a cut inside one, does not.
    let header = new.find('\n').unwrap() + 1;
    let first_row = header + new[header..].find('\n').unwrap() + 1;
    let population_1 = new.find("\n1,").unwrap() + 1;
    assert!(whole_populations_of(&new, &new) && whole_populations_of(&new[..population_1], &new));
    assert!(!whole_populations_of(&new[..header], &new));
    assert!(!whole_populations_of(&new[..first_row], &new));
    assert!(!whole_populations_of(&new[..population_1 - 1], &new));

    assert_eq!(small_run(tmp.path(), "R", &[]).0, 0);
    let old = export(tmp.path(), "R");
    let r = tmp.path().join("R");
    let kills = [
        KillAt::Start(30),
        KillAt::Swap(0),
        KillAt::Swap(20),
        KillAt::Swap(100),
        KillAt::Swap(300),
    ];
    for kill in kills {
        let old_inode = std::fs::metadata(&r).unwrap().ino();
        let mut child = bin()
            .current_dir(tmp.path())
            .args(["abc", "--out", "R", "--force"])
            .args(new_run)
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .spawn()
            .unwrap();
        let started = Instant::now();
        let swapped = loop {
            // R is never missing, at any moment of the run.
            let swapped = std::fs::metadata(&r).unwrap().ino() != old_inode;
            let due = match kill {
                KillAt::Start(ms) => started.elapsed() >= Duration::from_millis(ms),
                KillAt::Swap(_) => swapped,
            };
            if due {
                break swapped;
            }
            if child.try_wait().unwrap().is_some() {
                // Ended: whether it swapped is what R is now (it may have swapped and ended
                // since the look above).
                break std::fs::metadata(&r).unwrap().ino() != old_inode;
            }
            assert!(started.elapsed() < Duration::from_secs(120), "no swap in 120 s");
            std::thread::sleep(Duration::from_millis(1));
        };
        if let KillAt::Swap(ms) = kill {
            std::thread::sleep(Duration::from_millis(ms));
        }
        let _ = child.kill(); // SIGKILL (an error if it had already ended)
        let status = child.wait().unwrap();
        let now = export(tmp.path(), "R");
        match kill {
            KillAt::Start(ms) => assert_eq!(now, old, "killed {ms} ms after the start: the old run"),
            KillAt::Swap(ms) => {
                assert!(swapped, "{kill:?}: the run ended ({status}) without swapping");
                assert!(
                    whole_populations_of(&now, &new),
                    "killed {ms} ms after the swap: R holds neither the old run nor whole populations of the new one:\n{}",
                    now.lines().take(3).collect::<Vec<_>>().join("\n")
                );
                // Back to the old run for the next kill.
                assert_eq!(small_run(tmp.path(), "R", &["--force"]).0, 0);
                assert_eq!(export(tmp.path(), "R"), old);
            }
        }
    }
    // A later run in the same parent removes the staging directories the kills left.
    assert_eq!(small_run(tmp.path(), "R", &["--force"]).0, 0);
    assert_eq!(names(tmp.path()), ["R"]);
}

// 2. Every file whole or not at all.

#[test]
fn a_failed_write_leaves_the_old_file_and_no_temporary() {
    let tmp = tempfile::tempdir().unwrap();
    let target = tmp.path().join("map.csv");
    std::fs::write(&target, "old contents\n").unwrap();
    // A full disk mid-write, injected: part of the file is written, then ENOSPC.
    let err = bitrock::run::dir::write_whole(&target, "out", true, |w| {
        w.write_all(b"omega_rpm,wob_kn\n20,1")?;
        Err(std::io::Error::from(std::io::ErrorKind::StorageFull))
    })
    .unwrap_err();
    let text = err.to_string();
    assert!(text.starts_with("`out`: ") && text.contains("map.csv"), "{text}");
    assert!(!err.is_bad_input(), "a full disk is a failure of the machine (exit 3)");
    assert_eq!(std::fs::read_to_string(&target).unwrap(), "old contents\n");
    assert_eq!(names(tmp.path()), ["map.csv"]);
    // A write that succeeds replaces it whole.
    bitrock::run::dir::write_whole(&target, "out", true, |w| w.write_all(b"new\n")).unwrap();
    assert_eq!(std::fs::read_to_string(&target).unwrap(), "new\n");
    assert_eq!(names(tmp.path()), ["map.csv"]);
}

#[cfg(unix)]
#[test]
fn outputs_are_created_with_the_process_umask() {
    use std::os::unix::fs::PermissionsExt;
    let tmp = tempfile::tempdir().unwrap();
    assert_eq!(small_run(tmp.path(), "R", &[]).0, 0);
    let bitrock = env!("CARGO_BIN_EXE_bitrock");
    let script = format!(
        "umask 027 && '{bitrock}' export R -o particles.csv && '{bitrock}' simulate --law m2 --omega-rpm 100 --duration-s 2 -o sim.csv"
    );
    let status = std::process::Command::new("sh")
        .current_dir(tmp.path())
        .args(["-c", &script])
        .status()
        .unwrap();
    assert!(status.success());
    for name in ["particles.csv", "sim.csv"] {
        let mode = std::fs::metadata(tmp.path().join(name)).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode, 0o640, "{name}: {mode:o}");
    }
}

#[test]
fn a_store_killed_while_being_created_leaves_only_a_stale_temporary_the_next_run_removes() {
    let tmp = tempfile::tempdir().unwrap();
    let r = tmp.path().join("R");
    std::fs::create_dir(&r).unwrap();
    // What a kill during creation leaves: an unlocked temporary of bitrock's naming.
    std::fs::write(r.join(format!("{TEMP_PREFIX}Ab12Cd")), b"SQLite format 3\0partial").unwrap();
    // Not a run (export says so), and not a directory that needs --force.
    assert_eq!(run_in(tmp.path(), &["export", "R"]).0, 2);
    assert_eq!(small_run(tmp.path(), "R", &[]).0, 0);
    assert_eq!(
        names(&r),
        [".bitrock-lock", "data.csv", "envelopes.csv", "run.json", "run.sqlite"]
    );
}

#[test]
fn stale_staging_directories_of_summaries_and_reports_are_removed_by_the_next_run() {
    let tmp = tempfile::tempdir().unwrap();
    assert_eq!(small_run(tmp.path(), "R", &[]).0, 0);
    let r = tmp.path().join("R");
    std::fs::create_dir(r.join(".bitrock-summary-x1Y2")).unwrap();
    std::fs::write(r.join(".bitrock-summary-x1Y2/run.json"), "{").unwrap();
    let (code, _, err) = run_in(tmp.path(), &["abc", "--resume", "R", "-q"]);
    assert_eq!(code, 0, "{err}");
    assert!(!r.join(".bitrock-summary-x1Y2").exists());
}

#[test]
fn no_command_writes_over_a_runs_store() {
    let tmp = tempfile::tempdir().unwrap();
    assert_eq!(small_run(tmp.path(), "R", &[]).0, 0);
    let before = export(tmp.path(), "R");
    assert_refused(
        run_in(tmp.path(), &["export", "R", "-o", "R/run.sqlite"]),
        &["--out", "run's store"],
    );
    assert_refused(
        run_in(
            tmp.path(),
            &[
                "stability",
                "--run",
                "R",
                "--out",
                "R/run.sqlite",
                "--omega-rpm",
                "20:220:3",
                "--wob-kn",
                "20:700:3",
            ],
        ),
        &["--out", "run's store"],
    );
    assert_eq!(export(tmp.path(), "R"), before);
}

// 3. One writer per run directory.

#[test]
fn a_locked_run_is_refused_naming_the_holder() {
    let tmp = tempfile::tempdir().unwrap();
    assert_eq!(small_run(tmp.path(), "R", &[]).0, 0);
    let before = export(tmp.path(), "R");
    let lock = DirLock::acquire(&tmp.path().join("R")).unwrap();
    let pid = format!("PID {}", std::process::id());
    assert_refused(run_in(tmp.path(), &["abc", "--resume", "R", "-q"]), &["in use", &pid]);
    assert_refused(small_run(tmp.path(), "R", &["--force"]), &["in use", &pid]);
    drop(lock);
    assert_eq!(export(tmp.path(), "R"), before);
    assert_eq!(run_in(tmp.path(), &["abc", "--resume", "R", "-q"]).0, 0);
}

// 4. No flag can hang, exhaust memory or spawn unbounded threads.

#[test]
fn flags_beyond_the_machine_are_refused_before_any_work() {
    let tmp = tempfile::tempdir().unwrap();
    assert_refused(
        small_run(tmp.path(), "T", &["--threads", "99999999999"]),
        &["--threads", "1..="],
    );
    assert_refused(
        run_in(
            tmp.path(),
            &[
                "abc",
                "--out",
                "P",
                "--particles",
                "1000000000",
                "--backend",
                "cpu",
                "-q",
            ],
        ),
        &["--particles", "needs about", "available"],
    );
    assert_refused(
        run_in(
            tmp.path(),
            &["simulate", "--law", "m2", "--omega-rpm", "100", "--duration-s", "1e12"],
        ),
        &["--duration-s", "needs about"],
    );
    assert_refused(small_run(tmp.path(), "D", &["--delta", "1e100"]), &["--delta"]);
    assert_refused(
        small_run(
            tmp.path(),
            "K",
            &[
                "--sampler",
                "smc",
                "--perturbation",
                "global",
                "--kernel-scale",
                "1e300",
            ],
        ),
        &["--kernel-scale", "prior box"],
    );
    assert_refused(
        small_run(tmp.path(), "E", &["--start-epsilon", "0.001"]),
        &["--start-epsilon"],
    );
    assert_refused(
        small_run(tmp.path(), "S", &["--summary-population", "99"]),
        &["--summary-population"],
    );
    // Nothing was written for any of them.
    assert!(names(tmp.path()).is_empty(), "{:?}", names(tmp.path()));
}

#[test]
fn a_summary_population_beyond_the_resumed_run_is_refused_before_any_population() {
    let tmp = tempfile::tempdir().unwrap();
    assert_eq!(small_run(tmp.path(), "R", &[]).0, 0);
    let before = export(tmp.path(), "R");
    // Were it checked only after the run, populations 2 and 3 would be stored first.
    assert_refused(
        run_in(
            tmp.path(),
            &[
                "abc",
                "--resume",
                "R",
                "--max-populations",
                "4",
                "--summary-population",
                "4",
                "-q",
            ],
        ),
        &["--summary-population", "at most 4 populations (0..=3), got 4"],
    );
    assert_eq!(export(tmp.path(), "R"), before);
    // One the continued run can have is accepted and summarised.
    let (code, out, err) = run_in(
        tmp.path(),
        &["abc", "--resume", "R", "--summary-population", "0", "--json", "-q"],
    );
    assert_eq!(code, 0, "{err}");
    let summary: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(summary["posterior"]["population"], 0, "{out}");
}

#[test]
fn resuming_a_store_that_lost_particles_is_refused_not_a_panic() {
    let tmp = tempfile::tempdir().unwrap();
    assert_eq!(small_run(tmp.path(), "R", &[]).0, 0);
    let conn = rusqlite::Connection::open(tmp.path().join("R/run.sqlite")).unwrap();
    // Schema 3 stores each particle once (`particles` is a view): delete the rows themselves.
    conn.execute("DELETE FROM particle_rows", []).unwrap();
    drop(conn);
    assert_refused(
        run_in(tmp.path(), &["abc", "--resume", "R", "--max-populations", "3", "-q"]),
        &["run.sqlite", "population 1 has 0 of its 200 particles"],
    );
}

// 5. Exit codes and messages.

#[test]
fn data_that_defeat_the_fits_exit_2_naming_the_file_and_the_cause() {
    let tmp = tempfile::tempdir().unwrap();
    let p = |name: &str| tmp.path().join(name);
    // Columns: time_s, bit_speed_rpm, torque_knm, wob_kn.
    let cases = [
        (
            record(&p("constant.csv"), |v| vec![v[0], 100.0, v[2], v[3]]),
            "bit speed",
        ),
        (
            record(&p("identical.csv"), |_| vec![1.0, 100.0, 7.0, 240.0]),
            "bit speed",
        ),
        (
            record(&p("huge.csv"), |v| vec![v[0], v[1], v[2] * 1e300, v[3]]),
            "largest |torque|",
        ),
        (
            record(&p("tiny.csv"), |v| vec![v[0], v[1], v[2] * 1e-320, v[3]]),
            "largest |torque|",
        ),
    ];
    for (file, cause) in &cases {
        let path = file.to_str().unwrap();
        assert_refused(run_in(tmp.path(), &["fit", path]), &[path, cause]);
    }
    // Records that pass those checks but defeat a law's fit: the record, the law and the cause
    // are named, in every command that fits, and nothing is written.
    let fast = record(&p("fast.csv"), |v| vec![v[0], v[1] * 1e60, v[2], v[3]]);
    let fast = fast.to_str().unwrap();
    assert_refused(run_in(tmp.path(), &["fit", fast]), &[fast, "bit speed", "--speed-unit"]);
    // Two speeds, alternating: four-parameter laws are curves through two points.
    let two = record(&p("two_speeds.csv"), |v| {
        vec![v[0], if v[0] % 0.04 < 0.01 { 100.0 } else { 150.0 }, v[2], v[3]]
    });
    let two = two.to_str().unwrap();
    // Of several laws that fail, the first asked for is named, every time.
    for command in [
        &["fit", two, "--laws", "m4,m2"][..],
        &["abc", two, "--out", "T2", "--laws", "m4,m1"],
    ] {
        assert_refused(
            run_in(tmp.path(), command),
            &[
                two,
                "m4: least-squares fit",
                "2 distinct bit speeds",
                "needs at least 4",
            ],
        );
    }
    // Four speeds 10⁻⁸ apart: distinct, but the cubic's normal equations are singular.
    let near = record(&p("near_speeds.csv"), |v| {
        vec![v[0], 100.0 + 1e-6 * ((v[0] * 50.0).round() % 4.0), v[2], v[3]]
    });
    let near = near.to_str().unwrap();
    assert_refused(
        run_in(tmp.path(), &["fit", near, "--laws", "m4"]),
        &[near, "m4: least-squares fit", "no starting point"],
    );
    assert_refused(
        run_in(tmp.path(), &["parity", near, "--laws", "m4"]),
        &[near, "m4: least-squares fit"],
    );
    assert!(!p("T2").exists());
    let no_wob = record(&p("no_wob.csv"), |v| vec![v[0], v[1], v[2], 0.0]);
    assert_refused(
        run_in(tmp.path(), &["fit", no_wob.to_str().unwrap(), "--scale-by-wob"]),
        &["--scale-by-wob", "weight on bit ≤ 0"],
    );
}

#[test]
fn output_targets_that_cannot_be_written_name_their_flag() {
    let tmp = tempfile::tempdir().unwrap();
    assert_eq!(small_run(tmp.path(), "R", &[]).0, 0);
    std::fs::create_dir(tmp.path().join("adir")).unwrap();
    assert_refused(
        run_in(tmp.path(), &["export", "R", "--out", "adir"]),
        &["--out", "is a directory"],
    );
    assert_refused(
        run_in(tmp.path(), &["export", "R", "--out", "missing/x.csv"]),
        &["--out", "does not exist"],
    );
    let (code, _, err) = small_run(tmp.path(), "/proc/bitrock-run", &[]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("--out: /proc/bitrock-run"), "{err}");
    assert_eq!(err.matches("os error").count(), 1, "the OS error once: {err}");
    #[cfg(unix)]
    {
        std::os::unix::fs::symlink("nowhere", tmp.path().join("dangling")).unwrap();
        assert_refused(small_run(tmp.path(), "dangling", &[]), &["--out", "symbolic link"]);
        assert_refused(
            run_in(tmp.path(), &["export", "R", "-o", "dangling"]),
            &["--out", "symbolic link"],
        );
    }
}

#[test]
fn extra_values_duplicate_columns_and_doubled_roles_are_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let prior = tmp.path().join("prior.toml");
    std::fs::write(&prior, "[m1]\nb0 = [4.0, 5.0, 6.0]\n").unwrap();
    assert_refused(
        small_run(tmp.path(), "R", &["--prior", prior.to_str().unwrap()]),
        &["prior.toml", "[m1] b0 has 3 values"],
    );
    // Empty explicit bounds are blamed on the file, in its units.
    std::fs::write(&prior, "[m2]\ntsb = [-2.0, -1.0]\n").unwrap();
    assert_refused(
        small_run(tmp.path(), "R", &["--prior", prior.to_str().unwrap()]),
        &["--prior", "[m2] tsb"],
    );
    assert_refused(
        run_in(
            tmp.path(),
            &[
                "simulate",
                "--law",
                "m2",
                "--omega-rpm",
                "100",
                "--params",
                "10,5,0.3,7",
            ],
        ),
        &["--params", "takes 3 parameters", "got 4"],
    );
    let dup = tmp.path().join("dup.csv");
    std::fs::write(&dup, "bit_speed_rpm,torque_knm,torque_knm\n100,7,8\n120,6,5\n").unwrap();
    assert_refused(
        run_in(tmp.path(), &["fit", dup.to_str().unwrap()]),
        &["dup.csv:1", "two columns"],
    );
    let rec = record(&tmp.path().join("rec.csv"), |v| v.to_vec());
    assert_refused(
        run_in(tmp.path(), &["fit", rec.to_str().unwrap(), "--speed-col", "torque_knm"]),
        &["rec.csv:1", "--speed-col and --torque-col"],
    );
    assert_refused(
        run_in(
            tmp.path(),
            &[
                "stability",
                "--law",
                "m2",
                "--params",
                "10,5,0.3",
                "--fe-file",
                "nowhere.toml",
            ],
        ),
        &["--fe-file", "--structure fe"],
    );
    assert_eq!(names(tmp.path()), ["dup.csv", "prior.toml", "rec.csv"]);
}

#[test]
fn flags_that_do_not_apply_to_the_run_are_refused_naming_flag_and_mode() {
    let tmp = tempfile::tempdir().unwrap();
    // SMC-only flags with the rejection sampler (the default, or named).
    for (flag, value) in [("--kernel-scale", "3"), ("--p-stay", "0.5"), ("--smc-weights", "host")] {
        assert_refused(
            small_run(tmp.path(), "R", &[flag, value]),
            &[&format!("{flag}: applies only to --sampler smc"), "rejection sampler"],
        );
        assert_refused(
            small_run(tmp.path(), "R", &["--sampler", "rejection", flag, value]),
            &[flag, "rejection sampler"],
        );
    }
    // The rejection sampler's --mode with SMC.
    assert_refused(
        small_run(tmp.path(), "R", &["--sampler", "smc", "--mode", "paper"]),
        &["--mode: applies only to the rejection sampler", "--sampler smc"],
    );
    // The stderr rule's k with the δ rule.
    assert_refused(
        small_run(tmp.path(), "R", &["--prior-k", "2"]),
        &["--prior-k: applies only to --prior-rule stderr"],
    );
    // W_ref without the scaling that uses it.
    for result in [
        run_in(tmp.path(), &["fit", "--w-ref-kn", "100"]),
        small_run(tmp.path(), "R", &["--w-ref-kn", "100"]),
    ] {
        assert_refused(result, &["--w-ref-kn: applies only with --scale-by-wob"]);
    }
    assert!(names(tmp.path()).is_empty(), "{:?}", names(tmp.path()));
    // What defines the populations cannot be changed by a resume: refused, naming the flag.
    assert_eq!(small_run(tmp.path(), "R", &[]).0, 0);
    let before = export(tmp.path(), "R");
    for extra in [
        &["--seed", "2"][..],
        &["--particles", "100"],
        &["--delta", "0.5"],
        &["--prior-rule", "stderr"],
        &["--prior-k", "2"],
        &["--laws", "m2"],
        &["--sampler", "smc"],
        &["--kernel-scale", "3"],
        &["--mode", "paper"],
        &["--epsilons", "0.1,0.05"],
        &["--force"],
        &["--min-speed-rpm", "10"],
        &["--w-ref-kn", "100"],
        &["--column-map", "map.toml"],
    ] {
        let mut args = vec!["abc", "--resume", "R", "-q"];
        args.extend_from_slice(extra);
        assert_refused(run_in(tmp.path(), &args), &["--resume", extra[0]]);
    }
    assert_eq!(export(tmp.path(), "R"), before);
}

/// A full disk under standard output (`/dev/full`) is a failure of the machine (exit 3) whose
/// message names what could not be written, once.
#[cfg(target_os = "linux")]
#[test]
fn a_full_disk_under_standard_output_is_named() {
    let tmp = tempfile::tempdir().unwrap();
    assert_eq!(small_run(tmp.path(), "R", &[]).0, 0);
    for args in [
        &["export", "R"][..],
        &["fit", "--json"],
        &["simulate", "--law", "m2", "--omega-rpm", "100", "--duration-s", "2"],
        &["abc", "--resume", "R", "-q", "--json"],
    ] {
        let full = std::fs::OpenOptions::new().write(true).open("/dev/full").unwrap();
        let out = bin().current_dir(tmp.path()).args(args).stdout(full).output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(3), "{args:?}: {err}");
        assert!(
            err.contains("error: standard output: cannot write: "),
            "{args:?}: {err}"
        );
        assert_eq!(err.matches("os error").count(), 1, "{args:?}: {err}");
    }
}
