//! `bitrock evidence`: the marginal likelihood of each law on a record and the posterior law
//! probabilities it gives, through [`bitrock::run::evidence`]; tables or JSON.

use super::args::{InferenceArgs, finite_number, load_data, set_threads};
use super::print;
use bitrock::abc::evidence::sensitivity::every_box_widened;
use bitrock::abc::evidence::{Evidence, EvidenceConfig, LN_Z_PER_DOUBLING, REFINE_ABOVE_NATS, Start, describe_starts};
use bitrock::data::FieldData;
use bitrock::documents::to_record_units;
use bitrock::eval::Backend;
use bitrock::run;
use bitrock::run::evidence::{
    self, Boxes, DEFAULT_PRIOR_SCALE, EvidenceAnalysis, EvidenceCheck, EvidenceWarning, Noise,
};
use clap::Args;
use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Debug, Args)]
pub struct EvidenceCmd {
    #[command(flatten)]
    pub input: InferenceArgs,
    /// The prior boxes integrated over.
    #[arg(long, value_enum, default_value_t = Boxes::Physical)]
    pub boxes: Boxes,
    /// Width of the physical boxes, in record scales.
    #[arg(long, value_parser = finite_number, default_value_t = DEFAULT_PRIOR_SCALE, value_name = "K", allow_hyphen_values = true)]
    pub prior_scale: f64,
    /// Half-width of the paper's boxes with --boxes delta.
    #[arg(long, value_parser = finite_number, default_value_t = bitrock::run::abc::Config::default().delta, value_name = "DELTA", allow_hyphen_values = true)]
    pub delta: f64,
    /// Prior file (TOML) with explicit bounds or law weights; overrides the boxes where it
    /// speaks (format in docs/commands.md).
    #[arg(long, value_name = "FILE")]
    pub prior: Option<PathBuf>,
    /// The residuals' noise model: auto computes the evidence under each and reports the one
    /// the data favour (twice the work, and more for ar1's lag pass).
    #[arg(long, value_enum, default_value_t = Noise::Auto)]
    pub noise: Noise,
    /// Where each law's samplers start their tempered path (the evidence is of the boxes
    /// either way).
    #[arg(long, value_enum, default_value_t = EvidenceConfig::default().start, value_name = "START")]
    pub start_from: Start,
    /// Particles of each independent sampler (island).
    #[arg(long, default_value_t = EvidenceConfig::default().particles, value_name = "N")]
    pub particles: usize,
    /// Independent samplers per law and start; their spread gives ln Z's Monte-Carlo error.
    #[arg(long, default_value_t = EvidenceConfig::default().islands, value_name = "K")]
    pub islands: usize,
    /// Most tempering steps of one island: a likelihood much narrower than its prior box
    /// needs many (about one per nat of information the record holds about the law).
    #[arg(long, default_value_t = EvidenceConfig::default().max_stages, value_name = "COUNT")]
    pub max_stages: usize,
    /// Share of the particles' effective sample size each tempering step keeps, in (0, 1):
    /// higher is more, gentler steps.
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, default_value_t = EvidenceConfig::default().ess_share, value_name = "SHARE")]
    pub ess_share: f64,
    /// Most Metropolis sweeps after each tempering step.
    #[arg(long, default_value_t = EvidenceConfig::default().max_sweeps, value_name = "COUNT")]
    pub max_sweeps: usize,
    /// Most times a law's islands of one start are run again, each time with twice the
    /// particles, while their ln Z spread by more than a nat and the law's ln Z is uncertain
    /// by more than half a nat (0: never). What is still apart after them is ln Z's error.
    #[arg(long, default_value_t = EvidenceConfig::default().refine_rounds, value_name = "COUNT")]
    pub refine_rounds: usize,
    /// Seed of the samplers' streams: the same seed gives the same result.
    #[arg(long, default_value_t = EvidenceConfig::default().seed)]
    pub seed: u64,
    /// Where ρ is computed: auto = the GPU when an adapter exists (else the CPU, saying so),
    /// gpu = the GPU or an error, cpu = the f64 reference [default: auto; with --resume: the
    /// evidence's].
    #[arg(long, value_enum)]
    pub backend: Option<Backend>,
    /// Worker threads [default: all cores].
    #[arg(long, value_name = "N")]
    pub threads: Option<usize>,
    /// Then check the answer by re-simulation: K synthetic records per law, each made from
    /// the law's evidence posterior and the record's own residuals, each through a lighter
    /// evidence over the same boxes (at most 200 particles in 2 islands per law, from the
    /// replicate's fit where the evidence starts from fits); a confusion matrix with the share
    /// decided, undecided and decided wrongly, and the answer undecided where the check decides
    /// fewer than half the records made by its law for it (against every other law), or half
    /// or more of the runner-up's for it too [default: 4 where two laws or more are compared;
    /// 0: no check; with --resume, the resuming command's].
    #[arg(long, value_name = "K")]
    pub check: Option<usize>,
    /// Write the posterior (every law's sets, weighed by its P(m | y)) as particle CSV to FILE,
    /// parameters in the record's torque unit, for `bitrock stability --posterior FILE`.
    #[arg(long, value_name = "FILE")]
    pub posterior_out: Option<PathBuf>,
    /// Evidence directory: evidence.json (this document with each law's posterior sets, what
    /// `bitrock.read_evidence` reads) and posterior.csv (what `bitrock stability --run DIR`
    /// maps), written together once the evidence (and its check) is done; meanwhile DIR
    /// keeps the evidence under way (unfinished/), which --resume continues.
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Replace the evidence --out holds (finished or under way).
    #[arg(long, requires = "out")]
    pub force: bool,
    /// Continue the evidence under way in DIR (killed or stopped part-way) from its last saved
    /// state, with its record and settings: the evidence the uninterrupted command gives, bit
    /// for bit on the same backend. Then written to DIR as --out writes it.
    #[arg(long, value_name = "DIR", conflicts_with_all = super::args::resume_conflicts!(
        "boxes", "prior_scale", "delta", "prior", "noise", "start_from", "particles", "islands", "max_stages",
        "ess_share", "max_sweeps", "refine_rounds", "seed",
    ))]
    pub resume: Option<PathBuf>,
    /// No progress lines on stderr.
    #[arg(long, short)]
    pub quiet: bool,
    /// Print JSON instead of tables.
    #[arg(long)]
    pub json: bool,
}

