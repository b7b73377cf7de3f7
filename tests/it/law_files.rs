//! Law files: the WGSL a law file compiles to against its f64 CPU twin (the built-in laws
//! written as files, random expressions), the built-in laws' fits, scores and stability maps
//! reproduced from their files, and a law file through every command (a run on both backends,
//! resumed without the file, reported and checked). The GPU tests need an adapter, as
//! tests/it/gpu.rs's do.

use crate::gpu::{demo_problem, require_gpu};
use crate::support::{bin, outcome};
use bitrock::Law;
use bitrock::data::{DataOptions, demo_field_data};
use bitrock::eval::cpu::CpuEvaluator;
use bitrock::eval::gpu::law_points::{Point, torques};
use bitrock::eval::gpu::{Shape, residual::GpuEvaluator, tune};
use bitrock::eval::{Backend, Evaluator, PARITY_TOLERANCE, Problem};
use bitrock::fit::{FitOptions, fit_record};
use bitrock::laws::file::expr::{Binary, Expr, Unary, Var, parse};
use bitrock::laws::file::register;
use bitrock::laws::file::{LawFile, LawParam};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use std::path::Path;

/// f32's unit roundoff.
const U: f64 = 1.0 / 16_777_216.0;

/// The expression's f64 value and a bound on the size of what f32 rounding can do to it: every
/// operation's rounding, weighted by how much the result depends on it (a first-order forward
/// error bound, in units of the roundoff; transcendentals count a few ulps, sin and cos an
/// absolute few from their argument reduction).
fn value_and_sensitivity(e: &Expr, p: &[f64], w: f64, r: f64) -> (f64, f64) {
    match e {
        Expr::Const(c) => (*c, c.abs()),
        Expr::Var(Var::Speed) => (w, 0.0),
        Expr::Var(Var::Ratio) => (r, 0.0),
        Expr::Var(Var::Param(i)) => (p[*i], 0.0),
        Expr::Unary(op, a) => {
            let (x, m) = value_and_sensitivity(a, p, w, r);
            let v = e.eval(p, w, r);
            let s = match op {
                Unary::Neg | Unary::Abs => m,
                Unary::Sign => 0.0,
                Unary::Exp => v.abs() * (m + 4.0 + x.abs()),
                Unary::Ln => m / x.abs() + 4.0 * v.abs().max(1.0),
                Unary::Sqrt => m / (2.0 * v.abs()) + v.abs(),
                Unary::Tanh => (1.0 - v * v) * (m + 4.0 + x.abs()) + 4.0 * v.abs(),
                Unary::Sin | Unary::Cos => m + 4.0 + x.abs(),
            };
            (v, s)
        }
        Expr::Binary(op, a, b) => {
            let (x, ma) = value_and_sensitivity(a, p, w, r);
            let (y, mb) = value_and_sensitivity(b, p, w, r);
            let v = e.eval(p, w, r);
            let s = match op {
                Binary::Add | Binary::Sub => ma + mb + v.abs(),
                Binary::Mul => ma * y.abs() + x.abs() * mb + v.abs(),
                Binary::Div => ma / y.abs() + x.abs() * mb / (y * y) + v.abs(),
                Binary::Pow => {
                    let n = y.abs().max(1.0);
                    let log = x.abs().ln().abs().max(1.0);
                    (y * v / x).abs() * ma + (v * log).abs() * (mb + 4.0 * n) + 4.0 * n * v.abs()
                }
            };
            (v, s)
        }
    }
}

/// Compares the GPU's (T, dT/dw) of `law` with the twin's at `points`; returns how many
/// points were compared (those where both are finite and moderate in the f64 twin).
fn compare(law: &LawFile, points: &[Point]) -> usize {
    let gpu = torques(law, points).unwrap();
    let mut compared = 0;
    for (q, g) in points.iter().zip(&gpu) {
        let p: Vec<f64> = q.p[..law.params.len()].iter().map(|&v| f64::from(v)).collect();
        let (w, r) = (f64::from(q.w), f64::from(q.r));
        let mut all_finite = true;
        for (k, expr) in [&law.torque, &law.dtorque_dw].into_iter().enumerate() {
            let (v, s) = value_and_sensitivity(expr, &p, w, r);
            if !(v.is_finite() && s.is_finite() && s < 1e30) {
                all_finite = false;
                continue;
            }
            let got = f64::from(g[k]);
            let bound = 32.0 * U * s + 1e-30;
            assert!(
                (got - v).abs() <= bound,
                "{} ({}) at p = {p:?}, w = {w}, r = {r}: GPU {got}, twin {v}, bound {bound:e}\n{}",
                if k == 0 { "T" } else { "dT/dw" },
                law.formula,
                law.wgsl()
            );
        }
        compared += usize::from(all_finite);
    }
    compared
}

