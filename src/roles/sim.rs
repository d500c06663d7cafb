//! The sim process: owns the batch of environments and publishes each
//! observation batch by stepping the environments **directly into a loaned
//! shared-memory sample** (no intermediate copy of the cells), then waits
//! for the action batch that answers it (lock-step, see
//! `shm_schemas::service`).
//!
//! The final cells (the grid of each episode the step ended) are written in
//! place too. The one exception is the step records (reward, flags, agent,
//! end pose; 28 bytes per environment): they are stepped into a private
//! buffer and copied into the sample in one burst. The learner reads them
//! from the other core, so each record's cache line belongs to the learner
//! when the sim writes it again; written field by field while stepping,
//! every write would wait for the line (the cost is measured in
//! `docs/implementation_details.md`, "Pipeline throughput").
//!
//! With `--slices K` (default 2) the batch is `K` slices of `N / K`
//! environments, published as separate samples, and up to `K` samples are
//! awaiting their actions at once: the sim steps slice 1 while the learner
//! chooses slice 0's actions (double-buffered sampling, as in Sample
//! Factory). Each slice is still lock-step with its own actions; the
//! environments and their trajectories are the same for every `K`.
//!
//! Hot-loop histograms: `step` (loaning a sample and stepping one slice's
//! environments into it, up to the header's send stamp), `action_round_trip`
//! (that stamp of sample k → receipt of action k, so it includes the
//! publish).

use std::io::Write;

use clap::Args;
use iceoryx2::prelude::ipc;
use serde::Serialize;
use shm_schemas::service::PipelineNode;
use shm_schemas::{Backoff, ObsShape, monotonic_ns};
use sim::{BatchEnv, StepOut};

use super::{
    EXIT_PEER_DIED, LEARNER_NODE, OnPeerDeath, PeerEvent, PeerWatch, RunArgs, RunCtx, SIM_NODE,
    config_exit,
};
use crate::latency::{Latencies, Recorder};
use crate::world_args::WorldArgs;

/// `sim serve` options.
#[derive(Debug, Clone, Args)]
pub struct SimServeArgs {
    #[command(flatten)]
    pub world: WorldArgs,
    #[command(flatten)]
    pub run: RunArgs,
    /// Environments in the batch.
    #[arg(long, default_value_t = 256)]
    pub envs: usize,
    /// Slices the batch is published in (1–4, dividing --envs): with 2 the
    /// sim steps one half while the learner chooses the other half's
    /// actions. Every process of a run must use the same value.
    #[arg(long, default_value_t = 2)]
    pub slices: usize,
    /// Threads stepping the batch (1 leaves the other core to the learner).
    #[arg(long, default_value_t = 1)]
    pub threads: usize,
}

/// What the sim reports at exit (`sim.report.json`).
#[derive(Debug, Serialize)]
pub struct SimReport {
    /// Samples published (each one slice of the batch).
    pub batches: u64,
    /// Environment steps taken.
    pub env_steps: u64,
    /// Seconds from the first to the last published batch.
    pub seconds: f64,
    /// `env_steps / seconds`.
    pub steps_per_sec: f64,
    /// Action batches that did not answer the waited-for observation (ignored).
    pub stale_actions: u64,
    /// Times the learner was declared gone.
    pub learner_deaths: u64,
    /// Episodes finished.
    pub episodes: u64,
    /// Round trip percentiles (µs).
    pub roundtrip_p50_us: f64,
    /// Round trip p99 (µs).
    pub roundtrip_p99_us: f64,
    /// Round trip p99.9 (µs).
    pub roundtrip_p999_us: f64,
    /// Step p50 (µs).
    pub step_p50_us: f64,
    /// Share of the loop's time spent waiting for action batches rather
    /// than stepping (loan + step + send): near 0 when the sim is the
    /// bottleneck, large when the learner or the transport is. Waits over
    /// [`LONG_WAIT_NS`] (a paused, dead or restarting learner) are left out.
    pub wait_fraction: f64,
    /// Why the loop ended.
    pub stopped_by: String,
}

