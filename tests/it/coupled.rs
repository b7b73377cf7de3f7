//! The coupled axial-torsional bit (RGD): steady drilling in closed form, the published
//! qualitative facts (stick-slip below a critical speed and beyond a critical string length,
//! steady drilling otherwise), the kernel against its CPU twin, and the command's record,
//! map and refusals.

use crate::gpu::require_gpu;
use crate::support::{bin, outcome};
use bitrock::bench::simulators::{coupled_parity_cells as parity_cells, coupled_parity_job as job};
use bitrock::eval::gpu::coupled::{self as gpu_coupled, Lanes};
use bitrock::eval::{Backend, coupled as backend};
use bitrock::simulate::coupled::{self, Assembly, Axial, Bit, CoupledJob, Regime, Schedule};
use bitrock::stability::lumped::Lumped;
use bitrock::units::RAD_S_PER_RPM;

const WOB_150_KN: Axial = Axial::Weight { wob_n: 150e3 };

fn schedule() -> Schedule {
    Schedule::new(1e-4, 50.0, 30.0, 60.0).unwrap()
}

#[test]
fn a_fast_bit_drills_steadily_at_the_closed_form_rate_and_forces() {
    // 180 rpm under 150 kN: the kick dies out and the bit drills at
    // d = (W − a·l·σ)/(a·ζ·ε + C_a·Ω/2π) a turn, 210.5 m/h (218.7 undamped).
    let j = job(180.0, WOB_150_KN);
    let steady = j.steady(&Assembly::default());
    let s = coupled::integrate(&Assembly::default(), &schedule(), &j);
    assert_eq!(s.regime(), Regime::Steady, "{s:?}");
    let rel = |a: f64, b: f64| (a - b).abs() / b.abs();
    assert!((steady.rate_m_s * 3600.0 - 210.54).abs() < 0.01, "{steady:?}");
    assert!(
        rel(s.rate_m_s(), steady.rate_m_s) < 1e-4,
        "{} vs {}",
        s.rate_m_s(),
        steady.rate_m_s
    );
    assert!(rel(s.wob_mean_n(), steady.wob_n) < 1e-4);
    assert!(rel(s.torque_mean_nm(), steady.torque_nm) < 1e-4);
    assert!(s.speed_max_rad_s - s.speed_min_rad_s < 1e-3 * j.omega_rad_s, "{s:?}");
}

#[test]
fn the_bit_stick_slips_below_a_critical_speed_and_drills_steadily_above() {
    // The public bit under 150 kN on the paper's string, rate-independent friction throughout:
    // the falling torque comes from the depth of cut alone.
    let rpms = [45.0, 60.0, 100.0, 120.0, 150.0];
    let jobs: Vec<_> = rpms.iter().map(|&r| job(r, WOB_150_KN)).collect();
    let out = coupled::integrate_batch(&Assembly::default(), &schedule(), &jobs, None);
    for (rpm, s) in rpms.iter().zip(&out) {
        let sticks = *rpm < 80.0;
        assert_eq!(
            s.regime(),
            if sticks { Regime::StickSlip } else { Regime::Steady },
            "{rpm} rpm: {s:?}"
        );
        if sticks {
            assert!(s.stuck_share() > 0.05, "{rpm} rpm: {s:?}");
            // The bit that stops and slips cuts faster on average than steady drilling would.
            assert!(
                s.rate_m_s() > job(*rpm, WOB_150_KN).steady(&Assembly::default()).rate_m_s,
                "{rpm} rpm"
            );
        } else {
            assert_eq!(s.stuck, 0, "{rpm} rpm");
        }
    }
}

#[test]
fn a_longer_string_stick_slips_where_a_shorter_one_drills_steadily() {
    // At 100 rpm under 150 kN: the paper's string (ω_n 0.85 rad/s) drills steadily; the same
    // assembly on a string 8 times as compliant (ω_n 0.3 rad/s: k ∝ 1/L) stick-slips.
    let short = coupled::integrate(&Assembly::default(), &schedule(), &job(100.0, WOB_150_KN));
    let long_string = Assembly {
        torsion: Lumped {
            omega_n_rad_s: 0.3,
            ..Lumped::default()
        },
        ..Assembly::default()
    };
    let long = coupled::integrate(&long_string, &schedule(), &job(100.0, WOB_150_KN));
    assert_eq!(short.regime(), Regime::Steady, "{short:?}");
    assert_eq!(long.regime(), Regime::StickSlip, "{long:?}");
    assert!(long.period_s(50.0).unwrap() > 10.0, "{long:?}");
}

#[test]
fn the_parity_test_s_stick_slip_cells_move_regularly() {
    // Kicks of 1 rpm and of 1 rpm times 1 + 10⁻⁵, 2·10⁻⁵, 3·10⁻⁵: the CPU's stuck shares agree
    // within a fifth of the parity test's tolerance, its rates of penetration within a tenth.
    let (cells, sched) = parity_cells();
    let assembly = Assembly::default();
    let jobs: Vec<_> = cells.iter().map(|&(r, a)| job(r, a)).collect();
    let regimes: Vec<_> = coupled::integrate_batch(&assembly, &sched, &jobs, None)
        .iter()
        .map(|s| s.regime())
        .collect();
    assert_eq!(
        regimes,
        [
            Regime::StickSlip,
            Regime::StickSlip,
            Regime::BitBounce,
            Regime::Steady,
            Regime::Steady
        ],
        "the cells are what they are said to be"
    );
    for &(rpm, axial) in &cells[..2] {
        let kicked: Vec<_> = (0..4)
            .map(|k| CoupledJob {
                kick_rad_s: RAD_S_PER_RPM * (1.0 + 1e-5 * f64::from(k)),
                ..job(rpm, axial)
            })
            .collect();
        let out = coupled::integrate_batch(&assembly, &sched, &kicked, None);
        let c = &out[0];
        for other in &out[1..] {
            assert!(
                (other.stuck_share() - c.stuck_share()).abs() <= 0.002,
                "{rpm} rpm: {other:?}\n{c:?}"
            );
            assert!(
                (other.rate_m_s() - c.rate_m_s()).abs() < 0.001 * c.rate_m_s(),
                "{rpm} rpm"
            );
        }
    }
}

#[test]
#[cfg_attr(skip_gpu_tests, ignore = "BITROCK_SKIP_GPU_TESTS=1")]
fn the_kernel_integrates_the_coupled_bit_as_its_cpu_twin_does() {
    require_gpu();
    // The cells of `parity_cells` in one batch, f32 against f64 over 600,000 steps a string,
    // by `bitrock parity`'s rule: regimes and samples equal; rate of penetration within 1 %
    // (3 % where the bit bounces: its minute's rate moves by 1-2 % with the rounding as with
    // the step), stuck share within 0.01, off-bottom share within 0.015, mean weight and
    // torque within 1 %.
    let parity = bitrock::bench::simulators::coupled_parity().unwrap();
    assert!(parity.pass, "{parity:#?}");
}

#[test]
#[cfg_attr(skip_gpu_tests, ignore = "BITROCK_SKIP_GPU_TESTS=1")]
fn the_kernel_gives_the_same_summaries_whether_its_lanes_leave_the_held_line_together_or_alone() {
    require_gpu();
    assert!(
        bitrock::eval::gpu::context().unwrap().has_subgroups(),
        "the device has no subgroup operations: both runs would be the kernel without them"
    );
    // A spread of speeds and weights side by side in each subgroup, so that lanes leave the
    // held ring line at different steps: stuck, bouncing and steady strings, and rebases of
    // the ring every centimetre drilled. Under a weight and under a feed.
    let weights: Vec<CoupledJob> = (0..64)
        .map(|i| {
            let rpm = 40.0 + 120.0 * f64::from(i % 13) / 12.0;
            job(
                rpm,
                Axial::Weight {
                    wob_n: 1e3 * (100.0 + 160.0 * f64::from(i % 11) / 10.0),
                },
            )
        })
        .collect();
    let feeds: Vec<CoupledJob> = (0..16)
        .map(|i| {
            let rate_m_s = (10.0 + 5.0 * f64::from(i % 8)) / 3600.0;
            job(30.0 + 10.0 * f64::from(i % 5), Axial::Feed { rate_m_s })
        })
        .collect();
    let assembly = Assembly::default();
    let sched = Schedule::new(1e-4, 50.0, 2.0, 20.0).unwrap();
    for jobs in [&weights, &feeds] {
        let run = |lanes| gpu_coupled::integrate_batch_with(&assembly, &sched, jobs, None, lanes).unwrap();
        let (together, each) = (run(Lanes::Together), run(Lanes::Each));
        assert_eq!(together, each);
    }
    let regimes: Vec<Regime> = coupled::integrate_batch(&assembly, &sched, &weights, None)
        .iter()
        .map(|s| s.regime())
        .collect();
    for regime in [Regime::Steady, Regime::StickSlip, Regime::BitBounce] {
        assert!(regimes.contains(&regime), "no {regime:?} string among {regimes:?}");
    }
}