/// Says the user's notes (a fallback to the CPU) on standard error.
pub(super) struct Notes;

impl bitrock::abc::Observer for Notes {
    fn note(&mut self, line: String) {
        print::note(format_args!("note: {line}"));
    }
}

pub fn run(cmd: &EvidenceCmd) -> anyhow::Result<ExitCode> {
    set_threads(cmd.threads)?;
    if let Some(path) = &cmd.posterior_out {
        bitrock::run::dir::check_output_file(path, "posterior_out", false)?;
    }
    let (job, data, analysis, unfinished) = start_or_resume(cmd)?;
    let dir = cmd.resume.as_ref().or(cmd.out.as_ref());
    finish(cmd, &job, &data, &analysis, unfinished).inspect_err(|e| {
        if let Some(dir) = dir {
            still_under_way(dir, e.downcast_ref());
        }
    })
}

/// Says where the evidence under way is kept after a failure that continuing it can mend (a
/// machine's or a device's, not the user's input, which would fail again), and how.
fn still_under_way(dir: &std::path::Path, error: Option<&bitrock::Error>) {
    if error.is_none_or(|e| !e.is_bad_input()) && bitrock::run::dir::is_unfinished_evidence_dir(dir) {
        print::note(format_args!(
            "note: the evidence so far is kept in {0}; continue it with `bitrock evidence --resume {0}`",
            dir.display()
        ));
    }
}

