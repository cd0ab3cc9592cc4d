//! Contact with obstacles: every node stays outside every obstacle at every check instant.
//!
//! The instants are the keys that own a pose (a contact's two keys share one) and every frame
//! of the full-frame output at `frame_rate` between them: what a viewer sees. A node's
//! position at an instant is linear in the keyframe unknowns,
//!
//! ```text
//! x_a(t) = Σ_j h_j(θ, T_i) u_j(a)     (the four unknowns of the interval i containing t)
//! ```
//!
//! so each check is one linear inequality on a step (the obstacle's normal times these
//! weights; at a key, the key's position alone). When the key times move too, a frame's
//! position also depends on the interval lengths: the frame's absolute time is fixed, so
//! lengthening an earlier interval moves every later key past it (`∂x/∂T_j = -ẋ(t)` for
//! `j < i`), and lengthening its own interval slides its `θ` back and stretches the velocity
//! weights (`∂x/∂T_i = -θ ẋ(t) + Σ_j ∂h_j/∂T_i u_j`). [`Contacts::row`] linearizes there.
//!
//! The solver keeps the active checks as rows of the active set ([`super::active_set`]) and
//! blocks every step at the first inactive check it would cross ([`Contacts::blocking`]).

use super::active_set::{Row, RowKind};
use super::obstacles::Obstacle;
use super::sampling::TimeSlots;
use super::trajectory::{frames_between, hermite_weights, length_derivative, locate, Trajectory};
use super::unknowns::Unknowns;
use crate::algorithms::geometry::{dot, Point};

/// An instant at which the nodes are checked.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum At {
    /// The pose of key `k` (at whatever time it has).
    Key(usize),
    /// Frame number `f`, at the absolute time `f / frame_rate`.
    Frame(i64),
}

/// One node against one obstacle at one instant.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Check {
    /// The instant.
    pub at: At,
    /// The mesh node.
    pub node: u32,
    /// Index of the obstacle in [`Contacts::obstacles`].
    pub obstacle: u16,
}

/// The obstacles and the instants at which they are enforced.
#[derive(Debug, Clone, PartialEq)]
pub struct Contacts {
    /// The obstacles every node must stay outside of.
    pub obstacles: Vec<Obstacle>,
    /// Frames per second of the frames checked.
    pub frame_rate: f64,
}

/// The positions of every node at every instant of a trajectory.
pub struct Snapshot {
    /// `(instant, time)`, keys first, then frames in time order.
    pub instants: Vec<(At, f64)>,
    /// `positions[instant][node]`.
    pub positions: Vec<Vec<Point>>,
}

impl Contacts {
    /// The instants of `tr`: every key that owns its pose, and every frame that is not at a
    /// key's time (there the key is checked).
    pub fn instants(&self, tr: &Trajectory, slots: &TimeSlots) -> Vec<(At, f64)> {
        let mut out: Vec<(At, f64)> =
            (0..tr.key_count()).filter(|&k| slots.keys_of(slots.position(k)).next() == Some(k)).map(|k| (At::Key(k), tr.times[k])).collect();
        let at_key = |t: f64| tr.times.iter().any(|&k| (k - t).abs() <= 1e-9);
        out.extend(frames_between(tr.start(), tr.end(), self.frame_rate).into_iter().filter(|&(_, t)| !at_key(t)).map(|(f, t)| (At::Frame(f), t)));
        out
    }

    /// Every node's position at every instant.
    pub fn snapshot(&self, tr: &Trajectory, slots: &TimeSlots) -> Snapshot {
        let instants = self.instants(tr, slots);
        let positions = instants
            .iter()
            .map(|&(at, t)| match at {
                At::Key(k) => tr.positions[k].clone(),
                At::Frame(_) => tr.evaluate(t),
            })
            .collect();
        Snapshot { instants, positions }
    }

    /// The signed distance of a check in a snapshot (negative inside).
    pub fn distance(&self, snap: &Snapshot, instant: usize, node: usize, obstacle: usize) -> f64 {
        self.obstacles[obstacle].distance(snap.positions[instant][node])
    }

    /// Every check of a snapshot with its distance, for callers that scan them all.
    pub fn each<'s>(&'s self, snap: &'s Snapshot) -> impl Iterator<Item = (Check, usize, f64)> + 's {
        snap.instants.iter().enumerate().flat_map(move |(i, &(at, _))| {
            snap.positions[i].iter().enumerate().flat_map(move |(node, &x)| {
                self.obstacles
                    .iter()
                    .enumerate()
                    .map(move |(o, obstacle)| (Check { at, node: node as u32, obstacle: o as u16 }, i, obstacle.distance(x)))
            })
        })
    }

