//! Crash-safe checkpoints: tch weights serialised in memory, and a
//! checkpoint directory committed as a whole.
//!
//! libtorch's own `VarStore::save` writes straight to a file and, when the
//! disk is full, throws a C++ exception that aborts the process with a torn
//! file behind. Here the weights are serialised into memory
//! ([`var_store_bytes`], `VarStore::save_to_stream`) and every file is
//! written with the project's atomic write (`sim::atomic_file::write_atomic`:
//! write a temporary file, fsync, rename, fsync the directory). A
//! checkpoint's files are committed together ([`commit`]): they are all
//! written into a staging directory `<dir>.new` first, which then replaces
//! `<dir>` by two renames (`<dir>` → `<dir>.old`, `<dir>.new` → `<dir>`). A
//! crash between them leaves `<dir>.old` and no `<dir>`, which [`recover`]
//! (called by [`commit`] and by every reader) renames back, so a reader
//! always sees the previous checkpoint or the new one, whole. A write that
//! fails (no space left) leaves the previous checkpoint as it was and no
//! staging files, and comes back as [`LearnerError::Checkpoint`] naming the
//! file and the cause.

use std::io::{Cursor, Write};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use tch::Tensor;
use tch::nn::VarStore;

use crate::LearnerError;

/// A `Write` into a buffer shared with the caller: libtorch takes ownership
/// of the stream it writes to, so the bytes are collected behind an `Arc`.
#[derive(Clone, Default)]
struct SharedBuf(Arc<Mutex<Vec<u8>>>);

