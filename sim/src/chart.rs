//! Line charts drawn on a [`Canvas`]: learning curves, latency percentile
//! plots. Text uses the public-domain 8×8 bitmap font of `font8x8`, so no
//! system font is needed.

use font8x8::legacy::BASIC_LEGACY;

use crate::render::{Canvas, Rgb};

/// Colours for successive series.
pub const PALETTE: [Rgb; 8] = [
    [31, 119, 180],
    [255, 127, 14],
    [44, 160, 44],
    [214, 39, 40],
    [148, 103, 189],
    [140, 86, 75],
    [227, 119, 194],
    [127, 127, 127],
];

/// One line of a chart.
#[derive(Debug, Clone)]
pub struct Series {
    /// Legend label.
    pub name: String,
    /// Points `(x, y)`, in x order.
    pub points: Vec<(f64, f64)>,
}

/// How the x axis is scaled.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum XScale {
    /// Linear.
    Linear,
    /// HdrHistogram's percentile axis: x is a percentile in [0, 100) drawn
    /// at `log10(1 / (1 - x/100))`, so the tail gets room.
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

impl Canvas {
    /// Draws `text` with its top-left corner at `(x, y)`, each glyph scaled by `scale`.
    pub fn text(&mut self, x: i64, y: i64, text: &str, scale: i64, c: Rgb) {
        for (k, ch) in text.chars().enumerate() {
            let glyph = BASIC_LEGACY
                .get(ch as usize)
                .copied()
                .unwrap_or(BASIC_LEGACY[b'?' as usize]);
            for (row, bits) in glyph.iter().enumerate() {
                for col in 0..8 {
                    if bits & (1 << col) != 0 {
                        let gx = x + (k as i64 * 8 + col) * scale;
                        self.fill_rect(gx, y + row as i64 * scale, scale, scale, c, 1.0);
                    }
                }
            }
        }
    }
}

/// Width in pixels of `text` at `scale`.
pub fn text_width(text: &str, scale: i64) -> i64 {
    text.chars().count() as i64 * 8 * scale
}

