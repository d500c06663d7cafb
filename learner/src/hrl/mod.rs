//! Stage 2 of Shang et al. 2019 (section 4): agents that solve the maze
//! tasks with the world graph of stage 1.
//!
//! - [`a2c`]: the A2C-LSTM baseline (section 4.1);
//! - [`feudal`]: the Feudal Manager on its own time scale (section 4.1);
//! - [`worker`]: the goal-conditioned Worker and its reward;
//! - [`wide_narrow`]: Wide-then-Narrow Manager instructions (section 4.2);
//! - [`traversal`]: world graph traversal (section 4.3);
//! - [`steering`]: `π_g` steering traversals in stochastic worlds, and its
//!   fine-tuning (section 4.3);
//! - [`init`]: initialisation from `π_g` (section 4.4).
//!
//! [`HrlAgent`] runs one of them on a [`BatchEnvironment`]: `A2C`, `FN`
//! (Manager over every valid cell) or `WN` (wide goals from `V_all`,
//! `V_rand` or `V_p`), each optionally initialised from `π_g`, WN
//! optionally with traversal. Training is the A2C core's
//! ([`crate::a2c`]): the Worker (or the baseline) learns from `[T, B]`
//! rollouts, the Manager from its decision queues.
//!
//! A run starts its training stream once ([`HrlAgent::start_segment`]) and
//! carries it across validations; a checkpoint saves the controller
//! ([`HrlAgent::save_controller`]) beside the environments' states, so a
//! resumed run goes on exactly where it stopped.

pub mod a2c;
pub mod config;
mod controller;
pub mod feudal;
pub mod init;
pub mod stats;
pub mod steering;
pub mod traversal;
pub mod wide_narrow;
pub mod worker;

use std::path::Path;

use planner::{Route, WorldGraph};
use shm_schemas::EnvMeta;
use sim::{Layout, ReplayRng, Task, action};
use tch::{Device, Tensor, nn};

use crate::a2c::input::{CellInput, GOAL_CHANNEL, GoalMarks, NO_GOAL, goal_planes, mask};
use crate::a2c::net::{ActorCritic, ActorCriticConfig, LstmState, Trunk};
use crate::a2c::optim::Adam;
use crate::a2c::rollout::{GradPath, Rollout, bootstrap_truncated, bootstrap_values};
use crate::a2c::{LossFigures, PhaseTimes};
use crate::batch_env::{BatchEnvironment, ObsView};
use crate::error::{ConfigError, LearnerError};
use crate::gcp::GoalConditionedPolicy;
pub use config::{AgentConfig, AgentKind, Candidates, HandOver, WorkerTaskEnd, WorldGraphInputs};
use controller::Controller;
pub use controller::SavedController;
use feudal::{Decision, Manager, ManagerHead};
use stats::{Decisions, StepCounts};
pub use stats::{EpisodeTrace, EvalResult, IterationStats};
use steering::{Leg, Steering};
use traversal::{Execution, Progress, Traversal};
use wide_narrow::{WideNarrowHead, Window};
use worker::{EpisodeEnd, WorkerGoal};

/// A stage 2 agent (module docs).
pub struct HrlAgent {
    cfg: AgentConfig,
    task: Task,
    width: usize,
    height: usize,
    num_actions: usize,
    horizon: u32,
    worker_vs: nn::VarStore,
    worker: ActorCritic,
    worker_opt: Adam,
    manager_vs: Option<nn::VarStore>,
    manager: Option<Manager>,
    manager_opt: Option<Adam>,
    /// Wide-goal cells `V` (WN).
    candidates: Vec<u32>,
    window: Option<Window>,
    graph: Option<WorldGraph>,
    gcp: Option<GoalConditionedPolicy>,
    execution: Execution,
    /// `π_g`'s fine-tuning while it steers traversals (training only).
    steering: Option<Steering>,
    ctl: Controller,
    rollout: Rollout,
    seed: u64,
    route: Route,
    times: PhaseTimes,
    init_report: Option<init::InitReport>,
}

impl std::fmt::Debug for HrlAgent {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("HrlAgent")
            .field("cfg", &self.cfg)
            .field("task", &self.task)
            .finish_non_exhaustive()
    }
}

/// Salts of the agent's seeds.
const SEGMENT_SALT: u64 = 0x5E6_0000;
const EVAL_SALT: u64 = 0xE7A1_0000;

