//! The command line as a user runs it: traces, renders, benchmarks and the
//! errors a malformed layout gets.

use std::path::Path;
use std::process::{Command, Output};

fn worldgraph(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_worldgraph"))
        .args(args)
        .output()
        .expect("run worldgraph")
}

fn write(dir: &Path, name: &str, text: &str) -> String {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p.display().to_string()
}

fn json_lines(out: &Output) -> Vec<serde_json::Value> {
    assert!(
        out.status.success(),
        "stderr: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).expect("JSON line"))
        .collect()
}

#[test]
fn trace_reports_positions_doors_and_rewards_of_a_door_key_layout() {
    let dir = tempfile::tempdir().unwrap();
    let layout = write(dir.path(), "dk.txt", "########\n#K<D..E#\n########\n");
    // Turn to the key, pick it up, turn back, unlock, walk to the exit.
    let out = worldgraph(&[
        "sim",
        "trace",
        "--layout",
        &layout,
        "--task",
        "doorkey",
        "--json",
        "--actions",
        "2,pickup,1,1,5,2,2,2,2",
    ]);
    let steps = json_lines(&out);
    assert_eq!(
        steps.len(),
        10,
        "the initial state plus one object per action"
    );
    assert_eq!(steps[0]["pos"], serde_json::json!([2, 1]));
    assert_eq!(steps[0]["dir"], 2);
    assert_eq!(
        steps[0]["doors"],
        serde_json::json!([{ "pos": [3, 1], "state": "locked" }])
    );
    assert_eq!(
        steps[1]["pos"],
        serde_json::json!([2, 1]),
        "the key blocks the way"
    );
    assert_eq!(steps[2]["carrying"], "key");
    assert_eq!(steps[5]["doors"][0]["state"], "open");
    assert!((steps[5]["reward"].as_f64().unwrap() - 0.99).abs() < 1e-6);
    let last = &steps[9];
    assert_eq!(last["pos"], serde_json::json!([6, 1]));
    assert_eq!(last["terminated"], true);
    assert_eq!(last["truncated"], false);
    assert!(steps[..9].iter().all(|s| s["terminated"] == false));
    assert!(
        steps[1..]
            .iter()
            .all(|s| s["t"].as_u64().is_some() && s["reward"].is_number())
    );
}

#[test]
fn trace_of_a_layout_file_spawns_no_random_balls_and_is_reproducible() {
    let dir = tempfile::tempdir().unwrap();
    let layout = write(dir.path(), "mg.txt", "#######\n#>.B.E#\n#######\n");
    let args = [
        "sim",
        "trace",
        "--layout",
        &layout,
        "--json",
        "--actions",
        "2,2,2,2",
        "--seed",
        "9",
    ];
    let a = json_lines(&worldgraph(&args));
    assert_eq!(a[2]["balls"], 1, "the file's ball is collected");
    assert!((a[2]["reward"].as_f64().unwrap() - 0.99).abs() < 1e-6);
    assert_eq!(a[4]["terminated"], true);
    assert!((a[4]["episode_return"].as_f64().unwrap() - 1.96).abs() < 1e-6);
    assert_eq!(a, json_lines(&worldgraph(&args)));
}

#[test]
fn embedded_maze_traces_depend_on_the_seed_only() {
    let run = |seed: &str| {
        let out = worldgraph(&[
            "sim",
            "trace",
            "--maze",
            "small",
            "--task",
            "multigoal-stochastic",
            "--seed",
            seed,
            "--json",
            "--actions",
            "2,2,1,2,2,2,0,2,2,2,2",
        ]);
        json_lines(&out)
    };
    assert_eq!(run("4"), run("4"));
}

#[test]
fn malformed_layouts_are_refused_with_line_and_column() {
    let dir = tempfile::tempdir().unwrap();
    let cases = [
        ("ragged", "#####\n#>.E#\n####\n", "ragged.txt:3:5"),
        ("unknown", "#####\n#>?E#\n#####\n", "line 2, column 3"),
        ("two-agents", "######\n#>.<E#\n######\n", "line 2, column 4"),
        ("no-exit", "#####\n#>..#\n#####\n", "no exit"),
        ("open", "#####\n#>..E\n#####\n", "line 2, column 5"),
        (
            "unreachable",
            "######\n#>#.E#\n######\n",
            "cannot be reached",
        ),
    ];
    for (name, text, needle) in cases {
        let path = write(dir.path(), &format!("{name}.txt"), text);
        let out = worldgraph(&["sim", "trace", "--layout", &path, "--actions", "2"]);
        assert!(!out.status.success(), "{name} accepted");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(needle), "{name}: {err}");
    }
    let out = worldgraph(&[
        "sim",
        "trace",
        "--layout",
        "/nonexistent/x.txt",
        "--actions",
        "2",
    ]);
    assert!(String::from_utf8_lossy(&out.stderr).contains("/nonexistent/x.txt"));
}