/// The evidence of a new job (kept under way in --out, when given, as it goes) or of the one
/// --resume continues: its job, record and analysis, and its directory under way.
fn start_or_resume(
    cmd: &EvidenceCmd,
) -> anyhow::Result<(
    run::evidence::Job,
    FieldData,
    EvidenceAnalysis,
    Option<evidence::dir::Unfinished>,
)> {
    if let Some(dir) = &cmd.resume {
        let (unfinished, mut job, data, progress) = evidence::dir::Unfinished::open(dir)?;
        if let Some(backend) = cmd.backend {
            job.backend = backend;
        }
        evidence::replicates_asked(cmd.check, job.laws.len())
            .map(|k| evidence::check_size(k, "check", &job, &data))
            .transpose()?;
        let analysis = unfinished
            .run(&job, &data, progress, Default::default(), &mut Notes)
            .inspect_err(|e| still_under_way(dir, Some(e)))?;
        return Ok((job, data, analysis, Some(unfinished)));
    }
    let job = new_job(cmd)?;
    if let Some(dir) = &cmd.out {
        evidence::dir::check_out(dir, cmd.force)?;
    }
    let data = load_data(&cmd.input.record)?;
    evidence::replicates_asked(cmd.check, job.laws.len())
        .map(|k| evidence::check_size(k, "check", &job, &data))
        .transpose()?;
    match &cmd.out {
        None => {
            let analysis = job.run(&data, Default::default(), &mut Notes)?;
            Ok((job, data, analysis, None))
        }
        Some(dir) => {
            let unfinished = evidence::dir::Unfinished::start(dir, cmd.force, &job, &data)?;
            let analysis = unfinished
                .run(&job, &data, Default::default(), Default::default(), &mut Notes)
                .inspect_err(|e| still_under_way(dir, Some(e)))?;
            Ok((job, data, analysis, Some(unfinished)))
        }
    }
}

/// The job the flags describe.
fn new_job(cmd: &EvidenceCmd) -> anyhow::Result<run::evidence::Job> {
    let settings = evidence::Settings {
        boxes: cmd.boxes,
        prior_scale: cmd.prior_scale,
        delta: cmd.delta,
        prior: cmd.prior.clone(),
        noise: cmd.noise,
        start_from: cmd.start_from,
        particles: cmd.particles,
        islands: cmd.islands,
        max_stages: cmd.max_stages,
        ess_share: cmd.ess_share,
        max_sweeps: cmd.max_sweeps,
        refine_rounds: cmd.refine_rounds,
        seed: cmd.seed,
        backend: cmd.backend.unwrap_or_default(),
    };
    let mut job = settings.job(cmd.input.fit.laws()?, cmd.input.fit.options()?)?;
    job.string = cmd.input.string.given().spec()?;
    Ok(job)
}

/// The evidence's check, its directory and posterior written, its tables or JSON printed.
fn finish(
    cmd: &EvidenceCmd,
    job: &run::evidence::Job,
    data: &FieldData,
    analysis: &EvidenceAnalysis,
    unfinished: Option<evidence::dir::Unfinished>,
) -> anyhow::Result<ExitCode> {
    if let Some(path) = &cmd.posterior_out {
        let csv = analysis.posterior_csv(&job.laws, data);
        bitrock::run::dir::write_whole(path, "posterior_out", false, |file| file.write_all(&csv))?;
        if let Some(w_ref_n) = analysis.fit.w_ref_n {
            print::note(format_args!(
                "note: the posterior's torque parameters are for W = W_ref = {:.3} kN (each predicted torque scaled by WOB / W_ref): map it with `bitrock stability --posterior {} --w-ref-kn {:.3}`",
                w_ref_n / 1000.0,
                path.display(),
                w_ref_n / 1000.0
            ));
        }
    }
    let quiet = cmd.quiet;
    let check = evidence::replicates_asked(cmd.check, job.laws.len())
        .map(|k| {
            let mut progress = |done: usize, total: usize| {
                if !quiet {
                    print::note(format_args!("evidence check: replicate {done}/{total}"));
                }
            };
            evidence::check(
                job,
                data,
                analysis,
                k,
                &mut Default::default(),
                &mut progress,
                &mut Notes,
            )
        })
        .transpose()?;
    let advice = analysis.record_advice(data, job, &mut |line| print::note(line))?;
    let document = |sets: bool| {
        EvidenceAnalysis::with_advice(
            analysis.document(data, &job.prior.describe(), sets),
            data,
            advice.as_ref(),
        )
    };
    if let Some(unfinished) = unfinished {
        let dir = cmd.resume.as_ref().or(cmd.out.as_ref()).expect("a directory under way");
        let mut document = document(true);
        if let Some(check) = &check {
            analysis.with_check(&mut document, check);
        }
        unfinished.finish(&document, analysis, job, data)?;
        print::note(format_args!(
            "note: evidence written to {} (`bitrock stability --run {}` maps its posterior, `bitrock report {}` draws it)",
            dir.display(),
            dir.display(),
            dir.display()
        ));
    }
    let mut out = print::stdout();
    if cmd.json {
        let mut document = document(false);
        if let Some(check) = &check {
            analysis.with_check(&mut document, check);
        }
        print::json(&mut out, document)?;
    } else {
        tables(&mut out, data, job, analysis)?;
        if let Some(check) = &check {
            check_table(&mut out, check)?;
        }
        if let Some(advice) = &advice {
            let string = job
                .string
                .as_ref()
                .map_or_else(|| "the paper's 1-DOF string".to_string(), |s| s.describe());
            writeln!(
                out,
                "\nadvice at the record's operating point ({string}): {}",
                advice.words
            )?;
        }
        print::answer(&mut out, analysis.answer(check.as_ref()).as_ref())?;
    }
    Ok(ExitCode::SUCCESS)
}

