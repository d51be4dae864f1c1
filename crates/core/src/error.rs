//! One error type for the library, with the offending file and an absolute location.
//!
//! Every message a user can cause names the file, what is wrong and where:
//! `scan.ply: element 1203877 (byte 48213004): x is NaN`.

use std::fmt;
use std::path::{Path, PathBuf};

/// Where in a file something went wrong, counted from the start of the file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum Location {
    /// Nowhere in particular (the whole file).
    File,
    /// A byte offset.
    Byte(u64),
    /// A 1-based line number.
    Line(u64),
    /// A 0-based element (point) index and the byte it starts at.
    Element {
        /// 0-based index of the element among the points of the file.
        index: u64,
        /// Byte offset where the element starts.
        byte: u64,
    },
    /// A 0-based element index and its 1-based line (text formats).
    ElementLine {
        /// 0-based index of the element among the points of the file.
        index: u64,
        /// 1-based line number.
        line: u64,
    },
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Location::File => write!(f, "file"),
            Location::Byte(b) => write!(f, "byte {b}"),
            Location::Line(l) => write!(f, "line {l}"),
            Location::Element { index, byte } => write!(f, "element {index} (byte {byte})"),
            Location::ElementLine { index, line } => write!(f, "element {index} (line {line})"),
        }
    }
}

/// Errors of the scanflow library.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// An operating-system error on a file.
    #[error("{}: {err}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error (in the message, so not chained again).
        err: std::io::Error,
    },
    /// Malformed content at a known place in a file.
    #[error("{}: {location}: {msg}", path.display())]
    Format {
        /// The file.
        path: PathBuf,
        /// Where.
        location: Location,
        /// What was expected and what was found.
        msg: String,
    },
    /// A whole-file problem (unsupported format, nothing to read, inconsistent options).
    #[error("{}: {msg}", path.display())]
    Input {
        /// The file or directory.
        path: PathBuf,
        /// What is wrong.
        msg: String,
    },
    /// A bad option value.
    #[error("{0}")]
    Usage(String),
    /// A worker thread died; a bug, reported instead of a panic.
    #[error("internal error: {0}")]
    Internal(String),
}

/// Result alias for the library.
pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    /// An I/O error on `path`.
    pub fn io(path: impl AsRef<Path>, source: std::io::Error) -> Error {
        Error::Io {
            path: path.as_ref().to_path_buf(),
            err: source,
        }
    }

    /// A format error at `location` in `path`.
    pub fn format(path: impl AsRef<Path>, location: Location, msg: impl Into<String>) -> Error {
        Error::Format {
            path: path.as_ref().to_path_buf(),
            location,
            msg: msg.into(),
        }
    }

    /// A whole-file error on `path`.
    pub fn input(path: impl AsRef<Path>, msg: impl Into<String>) -> Error {
        Error::Input {
            path: path.as_ref().to_path_buf(),
            msg: msg.into(),
        }
    }
}

/// Attach a path to `std::io::Result`s.
pub trait IoContext<T> {
    /// Map the error to [`Error::Io`] naming `path`.
    fn with_path(self, path: impl AsRef<Path>) -> Result<T>;
}

impl<T> IoContext<T> for std::io::Result<T> {
    fn with_path(self, path: impl AsRef<Path>) -> Result<T> {
        self.map_err(|e| Error::io(path, e))
    }
}
