//! Wavefront OBJ surfaces.
//!
//! Contract: `parse` reads `v` and `f` lines of the *first object* (stop at the second `o`
//! line that follows faces; `g` lines do not split), keeps every `v` in file order (unused
//! vertices included, so index files match the file), triangulates polygons as fans, accepts
//! `f a/b/c`, `a//c`, `a/b` forms and negative (relative) indices, and ignores `mtllib`, `s`,
//! `l`, `p` and comments. Errors name the line and say how to fix it.
//! `tobj` is not used: it renumbers vertices in first-use order and drops unused ones.
//!
//! Attributes: `vt` (texture coordinates), `vn` (normals) and `usemtl` (material groups) are
//! kept per triangle corner in [`TriMesh::attributes`] (`None` when the file has none of
//! them on its faces, so such meshes are exactly what they were). UVs (likewise normals) are
//! kept only when every face corner gives one: a surface textured on some faces only has no
//! UV layout to carry, and such files were read before, so they still are (without UVs).
//! Faces before the first `usemtl` form the group `default`.
//!
//! Textures ([`read`] only, which knows the file's folder): the `.mtl` files of `mtllib` lines
//! are read for each group's `map_Kd` (diffuse texture; its last token is the file, options
//! before it are ignored), kept as absolute paths in [`CornerAttributes::textures`]. A missing
//! `.mtl` is ignored (exporters often name one they did not write, and the geometry does not
//! need it); a `map_Kd` naming a missing file is an error, since the result would be untextured.
//!
//! Extra columns after `v x y z` (a `w` weight or per-vertex colours) are ignored. Face
//! indices must refer to vertices defined above the face, as every exporter writes them:
//! that is what makes a relative index well defined.

use std::fmt::Write as _;
use std::path::Path;

use super::{Point, TriMesh};
use crate::algorithms::geometry::attributes::CornerAttributes;
use crate::support::error::{quoted, Error, Result};

/// Read an OBJ surface; errors name the file and the line.
///
/// Bytes that are not UTF-8 (Latin-1 comments or group names from older exporters) are
/// replaced, not refused: only the ASCII keywords and numbers matter.
pub fn read(path: &Path) -> Result<TriMesh> {
    let bytes = crate::support::input::read_bytes(path, "the OBJ surface")?;
    let text = String::from_utf8_lossy(&bytes);
    let mut mesh = parse(&text).map_err(|e| e.with_path(path))?;
    if let Some(a) = mesh.attributes.as_mut().filter(|a| !a.groups.is_empty()) {
        let folder = path.parent().unwrap_or(Path::new("."));
        let mut found: Vec<(String, String)> = Vec::new();
        for line in text.lines() {
            let mut tokens = line.split('#').next().unwrap_or("").split_whitespace();
            if tokens.next() == Some("mtllib") {
                // A library name may contain spaces; exporters write one file per line.
                let name = tokens.collect::<Vec<_>>().join(" ");
                found.extend(read_mtl_textures(&folder.join(name))?);
            }
        }
        let textures: Vec<Option<String>> = a.groups.iter().map(|g| found.iter().find(|(m, _)| m == g).map(|(_, t)| t.clone())).collect();
        if textures.iter().any(Option::is_some) {
            a.textures = textures;
        }
    }
    Ok(mesh)
}

