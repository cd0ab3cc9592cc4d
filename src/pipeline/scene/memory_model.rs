//! The whole bake's peak memory, predicted from counts: the peak is the largest of the phases'
//! live bytes (import and TetGen, the fit of the keys to the body, the solve, the export with
//! the report measured beside it), each phase's bytes from counts known before it runs
//! ([`BakeCounts`]). `--max-memory` refuses a bake whose estimate is over it before any work
//! starts ([`BakeCounts::before_tetgen`]: the cage's size predicted, TetGen's body at the
//! least it can be), and again once the body is known (before the solve).
//!
//! Each constant is the bytes one count costs in its phase, measured as the resident set of
//! `blendsim bake` sampled through the phases on the scaling bench's scenes (`make
//! bench-scale`, which prints this estimate beside the peak). The process's own code and
//! runtime (about 10 MB) is not counted.

use crate::algorithms::spacetime::global_step::{ModalSize, BYTES_PER_FACTOR_ENTRY};
use crate::support::budget::{frame_count, frames_bytes, samples_bytes, Budget};
use crate::support::error::Result;

use super::{Method, Scene, Solver};

/// Bytes per key and surface vertex while the keys are read and checked (the f64 poses, the
/// masks, the parsers' text and buffers): 158-162 measured at 25k and 100k vertices, 10 keys.
const IMPORT_BYTES_PER_KEY_VERTEX: f64 = 160.0;
/// Bytes per tet of the TetGen process (its mesh structures, pools and output files'
/// buffers; a separate process, so its peak is its own): 12 MiB at 9,840 tets.
const TETGEN_BYTES_PER_TET: f64 = 1300.0;
/// Bytes per key and tet node while the keys are fitted to the body (the interior nodes'
/// equilibrium solves of a TetGen body: every key's node positions and the solves' vectors).
const FIT_BYTES_PER_KEY_NODE: f64 = 200.0;
/// Bytes per key and surface vertex of a cage's fit (the binding's weights, the fitted keys'
/// least-squares systems, the embedded keys measured against the surface's): 72 measured at
/// 100k vertices and 10 keys, over the body's.
const CAGE_FIT_BYTES_PER_KEY_VERTEX: f64 = 72.0;
/// Bytes per key and surface vertex the bake keeps from the import to the export (the keys'
/// surface poses, the surface, the binding of an embedded surface): the solve's peak of the
/// 100k-vertex surface on its cage over the 25k one's, 80 per key and vertex.
const BODY_BYTES_PER_KEY_VERTEX: f64 = 80.0;
/// Bytes per unknown of the solve (one node at one time slot, three coordinates): the
/// iterate, gradient and search direction, the L-BFGS curvature pairs, the trajectory's
/// evaluation buffers. The 1k-node prism's solve (modal, 10,020 unknowns) less its samples and
/// modes: 3,150.
const SOLVE_BYTES_PER_UNKNOWN: f64 = 3150.0;
/// The direct factor's predicted entries are `FACTOR_ENTRIES * (2 x keys x nodes)^FACTOR_FILL_POWER`
/// (nested dissection of a 3-D body times the time slots: held positions leave the fill
/// alone), at [`BYTES_PER_FACTOR_ENTRY`] each. Fitted to the solve's peak less its other terms
/// on the 2.6k, 10k and 21k-node prisms (5 keys) and the 960-node cage (10 keys): 430 MB, 3.2
/// GB, 9.2 GB and 287 MB, within 4% of the fit.
const FACTOR_ENTRIES: f64 = 10.9;
/// See [`FACTOR_ENTRIES`] (4/3 for the factor's entries in theory; the measured peaks grow a
/// little faster, the supernodes' padding and the assembled matrix with them).
const FACTOR_FILL_POWER: f64 = 1.46;
/// The iterative step's per-key block factors: entries per key and `(2 x nodes)^FACTOR_FILL_POWER`
/// (the 30k-node prism at 5 keys: 3.3 GB over its samples and the solver's state).
const BLOCK_ENTRIES: f64 = 4.85;
/// Bytes per key and exported vertex of the export and the report beside it (the blendshape
/// clip's per-key targets and the writers' per-key arrays).
const EXPORT_BYTES_PER_KEY_VERTEX: f64 = 100.0;
/// Bytes per exported vertex of the export and the report, whatever the keys (normals,
/// indices, one frame's two poses in f64 for the report's measures, the glb's buffers). With
/// the per-key term: 1,940 per vertex measured at 100k vertices and 10 keys over the body
/// and the full-frame poses.
const EXPORT_BYTES_PER_VERTEX: f64 = 940.0;

