//! Where the residual force is sampled, and the time slots the unknowns live in.
//!
//! Sample placement: `K` samples per interval at the midpoints `θ_k = (k + ½) / K`, each with
//! quadrature weight `dτ = T_i / K` (the composite midpoint rule for `∫ ½|f|² dt`). Midpoints
//! treat every interval alike and never sample a key twice from both sides. (The reference
//! code samples `θ = k/K` and moves the last sample of the last interval to `θ = 1`.)
//!
//! Time slots: every key owns a position slot and a velocity slot, `2k` and `2k + 1`. In a
//! cyclic animation the last key is the first, so it owns no slots of its own: the number of
//! slots is `2 (N - cyclic)`.

use super::trajectory::{hermite_weights, SlotWeights};

/// Maps keys to their time slots.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TimeSlots {
    pub keys: usize,
    pub cyclic: bool,
}

impl TimeSlots {
    /// The key whose unknowns key `k` uses (itself, or the first key for the last of a loop).
    pub fn owner(&self, k: usize) -> usize {
        if self.cyclic && k + 1 == self.keys {
            0
        } else {
            k
        }
    }

    pub fn position(&self, k: usize) -> usize {
        2 * self.owner(k)
    }

    pub fn velocity(&self, k: usize) -> usize {
        2 * self.owner(k) + 1
    }

    pub fn count(&self) -> usize {
        2 * (self.keys - self.cyclic as usize)
    }

    /// Keys that share slot `s` (one, or two for the first slot pair of a loop).
    pub fn keys_of(&self, s: usize) -> impl Iterator<Item = usize> + '_ {
        (0..self.keys).filter(move |&k| self.owner(k) == s / 2)
    }
}

/// One sample point of the residual.
#[derive(Debug, Clone, PartialEq)]
pub struct Sample {
    pub interval: usize,
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

/// `per_interval` midpoint samples on every interval of `times`.
pub fn samples(times: &[f64], per_interval: usize, slots: &TimeSlots) -> Vec<Sample> {
    let mut out = Vec::with_capacity(per_interval * times.len().saturating_sub(1));
    for i in 0..times.len() - 1 {
        let len = times[i + 1] - times[i];
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
        let s = TimeSlots { keys: 4, cyclic: true };
        assert_eq!(s.count(), 6);
        assert_eq!((s.position(3), s.velocity(3)), (0, 1));
        assert_eq!(s.keys_of(0).collect::<Vec<_>>(), vec![0, 3]);
        assert_eq!(s.keys_of(3).collect::<Vec<_>>(), vec![1]);
    }

    #[test]
    fn weights_integrate_the_duration_and_samples_are_midpoints() {
        let times = [0.0, 0.5, 1.7];
        let s = samples(&times, 4, &TimeSlots { keys: 3, cyclic: false });
        assert_eq!(s.len(), 8);
        assert!((s.iter().map(|s| s.weight).sum::<f64>() - 1.7).abs() < 1e-15);
        assert!((s[0].time - 0.0625).abs() < 1e-15);
        assert!((s[7].time - (0.5 + 1.2 * 7.0 / 8.0)).abs() < 1e-15);
    }
}
