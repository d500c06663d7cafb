//! `worldgraph clean`: removes the shared memory that dead runs left behind.
//!
//! A run killed with SIGKILL (or a killed `bench`, whose runs are named
//! `bench-<pid>`) leaves its `/dev/shm/wg_<run>_*` files; every role sweeps
//! such files of dead runs at start, and this command does it on demand,
//! saying what it removed. Runs with a live process are never touched.

use std::time::Duration;

use clap::Args;
use iceoryx2::prelude::ipc;
use shm_schemas::service::{PREFIX_ROOT, sweep_stale_prefixes};

/// `clean` options.
#[derive(Debug, Clone, Args)]
pub struct CleanArgs {
    /// Leave files younger than this many seconds (a run that is starting
    /// has files before its first process registers).
    #[arg(long, default_value_t = 2.0)]
    pub min_age: f64,
}

/// Runs `worldgraph clean`.
pub fn run(a: CleanArgs) -> anyhow::Result<std::process::ExitCode> {
    anyhow::ensure!(
        a.min_age.is_finite() && a.min_age >= 0.0,
        "--min-age must be a number of seconds, at least 0"
    );
    let swept =
        sweep_stale_prefixes::<ipc::Service>(PREFIX_ROOT, Duration::from_secs_f64(a.min_age))?;
    if swept.is_empty() {
        println!("clean: no shared memory of a dead run to remove");
    }
    for s in &swept {
        println!(
            "clean: removed {} file(s) of dead run prefix {}",
            s.removed.len(),
            s.prefix
        );
        for f in &s.removed {
            println!("  {}", f.display());
        }
    }
    Ok(std::process::ExitCode::SUCCESS)
}
