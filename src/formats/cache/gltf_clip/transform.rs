//! 4x4 affine transforms of glTF nodes, column-major as glTF stores them.

use crate::algorithms::geometry::Point;

/// Column-major 4x4 matrix: element (row r, column c) is `m[4 * c + r]`.
pub(crate) type Mat4 = [f64; 16];

pub(crate) const IDENTITY: Mat4 = [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0];

/// A node's local transform: translation, rotation (unit quaternion x, y, z, w), scale.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Trs {
    pub translation: [f64; 3],
    pub rotation: [f64; 4],
    pub scale: [f64; 3],
}

impl Trs {
    /// `T * R * S`, the glTF node transform. The quaternion is used as given (as three.js's
    /// `compose` does): glTF requires unit rotations, and CUBICSPLINE results are normalized
    /// by the sampler.
    pub fn matrix(&self) -> Mat4 {
        let [x, y, z, w] = self.rotation;
        let (x2, y2, z2) = (x + x, y + y, z + z);
        let (xx, xy, xz) = (x * x2, x * y2, x * z2);
        let (yy, yz, zz) = (y * y2, y * z2, z * z2);
        let (wx, wy, wz) = (w * x2, w * y2, w * z2);
        let [sx, sy, sz] = self.scale;
        let [tx, ty, tz] = self.translation;
        [
            (1.0 - (yy + zz)) * sx,
            (xy + wz) * sx,
            (xz - wy) * sx,
            0.0,
            (xy - wz) * sy,
            (1.0 - (xx + zz)) * sy,
            (yz + wx) * sy,
            0.0,
            (xz + wy) * sz,
            (yz - wx) * sz,
            (1.0 - (xx + yy)) * sz,
            0.0,
            tx,
            ty,
            tz,
            1.0,
        ]
    }
}

/// `a * b`.
pub fn mul(a: &Mat4, b: &Mat4) -> Mat4 {
    let mut m = [0.0; 16];
    for c in 0..4 {
        for r in 0..4 {
            m[4 * c + r] = (0..4).map(|k| a[4 * k + r] * b[4 * c + k]).sum();
        }
    }
    m
}

/// `m * (p, 1)` for an affine `m`.
#[inline]
pub fn apply(m: &Mat4, p: Point) -> Point {
    [
        m[0] * p[0] + m[4] * p[1] + m[8] * p[2] + m[12],
        m[1] * p[0] + m[5] * p[1] + m[9] * p[2] + m[13],
        m[2] * p[0] + m[6] * p[1] + m[10] * p[2] + m[14],
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn trs_composes_translation_rotation_scale() {
        // 90 degrees about z: x -> y.
        let h = std::f64::consts::FRAC_1_SQRT_2;
        let trs = Trs { translation: [1.0, 2.0, 3.0], rotation: [0.0, 0.0, h, h], scale: [2.0, 1.0, 1.0] };
        let p = apply(&trs.matrix(), [1.0, 0.0, 0.0]);
        assert!((p[0] - 1.0).abs() < 1e-12 && (p[1] - 4.0).abs() < 1e-12 && (p[2] - 3.0).abs() < 1e-12, "{p:?}");
        let t = Trs { translation: [0.0, 0.0, 5.0], rotation: [0.0, 0.0, 0.0, 1.0], scale: [1.0; 3] };
        let composed = apply(&mul(&t.matrix(), &trs.matrix()), [1.0, 0.0, 0.0]);
        assert!((composed[2] - 8.0).abs() < 1e-12, "{composed:?}");
        assert_eq!(mul(&IDENTITY, &trs.matrix()), trs.matrix());
    }
}
