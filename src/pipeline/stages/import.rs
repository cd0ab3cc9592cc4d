//! The `import` stage: read the scene's keyframe meshes, check they share one topology,
//! apply procedural deformations, orient the rest shape, and resolve the per-key vertex
//! selections (the scene's `fixed` and `fixed_velocity`) into sets. A contact key
//! (`contact = [k]`) is duplicated here, so every later stage sees the contact as what it is:
//! two keys at the same time.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use rayon::prelude::*;

use crate::algorithms::geometry::{self, surface, Point, TetMesh, TriMesh};
use crate::formats::mesh::{self, MeshFile};
use crate::pipeline::scene::{Rest, SceneFile, Selection};
use crate::pipeline::stage_file::{Keyframes, Shape, VertexSet};
use crate::support::budget::Budget;
use crate::support::error::{Error, Result};

/// The phase `--max-time` names when the keyframe import runs out of it.
const IMPORT_PHASE: &str = "keyframe import";
/// What to do when the keyframe import runs out of `--max-time`.
const IMPORT_TIME_FIX: &str =
    "raise --max-time, or give fewer keys (a long clip keyed at every frame is a vertex cache: give it as [cache] with keyframes = \"auto\")";

/// Meshes read once per path (scenes often repeat the rest mesh).
#[derive(Default)]
pub(super) struct MeshCache(pub(super) HashMap<PathBuf, MeshFile>);

impl MeshCache {
    fn get(&mut self, path: &Path) -> Result<&MeshFile> {
        if !self.0.contains_key(path) {
            let m = mesh::read(path)?;
            self.0.insert(path.to_path_buf(), m);
        }
        Ok(&self.0[path])
    }

    /// Read the files of `paths` not read yet, in parallel (each file parsed on its own, so the
    /// same meshes). A file that fails is left out, for `get` to read again and report in key
    /// order, as without the prefetch.
    /// Files not read once `--max-time` is spent are left out too; the key loop then stops.
    fn prefetch(&mut self, paths: &[PathBuf], budget: &Budget) {
        let mut todo: Vec<&PathBuf> = paths.iter().filter(|p| !self.0.contains_key(p.as_path())).collect();
        todo.sort();
        todo.dedup();
        let read_in_time = |p: &PathBuf| budget.check_time(IMPORT_PHASE, String::new).and_then(|()| mesh::read(p));
        let read: Vec<(PathBuf, Result<MeshFile>)> = todo.into_par_iter().map(|p| (p.clone(), read_in_time(p))).collect();
        self.0.extend(read.into_iter().filter_map(|(p, m)| Some((p, m.ok()?))));
    }
}

/// Topology of a keyframe file, compared between keys. Tets are compared as vertex sets,
/// since readers may reorder a tet's vertices to orient it.
#[derive(PartialEq)]
pub(super) enum Topology {
    Surface(Vec<[u32; 3]>),
    Volume(Vec<[u32; 4]>),
}

impl Topology {
    pub(super) fn of(m: &MeshFile) -> Topology {
        match m {
            MeshFile::Surface(s) => Topology::Surface(s.triangles.clone()),
            MeshFile::Volume(v) => Topology::Volume(
                v.tets
                    .iter()
                    .map(|t| {
                        let mut s = *t;
                        s.sort_unstable();
                        s
                    })
                    .collect(),
            ),
        }
    }

    fn describe(&self) -> (&'static str, usize, &'static str) {
        match self {
            Topology::Surface(t) => ("surface", t.len(), "triangles"),
            Topology::Volume(t) => ("tet mesh", t.len(), "tets"),
        }
    }
}

/// Check that `other` (from `other_path`) has the topology of `first` (from `first_path`).
fn check_same_topology(first: (&Path, &MeshFile, &Topology), other: (&Path, &MeshFile, &Topology)) -> Result<()> {
    let (fp, fm, ft) = first;
    let (op, om, ot) = other;
    let fix = "every keyframe must be the same mesh with moved vertices: export it from the same object without remeshing";
    let (f_kind, f_count, f_what) = ft.describe();
    let (o_kind, o_count, o_what) = ot.describe();
    if f_kind != o_kind {
        return Err(Error::in_file(op, format!("is a {o_kind} but {} is a {f_kind}", fp.display()), "give every keyframe the same kind of file"));
    }
    if fm.positions().len() != om.positions().len() {
        return Err(Error::in_file(op, format!("has {} vertices but {} has {}", om.positions().len(), fp.display(), fm.positions().len()), fix));
    }
    if f_count != o_count {
        return Err(Error::in_file(op, format!("has {o_count} {o_what} but {} has {f_count} {f_what}", fp.display()), fix));
    }
    if ft != ot {
        return Err(Error::in_file(op, format!("has the same counts as {} but its {o_what} connect different vertices", fp.display()), fix));
    }
    Ok(())
}

