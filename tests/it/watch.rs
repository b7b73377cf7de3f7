//! `bitrock watch` on simulated wells (`bitrock simulate --well`): windows cut by the record's
//! time stamps whatever its pace, the generating formation's law found, changes of formation
//! noticed where they are and nowhere else, and what a stream gets wrong said, not fatal.

use crate::support::{bin, outcome};
use std::path::Path;

/// m2 at the paper's estimate for 90 s, then m3 for 90 s, sampled at 20 Hz with noise, at a
/// top-drive speed where the bit sticks and slips.
const WELL: &str = "sample_hz = 20\nnoise_torque_knm = 0.3\nnoise_speed_rpm = 0.5\nseed = 5\n\n\
[[segment]]\nname = \"claystone\"\nduration_s = 90\nlaw = \"m2\"\nomega_rpm = 60\n\n\
[[segment]]\nname = \"sandstone\"\nduration_s = 90\nlaw = \"m3\"\nomega_rpm = 60\n";
const BOUNDARY_S: f64 = 90.0;

fn simulate_well(dir: &Path) -> std::path::PathBuf {
    simulate(dir, "well", WELL)
}

/// The record `bitrock simulate --well` makes of the well file `text`, as `dir/name.csv`.
fn simulate(dir: &Path, name: &str, text: &str) -> std::path::PathBuf {
    let well = dir.join(format!("{name}.toml"));
    std::fs::write(&well, text).unwrap();
    let record = dir.join(format!("{name}.csv"));
    let (code, _, stderr) = outcome(bin().args(["simulate", "--well"]).arg(&well).arg("-o").arg(&record));
    assert_eq!(code, 0, "{stderr}");
    record
}

/// The record `bitrock simulate` makes of m2 at its paper estimate at 60 rpm for `duration_s`
/// at 20 Hz, with the further flags `extra` (noise, seed), as `dir/name.csv`.
fn m2_record(dir: &Path, name: &str, duration_s: &str, extra: &[&str]) -> std::path::PathBuf {
    let record = dir.join(format!("{name}.csv"));
    let (code, _, stderr) = outcome(
        bin()
            .args([
                "simulate",
                "--law",
                "m2",
                "--omega-rpm",
                "60",
                "--duration-s",
                duration_s,
            ])
            .args(["--sample-hz", "20"])
            .args(extra)
            .arg("-o")
            .arg(&record),
    );
    assert_eq!(code, 0, "{stderr}");
    record
}

/// `bitrock watch --json --laws m2,m3 --backend cpu`.
fn watch_command() -> std::process::Command {
    let mut command = bin();
    command.args(["watch", "--json", "--laws", "m2,m3", "--backend", "cpu"]);
    command
}

/// Updates without their latencies (which are the clock's).
fn without_latency(updates: &[serde_json::Value]) -> Vec<serde_json::Value> {
    updates
        .iter()
        .map(|u| {
            let mut u = u.clone();
            u.as_object_mut().unwrap().remove("latency_s");
            u
        })
        .collect()
}

/// The JSON lines of [`watch_command`] with `args`.
fn watch(args: &[&str]) -> Vec<serde_json::Value> {
    let (code, stdout, stderr) = outcome(watch_command().args(args));
    assert_eq!(code, 0, "{stderr}");
    stdout.lines().map(|l| serde_json::from_str(l).unwrap()).collect()
}

/// Windows of 20 s every 10 s.
const WINDOWS: [&str; 4] = ["--window-s", "20", "--step-s", "10"];

/// The updates of `--particles 100` with [`WINDOWS`] on the well of [`WELL`] read as a file:
/// what a stream, a folder of WITSML chunks and a served page are each compared with, watched
/// once for all of them (the well's record is the same to the byte wherever it is made).
fn well_windows() -> &'static [serde_json::Value] {
    static UPDATES: std::sync::OnceLock<Vec<serde_json::Value>> = std::sync::OnceLock::new();
    UPDATES.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let record = simulate_well(dir.path());
        watch(&[&WINDOWS[..], &["--particles", "100", record.to_str().unwrap()]].concat())
    })
}

#[test]
fn the_watch_finds_each_formations_law_and_the_change_between_them() {
    let dir = tempfile::tempdir().unwrap();
    let record = simulate_well(dir.path());
    let whole = watch(&[&WINDOWS[..], &[record.to_str().unwrap()]].concat());
    // Windows of 20 s every 10 s over 180 s: starts 0, 10, …, 160.
    assert_eq!(whole.len(), 17);
    let end = |u: &serde_json::Value| u["end_s"].as_f64().unwrap();
    let start = |u: &serde_json::Value| u["start_s"].as_f64().unwrap();
    for u in &whole {
        assert!(u["uninformative"].is_null(), "{u}");
        let laws = u["laws"].as_array().unwrap();
        let total: f64 = laws.iter().map(|l| l["probability"].as_f64().unwrap()).sum();
        assert!((total - 1.0).abs() < 1e-9 && laws.iter().all(|l| l["probability"].as_f64().unwrap() >= 0.01 - 1e-12));
        let advice = &u["advice"];
        assert!(
            (advice["omega_rpm"].as_f64().unwrap() - 60.0).abs() < 1e-6,
            "the top-drive column: {advice}"
        );
        assert!(advice["words"].as_str().unwrap().contains("rpm"));
    }
    // Inside the first formation: m2 at the parameters that made it (in the record's kN·m),
    // and no change declared.
    for u in whole.iter().filter(|u| end(u) <= BOUNDARY_S) {
        assert_eq!(u["most_probable"], "m2", "{u}");
        assert_eq!(u["change"], false, "{u}");
        // The window's own answer, in the evidence's words: the law of the window's largest
        // P(m | window) over the next.
        let answer = &u["answer"];
        assert_eq!(answer["method"], "evidence", "{u}");
        let laws = u["laws"].as_array().unwrap();
        let first = laws
            .iter()
            .max_by(|a, b| {
                a["window_probability"]
                    .as_f64()
                    .unwrap()
                    .total_cmp(&b["window_probability"].as_f64().unwrap())
            })
            .unwrap();
        assert_eq!(answer["law"], first["law"], "{u}");
        let sentence = answer["sentence"].as_str().unwrap();
        assert!(
            sentence.starts_with(&format!("{} over ", first["law"].as_str().unwrap())),
            "{sentence}"
        );
        let m2 = &u["laws"][0];
        for key in ["mean", "map"] {
            let estimate: Vec<f64> = m2[key]
                .as_array()
                .unwrap()
                .iter()
                .map(|v| v.as_f64().unwrap())
                .collect();
            for (got, truth) in estimate.iter().zip([13.0, 6.5, 0.3]) {
                assert!(
                    (got / truth - 1.0).abs() < 0.1,
                    "m2 {key} {estimate:?} against the paper's (13, 6.5, 0.3)"
                );
            }
        }
        // Kish's ESS of the law's weighted particles: at least one, at most all (2 × 300).
        let ess = m2["ess"].as_f64().unwrap();
        assert!((1.0..=600.0 + 1e-9).contains(&ess), "ess {ess}");
    }
    // The change is declared once, by a window that holds the boundary or by the next one.
    let declared: Vec<f64> = whole.iter().filter(|u| u["change"] == true).map(start).collect();
    let near = |s: f64| (BOUNDARY_S - 20.0 + 1e-9..=BOUNDARY_S).contains(&s);
    assert!(
        declared.len() == 1 && near(declared[0]),
        "declared once, by a window that holds the boundary or the one just after, nowhere else: {declared:?}"
    );
    // Inside the second formation, once the change is behind: m3.
    for u in whole.iter().filter(|u| start(u) >= BOUNDARY_S + 10.0) {
        assert_eq!(u["most_probable"], "m3", "{u}");
    }
    // The same windows, the same numbers, replayed at 100 times real time.
    let replayed = watch(&[&WINDOWS[..], &[record.to_str().unwrap(), "--replay-speed", "100"]].concat());
    assert_eq!(without_latency(&whole), without_latency(&replayed));

    // The paper's way, every window's evidence from the boxes: the same law ranked first in
    // every window, at more candidates (each window above starts from the one before's
    // posterior, its improbable law with fewer particles; measured: 0.42 of the candidates).
    let cold = watch(&[&WINDOWS[..], &[record.to_str().unwrap(), "--cold-start"]].concat());
    assert_eq!(cold.len(), whole.len());
    for (warm, cold) in whole.iter().zip(&cold) {
        assert_eq!(
            warm["most_probable"], cold["most_probable"],
            "window {}",
            warm["window"]
        );
    }
    let candidates = |v: &[serde_json::Value]| v.iter().map(|u| u["candidates_scored"].as_u64().unwrap()).sum::<u64>();
    assert!(
        candidates(&whole) * 2 < candidates(&cold),
        "warm {} against cold {}",
        candidates(&whole),
        candidates(&cold)
    );
    assert_eq!(
        whole[0]["candidates_scored"], cold[0]["candidates_scored"],
        "the first window starts cold"
    );
}

