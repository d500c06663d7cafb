//! Failures that must be clean and runs that must not collide, with real
//! processes and real files: a configuration `run` refuses before it starts
//! anything, a full disk under `discover`, a second run of the same name,
//! a learner waiting for a sim that never comes, stale shared memory, a
//! discovery run's configuration identity, a learner of another task.
//!
//! Each test asserts the exit status, the message and what is left on disk
//! and in `/dev/shm`. Waits are bounded (a test fails, never hangs).

use std::path::Path;
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

fn exe() -> &'static str {
    env!("CARGO_BIN_EXE_worldgraph")
}

fn run_name(test: &str) -> String {
    format!("r{}-{}", std::process::id(), test)
}

/// The run's files in `/dev/shm`.
pub(crate) fn shm_files(run: &str) -> Vec<String> {
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

/// A process killed when dropped (a failed assertion leaves nothing running).
struct Proc(Child);

impl Drop for Proc {
    fn drop(&mut self) {
        if matches!(self.0.try_wait(), Ok(None)) {
            let _ = self.0.kill();
            let _ = self.0.wait();
        }
    }
}

fn spawn(dir: &Path, log: &str, args: &[&str]) -> Proc {
    let f = std::fs::File::create(dir.join(log)).unwrap();
    Proc(
        Command::new(exe())
            .args(args)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(f)
            .spawn()
            .expect("spawn worldgraph"),
    )
}

/// Runs worldgraph to its end, killing it (and failing) after `limit`.
fn run_bounded(args: &[&str], limit: Duration) -> Output {
    run_bounded_with_pid(args, limit).1
}

/// [`run_bounded`], with the process's pid (a `soak` names its run after it).
pub(crate) fn run_bounded_with_pid(args: &[&str], limit: Duration) -> (u32, Output) {
    let child = Command::new(exe())
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn worldgraph");
    let pid = child.id();
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let _ = tx.send(child.wait_with_output());
    });
    match rx.recv_timeout(limit) {
        Ok(out) => (pid, out.unwrap()),
        Err(_) => {
            let _ = Command::new("kill")
                .args(["-KILL", &pid.to_string()])
                .status();
            panic!("worldgraph {args:?} still running after {limit:?}");
        }
    }
}

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

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

fn no_crash_text(err: &str) {
    for bad in ["panicked", "terminate called", "RUST_BACKTRACE", "frame #"] {
        assert!(!err.contains(bad), "crash text {bad:?} in: {err}");
    }
}

/// Every file under `dir`, recursively.
fn files_under(dir: &Path) -> Vec<String> {
    let mut out = Vec::new();
    if let Ok(entries) = std::fs::read_dir(dir) {
        for e in entries.flatten() {
            let p = e.path();
            if p.is_dir() {
                out.extend(files_under(&p));
            } else {
                out.push(p.display().to_string());
            }
        }
    }
    out
}

// ------------------------------------------------------------ item 1

#[test]
fn run_refuses_a_bad_configuration_before_starting_anything() {
    let dir = tempfile::tempdir().unwrap();
    let ragged = dir.path().join("ragged.txt");
    std::fs::write(&ragged, "#####\n#>..#\n###\n").unwrap();
    let ragged = ragged.display().to_string();
    let missing = dir.path().join("no-such-nodes.txt").display().to_string();
    let cases: [(&str, Vec<&str>, &str); 4] = [
        ("envs0", vec!["--maze", "small", "--envs", "0"], "envs"),
        ("slices3", vec!["--maze", "small", "--slices", "3"], "slice"),
        ("ragged", vec!["--layout", &ragged], "ragged.txt"),
        (
            "nodefile",
            vec!["--maze", "small", "--node-file", &missing],
            "no-such-nodes.txt",
        ),
    ];
    for (name, extra, needle) in cases {
        let run = run_name(name);
        let run_dir = dir.path().join(name);
        let mut args = vec!["run", "--run", &run, "--run-dir", run_dir.to_str().unwrap()];
        args.extend(extra.iter().copied());
        // No --duration: a run that restarted its children forever would
        // never end; this one must end by itself, at once.
        let out = run_bounded(&args, Duration::from_secs(30));
        let err = stderr(&out);
        assert!(!out.status.success(), "{name}: accepted: {err}");
        assert!(err.contains(needle), "{name}: {needle:?} not in: {err}");
        assert!(!err.contains("restarting"), "{name}: restarted: {err}");
        // Each cause is printed once.
        for cause in ["ragged row", "No such file or directory"] {
            assert!(err.matches(cause).count() <= 1, "{name}: twice: {err}");
        }
        no_crash_text(&err);
        assert!(shm_files(&run).is_empty(), "{name}: {:?}", shm_files(&run));
        assert!(
            !run_dir.join("sim.report.json").exists(),
            "{name}: a role ran"
        );
    }
}

