//! The GPU backend against the CPU reference: shaders valid without a device, Philox and
//! candidates bit for bit, ρ within the parity tolerance, whole runs alike. These tests need a
//! GPU adapter (Mesa's lavapipe is enough: scripts/test.sh installs it) and fail loudly without
//! one, unless BITROCK_SKIP_GPU_TESTS=1. Every test that scores runs once per scoring shape
//! (`per_shape!`: `NAME::blocked`, `NAME::tiled`), whatever shape the adapter would pick.

use bitrock::Law;
use bitrock::abc::rejection::{self, RejectionConfig};
use bitrock::abc::schedule::Schedule;
use bitrock::data::{DataOptions, demo_field_data};
use bitrock::eval::cpu::CpuEvaluator;
use bitrock::eval::gpu::{self, Shape, candidates, residual::GpuEvaluator};
use bitrock::eval::{Evaluator, PARITY_TOLERANCE, Problem};
use bitrock::fit::{FitOptions, fit_laws};
use bitrock::prior::{MAX_DIMS, Prior};

/// Stops a GPU test with what to do when no adapter exists. Built with
/// BITROCK_SKIP_GPU_TESTS=1, the GPU tests are compiled as ignored instead (see `build.rs`).
pub(crate) fn require_gpu() {
    match gpu::context() {
        Ok(ctx) => eprintln!("GPU tests on {}", ctx.describe()),
        Err(e) => panic!(
            "GPU tests need a GPU adapter and found none ({e}). Run ./scripts/test.sh, which installs Mesa's lavapipe \
             (apt-get install mesa-vulkan-drivers libvulkan1), or set BITROCK_SKIP_GPU_TESTS=1 to skip them."
        ),
    }
}

