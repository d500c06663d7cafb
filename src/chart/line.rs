//! Line charts: learning curves, discovery curves, latency percentile
//! plots, and mean ± std bands ([`LineChart`], [`band_chart`]).

use plotters::coord::ranged1d::{DefaultFormatting, KeyPointHint};
use plotters::prelude::*;
use sim::render::Canvas;

use super::{PALETTE, register_font};

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
    use sim::render::Rgb;

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
