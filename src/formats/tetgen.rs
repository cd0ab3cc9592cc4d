//! The external TetGen process: write the surface as a PLC, run `tetgen` with a time bound,
//! read `.node`/`.ele` back and check the result.
//!
//! Contract: `-pYzQ` plus `-q{quality}` and `-a{max_volume}` when nonzero, in a private
//! temporary folder. Surface vertices keep their indices: node `i < surface.positions.len()`
//! is surface vertex `i` (checked by position). Diagnosed failures, each an [`Error`] naming
//! the surface file and a fix: `tetgen` not installed (how to install), a surface with a hole
//! (TetGen exits 0 with no tets; name an open edge), self-intersections (exit 134; name the
//! intersecting faces via `tetgen -d` when possible), timeout, unreadable output.
//!
//! The binary is `$BLENDSIM_TETGEN` when set, else `tetgen` on `PATH` (Debian `tetgen` 1.5).
//! What TetGen 1.5 does with vertices no triangle uses (all vertices are passed, so that
//! vertex numbers match the surface file): one inside the body stays a node at its own index
//! and becomes a tet corner (the paper's `rectangular_prism.obj` lists its 252 interior grid
//! points this way); one outside the body, or on top of another vertex, is silently dropped
//! and every later node shifts down, which the position check reports by vertex; one lying
//! on the surface makes TetGen abort, reported with a hint. Cheap problems (holes, duplicate
//! or zero-area triangles) are diagnosed before TetGen runs, because TetGen either says
//! nothing about them (a hole gives zero tets) or aborts with a bare C++ exception.

