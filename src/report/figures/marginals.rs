//! The posterior's marginals per parameter and the correlations between parameters.

use super::*;

/// Figures 5: posterior marginals, one figure per law with particles, runs overlaid.
pub(super) fn render_marginals(p: &Prepared, laws: &[Law]) -> Result<Vec<Rendered>> {
    let mut out = Vec::new();
    for &law in laws {
        if let Some(m) = Marginals::new(p, law) {
            out.push(render_one(
                format!("fig05_marginals_{law}"),
                format!(
                    "Posterior marginal densities of the parameters of {law} (weighted histograms of the last \
                     population, one outline per run)."
                ),
                FIGURE_SIZE,
                &m,
            )?);
        }
    }
    Ok(out)
}

/// Figures 6: the reference run's correlation matrices, one per law with enough particles.
pub(super) fn render_correlations(p: &Prepared) -> Result<Vec<Rendered>> {
    let reference = &p.runs[0];
    let mut out = Vec::new();
    for ls in &reference.summary.laws {
        if ls.count >= MIN_CORRELATION_PARTICLES {
            let c = Correlation::new(p, ls.law);
            out.push(render_one(
                format!("fig06_correlation_{}", ls.law),
                format!(
                    "Correlations of the parameters of {} ({}): weighted histograms on the diagonal, {} particles \
                     of the last population below it, weighted Pearson coefficients above it.",
                    ls.law,
                    reference.run.label,
                    c.scatter.len()
                ),
                CORRELATION_SIZE,
                &c,
            )?);
        }
    }
    Ok(out)
}

/// Figure 5: one law's posterior marginals, one panel per parameter, runs overlaid.
struct Marginals {
    law: Law,
    /// Per parameter: axis name, range, and per run (index, densities).
    params: Vec<MarginalPanel>,
    runs: Vec<String>,
}

impl Marginals {
    /// `None` when no run's last population holds the law.
    fn new(p: &Prepared, law: Law) -> Option<Self> {
        let members: Vec<(usize, Vec<&crate::abc::Particle>)> = p
            .runs
            .iter()
            .enumerate()
            .map(|(i, r)| (i, r.last.particles.iter().filter(|q| q.law == law).collect::<Vec<_>>()))
            .filter(|(_, m)| !m.is_empty())
            .collect();
        if members.is_empty() {
            return None;
        }
        let display: Vec<(usize, Vec<Vec<f64>>, Vec<f64>)> = members
            .iter()
            .map(|(i, m)| {
                (
                    *i,
                    m.iter().map(|q| p.display(law, &q.params)).collect(),
                    m.iter().map(|q| q.weight).collect(),
                )
            })
            .collect();
        let params = law
            .params()
            .iter()
            .enumerate()
            .map(|(j, spec)| {
                let range = plot::extent(display.iter().flat_map(|d| d.1.iter().map(|v| v[j]))).unwrap_or((0.0, 1.0));
                let range = padded(range.0, range.1, 0.0);
                let hists = display
                    .iter()
                    .map(|(i, values, weights)| {
                        let column: Vec<f64> = values.iter().map(|v| v[j]).collect();
                        (*i, stats::density_histogram(&column, weights, range.0, range.1, BINS))
                    })
                    .collect();
                (format!("{} ({})", spec.name, plot::unit(spec, p.unit)), range, hists)
            })
            .collect();
        Some(Self {
            law,
            params,
            runs: p.runs.iter().map(|r| r.run.label.clone()).collect(),
        })
    }
}

/// The outline of a histogram over [lo, hi] as a closed step polygon along y = 0.
fn step_outline(lo: f64, hi: f64, density: &[f64]) -> Vec<(f64, f64)> {
    let width = (hi - lo) / density.len() as f64;
    let mut pts = vec![(lo, 0.0)];
    for (k, &d) in density.iter().enumerate() {
        pts.push((lo + k as f64 * width, d));
        pts.push((lo + (k + 1) as f64 * width, d));
    }
    pts.push((hi, 0.0));
    pts
}

