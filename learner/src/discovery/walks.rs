//! Step 1 of a round: random walks from the agent's start state and from
//! the pivotal states, reached by replaying the action path recorded the
//! first time the agent got there (section 3.2: "the agent records the
//! paths it took"; the recorded paths have their loops erased,
//! [`LoopErasedRoute`]).

use rand::Rng;
use rand::rngs::SmallRng;
use sim::{action, flags};

use super::Discovery;
use crate::batch_env::{BatchEnvironment, EnvError};
use crate::vae::{AgentPose, Trajectory};

/// The pose the latent model reads from an observation record (the one
/// constructor every trajectory source uses, [`AgentPose::from_meta`]).
pub fn pose_of(m: &sim::EnvMeta, width: usize) -> AgentPose {
    AgentPose::from_meta(m, width)
}

enum Phase {
    NeedReset,
    Replay { path: Vec<u8>, next: usize },
    Walk { left: u32 },
}

struct Walker {
    phase: Phase,
    /// The way from the start to the agent's pose, loops erased.
    route: LoopErasedRoute,
    /// The action whose outcome the next observation shows (`None` after a
    /// reset).
    pending: Option<u8>,
    /// The walk started with a replay whose trajectory is not emitted yet.
    replayed: bool,
    states: Vec<AgentPose>,
    actions: Vec<u8>,
}

/// The actions since the last reset with every loop erased: whenever the
/// agent comes back to a pose (cell and facing) it had, the actions in
/// between are dropped. In a maze with deterministic dynamics the result
/// still leads from the start to the same pose, and it is never longer
/// than what was walked, so recorded paths approach the agent's shortest
/// known routes (its own experience: no map is consulted). Their replays
/// are goal-directed trajectories, which the latent model needs: uniformly
/// random actions are unpredictable between any kept states, so on them
/// alone it learns to keep none.
#[derive(Debug, Default)]
pub(super) struct LoopErasedRoute {
    poses: Vec<AgentPose>,
    actions: Vec<u8>,
    index: std::collections::HashMap<AgentPose, usize>,
}

impl LoopErasedRoute {
    pub(super) fn reset(&mut self, start: AgentPose) {
        self.poses.clear();
        self.actions.clear();
        self.index.clear();
        self.poses.push(start);
        self.index.insert(start, 0);
    }

    fn clear(&mut self) {
        self.poses.clear();
        self.actions.clear();
        self.index.clear();
    }

    /// `action` led to `pose`.
    pub(super) fn push(&mut self, action: u8, pose: AgentPose) {
        if self.poses.is_empty() {
            return; // not started since the last episode end
        }
        if let Some(&i) = self.index.get(&pose) {
            for p in self.poses.drain(i + 1..) {
                self.index.remove(&p);
            }
            self.actions.truncate(i);
        } else {
            self.actions.push(action);
            self.poses.push(pose);
            self.index.insert(pose, self.poses.len() - 1);
        }
    }

    pub(super) fn trajectory(&self) -> Trajectory {
        Trajectory {
            states: self.poses.clone(),
            actions: self.actions.clone(),
        }
    }
}

