//! The observation batch (`wg/<run>/obs`): what the simulator publishes
//! after every batch step and the learner and planner read in place.
//!
//! ## Layout of one sample
//!
//! ```text
//! user header  ObsHeader (48 B)            schema version, run, seq, step, send time, N, W, H
//! payload      [u64] of payload_words()    viewed as bytes:
//!   [0, 28·N)                               N × EnvMeta            (align 4)
//!   [cells_offset, cells_offset + N·H·W)    N × H × W cell bytes   (env i at i·H·W, row-major)
//!   [final_cells_offset, … + N·H·W)         N × H × W final cells  (written where the step ended an episode)
//! ```
//!
//! The final cells are the grid a finished episode ended on (see
//! [`EnvMeta`], "The final state of a finished episode"): environment `i`'s
//! block is written only on a step whose record has `flags & DONE`, and
//! holds stale bytes otherwise.
//!
//! The payload is an iceoryx2 *slice* of `u64` words (8-byte aligned, so
//! `EnvMeta` records can be viewed in place) sized exactly for the run's
//! [`ObsShape`], where a worst-case fixed array of `MAX_ENVS × MAX_CELLS`
//! would pin megabytes for every chunk. The shape is fixed for the lifetime
//! of a run, so the publisher allocates with the `Static` strategy and
//! never regrows.
//!
//! [`ObsBatchMut`] splits a loaned sample into `(&mut ObsHeader,
//! &mut [EnvMeta], cells, final cells)` for the simulator to write directly;
//! [`ObsBatch`] is the subscribers' read view. Both are built from a header
//! and the raw payload with safe `bytemuck` casts; [`crate::service`]
//! wraps them around real samples.

use bytemuck::{Pod, Zeroable};
#[cfg(feature = "ipc")]
use iceoryx2::prelude::ZeroCopySend;

use crate::{Channel, SCHEMA_VERSION, SchemaError};

/// Most environments in one batch.
pub const MAX_ENVS: usize = 1024;
/// Most slices a batch may be published in ([`ObsShape::sliced`]).
pub const MAX_SLICES: usize = 4;
/// Longest grid side (width or height) in cells.
pub const MAX_GRID_SIDE: usize = 64;
/// Most cells of one environment's grid (`W × H`).
pub const MAX_CELLS: usize = MAX_GRID_SIDE * MAX_GRID_SIDE;
/// Offset alignment of the cell block inside the payload, in bytes.
pub const CELLS_ALIGN: usize = 8;
/// Byte debug builds fill observation loans with, so a cell the simulator
/// forgot to write is visible (no cell code uses it).
pub const SENTINEL_BYTE: u8 = 0xEE;

/// Bits of [`EnvMeta::flags`].
pub mod flags {
    /// The episode ended by the task's own rule (exit reached, lava, ...).
    pub const TERMINATED: u8 = 1 << 0;
    /// The episode ended by the step limit.
    pub const TRUNCATED: u8 = 1 << 1;
    /// The observation is the first of a new episode (auto-reset happened,
    /// or the environment was just reset).
    pub const RESET: u8 = 1 << 2;
    /// `TERMINATED | TRUNCATED`: [`super::EnvMeta::episode_return`] and
    /// [`super::EnvMeta::episode_len`] hold the finished episode's figures.
    pub const DONE: u8 = TERMINATED | TRUNCATED;
}

