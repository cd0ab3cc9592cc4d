//! Which keyframe positions and velocities are unknowns, and where they sit in the global
//! vector. Masked (fixed) values are eliminated, not penalized: they keep the value they have
//! in the trajectory and are never written.
//!
//! Layout is node-major (all free slots of node 0, then node 1, ...), so a node's unknowns are
//! contiguous and the three coordinates share one index (they are three right-hand sides of
//! one system).

use super::sampling::TimeSlots;
use crate::algorithms::geometry::Point;

/// The keyframes a trajectory is solved for: key times, the input poses (where the solve
/// starts), the node positions and velocities each key prescribes, and whether it loops.
///
/// Invariants: at least two non-decreasing `times`, where two equal consecutive times are a
/// contact (the two keys share their pose, not their velocities; never two contacts in a row,
/// nor at the first or last key); one pose and one index list of each kind per key, equal for
/// the two keys of a contact; every pose has the body's node count; index lists are sorted node
/// indices.
#[derive(Debug, Clone, PartialEq)]
pub struct KeyConstraints {
    /// Key times in seconds.
    pub times: Vec<f64>,
    /// `positions[key][node]`: the input poses.
    pub positions: Vec<Vec<Point>>,
    /// Per key, the nodes whose position is prescribed (kept at its input value).
    pub fixed: Vec<Vec<u32>>,
    /// Per key, the nodes whose velocity is prescribed (kept at zero).
    pub fixed_velocity: Vec<Vec<u32>>,
    /// The last key is the first: the animation loops.
    pub cyclic: bool,
}

impl KeyConstraints {
    /// The time slots of these keys (contacts and loops alias slots).
    pub fn slots(&self) -> TimeSlots {
        TimeSlots::new(&self.times, self.cyclic)
    }

    /// Per node, whether its whole trajectory is prescribed: position and velocity held at
    /// every key. Its residual is then the force the support exerts on it (a reaction), not a
    /// dynamics error, and W leaves it out (see [`super::objective`]).
    pub fn supports(&self, nodes: usize) -> Vec<bool> {
        let mut count = vec![0usize; nodes];
        for (fixed, velocity) in self.fixed.iter().zip(&self.fixed_velocity) {
            for &a in fixed {
                count[a as usize] += 1;
            }
            for &a in velocity {
                count[a as usize] += 1;
            }
        }
        count.iter().map(|&c| c == 2 * self.times.len()).collect()
    }
}

/// The free keyframe values of every node and their place in the global vector.
#[derive(Debug, Clone, PartialEq)]
pub struct Unknowns {
    /// The time slots of the keys.
    pub slots: TimeSlots,
    /// Nodes of the body.
    pub nodes: usize,
    /// `index[node * slot_count + slot]`, `u32::MAX` when fixed.
    index: Vec<u32>,
    count: usize,
}

const FIXED: u32 = u32::MAX;

impl Unknowns {
    /// The free entries of a per-slot array, in unknown order.
    pub fn gather(&self, per_slot: &[Vec<Point>]) -> Vec<Point> {
        let mut out = vec![[0.0; 3]; self.count()];
        for (s, values) in per_slot.iter().enumerate() {
            for (a, v) in values.iter().enumerate() {
                if let Some(i) = self.get(a, s) {
                    out[i] = *v;
                }
            }
        }
        out
    }

    /// A per-slot array from free entries (zero at fixed entries).
    pub fn scatter(&self, free: &[Point]) -> Vec<Vec<Point>> {
        let mut out = vec![vec![[0.0; 3]; self.nodes]; self.slots.count()];
        for (s, values) in out.iter_mut().enumerate() {
            for (a, v) in values.iter_mut().enumerate() {
                if let Some(i) = self.get(a, s) {
                    *v = free[i];
                }
            }
        }
        out
    }

    /// Free unknowns of `keys`: a slot is fixed for a node if any key sharing that slot fixes
    /// it (a loop's last key adds its masks to the first key's).
    pub fn new(keys: &KeyConstraints, nodes: usize) -> Unknowns {
        let slots = keys.slots();
        let s_count = slots.count();
        let mut fixed = vec![false; nodes * s_count];
        for k in 0..slots.keys() {
            for &a in &keys.fixed[k] {
                fixed[a as usize * s_count + slots.position(k)] = true;
            }
            for &a in &keys.fixed_velocity[k] {
                fixed[a as usize * s_count + slots.velocity(k)] = true;
            }
        }
        let mut count = 0usize;
        let index = fixed
            .iter()
            .map(|&f| {
                if f {
                    FIXED
                } else {
                    count += 1;
                    (count - 1) as u32
                }
            })
            .collect();
        Unknowns { slots, nodes, index, count }
    }

    /// Number of free unknowns (per coordinate).
    pub fn count(&self) -> usize {
        self.count
    }

    /// Whether any keyframe position is held. Without one, translating the whole animation
    /// (and, with free velocities, a uniform drift `c t`) leaves W unchanged: the problem has a
    /// null space that only regularization removes.
    pub(crate) fn any_position_fixed(&self) -> bool {
        let s_count = self.slots.count();
        (0..s_count).filter(|&s| self.slots.is_position(s)).any(|s| (0..self.nodes).any(|a| self.get(a, s).is_none()))
    }

    /// Global index of slot `s` of `node`, if free.
    #[inline]
    pub fn get(&self, node: usize, s: usize) -> Option<usize> {
        let i = self.index[node * self.slots.count() + s];
        (i != FIXED).then_some(i as usize)
    }
}