use std::ffi::{OsStr, OsString};
use std::io::Read;
use std::path::Path;
use std::process::{Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

use crate::algorithms::geometry::surface::open_edges;
use crate::algorithms::geometry::{bbox_diagonal, cross, norm, scale, sub, Bounds, Point, TetMesh, TriMesh};
use crate::formats::mesh::tetgen_io::{first_flat_tet, parse_ele, parse_node, write_smesh};
use crate::formats::work_dir::WorkDir;
use crate::support::budget::Budget;
use crate::support::error::{Error, Result};

/// TetGen's switches and time bound.
#[derive(Debug, Clone, PartialEq)]
pub struct TetgenOptions {
    /// `-q` radius-edge bound; 0 = no quality refinement.
    pub quality: f64,
    /// `-a` maximum volume; 0 = none.
    pub max_volume: f64,
    /// Seconds before the process is killed.
    pub timeout: f64,
}

/// Seconds TetGen is predicted to take on `surface` with `options` (for the progress bar's
/// estimate; measured by `cargo bench --bench demo -- models`): the tets it will make, from the
/// enclosed volume over `max_volume` and the surface's triangles, at a measured cost per tet,
/// plus the process start and the file round trip.
pub fn predicted_seconds(surface: &TriMesh, options: &TetgenOptions) -> f64 {
    let triangles = surface.triangles.len() as f64;
    let volume = crate::algorithms::geometry::surface::enclosed_volume(&surface.positions, &surface.triangles).abs();
    let by_volume = if options.max_volume > 0.0 { TETS_PER_MAX_VOLUME * volume / options.max_volume } else { 0.0 };
    TETGEN_START_SECONDS + TETGEN_SECONDS_PER_TET * (TETS_PER_TRIANGLE * triangles + by_volume)
}

/// The cost model of [`predicted_seconds`] (measured on TetGen 1.5, `-q1.414`, prisms of 770 to
/// 12k surface vertices: 2.0 to 2.9 tets per triangle, 10 to 14 µs of CPU per tet): tets per surface triangle, tets per `max_volume` of enclosed volume,
/// seconds per tet, and the start.
const TETS_PER_TRIANGLE: f64 = 2.5;
const TETS_PER_MAX_VOLUME: f64 = 1.0;
const TETGEN_SECONDS_PER_TET: f64 = 1.2e-5;
const TETGEN_START_SECONDS: f64 = 0.01;

/// Tetrahedralize a closed surface. `source` is the file the surface came from (for errors).
pub fn run(surface: &TriMesh, options: &TetgenOptions, source: &Path) -> Result<TetMesh> {
    run_within(surface, options, source, &Budget::default())
}

/// [`run`], TetGen given at most the time left of `budget` (when less than its timeout).
pub fn run_within(surface: &TriMesh, options: &TetgenOptions, source: &Path, budget: &Budget) -> Result<TetMesh> {
    run_with(&program(), surface, options, source, budget)
}

/// The TetGen binary a run starts: `$BLENDSIM_TETGEN` when set, else `tetgen` (on `PATH`).
pub fn program() -> OsString {
    std::env::var_os("BLENDSIM_TETGEN").filter(|p| !p.is_empty()).unwrap_or_else(|| "tetgen".into())
}

/// [`run_within`] with an explicit TetGen binary (tests use it instead of the variable).
pub(crate) fn run_with(program: &OsStr, surface: &TriMesh, options: &TetgenOptions, source: &Path, budget: &Budget) -> Result<TetMesh> {
    check_surface(surface, source)?;
    let timeout = Duration::try_from_secs_f64(options.timeout).ok().filter(|t| !t.is_zero()).ok_or_else(|| {
        Error::in_file(
            source,
            format!("the TetGen timeout {} s is not a positive duration", options.timeout),
            "set [tet] timeout to a number of seconds, e.g. 120",
        )
    })?;
    // `--max-time` bounds TetGen too: it gets what is left of the budget when that is less.
    let left = budget.time_left();
    if left.is_some_and(|l| l <= 0.0) {
        return Err(budget.time_spent("tetrahedralization", "before TetGen started"));
    }
    let by_max_time = left.is_some_and(|l| l < timeout.as_secs_f64());
    let timeout = left.filter(|_| by_max_time).map_or(timeout, Duration::from_secs_f64);
    let dir = WorkDir::create("tetgen").map_err(|e| Error::io(std::env::temp_dir(), &e, "create a private folder for TetGen"))?;
    let input = dir.path.join(INPUT);
    std::fs::write(&input, write_smesh(surface)).map_err(|e| Error::io(&input, &e, "write the TetGen input"))?;
    let run = run_process(program, &switches(options), &dir.path, timeout, by_max_time.then_some(budget), source)?;
    if !run.status.success() {
        return Err(diagnose_failure(program, surface, &run, &dir.path, timeout, source));
    }
    let node_text = std::fs::read_to_string(dir.path.join("surface.1.node")).map_err(|e| {
        Error::in_file(
            source,
            format!("`{}` finished but wrote no surface.1.node ({e})", program.to_string_lossy()),
            "check that BLENDSIM_TETGEN (or `tetgen` on PATH) is TetGen 1.5: `apt-get install tetgen`",
        )
    })?;
    // TetGen writes no .ele at all when it makes no tets.
    let ele_text = std::fs::read_to_string(dir.path.join("surface.1.ele")).ok();
    check_output(surface, &node_text, ele_text.as_deref(), source)
}

const INPUT: &str = "surface.smesh";

/// `-p` PLC input, `-Y` keep the surface unsplit, `-z` 0-based output, `-Q` quiet.
fn switches(options: &TetgenOptions) -> String {
    let mut switches = String::from("-pYzQ");
    if options.quality > 0.0 {
        switches += &format!("q{}", options.quality);
    }
    if options.max_volume > 0.0 {
        switches += &format!("a{}", options.max_volume);
    }
    switches
}

/// Problems TetGen reports badly or not at all, found cheaply before it runs.
fn check_surface(surface: &TriMesh, source: &Path) -> Result<()> {
    let positions = &surface.positions;
    let fail = |problem: String, fix: &str| Err(Error::in_file(source, problem, fix));
    if surface.triangles.is_empty() {
        return fail("the surface has no triangles to tetrahedralize".into(), "give a closed triangle surface");
    }
    if let Some(v) = positions.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
        return fail(format!("vertex {v} has a non-finite position"), "fix or delete the vertex in your modeling tool");
    }
    for (t, triangle) in surface.triangles.iter().enumerate() {
        if let Some(v) = triangle.iter().find(|&&v| v as usize >= positions.len()) {
            return fail(format!("triangle {t} refers to vertex {v}, but the surface has {} vertices", positions.len()), "re-export the surface");
        }
        let [a, b, c] = triangle.map(|v| positions[v as usize]);
        // Edges scaled by their largest coordinate before any product: squares and cross
        // products overflow for a body 1e300 wide and vanish for one 1e-300 wide. A zero
        // triangle gives NaN: no area.
        let size = [sub(a, b), sub(b, c), sub(c, a)].iter().flatten().fold(0.0f64, |m, x| m.max(x.abs()));
        let unit = |e: Point| scale(e, 1.0 / size);
        let longest = norm(unit(sub(a, b))).max(norm(unit(sub(b, c)))).max(norm(unit(sub(c, a))));
        let area = norm(cross(unit(sub(b, a)), unit(sub(c, a))));
        if area.is_nan() || area <= 1e-12 * longest * longest {
            let [i, j, k] = triangle;
            return fail(
                format!("triangle {t} (vertices {i} {j} {k}) has no area, near {}", at(a)),
                "dissolve degenerate faces in your modeling tool, then re-export",
            );
        }
    }
    let mut keys: Vec<([u32; 3], usize)> = surface
        .triangles
        .iter()
        .enumerate()
        .map(|(t, triangle)| {
            let mut key = *triangle;
            key.sort_unstable();
            (key, t)
        })
        .collect();
    keys.sort_unstable();
    if let Some(w) = keys.windows(2).find(|w| w[0].0 == w[1].0) {
        let [i, j, k] = w[0].0;
        return fail(
            format!("triangles {} and {} both join vertices {i} {j} {k} (a duplicate face)", w[0].1, w[1].1),
            "delete the duplicate face in your modeling tool, then re-export",
        );
    }
    let open = open_edges(surface);
    if let Some(&[a, b]) = open.first() {
        return fail(
            format!(
                "the surface has a hole: the edge from vertex {a} {} to vertex {b} {} belongs to one triangle only ({} open edges in all)",
                at(positions[a as usize]),
                at(positions[b as usize]),
                open.len()
            ),
            "close the hole in your modeling tool (fill it, or merge the vertices along the seam), then re-export",
        );
    }
    // TetGen's predicates multiply up to five coordinates: beyond this extent they overflow
    // or vanish (a box 1e300 wide made it abort).
    let bounds = Bounds::of(positions);
    let extent = (0..3).map(|d| bounds.hi[d] - bounds.lo[d]).fold(0.0f64, f64::max);
    if !(MIN_EXTENT..=MAX_EXTENT).contains(&extent) {
        return fail(
            format!("the surface is {extent:e} units across, outside the {MIN_EXTENT:e} to {MAX_EXTENT:e} that TetGen's arithmetic handles"),
            "export the mesh in sensible units (e.g. metres, and set [export] meters_per_unit)",
        );
    }
    Ok(())
}

