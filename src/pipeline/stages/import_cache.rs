//! The `cache` stage (the `import` of a `[cache]` scene): open the vertex cache, choose its
//! keys (`keyframes = "auto"` or the listed frames), and produce the keyframes stage data,
//! which records how to open the cache again rather than its frames.
//!
//! - the keys' poses are the cache frames at the keys;
//! - `fixed` / `fixed_velocity` are one selection each, applied at every key (the key count may
//!   be chosen automatically); `auto` chooses its keys with the `fixed` vertices pinned, so the
//!   keys fit the constraints the solve will have;
//! - the scene's `fps` becomes the cache's rate: full-frame files and USD weights are sampled
//!   at the cache's frames.
//!
//! [`reopen`] opens the cache again for a later stage and refuses a cache that changed since.

use std::path::{Path, PathBuf};

use crate::algorithms::frames::deviation::{cache_diagonal, deviation, CacheDeviation};
use crate::algorithms::frames::fit::{fit, FitSettings};
use crate::algorithms::frames::keyframes::{select, AutoSettings};
use crate::algorithms::frames::weld::{Weld, Welded};
use crate::algorithms::frames::{FrameRange, FrameSource, Metered};
use crate::algorithms::geometry::{surface, Point, TriMesh};
use crate::algorithms::spacetime::trajectory::Trajectory;
use crate::formats::cache::{CacheFormat, CacheOptions, VertexCache};
use crate::formats::mesh;
use crate::pipeline::scene::{CacheKeys, CacheSpec, Method, Rest, SceneFile, Selection};
use crate::pipeline::stage_file::{CacheRecord, CacheRecordOptions, Keyframes, Shape, VertexSet};
use crate::support::budget::Budget;
use crate::support::error::{Error, Result};

use super::key_meshes::resolve_selection;

/// Modification time of a regular file in ns since the epoch (none for a sequence pattern or
/// a file system without times).
fn modified_ns(path: &Path) -> Option<u64> {
    let meta = std::fs::metadata(path).ok().filter(|m| m.is_file())?;
    let since = meta.modified().ok()?.duration_since(std::time::UNIX_EPOCH).ok()?;
    u64::try_from(since.as_nanos()).ok()
}

fn reader_options(o: &CacheRecordOptions, budget: &Budget) -> CacheOptions {
    CacheOptions {
        budget: *budget,
        fps: o.fps,
        rest: o.rest.as_ref().map(PathBuf::from),
        animation: o.animation.clone(),
        prim: o.prim.clone(),
        object: o.object.clone(),
        take: o.take.clone(),
        meters_per_unit: o.meters_per_unit,
        range: FrameRange { start: o.start, end: o.end },
    }
}

/// Open the cache of `record` again, checking it is the one `import` read (same format,
/// bytes, modification time, frames and vertices).
pub fn reopen(record: &CacheRecord, budget: &Budget) -> Result<VertexCache> {
    let path = Path::new(&record.path);
    let mut cache = VertexCache::open(path, &reader_options(&record.options, budget))?;
    if let Some(map) = record.weld.as_ref().filter(|m| m.len() == cache.frames.vertex_count()) {
        cache = welded(cache, Weld::from_map(map.clone()));
    }
    let now = (cache.format.name(), cache.bytes, modified_ns(path), cache.frame_count(), cache.frames.vertex_count());
    let then = (record.format.as_str(), record.bytes, record.modified_ns, record.frames, record.vertices);
    if now != then {
        return Err(Error::in_file(
            path,
            format!(
                "changed since `blendsim import` read it ({} bytes, {} frames of {} vertices then; {} bytes, {} frames of {} vertices now, or a new modification time)",
                then.1, then.3, then.4, now.1, now.3, now.4
            ),
            "re-run `blendsim import` (or `bake`) on the scene",
        ));
    }
    Ok(cache)
}

/// `cache` on the welded vertices of `weld`: its mesh (the same triangles over the welded
/// vertices, so per-corner attributes stay) and its frames.
fn welded(mut cache: VertexCache, weld: Weld) -> VertexCache {
    cache.mesh.positions = weld.pick(&cache.mesh.positions);
    cache.mesh.triangles = weld.triangles(&cache.mesh.triangles);
    cache.frames = Box::new(Welded::new(cache.frames, weld));
    cache
}

