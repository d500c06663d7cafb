//! `worldgraph evaluate`: scores a train run's best checkpoint on any
//! seeds of the held-out test stream (section 5's protocol scores it on
//! the first 100 at the end of `train`), optionally under another
//! MultiGoal task's rewards.

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use clap::Args;
use learner::hrl::config::EvalActions;
use learner::hrl::{Agent, EpisodeTrace};
use learner::run::artefact::build_agent;
use learner::run::config::{MAX_EVAL_SEEDS, read_config, trained_env_steps};
use learner::run::dir::{RunKind, describe, kind_of};
use learner::run::protocol::{self, RunState, TEST_STREAM, eval_env};
use learner::run::train_run::LAYOUT_FILE;
use sim::{EnvConfig, Layout, Maze, Task};

use super::train::train_world;
use crate::episode_picture::episode_picture;

/// `evaluate` options.
#[derive(Debug, Clone, Args)]
pub struct EvaluateArgs {
    /// A `worldgraph train` run directory.
    pub run: PathBuf,
    /// Test seeds as `A..B` (B exclusive), environments `(test stream, A..B)`;
    /// at most 10,000 at once.
    #[arg(long, default_value = "0..100")]
    pub seeds: String,
    /// Episodes per seed (the seed fixes the maze's randomness; the policy's
    /// sampling differs between episodes).
    #[arg(long, default_value_t = 1)]
    pub episodes_per_seed: usize,
    /// Write a picture of the first episode here.
    #[arg(long)]
    pub picture: Option<PathBuf>,
    /// Write the first episode's trace here as JSON, in the format of a
    /// run's `test_episode.json`: the cell after every step, the steps a
    /// traversal took, the Manager's decisions `[step, g_w, g_n]` and the
    /// grid at the start and at the end.
    #[arg(long)]
    pub trace: Option<PathBuf>,
    /// Score the agent on another task of its maze with the same actions
    /// (multigoal, multigoal-sparse, multigoal-stochastic), e.g. how a policy
    /// trained on dense rewards scores under the sparse ones; the run's own
    /// task by default. The agent is unchanged: only the environment's
    /// rewards (and lava) are the other task's.
    #[arg(long)]
    pub task: Option<Task>,
    /// How the agent acts: `sample` draws its actions and goals from its
    /// policies, `greedy` takes each policy's most likely choice (the
    /// Worker's action; the Manager's wide goal, then its narrow goal). The
    /// run's own `agent.eval_actions` by default, the one its validation
    /// and test used.
    #[arg(long)]
    pub eval_actions: Option<EvalActions>,
    /// Print JSON.
    #[arg(long)]
    pub json: bool,
}

/// Runs `worldgraph evaluate`.
pub fn evaluate(a: EvaluateArgs) -> anyhow::Result<std::process::ExitCode> {
    let (first, end) = seed_range(&a.seeds)?;
    anyhow::ensure!(
        a.episodes_per_seed > 0,
        "--episodes-per-seed must be at least 1"
    );
    if let Some(path) = &a.picture {
        crate::picture_path::prepare("--picture", path)?;
    }
    if let Some(path) = &a.trace {
        crate::picture_path::prepare("--trace", path)?;
    }
    let mut scored = ScoredRun::open(&a.run, a.task, a.eval_actions)?;
    let mut env = eval_env(
        &scored.layout,
        scored.env_cfg,
        TEST_STREAM,
        first,
        (end - first) as usize,
    )?;
    let mut scores = Vec::new();
    let mut episodes = EpisodeFigures::default();
    let mut trace = EpisodeTrace::default();
    for k in 0..a.episodes_per_seed {
        // The first round plays the test protocol's own episodes (and is
        // the one pictured); each further round samples anew.
        let r = if k == 0 {
            scored
                .agent
                .evaluate(&mut env, u64::MAX, Some(&mut trace))?
        } else {
            scored.agent.evaluate(&mut env, k as u64, None)?
        };
        scores.push(r.score);
        episodes.add(&r);
    }
    let score = scores.iter().sum::<f64>() / scores.len() as f64;
    let episodes = episodes.means();
    if let Some(p) = &a.picture {
        let id = &scored.state.identity;
        episode_picture(
            &scored.layout,
            &trace,
            scored.agent.graph(),
            &id.config.agent,
            scored.task,
            first,
        )
        .save_png(p)?;
    }
    if let Some(path) = &a.trace {
        sim::atomic_file::write_atomic(path, &serde_json::to_vec(&trace)?)
            .with_context(|| format!("--trace {}", path.display()))?;
    }
    if a.json {
        let (task, trained_on) = (scored.task.name(), scored.state.identity.task.name());
        println!(
            "{}",
            serde_json::json!({"score": score, "task": task, "trained_on": trained_on, "seeds": a.seeds, "episodes_per_seed": a.episodes_per_seed, "eval_actions": scored.eval_actions, "per_round": scores, "finished": scored.unfinished.is_none(), "env_steps": scored.state.env_steps, "episodes": episodes})
        );
    } else {
        print_evaluation(&a, &scored, score, &episodes);
    }
    Ok(std::process::ExitCode::SUCCESS)
}

