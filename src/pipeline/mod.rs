//! Starting, watching, restarting and stopping the three role processes
//! side by side (used by `run`, `bench pipeline` and `soak`).
//!
//! Each role is this same executable with a role subcommand (`sim serve`,
//! `learner serve`, `planner serve`). Children are always reaped (a zombie
//! keeps its iceoryx2 node looking alive), stopped with SIGTERM first and
//! SIGKILL only after a grace period, and the run's shared memory is torn
//! down once all of them are gone.

mod spec;

pub use self::spec::RunCmdArgs;

use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

use anyhow::Context;
use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;

use crate::world_args::WorldArgs;

/// A command that runs this very executable, as a child that dies with
/// this process ([`die_with_parent`]). Every child of `worldgraph` (the
/// roles of `run`, `soak` and `bench pipeline`, the sim and planner of
/// `train`/`discover --pipeline`, the runs of `experiment`) is started
/// from here. When a rebuild has replaced its file since this process
/// started (the path `current_exe` returns is gone), Linux's
/// `/proc/self/exe` still names the running image, so the children run the
/// same build as their parent; `argv[0]` stays `worldgraph`, which their
/// usage messages print.
pub fn worldgraph_command() -> anyhow::Result<Command> {
    let exe = std::env::current_exe().context("cannot find the worldgraph executable")?;
    let running = Path::new("/proc/self/exe");
    let mut cmd = if !exe.exists() && running.exists() {
        use std::os::unix::process::CommandExt;
        let mut cmd = Command::new(running);
        cmd.arg0("worldgraph");
        cmd
    } else {
        Command::new(exe)
    };
    die_with_parent(&mut cmd);
    Ok(cmd)
}

/// The signal a child gets when its parent dies, whatever killed the
/// parent (SIGKILL included): SIGTERM, which every role turns into a clean
/// stop (reports written, the last one out removes the run's shared
/// memory) and which ends a `train` or `discover` at once (they resume
/// from their last checkpoint).
pub const PARENT_DEATH_SIGNAL: libc::c_int = libc::SIGTERM;

/// Makes the child started by `cmd` get [`PARENT_DEATH_SIGNAL`] when this
/// process dies (Linux `PR_SET_PDEATHSIG`), so a killed `run` or
/// `experiment` leaves no sim, learner, planner or `train` running. A
/// parent that died between the fork and the request is caught by
/// comparing `getppid()` with its pid, recorded before the fork: the child
/// then ends before `exec`.
///
/// The kernel sends the signal when the *thread* that forked exits, not
/// the process: every `worldgraph` command starts its children from its
/// main thread, which lives as long as the process.
#[allow(unsafe_code)]
fn die_with_parent(cmd: &mut Command) {
    use std::os::unix::process::CommandExt;
    let parent = std::process::id() as libc::pid_t;
    let signal = PARENT_DEATH_SIGNAL as libc::c_ulong;
    // SAFETY: the closure runs in the child between `fork` and `exec`, where
    // only async-signal-safe calls are allowed: it calls `prctl` and
    // `getppid` (system calls), builds errors from an errno (no allocation)
    // and takes no lock.
    unsafe {
        cmd.pre_exec(move || {
            if libc::prctl(libc::PR_SET_PDEATHSIG, signal, 0, 0, 0) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            if libc::getppid() != parent {
                // The parent is already gone: nobody would stop this child.
                return Err(std::io::Error::from_raw_os_error(libc::ESRCH));
            }
            Ok(())
        });
    }
}

/// One of the three processes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Role {
    /// The simulator.
    Sim,
    /// The learner.
    Learner,
    /// The planner.
    Planner,
}

impl Role {
    /// All roles, in start order (the planner first: it builds the graph
    /// while the others connect).
    pub const ALL: [Role; 3] = [Role::Planner, Role::Sim, Role::Learner];

    /// The role's name.
    pub fn name(self) -> &'static str {
        match self {
            Role::Sim => "sim",
            Role::Learner => "learner",
            Role::Planner => "planner",
        }
    }
}