/// `bitrock coupled` at `rpm` under 150 kN, `seconds` recorded after 10 s, its record written
/// to `name` in `dir`: the summary's JSON and the record's path.
fn simulated_record(dir: &std::path::Path, name: &str, rpm: f64, seconds: f64) -> (String, std::path::PathBuf) {
    let csv = dir.join(name);
    let (code, stdout, stderr) = outcome(
        bin()
            .args(["coupled", "--wob-kn", "150", "--settle-s", "10", "--json"])
            .args([
                "--omega-rpm",
                &rpm.to_string(),
                "--duration-s",
                &seconds.to_string(),
                "--out",
            ])
            .arg(&csv),
    );
    assert_eq!(code, 0, "{stderr}");
    (stdout, csv)
}

#[test]
#[cfg_attr(skip_gpu_tests, ignore = "BITROCK_SKIP_GPU_TESTS=1")]
fn the_benchmark_says_how_the_kernel_s_lanes_left_their_steps() {
    require_gpu();
    let run = |backend: &str| {
        let (code, stdout, stderr) = outcome(bin().args([
            "bench",
            "--coupled",
            "--backend",
            backend,
            "--strings-n",
            "16",
            "--reps",
            "1",
            "--json",
        ]));
        assert_eq!(code, 0, "{stderr}");
        let report: serde_json::Value = serde_json::from_str(&stdout).unwrap();
        report.as_array().unwrap()[0].clone()
    };
    let has = bitrock::eval::gpu::context().unwrap().has_subgroups();
    assert_eq!(run("gpu")["subgroup_vote"], has);
    assert!(run("cpu").get("subgroup_vote").is_none());
}

#[test]
fn a_misspelt_clock_or_acceleration_column_is_refused_where_the_axial_speed_makes_it_unneeded() {
    // The record has the bit's axial speed, so neither its clock nor its acceleration is read;
    // a column named for them must still be there.
    let dir = tempfile::tempdir().unwrap();
    let (_, csv) = simulated_record(dir.path(), "rgd.csv", 45.0, 20.0);
    for (flag, name) in [("--time-col", "tme"), ("--axial-acceleration-col", "axial_acc")] {
        let (code, _, stderr) = outcome(bin().args(["coupled", "--calibrate"]).arg(&csv).args([flag, name]));
        assert_eq!(code, 2, "{flag}: {stderr}");
        assert!(stderr.contains(&format!("no column named '{name}'")), "{stderr}");
        assert!(stderr.contains(flag), "{stderr}");
        assert!(
            stderr.contains("time_s, top_drive_rpm"),
            "the header is listed: {stderr}"
        );
    }
    // Named rightly, they are taken and the calibration runs.
    let (code, _, stderr) = outcome(
        bin()
            .args(["coupled", "--calibrate"])
            .arg(&csv)
            .args(["--time-col", "time_s"]),
    );
    assert_eq!(code, 0, "{stderr}");
}

#[test]
fn the_command_writes_the_record_in_named_units_and_its_summary() {
    let dir = tempfile::tempdir().unwrap();
    let (stdout, csv) = simulated_record(dir.path(), "rgd.csv", 45.0, 20.0);
    let summary: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    assert_eq!(summary["regime"], "stick_slip");
    let text = std::fs::read_to_string(&csv).unwrap();
    let mut lines = text.lines();
    assert_eq!(
        lines.next().unwrap(),
        "time_s,top_drive_rpm,surface_torque_knm,bit_speed_rpm,torque_on_bit_knm,wob_kn,axial_speed_m_h,axial_acceleration_m_s2,rop_m_h,depth_of_cut_mm"
    );
    let rows: Vec<Vec<f64>> = lines
        .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
        .collect();
    assert_eq!(rows.len(), 1000);
    let mean = |k: usize| rows.iter().map(|r| r[k]).sum::<f64>() / rows.len() as f64;
    // The record's columns are the summary's, in kN·m, kN, m/h and rpm.
    for (column, key) in [(4, "torque_knm"), (5, "wob_kn"), (3, "bit_speed_rpm")] {
        let want = summary[key]["mean"].as_f64().unwrap();
        assert!(
            (mean(column) - want).abs() < 1e-4 * want.abs().max(1.0),
            "{key}: {} vs {want}",
            mean(column)
        );
    }
    assert!((mean(6) - summary["rop_m_h"].as_f64().unwrap()).abs() < 1e-3);
    // The acceleration is the axial speed's change over each sample period (0.02 s): summed,
    // it gives the speed back, as a box-filtered accelerometer's samples would.
    for k in 1..rows.len() {
        let change_m_s = (rows[k][6] - rows[k - 1][6]) / 3600.0;
        assert!(
            (change_m_s - 0.02 * rows[k][7]).abs() < 1e-7,
            "sample {k}: {:?}",
            rows[k]
        );
    }
    assert!(
        rows.iter().any(|r| r[7].abs() > 0.1),
        "the bit's axial motion is in the record"
    );
    let stuck = rows.iter().filter(|r| r[3].abs() < 1.0).count() as f64 / rows.len() as f64;
    assert!((stuck - summary["stuck_share"].as_f64().unwrap()).abs() < 1e-9);
    // Torque on bit of a kN·m scale: steady drilling here takes 10.6 kN·m.
    assert!((5.0..20.0).contains(&mean(4)), "{}", mean(4));
}

#[test]
fn the_command_maps_the_regimes_over_speed_and_weight() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("map.csv");
    let (code, stdout, stderr) = outcome(
        bin()
            .args([
                "coupled",
                "--map",
                "--wob-kn",
                "150",
                "--map-rpm",
                "45:180:2",
                "--map-wob-kn",
                "150:220:2",
            ])
            .args(["--duration-s", "30", "--settle-s", "20", "--backend", "cpu", "--out"])
            .arg(&csv),
    );
    assert_eq!(code, 0, "{stderr}");
    assert!(stdout.contains("4 strings on the CPU"), "{stdout}");
    let text = std::fs::read_to_string(&csv).unwrap();
    let rows: Vec<Vec<&str>> = text.lines().skip(1).map(|l| l.split(',').collect()).collect();
    let regime = |rpm: &str, kn: &str| rows.iter().find(|r| r[0] == rpm && r[1] == kn).unwrap()[2].to_string();
    assert_eq!(regime("45", "150"), "stick-slip");
    assert_eq!(regime("180", "150"), "steady");
    assert_eq!(regime("180", "220"), "steady");
}

#[test]
fn bad_parameters_are_refused_by_flag_with_nothing_written() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("never.csv");
    for (args, flag) in [
        (vec!["--zeta", "-0.5"], "--zeta"),
        (vec!["--blades", "0"], "--blades"),
        (vec!["--omega-rpm", "0"], "--omega-rpm"),
        (vec!["--wob-kn", "-10"], "--wob-kn"),
        (vec!["--feed-m-h", "0"], "--feed-m-h"),
        (vec!["--wear-flat-mm", "500"], "--wear-flat-mm"),
        (vec!["--mass-kg", "0"], "--mass-kg"),
        (vec!["--map", "--map-rpm", "200:20:5"], "--map-rpm"),
        // The other drive's axis: the drive decides which the map is over.
        (vec!["--map", "--map-wob-kn", "130:170:5"], "--map-wob-kn:"),
        (
            vec!["--map", "--wob-kn", "150", "--map-feed-m-h", "10:40:4"],
            "--map-feed-m-h:",
        ),
        // A step the ring cannot resolve: at 200 rpm a slipping bit crosses a tenth of a
        // blade sector in 2.5 ms; on a map, at its fastest cell.
        (vec!["--omega-rpm", "200", "--dt-s", "0.005"], "--dt-s"),
        (vec!["--map", "--map-rpm", "20:200:3", "--dt-s", "0.005"], "--dt-s"),
    ] {
        let (code, _, stderr) = outcome(bin().arg("coupled").args(&args).arg("--out").arg(&csv));
        assert_eq!(code, 2, "{args:?}: {stderr}");
        assert!(stderr.contains(flag), "{args:?}: {stderr}");
        assert!(!csv.exists(), "{args:?}");
    }
}