/// The least-squares fit of the cache of `record` on its keys, its `fixed` vertices held on
/// the cache frames at every key.
pub(crate) fn fit_cache(record: &CacheRecord, budget: &Budget) -> Result<Trajectory> {
    let mut cache = reopen(record, budget)?;
    let pins = if record.fixed.is_empty() { Vec::new() } else { vec![record.fixed.to_mask(record.vertices); record.keys.len()] };
    fit(&mut timed(cache.frames.as_mut(), "cache fit", budget), &record.keys, &pins, &FitSettings::default())
        .map_err(|e| e.with_path(Path::new(&record.path)))
}

/// A cache whose every frame read first checks the time budget ([`Budget::check_time`]):
/// the key selection, the fit and the error measure stream the cache, so a frame is their unit
/// of work.
fn timed<'a, S: FrameSource + ?Sized>(
    frames: &'a mut S,
    phase: &'static str,
    budget: &Budget,
) -> Metered<'a, S, impl FnMut(usize, usize) -> Result<()>> {
    let budget = *budget;
    Metered::new(frames, move |_, reads| budget.check_time(phase, || format!("after reading {reads} cache frames")))
}

/// The distance of `trajectory` (over the cache's vertices) from every frame of the cache.
/// It streams the whole cache (once per candidate rank in the export's rank search), so it
/// checks `--max-time` at every frame like the fit.
pub(crate) fn error_against(record: &CacheRecord, trajectory: &Trajectory, budget: &Budget) -> Result<CacheDeviation> {
    let mut cache = reopen(record, budget)?;
    deviation(&mut timed(cache.frames.as_mut(), "cache error measure", budget), trajectory, record.diagonal)
        .map_err(|e| e.with_path(Path::new(&record.path)))
}

/// Write the `[cache]` of a scene (its range, as the scene opens it) to `out`, in the format
/// `out` names: a converter, streaming one frame at a time.
pub fn convert(scene_file: &SceneFile, spec: &CacheSpec, out: &Path) -> Result<()> {
    let (path, options) = open_options(scene_file, spec)?;
    let mut cache = VertexCache::open(&path, &reader_options(&options, &Budget::default()))?;
    crate::formats::cache::write(out, &cache.mesh, cache.frames.as_mut(), cache.fps)
}

/// The scene table that names an animated file: `[cache]`, or `[keyframes]` with a `clip`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Table {
    Cache,
    Clip,
}

/// The checks shared by `[cache]` and `[keyframes] clip` before the file is opened: a PC2 or
/// MDD (positions only) needs `rest = "mesh.obj"` for its triangles (`rest_mesh`), and a file
/// with its own frame times (USD, Alembic, FBX) takes no `fps` (`fps_given`).
pub(super) fn check_rate_and_topology(path: &Path, format: Option<CacheFormat>, table: Table, fps_given: bool, rest_mesh: bool) -> Result<()> {
    if matches!(format, Some(CacheFormat::Pc2 | CacheFormat::Mdd)) && !rest_mesh {
        let (problem, fix) = match table {
            Table::Cache => (
                "holds positions only, so its triangles and rest shape must come from the mesh it animates",
                "give rest = \"mesh.obj\" in [cache], the mesh the cache was baked from",
            ),
            Table::Clip => (
                "holds positions only, so the keys' triangles must come from the mesh it animates",
                "give rest = \"mesh.obj\" in [keyframes], the mesh the clip was baked from",
            ),
        };
        return Err(Error::in_file(path, problem, fix));
    }
    let own_rate = format.filter(|f| matches!(f, CacheFormat::Usd | CacheFormat::Alembic | CacheFormat::Fbx));
    if let (Some(f), true) = (own_rate, fps_given) {
        let (problem, fix) = match (table, f) {
            (Table::Cache, CacheFormat::Usd) => (
                "fps is given, but a USD stage carries its own rate (timeCodesPerSecond)".to_string(),
                "remove fps from [cache]: the stage's rate is used",
            ),
            (Table::Cache, _) => (
                "fps is given, but Alembic and FBX files carry their own frame times".to_string(),
                "remove fps from [cache]: the file's rate is used",
            ),
            (Table::Clip, _) => (
                format!("fps is given in [keyframes], but {} carries its own frame times", f.described()),
                "remove fps from [keyframes]: the file's rate is used",
            ),
        };
        return Err(Error::in_file(path, problem, fix));
    }
    Ok(())
}

