//! Parallelism for faer's dense kernels whose split is fixed, never taken from the thread pool:
//! the same bytes on any thread count ("same input, same bytes out").
//!
//! faer's `Par::rayon(0)` (and its global default, which the convenience methods such as
//! `Mat::self_adjoint_eigen`, `Mat::qr` and `&a * &b` read) splits its kernels into as many
//! parts as the pool has threads: the symmetric eigensolver's tridiagonalization sums a
//! matrix-vector product in per-part pieces, and pieces grouped differently round
//! differently. The rest vibration of the cyclic bar test's 720-tet bar (675 free
//! coordinates) came out different in the 12th digit on one and two threads, enough to move
//! the timing solve that starts from it by five iterations. `Par::rayon(TASKS)` splits every
//! kernel into the same parts whatever the pool's size (fewer threads take the parts in turn,
//! more threads idle), so the arithmetic is the same on any pool.

use faer::linalg::matmul::matmul;
use faer::linalg::qr::no_pivoting::factor as qr;
use faer::{Accum, Mat, MatRef, Par};

/// The parts of every split: the machines this runs on have 2 to 8 cores; with fewer
/// threads the parts run in turn, with more the extra threads idle in these kernels.
pub const TASKS: usize = 4;

/// faer's parallelism with the split fixed at [`TASKS`] parts.
pub fn par() -> Par {
    Par::rayon(TASKS)
}

/// `a * b` with the split of [`par`].
pub fn product(a: MatRef<'_, f64>, b: MatRef<'_, f64>) -> Mat<f64> {
    let mut out = Mat::<f64>::zeros(a.nrows(), b.ncols());
    matmul(out.as_mut(), Accum::Replace, a, b, 1.0, par());
    out
}

/// The eigenvalues (ascending) and eigenvectors (columns) of the symmetric `a` (its lower
/// triangle is read), with the split of [`par`]; `None` when the eigensolver fails.
pub fn self_adjoint_eigen(a: MatRef<'_, f64>) -> Option<(Vec<f64>, Mat<f64>)> {
    let n = a.nrows();
    let (params, par) = (Default::default(), par());
    let mut u = Mat::<f64>::zeros(n, n);
    let mut lambda = vec![0.0; n];
    let mut buffer = faer::dyn_stack::MemBuffer::new(faer::linalg::evd::self_adjoint_evd_scratch::<f64>(
        n,
        faer::linalg::evd::ComputeEigenvectors::Yes,
        par,
        params,
    ));
    let diag = faer::diag::DiagMut::from_slice_mut(&mut lambda);
    faer::linalg::evd::self_adjoint_evd(a, diag, Some(u.as_mut()), par, faer::dyn_stack::MemStack::new(&mut buffer), params).ok()?;
    Some((lambda, u))
}

