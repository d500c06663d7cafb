//! Files named on the command line for a picture or a trace (`sim render
//! --png`, `evaluate --picture`, `evaluate --trace`): checked before any work is done. A missing folder
//! is created, and the command says so; a path that runs through a regular
//! file, or that names a folder, is refused with a message naming it.

use std::path::Path;

use anyhow::{Context, bail};

/// Makes `path`, given with the option `flag`, writable as a file: creates
/// its missing parent folders (printing the one created on stderr), or
/// fails naming the path and what stands in the way.
pub fn prepare(flag: &str, path: &Path) -> anyhow::Result<()> {
    if path.is_dir() {
        bail!(
            "{flag} {}: is a folder; name the file to write",
            path.display()
        );
    }
    let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) else {
        return Ok(());
    };
    if parent.is_dir() {
        return Ok(());
    }
    // The deepest part of the path that exists must be a folder.
    if let Some(existing) = parent
        .ancestors()
        .find(|a| !a.as_os_str().is_empty() && a.exists())
        && !existing.is_dir()
    {
        bail!(
            "{flag} {}: {} is a file, not a folder",
            path.display(),
            existing.display()
        );
    }
    std::fs::create_dir_all(parent).with_context(|| {
        format!(
            "{flag} {}: cannot create the folder {}",
            path.display(),
            parent.display()
        )
    })?;
    eprintln!("{flag}: created the folder {}", parent.display());
    Ok(())
}