/// Waits for actions longer than this are a paused or absent learner, not
/// the pipeline's rhythm ([`SimReport::wait_fraction`]).
const LONG_WAIT_NS: u64 = 1_000_000;

/// How often a line is appended to `sim.stats.jsonl`.
const STATS_EVERY_NS: u64 = 250_000_000;

/// A minute in the loop's nanoseconds (per-minute round-trip summaries).
const MINUTE_NS: u64 = 60_000_000_000;

/// One line of `sim.stats.jsonl`: progress every [`STATS_EVERY_NS`], and a
/// per-minute round-trip summary (`minute` set) every 60 s.
#[derive(Debug, Serialize)]
struct StatsLine {
    /// Seconds since this sim process published its first batch.
    t: f64,
    /// Wall-clock time (ms since the Unix epoch), to line up restarted sims.
    unix_ms: u64,
    /// Process id (a restarted sim appends to the same file).
    pid: u32,
    /// Samples answered so far (the oldest awaited sample's number).
    seq: u64,
    /// Environment steps taken so far by this process.
    env_steps: u64,
    /// Env-steps/s over the interval.
    steps_per_sec: f64,
    /// Round-trip p99 over the interval (µs).
    roundtrip_p99_us: f64,
    /// Whether the learner's node was alive at the last check.
    learner_alive: bool,
    /// For per-minute lines: the minute's index since start.
    #[serde(skip_serializing_if = "Option::is_none")]
    minute: Option<u64>,
    /// For per-minute lines: the minute's round-trip p99 (µs).
    #[serde(skip_serializing_if = "Option::is_none")]
    minute_roundtrip_p99_us: Option<f64>,
}

