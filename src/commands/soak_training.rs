//! `soak --learner-trains`: what the kills cost a learner that trains π_g
//! (`learner serve --policy train-gcp`), from its per-iteration log
//! (`learner-train.jsonl`, one line per iteration with the pid, the time,
//! iterations done and the last checkpointed iteration, plus a `start` line
//! per process with the iteration it resumed from).
//!
//! - **Iterations lost** to a learner kill: the killed process's last
//!   iteration minus the iteration its successor resumed from (the
//!   iterations since its last checkpoint; the rollout it was in when
//!   killed is lost too, and not counted).
//! - **Training pause** of any kill: the longest time without an iteration
//!   finishing (by any learner process) in the [`PAUSE_WINDOW_S`] after the
//!   kill, or until the next kill; to be read against the median time
//!   between iterations. (An iteration can still finish just after a sim
//!   is killed, from the batches it already had: the stall follows it.)
//! - **Final π_g**: the checkpoint left in `<run dir>/learner-train/` is
//!   loaded back into a fresh π_g of the soak's settings.

use std::collections::BTreeMap;
use std::io::BufRead;
use std::path::Path;

use super::soak_report::{KillCost, Recovery, TrainingReport};
use crate::pipeline::Role;
use crate::roles::learner_train::{CHECKPOINT_DIR, TRAIN_LOG, open};
use crate::world_args::WorldArgs;

/// How long after a kill its training pause is looked for.
pub const PAUSE_WINDOW_S: f64 = 10.0;

#[derive(Debug, Default)]
struct ProcLog {
    start_ms: u64,
    resumed_from: u64,
    last_iteration: u64,
    checkpoints: u64,
    dropped: u64,
    iteration_ms: Vec<u64>,
}

fn read_log(path: &Path) -> BTreeMap<u64, ProcLog> {
    let mut procs: BTreeMap<u64, ProcLog> = BTreeMap::new();
    let Ok(f) = std::fs::File::open(path) else {
        return procs;
    };
    for l in std::io::BufReader::new(f).lines().map_while(Result::ok) {
        let Ok(v) = serde_json::from_str::<serde_json::Value>(&l) else {
            continue; // a line torn by a kill
        };
        let (Some(pid), Some(ms), Some(it)) = (
            v["pid"].as_u64(),
            v["unix_ms"].as_u64(),
            v["iteration"].as_u64(),
        ) else {
            continue;
        };
        let p = procs.entry(pid).or_default();
        match v["event"].as_str() {
            Some("start") => {
                (p.start_ms, p.resumed_from, p.last_iteration) = (ms, it, it);
            }
            Some("iteration") => {
                p.last_iteration = it;
                p.iteration_ms.push(ms);
            }
            Some("dropped") => p.dropped += 1,
            _ => {}
        }
        p.checkpoints += u64::from(v["checkpointed"].as_bool() == Some(true));
    }
    // A learner killed after committing a checkpoint but before logging
    // that iteration reached it all the same: the next learner (started
    // after it; learners run one at a time) resumes from that checkpoint.
    let mut by_start: Vec<&mut ProcLog> = procs.values_mut().collect();
    by_start.sort_by_key(|p| p.start_ms);
    for i in 1..by_start.len() {
        let resumed = by_start[i].resumed_from;
        let killed = &mut by_start[i - 1];
        killed.last_iteration = killed.last_iteration.max(resumed);
    }
    procs
}

/// The training section of a soak in `dir`, and each kill's cost filled
/// into `recoveries` (`start_unix_ms`: the soak's start).
pub fn analyse(
    dir: &Path,
    recoveries: &mut [Recovery],
    start_unix_ms: u64,
    world: &WorldArgs,
    envs: usize,
    checkpoint_every: u64,
) -> TrainingReport {
    let procs = read_log(&dir.join(TRAIN_LOG));
    let mut all_ms: Vec<u64> = procs
        .values()
        .flat_map(|p| p.iteration_ms.clone())
        .collect();
    all_ms.sort_unstable();
    let mut gaps: Vec<u64> = procs
        .values()
        .flat_map(|p| p.iteration_ms.windows(2).map(|w| w[1] - w[0]))
        .collect();
    gaps.sort_unstable();
    let kills_ms: Vec<u64> = recoveries
        .iter()
        .map(|r| start_unix_ms + (r.at_s * 1000.0) as u64)
        .collect();
    for (i, r) in recoveries.iter_mut().enumerate() {
        let kill_ms = kills_ms[i];
        let window_end = kills_ms
            .get(i + 1)
            .copied()
            .unwrap_or(u64::MAX)
            .min(kill_ms + (PAUSE_WINDOW_S * 1000.0) as u64);
        r.training = Some(KillCost {
            iterations_lost: iterations_lost(&procs, r, kill_ms),
            pause_s: training_pause(&all_ms, kill_ms, window_end),
        });
    }
    let (iterations_kept, final_checkpoint_error) = final_checkpoint(dir, world, envs);
    TrainingReport {
        checkpoint_every,
        learner_processes: procs.len(),
        iterations_run: procs
            .values()
            .map(|p| p.last_iteration - p.resumed_from)
            .sum(),
        iterations_kept,
        iterations_lost: recoveries
            .iter()
            .filter_map(|r| r.training.as_ref()?.iterations_lost)
            .sum(),
        checkpoints_written: procs.values().map(|p| p.checkpoints).sum(),
        rollouts_dropped: procs.values().map(|p| p.dropped).sum(),
        median_iteration_s: gaps
            .get(gaps.len() / 2)
            .map_or(f64::NAN, |&g| g as f64 / 1000.0),
        final_checkpoint_error,
    }
}