fn point(p: &[f64], w: f64, r: f64) -> Point {
    let mut q = [0.0f32; 6];
    for (a, b) in q.iter_mut().zip(p) {
        *a = *b as f32;
    }
    Point {
        p: q,
        w: w as f32,
        r: r as f32,
    }
}

#[test]
#[cfg_attr(skip_gpu_tests, ignore = "BITROCK_SKIP_GPU_TESTS=1")]
fn the_built_in_laws_as_files_agree_on_the_gpu_with_their_twins() {
    require_gpu();
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/laws");
    for file in ["tucker_wang", "navarro_suarez", "gaussian_tanh", "cubic", "stribeck"] {
        let law = LawFile::load(&dir.join(format!("{file}.toml"))).unwrap();
        let reference: Vec<f64> = law
            .params
            .iter()
            .map(|p| p.reference.unwrap_or(if p.torque_power == 1 { 8_000.0 } else { 0.5 }))
            .collect();
        let mut points = Vec::new();
        for scale in [1.0, 0.3, 2.0] {
            let p: Vec<f64> = reference.iter().map(|v| v * scale).collect();
            for i in 0..200 {
                // Backwards through zero to fast: −2 … 20 rad/s.
                let w = -2.0 + 22.0 * f64::from(i) / 199.0;
                points.push(point(&p, w, if i % 2 == 0 { 1.0 } else { 0.83 }));
            }
        }
        let compared = compare(&law, &points);
        assert_eq!(compared, points.len(), "{file}");
    }
}

/// A random expression in the law file grammar, over the parameters a, b, c, w and r; which
/// parameters it uses are marked in `used`.
fn random_expression(rng: &mut StdRng, depth: u32, used: &mut [bool; 3]) -> String {
    if depth == 0 || rng.random::<f64>() < 0.25 {
        return match rng.random_range(0..6) {
            0 => "w".into(),
            1 => "r".into(),
            k @ 2..=4 => {
                used[k - 2] = true;
                ["a", "b", "c"][k - 2].into()
            }
            _ => format!("{:.2}", rng.random_range(-3.0..3.0)),
        };
    }
    let mut sub = |rng: &mut StdRng| random_expression(rng, depth - 1, used);
    match rng.random_range(0..14) {
        0 => format!("({} + {})", sub(rng), sub(rng)),
        1 => format!("({} - {})", sub(rng), sub(rng)),
        2 | 3 => format!("{} * {}", sub(rng), sub(rng)),
        4 => format!("{} / (1.5 + {}^2)", sub(rng), sub(rng)),
        5 => format!("({})^{}", sub(rng), rng.random_range(-2..=3)),
        6 => format!("pow(abs({}) + 0.5, {:.2})", sub(rng), rng.random_range(-1.5..2.5)),
        7 => format!("exp({} / 4)", sub(rng)),
        8 => format!("ln(abs({}) + 0.25)", sub(rng)),
        9 => format!("sqrt(abs({}))", sub(rng)),
        10 => format!("tanh({})", sub(rng)),
        11 => format!("sin({})", sub(rng)),
        12 => format!("cos({})", sub(rng)),
        _ => format!("-{}", sub(rng)),
    }
}