impl HrlAgent {
    /// A fresh agent for `task` on `layout`, weights initialised from
    /// `seed` (then copied from `π_g` where configured).
    pub fn new(
        cfg: &AgentConfig,
        layout: &Layout,
        task: Task,
        inputs: Option<WorldGraphInputs>,
        seed: u64,
    ) -> Result<HrlAgent, LearnerError> {
        cfg.validate()?;
        let (width, height) = (layout.width, layout.height);
        let num_actions = task.num_actions();
        let inputs = inputs.unwrap_or(WorldGraphInputs {
            graph: None,
            gcp: None,
        });
        if cfg.needs_graph() && inputs.graph.is_none() {
            return Err(ConfigError::new(
                "candidates",
                "WN over V_rand or V_p needs a world graph",
            )
            .into());
        }
        if cfg.init_from_gcp && inputs.gcp.is_none() {
            return Err(ConfigError::new("init_from_gcp", "needs π_g from a discovery run").into());
        }
        let hierarchical = cfg.kind != AgentKind::A2c;
        let net_cfg = ActorCriticConfig {
            conv_channels: cfg.conv_channels,
            hidden: cfg.hidden,
            num_actions: num_actions as i64,
            goal_planes: cfg.goal_planes(),
        };
        let candidates: Vec<u32> = match (cfg.kind, cfg.candidates) {
            (AgentKind::WideNarrow, Candidates::All) => planner::pivotal::v_all(layout)
                .iter()
                .map(|c| c.0)
                .collect(),
            (AgentKind::WideNarrow, _) => inputs
                .graph
                .as_ref()
                .map(|g| g.nodes().iter().map(|c| c.0).collect())
                .unwrap_or_default(),
            _ => Vec::new(),
        };
        let window = (cfg.kind == AgentKind::WideNarrow).then(|| {
            let side = match cfg.window {
                0 => wide_narrow::covering_side(cfg.window_side(width), &candidates, layout),
                n => n,
            };
            Window::new(side, layout)
        });
        let valid_cells: Vec<bool> = {
            let mut v = vec![false; width * height];
            for c in planner::pivotal::v_all(layout) {
                v[c.index()] = true;
            }
            v
        };
        let (worker_vs, worker, manager_vs, manager) = crate::seeding::init_seeded(seed, || {
            let worker_vs = nn::VarStore::new(Device::Cpu);
            let worker = ActorCritic::new(&worker_vs.root(), &net_cfg, width, height);
            let (manager_vs, manager) = if hierarchical {
                let vs = nn::VarStore::new(Device::Cpu);
                let trunk = Trunk::new(
                    &vs.root(),
                    (crate::a2c::input::BASE_CHANNELS) as i64,
                    cfg.conv_channels,
                    cfg.hidden,
                    width,
                    height,
                );
                let m = Manager::new(&vs.root(), trunk, |p, hidden| match cfg.kind {
                    AgentKind::WideNarrow => ManagerHead::WideNarrow(WideNarrowHead::new(
                        p,
                        hidden,
                        candidates.len(),
                        window.as_ref().map_or(1, Window::len),
                    )),
                    _ => Manager::feudal_head(p, hidden, &valid_cells),
                });
                let m = if cfg.goal_map {
                    let cells = (cfg.kind == AgentKind::WideNarrow).then_some(&candidates[..]);
                    m.with_goal_map(&vs.root(), (cfg.conv_channels[0] / 2).max(1), cells)
                } else {
                    m
                };
                (Some(vs), Some(m))
            } else {
                (None, None)
            };
            (worker_vs, worker, manager_vs, manager)
        });
        let mut init_report = None;
        if cfg.init_from_gcp {
            let gcp = inputs.gcp.as_ref().expect("checked above");
            let g = gcp.config();
            if g.conv_channels != cfg.conv_channels || g.hidden != cfg.hidden {
                return Err(ConfigError::new(
                    "init_from_gcp",
                    format!(
                        "π_g has conv {:?} / hidden {}; the agent has {:?} / {}",
                        g.conv_channels, g.hidden, cfg.conv_channels, cfg.hidden
                    ),
                )
                .into());
            }
            let mut report = init::copy_from(
                gcp.var_store(),
                &worker_vs,
                &["encoder", "core", "policy", "value"],
            );
            init::copy_goal_plane(gcp.var_store(), &worker_vs, GOAL_CHANNEL);
            if let Some(vs) = &manager_vs {
                let m = init::copy_from(gcp.var_store(), vs, &["encoder"]);
                report
                    .copied
                    .extend(m.copied.into_iter().map(|n| format!("manager/{n}")));
                report
                    .partial
                    .extend(m.partial.into_iter().map(|n| format!("manager/{n}")));
            }
            init_report = Some(report);
        }
        let worker_opt = Adam::new(&[("worker", &worker_vs)], cfg.worker.learning_rate);
        let manager_opt = manager_vs
            .as_ref()
            .map(|vs| Adam::new(&[("manager", vs)], cfg.manager.learning_rate));
        let execution = if task == Task::MultiGoalStochastic {
            Execution::Steer
        } else {
            Execution::Replay
        };
        if cfg.traversal && execution == Execution::Steer && inputs.gcp.is_none() {
            return Err(ConfigError::new(
                "traversal",
                "MultiGoal-Stochastic traversal is steered by π_g: give a discovery run",
            )
            .into());
        }
        let steering = match &inputs.gcp {
            Some(gcp) if cfg.traversal && execution == Execution::Steer && cfg.fine_tune_pi_g => {
                Some(Steering::new(
                    gcp,
                    cfg.envs,
                    width,
                    height,
                    cfg.goal_reward,
                    cfg.step_penalty,
                ))
            }
            _ => None,
        };
        let mut agent = HrlAgent {
            cfg: cfg.clone(),
            task,
            width,
            height,
            num_actions,
            horizon: cfg.horizon(),
            rollout: Rollout::new(
                GradPath::default(),
                cfg.envs,
                width,
                height,
                cfg.goal_planes(),
            ),
            worker_vs,
            worker,
            worker_opt,
            manager_vs,
            manager,
            manager_opt,
            candidates,
            window,
            graph: if cfg.traversal { inputs.graph } else { None },
            gcp: inputs.gcp,
            execution,
            steering,
            ctl: Controller {
                worker_state: LstmState::zeros(1, 1),
                manager_state: None,
                steer_state: None,
                envs: Vec::new(),
                queues: Vec::new(),
                manager_init: None,
                rng: ReplayRng::seed_from_u64(seed),
            },
            seed,
            route: Route::with_capacity(1024, 64),
            times: PhaseTimes::default(),
            init_report,
        };
        agent.ctl = agent.controller(cfg.envs, seed);
        Ok(agent)
    }

    /// The configuration.
    pub fn config(&self) -> &AgentConfig {
        &self.cfg
    }

    /// What `π_g` initialisation copied.
    pub fn init_report(&self) -> Option<&init::InitReport> {
        self.init_report.as_ref()
    }

    /// The wide-goal candidates `V` (WN).
    pub fn candidates(&self) -> &[u32] {
        &self.candidates
    }

    /// Which free cells can be narrow goals: the coverage of the windows
    /// around `V` (WN).
    pub fn window_coverage(&self) -> Option<wide_narrow::Coverage> {
        self.window.as_ref().map(|w| w.coverage(&self.candidates))
    }

    /// The world graph traversal follows.
    pub fn graph(&self) -> Option<&WorldGraph> {
        self.graph.as_ref()
    }

