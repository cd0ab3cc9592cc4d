//! TetGen `.node` / `.ele` files and the `.smesh` PLC we feed TetGen.
//!
//! `.node`: a header `count 3 attributes markers`, then `number x y z [attributes] [marker]`.
//! `.ele`: a header `count 4|10 attributes`, then `number a b c d [more nodes] [attributes]`
//! (of 10-node tets the first four are the corners). `#` starts a comment. Node numbers must
//! run consecutively from 0 or 1, as TetGen writes them.

use std::fmt::Write as _;
use std::path::Path;
use std::str::FromStr;

use crate::algorithms::geometry::{norm, sub, tet_signed_volume, Point, TetMesh, TriMesh};
use crate::support::error::{quoted, short, Error, Result};

/// Read a `.node`/`.ele` pair given either file; indices may be 0- or 1-based (taken from the
/// first node number). Tets are oriented to positive volume.
pub fn read(path: &Path) -> Result<TetMesh> {
    let node_path = path.with_extension("node");
    let ele_path = path.with_extension("ele");
    let node_text = crate::support::input::read_text(&node_path, "the TetGen nodes")?;
    let (positions, first_index) = parse_node(&node_text).map_err(|e| e.with_path(&node_path))?;
    let ele_text = crate::support::input::read_text(&ele_path, "the TetGen tetrahedra")?;
    let tets = parse_ele(&ele_text, first_index, positions.len()).map_err(|e| e.with_path(&ele_path))?;
    if tets.is_empty() {
        return Err(Error::in_file(&ele_path, "has no tetrahedra", "re-run TetGen on a closed surface"));
    }
    let mut mesh = TetMesh { positions, tets };
    if let Some(t) = first_flat_tet(&mesh) {
        let [a, b, c, d] = mesh.tets[t].map(|i| i as usize + first_index);
        return Err(Error::in_file(
            &ele_path,
            format!("tetrahedron {} (nodes {a} {b} {c} {d}) is flat: it has no volume", t + first_index),
            "re-run TetGen with quality refinement (-q) or remove the degenerate tetrahedron",
        ));
    }
    mesh.orient_positive();
    Ok(mesh)
}

/// Parse `.node` text: returns the points and the first index (0 or 1).
pub(crate) fn parse_node(text: &str) -> Result<(Vec<Point>, usize)> {
    let mut lines = content_lines(text);
    let (header_no, header) = lines.next().ok_or_else(|| Error::general("is empty, expected a `count 3 attributes markers` header", REMESH))?;
    let count: usize = field(&header, 0, header_no, "the node count")?;
    let dimension: usize = optional_field(&header, 1, header_no, "the dimension")?.unwrap_or(3);
    let attributes: usize = optional_field(&header, 2, header_no, "the attribute count")?.unwrap_or(0);
    let markers: usize = optional_field(&header, 3, header_no, "the boundary-marker flag")?.unwrap_or(0);
    if dimension != 3 || markers > 1 {
        return Err(Error::general(
            format!("line {header_no}: header says dimension {dimension} and marker flag {markers}, expected 3 and 0 or 1"),
            REMESH,
        ));
    }
    let columns = 4 + attributes + markers;
    let mut points = Vec::new();
    let mut first_index = 0;
    for k in 0..count {
        let (line_no, tokens) = next_row(&mut lines, "node", k, count, header_no)?;
        check_columns(&tokens, columns, line_no, "node", header_no)?;
        let number: usize = field(&tokens, 0, line_no, "the node number")?;
        if k == 0 && number > 1 {
            return Err(Error::general(format!("line {line_no}: the first node is numbered {number}, not 0 or 1"), REMESH));
        }
        if k == 0 {
            first_index = number;
        } else if number != first_index + k {
            return Err(Error::general(format!("line {line_no}: node number {number} is out of sequence (expected {})", first_index + k), REMESH));
        }
        let mut p = [0.0; 3];
        for (d, slot) in p.iter_mut().enumerate() {
            *slot = field::<f64>(&tokens, d + 1, line_no, "a coordinate")?;
            if !slot.is_finite() {
                return Err(Error::general(format!("line {line_no}: node {number} has a non-finite coordinate"), REMESH));
            }
        }
        points.push(p);
    }
    Ok((points, first_index))
}

