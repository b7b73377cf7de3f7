//! What the binary prints for people: aligned tables with units (the JSON and CSV documents
//! for programs are the library's, `bitrock::documents`). Parameters leave the library in SI
//! and are shown in the record's torque unit.

use bitrock::Law;
use bitrock::abc::Run;
use bitrock::abc::posterior::PosteriorSummary;
use bitrock::data::FieldData;
use bitrock::documents::{fit_in_record_units, to_record_units};
use bitrock::fit::LawFit;
use bitrock::run::answer::{Answer, Method};
use bitrock::separation::Separation;
use bitrock::units::TorqueUnit;
use std::io::{self, Write};

/// Standard output for a command's results. A failed write names it (`standard output:
/// cannot write: No space left on device`) and keeps its kind, so that a closed pipe still ends
/// quietly. (Standard output is line-buffered: results end with a newline, so nothing is left
/// for the flush at exit, whose error would be lost.)
pub fn stdout() -> Stdout {
    Stdout(io::stdout().lock())
}

/// See [`stdout`].
pub struct Stdout(io::StdoutLock<'static>);

impl Write for Stdout {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        self.0.write(buf).map_err(named_stdout)
    }
    fn flush(&mut self) -> io::Result<()> {
        self.0.flush().map_err(named_stdout)
    }
}

fn named_stdout(e: io::Error) -> io::Error {
    io::Error::new(e.kind(), format!("standard output: cannot write: {e}"))
}

/// Prints a JSON document, its messages said with flags ([`super::fields::json_as_flags`]).
pub fn json(out: &mut impl Write, mut document: serde_json::Value) -> io::Result<()> {
    super::fields::json_as_flags(&mut document);
    serde_json::to_writer_pretty(&mut *out, &document)?;
    writeln!(out)
}

/// Writes one line for people to standard error: notes, progress and the final error. A
/// standard error that cannot be written (full, closed) loses the line and nothing else: the
/// work goes on and ends with its own exit status, never a panic (`eprintln!` panics).
/// Settings the library names are said as their flags ([`super::fields`]).
pub fn note(line: impl std::fmt::Display) {
    let _ = writeln!(io::stderr().lock(), "{}", super::fields::as_flags(&line.to_string()));
}

/// [`note`] as written, its backticked names kept as they are (a file's keys).
pub fn note_verbatim(line: impl std::fmt::Display) {
    let _ = writeln!(io::stderr().lock(), "{line}");
}

/// Numbers in a table: fixed notation where it reads well, scientific otherwise.
fn number(v: f64) -> String {
    let a = v.abs();
    if a != 0.0 && !(1e-3..1e5).contains(&a) {
        format!("{v:.4e}")
    } else {
        format!("{v:.5}")
    }
}

/// The human form of `fit`: one block per law.
pub fn fit_tables(out: &mut impl Write, data: &FieldData, fits: &[LawFit]) -> io::Result<()> {
    let torque = data.torque_unit.label();
    writeln!(
        out,
        "data: {}  (speed '{}' in {}, torque '{}' in {})",
        data.source.display(),
        data.columns.speed,
        data.speed_unit.label(),
        data.columns.torque,
        torque
    )?;
    if let Some(note) = data.clock_note() {
        writeln!(out, "{note}")?;
    }
    writeln!(
        out,
        "rows: {} read, {} used ({} calibration, {} validation)",
        data.rows_read,
        data.rows_used,
        data.calibration.len(),
        data.validation.len()
    )?;
    writeln!(
        out,
        "least squares on the calibration rows; ρ = ‖y − T(w)‖² / ‖y‖², w in rad/s\n"
    )?;
    for fit in fits {
        let (params, std_errors) = fit_in_record_units(data, fit);
        let validation = fit
            .validation_rho
            .map(|v| format!("   ρ(validation) = {v:.5}"))
            .unwrap_or_default();
        writeln!(out, "{}  T = {}", fit.law, fit.law.formula())?;
        writeln!(out, "    ρ = {:.5}{validation}", fit.rho)?;
        let rows: Vec<[String; 4]> = fit
            .law
            .params()
            .iter()
            .zip(&params)
            .zip(&std_errors)
            .map(|((spec, &p), se)| {
                [
                    spec.name.to_string(),
                    number(p),
                    se.map(number).unwrap_or_else(|| "—".into()),
                    spec.unit(torque),
                ]
            })
            .collect();
        let header = ["param", "estimate", "std.error", "unit"].map(String::from);
        let width: Vec<usize> = (0..4)
            .map(|c| {
                rows.iter()
                    .chain([&header])
                    .map(|r| r[c].chars().count())
                    .max()
                    .unwrap_or(0)
            })
            .collect();
        for r in std::iter::once(&header).chain(&rows) {
            writeln!(
                out,
                "    {:<w0$}  {:>w1$}  {:>w2$}  {}",
                r[0],
                r[1],
                r[2],
                r[3],
                w0 = width[0],
                w1 = width[1],
                w2 = width[2]
            )?;
        }
        for w in &fit.warnings {
            writeln!(out, "    warning: {}", super::fields::as_flags(&w.to_string()))?;
        }
        writeln!(out)?;
    }
    Ok(())
}

