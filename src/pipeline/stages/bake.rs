//! The whole chain for one scene, in one process: the only place its order is written. The
//! CLI's `bake`, the integration tests and the benchmark all run it, to the stage they need.

use crate::pipeline::report::Report;
use crate::pipeline::scene::{Method, SceneFile};
use crate::pipeline::stage_file::{Animation, Body};
use crate::support::budget::Budget;
use crate::support::error::Result;
use crate::support::output::Staging;
use crate::support::progress::Progress;

use super::export::blendshape_clip;
use super::report::{measure, with_outputs};
use super::{embed, export_with, import, solve_within, tetrahedralize};

/// A scene to bake, with the options the CLI gives (`--method`).
#[derive(Debug, Clone)]
pub struct Bake<'a> {
    scene: &'a SceneFile,
    method: Option<Method>,
    budget: Budget,
    progress: &'a Progress,
}

impl<'a> Bake<'a> {
    /// The chain for `scene`, reporting progress to `progress`.
    pub fn new(scene: &'a SceneFile, progress: &'a Progress) -> Bake<'a> {
        Bake { scene, method: None, budget: Budget::default(), progress }
    }

    /// Solve with `method` instead of the scene's `[solver] method` (when given).
    pub fn method(self, method: Option<Method>) -> Bake<'a> {
        Bake { method, ..self }
    }

    /// Bake within `budget` (the CLI's `--max-memory` and `--max-time`; default: 60% of the
    /// available memory, no time limit): every stage checks it before it allocates or runs long.
    pub fn budget(self, budget: Budget) -> Bake<'a> {
        Bake { budget, ..self }
    }

    /// `import`, `tetrahedralize`: the simulation body. The method is known from the start, so
    /// `fit` skips TetGen and a cache's default `fixed` follows the method.
    pub fn body(&self) -> Result<Body> {
        let mut scene = self.scene.clone();
        if let Some(m) = self.method {
            scene.scene.solver.method = m;
        }
        let bar = self.progress.stage("import");
        let keys = import(&scene, &self.budget)?;
        bar.finish_and_clear();
        tetrahedralize(&keys, &self.budget, self.progress)
    }

    /// ... `solve`, `embed`: the exported surface's animation.
    pub fn animation(&self) -> Result<Animation> {
        let body = self.body()?;
        // The interruption tests stop here, between TetGen and the solver.
        crate::support::interrupt::pause_point("solve", "");
        let solution = solve_within(&body, self.method, &self.budget, self.progress)?;
        // The binding's searches run in parallel.
        let (tets, points) = (solution.body.mesh.as_ref().map_or(0, |m| m.tets.len()), solution.body.surface.positions.len());
        let bar = self
            .progress
            .predicted("embed", crate::algorithms::embed::Binding::predicted_seconds(tets, points) / rayon::current_num_threads().max(1) as f64);
        let animation = embed(&solution)?;
        bar.finish_and_clear();
        Ok(animation)
    }

    /// ... `export`, `report`: every file staged in `staging` (the caller commits it), and the
    /// report.
    pub fn files(&self, staging: &mut Staging) -> Result<Report> {
        let animation = self.animation()?;
        // The report's measures need no file: they run on a second thread while the files are
        // written, each computed as alone, so the same numbers. Export's error comes first, as when they ran one after the other.
        let clip = blendshape_clip(&animation, None, &self.budget)?;
        let (outputs, measured) = std::thread::scope(|scope| {
            let measuring = scope.spawn(|| measure(&animation, &clip, &self.budget));
            let outputs = export_with(&animation, &clip, staging, &self.budget, self.progress);
            let bar = self.progress.stage("report");
            let measured = measuring.join().unwrap_or_else(|panic| std::panic::resume_unwind(panic));
            bar.finish_and_clear();
            (outputs, measured)
        });
        let outputs = outputs?;
        let report = with_outputs(measured?, &outputs);
        // The stages warned as they went; the guard rails' warnings come after theirs.
        report.warnings[animation.warnings.len()..].iter().for_each(|w| self.progress.warn(w));
        report.write(staging)?;
        Ok(report)
    }
}

/// The files a bake of `scene` writes, textures aside: the export's and the report.
pub fn file_names(scene: &SceneFile) -> Vec<String> {
    let mut names = super::export::file_names(&scene.scene);
    names.extend(crate::pipeline::report::FILES.map(String::from));
    names
}

/// Bake `scene` into `staging`: the files of every stage and the report (see [`Bake::files`]).
pub fn bake(scene: &SceneFile, method: Option<Method>, staging: &mut Staging, progress: &Progress) -> Result<Report> {
    Bake::new(scene, progress).method(method).files(staging)
}
