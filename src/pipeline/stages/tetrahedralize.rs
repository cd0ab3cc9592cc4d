//! The `tetrahedralize` stage: turn the keyframes into a simulation body.
//!
//! Tet-mesh keyframes are used as they are. Surface keyframes go through TetGen on the rest
//! surface (`-Y`: surface vertices keep their indices as nodes); the interior nodes TetGen
//! adds get a pose per keyframe from a quasi-static fit (surface nodes pinned to that key,
//! interior nodes at elastic equilibrium), so no key starts with its inside at the rest pose.
//! Masks apply to the keyframes' own vertices; added interior nodes are free.
//!
//! A surface with more vertices than `[tet] max_nodes`, or a messy one (open, in several parts,
//! non-manifold, self-intersecting), is simulated on an automatic cage instead (`[tet] cage`,
//! on by default; see `crate::algorithms::cage`): a voxel tet body around the surface, whose keyframes are
//! fitted to the fine keyframes by least squares through the binding (regularized by the
//! cage's elastic energy), whose masks are carried over from the fine vertices by the majority
//! of binding weight; the fine surface is the one exported (embedded in the cage).

use std::path::Path;

use rayon::prelude::*;

use crate::algorithms::cage::fit::{carry_mask, CageFit};
use crate::algorithms::cage::{voxel_cage, CageError, Defects};
use crate::algorithms::embed::Binding;
use crate::algorithms::geometry::{surface, Bounds, Point, TetMesh, TriMesh};
use crate::algorithms::physics::elastic::Elastic;
use crate::algorithms::physics::equilibrium::Equilibrium;
use crate::formats::tetgen::{self, TetgenOptions};
use crate::pipeline::report::guard_rails::{code, coded};
use crate::pipeline::scene::Method;
use crate::pipeline::stage_file::{Body, CageInfo, KeyPoses, Keyframes, Shape, VertexSet};
use crate::support::budget::Budget;
use crate::support::error::{Error, Result};
use crate::support::progress::Progress;

/// The surface that is exported: the scene's display mesh, or the keyframe surface with every
/// vertex, unused ones included (they are tet nodes, so they have trajectories), so that
/// point `i` of the files is the input's vertex `i`.
fn export_surface(keys: &Keyframes, rest_surface: TriMesh) -> TriMesh {
    keys.display.clone().unwrap_or(rest_surface)
}

/// A surface error on welded keys names welded vertices, which the file does not number: say
/// how they are numbered.
fn welded_numbers(mut e: Error, keys: &Keyframes) -> Error {
    if keys.weld.is_some() && e.problem.contains("vert") {
        e.problem.push_str(" (vertex numbers after welding, [keyframes] weld: the merged vertices in the order of their first vertex in the file)");
    }
    e
}

/// The keys' weld, when the exported surface is theirs (an `[embed] surface` is its own file,
/// never welded, whose vertices the files number).
fn export_weld(keys: &Keyframes) -> Option<Vec<u32>> {
    keys.weld.clone().filter(|_| keys.display.is_none())
}

/// The simulation body of `keys`: its tet mesh, every node's keyframe poses, and the surface
/// to export; a body whose size is far from the material's (`implausible_size`) and an
/// `[embed] surface` far outside the body (`embedded_far_outside`) are warned of.
pub fn tetrahedralize(keys: &Keyframes, budget: &Budget, progress: &Progress) -> Result<Body> {
    tetrahedralize_with(keys, budget, progress, &mut tetgen::run_within)
}

/// TetGen's mesh of a rest surface with options (`source` names the surface in errors):
/// [`tetgen::run_within`], or a mesh an earlier bake kept for the same inputs.
pub(crate) type Tetgen<'a> = dyn FnMut(&TriMesh, &TetgenOptions, &Path, &Budget) -> Result<TetMesh> + 'a;