/// What one environment reports after one step: the reward of the action,
/// how the episode stands, the agent's state in the observation, and where
/// the action left the agent.
///
/// Position `x` is the column from the left, `y` the row from the top;
/// `dir` is 0 right, 1 down, 2 left, 3 up; `carrying` is a cell code
/// (`sim::Object as u8`) or [`EnvMeta::CARRYING_NOTHING`].
///
/// ## The final state of a finished episode
/// With same-step auto-reset, the record of a step that ended an episode
/// (`flags & DONE`) holds the *next* episode's first pose in `x, y, dir,
/// carrying`. The pose the action actually led to — the finished episode's
/// final state, where arrival is judged — is in `end_x, end_y, end_dir,
/// end_carrying` ([`EnvMeta::end_cell`]); the batch carries the final grid
/// beside the observation's ([`ObsBatch::final_cells`]), so a truncated step
/// can be bootstrapped from the value of its final state (Gymnasium's
/// `final_obs`). On every other step the `end_*` fields equal the
/// observation's pose.
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
#[cfg_attr(feature = "ipc", derive(ZeroCopySend), type_name("wg.EnvMeta.v3"))]
#[repr(C)]
pub struct EnvMeta {
    /// Reward of the step that produced this record.
    pub reward: f32,
    /// Return of the episode so far, or of the finished one when `flags & DONE`.
    pub episode_return: f32,
    /// Steps taken in the episode so far, or of the finished one when `flags & DONE`.
    pub episode_len: u32,
    /// Agent column.
    pub x: u16,
    /// Agent row.
    pub y: u16,
    /// Agent facing: 0 right, 1 down, 2 left, 3 up.
    pub dir: u8,
    /// Carried object's cell code, or [`EnvMeta::CARRYING_NOTHING`].
    pub carrying: u8,
    /// Bits from [`flags`].
    pub flags: u8,
    /// Balls collected in the current (or just finished) episode.
    pub balls: u8,
    /// Column the step's action left the agent in (before any auto-reset).
    pub end_x: u16,
    /// Row the step's action left the agent in (before any auto-reset).
    pub end_y: u16,
    /// Facing after the step's action (before any auto-reset).
    pub end_dir: u8,
    /// Carried object after the step's action (before any auto-reset).
    pub end_carrying: u8,
    /// Zero; keeps the record free of implicit padding.
    pub reserved: u16,
}

impl EnvMeta {
    /// Value of [`EnvMeta::carrying`] when the agent's hands are empty.
    pub const CARRYING_NOTHING: u8 = 0xff;

    /// A record with every field zero and nothing carried.
    pub const EMPTY: EnvMeta = EnvMeta {
        reward: 0.0,
        episode_return: 0.0,
        episode_len: 0,
        x: 0,
        y: 0,
        dir: 0,
        carrying: Self::CARRYING_NOTHING,
        flags: 0,
        balls: 0,
        end_x: 0,
        end_y: 0,
        end_dir: 0,
        end_carrying: Self::CARRYING_NOTHING,
        reserved: 0,
    };

    /// True when this step ended the episode (terminated or truncated).
    pub fn done(&self) -> bool {
        self.flags & flags::DONE != 0
    }
    /// True when the task's own rule ended the episode.
    pub fn terminated(&self) -> bool {
        self.flags & flags::TERMINATED != 0
    }
    /// True when the step limit ended the episode.
    pub fn truncated(&self) -> bool {
        self.flags & flags::TRUNCATED != 0
    }
    /// Row-major cell index of the observation's agent on a grid `width`
    /// cells wide.
    pub fn cell(&self, width: usize) -> usize {
        self.y as usize * width + self.x as usize
    }
    /// Row-major cell index where the step's action left the agent: the
    /// finished episode's final cell on a step that ended it, the
    /// observation's cell otherwise.
    pub fn end_cell(&self, width: usize) -> usize {
        self.end_y as usize * width + self.end_x as usize
    }
    /// Sets the `end_*` fields to the observation's pose (a step that did
    /// not end an episode, or a reset).
    pub fn end_at_agent(&mut self) {
        self.end_x = self.x;
        self.end_y = self.y;
        self.end_dir = self.dir;
        self.end_carrying = self.carrying;
    }
}

impl Default for EnvMeta {
    fn default() -> Self {
        Self::EMPTY
    }
}

