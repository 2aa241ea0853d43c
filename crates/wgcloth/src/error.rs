//! One error type for the library: every failure names what is wrong
//! (the field, the file, the vertex) in one line, and the CLI maps it to
//! exit code 2.

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A configuration value out of its range (CLI flag or TOML field).
    #[error("invalid `{field}`: {reason}")]
    Config { field: String, reason: String },

    /// A file that could not be read or written.
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },

    /// A file that was read but whose content is wrong.
    #[error("{}: {reason}", path.display())]
    File { path: PathBuf, reason: String },

    /// A request the current build cannot honour.
    #[error("{0}")]
    Unsupported(String),

    /// No usable GPU adapter, a device that could not be created or was
    /// lost, or a scene beyond the adapter's limits.
    #[error("GPU: {0}")]
    Gpu(String),

    /// The simulation state stopped being finite, exploded or the solver
    /// broke down (`health::diagnose` names the vertex).
    #[error("simulation diverged at step {step}, vertex {vertex}: {reason}")]
    Diverged {
        step: u64,
        vertex: u32,
        reason: String,
    },
}

impl Error {
    pub fn config(field: impl Into<String>, reason: impl Into<String>) -> Self {
        Error::Config {
            field: field.into(),
            reason: reason.into(),
        }
    }

    pub fn file(path: impl Into<PathBuf>, reason: impl Into<String>) -> Self {
        Error::File {
            path: path.into(),
            reason: reason.into(),
        }
    }

    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io {
            path: path.into(),
            source,
        }
    }
}

pub type Result<T, E = Error> = std::result::Result<T, E>;