#[test]
#[cfg_attr(skip_gpu_tests, ignore = "BITROCK_SKIP_GPU_TESTS=1")]
fn random_expressions_agree_on_the_gpu_with_their_twins() {
    require_gpu();
    let mut rng = StdRng::seed_from_u64(28);
    let (mut laws, mut compared, mut total) = (0, 0, 0);
    while laws < 150 {
        let mut used = [false; 3];
        let text = random_expression(&mut rng, 4, &mut used);
        let names: Vec<&str> = ["a", "b", "c"]
            .into_iter()
            .zip(used)
            .filter(|(_, u)| *u)
            .map(|(n, _)| n)
            .collect();
        // The compiler alone: random expressions are neither torques nor proportional to r,
        // which a law file's checks would refuse.
        let (torque, _) = parse(&text, &names).unwrap_or_else(|e| panic!("{e:?}\n{text}"));
        let law = LawFile {
            name: "random".into(),
            description: None,
            prior_curve_within: None,
            formula: text.clone(),
            params: names
                .iter()
                .map(|n| LawParam {
                    name: n.to_string(),
                    torque_power: 0,
                    inverse_speed_power: 0,
                    lower: f64::NEG_INFINITY,
                    upper: f64::INFINITY,
                    reference: None,
                })
                .collect(),
            dtorque_dw: torque.derivative(Var::Speed),
            gradient: Vec::new(),
            torque,
            source: text.clone(),
        };
        let points: Vec<Point> = (0..64)
            .map(|_| {
                let p: Vec<f64> = names.iter().map(|_| rng.random_range(-2.0..2.0)).collect();
                point(&p, rng.random_range(-3.0..6.0), rng.random_range(0.5..1.5))
            })
            .collect();
        compared += compare(&law, &points);
        total += points.len();
        laws += 1;
    }
    // Most points give finite values; the comparison is not vacuous.
    eprintln!("{compared} of {total} points compared over {laws} random laws");
    assert!(compared * 10 >= total * 8, "{compared} of {total}");
}

/// The built-in laws and their law files (examples/laws), registered.
fn built_in_pairs() -> Vec<(Law, Law)> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/laws");
    [
        (Law::M1, "tucker_wang"),
        (Law::M2, "navarro_suarez"),
        (Law::M3, "gaussian_tanh"),
        (Law::M4, "cubic"),
    ]
    .into_iter()
    .map(|(law, file)| {
        (
            law,
            register(LawFile::load(&dir.join(format!("{file}.toml"))).unwrap()).unwrap(),
        )
    })
    .collect()
}

#[test]
fn the_built_in_laws_as_files_fit_the_embedded_record_as_the_built_in_laws_do() {
    let data = demo_field_data(&DataOptions::default()).unwrap();
    for (law, file) in built_in_pairs() {
        let fits = fit_record(&[law, file], &data, &FitOptions::default()).unwrap();
        let (a, b) = (&fits[0], &fits[1]);
        assert_eq!((a.law, b.law), (law, file));
        // The same minimum: ρ within 1e-9; every parameter within a thousandth of its standard
        // error (LM stops on the flat directions of m1 and m3 a few 1e-7 apart, relative).
        assert!(
            (a.rho - b.rho).abs() <= 1e-9 * a.rho,
            "{law}: ρ {} against {}",
            a.rho,
            b.rho
        );
        for j in 0..law.n_params() {
            let (x, y) = (a.params_si[j], b.params_si[j]);
            let tolerance = a.std_errors_si[j].map_or(1e-6 * x.abs(), |se| 1e-3 * se);
            assert!((x - y).abs() <= tolerance, "{law} parameter {j}: {x} against {y}");
        }
    }
}

#[test]
#[cfg_attr(skip_gpu_tests, ignore = "BITROCK_SKIP_GPU_TESTS=1")]
fn a_law_file_scores_as_its_built_in_law_on_both_backends_in_both_shapes() {
    require_gpu();
    for (law, file) in built_in_pairs() {
        // The same boxes and the same seed: the same candidates, of the built-in law or of the file.
        let built_in = demo_problem(&[law], 17);
        let mut as_file = built_in.clone();
        as_file.prior.boxes[0].law = file;
        let count = 4_096;
        let score = |problem: &Problem, backend: Backend, shape: Option<Shape>| -> Vec<f64> {
            let mut rho = vec![0.0; count];
            match (backend, shape) {
                (Backend::Gpu, Some(shape)) => GpuEvaluator::with_shape(problem.clone(), shape)
                    .unwrap()
                    .score(1, 0, &mut rho)
                    .unwrap(),
                _ => CpuEvaluator::new(problem.clone()).score(1, 0, &mut rho).unwrap(),
            }
            rho
        };
        let reference = score(&built_in, Backend::Cpu, None);
        // CPU: the twin against the built-in law's hand-written (vectorised) code.
        for (a, b) in score(&as_file, Backend::Cpu, None).iter().zip(&reference) {
            assert!((a - b).abs() <= 1e-12 * b, "{law} on the CPU: {a} against {b}");
        }
        for shape in [Shape::Blocked, Shape::Tiled] {
            let gpu = score(&as_file, Backend::Gpu, Some(shape));
            let worst = gpu
                .iter()
                .zip(&reference)
                .map(|(g, c)| ((g - c) / c).abs())
                .fold(0.0, f64::max);
            eprintln!("{file} ({shape}): largest relative difference of ρ from the CPU {worst:.2e}");
            assert!(worst <= PARITY_TOLERANCE, "{file} ({shape}): {worst:e}");
        }
    }
}

