//! Linear equality constraints on a step of the solver, held by projection: the active set.
//!
//! The solver's variables are the free keyframe unknowns `u` (three coordinates each) and,
//! when the key times are optimized, the free interval lengths `T`, flattened into one vector
//! `z = (u, T)`. A row is a linear functional of a step `Δz`:
//!
//! ```text
//! r·Δz = Σ_(i, w) w (n·Δu_i) + Σ_(j, c) c ΔT_j
//! ```
//!
//! (`n` is one direction shared by the row's `u` entries: an obstacle's normal). Rows are the
//! active constraints: obstacle contacts held on the surface, interval lengths held at their
//! minimum, and the sums of the intervals between fixed key times.
//!
//! With a step preconditioner `H₀ = diag(A⁻¹ ⊗ I₃, D_T)` (the global step's factorization and
//! a diagonal for the times), [`Projection`] applies
//!
//! ```text
//! P = H₀ - H₀ Rᵀ S⁻¹ R H₀,   S = R H₀ Rᵀ
//! ```
//!
//! the preconditioner restricted to steps that keep every row: `P g` is the minimizer of
//! `½ Δᵀ H₀⁻¹ Δ + gᵀ Δ` with `R Δ = 0`. With the local/global matrix as `H₀` and no times,
//! `-P g` is exactly the paper's KKT step with the active set bordering the matrix (the
//! reference code solves the bordered system; here the border is a small dense Schur
//! complement, `A` is never refactorized for it). `λ = S⁻¹ R H₀ g` are the multipliers:
//! `g = Rᵀλ` at a constrained stationary point, and an inequality row with `λ < 0` is one the
//! objective pulls away from (the obstacle would have to pull): it is released.
//!
//! `A⁻¹` acts on the three coordinates alike, so `A⁻¹ (e ⊗ n) = (A⁻¹ e) ⊗ n`: every row costs
//! one scalar solve, and three rows share one three-column solve. Rows that depend on the
//! others (a pivot of `S` below `1e-10` of its diagonal) are dropped: holding the others holds
//! them.

use crate::algorithms::geometry::Point;

/// What a row holds, for the solver's bookkeeping.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum RowKind {
    /// The sum of a block of intervals (between two fixed key times): an equality.
    Sum,
    /// Interval variable `j` at its minimum length: an inequality (`ΔT_j >= 0`).
    Bound(usize),
    /// A node against an obstacle at a check time (index into the solver's candidate list): an
    /// inequality (`n·Δx >= 0`).
    Contact(usize),
}

impl RowKind {
    /// Whether the row is an inequality (released when its multiplier is negative).
    pub(crate) fn is_inequality(self) -> bool {
        !matches!(self, RowKind::Sum)
    }
}

/// One linear functional of a step.
#[derive(Debug, Clone, PartialEq)]
pub struct Row {
    /// What the row holds (and so whether it may be released).
    pub kind: RowKind,
    /// `(free unknown, weight)`: the row reads `weight n·Δu` of each.
    pub u: Vec<(usize, f64)>,
    /// The direction the `u` entries are read along.
    pub normal: Point,
    /// `(interval variable, coefficient)`.
    pub t: Vec<(usize, f64)>,
}

/// The step preconditioner `H₀` without constraints.
pub struct Preconditioner<'a> {
    /// Free unknowns (per coordinate).
    pub unknowns: usize,
    /// `x <- A⁻¹ x` on the unknowns, three coordinates as three right-hand sides.
    pub solve: &'a dyn Fn(&mut [Point]),
    /// `D_T`: the inverse curvature of each interval variable.
    pub times: &'a [f64],
}

impl Preconditioner<'_> {
    /// `z <- H₀ z`.
    pub fn apply(&self, z: &mut [f64]) {
        let nu3 = 3 * self.unknowns;
        let (u, t) = z.split_at_mut(nu3);
        let (points, _) = u.as_chunks_mut::<3>();
        (self.solve)(points);
        for (x, d) in t.iter_mut().zip(self.times) {
            *x *= d;
        }
    }
}

/// `r·z` where `z` holds `3 nu` unknown entries and then the times.
pub(crate) fn row_dot(row: &Row, z: &[f64], nu: usize) -> f64 {
    let mut s = 0.0;
    for &(i, w) in &row.u {
        s += w * (row.normal[0] * z[3 * i] + row.normal[1] * z[3 * i + 1] + row.normal[2] * z[3 * i + 2]);
    }
    for &(j, c) in &row.t {
        s += c * z[3 * nu + j];
    }
    s
}

/// The preconditioner restricted to steps that keep the active rows (module documentation).
pub struct Projection {
    /// The rows kept (independent ones), in the order given; dependent rows are dropped.
    pub rows: Vec<Row>,
    /// `A⁻¹ e` of each kept row (scalar per unknown; empty for a row without unknowns).
    h0_u: Vec<Vec<f64>>,
    /// `D_T t` of each kept row (dense over the interval variables).
    h0_t: Vec<Vec<f64>>,
    /// Lower Cholesky factor of `S`, row-major `m × m`.
    factor: Vec<f64>,
    unknowns: usize,
}

