//! Simulated vertex caches from an independent simulator (rapier3d's FEM soft bodies, not our
//! solver): an elastic bar clamped at one end, released straight and swinging under gravity.
//!
//! The body is a structured tet grid (six tets per cell, Kuhn split: conforming, no TetGen
//! needed, the same mesh on every machine); the cache holds the bar's boundary surface as
//! `procedural::prism` numbers it (same size and divisions), so the surface mesh and the frames
//! share their vertex order. Frames are generated once per parameter set and kept under
//! Cargo's target scratch folder, so the suite does not re-simulate in every test.
//!
//! Used by the cache tests and the cache benchmark; the timing work releases the bar from a
//! bent pose ([`bar_released`]) and measures its period from the tip trajectory.
#![allow(dead_code)]

use std::io::{Read, Write};
use std::path::PathBuf;

use blendsim::algorithms::frames::MemoryFrames;
use blendsim::algorithms::geometry::{Point, TetMesh, TriMesh};
use blendsim::algorithms::procedural;

/// Bumped whenever the simulation code changes, so stale frames on disk are not reused.
const SIMULATOR_VERSION: u32 = 1;

/// An elastic bar along +x, clamped at x = 0, cross-section `size[1] x size[2]` centred on the
/// x axis' plane y, z >= 0, gravity along -y. SI units.
#[derive(Debug, Clone, PartialEq)]
pub struct BarSettings {
    /// Length (x), height (y, the bending direction), depth (z), in metres.
    pub size: [f64; 3],
    /// Grid cells per axis; the body has `6 * product` tets.
    pub divisions: [usize; 3],
    /// Young's modulus in Pa.
    pub young_modulus: f64,
    pub poisson_ratio: f64,
    /// kg/m³.
    pub density: f64,
    /// rapier's elastic damping ratio of the cells.
    pub damping_ratio: f64,
    /// m/s², along -y.
    pub gravity: f64,
    /// Seconds simulated; the cache has `duration * fps + 1` frames (the rest pose first).
    pub duration: f64,
    pub fps: f64,
    /// Simulation substeps per frame.
    pub substeps: usize,
}

impl Default for BarSettings {
    /// The test bar: 3 s at 60 fps, 2880 tets, about 1.9 Hz (Euler-Bernoulli), a tip
    /// sag of about 0.1 m (8% of the length).
    fn default() -> Self {
        BarSettings {
            size: [1.2, 0.16, 0.16],
            divisions: [30, 4, 4],
            young_modulus: 1.0e7,
            poisson_ratio: 0.3,
            density: 1000.0,
            damping_ratio: 0.05,
            gravity: 9.81,
            duration: 3.0,
            fps: 60.0,
            substeps: 4,
        }
    }
}

impl BarSettings {
    pub fn frame_count(&self) -> usize {
        (self.duration * self.fps).round() as usize + 1
    }

    /// First bending frequency (Hz) of the clamped-free Euler-Bernoulli beam in y:
    /// `(1.8751² / 2π L²) sqrt(E I / ρ A)`, `I / A = h² / 12`. Small-deflection theory: the
    /// simulated bar (finite thickness, shear, large swing, coarse tets) is close to it, not equal.
    pub fn euler_bernoulli_frequency(&self) -> f64 {
        let [l, h, _] = self.size;
        let beta = 1.875_104_068_711_961_f64;
        beta * beta / (std::f64::consts::TAU * l * l) * (self.young_modulus * h * h / (12.0 * self.density)).sqrt()
    }
}

impl BarSettings {
    /// Static tip deflection (m) of the clamped-free Euler-Bernoulli beam under its own weight:
    /// `ρ g A L⁴ / 8 E I`, with the same caveats as the frequency.
    pub fn euler_bernoulli_sag(&self) -> f64 {
        let [l, h, _] = self.size;
        self.density * self.gravity * l.powi(4) * 12.0 / (8.0 * self.young_modulus * h * h)
    }
}

/// A simulated bar and its cache.
#[derive(Debug, Clone)]
pub struct BarCache {
    pub settings: BarSettings,
    /// The simulated body at rest.
    pub body: TetMesh,
    /// The boundary surface at rest (`procedural::prism` order); `frames` holds its vertices.
    pub surface: TriMesh,
    /// `frames.frames[f][v]`: surface vertex `v` at frame `f`, `frames.times[f] = f / fps`.
    pub frames: MemoryFrames,
    /// Centroid of the free end face (x = length) at every frame.
    pub tip: Vec<Point>,
}

