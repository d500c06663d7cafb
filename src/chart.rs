//! Line charts for the reports: learning curves, discovery curves, latency
//! percentile plots, and mean ± std bands.
//!
//! Drawn with `plotters` on its bitmap backend straight into a
//! [`sim::render::Canvas`], so a chart is saved with the same atomic PNG
//! writer as the maze pictures. Text uses DejaVu Sans Mono, shipped in
//! `assets/fonts/` and compiled into the binary: no system font is looked up.
//!
//! Every chart puts its legend in a column right of the plot, so it never
//! covers the data. [`XScale::Count`] keeps the x ticks on whole numbers (an
//! axis of rounds), and [`XScale::PercentileTail`] is HdrHistogram's
//! percentile axis.

use std::sync::Once;

use plotters::coord::ranged1d::{DefaultFormatting, KeyPointHint};
use plotters::prelude::*;
use plotters::style::FontStyle;
use sim::Object;
use sim::render::{Canvas, Rgb, draw_grid, object_color};

/// The font every chart's text is set in (DejaVu Sans Mono; licence in
/// `assets/fonts/LICENSE-DejaVu`).
const FONT: &[u8] = include_bytes!("../assets/fonts/DejaVuSansMono.ttf");

/// Colours for successive series: matplotlib's tab10, so that the ten
/// configurations of the paper's Table 1 each get their own.
pub const PALETTE: [Rgb; 10] = [
    [31, 119, 180],
    [255, 127, 14],
    [44, 160, 44],
    [214, 39, 40],
    [148, 103, 189],
    [140, 86, 75],
    [227, 119, 194],
    [127, 127, 127],
    [188, 189, 34],
    [23, 190, 207],
];

/// One line of a chart.
#[derive(Debug, Clone)]
pub struct Series {
    /// Legend label.
    pub name: String,
    /// Points `(x, y)`, in x order. A non-finite point breaks the line.
    pub points: Vec<(f64, f64)>,
}

/// A line with a shaded band around it, such as the mean of several seeds'
/// curves with ± one standard deviation.
#[derive(Debug, Clone)]
pub struct Band {
    /// Legend label.
    pub name: String,
    /// Points `(x, centre, low, high)`, in x order: the line runs through
    /// `centre`, the band fills from `low` to `high`.
    pub points: Vec<(f64, f64, f64, f64)>,
}

/// How the x axis is scaled.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum XScale {
    /// Linear.
    Linear,
    /// Linear with ticks only on whole numbers: an axis that counts
    /// (rounds, iterations).
    Count,
    /// HdrHistogram's percentile axis: x is a percentile in [0, 100) drawn
    /// at `log10(1 / (1 - x/100))`, ticks labelled 0%, 50%, 90%, 99%,
    /// 99.9%, ..., so each further nine of the tail gets the same room.
    PercentileTail,
}

/// A line chart.
#[derive(Debug, Clone)]
pub struct LineChart {
    /// Title above the plot.
    pub title: String,
    /// Label of the x axis.
    pub x_label: String,
    /// Label of the y axis.
    pub y_label: String,
    /// The lines.
    pub series: Vec<Series>,
    /// X scale.
    pub x_scale: XScale,
}

impl LineChart {
    /// Renders the chart at `width × height` pixels.
    pub fn render(&self, width: usize, height: usize) -> Canvas {
        draw(self, &[], width, height)
    }
}

impl Band {
    /// The mean ± one (population) standard deviation of several runs'
    /// curves, at each x where every run has a point (runs are matched by
    /// index: run `r`'s `k`-th point is taken at the first run's `k`-th x).
    /// An empty `runs` gives an empty band.
    #[allow(dead_code, reason = "API for the experiment table's mean ± std curves")]
    pub fn mean_std(name: &str, runs: &[Vec<(f64, f64)>]) -> Band {
        let len = runs.iter().map(Vec::len).min().unwrap_or(0);
        let points = (0..len)
            .map(|k| {
                let n = runs.len() as f64;
                let mean = runs.iter().map(|r| r[k].1).sum::<f64>() / n;
                let var = runs.iter().map(|r| (r[k].1 - mean).powi(2)).sum::<f64>() / n;
                let std = var.sqrt();
                (runs[0][k].0, mean, mean - std, mean + std)
            })
            .collect();
        Band {
            name: name.into(),
            points,
        }
    }
}

/// Renders `chart` with `bands` drawn beneath its lines, at `width × height`
/// pixels. Band `k` takes colour `k` of [`PALETTE`]; the chart's own lines
/// take the colours after the bands'. Each band's legend entry is its
/// centre line's colour.
#[allow(dead_code, reason = "API for the experiment table's mean ± std curves")]
pub fn band_chart(chart: &LineChart, bands: &[Band], width: usize, height: usize) -> Canvas {
    draw(chart, bands, width, height)
}

/// Registers the shipped font as plotters' `sans-serif`, once per process
/// (the family every default text style of plotters asks for).
fn register_font() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        if plotters::style::register_font("sans-serif", FontStyle::Normal, FONT).is_err() {
            unreachable!("invariant: the shipped DejaVu Sans Mono parses");
        }
    });
}

