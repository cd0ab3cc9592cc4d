//! Test helpers shared by the mass-spring tests.

use super::energy::{Definiteness, SpringSystem};
use crate::algorithms::geometry::Point;

/// A small deterministic generator (SplitMix64).
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Rng {
        Rng(seed)
    }

    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in `[lo, hi)`.
    pub fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// Bend a bar lying along +y from y = 0 to `length` into an arc of `angle` radians in the xy
/// plane, turning towards +x about the line x = `axis_x` + length / angle: the centre line
/// x = `axis_x` keeps its length, fibres at x > axis_x shorten, and the volume is kept (the
/// centroid stays on the centre line of a symmetric section: Pappus). Angle 0 is the identity.
pub fn bend(points: &[Point], length: f64, angle: f64, axis_x: f64) -> Vec<Point> {
    if angle == 0.0 {
        return points.to_vec();
    }
    let radius = length / angle;
    let centre_x = axis_x + radius;
    points
        .iter()
        .map(|p| {
            let phi = angle * p[1] / length;
            let rho = centre_x - p[0];
            [centre_x - rho * phi.cos(), rho * phi.sin(), p[2]]
        })
        .collect()
}

/// Every column of the network's Hessian at `x` (`definiteness` as the solver assembles it):
/// `check(v, c, column)` gets `H e_vc`, the product with the unit vector of vertex `v`'s
/// coordinate `c`, so a test can compare it entry by entry with another form of `H`.
pub fn hessian_columns(system: &SpringSystem, x: &[Point], definiteness: Definiteness, mut check: impl FnMut(usize, usize, &[Point])) {
    let n = x.len();
    let mut e = vec![[0.0; 3]; n];
    let mut column = vec![[0.0; 3]; n];
    for v in 0..n {
        for c in 0..3 {
            e.fill([0.0; 3]);
            e[v][c] = 1.0;
            system.hessian_apply(x, &e, definiteness, &mut column);
            check(v, c, &column);
        }
    }
}
