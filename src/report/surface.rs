//! The report of a surface directory (`bitrock report DIR` where DIR holds a surface run,
//! [`crate::run::surface::dir`]): report.md (what the record shows, the sampler, each law's
//! probability with the check by re-simulation and its posterior, the string, what the surface
//! implies at the bit) and one figure: the surface channels and the bit's predicted speed.

use super::figures::{SurfaceFigure, render_surface};
use super::{ReportSummary, figures_markdown, replace_report};
use crate::error::{Error, Result};
use crate::laws::Law;
use crate::run::dir::SURFACE_JSON;
use crate::run::surface::dir;
use crate::units::RAD_S_PER_RPM;
use serde_json::Value;
use std::fmt::Write;
use std::path::Path;
use std::time::Instant;

/// Writes the report of the surface directory `surface_dir` to `out` (replaced as a whole, as
/// every report is).
pub fn write_surface_report(out: &Path, surface_dir: &Path) -> Result<ReportSummary> {
    let start = Instant::now();
    let dir::Finished {
        job, document, record, ..
    } = dir::Finished::read(surface_dir)?;
    let unit = record.torque_unit;
    let per_unit = unit.newton_metres();
    let number = |v: &Value, name: &str| {
        v.as_f64().ok_or_else(|| Error::Data {
            path: surface_dir.join(SURFACE_JSON),
            message: format!("{name} is not a number"),
        })
    };
    let bit = &document["at_the_bit"];
    let bit_rpm: Vec<[f64; 3]> = serde_json::from_value(bit["speed_rpm"].clone()).map_err(|e| Error::Data {
        path: surface_dir.join(SURFACE_JSON),
        message: format!("at_the_bit.speed_rpm: {e}"),
    })?;
    let draws = bit["draws"].as_u64().unwrap_or(0) as usize;
    let rendered = vec![render_surface(
        &SurfaceFigure {
            time_s: record.time_s.clone(),
            surface_torque: record.surface_torque_nm.iter().map(|t| t / per_unit).collect(),
            torque_unit: unit.label(),
            top_drive_rpm: record.top_drive_rad_s.iter().map(|w| w / RAD_S_PER_RPM).collect(),
            bit_rpm,
        },
        draws,
    )?];

    let mut md = String::new();
    let _ = writeln!(md, "# Surface inference of {}\n", job.source.display());
    let _ = writeln!(md, "{}.\n", document["roles"].as_str().unwrap_or("the record"));
    let noise = &document["noise"];
    let _ = writeln!(
        md,
        "Surface torque noise {:.4} {} ({}). {} Mean surface torque {:.3} {} at {:.1} rpm.\n",
        number(&noise["sd_nm"], "noise.sd_nm")? / per_unit,
        unit.label(),
        noise["how"].as_str().unwrap_or("?"),
        match document["cycle"]["period_s"].as_f64() {
            Some(p) => format!(
                "A stick-slip cycle at the surface: period {p:.2} s, {:.1} cycles in the record.",
                document["cycle"]["cycles"].as_f64().unwrap_or(f64::NAN)
            ),
            None => "No stick-slip cycle at the surface.".into(),
        },
        number(&document["mean_torque_nm"], "mean_torque_nm")? / per_unit,
        unit.label(),
        number(&document["mean_top_drive_rpm"], "mean_top_drive_rpm")?,
    );
    let _ = writeln!(
        md,
        "ABC-SMC on strings simulated per candidate (distance: {}): {} populations, final ε {} (the noise's own \
         distance {:.4}), {} strings simulated in {:.1} s on the {} ({}); {:.1} strings per particle.\n",
        document["distance"].as_str().unwrap_or("?"),
        document["populations"],
        document["final_epsilon"]
            .as_f64()
            .map_or("∞".to_string(), |e| format!("{e:.4}")),
        document["noise_floor"].as_f64().unwrap_or(f64::NAN),
        document["simulations"],
        document["seconds"].as_f64().unwrap_or(f64::NAN),
        document["backend"].as_str().unwrap_or("?"),
        document["stop"].as_str().unwrap_or("?"),
        document["cost"]["strings_per_particle"].as_f64().unwrap_or(f64::NAN),
    );
    laws_markdown(&mut md, &document, unit, &surface_dir.join(SURFACE_JSON))?;
    string_markdown(&mut md, &document["string"]);
    at_the_bit_markdown(&mut md, bit);
    if let Some(warnings) = document["warnings"].as_array().filter(|w| !w.is_empty()) {
        let _ = writeln!(md, "\n## Warnings\n");
        for w in warnings {
            let _ = writeln!(md, "- {}", w.as_str().unwrap_or("?"));
        }
    }
    let infos: Vec<super::FigureInfo> = rendered.iter().map(|r| r.info.clone()).collect();
    figures_markdown(&mut md, &infos);
    replace_report(out, md, rendered, start)
}

