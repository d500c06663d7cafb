//! The world graph drawn on its maze ([`WorldGraph::render`]).

use std::path::Path;

use sim::render::{Canvas, Rgb, draw_grid};

use super::WorldGraph;
use crate::error::PlannerError;
use crate::ids::CellIdx;

impl WorldGraph {
    /// Colours of [`WorldGraph::render`]'s edges: the lightest edge's (dark
    /// blue) and the heaviest's (light blue); the others lie between.
    pub const EDGE_COLOURS: (Rgb, Rgb) = ([20, 50, 170], [150, 175, 225]);
    /// Colour of [`WorldGraph::render`]'s node discs (on a white ring).
    pub const NODE_COLOUR: Rgb = [200, 30, 110];

    /// The maze with the graph drawn on it, `px` pixels per cell: each edge
    /// along its path, through the cells it visits (dark for light edges,
    /// pale for heavy ones; every segment is offset to the left of its
    /// direction and the last ends in an arrow head, so `p → q` and `q → p`
    /// are told apart), nodes as discs.
    pub fn render(&self, px: usize) -> Canvas {
        let l = self.layout();
        let px = px.max(4);
        let mut canvas = Canvas::new(l.width * px, l.height * px, [255, 255, 255]);
        draw_grid(&mut canvas, &l.cells, l.width, 0, 0, px);
        let s = px as f32;
        let centre = |c: CellIdx| {
            let (x, y) = c.xy(l.width);
            ((x as f32 + 0.5) * s, (y as f32 + 0.5) * s)
        };
        let (wmin, wmax) = self.edges.iter().fold((u32::MAX, 0), |(lo, hi), e| {
            (lo.min(e.weight()), hi.max(e.weight()))
        });
        for e in &self.edges {
            let t = if wmax > wmin {
                (e.weight() - wmin) as f32 / (wmax - wmin) as f32
            } else {
                0.0
            };
            let colour = lerp(Self::EDGE_COLOURS.0, Self::EDGE_COLOURS.1, t);
            // The cells the path passes, each once in a row (turns stay).
            let mut cells = vec![self.nodes()[e.from.index()]];
            for &c in &e.cells {
                if cells.last() != Some(&c) {
                    cells.push(c);
                }
            }
            let points: Vec<(f32, f32)> = cells.iter().map(|&c| centre(c)).collect();
            for (k, pair) in points.windows(2).enumerate() {
                let (a, b) = (pair[0], pair[1]);
                let (dx, dy) = (b.0 - a.0, b.1 - a.1);
                let len = (dx * dx + dy * dy).sqrt().max(1e-3);
                let (ux, uy) = (dx / len, dy / len);
                let off = (uy * s * 0.12, -ux * s * 0.12);
                let (a, b) = ((a.0 + off.0, a.1 + off.1), (b.0 + off.0, b.1 + off.1));
                canvas.line(a, b, (s * 0.08).max(1.0), colour, 0.8);
                if k + 2 == points.len() {
                    let tip = (b.0 - ux * s * 0.3, b.1 - uy * s * 0.3);
                    let base = (tip.0 - ux * s * 0.3, tip.1 - uy * s * 0.3);
                    let side = (-uy * s * 0.14, ux * s * 0.14);
                    canvas.fill_triangle(
                        [
                            tip,
                            (base.0 + side.0, base.1 + side.1),
                            (base.0 - side.0, base.1 - side.1),
                        ],
                        colour,
                        0.9,
                    );
                }
            }
        }
        for &c in self.nodes() {
            let (x, y) = centre(c);
            canvas.fill_disc(x, y, s * 0.3, [255, 255, 255], 1.0);
            canvas.fill_disc(x, y, s * 0.24, Self::NODE_COLOUR, 1.0);
        }
        canvas
    }

    /// Writes [`WorldGraph::render`] as a PNG, atomically.
    pub fn save_png(&self, path: &Path, px: usize) -> Result<(), PlannerError> {
        Ok(self.render(px).save_png(path)?)
    }
}

/// The colour a fraction `t` of the way from `a` to `b` (clamped to
/// [0, 1]).
pub(crate) fn lerp(a: Rgb, b: Rgb, t: f32) -> Rgb {
    let t = t.clamp(0.0, 1.0);
    [0, 1, 2].map(|i| (a[i] as f32 + (b[i] as f32 - a[i] as f32) * t).round() as u8)
}