/// Parse `.ele` text given the first node index.
pub(crate) fn parse_ele(text: &str, first_index: usize, node_count: usize) -> Result<Vec<[u32; 4]>> {
    let mut lines = content_lines(text);
    let (header_no, header) = lines.next().ok_or_else(|| Error::general("is empty, expected a `count 4 attributes` header", REMESH))?;
    let count: usize = field(&header, 0, header_no, "the tetrahedron count")?;
    let corners: usize = optional_field(&header, 1, header_no, "the nodes per tetrahedron")?.unwrap_or(4);
    let attributes: usize = optional_field(&header, 2, header_no, "the attribute count")?.unwrap_or(0);
    if corners != 4 && corners != 10 {
        return Err(Error::general(format!("line {header_no}: header says {corners} nodes per tetrahedron, expected 4 or 10"), REMESH));
    }
    let mut tets = Vec::new();
    for k in 0..count {
        let (line_no, tokens) = next_row(&mut lines, "tetrahedron", k, count, header_no)?;
        check_columns(&tokens, 1 + corners + attributes, line_no, "tetrahedron", header_no)?;
        let mut tet = [0u32; 4];
        for (c, slot) in tet.iter_mut().enumerate() {
            let node: usize = field(&tokens, c + 1, line_no, "a node number")?;
            match node.checked_sub(first_index) {
                Some(i) if i < node_count => *slot = i as u32,
                _ => {
                    return Err(Error::general(
                        format!(
                            "line {line_no}: tetrahedron {} refers to node {node}, but nodes are numbered {first_index} to {}",
                            short(tokens[0]),
                            (first_index + node_count).saturating_sub(1)
                        ),
                        "use the .node file written together with this .ele file",
                    ))
                }
            }
        }
        tets.push(tet);
    }
    Ok(tets)
}

/// A `.smesh` PLC for a closed surface (all vertices listed, 0-based).
pub(crate) fn write_smesh(surface: &TriMesh) -> String {
    let mut out = String::new();
    let ok = "writing to a String cannot fail";
    writeln!(out, "# blendsim surface: nodes (0-based), facets, holes, regions").expect(ok);
    writeln!(out, "{} 3 0 0", surface.positions.len()).expect(ok);
    for (i, [x, y, z]) in surface.positions.iter().enumerate() {
        writeln!(out, "{i} {x} {y} {z}").expect(ok);
    }
    writeln!(out, "{} 0", surface.triangles.len()).expect(ok);
    for [a, b, c] in &surface.triangles {
        writeln!(out, "3 {a} {b} {c}").expect(ok);
    }
    out.push_str("0\n0\n");
    out
}

/// The first tet whose volume is at round-off level (below 1e-12 of its longest edge cubed),
/// which no orientation fix can make positive. A volume that overflows (finite coordinates
/// near 1e100 and beyond give an infinite or NaN volume) counts as flat too: no sign can be
/// trusted.
pub(crate) fn first_flat_tet(mesh: &TetMesh) -> Option<usize> {
    mesh.tets.iter().position(|tet| {
        let [a, b, c, d] = tet.map(|i| mesh.positions[i as usize]);
        let longest = [(a, b), (a, c), (a, d), (b, c), (b, d), (c, d)].iter().map(|&(p, q)| norm(sub(p, q))).fold(0.0, f64::max);
        let volume6 = 6.0 * tet_signed_volume(a, b, c, d).abs();
        !(volume6.is_finite() && volume6 > 1e-12 * longest.powi(3))
    })
}

const REMESH: &str = "re-run TetGen, or re-export the tet mesh as TetGen .node/.ele";

