//! What running a stage 2 agent reports: a training iteration's figures
//! ([`IterationStats`]), an evaluation's scores ([`EvalResult`]) and one
//! evaluation episode for the picture of the paper's Figure 1
//! ([`EpisodeTrace`]); and, inside the agent, the counts a batch step adds
//! to (`StepCounts`, `Decisions`) and the trace of the episode under way
//! (`Tracing`).

use serde::{Deserialize, Serialize};

use crate::a2c::LossFigures;
use crate::batch_env::{BatchEnvironment, ObsView};
use crate::error::LearnerError;

/// What one iteration measured.
#[derive(Debug, Clone, Copy, Default, Serialize)]
pub struct IterationStats {
    /// Env steps of the iteration.
    pub env_steps: u64,
    /// Episodes that ended.
    pub episodes: usize,
    /// Mean return of those episodes (0 when none).
    pub mean_return: f64,
    /// The Worker's (or the baseline's) loss.
    pub worker: LossFigures,
    /// The Manager's loss (zeros for A2C).
    pub manager: LossFigures,
    /// Manager intervals that ended (FN, WN).
    pub intervals: usize,
    /// Share of those in which the Worker reached `g_n`.
    pub goals_reached: f64,
    /// Share of env steps taken by graph traversal.
    pub traversal_share: f64,
    /// Share of the episodes that ended by reaching the exit.
    pub exit_share: f64,
    /// Manager decisions made (FN, WN).
    pub decisions: usize,
    /// Share of those whose narrow goal `g_n` is the exit.
    pub exit_goal_share: f64,
    /// Share of those whose narrow goal `g_n` held a ball when named.
    pub ball_goal_share: f64,
    /// Share of the episodes that ended carrying the key (Door-Key).
    pub key_share: f64,
    /// Door-Key: share of the episodes in which the agent opened the
    /// locked door (unlocked it: it may be closed again by the end).
    pub door_share: f64,
    /// Door-Key: share of the episodes in which the key was picked up (it
    /// is carried at the end, or no longer lies in the final grid).
    pub key_taken_share: f64,
    /// Door-Key: share of the Manager's decisions that named the key's
    /// cell as `g_w` or `g_n`.
    pub key_goal_share: f64,
    /// Door-Key: share of the decisions that named a door that was not
    /// open as `g_w` or `g_n`.
    pub door_goal_share: f64,
}

/// The result of an evaluation: one episode per environment.
#[derive(Debug, Clone, Serialize)]
pub struct EvalResult {
    /// Mean return (MultiGoal tasks) or success rate (Door-Key).
    pub score: f64,
    /// Mean episode return.
    pub mean_return: f64,
    /// Share of episodes that reached the exit.
    pub success_rate: f64,
    /// Episode returns, by environment.
    pub returns: Vec<f32>,
    /// Episode lengths.
    pub lengths: Vec<u32>,
    /// Balls collected in each episode (the MultiGoal tasks).
    pub balls: Vec<u8>,
    /// Share of steps taken by traversal.
    pub traversal_share: f64,
}

/// One evaluation episode, for the picture of the paper's Figure 1.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct EpisodeTrace {
    /// The agent's cell before the first step and after each (after the
    /// last, the cell the episode ended on).
    pub cells: Vec<u32>,
    /// Whether each step was taken by traversal.
    pub traversed: Vec<bool>,
    /// The action of each step (`sim::action`, MiniGrid's numbering), by
    /// traversal or by the Worker (the flat agent's own).
    #[serde(default)]
    pub actions: Vec<u8>,
    /// Manager decisions: `(step, g_w, g_n)`.
    pub goals: Vec<(u32, u32, u32)>,
    /// The episode's return.
    pub episode_return: f32,
    /// The grid the episode started on (row-major object codes, as
    /// `sim::Object`): its balls, key, doors, exit.
    #[serde(default)]
    pub start_cells: Vec<u8>,
    /// The grid the episode ended on (the step record's final cells of the
    /// step that ended it): a ball of `start_cells` missing here was
    /// collected. Empty when the transport carries no final cells.
    #[serde(default)]
    pub end_cells: Vec<u8>,
    /// Door-Key: the step (1 for the first) after which the key was in
    /// hand, if it was taken.
    #[serde(default)]
    pub key_step: Option<u32>,
    /// The step after which a door that was not open at the start was
    /// open, if one was opened.
    #[serde(default)]
    pub door_step: Option<u32>,
}