fn colour(k: usize) -> RGBColor {
    let [r, g, b] = PALETTE[k % PALETTE.len()];
    RGBColor(r, g, b)
}

/// The x position a value is drawn at.
fn x_pos(scale: XScale, x: f64) -> f64 {
    match scale {
        XScale::Linear | XScale::Count => x,
        XScale::PercentileTail => (1.0 / (1.0 - (x / 100.0).min(0.999_999_9))).log10(),
    }
}

/// The percentiles labelled on a [`XScale::PercentileTail`] axis.
const PERCENTILE_TICKS: [f64; 8] = [0.0, 50.0, 90.0, 99.0, 99.9, 99.99, 99.999, 99.9999];

/// The label of the tick at position `v` of a [`XScale::PercentileTail`]
/// axis: `0%`, `50%`, `90%`, `99%`, `99.9%`, ...
fn percentile_label(v: f64) -> String {
    let p = 100.0 * (1.0 - 10f64.powf(-v));
    // One decimal per nine past 99 %.
    let decimals = (v - 2.0 - 1e-9).ceil().max(0.0) as usize;
    format!("{p:.decimals$}%")
}

/// Round tick values covering `[lo, hi]`, at most about `target` of them,
/// spaced by at least `min_step`.
fn ticks(lo: f64, hi: f64, target: usize, min_step: f64) -> Vec<f64> {
    let span = (hi - lo).max(f64::MIN_POSITIVE);
    let raw = span / target.max(1) as f64;
    let mag = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .map(|m| m * mag)
        .find(|s| span / s <= target as f64)
        .unwrap_or(10.0 * mag)
        .max(min_step);
    let mut t = (lo / step).ceil() * step;
    let mut out = Vec::new();
    while t <= hi + step * 1e-9 {
        out.push(if t.abs() < step * 1e-9 { 0.0 } else { t });
        t += step;
    }
    out
}

/// A short label for a tick value.
fn fmt_tick(v: f64) -> String {
    let a = v.abs();
    if a >= 1e6 {
        format!("{:.3}M", v / 1e6)
            .trim_end_matches('0')
            .trim_end_matches('.')
            .replace(".M", "M")
    } else if a >= 1e4 {
        format!("{:.0}k", v / 1e3)
    } else if a >= 100.0 || v == v.trunc() {
        format!("{v:.0}")
    } else if a >= 1.0 {
        format!("{v:.1}")
    } else {
        format!("{v:.2}")
    }
}

/// The finite runs of `points`, mapped through `f` (a non-finite point
/// ends a run).
fn runs<T: Copy>(points: &[T], finite: impl Fn(T) -> bool) -> Vec<Vec<T>> {
    let mut out: Vec<Vec<T>> = vec![Vec::new()];
    for &p in points {
        if finite(p) {
            out.last_mut().expect("invariant: never empty").push(p);
        } else if !out.last().expect("invariant: never empty").is_empty() {
            out.push(Vec::new());
        }
    }
    out.retain(|r| !r.is_empty());
    out
}

/// The data's ranges on screen: `(x0, x1, y0, y1)`, each span non-empty.
fn bounds(chart: &LineChart, bands: &[Band]) -> (f64, f64, f64, f64) {
    let fx = |x| x_pos(chart.x_scale, x);
    let mut xs = Vec::new();
    let mut ys = Vec::new();
    for s in &chart.series {
        for &(x, y) in &s.points {
            xs.push(fx(x));
            ys.push(y);
        }
    }
    for b in bands {
        for &(x, c, lo, hi) in &b.points {
            xs.push(fx(x));
            ys.extend([c, lo, hi]);
        }
    }
    let lo_hi = |v: &[f64]| {
        v.iter()
            .filter(|v| v.is_finite())
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
                (a.min(v), b.max(v))
            })
    };
    let (mut x0, mut x1) = lo_hi(&xs);
    let (mut y0, mut y1) = lo_hi(&ys);
    if !x0.is_finite() {
        (x0, x1) = (0.0, 1.0);
    }
    if !y0.is_finite() {
        (y0, y1) = (0.0, 1.0);
    }
    if chart.x_scale == XScale::PercentileTail {
        x0 = 0.0;
    }
    if y0 > 0.0 && y0 < 0.5 * y1 {
        y0 = 0.0;
    }
    if x1 - x0 < 1e-12 {
        x1 = x0 + 1.0;
    }
    if y1 - y0 < 1e-12 {
        y1 = y0 + 1.0;
    }
    let pad = (y1 - y0) * 0.05;
    (x0, x1, y0 - if y0 == 0.0 { 0.0 } else { pad }, y1 + pad)
}

/// A linear axis over `[lo, hi]` with its ticks at given values (plotters'
/// own ticks would put an axis of rounds at 0.5 steps).
struct Axis {
    lo: f64,
    hi: f64,
    ticks: Vec<f64>,
}

impl Ranged for Axis {
    type FormatOption = DefaultFormatting;
    type ValueType = f64;