impl Figure for Marginals {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult
    where
        DB::ErrorType: 'static,
    {
        let area = titled(root, &format!("Posterior marginals of {}", self.law))?;
        let (main, strip) = area.split_vertically(area.dim_in_pixel().1 - LEGEND_STRIP);
        for (panel, (name, range, hists)) in panels(&main, self.params.len()).iter().zip(&self.params) {
            let top = hists.iter().flat_map(|h| h.1.iter().copied()).fold(0.0, f64::max);
            let y_top = (top * 1.08).max(1e-300);
            let (x_power, y_power) = (plot::axis_power(range.0, range.1), plot::axis_power(0.0, y_top));
            let mut chart = ChartBuilder::on(panel)
                .margin(10)
                .margin_right(22)
                .x_label_area_size(58)
                .y_label_area_size(84)
                .build_cartesian_2d(range.0..range.1, 0.0..y_top)?;
            chart
                .configure_mesh()
                .x_desc(plot::in_power(name, x_power))
                .y_desc(plot::in_power("density", y_power))
                .axis_desc_style(font(AXIS - 2))
                .label_style(font(TICK - 3))
                .max_light_lines(0)
                .bold_line_style(GRID)
                .x_labels(4)
                .y_labels(5)
                .x_label_formatter(&|x| plot::tick_in(*x, x_power))
                .y_label_formatter(&|y| plot::tick_in(*y, y_power))
                .draw()?;
            for (i, density) in hists {
                let c = run_color(*i);
                let outline = step_outline(range.0, range.1, density);
                chart.draw_series(std::iter::once(Polygon::new(outline.clone(), c.mix(0.12).filled())))?;
                chart.draw_series(LineSeries::new(outline, c.stroke_width(2)))?;
            }
        }
        let present: Vec<usize> = self
            .params
            .first()
            .map_or(Vec::new(), |p| p.2.iter().map(|h| h.0).collect());
        let items: Vec<(Swatch, String)> = present
            .iter()
            .map(|&i| (Swatch::Line(run_color(i)), self.runs[i].clone()))
            .collect();
        legend_row(&strip, &items)
    }
}

/// Figure 6: correlation matrix of one law's parameters (reference run).
struct Correlation {
    law: Law,
    run: String,
    names: Vec<String>,
    /// All particles of the law, display units, and their weights.
    columns: Vec<Vec<f64>>,
    weights: Vec<f64>,
    /// The scatter's particles (parameter vectors, display units).
    scatter: Vec<Vec<f64>>,
}

impl Correlation {
    fn new(p: &Prepared, law: Law) -> Self {
        let r = &p.runs[0];
        let members: Vec<&crate::abc::Particle> = r.last.particles.iter().filter(|q| q.law == law).collect();
        let columns = (0..law.n_params())
            .map(|j| members.iter().map(|q| p.display(law, &q.params)[j]).collect())
            .collect();
        Self {
            law,
            run: r.run.label.clone(),
            names: law
                .params()
                .iter()
                .map(|s| format!("{} ({})", s.name, plot::unit(s, p.unit)))
                .collect(),
            columns,
            weights: members.iter().map(|q| q.weight).collect(),
            scatter: posterior::law_samples(&r.last.particles, law, MAX_SCATTER)
                .into_iter()
                .map(|q| p.display(law, &q.params))
                .collect(),
        }
    }
}

/// Diverging colour of a correlation r ∈ [−1, 1]: blue for negative, red for positive.
fn correlation_color(r: f64) -> RGBColor {
    let t = r.abs().min(1.0);
    let (tr, tg, tb) = if r < 0.0 {
        (33.0, 102.0, 172.0)
    } else {
        (178.0, 24.0, 43.0)
    };
    let mix = |c: f64| (255.0 + t * 0.75 * (c - 255.0)).round() as u8;
    RGBColor(mix(tr), mix(tg), mix(tb))
}

