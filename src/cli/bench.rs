//! `bitrock bench`: the benchmark report (throughput, fixed cost, end-to-end runs).

use bitrock::Error;
use bitrock::eval::Backend;
use clap::Args;
use std::io::Write;
use std::process::ExitCode;

#[derive(Debug, Args)]
pub struct BenchCmd {
    /// Repetitions per measurement (median, min and max are reported).
    #[arg(long, default_value_t = 5, value_name = "R")]
    pub reps: usize,
    /// Laws to measure, comma-separated (built-in laws and --law-file laws with reference values).
    #[arg(long, default_value = bitrock::built_in_law_list!(), value_name = "LAWS")]
    pub laws: String,
    /// Only this backend [default: both].
    #[arg(long, value_enum)]
    pub backend: Option<Backend>,
    /// Small sizes only (65,536 × 5,000; end-to-end with N = 5,000; the samplers near the noise
    /// floor with N = 200): a smoke test in seconds.
    #[arg(long)]
    pub quick: bool,
    /// Measure only `bitrock check-selection`: on the embedded record, a laboratory rig's
    /// record (N·m) and records from m2 and m4 (kN·m), all four made as `bitrock simulate`
    /// makes them, a run of every law (N = 5,000, to the record's floor), then K replicates
    /// per law checked, timed (up to 3 repetitions); K = 20 (K = 2 and N = 1,000 with
    /// --quick). --backend picks the backend [default: auto].
    #[arg(long)]
    pub selection: bool,
    /// Measure only the SMC schemes against the rejection sampler near the noise floor (ε_min
    /// = 1.1 × the record's best least-squares ρ, four laws, N = 4,000, on the CPU): on the
    /// embedded record, the laboratory rig's and the m2 record of --selection; one run per seed
    /// 1..=R (--reps): rejection, the classic SMC (fresh refill, model kernel, global
    /// perturbation), each change alone, survivors with worth, and all three (the default);
    /// candidates scored per final effective sample size, and agreement with rejection.
    /// --quick: N = 1,000.
    #[arg(long, conflicts_with = "selection")]
    pub smc: bool,
    /// Measure only `bitrock watch`: a simulated well of three formations (two of 60 s with
    /// --quick), watched with each window's evidence started from the one before (the
    /// default) and from the boxes (--cold-start), and by the paper's ABC (--abc): per-window
    /// latency, candidates, changes declared, agreement.
    #[arg(long, conflicts_with_all = ["selection", "smc"])]
    pub watch: bool,
    /// Measure only the simulated strings: string-seconds per second on the 1-DOF string and
    /// the paper's 10-element string lumped (65,536 strings × 60 s; 4,096 with --quick), and an
    /// escape map of 50 × 50 cells × 100 posterior samples (10 × 10 × 20 with --quick). Without
    /// --backend (or with auto), a software GPU is measured only where `auto` would simulate on
    /// it: not the 10-element string, which `auto` leaves to the CPU.
    #[arg(long, conflicts_with_all = ["selection", "smc", "watch"])]
    pub strings: bool,
    /// Measure only a surface record's inference (`bitrock surface`): ten minutes of m2 at 60
    /// rpm at 1 Hz, four laws, N = 2,000 (two minutes and N = 300 with --quick), on the GPU
    /// and the CPU (or the --backend named): wall time, strings per particle and rejection
    /// ABC's to the same tolerance.
    #[arg(long, conflicts_with_all = ["selection", "smc", "watch", "strings"])]
    pub surface: bool,
    /// Measure only the coupled axial-torsional bit's simulator (`bitrock coupled`):
    /// string-seconds per second, 16,384 strings × 60 s at 1e-4 s (1,024 with --quick), on
    /// 40–160 rpm and 100–260 kN.
    #[arg(long, conflicts_with_all = ["selection", "smc", "watch", "strings", "surface"])]
    pub coupled: bool,
    /// Strings per batch of --strings or --coupled [default: 65,536 and 16,384; 4,096 and
    /// 1,024 with --quick].
    #[arg(long, value_name = "N")]
    pub strings_n: Option<usize>,
    /// Measure the GPU scoring shapes again, even where this adapter's table is cached, and
    /// keep the new table.
    #[arg(long)]
    pub retune: bool,
    /// Print JSON instead of lines.
    #[arg(long)]
    pub json: bool,
}

