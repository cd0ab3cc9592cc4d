//! Method "fit": the cubic Hermite trajectory on given keys that best fits a vertex cache in
//! least squares, with no physics.
//!
//! Unknowns per vertex and coordinate: every key position `x_k` and velocity `v_k` (key
//! positions may be pinned to the cache frame instead). The fit minimizes
//!
//! ```text
//! E = Σ_f |x(t_f) - y_f|²
//! ```
//!
//! over every cache frame `f` from the first key to the last. `x(t_f)` is linear in the
//! unknowns with the same weights for every vertex and coordinate, so the normal matrix `N` is
//! one small banded `2K x 2K` matrix (`K` keys, unknowns ordered `x_0, v_0, x_1, v_1, ...`,
//! half-bandwidth 3), factored once; the cache is streamed once to accumulate the right-hand
//! sides (`K x vertices x 6` doubles), then all of them are solved together.
//!
//! Where the frames leave unknowns undetermined (two keys on adjacent frames have no frame
//! between them to fix their velocities), the fit takes the least-bending curve: a tiny term
//! `λ Σ_i T_i³ ∫_i |x''|² dt` (dimensionless like the data term) is added to the factored
//! matrix, and the solution is then refined with the residual of the plain least squares, so
//! that it decides only what the frames do not (see `NormalEquations::solve`). `λ = 0` is
//! the plain least squares, and an undetermined velocity is then an error.
//!
//! Velocity unknowns are scaled by a per-key time `τ_k` (the mean length of the intervals at
//! the key), so every entry of the normal matrix is dimensionless and O(1) whatever the frame
//! rate and key spacing.

use std::collections::BTreeMap;

use super::band::{axpy, Band, NotPositiveDefinite};
use super::FrameSource;
use crate::algorithms::geometry::Point;
use crate::algorithms::spacetime::trajectory::{hermite_weights, Trajectory};
use crate::support::error::{Error, Result};

/// Settings of the least-squares fit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FitSettings {
    /// Weight `λ >= 0` of the bending term that fills what the frames do not determine.
    pub regularization: f64,
}

impl Default for FitSettings {
    fn default() -> Self {
        FitSettings { regularization: 1e-9 }
    }
}

/// The least-squares fit of a Hermite trajectory on `keys` (frame indices of `source`, strictly
/// increasing, at least two) to every frame from the first key to the last.
///
/// `pins` is empty, or one vertex mask per key (each empty, or one flag per vertex): a flagged
/// vertex keeps the cache position at that key and only its velocity is fitted. Frames outside
/// the key range are not part of the fit (the trajectory holds its end poses there).
pub fn fit<S: FrameSource + ?Sized>(source: &mut S, keys: &[usize], pins: &[Vec<bool>], settings: &FitSettings) -> Result<Trajectory> {
    check_keys(source, keys)?;
    let vertices = source.vertex_count();
    check_pins(pins, keys.len(), vertices)?;
    if !(settings.regularization >= 0.0 && settings.regularization.is_finite()) {
        return Err(Error::general(
            format!("the fit regularization {} is not a finite number >= 0", settings.regularization),
            "use the default (1e-9), or 0 for the plain least squares",
        ));
    }
    let times: Vec<f64> = keys.iter().map(|&f| source.time(f)).collect();
    let mut system = NormalEquations::new(times, vertices, settings.regularization);
    let pinned_keys: Vec<bool> = (0..keys.len()).map(|k| pins.get(k).is_some_and(|m| m.iter().any(|&p| p))).collect();
    let mut key_frames: Vec<Option<Vec<Point>>> = vec![None; keys.len()];
    let mut frame = vec![[0.0; 3]; vertices];
    for f in keys[0]..=keys[keys.len() - 1] {
        source.read_frame(f, &mut frame)?;
        system.add_frame(source.time(f), &frame);
        if let Ok(k) = keys.binary_search(&f) {
            if pinned_keys[k] {
                key_frames[k] = Some(frame.clone());
            }
        }
    }
    // Group vertices by the set of keys that pin them: one factorization per group.
    let mut pattern_index: BTreeMap<Vec<bool>, usize> = BTreeMap::new();
    let mut patterns: Vec<Vec<bool>> = Vec::new();
    let mut vertex_pattern = Vec::with_capacity(vertices);
    for v in 0..vertices {
        let fixed: Vec<bool> = (0..keys.len()).flat_map(|k| [pins.get(k).is_some_and(|m| m.get(v) == Some(&true)), false]).collect();
        let next = patterns.len();
        let p = *pattern_index.entry(fixed.clone()).or_insert(next);
        if p == next {
            patterns.push(fixed);
        }
        vertex_pattern.push(p);
    }
    let fixed_value = |row: usize, column: usize| -> f64 {
        // Only position rows are ever fixed here.
        key_frames[row / 2].as_ref().expect("pinned keys were captured")[column / 3][column % 3]
    };
    let solution = system.solve(&patterns, &vertex_pattern, &fixed_value).map_err(|e| singular(e, keys))?;
    Ok(solution)
}

