//! Charts for the reports: line charts (learning curves, discovery curves,
//! latency percentile plots, and mean ± std bands), and captions for the
//! pictures (a title above, a legend of the picture's own marks below).
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
//!
//! ## Files
//! - `line.rs`: line charts ([`LineChart`], [`Band`]);
//! - `caption.rs`: captioned pictures ([`captioned`], [`LegendEntry`]);
//! - this one: what both share (the font, the palette).

mod caption;
mod line;

use std::sync::Once;

use plotters::style::FontStyle;
use sim::render::Rgb;

pub use self::caption::{
    LEGEND_CELL, LegendEntry, Mark, blended, captioned, cell_sample, object_entries,
};
pub use self::line::{Band, LineChart, Series, XScale, band_chart};

/// The font every chart's text is set in (DejaVu Sans Mono; licence in
/// `assets/fonts/LICENSE-DejaVu`).
const FONT: &[u8] = include_bytes!("../../assets/fonts/DejaVuSansMono.ttf");

/// Colours for successive series: matplotlib's tab10, so that the ten
/// configurations of the paper's Table 1 each get their own, then black and
/// a dark magenta for a reference row beside them (`table --reference`).
pub const PALETTE: [Rgb; 12] = [
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
    [0, 0, 0],
    [128, 0, 96],
];

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
