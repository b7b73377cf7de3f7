//! The figures, one struct each holding what it draws (display units: rpm, the record's torque
//! unit, kN), drawn by the same code on the SVG and the PNG backend; one file per family, the
//! drawing helpers they share here.

mod evidence;
mod fits;
mod marginals;
mod probabilities;
mod selection;
mod stability;
mod surface;

pub(crate) use evidence::{EvidenceFigures, render_evidence};
use fits::{render_data_and_fits, render_envelopes};
use marginals::{render_correlations, render_marginals};
use probabilities::{render_final_probabilities, render_model_probabilities, render_tolerance};
pub(crate) use selection::confusion_figure;
use selection::render_selection_checks;
use stability::{render_deterministic_map, render_simulated_map, render_stochastic_map, render_structures};
pub(crate) use surface::{SurfaceFigure, render_surface};

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
pub(crate) struct Rendered {
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
pub(crate) const LEGEND_STRIP: u32 = 56;

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

pub(crate) type Chart<'a, DB> = ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

pub(crate) fn render_one(stem: String, caption: String, size: (u32, u32), figure: &impl Figure) -> Result<Rendered> {
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
    out.extend(render_simulated_map(p)?);
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

/// Axes with the figures' margins and label areas.
pub(crate) fn axes<'a, DB: DrawingBackend>(
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

pub(crate) fn mesh<DB: DrawingBackend>(chart: &mut Chart<'_, DB>, x_desc: &str, y_desc: &str) -> DrawResult
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
pub(crate) enum Swatch {
    Line(RGBColor),
    Dashed(RGBColor),
    Bar(RGBColor),
    Circle(RGBColor),
    Dot(RGBColor),
    Band,
}

/// A centred row of legend entries (for multi-panel figures, where a legend inside a panel
/// would cover data).
pub(crate) fn legend_row<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, items: &[(Swatch, String)]) -> DrawResult
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
pub(crate) fn titled<DB: DrawingBackend>(
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
pub(crate) fn panels<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, n: usize) -> Vec<DrawingArea<DB, Shift>> {
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
