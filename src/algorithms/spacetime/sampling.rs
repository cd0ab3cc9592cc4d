//! Where the residual force is sampled, and the time slots the unknowns live in.
//!
//! Sample placement: `K_i` samples on interval `i` at the midpoints `θ_k = (k + ½) / K_i`, each
//! with quadrature weight `dτ = T_i / K_i` (the composite midpoint rule for `∫ ½|f|² dt`).
//! Midpoints treat every interval alike and never sample a key twice from both sides. (The
//! reference code samples `θ = k/K` and moves the last sample of the last interval to `θ = 1`.)
//! `K_i` is the scene's `samples`, or `contact_samples` on an interval that begins or ends at
//! a contact ([`sample_counts`]); a zero-length (contact) interval has no samples.
//!
//! Time slots: every key owns a velocity slot; a key owns a position slot unless it shares
//! its predecessor's position (a contact: two keys at the same time, the same pose, separate
//! velocities) or it is the last key of a loop (which is the first key). So the number of
//! slots is `2 N - contacts` in an open animation, minus 2 more in a loop.

use super::trajectory::{hermite_weights, SlotWeights};

/// Maps keys to their time slots.
///
/// Invariants: `position` and `velocity` have one entry per key; every slot below `count` is
/// used by at least one key, and a slot holds either positions or velocities, never both.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TimeSlots {
    position: Vec<usize>,
    velocity: Vec<usize>,
    count: usize,
}

impl TimeSlots {
    /// The slots of keys at `times` (non-decreasing; equal consecutive times are a contact).
    pub fn new(times: &[f64], cyclic: bool) -> TimeSlots {
        let keys = times.len();
        let (mut position, mut velocity, mut count) = (Vec::with_capacity(keys), Vec::with_capacity(keys), 0);
        for k in 0..keys {
            if cyclic && k + 1 == keys && k > 0 {
                position.push(position[0]);
                velocity.push(velocity[0]);
                continue;
            }
            if k > 0 && times[k] == times[k - 1] {
                position.push(position[k - 1]);
            } else {
                position.push(count);
                count += 1;
            }
            velocity.push(count);
            count += 1;
        }
        TimeSlots { position, velocity, count }
    }

    /// Number of keys.
    pub fn keys(&self) -> usize {
        self.position.len()
    }

    /// The position slot of key `k`.
    pub fn position(&self, k: usize) -> usize {
        self.position[k]
    }

    /// The velocity slot of key `k`.
    pub fn velocity(&self, k: usize) -> usize {
        self.velocity[k]
    }

    /// Number of slots.
    pub fn count(&self) -> usize {
        self.count
    }

    /// Whether slot `s` holds positions (else velocities).
    pub(crate) fn is_position(&self, s: usize) -> bool {
        self.position.contains(&s)
    }

    /// Keys whose position (for a position slot) or velocity uses slot `s`.
    pub(crate) fn keys_of(&self, s: usize) -> impl Iterator<Item = usize> + '_ {
        let list = if self.is_position(s) { &self.position } else { &self.velocity };
        (0..self.keys()).filter(move |&k| list[k] == s)
    }
}

/// Whether interval `i` of `times` is a contact (zero length).
pub(crate) fn is_contact(times: &[f64], i: usize) -> bool {
    times[i + 1] == times[i]
}

/// Samples per interval: none on a contact (zero-length) interval, `contact` on an interval
/// next to a contact, `regular` elsewhere.
pub fn sample_counts(times: &[f64], regular: usize, contact: usize) -> Vec<usize> {
    let intervals = times.len() - 1;
    (0..intervals)
        .map(|i| {
            if is_contact(times, i) {
                0
            } else if (i > 0 && is_contact(times, i - 1)) || (i + 1 < intervals && is_contact(times, i + 1)) {
                contact
            } else {
                regular
            }
        })
        .collect()
}

/// One sample point of the residual.
#[derive(Debug, Clone, PartialEq)]
pub struct Sample {
    /// The keyframe interval `i` the sample lies in.
    pub interval: usize,
    /// Fraction of the interval elapsed at the sample, in `(0, 1)`.
    pub theta: f64,
    /// Absolute time in seconds.
    pub time: f64,
    /// Quadrature weight dτ (seconds).
    pub weight: f64,
    /// Slots of `(x_i, v_i, x_{i+1}, v_{i+1})`.
    pub slots: [usize; 4],
    /// Hermite weights of those unknowns at this instant.
    pub basis: SlotWeights,
}

/// `counts[i]` midpoint samples on interval `i` of `times` (see [`sample_counts`]); intervals
/// of zero length get none whatever their count.
pub fn samples(times: &[f64], counts: &[usize], slots: &TimeSlots) -> Vec<Sample> {
    let mut out = Vec::with_capacity(counts.iter().sum());
    for i in 0..times.len() - 1 {
        let len = times[i + 1] - times[i];
        let per_interval = counts[i];
        if len <= 0.0 {
            continue;
        }
        for k in 0..per_interval {
            let theta = (k as f64 + 0.5) / per_interval as f64;
            out.push(Sample {
                interval: i,
                theta,
                time: times[i] + theta * len,
                weight: len / per_interval as f64,
                slots: [slots.position(i), slots.velocity(i), slots.position(i + 1), slots.velocity(i + 1)],
                basis: hermite_weights(theta, len),
            });
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cyclic_slots_alias_the_last_key_to_the_first() {
        let s = TimeSlots::new(&[0.0, 1.0, 2.0, 3.0], true);
        assert_eq!(s.count(), 6);
        assert_eq!((s.position(3), s.velocity(3)), (0, 1));
        assert_eq!(s.keys_of(0).collect::<Vec<_>>(), vec![0, 3]);
        assert_eq!(s.keys_of(3).collect::<Vec<_>>(), vec![1]);
    }

    #[test]
    fn a_contact_shares_the_position_slot_and_not_the_velocity() {
        // Keys 1 and 2 are a contact: one position, two velocities.
        let s = TimeSlots::new(&[0.0, 0.3, 0.3, 0.8], false);
        assert_eq!(s.count(), 7);
        assert_eq!((s.position(1), s.position(2)), (2, 2));
        assert_ne!(s.velocity(1), s.velocity(2));
        assert_eq!(s.keys_of(2).collect::<Vec<_>>(), vec![1, 2]);
        assert!(s.is_position(2) && !s.is_position(s.velocity(2)));
        assert_eq!(sample_counts(&[0.0, 0.3, 0.3, 0.8, 1.0], 10, 20), vec![20, 0, 20, 10]);
        let samples = samples(&[0.0, 0.3, 0.3, 0.8], &[4, 4, 4], &s);
        assert_eq!(samples.len(), 8, "the contact interval has none");
        assert!(samples.iter().all(|x| x.interval != 1 && x.basis.acc.iter().all(|a| a.is_finite())));
    }

    #[test]
    fn weights_integrate_the_duration_and_samples_are_midpoints() {
        let times = [0.0, 0.5, 1.7];
        let s = samples(&times, &[4, 4], &TimeSlots::new(&times, false));
        assert_eq!(s.len(), 8);
        assert!((s.iter().map(|s| s.weight).sum::<f64>() - 1.7).abs() < 1e-15);
        assert!((s[0].time - 0.0625).abs() < 1e-15);
        assert!((s[7].time - (0.5 + 1.2 * 7.0 / 8.0)).abs() < 1e-15);
    }
}