fn singular(e: NotPositiveDefinite, keys: &[usize]) -> Error {
    let k = (e.row / 2).min(keys.len() - 1);
    Error::general(
        format!(
            "the Hermite fit cannot determine the {} of the key at frame {} (normal equations singular, relative pivot {:.1e})",
            if e.row.is_multiple_of(2) { "position" } else { "velocity" },
            keys[k],
            e.pivot
        ),
        "leave at least two cache frames between keys, or use a positive fit regularization",
    )
}

/// Keys must be strictly increasing frame indices of the source, at least two.
pub(crate) fn check_keys<S: FrameSource + ?Sized>(source: &S, keys: &[usize]) -> Result<()> {
    let frames = source.frame_count();
    if keys.len() < 2 {
        return Err(Error::general(
            format!("a Hermite fit needs at least 2 keys, got {}", keys.len()),
            "list at least the first and last frame as keys, or use keyframes = \"auto\"",
        ));
    }
    if let Some(&bad) = keys.iter().find(|&&f| f >= frames) {
        return Err(Error::general(
            format!("key frame {bad} is past the end of the cache ({frames} frames, 0 to {})", frames.saturating_sub(1)),
            "list frame indices between 0 and the last frame",
        ));
    }
    if let Some(w) = keys.windows(2).find(|w| w[1] <= w[0]) {
        return Err(Error::general(
            format!("key frames must be strictly increasing, but {} is followed by {}", w[0], w[1]),
            "list each key frame once, in increasing order",
        ));
    }
    Ok(())
}

fn check_pins(pins: &[Vec<bool>], keys: usize, vertices: usize) -> Result<()> {
    if !pins.is_empty() && pins.len() != keys {
        return Err(Error::general(format!("{} pin masks for {keys} keys", pins.len()), "give one vertex mask per key, or none"));
    }
    if let Some((k, m)) = pins.iter().enumerate().find(|(_, m)| !m.is_empty() && m.len() != vertices) {
        return Err(Error::general(
            format!("the pin mask of key {k} has {} entries for {vertices} vertices", m.len()),
            "give one flag per cache vertex, or an empty mask",
        ));
    }
    Ok(())
}

/// Normal equations of a Hermite fit on fixed key times, accumulated frame by frame: one
/// banded matrix shared by every column (vertex coordinate), one right-hand side per column.
///
/// Row `2k` is key `k`'s position, row `2k + 1` its scaled velocity `τ_k v_k`.
pub(crate) struct NormalEquations {
    times: Vec<f64>,
    /// `τ_k`: the mean length of the intervals at key `k`.
    scale: Vec<f64>,
    columns: usize,
    /// `Σ_f w_f w_fᵀ` over the frames added.
    data: Band,
    /// `λ R`: the bending term.
    bending: Band,
    /// `rhs[row * columns + column] = Σ_f w_f[row] y_f[column]`.
    rhs: Vec<f64>,
}

/// Columns solved at once: bounds the solver's scratch memory whatever the vertex count.
const CHUNK_COLUMNS: usize = 3 * 512;

/// Refinement steps towards the plain least squares (see `NormalEquations::solve`).
const REFINEMENT_STEPS: usize = 2;