    /// Chooses the gradient path of the Worker's (or baseline's) update
    /// (the benchmark's plain path is [`GradPath::PerStep`]).
    pub fn set_grad_path(&mut self, path: GradPath) {
        self.rollout = Rollout::new(
            path,
            self.cfg.envs,
            self.width,
            self.height,
            self.cfg.goal_planes(),
        );
    }

    fn hierarchical(&self) -> bool {
        self.manager.is_some()
    }

    fn controller(&self, n: usize, seed: u64) -> Controller {
        Controller::new(
            n,
            seed,
            &self.worker,
            self.manager.as_ref(),
            self.gcp.as_ref(),
        )
    }

    /// The training controller — core states, goals, traversals, the
    /// Manager's decision queues and the action RNG — as a record (JSON)
    /// and a tensor file. Saved with a checkpoint beside the environments'
    /// states, it lets a run resume mid-episode exactly where it stopped,
    /// so that neither validation nor a crash perturbs training.
    pub fn save_controller(&self) -> Result<SavedController, LearnerError> {
        self.ctl.save()
    }

    /// Restores [`Self::save_controller`]'s record and tensors (of an agent
    /// of the same configuration and batch); `source` names them in errors.
    pub fn load_controller(
        &mut self,
        json: &[u8],
        tensors: &[u8],
        source: &Path,
    ) -> Result<(), LearnerError> {
        self.ctl.restore(json, tensors, source, self.cfg.envs)
    }

    /// Starts training segment `segment`: every environment starts a new
    /// episode, and the core states, goals and the action RNG start afresh
    /// from `(seed, segment)`. A run calls it once, at its start (segment
    /// 0); between segments training goes on where it was (validation uses
    /// environments and a controller of its own), and a resumed run
    /// restores its controller ([`Self::load_controller`]) — where the
    /// environments' states cannot be restored (another process owns them),
    /// it starts the segment afresh instead.
    pub fn start_segment(
        &mut self,
        env: &mut dyn BatchEnvironment,
        segment: u64,
    ) -> Result<(), LearnerError> {
        let n = self.check_batch(env)?;
        env.step(&vec![action::RESET; n])?;
        self.ctl = self.controller(n, sim::env_seed(self.seed ^ SEGMENT_SALT, segment));
        Ok(())
    }

    /// The batch's size, which must be the one the agent trains on.
    fn check_batch(&self, env: &dyn BatchEnvironment) -> Result<usize, LearnerError> {
        let n = env.num_envs();
        if n != self.cfg.envs {
            return Err(ConfigError::new(
                "envs",
                format!(
                    "the agent was built for {} environments, the batch has {n}",
                    self.cfg.envs
                ),
            )
            .into());
        }
        Ok(n)
    }

    /// Where training time went since the last call.
    pub fn take_times(&mut self) -> PhaseTimes {
        let mut t = std::mem::take(&mut self.times);
        t.add(&std::mem::take(&mut self.rollout.times));
        t
    }

    /// Model FLOPs per env-step of the Worker's (baseline's) update path,
    /// plus the Manager's forward and backward once per decision (about one
    /// per `c / 2` steps).
    pub fn flops_per_env_step(&self, path: GradPath) -> f64 {
        let worker =
            crate::a2c::net::flops_per_env_step(self.worker.trunk(), self.num_actions as i64, path);
        match &self.manager {
            Some(m) => {
                let (c1, rest) = crate::a2c::net::trunk_macs(m.trunk(), Some(10.0));
                let per_decision = 2.0 * 3.0 * (c1 + rest);
                worker + per_decision / (self.horizon as f64 / 2.0).max(1.0)
            }
            None => worker,
        }
    }

    /// Goal marks of the Worker's input: the subgoal (FN), or `g_w` and
    /// `g_n` on planes of their own (WN), `g_w` only until it is paid (the
    /// Worker is rewarded for it once per interval).
    fn goal_marks(&self, ctl: &Controller) -> Vec<u32> {
        worker_goal_marks(self.cfg.kind, ctl.goals())
    }

    fn slots(&self) -> usize {
        self.cfg.goal_planes()
    }

