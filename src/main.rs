//! The `bitrock` binary: parse, validate, call the library, print. Bad input exits with
//! status 2 and a message naming the file, line, column or flag; other failures exit 1.

mod cli;
mod export;
mod output;
mod progress;
mod stability_cmd;

use anyhow::Context;
use bitrock::abc::posterior::{PosteriorSummary, predictive_envelope, speed_grid, summarize};
use bitrock::abc::rejection::{Mode, RejectionConfig};
use bitrock::data::{self, FieldData};
use bitrock::eval::AbcProblem;
use bitrock::eval::Backend;
use bitrock::fit::{self, FitOptions};
use bitrock::prior::{Prior, PriorFile};
use bitrock::run::{Continuation, RunConfig, SamplerConfig};
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
            let done = abc_cmd(&cmd)?;
            let mut out = std::io::stdout().lock();
            if cmd.json {
                serde_json::to_writer_pretty(&mut out, &done.report)?;
                writeln!(out)?;
            } else {
                let dir = cmd.resume.as_ref().or(cmd.out.as_ref()).expect("clap requires one");
                output::print_population_table(&mut out, &done.outcome.run)?;
                output::print_posterior(&mut out, &done.posterior, done.outcome.setup.data.torque_unit)?;
                writeln!(out, "\nrun written to {}", dir.display())?;
            }
        }
        Command::Export(cmd) => export::export_cmd(&cmd)?,
        Command::Report(cmd) => {
            let summary = report_cmd(&cmd.runs, &cmd.out)?;
            println!(
                "report written to {} ({} figures, SVG and PNG)",
                summary.dir.join("report.md").display(),
                summary.figures.len()
            );
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
    outcome: bitrock::run::Outcome,
    posterior: PosteriorSummary,
    report: serde_json::Value,
}

/// `bitrock abc`: a new run into `--out`, or `--resume DIR`; then the summary files.
fn abc_cmd(cmd: &cli::AbcCmd) -> anyhow::Result<AbcDone> {
    set_threads(cmd.abc.threads)?;
    let quiet = cmd.quiet;
    let mut note = |line: String| {
        if !quiet {
            eprintln!("{line}");
        }
    };
    let mut progress = progress::RunProgress::new(quiet);
    let (outcome, dir) = match (&cmd.resume, &cmd.out) {
        (Some(dir), _) => {
            let more = Continuation {
                eps_min: cmd.abc.eps_min,
                max_populations: cmd.abc.max_populations,
                max_draws: cmd.abc.max_draws,
                min_acceptance: cmd.abc.min_acceptance,
                max_seconds: cmd.abc.max_seconds,
                backend: cmd.abc.backend,
            };
            (bitrock::run::resume(dir, &more, &mut progress, &mut note)?, dir)
        }
        (None, Some(dir)) => {
            let data = load_data(cmd.data.as_deref(), &cmd.data_args)?;
            let (config, prior_file) = abc_config(&data, &cmd.fit, &cmd.abc)?;
            bitrock::run::check_new_run_dir(dir, cmd.force)?;
            let outcome = bitrock::run::start(dir, data, config, prior_file.as_ref(), &mut progress, &mut note)?;
            (outcome, dir)
        }
        (None, None) => return Err(Error::arg("--out", "give the run directory to write").into()),
    };
    write_summary(dir, outcome, cmd.abc.summary_population)
}

fn set_threads(threads: Option<usize>) -> anyhow::Result<()> {
    if let Some(threads) = threads {
        if threads == 0 {
            return Err(Error::arg("--threads", "must be at least 1").into());
        }
        rayon::ThreadPoolBuilder::new().num_threads(threads).build_global()?;
    }
    Ok(())
}

