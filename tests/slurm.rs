//! `worldgraph experiment --slurm`, `--status` and the cell processes both
//! runners start.
//!
//! Without SLURM (in `make test`): the job scripts `--dry-run` prints; a
//! job script run by hand as an array task writes the local runner's
//! summary; the clear refusals when sbatch is missing or rejects a script.
//!
//! On a real SLURM (`make test-slurm`, which starts a one-node cluster with
//! scripts/slurm-one-node.sh and names its folder in
//! WORLDGRAPH_SLURM_CLUSTER; `#[ignore]`d otherwise): a grid submitted as job
//! arrays writes the local runner's summaries, a cell killed with `scancel`
//! is resumed by a resubmission, and slurmctld stopped mid-grid and started
//! again loses nothing.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

use crate::experiment::{ok, refused, worldgraph};

/// `experiment grid.toml` with `args`, its summaries in `results` and
/// its runs in `work`.
fn on_grid<'a>(args: &[&'a str], results: &'a str, work: &'a str) -> Vec<&'a str> {
    let mut v = vec!["experiment", "grid.toml"];
    v.extend_from_slice(args);
    v.extend(["--results", results, "--work", work]);
    v
}

/// A CI-sized grid on the small maze: `configs` × `seeds`, each run
/// `env_steps` in segments of 1920 (six segments, 11520, are long enough
/// to cancel one in between), 2 validation and 3 test seeds, one-round
/// discoveries.
fn grid(name: &str, seeds: &str, configs: &str, env_steps: u64) -> String {
    format!(
        "name = \"{name}\"\nseeds = [{seeds}]\nvalidation_seeds = 2\ntest_seeds = 3\n\
         [[maze]]\nname = \"small\"\nenv_steps = {env_steps}\neval_every = 1920\ndiscover_rounds = 1\n\
         [[group]]\ntable = 1\ntasks = [\"multigoal\"]\nconfigs = [{configs}]\n"
    )
}

/// The summaries under `root`, relative paths.
fn summaries(root: &Path) -> BTreeSet<PathBuf> {
    fn walk(root: &Path, dir: &Path, out: &mut BTreeSet<PathBuf>) {
        for e in std::fs::read_dir(dir).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                walk(root, &p, out);
            } else if p.extension().is_some_and(|x| x == "json") {
                out.insert(p.strip_prefix(root).unwrap().to_path_buf());
            }
        }
    }
    let mut out = BTreeSet::new();
    walk(root, root, &mut out);
    out
}

/// The keys whose values are measured time, not computed: they differ
/// between any two runs of a cell, two local ones included.
const TIMING_KEYS: [&str; 2] = ["\"wall_seconds\": ", "\"train_steps_per_sec\": "];

/// A summary's bytes with the values of [`TIMING_KEYS`] replaced by `T`,
/// everything else (keys, order, every digit of every other number) as
/// written; and how many values were replaced.
fn without_timing(bytes: &[u8]) -> (String, usize) {
    let text = String::from_utf8(bytes.to_vec()).unwrap();
    let mut replaced = 0;
    let lines: Vec<String> = text
        .split('\n')
        .map(|line| {
            for key in TIMING_KEYS {
                if let Some(at) = line.find(key) {
                    let end = at + key.len();
                    let comma = if line.ends_with(',') { "," } else { "" };
                    replaced += 1;
                    return format!("{}T{comma}", &line[..end]);
                }
            }
            line.to_string()
        })
        .collect();
    (lines.join("\n"), replaced)
}

/// Asserts that every summary under `a` has its twin under `b`, equal byte
/// for byte but for the measured times; returns how many were compared.
fn assert_same_summaries(a: &Path, b: &Path) -> usize {
    let (left, right) = (summaries(a), summaries(b));
    assert_eq!(left, right, "the two runners wrote different summaries");
    for rel in &left {
        let (x, y) = (
            std::fs::read(a.join(rel)).unwrap(),
            std::fs::read(b.join(rel)).unwrap(),
        );
        let ((x, nx), (y, ny)) = (without_timing(&x), without_timing(&y));
        assert!(
            nx > 0 && nx == ny,
            "{}: timing values {nx} and {ny}",
            rel.display()
        );
        assert!(
            x == y,
            "{} differs beyond its timing:\n{x}\n---\n{y}",
            rel.display()
        );
    }
    left.len()
}