/// `--seeds A..B` as `(A, B)`: non-empty and at most [`MAX_EVAL_SEEDS`].
fn seed_range(seeds: &str) -> anyhow::Result<(u64, u64)> {
    let (first, end) = seeds
        .split_once("..")
        .and_then(|(x, y)| Some((x.trim().parse::<u64>().ok()?, y.trim().parse::<u64>().ok()?)))
        .with_context(|| format!("--seeds {seeds:?} is not A..B"))?;
    anyhow::ensure!(end > first, "--seeds {seeds:?} is empty");
    anyhow::ensure!(
        end - first <= MAX_EVAL_SEEDS,
        "--seeds {seeds:?} asks for {} seeds: at most {MAX_EVAL_SEEDS} at once (score the range \
         in parts)",
        end - first
    );
    Ok((first, end))
}

/// A train run opened for scoring: its best checkpoint loaded into the
/// agent its identity describes, on its maze, under the task scored.
struct ScoredRun {
    run: PathBuf,
    state: RunState,
    /// The task scored (the run's own, or another MultiGoal task).
    task: Task,
    layout: Layout,
    env_cfg: EnvConfig,
    agent: Agent,
    /// How the agent acts.
    eval_actions: EvalActions,
    /// The run's budget, when it has not trained it all.
    unfinished: Option<u64>,
}

impl ScoredRun {
    /// Opens `run` (refusing a discovery run or a directory that is not a
    /// train run) for scoring on `task` (its own by default; another task
    /// only among the MultiGoal tasks, which share actions and layout).
    /// `eval_actions` replaces the run's own way of acting.
    fn open(
        run: &Path,
        task: Option<Task>,
        eval_actions: Option<EvalActions>,
    ) -> anyhow::Result<ScoredRun> {
        if let Some(kind @ RunKind::Discover) = kind_of(run) {
            bail!(
                "{} is {}, not a train run: evaluate scores a train run's best checkpoint (give \
                 this one to `train --world-graph`)",
                run.display(),
                describe(run, kind)
            );
        }
        let state = protocol::read_state(run)?.with_context(|| {
            format!(
                "{} is not a train run (no checkpoint/state.json)",
                run.display()
            )
        })?;
        let id = &state.identity;
        let task = task.unwrap_or(id.task);
        anyhow::ensure!(
            task == id.task || (task.is_multigoal() && id.task.is_multigoal()),
            "--task {}: {} was trained on {}, whose actions and layout differ; a run is scored \
             on another task only among multigoal, multigoal-sparse and multigoal-stochastic",
            task.name(),
            run.display(),
            id.task.name()
        );
        // The budget is in the run's config.toml (the identity holds 0).
        let budget = read_config(&run.join("config.toml"))
            .ok()
            .map(|c| trained_env_steps(&c));
        let unfinished = budget.filter(|&b| state.env_steps < b);
        if let Some(b) = unfinished {
            eprintln!(
                "evaluate: {} is unfinished ({} of {b} env steps trained): scoring its best \
                 checkpoint so far",
                run.display(),
                state.env_steps
            );
        }
        let (layout, mut env_cfg) = run_world(run, &id.maze, task)?;
        // The run's episode step limit (0 in a run recorded before it was a
        // setting: the environment's own).
        env_cfg.max_steps = id.config.episode_limit(env_cfg.max_steps);
        let mut agent_cfg = id.config.agent.clone();
        agent_cfg.eval_actions = eval_actions.unwrap_or(agent_cfg.eval_actions);
        let mut agent = build_agent(
            &agent_cfg,
            &layout,
            id.task,
            id.world_graph.as_deref().map(Path::new),
            id.seed,
        )?;
        protocol::load_best(run, &mut agent)?;
        Ok(ScoredRun {
            run: run.to_path_buf(),
            state,
            task,
            layout,
            env_cfg,
            agent,
            eval_actions: agent_cfg.eval_actions,
            unfinished,
        })
    }
}

