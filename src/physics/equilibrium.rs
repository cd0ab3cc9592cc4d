//! Quasi-static equilibrium: positions of the free nodes that minimize the elastic energy
//! with the pinned nodes held, by local/global projective-dynamics iterations.
//!
//! Used to give the interior nodes TetGen adds a keyframe pose that matches each keyframe
//! surface (instead of leaving them at the rest pose). Each iteration minimizes `E` exactly
//! over the projections (local step) and then over the free positions (global step), so `E`
//! decreases monotonically; the free-free block of `L` is factorized once and reused for
//! every keyframe.

use faer::sparse::{SparseColMat, SymbolicSparseColMat};
use faer::{Mat, Par};

use super::cholesky::Cholesky;
use super::ordering::FillOrdering;
use super::elastic::Elastic;
use super::mat3::Mat3;
use crate::error::{Error, Result};
use crate::mesh::Point;

pub struct Equilibrium<'a> {
    elastic: &'a Elastic,
    /// Index among the free nodes, or `None` for pinned nodes.
    free: Vec<Option<usize>>,
    free_nodes: Vec<usize>,
    cholesky: Option<Cholesky>,
}

/// How an equilibrium solve ended.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EquilibriumInfo {
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
                moved = moved.max(crate::mesh::norm(crate::mesh::sub(new, positions[a])));
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::elastic::Material;
    use crate::testing::cube_mesh;

    fn material() -> Material {
        Material { stiffness: 70.0, volume: 70.0, density: 1.0 }
    }

    fn boundary_mask(mesh: &crate::mesh::TetMesh) -> Vec<bool> {
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
            assert!(crate::mesh::norm(crate::mesh::sub(x[a], moved(p))) < 1e-9, "node {a}");
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
                assert!(crate::mesh::norm(g[a]) < 1e-6, "node {a}: {:?}", g[a]);
            }
        }
    }
}
