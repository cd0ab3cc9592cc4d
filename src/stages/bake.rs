//! The whole chain for one scene, in one process: the only place its order is written. The
//! CLI's `bake`, the integration tests and the benchmark all run it, to the stage they need.

use crate::error::Result;
use crate::output::Staging;
use crate::progress::Progress;
use crate::report::Report;
use crate::scene::{Method, SceneFile};
use crate::stage::{Animation, Body};

use super::{embed, export, import, report, solve, tetrahedralize};

/// A scene to bake, with the options the CLI gives (`--method`).
#[derive(Debug, Clone)]
pub struct Bake<'a> {
    scene: &'a SceneFile,
    method: Option<Method>,
    progress: &'a Progress,
}

impl<'a> Bake<'a> {
    /// The chain for `scene`, reporting progress to `progress`.
    pub fn new(scene: &'a SceneFile, progress: &'a Progress) -> Bake<'a> {
        Bake { scene, method: None, progress }
    }

    /// Solve with `method` instead of the scene's `[solver] method` (when given).
    pub fn method(self, method: Option<Method>) -> Bake<'a> {
        Bake { method, ..self }
    }

    /// `import`, `tetrahedralize`: the simulation body. The method is known from the start, so
    /// `fit` skips TetGen and a cache's default `fixed` follows the method.
    pub fn body(&self) -> Result<Body> {
        let mut scene = self.scene.clone();
        if let Some(m) = self.method {
            scene.scene.solver.method = m;
        }
        tetrahedralize(&import(&scene)?, self.progress)
    }

    /// ... `solve`, `embed`: the exported surface's animation.
    pub fn animation(&self) -> Result<Animation> {
        let body = self.body()?;
        // The interruption tests stop here, between TetGen and the solver.
        crate::interrupt::pause_point("solve", "");
        embed(&solve(&body, self.method, self.progress)?)
    }

    /// ... `export`, `report`: every file staged in `staging` (the caller commits it), and the
    /// report.
    pub fn files(&self, staging: &mut Staging) -> Result<Report> {
        let animation = self.animation()?;
        let outputs = export(&animation, staging)?;
        let report = report(&animation, &outputs)?;
        report.write(staging)?;
        Ok(report)
    }
}

/// Bake `scene` into `staging`: the files of every stage and the report (see [`Bake::files`]).
pub fn bake(scene: &SceneFile, method: Option<Method>, staging: &mut Staging, progress: &Progress) -> Result<Report> {
    Bake::new(scene, progress).method(method).files(staging)
}
