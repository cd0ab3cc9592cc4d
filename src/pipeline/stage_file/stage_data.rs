//! What each stage file holds beyond its fields: its header names, the invariants checked
//! when it is read, and the paths it keeps relative to its own folder.

use serde::de::DeserializeOwned;
use serde::Serialize;

use super::*;

/// Names the stage a file holds, so a wrong file passed to a subcommand is caught at once.
pub trait StageData: Serialize + DeserializeOwned {
    /// The stage name in the file header.
    const STAGE: &'static str;
    /// The subcommand that writes it.
    const WRITER: &'static str;
    /// The invariants the types document but JSON cannot enforce (lengths, index ranges,
    /// increasing times, finite numbers, the embedded scene), checked when a file is read, so a
    /// hand-edited or damaged file fails here with one line instead of deep inside a stage.
    /// The memory the stages after it need is checked against `budget`.
    fn validate(&self, budget: &Budget) -> Result<()>;
    /// The surfaces the data carries, whose texture paths (absolute in memory) the file holds
    /// relative to its own folder ([`write()`], [`read`]), so a staged folder can be moved.
    fn surfaces_mut(&mut self) -> Vec<&mut TriMesh> {
        Vec::new()
    }
    /// Whether any surface has a texture (so [`write()`] has paths to rewrite).
    fn has_textures(&self) -> bool {
        false
    }
    /// The cache record the data carries (`[cache]` scenes), whose paths (the cache, its rest
    /// mesh) the file holds relative to its own folder like the textures.
    fn cache(&self) -> Option<&CacheRecord> {
        None
    }
    /// See [`StageData::cache`].
    fn cache_mut(&mut self) -> Option<&mut CacheRecord> {
        None
    }
    /// Whether the data names files other than textures ([`StageData::files_mut`]).
    fn has_files(&self) -> bool {
        self.cache().is_some()
    }
    /// The file paths the data names other than textures: the cache and its rest mesh, and the
    /// keyframes' rest source. The file holds them relative to its own folder like the textures.
    fn files_mut(&mut self) -> Vec<&mut String> {
        self.cache_mut().into_iter().flat_map(cache_paths_mut).collect()
    }
}

impl StageData for Keyframes {
    const STAGE: &'static str = "keyframes";
    const WRITER: &'static str = "blendsim import";
    fn surfaces_mut(&mut self) -> Vec<&mut TriMesh> {
        let rest = match &mut self.rest {
            Shape::Surface(m) => Some(m),
            Shape::Volume(_) => None,
        };
        rest.into_iter().chain(self.display.as_mut()).collect()
    }
    fn has_textures(&self) -> bool {
        matches!(&self.rest, Shape::Surface(m) if textured(m)) || self.display.as_ref().is_some_and(textured)
    }
    fn cache(&self) -> Option<&CacheRecord> {
        self.cache.as_ref()
    }
    fn cache_mut(&mut self) -> Option<&mut CacheRecord> {
        self.cache.as_mut()
    }
    fn has_files(&self) -> bool {
        true
    }
    fn files_mut(&mut self) -> Vec<&mut String> {
        std::iter::once(&mut self.rest_source).chain(self.cache.iter_mut().flat_map(cache_paths_mut)).collect()
    }
    fn validate(&self, budget: &Budget) -> Result<()> {
        let rerun = Check(Self::WRITER, contact_keys(&self.scene), budget);
        rerun.scene(&self.scene)?;
        let n = match &self.rest {
            Shape::Surface(m) => rerun.tri_mesh("rest surface", m)?,
            Shape::Volume(m) => rerun.tet_mesh("rest mesh", m)?,
        };
        rerun.times("times", &self.times)?;
        let keys = self.times.len();
        rerun.poses("poses", &self.poses, keys, n)?;
        rerun.sets("fixed", &self.fixed, keys, n)?;
        rerun.sets("fixed_velocity", &self.fixed_velocity, keys, n)?;
        rerun.cyclic(self.cyclic, keys)?;
        if let Some(display) = &self.display {
            rerun.tri_mesh("display surface", display)?;
        }
        let tets = match &self.rest {
            Shape::Surface(m) => m.triangles.len().div_ceil(4),
            Shape::Volume(m) => m.tets.len(),
        };
        let vertices = self.display.as_ref().map_or(n, |d| d.positions.len());
        rerun.resources(&self.scene, &self.times, vertices, tets)
    }
}