/// The extents of a surface TetGen is given (see `check_surface`).
const MIN_EXTENT: f64 = 1e-30;
const MAX_EXTENT: f64 = 1e30;

/// Read TetGen's output and check what the contract promises: some tets, the surface
/// vertices as the first nodes in order, every tet with volume (then oriented positive).
fn check_output(surface: &TriMesh, node_text: &str, ele_text: Option<&str>, source: &Path) -> Result<TetMesh> {
    let unreadable = |file: &str, e: Error| {
        Error::in_file(
            source,
            format!("TetGen wrote an unreadable {file}: {}", e.problem),
            "check that `tetgen` is TetGen 1.5 (Debian package `tetgen`)",
        )
    };
    let (positions, first_index) = parse_node(node_text).map_err(|e| unreadable("surface.1.node", e))?;
    let tets = match ele_text {
        Some(text) => parse_ele(text, first_index, positions.len()).map_err(|e| unreadable("surface.1.ele", e))?,
        None => Vec::new(),
    };
    if tets.is_empty() {
        return Err(Error::in_file(
            source,
            "TetGen made no tetrahedra: it found no closed volume in the surface",
            "make the surface watertight: no holes, no faces inside the body, no zero-thickness parts",
        ));
    }
    let tolerance = 1e-12 * bbox_diagonal(&surface.positions);
    let lost = (0..surface.positions.len()).find(|&i| positions.get(i).is_none_or(|p| norm(sub(*p, surface.positions[i])) > tolerance));
    if let Some(v) = lost {
        let place = at(surface.positions[v]);
        return Err(if surface.triangles.iter().flatten().any(|&u| u as usize == v) {
            Error::in_file(
                source,
                format!("TetGen moved or dropped surface vertex {v} at {place}"),
                "merge duplicate vertices (merge by distance) in your modeling tool, then re-export",
            )
        } else {
            Error::in_file(
                source,
                format!("TetGen dropped vertex {v} at {place}, which no triangle uses: it lies outside the body or on another vertex"),
                "delete loose vertices outside the body in your modeling tool (interior ones may stay), then re-export",
            )
        });
    }
    let mut mesh = TetMesh { positions, tets };
    if let Some(t) = first_flat_tet(&mesh) {
        return Err(Error::in_file(
            source,
            format!("TetGen made a flat tetrahedron {t} (nodes {:?})", mesh.tets[t]),
            "turn on quality refinement ([tet] quality = 1.414)",
        ));
    }
    mesh.orient_positive();
    Ok(mesh)
}