/// The thin `Q` of `a = Q R` (`a` with at least as many rows as columns): orthonormal columns
/// spanning `a`'s, with the split of [`par`].
pub(crate) fn thin_q(mut a: Mat<f64>) -> Mat<f64> {
    let (m, n) = a.shape();
    let par = par();
    let block = qr::recommended_block_size::<f64>(m, n);
    let mut coeff = Mat::<f64>::zeros(block, n.min(m));
    let mut buffer = faer::dyn_stack::MemBuffer::new(qr::qr_in_place_scratch::<f64>(m, n, block, par, Default::default()));
    qr::qr_in_place(a.as_mut(), coeff.as_mut(), par, faer::dyn_stack::MemStack::new(&mut buffer), Default::default());
    let mut q = Mat::<f64>::identity(m, n.min(m));
    let mut buffer = faer::dyn_stack::MemBuffer::new(
        faer::linalg::householder::apply_block_householder_sequence_on_the_left_in_place_scratch::<f64>(m, block, n.min(m)),
    );
    // The Householder basis is `a`'s strictly lower part (the reflectors' unit diagonal is implicit).
    faer::linalg::householder::apply_block_householder_sequence_on_the_left_in_place_with_conj(
        a.as_ref().subcols(0, n.min(m)),
        coeff.as_ref(),
        faer::Conj::No,
        q.as_mut(),
        par,
        faer::dyn_stack::MemStack::new(&mut buffer),
    );
    q
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bits(m: &Mat<f64>) -> Vec<u64> {
        (0..m.ncols()).flat_map(|j| (0..m.nrows()).map(move |i| (i, j))).map(|(i, j)| m[(i, j)].to_bits()).collect()
    }

    /// A symmetric, diagonally heavy test matrix (no structure faer could shortcut).
    fn symmetric(n: usize) -> Mat<f64> {
        Mat::from_fn(n, n, |i, j| {
            let (a, b) = (i.min(j) as f64, i.max(j) as f64);
            ((a * 0.618_033_988_749_895 + b * 0.414_213_562_373_095).fract() - 0.5) + if i == j { n as f64 } else { 0.0 }
        })
    }

    /// The kernels give the same bytes on pools of one, two and three threads (sizes where
    /// faer splits them), and agree with faer's own convenience methods to round-off.
    #[test]
    fn the_kernels_give_the_same_bytes_on_any_pool() {
        let n = 400;
        let a = symmetric(n);
        let tall = Mat::from_fn(n, 24, |i, j| ((i as f64 + 1.0) * (j as f64 + 1.0) * 0.618_033_988_749_895).fract() - 0.5);
        let run = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            pool.install(|| {
                let (values, vectors) = self_adjoint_eigen(a.as_ref()).unwrap();
                let q = thin_q(tall.clone());
                let p = product(a.as_ref(), tall.as_ref());
                (values.iter().map(|v| v.to_bits()).collect::<Vec<u64>>(), bits(&vectors), bits(&q), bits(&p))
            })
        };
        let one = run(1);
        assert_eq!(run(2), one, "two threads");
        assert_eq!(run(3), one, "three threads");
        // The same decompositions as faer's methods.
        let (values, vectors) = self_adjoint_eigen(a.as_ref()).unwrap();
        let reference = a.self_adjoint_eigen(faer::Side::Lower).unwrap();
        for i in 0..n {
            assert!((values[i] - reference.S()[i]).abs() < 1e-12 * n as f64, "eigenvalue {i}");
        }
        let av = product(a.as_ref(), vectors.as_ref());
        for j in (0..n).step_by(37) {
            for i in 0..n {
                assert!((av[(i, j)] - values[j] * vectors[(i, j)]).abs() < 1e-10 * n as f64, "A v = λ v at ({i}, {j})");
            }
        }
        let q = thin_q(tall.clone());
        let qtq = product(q.transpose(), q.as_ref());
        let r = product(q.transpose(), tall.as_ref());
        let back = product(q.as_ref(), r.as_ref());
        for j in 0..24 {
            for i in 0..24 {
                assert!((qtq[(i, j)] - if i == j { 1.0 } else { 0.0 }).abs() < 1e-13, "QᵀQ = I at ({i}, {j})");
                if i > j {
                    assert!(r[(i, j)].abs() < 1e-12, "R upper triangular at ({i}, {j})");
                }
            }
            for i in 0..n {
                assert!((back[(i, j)] - tall[(i, j)]).abs() < 1e-12, "Q R = A at ({i}, {j})");
            }
        }
    }

    /// Why: faer's pool-sized split (`Par::rayon(0)`) does change the bytes of the eigenvectors
    /// between one and two threads at this size. If a faer update stops splitting this kernel
    /// by the pool, this test says so (and the module may become unnecessary).
    #[test]
    fn the_pool_sized_split_changes_the_bytes() {
        let a = symmetric(400);
        let run = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            pool.install(|| bits(&a.self_adjoint_eigen(faer::Side::Lower).unwrap().U().to_owned()))
        };
        assert_ne!(run(1), run(2));
    }
}
