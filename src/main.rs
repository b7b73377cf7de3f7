//! The `bitrock` binary: parse, validate, call the library, print. Bad input exits with
//! status 2 and a message naming the file, line, column or flag; other failures exit 1.

mod cli;
mod output;
mod stability_cmd;

use anyhow::Context;
use bitrock::abc::Run;
use bitrock::abc::posterior::{PosteriorSummary, predictive_envelope, speed_grid, summarize};
use bitrock::abc::rejection::{self, Mode, RejectionConfig};
use bitrock::data::{self, FieldData};
use bitrock::eval::AbcProblem;
use bitrock::fit::{self, FitOptions};
use bitrock::prior::{Prior, PriorFile};
use bitrock::simulate::{self, Initial, SimConfig};
use bitrock::units::{RAD_S_PER_RPM, TorqueUnit};
use bitrock::{Error, Law};
use clap::Parser;
use cli::{Cli, Command, FitArgs};
use std::io::Write;
use std::path::Path;
use std::process::ExitCode;

fn main() -> ExitCode {
    match run(Cli::parse()) {
        Ok(code) => code,
        Err(err) => {
            eprintln!("error: {err:#}");
            let bad_input = err
                .chain()
                .any(|e| e.downcast_ref::<Error>().is_some_and(Error::is_bad_input));
            ExitCode::from(if bad_input { 2 } else { 1 })
        }
    }
}

fn run(cli: Cli) -> anyhow::Result<ExitCode> {
    match cli.command {
        Command::Fit(cmd) => {
            let data = load_data(cmd.data.as_deref(), &cmd.data_args)?;
            fit_and_print(&data, &cmd.fit, cmd.json)?;
        }
        Command::Abc(cmd) => {
            let data = load_data(cmd.data.as_deref(), &cmd.data_args)?;
            let done = run_abc(&data, &cmd.fit, &cmd.abc, &cmd.out, cmd.force, cmd.json)?;
            let mut out = std::io::stdout().lock();
            if cmd.json {
                serde_json::to_writer_pretty(&mut out, &done.report)?;
                writeln!(out)?;
            } else {
                output::print_population_table(&mut out, &done.run)?;
                output::print_posterior(&mut out, &done.posterior, data.torque_unit)?;
                writeln!(out, "\nrun written to {}", cmd.out.display())?;
            }
        }
        Command::Simulate(cmd) => simulate_cmd(&cmd)?,
        Command::Demo(cmd) => demo_cmd(&cmd)?,
        Command::Parity(cmd) => return parity_cmd(&cmd),
        Command::Bench(cmd) => bench_cmd(&cmd)?,
        Command::Fe(cmd) => stability_cmd::fe_cmd(&cmd)?,
        Command::Stability(cmd) => stability_cmd::stability_cmd(&cmd)?,
    }
    Ok(ExitCode::SUCCESS)
}

/// The record at `path`, or the embedded demo record (saying so) when there is none.
fn load_data(path: Option<&Path>, args: &cli::DataArgs) -> anyhow::Result<FieldData> {
    let opts = args.options();
    Ok(match path {
        Some(path) => data::read_field_data(path, &opts)?,
        None => {
            eprintln!("note: no DATA given; using the embedded synthetic demo record");
            data::demo_field_data(&opts)?
        }
    })
}

/// Validated fit options from the flags.
fn fit_options(args: &FitArgs, data: &FieldData) -> anyhow::Result<FitOptions> {
    if !(args.w_ref_kn.is_finite() && args.w_ref_kn > 0.0) {
        return Err(Error::arg(
            "--w-ref-kn",
            format!("must be a positive number of kN, got {}", args.w_ref_kn),
        )
        .into());
    }
    if args.starts == 0 {
        return Err(Error::arg("--starts", "must be at least 1").into());
    }
    if args.scale_by_wob && data.calibration.wob_n.is_none() {
        return Err(Error::arg(
            "--scale-by-wob",
            "the record has no weight-on-bit column (name one with --wob-col)",
        )
        .into());
    }
    Ok(FitOptions {
        bounded: !args.no_bounds,
        starts: args.starts,
        w_ref_n: args.scale_by_wob.then_some(args.w_ref_kn * 1000.0),
    })
}

