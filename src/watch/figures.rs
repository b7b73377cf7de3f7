//! A watch along the record: law probabilities, each law's parameters and the risk of
//! stick-slip, window by window, with the changes of formation marked.

use super::Update;
use super::store::StoredWatch;
use crate::error::Result;
use crate::laws::Law;
use crate::report::FIGURE_SIZE;
use crate::report::figures::{
    Chart, LEGEND_STRIP, Rendered, Swatch, axes, legend_row, mesh, panels, render_one, titled,
};
use crate::report::plot::{self, DrawResult, Figure, extent, law_color, padded};
use plotters::coord::Shift;
use plotters::element::DashedPathElement;
use plotters::prelude::*;

/// Grey of the windows that informed nothing.
const UNINFORMATIVE: RGBColor = RGBColor(215, 215, 215);

/// Renders the watch's figures: probabilities, P(unstable) and advice, then one figure of
/// parameters per law.
pub(super) fn render(watch: &StoredWatch) -> Result<Vec<Rendered>> {
    let along = Along::new(watch);
    let size = FIGURE_SIZE;
    let mut out = vec![
        render_one(
            "watch-probabilities".into(),
            format!(
                "Law probabilities along the record, carried from window to window (forgetting {}, floor {}); \
                 each column is a window, at its end time; dashed lines: changes of formation declared; grey: \
                 windows that inform nothing.",
                watch.meta.settings["forgetting"], watch.meta.settings["floor"]
            ),
            size,
            &ProbabilitiesAlong { along: &along },
        )?,
        render_one(
            "watch-risk".into(),
            format!(
                "P(stick-slip) at each window's operating point under the mixture posterior ({}), \
                 against the risk of {}; below: the top-drive speed and the nearest speed below the \
                 risk at the same weight on bit.",
                super::store::criterion_words(&watch.meta.settings),
                watch.meta.settings["risk"]
            ),
            size,
            &RiskAlong { along: &along },
        )?,
    ];
    for &law in &along.laws {
        out.push(render_one(
            format!("watch-parameters-{law}"),
            format!(
                "{law}'s parameters along the record: posterior mean (line) and 1–99 % interval (band) of each \
                 window, in {}; dashed lines: changes of formation.",
                watch.meta.torque_unit.label()
            ),
            size,
            &ParametersAlong { along: &along, law },
        )?);
    }
    Ok(out)
}

/// What the figures read off the stored windows.
struct Along<'a> {
    updates: &'a [Update],
    laws: Vec<Law>,
    /// Half the step: each window's column is its end ± this.
    half_step: f64,
    /// The record's time span of the windows' ends, padded by a half step.
    x: (f64, f64),
    /// End times of the windows that declared a change.
    changes: Vec<f64>,
    torque_unit: &'static str,
    /// The risk the advice keeps below.
    risk: Option<f64>,
}

impl<'a> Along<'a> {
    fn new(watch: &'a StoredWatch) -> Self {
        let updates = &watch.updates[..];
        let mut laws: Vec<Law> = Vec::new();
        for u in updates {
            for l in &u.laws {
                if !laws.contains(&l.law) {
                    laws.push(l.law);
                }
            }
        }
        let half_step = watch.meta.step_s / 2.0;
        let ends = extent(updates.iter().map(|u| u.end_s)).unwrap_or((0.0, 1.0));
        Self {
            updates,
            laws,
            half_step,
            x: (ends.0 - half_step, ends.1 + half_step),
            changes: updates.iter().filter(|u| u.change).map(|u| u.end_s).collect(),
            torque_unit: watch.meta.torque_unit.label(),
            risk: watch.meta.settings["risk"].as_f64(),
        }
    }

