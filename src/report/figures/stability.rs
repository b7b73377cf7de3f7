//! The stability maps: deterministic boundaries, the stochastic map and the structures compared.

use super::*;

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

/// A map figure's caption where some boundary lies wholly off the map (report.md says which).
fn off_the_map_caption(p: &Prepared) -> &'static str {
    if p.off_the_map.is_empty() {
        ""
    } else {
        " Some boundaries lie wholly off this map and are not drawn (report.md, Stability, says where)."
    }
}

/// Figure 8, deterministic: the 1-DOF string's stability map with each law's MAP parameters.
pub(super) fn render_deterministic_map(p: &Prepared) -> Result<Rendered> {
    let (omega_range, wob_range) = map_ranges(p);
    render_one(
        "fig08_map_deterministic".into(),
        format!(
            "Stability map of the 1-DOF string with each law's MAP parameters ({}): operating points above a \
             curve are unstable, below it stable.{}",
            p.runs[0].run.label,
            off_the_map_caption(p)
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
pub(super) fn render_stochastic_map(p: &Prepared) -> Result<Rendered> {
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
             boundary (black dashed).{}",
            s.samples_per_law,
            s.percentile * 100.0,
            s.percentile * 100.0,
            off_the_map_caption(p)
        ),
        FIGURE_SIZE,
        &stochastic,
    )
}

/// Figure 9, the appendix: the MAP boundaries on the 1-DOF and the finite-element strings.
pub(super) fn render_structures(p: &Prepared) -> Result<Rendered> {
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

/// A map's axes over (Ω, W) on `area`, its cells coloured by `grid` (row-major over Ω; NaN
/// grey).
fn heat_map<'a, DB: DrawingBackend>(
    area: &'a DrawingArea<DB, Shift>,
    omega: &[f64],
    wob: &[f64],
    grid: &[f64],
) -> std::result::Result<Chart<'a, DB>, Box<dyn std::error::Error>>
where
    DB::ErrorType: 'static,
{
    let (x0, x1) = (omega[0], omega[omega.len() - 1]);
    let (y0, y1) = (wob[0], wob[wob.len() - 1]);
    let mut chart = axes(area, "", (x0, x1), (y0, y1))?;
    let (xe, ye) = (edges(omega), edges(wob));
    let nw = wob.len();
    chart.draw_series((0..omega.len()).flat_map(|i| {
        let (xe, ye) = (&xe, &ye);
        (0..nw).map(move |j| {
            Rectangle::new(
                [(xe[i], ye[j]), (xe[i + 1], ye[j + 1])],
                heat_color(grid[i * nw + j]).filled(),
            )
        })
    }))?;
    Ok(chart)
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
        let mut chart = heat_map(&main, &self.omega, &self.wob, &self.grid)?;
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

        colour_bar(&bar, "P(unstable)")
    }
}

/// The maps by simulated strings: P(stick-slip persists) from the record's operating point (P
/// of it developing from steady rotation where the record's point is unknown), the onset and
/// escape boundaries, the bistable band between them, the operating point and the advice.
pub(super) fn render_simulated_map(p: &Prepared) -> Result<Option<Rendered>> {
    let Some(sim) = &p.simulated else {
        return Ok(None);
    };
    let (heat, point, advised) = match &sim.escape {
        Some((grid, advice)) => {
            let mut advised = Vec::new();
            if let Some(w) = advice.speed_rpm {
                advised.push(((w.to, advice.point.wob_kn), format!("raise to {:.0} rpm", w.to)));
            }
            if let Some(w) = advice.wob_kn {
                advised.push(((advice.point.omega_rpm, w.to), format!("lower to {:.0} kN", w.to)));
            }
            (grid, Some((advice.point.omega_rpm, advice.point.wob_kn)), advised)
        }
        None => (&sim.onset, None, Vec::new()),
    };
    let figure = SimulatedMap {
        omega: sim.onset.omega_rpm.clone(),
        wob: sim.onset.wob_kn.clone(),
        // Among the strings that stayed in bounds; cells where some left them are marked.
        heat: heat
            .stick_slip_weight
            .iter()
            .zip(&heat.diverged_weight)
            .map(|(s, d)| if *d < 1.0 { s / (1.0 - d) } else { f64::NAN })
            .collect(),
        diverged: heat.diverged_weight.iter().map(|d| *d > 0.0).collect(),
        heat_label: if sim.escape.is_some() {
            "P(persists)"
        } else {
            "P(develops)"
        },
        onset: sim.onset.boundary_wob_kn(0.5),
        escape: sim.escape.as_ref().map(|(g, _)| g.boundary_wob_kn(0.5)),
        bistable: match &sim.escape {
            Some((escape, _)) => escape
                .stick_slip_weight
                .iter()
                .zip(&sim.onset.stick_slip_weight)
                .zip(&sim.onset.diverged_weight)
                .map(|((e, o), d)| *e >= 0.5 && o + d < 0.5)
                .collect(),
            None => Vec::new(),
        },
        point,
        advised,
        title: format!(
            "Stick-slip by simulated strings, {}, {}",
            p.runs[0].run.label, p.structures[0].label
        ),
    };
    Ok(Some(render_one(
        "fig11_stick_slip_simulated".into(),
        "Stick-slip by simulated strings: where it develops from steady rotation kicked by a tenth of the speed \
         (dashed), where it persists once the bit is in it at the record's operating point (solid, the colours), \
         and the bistable band between them (hatched orange): operating points where steady rotation survives, \
         but a stick-slipping bit stays stuck in its cycle. Colours: the share of the strings that stayed in \
         physical bounds; a grey × marks cells where some left them (a law extrapolated past its data)."
            .into(),
        FIGURE_SIZE,
        &figure,
    )?))
}