const _: () = assert!(std::mem::size_of::<EnvMeta>() == 28);
const _: () = assert!(std::mem::align_of::<EnvMeta>() == 4);

/// Shape of the observation batches of a run: batch size and grid size.
/// Fixed for the lifetime of a run; part of the obs service's identity
/// (service attributes `wg.num_envs`, `wg.grid`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub struct ObsShape {
    /// Environments per batch (`N`).
    pub num_envs: u32,
    /// Grid width in cells (`W`).
    pub width: u16,
    /// Grid height in cells (`H`).
    pub height: u16,
    /// Slices `K` the simulator's batch is split into (1: one sample per
    /// step of the whole batch). Each sample carries `N` = batch / `K`
    /// environments; see [`ObsShape::sliced`].
    pub slices: u16,
}

impl ObsShape {
    /// A checked shape of one slice: `1 ≤ N ≤ MAX_ENVS`,
    /// `1 ≤ W, H ≤ MAX_GRID_SIDE`.
    pub fn new(num_envs: usize, width: usize, height: usize) -> Result<ObsShape, SchemaError> {
        check_range(Channel::Obs, "num_envs", num_envs, MAX_ENVS)?;
        check_range(Channel::Obs, "width", width, MAX_GRID_SIDE)?;
        check_range(Channel::Obs, "height", height, MAX_GRID_SIDE)?;
        Ok(ObsShape {
            num_envs: num_envs as u32,
            width: width as u16,
            height: height as u16,
            slices: 1,
        })
    }

    /// The shape of a batch of `total_envs` environments published as
    /// `slices` samples of `total_envs / slices` environments each
    /// (double-buffered sampling: the simulator steps one slice while the
    /// learner chooses the other's actions). `slices` must divide the batch
    /// and lie in `1..=MAX_SLICES`.
    pub fn sliced(
        total_envs: usize,
        slices: usize,
        width: usize,
        height: usize,
    ) -> Result<ObsShape, SchemaError> {
        check_range(Channel::Obs, "slices", slices, MAX_SLICES)?;
        if !total_envs.is_multiple_of(slices) {
            return Err(SchemaError::SlicesDoNotDivide {
                channel: Channel::Obs,
                slices,
                total: total_envs,
            });
        }
        let mut shape = ObsShape::new(total_envs / slices, width, height)?;
        shape.slices = slices as u16;
        Ok(shape)
    }

    /// Environments of the whole batch (`N · K`).
    pub const fn total_envs(&self) -> usize {
        self.envs() * self.slices as usize
    }

    /// `N` as `usize`.
    pub const fn envs(&self) -> usize {
        self.num_envs as usize
    }
    /// `W × H`.
    pub const fn cells_per_env(&self) -> usize {
        self.width as usize * self.height as usize
    }
    /// Bytes of the `EnvMeta` block (`28 · N`).
    pub const fn meta_bytes(&self) -> usize {
        self.envs() * size_of::<EnvMeta>()
    }
    /// Byte offset of the cell block in the payload.
    pub const fn cells_offset(&self) -> usize {
        self.meta_bytes().next_multiple_of(CELLS_ALIGN)
    }
    /// Bytes of the cell block (`N · H · W`).
    pub const fn cells_bytes(&self) -> usize {
        self.envs() * self.cells_per_env()
    }
    /// Byte offset of the final-cells block in the payload.
    pub const fn final_cells_offset(&self) -> usize {
        (self.cells_offset() + self.cells_bytes()).next_multiple_of(CELLS_ALIGN)
    }
    /// Payload bytes actually used.
    pub const fn payload_bytes(&self) -> usize {
        self.final_cells_offset() + self.cells_bytes()
    }
    /// Payload length in `u64` words (the iceoryx2 slice length).
    pub const fn payload_words(&self) -> usize {
        self.payload_bytes().div_ceil(8)
    }
    /// The `wg.grid` attribute value, `"WxH"`.
    pub fn grid_attr(&self) -> String {
        format!("{}x{}", self.width, self.height)
    }
}