/// [`tetrahedralize`], TetGen's meshes made by `tetgen` (`blendsim bake --from` reuses one).
pub fn tetrahedralize_with(keys: &Keyframes, budget: &Budget, progress: &Progress, tetgen: &mut Tetgen) -> Result<Body> {
    let mut body = simulation_body(keys, budget, progress, tetgen)?;
    let rest = keys.rest.positions();
    if body.mesh.is_some() {
        if let Some(w) = implausible_size(crate::algorithms::geometry::bbox_diagonal(rest), keys.scene.meters_per_unit(), &keys.rest_source) {
            body.warn(progress, w);
        }
    }
    if let Some(w) = keys.display.as_ref().and_then(|display| embedded_far_outside(&display.positions, rest, &keys.rest_source)) {
        body.warn(progress, w);
    }
    if let Some(w) = units_conflict(keys) {
        body.warn(progress, w);
    }
    Ok(body)
}

/// The warning for a cache whose file states a unit (a USD stage's `metersPerUnit`, glTF's
/// meters) other than the scene's explicit `units`: the scene's is used, as given.
fn units_conflict(keys: &Keyframes) -> Option<String> {
    let file = keys.cache.as_ref()?.meters_per_unit?;
    let scene = keys.scene.meters_per_unit();
    // Equal up to the rounding of a unit written as a number (0.01 vs 0.009999999776 as f32).
    ((file - scene).abs() > 1e-6 * file.max(scene)).then(|| {
        coded(
            code::UNITS_CONFLICT,
            format_args!(
                "{}: the file states {file:e} m per unit but the scene's units say {scene:e} m; the scene's are used (remove units from the scene to use the file's, or correct it)",
                keys.rest_source
            ),
        )
    })
}

/// The body sizes (bounding-box diagonal, meters) the default material is meant for
/// (`formats/scene.md`, "The default material"): below, the body is so stiff for its mass
/// that the in-betweens are statics; above, so soft that it cannot follow its keys.
pub const PLAUSIBLE_METERS: [f64; 2] = [1e-3, 20.0];

/// The warning for a body of diagonal `diagonal` (in units of `meters_per_unit` meters) outside
/// [`PLAUSIBLE_METERS`], naming the unit that would bring it inside.
fn implausible_size(diagonal: f64, meters_per_unit: f64, source: &str) -> Option<String> {
    let meters = diagonal * meters_per_unit;
    let [low, high] = PLAUSIBLE_METERS;
    if (low..=high).contains(&meters) || !meters.is_finite() || meters <= 0.0 {
        return None;
    }
    let side = if meters < low { "under" } else { "over" };
    // The most used unit that would put the body inside the range.
    let fix = crate::pipeline::scene::UNIT_NAMES
        .iter()
        .find(|&&(_, unit)| unit != meters_per_unit && (low..=high).contains(&(diagonal * unit)))
        .map_or(String::new(), |(name, _)| format!("if the mesh is in {name}, set units = \"{name}\" at the top of the scene; "));
    Some(coded(
        code::BODY_SIZE,
        format_args!(
            "{source}: the body is {diagonal:.3e} units across ({meters:.3e} m at {meters_per_unit:e} m per unit), {side} the {low:e} to {high} m \
         the material is meant for: {fix}otherwise scale [material] to the body (formats/scene.md, \"The default material\")"
        ),
    ))
}

/// An embedded surface point farther than this share of the body's bounding-box diagonal
/// outside the body's box is a warning: points outside the tets are carried by the nearest
/// tet's motion extrapolated, which is right only close to the body.
pub const EMBED_FAR: f64 = 0.1;

/// The warning for an `[embed] surface` whose farthest point lies more than [`EMBED_FAR`]
/// of the body's diagonal outside the body's bounding box (at rest).
fn embedded_far_outside(display: &[Point], rest: &[Point], source: &str) -> Option<String> {
    let body = Bounds::of(rest);
    let diagonal = body.diagonal();
    let farthest = display.iter().map(|&p| body.distance(p)).fold(0.0, f64::max);
    (farthest > EMBED_FAR * diagonal).then(|| {
        coded(
            code::EMBED_FAR,
            format_args!(
            "{source}: the [embed] surface reaches {:.2} of this body's bounding-box diagonal outside its box (more than {EMBED_FAR}), and its far points follow the nearest tets' motion extrapolated (give an [embed] surface that lies on or inside the body, in the keys' units and placement)",
            farthest / diagonal
        ))
    })
}

