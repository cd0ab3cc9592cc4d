//! What a bake keeps for the next one: `bake.cache` in its folder, written by a bake with
//! `--from` and read back by the next `blendsim bake --from DIR`. It holds TetGen's mesh and the solve's result, each under a
//! content hash of everything that made it, so a re-bake reuses a stage only when its inputs
//! are the same bytes:
//!
//! - TetGen's mesh: the blendsim binary, the TetGen program, the rest surface and the `[tet]`
//!   options;
//! - the solve: the binary, the whole body (tet mesh, key poses, masks, times, surface, the
//!   scene with every setting, the method) and `--max-memory`;
//! - the warm start: the same without the key poses. When only the poses moved, the solve
//!   starts from the previous solution moved by the keys' edits (each key's node by its own
//!   move), not from the first guess.
//!
//! Import always runs (it reads the inputs that are hashed); the cage, the fit of the interior
//! nodes, embed, export and report run again from the reused data, so the files are the cold
//! bake's bytes when nothing changed. The binary is identified by its build ID (the linker's
//! hash of the linked file, read from its ELF note) or, without one, by the hash of its bytes:
//! a rebuilt blendsim reuses nothing. The file is JSON in shortest round-trip numbers (values
//! read back are the values written) and is written with the bake's other files, in its one
//! commit.

use std::hash::{DefaultHasher, Hasher};
use std::io::Write;
use std::path::Path;
use std::sync::OnceLock;

use serde::{Deserialize, Serialize};

use crate::algorithms::geometry::{Point, TetMesh, TriMesh};
use crate::algorithms::spacetime::trajectory::Trajectory;
use crate::formats::tetgen::{self, TetgenOptions};
use crate::pipeline::stage_file::{Body, KeyPoses, Solution, SolverLog};
use crate::support::build_id::gnu_build_id;
use crate::support::error::{Error, Result};

/// The file's name in a bake's folder.
pub const FILE: &str = "bake.cache";

/// The format of [`FILE`]; another is read as no cache (a cold bake).
const FORMAT: u32 = 1;

/// The contents of [`FILE`].
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct BakeCache {
    blendsim_bake_cache: u32,
    /// The identity of the blendsim binary that wrote it (its build ID, or its bytes' hash).
    binary: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    tetgen: Option<TetgenEntry>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    solve: Option<SolveEntry>,
}

/// TetGen's mesh and the key of its inputs.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct TetgenEntry {
    key: String,
    mesh: TetMesh,
}

/// The solve's result, the keys of its inputs with and without the key poses, and the key
/// poses (per key and node) it was solved for.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct SolveEntry {
    key: String,
    warm_key: String,
    keys: Vec<Vec<Point>>,
    trajectory: Trajectory,
    log: SolverLog,
}

/// What a re-bake took from the previous one.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Reused {
    /// TetGen did not run: its mesh of the same surface and options was kept.
    pub tetgen: bool,
    /// The solve did not run: its result for the same body and settings was kept.
    pub solve: bool,
    /// The solve started from the previous solution (only the key poses moved).
    pub warm_start: bool,
}

impl Reused {
    /// One line for the command line: what was reused, or that nothing could be.
    pub fn describe(&self) -> String {
        let mut parts = Vec::new();
        if self.tetgen {
            parts.push("TetGen's mesh");
        }
        if self.solve {
            parts.push("the solve");
        } else if self.warm_start {
            parts.push("the solution as the solve's start (only keys moved)");
        }
        if parts.is_empty() {
            "nothing reused (the inputs changed), every stage ran".into()
        } else {
            format!("reused {}", parts.join(", "))
        }
    }
}

impl BakeCache {
    /// A cache to fill, for this binary.
    pub fn new() -> Result<BakeCache> {
        Ok(BakeCache { blendsim_bake_cache: FORMAT, binary: binary()?.clone(), tetgen: None, solve: None })
    }

    /// The cache of the bake folder `dir` (`--from`): an error when `dir` is not a bake's
    /// output folder; `Ok(Err(why))` when it is but its cache cannot serve (missing, damaged,
    /// another format or another binary), for a warning and a cold bake.
    pub fn load(dir: &Path) -> Result<std::result::Result<BakeCache, String>> {
        let fix = "pass the --out folder of an earlier `blendsim bake`";
        if !dir.is_dir() {
            return Err(Error::in_file(dir, "is not a bake output folder (no such folder)", fix));
        }
        let path = dir.join(FILE);
        if !path.exists() {
            if !dir.join(crate::support::output::MANIFEST).is_file() {
                return Err(Error::in_file(dir, format!("is not a bake output folder (no {FILE}, no {})", crate::support::output::MANIFEST), fix));
            }
            return Ok(Err(format!("{} has no {FILE} (a bake keeps one only when run with --from)", dir.display())));
        }
        let bytes = std::fs::read(&path).map_err(|e| Error::io(&path, &e, "read the previous bake's cache"))?;
        let cache: BakeCache = match serde_json::from_slice(&bytes) {
            Ok(c) => c,
            Err(e) => return Ok(Err(format!("{} is damaged ({e})", path.display()))),
        };
        if cache.blendsim_bake_cache != FORMAT {
            return Ok(Err(format!("{} is in format {}, this blendsim reads {FORMAT}", path.display(), cache.blendsim_bake_cache)));
        }
        if cache.binary != *binary()? {
            return Ok(Err(format!("{} was written by another blendsim build", path.display())));
        }
        Ok(Ok(cache))
    }

