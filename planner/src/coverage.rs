//! Visitation counts per cell, fed from the observation stream, so a user
//! can see which parts of the maze the agents cover (issue 3; the paper's
//! exploration argument, section 4.3, is about exactly this coverage).

use std::path::Path;

use serde::{Deserialize, Serialize};
use sim::render::{Canvas, draw_grid};
use sim::{EnvMeta, Layout};

use crate::error::PlannerError;
use crate::ids::CellIdx;

/// How often the agents stood on each cell.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Coverage {
    width: usize,
    height: usize,
    counts: Vec<u64>,
    total: u64,
}

impl Coverage {
    /// Zero counts for a `width × height` grid.
    pub fn new(width: usize, height: usize) -> Coverage {
        Coverage {
            width,
            height,
            counts: vec![0; width * height],
            total: 0,
        }
    }

    /// Zero counts for `layout`'s grid.
    pub fn for_layout(layout: &Layout) -> Coverage {
        Coverage::new(layout.width, layout.height)
    }

    /// Counts the agent position of every record of an observation batch.
    /// Positions outside the grid (a record of another grid) are skipped.
    /// Allocates nothing.
    pub fn observe(&mut self, batch: &[EnvMeta]) {
        for m in batch {
            let (x, y) = (m.x as usize, m.y as usize);
            if x < self.width && y < self.height {
                self.counts[y * self.width + x] += 1;
                self.total += 1;
            }
        }
    }

    /// Adds another coverage of the same grid (ignored when the grid differs).
    pub fn merge(&mut self, other: &Coverage) {
        if (self.width, self.height) == (other.width, other.height) {
            for (a, b) in self.counts.iter_mut().zip(&other.counts) {
                *a += b;
            }
            self.total += other.total;
        }
    }

    /// Visits of `cell` (0 outside the grid).
    pub fn count(&self, cell: CellIdx) -> u64 {
        self.counts.get(cell.index()).copied().unwrap_or(0)
    }

    /// All counts, row-major.
    pub fn counts(&self) -> &[u64] {
        &self.counts
    }

    /// Positions counted so far.
    pub fn total(&self) -> u64 {
        self.total
    }

    /// Cells visited at least once.
    pub fn visited_cells(&self) -> usize {
        self.counts.iter().filter(|&&c| c > 0).count()
    }

    /// Sets every count to zero.
    pub fn clear(&mut self) {
        self.counts.fill(0);
        self.total = 0;
    }

    /// A heat map over `layout`: each visited cell tinted from yellow (few
    /// visits) to red (the most), on a log scale, `px` pixels per cell.
    pub fn render(&self, layout: &Layout, px: usize) -> Canvas {
        let px = px.max(2);
        let mut canvas = Canvas::new(layout.width * px, layout.height * px, [255, 255, 255]);
        draw_grid(&mut canvas, &layout.cells, layout.width, 0, 0, px);
        let max = self.counts.iter().copied().max().unwrap_or(0);
        if max == 0 || (self.width, self.height) != (layout.width, layout.height) {
            return canvas;
        }
        let scale = ((max + 1) as f32).ln();
        for (i, &c) in self.counts.iter().enumerate().filter(|(_, c)| **c > 0) {
            let t = ((c + 1) as f32).ln() / scale;
            let colour = crate::world_graph::lerp([255, 220, 40], [210, 20, 20], t);
            let (x, y) = ((i % self.width * px) as i64, (i / self.width * px) as i64);
            canvas.fill_rect(x, y, px as i64, px as i64, colour, 0.35 + 0.5 * t);
        }
        canvas
    }

    /// Writes [`Coverage::render`] as a PNG, atomically.
    pub fn save_png(&self, layout: &Layout, path: &Path, px: usize) -> Result<(), PlannerError> {
        Ok(self.render(layout, px).save_png(path)?)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_positions_of_a_batch_and_renders() {
        let layout = sim::Maze::Small.layout(false);
        let mut cov = Coverage::for_layout(&layout);
        let at = |x, y| EnvMeta {
            x,
            y,
            ..EnvMeta::EMPTY
        };
        cov.observe(&[at(1, 1), at(1, 1), at(2, 1), at(200, 1)]);
        assert_eq!(cov.count(CellIdx::from_xy(1, 1, layout.width)), 2);
        assert_eq!((cov.total(), cov.visited_cells()), (3, 2));
        let mut twice = cov.clone();
        twice.merge(&cov);
        assert_eq!(twice.total(), 6);
        let picture = cov.render(&layout, 8);
        let plain = Coverage::for_layout(&layout).render(&layout, 8);
        assert_ne!(picture.rgb, plain.rgb, "visited cells are tinted");
        cov.clear();
        assert_eq!((cov.total(), cov.visited_cells()), (0, 0));
    }
}
