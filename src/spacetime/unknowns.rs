//! Which keyframe positions and velocities are unknowns, and where they sit in the global
//! vector. Masked (fixed) values are eliminated, not penalized: they keep the value they have
//! in the trajectory and are never written.
//!
//! Layout is node-major (all free slots of node 0, then node 1, ...), so a node's unknowns are
//! contiguous and the three coordinates share one index (they are three right-hand sides of
//! one system).

use super::sampling::TimeSlots;
use crate::mesh::Point;

/// The keyframes a trajectory is solved for: key times, the input poses (where the solve
/// starts), the node positions and velocities each key prescribes, and whether it loops.
///
/// Invariants: at least two strictly increasing `times`; one pose and one index list of each
/// kind per key; every pose has the body's node count; index lists are sorted node indices.
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
    /// Free unknowns of `keys`: a slot is fixed for a node if any key sharing that slot fixes
    /// it (a loop's last key adds its masks to the first key's).
    pub fn new(keys: &KeyConstraints, nodes: usize) -> Unknowns {
        let slots = TimeSlots { keys: keys.times.len(), cyclic: keys.cyclic };
        let s_count = slots.count();
        let mut fixed = vec![false; nodes * s_count];
        for k in 0..slots.keys {
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
    pub fn any_position_fixed(&self) -> bool {
        let s_count = self.slots.count();
        (0..self.nodes).any(|a| (0..s_count).step_by(2).any(|s| self.get(a, s).is_none()))
    }

    /// Global index of slot `s` of `node`, if free.
    #[inline]
    pub fn get(&self, node: usize, s: usize) -> Option<usize> {
        let i = self.index[node * self.slots.count() + s];
        (i != FIXED).then_some(i as usize)
    }
}