/// The command-line words that reproduce `w`.
pub fn world_words(w: &WorldArgs) -> Vec<String> {
    let mut v = vec![
        "--task".into(),
        w.task.name().into(),
        "--seed".into(),
        w.seed.to_string(),
    ];
    match &w.layout {
        Some(p) => v.extend(["--layout".into(), p.display().to_string()]),
        None => v.extend(["--maze".into(), w.maze.name().into()]),
    }
    if let Some(m) = w.max_steps {
        v.extend(["--max-steps".into(), m.to_string()]);
    }
    if let Some(b) = w.balls {
        v.extend(["--balls".into(), b.to_string()]);
    }
    v
}

struct Slot {
    role: Role,
    args: Vec<String>,
    child: Option<Child>,
    started: Instant,
    spawned: u32,
}

/// The running role processes of one run.
pub struct Pipeline {
    log_dir: Option<PathBuf>,
    slots: Vec<Slot>,
}

impl Pipeline {
    /// A pipeline of `roles` with their full argument lists (role words
    /// included); children log to `<log_dir>/<role>.log` when given, else
    /// inherit stderr.
    pub fn new(
        roles: Vec<(Role, Vec<String>)>,
        log_dir: Option<&Path>,
    ) -> anyhow::Result<Pipeline> {
        let slots = roles
            .into_iter()
            .map(|(role, args)| Slot {
                role,
                args,
                child: None,
                started: Instant::now(),
                spawned: 0,
            })
            .collect();
        Ok(Pipeline {
            log_dir: log_dir.map(Path::to_path_buf),
            slots,
        })
    }

    fn slot(&mut self, role: Role) -> &mut Slot {
        self.slots
            .iter_mut()
            .find(|s| s.role == role)
            .expect("invariant: every started role has a slot")
    }

    /// Starts (or restarts) `role`.
    pub fn spawn(&mut self, role: Role) -> anyhow::Result<()> {
        let log_dir = self.log_dir.clone();
        let slot = self.slot(role);
        let mut cmd = worldgraph_command()?;
        cmd.args(&slot.args)
            .stdin(Stdio::null())
            .stdout(Stdio::null());
        if let Some(dir) = &log_dir {
            let log = std::fs::OpenOptions::new()
                .create(true)
                .append(true)
                .open(dir.join(format!("{}.log", role.name())))?;
            cmd.stderr(log);
        }
        let child = cmd
            .spawn()
            .with_context(|| format!("cannot start the {} process", role.name()))?;
        slot.spawned += 1;
        slot.child = Some(child);
        slot.started = Instant::now();
        Ok(())
    }

    /// Starts every role.
    pub fn start_all(&mut self) -> anyhow::Result<()> {
        let roles: Vec<Role> = self.slots.iter().map(|s| s.role).collect();
        for r in roles {
            self.spawn(r)?;
        }
        Ok(())
    }

    /// Roles whose process has exited since the last call (reaped), with status.
    pub fn poll_exited(&mut self) -> Vec<(Role, ExitStatus)> {
        let mut out = Vec::new();
        for s in &mut self.slots {
            if let Some(child) = &mut s.child
                && let Ok(Some(status)) = child.try_wait()
            {
                out.push((s.role, status));
                s.child = None;
            }
        }
        out
    }

    /// Process id of `role`, if running.
    pub fn pid(&self, role: Role) -> Option<u32> {
        self.slots
            .iter()
            .find(|s| s.role == role)?
            .child
            .as_ref()
            .map(Child::id)
    }

    /// How long `role`'s latest process ran (or has been running).
    pub fn uptime(&self, role: Role) -> Duration {
        self.slots
            .iter()
            .find(|s| s.role == role)
            .map_or(Duration::ZERO, |s| s.started.elapsed())
    }

    /// Restarts so far of `role`.
    pub fn restarts(&self, role: Role) -> u32 {
        self.slots
            .iter()
            .find(|s| s.role == role)
            .map_or(0, |s| s.spawned.saturating_sub(1))
    }

    /// Whether any role is still running.
    pub fn any_running(&self) -> bool {
        self.slots.iter().any(|s| s.child.is_some())
    }

