//! Per-corner surface attributes: texture coordinates, normals and material groups (OBJ `vt`,
//! `vn`, `usemtl`), and the vertex split a per-vertex format (glTF) needs at their seams.
//!
//! Invariants of [`CornerAttributes`] (checked by [`CornerAttributes::check`]): `uv_corners`
//! and `normal_corners` are empty or have one entry per triangle, every entry indexing `uvs`
//! / `normals`; `triangle_groups` is empty or has one entry per triangle, indexing `groups`;
//! `textures` is empty or has one entry per group.
//! Attributes are per triangle *corner*, so vertex renumbering (`surface::compact`) leaves
//! them valid; reversing a triangle's winding must swap its corners too
//! ([`CornerAttributes::swap_corners`]).

use serde::{Deserialize, Serialize};

use super::Point;

/// Texture coordinates, normals and material groups of a triangle surface, per corner.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct CornerAttributes {
    /// Texture coordinates (OBJ `vt`, v up), in file order.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub uvs: Vec<[f64; 2]>,
    /// Per triangle, the `uvs` index of each corner (empty: no UVs).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub uv_corners: Vec<[u32; 3]>,
    /// Normals (OBJ `vn`, as written: not necessarily unit), in file order.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub normals: Vec<Point>,
    /// Per triangle, the `normals` index of each corner (empty: no normals).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub normal_corners: Vec<[u32; 3]>,
    /// Material group names (OBJ `usemtl`), in order of first use.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub groups: Vec<String>,
    /// Per triangle, its index in `groups` (empty: no groups).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub triangle_groups: Vec<u32>,
    /// Per group, the diffuse texture its material names (the `.mtl`'s `map_Kd`, an absolute
    /// path), or `None`; empty when no group has one.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub textures: Vec<Option<String>>,
}

impl CornerAttributes {
    /// Whether nothing is carried (then a surface has no attributes at all).
    pub fn is_empty(&self) -> bool {
        self.uv_corners.is_empty() && self.normal_corners.is_empty() && self.triangle_groups.is_empty()
    }

    /// Reverse triangle `t`'s winding the way `surface::orient_outward` does (swap corners 1, 2).
    pub fn swap_corners(&mut self, t: usize) {
        if let Some(c) = self.uv_corners.get_mut(t) {
            c.swap(1, 2);
        }
        if let Some(c) = self.normal_corners.get_mut(t) {
            c.swap(1, 2);
        }
    }

    /// The invariants, for `triangles` triangles; `Err` says which is broken.
    pub fn check(&self, triangles: usize) -> std::result::Result<(), String> {
        let per_triangle = |what: &str, len: usize| {
            if len != 0 && len != triangles {
                Err(format!("has {len} {what} for {triangles} triangles"))
            } else {
                Ok(())
            }
        };
        per_triangle("UV corners", self.uv_corners.len())?;
        per_triangle("normal corners", self.normal_corners.len())?;
        per_triangle("material groups", self.triangle_groups.len())?;
        if self.uv_corners.iter().flatten().any(|&i| i as usize >= self.uvs.len()) {
            return Err(format!("has a UV corner beyond its {} UVs", self.uvs.len()));
        }
        if self.normal_corners.iter().flatten().any(|&i| i as usize >= self.normals.len()) {
            return Err(format!("has a normal corner beyond its {} normals", self.normals.len()));
        }
        if self.triangle_groups.iter().any(|&g| g as usize >= self.groups.len()) {
            return Err(format!("has a triangle in a group beyond its {} groups", self.groups.len()));
        }
        if !self.textures.is_empty() && self.textures.len() != self.groups.len() {
            return Err(format!("has {} group textures for {} groups", self.textures.len(), self.groups.len()));
        }
        Ok(())
    }

    /// Whether one UV per vertex describes the UVs (no seam): every corner of a vertex has the
    /// same UV value. `vertices` is the vertex count, `triangles` the surface's triangles.
    pub(crate) fn uvs_per_vertex(&self, triangles: &[[u32; 3]], vertices: usize) -> Option<Vec<[f64; 2]>> {
        per_vertex(triangles, vertices, &self.uv_corners, &self.uvs)
    }

