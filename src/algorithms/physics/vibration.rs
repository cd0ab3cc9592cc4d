//! Natural vibration of an elastic body about its rest shape with some nodes held: the
//! generalized eigenproblem `K u = λ M u` over the free nodes' coordinates, periods
//! `2π / sqrt(λ)`. A cyclic animation whose duration matches the first period can follow
//! the dynamics exactly, which is what the timing optimization should find.
//!
//! Two stiffnesses ([`RestStiffness`]):
//! - the tangent stiffness `∇²E = L - J DP dF` at rest, the small-amplitude dynamics of the
//!   elastic energy (a frame-by-frame simulation of the same material oscillates with it);
//! - `L` alone, the projective-dynamics matrix, i.e. the targets frozen at rest. It also resists
//!   rotating the elements, so it is stiffer and its periods are shorter: it is the right model
//!   only where the elements do not rotate.
//!
//! With the lumped (diagonal) mass, `K u = λ M u` is the symmetric problem
//! `M^{-1/2} K M^{-1/2} y = λ y`. Small problems are solved densely (faer's symmetric
//! eigensolver); larger ones by subspace iteration with a sparse Cholesky factor of the
//! slightly shifted matrix (shift-invert at zero) and Rayleigh-Ritz on a block of vectors, which
//! also resolves the pairs of equal periods a symmetric bar has. Zero eigenvalues (motions the
//! held nodes leave free, e.g. spinning about a single held node) are counted and skipped.

use faer::sparse::{SparseColMat, SymbolicSparseColMat};
use faer::{Mat, Par};

use super::cholesky::Cholesky;
use super::csr::Csr;
use super::elastic::Elastic;
use super::fixed_par;
use super::ordering::FillOrdering;
use super::projection::project_with_jacobian;
use crate::algorithms::geometry::Point;
use crate::support::error::{Error, Result};

/// The stiffness a body vibrates with (see the module documentation).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RestStiffness {
    /// `∇²E` at rest.
    Tangent,
    /// The projective-dynamics matrix `L` (per coordinate).
    Projective,
}

/// The lowest modes of a held body.
#[derive(Debug, Clone, PartialEq)]
pub struct Vibration {
    /// The smallest nonzero eigenvalues `λ = ω²` (1/s²), ascending.
    pub eigenvalues: Vec<f64>,
    /// The mode shapes (nodal displacements, zero at held nodes, `uᵀ M u = 1`), one per
    /// eigenvalue.
    pub shapes: Vec<Vec<Point>>,
    /// Zero eigenvalues skipped (free rigid motions).
    pub zero_modes: usize,
    /// "dense" or "subspace iteration".
    pub method: &'static str,
}

impl Vibration {
    /// Periods `2π / sqrt(λ)` in seconds, longest first.
    pub fn periods(&self) -> Vec<f64> {
        self.eigenvalues.iter().map(|l| 2.0 * std::f64::consts::PI / l.sqrt()).collect()
    }
}

/// Free coordinates up to this count are solved densely.
const DENSE_LIMIT: usize = 1200;
/// Eigenvalues below this fraction of the largest diagonal entry count as zero.
const ZERO: f64 = 1e-10;

/// The `count` lowest nonzero modes of `elastic` with the nodes `held[a]` fixed.
pub fn natural_vibration(elastic: &Elastic, held: &[bool], stiffness: RestStiffness, count: usize) -> Result<Vibration> {
    natural_vibration_with(elastic, held, stiffness, count, DENSE_LIMIT)
}