/// The bar with `settings`, simulated once per parameter set and then read from disk.
pub fn bar(settings: &BarSettings) -> BarCache {
    simulated(settings, None)
}

/// The bar's tet mesh at rest (the nodes [`bar_released`] takes a start pose of).
pub fn bar_body(settings: &BarSettings) -> TetMesh {
    geometry(settings).0
}

/// The bar with `settings` released at rest from the node positions `start` (a bent pose of
/// [`bar_body`]'s nodes; the clamped ones where they are at rest) instead of straight.
pub fn bar_released(settings: &BarSettings, start: &[Point]) -> BarCache {
    simulated(settings, Some(start))
}

fn simulated(settings: &BarSettings, start: Option<&[Point]>) -> BarCache {
    let mut key = format!("v{SIMULATOR_VERSION} {settings:?}");
    if let Some(start) = start {
        let bytes: Vec<u8> = start.iter().flatten().flat_map(|x| x.to_le_bytes()).collect();
        key += &format!(" released from {:016x}", fnv1a(&bytes));
    }
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("simulated-caches");
    let name = format!("bar-{:016x}.bin", fnv1a(key.as_bytes()));
    let path = dir.join(&name);
    let (body, surface, node_of_vertex) = geometry(settings);
    if let Some((frames, tip)) = std::fs::read(&path).ok().and_then(|bytes| decode(&bytes, &key, surface.positions.len())) {
        return BarCache { settings: settings.clone(), body, surface, frames, tip };
    }
    let (frames, tip) = simulate(settings, &body, &node_of_vertex, start);
    std::fs::create_dir_all(&dir).unwrap();
    // Write then rename: concurrent test binaries never read a half-written file. Each call
    // writes its own temporary file: two tests of one binary may simulate the same bar at
    // once (an empty target folder), and a shared one would be renamed away under the other.
    static CALLS: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let call = CALLS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let tmp = dir.join(format!("{name}.{}-{call}.tmp", std::process::id()));
    std::fs::File::create(&tmp).unwrap().write_all(&encode(&key, &frames, &tip)).unwrap();
    std::fs::rename(&tmp, &path).unwrap();
    BarCache { settings: settings.clone(), body, surface, frames, tip }
}

/// The structured tet grid, the prism surface, and for each surface vertex its grid node.
fn geometry(s: &BarSettings) -> (TetMesh, TriMesh, Vec<usize>) {
    let [_, ny, nz] = s.divisions;
    let node = |i: usize, j: usize, k: usize| (i * (ny + 1) + j) * (nz + 1) + k;
    // The Kuhn split of the grid (six tets per cell), node (i, j, k) numbered as `node` does.
    let body = procedural::box_tets(s.size, s.divisions);
    let surface = procedural::prism(s.size, s.divisions);
    let node_of_vertex = surface
        .positions
        .iter()
        .map(|p| {
            let c: [usize; 3] = std::array::from_fn(|d| (p[d] / s.size[d] * s.divisions[d] as f64).round() as usize);
            node(c[0], c[1], c[2])
        })
        .collect();
    (body, surface, node_of_vertex)
}

