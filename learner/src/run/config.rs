//! A training run's settings (`config.toml`) and identity: what `train`
//! is configured by, how `--config` and `--set` combine, the budget the
//! protocol actually trains, and what must match for a run to resume.

use std::path::Path;

use anyhow::Context;
use serde::{Deserialize, Serialize};
use sim::Task;

use crate::hrl::{AgentConfig, AgentKind};
use sim::Layout;

/// The most seeds one evaluation steps side by side (`evaluate --seeds`,
/// `validation_seeds`, `test_seeds`): each is an environment of one batch.
pub const MAX_EVAL_SEEDS: u64 = 10_000;

/// Everything `train` is configured by (the run's `config.toml`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TrainConfig {
    /// Env-step budget.
    pub env_steps: u64,
    /// Env steps per segment (validation and checkpoint after each).
    pub eval_every: u64,
    /// Validation seeds.
    pub validation_seeds: usize,
    /// Test seeds.
    pub test_seeds: usize,
    /// Step limit of an episode, in training, validation and test (an
    /// episode that reaches it is cut, its step penalties paid). The paper
    /// does not give its limit; `0 = auto`: twice the maze's free cells
    /// ([`sim::EnvConfig::for_task`]), written resolved to `config.toml`.
    pub max_episode_steps: u32,
    /// The agent.
    pub agent: AgentConfig,
}

impl Default for TrainConfig {
    fn default() -> Self {
        TrainConfig {
            env_steps: 1_000_000,
            eval_every: 50_000,
            validation_seeds: 10,
            test_seeds: 100,
            max_episode_steps: 0,
            agent: AgentConfig::default(),
        }
    }
}

/// A run's identity: what must match to resume it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunIdentity {
    /// Maze.
    pub maze: String,
    /// Task.
    pub task: Task,
    /// Seed.
    pub seed: u64,
    /// The discovery run (canonical path), if any.
    pub world_graph: Option<String>,
    /// The resolved configuration, less the budget.
    pub config: TrainConfig,
}

impl RunIdentity {
    /// Every field in which this saved identity differs from `now`, in
    /// words: `config.agent.horizon: 20 there, 15 here; ...`.
    pub fn differences(&self, now: &RunIdentity) -> String {
        crate::identity::describe(&crate::identity::differences(self, now, &[]))
    }
}

/// Refuses a budget that cannot run (before anything is written): no
/// segment, no validation or test seed, or batches larger than a run can
/// hold (`file`, the --config file, is named).
pub fn check_budget(cfg: &TrainConfig, file: Option<&Path>) -> anyhow::Result<()> {
    let from = file.map_or(String::new(), |f| format!(" (in {})", f.display()));
    anyhow::ensure!(cfg.eval_every > 0, "eval_every must be at least 1");
    anyhow::ensure!(
        cfg.validation_seeds > 0 && cfg.test_seeds > 0,
        "validation_seeds and test_seeds must be at least 1"
    );
    let max_envs = shm_schemas::MAX_ENVS;
    anyhow::ensure!(
        cfg.agent.envs <= max_envs,
        "[agent] envs = {}{from}: at most {max_envs} environments",
        cfg.agent.envs
    );
    for (name, n) in [
        ("validation_seeds", cfg.validation_seeds),
        ("test_seeds", cfg.test_seeds),
    ] {
        anyhow::ensure!(
            n as u64 <= MAX_EVAL_SEEDS,
            "{name} = {n}{from}: at most {MAX_EVAL_SEEDS} seeds"
        );
    }
    Ok(())
}

/// The training settings of `--config` (or the defaults) with every
/// `--set KEY=VALUE` applied: each names a dotted path into the TOML and a
/// TOML value (a bare word that is not one is taken as a string).
pub fn config_with_overrides(
    file: Option<&Path>,
    overrides: &[String],
) -> anyhow::Result<TrainConfig> {
    let base = match file {
        Some(p) => read_config(p)?,
        None => TrainConfig::default(),
    };
    apply_overrides(base, overrides)
}

