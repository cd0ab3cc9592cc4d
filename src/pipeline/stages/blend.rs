//! Mass-spring blendshapes (Ma et al. 2012, `algorithms::massspring`) as a stage: `blendsim
//! blend` ([`blend()`]): target meshes and convex weights in, blended shapes out (one OBJ, or a
//! vertex cache for a weights file). A keyframe scene's `[solver] method = "mass-spring"` is
//! the `solve` stage's ([`stages::solve`](mod@super::solve)).
//!
//! This layer translates files into the model's plain inputs (target positions, triangles, the
//! tet body, fixed vertices or the default anchor, obstacles) and the blended shapes back into
//! files.

use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::algorithms::frames::MemoryFrames;
use crate::algorithms::geometry::{surface, Point, TriMesh};
use crate::algorithms::massspring::{self, refine, Boundary, MassSpring, Settings, Targets};
use crate::formats::cache::{self, CacheFormat};
use crate::formats::mesh::{obj, selection};
use crate::formats::tetgen::{self, TetgenOptions};
use crate::pipeline::scene::{self, ObstacleSpec};
use crate::support::budget::Budget;
use crate::support::error::{Error, Result};
use crate::support::progress::Progress;

/// The weights of `blendsim blend`.
#[derive(Debug, Clone, PartialEq)]
pub enum Weights {
    /// One blend (`--weights 0.2,0.5,0.3`).
    One(Vec<f64>),
    /// A text file with one blend per line (`--weights-file`): weights separated by commas
    /// or blanks, `#` starts a comment, blank lines are skipped.
    File(PathBuf),
}

/// A `blendsim blend` job: everything is read and checked before anything is written, and
/// nothing is written when any of it fails.
#[derive(Debug, Clone, PartialEq)]
pub struct BlendJob {
    /// The target meshes (OBJ), one topology, the first one the rest of the spring network.
    pub targets: Vec<PathBuf>,
    /// The weights, one per target.
    pub weights: Weights,
    /// The output: an `.obj` for one blend, or any vertex cache `cache::write` names (an OBJ
    /// sequence `frames/frame_####.obj`, `.pc2`, `.mdd`, `.glb`, `.usda`/`.usdc`/`.usd`).
    pub out: PathBuf,
    /// Frame rate of a cache output (frame `i` is blend `i`).
    pub fps: f64,
    /// A vertex selection file (indices, or a `.dmat` mask) of vertices that follow the linear
    /// blend; without one, the default anchor holds the body.
    pub fixed: Option<PathBuf>,
    /// A TOML file of `[[obstacle]]` tables (the scene's obstacle syntax).
    pub obstacles: Option<PathBuf>,
    /// Tetrahedralize target 0 for internal springs (needs a closed surface); false: surface
    /// springs only (open surfaces such as a face mask).
    pub body: bool,
    /// Split surface edges longer than this multiple of the median edge first (the output then
    /// has the refined mesh's vertices: the targets' own first, then one per split).
    pub refine: Option<f64>,
    /// Write the linear blend `Σ w_j x_j` instead (the baseline, for comparison).
    pub linear: bool,
}

/// What [`blend()`] did.
#[derive(Debug, Clone, PartialEq)]
pub struct BlendSummary {
    /// Blends written.
    pub blends: usize,
    /// Vertices of the spring network (surface, interior, anchor).
    pub vertices: usize,
    /// Springs.
    pub springs: usize,
    /// Newton iterations over all blends.
    pub iterations: usize,
    /// Seconds building the model, and blending.
    pub build_seconds: f64,
    /// Seconds blending (all blends).
    pub blend_seconds: f64,
}

