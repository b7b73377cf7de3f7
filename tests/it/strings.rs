//! The batched string simulator: the kernel against its CPU twin, string by string, and the
//! escape from stick-slip where independent simulations put it.

use crate::gpu::require_gpu;
use bitrock::Law;
use bitrock::bench::simulators;
use bitrock::eval::gpu::strings::{self as gpu_strings, OnClockJob};
use bitrock::eval::surface::InferredString;
use bitrock::eval::{Backend, strings};
use bitrock::laws::PAPER_W_REF_N;
use bitrock::run::strings::{Grid, OperatingPoint, SimulatedSettings, Simulator};
use bitrock::simulate::strings::STUCK_SPEED_RAD_S;
use bitrock::simulate::strings::{Chain, Schedule, StringJob, StringState, Summary, padded, steady_start};
use bitrock::simulate::surface::{
    DownholeExtremes, Drive, Integration, N_SUMMARIES, N_TORQUE_SUMMARIES, OnClock, SUMMARY_NAMES, simulate_on_clock,
    summaries,
};
use bitrock::stability::fe::DrillString;
use bitrock::stability::lumped::Lumped;
use bitrock::stability::map::LawSamples;
use bitrock::units::RAD_S_PER_RPM;

/// Kernel against twin, string by string, by `bitrock parity`'s rule: the stick-slip verdict
/// agrees on ≥ 99 % of the strings; where both are steady or both stick-slip, the stuck share
/// within 0.01 and the speed extremes within 1 % of the largest speed (f32 against f64 through a
/// chaotic cycle: measured, every verdict agrees and the shares within 0.001 on lavapipe).
fn compare(chain: &Chain, schedule: &Schedule, jobs: &[StringJob]) -> Vec<(Summary, StringState)> {
    let (cpu, _) = strings::integrate(chain, schedule, jobs, Backend::Cpu, &mut |_| {}).unwrap();
    let (gpu, ran) = strings::integrate(chain, schedule, jobs, Backend::Gpu, &mut |_| {}).unwrap();
    assert!(matches!(ran, strings::Ran::Gpu(_)));
    agree(jobs, &cpu, &gpu);
    cpu
}

/// [`compare`]'s rule on results already integrated.
fn agree(jobs: &[StringJob], cpu: &[(Summary, StringState)], gpu: &[(Summary, StringState)]) {
    let parity = simulators::compare_strings(jobs, cpu, gpu);
    assert!(parity.pass, "{parity:#?}");
}

/// Both kinds of string are in the batch the CPU twin integrated: the comparison saw cycles
/// and steady rotation.
fn assert_both_kinds(cpu: &[(Summary, StringState)]) {
    let slipping = cpu.iter().filter(|r| r.0.stick_slips()).count();
    assert!(
        slipping > cpu.len() / 5 && slipping < cpu.len() * 4 / 5,
        "{slipping} of {}",
        cpu.len()
    );
}

#[test]
#[cfg_attr(skip_gpu_tests, ignore = "BITROCK_SKIP_GPU_TESTS=1")]
fn the_kernel_integrates_the_1dof_string_as_its_cpu_twin_does() {
    require_gpu();
    let chain = Chain::one_dof(&Lumped::default());
    // `bitrock parity`'s strings and schedule.
    let schedule = simulators::string_parity_schedule();
    let all = simulators::string_parity_jobs(&chain);
    // Every law in one batch (the law read per string), then each law's own batch (the law
    // compiled into the kernel).
    assert_both_kinds(&compare(&chain, &schedule, &all));
    for law in Law::ALL {
        let own: Vec<StringJob> = all.iter().filter(|j| j.law == law).cloned().collect();
        compare(&chain, &schedule, &own);
    }
}

#[test]
#[cfg_attr(skip_gpu_tests, ignore = "BITROCK_SKIP_GPU_TESTS=1")]
fn the_kernel_integrates_the_lumped_fe_string_as_its_cpu_twin_does() {
    require_gpu();
    // The paper's 2-element string: a top node above the bit (lavapipe runs the wider chains'
    // arrays slowly; the 10-element string is the benchmark's).
    let chain = Chain::lumped_fe(&DrillString::default()).unwrap();
    let jobs: Vec<StringJob> = simulators::string_parity_jobs(&chain).into_iter().step_by(2).collect();
    let schedule = Schedule::new(0.01, 50.0, 30.0, 20.0).unwrap();
    assert_both_kinds(&compare(&chain, &schedule, &jobs));
}

