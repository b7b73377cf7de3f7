//! The figure of a surface directory's report: the record's surface channels and the bit's
//! speed the surface implies, on the record's time axis.

use super::*;

/// What the surface figure draws (display units: s, rpm, the record's torque unit).
pub(crate) struct SurfaceFigure {
    pub time_s: Vec<f64>,
    pub surface_torque: Vec<f64>,
    pub torque_unit: &'static str,
    pub top_drive_rpm: Vec<f64>,
    /// The bit's predicted speed per sample: 5 %, median, 95 %, rpm.
    pub bit_rpm: Vec<[f64; 3]>,
}

/// The surface figure, rendered.
pub(crate) fn render_surface(input: &SurfaceFigure, draws: usize) -> Result<Rendered> {
    render_one(
        "fig01_surface_and_bit".into(),
        format!(
            "Top: the record's surface torque. Bottom: its top-drive speed (blue) and the bit's speed the surface \
             implies: the median (black) and 90 % band (grey) of {draws} posterior draws simulated on the record's clock."
        ),
        (FIGURE_SIZE.0, FIGURE_SIZE.1 + FIGURE_SIZE.1 / 2),
        input,
    )
}

impl Figure for SurfaceFigure {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult
    where
        DB::ErrorType: 'static,
    {
        let area = titled(root, "The surface and the bit")?;
        let (main, strip) = area.split_vertically(area.dim_in_pixel().1 - LEGEND_STRIP);
        let (top, bottom) = main.split_vertically(main.dim_in_pixel().1 * 2 / 5);
        let (t_lo, t_hi) = plot::extent(self.time_s.iter().copied()).unwrap_or((0.0, 1.0));
        let x = (t_lo, t_hi.max(t_lo + 1e-9));
        let (y_lo, y_hi) = plot::extent(self.surface_torque.iter().copied()).unwrap_or((0.0, 1.0));
        let mut chart = axes(&top, "", x, padded(y_lo, y_hi, 0.06))?;
        mesh(
            &mut chart,
            "time (s)",
            &format!("surface torque ({})", self.torque_unit),
        )?;
        chart.draw_series(LineSeries::new(
            self.time_s.iter().copied().zip(self.surface_torque.iter().copied()),
            BLACK.stroke_width(2),
        ))?;
        let speeds = self
            .top_drive_rpm
            .iter()
            .copied()
            .chain(self.bit_rpm.iter().flat_map(|q| [q[0], q[2]]));
        let (s_lo, s_hi) = plot::extent(speeds).unwrap_or((0.0, 1.0));
        let mut chart = axes(&bottom, "", x, padded(s_lo.min(0.0), s_hi, 0.06))?;
        mesh(&mut chart, "time (s)", "speed (rpm)")?;
        let mut band: Vec<(f64, f64)> = self.time_s.iter().zip(&self.bit_rpm).map(|(&t, q)| (t, q[2])).collect();
        band.extend(self.time_s.iter().zip(&self.bit_rpm).rev().map(|(&t, q)| (t, q[0])));
        chart.draw_series(std::iter::once(Polygon::new(band, band_color().filled())))?;
        chart.draw_series(LineSeries::new(
            self.time_s.iter().copied().zip(self.top_drive_rpm.iter().copied()),
            VALIDATION.stroke_width(2),
        ))?;
        chart.draw_series(LineSeries::new(
            self.time_s.iter().zip(&self.bit_rpm).map(|(&t, q)| (t, q[1])),
            BLACK.stroke_width(2),
        ))?;
        legend_row(
            &strip,
            &[
                (Swatch::Line(VALIDATION), "top-drive speed".into()),
                (Swatch::Line(BLACK), "bit speed, median".into()),
                (Swatch::Band, "bit speed, 90 % band".into()),
            ],
        )
    }
}