    /// The changes as dashed vertical lines over the chart's height.
    fn draw_changes<DB: DrawingBackend>(&self, chart: &mut Chart<'_, DB>) -> DrawResult
    where
        DB::ErrorType: 'static,
    {
        let y = chart.y_range();
        for &t in &self.changes {
            chart.draw_series(std::iter::once(DashedPathElement::new(
                vec![(t, y.start), (t, y.end)],
                8,
                6,
                BLACK.stroke_width(2),
            )))?;
        }
        Ok(())
    }

    /// The uninformative windows as grey columns.
    fn draw_uninformative<DB: DrawingBackend>(&self, chart: &mut Chart<'_, DB>) -> DrawResult
    where
        DB::ErrorType: 'static,
    {
        let y = chart.y_range();
        chart.draw_series(self.updates.iter().filter(|u| u.uninformative.is_some()).map(|u| {
            Rectangle::new(
                [(u.end_s - self.half_step, y.start), (u.end_s + self.half_step, y.end)],
                UNINFORMATIVE.filled(),
            )
        }))?;
        Ok(())
    }
}

struct ProbabilitiesAlong<'a> {
    along: &'a Along<'a>,
}

impl Figure for ProbabilitiesAlong<'_> {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult
    where
        DB::ErrorType: 'static,
    {
        let a = self.along;
        let area = titled(root, "Law probabilities along the record")?;
        let (plot_area, legend) = area.split_vertically(area.dim_in_pixel().1 - LEGEND_STRIP);
        let mut chart = axes(&plot_area, "", a.x, (0.0, 1.0))?;
        mesh(&mut chart, "record time at the window's end (s)", "P(law), carried")?;
        a.draw_uninformative(&mut chart)?;
        for u in a.updates {
            let mut below = 0.0;
            for law in &a.laws {
                let Some(l) = u.laws.iter().find(|l| l.law == *law) else {
                    continue;
                };
                let top = (below + l.probability).min(1.0);
                chart.draw_series(std::iter::once(Rectangle::new(
                    [(u.end_s - a.half_step, below), (u.end_s + a.half_step, top)],
                    law_color(*law).filled(),
                )))?;
                below = top;
            }
        }
        a.draw_changes(&mut chart)?;
        let mut items: Vec<(Swatch, String)> = a
            .laws
            .iter()
            .map(|l| (Swatch::Bar(law_color(*l)), l.to_string()))
            .collect();
        items.push((Swatch::Dashed(BLACK), "change of formation".into()));
        items.push((Swatch::Bar(UNINFORMATIVE), "uninformative".into()));
        legend_row(&legend, &items)
    }
}

struct RiskAlong<'a> {
    along: &'a Along<'a>,
}

