//! The paper's protocol (section 5, Control Experiments): training runs in
//! segments of `eval_every` env steps; after each, the agent is scored on
//! the validation seeds and the run checkpointed, the best checkpoint is
//! kept, and at the end that checkpoint is scored on held-out test seeds.
//!
//! The streams keep the three sets of environments apart: training
//! environment `i` of seed `s` is `(s, i)` with `s` below
//! [`MAX_TRAIN_SEED`], validation seed `v` is `(VALIDATION_STREAM, v)`,
//! test seed `t` is `(TEST_STREAM, t)`.
//!
//! A checkpoint is the set of files of one segment committed by
//! `state.json`, written last ([`save_state`]); it holds the agent's
//! weights and optimiser moments and, in process, the training
//! environments' and the controller's states, so a killed run resumes
//! mid-episode and ends exactly as an uninterrupted one.

use std::path::Path;

use anyhow::Context;
use serde::{Deserialize, Serialize};
use sim::atomic_file::write_atomic;
use sim::{BatchEnv, EnvConfig, Layout, Object, Task};

use super::config::{RunIdentity, Schedule, TrainConfig};
use crate::batch_env::{BatchEnvironment, InProcess};
use crate::hrl::wide_narrow::Coverage;
use crate::hrl::{Agent, EpisodeTrace, EvalResult, IterationStats, opened_a_door};

/// Environment stream of the validation seeds: validation seed `v` is the
/// environment `(VALIDATION_STREAM, v)`.
pub const VALIDATION_STREAM: u64 = 1_000_003;
/// Environment stream of the test seeds.
pub const TEST_STREAM: u64 = 2_000_003;
/// Training seeds are below this (so their streams `(seed, i)` never meet
/// the validation and test streams).
pub const MAX_TRAIN_SEED: u64 = 1_000_000;

/// One row of `metrics.csv` (one segment).
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
pub struct MetricsRow {
    /// Segments done.
    pub segment: u64,
    /// Iterations done.
    pub iteration: u64,
    /// Env steps done.
    pub env_steps: u64,
    /// Mean return of the training episodes of the segment.
    pub train_return: f64,
    /// Validation score after the segment.
    pub validation_score: f64,
    /// Worker (or baseline) policy loss, mean over the segment.
    pub worker_policy_loss: f64,
    /// Worker value loss.
    pub worker_value_loss: f64,
    /// Worker entropy.
    pub worker_entropy: f64,
    /// Manager policy loss.
    pub manager_policy_loss: f64,
    /// Manager value loss.
    pub manager_value_loss: f64,
    /// Manager entropy.
    pub manager_entropy: f64,
    /// Share of Manager intervals in which the Worker reached its goal.
    pub goals_reached: f64,
    /// Share of env steps taken by traversal.
    pub traversal_share: f64,
}

/// The run's progress (`checkpoint/state.json`).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunState {
    /// What the run was started with.
    pub identity: RunIdentity,
    /// Segments trained.
    pub segments_done: u64,
    /// Env steps trained.
    pub env_steps: u64,
    /// The best validation score so far.
    pub best_score: Option<f64>,
    /// The segment it was reached at.
    pub best_segment: u64,
    /// One row per segment.
    pub rows: Vec<MetricsRow>,
    /// Training wall seconds after each segment.
    pub wall_seconds: Vec<f64>,
}

