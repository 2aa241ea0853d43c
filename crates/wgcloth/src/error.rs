//! One error type for the library: every failure names what is wrong
//! (the field, the file, the vertex) in one line, and the CLI maps it to
//! exit code 2.

use std::path::PathBuf;

/// Everything that can fail in the library, each naming its cause.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A configuration value out of its range (CLI flag or TOML field).
    #[error("invalid `{field}`: {reason}")]
    Config {
        /// The dotted config name (`cloth.mass`) or the flag (`--size`).
        field: String,
        /// What is wrong with its value.
        reason: String,
    },

    /// A file that could not be read or written.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying I/O error.
        #[source]
        source: std::io::Error,
    },

    /// A file that was read but whose content is wrong.
    #[error("{}: {reason}", path.display())]
    File {
        /// The file.
        path: PathBuf,
        /// What is wrong with its content.
        reason: String,
    },

    /// A request the current build cannot honour.
    #[error("{0}")]
    Unsupported(String),

    /// No usable GPU adapter, a device that could not be created or was
    /// lost, or a scene beyond the adapter's limits.
    #[error("GPU: {0}")]
    Gpu(String),

    /// A scene the device cannot run: what needs more than one of the
    /// device's limits allows (a smaller cloth grid fits).
    #[error("GPU: the scene's {what} need {needed}; the device's {limit} is {device}")]
    Limit {
        /// What the scene needs it for ("topology", "contacts", …).
        what: String,
        /// The `wgpu::Limits` field.
        limit: &'static str,
        /// What the scene needs, with its unit.
        needed: String,
        /// The device's value of the limit, with its unit.
        device: String,
    },

    /// The simulation state stopped being finite, exploded or the solver
    /// broke down (`health::diagnose` names the vertex).
    #[error("simulation diverged at step {step}, vertex {vertex}: {reason}")]
    Diverged {
        /// The failing step.
        step: u64,
        /// The vertex where the failure starts.
        vertex: u32,
        /// What went wrong there.
        reason: String,
    },
}

impl Error {
    /// An invalid configuration value, named by its dotted field or flag.
    pub fn config(field: impl Into<String>, reason: impl Into<String>) -> Self {
        Error::Config {
            field: field.into(),
            reason: reason.into(),
        }
    }

    /// A file whose content is wrong.
    pub fn file(path: impl Into<PathBuf>, reason: impl Into<String>) -> Self {
        Error::File {
            path: path.into(),
            reason: reason.into(),
        }
    }

    /// A file that could not be read or written.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io {
            path: path.into(),
            source,
        }
    }
}

/// The library's result type, failing with [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;
