//! A stage 2 agent (Shang et al. 2019, section 4): the flat A2C baseline
//! ([`A2cAgent`], section 4.1) or a hierarchy — Feudal or Wide-then-Narrow,
//! with or without traversal and `π_g` init ([`HrlAgent`], sections
//! 4.1–4.4). A run trains, validates, tests and checkpoints either through
//! [`Agent`]; the configuration's [`AgentKind`] chooses which is built.

use std::path::Path;

use planner::WorldGraph;
use sim::{Layout, Task};

use super::HrlAgent;
use super::baseline::A2cAgent;
use super::config::{AgentConfig, AgentKind, WorldGraphInputs};
use super::controller::SavedController;
use super::init::InitReport;
use super::reports::{EpisodeTrace, EvalResult, IterationStats};
use super::wide_narrow::Coverage;
use crate::a2c::PhaseTimes;
use crate::a2c::rollout::GradPath;
use crate::batch_env::BatchEnvironment;
use crate::error::LearnerError;

/// The flat A2C baseline or a hierarchy (module docs).
#[derive(Debug)]
pub enum Agent {
    /// The A2C baseline.
    A2c(Box<A2cAgent>),
    /// A Feudal or Wide-then-Narrow hierarchy.
    Hierarchy(Box<HrlAgent>),
}

/// Calls `$method` on whichever agent `$agent` is.
macro_rules! either {
    ($agent:expr, $a:ident => $call:expr) => {
        match $agent {
            Agent::A2c($a) => $call,
            Agent::Hierarchy($a) => $call,
        }
    };
}

impl Agent {
    /// A fresh agent of `cfg` for `task` on `layout` (the hierarchies with
    /// the world graph and `π_g` of `inputs` where they use them), weights
    /// drawn from `seed`.
    pub fn new(
        cfg: &AgentConfig,
        layout: &Layout,
        task: Task,
        inputs: Option<WorldGraphInputs>,
        seed: u64,
    ) -> Result<Agent, LearnerError> {
        Ok(match cfg.kind {
            AgentKind::A2c => Agent::A2c(Box::new(A2cAgent::new(cfg, layout, task, seed)?)),
            _ => Agent::Hierarchy(Box::new(HrlAgent::new(cfg, layout, task, inputs, seed)?)),
        })
    }

    /// The hierarchy, if the agent is one.
    pub fn hierarchy(&self) -> Option<&HrlAgent> {
        match self {
            Agent::Hierarchy(h) => Some(h),
            Agent::A2c(_) => None,
        }
    }

    /// The configuration.
    pub fn config(&self) -> &AgentConfig {
        either!(self, a => a.config())
    }

    /// What `π_g` initialisation copied (hierarchies initialised from it).
    pub fn init_report(&self) -> Option<&InitReport> {
        self.hierarchy().and_then(HrlAgent::init_report)
    }

    /// The wide-goal candidates `V` (WN; empty otherwise).
    pub fn candidates(&self) -> &[u32] {
        self.hierarchy().map_or(&[], HrlAgent::candidates)
    }

    /// Which free cells can be narrow goals (WN).
    pub fn window_coverage(&self) -> Option<Coverage> {
        self.hierarchy().and_then(HrlAgent::window_coverage)
    }

    /// The world graph traversal follows (WN with traversal).
    pub fn graph(&self) -> Option<&WorldGraph> {
        self.hierarchy().and_then(HrlAgent::graph)
    }

    /// Chooses the gradient path of the updates.
    pub fn set_grad_path(&mut self, path: GradPath) {
        either!(self, a => a.set_grad_path(path))
    }

    /// Starts training segment `segment` ([`HrlAgent::start_segment`]).
    pub fn start_segment(
        &mut self,
        env: &mut dyn BatchEnvironment,
        segment: u64,
    ) -> Result<(), LearnerError> {
        either!(self, a => a.start_segment(env, segment))
    }

    /// One training iteration.
    pub fn train_iteration(
        &mut self,
        env: &mut dyn BatchEnvironment,
    ) -> Result<IterationStats, LearnerError> {
        either!(self, a => a.train_iteration(env))
    }

    /// Plays one episode in every environment of `env` without training
    /// ([`HrlAgent::evaluate`]).
    pub fn evaluate(
        &mut self,
        env: &mut dyn BatchEnvironment,
        seed: u64,
        trace: Option<&mut EpisodeTrace>,
    ) -> Result<EvalResult, LearnerError> {
        either!(self, a => a.evaluate(env, seed, trace))
    }

    /// The training state a checkpoint saves beside the weights.
    pub fn save_controller(&self) -> Result<SavedController, LearnerError> {
        either!(self, a => a.save_controller())
    }

    /// Restores [`Self::save_controller`]'s record and tensors.
    pub fn load_controller(
        &mut self,
        json: &[u8],
        tensors: &[u8],
        source: &Path,
    ) -> Result<(), LearnerError> {
        either!(self, a => a.load_controller(json, tensors, source))
    }

    /// Where training time went since the last call.
    pub fn take_times(&mut self) -> PhaseTimes {
        either!(self, a => a.take_times())
    }

    /// Model FLOPs per env-step of the update path.
    pub fn flops_per_env_step(&self) -> f64 {
        either!(self, a => a.flops_per_env_step())
    }

    /// The weights and optimiser moments as bytes (a checkpoint's tensor
    /// file).
    pub fn to_bytes(&self) -> Result<Vec<u8>, LearnerError> {
        either!(self, a => a.to_bytes())
    }

    /// Restores [`Self::to_bytes`]; `source` names the input in errors.
    pub fn load_bytes(&mut self, bytes: &[u8], source: &Path) -> Result<(), LearnerError> {
        either!(self, a => a.load_bytes(bytes, source))
    }
}