/// Stamps out each `fn name(shape: Shape) { ... }` as a module `name` with one test per
/// scoring shape, `name::blocked` and `name::tiled`.
macro_rules! per_shape {
    ($($(#[$doc:meta])* fn $name:ident($shape:ident: Shape) $body:block)*) => {
        $(
            $(#[$doc])*
            mod $name {
                use super::*;

                fn run($shape: Shape) $body

                #[test]
                #[cfg_attr(skip_gpu_tests, ignore = "BITROCK_SKIP_GPU_TESTS=1")]
                fn blocked() {
                    run(Shape::Blocked)
                }

                #[test]
                #[cfg_attr(skip_gpu_tests, ignore = "BITROCK_SKIP_GPU_TESTS=1")]
                fn tiled() {
                    run(Shape::Tiled)
                }
            }
        )*
    };
}

pub(crate) use per_shape;

/// The evaluator of `problem` in `shape`.
fn gpu_evaluator(problem: &Problem, shape: Shape) -> GpuEvaluator {
    GpuEvaluator::with_shape(problem.clone(), shape).unwrap()
}

#[test]
fn every_shader_parses_and_validates_with_naga() {
    for (name, source, entry_points) in gpu::kernel_sources() {
        let module =
            naga::front::wgsl::parse_str(&source).unwrap_or_else(|e| panic!("{name}: {}", e.emit_to_string(&source)));
        bitrock::eval::gpu::validator::validator(name)
            .validate(&module)
            .unwrap_or_else(|e| panic!("{name}: {}", e.emit_to_string(&source)));
        for entry in entry_points {
            assert!(
                module.entry_points.iter().any(|e| e.name == *entry),
                "{name} has no entry point {entry}"
            );
        }
    }
}

/// The demo record in full (5,374 samples ≥ 5,000) and the paper's priors (δ = 0.4) for `laws`.
pub(crate) fn demo_problem(laws: &[Law], seed: u64) -> Problem {
    let data = demo_field_data(&DataOptions {
        calibration_fraction: 1.0,
        ..Default::default()
    })
    .unwrap();
    let fits = fit_laws(laws, &data.calibration, &data.validation, &FitOptions::default()).unwrap();
    let prior = Prior::from_fits(&fits, 0.4, None, 1000.0).unwrap();
    Problem::new(prior, seed, &data.calibration, None)
}

#[test]
#[cfg_attr(skip_gpu_tests, ignore = "BITROCK_SKIP_GPU_TESTS=1")]
fn philox_words_and_candidates_are_identical_bit_for_bit() {
    require_gpu();
    let problem = demo_problem(&Law::ALL, 0x1234_5678_9abc_def0);
    // 131,072 candidates × 8 Philox words = 1,048,576 words; the start crosses 2³² so the
    // high counter word is exercised.
    let start = (1u64 << 32) - 65_536;
    let count = 131_072u32;
    let got = candidates::generate(&problem.prior, problem.seed, 7, start, count).unwrap();
    let key = bitrock::rng::key_of_seed(problem.seed);
    for (k, g) in got.iter().enumerate() {
        let index = start + k as u64;
        let b0 = bitrock::rng::philox4x32_10(bitrock::rng::candidate_counter(7, index, 0), key);
        let b1 = bitrock::rng::philox4x32_10(bitrock::rng::candidate_counter(7, index, 1), key);
        assert_eq!(g.philox[..4], b0, "block 0 of candidate {index}");
        assert_eq!(g.philox[4..], b1, "block 1 of candidate {index}");
        let c = problem.prior.candidate(problem.seed, 7, index);
        assert_eq!(g.slot as usize, c.slot, "law of candidate {index}");
        let n = problem.prior.boxes[c.slot].lower.len();
        for j in 0..n {
            assert_eq!(
                g.param_bits[j],
                c.params[j].to_bits(),
                "parameter {j} of candidate {index}"
            );
        }
    }
}

/// Largest and median relative difference of ρ between backends over `count` candidates.
fn rho_difference(problem: &Problem, count: usize, shape: Shape) -> (f64, f64) {
    let gpu = gpu_evaluator(problem, shape);
    let cpu = CpuEvaluator::new(problem.clone());
    let (mut a, mut b) = (vec![0.0; count], vec![0.0; count]);
    gpu.score(3, 10_000, &mut a).unwrap();
    cpu.score(3, 10_000, &mut b).unwrap();
    let mut rel: Vec<f64> = a.iter().zip(&b).map(|(g, c)| ((g - c) / c).abs()).collect();
    rel.sort_by(f64::total_cmp);
    (rel[count - 1], rel[count / 2])
}

/// The parameters of a particle as bits: the backends must agree on every one.
fn param_bits(p: &bitrock::abc::Particle) -> Vec<u64> {
    p.params.iter().map(|v| v.to_bits()).collect()
}

per_shape! {
fn rho_agrees_with_the_cpu_for_every_law(shape: Shape) {
    require_gpu();
    // 20,000 candidates of each law over more than one group of 4,096 samples; on lavapipe
    // the largest difference stays under a tenth of the tolerance (7.3e-7, m2 blocked).
    for law in Law::ALL {
        let problem = demo_problem(&[law], 11);
        assert!(problem.data_len() >= 5_000);
        let (max, median) = rho_difference(&problem, 20_000, shape);
        eprintln!(
            "{shape} {law}: largest relative difference of rho {max:.2e}, median {median:.2e} (20,000 candidates, D = {})",
            problem.data_len()
        );
        assert!(max <= PARITY_TOLERANCE, "{law}: {max:e} > {PARITY_TOLERANCE:e}");
    }
}

fn a_rejection_run_gives_the_same_populations_on_both_backends(shape: Shape) {
    require_gpu();
    let problem = demo_problem(&Law::ALL, 21);
    let config = RejectionConfig::from(Schedule { particles: 1_000, eps_min: 0.014, ..Schedule::default() });
    let cpu = rejection::run(&CpuEvaluator::new(problem.clone()), &config).unwrap();
    let gpu_run = rejection::run(&gpu_evaluator(&problem, shape), &config).unwrap();
    assert_eq!(cpu.populations.len(), gpu_run.populations.len());
    assert!(cpu.populations.len() >= 5, "{} populations", cpu.populations.len());
    let reference = CpuEvaluator::new(problem);
    let (mut exceptions, mut identical_populations, mut particles_compared) = (0, 0, 0);
    for (c, g) in cpu.populations.iter().zip(&gpu_run.populations) {
        let (ec, eg) = (
            c.record.epsilon.unwrap_or(f64::INFINITY),
            g.record.epsilon.unwrap_or(f64::INFINITY),
        );
        assert!(ec == eg || ((ec - eg) / ec).abs() <= PARITY_TOLERANCE, "ε {ec} vs {eg}");
        // A candidate accepted on both sides is the same particle: law, parameters to the
        // bit; only its ρ may differ, within the parity tolerance.
        let on_gpu: std::collections::BTreeMap<u64, &bitrock::abc::Particle> =
            g.particles.iter().map(|p| (p.index, p)).collect();
        for pc in &c.particles {
            if let Some(pg) = on_gpu.get(&pc.index) {
                assert_eq!(pc.law, pg.law, "law of candidate {}", pc.index);
                assert_eq!(param_bits(pc), param_bits(pg), "parameters of candidate {}", pc.index);
                assert!(
                    ((pc.rho - pg.rho) / pc.rho).abs() <= PARITY_TOLERANCE,
                    "candidate {}: rho {} vs {}",
                    pc.index,
                    pc.rho,
                    pg.rho
                );
                particles_compared += 1;
            }
        }
        if c.record.near_threshold == 0 && g.record.near_threshold == 0 {
            // No ρ within the tolerance of ε: the same particles in the same order, the same
            // draws per law.
            let key = |p: &bitrock::abc::Particle| (p.index, p.law, param_bits(p));
            assert_eq!(
                c.particles.iter().map(key).collect::<Vec<_>>(),
                g.particles.iter().map(key).collect::<Vec<_>>(),
                "population {}",
                c.record.index
            );
            assert_eq!(c.record.per_law, g.record.per_law, "population {}", c.record.index);
            identical_populations += 1;
            continue;
        }
        let ci: std::collections::BTreeSet<u64> = c.particles.iter().map(|p| p.index).collect();
        let gi: std::collections::BTreeSet<u64> = on_gpu.keys().copied().collect();
        for &index in ci.symmetric_difference(&gi) {
            // A candidate on one side only must lie within the parity tolerance of ε, or past
            // the end of the other side's scan (the N-th particle moved with it).
            let mut rho = [0.0];
            reference.score(c.record.stream, index, &mut rho).unwrap();
            let last = ci.last().unwrap().min(gi.last().unwrap());
            let near = (rho[0] - ec).abs() <= 2.0 * PARITY_TOLERANCE * ec;
            assert!(near || index > *last, "candidate {index}: rho {} vs ε {ec}", rho[0]);
            exceptions += 1;
        }
    }
    eprintln!(
        "{shape}: {} populations: {identical_populations} identical on both backends, {particles_compared} particles alike to the bit, {exceptions} near-threshold exceptions",
        cpu.populations.len()
    );
    // Population 0 (ε = ∞) decides nothing near a threshold: always identical.
    assert!(identical_populations >= 1);
}
}

fn run_bitrock(args: &[&str]) -> (i32, String, String) {
    run_bitrock_with(&[], args)
}

/// Runs the binary with environment variables `env` set.
fn run_bitrock_with(env: &[(&str, &str)], args: &[&str]) -> (i32, String, String) {
    let out = crate::support::bin()
        .envs(env.iter().copied())
        .args(args)
        .output()
        .expect("run bitrock");
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

per_shape! {
/// The shape comes through BITROCK_GPU_SHAPE, as a user overrides it.
fn parity_command_reports_agreement_as_json(shape: Shape) {
    require_gpu();
    let (code, stdout, stderr) = run_bitrock_with(
        &[(gpu::SHAPE_VAR, shape.name())],
        &["parity", "--candidates", "4000", "--json"],
    );
    assert_eq!(code, 0, "{stderr}");
    let v: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    assert_eq!(v["pass"], true);
    assert_eq!(v["philox"]["words_compared"], 1_048_576);
    assert_eq!(v["philox"]["words_differ"], 0);
    assert_eq!(v["philox"]["candidates_differ"], 0);
    assert_eq!(v["philox"]["first_differences"], serde_json::json!([]));
    assert_eq!(v["laws"].as_array().unwrap().len(), 4);
    for l in v["laws"].as_array().unwrap() {
        assert!(l["max_rel_diff"].as_f64().unwrap() <= PARITY_TOLERANCE);
    }
    // The simulators' sections: 200 torsional strings, five cells of the coupled bit.
    assert_eq!(v["strings"]["strings"], 200);
    assert_eq!(v["strings"]["pass"], true, "{}", v["strings"]);
    assert_eq!(v["coupled"]["cells"].as_array().unwrap().len(), 5);
    assert_eq!(v["coupled"]["pass"], true, "{}", v["coupled"]);
}
}

/// Where no desktop session runs (no XDG_RUNTIME_DIR), Mesa's device-select layer would print
/// its complaint twice on every command that looks for a GPU: the binary switches it off.
#[test]
#[cfg_attr(skip_gpu_tests, ignore = "BITROCK_SKIP_GPU_TESTS=1")]
fn a_command_on_the_gpu_prints_no_desktop_session_complaint() {
    require_gpu();
    let out = crate::support::bin()
        .env_remove("XDG_RUNTIME_DIR")
        .env_remove("NODEVICE_SELECT")
        .args(["parity", "--candidates", "2000", "--json"])
        .output()
        .expect("run bitrock");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{stderr}");
    assert!(!stderr.contains("XDG_RUNTIME_DIR"), "{stderr}");
}

#[test]
fn a_refused_shape_setting_exits_2_naming_the_variable() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    let (code, stdout, stderr) = run_bitrock_with(
        &[(gpu::SHAPE_VAR, "wide")],
        &[
            "abc",
            "--particles",
            "10",
            "--backend",
            "auto",
            "--json",
            "--out",
            out.to_str().unwrap(),
        ],
    );
    assert_eq!(code, 2, "{stderr}");
    assert!(stdout.is_empty(), "{stdout}");
    assert!(!out.exists(), "nothing may be written");
    assert!(
        stderr.contains("BITROCK_GPU_SHAPE") && stderr.contains("`wide`"),
        "{stderr}"
    );
}

#[test]
#[cfg_attr(skip_gpu_tests, ignore = "BITROCK_SKIP_GPU_TESTS=1")]
fn bench_json_keeps_its_keys_and_both_backends_count_the_same_evaluations() {
    require_gpu();
    let (code, stdout, stderr) = run_bitrock(&["bench", "--quick", "--reps", "1", "--laws", "m2", "--json"]);
    assert_eq!(code, 0, "{stderr}");
    let v: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    // The adapter the library opens, described as the benchmark report names it.
    assert_eq!(v["adapter"].as_str().unwrap(), gpu::context().unwrap().describe());
    // The shape BITROCK_GPU_SHAPE names, or the measured table's fastest at 65,536
    // candidates per dispatch.
    match std::env::var(gpu::SHAPE_VAR) {
        Ok(named) => assert_eq!(v["shape"], named.trim().to_lowercase()),
        Err(_) => {
            let bands = v["tuning"]["bands"].as_array().unwrap();
            let sizes: Vec<u64> = bands.iter().map(|b| b["candidates"].as_u64().unwrap()).collect();
            assert_eq!(sizes, gpu::tune::SIZES.map(|n| n as u64));
            assert_eq!(v["shape"], bands[1]["winner"]);
        }
    }
    let t = v["throughput"].as_array().unwrap();
    assert_eq!(t.len(), 2);
    for row in t {
        for key in ["backend", "law", "n", "d", "evals_per_s"] {
            assert!(row.get(key).is_some(), "{key} missing in {row}");
        }
        assert!(row["evals_per_s"].as_f64().unwrap() > 0.0);
    }
    let e = v["end_to_end"].as_array().unwrap();
    assert_eq!(e.len(), 2);
    // Same seed, same populations: the CPU and GPU runs score the same candidates.
    assert_eq!(e[0]["evaluations"], e[1]["evaluations"]);
    for run in e {
        let rate = run["evaluations"].as_f64().unwrap() / run["seconds"].as_f64().unwrap();
        assert!(
            (run["evals_per_s"].as_f64().unwrap() / rate - 1.0).abs() < 1e-9,
            "{run}"
        );
    }
    // One run per backend, CPU first, each with populations and a positive wall time.
    assert_eq!(
        (e[0]["backend"].as_str(), e[1]["backend"].as_str()),
        (Some("cpu"), Some("gpu"))
    );
    assert_eq!(e[0]["populations"], e[1]["populations"]);
    assert!(
        e.iter()
            .all(|run| run["seconds"].as_f64().unwrap() > 0.0 && run["populations"].as_u64().unwrap() > 0)
    );
}

per_shape! {
fn abc_on_the_gpu_backend_matches_the_cpu_backend(shape: Shape) {
    require_gpu();
    let dir = tempfile::tempdir().unwrap();
    let mut outputs = Vec::new();
    for backend in ["cpu", "gpu"] {
        let out = dir.path().join(backend);
        let (code, stdout, stderr) = run_bitrock_with(&[(gpu::SHAPE_VAR, shape.name())], &[
            "abc",
            "--particles",
            "1000",
            "--backend",
            backend,
            "--out",
            out.to_str().unwrap(),
            "--json",
        ]);
        assert_eq!(code, 0, "{stderr}");
        let v: serde_json::Value = serde_json::from_str(&stdout).unwrap();
        assert_eq!(v["backend"], backend);
        outputs.push(v);
    }
    let (a, b) = (&outputs[0]["populations"], &outputs[1]["populations"]);
    assert_eq!(a.as_array().unwrap().len(), b.as_array().unwrap().len());
    for (pa, pb) in a.as_array().unwrap().iter().zip(b.as_array().unwrap()) {
        // Identical unless a candidate sat within the parity tolerance of ε.
        if pa["near_threshold"] == 0 && pb["near_threshold"] == 0 {
            assert_eq!(pa["draws"], pb["draws"]);
            assert_eq!(pa["model_probabilities"], pb["model_probabilities"]);
        }
    }
}

fn a_million_data_points_and_a_two_dimensional_dispatch_agree_with_the_cpu(shape: Shape) {
    require_gpu();
    // D = 2^20: the blocked accumulation over a long record (32 dispatches of 32,768 samples),
    // for 64 candidates: four tiles, or four invocations of the blocked shape.
    let big = bitrock::bench::synthetic_problem(Law::M3, 1 << 20, 5);
    let (max, _) = rho_difference(&big, 64, shape);
    eprintln!("{shape} D = 2^20: largest relative difference of rho {max:.2e}");
    assert!(max <= PARITY_TOLERANCE, "{max:e}");
    // 1,048,592 candidates in one dispatch: 65,537 tiles, past 65,535 workgroups (tiled: one
    // per tile), so the grid is 2-D: 65,535 × 2 workgroups, two of the second row with a tile.
    let small = bitrock::bench::synthetic_problem(Law::M2, 64, 6);
    let (max, _) = rho_difference(&small, (1 << 20) + 16, shape);
    eprintln!("{shape} 1,048,592 candidates: largest relative difference of rho {max:.2e}");
    assert!(max <= PARITY_TOLERANCE, "{max:e}");
}

fn mixed_laws_over_a_long_record_agree_with_the_cpu(shape: Shape) {
    require_gpu();
    // Candidates of all four laws share each invocation (blocked) or tile (tiled), so the
    // kernel makes one pass over the data per law present (per group of four, tiled); every
    // pass must cover all 32,768 samples of each of the 32 dispatches (lavapipe's loop limiter)
    // and keep only its own law's sums. 2^20 samples: the demo record repeated; 161 candidates
    // drawn from the four laws' boxes: ten whole tiles of mixed laws and one of a single
    // candidate.
    let data = demo_field_data(&DataOptions {
        calibration_fraction: 1.0,
        ..Default::default()
    })
    .unwrap();
    let fits = fit_laws(&Law::ALL, &data.calibration, &data.validation, &FitOptions::default()).unwrap();
    let prior = Prior::from_fits(&fits, 0.4, None, 1000.0).unwrap();
    let mut long = data.calibration.clone();
    long.wob_n = None;
    long.time_s = None;
    let n = data.calibration.speed_rad_s.len();
    long.speed_rad_s = (0..1 << 20).map(|i| data.calibration.speed_rad_s[i % n]).collect();
    long.torque_nm = (0..1 << 20).map(|i| data.calibration.torque_nm[i % n]).collect();
    let problem = Problem::new(prior, 17, &long, None);
    let (max, _) = rho_difference(&problem, 161, shape);
    eprintln!("{shape} four laws mixed, D = 2^20: largest relative difference of rho {max:.2e}");
    assert!(max <= PARITY_TOLERANCE, "{max:e}");
}
}

#[test]
#[cfg_attr(skip_gpu_tests, ignore = "BITROCK_SKIP_GPU_TESTS=1")]
fn the_stability_grid_agrees_with_the_cpu_cell_by_cell() {
    use bitrock::stability::lumped::Lumped;
    use bitrock::stability::map::{Criterion, Grid, growth_rate_grid, parse_axis, probability_grid};
    require_gpu();
    let omega = parse_axis("10:250:61", "x").unwrap();
    let wob = parse_axis("10:700:71", "y").unwrap();
    let lumped = Lumped::default();
    let w_ref = 244.2e3;
    for law in Law::ALL {
        // 40,000 samples: more than one slice of 32,768, ±30 % around the paper's estimate.
        let base = law.scale_torque(law.paper_estimate().unwrap(), 1000.0);
        let samples: Vec<Vec<f64>> = (0..40_000u32)
            .map(|i| {
                base.iter()
                    .enumerate()
                    .map(|(j, &p)| {
                        let u = f64::from(bitrock::rng::unit_f32(
                            bitrock::rng::philox4x32_10([i, j as u32, 0, 0], [9, 9])[0],
                        ));
                        p * (0.7 + 0.6 * u)
                    })
                    .collect()
            })
            .collect();
        for criterion in [Criterion::Lumped(lumped), Criterion::Critical(-200.0)] {
            let grid = Grid {
                law,
                samples: &samples,
                omega_rpm: &omega,
                wob_kn: &wob,
                criterion,
                w_ref_n: w_ref,
            };
            let cpu = probability_grid(&grid);
            let (gpu, growth) = gpu::stability::stability_grid(&grid).unwrap();
            let c = criterion.critical_nms();
            let mut differing = 0;
            for (cell, (&p, &count)) in cpu.iter().zip(&gpu).enumerate() {
                let (rpm, kn) = (omega[cell / wob.len()], wob[cell % wob.len()]);
                let diff = ((p * samples.len() as f64).round() - f64::from(count)).abs();
                if diff > 0.0 {
                    // Samples whose bit damping lies within 1e-5 of c_b* may be decided either way.
                    let near = samples
                        .iter()
                        .filter(|s| {
                            let cb = kn * 1000.0 / w_ref * law.dtorque_dw(s, rpm * bitrock::units::RAD_S_PER_RPM, 1.0);
                            (cb - c).abs() <= 1e-5 * c.abs()
                        })
                        .count();
                    assert!(
                        diff <= near as f64,
                        "{law} at ({rpm} rpm, {kn} kN): {count} vs {}",
                        p * samples.len() as f64
                    );
                }
                differing += usize::from(diff > 0.0);
            }
            eprintln!(
                "{law} {criterion:?}: {differing} of {} cells differ, all within the tolerance",
                cpu.len()
            );
            if let Criterion::Lumped(l) = criterion {
                let reference = growth_rate_grid(law, &samples[0], &omega, &wob, &l, w_ref);
                // The eigenvalue sums terms of order ω_n ≈ 1/s in f32: absolute agreement to
                // 1e-5/s, relative beyond.
                for (g, r) in growth.iter().zip(&reference) {
                    assert!((f64::from(*g) - r).abs() <= 1e-5 * (1.0 + r.abs()), "growth {g} vs {r}");
                }
            }
        }
    }
}

/// Candidates of the prior stream, as explicit parameter vectors.
fn stream_candidates(problem: &Problem, population: u32, start: u64, count: usize) -> Vec<bitrock::prior::Candidate> {
    (0..count as u64)
        .map(|k| problem.prior.candidate(problem.seed, population, start + k))
        .collect()
}

per_shape! {
fn explicit_parameters_score_as_the_stream_does_on_both_backends(shape: Shape) {
    require_gpu();
    let problem = demo_problem(&Law::ALL, 31);
    let count = 40_000;
    let candidates = stream_candidates(&problem, 2, 500, count);
    let cpu = CpuEvaluator::new(problem.clone());
    let gpu = gpu_evaluator(&problem, shape);
    let (mut stream, mut cpu_params, mut gpu_params) = (vec![0.0; count], vec![0.0; count], vec![0.0; count]);
    cpu.score(2, 500, &mut stream).unwrap();
    cpu.score_params(&candidates, &mut cpu_params).unwrap();
    gpu.score_params(&candidates, &mut gpu_params).unwrap();
    // The CPU scores the same f32 parameters by the same code: the same bits.
    for (a, b) in stream.iter().zip(&cpu_params) {
        assert_eq!(a.to_bits(), b.to_bits());
    }
    let mut worst = 0.0f64;
    for (g, c) in gpu_params.iter().zip(&cpu_params) {
        worst = worst.max(((g - c) / c).abs());
    }
    eprintln!("{shape} score_params: largest relative difference of rho {worst:.2e} ({count} candidates, four laws)");
    assert!(worst <= PARITY_TOLERANCE, "{worst:e}");
    // Past the 32,768-sample slicing: a long record through the explicit kernel.
    let big = bitrock::bench::synthetic_problem(Law::M1, 100_000, 3);
    let candidates = stream_candidates(&big, 0, 0, 256);
    let (mut c, mut g) = (vec![0.0; 256], vec![0.0; 256]);
    CpuEvaluator::new(big.clone())
        .score_params(&candidates, &mut c)
        .unwrap();
    gpu_evaluator(&big, shape)
        .score_params(&candidates, &mut g)
        .unwrap();
    let worst = g.iter().zip(&c).map(|(g, c)| ((g - c) / c).abs()).fold(0.0, f64::max);
    eprintln!("{shape} score_params, D = 100,000: largest relative difference of rho {worst:.2e}");
    assert!(worst <= PARITY_TOLERANCE, "{worst:e}");
}
}

/// Largest relative difference between the GPU kernel sums and the CPU twin allowed: f32
/// coordinates (relative 6e-8 of |y| ≈ 3) and f32 exp make each term's relative error about
/// 1e-6 for the distances that carry the sum. Measured on lavapipe: 3.5e-7 largest, 8e-8 median.
const KERNEL_SUM_TOLERANCE: f64 = 1e-5;

#[test]
#[cfg_attr(skip_gpu_tests, ignore = "BITROCK_SKIP_GPU_TESTS=1")]
fn kernel_sums_agree_with_the_cpu_twin() {
    require_gpu();
    use bitrock::eval::KernelSums;
    // 70,000 sources (three dispatches of 32,768) in 4 whitened dimensions, standard normal; 500
    // targets (eight workgroups, the last part-filled) drawn from the same cloud, as SMC
    // proposals are. Weights positive, normalised.
    let normal = |i: u32, j: u32| {
        let w = bitrock::rng::philox4x32_10([i, j, 0, 0], [5, 6]);
        let u1 = (f64::from(w[0]) + 0.5) / 4_294_967_296.0;
        let u2 = f64::from(w[1]) / 4_294_967_296.0;
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    };
    let point = |i: u32| -> [f64; MAX_DIMS] { std::array::from_fn(|j| if j < 4 { normal(i, j as u32) } else { 0.0 }) };
    let sources: Vec<[f64; MAX_DIMS]> = (0..70_000).map(point).collect();
    let targets: Vec<[f64; MAX_DIMS]> = (100_000..100_500).map(point).collect();
    let raw: Vec<f64> = (0..70_000u32).map(|i| 0.5 + normal(i, 9).abs()).collect();
    let total: f64 = raw.iter().sum();
    let weights: Vec<f64> = raw.iter().map(|w| w / total).collect();
    let sums = KernelSums {
        targets: &targets,
        sources: &sources,
        weights: &weights,
        rank_one: None,
    };
    let cpu = CpuEvaluator::new(demo_problem(&[Law::M2], 1));
    let gpu = GpuEvaluator::new(demo_problem(&[Law::M2], 1)).unwrap();
    let (mut c, mut g) = (vec![0.0; targets.len()], vec![0.0; targets.len()]);
    cpu.kernel_sums(&sums, &mut c).unwrap();
    gpu.kernel_sums(&sums, &mut g).unwrap();
    let mut rel: Vec<f64> = g.iter().zip(&c).map(|(g, c)| ((g - c) / c).abs()).collect();
    rel.sort_by(f64::total_cmp);
    let (worst, median) = (rel[rel.len() - 1], rel[rel.len() / 2]);
    eprintln!("kernel sums: largest relative difference {worst:.2e}, median {median:.2e} (500 × 70,000, d = 4)");
    assert!(worst <= KERNEL_SUM_TOLERANCE, "{worst:e}");
    assert!(c.iter().all(|&s| s > 0.0));
    // The local kernel: each source its own covariance I + x xᵀ (c_j = 1 / (1 + |x_j|²)).
    let rank_one: Vec<f64> = sources
        .iter()
        .map(|x| 1.0 / (1.0 + x.iter().map(|v| v * v).sum::<f64>()))
        .collect();
    let local = KernelSums {
        rank_one: Some(&rank_one),
        ..sums
    };
    cpu.kernel_sums(&local, &mut c).unwrap();
    gpu.kernel_sums(&local, &mut g).unwrap();
    let worst = g.iter().zip(&c).map(|(g, c)| ((g - c) / c).abs()).fold(0.0, f64::max);
    eprintln!("local kernel sums: largest relative difference {worst:.2e}");
    assert!(worst <= KERNEL_SUM_TOLERANCE, "{worst:e}");
}

per_shape! {
fn an_smc_run_gives_the_same_populations_on_both_backends(shape: Shape) {
    use bitrock::abc::smc::{self, SmcConfig, WeightsOn};
    require_gpu();
    let problem = demo_problem(&Law::ALL, 21);
    let config = SmcConfig {
        schedule: Schedule { particles: 1000, eps_min: 0.009, ..Schedule::default() },
        ..Default::default()
    };
    let cpu = smc::run(&CpuEvaluator::new(problem.clone()), &config).unwrap();
    let gpu_run = smc::run(&gpu_evaluator(&problem, shape), &config).unwrap();
    assert!(cpu.populations.len() >= 6, "{}", cpu.populations.len());
    let reference = CpuEvaluator::new(problem.clone());
    let mut identical = 0;
    let mut exceptions = 0;
    for (c, g) in cpu.populations.iter().zip(&gpu_run.populations) {
        let (ec, eg) = (
            c.record.epsilon.unwrap_or(f64::INFINITY),
            g.record.epsilon.unwrap_or(f64::INFINITY),
        );
        assert!(ec == eg || ((ec - eg) / ec).abs() <= PARITY_TOLERANCE, "ε {ec} vs {eg}");
        let ci: Vec<u64> = c.particles.iter().map(|p| p.index).collect();
        let gi: Vec<u64> = g.particles.iter().map(|p| p.index).collect();
        if ci != gi {
            // A decision taken otherwise: it must be a candidate within the parity tolerance
            // of ε (or past the end of the other side's scan). From here on the populations
            // legitimately differ (other ancestors, other kernels).
            let (cs, gs): (std::collections::BTreeSet<u64>, std::collections::BTreeSet<u64>) =
                (ci.iter().copied().collect(), gi.iter().copied().collect());
            let last = *ci.last().unwrap().min(gi.last().unwrap());
            for &index in cs.symmetric_difference(&gs) {
                let p = c
                    .particles
                    .iter()
                    .chain(&g.particles)
                    .find(|p| p.index == index)
                    .unwrap();
                let slot = problem.prior.boxes.iter().position(|b| b.law == p.law).unwrap();
                let mut params = [0.0f32; MAX_DIMS];
                for (d, &s) in params.iter_mut().zip(&p.params) {
                    *d = s as f32;
                }
                let mut rho = [0.0];
                reference
                    .score_params(&[bitrock::prior::Candidate { slot, params }], &mut rho)
                    .unwrap();
                let near = (rho[0] - ec).abs() <= 2.0 * PARITY_TOLERANCE * ec;
                assert!(near || index > last, "candidate {index}: rho {} vs ε {ec}", rho[0]);
                exceptions += 1;
            }
            break;
        }
        // Same proposals and host weights: parameters and weights to the bit, ρ within tolerance.
        for (a, b) in c.particles.iter().zip(&g.particles) {
            assert_eq!(a.params, b.params);
            assert_eq!(a.weight.to_bits(), b.weight.to_bits(), "weight of particle {}", a.index);
            assert!(((a.rho - b.rho) / a.rho).abs() <= PARITY_TOLERANCE);
        }
        assert_eq!(c.record.per_law, g.record.per_law);
        identical += 1;
    }
    eprintln!(
        "{shape} SMC: {identical} of {} populations alike on both backends; {exceptions} near-threshold exceptions",
        cpu.populations.len()
    );
    assert!(identical == cpu.populations.len() || exceptions > 0);
    if exceptions == 0 {
        assert_eq!(cpu.populations.len(), gpu_run.populations.len());
    }

    // Weights from the GPU kernel: population 1's proposals depend on population 0 only (equal
    // weights), so its particles are the CPU's, and its weights within the kernel tolerance.
    let on_gpu = SmcConfig {
        weights_on: WeightsOn::Evaluator,
        schedule: Schedule { max_populations: 2, ..config.schedule.clone() },
        ..config
    };
    let g = smc::run(&gpu_evaluator(&problem, shape), &on_gpu).unwrap();
    let (a, b) = (&cpu.populations[1], &g.populations[1]);
    let worst = a
        .particles
        .iter()
        .zip(&b.particles)
        .map(|(x, y)| {
            assert_eq!(x.index, y.index);
            ((x.weight - y.weight) / x.weight).abs()
        })
        .fold(0.0, f64::max);
    eprintln!("{shape} SMC weights from the GPU kernel: largest relative difference {worst:.2e}");
    assert!(worst <= KERNEL_SUM_TOLERANCE, "{worst:e}");
}
}

per_shape! {
    /// The model evidence scored on the GPU: the same samplers from the same seed on f32 sums,
    /// so ln Z of every law agrees with the CPU's within three times their combined Monte-Carlo
    /// error (in practice far closer: a Metropolis decision flips only where f32 moves the
    /// log-likelihood across its uniform).
    fn the_evidence_on_the_gpu_agrees_with_the_cpu(shape: Shape) {
        use bitrock::abc::Silent;
        use bitrock::abc::evidence::{self, EvidenceConfig};
        use bitrock::abc::shard::Local;
        use bitrock::prior::PhysicalScales;
        require_gpu();
        let data = demo_field_data(&DataOptions {
            thin: 8,
            ..Default::default()
        })
        .unwrap();
        let laws = [Law::M2, Law::M3];
        let prior = Prior::physical(&laws, &PhysicalScales::of(&data.calibration), 10.0, None, 1000.0).unwrap();
        let problem = Problem::new(prior, 1, &data.calibration, None);
        let config = EvidenceConfig {
            particles: 200,
            islands: 3,
            seed: 4,
            ..EvidenceConfig::default()
        };
        let cpu = evidence::run(&Local(Box::new(CpuEvaluator::new(problem.clone()))), &config, &mut Silent).unwrap();
        let gpu = evidence::run(&Local(Box::new(gpu_evaluator(&problem, shape))), &config, &mut Silent).unwrap();
        for (c, g) in cpu.laws.iter().zip(&gpu.laws) {
            eprintln!(
                "{}: ln Z cpu {:.4} ± {:.3}, gpu {:.4} ± {:.3}",
                c.law, c.ln_z, c.ln_z_error, g.ln_z, g.ln_z_error
            );
        }
        for (c, g) in cpu.laws.iter().zip(&gpu.laws) {
            let error = c.ln_z_error.hypot(g.ln_z_error);
            assert!((c.ln_z - g.ln_z).abs() < 3.0 * error, "{}: {} vs {}", c.law, c.ln_z, g.ln_z);
        }
        // The log odds of the two laws, within three of their combined errors.
        let odds = |e: &evidence::Evidence| e.ln_bayes_factor(Law::M3, Law::M2).unwrap();
        let ((a, ea), (b, eb)) = (odds(&cpu), odds(&gpu));
        assert!((a - b).abs() < 3.0 * ea.hypot(eb), "ln B cpu {a} ± {ea}, gpu {b} ± {eb}");
    }
}

/// Largest difference between the GPU's and the CPU's λ = Σ e_t·e_(t−1) / Σy² over
/// `candidates`, relative to ρ (λ may be near 0 where ρ is not: the AR(1) likelihood needs
/// λ to the precision of ρ, not relative to itself).
fn lag_difference(problem: &Problem, candidates: &[bitrock::prior::Candidate], shape: Shape) -> f64 {
    let n = candidates.len();
    let (mut rho_c, mut lag_c, mut rho_g, mut lag_g) = (vec![0.0; n], vec![0.0; n], vec![0.0; n], vec![0.0; n]);
    CpuEvaluator::new(problem.clone())
        .score_params_lagged(candidates, &mut rho_c, &mut lag_c)
        .unwrap();
    gpu_evaluator(problem, shape)
        .score_params_lagged(candidates, &mut rho_g, &mut lag_g)
        .unwrap();
    // The lag pass leaves ρ to the squares' pass: the same ρ as score_params.
    let mut rho = vec![0.0; n];
    gpu_evaluator(problem, shape)
        .score_params(candidates, &mut rho)
        .unwrap();
    assert_eq!(rho, rho_g);
    // Not a vacuous comparison: lags of a tenth of ρ or more.
    assert!(lag_c.iter().zip(&rho_c).any(|(l, r)| l.abs() > 0.1 * r));
    lag_g
        .iter()
        .zip(&lag_c)
        .zip(&rho_c)
        .map(|((g, c), r)| ((g - c) / r).abs())
        .fold(0.0, f64::max)
}

per_shape! {
    /// The AR(1) noise model's lag-1 sums from the kernels' lag pass agree with the CPU twin
    /// within the parity contract: on the embedded record for every law, with a fluctuating
    /// weight-on-bit ratio, past the 32,768-sample slicing of a long record (the pair across a
    /// slice boundary counted once), and for a law file.
    fn lag_sums_agree_with_the_cpu_twin(shape: Shape) {
        require_gpu();
        let problem = demo_problem(&Law::ALL, 5);
        let candidates = stream_candidates(&problem, 1, 0, 4_096);
        let worst = lag_difference(&problem, &candidates, shape);
        eprintln!("{shape} lag sums: largest difference relative to rho {worst:.2e} (four laws)");
        assert!(worst <= PARITY_TOLERANCE, "{worst:e}");

        let mut scaled = problem.clone();
        for (i, r) in scaled.wob_ratio.iter_mut().enumerate() {
            *r = 1.0 + 0.05 * (i as f64 * 0.01).sin();
        }
        let worst = lag_difference(&scaled, &candidates, shape);
        eprintln!("{shape} lag sums with weight-on-bit ratios: {worst:.2e}");
        assert!(worst <= PARITY_TOLERANCE, "{worst:e}");

        let big = bitrock::bench::synthetic_problem(Law::M3, 100_003, 3);
        let candidates = stream_candidates(&big, 0, 0, 256);
        let worst = lag_difference(&big, &candidates, shape);
        eprintln!("{shape} lag sums, D = 100,003: {worst:.2e}");
        assert!(worst <= PARITY_TOLERANCE, "{worst:e}");

        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/laws");
        let file = bitrock::laws::file::register(
            bitrock::laws::file::LawFile::load(&dir.join("gaussian_tanh.toml")).unwrap(),
        )
        .unwrap();
        let mut as_file = demo_problem(&[Law::M3], 5);
        as_file.prior.boxes[0].law = file;
        let candidates = stream_candidates(&as_file, 1, 0, 1_024);
        let worst = lag_difference(&as_file, &candidates, shape);
        eprintln!("{shape} lag sums of a law file: {worst:.2e}");
        assert!(worst <= PARITY_TOLERANCE, "{worst:e}");
    }
}

/// `auto` on a software driver (lavapipe, here) races it against the CPU on the run's own
/// dispatches and says which it keeps: the evidence's explicit dispatches (60 particles × 2
/// islands × 2 starts × 2 laws = 480 candidates) go to the faster, whose evidence is then
/// `--backend cpu`'s or `--backend gpu`'s bit for bit; the race is kept in the cache and a
/// second run reads it to the same choice; the AR(1) noise model's calls (with their lag-1
/// sums) are raced apart; with tuning off there is no race and the GPU scores. On a hardware
/// GPU there is no race at all.
#[test]
#[cfg_attr(skip_gpu_tests, ignore = "BITROCK_SKIP_GPU_TESTS=1")]
fn auto_races_a_software_driver_against_the_cpu_and_keeps_the_faster() {
    require_gpu();
    let software = gpu::context().unwrap().info.device_type == wgpu::DeviceType::Cpu;
    let cache = tempfile::tempdir().unwrap();
    let cache_dir = cache.path().to_str().unwrap();
    let args = |backend: &'static str| {
        [
            "evidence",
            "--laws",
            "m2,m3",
            "--particles",
            "60",
            "--islands",
            "2",
            "--seed",
            "3",
            "--noise",
            "iid",
            "--check",
            "0",
            "--thin",
            "4",
            "--json",
            "--backend",
            backend,
        ]
    };
    let (code, cpu, err) = run_bitrock_with(&[("BITROCK_CACHE_DIR", cache_dir)], &args("cpu"));
    assert_eq!(code, 0, "{err}");
    let (code, gpu, err) = run_bitrock_with(&[("BITROCK_CACHE_DIR", cache_dir)], &args("gpu"));
    assert_eq!(code, 0, "{err}");
    let ln_z = |out: &str| -> Vec<f64> {
        let doc: serde_json::Value = serde_json::from_str(out).unwrap();
        doc["laws"]
            .as_array()
            .unwrap()
            .iter()
            .map(|l| l["ln_z"].as_f64().unwrap())
            .collect()
    };
    // The two backends' evidences differ in their last bits, so that each tells which one ran.
    assert_ne!(ln_z(&cpu), ln_z(&gpu));
    // The first run races, the second reads the race back: the same choice, said the same way.
    let mut said = Vec::new();
    for _ in 0..2 {
        let (code, auto, err) = run_bitrock_with(&[("BITROCK_CACHE_DIR", cache_dir)], &args("auto"));
        assert_eq!(code, 0, "{err}");
        if software {
            let line = err
                .lines()
                .find(|l| l.contains("auto: scoring on"))
                .unwrap_or_else(|| panic!("no race said: {err}"))
                .to_string();
            assert!(line.contains("a dispatch of 480 candidates"), "{line}");
            let chose_cpu = line.contains("auto: scoring on the CPU rather than");
            assert!(chose_cpu || line.contains("rather than the CPU"), "{line}");
            // One line says where the run is scored; the GPU it names comes with its shape.
            assert!(!err.contains("GPU backend"), "{err}");
            assert!(line.contains(" scoring, "), "{line}");
            // The faster kept, the GPU only by its margin (the times as said, to 0.1 ms).
            let ms = |before: &str| -> f64 {
                let at = line.find(before).unwrap_or_else(|| panic!("{before}: {line}"));
                line[..at].rsplit(' ').next().unwrap().parse().unwrap()
            };
            let (cpu_ms, gpu_ms) = (ms(" ms on the CPU"), ms(" ms on the software GPU"));
            if chose_cpu {
                assert!(cpu_ms <= 1.2 * gpu_ms + 0.15, "{line}");
            } else {
                assert!(cpu_ms + 0.15 >= 1.2 * gpu_ms, "{line}");
            }
            assert_eq!(ln_z(&auto), ln_z(if chose_cpu { &cpu } else { &gpu }), "{line}");
            said.push(line);
        } else {
            assert!(!err.contains("auto: scoring on"), "{err}");
            assert_eq!(ln_z(&auto), ln_z(&gpu));
        }
    }
    if software {
        assert_eq!(said[0], said[1]);
        let kept = std::fs::read_to_string(cache.path().join("gpu-shapes.json")).unwrap();
        assert!(kept.contains("512 candidates | explicit\""), "{kept}");
        // The other outcome, read from a race kept the other way (the GPU ten times faster or
        // slower than the CPU): said once too, and the run scored where it says.
        let chose_cpu = said[0].contains("auto: scoring on the CPU rather than");
        let mut doc: serde_json::Value = serde_json::from_str(&kept).unwrap();
        for race in doc["races"].as_array_mut().unwrap() {
            let cpu_s = race["cpu_s"].as_f64().unwrap();
            race["gpu_s"] = serde_json::json!(if chose_cpu { cpu_s / 10.0 } else { cpu_s * 10.0 });
        }
        std::fs::write(cache.path().join("gpu-shapes.json"), doc.to_string()).unwrap();
        let (code, flipped, err) = run_bitrock_with(&[("BITROCK_CACHE_DIR", cache_dir)], &args("auto"));
        assert_eq!(code, 0, "{err}");
        let lines: Vec<&str> = err
            .lines()
            .filter(|l| l.contains("auto: scoring on") || l.contains("GPU backend"))
            .collect();
        assert_eq!(lines.len(), 1, "{err}");
        let now_cpu = lines[0].contains("auto: scoring on the CPU rather than");
        assert_eq!(now_cpu, !chose_cpu, "{err}");
        assert_eq!(ln_z(&flipped), ln_z(if now_cpu { &cpu } else { &gpu }), "{err}");
        // Under the AR(1) noise model the evidence scores the lag-1 sums too (two dispatches on
        // the GPU, one pass on the CPU): a race of its own, on those calls.
        let ar1: Vec<&str> = args("auto")
            .into_iter()
            .map(|a| if a == "iid" { "ar1" } else { a })
            .collect();
        let (code, _, err) = run_bitrock_with(&[("BITROCK_CACHE_DIR", cache_dir)], &ar1);
        assert_eq!(code, 0, "{err}");
        assert!(err.contains("auto: scoring on"), "{err}");
        let kept = std::fs::read_to_string(cache.path().join("gpu-shapes.json")).unwrap();
        assert!(kept.contains("512 candidates | explicit lagged\""), "{kept}");
    }
    let (code, _, err) = run_bitrock_with(
        &[("BITROCK_CACHE_DIR", cache_dir), ("BITROCK_GPU_TUNING", "off")],
        &args("auto"),
    );
    assert_eq!(code, 0, "{err}");
    assert!(
        !err.contains("auto: scoring on") && err.contains("GPU backend"),
        "{err}"
    );
}
