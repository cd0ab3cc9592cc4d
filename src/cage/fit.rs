//! Posing a cage from the fine keyframes, and carrying per-vertex masks to its nodes.
//!
//! The fine surface is bound to the cage at rest by barycentric weights `W` (fine = `W` cage,
//! exact at rest because the cage encloses the surface). A key pose `X` of the fine vertices
//! gives the cage pose `C = C₀ + U` whose embedding is closest to it:
//!
//! ```text
//! min_U |W U - (X - X₀)|² + λ Uᵀ G U
//! ```
//!
//! where `G` is the graph Laplacian of the cage's tet edges: a small smoothness term on the
//! displacement that decides the nodes no fine vertex constrains (deep interior nodes) and
//! keeps the system positive definite. `λ = SMOOTHNESS · tr(WᵀW) / tr(G)`, so the term is
//! scale free and small against the data. One factorization serves every key and coordinate.
//!
//! Masks: a cage node is held at a key when the fine vertices held there carry at least half
//! of the binding weight on that node (`Σ_{v held} w_va ≥ ½ Σ_v w_va > 0`); nodes no fine vertex
//! is bound to are free, like the interior nodes TetGen adds. When a mask holds some fine
//! vertices but no node reaches half, the node with the most weight from the held vertices is
//! held, so a pinned vertex still pins something.

use faer::sparse::{SparseColMat, Triplet};
use faer::Par;

use crate::embed::Binding;
use crate::mesh::{norm, sub, Point, TetMesh};
use crate::physics::cholesky::Cholesky;
use crate::physics::ordering::FillOrdering;

/// Weight of the smoothness term relative to the data term (see the module documentation).
pub const SMOOTHNESS: f64 = 1e-7;

/// The least-squares fit of cage poses to fine poses through a fixed binding.
pub struct CageFit<'a> {
    cage: &'a TetMesh,
    binding: &'a Binding,
    cholesky: Cholesky,
}

/// How closely the embedded cage keys reproduce the fine keys, relative to the fine rest
/// surface's bounding-box diagonal.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reproduction {
    pub max: f64,
    pub rms: f64,
}

impl<'a> CageFit<'a> {
    /// Prepare the fit for `binding` (of the fine points to `cage`).
    pub fn new(cage: &'a TetMesh, binding: &'a Binding) -> CageFit<'a> {
        let n = cage.positions.len();
        let mut triplets: Vec<Triplet<usize, usize, f64>> = Vec::new();
        let mut data_trace = 0.0;
        for (t, w) in binding.tets.iter().zip(&binding.weights) {
            let ids = cage.tets[*t as usize];
            for i in 0..4 {
                for j in 0..4 {
                    let (a, b) = (ids[i] as usize, ids[j] as usize);
                    if a >= b {
                        triplets.push(Triplet::new(a, b, w[i] * w[j]));
                    }
                }
                data_trace += w[i] * w[i];
            }
        }
        let mut edges: Vec<(u32, u32)> = cage
            .tets
            .iter()
            .flat_map(|t| (0..4).flat_map(move |i| (i + 1..4).map(move |j| (t[i].min(t[j]), t[i].max(t[j])))))
            .collect();
        edges.sort_unstable();
        edges.dedup();
        let lambda = SMOOTHNESS * data_trace.max(1.0) / (2.0 * edges.len().max(1) as f64);
        for &(a, b) in &edges {
            let (a, b) = (a as usize, b as usize);
            triplets.push(Triplet::new(a, a, lambda));
            triplets.push(Triplet::new(b, b, lambda));
            triplets.push(Triplet::new(b, a, -lambda));
        }
        // A tiny diagonal shift keeps a cage part without any bound vertex (impossible for a
        // cage built around the surface, but cheap to rule out) from being singular.
        for a in 0..n {
            triplets.push(Triplet::new(a, a, 1e-9 * lambda));
        }
        let lower = SparseColMat::<usize, f64>::try_new_from_triplets(n, n, &triplets).expect("valid triplets");
        let cholesky = Cholesky::factor(&lower, &FillOrdering::Amd, Par::Seq).expect("WᵀW + λG + εI is positive definite");
        CageFit { cage, binding, cholesky }
    }

    /// The cage pose whose embedding best matches `fine` (the fine points' pose), given the
    /// cage rest pose and the fine rest pose.
    pub fn pose(&self, cage_rest: &[Point], fine_rest: &[Point], fine: &[Point]) -> Vec<Point> {
        let mut rhs = vec![[0.0; 3]; self.cage.positions.len()];
        for (v, (t, w)) in self.binding.tets.iter().zip(&self.binding.weights).enumerate() {
            let d = sub(fine[v], fine_rest[v]);
            for (i, &a) in self.cage.tets[*t as usize].iter().enumerate() {
                for c in 0..3 {
                    rhs[a as usize][c] += w[i] * d[c];
                }
            }
        }
        self.cholesky.solve_rows3(&mut rhs);
        cage_rest.iter().zip(&rhs).map(|(p, u)| [p[0] + u[0], p[1] + u[1], p[2] + u[2]]).collect()
    }

    /// How far the embedding of the cage poses is from the fine poses, over all keys.
    pub fn reproduction(&self, cage_poses: &[Vec<Point>], fine_poses: &[Vec<Point>], diagonal: f64) -> Reproduction {
        let (mut max, mut sum, mut count) = (0.0f64, 0.0, 0usize);
        for (c, x) in cage_poses.iter().zip(fine_poses) {
            for (e, p) in self.binding.apply(self.cage, c).iter().zip(x) {
                let d = norm(sub(*e, *p));
                max = max.max(d);
                sum += d * d;
                count += 1;
            }
        }
        let scale = if diagonal > 0.0 { 1.0 / diagonal } else { 1.0 };
        Reproduction { max: max * scale, rms: (sum / count.max(1) as f64).sqrt() * scale }
    }
}