/// Header of an observation batch (iceoryx2 user header of `wg/<run>/obs`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Pod, Zeroable)]
#[cfg_attr(feature = "ipc", derive(ZeroCopySend), type_name("wg.ObsHeader.v3"))]
#[repr(C)]
pub struct ObsHeader {
    /// [`SCHEMA_VERSION`] of the writer.
    pub schema_version: u32,
    /// Environments in the batch (`N`).
    pub num_envs: u32,
    /// [`crate::service::RunName::id`] of the run.
    pub run_id: u64,
    /// Batch sequence number, +1 per published batch; the action batch that
    /// answers it carries the same number.
    pub seq: u64,
    /// Simulator step count of this batch (0 after the initial reset).
    pub step: u64,
    /// `CLOCK_MONOTONIC` time of `send()` in ns ([`crate::monotonic_ns`]).
    pub send_time_ns: u64,
    /// Grid width (`W`).
    pub width: u16,
    /// Grid height (`H`).
    pub height: u16,
    /// Which slice of the batch this sample holds (`seq mod slices`):
    /// environments `slice · N .. (slice + 1) · N` of the simulator.
    pub slice: u16,
    /// Slices per batch (`K`, [`ObsShape::slices`]).
    pub slices: u16,
}

impl ObsHeader {
    /// A header for `shape` in run `run_id`, sequence and step zero.
    pub fn new(shape: &ObsShape, run_id: u64) -> ObsHeader {
        ObsHeader {
            schema_version: SCHEMA_VERSION,
            num_envs: shape.num_envs,
            run_id,
            width: shape.width,
            height: shape.height,
            slices: shape.slices,
            ..ObsHeader::default()
        }
    }

    /// The shape this header announces (unchecked).
    pub fn shape(&self) -> ObsShape {
        ObsShape {
            num_envs: self.num_envs,
            width: self.width,
            height: self.height,
            slices: self.slices,
        }
    }

    /// Checks version, run and shape against what this process expects.
    pub fn check(&self, expected: &ObsShape, run_id: u64) -> Result<(), SchemaError> {
        check_version(Channel::Obs, self.schema_version)?;
        check_run(Channel::Obs, run_id, self.run_id)?;
        if (self.width, self.height) != (expected.width, expected.height) {
            return Err(SchemaError::GridShape {
                channel: Channel::Obs,
                expected: (expected.width, expected.height),
                wire: (self.width, self.height),
            });
        }
        if self.slices != expected.slices || self.slice >= self.slices {
            return Err(SchemaError::Slices {
                channel: Channel::Obs,
                expected: expected.slices,
                wire: self.slices,
            });
        }
        if self.num_envs != expected.num_envs {
            return Err(SchemaError::BatchSize {
                channel: Channel::Obs,
                expected: expected.num_envs,
                wire: self.num_envs,
            });
        }
        Ok(())
    }
}

/// Read view of one observation batch, borrowed from a sample.
#[derive(Debug, Clone, Copy)]
pub struct ObsBatch<'a> {
    /// The header.
    pub header: &'a ObsHeader,
    /// `N` step records.
    pub meta: &'a [EnvMeta],
    /// `N × H × W` cell bytes, environment `i` at `i·H·W`, row-major.
    pub cells: &'a [u8],
    /// `N × H × W` final cells of the episodes that ended with this step
    /// (environment `i`'s block is meaningful only where `meta[i].done()`).
    pub final_cells: &'a [u8],
}

