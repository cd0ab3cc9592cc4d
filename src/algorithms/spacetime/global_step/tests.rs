use super::*;
use crate::algorithms::physics::elastic::Elastic;
use crate::algorithms::physics::pcg::SymmetricOperator;
use crate::algorithms::spacetime::solver::objective;
use crate::algorithms::spacetime::tests::{keys, material, settings};
use crate::algorithms::testing::cube_mesh;
use crate::support::testing::Rng;

/// Ten keys of a bent cube, the bottom held at the first: enough keys for the
/// key-separator candidate.
fn problem() -> (Elastic, KeyConstraints) {
    let mesh = cube_mesh(4);
    let el = Elastic::new(&mesh, &material()).unwrap();
    let times: Vec<f64> = (0..10).map(|k| 0.2 * k as f64).collect();
    let poses = (0..10).map(|k| mesh.positions.iter().map(|p| [p[0] + 0.05 * k as f64 * p[1] * p[1], p[1], p[2]]).collect()).collect();
    let bottom: Vec<u32> = (0..mesh.positions.len() as u32).filter(|&i| mesh.positions[i as usize][1] == 0.0).collect();
    let mut fixed = vec![Vec::new(); 10];
    fixed[0] = bottom;
    (el, keys(times, poses, fixed, false))
}

use crate::algorithms::physics::pcg::SymmetricRows;
use crate::algorithms::spacetime::unknowns::KeyConstraints;

#[test]
fn the_cost_model_prefers_the_faster_solver_within_the_budget() {
    // A small factor: direct. A factor with 100x the entries of all key blocks and 1e13
    // flops: iterative. Over the budget: iterative whatever the time.
    let small = Cost { flops: 1e9, entries: 1e6 };
    let blocks = Cost { flops: 1e8, entries: 5e5 };
    assert_eq!(choose(&small, &blocks, None, true, u64::MAX).0, Method::Direct);
    let huge = Cost { flops: 1e13, entries: 5e7 };
    let (method, [(ds, db), _, (is, ib)]) = choose(&huge, &blocks, None, true, u64::MAX);
    assert!(method == Method::Iterative && is < ds && ib < db, "{ds} {is}");
    assert_eq!(choose(&small, &blocks, None, true, 1).0, Method::Iterative);
    // A body of 2.6k nodes with 20 keys (40 slots) and 3.4k held entries on 169 nodes: the
    // modes beat both (predicted), within a budget that holds them but not the factor.
    let modal = ModalSize { nodes: 2600, slots: 40, held: 3400, held_nodes: 170 };
    let (modal_seconds, modal_bytes) = modal.predicted();
    let key_blocks = Cost { flops: 1e11, entries: 7e7 };
    assert_eq!(choose(&small, &blocks, Some(&modal), true, u64::MAX).0, Method::Direct, "a fast direct step is kept");
    let (method, [_, (ms, mb), _]) = choose(&huge, &key_blocks, Some(&modal), true, u64::MAX);
    assert_eq!((method, ms, mb), (Method::Modal, modal_seconds, modal_bytes));
    assert!(modal_bytes < 1e9, "{modal_bytes}");
    assert_eq!(choose(&huge, &key_blocks, Some(&modal), true, (modal_bytes * 0.9) as u64).0, Method::Iterative);
}