/// Each law's estimate from each start, where its samplers started from both.
fn starts_table(out: &mut impl Write, evidence: &Evidence) -> std::io::Result<()> {
    if evidence.laws.iter().all(|l| l.starts.is_empty()) {
        return Ok(());
    }
    writeln!(
        out,
        "\neach start's ln Z (N·m; a start errs low where it misses part of the posterior):"
    )?;
    for law in &evidence.laws {
        if let Some(line) = describe_starts(&law.starts) {
            writeln!(out, "  {:<6} {line}", law.law.name())?;
        }
    }
    Ok(())
}

/// The evidence table, the Bayes factors against the most probable law, and the boxes.
fn tables(
    out: &mut impl Write,
    data: &FieldData,
    job: &run::evidence::Job,
    analysis: &EvidenceAnalysis,
) -> std::io::Result<()> {
    let evidence = &analysis.evidence;
    let config = &evidence.config;
    writeln!(
        out,
        "data: {}  ({} calibration samples; torque in {})",
        data.source.display(),
        evidence.data_points,
        data.torque_unit.label()
    )?;
    if let Some(note) = data.clock_note() {
        writeln!(out, "{note}")?;
    }
    writeln!(
        out,
        "model evidence: tempered SMC per law, {} islands × {} particles {}; noise model: {}{}",
        config.islands,
        config.particles,
        config.start.describe(),
        config.noise.describe(),
        scaling(analysis.fit.w_ref_n.map(|w| w / 1000.0))
    )?;
    writeln!(out, "prior: {}\n", job.prior.describe())?;
    print::separation_tables(out, &analysis.separations, &job.laws)?;
    law_table(out, evidence)?;
    starts_table(out, evidence)?;
    bayes_factor_table(out, analysis)?;
    let lag1: Vec<String> = analysis
        .fits
        .iter()
        .zip(&analysis.residual_lag1)
        .zip(&analysis.ar1_preference_nats)
        .map(|((fit, phi), nats)| format!("{} {phi:.2} ({nats:+.1})", fit.law))
        .collect();
    writeln!(
        out,
        "\nresidual lag-1 autocorrelation of the fits (time order), and in brackets the nats by which the data prefer \
         AR(1) residuals to i.i.d. ones there: {}",
        lag1.join(", ")
    )?;
    noise_model_table(out, analysis)?;
    for warning in analysis.warnings() {
        // Where a flag of this command changes what the warning is about.
        let hint = match warning {
            EvidenceWarning::Autocorrelated { .. } => " (--noise ar1)",
            EvidenceWarning::IslandsDisagree { .. } => "; more --particles or --max-sweeps narrow it",
            EvidenceWarning::CutByBox { .. } => "; widen it (--prior-scale, or a --prior file)",
            EvidenceWarning::DecidedByTheBoxes { .. } => " (--prior-scale, or a --prior file)",
        };
        writeln!(out, "warning: {warning}{hint}")?;
    }
    boxes_table(out, data, analysis)?;
    writeln!(
        out,
        "\n{} candidates scored ({:.3e} candidate × data-point evaluations) on {} in {:.2} s",
        evidence.candidates_scored, evidence.evaluations as f64, evidence.backend, evidence.seconds
    )?;
    if analysis.noise_models.len() > 1 {
        let models = &analysis.noise_models;
        writeln!(
            out,
            "all {} models of the residuals: {} candidates in {:.2} s",
            models.len(),
            models.iter().map(|m| m.candidates_scored).sum::<u64>(),
            models.iter().map(|m| m.seconds).sum::<f64>()
        )?;
    }
    Ok(())
}

