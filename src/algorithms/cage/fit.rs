//! Posing a cage from the fine keyframes, and carrying per-vertex masks to its nodes.
//!
//! The fine surface is bound to the cage at rest by barycentric weights `W` (fine = `W` cage,
//! exact at rest because the cage encloses the surface). A key pose `X` of the fine vertices
//! gives the cage pose `C` whose embedding is closest to it, regularized by the cage's own
//! projective-dynamics elastic energy:
//!
//! ```text
//! min_C |W C - X|² + μ E(C),   E(C) = ½ Σ_e w_e |G_e C - P_e(C)|²
//! ```
//!
//! by local/global iterations (projections `P_e` of the current pose, then the linear solve
//! `(WᵀW + μ L) C = Wᵀ X + μ J p`; one factorization serves every iteration, key and
//! coordinate). The elastic term decides the nodes no fine vertex constrains (the cage's
//! interior) and keeps weakly constrained ones from flying off, and costs nothing for rigid
//! motions, so rotated parts are not shrunk the way a Laplacian of the displacement would
//! shrink them. `μ = ELASTIC · tr(WᵀW) / tr(L)` makes it scale free and small against the data.
//!
//! Masks: a cage node is held at a key when the fine vertices held there carry at least half
//! of the binding weight on that node (`Σ_{v held} w_va ≥ ½ Σ_v w_va > 0`); nodes no fine vertex
//! is bound to are free, like the interior nodes TetGen adds. When a mask holds some fine
//! vertices but no node reaches half, the node with the most weight from the held vertices is
//! held, so a pinned vertex still pins something.

use faer::sparse::{SparseColMat, Triplet};
use faer::Par;

use crate::algorithms::embed::Binding;
use crate::algorithms::geometry::{norm, sub, Point, TetMesh};
use crate::algorithms::physics::cholesky::Cholesky;
use crate::algorithms::physics::elastic::Elastic;
use crate::algorithms::physics::mat3::Mat3;
use crate::algorithms::physics::ordering::FillOrdering;

/// Weight of the elastic term against the data term, as a ratio of their traces (see the
/// module documentation).
pub const ELASTIC: f64 = 1e-2;

/// Local/global iterations per key at most; they stop earlier when no node moves by more than
/// `1e-9` of the cage's size.
const ITERATIONS: usize = 200;

/// The cost model of [`CageFit::predicted_seconds`] (CPU seconds per cage tet and fine point,
/// per key; measured on cages of 735 nodes, 3k tets, around 200 to 120k fine points: 0.02 s to
/// 0.1 s per key).
const FIT_SECONDS_PER_TET: f64 = 7e-6;
const FIT_SECONDS_PER_POINT: f64 = 7e-7;

/// The fit of cage poses to fine poses through a fixed binding.
pub struct CageFit<'a> {
    cage: &'a TetMesh,
    binding: &'a Binding,
    elastic: &'a Elastic,
    /// The weight of the elastic term.
    mu: f64,
    cholesky: Cholesky,
}

/// How closely the embedded cage keys reproduce the fine keys, relative to the fine rest
/// surface's bounding-box diagonal.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reproduction {
    /// Largest distance of a fine vertex from its embedding in the cage, over every key.
    pub max: f64,
    /// Root mean square of those distances over every fine vertex and key.
    pub rms: f64,
}

