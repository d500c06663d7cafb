//! `worldgraph experiment`, `--reproduce` and `table` as a user runs them:
//! a grid with a real (one-round) discovery, its summaries under
//! `results/`, finished runs skipped on a restart, a stopped grid resumed
//! to the uninterrupted result, a summary reproduced from its JSON alone,
//! and the tables rendered beside the paper's values.

use std::path::Path;
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

pub(crate) fn worldgraph(dir: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_worldgraph"))
        .args(args)
        .current_dir(dir)
        .env("WORLDGRAPH_TORCH_THREADS", "1")
        .output()
        .expect("run worldgraph")
}

pub(crate) fn ok(out: &Output) -> (String, String) {
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(
        out.status.success(),
        "status {:?}\nstderr: {stderr}",
        out.status
    );
    (String::from_utf8_lossy(&out.stdout).into_owned(), stderr)
}

pub(crate) fn refused(out: &Output) -> String {
    assert!(!out.status.success(), "expected a refusal");
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// A CI-sized grid: the small maze, one seed, two iterations of 32 × 60
/// env steps per run, a one-round discovery, 2 validation and 3 test seeds.
fn grid(name: &str, env_steps: u64, configs: &str) -> String {
    format!(
        "name = \"{name}\"\nseeds = [0]\nvalidation_seeds = 2\ntest_seeds = 3\n\
         [[maze]]\nname = \"small\"\nenv_steps = {env_steps}\neval_every = 1920\ndiscover_rounds = 1\n\
         [[group]]\ntable = 1\ntasks = [\"multigoal\"]\nconfigs = [{configs}]\n"
    )
}

/// Copies the committed file `from` (relative to the repository) to `to`
/// (relative to the test's directory `d`), making its folders.
fn copy_committed(d: &Path, from: &str, to: &str) {
    let to = d.join(to);
    std::fs::create_dir_all(to.parent().unwrap()).unwrap();
    std::fs::copy(Path::new(env!("CARGO_MANIFEST_DIR")).join(from), &to).unwrap();
}

fn json(p: &Path) -> serde_json::Value {
    serde_json::from_str(
        &std::fs::read_to_string(p).unwrap_or_else(|e| panic!("{}: {e}", p.display())),
    )
    .unwrap()
}

#[test]
fn a_grid_records_its_runs_skips_them_on_restart_and_each_reproduces() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // The grid pins its discovery settings.
    std::fs::write(d.join("discover.toml"), "[goal_chains]\nper_round = 64\n").unwrap();
    std::fs::write(
        d.join("grid.toml"),
        format!(
            "discover_config = \"discover.toml\"\n{}",
            grid("tiny", 3840, "\"a2c\", \"wn-pivotal-trav-init\"")
        ),
    )
    .unwrap();
    let (_, err) = ok(&worldgraph(d, &["experiment", "grid.toml", "--jobs", "2"]));
    assert!(
        err.contains("2 training runs (0 done, 2 to run), 1 discoveries to run"),
        "{err}"
    );

    // The result set keeps the grid file its summaries came from.
    assert_eq!(
        std::fs::read_to_string(d.join("results/tiny.toml")).unwrap(),
        std::fs::read_to_string(d.join("grid.toml")).unwrap()
    );

    let wn = json(&d.join("results/small/multigoal/wn-pivotal-trav-init/seed-0.json"));
    let a2c = json(&d.join("results/small/multigoal/a2c/seed-0.json"));
    for (r, config) in [(&wn, "wn-pivotal-trav-init"), (&a2c, "a2c")] {
        assert_eq!(r["config"], config);
        assert_eq!(r["maze"], "small");
        assert_eq!(r["task"], "multigoal");
        assert_eq!(r["seed"], 0);
        assert_eq!(r["env_steps"], 3840);
        assert_eq!(r["test_seeds"], 3);
        assert_eq!(r["validation_seeds"], 2);
        assert_eq!(r["train_config"]["env_steps"], 3840);
        let curve = r["validation_curve"].as_array().unwrap();
        assert_eq!(curve.len(), 2, "one validation per 1920 env steps");
        assert_eq!(curve[1]["env_steps"], 3840);
        assert!(curve[1]["wall_seconds"].as_f64().unwrap() > 0.0);
        let score = r["test_score"].as_f64().unwrap();
        assert!((-10.0..=10.0).contains(&score), "{score}");
    }
    // The WN run used the grid's discovery, recorded so it can be redone;
    // A2C needs none.
    assert_eq!(wn["discover"]["rounds"], 1);
    assert!(a2c["discover"].is_null());
    let disc = json(&d.join("results/small/discover/seed-0.json"));
    assert!(disc["summary"]["pivotal_states"].as_u64().unwrap() > 0);
    assert_eq!(disc["spec"]["rounds"], 1);

    // A restart runs nothing: every run has its summary.
    let before = std::fs::read(d.join("results/small/multigoal/a2c/seed-0.json")).unwrap();
    let (_, err) = ok(&worldgraph(d, &["experiment", "grid.toml"]));
    assert!(
        err.contains("(2 done, 0 to run), 0 discoveries to run"),
        "{err}"
    );
    assert!(err.contains("0 runs finished, 0 failed"), "{err}");
    assert_eq!(
        std::fs::read(d.join("results/small/multigoal/a2c/seed-0.json")).unwrap(),
        before
    );

    // A discovery that finished without its summary (the grid stopped in
    // between) is recorded on the next start, and --discoveries-only runs
    // no training.
    let disc_path = d.join("results/small/discover/seed-0.json");
    let recorded = std::fs::read(&disc_path).unwrap();
    std::fs::remove_file(&disc_path).unwrap();
    let (_, err) = ok(&worldgraph(
        d,
        &["experiment", "grid.toml", "--discoveries-only"],
    ));
    assert!(
        err.contains("0 training runs") && err.contains("recorded discover small seed 0"),
        "{err}"
    );
    assert_eq!(std::fs::read(&disc_path).unwrap(), recorded);
    // Its summary names the binary that made the discovery (the last start
    // in its invocations.txt), not the one that recorded it: a discovery
    // copied in from a grid run on an older commit keeps that commit.
    assert_eq!(disc["commit"], wn["commit"]);
    let invocations = d.join("results/runs/tiny/discover/small-seed-0/invocations.txt");
    let made_by = std::fs::read_to_string(&invocations).unwrap();
    let head = wn["commit"].as_str().unwrap();
    assert!(made_by.contains(&format!("(commit {head}): ")), "{made_by}");
    let older = "0123456789abcdef0123456789abcdef01234567";
    std::fs::write(&invocations, made_by.replace(head, older)).unwrap();
    std::fs::remove_file(&disc_path).unwrap();
    ok(&worldgraph(
        d,
        &["experiment", "grid.toml", "--discoveries-only"],
    ));
    assert_eq!(json(&disc_path)["commit"], older);
    // A discovery made before `discover` recorded its starts names none.
    std::fs::remove_file(&invocations).unwrap();
    std::fs::remove_file(&disc_path).unwrap();
    ok(&worldgraph(
        d,
        &["experiment", "grid.toml", "--discoveries-only"],
    ));
    assert_eq!(json(&disc_path)["commit"], "unknown");
    std::fs::write(&disc_path, &recorded).unwrap();

    // The same results under another budget are refused, not counted.
    std::fs::write(
        d.join("longer.toml"),
        grid("tiny", 5760, "\"a2c\", \"wn-pivotal-trav-init\""),
    )
    .unwrap();
    let err = refused(&worldgraph(d, &["experiment", "longer.toml"]));
    assert!(
        err.contains("was run with env_steps 3840") && err.contains("another --results"),
        "{err}"
    );

    // Each summary reproduces from its JSON alone, discovery included, in a
    // fresh working directory.
    let (out, _) = ok(&worldgraph(
        d,
        &[
            "experiment",
            "--reproduce",
            "results/small/multigoal/wn-pivotal-trav-init/seed-0.json",
            "--work",
            "again",
        ],
    ));
    assert!(out.contains("reproduced: the same test score"), "{out}");
    assert!(d.join("again/discover/small-seed-0/graph.json").exists());
    // ... with the settings its grid pins.
    let resolved =
        std::fs::read_to_string(d.join("again/discover/small-seed-0/config.toml")).unwrap();
    assert!(resolved.contains("per_round = 64"), "{resolved}");
    // A summary whose score was changed does not.
    let mut bad = a2c.clone();
    bad["test_score"] = serde_json::json!(a2c["test_score"].as_f64().unwrap() + 0.5);
    std::fs::write(d.join("edited.json"), serde_json::to_vec(&bad).unwrap()).unwrap();
    let err = refused(&worldgraph(
        d,
        &[
            "experiment",
            "--reproduce",
            "edited.json",
            "--work",
            "edited",
        ],
    ));
    assert!(err.contains("differs"), "{err}");
    // Every summary records the CPU it ran on (floats differ from one CPU
    // model to another); a summary from another CPU that does not reproduce
    // says so.
    let cpu = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|i| {
            i.lines()
                .find_map(|l| l.strip_prefix("model name"))
                .and_then(|r| r.split_once(':'))
                .map(|(_, n)| n.trim().to_string())
        })
        .unwrap_or_else(|| "unknown".to_string());
    assert_eq!(a2c["cpu"], cpu.as_str());
    assert_eq!(disc["cpu"], cpu.as_str());
    bad["cpu"] = serde_json::json!("Another CPU");
    std::fs::write(d.join("elsewhere.json"), serde_json::to_vec(&bad).unwrap()).unwrap();
    let err = refused(&worldgraph(
        d,
        &[
            "experiment",
            "--reproduce",
            "elsewhere.json",
            "--work",
            "elsewhere",
        ],
    ));
    assert!(
        err.contains("made on another CPU (Another CPU") && err.contains(&cpu),
        "{err}"
    );
    // The summaries record the production gradient path; one made on a path
    // this version retired names the commit it reproduces on, and starts
    // nothing.
    assert_eq!(a2c["grad_path"], "rust-core");
    let mut old = a2c.clone();
    old["grad_path"] = serde_json::json!("rust-encoder");
    old["commit"] = serde_json::json!("0123456789abcdef0123456789abcdef01234567+dirty");
    std::fs::write(d.join("old.json"), serde_json::to_vec(&old).unwrap()).unwrap();
    let err = refused(&worldgraph(
        d,
        &["experiment", "--reproduce", "old.json", "--work", "old"],
    ));
    assert!(
        err.contains("\"rust-encoder\"")
            && err.contains("git checkout 0123456789abcdef0123456789abcdef01234567`")
            && err.contains("uncommitted changes"),
        "{err}"
    );
    assert!(
        !d.join("old").exists(),
        "a refused reproduction starts nothing"
    );

    // The tables: each run's cell beside the paper's value, the budget, the
    // time to score and the curves.
    ok(&worldgraph(
        d,
        &["table", "results", "--out", "docs/results.md"],
    ));
    let md = std::fs::read_to_string(d.join("docs/results.md")).unwrap();
    let a2c_cell = format!(
        "| A2C | {:.3} ± 0.000 (n=1) | 2.04 |",
        a2c["test_score"].as_f64().unwrap()
    );
    assert!(md.contains(&a2c_cell), "{a2c_cell} not in\n{md}");
    assert!(md.contains("| FN | — | Fail |"), "{md}");
    assert!(md.contains("| small | 3840 | 1920 | 2 |"), "{md}");
    // `--no-figures`: the same tables, no figure drawn or linked.
    ok(&worldgraph(d, &["table", "results", "--no-figures"]));
    let text_only = std::fs::read_to_string(d.join("results/README.md")).unwrap();
    assert!(text_only.contains(&a2c_cell), "{text_only}");
    assert!(
        text_only.contains("## Time to score") && !text_only.contains(".png"),
        "{text_only}"
    );
    assert!(!d.join("results/figures").exists());
    // The set's discovery, with what `discover` measured of it.
    let pivotal = disc["summary"]["pivotal_states"].as_u64().unwrap();
    let row = format!("| small | 0 | 1 | {pivotal} | ");
    assert!(
        text_only.contains("## World graph discoveries") && text_only.contains(&row),
        "{row} not in\n{text_only}"
    );
    // A set of discoveries alone (`--discoveries-only`) gets the same
    // section as its README, not a refusal.
    let only = d.join("discovered/small/discover");
    std::fs::create_dir_all(&only).unwrap();
    std::fs::copy(
        d.join("results/small/discover/seed-0.json"),
        only.join("seed-0.json"),
    )
    .unwrap();
    ok(&worldgraph(d, &["table", "discovered"]));
    let md_only = std::fs::read_to_string(d.join("discovered/README.md")).unwrap();
    assert!(
        md_only.contains("from the 1 discovery summaries") && md_only.contains(&row),
        "{md_only}"
    );
    // Without --out, the tables are the result set's README, its figures
    // beside it: the set is one folder.
    ok(&worldgraph(d, &["table", "results"]));
    let readme = std::fs::read_to_string(d.join("results/README.md")).unwrap();
    assert!(readme.contains(&a2c_cell), "{readme}");
    assert!(
        d.join("results/figures/time-to-score-small-multigoal.png")
            .is_file()
    );
    // Every cell's budget beside it, with its share of the paper's 100k
    // iterations × 32 agents × 60 steps.
    assert!(
        md.contains("| configuration | small (3840 env steps, 0.002 % of the paper's) | paper |"),
        "{md}"
    );
    assert!(md.contains("## Time to score"), "{md}");
    for f in [
        "docs/figures/fig4-small-multigoal-pi-g-init.png",
        "docs/figures/time-to-score-small-multigoal.png",
    ] {
        let png = std::fs::read(d.join(f)).unwrap_or_else(|e| panic!("{f}: {e}"));
        assert_eq!(&png[1..4], b"PNG", "{f}");
    }
    // The rliable aggregates: one run per cell, so the IQM is the score
    // and its interval a point; the probability of improvement of the
    // hierarchy over A2C is 1, ½ or 0 as their test scores compare.
    let (a2c_score, wn_score) = (
        a2c["test_score"].as_f64().unwrap(),
        wn["test_score"].as_f64().unwrap(),
    );
    let iqm = format!(
        "| small | multigoal | A2C | 1 | {a2c_score:.3} [{a2c_score:.3}, {a2c_score:.3}] |"
    );
    assert!(md.contains(&iqm), "{iqm} not in\n{md}");
    let p = if wn_score > a2c_score {
        1.0
    } else if wn_score == a2c_score {
        0.5
    } else {
        0.0
    };
    let poi =
        format!("| WN V_p + traversal + π_g init over A2C | 1 | 1 / 1 | {p:.2} [{p:.2}, {p:.2}] |");
    assert!(md.contains(&poi), "{poi} not in\n{md}");
    // ... and the same on that maze and task alone.
    let per_task = format!(
        "| WN V_p + traversal + π_g init over A2C | small | multigoal | 1 / 1 | {p:.2} [{p:.2}, {p:.2}] |"
    );
    assert!(md.contains(&per_task), "{per_task} not in\n{md}");
    // scores.csv: a header and one row per run that pandas reads as is.
    let csv = std::fs::read_to_string(d.join("results/scores.csv")).unwrap();
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(lines.len(), 3, "{csv}");
    assert!(
        lines[0].starts_with("maze,task,config,seed,test_score,"),
        "{csv}"
    );
    let a2c_row: Vec<&str> = lines[1].split(',').collect();
    assert_eq!(&a2c_row[..4], ["small", "multigoal", "a2c", "0"], "{csv}");
    assert_eq!(a2c_row[4].parse::<f64>().unwrap(), a2c_score);
    assert_eq!(a2c_row.len(), lines[0].split(',').count());
}