/// The choice on problem sizes recorded from the project's bodies (the costs `build` weighs,
/// with the measured outcome): the 2744-node cube with 20 keys and with 5 keys, the bottom
/// held at every key (set-up timed phase by phase), and the small bodies of the demo and the paper.
#[test]
fn the_cost_model_on_recorded_problem_sizes() {
    // 20 keys: the node order (the key separators are not weighed: even 4x fewer flops
    // would not make the direct step the choice), 1.4e13 flops and 1.1e9 entries (the
    // factorization measured 60 s and 6.9 GB with the key-separator order); the per-key
    // blocks; the modes measured 8 CPU s to set up and 0.13-0.19 CPU s per solve, CG 4.9-5.5 s
    // per solve.
    let direct = Cost { flops: 13999542089240.0, entries: 1098108520.0 };
    let blocks = Cost { flops: 37876401839.99901, entries: 58123760.0 };
    let modal = ModalSize { nodes: 2744, slots: 40, held: 3920, held_nodes: 196 };
    let (method, [(ds, db), (ms, mb), (is, _)]) = choose(&direct, &blocks, Some(&modal), true, 3 << 30);
    assert_eq!(method, Method::Modal, "{ds} {ms} {is}");
    assert!(db > 1e10 && mb < 5e8 && ms < is / 5.0 && ms < ds / 5.0, "{db} {mb} {ms} {is} {ds}");
    // Under a budget below the modes' dense matrices, CG.
    assert_eq!(choose(&direct, &blocks, Some(&modal), true, (mb * 0.9) as u64).0, Method::Iterative);
    // The cut the key separators may bring does not change that.
    let optimistic = Cost { flops: direct.flops / KEY_SEPARATOR_MAX_GAIN, entries: direct.entries / KEY_SEPARATOR_MAX_GAIN };
    assert_eq!(choose(&optimistic, &blocks, Some(&modal), true, u64::MAX).0, Method::Modal);
    // 5 keys: measured 6.9 CPU s to factorize (2.2e11 flops, 87M entries) and 0.126 CPU s
    // per solve, against the modes' 6.2-6.8 CPU s and 0.055-0.094 CPU s per solve: over a
    // bake's solves the modes are faster.
    let direct = Cost { flops: 218794320635.0, entries: 68641705.0 };
    let blocks = Cost { flops: 9469100459.999752, entries: 14530940.0 };
    let modal = ModalSize { nodes: 2744, slots: 10, held: 980, held_nodes: 196 };
    assert_eq!(choose(&direct, &blocks, Some(&modal), true, u64::MAX).0, Method::Modal);
    // ARMADILLO-size (2630 nodes, 5 keys, nothing held: 8.3e10 flops, 50M entries), idle:
    // the direct step factorizes in 2.0 s and solves in 0.046 s; the modes took 11.4 s to
    // set up and 0.20 s a solve at load 10. Direct (Table 1's precompute and iteration).
    let direct = Cost { flops: 8.3e10, entries: 50.15e6 };
    let blocks = Cost { flops: 4.0e9, entries: 10.0e6 };
    let modal = ModalSize { nodes: 2630, slots: 10, held: 0, held_nodes: 0 };
    let (method, [(ds, _), (ms, _), _]) = choose(&direct, &blocks, Some(&modal), true, u64::MAX);
    assert_eq!(method, Method::Direct, "direct {ds} s, modal {ms} s");
    // Small bodies, with the bakes' measured precompute plus solves (2026-12-03, load 5, so
    // only the ratios count): the demo (182 nodes, 4 keys of a loop) 0.175 s direct against
    // 0.072 s modal, the paper's TWIST 0.71 against 0.26; STRETCH 0.081 direct against 0.122
    // modal, DINO 0.48 against 8.1 (3966 held entries: the capacitance matrix is large).
    let small = |direct: [f64; 2], blocks: [f64; 2], modal: [usize; 4], parallel| {
        let [nodes, slots, held, held_nodes] = modal;
        let cost = |[flops, entries]: [f64; 2]| Cost { flops, entries };
        choose(&cost(direct), &cost(blocks), Some(&ModalSize { nodes, slots, held, held_nodes }), parallel, u64::MAX).0
    };
    assert_eq!(small([1.6977e8, 4.5290e5], [1.1534e7, 1.2121e5], [182, 8, 64, 16], false), Method::Modal, "the demo");
    assert_eq!(small([2.5544e9, 2.9960e6], [1.7333e8, 8.0396e5], [540, 8, 216, 54], true), Method::Modal, "TWIST");
    assert_eq!(small([3.7608e8, 8.5047e5], [1.1602e8, 4.8696e5], [594, 4, 216, 108], false), Method::Direct, "STRETCH");
    assert_eq!(small([3.6684e8, 1.2044e6], [2.5919e7, 4.2553e5], [439, 20, 3966, 439], false), Method::Direct, "DINO");
}

