//! `bitrock demo`: the whole paper on the embedded record: the fits, three calls of the
//! library's ABC job (δ = 0.4, 0.6, 0.8), the report, and the headline numbers.

use super::args::set_threads;
use super::fit::fit_and_print;
use super::print;
use super::progress::RunProgress;
use bitrock::abc::evidence::EvidenceConfig;
use bitrock::abc::posterior::PosteriorSummary;
use bitrock::abc::schedule::Schedule;
use bitrock::data;
use bitrock::data::FieldData;
use bitrock::eval::Backend;
use bitrock::report::ReportRun;
use bitrock::report::ReportSummary;
use bitrock::run;
use bitrock::run::abc::SamplerConfig;
use bitrock::run::answer::Answer;
use bitrock::run::dir::Owned;
use bitrock::run::evidence::{EvidenceAnalysis, EvidenceCheck};
use bitrock::{Error, files};
use clap::Args;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

#[derive(Debug, Args)]
pub struct DemoCmd {
    /// Directory of the demo: the runs (delta-0.4/, delta-0.6/, delta-0.8/) and report/.
    #[arg(long, value_name = "DIR", default_value = "bitrock-demo")]
    pub out: PathBuf,
    /// Particles per population (the paper's N is 25,000); each of the model evidence's
    /// islands gets N/50 (500 at the paper's N, at least 20).
    #[arg(long, default_value_t = Schedule::default().particles, value_name = "N")]
    pub particles: usize,
    /// Seed of the candidate streams.
    #[arg(long, default_value_t = bitrock::run::abc::Config::default().seed)]
    pub seed: u64,
    /// Worker threads [default: all cores].
    #[arg(long, value_name = "N")]
    pub threads: Option<usize>,
    /// Where ρ is computed and the report's strings integrated (auto, gpu, cpu).
    #[arg(long, value_enum, default_value_t = Backend::Auto)]
    pub backend: Backend,
    /// Synthetic records per law with which the model evidence's answer is checked by
    /// re-simulation, as `bitrock evidence --check` checks it [default: 4; 0: no check].
    #[arg(long, value_name = "K")]
    pub check: Option<usize>,
}

/// Marks a directory the demo wrote, so that a later demo may replace it (and nothing else).
const DEMO_MARKER: &str = "bitrock-demo.txt";

/// The demo's report, beside its runs.
const REPORT_DIR: &str = "report";

/// The prior half-widths δ of the paper's three runs.
const DEMO_DELTAS: [f64; 3] = [0.4, 0.6, 0.8];