    /// The Manager decides for every environment that needs a new goal;
    /// with `record`, the decisions join the training queues.
    fn decide(
        &mut self,
        ctl: &mut Controller,
        obs: &ObsView<'_>,
        record: bool,
        trace: &mut Option<(usize, u32, &mut EpisodeTrace)>,
    ) -> Decisions {
        let mut made = Decisions::default();
        let Some(manager) = &self.manager else {
            return made;
        };
        let who: Vec<usize> = (0..ctl.envs.len())
            .filter(|&e| ctl.envs[e].need_decision)
            .collect();
        if who.is_empty() {
            return made;
        }
        let idx = Tensor::from_slice(&who.iter().map(|&e| e as i64).collect::<Vec<_>>());
        let mut input = CellInput::new(self.width, self.height, 0);
        for &e in &who {
            input.push_env(obs, e, None);
        }
        let resets: Vec<bool> = who.iter().map(|&e| ctl.envs[e].manager_reset).collect();
        let state = ctl
            .manager_state
            .as_ref()
            .expect("a Manager has a core state")
            .select(&idx)
            .reset_done(&mask(&resets));
        let step = manager.act(&input, &state);
        let (next, values, h) = (step.state, step.values, step.h);
        let bias = tch::no_grad(|| manager.goal_bias(&input));
        ctl.manager_state
            .as_mut()
            .expect("state")
            .scatter(&idx, &next);
        // Draw the goals.
        let mut picks: Vec<Pick> = Vec::with_capacity(who.len());
        match manager.head() {
            ManagerHead::Feudal { .. } => {
                let pi = manager.feudal_policy(&h, bias.as_ref()).expect("feudal");
                for cell in crate::seeding::sample_index(&mut ctl.rng, &pi.probs()) {
                    picks.push((
                        cell as i64,
                        0,
                        cell as u32,
                        cell as u32,
                        Vec::new(),
                        Vec::new(),
                    ));
                }
            }
            ManagerHead::WideNarrow(head) => {
                let window = self.window.as_ref().expect("WN has a window");
                let wide = crate::seeding::sample_index(
                    &mut ctl.rng,
                    &head.wide(&h, bias.as_ref()).probs(),
                );
                let mut locals = Vec::new();
                let mut valids = Vec::new();
                for (j, &e) in who.iter().enumerate() {
                    let gw = self.candidates[wide[j]];
                    locals.push(window.local_input(obs, e, gw));
                    // The agent's own cell is no goal (reaching means
                    // arriving), unless the window holds nothing else.
                    let mut valid = window.valid(gw);
                    let here = obs.meta[e].cell(self.width) as u32;
                    if let Some(k) = window.slot_of(gw, here)
                        && valid.iter().filter(|&&v| v).count() > 1
                    {
                        valid[k] = false;
                    }
                    valids.push(valid);
                }
                let local = Tensor::from_slice(&locals.concat()).view([who.len() as i64, -1]);
                let valid = Tensor::from_slice(&valids.concat()).view([who.len() as i64, -1]);
                let wide_idx =
                    Tensor::from_slice(&wide.iter().map(|&k| k as i64).collect::<Vec<_>>());
                let narrow = tch::no_grad(|| {
                    crate::seeding::sample_index(
                        &mut ctl.rng,
                        &head.narrow(&h, &wide_idx, &local, &valid).probs(),
                    )
                });
                for j in 0..who.len() {
                    let gw = self.candidates[wide[j]];
                    let gn = window
                        .cell(gw, narrow[j])
                        .expect("a valid slot is inside the grid");
                    picks.push((
                        wide[j] as i64,
                        narrow[j] as i64,
                        gw,
                        gn,
                        std::mem::take(&mut locals[j]),
                        std::mem::take(&mut valids[j]),
                    ));
                }
            }
        }
        for (j, (&e, (wide, narrow, gw, gn, local, valid))) in who.iter().zip(picks).enumerate() {
            let c = &mut ctl.envs[e];
            if record {
                let mut one = CellInput::new(self.width, self.height, 0);
                one.push_env(obs, e, None);
                ctl.queues[e].decisions.push(Decision {
                    input: one,
                    wide,
                    narrow,
                    local,
                    valid,
                    value: values[j],
                    reset_before: c.manager_reset,
                    rewards: Vec::new(),
                    complete: false,
                    episode_ended: false,
                    final_value: None,
                });
            }
            if let Some((te, step, t)) = trace.as_mut()
                && *te == e
            {
                t.goals.push((*step, gw, gn));
            }
            c.need_decision = false;
            c.manager_reset = false;
            c.goal = WorkerGoal::new(gw, gn, obs.meta[e].cell(self.width) as u32);
            made.count += 1;
            let named = obs.env_cells(e).get(gn as usize).copied();
            made.exit_goals += usize::from(named == Some(sim::Object::Exit as u8));
            made.ball_goals += usize::from(named == Some(sim::Object::Ball as u8));
        }
        // A fresh goal episode for the Worker.
        let fresh: Vec<bool> = (0..ctl.envs.len()).map(|e| who.contains(&e)).collect();
        ctl.worker_state = ctl.worker_state.reset_done(&mask(&fresh));
        made
    }

    /// Starts a traversal for environment `e` if it stands on a node with a
    /// route to its wide goal (and `g_w` is not paid for yet).
    fn try_traverse(&mut self, ctl: &mut Controller, obs: &ObsView<'_>, e: usize) -> bool {
        let Some(graph) = &self.graph else {
            return false;
        };
        let c = &ctl.envs[e];
        if c.traversal.is_some() || c.goal.wide_paid || c.goal.wide == NO_GOAL {
            return false;
        }
        match Traversal::plan(graph, obs, e, c.goal.wide, self.execution, &mut self.route) {
            Some(t) => {
                ctl.envs[e].traversal = Some(t);
                true
            }
            None => false,
        }
    }

    /// Actions for the environments under traversal: the recorded action
    /// (replay) or `π_g`'s step towards the next node (steer): sampled and
    /// recorded for its fine-tuning when `train` and fine-tuning is on,
    /// greedy otherwise. Returns whether the step was recorded.
    fn traversal_actions(
        &mut self,
        ctl: &mut Controller,
        obs: &ObsView<'_>,
        actions: &mut [u8],
        train: bool,
    ) -> Result<bool, LearnerError> {
        let mut steer = false;
        let mut recorded = false;
        for (e, c) in ctl.envs.iter().enumerate() {
            if let Some(t) = &c.traversal {
                match t.execution() {
                    Execution::Replay => {
                        actions[e] = t
                            .next_action()
                            .expect("a traversal under way has an action")
                    }
                    Execution::Steer => steer = true,
                }
            }
        }
        if steer {
            let gcp = self.gcp.as_mut().expect("steered traversal has π_g");
            let (goals, fresh) = steer_targets(ctl);
            let state = ctl
                .steer_state
                .as_ref()
                .expect("steer state")
                .reset_done(&mask(&fresh));
            let (chosen, next) = match self.steering.as_mut().filter(|_| train) {
                Some(steering) => {
                    let (logits, next) = steering.act(gcp, obs, &goals, &state);
                    let probs = tch::no_grad(|| logits.softmax(-1, tch::Kind::Float));
                    recorded = true;
                    (
                        crate::seeding::sample_categorical(&mut ctl.rng, &probs, false),
                        next,
                    )
                }
                None => {
                    gcp.greedy_step(obs, &goals, &state)
                        .map_err(|e| LearnerError::Checkpoint {
                            path: "π_g".into(),
                            message: e.to_string(),
                        })?
                }
            };
            ctl.steer_state = Some(next);
            for (e, c) in ctl.envs.iter().enumerate() {
                if c.traversal
                    .as_ref()
                    .is_some_and(|t| t.execution() == Execution::Steer)
                {
                    // π_g was trained on the navigation actions.
                    actions[e] = chosen[e].min(action::FORWARD);
                }
            }
        }
        Ok(recorded)
    }

