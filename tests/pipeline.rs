//! The pipeline with real processes: the three roles exchange data through
//! shared memory, a shape mismatch is refused, a killed learner is detected
//! and a restarted one rejoins, and nothing is left in /dev/shm.
//!
//! Each test uses its own run name, hence its own iceoryx2 prefix
//! (`wg_<run>_`), so tests run in parallel. Waits are bounded by watchdogs
//! (a test fails, never hangs); nothing asserts a maximum runtime.

use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

fn exe() -> &'static str {
    env!("CARGO_BIN_EXE_worldgraph")
}

fn run_name(test: &str) -> String {
    format!("t{}-{}", std::process::id(), test)
}

fn shm_files(run: &str) -> Vec<String> {
    let prefix = format!("wg_{run}_");
    std::fs::read_dir("/dev/shm")
        .map(|d| {
            d.flatten()
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .filter(|n| n.starts_with(&prefix))
                .collect()
        })
        .unwrap_or_default()
}

fn read_json(dir: &Path, name: &str) -> serde_json::Value {
    let bytes = std::fs::read(dir.join(name)).unwrap_or_else(|e| panic!("{name}: {e}"));
    serde_json::from_slice(&bytes).expect("valid JSON")
}

/// A role's process, killed when dropped: a failing assertion must not
/// leave a spinning process behind to disturb the tests and benchmarks that
/// run after it.
struct Proc(Child);

impl std::ops::Deref for Proc {
    type Target = Child;
    fn deref(&self) -> &Child {
        &self.0
    }
}

impl std::ops::DerefMut for Proc {
    fn deref_mut(&mut self) -> &mut Child {
        &mut self.0
    }
}

impl Drop for Proc {
    fn drop(&mut self) {
        if matches!(self.0.try_wait(), Ok(None)) {
            let _ = self.0.kill();
            let _ = self.0.wait();
        }
    }
}

/// Starts one role; its stderr goes to `<dir>/<log>`.
fn role(dir: &Path, log: &str, args: &[&str]) -> Proc {
    let f = std::fs::File::create(dir.join(log)).unwrap();
    Proc(
        Command::new(exe())
            .args(args)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(f)
            .spawn()
            .expect("spawn role"),
    )
}

