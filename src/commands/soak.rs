//! `worldgraph soak`: the three processes for M minutes on this machine,
//! optionally SIGKILLing a random one every S seconds, with a report of what
//! a long run must not do: lose or reorder batches, grow in memory, leave
//! shared memory behind, or fail to recover.
//!
//! - **Lost / reordered** batches come from every learner process's stream
//!   accounting (`learner.stream.jsonl`, one line per 250 ms with its pid,
//!   so a killed learner's count survives it).
//! - **Memory growth**: each process's resident set, sampled every second;
//!   growth is the last sample minus the one 30 s into that process's life.
//! - **Recovery** after a kill: the time until the sim publishes batches
//!   again with a learner answering (progress in `sim.stats.jsonl` after the
//!   restart).
//! - **Round-trip p99 per minute** of the soak: the sims' 250 ms interval
//!   p99s, grouped by the soak's minutes (the median and the worst interval
//!   of each minute), so restarts do not hide a minute.
//! - **Shared memory left behind**: the run's `/dev/shm` files after teardown.
//!
//! Kills begin once the pipeline flows (the sim publishes and, with
//! `--learner-trains`, the learner has finished an iteration), so a slow
//! start on a loaded machine does not turn the first kill into a kill of a
//! process still loading.
//!
//! Exits non-zero when anything was lost, reordered, leaked or left behind,
//! a recovery failed, or the pipeline never flowed.

use std::collections::BTreeMap;
use std::io::BufRead;
use std::path::{Path, PathBuf};
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use clap::Args;
use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};

use super::soak_report::{KillCost, Recovery, SoakReport, TrainingReport};
use crate::pipeline::Role;
use crate::pipeline::RunCmdArgs;
use crate::roles::learner::PolicyKind;
use crate::roles::learner_train::TRAIN_LOG;
use crate::roles::planner::GraphArgs;
use crate::roles::rss_kib;
use crate::roles::{OnPeerDeath, RunArgs};
use crate::shutdown::{stop_flag, teardown};
use crate::world_args::WorldArgs;

/// Growth of a process's resident set above which the soak fails (KiB).
pub const RSS_GROWTH_LIMIT_KIB: i64 = 16 * 1024;
/// How long a recovery may take before it counts as failed.
pub const RECOVERY_LIMIT: Duration = Duration::from_secs(30);

/// No kill in the soak's last this many seconds: a kill leaves its
/// recovery this long to happen inside the soak (and the soak still waits
/// for the recovery of its last kill, up to [`RECOVERY_LIMIT`]).
pub const KILL_MARGIN_S: f64 = 5.0;

/// True if a kill `at_s` seconds into a soak of `duration_s` seconds may be
/// made: it leaves at least [`KILL_MARGIN_S`] before the end.
pub fn kill_allowed(at_s: f64, duration_s: f64) -> bool {
    at_s + KILL_MARGIN_S <= duration_s
}

/// The kill times of a soak of `duration_s` seconds killing every
/// `every_s` seconds, each recovering at once (a slow recovery delays the
/// kills after it): the schedule the soak follows through [`kill_allowed`].
#[cfg(test)]
pub fn kill_schedule(duration_s: f64, every_s: f64) -> Vec<f64> {
    (1..)
        .map(|k| k as f64 * every_s)
        .take_while(|&t| kill_allowed(t, duration_s))
        .collect()
}

