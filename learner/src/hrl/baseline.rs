//! The A2C baseline (Shang et al. 2019, section 4.1), top to bottom: one
//! A2C-LSTM on the task's observation and actions (left, right, forward
//! for the MultiGoal tasks; pick and open too for Door-Key), trained on
//! the task's own rewards. No Manager, no goals, no world graph.
//!
//! A training iteration ([`A2cAgent::train_iteration`]):
//!
//! 1. for `T` steps, the network acts on every environment of the batch
//!    from its LSTM core, an action is sampled from its policy, the
//!    environments step, and the step's reward (the task's, plus the
//!    count-based bonus where it is set) and episode end go into the
//!    rollout; an episode the step limit cut is bootstrapped from its
//!    final state (truncation is not termination);
//! 2. the rollout bootstraps from `V(s_T)`, and the A2C loss over it takes
//!    one optimiser step ([`A2cLearner::update`]).
//!
//! Its network is the Worker's without goal planes and it learns through
//! the same [`A2cLearner`] (rollout storage and loss); its checkpoints name
//! the network `worker/`, as the Worker's are named, so that a run's files
//! read the same whichever agent wrote them.

use std::path::Path;

use serde::{Deserialize, Serialize};
use shm_schemas::EnvMeta;
use sim::{Layout, ReplayRng, RngState, Task};

use super::agent::{EVAL_SALT, SEGMENT_SALT, check_batch, reset_batch};
use super::config::{AgentConfig, AgentKind};
use super::controller::{CoreStates, SavedController, VisitCounts, save_core_states};
use super::reports::{
    EpisodeTrace, EvalResult, IterationStats, StepCounts, Tracing, play_episodes,
};
use crate::a2c::input::mask;
use crate::a2c::learner::{A2cLearner, load_variables, moments_of};
use crate::a2c::net::LstmState;
use crate::a2c::rollout::GradPath;
use crate::a2c::{LossFigures, PhaseTimes};
use crate::batch_env::BatchEnvironment;
use crate::checkpoint::{checkpoint_error, named_tensors_bytes, named_tensors_of};
use crate::error::{ConfigError, LearnerError};

/// The baseline's reward and episode end for a step: the task's reward,
/// and the end of the task's episode.
pub fn task_step(meta: &EnvMeta) -> (f32, bool) {
    (meta.reward, meta.done())
}

/// The flat A2C agent (module docs).
pub struct A2cAgent {
    cfg: AgentConfig,
    task: Task,
    width: usize,
    /// The environment action of each policy output
    /// ([`AgentConfig::worker_actions`]).
    actions: &'static [u8],
    pub(super) learner: A2cLearner,
    /// What training carries from one iteration to the next.
    carry: Carry,
    seed: u64,
    times: PhaseTimes,
}

impl std::fmt::Debug for A2cAgent {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("A2cAgent")
            .field("cfg", &self.cfg)
            .field("task", &self.task)
            .finish_non_exhaustive()
    }
}

/// What a batch of episodes carries from one step to the next: the LSTM
/// core state, the action RNG and (training) the visit counts of the
/// count-based bonus.
#[derive(Debug)]
struct Carry {
    state: LstmState,
    rng: ReplayRng,
    visits: VisitCounts,
}

impl Carry {
    /// `n` environments at the start of their episodes, the action RNG
    /// seeded by `seed`.
    fn new(n: usize, seed: u64, learner: &A2cLearner) -> Carry {
        Carry {
            state: learner.net.zero_state(n as i64),
            rng: ReplayRng::seed_from_u64(seed),
            visits: VisitCounts::default(),
        }
    }
}

/// What of a [`Carry`] is not a tensor, as a checkpoint saves it (a
/// hierarchy's controller record has more fields, which it ignores).
#[derive(Debug, Serialize, Deserialize)]
struct CarryRecord {
    rng: RngState,
    #[serde(default, skip_serializing_if = "VisitCounts::is_empty")]
    visits: VisitCounts,
}