/// The stored windows of a watch directory, without their latencies (which are the clock's).
fn stored(dir: &Path) -> (Vec<serde_json::Value>, bitrock::watch::store::StoredWatch) {
    let watch = bitrock::watch::store::read(dir).unwrap();
    let updates: Vec<serde_json::Value> = watch.updates.iter().map(|u| serde_json::to_value(u).unwrap()).collect();
    (without_latency(&updates), watch)
}

/// Starts a replayed watch into `out` and waits for `lines` of its JSON lines.
fn watch_until(record: &Path, out: &Path, lines: usize) -> (std::process::Child, Vec<String>) {
    use std::io::BufRead;
    let mut child = watch_command()
        .args(["--particles", "100"])
        .args(WINDOWS)
        .arg(record)
        .args(["--replay-speed", "20", "--out"])
        .arg(out)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let mut reader = std::io::BufReader::new(child.stdout.take().unwrap());
    let mut read = Vec::new();
    while read.len() < lines {
        let mut line = String::new();
        assert!(reader.read_line(&mut line).unwrap() > 0, "the watch ended early");
        read.push(line);
    }
    // Keep the pipe open (a closed one would end the watch) until the caller is done.
    std::mem::forget(reader);
    (child, read)
}

#[test]
fn a_watch_killed_or_stopped_goes_on_from_its_directory_as_if_it_never_stopped() {
    let dir = tempfile::tempdir().unwrap();
    let record = simulate_well(dir.path());
    let record_arg = record.to_str().unwrap();
    let whole_dir = dir.path().join("whole");
    let args = |out: &Path, extra: &[&str]| -> Vec<String> {
        let mut v: Vec<String> = ["--particles", "100"].iter().map(|s| s.to_string()).collect();
        v.extend(WINDOWS.iter().map(|s| s.to_string()));
        v.extend([record_arg.to_string(), "--out".into(), out.to_str().unwrap().into()]);
        v.extend(extra.iter().map(|s| s.to_string()));
        v
    };
    let as_str = |v: &[String]| v.iter().map(String::as_str).collect::<Vec<_>>().join("\u{1}");
    let whole_args = args(&whole_dir, &[]);
    let printed = watch(&whole_args.iter().map(String::as_str).collect::<Vec<_>>());
    let (whole, whole_store) = stored(&whole_dir);
    assert_eq!(whole.len(), 17);
    assert_eq!(without_latency(&printed), whole, "stored as said");

    // Killed (SIGKILL) after its third window: the directory holds the windows it said, and
    // the resumed watch gives the rest, the same numbers as the watch that never stopped.
    let killed = dir.path().join("killed");
    let (mut child, said) = watch_until(&record, &killed, 3);
    child.kill().unwrap();
    child.wait().unwrap();
    let (before, _) = stored(&killed);
    assert!(
        before.len() >= 3 && before.len() < 17,
        "{} windows stored",
        before.len()
    );
    let said: Vec<serde_json::Value> = said.iter().map(|l| serde_json::from_str(l).unwrap()).collect();
    assert_eq!(without_latency(&said), before[..3]);
    let resumed = watch(
        &args(&killed, &["--resume"])
            .iter()
            .map(String::as_str)
            .collect::<Vec<_>>(),
    );
    assert_eq!(
        resumed.len(),
        17 - before.len(),
        "only the windows not stored are given"
    );
    let (after, after_store) = stored(&killed);
    assert_eq!(
        after, whole,
        "a resumed watch's windows are those of one that never stopped"
    );
    // (As JSON: the evidence's particles carry no ρ, NaN, which equals nothing.)
    let carried = |w: &bitrock::watch::store::StoredWatch| serde_json::to_string(&w.carried).unwrap();
    assert!(
        carried(&after_store) == carried(&whole_store),
        "a resumed watch carries what one that never stopped carries"
    );

    // Ctrl-C (SIGINT): the window in progress is stored, the status is 130, and resuming
    // gives the rest.
    let stopped = dir.path().join("stopped");
    let (mut child, _) = watch_until(&record, &stopped, 2);
    let (code, _, _) = outcome(std::process::Command::new("kill").args(["-INT", &child.id().to_string()]));
    assert_eq!(code, 0);
    let status = child.wait().unwrap();
    assert_eq!(status.code(), Some(130), "{status:?}");
    let (before, _) = stored(&stopped);
    assert!(
        before.len() >= 2 && before.len() < 17,
        "{} windows stored",
        before.len()
    );
    watch(
        &args(&stopped, &["--resume"])
            .iter()
            .map(String::as_str)
            .collect::<Vec<_>>(),
    );
    assert_eq!(stored(&stopped).0, whole);

    // Another watch's settings, an existing watch without `--resume`, and a resume without
    // a directory are refused, naming the flag, with nothing written.
    let refused = [
        (
            args(&killed, &["--resume", "--forgetting", "0.9"]),
            "--forgetting: is 0.9 here, 0.5",
        ),
        (args(&killed, &["--resume", "--particles", "120"]), "--particles"),
        (
            args(&killed, &["--resume", "--cold-start"]),
            "--cold-start: is true here, false",
        ),
        (
            args(&killed, &["--resume", "--structure", "fe"]),
            "--structure: differs from the one the watch in",
        ),
        (args(&killed, &[]), "--resume"),
    ];
    for (flags, named) in refused {
        let (code, _, stderr) = outcome(watch_command().args(&flags));
        assert_eq!(code, 2, "{}: {stderr}", as_str(&flags));
        assert!(stderr.contains(named) && !stderr.contains('{'), "{stderr}");
        assert_eq!(stored(&killed).0, whole);
    }
    let (code, _, stderr) = outcome(bin().args(["watch", record_arg, "--resume"]));
    assert_eq!(code, 2);
    assert!(stderr.contains("--out"), "{stderr}");

    // The report along the record: the change where the watch declared it, the stretches'
    // laws, and the figures.
    let report = dir.path().join("report");
    let (code, _, stderr) = outcome(bin().arg("report").arg(&killed).arg("--out").arg(&report));
    assert_eq!(code, 0, "{stderr}");
    let md = std::fs::read_to_string(report.join("report.md")).unwrap();
    let change = whole.iter().find(|u| u["change"] == true).unwrap();
    let row = format!(
        "| {} | {}–{} |",
        change["window"],
        change["start_s"].as_f64().unwrap(),
        change["end_s"].as_f64().unwrap()
    );
    assert!(md.contains(&row), "the change's row {row} in:\n{md}");
    let stretches = md.split("## Stretches").nth(1).unwrap().split("##").next().unwrap();
    let laws: Vec<&str> = stretches
        .lines()
        .filter(|l| l.starts_with("| ") && !l.starts_with("| from"))
        .filter_map(|l| l.split('|').nth(4).map(str::trim))
        .collect();
    assert_eq!(laws, ["m2", "m3"], "{stretches}");
    for stem in [
        "watch-probabilities",
        "watch-risk",
        "watch-parameters-m2",
        "watch-parameters-m3",
    ] {
        for ext in ["svg", "png"] {
            let file = report.join("figures").join(format!("{stem}.{ext}"));
            assert!(std::fs::metadata(&file).unwrap().len() > 1000, "{}", file.display());
        }
    }
    let (code, _, stderr) = outcome(
        bin()
            .arg("report")
            .arg(&killed)
            .arg(&whole_dir)
            .arg("--out")
            .arg(&report),
    );
    assert_eq!(code, 2, "{stderr}");
    assert!(stderr.contains("watch directory"), "{stderr}");
}

/// Serves `connections` one after the other on a local port (each: its text, then closed;
/// the last held open until the watch is done); returns the port.
fn serve(connections: Vec<String>) -> u16 {
    use std::io::Write;
    let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let port = listener.local_addr().unwrap().port();
    std::thread::spawn(move || {
        let last = connections.len() - 1;
        for (k, text) in connections.into_iter().enumerate() {
            let (mut stream, _) = listener.accept().unwrap();
            let _ = stream.write_all(text.as_bytes());
            if k == last {
                std::thread::sleep(std::time::Duration::from_secs(600));
            }
        }
    });
    port
}

/// The first `n` JSON lines of `bitrock watch` on a feed with `args`, then Ctrl-C; and its
/// standard error.
fn watch_feed(port: u16, args: &[&str], n: usize) -> (Vec<serde_json::Value>, String) {
    use std::io::{BufRead, Read};
    let mut child = watch_command()
        .args(["--particles", "100"])
        .args(WINDOWS)
        .arg(format!("tcp://127.0.0.1:{port}"))
        .args(args)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut reader = std::io::BufReader::new(child.stdout.take().unwrap());
    let mut lines = Vec::new();
    while lines.len() < n {
        let mut line = String::new();
        assert!(reader.read_line(&mut line).unwrap() > 0, "the watch ended early");
        lines.push(serde_json::from_str(&line).unwrap());
    }
    let (code, _, _) = outcome(std::process::Command::new("kill").args(["-INT", &child.id().to_string()]));
    assert_eq!(code, 0);
    assert_eq!(child.wait().unwrap().code(), Some(130));
    let mut stderr = String::new();
    child.stderr.take().unwrap().read_to_string(&mut stderr).unwrap();
    (lines, stderr)
}