/// Each law's probability, its re-simulated records recognised as it, its parameters (in the
/// record's torque unit), and the verdict.
fn laws_markdown(md: &mut String, document: &Value, unit: crate::units::TorqueUnit, path: &Path) -> Result<()> {
    let _ = writeln!(md, "## Laws\n");
    let _ = writeln!(
        md,
        "| law | P(law) | re-simulated records recognised as it | parameters: median [5 %, 95 %] |"
    );
    let _ = writeln!(md, "|---|---|---|---|");
    let rows = document["check"]["rows"].as_array().cloned().unwrap_or_default();
    for law in document["laws"].as_array().cloned().unwrap_or_default() {
        let name = law["law"].as_str().unwrap_or("?");
        let parsed: Law = name.parse().map_err(|message| Error::Data {
            path: path.to_path_buf(),
            message,
        })?;
        let recognised = rows
            .iter()
            .find(|r| r["law"].as_str() == Some(name))
            .map_or("no particle".to_string(), |r| {
                format!(
                    "{:.0} % of {}",
                    100.0 * r["recognised"].as_f64().unwrap_or(f64::NAN),
                    r["replicates"]
                )
            });
        let params: Vec<String> = law["params"]
            .as_array()
            .cloned()
            .unwrap_or_default()
            .iter()
            .zip(parsed.params())
            .map(|(p, spec)| {
                let scale = unit.newton_metres().powi(spec.torque_power);
                let q = |k: &str| p[k].as_f64().unwrap_or(f64::NAN) / scale;
                format!(
                    "{} {:.4} [{:.4}, {:.4}] {}{}",
                    p["name"].as_str().unwrap_or("?"),
                    q("median"),
                    q("q05"),
                    q("q95"),
                    spec.unit(unit.label()),
                    if p["identified"].as_bool() == Some(false) {
                        " (not identified)"
                    } else {
                        ""
                    }
                )
            })
            .collect();
        let _ = writeln!(
            md,
            "| {name} | {:.3} | {recognised} | {} |",
            law["probability"].as_f64().unwrap_or(f64::NAN),
            if params.is_empty() {
                "no particle".to_string()
            } else {
                params.join("; ")
            }
        );
    }
    let _ = writeln!(
        md,
        "\n**Verdict:** {}\n",
        document["check"]["verdict"].as_str().unwrap_or("?")
    );
    Ok(())
}

/// The string the candidates were simulated on: given, or its posterior.
fn string_markdown(md: &mut String, string: &Value) {
    let part = |p: &Value, name: &str, unit: &str| {
        let v = |k: &str| p[k].as_f64().unwrap_or(f64::NAN);
        if p["given"].as_bool() == Some(true) {
            format!("{name} {:.4}{unit} (given)", v("median"))
        } else {
            format!("{name} {:.4} [{:.4}, {:.4}]{unit}", v("median"), v("q05"), v("q95"))
        }
    };
    let k = &string["stiffness_knm_per_rad"];
    let _ = writeln!(
        md,
        "**String** ({}): I_eq {} kg·m², {}, {}; stiffness {:.4} kN·m/rad.\n",
        if string["inferred"].as_bool() == Some(true) {
            "inferred with the laws"
        } else {
            "given"
        },
        string["inertia_kg_m2"],
        part(&string["omega_n_rad_s"], "ω_n", " rad/s"),
        part(&string["damping_ratio"], "ξ", ""),
        k[1].as_f64().unwrap_or(f64::NAN),
    );
}

/// What the surface implies at the bit.
fn at_the_bit_markdown(md: &mut String, bit: &Value) {
    let q = |name: &str, i: usize| bit[name][i].as_f64().unwrap_or(f64::NAN);
    let _ = writeln!(md, "## At the bit\n");
    let _ = writeln!(
        md,
        "From {} posterior draws simulated on the record's clock: stuck {:.2} [{:.2}, {:.2}] of the time, severity \
         {:.2} [{:.2}, {:.2}], P(stick-slip) {:.2}.",
        bit["draws"],
        q("stuck_share", 1),
        q("stuck_share", 0),
        q("stuck_share", 2),
        q("severity", 1),
        q("severity", 0),
        q("severity", 2),
        bit["stick_slip_probability"].as_f64().unwrap_or(f64::NAN),
    );
    if let Some(advice) = bit["advice"].as_str() {
        let _ = writeln!(md, "\n**Advice:** {advice}");
    }
}
