//! What the binary prints: aligned tables with units for people, JSON for programs.
//! Parameters leave the library in SI and are shown in the record's torque unit.

use bitrock::Law;
use bitrock::abc::posterior::{Envelope, PosteriorSummary};
use bitrock::abc::{Population, PopulationRecord, Run};
use bitrock::data::FieldData;
use bitrock::fit::LawFit;
use bitrock::prior::Prior;
use bitrock::units::TorqueUnit;
use serde_json::{Value, json};
use std::io::{self, Write};
use std::path::Path;

/// The parameter values and standard errors of `fit` in the record's torque unit.
fn in_record_units(data: &FieldData, fit: &LawFit) -> (Vec<f64>, Vec<Option<f64>>) {
    let to_unit = 1.0 / data.torque_unit.newton_metres();
    let params = fit.law.scale_torque(&fit.params_si, to_unit);
    let std_errors = fit
        .std_errors_si
        .iter()
        .zip(fit.law.params())
        .map(|(se, spec)| se.map(|v| if spec.torque_power == 1 { v * to_unit } else { v }))
        .collect();
    (params, std_errors)
}

/// `fit --json`: `{"rows_read", "rows_used", "fits": [{"law", "names", "params", "std_errors",
/// "rho", "warnings"}]}` plus context (units, split, validation misfit).
pub fn fit_json(data: &FieldData, fits: &[LawFit]) -> Value {
    let torque = data.torque_unit.label();
    let fits: Vec<Value> = fits
        .iter()
        .map(|fit| {
            let (params, std_errors) = in_record_units(data, fit);
            json!({
                "law": fit.law,
                "formula": fit.law.formula(),
                "names": fit.law.param_names(),
                "units": fit.law.params().iter().map(|s| s.unit(torque)).collect::<Vec<_>>(),
                "params": params,
                "std_errors": std_errors,
                "rho": fit.rho,
                "validation_rho": fit.validation_rho,
                "condition_number": if fit.condition_number.is_finite() { json!(fit.condition_number) } else { Value::Null },
                "correlations": fit.correlations,
                "warnings": fit.warnings,
                "starts": fit.starts,
            })
        })
        .collect();
    json!({
        "source": data.source.display().to_string(),
        "columns": data.columns,
        "torque_unit": torque,
        "speed_unit_of_params": "rad/s",
        "rows_read": data.rows_read,
        "rows_used": data.rows_used,
        "calibration_rows": data.calibration.len(),
        "validation_rows": data.validation.len(),
        "fits": fits,
    })
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
pub fn print_fit_tables(out: &mut impl Write, data: &FieldData, fits: &[LawFit]) -> io::Result<()> {
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
        let (params, std_errors) = in_record_units(data, fit);
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
        let header = ["param", "estimate", "std.error", "unit"];
        let width: Vec<usize> = (0..4)
            .map(|c| {
                rows.iter()
                    .map(|r| r[c].chars().count())
                    .chain([header[c].len()])
                    .max()
                    .unwrap_or(0)
            })
            .collect();
        writeln!(
            out,
            "    {:<w0$}  {:>w1$}  {:>w2$}  {}",
            header[0],
            header[1],
            header[2],
            header[3],
            w0 = width[0],
            w1 = width[1],
            w2 = width[2]
        )?;
        for r in &rows {
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
            writeln!(out, "    warning: {w}")?;
        }
        writeln!(out)?;
    }
    Ok(())
}

/// A torque-scaled vector (parameters, their spreads) from SI to the record's torque unit.
fn to_record_units(law: Law, values_si: &[f64], torque_unit: TorqueUnit) -> Vec<f64> {
    law.scale_torque(values_si, 1.0 / torque_unit.newton_metres())
}

/// `{"m1": p, ...}` from per-law values.
fn by_law(values: impl IntoIterator<Item = (Law, f64)>) -> Value {
    Value::Object(
        values
            .into_iter()
            .map(|(law, p)| (law.name().to_string(), json!(p)))
            .collect(),
    )
}

/// One population's record as JSON.
fn population_json(record: &PopulationRecord) -> Value {
    json!({
        "index": record.index,
        "epsilon": record.epsilon,
        "draws": record.draws,
        "accepted": record.accepted,
        "acceptance_rate": record.acceptance_rate,
        "model_probabilities": by_law(record.per_law.iter().map(|l| (l.law, l.probability))),
        "per_law": record.per_law,
        "candidates_scored": record.candidates_scored,
        "evaluations": record.evaluations,
        "near_threshold": record.near_threshold,
        "ess": record.ess,
        "seconds": record.seconds,
        "stream": record.stream,
    })
}