/// The validated run configuration (and parsed prior file) of a new run, refused before any
/// work when a flag is out of range.
fn abc_config(
    data: &FieldData,
    fit_args: &FitArgs,
    args: &cli::AbcArgs,
) -> anyhow::Result<(RunConfig, Option<PriorFile>)> {
    let fit = fit_options(fit_args, data)?;
    let defaults = RejectionConfig::default();
    let sampler = RejectionConfig {
        particles: args.particles,
        eps_min: args.eps_min.unwrap_or(defaults.eps_min),
        max_populations: args.max_populations.unwrap_or(defaults.max_populations),
        max_draws: args.max_draws.unwrap_or(defaults.max_draws),
        min_acceptance: args.min_acceptance.unwrap_or(defaults.min_acceptance),
        start_epsilon: args.start_epsilon,
        epsilons: args.epsilons.clone(),
        mode: args.mode,
        max_seconds: args.max_seconds,
        ..defaults
    };
    sampler.validate()?;
    if !(args.delta.is_finite() && args.delta > 0.0) {
        return Err(Error::arg("--delta", format!("must be a positive number, got {}", args.delta)).into());
    }
    let prior_file = args.prior.as_deref().map(PriorFile::read).transpose()?;
    let config = RunConfig {
        laws: fit_args.laws.clone(),
        fit,
        delta: args.delta,
        prior_file: args.prior.clone(),
        seed: args.seed,
        backend: args.backend.unwrap_or(Backend::Auto),
        sampler: match args.sampler {
            cli::Sampler::Rejection => SamplerConfig::Rejection(sampler),
            cli::Sampler::Smc => SamplerConfig::Smc(bitrock::abc::smc::SmcConfig {
                base: sampler,
                p_stay: args.p_stay,
                kernel_scale: args.kernel_scale,
                weights_on: args.smc_weights,
            }),
        },
    };
    config.sampler.validate()?;
    Ok((config, prior_file))
}

/// Summarises population `summary_population` (default: the last) and writes run.json and
/// envelopes.csv (with data.csv beside) into the run directory, each whole or not at all.
fn write_summary(
    dir: &Path,
    outcome: bitrock::run::Outcome,
    summary_population: Option<usize>,
) -> anyhow::Result<AbcDone> {
    let run = &outcome.run;
    let data = &outcome.setup.data;
    let last = match summary_population {
        None => run.populations.last().ok_or_else(|| {
            anyhow::anyhow!(
                "no population completed: {}; continue with `bitrock abc --resume {}`",
                run.stop.describe(),
                dir.display()
            )
        })?,
        Some(g) => run.populations.get(g).ok_or_else(|| {
            Error::arg(
                "--summary-population",
                format!(
                    "the run has populations 0..={}",
                    run.populations.len().saturating_sub(1)
                ),
            )
        })?,
    };
    let laws = &outcome.config.laws;
    let posterior = summarize(&last.particles, laws);
    let all_speeds = data.calibration.speed_rad_s.iter().chain(&data.validation.speed_rad_s);
    let (lo, hi) = all_speeds.fold((f64::INFINITY, 0.0f64), |(a, b), &w| (a.min(w), b.max(w)));
    let grid = speed_grid(lo, hi, 200);
    let envelopes: Vec<_> = laws
        .iter()
        .filter_map(|&law| predictive_envelope(&last.particles, law, &grid, output::ENVELOPE_LEVEL, 1.0))
        .collect();
    let mut config = serde_json::to_value(&outcome.config)?;
    config["threads"] = rayon::current_num_threads().into();
    let report = output::AbcReport {
        data,
        fits: &outcome.setup.fits,
        prior: &outcome.setup.prior,
        run,
        posterior: &posterior,
        summary_population: last.record.index,
        config,
        seed: outcome.config.seed,
        backend: outcome.backend,
    }
    .json();
    // Written beside the targets, then moved into place.
    let staging = tempfile::Builder::new()
        .prefix(".bitrock-summary-")
        .tempdir_in(dir)
        .map_err(|source| Error::Write {
            path: dir.to_path_buf(),
            source,
        })?;
    std::fs::write(
        staging.path().join("run.json"),
        serde_json::to_string_pretty(&report)? + "\n",
    )?;
    output::write_envelopes(staging.path(), &envelopes, data)?;
    for name in ["run.json", "envelopes.csv", "data.csv"] {
        std::fs::rename(staging.path().join(name), dir.join(name)).map_err(|source| Error::Write {
            path: dir.join(name),
            source,
        })?;
    }
    Ok(AbcDone {
        outcome,
        posterior,
        report,
    })
}

