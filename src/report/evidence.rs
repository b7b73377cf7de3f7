//! The report of an evidence directory (`bitrock report DIR` where DIR holds an evidence,
//! [`crate::run::evidence::dir`]): report.md (each law's evidence, the Bayes factors, the
//! models of the residuals compared, which pairs the record can tell apart, the boxes) and two
//! figures: each law's 98 % posterior predictive envelope over the samples, and P(m | y).

use super::figures::{self, EvidenceFigures};
use super::{ReportSummary, figures_markdown, replace_report};
use crate::abc::evidence::{BayesFactor, Start, StartEstimate, Strength, describe_starts, ln_bayes_factor};
use crate::error::{Error, Result};
use crate::laws::Law;
use crate::run::dir::POSTERIOR_CSV;
use crate::run::evidence::dir;
use serde_json::Value;
use std::fmt::Write;
use std::path::Path;
use std::time::Instant;

/// One law's line of the evidence document.
struct LawLine {
    law: Law,
    ln_z: f64,
    ln_z_error: f64,
    probability: f64,
    best_rho: f64,
    converged: bool,
    island_spread: f64,
    cut_by_box: Vec<String>,
    /// Each start's estimate, where the law's samplers started from both.
    starts: Vec<StartEstimate>,
}

/// Writes the report of the evidence directory `evidence_dir` to `out` (replaced as a whole,
/// as every report is).
pub fn write_evidence_report(out: &Path, evidence_dir: &Path) -> Result<ReportSummary> {
    let start = Instant::now();
    let document = dir::read(evidence_dir)?;
    let laws = law_lines(&document, evidence_dir)?;
    let particles = crate::documents::read_particles_csv(&evidence_dir.join(POSTERIOR_CSV))?;
    let samples = dir::samples(evidence_dir)?;
    let source = document["source"].as_str().unwrap_or("the record").to_string();
    let w_ref_kn = document["w_ref_kn"].as_f64();
    let rendered = figures::render_evidence(&EvidenceFigures {
        particles: &particles,
        laws: laws.iter().map(|l| (l.law, l.probability)).collect(),
        ln_z: laws.iter().map(|l| (l.ln_z, l.ln_z_error)).collect(),
        samples: &samples,
        w_ref_kn,
    })?;
    let mut md = String::new();
    let _ = writeln!(md, "# Model evidence of {source}\n");
    let sampler = &document["sampler"];
    let _ = writeln!(
        md,
        "Marginal likelihood ln Z of each law on {} calibration samples (tempered SMC per law, {} islands × {} \
         particles {}, seed {}; {} noise model{}; ln Z with torques in N·m), on {} in {:.2} s. Prior: {}.\n",
        document["data_points"],
        sampler["islands"],
        sampler["particles"],
        // A document that names no start ran from the boxes.
        serde_json::from_value::<Start>(sampler["start"].clone())
            .unwrap_or_default()
            .describe(),
        sampler["seed"],
        document["noise_model"].as_str().unwrap_or("?"),
        w_ref_kn.map_or(String::new(), |w| format!(
            ", each predicted torque scaled by WOB / W_ref, W_ref = {w:.1} kN"
        )),
        document["backend"].as_str().unwrap_or("?"),
        document["seconds"].as_f64().unwrap_or(f64::NAN),
        document["prior"].as_str().unwrap_or("?"),
    );
    if let Some(answer) = document["answer"]["sentence"].as_str() {
        let _ = writeln!(md, "**Answer:** {answer}.\n");
    }
    laws_markdown(&mut md, &laws);
    let factors = bayes_factors(&document, &laws, evidence_dir)?;
    bayes_factors_markdown(&mut md, &factors);
    check_markdown(&mut md, &document);
    noise_models_markdown(&mut md, &document);
    separations_markdown(&mut md, &document);
    let infos: Vec<super::FigureInfo> = rendered.iter().map(|r| r.info.clone()).collect();
    figures_markdown(&mut md, &infos);
    replace_report(out, md, rendered, start)
}

