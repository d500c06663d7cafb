//! The run's files in `/dev/shm`: permissions, dead-node cleanup and teardown.

use std::path::{Path as StdPath, PathBuf};
use std::time::Duration;

use iceoryx2::config::Config;
use iceoryx2::node::{CleanupState, NodeView};
use iceoryx2::prelude::*;

use super::SHM_DIR;
use super::names::config_prefix;
use crate::ShmError;

/// Removes group and other permission bits from `/dev/shm/<prefix>*`
/// (iceoryx2 creates the `global_mgmt` segment world read-writable).
/// Returns the files changed.
pub fn harden_shm_permissions(prefix: &str) -> Result<Vec<PathBuf>, ShmError> {
    use std::os::unix::fs::PermissionsExt;
    let mut changed = Vec::new();
    for (path, mode) in shm_files(prefix)? {
        if mode & 0o077 != 0 {
            let perms = std::fs::Permissions::from_mode(mode & 0o700);
            let done = std::fs::set_permissions(&path, perms);
            changed.extend(unless_vanished("chmod", path, done)?);
        }
    }
    Ok(changed)
}

/// The outcome of `op` on `path`: the path if it succeeded, nothing if the
/// file was removed meanwhile (a peer's cleanup got there first, which
/// leaves nothing to do), the error otherwise.
fn unless_vanished(
    op: &'static str,
    path: PathBuf,
    done: std::io::Result<()>,
) -> Result<Option<PathBuf>, ShmError> {
    match done {
        Ok(()) => Ok(Some(path)),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
        Err(source) => Err(ShmError::Io { op, path, source }),
    }
}

/// `/dev/shm/<prefix>*` files with their permission bits.
///
/// iceoryx2 names them `<prefix><40 hex digits>` followed by `_` or `.`;
/// only such names count, so the files of run `a_b` are not mistaken for
/// files of run `a` (whose prefix `wg_a_` is a prefix of `wg_a_b_`).
pub fn shm_files(prefix: &str) -> Result<Vec<(PathBuf, u32)>, ShmError> {
    let mut files = files_with_prefix(StdPath::new(SHM_DIR), prefix)?;
    files.retain(|(path, _)| {
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        is_iceoryx2_name_after_prefix(name.as_bytes().get(prefix.len()..).unwrap_or_default())
    });
    Ok(files)
}

/// `<40 hex digits>` then `_` or `.`: the hash iceoryx2 puts after the prefix.
pub(super) fn is_iceoryx2_name_after_prefix(rest: &[u8]) -> bool {
    rest.len() > 40
        && rest[..40].iter().all(u8::is_ascii_hexdigit)
        && matches!(rest[40], b'_' | b'.')
}

pub(super) fn files_with_prefix(
    dir: &StdPath,
    prefix: &str,
) -> Result<Vec<(PathBuf, u32)>, ShmError> {
    use std::os::unix::fs::PermissionsExt;
    let entries = std::fs::read_dir(dir).map_err(|source| ShmError::Io {
        op: "list",
        path: dir.to_owned(),
        source,
    })?;
    let mut out = Vec::new();
    for entry in entries.flatten() {
        let name = entry.file_name();
        if !name.to_string_lossy().starts_with(prefix) {
            continue;
        }
        if let Ok(meta) = entry.metadata() {
            out.push((entry.path(), meta.permissions().mode() & 0o7777));
        }
    }
    out.sort();
    Ok(out)
}

// ---------------------------------------------------------------- cleanup

/// One node found by [`list_nodes`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct NodeSummary {
    /// Node name (empty when its details could not be read).
    pub name: String,
    /// Process id.
    pub pid: i64,
    /// Executable name.
    pub executable: String,
    /// Whether the owning process is alive.
    pub alive: bool,
}

/// The nodes registered under `config`'s prefix, alive and dead
/// (inaccessible or undefined ones are skipped).
pub fn list_nodes<S: Service>(config: &Config) -> Result<Vec<NodeSummary>, ShmError> {
    let mut out = Vec::new();
    Node::<S>::list(config, |state| {
        let (view_details, alive) = match &state {
            NodeState::Alive(v) => (v.details().clone(), true),
            NodeState::Dead(v) => (v.details().clone(), false),
            NodeState::Inaccessible(_) | NodeState::Undefined(_) => {
                return CallbackProgression::Continue;
            }
        };
        let (name, pid, executable) = match view_details {
            Some(d) => (
                d.name().to_string(),
                d.process_id().value() as i64,
                d.executable().to_string(),
            ),
            None => (String::new(), -1, String::new()),
        };
        out.push(NodeSummary {
            name,
            pid,
            executable,
            alive,
        });
        CallbackProgression::Continue
    })
    .map_err(|e| ShmError::Ipc {
        op: "list nodes",
        service: config_prefix(config),
        detail: format!("{e:?}"),
    })?;
    Ok(out)
}

/// The dead nodes under `config`'s prefix (a crashed or killed process).
pub fn list_dead_nodes<S: Service>(config: &Config) -> Result<Vec<NodeSummary>, ShmError> {
    Ok(list_nodes::<S>(config)?
        .into_iter()
        .filter(|n| !n.alive)
        .collect())
}

