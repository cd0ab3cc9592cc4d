//! Axis-aligned bounding boxes: of point sets (a mesh's scale, a twist's axis), of tets (the
//! binding's search tree), and of the exported poses (USD extents, glTF accessor bounds).

use super::{norm, sub, Point};

/// A closed axis-aligned box `[lo, hi]`. Empty when some `lo[d] > hi[d]` ([`Bounds::EMPTY`], the
/// bounds of no points, is the identity of [`Bounds::union`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bounds {
    /// Smallest coordinate per axis.
    pub lo: Point,
    /// Largest coordinate per axis.
    pub hi: Point,
}

impl Bounds {
    /// The bounds of no points.
    pub const EMPTY: Bounds = Bounds { lo: [f64::INFINITY; 3], hi: [f64::NEG_INFINITY; 3] };

    /// The smallest box holding every point (empty for none).
    pub fn of(points: &[Point]) -> Bounds {
        points.iter().fold(Bounds::EMPTY, |b, &p| b.including(p))
    }

    /// [`Bounds::of`] single-precision points (exact: the bounds of `f32` values are `f32` values).
    pub(crate) fn of_f32(points: &[[f32; 3]]) -> Bounds {
        points.iter().fold(Bounds::EMPTY, |b, p| b.including(p.map(f64::from)))
    }

    /// Whether the box holds no point.
    pub fn is_empty(&self) -> bool {
        (0..3).any(|d| self.lo[d] > self.hi[d])
    }

    /// The box grown to hold `p`.
    pub fn including(self, p: Point) -> Bounds {
        self.union(Bounds { lo: p, hi: p })
    }

    /// The smallest box holding both.
    pub fn union(self, other: Bounds) -> Bounds {
        Bounds { lo: std::array::from_fn(|d| self.lo[d].min(other.lo[d])), hi: std::array::from_fn(|d| self.hi[d].max(other.hi[d])) }
    }

    /// The box grown by `pad` on every side.
    pub fn padded(self, pad: f64) -> Bounds {
        Bounds { lo: self.lo.map(|c| c - pad), hi: self.hi.map(|c| c + pad) }
    }

    /// The centre of the box.
    pub fn center(&self) -> Point {
        std::array::from_fn(|d| 0.5 * (self.lo[d] + self.hi[d]))
    }

    /// Whether `p` is in the (closed) box.
    pub fn contains(&self, p: Point) -> bool {
        (0..3).all(|d| self.lo[d] <= p[d] && p[d] <= self.hi[d])
    }

    /// Euclidean distance from `p` to the box (0 when inside): a lower bound on the distance
    /// to anything the box holds.
    pub fn distance(&self, p: Point) -> f64 {
        (0..3)
            .map(|d| {
                let gap = (self.lo[d] - p[d]).max(p[d] - self.hi[d]).max(0.0);
                gap * gap
            })
            .sum::<f64>()
            .sqrt()
    }

    /// Length of the diagonal (0 when empty): the scale errors are reported in.
    pub fn diagonal(&self) -> f64 {
        if self.is_empty() {
            0.0
        } else {
            norm(sub(self.hi, self.lo))
        }
    }

    /// `lo` and `hi` in single precision, as the file formats store them (zeros when empty).
    pub fn to_f32(&self) -> [[f32; 3]; 2] {
        if self.is_empty() {
            [[0.0; 3]; 2]
        } else {
            [self.lo.map(|x| x as f32), self.hi.map(|x| x as f32)]
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bounds_of_points_and_their_measures() {
        let b = Bounds::of(&[[1.0, -2.0, 0.5], [-1.0, 2.0, 0.5], [0.0, 0.0, 2.5]]);
        assert_eq!(b, Bounds { lo: [-1.0, -2.0, 0.5], hi: [1.0, 2.0, 2.5] });
        assert_eq!(b.center(), [0.0, 0.0, 1.5]);
        assert_eq!(b.diagonal(), 6f64.sqrt() * 2.0);
        assert!(b.contains([1.0, 2.0, 2.5]) && !b.contains([1.0, 2.0, 2.6]));
        assert_eq!(b.distance([4.0, 6.0, 0.5]), 5.0);
        assert_eq!(b.distance([0.0, 0.0, 1.0]), 0.0);
        assert_eq!(b.padded(1.0).lo, [-2.0, -3.0, -0.5]);
    }

    #[test]
    fn empty_bounds_are_the_identity_of_union() {
        assert!(Bounds::of(&[]).is_empty());
        assert_eq!(Bounds::of(&[]).diagonal(), 0.0);
        assert_eq!(Bounds::of(&[]).to_f32(), [[0.0; 3]; 2]);
        let b = Bounds::of(&[[1.0, 2.0, 3.0]]);
        assert!(!b.is_empty());
        assert_eq!(Bounds::EMPTY.union(b), b);
        assert_eq!(Bounds::of_f32(&[[0.1, 0.2, 0.3]]).to_f32(), [[0.1f32, 0.2, 0.3]; 2]);
    }
}