/// The table of each law's evidence, and each start's ln Z where both starts ran.
fn laws_markdown(md: &mut String, laws: &[LawLine]) {
    let _ = writeln!(
        md,
        "| law | ln Z | ± Monte-Carlo error | P(m \\| y) | best ρ | islands agree | posterior cut by its box |"
    );
    let _ = writeln!(md, "|---|---|---|---|---|---|---|");
    for l in laws {
        let agree = if l.converged {
            "yes".to_string()
        } else {
            format!("no: {:.1} nats apart", l.island_spread)
        };
        let cut = if l.cut_by_box.is_empty() {
            "no".to_string()
        } else {
            l.cut_by_box.join(", ")
        };
        let _ = writeln!(
            md,
            "| {} | {:.3} | {:.3} | {:.4} | {:.5} | {agree} | {cut} |",
            l.law, l.ln_z, l.ln_z_error, l.probability, l.best_rho
        );
    }
    if laws.iter().any(|l| !l.starts.is_empty()) {
        let _ = writeln!(
            md,
            "\nEach start's ln Z (a start errs low where it misses part of the posterior; the higher kept where \
             they differ beyond their errors or a start's islands disagree):\n"
        );
        for l in laws {
            if let Some(line) = describe_starts(&l.starts) {
                let _ = writeln!(md, "- {}: {line}", l.law);
            }
        }
    }
}

/// The Bayes factors of the law of the largest evidence against each other law, in words.
fn bayes_factors_markdown(md: &mut String, factors: &[BayesFactor]) {
    if let [first, ..] = factors {
        let _ = writeln!(
            md,
            "\nBayes factors of {}, the law of the largest evidence, against each other law, split into the data's \
             part (⟨ln L⟩ over the posteriors) and the boxes' part (the Occam factors, which boxes twice as wide move \
             by ln 2 per parameter, less where a law's prior is cut to the record's torques). Kass & Raftery's words, on the data's part: undecided below 1 nat or within \
             twice the error; decided by the boxes where the data's part is below {} nat or the fits do not \
             separate the pair:\n",
            first.favoured,
            crate::abc::evidence::DATA_DECIDES_NATS
        );
        for f in factors {
            let parts = f.parts();
            let _ = writeln!(
                md,
                "- {} against {}: ln B = {:.2} ± {:.2}, {}{}",
                f.favoured,
                f.against,
                f.ln_b,
                f.error,
                f.strength,
                if parts.is_empty() {
                    String::new()
                } else {
                    format!(" ({parts})")
                }
            );
            if let Some(range) = &f.sensitivity {
                let _ = writeln!(md, "  - {}", range.describe());
            }
        }
    }
}

/// The document's Bayes factors; a document written without them gets the plain factors of
/// its laws' ln Z, worded without the data's part.
fn bayes_factors(document: &Value, laws: &[LawLine], dir: &Path) -> Result<Vec<BayesFactor>> {
    if let Some(factors) = document.get("bayes_factors") {
        return serde_json::from_value(factors.clone()).map_err(|e| Error::Data {
            path: dir.join(crate::run::dir::EVIDENCE_JSON),
            message: format!("`bayes_factors` does not read ({e})"),
        });
    }
    let Some(best) = laws.iter().max_by(|a, b| a.ln_z.total_cmp(&b.ln_z)) else {
        return Ok(Vec::new());
    };
    Ok(laws
        .iter()
        .filter(|l| l.law != best.law)
        .map(|l| {
            let (ln_b, error) = ln_bayes_factor((best.ln_z, best.ln_z_error), (l.ln_z, l.ln_z_error));
            BayesFactor {
                favoured: best.law,
                against: l.law,
                ln_b,
                error,
                data_nats: None,
                boxes_nats: None,
                separation_nats: None,
                strength: Strength::of(ln_b, error, None, None),
                sensitivity: None,
            }
        })
        .collect())
}