    /// The smallest signed distance of any node to any obstacle at any instant (infinite
    /// without obstacles).
    pub fn clearance(&self, snap: &Snapshot) -> f64 {
        self.each(snap).map(|(_, _, d)| d).fold(f64::INFINITY, f64::min)
    }

    /// The linearized check as a row of the active set, with its current distance; `None`
    /// when no free unknown and no free interval moves it (the check is data). `vars[i]` is
    /// the variable of interval `i`, if its length is optimized.
    pub fn row(&self, check: Check, tr: &Trajectory, unknowns: &Unknowns, vars: &[Option<usize>], kind: RowKind) -> Option<(Row, f64)> {
        let node = check.node as usize;
        let obstacle = &self.obstacles[check.obstacle as usize];
        let slots = &unknowns.slots;
        let (x, u, t) = match check.at {
            At::Key(k) => {
                let u: Vec<(usize, f64)> = unknowns.get(node, slots.position(k)).map(|i| (i, 1.0)).into_iter().collect();
                (tr.positions[k][node], u, Vec::new())
            }
            At::Frame(f) => {
                let time = f as f64 / self.frame_rate;
                let (i, theta) = locate(&tr.times, time);
                let len = tr.times[i + 1] - tr.times[i];
                let w = hermite_weights(theta, len);
                let s = [slots.position(i), slots.velocity(i), slots.position(i + 1), slots.velocity(i + 1)];
                let values = [tr.positions[i][node], tr.velocities[i][node], tr.positions[i + 1][node], tr.velocities[i + 1][node]];
                let combine = |c: &[f64; 4]| -> Point { std::array::from_fn(|d| (0..4).map(|j| c[j] * values[j][d]).sum()) };
                let x = combine(&w.pos);
                let mut u: Vec<(usize, f64)> = Vec::new();
                for j in 0..4 {
                    if let Some(idx) = unknowns.get(node, s[j]).filter(|_| w.pos[j] != 0.0) {
                        match u.iter_mut().find(|e| e.0 == idx) {
                            Some(e) => e.1 += w.pos[j],
                            None => u.push((idx, w.pos[j])),
                        }
                    }
                }
                let n = obstacle.normal(x);
                let velocity = combine(&w.vel);
                let stretch = combine(&length_derivative(&w, len, 1).pos);
                let mut t = Vec::new();
                for (j, var) in vars.iter().enumerate().take(i + 1) {
                    let Some(var) = *var else { continue };
                    let dx: Point = if j < i { velocity.map(|v| -v) } else { std::array::from_fn(|d| -theta * velocity[d] + stretch[d]) };
                    t.push((var, dot(n, dx)));
                }
                (x, u, t)
            }
        };
        if u.is_empty() && t.is_empty() {
            return None;
        }
        Some((Row { kind, u, normal: obstacle.normal(x), t }, obstacle.distance(x)))
    }
}

impl Contacts {
    /// How fast every node moves at every instant of `snap` (taken at `tr`) along a step: `du`
    /// holds the step of the keyframe values (a trajectory on the same times), `dt[i]` the
    /// change of interval `i`'s length. Linear in the step (module documentation).
    pub fn motion(&self, snap: &Snapshot, tr: &Trajectory, du: &Trajectory, dt: &[f64]) -> Vec<Vec<Point>> {
        let moves_times = dt.iter().any(|&d| d != 0.0);
        snap.instants
            .iter()
            .map(|&(at, t)| match at {
                At::Key(k) => du.positions[k].clone(),
                At::Frame(_) => {
                    let mut dx = du.evaluate(t);
                    if moves_times {
                        let (i, theta) = tr.locate(t);
                        let before: f64 = dt[..i].iter().sum();
                        let len = tr.times[i + 1] - tr.times[i];
                        let w = hermite_weights(theta, len);
                        let stretch = length_derivative(&w, len, 1).pos;
                        let velocity = tr.velocity(t);
                        for (node, d) in dx.iter_mut().enumerate() {
                            for c in 0..3 {
                                let s = stretch[0] * tr.positions[i][node][c]
                                    + stretch[1] * tr.velocities[i][node][c]
                                    + stretch[2] * tr.positions[i + 1][node][c]
                                    + stretch[3] * tr.velocities[i + 1][node][c];
                                d[c] += -velocity[node][c] * (before + theta * dt[i]) + s * dt[i];
                            }
                        }
                    }
                    dx
                }
            })
            .collect()
    }