/// `test.json`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct TestSummary {
    /// The agent's short name.
    pub agent: String,
    /// Maze.
    pub maze: String,
    /// Task.
    pub task: String,
    /// Training seed.
    pub seed: u64,
    /// Test score of the best checkpoint (mean reward, or Door-Key success rate).
    pub test_score: f64,
    /// Mean test return.
    pub test_return: f64,
    /// Test success rate.
    pub test_success_rate: f64,
    /// Test seeds: environments `(test_stream, 0..test_seeds)`.
    pub test_stream: u64,
    /// Number of test seeds.
    pub test_seeds: usize,
    /// Validation seeds: `(validation_stream, 0..validation_seeds)`.
    pub validation_stream: u64,
    /// Number of validation seeds.
    pub validation_seeds: usize,
    /// Best validation score and the env steps it was reached at.
    pub best_validation: f64,
    /// Env steps at the best checkpoint.
    pub best_env_steps: u64,
    /// Env steps trained.
    pub env_steps: u64,
    /// Wall seconds of training (all sessions).
    pub wall_seconds: f64,
    /// Training env-steps per second.
    pub train_steps_per_sec: f64,
    /// Validation curve: `(env steps, score)`.
    pub validation_curve: Vec<(u64, f64)>,
    /// Training wall seconds at each point of the validation curve (for
    /// time to score).
    #[serde(default)]
    pub validation_wall_seconds: Vec<f64>,
    /// Side `N` of the narrow window (WN).
    #[serde(default)]
    pub window_side: Option<usize>,
    /// Which free cells the narrow goals can reach under the candidate set
    /// the run used (WN).
    #[serde(default)]
    pub window_coverage: Option<Coverage>,
}

/// Evaluation environments: `count` seeds of `stream` from `first`, one
/// episode each.
pub fn eval_env(
    layout: &Layout,
    env_cfg: EnvConfig,
    stream: u64,
    first: u64,
    count: usize,
) -> anyhow::Result<InProcess> {
    let batch =
        BatchEnv::with_first_index(layout.clone(), env_cfg, first as usize, count, stream, 1)?;
    Ok(InProcess::from_batch(batch))
}

/// The files of segment `k`'s checkpoint besides `state.json`: the agent's
/// weights and optimiser moments, the training controller (record and
/// tensors) and the training environments' states.
fn checkpoint_files(k: u64) -> [String; 4] {
    [
        format!("agent-{k}.ot"),
        format!("controller-{k}.json"),
        format!("controller-{k}.ot"),
        format!("envs-{k}.json"),
    ]
}

/// Commits segment `state.segments_done`'s checkpoint in `dir`: the
/// agent's weights (and `best`, the best checkpoint's, when this segment
/// set it), in process the controller and environments, then `state.json`
/// last, which names the set; then the previous segment's files are
/// removed and `metrics.csv` and `timing.csv` rewritten.
pub fn save_state(
    dir: &Path,
    state: &RunState,
    agent: &Agent,
    best: Option<&[u8]>,
    env: Option<&dyn BatchEnvironment>,
) -> anyhow::Result<()> {
    let ckpt = dir.join("checkpoint");
    std::fs::create_dir_all(&ckpt).with_context(|| format!("cannot create {}", ckpt.display()))?;
    let [weights, record, tensors, envs] = checkpoint_files(state.segments_done);
    write_atomic(&ckpt.join(weights), &agent.to_bytes()?)?;
    if let Some(snapshot) = env.and_then(|e| e.snapshot()) {
        let saved = agent.save_controller()?;
        write_atomic(&ckpt.join(record), &saved.record)?;
        write_atomic(&ckpt.join(tensors), &saved.tensors)?;
        write_atomic(&ckpt.join(envs), &serde_json::to_vec(&snapshot)?)?;
    }
    if let Some(b) = best {
        write_atomic(&ckpt.join("best.ot"), b)?;
    }
    // The state names its files: written last, it commits the set.
    write_atomic(&ckpt.join("state.json"), &serde_json::to_vec_pretty(state)?)?;
    if state.segments_done > 0 {
        for old in checkpoint_files(state.segments_done - 1) {
            let _ = std::fs::remove_file(ckpt.join(old));
        }
    }
    write_metrics(dir, state)?;
    Ok(())
}

/// The state of the last committed checkpoint in `dir`, if any.
pub fn read_state(dir: &Path) -> anyhow::Result<Option<RunState>> {
    let path = dir.join("checkpoint").join("state.json");
    if !path.exists() {
        return Ok(None);
    }
    let bytes = std::fs::read(&path).with_context(|| format!("cannot read {}", path.display()))?;
    let state = serde_json::from_slice(&bytes)
        .with_context(|| format!("{} is not a training state", path.display()))?;
    Ok(Some(state))
}

