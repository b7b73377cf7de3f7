//! The law probabilities: per population, the last population's per run, and the tolerance
//! schedule.

use super::*;

/// Figure 2: model probabilities per population, one panel per run.
pub(super) fn render_model_probabilities(p: &Prepared, laws: &[Law]) -> Result<Rendered> {
    let probabilities = ModelProbabilities {
        laws: laws.to_vec(),
        runs: p
            .runs
            .iter()
            .map(|r| {
                let per_population = r
                    .run
                    .populations
                    .iter()
                    .map(|pop| {
                        super::super::record_probabilities(pop, laws)
                            .into_iter()
                            .map(|x| x.1)
                            .collect()
                    })
                    .collect();
                (r.run.label.clone(), per_population)
            })
            .collect(),
    };
    render_one(
        "fig02_model_probabilities".into(),
        "Model probabilities P(M_k | y) per population, one panel per prior width δ.".into(),
        FIGURE_SIZE,
        &probabilities,
    )
}

/// Figure 3: final model probabilities; 0* marks those that are 0 by construction.
pub(super) fn render_final_probabilities(p: &Prepared, laws: &[Law]) -> Result<Rendered> {
    let last = FinalProbabilities {
        laws: laws.to_vec(),
        runs: p
            .runs
            .iter()
            .map(|r| {
                let probs = super::super::record_probabilities(r.last, laws)
                    .into_iter()
                    .map(|x| x.1)
                    .collect();
                (r.run.label.clone(), probs)
            })
            .collect(),
        zero_by_construction: p
            .runs
            .iter()
            .map(|r| super::super::record_zero_by_construction(r.last, laws))
            .collect(),
    };
    let any_zero = last.zero_by_construction.iter().flatten().any(|&z| z);
    render_one(
        "fig03_final_probabilities".into(),
        if any_zero {
            format!(
                "Model probabilities at the last population of each run. {}",
                super::super::BY_CONSTRUCTION_NOTE
            )
        } else {
            "Model probabilities at the last population of each run.".into()
        },
        FIGURE_SIZE,
        &last,
    )
}

/// Figure 4: the tolerance per population, runs overlaid.
pub(super) fn render_tolerance(p: &Prepared) -> Result<Rendered> {
    let tolerance = Tolerance {
        runs: p
            .runs
            .iter()
            .map(|r| {
                let eps = r
                    .run
                    .populations
                    .iter()
                    .filter_map(|pop| pop.record.epsilon.map(|e| (pop.record.index as f64, e)))
                    .collect();
                (r.run.label.clone(), eps)
            })
            .collect(),
    };
    render_one(
        "fig04_tolerance".into(),
        "Tolerance ε_g per population (population 0, ε = ∞, is the prior).".into(),
        FIGURE_SIZE,
        &tolerance,
    )
}

/// Figure 2: P(law) per population, one panel per run.
struct ModelProbabilities {
    laws: Vec<Law>,
    /// (label, probabilities[population][law]).
    runs: Vec<(String, Vec<Vec<f64>>)>,
}

fn law_legend(laws: &[Law]) -> Vec<(Swatch, String)> {
    laws.iter()
        .map(|&l| (Swatch::Bar(law_color(l)), l.name().to_string()))
        .collect()
}

/// The mesh of a bar chart of model probabilities: groups along x (`x_labels` of them named by
/// `x_label`), P(M_k | y) in tenths up to 1 (headroom above 1 left unlabelled).
fn probability_mesh<DB: DrawingBackend>(
    chart: &mut Chart<'_, DB>,
    x_desc: &str,
    x_labels: usize,
    x_label: &dyn Fn(&f64) -> String,
) -> DrawResult
where
    DB::ErrorType: 'static,
{
    chart
        .configure_mesh()
        .x_desc(x_desc)
        .y_desc("P(M_k | y)")
        .axis_desc_style(font(AXIS))
        .label_style(font(TICK))
        .max_light_lines(0)
        .bold_line_style(GRID)
        .disable_x_mesh()
        .x_labels(x_labels)
        .x_label_formatter(x_label)
        .y_labels(6)
        .y_label_formatter(&|y| {
            if *y <= 1.0 + 1e-9 {
                format!("{y:.1}")
            } else {
                String::new()
            }
        })
        .draw()?;
    Ok(())
}

