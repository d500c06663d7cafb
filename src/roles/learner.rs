//! The learner process: reads observation batches in place through the
//! shared-memory [`ShmEnv`], runs a policy, sends action batches; optionally
//! asks the planner for routes now and then (client-observed route latency).
//!
//! Hot-loop histograms: `policy` (choosing N actions), `obs_one_way`
//! (sim's publish → this process's receive, from the header's send time),
//! `route_client` (request → response, when `--route-every` is set).

use std::time::{Duration, Instant};

use clap::Args;
use iceoryx2::prelude::ipc;
use learner::a2c::net::ActorCriticConfig;
use learner::batch_env::{BatchEnvironment, EnvError};
use learner::serving_policy::{ActorCriticPolicy, Policy, RandomPolicy};
use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};
use serde::Serialize;
use shm_schemas::ObsShape;

use super::learner_train::{Trainer, check_slices};
pub use super::policy_loop::PolicyKind;
use super::policy_loop::{Served, StreamLog, TrainSummary, after_sim_death};
use super::shm_env::{ShmEnv, ShmEnvOptions, StreamStats};
use super::{
    EXIT_PEER_DIED, LEARNER_NODE, PLANNER_NODE, PeerWatch, RunArgs, RunCtx, SIM_NODE, config_exit,
};
use crate::latency::Latencies;
use crate::world_args::WorldArgs;

/// `learner serve` options.
#[derive(Debug, Clone, Args)]
pub struct LearnerServeArgs {
    #[command(flatten)]
    pub world: WorldArgs,
    #[command(flatten)]
    pub run: RunArgs,
    /// Environments in the batch (must match the sim's).
    #[arg(long, default_value_t = 256)]
    pub envs: usize,
    /// Slices the sim publishes its batch in (must match the sim's).
    #[arg(long, default_value_t = 2)]
    pub slices: usize,
    /// The policy.
    #[arg(long, value_enum, default_value = "random")]
    pub policy: PolicyKind,
    /// Ask the planner for a route every this many batches (0 = never;
    /// `train-gcp` asks for none).
    #[arg(long, default_value_t = 0)]
    pub route_every: u64,
    /// With `--policy train-gcp`: checkpoint π_g every this many training
    /// iterations (and at a clean stop).
    #[arg(long, default_value_t = 10)]
    pub checkpoint_every: u64,
}

/// What the learner reports at exit (`learner.report.json`).
#[derive(Debug, Serialize)]
pub struct LearnerReport {
    /// Policy name.
    pub policy: String,
    /// Observation stream accounting.
    pub stream: StreamStats,
    /// Batches answered.
    pub batches: u64,
    /// Episodes finished.
    pub episodes: u64,
    /// Mean return of finished episodes.
    pub mean_episode_return: f64,
    /// Routes received / requested.
    pub routes_ok: u64,
    /// Route requests sent.
    pub routes_requested: u64,
    /// Why the loop ended.
    pub stopped_by: String,
    /// With `train-gcp`: the training this process did and kept.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub training: Option<TrainSummary>,
}

/// Runs the learner role until stopped; returns the process exit code.
pub fn serve(a: LearnerServeArgs) -> anyhow::Result<std::process::ExitCode> {
    // Everything a restart could not fix is checked first (EXIT_CONFIG).
    let checked = (|| -> anyhow::Result<_> {
        let (layout, cfg) = a.world.build()?;
        let shape = ObsShape::sliced(a.envs, a.slices, layout.width, layout.height)?;
        check_slices(a.policy, a.slices)?;
        let ctx = RunCtx::new(&a.run, LEARNER_NODE)?;
        // A checkpoint of another run's settings is refused before connecting.
        let trainer = match a.policy {
            PolicyKind::TrainGcp => Some(Trainer::open(
                &ctx.dir,
                &layout,
                a.envs,
                cfg.task.name(),
                cfg.task.num_actions(),
                a.world.seed,
                a.checkpoint_every,
            )?),
            _ => None,
        };
        Ok((ctx, layout, cfg, shape, trainer))
    })();
    let (ctx, layout, cfg, shape, trainer) = match checked {
        Ok(v) => v,
        Err(e) => return Ok(config_exit("learner", &e)),
    };
    let num_actions = cfg.task.num_actions();
    let opts = ShmEnvOptions {
        node_name: LEARNER_NODE.into(),
        sim_node_name: SIM_NODE.into(),
        stop: Some(ctx.stop.clone()),
        connect_timeout: Duration::from_secs(3600),
        task: Some(cfg.task.name().into()),
        ..ShmEnvOptions::default()
    };
    eprintln!(
        "learner: run '{}', waiting for observation batches of {} x {}x{}",
        ctx.run, a.envs, shape.width, shape.height
    );
    let mut env = match ShmEnv::<ipc::Service>::connect(
        &ctx.config,
        ctx.run.clone(),
        shape,
        num_actions,
        opts,
    ) {
        Ok(env) => env,
        // Stopped (or out of time) while waiting: the last one out removes
        // the run's shared memory.
        Err(EnvError::Interrupted) => {
            ctx.tidy();
            return Ok(std::process::ExitCode::SUCCESS);
        }
        // Another shape, slicing, task or schema: a restart cannot fix it.
        Err(EnvError::Shm(shm_schemas::ShmError::Schema(e))) => {
            ctx.tidy();
            return Ok(config_exit("learner", &anyhow::Error::new(e)));
        }
        Err(e) => return Err(e.into()),
    };
    let mut stream_log = StreamLog::open(&ctx.dir)?;
    let mut lat = Latencies::new("learner");
    let served = match trainer {
        Some(t) => t.run(&ctx, &mut env, &mut stream_log, &mut lat)?,
        None => serve_policy(
            &a,
            &ctx,
            &layout,
            shape,
            &mut env,
            &mut stream_log,
            &mut lat,
        )?,
    };
    stream_log.write(env.stats())?;
    let stream = env.stats();
    drop(env);
    ctx.tidy();
    let stopped_by = served.stopped_by.clone();
    let report = LearnerReport {
        policy: served.policy,
        stream,
        batches: served.batches,
        episodes: served.episodes,
        mean_episode_return: if served.episodes > 0 {
            served.return_sum / served.episodes as f64
        } else {
            f64::NAN
        },
        routes_ok: served.routes_ok,
        routes_requested: served.routes_requested,
        stopped_by: stopped_by.clone(),
        training: served.training,
    };
    ctx.write_json("learner.report.json", &report)?;
    lat.write_reports(&ctx.dir)?;
    eprint!("{}", lat.table());
    eprintln!(
        "learner: {} batches, lost {}, reordered {}, sim restarts {}, stopped by {}",
        report.batches,
        report.stream.lost,
        report.stream.reordered,
        report.stream.sim_restarts,
        stopped_by
    );
    Ok(if stopped_by == "sim died" {
        std::process::ExitCode::from(EXIT_PEER_DIED)
    } else {
        std::process::ExitCode::SUCCESS
    })
}