#[test]
fn the_summary_comparison_masks_the_measured_times_and_nothing_else() {
    let a = b"{\n  \"test_score\": 0.5,\n  \"wall_seconds\": 1.25,\n  \"train_steps_per_sec\": 900.0\n}";
    let b =
        b"{\n  \"test_score\": 0.5,\n  \"wall_seconds\": 7.5,\n  \"train_steps_per_sec\": 12.0\n}";
    let c = b"{\n  \"test_score\": 0.50000001,\n  \"wall_seconds\": 1.25,\n  \"train_steps_per_sec\": 900.0\n}";
    let (ma, na) = without_timing(a);
    assert_eq!(na, 2);
    assert_eq!(ma, without_timing(b).0);
    assert_ne!(ma, without_timing(c).0);
    assert!(ma.contains("\"wall_seconds\": T,\n"), "{ma}");
}

/// A `bin/` with fake `sbatch` and `squeue`: sbatch records its arguments
/// in `sbatch.args`, keeps a copy of each script and answers job id 42 (or
/// refuses, with `refuse`); squeue knows no job.
fn fake_slurm(d: &Path, refuse: bool) -> PathBuf {
    let bin = d.join("bin");
    std::fs::create_dir_all(&bin).unwrap();
    let sbatch = if refuse {
        "#!/bin/sh\necho 'sbatch: error: Batch job submission failed: Invalid partition name specified' >&2\nexit 1\n".to_string()
    } else {
        format!(
            "#!/bin/sh\necho \"$@\" >> {0}/sbatch.args\nfor a; do last=$a; done\ncp \"$last\" {0}/job-$(wc -l < {0}/sbatch.args).sh\necho 42\n",
            d.display()
        )
    };
    for (name, text) in [
        ("sbatch", sbatch.as_str()),
        ("squeue", "#!/bin/sh\nexit 0\n"),
    ] {
        let p = bin.join(name);
        std::fs::write(&p, text).unwrap();
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(&p, std::fs::Permissions::from_mode(0o755)).unwrap();
    }
    bin
}

fn with_path(dir: &Path, path: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_worldgraph"))
        .args(args)
        .current_dir(dir)
        .env("PATH", path)
        .env("WORLDGRAPH_TORCH_THREADS", "1")
        .output()
        .expect("run worldgraph")
}

#[test]
fn dry_run_prints_one_array_per_stage_the_training_after_the_discoveries() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(
        d.join("grid.toml"),
        grid("dry", "0, 1", "\"a2c\", \"wn-pivotal-trav-init\"", 11520),
    )
    .unwrap();
    std::fs::write(
        d.join("preamble.sh"),
        "#SBATCH --mem=2G\nmodule load libtorch\n",
    )
    .unwrap();
    let (out, err) = ok(&worldgraph(
        d,
        &[
            "experiment",
            "grid.toml",
            "--slurm",
            "--dry-run",
            "--jobs",
            "3",
            "--partition",
            "gpu",
            "--time",
            "2:00:00",
            "--sbatch-arg=--account=rl",
            "--sbatch-preamble",
            "preamble.sh",
        ],
    ));
    assert!(
        err.contains("4 training runs and 2 discoveries to submit"),
        "{err}"
    );
    // Cells 0-1 are the discoveries, 2-5 the training runs.
    assert!(
        out.contains("# sbatch --parsable --account=rl results/runs/dry/slurm/scripts/"),
        "{out}"
    );
    assert!(out.contains("#SBATCH --array=0-1%3\n"), "{out}");
    assert!(out.contains("#SBATCH --array=2-5%3\n"), "{out}");
    assert!(
        out.contains(
            "--dependency=afterok:<job id of the discover array> --kill-on-invalid-dep=yes"
        ),
        "{out}"
    );
    for line in [
        "#SBATCH --partition=gpu",
        "#SBATCH --time=2:00:00",
        "#SBATCH --cpus-per-task=1",
        "#SBATCH --mem=2G\nmodule load libtorch\n",
    ] {
        assert_eq!(
            out.matches(line).count(),
            2,
            "{line} in both scripts:\n{out}"
        );
    }
    assert!(
        out.contains(&format!(
            "#SBATCH --chdir={}\n",
            d.canonicalize().unwrap().display()
        )) || out.contains(&format!("#SBATCH --chdir={}\n", d.display())),
        "{out}"
    );
    assert!(
        out.contains("'experiment' 'grid.toml' '--results' 'results' '--work' 'results/runs/dry' '--threads' '1' '--jobs' '3' '--grid-digest' '"),
        "{out}"
    );
    assert!(out.contains(" --cell \"$SLURM_ARRAY_TASK_ID\"\n"), "{out}");
    assert!(!d.join("results").exists(), "a dry run writes nothing");
}

