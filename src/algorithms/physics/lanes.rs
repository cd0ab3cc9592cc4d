//! The SIMD lane layer: `N` values of `f64` (or `N` conditions) combined lane by lane, 3-vectors
//! and 3x3 matrices of lanes, and the run-time choice of the widest vector instructions.
//!
//! Kernels written on `Lanes` do per lane exactly the operations their scalar form does (every
//! branch a per-lane select; no fused multiply-adds are ever generated), so a value gets the same
//! bytes whether it goes through one lane, a batch of [`BATCH`], or a build for AVX2 or AVX-512.
//! Users: the signed SVD and the projections of the local step ([`super::svd3`],
//! [`super::projection`]), and the supernodal sweeps of the Cholesky solve
//! ([`super::cholesky`]), which are compiled for AVX2 by `simd_dispatch`.

use std::ops::{Add, BitAnd, BitOr, Div, Mul, Neg, Not, Sub};

use super::mat3::Mat3;

/// Matrices per call of the batched kernels.
pub const BATCH: usize = 16;

/// `N` lanes of `f64`, combined lane by lane.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Lanes<const N: usize>(pub [f64; N]);

/// `N` lane conditions.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Mask<const N: usize>(pub [bool; N]);

macro_rules! lane_op {
    ($trait:ident, $method:ident, $op:tt) => {
        impl<const N: usize> $trait for Lanes<N> {
            type Output = Lanes<N>;
            #[inline(always)]
            fn $method(self, b: Lanes<N>) -> Lanes<N> {
                let mut o = self.0;
                for l in 0..N {
                    o[l] = self.0[l] $op b.0[l];
                }
                Lanes(o)
            }
        }
    };
}
lane_op!(Add, add, +);
lane_op!(Sub, sub, -);
lane_op!(Mul, mul, *);
lane_op!(Div, div, /);

impl<const N: usize> Neg for Lanes<N> {
    type Output = Lanes<N>;
    #[inline(always)]
    fn neg(self) -> Lanes<N> {
        let mut o = self.0;
        for v in o.iter_mut() {
            *v = -*v;
        }
        Lanes(o)
    }
}

/// A lane-wise method from a `f64` one (written out, not through a closure: closures are not
/// reliably inlined into the SIMD-compiled callers).
macro_rules! lane_fn {
    ($name:ident, $f:expr) => {
        #[inline(always)]
        pub fn $name(self) -> Self {
            let mut o = self.0;
            for v in o.iter_mut() {
                *v = $f(*v);
            }
            Lanes(o)
        }
    };
}

macro_rules! lane_cmp {
    ($method:ident, $op:tt) => {
        #[inline(always)]
        pub fn $method(self, b: Lanes<N>) -> Mask<N> {
            let mut m = [false; N];
            for l in 0..N {
                m[l] = self.0[l] $op b.0[l];
            }
            Mask(m)
        }
    };
}

impl<const N: usize> Lanes<N> {
    #[inline(always)]
    pub(crate) fn splat(x: f64) -> Self {
        Lanes([x; N])
    }

    lane_fn!(sqrt, f64::sqrt);
    lane_fn!(abs, f64::abs);
    // `±1` and `±1e-12` with the sign of each lane.
    lane_fn!(sign, |x: f64| 1f64.copysign(x));
    lane_fn!(tiny_with_sign, |x: f64| 1e-12f64.copysign(x));

    #[inline(always)]
    pub fn max(self, b: Self) -> Self {
        let mut o = self.0;
        for l in 0..N {
            o[l] = o[l].max(b.0[l]);
        }
        Lanes(o)
    }

    /// `self` where `m`, else `other`.
    #[inline(always)]
    pub fn select(m: Mask<N>, a: Self, b: Self) -> Self {
        let mut o = b.0;
        for l in 0..N {
            if m.0[l] {
                o[l] = a.0[l];
            }
        }
        Lanes(o)
    }

    lane_cmp!(lt, <);
    lane_cmp!(le, <=);
    lane_cmp!(gt, >);
    lane_cmp!(eq, ==);
}

impl<const N: usize> Mask<N> {
    #[inline(always)]
    pub(crate) fn splat(b: bool) -> Self {
        Mask([b; N])
    }

    #[inline(always)]
    pub fn any(self) -> bool {
        self.0.iter().any(|&b| b)
    }
}

impl<const N: usize> BitAnd for Mask<N> {
    type Output = Mask<N>;
    #[inline(always)]
    fn bitand(self, b: Mask<N>) -> Mask<N> {
        let mut m = self.0;
        for l in 0..N {
            m[l] &= b.0[l];
        }
        Mask(m)
    }
}

impl<const N: usize> BitOr for Mask<N> {
    type Output = Mask<N>;
    #[inline(always)]
    fn bitor(self, b: Mask<N>) -> Mask<N> {
        let mut m = self.0;
        for l in 0..N {
            m[l] |= b.0[l];
        }
        Mask(m)
    }
}

