use super::experiment::many_keys_problem;
use super::*;
use crate::algorithms::spacetime::solver::objective;
use crate::algorithms::spacetime::tests::settings;
use crate::support::testing::Rng;
use faer::sparse::SparseColMat;

/// CPU seconds of the process (all threads), from getrusage.
fn cpu() -> f64 {
    let mut u: libc::rusage = unsafe { std::mem::zeroed() };
    unsafe { libc::getrusage(libc::RUSAGE_SELF, &mut u) };
    let t = |v: libc::timeval| v.tv_sec as f64 + v.tv_usec as f64 * 1e-6;
    t(u.ru_utime) + t(u.ru_stime)
}

fn timed<T>(name: &str, f: impl FnOnce() -> T) -> T {
    let (w, c) = (std::time::Instant::now(), cpu());
    let out = f();
    println!("{name:<44} wall {:8.3} s  cpu {:8.3} s", w.elapsed().as_secs_f64(), cpu() - c);
    out
}

/// The global step's matrix of [`many_keys_problem`] with its fill-reducing order (every
/// order allowed): what the factorization measurements factor.
fn many_keys_matrix() -> (usize, Unknowns, SparseColMat<usize, f64>, FillReducingOrder) {
    let (el, k, kc) = many_keys_problem();
    let s = settings();
    let obj = objective(&el, &k, &s);
    let unknowns = Unknowns::new(&k, el.node_count());
    let c = TimeCoefficients::new(&obj, proximal_weight(&obj, s.regularization));
    let a = assemble(&obj, &unknowns, &c);
    let order = fill_reducing_order(&a, &unknowns, &el.rest, |_| true);
    (kc, unknowns, a, order)
}

/// The numeric factorization of the global step's matrix: faer's (one thread, both cores
/// inside its dense kernels) against ours ([`Cholesky::refactor`]: the two halves of the
/// elimination tree on two threads), medians of `REPEAT` (default 3), wall and CPU
/// seconds. `CUBE=13 KEYS=5 cargo test --release --lib factor_on_two_cores -- --ignored --nocapture`
#[test]
#[ignore]
fn factor_on_two_cores() {
    let (kc, unknowns, a, order) = many_keys_matrix();
    let repeat: usize = std::env::var("REPEAT").ok().and_then(|v| v.parse().ok()).unwrap_or(3);
    println!(
        "{} nodes, {kc} keys, {} unknowns, {} ordering, {:.3e} flops predicted, load {}",
        unknowns.nodes,
        unknowns.count(),
        order.name,
        order.cost.flops,
        std::fs::read_to_string("/proc/loadavg").unwrap_or_default().trim()
    );
    let mut chol = Cholesky::factor(&a, &FillOrdering::Custom(order.perm.clone()), Par::rayon(0)).unwrap();
    println!("factor entries {}\n{}", chol.factor_nnz(), chol.shape_report());
    let median = |mut v: Vec<(f64, f64)>| {
        v.sort_by(|a, b| a.0.total_cmp(&b.0));
        v[v.len() / 2]
    };
    let mut run = |name: &str, par: Par, ours: bool| {
        let times: Vec<(f64, f64)> = (0..repeat)
            .map(|_| {
                let (w, c0) = (std::time::Instant::now(), cpu());
                chol.par = par;
                if ours {
                    chol.refactor(&a).unwrap()
                } else {
                    chol.refactor_by_faer(&a).unwrap()
                }
                (w.elapsed().as_secs_f64(), cpu() - c0)
            })
            .collect();
        let (w, c) = median(times);
        println!(
            "{name:<36} wall {w:8.3} s  cpu {c:8.3} s  {:.3e} predicted flops per wall s, {:.3e} per CPU s",
            order.cost.flops / w,
            order.cost.flops / c
        );
        (w, chol.values_for_tests().to_vec())
    };
    // Our phases' thread CPU seconds on one thread: the two-core time they predict.
    let _ = run("(warm-up)", Par::Seq, true);
    *crate::algorithms::physics::cholesky::phases::CPU.lock().unwrap() = [0.0; 6];
    let _ = run("ours Par::Seq, phases timed", Par::Seq, true);
    let p = crate::algorithms::physics::cholesky::phases::CPU.lock().unwrap().map(|v| v / repeat as f64);
    let (total, path) = (p[0] + p[1] + p[2] + p[3] + p[4], p[0].max(p[1]) + p[5] + p[4]);
    println!("phases (thread CPU s): groups {:.3} + {:.3}, top halves {:.3} + {:.3} (longer {:.3}), top dense {:.3}; two-core critical path with the dense blocks on one core {:.3} s: {:.2}x", p[0], p[1], p[2], p[3], p[5], p[4], path, total / path);
    println!(
        "one thread: {:.3e} predicted flops per CPU s of the phases; two cores by the critical path: {:.3e}",
        order.cost.flops / total,
        order.cost.flops / path
    );
    let (faer_seq, reference) = run("faer Par::Seq", Par::Seq, false);
    let (faer_par, _) = run("faer Par::rayon", Par::rayon(0), false);
    let (ours_seq, one) = run("ours Par::Seq", Par::Seq, true);
    let (ours_par, two) = run("ours Par::rayon", Par::rayon(0), true);
    assert!(one.iter().zip(&two).all(|(x, y)| x.to_bits() == y.to_bits()));
    let scale = reference.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let worst = two.iter().zip(&reference).fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
    println!("speed-up over faer Par::Seq: faer rayon {:.2}x, ours seq {:.2}x, ours rayon {:.2}x; largest difference from faer {:.1e} of the largest entry", faer_seq / faer_par, faer_seq / ours_seq, faer_seq / ours_par, worst / scale);
}