/// Everything an ABC run produced, as written to DIR/run.json and printed by `abc --json`.
pub struct AbcReport<'a> {
    pub data: &'a FieldData,
    pub fits: &'a [LawFit],
    pub prior: &'a Prior,
    pub run: &'a Run,
    pub posterior: &'a PosteriorSummary,
    /// Index of the summarised population.
    pub summary_population: usize,
    pub config: Value,
    pub seed: u64,
    pub backend: &'a str,
}

impl AbcReport<'_> {
    pub fn json(&self) -> Value {
        let unit = self.data.torque_unit;
        let priors = prior_json(self.prior, unit);
        let laws: Vec<Value> = self
            .posterior
            .laws
            .iter()
            .map(|s| {
                let conv = |v: &[f64]| to_record_units(s.law, v, unit);
                json!({
                    "law": s.law,
                    "names": s.names,
                    "units": s.law.params().iter().map(|p| p.unit(unit.label())).collect::<Vec<_>>(),
                    "count": s.count,
                    "probability": s.probability,
                    "mean": conv(&s.mean),
                    "std_dev": conv(&s.std_dev),
                    "q01": conv(&s.q01),
                    "q50": conv(&s.q50),
                    "q99": conv(&s.q99),
                    "correlation": s.correlation,
                    "best": {"index": s.best.index, "rho": s.best.rho, "params": conv(&s.best.params)},
                    "map": conv(&s.map),
                    "map_bandwidth": conv(&s.map_bandwidth),
                })
            })
            .collect();
        let fits = fit_json(self.data, self.fits);
        json!({
            "version": env!("CARGO_PKG_VERSION"),
            "backend": self.backend,
            "seed": self.seed,
            "config": self.config,
            "data": {
                "source": fits["source"],
                "columns": fits["columns"],
                "torque_unit": unit.label(),
                "rows_read": self.data.rows_read,
                "rows_used": self.data.rows_used,
                "calibration_rows": self.data.calibration.len(),
                "validation_rows": self.data.validation.len(),
            },
            "fits": fits["fits"],
            "priors": priors,
            "populations": self.run.populations.iter().map(|p| population_json(&p.record)).collect::<Vec<_>>(),
            "stop_reason": self.run.stop,
            "stop_description": self.run.stop.describe(),
            "posterior": {
                "population": self.summary_population,
                "total": self.posterior.total,
                "model_probabilities": by_law(self.posterior.model_probabilities.iter().copied()),
                "laws": laws,
            },
            "envelopes": {"file": "envelopes.csv", "level": ENVELOPE_LEVEL},
            "evaluations": self.run.evaluations,
            "seconds": self.run.seconds,
        })
    }
}

pub use bitrock::abc::posterior::ENVELOPE_LEVEL;

/// Header of a particle CSV: population, law, candidate, rho, weight, then every law's
/// parameters with units.
fn particle_header(laws: &[Law], unit: TorqueUnit) -> Vec<String> {
    let mut header: Vec<String> = ["population", "law", "candidate", "rho", "weight"]
        .iter()
        .map(|s| s.to_string())
        .collect();
    for law in laws {
        for spec in law.params() {
            header.push(format!("{} [{}]", spec.name, spec.unit(unit.label())));
        }
    }
    header
}

/// Writes populations' particles as CSV: one row per particle, parameters in columns in the
/// record's torque unit (empty cells for the other laws' parameters).
pub fn write_particles(
    out: impl Write,
    populations: &[&Population],
    laws: &[Law],
    unit: TorqueUnit,
) -> anyhow::Result<()> {
    let mut w = csv::Writer::from_writer(out);
    w.write_record(particle_header(laws, unit))?;
    for population in populations {
        for p in &population.particles {
            let mut row = vec![
                population.record.index.to_string(),
                p.law.name().to_string(),
                p.index.to_string(),
                format!("{:e}", p.rho),
                format!("{:e}", p.weight),
            ];
            for law in laws {
                if *law == p.law {
                    row.extend(to_record_units(p.law, &p.params, unit).iter().map(|v| format!("{v:e}")));
                } else {
                    row.extend(std::iter::repeat_n(String::new(), law.n_params()));
                }
            }
            w.write_record(&row)?;
        }
    }
    w.flush()?;
    Ok(())
}

/// A population and its particles as JSON, parameters in the record's torque unit.
pub fn population_with_particles_json(population: &Population, unit: TorqueUnit) -> Value {
    let particles: Vec<Value> = population
        .particles
        .iter()
        .map(|p| {
            json!({
                "law": p.law,
                "candidate": p.index,
                "rho": p.rho,
                "weight": p.weight,
                "params": to_record_units(p.law, &p.params, unit),
            })
        })
        .collect();
    let mut value = population_json(&population.record);
    value["particles"] = Value::Array(particles);
    value
}

