//! Wavefront OBJ surfaces (helper-owned: see the contract below).
//!
//! Contract: `parse` reads `v` and `f` lines of the *first object* (stop at the second `o`
//! line that follows faces; `g` lines do not split), keeps every `v` in file order (unused
//! vertices included, so index files match the file), triangulates polygons as fans, accepts
//! `f a/b/c`, `a//c`, `a/b` forms and negative (relative) indices, ignores `vt`, `vn`, `usemtl`,
//! `mtllib`, `s`, `l`, `p` and comments. Errors name the line and say how to fix it.
//! `tobj` is not used: it renumbers vertices in first-use order and drops unused ones.

use std::path::Path;

use super::TriMesh;
use crate::error::Result;

pub fn read(path: &Path) -> Result<TriMesh> {
    let _ = path;
    todo!("mesh::obj::read")
}

pub fn parse(text: &str) -> Result<TriMesh> {
    let _ = text;
    todo!("mesh::obj::parse")
}

/// OBJ text for a surface (`v` lines with shortest round-trip floats, 1-based `f` lines).
pub fn write(mesh: &TriMesh) -> String {
    let _ = mesh;
    todo!("mesh::obj::write")
}