impl Figure for Correlation {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult
    where
        DB::ErrorType: 'static,
    {
        let area = titled(
            root,
            &format!("Correlations of the parameters of {}, {}", self.law, self.run),
        )?;
        let d = self.columns.len();
        let ranges: Vec<(f64, f64)> = self
            .columns
            .iter()
            .map(|c| {
                let (lo, hi) = plot::extent(c.iter().copied()).unwrap_or((0.0, 1.0));
                padded(lo, hi, 0.04)
            })
            .collect();
        let cells = area.margin(0, 16, 0, 0).split_evenly((d, d));
        // Smaller text where six parameters share the width.
        let small = if d <= 4 { TICK - 2 } else { TICK - 6 };
        for (index, cell) in cells.iter().enumerate() {
            let (i, j) = (index / d, index % d);
            let (x_range, y_range) = if i == j {
                let h = stats::density_histogram(&self.columns[j], &self.weights, ranges[j].0, ranges[j].1, 30);
                (
                    ranges[j],
                    (0.0, h.iter().copied().fold(0.0, f64::max).max(1e-300) * 1.1),
                )
            } else if i > j {
                (ranges[j], ranges[i])
            } else {
                ((0.0, 1.0), (0.0, 1.0))
            };
            let mut chart = ChartBuilder::on(cell)
                .margin(3)
                .x_label_area_size(if i + 1 == d { 52 } else { 6 })
                .y_label_area_size(if j == 0 { 76 } else { 6 })
                .build_cartesian_2d(x_range.0..x_range.1, y_range.0..y_range.1)?;
            // The parameters' axes count in a power of ten where their numbers are long.
            let x_power = plot::axis_power(ranges[j].0, ranges[j].1);
            let y_power = if i > j {
                plot::axis_power(ranges[i].0, ranges[i].1)
            } else {
                0
            };
            let x_tick = |x: &f64| plot::tick_in(*x, x_power);
            let y_tick = |y: &f64| plot::tick_in(*y, y_power);
            let mut mesh = chart.configure_mesh();
            mesh.max_light_lines(0)
                .disable_mesh()
                .label_style(font(small))
                .axis_desc_style(font(small + 1))
                .x_labels(3)
                .y_labels(3)
                .x_label_formatter(&x_tick)
                .y_label_formatter(&y_tick);
            if i + 1 == d {
                mesh.x_desc(plot::in_power(&self.names[j], x_power));
            } else {
                mesh.x_labels(0);
            }
            if j == 0 && i != 0 {
                mesh.y_desc(plot::in_power(&self.names[i], y_power));
            } else if j == 0 {
                mesh.y_desc(format!("density of {}", self.names[0].split(' ').next().unwrap_or("")));
            }
            if j != 0 || i == j {
                mesh.y_labels(0);
            }
            mesh.draw()?;
            if i == j {
                let h = stats::density_histogram(&self.columns[j], &self.weights, ranges[j].0, ranges[j].1, 30);
                let outline = step_outline(ranges[j].0, ranges[j].1, &h);
                chart.draw_series(std::iter::once(Polygon::new(
                    outline.clone(),
                    law_color(self.law).mix(0.45).filled(),
                )))?;
                chart.draw_series(LineSeries::new(outline, law_color(self.law).stroke_width(1)))?;
            } else if i > j {
                chart.draw_series(
                    self.scatter
                        .iter()
                        .map(|v| Circle::new((v[j], v[i]), 2, law_color(self.law).mix(0.6).filled())),
                )?;
            } else {
                let r = stats::weighted_correlation(&self.columns[i], &self.columns[j], &self.weights);
                let fill = r.map_or(RGBColor(240, 240, 240), correlation_color);
                chart.draw_series(std::iter::once(Rectangle::new([(0.0, 0.0), (1.0, 1.0)], fill.filled())))?;
                chart.draw_series(std::iter::once(Text::new(
                    r.map_or("r undefined".into(), |r| format!("r = {r:.2}")),
                    (0.5, 0.5),
                    font(TICK + 1).pos(Pos::new(HPos::Center, VPos::Center)),
                )))?;
            }
        }
        Ok(())
    }
}