#[test]
fn render_writes_a_png_of_one_env_and_of_a_batch() {
    let dir = tempfile::tempdir().unwrap();
    let one = dir.path().join("one.png");
    let out = worldgraph(&[
        "sim",
        "render",
        "--maze",
        "small",
        "--png",
        one.to_str().unwrap(),
        "--cell-px",
        "10",
    ]);
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.starts_with("#############\n#.....#"), "{text}");
    let bytes = std::fs::read(&one).unwrap();
    assert_eq!(&bytes[1..4], b"PNG");
    // IHDR: width and height of 13x13 cells of 10 px.
    assert_eq!(u32::from_be_bytes(bytes[16..20].try_into().unwrap()), 130);
    let grid = dir.path().join("grid.png");
    assert!(
        worldgraph(&[
            "sim",
            "render",
            "--maze",
            "large",
            "--batch",
            "4",
            "--png",
            grid.to_str().unwrap()
        ])
        .status
        .success()
    );
    assert!(std::fs::metadata(&grid).unwrap().len() > 1000);
}

#[test]
fn bench_sim_json_has_the_documented_fields() {
    let out = worldgraph(&[
        "bench",
        "sim",
        "--maze",
        "small",
        "--envs",
        "64",
        "--threads",
        "2",
        "--seconds",
        "0.2",
        "--json",
    ]);
    let r = &json_lines(&out)[0];
    for k in [
        "steps_per_sec",
        "obs_bytes_per_step",
        "memcpy_bytes_per_sec",
        "ratio_to_memcpy_bound",
    ] {
        assert!(r[k].as_f64().is_some_and(|v| v > 0.0), "{k} in {r}");
    }
    // What was run, as asked, and the bytes of one observation: the small
    // maze's 13×13 cells and one 28-byte EnvMeta (the final cells are
    // written only on the steps that end an episode).
    assert_eq!(
        (&r["maze"], &r["task"], &r["envs"], &r["threads"]),
        (&"small".into(), &"multigoal".into(), &64.into(), &2.into()),
        "{r}"
    );
    assert_eq!(r["obs_bytes_per_step"], 13 * 13 + 28);
    // The ratio is the median of the windows' ratios.
    let f = |k: &str| r[k].as_f64().unwrap_or(f64::NAN);
    assert!(
        f("ratio_min") <= f("ratio_to_memcpy_bound")
            && f("ratio_to_memcpy_bound") <= f("ratio_max"),
        "min ≤ median ≤ max in {r}"
    );
    assert!(r["episodes"].as_u64().is_some_and(|e| e > 0), "{r}");
}

/// `a` and `b` agree to a relative 1e-9 (figures recomputed from others).
fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-9 * a.abs().max(b.abs())
}

