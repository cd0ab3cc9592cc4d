//! MEDIT ASCII `.mesh` tet meshes.
//!
//! Contract: `MeshVersionFormatted`, `Dimension 3`, `Vertices`, `Tetrahedra` blocks (others,
//! e.g. `Triangles`, `Edges`, `Corners`, are skipped), 1-based indices, each row ending with
//! a reference number; `End` optional. Every tet is oriented to positive volume on load.
//! Degenerate (zero-volume) tets and out-of-range indices are errors naming the block row.
//!
//! Rows are read one per line (as every writer emits them), so a wrong block count is caught
//! at the line where the next keyword appears instead of silently shifting every later value.
//! A block's count may follow its keyword on the same line or on the next; the reference
//! number may be missing. Skipped blocks are not validated: the `Triangles` of some files
//! (e.g. the paper's `spot.mesh`) list every face twice.

use std::path::Path;

use super::tetgen_io::{content_lines, first_flat_tet};
use super::{Point, TetMesh};
use crate::support::error::{quoted, Error, Result};

/// Read a MEDIT tet mesh; errors name the file and the line.
pub fn read(path: &Path) -> Result<TetMesh> {
    let text = crate::support::input::read_text(path, "the MEDIT tet mesh")?;
    parse(&text).map_err(|e| e.with_path(path))
}

/// A non-empty line without its comment: its 1-based number and its tokens.
type Line<'a> = (usize, Vec<&'a str>);

const REEXPORT: &str = "re-export the tet mesh from the tool that made it";

/// Parse MEDIT text (see the module contract). Errors carry no path.
pub fn parse(text: &str) -> Result<TetMesh> {
    let mut lines = content_lines(text);
    let mut positions: Option<Vec<Point>> = None;
    // Each tet row with its line and 1-based row number, checked once all blocks are read.
    let mut tet_rows: Option<Vec<([i64; 4], usize, usize)>> = None;
    while let Some((line_no, tokens)) = lines.next() {
        let keyword = tokens[0];
        if keyword == "End" {
            break;
        }
        if !is_keyword(keyword) {
            return Err(Error::general(
                format!("line {line_no}: expected a block keyword (Vertices, Tetrahedra, ...), found {}", quoted(keyword)),
                "the row count of the block above is too small; correct it or re-export the tet mesh",
            ));
        }
        let value = block_value(keyword, &tokens[1..], line_no, &mut lines)?;
        match keyword {
            "MeshVersionFormatted" => {}
            "Dimension" if value != 3 => {
                return Err(Error::general(
                    format!("line {line_no}: the mesh has dimension {value}, blendsim needs 3"),
                    "export a 3D tetrahedral mesh",
                ))
            }
            "Dimension" => {}
            "Vertices" | "Tetrahedra" => {
                let rows = block_rows(keyword, value, line_no, &mut lines)?;
                let duplicate = if keyword == "Vertices" {
                    positions.replace(rows.iter().enumerate().map(|(k, row)| vertex_row(row, k + 1)).collect::<Result<_>>()?).is_some()
                } else {
                    tet_rows.replace(rows.iter().enumerate().map(|(k, row)| tet_row(row, k + 1)).collect::<Result<_>>()?).is_some()
                };
                if duplicate {
                    return Err(Error::general(
                        format!("line {line_no}: a second `{keyword}` block"),
                        "merge the blocks into one, or split the file into one mesh per file",
                    ));
                }
            }
            _ => {
                block_rows(keyword, value, line_no, &mut lines)?;
            }
        }
    }

    let positions = positions.ok_or_else(|| Error::general("has no `Vertices` block", REEXPORT))?;
    let tet_rows = tet_rows.unwrap_or_default();
    if tet_rows.is_empty() {
        return Err(Error::general(
            "has no tetrahedra (no `Tetrahedra` rows): it is a surface mesh",
            "tetrahedralize it first (e.g. `tetgen -pg`), or give the surface as an OBJ file",
        ));
    }
    let vertex_count = positions.len();
    let mut tets = Vec::with_capacity(tet_rows.len());
    for (corners, line_no, row) in &tet_rows {
        let mut tet = [0u32; 4];
        for (slot, &v) in tet.iter_mut().zip(corners) {
            if v < 1 || v as usize > vertex_count {
                return Err(Error::general(
                    format!("line {line_no}: Tetrahedra row {row} refers to vertex {v}, but vertices are numbered 1 to {vertex_count}"),
                    REEXPORT,
                ));
            }
            *slot = (v - 1) as u32;
        }
        tets.push(tet);
    }
    let mut mesh = TetMesh { positions, tets };
    if let Some(t) = first_flat_tet(&mesh) {
        let (corners, line_no, row) = &tet_rows[t];
        let [a, b, c, d] = corners;
        return Err(Error::general(
            format!("line {line_no}: Tetrahedra row {row} (vertices {a} {b} {c} {d}) is flat: it has no volume"),
            "remove the degenerate tetrahedron or re-mesh the body (e.g. TetGen with -q)",
        ));
    }
    mesh.orient_positive();
    Ok(mesh)
}

