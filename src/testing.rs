//! Helpers shared by the unit tests of several modules: small meshes, a deterministic random
//! generator, and the paper's assets.

use std::path::{Path, PathBuf};

use crate::mesh::TetMesh;
use crate::physics::mat3::Mat3;

/// A cube [0,1]³ split into `n³` cells of 6 tets each (Kuhn triangulation, positive).
pub fn cube_mesh(n: usize) -> TetMesh {
    let idx = |i: usize, j: usize, k: usize| (i * (n + 1) * (n + 1) + j * (n + 1) + k) as u32;
    let mut positions = Vec::new();
    for i in 0..=n {
        for j in 0..=n {
            for k in 0..=n {
                positions.push([i as f64 / n as f64, j as f64 / n as f64, k as f64 / n as f64]);
            }
        }
    }
    let mut tets = Vec::new();
    for i in 0..n {
        for j in 0..n {
            for k in 0..n {
                let c = |d: [usize; 3]| idx(i + d[0], j + d[1], k + d[2]);
                // The 6 monotone paths from corner 000 to 111.
                for perm in [[0, 1, 2], [0, 2, 1], [1, 0, 2], [1, 2, 0], [2, 0, 1], [2, 1, 0]] {
                    let mut p = [0usize; 3];
                    let mut verts = vec![c(p)];
                    for &axis in &perm {
                        p[axis] = 1;
                        verts.push(c(p));
                    }
                    tets.push([verts[0], verts[1], verts[2], verts[3]]);
                }
            }
        }
    }
    let mut m = TetMesh { positions, tets };
    m.orient_positive();
    m
}


/// A small deterministic generator of test data (xorshift).
pub struct Rng(pub u64);

impl Rng {
    /// Uniform in [-1, 1).
    pub fn next(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    }
    /// A matrix of [`Rng::next`] entries.
    pub fn mat(&mut self) -> Mat3 {
        [[self.next(), self.next(), self.next()], [self.next(), self.next(), self.next()], [self.next(), self.next(), self.next()]]
    }
}

/// A file of the paper's scenes under `../shared/assets/paper`, or `None` (with a note)
/// when it is missing outside CI. With `CI=true` a missing asset fails the test.
pub fn paper_asset(rel: &str) -> Option<PathBuf> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/assets/paper").join(rel);
    if path.is_file() {
        return Some(path);
    }
    assert!(
        std::env::var("CI").as_deref() != Ok("true"),
        "test asset {} is missing (required when CI=true)",
        path.display()
    );
    eprintln!("skipped: test asset {} is missing", path.display());
    None
}