/// `soak` options.
#[derive(Debug, Clone, Args)]
pub struct SoakArgs {
    #[command(flatten)]
    pub world: WorldArgs,
    /// Minutes to run.
    #[arg(long, default_value_t = 10.0)]
    pub minutes: f64,
    /// SIGKILL a random process (sim, learner or planner) every this many
    /// seconds, the first this long after the pipeline flows (the sim
    /// publishes and, with --learner-trains, the learner has finished an
    /// iteration); none in the last 5 seconds, and the soak waits for the
    /// recovery of its last kill.
    #[arg(long)]
    pub kill_every: Option<f64>,
    /// Environments in the batch.
    #[arg(long, default_value_t = 256)]
    pub envs: usize,
    /// Slices the sim publishes its batch in (see `run --slices`)
    /// [default: 2; 1 with --learner-trains, which needs it].
    #[arg(long)]
    pub slices: Option<usize>,
    /// The learner asks the planner for a route every this many batches
    /// (not with --learner-trains).
    #[arg(long, default_value_t = 1000)]
    pub route_every: u64,
    /// The learner trains π_g (`learner serve --policy train-gcp`) instead
    /// of answering with random actions: a killed learner resumes from its
    /// last checkpoint, and the report says what each kill cost the training.
    #[arg(long)]
    pub learner_trains: bool,
    /// With --learner-trains: checkpoint π_g every this many iterations.
    #[arg(long, default_value_t = 10)]
    pub checkpoint_every: u64,
    /// Run directory [default: runs/soak-<pid>].
    #[arg(long)]
    pub run_dir: Option<PathBuf>,
    /// Print the report as JSON.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, Default)]
struct ProcMem {
    started: Option<Instant>,
    baseline: Option<u64>,
    last: u64,
    max: u64,
}

/// The sim's `(pid, seq)` from its latest progress line.
type SimProgress = (u32, u64);

/// The last line of `sim.stats.jsonl`, if any.
fn last_progress(path: &Path) -> Option<SimProgress> {
    let f = std::fs::File::open(path).ok()?;
    let line = std::io::BufReader::new(f)
        .lines()
        .map_while(Result::ok)
        .filter(|l| !l.is_empty())
        .last()?;
    let v: serde_json::Value = serde_json::from_str(&line).ok()?;
    Some((v["pid"].as_u64()? as u32, v["seq"].as_u64()?))
}

/// Whether the pipeline flows: the sim has published (a progress line in
/// `sim.stats.jsonl`) and, when the learner trains, it has finished an
/// iteration (`learner-train.jsonl`). The kill clock starts then, so that
/// the first kill finds processes at work rather than still loading.
fn pipeline_flows(stats: &Path, train_log: Option<&Path>) -> bool {
    let learner_ready = train_log.is_none_or(|log| {
        std::fs::File::open(log).is_ok_and(|f| {
            std::io::BufReader::new(f)
                .lines()
                .map_while(Result::ok)
                .any(|l| l.contains("\"event\":\"iteration\""))
        })
    });
    learner_ready && last_progress(stats).is_some()
}

/// Runs the soak.
pub fn run(a: SoakArgs) -> anyhow::Result<std::process::ExitCode> {
    anyhow::ensure!(a.minutes > 0.0, "--minutes must be positive");
    if let Some(k) = a.kill_every {
        anyhow::ensure!(k >= 2.0, "--kill-every must be at least 2 seconds");
    }
    let stop = stop_flag()?;
    let mut soak = Soak::start(a)?;
    // Past the end, the soak only waits for the recovery of its last kill.
    while soak.goes_on() && !stop.load(Ordering::Relaxed) {
        std::thread::sleep(Duration::from_millis(50));
        soak.tick()?;
    }
    let (report, dir, json) = soak.finish()?;
    sim::atomic_file::write_atomic(
        &dir.join("soak.report.json"),
        &serde_json::to_vec_pretty(&report)?,
    )?;
    if json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        print_report(&report, &dir);
    }
    Ok(if report.ok {
        std::process::ExitCode::SUCCESS
    } else {
        std::process::ExitCode::FAILURE
    })
}

/// A kill awaiting its recovery: its index in the recoveries, when it was
/// made, and the sim's progress just before it.
type Pending = (usize, Instant, Option<SimProgress>);

/// A soak under way: the pipeline, its kill schedule, the kills made and
/// the memory samples taken.
struct Soak {
    a: SoakArgs,
    run: String,
    dir: PathBuf,
    p: crate::pipeline::Pipeline,
    start: Instant,
    start_unix_ms: u64,
    end: Instant,
    rng: SmallRng,
    /// When the pipeline first flowed ([`pipeline_flows`]).
    flowing_since: Option<Instant>,
    next_kill: Option<Instant>,
    pending: Option<Pending>,
    recoveries: Vec<Recovery>,
    mem: BTreeMap<(Role, u32), ProcMem>,
    next_sample: Instant,
    bar: indicatif::ProgressBar,
}

