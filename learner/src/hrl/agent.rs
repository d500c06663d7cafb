//! A stage 2 agent (Shang et al. 2019, section 4): its owners, how it is
//! built, and its checkpoints.
//!
//! [`HrlAgent`] — a Feudal or Wide-then-Narrow hierarchy; the flat A2C
//! baseline is [`super::A2cAgent`] — holds the Worker's side
//! ([`WorkerSide`]), the Manager's side ([`ManagerSide`],
//! sections 4.1–4.2), the world graph traversal with `π_g`
//! ([`Traverser`], section 4.3) and the training controller
//! ([`Controller`]). Building it initialises the weights from the seed,
//! then copies `π_g`'s where configured (section 4.4; [`init`]). Running it
//! — a batch step, training iterations, evaluation — is in
//! [`super::iteration`].

use std::path::Path;

use planner::WorldGraph;
use sim::{Layout, Task, action};
use tch::Tensor;

use super::config::{AgentConfig, AgentKind, WorldGraphInputs};
use super::controller::{Controller, SavedController};
use super::init;
use super::manager::ManagerSide;
use super::traversal::Traverser;
use super::wide_narrow;
use super::worker::WorkerSide;
use crate::a2c::PhaseTimes;
use crate::a2c::learner::{load_variables, moments_of, named_variables};
use crate::a2c::rollout::GradPath;
use crate::batch_env::BatchEnvironment;
use crate::checkpoint::{checkpoint_error, named_tensors_bytes, named_tensors_of};
use crate::error::{ConfigError, LearnerError};