#[test]
fn a_job_script_run_as_an_array_task_writes_the_local_runners_summary() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("grid.toml"), grid("script", "0", "\"a2c\"", 11520)).unwrap();
    ok(&worldgraph(
        d,
        &on_grid(&["--jobs", "1"], "local", "local-work"),
    ));
    let path = format!("{}:/usr/bin:/bin", fake_slurm(d, false).display());
    let (_, err) = ok(&with_path(
        d,
        path.as_ref(),
        &on_grid(&["--slurm", "--jobs", "1"], "slurm", "slurm-work"),
    ));
    assert!(
        err.contains("submitted 1 train cells as SLURM job 42 (array 0, 1 at once)"),
        "{err}"
    );
    let args = std::fs::read_to_string(d.join("sbatch.args")).unwrap();
    assert!(
        args.starts_with("--parsable slurm-work/slurm/scripts/"),
        "{args}"
    );
    let subs = std::fs::read_to_string(d.join("slurm-work/slurm/submissions.jsonl")).unwrap();
    assert!(
        subs.contains("\"job\":42,\"kind\":\"train\",\"cells\":[0]"),
        "{subs}"
    );
    // The script, run as SLURM would run array task 0 of job 42.
    let out = Command::new("bash")
        .arg(d.join("job-1.sh"))
        .current_dir("/")
        .env("SLURM_ARRAY_JOB_ID", "42")
        .env("SLURM_ARRAY_TASK_ID", "0")
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(assert_same_summaries(&d.join("local"), &d.join("slurm")), 1);
    let log =
        std::fs::read_to_string(d.join("slurm-work/logs/small_multigoal_a2c_seed-0.log")).unwrap();
    assert!(log.contains(", SLURM job 42_0 =="), "{log}");
    // Done on either runner, by --status of either.
    for (results, work) in [("local", "local-work"), ("slurm", "slurm-work")] {
        let (out, _) = ok(&with_path(
            d,
            path.as_ref(),
            &on_grid(&["--status"], results, work),
        ));
        assert!(
            out.contains("done 1, queued 0, running 0, failed 0, left 0"),
            "{out}"
        );
    }
    // Submitted again, nothing is left to submit.
    let (_, err) = ok(&with_path(
        d,
        path.as_ref(),
        &on_grid(&["--slurm"], "slurm", "slurm-work"),
    ));
    assert!(err.contains("nothing to submit"), "{err}");
}