    /// The texture of each group, `None` for groups without one (or without textures at all).
    pub fn texture(&self, group: usize) -> Option<&str> {
        self.textures.get(group).and_then(|t| t.as_deref())
    }

    /// Whether one normal per vertex describes the normals (no crease), as for UVs.
    pub(crate) fn normals_per_vertex(&self, triangles: &[[u32; 3]], vertices: usize) -> Option<Vec<Point>> {
        per_vertex(triangles, vertices, &self.normal_corners, &self.normals)
    }
}

/// The value of each vertex when all its corners agree (compared by value, not index), `None`
/// at the first disagreement or when there are no corners.
fn per_vertex<T: Copy + PartialEq + Default>(triangles: &[[u32; 3]], vertices: usize, corners: &[[u32; 3]], values: &[T]) -> Option<Vec<T>> {
    if corners.is_empty() {
        return None;
    }
    let mut out: Vec<Option<T>> = vec![None; vertices];
    for (t, c) in triangles.iter().zip(corners) {
        for k in 0..3 {
            let value = values[c[k] as usize];
            match &mut out[t[k] as usize] {
                Some(v) if *v != value => return None,
                slot => *slot = Some(value),
            }
        }
    }
    Some(out.into_iter().map(Option::unwrap_or_default).collect())
}

/// A surface with one value of every attribute per vertex: vertices split where corners of one
/// vertex carry different UVs or normals (a seam).
///
/// Invariant: `sources[i] == i` for `i < vertices` (every vertex keeps its index, unused ones
/// included), and the seam copies follow, so point `i` of the animation is split vertex `i`
/// and copy `j >= vertices` moves with point `sources[j]`. A vertex no triangle uses has no
/// corner to take attributes from: its UV is `[0, 0]` and its normal zero.
#[derive(Debug, Clone, PartialEq)]
pub struct SplitSurface {
    /// For each split vertex, the surface vertex it copies.
    pub sources: Vec<u32>,
    /// Triangles over split vertices, in the surface's triangle order.
    pub triangles: Vec<[u32; 3]>,
    /// Per split vertex UV (when the surface has UVs).
    pub uvs: Option<Vec<[f64; 2]>>,
    /// Per split vertex normal (when the surface has normals).
    pub normals: Option<Vec<Point>>,
}