/// `base` with each `KEY=VALUE` of `overrides` set (dotted keys into the
/// settings' tables, values in TOML syntax or a bare string); an unknown
/// key or an ill-typed value is refused, naming it.
pub fn apply_overrides(base: TrainConfig, overrides: &[String]) -> anyhow::Result<TrainConfig> {
    if overrides.is_empty() {
        return Ok(base);
    }
    let mut doc = toml::Value::try_from(&base).context("the settings do not serialise")?;
    for o in overrides {
        let (key, value) = o
            .split_once('=')
            .with_context(|| format!("--set {o}: expected KEY=VALUE, e.g. agent.horizon=15"))?;
        let (key, value) = (key.trim(), value.trim());
        let value: toml::Value = toml::from_str::<toml::Table>(&format!("v = {value}"))
            .ok()
            .and_then(|mut t| t.remove("v"))
            .unwrap_or_else(|| toml::Value::String(value.to_string()));
        let mut at = &mut doc;
        let parts: Vec<&str> = key.split('.').collect();
        for (i, part) in parts.iter().enumerate() {
            let table = at
                .as_table_mut()
                .with_context(|| format!("--set {o}: {} is not a table", parts[..i].join(".")))?;
            if i + 1 == parts.len() {
                anyhow::ensure!(
                    table.contains_key(*part),
                    "--set {o}: the training settings have no field {key}"
                );
                table.insert(part.to_string(), value.clone());
                break;
            }
            at = table
                .get_mut(*part)
                .with_context(|| format!("--set {o}: the training settings have no field {key}"))?;
        }
    }
    TrainConfig::deserialize(doc).map_err(|e| anyhow::anyhow!("--set: {}", e.message()))
}

/// Reads a TOML config file.
pub fn read_config(path: &Path) -> anyhow::Result<TrainConfig> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    toml::from_str(&text)
        .with_context(|| format!("{} is not a valid training config", path.display()))
}

impl TrainConfig {
    /// The episode step limit of a run of these settings on an environment
    /// whose own limit is `auto` (`0 = auto`).
    pub fn episode_limit(&self, auto: u32) -> u32 {
        if self.max_episode_steps == 0 {
            auto
        } else {
            self.max_episode_steps
        }
    }
}

/// The env steps a run of `cfg` trains ([`Schedule::trained_env_steps`]).
pub fn trained_env_steps(cfg: &TrainConfig) -> u64 {
    Schedule::of(cfg).trained_env_steps()
}

/// How a budget divides: iterations of `envs × rollout_len` env steps,
/// whole iterations per segment, whole segments per run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Schedule {
    /// Env steps of one iteration (one update).
    pub steps_per_iter: u64,
    /// Iterations of one segment (`eval_every` rounded up).
    pub iters_per_segment: u64,
    /// Segments of the run (the budget rounded up).
    pub segments: u64,
}

impl Schedule {
    /// The schedule of `cfg`.
    pub fn of(cfg: &TrainConfig) -> Schedule {
        let steps_per_iter = (cfg.agent.envs * cfg.agent.rollout_len) as u64;
        let iters_per_segment = cfg.eval_every.div_ceil(steps_per_iter).max(1);
        Schedule {
            steps_per_iter,
            iters_per_segment,
            segments: cfg.env_steps.div_ceil(iters_per_segment * steps_per_iter),
        }
    }

    /// Env steps of one segment.
    pub fn steps_per_segment(&self) -> u64 {
        self.iters_per_segment * self.steps_per_iter
    }

    /// Env steps of the whole run: the budget rounded up to whole segments
    /// of whole iterations.
    pub fn trained_env_steps(&self) -> u64 {
        self.segments * self.steps_per_segment()
    }
}

/// What `0 = auto` stands for in `cfg` on this run, from the maze and the
/// world graph alone (before any agent is built): the Manager horizon `c`
/// (FN and WN; A2C has no Manager) and the narrow window's side (WN: the
/// narrowest odd side from the default up whose windows around the
/// wide-goal `candidates` cover every free cell,
/// [`crate::hrl::wide_narrow::covering_side`]; `None` when the candidates
/// are not known).
pub fn auto_values(
    cfg: &AgentConfig,
    layout: &Layout,
    candidates: Option<&[u32]>,
) -> (Option<usize>, Option<usize>) {
    let horizon = (cfg.kind != AgentKind::A2c).then(|| {
        AgentConfig {
            horizon: 0,
            ..cfg.clone()
        }
        .horizon() as usize
    });
    let window = candidates
        .filter(|_| cfg.kind == AgentKind::WideNarrow)
        .map(|candidates| {
            let base = AgentConfig {
                window: 0,
                ..cfg.clone()
            }
            .window_side(layout.width);
            crate::hrl::wide_narrow::covering_side(base, candidates, layout)
        });
    (horizon, window)
}

