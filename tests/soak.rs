//! `worldgraph soak --learner-trains`: a short soak whose learner trains π_g
//! while the soak SIGKILLs a process every few seconds. The killed learner
//! must resume from its last checkpoint (the iteration count keeps growing
//! across kills), lose at most one checkpoint interval, and the stream must
//! lose and reorder nothing.

use std::path::Path;
use std::time::Duration;

use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};

use crate::reliability::{run_bounded_with_pid, shm_files};

/// The roles the soak kills for `seed`, in order: it draws them as
/// `Role::ALL[rng.random_range(0..3)]` from `SmallRng::seed_from_u64(seed)`,
/// `Role::ALL` being planner, sim, learner.
fn kill_order(seed: u64, n: usize) -> Vec<&'static str> {
    let mut rng = SmallRng::seed_from_u64(seed);
    (0..n)
        .map(|_| ["planner", "sim", "learner"][rng.random_range(0..3usize)])
        .collect()
}

fn json_lines(path: &std::path::Path) -> Vec<serde_json::Value> {
    std::fs::read_to_string(path)
        .unwrap_or_default()
        .lines()
        .filter_map(|l| serde_json::from_str(l).ok())
        .collect()
}

#[test]
fn soak_with_a_training_learner_resumes_after_kills() {
    // A seed whose first kill is the learner and second the sim, so both a
    // resume and a rollout cut by a sim death happen within the soak.
    let seed = (0..1000u64)
        .find(|&s| kill_order(s, 2) == ["learner", "sim"])
        .expect("a seed with a learner kill first");
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("soak");
    let every = 5u64;
    let (every_s, seed_s) = (every.to_string(), seed.to_string());
    let (pid, out) = run_bounded_with_pid(
        &[
            "soak",
            "--minutes",
            "0.4",
            "--kill-every",
            "6",
            "--learner-trains",
            "--checkpoint-every",
            &every_s,
            "--maze",
            "small",
            "--envs",
            "8",
            "--seed",
            &seed_s,
            "--json",
            "--run-dir",
            dir.to_str().unwrap(),
        ],
        Duration::from_secs(120),
    );
    let run = format!("soak-{pid}");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "soak failed: {stderr}");
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();

    assert_eq!(report["lost"], 0, "{report}");
    assert_eq!(report["reordered"], 0, "{report}");
    assert_eq!(report["shm_left_behind"].as_array().unwrap().len(), 0);
    let left = shm_files(&run);
    assert!(left.is_empty(), "left in /dev/shm: {left:?}");

    let kills = report["recoveries"].as_array().unwrap();
    // The kill clock starts once the pipeline flows, so the first kill (the
    // learner's) finds a learner that has trained, however slow the start.
    let flowed = report["flowed_after_s"]
        .as_f64()
        .unwrap_or_else(|| panic!("the pipeline never flowed: {report}"));
    let first_kill = kills[0]["at_s"].as_f64().unwrap();
    assert!(
        first_kill >= flowed + 6.0,
        "first kill {first_kill} s, flowing from {flowed} s"
    );
    let learner_kills: Vec<_> = kills.iter().filter(|k| k["role"] == "learner").collect();
    assert!(!learner_kills.is_empty(), "no learner kill: {report}");
    assert!(
        kills.iter().any(|k| k["role"] == "sim"),
        "no sim kill: {report}"
    );
    for k in &learner_kills {
        let lost = k["training"]["iterations_lost"]
            .as_u64()
            .unwrap_or_else(|| panic!("learner kill without a count: {k}"));
        assert!(
            lost <= every,
            "lost {lost} > checkpoint interval {every}: {k}"
        );
    }
    for k in kills {
        assert!(k["recovered_after_s"].is_number(), "not recovered: {k}");
        assert!(
            k["training"]["pause_s"].is_number(),
            "no iteration after: {k}"
        );
    }

    // Resumed, not restarted: each learner process starts at the iteration
    // count the previous one checkpointed, which keeps growing.
    let log = json_lines(&dir.join("learner-train.jsonl"));
    let starts: Vec<u64> = log
        .iter()
        .filter(|l| l["event"] == "start")
        .map(|l| l["iteration"].as_u64().unwrap())
        .collect();
    assert!(starts.len() >= 2, "one learner process only: {starts:?}");
    assert!(starts.windows(2).all(|w| w[0] <= w[1]), "{starts:?}");
    assert!(starts[1] > 0, "the restarted learner began from scratch");
    let first_kill_pid = learner_kills[0]["pid"].as_u64().unwrap();
    let at_first_kill = log
        .iter()
        .filter(|l| l["pid"] == first_kill_pid)
        .filter_map(|l| l["iteration"].as_u64())
        .max()
        .unwrap();
    let t = &report["training"];
    let kept = t["iterations_kept"].as_u64().unwrap();
    assert!(kept > at_first_kill, "kept {kept} ≤ {at_first_kill}: {t}");
    assert!(t["final_checkpoint_error"].is_null(), "{t}");
    assert!(t["checkpoints_written"].as_u64().unwrap() >= 2, "{t}");
    // A sim kill always cuts a rollout (or the next one's first step).
    let sim_kills = kills.iter().filter(|k| k["role"] == "sim").count() as u64;
    assert!(t["rollouts_dropped"].as_u64().unwrap() >= sim_kills, "{t}");
    assert_eq!(
        t["iterations_run"].as_u64().unwrap(),
        kept + t["iterations_lost"].as_u64().unwrap(),
        "every iteration run is kept or counted lost: {t}"
    );
    let state: serde_json::Value = serde_json::from_slice(
        &std::fs::read(dir.join("learner-train").join("state.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(state["iterations"].as_u64(), Some(kept));

    // A learner of another batch size does not resume those weights: it is
    // refused before it connects, naming the field.
    let (_, out) = run_bounded_with_pid(
        &[
            "learner",
            "serve",
            "--policy",
            "train-gcp",
            "--slices",
            "1",
            "--envs",
            "16",
            "--maze",
            "small",
            "--run",
            &format!("{run}-again"),
            "--run-dir",
            dir.to_str().unwrap(),
        ],
        Duration::from_secs(30),
    );
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("--envs is 8 in the checkpoint, 16 now"),
        "{stderr}"
    );
    assert!(shm_files(&format!("{run}-again")).is_empty());
}

#[test]
fn a_training_learner_needs_one_slice() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().to_str().unwrap();
    let run = format!("s{}-slices", std::process::id());
    let limit = Duration::from_secs(30);
    let want = "--policy train-gcp trains on the whole batch lock-step: it needs --slices 1, not 2";
    let (_, role) = run_bounded_with_pid(
        &[
            "learner",
            "serve",
            "--policy",
            "train-gcp",
            "--slices",
            "2",
            "--run",
            &run,
            "--run-dir",
            dir,
        ],
        limit,
    );
    let (_, soak) = run_bounded_with_pid(
        &[
            "soak",
            "--learner-trains",
            "--slices",
            "2",
            "--run-dir",
            dir,
        ],
        limit,
    );
    for (out, code) in [(role, 2), (soak, 1)] {
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(code), "{stderr}");
        assert!(stderr.contains(want), "{stderr}");
    }
    assert!(shm_files(&run).is_empty());
    assert!(!Path::new(dir).join("learner-train").exists());
}