/// Why TetGen failed, as precisely as it can be told: self-intersections found by a
/// `tetgen -d` rerun, else TetGen's own last words and what in the surface may cause them.
fn diagnose_failure(program: &OsStr, surface: &TriMesh, failed: &Finished, dir: &Path, timeout: Duration, source: &Path) -> Error {
    let pairs = run_process(program, "-dz", dir, timeout, None, source)
        .map(|check| intersecting_pairs(&check.stdout, surface.triangles.len()))
        .unwrap_or_default();
    if let Some(&(s, t)) = pairs.first() {
        let [a, b, c] = surface.triangles[s];
        let [d, e, f] = surface.triangles[t];
        return Error::in_file(
            source,
            format!(
                "the surface intersects itself: triangle {s} (vertices {a} {b} {c}, around {}) crosses triangle {t} (vertices {d} {e} {f}) ({} intersecting pairs in all), so TetGen stopped",
                at(centroid([a, b, c].map(|v| surface.positions[v as usize]))),
                pairs.len()
            ),
            "separate or boolean-union the intersecting parts in your modeling tool, then re-export",
        );
    }
    let last_words: Vec<&str> =
        failed.stderr.lines().chain(failed.stdout.lines()).map(str::trim).filter(|l| !l.is_empty() && !l.starts_with("Opening ")).collect();
    let said = match last_words.len() {
        0 => "no message".to_string(),
        n => last_words[n.saturating_sub(3)..].join("; "),
    };
    let mut used = vec![false; surface.positions.len()];
    surface.triangles.iter().flatten().for_each(|&v| used[v as usize] = true);
    let loose = used.iter().filter(|u| !**u).count();
    let hint = match loose {
        0 => String::new(),
        1 => "; 1 vertex is used by no triangle, and TetGen fails if it lies on the surface".to_string(),
        n => format!("; {n} vertices are used by no triangle, and TetGen fails when one lies on the surface"),
    };
    Error::in_file(
        source,
        format!("TetGen failed ({}): {said}; `tetgen -d` found no intersecting faces{hint}", failed.status),
        "clean the surface in your modeling tool (delete loose vertices on it, merge near-duplicate vertices, remove overlapping faces), then re-export",
    )
}

/// Triangle pairs (0-based, deduplicated, sorted) from `tetgen -d` lines such as
/// `  Facet #3 intersects facet #17 at triangles:` (facets are numbered from 1).
fn intersecting_pairs(stdout: &str, triangles: usize) -> Vec<(usize, usize)> {
    let mut pairs: Vec<(usize, usize)> = stdout
        .lines()
        .filter_map(|line| {
            let (s, rest) = line.trim().strip_prefix("Facet #")?.split_once(" intersects facet #")?;
            let t = rest.split_whitespace().next()?;
            let (s, t) = (s.parse::<usize>().ok()?.checked_sub(1)?, t.parse::<usize>().ok()?.checked_sub(1)?);
            (s < triangles && t < triangles).then_some((s.min(t), s.max(t)))
        })
        .collect();
    pairs.sort_unstable();
    pairs.dedup();
    pairs
}

fn centroid([a, b, c]: [Point; 3]) -> Point {
    std::array::from_fn(|d| (a[d] + b[d] + c[d]) / 3.0)
}