    fn map(&self, value: &f64, limit: (i32, i32)) -> i32 {
        let t = (value - self.lo) / (self.hi - self.lo);
        limit.0 + (t * f64::from(limit.1 - limit.0)).round() as i32
    }

    fn key_points<Hint: KeyPointHint>(&self, _hint: Hint) -> Vec<f64> {
        self.ticks.clone()
    }

    fn range(&self) -> std::ops::Range<f64> {
        self.lo..self.hi
    }
}

const TITLE_PX: u32 = 22;
const TEXT_PX: u32 = 15;
const TICK_PX: u32 = 13;

fn draw(chart: &LineChart, bands: &[Band], width: usize, height: usize) -> Canvas {
    register_font();
    let mut canvas = Canvas::new(width, height, [255, 255, 255]);
    if let Err(e) = plot(chart, bands, &mut canvas) {
        // Only the backend can fail here (the buffer is sized for it and
        // the font is registered above): an invariant, not an input error.
        unreachable!("invariant: drawing into a canvas of the right size: {e}");
    }
    canvas
}

fn plot<'c>(
    chart: &LineChart,
    bands: &[Band],
    canvas: &'c mut Canvas,
) -> Result<(), Box<dyn std::error::Error + 'c>> {
    let (w, h) = (canvas.width as u32, canvas.height as u32);
    let (x0, x1, y0, y1) = bounds(chart, bands);
    let scale = chart.x_scale;
    let x_ticks = match scale {
        XScale::Linear => ticks(x0, x1, 8, 0.0),
        XScale::Count => ticks(x0, x1, 8, 1.0),
        XScale::PercentileTail => PERCENTILE_TICKS
            .iter()
            .map(|&p| x_pos(scale, p))
            .filter(|&v| v <= x1 + 1e-9)
            .collect(),
    };
    let y_ticks = ticks(y0, y1, 6, 0.0);
    let names: Vec<&str> = bands
        .iter()
        .map(|b| b.name.as_str())
        .chain(chart.series.iter().map(|s| s.name.as_str()))
        .collect();

    let root = BitMapBackend::with_buffer(&mut canvas.rgb, (w, h)).into_drawing_area();
    let root = root.titled(&chart.title, ("sans-serif", TITLE_PX))?;
    // The legend's column: a swatch, a gap and the longest name (a mono
    // font's advance is 0.6 em).
    let longest = names.iter().map(|n| n.chars().count()).max().unwrap_or(0) as u32;
    let legend_w = if names.is_empty() {
        0
    } else {
        (36 + longest * TEXT_PX * 6 / 10 + 16).min(w / 3)
    };
    let (plot_area, legend_area) = root.split_horizontally(w.saturating_sub(legend_w));

    let mut ctx = ChartBuilder::on(&plot_area)
        .margin_left(8)
        .margin_right(16)
        .margin_top(8)
        .margin_bottom(8)
        .x_label_area_size(44)
        .y_label_area_size(72)
        .build_cartesian_2d(
            Axis {
                lo: x0,
                hi: x1,
                ticks: x_ticks,
            },
            Axis {
                lo: y0,
                hi: y1,
                ticks: y_ticks,
            },
        )?;
    let x_fmt = |v: &f64| match scale {
        XScale::PercentileTail => percentile_label(*v),
        XScale::Linear | XScale::Count => fmt_tick(*v),
    };
    ctx.configure_mesh()
        .x_desc(chart.x_label.as_str())
        .y_desc(chart.y_label.as_str())
        .x_label_formatter(&x_fmt)
        .y_label_formatter(&|v| fmt_tick(*v))
        .label_style(("sans-serif", TICK_PX))
        .axis_desc_style(("sans-serif", TEXT_PX))
        .bold_line_style(RGBColor(228, 228, 228))
        .light_line_style(TRANSPARENT)
        .axis_style(RGBColor(40, 40, 40))
        .draw()?;

    let fx = |x| x_pos(scale, x);
    for (k, b) in bands.iter().enumerate() {
        let c = colour(k);
        for run in runs(&b.points, |(x, m, lo, hi)| {
            x.is_finite() && m.is_finite() && lo.is_finite() && hi.is_finite()
        }) {
            let outline: Vec<(f64, f64)> = run
                .iter()
                .map(|p| (fx(p.0), p.3))
                .chain(run.iter().rev().map(|p| (fx(p.0), p.2)))
                .collect();
            ctx.draw_series(std::iter::once(Polygon::new(outline, c.mix(0.2).filled())))?;
            let centre: Vec<(f64, f64)> = run.iter().map(|p| (fx(p.0), p.1)).collect();
            draw_line(&mut ctx, centre, c)?;
        }
    }
    for (k, s) in chart.series.iter().enumerate() {
        let c = colour(bands.len() + k);
        for run in runs(&s.points, |(x, y)| x.is_finite() && y.is_finite()) {
            draw_line(&mut ctx, run.iter().map(|p| (fx(p.0), p.1)).collect(), c)?;
        }
    }

    // The legend, level with the top of the plot.
    for (k, name) in names.iter().enumerate() {
        let y = 16 + k as i32 * (TEXT_PX as i32 + 8);
        let c = colour(k);
        legend_area.draw(&PathElement::new(vec![(4, y), (28, y)], c.stroke_width(3)))?;
        legend_area.draw(&Text::new(
            name.to_string(),
            (36, y - TEXT_PX as i32 / 2 + 1),
            ("sans-serif", TEXT_PX)
                .into_font()
                .color(&RGBColor(40, 40, 40)),
        ))?;
    }
    root.present()?;
    Ok(())
}