impl StageData for Body {
    const STAGE: &'static str = "body";
    const WRITER: &'static str = "blendsim tetrahedralize";
    fn surfaces_mut(&mut self) -> Vec<&mut TriMesh> {
        vec![&mut self.surface]
    }
    fn has_textures(&self) -> bool {
        textured(&self.surface)
    }
    fn cache(&self) -> Option<&CacheRecord> {
        self.cache.as_ref()
    }
    fn cache_mut(&mut self) -> Option<&mut CacheRecord> {
        self.cache.as_mut()
    }
    fn validate(&self, budget: &Budget) -> Result<()> {
        let rerun = Check(Self::WRITER, contact_keys(&self.scene), budget);
        rerun.scene(&self.scene)?;
        // Without a tet mesh (method fit) the keys are the surface's own.
        let surface = rerun.tri_mesh("surface", &self.surface)?;
        let n = match &self.mesh {
            Some(m) => rerun.tet_mesh("mesh", m)?,
            None => surface,
        };
        rerun.key_poses(&self.keys, n)?;
        rerun.resources(&self.scene, &self.keys.times, surface, self.mesh.as_ref().map_or(0, |m| m.tets.len()))
    }
}

impl StageData for Solution {
    const STAGE: &'static str = "solution";
    const WRITER: &'static str = "blendsim solve";
    fn surfaces_mut(&mut self) -> Vec<&mut TriMesh> {
        vec![&mut self.body.surface]
    }
    fn has_textures(&self) -> bool {
        textured(&self.body.surface)
    }
    fn cache(&self) -> Option<&CacheRecord> {
        self.body.cache.as_ref()
    }
    fn cache_mut(&mut self) -> Option<&mut CacheRecord> {
        self.body.cache.as_mut()
    }
    fn validate(&self, budget: &Budget) -> Result<()> {
        let rerun = Check(Self::WRITER, contact_keys(&self.body.scene), budget);
        rerun.scene(&self.body.scene)?;
        let surface = rerun.tri_mesh("body surface", &self.body.surface)?;
        let (n, of) = match &self.body.mesh {
            Some(m) => (rerun.tet_mesh("body mesh", m)?, "tet nodes"),
            None => (surface, "surface vertices"),
        };
        rerun.key_poses(&self.body.keys, n)?;
        rerun.trajectory(&self.trajectory, n, of)?;
        rerun.resources(&self.body.scene, &self.trajectory.times, self.body.surface.positions.len(), 0)
    }
}

impl StageData for Animation {
    const STAGE: &'static str = "animation";
    const WRITER: &'static str = "blendsim embed";
    fn surfaces_mut(&mut self) -> Vec<&mut TriMesh> {
        vec![&mut self.mesh]
    }
    fn has_textures(&self) -> bool {
        textured(&self.mesh)
    }
    fn cache(&self) -> Option<&CacheRecord> {
        self.cache.as_ref()
    }
    fn cache_mut(&mut self) -> Option<&mut CacheRecord> {
        self.cache.as_mut()
    }
    fn validate(&self, budget: &Budget) -> Result<()> {
        let rerun = Check(Self::WRITER, contact_keys(&self.scene), budget);
        rerun.scene(&self.scene)?;
        let n = rerun.tri_mesh("mesh", &self.mesh)?;
        rerun.trajectory(&self.trajectory, n, "mesh vertices")?;
        // mass-spring's in-betweens are keys of the trajectory but not input keys.
        let input_keys = match self.log.method {
            Method::MassSpring => (self.trajectory.key_count().saturating_sub(1)) / (self.scene.mass_spring.inbetweens + 1) + 1,
            _ => self.trajectory.key_count(),
        };
        rerun.poses("input_keys", &self.input_keys, input_keys, n)?;
        let c = &self.counts;
        if c.vertices != n || c.faces != self.mesh.triangles.len() {
            return rerun.fail(format!(
                "counts say {} vertices and {} faces but the mesh has {n} and {}",
                c.vertices,
                c.faces,
                self.mesh.triangles.len()
            ));
        }
        rerun.resources(&self.scene, &self.trajectory.times, n, 0)
    }
}