/// Non-empty lines without their `#` comment: 1-based number and tokens. Shared with the
/// MEDIT reader, whose comments are the same. A UTF-8 byte order mark is skipped.
pub(super) fn content_lines(text: &str) -> impl Iterator<Item = (usize, Vec<&str>)> {
    text.strip_prefix('\u{feff}').unwrap_or(text).lines().enumerate().filter_map(|(i, line)| {
        let tokens: Vec<&str> = line.split('#').next().unwrap_or("").split_whitespace().collect();
        (!tokens.is_empty()).then_some((i + 1, tokens))
    })
}

fn next_row<'a>(
    lines: &mut impl Iterator<Item = (usize, Vec<&'a str>)>,
    what: &str,
    k: usize,
    count: usize,
    header_no: usize,
) -> Result<(usize, Vec<&'a str>)> {
    lines.next().ok_or_else(|| {
        Error::general(
            format!("line {header_no}: the header announces {count} {what} rows but the file ends after {k}"),
            "the file is truncated; re-run TetGen",
        )
    })
}

fn check_columns(tokens: &[&str], expected: usize, line_no: usize, what: &str, header_no: usize) -> Result<()> {
    if tokens.len() == expected {
        return Ok(());
    }
    Err(Error::general(
        format!("line {line_no}: {what} row has {} columns, but the header on line {header_no} implies {expected}", tokens.len()),
        REMESH,
    ))
}

fn field<T: FromStr>(tokens: &[&str], i: usize, line_no: usize, what: &str) -> Result<T> {
    optional_field(tokens, i, line_no, what)?.ok_or_else(|| Error::general(format!("line {line_no}: {what} is missing"), REMESH))
}

fn optional_field<T: FromStr>(tokens: &[&str], i: usize, line_no: usize, what: &str) -> Result<Option<T>> {
    tokens
        .get(i)
        .map(|token| token.parse().map_err(|_| Error::general(format!("line {line_no}: {what} {} is not a valid number", quoted(token)), REMESH)))
        .transpose()
}

#[cfg(test)]
mod tests {
    use super::*;

    const NODE: &str = "# nodes, 1-based, one attribute and markers\n5 3 1 1\n1 0 0 0 9.5 1\n2 1 0 0 9.5 1\n\
                        3 0 1 0 9.5 1   # comment\n\n4 0 0 1 9.5 0\n5 0 0 -1 9.5 1\n# Generated by hand\n";
    const ELE: &str = "2 4 1\n1 1 2 3 4 7\n2 1 2 3 5 7\n";

    fn err(result: Result<impl std::fmt::Debug>) -> String {
        let s = result.expect_err("malformed input must not parse").with_path("x.1.node").to_string();
        assert!(s.starts_with("x.1.node: ") && s.contains(" (fix: ") && !s.contains('\n'), "{s}");
        s
    }