#[test]
fn a_tcp_feed_of_csv_or_wits_gives_the_file_s_windows_through_a_dropped_connection() {
    let dir = tempfile::tempdir().unwrap();
    let record = simulate_well(dir.path());
    let text = std::fs::read_to_string(&record).unwrap();
    let mut lines = text.lines();
    let header = lines.next().unwrap().to_string();
    let rows: Vec<&str> = lines.collect();
    let whole = well_windows();
    // A feed never ends: its last window (which ends with the record) is not given.
    let n = whole.len() - 1;

    // CSV lines; the connection drops a third of the way (mid-line) and the header comes
    // again with the next one.
    let cut = rows.len() / 3;
    let first = format!("{header}\n{}\n{}", rows[..cut].join("\n"), &rows[cut][..5]);
    let second = format!("{header}\n{}\n", rows[cut..].join("\n"));
    let (fed, stderr) = watch_feed(serve(vec![first, second]), &[], n);
    assert_eq!(without_latency(&fed), without_latency(&whole[..n]));
    assert!(
        stderr.contains("the feed closed the connection") && stderr.contains("connected again"),
        "{stderr}"
    );

    // The same record as WITS level-0 blocks (the time in an item of seconds, the speeds in
    // rpm, the torque in kN·m, the weight on bit in kN), with another record's blocks between.
    let mut wits = String::new();
    for (k, row) in rows.iter().enumerate() {
        let v: Vec<&str> = row.split(',').collect();
        wits.push_str(&format!(
            "&&\n0901{}\n0902{}\n0118{}\n0116{}\n0120{}\n!!\n",
            v[0], v[1], v[2], v[3], v[4]
        ));
        if k % 50 == 0 {
            wits.push_str("&&\n0108 1234.5\n0113 12.0\n!!\n");
        }
    }
    let items = ["--wits-items", "seconds=0901,speed=0902,top_drive=0120"];
    let units = ["--torque-unit", "knm", "--wob-unit", "kn"];
    let (fed, stderr) = watch_feed(serve(vec![wits.clone()]), &[&items[..], &units[..]].concat(), n);
    assert_eq!(without_latency(&fed), without_latency(&whole[..n]));
    // The torque's item is record 01's surface average: read as the bit's, that is said; the
    // speed's is a downhole item.
    assert_eq!(
        stderr
            .matches("item 0118 is WITS record 01's rotary torque, a surface average")
            .count(),
        1,
        "{stderr}"
    );
    assert!(
        stderr.contains("named with --wits-items") && !stderr.contains("item 0902 is"),
        "{stderr}"
    );

    // WITS names no units: the torque's is asked for.
    let (code, _, stderr) = outcome(
        bin()
            .args(["watch", "--laws", "m2"])
            .arg(format!("tcp://127.0.0.1:{}", serve(vec![wits])))
            .args(items),
    );
    assert_eq!(code, 2, "{stderr}");
    assert!(stderr.contains("--torque-unit"), "{stderr}");
    let (code, _, stderr) = outcome(bin().args(["watch", "tcp://127.0.0.1:1", "--follow"]));
    assert_eq!(code, 2, "{stderr}");
    assert!(stderr.contains("--follow"), "{stderr}");
}

#[test]
fn a_stream_s_bad_lines_are_skipped_and_a_record_without_time_refused() {
    let dir = tempfile::tempdir().unwrap();
    let feed = dir.path().join("feed.csv");
    let mut text = String::from("time_s,bit_speed_rpm,torque_knm\n");
    for k in 0..400 {
        let t = k as f64 * 0.1;
        let w = 40.0 + 30.0 * (t * 0.7).sin().abs();
        text.push_str(&format!("{t:.1},{w:.3},{:.4}\n", 6.0 + 6.0 * (-0.05 * w).exp()));
        if k == 150 {
            text.push_str("garbage,line\n");
        }
        if k == 200 {
            text.push_str("10.0,50,7\n"); // time runs backwards
        }
    }
    std::fs::write(&feed, &text).unwrap();
    let (code, stdout, stderr) = outcome(
        bin()
            .args([
                "watch",
                "--laws",
                "m2",
                "--window-s",
                "20",
                "--step-s",
                "10",
                "--backend",
                "cpu",
                "--particles",
                "100",
            ])
            .arg(&feed),
    );
    assert_eq!(code, 0, "{stderr}");
    assert!(
        stderr.contains("feed.csv:153") && stderr.contains("line skipped"),
        "{stderr}"
    );
    assert!(stderr.contains("time runs backwards"), "{stderr}");
    assert!(
        stdout.contains("3 windows of 20 s every 10 s") && stdout.contains("1 lines skipped"),
        "{stdout}"
    );

    // A window of torques of the wrong sign (which no law describes) or whose torques are all
    // zero says so; the windows around it are watched as before.
    let mut text = String::from("time_s,bit_speed_rpm,torque_knm\n");
    for k in 0..600 {
        let t = k as f64 * 0.1;
        let w = 40.0 + 30.0 * (t * 0.7).sin().abs();
        let torque = 6.0 + 6.0 * (-0.05 * w).exp();
        let torque = match t {
            t if (20.0..40.0).contains(&t) => -torque,
            t if (40.0..60.0).contains(&t) => 0.0,
            _ => torque,
        };
        text.push_str(&format!("{t:.1},{w:.3},{torque:.4}\n"));
    }
    std::fs::write(&feed, &text).unwrap();
    let updates = watch(&[
        "--window-s",
        "20",
        "--step-s",
        "20",
        "--particles",
        "100",
        feed.to_str().unwrap(),
    ]);
    assert_eq!(updates.len(), 3);
    assert!(updates[0]["uninformative"].is_null() && updates[0]["most_probable"] == "m2");
    let why = updates[1]["uninformative"].as_str().unwrap();
    assert!(why.contains("200 of its 200 torques are zero or negative"), "{why}");
    assert!(
        updates[2]["uninformative"].as_str().unwrap().contains("is zero"),
        "{}",
        updates[2]
    );

    std::fs::write(&feed, "bit_speed_rpm,torque_knm\n60,7\n").unwrap();
    let (code, _, stderr) = outcome(bin().args(["watch"]).arg(&feed));
    assert_eq!(code, 2, "{stderr}");
    assert!(stderr.contains("--time-col"), "{stderr}");
    std::fs::write(&feed, "time_s,bit_speed_rpm,torque_knm\n0,60,7\n").unwrap();
    let (code, _, stderr) = outcome(bin().args(["watch", "--window-s", "10", "--step-s", "20"]).arg(&feed));
    assert_eq!(code, 2, "{stderr}");
    assert!(stderr.contains("--step-s"), "{stderr}");
}

#[test]
fn a_well_file_is_one_simulation_and_refuses_the_single_one_s_flags() {
    let dir = tempfile::tempdir().unwrap();
    let record = simulate_well(dir.path());
    let text = std::fs::read_to_string(&record).unwrap();
    assert_eq!(text.lines().count(), 1 + 180 * 20);
    assert!(text.starts_with("time_s,bit_speed_rpm,torque_knm,wob_kn,top_drive_rpm,segment\n"));
    // The record reads as any other (its extra columns are not the fit's).
    let (code, _, stderr) = outcome(bin().args(["fit", "--laws", "m2"]).arg(&record));
    assert_eq!(code, 0, "{stderr}");
    let (code, _, stderr) = outcome(bin().args(["simulate", "--well", "x.toml", "--law", "m2"]));
    assert_eq!(code, 2, "{stderr}");
    assert!(stderr.contains("--law"), "{stderr}");
    std::fs::write(
        dir.path().join("bad.toml"),
        "[[segment]]\nduration_s = 30\nlaw = \"m2\"\nomega = 60\n",
    )
    .unwrap();
    let (code, _, stderr) = outcome(bin().args(["simulate", "--well"]).arg(dir.path().join("bad.toml")));
    assert_eq!(code, 2, "{stderr}");
    assert!(stderr.contains("bad.toml:4:1") && stderr.contains("omega"), "{stderr}");
}

/// The live page's address (HOST:PORT) a `--serve` watch or `bitrock serve` says on its
/// standard error (piped), and the line that says it; the rest of its standard error is read
/// (and dropped) on a thread, so the child never writes to a closed pipe.
fn page_address(child: &mut std::process::Child) -> (String, String) {
    use std::io::BufRead;
    let mut stderr = std::io::BufReader::new(child.stderr.take().unwrap());
    let mut line = String::new();
    loop {
        line.clear();
        assert!(stderr.read_line(&mut line).unwrap() > 0, "no address said");
        if let Some(at) = line.split("the live page is at http://").nth(1) {
            let address = at.split('/').next().unwrap().to_string();
            std::thread::spawn(move || std::io::copy(&mut stderr, &mut std::io::sink()));
            return (address, line);
        }
    }
}

