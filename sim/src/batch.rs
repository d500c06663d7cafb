//! Batched stepping: N environments stepped in parallel with rayon, writing
//! into caller-provided buffers (EnvPool's layout).
//!
//! The caller owns the output: `cells` holds `N × H × W` bytes (environment
//! `i`'s grid at `i·H·W`), `meta` holds `N` [`EnvMeta`] records. In the
//! pipeline both live inside a loaned shared-memory sample, so the
//! simulator's step is the only write of an observation. A step allocates
//! nothing.
//!
//! Environment `i` is seeded from `(seed, i)` ([`crate::env::env_seed`]) and
//! only ever touches its own slices, so results do not depend on the number
//! of threads or on how rayon splits the work.

use std::sync::Arc;

use rayon::prelude::*;
use shm_schemas::EnvMeta;

use crate::SimError;
use crate::env::{Env, EnvConfig, EnvState, Shared};
use crate::layout::Layout;

/// Output buffers of one batch step (or reset).
#[derive(Debug)]
pub struct StepOut<'a> {
    /// `N × H × W` cell codes.
    pub cells: &'a mut [u8],
    /// `N × H × W` final cells: environment `i`'s block receives the grid
    /// its episode ended on when the step ends it, and is untouched
    /// otherwise ([`shm_schemas::ObsBatch::final_cells`]).
    pub final_cells: &'a mut [u8],
    /// `N` step records.
    pub meta: &'a mut [EnvMeta],
}

/// Owned output buffers sized for a batch, for in-process use.
#[derive(Debug, Clone)]
pub struct StepBuffers {
    /// `N × H × W` cell codes.
    pub cells: Vec<u8>,
    /// `N × H × W` final cells of the episodes the last step ended.
    pub final_cells: Vec<u8>,
    /// `N` step records.
    pub meta: Vec<EnvMeta>,
}

impl StepBuffers {
    /// Buffers for `n` environments of `cells_per_env` cells.
    pub fn new(n: usize, cells_per_env: usize) -> StepBuffers {
        StepBuffers {
            cells: vec![0; n * cells_per_env],
            final_cells: vec![0; n * cells_per_env],
            meta: vec![EnvMeta::EMPTY; n],
        }
    }

    /// Borrowed view for [`BatchEnv::step`].
    pub fn out(&mut self) -> StepOut<'_> {
        StepOut {
            cells: &mut self.cells,
            final_cells: &mut self.final_cells,
            meta: &mut self.meta,
        }
    }
}

/// A batch of environments on one layout.
#[derive(Debug)]
pub struct BatchEnv {
    envs: Vec<Env>,
    pool: Option<rayon::ThreadPool>,
    cells_per_env: usize,
    /// Environments per rayon task.
    chunk: usize,
}

impl BatchEnv {
    /// `n` environments seeded from `(seed, 0..n)`, stepped on `threads`
    /// threads (1 = on the caller's thread, no pool).
    pub fn new(
        layout: Layout,
        cfg: EnvConfig,
        n: usize,
        seed: u64,
        threads: usize,
    ) -> Result<BatchEnv, SimError> {
        BatchEnv::with_first_index(layout, cfg, 0, n, seed, threads)
    }

    /// Environments `first .. first + n` of a larger batch, each seeded from
    /// `(seed, i)` as in that batch: one slice of a batch that is stepped in
    /// parts (the pipeline's double-buffered sampling), with the same
    /// trajectories as the whole batch.
    pub fn with_first_index(
        layout: Layout,
        cfg: EnvConfig,
        first: usize,
        n: usize,
        seed: u64,
        threads: usize,
    ) -> Result<BatchEnv, SimError> {
        if n == 0 {
            return Err(SimError::Config(
                "a batch needs at least one environment".into(),
            ));
        }
        if threads == 0 {
            return Err(SimError::Config("--threads must be at least 1".into()));
        }
        if cfg.max_steps == 0 {
            return Err(SimError::Config("max_steps must be at least 1".into()));
        }
        let cells_per_env = layout.width * layout.height;
        let shared = Shared::new(layout, cfg);
        let envs = (0..n)
            .map(|i| Env::with_shared(Arc::clone(&shared), seed, (first + i) as u64))
            .collect();
        let pool = if threads > 1 {
            Some(
                rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .thread_name(|i| format!("sim-{i}"))
                    .build()
                    .map_err(|e| {
                        SimError::Config(format!("cannot start {threads} threads: {e}"))
                    })?,
            )
        } else {
            None
        };
        // A few tasks per thread balances load without drowning in overhead.
        let chunk = n.div_ceil(threads * 4).max(16);
        Ok(BatchEnv {
            envs,
            pool,
            cells_per_env,
            chunk,
        })
    }

    /// Number of environments.
    pub fn len(&self) -> usize {
        self.envs.len()
    }

    /// True for an empty batch (never: `new` refuses it).
    pub fn is_empty(&self) -> bool {
        self.envs.is_empty()
    }

    /// Cells (bytes) of one environment's observation.
    pub fn cells_per_env(&self) -> usize {
        self.cells_per_env
    }

    /// The layout shared by the batch.
    pub fn layout(&self) -> &Layout {
        self.envs[0].layout()
    }

    /// The configuration shared by the batch.
    pub fn config(&self) -> &EnvConfig {
        self.envs[0].config()
    }

