//! Small dense 3x3 algebra for per-element work (row-major `[[f64; 3]; 3]`).

/// A 3x3 matrix, row-major: `m[row][column]`.
pub(crate) type Mat3 = [[f64; 3]; 3];

/// The identity matrix.
pub(crate) const IDENTITY: Mat3 = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

/// `a * b`.
#[inline]
pub fn mul(a: &Mat3, b: &Mat3) -> Mat3 {
    let mut c = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            c[i][j] = a[i][0] * b[0][j] + a[i][1] * b[1][j] + a[i][2] * b[2][j];
        }
    }
    c
}

/// `a * bᵀ`.
#[inline]
pub(crate) fn mul_transpose(a: &Mat3, b: &Mat3) -> Mat3 {
    let mut c = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            c[i][j] = a[i][0] * b[j][0] + a[i][1] * b[j][1] + a[i][2] * b[j][2];
        }
    }
    c
}

/// `aᵀ`.
#[inline]
pub fn transpose(a: &Mat3) -> Mat3 {
    [[a[0][0], a[1][0], a[2][0]], [a[0][1], a[1][1], a[2][1]], [a[0][2], a[1][2], a[2][2]]]
}

/// The determinant.
#[inline]
pub fn det(a: &Mat3) -> f64 {
    a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1]) - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
        + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0])
}

/// Inverse, or `None` when the determinant is not safely nonzero.
pub fn inverse(a: &Mat3) -> Option<Mat3> {
    let d = det(a);
    let scale = a.iter().flatten().fold(0.0f64, |m, v| m.max(v.abs()));
    // Written so that a NaN determinant also counts as singular.
    let invertible = d.abs() > 1e-14 * scale * scale * scale;
    if !invertible {
        return None;
    }
    let c = |i: usize, j: usize| {
        let (i1, i2) = ((i + 1) % 3, (i + 2) % 3);
        let (j1, j2) = ((j + 1) % 3, (j + 2) % 3);
        a[i1][j1] * a[i2][j2] - a[i1][j2] * a[i2][j1]
    };
    // Inverse = adjugate / det; the adjugate is the transposed cofactor matrix.
    Some(std::array::from_fn(|row| std::array::from_fn(|col| c(col, row) / d)))
}

/// `a * diag(s) * bᵀ`.
#[inline]
pub fn scaled_product(a: &Mat3, s: [f64; 3], b: &Mat3) -> Mat3 {
    let mut c = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            c[i][j] = a[i][0] * s[0] * b[j][0] + a[i][1] * s[1] * b[j][1] + a[i][2] * s[2] * b[j][2];
        }
    }
    c
}

/// Frobenius norm of `a - b`.
pub fn distance(a: &Mat3, b: &Mat3) -> f64 {
    a.iter().flatten().zip(b.iter().flatten()).map(|(x, y)| (x - y) * (x - y)).sum::<f64>().sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn inverse_times_matrix_is_identity() {
        let a = [[2.0, 1.0, 0.5], [0.0, 3.0, -1.0], [1.0, 0.0, 4.0]];
        let inv = inverse(&a).unwrap();
        assert!(distance(&mul(&a, &inv), &IDENTITY) < 1e-14);
        assert!(inverse(&[[1.0, 2.0, 3.0], [2.0, 4.0, 6.0], [0.0, 0.0, 1.0]]).is_none());
    }
}