/// A block keyword starts with a letter; `nan`, `inf` and `infinity` (any case) are values of
/// a row, so a NaN row is reported as a NaN, not as the end of its block.
fn is_keyword(token: &str) -> bool {
    token.starts_with(|c: char| c.is_ascii_alphabetic()) && token.parse::<f64>().is_err()
}

/// The number after a keyword: on the same line or alone on the next one.
fn block_value<'a>(keyword: &str, rest: &[&str], line_no: usize, lines: &mut impl Iterator<Item = Line<'a>>) -> Result<usize> {
    let (at, token) = match rest.first() {
        Some(token) => (line_no, token.to_string()),
        None => match lines.next() {
            Some((next_no, tokens)) => (next_no, tokens[0].to_string()),
            None => (line_no, "the end of the file".to_string()),
        },
    };
    token.parse().map_err(|_| {
        Error::general(
            format!("line {at}: {} must be followed by a count or value, found {}", quoted(keyword), quoted(&token)),
            "write the number of rows after each block keyword, as MEDIT files do",
        )
    })
}

/// The `count` rows of a block, one per line.
fn block_rows<'a>(keyword: &str, count: usize, line_no: usize, lines: &mut impl Iterator<Item = Line<'a>>) -> Result<Vec<Line<'a>>> {
    let mut rows = Vec::new();
    while rows.len() < count {
        let short = |found: String| {
            Error::general(
                format!("line {line_no}: {} declares {count} rows but only {} follow before {found}", quoted(keyword), rows.len()),
                format!("correct the count on line {line_no} or re-export the tet mesh"),
            )
        };
        match lines.next() {
            Some((_, tokens)) if is_keyword(tokens[0]) => return Err(short(quoted(tokens[0]))),
            Some(row) => rows.push(row),
            None => return Err(short("the end of the file".into())),
        }
    }
    Ok(rows)
}

fn vertex_row((line_no, tokens): &Line, row: usize) -> Result<Point> {
    if !(3..=4).contains(&tokens.len()) {
        return Err(Error::general(
            format!("line {line_no}: Vertices row {row} has {} values, expected `x y z ref`", tokens.len()),
            "blendsim reads 3D meshes only; check the Dimension and the block counts",
        ));
    }
    let mut p = [0.0; 3];
    for (slot, token) in p.iter_mut().zip(tokens) {
        *slot = token
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| Error::general(format!("line {line_no}: Vertices row {row}: {} is not a finite number", quoted(token)), REEXPORT))?;
    }
    Ok(p)
}