    /// Environment `i`.
    pub fn env(&self, i: usize) -> &Env {
        &self.envs[i]
    }

    /// Every environment's state ([`Env::snapshot`]).
    pub fn snapshot(&self) -> Vec<EnvState> {
        self.envs.iter().map(Env::snapshot).collect()
    }

    /// Puts every environment back in its saved state and writes the
    /// observation it was in (grid and agent; the step fields cleared).
    pub fn restore(&mut self, states: &[EnvState], out: StepOut<'_>) -> Result<(), SimError> {
        self.check(&out);
        if states.len() != self.len() {
            return Err(SimError::Config(format!(
                "{} saved environments for a batch of {}",
                states.len(),
                self.len()
            )));
        }
        let cpe = self.cells_per_env;
        for (((env, state), cells), meta) in self
            .envs
            .iter_mut()
            .zip(states)
            .zip(out.cells.chunks_mut(cpe))
            .zip(out.meta.iter_mut())
        {
            env.restore(state)?;
            env.observe(cells, meta);
        }
        Ok(())
    }

    /// Owned buffers of the right size for this batch.
    pub fn buffers(&self) -> StepBuffers {
        StepBuffers::new(self.len(), self.cells_per_env)
    }

    fn check(&self, out: &StepOut<'_>) {
        assert_eq!(
            out.cells.len(),
            self.len() * self.cells_per_env,
            "cells buffer size"
        );
        assert_eq!(
            out.final_cells.len(),
            out.cells.len(),
            "final cells buffer size"
        );
        assert_eq!(out.meta.len(), self.len(), "meta buffer size");
    }

    /// Resets every environment and writes the first observations.
    pub fn reset(&mut self, out: StepOut<'_>) {
        self.check(&out);
        let cpe = self.cells_per_env;
        for ((env, cells), meta) in self
            .envs
            .iter_mut()
            .zip(out.cells.chunks_mut(cpe))
            .zip(out.meta.iter_mut())
        {
            env.reset(cells, meta);
        }
    }

    /// Steps environment `i` with `actions[i]` for every `i`, in parallel.
    /// Returns how many episodes ended in this step (counted while each
    /// environment's record is hot, so callers need no second pass).
    pub fn step(&mut self, actions: &[u8], out: StepOut<'_>) -> usize {
        self.check(&out);
        assert_eq!(actions.len(), self.len(), "one action per environment");
        let (cpe, chunk) = (self.cells_per_env, self.chunk);
        let StepOut {
            cells,
            final_cells,
            meta,
        } = out;
        let BatchEnv { envs, pool, .. } = self;
        match pool {
            Some(pool) => pool.install(|| {
                envs.par_chunks_mut(chunk)
                    .zip(actions.par_chunks(chunk))
                    .zip(cells.par_chunks_mut(chunk * cpe))
                    .zip(final_cells.par_chunks_mut(chunk * cpe))
                    .zip(meta.par_chunks_mut(chunk))
                    .map(|((((envs, actions), cells), finals), meta)| {
                        step_chunk(envs, actions, cells, finals, meta, cpe)
                    })
                    .sum()
            }),
            None => step_chunk(envs, actions, cells, final_cells, meta, cpe),
        }
    }
}

#[inline]
fn step_chunk(
    envs: &mut [Env],
    actions: &[u8],
    cells: &mut [u8],
    final_cells: &mut [u8],
    meta: &mut [EnvMeta],
    cpe: usize,
) -> usize {
    let mut ended = 0;
    for ((((env, &a), c), f), m) in envs
        .iter_mut()
        .zip(actions)
        .zip(cells.chunks_exact_mut(cpe))
        .zip(final_cells.chunks_exact_mut(cpe))
        .zip(meta.iter_mut())
    {
        env.step(a, c, f, m);
        ended += usize::from(m.done());
    }
    ended
}

#[cfg(test)]
mod snapshot_tests {
    use super::*;
    use crate::{Maze, Task};

    #[test]
    fn a_restored_batch_continues_exactly_where_the_snapshot_was_taken() {
        for task in [Task::MultiGoal, Task::MultiGoalStochastic, Task::DoorKey] {
            let layout = Maze::Small.layout(task == Task::DoorKey);
            let mut cfg = EnvConfig::for_task(task, &layout);
            cfg.max_steps = 40;
            let mut a = BatchEnv::new(layout.clone(), cfg, 6, 9, 1).expect("batch");
            let mut buf = a.buffers();
            a.reset(buf.out());
            let actions = |t: usize| -> Vec<u8> {
                (0..6)
                    .map(|i| ((i * 5 + t * 7) % task.num_actions()) as u8)
                    .collect()
            };
            for t in 0..57 {
                a.step(&actions(t), buf.out());
            }
            let saved = a.snapshot();
            // A batch of another seed, put back in the saved states.
            let mut b = BatchEnv::new(layout, cfg, 6, 1234, 1).expect("batch");
            let mut restored = b.buffers();
            b.restore(&saved, restored.out()).expect("restore");
            assert_eq!(buf.cells, restored.cells, "{task:?}: the observation");
            for t in 57..200 {
                a.step(&actions(t), buf.out());
                b.step(&actions(t), restored.out());
                assert_eq!(buf.cells, restored.cells, "{task:?}: step {t}");
                assert_eq!(buf.meta, restored.meta, "{task:?}: step {t}");
            }
        }
    }
}