fn fit_and_print(data: &FieldData, args: &FitArgs, json: bool) -> anyhow::Result<()> {
    let opts = fit_options(args, data)?;
    let fits = fit::fit_laws(&args.laws, &data.calibration, &data.validation, &opts)?;
    let mut out = std::io::stdout().lock();
    if json {
        serde_json::to_writer_pretty(&mut out, &output::fit_json(data, &fits))?;
        writeln!(out)?;
    } else {
        output::print_fit_tables(&mut out, data, &fits)?;
    }
    Ok(())
}

/// What an ABC run leaves for printing.
struct AbcDone {
    run: Run,
    posterior: PosteriorSummary,
    report: serde_json::Value,
}

/// Refuses a run directory that would be overwritten without --force, before any work.
fn check_run_dir(dir: &Path, force: bool) -> anyhow::Result<()> {
    if dir.exists() {
        if !dir.is_dir() {
            return Err(Error::arg("--out", format!("{} exists and is not a directory", dir.display())).into());
        }
        let non_empty = std::fs::read_dir(dir)?.next().is_some();
        if non_empty && !force {
            return Err(Error::arg(
                "--out",
                format!("{} is not empty; pass --force to replace it", dir.display()),
            )
            .into());
        }
    }
    Ok(())
}

/// Fit, prior, rejection sampling, summaries; writes the run directory whole or not at all.
fn run_abc(
    data: &FieldData,
    fit_args: &FitArgs,
    args: &cli::AbcArgs,
    out_dir: &Path,
    force: bool,
    quiet: bool,
) -> anyhow::Result<AbcDone> {
    // Everything that can be refused is refused before any work.
    let fit_opts = fit_options(fit_args, data)?;
    let config = RejectionConfig {
        particles: args.particles,
        eps_min: args.eps_min,
        max_populations: args.max_populations,
        max_draws: args.max_draws,
        min_acceptance: args.min_acceptance,
        start_epsilon: args.start_epsilon,
        epsilons: args.epsilons.clone(),
        mode: args.mode,
        ..RejectionConfig::default()
    };
    config.validate()?;
    let smc_config = bitrock::abc::smc::SmcConfig {
        base: config.clone(),
        p_stay: args.p_stay,
        kernel_scale: args.kernel_scale,
        weights_on: args.smc_weights,
    };
    smc_config.validate()?;
    if !(args.delta.is_finite() && args.delta > 0.0) {
        return Err(Error::arg("--delta", format!("must be a positive number, got {}", args.delta)).into());
    }
    let prior_file = args.prior.as_deref().map(PriorFile::read).transpose()?;
    check_run_dir(out_dir, force)?;
    if let Some(threads) = args.threads {
        if threads == 0 {
            return Err(Error::arg("--threads", "must be at least 1").into());
        }
        rayon::ThreadPoolBuilder::new().num_threads(threads).build_global()?;
    }

    let fits = fit::fit_laws(&fit_args.laws, &data.calibration, &data.validation, &fit_opts)?;
    let prior = Prior::from_fits(&fits, args.delta, prior_file.as_ref(), data.torque_unit.newton_metres())?;
    let problem = AbcProblem::new(prior.clone(), args.seed, &data.calibration, fit_opts.w_ref_n);
    let evaluator = bitrock::eval::evaluator(problem, args.backend, &mut |note| {
        if !quiet {
            eprintln!("{note}");
        }
    })?;
    struct Log {
        quiet: bool,
    }
    impl bitrock::abc::Observer for Log {
        fn population_done(&mut self, p: &bitrock::abc::Population) -> bitrock::Result<()> {
            let r = &p.record;
            if !self.quiet {
                let eps = r.epsilon.map(|e| format!("{e:.5}")).unwrap_or_else(|| "∞".into());
                eprintln!(
                    "population {:>2}: ε = {eps}, {} accepted of {} drawn, {:.2} s",
                    r.index, r.accepted, r.draws, r.seconds
                );
            }
            Ok(())
        }
    }
    let run = match args.sampler {
        cli::Sampler::Rejection => {
            rejection::run_observed(evaluator.as_ref(), &config, Vec::new(), &mut Log { quiet })?
        }
        cli::Sampler::Smc => {
            bitrock::abc::smc::run_observed(evaluator.as_ref(), &smc_config, Vec::new(), &mut Log { quiet })?
        }
    };
    let last = match args.summary_population {
        None => run
            .populations
            .last()
            .ok_or_else(|| Error::Numerical("no population completed".into()))?,
        Some(g) => run.populations.get(g).ok_or_else(|| {
            Error::arg(
                "--summary-population",
                format!("the run has populations 0..={}", run.populations.len() - 1),
            )
        })?,
    };
    let posterior = summarize(&last.particles, &fit_args.laws);
    let all_speeds = data.calibration.speed_rad_s.iter().chain(&data.validation.speed_rad_s);
    let (lo, hi) = all_speeds.fold((f64::INFINITY, 0.0f64), |(a, b), &w| (a.min(w), b.max(w)));
    let grid = speed_grid(lo, hi, 200);
    let envelopes: Vec<_> = fit_args
        .laws
        .iter()
        .filter_map(|&law| predictive_envelope(&last.particles, law, &grid, output::ENVELOPE_LEVEL, 1.0))
        .collect();
    let report = output::AbcReport {
        data,
        fits: &fits,
        prior: &prior,
        run: &run,
        posterior: &posterior,
        summary_population: last.record.index,
        config: serde_json::json!({
            "particles": args.particles,
            "delta": args.delta,
            "prior_file": args.prior.as_ref().map(|p| p.display().to_string()),
            "eps_min": args.eps_min,
            "epsilons": args.epsilons,
            "start_epsilon": args.start_epsilon,
            "max_populations": args.max_populations,
            "max_draws": args.max_draws,
            "min_acceptance": args.min_acceptance,
            "mode": args.mode,
            "sampler": args.sampler,
            "p_stay": args.p_stay,
            "kernel_scale": args.kernel_scale,
            "smc_weights": args.smc_weights,
            "laws": fit_args.laws,
            "bounded_fit": fit_opts.bounded,
            "w_ref_kn_for_wob_scaling": fit_opts.w_ref_n.map(|w| w / 1000.0),
            "threads": rayon::current_num_threads(),
        }),
        seed: args.seed,
        backend: evaluator.backend(),
    }
    .json();

    // Write into a fresh directory beside the target, then move it into place.
    let parent = out_dir
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    std::fs::create_dir_all(parent).map_err(|source| Error::Write {
        path: parent.to_path_buf(),
        source,
    })?;
    let staging = tempfile::Builder::new()
        .prefix(".bitrock-run-")
        .tempdir_in(parent)
        .map_err(|source| Error::Write {
            path: parent.to_path_buf(),
            source,
        })?;
    std::fs::write(
        staging.path().join("run.json"),
        serde_json::to_string_pretty(&report)? + "\n",
    )?;
    std::fs::create_dir(staging.path().join("populations"))?;
    for p in &run.populations {
        let path = staging
            .path()
            .join("populations")
            .join(format!("population_{:03}.csv", p.record.index));
        output::write_particles(&path, &p.particles, &fit_args.laws, data.torque_unit)?;
    }
    output::write_envelopes(staging.path(), &envelopes, data)?;
    if out_dir.exists() {
        std::fs::remove_dir_all(out_dir).map_err(|source| Error::Write {
            path: out_dir.to_path_buf(),
            source,
        })?;
    }
    let staged = staging.keep();
    std::fs::rename(&staged, out_dir).map_err(|source| Error::Write {
        path: out_dir.to_path_buf(),
        source,
    })?;
    Ok(AbcDone { run, posterior, report })
}

