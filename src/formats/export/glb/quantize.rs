//! `KHR_mesh_quantization`: positions and morph-target offsets as integers on one grid, undone
//! by the node's scale and translation; normals as normalized bytes; UVs as normalized shorts.
//!
//! One grid serves the base and every target because a node transform applies to the morphed
//! point as a whole: `world = node · (base + Σ w_j offset_j)`. Its step is the coarsest whose
//! rounding keeps every played point within the error budget (`formats/gltf.md`,
//! "Quantization").

use gltf_json::accessor::ComponentType;

/// The integer grid of a file's positions: a point `p` is stored as `round((p - center) / step)`,
/// an offset `d` as `round(d / step)`, both non-normalized (`KHR_mesh_quantization` allows it).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Grid {
    /// Scene units per integer step (the node's scale, times the placement's units).
    pub step: f32,
    /// The base's bounding-box center (the node's translation, placed).
    pub center: [f32; 3],
}

/// The largest magnitude stored in a signed short (symmetric: -32768 is left out).
const I16_MAX: f64 = 32767.0;
/// The largest magnitude stored in a signed byte.
const I8_MAX: i32 = 127;

impl Grid {
    /// The coarsest grid whose rounding keeps every played point within `max_error` (scene units):
    /// each stored vector is off by at most `√3/2 · step`, and a played point sums the base and
    /// the targets scaled by their weights, `weight_sum` being the largest `Σ |w_j|` played; so
    /// `step = 2 max_error / (√3 (1 + weight_sum))`. `None` when signed shorts cannot hold the
    /// base's extent or the largest offset component (`largest_offset`) at that step, or when
    /// there is no budget: the file then stays f32.
    pub(crate) fn for_budget(base: &[[f32; 3]], largest_offset: f32, weight_sum: f64, max_error: f64) -> Option<Grid> {
        let step = 2.0 * max_error / (3f64.sqrt() * (1.0 + weight_sum.abs()));
        if !(step.is_finite() && step > 0.0) || base.is_empty() {
            return None;
        }
        let step = step as f32;
        let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
        for p in base {
            for a in 0..3 {
                (lo[a], hi[a]) = (lo[a].min(p[a]), hi[a].max(p[a]));
            }
        }
        let center: [f32; 3] = std::array::from_fn(|a| ((lo[a] as f64 + hi[a] as f64) / 2.0) as f32);
        let half = (0..3).map(|a| (hi[a] as f64 - center[a] as f64).max(center[a] as f64 - lo[a] as f64)).fold(largest_offset.abs() as f64, f64::max);
        // One step of margin for the rounding of the center.
        (half / step as f64 + 1.0 <= I16_MAX && half.is_finite()).then_some(Grid { step, center })
    }

    /// A point on the grid (relative to the center).
    pub fn point(&self, p: [f32; 3]) -> [i32; 3] {
        std::array::from_fn(|a| ((p[a] as f64 - self.center[a] as f64) / self.step as f64).round() as i32)
    }

    /// An offset on the grid.
    pub fn offset(&self, d: [f32; 3]) -> [i32; 3] {
        std::array::from_fn(|a| (d[a] as f64 / self.step as f64).round() as i32)
    }
}

/// The smallest signed type holding every component: `(I8, 1)` or `(I16, 2)`.
pub fn component(values: &[[i32; 3]]) -> (ComponentType, usize) {
    if values.iter().flatten().all(|&x| x.abs() <= I8_MAX) {
        (ComponentType::I8, 1)
    } else {
        (ComponentType::I16, 2)
    }
}

/// Little-endian bytes of `values` in components of `size` bytes; with `padded`, each vec3 is
/// followed by one zero component, so that every element starts on a 4-byte boundary (vertex
/// attributes, glTF 2.0 §3.6.2.4); without, tightly packed (sparse values).
pub(crate) fn vec3_bytes(values: &[[i32; 3]], size: usize, padded: bool) -> Vec<u8> {
    let mut out = Vec::with_capacity(values.len() * 4 * size);
    for v in values {
        for &x in v.iter().chain(padded.then_some(&0)) {
            match size {
                1 => out.push(x as i8 as u8),
                _ => out.extend((x as i16).to_le_bytes()),
            }
        }
    }
    out
}

