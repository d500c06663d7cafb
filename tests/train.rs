//! `worldgraph train` and `evaluate` as a user runs them: the protocol's
//! files, the same result for the same seed, after a kill and resume too,
//! traversal and `π_g` initialisation from a discovery run's files, and
//! clear refusals.

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use learner::gcp::{GcpConfig, GoalConditionedPolicy};
use planner::{CandidateSet, PlannerConfig, WorldGraph};
use sim::{Maze, Task};

fn worldgraph(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_worldgraph"))
        .args(args)
        .env("WORLDGRAPH_TORCH_THREADS", "1")
        .output()
        .expect("run worldgraph")
}

fn ok(out: &Output) -> String {
    assert!(
        out.status.success(),
        "status {:?}\nstderr: {}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// A CI-sized budget: 8 environments, rollouts of 20, four segments of
/// five iterations, 3 validation and 5 test seeds.
const TINY: &str = "env_steps = 3200\neval_every = 800\nvalidation_seeds = 3\ntest_seeds = 5\n[agent]\nenvs = 8\nrollout_len = 21\n";

fn tiny_config(dir: &Path) -> String {
    let p = dir.join("tiny.toml");
    std::fs::write(&p, TINY).unwrap();
    p.display().to_string()
}

/// The files a `discover` run leaves for stage 2, made directly: a world
/// graph over 12 random cells of the small maze and an untrained `π_g`.
fn discovery_files(dir: &Path) -> PathBuf {
    let run = dir.join("discovery");
    std::fs::create_dir_all(&run).unwrap();
    let layout = Maze::Small.layout(false);
    let cfg = PlannerConfig {
        candidates: CandidateSet::Random { k: 12 },
        seed: 5,
        walks_per_node: 128,
        walk_len: 128,
        task: Task::MultiGoal,
        ..PlannerConfig::default()
    };
    WorldGraph::build(&layout, &cfg, &[])
        .unwrap()
        .save(&run.join("graph.json"))
        .unwrap();
    let gcp_cfg = GcpConfig::default();
    let gcp = GoalConditionedPolicy::new(&gcp_cfg, &layout, 1, 3, 9).unwrap();
    gcp.save(run.join("pi_g.ot")).unwrap();
    std::fs::write(run.join("pi_g.json"), serde_json::to_vec(&gcp_cfg).unwrap()).unwrap();
    run
}

fn read(p: &Path) -> String {
    std::fs::read_to_string(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

/// `worldgraph evaluate RUN ARGS... --json`, parsed.
fn evaluate_json(run: &Path, args: &[&str]) -> serde_json::Value {
    let run = run.to_str().unwrap();
    let out = ok(&worldgraph(
        &[&["evaluate", run], args, &["--json"]].concat(),
    ));
    serde_json::from_str(out.trim()).unwrap()
}

fn test_json(run: &Path) -> serde_json::Value {
    serde_json::from_str(&read(&run.join("test.json"))).unwrap()
}

#[test]
fn a2c_runs_the_protocol_and_the_same_seed_gives_the_same_metrics() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = tiny_config(dir.path());
    let run = |name: &str, seed: &str| {
        let r = dir.path().join(name);
        ok(&worldgraph(&[
            "train",
            "--task",
            "multigoal",
            "--maze",
            "small",
            "--agent",
            "a2c",
            "--seed",
            seed,
            "--config",
            &cfg,
            "--run",
            r.to_str().unwrap(),
        ]));
        r
    };
    let a = run("a", "3");
    let b = run("b", "3");
    let c = run("c", "4");
    // The environments in a sim process over shared memory: the same run.
    let p = dir.path().join("pipeline");
    ok(&worldgraph(&[
        "train",
        "--task",
        "multigoal",
        "--maze",
        "small",
        "--agent",
        "a2c",
        "--seed",
        "3",
        "--config",
        &cfg,
        "--run",
        p.to_str().unwrap(),
        "--pipeline",
    ]));
    assert_eq!(
        read(&p.join("metrics.csv")),
        read(&a.join("metrics.csv")),
        "--pipeline gives the in-process metrics"
    );
    for f in [
        "config.toml",
        "metrics.csv",
        "curves.png",
        "test.json",
        "episode.png",
        "seeds.json",
    ] {
        assert!(a.join(f).exists(), "{f} missing");
    }
    let metrics = read(&a.join("metrics.csv"));
    assert_eq!(
        metrics.lines().count(),
        1 + 4,
        "a header and one row per segment:\n{metrics}"
    );
    assert_eq!(
        metrics,
        read(&b.join("metrics.csv")),
        "same seed, same metrics"
    );
    assert_ne!(
        metrics,
        read(&c.join("metrics.csv")),
        "another seed, other metrics"
    );
    let t = test_json(&a);
    assert_eq!(t["test_seeds"], 5);
    assert_eq!(t["validation_seeds"], 3);
    assert_eq!(t["env_steps"], 4 * 5 * 8 * 21);
    assert_eq!(t["test_score"], test_json(&b)["test_score"]);
    let curve = t["validation_curve"].as_array().unwrap();
    assert_eq!(curve.len(), 4);
    // The best checkpoint is the one with the best validation score.
    let best = curve
        .iter()
        .map(|p| p[1].as_f64().unwrap())
        .fold(f64::MIN, f64::max);
    assert_eq!(t["best_validation"].as_f64().unwrap(), best);
    // Its score on the test seeds, re-scored by `evaluate`.
    let e = evaluate_json(&a, &["--seeds", "0..5"]);
    assert_eq!(
        e["score"], t["test_score"],
        "evaluate reproduces the test score"
    );
    // The episodes' figures are those episodes': on MultiGoal a return is
    // the balls collected, +1 at the exit and -0.01 a step.
    let ep = &e["episodes"];
    let f = |k: &str| ep[k].as_f64().unwrap();
    assert_eq!(ep["episodes"], 5);
    assert!(
        (f("mean_return") - t["test_return"].as_f64().unwrap()).abs() < 1e-6,
        "{ep}"
    );
    let rebuilt = f("mean_balls") + f("exit_share") - 0.01 * f("mean_length");
    assert!((rebuilt - f("mean_return")).abs() < 1e-4, "{ep}");

    // The same policy scored under MultiGoal-Sparse's rewards: the same
    // episodes (the rewards do not steer it), each paying `balls / 5` at the
    // exit instead of `balls + 1`.
    let s = evaluate_json(&a, &["--seeds", "0..5", "--task", "multigoal-sparse"]);
    assert_eq!(s["task"], "multigoal-sparse");
    assert_eq!(s["trained_on"], "multigoal");
    let sp = &s["episodes"];
    let g = |k: &str| sp[k].as_f64().unwrap();
    for k in ["mean_length", "mean_balls", "exit_share"] {
        assert_eq!(g(k), f(k), "{k}: the same episodes\n{ep}\n{sp}");
    }
    // Per episode: sparse = dense - balls - exited + exited * balls / 5.
    let dense_less = f("mean_return") - f("mean_balls") - f("exit_share");
    assert!(
        g("mean_return") >= dense_less - 1e-4
            && g("mean_return") <= dense_less + f("mean_balls") / 5.0 + 1e-4,
        "{ep}\n{sp}"
    );
    assert!((s["score"].as_f64().unwrap() - g("mean_return")).abs() < 1e-4);
    // `--trace` writes the first episode, the test's: the run's own
    // `test_episode.json`, byte for byte.
    let trace = a.join("evaluate-trace.json");
    ok(&worldgraph(&[
        "evaluate",
        a.to_str().unwrap(),
        "--seeds",
        "0..5",
        "--trace",
        trace.to_str().unwrap(),
    ]));
    assert_eq!(read(&trace), read(&a.join("test_episode.json")));
    // Greedy: every round plays the same episodes (the rounds differ only
    // in the sampling seed), and the JSON says how the agent acted.
    let g = evaluate_json(
        &a,
        &[
            "--seeds",
            "0..5",
            "--episodes-per-seed",
            "2",
            "--eval-actions",
            "greedy",
        ],
    );
    assert_eq!(g["eval_actions"], "greedy");
    assert_eq!(g["per_round"][0], g["per_round"][1], "{g}");
    assert_eq!(e["eval_actions"], "sample");
    // Door-Key has other actions and another layout: refused, clearly.
    let out = worldgraph(&["evaluate", a.to_str().unwrap(), "--task", "doorkey"]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("--task doorkey") && err.contains("trained on multigoal"),
        "{err}"
    );
}

/// `train` arguments of WN over `V_p` with traversal on the small maze's
/// MultiGoal (and `π_g` initialisation with `init`).
fn wn_traversal_args(seed: u64, init: bool, cfg: &str, graph: &Path, run: &Path) -> Vec<String> {
    let mut args: Vec<String> = [
        "train",
        "--task",
        "multigoal",
        "--maze",
        "small",
        "--agent",
        "wn",
        "--candidates",
        "pivotal",
        "--traversal",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    if init {
        args.extend(["--init".into(), "pi-g".into()]);
    }
    let seed = seed.to_string();
    for (k, v) in [
        ("--seed", seed.as_str()),
        ("--config", cfg),
        ("--world-graph", graph.to_str().unwrap()),
        ("--run", run.to_str().unwrap()),
    ] {
        args.extend([k.to_string(), v.to_string()]);
    }
    args
}

#[test]
fn validation_in_the_middle_of_a_run_leaves_its_training_unchanged() {
    // The same 20 iterations, validated after every 5 or only at the end:
    // the training environments and the controller go on across
    // validations, so the trained weights are the same bit for bit.
    let dir = tempfile::tempdir().unwrap();
    let graph = discovery_files(dir.path());
    let run = |name: &str, eval_every: u32| -> PathBuf {
        let cfg = dir.path().join(format!("{name}.toml"));
        std::fs::write(
            &cfg,
            TINY.replace("eval_every = 800", &format!("eval_every = {eval_every}")),
        )
        .unwrap();
        let run = dir.path().join(name);
        let args = wn_traversal_args(3, false, &cfg.display().to_string(), &graph, &run);
        ok(&worldgraph(
            &args.iter().map(String::as_str).collect::<Vec<_>>(),
        ));
        run
    };
    let often = run("often", 800);
    let once = run("once", 3200);
    let weights = |run: &Path, segments: u32| {
        std::fs::read(run.join("checkpoint").join(format!("agent-{segments}.ot"))).unwrap()
    };
    assert_eq!(read(&often.join("metrics.csv")).lines().count(), 5);
    assert_eq!(read(&once.join("metrics.csv")).lines().count(), 2);
    assert!(
        weights(&often, 4) == weights(&once, 1),
        "validating every 5 iterations changed what was trained"
    );
}

#[test]
fn a_killed_run_resumes_and_ends_as_an_uninterrupted_one() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = tiny_config(dir.path());
    let graph = discovery_files(dir.path());
    let args = |run: &Path| wn_traversal_args(1, true, &cfg, &graph, run);
    let whole = dir.path().join("whole");
    let a: Vec<String> = args(&whole);
    ok(&worldgraph(
        &a.iter().map(String::as_str).collect::<Vec<_>>(),
    ));

    let killed = dir.path().join("killed");
    let a: Vec<String> = args(&killed);
    let mut child = Command::new(env!("CARGO_BIN_EXE_worldgraph"))
        .args(&a)
        .env("WORLDGRAPH_TORCH_THREADS", "1")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let state = killed.join("checkpoint").join("state.json");
    let start = Instant::now();
    while !state.exists() && start.elapsed() < Duration::from_secs(120) {
        std::thread::sleep(Duration::from_millis(20));
    }
    assert!(state.exists(), "no checkpoint within 2 minutes");
    child.kill().unwrap();
    child.wait().unwrap();
    let out = worldgraph(&a.iter().map(String::as_str).collect::<Vec<_>>());
    ok(&out);
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("resuming"),
        "the restart resumed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(
        read(&whole.join("metrics.csv")),
        read(&killed.join("metrics.csv"))
    );
    assert_eq!(
        test_json(&whole)["test_score"],
        test_json(&killed)["test_score"]
    );
    // The per-update log is the uninterrupted run's, row for row, but for
    // the wall clock (columns wall_seconds and sps), and TensorBoard's
    // events are there; each start recorded its command line and commit.
    let learning = |run: &Path| -> Vec<String> {
        read(&run.join("updates.csv"))
            .lines()
            .map(|l| {
                let f: Vec<&str> = l.split(',').collect();
                // Column 14 is sps.
                let mut keep = vec![f[0], f[1]];
                keep.extend(&f[3..14]);
                keep.extend(&f[15..]);
                keep.join(",")
            })
            .collect()
    };
    let rows = learning(&whole);
    assert_eq!(rows.len(), 1 + 20, "{rows:?}");
    assert!(rows[0].starts_with("update,env_steps,episodes,episodic_return,policy_loss"));
    assert!(
        rows[0].ends_with(
            ",exit_share,exit_goal_share,ball_goal_share,key_share,door_share,\
             key_taken_share,key_goal_share,door_goal_share"
        ),
        "{}",
        rows[0]
    );
    assert_eq!(rows, learning(&killed));
    for run in [&whole, &killed] {
        let tb: Vec<_> = std::fs::read_dir(run.join("tensorboard"))
            .unwrap()
            .collect();
        assert_eq!(tb.len(), 1);
    }
    let invocations = read(&killed.join("invocations.txt"));
    assert_eq!(invocations.lines().count(), 2, "{invocations}");
    assert!(
        invocations.contains("(commit ") && invocations.contains(" train "),
        "{invocations}"
    );
    // Traversal happened, and the world graph came from the discovery run.
    let metrics = read(&whole.join("metrics.csv"));
    let traversal: f64 = metrics
        .lines()
        .skip(1)
        .map(|l| l.rsplit(',').next().unwrap().parse::<f64>().unwrap())
        .sum();
    assert!(traversal > 0.0, "no step was a traversal:\n{metrics}");
}

#[test]
fn train_refuses_what_it_cannot_run_with_a_clear_message() {
    let dir = tempfile::tempdir().unwrap();
    let bad = |args: &[&str], says: &str| {
        let out = worldgraph(args);
        assert!(!out.status.success(), "{args:?} was accepted");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(says), "{args:?}: {err}");
    };
    let run = dir.path().join("r");
    let run = run.to_str().unwrap();
    bad(
        &[
            "train",
            "--agent",
            "wn",
            "--candidates",
            "pivotal",
            "--run",
            run,
        ],
        "needs --world-graph",
    );
    bad(
        &["train", "--agent", "fn", "--traversal", "--run", run],
        "traversal",
    );
    let cfg = dir.path().join("bad.toml");
    std::fs::write(&cfg, "env_steps = 10\n[agent]\nenvz = 3\n").unwrap();
    bad(
        &["train", "--config", cfg.to_str().unwrap(), "--run", run],
        "unknown field",
    );
    bad(
        &["train", "--seed", "5000000", "--run", run],
        "--seed must be below",
    );
    // A run directory of another configuration is not resumed.
    let tiny = tiny_config(dir.path());
    ok(&worldgraph(&[
        "train",
        "--agent",
        "a2c",
        "--config",
        &tiny,
        "--run",
        run,
        "--env-steps",
        "800",
    ]));
    bad(
        &[
            "train",
            "--agent",
            "fn",
            "--config",
            &tiny,
            "--run",
            run,
            "--env-steps",
            "800",
        ],
        "agent.kind",
    );
}

/// Issue 21, item 8: the rounding of the budget is printed; a finished run
/// rerun with a smaller budget is refused with its `config.toml` untouched;
/// `evaluate` says when a run is unfinished.
#[test]
fn a_budget_is_rounded_aloud_and_a_smaller_one_leaves_a_finished_run_alone() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = tiny_config(dir.path());
    let r = dir.path().join("r");
    let train = |env_steps: &str| {
        worldgraph(&[
            "train",
            "--task",
            "multigoal",
            "--maze",
            "small",
            "--agent",
            "a2c",
            "--config",
            &cfg,
            "--env-steps",
            env_steps,
            "--run",
            r.to_str().unwrap(),
        ])
    };
    // 8 envs × 21 steps = 168 per iteration; eval_every 800 → 5 iterations
    // (840 env steps) per segment; 1000 → 2 segments, 1680 env steps.
    let out = train("1000");
    ok(&out);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("budget of 1000 env steps rounds up to 1680"),
        "{err}"
    );
    let config = read(&r.join("config.toml"));
    assert!(config.contains("env_steps = 1000"), "{config}");
    let test = test_json(&r);
    assert_eq!(test["env_steps"], 1680, "{test}");

    let out = train("800");
    assert!(!out.status.success(), "a smaller budget was accepted");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("already trained 1680 env steps"), "{err}");
    assert_eq!(
        read(&r.join("config.toml")),
        config,
        "config.toml rewritten"
    );

    // A run whose budget is not trained yet (as a killed one): evaluate
    // scores it and says it is unfinished.
    std::fs::write(
        r.join("config.toml"),
        config.replace("env_steps = 1000", "env_steps = 5000"),
    )
    .unwrap();
    let out = worldgraph(&["evaluate", r.to_str().unwrap(), "--seeds", "0..2"]);
    let stdout = ok(&out);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("unfinished (1680 of 5040 env steps trained)")
            && stdout.contains("unfinished run"),
        "{stdout}\n{err}"
    );
}