/// The files an OBJ brings in besides itself, as a build tool must know them (`bake
/// --depfile`): each `.mtl` of its `mtllib` lines that exists, and each texture a `map_Kd` of
/// those names that exists. Nothing is checked here: [`read`] does that.
pub(crate) fn companions(path: &Path) -> Result<Vec<std::path::PathBuf>> {
    let bytes = crate::support::input::read_bytes(path, "the OBJ surface")?;
    let folder = path.parent().unwrap_or(Path::new("."));
    let mut out = Vec::new();
    for line in String::from_utf8_lossy(&bytes).lines() {
        let mut tokens = line.split('#').next().unwrap_or("").split_whitespace();
        if tokens.next() != Some("mtllib") {
            continue;
        }
        let mtl = folder.join(tokens.collect::<Vec<_>>().join(" "));
        if !mtl.is_file() {
            continue;
        }
        let text = crate::support::input::read_bytes(&mtl, "the material library (.mtl)")?;
        let mtl_folder = mtl.parent().unwrap_or(Path::new(".")).to_path_buf();
        for line in String::from_utf8_lossy(&text).lines() {
            let mut tokens = line.split('#').next().unwrap_or("").split_whitespace();
            if tokens.next().is_some_and(|k| k.eq_ignore_ascii_case("map_Kd")) {
                if let Some(file) = tokens.last() {
                    let texture = mtl_folder.join(file.replace('\\', "/"));
                    if texture.is_file() {
                        out.push(texture);
                    }
                }
            }
        }
        out.push(mtl);
    }
    Ok(out)
}

/// `(material, absolute texture path)` for each `newmtl` of a `.mtl` file with a `map_Kd`;
/// nothing when the file does not exist.
fn read_mtl_textures(mtl: &Path) -> Result<Vec<(String, String)>> {
    if std::fs::symlink_metadata(mtl).is_err() {
        return Ok(Vec::new());
    }
    // Read as a regular file only: a FIFO would block the bake forever.
    let bytes = crate::support::input::read_bytes(mtl, "the material library (.mtl)")?;
    let folder = mtl.parent().unwrap_or(Path::new("."));
    let mut out = Vec::new();
    let mut material: Option<String> = None;
    for (number, line) in String::from_utf8_lossy(&bytes).lines().enumerate() {
        let mut tokens = line.split('#').next().unwrap_or("").split_whitespace();
        match tokens.next() {
            Some("newmtl") => material = Some(tokens.collect::<Vec<_>>().join(" ")),
            Some(key) if key.eq_ignore_ascii_case("map_Kd") => {
                let (Some(m), Some(file)) = (&material, tokens.last()) else { continue };
                // Exporters on Windows write backslashes.
                let texture = folder.join(file.replace('\\', "/"));
                let wrong = match std::fs::metadata(&texture) {
                    Err(_) => Some("does not exist".to_string()),
                    Ok(m) if !m.is_file() => Some(format!("is {}, not an image file", crate::support::input::kind(&m))),
                    Ok(_) => None,
                };
                if let Some(what) = wrong {
                    return Err(Error::in_file(
                        mtl,
                        format!("line {}: map_Kd names the texture {}, which {what}", number + 1, quoted(file)),
                        "put the texture beside the .mtl (paths are relative to it), or remove the map_Kd line",
                    ));
                }
                // Checked now, before the solve, not when the export embeds it.
                let header = std::fs::File::open(&texture).map_err(|e| Error::io(&texture, &e, "read the texture"))?;
                if let Err((problem, fix)) = crate::formats::export::texture::inspect(std::io::BufReader::new(header)) {
                    return Err(Error::in_file(mtl, format!("line {}: map_Kd names the texture {}, which {problem}", number + 1, quoted(file)), fix));
                }
                let absolute = texture.canonicalize().map_err(|e| Error::io(&texture, &e, "resolve the texture path"))?;
                out.retain(|(x, _): &(String, String)| x != m);
                out.push((m.clone(), absolute.to_string_lossy().into_owned()));
            }
            _ => {}
        }
    }
    Ok(out)
}

