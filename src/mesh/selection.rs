//! Vertex selection files: which vertices of a mesh a keyframe holds.
//!
//! - `.dmat` (libigl ASCII): a header `cols rows` (`1 N` for N vertices), then one value per
//!   line; nonzero selects the vertex.
//! - any other extension: 0-based vertex indices, one per line (`#` starts a comment).
//!
//! Indices refer to the vertex order of the mesh file, which the readers keep.

use std::path::Path;

use crate::error::{Error, Result};

/// The vertices a selection file marks, as a mask over `n` vertices: a `.dmat` column of 0/1
/// flags, or any other file as a list of 0-based indices (see the module documentation).
pub fn read(path: &Path, n: usize) -> Result<Vec<bool>> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, &e, "read the vertex selection"))?;
    let is_dmat = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("dmat"));
    let mut mask = vec![false; n];
    if is_dmat {
        let mut lines = text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty());
        let header = lines.next().map(|(_, l)| l.split_whitespace().map(str::parse::<usize>).collect::<Vec<_>>());
        match header.as_deref() {
            Some([Ok(1), Ok(rows)]) if *rows == n => {}
            Some([Ok(cols), Ok(rows)]) => {
                return Err(Error::in_file(
                    path,
                    format!("is a {rows}x{cols} matrix but the mesh has {n} vertices"),
                    format!("give one 0/1 value per vertex: a header \"1 {n}\" and {n} values"),
                ))
            }
            _ => return Err(Error::in_file(path, "has no \"cols rows\" header", "write libigl's ASCII .dmat: \"1 N\", then one value per line")),
        }
        let values: Vec<(usize, &str)> = lines.map(|(i, l)| (i, l.trim())).collect();
        if values.len() != n {
            return Err(Error::in_file(path, format!("has {} values for {n} vertices", values.len()), "give one value per vertex"));
        }
        for (v, (line, value)) in values.iter().enumerate() {
            let x: f64 = value.parse().map_err(|_| {
                Error::in_file(path, format!("line {}: {value:?} is not a number", line + 1), "write 0 or 1 per vertex")
            })?;
            mask[v] = x != 0.0;
        }
    } else {
        for (i, line) in text.lines().enumerate() {
            let content = line.split('#').next().unwrap_or("").trim();
            if content.is_empty() {
                continue;
            }
            let index: usize = content.parse().map_err(|_| {
                Error::in_file(path, format!("line {}: {content:?} is not a vertex index", i + 1), "write one 0-based vertex index per line")
            })?;
            if index >= n {
                return Err(Error::in_file(
                    path,
                    format!("line {}: vertex {index} does not exist (the mesh has {n} vertices, indexed from 0)", i + 1),
                    "use indices of the keyframe mesh this scene reads",
                ));
            }
            mask[index] = true;
        }
    }
    Ok(mask)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn file(name: &str, text: &str) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("blendsim-selection-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join(name);
        std::fs::write(&path, text).unwrap();
        path
    }

    #[test]
    fn index_files_list_vertices_with_comments() {
        let path = file("ends.txt", "# the ends\n0\n3  # top\n\n2\n");
        assert_eq!(read(&path, 5).unwrap(), [true, false, true, true, false]);
        let e = read(&file("far.txt", "1\n5\n"), 5).unwrap_err().to_string();
        assert!(e.contains("line 2: vertex 5 does not exist (the mesh has 5 vertices, indexed from 0)"), "{e}");
        let e = read(&file("word.txt", "one\n"), 5).unwrap_err().to_string();
        assert!(e.contains("line 1: \"one\" is not a vertex index"), "{e}");
    }

    #[test]
    fn dmat_files_flag_every_vertex() {
        let path = file("tail.dmat", "1 4\n0\n1\n0.0\n2\n");
        assert_eq!(read(&path, 4).unwrap(), [false, true, false, true]);
        let e = read(&file("short.dmat", "1 4\n0\n1\n"), 4).unwrap_err().to_string();
        assert!(e.contains("has 2 values for 4 vertices"), "{e}");
        let e = read(&file("wide.dmat", "3 4\n"), 4).unwrap_err().to_string();
        assert!(e.contains("is a 4x3 matrix but the mesh has 4 vertices"), "{e}");
        let e = read(&file("bare.dmat", "0\n1\n"), 2).unwrap_err().to_string();
        assert!(e.contains("has no \"cols rows\" header"), "{e}");
    }
}
