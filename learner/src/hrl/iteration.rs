//! Running a stage 2 agent (Shang et al. 2019, section 4): one environment
//! step of the whole batch, and the training iterations and evaluations
//! made of them.
//!
//! A batch step ([`HrlAgent::step_batch`]):
//!
//! 1. the Manager decides for every environment that needs a goal — its
//!    episode started or its interval ended (sections 4.1–4.2;
//!    `ManagerSide::decide`);
//! 2. an environment whose agent stands on a pivotal state with a route to
//!    its wide goal hands over to a world graph traversal (section 4.3);
//! 3. the Worker samples every environment's action, and a
//!    traversal under way overrides it with its own;
//! 4. the environments step;
//! 5. each step is booked: the task's reward for the Manager's interval,
//!    the Worker's reward from its goals ([`super::worker`]; a Worker that
//!    now stands where a traversal can start hands over to it) or the
//!    traversal's progress ([`traversal::book_step`]), and where the
//!    interval ends, a decision is due at the next step.
//!
//! Training records the steps in the Worker's rollout and the Manager's
//! decision queues and updates both after `T` steps
//! ([`HrlAgent::train_iteration`]); evaluation plays one episode per
//! environment without recording ([`HrlAgent::evaluate`]).

use super::agent::{EVAL_SALT, HrlAgent, check_batch};
use super::config::HandOver;
use super::controller::Controller;
use super::reports::{
    EpisodeTrace, EvalResult, IterationStats, StepCounts, Tracing, play_episodes,
};
use super::steering::Leg;
use super::traversal::{self, Execution, Traversal};
use super::worker::{Arrival, EpisodeEnd, WorkerStep};
use crate::a2c::input::mask;
use crate::a2c::net::LstmState;
use crate::batch_env::{BatchEnvironment, ObsView};
use crate::error::LearnerError;

/// What the agent chose before a batch step.
struct Acted {
    /// Each environment's action (MiniGrid numbering).
    actions: Vec<u8>,
    /// The Worker's policy output sampled for each environment (its index
    /// into [`HrlAgent::actions`]), which its rollout learns from.
    choices: Vec<u8>,
    /// Each environment's goal cells `(g_w, g_n)` and the objects lying
    /// there before the step (object goals are reached by acting on them).
    goal_objects: Vec<[(u32, u8); 2]>,
    /// The Worker's core state after the step.
    state: LstmState,
    /// `π_g` steered the step and it is recorded for its fine-tuning.
    steered: bool,
}

/// The booking of one batch step, by environment.
struct StepBook {
    /// The Worker's rewards.
    rewards: Vec<f32>,
    /// The Worker's goal episode ended.
    dones: Vec<bool>,
    /// 1 where the Worker chose the action, 0 for a traversal's.
    weights: Vec<f32>,
    /// Worker goal episodes that the step limit cut:
    /// bootstrapped from their final states.
    cut_worker: Vec<usize>,
    /// Manager intervals that the step limit cut, likewise.
    cut_manager: Vec<usize>,
    /// How the step went for `π_g`'s fine-tuning.
    legs: Vec<Leg>,
}

impl StepBook {
    fn new(n: usize) -> StepBook {
        StepBook {
            rewards: vec![0f32; n],
            dones: vec![false; n],
            weights: vec![0f32; n],
            cut_worker: Vec::new(),
            cut_manager: Vec::new(),
            legs: vec![Leg::Idle; n],
        }
    }
}

impl HrlAgent {
    /// Before a batch step on `obs`: the Manager's decisions, the
    /// traversals that start, the Worker's actions and the traversals'.
    fn act(
        &mut self,
        ctl: &mut Controller,
        obs: &ObsView<'_>,
        train: bool,
        trace: Option<&mut Tracing<'_>>,
        stats: &mut StepCounts,
    ) -> Result<Acted, LearnerError> {
        let greedy = self.cfg.eval_actions.greedy(train);
        stats.add(self.manager.decide(ctl, obs, train, greedy, trace));
        if self.traverser.graph().is_some() {
            for (e, c) in ctl.envs.iter_mut().enumerate() {
                self.traverser.try_start(&c.goal, &mut c.traversal, obs, e);
            }
        }
        let marks = self.worker.goal_marks(ctl.goals());
        let out = self.worker.act(obs, &marks, &ctl.worker_state, train);
        let probs = tch::no_grad(|| out.logits.softmax(-1, tch::Kind::Float));
        let choices = crate::seeding::sample_categorical(&mut ctl.rng, &probs, greedy);
        let mut actions: Vec<u8> = choices.iter().map(|&i| self.actions[i as usize]).collect();
        // Only object goals are judged on the objects under the goals.
        let goal_objects = if self.cfg.object_goals {
            ctl.goals()
                .enumerate()
                .map(|(e, g)| {
                    let grid = obs.env_cells(e);
                    let at = |c: u32| (c, grid.get(c as usize).copied().unwrap_or(0));
                    [at(g.wide), at(g.narrow)]
                })
                .collect()
        } else {
            Vec::new()
        };
        let traversals: Vec<Option<&Traversal>> =
            ctl.envs.iter().map(|c| c.traversal.as_ref()).collect();
        let steered = self.traverser.actions(
            &traversals,
            &mut ctl.steer_state,
            &mut ctl.rng,
            obs,
            &mut actions,
            train,
        )?;
        Ok(Acted {
            actions,
            choices,
            goal_objects,
            state: out.state,
            steered,
        })
    }

