//! The keyframe meshes of a scene, read once per file and checked against the first (one
//! topology), the rest shape among them, and the scene's vertex selections resolved on it:
//! what the keyframe import, a clip's keys and a vertex cache's keys share.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use rayon::prelude::*;

use crate::algorithms::frames::weld::Weld;
use crate::algorithms::frames::MemoryFrames;
use crate::algorithms::geometry::{self, surface, Point, TetMesh, TriMesh};
use crate::formats::mesh::{self, MeshFile};
use crate::pipeline::scene::{Rest, SceneFile, Selection};
use crate::pipeline::stage_file::Shape;
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
    pub(super) fn read(scene_file: &SceneFile, budget: &Budget) -> Result<KeyMeshes> {
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
    pub(super) fn bytes(&self) -> u64 {
        if let Some(bytes) = self.clip_bytes {
            return bytes;
        }
        let mut paths: Vec<&PathBuf> = self.paths.iter().collect();
        paths.sort();
        paths.dedup();
        paths.iter().filter_map(|p| std::fs::metadata(p).ok()).map(|m| m.len()).sum()
    }

    /// Weld the keys' surface (`[keyframes] weld`): the vertices at one position in every key
    /// (and in a rest mesh) become one, and `poses` hold the welded vertices. Returns the weld,
    /// none when no two vertices merge or the keys are tet meshes (whose nodes are not copies
    /// of each other). [`KeyMeshes::rest_shape`] then takes it.
    pub(super) fn weld(&mut self, scene_file: &SceneFile) -> Result<Option<Weld>> {
        if !matches!(self.first, MeshFile::Surface(_)) {
            return Ok(None);
        }
        // The rest mesh's positions must coincide too (a different vertex count is
        // `rest_shape`'s error).
        let rest = match &scene_file.scene.keyframes.as_ref().expect("a keyframe scene").rest {
            Rest::Mesh(p) => Some(self.cache.get(&scene_file.resolve(p))?.positions().to_vec()).filter(|r| r.len() == self.poses[0].len()),
            Rest::Key(_) => None,
        };
        // The poses are lent to the frame source and taken back, not copied.
        let mut frames = std::mem::take(&mut self.poses);
        let with_rest = rest.is_some();
        frames.extend(rest);
        let mut source = MemoryFrames { times: (0..frames.len()).map(|k| k as f64).collect(), frames };
        let weld = Weld::find(&mut source);
        self.poses = source.frames;
        if with_rest {
            self.poses.pop();
        }
        let weld = weld?;
        if weld.is_identity() {
            return Ok(None);
        }
        self.poses.iter_mut().for_each(|p| *p = weld.pick(p));
        Ok(Some(weld))
    }

    /// The elastic rest shape (a key's pose or its own mesh), oriented, and the file it came
    /// from; on the welded vertices of `weld` ([`KeyMeshes::weld`], which welded the poses).
    pub(super) fn rest_shape(&mut self, scene_file: &SceneFile, weld: Option<&Weld>) -> Result<(Shape, PathBuf)> {
        let (rest_positions, rest_source) = match &scene_file.scene.keyframes.as_ref().expect("a keyframe scene").rest {
            Rest::Key(r) => (self.poses[*r].clone(), self.paths[*r].clone()),
            Rest::Mesh(p) => {
                let path = scene_file.resolve(p);
                let m = self.cache.get(&path)?;
                check_same_topology((&self.paths[0], &self.first, &self.first_topology), (&path, m, &Topology::of(m)))?;
                (weld.map_or_else(|| m.positions().to_vec(), |w| w.pick(m.positions())), path)
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
                // Welding keeps the triangles and their corners' attributes, on the welded vertices.
                let triangles = weld.map_or_else(|| s.triangles.clone(), |w| w.triangles(&s.triangles));
                let mut rest = TriMesh { positions: rest_positions, triangles, attributes };
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
    pub(super) fn check_loop(&self, rest_points: &[Point]) -> Result<()> {
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