impl Soak {
    /// Starts the three processes in a fresh run directory.
    fn start(a: SoakArgs) -> anyhow::Result<Self> {
        let run = format!("soak-{}", std::process::id());
        let dir = a
            .run_dir
            .clone()
            .unwrap_or_else(|| PathBuf::from("runs").join(&run));
        let args = RunCmdArgs {
            world: a.world.clone(),
            graph: GraphArgs {
                nodes: 32,
                node_file: None,
                walks_per_node: 128,
                walk_len: 64,
                graph_seed: None,
                no_shorten: false,
            },
            run: RunArgs {
                run: run.clone(),
                run_dir: Some(dir.clone()),
                on_peer_death: OnPeerDeath::Wait,
                duration: None,
                cpu: None,
            },
            envs: a.envs,
            slices: a.slices.unwrap_or(if a.learner_trains { 1 } else { 2 }),
            threads: 1,
            policy: if a.learner_trains {
                PolicyKind::TrainGcp
            } else {
                PolicyKind::Random
            },
            route_every: if a.learner_trains { 0 } else { a.route_every },
            checkpoint_every: a.checkpoint_every,
            logs_to_files: true,
            pin: false,
        };
        args.validate()?;
        let mut p = args.pipeline()?;
        p.start_all()?;
        let start = Instant::now();
        let start_unix_ms = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_millis() as u64);
        let bar = indicatif::ProgressBar::new((a.minutes * 60.0) as u64);
        bar.set_style(
            indicatif::ProgressStyle::with_template("soak {bar:40} {pos}/{len} s  {msg}")
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
        );
        Ok(Self {
            end: start + Duration::from_secs_f64(a.minutes * 60.0),
            rng: SmallRng::seed_from_u64(a.world.seed),
            a,
            run,
            dir,
            p,
            start,
            start_unix_ms,
            flowing_since: None,
            next_kill: None,
            pending: None,
            recoveries: Vec::new(),
            mem: BTreeMap::new(),
            next_sample: start,
            bar,
        })
    }

    fn stats(&self) -> PathBuf {
        self.dir.join("sim.stats.jsonl")
    }

    /// Until the end, and past it until the last kill's recovery.
    fn goes_on(&self) -> bool {
        Instant::now() < self.end || self.pending.is_some()
    }

    /// One look at the pipeline: restart what exited, sample memory, settle
    /// a pending recovery, start the kill clock once the pipeline flows,
    /// and kill when a kill is due.
    fn tick(&mut self) -> anyhow::Result<()> {
        let now = Instant::now();
        for (role, status) in self.p.poll_exited() {
            self.bar.println(format!(
                "soak: the {} process exited ({status}); restarting it",
                role.name()
            ));
            self.p.spawn(role)?;
        }
        if now >= self.next_sample {
            self.next_sample = now + Duration::from_secs(1);
            self.sample(now);
        }
        self.settle_recovery(now);
        if self.flowing_since.is_none() {
            let train_log = self.a.learner_trains.then(|| self.dir.join(TRAIN_LOG));
            if pipeline_flows(&self.stats(), train_log.as_deref()) {
                self.flowing_since = Some(now);
                self.next_kill = self.a.kill_every.map(|k| now + Duration::from_secs_f64(k));
            }
        }
        if self.pending.is_none()
            && self.next_kill.is_some_and(|k| now >= k)
            && kill_allowed((now - self.start).as_secs_f64(), self.a.minutes * 60.0)
        {
            self.kill()?;
        }
        Ok(())
    }

    /// Each process's resident set, and the progress bar.
    fn sample(&mut self, now: Instant) {
        for role in Role::ALL {
            if let Some(pid) = self.p.pid(role)
                && let Some(rss) = rss_kib(pid)
            {
                let m = self.mem.entry((role, pid)).or_default();
                let born = *m.started.get_or_insert(now);
                if m.baseline.is_none() && now - born >= Duration::from_secs(30) {
                    m.baseline = Some(rss);
                }
                m.last = rss;
                m.max = m.max.max(rss);
            }
        }
        self.bar.set_position((now - self.start).as_secs());
        // No bar on a non-terminal stderr: a line every 10 s instead.
        let secs = (now - self.start).as_secs();
        if secs > 0
            && secs.is_multiple_of(10)
            && !std::io::IsTerminal::is_terminal(&std::io::stderr())
        {
            // (A kill is in `recoveries` from the moment it is made.)
            eprintln!("soak: {secs} s, kills {}", self.recoveries.len());
        }
        self.bar
            .set_message(format!("kills {}", self.recoveries.len()));
    }

    /// A pending recovery: batches flow again once the sim's progress moved
    /// past what it was right after the restart.
    fn settle_recovery(&mut self, now: Instant) {
        let Some((i, killed_at, before)) = self.pending else {
            return;
        };
        let stats = self.stats();
        let moved = match (before, last_progress(&stats)) {
            (Some((pid0, seq0)), Some((pid1, seq1))) => pid1 != pid0 || seq1 > seq0 + 2,
            (None, Some(_)) => true,
            _ => false,
        };
        // A restarted sim appends from seq 0: any two lines of it count.
        if moved && now - killed_at > Duration::from_millis(300) {
            let settle = last_progress(&stats);
            std::thread::sleep(Duration::from_millis(300));
            if last_progress(&stats) != settle {
                self.recoveries[i].recovered_after_s = Some(killed_at.elapsed().as_secs_f64());
                self.pending = None;
            }
        } else if now - killed_at > RECOVERY_LIMIT {
            self.bar.println(format!(
                "soak: no recovery within {RECOVERY_LIMIT:?} after killing the {}",
                self.recoveries[i].role.name()
            ));
            self.pending = None;
        }
    }

    /// SIGKILLs a random process and restarts it.
    fn kill(&mut self) -> anyhow::Result<()> {
        let role = Role::ALL[self.rng.random_range(0..Role::ALL.len())];
        let before = last_progress(&self.stats());
        let pid = self.p.pid(role);
        self.p.kill_hard(role)?;
        let killed_at = Instant::now();
        self.bar.println(format!(
            "soak: {:>6.1} s  SIGKILL {}",
            (killed_at - self.start).as_secs_f64(),
            role.name()
        ));
        self.p.spawn(role)?;
        self.recoveries.push(Recovery {
            at_s: (killed_at - self.start).as_secs_f64(),
            role,
            pid,
            recovered_after_s: None,
            training: None,
        });
        self.pending = Some((self.recoveries.len() - 1, killed_at, before));
        self.next_kill = self
            .a
            .kill_every
            .map(|s| killed_at + Duration::from_secs_f64(s));
        Ok(())
    }

    /// Stops the processes, tears the run's shared memory down and reads
    /// the report out of the logs. Returns it with the run directory and
    /// whether it is wanted as JSON.
    fn finish(mut self) -> anyhow::Result<(SoakReport, PathBuf, bool)> {
        self.bar.finish_and_clear();
        self.p.stop_all(Duration::from_secs(5));
        let left: Vec<String> = teardown(&self.run)?
            .iter()
            .map(|p| p.display().to_string())
            .collect();
        let (lost, reordered, sim_restarts_seen) = stream_counts(&self.dir);
        let (batches, per_minute, worst_per_minute) =
            sim_figures(&self.stats(), self.start_unix_ms);
        let (growth, max_rss) = memory_figures(&self.mem);
        let a = &self.a;
        let training = a.learner_trains.then(|| {
            super::soak_training::analyse(
                &self.dir,
                &mut self.recoveries,
                self.start_unix_ms,
                &a.world,
                a.envs,
                a.checkpoint_every,
            )
        });
        let trained = training
            .as_ref()
            .is_none_or(|t| t.final_checkpoint_error.is_none() && t.iterations_kept > 0);
        let failed_recoveries = self
            .recoveries
            .iter()
            .filter(|r| r.recovered_after_s.is_none())
            .count();
        let leaked = growth.values().any(|&g| g > RSS_GROWTH_LIMIT_KIB);
        let flowed_after_s = self.flowing_since.map(|t| (t - self.start).as_secs_f64());
        let ok = lost == 0
            && reordered == 0
            && left.is_empty()
            && !leaked
            && failed_recoveries == 0
            && trained
            && batches > 0
            && flowed_after_s.is_some();
        let report = SoakReport {
            minutes: self.start.elapsed().as_secs_f64() / 60.0,
            flowed_after_s,
            batches,
            lost,
            reordered,
            sim_restarts_seen,
            recoveries: self.recoveries,
            rss_growth_kib: growth,
            rss_max_kib: max_rss,
            roundtrip_p99_us_per_minute: per_minute,
            roundtrip_p99_us_worst_interval_per_minute: worst_per_minute,
            shm_left_behind: left,
            training,
            ok,
        };
        Ok((report, self.dir, self.a.json))
    }
}