impl A2cAgent {
    /// A fresh baseline for `task` on `layout`, its weights drawn from
    /// `seed`.
    pub fn new(
        cfg: &AgentConfig,
        layout: &Layout,
        task: Task,
        seed: u64,
    ) -> Result<Self, LearnerError> {
        cfg.validate()?;
        if cfg.kind != AgentKind::A2c {
            return Err(ConfigError::new("kind", "the flat A2C agent is the A2C baseline").into());
        }
        let actions = cfg.worker_actions(task);
        let learner = crate::seeding::init_seeded(seed, || {
            A2cLearner::new(
                &cfg.network(actions.len()),
                layout.width,
                layout.height,
                "worker",
                cfg.worker.learning_rate,
                cfg.grad_path,
                cfg.envs,
            )
        });
        let carry = Carry::new(cfg.envs, seed, &learner);
        Ok(A2cAgent {
            cfg: cfg.clone(),
            task,
            width: layout.width,
            actions,
            learner,
            carry,
            seed,
            times: PhaseTimes::default(),
        })
    }

    /// The configuration.
    pub fn config(&self) -> &AgentConfig {
        &self.cfg
    }

    /// Chooses the gradient path of the update.
    pub fn set_grad_path(&mut self, path: GradPath) {
        self.learner.set_grad_path(path, self.cfg.envs);
    }

    /// Starts training segment `segment`: every environment starts a new
    /// episode, and the core state and the action RNG start afresh from
    /// `(seed, segment)` (as [`super::HrlAgent::start_segment`]).
    pub fn start_segment(
        &mut self,
        env: &mut dyn BatchEnvironment,
        segment: u64,
    ) -> Result<(), LearnerError> {
        let n = reset_batch(self.cfg.envs, env)?;
        self.carry = Carry::new(
            n,
            sim::env_seed(self.seed ^ SEGMENT_SALT, segment),
            &self.learner,
        );
        Ok(())
    }

    /// One training iteration (module docs).
    pub fn train_iteration(
        &mut self,
        env: &mut dyn BatchEnvironment,
    ) -> Result<IterationStats, LearnerError> {
        check_batch(self.cfg.envs, env)?;
        let mut carry = std::mem::replace(&mut self.carry, Carry::new(0, 0, &self.learner));
        self.learner.rollout.start(&carry.state);
        let mut counts = StepCounts::for_task(self.task);
        for _ in 0..self.cfg.rollout_len {
            self.step_batch(&mut carry, env, true, None, &mut counts)?;
        }
        self.learner.bootstrap(&env.observe(), None, &carry.state);
        let losses = self.learner.update(&self.cfg.worker, &mut self.times);
        carry.state = carry.state.detach();
        self.carry = carry;
        Ok(counts.iteration(losses, LossFigures::default()))
    }

    /// One step of every environment of `env`: act, step, and (with
    /// `train`) record the step in the rollout; `trace` follows the traced
    /// environment.
    fn step_batch(
        &mut self,
        carry: &mut Carry,
        env: &mut dyn BatchEnvironment,
        train: bool,
        mut trace: Option<&mut Tracing<'_>>,
        stats: &mut StepCounts,
    ) -> Result<(), LearnerError> {
        let n = env.num_envs();
        let (choices, state, balls_before) = {
            let obs = env.observe();
            let before = super::controller::balls_before_batch(
                obs.meta,
                train && self.cfg.ball_shaping > 0.0,
            );
            let out = self.learner.act(&obs, None, &carry.state, train);
            let probs = tch::no_grad(|| out.logits.softmax(-1, tch::Kind::Float));
            let greedy = self.cfg.eval_actions.greedy(train);
            let choices = crate::seeding::sample_categorical(&mut carry.rng, &probs, greedy);
            (choices, out.state, before)
        };
        let actions: Vec<u8> = choices.iter().map(|&i| self.actions[i as usize]).collect();
        let t = std::time::Instant::now();
        env.step(&actions)?;
        self.times.step += t.elapsed().as_secs_f64();
        let obs = env.observe();
        let (mut rewards, mut dones, mut cut) = (vec![0f32; n], vec![false; n], Vec::new());
        for e in 0..n {
            let m = &obs.meta[e];
            let cell = obs.end_cell(e);
            stats.count_step(&obs, e, m.done());
            if let Some(t) = trace.as_deref_mut() {
                t.step(&obs, e, actions[e], cell, false, m.done());
            }
            (rewards[e], dones[e]) = task_step(m);
            if train && self.cfg.count_bonus > 0.0 {
                let cells = obs.env_cells(e).len();
                rewards[e] += carry.visits.bonus(
                    e,
                    n,
                    cell,
                    cells,
                    self.cfg.count_bonus,
                    self.cfg.count_bonus_fade,
                );
            }
            if train && self.cfg.ball_shaping > 0.0 {
                rewards[e] += super::controller::ball_shaping(
                    self.cfg.ball_shaping,
                    self.cfg.worker.gamma,
                    balls_before[e],
                    m,
                );
            }
            if m.truncated() {
                cut.push(e);
            }
        }
        if train {
            if !cut.is_empty() {
                let gamma = self.cfg.worker.gamma;
                self.learner
                    .bootstrap_truncated(&mut rewards, &obs, None, &state, &cut, gamma);
            }
            self.learner
                .rollout
                .record(&choices, &rewards, &dones, &vec![1.0; n]);
        }
        carry.state = state.reset_done(&mask(&dones));
        Ok(())
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
        let seed = sim::env_seed(seed ^ EVAL_SALT, 0);
        let mut carry = Carry::new(env.num_envs(), seed, &self.learner);
        play_episodes(env, self.task, self.width, trace, |env, traced, counts| {
            self.step_batch(&mut carry, env, false, traced, counts)
        })
    }

