use super::*;
use crate::algorithms::physics::elastic::Elastic;
use crate::algorithms::physics::pcg::SymmetricOperator;
use crate::algorithms::spacetime::solver::objective;
use crate::algorithms::spacetime::tests::{keys, material, settings};
use crate::support::testing::{cube_mesh, Rng};

/// The measurements' body: a `CUBE`-per-side (default 13) Kuhn cube stretched to 1.2 x 3.6
/// x 1.2, bent over `KEYS` (default 20) keys of 0.5 s, its bottom face held at every key.
pub(super) fn many_keys_problem() -> (Elastic, crate::algorithms::spacetime::unknowns::KeyConstraints, usize) {
    let n: usize = std::env::var("CUBE").ok().and_then(|v| v.parse().ok()).unwrap_or(13);
    let kc: usize = std::env::var("KEYS").ok().and_then(|v| v.parse().ok()).unwrap_or(20);
    // `PRISM=d MAX_VOLUME=v`: the benchmark's prism series body instead (TetGen on the
    // 1.2 x 3.6 x 1.2 prism of d x 3d x d cells: 22 and 0.0005 give its 10k-node row).
    let prism: usize = std::env::var("PRISM").ok().and_then(|v| v.parse().ok()).unwrap_or(0);
    let mesh = if prism > 0 {
        let max_volume: f64 = std::env::var("MAX_VOLUME").ok().and_then(|v| v.parse().ok()).unwrap_or(0.0005);
        let surface = crate::algorithms::procedural::prism([1.2, 3.6, 1.2], [prism, 3 * prism, prism]);
        crate::formats::tetgen::run(
            &surface,
            &crate::formats::tetgen::TetgenOptions { quality: 1.414, max_volume, timeout: 600.0 },
            std::path::Path::new("prism"),
        )
        .unwrap()
    } else {
        let mut mesh = cube_mesh(n);
        for p in &mut mesh.positions {
            *p = [p[0] * 1.2, p[1] * 3.6, p[2] * 1.2];
        }
        mesh
    };
    let el = Elastic::new(&mesh, &material()).unwrap();
    let times: Vec<f64> = (0..kc).map(|k| 0.5 * k as f64).collect();
    let poses = (0..kc).map(|k| mesh.positions.iter().map(|p| [p[0] + 0.05 * (k as f64).sin() * p[1] * p[1], p[1], p[2]]).collect()).collect();
    let bottom: Vec<u32> = (0..mesh.positions.len() as u32).filter(|&i| mesh.positions[i as usize][1] == 0.0).collect();
    let k = keys(times, poses, vec![bottom; kc], false);
    (el, k, kc)
}

/// `cargo test --release --lib cg_at_20_keys -- --ignored --nocapture`
#[test]
#[ignore]
fn cg_at_20_keys() {
    let (el, k, kc) = many_keys_problem();
    let mut s = settings();
    s.damping = 0.1;
    let obj = objective(&el, &k, &s);
    let unknowns = Unknowns::new(&k, el.node_count());
    let t = std::time::Instant::now();
    let it = GlobalStep::within(&obj, unknowns.clone(), s.regularization, &Budget::new(Some(1), None)).unwrap();
    // The predicted seconds at the cost model's two-thread factorization rate (`choose`'s,
    // past PARALLEL_FACTOR_FLOPS as here); they include the solves' sweeps, so this bounds the factorization's flops from above.
    let flops = it.stats.predicted_seconds * FACTOR_FLOPS_PER_SECOND[1];
    println!(
        "{} nodes, {kc} keys, {} unknowns: iterative setup {:.2} s, predicted direct {flops:.3e} flops {:.1} GB {:.1} s",
        el.node_count(),
        it.stats.unknowns,
        t.elapsed().as_secs_f64(),
        it.stats.predicted_bytes / 1e9,
        it.stats.predicted_seconds
    );
    if let Some(Inverse::Iterative(itr)) = &it.cholesky {
        let x: Vec<Point> = (0..it.stats.unknowns).map(|i| [i as f64, 1.0, 2.0]).collect();
        let mut y = x.clone();
        let t = std::time::Instant::now();
        for _ in 0..5 {
            itr.operator.apply(&x, &mut y);
        }
        let mv = t.elapsed().as_secs_f64() / 5.0;
        let t = std::time::Instant::now();
        for _ in 0..5 {
            itr.preconditioner.apply(&x, &mut y);
        }
        println!(
            "matrix nnz {} factor nnz {}: matvec {:.4} s, preconditioner {:.4} s",
            it.stats.matrix_nnz,
            it.stats.factor_nnz,
            mv,
            t.elapsed().as_secs_f64() / 5.0
        );
    }
    let mut rng = Rng(7);
    let g: Vec<Vec<Point>> =
        (0..unknowns.slots.count()).map(|_| (0..unknowns.nodes).map(|_| [rng.next(), rng.next(), rng.next()]).collect()).collect();
    let t = std::time::Instant::now();
    let modal = GlobalStep::build(&obj, unknowns.clone(), s.regularization, &Budget::default(), Some(Method::Modal)).unwrap();
    println!(
        "modal setup {:.2} s (predicted {:.1} s, {:.0} MB)",
        t.elapsed().as_secs_f64(),
        modal.stats.predicted_modal_seconds,
        modal.stats.predicted_modal_bytes / 1e6
    );
    let t = std::time::Instant::now();
    let by_modes = modal.step(&g);
    println!("modal solve {:.3} s", t.elapsed().as_secs_f64());
    let by_cg = it.step(&g);
    let scale = by_cg.iter().flatten().map(|p| crate::algorithms::geometry::norm(*p)).fold(0.0, f64::max);
    let diff = by_cg
        .iter()
        .flatten()
        .zip(by_modes.iter().flatten())
        .map(|(a, b)| crate::algorithms::geometry::norm(crate::algorithms::geometry::sub(*a, *b)))
        .fold(0.0, f64::max);
    println!("modal vs CG: max difference {:.2e} of the largest entry", diff / scale);
    for round in 0..3 {
        let t = std::time::Instant::now();
        let gg: Vec<Vec<Point>> = g.iter().map(|v| v.iter().map(|p| [p[0] + 0.01 * round as f64 * p[1], p[1], p[2]]).collect()).collect();
        let _ = it.step(&gg);
        println!("solve {round}: {:.2} s, {:?}", t.elapsed().as_secs_f64(), it.cg_log());
    }
}
