//! The figures of an evidence directory's report: each law's 98 % posterior predictive
//! envelope over the samples, and the posterior law probabilities.

use super::fits::{Envelopes, envelope_panel};
use super::*;
use crate::abc::Particle;
use crate::run::evidence::dir::StoredSamples;

/// What the evidence's figures are drawn from.
pub(crate) struct EvidenceFigures<'a> {
    /// The posterior (SI), every law's sets weighed by its P(m | y).
    pub particles: &'a [Particle],
    /// Each law and its P(m | y), in the evidence's order.
    pub laws: Vec<(Law, f64)>,
    /// Each law's ln Z and its Monte-Carlo error, in the same order.
    pub ln_z: Vec<(f64, f64)>,
    pub samples: &'a StoredSamples,
    /// Where the evidence scaled each torque by WOB / W_ref: that W_ref, kN.
    pub w_ref_kn: Option<f64>,
}

/// The evidence's two figures.
pub(crate) fn render_evidence(input: &EvidenceFigures) -> Result<Vec<Rendered>> {
    let samples = input.samples;
    let speeds = samples.calibration.iter().chain(&samples.validation).map(|s| s.0);
    let (lo, hi) = super::super::plot::extent(speeds).unwrap_or((0.0, 1.0));
    let grid = speed_grid(lo, hi, CURVE_POINTS);
    let points = |set: &[(f64, f64)]| set.iter().map(|&(w, t)| (super::super::rpm(w), t)).collect::<Vec<_>>();
    let envelopes = Envelopes {
        panels: input
            .laws
            .iter()
            .filter_map(|&(law, probability)| {
                envelope_panel(input.particles, law, probability, &grid, samples.unit.newton_metres())
            })
            .take(4)
            .collect(),
        cal: points(&samples.calibration),
        val: points(&samples.validation),
        unit: samples.unit.label(),
        run: "the evidence's posterior".into(),
    };
    let scaled = input.w_ref_kn.map_or(String::new(), |w| {
        format!(" The torque is the laws' at W_ref = {w:.1} kN (the evidence scaled each torque by WOB / W_ref).")
    });
    let evidence = LnZ {
        laws: input
            .laws
            .iter()
            .zip(&input.ln_z)
            .map(|(&(law, probability), &(ln_z, error))| (law, ln_z, error, probability))
            .collect(),
    };
    Ok(vec![
        render_one(
            "fig01_evidence_envelopes".into(),
            format!(
                "98 % posterior predictive envelopes of each law's torque (grey band) and its median (black), \
                 with the calibration (red circles) and validation (blue dots) samples.{scaled}"
            ),
            FIGURE_SIZE,
            &envelopes,
        )?,
        render_one(
            "fig02_evidence".into(),
            "Each law's ln Z less the largest (nats), with twice its Monte-Carlo error as a bar, and its P(m | y): \
             a law a few nats below the first is already far less probable."
                .into(),
            FIGURE_SIZE,
            &evidence,
        )?,
    ])
}

/// The evidence figure: each law's ln Z relative to the largest, ± twice its error.
struct LnZ {
    /// (law, ln Z, its Monte-Carlo error, P(m | y)).
    laws: Vec<(Law, f64, f64, f64)>,
}

impl Figure for LnZ {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult
    where
        DB::ErrorType: 'static,
    {
        let area = titled(root, "Model evidence")?;
        let top = self.laws.iter().map(|l| l.1).fold(f64::NEG_INFINITY, f64::max);
        let relative: Vec<(f64, f64)> = self.laws.iter().map(|l| (l.1 - top, 2.0 * l.2)).collect();
        let low = relative.iter().map(|(d, e)| d - e).fold(0.0, f64::min);
        let high = relative.iter().map(|(_, e)| *e).fold(0.0, f64::max);
        let pad = 0.12 * (high - low).max(1.0);
        let n = self.laws.len().max(1) as f64;
        let mut chart = axes(&area, "", (-0.6, n - 0.4), (low - pad, high + pad))?;
        let names: Vec<String> = self.laws.iter().map(|l| l.0.name().to_string()).collect();
        chart
            .configure_mesh()
            .x_desc("law")
            .y_desc("ln Z − largest ln Z (nats)")
            .axis_desc_style(font(AXIS))
            .label_style(font(TICK))
            .max_light_lines(0)
            .bold_line_style(GRID)
            .disable_x_mesh()
            .x_labels(self.laws.len().max(2))
            .x_label_formatter(&|x| {
                let k = x.round();
                if (x - k).abs() < 1e-9 && k >= 0.0 {
                    names.get(k as usize).cloned().unwrap_or_default()
                } else {
                    String::new()
                }
            })
            .y_labels(8)
            .y_label_formatter(&|y| super::super::plot::short(*y))
            .draw()?;
        for (k, (&(law, _, _, probability), &(d, e))) in self.laws.iter().zip(&relative).enumerate() {
            let x = k as f64;
            let colour = law_color(law);
            chart.draw_series(std::iter::once(ErrorBar::new_vertical(
                x,
                d - e,
                d,
                d + e,
                colour.stroke_width(3),
                18,
            )))?;
            chart.draw_series(std::iter::once(Circle::new((x, d), 7, colour.filled())))?;
            chart.draw_series(std::iter::once(Text::new(
                format!("P = {probability:.3}"),
                (x + 0.08, d + e + 0.04 * (high - low + 2.0 * pad)),
                font(LEGEND),
            )))?;
        }
        Ok(())
    }
}