/// The body of `keys`, before its size is judged ([`tetrahedralize`]).
fn simulation_body(keys: &Keyframes, budget: &Budget, progress: &Progress, tetgen: &mut Tetgen) -> Result<Body> {
    let scene = &keys.scene;
    let key_poses = |positions: Vec<Vec<Point>>| KeyPoses {
        times: keys.times.clone(),
        positions,
        fixed: keys.fixed.clone(),
        fixed_velocity: keys.fixed_velocity.clone(),
        cyclic: keys.cyclic,
    };
    let cache = keys.cache.clone();
    match &keys.rest {
        // The fit of a cache simulates nothing: its trajectory is the surface's own.
        Shape::Surface(rest) if scene.solver.method == Method::Fit => Ok(Body {
            scene: scene.clone(),
            mesh: None,
            keys: key_poses(keys.poses.clone()),
            surface: rest.clone(),
            cache,
            cage: None,
            warnings: Vec::new(),
            input_bytes: keys.input_bytes,
            weld: export_weld(keys),
        }),
        Shape::Volume(mesh) => {
            // A tet mesh's surface is its boundary: interior nodes are not points of it.
            let boundary = surface::compact(&TriMesh { positions: mesh.positions.clone(), triangles: surface::boundary(mesh), attributes: None }).0;
            let warnings = folded_keys(mesh, &keys.poses, keys);
            warnings.iter().for_each(|w| progress.warn(w));
            Ok(Body {
                scene: scene.clone(),
                mesh: Some(mesh.clone()),
                keys: key_poses(keys.poses.clone()),
                surface: export_surface(keys, boundary),
                cache,
                cage: None,
                warnings,
                input_bytes: keys.input_bytes,
                weld: export_weld(keys),
            })
        }
        Shape::Surface(rest) => {
            if let Some(reason) = cage_reason(rest, &scene.tet) {
                return caged(keys, rest, reason, progress);
            }
            let options = TetgenOptions { quality: scene.tet.quality, max_volume: scene.tet.max_volume, timeout: scene.tet.timeout };
            let bar = progress.predicted("tetrahedralize: TetGen", tetgen::predicted_seconds(rest, &options));
            let mesh: TetMesh = tetgen(rest, &options, Path::new(&keys.rest_source), budget).map_err(|e| welded_numbers(e, keys))?;
            bar.finish_and_clear();
            let n_surface = rest.positions.len();
            let pinned: Vec<bool> = (0..mesh.positions.len()).map(|a| a < n_surface).collect();
            let elastic = Elastic::new(&mesh, &super::elastic_material(scene))?;
            let equilibrium = Equilibrium::new(&elastic, &pinned)?;
            let tolerance = 1e-10 * crate::algorithms::geometry::bbox_diagonal(&mesh.positions);
            let bar = progress.bar(keys.poses.len() as u64, "tetrahedralize: fit interior nodes");
            let positions: Vec<Vec<Point>> = keys
                .poses
                .par_iter()
                .map(|pose| {
                    budget.check_time("tetrahedralization", || "while fitting the keys' interior nodes".into())?;
                    let mut x = mesh.positions.clone();
                    x[..n_surface].copy_from_slice(pose);
                    // The rest pose is its own equilibrium.
                    if pose[..] != rest.positions[..] {
                        equilibrium.solve(&mut x, tolerance, 2000);
                    }
                    bar.inc(1);
                    Ok(x)
                })
                .collect::<Result<_>>()?;
            bar.finish_and_clear();
            let mut warnings = unhonoured_max_volume(&mesh, scene.tet.max_volume, &keys.rest_source).into_iter().collect::<Vec<_>>();
            warnings.extend(folded_keys(&mesh, &positions, keys));
            warnings.iter().for_each(|w| progress.warn(w));
            Ok(Body {
                scene: scene.clone(),
                mesh: Some(mesh),
                keys: key_poses(positions),
                surface: export_surface(keys, rest.clone()),
                cache,
                cage: None,
                warnings,
                input_bytes: keys.input_bytes,
                weld: export_weld(keys),
            })
        }
    }
}