#[test]
fn a_role_that_refuses_its_configuration_exits_with_status_2_and_is_not_restarted() {
    // The role's own check, as `run` sees it: status 2 (EXIT_CONFIG).
    let dir = tempfile::tempdir().unwrap();
    let run = run_name("role-config");
    let out = run_bounded(
        &[
            "sim",
            "serve",
            "--run",
            &run,
            "--run-dir",
            dir.path().to_str().unwrap(),
            "--maze",
            "small",
            "--envs",
            "0",
        ],
        Duration::from_secs(30),
    );
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(stderr(&out).contains("configuration refused"));
    assert!(shm_files(&run).is_empty());
}

// ------------------------------------------------------------ item 2

/// A tmpfs of `size` mounted at a new directory; unmounted on drop.
struct Tmpfs(tempfile::TempDir);

impl Tmpfs {
    fn mount(size: &str) -> Option<Tmpfs> {
        let dir = tempfile::tempdir().unwrap();
        let ok = Command::new("mount")
            .args(["-t", "tmpfs", "-o", &format!("size={size}"), "tmpfs"])
            .arg(dir.path())
            .stderr(Stdio::null())
            .status()
            .is_ok_and(|s| s.success());
        ok.then_some(Tmpfs(dir))
    }
    fn path(&self) -> &Path {
        self.0.path()
    }
}

impl Drop for Tmpfs {
    fn drop(&mut self) {
        let _ = Command::new("umount").arg(self.0.path()).status();
    }
}

fn discover_args<'a>(run: &'a str, rounds: &'a str) -> Vec<&'a str> {
    vec![
        "discover",
        "--run",
        run,
        "--maze",
        "small",
        "--rounds",
        rounds,
        "--envs",
        "4",
        "--gcp-iters",
        "2",
    ]
}

#[test]
fn a_full_disk_under_discover_is_an_error_naming_the_file_and_keeps_the_checkpoint() {
    let Some(fs) = Tmpfs::mount("64k") else {
        eprintln!("skipped: cannot mount a tmpfs here (not root?)");
        return;
    };
    let run = fs.path().join("r");
    let out = run_bounded(
        &discover_args(run.to_str().unwrap(), "1"),
        Duration::from_secs(300),
    );
    let err = stderr(&out);
    assert!(!out.status.success(), "{err}");
    assert_eq!(out.status.code(), Some(1), "not an abort: {err}");
    assert!(err.contains("No space left on device"), "{err}");
    assert!(err.contains("checkpoint"), "{err}");
    no_crash_text(&err);
    let left = files_under(fs.path());
    assert!(
        !left.iter().any(|f| {
            let f = &f[fs.path().display().to_string().len()..];
            f.contains(".tmp") || f.contains(".new") || f.contains(".old")
        }),
        "temporary files left: {left:?}"
    );
}

#[test]
fn a_full_disk_on_a_later_round_keeps_the_previous_checkpoint_resumable() {
    let Some(fs) = Tmpfs::mount("16m") else {
        eprintln!("skipped: cannot mount a tmpfs here (not root?)");
        return;
    };
    let run = fs.path().join("r");
    let r = run.to_str().unwrap();
    let out = run_bounded(&discover_args(r, "1"), Duration::from_secs(300));
    assert!(out.status.success(), "{}", stderr(&out));
    let state = run.join("checkpoint").join("state.json");
    let before = std::fs::read(&state).unwrap();
    // Fill the disk, leaving a few KiB: the next checkpoint cannot fit.
    let filler = fs.path().join("filler");
    let _ = Command::new("dd")
        .args(["if=/dev/zero", "bs=4k"])
        .arg(format!("of={}", filler.display()))
        .stderr(Stdio::null())
        .status();
    let out = run_bounded(&discover_args(r, "2"), Duration::from_secs(300));
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("No space left on device"), "{err}");
    no_crash_text(&err);
    assert_eq!(
        std::fs::read(&state).unwrap(),
        before,
        "the round-1 checkpoint changed"
    );
    let left = files_under(fs.path());
    assert!(
        !left.iter().any(|f| {
            let f = &f[fs.path().display().to_string().len()..];
            f.contains(".tmp") || f.contains(".new") || f.contains(".old")
        }),
        "temporary files left: {left:?}"
    );
    // Space again: the run resumes from round 1 and finishes round 2.
    std::fs::remove_file(&filler).unwrap();
    let out = run_bounded(&discover_args(r, "2"), Duration::from_secs(300));
    let err = stderr(&out);
    assert!(out.status.success(), "{err}");
    assert!(err.contains("resuming"), "{err}");
}