    /// The training state — core state, action RNG, visit counts — as a
    /// record (JSON) and a tensor file, saved with a checkpoint so that a
    /// resumed run goes on exactly where it stopped.
    pub fn save_controller(&self) -> Result<SavedController, LearnerError> {
        let record = CarryRecord {
            rng: self.carry.rng.state(),
            visits: self.carry.visits.clone(),
        };
        let json = serde_json::to_vec(&record).map_err(|e| checkpoint_error("controller", e))?;
        Ok(SavedController {
            record: json,
            tensors: save_core_states(&[("worker", Some(&self.carry.state))])?,
        })
    }

    /// Restores [`Self::save_controller`]'s record and tensors; `source`
    /// names them in errors.
    pub fn load_controller(
        &mut self,
        json: &[u8],
        tensors: &[u8],
        source: &Path,
    ) -> Result<(), LearnerError> {
        let bad = |message: String| checkpoint_error(source, message);
        let record: CarryRecord = serde_json::from_slice(json).map_err(|e| bad(e.to_string()))?;
        let state = CoreStates::load(tensors)
            .and_then(|s| s.get("worker"))
            .map_err(bad)?
            .ok_or_else(|| bad("no core state".into()))?;
        if state.h.size() != self.carry.state.h.size()
            || !(record.visits.is_empty() || record.visits.envs() == self.cfg.envs)
        {
            return Err(bad("the controller is of another agent or batch".into()));
        }
        self.carry = Carry {
            state,
            rng: ReplayRng::from_state(record.rng),
            visits: record.visits,
        };
        Ok(())
    }

    /// Where training time went since the last call.
    pub fn take_times(&mut self) -> PhaseTimes {
        let mut t = std::mem::take(&mut self.times);
        t.add(&std::mem::take(&mut self.learner.rollout.times));
        t
    }

    /// Model FLOPs per env-step of the update path.
    pub fn flops_per_env_step(&self) -> f64 {
        crate::a2c::net::flops_per_env_step(self.learner.net.trunk(), self.actions.len() as i64)
    }

    /// The weights and optimiser moments as bytes (a checkpoint's tensor
    /// file).
    pub fn to_bytes(&self) -> Result<Vec<u8>, LearnerError> {
        let mut named = self.learner.weights("worker");
        named.extend(self.learner.moments("worker"));
        named_tensors_bytes(&named)
    }