/// A largest tet this many times over `[tet] max_volume` is a warning. TetGen keeping the
/// surface (`-Y`) inserts no point that would split a surface triangle, so tets next to the
/// surface are as large as its triangles make them and may exceed the bound by a small factor
/// (the demo's largest is 2.5x, 161 of 777 over; `formats/scene.md`; the report lists the
/// largest volume always); an order of magnitude means the bound is far below what the
/// surface's own triangles allow (a box with max_volume = 1e-9 kept tets of 0.02).
pub(crate) const MAX_VOLUME_WARNING_FACTOR: f64 = 10.0;

/// The warning when TetGen left a tet far larger than `[tet] max_volume`.
fn unhonoured_max_volume(mesh: &TetMesh, max_volume: f64, source: &str) -> Option<String> {
    if max_volume <= 0.0 {
        return None;
    }
    let (t, largest) =
        (0..mesh.tets.len()).map(|t| (t, mesh.signed_volume_at(&mesh.positions, t).abs())).fold((0, 0.0), |m, x| if x.1 > m.1 { x } else { m });
    (largest > MAX_VOLUME_WARNING_FACTOR * max_volume).then(|| {
        coded(
            code::MAX_VOLUME,
            format!(
            "{source}: TetGen could not honour [tet] max_volume = {max_volume:e}: the largest of its {} tets (tet {t}) has volume {largest:.3e}, {:.1}x the bound (raise max_volume to what the surface allows, or refine the surface)",
            mesh.tets.len(),
                largest / max_volume
            ),
        )
    })
}

/// The warnings for keys with inverted or flattened tets: a tet key posed by a rig (linear-blend
/// skinning folds a few tets at a joint), or a surface key whose interior fit left them so (it
/// folds locally, or bends more sharply than its interior nodes can follow). One line per key,
/// naming the key's mesh as the scene gives it, how many tets and its worst. They bake: the
/// local step projects an inverted tet to its nearest rotation (signed SVD), so the solve pulls
/// the in-betweens back towards the rest shape; only a folded rest mesh is an error (import).
fn folded_keys(mesh: &TetMesh, positions: &[Vec<Point>], keys: &Keyframes) -> Vec<String> {
    // The scene's mesh of every key (a contact key's duplicate shares it, as in import).
    let mut names: Vec<String> = keys.scene.keyframes.as_ref().map_or(Vec::new(), |k| k.key_names());
    for &k in keys.scene.keyframes.as_ref().map_or(&[][..], |k| &k.contact[..]).iter().rev() {
        if k < names.len() {
            names.insert(k + 1, names[k].clone());
        }
    }
    names.resize(positions.len(), keys.rest_source.clone());
    let mut out = Vec::new();
    for (k, pose) in positions.iter().enumerate() {
        let collapsed = mesh.collapsed_at(pose, super::import::FLAT_TET_RATIO);
        let Some(&(t, ratio)) = collapsed.iter().min_by(|a, b| a.1.total_cmp(&b.1)) else { continue };
        let inverted = collapsed.iter().filter(|c| c.1 < 0.0).count();
        let [a, b, c, d] = mesh.tets[t];
        out.push(coded(
            code::FOLDED_KEY,
            format!(
                "{}: key {k} folds the tet body: {inverted} tets inverted, {} flattened below {:.1}% of their rest volume; the worst, tet {t} (nodes {a}, {b}, {c}, {d}), is at {:.1}% (it bakes; the key holds the fold, re-pose the key to remove it)",
                names[k],
                collapsed.len() - inverted,
                100.0 * super::import::FLAT_TET_RATIO,
                100.0 * ratio
            ),
        ));
    }
    out
}