// ------------------------------------------------------------ item 3

#[test]
fn a_second_run_of_the_same_name_is_refused_at_once_naming_the_holder() {
    let dir = tempfile::tempdir().unwrap();
    let run = run_name("twice");
    let first_dir = dir.path().join("first");
    let mut first = spawn(
        dir.path(),
        "first.log",
        &[
            "run",
            "--run",
            &run,
            "--run-dir",
            first_dir.to_str().unwrap(),
            "--maze",
            "small",
            "--envs",
            "16",
            "--duration",
            "120",
        ],
    );
    assert!(
        wait_for(Duration::from_secs(60), || first_dir
            .join("sim.stats.jsonl")
            .exists()),
        "the first run never published: {}",
        std::fs::read_to_string(dir.path().join("first.log")).unwrap_or_default()
    );
    let second_dir = dir.path().join("second");
    let t0 = Instant::now();
    let out = run_bounded(
        &[
            "run",
            "--run",
            &run,
            "--run-dir",
            second_dir.to_str().unwrap(),
            "--maze",
            "small",
            "--envs",
            "16",
            "--duration",
            "5",
        ],
        Duration::from_secs(30),
    );
    let err = stderr(&out);
    assert!(!out.status.success(), "{err}");
    assert!(err.contains(&format!("run '{run}' is in use")), "{err}");
    assert!(err.contains("process "), "{err}");
    assert!(
        !err.contains("ExceedsMaxSupportedPublishers"),
        "internal error name: {err}"
    );
    assert!(t0.elapsed() < Duration::from_secs(5), "not at once: {err}");
    assert!(!second_dir.join("sim.report.json").exists());
    // A second sim started by hand is refused too, naming the first's pid.
    let out = run_bounded(
        &[
            "sim",
            "serve",
            "--run",
            &run,
            "--run-dir",
            second_dir.to_str().unwrap(),
            "--maze",
            "small",
            "--envs",
            "16",
        ],
        Duration::from_secs(30),
    );
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("already has a live sim (process"), "{err}");
    // The first run was not disturbed and ends cleanly.
    let _ = Command::new("kill")
        .args(["-TERM", &first.0.id().to_string()])
        .status();
    let st = wait_exit(&mut first.0, Duration::from_secs(30));
    assert!(st.success(), "first run: {st}");
    let sim: serde_json::Value =
        serde_json::from_slice(&std::fs::read(first_dir.join("sim.report.json")).unwrap()).unwrap();
    assert!(sim["batches"].as_u64().unwrap() > 0);
    assert!(shm_files(&run).is_empty(), "{:?}", shm_files(&run));
}

// ------------------------------------------------------------ item 4

#[test]
fn a_learner_without_a_sim_stops_at_its_duration_and_leaves_no_shared_memory() {
    let dir = tempfile::tempdir().unwrap();
    let run = run_name("lonely");
    let t0 = Instant::now();
    let out = run_bounded(
        &[
            "learner",
            "serve",
            "--run",
            &run,
            "--run-dir",
            dir.path().to_str().unwrap(),
            "--maze",
            "small",
            "--duration",
            "3",
        ],
        Duration::from_secs(30),
    );
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(t0.elapsed() >= Duration::from_secs(3));
    assert!(shm_files(&run).is_empty(), "{:?}", shm_files(&run));
}