#[test]
fn a_stopped_grid_resumes_to_the_uninterrupted_result() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // Six iterations, three validations: long enough to stop in between.
    std::fs::write(d.join("whole.toml"), grid("whole", 11520, "\"a2c\"")).unwrap();
    std::fs::write(d.join("stopped.toml"), grid("stopped", 11520, "\"a2c\"")).unwrap();
    ok(&worldgraph(
        d,
        &["experiment", "whole.toml", "--results", "whole"],
    ));

    let child = Command::new(env!("CARGO_BIN_EXE_worldgraph"))
        .args(["experiment", "stopped.toml", "--results", "stopped"])
        .current_dir(d)
        .env("WORLDGRAPH_TORCH_THREADS", "1")
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Stop it once its run has checkpointed a segment.
    let state = d.join("stopped/runs/stopped/small/multigoal/a2c/seed-0/checkpoint/state.json");
    let t0 = Instant::now();
    while !state.exists() && t0.elapsed() < Duration::from_secs(120) {
        std::thread::sleep(Duration::from_millis(20));
    }
    assert!(state.exists(), "the run never checkpointed");
    nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(child.id() as i32),
        nix::sys::signal::Signal::SIGTERM,
    )
    .unwrap();
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    let finished_first = d.join("stopped/small/multigoal/a2c/seed-0.json").exists();
    if !finished_first {
        assert!(!out.status.success(), "a stopped grid exits non-zero");
        assert!(err.contains("stopped"), "{err}");
    }
    // Its run was stopped with it: the run directory is free again.
    let (_, err) = ok(&worldgraph(
        d,
        &["experiment", "stopped.toml", "--results", "stopped"],
    ));
    assert!(!err.contains("in use"), "{err}");
    let whole = json(&d.join("whole/small/multigoal/a2c/seed-0.json"));
    let stopped = json(&d.join("stopped/small/multigoal/a2c/seed-0.json"));
    assert_eq!(whole["test_score"], stopped["test_score"]);
    let scores = |r: &serde_json::Value| -> Vec<f64> {
        r["validation_curve"]
            .as_array()
            .unwrap()
            .iter()
            .map(|p| p["score"].as_f64().unwrap())
            .collect()
    };
    assert_eq!(scores(&whole), scores(&stopped));
}