#[test]
fn any_setting_can_be_set_from_the_command_line_and_printed_resolved() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("never");
    let out = ok(&worldgraph(&[
        "train",
        "--agent",
        "wn",
        "--set",
        "agent.worker.learning_rate=3e-4",
        "--set",
        "eval_every = 1000",
        "--set",
        "agent.kind=wide-narrow",
        "--run",
        run.to_str().unwrap(),
        "--print-config",
    ]));
    let printed: toml::Table = toml::from_str(&out).expect("the printed settings are TOML");
    assert_eq!(printed["eval_every"].as_integer(), Some(1000), "{out}");
    assert_eq!(
        printed["agent"]["worker"]["learning_rate"].as_float(),
        Some(3e-4),
        "{out}"
    );
    assert!(!run.exists(), "--print-config writes nothing");
    let bad = worldgraph(&["train", "--set", "agent.worker.lr=3e-4", "--print-config"]);
    assert!(!bad.status.success());
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(err.contains("agent.worker.lr"), "{err}");
}

/// `train --print-config` with `extra`, parsed.
fn printed_config(extra: &[&str]) -> toml::Table {
    let mut args = vec!["train", "--print-config"];
    args.extend(extra);
    let out = ok(&worldgraph(&args));
    toml::from_str(&out).unwrap_or_else(|e| panic!("{e}:\n{out}"))
}

