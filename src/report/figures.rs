//! The figures, one struct each holding what it draws (display units: rpm, the record's torque
//! unit, kN), drawn by the same code on the SVG and the PNG backend.

use super::plot::{
    self, AXIS, CALIBRATION, DrawResult, Figure, GRID, LEGEND, TICK, TITLE, VALIDATION, clip_curve, font, heat_color,
    law_color, padded, run_color,
};
use super::stats;
use super::{CORRELATION_SIZE, FIGURE_SIZE, FigureInfo, MIN_CORRELATION_PARTICLES, Prepared, rpm};
use crate::abc::posterior::{self, ENVELOPE_LEVEL, predictive_envelope, speed_grid};
use crate::error::{Error, Result};
use crate::laws::Law;
use crate::stability::map;
use plotters::coord::Shift;
use plotters::coord::types::RangedCoordf64;
use plotters::element::DashedPathElement;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

/// A figure rendered in memory.
pub(super) struct Rendered {
    pub info: FigureInfo,
    pub svg: String,
    pub png: Vec<u8>,
}

/// Most data points drawn per set (every k-th beyond).
const MAX_POINTS: usize = 3000;
/// Most data points per set under an envelope, which must stay visible through them.
const ENVELOPE_POINTS: usize = 700;
/// Most particles in a correlation scatter (the paper shows 700).
const MAX_SCATTER: usize = 700;
/// Speeds of the fitted and predicted curves.
const CURVE_POINTS: usize = 200;
/// Bins of the marginal histograms.
const BINS: usize = 40;
/// Height (px) of the legend strip under multi-panel figures.
const LEGEND_STRIP: u32 = 56;

/// (law, points, legend label).
type FitCurve = (Law, Vec<(f64, f64)>, String);
/// (axis name, range, per run: (run index, densities)).
type MarginalPanel = (String, (f64, f64), Vec<(usize, Vec<f64>)>);
/// (law, probability, [(rpm, lower, median, upper)]).
type EnvelopePanel = (Law, f64, Vec<(f64, f64, f64, f64)>);
/// (law, legend label, boundary in kN per speed).
type BoundaryCurve = (Law, String, Vec<Option<f64>>);
/// (law, probability, MAP boundary, percentile boundary).
type MapLaw = (Law, f64, Vec<Option<f64>>, Vec<Option<f64>>);

type Chart<'a, DB> = ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

fn render_one(stem: String, caption: String, size: (u32, u32), figure: &impl Figure) -> Result<Rendered> {
    let (svg, png) = plot::render(figure, size).map_err(|message| Error::Plot {
        figure: stem.clone(),
        message,
    })?;
    Ok(Rendered {
        info: FigureInfo {
            stem,
            caption,
            width: size.0,
            height: size.1,
        },
        svg,
        png,
    })
}

/// Builds and renders every figure, in the paper's order.
pub(super) fn render_all(p: &Prepared) -> Result<Vec<Rendered>> {
    let shared = Shared::new(p);
    let laws = p.all_laws();
    let mut out = vec![
        render_data_and_fits(p, &shared)?,
        render_model_probabilities(p, &laws)?,
        render_final_probabilities(p, &laws)?,
        render_tolerance(p)?,
    ];
    out.extend(render_marginals(p, &laws)?);
    out.extend(render_correlations(p)?);
    out.push(render_envelopes(p, &shared)?);
    out.push(render_deterministic_map(p)?);
    out.push(render_stochastic_map(p)?);
    out.push(render_structures(p)?);
    out.extend(render_selection_checks(p)?);
    Ok(out)
}

/// What figures 1 and 7 share: the record's points in display units and the curves' speeds.
struct Shared {
    /// Calibration points (rpm, torque), thinned to [`MAX_POINTS`].
    cal: Vec<(f64, f64)>,
    /// Validation points (rpm, torque), thinned to [`MAX_POINTS`].
    val: Vec<(f64, f64)>,
    /// The captions' note on thinned points; empty when every sample is shown.
    thinning_note: String,
    /// Speeds (rad/s) of the fitted and predicted curves, over the record's speeds.
    grid: Vec<f64>,
}