/// How the global step is solved, as far as it is known before the solve.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StepChoice {
    /// A sparse Cholesky factor.
    Direct,
    /// The body's vibration modes.
    Modal,
    /// Conjugate gradients with per-key block factors.
    Iterative,
    /// Not chosen yet (`auto`): the cost model chooses it within what the rest of the solve
    /// leaves of the budget (`step_budget`), so it is not counted here.
    Auto,
    /// No global step (`hermite`, `fit`, mass-spring, nothing free).
    None,
}

impl StepChoice {
    /// The step `solver` forces (`[solver] global_step`), else [`StepChoice::Auto`]; none
    /// without the spacetime method.
    pub(crate) fn of(solver: &Solver) -> StepChoice {
        match (solver.method, solver.global_step.as_str()) {
            (Method::Spacetime, "direct") => StepChoice::Direct,
            (Method::Spacetime, "modal") => StepChoice::Modal,
            (Method::Spacetime, "iterative") => StepChoice::Iterative,
            (Method::Spacetime, _) => StepChoice::Auto,
            _ => StepChoice::None,
        }
    }
}

/// The counts the model reads: known after import, except the body's (predicted before TetGen).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BakeCounts {
    /// Keys (a contact key counted twice).
    pub keys: usize,
    /// Vertices of the keyframes' surface.
    pub surface_vertices: usize,
    /// Vertices of the exported surface (the keyframes', or `[embed] surface`).
    pub exported_vertices: usize,
    /// Tet nodes of the solved body (TetGen's or the cage's).
    pub nodes: usize,
    /// Its tets.
    pub tets: usize,
    /// Unknowns of the solve: nodes x 2 slots per key (position and velocity), less the held.
    pub unknowns: usize,
    /// Held (node, key) positions.
    pub held: usize,
    /// Nodes held at one key or more.
    pub held_nodes: usize,
    /// The body is a cage around the surface (its fit and embedding).
    pub caged: bool,
    /// The body came from TetGen (its process is a phase).
    pub tetgen: bool,
    /// The global step.
    pub step: StepChoice,
}

/// Live bytes of each phase of a bake; its peak is the largest.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PhaseBytes {
    /// Reading and checking the keys.
    pub import: f64,
    /// The TetGen process.
    pub tetgen: f64,
    /// Fitting the keys to the body (the interior nodes, or the cage).
    pub fit: f64,
    /// The solve: the samples, the global step, the solver's state.
    pub solve: f64,
    /// The export and the report measured beside it.
    pub export: f64,
}