fn tet_row((line_no, tokens): &Line, row: usize) -> Result<([i64; 4], usize, usize)> {
    if !(4..=5).contains(&tokens.len()) {
        return Err(Error::general(
            format!("line {line_no}: Tetrahedra row {row} has {} values, expected `a b c d ref`", tokens.len()),
            "blendsim reads linear (4-node) tetrahedra; check the block counts",
        ));
    }
    let mut corners = [0i64; 4];
    for (slot, token) in corners.iter_mut().zip(tokens) {
        *slot = token
            .parse()
            .map_err(|_| Error::general(format!("line {line_no}: Tetrahedra row {row}: {} is not a vertex number", quoted(token)), REEXPORT))?;
    }
    Ok((corners, *line_no, row))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::algorithms::geometry::Bounds;
    use crate::support::testing::paper_asset;

    const TWO_TETS: &str = "\
MeshVersionFormatted 1
# a comment
Dimension
3

Vertices 5
0 0 0 1
1 0 0 1
0 1 0 1
0 0 1 1
0 0 -1 7
Edges
1
1 2 0
Triangles
2
1 2 3 0
1 2 3 0
Tetrahedra
2
1 2 3 4 1
1 2 3 5 1   # negative as written
Corners
1
1
End
";

    fn parse_err(text: &str) -> String {
        let s = parse(text).expect_err("malformed MEDIT must not parse").with_path("k.mesh").to_string();
        assert!(s.starts_with("k.mesh: ") && s.contains(" (fix: ") && !s.contains('\n'), "{s}");
        s
    }

    #[test]
    fn a_byte_order_mark_and_crlf_are_accepted() {
        let with_bom = format!("\u{feff}{}", TWO_TETS.replace('\n', "\r\n"));
        assert_eq!(parse(&with_bom).unwrap(), parse(TWO_TETS).unwrap());
    }

    #[test]
    fn skips_other_blocks_and_orients_tets() {
        let mesh = parse(TWO_TETS).unwrap();
        assert_eq!(mesh.positions.len(), 5);
        assert_eq!(mesh.tets, vec![[0, 1, 2, 3], [0, 1, 4, 2]]);
        assert!((0..2).all(|t| (mesh.signed_volume_at(&mesh.positions, t) - 1.0 / 6.0).abs() < 1e-15));
    }

    #[test]
    fn malformed_files_name_the_row_and_a_fix() {
        let cases = [
            (TWO_TETS.replace("1 2 3 5 1", "1 2 3 6 1"), "line 22: Tetrahedra row 2 refers to vertex 6, but vertices are numbered 1 to 5"),
            (TWO_TETS.replace("1 2 3 5 1", "0 1 2 3 1"), "line 22: Tetrahedra row 2 refers to vertex 0"),
            (TWO_TETS.replace("1 2 3 5 1", "1 2 3 3 1"), "line 22: Tetrahedra row 2 (vertices 1 2 3 3) is flat"),
            (TWO_TETS.replace("0 0 -1 7", "1 1 0 7"), "line 22: Tetrahedra row 2 (vertices 1 2 3 5) is flat"),
            (TWO_TETS.replace("Vertices 5", "Vertices 6"), "line 6: `Vertices` declares 6 rows but only 5 follow before `Edges`"),
            (TWO_TETS.replace("Vertices 5", "Vertices 4"), "line 11: expected a block keyword (Vertices, Tetrahedra, ...), found `0`"),
            (TWO_TETS.replace("1 0 0 1\n", "1 x 0 1\n"), "line 8: Vertices row 2: `x` is not a finite number"),
            (TWO_TETS.replace("1 0 0 1\n", "1 0 0 0 1\n"), "line 8: Vertices row 2 has 5 values"),
            (TWO_TETS.replace("1 2 3 4 1", "1 2 3.5 4 1"), "line 21: Tetrahedra row 1: `3.5` is not a vertex number"),
            (TWO_TETS.replace("Dimension\n3", "Dimension 2"), "line 3: the mesh has dimension 2, blendsim needs 3"),
            (TWO_TETS.replace("Tetrahedra\n2\n1 2 3 4 1\n1 2 3 5 1", "Tetrahedra\n0"), "has no tetrahedra"),
            (TWO_TETS.replace("Tetrahedra\n2", "Tetrahedra\nmany"), "line 20: `Tetrahedra` must be followed by a count"),
            (format!("{TWO_TETS}Vertices\n0\n").replace("End\n", ""), "a second `Vertices` block"),
            ("MeshVersionFormatted 1\nDimension 3\n".to_string(), "has no `Vertices` block"),
            // A NaN row is a NaN, not the end of its block.
            (TWO_TETS.replace("1 0 0 1\n", "nan 0 0 1\n"), "line 8: Vertices row 2: `nan` is not a finite number"),
            (TWO_TETS.replace("1 0 0 1\n", "1 -Infinity 0 1\n"), "line 8: Vertices row 2: `-Infinity` is not a finite number"),
            (TWO_TETS.replace("1 2 3 5 1", "1 2 3 5 1\nNaN 2 3 4 1"), "line 23: expected a block keyword (Vertices, Tetrahedra, ...), found `NaN`"),
            (TWO_TETS.replace("0 0 0 1\n", &format!("0 0 {} 1\n", "1".repeat(100_000))), "(100000 bytes) is not a finite number"),
        ];
        for (text, expected) in cases {
            let s = parse_err(&text);
            assert!(s.contains(expected), "expected {expected:?}, got {s}");
        }
    }

    #[test]
    fn paper_stretch3d_rest_mesh_is_oriented_on_load() {
        let Some(path) = paper_asset("stretch3d/0.mesh") else { return };
        let text = std::fs::read_to_string(&path).unwrap();
        let mesh = parse(&text).unwrap();
        assert_eq!((mesh.positions.len(), mesh.tets.len()), (594, 2400));
        // The file really has mixed orientation: reading it flipped some tets.
        let mut raw = mesh.clone();
        raw.tets = text
            .lines()
            .skip_while(|l| l.trim() != "Tetrahedra")
            .skip(2)
            .take(2400)
            .map(|l| {
                let v: Vec<u32> = l.split_whitespace().take(4).map(|t| t.parse::<u32>().unwrap() - 1).collect();
                [v[0], v[1], v[2], v[3]]
            })
            .collect();
        let flipped = raw.orient_positive();
        assert!(flipped > 0 && flipped < 2400, "{flipped} tets flipped");
        assert_eq!(raw.tets, mesh.tets);
        assert!((0..2400).all(|t| mesh.signed_volume_at(&mesh.positions, t) > 0.0));
        assert!((mesh.volume_at(&mesh.positions) - 1.6 * 3.0 * 1.0).abs() < 1e-12);
        assert_eq!(Bounds::of(&mesh.positions), Bounds { lo: [-0.8, 0.0, -0.5], hi: [0.8, 3.0, 0.5] });
    }

    #[test]
    fn paper_stretch3d_keyframes_share_the_rest_topology() {
        let (Some(p0), Some(p1), Some(p2)) = (paper_asset("stretch3d/0.mesh"), paper_asset("stretch3d/1.mesh"), paper_asset("stretch3d/2.mesh"))
        else {
            return;
        };
        let sorted = |m: &TetMesh| {
            m.tets
                .iter()
                .map(|t| {
                    let mut t = *t;
                    t.sort();
                    t
                })
                .collect::<Vec<_>>()
        };
        let rest = read(&p0).unwrap();
        for (path, y_range) in [(p1, (-3.0, 3.0)), (p2, (0.8, 3.0))] {
            let key = read(&path).unwrap();
            assert_eq!(sorted(&key), sorted(&rest), "{}", path.display());
            let Bounds { lo, hi } = Bounds::of(&key.positions);
            assert!((lo[1] - y_range.0).abs() < 1e-9 && (hi[1] - y_range.1).abs() < 1e-9, "{lo:?} {hi:?}");
        }
    }

    #[test]
    fn paper_dino_walk_cycle_and_spot() {
        if let Some(path) = paper_asset("dino/dino.mesh") {
            let rest = read(&path).unwrap();
            assert_eq!((rest.positions.len(), rest.tets.len()), (439, 1192));
            for k in 0..=10 {
                let Some(path) = paper_asset(&format!("dino/anim/dino_tet_{k}.mesh")) else { continue };
                let pose = read(&path).unwrap();
                assert_eq!((pose.positions.len(), pose.tets.len()), (439, 1192), "pose {k}");
            }
        }
        if let Some(path) = paper_asset("spot/spot.mesh") {
            let spot = read(&path).unwrap();
            assert_eq!((spot.positions.len(), spot.tets.len()), (837, 2288));
            assert!((0..spot.tets.len()).all(|t| spot.signed_volume_at(&spot.positions, t) > 0.0));
        }
    }
}