/// A point for messages: f32 precision is plenty to find it in a modeling tool.
fn at(p: Point) -> String {
    format!("({}, {}, {})", p[0] as f32, p[1] as f32, p[2] as f32)
}

struct Finished {
    status: ExitStatus,
    stdout: String,
    stderr: String,
}

/// Run `program switches surface.smesh` in `dir`, killing it after `timeout` (what was left of
/// `--max-time` when `by_max_time`, which then names the budget in the error).
fn run_process(program: &OsStr, switches: &str, dir: &Path, timeout: Duration, by_max_time: Option<&Budget>, source: &Path) -> Result<Finished> {
    // Started so that it dies with us (signal or kill), see `interrupt::spawn`.
    let mut guard = crate::support::interrupt::spawn(
        Command::new(program).args([switches, INPUT]).current_dir(dir).stdin(Stdio::null()).stdout(Stdio::piped()).stderr(Stdio::piped()),
    )
    .map_err(|e| {
        Error::in_file(
            source,
            format!("cannot tetrahedralize: `tetgen` is not installed (starting `{}` failed: {e})", program.to_string_lossy()),
            "apt-get install tetgen, or set BLENDSIM_TETGEN to the path of a tetgen binary",
        )
    })?;
    // Drain both pipes while waiting, so a chatty TetGen never blocks on a full pipe.
    fn drain(pipe: Option<impl Read + Send + 'static>) -> std::thread::JoinHandle<String> {
        std::thread::spawn(move || {
            let mut bytes = Vec::new();
            if let Some(mut pipe) = pipe {
                let _ = pipe.read_to_end(&mut bytes);
            }
            String::from_utf8_lossy(&bytes).into_owned()
        })
    }
    crate::support::interrupt::pause_point("tetgen", &format!("(pid {})", guard.id()));
    let child = guard.child();
    let stdout = drain(child.stdout.take());
    let stderr = drain(child.stderr.take());
    let started = Instant::now();
    // A helper thread blocks until the exit and says so: the exit is seen at once (polling
    // with growing pauses saw the demo's 13 ms TetGen up to 8 ms late) and this thread sleeps
    // until then or the timeout.
    let (exited, exit) = std::sync::mpsc::channel();
    let pid = child.id();
    let watcher = std::thread::spawn(move || {
        wait_for_exit(pid);
        let _ = exited.send(());
    });
    let waited = exit.recv_timeout(timeout);
    let elapsed = started.elapsed();
    let outcome = match waited {
        Ok(()) => child.wait().map(Some),
        Err(_) => child.try_wait(),
    };
    let status = match outcome {
        Ok(Some(status)) => status,
        outcome => {
            let _ = child.kill();
            let _ = child.wait();
            let _ = watcher.join();
            return Err(match (outcome, by_max_time) {
                (Err(e), _) => Error::in_file(
                    source,
                    format!("lost track of the TetGen process: {e}"),
                    "retry; if it persists, check the system's process limits",
                ),
                (_, Some(budget)) => budget.time_spent("tetrahedralization", &format!("TetGen stopped after {:.2} s", elapsed.as_secs_f64())),
                _ => Error::in_file(
                    source,
                    format!("TetGen did not finish within {} s and was stopped", timeout.as_secs_f64()),
                    "raise [tet] timeout, or ask for fewer tetrahedra: a larger [tet] max_volume, a looser quality, or a coarser surface",
                ),
            });
        }
    };
    let _ = watcher.join();
    Ok(Finished { status, stdout: stdout.join().unwrap_or_default(), stderr: stderr.join().unwrap_or_default() })
}