/// Round tick values covering `[lo, hi]`.
fn ticks(lo: f64, hi: f64, target: usize) -> Vec<f64> {
    let span = (hi - lo).max(f64::MIN_POSITIVE);
    let raw = span / target.max(1) as f64;
    let mag = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .map(|m| m * mag)
        .find(|s| span / s <= target as f64)
        .unwrap_or(10.0 * mag);
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

impl LineChart {
    /// Renders the chart at `width × height` pixels.
    pub fn render(&self, width: usize, height: usize) -> Canvas {
        let mut c = Canvas::new(width, height, [255, 255, 255]);
        let (w, h) = (width as i64, height as i64);
        let (left, right, top, bottom) = (78i64, 20i64, 34i64, 48i64);
        let (pw, ph) = ((w - left - right).max(10), (h - top - bottom).max(10));
        let fx = |x: f64| match self.x_scale {
            XScale::Linear => x,
            XScale::PercentileTail => (1.0 / (1.0 - (x / 100.0).min(0.999_999))).log10(),
        };
        let pts = self
            .series
            .iter()
            .flat_map(|s| s.points.iter())
            .filter(|p| p.0.is_finite() && p.1.is_finite());
        let (mut x0, mut x1, mut y0, mut y1) = (
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
        );
        for &(x, y) in pts {
            let x = fx(x);
            x0 = x0.min(x);
            x1 = x1.max(x);
            y0 = y0.min(y);
            y1 = y1.max(y);
        }
        if !x0.is_finite() {
            (x0, x1, y0, y1) = (0.0, 1.0, 0.0, 1.0);
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
        let (y0, y1) = (y0 - if y0 == 0.0 { 0.0 } else { pad }, y1 + pad);
        let px = |x: f64| left as f32 + ((fx(x) - x0) / (x1 - x0)) as f32 * pw as f32;
        let py = |y: f64| (top + ph) as f32 - ((y - y0) / (y1 - y0)) as f32 * ph as f32;
        let grid: Rgb = [228, 228, 228];
        let ink: Rgb = [40, 40, 40];
        // Y ticks and grid.
        for t in ticks(y0, y1, 6) {
            let y = py(t) as i64;
            c.fill_rect(left, y, pw, 1, grid, 1.0);
            let label = fmt_tick(t);
            c.text(left - 6 - text_width(&label, 1), y - 4, &label, 1, ink);
        }
        // X ticks.
        match self.x_scale {
            XScale::Linear => {
                for t in ticks(x0, x1, 6) {
                    let x = px(t) as i64;
                    c.fill_rect(x, top, 1, ph, grid, 1.0);
                    let label = fmt_tick(t);
                    c.text(x - text_width(&label, 1) / 2, top + ph + 6, &label, 1, ink);
                }
            }
            XScale::PercentileTail => {
                for (p, label) in [
                    (0.0, "0%"),
                    (90.0, "90%"),
                    (99.0, "99%"),
                    (99.9, "99.9%"),
                    (99.99, "99.99%"),
                    (99.999, "99.999%"),
                ] {
                    if fx(p) > x1 + 1e-9 {
                        break;
                    }
                    let x = px(p) as i64;
                    c.fill_rect(x, top, 1, ph, grid, 1.0);
                    c.text(x - text_width(label, 1) / 2, top + ph + 6, label, 1, ink);
                }
            }
        }
        // Axes.
        c.fill_rect(left, top, 1, ph + 1, ink, 1.0);
        c.fill_rect(left, top + ph, pw, 1, ink, 1.0);
        // Series.
        for (k, s) in self.series.iter().enumerate() {
            let col = PALETTE[k % PALETTE.len()];
            let mut prev: Option<(f32, f32)> = None;
            for &(x, y) in &s.points {
                if !(x.is_finite() && y.is_finite()) {
                    prev = None;
                    continue;
                }
                let p = (px(x), py(y));
                match prev {
                    Some(q) => c.line(q, p, 2.0, col, 1.0),
                    None if s.points.len() == 1 => c.fill_disc(p.0, p.1, 3.0, col, 1.0),
                    None => {}
                }
                prev = Some(p);
            }
        }
        // Title, labels, legend.
        c.text((w - text_width(&self.title, 2)) / 2, 8, &self.title, 2, ink);
        c.text(
            left + (pw - text_width(&self.x_label, 1)) / 2,
            h - 18,
            &self.x_label,
            1,
            ink,
        );
        c.text(6, top - 14, &self.y_label, 1, ink);
        let mut ly = top + 6;
        for (k, s) in self.series.iter().enumerate() {
            let lx = left + pw - text_width(&s.name, 1) - 30;
            c.fill_rect(
                lx - 4,
                ly - 3,
                text_width(&s.name, 1) + 32,
                14,
                [255, 255, 255],
                0.85,
            );
            c.fill_rect(lx, ly + 3, 18, 3, PALETTE[k % PALETTE.len()], 1.0);
            c.text(lx + 24, ly, &s.name, 1, ink);
            ly += 16;
        }
        c
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ticks_are_round_and_cover_the_range() {
        assert_eq!(ticks(0.0, 10.0, 5), vec![0.0, 2.0, 4.0, 6.0, 8.0, 10.0]);
        let t = ticks(0.013, 0.087, 4);
        assert!(t.first().unwrap() >= &0.013 && t.last().unwrap() <= &0.087 && t.len() >= 3);
    }

    #[test]
    fn a_chart_draws_its_series_in_colour() {
        let chart = LineChart {
            title: "t".into(),
            x_label: "x".into(),
            y_label: "y".into(),
            series: vec![Series {
                name: "a".into(),
                points: vec![(0.0, 0.0), (1.0, 1.0)],
            }],
            x_scale: XScale::Linear,
        };
        let c = chart.render(200, 150);
        let blue = c.rgb.chunks(3).filter(|p| p == &PALETTE[0]).count();
        assert!(blue > 100, "the line is drawn: {blue} pixels");
    }
}