#[test]
fn the_kronecker_sum_is_the_assembled_matrix() {
    // Supports (the bottom held at every key) and a key with extra held nodes: the
    // operator must drop exactly the rows and columns the assembly drops.
    let (el, mut k) = problem();
    let bottom = k.fixed[0].clone();
    for (f, v) in k.fixed.iter_mut().zip(k.fixed_velocity.iter_mut()) {
        f.clone_from(&bottom);
        v.clone_from(&bottom);
    }
    k.fixed[3].extend([40, 41, 42]);
    k.fixed_velocity[5].extend([7, 8]);
    let s = settings();
    let obj = objective(&el, &k, &s);
    assert!(obj.supports.iter().any(|&x| x), "the test needs supports");
    let unknowns = Unknowns::new(&k, el.node_count());
    let c = TimeCoefficients::new(&obj, 1.0 / s.regularization.powi(4));
    let a = assemble(&obj, &unknowns, &c);
    let rows = SymmetricRows::from_lower(&a);
    let op = KroneckerSum::new(&obj, &unknowns, &c);
    let mut rng = Rng::new(3);
    let x: Vec<Point> = (0..unknowns.count()).map(|_| [rng.next(), rng.next(), rng.next()]).collect();
    let (mut y0, mut y1) = (vec![[0.0; 3]; x.len()], vec![[1.0; 3]; x.len()]);
    rows.apply(&x, &mut y0);
    SymmetricOperator::apply(&op, &x, &mut y1);
    let scale = y0.iter().map(|p| crate::algorithms::geometry::norm(*p)).fold(0.0, f64::max);
    for (p, q) in y0.iter().zip(&y1) {
        assert!(crate::algorithms::geometry::norm(crate::algorithms::geometry::sub(*p, *q)) <= 1e-12 * scale, "{p:?} vs {q:?}");
    }
    // The same bytes on one thread.
    let mut y2 = vec![[0.0; 3]; x.len()];
    rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap().install(|| SymmetricOperator::apply(&op, &x, &mut y2));
    assert_eq!(y1, y2);
}

fn gradient(unknowns: &Unknowns) -> Vec<Vec<Point>> {
    let mut rng = Rng::new(7);
    (0..unknowns.slots.count()).map(|_| (0..unknowns.nodes).map(|_| [rng.next(), rng.next(), rng.next()]).collect()).collect()
}

#[test]
fn the_iterative_step_over_budget_gives_the_direct_step() {
    let (el, k) = problem();
    let s = settings();
    let obj = objective(&el, &k, &s);
    let unknowns = Unknowns::new(&k, el.node_count());
    let direct = GlobalStep::build(&obj, unknowns.clone(), s.regularization, &Budget::new(Some(u64::MAX), None), Some(Method::Direct)).unwrap();
    let iterative = GlobalStep::within(&obj, unknowns.clone(), s.regularization, &Budget::new(Some(1), None)).unwrap();
    assert_eq!((direct.stats.linear_solver, iterative.stats.linear_solver), ("direct", "iterative"));
    assert!(direct.stats.predicted_bytes > 1.0 && direct.stats.predicted_seconds > 0.0);
    let g = gradient(&unknowns);
    // Twice: the second solve starts from the first's solution (a different right-hand
    // side), and must still converge to the direct answer.
    for g in [g.clone(), g.iter().map(|v| v.iter().map(|p| [p[1], -p[0], 2.0 * p[2]]).collect()).collect()] {
        let (a, b) = (direct.step(&g), iterative.step(&g));
        let scale = a.iter().flatten().map(|p| crate::algorithms::geometry::norm(*p)).fold(0.0, f64::max);
        for (x, y) in a.iter().flatten().zip(b.iter().flatten()) {
            assert!(crate::algorithms::geometry::norm(crate::algorithms::geometry::sub(*x, *y)) <= 1e-7 * scale, "{x:?} vs {y:?}");
        }
    }
}