/// Vertices selected by `selection`, over `rest` positions.
pub(super) fn resolve_selection(selection: &Selection, scene: &SceneFile, rest: &[Point]) -> Result<Vec<bool>> {
    let n = rest.len();
    Ok(match selection {
        Selection::All => vec![true; n],
        Selection::None => vec![false; n],
        Selection::File { file, invert } => {
            let path = scene.resolve(file);
            let mut mask = mesh::selection::read(&path, n)?;
            if *invert {
                mask.iter_mut().for_each(|m| *m = !*m);
            }
            mask
        }
        Selection::Slab { axis, min, max, invert } => rest
            .iter()
            .map(|p| {
                let c = p[axis.index()];
                let inside = min.is_none_or(|lo| c >= lo) && max.is_none_or(|hi| c <= hi);
                inside != *invert
            })
            .collect(),
        Selection::Union(items) => {
            let mut mask = vec![false; n];
            for item in items {
                for (m, s) in mask.iter_mut().zip(resolve_selection(item, scene, rest)?) {
                    *m |= s;
                }
            }
            mask
        }
    })
}

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
    let (rest, rest_source) = meshes.rest_shape(scene_file)?;
    let rest_points = rest.positions();
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
                let set = VertexSet::from_mask(&resolve_selection(sel, scene_file, rest_points)?);
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
    })
}

/// The keyframe meshes of a scene, read and checked against the first.
pub(super) struct KeyMeshes {
    pub(super) cache: MeshCache,
    /// Resolved path of every key's mesh (the clip's, for every key of a clip).
    pub(super) paths: Vec<PathBuf>,
    pub(super) first: MeshFile,
    pub(super) first_topology: Topology,
    /// `poses[key][vertex]`, after any procedural deformation.
    pub(super) poses: Vec<Vec<Point>>,
    /// A clip's: the key times (its frames' times) and the bytes of the clip.
    pub(super) times: Option<Vec<f64>>,
    pub(super) clip_bytes: Option<u64>,
}

impl KeyMeshes {
    /// Read every key's mesh (each file once), check it has the first one's topology, and
    /// deform it as the scene says; `--max-time` is checked before every file and every key.
    fn read(scene_file: &SceneFile, budget: &Budget) -> Result<KeyMeshes> {
        let keys = scene_file.scene.keyframes.as_ref().expect("a keyframe scene");
        let mut cache = MeshCache::default();
        let paths: Vec<PathBuf> = keys.meshes.iter().map(|m| scene_file.resolve(m.path())).collect();
        let n = paths.len();
        cache.prefetch(&paths, budget);
        let first = cache.get(&paths[0])?.clone();
        let first_topology = Topology::of(&first);
        let mut poses: Vec<Vec<Point>> = Vec::with_capacity(keys.meshes.len());
        for (k, key) in keys.meshes.iter().enumerate() {
            budget.check_time_to(IMPORT_PHASE, || format!("after reading {k} of {n} keys"), IMPORT_TIME_FIX)?;
            let m = cache.get(&paths[k])?;
            if k > 0 {
                check_same_topology((&paths[0], &first, &first_topology), (&paths[k], m, &Topology::of(m)))?;
            }
            let mut positions = match key.twist() {
                Some(t) => crate::algorithms::procedural::twist(m.positions(), t),
                None => m.positions().to_vec(),
            };
            if let Some(offset) = key.offset() {
                positions.iter_mut().for_each(|p| *p = std::array::from_fn(|c| p[c] + offset[c]));
            }
            poses.push(positions);
        }
        Ok(KeyMeshes { cache, paths, first, first_topology, poses, times: None, clip_bytes: None })
    }