/// The resolved cache path and the reader's options of a `[cache]` table.
fn open_options(scene_file: &SceneFile, spec: &CacheSpec) -> Result<(PathBuf, CacheRecordOptions)> {
    let path = scene_file.resolve(&spec.path);
    let format = CacheFormat::of(&path);
    let topology_mesh = matches!(format, Some(CacheFormat::Pc2 | CacheFormat::Mdd));
    let rest_mesh_path = match &spec.rest {
        Some(Rest::Mesh(m)) => Some(scene_file.resolve(m)),
        _ => None,
    };
    check_rate_and_topology(&path, format, Table::Cache, spec.fps.is_some(), rest_mesh_path.is_some())?;
    let options = CacheRecordOptions {
        fps: spec.fps,
        rest: if topology_mesh { rest_mesh_path.as_ref().map(|p| p.display().to_string()) } else { None },
        animation: spec.animation.clone(),
        prim: spec.prim.clone(),
        object: spec.object.clone(),
        take: spec.take.clone(),
        // FBX lengths arrive in the scene's units (metres when it gives none).
        meters_per_unit: (format == Some(CacheFormat::Fbx)).then(|| scene_file.scene.meters_per_unit()),
        start: spec.start,
        end: spec.end,
    };
    Ok((path, options))
}