#[test]
fn a_well_is_one_string_through_its_formations_each_segment_reported_and_recorded() {
    let dir = tempfile::tempdir().unwrap();
    let well = dir.path().join("well.toml");
    std::fs::write(
        &well,
        "settle_s = 10\n\
         [[segment]]\nname = \"shale\"\nduration_s = 20\nomega_rpm = 45\nwob_kn = 150\n\
         [[segment]]\nname = \"sandstone\"\nduration_s = 20\nomega_rpm = 45\nwob_kn = 150\nintrinsic_energy_mpa = 90\n",
    )
    .unwrap();
    // The well drilled with its JSON printed and its record written to `csv`.
    let drill = |well: &std::path::Path, csv: &std::path::Path| -> serde_json::Value {
        let (code, stdout, stderr) = outcome(
            bin()
                .args(["coupled", "--json", "--well"])
                .arg(well)
                .arg("--out")
                .arg(csv),
        );
        assert_eq!(code, 0, "{stderr}");
        serde_json::from_str(&stdout).unwrap()
    };
    let csv = dir.path().join("well.csv");
    let report = drill(&well, &csv);
    let segments = report["segments"].as_array().unwrap();
    assert_eq!(segments.len(), 2);
    assert_eq!(
        (segments[1]["name"].as_str(), segments[1]["start_s"].as_f64()),
        (Some("sandstone"), Some(20.0))
    );
    // The drive as the file gives it, apart from the weight the bit felt (its range).
    assert_eq!(segments[1]["drive"], serde_json::json!({"wob_kn": 150.0}));
    assert_eq!(segments[1]["omega_rpm"], 45.0);
    assert!(
        segments[1]["wob_kn"]["max"].as_f64().unwrap() > 150.0,
        "{}",
        segments[1]
    );
    // The first segment is the single string of the same settings, figure for figure.
    let (single, _) = simulated_record(dir.path(), "single.csv", 45.0, 20.0);
    let single: serde_json::Value = serde_json::from_str(&single).unwrap();
    for key in ["regime", "rop_m_h", "stuck_share", "torque_knm", "steady"] {
        assert_eq!(segments[0][key], single[key], "{key}");
    }
    // The harder rock's steady drilling is slower.
    let steady = |k: usize| segments[k]["steady"]["rop_m_h"].as_f64().unwrap();
    assert!(steady(1) < 0.8 * steady(0), "{} {}", steady(0), steady(1));
    let text = std::fs::read_to_string(&csv).unwrap();
    let mut lines = text.lines();
    assert_eq!(
        lines.next().unwrap(),
        "time_s,segment,top_drive_rpm,surface_torque_knm,bit_speed_rpm,torque_on_bit_knm,wob_kn,axial_speed_m_h,axial_acceleration_m_s2,rop_m_h,depth_of_cut_mm"
    );
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len(), 2000);
    assert_eq!((rows[999][1], rows[1000][1]), ("shale", "sandstone"));
    assert_eq!((rows[1000][0], rows[1000][2]), ("20.000000", "45.000000"));
    // Each segment's recorded mean torque is its summary's.
    for (k, segment) in segments.iter().enumerate() {
        let torques: Vec<f64> = rows[1000 * k..1000 * (k + 1)]
            .iter()
            .map(|r| r[5].parse().unwrap())
            .collect();
        let mean = torques.iter().sum::<f64>() / torques.len() as f64;
        let want = segment["torque_knm"]["mean"].as_f64().unwrap();
        assert!((mean - want).abs() < 1e-4 * want, "{mean} vs {want}");
    }
    // The table names each segment; a single string's flag beside a well is refused by name,
    // and a bad file by its line and column, with nothing written.
    let (code, stdout, _) = outcome(bin().args(["coupled", "--well"]).arg(&well));
    assert_eq!(code, 0);
    assert!(
        stdout.contains("sandstone") && stdout.contains("stick-slip"),
        "{stdout}"
    );
    // A ramp: as the file gives it in the JSON and the table, followed by the record.
    let ramp = dir.path().join("ramp.toml");
    std::fs::write(
        &ramp,
        "settle_s = 2\n[[segment]]\nduration_s = 4\nomega_rpm = [45, 90]\nwob_kn = [150, 120]\n",
    )
    .unwrap();
    let ramp_csv = dir.path().join("ramp.csv");
    let report = drill(&ramp, &ramp_csv);
    let segment = &report["segments"][0];
    assert_eq!(segment["omega_rpm"], serde_json::json!({"from": 45.0, "to": 90.0}));
    assert_eq!(
        segment["drive"],
        serde_json::json!({"wob_kn": {"from": 150.0, "to": 120.0}})
    );
    let text = std::fs::read_to_string(&ramp_csv).unwrap();
    let top_drive: Vec<f64> = text
        .lines()
        .skip(1)
        .map(|l| l.split(',').nth(2).unwrap().parse().unwrap())
        .collect();
    assert_eq!((top_drive.len(), top_drive[0], top_drive[100]), (200, 45.0, 67.5));
    let (code, stdout, _) = outcome(bin().args(["coupled", "--well"]).arg(&ramp));
    assert_eq!(code, 0);
    assert!(stdout.contains("45→90") && stdout.contains("150→120 kN"), "{stdout}");
    let never = dir.path().join("never.csv");
    for flag in [["--omega-rpm", "60"], ["--seed", "3"], ["--backend", "cpu"]] {
        let (code, _, stderr) = outcome(
            bin()
                .arg("coupled")
                .args(flag)
                .arg("--well")
                .arg(&well)
                .arg("--out")
                .arg(&never),
        );
        assert_eq!(code, 2);
        assert!(stderr.contains("--well") && stderr.contains(flag[0]), "{stderr}");
    }
    std::fs::write(&well, "[[segment]]\nduration_s = 20\nomega_rpm = 45\nblades = 3\n").unwrap();
    let (code, _, stderr) = outcome(bin().args(["coupled", "--well"]).arg(&well).arg("--out").arg(&never));
    assert_eq!(code, 2);
    assert!(
        stderr.contains("well.toml:4:1") && stderr.contains("unknown field `blades`"),
        "{stderr}"
    );
    assert!(!never.exists());
}

#[test]
fn a_bit_off_bottom_nearly_throughout_is_said() {
    // Undamped axially, the bit pumps energy into its bounce: off bottom 96 % of the time.
    let args = [
        "coupled",
        "--axial-damping-kns-m",
        "0",
        "--omega-rpm",
        "60",
        "--wob-kn",
        "200",
    ];
    let (code, stdout, stderr) = outcome(
        bin()
            .args(args)
            .args(["--duration-s", "20", "--settle-s", "60", "--json"]),
    );
    assert_eq!(code, 0, "{stderr}");
    let one: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    let share = one["off_bottom_share"].as_f64().unwrap();
    assert!(share >= 0.9, "{share}");
    let warning = one["warning"].as_str().unwrap();
    assert!(
        warning.contains(&format!("off bottom for {:.0} % of the record", 100.0 * share)),
        "{warning}"
    );
    assert!(stderr.contains(warning), "{stderr}");
    // A bit that cuts has no such warning.
    let (_, stdout, _) = outcome(bin().args([
        "coupled",
        "--omega-rpm",
        "180",
        "--wob-kn",
        "150",
        "--duration-s",
        "5",
        "--settle-s",
        "5",
        "--json",
    ]));
    let one: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    assert!(one.get("warning").is_none(), "{one}");
}

/// The public bit at 45 rpm under 150 kN (stick-slip), sampled at `hz` for `seconds` after 30 s.
fn record_samples(hz: f64, seconds: f64) -> Vec<coupled::Sample> {
    let mut samples = Vec::new();
    let sched = Schedule::new(1e-4, hz, 30.0, seconds).unwrap();
    coupled::integrate_with(&Assembly::default(), &sched, &job(45.0, WOB_150_KN), &mut |s| {
        samples.push(*s)
    });
    samples
}

/// A record of the public bit at 45 rpm under 150 kN (stick-slip), 60 s at 50 Hz, noise of
/// `torque_nm` and `wob_n` added from `seed`; with the bit's axial speed or without.
fn drilling_record(torque_nm: f64, wob_n: f64, seed: u64, axial: bool) -> bitrock::data::drilling::DrillingRecord {
    drilling_record_at(50.0, 60.0, torque_nm, wob_n, seed, axial)
}

/// [`drilling_record`] sampled at `hz` for `seconds`.
fn drilling_record_at(
    hz: f64,
    seconds: f64,
    torque_nm: f64,
    wob_n: f64,
    seed: u64,
    axial: bool,
) -> bitrock::data::drilling::DrillingRecord {
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};
    let samples = record_samples(hz, seconds);
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let (nt, nw) = (Normal::new(0.0, torque_nm).unwrap(), Normal::new(0.0, wob_n).unwrap());
    bitrock::data::drilling::DrillingRecord {
        source: "simulated.csv".into(),
        columns: bitrock::data::drilling::DrillingColumns {
            speed: "bit_speed_rpm".into(),
            torque: "torque_on_bit_knm".into(),
            wob: "wob_kn".into(),
            rop: Some("rop_m_h".into()),
            axial_speed: axial.then(|| "axial_speed_m_h".into()),
            axial_acceleration: None,
            time: None,
        },
        speed_rad_s: samples.iter().map(|s| s.bit_speed_rad_s).collect(),
        torque_nm: samples.iter().map(|s| s.torque_nm + nt.sample(&mut rng)).collect(),
        wob_n: samples.iter().map(|s| s.wob_n + nw.sample(&mut rng)).collect(),
        rop_m_s: Some(samples.iter().map(|s| s.cutting_rate_m_s).collect()),
        axial_speed_m_s: axial.then(|| samples.iter().map(|s| s.axial_speed_m_s).collect()),
        axial_acceleration_m_s2: None,
        sample_period_s: None,
        unread: Vec::new(),
    }
}

