//! The GPU scoring shape chosen by measurement: the table an adapter measures, the wider tiles'
//! parity, the cache, and a run that records its shape and keeps it when resumed or checked.
//! These tests need a GPU adapter, as tests/it/gpu.rs's do.

use crate::gpu::{demo_problem, require_gpu};
use crate::support::{bin, outcome};
use bitrock::Law;
use bitrock::eval::cpu::CpuEvaluator;
use bitrock::eval::gpu::{self, Shape, residual::GpuEvaluator, tune};
use bitrock::eval::{Evaluator, PARITY_TOLERANCE};
use std::path::Path;

#[test]
#[cfg_attr(skip_gpu_tests, ignore = "BITROCK_SKIP_GPU_TESTS=1")]
fn the_table_times_every_shape_worth_trying_and_the_fastest_wins() {
    require_gpu();
    let ctx = gpu::context().unwrap();
    let tuning = tune::measure(ctx, &demo_problem(&Law::ALL, 5)).unwrap();
    for line in tuning.table() {
        eprintln!("{line}");
    }
    eprintln!("measured in {:.2} s", tuning.seconds);
    let tried = tune::worth_trying(ctx.info.device_type, &ctx.limits);
    assert_eq!(tuning.samples, 4_096);
    assert_eq!(tuning.bands.len(), tune::SIZES.len());
    let mut previous_winner = None;
    for (band, size) in tuning.bands.iter().zip(tune::SIZES) {
        assert_eq!(band.candidates, size);
        assert_eq!(band.timings.iter().map(|t| t.shape).collect::<Vec<_>>(), tried);
        // Each timing is a time, a lower bound already above the fastest, or a projection over
        // the cap: exactly one of them.
        let one = |t: &tune::Timing| [t.seconds, t.at_least_s, t.projected_s].iter().flatten().count() == 1;
        assert!(band.timings.iter().all(one), "{band:?}");
        let fastest = band
            .timings
            .iter()
            .filter_map(|t| Some((t.shape, t.seconds?)))
            .min_by(|a, b| a.1.total_cmp(&b.1));
        // The fastest timed shape wins; where none was timed, the smaller size's winner.
        match fastest {
            Some((shape, _)) => assert_eq!(band.winner, shape, "{band:?}"),
            None => assert_eq!(Some(band.winner), previous_winner, "{band:?}"),
        }
        previous_winner = Some(band.winner);
    }
    // The first size times every shape. Which shape wins is a measurement, not an invariant: on
    // lavapipe the two shapes' times lie within a few per cent of each other on a loaded machine.
    assert!(tuning.bands[0].timings.iter().all(|t| t.seconds.is_some()));
}

#[test]
#[cfg_attr(skip_gpu_tests, ignore = "BITROCK_SKIP_GPU_TESTS=1")]
fn wider_tiles_score_within_the_parity_tolerance_of_the_cpu() {
    require_gpu();
    let ctx = gpu::context().unwrap();
    let problem = demo_problem(&Law::ALL, 5);
    let cpu = CpuEvaluator::new(problem.clone());
    let count = 20_000;
    let mut expected = vec![0.0; count];
    cpu.score(2, 5_000, &mut expected).unwrap();
    for shape in [Shape::Tiled128, Shape::Tiled256] {
        if !shape.fits(&ctx.limits) {
            eprintln!("{shape} does not fit {}", ctx.describe());
            continue;
        }
        let gpu = GpuEvaluator::with_shape(problem.clone(), shape).unwrap();
        let mut got = vec![0.0; count];
        gpu.score(2, 5_000, &mut got).unwrap();
        let worst = got
            .iter()
            .zip(&expected)
            .map(|(g, c)| ((g - c) / c).abs())
            .fold(0.0, f64::max);
        eprintln!("{shape}: largest relative difference of rho {worst:.2e}");
        assert!(worst <= PARITY_TOLERANCE, "{shape}: {worst:e}");
    }
}

/// Runs the binary with a cache directory of its own and `env`; (status, stdout, stderr).
fn run(cache: &Path, env: &[(&str, &str)], args: &[&str]) -> (i32, String, String) {
    outcome(
        bin()
            .env(tune::CACHE_DIR_VAR, cache)
            .env_remove(gpu::SHAPE_VAR)
            .env_remove(tune::TUNING_VAR)
            .envs(env.iter().copied())
            .args(args),
    )
}

/// The `gpu_shape` of a run directory's run.json.
fn recorded_shape(run: &Path) -> serde_json::Value {
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("run.json")).unwrap()).unwrap();
    json["config"]["gpu_shape"].clone()
}

