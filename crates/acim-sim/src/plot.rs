//! Paper-style PNG figures of simulation traces.
//!
//! [`render_panels`] draws a column of panels that share one time axis: a figure
//! title at the top, then per panel a title and a legend above the plot, its own
//! y range taken from its data, and the time axis described under the last panel.
//!
//! Lines are drawn by `plotters` on its pure-Rust bitmap backend and written with its
//! PNG encoder. Text is rasterised here with `ab_glyph` from a font embedded in the
//! binary (`assets/DejaVuSans.ttf`, licence in `assets/LICENSE-DejaVu.txt`), so neither
//! building nor running needs fontconfig, freetype or any system font. (Axes, ticks
//! and labels are drawn here too rather than by plotters' mesh: plotters 0.3.7's
//! `ab_glyph` text path drops glyph side bearings, which spaces digits unevenly.)
//!
//! Long series are decimated before drawing: at most [`MAX_POINTS_PER_SERIES`] points
//! (and two per pixel column), keeping the minimum and the maximum of each bucket so
//! that short spikes stay visible. Non-finite samples (NaN, ±inf) are skipped and
//! break the line.

use std::fmt;
use std::path::Path;
use std::sync::OnceLock;

use ab_glyph::{Font, FontRef, PxScale, ScaleFont};
use plotters::backend::BitMapBackend;
use plotters::chart::ChartBuilder;
use plotters::coord::Shift;
use plotters::drawing::{DrawingArea, IntoDrawingArea};
use plotters::element::{Circle, PathElement, Rectangle};
use plotters::style::{Color as _, RGBColor, ShapeStyle, BLACK, WHITE};

/// Most points drawn per series; longer series are reduced to min/max pairs per bucket.
pub const MAX_POINTS_PER_SERIES: usize = 4000;

/// Font embedded in the binary (DejaVu Sans 2.37, Bitstream Vera licence).
static FONT_BYTES: &[u8] = include_bytes!("../assets/DejaVuSans.ttf");

/// Line colours: a print-friendly palette (matplotlib's "tab10") plus free RGB.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[allow(dead_code)] // a palette: callers need not use every colour
pub enum Color {
    /// Black (tab10 palette).
    Black,
    /// Blue (tab10 palette).
    Blue,
    /// Orange (tab10 palette).
    Orange,
    /// Green (tab10 palette).
    Green,
    /// Red (tab10 palette).
    Red,
    /// Purple (tab10 palette).
    Purple,
    /// Brown (tab10 palette).
    Brown,
    /// Gray (tab10 palette).
    Gray,
    /// Any colour, red, green, blue.
    Rgb(u8, u8, u8),
}

impl Color {
    fn rgb(self) -> RGBColor {
        match self {
            Color::Black => RGBColor(0, 0, 0),
            Color::Blue => RGBColor(31, 119, 180),
            Color::Orange => RGBColor(255, 127, 14),
            Color::Green => RGBColor(44, 160, 44),
            Color::Red => RGBColor(214, 39, 40),
            Color::Purple => RGBColor(148, 103, 189),
            Color::Brown => RGBColor(140, 86, 75),
            Color::Gray => RGBColor(127, 127, 127),
            Color::Rgb(r, g, b) => RGBColor(r, g, b),
        }
    }
}

/// How one series is stroked.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LineStyle {
    /// A continuous line.
    Solid(Color),
    /// A dashed line (references, limits).
    Dashed(Color),
}

impl LineStyle {
    fn color(self) -> Color {
        match self {
            LineStyle::Solid(c) | LineStyle::Dashed(c) => c,
        }
    }
    fn is_dashed(self) -> bool {
        matches!(self, LineStyle::Dashed(_))
    }
}

/// One trace. `values[i]` is drawn at `time_s[i]`; if the two lengths differ, only
/// the common prefix is drawn.
#[derive(Clone, Debug)]
pub struct Series<'a> {
    /// Legend text.
    pub label: &'a str,
    /// Samples, in the y-axis unit of the panel.
    pub values: &'a [f32],
    /// Stroke.
    pub style: LineStyle,
}

/// One plot of the column: a title, a y-axis description (with unit) and its traces.
#[derive(Clone, Debug)]
pub struct Panel<'a> {
    /// Title above the panel.
    pub title: &'a str,
    /// y-axis label, with its unit.
    pub y_label: &'a str,
    /// The traces drawn in this panel.
    pub series: Vec<Series<'a>>,
}

/// What a run's figure marks behind its traces, in every panel: shaded time spans (the
/// metric windows) and vertical lines (state changes, a fault).
#[derive(Clone, Debug, Default)]
pub struct Marks {
    /// Shaded spans, (from, to) in x-axis units.
    pub spans: Vec<(f64, f64)>,
    /// Vertical lines at an x value, in a colour.
    pub lines: Vec<(f64, Color)>,
}

/// The shading of [`Marks::spans`] (a pale blue behind the grid's gray).
pub const SPAN_COLOR: Color = Color::Rgb(222, 235, 250);