type Ctx<'a, 'b> = ChartContext<'a, BitMapBackend<'b>, Cartesian2d<Axis, Axis>>;

// ------------------------------------------------------------- captions

/// Side in pixels of the cell a legend mark is drawn on.
pub const LEGEND_CELL: usize = 24;
/// The narrowest captioned picture: a smaller picture is centred on a
/// canvas this wide, so that its title and legend have room.
pub const MIN_CAPTIONED_WIDTH: usize = 480;
/// Title sizes tried in turn: the first that sets the title in at most two
/// lines is used (the last wraps onto as many as it needs).
const CAPTION_TITLE_PX: [u32; 3] = [18, 16, 14];
const CAPTION_TEXT_PX: u32 = 14;
const CAPTION_PAD: usize = 10;
/// A legend mark's box: two cells wide, one cell tall.
const MARK_W: usize = 2 * LEGEND_CELL;
/// Room for a legend column: its mark, a gap and about 36 characters.
const LEGEND_COLUMN_MIN: usize = 360;
const INK: RGBColor = RGBColor(30, 30, 30);

/// How a legend entry's mark is drawn: as the picture draws it, with the
/// same primitives and colours, on a cell of [`LEGEND_CELL`] pixels of
/// floor. Sizes are fractions of a cell.
#[derive(Debug, Clone)]
pub enum Mark {
    /// A square inset by `inset` of a cell on every side, `fill` blended
    /// at `alpha`.
    Square {
        /// Colour.
        fill: Rgb,
        /// Opacity in [0, 1].
        alpha: f32,
        /// Inset from the cell's sides, as a fraction of the cell.
        inset: f32,
    },
    /// A disc of `radius` in `fill` at `alpha`, over a disc a quarter
    /// wider in `outline` when there is one.
    Disc {
        /// Colour.
        fill: Rgb,
        /// Opacity in [0, 1].
        alpha: f32,
        /// Radius, as a fraction of the cell.
        radius: f32,
        /// The colour of a ring around the disc.
        outline: Option<Rgb>,
    },
    /// A line across two cells, `width` of a cell wide, in `colour` at
    /// `alpha`; with `arrow`, an arrow head at its right end.
    Line {
        /// Colour.
        colour: Rgb,
        /// Opacity in [0, 1].
        alpha: f32,
        /// Width, as a fraction of the cell.
        width: f32,
        /// An arrow head at the right end.
        arrow: bool,
    },
    /// A shade from `low` (left) to `high` (right), two cells long.
    Ramp {
        /// Colour at the left end.
        low: Rgb,
        /// Colour at the right end.
        high: Rgb,
    },
    /// A sample the picture's own drawing code made (a grid cell, a mark
    /// of several parts), shown as it is, centred in the mark's box.
    Sample(Canvas),
}

/// One row of a picture's legend: a mark and what it means.
#[derive(Debug, Clone)]
pub struct LegendEntry {
    /// The mark, drawn as the picture draws it.
    pub mark: Mark,
    /// What it means.
    pub label: String,
}

impl LegendEntry {
    /// An entry.
    pub fn new(mark: Mark, label: impl Into<String>) -> LegendEntry {
        LegendEntry {
            mark,
            label: label.into(),
        }
    }
}

/// One cell of object code `code` as [`draw_grid`] draws it, at
/// [`LEGEND_CELL`] pixels: a legend sample.
pub fn cell_sample(code: u8) -> Canvas {
    let mut c = Canvas::new(LEGEND_CELL, LEGEND_CELL, [255, 255, 255]);
    draw_grid(&mut c, &[code], 1, 0, 0, LEGEND_CELL);
    c
}

/// Legend entries for the objects a grid of `cells` holds (one per kind,
/// each drawn as [`draw_grid`] draws it), leaving out the kinds in `skip`
/// (those the picture explains itself).
pub fn object_entries(cells: &[u8], skip: &[Object]) -> Vec<LegendEntry> {
    Object::ALL
        .into_iter()
        .filter(|o| !skip.contains(o) && cells.contains(&(*o as u8)))
        .map(|o| {
            let label = match o {
                Object::Floor => "floor",
                Object::Wall => "wall",
                Object::Ball => "ball",
                Object::Key => "key",
                Object::DoorOpen => "open door",
                Object::DoorClosed => "closed door",
                Object::DoorLocked => "locked door (the key opens it)",
                Object::Exit => "exit",
                Object::Lava => "lava",
            };
            LegendEntry::new(Mark::Sample(cell_sample(o as u8)), label)
        })
        .collect()
}