/// The prior boxes in the record's units, with names, units and law weights.
pub fn prior_json(prior: &Prior, unit: TorqueUnit) -> Value {
    prior
        .boxes
        .iter()
        .zip(&prior.weights)
        .zip(&prior.rules)
        .map(|((b, w), rules)| {
            let lower: Vec<f64> = b.lower.iter().map(|&v| f64::from(v)).collect();
            let upper: Vec<f64> = b.upper.iter().map(|&v| f64::from(v)).collect();
            json!({
                "law": b.law,
                "names": b.law.param_names(),
                "units": b.law.params().iter().map(|s| s.unit(unit.label())).collect::<Vec<_>>(),
                "lower": to_record_units(b.law, &lower, unit),
                "upper": to_record_units(b.law, &upper, unit),
                "rules": rules.iter().map(|r| r.name()).collect::<Vec<_>>(),
                "weight": w,
            })
        })
        .collect()
}

/// Writes the predictive envelopes (one block of rows per law) and, beside them, the data.
pub fn write_envelopes(dir: &Path, envelopes: &[Envelope], data: &FieldData) -> anyhow::Result<()> {
    let unit = data.torque_unit;
    let suffix = match unit {
        TorqueUnit::Nm => "nm",
        TorqueUnit::KNm => "knm",
    };
    let to_unit = 1.0 / unit.newton_metres();
    let mut w = csv::Writer::from_path(dir.join("envelopes.csv"))?;
    w.write_record([
        "law".to_string(),
        "speed_rad_s".into(),
        format!("lower_{suffix}"),
        format!("median_{suffix}"),
        format!("upper_{suffix}"),
    ])?;
    for e in envelopes {
        for i in 0..e.speed_rad_s.len() {
            w.write_record([
                e.law.name().to_string(),
                format!("{:.6}", e.speed_rad_s[i]),
                format!("{:.6e}", e.lower[i] * to_unit),
                format!("{:.6e}", e.median[i] * to_unit),
                format!("{:.6e}", e.upper[i] * to_unit),
            ])?;
        }
    }
    w.flush()?;
    let mut w = csv::Writer::from_path(dir.join("data.csv"))?;
    w.write_record(["set".to_string(), "speed_rad_s".into(), format!("torque_{suffix}")])?;
    for (set, samples) in [("calibration", &data.calibration), ("validation", &data.validation)] {
        for (s, t) in samples.speed_rad_s.iter().zip(&samples.torque_nm) {
            w.write_record([set.to_string(), format!("{s:.6}"), format!("{:.6e}", t * to_unit)])?;
        }
    }
    w.flush()?;
    Ok(())
}

/// The per-population table of an ABC run.
pub fn print_population_table(out: &mut impl Write, run: &Run) -> io::Result<()> {
    let Some(first) = run.populations.first() else {
        return writeln!(out, "stopped before any population completed: {}", run.stop.describe());
    };
    let laws: Vec<Law> = first.record.per_law.iter().map(|l| l.law).collect();
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
            write!(out, "  {:>7.4}", l.probability)?;
        }
        writeln!(out, "  {:>8.0}  {:>8.3}", r.ess, r.seconds)?;
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
        run.stop.describe(),
        run.evaluations as f64,
        run.seconds
    )
}

/// Per-law posterior tables in the record's units.
pub fn print_posterior(out: &mut impl Write, posterior: &PosteriorSummary, unit: TorqueUnit) -> io::Result<()> {
    for s in &posterior.laws {
        writeln!(
            out,
            "\n{}  P = {:.4}  ({} particles; best ρ = {:.5})",
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
            writeln!(out, "  {}", spec.unit(unit.label()))?;
        }
    }
    Ok(())
}

/// Writes `path` through `write` into a temporary file beside it, then renames it into place,
/// so a failure leaves nothing half-written.
pub fn write_file_atomically(
    path: &Path,
    write: impl FnOnce(&mut std::fs::File) -> anyhow::Result<()>,
) -> anyhow::Result<()> {
    let dir = path
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let mut tmp = tempfile::NamedTempFile::new_in(dir).map_err(|source| bitrock::Error::Write {
        path: path.to_path_buf(),
        source,
    })?;
    write(tmp.as_file_mut())?;
    tmp.persist(path).map_err(|e| bitrock::Error::Write {
        path: path.to_path_buf(),
        source: e.error,
    })?;
    Ok(())
}
