//! What a run directory holds, looked at before `train` or `discover`
//! writes into it: a command writes only into a new or empty directory or
//! a run of its own kind; any other directory (another kind of run, a
//! folder of the user's) is refused and left untouched.
//!
//! A run is recognised by its own files: a `train` run by its
//! `config.toml` (a training config) or its `seeds.json` beside a
//! checkpoint, a `discover` run by its `config.toml` (the layout and
//! settings it was started with), its latent model's checkpoint or its
//! world graph and `π_g`.

use std::path::Path;

use anyhow::{Context, bail};

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
    let discover = config
        .as_deref()
        .is_some_and(super::discover::is_run_identity)
        || dir.join("checkpoint").join("latent.ot").is_file()
        || (dir.join("graph.json").is_file() && dir.join("pi_g.ot").is_file());
    if discover {
        return Some(RunKind::Discover);
    }
    let train = config
        .as_deref()
        .is_some_and(|t| toml::from_str::<super::train::TrainConfig>(t).is_ok())
        || (dir.join("seeds.json").is_file()
            && dir.join("checkpoint").join("state.json").is_file());
    train.then_some(RunKind::Train)
}

/// What `dir` holds, in words, for a message: `a discover run (the world
/// graph of maze small)`.
pub fn describe(dir: &Path, kind: RunKind) -> String {
    match kind {
        RunKind::Discover => match super::discover::recorded_layout(dir) {
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