/// Lost, reordered and sim restarts seen: the last line of every learner
/// process's stream accounting (`learner.stream.jsonl`), summed.
fn stream_counts(dir: &Path) -> (u64, u64, u64) {
    let mut per_pid: BTreeMap<u64, serde_json::Value> = BTreeMap::new();
    if let Ok(f) = std::fs::File::open(dir.join("learner.stream.jsonl")) {
        for l in std::io::BufReader::new(f).lines().map_while(Result::ok) {
            if let Ok(v) = serde_json::from_str::<serde_json::Value>(&l)
                && let Some(pid) = v["pid"].as_u64()
            {
                per_pid.insert(pid, v["stream"].clone());
            }
        }
    }
    let sum = |k: &str| {
        per_pid
            .values()
            .map(|s| s[k].as_u64().unwrap_or(0))
            .sum::<u64>()
    };
    (sum("lost"), sum("reordered"), sum("sim_restarts"))
}

/// Batches published by all sim processes, and per soak minute the median
/// and the worst of the sims' 250 ms round-trip p99s, from `sim.stats.jsonl`.
fn sim_figures(stats: &Path, start_unix_ms: u64) -> (u64, Vec<f64>, Vec<f64>) {
    let mut last_seq: BTreeMap<u64, u64> = BTreeMap::new();
    let mut minutes: BTreeMap<u64, Vec<f64>> = BTreeMap::new();
    if let Ok(f) = std::fs::File::open(stats) {
        for l in std::io::BufReader::new(f).lines().map_while(Result::ok) {
            if let Ok(v) = serde_json::from_str::<serde_json::Value>(&l) {
                last_seq.insert(
                    v["pid"].as_u64().unwrap_or(0),
                    v["seq"].as_u64().unwrap_or(0),
                );
                if let (Some(p99), Some(ms)) =
                    (v["roundtrip_p99_us"].as_f64(), v["unix_ms"].as_u64())
                    && p99.is_finite()
                {
                    minutes
                        .entry(ms.saturating_sub(start_unix_ms) / 60_000)
                        .or_default()
                        .push(p99);
                }
            }
        }
    }
    let (mut per_minute, mut worst_per_minute) = (Vec::new(), Vec::new());
    for v in minutes.values_mut() {
        v.sort_by(f64::total_cmp);
        per_minute.push(v[v.len() / 2]);
        worst_per_minute.push(v[v.len() - 1]);
    }
    let batches = last_seq.values().map(|s| s + 1).sum::<u64>();
    (batches, per_minute, worst_per_minute)
}

