//! How a command that drives a run stops it: a flag that SIGINT and SIGTERM
//! set ([`stop_flag`], SIGHUP too with [`stop_flag_with_hangup`]), and the
//! teardown of the run's shared memory once its processes are gone
//! ([`teardown`]). `run`, `soak`, `discover --pipeline`, `train --pipeline`,
//! `bench pipeline` and `experiment` use them; no command needs another
//! for them.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

use iceoryx2::prelude::ipc;
use shm_schemas::service::{RunName, run_config, teardown_run};

/// Installs SIGINT/SIGTERM handlers that set the returned flag.
pub fn stop_flag() -> anyhow::Result<Arc<AtomicBool>> {
    flag_on(&[signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM])
}

/// Set on SIGINT, SIGTERM or SIGHUP: stop the children and exit.
pub fn stop_flag_with_hangup() -> anyhow::Result<Arc<AtomicBool>> {
    flag_on(&[
        signal_hook::consts::SIGINT,
        signal_hook::consts::SIGTERM,
        signal_hook::consts::SIGHUP,
    ])
}

fn flag_on(signals: &[i32]) -> anyhow::Result<Arc<AtomicBool>> {
    let stop = Arc::new(AtomicBool::new(false));
    for &sig in signals {
        signal_hook::flag::register(sig, Arc::clone(&stop))?;
    }
    Ok(stop)
}

/// Tears the run's shared memory down; returns the files left behind.
pub fn teardown(run: &str) -> anyhow::Result<Vec<PathBuf>> {
    let config = run_config(&RunName::new(run)?)?;
    // Peers exit within moments of each other; give the registry a moment.
    let until = Instant::now() + Duration::from_secs(3);
    loop {
        match teardown_run::<ipc::Service>(&config) {
            Ok(left) => return Ok(left),
            Err(e) if Instant::now() < until => {
                tracing::debug!("teardown: {e}; retrying");
                std::thread::sleep(Duration::from_millis(100));
            }
            Err(e) => return Err(e.into()),
        }
    }
}