/// Loads the weights (and optimiser moments) of `state`'s checkpoint in
/// `dir` into `agent`.
pub fn load_weights(dir: &Path, state: &RunState, agent: &mut Agent) -> anyhow::Result<()> {
    let [weights, ..] = checkpoint_files(state.segments_done);
    load_file(&dir.join("checkpoint").join(weights), agent)
}

/// Loads the best checkpoint of the run in `dir` into `agent`.
pub fn load_best(dir: &Path, agent: &mut Agent) -> anyhow::Result<()> {
    load_file(&dir.join("checkpoint").join("best.ot"), agent)
}

fn load_file(path: &Path, agent: &mut Agent) -> anyhow::Result<()> {
    let bytes = std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
    agent.load_bytes(&bytes, path)?;
    Ok(())
}

/// Puts the training environments and the agent's controller back in the
/// states the checkpoint of `state` saved; false when it saved none (a
/// pipeline run, or a run made before they were saved).
pub fn restore_training(
    dir: &Path,
    state: &RunState,
    agent: &mut Agent,
    env: &mut dyn BatchEnvironment,
) -> anyhow::Result<bool> {
    let ckpt = dir.join("checkpoint");
    let [_, record, tensors, envs] = checkpoint_files(state.segments_done);
    let (record, tensors, envs) = (ckpt.join(record), ckpt.join(tensors), ckpt.join(envs));
    if !(record.exists() && tensors.exists() && envs.exists()) {
        return Ok(false);
    }
    let read = |p: &Path| std::fs::read(p).with_context(|| format!("cannot read {}", p.display()));
    let states: Vec<sim::EnvState> = serde_json::from_slice(&read(&envs)?)
        .with_context(|| format!("{} is not a set of environment states", envs.display()))?;
    if !env
        .restore(&states)
        .with_context(|| format!("cannot restore {}", envs.display()))?
    {
        return Ok(false);
    }
    agent.load_controller(&read(&record)?, &read(&tensors)?, &record)?;
    Ok(true)
}

/// `metrics.csv` (one row per segment) and `timing.csv` (its wall seconds).
fn write_metrics(dir: &Path, state: &RunState) -> anyhow::Result<()> {
    let mut w = csv_writer();
    for r in &state.rows {
        w.push_str(&format!(
            "{},{},{},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6}\n",
            r.segment,
            r.iteration,
            r.env_steps,
            r.train_return,
            r.validation_score,
            r.worker_policy_loss,
            r.worker_value_loss,
            r.worker_entropy,
            r.manager_policy_loss,
            r.manager_value_loss,
            r.manager_entropy,
            r.goals_reached,
            r.traversal_share
        ));
    }
    write_atomic(&dir.join("metrics.csv"), w.as_bytes())?;
    let mut t = String::from("segment,env_steps,wall_seconds\n");
    for (r, s) in state.rows.iter().zip(&state.wall_seconds) {
        t.push_str(&format!("{},{},{:.3}\n", r.segment, r.env_steps, s));
    }
    write_atomic(&dir.join("timing.csv"), t.as_bytes())?;
    Ok(())
}

/// The header of `metrics.csv`.
fn csv_writer() -> String {
    String::from(
        "segment,iteration,env_steps,train_return,validation_score,worker_policy_loss,worker_value_loss,worker_entropy,manager_policy_loss,manager_value_loss,manager_entropy,goals_reached,traversal_share\n",
    )
}