#[test]
fn a_stick_slip_record_calibrates_the_bit_and_its_intervals_cover_the_truth() {
    use bitrock::fit::coupled::{CuttingBy, calibrate};
    let b = Bit::default();
    let truth = [60.0, 0.6, b.contact_weight_n() / 1e3, 0.6];
    // Noise-free, with the bit's axial speed: the lines are the bit's own.
    let exact = calibrate(&drilling_record(0.0, 0.0, 0, true), b.radius_m, 400, 1).unwrap();
    for (e, t) in exact.estimates.iter().zip(truth) {
        assert!((e.value - t).abs() < 1e-6 * t, "{e:?}");
    }
    assert!(exact.warning.is_none());
    // 0.3 kN·m and 5 kN of noise: the 90 % intervals hold the truth in 20 records of 20, as
    // often as they should (at least 15; 18 expected).
    let mut covered = [0; 4];
    for seed in 0..20 {
        let c = calibrate(&drilling_record(300.0, 5e3, seed, true), b.radius_m, 2000, seed).unwrap();
        for (k, (e, t)) in c.estimates.iter().zip(truth).enumerate() {
            covered[k] += usize::from(e.lo <= t && t <= e.hi);
        }
    }
    assert!(covered.iter().all(|&c| c >= 15), "{covered:?} of 20");
    // Without the axial speed, the samples of a bit moving down are the weight's upper edge:
    // noise-free, the same lines, through the samples moving down (a neighbour held is in
    // another state and left out of a sample's average) and one at axial rest with its whole
    // contact: 1,171 for 1,170.
    let blind = calibrate(&drilling_record(0.0, 0.0, 0, false), b.radius_m, 400, 1).unwrap();
    assert_eq!(blind.cutting_by, CuttingBy::WeightEdge);
    let (found, moving) = (blind.cutting_samples, exact.cutting_samples);
    assert!(found.abs_diff(moving) <= moving / 100, "{found} of {moving}");
    for (e, t) in blind.estimates.iter().zip(truth) {
        assert!((e.value - t).abs() < 1e-6 * t, "{e:?}");
    }
    assert!(blind.warning.is_none(), "{:?}", blind.warning);
    // With 5 kN of noise on the weight, its noise is read off the edge within a tenth and the
    // intervals hold the truth as often as with the axial speed.
    let mut covered = [0; 4];
    for seed in 0..20 {
        let c = calibrate(&drilling_record(300.0, 5e3, seed, false), b.radius_m, 2000, seed).unwrap();
        let noise_kn = c.weight_edge_noise_kn.unwrap();
        assert!(
            (noise_kn - 5.0).abs() < 0.5 && c.warning.is_none(),
            "{noise_kn} {:?}",
            c.warning
        );
        for (k, (e, t)) in c.estimates.iter().zip(truth).enumerate() {
            covered[k] += usize::from(e.lo <= t && t <= e.hi);
        }
    }
    assert!(covered.iter().all(|&c| c >= 15), "{covered:?} of 20");
    // A weight spike of 50 kN in one sample of 100 is left out of the edge and of its noise.
    for seed in 0..20 {
        let mut record = drilling_record(300.0, 5e3, seed, false);
        for w in record.wob_n.iter_mut().skip(37).step_by(100) {
            *w += 5e4;
        }
        let c = calibrate(&record, b.radius_m, 20, seed).unwrap();
        let noise_kn = c.weight_edge_noise_kn.unwrap();
        assert!(
            (noise_kn - 5.0).abs() < 0.6 && c.warning.is_none(),
            "{noise_kn} {:?}",
            c.warning
        );
        for (e, t) in c.estimates.iter().zip(truth) {
            assert!((e.value - t).abs() < 0.05 * t, "seed {seed}: {e:?}");
        }
    }
    // With 10 kN, each sample's deficit read off the weight and the torque and averaged over
    // three samples in time still tells them: no warning, and the intervals hold the truth as
    // often as they should (19, 17, 18, 18; by the weight alone ε's held it in 14 of 20, and
    // every record was warned of).
    let mut covered = [0; 4];
    for seed in 0..20 {
        let c = calibrate(&drilling_record(300.0, 10e3, seed, false), b.radius_m, 2000, seed).unwrap();
        assert!(c.warning.is_none(), "{:?}", c.warning);
        for (k, (e, t)) in c.estimates.iter().zip(truth).enumerate() {
            covered[k] += usize::from(e.lo <= t && t <= e.hi);
        }
    }
    assert!(covered.iter().all(|&c| c >= 15), "{covered:?} of 20");
    // With 10 kN on the weight and 1 kN·m on the torque, a held bit blurs into one moving
    // down: said in every record.
    for seed in 0..10 {
        let c = calibrate(&drilling_record(1e3, 10e3, seed, false), b.radius_m, 20, seed).unwrap();
        let warning = c.warning.unwrap_or_default();
        assert!(
            warning.contains("scatter") && warning.contains("axial speed"),
            "{warning:?}"
        );
    }
}

/// [`drilling_record_at`] (noise of `torque_nm` and `wob_n`) without the bit's axial speed, with
/// its axial acceleration (each
/// sample the mean over its period, as a filtered accelerometer reads it, plus `offset_m_s2` and
/// white noise of `noise_m_s2` drawn from `seed`, all times `sign`) and its clock; one sample in
/// `every` kept, the acceleration read at that sample only (a logger without a filter).
fn accelerometer_record(
    hz: f64,
    (torque_nm, wob_n): (f64, f64),
    (noise_m_s2, offset_m_s2, sign): (f64, f64, f64),
    every: usize,
    seed: u64,
) -> bitrock::data::drilling::DrillingRecord {
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};
    let mut record = drilling_record_at(hz, 60.0, torque_nm, wob_n, seed, false);
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed + 1_000);
    let noise = Normal::new(0.0, noise_m_s2).unwrap();
    let acceleration: Vec<f64> = record_samples(hz, 60.0)
        .iter()
        .map(|s| sign * (s.axial_acceleration_m_s2 + offset_m_s2 + noise.sample(&mut rng)))
        .collect();
    let kept = |v: &[f64]| v.iter().step_by(every).copied().collect::<Vec<f64>>();
    record.columns.axial_acceleration = Some("axial_acceleration_m_s2".into());
    record.speed_rad_s = kept(&record.speed_rad_s);
    record.torque_nm = kept(&record.torque_nm);
    record.wob_n = kept(&record.wob_n);
    record.rop_m_s = record.rop_m_s.as_deref().map(kept);
    record.axial_acceleration_m_s2 = Some(kept(&acceleration));
    record.sample_period_s = Some(every as f64 / hz);
    record
}

#[test]
fn a_record_with_the_bit_s_axial_acceleration_calibrates_the_bit_through_a_noisy_weight() {
    use bitrock::fit::coupled::{CuttingBy, calibrate};
    let b = Bit::default();
    let truth = [60.0, 0.6, b.contact_weight_n() / 1e3, 0.6];
    // Noise-free, gravity's reading at rest: the samples moving down are the bit's own, the
    // lines exact, and the bit's travel from rest to rest the depth it cut.
    let c = calibrate(
        &accelerometer_record(50.0, (0.0, 0.0), (0.0, 9.81, 1.0), 1, 0),
        b.radius_m,
        400,
        1,
    )
    .unwrap();
    assert_eq!(c.cutting_by, CuttingBy::AxialAcceleration);
    let rests = c.axial_rests.as_ref().unwrap();
    // Per sample, as the bit's own axial speed sorts them, but where the bit barely moves (a
    // sample starting at 7e-8 m/s reads as a rest: its acceleration is within the channel's
    // rounding of one).
    let speed: Vec<f64> = record_samples(50.0, 60.0).iter().map(|s| s.axial_speed_m_s).collect();
    let differ = (0..speed.len())
        .filter(|&i| rests.moving_down[i] != (speed[i] > 0.0))
        .inspect(|&i| assert!(speed[i].abs() < 1e-6, "sample {i}: {} m/s", speed[i]))
        .count();
    assert!(differ <= 1, "{differ} samples sorted otherwise");
    for (e, t) in c.estimates.iter().zip(truth) {
        assert!((e.value - t).abs() < 1e-6 * t, "{e:?}");
    }
    let (moved, cut) = (rests.travel_m.unwrap(), rests.depth_cut_m.unwrap());
    assert!((moved - cut).abs() < 0.005 * cut, "{moved} m for {cut} m");
    // 30 kN of noise on the weight, where its upper edge tells a held bit from one moving down
    // no longer (ε's interval held the truth in none of 20 records, all warned), and 0.05 m/s²
    // on an accelerometer reading 0.3 m/s² at rest: the 90 % intervals hold the truth as often as
    // they should (at least 15 of 20; 18 expected), nothing warned of.
    let mut covered = [0; 4];
    for seed in 0..20 {
        let record = accelerometer_record(50.0, (300.0, 30e3), (0.05, 0.3, 1.0), 1, seed);
        let c = calibrate(&record, b.radius_m, 2000, seed).unwrap();
        assert_eq!(c.cutting_by, CuttingBy::AxialAcceleration);
        assert!(c.notes().is_empty(), "{:?}", c.notes());
        let rests = c.axial_rests.as_ref().unwrap();
        assert!(
            (rests.noise_m_s2 - 0.05).abs() < 0.005 && !rests.upward_positive,
            "{rests:?}"
        );
        for (k, (e, t)) in c.estimates.iter().zip(truth).enumerate() {
            covered[k] += usize::from(e.lo <= t && t <= e.hi);
        }
    }
    assert!(covered.iter().all(|&c| c >= 15), "{covered:?} of 20");
    // The same channel read upward positive gives the same samples.
    let up = calibrate(
        &accelerometer_record(50.0, (300.0, 30e3), (0.05, 0.3, -1.0), 1, 3),
        b.radius_m,
        400,
        1,
    )
    .unwrap();
    let down = calibrate(
        &accelerometer_record(50.0, (300.0, 30e3), (0.05, 0.3, 1.0), 1, 3),
        b.radius_m,
        400,
        1,
    )
    .unwrap();
    assert!(up.axial_rests.as_ref().unwrap().upward_positive);
    let picks = |c: &bitrock::fit::coupled::CoupledCalibration| c.axial_rests.as_ref().unwrap().moving_down.clone();
    assert_eq!(picks(&up), picks(&down));
    for (u, d) in up.estimates.iter().zip(&down.estimates) {
        assert!((u.value - d.value).abs() <= 1e-9 * d.value.abs(), "{u:?} {d:?}");
    }
    // At 5 Hz a held spell lasts less than two samples: the quiet readings found are a moving
    // bit's, away from the record's mean, said, and the weight's edge tells the samples instead.
    let slow = calibrate(
        &accelerometer_record(5.0, (300.0, 5e3), (0.05, 0.3, 1.0), 1, 0),
        b.radius_m,
        400,
        1,
    )
    .unwrap();
    assert_eq!(slow.cutting_by, CuttingBy::WeightEdge);
    let why = slow.axial_acceleration_unused.unwrap_or_default();
    assert!(why.contains("no rests") && why.contains("sampled too slowly"), "{why}");
    // A 50-Hz channel read one sample in ten, without its filter: its sums are no speed, and
    // it is not used (here its quiet readings make no rests; where they do, the bit's travel
    // from rest to rest is not the depth cut: `fit::axial_rests`'s tests).
    let aliased = calibrate(
        &accelerometer_record(50.0, (300.0, 5e3), (0.05, 0.3, 1.0), 10, 0),
        b.radius_m,
        400,
        1,
    )
    .unwrap();
    assert_eq!(aliased.cutting_by, CuttingBy::WeightEdge);
    assert!(aliased.axial_acceleration_unused.is_some());
}