#[test]
fn missing_or_refusing_sbatch_and_a_changed_grid_are_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("grid.toml"), grid("errors", "0", "\"a2c\"", 11520)).unwrap();
    let empty = d.join("empty");
    std::fs::create_dir(&empty).unwrap();
    let err = refused(&with_path(
        d,
        &empty,
        &["experiment", "grid.toml", "--slurm"],
    ));
    assert!(
        err.contains("sbatch is not on PATH") && err.contains("login node"),
        "{err}"
    );

    let refusing = fake_slurm(&d.join("refusing"), true);
    let err = refused(&with_path(
        d,
        &refusing,
        &["experiment", "grid.toml", "--slurm", "--partition", "nope"],
    ));
    assert!(
        err.contains("sbatch refused results/runs/errors/slurm/scripts/")
            && err.contains("Invalid partition name specified"),
        "{err}"
    );
    assert!(
        !d.join("results/runs/errors/slurm/submissions.jsonl")
            .exists()
    );

    // A cell of a grid edited since its runner read it is refused, and so
    // is a cell the grid does not have.
    let err = refused(&worldgraph(
        d,
        &[
            "experiment",
            "grid.toml",
            "--cell",
            "0",
            "--grid-digest",
            "0000000000000000",
        ],
    ));
    assert!(
        err.contains("grid.toml changed since this cell was started"),
        "{err}"
    );
    let err = refused(&worldgraph(d, &["experiment", "grid.toml", "--cell", "7"]));
    assert!(
        err.contains("has 1 cells (0 to 0): there is no cell 7"),
        "{err}"
    );
    // The SLURM options need --slurm.
    let err = refused(&worldgraph(
        d,
        &["experiment", "grid.toml", "--partition", "main"],
    ));
    assert!(err.contains("--slurm"), "{err}");
}

#[test]
fn status_follows_a_local_grid_and_names_a_failed_cells_log() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("grid.toml"), grid("local", "0, 1", "\"a2c\"", 11520)).unwrap();
    let (out, _) = ok(&worldgraph(d, &["experiment", "grid.toml", "--status"]));
    assert!(
        out.contains("2 cells (2 training runs, 0 discoveries)"),
        "{out}"
    );
    assert!(
        out.contains("done 0, queued 0, running 0, failed 0, left 2"),
        "{out}"
    );
    // Seed 1's run directory holds a file of another kind: its train refuses it.
    let run = d.join("results/runs/local/small/multigoal/a2c/seed-1");
    std::fs::create_dir_all(&run).unwrap();
    std::fs::write(run.join("mine.txt"), "not a run").unwrap();
    let err = refused(&worldgraph(d, &["experiment", "grid.toml"]));
    assert!(err.contains("1 runs finished, 1 failed"), "{err}");
    let (out, _) = ok(&worldgraph(d, &["experiment", "grid.toml", "--status"]));
    assert!(
        out.contains("done 1, queued 0, running 0, failed 1, left 0"),
        "{out}"
    );
    assert!(
        out.contains(
            "failed   small/multigoal/a2c/seed-1  train ended with exit status: 1: error: --run \
             results/runs/local/small/multigoal/a2c/seed-1 is not empty and not a train run"
        ) && out.ends_with("; log results/runs/local/logs/small_multigoal_a2c_seed-1.log\n"),
        "{out}"
    );
}

// ---- On a real SLURM (make test-slurm) ----

/// The folder of the one-node cluster `make test-slurm` started.
fn cluster() -> PathBuf {
    PathBuf::from(std::env::var_os("WORLDGRAPH_SLURM_CLUSTER").expect(
        "WORLDGRAPH_SLURM_CLUSTER names the folder of a running cluster: run `make test-slurm`",
    ))
}

/// scripts/slurm-one-node.sh with `args`.
fn cluster_script(args: &[&str]) {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/slurm-one-node.sh");
    let st = Command::new("bash")
        .arg(script)
        .args(args)
        .status()
        .unwrap();
    assert!(st.success(), "slurm-one-node.sh {args:?}: {st}");
}

fn squeue() -> String {
    let out = Command::new("squeue")
        .args(["--array", "--format=%.10i %.22j %.9T %R"])
        .output()
        .unwrap();
    String::from_utf8_lossy(&out.stdout).into_owned() + &String::from_utf8_lossy(&out.stderr)
}

/// `--status` of the grid in `d` (results `results`, work `work`).
fn status(d: &Path, results: &str, work: &str) -> Output {
    worldgraph(d, &on_grid(&["--status"], results, work))
}

/// Prints each new `squeue` picture.
#[derive(Default)]
struct QueueWatch {
    last: String,
    looked: Option<Instant>,
    start: Option<Instant>,
}