#[test]
fn stalled_viewers_of_the_live_page_change_nothing_and_bad_addresses_are_refused() {
    use std::io::{Read, Write};
    let dir = tempfile::tempdir().unwrap();
    let record = simulate_well(dir.path());
    let args = [
        "--particles",
        "100",
        "--window-s",
        "20",
        "--step-s",
        "10",
        record.to_str().unwrap(),
    ];
    let plain = well_windows();

    // Fifty viewers that ask for the stream and never read it: the watch gives the same
    // windows and ends (their queues drop, their writes time out, none is waited for).
    let mut child = watch_command()
        .args(args)
        .args(["--serve", "127.0.0.1:0"])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let (address, line) = page_address(&mut child);
    assert!(line.contains("this machine only"), "{line}");
    let stalled: Vec<std::net::TcpStream> = (0..50)
        .map(|_| {
            let mut s = std::net::TcpStream::connect(&address).unwrap();
            s.write_all(b"GET /events HTTP/1.1\r\nHost: x\r\n\r\n").unwrap();
            s
        })
        .collect();
    let mut stdout = String::new();
    child.stdout.take().unwrap().read_to_string(&mut stdout).unwrap();
    assert!(child.wait().unwrap().success());
    let served: Vec<serde_json::Value> = stdout.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    assert_eq!(without_latency(&served), without_latency(plain));
    drop(stalled);

    // A port in use, and an address that is none, are refused naming the flag.
    let held = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let busy = held.local_addr().unwrap().to_string();
    for bad in [busy.as_str(), "nonsense"] {
        let (code, _, stderr) = outcome(bin().args(["watch", record.to_str().unwrap(), "--serve", bad]));
        assert_eq!(code, 2, "{stderr}");
        assert!(stderr.contains("--serve") && stderr.contains(bad), "{stderr}");
    }
    let nowhere = dir.path().join("nowhere");
    let (code, _, stderr) = outcome(bin().arg("serve").arg(&nowhere));
    assert_eq!(code, 2, "{stderr}");
    assert!(stderr.contains("not a bitrock watch directory"), "{stderr}");
}

#[test]
fn bitrock_serve_follows_a_watch_directory_while_its_watch_writes_it() {
    use std::io::{Read, Write};
    let dir = tempfile::tempdir().unwrap();
    let record = simulate_well(dir.path());
    let out = dir.path().join("w");
    let mut watch = watch_command()
        .args([
            "--particles",
            "100",
            "--window-s",
            "20",
            "--step-s",
            "10",
            "--replay-speed",
            "15",
        ])
        .arg(&record)
        .arg("--out")
        .arg(&out)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let started = std::time::Instant::now();
    while !out.join(bitrock::watch::store::WATCH_STORE_FILE).is_file() {
        assert!(started.elapsed().as_secs() < 60, "no watch store");
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    let mut serve = bin()
        .args(["serve", out.to_str().unwrap(), "--address", "127.0.0.1:0"])
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let (address, _) = page_address(&mut serve);
    let mut stdout = String::new();
    watch.stdout.take().unwrap().read_to_string(&mut stdout).unwrap();
    assert!(
        watch.wait().unwrap().success(),
        "the watch ends well while it is served"
    );
    let lines: Vec<serde_json::Value> = stdout.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    assert_eq!(lines.len(), 17);
    // The server reads the store every 250 ms: it has every window soon after the watch ends.
    let state = loop {
        let mut s = std::net::TcpStream::connect(&address).unwrap();
        s.write_all(b"GET /state.json HTTP/1.1\r\n\r\n").unwrap();
        let mut answer = String::new();
        s.read_to_string(&mut answer).unwrap();
        let state: serde_json::Value = serde_json::from_str(answer.split("\r\n\r\n").nth(1).unwrap()).unwrap();
        if state["updates"].as_array().unwrap().len() == lines.len() || started.elapsed().as_secs() > 300 {
            break state;
        }
        std::thread::sleep(std::time::Duration::from_millis(100));
    };
    assert_eq!(state["updates"].as_array().unwrap(), &lines);
    assert_eq!(state["view"]["window"], 16);
    assert_eq!(state["meta"]["laws"][1]["name"], "m3");
    // The page says the watch has ended, as its store recorded, and a viewer who comes now
    // gets the history with its end and is let go.
    let get = |path: &str| {
        let mut s = std::net::TcpStream::connect(&address).unwrap();
        s.set_read_timeout(Some(std::time::Duration::from_secs(30))).unwrap();
        s.write_all(format!("GET {path} HTTP/1.1\r\n\r\n").as_bytes()).unwrap();
        let mut answer = String::new();
        s.read_to_string(&mut answer).expect("the server closes the stream");
        answer
    };
    let ended = loop {
        let state: serde_json::Value =
            serde_json::from_str(get("/state.json").split("\r\n\r\n").nth(1).unwrap()).unwrap();
        if !state["ended"].is_null() || started.elapsed().as_secs() > 300 {
            break state["ended"].clone();
        }
        std::thread::sleep(std::time::Duration::from_millis(100));
    };
    assert_eq!(ended["said"], "the watch has ended", "{ended}");
    assert_eq!(ended["windows"], 17);
    let events = get("/events");
    assert!(
        events.contains("event: history") && events.contains("the watch has ended"),
        "{events}"
    );
    let (code, _, _) = outcome(std::process::Command::new("kill").args(["-INT", &serve.id().to_string()]));
    assert_eq!(code, 0);
    assert!(serve.wait().unwrap().success(), "Ctrl-C stops the server cleanly");

    // A watch killed mid-way records no end: its page says it is not running.
    let killed = dir.path().join("killed");
    let (mut child, _) = watch_until(&record, &killed, 1);
    child.kill().unwrap();
    child.wait().unwrap();
    let mut serve = bin()
        .args(["serve", killed.to_str().unwrap(), "--address", "127.0.0.1:0"])
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let (address, _) = page_address(&mut serve);
    let said = loop {
        let mut s = std::net::TcpStream::connect(&address).unwrap();
        s.write_all(b"GET /state.json HTTP/1.1\r\n\r\n").unwrap();
        let mut answer = String::new();
        s.read_to_string(&mut answer).unwrap();
        let state: serde_json::Value = serde_json::from_str(answer.split("\r\n\r\n").nth(1).unwrap()).unwrap();
        if !state["ended"].is_null() || started.elapsed().as_secs() > 300 {
            break state["ended"]["said"].clone();
        }
        std::thread::sleep(std::time::Duration::from_millis(100));
    };
    assert!(
        said.as_str().unwrap().contains("not running and recorded no end"),
        "{said}"
    );
    serve.kill().unwrap();
    serve.wait().unwrap();
}

#[test]
fn the_advice_on_the_finite_element_string_uses_its_critical_bit_damping_and_a_resume_keeps_it() {
    let dir = tempfile::tempdir().unwrap();
    let record = simulate_well(dir.path());
    let (code, fe, stderr) = outcome(bin().args(["fe", "--json"]));
    assert_eq!(code, 0, "{stderr}");
    let fe: serde_json::Value = serde_json::from_str(&fe).unwrap();
    let windows = ["--window-s", "30", "--step-s", "30", "--particles", "60"];
    let one_dof = watch(&[&windows[..], &[record.to_str().unwrap()]].concat());
    let out = dir.path().join("fe-watch");
    let on_fe = watch(
        &[
            &windows[..],
            &[
                record.to_str().unwrap(),
                "--structure",
                "fe",
                "--out",
                out.to_str().unwrap(),
            ],
        ]
        .concat(),
    );
    // The structure changes the advice only: the same windows, evidence and probabilities.
    assert_eq!(one_dof.len(), on_fe.len());
    for (a, b) in one_dof.iter().zip(&on_fe) {
        assert_eq!(a["laws"], b["laws"]);
        assert!(b["advice"]["p_unstable"].as_f64().unwrap().is_finite(), "{b}");
    }
    // The well stick-slips at 60 rpm: on the finite-element string too, each such window's way
    // out is simulated, on that string.
    let stuck: Vec<&serde_json::Value> = on_fe.iter().filter(|u| u["advice"]["stick_slip_now"] == true).collect();
    assert!(!stuck.is_empty());
    for u in stuck {
        let advice = &u["advice"];
        assert!(
            advice["escape_omega_rpm"].is_array() || advice["escape_wob_kn"].is_array(),
            "{advice}"
        );
        assert!(!advice["words"].as_str().unwrap().contains("steady"), "{advice}");
    }
    // The watch stores the string's critical bit damping, the number `bitrock fe` gives.
    let (_, stored) = stored(&out);
    assert_eq!(
        stored.meta.settings["criterion"],
        serde_json::json!({"structure": "fe", "critical_bit_damping_nms": fe["critical_bit_damping_nms"]})
    );
    // A resume on another structure is refused, naming the flag; FE settings on the 1-DOF
    // string are refused before any work.
    let (code, _, stderr) = outcome(watch_command().args(windows).args([
        record.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--resume",
    ]));
    assert_eq!(code, 2, "{stderr}");
    assert!(
        stderr.contains("--structure: differs from the one the watch in") && !stderr.contains('{'),
        "{stderr}"
    );
    let (code, _, stderr) = outcome(watch_command().args([record.to_str().unwrap(), "--dp-elements", "4"]));
    assert_eq!(code, 2, "{stderr}");
    assert!(
        stderr.contains("--dp-elements") && stderr.contains("--structure fe"),
        "{stderr}"
    );
}

#[test]
fn a_feed_that_never_sends_its_first_line_is_stopped_by_ctrl_c() {
    // A listener that accepts and then says nothing.
    let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let port = listener.local_addr().unwrap().port();
    let (connected, accepted) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let held = listener.accept();
        connected.send(()).unwrap();
        std::thread::sleep(std::time::Duration::from_secs(60));
        drop(held);
    });
    let child = watch_command()
        .arg(format!("tcp://127.0.0.1:{port}"))
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // Connected: its Ctrl-C handler is in place (however slowly a loaded machine started it),
    // and it waits for the first line.
    accepted
        .recv_timeout(std::time::Duration::from_secs(60))
        .expect("the watch connects to the feed");
    std::thread::sleep(std::time::Duration::from_millis(200));
    let (code, _, _) = outcome(std::process::Command::new("kill").args(["-INT", &child.id().to_string()]));
    assert_eq!(code, 0);
    let started = std::time::Instant::now();
    let output = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(130), "{stderr}");
    assert!(started.elapsed() < std::time::Duration::from_secs(5));
    assert!(
        stderr.contains("stopped before") && stderr.contains("first line"),
        "{stderr}"
    );
    assert!(output.stdout.is_empty());
}