impl<'a> CageFit<'a> {
    /// Prepare the fit for `binding` (of the fine points to `cage`), regularized by the cage's
    /// elastic energy `elastic` (built on `cage`).
    pub fn new(cage: &'a TetMesh, binding: &'a Binding, elastic: &'a Elastic) -> CageFit<'a> {
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
        let l = &elastic.stiffness;
        let elastic_trace: f64 = (0..n).map(|a| l.get(a, a)).sum();
        let mu = ELASTIC * data_trace.max(1.0) / elastic_trace;
        for b in 0..n {
            for (a, v) in l.row(b) {
                if a >= b {
                    triplets.push(Triplet::new(a, b, mu * v));
                }
            }
        }
        let lower = SparseColMat::<usize, f64>::try_new_from_triplets(n, n, &triplets).expect("valid triplets");
        // L is singular only for translations, which the data term (every part of a cage holds
        // fine vertices) removes.
        let cholesky = Cholesky::factor(&lower, &FillOrdering::Amd, Par::Seq).expect("WᵀW + μL is positive definite");
        CageFit { cage, binding, elastic, mu, cholesky }
    }

    /// Seconds the fit of `keys` keys is predicted to take for a cage of `cage_tets` tets and
    /// `points` fine points (for the progress bar's estimate; measured by `cargo bench --bench
    /// demo -- models`): the factorization, then per key the local/global iterations.
    pub fn predicted_seconds(cage_tets: usize, points: usize, keys: usize) -> f64 {
        FIT_SECONDS_PER_TET * cage_tets as f64 * keys as f64 + FIT_SECONDS_PER_POINT * points as f64 * keys as f64
    }

    /// The cage pose whose embedding best matches `fine` (the fine points' pose) under the
    /// elastic regularization, by local/global iterations from the cage's rest pose; the fine
    /// rest pose gives the cage rest pose.
    pub fn pose(&self, fine_rest: &[Point], fine: &[Point]) -> Vec<Point> {
        let rest = &self.cage.positions;
        if fine == fine_rest {
            return rest.clone();
        }
        let n = rest.len();
        // Wᵀ X, fixed over the iterations.
        let mut data = vec![[0.0; 3]; n];
        for (v, (t, w)) in self.binding.tets.iter().zip(&self.binding.weights).enumerate() {
            for (i, &a) in self.cage.tets[*t as usize].iter().enumerate() {
                for c in 0..3 {
                    data[a as usize][c] += w[i] * fine[v][c];
                }
            }
        }
        let tolerance = 1e-9 * crate::algorithms::geometry::bbox_diagonal(rest);
        let mut x = rest.clone();
        let mut targets: Vec<Mat3> = vec![[[0.0; 3]; 3]; self.elastic.tet_count()];
        let mut jp = vec![[0.0; 3]; n];
        for _ in 0..ITERATIONS {
            self.elastic.local_step(&x, &mut targets);
            self.elastic.apply_j(&targets, &mut jp);
            let mut rhs = faer::Mat::<f64>::from_fn(n, 3, |a, c| data[a][c] + self.mu * jp[a][c]);
            self.cholesky.solve_in_place(rhs.as_mut());
            let next: Vec<Point> = (0..n).map(|a| [rhs[(a, 0)], rhs[(a, 1)], rhs[(a, 2)]]).collect();
            let moved = x.iter().zip(&next).map(|(a, b)| norm(sub(*a, *b))).fold(0.0, f64::max);
            x = next;
            if moved <= tolerance {
                break;
            }
        }
        x
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
#[cfg(test)]
fn bound_weight(cage: &TetMesh, binding: &Binding) -> Vec<f64> {
    let mut weight = vec![0.0; cage.positions.len()];
    for (t, w) in binding.tets.iter().zip(&binding.weights) {
        for (i, &a) in cage.tets[*t as usize].iter().enumerate() {
            weight[a as usize] += w[i];
        }
    }
    weight
}

/// The cage nodes a fine-vertex mask holds (the rule of the module documentation).
pub(crate) fn carry_mask(cage: &TetMesh, binding: &Binding, fine_mask: &[bool]) -> Vec<bool> {
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
    use crate::algorithms::testing::cube_mesh;

    fn fine_points() -> Vec<Point> {
        let mut points = Vec::new();
        for i in 0..7 {
            for j in 0..7 {
                points.push([0.05 + 0.15 * i as f64, 0.05 + 0.15 * j as f64, 0.5 + 0.3 * ((i + j) % 2) as f64]);
            }
        }
        points
    }

    fn elastic(cage: &TetMesh) -> Elastic {
        Elastic::new(cage, &crate::algorithms::physics::elastic::Material { stiffness: 70.0, volume: 70.0, density: 1.0 }).unwrap()
    }

    #[test]
    fn a_rigid_motion_is_reproduced_exactly_and_moves_every_node_rigidly() {
        let cage = cube_mesh(3);
        let fine = fine_points();
        let binding = Binding::compute(&cage, &fine);
        let el = elastic(&cage);
        let fit = CageFit::new(&cage, &binding, &el);
        let (s, c) = 1.3f64.sin_cos();
        let rigid = |p: Point| [c * p[0] - s * p[2] + 0.3, p[1] - 2.0, s * p[0] + c * p[2]];
        let moved: Vec<Point> = fine.iter().map(|&p| rigid(p)).collect();
        let pose = fit.pose(&fine, &moved);
        let r = fit.reproduction(std::slice::from_ref(&pose), &[moved], 1.0);
        assert!(r.max < 1e-7, "{r:?}");
        // Nodes no fine point constrains follow too: a rigid motion costs no elastic energy.
        for (a, p) in cage.positions.iter().enumerate() {
            assert!(norm(sub(pose[a], rigid(*p))) < 1e-6, "node {a}");
        }
    }

    #[test]
    fn a_stretch_is_reproduced_closely_and_the_rest_pose_exactly() {
        let cage = cube_mesh(3);
        let fine = fine_points();
        let binding = Binding::compute(&cage, &fine);
        let el = elastic(&cage);
        let fit = CageFit::new(&cage, &binding, &el);
        assert_eq!(fit.pose(&fine, &fine), cage.positions);
        let moved: Vec<Point> = fine.iter().map(|&p| [1.2 * p[0], p[1], p[2]]).collect();
        let pose = fit.pose(&fine, &moved);
        let r = fit.reproduction(&[pose], &[moved], 1.0);
        assert!(r.max < 2e-3, "{r:?}");
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