#[test]
fn a_killed_runs_shared_memory_is_removed_by_clean_which_says_what_it_removed() {
    let dir = tempfile::tempdir().unwrap();
    let run = run_name("killed");
    let mut learner = spawn(
        dir.path(),
        "learner.log",
        &[
            "learner",
            "serve",
            "--run",
            &run,
            "--run-dir",
            dir.path().to_str().unwrap(),
            "--maze",
            "small",
        ],
    );
    assert!(wait_for(Duration::from_secs(30), || !shm_files(&run).is_empty()));
    std::thread::sleep(Duration::from_millis(300));
    learner.0.kill().unwrap();
    learner.0.wait().unwrap();
    assert!(!shm_files(&run).is_empty(), "SIGKILL left nothing to sweep");
    let out = run_bounded(&["clean", "--min-age", "0"], Duration::from_secs(30));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(text.contains(&format!("wg_{run}_")), "{text}");
    assert!(shm_files(&run).is_empty(), "{:?}", shm_files(&run));
}

// ------------------------------------------------------------ item 5

fn discover(run: &str, extra: &[&str]) -> Output {
    let mut args = discover_args(run, "1");
    args.extend(extra);
    run_bounded(&args, Duration::from_secs(300))
}

#[test]
fn discover_configs_are_toml_their_seed_is_kept_and_a_changed_run_names_the_field() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = dir.path().join("c.toml");
    std::fs::write(&cfg, "seed = 7\nwalk_len = 40\n").unwrap();
    let cfg_s = cfg.to_str().unwrap();
    let run = dir.path().join("r");
    let r = run.to_str().unwrap();
    let out = discover(r, &["--config", cfg_s]);
    assert!(out.status.success(), "{}", stderr(&out));
    let identity = std::fs::read_to_string(run.join("config.toml")).unwrap();
    assert!(identity.contains("seed = 7"), "{identity}");
    assert!(identity.contains("layout_digest"), "{identity}");
    // A larger budget on a finished run is a continuation.
    let mut more = discover_args(r, "2");
    more.extend(["--config", cfg_s]);
    let out = run_bounded(&more, Duration::from_secs(300));
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(stderr(&out).contains("resuming"), "{}", stderr(&out));
    // Another setting: refused, naming the field and both values.
    std::fs::write(&cfg, "seed = 7\nwalk_len = 41\n").unwrap();
    let out = run_bounded(&more, Duration::from_secs(60));
    let err = stderr(&out);
    assert!(!out.status.success(), "{err}");
    assert!(
        err.contains("walk_len") && err.contains("40") && err.contains("41"),
        "{err}"
    );
    // Not TOML (a JSON array), an unknown key: refused with the file named.
    for (text, needle) in [("[1, 2, 3]\n", "TOML"), ("sed = 7\n", "sed")] {
        std::fs::write(&cfg, text).unwrap();
        let out = discover(
            &dir.path().join("other").display().to_string(),
            &["--config", cfg_s],
        );
        let err = stderr(&out);
        assert!(!out.status.success(), "{text}: {err}");
        assert!(
            err.contains(needle) && err.contains("c.toml"),
            "{text}: {err}"
        );
    }
}

#[test]
fn an_edited_layout_of_the_same_name_and_size_is_not_resumed() {
    let dir = tempfile::tempdir().unwrap();
    let layout = dir.path().join("maze.txt");
    std::fs::write(&layout, "#######\n#>....#\n#.....#\n#....E#\n#######\n").unwrap();
    let run = dir.path().join("r");
    let args = |rounds| {
        vec![
            "discover".to_string(),
            "--run".into(),
            run.display().to_string(),
            "--layout".into(),
            layout.display().to_string(),
            "--rounds".into(),
            rounds,
            "--envs".into(),
            "4".into(),
            "--gcp-iters".into(),
            "2".into(),
        ]
    };
    let a1 = args("1".into());
    let out = run_bounded(
        &a1.iter().map(String::as_str).collect::<Vec<_>>(),
        Duration::from_secs(300),
    );
    assert!(out.status.success(), "{}", stderr(&out));
    std::fs::write(&layout, "#######\n#>....#\n#..#..#\n#....E#\n#######\n").unwrap();
    let a2 = args("2".into());
    let out = run_bounded(
        &a2.iter().map(String::as_str).collect::<Vec<_>>(),
        Duration::from_secs(60),
    );
    let err = stderr(&out);
    assert!(!out.status.success(), "{err}");
    assert!(err.contains("the file was edited"), "{err}");
}

