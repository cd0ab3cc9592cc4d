//! One error type for the whole toolchain.
//!
//! Every error a user can meet says three things on one line: the file it concerns, what is
//! wrong with it, and how to fix it. `blendsim` prints it as
//! `error: FILE: PROBLEM (fix: FIX)` and exits with code 1; warnings refused by `--strict`
//! are printed one line each and exit with code 3.

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
    /// The warnings `--strict` turned into this error (one line each; the CLI exits with
    /// code 3); empty for every other error.
    pub refused: Vec<String>,
}

impl Error {
    /// A problem with a specific file.
    pub fn in_file(path: impl AsRef<Path>, problem: impl Into<String>, fix: impl Into<String>) -> Self {
        Error { path: Some(path.as_ref().to_path_buf()), problem: problem.into(), fix: fix.into(), refused: Vec::new() }
    }

    /// A problem that concerns no single file (for example an external program that is missing).
    pub fn general(problem: impl Into<String>, fix: impl Into<String>) -> Self {
        Error { path: None, problem: problem.into(), fix: fix.into(), refused: Vec::new() }
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

    /// `--strict`: the `warnings` of a run, refused (none is written, the CLI exits with code 3).
    pub fn refused(warnings: &[String]) -> Self {
        let mut e = Error::general(
            format!("--strict: {} warnings", warnings.len()),
            "fix what each warning says, or run without --strict to accept the result",
        );
        e.refused = warnings.to_vec();
        e
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
        // One line, always, and nothing a terminal would act on: control characters in paths
        // are shown escaped, and line breaks in the problem (external tools' messages) folded.
        if let Some(path) = &self.path {
            write!(f, "{}: ", excerpt(&printable(&path.display().to_string()), MAX_PART))?;
        }
        write!(f, "{} (fix: {})", excerpt(&folded(&self.problem), MAX_PART), excerpt(&folded(&self.fix), MAX_PART))
    }
}

/// The longest path, problem or fix a message shows (longer ones are elided in the middle).
const MAX_PART: usize = 2000;
/// The longest token [`quoted`] shows.
const MAX_TOKEN: usize = 40;

/// Characters a terminal may act on or that break a line: C0 and C1 controls (newline, CR,
/// ESC, ...), DEL, the Unicode line and paragraph separators, and bidirectional overrides.
fn is_unsafe(c: char) -> bool {
    c.is_control() || matches!(c, '\u{2028}' | '\u{2029}' | '\u{202a}'..='\u{202e}' | '\u{2066}'..='\u{2069}')
}

/// `text` with every unsafe character shown as an escape (`\n`, `\r`, `\u{1b}`), so it
/// prints on one line and cannot drive the terminal. For paths and tokens from input files.
pub fn printable(text: &str) -> String {
    if !text.chars().any(is_unsafe) {
        return text.to_string();
    }
    text.chars().map(|c| if is_unsafe(c) { c.escape_default().to_string() } else { c.to_string() }).collect()
}

/// Line breaks and tabs as spaces (messages of external tools span lines), other unsafe
/// characters escaped.
fn folded(text: &str) -> String {
    printable(&text.replace("\r\n", " ").replace(['\n', '\r', '\t'], " "))
}

/// At most `max` characters of `text`: longer text keeps its head and tail around a note of
/// how much was left out.
fn excerpt(text: &str, max: usize) -> String {
    let count = text.chars().count();
    if count <= max {
        return text.to_string();
    }
    let keep = max / 2;
    let head: String = text.chars().take(keep).collect();
    let tail: String = text.chars().skip(count - keep / 2).collect();
    format!("{head}...[{} characters left out]...{tail}", count - keep - keep / 2)
}

/// A token from an input file as [`quoted`] shows it, without the backquotes.
pub fn short(token: &str) -> String {
    let q = quoted(token);
    match q.strip_prefix('`').and_then(|r| r.split_once('`')) {
        Some((inner, rest)) => format!("{inner}{rest}"),
        None => q,
    }
}

/// A token from an input file, for a message: in backquotes, unsafe characters escaped, and at
/// most a short excerpt of a long token with its length (a 200 MB token is not echoed).
pub fn quoted(token: &str) -> String {
    let count = token.chars().count();
    if count <= MAX_TOKEN {
        return format!("`{}`", printable(token));
    }
    let head: String = token.chars().take(MAX_TOKEN - 8).collect();
    format!("`{}...` ({} bytes)", printable(&head), token.len())
}

/// A number a user gave, for a message: in decimal from 1e-4 to 1e7 (`0.5`, `70`, `-1`),
/// in exponent form beyond (`1e300`, `1e-300`, `1.5e-7`), so a message never echoes 300
/// digits. Always the shortest text that reads back as the same number.
pub fn number(x: f64) -> String {
    if x.is_finite() && x != 0.0 && !(1e-4..1e7).contains(&x.abs()) {
        format!("{x:e}")
    } else {
        format!("{x}")
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
    fn control_characters_are_folded_and_long_text_elided() {
        let e = Error::in_file("out\n\u{1b}[2J/k\r.obj", "TetGen said:\nline one\r\nline two\u{7}", "re-export\u{202e}");
        let s = e.to_string();
        assert_eq!(s, "out\\n\\u{1b}[2J/k\\r.obj: TetGen said: line one line two\\u{7} (fix: re-export\\u{202e})");
        assert!(!s.chars().any(is_unsafe));
        let long = "x".repeat(10_000);
        let s = Error::general(format!("bad {long}"), "fix").to_string();
        assert!(s.len() < 2 * MAX_PART && s.contains("characters left out") && s.ends_with("(fix: fix)"), "{}", s.len());
        assert_eq!(quoted("1.5e3"), "`1.5e3`");
        let q = quoted(&"9".repeat(200_000_000 / 1000));
        assert_eq!(q, format!("`{}...` (200000 bytes)", "9".repeat(MAX_TOKEN - 8)));
        assert_eq!(quoted("a\u{1b}b"), "`a\\u{1b}b`");
    }

    #[test]
    fn numbers_are_short() {
        let cases = [
            (1e300, "1e300"),
            (1e-300, "1e-300"),
            (-1e300, "-1e300"),
            (0.5, "0.5"),
            (70.0, "70"),
            (-1.0, "-1"),
            (0.0, "0"),
            (1e6, "1000000"),
            (1e7, "1e7"),
            (123456789.0, "1.23456789e8"),
            (1.5e-7, "1.5e-7"),
            (f64::NAN, "NaN"),
        ];
        for (x, text) in cases {
            assert_eq!(number(x), text);
            assert!(x.is_nan() || text.parse::<f64>() == Ok(x), "{text} reads back");
        }
        assert_eq!(number(f64::MAX), "1.7976931348623157e308");
        assert_eq!(number(f64::INFINITY), "inf");
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