impl Shared {
    /// Reads the points, the thinning note and the curves' speeds off the record.
    fn new(p: &Prepared) -> Self {
        let data = p.input.data;
        let points = |s: &crate::data::Samples| -> Vec<(f64, f64)> {
            let all: Vec<(f64, f64)> = s
                .speed_rad_s
                .iter()
                .zip(&s.torque_nm)
                .map(|(&w, &t)| (rpm(w), t / p.torque_scale))
                .collect();
            plot::thinned(&all, MAX_POINTS)
        };
        let (cal, val) = (points(&data.calibration), points(&data.validation));
        let thinning_note = {
            let shown = cal.len() + val.len();
            let total = data.calibration.len() + data.validation.len();
            if shown < total {
                format!(" ({shown} of {total} samples shown, evenly spaced in time)")
            } else {
                String::new()
            }
        };
        let (w_lo, w_hi) = plot::extent(
            data.calibration
                .speed_rad_s
                .iter()
                .chain(&data.validation.speed_rad_s)
                .copied(),
        )
        .unwrap_or((0.1, 25.0));
        Self {
            cal,
            val,
            thinning_note,
            grid: speed_grid(w_lo, w_hi, CURVE_POINTS),
        }
    }
}

/// Figure 1: the data and each law's least-squares fit.
fn render_data_and_fits(p: &Prepared, shared: &Shared) -> Result<Rendered> {
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

/// Figure 2: model probabilities per population, one panel per run.
fn render_model_probabilities(p: &Prepared, laws: &[Law]) -> Result<Rendered> {
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
                        super::record_probabilities(pop, laws)
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
fn render_final_probabilities(p: &Prepared, laws: &[Law]) -> Result<Rendered> {
    let last = FinalProbabilities {
        laws: laws.to_vec(),
        runs: p
            .runs
            .iter()
            .map(|r| {
                let probs = super::record_probabilities(r.last, laws)
                    .into_iter()
                    .map(|x| x.1)
                    .collect();
                (r.run.label.clone(), probs)
            })
            .collect(),
        zero_by_construction: p
            .runs
            .iter()
            .map(|r| super::record_zero_by_construction(r.last, laws))
            .collect(),
    };
    let any_zero = last.zero_by_construction.iter().flatten().any(|&z| z);
    render_one(
        "fig03_final_probabilities".into(),
        if any_zero {
            format!(
                "Model probabilities at the last population of each run. {}",
                super::BY_CONSTRUCTION_NOTE
            )
        } else {
            "Model probabilities at the last population of each run.".into()
        },
        FIGURE_SIZE,
        &last,
    )
}

/// Figure 4: the tolerance per population, runs overlaid.
fn render_tolerance(p: &Prepared) -> Result<Rendered> {
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

/// Figures 5: posterior marginals, one figure per law with particles, runs overlaid.
fn render_marginals(p: &Prepared, laws: &[Law]) -> Result<Vec<Rendered>> {
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
fn render_correlations(p: &Prepared) -> Result<Vec<Rendered>> {
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

/// Figure 7: the reference run's predictive envelopes over the data, up to four laws.
fn render_envelopes(p: &Prepared, shared: &Shared) -> Result<Rendered> {
    let reference = &p.runs[0];
    let envelopes = Envelopes {
        panels: reference
            .summary
            .laws
            .iter()
            .filter_map(|ls| {
                let e = predictive_envelope(&reference.particles, ls.law, &shared.grid, ENVELOPE_LEVEL, 1.0)?;
                let prob = reference
                    .probabilities
                    .iter()
                    .find(|x| x.0 == ls.law)
                    .map_or(0.0, |x| x.1);
                let band = e
                    .speed_rad_s
                    .iter()
                    .enumerate()
                    .map(|(i, &w)| {
                        (
                            rpm(w),
                            e.lower[i] / p.torque_scale,
                            e.median[i] / p.torque_scale,
                            e.upper[i] / p.torque_scale,
                        )
                    })
                    .collect();
                Some((ls.law, prob, band))
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

/// Each law's deterministic boundary (kN per map speed) on a structure of critical damping `c`.
fn deterministic_boundaries(p: &Prepared, c: f64) -> Vec<BoundaryCurve> {
    let s = &p.input.stability;
    p.deterministic
        .iter()
        .map(|(law, params, least_squares)| {
            let label = if *least_squares {
                format!("{law} (least squares; died out)")
            } else {
                format!("{law} (MAP)")
            };
            (
                *law,
                label,
                map::deterministic_boundary_kn(*law, params, &s.omega_rpm, c, p.w_ref_n),
            )
        })
        .collect()
}

/// The maps' (Ω range in rpm, W range in kN): first to last value of each axis.
fn map_ranges(p: &Prepared) -> ((f64, f64), (f64, f64)) {
    let s = &p.input.stability;
    (
        (s.omega_rpm[0], s.omega_rpm[s.omega_rpm.len() - 1]),
        (s.wob_kn[0], s.wob_kn[s.wob_kn.len() - 1]),
    )
}

/// Figure 8, deterministic: the 1-DOF string's stability map with each law's MAP parameters.
fn render_deterministic_map(p: &Prepared) -> Result<Rendered> {
    let (omega_range, wob_range) = map_ranges(p);
    render_one(
        "fig08_map_deterministic".into(),
        format!(
            "Stability map of the 1-DOF string with each law's MAP parameters ({}): operating points above a \
             curve are unstable, below it stable.",
            p.runs[0].run.label
        ),
        FIGURE_SIZE,
        &BoundaryPanels {
            title: format!("Deterministic stability map, {}", p.structures[0].label),
            panels: vec![(String::new(), deterministic_boundaries(p, p.structures[0].critical_nms))],
            omega: p.input.stability.omega_rpm.clone(),
            omega_range,
            wob_range,
        },
    )
}

/// Figure 8, stochastic: P(unstable) of the reference run's mixture with the MAP and percentile
/// boundaries.
fn render_stochastic_map(p: &Prepared) -> Result<Rendered> {
    let s = &p.input.stability;
    let map_laws = p.map_laws();
    let inputs: Vec<_> = map_laws.iter().map(|m| (*m).clone()).collect();
    let lumped_c = p.structures[0].critical_nms;
    let b = map::boundaries(&inputs, &s.omega_rpm, lumped_c, p.w_ref_n, s.percentile);
    let stochastic = StochasticMap {
        omega: s.omega_rpm.clone(),
        wob: s.wob_kn.clone(),
        grid: p.mixture_grid(),
        laws: b
            .laws
            .iter()
            .map(|l| (l.law, l.probability, l.map_wob_kn.clone(), l.p_wob_kn.clone()))
            .collect(),
        mixture: b.mixture_wob_kn.clone(),
        percent: s.percentile * 100.0,
        title: format!(
            "Stochastic stability map, {}, {}",
            p.runs[0].run.label, p.structures[0].label
        ),
    };
    render_one(
        "fig08_map_stochastic".into(),
        format!(
            "P(unstable) of the 1-DOF string under the mixture of the laws weighted by their probability (colour; {} samples per law), \
             each law's MAP boundary (solid), its {} % percentile boundary (dashed) and the mixture's {} % \
             boundary (black dashed).",
            s.samples_per_law,
            s.percentile * 100.0,
            s.percentile * 100.0
        ),
        FIGURE_SIZE,
        &stochastic,
    )
}

/// Figure 9, the appendix: the MAP boundaries on the 1-DOF and the finite-element strings.
fn render_structures(p: &Prepared) -> Result<Rendered> {
    let s = &p.input.stability;
    let (omega_range, wob_range) = map_ranges(p);
    let structures = BoundaryPanels {
        title: match s.strings.first() {
            Some(fe) => format!(
                "MAP boundaries: 1-DOF and finite-element strings (α = {} 1/s)",
                fe.alpha
            ),
            None => "MAP boundaries".into(),
        },
        panels: p
            .structures
            .iter()
            .map(|st| {
                (
                    format!("{}: c_b* = {:.0} N·m·s/rad", st.short_label, st.critical_nms),
                    deterministic_boundaries(p, st.critical_nms),
                )
            })
            .collect(),
        omega: s.omega_rpm.clone(),
        omega_range,
        wob_range,
    };
    render_one(
        "fig09_structures".into(),
        "The MAP boundaries of each law on the 1-DOF string and on the finite-element strings (the paper's \
         appendix): each structure enters only through its critical bit damping c_b*."
            .into(),
        FIGURE_SIZE,
        &structures,
    )
}

/// Figures 10: the confusion matrix of each run that holds a selection check.
fn render_selection_checks(p: &Prepared) -> Result<Vec<Rendered>> {
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
pub(crate) fn confusion_figure(check: &crate::selection::SelectionCheck) -> Result<(String, Vec<u8>)> {
    let rendered = render_one(
        "confusion".into(),
        String::new(),
        FIGURE_SIZE,
        &ConfusionMatrix::new(check, &check.run_dir.display().to_string()),
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

    fn new(check: &crate::selection::SelectionCheck, run: &str) -> Self {
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

/// Axes with the figures' margins and label areas.
fn axes<'a, DB: DrawingBackend>(
    area: &'a DrawingArea<DB, Shift>,
    caption: &str,
    x: (f64, f64),
    y: (f64, f64),
) -> std::result::Result<Chart<'a, DB>, Box<dyn std::error::Error>>
where
    DB::ErrorType: 'static,
{
    let mut b = ChartBuilder::on(area);
    b.margin(12)
        .margin_right(24)
        .x_label_area_size(64)
        .y_label_area_size(92);
    if !caption.is_empty() {
        b.caption(caption, font(AXIS));
    }
    Ok(b.build_cartesian_2d(x.0..x.1, y.0..y.1)?)
}

fn mesh<DB: DrawingBackend>(chart: &mut Chart<'_, DB>, x_desc: &str, y_desc: &str) -> DrawResult
where
    DB::ErrorType: 'static,
{
    chart
        .configure_mesh()
        .x_desc(x_desc)
        .y_desc(y_desc)
        .axis_desc_style(font(AXIS))
        .label_style(font(TICK))
        .max_light_lines(0)
        .bold_line_style(GRID)
        .x_labels(8)
        .y_labels(8)
        .x_label_formatter(&|x| plot::short(*x))
        .y_label_formatter(&|y| plot::short(*y))
        .draw()?;
    Ok(())
}

fn legend_box<'a, DB: DrawingBackend + 'a>(chart: &mut Chart<'a, DB>, position: SeriesLabelPosition) -> DrawResult
where
    DB::ErrorType: 'static,
{
    chart
        .configure_series_labels()
        .label_font(font(LEGEND))
        .background_style(WHITE.mix(0.9))
        .border_style(BLACK.mix(0.5))
        .position(position)
        .margin(12)
        .draw()?;
    Ok(())
}

/// What a legend entry shows.
#[derive(Clone, Copy)]
enum Swatch {
    Line(RGBColor),
    Dashed(RGBColor),
    Bar(RGBColor),
    Circle(RGBColor),
    Dot(RGBColor),
    Band,
}

/// A centred row of legend entries (for multi-panel figures, where a legend inside a panel
/// would cover data).
fn legend_row<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, items: &[(Swatch, String)]) -> DrawResult
where
    DB::ErrorType: 'static,
{
    let style = font(LEGEND);
    let (swatch, gap, spacing) = (34, 8, 34);
    let mut widths = Vec::with_capacity(items.len());
    for (_, text) in items {
        widths.push(area.estimate_text_size(text, &style)?.0 as i32);
    }
    let total: i32 = widths.iter().map(|w| swatch + gap + w).sum::<i32>() + spacing * (items.len() as i32 - 1).max(0);
    let (width, height) = area.dim_in_pixel();
    let y = height as i32 / 2;
    let mut x = ((width as i32 - total) / 2).max(4);
    for ((kind, text), w) in items.iter().zip(&widths) {
        let (x0, x1) = (x, x + swatch);
        match *kind {
            Swatch::Line(c) => area.draw(&PathElement::new(vec![(x0, y), (x1, y)], c.stroke_width(3)))?,
            Swatch::Dashed(c) => {
                for k in 0..3 {
                    let a = x0 + k * 13;
                    area.draw(&PathElement::new(vec![(a, y), ((a + 8).min(x1), y)], c.stroke_width(3)))?;
                }
            }
            Swatch::Bar(c) => area.draw(&Rectangle::new([(x0 + 4, y - 9), (x1 - 4, y + 9)], c.filled()))?,
            Swatch::Circle(c) => area.draw(&Circle::new((x0 + swatch / 2, y), 5, c.stroke_width(2)))?,
            Swatch::Dot(c) => area.draw(&Circle::new((x0 + swatch / 2, y), 4, c.filled()))?,
            Swatch::Band => area.draw(&Rectangle::new(
                [(x0 + 2, y - 9), (x1 - 2, y + 9)],
                band_color().filled(),
            ))?,
        }
        area.draw(&Text::new(
            text.clone(),
            (x1 + gap, y),
            style.pos(Pos::new(HPos::Left, VPos::Center)),
        ))?;
        x += swatch + gap + w + spacing;
    }
    Ok(())
}

fn band_color() -> RGBAColor {
    RGBColor(120, 120, 120).mix(0.45)
}

/// Height (px) of the title strip.
const TITLE_STRIP: u32 = 58;

/// Clears the figure and writes its title centred in a strip at the top; returns the area under
/// it. (plotters' own `titled` puts the text flush with the top edge, where ab_glyph's glyph
/// placement clips it.)
fn titled<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    title: &str,
) -> std::result::Result<DrawingArea<DB, Shift>, Box<dyn std::error::Error>>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE)?;
    let (top, rest) = root.split_vertically(TITLE_STRIP);
    let (w, h) = top.dim_in_pixel();
    top.draw(&Text::new(
        title.to_string(),
        (w as i32 / 2, h as i32 / 2 + 4),
        font(TITLE).pos(Pos::new(HPos::Center, VPos::Center)),
    ))?;
    Ok(rest)
}

/// Splits `area` into `n` panels: one row up to three, else rows of three (two for four).
fn panels<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, n: usize) -> Vec<DrawingArea<DB, Shift>> {
    let cols = match n {
        0 | 1 => 1,
        2 | 4 => 2,
        _ => 3,
    };
    let rows = n.max(1).div_ceil(cols);
    area.split_evenly((rows, cols)).into_iter().take(n).collect()
}

/// Every `key` on an integer axis as an integer, nothing between.
fn integer_label(x: &f64) -> String {
    if (x - x.round()).abs() < 1e-9 {
        format!("{}", x.round() as i64)
    } else {
        String::new()
    }
}

fn draw_points<DB: DrawingBackend>(chart: &mut Chart<'_, DB>, cal: &[(f64, f64)], val: &[(f64, f64)]) -> DrawResult
where
    DB::ErrorType: 'static,
{
    let (x, y) = (chart.x_range(), chart.y_range());
    let inside = |&(a, b): &(f64, f64)| x.contains(&a) && y.contains(&b);
    chart
        .draw_series(
            val.iter()
                .filter(|p| inside(p))
                .map(|&p| Circle::new(p, 2, VALIDATION.filled())),
        )?
        .label("validation")
        .legend(|(x, y)| Circle::new((x + 10, y), 4, VALIDATION.filled()));
    chart
        .draw_series(
            cal.iter()
                .filter(|p| inside(p))
                .map(|&p| Circle::new(p, 3, CALIBRATION.stroke_width(1))),
        )?
        .label("calibration")
        .legend(|(x, y)| Circle::new((x + 10, y), 5, CALIBRATION.stroke_width(2)));
    Ok(())
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
            chart
                .configure_mesh()
                .x_desc("population")
                .y_desc("P(M_k | y)")
                .axis_desc_style(font(AXIS))
                .label_style(font(TICK))
                .max_light_lines(0)
                .bold_line_style(GRID)
                .disable_x_mesh()
                .x_labels(groups.len().clamp(2, 12))
                .x_label_formatter(&integer_label)
                .y_labels(6)
                .y_label_formatter(&|y| format!("{y:.1}"))
                .draw()?;
            grouped_bars(&mut chart, &self.laws, groups)?;
        }
        legend_row(&strip, &law_legend(&self.laws))
    }
}

/// Figure 3: P(law) at the last population of each run.
struct FinalProbabilities {
    laws: Vec<Law>,
    runs: Vec<(String, Vec<f64>)>,
    /// Per run and law: the probability is 0 by construction (labelled `0*`).
    zero_by_construction: Vec<Vec<bool>>,
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
        chart
            .configure_mesh()
            .x_desc("prior width")
            .y_desc("P(M_k | y)")
            .axis_desc_style(font(AXIS))
            .label_style(font(TICK))
            .max_light_lines(0)
            .bold_line_style(GRID)
            .disable_x_mesh()
            .x_labels(self.runs.len().max(2))
            .x_label_formatter(&formatter)
            .y_labels(6)
            .y_label_formatter(&|y| {
                if *y <= 1.0 + 1e-9 {
                    format!("{y:.1}")
                } else {
                    String::new()
                }
            })
            .draw()?;
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
            let mut chart = ChartBuilder::on(panel)
                .margin(10)
                .margin_right(22)
                .x_label_area_size(58)
                .y_label_area_size(84)
                .build_cartesian_2d(range.0..range.1, 0.0..(top * 1.08).max(1e-300))?;
            chart
                .configure_mesh()
                .x_desc(name.as_str())
                .y_desc("density")
                .axis_desc_style(font(AXIS - 2))
                .label_style(font(TICK - 3))
                .max_light_lines(0)
                .bold_line_style(GRID)
                .x_labels(4)
                .y_labels(5)
                .x_label_formatter(&|x| plot::short(*x))
                .y_label_formatter(&|y| plot::short(*y))
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
            let mut mesh = chart.configure_mesh();
            mesh.max_light_lines(0)
                .disable_mesh()
                .label_style(font(small))
                .axis_desc_style(font(small + 1))
                .x_labels(3)
                .y_labels(3)
                .x_label_formatter(&|x| plot::short(*x))
                .y_label_formatter(&|y| plot::short(*y));
            if i + 1 == d {
                mesh.x_desc(self.names[j].as_str());
            } else {
                mesh.x_labels(0);
            }
            if j == 0 && i != 0 {
                mesh.y_desc(self.names[i].as_str());
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

/// Figure 7: predictive envelopes with the data, one panel per law.
struct Envelopes {
    /// (law, probability, [(rpm, lower, median, upper)]) in the display unit.
    panels: Vec<EnvelopePanel>,
    cal: Vec<(f64, f64)>,
    val: Vec<(f64, f64)>,
    unit: &'static str,
    run: String,
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

/// Draws a boundary curve (pieces inside the axes), solid or dashed; the first piece carries
/// the legend label.
fn draw_boundary<DB: DrawingBackend>(
    chart: &mut Chart<'_, DB>,
    omega: &[f64],
    wob: &[Option<f64>],
    color: RGBColor,
    dashed: bool,
    label: Option<&str>,
) -> DrawResult
where
    DB::ErrorType: 'static,
{
    let y = chart.y_range();
    let style = color.stroke_width(3);
    for (k, piece) in clip_curve(omega, wob, y.start, y.end).into_iter().enumerate() {
        let series = if dashed {
            chart.draw_series(DashedLineSeries::new(piece, 12, 7, style))?
        } else {
            chart.draw_series(LineSeries::new(piece, style))?
        };
        if k == 0
            && let Some(label) = label
        {
            if dashed {
                series
                    .label(label)
                    .legend(move |(x, y)| DashedPathElement::new(vec![(x, y), (x + 24, y)], 8, 5, style));
            } else {
                series
                    .label(label)
                    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], style));
            }
        }
    }
    Ok(())
}

/// Figures 8 (deterministic map) and 9 (one panel per structure): MAP boundaries per law.
struct BoundaryPanels {
    title: String,
    /// (panel caption, [(law, legend label, boundary kN per speed)]).
    panels: Vec<(String, Vec<BoundaryCurve>)>,
    omega: Vec<f64>,
    omega_range: (f64, f64),
    wob_range: (f64, f64),
}

impl Figure for BoundaryPanels {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult
    where
        DB::ErrorType: 'static,
    {
        let area = titled(root, &self.title)?;
        let single = self.panels.len() == 1;
        let (main, strip) = if single {
            let (a, b) = area.split_vertically(area.dim_in_pixel().1);
            (a, b)
        } else {
            area.split_vertically(area.dim_in_pixel().1 - LEGEND_STRIP)
        };
        for (panel, (caption, curves)) in panels(&main, self.panels.len()).iter().zip(&self.panels) {
            let mut chart = ChartBuilder::on(panel)
                .margin(10)
                .margin_right(24)
                .x_label_area_size(if single { 64 } else { 54 })
                .y_label_area_size(if single { 92 } else { 80 })
                .caption(caption.as_str(), font(if single { AXIS } else { TICK }))
                .build_cartesian_2d(
                    self.omega_range.0..self.omega_range.1,
                    self.wob_range.0..self.wob_range.1,
                )?;
            chart
                .configure_mesh()
                .x_desc("top-drive speed Ω (rpm)")
                .y_desc("weight on bit W (kN)")
                .axis_desc_style(font(if single { AXIS } else { TICK }))
                .label_style(font(if single { TICK } else { TICK - 3 }))
                .max_light_lines(0)
                .bold_line_style(GRID)
                .x_labels(if single { 11 } else { 6 })
                .y_labels(8)
                .x_label_formatter(&|x| plot::short(*x))
                .y_label_formatter(&|y| plot::short(*y))
                .draw()?;
            for (law, label, wob) in curves {
                draw_boundary(
                    &mut chart,
                    &self.omega,
                    wob,
                    law_color(*law),
                    label.contains("least squares"),
                    single.then_some(label.as_str()),
                )?;
            }
            if single {
                legend_box(&mut chart, SeriesLabelPosition::UpperLeft)?;
            }
        }
        if !single && let Some((_, curves)) = self.panels.first() {
            let items: Vec<(Swatch, String)> = curves
                .iter()
                .map(|(law, label, _)| {
                    let c = law_color(*law);
                    let swatch = if label.contains("least squares") {
                        Swatch::Dashed(c)
                    } else {
                        Swatch::Line(c)
                    };
                    (swatch, label.clone())
                })
                .collect();
            legend_row(&strip, &items)?;
        }
        Ok(())
    }
}

/// Figure 8: the stochastic map of the reference run.
struct StochasticMap {
    omega: Vec<f64>,
    wob: Vec<f64>,
    /// P(unstable) of the mixture, row-major over Ω.
    grid: Vec<f64>,
    /// (law, probability, MAP boundary, percentile boundary).
    laws: Vec<MapLaw>,
    mixture: Option<Vec<Option<f64>>>,
    percent: f64,
    title: String,
}

/// Cell edges of an axis of cell centres: midpoints, the ends at the first and last value.
fn edges(centres: &[f64]) -> Vec<f64> {
    let mut e = vec![centres[0]];
    e.extend(centres.windows(2).map(|w| 0.5 * (w[0] + w[1])));
    e.push(centres[centres.len() - 1]);
    e
}

impl Figure for StochasticMap {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult
    where
        DB::ErrorType: 'static,
    {
        let area = titled(root, &self.title)?;
        let (main, bar) = area.split_horizontally(area.dim_in_pixel().0 - 150);
        let (x0, x1) = (self.omega[0], self.omega[self.omega.len() - 1]);
        let (y0, y1) = (self.wob[0], self.wob[self.wob.len() - 1]);
        let mut chart = axes(&main, "", (x0, x1), (y0, y1))?;
        let (xe, ye) = (edges(&self.omega), edges(&self.wob));
        let nw = self.wob.len();
        chart.draw_series((0..self.omega.len()).flat_map(|i| {
            let (xe, ye) = (&xe, &ye);
            (0..nw).map(move |j| {
                Rectangle::new(
                    [(xe[i], ye[j]), (xe[i + 1], ye[j + 1])],
                    heat_color(self.grid[i * nw + j]).filled(),
                )
            })
        }))?;
        mesh(&mut chart, "top-drive speed Ω (rpm)", "weight on bit W (kN)")?;
        for (law, prob, map_wob, p_wob) in &self.laws {
            let c = law_color(*law);
            draw_boundary(
                &mut chart,
                &self.omega,
                map_wob,
                c,
                false,
                Some(&format!("{law} MAP (P = {prob:.2})")),
            )?;
            draw_boundary(
                &mut chart,
                &self.omega,
                p_wob,
                c,
                true,
                Some(&format!("{law} {} %", self.percent)),
            )?;
        }
        if let Some(m) = &self.mixture {
            draw_boundary(
                &mut chart,
                &self.omega,
                m,
                BLACK,
                true,
                Some(&format!("mixture {} %", self.percent)),
            )?;
        }
        legend_box(&mut chart, SeriesLabelPosition::UpperLeft)?;

        // Colour bar.
        let mut scale = ChartBuilder::on(&bar)
            .margin_top(40)
            .margin_bottom(76)
            .margin_right(12)
            .y_label_area_size(86)
            .build_cartesian_2d(0.0..1.0, 0.0..1.0)?;
        scale
            .configure_mesh()
            .disable_mesh()
            .x_labels(0)
            .y_labels(6)
            .y_desc("P(unstable)")
            .axis_desc_style(font(AXIS))
            .label_style(font(TICK))
            .y_label_formatter(&|y| format!("{y:.1}"))
            .draw()?;
        scale.draw_series((0..100).map(|k| {
            let (a, b) = (k as f64 / 100.0, (k + 1) as f64 / 100.0);
            Rectangle::new([(0.0, a), (1.0, b)], heat_color(0.5 * (a + b)).filled())
        }))?;
        Ok(())
    }
}