#[test]
#[cfg_attr(skip_gpu_tests, ignore = "BITROCK_SKIP_GPU_TESTS=1")]
fn the_kernel_integrates_the_ten_element_string_through_every_slice_of_its_steps() {
    require_gpu();
    // The benchmark's string: ten nodes at 1e-4 s, 200 steps a sample, 10,000 steps in all.
    // lavapipe counts the loops over the nodes against an invocation's 65,535 iterations, so
    // the host slices the steps by the chain's length: every sample must come back.
    let fe = DrillString {
        dp_elements: 8,
        bha_elements: 2,
        ..DrillString::default()
    };
    let chain = Chain::lumped_fe(&fe).unwrap();
    assert_eq!(chain.nodes(), 10);
    let jobs: Vec<StringJob> = simulators::string_parity_jobs(&chain).into_iter().step_by(10).collect();
    let schedule = Schedule::new(1e-4, 50.0, 0.2, 0.8).unwrap();
    let (cpu, _) = strings::integrate(&chain, &schedule, &jobs, Backend::Cpu, &mut |_| {}).unwrap();
    let gpu = gpu_strings::integrate_batch(&chain, &schedule, &jobs).unwrap();
    agree(&jobs, &cpu, &gpu);
    assert!(cpu.iter().all(|(s, _)| !s.diverged && s.samples == 40));
    // Slicing changes no result: slices of 1,500 steps (which lavapipe cuts, so that the chunk
    // runs again in shorter ones) give the summaries and states of the slices above (370 steps,
    // ending inside sample periods) to the bit.
    let sliced = gpu_strings::integrate_batch_in_slices(&chain, &schedule, &jobs, 1_500).unwrap();
    assert!(sliced == gpu);
}

#[test]
#[cfg_attr(skip_gpu_tests, ignore = "BITROCK_SKIP_GPU_TESTS=1")]
fn auto_leaves_a_chain_of_nodes_to_the_cpu_only_where_the_gpu_is_a_software_driver() {
    require_gpu();
    let software = bitrock::eval::gpu::context().unwrap().is_software();
    let schedule = Schedule::new(0.01, 50.0, 1.0, 2.0).unwrap();
    let one_dof = Chain::one_dof(&Lumped::default());
    let chain_of = |dp_elements, bha_elements| {
        Chain::lumped_fe(&DrillString {
            dp_elements,
            bha_elements,
            ..DrillString::default()
        })
        .unwrap()
    };
    let (four, five) = (chain_of(3, 1), chain_of(3, 2));
    assert_eq!(
        (four.nodes(), five.nodes()),
        (strings::SOFTWARE_GPU_MAX_NODES, strings::SOFTWARE_GPU_MAX_NODES + 1)
    );
    for (chain, on_cpu) in [(&one_dof, false), (&four, false), (&five, software)] {
        let all = simulators::string_parity_jobs(chain);
        let mut notes = Vec::new();
        let (auto, ran) =
            strings::integrate(chain, &schedule, &all[..8], Backend::Auto, &mut |n| notes.push(n)).unwrap();
        assert_eq!(ran == strings::Ran::Cpu, on_cpu, "{} nodes: {ran}", chain.nodes());
        let said = notes
            .iter()
            .any(|n| n.contains("nodes on the CPU rather than the software GPU"));
        assert_eq!(said, on_cpu, "{notes:?}");
        if on_cpu {
            let (cpu, _) = strings::integrate(chain, &schedule, &all[..8], Backend::Cpu, &mut |_| {}).unwrap();
            assert_eq!(auto, cpu);
        }
    }
}