/// Each law's line of `document` (read from `dir`).
fn law_lines(document: &Value, dir: &Path) -> Result<Vec<LawLine>> {
    let bad = |message: String| Error::Data {
        path: dir.join(crate::run::dir::EVIDENCE_JSON),
        message,
    };
    let laws = document["laws"]
        .as_array()
        .ok_or_else(|| bad("no `laws` in the evidence document".into()))?;
    laws.iter()
        .map(|entry| {
            let law: Law =
                serde_json::from_value(entry["law"].clone()).map_err(|e| bad(format!("law {}: {e}", entry["law"])))?;
            let number = |key: &str| {
                entry[key]
                    .as_f64()
                    .ok_or_else(|| bad(format!("law {law}: `{key}` is not a number")))
            };
            Ok(LawLine {
                law,
                ln_z: number("ln_z")?,
                ln_z_error: number("ln_z_error")?,
                probability: number("probability")?,
                best_rho: number("best_rho")?,
                converged: entry["converged"].as_bool().unwrap_or(true),
                island_spread: entry["island_spread"].as_f64().unwrap_or(0.0),
                cut_by_box: entry["cut_by_box"]
                    .as_array()
                    .map(|a| a.iter().filter_map(|v| v.as_str().map(str::to_string)).collect())
                    .unwrap_or_default(),
                starts: match entry.get("starts") {
                    Some(starts) => serde_json::from_value(starts.clone())
                        .map_err(|e| bad(format!("law {law}: `starts` does not read ({e})")))?,
                    None => Vec::new(),
                },
            })
        })
        .collect()
}

/// The evidence's check by re-simulation, where it ran: per law that made the synthetic
/// records, how many of them were decided for it, undecided or decided for another, and its
/// verdict.
fn check_markdown(md: &mut String, document: &Value) {
    let Ok(check) = serde_json::from_value::<crate::run::evidence::EvidenceCheck>(document["check"].clone()) else {
        return;
    };
    let _ = writeln!(
        md,
        "\n## Check by re-simulation\n\n{} synthetic records per law, each made from the law's posterior with the \
         record's own residuals and put through a lighter evidence over the same boxes:\n",
        check.replicates
    );
    let _ = writeln!(md, "| made by | decided right | undecided | decided wrong | verdict |");
    let _ = writeln!(md, "|---|---|---|---|---|");
    for row in &check.rows {
        let _ = writeln!(
            md,
            "| {} | {:.0} % | {:.0} % | {:.0} % | {} |",
            row.law,
            100.0 * row.decided_right,
            100.0 * row.undecided,
            100.0 * row.decided_wrong,
            row.verdict
        );
    }
}

/// The models of the residuals compared, where there were several.
fn noise_models_markdown(md: &mut String, document: &Value) {
    let Some(models) = document["noise_models"].as_array().filter(|m| m.len() > 1) else {
        return;
    };
    let _ = writeln!(md, "\n## Models of the residuals (equal prior odds)\n");
    let _ = writeln!(
        md,
        "| noise | torque | ln p(y \\| model) | ± Monte-Carlo error | P(model \\| y) | first law |"
    );
    let _ = writeln!(md, "|---|---|---|---|---|---|");
    for m in models {
        let torque = m["w_ref_kn"]
            .as_f64()
            .map_or("as the law".to_string(), |w| format!("× WOB / {w:.1} kN"));
        let _ = writeln!(
            md,
            "| {} | {torque} | {:.2} | {:.2} | {:.4} | {} ({:.3}) |",
            m["model"].as_str().unwrap_or("?"),
            m["ln_evidence"].as_f64().unwrap_or(f64::NAN),
            m["ln_evidence_error"].as_f64().unwrap_or(f64::NAN),
            m["probability"].as_f64().unwrap_or(f64::NAN),
            m["first_law"].as_str().unwrap_or("?"),
            m["first_probability"].as_f64().unwrap_or(f64::NAN),
        );
    }
}

/// Which pairs of laws the record can tell apart, from the least-squares fits alone.
fn separations_markdown(md: &mut String, document: &Value) {
    let Some(pairs) = document["separations"].as_array().filter(|p| !p.is_empty()) else {
        return;
    };
    let _ = writeln!(
        md,
        "\n## Can this record tell the laws apart?\n\nExpected log-likelihood gap D (nats) if the first law, as fitted, made the \
         record, and the chance that the second is ranked above it; below {} nats the priors, not the data, decide.\n",
        crate::separation::UNDECIDED_NATS
    );
    let _ = writeln!(md, "| made by | against | D (nats) | P(misranked) |");
    let _ = writeln!(md, "|---|---|---|---|");
    for s in pairs {
        let _ = writeln!(
            md,
            "| {} | {} | {:.1} | {:.3} |",
            s["truth"].as_str().unwrap_or("?"),
            s["rival"].as_str().unwrap_or("?"),
            s["gap_nats"].as_f64().unwrap_or(f64::NAN),
            s["misranking"].as_f64().unwrap_or(f64::NAN),
        );
    }
}