impl<'a> ObsBatch<'a> {
    /// Views `payload` according to `header`, after checking the header
    /// against the expected shape and run.
    pub fn new(
        header: &'a ObsHeader,
        payload: &'a [u64],
        expected: &ObsShape,
        run_id: u64,
    ) -> Result<ObsBatch<'a>, SchemaError> {
        header.check(expected, run_id)?;
        let bytes: &[u8] = bytemuck::cast_slice(payload);
        check_len(Channel::Obs, expected.payload_bytes(), bytes.len())?;
        let meta = bytemuck::cast_slice(&bytes[..expected.meta_bytes()]);
        let cells = &bytes[expected.cells_offset()..][..expected.cells_bytes()];
        let final_cells = &bytes[expected.final_cells_offset()..expected.payload_bytes()];
        Ok(ObsBatch {
            header,
            meta,
            cells,
            final_cells,
        })
    }

    /// The shape of the batch.
    pub fn shape(&self) -> ObsShape {
        self.header.shape()
    }

    /// Environment `i`'s grid, `H × W` bytes, row-major.
    pub fn env_cells(&self, i: usize) -> &'a [u8] {
        let cpe = self.shape().cells_per_env();
        &self.cells[i * cpe..(i + 1) * cpe]
    }
}

/// Write view of a loaned observation sample: the simulator steps straight
/// into `meta` and `cells` (the contents are stale on loan and must all be
/// overwritten) and may adjust `header` (`seq`, `step`; the service layer
/// fills the rest and stamps `send_time_ns` at send).
#[derive(Debug)]
pub struct ObsBatchMut<'a> {
    /// The header.
    pub header: &'a mut ObsHeader,
    /// `N` step records.
    pub meta: &'a mut [EnvMeta],
    /// `N × H × W` cell bytes, environment `i` at `i·H·W`, row-major.
    pub cells: &'a mut [u8],
    /// `N × H × W` final cells (see [`ObsBatch::final_cells`]).
    pub final_cells: &'a mut [u8],
}

impl<'a> ObsBatchMut<'a> {
    /// Views `payload` as a batch of `shape`, writing the shape into the
    /// header (`schema_version`, `num_envs`, `width`, `height`).
    pub fn new(
        header: &'a mut ObsHeader,
        payload: &'a mut [u64],
        shape: &ObsShape,
    ) -> Result<ObsBatchMut<'a>, SchemaError> {
        let bytes: &mut [u8] = bytemuck::cast_slice_mut(payload);
        check_len(Channel::Obs, shape.payload_bytes(), bytes.len())?;
        header.schema_version = SCHEMA_VERSION;
        header.num_envs = shape.num_envs;
        header.width = shape.width;
        header.height = shape.height;
        let (meta, rest) = bytes.split_at_mut(shape.cells_offset());
        let meta = bytemuck::cast_slice_mut(&mut meta[..shape.meta_bytes()]);
        let (cells, rest) = rest.split_at_mut(shape.final_cells_offset() - shape.cells_offset());
        let cells = &mut cells[..shape.cells_bytes()];
        let final_cells = &mut rest[..shape.cells_bytes()];
        Ok(ObsBatchMut {
            header,
            meta,
            cells,
            final_cells,
        })
    }

    /// The parts, for handing `meta`, `cells` and `final_cells` to the
    /// simulator.
    #[allow(clippy::type_complexity)]
    pub fn into_parts(
        self,
    ) -> (
        &'a mut ObsHeader,
        &'a mut [EnvMeta],
        &'a mut [u8],
        &'a mut [u8],
    ) {
        (self.header, self.meta, self.cells, self.final_cells)
    }

    /// Environment `i`'s grid, mutable.
    pub fn env_cells_mut(&mut self, i: usize) -> &mut [u8] {
        let cpe = self.header.shape().cells_per_env();
        &mut self.cells[i * cpe..(i + 1) * cpe]
    }
}

/// `Err(OutOfRange)` unless `1 <= value <= max`.
pub(crate) fn check_range(
    channel: Channel,
    what: &'static str,
    value: usize,
    max: usize,
) -> Result<(), SchemaError> {
    if (1..=max).contains(&value) {
        Ok(())
    } else {
        Err(SchemaError::OutOfRange {
            channel,
            what,
            value,
            max,
        })
    }
}