#[test]
fn a_record_sampled_slowly_calibrates_the_bit_from_its_weight_s_upper_edge() {
    use bitrock::fit::coupled::calibrate;
    let b = Bit::default();
    let truth = [60.0, 0.6, b.contact_weight_n() / 1e3, 0.6];
    // At 20, 5 and 2 Hz the bit's held spells last a sample or two: a held neighbour left in a
    // sample's average would pull the edge's samples below it and the held ones onto it
    // (ε 57.1 MPa and W_f 76.9 kN noise-free at 20 Hz, unwarned). Noise-free, the bit's own
    // lines, no warning.
    for hz in [20.0, 5.0, 2.0] {
        let c = calibrate(&drilling_record_at(hz, 120.0, 0.0, 0.0, 0, false), b.radius_m, 400, 1).unwrap();
        for (e, t) in c.estimates.iter().zip(truth) {
            assert!((e.value - t).abs() < 1e-6 * t, "{hz} Hz: {e:?}");
        }
        assert!(c.warning.is_none(), "{hz} Hz: {:?}", c.warning);
    }
    // With 0.3 kN·m and 5 kN of noise at 5 Hz (600 samples), the 90 % intervals hold the truth
    // as often as they should (20, 17, 20, 20 of 20; at least 15), the noise read within a
    // quarter.
    let mut covered = [0; 4];
    for seed in 0..20 {
        let c = calibrate(
            &drilling_record_at(5.0, 120.0, 300.0, 5e3, seed, false),
            b.radius_m,
            2000,
            seed,
        )
        .unwrap();
        let noise_kn = c.weight_edge_noise_kn.unwrap();
        assert!((noise_kn - 5.0).abs() < 1.25, "seed {seed}: {noise_kn}");
        for (k, (e, t)) in c.estimates.iter().zip(truth).enumerate() {
            covered[k] += usize::from(e.lo <= t && t <= e.hi);
        }
    }
    assert!(covered.iter().all(|&c| c >= 15), "{covered:?} of 20");
}

#[test]
fn a_steady_record_cannot_calibrate_the_bit_and_says_why() {
    let dir = tempfile::tempdir().unwrap();
    let (_, csv) = simulated_record(dir.path(), "steady.csv", 150.0, 10.0);
    let (code, _, stderr) = outcome(bin().args(["coupled", "--calibrate"]).arg(&csv));
    assert_eq!(code, 2, "{stderr}");
    assert!(
        stderr.contains("steady.csv") && stderr.contains("hardly varies") && stderr.contains("several weights"),
        "{stderr}"
    );
    // A calibrated escape map starts where the record's bit was drilling: no default knows it.
    for (given, missing) in [
        (vec!["--wob-kn", "150"], "--omega-rpm"),
        (vec!["--omega-rpm", "45"], "--wob-kn"),
    ] {
        let (code, _, stderr) = outcome(
            bin()
                .args(["coupled", "--calibrate"])
                .arg(&csv)
                .args(["--map", "--escape"])
                .args(given),
        );
        assert!(
            code == 2 && stderr.contains(missing) && stderr.contains("drilling"),
            "{stderr}"
        );
    }
}

#[test]
fn the_calibrated_bit_s_regimes_come_with_their_probabilities() {
    let dir = tempfile::tempdir().unwrap();
    let (_, record) = simulated_record(dir.path(), "rgd.csv", 45.0, 30.0);
    let (code, stdout, stderr) = outcome(
        bin()
            .args(["coupled", "--calibrate"])
            .arg(&record)
            .args([
                "--map",
                "--wob-kn",
                "150",
                "--map-rpm",
                "45:180:2",
                "--map-wob-kn",
                "150:151:2",
                "--samples",
                "4",
            ])
            .args(["--duration-s", "30", "--settle-s", "20", "--backend", "cpu", "--json"]),
    );
    assert_eq!(code, 0, "{stderr}");
    let v: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    assert_eq!(v["map"]["samples"], 4);
    assert_eq!(v["map"]["strings"], 16, "2 × 2 cells × 4 draws");
    let p = &v["map"]["probabilities"];
    // The record's own operating point stick-slips for every draw; 180 rpm drills steadily.
    assert_eq!(p[0][0]["stick_slip"], 1.0, "{p}");
    assert_eq!(p[1][0]["steady"], 1.0, "{p}");
    let e = &v["calibration"]["estimates"];
    assert!((e[0]["value"].as_f64().unwrap() - 60.0).abs() < 0.01, "{e}");
}

