//! What the binary prints: aligned tables with units for people, JSON for programs.
//! Parameters leave the library in SI and are shown in the record's torque unit.

use bitrock::data::FieldData;
use bitrock::fit::LawFit;
use serde_json::{Value, json};
use std::io::{self, Write};

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