/// Blend the targets of `job` and write the result (see [`BlendJob`]).
pub fn blend(job: &BlendJob, budget: &Budget, progress: &Progress) -> Result<BlendSummary> {
    let out_is_obj = job.out.extension().is_some_and(|e| e.eq_ignore_ascii_case("obj")) && CacheFormat::of(&job.out).is_none();
    if out_is_obj && matches!(job.weights, Weights::File(_)) {
        return Err(Error::in_file(
            &job.out,
            "is one OBJ, but a weights file makes one shape per line",
            "write an OBJ sequence (frames/frame_####.obj) or a cache (.pc2, .mdd, .glb, .usda)",
        ));
    }
    if !out_is_obj
        && CacheFormat::of(&job.out).is_none_or(|f| f == CacheFormat::Gltf && job.out.extension().is_some_and(|e| e.eq_ignore_ascii_case("gltf")))
    {
        return Err(Error::in_file(
            &job.out,
            "is not a format blend writes",
            "name the output .obj (one blend), frames/frame_####.obj, .pc2, .mdd, .glb or .usda",
        ));
    }
    if !(job.fps.is_finite() && job.fps > 0.0) {
        return Err(Error::general(format!("--fps {} is not positive", job.fps), "give the cache's frame rate, e.g. 24"));
    }
    if job.targets.len() < 2 {
        return Err(Error::general(format!("{} target mesh given", job.targets.len()), "give at least two targets: --targets a.obj b.obj ..."));
    }
    let meshes: Vec<TriMesh> = job.targets.iter().map(|p| obj::read(p)).collect::<Result<_>>()?;
    let first = &meshes[0];
    for (path, mesh) in job.targets.iter().zip(&meshes).skip(1) {
        if mesh.positions.len() != first.positions.len() {
            return Err(Error::in_file(
                path,
                format!("has {} vertices but {} has {}", mesh.positions.len(), job.targets[0].display(), first.positions.len()),
                "give targets that are one mesh with moved vertices (export them from one object, without remeshing)",
            ));
        }
        if mesh.triangles != first.triangles {
            return Err(Error::in_file(
                path,
                format!("has other triangles than {}", job.targets[0].display()),
                "give targets that are one mesh with moved vertices (export them from one object, without remeshing)",
            ));
        }
    }
    let weights = read_weights(&job.weights, meshes.len())?;
    let n = first.positions.len();
    let boundary = match &job.fixed {
        Some(path) => {
            let mask = selection::read(path, n)?;
            Boundary::Fixed((0..n as u32).filter(|&v| mask[v as usize]).collect())
        }
        None => Boundary::Anchor(None),
    };
    let obstacles = match &job.obstacles {
        Some(path) => read_obstacles(path)?,
        None => Vec::new(),
    };
    if let Some(ratio) = job.refine {
        if !(ratio.is_finite() && ratio > 1.0) {
            return Err(Error::general(
                format!("--refine {ratio} is not above 1"),
                "give the longest edge allowed as a multiple of the median edge, e.g. 2",
            ));
        }
    }
    let (positions, triangles): (Vec<Vec<Point>>, Vec<[u32; 3]>) = match job.refine {
        Some(ratio) if !job.linear => {
            let positions: Vec<Vec<Point>> = meshes.iter().map(|m| m.positions.clone()).collect();
            let refined = refine::split_long_edges(&positions, &first.triangles, ratio);
            (refined.surface, refined.triangles)
        }
        _ => (meshes.iter().map(|m| m.positions.clone()).collect(), first.triangles.clone()),
    };
    let first = &TriMesh { positions: positions[0].clone(), triangles, attributes: None };
    if job.linear {
        let shapes: Vec<Vec<Point>> = weights.iter().map(|w| massspring::linear_blend(&positions, w)).collect();
        write_shapes(job, first, shapes, out_is_obj)?;
        return Ok(BlendSummary {
            blends: weights.len(),
            vertices: first.positions.len(),
            springs: 0,
            iterations: 0,
            build_seconds: 0.0,
            blend_seconds: 0.0,
        });
    }
    let body = if job.body {
        if !surface::open_edges(first).is_empty() {
            return Err(Error::in_file(
                &job.targets[0],
                "is not a closed surface, so it cannot be tetrahedralized for internal springs",
                "close the surface, or pass --no-body for surface springs only",
            ));
        }
        let bar = progress.stage("blend: TetGen");
        let d = scene::Tet::default();
        // With refinement, interior edges are bounded like the surface's (a regular tet's volume).
        let max_volume =
            job.refine.map_or(d.max_volume, |ratio| refine::regular_tet_volume(ratio * refine::median_edge(&positions[..1], &first.triangles)));
        let body = tetgen::run_within(first, &TetgenOptions { quality: d.quality, max_volume, timeout: d.timeout }, &job.targets[0], budget)?;
        bar.finish_and_clear();
        Some(body)
    } else {
        None
    };
    let targets = Targets { surface: &positions, triangles: &first.triangles, body: body.as_ref(), body_poses: None };
    let start = Instant::now();
    let bar = progress.stage("blend: springs");
    let mut model =
        MassSpring::new(&targets, &boundary, &Settings { budget: *budget, ..Settings::default() }).map_err(|e| in_targets(e, &job.targets))?;
    bar.finish_and_clear();
    let build_seconds = start.elapsed().as_secs_f64();
    let start = Instant::now();
    let bar = progress.bar(weights.len() as u64, "blend: equilibria");
    let mut shapes = Vec::with_capacity(weights.len());
    let mut iterations = 0;
    for (done, w) in weights.iter().enumerate() {
        budget.check_time("mass-spring blend", || format!("after {done} of {} blends", weights.len()))?;
        let shape = model.blend(w, &obstacles).map_err(|e| in_targets(e, &job.targets))?;
        iterations += shape.report.iterations;
        shapes.push(shape.surface().to_vec());
        bar.inc(1);
    }
    bar.finish_and_clear();
    let blend_seconds = start.elapsed().as_secs_f64();
    write_shapes(job, first, shapes, out_is_obj)?;
    let summary = model.summary();
    Ok(BlendSummary {
        blends: weights.len(),
        vertices: summary.surface_vertices + summary.interior_vertices + summary.anchor_points,
        springs: summary.springs,
        iterations,
        build_seconds,
        blend_seconds,
    })
}