/// Grouped bars: one group per x position, one bar per law.
fn grouped_bars<DB: DrawingBackend>(chart: &mut Chart<'_, DB>, laws: &[Law], groups: &[Vec<f64>]) -> DrawResult
where
    DB::ErrorType: 'static,
{
    let width = 0.8 / laws.len().max(1) as f64;
    for (g, probs) in groups.iter().enumerate() {
        for (k, (&law, &prob)) in laws.iter().zip(probs).enumerate() {
            let x0 = g as f64 - 0.4 + k as f64 * width;
            chart.draw_series(std::iter::once(Rectangle::new(
                [(x0, 0.0), (x0 + width * 0.92, prob)],
                law_color(law).filled(),
            )))?;
        }
    }
    Ok(())
}

impl Figure for ModelProbabilities {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult
    where
        DB::ErrorType: 'static,
    {
        let area = titled(root, "Model probabilities per population")?;
        let (main, strip) = area.split_vertically(area.dim_in_pixel().1 - LEGEND_STRIP);
        for (panel, (label, groups)) in panels(&main, self.runs.len()).iter().zip(&self.runs) {
            let n = groups.len().max(1) as f64;
            let mut chart = axes(panel, label, (-0.6, n - 0.4), (0.0, 1.0))?;
            probability_mesh(&mut chart, "population", groups.len().clamp(2, 12), &integer_label)?;
            grouped_bars(&mut chart, &self.laws, groups)?;
        }
        legend_row(&strip, &law_legend(&self.laws))
    }
}

/// Figure 3: P(law) at the last population of each run.
pub(super) struct FinalProbabilities {
    pub(super) laws: Vec<Law>,
    pub(super) runs: Vec<(String, Vec<f64>)>,
    /// Per run and law: the probability is 0 by construction (labelled `0*`).
    pub(super) zero_by_construction: Vec<Vec<bool>>,
}

impl Figure for FinalProbabilities {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult
    where
        DB::ErrorType: 'static,
    {
        let area = titled(root, "Model probabilities at the last population")?;
        let (main, strip) = area.split_vertically(area.dim_in_pixel().1 - LEGEND_STRIP);
        let n = self.runs.len() as f64;
        let mut chart = axes(&main, "", (-0.6, n - 0.4), (0.0, 1.08))?;
        let labels: Vec<String> = self.runs.iter().map(|r| r.0.clone()).collect();
        let formatter = |x: &f64| {
            let s = integer_label(x);
            s.parse::<usize>()
                .ok()
                .and_then(|i| labels.get(i).cloned())
                .unwrap_or_default()
        };
        probability_mesh(&mut chart, "prior width", self.runs.len().max(2), &formatter)?;
        let groups: Vec<Vec<f64>> = self.runs.iter().map(|r| r.1.clone()).collect();
        grouped_bars(&mut chart, &self.laws, &groups)?;
        let width = 0.8 / self.laws.len().max(1) as f64;
        for (g, probs) in groups.iter().enumerate() {
            for (k, &prob) in probs.iter().enumerate() {
                let x = g as f64 - 0.4 + (k as f64 + 0.46) * width;
                let by_construction = self.zero_by_construction.get(g).and_then(|z| z.get(k)) == Some(&true);
                chart.draw_series(std::iter::once(Text::new(
                    if by_construction {
                        "0*".to_string()
                    } else {
                        format!("{prob:.2}")
                    },
                    (x, prob + 0.01),
                    font(TICK - 2).pos(Pos::new(HPos::Center, VPos::Bottom)),
                )))?;
            }
        }
        legend_row(&strip, &law_legend(&self.laws))
    }
}

/// Figure 4: ε per population, log scale, runs overlaid.
struct Tolerance {
    runs: Vec<(String, Vec<(f64, f64)>)>,
}

/// 1-2-5 multiples of powers of ten within [lo, hi]: the ticks of a log axis.
fn log_ticks(lo: f64, hi: f64) -> Vec<f64> {
    let mut ticks = Vec::new();
    let mut decade = 10f64.powf(lo.log10().floor());
    while decade <= hi {
        for m in [1.0, 2.0, 5.0] {
            let t = m * decade;
            if t >= lo && t <= hi {
                ticks.push(t);
            }
        }
        decade *= 10.0;
    }
    ticks
}

impl Figure for Tolerance {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult
    where
        DB::ErrorType: 'static,
    {
        let area = titled(root, "Tolerance per population")?;
        let all = || self.runs.iter().flat_map(|r| r.1.iter().copied());
        let (x_hi, (e_lo, e_hi)) = (
            plot::extent(all().map(|p| p.0)).map_or(1.0, |e| e.1),
            plot::extent(all().map(|p| p.1)).unwrap_or((0.01, 1.0)),
        );
        // log10 ε on a linear axis, so that the ticks can be placed at 1-2-5 values by hand
        // (plotters' log axis labels only the decades here).
        let (e_lo, e_hi) = (e_lo / 1.3, e_hi * 1.3);
        let mut chart = axes(&area, "", (0.5, x_hi + 0.5), (e_lo.log10(), e_hi.log10()))?;
        chart
            .configure_mesh()
            .x_desc("population")
            .y_desc("tolerance ε (log scale)")
            .axis_desc_style(font(AXIS))
            .label_style(font(TICK))
            .max_light_lines(0)
            .bold_line_style(GRID)
            .disable_y_mesh()
            .x_labels((x_hi as usize).clamp(2, 15))
            .x_label_formatter(&integer_label)
            .y_labels(0)
            .draw()?;
        for t in log_ticks(e_lo, e_hi) {
            let y = t.log10();
            chart.draw_series(LineSeries::new([(0.5, y), (x_hi + 0.5, y)], GRID.stroke_width(1)))?;
            let (px, py) = chart.backend_coord(&(0.5, y));
            root.draw(&PathElement::new(vec![(px - 6, py), (px, py)], BLACK.stroke_width(1)))?;
            root.draw(&Text::new(
                plot::short(t),
                (px - 10, py),
                font(TICK).pos(Pos::new(HPos::Right, VPos::Center)),
            ))?;
        }
        for (i, (label, eps)) in self.runs.iter().enumerate() {
            let c = run_color(i);
            let points: Vec<(f64, f64)> = eps.iter().map(|&(g, e)| (g, e.log10())).collect();
            chart
                .draw_series(LineSeries::new(points.clone(), c.stroke_width(3)))?
                .label(label.as_str())
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(3)));
            chart.draw_series(points.into_iter().map(|p| Circle::new(p, 5, c.filled())))?;
        }
        legend_box(&mut chart, SeriesLabelPosition::UpperRight)
    }
}