/// Split `triangles` (over `vertices` vertices) at the seams of `attributes`. A vertex's first corner, in triangle order, keeps its index; each further
/// distinct (UV index, normal index) pair of it becomes a copy appended after all vertices.
pub fn split_at_seams(triangles: &[[u32; 3]], vertices: usize, attributes: &CornerAttributes) -> SplitSurface {
    let has_uv = !attributes.uv_corners.is_empty();
    let has_normal = !attributes.normal_corners.is_empty();
    let key =
        |t: usize, k: usize| (if has_uv { attributes.uv_corners[t][k] } else { 0 }, if has_normal { attributes.normal_corners[t][k] } else { 0 });
    // Per vertex, its (key, split index) list; a handful of entries at most.
    let mut seen: Vec<Vec<((u32, u32), u32)>> = vec![Vec::new(); vertices];
    let mut sources: Vec<u32> = (0..vertices as u32).collect();
    // Per split vertex, the (UV index, normal index) it shows; `None` for unused vertices.
    let mut corner_key: Vec<Option<(u32, u32)>> = vec![None; vertices];
    let mut split = Vec::with_capacity(triangles.len());
    for (t, tri) in triangles.iter().enumerate() {
        let mut out = [0u32; 3];
        for k in 0..3 {
            let v = tri[k] as usize;
            let kk = key(t, k);
            let list = &mut seen[v];
            out[k] = if list.is_empty() {
                list.push((kk, v as u32));
                corner_key[v] = Some(kk);
                v as u32
            } else if let Some(&(_, i)) = list.iter().find(|(x, _)| *x == kk) {
                i
            } else {
                let i = sources.len() as u32;
                sources.push(v as u32);
                corner_key.push(Some(kk));
                list.push((kk, i));
                i
            };
        }
        split.push(out);
    }
    let uvs = has_uv.then(|| corner_key.iter().map(|k| k.map_or([0.0; 2], |k| attributes.uvs[k.0 as usize])).collect());
    let normals = has_normal.then(|| corner_key.iter().map(|k| k.map_or([0.0; 3], |k| attributes.normals[k.1 as usize])).collect());
    SplitSurface { sources, triangles: split, uvs, normals }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two triangles sharing edge 1-2; vertex 1 has UV 1 in the first and UV 3 in the second.
    fn seam() -> ([[u32; 3]; 2], CornerAttributes) {
        let attributes = CornerAttributes {
            uvs: vec![[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0]],
            uv_corners: vec![[0, 1, 2], [2, 3, 3]],
            ..Default::default()
        };
        ([[0, 1, 2], [2, 1, 3]], attributes)
    }

    #[test]
    fn seams_split_only_the_disagreeing_vertices_and_keep_the_first_index() {
        let (triangles, mut a) = seam();
        // Vertex 3 reuses UV index 3 consistently; vertex 1 has UVs 1 and 3 (a seam).
        let s = split_at_seams(&triangles, 4, &a);
        assert_eq!(s.sources, vec![0, 1, 2, 3, 1]);
        assert_eq!(s.triangles, vec![[0, 1, 2], [2, 4, 3]]);
        assert_eq!(s.uvs.as_ref().unwrap()[4], [1.0, 1.0]);
        assert!(s.normals.is_none());
        assert_eq!(a.uvs_per_vertex(&triangles, 4), None);
        // Without the seam nothing splits and the per-vertex form exists.
        a.uv_corners[1] = [2, 1, 3];
        let s = split_at_seams(&triangles, 4, &a);
        assert_eq!(s.sources, vec![0, 1, 2, 3]);
        assert_eq!(s.triangles, triangles.to_vec());
        assert_eq!(a.uvs_per_vertex(&triangles, 4), Some(vec![[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0]]));
    }

    #[test]
    fn unused_vertices_keep_their_index_with_a_zero_uv_and_normal() {
        // Vertex 2 of 5 and vertex 4 (the last) are used by no triangle.
        let triangles = [[0, 1, 3], [3, 1, 0]];
        let a = CornerAttributes {
            uvs: vec![[0.5, 0.5], [1.0, 0.0], [0.0, 1.0]],
            uv_corners: vec![[0, 1, 2], [2, 1, 1]],
            normals: vec![[0.0, 1.0, 0.0]],
            normal_corners: vec![[0, 0, 0], [0, 0, 0]],
            ..Default::default()
        };
        let s = split_at_seams(&triangles, 5, &a);
        // Vertex 0 has UVs 0 and 1: one copy, after the five points.
        assert_eq!(s.sources, vec![0, 1, 2, 3, 4, 0]);
        assert_eq!(s.triangles, vec![[0, 1, 3], [3, 1, 5]]);
        assert_eq!(s.uvs.unwrap(), vec![[0.5, 0.5], [1.0, 0.0], [0.0, 0.0], [0.0, 1.0], [0.0, 0.0], [1.0, 0.0]]);
        let normals = s.normals.unwrap();
        assert_eq!((normals[2], normals[4], normals[3]), ([0.0; 3], [0.0; 3], [0.0, 1.0, 0.0]));
        assert_eq!(a.normals_per_vertex(&triangles, 5).unwrap()[2], [0.0; 3]);
    }

    #[test]
    fn equal_uv_values_under_different_indices_are_not_a_seam_per_vertex() {
        let (triangles, mut a) = seam();
        a.uvs[3] = [1.0, 0.0];
        assert!(a.uvs_per_vertex(&triangles, 4).is_some());
    }

    #[test]
    fn check_names_the_broken_invariant() {
        let (_, mut a) = seam();
        assert_eq!(a.check(2), Ok(()));
        assert!(a.check(3).unwrap_err().contains("2 UV corners for 3 triangles"));
        a.uv_corners[0][0] = 9;
        assert!(a.check(2).unwrap_err().contains("beyond its 4 UVs"));
        let g = CornerAttributes { groups: vec!["a".into()], triangle_groups: vec![0, 1], ..Default::default() };
        assert!(g.check(2).unwrap_err().contains("beyond its 1 groups"));
    }
}
