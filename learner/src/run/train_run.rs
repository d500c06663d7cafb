//! A training run as a value (section 5's protocol): [`TrainRun::open`]
//! makes a run directory new or resumes the one it holds (identity, lock,
//! files), [`TrainRun::train`] trains its segments, [`TrainRun::test`]
//! scores its best checkpoint on the held-out test seeds. The command
//! parses, calls these in order and prints.

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use sim::atomic_file::write_atomic;
use sim::{EnvConfig, Layout, Task};

use super::artefact::{known_candidates, load_inputs};
use super::config::{
    RunIdentity, Schedule, TrainConfig, auto_values, resolve_auto, trained_env_steps,
};
use super::dir::{RunKind, check, lock, record_invocation};
use super::protocol::{self, Observer, RunState, TEST_STREAM, TestSummary, VALIDATION_STREAM};
use crate::batch_env::BatchEnvironment;
use crate::hrl::{Agent, EpisodeTrace, EvalResult};

/// The file a run trained on a layout file keeps a copy of it in.
pub const LAYOUT_FILE: &str = "layout.txt";

/// What a training run is: everything [`TrainRun::open`] needs, settled
/// before anything is built or written.
#[derive(Debug, Clone)]
pub struct TrainSpec {
    /// The run directory (new, empty, or a run of this spec to resume).
    pub dir: PathBuf,
    /// The settings, overrides applied and checked; [`TrainRun::open`]
    /// resolves their `0 = auto` values in place.
    pub config: TrainConfig,
    /// The maze.
    pub layout: Layout,
    /// The task's environment settings on it.
    pub env_cfg: EnvConfig,
    /// The task.
    pub task: Task,
    /// The training seed.
    pub seed: u64,
    /// The discovery run the agent builds on (world graph, `π_g`).
    pub world_graph: Option<PathBuf>,
    /// Files a new directory may already hold (the lock, the `--config`
    /// file the user put there).
    pub own_files: Vec<String>,
    /// Whether the layout came from a file (kept in the run as
    /// [`LAYOUT_FILE`]).
    pub keep_layout: bool,
    /// The crate's version and the commit the binary was built from, for
    /// `invocations.txt`.
    pub version: String,
    /// See `version`.
    pub commit: String,
}

/// An open training run: its directory locked, its files written, its
/// agent built (and its weights loaded when resumed).
pub struct TrainRun {
    /// What the run is, its settings resolved (as written to `config.toml`).
    spec: TrainSpec,
    /// The agent.
    pub agent: Agent,
    /// Where the protocol stands.
    pub state: RunState,
    resumed: bool,
    _lock: std::fs::File,
}

impl TrainRun {
    /// Opens the run `spec` describes. Nothing is written before the
    /// directory, the world graph and the run it may hold are known to fit
    /// this run: another run's directory, a resumed run with other
    /// settings, or a budget below what it already trained are refused
    /// with the reason.
    pub fn open(mut spec: TrainSpec) -> anyhow::Result<TrainRun> {
        let dir = spec.dir.clone();
        check("--run", &dir, RunKind::Train, &spec.own_files)?;
        // The episode step limit: `0 = auto` is the environment's own
        // (twice the free cells); another value replaces it everywhere.
        let auto_limit = spec.env_cfg.max_steps;
        spec.config.max_episode_steps = spec.config.episode_limit(auto_limit);
        spec.env_cfg.max_steps = spec.config.max_episode_steps;
        // The settings are resolved once, from the maze and the world
        // graph, before the agent is built: the run's files, its identity
        // and the agent all hold what `0 = auto` resolved to.
        let inputs = load_inputs(
            &spec.config.agent,
            &spec.layout,
            spec.task,
            spec.world_graph.as_deref(),
            spec.seed,
        )?;
        let candidates = known_candidates(&spec.config.agent, &spec.layout, inputs.as_ref());
        let auto = auto_values(&spec.config.agent, &spec.layout, candidates.as_deref());
        spec.config.agent = resolve_auto(&spec.config.agent, auto);
        let mut agent = Agent::new(
            &spec.config.agent,
            &spec.layout,
            spec.task,
            inputs,
            spec.seed,
        )?;
        let config = &spec.config;
        let identity = RunIdentity {
            maze: spec.layout.name.clone(),
            task: spec.task,
            seed: spec.seed,
            world_graph: spec.world_graph.as_ref().map(|p| p.display().to_string()),
            config: TrainConfig {
                env_steps: 0,
                ..config.clone()
            },
        };
        let read_state = || -> anyhow::Result<Option<RunState>> {
            let Some(mut old) = protocol::read_state(&dir)? else {
                return Ok(None);
            };
            // A run recorded before its identity held resolved values says
            // 0 = auto: resolved for this maze and world graph, as this one.
            old.identity.config.agent = resolve_auto(&old.identity.config.agent, auto);
            old.identity.config.max_episode_steps = old.identity.config.episode_limit(auto_limit);
            if old.identity != identity {
                bail!(
                    "{} holds another run ({}); use another --run",
                    dir.display(),
                    old.identity.differences(&identity)
                );
            }
            Ok(Some(old))
        };
        let trained = trained_env_steps(config);
        if let Some(old) = read_state()?
            && old.env_steps > trained
        {
            bail!(
                "{} already trained {} env steps, more than --env-steps {} ({trained} rounded); \
                 give at least {} to go on, or another --run (its config.toml is left as it is)",
                dir.display(),
                old.env_steps,
                config.env_steps,
                old.env_steps
            );
        }

        std::fs::create_dir_all(&dir)
            .with_context(|| format!("cannot create {}", dir.display()))?;
        let lock = lock(&dir, "train")?;
        write_files(&spec)?;
        let mut state = RunState {
            identity: identity.clone(),
            segments_done: 0,
            env_steps: 0,
            best_score: None,
            best_segment: 0,
            rows: Vec::new(),
            wall_seconds: Vec::new(),
        };
        // Read again under the lock: the state a finished holder left.
        let resumed = if let Some(old) = read_state()? {
            protocol::load_weights(&dir, &old, &mut agent)?;
            state = old;
            true
        } else {
            false
        };
        Ok(TrainRun {
            spec,
            agent,
            state,
            resumed,
            _lock: lock,
        })
    }