// ------------------------------------------------------------ item 6

#[test]
fn a_learner_of_another_task_or_batch_is_refused_in_the_users_terms() {
    let dir = tempfile::tempdir().unwrap();
    let run = run_name("task");
    let d = dir.path().to_str().unwrap();
    let mut sim = spawn(
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
            "128",
        ],
    );
    assert!(wait_for(Duration::from_secs(30), || !shm_files(&run).is_empty()));
    std::thread::sleep(Duration::from_millis(500));
    for (extra, needles) in [
        (
            vec!["--envs", "128", "--task", "doorkey"],
            vec!["doorkey (6 actions)", "multigoal (3 actions)"],
        ),
        (
            vec!["--envs", "64"],
            vec!["batch of 64 environments expected, publisher sends 128"],
        ),
    ] {
        let mut args = vec![
            "learner",
            "serve",
            "--run",
            &run,
            "--run-dir",
            d,
            "--maze",
            "small",
        ];
        args.extend(extra.iter().copied());
        let out = run_bounded(&args, Duration::from_secs(30));
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(2), "{extra:?} accepted: {err}");
        for n in needles {
            assert!(err.contains(n), "{n:?} not in: {err}");
        }
    }
    let _ = Command::new("kill")
        .args(["-TERM", &sim.0.id().to_string()])
        .status();
    assert!(wait_exit(&mut sim.0, Duration::from_secs(20)).success());
    assert!(
        wait_for(Duration::from_secs(5), || shm_files(&run).is_empty()),
        "{:?}",
        shm_files(&run)
    );
}

// ------------------------------------------------------------ item 7

#[test]
fn role_logs_in_files_carry_no_colour_codes_and_a_quiet_run_prints_progress() {
    let dir = tempfile::tempdir().unwrap();
    let run = run_name("logs");
    let run_dir = dir.path().join("r");
    let out = run_bounded(
        &[
            "run",
            "--run",
            &run,
            "--run-dir",
            run_dir.to_str().unwrap(),
            "--maze",
            "small",
            "--envs",
            "16",
            "--duration",
            "11",
            "--logs-to-files",
        ],
        Duration::from_secs(60),
    );
    let err = stderr(&out);
    assert!(out.status.success(), "{err}");
    assert!(err.contains("run: 10 s"), "no progress line: {err}");
    for role in ["sim", "learner", "planner"] {
        let log = std::fs::read_to_string(run_dir.join(format!("{role}.log"))).unwrap();
        assert!(!log.contains('\u{1b}'), "{role}.log has ANSI codes: {log}");
    }
    assert!(shm_files(&run).is_empty());
}

// ------------------------------------------------------------ issue 21

/// `(state, parent pid)` of process `pid` (Linux `/proc/<pid>/stat`).
fn proc_state(pid: u32) -> Option<(char, u32)> {
    let s = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    // The command name, in parentheses, may hold spaces: fields follow the last ')'.
    let mut fields = s.get(s.rfind(')')? + 1..)?.split_whitespace();
    let state = fields.next()?.chars().next()?;
    let ppid = fields.next()?.parse().ok()?;
    Some((state, ppid))
}

/// Whether process `pid` runs (a zombie does not: it only waits to be reaped).
pub(crate) fn alive(pid: u32) -> bool {
    proc_state(pid).is_some_and(|(state, _)| state != 'Z')
}

/// The running children of process `pid`.
pub(crate) fn children_of(pid: u32) -> Vec<u32> {
    let mut out: Vec<u32> = std::fs::read_dir("/proc")
        .into_iter()
        .flatten()
        .flatten()
        .filter_map(|e| e.file_name().to_str()?.parse::<u32>().ok())
        .filter(|&p| proc_state(p).is_some_and(|(state, ppid)| ppid == pid && state != 'Z'))
        .collect();
    out.sort_unstable();
    out
}

/// Processes a test started through a parent: SIGKILLed when dropped if
/// still running (a failed assertion leaves nothing behind), each only if
/// its command line still names `tag` (its pid was not reused).
pub(crate) struct Orphans {
    pub(crate) pids: Vec<u32>,
    pub(crate) tag: String,
}