/// The modal step is the direct step: with positions held at every key (velocities free),
/// with supports and a few extra held entries, at the first times and after a retime; the
/// same bytes when built twice and on one thread.
#[test]
fn the_modal_step_gives_the_direct_step() {
    for variant in 0..2 {
        let (el, mut k) = problem();
        let bottom = k.fixed[0].clone();
        for f in k.fixed.iter_mut() {
            f.clone_from(&bottom);
        }
        if variant == 1 {
            for v in k.fixed_velocity.iter_mut() {
                v.clone_from(&bottom);
            }
            k.fixed[3].extend([40, 41, 42]);
            k.fixed_velocity[5].extend([60, 61]);
        }
        let s = settings();
        let obj = objective(&el, &k, &s);
        assert_eq!(obj.supports.iter().any(|&x| x), variant == 1);
        let unknowns = Unknowns::new(&k, el.node_count());
        let direct = GlobalStep::build(&obj, unknowns.clone(), s.regularization, &Budget::default(), Some(Method::Direct)).unwrap();
        let mut modal = GlobalStep::build(&obj, unknowns.clone(), s.regularization, &Budget::default(), Some(Method::Modal)).unwrap();
        assert_eq!((direct.stats.linear_solver, modal.stats.linear_solver), ("direct", "modal"));
        let g = gradient(&unknowns);
        let close = |a: &[Vec<Point>], b: &[Vec<Point>]| {
            let scale = a.iter().flatten().map(|p| crate::algorithms::geometry::norm(*p)).fold(0.0, f64::max);
            for (x, y) in a.iter().flatten().zip(b.iter().flatten()) {
                assert!(
                    crate::algorithms::geometry::norm(crate::algorithms::geometry::sub(*x, *y)) <= 1e-9 * scale,
                    "variant {variant}: {x:?} vs {y:?}"
                );
            }
        };
        let step = modal.step(&g);
        close(&direct.step(&g), &step);
        // Held entries stay zero (the step is scattered from the free ones only) and the
        // free ones solve the system: checked through the direct step above.
        let again = GlobalStep::build(&obj, unknowns.clone(), s.regularization, &Budget::default(), Some(Method::Modal)).unwrap();
        assert_eq!(again.step(&g), step);
        let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
        let single =
            one.install(|| GlobalStep::build(&obj, unknowns.clone(), s.regularization, &Budget::default(), Some(Method::Modal)).unwrap().step(&g));
        // The modes' kernels split by a fixed count: the same bytes on one thread.
        assert_eq!(single, step, "variant {variant}: one thread");
        // New key times: the same modes, new per-mode systems.
        let mut k2 = k.clone();
        k2.times = k.times.iter().enumerate().map(|(i, t)| t * (1.0 + 0.05 * (i % 3) as f64)).collect();
        let obj2 = objective(&el, &k2, &s);
        modal.retime(&obj2, s.regularization).unwrap();
        let fresh = GlobalStep::build(&obj2, unknowns.clone(), s.regularization, &Budget::default(), Some(Method::Direct)).unwrap();
        close(&fresh.step(&g), &modal.step(&g));
    }
}

#[test]
fn keys_as_separators_is_a_valid_order_that_solves_the_system() {
    let (el, k) = problem();
    let s = settings();
    let obj = objective(&el, &k, &s);
    let unknowns = Unknowns::new(&k, el.node_count());
    let c = TimeCoefficients::new(&obj, 1.0 / s.regularization.powi(4));
    let a = assemble(&obj, &unknowns, &c);
    let node_order: Vec<u32> = (0..unknowns.nodes as u32).rev().collect();
    let by_keys = key_separator_order(&a, &unknowns, &node_order).unwrap();
    let mut sorted = by_keys.perm.clone();
    sorted.sort_unstable();
    assert_eq!(sorted, (0..unknowns.count()).collect::<Vec<_>>());
    assert!(by_keys.cost.flops > 0.0 && by_keys.node_cost.flops > 0.0);
    // Factorized in that order it solves the system.
    let chol = Cholesky::factor(&a, &FillOrdering::Custom(by_keys.perm), Par::Seq).unwrap();
    let b: Vec<Point> = (0..unknowns.count()).map(|i| [i as f64, 1.0, -1.0]).collect();
    let mut x = b.clone();
    chol.solve_rows3(&mut x);
    let rows = SymmetricRows::from_lower(&a);
    let mut ax = vec![[0.0; 3]; x.len()];
    rows.apply(&x, &mut ax);
    for (p, q) in ax.iter().zip(&b) {
        assert!(crate::algorithms::geometry::norm(crate::algorithms::geometry::sub(*p, *q)) < 1e-8 * (1.0 + crate::algorithms::geometry::norm(*q)));
    }
}