/// The row of a segment from its iterations' figures (episode returns and
/// goals reached weighted by their counts).
pub fn mean_row(stats: &[IterationStats]) -> MetricsRow {
    let n = stats.len().max(1) as f64;
    // The mean of `value` over the iterations, each weighted by `weight`
    // (0 when every weight is).
    let weighted = |value: fn(&IterationStats) -> f64, weight: fn(&IterationStats) -> usize| {
        let total: usize = stats.iter().map(weight).sum();
        if total == 0 {
            return 0.0;
        }
        stats
            .iter()
            .filter(|s| weight(s) > 0)
            .map(|s| value(s) * weight(s) as f64)
            .sum::<f64>()
            / total as f64
    };
    MetricsRow {
        train_return: weighted(|s| s.mean_return, |s| s.episodes),
        worker_policy_loss: stats.iter().map(|s| s.worker.policy_loss).sum::<f64>() / n,
        worker_value_loss: stats.iter().map(|s| s.worker.value_loss).sum::<f64>() / n,
        worker_entropy: stats.iter().map(|s| s.worker.entropy).sum::<f64>() / n,
        manager_policy_loss: stats.iter().map(|s| s.manager.policy_loss).sum::<f64>() / n,
        manager_value_loss: stats.iter().map(|s| s.manager.value_loss).sum::<f64>() / n,
        manager_entropy: stats.iter().map(|s| s.manager.entropy).sum::<f64>() / n,
        goals_reached: weighted(|s| s.goals_reached, |s| s.intervals),
        traversal_share: stats.iter().map(|s| s.traversal_share).sum::<f64>() / n,
        ..MetricsRow::default()
    }
}

/// with and collected, whether it ended on the exit, the key and the door
/// (from the grids it started and ended on).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct EpisodeOutcome {
    /// Balls on the grid at the start.
    pub balls: usize,
    /// Of those, the ones missing from the final grid.
    pub collected: usize,
    /// The episode ended on an exit cell.
    pub exited: bool,
    /// A key on the start grid was gone from its cell at the end.
    pub key_taken: bool,
    /// A door was opened ([`opened_a_door`]).
    pub door_opened: bool,
}

impl EpisodeOutcome {
    /// The outcome of `t`; `None` when it holds no start and end grids.
    pub fn of(t: &EpisodeTrace) -> Option<EpisodeOutcome> {
        let (a, b) = (&t.start_cells, &t.end_cells);
        if a.is_empty() || a.len() != b.len() {
            return None;
        }
        let code = |o: Object| o as u8;
        let gone = |o: Object| {
            a.iter()
                .zip(b)
                .filter(|&(&x, &y)| x == code(o) && y != code(o))
                .count()
        };
        let last = t.cells.last().map(|&c| c as usize);
        Some(EpisodeOutcome {
            balls: a.iter().filter(|&&c| c == code(Object::Ball)).count(),
            collected: gone(Object::Ball),
            exited: last.and_then(|c| b.get(c)) == Some(&code(Object::Exit)),
            key_taken: gone(Object::Key) > 0,
            door_opened: opened_a_door(a, b),
        })
    }
}

/// What the caller of [`train_segments`] sees of the run as it trains:
/// every update (for a progress bar and the per-update log) and every
/// committed segment.
pub trait Observer {
    /// After update `update` (1 for the run's first), `wall_seconds` into
    /// the run's training time, the update itself taking `seconds`.
    fn update(
        &mut self,
        update: u64,
        stats: &IterationStats,
        wall_seconds: f64,
        seconds: f64,
    ) -> anyhow::Result<()>;
    /// After a segment was validated and its checkpoint committed.
    fn segment(&mut self, state: &RunState) -> anyhow::Result<()>;
}