    /// One environment step of the whole batch: Manager decisions,
    /// traversal hand-overs, the Worker's (baseline's) actions, the step,
    /// and its booking. With `train`, the step is recorded in the rollout
    /// and the decision queues. Returns per-environment `(worker reward,
    /// worker done, worker weight)` and the step's `(episode ended, return,
    /// traversed)` figures.
    fn step_batch(
        &mut self,
        ctl: &mut Controller,
        env: &mut dyn BatchEnvironment,
        train: bool,
        mut trace: Option<(usize, u32, &mut EpisodeTrace)>,
        stats: &mut StepCounts,
    ) -> Result<(), LearnerError> {
        let n = env.num_envs();
        let steered;
        let (actions, out_state) = {
            let obs = env.observe();
            stats.add(self.decide(ctl, &obs, train, &mut trace));
            if self.graph.is_some() {
                for e in 0..n {
                    self.try_traverse(ctl, &obs, e);
                }
            }
            let goals = self.goal_marks(ctl);
            let marks = self.hierarchical().then(|| GoalMarks {
                cells: &goals,
                per_env: self.slots(),
            });
            let out = if train {
                self.rollout
                    .act(&self.worker, &obs, marks, &ctl.worker_state)
            } else {
                let mut input = CellInput::new(self.width, self.height, goal_planes(marks));
                input.push_obs(&obs, marks);
                tch::no_grad(|| self.worker.step(&input, &ctl.worker_state))
            };
            let probs = tch::no_grad(|| out.logits.softmax(-1, tch::Kind::Float));
            let mut actions = crate::seeding::sample_categorical(&mut ctl.rng, &probs, false);
            steered = self.traversal_actions(ctl, &obs, &mut actions, train)?;
            (actions, out.state)
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
        let mut legs = vec![Leg::Idle; n];
        let t1 = std::time::Instant::now();
        env.step(&actions)?;
        self.times.step += t1.elapsed().as_secs_f64();
        let obs = env.observe();
        let mut rewards = vec![0f32; n];
        let mut dones = vec![false; n];
        let mut weights = vec![0f32; n];
        // Worker (baseline) steps and Manager intervals cut by the
        // episode's step limit: bootstrapped from their final states.
        let mut cut_worker: Vec<usize> = Vec::new();
        let mut cut_manager: Vec<usize> = Vec::new();
        for e in 0..n {
            let m: &EnvMeta = &obs.meta[e];
            let end = EpisodeEnd::of(m);
            let ended = end.ended();
            // Where the action led the agent: on a step that ended the
            // episode, its final cell (the observation is the next start).
            let cell = obs.end_cell(e);
            if ended {
                stats.episodes += 1;
                stats.returns += f64::from(m.episode_return);
                stats.successes += usize::from(reached_exit(&obs, e));
            }
            stats.steps += 1;
            if let Some((te, step, t)) = trace.as_mut()
                && *te == e
            {
                t.cells.push(cell);
                t.traversed.push(traversing[e]);
                *step += 1;
                if ended {
                    let cpe = obs.width * obs.height;
                    t.end_cells = obs
                        .final_cells
                        .get(e * cpe..(e + 1) * cpe)
                        .map(<[u8]>::to_vec)
                        .unwrap_or_default();
                }
            }
            if !self.hierarchical() {
                (rewards[e], dones[e]) = a2c::task_step(m);
                if m.truncated() {
                    cut_worker.push(e);
                }
                weights[e] = 1.0;
                continue;
            }
            let horizon = self.horizon;
            let (goal_r, penalty) = (self.cfg.goal_reward, self.cfg.step_penalty);
            let mut interval_over = ended;
            if train {
                ctl.book_manager_reward(e, m.reward);
            }
            let c = &mut ctl.envs[e];
            if traversing[e] {
                stats.traversal_steps += 1;
                dones[e] = true;
                c.goal.moved_to(cell);
                let t = c.traversal.as_mut().expect("traversing");
                let progress = t.advance(cell, ended);
                if let Some(before) = legs_before[e] {
                    legs[e] = match progress {
                        Progress::Continue if t.leg() > before => Leg::Reached,
                        Progress::Continue => Leg::Going,
                        Progress::Arrived => Leg::Reached,
                        Progress::Stopped => Leg::Ended,
                    };
                }
                match progress {
                    Progress::Continue => {}
                    Progress::Arrived => {
                        c.traversal = None;
                        c.goal.wide_paid = true;
                        if cell == c.goal.narrow {
                            interval_over = true;
                            stats.reached += 1;
                        }
                        interval_over |= c.goal.steps >= horizon;
                    }
                    Progress::Stopped => {
                        c.traversal = None;
                        interval_over |= c.goal.steps >= horizon;
                    }
                }
            } else {
                let mut s = c.goal.book(
                    cell,
                    end,
                    horizon,
                    goal_r,
                    penalty,
                    self.cfg.worker_task_end,
                );
                stats.reached += usize::from(s.reached);
                interval_over |= s.interval_over;
                if s.bootstrap {
                    cut_worker.push(e);
                }
                if !s.interval_over && self.graph.is_some() {
                    // Hand over to a traversal from here, if there is one.
                    if self.try_traverse(ctl, &obs, e) {
                        let pay = match self.cfg.hand_over {
                            HandOver::PaysWideGoal => goal_r,
                            HandOver::Unpaid => 0.0,
                        };
                        ctl.envs[e].goal.hand_over(&mut s, pay);
                    }
                }
                rewards[e] = s.reward;
                dones[e] = s.done;
                weights[e] = 1.0;
            }
            if interval_over && legs[e] == Leg::Going {
                legs[e] = Leg::Ended;
            }
            if interval_over {
                stats.intervals += 1;
                dones[e] = true;
                if ctl.end_interval(e, ended, train) && end == EpisodeEnd::Truncated {
                    cut_manager.push(e);
                }
            }
        }
        if train {
            // Truncation is not termination (Gymnasium's final_obs): the
            // cut steps' targets go on from their final states' values.
            if !cut_worker.is_empty() {
                let goals = self.goal_marks(ctl);
                let marks = self.hierarchical().then(|| GoalMarks {
                    cells: &goals,
                    per_env: self.slots(),
                });
                bootstrap_truncated(
                    &mut rewards,
                    &self.worker,
                    &obs,
                    marks,
                    &out_state,
                    &cut_worker,
                    self.cfg.worker.gamma,
                );
            }
            if let Some(manager) = &self.manager
                && !cut_manager.is_empty()
            {
                let state = ctl.manager_state.as_ref().expect("a Manager has a state");
                for (&e, v) in
                    cut_manager
                        .iter()
                        .zip(manager.final_values(&obs, state, &cut_manager))
                {
                    if let Some(q) = ctl.queues[e].decisions.last_mut() {
                        q.final_value = Some(v);
                    }
                }
            }
            self.rollout.record(&actions, &rewards, &dones, &weights);
        }
        if steered && let Some(s) = self.steering.as_mut() {
            let steer_actions: Vec<u8> = (0..n)
                .map(|e| if legs[e] == Leg::Idle { 0 } else { actions[e] })
                .collect();
            s.book(&steer_actions, &legs);
        }
        ctl.worker_state = out_state.reset_done(&mask(&dones));
        Ok(())
    }

    /// One training iteration: a rollout of `T` steps, then the Worker's
    /// (baseline's) and the Manager's updates.
    pub fn train_iteration(
        &mut self,
        env: &mut dyn BatchEnvironment,
    ) -> Result<IterationStats, LearnerError> {
        self.check_batch(env)?;
        let empty = self.controller(0, 0);
        let mut ctl = std::mem::replace(&mut self.ctl, empty);
        self.rollout.start(&ctl.worker_state);
        if let (Some(s), Some(state)) = (self.steering.as_mut(), ctl.steer_state.as_ref()) {
            s.start(state);
        }
        let mut counts = StepCounts::default();
        for _ in 0..self.cfg.rollout_len {
            self.step_batch(&mut ctl, env, true, None, &mut counts)?;
        }
        {
            let obs = env.observe();
            counts.add(self.decide(&mut ctl, &obs, true, &mut None));
            let goals = self.goal_marks(&ctl);
            let marks = self.hierarchical().then(|| GoalMarks {
                cells: &goals,
                per_env: self.slots(),
            });
            self.rollout.bootstrap = bootstrap_values(&self.worker, &obs, marks, &ctl.worker_state);
            if let (Some(s), Some(gcp), Some(state)) = (
                self.steering.as_mut(),
                self.gcp.as_ref(),
                ctl.steer_state.as_ref(),
            ) {
                // (Environments not steering bootstrap nothing: their last
                // recorded step ended its goal episode.)
                let (goals, fresh) = steer_targets(&ctl);
                s.update(gcp, &obs, &goals, &state.reset_done(&mask(&fresh)));
            }
        }
        let t0 = std::time::Instant::now();
        let (loss, worker) = self.rollout.loss(&self.worker, &self.cfg.worker);
        let t1 = PhaseTimes::lap(&mut self.times.loss, t0);
        self.worker_opt
            .backward_step(&loss, self.cfg.worker.grad_clip_norm);
        let mut t2 = PhaseTimes::lap(&mut self.times.backward, t1);
        let mut manager_figures = LossFigures::default();
        if let (Some(m), Some(opt)) = (&self.manager, self.manager_opt.as_mut()) {
            let init = ctl.manager_init.take().expect("Manager init state");
            let l = m.loss(
                &ctl.queues,
                &init,
                &self.cfg.manager,
                self.cfg.manager.gamma,
            );
            t2 = PhaseTimes::lap(&mut self.times.loss, t2);
            if l.figures.entries > 0.0 {
                opt.backward_step(&l.loss, self.cfg.manager.grad_clip_norm);
            }
            PhaseTimes::lap(&mut self.times.backward, t2);
            manager_figures = l.figures;
            ctl.manager_init = Some(l.next_init);
            for q in &mut ctl.queues {
                let last = q.decisions.pop();
                q.decisions.clear();
                q.decisions.extend(last);
            }
        }
        ctl.detach();
        self.ctl = ctl;
        Ok(IterationStats {
            env_steps: counts.steps,
            episodes: counts.episodes,
            mean_return: if counts.episodes > 0 {
                counts.returns / counts.episodes as f64
            } else {
                0.0
            },
            worker,
            manager: manager_figures,
            intervals: counts.intervals,
            goals_reached: if counts.intervals > 0 {
                counts.reached as f64 / counts.intervals as f64
            } else {
                0.0
            },
            traversal_share: counts.traversal_steps as f64 / counts.steps.max(1) as f64,
            exit_share: counts.successes as f64 / counts.episodes.max(1) as f64,
            decisions: counts.decisions,
            exit_goal_share: counts.exit_goals as f64 / counts.decisions.max(1) as f64,
            ball_goal_share: counts.ball_goals as f64 / counts.decisions.max(1) as f64,
        })
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
        let n = env.num_envs();
        env.step(&vec![action::RESET; n])?;
        let mut ctl = self.controller(n, sim::env_seed(seed ^ EVAL_SALT, 0));
        let mut done = vec![false; n];
        let mut returns = vec![0f32; n];
        let mut lengths = vec![0u32; n];
        let mut success = vec![false; n];
        let mut counts = StepCounts::default();
        let mut trace = trace.map(|t| {
            *t = EpisodeTrace::default();
            let obs = env.observe();
            t.cells.push(obs.meta[0].cell(self.width) as u32);
            t.start_cells = obs.env_cells(0).to_vec();
            (0usize, 0u32, t)
        });
        while done.iter().any(|d| !d) {
            let tr = match &mut trace {
                Some((_, step, t)) if !done[0] => Some((0, *step, &mut **t)),
                _ => None,
            };
            let before = tr.as_ref().map(|(_, s, _)| *s);
            self.step_batch(&mut ctl, env, false, tr, &mut counts)?;
            if let (Some((_, step, _)), Some(b)) = (&mut trace, before) {
                *step = b + 1;
            }
            let obs = env.observe();
            for e in 0..n {
                let m = &obs.meta[e];
                if !done[e] && m.done() {
                    done[e] = true;
                    returns[e] = m.episode_return;
                    lengths[e] = m.episode_len;
                    success[e] = reached_exit(&obs, e);
                }
            }
        }
        if let Some((_, _, t)) = trace {
            t.episode_return = returns[0];
        }
        let mean_return = returns.iter().map(|&r| f64::from(r)).sum::<f64>() / n.max(1) as f64;
        let success_rate = success.iter().filter(|&&s| s).count() as f64 / n.max(1) as f64;
        Ok(EvalResult {
            score: if self.task == Task::DoorKey {
                success_rate
            } else {
                mean_return
            },
            mean_return,
            success_rate,
            returns,
            lengths,
            traversal_share: counts.traversal_steps as f64 / counts.steps.max(1) as f64,
        })
    }

    /// Every tensor of the agent's state: the networks' weights and the
    /// optimisers' moments (`worker/...`, `manager/...`, `adam-worker/...`).
    fn named_tensors(&self) -> Vec<(String, Tensor)> {
        let mut out: Vec<(String, Tensor)> = Vec::new();
        let mut add = |prefix: &str, vs: &nn::VarStore| {
            let mut v: Vec<(String, Tensor)> = vs
                .variables()
                .into_iter()
                .map(|(k, t)| (format!("{prefix}/{k}"), t))
                .collect();
            v.sort_by(|a, b| a.0.cmp(&b.0));
            out.extend(v);
        };
        add("worker", &self.worker_vs);
        if let Some(vs) = &self.manager_vs {
            add("manager", vs);
        }
        if let (Some(_), Some(gcp)) = (&self.steering, &self.gcp) {
            add("pi_g", gcp.var_store());
        }
        out.extend(
            self.worker_opt
                .state()
                .into_iter()
                .map(|(k, t)| (format!("worker-{k}"), t)),
        );
        if let Some(o) = &self.manager_opt {
            out.extend(
                o.state()
                    .into_iter()
                    .map(|(k, t)| (format!("manager-{k}"), t)),
            );
        }
        if let Some(s) = &self.steering {
            out.extend(
                s.optimiser()
                    .state()
                    .into_iter()
                    .map(|(k, t)| (format!("pi_g-{k}"), t)),
            );
        }
        out
    }

    /// The weights and optimiser moments as bytes (a checkpoint's tensor
    /// file).
    pub fn to_bytes(&self) -> Result<Vec<u8>, LearnerError> {
        let named = self.named_tensors();
        let refs: Vec<(&str, &Tensor)> = named.iter().map(|(k, t)| (k.as_str(), t)).collect();
        let mut buf = Vec::new();
        Tensor::save_multi_to_stream(&refs, &mut buf)?;
        Ok(buf)
    }

    /// Restores [`Self::to_bytes`] (of an agent of the same configuration);
    /// `source` names the input in errors.
    pub fn load_bytes(&mut self, bytes: &[u8], source: &Path) -> Result<(), LearnerError> {
        let bad = |message: String| LearnerError::Checkpoint {
            path: source.display().to_string(),
            message,
        };
        let loaded = Tensor::load_multi_from_stream(std::io::Cursor::new(bytes))
            .map_err(|e| bad(e.to_string()))?;
        let find = |k: &str| loaded.iter().find(|(n, _)| n == k).map(|(_, t)| t);
        tch::no_grad(|| -> Result<(), LearnerError> {
            let fine_tuned = self
                .gcp
                .as_ref()
                .filter(|_| self.steering.is_some())
                .map(|g| ("pi_g", g.var_store()));
            for (prefix, vs) in std::iter::once(("worker", &self.worker_vs))
                .chain(self.manager_vs.as_ref().map(|v| ("manager", v)))
                .chain(fine_tuned)
            {
                for (k, mut t) in vs.variables() {
                    let key = format!("{prefix}/{k}");
                    let src = find(&key).ok_or_else(|| bad(format!("no tensor {key}")))?;
                    if src.size() != t.size() {
                        return Err(bad(format!(
                            "{key} has shape {:?}, expected {:?}",
                            src.size(),
                            t.size()
                        )));
                    }
                    t.copy_(src);
                }
            }
            Ok(())
        })?;
        let strip = |prefix: &str| -> Vec<(String, Tensor)> {
            loaded
                .iter()
                .filter_map(|(k, t)| {
                    k.strip_prefix(prefix)
                        .map(|s| (s.to_string(), t.shallow_clone()))
                })
                .collect()
        };
        self.worker_opt.load_state(&strip("worker-")).map_err(bad)?;
        if let Some(o) = self.manager_opt.as_mut() {
            o.load_state(&strip("manager-")).map_err(bad)?;
        }
        if let Some(s) = self.steering.as_mut() {
            s.optimiser_mut().load_state(&strip("pi_g-")).map_err(bad)?;
        }
        Ok(())
    }
}

/// Whether environment `e`'s episode ended, with the step that produced
/// `obs`, by the agent stepping onto the exit (its success; judged on the
/// final state, since the observation is the next episode's start).
fn reached_exit(obs: &ObsView<'_>, e: usize) -> bool {
    let m = &obs.meta[e];
    m.terminated()
        && obs
            .final_cells
            .get(e * obs.width * obs.height + obs.end_cell(e) as usize)
            .is_some_and(|&c| c == sim::Object::Exit as u8)
}

/// The Worker's goal marks of `goals`, [`AgentConfig::goal_planes`] per
/// environment ([`HrlAgent::goal_marks`]).
fn worker_goal_marks<'a>(kind: AgentKind, goals: impl Iterator<Item = &'a WorkerGoal>) -> Vec<u32> {
    match kind {
        AgentKind::WideNarrow => goals
            .flat_map(|g| [if g.wide_paid { NO_GOAL } else { g.wide }, g.narrow])
            .collect(),
        AgentKind::Feudal => goals.map(|g| g.narrow).collect(),
        AgentKind::A2c => Vec::new(),
    }
}