/// One OBJ, or a cache with one frame per shape.
fn write_shapes(job: &BlendJob, mesh: &TriMesh, mut shapes: Vec<Vec<Point>>, out_is_obj: bool) -> Result<()> {
    if out_is_obj {
        let shape = TriMesh { positions: shapes.pop().expect("one blend"), triangles: mesh.triangles.clone(), attributes: mesh.attributes.clone() };
        crate::support::output::write_atomic(&job.out, obj::write(&shape).as_bytes())
    } else {
        let mut frames = MemoryFrames { times: (0..shapes.len()).map(|i| i as f64 / job.fps).collect(), frames: shapes };
        cache::write(&job.out, mesh, &mut frames, job.fps)
    }
}

/// The model's errors concern the targets as a set: say which files.
fn in_targets(e: Error, targets: &[PathBuf]) -> Error {
    if e.path.is_some() {
        return e;
    }
    let names: Vec<String> = targets.iter().map(|p| p.display().to_string()).collect();
    Error { problem: format!("targets {}: {}", names.join(", "), e.problem), ..e }
}

/// The weight vectors, each checked convex (see [`Weights`]).
fn read_weights(weights: &Weights, targets: usize) -> Result<Vec<Vec<f64>>> {
    let tolerance = Settings::default().weight_tolerance;
    match weights {
        Weights::One(w) => {
            massspring::check_weights(w, targets, tolerance).map_err(|e| Error { problem: format!("--weights: {}", e.problem), ..e })?;
            Ok(vec![w.clone()])
        }
        Weights::File(path) => {
            let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, &e, "read the weights file"))?;
            let mut all = Vec::new();
            for (number, line) in text.lines().enumerate() {
                let line = line.split('#').next().unwrap_or("").trim();
                if line.is_empty() {
                    continue;
                }
                let w: Vec<f64> = line
                    .split(|c: char| c == ',' || c.is_whitespace())
                    .filter(|s| !s.is_empty())
                    .map(|s| {
                        s.parse::<f64>().map_err(|_| {
                            Error::in_file(
                                path,
                                format!("line {}: {s:?} is not a number", number + 1),
                                "write one blend per line: weights separated by commas or spaces",
                            )
                        })
                    })
                    .collect::<Result<_>>()?;
                massspring::check_weights(&w, targets, tolerance)
                    .map_err(|e| Error::in_file(path, format!("line {}: {}", number + 1, e.problem), e.fix))?;
                all.push(w);
            }
            if all.is_empty() {
                return Err(Error::in_file(path, "has no weights", "write one blend per line, e.g. 0.2,0.5,0.3"));
            }
            Ok(all)
        }
    }
}