/// `bench --strings` measures the GPU where `auto` would simulate on it: by default a software
/// driver's row for the ten-element string is left out, saying so (that chain runs on the CPU
/// under `auto`); a hardware GPU is measured on both chains. (`--backend gpu` is not run here:
/// lavapipe takes about 30 s to compile the ten-node kernel from an empty shader cache.)
#[test]
#[cfg_attr(skip_gpu_tests, ignore = "BITROCK_SKIP_GPU_TESTS=1")]
fn bench_strings_measures_the_gpu_where_auto_would_simulate_on_it() {
    use crate::support::{bin, outcome};
    require_gpu();
    let software = bitrock::eval::gpu::context().unwrap().is_software();
    let args = ["bench", "--strings", "--quick", "--strings-n", "16", "--reps", "1"];
    let (code, stdout, stderr) = outcome(bin().args(args));
    assert_eq!(code, 0, "{stderr}");
    let row = |out: &str, string: &str, backend: &str| {
        out.lines()
            .any(|l| l.starts_with("throughput") && l.contains(&format!(" {string} ")) && l.contains(backend))
    };
    for string in ["1dof", "fe"] {
        assert!(row(&stdout, string, " cpu "), "{string}: {stdout}");
    }
    assert!(row(&stdout, "1dof", " gpu ("), "{stdout}");
    assert_eq!(row(&stdout, "fe", " gpu ("), !software, "{stdout}");
    assert_eq!(
        stderr.contains("strings fe on the GPU not measured") && stderr.contains("(measured with --backend gpu)"),
        software,
        "{stderr}"
    );
}

/// m2 at the paper's estimate and 244 kN, in stick-slip at 60 rpm: the simulated escape.
fn m2_escape(backend: Backend) -> (Grid, f64) {
    let law = Law::M2;
    let p = law.scale_torque(law.paper_estimate().unwrap(), 1000.0);
    let inputs = vec![LawSamples {
        law,
        probability: 1.0,
        map_si: p.clone(),
        samples_si: vec![p],
        strings: Vec::new(),
    }];
    let settings = SimulatedSettings::new(Chain::one_dof(&Lumped::default()), PAPER_W_REF_N, backend);
    let mut note = |_| {};
    let mut sim = Simulator::new(&settings, &inputs, &mut note).unwrap();
    let at = sim
        .at_point(OperatingPoint {
            omega_rpm: 60.0,
            wob_kn: 244.2,
        })
        .unwrap();
    let grid = sim.escape(&at, &[85.0, 120.0, 150.0], &[244.2]).unwrap();
    (grid, at.stick_slip_probability)
}

#[test]
fn m2_escapes_stick_slip_between_85_and_150_rpm() {
    // An independent simulator (LSODA) and `simulate --well` keep the bit stuck a third of the
    // time at 85 rpm and free it at 150 rpm; the linear criterion calls 85 rpm stable.
    let (grid, now) = m2_escape(Backend::Cpu);
    assert_eq!(now, 1.0, "the bit stick-slips at 60 rpm in every phase");
    assert_eq!(grid.at(0, 0), 1.0, "85 rpm: stick-slip persists");
    assert_eq!(grid.at(2, 0), 0.0, "150 rpm: it ends");
    // The linear criterion's onset for m2 at r = 1 (8.27 rad/s = 79 rpm) lies below 85 rpm:
    // 85 rpm is in the bistable band.
    let p = Law::M2.scale_torque(Law::M2.paper_estimate().unwrap(), 1000.0);
    let c_b = Law::M2.dtorque_dw(&p, 85.0 * RAD_S_PER_RPM, 1.0);
    assert!(!Lumped::default().is_unstable(c_b));
}

#[test]
#[cfg_attr(skip_gpu_tests, ignore = "BITROCK_SKIP_GPU_TESTS=1")]
fn the_escape_map_is_the_same_on_the_gpu() {
    require_gpu();
    let (cpu, _) = m2_escape(Backend::Cpu);
    let (gpu, now) = m2_escape(Backend::Gpu);
    assert_eq!(now, 1.0);
    // A driver may fuse and reassociate: one phase of eight may fall the other way at a cell.
    for (c, g) in cpu.probability.iter().zip(&gpu.probability) {
        assert!(
            (c - g).abs() <= 0.125 + 1e-12,
            "cpu {:?}, gpu {:?}",
            cpu.probability,
            gpu.probability
        );
    }
}