pub fn run(cmd: &BenchCmd) -> anyhow::Result<ExitCode> {
    if cmd.reps == 0 {
        return Err(Error::setting("reps", "must be at least 1").into());
    }
    if cmd.watch {
        return watch(cmd);
    }
    if cmd.strings {
        return strings(cmd);
    }
    if cmd.coupled {
        return coupled(cmd);
    }
    if cmd.surface {
        return surface(cmd);
    }
    let opts = options(cmd)?;
    let report = bitrock::bench::run(&opts, &mut say(cmd, ""))?;
    print_report(cmd, &report, print_tables)
}

/// What a bench says while it runs, each line after `prefix`, on standard error; nothing with
/// `--json`, whose document alone goes out.
fn say(cmd: &BenchCmd, prefix: &'static str) -> impl FnMut(String) {
    let quiet = cmd.json;
    move |line| {
        if !quiet {
            super::print::note(format_args!("{prefix}{line}"));
        }
    }
}

/// The bench's options from the flags.
fn options(cmd: &BenchCmd) -> anyhow::Result<bitrock::bench::BenchOptions> {
    let mut opts = bitrock::bench::BenchOptions {
        repetitions: cmd.reps,
        laws: super::args::parse_laws(&cmd.laws)?,
        retune: cmd.retune,
        ..Default::default()
    };
    match cmd.backend {
        Some(bitrock::eval::Backend::Auto) | None => {}
        Some(b) => opts.backends = vec![b],
    }
    if cmd.quick {
        opts.sizes = vec![(65_536, 5_000)];
        opts.particles = 5_000;
        opts.floor_particles = 200;
        opts.stability = (128, 1_000);
    }
    if cmd.selection {
        opts.selection = Some(if cmd.quick {
            (2, bitrock::bench::SELECTION_QUICK_PARTICLES)
        } else {
            (20, bitrock::bench::SELECTION_PARTICLES)
        });
        // The check runs on one backend: the one asked for, auto otherwise.
        opts.backends = vec![cmd.backend.unwrap_or(Backend::Auto)];
    }
    if cmd.smc {
        use bitrock::bench::SelectionRecord;
        let records = vec![SelectionRecord::Embedded, SelectionRecord::Rig, SelectionRecord::M2];
        opts.smc = Some((records, if cmd.quick { 1_000 } else { 4_000 }, cmd.reps as u64));
    }
    Ok(opts)
}

