//! Quasi-static equilibrium: positions of the free nodes that minimize the elastic energy
//! with the pinned nodes held, by local/global projective-dynamics iterations.
//!
//! Used to give the interior nodes TetGen adds a keyframe pose that matches each keyframe
//! surface (instead of leaving them at the rest pose). Each iteration minimizes `E` exactly
//! over the projections (local step) and then over the free positions (global step), so `E`
//! decreases monotonically; the free-free block of `L` is factorized once and reused for
//! every keyframe.
//!
//! [`loaded_equilibrium`] is the static pose under nodal forces (a bent key a body can hold:
//! its stretch along the bend is its own, not a linear shape's), by Newton steps with the
//! tangent stiffness at rest. Local/global iterations would do too, but `L` resists the
//! elements' rotation that bending is made of, so they crawl there (a rate of about
//! `1 - λ_tangent / λ_L` per iteration, near 1 on a slender bar).

use faer::sparse::{SparseColMat, SymbolicSparseColMat};
use faer::{Mat, Par};

use super::cholesky::Cholesky;
use super::elastic::Elastic;
use super::mat3::Mat3;
use super::ordering::FillOrdering;
use super::vibration::{rest_stiffness, RestStiffness};
use crate::algorithms::geometry::Point;
use crate::support::error::{Error, Result};

/// Quasi-static equilibria with one set of pinned nodes: the free-free block of `L`,
/// factorized once and reused for every pose.
pub(crate) struct Equilibrium<'a> {
    elastic: &'a Elastic,
    /// Index among the free nodes, or `None` for pinned nodes.
    free: Vec<Option<usize>>,
    free_nodes: Vec<usize>,
    cholesky: Option<Cholesky>,
}

/// How an equilibrium solve ended.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EquilibriumInfo {
    /// Iterations taken.
    pub iterations: usize,
    /// Largest node move in the last iteration.
    pub last_move: f64,
}