/// Read a `[cache]` scene: the keyframes stage data, with the record of the cache.
pub fn import(scene_file: &SceneFile, spec: &CacheSpec, budget: &Budget) -> Result<Keyframes> {
    let scene = &scene_file.scene;
    let (path, options) = open_options(scene_file, spec)?;
    let topology_mesh = options.rest.is_some();
    let rest_mesh_path = match &spec.rest {
        Some(Rest::Mesh(m)) => Some(scene_file.resolve(m)),
        _ => None,
    };
    let mut cache = VertexCache::open(&path, &reader_options(&options, budget))?;
    let frames = cache.frame_count();
    let vertices = cache.frames.vertex_count();
    // Vertices equal at every frame are one (a vertex per triangle corner is common in glTF).
    let weld = if spec.weld() && frames >= 2 {
        Some(Weld::find(&mut timed(cache.frames.as_mut(), "cache weld", budget)).map_err(|e| e.with_path(&path))?).filter(|w| !w.is_identity())
    } else {
        None
    };
    if frames < 2 {
        return Err(Error::in_file(
            &path,
            format!("has {frames} frame in the range: nothing moves"),
            "give a range of at least two frames (start, end)",
        ));
    }
    let method = scene.solver.method;
    // The elastic rest shape: the topology mesh, another mesh, or a frame.
    let mut rest = cache.mesh.clone();
    match &spec.rest {
        Some(Rest::Key(f)) => {
            if *f >= frames {
                return Err(Error::in_file(
                    &path,
                    format!("rest = {f}, but the range has {frames} frames"),
                    "give a frame index from `start`, below the frame count",
                ));
            }
            cache.frames.read_frame(*f, &mut rest.positions)?;
        }
        Some(Rest::Mesh(_)) if !topology_mesh => {
            let m = rest_mesh_path.as_deref().expect("a rest mesh");
            let other = mesh::obj::read(m)?;
            if other.positions.len() != vertices || other.triangles != cache.mesh.triangles {
                return Err(Error::in_file(
                    m,
                    format!(
                        "is not the cache's mesh ({} vertices and {} triangles, the cache has {vertices} and {})",
                        other.positions.len(),
                        other.triangles.len(),
                        cache.mesh.triangles.len()
                    ),
                    "give the mesh the cache was made from, with the same vertex order, or a frame index",
                ));
            }
            rest.positions = other.positions;
        }
        _ => {}
    }
    // Selections number the input's vertices (index files), so they are resolved before welding.
    let mask = |sel: &Selection| resolve_selection(sel, scene_file, &rest.positions);
    let (mut fixed, mut fixed_velocity) = (mask(&spec.fixed_for(method))?, mask(spec.fixed_velocity.as_ref().unwrap_or(&Selection::None))?);
    if let Some(w) = &weld {
        (fixed, fixed_velocity) = (w.mask(&fixed), w.mask(&fixed_velocity));
        rest.positions = w.pick(&rest.positions);
        rest.triangles = w.triangles(&rest.triangles);
        cache = welded(cache, w.clone());
    }
    let vertices = cache.frames.vertex_count();
    surface::orient_outward(&mut rest);
    if method != Method::Fit && surface::compact(&rest).1.len() != vertices {
        return Err(Error::in_file(
            &path,
            "has vertices no triangle uses, which cannot be simulated (the solve tetrahedralizes the surface)",
            "remove the loose vertices from the cache, or use [solver] method = \"fit\"",
        ));
    }
    let diagonal = cache_diagonal(cache.frames.as_mut())?;
    let (keys, selection) = match &spec.keyframes {
        CacheKeys::Auto => {
            let settings = AutoSettings {
                tolerance: spec.tolerance(),
                pinned: if fixed.iter().any(|&b| b) { fixed.clone() } else { Vec::new() },
                window_bytes: usize::try_from(spec.window_bytes()).unwrap_or(usize::MAX),
                ..AutoSettings::default()
            };
            let auto = select(&mut timed(cache.frames.as_mut(), "cache key selection", budget), &settings).map_err(|e| e.with_path(&path))?;
            (auto.keys, Some(auto.stats))
        }
        CacheKeys::Frames(list) => {
            if let Some(&f) = list.iter().find(|&&f| f >= frames) {
                return Err(Error::in_file(
                    &path,
                    format!("keyframes lists frame {f}, but the range has {frames} frames"),
                    "list frame indices from `start`, below the frame count",
                ));
            }
            (list.clone(), None)
        }
    };
    let mut poses: Vec<Vec<Point>> = Vec::with_capacity(keys.len());
    for &k in &keys {
        let mut pose = vec![[0.0; 3]; vertices];
        cache.frames.read_frame(k, &mut pose)?;
        poses.push(pose);
    }
    let times: Vec<f64> = keys.iter().map(|&k| cache.frames.time(k)).collect();
    let record = CacheRecord {
        path: path.display().to_string(),
        format: cache.format.name().into(),
        options,
        frames,
        vertices,
        fps: cache.fps,
        fps_note: cache.fps_note(),
        bytes: cache.bytes,
        modified_ns: modified_ns(&path),
        diagonal,
        keys: keys.clone(),
        fixed: VertexSet::from_mask(&fixed),
        tolerance: matches!(spec.keyframes, CacheKeys::Auto).then(|| spec.tolerance()),
        selection,
        meters_per_unit: cache.meters_per_unit,
        weld: weld.map(|w| w.map),
    };
    let mut scene = scene.clone();
    scene.fps = cache.fps;
    // The file's unit is the scene's when the scene gives none (`tetrahedralize` warns when
    // they differ: `units-conflict`).
    let (low, high) = crate::pipeline::scene::METERS_PER_UNIT_RANGE;
    match cache.meters_per_unit {
        // (A file in meters changes nothing: the scene stays as written, bit for bit.)
        Some(m) if scene.units.is_none() && scene.export.meters_per_unit == 1.0 && m != 1.0 && (low..=high).contains(&m) => {
            scene.units = Some(crate::pipeline::scene::Units::MetersPerUnit(m));
        }
        _ => {}
    }
    let per_key = |m: &[bool]| vec![VertexSet::from_mask(m); keys.len()];
    Ok(Keyframes {
        scene,
        rest_source: record.path.clone(),
        rest: Shape::Surface(TriMesh { positions: rest.positions, triangles: rest.triangles, attributes: rest.attributes }),
        times,
        poses,
        fixed: per_key(&fixed),
        fixed_velocity: per_key(&fixed_velocity),
        cyclic: false,
        display: None,
        input_bytes: record.bytes,
        weld: None,
        cache: Some(record),
    })
}
