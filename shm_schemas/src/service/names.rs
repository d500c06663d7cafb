//! Run and service names, and the iceoryx2 config that isolates a run.

use iceoryx2::config::Config;
use iceoryx2::prelude::*;

use super::{PREFIX_ROOT, SERVICE_ROOT};
use crate::{Channel, ShmError};

/// A run's name: `1..=64` characters from `[A-Za-z0-9_.-]`, not starting
/// with `.` (it becomes part of service names and file names).
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct RunName(String);

impl RunName {
    /// Longest accepted name.
    pub const MAX_LEN: usize = 64;

    /// Checks and wraps `name`.
    pub fn new(name: &str) -> Result<RunName, ShmError> {
        let bad = |reason: &str| ShmError::InvalidName {
            what: "run name",
            value: name.to_owned(),
            reason: reason.to_owned(),
        };
        if name.is_empty() || name.len() > Self::MAX_LEN {
            return Err(bad("must have 1 to 64 characters"));
        }
        if name.starts_with('.') {
            return Err(bad("must not start with '.'"));
        }
        if !name
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b"_.-".contains(&b))
        {
            return Err(bad("only letters, digits, '_', '.' and '-' are allowed"));
        }
        Ok(RunName(name.to_owned()))
    }

    /// The name.
    pub fn as_str(&self) -> &str {
        &self.0
    }

    /// The run id written into every header: FNV-1a (64 bit) of the name.
    pub fn id(&self) -> u64 {
        self.0.bytes().fold(0xcbf2_9ce4_8422_2325_u64, |h, b| {
            (h ^ b as u64).wrapping_mul(0x0100_0000_01b3)
        })
    }

    /// The run's iceoryx2 prefix, `wg_<name>_`.
    pub fn prefix(&self) -> String {
        format!("{PREFIX_ROOT}{}_", self.0)
    }
}

impl std::fmt::Display for RunName {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

/// `wg/<run>/<channel>` as a string.
pub fn service_name_str(run: &RunName, channel: Channel) -> String {
    format!("{SERVICE_ROOT}/{}/{}", run.as_str(), channel.suffix())
}

/// `wg/<run>/<channel>` as an iceoryx2 service name.
pub fn service_name(run: &RunName, channel: Channel) -> Result<ServiceName, ShmError> {
    let s = service_name_str(run, channel);
    ServiceName::new(&s).map_err(|e| ShmError::InvalidName {
        what: "service name",
        value: s,
        reason: format!("{e:?}"),
    })
}

// ---------------------------------------------------------------- config and nodes

/// A default iceoryx2 config (never a config file found on disk) with the
/// given file prefix: what isolates one run, or one test, from the others.
pub fn isolated_config(prefix: &str) -> Result<Config, ShmError> {
    let mut config = Config::default();
    config.global.prefix = FileName::new(prefix.as_bytes()).map_err(|e| ShmError::InvalidName {
        what: "iceoryx2 prefix",
        value: prefix.to_owned(),
        reason: format!("{e:?}"),
    })?;
    Ok(config)
}

/// The config of a run: [`isolated_config`] with [`RunName::prefix`].
pub fn run_config(run: &RunName) -> Result<Config, ShmError> {
    isolated_config(&run.prefix())
}

/// The prefix of `config` as a string.
pub fn config_prefix(config: &Config) -> String {
    config.global.prefix.to_string()
}