impl Drop for Orphans {
    fn drop(&mut self) {
        for &p in &self.pids {
            let cmdline = std::fs::read(format!("/proc/{p}/cmdline")).unwrap_or_default();
            if alive(p) && String::from_utf8_lossy(&cmdline).contains(&self.tag) {
                let _ = nix::sys::signal::kill(
                    nix::unistd::Pid::from_raw(p as i32),
                    nix::sys::signal::Signal::SIGKILL,
                );
            }
        }
    }
}

#[test]
fn a_run_killed_with_sigkill_takes_its_processes_and_their_shared_memory_with_it() {
    let dir = tempfile::tempdir().unwrap();
    let run = run_name("orphans");
    let run_dir = dir.path().join("r");
    // No --duration: the run would go on for ever.
    let mut parent = spawn(
        dir.path(),
        "run.log",
        &[
            "run",
            "--run",
            &run,
            "--run-dir",
            run_dir.to_str().unwrap(),
            "--maze",
            "small",
            "--envs",
            "16",
        ],
    );
    let pid = parent.0.id();
    assert!(
        wait_for(Duration::from_secs(60), || children_of(pid).len() == 3
            && run_dir.join("sim.stats.jsonl").exists()),
        "the run never started its three processes ({:?}): {}",
        children_of(pid),
        std::fs::read_to_string(dir.path().join("run.log")).unwrap_or_default()
    );
    let children = Orphans {
        pids: children_of(pid),
        tag: run.clone(),
    };
    assert!(
        !shm_files(&run).is_empty(),
        "the run holds no shared memory"
    );
    parent.0.kill().unwrap();
    parent.0.wait().unwrap();
    assert!(
        wait_for(Duration::from_secs(10), || children
            .pids
            .iter()
            .all(|&p| !alive(p))),
        "still running after their parent's SIGKILL: {:?}",
        children
            .pids
            .iter()
            .filter(|&&p| alive(p))
            .collect::<Vec<_>>()
    );
    assert!(
        wait_for(Duration::from_secs(5), || shm_files(&run).is_empty()),
        "shared memory left: {:?}",
        shm_files(&run)
    );
    // The run's name is free again at once.
    let out = run_bounded(
        &[
            "run",
            "--run",
            &run,
            "--run-dir",
            run_dir.to_str().unwrap(),
            "--maze",
            "small",
            "--envs",
            "16",
            "--duration",
            "2",
        ],
        Duration::from_secs(60),
    );
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(shm_files(&run).is_empty(), "{:?}", shm_files(&run));
}

/// Every file under `dir` with its bytes.
fn snapshot(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut files: Vec<(String, Vec<u8>)> = files_under(dir)
        .into_iter()
        .map(|f| {
            let bytes = std::fs::read(&f).unwrap();
            (f, bytes)
        })
        .collect();
    files.sort();
    files
}

const TINY_TRAIN: &str = "env_steps = 320\neval_every = 160\nvalidation_seeds = 2\ntest_seeds = 2\n[agent]\nenvs = 8\nrollout_len = 20\n";

fn train_args<'a>(config: &'a str, run: &'a str) -> Vec<&'a str> {
    vec![
        "train", "--maze", "small", "--agent", "a2c", "--config", config, "--run", run,
    ]
}