#[test]
fn a_fast_record_is_thinned_to_fifty_hertz_and_watched_as_its_thinned_copy() {
    let dir = tempfile::tempdir().unwrap();
    let record = simulate(
        dir.path(),
        "fast",
        "sample_hz = 200\nnoise_torque_knm = 0.3\nnoise_speed_rpm = 0.5\nseed = 3\n\n\
         [[segment]]\nname = \"claystone\"\nduration_s = 40\nlaw = \"m2\"\nomega_rpm = 60\n",
    );
    // The same record with one row in 4 written: what a 50 Hz logger would have sent.
    let text = std::fs::read_to_string(&record).unwrap();
    let mut lines = text.lines();
    let header = lines.next().unwrap();
    let kept: Vec<&str> = std::iter::once(header).chain(lines.step_by(4)).collect();
    let copy = dir.path().join("copy.csv");
    std::fs::write(&copy, kept.join("\n") + "\n").unwrap();

    let (code, stdout, stderr) = outcome(watch_command().args(WINDOWS).arg(&record));
    assert_eq!(code, 0, "{stderr}");
    assert!(
        stderr.contains("one row in 4 used (200.0 Hz thinned to 50.0 Hz)"),
        "{stderr}"
    );
    let thinned: Vec<serde_json::Value> = stdout.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    let copied = watch(&[&WINDOWS[..], &[copy.to_str().unwrap()]].concat());
    assert_eq!(thinned.len(), 3);
    assert_eq!(without_latency(&thinned), without_latency(&copied));
    assert!(thinned.iter().all(|u| u["samples"] == 1000), "{thinned:?}");

    // `--thin 1` uses every row.
    let whole = watch(&[&WINDOWS[..], &["--thin", "1", record.to_str().unwrap()]].concat());
    assert!(whole.iter().all(|u| u["samples"] == 4000), "{whole:?}");
}

/// m2 for 40 s then m3 for 40 s, logged at 1 kHz: thinned to 50 Hz by default, windows of
/// 10 s every 2 s.
const LOGGER_WELL: &str = "sample_hz = 1000\nnoise_torque_knm = 0.3\nnoise_speed_rpm = 0.5\nseed = 7\n\n\
[[segment]]\nname = \"claystone\"\nduration_s = 40\nlaw = \"m2\"\nomega_rpm = 60\nwob_kn = 244.2\n\n\
[[segment]]\nname = \"sandstone\"\nduration_s = 40\nlaw = \"m3\"\nomega_rpm = 60\nwob_kn = 244.2\n";

#[test]
fn a_logger_s_record_ranks_each_formation_s_law_first_in_every_window_inside_it() {
    let dir = tempfile::tempdir().unwrap();
    let record = simulate(dir.path(), "logger", LOGGER_WELL);
    let mut command = bin();
    command.args(["watch", "--json", "--backend", "cpu"]).arg(&record);
    let (code, stdout, stderr) = outcome(&mut command);
    assert_eq!(code, 0, "{stderr}");
    assert!(
        stderr.contains("one row in 20 used (1000.0 Hz thinned to 50.0 Hz)"),
        "{stderr}"
    );
    let updates: Vec<serde_json::Value> = stdout.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    // Windows of 10 s every 2 s over 80 s: starts 0, 2, …, 70.
    assert_eq!(updates.len(), 36);
    let start = |u: &serde_json::Value| u["start_s"].as_f64().unwrap();
    // Every window inside a formation (after the first 10 s, the simulation's start-up
    // before the bit sticks) ranks its law first: a warm start that misses a posterior the
    // window before did not have (m3's, in the sandstone) is found again from the boxes.
    for u in &updates {
        let want = if start(u) >= 10.0 && start(u) + 10.0 <= 40.0 {
            "m2"
        } else if start(u) >= 40.0 {
            "m3"
        } else {
            continue;
        };
        assert_eq!(u["most_probable"], want, "window {} at {} s", u["window"], start(u));
    }
    // A change where the start-up ends, and one within two windows of the first that holds
    // the sandstone (window 16, [32, 42) s); none elsewhere.
    let changes: Vec<u64> = updates
        .iter()
        .filter(|u| u["change"] == true)
        .map(|u| u["window"].as_u64().unwrap())
        .collect();
    assert_eq!(changes.len(), 2, "{changes:?}");
    assert_eq!(changes[0], 5);
    assert!((16..=18).contains(&changes[1]), "{changes:?}");
}

/// The rows of `record` (a CSV with a `time_s` column first) with `start` ≤ t < `end`, as a
/// CSV of their own.
fn rows_between(record: &Path, start: f64, end: f64, to: &Path) {
    let text = std::fs::read_to_string(record).unwrap();
    let mut lines = text.lines();
    let mut kept = vec![lines.next().unwrap().to_string()];
    kept.extend(
        lines
            .filter(|l| {
                let t: f64 = l.split(',').next().unwrap().parse().unwrap();
                (start..end).contains(&t)
            })
            .map(str::to_string),
    );
    std::fs::write(to, kept.join("\n") + "\n").unwrap();
}

#[test]
fn the_paper_s_abc_on_each_window_is_bitrock_abc_on_the_window_s_rows() {
    let dir = tempfile::tempdir().unwrap();
    let record = simulate_well(dir.path());
    let args = ["--abc", "--cold-start", "--seed", "3"];
    let updates = watch(&[&WINDOWS[..], &args[..], &[record.to_str().unwrap()]].concat());
    assert_eq!(updates.len(), 17);
    for u in &updates {
        assert!(u["uninformative"].is_null(), "{u}");
        let laws = u["laws"].as_array().unwrap();
        let window: f64 = laws.iter().map(|l| l["window_probability"].as_f64().unwrap()).sum();
        assert!((window - 1.0).abs() < 1e-9, "{u}");
        assert!(
            laws.iter().all(|l| l["ln_z"].is_null() && l["ln_z_error"].is_null()),
            "{u}"
        );
        // The paper's floor, which every window of this well reaches.
        assert_eq!(u["epsilon"].as_f64(), Some(0.014), "{u}");
        assert!(u["candidates_scored"].as_u64().unwrap() >= 4000, "{u}");
    }
    // A change is judged by the fits, whichever procedure selects: declared once, near the
    // boundary.
    let declared: Vec<f64> = updates
        .iter()
        .filter(|u| u["change"] == true)
        .map(|u| u["start_s"].as_f64().unwrap())
        .collect();
    assert!(
        declared.len() == 1 && (BOUNDARY_S - 20.0 + 1e-9..=BOUNDARY_S).contains(&declared[0]),
        "{declared:?}"
    );
    // Window k's probabilities are those of `bitrock abc` on its rows (every row calibrates,
    // seed 3 + k, 4,000 particles): one window in each formation.
    for k in [2usize, 12] {
        let (start, end) = (10.0 * k as f64, 10.0 * k as f64 + 20.0);
        let rows = dir.path().join(format!("window-{k}.csv"));
        rows_between(&record, start, end, &rows);
        let out = dir.path().join(format!("run-{k}"));
        let seed = (3 + k).to_string();
        let (code, _, stderr) = outcome(
            bin()
                .args([
                    "abc",
                    "--laws",
                    "m2,m3",
                    "--backend",
                    "cpu",
                    "--quiet",
                    "--particles",
                    "4000",
                ])
                .args(["--calibration-fraction", "1", "--seed", &seed, "--out"])
                .arg(&out)
                .arg(&rows),
        );
        assert_eq!(code, 0, "{stderr}");
        let run: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("run.json")).unwrap()).unwrap();
        let last = run["populations"].as_array().unwrap().last().unwrap().clone();
        let u = &updates[k];
        assert_eq!(u["epsilon"], last["epsilon"], "window {k}");
        // The window's answer is the run's, in the same words.
        assert_eq!(u["answer"], run["answer"], "window {k}");
        for l in u["laws"].as_array().unwrap() {
            let law = l["law"].as_str().unwrap();
            assert_eq!(
                l["window_probability"], last["model_probabilities"][law],
                "window {k}, {law}"
            );
        }
        let scored: u64 = run["populations"]
            .as_array()
            .unwrap()
            .iter()
            .map(|p| p["candidates_scored"].as_u64().unwrap())
            .sum();
        assert_eq!(u["candidates_scored"].as_u64(), Some(scored), "window {k}");
    }
    // Settings of the procedure not used are refused, naming the flag.
    let (code, _, stderr) = outcome(watch_command().args(["--delta", "0.2"]).arg(&record));
    assert_eq!(code, 2, "{stderr}");
    assert!(stderr.contains("--abc"), "{stderr}");
    let (code, _, stderr) = outcome(watch_command().args(["--abc", "--islands", "3"]).arg(&record));
    assert_eq!(code, 2, "{stderr}");
    assert!(stderr.contains("--islands"), "{stderr}");
}