/// Runs the binary with its own cache directory; (status, stdout, stderr).
fn run(cache: &Path, args: &[&str]) -> (i32, String, String) {
    outcome(
        bin()
            .env(tune::CACHE_DIR_VAR, cache)
            .env("NODEVICE_SELECT", "1")
            .args(args),
    )
}

/// The populations of a run directory's run.json.
fn populations(dir: &Path) -> serde_json::Value {
    let run: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(dir.join("run.json")).unwrap()).unwrap();
    run["populations"].clone()
}

#[test]
#[cfg_attr(skip_gpu_tests, ignore = "BITROCK_SKIP_GPU_TESTS=1")]
fn a_run_with_a_law_file_is_the_same_on_both_backends_and_resumes_without_the_file() {
    require_gpu();
    let tmp = tempfile::tempdir().unwrap();
    let cache = tmp.path().join("cache");
    let law = tmp.path().join("mine.toml");
    std::fs::copy(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/laws/stribeck.toml"),
        &law,
    )
    .unwrap();
    let out = |name: &str| tmp.path().join(name).to_str().unwrap().to_string();
    // The embedded record thinned by 4: each process fits five laws to it, the file's
    // interpreted, and the parity, resume and check need no more points.
    let common = [
        "abc",
        "--law-file",
        law.to_str().unwrap(),
        "--thin",
        "4",
        "--particles",
        "800",
        "--seed",
        "5",
        "-q",
    ];
    let mut runs = Vec::new();
    for (name, extra) in [
        ("cpu", vec!["--backend", "cpu"]),
        ("gpu", vec!["--backend", "gpu"]),
        ("smc", vec!["--backend", "cpu", "--sampler", "smc"]),
        ("smc_gpu", vec!["--backend", "gpu", "--sampler", "smc"]),
        ("part", vec!["--backend", "cpu", "--max-populations", "2"]),
    ] {
        let target = out(name);
        let args: Vec<&str> = common.iter().copied().chain(extra).chain(["--out", &target]).collect();
        let (code, _, stderr) = run(&cache, &args);
        assert_eq!(code, 0, "{name}: {stderr}");
        runs.push(target);
    }
    // The law took part: five laws in the populations' table, stribeck among them.
    let cpu = populations(Path::new(&runs[0]));
    assert!(cpu.to_string().contains("stribeck"), "{cpu}");
    // The run stopped at two populations has more to go (its resume below continues it).
    assert!(cpu.as_array().unwrap().len() > 2, "{cpu}");
    // The same draws, acceptances and probabilities on both backends; ε, a median of ρ,
    // within the parity tolerance (the f32 sums round differently).
    let strip = |p: &serde_json::Value| -> Vec<serde_json::Value> {
        p.as_array()
            .unwrap()
            .iter()
            .map(|p| {
                let mut p = p.clone();
                p.as_object_mut()
                    .unwrap()
                    .retain(|k, _| !k.contains("seconds") && k != "near_threshold" && k != "epsilon");
                p
            })
            .collect()
    };
    let epsilons = |p: &serde_json::Value| -> Vec<f64> {
        p.as_array()
            .unwrap()
            .iter()
            .map(|p| p["epsilon"].as_f64().unwrap_or(f64::INFINITY))
            .collect()
    };
    for (a, b) in [(0, 1), (2, 3)] {
        let (a, b) = (populations(Path::new(&runs[a])), populations(Path::new(&runs[b])));
        assert!(strip(&a) == strip(&b), "runs differ beyond ε");
        for (x, y) in epsilons(&a).into_iter().zip(epsilons(&b)) {
            assert!(x == y || (x - y).abs() <= PARITY_TOLERANCE * x, "ε {x} against {y}");
        }
    }
    // The law file gone, the stopped run continues to the uninterrupted run's populations.
    std::fs::remove_file(&law).unwrap();
    let (code, _, stderr) = run(&cache, &["abc", "--resume", &runs[4], "--max-populations", "50", "-q"]);
    assert_eq!(code, 0, "{stderr}");
    // (A continued nested run rescores what the stopped one had scored: the work it counts
    // differs, not its populations.)
    let work = |p: Vec<serde_json::Value>| -> Vec<serde_json::Value> {
        p.into_iter()
            .map(|mut p| {
                p.as_object_mut()
                    .unwrap()
                    .retain(|k, _| k != "candidates_scored" && k != "evaluations");
                p
            })
            .collect()
    };
    let resumed = populations(Path::new(&runs[4]));
    assert!(work(strip(&cpu)) == work(strip(&resumed)), "the resumed run differs");
    assert_eq!(epsilons(&cpu), epsilons(&resumed));
    // And its report is written from the run alone.
    let report = out("report");
    let (code, _, stderr) = run(&cache, &["report", &runs[0], "--out", &report]);
    assert_eq!(code, 0, "{stderr}");
    let md = std::fs::read_to_string(Path::new(&report).join("report.md")).unwrap();
    assert!(md.contains("stribeck"), "the report names the law file's law");
    // The selection check re-simulates every law of the run, the file's among them (batched
    // records on the GPU).
    let (code, stdout, stderr) = run(
        &cache,
        &["check-selection", &runs[1], "--replicates", "1", "--backend", "gpu"],
    );
    assert_eq!(code, 0, "{stderr}");
    assert!(stdout.contains("stribeck data"), "{stdout}");
}

