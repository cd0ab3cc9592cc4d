//! The `import` stage: read the scene's keyframe meshes, check they share one topology,
//! apply procedural deformations, orient the rest shape, and resolve the per-key vertex
//! selections (the scene's `fixed` and `fixed_velocity`) into sets. A contact key
//! (`contact = [k]`) is duplicated here, so every later stage sees the contact as what it is:
//! two keys at the same time.

use std::borrow::Cow;
use std::path::PathBuf;

use super::key_meshes::{resolve_selection, KeyMeshes};
use crate::algorithms::geometry::{self, surface, Point};
use crate::formats::mesh;
use crate::pipeline::scene::memory_model::{self, BakeCounts};
use crate::pipeline::scene::{SceneFile, Selection};
use crate::pipeline::stage_file::{Keyframes, Shape, VertexSet};
use crate::support::budget::Budget;
use crate::support::error::{Error, Result};

/// Read and check the keyframes of a scene.
pub fn import(scene_file: &SceneFile, budget: &Budget) -> Result<Keyframes> {
    let scene = &scene_file.scene;
    let keys = match (&scene.keyframes, &scene.cache) {
        (Some(keys), _) => keys,
        (None, Some(cache)) => return super::import_cache::import(scene_file, cache, budget),
        (None, None) => return Err(Error::general("the scene has neither [keyframes] nor [cache]", "add one of them (formats/scene.md)")),
    };
    let mut meshes = match &keys.clip {
        Some(_) => super::import_clip::read(scene_file, keys, budget)?,
        None => KeyMeshes::read(scene_file, budget)?,
    };
    // A clip's keys are at its frames' own times.
    let key_times = meshes.times.take().unwrap_or_else(|| keys.times.clone());
    let weld = if keys.weld() { meshes.weld(scene_file)? } else { None };
    let (rest, rest_source) = meshes.rest_shape(scene_file, weld.as_ref())?;
    let rest_points = rest.positions();
    // Selections number the input's vertices (index files): resolved on the input's rest
    // points (a welded vertex stands at each of its input vertices' places), then welded.
    let input_rest: Cow<[Point]> = match &weld {
        Some(w) => w.map.iter().map(|&v| rest_points[v as usize]).collect(),
        None => Cow::Borrowed(rest_points),
    };
    let resolve = |sel: &Selection| -> Result<Vec<bool>> {
        let mask = resolve_selection(sel, scene_file, &input_rest)?;
        Ok(match &weld {
            Some(w) => w.mask(&mask),
            None => mask,
        })
    };
    // One selection per key, usually the same one at every key: each distinct one is resolved
    // (its file read) once.
    let masks = |list: &Option<Vec<Selection>>, default: Selection| -> Result<Vec<VertexSet>> {
        let mut resolved: Vec<(&Selection, VertexSet)> = Vec::new();
        (0..meshes.poses.len())
            .map(|k| {
                let sel = list.as_ref().map_or(&default, |l| &l[k]);
                if let Some((_, set)) = resolved.iter().find(|(s, _)| *s == sel) {
                    return Ok(set.clone());
                }
                let set = VertexSet::from_mask(&resolve(sel)?);
                resolved.push((sel, set.clone()));
                Ok(set)
            })
            .collect()
    };
    let fixed = masks(&keys.fixed, Selection::All)?;
    let fixed_velocity = masks(&keys.fixed_velocity, Selection::None)?;
    if keys.cyclic {
        meshes.check_loop(rest_points)?;
    }
    check_key_volumes(&rest, &meshes.poses, &meshes.paths)?;
    check_key_precision(rest_points, &meshes.poses, &meshes.paths)?;
    let display = match &scene.embed.surface {
        Some(p) => {
            let mut s = mesh::obj::read(&scene_file.resolve(p))?;
            surface::orient_outward(&mut s);
            Some(s)
        }
        None => None,
    };
    // Before TetGen: the exported vertices, and the fewest tets a tet mesh of the rest shape
    // can have (each boundary triangle is a face of a tet, a tet has 4 faces).
    let (vertices, tets) = match &rest {
        Shape::Surface(s) => (s.positions.len(), s.triangles.len().div_ceil(4)),
        Shape::Volume(v) => (v.positions.len(), v.tets.len()),
    };
    let vertices = display.as_ref().map_or(vertices, |d| d.positions.len());
    scene.check_resources(&key_times, vertices, tets, budget)?;
    // A contact key is duplicated at its own time: the two share the pose and the masks (the
    // solver aliases their positions), not the velocities.
    let input_bytes = meshes.bytes();
    let (mut times, mut poses, mut fixed, mut fixed_velocity) = (key_times, meshes.poses, fixed, fixed_velocity);
    for &k in keys.contact.iter().rev() {
        times.insert(k + 1, times[k]);
        poses.insert(k + 1, poses[k].clone());
        fixed.insert(k + 1, fixed[k].clone());
        fixed_velocity.insert(k + 1, fixed_velocity[k].clone());
    }
    // The whole bake's estimate, the body's counts predicted, before TetGen starts.
    let mesh = match &rest {
        Shape::Surface(_) => None,
        Shape::Volume(v) => Some((v.positions.len(), v.tets.len())),
    };
    let held: Vec<usize> = fixed.iter().map(VertexSet::len).collect();
    let counts = BakeCounts::before_tetgen(scene, rest_points.len(), mesh, &held, vertices);
    memory_model::check(scene, &times, &counts, budget, false)?;
    Ok(Keyframes {
        scene: scene.clone(),
        rest_source: rest_source.display().to_string(),
        rest,
        times,
        poses,
        fixed,
        fixed_velocity,
        cyclic: keys.cyclic,
        display,
        cache: None,
        input_bytes,
        weld: weld.map(|w| w.map),
    })
}