/// The nearest cell of `axis` (in its order) where the strings end stick-slip with the advice's
/// confidence, read off a whole scan.
fn nearest_ending(axis: &[f64], scan: &Grid, reversed: bool) -> Option<(f64, f64)> {
    let mut cells: Vec<(f64, f64)> = (0..axis.len())
        .map(|k| (axis[k], 1.0 - scan.stick_slip_weight[k] - scan.diverged_weight[k]))
        .collect();
    if reversed {
        cells.reverse();
    }
    cells
        .into_iter()
        .find(|(_, p)| *p >= bitrock::run::strings::ADVICE_CONFIDENCE)
}

#[test]
fn the_advice_stops_its_scans_where_a_change_ends_stick_slip_and_says_what_the_whole_scans_say() {
    // On two threads, a cell at a time (16 strings a cell): where the scans stop does not
    // depend on the machine's cores.
    let two = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();
    two.install(advice_against_whole_scans);
}

/// m2 and m3 stick-slipping at 60 rpm: the advice's scans against the whole scans.
fn advice_against_whole_scans() {
    // m2 and m3 at their paper estimates, stick-slipping at 60 rpm and 244 kN.
    let inputs: Vec<LawSamples> = [Law::M2, Law::M3]
        .into_iter()
        .map(|law| {
            let p = law.scale_torque(law.paper_estimate().unwrap(), 1000.0);
            LawSamples {
                law,
                probability: 0.5,
                map_si: p.clone(),
                samples_si: vec![p],
                strings: Vec::new(),
            }
        })
        .collect();
    let settings = SimulatedSettings::new(Chain::one_dof(&Lumped::default()), PAPER_W_REF_N, Backend::Cpu);
    let mut note = |_| {};
    let mut sim = Simulator::new(&settings, &inputs, &mut note).unwrap();
    let point = OperatingPoint {
        omega_rpm: 60.0,
        wob_kn: 244.2,
    };
    let at = sim.at_point(point).unwrap();
    let speeds = bitrock::run::strings::advice_speeds_rpm(point.omega_rpm);
    let weights = bitrock::run::strings::advice_weights_kn(point.wob_kn);
    let advice = sim.escape_advice(&at, &speeds, &weights).unwrap();
    let whole_speeds = sim.escape(&at, &speeds, &[point.wob_kn]).unwrap();
    let whole_weights = sim.escape(&at, &[point.omega_rpm], &weights).unwrap();
    let by_speed = nearest_ending(&speeds, &whole_speeds, false).expect("a speed scanned ends it");
    let way = advice.speed_rpm.expect("the advice finds the speed");
    assert_eq!((way.to, way.ends_probability), by_speed);
    // The scan stopped short of the top speed, its cells the whole scan's first ones.
    let scanned = advice.speed_scan.omega_rpm.len();
    assert!(scanned < speeds.len(), "{scanned} of {} speeds", speeds.len());
    assert_eq!(advice.speed_scan.omega_rpm, speeds[..scanned]);
    assert_eq!(
        advice.speed_scan.stick_slip_weight,
        whole_speeds.stick_slip_weight[..scanned]
    );
    // The weights go down from the operating point: the same nearest (or none).
    let by_weight = nearest_ending(&weights, &whole_weights, true);
    assert_eq!(advice.wob_kn.map(|w| (w.to, w.ends_probability)), by_weight);
    let kept = advice.wob_scan.wob_kn.len();
    assert_eq!(advice.wob_scan.wob_kn, weights[weights.len() - kept..]);
    assert_eq!(
        advice.wob_scan.stick_slip_weight,
        whole_weights.stick_slip_weight[weights.len() - kept..]
    );
}

/// The summaries a surface run compares, of a string on a record's clock.
fn clock_summaries(run: &OnClock, period_s: f64) -> [f64; N_SUMMARIES] {
    let tool = DownholeExtremes {
        window_samples: 3,
        least: true,
        greatest: true,
    };
    summaries(&run.surface_torque_nm, period_s, &tool.summaries_of(run))
}