/// The policy loop of `random` and `actor-critic`: one policy per slice,
/// route requests now and then.
fn serve_policy(
    a: &LearnerServeArgs,
    ctx: &RunCtx,
    layout: &sim::Layout,
    shape: ObsShape,
    env: &mut ShmEnv<ipc::Service>,
    stream_log: &mut StreamLog,
    lat: &mut Latencies,
) -> anyhow::Result<Served> {
    let per_slice = shape.envs();
    let num_actions = env.num_actions();
    // One policy per slice: sample k holds slice k mod K, and each slice's
    // environments keep their own recurrent state.
    let mut policies: Vec<Box<dyn Policy>> = (0..a.slices as u64)
        .map(|k| -> Box<dyn Policy> {
            match a.policy {
                // (`train-gcp` runs its own loop, [`Trainer::run`].)
                PolicyKind::Random | PolicyKind::TrainGcp => Box::new(RandomPolicy::new(
                    num_actions,
                    sim::env_seed(a.world.seed ^ 0x5eed, k),
                )),
                PolicyKind::ActorCritic => Box::new(ActorCriticPolicy::new(
                    &ActorCriticConfig {
                        num_actions: num_actions as i64,
                        ..ActorCriticConfig::default()
                    },
                    per_slice,
                    layout.width,
                    layout.height,
                    a.world.seed,
                )),
            }
        })
        .collect();
    let route_client = if a.route_every > 0 {
        Some(env.node().route_client()?)
    } else {
        None
    };
    let graph = if a.route_every > 0 {
        Some(env.node().graph_subscriber(layout.width, layout.height)?)
    } else {
        None
    };
    let mut num_pivots = 0usize;
    let mut rng = SmallRng::seed_from_u64(a.world.seed);
    for h in ["policy", "obs_one_way", "route_client"] {
        lat.register(h);
    }
    let mut planner = PeerWatch::new(PLANNER_NODE);
    let mut actions = vec![0u8; per_slice];
    let (mut batches, mut episodes, mut return_sum) = (0u64, 0u64, 0f64);
    let (mut routes_ok, mut routes_requested) = (0u64, 0u64);
    let mut next_log = Instant::now() + Duration::from_secs(1);
    let stopped_by;
    loop {
        let obs = env.observe();
        for m in obs.meta.iter().filter(|m| m.done()) {
            episodes += 1;
            return_sum += m.episode_return as f64;
        }
        lat.record("obs_one_way", env.last_latency_ns());
        let t0 = Instant::now();
        policies[(obs.seq % a.slices as u64) as usize].act(&obs, &mut actions);
        lat.record("policy", t0.elapsed().as_nanos() as u64);
        let (cell, dir) = {
            let m = obs.meta[0];
            (m.y as u32 * shape.width as u32 + m.x as u32, m.dir)
        };
        match env.step(&actions) {
            Ok(()) => {}
            Err(EnvError::Interrupted) => {
                stopped_by = "stop request".to_string();
                break;
            }
            Err(EnvError::PeerGone { detail, .. }) => {
                if let Some(why) = after_sim_death(ctx, env, &detail)? {
                    stopped_by = why.to_string();
                    break;
                }
            }
            Err(e) => return Err(e.into()),
        }
        batches += 1;

        if let (Some(client), Some(graph)) = (&route_client, &graph)
            && batches % a.route_every == 0
        {
            if let Some(s) = graph.receive()? {
                num_pivots = s.snapshot().nodes.len();
            }
            planner.poll(ctx);
            if num_pivots > 0 && !planner.gone {
                let to = rng.random_range(0..num_pivots) as u16;
                let t0 = Instant::now();
                routes_requested += 1;
                if let Ok(reply) = client
                    .request(0, cell, dir, to)?
                    .wait(Duration::from_millis(50))
                {
                    lat.record("route_client", t0.elapsed().as_nanos() as u64);
                    routes_ok +=
                        u64::from(reply.response().status() == Some(shm_schemas::RouteStatus::Ok));
                }
            }
        }
        if batches % 64 == 0 && Instant::now() >= next_log {
            next_log = Instant::now() + Duration::from_millis(250);
            stream_log.write(env.stats())?;
            ctx.report_on_request(lat);
        }
    }
    drop((route_client, graph));
    Ok(Served {
        policy: policies[0].name().to_string(),
        batches,
        episodes,
        return_sum,
        routes_ok,
        routes_requested,
        stopped_by,
        training: None,
    })
}
