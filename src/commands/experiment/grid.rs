//! The grid file of `worldgraph experiment` (`experiments/*.toml`): the
//! mazes with their budgets, the seeds, and the groups of tasks and agent
//! configurations (named as [`AgentConfig::name`] names them) that make up
//! the paper's Tables 1 and 2.

use std::path::{Path, PathBuf};

use anyhow::Context;
use learner::hrl::{AgentConfig, AgentKind};
use learner::run::config::MAX_EVAL_SEEDS;
use learner::run::config::TrainConfig;
use learner::run::protocol::MAX_TRAIN_SEED;
use serde::{Deserialize, Serialize};
use sim::{Maze, Task};

/// A grid file (`experiments/*.toml`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Grid {
    /// Name; the runs' working files go to `<results>/runs/<name>/` unless
    /// `--work` says otherwise.
    pub name: String,
    /// Training seeds of every cell (the paper: 3).
    pub seeds: Vec<u64>,
    /// Validation seeds of each run (the paper: 10).
    #[serde(default = "default_validation_seeds")]
    pub validation_seeds: usize,
    /// Test seeds of each run (the paper: 100).
    #[serde(default = "default_test_seeds")]
    pub test_seeds: usize,
    /// Budgets, one per maze of the grid.
    pub maze: Vec<MazeBudget>,
    /// The discovery settings of the grid's world graphs: a TOML file of
    /// `DiscoveryConfig` (`discover --config`), relative to the directory
    /// the command runs in (the repository). `None`: the current defaults.
    /// A summary names its grid, so reproducing it reads this too: pinning
    /// it keeps committed results reproducible when the defaults move on.
    #[serde(default)]
    pub discover_config: Option<PathBuf>,
    /// Settings of every training run of the grid, as `train --set`
    /// takes them (`"agent.object_goals=false"`): a lever's ablation is a
    /// grid of its own. Each summary records the resolved settings.
    #[serde(default)]
    pub set: Vec<String>,
    /// Cells: tasks × configurations (× the grid's mazes and seeds).
    pub group: Vec<Group>,
}

fn default_validation_seeds() -> usize {
    10
}

fn default_test_seeds() -> usize {
    100
}

/// One maze's budget.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MazeBudget {
    /// The embedded maze.
    pub name: Maze,
    /// Env steps of each training run.
    pub env_steps: u64,
    /// Env steps between validations (and checkpoints).
    pub eval_every: u64,
    /// Rounds of the maze's world graph discovery (one per training seed).
    pub discover_rounds: u32,
}

/// A block of cells: every task with every configuration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Group {
    /// The paper's table the cells fill (1: the MultiGoal tasks, 2: Door-Key).
    pub table: u8,
    /// Tasks, by their command-line names (`multigoal`, `multigoal-sparse`,
    /// `multigoal-stochastic`, `doorkey`).
    #[serde(with = "task_names")]
    pub tasks: Vec<Task>,
    /// Agent configurations by name: `a2c`, `fn`, `fn-init`, or
    /// `wn-<all|random|pivotal>[-trav][-init]`.
    pub configs: Vec<String>,
    /// Mazes of the group [default: every maze of the grid].
    #[serde(default)]
    pub mazes: Vec<Maze>,
}

/// Tasks by their command-line names in grid files.
mod task_names {
    use serde::{Deserialize, Deserializer, Serializer};
    use sim::Task;