#[test]
fn a_stick_slipping_bit_needs_more_to_escape_than_steady_drilling_to_stay_and_the_advice_works() {
    use bitrock::run::coupled::{Settings, escape_map, map};
    let settings = Settings {
        omega_rpm: 45.0,
        wob_kn: Some(150.0),
        map_rpm: "40:120:5".into(),
        map_wob_kn: "120:160:5".into(),
        backend: Backend::Cpu,
        ..Settings::default()
    };
    let onset = map(&settings, &mut |_| {}).unwrap();
    let escape = escape_map(&settings, &mut |_| {}).unwrap();
    assert_eq!(escape.from.summary.regime, Regime::StickSlip);
    // The escape map holds the start's own speed: a 45-rpm row the onset map lacks.
    assert_eq!(onset.axes.omega_rpm, [40.0, 60.0, 80.0, 100.0, 120.0]);
    assert_eq!(escape.map.axes.omega_rpm, [40.0, 45.0, 60.0, 80.0, 100.0, 120.0]);
    // At 140 kN and 40-60 rpm steady drilling stays steady, but a bit already stick-slipping
    // at 45 rpm and 150 kN keeps stick-slipping there: the bistable band.
    let regime = |m: &[Vec<bitrock::run::coupled::SummaryReport>], i: usize, j: usize| m[i][j].regime;
    for (onset_row, escape_row) in [(0, 0), (1, 2)] {
        assert_eq!(
            regime(&onset.cells, onset_row, 2),
            Regime::Steady,
            "onset, row {onset_row}"
        );
        assert_eq!(
            regime(&escape.map.cells, escape_row, 2),
            Regime::StickSlip,
            "escape, row {escape_row}"
        );
    }
    assert_eq!(escape.advice.lighter_drive, Some(130.0), "{:?}", escape.advice);
    // The advice, applied: from the stuck state, the speed it names drills steadily for two
    // minutes, and the speed below it does not.
    let faster = escape.advice.faster_rpm.expect("a way out by speed");
    assert_eq!(faster, 80.0, "{:?}", escape.advice);
    let assembly = Assembly::default();
    let settle = Schedule::new(1e-4, 50.0, 30.0, 60.0).unwrap();
    let (_, state) = coupled::integrate_from(&assembly, &settle, &job(45.0, WOB_150_KN), None, &mut |_| {});
    let after = Schedule::new(1e-4, 50.0, 0.0, 120.0).unwrap();
    let at = |rpm: f64| coupled::integrate_from(&assembly, &after, &job(rpm, WOB_150_KN), Some(&state), &mut |_| {}).0;
    let (escaped, stayed) = (at(faster), at(60.0));
    assert!(escaped.stuck_share() < 0.01 && escaped.stick_onsets <= 1, "{escaped:?}");
    assert!(stayed.stuck_share() > 0.1, "{stayed:?}");
    assert!(
        escape.advice.words.contains("turning at 80 rpm"),
        "{}",
        escape.advice.words
    );
    // The bit calibrated on a record of it without its axial speed, 5 kN and 0.3 kN·m of noise:
    // each of 16 posterior draws' bits settled at 45 rpm and 150 kN and continued from there,
    // on a map reaching down to 100 kN. In every cell most draws do what the bit does but at
    // the bistable band's edge (at 80 rpm and 150 kN four of 16 stay stuck; at 45 rpm and 130
    // kN nine vibrate), so the way out may lie one step beyond the bit's own. Applied to the bit
    // itself from its stuck state, it works.
    let calibration =
        bitrock::fit::coupled::calibrate(&drilling_record(300.0, 5e3, 7, false), Bit::default().radius_m, 4000, 7)
            .unwrap();
    let calibrated = Settings {
        samples: 16,
        escape: true,
        map_wob_kn: "100:160:7".into(),
        ..settings.clone()
    };
    let posterior = bitrock::run::coupled::posterior_escape_map(&calibrated, &calibration, &mut |_| {}).unwrap();
    assert_eq!(posterior.from.probabilities.stick_slip, 1.0, "{:?}", posterior.from);
    let own = |i: usize, j: usize| f64::from(u8::from(escape.map.cells[i][j].regime == Regime::Steady));
    let own_wob = escape.map.axes.wob_kn.clone().unwrap();
    let (rows, columns) = (escape.map.cells.len(), own_wob.len());
    assert_eq!(posterior.map.axes.omega_rpm, escape.map.axes.omega_rpm);
    for (i, row) in posterior.map.probabilities.iter().enumerate() {
        for (w, p) in posterior.map.axes.wob_kn.clone().unwrap().iter().zip(row) {
            let Some(j) = own_wob.iter().position(|v| v == w) else {
                continue;
            };
            // Where no more than half the draws do what the bit does, the bit's own map changes
            // regime beside the cell: the band's edge.
            let neighbours = [(i.wrapping_sub(1), j), (i + 1, j), (i, j.wrapping_sub(1)), (i, j + 1)];
            let at_edge = neighbours
                .iter()
                .any(|&(a, b)| a < rows && b < columns && own(a, b) != own(i, j));
            // There the draws are split, not all against the bit.
            let agrees = (p.steady - own(i, j)).abs() < 0.5;
            assert!(
                agrees || (at_edge && p.steady > 0.0 && p.steady < 1.0),
                "{i}, {w} kN: {p:?}"
            );
        }
    }
    let advice = &posterior.advice;
    let (rpm, p) = advice.faster_rpm.expect("a way out by speed");
    assert!((rpm == 80.0 || rpm == 100.0) && p >= 0.9, "{advice:?}");
    // By weight, between the map's lightest (100 kN) and the bit's own way out (130 kN): at 45
    // rpm and 130 kN the draws are split, at the band's edge.
    let (lighter_kn, p_lighter) = advice.lighter_drive.expect("a way out by weight");
    assert!((100.0..=130.0).contains(&lighter_kn) && p_lighter >= 0.9, "{advice:?}");
    let draws = |p: f64| (p * 16.0).round();
    for way in [
        format!("turning at {rpm} rpm (it ends for {} of 16 draws)", draws(p)),
        format!(
            "the weight on bit to {lighter_kn} kN (it ends for {} of 16 draws)",
            draws(p_lighter)
        ),
    ] {
        assert!(advice.words.contains(&way), "{way} in {}", advice.words);
    }
    let escaped = at(rpm);
    assert!(escaped.stuck_share() < 0.01 && escaped.stick_onsets <= 1, "{escaped:?}");
    // Lowering the weight ends it more slowly: at the bit's own 130 kN it sticks four more
    // times in the first 22 s (which the map's 30-s settle leaves out), then drills steadily;
    // so does the posterior's weight.
    let settled_after = Schedule::new(1e-4, 50.0, 30.0, 90.0).unwrap();
    for wob_kn in [130.0, lighter_kn] {
        let lighter = coupled::integrate_from(
            &assembly,
            &settled_after,
            &job(45.0, Axial::Weight { wob_n: wob_kn * 1e3 }),
            Some(&state),
            &mut |_| {},
        )
        .0;
        assert!(
            lighter.stuck == 0 && lighter.regime() == Regime::Steady,
            "{wob_kn} kN: {lighter:?}"
        );
    }
}

#[test]
#[cfg_attr(skip_gpu_tests, ignore = "BITROCK_SKIP_GPU_TESTS=1")]
fn a_fed_bit_drills_at_the_cpu_s_rate_on_the_gpu() {
    require_gpu();
    // Under a feed the string's compression, 0.6-0.9 m here, grows by (V_f − V)·dt each step:
    // near steady drilling a few of its f32 ulps (6·10⁻⁸ m) or less than one. Added to it in
    // f32, the weight drifted and the rate of penetration with it (on lavapipe, the 2-core
    // build machine, 2026-12-06: these cells' rates off by up to 9·10⁻⁴ of the CPU's); the
    // kernel keeps the increments' low bits apart, as for the lag (within 7·10⁻⁵ there).
    let jobs: Vec<CoupledJob> = [60.0, 90.0]
        .iter()
        .flat_map(|&rpm| {
            [15.0, 30.0, 60.0].map(move |feed_m_h| {
                job(
                    rpm,
                    Axial::Feed {
                        rate_m_s: feed_m_h / 3600.0,
                    },
                )
            })
        })
        .collect();
    let assembly = Assembly::default();
    let cpu = coupled::integrate_batch(&assembly, &schedule(), &jobs, None);
    let (gpu, _) = backend::integrate(&assembly, &schedule(), &jobs, None, Backend::Gpu, &mut |_| {}).unwrap();
    for ((c, g), j) in cpu.iter().zip(&gpu).zip(&jobs) {
        let at = j.omega_rad_s / RAD_S_PER_RPM;
        assert_eq!((c.regime(), g.regime()), (Regime::Steady, Regime::Steady), "{at} rpm");
        assert!(
            (c.rate_m_s() - g.rate_m_s()).abs() < 2e-4 * c.rate_m_s(),
            "{at} rpm: {c:?}\n{g:?}"
        );
    }
}

#[test]
#[cfg_attr(skip_gpu_tests, ignore = "BITROCK_SKIP_GPU_TESTS=1")]
fn a_stuck_bit_breaks_free_when_the_cpu_s_does_on_the_gpu_at_a_fine_step() {
    require_gpu();
    // A bit held at rest while the top drive winds the string up from 70 % of its steady
    // torque: it breaks free when the lag has grown by Ω₀·t. The lag, 25-36 rad, grows by
    // Ω₀·dt (5.2·10⁻⁵ rad at 20 rpm and 2.5·10⁻⁵ s, 14 to 28 of its f32 ulps) each step:
    // added to it in f32, each step's rounding falls the same way (on lavapipe, the 2-core
    // build machine, 2026-12-06, a kernel that did so kept the bit 261 samples at rest where
    // the CPU keeps it 258). The kernel keeps the increments' low bits apart.
    let dt = 2.5e-5;
    let assembly = Assembly::default();
    let at_20 = job(20.0, WOB_150_KN);
    let steady = Schedule::new(dt, 50.0, 0.0, 0.02).unwrap();
    let (_, mut state) = coupled::integrate_from(&assembly, &steady, &at_20, None, &mut |_| {});
    state.speed_rad_s = 0.0;
    state.lag_rad *= 0.7;
    let held = Schedule::new(dt, 50.0, 0.0, 6.0).unwrap();
    let cpu = coupled::integrate_batch(&assembly, &held, &[at_20], Some(&state));
    let (gpu, _) = backend::integrate(&assembly, &held, &[at_20], Some(&state), Backend::Gpu, &mut |_| {}).unwrap();
    let (c, g) = (&cpu[0], &gpu[0]);
    assert_eq!(c.stick_onsets, 1, "one rest, then the slip: {c:?}");
    assert!(c.stuck > 100 && c.stuck < c.samples, "{c:?}");
    assert!(
        c.stuck.abs_diff(g.stuck) <= 1,
        "cpu {} samples stuck, gpu {}",
        c.stuck,
        g.stuck
    );
}

#[test]
#[cfg_attr(skip_gpu_tests, ignore = "BITROCK_SKIP_GPU_TESTS=1")]
fn the_kernel_continues_a_string_from_its_state_as_the_cpu_does() {
    require_gpu();
    let assembly = Assembly::default();
    let settle = Schedule::new(1e-4, 50.0, 0.0, 30.0).unwrap();
    let (_, state) = coupled::integrate_from(&assembly, &settle, &job(45.0, WOB_150_KN), None, &mut |_| {});
    let after = Schedule::new(1e-4, 50.0, 10.0, 40.0).unwrap();
    let jobs: Vec<_> = [(45.0, 150e3), (60.0, 150e3), (120.0, 150e3)]
        .iter()
        .map(|&(r, w)| job(r, Axial::Weight { wob_n: w }))
        .collect();
    let cpu = coupled::integrate_batch(&assembly, &after, &jobs, Some(&state));
    let (gpu, _) = backend::integrate(&assembly, &after, &jobs, Some(&state), Backend::Gpu, &mut |_| {}).unwrap();
    let regimes: Vec<_> = cpu.iter().map(|s| s.regime()).collect();
    assert_eq!(regimes, [Regime::StickSlip, Regime::StickSlip, Regime::Steady]);
    for (c, g) in cpu.iter().zip(&gpu) {
        assert_eq!(c.regime(), g.regime());
        assert!((c.stuck_share() - g.stuck_share()).abs() < 0.01, "{c:?}\n{g:?}");
        assert!(
            (c.rate_m_s() - g.rate_m_s()).abs() < 0.01 * c.rate_m_s(),
            "{c:?}\n{g:?}"
        );
    }
}

