//! The whole chain for one scene, in one process: the only place its order is written. The
//! CLI's `bake`, the integration tests and the benchmark all run it, to the stage they need.

use crate::pipeline::report::Report;
use crate::pipeline::scene::{Method, SceneFile};
use crate::pipeline::stage_file::{Animation, Body};
use crate::support::budget::Budget;
use crate::support::error::Result;
use crate::support::output::Staging;
use crate::support::progress::Progress;

use super::bake_cache::{tetgen_key, BakeCache, Reused, SolveKeys};
use super::export::blendshape_clip;
use super::report::{measure, with_outputs};
use super::{embed, export_with, import, solve_starting, tetrahedralize_with};

/// A scene to bake, with the options the CLI gives (`--method`, `--from`).
#[derive(Debug, Clone)]
pub struct Bake<'a> {
    scene: &'a SceneFile,
    method: Option<Method>,
    budget: Budget,
    progress: &'a Progress,
    previous: Option<&'a BakeCache>,
}

impl<'a> Bake<'a> {
    /// The chain for `scene`, reporting progress to `progress`.
    pub fn new(scene: &'a SceneFile, progress: &'a Progress) -> Bake<'a> {
        Bake { scene, method: None, budget: Budget::default(), progress, previous: None }
    }

    /// Reuse what `previous` (an earlier bake's `bake.cache`) kept for the same inputs
    /// ([`super::bake_cache`]).
    pub fn reusing(self, previous: Option<&'a BakeCache>) -> Bake<'a> {
        Bake { previous, ..self }
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
        self.body_kept(None, &mut Reused::default())
    }

    /// [`Bake::body`], TetGen's mesh taken from the previous bake when it has it for the same
    /// inputs, and kept in `cache` when given.
    fn body_kept(&self, mut cache: Option<&mut BakeCache>, reused: &mut Reused) -> Result<Body> {
        let mut scene = self.scene.clone();
        if let Some(m) = self.method {
            scene.scene.solver.method = m;
        }
        let bar = self.progress.stage("import");
        let keys = import(&scene, &self.budget)?;
        bar.finish_and_clear();
        tetrahedralize_with(&keys, &self.budget, self.progress, &mut |surface, options, source, budget| {
            let key = (self.previous.is_some() || cache.is_some()).then(|| tetgen_key(surface, options));
            let mesh = match self.previous.zip(key.as_deref()).and_then(|(p, key)| p.tetgen(key)) {
                Some(mesh) => {
                    reused.tetgen = true;
                    mesh
                }
                None => crate::formats::tetgen::run_within(surface, options, source, budget)?,
            };
            if let (Some(cache), Some(key)) = (cache.as_deref_mut(), key) {
                cache.keep_tetgen(key, &mesh);
            }
            Ok(mesh)
        })
    }

    /// ... `solve`, `embed`: the exported surface's animation.
    pub fn animation(&self) -> Result<Animation> {
        self.animation_kept(None, &mut Reused::default())
    }

    /// [`Bake::animation`], the solve taken from the previous bake or started from its
    /// solution when it has them for the same inputs, and kept in `cache` when given.
    fn animation_kept(&self, mut cache: Option<&mut BakeCache>, reused: &mut Reused) -> Result<Animation> {
        let body = self.body_kept(cache.as_deref_mut(), reused)?;
        // The interruption tests stop here, between TetGen and the solver.
        crate::support::interrupt::pause_point("solve", "");
        let keys = (self.previous.is_some() || cache.is_some()).then(|| SolveKeys::of(&body, self.budget.max_memory()));
        let previous = self.previous.zip(keys.as_ref());
        let solution = match previous.and_then(|(p, keys)| p.solution(&body, keys)) {
            Some(solution) => {
                reused.solve = true;
                super::solve::reused(solution, self.progress)
            }
            None => {
                let start = previous.and_then(|(p, keys)| p.warm_start(&body, keys));
                reused.warm_start = start.is_some();
                solve_starting(&body, self.method, &self.budget, self.progress, start.as_ref())?
            }
        };
        if let (Some(cache), Some(keys)) = (cache, keys) {
            cache.keep_solution(&solution, keys);
        }
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
        Ok(self.files_kept(staging, None)?.0)
    }

    /// [`Bake::files`], with `bake.cache` (what the next bake can reuse, [`super::bake_cache`])
    /// staged with them (`blendsim bake --from`); and what was reused from the previous bake
    /// ([`Bake::reusing`]).
    pub fn files_reusing(&self, staging: &mut Staging) -> Result<(Report, Reused)> {
        self.files_kept(staging, Some(BakeCache::new()?))
    }

    /// [`Bake::files`], filling and staging `cache` when given.
    fn files_kept(&self, staging: &mut Staging, mut cache: Option<BakeCache>) -> Result<(Report, Reused)> {
        let mut reused = Reused::default();
        let animation = self.animation_kept(cache.as_mut(), &mut reused)?;
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
        if let Some(cache) = cache {
            staging.set_group("bake");
            staging.write(super::bake_cache::FILE, &cache.to_json())?;
        }
        Ok((report, reused))
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