    pub fn serialize<S: Serializer>(tasks: &[Task], s: S) -> Result<S::Ok, S::Error> {
        s.collect_seq(tasks.iter().map(|t| t.name()))
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<Task>, D::Error> {
        Vec::<String>::deserialize(d)?
            .iter()
            .map(|n| n.parse::<Task>().map_err(serde::de::Error::custom))
            .collect()
    }
}

/// The agent settings of a configuration name (`wn-pivotal-trav-init`;
/// [`AgentConfig::from_name`], the inverse of [`AgentConfig::name`]).
pub(super) fn config_named(name: &str) -> anyhow::Result<AgentConfig> {
    Ok(AgentConfig::from_name(name, &AgentConfig::default())?)
}

/// The `train` arguments that select the agent of configuration `name`.
pub(super) fn train_args(name: &str) -> anyhow::Result<Vec<String>> {
    let cfg = config_named(name)?;
    let mut v = vec![
        "--agent".to_string(),
        match cfg.kind {
            AgentKind::A2c => "a2c",
            AgentKind::Feudal => "fn",
            AgentKind::WideNarrow => "wn",
        }
        .to_string(),
        "--candidates".to_string(),
        cfg.candidates.name().to_string(),
        "--init".to_string(),
        if cfg.init_from_gcp { "pi-g" } else { "none" }.to_string(),
    ];
    if cfg.traversal {
        v.push("--traversal".to_string());
    }
    Ok(v)
}

impl Grid {
    /// Reads and checks a grid file.
    pub fn read(path: &Path) -> anyhow::Result<Grid> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("cannot read {}", path.display()))?;
        let g: Grid = toml::from_str(&text)
            .with_context(|| format!("{} is not a valid experiment grid", path.display()))?;
        g.check()
            .with_context(|| format!("{} is not a valid experiment grid", path.display()))?;
        Ok(g)
    }

    /// Refuses, with the reason, a grid that could not run to its end: a
    /// bad name, seeds, settings, discovery config, maze budget or group.
    fn check(&self) -> anyhow::Result<()> {
        anyhow::ensure!(
            !self.name.is_empty()
                && self
                    .name
                    .chars()
                    .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_'),
            "name {:?} must be letters, digits, '-' or '_'",
            self.name
        );
        self.check_seeds()?;
        anyhow::ensure!(!self.maze.is_empty(), "[[maze]]: at least one maze");
        let cfg = self.try_train_config(self.maze[0].name).context("set")?;
        cfg.agent.validate().context("set")?;
        self.check_discover_config()?;
        for (i, m) in self.maze.iter().enumerate() {
            anyhow::ensure!(
                m.env_steps > 0 && m.eval_every > 0 && m.discover_rounds > 0,
                "maze {}: env_steps, eval_every and discover_rounds must be at least 1",
                m.name.name()
            );
            anyhow::ensure!(
                !self.maze[..i].iter().any(|o| o.name == m.name),
                "maze {} is listed twice",
                m.name.name()
            );
        }
        for g in &self.group {
            anyhow::ensure!(
                g.table == 1 || g.table == 2,
                "group table {} (1 or 2)",
                g.table
            );
            anyhow::ensure!(
                !g.tasks.is_empty() && !g.configs.is_empty(),
                "a group needs tasks and configs"
            );
            for c in &g.configs {
                config_named(c)?;
            }
            for m in &g.mazes {
                anyhow::ensure!(
                    self.budget(*m).is_some(),
                    "group maze {} has no [[maze]] budget",
                    m.name()
                );
            }
        }
        Ok(())
    }

    /// The training seeds (each once, below the validation and test
    /// streams) and the validation and test seed counts.
    fn check_seeds(&self) -> anyhow::Result<()> {
        anyhow::ensure!(!self.seeds.is_empty(), "seeds: at least one training seed");
        for (i, &s) in self.seeds.iter().enumerate() {
            anyhow::ensure!(
                s < MAX_TRAIN_SEED,
                "seeds: {s} is not below {}",
                MAX_TRAIN_SEED
            );
            // Two runs of one seed would share a run directory and a summary.
            anyhow::ensure!(
                !self.seeds[..i].contains(&s),
                "seeds: {s} is listed twice (each training seed once)"
            );
        }
        anyhow::ensure!(
            self.validation_seeds > 0 && self.test_seeds > 0,
            "validation_seeds and test_seeds must be at least 1"
        );
        let max = MAX_EVAL_SEEDS;
        for (name, n) in [
            ("validation_seeds", self.validation_seeds),
            ("test_seeds", self.test_seeds),
        ] {
            anyhow::ensure!(n as u64 <= max, "{name} = {n}: at most {max} seeds");
        }
        Ok(())
    }

    /// `discover_config`, when given: a file of valid discovery settings
    /// (refused here, `--dry-run` included, rather than by each discovery).
    fn check_discover_config(&self) -> anyhow::Result<()> {
        if let Some(c) = &self.discover_config {
            anyhow::ensure!(
                c.is_file(),
                "discover_config: {} is not a file (paths are relative to the directory the command runs in)",
                c.display()
            );
            learner::run::artefact::read_discovery_config(c)
                .and_then(|cfg| {
                    cfg.validate()
                        .with_context(|| format!("{} is not a valid discovery config", c.display()))
                })
                .context("discover_config")?;
        }
        Ok(())
    }

    /// Whether the grid holds runs of configuration `config` on `maze`
    /// and `task` (a group with them, on a maze with a budget).
    pub fn declares(&self, maze: Maze, task: Task, config: &str) -> bool {
        self.group.iter().any(|g| {
            self.group_mazes(g).contains(&maze)
                && g.tasks.contains(&task)
                && g.configs.iter().any(|c| c == config)
        })
    }

    /// The mazes of group `g`: its own, or every maze of the grid.
    pub(super) fn group_mazes(&self, g: &Group) -> Vec<Maze> {
        if g.mazes.is_empty() {
            self.maze.iter().map(|m| m.name).collect()
        } else {
            g.mazes.clone()
        }
    }

    /// The budget of `maze`.
    pub fn budget(&self, maze: Maze) -> Option<&MazeBudget> {
        self.maze.iter().find(|m| m.name == maze)
    }

    /// The training configuration of a run on `maze`.
    pub fn train_config(&self, maze: Maze) -> TrainConfig {
        self.try_train_config(maze)
            .expect("invariant: the grid's settings were checked when it was read")
    }

    fn try_train_config(&self, maze: Maze) -> anyhow::Result<TrainConfig> {
        let b = self.budget(maze).context("no budget for that maze")?;
        let base = TrainConfig {
            env_steps: b.env_steps,
            eval_every: b.eval_every,
            validation_seeds: self.validation_seeds,
            test_seeds: self.test_seeds,
            ..TrainConfig::default()
        };
        learner::run::config::apply_overrides(base, &self.set)
    }
}