/// A bit record of `truth` ("RGD": the public bit under 150 kN; a law: its paper estimate
/// on the paper's string under W_ref) at `rpm`: 30 s at 50 Hz after 20 s from a 5-rpm kick,
/// with white noise of 1 rpm, 0.3 kN·m and 3 kN drawn from `seed`.
fn bit_record(truth: &str, rpm: f64, seed: u64) -> bitrock::data::drilling::DrillingRecord {
    use bitrock::laws::{Law, PAPER_W_REF_N};
    use bitrock::simulate::{Initial, Recording, SimConfig, simulate};
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};
    let (speed, torque, wob) = if truth == "RGD" {
        let (mut speed, mut torque, mut wob) = (Vec::new(), Vec::new(), Vec::new());
        let sched = Schedule::new(1e-4, 50.0, 20.0, 30.0).unwrap();
        let kicked = CoupledJob {
            kick_rad_s: 5.0 * RAD_S_PER_RPM,
            ..job(rpm, WOB_150_KN)
        };
        coupled::integrate_with(&Assembly::default(), &sched, &kicked, &mut |s| {
            speed.push(s.bit_speed_rad_s);
            torque.push(s.torque_nm);
            wob.push(s.wob_n);
        });
        (speed, torque, wob)
    } else {
        let law: Law = truth.parse().unwrap();
        let params = law.scale_torque(law.paper_estimate().unwrap(), 1000.0);
        let cfg = SimConfig {
            duration_s: 30.0,
            recording: Recording {
                settle_s: 20.0,
                initial: Initial::Equilibrium {
                    speed_perturbation_rad_s: 5.0 * RAD_S_PER_RPM,
                },
                ..Recording::default()
            },
            ..SimConfig::new(law, params, rpm * RAD_S_PER_RPM, PAPER_W_REF_N)
        };
        let trace = simulate(&cfg).unwrap();
        (trace.bit_speed_rad_s, trace.torque_nm, trace.wob_n)
    };
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let mut noisy = |v: Vec<f64>, sd: f64| {
        let n = Normal::new(0.0, sd).unwrap();
        v.into_iter().map(|x| x + n.sample(&mut rng)).collect::<Vec<f64>>()
    };
    bitrock::data::drilling::DrillingRecord {
        source: format!("{truth}.csv").into(),
        columns: bitrock::data::drilling::DrillingColumns {
            speed: "bit_speed_rpm".into(),
            torque: "torque_on_bit_knm".into(),
            wob: "wob_kn".into(),
            rop: None,
            axial_speed: None,
            axial_acceleration: None,
            time: None,
        },
        speed_rad_s: noisy(speed, RAD_S_PER_RPM),
        torque_nm: noisy(torque, 300.0),
        wob_n: noisy(wob, 3e3),
        rop_m_s: None,
        axial_speed_m_s: None,
        axial_acceleration_m_s2: None,
        sample_period_s: None,
        unread: Vec::new(),
    }
}

#[test]
fn the_structure_a_bit_record_shows_is_its_own_family_and_never_another_law() {
    use bitrock::run::choice::{Family, Structure, choice};
    use bitrock::run::coupled::Settings;
    // The coupled bit stick-slipping (45 and 60 rpm) and drilling steadily (120 rpm), two noise
    // draws each; the four laws on the paper's string, m1 and m2 twice; 100 candidates of each
    // structure.
    let mut called = Vec::new();
    let records = [
        ("RGD", 45.0, 2),
        ("RGD", 60.0, 2),
        ("RGD", 120.0, 2),
        ("m1", 40.0, 2),
        ("m2", 60.0, 2),
        ("m3", 60.0, 1),
        ("m4", 60.0, 1),
    ];
    for (truth, rpm, draws) in records {
        for seed in 0..draws {
            let record = bit_record(truth, rpm, seed);
            let settings = Settings {
                omega_rpm: rpm,
                settle_s: 20.0,
                reference: 100,
                replicates: 5,
                seed,
                ..Settings::default()
            };
            let c = choice(&record, &settings, &mut |_| {}).unwrap();
            let family = if truth == "RGD" {
                Family::Coupled
            } else {
                Family::Torsional
            };
            // The record's family is decided, by the check, in every record.
            assert_eq!(
                c.family.decided,
                Some(family),
                "{truth} at {rpm} rpm, seed {seed}: {}",
                c.family.verdict
            );
            // A structure called is the one that made the record.
            if let Some(s) = c.decided {
                assert_eq!(s.to_string(), truth, "{truth} at {rpm} rpm, seed {seed}: {}", c.verdict);
                called.push(s);
            }
            // The bit assembly's weight is the record's mean weight on bit.
            let mean_kn = record.wob_n.iter().sum::<f64>() / 1500.0 / 1e3;
            assert!(
                c.drive.wob_from_record && (c.drive.wob_kn - mean_kn).abs() < 1e-9,
                "{:?}",
                c.drive
            );
        }
    }
    // The coupled bit's records are told from every torsional law's, not only its family.
    assert!(
        called.iter().filter(|s| **s == Structure::Coupled).count() >= 4,
        "{called:?}"
    );
}

#[test]
fn the_choice_refuses_what_it_cannot_use_by_flag_with_nothing_written() {
    let dir = tempfile::tempdir().unwrap();
    let (_, record) = simulated_record(dir.path(), "rgd.csv", 45.0, 5.0);
    let never = dir.path().join("never.csv");
    for (args, flag) in [
        (vec!["--reference", "5"], "--reference"),
        (vec!["--replicates", "0"], "--replicates"),
        (vec!["--wob-kn", "-5"], "--wob-kn"),
        (vec!["--radius-m", "5"], "--radius-m"),
        (vec!["--zeta", "0.5"], "--zeta"),
        (vec!["--map"], "--map"),
        (vec!["--out", never.to_str().unwrap()], "--out"),
        (vec!["--calibrate", record.to_str().unwrap()], "--calibrate"),
        (vec!["--wob-col", "no_such_column"], "no_such_column"),
    ] {
        let (code, _, stderr) = outcome(
            bin()
                .args(["coupled", "--omega-rpm", "45", "--select"])
                .arg(&record)
                .args(&args),
        );
        assert_eq!(code, 2, "{args:?}: {stderr}");
        assert!(stderr.contains(flag), "{args:?}: {stderr}");
        assert!(!never.exists(), "{args:?}");
    }
    // The record's top-drive speed is needed; the choice's own flags need the record.
    let (code, _, stderr) = outcome(bin().args(["coupled", "--select"]).arg(&record));
    assert_eq!(code, 2, "{stderr}");
    assert!(stderr.contains("--omega-rpm"), "{stderr}");
    let (code, _, stderr) = outcome(bin().args(["coupled", "--omega-rpm", "45", "--reference", "50"]));
    assert_eq!(code, 2, "{stderr}");
    assert!(stderr.contains("--select"), "{stderr}");
}

#[test]
fn the_choice_from_the_surface_refuses_what_it_cannot_use_by_flag() {
    let dir = tempfile::tempdir().unwrap();
    let record = surface_record(dir.path(), "RGD", 45.0, 0.2, 0);
    let select = |args: &[&str], path: &std::path::Path| {
        outcome(
            bin()
                .args(["coupled", "--select"])
                .arg(path)
                .args(["--from-surface", "--replicates", "1"])
                .args(args),
        )
    };
    for (args, flag) in [
        (vec!["--omega-rpm", "45"], "--omega-rpm"),
        (vec!["--sample-hz", "10"], "--sample-hz"),
        (vec!["--speed-col", "bit_speed_rpm"], "--speed-col"),
        (vec!["--surface-torque-col", "no_such_column"], "no_such_column"),
        (vec!["--reference", "5"], "at least 10"),
    ] {
        let args: Vec<&str> = if args.contains(&"--reference") {
            args
        } else {
            [args, vec!["--reference", "10"]].concat()
        };
        let (code, _, stderr) = select(&args, &record);
        assert_eq!(code, 2, "{args:?}: {stderr}");
        assert!(stderr.contains(flag), "{args:?}: {stderr}");
    }
    // The surface's columns need the surface.
    let (code, _, stderr) = outcome(
        bin()
            .args(["coupled", "--omega-rpm", "45", "--select"])
            .arg(&record)
            .args(["--top-drive-col", "top_drive_rpm"]),
    );
    assert_eq!(code, 2, "{stderr}");
    assert!(stderr.contains("--from-surface"), "{stderr}");
    // A top drive that changes speed, and a record without a weight on bit, are refused by
    // what is wrong with them.
    let text = std::fs::read_to_string(&record).unwrap();
    let stepped: String = text
        .lines()
        .enumerate()
        .map(|(i, line)| if i > 300 { line.replacen(",45,", ",60,", 1) } else { line.to_string() } + "\n")
        .collect();
    let stepped_path = dir.path().join("stepped.csv");
    std::fs::write(&stepped_path, stepped).unwrap();
    let (code, _, stderr) = select(&["--reference", "10"], &stepped_path);
    assert_eq!(code, 2, "{stderr}");
    assert!(
        stderr.contains("stepped.csv") && stderr.contains("steady drive"),
        "{stderr}"
    );
    let no_wob: String = text
        .lines()
        .map(|line| line.rsplit_once(',').unwrap().0.to_string() + "\n")
        .collect();
    let no_wob_path = dir.path().join("no_wob.csv");
    std::fs::write(&no_wob_path, no_wob).unwrap();
    let (code, _, stderr) = select(&["--reference", "10"], &no_wob_path);
    assert_eq!(code, 2, "{stderr}");
    assert!(stderr.contains("--wob-kn") && stderr.contains("no_wob.csv"), "{stderr}");
    // A surface torque whose name carries no unit needs --torque-unit, which names its unit
    // here as it names the torque on bit's elsewhere. An MWD tool's column, unused by the
    // choice, is left alone (its missing unit refuses nothing).
    let unitless_path = dir.path().join("unitless.csv");
    let unitless: String = std::fs::read_to_string(&no_wob_path)
        .unwrap()
        .replacen("surface_torque_knm", "surface_torque", 1)
        .lines()
        .enumerate()
        .map(|(i, line)| format!("{line},{}\n", if i == 0 { "DRPM_MAX" } else { "50" }))
        .collect();
    std::fs::write(&unitless_path, unitless).unwrap();
    let (code, _, stderr) = select(&["--reference", "10", "--wob-kn", "150"], &unitless_path);
    assert_eq!(code, 2, "{stderr}");
    assert!(
        stderr.contains("--torque-unit") && stderr.contains("unitless.csv"),
        "{stderr}"
    );
    // Given the weight and the unit, the record is chosen from.
    let (code, stdout, stderr) = select(
        &[
            "--reference",
            "10",
            "--wob-kn",
            "150",
            "--settle-s",
            "10",
            "--torque-unit",
            "knm",
        ],
        &unitless_path,
    );
    assert_eq!(code, 0, "{stderr}");
    assert!(
        stdout.contains("of surface torque") && stdout.contains("the family:"),
        "{stdout}"
    );
}