/// Runs the sim role until stopped; returns the process exit code.
pub fn serve(a: SimServeArgs) -> anyhow::Result<std::process::ExitCode> {
    // Everything a restart could not fix is checked first (EXIT_CONFIG).
    let checked = (|| -> anyhow::Result<_> {
        let (layout, cfg) = a.world.build()?;
        let shape = ObsShape::sliced(a.envs, a.slices, layout.width, layout.height)?;
        Ok((RunCtx::new(&a.run, SIM_NODE)?, layout, cfg, shape))
    })();
    let (ctx, layout, cfg, shape) = match checked {
        Ok(v) => v,
        Err(e) => return Ok(config_exit("sim", &e)),
    };
    let per_slice = shape.envs();
    let mut slices = (0..a.slices)
        .map(|k| {
            BatchEnv::with_first_index(
                layout.clone(),
                cfg,
                k * per_slice,
                per_slice,
                a.world.seed,
                a.threads,
            )
        })
        .collect::<Result<Vec<_>, _>>()?;
    let node = PipelineNode::<ipc::Service>::new(&ctx.config, ctx.run.clone(), SIM_NODE)?
        .with_task(cfg.task.name(), cfg.task.num_actions());
    let cleaned = node.cleanup_dead_nodes();
    if cleaned.cleanups > 0 {
        tracing::info!(
            "sim: removed stale resources of {} dead node(s) of a previous run",
            cleaned.cleanups
        );
    }
    let ports = node
        .obs_publisher(shape)
        .and_then(|p| node.act_subscriber(per_slice).map(|a| (p, a)));
    let (publisher, actions) = match ports {
        Ok(ports) => ports,
        // Another shape, slicing, task or schema: a restart cannot fix it.
        Err(shm_schemas::ShmError::Schema(e)) => {
            return Ok(config_exit("sim", &anyhow::Error::new(e)));
        }
        Err(e) => {
            return Err(anyhow::Error::new(e).context("sim: cannot open its services"));
        }
    };
    tracing::info!(
        "sim: run '{}', {} x {}x{} {} on '{}' in {} slice(s), publishing",
        ctx.run,
        a.envs,
        shape.width,
        shape.height,
        cfg.task,
        layout.name,
        a.slices
    );

    // The per-sample loop records into bare recorders (no name lookups);
    // every stats interval they are folded into the named histograms.
    let mut lat = Latencies::new("sim");
    for h in ["step", "action_round_trip"] {
        lat.register(h);
    }
    let mut step_rec = Recorder::new();
    let (mut rtt_interval, mut rtt_minute) = (Recorder::new(), Recorder::new());
    let fold = |lat: &mut Latencies, step: &mut Recorder, rtt: &Recorder| {
        lat.absorb("step", step);
        lat.absorb("action_round_trip", rtt);
        step.reset();
    };
    let mut stats = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(ctx.dir.join("sim.stats.jsonl"))?;
    let pid = std::process::id();
    let mut learner = PeerWatch::new(LEARNER_NODE);

    // Samples 0..K: every slice's first observations, written in place.
    // `seq` is the oldest sample awaiting its actions; samples seq..seq+K
    // are out, sample k holding slice k mod K; `sent_at[k mod K]` is when
    // sample k was published (its header's `send_time_ns`). The loop keeps
    // time in those nanoseconds: two clock reads per sample.
    let k_slices = a.slices as u64;
    let mut sent_at = vec![0u64; a.slices];
    for (k, batch) in slices.iter_mut().enumerate() {
        let mut sample = publisher.loan(k as u64, 0)?;
        {
            let (_, meta, cells, final_cells) = sample.batch_mut().into_parts();
            batch.reset(StepOut {
                cells,
                final_cells,
                meta,
            });
        }
        sent_at[k] = sample.send_stamped()?.1;
    }
    let mut records = vec![sim::EnvMeta::EMPTY; per_slice];
    let (mut wait_ns, mut step_ns) = (0u64, 0u64);
    let mut seq = 0u64;
    let started = sent_at[0];
    let mut last_sent = started;
    let (mut env_steps, mut episodes, mut stale) = (0u64, 0u64, 0u64);
    let mut next_stats = started + STATS_EVERY_NS;
    let mut next_minute = started + MINUTE_NS;
    let mut minutes = 0u64;
    let (mut last_stats_seq, mut last_stats_t) = (0u64, started);
    let mut stopped_by = "stop request".to_string();

    'run: loop {
        // Wait for the action batch answering `seq`.
        let mut backoff = Backoff::new();
        let mut polls = 0u32;
        let act = loop {
            if let Some(act) = actions.receive()? {
                if act.header().seq == seq {
                    break act;
                }
                stale += 1;
                continue;
            }
            backoff.snooze();
            polls = polls.wrapping_add(1);
            if !polls.is_multiple_of(128) {
                continue;
            }
            if ctx.should_stop() {
                break 'run;
            }
            ctx.report_on_request(&lat);
            match learner.poll(&ctx) {
                PeerEvent::Died => {
                    eprintln!(
                        "sim: the learner is gone (no live '{LEARNER_NODE}' node for {:?})",
                        super::PEER_TIMEOUT
                    );
                    node.cleanup_dead_nodes();
                    if ctx.on_peer_death == OnPeerDeath::Exit {
                        stopped_by = "learner died".into();
                        break 'run;
                    }
                    eprintln!("sim: waiting for a learner to rejoin at batch {seq}");
                }
                PeerEvent::Back => eprintln!("{}", rejoined(seq)),
                PeerEvent::Quiet => {}
            }
            if backoff.waited() > Backoff::YIELD {
                // A late or restarted learner gets the waited-for batch from
                // history when connections are updated.
                publisher.update_connections()?;
            }
        };
        act.prefetch_actions();
        if learner.gone && learner.heard_from() {
            eprintln!("{}", rejoined(seq));
        }
        let now = monotonic_ns();
        let slice = (seq % k_slices) as usize;
        rtt_interval.record(now - sent_at[slice]);
        let waited = now - last_sent;
        if waited <= LONG_WAIT_NS {
            wait_ns += waited;
        }

        // Step this slice straight into its next loaned sample: the cells in
        // place, the step records through `records` (module docs).
        let next = seq + k_slices;
        let mut sample = publisher.loan(next, next / k_slices)?;
        {
            let (_, meta, cells, final_cells) = sample.batch_mut().into_parts();
            let out = StepOut {
                cells,
                final_cells,
                meta: &mut records,
            };
            episodes += slices[slice].step(act.actions(), out) as u64;
            meta.copy_from_slice(&records);
        }
        drop(act);
        // The header's send stamp is also this loop's clock: loan + step is
        // the `step` histogram, and this slice's next round trip starts here.
        let sent = sample.send_stamped()?.1;
        sent_at[slice] = sent;
        last_sent = sent;
        step_rec.record(sent - now);
        step_ns += sent - now;
        env_steps += per_slice as u64;
        seq += 1;

        if sent >= next_stats {
            let dt = secs(last_sent - last_stats_t);
            let mut line = StatsLine {
                t: secs(last_sent - started),
                unix_ms: std::time::SystemTime::now()
                    .duration_since(std::time::UNIX_EPOCH)
                    .map_or(0, |d| d.as_millis() as u64),
                pid,
                seq,
                env_steps,
                steps_per_sec: (seq - last_stats_seq) as f64 * per_slice as f64 / dt,
                roundtrip_p99_us: rtt_interval.percentile_us(99.0),
                learner_alive: !learner.gone,
                minute: None,
                minute_roundtrip_p99_us: None,
            };
            fold(&mut lat, &mut step_rec, &rtt_interval);
            rtt_minute.absorb(&rtt_interval);
            rtt_interval.reset();
            if last_sent >= next_minute {
                line.minute = Some(minutes);
                line.minute_roundtrip_p99_us = Some(rtt_minute.percentile_us(99.0));
                rtt_minute.reset();
                minutes += 1;
                next_minute += MINUTE_NS;
            }
            writeln!(stats, "{}", serde_json::to_string(&line)?)?;
            ctx.report_on_request(&lat);
            (last_stats_seq, last_stats_t) = (seq, last_sent);
            next_stats = last_sent + STATS_EVERY_NS;
            if ctx.should_stop() {
                break;
            }
        }
    }

    fold(&mut lat, &mut step_rec, &rtt_interval);
    drop((actions, publisher, node));
    ctx.tidy();
    let seconds = secs(last_sent - started).max(1e-9);
    let report = SimReport {
        batches: seq + k_slices,
        env_steps,
        seconds,
        steps_per_sec: env_steps as f64 / seconds,
        stale_actions: stale,
        learner_deaths: learner.deaths,
        episodes,
        roundtrip_p50_us: lat.percentile_us("action_round_trip", 50.0),
        roundtrip_p99_us: lat.percentile_us("action_round_trip", 99.0),
        roundtrip_p999_us: lat.percentile_us("action_round_trip", 99.9),
        step_p50_us: lat.percentile_us("step", 50.0),
        wait_fraction: wait_ns as f64 / ((wait_ns + step_ns) as f64).max(1.0),
        stopped_by: stopped_by.clone(),
    };
    ctx.write_json("sim.report.json", &report)?;
    lat.write_reports(&ctx.dir)?;
    eprint!("{}", lat.table());
    eprintln!(
        "sim: {} batches, {:.2}M env-steps/s, stopped by {}",
        report.batches,
        report.steps_per_sec / 1e6,
        stopped_by
    );
    Ok(if stopped_by == "learner died" {
        std::process::ExitCode::from(EXIT_PEER_DIED)
    } else {
        std::process::ExitCode::SUCCESS
    })
}

/// Nanoseconds to seconds.
fn secs(ns: u64) -> f64 {
    ns as f64 * 1e-9
}

/// What the sim says when a learner is back after being declared gone.
fn rejoined(seq: u64) -> String {
    format!("sim: a learner rejoined; continuing at batch {seq}")
}