/// Can this record tell the laws apart: the matrix of expected log-likelihood gaps, the pairs
/// it leaves to the priors (with where a record would have to reach), and where the others'
/// information lies.
pub fn separation_tables(out: &mut impl Write, separations: &[Separation], laws: &[Law]) -> io::Result<()> {
    use bitrock::units::RAD_S_PER_RPM;
    if laws.len() < 2 {
        return Ok(());
    }
    writeln!(
        out,
        "can this record tell the laws apart? expected log-likelihood gap D (nats) if the row's law, as fitted, made it:"
    )?;
    write!(out, "    truth \\ rival")?;
    for law in laws {
        write!(out, " {:>9}", law.name())?;
    }
    writeln!(out)?;
    let find = |a: Law, b: Law| separations.iter().find(|s| s.truth == a && s.rival == b);
    for &truth in laws {
        write!(out, "    {:<13}", truth.name())?;
        for &rival in laws {
            match find(truth, rival) {
                Some(s) => write!(out, " {:>9.1}", s.gap_nats)?,
                None => write!(out, " {:>9}", "—")?,
            }
        }
        writeln!(out)?;
    }
    let rpm = |w: f64| w / RAD_S_PER_RPM;
    let undecided: Vec<&Separation> = separations.iter().filter(|s| s.undecided()).collect();
    if !undecided.is_empty() {
        writeln!(
            out,
            "    not separated (D < {} nats: the priors, not the data, decide):",
            bitrock::separation::UNDECIDED_NATS
        )?;
        for s in undecided {
            let mut reach = Vec::new();
            if let Some(w) = s.parts_below_rad_s {
                reach.push(format!("below {:.1} rpm", rpm(w)));
            }
            if let Some(w) = s.parts_above_rad_s {
                reach.push(format!("above {:.0} rpm", rpm(w)));
            }
            let reach = if reach.is_empty() {
                "the fitted curves stay within the noise from 0 to 4 times the fastest recorded speed".to_string()
            } else {
                format!("the fitted curves part by more than the noise {}", reach.join(" and "))
            };
            writeln!(
                out,
                "      {} made it, {} fits as well: D = {:.1}, P(misranked) = {:.2}; {reach}",
                s.truth, s.rival, s.gap_nats, s.misranking
            )?;
        }
    }
    let mut lines = Vec::new();
    for s in separations.iter().filter(|s| !s.undecided()) {
        if let Some(band) = s.bands.iter().max_by(|a, b| a.share.total_cmp(&b.share)) {
            lines.push(format!(
                "      {} against {}: {:.0} % of D at {:.1}–{:.1} rpm",
                s.truth,
                s.rival,
                100.0 * band.share,
                rpm(band.speed_rad_s.0),
                rpm(band.speed_rad_s.1)
            ));
        }
    }
    if !lines.is_empty() {
        writeln!(
            out,
            "    where the separated pairs' information lies (the richest fifth of the speeds):"
        )?;
        for line in lines {
            writeln!(out, "{line}")?;
        }
    }
    writeln!(out)
}