#[test]
fn a_record_no_law_can_fit_calls_nothing_and_says_why() {
    // A bit stuck throughout: no turning sample to fit a law on.
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("stuck.csv");
    let mut rng = rand::rngs::StdRng::seed_from_u64(3);
    let noise = Normal::new(0.0, 0.3).unwrap();
    let mut text = String::from("bit_speed_rpm,torque_on_bit_knm,wob_kn\n");
    for _ in 0..1000 {
        let (w, t, f) = (noise.sample(&mut rng), noise.sample(&mut rng), noise.sample(&mut rng));
        text.push_str(&format!("{w},{},{}\n", 10.0 + t, 150.0 + 10.0 * f));
    }
    std::fs::write(&csv, text).unwrap();
    let (code, stdout, stderr) = outcome(
        bin()
            .args([
                "coupled",
                "--omega-rpm",
                "45",
                "--reference",
                "30",
                "--replicates",
                "2",
                "--json",
                "--select",
            ])
            .arg(&csv),
    );
    assert_eq!(code, 0, "{stderr}");
    let c: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    assert!(c["decided"].is_null() && c["family"]["decided"].is_null(), "{c}");
    assert!(
        c["verdict"]
            .as_str()
            .unwrap()
            .contains("m1, m2, m3, m4 had no candidate"),
        "{c}"
    );
    let notes = c["notes"].to_string();
    assert!(
        notes.contains("m3: left out") && notes.contains("0 calibration samples"),
        "{notes}"
    );
}

/// A surface record (time, top-drive speed, surface torque in kN·m with `noise_knm` of white
/// noise from `seed`, weight on bit) of 60 s at 10 Hz: the coupled bit under 150 kN (`truth`
/// "RGD") or a law at its paper estimate on the paper's string, at `rpm`; written to `dir`.
fn surface_record(dir: &std::path::Path, truth: &str, rpm: f64, noise_knm: f64, seed: u64) -> std::path::PathBuf {
    use bitrock::simulate::strings::Chain;
    use bitrock::simulate::surface::{Drive, Integration, simulate_on_clock};
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};
    let (torque_nm, wob_n): (Vec<f64>, Vec<f64>) = if truth == "RGD" {
        let mut out = (Vec::new(), Vec::new());
        let schedule = Schedule::new(1e-4, 10.0, 30.0, 60.0).unwrap();
        coupled::integrate_with(&Assembly::default(), &schedule, &job(rpm, WOB_150_KN), &mut |s| {
            out.0.push(s.surface_torque_nm);
            out.1.push(s.wob_n);
        });
        out
    } else {
        let law: bitrock::laws::Law = truth.parse().unwrap();
        let drive = Drive {
            omega_rad_s: vec![rpm * RAD_S_PER_RPM; 600],
            ratio: vec![1.0; 600],
            period_s: 0.1,
        };
        let params = law.scale_torque(law.paper_estimate().unwrap(), 1000.0);
        let integration = Integration {
            dt_s: 0.01,
            settle_s: 60.0,
        };
        let run = simulate_on_clock(&Chain::one_dof(&Lumped::default()), &drive, law, &params, integration);
        assert!(!run.diverged);
        (run.surface_torque_nm, vec![150e3; 600])
    };
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let noise = Normal::new(0.0, noise_knm).unwrap();
    let mut csv = String::from("time_s,top_drive_rpm,surface_torque_knm,wob_kn\n");
    for (i, (t, w)) in torque_nm.iter().zip(&wob_n).enumerate() {
        let torque_knm = t / 1e3 + noise.sample(&mut rng);
        csv.push_str(&format!("{:.1},{rpm},{torque_knm:.6},{:.3}\n", i as f64 * 0.1, w / 1e3));
    }
    let path = dir.join(format!("{truth}_{rpm}_{seed}.csv"));
    std::fs::write(&path, csv).unwrap();
    path
}

#[test]
fn the_choice_from_the_surface_torque_calls_nothing_the_record_did_not_come_from() {
    use bitrock::data::surface::{SurfaceOptions, SurfaceRecord};
    use bitrock::run::choice::{Channels, Family, SURFACE_SUMMARIES, Structure, surface_choice};
    use bitrock::run::coupled::Settings;
    use bitrock::simulate::surface::{N_DOWNHOLE_SUMMARIES, N_TORQUE_SUMMARIES, summaries};
    // A minute of surface torque at 10 Hz with 0.2 kN·m of noise: the coupled bit
    // stick-slipping at 45 and 60 rpm under 150 kN, each law at its paper estimate; 100
    // candidates of each structure.
    let dir = tempfile::tempdir().unwrap();
    for (truth, rpm) in [
        ("RGD", 45.0),
        ("RGD", 60.0),
        ("m1", 40.0),
        ("m2", 60.0),
        ("m3", 60.0),
        ("m4", 60.0),
    ] {
        let path = surface_record(dir.path(), truth, rpm, 0.2, 0);
        let record = SurfaceRecord::read(&path, &SurfaceOptions::default()).unwrap();
        let settings = Settings {
            settle_s: 20.0,
            reference: 100,
            ..Settings::default()
        };
        let c = surface_choice(&record, &settings, &mut |_| {}).unwrap();
        let what = format!("{truth} at {rpm} rpm: {} | {}", c.verdict, c.family.verdict);
        // The drive is the record's: its top drive, clock, weight and noise.
        let d = &c.drive;
        assert_eq!(d.channels, Channels::Surface);
        assert!((d.omega_rpm - rpm).abs() < 1e-9 * rpm, "{d:?}");
        assert_eq!(d.samples, 600);
        assert!((d.duration_s - 60.0).abs() < 1e-6, "{d:?}");
        let mean_wob_kn = record.wob_n.as_ref().unwrap().iter().sum::<f64>() / 600.0 / 1e3;
        assert!(d.wob_from_record && (d.wob_kn - mean_wob_kn).abs() < 1e-9, "{d:?}");
        assert!((d.noise_torque_knm - 0.2).abs() < 0.05, "{d:?}");
        assert_eq!((d.noise_speed_rpm, d.noise_wob_kn), (None, None));
        // The summaries are the surface sampler's of the record's torque.
        let want = summaries(
            &record.surface_torque_nm,
            record.sample_period_s,
            &[0.0; N_DOWNHOLE_SUMMARIES],
        );
        assert_eq!(c.record_summaries.len(), N_TORQUE_SUMMARIES);
        for ((name, got), (want_name, want)) in c.record_summaries.iter().zip(SURFACE_SUMMARIES.iter().zip(want)) {
            assert_eq!((name, *got), (want_name, want));
        }
        // Every candidate of the table is classified once.
        for (row, share) in c.table_check.iter().zip(&c.structures) {
            assert_eq!(row.structure, share.structure);
            assert_eq!(row.replicates, share.candidates, "{row:?}");
            assert_eq!(row.classified_as.iter().map(|x| x.1).sum::<usize>(), row.replicates);
        }
        // Nothing the record did not come from is called, and no law from the surface.
        let family = if truth == "RGD" {
            Family::Coupled
        } else {
            Family::Torsional
        };
        assert!(c.family.decided.is_none_or(|f| f == family), "{what}");
        assert!(
            c.decided.is_none_or(|s| s == Structure::Coupled && truth == "RGD"),
            "{what}"
        );
    }
}