#[test]
#[cfg_attr(skip_gpu_tests, ignore = "BITROCK_SKIP_GPU_TESTS=1")]
fn the_kernel_drives_strings_on_a_record_s_clock_as_its_cpu_twin_does() {
    require_gpu();
    // A record's drive at 1 Hz: 60 rpm under r = 1 for 90 s, then 120 rpm under r = 0.8 for
    // 90 s (m2 stick-slips, then turns steadily). Every law, each at two strings of its own
    // (the paper's, and one stiffer and less damped), and m4 at 400 rpm, which runs away.
    let mut omega = vec![60.0 * RAD_S_PER_RPM; 90];
    omega.extend(vec![120.0 * RAD_S_PER_RPM; 90]);
    let mut ratio = vec![1.0; 90];
    ratio.extend(vec![0.8; 90]);
    let drive = Drive {
        omega_rad_s: omega,
        ratio,
        period_s: 1.0,
    };
    let integration = Integration::default();
    let paper = Lumped::default();
    let stiffer = Lumped {
        omega_n_rad_s: 1.3 * paper.omega_n_rad_s,
        damping_ratio: 0.5 * paper.damping_ratio,
        ..paper
    };
    let chains = [Chain::one_dof(&paper), Chain::one_dof(&stiffer)];
    let params: Vec<(Law, Vec<f64>)> = Law::ALL
        .iter()
        .map(|&law| (law, law.scale_torque(law.paper_estimate().unwrap(), 1000.0)))
        .collect();
    let mut jobs: Vec<OnClockJob<'_>> = Vec::new();
    for (law, p) in &params {
        for chain in &chains {
            jobs.push(OnClockJob {
                law: *law,
                params_nm: p,
                chain,
            });
        }
    }
    let gpu = gpu_strings::on_clock_batch(&drive, integration, &jobs).unwrap();
    let share = |r: &OnClock| {
        r.bit_speed_rad_s.iter().filter(|w| w.abs() < STUCK_SPEED_RAD_S).count() as f64 / r.bit_speed_rad_s.len() as f64
    };
    let (mut slipping, mut steady) = (0, 0);
    for (job, g) in jobs.iter().zip(&gpu) {
        let c = simulate_on_clock(job.chain, &drive, job.law, job.params_nm, integration);
        let what = format!("{} on k = {:.0} N·m/rad", job.law, job.chain.stiffness_nm_per_rad[0]);
        assert!(!c.diverged && !g.diverged, "{what}");
        assert_eq!(c.surface_torque_nm.len(), g.surface_torque_nm.len(), "{what}");
        // Phase-blind, as the surface run compares them: the torque's mean and quantiles
        // within 1 % of the torque's range, the stuck share and the held share within 0.02, the
        // cycle's period within 3 %, the speeds' means within 1 % of the largest speed
        // (measured on lavapipe: the same stuck shares, the means within 4·10⁻⁷ of their
        // values, the periods within 10⁻⁶ s).
        let (sc, sg) = (clock_summaries(&c, 1.0), clock_summaries(g, 1.0));
        let range = sc[6] - sc[2] + 0.01 * sc[0].abs();
        for j in [0, 2, 3, 4, 5, 6] {
            assert!(
                (sc[j] - sg[j]).abs() <= 0.01 * range,
                "{what}: {} {} vs {}",
                SUMMARY_NAMES[j],
                sc[j],
                sg[j]
            );
        }
        assert!(
            (share(&c) - share(g)).abs() <= 0.02,
            "{what}: stuck {} vs {}",
            share(&c),
            share(g)
        );
        // The wind-up rate within 1 % of itself (the selection by the neighbours' signs is
        // the same where no change lies at 0).
        let wind_up = N_TORQUE_SUMMARIES - 1;
        assert_eq!(SUMMARY_NAMES[wind_up], "wind_up_nm_s");
        assert!(
            (sc[wind_up] - sg[wind_up]).abs() <= 0.01 * sc[wind_up].abs() + 1.0,
            "{what}: wind-up {} vs {}",
            sc[wind_up],
            sg[wind_up]
        );
        let (least, held) = (N_TORQUE_SUMMARIES, N_TORQUE_SUMMARIES + 1);
        assert!(
            (sc[held] - sg[held]).abs() <= 0.02,
            "{what}: held {} vs {}",
            sc[held],
            sg[held]
        );
        assert!(
            (sc[11] - sg[11]).abs() <= 0.03 * sc[11].max(1.0),
            "{what}: period {} vs {}",
            sc[11],
            sg[11]
        );
        let fastest = sc[N_SUMMARIES - 1].max(120.0 * RAD_S_PER_RPM);
        for j in [least, least + 2, least + 3] {
            assert!(
                (sc[j] - sg[j]).abs() <= 0.01 * fastest,
                "{what}: {} {} vs {}",
                SUMMARY_NAMES[j],
                sc[j],
                sg[j]
            );
        }
        // Steady at 120 rpm: sample by sample, within 10⁻³ of the torque and of the speed.
        for k in 150..180 {
            let (tc, tg) = (c.surface_torque_nm[k], g.surface_torque_nm[k]);
            let (wc, wg) = (c.bit_speed_rad_s[k], g.bit_speed_rad_s[k]);
            if (wc - 120.0 * RAD_S_PER_RPM).abs() < 0.01 {
                assert!((tc - tg).abs() <= 1e-3 * tc.abs(), "{what}: sample {k}: {tc} vs {tg}");
                assert!((wc - wg).abs() <= 1e-3 * wc, "{what}: sample {k}: {wc} vs {wg}");
                steady += 1;
            }
        }
        slipping += usize::from(share(&c) > 0.1);
    }
    assert!(steady >= 30, "{steady} steady samples compared");
    assert!(
        slipping >= 2 && slipping < jobs.len(),
        "{slipping} of {} stick-slip",
        jobs.len()
    );
    // A law that runs away is said so on both, with the samples up to where it left bounds.
    let m4 = Law::M4.scale_torque(Law::M4.paper_estimate().unwrap(), 1000.0);
    let fast = Drive {
        omega_rad_s: vec![400.0 * RAD_S_PER_RPM; 60],
        ratio: vec![1.0; 60],
        period_s: 1.0,
    };
    let runaway = [OnClockJob {
        law: Law::M4,
        params_nm: &m4,
        chain: &chains[0],
    }];
    let c = simulate_on_clock(&chains[0], &fast, Law::M4, &m4, integration);
    let g = &gpu_strings::on_clock_batch(&fast, integration, &runaway).unwrap()[0];
    assert!(c.diverged && g.diverged, "cpu {} gpu {}", c.diverged, g.diverged);

    // A record longer than one dispatch integrates (a software driver ends an invocation's
    // loops after 65,535 iterations): 1,400 s of m2 at 60 rpm, 73,000 steps, to its last
    // sample on both, with the same stuck share; a string with no settling, whose first sample
    // is the string at rest; and one whose settling fills one slice exactly.
    let m2 = &params[1].1;
    let long = Drive {
        omega_rad_s: vec![60.0 * RAD_S_PER_RPM; 1400],
        ratio: vec![1.0; 1400],
        period_s: 1.0,
    };
    let unsettled = Integration {
        settle_s: 0.0,
        ..integration
    };
    // A settling of exactly one slice (6,000 steps of 20 ms): a slice ends with the settling.
    let one_slice = Integration {
        settle_s: 120.0,
        ..integration
    };
    for (drive, integration) in [(&long, integration), (&drive, unsettled), (&drive, one_slice)] {
        let job = [OnClockJob {
            law: Law::M2,
            params_nm: m2,
            chain: &chains[0],
        }];
        let c = simulate_on_clock(&chains[0], drive, Law::M2, m2, integration);
        let g = &gpu_strings::on_clock_batch(drive, integration, &job).unwrap()[0];
        assert!(!c.diverged && !g.diverged);
        if std::ptr::eq(drive, &long) {
            // The whole record asked of one dispatch (73,000 steps: more iterations than a
            // software driver lets an invocation's loops run; the chunk comes back short of its
            // samples or told cut, and runs again in shorter slices): the same bits as the
            // default slices.
            let whole = &gpu_strings::on_clock_batch_in_slices(drive, integration, &job, 100_000).unwrap()[0];
            let bits = |r: &OnClock| {
                let columns = [
                    &r.surface_torque_nm,
                    &r.bit_speed_rad_s,
                    &r.bit_least_rad_s,
                    &r.bit_greatest_rad_s,
                ];
                let words: Vec<Vec<u64>> = columns
                    .iter()
                    .map(|c| c.iter().map(|v| v.to_bits()).collect())
                    .collect();
                (words, r.diverged)
            };
            assert!(bits(whole) == bits(g), "one slice and the default slices differ");
        }
        assert_eq!(g.surface_torque_nm.len(), drive.omega_rad_s.len());
        assert!(
            (share(&c) - share(g)).abs() <= 0.02,
            "stuck {} vs {}",
            share(&c),
            share(g)
        );
        if integration.settle_s == 0.0 {
            // At rest: the top element's damping alone, β·k·Ω.
            let at_rest = chains[0].beta_s * chains[0].stiffness_nm_per_rad[0] * drive.omega_rad_s[0];
            let (tc, tg) = (c.surface_torque_nm[0], g.surface_torque_nm[0]);
            assert!((tc - at_rest).abs() <= 1e-9 * at_rest, "first sample {tc} vs {at_rest}");
            assert!((tg - at_rest).abs() <= 1e-6 * at_rest, "first sample {tg} vs {at_rest}");
        }
    }
}

