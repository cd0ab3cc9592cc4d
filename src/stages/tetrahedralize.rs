//! The `tetrahedralize` stage: turn the keyframes into a simulation body.
//!
//! Tet-mesh keyframes are used as they are. Surface keyframes go through TetGen on the rest
//! surface (`-Y`: surface vertices keep their indices as nodes); the interior nodes TetGen
//! adds get a pose per keyframe from a quasi-static fit (surface nodes pinned to that key,
//! interior nodes at elastic equilibrium), so no key starts with its inside at the rest pose.
//! Masks apply to the keyframes' own vertices; added interior nodes are free.

use rayon::prelude::*;

use crate::error::Result;
use crate::mesh::{surface, Point, TetMesh, TriMesh};
use crate::physics::elastic::Elastic;
use crate::physics::equilibrium::Equilibrium;
use crate::progress::Progress;
use crate::scene::Method;
use crate::stage::{Body, KeyPoses, Keyframes, Shape};
use crate::tetgen::{self, TetgenOptions};

/// The surface that is exported: the scene's display mesh, or the keyframe surface without
/// unused vertices.
fn export_surface(keys: &Keyframes, rest_surface: TriMesh) -> TriMesh {
    keys.display.clone().unwrap_or_else(|| surface::compact(&rest_surface).0)
}

/// The simulation body of `keys`: its tet mesh, every node's keyframe poses, and the surface
/// to export.
pub fn tetrahedralize(keys: &Keyframes, progress: &Progress) -> Result<Body> {
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
        Shape::Surface(rest) if scene.solver.method == Method::Fit => {
            Ok(Body { scene: scene.clone(), mesh: None, keys: key_poses(keys.poses.clone()), surface: rest.clone(), cache })
        }
        Shape::Volume(mesh) => {
            let boundary = TriMesh { positions: mesh.positions.clone(), triangles: surface::boundary(mesh) };
            Ok(Body { scene: scene.clone(), mesh: Some(mesh.clone()), keys: key_poses(keys.poses.clone()), surface: export_surface(keys, boundary), cache })
        }
        Shape::Surface(rest) => {
            let options = TetgenOptions { quality: scene.tet.quality, max_volume: scene.tet.max_volume, timeout: scene.tet.timeout };
            let bar = progress.stage("tetrahedralize: TetGen");
            let mesh: TetMesh = tetgen::run(rest, &options, std::path::Path::new(&keys.rest_source))?;
            bar.finish_and_clear();
            let n_surface = rest.positions.len();
            let pinned: Vec<bool> = (0..mesh.positions.len()).map(|a| a < n_surface).collect();
            let elastic = Elastic::new(&mesh, &super::elastic_material(&scene.material))?;
            let equilibrium = Equilibrium::new(&elastic, &pinned)?;
            let tolerance = 1e-10 * crate::mesh::bbox_diagonal(&mesh.positions);
            let bar = progress.bar(keys.poses.len() as u64, "tetrahedralize: fit interior nodes");
            let positions: Vec<Vec<Point>> = keys
                .poses
                .par_iter()
                .map(|pose| {
                    let mut x = mesh.positions.clone();
                    x[..n_surface].copy_from_slice(pose);
                    // The rest pose is its own equilibrium.
                    if pose[..] != rest.positions[..] {
                        equilibrium.solve(&mut x, tolerance, 2000);
                    }
                    bar.inc(1);
                    x
                })
                .collect();
            bar.finish_and_clear();
            Ok(Body { scene: scene.clone(), mesh: Some(mesh), keys: key_poses(positions), surface: export_surface(keys, rest.clone()), cache })
        }
    }
}
