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

#[test]
fn a_simulation_beyond_a_days_work_on_this_machine_is_refused_at_once() {
    let tmp = tempfile::tempdir().unwrap();
    let started = std::time::Instant::now();
    assert_refused(
        run_in(
            tmp.path(),
            &[
                "simulate",
                "--law",
                "m2",
                "--params",
                "13,6.5,0.3",
                "--omega-rpm",
                "60",
                "--dt-s",
                "1e-12",
                "--duration-s",
                "1",
                "-o",
                "x.csv",
            ],
        ),
        &["--dt-s", "1.000e12 steps", "on this machine"],
    );
    // Refused on the pace of its first steps, not after a day.
    assert!(started.elapsed().as_secs() < 30, "{:?}", started.elapsed());
    assert!(!tmp.path().join("x.csv").exists());
}

#[test]
fn a_measured_pace_refuses_what_cannot_finish_and_reports_what_can() {
    // 10¹² units at the pace of this loop (well under 10⁹ per second with the sleeps).
    let mut reports = 0;
    let mut report = |_: u64, _: u64| reports += 1;
    let mut pace = bitrock::limits::Pace::new("dt_s", "a test".into(), 1_000_000_000_000, &mut report);
    let refused = (0..100_000).find_map(|_| {
        std::thread::sleep(std::time::Duration::from_micros(50));
        pace.advance(1000).err()
    });
    let e = refused.expect("refused once the pace was measured").to_string();
    assert!(
        e.starts_with("`dt_s`: a test would take about") && e.contains("on this machine"),
        "{e}"
    );
    // Work that fits is never refused, whatever its pace.
    let mut quiet = |_: u64, _: u64| {};
    let mut pace = bitrock::limits::Pace::new("dt_s", "a test".into(), 50_000, &mut quiet);
    for _ in 0..50 {
        std::thread::sleep(std::time::Duration::from_millis(1));
        pace.advance(1000).unwrap();
    }
}

#[test]
fn a_finite_element_strings_cost_is_measured_and_bounded_by_it() {
    use bitrock::stability::fe::DrillString;
    let small = DrillString::default();
    assert_eq!(small.estimate_seconds(250.0), 0.0, "a small string is not measured");
    let big = DrillString {
        dp_elements: 600,
        bha_elements: 60,
        ..DrillString::default()
    };
    let medium = DrillString {
        dp_elements: 150,
        bha_elements: 15,
        ..DrillString::default()
    };
    let (b, m) = (big.estimate_seconds(250.0), medium.estimate_seconds(250.0));
    // The cube of the size: 4 × the elements, 64 × the time, times the ratio of two timings of
    // the same 60-DOF probe (noise on a busy machine, far from 8×).
    assert!(b > 8.0 * m && m > 0.0, "{b} {m}");
    // What could not finish in a day is refused naming the larger element count.
    let e = big.check_cost(1e7).unwrap_err().to_string();
    assert!(
        e.starts_with("`dp_elements`: ") && e.contains("660-DOF") && e.contains("on this machine"),
        "{e}"
    );
    assert!(medium.check_cost(250.0).is_ok());
}

#[test]
fn every_settings_file_is_bounded_before_it_is_read() {
    let tmp = tempfile::tempdir().unwrap();
    // Devices: refused naming the file, before a byte is read (no memory exhausted).
    for (flag, what) in [("--law-file", "not a law file"), ("--prior", "not a prior file")] {
        assert_refused(
            run_in(
                tmp.path(),
                &["abc", "--out", "R", "--backend", "cpu", flag, "/dev/zero"],
            ),
            &["/dev/zero", what],
        );
    }
    assert_refused(
        run_in(tmp.path(), &["fe", "--fe-file", "/dev/zero"]),
        &["/dev/zero", "not a drill-string file"],
    );
    // Too large: refused by its size, before it is read.
    std::fs::write(tmp.path().join("big.toml"), vec![b'#'; 100_000]).unwrap();
    assert_refused(
        run_in(tmp.path(), &["law", "big.toml"]),
        &["big.toml", "larger than 64.0 kB", "law file"],
    );
    std::fs::write(tmp.path().join("prior.toml"), vec![b'#'; 1_100_000]).unwrap();
    assert_refused(
        run_in(
            tmp.path(),
            &["abc", "--out", "R", "--backend", "cpu", "--prior", "prior.toml"],
        ),
        &["prior.toml", "larger than 1.0 MB"],
    );
    assert!(!tmp.path().join("R").exists());
    // A named pipe no process writes to is read as empty, at once: never a hang.
    let fifo = tmp.path().join("law.fifo");
    assert!(
        std::process::Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .unwrap()
            .success()
    );
    let started = std::time::Instant::now();
    let (code, _, err) = run_in(tmp.path(), &["law", "law.fifo"]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("law.fifo"), "{err}");
    assert!(started.elapsed().as_secs() < 30);
    // The same for the library's reader of the shape cache, which must be a regular file.
    let e = bitrock::eval::gpu::tune::read_cache(&fifo).unwrap_err().to_string();
    assert!(e.contains("not a regular file"), "{e}");
}