    #[test]
    fn one_based_nodes_with_attributes_and_markers() {
        let (points, first) = parse_node(NODE).unwrap();
        assert_eq!(first, 1);
        assert_eq!(points, vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, -1.0]]);
        assert_eq!(parse_ele(ELE, 1, 5).unwrap(), vec![[0, 1, 2, 3], [0, 1, 2, 4]]);
    }

    #[test]
    fn zero_based_ten_node_tets_keep_their_corners() {
        let (points, first) = parse_node("4 3 0 0\n0 0 0 0\n1 1 0 0\n2 0 1 0\n3 0 0 1\n").unwrap();
        assert_eq!((points.len(), first), (4, 0));
        let ele = "1 10 0\n0 0 1 2 3 0 1 2 3 0 1\n";
        assert_eq!(parse_ele(ele, 0, 4).unwrap(), vec![[0, 1, 2, 3]]);
    }

    #[test]
    fn malformed_files_name_the_line() {
        assert!(err(parse_node("")).contains("is empty"));
        assert!(err(parse_node("2 2 0 0\n")).contains("line 1: header says dimension 2"));
        assert!(err(parse_node("2 3 0 0\n0 0 0 0\n2 1 0 0\n")).contains("line 3: node number 2 is out of sequence (expected 1)"));
        assert!(err(parse_node("2 3 0 0\n5 0 0 0\n")).contains("line 2: the first node is numbered 5"));
        assert!(err(parse_node("2 3 0 0\n0 0 0 0\n")).contains("line 1: the header announces 2 node rows but the file ends after 1"));
        assert!(err(parse_node("1 3 0 1\n0 0 0 0\n")).contains("line 2: node row has 4 columns, but the header on line 1 implies 5"));
        assert!(err(parse_node("1 3 0 0\n0 0 y 0\n")).contains("line 2: a coordinate `y` is not a valid number"));
        assert!(err(parse_node("1 3 0 0\n0 0 inf 0\n")).contains("line 2: node 0 has a non-finite coordinate"));
        assert!(err(parse_ele("1 4 0\n1 1 2 3 6\n", 1, 5)).contains("line 2: tetrahedron 1 refers to node 6, but nodes are numbered 1 to 5"));
        assert!(err(parse_ele("1 4 0\n1 0 2 3 4\n", 1, 5)).contains("refers to node 0"));
        assert!(err(parse_ele("1 6 0\n", 0, 5)).contains("line 1: header says 6 nodes per tetrahedron"));
        assert_eq!(parse_node(&format!("\u{feff}{NODE}")).unwrap(), parse_node(NODE).unwrap(), "a byte order mark is skipped");
        let long = "9".repeat(99_999) + "x";
        let s = err(parse_node(&format!("1 3 0 0\n0 {long} 0 0\n")));
        assert!(s.contains("line 2: a coordinate `999") && s.contains("(100000 bytes) is not a valid number") && s.len() < 300, "{s}");
    }

    #[test]
    fn a_tet_whose_volume_overflows_counts_as_flat() {
        // Finite coordinates whose volume is NaN in f64 (0 * inf): no orientation can be trusted.
        let positions =
            vec![[0.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 1e308, 0.0], [0.0, 0.0, 1e308], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        let mesh = TetMesh { positions, tets: vec![[0, 4, 5, 6], [0, 1, 2, 3]] };
        assert!(mesh.signed_volume_at(&mesh.positions, 1).is_nan());
        assert_eq!(first_flat_tet(&mesh), Some(1));
    }

    #[test]
    fn read_takes_either_file_orients_and_names_the_file() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path();
        std::fs::write(dir.join("body.1.node"), NODE).unwrap();
        std::fs::write(dir.join("body.1.ele"), ELE).unwrap();
        for name in ["body.1.node", "body.1.ele"] {
            let mesh = read(&dir.join(name)).unwrap();
            assert_eq!(mesh.tets, vec![[0, 1, 2, 3], [0, 1, 4, 2]]);
        }
        std::fs::write(dir.join("flat.node"), NODE.replace("5 0 0 -1 9.5 1", "5 1 1 0 9.5 1")).unwrap();
        std::fs::write(dir.join("flat.ele"), ELE).unwrap();
        let flat = read(&dir.join("flat.node")).unwrap_err().to_string();
        assert!(flat.contains("flat.ele: tetrahedron 2 (nodes 1 2 3 5) is flat"), "{flat}");
        std::fs::write(dir.join("alone.node"), NODE).unwrap();
        let missing = read(&dir.join("alone.node")).unwrap_err().to_string();
        assert!(missing.contains("alone.ele: cannot read the TetGen tetrahedra") && missing.contains("(fix: "), "{missing}");
    }

    #[test]
    fn smesh_lists_every_vertex_zero_based() {
        let surface = TriMesh {
            positions: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.25, 0.25, 0.1]],
            triangles: vec![[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]],
            attributes: None,
        };
        assert_eq!(
            write_smesh(&surface),
            "# blendsim surface: nodes (0-based), facets, holes, regions\n5 3 0 0\n0 0 0 0\n1 1 0 0\n2 0 1 0\n\
             3 0 0 1\n4 0.25 0.25 0.1\n4 0\n3 0 2 1\n3 0 1 3\n3 1 2 3\n3 0 3 2\n0\n0\n"
        );
    }
}