#[test]
fn bad_grids_are_refused_naming_what_is_wrong() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let cases = [
        (
            grid("g", 3840, "\"wn-best\""),
            "unknown configuration \"wn-best\"",
        ),
        (grid("g", 3840, "\"wn-all-trav\""), "traversal"),
        (
            grid("g", 3840, "\"a2c\"").replace("seeds = [0]", "seeds = []"),
            "at least one training seed",
        ),
        (
            grid("g", 3840, "\"a2c\"").replace("table = 1", "table = 1\nmazes = [\"large\"]"),
            "group maze large has no [[maze]] budget",
        ),
        (
            grid("g", 3840, "\"a2c\"")
                .replace("discover_rounds = 1", "discover_rounds = 1\nepochs = 3"),
            "unknown field `epochs`",
        ),
        (
            grid("g", 3840, "\"a2c\"").replace("\"multigoal\"", "\"multi\""),
            "multi",
        ),
        (
            grid("g", 3840, "\"a2c\"").replace("name = \"g\"", "name = \"../g\""),
            "must be letters",
        ),
    ];
    for (text, what) in cases {
        std::fs::write(d.join("bad.toml"), &text).unwrap();
        let err = refused(&worldgraph(d, &["experiment", "bad.toml"]));
        assert!(err.contains(what), "{what:?} not in {err}");
        assert!(
            !d.join("runs").exists() && !d.join("results").exists(),
            "a refused grid starts nothing"
        );
    }
    let err = refused(&worldgraph(d, &["table", "nothing-here"]));
    assert!(err.contains("nothing-here"), "{err}");
}