    /// The first check not in `active` that the step `α × (du, dt)` would push through its
    /// obstacle for some `α` in `(0, limit]`, by the linearization: the largest `α` that
    /// keeps every one outside, and the check that stops it (none when the whole `limit` is
    /// free). Checks already inside stay where they are (`α = 0` only if they go deeper).
    pub fn blocking(&self, snap: &Snapshot, motion: &[Vec<Point>], active: &dyn Fn(Check) -> bool, limit: f64) -> Option<(f64, Check)> {
        let mut best: Option<(f64, Check)> = None;
        for (check, i, distance) in self.each(snap) {
            let node = check.node as usize;
            let n = self.obstacles[check.obstacle as usize].normal(snap.positions[i][node]);
            let rate = dot(n, motion[i][node]);
            if rate >= 0.0 || active(check) {
                continue;
            }
            let alpha = (distance.max(0.0) / -rate).min(limit);
            if alpha < limit && best.is_none_or(|b| alpha < b.0) {
                best = Some((alpha, check));
            }
        }
        best
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::algorithms::spacetime::unknowns::KeyConstraints;

    /// One node falling onto the plane y = 0 with a contact at key 1.
    fn bounce() -> (Trajectory, KeyConstraints) {
        let times = vec![0.0, 0.4, 0.4, 1.0];
        let positions = vec![vec![[0.0, 1.0, 0.0]], vec![[0.1, 0.0, 0.0]], vec![[0.1, 0.0, 0.0]], vec![[0.2, 0.8, 0.0]]];
        let velocities = vec![vec![[0.2, 0.0, 0.0]], vec![[0.3, -4.0, 0.1]], vec![[0.2, 3.0, 0.0]], vec![[0.1, 0.5, 0.0]]];
        let keys = KeyConstraints {
            times: times.clone(),
            positions: positions.clone(),
            fixed: vec![vec![0], vec![], vec![], vec![0]],
            fixed_velocity: vec![vec![]; 4],
            cyclic: false,
        };
        (Trajectory { times, positions, velocities }, keys)
    }

    #[test]
    fn instants_are_owned_keys_and_frames_between_them() {
        let (tr, keys) = bounce();
        let c = Contacts { obstacles: vec![Obstacle::plane([0.0; 3], [0.0, 1.0, 0.0])], frame_rate: 10.0 };
        let at: Vec<At> = c.instants(&tr, &keys.slots()).into_iter().map(|i| i.0).collect();
        // Keys 0, 1, 3 (2 shares 1's pose); frames 1-3 and 5-9 (0, 4, 10 are at keys).
        let mut expected = vec![At::Key(0), At::Key(1), At::Key(3)];
        expected.extend([1, 2, 3, 5, 6, 7, 8, 9].map(At::Frame));
        assert_eq!(at, expected);
    }

    #[test]
    fn a_frame_row_is_the_derivative_of_the_distance() {
        // d/dz of the node's distance at a frame, by central differences in the unknowns and
        // in every interval length (the frame's absolute time fixed).
        let (tr, keys) = bounce();
        let unknowns = Unknowns::new(&keys, 1);
        let c = Contacts { obstacles: vec![Obstacle::Sphere { center: [0.3, -2.0, 0.2], radius: 1.5 }], frame_rate: 10.0 };
        let vars = vec![Some(0), None, Some(1)];
        for f in [2, 6] {
            let check = Check { at: At::Frame(f), node: 0, obstacle: 0 };
            let (row, dist) = c.row(check, &tr, &unknowns, &vars, RowKind::Contact(0)).unwrap();
            let distance = |tr: &Trajectory| c.obstacles[0].distance(tr.evaluate(f as f64 / 10.0)[0]);
            assert!((dist - distance(&tr)).abs() < 1e-15);
            let h = 1e-6;
            for &(i, w) in &row.u {
                for d in 0..3 {
                    let mut delta = vec![vec![[0.0; 3]; 1]; unknowns.slots.count()];
                    let slot = (0..unknowns.slots.count()).find(|&s| unknowns.get(0, s) == Some(i)).unwrap();
                    delta[slot][0][d] = 1.0;
                    let (mut p, mut m) = (tr.clone(), tr.clone());
                    crate::algorithms::spacetime::solver::apply_step(&mut p, &unknowns.slots, &delta, h);
                    crate::algorithms::spacetime::solver::apply_step(&mut m, &unknowns.slots, &delta, -h);
                    let fd = (distance(&p) - distance(&m)) / (2.0 * h);
                    assert!((fd - w * row.normal[d]).abs() < 1e-6, "frame {f}, unknown {i}, axis {d}: {fd} vs {}", w * row.normal[d]);
                }
            }
            for &(var, coefficient) in &row.t {
                let interval = [0, 2][var];
                let stretched = |e: f64| {
                    let mut t = tr.clone();
                    for k in interval + 1..t.times.len() {
                        t.times[k] += e;
                    }
                    t
                };
                let fd = (distance(&stretched(h)) - distance(&stretched(-h))) / (2.0 * h);
                assert!((fd - coefficient).abs() < 1e-6, "frame {f}, interval {interval}: {fd} vs {coefficient}");
            }
            assert_eq!(row.t.len(), if f < 4 { 1 } else { 2 });
        }
    }
}