fn agent_int(t: &toml::Table, key: &str) -> i64 {
    t["agent"][key]
        .as_integer()
        .unwrap_or_else(|| panic!("agent.{key}: {t}"))
}

/// Issue 21: `--print-config` and a run's `config.toml` hold what
/// `0 = auto` resolved to (the horizon a third of the rollout, the window
/// from the world graph's candidates); a resume with the same command line
/// (auto again), with the values given explicitly, or of a run recorded
/// with 0 goes on; another value is refused. The pictures are captioned.
#[test]
fn resolved_settings_are_written_and_a_run_resumes_under_auto_or_explicit_values() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = tiny_config(dir.path());
    let graph = discovery_files(dir.path());
    let g = graph.to_str().unwrap();
    // V_all needs no world graph; V_p's window comes from it.
    let all = printed_config(&["--agent", "wn", "--candidates", "all", "--config", &cfg]);
    assert_eq!(agent_int(&all, "horizon"), 7, "a third of rollout_len 21");
    let side = agent_int(&all, "window");
    assert!(side >= 5 && side % 2 == 1, "{all}");
    let vp = printed_config(&["--agent", "wn", "--world-graph", g, "--config", &cfg]);
    assert_eq!(agent_int(&vp, "horizon"), 7);
    let window = agent_int(&vp, "window");
    assert!(window >= 5 && window % 2 == 1, "{vp}");
    let a2c = printed_config(&["--agent", "a2c", "--config", &cfg]);
    assert_eq!(
        (agent_int(&a2c, "horizon"), agent_int(&a2c, "window")),
        (0, 0),
        "A2C has no Manager and no window"
    );

    let run = dir.path().join("r");
    let train = |budget: &str, extra: &[&str]| {
        let mut args = vec![
            "train",
            "--task",
            "multigoal",
            "--maze",
            "small",
            "--agent",
            "wn",
            "--world-graph",
            g,
            "--config",
            &cfg,
            "--run",
            run.to_str().unwrap(),
            "--env-steps",
            budget,
        ];
        args.extend(extra);
        worldgraph(&args)
    };
    let resumed = |out: &Output| {
        ok(out);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains("resuming"), "{err}");
    };
    ok(&train("800", &[]));
    let written: toml::Table = toml::from_str(&read(&run.join("config.toml"))).unwrap();
    assert_eq!(agent_int(&written, "horizon"), 7, "{written}");
    assert_eq!(
        agent_int(&written, "window"),
        window,
        "as printed: {written}"
    );
    assert_eq!(
        test_json(&run)["window_side"],
        window,
        "the side the agent used"
    );
    resumed(&train("1600", &[]));
    let explicit = format!("agent.window={window}");
    resumed(&train(
        "2400",
        &["--set", "agent.horizon=7", "--set", &explicit],
    ));
    let other = train("3200", &["--set", "agent.horizon=5"]);
    assert!(!other.status.success(), "another horizon was resumed");
    let err = String::from_utf8_lossy(&other.stderr);
    assert!(err.contains("agent.horizon"), "{err}");
    // A run recorded before the values were resolved says 0.
    let state = run.join("checkpoint").join("state.json");
    let mut s: serde_json::Value = serde_json::from_str(&read(&state)).unwrap();
    s["identity"]["config"]["agent"]["horizon"] = 0.into();
    s["identity"]["config"]["agent"]["window"] = 0.into();
    std::fs::write(&state, serde_json::to_vec(&s).unwrap()).unwrap();
    resumed(&train("3200", &[]));
    assert_eq!(read(&run.join("metrics.csv")).lines().count(), 1 + 4);

    // The episode picture is captioned, and its trace holds the grids.
    let (w, h) = super::discover::png_size(&run.join("episode.png"));
    let maze = Maze::Small.layout(false);
    assert!(
        w >= 480 && h > maze.height as u32 * 28 + 100,
        "episode.png is {w}×{h}: no caption"
    );
    let trace: serde_json::Value =
        serde_json::from_str(&read(&run.join("test_episode.json"))).unwrap();
    for grid in ["start_cells", "end_cells"] {
        assert_eq!(
            trace[grid].as_array().map(Vec::len),
            Some(maze.cells.len()),
            "{grid}"
        );
    }
}