/// The binding weight each cage node carries (`Σ_v w_va`).
pub fn bound_weight(cage: &TetMesh, binding: &Binding) -> Vec<f64> {
    let mut weight = vec![0.0; cage.positions.len()];
    for (t, w) in binding.tets.iter().zip(&binding.weights) {
        for (i, &a) in cage.tets[*t as usize].iter().enumerate() {
            weight[a as usize] += w[i];
        }
    }
    weight
}

/// The cage nodes a fine-vertex mask holds (the rule of the module documentation).
pub fn carry_mask(cage: &TetMesh, binding: &Binding, fine_mask: &[bool]) -> Vec<bool> {
    let n = cage.positions.len();
    let (mut held, mut total) = (vec![0.0; n], vec![0.0; n]);
    for (v, (t, w)) in binding.tets.iter().zip(&binding.weights).enumerate() {
        for (i, &a) in cage.tets[*t as usize].iter().enumerate() {
            total[a as usize] += w[i];
            if fine_mask[v] {
                held[a as usize] += w[i];
            }
        }
    }
    let mut mask: Vec<bool> = (0..n).map(|a| total[a] > 0.0 && held[a] >= 0.5 * total[a]).collect();
    if !mask.iter().any(|&m| m) && fine_mask.iter().any(|&m| m) {
        let best = (0..n).max_by(|&a, &b| held[a].total_cmp(&held[b]).then(b.cmp(&a))).expect("a cage has nodes");
        mask[best] = true;
    }
    mask
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::cube_mesh;

    fn fine_points() -> Vec<Point> {
        let mut points = Vec::new();
        for i in 0..7 {
            for j in 0..7 {
                points.push([0.05 + 0.15 * i as f64, 0.05 + 0.15 * j as f64, 0.5 + 0.3 * ((i + j) % 2) as f64]);
            }
        }
        points
    }

    #[test]
    fn an_affine_motion_is_reproduced_exactly() {
        let cage = cube_mesh(3);
        let fine = fine_points();
        let binding = Binding::compute(&cage, &fine);
        let fit = CageFit::new(&cage, &binding);
        let affine = |p: Point| [1.1 * p[0] + 0.2 * p[1] + 0.3, 0.9 * p[1] - 0.1 * p[2], p[2] + 0.05 * p[0] - 1.0];
        let moved: Vec<Point> = fine.iter().map(|&p| affine(p)).collect();
        let pose = fit.pose(&cage.positions, &fine, &moved);
        let r = fit.reproduction(&[pose], &[moved], 1.0);
        assert!(r.max < 1e-7, "{r:?}");
    }

    #[test]
    fn the_rest_pose_is_the_cage_rest() {
        let cage = cube_mesh(2);
        let fine = fine_points();
        let binding = Binding::compute(&cage, &fine);
        let fit = CageFit::new(&cage, &binding);
        assert_eq!(fit.pose(&cage.positions, &fine, &fine), cage.positions);
    }

    #[test]
    fn masks_carry_by_majority_and_a_lone_pin_still_pins() {
        let cage = cube_mesh(2);
        let fine = fine_points();
        let binding = Binding::compute(&cage, &fine);
        // Hold the fine points with x < 0.5: the cage nodes at x = 0 carry only those.
        let mask: Vec<bool> = fine.iter().map(|p| p[0] < 0.5).collect();
        let held = carry_mask(&cage, &binding, &mask);
        for (a, p) in cage.positions.iter().enumerate() {
            if p[0] == 0.0 && bound_weight(&cage, &binding)[a] > 0.0 {
                assert!(held[a], "node {a} at {p:?}");
            }
            if p[0] == 1.0 {
                assert!(!held[a], "node {a} at {p:?}");
            }
        }
        let mut one = vec![false; fine.len()];
        one[10] = true;
        assert_eq!(carry_mask(&cage, &binding, &one).iter().filter(|&&m| m).count(), 1);
        assert!(!carry_mask(&cage, &binding, &vec![false; fine.len()]).iter().any(|&m| m));
    }
}