#[test]
fn a_grid_killed_with_sigkill_takes_its_runs_with_it() {
    use crate::reliability::{Orphans, alive, children_of};
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // A budget far longer than the test: the run is still training when
    // its grid is killed.
    std::fs::write(d.join("long.toml"), grid("long", 100_000_000, "\"a2c\"")).unwrap();
    let log = std::fs::File::create(d.join("grid.log")).unwrap();
    let mut parent = Command::new(env!("CARGO_BIN_EXE_worldgraph"))
        .args(["experiment", "long.toml"])
        .current_dir(d)
        .env("WORLDGRAPH_TORCH_THREADS", "1")
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(log)
        .spawn()
        .unwrap();
    let pid = parent.id();
    let run = d.join("results/runs/long/small/multigoal/a2c/seed-0");
    let t0 = Instant::now();
    while !(children_of(pid).len() == 1 && run.join("seeds.json").exists())
        && t0.elapsed() < Duration::from_secs(60)
    {
        std::thread::sleep(Duration::from_millis(20));
    }
    let runs = Orphans {
        pids: children_of(pid),
        tag: "long".to_string(),
    };
    if runs.pids.len() != 1 || !run.join("seeds.json").exists() {
        let _ = parent.kill();
        let _ = parent.wait();
        panic!(
            "the grid never started its run: {}",
            std::fs::read_to_string(d.join("grid.log")).unwrap_or_default()
        );
    }
    // --status names the run's cell process, the grid's child.
    let (out, _) = ok(&worldgraph(d, &["experiment", "long.toml", "--status"]));
    assert!(
        out.contains(&format!(
            "running  small/multigoal/a2c/seed-0  pid {} on ",
            runs.pids[0]
        )),
        "{out}"
    );
    parent.kill().unwrap();
    parent.wait().unwrap();
    let t0 = Instant::now();
    while runs.pids.iter().any(|&p| alive(p)) && t0.elapsed() < Duration::from_secs(10) {
        std::thread::sleep(Duration::from_millis(20));
    }
    assert!(
        runs.pids.iter().all(|&p| !alive(p)),
        "the run's cell process outlived its grid's SIGKILL"
    );
    // Its run directory is free: a rerun of the grid would take it.
    let lock = std::fs::File::open(run.join("lock")).unwrap();
    assert!(lock.try_lock().is_ok(), "the run's lock is still held");
    // The cell stopped its run and said so.
    let (out, _) = ok(&worldgraph(d, &["experiment", "long.toml", "--status"]));
    assert!(
        out.contains("failed 1, left 0")
            && out.contains("failed   small/multigoal/a2c/seed-0  stopped by a signal"),
        "{out}"
    );
}

