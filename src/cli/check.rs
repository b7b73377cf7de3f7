//! `bitrock check-selection DIR`: how far the model selection of a run or an evidence can be
//! trusted, by re-simulation ([`bitrock::run::selection`], [`bitrock::run::evidence::check`]);
//! the confusion matrix on stdout (or JSON), the results in `DIR/selection/` (a run) or the
//! evidence's document (an evidence).

use super::args::set_threads;
use bitrock::eval::Backend;
use bitrock::run::selection::{self, CheckOptions, CheckedRun, SelectionCheck};
use clap::Args;
use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Debug, Args)]
pub struct CheckCmd {
    /// Run directory (written by `bitrock abc --out`) whose selection is checked, the results
    /// in RUN_DIR/selection/ (selection.json, matrix.csv, replicates.csv, confusion.svg/png);
    /// or evidence directory (written by `bitrock evidence --out`), its evidence computed again
    /// and checked as `bitrock evidence --check K` checks it, the check written into its
    /// evidence.json; or surface directory (written by `bitrock surface --out`), its check by
    /// re-simulation made again with K records per law and written into its surface.json.
    #[arg(value_name = "RUN_DIR")]
    pub run: PathBuf,
    /// Synthetic records per law, K.
    #[arg(long, default_value_t = CheckOptions::default().replicates, value_name = "K")]
    pub replicates: usize,
    /// Replicates run at once, their candidates scored together (one GPU dispatch or one
    /// pass over the CPU threads per round) [default: all].
    #[arg(long, value_name = "COUNT")]
    pub batch: Option<usize>,
    /// Where ρ is computed [default: the run's backend].
    #[arg(long, value_enum)]
    pub backend: Option<Backend>,
    /// Worker threads [default: all cores].
    #[arg(long, value_name = "N")]
    pub threads: Option<usize>,
    /// No progress lines on stderr.
    #[arg(long, short)]
    pub quiet: bool,
    /// Print the check as JSON instead of tables.
    #[arg(long)]
    pub json: bool,
}

pub fn run(cmd: &CheckCmd) -> anyhow::Result<ExitCode> {
    if bitrock::run::dir::is_evidence_dir(&cmd.run) {
        return check_evidence(cmd);
    }
    if bitrock::run::surface::dir::is_surface_dir(&cmd.run) {
        return check_surface(cmd);
    }
    let options = CheckOptions {
        replicates: cmd.replicates,
        backend: cmd.backend,
        batch: cmd.batch,
    };
    options.validate()?;
    set_threads(cmd.threads)?;
    bitrock::run::dir::refuse_unfinished_evidence(&cmd.run)?;
    let checked = CheckedRun::open(&cmd.run)?;
    if let Some(why) = bitrock::run::abc::Store::open(&cmd.run)?.early_end()? {
        super::print::note(format_args!("note: {}: {why}", cmd.run.display()));
    }
    let quiet = cmd.quiet;
    let progress = |done: usize, total: usize| {
        if !quiet {
            super::print::note(format_args!("replicate {done}/{total}"));
        }
    };
    let check = selection::check(&checked, &options, &progress, &mut |line| {
        if !quiet {
            super::print::note(line);
        }
    })?;
    let written = bitrock::report::write_selection(&checked, &check)?;
    let mut out = std::io::stdout().lock();
    if cmd.json {
        serde_json::to_writer_pretty(&mut out, &check)?;
        writeln!(out)?;
    } else {
        table(&mut out, &check)?;
        writeln!(out, "\ncheck written to {}", written.display())?;
    }
    Ok(ExitCode::SUCCESS)
}