/// Parse OBJ text (see the module contract). Errors carry no path; their problem starts with
/// `line N:` when a line is at fault.
pub fn parse(text: &str) -> Result<TriMesh> {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut mesh = TriMesh::default();
    let mut attributes = CornerAttributes::default();
    // Per triangle, its `usemtl` group (None before the first `usemtl`).
    let mut triangle_groups: Vec<Option<u32>> = Vec::new();
    let mut group: Option<u32> = None;
    let mut uv_corners: Vec<Option<[u32; 3]>> = Vec::new();
    let mut normal_corners: Vec<Option<[u32; 3]>> = Vec::new();
    for (number, line) in text.lines().enumerate() {
        let line_no = number + 1;
        let content = line.split('#').next().unwrap_or("");
        let mut tokens = content.split_whitespace();
        match tokens.next() {
            Some("v") => mesh.positions.push(parse_vertex(tokens, line_no)?),
            Some("vt") => {
                let uv = parse_numbers::<2>(tokens, 1, line_no, "texture coordinate", "`vt u v`")?;
                attributes.uvs.push(uv);
            }
            Some("vn") => attributes.normals.push(parse_numbers::<3>(tokens, 3, line_no, "normal", "`vn x y z`")?),
            Some("usemtl") => {
                let name = tokens.collect::<Vec<_>>().join(" ");
                let name = if name.is_empty() { "default".to_string() } else { name };
                group = Some(match attributes.groups.iter().position(|g| *g == name) {
                    Some(g) => g as u32,
                    None => {
                        attributes.groups.push(name);
                        attributes.groups.len() as u32 - 1
                    }
                });
            }
            Some("f") => {
                let defined = (mesh.positions.len(), attributes.uvs.len(), attributes.normals.len());
                let corners = tokens.map(|t| parse_corner(t, defined, line_no)).collect::<Result<Vec<Corner>>>()?;
                if corners.len() < 3 {
                    return Err(Error::general(
                        format!("line {line_no}: face has {} vertices, needs at least 3", corners.len()),
                        "remove the line, or export edges as `l` lines and polygons as `f` lines",
                    ));
                }
                for k in 1..corners.len() - 1 {
                    let tri = [&corners[0], &corners[k], &corners[k + 1]];
                    mesh.triangles.push(tri.map(|c| c.vertex));
                    let all = |f: fn(&Corner) -> Option<u32>| tri.iter().all(|c| f(c).is_some()).then(|| tri.map(|c| f(c).unwrap_or(0)));
                    uv_corners.push(all(|c| c.uv));
                    normal_corners.push(all(|c| c.normal));
                    triangle_groups.push(group);
                }
            }
            Some("o") if !mesh.triangles.is_empty() => break,
            _ => {}
        }
    }
    if mesh.triangles.is_empty() {
        return Err(Error::general(
            format!("has no faces ({} vertices, no `f` lines in the first object)", mesh.positions.len()),
            "export the mesh with its faces; point clouds and curves cannot be simulated",
        ));
    }
    if triangle_groups.iter().any(Option::is_some) {
        let default = || match attributes.groups.iter().position(|g| g == "default") {
            Some(g) => g as u32,
            None => attributes.groups.len() as u32,
        };
        let fallback = default();
        if fallback as usize == attributes.groups.len() && triangle_groups.iter().any(Option::is_none) {
            attributes.groups.push("default".into());
        }
        attributes.triangle_groups = triangle_groups.iter().map(|g| g.unwrap_or(fallback)).collect();
    } else {
        attributes.groups.clear();
    }
    attributes.uv_corners = uv_corners.into_iter().collect::<Option<Vec<_>>>().unwrap_or_default();
    attributes.normal_corners = normal_corners.into_iter().collect::<Option<Vec<_>>>().unwrap_or_default();
    if !attributes.is_empty() {
        // Only what the faces use is kept: values no face refers to would be dead weight.
        if attributes.uv_corners.is_empty() {
            attributes.uvs.clear();
        }
        if attributes.normal_corners.is_empty() {
            attributes.normals.clear();
        }
        mesh.attributes = Some(attributes);
    }
    Ok(mesh)
}

/// `N` finite numbers of a `vt` or `vn` line (at least `required`; missing ones are 0, extra
/// ones such as a `w` are ignored).
fn parse_numbers<'a, const N: usize>(
    tokens: impl Iterator<Item = &'a str>,
    required: usize,
    line_no: usize,
    what: &str,
    form: &str,
) -> Result<[f64; N]> {
    let mut out = [0.0; N];
    let mut count = 0;
    for token in tokens.take(N) {
        match token.parse::<f64>() {
            Ok(value) if value.is_finite() => out[count] = value,
            _ => {
                return Err(Error::general(
                    format!("line {line_no}: {what} value {} is not a finite number", quoted(token)),
                    format!("write {what}s as {form} with decimal numbers"),
                ))
            }
        }
        count += 1;
    }
    if count < required {
        return Err(Error::general(format!("line {line_no}: {what} has {count} values, needs {required}"), format!("write {what}s as {form}")));
    }
    Ok(out)
}