#[test]
#[cfg_attr(skip_gpu_tests, ignore = "BITROCK_SKIP_GPU_TESTS=1")]
fn the_first_run_measures_the_next_reads_the_cache_and_measuring_can_be_turned_off() {
    require_gpu();
    let dir = tempfile::tempdir().unwrap();
    let cache = dir.path().join("cache");
    let out = |name: &str| dir.path().join(name).to_str().unwrap().to_string();
    let abc = |cache: &Path, env: &[(&str, &str)], name: &str| {
        let out = out(name);
        // The embedded record thinned by 4: the shapes are measured on a problem of their own.
        let args = [
            "abc",
            "--thin",
            "4",
            "--particles",
            "200",
            "--max-populations",
            "2",
            "--backend",
            "gpu",
            "--out",
            &out,
        ];
        run(cache, env, &args)
    };
    let (code, _, stderr) = abc(&cache, &[], "a");
    assert_eq!(code, 0, "{stderr}");
    assert!(stderr.contains("measured fastest on this adapter just now"), "{stderr}");
    let file = cache.join(tune::CACHE_FILE);
    let kept = tune::read_cache(&file).unwrap();
    assert_eq!(kept.tunings.len(), 1);
    assert_eq!(kept.tunings[0].key, tune::adapter_key(gpu::context().unwrap()));
    // A run of N particles uses the band of 8 N candidates per dispatch.
    let shape = kept.tunings[0].shape_for(8 * 200);
    assert_eq!(recorded_shape(Path::new(&out("a"))), shape.name());
    let (code, _, stderr) = abc(&cache, &[], "b");
    assert_eq!(code, 0, "{stderr}");
    assert!(
        stderr.contains(&format!("({shape} scoring, measured fastest on this adapter)")),
        "{stderr}"
    );
    assert_eq!(
        std::fs::read_to_string(&file).unwrap(),
        serde_json::to_string_pretty(&kept).unwrap()
    );
    // Measuring off: the adapter type's guess, and no cache read or written.
    let off = dir.path().join("off-cache");
    let (code, _, stderr) = abc(&off, &[(tune::TUNING_VAR, "off")], "c");
    assert_eq!(code, 0, "{stderr}");
    let guess = Shape::guess(gpu::context().unwrap().info.device_type);
    assert!(
        stderr.contains(&format!(
            "({guess} scoring, guessed from the adapter type, measuring off)"
        )),
        "{stderr}"
    );
    assert!(!off.exists());
    // A value that is neither on nor off is refused before anything is written.
    let (code, stdout, stderr) = abc(&off, &[(tune::TUNING_VAR, "sometimes")], "d");
    assert_eq!(code, 2, "{stderr}");
    assert!(stdout.is_empty() && !Path::new(&out("d")).exists());
    assert!(
        stderr.contains(tune::TUNING_VAR) && stderr.contains("`sometimes`"),
        "{stderr}"
    );
}

#[test]
#[cfg_attr(skip_gpu_tests, ignore = "BITROCK_SKIP_GPU_TESTS=1")]
fn a_resumed_run_and_its_selection_check_score_in_the_recorded_shape() {
    require_gpu();
    let dir = tempfile::tempdir().unwrap();
    let cache = dir.path().join("cache");
    let path = |name: &str| dir.path().join(name).to_str().unwrap().to_string();
    let (split, whole) = (path("split"), path("whole"));
    let start = |out: &str, populations: &str| {
        let args = [
            "abc",
            "--thin",
            "4",
            "--particles",
            "300",
            "--seed",
            "4",
            "--backend",
            "gpu",
            "--eps-min",
            "0.02",
            "--max-populations",
            populations,
            "--out",
            out,
        ];
        // The tiled shape, named: lavapipe's measurement would pick the blocked one.
        run(&cache, &[(gpu::SHAPE_VAR, "tiled")], &args)
    };
    let (code, _, stderr) = start(&whole, "3");
    assert_eq!(code, 0, "{stderr}");
    assert!(
        stderr.contains("(tiled scoring, named by BITROCK_GPU_SHAPE)"),
        "{stderr}"
    );
    let (code, _, stderr) = start(&split, "2");
    assert_eq!(code, 0, "{stderr}");
    assert_eq!(recorded_shape(Path::new(&split)), "tiled");
    // Resumed without the variable: the recorded shape, and the uninterrupted run's particles.
    let (code, _, stderr) = run(&cache, &[], &["abc", "--resume", &split, "--max-populations", "3"]);
    assert_eq!(code, 0, "{stderr}");
    assert!(stderr.contains("(tiled scoring, recorded by the run)"), "{stderr}");
    assert_eq!(recorded_shape(Path::new(&split)), "tiled");
    let export = |run_dir: &str| {
        let csv = dir.path().join(format!(
            "{}.csv",
            Path::new(run_dir).file_name().unwrap().to_str().unwrap()
        ));
        let (code, _, stderr) = run(&cache, &[], &["export", run_dir, "-o", csv.to_str().unwrap()]);
        assert_eq!(code, 0, "{stderr}");
        std::fs::read_to_string(csv).unwrap()
    };
    assert_eq!(export(&split), export(&whole));
    // The selection check scores its replicates in the run's shape too.
    let (code, _, stderr) = run(&cache, &[], &["check-selection", &split, "--replicates", "1", "-q"]);
    assert_eq!(code, 0, "{stderr}");
    let check: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(Path::new(&split).join("selection").join("selection.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(check["gpu_shape"], "tiled", "{check}");
}
