//! Typed errors of the core. Every error that comes from user input names the
//! file (or the source) and the problem, so the CLI and the page can show it as is.

use thiserror::Error;

#[derive(Debug, Error)]
pub enum Error {
    /// A user-supplied file (PLY, JSON, ...) is unusable. `file` is its name as the user gave it.
    #[error("{file}: {problem}")]
    Input { file: String, problem: String },
    /// Reading or writing a file failed at the OS level.
    #[error("{file}: {source}")]
    Io {
        file: String,
        #[source]
        source: std::io::Error,
    },
    /// A sequence as a whole is unusable (a single frame, mismatched ground truth, ...).
    #[error("sequence: {0}")]
    Sequence(String),
    /// Options or arguments that cannot be honoured.
    #[error("invalid argument: {0}")]
    InvalidArgument(String),
    /// The caller cancelled a running job.
    #[error("cancelled")]
    Cancelled,
}

impl Error {
    pub fn input(file: impl Into<String>, problem: impl Into<String>) -> Self {
        Error::Input {
            file: file.into(),
            problem: problem.into(),
        }
    }
    pub fn io(file: impl Into<String>, source: std::io::Error) -> Self {
        Error::Io {
            file: file.into(),
            source,
        }
    }
}

pub type Result<T, E = Error> = std::result::Result<T, E>;