/// The training pause (s) of a kill at `kill_ms`: the longest time without
/// an iteration finishing (`all_ms`: every iteration's end, sorted) until
/// `window_end`; `None` when no iteration finished after the kill.
fn training_pause(all_ms: &[u64], kill_ms: u64, window_end: u64) -> Option<f64> {
    // Gaps between consecutive iterations that end after the kill and
    // begin within the window; the first one may begin before the kill.
    let first_after = all_ms.partition_point(|&t| t <= kill_ms);
    (first_after < all_ms.len()).then(|| {
        let from = first_after.saturating_sub(1);
        let gaps = all_ms[from..]
            .windows(2)
            .take_while(|w| w[0] < window_end)
            .map(|w| w[1] - w[0]);
        let first = all_ms[first_after].saturating_sub(kill_ms);
        gaps.fold(first, u64::max) as f64 / 1000.0
    })
}

/// For a learner kill (`r`, at `kill_ms`): the killed process's last
/// iteration minus the one the next learner process resumed from; `None`
/// for other kills, or when no learner started after it.
fn iterations_lost(procs: &BTreeMap<u64, ProcLog>, r: &Recovery, kill_ms: u64) -> Option<u64> {
    let (Role::Learner, Some(pid)) = (r.role, r.pid) else {
        return None;
    };
    let killed = procs.get(&u64::from(pid))?;
    let next = procs
        .values()
        .filter(|p| p.start_ms > kill_ms)
        .min_by_key(|p| p.start_ms)?;
    Some(killed.last_iteration.saturating_sub(next.resumed_from))
}

/// The iterations in the checkpoint left in `dir` (loaded into a fresh π_g
/// of the soak's settings), or 0 and why it does not load.
fn final_checkpoint(dir: &Path, world: &WorldArgs, envs: usize) -> (u64, Option<String>) {
    let ckpt = dir.join(CHECKPOINT_DIR);
    let loaded = world.build().and_then(|(layout, cfg)| {
        open(
            &ckpt,
            &layout,
            envs,
            cfg.task.name(),
            cfg.task.num_actions(),
            world.seed,
        )
    });
    match loaded {
        Ok((_, state)) if ckpt.join("gcp.ot").is_file() => (state.iterations, None),
        Ok(_) => (0, Some(format!("no checkpoint in {}", ckpt.display()))),
        Err(e) => (0, Some(format!("{e:#}"))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn line(pid: u64, ms: u64, event: &str, iteration: u64, checkpointed: bool) -> String {
        serde_json::json!({
            "pid": pid, "unix_ms": ms, "event": event, "iteration": iteration,
            "checkpointed": checkpointed,
        })
        .to_string()
    }

    #[test]
    fn a_learner_killed_between_its_checkpoint_and_its_log_line_ran_to_the_checkpoint() {
        // Learner 1 logs iterations 1–9 (checkpoint every 5) and is killed
        // after committing iteration 10's checkpoint, before its log line;
        // learner 2 resumes from 10 and runs to 14.
        let mut log: Vec<String> = vec![line(1, 0, "start", 0, false)];
        log.extend((1..10).map(|i| line(1, i, "iteration", i, i % 5 == 0)));
        log.push(line(2, 100, "start", 10, false));
        log.extend((11..15).map(|i| line(2, 100 + i, "iteration", i, false)));
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("log.jsonl");
        std::fs::write(&path, log.join("\n")).unwrap();
        let procs = read_log(&path);
        let run: u64 = procs
            .values()
            .map(|p| p.last_iteration - p.resumed_from)
            .sum();
        assert_eq!(procs[&1].last_iteration, 10);
        assert_eq!(
            run, 14,
            "every iteration the final checkpoint holds was run"
        );
    }
}
