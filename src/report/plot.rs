//! What every figure shares: the embedded font, rendering one drawing to SVG and PNG in memory,
//! the palette, and small geometry helpers (clipping curves to the axes, padded ranges).

use plotters::coord::Shift;
use plotters::prelude::*;
use std::sync::OnceLock;

/// The family name the embedded font is registered under; every text style names it.
pub(crate) const FONT: &str = "sans-serif";

/// DejaVu Sans (Bitstream Vera license, see `assets/fonts/LICENSE-DejaVu.txt`), embedded so that
/// a machine without system fonts draws the same text.
static FONT_BYTES: &[u8] = include_bytes!("../../assets/fonts/DejaVuSans.ttf");

/// Registers the embedded font with plotters once per process.
pub(crate) fn register_font() -> Result<(), String> {
    static DONE: OnceLock<Result<(), String>> = OnceLock::new();
    DONE.get_or_init(|| {
        plotters::style::register_font(FONT, FontStyle::Normal, FONT_BYTES)
            .map_err(|_| "the embedded font DejaVuSans.ttf cannot be parsed".to_string())
    })
    .clone()
}

/// What drawing a figure returns; plotters' errors are boxed and turned into
/// [`crate::Error::Plot`] by the caller.
pub(crate) type DrawResult = std::result::Result<(), Box<dyn std::error::Error>>;

/// A figure that can draw itself on any plotters backend (the same code makes SVG and PNG).
pub(crate) trait Figure {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult
    where
        DB::ErrorType: 'static;
}

/// Renders `figure` at `size` (px) to SVG text and PNG bytes.
pub(crate) fn render(figure: &impl Figure, size: (u32, u32)) -> Result<(String, Vec<u8>), String> {
    register_font()?;
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, size).into_drawing_area();
        figure.draw(&root).map_err(|e| e.to_string())?;
        root.present().map_err(|e| e.to_string())?;
    }
    let mut rgb = vec![0u8; size.0 as usize * size.1 as usize * 3];
    {
        let root = BitMapBackend::with_buffer(&mut rgb, size).into_drawing_area();
        figure.draw(&root).map_err(|e| e.to_string())?;
        root.present().map_err(|e| e.to_string())?;
    }
    let mut png_bytes = Vec::new();
    {
        let mut encoder = png::Encoder::new(&mut png_bytes, size.0, size.1);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        let mut writer = encoder.write_header().map_err(|e| e.to_string())?;
        writer.write_image_data(&rgb).map_err(|e| e.to_string())?;
    }
    Ok((svg, png_bytes))
}

/// Text sizes (px) at the figures' scale: titles, axis names, tick labels, legends.
pub(crate) const TITLE: u32 = 30;
pub(crate) const AXIS: u32 = 24;
pub(crate) const TICK: u32 = 19;
pub(crate) const LEGEND: u32 = 19;

pub(crate) fn font(size: u32) -> TextStyle<'static> {
    (FONT, size).into_font().into()
}

/// Hex colour.
const fn hex(c: u32) -> RGBColor {
    RGBColor((c >> 16) as u8, (c >> 8) as u8, c as u8)
}

/// One colour per law, the same in every figure, the live page and Python's plots
/// ([`crate::Law::colour`]).
pub(crate) fn law_color(law: crate::Law) -> RGBColor {
    hex(law.colour())
}

/// One colour per run (δ), in run order.
pub(crate) fn run_color(i: usize) -> RGBColor {
    // Okabe & Ito's blue, vermillion, black, sky blue, reddish purple, orange.
    const RUNS: [u32; 6] = [0x0072b2, 0xd55e00, 0x222222, 0x56b4e9, 0xcc79a7, 0xe69f00];
    hex(RUNS[i % RUNS.len()])
}

/// Calibration data (red circles) and validation data (blue dots), as in the paper: Okabe &
/// Ito's vermillion and blue.
pub(crate) const CALIBRATION: RGBColor = hex(0xd55e00);
pub(crate) const VALIDATION: RGBColor = hex(0x0072b2);
pub(crate) const GRID: RGBColor = hex(0xe6e6e6);

/// The maps' scale of a probability, (p, 0xRRGGBB) stops blended between: a pale blue-grey
/// (a stable cell, drawn, not blank) to blue, one hue, so that no reader has to tell red from
/// green; light enough at 1 that black and coloured curves stay readable on it. The report's
/// maps and the watch's page both draw with it.
pub const PROBABILITY_SCALE: [(f64, u32); 4] = [(0.0, 0xeef2f8), (0.1, 0xdeebf7), (0.5, 0x9ecae1), (1.0, 0x4a90c8)];