/// The maps by simulated strings, drawn.
struct SimulatedMap {
    omega: Vec<f64>,
    wob: Vec<f64>,
    /// The probability coloured, row-major over Ω (NaN: unknown).
    heat: Vec<f64>,
    /// Cells where some strings left physical bounds, row-major over Ω.
    diverged: Vec<bool>,
    heat_label: &'static str,
    onset: Vec<Option<f64>>,
    escape: Option<Vec<Option<f64>>>,
    /// Cells of the bistable band, row-major over Ω.
    bistable: Vec<bool>,
    /// The record's operating point (rpm, kN), and the advised points with their labels.
    point: Option<(f64, f64)>,
    advised: Vec<((f64, f64), String)>,
    title: String,
}

/// The bistable band's colour.
const BISTABLE: RGBColor = RGBColor(0xe6, 0x85, 0x0e);

impl Figure for SimulatedMap {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult
    where
        DB::ErrorType: 'static,
    {
        let area = titled(root, &self.title)?;
        let (main, bar) = area.split_horizontally(area.dim_in_pixel().0 - 150);
        let mut chart = heat_map(&main, &self.omega, &self.wob, &self.heat)?;
        let (xe, ye) = (edges(&self.omega), edges(&self.wob));
        let nw = self.wob.len();
        let cell = |i: usize, j: usize| [(xe[i], ye[j]), (xe[i + 1], ye[j + 1])];
        // The band hatched: diagonal strokes across each of its cells.
        chart.draw_series(
            (0..self.omega.len())
                .flat_map(|i| (0..nw).map(move |j| (i, j)))
                .filter(|(i, j)| self.bistable.get(i * nw + j).copied().unwrap_or(false))
                .flat_map(|(i, j)| {
                    let [(a, b), (c, d)] = cell(i, j);
                    (0..4).map(move |k| {
                        let t = f64::from(k) / 4.0;
                        PathElement::new(
                            vec![(a + t * (c - a), b), (c, d - t * (d - b))],
                            BISTABLE.stroke_width(2),
                        )
                    })
                }),
        )?;
        chart.draw_series(
            (0..self.omega.len())
                .flat_map(|i| (0..nw).map(move |j| (i, j)))
                .filter(|(i, j)| self.diverged[i * nw + j])
                .map(|(i, j)| {
                    Cross::new(
                        (self.omega[i], self.wob[j]),
                        4,
                        RGBColor(0x77, 0x77, 0x77).stroke_width(2),
                    )
                }),
        )?;
        mesh(&mut chart, "top-drive speed Ω (rpm)", "weight on bit W (kN)")?;
        draw_boundary(
            &mut chart,
            &self.omega,
            &self.onset,
            BLACK,
            true,
            Some("develops from steady rotation (P ≥ 0.5)"),
        )?;
        if let Some(escape) = &self.escape {
            draw_boundary(
                &mut chart,
                &self.omega,
                escape,
                BLACK,
                false,
                Some("persists from the cycle (P ≥ 0.5)"),
            )?;
        }
        if self.bistable.iter().any(|b| *b) {
            // A path of one point: an entry in the legend, nothing on the map.
            let (x0, y0) = (self.omega[0], self.wob[0]);
            chart
                .draw_series(std::iter::once(PathElement::new(vec![(x0, y0), (x0, y0)], BISTABLE)))?
                .label("bistable band")
                .legend(|(x, y)| Rectangle::new([(x, y - 6), (x + 24, y + 6)], BISTABLE.mix(0.6).filled()));
        }
        if let Some(point) = self.point {
            chart
                .draw_series(std::iter::once(Circle::new(point, 9, BLACK.filled())))?
                .label(format!("the record: {:.0} rpm, {:.0} kN", point.0, point.1))
                .legend(|(x, y)| Circle::new((x + 12, y), 6, BLACK.filled()));
        }
        for (at, label) in &self.advised {
            let style = RGBColor(0x2c, 0xa0, 0x2c);
            chart
                .draw_series(std::iter::once(TriangleMarker::new(*at, 12, style.filled())))?
                .label(format!("advice: {label}"))
                .legend(move |(x, y)| TriangleMarker::new((x + 12, y), 8, style.filled()));
        }
        legend_box(&mut chart, SeriesLabelPosition::UpperLeft)?;
        colour_bar(&bar, self.heat_label)
    }
}

/// The probability colour bar of a heat map, labelled `label`.
fn colour_bar<DB: DrawingBackend>(bar: &DrawingArea<DB, Shift>, label: &str) -> DrawResult
where
    DB::ErrorType: 'static,
{
    let mut scale = ChartBuilder::on(bar)
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
        .y_desc(label)
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
