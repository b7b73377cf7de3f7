//! The record with the least-squares fits (figure 1) and the posterior predictive envelopes
//! (figure 7).

use super::*;

/// Figure 1: the data and each law's least-squares fit.
pub(super) fn render_data_and_fits(p: &Prepared, shared: &Shared) -> Result<Rendered> {
    let fits = DataFits {
        cal: shared.cal.clone(),
        val: shared.val.clone(),
        unit: p.unit,
        curves: p
            .input
            .fits
            .iter()
            .map(|f| {
                let params = p.display(f.law, &f.params_si);
                let curve = shared
                    .grid
                    .iter()
                    .map(|&w| (rpm(w), f.law.torque(&params, w, 1.0)))
                    .collect();
                (f.law, curve, format!("{} (ρ = {:.4})", f.law, f.rho))
            })
            .collect(),
    };
    let thinning_note = &shared.thinning_note;
    render_one(
        "fig01_data_and_fits".into(),
        format!(
            "Field data (calibration: red circles, validation: blue dots){thinning_note} and the least-squares \
             fit of each law, torque on bit against bit speed."
        ),
        FIGURE_SIZE,
        &fits,
    )
}

/// Figure 7: the reference run's predictive envelopes over the data, up to four laws.
pub(super) fn render_envelopes(p: &Prepared, shared: &Shared) -> Result<Rendered> {
    let reference = &p.runs[0];
    let envelopes = Envelopes {
        panels: reference
            .summary
            .laws
            .iter()
            .filter_map(|ls| {
                let prob = reference
                    .probabilities
                    .iter()
                    .find(|x| x.0 == ls.law)
                    .map_or(0.0, |x| x.1);
                envelope_panel(&reference.particles, ls.law, prob, &shared.grid, p.torque_scale)
            })
            .take(4)
            .collect(),
        cal: shared.cal.clone(),
        val: shared.val.clone(),
        unit: p.unit,
        run: reference.run.label.clone(),
    };
    render_one(
        "fig07_envelopes".into(),
        format!(
            "98 % predictive envelopes of each law's torque (grey band) and its median (black) from the last \
             population of {}, with the calibration (red circles) and validation (blue dots) data{}.",
            reference.run.label, shared.thinning_note
        ),
        FIGURE_SIZE,
        &envelopes,
    )
}

/// The panel of `law`'s 98 % predictive envelope of `particles` (SI) over `grid` (rad/s), its
/// torques divided by `torque_scale` (N·m per display unit); `None` without particles of `law`.
pub(super) fn envelope_panel(
    particles: &[crate::abc::Particle],
    law: Law,
    probability: f64,
    grid: &[f64],
    torque_scale: f64,
) -> Option<EnvelopePanel> {
    let e = predictive_envelope(particles, law, grid, ENVELOPE_LEVEL, 1.0)?;
    let band = e
        .speed_rad_s
        .iter()
        .enumerate()
        .map(|(i, &w)| {
            (
                rpm(w),
                e.lower[i] / torque_scale,
                e.median[i] / torque_scale,
                e.upper[i] / torque_scale,
            )
        })
        .collect();
    Some((law, probability, band))
}

/// Figure 1: the record and the least-squares curves.
struct DataFits {
    cal: Vec<(f64, f64)>,
    val: Vec<(f64, f64)>,
    unit: &'static str,
    curves: Vec<FitCurve>,
}

impl Figure for DataFits {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult
    where
        DB::ErrorType: 'static,
    {
        let area = titled(root, "Field data and least-squares fits")?;
        let all = self.cal.iter().chain(&self.val).copied();
        let (x_hi, (y_lo, y_hi)) = (
            plot::extent(all.clone().map(|p| p.0)).map_or(1.0, |e| e.1),
            plot::extent(
                all.map(|p| p.1)
                    .chain(self.curves.iter().flat_map(|c| c.1.iter().map(|p| p.1))),
            )
            .unwrap_or((0.0, 1.0)),
        );
        let (y_lo, y_hi) = padded(y_lo, y_hi, 0.04);
        let mut chart = axes(&area, "", (0.0, x_hi * 1.02), (y_lo, y_hi))?;
        mesh(&mut chart, "bit speed (rpm)", &format!("torque on bit ({})", self.unit))?;
        draw_points(&mut chart, &self.cal, &self.val)?;
        for (law, curve, label) in &self.curves {
            let c = law_color(*law);
            chart
                .draw_series(LineSeries::new(curve.iter().copied(), c.stroke_width(3)))?
                .label(label.as_str())
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(3)));
        }
        legend_box(&mut chart, SeriesLabelPosition::UpperRight)
    }
}

/// Figure 7: predictive envelopes with the data, one panel per law.
pub(super) struct Envelopes {
    /// (law, probability, [(rpm, lower, median, upper)]) in the display unit.
    pub(super) panels: Vec<EnvelopePanel>,
    pub(super) cal: Vec<(f64, f64)>,
    pub(super) val: Vec<(f64, f64)>,
    pub(super) unit: &'static str,
    pub(super) run: String,
}

impl Figure for Envelopes {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult
    where
        DB::ErrorType: 'static,
    {
        let area = titled(root, &format!("98 % predictive envelopes, {}", self.run))?;
        let (main, strip) = area.split_vertically(area.dim_in_pixel().1 - LEGEND_STRIP);
        let points = || self.cal.iter().chain(&self.val).copied();
        let x_hi = plot::extent(points().map(|p| p.0)).map_or(1.0, |e| e.1);
        let (y_lo, y_hi) = plot::extent(
            points()
                .map(|p| p.1)
                .chain(self.panels.iter().flat_map(|p| p.2.iter().flat_map(|b| [b.1, b.3]))),
        )
        .unwrap_or((0.0, 1.0));
        let (y_lo, y_hi) = padded(y_lo, y_hi, 0.04);
        for (panel, (law, prob, band)) in panels(&main, self.panels.len()).iter().zip(&self.panels) {
            let mut chart = axes(
                panel,
                &format!("{law} (P = {prob:.2})"),
                (0.0, x_hi * 1.02),
                (y_lo, y_hi),
            )?;
            mesh(&mut chart, "bit speed (rpm)", &format!("torque on bit ({})", self.unit))?;
            let mut polygon: Vec<(f64, f64)> = band.iter().map(|b| (b.0, b.3)).collect();
            polygon.extend(band.iter().rev().map(|b| (b.0, b.1)));
            let (cal, val) = (
                plot::thinned(&self.cal, ENVELOPE_POINTS),
                plot::thinned(&self.val, ENVELOPE_POINTS),
            );
            draw_points(&mut chart, &cal, &val)?;
            chart.draw_series(std::iter::once(Polygon::new(polygon, band_color().filled())))?;
            chart.draw_series(LineSeries::new(band.iter().map(|b| (b.0, b.2)), BLACK.stroke_width(2)))?;
        }
        legend_row(
            &strip,
            &[
                (Swatch::Band, "98 % envelope".into()),
                (Swatch::Line(BLACK), "median".into()),
                (Swatch::Circle(CALIBRATION), "calibration data".into()),
                (Swatch::Dot(VALIDATION), "validation data".into()),
            ],
        )
    }
}