/// One rock (m2) throughout, at 60 rpm where the bit sticks and slips, while the weight on bit
/// steps from 200 to 240 kN, ramps back down to 180 kN and fluctuates by 5 kN all along: the
/// torque follows the weight (the laws' torque scaled by WOB / W_ref), the rock does not
/// change, and neither does the watch's verdict.
const ONE_ROCK_WOB_CHANGES: &str = "sample_hz = 20\nnoise_torque_knm = 0.3\nnoise_speed_rpm = 0.5\nseed = 9\n\
settle_s = 20\nwob_fluctuation_kn = 5\nwob_correlation_s = 5\n\n\
[[segment]]\nduration_s = 60\nlaw = \"m2\"\nomega_rpm = 60\nwob_kn = 200\n\n\
[[segment]]\nduration_s = 60\nlaw = \"m2\"\nomega_rpm = 60\nwob_kn = 240\n\n\
[[segment]]\nduration_s = 60\nlaw = \"m2\"\nomega_rpm = 60\nwob_kn = [240, 180]\n";

#[test]
fn a_change_of_weight_on_bit_in_one_rock_is_not_a_change_of_rock() {
    let dir = tempfile::tempdir().unwrap();
    let record = simulate(dir.path(), "wob", ONE_ROCK_WOB_CHANGES);
    let updates = watch(&[&WINDOWS[..], &["--particles", "100", record.to_str().unwrap()]].concat());
    assert_eq!(updates.len(), 17);
    let changes: Vec<(u64, f64)> = updates
        .iter()
        .filter(|u| u["change"] == true)
        .map(|u| (u["window"].as_u64().unwrap(), u["change_nats"].as_f64().unwrap()))
        .collect();
    assert!(changes.is_empty(), "changes declared: {changes:?}");
    // The windows across the step compared their fits with the earlier rock's, scaled to the
    // new weight: a loss of a few nats at most, far below the change threshold.
    let losses: Vec<f64> = updates.iter().filter_map(|u| u["change_nats"].as_f64()).collect();
    assert!(losses.len() >= 12, "{losses:?}");
    assert!(losses.iter().all(|l| *l < 10.0), "{losses:?}");
}

/// The lines of `record` with `edit` applied to each data row (its index among the rows, its
/// fields), written as `dir/name.csv`; `None` drops the row.
fn edited(
    record: &Path,
    dir: &Path,
    name: &str,
    edit: impl Fn(usize, Vec<String>) -> Option<Vec<String>>,
) -> std::path::PathBuf {
    let text = std::fs::read_to_string(record).unwrap();
    let mut lines = text.lines();
    let mut out = vec![lines.next().unwrap().to_string()];
    for (k, line) in lines.enumerate() {
        if let Some(fields) = edit(k, line.split(',').map(str::to_string).collect()) {
            out.push(fields.join(","));
        }
    }
    let path = dir.join(format!("{name}.csv"));
    std::fs::write(&path, out.join("\n") + "\n").unwrap();
    path
}

#[test]
fn a_time_stamp_far_ahead_is_a_glitch_and_a_gap_costs_no_windows() {
    let dir = tempfile::tempdir().unwrap();
    let record = simulate_well(dir.path());
    let args = |path: &Path| -> Vec<String> {
        let mut v: Vec<String> = WINDOWS.iter().map(|s| s.to_string()).collect();
        v.extend(["--particles".into(), "100".into(), path.to_str().unwrap().into()]);
        v
    };
    let run = |path: &Path| {
        let (code, stdout, stderr) = outcome(watch_command().args(args(path)));
        assert_eq!(code, 0, "{stderr}");
        let updates: Vec<serde_json::Value> = stdout.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
        (without_latency(&updates), stderr)
    };
    // Row 600 (30 s) stamped 10⁶ s: a glitch, skipped and said; the windows are those of the
    // record without that row.
    let glitch = edited(&record, dir.path(), "glitch", |k, mut f| {
        if k == 600 {
            f[0] = "1000000".into();
        }
        Some(f)
    });
    let without = edited(&record, dir.path(), "without", |k, f| (k != 600).then_some(f));
    let (with_glitch, said) = run(&glitch);
    assert!(
        said.contains("a row stamped 1000000 s") && said.contains("a glitch of the time column"),
        "{said}"
    );
    assert_eq!(with_glitch, run(&without).0);
    assert_eq!(with_glitch.len(), 17);
    // A logger gap from 60 s to 120 s: the windows that hold no row are not given, and said.
    let gap = edited(&record, dir.path(), "gap", |_, f| {
        let t: f64 = f[0].parse().unwrap();
        (!(60.0..120.0).contains(&t)).then_some(f)
    });
    let (updates, said) = run(&gap);
    let windows: Vec<u64> = updates.iter().map(|u| u["window"].as_u64().unwrap()).collect();
    assert_eq!(windows, [0, 1, 2, 3, 4, 5, 11, 12, 13, 14, 15, 16], "{said}");
    assert!(
        said.contains("no rows in windows 6–10 (the record has a gap)"),
        "{said}"
    );
    assert!(updates.iter().all(|u| u["samples"].as_u64().unwrap() > 0));
}

/// A logger that rounds its clock to whole seconds at 20 Hz: twenty rows share each stamp.
/// The rate is the rows per second (said), so the default windows are the record's own, and
/// each window holds the rows the precise stamps put in it (floor rounding keeps every row in
/// its whole-second window), with the same evidence, the last one too (its last stamp's rows
/// reach a tick past it).
#[test]
fn stamps_rounded_to_whole_seconds_give_the_record_s_rate_and_windows() {
    let dir = tempfile::tempdir().unwrap();
    let record = simulate_well(dir.path());
    let first_40_s = |f: Vec<String>| (f[0].parse::<f64>().unwrap() < 40.0).then_some(f);
    let precise = edited(&record, dir.path(), "precise", |_, f| first_40_s(f));
    let rounded = edited(&record, dir.path(), "rounded", |_, mut f| {
        f[0] = format!("{}", f[0].parse::<f64>().unwrap().floor());
        first_40_s(f)
    });
    let run = |path: &Path| {
        let (code, stdout, stderr) = outcome(watch_command().args(["--particles", "100"]).arg(path));
        assert_eq!(code, 0, "{stderr}");
        let updates: Vec<serde_json::Value> = stdout.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
        (without_latency(&updates), stderr)
    };
    let (exact, said_exact) = run(&precise);
    let (from_rounded, said) = run(&rounded);
    assert!(!said_exact.contains("time stamps repeat"), "{said_exact}");
    assert!(
        said.contains("about 20 rows share each stamp, 1 s apart") && said.contains("20.0 Hz"),
        "{said}"
    );
    assert!(said.contains("windows of 25 s every 5 s"), "{said}");
    // Windows of 25 s every 5 s over 40 s: starts 0, 5, 10, 15. The rounded stamps end at
    // 39 s, whose rows reach a tick past it: the last window is complete, and given.
    assert_eq!((exact.len(), from_rounded.len()), (4, 4));
    let laws = |updates: &[serde_json::Value]| -> Vec<(u64, u64, serde_json::Value)> {
        updates
            .iter()
            .map(|u| {
                (
                    u["window"].as_u64().unwrap(),
                    u["samples"].as_u64().unwrap(),
                    u["laws"].clone(),
                )
            })
            .collect()
    };
    assert_eq!(laws(&from_rounded), laws(&exact));
}

