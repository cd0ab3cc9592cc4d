//! Not API: the solver's parts, for the benchmark (`benches/solver.rs`), which times them one
//! by one, the writers, whose byte counts `benches/cache.rs` compares, and the natural
//! vibration periods and static poses for tests that compare against them. Nothing here is stable; library users
//! call [`crate::stages`].

pub use crate::export::fullframe::FullFrame;
pub use crate::export::glb::{self, Placement};
pub use crate::export::usda::{self, UsdSettings};
pub use crate::export::usdc;
pub use crate::physics::elastic::{Elastic, Material as ElasticMaterial};
pub use crate::physics::vibration::{natural_vibration, RestStiffness, Vibration};
pub use crate::physics::equilibrium::{loaded_equilibrium, EquilibriumInfo};
pub use crate::spacetime::global_step::{GlobalStats, GlobalStep};
pub use crate::spacetime::objective::{Evaluation, Objective, Projections};
pub use crate::spacetime::solver::{apply_step, initial_trajectory, objective, solve, Log, Settings, Solved, DEFAULT_COARSE_TOLERANCE, DEFAULT_TOLERANCE, WINDOW};
pub use crate::spacetime::solver::{IterationEstimate, ModelHessian, Step, NEGLIGIBLE};
pub use crate::spacetime::timing::{ProjectionMode, TimeDerivatives, Timing, TimingSettings, TimingStep};
pub use crate::spacetime::unknowns::{KeyConstraints, Unknowns};
pub use crate::tetgen::{run as tetgen, TetgenOptions};

use crate::error::Result;
use crate::stage::Body;

/// The solver's inputs for a body, as the `solve` stage builds them: the elastic body, its key
/// constraints, and the settings of its scene.
pub fn solver_inputs(body: &Body) -> Result<(Elastic, KeyConstraints, Settings)> {
    let tets = body.mesh.as_ref().ok_or_else(|| crate::error::Error::general("the body has no tet mesh (method fit)", "tetrahedralize for spacetime"))?;
    let elastic = Elastic::new(tets, &crate::stages::elastic_material(&body.scene.material))?;
    Ok((elastic, crate::stages::solve::key_constraints(&body.keys), crate::stages::solve::settings(&body.scene)))
}

/// The mass-spring blendshape model (Ma et al. 2012), for its benchmark (`benches/massspring.rs`).
pub mod massspring {
    pub use crate::massspring::{Blend, Boundary, MassSpring, Settings, Targets};
}

/// The automatic cage and the barycentric binding, for the demo benchmark's cost models
/// (`benches/demo.rs`).
pub use crate::cage::{fit::CageFit, voxel_cage};
pub use crate::embed::Binding;
pub use crate::cage::predicted_seconds as cage_seconds;
pub use crate::tetgen::predicted_seconds as tetgen_seconds;

/// glTF clips written for tests (the skinned ribbon the clip reader's unit tests and the
/// integration tests both bake).
pub mod gltf_fixtures {
    pub use crate::cache::gltf_clip::fixtures::skinned_clip;
}