#[test]
fn a_bad_law_file_is_refused_naming_file_line_and_column_and_nothing_is_written() {
    let tmp = tempfile::tempdir().unwrap();
    let law = tmp.path().join("bad.toml");
    std::fs::write(
        &law,
        "name = \"bad\"\ntorque = \"r * (k + w)\"\n[[parameter]]\nname = \"k\"\nunit = \"N·m\"\n",
    )
    .unwrap();
    let target = tmp.path().join("run");
    let (code, _, stderr) = run(
        &tmp.path().join("cache"),
        &[
            "abc",
            "--law-file",
            law.to_str().unwrap(),
            "--out",
            target.to_str().unwrap(),
        ],
    );
    assert_eq!(code, 2, "{stderr}");
    assert!(
        stderr.contains(&format!("{}:2:11: torque: adding w to k", law.display())),
        "{stderr}"
    );
    assert!(!target.exists());
    // A law the command line names but no file defines.
    let (code, _, stderr) = run(&tmp.path().join("cache"), &["fit", "--laws", "m2,stribeck"]);
    assert_eq!(code, 2, "{stderr}");
    assert!(stderr.contains("--laws: unknown law 'stribeck'"), "{stderr}");
}

#[test]
#[cfg_attr(skip_gpu_tests, ignore = "BITROCK_SKIP_GPU_TESTS=1")]
fn the_built_in_laws_as_files_draw_the_same_stability_maps_on_both_backends() {
    require_gpu();
    let tmp = tempfile::tempdir().unwrap();
    let cache = tmp.path().join("cache");
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/laws");
    for (law, file) in [
        (Law::M1, "tucker_wang"),
        (Law::M2, "navarro_suarez"),
        (Law::M3, "gaussian_tanh"),
        (Law::M4, "cubic"),
    ] {
        let params: Vec<String> = law.paper_estimate().unwrap().iter().map(|p| p.to_string()).collect();
        let params = params.join(",");
        let path = dir.join(format!("{file}.toml"));
        for backend in ["cpu", "gpu"] {
            let map = |name: &str, extra: &[&str]| -> serde_json::Value {
                let mut args = vec![
                    "stability",
                    "--law",
                    name,
                    "--params",
                    &params,
                    "--backend",
                    backend,
                    "--json",
                ];
                args.extend_from_slice(extra);
                let (code, stdout, stderr) = run(&cache, &args);
                assert_eq!(code, 0, "{name} on {backend}: {stderr}");
                serde_json::from_str(&stdout).unwrap()
            };
            let built_in = map(law.name(), &[]);
            let as_file = map(file, &["--law-file", path.to_str().unwrap()]);
            // The unstable cells (dT/dw from the WGSL or the CPU twin), the same, cell for cell.
            assert_eq!(
                built_in["probability_unstable"][law.name()],
                as_file["probability_unstable"][file],
                "{file} on {backend}"
            );
            // The boundary weight on bit at every speed, within 1e-12 (f64 on the host).
            for key in ["map_wob_kn", "p_wob_kn"] {
                let a = built_in["boundaries"][law.name()][key].as_array().unwrap();
                let b = as_file["boundaries"][file][key].as_array().unwrap();
                assert_eq!(a.len(), b.len());
                for (x, y) in a.iter().zip(b) {
                    match (x.as_f64(), y.as_f64()) {
                        (Some(x), Some(y)) => {
                            assert!((x - y).abs() <= 1e-12 * x.abs(), "{file} {key}: {x} against {y}")
                        }
                        _ => assert_eq!(x, y, "{file} {key}"),
                    }
                }
            }
        }
    }
}