/// Trains the segments `state` has not done yet (section 5): each runs
/// its iterations on `env`, is validated on fresh environments of the
/// validation seeds (which leaves the training environments and the
/// controller untouched), becomes the best checkpoint when it scores
/// higher than every earlier one, and is committed in `dir`.
#[allow(clippy::too_many_arguments)]
pub fn train_segments(
    dir: &Path,
    cfg: &TrainConfig,
    layout: &Layout,
    env_cfg: EnvConfig,
    state: &mut RunState,
    agent: &mut Agent,
    env: &mut dyn BatchEnvironment,
    observer: &mut dyn Observer,
) -> anyhow::Result<()> {
    let schedule = Schedule::of(cfg);
    let mut wall_before: f64 = state.wall_seconds.last().copied().unwrap_or(0.0);
    while state.segments_done < schedule.segments {
        let seg_start = std::time::Instant::now();
        let mut stats = Vec::with_capacity(schedule.iters_per_segment as usize);
        for k in 0..schedule.iters_per_segment {
            let t0 = std::time::Instant::now();
            let s = agent.train_iteration(env)?;
            let update = state.segments_done * schedule.iters_per_segment + k + 1;
            observer.update(
                update,
                &s,
                wall_before + seg_start.elapsed().as_secs_f64(),
                t0.elapsed().as_secs_f64(),
            )?;
            stats.push(s);
        }
        // The same validation episodes every time: fresh environments of
        // the validation seeds.
        let mut val_env = eval_env(layout, env_cfg, VALIDATION_STREAM, 0, cfg.validation_seeds)?;
        let val = agent.evaluate(&mut val_env, state.segments_done, None)?;
        state.segments_done += 1;
        state.env_steps += schedule.steps_per_segment();
        let mut row = mean_row(&stats);
        row.segment = state.segments_done;
        row.iteration = state.segments_done * schedule.iters_per_segment;
        row.env_steps = state.env_steps;
        row.validation_score = val.score;
        state.rows.push(row);
        wall_before += seg_start.elapsed().as_secs_f64();
        state.wall_seconds.push(wall_before);
        let mut best_bytes = None;
        if state.best_score.is_none_or(|b| val.score > b) {
            state.best_score = Some(val.score);
            state.best_segment = state.segments_done;
            best_bytes = Some(agent.to_bytes()?);
        }
        save_state(dir, state, agent, best_bytes.as_deref(), Some(&*env))?;
        observer.segment(state)?;
    }
    Ok(())
}

