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
    /// The base is stored as f32 in grid units (`(p - center) / step`, not rounded): a file with
    /// per-target steps (`per_target`), whose grid is the coarsest target's.
    pub float_base: bool,
}

/// How one morph target's offsets are stored in a quantized file.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Storage {
    /// Integers on the file's grid (`round(d / grid.step)`).
    Grid,
    /// Integers at their own step (scene units, at most the grid's): `round(d / step)`, the
    /// target's weights multiplied by `step / grid.step` so that the node's scale undoes it.
    Step(f32),
    /// f32 in grid units (`d / grid.step`): no rounding.
    Float,
}

impl Storage {
    /// The factor on the target's weights that makes the node's scale (the grid's step) undo
    /// this storage: `step / grid.step` for its own step, else 1.
    pub fn weight_scale(self, grid: &Grid) -> f64 {
        match self {
            Storage::Step(s) => s as f64 / grid.step as f64,
            _ => 1.0,
        }
    }
}

/// The bounding-box center of `base` and the largest distance of a coordinate from it.
fn center_and_half(base: &[[f32; 3]]) -> ([f32; 3], f64) {
    let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
    for p in base {
        for a in 0..3 {
            (lo[a], hi[a]) = (lo[a].min(p[a]), hi[a].max(p[a]));
        }
    }
    let center: [f32; 3] = std::array::from_fn(|a| ((lo[a] as f64 + hi[a] as f64) / 2.0) as f32);
    let half = (0..3).map(|a| (hi[a] as f64 - center[a] as f64).max(center[a] as f64 - lo[a] as f64)).fold(0.0, f64::max);
    (center, half)
}

/// Per-target steps, for a file that one grid cannot quantize (its shorts would not hold the
/// base's extent or the largest offset at the step the budget allows): the base stays f32 (it
/// adds no rounding), and each target gets the smallest type whose rounding fits the budget,
/// the budget spent where it buys most. Target `j`, stored in integers of at most `q` (127 for
/// bytes, 32767 for shorts) over its largest offset component `range_j`, has a step of at
/// least `range_j / q` and adds at most `√3/2 · wmax_j · step` to a played point, `wmax_j`
/// being its largest played `|w|`. Every target starts in f32; the moves f32 -> shorts and
/// shorts -> bytes (each saving 4 bytes per vertex) are taken cheapest first while the sum of
/// these bounds stays within `max_error`; the integer steps are then scaled by one factor
/// (>= 1) that spends the whole budget, the coarsest grid that meets it (what meshopt
/// compresses best). The file's grid is the coarsest target step, so that every target's
/// weight factor `step_j / grid.step` is at most 1 (weights in [0, 1] stay there). `None`
/// when no target can be an integer (the file then stays f32).
pub(crate) fn per_target(base: &[[f32; 3]], ranges: &[f32], weight_max: &[f64], max_error: f64) -> Option<(Grid, Vec<Storage>)> {
    if base.is_empty() || !(max_error.is_finite() && max_error > 0.0) {
        return None;
    }
    let cost: Vec<f64> = ranges.iter().zip(weight_max).map(|(&r, &w)| 3f64.sqrt() / 2.0 * w.abs() * r as f64).collect();
    // (bound added, target, largest integer): shorts before bytes for a target (cheaper).
    let mut moves: Vec<(f64, usize, f64)> = Vec::with_capacity(2 * ranges.len());
    for (j, &c) in cost.iter().enumerate().filter(|&(j, c)| ranges[j] > 0.0 && c.is_finite()) {
        moves.push((c / I16_MAX, j, I16_MAX));
        moves.push((c * (1.0 / I8_MAX as f64 - 1.0 / I16_MAX), j, I8_MAX as f64));
    }
    moves.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    let mut largest: Vec<Option<f64>> = vec![None; ranges.len()];
    let mut spent = 0.0;
    for (c, j, q) in moves {
        if spent + c > max_error {
            break;
        }
        spent += c;
        largest[j] = Some(q);
    }
    let bound: f64 = largest.iter().zip(&cost).filter_map(|(q, c)| q.map(|q| c / q)).sum();
    let spread = if bound > 0.0 { (max_error / bound).max(1.0) } else { 1.0 };
    let steps: Vec<Option<f32>> = largest.iter().zip(ranges).map(|(q, &r)| q.map(|q| (spread * r as f64 / q) as f32)).collect();
    let step = steps.iter().flatten().copied().fold(0.0f32, f32::max);
    if !(step.is_finite() && step > 0.0) {
        return None;
    }
    let (center, _) = center_and_half(base);
    let storage = steps.iter().zip(ranges).map(|(s, &r)| match s {
        Some(s) => Storage::Step(*s),
        None if r == 0.0 => Storage::Grid,
        None => Storage::Float,
    });
    Some((Grid { step, center, float_base: true }, storage.collect()))
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
        let (center, half) = center_and_half(base);
        let half = half.max(largest_offset.abs() as f64);
        // One step of margin for the rounding of the center.
        (half / step as f64 + 1.0 <= I16_MAX && half.is_finite()).then_some(Grid { step, center, float_base: false })
    }

    /// A point on the grid (relative to the center).
    pub fn point(&self, p: [f32; 3]) -> [i32; 3] {
        std::array::from_fn(|a| ((p[a] as f64 - self.center[a] as f64) / self.step as f64).round() as i32)
    }

    /// An offset on the grid.
    pub fn offset(&self, d: [f32; 3]) -> [i32; 3] {
        std::array::from_fn(|a| (d[a] as f64 / self.step as f64).round() as i32)
    }

    /// A point (`offset` false) or an offset stored as `storage` says (the base: as
    /// `float_base` says): integers, or f32 in grid units.
    pub(crate) fn store(&self, values: &[[f32; 3]], offset: bool, storage: Storage) -> Stored {
        let units = |v: [f32; 3], c: [f32; 3]| -> [f32; 3] { std::array::from_fn(|a| ((v[a] as f64 - c[a] as f64) / self.step as f64) as f32) };
        match (offset, storage) {
            (false, _) if self.float_base => Stored::Floats(values.iter().map(|&p| units(p, self.center)).collect()),
            (false, _) => Stored::Ints(values.iter().map(|&p| self.point(p)).collect()),
            (true, Storage::Grid) => Stored::Ints(values.iter().map(|&d| self.offset(d)).collect()),
            (true, Storage::Step(s)) => Stored::Ints(values.iter().map(|&d| d.map(|x| (x as f64 / s as f64).round() as i32)).collect()),
            (true, Storage::Float) => Stored::Floats(values.iter().map(|&d| units(d, [0.0; 3])).collect()),
        }
    }
}