/// Per role: the largest resident-set growth over processes that lived at
/// least 60 s, and the largest resident set (KiB).
fn memory_figures(
    mem: &BTreeMap<(Role, u32), ProcMem>,
) -> (BTreeMap<String, i64>, BTreeMap<String, u64>) {
    let mut growth: BTreeMap<String, i64> = BTreeMap::new();
    let mut max_rss: BTreeMap<String, u64> = BTreeMap::new();
    for ((role, _), m) in mem {
        let e = max_rss.entry(role.name().into()).or_default();
        *e = (*e).max(m.max);
        if let (Some(b), Some(st)) = (m.baseline, m.started)
            && st.elapsed() >= Duration::from_secs(60)
        {
            let g = growth.entry(role.name().into()).or_insert(i64::MIN);
            *g = (*g).max(m.last as i64 - b as i64);
        }
    }
    (growth, max_rss)
}

/// Prints the report as a table: the stream, memory and round-trip
/// figures, the training's (with `--learner-trains`), each kill, and the
/// result.
fn print_report(r: &SoakReport, dir: &Path) {
    println!("soak report ({})", dir.display());
    print_pipeline_figures(r);
    if let Some(t) = &r.training {
        print_training(t);
    }
    if !r.recoveries.is_empty() {
        println!("  kills:");
        for k in &r.recoveries {
            print_kill(k);
        }
    }
    println!("  result: {}", if r.ok { "OK" } else { "FAILED" });
}