/// The whole paper on the embedded record: fits, ABC for δ = 0.4, 0.6, 0.8, printed as tables,
/// the report, and the headline numbers.
pub fn run(cmd: &DemoCmd) -> anyhow::Result<ExitCode> {
    let data = data::demo_field_data(&data::DataOptions::default())?;
    let root = &cmd.out;
    check_root(root)?;
    set_threads(cmd.threads)?;
    let defaults = bitrock::run::abc::Config::default();
    let evidence_job = run::evidence::Settings {
        particles: (cmd.particles / 50).clamp(20, EvidenceConfig::default().particles),
        seed: cmd.seed,
        backend: cmd.backend,
        ..Default::default()
    }
    .job(defaults.laws.clone(), defaults.fit)?;
    let replicates = run::evidence::replicates_asked(cmd.check, evidence_job.laws.len());
    if let Some(replicates) = replicates {
        run::evidence::check_size(replicates, "check", &evidence_job, &data)?;
    }
    let mut out = super::print::stdout();
    writeln!(
        out,
        "bitrock demo: the embedded record is synthetic (made by `bitrock simulate`, see data/README.md);"
    )?;
    writeln!(out, "the paper's field data are not public.\n")?;
    // The runs below fit the record as this does: they take these fits.
    let fits = fit_and_print(&data, &defaults.laws, &defaults.fit, false)?;
    mark_root(root)?;
    let mut report_runs = Vec::new();
    let mut report_setup = None;
    let mut headlines = Vec::new();
    for delta in DEMO_DELTAS {
        let dir = root.join(run_dir_name(delta));
        let schedule = Schedule {
            particles: cmd.particles,
            ..Schedule::default()
        };
        writeln!(
            out,
            "\nABC rejection with model selection: N = {}, δ = {delta}, ε_min = {}, seed {} → {}",
            schedule.particles,
            schedule.eps_min,
            cmd.seed,
            dir.display()
        )?;
        let eps_min = schedule.eps_min;
        let job = run::abc::Job {
            config: bitrock::run::abc::Config {
                delta,
                seed: cmd.seed,
                backend: cmd.backend,
                sampler: SamplerConfig::Rejection(schedule.into()),
                ..bitrock::run::abc::Config::default()
            },
            summary_population: None,
            out: Some(bitrock::run::Dir {
                path: dir.clone(),
                replace: true,
            }),
        };
        let done = job.run_fitted(
            data.clone(),
            Some(fits.clone()),
            Default::default(),
            &mut RunProgress::new(false),
        )?;
        for warning in done.run_warnings() {
            super::print::note(format_args!("warning: {warning}"));
        }
        print::population_table(&mut out, &done.outcome.run)?;
        print::posterior(&mut out, &done.posterior, data.torque_unit)?;
        headlines.push(Headline {
            delta,
            eps_min,
            answer: done.answer.clone(),
            populations: done.outcome.run.populations.len(),
            posterior: done.posterior.clone(),
            caveats: done
                .outcome
                .run
                .populations
                .last()
                .map_or_else(Vec::new, |p| p.record.probability_caveats()),
        });
        // The report takes the runs as they are, with their summaries (no store reload, no
        // second kernel density estimate).
        let bitrock::run::abc::Outcome { config, setup, run, .. } = done.outcome;
        let mut report_run = ReportRun::new(&report_runs, &dir, &config, run.populations, Some(done.posterior));
        report_run.answer = done.answer;
        report_runs.push(report_run);
        report_setup.get_or_insert(setup);
    }
    writeln!(
        out,
        "\nmodel evidence: tempered SMC per law over physical boxes (no fit involved), i.i.d. and AR(1) residuals, the noise model chosen by its evidence"
    )?;
    let (evidence, check) = checked_evidence(&evidence_job, replicates, &data)?;
    let report_dir = root.join(REPORT_DIR);
    let report = bitrock::report::write_paper_report(
        &report_dir,
        &report_setup.expect("three runs"),
        &report_runs,
        Some(&evidence.evidence),
        bitrock::report::StabilitySettings {
            simulated: Some(Default::default()),
            backend: cmd.backend,
            ..Default::default()
        },
    )?;
    print_headline(&mut out, &headlines, (&evidence, check.as_ref()), &data, root, &report)?;
    Ok(ExitCode::SUCCESS)
}

/// The model evidence of the demo's laws on `data` (its particles scaled from the ABC runs'),
/// checked by re-simulation with `replicates` records per law as `bitrock evidence` checks it.
fn checked_evidence(
    job: &run::evidence::Job,
    replicates: Option<usize>,
    data: &FieldData,
) -> anyhow::Result<(EvidenceAnalysis, Option<EvidenceCheck>)> {
    let evidence = job.run(data, Default::default(), &mut RunProgress::new(false))?;
    let check = replicates
        .map(|replicates| {
            run::evidence::check(
                job,
                data,
                &evidence,
                replicates,
                &mut Default::default(),
                &mut |_, _| {},
                &mut RunProgress::new(false),
            )
        })
        .transpose()?;
    Ok((evidence, check))
}

/// Refuses an `--out` that holds something the demo did not write: a directory that is not
/// empty must be an earlier demo's (its marker) and hold nothing but the demo's runs, report
/// and marker ([`files::refuse_foreign`], the rule of `abc --force`).
fn check_root(root: &Path) -> anyhow::Result<()> {
    files::check_output_dir(root, "out")?;
    bitrock::run::dir::refuse_inside_kept_dir(root, "out")?;
    let empty = std::fs::read_dir(root).map_or(true, |mut d| d.next().is_none());
    if empty {
        return Ok(());
    }
    if !root.join(DEMO_MARKER).is_file() {
        return Err(Error::setting(
            "out",
            format!(
                "{} is not empty and was not written by `bitrock demo`; choose another directory",
                root.display()
            ),
        )
        .into());
    }
    files::refuse_foreign(root, "out", &|rel, is_dir| demo_owns(root, rel, is_dir))?;
    Ok(())
}

/// What the demo writes in its directory `root`: its marker, one run directory per δ, the
/// report (its files unchanged since the demo wrote them).
fn demo_owns(root: &Path, rel: &Path, is_dir: bool) -> bool {
    let mut parts = rel.components();
    let Some(first) = parts.next().and_then(|c| c.as_os_str().to_str()) else {
        return false;
    };
    let rest = parts.as_path();
    let top = rest.as_os_str().is_empty();
    if first == DEMO_MARKER {
        return top && !is_dir;
    }
    let owned = if DEMO_DELTAS.iter().any(|d| first == run_dir_name(*d)) {
        Owned::Run
    } else if first == REPORT_DIR {
        Owned::Report
    } else {
        return false;
    };
    if top {
        is_dir
    } else {
        bitrock::run::dir::owns_unchanged(owned, &root.join(first), rest, is_dir)
    }
}