/// The maze a run trained on, under `task`: a `--layout` run keeps its
/// layout; an embedded maze's run records its name (`<maze>-doorkey` for
/// Door-Key).
fn run_world(run: &Path, maze: &str, task: Task) -> anyhow::Result<(Layout, EnvConfig)> {
    let own_layout = run.join(LAYOUT_FILE);
    if own_layout.is_file() {
        return train_world(Maze::Small, Some(&own_layout), task);
    }
    let maze: Maze = maze
        .strip_suffix("-doorkey")
        .unwrap_or(maze)
        .parse()
        .map_err(|e: String| anyhow::anyhow!(e))?;
    train_world(maze, None, task)
}

/// The score and what the episodes did, as text.
fn print_evaluation(a: &EvaluateArgs, s: &ScoredRun, score: f64, episodes: &EpisodeFigures) {
    let trained_on = s.state.identity.task;
    println!(
        "{}: score {:.3} on test seeds {} ({} episode(s) per seed, {} actions){}{}",
        s.run.display(),
        score,
        a.seeds,
        a.episodes_per_seed,
        match s.eval_actions {
            EvalActions::Sample => "sampled",
            EvalActions::Greedy => "greedy",
        },
        if s.task == trained_on {
            String::new()
        } else {
            format!(" of {} (trained on {})", s.task.name(), trained_on.name())
        },
        match s.unfinished {
            Some(b) => format!(" (unfinished run: {} of {b} env steps)", s.state.env_steps),
            None => String::new(),
        }
    );
    println!(
        "episodes: return {:.3}, exit reached {:.1} %, length {:.1} steps{}",
        episodes.mean_return,
        100.0 * episodes.exit_share,
        episodes.mean_length,
        if s.task.is_multigoal() {
            format!(", balls collected {:.2}", episodes.mean_balls)
        } else {
            String::new()
        }
    );
}

/// What `evaluate`'s episodes did, over every round: the mean return, the
/// share that reached the exit, the mean length and the mean number of
/// balls collected (so a MultiGoal-Sparse score can be read as balls
/// against steps).
#[derive(Debug, Default, Clone, Copy, serde::Serialize)]
struct EpisodeFigures {
    episodes: usize,
    mean_return: f64,
    exit_share: f64,
    mean_length: f64,
    mean_balls: f64,
}

impl EpisodeFigures {
    /// Adds one round's episodes (sums until [`Self::means`]).
    fn add(&mut self, r: &learner::hrl::reports::EvalResult) {
        self.episodes += r.returns.len();
        self.mean_return += r.returns.iter().map(|&x| f64::from(x)).sum::<f64>();
        self.exit_share += r.success_rate * r.returns.len() as f64;
        self.mean_length += r.lengths.iter().map(|&x| f64::from(x)).sum::<f64>();
        self.mean_balls += r.balls.iter().map(|&x| f64::from(x)).sum::<f64>();
    }

    /// The sums as means over the episodes.
    fn means(self) -> EpisodeFigures {
        let n = self.episodes.max(1) as f64;
        EpisodeFigures {
            episodes: self.episodes,
            mean_return: self.mean_return / n,
            exit_share: self.exit_share / n,
            mean_length: self.mean_length / n,
            mean_balls: self.mean_balls / n,
        }
    }
}