/// Why a figure could not be rendered.
#[derive(Debug)]
pub enum PlotError {
    /// The arguments cannot give a figure (no panels, no time samples, bad size or path).
    InvalidInput(String),
    /// The embedded font could not be parsed.
    Font,
    /// Drawing or writing the PNG failed (message from `plotters` / the encoder).
    Draw(String),
}

impl fmt::Display for PlotError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            PlotError::InvalidInput(msg) => write!(f, "invalid plot input: {msg}"),
            PlotError::Font => write!(f, "the embedded plot font could not be parsed"),
            PlotError::Draw(msg) => write!(f, "plot drawing failed: {msg}"),
        }
    }
}

impl std::error::Error for PlotError {}

fn draw_err<E: fmt::Display>(e: E) -> PlotError {
    PlotError::Draw(e.to_string())
}

type Area<'b> = DrawingArea<BitMapBackend<'b>, Shift>;

// ---------------------------------------------------------------------------------------
// Text

fn font() -> Result<&'static FontRef<'static>, PlotError> {
    static FONT: OnceLock<Option<FontRef<'static>>> = OnceLock::new();
    FONT.get_or_init(|| FontRef::try_from_slice(FONT_BYTES).ok())
        .as_ref()
        .ok_or(PlotError::Font)
}

/// Where the anchor point sits on the text box, along one direction.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum Align {
    Start,
    Center,
    End,
}

impl Align {
    fn offset(self, extent: f32) -> f32 {
        match self {
            Align::Start => 0.0,
            Align::Center => extent / 2.0,
            Align::End => extent,
        }
    }
}

/// A text style: pixel size (ascent to descent), colour, alignment, orientation.
#[derive(Clone, Copy)]
struct Txt {
    size: f32,
    color: RGBColor,
    h: Align,
    v: Align,
    /// Turned a quarter left, reading upwards (for y-axis descriptions).
    upward: bool,
}

impl Txt {
    fn new(size: f32, h: Align, v: Align) -> Self {
        Txt {
            size,
            color: BLACK,
            h,
            v,
            upward: false,
        }
    }

    /// Advance width of `text` in pixels.
    fn width(&self, font: &FontRef<'static>, text: &str) -> f32 {
        let sf = font.as_scaled(PxScale::from(self.size));
        let mut caret = 0.0;
        let mut prev = None;
        for c in text.chars() {
            let id = sf.glyph_id(c);
            if let Some(p) = prev {
                caret += sf.kern(p, id);
            }
            caret += sf.h_advance(id);
            prev = Some(id);
        }
        caret
    }

    /// Draws `text` anchored at `at` (pixels of `area`), blending anti-aliased coverage.
    fn draw(
        &self,
        area: &Area,
        font: &FontRef<'static>,
        text: &str,
        at: (i32, i32),
    ) -> Result<(), PlotError> {
        let sf = font.as_scaled(PxScale::from(self.size));
        let box_w = self.width(font, text);
        let box_h = sf.ascent() - sf.descent();
        // Whole-pixel offsets keep the glyph rows contiguous (no doubled or skipped row).
        let (dx, dy) = (
            self.h.offset(box_w).round() as i32,
            self.v.offset(box_h).round() as i32,
        );
        let mut caret = 0.0;
        let mut prev = None;
        for c in text.chars() {
            let id = sf.glyph_id(c);
            if let Some(p) = prev {
                caret += sf.kern(p, id);
            }
            let glyph = id.with_scale_and_position(self.size, ab_glyph::point(caret, sf.ascent()));
            caret += sf.h_advance(id);
            prev = Some(id);
            let Some(outline) = font.outline_glyph(glyph) else {
                continue;
            };
            let bounds = outline.px_bounds();
            let mut result = Ok(());
            outline.draw(|gx, gy, coverage| {
                if coverage < 0.01 || result.is_err() {
                    return;
                }
                // Text-box coordinates: x along the text, y down from the box top.
                let lx = bounds.min.x as i32 + gx as i32 - dx;
                let ly = bounds.min.y as i32 + gy as i32 - dy;
                let (x, y) = if self.upward {
                    (at.0 + ly, at.1 - lx)
                } else {
                    (at.0 + lx, at.1 + ly)
                };
                result = area
                    .draw_pixel((x, y), &self.color.mix(f64::from(coverage.min(1.0))))
                    .map_err(draw_err);
            });
            result?;
        }
        Ok(())
    }
}

/// A polyline without gaps, in data coordinates (time s, value).
type Segment = Vec<(f64, f64)>;