/// Counts of one rollout or evaluation.
#[derive(Debug, Default)]
pub(super) struct StepCounts {
    /// Environment steps.
    pub(super) steps: u64,
    /// Episodes that ended.
    pub(super) episodes: usize,
    /// The sum of their returns.
    pub(super) returns: f64,
    /// Those that ended on the exit.
    pub(super) successes: usize,
    /// Those that ended carrying the key.
    pub(super) with_key: usize,
    /// Those in which a locked door was opened.
    pub(super) door_open: usize,
    /// Door-Key: those in which the key was picked up.
    pub(super) key_taken: usize,
    /// The task has a key to take (Door-Key): `key_taken` counts.
    pub(super) door_key: bool,
    /// Manager intervals that ended.
    pub(super) intervals: usize,
    /// Intervals in which `g_n` was reached.
    pub(super) reached: usize,
    /// Steps taken by world graph traversal.
    pub(super) traversal_steps: u64,
    /// Manager decisions.
    pub(super) decisions: usize,
    /// Decisions whose `g_n` was the exit.
    pub(super) exit_goals: usize,
    /// Decisions whose `g_n` held a ball.
    pub(super) ball_goals: usize,
    /// Decisions naming the key.
    pub(super) key_goals: usize,
    /// Decisions naming a door not yet open.
    pub(super) door_goals: usize,
}

impl StepCounts {
    /// Adds the decisions of one call of the Manager.
    pub(super) fn add(&mut self, d: Decisions) {
        self.decisions += d.count;
        self.exit_goals += d.exit_goals;
        self.ball_goals += d.ball_goals;
        self.key_goals += d.key_goals;
        self.door_goals += d.door_goals;
    }

    /// Counts for `task`'s episodes (Door-Key's key is counted).
    pub(super) fn for_task(task: sim::Task) -> StepCounts {
        StepCounts {
            door_key: task == sim::Task::DoorKey,
            ..StepCounts::default()
        }
    }

    /// Counts environment `e`'s step that produced `obs`; `ended`: the step
    /// ended the episode.
    pub(super) fn count_step(&mut self, obs: &ObsView<'_>, e: usize, ended: bool) {
        if ended {
            self.episodes += 1;
            self.returns += f64::from(obs.meta[e].episode_return);
            self.successes += usize::from(reached_exit(obs, e));
            self.with_key += usize::from(obs.meta[e].end_carrying == sim::Object::Key as u8);
            let cells = obs.width * obs.height;
            let last = obs.final_cells.get(e * cells..(e + 1) * cells);
            // The layout's start is the next episode's first grid, already
            // in `cells`.
            self.door_open += usize::from(last.is_some_and(|g| opened_a_door(obs.env_cells(e), g)));
            self.key_taken += usize::from(
                self.door_key
                    && (obs.meta[e].end_carrying == sim::Object::Key as u8
                        || last.is_some_and(|g| !g.contains(&(sim::Object::Key as u8)))),
            );
        }
        self.steps += 1;
    }

    /// The share of the steps taken by traversal.
    pub(super) fn traversal_share(&self) -> f64 {
        self.traversal_steps as f64 / self.steps.max(1) as f64
    }

    /// The figures of a training iteration of these counts and the
    /// Worker's and the Manager's losses.
    pub(super) fn iteration(&self, worker: LossFigures, manager: LossFigures) -> IterationStats {
        IterationStats {
            env_steps: self.steps,
            episodes: self.episodes,
            mean_return: if self.episodes > 0 {
                self.returns / self.episodes as f64
            } else {
                0.0
            },
            worker,
            manager,
            intervals: self.intervals,
            goals_reached: if self.intervals > 0 {
                self.reached as f64 / self.intervals as f64
            } else {
                0.0
            },
            traversal_share: self.traversal_share(),
            exit_share: self.successes as f64 / self.episodes.max(1) as f64,
            decisions: self.decisions,
            exit_goal_share: self.exit_goals as f64 / self.decisions.max(1) as f64,
            ball_goal_share: self.ball_goals as f64 / self.decisions.max(1) as f64,
            key_share: self.with_key as f64 / self.episodes.max(1) as f64,
            door_share: self.door_open as f64 / self.episodes.max(1) as f64,
            key_taken_share: self.key_taken as f64 / self.episodes.max(1) as f64,
            key_goal_share: self.key_goals as f64 / self.decisions.max(1) as f64,
            door_goal_share: self.door_goals as f64 / self.decisions.max(1) as f64,
        }
    }
}

/// Whether environment `e`'s episode ended, with the step that produced
/// `obs`, by the agent stepping onto the exit (its success; judged on the
/// final state, since the observation is the next episode's start).
pub(super) fn reached_exit(obs: &ObsView<'_>, e: usize) -> bool {
    let m = &obs.meta[e];
    m.terminated()
        && obs
            .final_cells
            .get(e * obs.width * obs.height + obs.end_cell(e) as usize)
            .is_some_and(|&c| c == sim::Object::Exit as u8)
}