    /// One environment step of the whole batch (module docs). With
    /// `train`, the step is recorded in the rollout and the decision
    /// queues; `trace` follows the traced environment.
    pub(super) fn step_batch(
        &mut self,
        ctl: &mut Controller,
        env: &mut dyn BatchEnvironment,
        train: bool,
        mut trace: Option<&mut Tracing<'_>>,
        stats: &mut StepCounts,
    ) -> Result<(), LearnerError> {
        let n = env.num_envs();
        let (acted, balls_before) = {
            let obs = env.observe();
            let before = super::controller::balls_before_batch(
                obs.meta,
                train && (self.cfg.ball_shaping > 0.0 || self.cfg.worker_ball_reward > 0.0),
            );
            (
                self.act(ctl, &obs, train, trace.as_deref_mut(), stats)?,
                before,
            )
        };
        let traversing: Vec<bool> = ctl.envs.iter().map(|c| c.traversal.is_some()).collect();
        // The steered legs before the step (for π_g's fine-tuning).
        let legs_before: Vec<Option<usize>> = ctl
            .envs
            .iter()
            .map(|c| {
                c.traversal
                    .as_ref()
                    .filter(|t| t.execution() == Execution::Steer)
                    .map(Traversal::leg)
            })
            .collect();
        let t1 = std::time::Instant::now();
        env.step(&acted.actions)?;
        self.times.step += t1.elapsed().as_secs_f64();
        let obs = env.observe();
        let mut book = StepBook::new(n);
        for e in 0..n {
            let m = &obs.meta[e];
            let end = EpisodeEnd::of(m);
            let ended = end.ended();
            // Where the action led the agent: on a step that ended the
            // episode, its final cell (the observation is the next start).
            let cell = obs.end_cell(e);
            stats.count_step(&obs, e, ended);
            if let Some(t) = trace.as_deref_mut() {
                t.step(&obs, e, acted.actions[e], cell, traversing[e], ended);
            }
            // The count-based exploration bonus (training only).
            let bonus = if train && self.cfg.count_bonus > 0.0 {
                let cells = obs.env_cells(e).len();
                ctl.visits.bonus(
                    e,
                    n,
                    cell,
                    cells,
                    self.cfg.count_bonus,
                    self.cfg.count_bonus_fade,
                )
            } else {
                0.0
            };
            let shaping = if train && self.cfg.ball_shaping > 0.0 {
                super::controller::ball_shaping(
                    self.cfg.ball_shaping,
                    self.cfg.manager.gamma,
                    balls_before[e],
                    m,
                )
            } else {
                0.0
            };
            let mut interval_over = ended;
            if train {
                ctl.book_manager_reward(e, m.reward + bonus + shaping);
            }
            if traversing[e] {
                stats.traversal_steps += 1;
                book.dones[e] = true;
                let c = &mut ctl.envs[e];
                let s = traversal::book_step(
                    &mut c.traversal,
                    &mut c.goal,
                    cell,
                    ended,
                    self.horizon,
                    legs_before[e],
                    self.traverser.end_window(),
                );
                book.legs[e] = s.leg;
                stats.reached += usize::from(s.reached);
                interval_over |= s.interval_over;
            } else {
                let arrival = if self.cfg.object_goals {
                    let grid = if ended {
                        obs.env_final_cells(e)
                    } else {
                        obs.env_cells(e)
                    };
                    let before = acted.goal_objects[e];
                    let after = before.map(|(c, o)| grid.get(c as usize).copied().unwrap_or(o));
                    Arrival::of_step(cell, before, after)
                } else {
                    Arrival::walked(cell)
                };
                let s = self.book_worker_step(ctl, &obs, e, arrival, end);
                stats.reached += usize::from(s.reached);
                interval_over |= s.interval_over;
                if s.bootstrap {
                    book.cut_worker.push(e);
                }
                // FeUdal's `r^I + α r`: the task's own payoffs, not its
                // step penalty (the Worker pays its own).
                book.rewards[e] =
                    s.reward + self.cfg.worker_task_share * (m.reward - sim::task::STEP_PENALTY);
                if train && self.cfg.worker_ball_reward > 0.0 {
                    let collected = super::controller::balls_collected(balls_before[e], m);
                    book.rewards[e] += self.cfg.worker_ball_reward * f32::from(collected);
                }
                book.dones[e] = s.done;
                book.weights[e] = 1.0;
            }
            if interval_over && book.legs[e] == Leg::Going {
                book.legs[e] = Leg::Ended;
            }
            if interval_over {
                stats.intervals += 1;
                book.dones[e] = true;
                if ctl.end_interval(e, ended, train) && end == EpisodeEnd::Truncated {
                    book.cut_manager.push(e);
                }
            }
        }
        if train {
            // Truncation is not termination (Gymnasium's final_obs): the
            // cut steps' targets go on from their final states' values.
            if !book.cut_worker.is_empty() {
                let marks = self.worker.goal_marks(ctl.goals());
                self.worker.bootstrap_truncated(
                    &mut book.rewards,
                    &obs,
                    &marks,
                    &acted.state,
                    &book.cut_worker,
                    self.cfg.worker.gamma,
                );
            }
            if !book.cut_manager.is_empty() {
                self.manager.bootstrap_cut(ctl, &obs, &book.cut_manager);
            }
            self.worker.learner.rollout.record(
                &self.recorded(&acted),
                &book.rewards,
                &book.dones,
                &book.weights,
            );
        }
        if acted.steered {
            self.traverser.book_steered(&acted.actions, &book.legs);
        }
        ctl.worker_state = acted.state.reset_done(&mask(&book.dones));
        Ok(())
    }

