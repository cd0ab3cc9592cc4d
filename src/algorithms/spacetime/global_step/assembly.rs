//! The global step's matrix assembled over the free unknowns, straight into compressed
//! columns in node-major order (rows come out sorted; no triplet sort).

use faer::sparse::{SparseColMat, SymbolicSparseColMat};
use rayon::prelude::*;

use crate::algorithms::spacetime::objective::Objective;
use crate::algorithms::spacetime::time_coefficients::TimeCoefficients;
use crate::algorithms::spacetime::unknowns::Unknowns;

/// Per slot pair: whether the mass block and the stiffness blocks are present in [`assemble`].
pub(super) fn coupling(c: &TimeCoefficients) -> Vec<(bool, bool)> {
    (0..c.slots * c.slots).map(|at| (c.mm[at] != 0.0, c.ml[at] != 0.0 || c.kk[at] != 0.0)).collect()
}

/// Lower triangle of the normal matrix restricted to the free unknowns.
pub fn assemble(objective: &Objective, unknowns: &Unknowns, coefficients: &TimeCoefficients) -> SparseColMat<usize, f64> {
    let el = objective.elastic;
    let n = el.node_count();
    // Supports' rows are not in W: the sum over the middle node of L M⁻¹ L skips them (the
    // other two blocks only couple free nodes, which are never supports).
    let inv_mass: Vec<f64> = el.mass.iter().zip(&objective.supports).map(|(m, &support)| if support { 0.0 } else { 1.0 / m }).collect();
    let k = el.stiffness.sandwich_diagonal(&inv_mass);
    let l = &el.stiffness;
    let s_count = coefficients.slots;
    let (mm, ml, kk) = (&coefficients.mm, &coefficients.ml, &coefficients.kk);
    // Columns of node b, for every b in parallel: (column lengths, rows, values).
    let blocks: Vec<(Vec<usize>, Vec<usize>, Vec<f64>)> = (0..n)
        .into_par_iter()
        .map(|b| {
            let (mut lens, mut rows, mut vals) = (Vec::new(), Vec::new(), Vec::new());
            let neighbours: Vec<(usize, f64, f64)> = k.row(b).filter(|&(a, _)| a >= b).map(|(a, kab)| (a, l.get(a, b), kab)).collect();
            for s2 in 0..s_count {
                if unknowns.get(b, s2).is_none() {
                    continue;
                }
                let start = rows.len();
                for &(a, lab, kab) in &neighbours {
                    let mab = if a == b { el.mass[a] } else { 0.0 };
                    for s1 in 0..s_count {
                        if a == b && s1 < s2 {
                            continue;
                        }
                        let Some(u) = unknowns.get(a, s1) else { continue };
                        let at = s1 * s_count + s2;
                        if !((a == b && mm[at] != 0.0) || ml[at] != 0.0 || kk[at] != 0.0) {
                            continue;
                        }
                        rows.push(u);
                        vals.push(mm[at] * mab + ml[at] * lab + kk[at] * kab);
                    }
                }
                lens.push(rows.len() - start);
            }
            (lens, rows, vals)
        })
        .collect();
    let dim = unknowns.count();
    let mut col_ptr = Vec::with_capacity(dim + 1);
    col_ptr.push(0usize);
    let total: usize = blocks.iter().map(|b| b.1.len()).sum();
    let (mut rows, mut vals) = (Vec::with_capacity(total), Vec::with_capacity(total));
    for (lens, r, v) in blocks {
        for len in lens {
            col_ptr.push(col_ptr.last().unwrap() + len);
        }
        rows.extend(r);
        vals.extend(v);
    }
    // The checked constructor validates sortedness and bounds.
    let symbolic = SymbolicSparseColMat::new_checked(dim, dim, col_ptr, None, rows);
    SparseColMat::new(symbolic, vals)
}