/// Removes the stale resources of every dead node under `config`'s prefix
/// (what a start-up should do after a killed run). Waits up to `timeout`
/// per node for a concurrent cleaner.
pub fn cleanup_dead_nodes<S: Service>(
    config: &Config,
    timeout: Duration,
) -> Result<CleanupState, ShmError> {
    let mut dead = Vec::new();
    Node::<S>::list(config, |state| {
        if let NodeState::Dead(view) = state {
            dead.push(view);
        }
        CallbackProgression::Continue
    })
    .map_err(|e| ShmError::Ipc {
        op: "list nodes",
        service: config_prefix(config),
        detail: format!("{e:?}"),
    })?;
    let mut state = CleanupState {
        cleanups: 0,
        failed_cleanups: 0,
    };
    for view in dead {
        match view.blocking_remove_stale_resources(timeout) {
            Ok(()) => state.cleanups += 1,
            Err(_) => state.failed_cleanups += 1,
        }
    }
    Ok(state)
}

/// Removes the `/dev/shm/<prefix>*global_mgmt` segments iceoryx2 leaves
/// behind after a clean exit (one per prefix and iceoryx2 version). Only
/// these are touched: removing live service segments by hand corrupts
/// services (iceoryx2 issue #601). Returns the files removed.
pub fn remove_global_mgmt(prefix: &str) -> Result<Vec<PathBuf>, ShmError> {
    let mut removed = Vec::new();
    for (path, _) in shm_files(prefix)? {
        if !path.to_string_lossy().ends_with("global_mgmt") {
            continue;
        }
        let done = std::fs::remove_file(&path);
        removed.extend(unless_vanished("remove", path, done)?);
    }
    Ok(removed)
}

/// Teardown of a run (or a test prefix): refuses while a node is alive,
/// cleans up dead nodes, then removes the leftover `global_mgmt` segments.
/// Returns the shared-memory files still present afterwards (empty after
/// a clean shutdown).
pub fn teardown_run<S: Service>(config: &Config) -> Result<Vec<PathBuf>, ShmError> {
    let prefix = config_prefix(config);
    let alive = list_nodes::<S>(config)?.iter().filter(|n| n.alive).count();
    if alive > 0 {
        return Err(ShmError::StillInUse { prefix, alive });
    }
    cleanup_dead_nodes::<S>(config, Duration::from_secs(1))?;
    remove_global_mgmt(&prefix)?;
    Ok(shm_files(&prefix)?.into_iter().map(|(p, _)| p).collect())
}

/// The iceoryx2 prefixes under [`SHM_DIR`] that start with `root` (e.g.
/// [`crate::service::PREFIX_ROOT`], `wg_`): each file named
/// `<prefix><40 hex digits>{_,.}…` contributes its prefix.
pub fn shm_prefixes(root: &str) -> Result<Vec<String>, ShmError> {
    let mut prefixes: Vec<String> = files_with_prefix(StdPath::new(SHM_DIR), root)?
        .into_iter()
        .filter_map(|(path, _)| {
            let name = path.file_name()?.to_string_lossy().into_owned();
            // The hash starts after the last '_' that is followed by 40 hex
            // digits and a separator.
            (root.len()..name.len())
                .rev()
                .filter(|&i| name.as_bytes()[i - 1] == b'_')
                .find(|&i| is_iceoryx2_name_after_prefix(&name.as_bytes()[i..]))
                .map(|i| name[..i].to_owned())
        })
        .collect();
    prefixes.sort();
    prefixes.dedup();
    Ok(prefixes)
}

/// What [`sweep_stale_prefixes`] removed for one prefix.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Swept {
    /// The iceoryx2 prefix (`wg_<run>_`).
    pub prefix: String,
    /// The files removed.
    pub removed: Vec<PathBuf>,
}

/// Removes the shared memory of every prefix under `root` (`wg_`) that no
/// live process uses: a killed run's dead nodes are cleaned up, then the
/// leftover `global_mgmt` segments removed ([`teardown_run`]). A prefix
/// with a live node is left alone, and so is one whose newest file is
/// younger than `min_age` (a run that is starting up has files before its
/// first node is registered). Returns what was removed, prefix by prefix.
pub fn sweep_stale_prefixes<S: Service>(
    root: &str,
    min_age: Duration,
) -> Result<Vec<Swept>, ShmError> {
    let mut out = Vec::new();
    for prefix in shm_prefixes(root)? {
        let before: Vec<PathBuf> = shm_files(&prefix)?.into_iter().map(|(p, _)| p).collect();
        let young = before.iter().any(|p| {
            std::fs::metadata(p)
                .and_then(|m| m.modified())
                .ok()
                .and_then(|t| t.elapsed().ok())
                .is_none_or(|age| age < min_age)
        });
        if young || before.is_empty() {
            continue;
        }
        let config = super::names::isolated_config(&prefix)?;
        match teardown_run::<S>(&config) {
            Ok(left) => {
                let removed: Vec<PathBuf> =
                    before.into_iter().filter(|p| !left.contains(p)).collect();
                if !removed.is_empty() {
                    out.push(Swept { prefix, removed });
                }
            }
            // A live node: its run is not stale.
            Err(ShmError::StillInUse { .. }) => {}
            Err(e) => return Err(e),
        }
    }
    Ok(out)
}