impl PhaseBytes {
    /// The phases by name.
    pub fn named(&self) -> [(&'static str, f64); 5] {
        [("import", self.import), ("TetGen", self.tetgen), ("fit", self.fit), ("solve", self.solve), ("export", self.export)]
    }

    /// The bake's peak: the largest phase, and its name.
    pub fn peak(&self) -> (&'static str, f64) {
        self.named().into_iter().fold(("import", f64::NEG_INFINITY), |a, b| if b.1 > a.1 || b.1.is_nan() { b } else { a })
    }
}

/// The direct factor's predicted peak bytes for `slots` node-slots (2 x keys x nodes).
fn direct_bytes(slots: f64) -> f64 {
    BYTES_PER_FACTOR_ENTRY * FACTOR_ENTRIES * slots.powf(FACTOR_FILL_POWER)
}

/// The iterative step's per-key block factors' bytes.
fn iterative_bytes(keys: f64, nodes: f64) -> f64 {
    BYTES_PER_FACTOR_ENTRY * BLOCK_ENTRIES * keys * (2.0 * nodes).powf(FACTOR_FILL_POWER)
}

/// The modal step's bytes: the cost model's prediction ([`ModalSize::predicted`]; every node
/// in the basis, a node is left out only when its velocities are held too).
fn modal_bytes(c: &BakeCounts) -> f64 {
    ModalSize { nodes: c.nodes, slots: 2 * c.keys, held: c.held, held_nodes: c.held_nodes }.predicted().1
}

/// The global step's bytes.
fn step_bytes(c: &BakeCounts) -> f64 {
    let (k, n) = (c.keys as f64, c.nodes as f64);
    let u = 2.0 * k * n;
    match c.step {
        StepChoice::Direct => direct_bytes(u),
        StepChoice::Modal => modal_bytes(c),
        StepChoice::Iterative => iterative_bytes(k, n),
        StepChoice::Auto | StepChoice::None => 0.0,
    }
}

/// Each phase's live bytes for a bake of `scene` with keys at `times` and these counts.
pub fn phase_bytes(scene: &Scene, times: &[f64], c: &BakeCounts) -> PhaseBytes {
    let (k, v, e, n) = (c.keys as f64, c.surface_vertices as f64, c.exported_vertices as f64, c.nodes as f64);
    let frames = match (times.first(), times.last()) {
        (Some(start), Some(end)) => frame_count(*start, *end, scene.fps),
        _ => 0.0,
    };
    let import = IMPORT_BYTES_PER_KEY_VERTEX * k * v;
    let body = BODY_BYTES_PER_KEY_VERTEX * k * v;
    let tetgen = if c.tetgen { TETGEN_BYTES_PER_TET * c.tets as f64 } else { 0.0 };
    let fit = body + if c.caged { CAGE_FIT_BYTES_PER_KEY_VERTEX * k * v } else { FIT_BYTES_PER_KEY_NODE * k * n };
    let samples = samples_bytes(scene.solver.samples, c.keys.saturating_sub(1), c.tets);
    let solve = body + samples + SOLVE_BYTES_PER_UNKNOWN * c.unknowns as f64 + step_bytes(c);
    let export =
        body + frames_bytes(frames, c.exported_vertices, scene.export.full_frame) + EXPORT_BYTES_PER_KEY_VERTEX * k * e + EXPORT_BYTES_PER_VERTEX * e;
    PhaseBytes { import, tetgen, fit, solve, export }
}

/// Nodes of a generated cage over its `[tet] cage_nodes` target, and its tets per node.
const CAGE_NODES_PER_TARGET: f64 = 0.96;
/// See [`CAGE_NODES_PER_TARGET`].
const CAGE_TETS_PER_NODE: f64 = 4.2;
/// The share of a cage's nodes that a whole held surface holds (the mask carried over by
/// binding weight): 528 of 960.
const CAGE_HELD_SHARE: f64 = 0.55;

impl BakeCounts {
    /// The counts before TetGen runs: the body's nodes and tets from the rest surface's
    /// `vertices` and `[tet]`, or exact for a tet-mesh rest shape (`mesh`: nodes and tets).
    /// A surface over `max_nodes` vertices is simulated on a cage of about `cage_nodes`. A
    /// TetGen body is counted at its surface's vertices and as many tets, the least it can be
    /// (TetGen keeps every surface vertex): how many interior nodes `max_volume` adds depends
    /// on how far TetGen can honour it (0.12 to 0.38 per rest volume over `max_volume`
    /// measured; a box at 1e-9 kept tets of 0.02), so a refusal here never rests on them; the
    /// check before the solve counts them. `held` is each key's held vertex count.
    pub(crate) fn before_tetgen(
        scene: &Scene,
        vertices: usize,
        mesh: Option<(usize, usize)>,
        held: &[usize],
        exported_vertices: usize,
    ) -> BakeCounts {
        let keys = held.len();
        let v = vertices as f64;
        let caged = mesh.is_none() && scene.tet.cage && vertices > scene.tet.max_nodes;
        let (nodes, tets) = match mesh {
            Some(counts) => counts,
            None if caged => {
                let n = CAGE_NODES_PER_TARGET * scene.tet.cage_nodes as f64;
                (n as usize, (CAGE_TETS_PER_NODE * n) as usize)
            }
            None => (vertices, vertices),
        };
        let held_share = |h: usize| if caged { CAGE_HELD_SHARE * h as f64 / v.max(1.0) * nodes as f64 } else { h as f64 };
        let held_total = held.iter().map(|&h| held_share(h)).sum::<f64>() as usize;
        let held_nodes = held.iter().map(|&h| held_share(h) as usize).max().unwrap_or(0);
        let simulated = scene.solver.method != Method::Fit;
        let step = StepChoice::of(&scene.solver);
        let (nodes, tets) = if simulated { (nodes, tets) } else { (0, 0) };
        BakeCounts {
            keys,
            surface_vertices: vertices,
            exported_vertices,
            nodes,
            tets,
            unknowns: (2 * keys * nodes).saturating_sub(held_total),
            held: held_total,
            held_nodes,
            caged: caged && simulated,
            tetgen: simulated && mesh.is_none() && !caged,
            step,
        }
    }
}

/// The budget the global step's cost model chooses within: `budget` less the solve's other
/// live bytes (the body, the samples, the solver's state), so that the step it picks keeps the
/// whole solve within `budget`.
pub(crate) fn step_budget(scene: &Scene, times: &[f64], counts: &BakeCounts, budget: &Budget) -> Budget {
    let others = phase_bytes(scene, times, &BakeCounts { step: StepChoice::None, ..*counts }).solve;
    match budget.memory() {
        Some(bytes) => budget.narrowed_to((bytes - others).max(1.0) as u64),
        None => *budget,
    }
}

/// Refuse a bake whose estimated peak is over `budget`: before TetGen with
/// [`BakeCounts::before_tetgen`], and before the solve with the body's own counts (`solving`:
/// the phases still to come, the solve and the export).
pub(crate) fn check(scene: &Scene, times: &[f64], counts: &BakeCounts, budget: &Budget, solving: bool) -> Result<()> {
    let mut phases = phase_bytes(scene, times, counts);
    if solving {
        (phases.import, phases.tetgen, phases.fit) = (0.0, 0.0, 0.0);
    }
    let (phase, bytes) = phases.peak();
    let body = if counts.nodes == 0 {
        String::new()
    } else {
        format!(", {} {} tet nodes and {} keys", if solving { "on its" } else { "on about" }, counts.nodes, counts.keys)
    };
    let fix = match phase {
        "export" => "turn off [export] full_frame, or lower fps",
        "import" | "fit" => "bake fewer or coarser keyframe meshes",
        _ => "make the body coarser (raise [tet] max_volume, or lower [tet] cage_nodes or max_nodes), lower [solver] samples, or set [solver] global_step = \"iterative\"",
    };
    budget.check(bytes, &format!("the whole bake (its peak in the {phase}{body})"), fix)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 5-key bake of a 2k-vertex surface on a 2.6k-node TetGen body, direct step.
    fn counts() -> BakeCounts {
        BakeCounts {
            keys: 5,
            surface_vertices: 2018,
            exported_vertices: 2018,
            nodes: 2633,
            tets: 9840,
            unknowns: 24640,
            held: 1690,
            held_nodes: 338,
            caged: false,
            tetgen: true,
            step: StepChoice::Direct,
        }
    }

    fn scene() -> Scene {
        Scene::parse("name = \"m\"\nfps = 30\n[keyframes]\nmeshes = [\"a.obj\", \"b.obj\"]\ntimes = [0.0, 1.0]\n").unwrap()
    }

    const TIMES: [f64; 5] = [0.0, 0.5, 1.0, 1.5, 2.0];

    #[test]
    fn the_estimate_grows_with_every_count() {
        let (scene, base) = (scene(), counts());
        let peak = |c: &BakeCounts| phase_bytes(&scene, &TIMES, c).peak().1;
        let phases = |c: &BakeCounts| phase_bytes(&scene, &TIMES, c).named().map(|p| p.1);
        let grown: [fn(&mut BakeCounts); 7] = [
            |c| c.keys *= 2,
            |c| c.surface_vertices *= 2,
            |c| c.exported_vertices *= 2,
            |c| c.nodes *= 2,
            |c| c.tets *= 2,
            |c| c.unknowns *= 2,
            |c| c.held *= 2,
        ];
        for (i, grow) in grown.iter().enumerate() {
            let mut c = base;
            grow(&mut c);
            // No phase shrinks, and the peak does not (held entries only enter the modes).
            assert!(phases(&c).iter().zip(phases(&base)).all(|(a, b)| *a >= b), "count {i}");
            assert!(peak(&c) >= peak(&base), "count {i}");
        }
        // The body's size and the keys raise the solve's peak strictly.
        for grow in [grown[0], grown[3], grown[4], grown[5]] {
            let mut c = base;
            grow(&mut c);
            assert!(peak(&c) > peak(&base));
        }
        // A forced step adds its bytes to the solve; `auto` leaves them to the cost model.
        let solve = |step| phase_bytes(&scene, &TIMES, &BakeCounts { step, ..base }).solve;
        for step in [StepChoice::Direct, StepChoice::Modal, StepChoice::Iterative] {
            assert!(solve(step) > solve(StepChoice::Auto));
        }
        assert_eq!(solve(StepChoice::Auto), solve(StepChoice::None));
    }

    #[test]
    fn the_peak_is_the_largest_phase() {
        let mut scene = scene();
        let c = counts();
        let p = phase_bytes(&scene, &TIMES, &c);
        assert_eq!(p.peak(), ("solve", p.solve));
        assert!(p.named().iter().all(|(_, b)| *b <= p.solve && *b >= 0.0));
        // 200k exported vertices at 120 fps with full-frame files: the frames are the peak.
        scene.fps = 120.0;
        scene.export.full_frame = true;
        let wide = BakeCounts { exported_vertices: 200_000, ..c };
        let p = phase_bytes(&scene, &TIMES, &wide);
        assert_eq!(p.peak(), ("export", p.export));
        let frames = frame_count(0.0, 2.0, 120.0) * (16.0 + 24.0 * 200_000.0);
        assert!(p.export > frames && p.export < 2.0 * frames, "{} against {frames}", p.export);
        // The direct step's bytes follow the fill power over the node-slots: 2x nodes,
        // 2^1.46 x the factor.
        let ratio = direct_bytes(2.0 * 52660.0) / direct_bytes(52660.0);
        assert!((ratio - 2f64.powf(FACTOR_FILL_POWER)).abs() < 1e-9);
        // The phases' estimate is the scene's `memory_estimate`.
        assert_eq!(scene.memory_estimate(&TIMES, &wide), p.export);
    }

    #[test]
    fn before_tetgen_the_body_is_predicted_from_the_surface_and_tet() {
        let mut scene = scene();
        scene.tet.cage = false;
        // The 2.6k-node prism's surface: 2,018 vertices, the least TetGen's body can be.
        scene.tet.max_volume = 0.003;
        let c = BakeCounts::before_tetgen(&scene, 2018, None, &[338; 5], 2018);
        assert!((c.nodes, c.tets) == (2018, 2018), "{c:?}");
        assert!(c.tetgen && !c.caged && c.step == StepChoice::Auto && c.held == 1690);
        assert_eq!(c.unknowns, 2 * 5 * c.nodes - 1690);
        // Over max_nodes with the cage on, the cage's size.
        scene.tet.cage = true;
        let caged = BakeCounts::before_tetgen(&scene, 25_370, None, &[25_370; 10], 25_370);
        assert!(caged.caged && !caged.tetgen && caged.nodes == 960 && caged.unknowns < 2 * 10 * 960, "{caged:?}");
        // A tet-mesh rest shape is its own body.
        let mesh = BakeCounts::before_tetgen(&scene, 500, Some((500, 1800)), &[10; 3], 200);
        assert!((mesh.nodes, mesh.tets, mesh.tetgen, mesh.caged) == (500, 1800, false, false));
    }

    #[test]
    fn over_the_budget_the_refusal_names_the_estimate_and_the_budget() {
        let scene = scene();
        let c = BakeCounts::before_tetgen(&scene, 2018, None, &[338; 5], 2018);
        let e = check(&scene, &TIMES, &c, &Budget::new(Some(1 << 20), None), false).unwrap_err();
        assert!(e.problem.starts_with("the scene would need about "), "{}", e.problem);
        assert!(e.problem.contains("for the whole bake (its peak in the solve, on about "), "{}", e.problem);
        assert!(e.problem.ends_with("more than the --max-memory budget of 1.0 MB"), "{}", e.problem);
        assert!(e.fix.contains("[tet] max_volume") && e.fix.ends_with("or raise --max-memory"), "{}", e.fix);
        assert!(check(&scene, &TIMES, &c, &Budget::new(Some(1 << 40), None), false).is_ok());
        // The step's budget is what the rest of the solve leaves.
        let step = step_budget(&scene, &TIMES, &c, &Budget::new(Some(1 << 30), None)).memory().unwrap();
        let rest = phase_bytes(&scene, &TIMES, &BakeCounts { step: StepChoice::None, ..c }).solve;
        assert_eq!(step, (f64::from(1u32 << 30) - rest).floor());
    }
}