fn simulate(s: &BarSettings, body: &TetMesh, node_of_vertex: &[usize], start: Option<&[Point]>) -> (MemoryFrames, Vec<Point>) {
    use rapier3d::prelude::*;
    let mut world = PhysicsWorld::new();
    world.gravity = Vector::new(0.0, -s.gravity as Real, 0.0);
    world.integration_parameters.dt = (1.0 / s.fps) as Real;
    world.integration_parameters.num_solver_iterations = s.substeps;
    // The default 20 conjugate-gradient iterations leave a stiff bar's steps truncated.
    world.integration_parameters.soft_bodies.fem.max_linear_iterations = 200;
    world.integration_parameters.soft_bodies.fem.linear_tolerance = 1e-6;
    // Lumped masses: a quarter of each tet's mass to each of its nodes.
    let mut masses = vec![0.0f64; body.positions.len()];
    for t in 0..body.tets.len() {
        let m = body.signed_volume_at(&body.positions, t) * s.density / 4.0;
        for &n in &body.tets[t] {
            masses[n as usize] += m;
        }
    }
    let clamped: Vec<u32> = (0..body.positions.len() as u32).filter(|&n| body.positions[n as usize][0] == 0.0).collect();
    let builder = SoftBodyBuilder::new(body.positions.iter().map(|p| Vector::new(p[0] as Real, p[1] as Real, p[2] as Real)).collect())
        .cells(body.tets.clone())
        .cell_model(SoftBodyCellModel::Corotational)
        .material(SoftBodyMaterial {
            young_modulus: s.young_modulus as Real,
            poisson_ratio: s.poisson_ratio as Real,
            elastic_damping_ratio: s.damping_ratio as Real,
            ..Default::default()
        })
        .solver(SoftBodySolver::Fem)
        .masses(masses.iter().map(|&m| m as Real).collect())
        .pinned_particles(clamped)
        .no_surface_collider()
        .can_sleep(false);
    let handle = world.insert_soft_body(builder);
    if let Some(start) = start {
        let sb = &mut world.soft_bodies[handle];
        for (n, p) in start.iter().enumerate() {
            sb.set_particle_position(n, Vector::new(p[0] as Real, p[1] as Real, p[2] as Real));
        }
    }
    let tip_nodes: Vec<usize> = (0..body.positions.len()).filter(|&n| body.positions[n][0] == s.size[0]).collect();
    let (mut times, mut frames, mut tip) = (Vec::new(), Vec::new(), Vec::new());
    for f in 0..s.frame_count() {
        if f > 0 {
            world.step();
        }
        let sb = &world.soft_bodies[handle];
        let nodes: Vec<Point> = (0..body.positions.len())
            .map(|n| {
                let p = sb.particle_position(n);
                [p.x as f64, p.y as f64, p.z as f64]
            })
            .collect();
        assert!(nodes.iter().flatten().all(|x| x.is_finite()), "the bar simulation blew up at frame {f}");
        times.push(f as f64 / s.fps);
        frames.push(node_of_vertex.iter().map(|&n| nodes[n]).collect());
        let mut c = [0.0; 3];
        for &n in &tip_nodes {
            for d in 0..3 {
                c[d] += nodes[n][d] / tip_nodes.len() as f64;
            }
        }
        tip.push(c);
    }
    (MemoryFrames { times, frames }, tip)
}

/// 64-bit FNV-1a: a stable file name for a parameter set (the full key is checked on read).
fn fnv1a(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325u64, |h, &b| (h ^ b as u64).wrapping_mul(0x0100_0000_01b3))
}

/// Key length, key, frame count, vertex count (u64 LE), then per frame its time, tip and
/// vertices as f64 LE.
fn encode(key: &str, frames: &MemoryFrames, tip: &[Point]) -> Vec<u8> {
    let mut out = Vec::new();
    let vertices = frames.frames.first().map_or(0, Vec::len);
    for n in [key.len(), frames.frames.len(), vertices] {
        out.extend((n as u64).to_le_bytes());
    }
    out.extend(key.as_bytes());
    for (f, frame) in frames.frames.iter().enumerate() {
        out.extend(frames.times[f].to_le_bytes());
        for x in tip[f].iter().chain(frame.iter().flatten()) {
            out.extend(x.to_le_bytes());
        }
    }
    out
}

fn decode(bytes: &[u8], key: &str, vertices: usize) -> Option<(MemoryFrames, Vec<Point>)> {
    fn u64le(r: &mut &[u8]) -> Option<u64> {
        let mut b = [0u8; 8];
        r.read_exact(&mut b).ok()?;
        Some(u64::from_le_bytes(b))
    }
    fn f64le(r: &mut &[u8]) -> f64 {
        f64::from_bits(u64le(r).expect("length checked"))
    }
    let mut r = bytes;
    let (key_len, count, stored_vertices) = (u64le(&mut r)? as usize, u64le(&mut r)? as usize, u64le(&mut r)? as usize);
    if key_len != key.len() || stored_vertices != vertices || r.len() != key_len + count * 8 * (4 + 3 * vertices) {
        return None;
    }
    let (stored_key, mut rest) = r.split_at(key_len);
    if stored_key != key.as_bytes() {
        return None;
    }
    let (mut times, mut frames, mut tip) = (Vec::new(), Vec::new(), Vec::new());
    for _ in 0..count {
        times.push(f64le(&mut rest));
        tip.push([f64le(&mut rest), f64le(&mut rest), f64le(&mut rest)]);
        frames.push((0..vertices).map(|_| [f64le(&mut rest), f64le(&mut rest), f64le(&mut rest)]).collect());
    }
    Some((MemoryFrames { times, frames }, tip))
}