#[test]
#[cfg_attr(skip_gpu_tests, ignore = "BITROCK_SKIP_GPU_TESTS=1")]
fn a_string_longer_than_one_dispatch_is_integrated_to_its_end() {
    require_gpu();
    // 700 s at 0.01 s: 70,000 steps, past the 65,535 loop iterations a software driver allows
    // an invocation. The kernel integrates it in slices, its state and summary carried between
    // them: every sample, as the twin's (compare's tolerances).
    let chain = Chain::one_dof(&Lumped::default());
    let schedule = Schedule::new(0.01, 1.0, 0.0, 700.0).unwrap();
    let omega = 60.0 * RAD_S_PER_RPM;
    let jobs: Vec<StringJob> = [Law::M2, Law::M3]
        .into_iter()
        .map(|law| {
            let p = padded(&law.scale_torque(law.paper_estimate().unwrap(), 1000.0));
            StringJob {
                law,
                params_nm: p,
                omega_rad_s: omega,
                ratio: 1.0,
                start: steady_start(&chain, law, &p, omega, 1.0, 0.1 * omega),
            }
        })
        .collect();
    let cpu = compare(&chain, &schedule, &jobs);
    assert!(cpu.iter().all(|(s, _)| s.samples == 700 && s.stick_slips()));
}