impl Projection {
    /// Factor `S = R H₀ Rᵀ` for `rows`, dropping dependent ones.
    pub fn new(rows: Vec<Row>, h0: &Preconditioner) -> Projection {
        let (nu, nt) = (h0.unknowns, h0.times.len());
        // A⁻¹ e for the rows with unknowns, three rows per solve.
        let with_u: Vec<usize> = (0..rows.len()).filter(|&a| !rows[a].u.is_empty()).collect();
        let mut h0_u = vec![Vec::new(); rows.len()];
        for chunk in with_u.chunks(3) {
            let mut x = vec![[0.0; 3]; nu];
            for (lane, &a) in chunk.iter().enumerate() {
                for &(i, w) in &rows[a].u {
                    x[i][lane] += w;
                }
            }
            (h0.solve)(&mut x);
            for (lane, &a) in chunk.iter().enumerate() {
                h0_u[a] = x.iter().map(|p| p[lane]).collect();
            }
        }
        let h0_t: Vec<Vec<f64>> = rows
            .iter()
            .map(|r| {
                let mut t = vec![0.0; nt];
                for &(j, c) in &r.t {
                    t[j] += c * h0.times[j];
                }
                t
            })
            .collect();
        // S_ab = r_a · H₀ r_b.
        let m = rows.len();
        let entry = |a: usize, b: usize| -> f64 {
            let mut s = 0.0;
            if !h0_u[b].is_empty() {
                let nn = rows[a].normal[0] * rows[b].normal[0] + rows[a].normal[1] * rows[b].normal[1] + rows[a].normal[2] * rows[b].normal[2];
                if nn != 0.0 {
                    s += nn * rows[a].u.iter().map(|&(i, w)| w * h0_u[b][i]).sum::<f64>();
                }
            }
            s + rows[a].t.iter().map(|&(j, c)| c * h0_t[b][j]).sum::<f64>()
        };
        // Cholesky with dependent rows dropped, in order.
        let mut kept: Vec<usize> = Vec::with_capacity(m);
        let mut factor: Vec<Vec<f64>> = Vec::with_capacity(m);
        for a in 0..m {
            let diag = entry(a, a);
            let mut l: Vec<f64> = Vec::with_capacity(kept.len() + 1);
            for (k, &b) in kept.iter().enumerate() {
                let mut v = entry(a, b);
                for p in 0..k {
                    v -= l[p] * factor[k][p];
                }
                l.push(v / factor[k][k]);
            }
            let pivot = diag - l.iter().map(|x| x * x).sum::<f64>();
            if !(diag > 0.0 && pivot > 1e-10 * diag) {
                continue;
            }
            l.push(pivot.sqrt());
            kept.push(a);
            factor.push(l);
        }
        let k = kept.len();
        let mut dense = vec![0.0; k * k];
        for (i, row) in factor.iter().enumerate() {
            dense[i * k..i * k + row.len()].copy_from_slice(row);
        }
        let mut keep = vec![false; m];
        kept.iter().for_each(|&a| keep[a] = true);
        let (mut out_rows, mut h0_u_kept, mut h0_t_kept) = (Vec::with_capacity(k), Vec::with_capacity(k), Vec::with_capacity(k));
        for (a, ((r, hu), ht)) in rows.into_iter().zip(h0_u).zip(h0_t).enumerate() {
            if keep[a] {
                out_rows.push(r);
                h0_u_kept.push(hu);
                h0_t_kept.push(ht);
            }
        }
        Projection { rows: out_rows, h0_u: h0_u_kept, h0_t: h0_t_kept, factor: dense, unknowns: nu }
    }

    /// `S⁻¹ c` by the two triangular solves.
    fn solve_s(&self, c: &mut [f64]) {
        let k = self.rows.len();
        let l = &self.factor;
        for i in 0..k {
            let mut v = c[i];
            for p in 0..i {
                v -= l[i * k + p] * c[p];
            }
            c[i] = v / l[i * k + i];
        }
        for i in (0..k).rev() {
            let mut v = c[i];
            for p in i + 1..k {
                v -= l[p * k + i] * c[p];
            }
            c[i] = v / l[i * k + i];
        }
    }

    /// `z <- P z`, and the multipliers `λ = S⁻¹ R H₀ z` (one per kept row).
    pub fn apply(&self, z: &mut [f64], h0: &Preconditioner) -> Vec<f64> {
        h0.apply(z);
        let mut lambda: Vec<f64> = self.rows.iter().map(|r| row_dot(r, z, self.unknowns)).collect();
        if lambda.is_empty() {
            return lambda;
        }
        self.solve_s(&mut lambda);
        let nu3 = 3 * self.unknowns;
        for (a, &l) in lambda.iter().enumerate() {
            if l == 0.0 {
                continue;
            }
            let n = self.rows[a].normal;
            for (i, &h) in self.h0_u[a].iter().enumerate() {
                if h != 0.0 {
                    for d in 0..3 {
                        z[3 * i + d] -= l * h * n[d];
                    }
                }
            }
            for (j, &h) in self.h0_t[a].iter().enumerate() {
                z[nu3 + j] -= l * h;
            }
        }
        lambda
    }