impl QueueWatch {
    /// Asks squeue, if `every` has passed since it last did, and prints
    /// what it says if that changed.
    fn look(&mut self, every: Duration) {
        let start = *self.start.get_or_insert_with(Instant::now);
        if self.looked.is_some_and(|t| t.elapsed() < every) {
            return;
        }
        self.looked = Some(Instant::now());
        let q = squeue();
        if q != self.last {
            eprintln!("[{:>5.1} s] squeue:\n{q}", start.elapsed().as_secs_f64());
            self.last = q;
        }
    }
}

/// Waits until no cell of the grid is queued or running and SLURM's queue
/// is empty (a cell is done once its summary is written, a moment before
/// its array task has ended), at most `limit`; prints each new `squeue`
/// picture on the way.
fn wait_for_grid(d: &Path, results: &str, work: &str, limit: Duration) -> String {
    let t0 = Instant::now();
    let mut watch = QueueWatch::default();
    loop {
        watch.look(Duration::ZERO);
        let (out, _) = ok(&status(d, results, work));
        let queue = Command::new("squeue").arg("--noheader").output().unwrap();
        if out.contains("queued 0, running 0,") && queue.status.success() && queue.stdout.is_empty()
        {
            return out;
        }
        assert!(
            t0.elapsed() < limit,
            "the grid did not end in {limit:?}:\n{out}"
        );
        std::thread::sleep(Duration::from_millis(500));
    }
}

/// Prints the job completion log's records of the grid's array tasks and
/// asserts how many ended COMPLETED and how many CANCELLED.
fn assert_job_ends(d: &Path, work: &str, completed: usize, cancelled: usize) {
    let jobs = submitted_jobs(d, work);
    let text = std::fs::read_to_string(cluster().join("jobcomp.txt")).unwrap_or_default();
    let records: Vec<String> = text
        .lines()
        .filter(|l| jobs.iter().any(|j| l.contains(&format!("ArrayJobId={j} "))))
        .map(|l| {
            // The fields that tell what ran.
            l.split(' ')
                .filter(|f| {
                    [
                        "JobId=",
                        "Name=",
                        "JobState=",
                        "StartTime=",
                        "EndTime=",
                        "ArrayJobId=",
                        "ArrayTaskId=",
                        "ExitCode=",
                    ]
                    .iter()
                    .any(|k| f.starts_with(k))
                })
                .collect::<Vec<_>>()
                .join(" ")
        })
        .collect();
    eprintln!(
        "job completion log of array jobs {jobs:?}:\n{}",
        records.join("\n")
    );
    let count = |state: &str| {
        records
            .iter()
            .filter(|l| l.contains(&format!("JobState={state} ")))
            .count()
    };
    assert_eq!(count("COMPLETED"), completed, "{records:#?}");
    assert_eq!(count("CANCELLED"), cancelled, "{records:#?}");
}

/// The array job ids of a grid's submissions.
fn submitted_jobs(d: &Path, work: &str) -> Vec<String> {
    std::fs::read_to_string(d.join(work).join("slurm/submissions.jsonl"))
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap()["job"].to_string())
        .collect()
}