    /// SIGKILLs `role` and reaps it (a soak test's crash).
    pub fn kill_hard(&mut self, role: Role) -> anyhow::Result<()> {
        let slot = self.slot(role);
        if let Some(child) = &mut slot.child {
            child.kill()?;
            child.wait()?;
        }
        slot.child = None;
        Ok(())
    }

    /// Sends `signal` to every running process (e.g. SIGSTOP/SIGCONT to
    /// pause the pipeline while a benchmark measures its baseline).
    pub fn signal_all(&self, signal: Signal) {
        for s in &self.slots {
            if let Some(c) = &s.child {
                let _ = kill(Pid::from_raw(c.id() as i32), signal);
            }
        }
    }

    /// Waits up to `grace` for every process to exit by itself, then
    /// SIGTERMs the rest, waits `grace` again and SIGKILLs what remains.
    /// Returns each role's last exit status.
    pub fn stop_all(&mut self, grace: Duration) -> Vec<(Role, Option<ExitStatus>)> {
        let mut done: Vec<(Role, Option<ExitStatus>)> = Vec::new();
        for phase in 0..3 {
            if phase == 1 {
                for s in &self.slots {
                    if let Some(c) = &s.child {
                        let _ = kill(Pid::from_raw(c.id() as i32), Signal::SIGTERM);
                    }
                }
            }
            if phase == 2 {
                for s in &mut self.slots {
                    if let Some(c) = &mut s.child {
                        let _ = c.kill();
                    }
                }
            }
            let until = Instant::now() + grace;
            while Instant::now() < until && self.any_running() {
                for (r, st) in self.poll_exited() {
                    done.push((r, Some(st)));
                }
                std::thread::sleep(Duration::from_millis(20));
            }
            if !self.any_running() {
                break;
            }
        }
        for (r, st) in self.poll_exited() {
            done.push((r, Some(st)));
        }
        done
    }
}

impl Drop for Pipeline {
    fn drop(&mut self) {
        for s in &mut self.slots {
            if let Some(c) = &mut s.child {
                let _ = c.kill();
                let _ = c.wait();
            }
        }
    }
}

/// A sim process stepping `envs` environments of `w` in one slice (the
/// learner's algorithms step the whole batch at once) for a learner in this
/// process, and the shared-memory client of its batch: the transport of
/// `discover --pipeline` and `train --pipeline`. The sim exits when this
/// process goes; stop it with [`Pipeline::stop_all`] and tear the run down.
pub fn spawn_sim_env(
    w: &WorldArgs,
    envs: usize,
    run_name: &str,
    dir: &Path,
) -> anyhow::Result<(
    crate::roles::shm_env::ShmEnv<iceoryx2::prelude::ipc::Service>,
    Pipeline,
)> {
    let (layout, env_cfg) = w.build()?;
    let mut words = vec!["sim".to_string(), "serve".into()];
    words.extend(world_words(w));
    words.extend([
        "--run".into(),
        run_name.to_string(),
        "--run-dir".into(),
        dir.display().to_string(),
        "--envs".into(),
        envs.to_string(),
        "--slices".into(),
        "1".into(),
        "--on-peer-death".into(),
        "exit".into(),
    ]);
    let mut p = Pipeline::new(vec![(Role::Sim, words)], Some(dir))?;
    p.spawn(Role::Sim)?;
    let run = shm_schemas::service::RunName::new(run_name)?;
    let shape = shm_schemas::ObsShape::new(envs, layout.width, layout.height)?;
    let opts = crate::roles::shm_env::ShmEnvOptions {
        node_name: crate::roles::LEARNER_NODE.into(),
        sim_node_name: crate::roles::SIM_NODE.into(),
        connect_timeout: Duration::from_secs(60),
        task: Some(env_cfg.task.name().into()),
        ..crate::roles::shm_env::ShmEnvOptions::default()
    };
    let env = crate::roles::shm_env::ShmEnv::connect(
        &shm_schemas::service::run_config(&run)?,
        run,
        shape,
        env_cfg.task.num_actions(),
        opts,
    )?;
    Ok((env, p))
}