impl<const N: usize> Not for Mask<N> {
    type Output = Mask<N>;
    #[inline(always)]
    fn not(self) -> Mask<N> {
        let mut m = self.0;
        for l in 0..N {
            m[l] = !m[l];
        }
        Mask(m)
    }
}

/// A 3-vector of lanes.
pub(crate) type V3<const N: usize> = [Lanes<N>; 3];
/// A row-major 3x3 matrix of lanes.
pub(crate) type M3<const N: usize> = [[Lanes<N>; 3]; 3];

/// Dot product, lane by lane.
#[inline(always)]
pub(crate) fn dot<const N: usize>(a: V3<N>, b: V3<N>) -> Lanes<N> {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Cross product, lane by lane.
#[inline(always)]
pub(crate) fn cross<const N: usize>(a: V3<N>, b: V3<N>) -> V3<N> {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

/// `a` where `m`, else `b`, per lane and coordinate.
#[inline(always)]
pub(crate) fn select3<const N: usize>(m: Mask<N>, a: V3<N>, b: V3<N>) -> V3<N> {
    [Lanes::select(m, a[0], b[0]), Lanes::select(m, a[1], b[1]), Lanes::select(m, a[2], b[2])]
}

/// `a b` for lane matrices (the same sums as [`super::mat3::mul`]).
#[inline(always)]
pub(crate) fn mul_lanes<const N: usize>(a: &M3<N>, b: &M3<N>) -> M3<N> {
    let z = Lanes::splat(0.0);
    let mut c = [[z; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            c[i][j] = a[i][0] * b[0][j] + a[i][1] * b[1][j] + a[i][2] * b[2][j];
        }
    }
    c
}

/// Determinant, lane by lane (the same sums as [`super::mat3::det`]).
#[inline(always)]
pub(crate) fn det<const N: usize>(a: &M3<N>) -> Lanes<N> {
    a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1]) - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
        + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0])
}

/// Lane matrices from `N` row-major matrices.
#[inline(always)]
pub(crate) fn to_lanes<const N: usize>(f: &[Mat3; N]) -> M3<N> {
    let z = Lanes::splat(0.0);
    let mut m = [[z; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            for l in 0..N {
                m[i][j].0[l] = f[l][i][j];
            }
        }
    }
    m
}

/// Lane `l` of a lane matrix.
#[inline(always)]
pub(crate) fn lane<const N: usize>(m: &M3<N>, l: usize) -> Mat3 {
    [[m[0][0].0[l], m[0][1].0[l], m[0][2].0[l]], [m[1][0].0[l], m[1][1].0[l], m[1][2].0[l]], [m[2][0].0[l], m[2][1].0[l], m[2][2].0[l]]]
}

/// Define `fn $name(args) -> ret { body }` so that the body (an expression on lane arithmetic)
/// is compiled for each listed x86-64 feature and the first one the CPU has is run, else the
/// portable build: the lanes become AVX-512 or AVX2 registers; the arithmetic is the same.
///
/// `simd_dispatch!(name, ["avx512f", "avx2"], fn(a: A, b: B) -> R { ... })`.
macro_rules! simd_dispatch {
    ($name:ident, [$($feature:tt),+], fn($($arg:ident: $ty:ty),*) -> $ret:ty $body:block) => {
        #[inline(always)]
        fn $name($($arg: $ty),*) -> $ret {
            #[cfg(target_arch = "x86_64")]
            {
                $crate::algorithms::physics::lanes::simd_dispatch!(@compiled_for [$($feature),+] ($($arg: $ty),*) -> $ret $body);
            }
            $body
        }
    };
    (@compiled_for [$feature:tt $(, $rest:tt)*] ($($arg:ident: $ty:ty),*) -> $ret:ty $body:block) => {
        if std::arch::is_x86_feature_detected!($feature) {
            #[target_feature(enable = $feature)]
            unsafe fn compiled($($arg: $ty),*) -> $ret $body
            // SAFETY: the CPU supports the feature (checked).
            return unsafe { compiled($($arg),*) };
        }
        $crate::algorithms::physics::lanes::simd_dispatch!(@compiled_for [$($rest),*] ($($arg: $ty),*) -> $ret $body);
    };
    (@compiled_for [] ($($arg:ident: $ty:ty),*) -> $ret:ty $body:block) => {};
}
pub(crate) use simd_dispatch;

/// [`simd_dispatch`] for the widest vector extension: AVX-512F, then AVX2.
macro_rules! with_widest_simd {
    ($name:ident, fn($($arg:ident: $ty:ty),*) -> $ret:ty $body:block) => {
        $crate::algorithms::physics::lanes::simd_dispatch!($name, ["avx512f", "avx2"], fn($($arg: $ty),*) -> $ret $body);
    };
}
pub(crate) use with_widest_simd;