#[test]
fn a_grid_is_checked_whole_at_load_and_filters_that_select_nothing_warn() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // A seed twice would be two runs sharing one directory and summary.
    std::fs::write(
        d.join("twice.toml"),
        grid("g", 3840, "\"a2c\"").replace("seeds = [0]", "seeds = [0, 0]"),
    )
    .unwrap();
    let err = refused(&worldgraph(d, &["experiment", "twice.toml", "--dry-run"]));
    assert!(err.contains("seeds: 0 is listed twice"), "{err}");
    // The discovery settings a grid pins are checked by --dry-run too.
    for (text, what) in [
        ("walk_len = 0\n", "walk_len"),
        (
            "[goal_chains]\nbatch_share = 2.0\n",
            "goal_chains.batch_share",
        ),
        ("walk_lenn = 3\n", "walk_lenn"),
    ] {
        std::fs::write(d.join("discover.toml"), text).unwrap();
        std::fs::write(
            d.join("pinned.toml"),
            format!(
                "discover_config = \"discover.toml\"\n{}",
                grid("g", 3840, "\"wn-pivotal\"")
            ),
        )
        .unwrap();
        let err = refused(&worldgraph(d, &["experiment", "pinned.toml", "--dry-run"]));
        assert!(
            err.contains("discover_config") && err.contains("discover.toml") && err.contains(what),
            "{what:?} not in {err}"
        );
    }
    assert!(
        !d.join("runs").exists() && !d.join("results").exists(),
        "a refused grid starts nothing"
    );
    // Filters that select no run say so.
    std::fs::write(d.join("ok.toml"), grid("g", 3840, "\"a2c\"")).unwrap();
    let (out, err) = ok(&worldgraph(
        d,
        &[
            "experiment",
            "ok.toml",
            "--dry-run",
            "--seed",
            "9",
            "--maze",
            "medium",
        ],
    ));
    assert!(out.is_empty(), "{out}");
    for w in [
        "warning: --maze medium matches no run of ok.toml",
        "warning: --seed 9 matches no run of ok.toml",
        "warning: the filters (--maze medium --seed 9) select no run of ok.toml",
    ] {
        assert!(err.contains(w), "{w:?} not in {err}");
    }
    let (out, err) = ok(&worldgraph(d, &["experiment", "ok.toml", "--dry-run"]));
    assert!(out.contains("small/multigoal/a2c/seed-0"), "{out}");
    assert!(!err.contains("warning"), "{err}");
}

