//! The command line's messages for bad input, word for word: the library names configuration
//! fields and the binary translates them into its flags, and what a user of the command line
//! reads must not change with that translation. `expected/messages.txt` holds each case's exit
//! status and `error:` lines.

use crate::support::bin;
use std::path::Path;

const EXPECTED: &str = include_str!("expected/messages.txt");

/// A field-like record at 60 rpm and 100 kN (m2 at the paper's estimate), written by
/// `bitrock simulate` into `dir/rec.csv`.
fn write_record(dir: &Path) {
    let out = bin()
        .current_dir(dir)
        .args([
            "simulate",
            "--law",
            "m2",
            "--params",
            "13,0.2,0.3",
            "--omega-rpm",
            "60",
            "--wob-kn",
            "100",
        ])
        .args([
            "--duration-s",
            "20",
            "--noise-torque-knm",
            "0.2",
            "--wob-fluctuation-kn",
            "10",
        ])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    std::fs::write(dir.join("rec.csv"), out.stdout).unwrap();
}

/// One case: its arguments and the exit status and `error:` lines expected.
struct Case {
    args: String,
    expected: Vec<String>,
}

fn cases() -> Vec<Case> {
    let mut cases: Vec<Case> = Vec::new();
    for line in EXPECTED.lines().filter(|l| !l.starts_with('#')) {
        match line.strip_prefix("$ ") {
            Some(args) => cases.push(Case {
                args: args.to_string(),
                expected: Vec::new(),
            }),
            None => cases
                .last_mut()
                .expect("a case before its lines")
                .expected
                .push(line.to_string()),
        }
    }
    cases
}

/// The memory this machine has, as the expected file writes it.
fn without_available_memory(line: &str) -> String {
    match line.find(" is available") {
        Some(end) => {
            let start = line[..end].rfind("; ").map_or(0, |i| i + 2);
            format!("{}<AVAILABLE>{}", &line[..start], &line[end..])
        }
        None => line.to_string(),
    }
}

#[test]
fn bad_input_is_told_in_the_words_of_the_command_line() {
    let dir = tempfile::tempdir().unwrap();
    write_record(dir.path());
    let cases = cases();
    assert!(cases.len() >= 60, "{} cases", cases.len());
    let mut differences = Vec::new();
    for case in &cases {
        let out = bin()
            .current_dir(dir.path())
            .args(case.args.split(' '))
            .env("NODEVICE_SELECT", "1")
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        let mut got = vec![format!("exit {}", out.status.code().unwrap_or(-1))];
        // Mesa's Vulkan loader writes its own `error:` line where XDG_RUNTIME_DIR is unset.
        let ours = |l: &&str| l.starts_with("error:") && !l.contains("XDG_RUNTIME_DIR");
        got.extend(stderr.lines().filter(ours).map(without_available_memory));
        if got != case.expected {
            differences.push(format!(
                "$ {}\n  expected: {:?}\n  got:      {:?}",
                case.args, case.expected, got
            ));
        }
        for name in ["r1", "r2", "r3", "r4", "r5", "r6", "r7", "r8", "r9"] {
            let _ = std::fs::remove_dir_all(dir.path().join(name));
        }
    }
    assert!(differences.is_empty(), "{}", differences.join("\n"));
}

/// A file's errors are said in the file's words (its keys, not the flags that share their
/// names); a record too short for a window, or without a row, says so; a long search for a
/// finite-element string's critical bit damping is said, with its time, before it starts; a
/// copied evidence directory, which bitrock may not write its check into, is refused before
/// the check's work.
#[test]
fn files_short_records_and_long_searches_are_told_in_their_own_words() {
    let dir = tempfile::tempdir().unwrap();
    write_record(dir.path());
    let run = |args: &[&str]| {
        let out = bin()
            .current_dir(dir.path())
            .args(args)
            .env("NODEVICE_SELECT", "1")
            .output()
            .unwrap();
        (out.status.code(), String::from_utf8_lossy(&out.stderr).into_owned())
    };
    let well = |name: &str, text: &str| {
        std::fs::write(dir.path().join(name), text).unwrap();
        run(&["simulate", "--well", name])
    };
    let (code, said) = well(
        "params.toml",
        "sample_hz = 20\n[[segment]]\nduration_s = 10\nlaw = \"m2\"\nparams = [1, 2]\nomega_rpm = 60\n",
    );
    assert_eq!(code, Some(2));
    assert!(
        said.contains("params.toml:5:10: `params`: law m2 takes 3 parameters"),
        "{said}"
    );
    let (code, said) = well(
        "missing.toml",
        "sample_hz = 20\n[[segment]]\nlaw = \"m2\"\nomega_rpm = 60\n",
    );
    assert_eq!(code, Some(2));
    assert!(
        said.contains("missing field `duration_s`") && !said.contains("--"),
        "{said}"
    );

    let text = std::fs::read_to_string(dir.path().join("rec.csv")).unwrap();
    let mut lines = text.lines();
    std::fs::write(dir.path().join("header.csv"), format!("{}\n", lines.next().unwrap())).unwrap();
    let short: Vec<&str> = text.lines().take(41).collect();
    std::fs::write(dir.path().join("short.csv"), short.join("\n") + "\n").unwrap();
    let (code, said) = run(&["watch", "header.csv", "--backend", "cpu"]);
    assert_eq!(code, Some(0));
    assert!(said.contains("header.csv: no data row: nothing to watch"), "{said}");
    let (code, said) = run(&["watch", "short.csv", "--backend", "cpu"]);
    assert_eq!(code, Some(0));
    assert!(
        said.contains("short.csv ended before a window of 10 s was complete"),
        "{said}"
    );

    let mut child = bin()
        .current_dir(dir.path())
        .args([
            "stability",
            "--law",
            "m2",
            "--params",
            "13,6.5,0.3",
            "--structure",
            "fe",
            "--dp-elements",
            "999",
        ])
        .stderr(std::process::Stdio::piped())
        .stdout(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let mut first = String::new();
    std::io::BufRead::read_line(&mut std::io::BufReader::new(child.stderr.take().unwrap()), &mut first).unwrap();
    child.kill().unwrap();
    child.wait().unwrap();
    assert!(
        first.starts_with("note: the critical bit damping of the 1000-element string: about 250 eigenvalue solves"),
        "{first}"
    );

    let (code, said) = run(&[
        "evidence",
        "rec.csv",
        "--laws",
        "m2",
        "--particles",
        "60",
        "--islands",
        "2",
        "--out",
        "ev",
        "-q",
    ]);
    assert_eq!(code, Some(0), "{said}");
    let copy = dir.path().join("copy");
    std::fs::create_dir(&copy).unwrap();
    for entry in std::fs::read_dir(dir.path().join("ev")).unwrap() {
        let entry = entry.unwrap();
        // As `cp` copies: the contents without bitrock's marks.
        std::fs::write(copy.join(entry.file_name()), std::fs::read(entry.path()).unwrap()).unwrap();
    }
    let (code, said) = run(&["check-selection", "copy", "--replicates", "1"]);
    assert_eq!(code, Some(2), "{said}");
    assert!(
        said.contains("holds files bitrock did not write") && !said.contains("replicate"),
        "{said}"
    );
}
