//! Vertex selection files: which vertices of a keyframe mesh a scene holds or frees.
//!
//! - `.dmat` (libigl ASCII): a header `cols rows` (`1 N` for N vertices), then one value per
//!   line, each exactly 0 or 1 (written as any number: `1`, `1.0`, `1e0`); anything else
//!   (0.5, 2, -1, nan) is an error, not "selected".
//! - any other extension: 0-based vertex indices, one per line; `#` starts a comment.
//!
//! Indices refer to the vertex order of the mesh file, which the readers keep. A UTF-8 byte
//! order mark is accepted. Errors name the line and quote at most a short excerpt of the bad
//! token.

use std::path::Path;

use crate::support::error::{quoted, Error, Result};

/// Read a selection file for a mesh of `n` vertices: `mask[v]` is whether vertex `v` is
/// selected. The format follows the extension (see the module documentation).
pub fn read(path: &Path, n: usize) -> Result<Vec<bool>> {
    let text = crate::support::input::read_text(path, "the vertex selection")?;
    let is_dmat = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("dmat"));
    let parsed = if is_dmat { parse_dmat(&text, n) } else { parse_indices(&text, n) };
    parsed.map_err(|e| e.with_path(path))
}

/// Parse a libigl ASCII `.dmat` column of 0/1 flags for `n` vertices. Errors carry no path.
pub(crate) fn parse_dmat(text: &str, n: usize) -> Result<Vec<bool>> {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut lines = text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty());
    let header = lines.next().map(|(_, l)| l.split_whitespace().map(str::parse::<usize>).collect::<Vec<_>>());
    match header.as_deref() {
        Some([Ok(1), Ok(rows)]) if *rows == n => {}
        Some([Ok(cols), Ok(rows)]) => {
            return Err(Error::general(
                format!("is a {rows}x{cols} matrix but the mesh has {n} vertices"),
                format!("give one 0/1 value per vertex: a header \"1 {n}\" and {n} values"),
            ))
        }
        _ => return Err(Error::general("has no \"cols rows\" header", "write libigl's ASCII .dmat: \"1 N\", then one value per line")),
    }
    let mut mask = Vec::with_capacity(n);
    for (line, value) in lines.map(|(i, l)| (i + 1, l.trim())) {
        if mask.len() == n {
            return Err(Error::general(format!("line {line}: more values than the {n} of the header"), "give one value per vertex"));
        }
        let x: f64 =
            value.parse().map_err(|_| Error::general(format!("line {line}: {} is not a number", quoted(value)), "write 0 or 1 per vertex"))?;
        if x != 0.0 && x != 1.0 {
            return Err(Error::general(
                format!("line {line}: value {} is neither 0 nor 1", quoted(value)),
                "write 1 for a selected vertex and 0 for the others",
            ));
        }
        mask.push(x == 1.0);
    }
    if mask.len() != n {
        return Err(Error::general(format!("has {} values for {n} vertices", mask.len()), "give one value per vertex"));
    }
    Ok(mask)
}