/// The colour `c` blended at `alpha` over `bg`, as [`Canvas::blend`] leaves
/// it.
pub fn blended(bg: Rgb, c: Rgb, alpha: f32) -> Rgb {
    [0, 1, 2].map(|i| {
        let old = bg[i] as f32;
        (old + (c[i] as f32 - old) * alpha)
            .round()
            .clamp(0.0, 255.0) as u8
    })
}

/// Characters of the shipped monospace font at `size` px that fit in `px`
/// pixels (its advance is 0.602 em; 0.62 leaves a margin).
fn chars_fitting(px: usize, size: u32) -> usize {
    ((px as f32) / (0.62 * size as f32)).floor().max(1.0) as usize
}

/// Width in pixels of `n` characters at `size` px.
fn text_width(n: usize, size: u32) -> usize {
    (n as f32 * 0.602 * size as f32).ceil() as usize
}

/// `text` in lines of at most `max` characters, broken between words (a
/// word longer than a line is broken inside).
fn wrap(text: &str, max: usize) -> Vec<String> {
    let max = max.max(1);
    let mut lines: Vec<String> = Vec::new();
    let mut line = String::new();
    for word in text.split_whitespace() {
        let mut word: Vec<char> = word.chars().collect();
        while word.len() > max {
            if !line.is_empty() {
                lines.push(std::mem::take(&mut line));
            }
            lines.push(word.drain(..max).collect());
        }
        let word: String = word.into_iter().collect();
        let len = line.chars().count();
        if len > 0 && len + 1 + word.chars().count() > max {
            lines.push(std::mem::take(&mut line));
        }
        if !line.is_empty() {
            line.push(' ');
        }
        line.push_str(&word);
    }
    if !line.is_empty() || lines.is_empty() {
        lines.push(line);
    }
    lines
}

/// The size of a mark's drawing: its box (a sample may be larger).
fn mark_size(m: &Mark) -> (usize, usize) {
    match m {
        Mark::Sample(c) => (c.width.max(MARK_W), c.height.max(LEGEND_CELL)),
        _ => (MARK_W, LEGEND_CELL),
    }
}

/// Draws mark `m` in the box whose top-left corner is `(x, y)`.
fn draw_mark(c: &mut Canvas, m: &Mark, x: usize, y: usize) {
    let cell = LEGEND_CELL as f32;
    let floor = object_color(Object::Floor);
    let (xi, yi) = (x as i64, y as i64);
    let p = LEGEND_CELL as i64;
    // A one-cell mark sits on a floor cell in the middle of the box.
    let (cx0, cy0) = (xi + (MARK_W as i64 - p) / 2, yi);
    match m {
        Mark::Square { fill, alpha, inset } => {
            c.fill_rect(cx0, cy0, p, p, floor, 1.0);
            let d = (inset * cell).round() as i64;
            c.fill_rect(cx0 + d, cy0 + d, p - 2 * d, p - 2 * d, *fill, *alpha);
        }
        Mark::Disc {
            fill,
            alpha,
            radius,
            outline,
        } => {
            c.fill_rect(cx0, cy0, p, p, floor, 1.0);
            let (mx, my) = (cx0 as f32 + cell / 2.0, cy0 as f32 + cell / 2.0);
            if let Some(o) = outline {
                c.fill_disc(mx, my, radius * cell * 1.25, *o, 1.0);
            }
            c.fill_disc(mx, my, radius * cell, *fill, *alpha);
        }
        Mark::Line {
            colour,
            alpha,
            width,
            arrow,
        } => {
            c.fill_rect(xi, yi, MARK_W as i64, p, floor, 1.0);
            let my = y as f32 + cell / 2.0;
            let (a, b) = ((x as f32 + 3.0, my), ((x + MARK_W) as f32 - 3.0, my));
            c.line(a, b, (width * cell).max(1.0), *colour, *alpha);
            if *arrow {
                let base = b.0 - cell * 0.3;
                c.fill_triangle(
                    [b, (base, my - cell * 0.14), (base, my + cell * 0.14)],
                    *colour,
                    0.9,
                );
            }
        }
        Mark::Ramp { low, high } => {
            let w = MARK_W as i64;
            for k in 0..w {
                let t = k as f32 / (w - 1) as f32;
                let col = [0, 1, 2]
                    .map(|i| (low[i] as f32 + (high[i] as f32 - low[i] as f32) * t).round() as u8);
                c.fill_rect(xi + k, yi + 2, 1, p - 4, col, 1.0);
            }
        }
        Mark::Sample(s) => {
            let (bw, _) = mark_size(m);
            c.blit(s, x + (bw - s.width) / 2, y);
        }
    }
}

