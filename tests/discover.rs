//! `worldgraph discover` as a user runs it: the same seed gives the same
//! world graph in one process and as the pipeline's processes, and a run
//! killed mid-way resumes to exactly what an uninterrupted run gives.

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// A short discovery on the small maze (3 rounds, 8 environments).
fn discover_args(run: &Path) -> Vec<String> {
    [
        "discover", "--maze", "small", "--seed", "3", "--rounds", "3", "--envs", "8", "--json",
        "--run",
    ]
    .iter()
    .map(|s| s.to_string())
    .chain([run.display().to_string()])
    .collect()
}

/// Runs to the end and returns the summary without its timings.
fn summary(args: &[String]) -> serde_json::Value {
    let out = Command::new(env!("CARGO_BIN_EXE_worldgraph"))
        .args(args)
        .stdin(Stdio::null())
        .output()
        .expect("run worldgraph");
    assert!(
        out.status.success(),
        "stderr: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    let line = stdout.lines().last().expect("a summary line");
    let mut v: serde_json::Value = serde_json::from_str(line).expect("JSON summary");
    let o = v.as_object_mut().expect("an object");
    for timing in ["wall_seconds", "train_steps_per_sec", "transport"] {
        assert!(o.remove(timing).is_some(), "summary lacks {timing}: {line}");
    }
    v
}

/// What the summary promises of its own figures: `V_p` is at most the top
/// 20 % of the small maze's 104 free cells and lists floor cells inside the
/// maze; the graph has edges, `π_g` shortened only edges that could be
/// shorter, and refinement only shortens, never below the shortest path.
fn assert_figures_hold_together(s: &serde_json::Value) {
    let n = |k: &str| s[k].as_u64().unwrap_or_else(|| panic!("{k} in {s}"));
    let cells = s["pivotal_cells"].as_array().expect("pivotal_cells");
    assert!(
        n("pivotal_states") > 0 && n("pivotal_states") <= 21,
        "|V_p| in {s}"
    );
    assert_eq!(cells.len() as u64, n("pivotal_states"), "{s}");
    let layout = sim::Maze::Small.layout(false);
    for c in cells {
        let (x, y) = (
            c[0].as_u64().unwrap() as usize,
            c[1].as_u64().unwrap() as usize,
        );
        assert!(
            x < layout.width && y < layout.height && layout.object(x, y) != sim::Object::Wall,
            "pivotal cell {c} is a floor cell"
        );
    }
    assert!(n("edges") > 0, "{s}");
    assert!(
        n("edges_refined_by_gcp") <= n("edges_improvable") && n("edges_improvable") <= n("edges"),
        "{s}"
    );
    assert!(
        n("edge_weight_shortest") <= n("edge_weight_refined")
            && n("edge_weight_refined") <= n("edge_weight_walks"),
        "{s}"
    );
    assert_eq!(n("rounds"), 3, "{s}");
}

#[test]
fn discovery_gives_the_same_graph_in_process_and_over_the_pipeline() {
    let dir = tempfile::tempdir().unwrap();
    let in_process = summary(&discover_args(&dir.path().join("a")));
    let mut args = discover_args(&dir.path().join("b"));
    args.push("--pipeline".into());
    let pipeline = summary(&args);
    assert_figures_hold_together(&in_process);
    assert_eq!(in_process, pipeline);
    for run in ["a", "b"] {
        for file in [
            "graph.json",
            "graph.png",
            "pivotal.png",
            "discovery_curves.png",
            "checkpoint/latent.ot",
        ] {
            assert!(
                dir.path().join(run).join(file).is_file(),
                "{run}/{file} missing"
            );
        }
        // Issue 21: the pictures carry a title and a legend, so they are
        // taller than the maze drawn at 24 px a cell.
        let maze = sim::Maze::Small.layout(false);
        for file in ["graph.png", "pivotal.png"] {
            let (w, h) = png_size(&dir.path().join(run).join(file));
            assert!(
                w >= 480 && h > maze.height as u32 * 24 + 100,
                "{run}/{file} is {w}×{h}: no caption"
            );
        }
    }
}

/// A PNG's width and height, from its header.
pub fn png_size(path: &Path) -> (u32, u32) {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    assert_eq!(&bytes[1..4], b"PNG", "{} is not a PNG", path.display());
    let be = |k: usize| u32::from_be_bytes([bytes[k], bytes[k + 1], bytes[k + 2], bytes[k + 3]]);
    (be(16), be(20))
}

#[test]
fn a_killed_discovery_resumes_to_the_uninterrupted_result() {
    let dir = tempfile::tempdir().unwrap();
    let whole = summary(&discover_args(&dir.path().join("whole")));

    let run = dir.path().join("killed");
    let args = discover_args(&run);
    let mut child = Command::new(env!("CARGO_BIN_EXE_worldgraph"))
        .args(&args)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    // Kill it as soon as the first round's checkpoint is written.
    let state = run.join("checkpoint").join("state.json");
    let until = Instant::now() + Duration::from_secs(120);
    while !state.is_file() && Instant::now() < until {
        std::thread::sleep(Duration::from_millis(20));
    }
    child.kill().unwrap();
    child.wait().unwrap();
    assert!(state.is_file(), "no checkpoint within 120 s");
    let rounds_done = serde_json::from_slice::<serde_json::Value>(&std::fs::read(&state).unwrap())
        .unwrap()["rounds_done"]
        .as_u64()
        .unwrap();
    assert!(
        rounds_done < 3,
        "the run finished before the kill ({rounds_done} rounds)"
    );

    let resumed = summary(&args);
    assert_eq!(whole, resumed);
}

/// A discovery whose `π_g` has not learnt to reach its goals says so, with
/// its success, and the settings that train it: stage 2 starts from it.
/// The settings file the warning names is one `discover` accepts (this run
/// uses it, five iterations a round instead of its 400).
#[test]
fn a_discovery_whose_pi_g_has_not_learnt_warns() {
    const REMEDY: &str = "experiments/discover-pi-g-curriculum.toml";
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    let mut args = discover_args(&run);
    args.retain(|a| a != "--json");
    let rounds = args.iter().position(|a| a == "--rounds").unwrap() + 1;
    args[rounds] = "1".into();
    let remedy = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(REMEDY);
    args.extend(["--gcp-iters", "5", "--config"].map(String::from));
    args.push(remedy.display().to_string());
    let out = Command::new(env!("CARGO_BIN_EXE_worldgraph"))
        .args(&args)
        .stdin(Stdio::null())
        .output()
        .expect("run worldgraph");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let summary: serde_json::Value =
        serde_json::from_slice(&std::fs::read(run.join("discovery.json")).unwrap()).unwrap();
    let success = summary["gcp_success_within_10"].as_f64().unwrap();
    assert!(success < 0.5, "5 iterations trained pi_g to {success}");
    let stderr = String::from_utf8_lossy(&out.stderr);
    let expected = format!(
        "warning: pi_g reaches {:.0}% of the goals within 10 steps",
        100.0 * success
    );
    assert!(stderr.contains(&expected), "{stderr}");
    assert!(stderr.contains(REMEDY), "{stderr}");
    let config = std::fs::read_to_string(run.join("config.toml")).unwrap();
    assert!(config.contains("goal_walk_len = 2"), "{config}");
}
