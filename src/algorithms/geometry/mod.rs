//! Mesh types and the geometry on them.
//!
//! - [`TriMesh`]: a triangle surface (OBJ keyframes, the exported surface).
//! - [`TetMesh`]: a tetrahedral body (MEDIT `.mesh`, TetGen `.node`/`.ele`), every tet with
//!   positive signed volume once loaded.
//! - [`Point`] and its vector helpers, [`Bounds`] (axis-aligned boxes), [`Axis`].
//! - [`surface`] operations (boundary, winding, volume); [`attributes`] per corner (UVs,
//!   normals) and the seams they split a surface at.
//!
//! Their files are read and written in [`crate::formats::mesh`].

pub mod attributes;
pub mod bounds;
pub mod surface;

pub use bounds::Bounds;

/// A point or vector in 3D.
pub type Point = [f64; 3];

/// A triangle surface. Triangles index `positions`; vertices no triangle uses are allowed
/// (they are kept so vertex indices match the file they came from).
#[derive(Debug, Clone, PartialEq, Default, serde::Serialize, serde::Deserialize)]
pub struct TriMesh {
    /// Vertex positions, in file order.
    pub positions: Vec<Point>,
    /// Vertex indices of each triangle, counter-clockwise seen from the front.
    pub triangles: Vec<[u32; 3]>,
    /// UVs, normals and material groups per triangle corner (OBJ `vt`, `vn`, `usemtl`), when
    /// the file has any. Absent from stage files that have none, so they read as before.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub attributes: Option<attributes::CornerAttributes>,
}

/// A tetrahedral mesh. Invariant once built by a reader: every tet has positive signed volume
/// `det[b-a, c-a, d-a] / 6 > 0`, and every index is in range.
#[derive(Debug, Clone, PartialEq, Default, serde::Serialize, serde::Deserialize)]
pub struct TetMesh {
    /// Node positions, in file order.
    pub positions: Vec<Point>,
    /// Node indices of each tet.
    pub tets: Vec<[u32; 4]>,
}

/// Length of the bounding-box diagonal (0 for an empty set): the scale errors are reported in.
pub fn bbox_diagonal(points: &[Point]) -> f64 {
    Bounds::of(points).diagonal()
}

/// A coordinate axis.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Axis {
    /// The first coordinate.
    X,
    /// The second coordinate.
    Y,
    /// The third coordinate.
    Z,
}

impl Axis {
    /// The coordinate's index in a [`Point`].
    pub fn index(self) -> usize {
        self as usize
    }
}

/// `a - b`.
#[inline]
pub fn sub(a: Point, b: Point) -> Point {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// `a + b`.
#[inline]
pub fn add(a: Point, b: Point) -> Point {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

/// `s a`.
#[inline]
pub fn scale(a: Point, s: f64) -> Point {
    [a[0] * s, a[1] * s, a[2] * s]
}

/// `a · b`.
#[inline]
pub fn dot(a: Point, b: Point) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// `a × b`.
#[inline]
pub fn cross(a: Point, b: Point) -> Point {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

/// `|a|`.
#[inline]
pub fn norm(a: Point) -> f64 {
    dot(a, a).sqrt()
}

/// Signed volume of the tet (a, b, c, d): positive when (b-a, c-a, d-a) is right-handed.
#[inline]
pub(crate) fn tet_signed_volume(a: Point, b: Point, c: Point, d: Point) -> f64 {
    dot(sub(b, a), cross(sub(c, a), sub(d, a))) / 6.0
}

impl TetMesh {
    /// Signed volume of tet `t` at the given positions (which may be a deformed pose).
    pub fn signed_volume_at(&self, positions: &[Point], t: usize) -> f64 {
        let [a, b, c, d] = self.tets[t].map(|i| positions[i as usize]);
        tet_signed_volume(a, b, c, d)
    }

    /// Total volume of the body at the given positions.
    pub fn volume_at(&self, positions: &[Point]) -> f64 {
        (0..self.tets.len()).map(|t| self.signed_volume_at(positions, t)).sum()
    }

    /// The tets that `positions` invert or flatten against the rest pose (`self.positions`,
    /// positively oriented): `(tet, V / V_rest)` for every tet whose ratio is below
    /// `min_ratio` (negative: inverted), in tet order. Tets flat at rest are skipped (the rest
    /// shape's own checks report them).
    pub fn collapsed_at(&self, positions: &[Point], min_ratio: f64) -> Vec<(usize, f64)> {
        (0..self.tets.len())
            .filter_map(|t| {
                let rest = self.signed_volume_at(&self.positions, t);
                let ratio = self.signed_volume_at(positions, t) / rest;
                (rest > 0.0 && (ratio.is_nan() || ratio < min_ratio)).then_some((t, ratio))
            })
            .collect()
    }

    /// A fold of the mesh at rest, whatever the tets' vertex order: two tets sharing a face
    /// with their opposite vertices on the same side of it (they overlap), as `(tet, other
    /// tet, the shared face)`, the first in tet order. A valid tet mesh has none.
    pub(crate) fn first_fold(&self) -> Option<(usize, usize, [u32; 3])> {
        let mut faces: std::collections::HashMap<[u32; 3], (usize, u32)> = std::collections::HashMap::with_capacity(2 * self.tets.len());
        let p = |v: u32| self.positions[v as usize];
        let mut folds = Vec::new();
        for (t, tet) in self.tets.iter().enumerate() {
            for i in 0..4 {
                let mut face = [tet[(i + 1) % 4], tet[(i + 2) % 4], tet[(i + 3) % 4]];
                face.sort_unstable();
                match faces.entry(face) {
                    std::collections::hash_map::Entry::Vacant(e) => {
                        e.insert((t, tet[i]));
                    }
                    std::collections::hash_map::Entry::Occupied(e) => {
                        let (other, opposite) = *e.get();
                        let [a, b, c] = face.map(p);
                        let (s1, s2) = (tet_signed_volume(a, b, c, p(opposite)), tet_signed_volume(a, b, c, p(tet[i])));
                        if s1 * s2 > 0.0 {
                            folds.push((other, t, face));
                        }
                    }
                }
            }
        }
        folds.into_iter().min()
    }

    /// Swap two vertices of every tet with negative signed volume, so all are positive.
    /// Returns how many were flipped.
    pub fn orient_positive(&mut self) -> usize {
        let mut flipped = 0;
        for t in 0..self.tets.len() {
            if self.signed_volume_at(&self.positions, t) < 0.0 {
                self.tets[t].swap(2, 3);
                flipped += 1;
            }
        }
        flipped
    }
}