/// Issue 21, item 4: a summary copied under another name or folder is the
/// same run, refused naming both files rather than counted as a fourth
/// seed. Item 8: `table` refuses an `--out` that is a directory before it
/// writes any figure.
#[test]
fn table_refuses_a_summary_counted_twice_and_an_out_that_is_a_directory() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let committed = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("results/archive/stage2/small/multigoal/a2c/seed-0.json");
    let cell = d.join("results/small/multigoal/a2c");
    std::fs::create_dir_all(&cell).unwrap();
    std::fs::copy(&committed, cell.join("seed-0.json")).unwrap();

    // One summary: the table renders; `--out` a directory is refused first.
    std::fs::create_dir_all(d.join("good")).unwrap();
    let err = refused(&worldgraph(d, &["table", "results", "--out", "good"]));
    assert!(err.contains("good") && err.contains("directory"), "{err}");
    assert!(
        !d.join("figures").exists() && std::fs::read_dir(d.join("good")).unwrap().next().is_none(),
        "a refused table writes no figure"
    );
    ok(&worldgraph(
        d,
        &["table", "results", "--out", "out/results.md"],
    ));

    // The same summary under another name, then under another folder.
    for copy in [
        cell.join("seed-0-copy.json"),
        d.join("results/old/seed-0.json"),
    ] {
        std::fs::create_dir_all(copy.parent().unwrap()).unwrap();
        std::fs::copy(&committed, &copy).unwrap();
        let err = refused(&worldgraph(
            d,
            &["table", "results", "--out", "out/results.md"],
        ));
        assert!(
            err.contains("results/small/multigoal/a2c/seed-0.json")
                && err.contains(&copy.strip_prefix(d).unwrap().display().to_string()),
            "both files named: {err}"
        );
        std::fs::remove_file(&copy).unwrap();
    }

    // Another grid's result set below the root (its own maze folders) is
    // not read, so not counted twice, and the table says it left it out.
    let other = d.join("results/goal-map/small/multigoal/a2c");
    std::fs::create_dir_all(&other).unwrap();
    std::fs::copy(&committed, other.join("seed-0.json")).unwrap();
    let out = worldgraph(d, &["table", "results", "--out", "out/results.md"]);
    let (_, err) = ok(&out);
    assert!(
        err.contains("results/goal-map") && err.contains("not read"),
        "{err}"
    );
    let md = std::fs::read_to_string(d.join("out/results.md")).unwrap();
    assert!(
        md.contains("from the 1 run summaries") && md.contains("`results/goal-map`"),
        "{md}"
    );
}

/// Issue 25's headline: the time-to-score table's reference may be the
/// flat A2C trained longer (`--reference`), so the speed-up is defined when
/// the grid's A2C does not reach the threshold within the grid's budget; an
/// A2C seed that never reaches it makes the speed-up a lower bound. Where
/// every seed of the grid's own A2C reaches it, that row stays the
/// reference. On the committed summaries: the small MultiGoal grid at 3M
/// env steps and the A2C run to 9M (`results/a2c-plateau`), seeds 0 and 1.
#[test]
fn time_to_score_takes_a_longer_a2c_as_reference_and_bounds_censored_seeds() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let copy = |from: &str, to: &str| copy_committed(d, from, to);
    for seed in [0, 1] {
        for config in ["a2c", "wn-pivotal-init"] {
            let p = format!("small/multigoal/{config}/seed-{seed}.json");
            copy(&format!("results/paper-real/{p}"), &format!("grid/{p}"));
        }
        let p = format!("small/multigoal/a2c/seed-{seed}.json");
        copy(&format!("results/a2c-plateau/{p}"), &format!("longer/{p}"));
    }
    let table = |reference: &str| {
        worldgraph(
            d,
            &[
                "table",
                "grid",
                "--out",
                "out/results.md",
                "--reference",
                reference,
            ],
        )
    };
    ok(&table("longer"));
    let md = std::fs::read_to_string(d.join("out/results.md")).unwrap();
    let row = |name: &str| {
        md.lines()
            .find(|l| l.starts_with("| small | multigoal |") && l.contains(&format!("| {name} |")))
            .unwrap_or_else(|| panic!("no {name} row in\n{md}"))
            .to_string()
    };
    // Within 3M neither A2C seed reaches the bar; within 9M seed 0 does and
    // seed 1 does not, so A2C's mean time is only bounded below.
    assert!(row("A2C").contains("| 0/2 |"), "{}", row("A2C"));
    let reference = row("A2C, 9.07M env steps (reference)");
    assert!(
        reference.contains("| 1/2 |") && reference.ends_with("| 1 (reference) |"),
        "{reference}"
    );
    let wn = row("WN V_p + π_g init");
    assert!(wn.contains("| 2/2 |") && wn.contains("≥ "), "{wn}");
    // The bound is A2C's censored mean over WN's mean time, both read from
    // the summaries themselves.
    let first = |p: &str, bar: f64| -> f64 {
        let v = json(&d.join(p));
        let curve = v["validation_curve"].as_array().unwrap();
        curve
            .iter()
            .find(|q| q["score"].as_f64().unwrap() >= bar)
            .map_or(v["env_steps"].as_f64().unwrap(), |q| {
                q["env_steps"].as_f64().unwrap()
            })
    };
    let bar: f64 = reference.split(" | ").nth(2).unwrap().parse().unwrap();
    let a2c = (first("longer/small/multigoal/a2c/seed-0.json", bar)
        + first("longer/small/multigoal/a2c/seed-1.json", bar))
        / 2.0;
    let own = (first("grid/small/multigoal/wn-pivotal-init/seed-0.json", bar)
        + first("grid/small/multigoal/wn-pivotal-init/seed-1.json", bar))
        / 2.0;
    assert!(
        wn.contains(&format!("≥ {:.2}× /", a2c / own)),
        "{wn}, {a2c} / {own}"
    );
    assert!(
        md.contains("repeat this grid's A2C run of the same seed at every validation, to the last digit, on 2 of the 2 seeds"),
        "{md}"
    );

    // Two reference sets of one maze and task: the one trained longest
    // is the reference, and the table says which it left out.
    for seed in [0, 1] {
        let p = format!("small/multigoal/a2c/seed-{seed}.json");
        copy(&format!("results/paper-real/{p}"), &format!("short/{p}"));
    }
    let out = worldgraph(
        d,
        &[
            "table",
            "grid",
            "--out",
            "out/results.md",
            "--reference",
            "short",
            "--reference",
            "longer",
        ],
    );
    let (_, err) = ok(&out);
    assert!(
        err.contains("short: small/multigoal is shorter than longer's"),
        "{err}"
    );
    let again = std::fs::read_to_string(d.join("out/results.md")).unwrap();
    assert!(again.contains(&reference) && again.contains(&wn), "{again}");

    // Where every seed of the grid's own A2C reaches the threshold, its
    // row stays the reference (exact, and timed beside the grid's runs),
    // not the longer A2C: a grid of A2C seeds 0 and 1 alone sets the bar at
    // 90 % of their own mean best validation, which both reach within 3M.
    for seed in [0, 1] {
        let p = format!("small/multigoal/a2c/seed-{seed}.json");
        copy(&format!("results/paper-real/{p}"), &format!("own/{p}"));
    }
    let out = worldgraph(
        d,
        &["table", "own", "--out", "own.md", "--reference", "longer"],
    );
    ok(&out);
    let md = std::fs::read_to_string(d.join("own.md")).unwrap();
    let rows: Vec<&str> = md
        .lines()
        .filter(|l| l.starts_with("| small | multigoal |") && l.contains("reference"))
        .collect();
    assert_eq!(rows.len(), 1, "one reference row, the grid's A2C: {rows:?}");
    let bar: f64 = rows[0].split(" | ").nth(2).unwrap().parse().unwrap();
    let steps = (first("own/small/multigoal/a2c/seed-0.json", bar)
        + first("own/small/multigoal/a2c/seed-1.json", bar))
        / 2.0;
    assert!(
        rows[0].contains(&format!("| A2C | 2/2 | {steps:.0} ± "))
            && rows[0].ends_with("| 1 (reference) |"),
        "{} (mean steps {steps})",
        rows[0]
    );
    assert!(
        md.contains("so its row is the reference, not the longer A2C `longer`")
            && md.contains("on 2 of the 2 seeds both ran"),
        "{md}"
    );

    // A reference is flat A2C only.
    copy(
        "results/paper-real/small/multigoal/fn/seed-0.json",
        "longer/small/multigoal/fn/seed-0.json",
    );
    let err = refused(&table("longer"));
    assert!(err.contains("not a flat A2C run"), "{err}");
}