/// `picture` with a title above it and a legend below: a new canvas at
/// least [`MIN_CAPTIONED_WIDTH`] wide with the picture centred. The title
/// is wrapped (and set smaller when long) so it is never cut; the legend
/// has one entry per row, in as many columns as the width holds, each row
/// the mark as the picture draws it and its label (wrapped too).
pub fn captioned(picture: &Canvas, title: &str, legend: &[LegendEntry]) -> Canvas {
    register_font();
    let w = picture.width.max(MIN_CAPTIONED_WIDTH);
    let inner = w - 2 * CAPTION_PAD;

    // The title: the largest size that takes at most two lines.
    let (title_px, title_lines) = CAPTION_TITLE_PX
        .iter()
        .map(|&px| (px, wrap(title, chars_fitting(inner, px))))
        .find(|(_, l)| l.len() <= 2)
        .unwrap_or_else(|| {
            let px = CAPTION_TITLE_PX[CAPTION_TITLE_PX.len() - 1];
            (px, wrap(title, chars_fitting(inner, px)))
        });
    let title_line_h = title_px as usize + 6;
    let title_h = CAPTION_PAD + title_lines.len() * title_line_h + CAPTION_PAD / 2;
    let pic = ((w - picture.width) / 2, title_h + 1 + CAPTION_PAD / 2);

    // The legend, column-major.
    let cols = (inner / LEGEND_COLUMN_MIN)
        .clamp(1, 3)
        .min(legend.len().max(1));
    let col_w = inner / cols;
    let text_line_h = CAPTION_TEXT_PX as usize + 4;
    let entries: Vec<(Vec<String>, (usize, usize))> = legend
        .iter()
        .map(|e| {
            let (mw, mh) = mark_size(&e.mark);
            let room = col_w.saturating_sub(mw + 8 + 4);
            (
                wrap(&e.label, chars_fitting(room, CAPTION_TEXT_PX)),
                (mw, mh),
            )
        })
        .collect();
    let rows = entries.len().div_ceil(cols);
    let row_h: Vec<usize> = (0..rows)
        .map(|r| {
            (0..cols)
                .filter_map(|k| entries.get(k * rows + r))
                .map(|(lines, (_, mh))| (*mh).max(lines.len() * text_line_h))
                .max()
                .unwrap_or(0)
                + 6
        })
        .collect();
    let legend_y = pic.1 + picture.height + CAPTION_PAD;
    let h = legend_y + row_h.iter().sum::<usize>() + CAPTION_PAD;

    let mut c = Canvas::new(w, h, [255, 255, 255]);
    c.fill_rect(
        CAPTION_PAD as i64,
        title_h as i64,
        inner as i64,
        1,
        [215, 215, 215],
        1.0,
    );
    c.blit(picture, pic.0, pic.1);
    // Where each entry's mark and label go.
    let mut places = Vec::with_capacity(entries.len());
    for (i, (lines, (mw, mh))) in entries.iter().enumerate() {
        let (col, row) = (i / rows.max(1), i % rows.max(1));
        let x = CAPTION_PAD + col * col_w;
        let y = legend_y + row_h[..row].iter().sum::<usize>();
        let content = (*mh).max(lines.len() * text_line_h);
        draw_mark(&mut c, &legend[i].mark, x, y + (content - mh) / 2);
        let text_y = y + (content - lines.len() * text_line_h) / 2 + 2;
        places.push((x + mw + 8, text_y));
    }
    if let Err(e) = caption_text(
        &mut c,
        (title_px, &title_lines, title_line_h),
        &entries,
        &places,
        text_line_h,
    ) {
        unreachable!("invariant: drawing text into a canvas of the right size: {e}");
    }
    c
}

fn caption_text<'c>(
    canvas: &'c mut Canvas,
    (title_px, title_lines, title_line_h): (u32, &[String], usize),
    entries: &[(Vec<String>, (usize, usize))],
    places: &[(usize, usize)],
    text_line_h: usize,
) -> Result<(), Box<dyn std::error::Error + 'c>> {
    let (w, h) = (canvas.width as u32, canvas.height as u32);
    let root = BitMapBackend::with_buffer(&mut canvas.rgb, (w, h)).into_drawing_area();
    for (k, line) in title_lines.iter().enumerate() {
        let lw = text_width(line.chars().count(), title_px);
        let x = (w as usize).saturating_sub(lw) / 2;
        root.draw(&Text::new(
            line.clone(),
            (x as i32, (CAPTION_PAD + k * title_line_h) as i32),
            ("sans-serif", title_px).into_font().color(&INK),
        ))?;
    }
    for ((lines, _), &(x, y)) in entries.iter().zip(places) {
        for (k, line) in lines.iter().enumerate() {
            root.draw(&Text::new(
                line.clone(),
                (x as i32, (y + k * text_line_h) as i32),
                ("sans-serif", CAPTION_TEXT_PX).into_font().color(&INK),
            ))?;
        }
    }
    root.present()?;
    Ok(())
}