/// The run directory of the demo's run with prior half-width `delta`.
fn run_dir_name(delta: f64) -> String {
    format!("delta-{delta:.1}")
}

/// Creates the demo's directory and marks it as the demo's (one [`check_root`] accepted). Its
/// runs and report are then replaced one by one, each in one step, so an interrupted demo
/// leaves each of them old or new, never half-written, and never anything of the user's lost.
fn mark_root(root: &Path) -> anyhow::Result<()> {
    std::fs::create_dir_all(root).map_err(|source| Error::output("out", root, source))?;
    files::write_own(&root.join(DEMO_MARKER), "out", |out| {
        out.write_all(
            b"Written by `bitrock demo`; a later `bitrock demo` replaces the runs and the report in this directory.\n",
        )
    })?;
    Ok(())
}

/// What the headline says of one run.
struct Headline {
    delta: f64,
    eps_min: f64,
    /// The run's answer to "which law, how sure".
    answer: Option<Answer>,
    populations: usize,
    posterior: PosteriorSummary,
    /// Which final probabilities are 0 by construction, and whether best-fit ρ alone decides.
    caveats: Vec<String>,
}

/// The closing lines: each run's final model probabilities, the MAP of the most probable law
/// of the first run, and where the runs and the report are.
fn print_headline(
    out: &mut impl Write,
    headlines: &[Headline],
    (evidence, check): (&EvidenceAnalysis, Option<&EvidenceCheck>),
    data: &FieldData,
    root: &Path,
    report: &ReportSummary,
) -> std::io::Result<()> {
    writeln!(out, "\n== bitrock demo: headline ==")?;
    if let Some(answer) = evidence.answer(check) {
        writeln!(out, "answer: {}", answer.sentence())?;
    }
    writeln!(
        out,
        "the paper's ABC model probabilities (ε = {}; shares of each law's prior box below ε):",
        headlines[0].eps_min
    )?;
    for h in headlines {
        let probabilities: Vec<String> = h
            .posterior
            .model_probabilities
            .iter()
            .map(|(law, p)| format!("P({law}) = {p:.3}"))
            .collect();
        writeln!(
            out,
            "  δ = {}: {} ({} populations)",
            h.delta,
            probabilities.join(", "),
            h.populations
        )?;
        for caveat in &h.caveats {
            writeln!(out, "    {caveat}")?;
        }
        if let Some(answer) = &h.answer {
            writeln!(out, "    its answer: {}", answer.sentence())?;
        }
    }
    let laws = &evidence.evidence.laws;
    let probabilities: Vec<String> = laws
        .iter()
        .map(|l| format!("P({}) = {:.3}", l.law, l.probability))
        .collect();
    writeln!(
        out,
        "model evidence (physical boxes, {}{}, chosen by its evidence): {}",
        evidence.evidence.config.noise.label(),
        evidence
            .fit
            .w_ref_n
            .map_or(String::new(), |w| format!(", torque × WOB/{:.1} kN", w / 1000.0)),
        probabilities.join(", ")
    )?;
    let factors = evidence.evidence.bayes_factors(&evidence.separations);
    if let [top, ..] = &factors[..] {
        let factors: Vec<String> = factors
            .iter()
            .map(|f| format!("{:.1} ± {:.1} against {} ({})", f.ln_b, f.error, f.against, f.strength))
            .collect();
        writeln!(out, "    {}: ln B = {}", top.favoured, factors.join(", "))?;
    }
    let first = &headlines[0];
    if let Some(best) = first
        .posterior
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
            "most probable law at δ = {}: {}, MAP {}",
            first.delta,
            best.law,
            named.join(", ")
        )?;
    }
    if let Some(advice) = &report.advice {
        writeln!(
            out,
            "advice at the record's operating point (δ = {}'s posterior, simulated strings): {advice}",
            first.delta
        )?;
    }
    writeln!(out, "runs: {}", root.display())?;
    writeln!(
        out,
        "report: {} ({} figures as SVG and PNG: fits, model probabilities, tolerances, marginals, correlations, envelopes, stability maps 1-DOF and FE, stick-slip by simulated strings)",
        report.dir.join("report.md").display(),
        report.figures.len()
    )
}