#[test]
fn simulate_runs_a_law_file_at_its_reference_values_and_refuses_one_without() {
    let tmp = tempfile::tempdir().unwrap();
    let cache = tmp.path().join("cache");
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/laws");
    let simulate = |law: &str, file: &str, extra: &[&str]| {
        let path = dir.join(file);
        let mut args = vec![
            "simulate",
            "--law-file",
            path.to_str().unwrap(),
            "--law",
            law,
            "--omega-rpm",
            "60",
            "--duration-s",
            "3",
        ];
        args.extend_from_slice(extra);
        run(&cache, &args)
    };
    // navarro_suarez at its references is m2 at the paper's estimate: the same record.
    let (code, as_file, stderr) = simulate("navarro_suarez", "navarro_suarez.toml", &[]);
    assert_eq!(code, 0, "{stderr}");
    let (code, built_in, stderr) = run(
        &cache,
        &["simulate", "--law", "m2", "--omega-rpm", "60", "--duration-s", "3"],
    );
    assert_eq!(code, 0, "{stderr}");
    assert_eq!(as_file, built_in);
    // stribeck gives no references: its parameters are needed.
    let (code, _, stderr) = simulate("stribeck", "stribeck.toml", &[]);
    assert_eq!(code, 2, "{stderr}");
    assert!(
        stderr.contains("--params") && stderr.contains("no reference values"),
        "{stderr}"
    );
    let (code, stdout, stderr) = simulate("stribeck", "stribeck.toml", &["--params", "9.5,5,8.8,0.04"]);
    assert_eq!(code, 0, "{stderr}");
    assert!(stdout.lines().count() > 100, "{stdout}");
}

#[test]
#[cfg_attr(skip_gpu_tests, ignore = "BITROCK_SKIP_GPU_TESTS=1")]
fn a_torque_with_no_value_rejects_its_candidate_on_both_backends() {
    require_gpu();
    // sqrt(h / t − 0.7) has no value where h < 0.7 t: about half of m2's prior box (tcb against
    // tsb) gives such candidates.
    let text = "name = \"partly_defined\"\ntorque = \"r * (t + h * sqrt(h / t - 0.7) * exp(-g * w))\"\n\
                [[parameter]]\nname = \"t\"\nunit = \"N·m\"\n[[parameter]]\nname = \"h\"\nunit = \"N·m\"\n\
                [[parameter]]\nname = \"g\"\nunit = \"s/rad\"\n";
    let law = register(LawFile::parse(text, Path::new("partly_defined.toml")).unwrap()).unwrap();
    let mut problem = demo_problem(&[Law::M2], 23);
    problem.prior.boxes[0].law = law;
    let count = 4_096;
    let mut cpu = vec![0.0; count];
    CpuEvaluator::new(problem.clone()).score(1, 0, &mut cpu).unwrap();
    let rejected = cpu.iter().filter(|r| **r == f64::INFINITY).count();
    assert!(cpu.iter().all(|r| !r.is_nan()));
    assert!(
        rejected > count / 10 && rejected < count * 9 / 10,
        "{rejected} of {count}"
    );
    for shape in [Shape::Blocked, Shape::Tiled] {
        let mut gpu = vec![0.0; count];
        GpuEvaluator::with_shape(problem.clone(), shape)
            .unwrap()
            .score(1, 0, &mut gpu)
            .unwrap();
        for (g, c) in gpu.iter().zip(&cpu) {
            if c.is_infinite() {
                assert_eq!(*g, f64::INFINITY, "{shape}");
            } else {
                assert!(((g - c) / c).abs() <= PARITY_TOLERANCE, "{shape}: {g} against {c}");
            }
        }
    }
}