/// Why `rest` should be simulated on a cage, if it should (see the module documentation).
fn cage_reason(rest: &TriMesh, tet: &crate::pipeline::scene::Tet) -> Option<String> {
    if !tet.cage {
        return None;
    }
    let (fine, _) = surface::compact(rest);
    let n = fine.positions.len();
    if n > tet.max_nodes {
        return Some(format!("the surface has {n} vertices, more than [tet] max_nodes = {}", tet.max_nodes));
    }
    Defects::of(&fine, true).describe().map(|d| format!("the surface is {d}"))
}

/// The body of surface keyframes simulated on a generated cage.
fn caged(keys: &Keyframes, rest: &TriMesh, reason: String, progress: &Progress) -> Result<Body> {
    let scene = &keys.scene;
    let source = Path::new(&keys.rest_source);
    let (fine, kept) = surface::compact(rest);
    let fine_poses: Vec<Vec<Point>> = keys.poses.iter().map(|p| kept.iter().map(|&v| p[v as usize]).collect()).collect();
    let mut enclose = fine.positions.clone();
    if let Some(display) = &keys.display {
        enclose.extend(&display.positions);
    }
    let target = scene.tet.cage_nodes;
    let bar = progress.predicted(
        format!("tetrahedralize: cage of about {target} nodes around {} vertices", fine.positions.len()),
        crate::algorithms::cage::predicted_seconds(fine.triangles.len(), target),
    );
    let cage = voxel_cage(&fine, &enclose, target).map_err(|CageError::Empty| {
        Error::in_file(source, "the surface has no extent: no triangle, or every vertex at one point", "give a surface with faces")
    })?;
    bar.finish_and_clear();
    let mesh = cage.mesh;
    // The binding and the fit's keys run in parallel.
    let threads = rayon::current_num_threads().max(1) as f64;
    let (cage_tets, n_fine, n_keys) = (mesh.tets.len(), fine.positions.len(), keys.poses.len());
    let fit_seconds = Binding::predicted_seconds(cage_tets, n_fine) / threads
        + CageFit::predicted_seconds(cage_tets, n_fine, n_keys) / threads.min(n_keys.max(1) as f64);
    let bar = progress.predicted(format!("tetrahedralize: fit {n_keys} cage keys to {n_fine} vertices"), fit_seconds);
    let binding = Binding::compute(&mesh, &fine.positions);
    let elastic = Elastic::new(&mesh, &super::elastic_material(scene))?;
    let fit = CageFit::new(&mesh, &binding, &elastic);
    let positions: Vec<Vec<Point>> = fine_poses.par_iter().map(|pose| fit.pose(&fine.positions, pose)).collect();
    let reproduction = fit.reproduction(&positions, &fine_poses, crate::algorithms::geometry::bbox_diagonal(&fine.positions));
    let carry = |sets: &[VertexSet]| -> Vec<VertexSet> {
        sets.iter()
            .map(|set| {
                let mask = set.to_mask(rest.positions.len());
                let fine_mask: Vec<bool> = kept.iter().map(|&v| mask[v as usize]).collect();
                VertexSet::from_mask(&carry_mask(&mesh, &binding, &fine_mask))
            })
            .collect()
    };
    let key_poses = KeyPoses {
        times: keys.times.clone(),
        positions,
        fixed: carry(&keys.fixed),
        fixed_velocity: carry(&keys.fixed_velocity),
        cyclic: keys.cyclic,
    };
    bar.finish_and_clear();
    let info = CageInfo {
        reason,
        fine_vertices: fine.positions.len(),
        boundary_nodes: cage.boundary_nodes,
        nodes: mesh.positions.len(),
        tets: mesh.tets.len(),
        spacing: cage.spacing,
        key_error_max: reproduction.max,
        key_error_rms: reproduction.rms,
    };
    Ok(Body {
        scene: scene.clone(),
        mesh: Some(mesh),
        keys: key_poses,
        surface: export_surface(keys, rest.clone()),
        cache: keys.cache.clone(),
        cage: Some(info),
        warnings: Vec::new(),
        input_bytes: keys.input_bytes,
        weld: export_weld(keys),
    })
}