/// The per-population table of an ABC run.
pub fn population_table(out: &mut impl Write, run: &Run) -> io::Result<()> {
    let Some(first) = run.populations.first() else {
        return writeln!(
            out,
            "stopped before any population completed: {}",
            super::fields::as_flags(run.stop.describe())
        );
    };
    let laws: Vec<Law> = first.record.per_law.iter().map(|l| l.law).collect();
    writeln!(
        out,
        "model probabilities by {}: the share of each law's prior box below ε",
        Method::PaperAbc.label()
    )?;
    write!(
        out,
        "{:>4}  {:>10}  {:>12}  {:>8}  {:>9}",
        "pop", "epsilon", "draws", "accepted", "acc.rate"
    )?;
    for law in &laws {
        write!(out, "  {:>7}", format!("P({law})"))?;
    }
    writeln!(out, "  {:>8}  {:>8}", "ESS", "time_s")?;
    for p in &run.populations {
        let r = &p.record;
        let eps = r.epsilon.map(|e| format!("{e:.5}")).unwrap_or_else(|| "∞".into());
        write!(
            out,
            "{:>4}  {:>10}  {:>12}  {:>8}  {:>9.5}",
            r.index, eps, r.draws, r.accepted, r.acceptance_rate
        )?;
        for l in &r.per_law {
            if l.zero_by_construction() {
                write!(out, "  {:>7}", "0*")?;
            } else {
                write!(out, "  {:>7.4}", l.probability)?;
            }
        }
        let ess = format!("{:.0}{}", r.ess, if r.thin() { "!" } else { "" });
        writeln!(out, "  {ess:>8}  {:>8.3}", r.seconds)?;
    }
    if run.populations.iter().any(|p| p.record.thin()) {
        writeln!(
            out,
            "! effective sample size below {:.0} % of the particles: that population rests on a few heavily weighted particles",
            bitrock::abc::MIN_ESS_SHARE * 100.0
        )?;
    }
    // Probabilities that are 0 because ε is below a law's best fit, not because of evidence.
    for law in &laws {
        let from = run.populations.iter().find(|p| {
            p.record
                .per_law
                .iter()
                .any(|l| l.law == *law && l.zero_by_construction())
        });
        if let Some(p) = from {
            writeln!(
                out,
                "* {law}: 0 by construction from population {} on (ε at or below its best least-squares ρ: none of its candidates can be accepted; not evidence against it)",
                p.record.index
            )?;
        }
    }
    if let Some(last) = run.populations.last() {
        for caveat in last.record.probability_caveats().iter().skip(1) {
            writeln!(out, "{caveat}")?;
        }
    }
    // SMC stops proposing a law with no particle left; say when each died.
    for law in &laws {
        let died = run
            .populations
            .iter()
            .find(|p| p.record.per_law.iter().any(|l| l.law == *law && !l.alive));
        if let Some(p) = died {
            writeln!(
                out,
                "{law} died out in population {}: no particle left, no proposals after it",
                p.record.index
            )?;
        }
    }
    let near: u64 = run.populations.iter().map(|p| p.record.near_threshold).sum();
    writeln!(
        out,
        "stopped: {}; {:.3e} candidate × data-point evaluations in {:.2} s; {near} candidates within the CPU/GPU parity tolerance of ε",
        super::fields::as_flags(run.stop.describe()),
        run.evaluations as f64,
        run.seconds
    )
}

/// Per-law posterior tables in the record's units.
pub fn posterior(out: &mut impl Write, posterior: &PosteriorSummary, unit: TorqueUnit) -> io::Result<()> {
    for s in &posterior.laws {
        writeln!(
            out,
            "\n{}  P(m | ρ < ε) = {:.4}  ({} particles; best ρ = {:.5})",
            s.law, s.probability, s.count, s.best.rho
        )?;
        let conv = |v: &[f64]| to_record_units(s.law, v, unit);
        let cols = [
            conv(&s.mean),
            conv(&s.std_dev),
            conv(&s.q01),
            conv(&s.q50),
            conv(&s.q99),
            conv(&s.map),
        ];
        writeln!(
            out,
            "    {:<6} {:>12} {:>12} {:>12} {:>12} {:>12} {:>12}  unit",
            "param", "mean", "std.dev", "q01", "q50", "q99", "MAP"
        )?;
        for (j, spec) in s.law.params().iter().enumerate() {
            write!(out, "    {:<6}", spec.name)?;
            for c in &cols {
                write!(out, " {:>12}", number(c[j]))?;
            }
            writeln!(
                out,
                "  {}{}",
                spec.unit(unit.label()),
                if s.identified[j] {
                    ""
                } else {
                    "  (not identified: its 98 % interval spans most of its prior box)"
                }
            )?;
        }
    }
    Ok(())
}

/// The headline: one answer to "which law, how sure", with its strength.
pub fn answer(out: &mut impl Write, answer: Option<&Answer>) -> io::Result<()> {
    match answer {
        Some(answer) => writeln!(out, "\nanswer: {}", super::fields::as_flags(&answer.sentence())),
        None => writeln!(out, "\nanswer: no law holds a particle: nothing was selected"),
    }
}

/// One row of a confusion matrix: the law that made the data, the mean probability and the
/// share ranked first of every column law, and the row's own summary after them.
pub struct ConfusionRow<'a> {
    pub law: Law,
    pub mean_probability: &'a [f64],
    pub first_share: &'a [f64],
    pub tail: String,
}

/// A confusion matrix by re-simulation (`check-selection`, `evidence --check`): a header of
/// the column `laws` then `tail_header`, and one line per row.
pub fn confusion_matrix<'a>(
    out: &mut impl Write,
    laws: &[Law],
    tail_header: &str,
    rows: impl IntoIterator<Item = ConfusionRow<'a>>,
) -> io::Result<()> {
    write!(out, "{:<10}", "data from")?;
    for law in laws {
        write!(out, " {:>15}", law.to_string())?;
    }
    writeln!(out, "   {tail_header}")?;
    for row in rows {
        write!(out, "{:<10}", row.law.to_string())?;
        for (p, f) in row.mean_probability.iter().zip(row.first_share) {
            write!(out, " {:>15}", format!("{p:.3} ({f:.2})"))?;
        }
        writeln!(out, "   {}", row.tail)?;
    }
    Ok(())
}
