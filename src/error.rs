//! The library's error type. Variants that describe bad input (a file, a cell, a flag) map to
//! exit status 2 in the binary; the rest are failures of the computation or the machine (exit
//! status 3).

use std::path::PathBuf;

/// Everything that can go wrong in bitrock.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// An input file cannot be opened or read.
    #[error("{}: cannot read: {source}", path.display())]
    Read { path: PathBuf, source: std::io::Error },
    /// A CSV cell holds something that is not a finite number.
    #[error("{}:{line}:{column}: column '{name}': {message}", path.display())]
    Cell {
        path: PathBuf,
        line: u64,
        column: usize,
        name: String,
        message: String,
    },
    /// A file is malformed as a whole or at a line (ragged rows, missing header, missing column).
    #[error("{}{}: {message}", path.display(), line.map(|l| format!(":{l}")).unwrap_or_default())]
    Format {
        path: PathBuf,
        line: Option<u64>,
        message: String,
    },
    /// A text file (a law file) is wrong at a line and column.
    #[error("{}:{line}:{column}: {message}", path.display())]
    Syntax {
        path: PathBuf,
        line: u64,
        column: usize,
        message: String,
    },
    /// The data read fine but cannot be used (empty after filtering, all-zero torque...).
    #[error("{}: {message}", path.display())]
    Data { path: PathBuf, message: String },
    /// A law's least-squares fit fails on the samples given (too few of them or of distinct
    /// speeds, no finite starting point, the optimiser diverging from every start): the record
    /// is at fault. `record` names it where known ([`crate::fit::fit_record`] attaches it).
    #[error("{}{law}: least-squares fit: {message}", record.as_ref().map(|p| format!("{}: ", p.display())).unwrap_or_default())]
    Fit {
        record: Option<PathBuf>,
        law: String,
        message: String,
    },
    /// A configuration value is refused. `field` names the setting as the library's
    /// configuration does (`particles`, `min_speed_rpm`); the command line shows its flag.
    #[error("`{field}`: {message}")]
    InvalidSetting { field: String, message: String },
    /// An output file cannot be written.
    #[error("{}: cannot write: {source}", path.display())]
    Write { path: PathBuf, source: std::io::Error },
    /// An output the user named by the setting `field` cannot be written (a missing directory, no
    /// permission: bad input; a full disk: a failure of the machine).
    #[error("`{field}`: {}: cannot write: {source}", path.display())]
    Output {
        field: String,
        path: PathBuf,
        source: std::io::Error,
    },
    /// A run directory is being written by another process (one writer per run directory).
    #[error("{}: in use by {holder}; one bitrock at a time writes a run directory", path.display())]
    Busy { path: PathBuf, holder: String },
    /// The GPU backend failed (no adapter, device lost, out of memory...). The GPU module's
    /// own error (`eval::gpu::GpuError`) converts into it, so that this bottom layer does not
    /// depend on the GPU module.
    #[error(transparent)]
    Gpu(Box<dyn std::error::Error + Send + Sync + 'static>),
    /// A store (SQLite: a run's or a watch's) failed or holds something it should not.
    #[error("{}: {message}", path.display())]
    Store { path: PathBuf, message: String },
    /// A run stopped (a draw or wall-time budget) before the population asked for was
    /// complete.
    #[error("{0}")]
    Incomplete(String),
    /// A numerical procedure failed where it should not have.
    #[error("numerical failure: {0}")]
    Numerical(String),
    /// A worker of a distributed run failed, or answered something the run did not ask for.
    #[error("worker: {0}")]
    Worker(String),
    /// A figure could not be drawn (the plotting library refused it or the embedded font is
    /// unreadable): a failure of the program, not of the user's input.
    #[error("figure {figure}: {message}")]
    Plot { figure: String, message: String },
    /// The run's observer asked it to stop (Ctrl-C in Python): the populations completed
    /// before are kept, and a run directory can be continued.
    #[error("interrupted; the completed populations are kept")]
    Interrupted,
}

impl Error {
    /// A refused setting as `field: message`, any other error as it reads: how a file's refusal
    /// names the key it points at.
    pub fn keyed(self) -> String {
        match self {
            Error::InvalidSetting { field, message } => format!("{field}: {message}"),
            other => other.to_string(),
        }
    }

    /// Shorthand for [`Error::InvalidSetting`].
    pub fn setting(field: impl Into<String>, message: impl Into<String>) -> Self {
        Error::InvalidSetting {
            field: field.into(),
            message: message.into(),
        }
    }

    /// Shorthand for [`Error::Output`].
    pub fn output(field: &str, path: &std::path::Path, source: std::io::Error) -> Self {
        Error::Output {
            field: field.to_string(),
            path: path.to_path_buf(),
            source,
        }
    }

    /// True when the user's input is at fault (exit status 2), false for failures of the
    /// computation or of the machine (exit status 3).
    pub fn is_bad_input(&self) -> bool {
        match self {
            Error::Read { .. }
            | Error::Cell { .. }
            | Error::Format { .. }
            | Error::Syntax { .. }
            | Error::Data { .. }
            | Error::Fit { .. }
            | Error::InvalidSetting { .. }
            | Error::Busy { .. } => true,
            Error::Output { source, .. } => is_bad_target(source),
            // A refused GPU setting converts into InvalidSetting (eval::gpu).
            _ => false,
        }
    }
}

/// True when writing failed because of the target the user gave (missing, not a directory, no
/// permission), not because the machine failed (a full disk, an I/O error).
fn is_bad_target(e: &std::io::Error) -> bool {
    use std::io::ErrorKind::*;
    matches!(
        e.kind(),
        NotFound | PermissionDenied | AlreadyExists | NotADirectory | IsADirectory | ReadOnlyFilesystem | InvalidInput
    )
}

/// Result with the library's [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;