/// Reads run directories into the report's runs and writes the report into `out`. The runs
/// must share their record (the figures draw one data set).
fn report_cmd(dirs: &[std::path::PathBuf], out: &Path) -> anyhow::Result<bitrock::report::ReportSummary> {
    let mut runs = Vec::new();
    let mut first: Option<bitrock::store::RunSetup> = None;
    for dir in dirs {
        let stored = bitrock::store::RunStore::open(dir)?.load()?;
        if stored.populations.is_empty() {
            return Err(Error::Data {
                path: dir.clone(),
                message: "the run has no completed population yet; continue it with `bitrock abc --resume`".into(),
            }
            .into());
        }
        let config: RunConfig = serde_json::from_value(stored.setup.config.clone()).map_err(|e| Error::Data {
            path: dir.clone(),
            message: format!("the stored configuration is not one this bitrock reads: {e}"),
        })?;
        if let Some(reference) = &first
            && (reference.data.calibration != stored.setup.data.calibration
                || reference.data.validation != stored.setup.data.validation)
        {
            return Err(Error::Data {
                path: dir.clone(),
                message: format!(
                    "its record differs from that of {}; a report draws runs of one record",
                    dirs[0].display()
                ),
            }
            .into());
        }
        runs.push(report_run(&runs, dir, &config, stored.populations, None));
        first.get_or_insert(stored.setup);
    }
    let setup = first.expect("clap requires at least one run");
    write_report(out, &setup, &runs)
}

/// One run of a report, labelled by its δ (and its directory when another run has the same δ).
fn report_run(
    earlier: &[bitrock::report::ReportRun],
    dir: &Path,
    config: &RunConfig,
    populations: Vec<bitrock::abc::Population>,
    summary: Option<PosteriorSummary>,
) -> bitrock::report::ReportRun {
    let same_delta = earlier.iter().any(|r| r.delta.to_bits() == config.delta.to_bits());
    let label = if same_delta {
        format!("δ = {} ({})", config.delta, dir.display())
    } else {
        format!("δ = {}", config.delta)
    };
    bitrock::report::ReportRun {
        label,
        delta: config.delta,
        laws: config.laws.clone(),
        populations,
        w_ref_n: config.fit.w_ref_n,
        summary,
    }
}

/// The report of `runs` (all of the record and fits in `setup`) with the paper's map settings.
fn write_report(
    out: &Path,
    setup: &bitrock::store::RunSetup,
    runs: &[bitrock::report::ReportRun],
) -> anyhow::Result<bitrock::report::ReportSummary> {
    let input = bitrock::report::ReportInput {
        data: &setup.data,
        fits: &setup.fits,
        runs,
        stability: bitrock::report::StabilitySettings::default(),
    };
    Ok(bitrock::report::write_report(out, &input)?)
}

/// Marks a directory the demo wrote, so that a later demo may replace it (and nothing else).
const DEMO_MARKER: &str = "bitrock-demo.txt";

/// The prior half-widths δ of the paper's three runs.
const DEMO_DELTAS: [f64; 3] = [0.4, 0.6, 0.8];

