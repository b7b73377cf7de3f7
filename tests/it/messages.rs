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