/// Issue 47: the flat A2C on Door-Key is a column of Table 2 (the paper
/// omits it), shown beside the paper's "not reported", from the committed
/// summaries of `doorkey-fixed`, where it never opened the door.
#[test]
fn table_2_shows_the_flat_a2c_on_door_key() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let committed =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("results/doorkey-fixed/small/doorkey");
    for config in ["a2c", "wn-pivotal-trav-init"] {
        let cell = d.join("results/small/doorkey").join(config);
        std::fs::create_dir_all(&cell).unwrap();
        for seed in 0..3 {
            let name = format!("seed-{seed}.json");
            std::fs::copy(committed.join(config).join(&name), cell.join(&name)).unwrap();
        }
    }
    ok(&worldgraph(
        d,
        &["table", "results", "--out", "out/results.md"],
    ));
    let md = std::fs::read_to_string(d.join("out/results.md")).unwrap();
    let table2 = md
        .split("## Table 2")
        .nth(1)
        .expect("a Table 2 section")
        .split("\n## ")
        .next()
        .unwrap();
    let head = table2
        .lines()
        .find(|l| l.starts_with("| maze |"))
        .expect("a header");
    assert!(
        head.starts_with("| maze | A2C | paper | WN V_all"),
        "A2C leads the columns: {head}"
    );
    let small = table2
        .lines()
        .find(|l| l.starts_with("| small"))
        .expect("a small row");
    let cells: Vec<&str> = small.split('|').map(str::trim).collect();
    assert_eq!(
        (cells[2], cells[3]),
        ("Fail", "not reported"),
        "A2C never opened the door; the paper has no figure: {small}"
    );
    assert!(
        small.contains("100 ± 1 | 92 ± 2"),
        "the full method beside the paper's: {small}"
    );
}

