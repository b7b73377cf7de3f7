//! The report of a watch directory: what the watch saw along the record, its changes of
//! formation, the stretches between them and the latest advice, with the figures along the
//! record.

use super::Update;
use super::store::StoredWatch;
use crate::error::Result;
use crate::report::{ReportSummary, figures_markdown, replace_report};
use std::fmt::Write as _;
use std::path::Path;
use std::time::Instant;

/// Writes `report.md` and the figures of the watch in `watch` under `dir`, replaced as a whole
/// (as [`crate::report::write_report`] does).
pub fn write(dir: &Path, watch: &StoredWatch) -> Result<ReportSummary> {
    let start = Instant::now();
    let rendered = super::figures::render(watch)?;
    let mut md = markdown(watch);
    figures_markdown(&mut md, &rendered.iter().map(|r| r.info.clone()).collect::<Vec<_>>());
    replace_report(dir, md, rendered, start)
}

fn markdown(watch: &StoredWatch) -> String {
    let meta = &watch.meta;
    let updates = &watch.updates;
    let settings = &meta.settings;
    let mut md = String::new();
    let _ = writeln!(md, "# bitrock watch report\n");
    let informative = updates.iter().filter(|u| u.uninformative.is_none()).count();
    let span = match (updates.first(), updates.last()) {
        (Some(a), Some(b)) => format!(", from t = {} s to {} s", a.start_s, b.end_s),
        _ => String::new(),
    };
    let _ = writeln!(
        md,
        "Record: `{}`, watched in windows of {} s every {} s (its rate: {:.1} Hz); torques in {}. \
         {} windows stored{span}, {informative} of them informative.\n",
        meta.source,
        meta.window_s,
        meta.step_s,
        meta.rate_hz,
        meta.torque_unit.label(),
        updates.len(),
    );
    let laws = settings["laws"]
        .as_array()
        .map(|l| l.iter().filter_map(|v| v.as_str()).collect::<Vec<_>>().join(", "))
        .unwrap_or_default();
    let per_window = match &meta.surface {
        Some(columns) => {
            let s = &settings["surface"];
            format!(
                "a record of surface channels alone (top-drive speed '{}', surface torque '{}'), each window's laws \
                 through strings simulated per candidate: ABC-SMC of {} particles, at most {} populations, a pilot of {}, \
                 its model choice checked by {} records re-simulated per law (seed {})",
                columns.top_drive,
                columns.surface_torque,
                s["particles"],
                s["max_populations"],
                s["pilot"],
                s["check_replicates"],
                settings["seed"],
            )
        }
        None => format!(
            "the evidence of each law per window from {} particles × {} islands (seed {})",
            settings["particles"], settings["islands"], settings["seed"],
        ),
    };
    let change = match &meta.surface {
        Some(_) => "no change of formation judged (the change rule compares fits of the bit's channels)".to_string(),
        None => format!(
            "a change declared beyond {} nats over the running level",
            settings["change_nats"]
        ),
    };
    let _ = writeln!(
        md,
        "Settings: laws {laws}; {per_window}; probabilities carried with forgetting {} and floor {}; \
         {change}; advice below a risk of {}. Watched by bitrock {}.\n",
        settings["forgetting"], settings["floor"], settings["risk"], meta.bitrock_version,
    );

    changes_section(&mut md, updates);

    stretches_section(&mut md, updates);

    if let Some(last) = updates.last() {
        last_window_section(&mut md, last);
    }
    let mut latencies: Vec<f64> = updates.iter().map(|u| u.latency_s).collect();
    if !latencies.is_empty() {
        latencies.sort_by(f64::total_cmp);
        let _ = writeln!(
            md,
            "Latency from a window's last sample to its update: median {:.2} s, 90th percentile {:.2} s.\n",
            crate::numerics::quantile(&latencies, 0.5),
            crate::numerics::quantile(&latencies, 0.9)
        );
    }
    md
}