/// The whole pipeline on the embedded record: fits, then ABC, printed as tables.
fn demo_cmd(cmd: &cli::DemoCmd) -> anyhow::Result<()> {
    let data = data::demo_field_data(&data::DataOptions::default())?;
    // The demo replaces its own run directory, but nothing else.
    let replace = cmd.out.join("run.json").exists();
    let mut out = std::io::stdout().lock();
    writeln!(
        out,
        "bitrock demo: the embedded record is synthetic (made by `bitrock simulate`, see data/README.md);"
    )?;
    writeln!(out, "the paper's field data are not public.\n")?;
    let fit_args = FitArgs {
        laws: Law::ALL.to_vec(),
        no_bounds: false,
        starts: 6,
        scale_by_wob: false,
        w_ref_kn: 244.2,
    };
    fit_and_print(&data, &fit_args, false)?;
    let args = cli::AbcArgs {
        particles: cmd.particles,
        delta: 0.4,
        prior: None,
        eps_min: 0.014,
        epsilons: None,
        start_epsilon: None,
        max_populations: 30,
        max_draws: 2_000_000_000,
        min_acceptance: 1e-5,
        mode: Mode::Nested,
        sampler: cli::Sampler::Rejection,
        p_stay: 0.7,
        kernel_scale: 2.0,
        smc_weights: bitrock::abc::smc::WeightsOn::Host,
        seed: cmd.seed,
        threads: cmd.threads,
        backend: cmd.backend,
        summary_population: None,
    };
    writeln!(
        out,
        "ABC rejection with model selection: N = {}, δ = 0.4, ε_min = 0.014, seed {}",
        args.particles, args.seed
    )?;
    let done = run_abc(&data, &fit_args, &args, &cmd.out, replace, false)?;
    output::print_population_table(&mut out, &done.run)?;
    output::print_posterior(&mut out, &done.posterior, data.torque_unit)?;
    writeln!(out, "\nrun written to {}", cmd.out.display())?;
    Ok(())
}