/// Block until the child `pid` has exited, without reaping it (`waitid` with `WNOWAIT`: its
/// `Child` still collects the status). Returns at once if it is gone or cannot be waited for.
fn wait_for_exit(pid: u32) {
    loop {
        // SAFETY: waitid writes one siginfo_t it is given.
        let mut info: libc::siginfo_t = unsafe { std::mem::zeroed() };
        let r = unsafe { libc::waitid(libc::P_PID, pid as libc::id_t, &mut info, libc::WEXITED | libc::WNOWAIT) };
        if r == 0 || std::io::Error::last_os_error().raw_os_error() != Some(libc::EINTR) {
            return;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::algorithms::geometry::scale;
    use crate::algorithms::geometry::surface::{boundary, enclosed_volume};
    use crate::algorithms::procedural::{icosphere, prism};
    use crate::formats::mesh::obj;
    use crate::support::testing::paper_asset;

    const TETGEN: &str = "tetgen";

    fn options(quality: f64, max_volume: f64) -> TetgenOptions {
        TetgenOptions { quality, max_volume, timeout: 30.0 }
    }

    fn failure(surface: &TriMesh, options: &TetgenOptions, program: &str) -> String {
        let e = run_with(program.as_ref(), surface, options, Path::new("keys/k0.obj"), &Budget::default()).expect_err("the run must fail");
        let s = e.to_string();
        assert!(s.starts_with("keys/k0.obj: ") && s.contains(" (fix: ") && !s.contains('\n'), "{s}");
        s
    }

    /// What every good run must give: positive tets, the surface as the first nodes, and
    /// (thanks to -Y) the surface triangles as the tet mesh boundary.
    fn assert_faithful(surface: &TriMesh, mesh: &TetMesh) {
        assert_eq!(&mesh.positions[..surface.positions.len()], &surface.positions[..]);
        assert!((0..mesh.tets.len()).all(|t| mesh.signed_volume_at(&mesh.positions, t) > 0.0));
        let canonical = |triangles: &[[u32; 3]]| {
            let mut c: Vec<[u32; 3]> = triangles
                .iter()
                .map(|t| {
                    let k = (0..3).min_by_key(|&k| t[k]).unwrap();
                    [t[k], t[(k + 1) % 3], t[(k + 2) % 3]]
                })
                .collect();
            c.sort_unstable();
            c
        };
        assert_eq!(canonical(&boundary(mesh)), canonical(&surface.triangles), "boundary = input surface");
        let enclosed = enclosed_volume(&surface.positions, &surface.triangles);
        assert!((mesh.volume_at(&mesh.positions) - enclosed).abs() < 1e-9 * enclosed, "volume");
    }

    fn cube_at(origin: Point) -> TriMesh {
        let mut cube = prism([1.0; 3], [1, 1, 1]);
        cube.positions.iter_mut().for_each(|p| *p = [p[0] + origin[0], p[1] + origin[1], p[2] + origin[2]]);
        cube
    }

    #[test]
    fn prism_and_icosphere_keep_their_surface() {
        let box_surface = prism([1.0, 3.0, 1.0], [3, 9, 3]);
        let mesh = run(&box_surface, &options(1.414, 0.0), Path::new("prism.obj")).unwrap();
        assert_faithful(&box_surface, &mesh);
        let sphere = icosphere(2);
        let mesh = run_with(TETGEN.as_ref(), &sphere, &options(1.414, 0.01), Path::new("s.obj"), &Budget::default()).unwrap();
        assert!(mesh.positions.len() > sphere.positions.len(), "refinement adds interior nodes");
        assert_faithful(&sphere, &mesh);
    }

    #[test]
    fn paper_rectangular_prism_keeps_its_interior_points_as_nodes() {
        let Some(path) = paper_asset("stretch3d/rectangular_prism.obj") else { return };
        let surface = obj::read(&path).unwrap();
        let mesh = run_with(TETGEN.as_ref(), &surface, &options(0.0, 0.0), &path, &Budget::default()).unwrap();
        assert_eq!(mesh.positions, surface.positions, "the 252 unused interior points are nodes, no Steiner points");
        let mut used = vec![false; mesh.positions.len()];
        mesh.tets.iter().flatten().for_each(|&v| used[v as usize] = true);
        assert!(used.iter().all(|u| *u), "every interior point is a tet corner");
        let mut oriented = surface.clone();
        crate::algorithms::geometry::surface::orient_outward(&mut oriented);
        assert_faithful(&oriented, &mesh);
        assert!((mesh.volume_at(&mesh.positions) - 4.8).abs() < 1e-12);
    }

    #[test]
    fn a_hole_is_named_before_tetgen_runs() {
        let mut surface = prism([1.0, 1.0, 1.0], [2, 2, 2]);
        let [a, b, c] = surface.triangles.remove(0);
        // Diagnosed before TetGen would be started, so even a missing binary does not matter.
        let s = failure(&surface, &options(0.0, 0.0), "/nonexistent/tetgen");
        let rim = [[b, a], [c, b], [a, c]];
        assert!(
            rim.iter()
                .any(|[u, v]| s.contains(&format!("the surface has a hole: the edge from vertex {u} (")) && s.contains(&format!(" to vertex {v} ("))),
            "{s}"
        );
        assert!(s.contains("(3 open edges in all)") && s.contains("fix: close the hole in your modeling tool"), "{s}");
    }

    #[test]
    fn duplicate_and_flat_triangles_are_named() {
        let mut surface = cube_at([0.0; 3]);
        surface.triangles.push(surface.triangles[4]);
        assert!(failure(&surface, &options(0.0, 0.0), TETGEN).contains("triangles 4 and 12 both join vertices"));
        let mut surface = cube_at([0.0; 3]);
        surface.triangles[2] = [1, 1, 5];
        assert!(failure(&surface, &options(0.0, 0.0), TETGEN).contains("triangle 2 (vertices 1 1 5) has no area"));
    }

    #[test]
    fn triangle_areas_are_judged_at_any_scale() {
        for s in [1e-30, 1e30] {
            let mut surface = cube_at([0.0; 3]);
            surface.positions.iter_mut().for_each(|p| *p = scale(*p, s));
            assert_eq!(check_surface(&surface, Path::new("box.obj")), Ok(()), "a box {s:e} wide");
        }
        // Beyond TetGen's range, the extent is the error, not "no area".
        for s in [1e-300, 1e300] {
            let mut surface = cube_at([0.0; 3]);
            surface.positions.iter_mut().for_each(|p| *p = scale(*p, s));
            let e = check_surface(&surface, Path::new("box.obj")).unwrap_err().to_string();
            assert!(e.contains(&format!("the surface is {s:e} units across, outside the 1e-30 to 1e30")), "{e}");
            surface.triangles[2] = [1, 1, 5];
            assert!(check_surface(&surface, Path::new("box.obj")).unwrap_err().to_string().contains("triangle 2 (vertices 1 1 5) has no area"));
        }
    }

    #[test]
    fn intersecting_boxes_name_a_crossing_pair() {
        let (first, second) = (cube_at([0.0; 3]), cube_at([0.5; 3]));
        let mut surface = first.clone();
        surface.positions.extend(&second.positions);
        surface.triangles.extend(second.triangles.iter().map(|t| t.map(|v| v + 8)));
        let s = failure(&surface, &options(0.0, 0.0), TETGEN);
        assert!(s.contains("the surface intersects itself: triangle "), "{s}");
        let pair = s.split("triangle ").skip(1).map(|t| t.split(' ').next().unwrap().parse::<usize>().unwrap());
        let pair: Vec<usize> = pair.collect();
        assert!(pair[0] < 12 && pair[1] >= 12, "one triangle from each box: {s}");
        assert!(s.contains("intersecting pairs in all") && s.contains("fix: separate or boolean-union"), "{s}");
    }

    #[test]
    fn loose_vertices_outside_or_on_the_surface_are_reported() {
        let mut outside = cube_at([0.0; 3]);
        outside.positions.insert(0, [3.0, 3.0, 3.0]);
        outside.triangles.iter_mut().flatten().for_each(|v| *v += 1);
        let s = failure(&outside, &options(0.0, 0.0), TETGEN);
        assert!(s.contains("TetGen dropped vertex 0 at (3, 3, 3), which no triangle uses"), "{s}");
        let mut on_face = cube_at([0.0; 3]);
        on_face.positions.push([0.5, 0.5, 0.0]);
        let s = failure(&on_face, &options(0.0, 0.0), TETGEN);
        assert!(s.contains("TetGen failed (") && s.contains("1 vertex is used by no triangle"), "{s}");
    }

    #[test]
    fn missing_tetgen_says_how_to_install_it() {
        let s = failure(&cube_at([0.0; 3]), &options(0.0, 0.0), "/nonexistent/tetgen");
        assert!(s.contains("cannot tetrahedralize: `tetgen` is not installed (starting `/nonexistent/tetgen` failed"), "{s}");
        assert!(s.contains("(fix: apt-get install tetgen, or set BLENDSIM_TETGEN"), "{s}");
        let s = failure(&cube_at([0.0; 3]), &options(0.0, 0.0), "true");
        assert!(s.contains("`true` finished but wrote no surface.1.node"), "{s}");
    }

    #[test]
    fn a_run_over_time_is_stopped() {
        // About four million tets are asked for: far more than 0.3 s of work.
        let sphere = icosphere(3);
        let started = Instant::now();
        let s = failure(&sphere, &TetgenOptions { quality: 1.414, max_volume: 1e-6, timeout: 0.3 }, TETGEN);
        assert!(s.contains("TetGen did not finish within 0.3 s and was stopped") && s.contains("fix: raise [tet] timeout"));
        // Stopped at the timeout, not at TetGen's own end (minutes): a bound far above 0.3 s,
        // so that a loaded machine's slow start and cleanup never reach it.
        assert!(started.elapsed() < Duration::from_secs(30), "{:?}", started.elapsed());
        let s = failure(&sphere, &TetgenOptions { timeout: 0.0, ..options(0.0, 0.0) }, TETGEN);
        assert!(s.contains("the TetGen timeout 0 s is not a positive duration"), "{s}");
    }

    #[test]
    fn output_checks_catch_what_tetgen_does_not_say() {
        let cube = cube_at([0.0; 3]);
        let source = Path::new("c.obj");
        let nodes = |points: &[Point]| {
            let mut text = format!("{} 3 0 0\n", points.len());
            points.iter().enumerate().for_each(|(i, p)| text += &format!("{i} {} {} {}\n", p[0], p[1], p[2]));
            text
        };
        let no_tets = check_output(&cube, "0 3 0 0\n", None, source).unwrap_err().to_string();
        assert!(no_tets.contains("TetGen made no tetrahedra") && no_tets.contains("(fix: make the surface watertight"));
        let mut moved = cube.positions.clone();
        moved[5] = scale(moved[5], 1.0 + 1e-9);
        let ele = "1 4 0\n0 0 1 2 4\n";
        let s = check_output(&cube, &nodes(&moved), Some(ele), source).unwrap_err().to_string();
        assert!(s.contains("TetGen moved or dropped surface vertex 5 at (1, 0, 1)"), "{s}");
        let s = check_output(&cube, &nodes(&cube.positions), Some("1 4 0\n0 0 1 2 3\n"), source).unwrap_err().to_string();
        assert!(s.contains("TetGen made a flat tetrahedron 0"), "{s}");
        let s = check_output(&cube, &nodes(&cube.positions), Some("1 4 0\n0 0 1 2 8\n"), source).unwrap_err().to_string();
        assert!(s.contains("TetGen wrote an unreadable surface.1.ele: line 2: tetrahedron 0 refers to node 8"), "{s}");
        let mesh = check_output(&cube, &nodes(&cube.positions), Some(ele), source).unwrap();
        assert_eq!(mesh.tets.len(), 1);
    }

    #[test]
    fn intersection_listing_of_tetgen_1_5_is_parsed() {
        let listing = "Detecting self-intersecting facets...\n  Facet #3 intersects facet #17 at triangles:\n    \
                       (   4,    5,    7) and (   8,    9,   13)\n  Facet #17 intersects facet #3 at triangles:\n  \
                       Facet #9 intersects facet #13 at triangles:\n  Facet #99 intersects facet #1 at triangles:\n\n\
                       !! Found 3 pairs of faces are intersecting.\n";
        assert_eq!(intersecting_pairs(listing, 24), vec![(2, 16), (8, 12)]);
    }

    #[test]
    fn work_folder_is_private_and_removed() {
        let dir = WorkDir::create("tetgen").unwrap();
        let path = dir.path.clone();
        std::fs::write(path.join("surface.1.node"), "0 3 0 0\n").unwrap();
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            assert_eq!(std::fs::metadata(&path).unwrap().permissions().mode() & 0o777, 0o700);
        }
        assert_ne!(WorkDir::create("tetgen").unwrap().path, path);
        drop(dir);
        assert!(!path.exists());
    }
}