/// m2 at the paper's estimate settled in stick-slip at 60 rpm and 244 kN on the strings
/// `strings` (ω_n rad/s, ξ), one sample each on the paper's inertia: P(stick-slip at the
/// point) and P(it persists) at 85, 100, 120, 135 and 150 rpm. `inferred`: the samples carry
/// their strings (the settings infer it), else the one string alone.
fn m2_on_strings(strings: &[(f64, f64)], inferred: bool, backend: Backend) -> (f64, Vec<f64>) {
    let law = Law::M2;
    let p = law.scale_torque(law.paper_estimate().unwrap(), 1000.0);
    let paper = Lumped::default();
    let inputs = vec![LawSamples {
        law,
        probability: 1.0,
        map_si: p.clone(),
        samples_si: vec![p.clone(); strings.len()],
        strings: if inferred {
            strings.iter().map(|&(w, xi)| [w, xi]).collect()
        } else {
            Vec::new()
        },
    }];
    let (w, xi) = strings[0];
    let one = Lumped {
        omega_n_rad_s: w,
        damping_ratio: xi,
        ..paper
    };
    // Where inferred, the settings' string is the paper's, which no sample is on.
    let chain = Chain::one_dof(if inferred { &paper } else { &one });
    let settings = SimulatedSettings {
        string: inferred.then_some(InferredString {
            inertia_kg_m2: paper.inertia_kg_m2,
            omega_n_rad_s: None,
            damping_ratio: None,
        }),
        ..SimulatedSettings::new(chain, PAPER_W_REF_N, backend)
    };
    let mut note = |_| {};
    let mut sim = Simulator::new(&settings, &inputs, &mut note).unwrap();
    let at = sim
        .at_point(OperatingPoint {
            omega_rpm: 60.0,
            wob_kn: 244.2,
        })
        .unwrap();
    let grid = sim.escape(&at, &[85.0, 100.0, 120.0, 135.0, 150.0], &[244.2]).unwrap();
    (at.stick_slip_probability, grid.probability)
}

