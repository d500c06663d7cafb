//! `worldgraph run`: the three processes side by side.
//!
//! Starts the planner, the sim and the learner as separate processes of one
//! run, stops them together on Ctrl-C / SIGTERM (or after `--duration`),
//! restarts a process that died when `--on-peer-death wait` (its peers wait
//! for it and it rejoins), tears the run's shared memory down at the end
//! and prints a summary table from the processes' reports.

use std::path::{Path, PathBuf};
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use crate::pipeline::{Role, RunCmdArgs};
use crate::roles::{EXIT_CONFIG, EXIT_PEER_DIED, OnPeerDeath};
use crate::shutdown::{stop_flag, teardown};

/// A role that dies this soon after its start counts as a fast failure.
pub const FAST_FAILURE: Duration = Duration::from_secs(3);
/// Consecutive fast failures of one role after which `run` gives up.
pub const MAX_FAST_FAILURES: u32 = 3;

fn read_json(dir: &Path, name: &str) -> Option<serde_json::Value> {
    serde_json::from_slice(&std::fs::read(dir.join(name)).ok()?).ok()
}

/// Prints the end-of-run table from the processes' reports.
pub fn print_summary(dir: &Path, restarts: &[(Role, u32)], leftovers: &[PathBuf]) {
    let sim = read_json(dir, "sim.report.json");
    let learner = read_json(dir, "learner.report.json");
    let planner = read_json(dir, "planner.report.json");
    let f = |v: &Option<serde_json::Value>, k: &str| -> String {
        v.as_ref()
            .and_then(|v| v.pointer(k))
            .map_or("-".into(), |x| match x.as_f64() {
                Some(n) if n.fract() != 0.0 => format!("{n:.2}"),
                _ => x.to_string(),
            })
    };
    println!("\nrun summary ({})", dir.display());
    println!("  {:<40} {:>14}", "figure", "value");
    let rows = [
        ("sim: batches", f(&sim, "/batches")),
        ("sim: env-steps/s", f(&sim, "/steps_per_sec")),
        (
            "sim: action round trip p50 (us)",
            f(&sim, "/roundtrip_p50_us"),
        ),
        (
            "sim: action round trip p99 (us)",
            f(&sim, "/roundtrip_p99_us"),
        ),
        ("sim: episodes", f(&sim, "/episodes")),
        ("learner: batches answered", f(&learner, "/batches")),
        ("learner: batches lost", f(&learner, "/stream/lost")),
        (
            "learner: batches reordered",
            f(&learner, "/stream/reordered"),
        ),
        (
            "learner: mean episode return",
            f(&learner, "/mean_episode_return"),
        ),
        (
            "planner: graph nodes / edges",
            format!("{} / {}", f(&planner, "/nodes"), f(&planner, "/edges")),
        ),
        ("planner: cells visited", f(&planner, "/cells_visited")),
        ("planner: routes answered", f(&planner, "/routes_answered")),
    ];
    for (k, v) in rows {
        println!("  {k:<40} {v:>14}");
    }
    for (r, n) in restarts {
        println!("  {:<40} {:>14}", format!("{} restarts", r.name()), n);
    }
    println!(
        "  {:<40} {:>14}",
        "shared-memory files left behind",
        leftovers.len()
    );
}

/// Runs `worldgraph run`.
pub fn run(a: RunCmdArgs) -> anyhow::Result<std::process::ExitCode> {
    a.validate()?;
    crate::roles::sweep_stale_runs("run");
    let stop = stop_flag()?;
    let mut p = a.pipeline()?;
    p.start_all()?;
    let started = Instant::now();
    let deadline = a.run.duration.map(|d| started + Duration::from_secs_f64(d));
    let quiet_stderr = !std::io::IsTerminal::is_terminal(&std::io::stderr());
    let mut next_progress = started + Duration::from_secs(10);
    let mut fast_failures = [0u32; 3];
    let mut failed = false;
    'watch: loop {
        std::thread::sleep(Duration::from_millis(50));
        if stop.load(Ordering::Relaxed) || deadline.is_some_and(|d| Instant::now() >= d) {
            break;
        }
        if quiet_stderr && Instant::now() >= next_progress {
            next_progress += Duration::from_secs(10);
            let restarts: u32 = Role::ALL.iter().map(|&r| p.restarts(r)).sum();
            eprintln!(
                "run: {:.0} s, {restarts} restart(s)",
                started.elapsed().as_secs_f64()
            );
        }
        for (role, status) in p.poll_exited() {
            if status.code() == Some(EXIT_CONFIG as i32) {
                eprintln!(
                    "run: the {} process refused its configuration (see above); stopping the run",
                    role.name()
                );
                failed = true;
                break 'watch;
            }
            if status.code() == Some(EXIT_PEER_DIED as i32) || status.success() {
                eprintln!(
                    "run: the {} process ended ({status}); stopping the run",
                    role.name()
                );
                break 'watch;
            }
            eprintln!("run: the {} process died ({status})", role.name());
            let slot = Role::ALL.iter().position(|&r| r == role).unwrap_or(0);
            if p.uptime(role) < FAST_FAILURE {
                fast_failures[slot] += 1;
            } else {
                fast_failures[slot] = 1;
            }
            if fast_failures[slot] >= MAX_FAST_FAILURES {
                eprintln!(
                    "run: the {} process died {MAX_FAST_FAILURES} times within {} s of its \
                     start; giving up",
                    role.name(),
                    FAST_FAILURE.as_secs()
                );
                failed = true;
                break 'watch;
            }
            if a.run.on_peer_death == OnPeerDeath::Wait {
                eprintln!("run: restarting the {} process", role.name());
                p.spawn(role)?;
            } else {
                failed = true;
                break 'watch;
            }
        }
    }
    p.stop_all(Duration::from_secs(3));
    let leftovers = teardown(&a.run.run)?;
    let restarts: Vec<(Role, u32)> = Role::ALL.iter().map(|&r| (r, p.restarts(r))).collect();
    print_summary(&a.dir(), &restarts, &leftovers);
    Ok(if failed {
        std::process::ExitCode::FAILURE
    } else {
        std::process::ExitCode::SUCCESS
    })
}
