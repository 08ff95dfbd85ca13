//! The crate's error type. Every error about an input names the file, and the line and
//! column where there is one, so a user can find what to fix.

use std::fmt;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// A place in an input file.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Location {
    pub file: Arc<PathBuf>,
    pub line: Option<u32>,
    pub col: Option<u32>,
}

impl Location {
    pub fn file(file: &Path) -> Location {
        Location { file: Arc::new(file.to_path_buf()), line: None, col: None }
    }
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.file.display())?;
        if let Some(l) = self.line {
            write!(f, ":{l}")?;
            if let Some(c) = self.col {
                write!(f, ":{c}")?;
            }
        }
        Ok(())
    }
}

#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A problem with an input file, at a location.
    #[error("{loc}: {msg}")]
    Input { loc: Location, msg: String },
    #[error(transparent)]
    Accel(#[from] crate::accel::AccelError),
    /// A bad option or argument.
    #[error("{0}")]
    Usage(String),
    /// An I/O failure while writing output.
    #[error("{path}: {msg}")]
    Output { path: PathBuf, msg: String },
}

impl Error {
    pub fn input(loc: &Location, msg: impl Into<String>) -> Error {
        Error::Input { loc: loc.clone(), msg: msg.into() }
    }

    pub fn in_file(file: &Path, msg: impl Into<String>) -> Error {
        Error::Input { loc: Location::file(file), msg: msg.into() }
    }
}

pub type Result<T, E = Error> = std::result::Result<T, E>;