    /// The settings, `0 = auto` resolved (as in `config.toml`).
    pub fn config(&self) -> &TrainConfig {
        &self.spec.config
    }

    /// The run directory.
    pub fn dir(&self) -> &Path {
        &self.spec.dir
    }

    /// The maze.
    pub fn layout(&self) -> &Layout {
        &self.spec.layout
    }

    /// The task's environment settings.
    pub fn env_cfg(&self) -> EnvConfig {
        self.spec.env_cfg
    }

    /// The env steps trained before this process opened the run, if it
    /// resumed one.
    pub fn resumed_after(&self) -> Option<u64> {
        self.resumed.then_some(self.state.env_steps)
    }

    /// The run's segments and iterations.
    pub fn schedule(&self) -> Schedule {
        Schedule::of(&self.spec.config)
    }

    /// Whether segments are left to train.
    pub fn needs_training(&self) -> bool {
        self.state.segments_done < self.schedule().segments
    }

    /// The seed of the training environments of the segment the run goes
    /// on from.
    pub fn segment_seed(&self) -> u64 {
        sim::env_seed(self.spec.seed, self.state.segments_done)
    }

    /// Trains the remaining segments on `env` (the training environments
    /// live for the whole run: a resumed run restores them mid-episode
    /// from its checkpoint where it can, else starts the segment afresh),
    /// validating and checkpointing after each.
    pub fn train(
        &mut self,
        env: &mut dyn BatchEnvironment,
        observer: &mut dyn Observer,
    ) -> anyhow::Result<()> {
        let dir = self.spec.dir.clone();
        let resumed = self.state.segments_done > 0
            && protocol::restore_training(&dir, &self.state, &mut self.agent, env)?;
        if !resumed {
            self.agent.start_segment(env, self.state.segments_done)?;
        }
        protocol::train_segments(
            &dir,
            &self.spec.config,
            &self.spec.layout,
            self.spec.env_cfg,
            &mut self.state,
            &mut self.agent,
            env,
            observer,
        )
    }

    /// The best checkpoint on the held-out test seeds: the summary
    /// (`test.json`), the episodes' figures and test seed 0's episode.
    pub fn test(&mut self) -> anyhow::Result<(TestSummary, EvalResult, EpisodeTrace)> {
        protocol::test(
            &self.spec.dir,
            &self.spec.config,
            &self.spec.layout,
            self.spec.env_cfg,
            self.spec.task,
            self.spec.seed,
            &self.state,
            &mut self.agent,
        )
    }
}

/// The run's own files: `config.toml` (resolved), the layout file's copy,
/// `seeds.json` (the protocol's streams) and `invocations.txt` (what made
/// the run).
fn write_files(spec: &TrainSpec) -> anyhow::Result<()> {
    let (dir, config) = (&spec.dir, &spec.config);
    write_atomic(
        &dir.join("config.toml"),
        toml::to_string(config)?.as_bytes(),
    )?;
    if spec.keep_layout {
        write_atomic(&dir.join(LAYOUT_FILE), spec.layout.to_text().as_bytes())?;
    }
    write_atomic(
        &dir.join("seeds.json"),
        &serde_json::to_vec_pretty(&serde_json::json!({
            "train": {"seed": spec.seed, "environments": config.agent.envs, "streams": format!("(env_seed({}, 0), 0..{}), carried across segments", spec.seed, config.agent.envs)},
            "validation": {"stream": VALIDATION_STREAM, "seeds": format!("0..{}", config.validation_seeds)},
            "test": {"stream": TEST_STREAM, "seeds": format!("0..{}", config.test_seeds)},
        }))?,
    )?;
    record_invocation(dir, &spec.version, &spec.commit)
}
