//! Keys from a clip (`[keyframes] clip`): the poses of one animated file at the listed frames
//! or times, read through the vertex cache readers (any format `[cache]` reads), so a rig's
//! poses need not be exported one OBJ at a time.
//!
//! - the clip is opened as a `[cache]` opens it, whole (no range): `frames` are 0-based in
//!   file order, `times` are on the clip's clock and must each be a frame's time (to a
//!   thousandth of a frame): a pose between frames is not in the file;
//! - the key times are the clip's times of those frames;
//! - the clip's mesh (its triangles, and UVs where the format has them) is the keys' topology;
//!   PC2 and MDD take it from `rest = "mesh.obj"`, which is then also the elastic rest shape.
//!   Vertices that coincide in every key are welded as for `meshes` keys (`[keyframes] weld`);
//!   selections number the clip's own vertices.
//!
//! The rest of the import (selections, rest shape, checks) is the keyframe import's.

use std::path::Path;

use super::import_cache::{check_rate_and_topology, Table};
use super::key_meshes::{KeyMeshes, MeshCache, Topology};
use crate::algorithms::frames::FrameRange;
use crate::algorithms::geometry::Point;
use crate::formats::cache::{CacheFormat, CacheOptions, VertexCache};
use crate::formats::mesh::MeshFile;
use crate::pipeline::scene::{KeyframeSpec, Rest, SceneFile};
use crate::support::budget::Budget;
use crate::support::error::{number, Error, Result};

/// How near a frame's time a listed time must be, in frames.
const TIME_MATCH_FRAMES: f64 = 1e-3;

/// Read the keys of a clip scene: the clip's poses at the listed frames or times.
pub(super) fn read(scene_file: &SceneFile, keys: &KeyframeSpec, budget: &Budget) -> Result<KeyMeshes> {
    let clip = keys.clip.as_deref().expect("a clip scene");
    let path = scene_file.resolve(clip);
    let format = CacheFormat::of(&path);
    let topology_mesh = matches!(format, Some(CacheFormat::Pc2 | CacheFormat::Mdd));
    let rest_mesh = match &keys.rest {
        Rest::Mesh(m) => Some(scene_file.resolve(m)),
        Rest::Key(_) => None,
    };
    check_rate_and_topology(&path, format, Table::Clip, keys.fps.is_some(), rest_mesh.is_some())?;
    let options = CacheOptions {
        fps: keys.fps,
        rest: if topology_mesh { rest_mesh } else { None },
        animation: keys.animation.clone(),
        prim: keys.prim.clone(),
        object: keys.object.clone(),
        take: keys.take.clone(),
        // FBX lengths arrive in the scene's units (metres when it gives none), as for [cache].
        meters_per_unit: (format == Some(CacheFormat::Fbx)).then(|| scene_file.scene.meters_per_unit()),
        range: FrameRange::ALL,
        budget: *budget,
    };
    let mut cache = VertexCache::open(&path, &options)?;
    let frames = match &keys.frames {
        Some(frames) => {
            let count = cache.frame_count();
            if let Some(&f) = frames.iter().find(|&&f| f >= count) {
                return Err(Error::in_file(
                    &path,
                    format!("[keyframes] frames lists frame {f}, but the clip has {count} frames (0 to {})", count - 1),
                    format!("list frame indices from 0 to {}, the clip's frames in file order", count - 1),
                ));
            }
            frames.clone()
        }
        None => keys.times.iter().enumerate().map(|(i, &t)| frame_at(&path, &cache, i, t)).collect::<Result<_>>()?,
    };
    let n = frames.len();
    let mut poses: Vec<Vec<Point>> = Vec::with_capacity(n);
    for (k, &f) in frames.iter().enumerate() {
        budget.check_time("keyframe import", || format!("after reading {k} of {n} keys from the clip"))?;
        let mut pose = vec![[0.0; 3]; cache.frames.vertex_count()];
        cache.frames.read_frame(f, &mut pose).map_err(|e| e.with_path(&path))?;
        poses.push(pose);
    }
    let times: Vec<f64> = frames.iter().map(|&f| cache.frames.time(f)).collect();
    let first = MeshFile::Surface(cache.mesh);
    let first_topology = Topology::of(&first);
    // The clip stands for every key's mesh (and a key's rest shape takes its UVs from it).
    let mut meshes = MeshCache::default();
    meshes.0.insert(path.clone(), first.clone());
    Ok(KeyMeshes { cache: meshes, paths: vec![path; n], first, first_topology, poses, times: Some(times), clip_bytes: Some(cache.bytes) })
}

/// The frame whose time is `t` (to [`TIME_MATCH_FRAMES`]), or an error that gives the clip's
/// span or the frames around `t`.
fn frame_at(path: &Path, cache: &VertexCache, i: usize, t: f64) -> Result<usize> {
    let frames = &cache.frames;
    let count = frames.frame_count();
    let slack = TIME_MATCH_FRAMES / cache.fps;
    let (first, last) = (frames.time(0), frames.time(count - 1));
    let given = format!("[keyframes] times[{i}] = {} s", number(t));
    if !(t >= first - slack && t <= last + slack) {
        return Err(Error::in_file(
            path,
            format!("{given} is outside the clip ({} to {} s, {count} frames)", number(first), number(last)),
            format!("give times on the clip's clock, from {} to {} s, or list frames = [...] (from 0 to {})", number(first), number(last), count - 1),
        ));
    }
    // Times increase: the first frame not before `t` (less the slack), or the one before it.
    let (mut lo, mut hi) = (0, count - 1);
    while lo < hi {
        let mid = (lo + hi) / 2;
        if frames.time(mid) < t - slack {
            lo = mid + 1;
        } else {
            hi = mid;
        }
    }
    if (frames.time(lo) - t).abs() <= slack {
        return Ok(lo);
    }
    let before = lo.saturating_sub(1);
    Err(Error::in_file(
        path,
        format!("{given} falls between frames {before} ({} s) and {lo} ({} s) of the clip", number(frames.time(before)), number(frames.time(lo))),
        "give a frame's time, or list frames = [...] (the clip's frame indices, from 0)",
    ))
}