impl Figure for RiskAlong<'_> {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult
    where
        DB::ErrorType: 'static,
    {
        let a = self.along;
        let area = titled(root, "Risk of stick-slip and the advice along the record")?;
        let (plot_area, legend) = area.split_vertically(area.dim_in_pixel().1 - LEGEND_STRIP);
        let (top, bottom) = plot_area.split_vertically(plot_area.dim_in_pixel().1 / 2);
        let advised: Vec<(f64, &crate::watch::Advice)> = a
            .updates
            .iter()
            .filter_map(|u| u.advice.as_ref().map(|v| (u.end_s, v)))
            .collect();

        let mut chart = axes(&top, "", a.x, (0.0, 1.0))?;
        mesh(&mut chart, "", "P(stick-slip)")?;
        a.draw_uninformative(&mut chart)?;
        if let Some(risk) = a.risk {
            chart.draw_series(std::iter::once(DashedPathElement::new(
                vec![(a.x.0, risk), (a.x.1, risk)],
                4,
                4,
                RISK.stroke_width(1),
            )))?;
        }
        let p: Vec<(f64, f64)> = advised.iter().map(|(t, v)| (*t, v.p_unstable)).collect();
        chart.draw_series(LineSeries::new(p.iter().copied(), RISK.stroke_width(2)))?;
        chart.draw_series(p.iter().map(|&q| Circle::new(q, 4, RISK.filled())))?;
        a.draw_changes(&mut chart)?;

        let speeds = advised
            .iter()
            .flat_map(|(_, v)| std::iter::once(v.omega_rpm).chain(v.safe_omega_rpm))
            .collect::<Vec<_>>();
        let (lo, hi) = extent(speeds).unwrap_or((0.0, 100.0));
        let mut chart = axes(&bottom, "", a.x, padded(lo.min(0.0), hi, 0.08))?;
        mesh(
            &mut chart,
            "record time at the window's end (s)",
            "top-drive speed (rpm)",
        )?;
        a.draw_uninformative(&mut chart)?;
        chart.draw_series(LineSeries::new(
            advised.iter().map(|(t, v)| (*t, v.omega_rpm)),
            BLACK.stroke_width(2),
        ))?;
        chart.draw_series(
            advised
                .iter()
                .filter(|(_, v)| v.safe_omega_rpm != Some(v.omega_rpm))
                .filter_map(|(t, v)| v.safe_omega_rpm.map(|o| Circle::new((*t, o), 5, SAFE.stroke_width(2)))),
        )?;
        a.draw_changes(&mut chart)?;
        legend_row(
            &legend,
            &[
                (Swatch::Line(RISK), "P(stick-slip) at the operating point".into()),
                (Swatch::Dashed(RISK), "risk".into()),
                (Swatch::Line(BLACK), "top-drive speed".into()),
                (Swatch::Circle(SAFE), "nearest speed below the risk".into()),
                (Swatch::Dashed(BLACK), "change".into()),
            ],
        )
    }
}

/// The risk's colour and the advised speeds' (neither a law's colour).
const RISK: RGBColor = RGBColor(200, 30, 45);
const SAFE: RGBColor = RGBColor(20, 110, 200);

struct ParametersAlong<'a> {
    along: &'a Along<'a>,
    law: Law,
}

impl Figure for ParametersAlong<'_> {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult
    where
        DB::ErrorType: 'static,
    {
        let a = self.along;
        let law = self.law;
        let area = titled(root, &format!("{law}'s parameters along the record"))?;
        let specs = law.params();
        let color = law_color(law);
        for (j, (panel, spec)) in panels(&area, specs.len()).iter().zip(specs).enumerate() {
            // (end time, mean, q01, q99) of the windows where the law was weighed.
            let points: Vec<(f64, f64, f64, f64)> = a
                .updates
                .iter()
                .filter_map(|u| {
                    let l = u.laws.iter().find(|l| l.law == law)?;
                    Some((u.end_s, *l.mean.get(j)?, *l.q01.get(j)?, *l.q99.get(j)?))
                })
                .filter(|p| p.1.is_finite() && p.2.is_finite() && p.3.is_finite())
                .collect();
            let (lo, hi) = extent(points.iter().flat_map(|p| [p.2, p.3])).unwrap_or((0.0, 1.0));
            let mut chart = axes(panel, spec.name, a.x, padded(lo, hi, 0.08))?;
            mesh(
                &mut chart,
                "window end (s)",
                &format!("{} ({})", spec.name, plot::unit(spec, a.torque_unit)),
            )?;
            a.draw_uninformative(&mut chart)?;
            // The band in runs of consecutive windows, so that a gap is not bridged.
            for run in points.chunk_by(|p, q| q.0 - p.0 <= 2.0 * a.half_step * 1.5) {
                let mut outline: Vec<(f64, f64)> = run.iter().map(|p| (p.0, p.3)).collect();
                outline.extend(run.iter().rev().map(|p| (p.0, p.2)));
                chart.draw_series(std::iter::once(Polygon::new(outline, color.mix(0.25).filled())))?;
                chart.draw_series(LineSeries::new(run.iter().map(|p| (p.0, p.1)), color.stroke_width(2)))?;
            }
            a.draw_changes(&mut chart)?;
        }
        Ok(())
    }
}