/// Each law's evidence, probability and cost, and what its refinement rounds did.
fn law_table(out: &mut impl Write, evidence: &bitrock::abc::evidence::Evidence) -> std::io::Result<()> {
    let config = &evidence.config;
    writeln!(
        out,
        "law       ln Z (N·m)   ± MC error   P(m | y)        ±     best ρ   stages   candidates"
    )?;
    for law in &evidence.laws {
        let stages = law.stages.iter().sum::<usize>() as f64 / law.stages.len() as f64;
        writeln!(
            out,
            "{:<6} {:>14.3} {:>12.3} {:>10.4} {:>8.4} {:>10.5} {:>8.1} {:>12}",
            law.law.name(),
            law.ln_z,
            law.ln_z_error,
            law.probability,
            law.probability_error,
            law.best_rho,
            stages,
            law.candidates_scored
        )?;
    }
    for law in evidence.laws.iter().filter(|l| l.refinements > 0) {
        let particles = config.particles_of(law.law) << law.refinements;
        writeln!(
            out,
            "{}: islands that ended more than a nat apart were run again {} time(s), the last with {particles} \
             particles each; its islands now span {:.2} nats{}",
            law.law,
            law.refinements,
            law.island_spread,
            if law.island_spread > REFINE_ABOVE_NATS {
                ", which its error carries"
            } else {
                ""
            }
        )?;
    }
    Ok(())
}

/// The Bayes factors of the law of the largest evidence against each other law: the data's
/// part and the boxes', the word the data's, and how the boxes change them.
fn bayes_factor_table(out: &mut impl Write, analysis: &EvidenceAnalysis) -> std::io::Result<()> {
    let evidence = &analysis.evidence;
    let factors = evidence.bayes_factors(&analysis.separations);
    if let [first, ..] = &factors[..] {
        writeln!(
            out,
            "\nBayes factors of {}, the law of the largest evidence, against each other law: the data's part \
             (⟨ln L⟩ over the posteriors) and the boxes' (Occam factors); the word is the data's:",
            first.favoured
        )?;
        // Every box twice as wide: each parameter costs ln 2 more where the posterior lies
        // inside its box (a prior cut to the record's torques gets most of it back; where the
        // wider boxes keep too little of its cut to estimate, no number is given).
        let widened: Vec<(bitrock::laws::Law, Option<f64>)> = analysis
            .prior
            .boxes
            .iter()
            .map(|b| {
                let shift = match b.curve {
                    None => Some(LN_Z_PER_DOUBLING * b.law.n_params() as f64),
                    Some(_) => every_box_widened(b),
                };
                (b.law, shift)
            })
            .collect();
        let shift = |law| widened.iter().find(|(l, _)| *l == law).and_then(|(_, s)| *s);
        for factor in &factors {
            let doubled = match (shift(factor.favoured), shift(factor.against)) {
                (Some(a), Some(b)) => format!("{:.2}", factor.ln_b + a - b),
                _ => "n/a (a cut prior's wider boxes keep too little of it)".to_string(),
            };
            writeln!(
                out,
                "  {} vs {:<6} ln B = {:>10.2} ± {:.2}  {:<20} ({}; boxes twice as wide: ln B {doubled})",
                factor.favoured,
                factor.against.name(),
                factor.ln_b,
                factor.error,
                factor.strength.words(),
                factor.parts(),
            )?;
            if let Some(range) = &factor.sensitivity {
                writeln!(out, "                   {}", range.describe())?;
            }
        }
    }
    Ok(())
}