/// A field of `/proc/self/status` in bytes (`VmHWM`: the peak resident set, `VmRSS`).
fn status_bytes(field: &str) -> f64 {
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    status.lines().find_map(|l| l.strip_prefix(field)?.trim().strip_suffix("kB")?.trim().parse::<f64>().ok()).map_or(0.0, |kb| kb * 1024.0)
}

/// The numeric factorization's own peak memory against what [`predicted_peak_bytes`]
/// assumes: the resident peak is reset (`/proc/self/clear_refs`) after the assembly, the
/// ordering and the symbolic analysis, then the factor is computed by ours (`FACTOR=ours`,
/// the default) or by faer (`FACTOR=faer`). One factorization per process, so the two
/// compare: `CUBE=13 KEYS=5 FACTOR=faer cargo test --release --lib factor_peak_memory --
/// --ignored --nocapture`.
#[test]
#[ignore]
fn factor_peak_memory() {
    let (kc, unknowns, a, order) = many_keys_matrix();
    let faer = std::env::var("FACTOR").is_ok_and(|v| v == "faer");
    let mut chol = Cholesky::analyse(&a, &FillOrdering::Custom(order.perm.clone()), Par::rayon(0));
    let before = status_bytes("VmRSS:");
    std::fs::write("/proc/self/clear_refs", "5").expect("reset the peak resident set");
    let (w, c0) = (std::time::Instant::now(), cpu());
    if faer {
        chol.refactor_by_faer(&a).unwrap()
    } else {
        chol.refactor(&a).unwrap()
    }
    let (wall, cpu_s) = (w.elapsed().as_secs_f64(), cpu() - c0);
    let peak = status_bytes("VmHWM:");
    let entries = chol.factor_nnz() as f64;
    let matrix = a.compute_nnz() as f64;
    println!(
        "{} nodes, {kc} keys, {} unknowns, {} ({:.3e} flops, {:.3e} entries predicted; {:.3e} stored), matrix {:.3e} entries, load {}",
        unknowns.nodes,
        unknowns.count(),
        order.name,
        order.cost.flops,
        order.cost.entries,
        entries,
        matrix,
        std::fs::read_to_string("/proc/loadavg").unwrap_or_default().trim()
    );
    println!(
        "{}: {wall:.2} s wall, {cpu_s:.2} CPU s; resident before {:.0} MB (of which the factor's zero pages are not resident), peak during {:.0} MB: {:.0} MB over before = {:.2} bytes per factor entry; process peak {:.2} bytes per entry; predicted peak {:.0} MB",
        if faer { "faer" } else { "ours" },
        before / 1e6,
        peak / 1e6,
        (peak - before) / 1e6,
        (peak - before) / entries,
        peak / entries,
        predicted_peak_bytes(&order.cost) / 1e6
    );
}

