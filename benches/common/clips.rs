//! Caches made by code for the cache bench, beside the rapier3d bars (the soft-body cache):
//! a morph clip with several targets and an unwelded skinned clip. Pure functions of their
//! constants, so every run compares the same frames.

use blendsim::algorithms::frames::MemoryFrames;
use blendsim::algorithms::geometry::{Point, TriMesh};

/// A cache made by code: its rest surface, its frames (at `fps`) on the surface's vertices.
pub struct Clip {
    pub surface: TriMesh,
    pub frames: MemoryFrames,
    pub fps: f64,
}

/// A subdivided saddle of 39 x 39 = 1521 vertices (2 x 2 m) moved by 7 morph targets over
/// 200 frames at 30 fps. Each target is a displacement of compact support (radius 0.55 m,
/// so neighbours overlap and each moves about a quarter of the vertices) in its own direction;
/// each weight is its own raised cosine (periods 2.1 to 4.5 s, phases apart), as an artist's
/// morph clip: frame = base + sum of weight x target.
pub fn morph_clip() -> Clip {
    const N: usize = 39;
    const TARGETS: usize = 7;
    let (fps, frame_count) = (30.0, 200);
    let mut base = Vec::with_capacity(N * N);
    for i in 0..N {
        for j in 0..N {
            let (x, z) = (2.0 * i as f64 / (N - 1) as f64 - 1.0, 2.0 * j as f64 / (N - 1) as f64 - 1.0);
            base.push([x, 0.15 * (x * x - z * z), z]);
        }
    }
    let targets: Vec<Vec<Point>> = (0..TARGETS)
        .map(|k| {
            let angle = std::f64::consts::TAU * k as f64 / (TARGETS - 1) as f64;
            // Six around a ring, the last in the middle.
            let centre = if k + 1 == TARGETS { [0.0, 0.0] } else { [0.5 * angle.cos(), 0.5 * angle.sin()] };
            let dir = [0.3 * (k as f64).sin(), 1.0, 0.3 * (k as f64).cos()];
            let amplitude = 0.12 + 0.02 * k as f64;
            base.iter()
                .map(|p| {
                    let r2 = ((p[0] - centre[0]).powi(2) + (p[2] - centre[1]).powi(2)) / 0.55f64.powi(2);
                    let falloff = if r2 < 1.0 { (1.0 - r2).powi(2) } else { 0.0 };
                    dir.map(|d| amplitude * falloff * d)
                })
                .collect()
        })
        .collect();
    let times: Vec<f64> = (0..frame_count).map(|f| f as f64 / fps).collect();
    let frames = times
        .iter()
        .map(|&t| {
            let weights: Vec<f64> = (0..TARGETS)
                .map(|k| {
                    let period = 2.1 + 0.4 * k as f64;
                    0.5 - 0.5 * (std::f64::consts::TAU * t / period + 0.9 * k as f64).cos()
                })
                .collect();
            base.iter()
                .enumerate()
                .map(|(v, p)| {
                    let mut q = *p;
                    for (w, target) in weights.iter().zip(&targets) {
                        for (qc, dc) in q.iter_mut().zip(target[v]) {
                            *qc += w * dc;
                        }
                    }
                    q
                })
                .collect()
        })
        .collect();
    let mut triangles = Vec::with_capacity(2 * (N - 1) * (N - 1));
    for i in 0..N - 1 {
        for j in 0..N - 1 {
            let (a, b, c, d) = ((i * N + j) as u32, (i * N + j + 1) as u32, ((i + 1) * N + j + 1) as u32, ((i + 1) * N + j) as u32);
            // Counter-clockwise seen from +y.
            triangles.push([a, b, c]);
            triangles.push([a, c, d]);
        }
    }
    Clip { surface: TriMesh { positions: base, triangles, attributes: None }, frames: MemoryFrames { times, frames }, fps }
}

/// A rigid motion `p -> r p + t`.
#[derive(Clone, Copy)]
struct Motion {
    r: [[f64; 3]; 3],
    t: Point,
}

impl Motion {
    /// Rotation by `angle` about `axis` (a unit vector) through `pivot`.
    fn about(axis: Point, angle: f64, pivot: Point) -> Motion {
        let (s, c) = angle.sin_cos();
        let [x, y, z] = axis;
        let r = [
            [c + x * x * (1.0 - c), x * y * (1.0 - c) - z * s, x * z * (1.0 - c) + y * s],
            [y * x * (1.0 - c) + z * s, c + y * y * (1.0 - c), y * z * (1.0 - c) - x * s],
            [z * x * (1.0 - c) - y * s, z * y * (1.0 - c) + x * s, c + z * z * (1.0 - c)],
        ];
        let rp = rotate(&r, pivot);
        Motion { r, t: [pivot[0] - rp[0], pivot[1] - rp[1], pivot[2] - rp[2]] }
    }

