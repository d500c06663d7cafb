//! The batch-environment trait the learner's algorithms are written against
//! (README.md, "The pipeline"), and its in-process implementation.
//!
//! Two transports implement [`BatchEnvironment`]:
//! - [`InProcess`]: the simulator in this process (fast tests, single-process
//!   runs, the benchmark baseline);
//! - `ShmEnv`, the shared-memory client of the pipeline, which reads
//!   observation batches in place from the sim process; it lives with the
//!   pipeline's roles in the `worldgraph` binary (`src/roles/shm_env.rs`),
//!   so this crate builds without IPC.
//!
//! An algorithm sees the same [`ObsView`] either way, so it trains in-process
//! or over the pipeline unchanged, and (the simulator being deterministic
//! per seed) with the same results.

use shm_schemas::EnvMeta;
use sim::{BatchEnv, EnvConfig, EnvState, Layout, SimError, StepBuffers};

/// One batch of observations, borrowed from the transport that produced it.
#[derive(Debug, Clone, Copy)]
pub struct ObsView<'a> {
    /// Sequence number of the batch (0 for the first after a (re)connect).
    pub seq: u64,
    /// `N × H × W` cell codes, environment `i` at `i·H·W`.
    pub cells: &'a [u8],
    /// `N × H × W` final cells: where `meta[i].done()`, the grid
    /// environment `i`'s finished episode ended on (the observation in
    /// `cells` is already the next episode's first); stale elsewhere.
    /// Empty for transports that do not carry it (benchmark stand-ins).
    pub final_cells: &'a [u8],
    /// `N` step records (reward, flags, agent pose, episode figures).
    pub meta: &'a [EnvMeta],
    /// Grid columns.
    pub width: usize,
    /// Grid rows.
    pub height: usize,
}

impl ObsView<'_> {
    /// Number of environments.
    pub fn num_envs(&self) -> usize {
        self.meta.len()
    }
    /// Cells of environment `i`.
    pub fn env_cells(&self, i: usize) -> &[u8] {
        let n = self.width * self.height;
        &self.cells[i * n..(i + 1) * n]
    }
    /// The grid environment `i`'s episode ended on, when this step ended it.
    pub fn env_final_cells(&self, i: usize) -> &[u8] {
        let n = self.width * self.height;
        &self.final_cells[i * n..(i + 1) * n]
    }
    /// Row-major cell index where environment `i`'s last action left the
    /// agent: its finished episode's final cell when the step ended one
    /// (the observation then shows the next episode's start).
    pub fn end_cell(&self, i: usize) -> u32 {
        self.meta[i].end_cell(self.width) as u32
    }
}

/// Errors of a batch environment.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum EnvError {
    /// The in-process simulator refused its configuration.
    #[error(transparent)]
    Sim(#[from] SimError),
    /// The shared-memory transport failed (schema mismatch, IPC error, ...).
    #[error(transparent)]
    Shm(#[from] shm_schemas::ShmError),
    /// The peer process that owns the environments is gone.
    #[error("the {peer} process is gone: {detail}")]
    PeerGone {
        /// Which peer.
        peer: &'static str,
        /// What was observed.
        detail: String,
    },
    /// Waiting was interrupted (Ctrl-C or a stop request).
    #[error("interrupted")]
    Interrupted,
    /// The actions do not fit the batch.
    #[error("expected {expected} actions, got {got}")]
    ActionCount {
        /// Batch size.
        expected: usize,
        /// Actions given.
        got: usize,
    },
}

/// A batch of environments stepped in lock-step: observe, then step with
/// one action per environment.
pub trait BatchEnvironment {
    /// Number of environments.
    fn num_envs(&self) -> usize;
    /// Actions the task uses (`0..num_actions`).
    fn num_actions(&self) -> usize;
    /// The current observation batch.
    fn observe(&self) -> ObsView<'_>;
    /// Applies `actions[i]` to environment `i`; afterwards [`observe`](Self::observe)
    /// returns the next batch.
    fn step(&mut self, actions: &[u8]) -> Result<(), EnvError>;
    /// Every environment's state, where the transport can save it (the
    /// in-process simulator); `None` where it cannot (another process owns
    /// the environments).
    fn snapshot(&self) -> Option<Vec<EnvState>> {
        None
    }
    /// Puts every environment back in a [`Self::snapshot`]'s state and
    /// makes [`Self::observe`] return the observation it was in. Returns
    /// false where the transport cannot.
    fn restore(&mut self, states: &[EnvState]) -> Result<bool, EnvError> {
        let _ = states;
        Ok(false)
    }
}

/// The simulator in this process.
#[derive(Debug)]
pub struct InProcess {
    batch: BatchEnv,
    buf: StepBuffers,
    seq: u64,
}

impl InProcess {
    /// `n` environments seeded from `(seed, 0..n)` on `threads` threads, reset.
    pub fn new(
        layout: Layout,
        cfg: EnvConfig,
        n: usize,
        seed: u64,
        threads: usize,
    ) -> Result<InProcess, EnvError> {
        let mut batch = BatchEnv::new(layout, cfg, n, seed, threads)?;
        let mut buf = batch.buffers();
        batch.reset(buf.out());
        Ok(InProcess { batch, buf, seq: 0 })
    }

    /// An existing batch (e.g. [`BatchEnv::with_first_index`]'s, for seeds
    /// of a stream from an offset), reset.
    pub fn from_batch(mut batch: BatchEnv) -> InProcess {
        let mut buf = batch.buffers();
        batch.reset(buf.out());
        InProcess { batch, buf, seq: 0 }
    }

    /// The simulator batch.
    pub fn batch(&self) -> &BatchEnv {
        &self.batch
    }
}

impl BatchEnvironment for InProcess {
    fn num_envs(&self) -> usize {
        self.batch.len()
    }
    fn num_actions(&self) -> usize {
        self.batch.config().task.num_actions()
    }
    fn observe(&self) -> ObsView<'_> {
        let l = self.batch.layout();
        ObsView {
            seq: self.seq,
            cells: &self.buf.cells,
            final_cells: &self.buf.final_cells,
            meta: &self.buf.meta,
            width: l.width,
            height: l.height,
        }
    }
    fn step(&mut self, actions: &[u8]) -> Result<(), EnvError> {
        if actions.len() != self.batch.len() {
            return Err(EnvError::ActionCount {
                expected: self.batch.len(),
                got: actions.len(),
            });
        }
        self.batch.step(actions, self.buf.out());
        self.seq += 1;
        Ok(())
    }
    fn snapshot(&self) -> Option<Vec<EnvState>> {
        Some(self.batch.snapshot())
    }
    fn restore(&mut self, states: &[EnvState]) -> Result<bool, EnvError> {
        self.batch.restore(states, self.buf.out())?;
        Ok(true)
    }
}