/// A glitch of the WOB channel (24,000 kN for 10 s, 40 % of a window at most) moves neither
/// the operating point nor the advice: the window's weight on bit is its median, and the
/// glitch is said for each window it touches.
#[test]
fn a_wob_glitch_is_said_and_moves_neither_the_operating_point_nor_the_advice() {
    let dir = tempfile::tempdir().unwrap();
    let record = m2_record(dir.path(), "m2", "40", &["--noise-torque-knm", "0.3", "--seed", "3"]);
    let glitch = edited(&record, dir.path(), "glitch", |k, mut f| {
        if (200..400).contains(&k) {
            f[3] = "24000".into();
        }
        Some(f)
    });
    let run = |path: &Path| {
        let (code, stdout, stderr) = outcome(watch_command().args(["--particles", "100"]).arg(path));
        assert_eq!(code, 0, "{stderr}");
        let updates: Vec<serde_json::Value> = stdout.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
        (without_latency(&updates), stderr)
    };
    let (clean, said_clean) = run(&record);
    let (glitched, said) = run(&glitch);
    assert!(!said_clean.contains("glitch of the WOB channel"), "{said_clean}");
    // Windows of 25 s every 5 s from 0 s: each of the four holds some of 10–20 s.
    assert_eq!(said.matches("a glitch of the WOB channel?").count(), 4, "{said}");
    assert!(said.contains("window 1: 40 % of its weights on bit"), "{said}");
    assert!(said.contains("its operating point takes the median, 244 kN"), "{said}");
    assert_eq!(clean.len(), 4);
    for (a, b) in clean.iter().zip(&glitched) {
        assert_eq!(a["advice"], b["advice"]);
        assert!(a["advice"]["words"].as_str().unwrap().contains("244 kN"), "{a}");
    }
}

/// A channel whose values do not fit the unit its name declares (N·m under `_knm`, rad/s
/// under `_rpm`) is said by the watch as `fit` says it of the whole record, once however many
/// windows hold it, and so is a top-drive column in rad/s under `_rpm`; the clean record says
/// nothing of the kind.
#[test]
fn the_watch_says_a_channel_in_another_unit_than_its_name_once_as_fit_does() {
    let dir = tempfile::tempdir().unwrap();
    let record = m2_record(dir.path(), "m2", "40", &["--noise-torque-knm", "0.3", "--seed", "3"]);
    let header = std::fs::read_to_string(&record)
        .unwrap()
        .lines()
        .next()
        .unwrap()
        .to_string();
    let column = |name: &str| header.split(',').position(|h| h == name).expect(name);
    let (speed, torque) = (column("bit_speed_rpm"), column("torque_knm"));
    let scaled = |name: &str, col: usize, by: f64| {
        edited(&record, dir.path(), name, |_, mut f| {
            f[col] = (f[col].parse::<f64>().unwrap() * by).to_string();
            Some(f)
        })
    };
    let said_by = |command: &mut std::process::Command| {
        let (code, _, stderr) = outcome(command);
        assert_eq!(code, 0, "{stderr}");
        stderr
    };
    let clean = said_by(watch_command().args(["--particles", "100"]).arg(&record));
    assert!(!clean.contains("say so with"), "{clean}");
    for (path, words) in [
        (scaled("newton_metres", torque, 1000.0), "read in kN·m have a median of"),
        (
            scaled("radians", speed, std::f64::consts::PI / 30.0),
            "read in rpm stay below",
        ),
    ] {
        let watched = said_by(watch_command().args(["--particles", "100"]).arg(&path));
        assert_eq!(watched.matches(words).count(), 1, "{watched}");
        let fitted = said_by(bin().args(["fit", "--laws", "m2"]).arg(&path));
        assert!(fitted.contains(words), "{fitted}");
    }
    // A top-drive column holding rad/s under `_rpm` (which `fit` does not read) is said too.
    let text = std::fs::read_to_string(&record).unwrap();
    let mut lines = text.lines();
    let mut with_top_drive = format!("{},top_drive_rpm\n", lines.next().unwrap());
    for line in lines {
        with_top_drive.push_str(&format!("{line},{}\n", 60.0 * std::f64::consts::PI / 30.0));
    }
    let path = dir.path().join("top-drive.csv");
    std::fs::write(&path, with_top_drive).unwrap();
    let watched = said_by(watch_command().args(["--particles", "100"]).arg(&path));
    let words = "the top-drive speeds of column 'top_drive_rpm' read in rpm stay below 6.3 rpm";
    assert_eq!(watched.matches(words).count(), 1, "{watched}");
    assert!(watched.contains("name it …_rad_s"), "{watched}");
}

/// A record without a time column is refused before the watch's directory is made, naming the
/// setting that names one.
#[test]
fn a_record_without_time_is_refused_before_its_directory_is_made() {
    let dir = tempfile::tempdir().unwrap();
    let record = dir.path().join("untimed.csv");
    let rows: String = (0..400)
        .map(|i| format!("{},{}\n", 60.0 + (i % 7) as f64, 9.0 + 0.01 * (i % 11) as f64))
        .collect();
    std::fs::write(&record, format!("speed_rpm,torque_knm\n{rows}")).unwrap();
    let out = dir.path().join("watch");
    let (code, _, stderr) = outcome(watch_command().arg("--out").arg(&out).arg(&record));
    assert_eq!(code, 2, "{stderr}");
    assert!(
        stderr.contains("--time-col") && stderr.contains("has no time column"),
        "{stderr}"
    );
    assert!(!out.exists());
}

/// A watch resumed with a law file edited since it started is refused, naming the law and the
/// flag, before any window; with the file as it was, it goes on.
#[test]
fn a_watch_resumed_with_an_edited_law_file_is_refused_naming_the_law() {
    let dir = tempfile::tempdir().unwrap();
    let record = m2_record(dir.path(), "m2", "30", &["--noise-torque-knm", "0.3", "--seed", "3"]);
    let law_file = dir.path().join("stribeck.toml");
    let original =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/laws/stribeck.toml")).unwrap();
    std::fs::write(&law_file, &original).unwrap();
    let out = dir.path().join("watch");
    let run = |extra: &[&str]| {
        outcome(
            bin()
                .args([
                    "watch",
                    "--json",
                    "--laws",
                    "m2,stribeck",
                    "--backend",
                    "cpu",
                    "--particles",
                    "100",
                ])
                .arg("--law-file")
                .arg(&law_file)
                .arg("--out")
                .arg(&out)
                .args(extra)
                .arg(&record),
        )
    };
    let (code, _, stderr) = run(&[]);
    assert_eq!(code, 0, "{stderr}");
    let stored = std::fs::read(out.join("watch.sqlite")).unwrap();
    let edited = original.replace("exp(-(w / vs)^2)", "exp(-(w / vs))");
    assert_ne!(edited, original);
    std::fs::write(&law_file, &edited).unwrap();
    let (code, _, stderr) = run(&["--resume"]);
    assert_eq!(code, 2, "{stderr}");
    assert!(
        stderr.contains("--law-file") && stderr.contains("the law file of stribeck is not the one"),
        "{stderr}"
    );
    assert_eq!(
        std::fs::read(out.join("watch.sqlite")).unwrap(),
        stored,
        "nothing written"
    );
    std::fs::write(&law_file, &original).unwrap();
    let (code, _, stderr) = run(&["--resume"]);
    assert_eq!(code, 0, "{stderr}");
}

/// A sample counts once however many overlapping windows hold it: on one rock, with nothing
/// forgotten (λ = 1), windows of 20 s every 5 s carry the first window's log-odds of m2
/// against m3 whole and each later window's at a quarter (each sample lies in four windows),
/// exactly; per window length of record brought in (1 + 20 × ¼ = 6) that is what windows of
/// 20 s every 20 s carry per window (6 of them), within the Monte-Carlo spread of m3's
/// evidence (30 %), where each window's evidence counted whole would carry nearly three times it.
#[test]
fn overlapping_windows_carry_each_sample_once() {
    let dir = tempfile::tempdir().unwrap();
    let record = m2_record(
        dir.path(),
        "m2",
        "120",
        &["--noise-torque-knm", "0.6", "--noise-speed-rpm", "0.5", "--seed", "4"],
    );
    // The carried and the window's own log-odds of m2 against m3, per window.
    let log_odds = |step: &str| -> Vec<(f64, f64)> {
        let updates = watch(&[
            "--window-s",
            "20",
            "--step-s",
            step,
            "--forgetting",
            "1",
            "--floor",
            "1e-300",
            "--particles",
            "200",
            record.to_str().unwrap(),
        ]);
        updates
            .iter()
            .map(|u| {
                assert!(u["uninformative"].is_null(), "{u}");
                let p = |law: &str, key: &str| {
                    u["laws"].as_array().unwrap().iter().find(|l| l["law"] == law).unwrap()[key]
                        .as_f64()
                        .unwrap()
                };
                let odds = |key: &str| (p("m2", key) / p("m3", key)).ln();
                (odds("probability"), odds("window_probability"))
            })
            .collect()
    };
    let overlapping = log_odds("5");
    let disjoint = log_odds("20");
    assert_eq!((overlapping.len(), disjoint.len()), (21, 6));
    let formula = overlapping[0].1 + 0.25 * overlapping[1..].iter().map(|o| o.1).sum::<f64>();
    let carried = overlapping.last().unwrap().0;
    assert!(
        (carried - formula).abs() < 1e-6 * formula.abs(),
        "{carried} vs {formula}"
    );
    let per_window = carried / 6.0;
    let disjoint_per_window = disjoint.last().unwrap().0 / 6.0;
    assert!(disjoint_per_window > 2.0, "{disjoint_per_window}");
    assert!(
        (per_window - disjoint_per_window).abs() < 0.3 * disjoint_per_window,
        "per window length: overlapping {per_window}, disjoint {disjoint_per_window}"
    );
}