#[test]
fn each_sample_is_simulated_on_its_own_string_where_the_string_was_inferred() {
    // The string decides where stick-slip ends as much as the law: measured, the paper's
    // string (0.85 rad/s, ξ 0.25) keeps m2's bit stuck up to 120 rpm, a softer one (0.5) up
    // to 150, a stiffer one (1.5) nowhere from 85 rpm up.
    let strings = [(0.85, 0.25), (0.5, 0.25), (1.5, 0.25)];
    let alone: Vec<(f64, Vec<f64>)> = strings
        .iter()
        .map(|s| m2_on_strings(&[*s], false, Backend::Cpu))
        .collect();
    assert!(
        alone[0].1[2] > 0.5,
        "the paper's string is still stuck at 120 rpm: {:?}",
        alone[0]
    );
    assert_eq!(
        alone[0].1[4], 0.0,
        "the paper's string escapes by 150 rpm: {:?}",
        alone[0]
    );
    assert!(
        alone[1].1[4] > 0.5,
        "the softer string is still stuck at 150 rpm: {:?}",
        alone[1]
    );
    assert_eq!(
        alone[2].1,
        vec![0.0; 5],
        "the stiffer string escapes at 85 rpm: {:?}",
        alone[2]
    );
    // One sample carrying its string is that string alone, exactly: phases and all.
    for (s, one) in strings.iter().zip(&alone) {
        assert_eq!(&m2_on_strings(&[*s], true, Backend::Cpu), one, "{s:?}");
    }
    // Two samples weigh their own strings alike: cell by cell, the mean of the strings alone
    // (each met at as many phases as alone, over its own string's period).
    let (now, mixed) = m2_on_strings(&strings[..2], true, Backend::Cpu);
    let mean = |k: usize| (alone[0].1[k] + alone[1].1[k]) / 2.0;
    assert!((now - (alone[0].0 + alone[1].0) / 2.0).abs() < 1e-12);
    for (k, p) in mixed.iter().enumerate() {
        assert!((p - mean(k)).abs() < 1e-12, "cell {k}: {p} against {}", mean(k));
    }
}

#[test]
fn thinned_samples_keep_their_own_strings() {
    use bitrock::run::strings::thinned;
    let samples_si: Vec<Vec<f64>> = (0..10).map(|k| vec![k as f64, 0.0, 0.0]).collect();
    let strings: Vec<[f64; 2]> = (0..10).map(|k| [0.5 + 0.1 * k as f64, k as f64]).collect();
    let inputs = vec![LawSamples {
        law: Law::M2,
        probability: 1.0,
        map_si: vec![0.0; 3],
        samples_si,
        strings,
    }];
    let kept = &thinned(&inputs, 3, 0.0)[0];
    assert_eq!((kept.samples_si.len(), kept.strings.len()), (3, 3));
    for (sample, string) in kept.samples_si.iter().zip(&kept.strings) {
        assert_eq!(sample[0], string[1], "{kept:?}");
    }
}

#[test]
#[cfg_attr(skip_gpu_tests, ignore = "BITROCK_SKIP_GPU_TESTS=1")]
fn samples_on_their_own_strings_escape_alike_on_the_gpu() {
    require_gpu();
    let strings = [(0.85, 0.25), (0.5, 0.25)];
    let (cpu_now, cpu) = m2_on_strings(&strings, true, Backend::Cpu);
    let (gpu_now, gpu) = m2_on_strings(&strings, true, Backend::Gpu);
    assert_eq!((cpu_now, gpu_now), (1.0, 1.0));
    // A driver may fuse and reassociate: one phase of sixteen strings may fall the other way.
    for (c, g) in cpu.iter().zip(&gpu) {
        assert!((c - g).abs() <= 0.0625 + 1e-12, "cpu {cpu:?}, gpu {gpu:?}");
    }
}