    fn apply(&self, p: Point) -> Point {
        let q = rotate(&self.r, p);
        [q[0] + self.t[0], q[1] + self.t[1], q[2] + self.t[2]]
    }

    /// `self` after `inner`: the child's global motion from the parent's and its own.
    fn then_inner(&self, inner: &Motion) -> Motion {
        let r: [[f64; 3]; 3] = std::array::from_fn(|i| std::array::from_fn(|j| (0..3).map(|k| self.r[i][k] * inner.r[k][j]).sum::<f64>()));
        Motion { r, t: self.apply(inner.t) }
    }
}

fn rotate(r: &[[f64; 3]; 3], p: Point) -> Point {
    std::array::from_fn(|i| r[i][0] * p[0] + r[i][1] * p[1] + r[i][2] * p[2])
}

fn smoothstep(edge: f64, width: f64, y: f64) -> f64 {
    let s = ((y - edge) / width + 0.5).clamp(0.0, 1.0);
    s * s * (3.0 - 2.0 * s)
}

/// A capped tube (radius 0.1 m, 1.2 m along +y; 24 rings of 16 points and two cap centres,
/// 386 points, 768 triangles) skinned by linear blend skinning to a chain of 3 bones (joints at
/// y = 0, 0.4, 0.8; weights blend over 0.15 m at each inner joint), bending over 80 frames at
/// 30 fps, written as exporters write skinned meshes without an index buffer: a vertex per
/// triangle corner (2304 vertices), so the bake's weld (on by default) merges them back.
pub fn unwelded_skinned_clip() -> Clip {
    const RINGS: usize = 24;
    const AROUND: usize = 16;
    let (fps, frame_count, length, radius) = (30.0, 80, 1.2, 0.1);
    let mut points: Vec<Point> = Vec::with_capacity(RINGS * AROUND + 2);
    for ring in 0..RINGS {
        let y = length * ring as f64 / (RINGS - 1) as f64;
        for k in 0..AROUND {
            let a = std::f64::consts::TAU * k as f64 / AROUND as f64;
            points.push([radius * a.cos(), y, radius * a.sin()]);
        }
    }
    let (bottom, top) = (points.len() as u32, points.len() as u32 + 1);
    points.push([0.0, 0.0, 0.0]);
    points.push([0.0, length, 0.0]);
    let mut triangles: Vec<[u32; 3]> = Vec::new();
    let at = |ring: usize, k: usize| (ring * AROUND + k % AROUND) as u32;
    for ring in 0..RINGS - 1 {
        for k in 0..AROUND {
            // Outward normals: around +y, counter-clockwise seen from outside.
            triangles.push([at(ring, k), at(ring + 1, k), at(ring + 1, k + 1)]);
            triangles.push([at(ring, k), at(ring + 1, k + 1), at(ring, k + 1)]);
        }
    }
    for k in 0..AROUND {
        triangles.push([bottom, at(0, k), at(0, k + 1)]);
        triangles.push([top, at(RINGS - 1, k + 1), at(RINGS - 1, k)]);
    }
    let joints = [[0.0, 0.0, 0.0], [0.0, 0.4, 0.0], [0.0, 0.8, 0.0]];
    let weights: Vec<[f64; 3]> = points
        .iter()
        .map(|p| {
            let (s1, s2) = (smoothstep(0.4, 0.15, p[1]), smoothstep(0.8, 0.15, p[1]));
            [1.0 - s1, s1 - s2, s2]
        })
        .collect();
    let times: Vec<f64> = (0..frame_count).map(|f| f as f64 / fps).collect();
    let frames: Vec<Vec<Point>> = times
        .iter()
        .map(|&t| {
            let w = std::f64::consts::TAU * t / (frame_count as f64 / fps);
            let root = Motion::about([0.0, 0.0, 1.0], 0.3 * w.sin(), joints[0]);
            let mid = root.then_inner(&Motion::about([1.0, 0.0, 0.0], 0.8 * (w + 0.7).sin(), joints[1]));
            let tip = mid.then_inner(&Motion::about([0.0, 0.0, 1.0], 1.0 * (2.0 * w).sin(), joints[2]));
            let bones = [root, mid, tip];
            // Per triangle corner, as the file has them.
            triangles
                .iter()
                .flatten()
                .map(|&v| {
                    let p = points[v as usize];
                    let mut q = [0.0; 3];
                    for (bone, wb) in bones.iter().zip(weights[v as usize]) {
                        let m = bone.apply(p);
                        for (qc, mc) in q.iter_mut().zip(m) {
                            *qc += wb * mc;
                        }
                    }
                    q
                })
                .collect()
        })
        .collect();
    let positions = triangles.iter().flatten().map(|&v| points[v as usize]).collect();
    let corners = (0..triangles.len() as u32).map(|t| [3 * t, 3 * t + 1, 3 * t + 2]).collect();
    Clip { surface: TriMesh { positions, triangles: corners, attributes: None }, frames: MemoryFrames { times, frames }, fps }
}