/// `[[obstacle]]` tables from a TOML file.
fn read_obstacles(path: &Path) -> Result<Vec<massspring::Obstacle>> {
    #[derive(serde::Deserialize)]
    #[serde(deny_unknown_fields)]
    struct File {
        #[serde(default)]
        obstacle: Vec<ObstacleSpec>,
    }
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, &e, "read the obstacles file"))?;
    let file: File = toml::from_str(&text).map_err(|e| {
        Error::in_file(
            path,
            format!("is not an obstacles file: {}", e.message()),
            "write [[obstacle]] tables: kind = \"plane\" with point, normal; kind = \"sphere\" with center, radius",
        )
    })?;
    file.obstacle
        .iter()
        .enumerate()
        .map(|(i, o)| model_obstacle(o).validated(&format!("obstacle {}", i + 1)).map_err(|e| e.with_path(path)))
        .collect()
}

/// A scene's or an obstacles file's `[[obstacle]]` as the mass-spring model's.
pub(crate) fn model_obstacle(o: &ObstacleSpec) -> massspring::Obstacle {
    match *o {
        ObstacleSpec::Plane { point, normal } => massspring::Obstacle::Plane { point, normal },
        ObstacleSpec::Sphere { center, radius } => massspring::Obstacle::Sphere { center, radius },
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pipeline::scene::{Method, Scene};

    const SCENE: &str = "name = \"s\"\n[keyframes]\nmeshes = [\"a.obj\", \"b.obj\"]\ntimes = [0.0, 1.0]\n[solver]\nmethod = \"mass-spring\"\n";

    #[test]
    fn mass_spring_table_parses_with_defaults_and_refuses_bad_values() {
        let s = Scene::parse(SCENE).unwrap();
        assert_eq!(s.solver.method, Method::MassSpring);
        assert_eq!(s.mass_spring, scene::MassSpring::default());
        let s = Scene::parse(&format!(
            "{SCENE}[mass_spring]\ninbetweens = 5\nbending = \"hinge\"\n[[obstacle]]\nkind = \"sphere\"\ncenter = [0, 1, 0]\nradius = 0.5\n"
        ))
        .unwrap();
        assert_eq!(s.mass_spring.inbetweens, 5);
        assert_eq!(s.obstacles, vec![ObstacleSpec::Sphere { center: [0.0, 1.0, 0.0], radius: 0.5 }]);
        for (table, says) in [
            ("bending = \"none\"", "bending"),
            ("tolerance = 0.0", "tolerance"),
            ("inbetweens = 5000", "inbetweens"),
            ("[[obstacle]]\nkind = \"plane\"\npoint = [0, 0, 0]\nnormal = [0, 0, 0]", "obstacle"),
            ("[[obstacle]]\nkind = \"cube\"", "cube"),
            ("stiffness = 1.0", "stiffness"),
        ] {
            let e = Scene::parse(&format!("{SCENE}[mass_spring]\n{table}\n")).unwrap_err();
            assert!(e.to_string().contains(says), "{table}: {e}");
        }
    }

    #[test]
    fn weights_files_take_commas_blanks_and_comments() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path();
        let path = dir.join("w.txt");
        std::fs::write(&path, "# header\n0.2, 0.8\n\n  1 0   # end\n0.5\t0.5\n").unwrap();
        let w = read_weights(&Weights::File(path.clone()), 2).unwrap();
        assert_eq!(w, vec![vec![0.2, 0.8], vec![1.0, 0.0], vec![0.5, 0.5]]);
        std::fs::write(&path, "# nothing\n").unwrap();
        assert!(read_weights(&Weights::File(path.clone()), 2).unwrap_err().to_string().contains("has no weights"));
        let e = read_weights(&Weights::One(vec![0.5, 0.6]), 2).unwrap_err();
        assert!(e.to_string().starts_with("--weights: the weights 0.5,0.6 sum to 1.1"), "{e}");
    }
}