/// `Err(SchemaVersion)` unless `wire == SCHEMA_VERSION`.
pub(crate) fn check_version(channel: Channel, wire: u32) -> Result<(), SchemaError> {
    if wire == SCHEMA_VERSION {
        Ok(())
    } else {
        Err(SchemaError::SchemaVersion {
            channel,
            wire,
            ours: SCHEMA_VERSION,
        })
    }
}

/// `Err(RunMismatch)` unless the run ids agree.
pub(crate) fn check_run(channel: Channel, expected: u64, wire: u64) -> Result<(), SchemaError> {
    if expected == wire {
        Ok(())
    } else {
        Err(SchemaError::RunMismatch {
            channel,
            expected,
            wire,
        })
    }
}

/// `Err(PayloadTooShort)` unless `got >= needed`.
pub(crate) fn check_len(channel: Channel, needed: usize, got: usize) -> Result<(), SchemaError> {
    if got >= needed {
        Ok(())
    } else {
        Err(SchemaError::PayloadTooShort {
            channel,
            needed,
            got,
        })
    }
}

const _: () = assert!(size_of::<ObsHeader>() == 48);
const _: () = assert!(align_of::<ObsHeader>() == 8);
const _: () = assert!(align_of::<EnvMeta>() <= align_of::<u64>());

#[cfg(test)]
mod tests {
    use super::*;

    fn shape() -> ObsShape {
        ObsShape::new(3, 5, 4).unwrap()
    }

    #[test]
    fn layout_figures() {
        let s = shape();
        assert_eq!(s.cells_per_env(), 20);
        assert_eq!(s.meta_bytes(), 84);
        assert_eq!(s.cells_offset(), 88);
        assert_eq!(s.final_cells_offset(), 152);
        assert_eq!(s.payload_bytes(), 212);
        assert_eq!(s.payload_words(), 27);
        let big = ObsShape::new(1024, 25, 19).unwrap();
        assert_eq!(big.payload_bytes(), 1024 * 28 + 2 * 1024 * 475);
    }

    #[test]
    fn sliced_shapes_split_the_batch() {
        let s = ObsShape::sliced(256, 2, 25, 19).unwrap();
        assert_eq!((s.envs(), s.slices, s.total_envs()), (128, 2, 256));
        assert_eq!(ObsShape::new(256, 25, 19).unwrap().slices, 1);
        let e = ObsShape::sliced(10, 4, 5, 5).unwrap_err();
        assert_eq!(
            e.to_string(),
            "observation batch: 4 slices do not divide a batch of 10 environments"
        );
        assert!(ObsShape::sliced(8, 0, 5, 5).is_err());
        assert!(ObsShape::sliced(10, MAX_SLICES + 1, 5, 5).is_err());
        // A header of another slicing is refused by name.
        let mut h = ObsHeader::new(&s, 1);
        assert!(h.check(&s, 1).is_ok());
        h.slices = 1;
        let e = h.check(&s, 1).unwrap_err();
        assert!(
            e.to_string()
                .contains("batch in 2 slice(s) expected, publisher sends 1"),
            "{e}"
        );
    }

    #[test]
    fn shape_limits() {
        assert!(ObsShape::new(0, 5, 5).is_err());
        assert!(ObsShape::new(MAX_ENVS + 1, 5, 5).is_err());
        let e = ObsShape::new(4, MAX_GRID_SIDE + 1, 5).unwrap_err();
        assert!(e.to_string().contains("width = 65"), "{e}");
    }