/// [`natural_vibration`], solving densely up to `dense_limit` free coordinates.
pub(crate) fn natural_vibration_with(
    elastic: &Elastic,
    held: &[bool],
    stiffness: RestStiffness,
    count: usize,
    dense_limit: usize,
) -> Result<Vibration> {
    let (k, free) = scaled_stiffness(elastic, held, stiffness);
    let dim = k.n;
    if dim == 0 || count == 0 {
        return Ok(Vibration { eigenvalues: Vec::new(), shapes: Vec::new(), zero_modes: 0, method: "none" });
    }
    let scale = (0..dim).map(|i| k.get(i, i)).fold(0.0, f64::max);
    let ((values, vectors), method) =
        if dim <= dense_limit { (dense_eigen(&k), "dense") } else { (subspace_eigen(&k, count + 6, scale)?, "subspace iteration") };
    let zero_modes = values.iter().take_while(|&&l| l < ZERO * scale).count();
    let eigenvalues: Vec<f64> = values[zero_modes..].iter().copied().take(count).collect();
    if eigenvalues.len() < count.min(dim - zero_modes) {
        return Err(Error::general(
            format!("the vibration eigensolver found {} of the {count} lowest modes", eigenvalues.len()),
            "ask for fewer modes, or use a coarser mesh",
        ));
    }
    // u = M^{-1/2} y on the free nodes.
    let shapes = (zero_modes..zero_modes + eigenvalues.len())
        .map(|c| {
            let mut u = vec![[0.0; 3]; elastic.node_count()];
            for (f, &a) in free.iter().enumerate() {
                let s = 1.0 / elastic.mass[a].sqrt();
                u[a] = [0, 1, 2].map(|d| s * vectors[(3 * f + d, c)]);
            }
            u
        })
        .collect();
    Ok(Vibration { eigenvalues, shapes, zero_modes, method })
}

/// The rest stiffness `K` of every node's coordinates (node-major, 3 per node, `3a + i`),
/// full symmetric storage, unscaled. The tangent one is `∇²E` at rest: positive semidefinite,
/// since the rest shape minimizes every element's energy (zero there).
pub(crate) fn rest_stiffness(el: &Elastic, stiffness: RestStiffness) -> Csr {
    let share = el.strain_share();
    let mut triplets = Vec::with_capacity(144 * el.tet_count());
    for (e, tet) in el.tets.iter().enumerate() {
        let (g, w) = (&el.grads[e], el.weights[e]);
        let jac = (stiffness == RestStiffness::Tangent).then(|| project_with_jacobian(&el.deformation_gradient(e, &el.rest), share).1);
        for (lb, &b) in tet.iter().enumerate() {
            for j in 0..3 {
                // Column (b, j): the force change for a unit move of node b along j, whose
                // deformation-gradient change is e_j g_bᵀ.
                let dp = jac.map(|jac| {
                    let mut df = [[0.0; 3]; 3];
                    df[j] = g[lb];
                    jac.apply(&df)
                });
                for (la, &a) in tet.iter().enumerate() {
                    let gab = crate::algorithms::geometry::dot(g[la], g[lb]);
                    for i in 0..3 {
                        let mut v = if i == j { gab } else { 0.0 };
                        if let Some(dp) = &dp {
                            v -= dp[i][0] * g[la][0] + dp[i][1] * g[la][1] + dp[i][2] * g[la][2];
                        }
                        if v != 0.0 {
                            triplets.push((3 * a + i as u32, 3 * b + j as u32, w * v));
                        }
                    }
                }
            }
        }
    }
    Csr::from_triplets(3 * el.node_count(), triplets)
}

/// `M^{-1/2} K M^{-1/2}` over the coordinates of the free nodes (node-major, 3 per node), full
/// symmetric storage; and the free nodes.
fn scaled_stiffness(el: &Elastic, held: &[bool], stiffness: RestStiffness) -> (Csr, Vec<usize>) {
    let mut index = vec![u32::MAX; el.node_count()];
    let free_nodes: Vec<usize> = (0..el.node_count()).filter(|&a| !held[a]).collect();
    for (f, &a) in free_nodes.iter().enumerate() {
        index[a] = f as u32;
    }
    let k = rest_stiffness(el, stiffness);
    let mut triplets = Vec::with_capacity(k.nnz());
    for r in 0..k.n {
        let (a, i) = (r / 3, r % 3);
        if index[a] == u32::MAX {
            continue;
        }
        for (c, v) in k.row(r) {
            let (b, j) = (c / 3, c % 3);
            if index[b] != u32::MAX {
                let v = v / (el.mass[a] * el.mass[b]).sqrt();
                triplets.push((3 * index[a] + i as u32, 3 * index[b] + j as u32, v));
            }
        }
    }
    (Csr::from_triplets(3 * free_nodes.len(), triplets), free_nodes)
}