/// Polls `cond` every 50 ms until it holds or `limit` passes.
fn wait_for(limit: Duration, mut cond: impl FnMut() -> bool) -> bool {
    let until = Instant::now() + limit;
    while Instant::now() < until {
        if cond() {
            return true;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    cond()
}

fn last_seq(dir: &Path) -> Option<u64> {
    let f = std::fs::File::open(dir.join("sim.stats.jsonl")).ok()?;
    let line = BufReader::new(f).lines().map_while(Result::ok).last()?;
    serde_json::from_str::<serde_json::Value>(&line).ok()?["seq"].as_u64()
}

fn sigterm(child: &Child) {
    let _ = Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status();
}

fn wait_exit(child: &mut Child, limit: Duration) -> std::process::ExitStatus {
    let until = Instant::now() + limit;
    loop {
        if let Some(st) = child.try_wait().unwrap() {
            return st;
        }
        if Instant::now() > until {
            let _ = child.kill();
            panic!("process {} did not exit within {limit:?}", child.id());
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

#[test]
fn the_three_roles_exchange_data_through_shared_memory() {
    let dir = tempfile::tempdir().unwrap();
    let run = run_name("exchange");
    let out = Command::new(exe())
        .args([
            "run",
            "--run",
            &run,
            "--run-dir",
            dir.path().to_str().unwrap(),
            "--duration",
            "3",
        ])
        .args([
            "--maze",
            "small",
            "--envs",
            "16",
            "--route-every",
            "20",
            "--nodes",
            "8",
            "--logs-to-files",
        ])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "run failed: {stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let sim = read_json(dir.path(), "sim.report.json");
    let learner = read_json(dir.path(), "learner.report.json");
    let planner = read_json(dir.path(), "planner.report.json");
    let batches = sim["batches"].as_u64().unwrap();
    assert!(batches > 100, "the sim published {batches} batches");
    // Lock-step: the learner answered every batch but the last ones. At the
    // stop, the sim's 2 slices are out awaiting answers, and the learner's
    // last answer may be uncounted (sent, then interrupted while waiting for
    // the next batch): `batches` - 3 at the least.
    let answered = learner["batches"].as_u64().unwrap();
    assert!(
        answered + 3 >= batches && answered <= batches,
        "{answered} answers to {batches} batches"
    );
    assert_eq!(learner["stream"]["lost"], 0);
    assert_eq!(learner["stream"]["reordered"], 0);
    // Episodes ended and were reported; the learner saw the ends of the
    // batches it received, a subset of those the sim stepped.
    let episodes = learner["episodes"].as_u64().unwrap();
    assert!(
        episodes > 0 && episodes <= sim["episodes"].as_u64().unwrap(),
        "{episodes} episodes reported, the sim's report: {sim}"
    );
    // MultiGoal's returns lie between every step's penalty over the longest
    // episode (twice the cells at most) and all 5 balls plus the exit.
    let mean_return = learner["mean_episode_return"].as_f64().unwrap();
    assert!(
        (-0.01 * 2.0 * 13.0 * 13.0..=6.0).contains(&mean_return),
        "mean episode return {mean_return}"
    );
    let read = planner["batches_read"].as_u64().unwrap();
    assert!(
        read > 0 && read <= batches,
        "the planner read {read} of the same stream's {batches} batches"
    );
    assert!(
        planner["cells_visited"].as_u64().unwrap() > 10,
        "coverage counted"
    );
    // A route request every 20 answered batches once the graph is known;
    // on the small maze's connected graph most come back as routes.
    let (ok, requested) = (
        learner["routes_ok"].as_u64().unwrap(),
        learner["routes_requested"].as_u64().unwrap(),
    );
    assert!(
        requested <= answered / 20 && ok <= requested && ok > 0 && 2 * ok >= requested,
        "{ok} routes of {requested} requested came back: {learner}"
    );
    assert_eq!(planner["nodes"], 8);
    for f in [
        "graph.json",
        "graph.png",
        "coverage.png",
        "sim.latency.png",
        "sim.action_round_trip.hgrm",
        "learner.policy.hgrm",
        "learner.obs_one_way.hgrm",
        "planner.route_service.hgrm",
    ] {
        assert!(dir.path().join(f).exists(), "{f} written");
    }
    // Issue 21: the planner's picture of its graph has a title and a legend.
    let (w, h) = super::discover::png_size(&dir.path().join("graph.png"));
    let maze = sim::Maze::Small.layout(false);
    assert!(
        w >= 480 && h > maze.height as u32 * 24 + 100,
        "graph.png is {w}×{h}: no caption"
    );
    assert!(
        stdout.contains("shared-memory files left behind"),
        "{stdout}"
    );
    assert!(
        shm_files(&run).is_empty(),
        "left behind: {:?}",
        shm_files(&run)
    );
}

#[test]
fn a_learner_with_another_grid_shape_is_refused_with_a_message_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let run = run_name("shape");
    let d = dir.path().to_str().unwrap();
    let mut sim = role(
        dir.path(),
        "sim.log",
        &[
            "sim",
            "serve",
            "--run",
            &run,
            "--run-dir",
            d,
            "--maze",
            "small",
            "--envs",
            "16",
        ],
    );
    assert!(wait_for(Duration::from_secs(20), || last_seq(dir.path())
        .is_some()
        || dir
            .path()
            .join("sim.log")
            .metadata()
            .is_ok_and(|m| m.len() > 0)));
    for (maze, envs, slices, needle) in [
        ("medium", "16", "2", "25x19"),
        ("small", "32", "2", "32"),
        (
            "small",
            "16",
            "1",
            "batch in 1 slice(s) expected, publisher sends 2",
        ),
    ] {
        let out = Command::new(exe())
            .args([
                "learner",
                "serve",
                "--run",
                &run,
                "--run-dir",
                d,
                "--maze",
                maze,
                "--envs",
                envs,
                "--slices",
                slices,
            ])
            .stdin(Stdio::null())
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            !out.status.success(),
            "a {maze}/{envs}/{slices} learner was accepted: {err}"
        );
        assert!(
            err.contains(needle) && (err.contains("13x13") || err.contains("16")),
            "{maze}/{envs}: {err}"
        );
    }
    sigterm(&sim);
    assert!(wait_exit(&mut sim, Duration::from_secs(20)).success());
    assert!(
        wait_for(Duration::from_secs(5), || shm_files(&run).is_empty()),
        "left behind: {:?}",
        shm_files(&run)
    );
}

#[test]
fn a_killed_learner_is_noticed_and_a_restarted_one_rejoins_without_losing_batches() {
    let dir = tempfile::tempdir().unwrap();
    let run = run_name("rejoin");
    let d = dir.path().to_str().unwrap();
    let common = [
        "--run",
        &run,
        "--run-dir",
        d,
        "--maze",
        "small",
        "--envs",
        "8",
        "--on-peer-death",
        "wait",
    ];
    let mut sim = role(
        dir.path(),
        "sim.log",
        &[&["sim", "serve"][..], &common].concat(),
    );
    let mut learner = role(
        dir.path(),
        "learner1.log",
        &[&["learner", "serve"][..], &common].concat(),
    );
    assert!(
        wait_for(Duration::from_secs(30), || last_seq(dir.path())
            .is_some_and(|s| s > 1000)),
        "the pipeline runs"
    );
    learner.kill().unwrap();
    learner.wait().unwrap();
    let killed = Instant::now();
    let noticed = wait_for(Duration::from_secs(10), || {
        std::fs::read_to_string(dir.path().join("sim.log"))
            .is_ok_and(|l| l.contains("the learner is gone"))
    });
    assert!(noticed, "the sim did not say the learner died");
    let after = killed.elapsed();
    eprintln!("sim noticed the dead learner after {after:?}");
    let seq_at_restart = last_seq(dir.path()).unwrap();
    // On request (SIGUSR1) the waiting sim prints its latency table.
    let _ = Command::new("kill")
        .args(["-USR1", &sim.id().to_string()])
        .status();
    assert!(
        wait_for(Duration::from_secs(10), || std::fs::read_to_string(
            dir.path().join("sim.log")
        )
        .is_ok_and(|l| l.contains("sim latency (µs)"))),
        "SIGUSR1 printed the percentile table"
    );
    let mut learner2 = role(
        dir.path(),
        "learner2.log",
        &[&["learner", "serve"][..], &common].concat(),
    );
    assert!(
        wait_for(Duration::from_secs(30), || last_seq(dir.path())
            .is_some_and(|s| s > seq_at_restart + 1000)),
        "batches flow again after the restart"
    );
    sigterm(&learner2);
    wait_exit(&mut learner2, Duration::from_secs(20));
    sigterm(&sim);
    wait_exit(&mut sim, Duration::from_secs(20));
    let sim_report = read_json(dir.path(), "sim.report.json");
    assert_eq!(sim_report["learner_deaths"], 1);
    let l2 = read_json(dir.path(), "learner.report.json");
    assert_eq!(
        l2["stream"]["lost"], 0,
        "the rejoined learner lost nothing: {l2}"
    );
    assert_eq!(l2["stream"]["reordered"], 0);
    assert!(
        std::fs::read_to_string(dir.path().join("sim.log"))
            .unwrap()
            .contains("a learner rejoined")
    );
    assert!(
        wait_for(Duration::from_secs(5), || shm_files(&run).is_empty()),
        "left behind: {:?}",
        shm_files(&run)
    );
}

#[test]
fn a_role_exits_cleanly_when_its_peer_dies_if_asked_to() {
    let dir = tempfile::tempdir().unwrap();
    let run = run_name("exit");
    let d = dir.path().to_str().unwrap();
    let common = [
        "--run",
        &run,
        "--run-dir",
        d,
        "--maze",
        "small",
        "--envs",
        "8",
        "--on-peer-death",
        "exit",
    ];
    let mut sim = role(
        dir.path(),
        "sim.log",
        &[&["sim", "serve"][..], &common].concat(),
    );
    let mut learner = role(
        dir.path(),
        "learner.log",
        &[&["learner", "serve"][..], &common].concat(),
    );
    assert!(wait_for(Duration::from_secs(30), || last_seq(dir.path())
        .is_some_and(|s| s > 100)));
    sim.kill().unwrap();
    sim.wait().unwrap();
    let st = wait_exit(&mut learner, Duration::from_secs(10));
    assert_eq!(
        st.code(),
        Some(3),
        "the learner exits with the peer-died status"
    );
    let report = read_json(dir.path(), "learner.report.json");
    assert_eq!(report["stopped_by"], "sim died");
    // The killed sim left its resources; the next start of the run cleans them up.
    let mut sim2 = role(
        dir.path(),
        "sim2.log",
        &[
            "sim",
            "serve",
            "--run",
            &run,
            "--run-dir",
            d,
            "--maze",
            "small",
            "--envs",
            "8",
        ],
    );
    assert!(
        wait_for(Duration::from_secs(20), || std::fs::read_to_string(
            dir.path().join("sim2.log")
        )
        .is_ok_and(|l| l.contains("publishing"))),
        "the second sim starts over the killed one's leftovers"
    );
    sigterm(&sim2);
    assert!(wait_exit(&mut sim2, Duration::from_secs(20)).success());
    assert!(
        wait_for(Duration::from_secs(5), || shm_files(&run).is_empty()),
        "left behind: {:?}",
        shm_files(&run)
    );
}

#[test]
fn a_restarted_sim_is_a_new_stream_not_a_reordering() {
    let dir = tempfile::tempdir().unwrap();
    let run = run_name("simrestart");
    let d = dir.path().to_str().unwrap();
    let common = [
        "--run",
        &run,
        "--run-dir",
        d,
        "--maze",
        "small",
        "--envs",
        "8",
        "--on-peer-death",
        "wait",
    ];
    let mut sim = role(
        dir.path(),
        "sim.log",
        &[&["sim", "serve"][..], &common].concat(),
    );
    let mut learner = role(
        dir.path(),
        "learner.log",
        &[&["learner", "serve"][..], &common].concat(),
    );
    assert!(wait_for(Duration::from_secs(30), || last_seq(dir.path())
        .is_some_and(|s| s > 2000)));
    sim.kill().unwrap();
    sim.wait().unwrap();
    assert!(wait_for(Duration::from_secs(10), || {
        std::fs::read_to_string(dir.path().join("learner.log"))
            .is_ok_and(|l| l.contains("the sim is gone"))
    }));
    let mut sim2 = role(
        dir.path(),
        "sim2.log",
        &[&["sim", "serve"][..], &common].concat(),
    );
    assert!(wait_for(Duration::from_secs(30), || {
        std::fs::read_to_string(dir.path().join("learner.log"))
            .is_ok_and(|l| l.contains("a sim rejoined"))
    }));
    std::thread::sleep(Duration::from_millis(500));
    sigterm(&learner);
    wait_exit(&mut learner, Duration::from_secs(20));
    sigterm(&sim2);
    wait_exit(&mut sim2, Duration::from_secs(20));
    let report = read_json(dir.path(), "learner.report.json");
    assert_eq!(report["stream"]["lost"], 0, "{report}");
    assert_eq!(
        report["stream"]["reordered"], 0,
        "a restarted sim's batches are not stale: {report}"
    );
    assert_eq!(report["stream"]["sim_restarts"], 1, "{report}");
}

/// Issue 24 over the transport: the real sim process steps its
/// environments into loaned samples; the test, as the learner, answers with
/// chosen actions and finds every record, the cells and, on the steps that
/// ended an episode, the end pose and the final cells equal to the same
/// environments stepped in this process (same layout, seed and actions).
#[test]
fn the_final_state_of_an_ending_step_crosses_shared_memory_as_stepped_in_process() {
    use iceoryx2::prelude::ipc;
    use shm_schemas::ObsShape;
    use shm_schemas::service::{PipelineNode, RunName, run_config};
    use sim::action::{FORWARD, LEFT, RIGHT};
    use sim::{AutoReset, BallSpawn, BatchEnv, EnvConfig, Layout, Object, Task};

    // Env 0 of each slice walks over the balls onto the exit (ends every 4
    // steps), env 1 turns (truncated every 9), the others wander.
    const TEXT: &str = "#######\n#>B.BE#\n#.....#\n#######\n";
    const MAX_STEPS: u32 = 9;
    const SEED: u64 = 3;
    const SAMPLES: u64 = 160;
    let (envs, slices) = (8usize, 2usize);
    let dir = tempfile::tempdir().unwrap();
    let run = run_name("finalstate");
    let d = dir.path().to_str().unwrap();
    let layout_file = dir.path().join("corridor.txt");
    std::fs::write(&layout_file, TEXT).unwrap();

    let layout = Layout::parse("corridor", TEXT).unwrap();
    let cfg = EnvConfig {
        task: Task::MultiGoal,
        max_steps: MAX_STEPS,
        balls: BallSpawn::Layout,
        auto_reset: AutoReset::SameStep,
    };
    let shape = ObsShape::sliced(envs, slices, layout.width, layout.height).unwrap();
    let per = shape.envs();
    let mut refs: Vec<BatchEnv> = (0..slices)
        .map(|k| BatchEnv::with_first_index(layout.clone(), cfg, k * per, per, SEED, 1).unwrap())
        .collect();
    let mut bufs: Vec<_> = refs.iter().map(BatchEnv::buffers).collect();
    let cpe = refs[0].cells_per_env();

    // The learner's ports exist before the sim starts: nothing is missed.
    let name = RunName::new(&run).unwrap();
    let learner = PipelineNode::<ipc::Service>::new(&run_config(&name).unwrap(), name, "learner")
        .unwrap()
        .with_task(cfg.task.name(), cfg.task.num_actions());
    let obs = learner.obs_subscriber(shape).unwrap();
    let act = learner.act_publisher(per).unwrap();
    let mut sim = role(
        dir.path(),
        "sim.log",
        &[
            "sim",
            "serve",
            "--run",
            &run,
            "--run-dir",
            d,
            "--layout",
            layout_file.to_str().unwrap(),
            "--task",
            cfg.task.name(),
            "--seed",
            &SEED.to_string(),
            "--max-steps",
            &MAX_STEPS.to_string(),
            "--envs",
            &envs.to_string(),
            "--slices",
            &slices.to_string(),
        ],
    );

    let mut rng = 0x9E37_79B9_7F4A_7C15u64;
    let mut sent = vec![Vec::new(); slices];
    let (mut terminated, mut truncated) = (0, 0);
    for seq in 0..SAMPLES {
        let until = Instant::now() + Duration::from_secs(30);
        let sample = loop {
            if let Some(s) = obs.receive().unwrap() {
                break s;
            }
            assert!(
                Instant::now() < until && matches!(sim.try_wait(), Ok(None)),
                "no sample {seq}: {}",
                std::fs::read_to_string(dir.path().join("sim.log")).unwrap_or_default()
            );
            std::thread::sleep(Duration::from_micros(50));
        };
        let b = sample.batch();
        assert_eq!(b.header.seq, seq);
        let k = (seq % slices as u64) as usize;
        if seq < slices as u64 {
            refs[k].reset(bufs[k].out());
        } else {
            refs[k].step(&sent[k], bufs[k].out());
        }
        let r = &bufs[k];
        assert_eq!(b.meta, &r.meta[..], "records of sample {seq}");
        assert_eq!(b.cells, &r.cells[..], "cells of sample {seq}");
        for (i, m) in b.meta.iter().enumerate() {
            if !m.done() {
                assert_eq!(
                    (m.end_x, m.end_y, m.end_dir, m.end_carrying),
                    (m.x, m.y, m.dir, m.carrying)
                );
                continue;
            }
            let (finals, ours) = (
                &b.final_cells[i * cpe..(i + 1) * cpe],
                &r.final_cells[i * cpe..(i + 1) * cpe],
            );
            assert_eq!(finals, ours, "final cells of env {i} in sample {seq}");
            if m.terminated() {
                terminated += 1;
                assert_eq!(layout.cells[m.end_cell(layout.width)], Object::Exit as u8);
                assert_eq!(m.cell(layout.width), layout.width + 1, "back at the start");
                if m.balls == 2 {
                    assert_ne!(
                        finals,
                        &b.cells[i * cpe..(i + 1) * cpe],
                        "the balls were collected"
                    );
                }
            }
            truncated += usize::from(m.truncated());
        }
        drop(sample);
        let actions: Vec<u8> = (0..per)
            .map(|i| match i {
                0 => FORWARD,
                1 => LEFT,
                _ => {
                    rng ^= rng << 13;
                    rng ^= rng >> 7;
                    rng ^= rng << 17;
                    [LEFT, RIGHT, FORWARD, FORWARD][(rng % 4) as usize]
                }
            })
            .collect();
        act.send_actions(seq, &actions).unwrap();
        sent[k] = actions;
    }
    // 79 steps per slice: env 0 ends every 4, env 1 every 9.
    assert!(terminated >= 2 * 19, "{terminated} terminations");
    assert!(truncated >= 2 * 8, "{truncated} truncations");

    drop((obs, act, learner));
    sigterm(&sim);
    assert!(wait_exit(&mut sim, Duration::from_secs(20)).success());
    assert!(
        wait_for(Duration::from_secs(5), || shm_files(&run).is_empty()),
        "left behind: {:?}",
        shm_files(&run)
    );
}