    #[test]
    fn write_then_read_views() {
        let s = shape();
        let mut words = vec![0u64; s.payload_words()];
        let mut header = ObsHeader::new(&s, 0);
        {
            let b = ObsBatchMut::new(&mut header, &mut words, &s).unwrap();
            let (h, meta, cells, final_cells) = b.into_parts();
            final_cells.fill(9);
            h.seq = 7;
            h.run_id = 42;
            for (i, m) in meta.iter_mut().enumerate() {
                *m = EnvMeta {
                    x: i as u16,
                    reward: i as f32 * 0.5,
                    ..EnvMeta::EMPTY
                };
            }
            for (i, c) in cells.iter_mut().enumerate() {
                *c = i as u8;
            }
        }
        let r = ObsBatch::new(&header, &words, &s, 42).unwrap();
        assert_eq!(r.header.seq, 7);
        assert_eq!(r.meta.len(), 3);
        assert_eq!(r.meta[2].x, 2);
        assert_eq!(r.meta[1].reward, 0.5);
        assert_eq!(
            r.env_cells(1),
            &(20..40).map(|i| i as u8).collect::<Vec<_>>()[..]
        );
        assert!(r.final_cells.len() == 60 && r.final_cells.iter().all(|&c| c == 9));
    }

    #[test]
    fn read_view_refuses_mismatches() {
        let s = shape();
        let mut words = vec![0u64; s.payload_words()];
        let mut header = ObsHeader::new(&s, 1);
        ObsBatchMut::new(&mut header, &mut words, &s).unwrap();
        let other = ObsShape::new(3, 13, 13).unwrap();
        let e = ObsBatch::new(&header, &words, &other, 1).unwrap_err();
        assert_eq!(
            e.to_string(),
            "observation batch: grid 13x13 expected, publisher sends 5x4"
        );
        let fewer = ObsShape::new(2, 5, 4).unwrap();
        assert!(matches!(
            ObsBatch::new(&header, &words, &fewer, 1),
            Err(SchemaError::BatchSize {
                expected: 2,
                wire: 3,
                ..
            })
        ));
        assert!(matches!(
            ObsBatch::new(&header, &words, &s, 2),
            Err(SchemaError::RunMismatch { .. })
        ));
        let mut v2 = header;
        v2.schema_version = SCHEMA_VERSION + 1;
        let e = ObsBatch::new(&v2, &words, &s, 1).unwrap_err();
        assert_eq!(
            e.to_string(),
            format!(
                "observation batch schema v{} on the wire, this process speaks v{}",
                SCHEMA_VERSION + 1,
                SCHEMA_VERSION
            )
        );
        assert!(matches!(
            ObsBatch::new(&header, &words[..10], &s, 1),
            Err(SchemaError::PayloadTooShort {
                needed: 212,
                got: 80,
                ..
            })
        ));
    }

    /// A writer of schema v2 (20-byte records, no end pose, no final cells)
    /// is refused by its header, naming both versions; and a payload of the
    /// v2 size behind a current header is too short, never read.
    #[test]
    fn a_v2_batch_is_refused_by_a_v3_reader() {
        assert_eq!(SCHEMA_VERSION, 3, "update this test's versions");
        let s = shape();
        let mut words = vec![0u64; s.payload_words()];
        let mut header = ObsHeader::new(&s, 1);
        ObsBatchMut::new(&mut header, &mut words, &s).unwrap();
        let mut v2 = header;
        v2.schema_version = 2;
        let e = ObsBatch::new(&v2, &words, &s, 1).unwrap_err();
        assert!(matches!(
            e,
            SchemaError::SchemaVersion {
                channel: Channel::Obs,
                wire: 2,
                ours: 3
            }
        ));
        assert_eq!(
            e.to_string(),
            "observation batch schema v2 on the wire, this process speaks v3"
        );
        // 3 × 20 bytes of records, padded to 64, and 3 × 20 cells: 16 words.
        let v2_words = (64 + 60usize).div_ceil(8);
        assert!(matches!(
            ObsBatch::new(&header, &words[..v2_words], &s, 1),
            Err(SchemaError::PayloadTooShort {
                needed: 212,
                got: 128,
                ..
            })
        ));
    }
}