/// Issue 48: the episode step limit is a setting (`max_episode_steps`; the
/// paper gives none). `0 = auto` resolves to twice the maze's free cells
/// and is written so; another value cuts every episode there, in training
/// and when the run is scored again by `evaluate`.
#[test]
fn the_episode_step_limit_is_a_setting_written_resolved_and_kept_by_evaluate() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = tiny_config(dir.path());
    let free = Maze::Small.layout(false).free_cells().len() as i64;
    let train = |name: &str, extra: &[&str]| {
        let run = dir.path().join(name);
        let mut args = vec![
            "train",
            "--maze",
            "small",
            "--task",
            "multigoal",
            "--agent",
            "a2c",
            "--config",
            &cfg,
            "--env-steps",
            "800",
        ];
        let r = run.display().to_string();
        args.extend(["--run", &r]);
        args.extend(extra);
        ok(&worldgraph(&args));
        let written: toml::Table = toml::from_str(&read(&run.join("config.toml"))).unwrap();
        let limit = written["max_episode_steps"].as_integer().unwrap();
        let eval = ok(&worldgraph(&["evaluate", &r, "--seeds", "0..20", "--json"]));
        let v: serde_json::Value = serde_json::from_str(&eval).unwrap();
        (limit, v["episodes"]["mean_length"].as_f64().unwrap())
    };
    let (auto, auto_len) = train("auto", &[]);
    assert_eq!(auto, 2 * free, "twice the free cells");
    let printed = printed_config(&["--agent", "a2c", "--config", &cfg]);
    assert_eq!(
        printed["max_episode_steps"].as_integer(),
        Some(auto),
        "--print-config resolves it"
    );
    let (cut, cut_len) = train("cut", &["--set", "max_episode_steps=12"]);
    assert_eq!(cut, 12);
    assert!(
        cut_len <= 12.0,
        "episodes of {cut_len} steps under a limit of 12"
    );
    assert!(
        auto_len > 12.0,
        "an untrained A2C exits within 12 steps: {auto_len}"
    );
}
