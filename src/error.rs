//! One error type for the whole toolchain.
//!
//! Every error a user can meet says three things on one line: the file it concerns, what is
//! wrong with it, and how to fix it. `blendsim` prints it as
//! `error: FILE: PROBLEM (fix: FIX)` and exits with code 1.

use std::fmt;
use std::path::{Path, PathBuf};

/// The result of every fallible operation of the toolchain.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// A problem a user can fix: the file, what is wrong, and the fix (see the module documentation).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Error {
    /// The file the problem is in (input, output, or external program), when there is one.
    pub path: Option<PathBuf>,
    /// What is wrong, in the user's terms.
    pub problem: String,
    /// What the user can do about it.
    pub fix: String,
}

impl Error {
    /// A problem with a specific file.
    pub fn in_file(path: impl AsRef<Path>, problem: impl Into<String>, fix: impl Into<String>) -> Self {
        Error { path: Some(path.as_ref().to_path_buf()), problem: problem.into(), fix: fix.into() }
    }

    /// A problem that concerns no single file (for example an external program that is missing).
    pub fn general(problem: impl Into<String>, fix: impl Into<String>) -> Self {
        Error { path: None, problem: problem.into(), fix: fix.into() }
    }

    /// An I/O failure while `doing` something with `path`, with a fix chosen from the error kind.
    pub fn io(path: impl AsRef<Path>, err: &std::io::Error, doing: &str) -> Self {
        use std::io::ErrorKind::*;
        let fix = match err.kind() {
            NotFound => "check the path; relative paths in a scene file resolve against the scene file's folder",
            PermissionDenied => "check the file and folder permissions",
            AlreadyExists => "remove the existing file or choose another output path",
            InvalidData | UnexpectedEof => "the file is damaged or not of the expected format; re-export it",
            _ => "check the path and that the disk is not full",
        };
        Error::in_file(path, format!("cannot {doing}: {err}"), fix)
    }

    /// Attach a file to an error that has none (used when a reader does not know its own path).
    pub fn with_path(mut self, path: impl AsRef<Path>) -> Self {
        if self.path.is_none() {
            self.path = Some(path.as_ref().to_path_buf());
        }
        self
    }
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if let Some(path) = &self.path {
            write!(f, "{}: ", path.display())?;
        }
        // One line, always: newlines from external tools' messages are folded.
        let problem = self.problem.replace('\n', " ");
        write!(f, "{problem} (fix: {})", self.fix.replace('\n', " "))
    }
}

impl std::error::Error for Error {}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn display_is_one_line_with_file_problem_and_fix() {
        let e = Error::in_file("a/k1.obj", "has 26 vertices\nbut k0 has 24", "re-export k1.obj");
        assert_eq!(e.to_string(), "a/k1.obj: has 26 vertices but k0 has 24 (fix: re-export k1.obj)");
        let g = Error::general("tetgen is not installed", "apt-get install tetgen");
        assert_eq!(g.to_string(), "tetgen is not installed (fix: apt-get install tetgen)");
    }

    #[test]
    fn io_error_names_the_file() {
        let err = std::io::Error::new(std::io::ErrorKind::NotFound, "No such file or directory");
        let e = Error::io("missing.obj", &err, "read the keyframe mesh");
        let s = e.to_string();
        assert!(s.starts_with("missing.obj: cannot read the keyframe mesh"), "{s}");
        assert!(s.contains("fix: check the path"), "{s}");
    }
}
