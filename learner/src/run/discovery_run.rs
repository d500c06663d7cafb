//! A discovery run as a value (stage 1, section 3): [`DiscoveryRun::open`]
//! makes a run directory new or resumes the one it holds (identity, lock,
//! checkpoint), [`DiscoveryRun::round`] runs one round of the loop and
//! checkpoints it, and [`DiscoveryRun::save_world_graph`] writes what
//! stage 2 takes: the world graph over the pivotal states `V_p` and `π_g`.
//! The command parses, calls these in order and prints.

use std::path::{Path, PathBuf};

use anyhow::Context;
use sim::Layout;
use sim::atomic_file::write_atomic;

use super::artefact::DiscoveryIdentity;
use super::dir::{RunKind, check, lock, record_invocation};
use crate::batch_env::BatchEnvironment;
use crate::discovery::{Discovery, DiscoveryConfig, RoundStats};

/// The checkpoint directory inside a discovery run.
pub const CHECKPOINT_DIR: &str = "checkpoint";
/// `V_p` as `[x, y]` cells, most pivotal first (what a planner process is
/// given as `--node-file`).
pub const PIVOTAL_FILE: &str = "pivotal.json";
/// The world graph (section 3.3).
pub const GRAPH_FILE: &str = "graph.json";

/// What a discovery run is: everything [`DiscoveryRun::open`] needs,
/// settled before anything is built or written.
#[derive(Debug, Clone)]
pub struct DiscoverySpec {
    /// The run directory (new, empty, or a discovery of this spec to
    /// resume or continue).
    pub dir: PathBuf,
    /// The maze's structure ([`Layout::structural`]: one world graph per
    /// maze serves every task on it).
    pub layout: Layout,
    /// Environments stepped in parallel.
    pub envs: usize,
    /// The settings, overrides applied.
    pub config: DiscoveryConfig,
    /// Actions of the task `π_g` learns on.
    pub num_actions: usize,
    /// Files a new directory may already hold (the lock, the `--config`
    /// file the user put there).
    pub own_files: Vec<String>,
    /// The crate's version, for `invocations.txt`.
    pub version: String,
    /// The commit the binary was built from, for `invocations.txt`: the
    /// grid runner names a discovery's commit from it, not from whichever
    /// binary records the discovery's summary.
    pub commit: String,
}

/// An open discovery run: its directory locked, its identity recorded, its
/// loop built (and restored from the checkpoint when resumed).
pub struct DiscoveryRun {
    dir: PathBuf,
    layout: Layout,
    discovery: Discovery,
    resumed: bool,
    _lock: std::fs::File,
}

impl DiscoveryRun {
    /// Opens the run `spec` describes. Another run's directory, or a
    /// discovery with other settings (other than a longer budget, which
    /// continues it), is refused with the reason before anything is
    /// written.
    pub fn open(spec: DiscoverySpec) -> anyhow::Result<DiscoveryRun> {
        let DiscoverySpec {
            dir,
            layout,
            envs,
            config,
            num_actions,
            own_files,
            version,
            commit,
        } = spec;
        check("--run", &dir, RunKind::Discover, &own_files)?;
        std::fs::create_dir_all(&dir)
            .with_context(|| format!("cannot create {}", dir.display()))?;
        let lock = lock(&dir, "discover")?;
        DiscoveryIdentity::new(&layout, envs, &config).check_and_record(&dir)?;
        record_invocation(&dir, &version, &commit)?;
        let mut discovery = Discovery::new(config, &layout, envs, num_actions)?;
        let resumed = discovery.resume(&dir.join(CHECKPOINT_DIR))?;
        Ok(DiscoveryRun {
            dir,
            layout,
            discovery,
            resumed,
            _lock: lock,
        })
    }

    /// The run directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The maze's structure the run discovers on.
    pub fn layout(&self) -> &Layout {
        &self.layout
    }

    /// The rounds the run resumed after, if it resumed.
    pub fn resumed_after(&self) -> Option<u32> {
        self.resumed.then(|| self.discovery.rounds_done())
    }

    /// The loop: its settings, curves and pivotal states.
    pub fn discovery(&self) -> &Discovery {
        &self.discovery
    }

    /// The loop, to act on it (evaluate or refine with `π_g`, build the
    /// world graph).
    pub fn discovery_mut(&mut self) -> &mut Discovery {
        &mut self.discovery
    }

    /// Whether the loop stopped (its budget, or patience after
    /// `min_rounds`).
    pub fn finished(&self) -> bool {
        self.discovery.finished()
    }

    /// One round of the loop (section 3: the latent model, `V_p`, `π_g`'s
    /// curriculum), checkpointed before it returns.
    pub fn round(&mut self, env: &mut dyn BatchEnvironment) -> anyhow::Result<RoundStats> {
        let stats = self.discovery.round(env)?;
        self.discovery.save(&self.dir.join(CHECKPOINT_DIR))?;
        Ok(stats)
    }

    /// `V_p` as `[x, y]` cells, most pivotal first, written to
    /// [`PIVOTAL_FILE`]; returns the cells and the file.
    pub fn write_pivotal_states(&self) -> anyhow::Result<(Vec<[u16; 2]>, PathBuf)> {
        let width = self.layout.width;
        let cells: Vec<[u16; 2]> = self
            .discovery
            .pivotal_states()
            .iter()
            .map(|&c| [(c as usize % width) as u16, (c as usize / width) as u16])
            .collect();
        let file = self.dir.join(PIVOTAL_FILE);
        write_atomic(&file, &serde_json::to_vec(&cells)?)?;
        Ok((cells, file))
    }

    /// Writes what stage 2 (`train --world-graph`) takes: the world graph
    /// ([`GRAPH_FILE`]) and `π_g`'s settings and weights.
    pub fn save_world_graph(&mut self, graph: &planner::WorldGraph) -> anyhow::Result<()> {
        graph.save(&self.dir.join(GRAPH_FILE))?;
        write_atomic(
            &self.dir.join("pi_g.json"),
            &serde_json::to_vec_pretty(self.discovery.gcp().config())?,
        )?;
        self.discovery.gcp().save(self.dir.join("pi_g.ot"))?;
        Ok(())
    }
}
