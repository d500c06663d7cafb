//! What a pipeline run is started with (`worldgraph run`'s options, which
//! `soak` and `bench pipeline` fill in too): the world, the graph, the
//! roles' settings, checked whole before any process starts, and the
//! [`Pipeline`] of role processes they describe.

use std::path::PathBuf;

use clap::Args;
use iceoryx2::prelude::ipc;
use shm_schemas::service::{RunName, run_config};

use super::{Pipeline, Role, world_words};
use crate::roles::learner::PolicyKind;
use crate::roles::planner::GraphArgs;
use crate::roles::{OnPeerDeath, RunArgs};
use crate::world_args::WorldArgs;

/// `run` options.
#[derive(Debug, Clone, Args)]
pub struct RunCmdArgs {
    #[command(flatten)]
    pub world: WorldArgs,
    #[command(flatten)]
    pub graph: GraphArgs,
    /// Run name, directory, peer-death policy (`wait` also restarts a
    /// process that died) and duration, passed on to every process.
    #[command(flatten)]
    pub run: RunArgs,
    /// Environments in the batch.
    #[arg(long, default_value_t = 256)]
    pub envs: usize,
    /// Slices the sim publishes its batch in (1–4, dividing --envs): with 2
    /// the sim steps one half while the learner chooses the other half's
    /// actions (double-buffered sampling); 1 is plain lock-step.
    #[arg(long, default_value_t = 2)]
    pub slices: usize,
    /// Threads stepping the batch in the sim process.
    #[arg(long, default_value_t = 1)]
    pub threads: usize,
    /// The learner's policy.
    #[arg(long, value_enum, default_value = "random")]
    pub policy: PolicyKind,
    /// The learner asks the planner for a route every this many batches (0 = never).
    #[arg(long, default_value_t = 0)]
    pub route_every: u64,
    /// With `--policy train-gcp`: the learner checkpoints π_g every this
    /// many training iterations (and at a clean stop).
    #[arg(long, default_value_t = 10)]
    pub checkpoint_every: u64,
    /// Write each process's messages to `<run dir>/<role>.log` instead of the terminal.
    #[arg(long)]
    pub logs_to_files: bool,
    /// Pin the sim (one-thread) to the first allowed CPU and the learner to
    /// the second; the planner, which mostly sleeps, stays unpinned. Off by
    /// default: on the 2-vCPU target it made no measurable difference
    /// (`bench pipeline`: 0.73–0.76 of in-process either way), but on
    /// larger machines it keeps the two busy-polling processes apart.
    #[arg(long)]
    pub pin: bool,
}

impl RunCmdArgs {
    /// The run directory.
    pub fn dir(&self) -> PathBuf {
        self.run
            .run_dir
            .clone()
            .unwrap_or_else(|| PathBuf::from("runs").join(&self.run.run))
    }

    /// The argument list of `role`'s process.
    pub fn role_args(&self, role: Role) -> Vec<String> {
        let mut v: Vec<String> = match role {
            Role::Sim => vec!["sim".into(), "serve".into()],
            Role::Learner => vec!["learner".into(), "serve".into()],
            Role::Planner => vec!["planner".into(), "serve".into()],
        };
        v.extend(world_words(&self.world));
        v.extend([
            "--run".into(),
            self.run.run.clone(),
            "--run-dir".into(),
            self.dir().display().to_string(),
            "--on-peer-death".into(),
            match self.run.on_peer_death {
                OnPeerDeath::Wait => "wait".into(),
                OnPeerDeath::Exit => "exit".into(),
            },
            "--envs".into(),
            self.envs.to_string(),
            "--slices".into(),
            self.slices.to_string(),
        ]);
        if let Some(cpu) = self.pinned_cpu(role) {
            v.extend(["--cpu".into(), cpu.to_string()]);
        }
        match role {
            Role::Sim => v.extend(["--threads".into(), self.threads.to_string()]),
            Role::Learner => {
                v.extend([
                    "--policy".into(),
                    self.policy.name().into(),
                    "--route-every".into(),
                    self.route_every.to_string(),
                ]);
                if self.policy == PolicyKind::TrainGcp {
                    v.extend([
                        "--checkpoint-every".into(),
                        self.checkpoint_every.to_string(),
                    ]);
                }
            }
            Role::Planner => {
                let g = &self.graph;
                v.extend([
                    "--nodes".into(),
                    g.nodes.to_string(),
                    "--walks-per-node".into(),
                    g.walks_per_node.to_string(),
                    "--walk-len".into(),
                    g.walk_len.to_string(),
                ]);
                if let Some(f) = &g.node_file {
                    v.extend(["--node-file".into(), f.display().to_string()]);
                }
                if let Some(s) = g.graph_seed {
                    v.extend(["--graph-seed".into(), s.to_string()]);
                }
            }
        }
        v
    }

    /// The CPU `role` is pinned to (see `--pin`).
    fn pinned_cpu(&self, role: Role) -> Option<usize> {
        if !self.pin || self.threads != 1 {
            return None;
        }
        let cpus = crate::roles::allowed_cpus();
        match role {
            _ if cpus.len() < 2 => None,
            Role::Sim => Some(cpus[0]),
            Role::Learner => Some(cpus[1]),
            Role::Planner => None,
        }
    }

    /// Checks everything the roles would refuse before starting any of
    /// them: the layout, the batch shape, the planner's settings and node
    /// file, and that no live process holds the run already.
    pub fn validate(&self) -> anyhow::Result<()> {
        let run = RunName::new(&self.run.run)?;
        let (layout, _) = self.world.build()?;
        shm_schemas::ObsShape::sliced(self.envs, self.slices, layout.width, layout.height)?;
        crate::roles::learner_train::check_slices(self.policy, self.slices)?;
        anyhow::ensure!(
            self.checkpoint_every >= 1,
            "--checkpoint-every must be at least 1"
        );
        self.graph.config(&self.world).validate()?;
        if let Some(path) = &self.graph.node_file {
            planner::pivotal::read_node_file(&layout, path)?;
        }
        if let Some(d) = self.run.duration {
            anyhow::ensure!(d > 0.0, "--duration must be positive");
        }
        anyhow::ensure!(self.threads >= 1, "--threads must be at least 1");
        refuse_live_run(&run)
    }

    /// A pipeline of the three roles.
    pub fn pipeline(&self) -> anyhow::Result<Pipeline> {
        anyhow::ensure!(
            self.run.cpu.is_none(),
            "--cpu pins a single role (sim|learner|planner serve); `run --pin` pins the sim \
             and the learner"
        );
        let dir = self.dir();
        std::fs::create_dir_all(&dir)?;
        let roles = Role::ALL.iter().map(|&r| (r, self.role_args(r))).collect();
        Pipeline::new(roles, self.logs_to_files.then_some(dir.as_path()))
    }
}

/// Refuses a run name that a live process already uses (another `run`,
/// `soak` or a role started by hand), naming the process: two runs of one
/// name would share the services and the run directory.
pub fn refuse_live_run(run: &RunName) -> anyhow::Result<()> {
    let config = run_config(run)?;
    let live: Vec<_> = shm_schemas::service::list_nodes::<ipc::Service>(&config)
        .unwrap_or_default()
        .into_iter()
        .filter(|n| n.alive)
        .collect();
    if let Some(n) = live.first() {
        anyhow::bail!(
            "run '{run}' is in use: its {} node is held by process {} ({}); stop that run \
             or choose another --run",
            n.name,
            n.pid,
            n.executable
        );
    }
    Ok(())
}