/// `cfg` with each `0 = auto` replaced by the value it stands for (from
/// [`auto_values`]); a setting the agent does not have (A2C's horizon and
/// window, FN's window), or whose value is unknown, stays as given.
pub fn resolve_auto(
    cfg: &AgentConfig,
    (horizon, window): (Option<usize>, Option<usize>),
) -> AgentConfig {
    let mut r = cfg.clone();
    if r.horizon == 0
        && let Some(h) = horizon
    {
        r.horizon = h;
    }
    if r.window == 0
        && let Some(w) = window
    {
        r.window = w;
    }
    r
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hrl::{Candidates, HrlAgent};
    use sim::{Maze, Task};

    /// Issue 21, item 8: the budget a run trains is its rounding to whole
    /// segments (`--env-steps 2000` trains 51,840 with the defaults).
    #[test]
    fn the_budget_rounds_up_to_whole_segments() {
        for (budget, trained) in [(2000, 51_840), (51_840, 51_840), (51_841, 2 * 51_840)] {
            let cfg = TrainConfig {
                env_steps: budget,
                ..TrainConfig::default()
            };
            assert_eq!(trained_env_steps(&cfg), trained, "{budget}");
        }
    }

    /// Issue 21: `0 = auto` resolves, before any agent is built (issue 50),
    /// to the values an agent given `0` uses; a setting the agent lacks
    /// stays 0, and an explicit value stays.
    #[test]
    fn auto_settings_resolve_before_the_agent_to_what_it_uses() {
        let layout = Maze::Small.layout(false);
        let wn = AgentConfig {
            kind: AgentKind::WideNarrow,
            candidates: Candidates::All,
            envs: 1,
            rollout_len: 21,
            ..AgentConfig::default()
        };
        let candidates = crate::run::artefact::known_candidates(&wn, &layout, None);
        let auto = auto_values(&wn, &layout, candidates.as_deref());
        let agent = HrlAgent::new(&wn, &layout, Task::MultiGoal, None, 0).unwrap();
        let side = agent.window_coverage().unwrap().side;
        assert_eq!(auto, (Some(7), Some(side)));
        let r = resolve_auto(&wn, auto);
        assert_eq!((r.horizon, r.window), (7, side));
        assert!(side >= 5 && side % 2 == 1, "{side}");
        // The resolved settings build the same agent.
        let again = HrlAgent::new(&r, &layout, Task::MultiGoal, None, 0).unwrap();
        assert_eq!(again.window_coverage().unwrap().side, side);
        let explicit = AgentConfig {
            horizon: 4,
            ..wn.clone()
        };
        assert_eq!(resolve_auto(&explicit, auto).horizon, 4);
        let a2c = AgentConfig {
            kind: AgentKind::A2c,
            ..wn.clone()
        };
        let r = resolve_auto(&a2c, auto_values(&a2c, &layout, None));
        assert_eq!((r.horizon, r.window), (0, 0), "A2C has neither");
        let fnet = AgentConfig {
            kind: AgentKind::Feudal,
            ..wn
        };
        let r = resolve_auto(&fnet, auto_values(&fnet, &layout, None));
        assert_eq!((r.horizon, r.window), (7, 0), "FN has a horizon, no window");
    }

    /// Issue 21, item 8: the config's agent kind may be spelled as the
    /// CLI's `--agent` spells it.
    #[test]
    fn the_config_accepts_the_clis_agent_kinds() {
        for (text, kind) in [
            ("fn", AgentKind::Feudal),
            ("feudal", AgentKind::Feudal),
            ("wn", AgentKind::WideNarrow),
            ("wide-narrow", AgentKind::WideNarrow),
            ("a2c", AgentKind::A2c),
        ] {
            let cfg: TrainConfig = toml::from_str(&format!("[agent]\nkind = \"{text}\"\n"))
                .unwrap_or_else(|e| panic!("kind = {text:?}: {e}"));
            assert_eq!(cfg.agent.kind, kind, "{text}");
        }
    }
}