/// All eigenvalues, ascending, and their eigenvectors (columns).
fn dense_eigen(k: &Csr) -> (Vec<f64>, Mat<f64>) {
    let mut a = Mat::<f64>::zeros(k.n, k.n);
    for i in 0..k.n {
        for (j, v) in k.row(i) {
            a[(i, j)] = v;
        }
    }
    // faer's kernels split by a fixed count, not the pool's: the same modes on any thread count.
    fixed_par::self_adjoint_eigen(a.as_ref()).expect("the symmetric eigensolver converges")
}

/// The `wanted` smallest eigenvalues (zero ones included), ascending, and their vectors, by
/// subspace iteration with the factor of `K + shift I`.
fn subspace_eigen(k: &Csr, wanted: usize, scale: f64) -> Result<(Vec<f64>, Mat<f64>)> {
    let n = k.n;
    let p = (2 * wanted + 8).min(n);
    // Lower triangle, compressed columns: column j of the lower part is row j's entries i >= j.
    let shift = 1e-9 * scale;
    let (mut col_ptr, mut rows, mut vals) = (vec![0usize], Vec::new(), Vec::new());
    for j in 0..n {
        for (i, v) in k.row(j).filter(|&(i, _)| i >= j) {
            rows.push(i);
            vals.push(if i == j { v + shift } else { v });
        }
        col_ptr.push(rows.len());
    }
    let lower = SparseColMat::new(SymbolicSparseColMat::new_checked(n, n, col_ptr, None, rows), vals);
    let chol = Cholesky::factor(&lower, &FillOrdering::Amd, Par::Seq)
        .map_err(|_| Error::general("the rest stiffness is not positive semidefinite", "check the mesh for inverted tets"))?;
    // A fixed start block (a Weyl sequence), so results do not depend on anything but the input.
    let mut q = Mat::<f64>::from_fn(n, p, |i, j| ((i as f64 + 1.0) * (j as f64 + 1.0) * 0.618_033_988_749_895).fract() - 0.5);
    let mut previous = vec![f64::INFINITY; p];
    for _ in 0..2000 {
        chol.solve_in_place(q.as_mut());
        q = fixed_par::thin_q(q);
        // Rayleigh-Ritz: B = Qᵀ K Q.
        let mut kq = Mat::<f64>::zeros(n, p);
        for i in 0..n {
            for (j, v) in k.row(i) {
                for c in 0..p {
                    kq[(i, c)] += v * q[(j, c)];
                }
            }
        }
        let b = fixed_par::product(q.transpose(), kq.as_ref());
        let b = Mat::<f64>::from_fn(p, p, |i, j| 0.5 * (b[(i, j)] + b[(j, i)]));
        let (theta, u) = fixed_par::self_adjoint_eigen(b.as_ref()).expect("the symmetric eigensolver converges");
        q = fixed_par::product(q.as_ref(), u.as_ref());
        // Zero modes settle to roundoff, about 1e-16 of the scale.
        let settled = (0..wanted).all(|i| (theta[i] - previous[i]).abs() <= 1e-12 * theta[i].abs() + 1e-14 * scale);
        if settled {
            return Ok((theta[..wanted].to_vec(), q));
        }
        previous = theta;
    }
    Err(Error::general("the vibration eigensolver did not converge in 2000 subspace iterations", "ask for fewer modes, or use a coarser mesh"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::algorithms::geometry::TetMesh;
    use crate::algorithms::physics::elastic::Material;
    use crate::algorithms::testing::cube_mesh;

    fn material(stiffness: f64, volume: f64, density: f64) -> Material {
        Material { stiffness, volume, density }
    }

    #[test]
    fn one_free_node_of_a_tet_by_hand() {
        // Corner tet 0, e1, e2, e3 with nodes 0..2 held: node 3 has mass ρV/4 (V = 1/6) and
        // g_3 = e3. Projective: L_33 = w |g_3|² = V (k_s + k_v) in every direction, so
        // λ = 4 (k_s + k_v) / ρ. Tangent: DP(I)[G] = r skew(G) + (1 - r)(G - tr(G)/3 I) gives
        // K_33 = diag(V k_s / 2, V k_s / 2, V (k_s + k_v / 3)), so λ = 2 k_s / ρ (twice) and
        // 4 (k_s + k_v / 3) / ρ.
        let mesh = TetMesh { positions: vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], tets: vec![[0, 1, 2, 3]] };
        let (ks, kv, rho) = (30.0, 12.0, 1.5);
        let el = Elastic::new(&mesh, &material(ks, kv, rho)).unwrap();
        let held = [true, true, true, false];
        let pd = natural_vibration(&el, &held, RestStiffness::Projective, 3).unwrap();
        let tangent = natural_vibration(&el, &held, RestStiffness::Tangent, 3).unwrap();
        let expect_pd = [4.0 * (ks + kv) / rho; 3];
        let mut expect_tangent = [2.0 * ks / rho, 2.0 * ks / rho, 4.0 * (ks + kv / 3.0) / rho];
        expect_tangent.sort_by(f64::total_cmp);
        for (got, want) in [(&pd.eigenvalues, &expect_pd), (&tangent.eigenvalues, &expect_tangent)] {
            for (g, w) in got.iter().zip(want.iter()) {
                assert!((g - w).abs() < 1e-12 * w, "{got:?} vs {want:?}");
            }
        }
        let period = 2.0 * std::f64::consts::PI / (2.0 * ks / rho).sqrt();
        assert!((tangent.periods()[0] - period).abs() < 1e-12 * period);
        // The stiffest mode moves node 3 along z only, with uᵀ M u = 1.
        let u = tangent.shapes[2][3];
        assert!(u[0].abs() < 1e-12 && u[1].abs() < 1e-12 && ((u[2] * u[2] * el.mass[3]).sqrt() - 1.0).abs() < 1e-12, "{u:?}");
        assert_eq!(tangent.shapes[2][0], [0.0; 3]);
    }

    /// A 4 x 1 x 1 bar of 4·n x n x n cubes... (cube lattice stretched along x), end x = 0 held.
    fn bar(n: usize) -> (Elastic, Vec<bool>) {
        let mut mesh = cube_mesh(n);
        for p in &mut mesh.positions {
            p[0] *= 4.0;
        }
        let el = Elastic::new(&mesh, &material(70.0, 70.0, 1.0)).unwrap();
        let held = mesh.positions.iter().map(|p| p[0] == 0.0).collect();
        (el, held)
    }

    #[test]
    fn subspace_iteration_agrees_with_the_dense_solver() {
        let (el, held) = bar(3);
        for stiffness in [RestStiffness::Tangent, RestStiffness::Projective] {
            let dense = natural_vibration_with(&el, &held, stiffness, 6, usize::MAX).unwrap();
            let iterative = natural_vibration_with(&el, &held, stiffness, 6, 0).unwrap();
            assert_eq!((dense.method, iterative.method), ("dense", "subspace iteration"));
            assert_eq!(dense.zero_modes, 0);
            for (a, b) in dense.eigenvalues.iter().zip(&iterative.eigenvalues) {
                assert!((a - b).abs() < 1e-9 * a, "{stiffness:?}: {:?} vs {:?}", dense.eigenvalues, iterative.eigenvalues);
            }
            // The first (non-degenerate for the tangent stiffness) shape, up to sign.
            if stiffness == RestStiffness::Tangent {
                let (u, v) = (&dense.shapes[0], &iterative.shapes[0]);
                let dot: f64 = u.iter().zip(v).zip(&el.mass).map(|((a, b), m)| m * crate::algorithms::geometry::dot(*a, *b)).sum();
                assert!((dot.abs() - 1.0).abs() < 1e-6, "M-inner product of the two first shapes: {dot}");
            }
            println!("{stiffness:?}: periods {:?}", dense.periods());
        }
    }

    #[test]
    fn the_first_mode_of_a_square_bar_is_a_pair_of_bendings_and_l_is_stiffer() {
        let (el, held) = bar(3);
        let tangent = natural_vibration(&el, &held, RestStiffness::Tangent, 4).unwrap();
        let pd = natural_vibration(&el, &held, RestStiffness::Projective, 4).unwrap();
        let (t, p) = (tangent.eigenvalues, pd.eigenvalues);
        // A square cross-section bends the same way about both axes (the lattice's diagonal
        // tets make the two only nearly equal: 5% apart), and the next mode is far above.
        assert!((t[1] - t[0]).abs() < 0.1 * t[0] && t[2] > 4.0 * t[1], "{t:?}");
        // L also penalizes rotating elements, which bending does: its bending is far stiffer
        // (λ 24 times the tangent one on this bar; periods 1.37 s vs 6.66 s).
        assert!(p[0] > 10.0 * t[0], "L: {p:?}, tangent: {t:?}");
    }

    #[test]
    fn the_modes_solve_the_elastic_hessian() {
        // K φ = λ M φ on the free nodes, with K applied by the elastic body's own Hessian
        // product (projection Jacobians at rest), an independent code path.
        let (el, held) = bar(3);
        let modes = natural_vibration(&el, &held, RestStiffness::Tangent, 3).unwrap();
        let (_, jacobians) = el.local_step_with_jacobians_sequential(&el.rest);
        for (lambda, phi) in modes.eigenvalues.iter().zip(&modes.shapes) {
            let mut k_phi = vec![[0.0; 3]; el.node_count()];
            el.hessian_apply(&jacobians, phi, &mut k_phi);
            let scale = phi.iter().zip(&el.mass).map(|(u, m)| lambda * m * crate::algorithms::geometry::norm(*u)).fold(0.0, f64::max);
            for a in (0..el.node_count()).filter(|&a| !held[a]) {
                for d in 0..3 {
                    assert!((k_phi[a][d] - lambda * el.mass[a] * phi[a][d]).abs() < 1e-9 * scale, "node {a}");
                }
            }
        }
    }

    #[test]
    fn a_single_held_node_leaves_three_rotations_free() {
        let mesh = cube_mesh(1);
        let el = Elastic::new(&mesh, &material(70.0, 70.0, 1.0)).unwrap();
        let mut held = vec![false; mesh.positions.len()];
        held[0] = true;
        let tangent = natural_vibration_with(&el, &held, RestStiffness::Tangent, 2, usize::MAX).unwrap();
        assert_eq!(tangent.zero_modes, 3, "{tangent:?}");
        let iterative = natural_vibration_with(&el, &held, RestStiffness::Tangent, 2, 0).unwrap();
        assert_eq!(iterative.zero_modes, 3);
        assert!((iterative.eigenvalues[0] - tangent.eigenvalues[0]).abs() < 1e-9 * tangent.eigenvalues[0]);
        // L resists rotations: no zero mode once a node is held.
        assert_eq!(natural_vibration(&el, &held, RestStiffness::Projective, 2).unwrap().zero_modes, 0);
    }
}