/// The heat map's colour of a probability p ∈ [0, 1] on [`PROBABILITY_SCALE`].
pub(crate) fn heat_color(p: f64) -> RGBColor {
    // A cell whose probability is unknown (the torque has no value there): grey, never "stable".
    if p.is_nan() {
        return RGBColor(0xbb, 0xbb, 0xbb);
    }
    const STOPS: [(f64, u32); 4] = PROBABILITY_SCALE;
    let p = p.clamp(0.0, 1.0);
    let k = STOPS.iter().position(|s| s.0 >= p).unwrap_or(STOPS.len() - 1).max(1);
    let ((p0, c0), (p1, c1)) = (STOPS[k - 1], STOPS[k]);
    let t = (p - p0) / (p1 - p0);
    let (a, b) = (hex(c0), hex(c1));
    let mix = |x: u8, y: u8| (f64::from(x) + t * (f64::from(y) - f64::from(x))).round() as u8;
    RGBColor(mix(a.0, b.0), mix(a.1, b.1), mix(a.2, b.2))
}

/// [lo, hi] padded by `pad` of its width on both sides (a point becomes a unit-wide range).
pub(crate) fn padded(lo: f64, hi: f64, pad: f64) -> (f64, f64) {
    if hi.is_nan() || lo.is_nan() || hi <= lo {
        let half = if lo.abs() > 0.0 { 0.05 * lo.abs() } else { 0.5 };
        return (lo - half, hi + half);
    }
    let d = (hi - lo) * pad;
    (lo - d, hi + d)
}

/// Min and max of finite values; `None` for none.
pub(crate) fn extent(values: impl IntoIterator<Item = f64>) -> Option<(f64, f64)> {
    values
        .into_iter()
        .filter(|v| v.is_finite())
        .fold(None, |acc, v| match acc {
            None => Some((v, v)),
            Some((a, b)) => Some((a.min(v), b.max(v))),
        })
}

/// The pieces of a boundary curve that lie inside y ∈ [lo, hi]: a gap where a value is `None`
/// (no weight on bit destabilises), and the exit through the frame interpolated, so that
/// nothing is drawn outside the axes.
pub(crate) fn clip_curve(x: &[f64], y: &[Option<f64>], lo: f64, hi: f64) -> Vec<Vec<(f64, f64)>> {
    let mut pieces: Vec<Vec<(f64, f64)>> = Vec::new();
    let mut current: Vec<(f64, f64)> = Vec::new();
    let inside = |v: f64| v >= lo && v <= hi;
    for i in 0..x.len() {
        // An unknown boundary (NaN: the torque has no value there) is a gap, as no boundary is.
        let Some(v) = y[i].filter(|v| !v.is_nan()) else {
            if current.len() > 1 {
                pieces.push(std::mem::take(&mut current));
            }
            current.clear();
            continue;
        };
        let previous = if i > 0 {
            y[i - 1].filter(|p| !p.is_nan()).map(|p| (x[i - 1], p))
        } else {
            None
        };
        if inside(v) {
            if let Some((px, pv)) = previous
                && !inside(pv)
            {
                let edge = if pv > hi { hi } else { lo };
                current.push((px + (x[i] - px) * (edge - pv) / (v - pv), edge));
            }
            current.push((x[i], v));
        } else if let Some((px, pv)) = previous
            && inside(pv)
        {
            let edge = if v > hi { hi } else { lo };
            current.push((px + (x[i] - px) * (edge - pv) / (v - pv), edge));
            pieces.push(std::mem::take(&mut current));
        }
    }
    if current.len() > 1 {
        pieces.push(current);
    }
    pieces
}

/// Every `k`-th point so that at most `max` remain (drawing 10⁵ markers says no more than 3,000
/// and makes a 10 MB SVG).
pub(crate) fn thinned<T: Copy>(points: &[T], max: usize) -> Vec<T> {
    let step = points.len().div_ceil(max.max(1)).max(1);
    points.iter().step_by(step).copied().collect()
}

/// A parameter's unit as people write it (`s²/rad²` for `s^2/rad^2`).
pub(crate) fn unit(spec: &crate::laws::ParamSpec, torque_unit: &str) -> String {
    spec.unit(torque_unit).replace("^2", "²").replace("^3", "³")
}