/// Splits a series into drawable segments, skipping non-finite samples (which break the
/// line) and reducing it to at most `max_points` points: when longer, the samples are
/// cut into `max_points / 2` buckets and each bucket keeps its minimum and maximum, in
/// time order, so that spikes survive. A bucket with no finite sample breaks the line.
fn decimate(time_s: &[f32], values: &[f32], max_points: usize) -> Vec<Segment> {
    let n = time_s.len().min(values.len());
    let finite = |i: usize| time_s[i].is_finite() && values[i].is_finite();
    let point = |i: usize| (f64::from(time_s[i]), f64::from(values[i]));
    let mut segments = Vec::new();
    let mut current: Segment = Vec::new();
    let max_points = max_points.max(2);

    if n <= max_points {
        for i in 0..n {
            if finite(i) {
                current.push(point(i));
            } else if !current.is_empty() {
                segments.push(std::mem::take(&mut current));
            }
        }
    } else {
        let buckets = max_points / 2;
        for b in 0..buckets {
            let lo = b * n / buckets;
            let hi = (b + 1) * n / buckets;
            let mut imin = None::<usize>;
            let mut imax = None::<usize>;
            for i in lo..hi {
                if !finite(i) {
                    continue;
                }
                if imin.is_none_or(|j| values[i] < values[j]) {
                    imin = Some(i);
                }
                if imax.is_none_or(|j| values[i] > values[j]) {
                    imax = Some(i);
                }
            }
            match (imin, imax) {
                (Some(a), Some(b)) => {
                    let (first, second) = if a <= b { (a, b) } else { (b, a) };
                    current.push(point(first));
                    if second != first {
                        current.push(point(second));
                    }
                }
                _ => {
                    if !current.is_empty() {
                        segments.push(std::mem::take(&mut current));
                    }
                }
            }
        }
    }
    if !current.is_empty() {
        segments.push(current);
    }
    segments
}

/// Cuts segments into dashes by position along the time axis (`on` drawn, `off` blank,
/// both in time units, phase anchored at `x0`). Dashing by x rather than by path length
/// keeps a regular pattern even on dense, noisy traces.
fn dash_segments(segments: &[Segment], x0: f64, on: f64, off: f64) -> Vec<Segment> {
    let period = on + off;
    if !(on > 0.0 && off > 0.0 && period.is_finite()) {
        return segments.to_vec();
    }
    let is_on = |x: f64| (x - x0).rem_euclid(period) < on;
    let mut dashes = Vec::new();
    for seg in segments {
        let Some(&first) = seg.first() else { continue };
        let mut on_now = is_on(first.0);
        let mut cur: Segment = if on_now { vec![first] } else { Vec::new() };
        for pair in seg.windows(2) {
            let ((xa, ya), (xb, yb)) = (pair[0], pair[1]);
            let mut x = xa;
            // Walk the dash boundaries strictly between xa and xb.
            for _ in 0..100_000 {
                let k = ((x - x0) / period).floor();
                let end_on = x0 + k * period + on;
                let start_on = x0 + (k + 1.0) * period;
                let (boundary, turns_on) = if end_on > x {
                    (end_on, false)
                } else {
                    (start_on, true)
                };
                if boundary.is_nan() || boundary <= x || boundary >= xb {
                    break;
                }
                let y = ya + (yb - ya) * (boundary - xa) / (xb - xa);
                if turns_on {
                    cur = vec![(boundary, y)];
                } else if on_now {
                    cur.push((boundary, y));
                    dashes.push(std::mem::take(&mut cur));
                }
                on_now = turns_on;
                x = boundary;
            }
            if on_now {
                cur.push((xb, yb));
            }
        }
        if cur.len() >= 2 {
            dashes.push(cur);
        }
    }
    dashes
}

/// The values drawn for a series: finite samples at finite times, within the common prefix.
fn finite_values<'s>(time_s: &'s [f32], values: &'s [f32]) -> impl Iterator<Item = f64> + 's {
    time_s
        .iter()
        .zip(values)
        .filter(|(t, v)| t.is_finite() && v.is_finite())
        .map(|(_, &v)| f64::from(v))
}

/// Range of `values` with a small margin; padded when flat, (-1, 1) when empty.
fn value_range(values: impl IntoIterator<Item = f64>) -> (f64, f64) {
    let mut lo = f64::INFINITY;
    let mut hi = f64::NEG_INFINITY;
    for y in values {
        lo = lo.min(y);
        hi = hi.max(y);
    }
    if !(lo.is_finite() && hi.is_finite()) {
        return (-1.0, 1.0);
    }
    let span = hi - lo;
    let magnitude = lo.abs().max(hi.abs());
    if span <= magnitude * 1e-9 || span == 0.0 {
        let mid = 0.5 * (lo + hi);
        let pad = if magnitude > 0.0 {
            magnitude * 0.05
        } else {
            1.0
        };
        return (mid - pad, mid + pad);
    }
    let margin = span * 0.06;
    (lo - margin, hi + margin)
}

/// Time range of the finite samples; padded by half a second when it is a single instant.
fn time_range(time_s: &[f32]) -> Option<(f64, f64)> {
    let (lo, hi) = time_s
        .iter()
        .filter(|t| t.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &t| {
            (lo.min(f64::from(t)), hi.max(f64::from(t)))
        });
    if !(lo.is_finite() && hi.is_finite()) {
        return None;
    }
    if hi > lo {
        Some((lo, hi))
    } else {
        Some((lo - 0.5, hi + 0.5))
    }
}

// ---------------------------------------------------------------------------------------
// Ticks