/// A key's tet at this fraction of its rest volume or below is flattened (a `folded-key` warning).
pub(crate) const FLAT_TET_RATIO: f64 = 1e-3;

/// How far from the origin, in rest bounding-box diagonals, a key's coordinates may lie: the
/// files keep positions as 32-bit floats, whose spacing there is 2^13 * 2^-23 = 2^-10 (about
/// 0.1%) of the diagonal. Farther, the shape is rounded by more (keys moved 1e12 units away
/// came back 19801 diagonals off).
pub const MAX_OFFSET_DIAGONALS: f64 = 8192.0;

/// Every key's coordinates must be within [`MAX_OFFSET_DIAGONALS`] of the origin, so the
/// exported 32-bit positions keep the shape.
fn check_key_precision(rest: &[Point], poses: &[Vec<Point>], paths: &[PathBuf]) -> Result<()> {
    let diagonal = geometry::bbox_diagonal(rest);
    if diagonal.is_nan() || diagonal <= 0.0 {
        return Ok(()); // the rest shape's own checks report it
    }
    for (k, pose) in poses.iter().enumerate() {
        let farthest = pose.iter().flat_map(|p| p.iter()).fold(0.0f64, |m, c| m.max(c.abs()));
        let offset = farthest / diagonal;
        if offset.is_nan() || offset > MAX_OFFSET_DIAGONALS {
            return Err(Error::in_file(
                &paths[k],
                format!(
                    "key {k} has a coordinate of {farthest:.3e}, {offset:.1e} times the rest shape's size ({diagonal:.3e}) from the origin, beyond the {MAX_OFFSET_DIAGONALS} that the files' 32-bit positions keep to 0.1%"
                ),
                "move the object near the origin before exporting the keys (or check that every key is in the same units)",
            ));
        }
    }
    Ok(())
}

/// A key whose enclosed volume is negative (mirrored: a negative scale in the exporter) or
/// almost zero (flattened or collapsed) against the rest shape's is an error naming the key:
/// the solver would either fight the inversion or have nothing to keep, and the report would
/// show volumes down to -100%. Both are fixed in the modeling tool, not by blendsim.
fn check_key_volumes(rest: &Shape, poses: &[Vec<Point>], paths: &[PathBuf]) -> Result<()> {
    let volume = |p: &[Point]| match rest {
        Shape::Surface(s) => surface::enclosed_volume(p, &s.triangles),
        Shape::Volume(v) => v.volume_at(p),
    };
    let rest_points = rest.positions();
    let rest_volume = volume(rest_points);
    if rest_volume.is_nan() || rest_volume <= 0.0 {
        return Ok(()); // the rest shape's own checks report it
    }
    for (k, pose) in poses.iter().enumerate() {
        let ratio = volume(pose) / rest_volume;
        let problem = if ratio < 0.0 {
            "is inside out (mirrored)"
        } else if ratio < 1e-3 {
            "is flattened or collapsed"
        } else {
            continue;
        };
        return Err(Error::in_file(
            &paths[k],
            format!("key {k} {problem}: it encloses {:.1}% of the rest shape's volume", 100.0 * ratio),
            "re-export the key from the same object without a zero or negative scale",
        ));
    }
    // A key that inverts or flattens some tets (a rig pose folding a joint) bakes: the local step
    // projects an inverted tet to its nearest rotation. `tetrahedralize` warns about it.
    Ok(())
}