impl StageData for Outputs {
    const STAGE: &'static str = "outputs";
    const WRITER: &'static str = "blendsim export";
    fn validate(&self, budget: &Budget) -> Result<()> {
        if self.rank == Some(0) {
            return Check(Self::WRITER, 0, budget).fail("rank is 0 (a principal clip has at least one component)".into());
        }
        for (i, f) in self.files.iter().enumerate() {
            let plain = !f.path.is_empty() && !f.path.starts_with('.') && !f.path.contains(['/', '\\']) && !f.path.chars().any(char::is_control);
            if !plain {
                return Check(Self::WRITER, 0, budget)
                    .fail(format!("files[{i}] is {}, not a plain file name", crate::support::error::quoted(&f.path)));
            }
        }
        Ok(())
    }
}

/// The checks behind [`StageData::validate`]. Each returns the first problem, with the fix of
/// re-running the subcommand that writes the stage (`.0`). `.1` is the number of contact keys
/// of the scene: each is a zero-length interval, so that many key times may repeat. `.2` is
/// the budget the next stages run under.
struct Check<'a>(&'static str, usize, &'a Budget);

/// The contact keys of a scene (`contact = [k]`; none for a cache).
fn contact_keys(scene: &Scene) -> usize {
    scene.keyframes.as_ref().map_or(0, |k| k.contact.len())
}