#[test]
#[ignore = "needs a SLURM cluster: make test-slurm"]
fn slurm_runs_the_grid_as_the_local_runner_does_and_resumes_a_cancelled_cell() {
    let _ = cluster();
    let t0 = Instant::now();
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(
        d.join("grid.toml"),
        grid(
            "onslurm",
            "0, 1",
            "\"a2c\", \"wn-pivotal-trav-init\"",
            11520,
        ),
    )
    .unwrap();
    ok(&worldgraph(
        d,
        &on_grid(&["--jobs", "2"], "local", "local-work"),
    ));
    eprintln!("local runner: {:.0} s", t0.elapsed().as_secs_f64());

    // A script sbatch rejects: a clear error, nothing recorded.
    let err = refused(&worldgraph(
        d,
        &on_grid(&["--slurm", "--partition", "nope"], "slurm", "slurm-work"),
    ));
    assert!(
        err.contains("sbatch refused") && err.contains("invalid partition"),
        "{err}"
    );
    assert!(!d.join("slurm-work/slurm/submissions.jsonl").exists());

    let t1 = Instant::now();
    let submit = on_grid(
        &[
            "--slurm",
            "--jobs",
            "2",
            "--partition",
            "main",
            "--time",
            "20",
        ],
        "slurm",
        "slurm-work",
    );
    let (_, err) = ok(&worldgraph(d, &submit));
    eprintln!("{err}");
    assert!(
        err.contains("submitted 2 discover cells as SLURM job"),
        "{err}"
    );
    assert!(
        err.contains("submitted 4 train cells as SLURM job"),
        "{err}"
    );

    // Cancel the A2C run of seed 0 (cell 2) once it has checkpointed, before it ends.
    let run = d.join("slurm-work/small/multigoal/a2c/seed-0");
    let wait = Instant::now();
    let mut watch = QueueWatch::default();
    while !run.join("checkpoint/state.json").exists() {
        assert!(
            wait.elapsed() < Duration::from_secs(600),
            "cell 2 never checkpointed:\n{}",
            squeue()
        );
        watch.look(Duration::from_millis(500));
        std::thread::sleep(Duration::from_millis(20));
    }
    let cell: serde_json::Value = serde_json::from_slice(
        &std::fs::read(d.join("slurm-work/cells/small_multigoal_a2c_seed-0.json")).unwrap(),
    )
    .unwrap();
    let task = cell["slurm_job"]
        .as_str()
        .expect("the cell runs in an array task")
        .to_string();
    let st = Command::new("scancel").arg(&task).status().unwrap();
    assert!(st.success(), "scancel {task}");
    let state: serde_json::Value =
        serde_json::from_slice(&std::fs::read(run.join("checkpoint/state.json")).unwrap()).unwrap();
    eprintln!(
        "scancel {task} at {} of 11520 env steps:\n{}",
        state["env_steps"],
        squeue()
    );

    let out = wait_for_grid(d, "slurm", "slurm-work", Duration::from_secs(900));
    eprintln!(
        "--status after the first submission ({:.0} s):\n{out}",
        t1.elapsed().as_secs_f64()
    );
    assert!(
        !run.join("test.json").exists(),
        "cell 2 finished before scancel reached it: lengthen the grid's runs"
    );
    assert!(
        out.contains("done 5, queued 0, running 0, failed 1, left 0"),
        "{out}"
    );
    assert!(
        out.contains(&format!(
            "failed   small/multigoal/a2c/seed-0  stopped by a signal; it resumes from its last checkpoint when run again; \
             log slurm-work/logs/small_multigoal_a2c_seed-0.log, SLURM output slurm-work/slurm/logs/{task}.out"
        )),
        "{out}"
    );

    // Submitted again: only the cancelled cell, which resumes.
    let (_, err) = ok(&worldgraph(d, &submit));
    eprintln!("{err}");
    assert!(
        err.contains("failed before: small/multigoal/a2c/seed-0"),
        "{err}"
    );
    assert!(
        err.contains("1 training runs and 0 discoveries to submit"),
        "{err}"
    );
    let out = wait_for_grid(d, "slurm", "slurm-work", Duration::from_secs(600));
    assert!(
        out.contains("done 6, queued 0, running 0, failed 0, left 0"),
        "{out}"
    );
    let log =
        std::fs::read_to_string(d.join("slurm-work/logs/small_multigoal_a2c_seed-0.log")).unwrap();
    let second = &log[log
        .rfind("== cell 2 ")
        .expect("the resubmitted cell's line")..];
    let resumed = second
        .lines()
        .find_map(|l| {
            l.strip_prefix("train: resuming ")
                .and_then(|r| r.split(" after ").nth(1))
        })
        .unwrap_or_else(|| panic!("the resubmitted cell did not resume:\n{log}"));
    let steps: u64 = resumed.trim_end_matches(" env steps").parse().unwrap();
    assert!(steps >= 1920, "resumed after {steps} env steps:\n{log}");
    assert_eq!(log.matches("== cell 2 ").count(), 2, "{log}");
    eprintln!("the cancelled cell's log:\n{log}");
    let invocations = std::fs::read_to_string(run.join("invocations.txt")).unwrap();
    assert_eq!(invocations.lines().count(), 2, "{invocations}");

    let n = assert_same_summaries(&d.join("local"), &d.join("slurm"));
    assert_eq!(n, 6, "4 training runs and 2 discoveries");
    eprintln!(
        "{n} summaries equal the local runner's byte for byte but for wall_seconds and train_steps_per_sec"
    );
    assert_job_ends(d, "slurm-work", 6, 1);
    eprintln!("on SLURM: {:.0} s", t1.elapsed().as_secs_f64());
}