    /// The step that changes the kept rows by `targets` (`R Δ = targets`) with the least
    /// `Δᵀ H₀⁻¹ Δ`: `Δ = H₀ Rᵀ S⁻¹ targets` (the projection onto violated constraints).
    pub fn correction(&self, targets: &[f64], len: usize) -> Vec<f64> {
        let mut c = targets.to_vec();
        self.solve_s(&mut c);
        let mut z = vec![0.0; len];
        let nu3 = 3 * self.unknowns;
        for (a, &l) in c.iter().enumerate() {
            let n = self.rows[a].normal;
            for (i, &h) in self.h0_u[a].iter().enumerate() {
                for d in 0..3 {
                    z[3 * i + d] += l * h * n[d];
                }
            }
            for (j, &h) in self.h0_t[a].iter().enumerate() {
                z[nu3 + j] += l * h;
            }
        }
        z
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::support::testing::Rng;

    /// A small SPD "A" (diagonal plus coupling) applied by a dense solve.
    fn dense_solve(a: &[Vec<f64>], x: &mut [Point]) {
        let n = a.len();
        for d in 0..3 {
            let mut m: Vec<Vec<f64>> = a.to_vec();
            let mut b: Vec<f64> = x.iter().map(|p| p[d]).collect();
            for c in 0..n {
                for r in c + 1..n {
                    let f = m[r][c] / m[c][c];
                    for k in c..n {
                        m[r][k] -= f * m[c][k];
                    }
                    b[r] -= f * b[c];
                }
            }
            for r in (0..n).rev() {
                let mut v = b[r];
                for k in r + 1..n {
                    v -= m[r][k] * b[k];
                }
                b[r] = v / m[r][r];
            }
            for (p, v) in x.iter_mut().zip(b) {
                p[d] = v;
            }
        }
    }

    #[test]
    fn the_projected_step_keeps_the_rows_and_solves_the_bordered_system() {
        let mut rng = Rng::new(7);
        let nu = 5;
        let mut a = vec![vec![0.0; nu]; nu];
        for i in 0..nu {
            a[i][i] = 3.0 + rng.next();
            if i + 1 < nu {
                let c = 0.5 * rng.next();
                a[i][i + 1] = c;
                a[i + 1][i] = c;
            }
        }
        let solve = |x: &mut [Point]| dense_solve(&a, x);
        let times = [0.5, 2.0, 1.5];
        let h0 = Preconditioner { unknowns: nu, solve: &solve, times: &times };
        let rows = vec![
            Row { kind: RowKind::Contact(0), u: vec![(1, 1.0), (2, 0.5)], normal: [0.0, 1.0, 0.0], t: vec![(0, 0.3)] },
            Row { kind: RowKind::Sum, u: vec![], normal: [0.0; 3], t: vec![(0, 1.0), (1, 1.0), (2, 1.0)] },
            Row { kind: RowKind::Contact(1), u: vec![(4, 1.0)], normal: [0.6, 0.8, 0.0], t: vec![] },
            // Twice the first row: dependent, dropped.
            Row { kind: RowKind::Contact(2), u: vec![(1, 2.0), (2, 1.0)], normal: [0.0, 1.0, 0.0], t: vec![(0, 0.6)] },
        ];
        let p = Projection::new(rows.clone(), &h0);
        let kept: Vec<RowKind> = p.rows.iter().map(|r| r.kind).collect();
        assert_eq!(kept, vec![RowKind::Contact(0), RowKind::Sum, RowKind::Contact(1)], "the dependent row is dropped");
        let len = 3 * nu + times.len();
        let g: Vec<f64> = (0..len).map(|_| rng.next()).collect();
        let mut step = g.clone();
        let lambda = p.apply(&mut step, &h0);
        for r in &rows {
            assert!(row_dot(r, &step, nu).abs() < 1e-12, "{:?} moved by {}", r.kind, row_dot(r, &step, nu));
        }
        // The projected step solves H₀⁻¹ Δ = g - Rᵀ λ: check H₀ (g - Rᵀλ) = Δ.
        let mut rhs = g.clone();
        for (r, l) in p.rows.iter().zip(&lambda) {
            for &(i, w) in &r.u {
                for d in 0..3 {
                    rhs[3 * i + d] -= l * w * r.normal[d];
                }
            }
            for &(j, c) in &r.t {
                rhs[3 * nu + j] -= l * c;
            }
        }
        h0.apply(&mut rhs);
        for (x, y) in rhs.iter().zip(&step) {
            assert!((x - y).abs() < 1e-12);
        }
        // The correction reaches its targets.
        let targets = [0.3, -0.2, 0.7];
        let c = p.correction(&targets, len);
        for (r, t) in p.rows.iter().zip(targets) {
            assert!((row_dot(r, &c, nu) - t).abs() < 1e-12);
        }
    }
}