    /// The JSON bytes of the file.
    pub fn to_json(&self) -> Vec<u8> {
        let mut bytes = serde_json::to_vec(self).expect("the bake cache serializes");
        bytes.push(b'\n');
        bytes
    }

    /// TetGen's kept mesh for the inputs of `key` ([`tetgen_key`]), if this cache has it.
    pub fn tetgen(&self, key: &str) -> Option<TetMesh> {
        self.tetgen.as_ref().filter(|e| e.key == key).map(|e| e.mesh.clone())
    }

    /// Keep TetGen's `mesh` for the inputs of `key`.
    pub(crate) fn keep_tetgen(&mut self, key: String, mesh: &TetMesh) {
        self.tetgen = Some(TetgenEntry { key, mesh: mesh.clone() });
    }

    /// The kept solution of `body` (whose keys are `keys`), if this cache has it.
    pub fn solution(&self, body: &Body, keys: &SolveKeys) -> Option<Solution> {
        let e = self.solve.as_ref().filter(|e| e.key == keys.key)?;
        Some(Solution { body: body.clone(), trajectory: e.trajectory.clone(), log: e.log.clone() })
    }

    /// Where the solve of `body` may start: the kept solution of the same body with other key
    /// poses, each key's nodes moved by their key's edit (prescribed values set to the new
    /// key's exactly).
    pub(crate) fn warm_start(&self, body: &Body, keys: &SolveKeys) -> Option<Trajectory> {
        let e = self.solve.as_ref().filter(|e| e.warm_key == keys.warm_key)?;
        let poses = &body.keys;
        let mut start = e.trajectory.clone();
        let (n_keys, nodes) = (poses.positions.len(), poses.positions.first().map_or(0, Vec::len));
        let fits = |p: &[Vec<Point>]| p.len() == n_keys && p.iter().all(|q| q.len() == nodes);
        if start.times != poses.times || !fits(&start.positions) || !fits(&start.velocities) || !fits(&e.keys) {
            return None;
        }
        for (k, (x, (new, old))) in start.positions.iter_mut().zip(poses.positions.iter().zip(&e.keys)).enumerate() {
            for (a, x) in x.iter_mut().enumerate() {
                *x = std::array::from_fn(|c| x[c] + (new[a][c] - old[a][c]));
            }
            for &a in poses.fixed[k].indices() {
                x[a as usize] = new[a as usize];
            }
            for &a in poses.fixed_velocity[k].indices() {
                start.velocities[k][a as usize] = [0.0; 3];
            }
        }
        // A loop's last key is its first.
        if poses.cyclic && n_keys > 1 {
            start.positions[n_keys - 1] = start.positions[0].clone();
            start.velocities[n_keys - 1] = start.velocities[0].clone();
        }
        Some(start)
    }

    /// Keep `solution`'s result, solved for the inputs of `keys`.
    pub(crate) fn keep_solution(&mut self, solution: &Solution, keys: SolveKeys) {
        self.solve = Some(SolveEntry {
            key: keys.key,
            warm_key: keys.warm_key,
            keys: solution.body.keys.positions.clone(),
            trajectory: solution.trajectory.clone(),
            log: solution.log.clone(),
        });
    }
}

/// The keys of a solve's inputs: all of them, and all but the key poses.
#[derive(Debug, Clone)]
pub struct SolveKeys {
    key: String,
    warm_key: String,
}

impl SolveKeys {
    /// The keys of solving `body` within `max_memory` (`--max-memory`, which chooses the
    /// linear solver): the warm key hashes the whole body but its key poses and what follows
    /// from them alone (the warnings, a cage's key errors, the input's size); the key adds
    /// those poses. The body is serialized once.
    pub fn of(body: &Body, max_memory: Option<u64>) -> SolveKeys {
        let mut rest = Body { warnings: Vec::new(), input_bytes: 0, keys: KeyPoses { positions: Vec::new(), ..body.keys.clone() }, ..body.clone() };
        if let Some(cage) = &mut rest.cage {
            (cage.key_error_max, cage.key_error_rms) = (0.0, 0.0);
        }
        let warm_key = digest(|d| {
            d.field("warm");
            d.field(binary().map_or("", String::as_str));
            d.json(&(&rest, max_memory));
        });
        let key = digest(|d| {
            d.field("solve");
            d.field(&warm_key);
            d.json(&(&body.keys.positions, body.cage.as_ref().map(|c| [c.key_error_max, c.key_error_rms]), body.input_bytes));
        });
        SolveKeys { key, warm_key }
    }
}