impl Discovery {
    /// Step 1: random walks from the start and from pivotal states.
    ///
    /// Each environment runs a small state machine: reset to the start;
    /// then either replay the recorded path to a random pivotal state or
    /// not; then `walk_len` uniformly random actions, recorded as a
    /// trajectory. Every step first records the outcome of the previous
    /// action (the observed pose), then picks the next action. The first
    /// time a cell is reached, or by a shorter path, the actions since the
    /// reset are recorded as the way back to it.
    pub(super) fn collect_walks(
        &mut self,
        env: &mut dyn BatchEnvironment,
        rng: &mut SmallRng,
    ) -> Result<(Vec<Trajectory>, u64), EnvError> {
        let cfg = self.state.config.clone();
        let n = env.num_envs();
        let width = env.observe().width;
        let num_actions = env.num_actions() as u8;
        let mut walkers: Vec<Walker> = (0..n)
            .map(|_| Walker {
                phase: Phase::NeedReset,
                route: LoopErasedRoute::default(),
                pending: None,
                replayed: false,
                states: Vec::new(),
                actions: Vec::new(),
            })
            .collect();
        let mut out = Vec::new();
        let mut actions = vec![0u8; n];
        let steps = cfg.walk_steps_per_round as u64;
        for _ in 0..steps {
            let obs = env.observe();
            for (i, w) in walkers.iter_mut().enumerate() {
                let m = obs.meta[i];
                let pose = pose_of(&m, width);
                // An ended episode auto-reset: the agent is back at the start
                // and the last action's outcome is lost.
                let ended = m.flags & flags::DONE != 0;
                if ended {
                    w.route.clear();
                    w.pending = None;
                    w.replayed = false;
                } else {
                    match w.pending.take() {
                        None => w.route.reset(pose),
                        Some(a) => {
                            if let Some(&before) = w.route.poses.last()
                                && cfg.records_experience()
                            {
                                self.state.experience.observe(before, a, pose);
                            }
                            w.route.push(a, pose);
                        }
                    }
                }
                let awaiting_outcome = !w.actions.is_empty() && w.states.len() == w.actions.len();
                if awaiting_outcome {
                    if ended {
                        w.actions.pop();
                    } else {
                        w.states.push(pose);
                    }
                }
                if ended || (awaiting_outcome && matches!(w.phase, Phase::Walk { left: 0 })) {
                    finish(w, &mut out);
                    w.phase = Phase::NeedReset;
                }
                if !ended {
                    *self.state.visits.entry(pose.cell).or_default() += 1;
                    let known = self
                        .state
                        .paths
                        .get(&pose.cell)
                        .map_or(usize::MAX, Vec::len);
                    if w.route.actions.len() < known && !w.route.poses.is_empty() {
                        self.state.paths.insert(pose.cell, w.route.actions.clone());
                    }
                }
                actions[i] = match &mut w.phase {
                    Phase::NeedReset => {
                        w.route.clear();
                        w.pending = None;
                        let pivot = (!self.state.pivotal.is_empty()
                            && rng.random_bool(cfg.from_pivotal))
                        .then(|| self.state.pivotal[rng.random_range(0..self.state.pivotal.len())]);
                        w.phase = match pivot.and_then(|p| self.state.paths.get(&p)) {
                            Some(path) if !path.is_empty() => {
                                w.replayed = true;
                                Phase::Replay {
                                    path: path.clone(),
                                    next: 0,
                                }
                            }
                            _ => Phase::Walk { left: cfg.walk_len },
                        };
                        action::RESET
                    }
                    Phase::Replay { path, next } => {
                        let a = path[*next];
                        *next += 1;
                        if *next == path.len() {
                            w.phase = Phase::Walk { left: cfg.walk_len };
                        }
                        w.pending = Some(a);
                        a
                    }
                    Phase::Walk { left } => {
                        if w.actions.is_empty() {
                            w.states.clear();
                            w.states.push(pose);
                        }
                        // The replay just ended here: its (loop-erased,
                        // goal-directed) trajectory is training data too.
                        if std::mem::take(&mut w.replayed) && w.route.actions.len() >= 2 {
                            out.push(w.route.trajectory());
                        }
                        let a = rng.random_range(0..num_actions);
                        w.actions.push(a);
                        w.pending = Some(a);
                        *left -= 1;
                        a
                    }
                };
            }
            env.step(&actions)?;
        }
        Ok((out, steps * n as u64))
    }
}

fn finish(w: &mut Walker, out: &mut Vec<Trajectory>) {
    if !w.actions.is_empty() && w.states.len() == w.actions.len() + 1 {
        out.push(Trajectory {
            states: std::mem::take(&mut w.states),
            actions: std::mem::take(&mut w.actions),
        });
    }
    w.states.clear();
    w.actions.clear();
}