impl NormalEquations {
    /// The bending term is set up at once; frames are added with [`NormalEquations::add_frame`].
    pub fn new(times: Vec<f64>, vertices: usize, regularization: f64) -> NormalEquations {
        let keys = times.len();
        assert!(keys >= 2 && times.windows(2).all(|w| w[1] > w[0]), "key times must be strictly increasing");
        let lengths: Vec<f64> = times.windows(2).map(|w| w[1] - w[0]).collect();
        let scale = (0..keys)
            .map(|k| match (k.checked_sub(1), (k + 1 < keys).then_some(k)) {
                (Some(a), Some(b)) => 0.5 * (lengths[a] + lengths[b]),
                (Some(a), None) => lengths[a],
                (None, Some(b)) => lengths[b],
                (None, None) => unreachable!("at least two keys"),
            })
            .collect();
        let columns = 3 * vertices;
        let n = 2 * keys;
        let mut normal = NormalEquations { times, scale, columns, data: Band::zeros(n, 3), bending: Band::zeros(n, 3), rhs: vec![0.0; n * columns] };
        if regularization > 0.0 {
            // ∫ over the interval of a quadratic (x'' is linear): 2-point Gauss is exact.
            let g = 0.5 / 3f64.sqrt();
            for (i, &t) in lengths.iter().enumerate() {
                for theta in [0.5 - g, 0.5 + g] {
                    let a = normal.scaled(i, hermite_weights(theta, t).acc);
                    add_outer(&mut normal.bending, i, &a, regularization * t.powi(3) * 0.5 * t);
                }
            }
        }
        normal
    }

    pub fn keys(&self) -> usize {
        self.times.len()
    }

    /// Basis weights in scaled unknowns: velocity slots divided by their key's `τ`.
    fn scaled(&self, i: usize, w: [f64; 4]) -> [f64; 4] {
        [w[0], w[1] / self.scale[i], w[2], w[3] / self.scale[i + 1]]
    }

    /// The interval holding `t` (clamped to the key range) and the weights of its four unknowns
    /// (rows `2i .. 2i + 4`) in the position at `t`.
    pub fn weights(&self, t: f64) -> (usize, [f64; 4]) {
        let n = self.times.len();
        let t = t.clamp(self.times[0], self.times[n - 1]);
        let i = self.times[..n - 1].partition_point(|&s| s <= t).saturating_sub(1);
        let len = self.times[i + 1] - self.times[i];
        let theta = ((t - self.times[i]) / len).clamp(0.0, 1.0);
        (i, self.scaled(i, hermite_weights(theta, len).pos))
    }

    /// Add the frame at time `t` with positions `y` (one per vertex).
    pub fn add_frame(&mut self, t: f64, y: &[Point]) {
        assert_eq!(3 * y.len(), self.columns, "frame vertex count");
        let (i, w) = self.weights(t);
        add_outer(&mut self.data, i, &w, 1.0);
        let flat = y.as_flattened();
        for (j, &wj) in w.iter().enumerate() {
            if wj != 0.0 {
                let row = 2 * i + j;
                axpy(wj, flat, &mut self.rhs[row * self.columns..(row + 1) * self.columns]);
            }
        }
    }

