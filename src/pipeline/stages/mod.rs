//! The chain, one stage per file: each stage is one function from the stage data before it to
//! the stage data after it (the types of [`crate::pipeline::stage_file`], which the CLI writes between
//! subcommands), and [`bake()`] runs them all in order.
//!
//! ```text
//! SceneFile -> import -> Keyframes -> tetrahedralize -> Body -> solve -> Solution
//!           -> embed -> Animation -> export -> (files, Outputs) -> report -> Report
//! ```
//!
//! - [`import()`]: read the keyframe meshes, check one topology, resolve the vertex selections;
//! - [`tetrahedralize()`]: TetGen for surface keyframes, interior nodes posed by a quasi-static fit;
//! - [`solve()`]: the node trajectory (spacetime projective dynamics, or the hermite baseline);
//! - [`embed()`]: the exported surface carried on it by a barycentric binding;
//! - [`export()`]: the blendshape and full-frame files;
//! - [`report()`]: sizes, fidelity, volume and the solver's history.
//!
//! Beside the chain, [`blend()`]: mass-spring blendshapes of target meshes (`blendsim blend`).
//!
//! This layer is the only one that reads the scene and the stage data: it translates them into
//! the plain inputs of the algorithms (meshes, an elastic material, key constraints, solver
//! settings) and their results back into stage data. No algorithm module knows the scene file
//! or the stage files.

pub mod bake;
pub mod bake_cache;
pub mod blend;
pub mod embed;
pub mod export;
pub mod import;
pub mod import_cache;
mod import_clip;
mod key_meshes;
pub mod report;
pub mod solve;
pub mod tetrahedralize;

#[cfg(test)]
mod fuzz;

pub use bake::{bake, Bake};
pub use blend::blend;
pub use embed::embed;
pub use export::{blendshape_clip, export, export_with};
pub use import::import;
pub use report::report;
pub use solve::{solve, solve_starting, solve_within};
pub use tetrahedralize::{tetrahedralize, tetrahedralize_with};

use crate::algorithms::physics::elastic;
use crate::pipeline::scene;

/// The elastic constants of the scene's `[material]` (SI), in the units of its geometry
/// (`units`, [`scene::Scene::meters_per_unit`] `m`): a body measured in units of `m` meters
/// is the same physical body when its weights (stresses) are multiplied by `m` and its
/// density by `m³` (the elastic and inertial forces then keep their ratio at every size;
/// `formats/scene.md`, "Units"). With meters (`m = 1`) the values are the scene's, bit for bit.
pub(crate) fn elastic_material(scene: &scene::Scene) -> elastic::Material {
    let (material, m) = (&scene.material, scene.meters_per_unit());
    elastic::Material { stiffness: material.stiffness * m, volume: material.volume * m, density: material.density * m * m * m }
}

/// The scene's gravity (m/s²) in its units per second squared.
pub(crate) fn gravity(scene: &scene::Scene) -> crate::algorithms::geometry::Point {
    scene.material.gravity.map(|g| g / scene.meters_per_unit())
}