    /// Bytes of the key files, each file once (a file used by several keys is read once).
    fn bytes(&self) -> u64 {
        if let Some(bytes) = self.clip_bytes {
            return bytes;
        }
        let mut paths: Vec<&PathBuf> = self.paths.iter().collect();
        paths.sort();
        paths.dedup();
        paths.iter().filter_map(|p| std::fs::metadata(p).ok()).map(|m| m.len()).sum()
    }

    /// The elastic rest shape (a key's pose or its own mesh), oriented, and the file it came
    /// from.
    fn rest_shape(&mut self, scene_file: &SceneFile) -> Result<(Shape, PathBuf)> {
        let (rest_positions, rest_source) = match &scene_file.scene.keyframes.as_ref().expect("a keyframe scene").rest {
            Rest::Key(r) => (self.poses[*r].clone(), self.paths[*r].clone()),
            Rest::Mesh(p) => {
                let path = scene_file.resolve(p);
                let m = self.cache.get(&path)?;
                check_same_topology((&self.paths[0], &self.first, &self.first_topology), (&path, m, &Topology::of(m)))?;
                (m.positions().to_vec(), path)
            }
        };
        debug_assert!(self.poses.iter().all(|p| p.len() == rest_positions.len()));
        // UVs, normals and material groups come from the rest file alone (it has the keys'
        // topology); other keyframes' `vt`/`vn`/`usemtl` are not read back (formats/scene.md).
        let attributes = match self.cache.get(&rest_source)? {
            MeshFile::Surface(s) => s.attributes.clone(),
            MeshFile::Volume(_) => None,
        };
        let rest = match &self.first {
            MeshFile::Surface(s) => {
                let mut rest = TriMesh { positions: rest_positions, triangles: s.triangles.clone(), attributes };
                surface::orient_outward(&mut rest);
                Shape::Surface(rest)
            }
            MeshFile::Volume(v) => {
                let mut rest = TetMesh { positions: rest_positions, tets: v.tets.clone() };
                check_rest_fold(&rest, &rest_source)?;
                rest.orient_positive();
                Shape::Volume(rest)
            }
        };
        Ok((rest, rest_source))
    }

    /// A loop's last key must repeat the first (to 1e-9 of the rest size).
    fn check_loop(&self, rest_points: &[Point]) -> Result<()> {
        let (poses, paths) = (&self.poses, &self.paths);
        let last = poses.len() - 1;
        let gap = poses[0].iter().zip(&poses[last]).map(|(a, b)| geometry::norm(geometry::sub(*a, *b))).fold(0.0, f64::max);
        if gap > 1e-9 * geometry::bbox_diagonal(rest_points).max(f64::MIN_POSITIVE) {
            return Err(Error::in_file(
                &paths[last],
                format!("cyclic = true, but the last keyframe differs from the first ({}) by up to {gap:.4e}", paths[0].display()),
                "repeat the first keyframe's mesh as the last key of a loop",
            ));
        }
        Ok(())
    }
}

/// A key's tet at this fraction of its rest volume or below is flattened (a `folded-key` warning).
pub const FLAT_TET_RATIO: f64 = 1e-3;

/// Tet numbers and vertices as the MEDIT file writes them (1-based).
fn tet_in_file(mesh: &TetMesh, t: usize) -> String {
    let [a, b, c, d] = mesh.tets[t].map(|v| v + 1);
    format!("tet {} (vertices {a}, {b}, {c}, {d}; 1-based, as in the file)", t + 1)
}

/// A rest tet mesh that overlaps itself (two tets sharing a face lie on the same side of it:
/// a tet turned inside out against its neighbours) is folded. The files' vertex order says
/// nothing (the paper's meshes mix both orders; tets are oriented on load), so the test is
/// geometric, on the faces.
fn check_rest_fold(rest: &TetMesh, path: &Path) -> Result<()> {
    let Some((t, u, face)) = rest.first_fold() else { return Ok(()) };
    let [a, b, c] = face.map(|v| v + 1);
    Err(Error::in_file(
        path,
        format!(
            "the rest mesh is folded: {} and {} overlap across their shared face (vertices {a}, {b}, {c})",
            tet_in_file(rest, t),
            tet_in_file(rest, u)
        ),
        "untangle the rest mesh in the modeling tool so that no tet is turned inside out",
    ))
}

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
