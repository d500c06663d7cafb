//! A run directory: what it holds, looked at before `train` or `discover`
//! writes into it: a command writes only into a new or empty directory or
//! a run of its own kind; any other directory (another kind of run, a
//! folder of the user's) is refused and left untouched.
//!
//! A run is recognised by its own files: a `train` run by its
//! `config.toml` (a training config) or its `seeds.json` beside a
//! checkpoint, a `discover` run by its `config.toml` (the layout and
//! settings it was started with), its latent model's checkpoint or its
//! world graph and `π_g`.

//!
//! A run holds its directory with [`lock`] for its lifetime and records
//! each start in `invocations.txt` ([`record_invocation`]).

use std::path::Path;

use anyhow::{Context, bail};

use super::artefact::{is_run_identity, recorded_layout};
use super::config::TrainConfig;

/// The kinds of run directories.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RunKind {
    /// A `worldgraph train` run.
    Train,
    /// A `worldgraph discover` run.
    Discover,
}

impl RunKind {
    fn command(self) -> &'static str {
        match self {
            RunKind::Train => "train",
            RunKind::Discover => "discover",
        }
    }
}

/// The kind of run `dir` holds, if any.
pub fn kind_of(dir: &Path) -> Option<RunKind> {
    let config = std::fs::read_to_string(dir.join("config.toml")).ok();
    let discover = config.as_deref().is_some_and(is_run_identity)
        || dir.join("checkpoint").join("latent.ot").is_file()
        || (dir.join("graph.json").is_file() && dir.join("pi_g.ot").is_file());
    if discover {
        return Some(RunKind::Discover);
    }
    let train = config
        .as_deref()
        .is_some_and(|t| toml::from_str::<TrainConfig>(t).is_ok())
        || (dir.join("seeds.json").is_file()
            && dir.join("checkpoint").join("state.json").is_file());
    train.then_some(RunKind::Train)
}

/// What `dir` holds, in words, for a message: `a discover run (the world
/// graph of maze small)`.
pub fn describe(dir: &Path, kind: RunKind) -> String {
    match kind {
        RunKind::Discover => match recorded_layout(dir) {
            Some(l) => format!("a discover run (the world graph of maze {})", l.name),
            None => "a discover run".to_string(),
        },
        RunKind::Train => "a train run".to_string(),
    }
}

/// Refuses `dir` (given with `flag`) as the run directory of `want`
/// unless it is missing, empty (but for the file names in `own`, which the
/// command or its caller put there: `train`'s lock, a grid's
/// `grid-config.toml`) or a run of kind `want`. Reads only.
pub fn check(flag: &str, dir: &Path, want: RunKind, own: &[String]) -> anyhow::Result<()> {
    let entries = match std::fs::read_dir(dir) {
        Ok(e) => e,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(()),
        Err(e) if e.kind() == std::io::ErrorKind::NotADirectory => {
            bail!("{flag} {}: is a file, not a directory", dir.display())
        }
        Err(e) => return Err(e).with_context(|| format!("cannot read {}", dir.display())),
    };
    let mut names: Vec<String> = entries
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| !own.contains(n))
        .collect();
    if names.is_empty() {
        return Ok(());
    }
    match kind_of(dir) {
        Some(k) if k == want => Ok(()),
        Some(k) => bail!(
            "{flag} {} is {}, not a {} run; it was left untouched: give {} a new or empty \
             directory{}",
            dir.display(),
            describe(dir, k),
            want.command(),
            want.command(),
            match (want, k) {
                (RunKind::Train, RunKind::Discover) => " (and this one as --world-graph)",
                _ => "",
            }
        ),
        None => {
            names.sort();
            let shown = names.len().min(5);
            bail!(
                "{flag} {} is not empty and not a {} run (it holds {}{}); it was left \
                 untouched: give {} a new or empty directory, or a {} run to resume",
                dir.display(),
                want.command(),
                names[..shown].join(", "),
                if names.len() > shown {
                    format!(" and {} more", names.len() - shown)
                } else {
                    String::new()
                },
                want.command(),
                want.command()
            )
        }
    }
}

/// The name of `file` when it lies directly in `dir` (both may not exist
/// yet): a file the caller put into the run directory on purpose.
pub fn name_in(dir: &Path, file: &Path) -> Option<String> {
    let dir = std::fs::canonicalize(dir).ok()?;
    let file = std::fs::canonicalize(file).ok()?;
    if file.parent()? != dir {
        return None;
    }
    Some(file.file_name()?.to_string_lossy().into_owned())
}

/// Holds `<run>/lock` for the run's lifetime: a second `train` on the same
/// directory is refused at once, naming the process that holds it.
pub fn lock(dir: &Path, command: &str) -> anyhow::Result<std::fs::File> {
    use std::io::Write;
    let path = dir.join("lock");
    let mut f = std::fs::OpenOptions::new()
        .create(true)
        .truncate(false)
        .read(true)
        .write(true)
        .open(&path)
        .with_context(|| format!("cannot open {}", path.display()))?;
    match f.try_lock() {
        Ok(()) => {
            f.set_len(0)?;
            write!(f, "{}", std::process::id())?;
            Ok(f)
        }
        Err(std::fs::TryLockError::WouldBlock) => {
            let holder = std::fs::read_to_string(&path).unwrap_or_default();
            bail!(
                "{} is in use by another {command} process (pid {}); wait for it to end or use another --run",
                dir.display(),
                holder.trim()
            )
        }
        Err(std::fs::TryLockError::Error(e)) => {
            Err(e).with_context(|| format!("cannot lock {}", path.display()))
        }
    }
}

/// Appends the command line, the crate's version and `build` (the commit
/// the binary was built from) to the run's `invocations.txt`: one line per
/// start, so a resumed run appends its own.
pub fn record_invocation(dir: &Path, version: &str, build: &str) -> anyhow::Result<()> {
    use std::io::Write as _;
    let args: Vec<String> = std::env::args_os()
        .map(|a| a.to_string_lossy().into_owned())
        .collect();
    let line = format!(
        "worldgraph {version} (commit {build}): {}\n",
        args.join(" ")
    );
    let path = dir.join("invocations.txt");
    std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(&path)
        .and_then(|mut f| f.write_all(line.as_bytes()))
        .with_context(|| format!("cannot append to {}", path.display()))
}

/// The commit of the binary that last started the run in `dir`, from its
/// `invocations.txt` ([`record_invocation`]); `None` when the run records
/// none (a run made before its command recorded invocations).
pub fn last_invocation_commit(dir: &Path) -> Option<String> {
    let text = std::fs::read_to_string(dir.join("invocations.txt")).ok()?;
    text.lines().rev().find_map(|line| {
        let rest = line.split_once(" (commit ")?.1;
        let (commit, _) = rest.split_once("): ")?;
        Some(commit.to_string())
    })
}
