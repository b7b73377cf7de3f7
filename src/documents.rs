//! The machine-readable documents bitrock writes: the fits as JSON (`fit --json`), a run's
//! summary (run.json, also printed by `abc --json`), its envelopes.csv and data.csv, and a
//! store's export (particles as CSV, the whole run as JSON). One place for their shapes, so
//! that the run directory the library writes and what the binary prints agree. Parameters
//! leave the library in SI and appear here in the record's torque unit, named with units.

use crate::Law;
use crate::abc::posterior::{ENVELOPE_LEVEL, Envelope, PosteriorSummary};
use crate::abc::{Particle, Population, PopulationRecord, Run};
use crate::data::FieldData;
use crate::fit::LawFit;
use crate::prior::Prior;
use crate::units::TorqueUnit;
use serde_json::{Value, json};

/// The parameter values and standard errors of `fit` in the record's torque unit.
pub fn fit_in_record_units(data: &FieldData, fit: &LawFit) -> (Vec<f64>, Vec<Option<f64>>) {
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
            let (params, std_errors) = fit_in_record_units(data, fit);
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

/// The evidence of a record's laws as JSON: the fits, the boxes (record units), and per law
/// ln Z with its Monte-Carlo error, P(m | y), the sampler's effort and the posterior mean.
/// `prior` describes the boxes of `boxes` in words.
#[allow(clippy::too_many_arguments)] // The parts of an evidence's analysis (`run::evidence`), which this layer, below the runs, cannot name.
pub fn evidence_json(
    data: &FieldData,
    fits: &[LawFit],
    boxes: &crate::prior::Prior,
    evidence: &crate::abc::evidence::Evidence,
    separations: &[crate::separation::Separation],
    residual_lag1: &[f64],
    ar1_preference_nats: &[f64],
    noise_models: &[crate::abc::evidence::NoiseEvidence],
    prior: &str,
) -> Value {
    let torque = data.torque_unit.label();
    let laws: Vec<Value> = evidence
        .laws
        .iter()
        .zip(&boxes.boxes)
        .map(|(law, bx)| {
            // The value of `law`'s fit in `per_fit` (in `fits` order), where it has one.
            let of_fit = |per_fit: &[f64]| {
                fits.iter()
                    .zip(per_fit)
                    .find(|(f, _)| f.law == law.law)
                    .map(|(_, &v)| v)
                    .filter(|v| v.is_finite())
            };
            let lower: Vec<f64> = bx.lower.iter().map(|&v| f64::from(v)).collect();
            let upper: Vec<f64> = bx.upper.iter().map(|&v| f64::from(v)).collect();
            let d = law.law.n_params();
            let mean_si: Vec<f64> = (0..d)
                .map(|j| law.posterior.iter().map(|(p, w)| w * p[j]).sum())
                .collect();
            json!({
                "law": law.law,
                "names": law.law.param_names(),
                "units": law.law.params().iter().map(|s| s.unit(torque)).collect::<Vec<_>>(),
                "lower": to_record_units(law.law, &lower, data.torque_unit),
                "upper": to_record_units(law.law, &upper, data.torque_unit),
                "ln_z": law.ln_z,
                "ln_z_error": law.ln_z_error,
                "island_ln_z": law.island_ln_z,
                "island_spread": law.island_spread,
                "converged": law.converged(),
                "prior_probability": law.prior_probability,
                "probability": law.probability,
                "probability_error": law.probability_error,
                "refinements": law.refinements,
                "posterior_mean": to_record_units(law.law, &mean_si, data.torque_unit),
                "best_rho": law.best_rho,
                // ⟨ln L⟩ over the posterior and the Occam factor ln Z − ⟨ln L⟩ (N·m, nats).
                "mean_ln_l": law.mean_ln_l,
                "occam_nats": law.mean_ln_l.map(|m| law.ln_z - m),
                // Each parameter's box widened and narrowed, its ends in the record's units.
                "box_changes": law.box_changes.iter().map(|c| {
                    let torque_valued = law.law.params().iter().any(|s| s.name == c.parameter && s.torque_power == 1);
                    let per_unit = if torque_valued { 1.0 / data.torque_unit.newton_metres() } else { 1.0 };
                    json!({
                        "parameter": c.parameter,
                        "factor": c.factor,
                        "lower": c.lower * per_unit,
                        "upper": c.upper * per_unit,
                        "ln_z_shift": c.ln_z_shift,
                    })
                }).collect::<Vec<_>>(),
                "cut_by_box": law.cut_by_box,
                // The box cut to curves within the record's torques, where the law's is: the
                // limit in the record's torque unit, up to which speed, and the box's share.
                "prior_curve": law.curve.as_ref().map(|c| json!({
                    "within": c.within,
                    "limit": c.limit_nm / data.torque_unit.newton_metres(),
                    "speeds": c.speeds_rad_s.len(),
                    "speeds_rad_s": [0.0, c.speeds_rad_s.last().copied().unwrap_or(0.0)],
                    "ln_share": c.ln_share,
                    "ln_share_error": c.ln_share_error,
                })),
                "starts": law.starts,
                "residual_lag1": of_fit(residual_lag1),
                // ln p(y | AR(1)) − ln p(y | i.i.d.) at the fit (nats).
                "ar1_preference_nats": of_fit(ar1_preference_nats),
                "stages": law.stages,
                "candidates_scored": law.candidates_scored,
            })
        })
        .collect();
    json!({
        "source": data.source.display().to_string(),
        "torque_unit": torque,
        "speed_unit_of_params": "rad/s",
        "data_points": evidence.data_points,
        "noise_model": evidence.config.noise,
        // The reported row's W_ref: the posterior's torque parameters are for W = W_ref.
        "w_ref_kn": noise_models
            .iter()
            .max_by(|a, b| a.probability.total_cmp(&b.probability))
            .and_then(|row| row.w_ref_kn),
        "noise_models": noise_models,
        "ln_z_torque_unit": "N·m",
        "prior": prior,
        "sampler": evidence.config,
        "backend": evidence.backend,
        "candidates_scored": evidence.candidates_scored,
        "evaluations": evidence.evaluations,
        "seconds": evidence.seconds,
        "laws": laws,
        "fits": fit_json(data, fits)["fits"],
        "separations": separations,
        "bayes_factors": evidence.bayes_factors(separations),
    })
}

/// A torque-scaled vector (parameters, their spreads) from SI to the record's torque unit.
pub fn to_record_units(law: Law, values_si: &[f64], torque_unit: TorqueUnit) -> Vec<f64> {
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
        "thin": record.thin(),
        "seconds": record.seconds,
        "stream": record.stream,
    })
}