/// The key of TetGen's inputs: the binary, the TetGen program, the surface and the options.
pub fn tetgen_key(surface: &TriMesh, options: &TetgenOptions) -> String {
    digest(|d| {
        d.field("tetgen");
        d.field(binary().map_or("", String::as_str));
        d.field(&tetgen_program());
        d.json(&(surface, [options.quality, options.max_volume, options.timeout]));
    })
}

/// The TetGen program a bake runs ([`tetgen::program`], found on `PATH`) as a path with its
/// size and modification time: another TetGen makes another key.
fn tetgen_program() -> String {
    let program = tetgen::program();
    let program = Path::new(&program);
    let found = if program.components().count() > 1 {
        Some(program.to_path_buf())
    } else {
        std::env::var_os("PATH").and_then(|path| std::env::split_paths(&path).map(|d| d.join(program)).find(|p| p.is_file()))
    };
    let stamp = |p: &Path| {
        let m = std::fs::metadata(p).ok()?;
        let modified = m.modified().ok()?.duration_since(std::time::UNIX_EPOCH).ok()?.as_nanos();
        Some(format!("{} {} {modified}", p.canonicalize().ok()?.display(), m.len()))
    };
    found.as_deref().and_then(stamp).unwrap_or_else(|| program.display().to_string())
}

/// The identity of the running blendsim's executable, computed once: its build ID (the
/// linker's hash of it, [`gnu_build_id`]) where it has one, else the hash of its bytes.
fn binary() -> Result<&'static String> {
    static BINARY: OnceLock<std::result::Result<String, String>> = OnceLock::new();
    let hashed = BINARY.get_or_init(|| {
        let exe = std::env::current_exe().map_err(|e| format!("cannot find the running blendsim ({e})"))?;
        if let Some(id) = gnu_build_id(&exe) {
            return Ok(format!("build-id {}", id.iter().map(|b| format!("{b:02x}")).collect::<String>()));
        }
        let mut d = Digest::default();
        std::fs::File::open(&exe)
            .and_then(|mut file| std::io::copy(&mut file, &mut d))
            .map_err(|e| format!("cannot read {} ({e})", exe.display()))?;
        Ok(d.hex())
    });
    hashed.as_ref().map_err(|e| Error::general(format!("the bake cache needs the binary's hash: {e}"), "run blendsim from a readable file"))
}

/// A 128-bit content hash: two SipHash-1-3 streams with different first bytes. Not a
/// defence against crafted collisions; the binary is part of every key, so the hash function
/// (std's, which may change between Rust releases) is always the same for one cache.
struct Digest(DefaultHasher, DefaultHasher);

impl Default for Digest {
    fn default() -> Digest {
        let (a, mut b) = (DefaultHasher::new(), DefaultHasher::new());
        b.write_u8(0xb5);
        Digest(a, b)
    }
}

impl Digest {
    fn add(&mut self, bytes: &[u8]) {
        self.0.write(bytes);
        self.1.write(bytes);
    }

    /// A string field, length-prefixed so fields cannot run into each other.
    fn field(&mut self, s: &str) {
        self.add(&(s.len() as u64).to_le_bytes());
        self.add(s.as_bytes());
    }

    /// A value as its JSON bytes (streamed, not buffered), closed by a separator JSON cannot hold.
    fn json<T: Serialize>(&mut self, value: &T) {
        serde_json::to_writer(&mut *self, value).expect("hashed values serialize");
        self.add(&[0xff]);
    }

    fn hex(&self) -> String {
        format!("{:016x}{:016x}", self.0.finish(), self.1.finish())
    }
}

impl Write for Digest {
    fn write(&mut self, bytes: &[u8]) -> std::io::Result<usize> {
        self.add(bytes);
        Ok(bytes.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

/// The hex digest of what `fill` adds.
fn digest(fill: impl FnOnce(&mut Digest)) -> String {
    let mut d = Digest::default();
    fill(&mut d);
    d.hex()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_digest_does_not_depend_on_how_the_bytes_are_split() {
        let whole = digest(|d| d.add(b"spacetime keyframes"));
        let split = digest(|d| {
            d.add(b"space");
            d.add(b"time keyframes");
        });
        assert_eq!(whole, split);
        assert_ne!(whole, digest(|d| d.add(b"spacetime keyframeS")));
        // Fields are length-prefixed: moving a byte from one to the next changes the key.
        assert_ne!(
            digest(|d| {
                d.field("ab");
                d.field("c")
            }),
            digest(|d| {
                d.field("a");
                d.field("bc")
            })
        );
    }
}