/// Issues 47 and 48: `docs/results.md` is one page from several result
/// sets (`table A --with B`). A block (maze, task) comes whole from the
/// last set that holds it, so the paper's grid keeps its MultiGoal rows
/// while its pre-fix Door-Key rows (every one 0 %) give way to the fixed
/// grid's, the page says which set gave which block, no set's own
/// `scores.csv` is overwritten, and two budgets in one maze are refused.
/// On the committed summaries of `paper-real` and `doorkey-fixed`.
#[test]
fn one_page_from_several_result_sets_takes_each_block_from_the_last_set() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let copy = |from: &str, to: &str| copy_committed(d, from, to);
    for seed in 0..3 {
        for (task, config) in [
            ("doorkey", "wn-pivotal-trav-init"),
            ("doorkey", "wn-random-init"),
            ("multigoal", "wn-pivotal-trav-init"),
        ] {
            let p = format!("small/{task}/{config}/seed-{seed}.json");
            copy(&format!("results/paper-real/{p}"), &format!("old/{p}"));
        }
        let p = format!("small/doorkey/wn-pivotal-trav-init/seed-{seed}.json");
        copy(&format!("results/doorkey-fixed/{p}"), &format!("fixed/{p}"));
    }
    // Each set keeps its grid file beside its summaries, as `experiment`
    // leaves it.
    copy("results/paper-real/paper-real.toml", "old/paper-real.toml");
    copy(
        "results/doorkey-fixed/doorkey-fixed.toml",
        "fixed/doorkey-fixed.toml",
    );
    let table = |with: &str| {
        worldgraph(
            d,
            &[
                "table",
                "old",
                "--with",
                with,
                "--out",
                "out/results.md",
                "--no-figures",
            ],
        )
    };
    ok(&table("fixed"));
    let md = std::fs::read_to_string(d.join("out/results.md")).unwrap();
    let section = |name: &str| {
        md.split(&format!("## {name}"))
            .nth(1)
            .unwrap_or_else(|| panic!("no {name} section in\n{md}"))
            .split("\n## ")
            .next()
            .unwrap()
            .to_string()
    };
    // The Door-Key block is the fixed grid's: its full method (100 % on
    // the three seeds), and none of the old grid's Door-Key rows, not even
    // the one the fixed set does not hold.
    let score = |p: &Path| json(p)["test_score"].as_f64().unwrap();
    let fixed: Vec<f64> = (0..3)
        .map(|s| {
            score(&d.join(format!(
                "fixed/small/doorkey/wn-pivotal-trav-init/seed-{s}.json"
            )))
        })
        .collect();
    let mean = 100.0 * fixed.iter().sum::<f64>() / 3.0;
    let small = section("Table 2")
        .lines()
        .find(|l| l.starts_with("| small"))
        .expect("a small row of Table 2")
        .to_string();
    let cells: Vec<&str> = small.split('|').map(str::trim).collect();
    assert!(
        cells
            .iter()
            .any(|c| c.starts_with(&format!("{mean:.0} ± "))),
        "the fixed grid's full method ({mean:.0} %) in {small}"
    );
    assert!(
        !small.contains("0 ± 0 |") && cells.iter().filter(|c| **c == "—").count() >= 6,
        "no pre-fix Door-Key row left in {small}"
    );
    // The MultiGoal block is still the old grid's.
    let mg: Vec<f64> = (0..3)
        .map(|s| {
            score(&d.join(format!(
                "old/small/multigoal/wn-pivotal-trav-init/seed-{s}.json"
            )))
        })
        .collect();
    let mg_mean = mg.iter().sum::<f64>() / 3.0;
    assert!(
        section("Table 1").contains(&format!("{mg_mean:.3} ± ")),
        "the old grid's MultiGoal cell ({mg_mean:.3}) in\n{md}"
    );
    // The page names each set's share, and the command that made it.
    let sets = section("Result sets");
    assert!(
        sets.contains("| `old` | small: multigoal | 3 |")
            && sets.contains("| `fixed` | small: doorkey | 3 |"),
        "{sets}"
    );
    assert!(
        md.contains("`worldgraph table old --with fixed --out out/results.md`"),
        "{md}"
    );
    // The rows short of their seeds, each with the command that runs it
    // on the grid of the set that gave its block: the old grid's
    // MultiGoal rows on `old`, named as its runs recorded the grid; the
    // Door-Key rows on `fixed`'s grid, even those `old` ran (its block is
    // replaced, so they count as not run). The rows done are not listed.
    let missing = section("Not run yet");
    for row in [
        "| small | multigoal | A2C | 0 | 0, 1, 2 | `worldgraph experiment \
         experiments/paper-real.toml --maze small --task multigoal --config a2c --results old` |",
        "| small | doorkey | WN V_rand + π_g init | 0 | 0, 1, 2 | `worldgraph experiment \
         fixed/doorkey-fixed.toml --maze small --task doorkey --config wn-random-init \
         --results fixed` |",
        "| small | doorkey | A2C | 0 | 0, 1, 2 |",
    ] {
        assert!(missing.contains(row), "{row} in\n{missing}");
    }
    assert_eq!(
        missing
            .lines()
            .filter(|l| l.starts_with("| small |"))
            .count(),
        9 + 7,
        "Table 1's ten rows but the one done, Table 2's eight but the one done:\n{missing}"
    );
    assert!(
        !missing.contains("WN V_p + traversal + π_g init"),
        "{missing}"
    );

    // The merged rows go beside the page; no set's scores.csv is written.
    let csv = std::fs::read_to_string(d.join("out/results.csv")).unwrap();
    assert_eq!(csv.lines().count(), 1 + 6, "{csv}");
    assert!(!d.join("old/scores.csv").exists() && !d.join("fixed/scores.csv").exists());

    // A set whose runs of the small maze had another budget is refused:
    // the flat A2C to 9M env steps beside the 3M grid.
    let p = "small/multigoal/a2c/seed-0.json";
    copy(&format!("results/a2c-plateau/{p}"), &format!("longer/{p}"));
    let err = refused(&table("longer"));
    assert!(
        err.contains("small maze would mix budgets") && err.contains("longer"),
        "{err}"
    );
    // And --with needs --out: the page is no one set's README.
    let err = refused(&worldgraph(d, &["table", "old", "--with", "fixed"]));
    assert!(err.contains("--out"), "{err}");
}