impl<'a> Equilibrium<'a> {
    /// Prepare for solves with the given nodes pinned.
    pub fn new(elastic: &'a Elastic, pinned: &[bool]) -> Result<Equilibrium<'a>> {
        let mut free = vec![None; pinned.len()];
        let mut free_nodes = Vec::new();
        for (a, &p) in pinned.iter().enumerate() {
            if !p {
                free[a] = Some(free_nodes.len());
                free_nodes.push(a);
            }
        }
        let cholesky = if free_nodes.is_empty() {
            None
        } else {
            // Lower triangle of L restricted to the free nodes, column by column.
            let l = &elastic.stiffness;
            let mut col_ptr = vec![0usize];
            let (mut rows, mut vals) = (Vec::new(), Vec::new());
            for &b in &free_nodes {
                for (a, v) in l.row(b) {
                    if let Some(i) = free[a] {
                        if a >= b {
                            rows.push(i);
                            vals.push(v);
                        }
                    }
                }
                col_ptr.push(rows.len());
            }
            let n = free_nodes.len();
            let a = SparseColMat::new(SymbolicSparseColMat::new_checked(n, n, col_ptr, None, rows), vals);
            Some(Cholesky::factor(&a, &FillOrdering::Amd, Par::Seq).map_err(|_| {
                Error::general(
                    "some interior nodes are not connected to any pinned surface node",
                    "check the tet mesh for loose pieces (every component needs surface vertices)",
                )
            })?)
        };
        Ok(Equilibrium { elastic, free, free_nodes, cholesky })
    }

    /// Move the free nodes of `positions` to equilibrium (pinned entries are read, not
    /// written). Starts from the harmonic extension of the pinned nodes.
    pub fn solve(&self, positions: &mut [Point], tolerance: f64, max_iterations: usize) -> EquilibriumInfo {
        let Some(chol) = &self.cholesky else { return EquilibriumInfo { iterations: 0, last_move: 0.0 } };
        let el = self.elastic;
        let n_free = self.free_nodes.len();
        let mut targets: Vec<Mat3> = vec![[[0.0; 3]; 3]; el.tet_count()];
        let mut jp = vec![[0.0; 3]; positions.len()];
        let mut info = EquilibriumInfo { iterations: 0, last_move: f64::INFINITY };
        // Iteration 0 uses zero projections: the harmonic extension of the pinned nodes.
        for iteration in 0..=max_iterations {
            if iteration > 0 {
                el.local_step(positions, &mut targets);
                el.apply_j(&targets, &mut jp);
            }
            // rhs = (J p - L_FP x_P) on the free nodes.
            let mut rhs = Mat::<f64>::zeros(n_free, 3);
            for (i, &a) in self.free_nodes.iter().enumerate() {
                let mut r = jp[a];
                for (b, v) in el.stiffness.row(a) {
                    if self.free[b].is_none() {
                        for d in 0..3 {
                            r[d] -= v * positions[b][d];
                        }
                    }
                }
                for d in 0..3 {
                    rhs[(i, d)] = r[d];
                }
            }
            chol.solve_in_place(rhs.as_mut());
            let mut moved: f64 = 0.0;
            for (i, &a) in self.free_nodes.iter().enumerate() {
                let new = [rhs[(i, 0)], rhs[(i, 1)], rhs[(i, 2)]];
                moved = moved.max(crate::algorithms::geometry::norm(crate::algorithms::geometry::sub(new, positions[a])));
                positions[a] = new;
            }
            info = EquilibriumInfo { iterations: iteration, last_move: moved };
            if iteration > 0 && moved <= tolerance {
                break;
            }
        }
        info
    }
}

/// The static pose of `elastic` under the nodal forces `load` with the nodes `held[a]` fixed:
/// the free nodes of `positions` (its start; held entries are read, not written) moved to where
/// `∇E(x) = f`, the minimum of the potential `E(x) - f·x`. Newton steps with the tangent
/// stiffness at rest `K` (factorized once: exact at small strains and rotations, a
/// contraction near them), each halved until the force imbalance `r = ∇E - f` on the free
/// nodes falls in the norm `rᵀ K⁻¹ r`; stops when no node moves more than `tolerance`. Errors when the held nodes leave the body
/// a free motion (the stiffness is then singular).
pub fn loaded_equilibrium(
    elastic: &Elastic,
    held: &[bool],
    load: &[Point],
    positions: &mut [Point],
    tolerance: f64,
    max_iterations: usize,
) -> Result<EquilibriumInfo> {
    let free_nodes: Vec<usize> = (0..elastic.node_count()).filter(|&a| !held[a]).collect();
    let mut index = vec![usize::MAX; elastic.node_count()];
    for (f, &a) in free_nodes.iter().enumerate() {
        index[a] = f;
    }
    // Lower triangle of K over the free coordinates (node-major, 3 per node), by columns:
    // column c of the lower part is row c's entries at or below the diagonal.
    let k = rest_stiffness(elastic, RestStiffness::Tangent);
    let n = 3 * free_nodes.len();
    let (mut col_ptr, mut rows, mut vals) = (vec![0usize], Vec::new(), Vec::new());
    for &a in &free_nodes {
        for i in 0..3 {
            let c = 3 * index[a] + i;
            for (r, v) in k.row(3 * a + i) {
                let b = index[r / 3];
                if b != usize::MAX && 3 * b + r % 3 >= c {
                    rows.push(3 * b + r % 3);
                    vals.push(v);
                }
            }
            col_ptr.push(rows.len());
        }
    }
    // Rows of the lower part must be sorted within each column: free nodes keep the order of
    // the nodes, so they are.
    let lower = SparseColMat::new(SymbolicSparseColMat::new_checked(n, n, col_ptr, None, rows), vals);
    let chol = Cholesky::factor(&lower, &FillOrdering::Amd, Par::Seq)
        .map_err(|_| Error::general("the held nodes leave the body free to move", "hold nodes that fix every rigid motion of each piece"))?;
    // The force imbalance r = ∇E - f on the free coordinates, the Newton step K⁻¹ r and the
    // merit rᵀ K⁻¹ r (the imbalance in the stiffness' inverse norm: bending a bar leaves axial
    // forces quadratic in the bend, far larger than the bending forces but cheap to relax, so
    // the plain norm of r would refuse the bending steps).
    let newton = |x: &[Point]| -> (Mat<f64>, f64) {
        let g = elastic.energy_gradient(x);
        let r = Mat::<f64>::from_fn(n, 1, |c, _| g[free_nodes[c / 3]][c % 3] - load[free_nodes[c / 3]][c % 3]);
        let mut step = r.clone();
        chol.solve_in_place(step.as_mut());
        let merit = (0..n).map(|c| r[(c, 0)] * step[(c, 0)]).sum::<f64>();
        (step, merit)
    };
    let (mut step, mut merit) = newton(positions);
    let mut info = EquilibriumInfo { iterations: 0, last_move: f64::INFINITY };
    for iteration in 1..=max_iterations {
        let mut scale = 1.0;
        let mut trial = positions.to_vec();
        loop {
            for (f, &a) in free_nodes.iter().enumerate() {
                trial[a] = std::array::from_fn(|d| positions[a][d] - scale * step[(3 * f + d, 0)]);
            }
            let (step_trial, merit_trial) = newton(&trial);
            // Past 40 halvings the step is round-off: take it (the move stops the loop).
            if merit_trial < merit || scale < 1e-12 {
                (step, merit) = (step_trial, merit_trial);
                break;
            }
            scale *= 0.5;
        }
        let moved = free_nodes
            .iter()
            .map(|&a| crate::algorithms::geometry::norm(crate::algorithms::geometry::sub(trial[a], positions[a])))
            .fold(0.0, f64::max);
        positions.copy_from_slice(&trial);
        info = EquilibriumInfo { iterations: iteration, last_move: moved };
        if moved <= tolerance {
            break;
        }
    }
    Ok(info)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::algorithms::physics::elastic::Material;
    use crate::algorithms::testing::cube_mesh;

    fn material() -> Material {
        Material { stiffness: 70.0, volume: 70.0, density: 1.0 }
    }

    fn boundary_mask(mesh: &crate::algorithms::geometry::TetMesh) -> Vec<bool> {
        mesh.positions.iter().map(|p| p.iter().any(|&c| c == 0.0 || c == 1.0)).collect()
    }

    #[test]
    fn rigidly_moved_boundary_gives_the_rigidly_moved_interior() {
        let mesh = cube_mesh(4);
        let el = Elastic::new(&mesh, &material()).unwrap();
        let pinned = boundary_mask(&mesh);
        let eq = Equilibrium::new(&el, &pinned).unwrap();
        let (s, c) = 0.8f64.sin_cos();
        let moved = |p: Point| [c * p[0] - s * p[1] + 2.0, s * p[0] + c * p[1], p[2] - 1.0];
        let mut x: Vec<Point> = mesh.positions.iter().enumerate().map(|(a, &p)| if pinned[a] { moved(p) } else { [0.0; 3] }).collect();
        let info = eq.solve(&mut x, 1e-12, 500);
        assert!(info.last_move <= 1e-12, "{info:?}");
        for (a, &p) in mesh.positions.iter().enumerate() {
            assert!(crate::algorithms::geometry::norm(crate::algorithms::geometry::sub(x[a], moved(p))) < 1e-9, "node {a}");
        }
        assert!(el.energy(&x) < 1e-16);
    }

    #[test]
    fn twisted_boundary_gives_a_low_energy_interior() {
        let mesh = cube_mesh(4);
        let el = Elastic::new(&mesh, &material()).unwrap();
        let pinned = boundary_mask(&mesh);
        let eq = Equilibrium::new(&el, &pinned).unwrap();
        let twist = |p: Point| {
            let (s, c) = (0.6 * p[1]).sin_cos();
            let (x, z) = (p[0] - 0.5, p[2] - 0.5);
            [c * x - s * z + 0.5, p[1], s * x + c * z + 0.5]
        };
        let mut x: Vec<Point> = mesh.positions.iter().map(|&p| twist(p)).collect();
        let e_twisted_interior = el.energy(&x);
        let info = eq.solve(&mut x, 1e-10, 2000);
        assert!(info.last_move <= 1e-10, "{info:?}");
        // The equilibrium is at most as stretched as the twist itself, and its gradient on the
        // free nodes vanishes.
        assert!(el.energy(&x) <= e_twisted_interior * (1.0 + 1e-9));
        let g = el.energy_gradient(&x);
        for (a, &p) in pinned.iter().enumerate() {
            if !p {
                assert!(crate::algorithms::geometry::norm(g[a]) < 1e-6, "node {a}: {:?}", g[a]);
            }
        }
    }

    /// A 4 x 1 x 1 bar (cube lattice stretched along x), end x = 0 held, and its first bending mode.
    fn bar() -> (Elastic, Vec<bool>, f64, Vec<Point>) {
        let mut mesh = cube_mesh(3);
        for p in &mut mesh.positions {
            p[0] *= 4.0;
        }
        let el = Elastic::new(&mesh, &material()).unwrap();
        let held: Vec<bool> = mesh.positions.iter().map(|p| p[0] == 0.0).collect();
        let modes = crate::algorithms::physics::vibration::natural_vibration(&el, &held, RestStiffness::Tangent, 1).unwrap();
        (el, held, modes.eigenvalues[0], modes.shapes[0].clone())
    }

    /// The largest node force imbalance `|∇E - f|` over the free nodes.
    fn imbalance(el: &Elastic, held: &[bool], x: &[Point], load: &[Point]) -> f64 {
        let g = el.energy_gradient(x);
        (0..x.len())
            .filter(|&a| !held[a])
            .map(|a| crate::algorithms::geometry::norm(crate::algorithms::geometry::sub(g[a], load[a])))
            .fold(0.0, f64::max)
    }

    #[test]
    fn a_small_modal_load_gives_the_mode_and_a_large_one_balances_without_stretching() {
        // The mode's inertial load λ M φ: its linear response is φ (K φ = λ M φ), so a small
        // multiple returns the same multiple of φ. A large one (tip moved by 15% of the
        // length) must still balance, and the bent bar nearly keeps its length, where φ
        // scaled up stretches it.
        let (el, held, lambda, phi) = bar();
        let tip: Vec<usize> = (0..el.node_count()).filter(|&a| el.rest[a][0] == 4.0).collect();
        let tip_y = |x: &[Point]| tip.iter().map(|&a| x[a][1] - el.rest[a][1]).sum::<f64>() / tip.len() as f64;
        let unit = 1.0 / tip_y(&el.rest.iter().zip(&phi).map(|(p, u)| std::array::from_fn(|d| p[d] + u[d])).collect::<Vec<Point>>());
        for tip_move in [1e-6, 0.2] {
            let s = tip_move * unit;
            let load: Vec<Point> = phi.iter().zip(&el.mass).map(|(u, m)| u.map(|c| s * lambda * m * c)).collect();
            let mut x = el.rest.clone();
            let info = loaded_equilibrium(&el, &held, &load, &mut x, 1e-12, 1000).unwrap();
            let force = load.iter().map(|f| crate::algorithms::geometry::norm(*f)).fold(0.0, f64::max);
            let residual = imbalance(&el, &held, &x, &load);
            println!(
                "tip load for {tip_move}: {} steps, last move {:.1e}, imbalance {:.1e} of the load, tip {}",
                info.iterations,
                info.last_move,
                residual / force,
                tip_y(&x)
            );
            // At the small load the imbalance is the projections' round-off (about 1e-12 of
            // the elastic forces of the rest shape's coordinates, 1e-6 of this load).
            assert!(info.last_move <= 1e-12 && residual < if tip_move < 1e-3 { 1e-4 } else { 1e-9 } * force, "{info:?}, imbalance {residual}");
            for a in (0..el.node_count()).filter(|&a| held[a]) {
                assert_eq!(x[a], el.rest[a]);
            }
            if tip_move < 1e-3 {
                let linear = (0..el.node_count())
                    .map(|a| {
                        crate::algorithms::geometry::norm(crate::algorithms::geometry::sub(
                            crate::algorithms::geometry::sub(x[a], el.rest[a]),
                            phi[a].map(|c| s * c),
                        ))
                    })
                    .fold(0.0, f64::max);
                assert!(linear < 1e-4 * tip_move, "off the mode by {linear}");
            } else {
                // The centroid line of the cross-sections stretches far less than along φ
                // scaled to the same tip (measured: 1.06e-3 vs 1.08e-2 of the length 4).
                let stations: Vec<f64> = (0..=3).map(|i| i as f64 / 3.0 * 4.0).collect();
                let length = |x: &[Point]| -> f64 {
                    let centroid = |s: f64| -> Point {
                        let nodes: Vec<usize> = (0..el.node_count()).filter(|&a| el.rest[a][0] == s).collect();
                        std::array::from_fn(|d| nodes.iter().map(|&a| x[a][d]).sum::<f64>() / nodes.len() as f64)
                    };
                    stations
                        .windows(2)
                        .map(|w| crate::algorithms::geometry::norm(crate::algorithms::geometry::sub(centroid(w[1]), centroid(w[0]))))
                        .sum()
                };
                let scaled: Vec<Point> = el.rest.iter().zip(&phi).map(|(p, u)| std::array::from_fn(|d| p[d] + tip_y(&x) * unit * u[d])).collect();
                let (bent, stretched) = (length(&x) - 4.0, length(&scaled) - 4.0);
                println!("centroid line: {bent:.3e} longer bent, {stretched:.3e} longer along the mode");
                assert!(bent.abs() < 0.2 * stretched, "bent {bent}, along the mode {stretched}");
            }
        }
    }

    #[test]
    fn an_unheld_body_is_an_error() {
        let mesh = cube_mesh(2);
        let el = Elastic::new(&mesh, &material()).unwrap();
        let mut x = el.rest.clone();
        let load = vec![[0.0, 1.0, 0.0]; el.node_count()];
        let error = loaded_equilibrium(&el, &vec![false; el.node_count()], &load, &mut x, 1e-9, 10).unwrap_err();
        assert!(error.to_string().contains("free to move"), "{error}");
    }
}