/// The values of a vec3 accessor as stored: integers (their type chosen by [`component`]) or f32.
pub(crate) enum Stored {
    Ints(Vec<[i32; 3]>),
    Floats(Vec<[f32; 3]>),
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
    fn per_target_steps_spend_the_budget_on_the_smallest_targets_first() {
        let base = [[0.0, 0.0, 0.0], [2.0, 1.0, 0.5]];
        // A large target no short can hold within the budget, a middle one for shorts, a small
        // one for bytes, an empty one and one never played.
        let (ranges, weights) = ([1.0f32, 0.01, 1e-4, 0.0, 0.5], [1.0, 1.0, 1.0, 1.0, 0.0]);
        let budget = 2e-6;
        let (g, storage) = per_target(&base, &ranges, &weights, budget).unwrap();
        assert!(g.float_base);
        assert_eq!(g.center, [1.0, 0.5, 0.25]);
        assert_eq!(storage[0], Storage::Float);
        assert_eq!(storage[3], Storage::Grid);
        let step = |j: usize| match storage[j] {
            Storage::Step(s) => s as f64,
            other => panic!("target {j}: {other:?}"),
        };
        // Each integer target holds its range in its type; the played bound spends the budget.
        assert!(ranges[1] as f64 / step(1) <= I16_MAX + 0.5 && ranges[1] as f64 / step(1) > I8_MAX as f64);
        assert!(ranges[2] as f64 / step(2) <= I8_MAX as f64 + 0.5);
        let bound: f64 = [1, 2].iter().map(|&j| 3f64.sqrt() / 2.0 * weights[j] * step(j)).sum();
        assert!((bound - budget).abs() < 1e-6 * budget, "{bound} vs {budget}");
        // The grid is the coarsest step: every weight factor is at most 1.
        assert_eq!(g.step as f64, (0..5).filter(|&j| matches!(storage[j], Storage::Step(_))).map(step).fold(0.0, f64::max));
        assert!(storage.iter().all(|s| s.weight_scale(&g) <= 1.0));
        let Stored::Ints(q) = g.store(&[[1e-4, -5e-5, 0.0]], true, storage[2]) else { panic!("integers") };
        assert!(q[0][0].abs() <= I8_MAX);
        let Stored::Floats(f) = g.store(&[[1.0, 0.5, 0.25]], false, Storage::Grid) else { panic!("an f32 base") };
        assert_eq!(f[0], [0.0; 3]);
        // No budget, or nothing to store in integers: no grid.
        assert!(per_target(&base, &ranges, &weights, 0.0).is_none());
        assert!(per_target(&base, &[0.0], &[1.0], 1e-3).is_none());
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