/// What `π_g` steers towards in each environment: the waypoint of its
/// traversal (`NO_GOAL` where none is steered), and whether its core state
/// starts afresh (a new edge begins).
fn steer_targets(ctl: &Controller) -> (Vec<u32>, Vec<bool>) {
    ctl.traversals()
        .into_iter()
        .map(|t| match t {
            Some(t) => (t.waypoint().unwrap_or(NO_GOAL), t.leg_starts()),
            None => (NO_GOAL, false),
        })
        .unzip()
}

/// One Manager choice: the wide and narrow indices as trained, the goal
/// cells, and (WN) the local input and valid slots of the window.
type Pick = (i64, i64, u32, u32, Vec<f32>, Vec<bool>);

#[cfg(test)]
mod tests {
    use super::*;
    use crate::batch_env::{EnvError, InProcess};
    use sim::{AutoReset, BallSpawn, EnvConfig};

    /// A batch environment that keeps every step record it produced.
    struct Recorder {
        env: InProcess,
        steps: Vec<Vec<EnvMeta>>,
    }

    impl BatchEnvironment for Recorder {
        fn num_envs(&self) -> usize {
            self.env.num_envs()
        }
        fn num_actions(&self) -> usize {
            self.env.num_actions()
        }
        fn observe(&self) -> ObsView<'_> {
            self.env.observe()
        }
        fn step(&mut self, actions: &[u8]) -> Result<(), EnvError> {
            self.env.step(actions)?;
            self.steps.push(self.env.observe().meta.to_vec());
            Ok(())
        }
    }

    #[test]
    fn a_truncated_step_is_bootstrapped_and_a_terminated_one_is_not() {
        // A corridor whose exit is two moves away and a step limit of 3:
        // random actions end episodes both ways.
        let layout = Layout::parse("corridor", "#####\n#>.E#\n#####\n").expect("layout");
        let env_cfg = EnvConfig {
            task: Task::MultiGoal,
            max_steps: 3,
            balls: BallSpawn::Layout,
            auto_reset: AutoReset::SameStep,
        };
        let cfg = AgentConfig {
            kind: AgentKind::A2c,
            envs: 8,
            rollout_len: 12,
            hidden: 16,
            conv_channels: [4, 8],
            ..AgentConfig::default()
        };
        let mut agent = HrlAgent::new(&cfg, &layout, Task::MultiGoal, None, 1).expect("agent");
        let mut env = Recorder {
            env: InProcess::new(layout.clone(), env_cfg, 8, 2, 1).expect("env"),
            steps: Vec::new(),
        };
        agent.start_segment(&mut env, 0).expect("segment");
        env.steps.clear();
        // Keep the rollout: the update does not clear it.
        agent.train_iteration(&mut env).expect("iteration");
        let (mut terminated, mut truncated) = (0, 0);
        let gamma = cfg.worker.gamma as f32;
        for (t, metas) in env.steps.iter().enumerate() {
            for (e, m) in metas.iter().enumerate() {
                let i = t * 8 + e;
                let (booked, done) = (agent.rollout.rewards[i], agent.rollout.dones[i]);
                if m.terminated() {
                    terminated += 1;
                    assert_eq!(booked, m.reward, "a terminated step is not bootstrapped");
                    assert_eq!(done, 1.0);
                } else if m.truncated() {
                    truncated += 1;
                    let bootstrap = booked - m.reward;
                    assert!(
                        bootstrap.abs() > 1e-6 && bootstrap.abs() <= gamma * 10.0,
                        "a truncated step adds γ·V(s_final), got {bootstrap}"
                    );
                    assert_eq!(done, 1.0, "nothing flows back from the next episode");
                } else {
                    assert_eq!(booked, m.reward);
                    assert_eq!(done, 0.0);
                }
            }
        }
        assert!(
            terminated > 0 && truncated > 0,
            "{terminated} / {truncated}"
        );
    }

    #[test]
    fn the_wide_narrow_worker_sees_which_goal_is_which() {
        let goals = [WorkerGoal::new(5, 9, 1), WorkerGoal::new(9, 5, 1)];
        let marks = worker_goal_marks(AgentKind::WideNarrow, goals.iter());
        assert_eq!(marks, vec![5, 9, 9, 5]);
        let layout = sim::Maze::Small.layout(false);
        let (cells, meta) = (layout.cells.repeat(2), vec![EnvMeta::EMPTY; 2]);
        let obs = ObsView {
            seq: 0,
            cells: &cells,
            final_cells: &[],
            meta: &meta,
            width: layout.width,
            height: layout.height,
        };
        let dense = crate::a2c::input::encode_obs(
            &obs,
            Some(GoalMarks {
                cells: &marks,
                per_env: 2,
            }),
        );
        assert!(
            !dense.get(0).equal(&dense.get(1)),
            "swapping g_w and g_n changes the Worker's input"
        );
        // Once g_w is paid its mark goes.
        let mut paid = WorkerGoal::new(5, 9, 1);
        paid.wide_paid = true;
        let marks = worker_goal_marks(AgentKind::WideNarrow, std::iter::once(&paid));
        assert_eq!(marks, vec![NO_GOAL, 9]);
    }
}