/// The middle value of an odd count.
fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// The three setups of `bench pipeline` really run: shared memory, in
/// process and over sockets each move environments, nothing is lost, and
/// every round carries its figures (and the host's core-to-core round trip
/// when there are two CPUs to measure it on).
#[test]
fn bench_pipeline_json_has_the_documented_fields_and_every_round() {
    let out = worldgraph(&[
        "bench",
        "pipeline",
        "--maze",
        "small",
        "--envs",
        "16",
        "--seconds",
        "1",
        "--json",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let r = &json_lines(&out)[0];
    for k in [
        "ipc_steps_per_sec",
        "inprocess_steps_per_sec",
        "socket_steps_per_sec",
        "roundtrip_p50_us",
        "roundtrip_p99_us",
        "ipc_to_inprocess",
        "ipc_to_socket",
    ] {
        assert!(r[k].as_f64().is_some_and(|v| v > 0.0), "{k} in {r}");
    }
    assert_eq!(r["ipc_batches_lost"], 0);
    assert_eq!(
        (&r["maze"], &r["envs"]),
        (&"small".into(), &16.into()),
        "{r}"
    );
    let f = |v: &serde_json::Value, k: &str| v[k].as_f64().unwrap_or(f64::NAN);
    assert!(
        f(r, "roundtrip_p50_us") <= f(r, "roundtrip_p99_us")
            && f(r, "roundtrip_p99_us") <= f(r, "roundtrip_p999_us")
            && f(r, "socket_roundtrip_p50_us") <= f(r, "socket_roundtrip_p99_us"),
        "percentiles in order in {r}"
    );
    assert!(
        (0.0..=1.0).contains(&f(r, "sim_wait_fraction")),
        "a fraction: {r}"
    );
    // Every round measured both setups, and the headline figures are the
    // rounds' medians and their ratios, as documented.
    let rounds = r["rounds"].as_array().expect("rounds");
    assert_eq!(rounds.len(), 5);
    for round in rounds {
        let (ipc, local) = (
            f(round, "ipc_steps_per_sec"),
            f(round, "inprocess_steps_per_sec"),
        );
        assert!(ipc > 0.0 && local > 0.0, "{round}");
        assert!(close(f(round, "ratio"), ipc / local), "{round}");
    }
    let of_rounds = |k: &str| median(rounds.iter().map(|x| f(x, k)).collect());
    assert!(
        close(f(r, "ipc_steps_per_sec"), of_rounds("ipc_steps_per_sec"))
            && close(
                f(r, "inprocess_steps_per_sec"),
                of_rounds("inprocess_steps_per_sec")
            )
            && close(f(r, "ipc_to_inprocess"), of_rounds("ratio")),
        "medians of the rounds in {r}"
    );
    assert!(
        close(
            f(r, "ipc_to_socket"),
            f(r, "ipc_steps_per_sec") / f(r, "socket_steps_per_sec")
        ),
        "{r}"
    );
    let two_cpus = std::thread::available_parallelism().is_ok_and(|n| n.get() >= 2);
    if two_cpus {
        assert!(
            r["core_to_core_rtt_ns"]
                .as_f64()
                .is_some_and(|ns| ns > 0.0 && ns < 1e6),
            "core-to-core round trip in {r}"
        );
    }
}

#[test]
fn a_role_pinned_to_a_cpu_it_may_not_use_is_refused_naming_the_allowed_ones() {
    let dir = tempfile::tempdir().unwrap();
    let run_dir = dir.path().join("run");
    let out = worldgraph(&[
        "sim",
        "serve",
        "--run",
        "wgtest_cpu",
        "--run-dir",
        run_dir.to_str().unwrap(),
        "--cpu",
        "4095",
    ]);
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("--cpu 4095") && stderr.contains("may only run on CPUs"),
        "{stderr}"
    );
}

/// `sim render --png` into a folder that does not exist yet creates it and
/// says so; a path through a regular file, or one naming a folder, is
/// refused before anything is drawn, with a message naming the path.
#[test]
fn png_paths_get_their_folder_or_a_clear_refusal() {
    let dir = tempfile::tempdir().unwrap();
    let render = |png: &Path| {
        worldgraph(&[
            "sim",
            "render",
            "--maze",
            "small",
            "--png",
            png.to_str().unwrap(),
        ])
    };
    let stderr = |out: &Output| String::from_utf8_lossy(&out.stderr).into_owned();

    let nested = dir.path().join("new").join("sub").join("maze.png");
    let out = render(&nested);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(nested.is_file(), "the picture is written");
    assert!(
        stderr(&out).contains(&format!(
            "--png: created the folder {}",
            nested.parent().unwrap().display()
        )),
        "the new folder is reported: {}",
        stderr(&out)
    );

    let file = dir.path().join("notes.txt");
    std::fs::write(&file, "a file").unwrap();
    let through = file.join("maze.png");
    let out = render(&through);
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    assert_eq!(
        stderr(&out).trim(),
        format!(
            "error: --png {}: {} is a file, not a folder",
            through.display(),
            file.display()
        )
    );
    assert!(out.stdout.is_empty(), "nothing was drawn");
    assert_eq!(std::fs::read_to_string(&file).unwrap(), "a file");

    let out = render(dir.path());
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    assert!(
        stderr(&out).contains(&format!("--png {}: is a folder", dir.path().display())),
        "{}",
        stderr(&out)
    );
}

/// Sizes no run could hold are refused, naming the option and its limit,
/// before anything is written; never a panic or an abort.
#[test]
fn seed_ranges_and_batches_too_large_are_refused_naming_the_option_and_the_limit() {
    let dir = tempfile::tempdir().unwrap();
    let stderr = |out: &Output| String::from_utf8_lossy(&out.stderr).into_owned();
    for seeds in ["0..18446744073709551615", "0..1000000000", "5..10006"] {
        let out = worldgraph(&["evaluate", "no-such-run", "--seeds", seeds]);
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(1), "{seeds}: {err}");
        assert!(
            err.contains(&format!("--seeds \"{seeds}\"")) && err.contains("at most 10000"),
            "{seeds}: {err}"
        );
    }
    let config = write(dir.path(), "huge.toml", "[agent]\nenvs = 100000000\n");
    let run = dir.path().join("run");
    for (args, needles) in [
        (
            vec![
                "train",
                "--agent",
                "a2c",
                "--config",
                &config,
                "--run",
                run.to_str().unwrap(),
            ],
            vec!["envs = 100000000", "huge.toml", "at most 1024 environments"],
        ),
        (
            vec![
                "discover",
                "--envs",
                "100000000",
                "--run",
                run.to_str().unwrap(),
            ],
            vec!["--envs 100000000", "1024"],
        ),
    ] {
        let out = worldgraph(&args);
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(1), "{args:?}: {err}");
        for n in needles {
            assert!(err.contains(n), "{args:?}: {n:?} not in {err}");
        }
        assert!(!err.contains("panicked"), "{err}");
        assert!(!run.exists(), "{args:?} wrote its run directory");
    }
}