fn parity_cmd(cmd: &cli::ParityCmd) -> anyhow::Result<ExitCode> {
    if cmd.candidates == 0 {
        return Err(Error::arg("--candidates", "must be at least 1").into());
    }
    if let Some(e) = cmd.epsilon
        && !(e.is_finite() && e > 0.0)
    {
        return Err(Error::arg("--epsilon", format!("must be a positive number, got {e}")).into());
    }
    let data = load_data(cmd.data.as_deref(), &cmd.data_args)?;
    let fits = fit::fit_laws(&cmd.laws, &data.calibration, &data.validation, &FitOptions::default())?;
    let prior = Prior::from_fits(&fits, 0.4, None, data.torque_unit.newton_metres())?;
    let problem = AbcProblem::new(prior, cmd.seed, &data.calibration, None);
    let report = bitrock::bench::parity(&problem, cmd.candidates, cmd.epsilon)?;
    let mut out = std::io::stdout().lock();
    if cmd.json {
        serde_json::to_writer_pretty(&mut out, &report)?;
        writeln!(out)?;
    } else {
        writeln!(out, "adapter: {}", report.adapter)?;
        writeln!(
            out,
            "data: {} points; tolerance on the relative difference of ρ: {:e}",
            problem.data_len(),
            report.tolerance
        )?;
        writeln!(
            out,
            "law  candidates  max rel.diff  median rel.diff     epsilon  decisions differ (near ε)"
        )?;
        for l in &report.laws {
            writeln!(
                out,
                "{:<3}  {:>10}  {:>12.3e}  {:>15.3e}  {:>10.5}  {:>8} ({})",
                l.law,
                l.candidates,
                l.max_rel_diff,
                l.median_rel_diff,
                l.epsilon,
                l.decisions_differ,
                l.decisions_differ_near_threshold
            )?;
        }
        let p = &report.philox;
        writeln!(
            out,
            "Philox: {} of {} words differ; candidates: {} of {} differ",
            p.words_differ, p.words_compared, p.candidates_differ, p.candidates_compared
        )?;
        writeln!(
            out,
            "{}",
            if report.pass {
                "PASS: this GPU agrees with the CPU reference"
            } else {
                "FAIL: do not trust this GPU's results"
            }
        )?;
    }
    Ok(if report.pass {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(1)
    })
}