#[test]
fn the_watch_and_the_evidence_bound_every_count_and_rate_before_any_work() {
    let tmp = tempfile::tempdir().unwrap();
    std::fs::write(tmp.path().join("rec.csv"), bitrock::data::DEMO_CSV).unwrap();
    let cpu = ["--backend", "cpu"];
    let refused = |args: &[&str], needles: &[&str]| {
        let args: Vec<&str> = args.iter().chain(&cpu).copied().collect();
        assert_refused(run_in(tmp.path(), &args), needles);
    };
    // Windows that repeat the same rows, as many per second of record as the step is short.
    refused(
        &[
            "watch",
            "rec.csv",
            "--window-s",
            "1e-300",
            "--step-s",
            "1e-300",
            "--out",
            "W",
        ],
        &[
            "--step-s",
            "1e-300 s is shorter than the record's sample period",
            "repeat the same rows",
        ],
    );
    // A replay slower than a second of record per day.
    refused(
        &["watch", "rec.csv", "--replay-speed", "1e-300"],
        &[
            "--replay-speed",
            "1e-300 replays each second of record in",
            "more than a day",
        ],
    );
    // Samplers beyond memory, in the watch's windows and in the evidence.
    // (Sizes past any machine's memory, not only this one's: 153.6 TB, 76.8 TB.)
    refused(
        &["watch", "rec.csv", "--particles", "100000000000", "--out", "W"],
        &["--particles", "8.000e11 particles", "memory"],
    );
    refused(
        &["evidence", "rec.csv", "--islands", "100000000", "--out", "E"],
        &["--islands", "islands per law and start", "memory"],
    );
    // Refinements whose last round would not fit, and more rounds than the doubling allows: the
    // first round an eighth of the memory here (the default islands of four laws from both
    // starts), the last round, 64 times the first, eight times the memory, whatever the machine.
    let available = bitrock::limits::available_memory_bytes().expect("this machine's memory") as f64;
    let islands = (bitrock::abc::evidence::EvidenceConfig::default().islands * 4 * 2) as f64;
    let particles = ((available / 8.0 / (islands * bitrock::abc::evidence::BYTES_PER_PARTICLE)) as u64).to_string();
    refused(
        &[
            "evidence",
            "rec.csv",
            "--particles",
            &particles,
            "--refine-rounds",
            "6",
            "--out",
            "E",
        ],
        &["--refine-rounds", "6 refinement rounds (64 times the", "memory"],
    );
    refused(
        &["evidence", "rec.csv", "--refine-rounds", "7", "--out", "E"],
        &["--refine-rounds", "at most 6"],
    );
    // A check of more records than memory keeps, refused before the evidence itself.
    refused(
        &["evidence", "rec.csv", "--check", "100000000000", "--out", "E"],
        &["--check", "synthetic records", "of memory"],
    );
    // The demo's check too, before its runs.
    refused(
        &["demo", "--check", "100000000000", "--out", "D"],
        &["--check", "synthetic records", "of memory"],
    );
    for made in ["W", "E", "D"] {
        assert!(!tmp.path().join(made).exists(), "{made}");
    }
}