fn parse_vertex<'a>(tokens: impl Iterator<Item = &'a str>, line_no: usize) -> Result<Point> {
    let mut p = [0.0; 3];
    let mut count = 0;
    for token in tokens.take(3) {
        let value: f64 = token.parse().map_err(|_| {
            Error::general(
                format!("line {line_no}: vertex coordinate {} is not a number", quoted(token)),
                "write vertices as `v x y z` with decimal numbers, e.g. `v 0.5 1 -2e-3`",
            )
        })?;
        if !value.is_finite() {
            return Err(Error::general(
                format!("line {line_no}: vertex coordinate {} is not finite", quoted(token)),
                "fix or delete the vertex in your modeling tool and re-export",
            ));
        }
        p[count] = value;
        count += 1;
    }
    if count < 3 {
        return Err(Error::general(format!("line {line_no}: vertex has {count} coordinates, needs 3"), "write vertices as `v x y z`"));
    }
    Ok(p)
}

/// One `f` corner: 0-based vertex, texture coordinate and normal indices.
struct Corner {
    vertex: u32,
    uv: Option<u32>,
    normal: Option<u32>,
}

/// One `f` corner (`v`, `v/t`, `v//n` or `v/t/n`), given how many vertices, texture
/// coordinates and normals are defined above it.
fn parse_corner(token: &str, defined: (usize, usize, usize), line_no: usize) -> Result<Corner> {
    let mut parts = token.split('/');
    let vertex = parts.next().unwrap_or("");
    let index: i64 = vertex.parse().map_err(|_| {
        Error::general(
            format!("line {line_no}: face corner {} does not start with an integer vertex index", quoted(token)),
            "write faces as `f 1 2 3` (or `f 1/1/1 2/2/2 3/3/3`) with 1-based vertex numbers",
        )
    })?;
    let vertex = resolve(index, defined.0, line_no, "vertex", "vertices")?;
    let mut optional = |defined: usize, what: &str, plural: &str| -> Result<Option<u32>> {
        match parts.next() {
            None | Some("") => Ok(None),
            Some(s) => {
                let index: i64 = s.parse().map_err(|_| {
                    Error::general(
                        format!("line {line_no}: face corner {} has a {what} index that is not an integer", quoted(token)),
                        "write face corners as `v`, `v/vt`, `v//vn` or `v/vt/vn` with 1-based numbers",
                    )
                })?;
                resolve(index, defined, line_no, what, plural).map(Some)
            }
        }
    };
    let uv = optional(defined.1, "texture coordinate", "texture coordinates")?;
    let normal = optional(defined.2, "normal", "normals")?;
    Ok(Corner { vertex, uv, normal })
}

/// A 1-based (or negative, relative) OBJ index as a 0-based one, given how many are defined.
fn resolve(index: i64, defined: usize, line_no: usize, what: &str, plural: &str) -> Result<u32> {
    let resolved = match index {
        0 => {
            return Err(Error::general(
                format!("line {line_no}: face refers to {what} 0, but OBJ {what} numbers start at 1"),
                "re-export the mesh; the exporter wrote 0-based indices",
            ))
        }
        i if i > 0 => i - 1,
        i => defined as i64 + i,
    };
    match u32::try_from(resolved) {
        Ok(i) if (i as usize) < defined => Ok(i),
        _ => Err(Error::general(
            format!("line {line_no}: face refers to {what} {index}, but only {defined} {plural} are defined above it"),
            "re-export the mesh; the file is truncated or its faces come from another mesh",
        )),
    }
}

