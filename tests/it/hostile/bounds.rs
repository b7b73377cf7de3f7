//! Every input that sizes memory, a loop or a file read is bounded before work, with the bound
//! named: DATA is a regular file (sized against memory) or a pipe read up to a cap; grids,
//! candidates and replicates are estimated against memory and a day's work.

use super::{assert_refused, run_in, small_run};
use std::io::Write;
use std::process::Stdio;

#[test]
fn data_that_is_a_device_or_a_directory_is_refused_before_a_byte_is_read() {
    let tmp = tempfile::tempdir().unwrap();
    for data in ["/dev/zero", "/dev/urandom"] {
        assert_refused(
            run_in(tmp.path(), &["fit", data]),
            &[data, "a device or socket", "not a record"],
        );
        assert_refused(
            run_in(tmp.path(), &["abc", data, "--out", "R", "--backend", "cpu"]),
            &[data, "not a record"],
        );
    }
    assert!(!tmp.path().join("R").exists());
    std::fs::create_dir(tmp.path().join("records")).unwrap();
    assert_refused(run_in(tmp.path(), &["fit", "records"]), &["records", "a directory"]);
}

#[test]
fn a_record_from_a_pipe_reads_like_the_file() {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("rec.csv");
    std::fs::write(&path, bitrock::data::DEMO_CSV).unwrap();
    let (code, from_file, err) = run_in(tmp.path(), &["fit", "rec.csv", "--json"]);
    assert_eq!(code, 0, "{err}");
    let mut child = crate::support::bin()
        .current_dir(tmp.path())
        .args(["fit", "/dev/stdin", "--json"])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    child
        .stdin
        .take()
        .unwrap()
        .write_all(bitrock::data::DEMO_CSV.as_bytes())
        .unwrap();
    let out = child.wait_with_output().unwrap();
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    let fits = |text: &str| serde_json::from_str::<serde_json::Value>(text).unwrap()["fits"].clone();
    assert_eq!(fits(&String::from_utf8_lossy(&out.stdout)), fits(&from_file));
}

#[test]
fn sizes_beyond_memory_or_a_days_work_are_refused_naming_the_flag() {
    let tmp = tempfile::tempdir().unwrap();
    assert_refused(
        run_in(
            tmp.path(),
            &["parity", "--candidates", "18446744073709551615", "--laws", "m2"],
        ),
        &["--candidates", "memory"],
    );
    // A grid of 10^10 cells: refused on memory before any cell is computed.
    assert_refused(
        run_in(
            tmp.path(),
            &[
                "stability",
                "--law",
                "m2",
                "--params",
                "13,6.5,0.3",
                "--omega-rpm",
                "20:220:100000",
                "--wob-kn",
                "20:700:100000",
                "--backend",
                "cpu",
            ],
        ),
        &["--omega-rpm/--wob-kn", "10000000000 cells", "memory"],
    );
    // A modest grid with samples that no machine computes in a day.
    assert_refused(
        run_in(
            tmp.path(),
            &[
                "stability",
                "--law",
                "m2",
                "--params",
                "13,6.5,0.3",
                "--omega-rpm",
                "20:220:1000",
                "--wob-kn",
                "20:700:1000",
                "--samples",
                "100000000000",
                "--backend",
                "cpu",
            ],
        ),
        &["--samples", "a day's work"],
    );
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
                "--dt-s",
                "1e-15",
            ],
        ),
        &["--dt-s", "a day's work"],
    );
    assert_eq!(small_run(tmp.path(), "R", &[]).0, 0);
    assert_refused(
        run_in(
            tmp.path(),
            &[
                "check-selection",
                "R",
                "--replicates",
                "18446744073709551615",
                "--backend",
                "cpu",
                "-q",
            ],
        ),
        &["--replicates"],
    );
    assert!(!tmp.path().join("R/selection").exists());
}