/// Output into a closed pipe (`worldgraph ... | true`) ends the command
/// quietly, as SIGPIPE ends any Unix tool: no panic, no status 101.
#[test]
fn a_command_writing_into_a_closed_pipe_ends_quietly() {
    use std::os::unix::process::ExitStatusExt;
    let dir = tempfile::tempdir().unwrap();
    let config = write(
        dir.path(),
        "tiny.toml",
        "env_steps = 320\neval_every = 160\nvalidation_seeds = 2\ntest_seeds = 2\n\
         [agent]\nenvs = 8\nrollout_len = 20\n",
    );
    let run = dir.path().join("run").display().to_string();
    let commands: [Vec<&str>; 3] = [
        vec!["clean", "--min-age", "100000"],
        vec!["sim", "render", "--maze", "small"],
        vec![
            "train", "--agent", "a2c", "--config", &config, "--run", &run,
        ],
    ];
    for args in commands {
        // A pipe whose reading end is closed before the command starts.
        let (read, write) = nix::unistd::pipe().unwrap();
        drop(read);
        let out = Command::new(env!("CARGO_BIN_EXE_worldgraph"))
            .args(&args)
            .env("WORLDGRAPH_TORCH_THREADS", "1")
            .stdout(std::process::Stdio::from(write))
            .stderr(std::process::Stdio::piped())
            .output()
            .expect("run worldgraph");
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(
            out.status.signal(),
            Some(nix::sys::signal::Signal::SIGPIPE as i32),
            "{args:?}: {:?}: {err}",
            out.status
        );
        assert!(!err.contains("panicked"), "{args:?}: {err}");
    }
}