/// Parse a list of 0-based vertex indices for `n` vertices. Errors carry no path.
pub(crate) fn parse_indices(text: &str, n: usize) -> Result<Vec<bool>> {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut mask = vec![false; n];
    for (i, line) in text.lines().enumerate() {
        let content = line.split('#').next().unwrap_or("").trim();
        if content.is_empty() {
            continue;
        }
        let index: usize = content.parse().map_err(|_| {
            Error::general(format!("line {}: {} is not a vertex index", i + 1, quoted(content)), "write one 0-based vertex index per line")
        })?;
        if index >= n {
            return Err(Error::general(
                format!("line {}: vertex {index} does not exist (the mesh has {n} vertices, indexed from 0)", i + 1),
                "use indices of the keyframe mesh this scene reads",
            ));
        }
        mask[index] = true;
    }
    Ok(mask)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn err(r: Result<Vec<bool>>) -> String {
        let s = r.expect_err("must fail").with_path("sel").to_string();
        assert!(s.starts_with("sel: ") && s.contains(" (fix: ") && !s.contains('\n'), "{s}");
        s
    }

    #[test]
    fn dmat_holds_exactly_zero_or_one_per_vertex() {
        assert_eq!(parse_dmat("1 3\n1\n0\n1.0\n", 3).unwrap(), [true, false, true]);
        assert_eq!(parse_dmat("\u{feff}1 2\r\n0\r\n1e0\r\n", 2).unwrap(), [false, true]);
        for bad in ["0.5", "2", "-1", "nan", "inf"] {
            let s = err(parse_dmat(&format!("1 2\n0\n{bad}\n"), 2));
            assert!(s.contains(&format!("line 3: value `{bad}` is neither 0 nor 1")), "{s}");
        }
        assert!(err(parse_dmat("1 2\n0\nyes\n", 2)).contains("line 3: `yes` is not a number"));
        assert!(err(parse_dmat("1 2\n0\n", 2)).contains("has 1 values for 2 vertices"));
        assert!(err(parse_dmat("1 2\n0\n1\n1\n", 2)).contains("line 4: more values than the 2"));
        assert!(err(parse_dmat("2 2\n0\n1\n", 2)).contains("is a 2x2 matrix"));
        assert!(err(parse_dmat("", 2)).contains("has no \"cols rows\" header"));
    }

    #[test]
    fn index_lists_name_the_line() {
        assert_eq!(parse_indices("\u{feff}# ends\n0\n\n2 # last\n", 3).unwrap(), [true, false, true]);
        assert!(err(parse_indices("0\n3\n", 3)).contains("line 2: vertex 3 does not exist"));
        assert!(err(parse_indices("-1\n", 3)).contains("line 1: `-1` is not a vertex index"));
        let long = "7".repeat(1_000_000);
        let s = err(parse_indices(&long, 3));
        assert!(s.contains("(1000000 bytes) is not a vertex index") && s.len() < 300, "{}", s.len());
    }

    fn file(dir: &tempfile::TempDir, name: &str, text: &str) -> std::path::PathBuf {
        let path = dir.path().join(name);
        std::fs::write(&path, text).unwrap();
        path
    }

    #[test]
    fn index_files_list_vertices_with_comments() {
        let dir = tempfile::tempdir().unwrap();
        let path = file(&dir, "ends.txt", "# the ends\n0\n3  # top\n\n2\n");
        assert_eq!(read(&path, 5).unwrap(), [true, false, true, true, false]);
        let e = read(&file(&dir, "far.txt", "1\n5\n"), 5).unwrap_err().to_string();
        assert!(e.contains("line 2: vertex 5 does not exist (the mesh has 5 vertices, indexed from 0)"), "{e}");
        let e = read(&file(&dir, "word.txt", "one\n"), 5).unwrap_err().to_string();
        assert!(e.contains("line 1: `one` is not a vertex index"), "{e}");
    }

    #[test]
    fn dmat_files_flag_every_vertex() {
        let dir = tempfile::tempdir().unwrap();
        let path = file(&dir, "tail.dmat", "1 4\n0\n1\n0.0\n1.0\n");
        assert_eq!(read(&path, 4).unwrap(), [false, true, false, true]);
        let e = read(&file(&dir, "short.dmat", "1 4\n0\n1\n"), 4).unwrap_err().to_string();
        assert!(e.contains("has 2 values for 4 vertices"), "{e}");
        let e = read(&file(&dir, "wide.dmat", "3 4\n"), 4).unwrap_err().to_string();
        assert!(e.contains("is a 4x3 matrix but the mesh has 4 vertices"), "{e}");
        let e = read(&file(&dir, "bare.dmat", "0\n1\n"), 2).unwrap_err().to_string();
        assert!(e.contains("has no \"cols rows\" header"), "{e}");
    }
}