#[test]
fn the_law_command_shows_a_law_file_as_compiled() {
    let tmp = tempfile::tempdir().unwrap();
    let cache = tmp.path().join("cache");
    let file = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/laws/stribeck.toml");
    let (code, stdout, stderr) = run(&cache, &["law", file.to_str().unwrap(), "--wgsl"]);
    assert_eq!(code, 0, "{stderr}");
    assert!(stdout.contains("law stribeck"), "{stdout}");
    // ∂T/∂cv = r·w, printed as the differentiator simplified it.
    assert!(
        stdout
            .lines()
            .any(|l| l.starts_with("cv") && l.contains("N·m·s/rad") && l.ends_with("(r * w)")),
        "{stdout}"
    );
    assert!(
        stdout.contains("fn file_torque_stribeck(p: array<f32, 6>, w: f32, r: f32) -> f32"),
        "{stdout}"
    );
    let bad = tmp.path().join("bad.toml");
    std::fs::write(
        &bad,
        "name = \"bad\"\ntorque = \"r * exp(k)\"\n[[parameter]]\nname = \"k\"\nunit = \"N·m\"\n",
    )
    .unwrap();
    let (code, _, stderr) = run(&cache, &["law", bad.to_str().unwrap()]);
    assert_eq!(code, 2, "{stderr}");
    assert!(
        stderr.contains("bad.toml:2:11: torque: the argument of exp k has dimension N·m"),
        "{stderr}"
    );
}

/// m2 as a law file named `name`, its decay rate g bounded by `g_bounds` (TOML lines).
fn capped_m2(name: &str, g_bounds: &str) -> String {
    format!(
        "name = \"{name}\"\ntorque = \"r * ((tsb - tcb) * exp(-g * w) + tcb)\"\n\
         [[parameter]]\nname = \"tsb\"\nunit = \"N·m\"\nlower = 0\n\
         [[parameter]]\nname = \"tcb\"\nunit = \"N·m\"\nlower = 0\n\
         [[parameter]]\nname = \"g\"\nunit = \"s/rad\"\n{g_bounds}\n"
    )
}

