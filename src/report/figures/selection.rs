//! The selection check's confusion matrix.

use super::*;

/// Figures 10: the confusion matrix of each run that holds a selection check.
pub(super) fn render_selection_checks(p: &Prepared) -> Result<Vec<Rendered>> {
    let mut out = Vec::new();
    for (i, r) in p.runs.iter().enumerate() {
        if let Some((check, _)) = &r.run.selection {
            let figure = ConfusionMatrix::new(check, &r.run.label);
            out.push(render_one(
                format!("fig10_selection_{}", i + 1),
                format!("{}: {}", r.run.label, ConfusionMatrix::CAPTION),
                FIGURE_SIZE,
                &figure,
            )?);
        }
    }
    Ok(out)
}

/// The heat map of a selection check (`bitrock check-selection`), SVG text and PNG bytes.
pub(crate) fn confusion_figure(check: &crate::run::selection::SelectionCheck) -> Result<(String, Vec<u8>)> {
    let rendered = render_one(
        "confusion".into(),
        String::new(),
        FIGURE_SIZE,
        &ConfusionMatrix::new(
            check,
            &check
                .run_dir
                .as_ref()
                .map_or("a run in memory".into(), |d| d.display().to_string()),
        ),
    )?;
    Ok((rendered.svg, rendered.png))
}

/// Figure 10: the confusion matrix of a selection check, two heat maps side by side: the mean
/// posterior probability of each law (columns) on records made by each law (rows), and the
/// share of those records on which each law ranks first.
struct ConfusionMatrix {
    title: String,
    laws: Vec<Law>,
    /// Generating laws, one per row.
    rows: Vec<Law>,
    mean: Vec<Vec<f64>>,
    first: Vec<Vec<f64>>,
}

impl ConfusionMatrix {
    const CAPTION: &'static str = "Selection check: rows are the law that made the synthetic records, columns the \
         law the ABC run favours; left the mean posterior probability, right the share of replicates in which the \
         law ranks first. A trustworthy selection has its weight on the diagonal.";

    fn new(check: &crate::run::selection::SelectionCheck, run: &str) -> Self {
        Self {
            title: format!(
                "Selection check, {run}: {} replicates per law, N = {}",
                check.replicates, check.particles
            ),
            laws: check.laws.clone(),
            rows: check.rows.iter().map(|r| r.law).collect(),
            mean: check.rows.iter().map(|r| r.mean_probability.clone()).collect(),
            first: check.rows.iter().map(|r| r.first_share.clone()).collect(),
        }
    }
}

impl Figure for ConfusionMatrix {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult
    where
        DB::ErrorType: 'static,
    {
        let area = titled(root, &self.title)?;
        let halves = panels(&area, 2);
        let (nx, ny) = (self.laws.len() as f64, self.rows.len() as f64);
        for (half, (caption, values)) in halves.iter().zip([
            ("mean posterior probability", &self.mean),
            ("share ranked first", &self.first),
        ]) {
            let mut chart = axes(half, caption, (0.0, nx), (0.0, ny))?;
            let laws = &self.laws;
            let rows = &self.rows;
            // Row 0 at the top, as a matrix is read.
            let column_label = |x: &f64| {
                let j = x.floor() as usize;
                if (x - x.floor() - 0.5).abs() < 1e-9 {
                    laws.get(j).map_or(String::new(), |l| l.to_string())
                } else {
                    String::new()
                }
            };
            let row_label = |y: &f64| {
                let i = (ny - y).floor() as usize;
                if (y - y.floor() - 0.5).abs() < 1e-9 {
                    rows.get(i).map_or(String::new(), |l| l.to_string())
                } else {
                    String::new()
                }
            };
            chart
                .configure_mesh()
                .disable_mesh()
                .x_desc("law favoured")
                .y_desc("law that made the data")
                .axis_desc_style(font(AXIS))
                .label_style(font(AXIS))
                .x_labels(2 * laws.len() + 1)
                .y_labels(2 * rows.len() + 1)
                .x_label_formatter(&column_label)
                .y_label_formatter(&row_label)
                .draw()?;
            for (i, row) in values.iter().enumerate() {
                let top = ny - i as f64;
                for (j, &v) in row.iter().enumerate() {
                    let x = j as f64;
                    chart.draw_series(std::iter::once(Rectangle::new(
                        [(x, top - 1.0), (x + 1.0, top)],
                        heat_color(v).filled(),
                    )))?;
                    chart.draw_series(std::iter::once(Rectangle::new(
                        [(x, top - 1.0), (x + 1.0, top)],
                        BLACK.mix(0.3).stroke_width(1),
                    )))?;
                    chart.draw_series(std::iter::once(Text::new(
                        format!("{v:.2}"),
                        (x + 0.5, top - 0.5),
                        font(TITLE).pos(Pos::new(HPos::Center, VPos::Center)),
                    )))?;
                }
            }
        }
        Ok(())
    }
}