/// The models of the residuals, where more than one was computed: each one's evidence, and
/// the one reported.
fn noise_model_table(out: &mut impl Write, analysis: &EvidenceAnalysis) -> std::io::Result<()> {
    if analysis.noise_models.len() > 1 {
        writeln!(
            out,
            "\nmodels of the residuals (equal prior odds):\n  noise  torque            ln p(y | model)   ± MC error   P(model | y)   first law"
        )?;
        let reported = analysis
            .noise_models
            .iter()
            .map(|row| row.probability)
            .fold(f64::NEG_INFINITY, f64::max);
        for row in &analysis.noise_models {
            let torque = match row.w_ref_kn {
                Some(w) => format!("× WOB/{w:.1} kN"),
                None => "as the law".to_string(),
            };
            let mark = if row.probability == reported {
                "  ← reported"
            } else {
                ""
            };
            writeln!(
                out,
                "  {:<6} {:<16} {:>16.2} {:>12.2} {:>14.4}   {} ({:.3}){mark}",
                row.model.name(),
                torque,
                row.ln_evidence,
                row.ln_evidence_error,
                row.probability,
                row.first_law,
                row.first_probability,
            )?;
        }
    }
    Ok(())
}

/// The prior boxes in the record's units.
fn boxes_table(out: &mut impl Write, data: &FieldData, analysis: &EvidenceAnalysis) -> std::io::Result<()> {
    writeln!(
        out,
        "\nprior boxes ({} for torques, rad/s for speeds):",
        data.torque_unit.label()
    )?;
    for bx in &analysis.prior.boxes {
        let lower: Vec<f64> = bx.lower.iter().map(|&v| f64::from(v)).collect();
        let upper: Vec<f64> = bx.upper.iter().map(|&v| f64::from(v)).collect();
        let lower = to_record_units(bx.law, &lower, data.torque_unit);
        let upper = to_record_units(bx.law, &upper, data.torque_unit);
        let ranges: Vec<String> = bx
            .law
            .param_names()
            .iter()
            .zip(lower.iter().zip(&upper))
            .map(|(name, (a, b))| format!("{name} [{a:.4e}, {b:.4e}]"))
            .collect();
        writeln!(out, "  {:<6} {}", bx.law.name(), ranges.join("  "))?;
        if let Some(curve) = &bx.curve {
            writeln!(
                out,
                "         cut to the curves within ±{:.4e} {} ({} times the largest torque) from rest to {:.3} rad/s: {:.3} of the box (ln {:.3} ± {:.3})",
                curve.limit_nm / data.torque_unit.newton_metres(),
                data.torque_unit.label(),
                curve.within,
                curve.speeds_rad_s.last().copied().unwrap_or(0.0),
                curve.ln_share.exp(),
                curve.ln_share,
                curve.ln_share_error
            )?;
        }
    }
    Ok(())
}

/// "; each predicted torque scaled by WOB / W_ref" where the evidence scaled it, W_ref in kN.
fn scaling(w_ref_kn: Option<f64>) -> String {
    w_ref_kn.map_or(String::new(), |w| {
        format!("; each predicted torque scaled by WOB / W_ref, W_ref = {w:.1} kN")
    })
}

/// The check's confusion matrix and verdicts.
pub(super) fn check_table(out: &mut impl Write, check: &EvidenceCheck) -> std::io::Result<()> {
    let sampled = check.sampler.as_ref().map_or(String::new(), |s| {
        format!(
            ", each evidence {} islands × {} particles {}",
            s.islands,
            s.particles,
            s.start.describe()
        )
    });
    writeln!(
        out,
        "\nEvidence check: {} synthetic records per law (parameters from its evidence posterior, noise resampled from its fit's residuals), the same boxes{sampled}; {} candidates scored in {:.1} s",
        check.replicates, check.candidates_scored, check.seconds
    )?;
    writeln!(
        out,
        "rows: law that made the data; columns: mean P(m | y) (share ranked first); decided: odds at least positive beyond their error and a fit at least 5 nats better, against every other law"
    )?;
    let rows = check.rows.iter().map(|row| print::ConfusionRow {
        law: row.law,
        mean_probability: &row.mean_probability,
        first_share: &row.first_share,
        tail: format!(
            "{:.2} / {:.2} / {:.2}",
            row.decided_right, row.undecided, row.decided_wrong
        ),
    });
    print::confusion_matrix(out, &check.laws, "decided right / undecided / decided wrong", rows)?;
    writeln!(out)?;
    for row in &check.rows {
        writeln!(out, "{}", row.verdict)?;
    }
    Ok(())
}