/// A "nice" tick step (1, 2, 2.5 or 5 × 10^k) giving at most `max_ticks` intervals over `span`.
fn nice_step(span: f64, max_ticks: usize) -> f64 {
    let raw = span / max_ticks.max(1) as f64;
    if !(raw.is_finite() && raw > 0.0) {
        return 1.0;
    }
    let mag = 10f64.powf(raw.log10().floor());
    [1.0, 2.0, 2.5, 5.0, 10.0]
        .into_iter()
        .map(|m| m * mag)
        .find(|&s| s >= raw * (1.0 - 1e-9))
        .unwrap_or(10.0 * mag)
}

/// Multiples of `step` within `[lo, hi]` (at most 200).
fn tick_values(lo: f64, hi: f64, step: f64) -> Vec<f64> {
    let k0 = (lo / step - 1e-9).ceil();
    let k1 = (hi / step + 1e-9).floor();
    if !(k0.is_finite() && k1.is_finite()) || k1 < k0 || k1 - k0 > 200.0 {
        return Vec::new();
    }
    (0..=(k1 - k0) as i64)
        .map(|i| (k0 + i as f64) * step)
        .collect()
}

/// Tick label format for ticks `step` apart on an axis reaching `magnitude`.
#[derive(Clone, Copy, Debug)]
struct TickFormat {
    step: f64,
    /// Fixed decimals for every label, or `None` for shortest scientific notation.
    decimals: Option<usize>,
}

impl TickFormat {
    fn new(step: f64, magnitude: f64) -> Self {
        if magnitude >= 1e6 || step.is_nan() || step < 1e-5 {
            return TickFormat {
                step,
                decimals: None,
            };
        }
        // Fewest decimals that write the step exactly (0.25 -> 2, 0.5 -> 1, 500 -> 0).
        let decimals = (0..=8)
            .find(|&d| {
                let x = step * 10f64.powi(d);
                (x - x.round()).abs() <= 1e-6 * x.max(1.0)
            })
            .unwrap_or(8) as usize;
        TickFormat {
            step,
            decimals: Some(decimals),
        }
    }

    fn format(self, v: f64) -> String {
        let s = match self.decimals {
            Some(d) => format!("{v:.d$}"),
            None if v.abs() <= self.step.abs() * 1e-6 => "0".to_string(),
            None => (0..=6)
                .map(|p| format!("{v:.p$e}"))
                .find(|s| {
                    s.parse::<f64>()
                        .is_ok_and(|back| (back - v).abs() <= self.step.abs() * 1e-3)
                })
                .unwrap_or_else(|| format!("{v:.6e}")),
        };
        // Never print "-0" / "-0.00"; use a true minus sign.
        match s.strip_prefix('-') {
            Some(rest) if rest.chars().all(|c| c == '0' || c == '.') => rest.to_string(),
            Some(rest) => format!("\u{2212}{rest}"),
            None => s,
        }
    }
}

// ---------------------------------------------------------------------------------------
// Figure

/// Sizes in pixels, scaled from a 1600 px wide reference figure.
struct Metrics {
    title: Txt,
    panel_title: Txt,
    legend: Txt,
    tick_y: Txt,
    tick_x: Txt,
    desc_x: Txt,
    desc_y: Txt,
    stroke: u32,
    margin_left: i32,
    margin_right: i32,
    title_h: i32,
    header_row_h: i32,
    tick_len: i32,
    gap: i32,
    legend_sample: i32,
    legend_gap: i32,
    dash_on_px: f64,
    dash_off_px: f64,
}

impl Metrics {
    fn new(width: u32) -> Self {
        let s = (f64::from(width) / 1600.0).clamp(0.5, 4.0);
        let px = |v: f64| (v * s).round() as i32;
        let f = |v: f64| (v * s) as f32;
        let upward = Txt {
            upward: true,
            ..Txt::new(f(19.0), Align::Center, Align::Center)
        };
        Metrics {
            title: Txt::new(f(32.0), Align::Center, Align::Center),
            panel_title: Txt::new(f(22.0), Align::Start, Align::Center),
            legend: Txt::new(f(19.0), Align::Start, Align::Center),
            tick_y: Txt::new(f(17.0), Align::End, Align::Center),
            tick_x: Txt::new(f(17.0), Align::Center, Align::Start),
            desc_x: Txt::new(f(19.0), Align::Center, Align::Start),
            desc_y: upward,
            stroke: ((2.0 * s).round() as u32).max(1),
            margin_left: px(14.0),
            margin_right: px(30.0),
            title_h: px(56.0),
            header_row_h: px(32.0),
            tick_len: px(6.0).max(3),
            gap: px(5.0).max(2),
            legend_sample: px(40.0),
            legend_gap: px(26.0),
            dash_on_px: 11.0 * s,
            dash_off_px: 7.0 * s,
        }
    }
}

/// Renders `panels` stacked vertically over the shared time axis `time_s` (seconds) into
/// a PNG file at `path` of `width` × `height` pixels, with `title` at the top.
///
/// Each panel gets its own y range from its finite data (with a small margin). Good
/// sizes are about 1600 px wide and 300–350 px per panel.
pub fn render_panels(
    path: &Path,
    title: &str,
    time_s: &[f32],
    panels: &[Panel],
    width: u32,
    height: u32,
) -> Result<(), PlotError> {
    render_panels_over(path, title, "Time (s)", time_s, panels, width, height)
}