/// The report's lines on the pipeline: its start, batches, memory, round
/// trips and shared memory left behind.
fn print_pipeline_figures(r: &SoakReport) {
    println!("  {:<34} {:>12.1}", "minutes", r.minutes);
    match r.flowed_after_s {
        Some(s) => println!("  {:<34} {:>12.1}", "pipeline flowing after (s)", s),
        None => println!("  pipeline NEVER flowed (no kill was made)"),
    }
    println!("  {:<34} {:>12}", "batches published", r.batches);
    println!("  {:<34} {:>12}", "batches lost", r.lost);
    println!("  {:<34} {:>12}", "batches reordered", r.reordered);
    println!(
        "  {:<34} {:>12}",
        "sim restarts seen by learners", r.sim_restarts_seen
    );
    for (role, g) in &r.rss_growth_kib {
        println!("  {:<34} {:>12}", format!("{role} RSS growth (KiB)"), g);
    }
    for (role, m) in &r.rss_max_kib {
        println!("  {:<34} {:>12}", format!("{role} RSS max (KiB)"), m);
    }
    let fmt = |v: &[f64]| {
        v.iter()
            .map(|x| format!("{x:.0}"))
            .collect::<Vec<_>>()
            .join(" ")
    };
    println!(
        "  {:<34} {}",
        "round-trip p99 per minute (us)",
        fmt(&r.roundtrip_p99_us_per_minute)
    );
    println!(
        "  {:<34} {}",
        "  worst 250 ms interval (us)",
        fmt(&r.roundtrip_p99_us_worst_interval_per_minute)
    );
    println!(
        "  {:<34} {:>12}",
        "shared-memory files left behind",
        r.shm_left_behind.len()
    );
}

/// The report's training section (`--learner-trains`).
fn print_training(t: &TrainingReport) {
    println!(
        "  training (π_g, checkpoint every {} iterations)",
        t.checkpoint_every
    );
    for (what, n) in [
        ("iterations run (all learners)", t.iterations_run),
        ("iterations kept (final checkpoint)", t.iterations_kept),
        ("iterations lost to learner kills", t.iterations_lost),
        ("checkpoints written", t.checkpoints_written),
        ("rollouts dropped (sim died)", t.rollouts_dropped),
        ("learner processes", t.learner_processes as u64),
    ] {
        println!("    {what:<32} {n:>12}");
    }
    println!(
        "    {:<32} {:>12.2}",
        "median time per iteration (s)", t.median_iteration_s
    );
    match &t.final_checkpoint_error {
        None => println!("    {:<32} {:>12}", "final π_g loads", "yes"),
        Some(e) => println!("    final π_g does NOT load: {e}"),
    }
}

/// The report's line on one kill: when, which process, its recovery and,
/// with `--learner-trains`, what it cost the training.
fn print_kill(k: &Recovery) {
    let cost = match &k.training {
        Some(KillCost {
            iterations_lost,
            pause_s,
        }) => {
            let lost = iterations_lost.map_or(String::new(), |n| {
                format!(", {n} iteration{} lost", if n == 1 { "" } else { "s" })
            });
            let pause = pause_s.map_or(", no iteration after it".into(), |p| {
                format!(", training paused {p:.1} s")
            });
            format!("{lost}{pause}")
        }
        None => String::new(),
    };
    match k.recovered_after_s {
        Some(s) => println!(
            "    {:>7.1} s  {:<8} recovered after {:.2} s{cost}",
            k.at_s,
            k.role.name(),
            s
        ),
        None => println!(
            "    {:>7.1} s  {:<8} NOT recovered{cost}",
            k.at_s,
            k.role.name()
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Issue 21, item 7: `--minutes 1 --kill-every 20` killed at 60.0 s, the
    /// instant the soak ended, and reported it NOT recovered.
    #[test]
    fn no_kill_is_scheduled_in_the_soaks_last_seconds() {
        assert_eq!(kill_schedule(60.0, 20.0), [20.0, 40.0]);
        assert_eq!(kill_schedule(60.0, 25.0), [25.0, 50.0]);
        assert_eq!(kill_schedule(60.0, 30.0), [30.0]);
        assert_eq!(kill_schedule(600.0, 30.0).len(), 19);
        assert!(kill_schedule(4.0, 2.0).is_empty());
        for (minutes, every) in [(1.0, 20.0), (0.4, 6.0), (10.0, 30.0), (2.0, 7.5)] {
            let duration = minutes * 60.0;
            for t in kill_schedule(duration, every) {
                assert!(
                    t + KILL_MARGIN_S <= duration,
                    "kill at {t} s of {duration} s"
                );
            }
        }
        // A kill delayed by a slow recovery into the last seconds is skipped.
        assert!(kill_allowed(55.0, 60.0));
        assert!(!kill_allowed(55.1, 60.0));
        assert!(!kill_allowed(60.0, 60.0));
    }
}