/// `cargo test --release --lib modal_setup_phases -- --ignored --nocapture` (CUBE, KEYS).
#[test]
#[ignore]
fn modal_setup_phases() {
    let (el, k, kc) = many_keys_problem();
    let s = settings();
    let obj = objective(&el, &k, &s);
    let unknowns = Unknowns::new(&k, el.node_count());
    println!(
        "{} nodes, {kc} keys, {} unknowns, load {}",
        el.node_count(),
        unknowns.count(),
        std::fs::read_to_string("/proc/loadavg").unwrap_or_default().trim()
    );
    let c = timed("time coefficients", || TimeCoefficients::new(&obj, proximal_weight(&obj, s.regularization)));
    let a = timed("assemble", || assemble(&obj, &unknowns, &c));
    let order = timed("fill_reducing_order", || fill_reducing_order(&a, &unknowns, &el.rest, |_| true));
    println!("  {} {:.3e} flops", order.name, order.cost.flops);
    let _ = timed("key_block_order", || key_block_order(&NodeOrders::new(&a, &unknowns, &el.rest), &unknowns));
    let size = modal_size(&obj, &unknowns);
    println!("  modal size {size:?}, predicted {:?}", size.predicted());
    let _ = timed("fill_reducing_order without keys", || fill_reducing_order(&a, &unknowns, &el.rest, |_| false));
    if std::env::var("DIRECT").is_ok() {
        for par in [Par::Seq, Par::rayon(0)] {
            let chol = timed(&format!("Cholesky::factor {par:?}"), || Cholesky::factor(&a, &FillOrdering::Custom(order.perm.clone()), par).unwrap());
            println!("  factor entries {}", chol.factor_nnz());
            let mut x: Vec<Point> = (0..unknowns.count()).map(|i| [i as f64, 1.0, 2.0]).collect();
            timed("  solve_rows3", || chol.solve_rows3(&mut x));
        }
    }
    let modes = timed("Modes::new (rayon)", || Modes::new(&el, &obj.supports, Par::rayon(0)).unwrap());
    if std::env::var("SEQ").is_ok() {
        let _ = timed("Modes::new (seq)", || Modes::new(&el, &obj.supports, Par::Seq).unwrap());
    }
    let step = timed("ModalStep::new (rayon)", || ModalStep::new(modes, &c, &unknowns, Par::rayon(0)).unwrap());
    let whole = timed("GlobalStep::build (modal, whole set-up)", || {
        GlobalStep::build(&obj, unknowns.clone(), s.regularization, &Budget::default(), Some(Method::Modal)).unwrap()
    });
    println!("  {:?}", whole.stats);
    drop(whole);
    let chosen = timed("GlobalStep::build (the cost model's choice)", || {
        GlobalStep::build(&obj, unknowns.clone(), s.regularization, &Budget::default(), None).unwrap()
    });
    println!("  {:?}", chosen.stats);
    drop(chosen);
    let mut rng = Rng(7);
    let x0: Vec<Point> = (0..unknowns.count()).map(|_| [rng.next(), rng.next(), rng.next()]).collect();
    for r in 0..3 {
        let mut x = x0.clone();
        timed(&format!("solve {r}"), || step.solve(&unknowns, &mut x));
    }
    let nn = size.nodes;
    let phi = faer::Mat::<f64>::from_fn(nn, nn, |i, j| ((i * 3 + j * 5) % 11) as f64);
    let r = faer::Mat::<f64>::from_fn(3 * c.slots, nn, |i, j| ((i * 7 + j) % 13) as f64);
    let mut y = faer::Mat::<f64>::zeros(3 * c.slots, nn);
    for par in [Par::rayon(0), Par::Seq] {
        timed(&format!("GEMM {}x{nn}x{nn} {par:?}", 3 * c.slots), || {
            faer::linalg::matmul::matmul(y.as_mut(), faer::Accum::Replace, r.as_ref(), phi.as_ref(), 1.0, par)
        });
        timed(&format!("GEMM^T {}x{nn}x{nn} {par:?}", 3 * c.slots), || {
            faer::linalg::matmul::matmul(y.as_mut(), faer::Accum::Replace, r.as_ref(), phi.transpose(), 1.0, par)
        });
    }
}