/// [`render_panels`] with [`Marks`] drawn behind the traces of every panel.
pub fn render_panels_marked(
    path: &Path,
    title: &str,
    time_s: &[f32],
    panels: &[Panel],
    width: u32,
    height: u32,
    marks: &Marks,
) -> Result<(), PlotError> {
    render(
        path, title, "Time (s)", time_s, panels, width, height, marks,
    )
}

/// [`render_panels`] over any ascending x axis `x`, labelled `x_label`.
pub fn render_panels_over(
    path: &Path,
    title: &str,
    x_label: &str,
    time_s: &[f32],
    panels: &[Panel],
    width: u32,
    height: u32,
) -> Result<(), PlotError> {
    render(
        path,
        title,
        x_label,
        time_s,
        panels,
        width,
        height,
        &Marks::default(),
    )
}

#[allow(clippy::too_many_arguments)] // the figure's whole description, private
fn render(
    path: &Path,
    title: &str,
    x_label: &str,
    time_s: &[f32],
    panels: &[Panel],
    width: u32,
    height: u32,
    marks: &Marks,
) -> Result<(), PlotError> {
    if panels.is_empty() {
        return Err(PlotError::InvalidInput("no panels".into()));
    }
    let is_png = path
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("png"));
    if !is_png {
        return Err(PlotError::InvalidInput(format!(
            "output path {} must end in .png",
            path.display()
        )));
    }
    let min_height = 100 + 120 * panels.len() as u32;
    if !(400..=16_000).contains(&width) || !(min_height..=16_000).contains(&height) {
        return Err(PlotError::InvalidInput(format!(
            "figure size {width}x{height} px: need width 400..=16000 and height {min_height}..=16000 for {} panels",
            panels.len()
        )));
    }
    let (mut t0, mut t1) = time_range(time_s)
        .ok_or_else(|| PlotError::InvalidInput("no finite time samples".into()))?;
    let font = font()?;
    let m = Metrics::new(width);

    // Y ranges, tick steps and label formats per panel.
    let ranges: Vec<(f64, f64)> = panels
        .iter()
        .map(|p| {
            value_range(
                p.series
                    .iter()
                    .flat_map(|s| finite_values(time_s, s.values)),
            )
        })
        .collect();

    // Horizontal layout: one y-label area width for all panels so the plots line up.
    // The tick count per panel is chosen later from the plot height, so measure the
    // labels of every count it can take (2..=8).
    let mut widest_tick = 0.0f32;
    for &(lo, hi) in &ranges {
        for max_ticks in 2..=8 {
            let step = nice_step(hi - lo, max_ticks);
            let fmt = TickFormat::new(step, lo.abs().max(hi.abs()));
            for v in tick_values(lo, hi, step) {
                widest_tick = widest_tick.max(m.tick_y.width(font, &fmt.format(v)));
            }
        }
    }
    let desc_h = m.desc_y.size.ceil() as i32;
    let plot_left =
        m.margin_left + desc_h + 2 * m.gap + widest_tick.ceil() as i32 + m.gap + m.tick_len;
    let plot_right = width as i32 - m.margin_right;
    let plot_w = (plot_right - plot_left).max(1);

    // Time axis: nice ticks; snap the ends out to a tick when that adds < 2 % of span.
    let x_step = nice_step(
        t1 - t0,
        ((plot_w as f32 / (m.tick_x.size * 8.0)) as usize).clamp(2, 10),
    );
    let (s0, s1) = (
        (t0 / x_step).floor() * x_step,
        (t1 / x_step).ceil() * x_step,
    );
    if t0 - s0 <= 0.02 * (t1 - t0) {
        t0 = s0;
    }
    if s1 - t1 <= 0.02 * (t1 - t0) {
        t1 = s1;
    }
    let x_ticks = tick_values(t0, t1, x_step);
    let x_format = TickFormat::new(x_step, t0.abs().max(t1.abs()));

    // Panel headers: title at the left, legend entries flowing right-aligned after it.
    let mut layouts: Vec<Vec<Vec<(usize, i32)>>> = Vec::with_capacity(panels.len());
    for panel in panels {
        let title_w = m.panel_title.width(font, panel.title).ceil() as i32;
        let mut rows: Vec<Vec<(usize, i32)>> = vec![Vec::new()];
        let mut row_used = 0;
        let mut row_cap = plot_w - title_w - m.legend_gap;
        for (i, s) in panel.series.iter().enumerate() {
            let w = m.legend_sample + m.gap * 2 + m.legend.width(font, s.label).ceil() as i32;
            let needed = if row_used == 0 {
                w
            } else {
                row_used + m.legend_gap + w
            };
            if needed > row_cap && row_used > 0 {
                rows.push(Vec::new());
                row_cap = plot_w;
                row_used = w;
            } else {
                row_used = needed;
            }
            rows.last_mut().expect("rows is never empty").push((i, w));
        }
        layouts.push(rows);
    }

    // Vertical layout.
    let x_labels_h = m.tick_len + m.gap + m.tick_x.size.ceil() as i32 + m.gap;
    let x_desc_h = m.desc_x.size.ceil() as i32 + 2 * m.gap;
    let headers: Vec<i32> = layouts
        .iter()
        .map(|rows| rows.len() as i32 * m.header_row_h)
        .collect();
    let fixed =
        m.title_h + x_desc_h + headers.iter().sum::<i32>() + x_labels_h * panels.len() as i32;
    let plot_h = (height as i32 - fixed) / panels.len() as i32;
    if plot_h < 40 {
        return Err(PlotError::InvalidInput(format!(
            "figure height {height} px leaves only {plot_h} px per plot; make it taller"
        )));
    }

    let root = BitMapBackend::new(path, (width, height)).into_drawing_area();
    root.fill(&WHITE).map_err(draw_err)?;
    // a title wider than the figure is set smaller to fit (it was clipped at both ends)
    let mut title_txt = m.title;
    let fit = 0.97 * width as f32;
    let title_w = title_txt.width(font, title);
    if title_w > fit {
        title_txt.size *= fit / title_w;
    }
    title_txt.draw(&root, font, title, (width as i32 / 2, m.title_h / 2))?;

    // Decimate to at most two points per pixel column (and MAX_POINTS_PER_SERIES).
    let max_points = (2 * plot_w as usize).min(MAX_POINTS_PER_SERIES);
    let grid = RGBColor(220, 220, 220);
    let mut top = m.title_h;
    for (k, panel) in panels.iter().enumerate() {
        let header_top = top;
        let py0 = top + headers[k];
        let py1 = py0 + plot_h;
        top = py1 + x_labels_h;
        let (y0, y1) = ranges[k];
        let y_step = nice_step(
            y1 - y0,
            ((plot_h as f32 / (m.tick_y.size * 2.6)) as usize).clamp(2, 8),
        );
        let y_format = TickFormat::new(y_step, y0.abs().max(y1.abs()));
        let y_ticks = tick_values(y0, y1, y_step);

        let plot_area = root
            .clone()
            .shrink((plot_left, py0), (plot_w as u32, plot_h as u32));
        let mut chart = ChartBuilder::on(&plot_area)
            .build_cartesian_2d(t0..t1, y0..y1)
            .map_err(draw_err)?;
        let mapping = chart.plotting_area().clone();
        let to_px = |x: f64, y: f64| mapping.map_coordinate(&(x, y));

        // Grid.
        for &x in &x_ticks {
            let (gx, _) = to_px(x, y0);
            root.draw(&PathElement::new(vec![(gx, py0), (gx, py1 - 1)], grid))
                .map_err(draw_err)?;
        }
        for &y in &y_ticks {
            let (_, gy) = to_px(t0, y);
            root.draw(&PathElement::new(
                vec![(plot_left, gy), (plot_right - 1, gy)],
                grid,
            ))
            .map_err(draw_err)?;
        }

        // Marks: shaded spans and vertical lines, clipped to the axis.
        for &(a, b) in &marks.spans {
            let (a, b) = (a.max(t0), b.min(t1));
            if b > a {
                let (xa, _) = to_px(a, y0);
                let (xb, _) = to_px(b, y0);
                root.draw(&Rectangle::new(
                    [(xa, py0 + 1), (xb, py1 - 2)],
                    SPAN_COLOR.rgb().filled(),
                ))
                .map_err(draw_err)?;
            }
        }
        for &(x, c) in &marks.lines {
            if x >= t0 && x <= t1 {
                let (gx, _) = to_px(x, y0);
                root.draw(&PathElement::new(
                    vec![(gx, py0), (gx, py1 - 1)],
                    ShapeStyle::from(&c.rgb()).stroke_width(1),
                ))
                .map_err(draw_err)?;
            }
        }

        // Traces.
        let s_per_px = (t1 - t0) / f64::from(plot_w);
        for series in &panel.series {
            let segments = decimate(time_s, series.values, max_points);
            let style = ShapeStyle::from(&series.style.color().rgb()).stroke_width(m.stroke);
            let drawn = if series.style.is_dashed() {
                dash_segments(
                    &segments,
                    t0,
                    m.dash_on_px * s_per_px,
                    m.dash_off_px * s_per_px,
                )
            } else {
                segments.clone()
            };
            // Thick polylines are drawn one straight piece at a time: plotters joins the
            // pieces of a wide path with miters, which shoot far out of the plot on the
            // sharp zigzags of a dense min/max envelope.
            let pieces = drawn
                .iter()
                .flat_map(|s| s.windows(2))
                .map(|w| PathElement::new(vec![w[0], w[1]], style));
            chart.draw_series(pieces).map_err(draw_err)?;
            // Isolated finite samples between gaps: a dot, so they are not lost.
            let dots = segments
                .iter()
                .filter(|s| s.len() == 1)
                .map(|s| Circle::new(s[0], m.stroke.max(2), style.filled()));
            chart.draw_series(dots).map_err(draw_err)?;
        }

        // Frame, ticks and tick labels.
        root.draw(&Rectangle::new(
            [(plot_left, py0), (plot_right - 1, py1 - 1)],
            BLACK.stroke_width(1),
        ))
        .map_err(draw_err)?;
        for &x in &x_ticks {
            let (gx, _) = to_px(x, y0);
            root.draw(&PathElement::new(
                vec![(gx, py1), (gx, py1 + m.tick_len)],
                BLACK,
            ))
            .map_err(draw_err)?;
            m.tick_x.draw(
                &root,
                font,
                &x_format.format(x),
                (gx, py1 + m.tick_len + m.gap),
            )?;
        }
        for &y in &y_ticks {
            let (_, gy) = to_px(t0, y);
            root.draw(&PathElement::new(
                vec![(plot_left - m.tick_len, gy), (plot_left - 1, gy)],
                BLACK,
            ))
            .map_err(draw_err)?;
            m.tick_y.draw(
                &root,
                font,
                &y_format.format(y),
                (plot_left - m.tick_len - m.gap, gy),
            )?;
        }
        m.desc_y.draw(
            &root,
            font,
            panel.y_label,
            (m.margin_left + desc_h / 2, (py0 + py1) / 2),
        )?;

        // Header: panel title and legend.
        let row_mid = |r: usize| header_top + r as i32 * m.header_row_h + m.header_row_h / 2;
        m.panel_title
            .draw(&root, font, panel.title, (plot_left, row_mid(0)))?;
        for (r, row) in layouts[k].iter().enumerate() {
            let row_w: i32 = row.iter().map(|&(_, w)| w).sum::<i32>()
                + m.legend_gap * (row.len() as i32 - 1).max(0);
            let mut x = plot_right - row_w;
            let yc = row_mid(r);
            for &(i, w) in row {
                let series = &panel.series[i];
                let style = ShapeStyle::from(&series.style.color().rgb()).stroke_width(m.stroke);
                let sample: Vec<(i32, i32)> = if series.style.is_dashed() {
                    let d = m.legend_sample / 3;
                    (0..3)
                        .map(|j| (x + j * d, x + j * d + (d * 2) / 3))
                        .collect()
                } else {
                    vec![(x, x + m.legend_sample)]
                };
                for (a, b) in sample {
                    root.draw(&PathElement::new(vec![(a, yc), (b, yc)], style))
                        .map_err(draw_err)?;
                }
                m.legend.draw(
                    &root,
                    font,
                    series.label,
                    (x + m.legend_sample + m.gap * 2, yc),
                )?;
                x += w + m.legend_gap;
            }
        }
    }
    m.desc_x.draw(
        &root,
        font,
        x_label,
        ((plot_left + plot_right) / 2, top + m.gap),
    )?;

    root.present().map_err(draw_err)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn synthetic(n: usize) -> (Vec<f32>, Vec<f32>, Vec<f32>, Vec<f32>) {
        let t: Vec<f32> = (0..n).map(|i| i as f32 * 2e-4).collect();
        let a: Vec<f32> = t.iter().map(|&t| 1000.0 * (t * 2.0).sin()).collect();
        let mut b: Vec<f32> = t
            .iter()
            .map(|&t| 1000.0 * (t * 2.0).sin() + 5.0 * (t * 900.0).sin())
            .collect();
        b[n / 3] = f32::NAN;
        b[n / 2] = f32::INFINITY;
        let c: Vec<f32> = t.iter().map(|&t| if t < 1.0 { 0.0 } else { 2.5 }).collect();
        (t, a, b, c)
    }

    #[test]
    fn renders_four_panel_png() {
        let (t, a, b, c) = synthetic(20_000);
        let err: Vec<f32> = a.iter().zip(&b).map(|(a, b)| b - a).collect();
        let flat = vec![3.0f32; t.len()];
        let nans = vec![f32::NAN; t.len()];
        let panels = [
            Panel {
                title: "Speed",
                y_label: "Speed (rpm)",
                series: vec![
                    Series {
                        label: "reference",
                        values: &a,
                        style: LineStyle::Solid(Color::Black),
                    },
                    Series {
                        label: "estimated",
                        values: &b,
                        style: LineStyle::Dashed(Color::Red),
                    },
                ],
            },
            Panel {
                title: "Error",
                y_label: "Error (rpm)",
                series: vec![Series {
                    label: "error",
                    values: &err,
                    style: LineStyle::Solid(Color::Blue),
                }],
            },
            Panel {
                title: "Flat and empty",
                y_label: "x",
                series: vec![
                    Series {
                        label: "flat",
                        values: &flat,
                        style: LineStyle::Solid(Color::Green),
                    },
                    Series {
                        label: "all NaN",
                        values: &nans,
                        style: LineStyle::Solid(Color::Gray),
                    },
                ],
            },
            Panel {
                title: "Load",
                y_label: "Torque (N m)",
                series: vec![Series {
                    label: "load",
                    values: &c,
                    style: LineStyle::Solid(Color::Orange),
                }],
            },
        ];
        let dir = std::env::temp_dir().join(format!("acim-plot-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("four_panels.png");
        render_panels(&path, "Synthetic test figure", &t, &panels, 1200, 1000).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n");
        assert!(bytes.len() > 20_000, "PNG only {} bytes", bytes.len());
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn rejects_bad_input() {
        let t = [0.0f32, 1.0];
        let p = [Panel {
            title: "a",
            y_label: "b",
            series: vec![],
        }];
        let tmp = std::env::temp_dir();
        assert!(matches!(
            render_panels(&tmp.join("x.png"), "t", &t, &[], 800, 600),
            Err(PlotError::InvalidInput(_))
        ));
        assert!(matches!(
            render_panels(&tmp.join("x.jpg"), "t", &t, &p, 800, 600),
            Err(PlotError::InvalidInput(_))
        ));
        assert!(matches!(
            render_panels(&tmp.join("x.png"), "t", &[f32::NAN], &p, 800, 600),
            Err(PlotError::InvalidInput(_))
        ));
    }

    #[test]
    fn decimation_keeps_spikes_and_bounds_points() {
        let n = 50_000;
        let t: Vec<f32> = (0..n).map(|i| i as f32).collect();
        let mut v = vec![0.0f32; n];
        v[12_345] = 100.0;
        v[40_000] = -7.0;
        let segs = decimate(&t, &v, MAX_POINTS_PER_SERIES);
        let pts: Vec<_> = segs.iter().flatten().collect();
        assert!(pts.len() <= MAX_POINTS_PER_SERIES);
        assert!(pts.iter().any(|p| p.1 == 100.0 && p.0 == 12_345.0));
        assert!(pts.iter().any(|p| p.1 == -7.0));
        assert!(
            pts.windows(2).all(|w| w[0].0 <= w[1].0),
            "points stay in time order"
        );
    }

    #[test]
    fn non_finite_samples_break_lines() {
        let t = [0.0f32, 1.0, 2.0, 3.0, 4.0, 5.0];
        let v = [1.0f32, 2.0, f32::NAN, 3.0, f32::NEG_INFINITY, 4.0];
        let segs = decimate(&t, &v, 100);
        assert_eq!(
            segs,
            vec![
                vec![(0.0, 1.0), (1.0, 2.0)],
                vec![(3.0, 3.0)],
                vec![(5.0, 4.0)]
            ]
        );
        assert!(value_range(segs.iter().flatten().map(|p| p.1)).0 < 1.0);
    }

    #[test]
    fn ranges_are_padded() {
        assert_eq!(value_range([]), (-1.0, 1.0));
        let (lo, hi) = value_range([5.0, 5.0]);
        assert!(lo < 5.0 && hi > 5.0);
        let (lo, hi) = value_range([0.0, 0.0]);
        assert!(lo < 0.0 && hi > 0.0);
        let (lo, hi) = value_range([0.0, 10.0]);
        assert!(lo < 0.0 && lo > -1.0 && hi > 10.0 && hi < 11.0);
        assert_eq!(time_range(&[2.0, 2.0]), Some((1.5, 2.5)));
    }

    #[test]
    fn dashes_follow_the_time_axis() {
        let seg = vec![(0.0, 0.0), (10.0, 10.0)];
        let dashes = dash_segments(&[seg], 0.0, 1.0, 1.0);
        assert_eq!(dashes.len(), 5);
        assert_eq!(dashes[0], vec![(0.0, 0.0), (1.0, 1.0)]);
        assert_eq!(dashes[1], vec![(2.0, 2.0), (3.0, 3.0)]);
    }

    #[test]
    fn ticks_are_nice_and_tidy() {
        assert_eq!(nice_step(3000.0, 6), 500.0);
        assert_eq!(nice_step(10.0, 12), 1.0);
        assert_eq!(nice_step(0.3, 6), 0.05);
        assert_eq!(tick_values(-0.1, 1.05, 0.5), vec![0.0, 0.5, 1.0]);
        let f = TickFormat::new(500.0, 1500.0);
        assert_eq!(f.format(500.0), "500");
        assert_eq!(f.format(-500.0), "\u{2212}500");
        let f = TickFormat::new(0.05, 0.3);
        assert_eq!(f.format(0.1), "0.10");
        assert_eq!(f.format(-0.0001), "0.00");
        assert_eq!(TickFormat::new(0.5, 3.0).format(2.5), "2.5");
        assert_eq!(TickFormat::new(0.25, 3.0).format(0.5), "0.50");
        assert_eq!(nice_step(1.0, 4), 0.25);
        let f = TickFormat::new(2.5e7, 1e8);
        assert_eq!(f.format(5e7), "5e7");
        assert_eq!(f.format(7.5e7), "7.5e7");
        assert_eq!(f.format(-2.5e7), "\u{2212}2.5e7");
        assert_eq!(f.format(1e-9), "0");
    }

    #[test]
    fn embedded_font_measures_text() {
        let f = font().unwrap();
        let t = Txt::new(20.0, Align::Start, Align::Start);
        let w = t.width(f, "1500");
        assert!(w > 30.0 && w < 60.0, "width {w}");
        assert!(t.width(f, "") == 0.0);
    }
}