/// The windows where a change of formation was declared.
fn changes_section(md: &mut String, updates: &[Update]) {
    let _ = writeln!(md, "## Changes of formation\n");
    let changes: Vec<_> = updates.iter().filter(|u| u.change).collect();
    if changes.is_empty() {
        let _ = writeln!(md, "None declared.\n");
    } else {
        let _ = writeln!(
            md,
            "| window | its time (s) | loss over the running level (nats) | most probable after |\n|---|---|---|---|"
        );
        for u in &changes {
            let _ = writeln!(
                md,
                "| {} | {}–{} | {} | {} |",
                u.window,
                u.start_s,
                u.end_s,
                u.change_nats.map_or("–".into(), |n| format!("{n:.1}")),
                u.most_probable.map_or("–".into(), |l| l.to_string()),
            );
        }
        let _ = writeln!(md);
    }
}

/// The stretches between changes: which law each most often ranked first.
fn stretches_section(md: &mut String, updates: &[Update]) {
    // The stretches between changes: which law each most often ranked first.
    let _ = writeln!(md, "## Stretches between changes\n");
    let _ = writeln!(
        md,
        "| from (s) | to (s) | informative windows | most often most probable | its share |\n|---|---|---|---|---|"
    );
    let mut stretch_start = 0;
    for k in 0..=updates.len() {
        let ends = k == updates.len() || (k > stretch_start && updates[k].change);
        if !ends {
            continue;
        }
        let stretch = &updates[stretch_start..k];
        let mut counts: Vec<(crate::Law, usize)> = Vec::new();
        for u in stretch.iter().filter(|u| u.uninformative.is_none()) {
            if let Some(law) = u.most_probable {
                match counts.iter_mut().find(|(l, _)| *l == law) {
                    Some((_, n)) => *n += 1,
                    None => counts.push((law, 1)),
                }
            }
        }
        let informative = stretch.iter().filter(|u| u.uninformative.is_none()).count();
        let top = counts.iter().max_by_key(|(_, n)| *n);
        if let (Some(first), Some(last)) = (stretch.first(), stretch.last()) {
            let _ = writeln!(
                md,
                "| {} | {} | {informative} | {} | {} |",
                first.start_s,
                last.end_s,
                top.map_or("–".into(), |(l, _)| l.to_string()),
                top.map_or("–".into(), |(_, n)| format!(
                    "{:.0} %",
                    100.0 * *n as f64 / informative.max(1) as f64
                )),
            );
        }
        stretch_start = k;
    }
    let _ = writeln!(md);
}

/// The last window: its law probabilities, its ABC's tolerance and its advice.
fn last_window_section(md: &mut String, last: &Update) {
    let _ = writeln!(md, "## The last window\n");
    let _ = writeln!(md, "Window {} ({}–{} s).", last.window, last.start_s, last.end_s);
    if let Some(why) = &last.uninformative {
        let _ = writeln!(md, "It informs nothing: {why}.");
    }
    for l in &last.laws {
        let ln_z = match (l.ln_z, l.ln_z_error) {
            (Some(ln_z), Some(error)) => format!(", ln Z = {ln_z:.1} ± {error:.1}"),
            _ => String::new(),
        };
        let _ = writeln!(
            md,
            "- {}: P = {:.3} (this window alone {:.3}{ln_z})",
            l.law, l.probability, l.window_probability
        );
    }
    if let Some(check) = &last.check {
        let _ = writeln!(md, "\nIts model choice, checked by re-simulation: {}.", check.verdict);
    }
    if let Some(epsilon) = last.epsilon {
        let sampler = if last.check.is_some() {
            "sampler of simulated strings"
        } else {
            "ABC"
        };
        let _ = writeln!(md, "\nThe window's {sampler} ended at ε = {epsilon:.5}.");
    }
    if let Some(advice) = &last.advice {
        let _ = writeln!(md, "\nAdvice: {}.", advice.words);
    }
    let _ = writeln!(md);
}