/// Every line bounded on every source, and the work of a long file said: a stream without a
/// newline (`/dev/zero`, a line of 2 MB) is refused naming its line, a WITS block never closed
/// is given up after 4,096 items and said, and a file whose windows take more than a minute at
/// the first one's pace says how many there are, from its size, before the rest.
#[test]
fn lines_are_bounded_and_a_long_file_s_work_is_said() {
    let dir = tempfile::tempdir().unwrap();
    let (code, _, stderr) = outcome(bin().args(["watch", "/dev/zero"]));
    assert_eq!(code, 2, "{stderr}");
    assert!(
        stderr.contains("/dev/zero:1: a line of more than 1.0 MB without a newline"),
        "{stderr}"
    );
    let long = dir.path().join("long-line.csv");
    std::fs::write(
        &long,
        format!("time_s,bit_speed_rpm,torque_knm\n0,60,7\n{}", "7".repeat(2_000_000)),
    )
    .unwrap();
    let (code, _, stderr) = outcome(bin().arg("watch").arg(&long));
    assert_eq!(code, 2, "{stderr}");
    assert!(
        stderr.contains("long-line.csv:3: a line of more than 1.0 MB"),
        "{stderr}"
    );
    let wits = dir.path().join("open.wits");
    std::fs::write(&wits, format!("&&\n{}", "0120 60\n".repeat(5000))).unwrap();
    let (code, _, stderr) = outcome(
        bin()
            .args(["watch", "--torque-unit", "knm", "--wob-unit", "kn"])
            .arg(&wits),
    );
    assert_eq!(code, 0, "{stderr}");
    assert!(
        stderr.contains("a WITS block of more than 4096 items without its closing !!"),
        "{stderr}"
    );

    let record = m2_record(
        dir.path(),
        "ten-minutes",
        "600",
        &["--noise-torque-knm", "0.3", "--seed", "2"],
    );
    // Windows of 10 s every sample (0.05 s): 11,801 of them.
    let mut child = bin()
        .args([
            "watch",
            "--laws",
            "m2,m3",
            "--backend",
            "cpu",
            "--window-s",
            "10",
            "--step-s",
            "0.05",
        ])
        .arg(&record)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let stderr = std::io::BufReader::new(child.stderr.take().unwrap());
    let said = std::io::BufRead::lines(stderr)
        .map_while(Result::ok)
        .find(|l| l.contains("windows in this record"));
    child.kill().unwrap();
    child.wait().unwrap();
    let said = said.expect("the estimate said");
    let windows: f64 = said.split_whitespace().nth(2).unwrap().parse().unwrap();
    assert!((11_000.0..12_500.0).contains(&windows), "{said}");
}

/// The rows of the CSV record `record` as WITSML 1.4.1 log chunks, as a server writes a growing
/// log into a folder: `parts` files of consecutive rows, each a whole log, the stamps ISO 8601
/// from 1970-01-01T00:00:00Z (so that the wall clock's seconds are the record's own), the
/// channels by rig mnemonics with their units in the unit list.
fn witsml_chunks(record: &Path, parts: usize) -> Vec<String> {
    let text = std::fs::read_to_string(record).unwrap();
    let rows: Vec<&str> = text.lines().skip(1).collect();
    let per = rows.len().div_ceil(parts);
    rows.chunks(per)
        .map(|chunk| {
            let mut xml = String::from(
                "<?xml version=\"1.0\" encoding=\"utf-8\"?>\n<logs xmlns=\"http://www.witsml.org/schemas/1series\" version=\"1.4.1.1\">\n\
                 <log uidWell=\"W\" uidWellbore=\"B\" uid=\"L\"><name>bit</name><indexType>date time</indexType><indexCurve>TIME</indexCurve>\n\
                 <logData><mnemonicList>TIME,RPM_DH,TOB,DWOB,top_drive</mnemonicList><unitList>s,rpm,kN.m,kN,rpm</unitList>\n",
            );
            for row in chunk {
                let v: Vec<&str> = row.split(',').collect();
                let tenths_ms = (v[0].parse::<f64>().unwrap() * 1e4).round() as u64;
                let stamp = format!(
                    "1970-01-01T00:{:02}:{:02}.{:04}Z",
                    tenths_ms / 600_000,
                    (tenths_ms / 10_000) % 60,
                    tenths_ms % 10_000
                );
                xml.push_str(&format!("<data>{stamp},{},{},{},{}</data>\n", v[1], v[2], v[3], v[4]));
            }
            xml.push_str("</logData></log></logs>\n");
            xml
        })
        .collect()
}

/// A WITSML log's folder of chunks gives the CSV record's windows: read whole, and followed
/// while a server writes its chunks (the newest one caught half-written); a single log file
/// too, which cannot be followed.
#[test]
fn a_folder_of_witsml_log_chunks_gives_the_csv_record_s_windows_read_whole_or_followed() {
    use std::io::{BufRead, Read};
    let dir = tempfile::tempdir().unwrap();
    let record = simulate_well(dir.path());
    let args = [&WINDOWS[..], &["--particles", "100"]].concat();
    let whole = well_windows();
    let chunks = witsml_chunks(&record, 3);

    let folder = dir.path().join("log");
    std::fs::create_dir(&folder).unwrap();
    for (k, chunk) in chunks.iter().enumerate() {
        std::fs::write(folder.join(format!("chunk-{k:03}.xml")), chunk).unwrap();
    }
    std::fs::write(folder.join("notes.txt"), "not a chunk").unwrap();
    let read = watch(&[&args[..], &[folder.to_str().unwrap()]].concat());
    assert_eq!(without_latency(&read), without_latency(whole));
    let single = dir.path().join("one.xml");
    std::fs::write(&single, witsml_chunks(&record, 1).remove(0)).unwrap();
    let read = watch(&[&args[..], &[single.to_str().unwrap()]].concat());
    assert_eq!(without_latency(&read), without_latency(whole));
    let (code, _, stderr) = outcome(watch_command().arg(&single).arg("--follow"));
    assert_eq!(code, 2, "{stderr}");
    assert!(
        stderr.contains("--follow") && stderr.contains("give the folder"),
        "{stderr}"
    );

    // Followed: the first chunk there at the start, the rest written while the watch waits,
    // the last caught half-written first.
    let growing = dir.path().join("growing");
    std::fs::create_dir(&growing).unwrap();
    std::fs::write(growing.join("chunk-000.xml"), &chunks[0]).unwrap();
    let mut child = watch_command()
        .args(&args)
        .arg(&growing)
        .arg("--follow")
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let writer = {
        let (growing, chunks) = (growing.clone(), chunks.clone());
        std::thread::spawn(move || {
            std::thread::sleep(std::time::Duration::from_secs(2));
            std::fs::write(growing.join("chunk-001.xml"), &chunks[1]).unwrap();
            std::thread::sleep(std::time::Duration::from_secs(2));
            let last = growing.join("chunk-002.xml");
            std::fs::write(&last, &chunks[2][..chunks[2].len() / 2]).unwrap();
            std::thread::sleep(std::time::Duration::from_secs(2));
            std::fs::write(&last, &chunks[2]).unwrap();
        })
    };
    // Followed, the last window (which ends with the record) waits for rows after it.
    let n = whole.len() - 1;
    let mut reader = std::io::BufReader::new(child.stdout.take().unwrap());
    let mut followed = Vec::new();
    while followed.len() < n {
        let mut line = String::new();
        assert!(reader.read_line(&mut line).unwrap() > 0, "the watch ended early");
        followed.push(serde_json::from_str::<serde_json::Value>(&line).unwrap());
    }
    writer.join().unwrap();
    let (code, _, _) = outcome(std::process::Command::new("kill").args(["-INT", &child.id().to_string()]));
    assert_eq!(code, 0);
    assert_eq!(child.wait().unwrap().code(), Some(130));
    let mut stderr = String::new();
    child.stderr.take().unwrap().read_to_string(&mut stderr).unwrap();
    assert_eq!(without_latency(&followed), without_latency(&whole[..n]), "{stderr}");
}
