//! Test helpers shared by the mass-spring tests.

use super::energy::{Definiteness, SpringSystem};
use crate::algorithms::geometry::Point;

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