/// A law file's upper bounds: refused where they contradict the lower bound or the reference
/// (naming the file, line and column); kept by the fit, where a bound below the least-squares
/// value ends the parameter on it (said in the warnings, at a worse misfit) and one far above
/// changes nothing; and closing the physical prior box.
#[test]
fn a_law_files_upper_bounds_hold_in_the_fit_and_the_prior() {
    let refused = LawFile::parse(
        &capped_m2("inverted", "lower = 1\nupper = 0.5"),
        Path::new("inverted.toml"),
    )
    .unwrap_err();
    assert!(
        refused
            .to_string()
            .contains("inverted.toml:15:9: upper bound of 'g' = 0.5 does not lie above its lower bound 1"),
        "{refused}"
    );
    let refused = LawFile::parse(
        &capped_m2("beyond", "lower = 0\nupper = 0.5\nreference = 0.7"),
        Path::new("beyond.toml"),
    )
    .unwrap_err();
    assert!(
        refused
            .to_string()
            .contains("beyond.toml:16:13: reference of 'g' = 0.7 lies above its upper bound 0.5"),
        "{refused}"
    );

    let data = demo_field_data(&DataOptions::default()).unwrap();
    let m2 = fit_record(&[Law::M2], &data, &FitOptions::default()).unwrap().remove(0);
    let g_hat = m2.params_si[2];
    let cap = 0.5 * g_hat;
    let capped = register(
        LawFile::parse(
            &capped_m2("capped_g", &format!("lower = 0\nupper = {cap}")),
            Path::new("capped_g.toml"),
        )
        .unwrap(),
    )
    .unwrap();
    let loose = register(
        LawFile::parse(
            &capped_m2("loose_g", &format!("lower = 0\nupper = {}", 100.0 * g_hat)),
            Path::new("loose_g.toml"),
        )
        .unwrap(),
    )
    .unwrap();
    let fits = fit_record(&[capped, loose], &data, &FitOptions::default()).unwrap();
    let (on_cap, free) = (&fits[0], &fits[1]);
    assert!(
        (on_cap.params_si[2] - cap).abs() <= 1e-6 * cap,
        "g = {} against the cap {cap}",
        on_cap.params_si[2]
    );
    assert!(on_cap.rho > m2.rho * (1.0 + 1e-4), "{} against {}", on_cap.rho, m2.rho);
    assert!(
        on_cap
            .warnings
            .iter()
            .any(|w| w.contains("g sits on its physical bound (g ≤")),
        "{:?}",
        on_cap.warnings
    );
    assert!(
        (free.rho - m2.rho).abs() <= 1e-9 * m2.rho,
        "{} against {}",
        free.rho,
        m2.rho
    );
    assert!(
        !free.warnings.iter().any(|w| w.contains("physical bound")),
        "{:?}",
        free.warnings
    );

    let prior = bitrock::prior::Prior::physical(
        &[capped],
        &bitrock::prior::PhysicalScales::of(&data.calibration),
        10.0,
        None,
        1000.0,
    )
    .unwrap();
    let bx = &prior.boxes[0];
    assert!(
        f64::from(bx.upper[2]) <= cap * (1.0 + 1e-6) && bx.lower[2] == 0.0,
        "{bx:?}"
    );
    // Values beyond the cap are refused as parameters.
    let err = capped.check_params(&[13e3, 6.5e3, 2.0 * cap], "params").unwrap_err();
    assert!(err.to_string().contains("is above its physical bound"), "{err}");
}

/// A law file's `prior_curve_within` cuts its evidence prior as m4's file cuts m4's: the cubic
/// written as a law file with the same limit gets the same boxes, the same share of them within
/// the limit (the same draws) and the same evidence within its errors; a limit that is not a
/// positive number is refused naming the file, line and column.
#[test]
fn a_law_file_s_prior_curve_limit_is_the_built_in_cubic_s() {
    let tmp = tempfile::tempdir().unwrap();
    let cache = tmp.path().join("cache");
    let cubic =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/laws/cubic.toml")).unwrap();
    let with_limit = |limit: &str| cubic.replacen("torque = ", &format!("prior_curve_within = {limit}\ntorque = "), 1);
    let law = tmp.path().join("cubic.toml");
    std::fs::write(&law, with_limit("2")).unwrap();
    let (code, stdout, stderr) = run(
        &cache,
        &[
            "evidence",
            "--law-file",
            law.to_str().unwrap(),
            "--laws",
            "m4,cubic",
            "--thin",
            "8",
            "--particles",
            "100",
            "--islands",
            "2",
            "--noise",
            "iid",
            "--check",
            "0",
            "--backend",
            "cpu",
            "--json",
        ],
    );
    assert_eq!(code, 0, "{stderr}");
    let doc: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    let (m4, file) = (&doc["laws"][0], &doc["laws"][1]);
    assert_eq!(file["law"], "cubic");
    assert_eq!(m4["prior_curve"], file["prior_curve"]);
    assert!(
        (m4["prior_curve"]["ln_share"].as_f64().unwrap() + 2.412).abs() < 0.03,
        "{m4}"
    );
    let number = |l: &serde_json::Value, key: &str| l[key].as_f64().unwrap();
    let error = number(m4, "ln_z_error").hypot(number(file, "ln_z_error"));
    assert!(
        (number(m4, "ln_z") - number(file, "ln_z")).abs() < 0.1 + 3.0 * error,
        "m4 {} against the file's {} ± {error}",
        number(m4, "ln_z"),
        number(file, "ln_z")
    );
    for bad in ["0", "-1", "nan"] {
        std::fs::write(&law, with_limit(bad)).unwrap();
        let (code, _, stderr) = run(&cache, &["fit", "--law-file", law.to_str().unwrap(), "--laws", "cubic"]);
        assert_eq!(code, 2, "{stderr}");
        assert!(
            stderr.contains(&format!("{}:5:22: prior_curve_within = ", law.display())),
            "{bad}: {stderr}"
        );
    }
}