/// The whole paper on the embedded record: fits, ABC for δ = 0.4, 0.6, 0.8, printed as tables.
fn demo_cmd(cmd: &cli::DemoCmd) -> anyhow::Result<()> {
    let data = data::demo_field_data(&data::DataOptions::default())?;
    let root = &cmd.out;
    if root.exists()
        && !root.join(DEMO_MARKER).exists()
        && std::fs::read_dir(root).map_or(true, |mut d| d.next().is_some())
    {
        return Err(Error::arg(
            "--out",
            format!(
                "{} is not empty and was not written by `bitrock demo`; choose another directory",
                root.display()
            ),
        )
        .into());
    }
    set_threads(cmd.threads)?;
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
    if root.exists() {
        std::fs::remove_dir_all(root).map_err(|source| Error::Write {
            path: root.clone(),
            source,
        })?;
    }
    std::fs::create_dir_all(root).map_err(|source| Error::Write {
        path: root.clone(),
        source,
    })?;
    std::fs::write(
        root.join(DEMO_MARKER),
        "Written by `bitrock demo`; a later `bitrock demo` replaces this directory.\n",
    )?;
    let mut report_runs = Vec::new();
    let mut report_setup = None;
    let mut headlines = Vec::new();
    for delta in DEMO_DELTAS {
        let args = cli::AbcArgs {
            particles: cmd.particles,
            delta,
            prior: None,
            eps_min: None,
            epsilons: None,
            start_epsilon: None,
            max_populations: None,
            max_draws: None,
            min_acceptance: None,
            max_seconds: None,
            mode: Mode::Nested,
            sampler: cli::Sampler::Rejection,
            p_stay: 0.7,
            kernel_scale: 2.0,
            smc_weights: bitrock::abc::smc::WeightsOn::Host,
            seed: cmd.seed,
            threads: None,
            backend: Some(cmd.backend),
            summary_population: None,
        };
        let (config, _) = abc_config(&data, &fit_args, &args)?;
        let dir = root.join(format!("delta-{delta:.1}"));
        writeln!(
            out,
            "\nABC rejection with model selection: N = {}, δ = {delta}, ε_min = 0.014, seed {} → {}",
            args.particles,
            args.seed,
            dir.display()
        )?;
        let mut progress = progress::RunProgress::new(false);
        let outcome = bitrock::run::start(&dir, data.clone(), config, None, &mut progress, &mut |line| {
            eprintln!("{line}")
        })?;
        let done = write_summary(&dir, outcome, None)?;
        output::print_population_table(&mut out, &done.outcome.run)?;
        output::print_posterior(&mut out, &done.posterior, data.torque_unit)?;
        headlines.push((delta, done.outcome.run.populations.len(), done.posterior.clone()));
        // The report takes the runs as they are, with their summaries (no store reload, no
        // second kernel density estimate).
        let bitrock::run::Outcome { config, setup, run, .. } = done.outcome;
        report_runs.push(report_run(
            &report_runs,
            &dir,
            &config,
            run.populations,
            Some(done.posterior),
        ));
        report_setup.get_or_insert(setup);
    }
    let report_dir = root.join("report");
    let report = write_report(&report_dir, &report_setup.expect("three runs"), &report_runs)?;
    writeln!(out, "\n== bitrock demo: headline ==")?;
    writeln!(out, "final model probabilities (ε = 0.014):")?;
    for (delta, populations, posterior) in &headlines {
        let probabilities: Vec<String> = posterior
            .model_probabilities
            .iter()
            .map(|(law, p)| format!("P({law}) = {p:.3}"))
            .collect();
        writeln!(
            out,
            "  δ = {delta}: {} ({populations} populations)",
            probabilities.join(", ")
        )?;
    }
    if let Some(best) = headlines[0]
        .2
        .laws
        .iter()
        .max_by(|a, b| a.probability.total_cmp(&b.probability))
    {
        let unit = data.torque_unit;
        let map = best.law.scale_torque(&best.map, 1.0 / unit.newton_metres());
        let named: Vec<String> = best
            .law
            .params()
            .iter()
            .zip(&map)
            .map(|(spec, v)| format!("{} = {v:.4} {}", spec.name, spec.unit(unit.label())))
            .collect();
        writeln!(
            out,
            "most probable law at δ = 0.4: {}, MAP {}",
            best.law,
            named.join(", ")
        )?;
    }
    writeln!(out, "runs: {}", root.display())?;
    writeln!(
        out,
        "report: {} ({} figures as SVG and PNG: fits, model probabilities, tolerances, marginals, correlations, envelopes, stability maps 1-DOF and FE)",
        report.dir.join("report.md").display(),
        report.figures.len()
    )?;
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
        for d in &p.first_differences {
            writeln!(out, "  {d}")?;
        }
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
        Some(path) => output::write_file_atomically(path, |file| Ok(simulate::write_csv(&trace, file)?))
            .with_context(|| format!("saving the simulation to {}", path.display()))?,
    }
    Ok(())
}