/// Whether an episode that started on grid `start` and ended on `end`
/// opened a door: one locked at the start is no longer locked (it may have
/// been closed again: a toggle turns an open door closed, never locked), or
/// one closed at the start is open.
pub fn opened_a_door(start: &[u8], end: &[u8]) -> bool {
    use sim::Object::{DoorClosed, DoorLocked, DoorOpen};
    start.iter().zip(end).any(|(&x, &y)| {
        (x == DoorLocked as u8 && y != x) || (x == DoorClosed as u8 && y == DoorOpen as u8)
    })
}

/// The evaluation episode being traced: environment `env`'s, `step` steps
/// in.
#[derive(Debug)]
pub(super) struct Tracing<'a> {
    /// The traced environment.
    pub(super) env: usize,
    /// Steps taken so far.
    pub(super) step: u32,
    /// The trace.
    pub(super) trace: &'a mut EpisodeTrace,
}

impl Tracing<'_> {
    /// Records the Manager's decision `(g_w, g_n)` in environment `e`.
    pub(super) fn decision(&mut self, e: usize, wide: u32, narrow: u32) {
        if e == self.env {
            self.trace.goals.push((self.step, wide, narrow));
        }
    }

    /// Records environment `e`'s step that took `action`, produced `obs` and
    /// led the agent to `cell` (`traversed`: by traversal; `ended`: the step
    /// ended the episode, whose final grid the step record holds).
    pub(super) fn step(
        &mut self,
        obs: &ObsView<'_>,
        e: usize,
        action: u8,
        cell: u32,
        traversed: bool,
        ended: bool,
    ) {
        if e != self.env {
            return;
        }
        let t = &mut *self.trace;
        t.cells.push(cell);
        t.traversed.push(traversed);
        t.actions.push(action);
        self.step += 1;
        let cpe = obs.width * obs.height;
        if t.key_step.is_none() && obs.meta[e].end_carrying == sim::Object::Key as u8 {
            t.key_step = Some(self.step);
        }
        let grid = if ended {
            obs.final_cells.get(e * cpe..(e + 1) * cpe).unwrap_or(&[])
        } else {
            obs.env_cells(e)
        };
        let open = |g: &[u8]| {
            g.iter()
                .filter(|&&c| c == sim::Object::DoorOpen as u8)
                .count()
        };
        if t.door_step.is_none() && !t.start_cells.is_empty() && open(grid) > open(&t.start_cells) {
            t.door_step = Some(self.step);
        }
        if ended {
            t.end_cells = obs
                .final_cells
                .get(e * cpe..(e + 1) * cpe)
                .map(<[u8]>::to_vec)
                .unwrap_or_default();
        }
    }
}

/// Plays one episode in every environment of `env`, freshly reset, for
/// an evaluation on `task` (a grid `width` cells wide): `step` steps the
/// whole batch, with the trace of environment 0's episode while it runs,
/// until every environment's first episode has ended; `trace` records that
/// episode.
pub(super) fn play_episodes(
    env: &mut dyn BatchEnvironment,
    task: sim::Task,
    width: usize,
    trace: Option<&mut EpisodeTrace>,
    mut step: impl FnMut(
        &mut dyn BatchEnvironment,
        Option<&mut Tracing<'_>>,
        &mut StepCounts,
    ) -> Result<(), LearnerError>,
) -> Result<EvalResult, LearnerError> {
    let n = env.num_envs();
    env.step(&vec![sim::action::RESET; n])?;
    let mut episodes = EvalEpisodes::new(n);
    let mut counts = StepCounts::for_task(task);
    let mut trace = trace.map(|t| Tracing::start(t, &env.observe(), width));
    while !episodes.all_done() {
        let traced = trace.as_mut().filter(|_| !episodes.done(0));
        step(env, traced, &mut counts)?;
        episodes.record(&env.observe());
    }
    if let Some(t) = trace {
        t.trace.episode_return = episodes.returns[0];
    }
    Ok(episodes.result(task, counts.traversal_share()))
}

/// The episodes of an evaluation, one per environment, each recorded when
/// it first ends ([`Self::record`]) and scored by [`Self::result`]: the
/// mean return (MultiGoal tasks) or the success rate (Door-Key).
#[derive(Debug)]
pub(super) struct EvalEpisodes {
    done: Vec<bool>,
    returns: Vec<f32>,
    lengths: Vec<u32>,
    balls: Vec<u8>,
    success: Vec<bool>,
}