    /// Restores [`Self::to_bytes`]; `source` names the input in errors.
    pub fn load_bytes(&mut self, bytes: &[u8], source: &Path) -> Result<(), LearnerError> {
        let bad = |message: String| checkpoint_error(source, message);
        let loaded = named_tensors_of(bytes, source)?;
        load_variables("worker", &self.learner.vs, &loaded).map_err(bad)?;
        self.learner
            .opt
            .load_state(&moments_of("worker", &loaded))
            .map_err(bad)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::batch_env::InProcess;
    use shm_schemas::flags;
    use sim::{EnvConfig, Maze};

    /// A small baseline with the count-based bonus on, and its batch.
    fn agent_and_env(seed: u64) -> (A2cAgent, InProcess) {
        let layout = Maze::Small.layout(false);
        let cfg = AgentConfig {
            kind: AgentKind::A2c,
            envs: 4,
            rollout_len: 8,
            hidden: 16,
            conv_channels: [4, 8],
            count_bonus: 0.1,
            ..AgentConfig::default()
        };
        let env_cfg = EnvConfig {
            max_steps: 12,
            ..EnvConfig::for_task(Task::MultiGoal, &layout)
        };
        let env = InProcess::new(layout.clone(), env_cfg, 4, 7, 1).expect("env");
        (
            A2cAgent::new(&cfg, &layout, Task::MultiGoal, seed).expect("agent"),
            env,
        )
    }

    /// A checkpoint taken between iterations — weights, optimiser moments,
    /// core state, action RNG, visit counts, and the environments' states —
    /// resumes into the run that was not interrupted, and a hierarchy's
    /// controller record (the format before the flat agent) still loads.
    #[test]
    fn a_resumed_baseline_goes_on_as_the_uninterrupted_one() {
        let (mut whole, mut env) = agent_and_env(3);
        whole.start_segment(&mut env, 0).expect("segment");
        for _ in 0..3 {
            whole.train_iteration(&mut env).expect("iteration");
        }
        let weights = whole.to_bytes().expect("bytes");
        let saved = whole.save_controller().expect("controller");
        let envs = env.snapshot().expect("snapshot");
        let after = |agent: &mut A2cAgent, env: &mut InProcess| {
            for _ in 0..3 {
                agent.train_iteration(env).expect("iteration");
            }
            agent.learner.weights("worker")
        };
        let expected = after(&mut whole, &mut env);

        let (mut resumed, mut env2) = agent_and_env(99);
        resumed.start_segment(&mut env2, 0).expect("segment");
        assert!(env2.restore(&envs).expect("restore"));
        resumed
            .load_bytes(&weights, Path::new("weights"))
            .expect("load");
        resumed
            .load_controller(&saved.record, &saved.tensors, Path::new("controller"))
            .expect("load controller");
        assert_eq!(resumed.save_controller().expect("again"), saved);
        let got = after(&mut resumed, &mut env2);
        assert_eq!(got.len(), expected.len());
        for ((k, a), (_, b)) in got.iter().zip(&expected) {
            assert!(a.equal(b), "{k} differs after the resume");
        }

        // A hierarchy's controller record has the Manager's fields too.
        let mut record: serde_json::Value = serde_json::from_slice(&saved.record).unwrap();
        record["envs"] = serde_json::json!([]);
        record["queues"] = serde_json::json!([]);
        let old = serde_json::to_vec(&record).unwrap();
        let (mut third, _) = agent_and_env(5);
        third
            .load_controller(&old, &saved.tensors, Path::new("old"))
            .expect("an older record loads");
        // A controller of another batch is refused.
        let cfg = AgentConfig {
            envs: 2,
            ..whole.config().clone()
        };
        let mut other =
            A2cAgent::new(&cfg, &Maze::Small.layout(false), Task::MultiGoal, 5).unwrap();
        let err = other
            .load_controller(&saved.record, &saved.tensors, Path::new("c"))
            .unwrap_err();
        assert!(err.to_string().contains("another agent or batch"), "{err}");
    }

    #[test]
    fn a_hierarchy_kind_is_not_a_flat_agent() {
        let cfg = AgentConfig {
            kind: AgentKind::Feudal,
            ..AgentConfig::default()
        };
        let err = A2cAgent::new(&cfg, &Maze::Small.layout(false), Task::MultiGoal, 0).unwrap_err();
        assert!(err.to_string().contains("A2C baseline"), "{err}");
    }

    #[test]
    fn the_baseline_learns_from_the_task_reward_and_episode() {
        let ball = EnvMeta {
            reward: 0.99,
            ..EnvMeta::EMPTY
        };
        assert_eq!(task_step(&ball), (0.99, false));
        let exit = EnvMeta {
            reward: 0.99,
            flags: flags::TERMINATED | flags::RESET,
            ..EnvMeta::EMPTY
        };
        assert_eq!(task_step(&exit), (0.99, true));
        let timeout = EnvMeta {
            reward: -0.01,
            flags: flags::TRUNCATED,
            ..EnvMeta::EMPTY
        };
        assert_eq!(task_step(&timeout), (-0.01, true));
    }
}