/// The check of an evidence directory: its evidence computed again, checked, the check
/// written into its document.
fn check_evidence(cmd: &CheckCmd) -> anyhow::Result<ExitCode> {
    if cmd.batch.is_some() {
        return Err(bitrock::Error::setting(
            "batch",
            "an evidence's check runs its replicates one after the other: leave --batch out",
        )
        .into());
    }
    set_threads(cmd.threads)?;
    let quiet = cmd.quiet;
    let mut progress = |done: usize, total: usize| {
        if !quiet {
            super::print::note(format_args!("evidence check: replicate {done}/{total}"));
        }
    };
    let check = bitrock::run::evidence::dir::check_dir(
        &cmd.run,
        cmd.replicates,
        cmd.backend,
        &mut bitrock::run::Scoring::Here,
        &mut progress,
        &mut super::evidence::Notes,
    )?;
    let mut out = std::io::stdout().lock();
    if cmd.json {
        serde_json::to_writer_pretty(&mut out, &check)?;
        writeln!(out)?;
    } else {
        super::evidence::check_table(&mut out, &check)?;
        writeln!(
            out,
            "
check written to {}",
            cmd.run.join("evidence.json").display()
        )?;
    }
    Ok(ExitCode::SUCCESS)
}

/// The confusion matrix, the generating law's own probability and the verdicts.
fn table(out: &mut impl Write, check: &SelectionCheck) -> std::io::Result<()> {
    writeln!(
        out,
        "Selection check of {}: {} replicates per law, N = {}, {} prior, backend {}, {:.1} s",
        check
            .run_dir
            .as_deref()
            .unwrap_or(std::path::Path::new("the run"))
            .display(),
        check.replicates,
        check.particles,
        match check.prior_rule {
            bitrock::prior::PriorRule::Delta => format!("δ = {}", check.delta),
            bitrock::prior::PriorRule::Stderr { k } => format!("φ̂ ± {k}·σ̂"),
        },
        check.backend,
        check.seconds
    )?;
    let t = &check.timing;
    writeln!(
        out,
        "synthetic records and fits {:.1} s, sampling {:.1} s (scoring {:.1} s in {} batches; {:.3e} candidate × data-point evaluations)",
        t.fit_seconds, t.sampling_seconds, t.scoring_seconds, t.batches, t.evaluations as f64
    )?;
    let f = &t.fits;
    if f.fits > 0 {
        writeln!(
            out,
            "least squares: {} fits, {} Levenberg-Marquardt runs; {} runs spent their patience (in {} fits; {} estimates did not converge), {} stopped early behind a better run",
            f.fits,
            f.runs,
            f.runs_out_of_patience,
            f.fits_out_of_patience,
            f.estimates_out_of_patience,
            f.runs_abandoned
        )?;
    }
    writeln!(
        out,
        "\nrows: law that made the data; columns: mean posterior probability (share ranked first)"
    )?;
    let rows = check.rows.iter().map(|row| {
        let q = &row.own_probability;
        super::print::ConfusionRow {
            law: row.law,
            mean_probability: &row.mean_probability,
            first_share: &row.first_share,
            tail: format!("{:.3} / {:.3} / {:.3}", q.q10, q.median, q.q90),
        }
    });
    super::print::confusion_matrix(out, &check.laws, "P(own) 10% / median / 90%", rows)?;
    writeln!(out)?;
    for row in &check.rows {
        let source = match row.source {
            selection::ParamSource::Posterior => "",
            selection::ParamSource::LeastSquares => " (the law died out: its least-squares estimate made the data)",
        };
        writeln!(out, "{}{source}", row.verdict)?;
    }
    Ok(())
}

/// The surface run in `cmd.run` checked again by re-simulation with `--replicates` records per
/// law: its populations as stored (none added), the check, the bit and the directory written
/// anew.
fn check_surface(cmd: &CheckCmd) -> anyhow::Result<ExitCode> {
    set_threads(cmd.threads)?;
    if cmd.batch.is_some() {
        return Err(bitrock::Error::setting(
            "batch",
            "applies to an ABC run's check; a surface run's re-simulated records are simulated together",
        )
        .into());
    }
    let quiet = cmd.quiet;
    let result = bitrock::run::surface::dir::check_again(&cmd.run, cmd.replicates, cmd.backend, &mut |line| {
        if !quiet {
            super::print::note(format_args!("note: {line}"));
        }
    })?;
    let mut out = std::io::stdout().lock();
    if cmd.json {
        serde_json::to_writer_pretty(&mut out, &result.check)?;
        writeln!(out)?;
    } else {
        super::surface::check_table(&mut out, &result)?;
        writeln!(
            out,
            "\ncheck written to {}",
            cmd.run.join(bitrock::run::dir::SURFACE_JSON).display()
        )?;
    }
    Ok(ExitCode::SUCCESS)
}