/// A stage 2 agent (module docs).
pub struct HrlAgent {
    pub(super) cfg: AgentConfig,
    pub(super) task: Task,
    pub(super) width: usize,
    /// The Manager horizon `c`.
    pub(super) horizon: u32,
    /// The environment action of each Worker policy output
    /// ([`AgentConfig::worker_actions`]).
    pub(super) actions: &'static [u8],
    /// The Worker.
    pub(super) worker: WorkerSide,
    /// The Manager.
    pub(super) manager: ManagerSide,
    /// World graph traversal and `π_g`.
    pub(super) traverser: Traverser,
    /// The training controller.
    pub(super) ctl: Controller,
    pub(super) seed: u64,
    pub(super) times: PhaseTimes,
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
pub(super) const SEGMENT_SALT: u64 = 0x5E6_0000;
pub(super) const EVAL_SALT: u64 = 0xE7A1_0000;

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
        if cfg.kind == AgentKind::A2c {
            return Err(ConfigError::new(
                "kind",
                "the A2C baseline is a flat agent (A2cAgent), not a hierarchy",
            )
            .into());
        }
        let (worker, manager) = crate::seeding::init_seeded(seed, || {
            let worker = WorkerSide::new(cfg, width, height, cfg.worker_actions(task).len());
            let manager = ManagerSide::new(cfg, layout, inputs.graph.as_ref());
            (worker, manager)
        });
        let init_report = match &inputs.gcp {
            Some(gcp) if cfg.init_from_gcp => Some(init::from_pi_g(
                gcp,
                cfg,
                &worker.learner.vs,
                Some(&manager.vs),
            )?),
            _ => None,
        };
        let mut traverser = Traverser::new(cfg, task, inputs.graph, inputs.gcp)?;
        if (cfg.traverse_outside_window || cfg.traversal_ends_in_window)
            && let Some(window) = &manager.window
        {
            traverser.start_outside(window.clone(), cfg.traversal_ends_in_window);
        }
        let ctl = Controller::new(
            cfg.envs,
            seed,
            &worker.learner.net,
            &manager.net,
            traverser.pi_g(),
        );
        Ok(HrlAgent {
            cfg: cfg.clone(),
            task,
            width,
            horizon: cfg.horizon(),
            actions: cfg.worker_actions(task),
            worker,
            manager,
            traverser,
            ctl,
            seed,
            times: PhaseTimes::default(),
            init_report,
        })
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
        &self.manager.candidates
    }

    /// Which free cells can be narrow goals: the coverage of the windows
    /// around `V` (WN).
    pub fn window_coverage(&self) -> Option<wide_narrow::Coverage> {
        let m = &self.manager;
        m.window.as_ref().map(|w| w.coverage(&m.candidates))
    }

    /// The world graph traversal follows.
    pub fn graph(&self) -> Option<&WorldGraph> {
        self.traverser.graph()
    }

    /// Chooses the gradient path of the Worker's and the Manager's updates
    /// (`bench learner` measures [`GradPath::RustCore`] against the
    /// [`GradPath::Tch`] reference this way).
    pub fn set_grad_path(&mut self, path: GradPath) {
        self.worker.learner.set_grad_path(path, self.cfg.envs);
        self.manager.set_grad_path(path);
    }

    /// A controller of `n` environments at the start of their episodes,
    /// its action RNG seeded by `seed`.
    pub(super) fn controller(&self, n: usize, seed: u64) -> Controller {
        Controller::new(
            n,
            seed,
            &self.worker.learner.net,
            &self.manager.net,
            self.traverser.pi_g(),
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
        let n = reset_batch(self.cfg.envs, env)?;
        self.ctl = self.controller(n, sim::env_seed(self.seed ^ SEGMENT_SALT, segment));
        Ok(())
    }

    /// Where training time went since the last call.
    pub fn take_times(&mut self) -> PhaseTimes {
        let mut t = std::mem::take(&mut self.times);
        t.add(&std::mem::take(&mut self.worker.learner.rollout.times));
        t
    }

    /// Model FLOPs per env-step of the Worker's update path,
    /// plus the Manager's forward and backward once per decision (about one
    /// per `c / 2` steps).
    pub fn flops_per_env_step(&self) -> f64 {
        let worker = crate::a2c::net::flops_per_env_step(
            self.worker.learner.net.trunk(),
            self.actions.len() as i64,
        );
        worker + self.manager.flops_per_decision() / (self.horizon as f64 / 2.0).max(1.0)
    }

    /// Every tensor of the agent's state: the networks' weights and the
    /// optimisers' moments (`worker/...`, `manager/...`, `adam-worker/...`).
    fn named_tensors(&self) -> Vec<(String, Tensor)> {
        let mut out = self.worker.learner.weights("worker");
        out.extend(named_variables("manager", &self.manager.vs));
        if let Some(vs) = self.traverser.fine_tuned() {
            out.extend(named_variables("pi_g", vs));
        }
        out.extend(self.worker.learner.moments("worker"));
        out.extend(
            self.manager
                .opt
                .state()
                .into_iter()
                .map(|(k, t)| (format!("manager-{k}"), t)),
        );
        if let Some(s) = self.traverser.steering() {
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
        named_tensors_bytes(&self.named_tensors())
    }

    /// Restores [`Self::to_bytes`] (of an agent of the same configuration);
    /// `source` names the input in errors.
    pub fn load_bytes(&mut self, bytes: &[u8], source: &Path) -> Result<(), LearnerError> {
        let bad = |message: String| checkpoint_error(source, message);
        let loaded = named_tensors_of(bytes, source)?;
        let fine_tuned = self.traverser.fine_tuned().map(|vs| ("pi_g", vs));
        for (prefix, vs) in std::iter::once(("worker", &self.worker.learner.vs))
            .chain(std::iter::once(("manager", &self.manager.vs)))
            .chain(fine_tuned)
        {
            load_variables(prefix, vs, &loaded).map_err(bad)?;
        }
        let strip = |prefix: &str| moments_of(prefix, &loaded);
        self.worker
            .learner
            .opt
            .load_state(&strip("worker"))
            .map_err(bad)?;
        self.manager
            .opt
            .load_state(&strip("manager"))
            .map_err(bad)?;
        self.manager.weights_changed();
        if let Some(s) = self.traverser.steering_mut() {
            s.optimiser_mut().load_state(&strip("pi_g")).map_err(bad)?;
        }
        Ok(())
    }
}

/// Starts a new episode in every environment of `env`, a batch of `envs`
/// (the one an agent was built for); returns its size.
pub(super) fn reset_batch(
    envs: usize,
    env: &mut dyn BatchEnvironment,
) -> Result<usize, LearnerError> {
    let n = check_batch(envs, env)?;
    env.step(&vec![action::RESET; n])?;
    Ok(n)
}

/// The size of `env`'s batch, which must be `envs`, the one an agent was
/// built for.
pub(super) fn check_batch(envs: usize, env: &dyn BatchEnvironment) -> Result<usize, LearnerError> {
    let n = env.num_envs();
    if n != envs {
        return Err(ConfigError::new(
            "envs",
            format!("the agent was built for {envs} environments, the batch has {n}"),
        )
        .into());
    }
    Ok(n)
}