/// The bench's report as tables: the machine, the scoring shapes, throughput per backend and
/// law, the small call, the stability grid, the selection check, the SMC schemes and the
/// paper-scale run.
fn print_tables(out: &mut dyn Write, report: &bitrock::bench::BenchReport) -> std::io::Result<()> {
    writeln!(
        out,
        "machine: {} ({} cores); adapter: {}",
        report.machine, report.cores, report.adapter
    )?;
    if let Some(t) = &report.tuning {
        let kept = t
            .cache_file
            .as_ref()
            .map_or(String::new(), |p| format!(", kept in {}", p.display()));
        writeln!(out, "GPU scoring shapes ({}{kept}):", t.source)?;
        for line in t.tuning.table().iter().skip(1) {
            writeln!(out, "  {line}")?;
        }
    }
    if let Some(shape) = report.shape {
        writeln!(out, "GPU scoring shape at 65,536 candidates per dispatch: {shape}")?;
    }
    writeln!(out, "medians of {} repetitions (min–max)", report.repetitions)?;
    // Law names: built-in and law files' laws, as wide as the widest.
    let width = report
        .throughput
        .iter()
        .map(|t| t.law.name().len())
        .max()
        .unwrap_or(3)
        .max(3);
    if !report.throughput.is_empty() {
        writeln!(
            out,
            "backend  {:<width$}          N        D   evaluations/s (min–max)  shape",
            "law"
        )?;
    }
    for t in &report.throughput {
        writeln!(
            out,
            "{:<7}  {:<width$}  {:>9}  {:>7}   {:.3e} ({:.2e}–{:.2e})  {}",
            t.backend,
            t.law.name(),
            t.n,
            t.d,
            t.evals_per_s,
            t.evals_per_s_spread.min,
            t.evals_per_s_spread.max,
            t.shape.map_or("", |s| s.name())
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
    print_selection(out, &report.selection)?;
    print_smc(out, &report.smc)?;
    for e in &report.end_to_end {
        writeln!(
            out,
            "{:<7}  paper-scale run: {:.3} s ({:.3}–{:.3}), {} populations, {:.3e} evaluations",
            e.backend, e.seconds, e.seconds_spread.min, e.seconds_spread.max, e.populations, e.evaluations as f64
        )?;
    }
    Ok(())
}

/// The selection check's table: one row per record.
fn print_selection(out: &mut dyn Write, selection: &[bitrock::bench::SelectionBench]) -> std::io::Result<()> {
    if let Some(first) = selection.first() {
        writeln!(
            out,
            "check-selection: {} laws × {} replicates, N = {} (--backend {}, scored on {}); medians (min–max)",
            first.laws,
            first.replicates_per_law,
            first.particles,
            serde_json::to_value(first.backend_asked)?.as_str().unwrap_or_default(),
            first.backend,
        )?;
        writeln!(
            out,
            "record    samples  ε_min    check s (min–max)     fits s  share  sampling s  fits out of patience  runs out / abandoned"
        )?;
    }
    for c in selection {
        writeln!(
            out,
            "{:<8}  {:>7}  {:<7.4}  {:>6.2} ({:.2}–{:.2})  {:>6.2}  {:>4.0} %  {:>10.2}  {:>9} of {:<8}  {} / {} of {}",
            c.record.name(),
            c.calibration_samples,
            c.eps_min,
            c.seconds,
            c.seconds_spread.min,
            c.seconds_spread.max,
            c.fit_seconds,
            100.0 * c.fit_share,
            c.sampling_seconds,
            c.fits.fits_out_of_patience,
            c.fits.fits,
            c.fits.runs_out_of_patience,
            c.fits.runs_abandoned,
            c.fits.runs,
        )?;
    }
    for c in selection.iter().filter(|c| c.command.is_some()) {
        writeln!(out, "  {}: {}", c.record.name(), c.command.unwrap_or_default())?;
    }
    Ok(())
}

/// The SMC schemes against rejection: one table per record.
fn print_smc(out: &mut dyn Write, smc: &[bitrock::bench::smc_comparison::SmcComparison]) -> std::io::Result<()> {
    for c in smc {
        writeln!(
            out,
            "{}: {} samples, best least-squares ρ {:.5}, ε_min {:.5}, N = {}, {} seeds; medians over the seeds",
            c.record.name(),
            c.calibration_samples,
            c.best_least_squares_rho,
            c.eps_min,
            c.particles,
            c.schemes.first().map_or(0, |s| s.runs.len())
        )?;
        writeln!(
            out,
            "  scheme                 scored/ESS  fewer than rejection  max |ΔP|/SE  max KS/critical"
        )?;
        for s in &c.schemes {
            writeln!(
                out,
                "  {:<21}  {:>10.1}  {:>19.1}×  {:>11.1}  {:>15.2}",
                s.scheme.name, s.scored_per_ess, s.fewer_than_rejection, s.max_probability_z, s.max_ks_ratio
            )?;
        }
        if let Some(command) = c.command {
            writeln!(out, "  record: {command}")?;
        }
    }
    Ok(())
}

/// `--watch`: the watch bench ([`bitrock::watch::bench`]), a table or JSON.
fn watch(cmd: &BenchCmd) -> anyhow::Result<ExitCode> {
    let scratch = tempfile::tempdir()?;
    let backend = cmd.backend.unwrap_or(Backend::Auto);
    let report = bitrock::watch::bench::run(cmd.quick, backend, scratch.path(), &mut say(cmd, "note: "))?;
    print_report(cmd, &report, |out, report| {
        writeln!(out, "watch of {}", report.record)?;
        writeln!(
            out,
            "start  windows  latency median   p90     p99   candidates/window (median)  total        changes  whole (s)"
        )?;
        for r in &report.runs {
            writeln!(
                out,
                "{:<5}  {:>7}  {:>12.3} s  {:>5.2} s  {:>5.2} s  {:>26}  {:>11}  {:>7}  {:>9.1}",
                r.start,
                r.windows,
                r.latency_median_s,
                r.latency_p90_s,
                r.latency_p99_s,
                r.candidates_median,
                r.candidates_total,
                format!("{:?}", r.changes),
                r.seconds
            )?;
        }
        let windows = report.runs.first().map_or(0, |r| r.windows);
        writeln!(
            out,
            "warm and cold: probabilities within 0.05 in {} of {windows} windows, the same law first in {}",
            report.agree_within_005, report.same_most_probable
        )?;
        Ok(())
    })
}

/// `report` on standard output: as JSON with `--json`, else as `table` writes it.
fn print_report<R: serde::Serialize>(
    cmd: &BenchCmd,
    report: &R,
    table: impl FnOnce(&mut dyn Write, &R) -> std::io::Result<()>,
) -> anyhow::Result<ExitCode> {
    let mut out = super::print::stdout();
    if cmd.json {
        serde_json::to_writer_pretty(&mut out, report)?;
        writeln!(out)?;
    } else {
        table(&mut out, report)?;
    }
    Ok(ExitCode::SUCCESS)
}

/// `--surface`: a surface record's inference end to end, on each backend asked for.
fn surface(cmd: &BenchCmd) -> anyhow::Result<ExitCode> {
    let mut reports = Vec::new();
    for backend in simulated_backends(cmd) {
        let opts = bitrock::bench::surface::SurfaceBenchOptions {
            record_s: if cmd.quick { 120.0 } else { 600.0 },
            particles: if cmd.quick { 300 } else { 2000 },
            repetitions: cmd.reps,
            backend,
        };
        reports.push(bitrock::bench::surface::run(&opts, &mut say(cmd, ""))?);
    }
    print_report(cmd, &reports, |out, reports| {
        for report in reports {
            writeln!(
                out,
                "surface inference on the {}: {}, four laws, N = {}",
                report.backend, report.record, report.particles
            )?;
            writeln!(
                out,
                "wall time {:.1} s (median of {}; {:.1}–{:.1}), {} strings simulated",
                report.wall_s.median, cmd.reps, report.wall_s.min, report.wall_s.max, report.strings
            )?;
            writeln!(
                out,
                "strings per particle: {:.1}; rejection ABC to the same ε: {}",
                report.strings_per_particle,
                report
                    .rejection_strings_per_particle
                    .map_or("more than the pilot".to_string(), |n| format!("{n:.0}"))
            )?;
            let probabilities: Vec<String> = report
                .probabilities
                .iter()
                .map(|(l, p)| format!("{l} {p:.3}"))
                .collect();
            writeln!(out, "P(law): {}; {}", probabilities.join(", "), report.verdict)?;
        }
        Ok(())
    })
}

/// The backends a simulator's benchmark measures: both where none (or auto) is named.
fn simulated_backends(cmd: &BenchCmd) -> Vec<Backend> {
    match cmd.backend {
        Some(Backend::Auto) | None => vec![Backend::Gpu, Backend::Cpu],
        Some(b) => vec![b],
    }
}

/// `--strings-n`, or the batch `quick` or `full` without it; at least one string.
fn strings_n(cmd: &BenchCmd, quick: usize, full: usize) -> anyhow::Result<usize> {
    let n = cmd.strings_n.unwrap_or(if cmd.quick { quick } else { full });
    if n == 0 {
        return Err(Error::setting("strings_n", "must be at least 1").into());
    }
    Ok(n)
}

/// `--coupled`: the coupled bit's simulator throughput, per backend.
fn coupled(cmd: &BenchCmd) -> anyhow::Result<ExitCode> {
    let opts = bitrock::bench::coupled::CoupledBenchOptions {
        strings: strings_n(cmd, 1_024, 16_384)?,
        seconds: 60.0,
        dt_s: 1e-4,
        backends: simulated_backends(cmd),
        repetitions: cmd.reps,
    };
    let report = bitrock::bench::coupled::run(&opts, &mut say(cmd, ""))?;
    print_report(cmd, &report, |out, report| {
        writeln!(
            out,
            "coupled bit (RGD) strings, dt = {} s, medians of {} repetitions (min–max)",
            opts.dt_s, opts.repetitions
        )?;
        for m in report {
            let [steady, stick_slip, bounce, both] = m.regimes;
            let lanes = match m.subgroup_vote {
                Some(true) => ", lanes by subgroup vote",
                Some(false) => ", each lane alone (no subgroup operations)",
                None => "",
            };
            writeln!(
                out,
                "{}  steady {steady:.2}, stick-slip {stick_slip:.2}, bounce {bounce:.2}, both {both:.2}{lanes}",
                m.throughput
            )?;
        }
        Ok(())
    })
}

/// `--strings`: the simulator's throughput and an escape map's time, per backend.
fn strings(cmd: &BenchCmd) -> anyhow::Result<ExitCode> {
    let opts = bitrock::bench::strings::StringsBenchOptions {
        strings: strings_n(cmd, 4_096, 65_536)?,
        seconds: 60.0,
        dt_s: bitrock::run::strings::DEFAULT_DT_S,
        map: if cmd.quick { (10, 10, 20) } else { (50, 50, 100) },
        backends: simulated_backends(cmd),
        repetitions: cmd.reps,
        gpu_where_auto_takes_it: matches!(cmd.backend, None | Some(Backend::Auto)),
    };
    let report = bitrock::bench::strings::run(&opts, &mut say(cmd, ""))?;
    print_report(cmd, &report, |out, report| {
        writeln!(
            out,
            "simulated strings, dt = {} s, medians of {} repetitions (min–max)",
            opts.dt_s, opts.repetitions
        )?;
        for m in report {
            writeln!(out, "{:<22} {:<5} {}", m.what, m.string, m.throughput)?;
        }
        Ok(())
    })
}