fn bench_cmd(cmd: &cli::BenchCmd) -> anyhow::Result<()> {
    if cmd.reps == 0 {
        return Err(Error::arg("--reps", "must be at least 1").into());
    }
    let mut opts = bitrock::bench::BenchOptions {
        repetitions: cmd.reps,
        laws: cmd.laws.clone(),
        ..Default::default()
    };
    match cmd.backend {
        Some(bitrock::eval::Backend::Auto) | None => {}
        Some(b) => opts.backends = vec![b],
    }
    if cmd.quick {
        opts.sizes = vec![(65_536, 5_000)];
        opts.particles = 5_000;
        opts.stability = (128, 1_000);
    }
    let quiet = cmd.json;
    let report = bitrock::bench::run(&opts, &mut |line| {
        if !quiet {
            eprintln!("{line}");
        }
    })?;
    let mut out = std::io::stdout().lock();
    if cmd.json {
        serde_json::to_writer_pretty(&mut out, &report)?;
        writeln!(out)?;
    } else {
        writeln!(
            out,
            "machine: {} ({} cores); adapter: {}",
            report.machine, report.cores, report.adapter
        )?;
        writeln!(out, "medians of {} repetitions (min–max)", report.repetitions)?;
        writeln!(out, "backend  law          N        D   evaluations/s (min–max)")?;
        for t in &report.throughput {
            writeln!(
                out,
                "{:<7}  {:<3}  {:>9}  {:>7}   {:.3e} ({:.2e}–{:.2e})",
                t.backend, t.law, t.n, t.d, t.evals_per_s, t.evals_per_s_spread.min, t.evals_per_s_spread.max
            )?;
        }
        for (backend, s) in &report.small_call_seconds {
            writeln!(
                out,
                "{backend:<7}  small call (64 × 100): {:.3e} s ({:.2e}–{:.2e})",
                s.median, s.min, s.max
            )?;
        }
        if let Some(st) = &report.stability {
            writeln!(
                out,
                "gpu      stability grid: {} cells × {} samples: {:.3e} cell-samples/s ({:.2e}–{:.2e})",
                st.cells,
                st.samples,
                st.cell_samples_per_s,
                st.cell_samples_per_s_spread.min,
                st.cell_samples_per_s_spread.max
            )?;
        }
        for e in &report.end_to_end {
            writeln!(
                out,
                "{:<7}  paper-scale run: {:.3} s ({:.3}–{:.3}), {} populations, {:.3e} evaluations",
                e.backend, e.seconds, e.seconds_spread.min, e.seconds_spread.max, e.populations, e.evaluations as f64
            )?;
        }
    }
    Ok(())
}

fn simulate_cmd(cmd: &cli::SimulateCmd) -> anyhow::Result<()> {
    let law: Law = cmd.law;
    let params = cmd.params.clone().unwrap_or_else(|| {
        let p = law.paper_estimate();
        law.scale_torque(
            p,
            TorqueUnit::KNm.newton_metres() / cmd.param_torque_unit.newton_metres(),
        )
    });
    let config = SimConfig {
        law,
        params_nm: law.scale_torque(&params, cmd.param_torque_unit.newton_metres()),
        structure: cmd.lumped.lumped(),
        omega_rad_s: cmd.omega_rpm * RAD_S_PER_RPM,
        wob_n: cmd.wob_kn * 1000.0,
        w_ref_n: cmd.w_ref_kn * 1000.0,
        duration_s: cmd.duration_s,
        settle_s: cmd.settle_s,
        sample_hz: cmd.sample_hz,
        dt_s: cmd.dt_s,
        initial: match cmd.initial {
            cli::InitialState::Equilibrium => Initial::Equilibrium {
                speed_perturbation_rad_s: cmd.kick_rpm * RAD_S_PER_RPM,
            },
            cli::InitialState::Rest => Initial::Rest,
        },
        noise_torque_nm: cmd.noise_torque_knm * 1000.0,
        noise_speed_rad_s: cmd.noise_speed_rpm * RAD_S_PER_RPM,
        wob_fluctuation_n: cmd.wob_fluctuation_kn * 1000.0,
        wob_correlation_s: cmd.wob_correlation_s,
        seed: cmd.seed,
    };
    config.validate()?;
    let trace = simulate::simulate(&config)?;
    match &cmd.out {
        None => simulate::write_csv(&trace, std::io::stdout().lock())?,
        Some(path) => {
            // Write beside the target and rename, so a failure leaves nothing half-written.
            let dir = path
                .parent()
                .filter(|d| !d.as_os_str().is_empty())
                .unwrap_or(std::path::Path::new("."));
            let mut tmp = tempfile::NamedTempFile::new_in(dir).map_err(|source| Error::Write {
                path: path.clone(),
                source,
            })?;
            simulate::write_csv(&trace, &mut tmp)?;
            tmp.persist(path)
                .map_err(|e| Error::Write {
                    path: path.clone(),
                    source: e.error,
                })
                .with_context(|| format!("saving the simulation to {}", path.display()))?;
        }
    }
    Ok(())
}