/// A number for a tick or a table: 4 significant digits, scientific outside [1e-3, 1e5).
pub(crate) fn short(v: f64) -> String {
    let a = v.abs();
    if a > 0.0 && !(1e-3..1e5).contains(&a) {
        format!("{v:.3e}")
    } else {
        let digits = if a >= 1.0 {
            3usize.saturating_sub(a.log10().floor() as usize)
        } else {
            4
        };
        let s = format!("{v:.digits$}");
        if s.contains('.') {
            s.trim_end_matches('0').trim_end_matches('.').to_string()
        } else {
            s
        }
    }
}

/// The power of ten an axis over `lo..hi` counts in, so that its ticks read short: 0 where its
/// largest magnitude lies in [1e-2, 1e4), else that magnitude's power (a0 ≈ 1.05·10¹⁰ kN·m:
/// ticks 0.5, 1, 1.5 in 10¹⁰ kN·m, not 5.000e9 overlapping 1.000e10).
pub(crate) fn axis_power(lo: f64, hi: f64) -> i32 {
    let a = lo.abs().max(hi.abs());
    if !a.is_finite() || a == 0.0 || (1e-2..1e4).contains(&a) {
        0
    } else {
        a.log10().floor() as i32
    }
}

/// The tick of `v` on an axis counting in 10^`power` ([`axis_power`]).
pub(crate) fn tick_in(v: f64, power: i32) -> String {
    short(v / 10f64.powi(power))
}

/// An axis name in the power of ten `power` its ticks count in: "a0 (kN·m)" reads
/// "a0 (10¹⁰ kN·m)", "density" reads "density (10⁻¹⁰)".
pub(crate) fn in_power(name: &str, power: i32) -> String {
    if power == 0 {
        return name.to_string();
    }
    const DIGITS: [char; 10] = ['⁰', '¹', '²', '³', '⁴', '⁵', '⁶', '⁷', '⁸', '⁹'];
    let mut exponent: String = power
        .unsigned_abs()
        .to_string()
        .chars()
        .map(|d| DIGITS[d.to_digit(10).expect("a digit") as usize])
        .collect();
    if power < 0 {
        exponent.insert(0, '⁻');
    }
    match name.strip_suffix(')').and_then(|n| n.split_once(" (")) {
        Some((head, unit)) => format!("{head} (10{exponent} {unit})"),
        None => format!("{name} (10{exponent})"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_axis_of_long_numbers_counts_in_a_power_of_ten() {
        assert_eq!(axis_power(1.2e9, 2.0e10), 10);
        assert_eq!(axis_power(-8.0e-5, -3.5e-5), -5);
        assert_eq!(axis_power(0.0, 1.0e-10), -10);
        assert_eq!(
            (
                axis_power(-300.0, -100.0),
                axis_power(0.0, 0.0),
                axis_power(0.01, 9999.0)
            ),
            (0, 0, 0)
        );
        assert_eq!(tick_in(1.5e10, 10), "1.5");
        assert_eq!(tick_in(-6.0e-5, -5), "-6");
        assert_eq!(in_power("a0 (kN·m)", 10), "a0 (10¹⁰ kN·m)");
        assert_eq!(in_power("c2 (N·m·s²/rad²)", -5), "c2 (10⁻⁵ N·m·s²/rad²)");
        assert_eq!(in_power("density", -10), "density (10⁻¹⁰)");
        assert_eq!(in_power("a1 (s²/rad²)", 0), "a1 (s²/rad²)");
    }

    #[test]
    fn curves_are_cut_at_gaps_and_at_the_frame() {
        let x = [0.0, 1.0, 2.0, 3.0, 4.0];
        let y = [Some(1.0), Some(3.0), None, Some(1.0), Some(1.5)];
        let pieces = clip_curve(&x, &y, 0.0, 2.0);
        assert_eq!(pieces.len(), 2);
        assert_eq!(pieces[0], vec![(0.0, 1.0), (0.5, 2.0)]);
        assert_eq!(pieces[1], vec![(3.0, 1.0), (4.0, 1.5)]);
    }

    #[test]
    fn numbers_read_short() {
        assert_eq!(short(13.0), "13");
        assert_eq!(short(0.30012), "0.3001");
        assert_eq!(short(-0.00012), "-1.200e-4");
        assert_eq!(short(244.25), "244.2");
        assert_eq!(short(1234.7), "1235");
    }
}