/// One run of a line; a lone point is drawn as a dot.
fn draw_line<'b>(
    ctx: &mut Ctx<'_, 'b>,
    pts: Vec<(f64, f64)>,
    c: RGBColor,
) -> Result<(), DrawingAreaErrorKind<<BitMapBackend<'b> as DrawingBackend>::ErrorType>> {
    if pts.len() == 1 {
        ctx.draw_series(std::iter::once(Circle::new(pts[0], 3, c.filled())))?;
    } else {
        ctx.draw_series(LineSeries::new(pts, c.stroke_width(2)))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn chart(series: Vec<Series>, x_scale: XScale) -> LineChart {
        LineChart {
            title: "t".into(),
            x_label: "x".into(),
            y_label: "y".into(),
            series,
            x_scale,
        }
    }

    fn count(c: &Canvas, rgb: Rgb) -> usize {
        c.rgb.chunks(3).filter(|p| *p == rgb).count()
    }

    /// The longest run of pixels of colour `rgb` along any row.
    fn longest_row_run(c: &Canvas, rgb: Rgb) -> usize {
        c.rgb
            .chunks(3 * c.width)
            .map(|row| {
                let (mut best, mut cur) = (0, 0);
                for p in row.chunks(3) {
                    cur = if p == rgb { cur + 1 } else { 0 };
                    best = best.max(cur);
                }
                best
            })
            .max()
            .unwrap_or(0)
    }

    #[test]
    fn ticks_are_round_and_cover_the_range() {
        assert_eq!(
            ticks(0.0, 10.0, 5, 0.0),
            vec![0.0, 2.0, 4.0, 6.0, 8.0, 10.0]
        );
        let t = ticks(0.013, 0.087, 4, 0.0);
        assert!(t.first().unwrap() >= &0.013 && t.last().unwrap() <= &0.087 && t.len() >= 3);
    }

    #[test]
    fn a_count_axis_ticks_only_whole_numbers() {
        assert_eq!(ticks(0.0, 3.0, 8, 1.0), vec![0.0, 1.0, 2.0, 3.0]);
        assert_eq!(ticks(0.0, 1.0, 8, 1.0), vec![0.0, 1.0]);
    }

    #[test]
    fn the_percentile_axis_is_labelled_like_hdrhistogram() {
        let labels: Vec<String> = PERCENTILE_TICKS
            .iter()
            .map(|&p| percentile_label(x_pos(XScale::PercentileTail, p)))
            .collect();
        assert_eq!(
            labels,
            [
                "0%", "50%", "90%", "99%", "99.9%", "99.99%", "99.999%", "99.9999%"
            ]
        );
        // One decade of 1/(1-p) per nine.
        let d = x_pos(XScale::PercentileTail, 99.9) - x_pos(XScale::PercentileTail, 99.0);
        assert!((d - 1.0).abs() < 1e-9, "{d}");
    }

    #[test]
    fn a_chart_draws_its_series_in_colour() {
        let c = chart(
            vec![Series {
                name: "a".into(),
                points: vec![(0.0, 0.0), (1.0, 1.0)],
            }],
            XScale::Linear,
        )
        .render(300, 200);
        assert!(count(&c, PALETTE[0]) > 100, "the line is drawn");
    }

    #[test]
    fn the_legend_leaves_the_data_uncovered() {
        // A flat line along the top of the data, where an inset legend would
        // sit, and a second series with a long name: the line stays whole.
        let c = chart(
            vec![
                Series {
                    name: "top".into(),
                    points: vec![(0.0, 1.0), (10.0, 1.0)],
                },
                Series {
                    name: "a long legend entry".into(),
                    points: vec![(0.0, 0.0), (10.0, 0.5)],
                },
            ],
            XScale::Linear,
        )
        .render(900, 520);
        let run = longest_row_run(&c, PALETTE[0]);
        assert!(run > 500, "the top line is unbroken: {run} px");
    }

    #[test]
    fn a_band_fills_between_its_low_and_high() {
        let band = Band::mean_std(
            "mean ± std",
            &[
                vec![(0.0, 0.0), (1.0, 1.0), (2.0, 2.0)],
                vec![(0.0, 2.0), (1.0, 3.0), (2.0, 4.0)],
            ],
        );
        assert_eq!(band.points[1], (1.0, 2.0, 1.0, 3.0));
        let c = band_chart(&chart(Vec::new(), XScale::Count), &[band], 400, 300);
        // The fill is the band colour at 20 % over white.
        let [r, g, b] = PALETTE[0];
        let mix = |v: u8| (0.2 * v as f64 + 0.8 * 255.0).round() as i32;
        let near = c
            .rgb
            .chunks(3)
            .filter(|p| {
                (p[0] as i32 - mix(r)).abs() <= 2
                    && (p[1] as i32 - mix(g)).abs() <= 2
                    && (p[2] as i32 - mix(b)).abs() <= 2
            })
            .count();
        assert!(near > 2000, "the band is filled: {near} px");
        assert!(count(&c, PALETTE[0]) > 100, "the centre line is drawn");
    }

    /// The row at which `picture` sits at column `x` of `c`, if anywhere.
    fn find_picture(c: &Canvas, picture: &Canvas, x: usize) -> Option<usize> {
        let row = |cv: &Canvas, y: usize, x0: usize| {
            cv.rgb[(y * cv.width + x0) * 3..(y * cv.width + x0 + picture.width) * 3].to_vec()
        };
        (0..=c.height.saturating_sub(picture.height))
            .find(|&y| (0..picture.height).all(|r| row(c, y + r, x) == row(picture, r, 0)))
    }

    /// Pixels that are not white in rows `y0..y1` and columns `x0..x1`.
    fn ink(c: &Canvas, (x0, x1): (usize, usize), (y0, y1): (usize, usize)) -> usize {
        (y0..y1)
            .flat_map(|y| (x0..x1).map(move |x| (x, y)))
            .filter(|&(x, y)| c.rgb[(y * c.width + x) * 3..(y * c.width + x) * 3 + 3] != [255; 3])
            .count()
    }

    /// Dark (text) pixels in rows `y0..y1` and columns `x0..x1`.
    fn dark(c: &Canvas, (x0, x1): (usize, usize), (y0, y1): (usize, usize)) -> usize {
        (y0..y1)
            .flat_map(|y| (x0..x1).map(move |x| (x, y)))
            .filter(|&(x, y)| {
                c.rgb[(y * c.width + x) * 3..(y * c.width + x) * 3 + 3]
                    .iter()
                    .all(|&v| v < 128)
            })
            .count()
    }

    /// A picture of three stripes (no row looks like another's neighbour).
    fn stripes(w: usize, h: usize) -> Canvas {
        let mut p = Canvas::new(w, h, [200, 40, 40]);
        p.fill_rect(
            0,
            (h / 3) as i64,
            w as i64,
            (h / 3) as i64,
            [40, 200, 40],
            1.0,
        );
        p.fill_rect(
            0,
            (2 * h / 3) as i64,
            w as i64,
            h as i64,
            [40, 40, 200],
            1.0,
        );
        p
    }

    #[test]
    fn a_captioned_picture_has_a_title_above_and_its_legend_below() {
        let picture = stripes(200, 90);
        let disc = [250, 120, 0];
        let c = captioned(
            &picture,
            "a title",
            &[
                LegendEntry::new(
                    Mark::Disc {
                        fill: disc,
                        alpha: 1.0,
                        radius: 0.3,
                        outline: None,
                    },
                    "an orange disc",
                ),
                LegendEntry::new(
                    Mark::Line {
                        colour: [0, 0, 0],
                        alpha: 1.0,
                        width: 0.1,
                        arrow: true,
                    },
                    "a line",
                ),
            ],
        );
        assert_eq!(c.width, MIN_CAPTIONED_WIDTH, "widened so the text fits");
        let x = (c.width - picture.width) / 2;
        let y = find_picture(&c, &picture, x).expect("the picture, whole and centred");
        assert!(y > 0 && c.height > y + picture.height, "{} {}", y, c.height);
        assert!(
            dark(&c, (0, c.width), (0, y.saturating_sub(2))) > 20,
            "the title strip holds text"
        );
        // The legend: the disc in its colour, and the labels' ink.
        let below = (y + picture.height, c.height);
        let discs = (below.0..below.1)
            .flat_map(|yy| (0..c.width).map(move |xx| (xx, yy)))
            .filter(|&(xx, yy)| c.rgb[(yy * c.width + xx) * 3..(yy * c.width + xx) * 3 + 3] == disc)
            .count();
        assert!(discs > 20, "the disc mark is drawn: {discs} px");
        assert!(
            dark(&c, (CAPTION_PAD + MARK_W + 8, c.width), below) > 20,
            "the labels are written"
        );
    }

    #[test]
    fn a_long_title_and_label_wrap_instead_of_being_cut() {
        let picture = stripes(120, 60);
        let label =
            "a legend label long enough to need more than one line in its column ".repeat(2);
        let short = captioned(&picture, "short", &[]);
        let long_title = "a very long title of a picture, ".repeat(8);
        let long = captioned(
            &picture,
            &long_title,
            &[LegendEntry::new(
                Mark::Ramp {
                    low: [255, 255, 255],
                    high: [0, 0, 0],
                },
                label,
            )],
        );
        let y_short = find_picture(&short, &picture, (short.width - 120) / 2).unwrap();
        let y_long = find_picture(&long, &picture, (long.width - 120) / 2).unwrap();
        assert!(
            y_long > y_short + 20,
            "the long title takes more lines: {y_long} vs {y_short}"
        );
        // Nothing reaches the right margin: no text is cut at the edge.
        let margin = (long.width - 4, long.width);
        assert_eq!(
            ink(&long, margin, (0, long.height)),
            0,
            "text ran off the right edge"
        );
        let legend_h = long.height - y_long - picture.height;
        assert!(
            legend_h > 2 * (CAPTION_TEXT_PX as usize + 4),
            "the label wrapped: {legend_h} px"
        );
        assert_eq!(wrap("ab cd ef", 5), ["ab cd", "ef"]);
        assert_eq!(wrap("abcdefgh", 3), ["abc", "def", "gh"]);
    }

    #[test]
    fn non_finite_points_break_the_line_and_nothing_panics() {
        let c = chart(
            vec![Series {
                name: "gaps".into(),
                points: vec![
                    (0.0, 1.0),
                    (1.0, f64::NAN),
                    (2.0, 2.0),
                    (3.0, f64::INFINITY),
                ],
            }],
            XScale::Count,
        )
        .render(300, 200);
        assert!(count(&c, PALETTE[0]) > 10, "lone points are dots");
        let empty = chart(Vec::new(), XScale::PercentileTail).render(300, 200);
        assert_eq!(empty.width, 300);
    }
}