/// Issue 21, item 8: a layout file is refused once it is longer than any
/// layout can be, not read whole first (`--layout /dev/zero` read 2 GB).
#[test]
fn a_layout_file_too_long_to_be_a_layout_is_refused_without_reading_it_whole() {
    use crate::reliability::run_bounded_with_pid;
    let dir = tempfile::tempdir().unwrap();
    let long = write(dir.path(), "long.txt", &"#".repeat(1 << 20));
    for path in [long.as_str(), "/dev/zero"] {
        let (_, out) = run_bounded_with_pid(
            &["sim", "trace", "--layout", path, "--actions", "2"],
            std::time::Duration::from_secs(20),
        );
        assert!(!out.status.success(), "{path} accepted");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            err.contains(path) && err.contains("longer than 65536 bytes"),
            "{path}: {err}"
        );
    }
}

/// Issue 21, item 8: `run --threads 0` is refused before anything starts
/// (the sim restarted in a loop, and with `--duration 1` the run exited 0
/// having run nothing); `run --help` does not offer `--cpu` as if `run`
/// took it.
#[test]
fn run_refuses_zero_threads_before_starting_and_its_help_says_cpu_is_for_one_role() {
    use crate::reliability::run_bounded_with_pid;
    let dir = tempfile::tempdir().unwrap();
    let run_dir = dir.path().join("r");
    let name = format!("threads0-{}", std::process::id());
    let (_, out) = run_bounded_with_pid(
        &[
            "run",
            "--maze",
            "small",
            "--envs",
            "8",
            "--threads",
            "0",
            "--duration",
            "1",
            "--run",
            &name,
            "--run-dir",
            run_dir.to_str().unwrap(),
        ],
        std::time::Duration::from_secs(30),
    );
    assert!(!out.status.success(), "--threads 0 accepted");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("--threads must be at least 1"), "{err}");
    assert!(!run_dir.exists(), "a refused run starts nothing");

    let help = String::from_utf8_lossy(&worldgraph(&["run", "--help"]).stdout).into_owned();
    assert!(help.contains("`run` refuses it"), "{help}");
}

#[test]
fn help_lists_the_environment_variables_the_commands_read() {
    let out = Command::new(env!("CARGO_BIN_EXE_worldgraph"))
        .arg("--help")
        .output()
        .expect("run worldgraph");
    let help = String::from_utf8_lossy(&out.stdout);
    for var in [
        "WORLDGRAPH_TORCH_THREADS",
        "WORLDGRAPH_LOG",
        "WORLDGRAPH_CACHE",
        "WORLDGRAPH_PYTHON",
    ] {
        assert!(help.contains(var), "{var} is not in --help:\n{help}");
    }
}