/// Unit normals as normalized signed bytes, each vec3 padded to 4 bytes (`round(127 n)`: about
/// half a degree, below what shading shows).
pub(crate) fn normal_bytes(normals: &[[f32; 3]]) -> Vec<u8> {
    normals.iter().flat_map(|n| [n[0], n[1], n[2], 0.0]).map(|x| (x.clamp(-1.0, 1.0) * 127.0).round() as i8 as u8).collect()
}

/// UVs as normalized unsigned shorts (`round(65535 u)`), when every coordinate is in [0, 1]
/// (else `None`: tiling UVs stay f32, since undoing a range needs `KHR_texture_transform`).
pub(crate) fn uv_bytes(uvs: &[[f32; 2]]) -> Option<Vec<u8>> {
    uvs.iter()
        .flatten()
        .all(|x| (0.0..=1.0).contains(x))
        .then(|| uvs.iter().flatten().flat_map(|&x| ((x * 65535.0).round() as u16).to_le_bytes()).collect())
}

/// `min` and `max` per component of integer vec3s (glTF requires them to equal the stored values).
pub(crate) fn int_bounds(values: &[[i32; 3]]) -> ([i32; 3], [i32; 3]) {
    let mut lo = [i32::MAX; 3];
    let mut hi = [i32::MIN; 3];
    for v in values {
        for a in 0..3 {
            (lo[a], hi[a]) = (lo[a].min(v[a]), hi[a].max(v[a]));
        }
    }
    (lo, hi)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_step_meets_the_budget_and_shorts_hold_the_range() {
        let base = [[0.0, 0.0, 0.0], [2.0, 1.0, 0.5]];
        let g = Grid::for_budget(&base, 0.3, 1.0, 1e-3).unwrap();
        // √3/2 · step · (1 + 1) = budget.
        assert!((3f64.sqrt() / 2.0 * g.step as f64 * 2.0 - 1e-3).abs() < 1e-9);
        assert_eq!(g.center, [1.0, 0.5, 0.25]);
        for p in base {
            let q = g.point(p);
            let back: Vec<f64> = (0..3).map(|a| q[a] as f64 * g.step as f64 + g.center[a] as f64).collect();
            let err = (0..3).map(|a| (back[a] - p[a] as f64).powi(2)).sum::<f64>().sqrt();
            assert!(err <= 3f64.sqrt() / 2.0 * g.step as f64 + 1e-9);
        }
        // A budget too fine for shorts over this extent: no grid.
        assert!(Grid::for_budget(&base, 0.0, 1.0, 1e-6).is_none());
        assert!(Grid::for_budget(&base, 0.0, 1.0, 0.0).is_none());
    }

    #[test]
    fn bytes_are_padded_for_attributes_and_packed_for_sparse_values() {
        let v = [[1, -2, 300]];
        assert_eq!(component(&v), (ComponentType::I16, 2));
        assert_eq!(component(&[[1, -127, 127]]), (ComponentType::I8, 1));
        assert_eq!(vec3_bytes(&v, 2, true), vec![1, 0, 254, 255, 44, 1, 0, 0]);
        assert_eq!(vec3_bytes(&[[1, -2, 3]], 1, false), vec![1, 254, 3]);
        assert_eq!(normal_bytes(&[[0.0, -1.0, 1.0]]), vec![0, 129, 127, 0]);
        assert_eq!(uv_bytes(&[[0.0, 1.0]]), Some(vec![0, 0, 255, 255]));
        assert_eq!(uv_bytes(&[[0.0, 1.5]]), None);
    }
}