impl Write for SharedBuf {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.0
            .lock()
            .map_err(|_| std::io::Error::other("checkpoint buffer poisoned"))?
            .extend_from_slice(buf);
        Ok(buf.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

/// The weights of `vs` in libtorch's multi-tensor format (what
/// `VarStore::save` would write to a file), as bytes.
pub fn var_store_bytes(vs: &VarStore) -> Result<Vec<u8>, LearnerError> {
    let buf = SharedBuf::default();
    vs.save_to_stream(buf.clone())
        .map_err(|e| checkpoint_error("(in memory)", first_line(&e.to_string())))?;
    let bytes = std::mem::take(
        &mut *buf
            .0
            .lock()
            .map_err(|_| checkpoint_error("(in memory)", "checkpoint buffer poisoned"))?,
    );
    Ok(bytes)
}

/// Named tensors (an agent's weights and optimiser moments) as the bytes
/// of a tensor file.
pub fn named_tensors_bytes(named: &[(String, Tensor)]) -> Result<Vec<u8>, LearnerError> {
    let refs: Vec<(&str, &Tensor)> = named.iter().map(|(k, t)| (k.as_str(), t)).collect();
    let mut buf = Vec::new();
    Tensor::save_multi_to_stream(&refs, &mut buf)?;
    Ok(buf)
}

/// The named tensors of [`named_tensors_bytes`]'s `bytes`, read from
/// `source` (named in the error).
pub fn named_tensors_of(
    bytes: &[u8],
    source: &Path,
) -> Result<Vec<(String, Tensor)>, LearnerError> {
    Tensor::load_multi_from_stream(Cursor::new(bytes))
        .map_err(|e| checkpoint_error(source, e.to_string()))
}

/// Loads weights written by [`var_store_bytes`] into `vs` (same variable
/// names; `path` only names the source in errors).
pub fn load_var_store(vs: &mut VarStore, bytes: Vec<u8>, path: &Path) -> Result<(), LearnerError> {
    vs.load_from_stream(Cursor::new(bytes))
        .map_err(|e| checkpoint_error(path, first_line(&e.to_string())))
}

/// Reads `path` and loads it into `vs` ([`load_var_store`]).
pub fn load_var_store_file(vs: &mut VarStore, path: &Path) -> Result<(), LearnerError> {
    let bytes = std::fs::read(path).map_err(|e| checkpoint_error(path, e))?;
    load_var_store(vs, bytes, path)
}

/// Writes `bytes` to `path` with the project's atomic write; an error names
/// `path` and the cause ("No space left on device").
pub fn write_file(path: &Path, bytes: &[u8]) -> Result<(), LearnerError> {
    sim::atomic_file::write_atomic(path, bytes).map_err(|e| match e {
        sim::SimError::Io { source, .. } => checkpoint_error(path, source),
        other => checkpoint_error(path, other),
    })
}

/// The weights of `vs` written to `path` atomically.
pub fn save_var_store_file(vs: &VarStore, path: &Path) -> Result<(), LearnerError> {
    write_file(path, &var_store_bytes(vs)?)
}

fn sibling(dir: &Path, suffix: &str) -> PathBuf {
    let name = dir
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "checkpoint".into());
    dir.with_file_name(format!("{name}{suffix}"))
}

/// Finishes or undoes an interrupted [`commit`] of `dir`: a crash between
/// its two renames left `<dir>.old` and no `<dir>` (renamed back), a crash
/// while staging left `<dir>.new` (removed), a crash after the swap left
/// `<dir>.old` beside the new `<dir>` (removed).
pub fn recover(dir: &Path) -> Result<(), LearnerError> {
    let (staging, old) = (sibling(dir, ".new"), sibling(dir, ".old"));
    if !dir.exists() && old.is_dir() {
        std::fs::rename(&old, dir).map_err(|e| checkpoint_error(&old, e))?;
    }
    for leftover in [staging, old] {
        if leftover.exists() {
            std::fs::remove_dir_all(&leftover).map_err(|e| checkpoint_error(&leftover, e))?;
        }
    }
    Ok(())
}

/// Commits `files` (name, bytes) as the checkpoint directory `dir`,
/// replacing what was there as a whole (see the module doc). On error the
/// previous checkpoint is untouched and no staging file remains.
pub fn commit(dir: &Path, files: &[(&str, &[u8])]) -> Result<(), LearnerError> {
    recover(dir)?;
    let (staging, old) = (sibling(dir, ".new"), sibling(dir, ".old"));
    let staged = (|| {
        std::fs::create_dir_all(&staging).map_err(|e| checkpoint_error(&staging, e))?;
        for (name, bytes) in files {
            // Errors name the file as the user knows it: <dir>/<name>.
            write_file(&staging.join(name), bytes).map_err(|e| match e {
                LearnerError::Checkpoint { message, .. } => {
                    checkpoint_error(dir.join(name), message)
                }
                other => other,
            })?;
        }
        Ok(())
    })();
    if let Err(e) = staged {
        let _ = std::fs::remove_dir_all(&staging);
        return Err(e);
    }
    if dir.exists() {
        std::fs::rename(dir, &old).map_err(|e| checkpoint_error(dir, e))?;
    }
    std::fs::rename(&staging, dir).map_err(|e| checkpoint_error(dir, e))?;
    if let Some(parent) = dir.parent().filter(|p| !p.as_os_str().is_empty())
        && let Ok(d) = std::fs::File::open(parent)
    {
        let _ = d.sync_all();
    }
    if old.exists() {
        let _ = std::fs::remove_dir_all(&old);
    }
    Ok(())
}

/// The first line of a libtorch message (the rest is a C++ backtrace,
/// logged at debug level).
pub fn first_line(message: &str) -> String {
    let mut lines = message.lines();
    let first = lines.next().unwrap_or_default().to_owned();
    let rest: Vec<&str> = lines.collect();
    if !rest.is_empty() {
        tracing_debug(&rest.join("\n"));
    }
    first
}

fn tracing_debug(backtrace: &str) {
    if std::env::var_os("RUST_LOG").is_some_and(|v| v.to_string_lossy().contains("debug")) {
        eprintln!("libtorch backtrace:\n{backtrace}");
    }
}

/// A checkpoint error naming the file `path` and the cause `e`.
pub fn checkpoint_error(path: impl AsRef<Path>, e: impl std::fmt::Display) -> LearnerError {
    LearnerError::Checkpoint {
        path: path.as_ref().display().to_string(),
        message: e.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tch::nn::Module;

    fn net(seed: i64) -> (VarStore, tch::nn::Linear) {
        let vs = VarStore::new(tch::Device::Cpu);
        let lin = crate::seeding::init_seeded(seed as u64, || {
            tch::nn::linear(vs.root() / "l", 3, 2, Default::default())
        });
        (vs, lin)
    }

    #[test]
    fn weights_round_trip_through_memory_and_a_committed_directory() {
        let tmp = tempdir();
        let dir = tmp.path().join("checkpoint");
        let (vs_a, lin_a) = net(1);
        let bytes = var_store_bytes(&vs_a).unwrap();
        commit(&dir, &[("w.ot", &bytes), ("state.json", b"{}")]).unwrap();
        let (mut vs_b, lin_b) = net(2);
        let x = tch::Tensor::ones([1, 3], (tch::Kind::Float, tch::Device::Cpu));
        let out = |lin: &tch::nn::Linear| -> Vec<f32> {
            Vec::<f32>::try_from(lin.forward(&x).flatten(0, -1)).unwrap()
        };
        assert_ne!(out(&lin_a), out(&lin_b));
        load_var_store_file(&mut vs_b, &dir.join("w.ot")).unwrap();
        assert_eq!(out(&lin_a), out(&lin_b));
        // A second commit replaces the set as a whole.
        commit(&dir, &[("only.txt", b"x")]).unwrap();
        assert!(!dir.join("w.ot").exists() && dir.join("only.txt").is_file());
        assert!(!sibling(&dir, ".new").exists() && !sibling(&dir, ".old").exists());
    }

    #[test]
    fn a_crash_between_the_renames_is_recovered() {
        let tmp = tempdir();
        let dir = tmp.path().join("checkpoint");
        commit(&dir, &[("a", b"1")]).unwrap();
        // As if killed after `<dir>` → `<dir>.old`, with a half-staged set.
        std::fs::rename(&dir, sibling(&dir, ".old")).unwrap();
        std::fs::create_dir(sibling(&dir, ".new")).unwrap();
        recover(&dir).unwrap();
        assert_eq!(std::fs::read(dir.join("a")).unwrap(), b"1");
        assert!(!sibling(&dir, ".new").exists() && !sibling(&dir, ".old").exists());
    }

    #[test]
    fn a_failed_write_names_the_file_and_keeps_the_previous_checkpoint() {
        let tmp = tempdir();
        let dir = tmp.path().join("checkpoint");
        commit(&dir, &[("a", b"1")]).unwrap();
        // A name that cannot be a file (a directory of that name is in the way).
        let err = commit(&dir, &[("a", b"2"), ("sub/../../x/..", b"3")]).unwrap_err();
        let msg = err.to_string();
        assert!(msg.contains("checkpoint"), "{msg}");
        assert_eq!(std::fs::read(dir.join("a")).unwrap(), b"1");
        assert!(!sibling(&dir, ".new").exists());
    }

    /// A fresh directory, removed when the test ends (pass or fail).
    fn tempdir() -> tempfile::TempDir {
        tempfile::Builder::new()
            .prefix("wg-ckpt-")
            .tempdir()
            .expect("a temporary directory")
    }
}