/// `bench learner` without a Python that has torch (issue 26): the Rust
/// paths are measured, the PyTorch figure is null with a note that says how
/// to install it; `--pytorch required` refuses instead, `--pytorch off`
/// says it is off.
#[test]
fn bench_learner_without_torch_reports_a_null_pytorch_figure_and_a_note() {
    use std::os::unix::fs::PermissionsExt;
    let dir = tempfile::tempdir().unwrap();
    let python = write(
        dir.path(),
        "python",
        "#!/bin/sh\necho \"ModuleNotFoundError: No module named 'torch'\" >&2\nexit 1\n",
    );
    std::fs::set_permissions(&python, std::fs::Permissions::from_mode(0o755)).unwrap();
    let bench = |extra: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_worldgraph"))
            .args([
                "bench",
                "learner",
                "--agent",
                "a2c",
                "--maze",
                "small",
                "--envs",
                "4",
                "--rollout",
                "4",
                "--threads",
                "1",
                "--seconds",
                "0.3",
                "--json",
            ])
            .args(extra)
            .env("WORLDGRAPH_PYTHON", &python)
            .output()
            .expect("run worldgraph")
    };
    let report = |out: &Output| -> serde_json::Value {
        assert!(
            out.status.success(),
            "stderr: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        serde_json::from_slice(&out.stdout).expect("one JSON object")
    };
    let r = report(&bench(&[]));
    assert!(
        r["fast"]["env_steps_per_sec"]
            .as_f64()
            .is_some_and(|v| v > 0.0),
        "{r}"
    );
    assert!(
        r["pytorch"].is_null() && r["fast_over_pytorch"].is_null(),
        "{r}"
    );
    let note = r["pytorch_note"].as_str().unwrap_or_default();
    assert!(
        note.contains("No module named 'torch'")
            && note.contains(&python)
            && note.contains("make bench-learner-python"),
        "{note}"
    );
    assert!(
        r["manager_decisions_per_env_step"].is_null(),
        "A2C has no Manager: {r}"
    );

    let out = bench(&["--pytorch", "required"]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("--pytorch required"), "{err}");

    let r = report(&bench(&["--pytorch", "off"]));
    assert!(r["pytorch"].is_null(), "{r}");
    assert!(
        r["pytorch_note"]
            .as_str()
            .is_some_and(|n| n.contains("--pytorch off")),
        "{r}"
    );
}

/// `train --layout` runs the method on a user's own Door-Key maze: its key
/// and door are the task's, the run keeps the layout for `evaluate`, and a
/// layout without a key is refused before anything is written.
#[test]
fn train_takes_a_door_key_layout_file_and_evaluate_reads_it_back() {
    let dir = tempfile::tempdir().unwrap();
    let layout = write(
        dir.path(),
        "mine.txt",
        "#######\n#>..#K#\n#...D.#\n#...#E#\n#######\n",
    );
    let run = dir.path().join("run");
    let out = worldgraph(&[
        "train",
        "--task",
        "doorkey",
        "--layout",
        &layout,
        "--agent",
        "a2c",
        "--env-steps",
        "2000",
        "--set",
        "eval_every=2000",
        "--set",
        "validation_seeds=2",
        "--set",
        "test_seeds=2",
        "--run",
        run.to_str().unwrap(),
        "--json",
    ]);
    let summary = json_lines(&out).pop().expect("a summary");
    assert_eq!(summary["task"], "doorkey");
    let kept = std::fs::read_to_string(run.join("layout.txt")).unwrap();
    assert_eq!(kept, std::fs::read_to_string(&layout).unwrap());
    assert!(
        run.join("objects.png").is_file(),
        "Door-Key's key/door/exit curves"
    );
    let out = worldgraph(&[
        "evaluate",
        run.to_str().unwrap(),
        "--seeds",
        "0..2",
        "--json",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // A layout without a key: the Door-Key task is refused, naming what is missing.
    let plain = write(dir.path(), "plain.txt", "#####\n#>.E#\n#####\n");
    let refused = dir.path().join("refused");
    let out = worldgraph(&[
        "train",
        "--task",
        "doorkey",
        "--layout",
        &plain,
        "--run",
        refused.to_str().unwrap(),
    ]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("needs a key (K) and a locked door (D)"));
    assert!(!refused.exists(), "nothing is written for a refused layout");
}