    /// The policy output the rollout records for each environment: that of
    /// the action taken (a traversal's too, recorded with weight 0), or the
    /// Worker's sample where the taken action is none of its outputs.
    fn recorded(&self, acted: &Acted) -> Vec<u8> {
        acted
            .actions
            .iter()
            .zip(&acted.choices)
            .map(|(&a, &choice)| {
                self.actions
                    .iter()
                    .position(|&b| b == a)
                    .map_or(choice, |i| i as u8)
            })
            .collect()
    }

    /// Books the Worker's step in environment `e` of `obs`, which led the
    /// agent to `cell` with the episode's state `end`; where the interval
    /// goes on and a traversal towards `g_w` can start from there, the
    /// Worker hands over to it (section 4.3), paid as [`HandOver`] says.
    fn book_worker_step(
        &mut self,
        ctl: &mut Controller,
        obs: &ObsView<'_>,
        e: usize,
        arrival: Arrival,
        end: EpisodeEnd,
    ) -> WorkerStep {
        let c = &mut ctl.envs[e];
        let was_paid = c.goal.wide_paid;
        let mut s = c.goal.book_arrival(
            arrival,
            end,
            self.horizon,
            self.cfg.goal_reward,
            self.cfg.step_penalty,
            self.cfg.worker_task_end,
        );
        if self.cfg.narrow_pays_wide {
            c.goal
                .narrow_pays_wide(&mut s, was_paid, self.cfg.goal_reward);
        }
        if !s.interval_over && self.traverser.try_start(&c.goal, &mut c.traversal, obs, e) {
            let pay = match self.cfg.hand_over {
                HandOver::PaysWideGoal => self.cfg.goal_reward,
                HandOver::Unpaid => 0.0,
            };
            if c.traversal.as_ref().is_some_and(Traversal::stops_in_front) {
                // Towards an object goal: the route ends facing it, and the
                // Worker is paid when it acts on it, not for the hand-over.
                s.done = true;
            } else {
                c.goal.hand_over(&mut s, pay);
            }
        }
        s
    }

    /// One training iteration: a rollout of `T` steps, then the Worker's
    /// and the Manager's updates.
    pub fn train_iteration(
        &mut self,
        env: &mut dyn BatchEnvironment,
    ) -> Result<IterationStats, LearnerError> {
        check_batch(self.cfg.envs, env)?;
        let empty = self.controller(0, 0);
        let mut ctl = std::mem::replace(&mut self.ctl, empty);
        self.worker.learner.rollout.start(&ctl.worker_state);
        self.traverser.start_fine_tuning(ctl.steer_state.as_ref());
        let mut counts = StepCounts::for_task(self.task);
        for _ in 0..self.cfg.rollout_len {
            self.step_batch(&mut ctl, env, true, None, &mut counts)?;
        }
        {
            let obs = env.observe();
            counts.add(self.manager.decide(&mut ctl, &obs, true, false, None));
            let marks = self.worker.goal_marks(ctl.goals());
            self.worker.bootstrap(&obs, &marks, &ctl.worker_state);
            self.traverser
                .fine_tune(&obs, &ctl.traversals(), ctl.steer_state.as_ref());
        }
        let worker = self
            .worker
            .learner
            .update(&self.cfg.worker, &mut self.times);
        let manager = self
            .manager
            .update(&mut ctl, &self.cfg.manager, &mut self.times);
        ctl.detach();
        self.ctl = ctl;
        Ok(counts.iteration(worker, manager))
    }

    /// Plays one episode in every environment of `env` (freshly reset)
    /// with actions sampled from the policy (RNG seeded by `seed`), without
    /// training; `trace` records environment 0's episode.
    pub fn evaluate(
        &mut self,
        env: &mut dyn BatchEnvironment,
        seed: u64,
        trace: Option<&mut EpisodeTrace>,
    ) -> Result<EvalResult, LearnerError> {
        let mut ctl = self.controller(env.num_envs(), sim::env_seed(seed ^ EVAL_SALT, 0));
        let (task, width) = (self.task, self.width);
        play_episodes(env, task, width, trace, |env, traced, counts| {
            self.step_batch(&mut ctl, env, false, traced, counts)
        })
    }
}
