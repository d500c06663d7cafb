//! Newtype ids of the world graph: a node (pivotal state) and a grid cell.
//!
//! Bare `usize`s are easy to mix up (a node's index in the graph against the
//! row-major index of its cell); these two cannot be.

use serde::{Deserialize, Serialize};
use sim::{Layout, Pose};

/// A node of the world graph `G_w` (a pivotal state, or a member of any
/// candidate set such as `V_rand`), numbered `0..num_nodes`. Same width as
/// the pivot ids of the wire format (`u16`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(transparent)]
pub struct NodeId(pub u16);

impl NodeId {
    /// The id as an index into per-node tables.
    #[inline]
    pub fn index(self) -> usize {
        self.0 as usize
    }
}

impl std::fmt::Display for NodeId {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "n{}", self.0)
    }
}

/// A grid cell, by its row-major index `y · width + x` (the layout's and the
/// observation's order).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(transparent)]
pub struct CellIdx(pub u32);

impl CellIdx {
    /// The cell `(x, y)` of a grid `width` cells wide.
    #[inline]
    pub fn from_xy(x: usize, y: usize, width: usize) -> CellIdx {
        CellIdx((y * width + x) as u32)
    }

    /// The cell under a pose.
    #[inline]
    pub fn of_pose(pose: Pose, width: usize) -> CellIdx {
        CellIdx::from_xy(pose.x as usize, pose.y as usize, width)
    }

    /// The index into row-major cell tables.
    #[inline]
    pub fn index(self) -> usize {
        self.0 as usize
    }

    /// `(x, y)` of the cell in a grid `width` cells wide.
    #[inline]
    pub fn xy(self, width: usize) -> (u16, u16) {
        ((self.index() % width) as u16, (self.index() / width) as u16)
    }

    /// The pose on this cell facing `dir`.
    #[inline]
    pub fn pose(self, width: usize, dir: u8) -> Pose {
        let (x, y) = self.xy(width);
        Pose { x, y, dir }
    }

    /// The neighbouring cell in direction `dir` (0 right, 1 down, 2 left,
    /// 3 up). Layouts are enclosed by walls, so the neighbour of a cell the
    /// agent can stand on is always inside the grid.
    #[inline]
    pub fn step(self, dir: u8, layout: &Layout) -> CellIdx {
        let (dx, dy) = Pose::DIR_VEC[(dir & 3) as usize];
        let (x, y) = self.xy(layout.width);
        let x = (x as i64 + dx as i64).clamp(0, layout.width as i64 - 1) as usize;
        let y = (y as i64 + dy as i64).clamp(0, layout.height as i64 - 1) as usize;
        CellIdx::from_xy(x, y, layout.width)
    }
}

impl std::fmt::Display for CellIdx {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "cell {}", self.0)
    }
}