    /// Solve for every column and return the trajectory.
    ///
    /// Vertex `v` follows constraint pattern `patterns[vertex_pattern[v]]`: one flag per row,
    /// true where the unknown is fixed; a fixed row takes `fixed_value(row, column)` (a
    /// position, or a true velocity for odd rows). Each pattern is factored once.
    ///
    /// The system solved is the plain least squares `N u = b` on the free rows. The bending
    /// term only breaks ties: the factored matrix is `N + λR`, whose solution is then refined
    /// with the residual of `N` ([`REFINEMENT_STEPS`] steps of iterated Tikhonov). Directions
    /// the frames determine converge to the least squares (the bias shrinks by `O(λ)` per
    /// step); directions they leave free keep the least-bending value, as no residual drives
    /// them.
    pub fn solve(
        mut self,
        patterns: &[Vec<bool>],
        vertex_pattern: &[usize],
        fixed_value: &dyn Fn(usize, usize) -> f64,
    ) -> Result<Trajectory, NotPositiveDefinite> {
        let (n, columns, vertices) = (2 * self.keys(), self.columns, self.columns / 3);
        assert_eq!(vertex_pattern.len(), vertices);
        let value = |row: usize, column: usize| {
            let x = fixed_value(row, column);
            if row % 2 == 1 {
                x * self.scale[row / 2]
            } else {
                x
            }
        };
        let mut full = self.data.clone();
        full.add_band(&self.bending);
        let mut members: Vec<Vec<usize>> = vec![Vec::new(); patterns.len()];
        for (v, &p) in vertex_pattern.iter().enumerate() {
            members[p].push(v);
        }
        let mut rhs = std::mem::take(&mut self.rhs);
        for (fixed, vs) in patterns.iter().zip(&members) {
            if vs.is_empty() {
                continue;
            }
            assert_eq!(fixed.len(), n);
            let free: Vec<usize> = (0..n).filter(|&r| !fixed[r]).collect();
            let keep: Vec<bool> = fixed.iter().map(|&f| !f).collect();
            let (data_ff, chol) = if free.is_empty() {
                (None, None)
            } else {
                let chol = full.submatrix(&keep).cholesky().map_err(|e| NotPositiveDefinite { row: free[e.row], ..e })?;
                (Some(self.data.submatrix(&keep)), Some(chol))
            };
            // Columns of this group, in chunks.
            let group_columns: Vec<usize> = vs.iter().flat_map(|&v| 3 * v..3 * v + 3).collect();
            for chunk in group_columns.chunks(CHUNK_COLUMNS) {
                let cols = chunk.len();
                if let (Some(data_ff), Some(chol)) = (&data_ff, &chol) {
                    // g = b_F - N_FP c_P (least squares), g_full = b_F - (N + λR)_FP c_P.
                    let mut g = vec![0.0; free.len() * cols];
                    let mut g_full = vec![0.0; free.len() * cols];
                    for (a, &r) in free.iter().enumerate() {
                        for (c, &col) in chunk.iter().enumerate() {
                            let (mut s, mut s_full) = (rhs[r * columns + col], rhs[r * columns + col]);
                            for q in r.saturating_sub(3)..(r + 4).min(n) {
                                if fixed[q] {
                                    let x = value(q, col);
                                    s -= self.data.get(r, q) * x;
                                    s_full -= full.get(r, q) * x;
                                }
                            }
                            g[a * cols + c] = s;
                            g_full[a * cols + c] = s_full;
                        }
                    }
                    let mut u = g_full;
                    chol.solve_rows(&mut u, cols);
                    if self.bending.any_nonzero() {
                        for _ in 0..REFINEMENT_STEPS {
                            let mut step = g.clone();
                            let mut nu = vec![0.0; u.len()];
                            data_ff.mul_add_rows(&u, &mut nu, cols);
                            step.iter_mut().zip(&nu).for_each(|(s, x)| *s -= x);
                            chol.solve_rows(&mut step, cols);
                            u.iter_mut().zip(&step).for_each(|(x, s)| *x += s);
                        }
                    }
                    for (a, &r) in free.iter().enumerate() {
                        for (c, &col) in chunk.iter().enumerate() {
                            rhs[r * columns + col] = u[a * cols + c];
                        }
                    }
                }
                for r in (0..n).filter(|&r| fixed[r]) {
                    for &col in chunk {
                        rhs[r * columns + col] = value(r, col);
                    }
                }
            }
        }
        let keys = self.keys();
        let row = |r: usize, s: f64| -> Vec<Point> {
            rhs[r * columns..(r + 1) * columns].chunks_exact(3).map(|p| [p[0] / s, p[1] / s, p[2] / s]).collect()
        };
        Ok(Trajectory {
            positions: (0..keys).map(|k| row(2 * k, 1.0)).collect(),
            velocities: (0..keys).map(|k| row(2 * k + 1, self.scale[k])).collect(),
            times: self.times,
        })
    }
}

/// `A += c w wᵀ` on the unknowns of interval `i`.
fn add_outer(a: &mut Band, i: usize, w: &[f64; 4], c: f64) {
    for p in 0..4 {
        for q in 0..=p {
            a.add(2 * i + p, 2 * i + q, c * w[p] * w[q]);
        }
    }
}

#[cfg(test)]
mod tests;
