//! Errors carrying the command line's exit-code contract: bad input exits with 2, any other
//! failure with 1. Every message names the file, the element and the reason on one line.

use std::fmt;
use std::path::Path;

/// What kind of failure an [`Error`] is; decides the exit code.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ErrorKind {
    /// The input (scene, image, option) is malformed or unsupported: exit code 2.
    BadInput,
    /// Anything else (I/O on output, internal failures): exit code 1.
    Other,
}

/// An error with its location: `file: element: reason`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Error {
    pub kind: ErrorKind,
    pub file: String,
    pub element: String,
    pub reason: String,
}

/// Result with lucerna's [`Error`].
pub type Result<T> = std::result::Result<T, Error>;

impl Error {
    /// Bad input in `file` at `element` (e.g. `meshes[2].primitives[0]`).
    pub fn bad_input(
        file: impl AsRef<Path>,
        element: impl Into<String>,
        reason: impl Into<String>,
    ) -> Self {
        Self {
            kind: ErrorKind::BadInput,
            file: file.as_ref().display().to_string(),
            element: element.into(),
            reason: reason.into(),
        }
    }

    /// A failure that is not the input's fault (e.g. the output cannot be written).
    pub fn other(
        file: impl AsRef<Path>,
        element: impl Into<String>,
        reason: impl Into<String>,
    ) -> Self {
        Self {
            kind: ErrorKind::Other,
            ..Self::bad_input(file, element, reason)
        }
    }

    /// Process exit code for this error: 2 for bad input, 1 otherwise.
    pub fn exit_code(&self) -> i32 {
        match self.kind {
            ErrorKind::BadInput => 2,
            ErrorKind::Other => 1,
        }
    }
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let parts = [&self.file, &self.element, &self.reason];
        let mut first = true;
        for part in parts.into_iter().filter(|p| !p.is_empty()) {
            if !first {
                f.write_str(": ")?;
            }
            // One line, always: a reason taken from a parser may contain newlines.
            f.write_str(&part.replace('\n', " "))?;
            first = false;
        }
        Ok(())
    }
}

impl std::error::Error for Error {}
