//! Errors of the simulator crate.

use crate::layout::LayoutError;

/// Everything that can go wrong building or running environments.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SimError {
    /// A layout was refused (the message names the line and column).
    #[error("{0}")]
    Layout(#[from] LayoutError),
    /// Reading or writing a file failed.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// The cause.
        #[source]
        source: std::io::Error,
    },
    /// An invalid setting.
    #[error("invalid configuration: {0}")]
    Config(String),
    /// Encoding a PNG failed.
    #[error("cannot encode PNG {path}: {message}")]
    Png {
        /// The file.
        path: String,
        /// The encoder's message.
        message: String,
    },
}