/// OBJ text for a surface (`v` lines with shortest round-trip floats, 1-based `f` lines).
pub fn write(mesh: &TriMesh) -> String {
    let mut out = String::new();
    for [x, y, z] in &mesh.positions {
        writeln!(out, "v {x} {y} {z}").expect("writing to a String cannot fail");
    }
    for [a, b, c] in &mesh.triangles {
        writeln!(out, "f {} {} {}", a + 1, b + 1, c + 1).expect("writing to a String cannot fail");
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::support::testing::paper_asset;

    #[test]
    fn map_kd_of_the_mtl_gives_each_group_its_texture() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path();
        std::fs::create_dir_all(dir.join("tex")).unwrap();
        std::fs::write(dir.join("tex/wood.png"), crate::formats::export::texture::png_claiming(1, 1)).unwrap();
        let obj = "mtllib a.mtl\nmtllib missing.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nvt 0 0\n\
                   usemtl wood\nf 1/1 2/1 3/1\nusemtl plain\nf 2/1 4/1 3/1\n";
        std::fs::write(dir.join("m.obj"), obj).unwrap();
        // Options before the file name, a backslash path, a material without a map.
        std::fs::write(dir.join("a.mtl"), "newmtl wood\nKd 1 1 1\nmap_Kd -bm 1 tex\\wood.png\nnewmtl plain\nKd 0.5 0.5 0.5\n").unwrap();
        let a = read(&dir.join("m.obj")).unwrap().attributes.unwrap();
        let wood = dir.join("tex/wood.png").canonicalize().unwrap();
        assert_eq!(a.textures, vec![Some(wood.to_string_lossy().into_owned()), None]);
        assert_eq!((a.texture(0).is_some(), a.texture(1)), (true, None));
        // A map naming a missing file: the .mtl, its line, the fix.
        std::fs::write(dir.join("a.mtl"), "newmtl wood\nmap_Kd gone.png\n").unwrap();
        let e = read(&dir.join("m.obj")).unwrap_err().to_string();
        assert!(e.contains("a.mtl") && e.contains("line 2: map_Kd names the texture") && e.contains("fix:"), "{e}");
        // No textures at all: the field stays empty (the stage file is as before).
        std::fs::write(dir.join("a.mtl"), "newmtl wood\nKd 1 0 0\n").unwrap();
        assert!(read(&dir.join("m.obj")).unwrap().attributes.unwrap().textures.is_empty());
    }

    fn parse_err(text: &str) -> String {
        let e = parse(text).expect_err("malformed OBJ must not parse");
        let s = e.with_path("k.obj").to_string();
        assert!(s.starts_with("k.obj: ") && s.contains(" (fix: ") && !s.contains('\n'), "{s}");
        s
    }

    #[test]
    fn fans_negative_indices_and_corner_forms() {
        let text = "# quad and pentagon\nmtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvn 0 0 1\n\
                    usemtl red\ns off\nf 1/1/1 2/1/1 3/1/1 4/1/1\nv 2 0 0 1.0 0.5 0.5\nf -1//1 -4/1 -3 -2 1 # comment\n\
                    l 1 2\np 3\n";
        let mesh = parse(text).unwrap();
        assert_eq!(mesh.positions.len(), 5);
        assert_eq!(mesh.positions[4], [2.0, 0.0, 0.0]);
        assert_eq!(mesh.triangles, vec![[0, 1, 2], [0, 2, 3], [4, 1, 2], [4, 2, 3], [4, 3, 0]]);
    }

    #[test]
    fn uvs_normals_and_groups_are_kept_per_corner() {
        // A quad (fanned into two triangles) in `red`, a triangle before any `usemtl` and one
        // in `blue`, with relative `vt`/`vn` indices on the last face.
        let text = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1 0.5\nvn 0 0 2\n\
                    f 1/1/1 2/2/1 3/3/1\nusemtl red\nf 1/1/1 2/2/1 3/3/1 4/4/1\nusemtl blue\nf -4/-4/-1 -3/-3/-1 -1/-1/-1\n";
        let mesh = parse(text).unwrap();
        let a = mesh.attributes.expect("vt, vn and usemtl are kept");
        assert_eq!(a.uvs, vec![[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]);
        assert_eq!(a.uv_corners, vec![[0, 1, 2], [0, 1, 2], [0, 2, 3], [0, 1, 3]]);
        assert_eq!(a.normals, vec![[0.0, 0.0, 2.0]]);
        assert_eq!(a.normal_corners, vec![[0; 3]; 4]);
        assert_eq!(a.groups, vec!["red", "blue", "default"]);
        assert_eq!(a.triangle_groups, vec![2, 0, 0, 1]);
        assert_eq!(a.check(mesh.triangles.len()), Ok(()));
    }

    #[test]
    fn attributes_on_some_corners_only_are_dropped_and_plain_meshes_have_none() {
        let mixed = parse("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvn 0 0 1\nf 1/1/1 2/1 3//1\n").unwrap();
        assert_eq!(mixed.attributes, None);
        let normals_only = parse("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvn 0 0 1\nf 1//1 2//1 3//1\n").unwrap();
        let a = normals_only.attributes.unwrap();
        assert!(a.uvs.is_empty() && a.uv_corners.is_empty() && a.groups.is_empty() && a.normal_corners.len() == 1);
        assert_eq!(parse("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1 2 3\n").unwrap().attributes, None);
    }

    #[test]
    fn bad_attribute_lines_name_the_line() {
        let cases = [
            ("vt x 0\n", "line 1: texture coordinate value `x` is not a finite number"),
            ("vn 0 0\n", "line 1: normal has 2 values, needs 3"),
            ("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/2 2/1 3/1\n", "line 5: face refers to texture coordinate 2, but only 1 texture coordinates"),
            ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1//0 2 3\n", "line 4: face refers to normal 0"),
            ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/a 2 3\n", "line 4: face corner `1/a` has a texture coordinate index that is not an integer"),
        ];
        for (text, expected) in cases {
            let s = parse_err(text);
            assert!(s.contains(expected), "{text:?}: got {s}");
        }
    }

    #[test]
    fn unused_vertices_are_kept_in_file_order() {
        let mesh = parse("v 9 9 9\nv 0 0 0\nv 7 7 7\nv 1 0 0\nv 0 1 0\nf 2 4 5\nv 8 8 8\n").unwrap();
        assert_eq!(mesh.positions.len(), 6);
        assert_eq!(mesh.positions[0], [9.0; 3]);
        assert_eq!(mesh.positions[5], [8.0; 3]);
        assert_eq!(mesh.triangles, vec![[1, 3, 4]]);
    }

    #[test]
    fn second_object_after_faces_ends_the_mesh_but_groups_do_not() {
        let text = "o A\nv 0 0 0\nv 1 0 0\nv 0 1 0\ng top\nf 1 2 3\ng bottom\nv 0 0 1\nf 1 3 4\n\
                    o B\nv 5 5 5\nv 6 5 5\nv 5 6 5\nf 5 6 7\n";
        let mesh = parse(text).unwrap();
        assert_eq!(mesh.positions.len(), 4);
        assert_eq!(mesh.triangles, vec![[0, 1, 2], [0, 2, 3]]);
    }

    #[test]
    fn malformed_lines_name_the_line_and_a_fix() {
        let cases = [
            ("v 0 0 0\nv 1 x 0\n", "line 2: vertex coordinate `x` is not a number"),
            ("v 0 0\n", "line 1: vertex has 2 coordinates, needs 3"),
            ("v 0 0 0\nv nan 0 0\n", "line 2: vertex coordinate `nan` is not finite"),
            ("v 0 0 0\nv 1 0 0\nv inf 0 0\n", "line 3: vertex coordinate `inf` is not finite"),
            ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n", "line 4: face refers to vertex 0"),
            ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n", "line 4: face refers to vertex 4, but only 3 vertices"),
            ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf -4 1 2\n", "line 4: face refers to vertex -4, but only 3 vertices"),
            ("v 0 0 0\nv 1 0 0\nv 0 1 0\n\nf 1 2\n", "line 5: face has 2 vertices, needs at least 3"),
            ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 b 3\n", "line 4: face corner `b` does not start with an integer"),
            ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 /2 3\n", "line 4: face corner `/2`"),
            ("f 1 2 3\nv 0 0 0\nv 1 0 0\nv 0 1 0\n", "line 1: face refers to vertex 1, but only 0 vertices"),
            ("v 0 0 0\nv 1 0 0\nl 1 2\n", "has no faces (2 vertices"),
            ("", "has no faces (0 vertices"),
        ];
        for (text, expected) in cases {
            let s = parse_err(text);
            assert!(s.contains(expected), "{text:?}: got {s}");
        }
    }

    #[test]
    fn crlf_and_byte_order_mark_are_accepted() {
        let mesh = parse("\u{feff}v 0 0 0\r\nv 1 0 0\r\nv 0 1 0\r\nf 1 2 3\r\n").unwrap();
        assert_eq!(mesh.triangles, vec![[0, 1, 2]]);
    }

    #[test]
    fn write_then_parse_is_exact_and_write_is_stable() {
        let mesh = TriMesh {
            positions: vec![[0.1 + 0.2, -0.0, 1e-300], [1e300, 5e-324, -1.0 / 3.0], [f64::MAX, 2.0, 0.5], [7.0, 8.0, 9.0]],
            triangles: vec![[0, 1, 2], [2, 1, 0]],
            attributes: None,
        };
        let text = write(&mesh);
        let back = parse(&text).unwrap();
        assert_eq!(back.triangles, mesh.triangles);
        for (a, b) in back.positions.iter().zip(&mesh.positions) {
            assert_eq!(a.map(f64::to_bits), b.map(f64::to_bits));
        }
        assert_eq!(write(&back), text);
        assert!(text.starts_with("v 0.30000000000000004 -0 0.000"), "{text}");
        assert!(text.ends_with("f 1 2 3\nf 3 2 1\n"), "{text}");
    }

    #[test]
    fn read_attaches_the_path_and_tolerates_latin1_comments() {
        let missing = Path::new("/nonexistent/blendsim/k0.obj");
        let s = read(missing).unwrap_err().to_string();
        assert!(s.starts_with("/nonexistent/blendsim/k0.obj: cannot read the OBJ surface") && s.contains("(fix: "), "{s}");
        let tmp = tempfile::tempdir().unwrap();
        let path = tmp.path().join("k1.obj");
        std::fs::write(&path, b"# mod\xe8le\ng caf\xe9\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2\n").unwrap();
        let s = read(&path).unwrap_err().to_string();
        let expected = "line 7: face has 2 vertices, needs at least 3 (fix: remove the line, or export edges as `l` lines";
        assert_eq!(s.split_once(": ").map(|(file, rest)| (file, rest.starts_with(expected))), Some((path.to_str().unwrap(), true)), "{s}");
    }

    #[test]
    fn paper_rectangular_prism_keeps_its_unused_interior_vertices() {
        let Some(path) = paper_asset("stretch3d/rectangular_prism.obj") else { return };
        let mesh = read(&path).unwrap();
        assert_eq!(mesh.positions.len(), 594);
        assert_eq!(mesh.triangles.len(), 680);
        let mut used = vec![false; 594];
        mesh.triangles.iter().flatten().for_each(|&i| used[i as usize] = true);
        assert_eq!(used.iter().filter(|u| !**u).count(), 252);
        assert_eq!(mesh.positions[0], [-0.8, 0.0, -0.5]);
    }

    #[test]
    fn paper_spot_with_uvs_and_blender_sphere() {
        if let Some(path) = paper_asset("spot/spot.obj") {
            let mesh = read(&path).unwrap();
            assert_eq!((mesh.positions.len(), mesh.triangles.len()), (2930, 5856));
        }
        if let Some(path) = paper_asset("ball/unit_sphere.obj") {
            let mesh = read(&path).unwrap();
            assert_eq!((mesh.positions.len(), mesh.triangles.len()), (192, 380));
            assert!(mesh.positions.iter().all(|p| (crate::algorithms::geometry::norm(*p) - 0.5).abs() < 1e-5), "a sphere of radius 0.5");
        }
    }
}