#[test]
fn train_and_discover_write_only_into_an_empty_directory_or_a_run_of_their_kind() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let config = d.join("tiny.toml");
    std::fs::write(&config, TINY_TRAIN).unwrap();
    let config = config.to_str().unwrap();
    let discovered = d.join("discovered");
    let out = discover(discovered.to_str().unwrap(), &[]);
    assert!(out.status.success(), "{}", stderr(&out));
    let trained = d.join("trained");
    let out = run_bounded(
        &train_args(config, trained.to_str().unwrap()),
        Duration::from_secs(120),
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let folder = d.join("folder");
    std::fs::create_dir(&folder).unwrap();
    std::fs::write(folder.join("notes.txt"), "mine\n").unwrap();
    std::fs::write(folder.join("config.toml"), "[package]\nname = \"mine\"\n").unwrap();

    let cases: [(&str, &Path, &[&str]); 4] = [
        (
            "train",
            &discovered,
            &["is a discover run", "maze small", "--world-graph"],
        ),
        (
            "train",
            &folder,
            &["is not empty and not a train run", "notes.txt"],
        ),
        (
            "discover",
            &trained,
            &["is a train run, not a discover run"],
        ),
        (
            "discover",
            &folder,
            &["is not empty and not a discover run", "notes.txt"],
        ),
    ];
    for (command, target, needles) in cases {
        let before = snapshot(target);
        let t = target.to_str().unwrap();
        let out = if command == "train" {
            run_bounded(&train_args(config, t), Duration::from_secs(60))
        } else {
            discover(t, &[])
        };
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(1), "{command} {t}: {err}");
        for n in needles {
            assert!(err.contains(n), "{command} {t}: {n:?} not in: {err}");
        }
        assert!(err.contains("left untouched"), "{err}");
        no_crash_text(&err);
        assert!(
            snapshot(target) == before,
            "{command} changed {t}: {:?}",
            files_under(target)
        );
    }
    // A run of its own kind, and an empty directory, are taken.
    let out = run_bounded(
        &train_args(config, trained.to_str().unwrap()),
        Duration::from_secs(120),
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let empty = d.join("empty");
    std::fs::create_dir(&empty).unwrap();
    let out = run_bounded(
        &train_args(config, empty.to_str().unwrap()),
        Duration::from_secs(120),
    );
    assert!(out.status.success(), "{}", stderr(&out));
}

#[test]
fn a_world_graph_of_another_maze_is_refused_before_anything_is_written() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let config = d.join("tiny.toml");
    std::fs::write(&config, TINY_TRAIN).unwrap();
    let medium = d.join("medium");
    let mut args = discover_args(medium.to_str().unwrap(), "1");
    args[4] = "medium";
    let out = run_bounded(&args, Duration::from_secs(300));
    assert!(out.status.success(), "{}", stderr(&out));
    let run = d.join("wn");
    for init in [
        vec!["--agent", "wn", "--candidates", "pivotal"],
        vec!["--agent", "a2c", "--init", "pi-g"],
    ] {
        let mut args = vec![
            "train",
            "--maze",
            "small",
            "--config",
            config.to_str().unwrap(),
            "--world-graph",
            medium.to_str().unwrap(),
            "--run",
            run.to_str().unwrap(),
        ];
        args.extend(init);
        let out = run_bounded(&args, Duration::from_secs(60));
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(1), "{err}");
        assert!(
            err.contains("is from maze medium (25x19), this run is small (13x13)"),
            "{err}"
        );
        assert!(!err.contains("tensor"), "{err}");
        no_crash_text(&err);
        assert!(!run.exists(), "files written: {:?}", files_under(&run));
    }
    // `evaluate` says what a discover run is.
    let out = run_bounded(
        &["evaluate", medium.to_str().unwrap()],
        Duration::from_secs(60),
    );
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("is a discover run (the world graph of maze medium), not a train run"),
        "{err}"
    );
    // `discover` and `train` default to the same maze.
    for command in ["discover", "train"] {
        let out = run_bounded(&[command, "--help"], Duration::from_secs(30));
        let help = String::from_utf8_lossy(&out.stdout).into_owned();
        // The --maze entry: its line and the description lines under it.
        let mut lines = help.lines().skip_while(|l| !l.contains("--maze <MAZE>"));
        let first = lines.next().unwrap_or_default().to_string();
        let maze: Vec<&str> = lines
            .take_while(|l| !l.trim_start().starts_with('-'))
            .collect();
        let maze = format!("{first} {}", maze.join(" "));
        assert!(maze.contains("[default: small]"), "{command}: {maze}");
    }
}

#[test]
fn evaluate_scores_a_door_key_run() {
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("tiny.toml");
    std::fs::write(&config, TINY_TRAIN).unwrap();
    let run = dir.path().join("dk");
    let mut args = train_args(config.to_str().unwrap(), run.to_str().unwrap());
    args.extend(["--task", "doorkey"]);
    let out = run_bounded(&args, Duration::from_secs(120));
    assert!(out.status.success(), "{}", stderr(&out));
    let out = run_bounded(
        &["evaluate", run.to_str().unwrap(), "--seeds", "0..3"],
        Duration::from_secs(60),
    );
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(
        String::from_utf8_lossy(&out.stdout).contains("on test seeds 0..3"),
        "{}",
        String::from_utf8_lossy(&out.stdout)
    );
}