#[test]
#[ignore = "needs a SLURM cluster: make test-slurm"]
fn slurmctld_stopped_mid_grid_and_started_again_loses_nothing() {
    let cluster_dir = cluster();
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(
        d.join("grid.toml"),
        grid("ctld", "0, 1, 2", "\"a2c\"", 38400),
    )
    .unwrap();
    let submit = on_grid(&["--slurm", "--jobs", "1"], "slurm", "slurm-work");
    ok(&worldgraph(d, &submit));
    let t0 = Instant::now();
    loop {
        let (out, _) = ok(&status(d, "slurm", "slurm-work"));
        if out.contains("running 1") {
            eprintln!("before the stop:\n{out}{}", squeue());
            break;
        }
        assert!(
            t0.elapsed() < Duration::from_secs(300),
            "no cell started:\n{out}"
        );
        std::thread::sleep(Duration::from_millis(200));
    }
    let cluster_dir = cluster_dir.display().to_string();
    cluster_script(&["stop-ctld", &cluster_dir]);
    let stopped = Instant::now();
    let stopped_at = std::time::SystemTime::now();

    // While it is down: --status prints what the files say and fails
    // clearly; a resubmission refuses rather than run a cell twice.
    let out = status(d, "slurm", "slurm-work");
    let (stdout, err) = (String::from_utf8_lossy(&out.stdout), refused(&out));
    eprintln!(
        "--status with slurmctld down ({:.1} s):\n{stdout}{err}",
        stopped.elapsed().as_secs_f64()
    );
    assert!(err.contains("SLURM is not answering (squeue: "), "{err}");
    assert!(
        stdout.contains("(submitted to SLURM, which does not answer)"),
        "{stdout}"
    );
    let asked = Instant::now();
    let err = refused(&worldgraph(d, &submit));
    eprintln!(
        "--slurm with slurmctld down ({:.1} s):\n{err}",
        asked.elapsed().as_secs_f64()
    );
    assert!(
        err.contains("not submitting") && err.contains("SLURM is not answering"),
        "{err}"
    );
    assert_eq!(submitted_jobs(d, "slurm-work").len(), 1);

    // The running array task goes on without slurmctld and writes its summary.
    let first = d.join("slurm/small/multigoal/a2c/seed-0.json");
    while !first.exists() && stopped.elapsed() < Duration::from_secs(120) {
        std::thread::sleep(Duration::from_millis(200));
    }
    assert!(
        first.exists(),
        "the running cell did not finish without slurmctld"
    );
    let written = std::fs::metadata(&first).unwrap().modified().unwrap();
    let after = written
        .duration_since(stopped_at)
        .expect("the running cell ended before slurmctld stopped: lengthen its runs");
    eprintln!(
        "the running cell's summary was written {:.1} s after slurmctld stopped; squeue then:\n{}",
        after.as_secs_f64(),
        squeue()
    );

    cluster_script(&["start-ctld", &cluster_dir]);
    eprintln!(
        "slurmctld down {:.1} s; started again:\n{}",
        stopped.elapsed().as_secs_f64(),
        squeue()
    );
    let out = wait_for_grid(d, "slurm", "slurm-work", Duration::from_secs(600));
    eprintln!("after the restart:\n{out}");
    assert!(
        out.contains("done 3, queued 0, running 0, failed 0, left 0"),
        "{out}"
    );
    assert_job_ends(d, "slurm-work", 3, 0);
}