impl EvalEpisodes {
    /// `n` environments, every episode under way.
    pub(super) fn new(n: usize) -> EvalEpisodes {
        EvalEpisodes {
            done: vec![false; n],
            returns: vec![0.0; n],
            lengths: vec![0; n],
            balls: vec![0; n],
            success: vec![false; n],
        }
    }

    /// Every episode has ended.
    pub(super) fn all_done(&self) -> bool {
        self.done.iter().all(|&d| d)
    }

    /// Environment `e`'s episode has ended.
    pub(super) fn done(&self, e: usize) -> bool {
        self.done[e]
    }

    /// Records the episodes that the step producing `obs` ended.
    pub(super) fn record(&mut self, obs: &ObsView<'_>) {
        for e in 0..self.done.len() {
            let m = &obs.meta[e];
            if !self.done[e] && m.done() {
                self.done[e] = true;
                self.returns[e] = m.episode_return;
                self.lengths[e] = m.episode_len;
                self.balls[e] = m.balls;
                self.success[e] = reached_exit(obs, e);
            }
        }
    }

    /// The evaluation's result on `task`, with the share of steps taken by
    /// traversal `traversal_share`.
    pub(super) fn result(self, task: sim::Task, traversal_share: f64) -> EvalResult {
        let n = self.done.len().max(1) as f64;
        let mean_return = self.returns.iter().map(|&r| f64::from(r)).sum::<f64>() / n;
        let success_rate = self.success.iter().filter(|&&s| s).count() as f64 / n;
        EvalResult {
            score: if task == sim::Task::DoorKey {
                success_rate
            } else {
                mean_return
            },
            mean_return,
            success_rate,
            returns: self.returns,
            lengths: self.lengths,
            balls: self.balls,
            traversal_share,
        }
    }
}

impl<'a> Tracing<'a> {
    /// Starts tracing environment 0's episode into `trace` from `obs`, the
    /// first observation (of a grid `width` cells wide).
    pub(super) fn start(trace: &'a mut EpisodeTrace, obs: &ObsView<'_>, width: usize) -> Self {
        *trace = EpisodeTrace::default();
        trace.cells.push(obs.meta[0].cell(width) as u32);
        trace.start_cells = obs.env_cells(0).to_vec();
        Tracing {
            env: 0,
            step: 0,
            trace,
        }
    }
}

/// The Manager's decisions of one call of
/// [`ManagerSide::decide`](super::manager::ManagerSide::decide).
#[derive(Debug, Default, Clone, Copy)]
pub(super) struct Decisions {
    /// Decisions made.
    pub(super) count: usize,
    /// Decisions whose narrow goal `g_n` is an exit cell.
    pub(super) exit_goals: usize,
    /// Decisions whose narrow goal `g_n` holds a ball.
    pub(super) ball_goals: usize,
    /// Decisions with `g_w` or `g_n` on the key.
    pub(super) key_goals: usize,
    /// Decisions with `g_w` or `g_n` on a door not yet open.
    pub(super) door_goals: usize,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::batch_env::{BatchEnvironment, InProcess};
    use sim::{EnvConfig, Layout, Task, action};

    /// Door-Key's figures come from the final state of an episode: an
    /// episode cut by the step limit after the agent picked up the key and
    /// opened the door counts in both, also when it closed the door again;
    /// one that did neither in none.
    #[test]
    fn an_episode_that_took_the_key_and_opened_the_door_counts_in_both_shares() {
        let layout = Layout::parse("door", "######\n#>KD.#\n#...E#\n######").expect("layout");
        let cfg = EnvConfig {
            task: Task::DoorKey,
            max_steps: 4,
            ..EnvConfig::for_task(Task::DoorKey, &layout)
        };
        let mut env = InProcess::new(layout, cfg, 3, 0, 1).expect("env");
        let mut counts = StepCounts::for_task(Task::DoorKey);
        // Environment 0 picks up the key, steps onto its cell, opens the
        // door; environment 1 turns on the spot; environment 2 does as 0,
        // then closes the door behind it.
        let steps = [
            [action::PICKUP, action::LEFT, action::PICKUP],
            [action::FORWARD, action::LEFT, action::FORWARD],
            [action::TOGGLE, action::LEFT, action::TOGGLE],
            [action::LEFT, action::LEFT, action::TOGGLE],
        ];
        for a in steps {
            env.step(&a).expect("step");
            let obs = env.observe();
            for e in 0..3 {
                counts.count_step(&obs, e, obs.meta[e].done());
            }
        }
        let s = counts.iteration(LossFigures::default(), LossFigures::default());
        assert_eq!(s.episodes, 3, "the step limit ends every episode");
        assert_eq!((s.key_share, s.door_share), (2.0 / 3.0, 2.0 / 3.0));
        assert_eq!(s.key_taken_share, 2.0 / 3.0);
    }
}