impl Check<'_> {
    fn fail<T>(&self, problem: String) -> Result<T> {
        Err(Error::general(problem, format!("the file was edited or damaged; re-run `{}` to rewrite it", self.0)))
    }

    /// The embedded scene: the same rules as a scene file (name, fps > 0, every table).
    fn scene(&self, scene: &Scene) -> Result<()> {
        scene.validate().map_err(|e| {
            Error::general(
                format!("its scene: {}", e.problem),
                format!("{}; edit the scene file, then re-run the chain from `blendsim import`", e.fix),
            )
        })
    }

    /// The memory the stages after this one need, within the budget.
    fn resources(&self, scene: &Scene, times: &[f64], vertices: usize, tets: usize) -> Result<()> {
        scene
            .check_resources(times, vertices, tets, self.2)
            .map_err(|e| Error::general(e.problem, format!("{}; edit the scene file, then re-run the chain from `blendsim import`", e.fix)))
    }

    fn points(&self, what: &str, points: &[Point]) -> Result<()> {
        match points.iter().position(|p| p.iter().any(|x| !x.is_finite())) {
            Some(v) => self.fail(format!("{what} has a non-finite coordinate at vertex {v}")),
            None => Ok(()),
        }
    }

    /// Finite positions, triangle indices in range, at least one triangle. Returns the vertex count.
    fn tri_mesh(&self, what: &str, m: &TriMesh) -> Result<usize> {
        let n = m.positions.len();
        self.points(what, &m.positions)?;
        if m.triangles.is_empty() {
            return self.fail(format!("{what} has no triangles"));
        }
        if let Some(t) = m.triangles.iter().position(|t| t.iter().any(|&i| i as usize >= n)) {
            return self.fail(format!("{what} triangle {t} uses vertex {}, but there are {n} vertices", m.triangles[t].iter().max().unwrap()));
        }
        Ok(n)
    }

    /// Finite positions, tet indices in range, every tet positively oriented ([`TetMesh`]'s
    /// invariant). Returns the node count.
    fn tet_mesh(&self, what: &str, m: &TetMesh) -> Result<usize> {
        let n = m.positions.len();
        self.points(what, &m.positions)?;
        if m.tets.is_empty() {
            return self.fail(format!("{what} has no tets"));
        }
        if let Some(t) = m.tets.iter().position(|t| t.iter().any(|&i| i as usize >= n)) {
            return self.fail(format!("{what} tet {t} uses node {}, but there are {n} nodes", m.tets[t].iter().max().unwrap()));
        }
        if let Some(t) = (0..m.tets.len()).find(|&t| m.signed_volume_at(&m.positions, t).partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater)) {
            return self
                .fail(format!("{what} tet {t} is inverted or flat in the rest pose (signed volume {:e})", m.signed_volume_at(&m.positions, t)));
        }
        Ok(n)
    }

    /// At least two finite, strictly increasing times.
    fn times(&self, what: &str, times: &[f64]) -> Result<()> {
        if times.len() < 2 {
            return self.fail(format!("{what} has {} key times, at least 2 are needed", times.len()));
        }
        if let Some(k) = times.iter().position(|t| !t.is_finite()) {
            return self.fail(format!("{what}[{k}] is not a finite number"));
        }
        // A contact key and its duplicate share their time; nothing else may.
        let repeats = times.windows(2).filter(|w| w[0] == w[1]).count();
        let triple = times.windows(3).any(|w| w[0] == w[2]);
        if let Some(k) = times.windows(2).position(|w| w[0] > w[1] || (w[0] == w[1] && (repeats > self.1 || triple))) {
            return self.fail(format!("{what} do not increase at key {} ({} after {})", k + 1, times[k + 1], times[k]));
        }
        Ok(())
    }

    /// `keys` poses of `n` finite points each.
    fn poses(&self, what: &str, poses: &[Vec<Point>], keys: usize, n: usize) -> Result<()> {
        if poses.len() != keys {
            return self.fail(format!("{what} has {} poses for {keys} key times", poses.len()));
        }
        for (k, pose) in poses.iter().enumerate() {
            if pose.len() != n {
                return self.fail(format!("{what}[{k}] has {} points but the mesh has {n}", pose.len()));
            }
            self.points(&format!("{what}[{k}]"), pose)?;
        }
        Ok(())
    }

    /// One set per key, each strictly increasing and below `n`.
    fn sets(&self, what: &str, sets: &[VertexSet], keys: usize, n: usize) -> Result<()> {
        if sets.len() != keys {
            return self.fail(format!("{what} has {} sets for {keys} keys", sets.len()));
        }
        for (k, s) in sets.iter().enumerate() {
            if let Some(&i) = s.indices().iter().find(|&&i| i as usize >= n) {
                return self.fail(format!("{what}[{k}] holds index {i}, but there are {n} vertices"));
            }
            if s.indices().windows(2).any(|w| w[0] >= w[1]) {
                return self.fail(format!("{what}[{k}] is not sorted without repeats"));
            }
        }
        Ok(())
    }

    fn cyclic(&self, cyclic: bool, keys: usize) -> Result<()> {
        if cyclic && keys < 3 {
            return self.fail(format!("cyclic is true with {keys} keys (at least 3 are needed)"));
        }
        Ok(())
    }

    fn key_poses(&self, keys: &KeyPoses, n: usize) -> Result<()> {
        self.times("keys.times", &keys.times)?;
        let k = keys.times.len();
        self.poses("keys.positions", &keys.positions, k, n)?;
        self.sets("keys.fixed", &keys.fixed, k, n)?;
        self.sets("keys.fixed_velocity", &keys.fixed_velocity, k, n)?;
        self.cyclic(keys.cyclic, k)
    }

    /// Key times, positions and velocities of `n` points each.
    fn trajectory(&self, tr: &Trajectory, n: usize, of: &str) -> Result<()> {
        self.times("trajectory.times", &tr.times)?;
        let k = tr.times.len();
        for (what, keys) in [("trajectory.positions", &tr.positions), ("trajectory.velocities", &tr.velocities)] {
            if keys.len() != k {
                return self.fail(format!("{what} has {} keys for {k} key times", keys.len()));
            }
            for (key, pose) in keys.iter().enumerate() {
                if pose.len() != n {
                    return self.fail(format!("{what}[{key}] has {} points for {n} {of}", pose.len()));
                }
                self.points(&format!("{what}[{key}]"), pose)?;
            }
        }
        Ok(())
    }
}