/// The end of the protocol: the best checkpoint of the run in `dir`,
/// scored on the `cfg.test_seeds` held-out test seeds; its summary and
/// the trace of test seed 0's episode are written as `test.json` and
/// `test_episode.json`.
#[allow(clippy::too_many_arguments)]
pub fn test(
    dir: &Path,
    cfg: &TrainConfig,
    layout: &Layout,
    env_cfg: EnvConfig,
    task: Task,
    seed: u64,
    state: &RunState,
    agent: &mut Agent,
) -> anyhow::Result<(TestSummary, EvalResult, EpisodeTrace)> {
    load_best(dir, agent)?;
    let mut test_env = eval_env(layout, env_cfg, TEST_STREAM, 0, cfg.test_seeds)?;
    let mut trace = EpisodeTrace::default();
    let test = agent.evaluate(&mut test_env, u64::MAX, Some(&mut trace))?;
    let wall = state.wall_seconds.last().copied().unwrap_or(0.0);
    let window_coverage = agent.window_coverage();
    let summary = TestSummary {
        agent: cfg.agent.name(),
        maze: layout.name.clone(),
        task: task.name().to_string(),
        seed,
        test_score: test.score,
        test_return: test.mean_return,
        test_success_rate: test.success_rate,
        test_stream: TEST_STREAM,
        test_seeds: cfg.test_seeds,
        validation_stream: VALIDATION_STREAM,
        validation_seeds: cfg.validation_seeds,
        best_validation: state.best_score.unwrap_or(0.0),
        best_env_steps: state.best_segment * Schedule::of(cfg).steps_per_segment(),
        env_steps: state.env_steps,
        wall_seconds: wall,
        train_steps_per_sec: state.env_steps as f64 / wall.max(1e-9),
        validation_curve: state
            .rows
            .iter()
            .map(|r| (r.env_steps, r.validation_score))
            .collect(),
        validation_wall_seconds: state.wall_seconds.clone(),
        window_side: window_coverage.as_ref().map(|c| c.side),
        window_coverage,
    };
    write_atomic(
        &dir.join("test.json"),
        &serde_json::to_vec_pretty(&summary)?,
    )?;
    write_atomic(&dir.join("test_episode.json"), &serde_json::to_vec(&trace)?)?;
    Ok((summary, test, trace))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hrl::{AgentConfig, AgentKind};
    use sim::Maze;

    /// A resumed run carries on from the rows it read back from
    /// `state.json`, so each float must read back as the same bits: these
    /// are a small-maze WN run's segment statistics that read back one ulp
    /// off before serde_json parsed floats exactly (`float_roundtrip`), so
    /// that a resumed run's `state.json` differed from an uninterrupted
    /// one's in the last digit.
    #[test]
    fn the_metrics_rows_read_back_from_state_json_bit_for_bit() {
        for x in [
            0.24993813412521654_f64,
            0.021377228659444622,
            0.011179948622538221,
        ] {
            let text = serde_json::to_string(&x).unwrap();
            let back: f64 = serde_json::from_str(&text).unwrap();
            assert_eq!(back.to_bits(), x.to_bits(), "{text} read back as {back:?}");
        }
    }

    /// A small agent of `kind` over `envs` environments, every cell a
    /// candidate goal: quick to build, for tests of the evaluation path.
    fn tiny_agent(kind: AgentKind, envs: usize) -> AgentConfig {
        AgentConfig {
            kind,
            candidates: crate::hrl::config::Candidates::All,
            envs,
            hidden: 16,
            conv_channels: [4, 8],
            ..AgentConfig::default()
        }
    }

    /// `agent.eval_actions`: a greedy agent's test episodes are its
    /// policies' most likely choices, so the sampling seed changes none of
    /// them; a sampling agent's differ between seeds. For the flat baseline
    /// and for WN (the Manager's goals as well as the Worker's actions).
    #[test]
    fn greedy_evaluation_plays_the_same_episodes_whatever_the_sampling_seed() {
        use crate::hrl::config::EvalActions;
        let layout = Maze::Small.layout(false);
        let env_cfg = EnvConfig::for_task(Task::MultiGoal, &layout);
        let episodes = |cfg: &AgentConfig, seed: u64| {
            let mut agent = Agent::new(cfg, &layout, Task::MultiGoal, None, 3).unwrap();
            let mut env = eval_env(&layout, env_cfg, TEST_STREAM, 0, 4).unwrap();
            let mut t = EpisodeTrace::default();
            let r = agent.evaluate(&mut env, seed, Some(&mut t)).unwrap();
            (r.lengths, r.returns, t.cells, t.goals)
        };
        for kind in [AgentKind::A2c, AgentKind::WideNarrow] {
            let sample = tiny_agent(kind, 4);
            let greedy = AgentConfig {
                eval_actions: EvalActions::Greedy,
                ..sample.clone()
            };
            assert_eq!(
                episodes(&greedy, 1),
                episodes(&greedy, 2),
                "{kind:?}: greedy episodes differ between sampling seeds"
            );
            assert_ne!(
                episodes(&sample, 1),
                episodes(&sample, 2),
                "{kind:?}: sampled episodes are the same for two seeds"
            );
            assert_ne!(
                episodes(&greedy, 1),
                episodes(&sample, 1),
                "{kind:?}: the greedy agent plays the sampling one's episodes"
            );
        }
    }

    /// A trace's actions are the ones its episode took: played again in a
    /// fresh environment of the same seed, they walk the trace's cells and
    /// earn its return. For the flat baseline and for WN, whose traced
    /// actions come from the Worker.
    #[test]
    fn a_traced_episode_replays_from_its_actions() {
        let layout = Maze::Small.layout(false);
        let env_cfg = EnvConfig::for_task(Task::MultiGoal, &layout);
        for kind in [AgentKind::A2c, AgentKind::WideNarrow] {
            let cfg = tiny_agent(kind, 2);
            let mut agent = Agent::new(&cfg, &layout, Task::MultiGoal, None, 5).unwrap();
            let mut env = eval_env(&layout, env_cfg, TEST_STREAM, 7, 2).unwrap();
            let mut t = EpisodeTrace::default();
            agent.evaluate(&mut env, 1, Some(&mut t)).unwrap();
            assert_eq!(t.actions.len() + 1, t.cells.len(), "{kind:?}");
            assert!(
                t.actions.iter().any(|&a| a != t.actions[0]),
                "{kind:?}: one action all episode"
            );
            // An evaluation starts its episodes with a reset (`play_episodes`).
            let mut replay = eval_env(&layout, env_cfg, TEST_STREAM, 7, 2).unwrap();
            replay.step(&[sim::action::RESET; 2]).unwrap();
            assert_eq!(
                replay.observe().env_cells(0),
                &t.start_cells[..],
                "{kind:?}"
            );
            let mut episode_return = 0.0f32;
            for (i, &a) in t.actions.iter().enumerate() {
                replay.step(&[a, sim::action::LEFT]).unwrap();
                let obs = replay.observe();
                episode_return += obs.meta[0].reward;
                assert_eq!(obs.end_cell(0), t.cells[i + 1], "{kind:?}: step {i}");
                assert_eq!(
                    obs.meta[0].done(),
                    i + 1 == t.actions.len(),
                    "{kind:?}: step {i} of {}",
                    t.actions.len()
                );
            }
            assert!(
                (episode_return - t.episode_return).abs() < 1e-4,
                "{kind:?}: replayed {episode_return}, traced {}",
                t.episode_return
            );
        }
    }

    /// A Door-Key episode that unlocked the door and closed it again
    /// opened it; one that never unlocked it did not (the grids a real
    /// episode of the tiny Door-Key layout starts and ends on).
    #[test]
    fn a_door_unlocked_then_closed_counts_as_opened() {
        let layout = Layout::parse("door", "######\n#>KD.#\n#...E#\n######").unwrap();
        let cfg = EnvConfig::for_task(Task::DoorKey, &layout);
        let mut env = sim::Env::new(layout, cfg, 0, 0);
        let start = env.grid().to_vec();
        let mut outcome_after = |actions: &[u8]| {
            for &a in actions {
                env.step_meta(a);
            }
            let t = EpisodeTrace {
                cells: vec![0],
                start_cells: start.clone(),
                end_cells: env.grid().to_vec(),
                ..EpisodeTrace::default()
            };
            EpisodeOutcome::of(&t).unwrap()
        };
        let o = outcome_after(&[sim::action::PICKUP, sim::action::FORWARD]);
        assert!(o.key_taken && !o.door_opened, "{o:?}");
        assert!(outcome_after(&[sim::action::TOGGLE]).door_opened);
        let closed = outcome_after(&[sim::action::TOGGLE]);
        assert!(closed.door_opened, "{closed:?}");
    }

    /// Issue 21: a real test episode records the grid it started on and
    /// the grid it ended on, and they agree with the simulator's return
    /// (MultiGoal: +1 a ball, +1 at the exit, −0.01 a step).
    #[test]
    fn a_traced_episode_records_its_start_and_end_grids() {
        let layout = Maze::Small.layout(false);
        let cfg = AgentConfig {
            kind: AgentKind::A2c,
            envs: 1,
            ..AgentConfig::default()
        };
        let mut agent = Agent::new(&cfg, &layout, Task::MultiGoal, None, 3).unwrap();
        let env_cfg = EnvConfig::for_task(Task::MultiGoal, &layout);
        let mut env = eval_env(&layout, env_cfg, TEST_STREAM, 0, 2).unwrap();
        let mut t = EpisodeTrace::default();
        let r = agent.evaluate(&mut env, 1, Some(&mut t)).unwrap();
        assert_eq!(t.start_cells.len(), layout.cells.len());
        assert_eq!(t.end_cells.len(), layout.cells.len());
        let o = EpisodeOutcome::of(&t).unwrap();
        assert_eq!(o.balls, sim::task::DEFAULT_BALLS as usize, "{o:?}");
        let steps = t.cells.len() - 1;
        assert_eq!(steps as u32, r.lengths[0]);
        let expected = o.collected as f32 + f32::from(u8::from(o.exited)) + steps as f32 * -0.01;
        assert!(
            (t.episode_return - expected).abs() < 1e-3,
            "return {} but the grids say {o:?} over {steps} steps",
            t.episode_return
        );
        // The walls and the exit are where the layout has them.
        for (i, (&s, &l)) in t.start_cells.iter().zip(&layout.cells).enumerate() {
            if l == Object::Wall as u8 || l == Object::Exit as u8 {
                assert_eq!(s, l, "cell {i}");
            }
        }
    }
}