/// The record's summary shared by run.json and the export: source, columns, unit, row counts.
fn data_json(data: &FieldData, fits: &Value) -> Value {
    json!({
        "source": fits["source"],
        "columns": fits["columns"],
        "torque_unit": data.torque_unit.label(),
        "rows_read": data.rows_read,
        "rows_used": data.rows_used,
        "calibration_rows": data.calibration.len(),
        "validation_rows": data.validation.len(),
    })
}

/// Everything an ABC run produced, as written to DIR/run.json and printed by `abc --json`.
pub struct RunSummary<'a> {
    pub data: &'a FieldData,
    pub fits: &'a [LawFit],
    pub prior: &'a Prior,
    pub run: &'a Run,
    pub posterior: &'a PosteriorSummary,
    /// Index of the summarised population.
    pub summary_population: usize,
    /// The run configuration as stored, with the worker threads of this invocation.
    pub config: Value,
    pub seed: u64,
    pub backend: &'a str,
}

impl RunSummary<'_> {
    /// The run.json document, with the result's `warnings` ([`crate::run::abc::Analysis::warnings`]).
    pub fn json(&self, warnings: Vec<String>) -> Value {
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
                    "identified": s.identified,
                })
            })
            .collect();
        let fits = fit_json(self.data, self.fits);
        json!({
            "version": env!("CARGO_PKG_VERSION"),
            "backend": self.backend,
            "seed": self.seed,
            "config": self.config,
            "data": data_json(self.data, &fits),
            "fits": fits["fits"],
            "priors": priors,
            "populations": self.run.populations.iter().map(|p| population_json(&p.record)).collect::<Vec<_>>(),
            "stop_reason": self.run.stop,
            "stop_description": self.run.stop.describe(),
            "warnings": warnings,
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

/// Header of a particle CSV: population, law, candidate, rho, weight, then every law's
/// parameters with units.
fn particle_header(laws: &[Law], unit: TorqueUnit) -> Vec<String> {
    let mut header: Vec<String> = ["population", "law", "candidate", "rho", "weight"]
        .iter()
        .map(|s| s.to_string())
        .collect();
    for law in laws {
        for spec in law.params() {
            // Namespaced by the law: a law file may reuse a built-in law's parameter name.
            header.push(format!("{}.{} [{}]", law.name(), spec.name, spec.unit(unit.label())));
        }
    }
    header
}

/// Rows of text as CSV (quoted where a cell needs it).
fn csv_text<R: AsRef<[u8]>>(rows: impl IntoIterator<Item = impl IntoIterator<Item = R>>) -> Vec<u8> {
    let mut w = csv::Writer::from_writer(Vec::new());
    for row in rows {
        w.write_record(row).expect("CSV into memory");
    }
    w.into_inner().expect("CSV into memory")
}

/// Populations' particles as CSV: one row per particle, parameters in columns in the record's
/// torque unit (empty cells for the other laws' parameters).
pub fn particles_csv(populations: &[&Population], laws: &[Law], unit: TorqueUnit) -> Vec<u8> {
    let groups: Vec<(usize, &[Particle])> = populations
        .iter()
        .map(|p| (p.record.index, p.particles.as_slice()))
        .collect();
    particle_groups_csv(&groups, laws, unit)
}

/// Groups of particles (population index, particles) as CSV, as [`particles_csv`] writes
/// them; a ρ that is not kept (NaN) is an empty cell.
pub fn particle_groups_csv(groups: &[(usize, &[Particle])], laws: &[Law], unit: TorqueUnit) -> Vec<u8> {
    particle_groups_csv_with(groups, laws, unit, &[])
}

/// [`particle_groups_csv`] with a column per `(header, coordinate)` of `coordinates` after the
/// laws' parameters: the particle's coordinate at that index past its law's parameters (a
/// surface run's string, inferred with the law), as it stands.
pub fn particle_groups_csv_with(
    groups: &[(usize, &[Particle])],
    laws: &[Law],
    unit: TorqueUnit,
    coordinates: &[(&str, usize)],
) -> Vec<u8> {
    let rows = groups.iter().flat_map(|&(population, particles)| {
        particles.iter().map(move |p| {
            let mut row = vec![
                population.to_string(),
                p.law.name().to_string(),
                p.index.to_string(),
                if p.rho.is_nan() {
                    String::new()
                } else {
                    format!("{:e}", p.rho)
                },
                format!("{:e}", p.weight),
            ];
            for law in laws {
                if *law == p.law {
                    row.extend(
                        to_record_units(p.law, &p.params[..law.n_params()], unit)
                            .iter()
                            .map(|v| format!("{v:e}")),
                    );
                } else {
                    row.extend(std::iter::repeat_n(String::new(), law.n_params()));
                }
            }
            let n = p.law.n_params();
            row.extend(coordinates.iter().map(|&(_, k)| format!("{:e}", p.params[n + k])));
            row
        })
    });
    let mut header = particle_header(laws, unit);
    header.extend(coordinates.iter().map(|(name, _)| name.to_string()));
    csv_text(std::iter::once(header).chain(rows))
}

/// Weighted particles from a CSV in [`particles_csv`]'s layout (SI): a `law` and a `weight`
/// column, and per law its parameters as `LAW.NAME [UNIT]` columns, torques in kN·m or N·m as
/// each column's unit says; `population`, `candidate` and `rho` may be absent, and a file of
/// several populations is refused (a map is of one). Law files' laws must be registered first.
/// Refusals name the file, line and column.
pub fn read_particles_csv(path: &std::path::Path) -> crate::error::Result<Vec<Particle>> {
    use crate::error::Error;
    let format = |line: Option<u64>, message: String| Error::Format {
        path: path.to_path_buf(),
        line,
        message,
    };
    let (mut reader, header) = crate::files::csv_with_header(path)?;
    let column = |name: &str| header.iter().position(|h| h == name);
    let (Some(law_col), Some(weight_col)) = (column("law"), column("weight")) else {
        return Err(format(
            Some(1),
            format!(
                "a particle file needs the columns 'law' and 'weight' (and 'LAW.NAME [UNIT]' per parameter); found {}",
                header.join(", ")
            ),
        ));
    };
    let (population_col, index_col, rho_col) = (column("population"), column("candidate"), column("rho"));
    // Per law met: each parameter's column and its scale to SI.
    let mut layouts: std::collections::HashMap<Law, Vec<(usize, f64)>> = Default::default();
    let mut population: Option<String> = None;
    let mut particles = Vec::new();
    for (i, row) in crate::files::csv_rows(&mut reader, path, &header).enumerate() {
        let row = row?;
        if let Some(col) = population_col {
            match &population {
                None => population = Some(row.cell(col).to_string()),
                Some(first) if first != row.cell(col) => {
                    return Err(row.bad_cell(
                        col,
                        format!(
                            "the file holds population {first} and {}; a map is of one population (bitrock export --population G)",
                            row.cell(col)
                        ),
                    ));
                }
                Some(_) => {}
            }
        }
        let law: Law = row
            .cell(law_col)
            .parse()
            .map_err(|e: String| row.bad_cell(law_col, e))?;
        if let std::collections::hash_map::Entry::Vacant(entry) = layouts.entry(law) {
            entry.insert(param_layout(law, &column).map_err(|message| format(Some(row.line), message))?);
        }
        let params = layouts[&law]
            .iter()
            .map(|&(col, scale)| row.number(col).map(|v| v * scale))
            .collect::<crate::error::Result<Vec<f64>>>()?;
        let weight = row.number(weight_col)?;
        if weight < 0.0 {
            return Err(row.bad_cell(weight_col, format!("{weight} is negative; weights are ≥ 0")));
        }
        particles.push(Particle {
            law,
            index: match index_col {
                Some(col) => row.number(col)? as u64,
                None => i as u64,
            },
            params,
            rho: match rho_col {
                Some(col) if !row.cell(col).is_empty() => row.number(col)?,
                _ => f64::NAN,
            },
            weight,
        });
    }
    if particles.is_empty() {
        return Err(format(None, "the file holds no particles".into()));
    }
    Ok(particles)
}

/// Each parameter's column of `law` in a particle file (found by `column`) and its scale to
/// SI, torques in kN·m or N·m as the column's unit says; `Err` names the column it lacks.
fn param_layout(law: Law, column: &dyn Fn(&str) -> Option<usize>) -> Result<Vec<(usize, f64)>, String> {
    let mut layout = Vec::new();
    for spec in law.params() {
        let found = [TorqueUnit::KNm, TorqueUnit::Nm].into_iter().find_map(|unit| {
            let name = format!("{}.{} [{}]", law.name(), spec.name, spec.unit(unit.label()));
            column(&name).map(|col| (col, unit))
        });
        let Some((col, unit)) = found else {
            return Err(format!(
                "law {law} needs the column '{}.{} [{}]' (or its N·m twin), which the header lacks",
                law.name(),
                spec.name,
                spec.unit(TorqueUnit::KNm.label())
            ));
        };
        let scale = if spec.torque_power == 1 {
            unit.newton_metres()
        } else {
            1.0
        };
        layout.push((col, scale));
    }
    Ok(layout)
}

/// A population and its particles as JSON, parameters in the record's torque unit.
fn population_with_particles_json(population: &Population, unit: TorqueUnit) -> Value {
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

/// A stored run as JSON (`export --format json`): its configuration (as stored), data summary,
/// fits, prior, and `populations` with their particles.
pub fn export_json(
    config: &Value,
    data: &FieldData,
    fits: &[LawFit],
    prior: &Prior,
    populations: &[&Population],
) -> Value {
    let unit = data.torque_unit;
    let fits = fit_json(data, fits);
    json!({
        "version": env!("CARGO_PKG_VERSION"),
        "config": config,
        "data": data_json(data, &fits),
        "fits": fits["fits"],
        "priors": prior_json(prior, unit),
        "populations": populations
            .iter()
            .map(|p| population_with_particles_json(p, unit))
            .collect::<Vec<_>>(),
    })
}

/// The prior boxes in the record's units, with names, units and law weights.
fn prior_json(prior: &Prior, unit: TorqueUnit) -> Value {
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

/// envelopes.csv: the predictive envelopes, one block of rows per law, in the record's torque
/// unit.
pub fn envelopes_csv(envelopes: &[Envelope], unit: TorqueUnit) -> Vec<u8> {
    let suffix = unit.suffix();
    let to_unit = 1.0 / unit.newton_metres();
    let header = [
        "law".to_string(),
        "speed_rad_s".into(),
        format!("lower_{suffix}"),
        format!("median_{suffix}"),
        format!("upper_{suffix}"),
    ];
    let rows = envelopes.iter().flat_map(|e| {
        (0..e.speed_rad_s.len()).map(move |i| {
            [
                e.law.name().to_string(),
                format!("{:.6}", e.speed_rad_s[i]),
                format!("{:.6e}", e.lower[i] * to_unit),
                format!("{:.6e}", e.median[i] * to_unit),
                format!("{:.6e}", e.upper[i] * to_unit),
            ]
        })
    });
    csv_text(std::iter::once(header).chain(rows))
}

/// data.csv: the calibration and validation samples the envelopes are drawn against.
pub fn data_csv(data: &FieldData) -> Vec<u8> {
    let suffix = data.torque_unit.suffix();
    let to_unit = 1.0 / data.torque_unit.newton_metres();
    let header = ["set".to_string(), "speed_rad_s".into(), format!("torque_{suffix}")];
    let rows = [("calibration", &data.calibration), ("validation", &data.validation)]
        .into_iter()
        .flat_map(|(set, samples)| {
            samples
                .speed_rad_s
                .iter()
                .zip(&samples.torque_nm)
                .map(move |(s, t)| [set.to_string(), format!("{s:.6}"), format!("{:.6e}", t * to_unit)])
        });
    csv_text(std::iter::once(header).chain(rows))
}
