//! The mass-spring blendshape model (Ma et al. 2012): targets in, blended shapes out.
//!
//! [`MassSpring::new`] builds the spring network once (structure, bending, internal and anchor
//! springs), finds every target's full configuration (interior nodes and anchor, see below),
//! records each spring's rest length in every target `r_q^j`, and analyses the stiffness
//! pattern. [`MassSpring::blend`] then takes convex weights `w`, gives each spring the rest
//! length `r̄_q = Σ_j w_j r_q^j` and the constant `k_q = 1 / r̄_q` (the paper's normalization
//! `k ∝ 1/r`, applied to the blended system's own rest length, so that a spring's strain, not
//! its length, sets its force), and returns the equilibrium.
//!
//! Boundary conditions ([`Boundary`]):
//! - `Fixed`: the listed vertices follow the linear blend of their target positions.
//! - `Anchor`: a few interior points tied to their nearest vertices (see [`super::anchor`]).
//!   Their positions in target `j` are solved for as the paper does, with the roles reversed:
//!   target `j`'s surface held, the anchor (and any interior node whose pose is not given)
//!   relaxed with target 0's rest lengths. The best-fit rigid motion `T_j` of the anchor
//!   (Kabsch) is its transform in target `j`, and `T_j` of the anchor's rest points is its pose
//!   there, so target `j` is exactly a zero-energy state. A blend interpolates the transforms
//!   (`T(w)`: slerp of the rotations about the anchor's centroid, linear translation; the
//!   weighted spherical mean for three or more targets), solves with the anchor held at its
//!   rest points in the anchor's own frame (every target is stored mapped by `T_j⁻¹`), and maps
//!   the result back by `T(w)`.
//!
//! Interior nodes of a body without given poses are placed in every target the same way
//! (target surface held, interior relaxed with target 0's rest lengths), starting from the
//! harmonic extension of the surface's displacement.
//!
//! Collisions: after each equilibrium, surface vertices deeper inside an obstacle than the
//! solver tolerance move to its surface and are held there, and the equilibrium is recomputed,
//! until none penetrates. Interior and anchor vertices are never held.
//!
//! Successive blends start from the previous equilibrium moved along the tangent of the family
//! of equilibria (one linear solve: how the equilibrium moves when the rest lengths and the
//! fixed vertices change), plus a second-order term when the last three weight vectors lie on
//! one line (the quadratic through the equilibrium before). A sequence of nearby weights
//! ([`MassSpring::blend_batch`], the in-betweens of an interval) then costs about two Newton
//! iterations per blend. A first blend, or one after [`MassSpring::reset_warm_start`], starts
//! from the linear blend (in the anchor's frame). Results depend on the start only to the
//! solver tolerance, and the same sequence of calls gives the same bytes.

use std::time::Instant;

use super::anchor;
use super::energy::SpringSystem;
use super::newton::{Newton, NewtonReport, NewtonSettings};
use super::obstacle::Obstacle;
use super::refine::median_edge;
use super::rigid::Rigid;
use super::springs::{Bending, SpringKind, Springs};
use crate::algorithms::geometry::{bbox_diagonal, norm, sub, Point, TetMesh};
use crate::support::budget::Budget;
use crate::support::error::{Error, Result};

/// Relative residual of the linear solves in a blend (its tangent and its Newton steps): the
/// Newton error shrinks by at least this factor per iteration on top of the quadratic rate.
/// Measured on the Man-size benchmark (36 steps): 1e-6 took 16.9 conjugate-gradient iterations
/// per step, 1e-3 10.3 with the same Newton iterations, 1e-2 13.6 (more Newton iterations).
const FORCING: f64 = 1e-3;

/// Relative residual of the tangent solve. The predictor's error in the soft modes (parts
/// turning about the anchor) is the solve's error amplified by the condition number: on the
/// Man-size benchmark 1e-3 left one more Newton iteration per step than 1e-6 (4 vs 3).
const TANGENT_FORCING: f64 = 1e-6;

/// The shapes to blend: one mesh in several poses.
#[derive(Debug, Clone, Copy)]
pub struct Targets<'a> {
    /// Surface vertex positions, one array per target, all of the same length and order.
    pub surface: &'a [Vec<Point>],
    /// The surface triangles, shared by every target.
    pub triangles: &'a [[u32; 3]],
    /// A tetrahedralization of target 0 whose first `surface[0].len()` nodes are the surface
    /// vertices at target 0's positions (what the TetGen bridge returns); its edges become
    /// internal springs and its other nodes interior vertices.
    pub body: Option<&'a TetMesh>,
    /// The body's node positions in every target, when known (for example a keyframe scene's
    /// fitted interior); otherwise each target's interior is relaxed (see the module docs).
    pub body_poses: Option<&'a [Vec<Point>]>,
}

/// What holds the body in place.
#[derive(Debug, Clone, PartialEq)]
pub enum Boundary {
    /// These vertices follow the linear blend of their target positions. They must hold the
    /// body: at least three, not on one line.
    Fixed(Vec<u32>),
    /// An anchor at these points (in target 0), or `None` for the default frame at the centre
    /// of mass (see the `anchor` module): at least three points, not on one line.
    Anchor(Option<Vec<Point>>),
}

/// Settings of the model and its solver. Lengths are relative to the bounding-box diagonal of
/// target 0's surface.
#[derive(Debug, Clone, PartialEq)]
pub struct Settings {
    /// Bending springs (default: the 2-ring, as the paper).
    pub bending: Bending,
    /// Newton stops when no vertex moves more than this (relative) in a step.
    pub tolerance: f64,
    /// Newton iterations per equilibrium at most.
    pub max_iterations: usize,
    /// The exact Hessian is used after a full Newton step shorter than this (relative).
    pub exact_below: f64,
    /// Spring constant of the anchor's own springs, as a multiple of the normal `1/r`.
    pub anchor_stiffness: f64,
    /// Vertices each anchor point is tied to.
    pub anchor_neighbours: usize,
    /// Largest accepted `|Σ w - 1|`.
    pub weight_tolerance: f64,
    /// Equilibria recomputed for collisions at most.
    pub max_collision_rounds: usize,
    /// The time the equilibria may take.
    pub budget: Budget,
}

impl Default for Settings {
    fn default() -> Settings {
        Settings {
            bending: Bending::TwoRing,
            tolerance: 1e-7,
            max_iterations: 100,
            exact_below: 1e-2,
            anchor_stiffness: 1e3,
            anchor_neighbours: 8,
            weight_tolerance: 1e-6,
            max_collision_rounds: 50,
            budget: Budget::default(),
        }
    }
}

/// The network and how it was built.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct ModelSummary {
    /// Number of targets.
    pub targets: usize,
    /// Surface vertices (numbered first in the system).
    pub surface_vertices: usize,
    /// The body's interior nodes (tet nodes that are not surface vertices); 0 without a body.
    pub interior_vertices: usize,
    /// Anchor points (0 with fixed vertices).
    pub anchor_points: usize,
    /// Springs of every kind.
    pub springs: usize,
    /// Springs on surface edges.
    pub structure_springs: usize,
    /// Springs between surface vertices two edges apart (see [`Bending`]).
    pub bending_springs: usize,
    /// Springs on tet edges of the body that are not surface edges.
    pub internal_springs: usize,
    /// The anchor's springs: to its nearest vertices and between its own points.
    pub anchor_springs: usize,
    /// Longest over median rest length, in target 0 (anchor frame springs excluded).
    pub longest_over_median: f64,
    /// The anchor's rotation angle in every target, degrees (0 without an anchor).
    pub anchor_degrees: Vec<f64>,
    /// Newton iterations spent placing interior nodes and the anchor in the targets.
    pub relax_iterations: usize,
    /// The fill-reducing ordering chosen for the stiffness matrix (nested dissection or
    /// minimum degree, on the vertex graph).
    pub ordering: String,
    /// Stored entries of the lower triangle of the stiffness matrix.
    pub matrix_nnz: usize,
    /// Stored entries of the Cholesky factor.
    pub factor_nnz: usize,
    /// Predicted floating-point operations of one numeric factorization in that ordering.
    pub predicted_flops: f64,
    /// Wall-clock seconds [`MassSpring::new`] took, placing the targets' interiors included.
    pub seconds: f64,
}

/// A blended shape.
#[derive(Debug, Clone, PartialEq)]
pub struct Blend {
    /// Every vertex: the surface's (first [`Blend::surface_count`]), then the body's interior
    /// nodes, then the anchor points.
    pub positions: Vec<Point>,
    /// How many of [`Blend::positions`] are surface vertices.
    pub surface_count: usize,
    /// How the equilibrium was found.
    pub report: BlendReport,
}

impl Blend {
    /// The surface vertices, in the input's order.
    pub fn surface(&self) -> &[Point] {
        &self.positions[..self.surface_count]
    }
}

/// How a blend was computed.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct BlendReport {
    /// One Newton solve per collision round (one when nothing collides).
    pub solves: Vec<NewtonReport>,
    /// Newton iterations over all rounds.
    pub iterations: usize,
    /// All the work: the warm start's tangent solve and every round's solve, summed
    /// (factorizations, conjugate-gradient iterations, seconds).
    pub work: NewtonReport,
    /// Surface vertices held on an obstacle, in the order they were caught.
    pub held: Vec<u32>,
    /// Final energy.
    pub energy: f64,
    /// Largest vertex move of the last Newton step, relative to the size.
    pub last_step: f64,
    /// Started from the previous blend (true) or from the linear blend (false).
    pub warm: bool,
    /// Wall-clock seconds of the whole blend (warm start and every collision round).
    pub seconds: f64,
}

/// The mass-spring model of a set of targets (see the module documentation).
pub struct MassSpring {
    settings: Settings,
    springs: Springs,
    /// Per spring: 1, or `anchor_stiffness` for the anchor's own springs.
    stiffness_scale: Vec<f64>,
    /// Rest lengths per target.
    rest: Vec<Vec<f64>>,
    /// Every vertex in every target, in the solving frame (mapped by `T_j⁻¹` with an anchor).
    poses: Vec<Vec<Point>>,
    /// Per target, the anchor frame's transform (identity without an anchor).
    frames: Vec<Rigid>,
    /// Boundary vertices (fixed vertices, or the anchor points).
    fixed: Vec<bool>,
    /// Vertices of the surface (used by a triangle): the only ones collisions may hold.
    on_surface: Vec<bool>,
    surface_count: usize,
    /// The boundary is an anchor (solved in its frame), not fixed vertices.
    anchored: bool,
    /// The bounding-box diagonal of target 0's surface: the unit of the relative settings.
    size: f64,
    newton: Newton,
    warm: Option<Warm>,
    summary: ModelSummary,
}

impl MassSpring {
    /// Build the model. Errors say what is wrong with the input and how to fix it.
    pub fn new(targets: &Targets, boundary: &Boundary, settings: &Settings) -> Result<MassSpring> {
        let start = Instant::now();
        check_settings(settings)?;
        let surface_count = check_targets(targets)?;
        let surface0 = &targets.surface[0];
        let size = bbox_diagonal(surface0);
        // Vertices of the system: surface, interior nodes, anchor points.
        let mut positions0: Vec<Point> = match targets.body {
            Some(body) => body.positions.clone(),
            None => surface0.clone(),
        };
        let body_count = positions0.len();
        let tets = targets.body.map_or(&[][..], |b| &b.tets[..]);
        let mut springs = Springs::build(body_count, targets.triangles, tets, settings.bending);
        let mut on_surface = vec![false; body_count];
        targets.triangles.iter().flatten().for_each(|&v| on_surface[v as usize] = true);
        let mut degree = vec![0usize; body_count];
        springs.ends.iter().flatten().for_each(|&v| degree[v as usize] += 1);
        if let Some(v) = degree.iter().position(|&d| d == 0) {
            let what = if v < surface_count { "surface vertex" } else { "body node" };
            return Err(Error::general(
                format!("{what} {v} belongs to no triangle or tet, so no spring holds it"),
                "remove loose vertices from the targets (or give a body whose tets use them)",
            ));
        }
        let mut fixed = vec![false; body_count];
        let anchor_points = match boundary {
            Boundary::Fixed(list) => {
                for &v in list {
                    if v as usize >= body_count {
                        return Err(Error::general(
                            format!("fixed vertex {v} does not exist: the targets have {body_count} vertices"),
                            "fix vertices by their 0-based index in the target meshes",
                        ));
                    }
                    fixed[v as usize] = true;
                }
                let points: Vec<Point> = (0..body_count).filter(|&v| fixed[v]).map(|v| positions0[v]).collect();
                if !spans_a_plane(&points) {
                    return Err(Error::general(
                        format!(
                            "the {} fixed vertices lie on one line (or there are fewer than 3), so the body can still turn about it",
                            points.len()
                        ),
                        "fix at least three vertices that are not on one line, or use an anchor instead",
                    ));
                }
                Vec::new()
            }
            Boundary::Anchor(points) => {
                let points = match points {
                    Some(p) => p.clone(),
                    None => {
                        let centre = anchor::centre_of_mass(surface0, targets.triangles);
                        anchor::tetrahedron_frame(centre, median_edge(&targets.surface[..1], targets.triangles))
                    }
                };
                if points.iter().any(|p| !p.iter().all(|c| c.is_finite())) || !spans_a_plane(&points) {
                    return Err(Error::general(
                        format!(
                            "the {} anchor points lie on one line (or there are fewer than 3), so the anchor's rotation is undetermined",
                            points.len()
                        ),
                        "give at least three anchor points that are not on one line (or use the default anchor)",
                    ));
                }
                let attachments = anchor::nearest(&points, &positions0, settings.anchor_neighbours);
                springs.add_anchor(&attachments);
                positions0.extend_from_slice(&points);
                fixed.resize(springs.vertex_count, true);
                on_surface.resize(springs.vertex_count, false);
                points
            }
        };
        let n = springs.vertex_count;
        let stiffness_scale: Vec<f64> =
            springs.kinds.iter().map(|&k| if k == SpringKind::AnchorFrame { settings.anchor_stiffness } else { 1.0 }).collect();
        let rest0 = springs.lengths(&positions0);
        check_rest_lengths(&springs, &rest0, 0)?;
        let mut newton = Newton::new(&springs, &positions0);
        let newton_settings = NewtonSettings {
            tolerance: settings.tolerance * size,
            max_iterations: settings.max_iterations,
            exact_below: settings.exact_below * size,
            start_exact: false,
            forcing: 1e-6,
            budget: settings.budget,
        };
        // Every target's full configuration.
        let anchor_first = body_count;
        let mut relaxed_free = vec![false; n];
        for v in surface_count..n {
            relaxed_free[v] = v >= anchor_first || targets.body_poses.is_none();
        }
        let held_in_relax: Vec<bool> = relaxed_free.iter().map(|f| !f).collect();
        let k0: Vec<f64> = rest0.iter().zip(&stiffness_scale).map(|(r, s)| s / r).collect();
        let mut rest = vec![rest0.clone()];
        let mut poses = vec![positions0.clone()];
        let centre = if anchor_points.is_empty() { [0.0; 3] } else { super::rigid::centroid(&anchor_points) };
        let mut frames = vec![Rigid::identity(centre)];
        let mut relax_iterations = 0;
        for j in 1..targets.surface.len() {
            let mut x = positions0.clone();
            x[..surface_count].copy_from_slice(&targets.surface[j]);
            if let Some(given) = targets.body_poses {
                x[..body_count].copy_from_slice(&given[j]);
            }
            if relaxed_free.iter().any(|&f| f) {
                // Start from the harmonic extension of the held vertices' displacement.
                let mut u: Vec<Point> = (0..n).map(|v| if relaxed_free[v] { [0.0; 3] } else { sub(x[v], positions0[v]) }).collect();
                newton.harmonic(&springs.ends, &k0, &mut u, &held_in_relax)?;
                for v in 0..n {
                    if relaxed_free[v] {
                        x[v] = crate::algorithms::geometry::add(positions0[v], u[v]);
                    }
                }
                let system = SpringSystem { ends: &springs.ends, rest: &rest0, stiffness: &k0 };
                let report = newton.solve(&system, &mut x, &held_in_relax, &newton_settings)?;
                relax_iterations += report.iterations;
                if !report.converged {
                    return Err(Error::general(
                        format!("placing the interior of target {j} did not converge in {} Newton iterations", settings.max_iterations),
                        "check that target's mesh for folds or self-intersections, or give the body's poses",
                    ));
                }
            }
            let frame = if anchor_points.is_empty() {
                Rigid::identity(centre)
            } else {
                let fit = Rigid::best_fit(&anchor_points, &x[anchor_first..]).ok_or_else(|| {
                    Error::general(
                        format!("the anchor collapsed onto a line in target {j}"),
                        "place the anchor points deeper inside the body, or use fixed vertices",
                    )
                })?;
                for (a, p) in anchor_points.iter().enumerate() {
                    x[anchor_first + a] = fit.apply(*p);
                }
                fit
            };
            let mut r = springs.lengths(&x);
            for q in 0..springs.len() {
                if springs.kinds[q] == SpringKind::AnchorFrame {
                    r[q] = rest0[q];
                }
            }
            check_rest_lengths(&springs, &r, j)?;
            rest.push(r);
            poses.push(x.iter().map(|&p| frame.apply_inverse(p)).collect());
            frames.push(frame);
        }
        // The anchor points are the same in every solving frame: use their rest points exactly.
        for pose in &mut poses {
            pose[anchor_first..].copy_from_slice(&anchor_points);
        }
        let mut sorted: Vec<f64> = (0..springs.len()).filter(|&q| springs.kinds[q] != SpringKind::AnchorFrame).map(|q| rest0[q]).collect();
        sorted.sort_unstable_by(f64::total_cmp);
        let summary = ModelSummary {
            targets: targets.surface.len(),
            surface_vertices: surface_count,
            interior_vertices: body_count - surface_count,
            anchor_points: anchor_points.len(),
            springs: springs.len(),
            structure_springs: springs.count(SpringKind::Structure),
            bending_springs: springs.count(SpringKind::Bending),
            internal_springs: springs.count(SpringKind::Internal),
            anchor_springs: springs.count(SpringKind::Anchor) + springs.count(SpringKind::AnchorFrame),
            longest_over_median: sorted.last().copied().unwrap_or(0.0) / sorted.get(sorted.len() / 2).copied().unwrap_or(1.0),
            anchor_degrees: frames.iter().map(|f| 2.0 * f.rotation.w.abs().min(1.0).acos().to_degrees()).collect(),
            relax_iterations,
            ordering: newton.ordering.to_string(),
            matrix_nnz: newton.matrix_nnz(),
            factor_nnz: newton.factor_nnz(),
            predicted_flops: newton.predicted_flops,
            seconds: start.elapsed().as_secs_f64(),
        };
        Ok(MassSpring {
            settings: settings.clone(),
            springs,
            stiffness_scale,
            rest,
            poses,
            frames,
            fixed,
            on_surface,
            surface_count,
            anchored: !anchor_points.is_empty(),
            size,
            newton,
            warm: None,
            summary,
        })
    }

    /// The network and how it was built.
    pub fn summary(&self) -> &ModelSummary {
        &self.summary
    }

    /// The spring network.
    pub fn springs(&self) -> &Springs {
        &self.springs
    }

    /// Rest lengths of every spring in target `j`.
    pub fn rest_lengths(&self, j: usize) -> &[f64] {
        &self.rest[j]
    }

    /// Every vertex of target `j` (surface, interior nodes as placed, anchor as fitted), in
    /// world coordinates: the zero-energy state of that target's rest lengths.
    pub fn target_pose(&self, j: usize) -> Vec<Point> {
        self.poses[j].iter().map(|&p| self.frames[j].apply(p)).collect()
    }

    /// Forget the previous blend: the next one starts from the linear blend.
    pub fn reset_warm_start(&mut self) {
        self.warm = None;
    }

    /// The equilibrium for convex `weights` (one per target), colliding with `obstacles`.
    /// Starts from the previous blend when there was one (see the module documentation).
    pub fn blend(&mut self, weights: &[f64], obstacles: &[Obstacle]) -> Result<Blend> {
        let start = Instant::now();
        check_weights(weights, self.rest.len(), self.settings.weight_tolerance)?;
        // Exactly convex from here on (a no-op for weights that already sum to 1 exactly).
        let total: f64 = weights.iter().sum();
        let weights: &[f64] = &weights.iter().map(|w| w / total).collect::<Vec<_>>();
        let obstacles: Vec<Obstacle> =
            obstacles.iter().enumerate().map(|(i, o)| o.validated(&format!("obstacle {}", i + 1))).collect::<Result<_>>()?;
        let n = self.springs.vertex_count;
        let blended_rest: Vec<f64> = (0..self.springs.len()).map(|q| blend_scalar(weights, |j| self.rest[j][q])).collect();
        // The start: the previous blend moved along the tangent, or the linear blend.
        let warm = self.warm.take();
        let is_warm = warm.is_some();
        let mut predictor = NewtonReport::default();
        let started: Option<Vec<Point>> = match &warm {
            Some(Warm { weights: previous_weights, solution: previous, before }) => {
                let tangent = self.tangent(previous_weights, previous, weights, &blended_rest, &mut predictor)?;
                let mut y: Vec<Point> = (0..n).map(|v| std::array::from_fn(|c| previous[v][c] + tangent[v][c])).collect();
                // Second order along a line of weights: the quadratic through the equilibrium
                // before, with the tangent at the previous one.
                if let Some((earlier_weights, earlier)) = before {
                    if let Some(h) = back_step(earlier_weights, previous_weights, weights) {
                        for v in 0..n {
                            for c in 0..3 {
                                y[v][c] += (earlier[v][c] - previous[v][c] + h * tangent[v][c]) / (h * h);
                            }
                        }
                    }
                }
                Some(y)
            }
            None => None,
        };
        // The Newton iterations stay near the start point: a factorization there serves them
        // all (the tangent above used the previous one, made near the previous equilibrium).
        self.newton.refresh();
        let stiffness: Vec<f64> = blended_rest.iter().zip(&self.stiffness_scale).map(|(r, s)| s / r).collect();
        let system = SpringSystem { ends: &self.springs.ends, rest: &blended_rest, stiffness: &stiffness };
        let frame = Rigid::blend(&self.frames, weights);
        let linear = |w: &[f64], v: usize| -> Point { std::array::from_fn(|c| blend_scalar(w, |j| self.poses[j][v][c])) };
        let boundary = |v: usize, w: &[f64]| if self.anchored { self.poses[0][v] } else { linear(w, v) };
        let mut y: Vec<Point> = match started {
            Some(y) => y,
            None => (0..n).map(|v| linear(weights, v)).collect(),
        };
        for v in 0..n {
            if self.fixed[v] {
                // Fixed vertices move linearly; anchor points stay at their rest points.
                y[v] = boundary(v, weights);
            }
        }
        // Obstacles in the solving frame.
        let local: Vec<Obstacle> = obstacles.iter().map(|o| o.mapped(|p| frame.apply_inverse(p), |d| frame.rotate_inverse(d))).collect();
        let settings = NewtonSettings {
            tolerance: self.settings.tolerance * self.size,
            max_iterations: self.settings.max_iterations,
            exact_below: self.settings.exact_below * self.size,
            start_exact: is_warm,
            forcing: FORCING,
            budget: self.settings.budget,
        };
        let mut held = Vec::new();
        let mut fixed = self.fixed.clone();
        let mut solves = Vec::new();
        loop {
            let report = self.newton.solve(&system, &mut y, &fixed, &settings)?;
            solves.push(report);
            if !report.converged {
                return Err(Error::general(
                    format!(
                        "the mass-spring equilibrium did not converge in {} Newton iterations (last step {:.3e} of the size)",
                        self.settings.max_iterations,
                        report.last_step / self.size
                    ),
                    "check the targets for folds or self-intersections; blends between very different targets may need intermediate weights",
                ));
            }
            let depth = settings.tolerance;
            let mut caught = 0;
            for v in 0..n {
                if !self.on_surface[v] || fixed[v] {
                    continue;
                }
                // The deepest obstacle wins when a vertex is inside several.
                let worst = local.iter().map(|o| (o.signed_distance(y[v]), o)).filter(|(d, _)| *d < -depth).min_by(|a, b| a.0.total_cmp(&b.0));
                if let Some((_, o)) = worst {
                    y[v] = o.project(y[v]);
                    fixed[v] = true;
                    held.push(v as u32);
                    caught += 1;
                }
            }
            if caught == 0 {
                break;
            }
            if solves.len() >= self.settings.max_collision_rounds {
                return Err(Error::general(
                    format!("surface vertices still entered the obstacles after {} collision rounds", solves.len()),
                    "move the obstacles out of the body, or raise the number of collision rounds",
                ));
            }
        }
        let last = *solves.last().expect("one solve at least");
        let mut work = predictor;
        solves.iter().for_each(|s| work.absorb(s));
        let report = BlendReport {
            iterations: solves.iter().map(|s| s.iterations).sum(),
            work,
            solves,
            held,
            energy: last.energy,
            last_step: last.last_step / self.size,
            warm: is_warm,
            seconds: start.elapsed().as_secs_f64(),
        };
        let positions = y.iter().map(|&p| frame.apply(p)).collect();
        let before = warm.map(|w| (w.weights, w.solution));
        self.warm = Some(Warm { weights: weights.to_vec(), solution: y, before });
        Ok(Blend { positions, surface_count: self.surface_count, report })
    }

    /// The first-order change of the equilibrium `previous` (for `previous_weights`) when the
    /// weights become `weights`. With `g(y, r̄) = 0` on the free vertices,
    /// `H dy = -(∂g/∂r̄ dr̄ + H_FB dy_B)`, where `dy_B` is the move of the fixed vertices; since
    /// `g_i = Σ_q s_q (l_q / r̄_q - 1) u_q` (with `k_q = s_q / r̄_q`),
    /// `∂g_i/∂r̄_q = -s_q d_q / r̄_q²`. One linear solve, preconditioned by the factorization made
    /// at the previous blend's start.
    fn tangent(
        &mut self,
        previous_weights: &[f64],
        previous: &[Point],
        weights: &[f64],
        rest: &[f64],
        report: &mut NewtonReport,
    ) -> Result<Vec<Point>> {
        let n = self.springs.vertex_count;
        let old_rest: Vec<f64> = (0..self.springs.len()).map(|q| blend_scalar(previous_weights, |j| self.rest[j][q])).collect();
        let old_stiffness: Vec<f64> = old_rest.iter().zip(&self.stiffness_scale).map(|(r, s)| s / r).collect();
        let system = SpringSystem { ends: &self.springs.ends, rest: &old_rest, stiffness: &old_stiffness };
        let linear = |w: &[f64], v: usize| -> Point { std::array::from_fn(|c| blend_scalar(w, |j| self.poses[j][v][c])) };
        // The boundary's move (none for an anchor, which stays at its rest points).
        let mut moved = vec![[0.0; 3]; n];
        if !self.anchored {
            for v in (0..n).filter(|&v| self.fixed[v]) {
                moved[v] = sub(linear(weights, v), linear(previous_weights, v));
            }
        }
        let mut rhs = vec![[0.0; 3]; n];
        system.hessian_apply(previous, &moved, super::energy::Definiteness::Exact, &mut rhs);
        for (q, &[i, j]) in self.springs.ends.iter().enumerate() {
            let change = rest[q] - old_rest[q];
            if change != 0.0 {
                let d = sub(previous[i as usize], previous[j as usize]);
                let f = -self.stiffness_scale[q] * change / (old_rest[q] * old_rest[q]);
                for c in 0..3 {
                    rhs[i as usize][c] += f * d[c];
                    rhs[j as usize][c] -= f * d[c];
                }
            }
        }
        for r in rhs.iter_mut() {
            *r = r.map(|c| -c);
        }
        report.absorb(&self.newton.linear_solve(&system, previous, &self.fixed, &mut rhs, TANGENT_FORCING)?);
        for v in (0..n).filter(|&v| self.fixed[v]) {
            rhs[v] = moved[v];
        }
        Ok(rhs)
    }

    /// Blend every weight vector in order, each starting from the one before.
    pub fn blend_batch(&mut self, weights: &[Vec<f64>], obstacles: &[Obstacle]) -> Result<Vec<Blend>> {
        weights.iter().map(|w| self.blend(w, obstacles)).collect()
    }
}

/// The previous blend (in the solving frame) and the one before it, to start the next from.
struct Warm {
    weights: Vec<f64>,
    solution: Vec<Point>,
    before: Option<(Vec<f64>, Vec<Point>)>,
}

/// `h` such that `previous - earlier = h (next - previous)` when the three weight vectors lie on
/// one line in that order, with `h` between 1/4 and 4 (a step of comparable size): then the
/// equilibria at `earlier` and `previous` and the tangent at `previous` define a quadratic
/// predictor of the next one.
fn back_step(earlier: &[f64], previous: &[f64], next: &[f64]) -> Option<f64> {
    let d: Vec<f64> = next.iter().zip(previous).map(|(a, b)| a - b).collect();
    let back: Vec<f64> = previous.iter().zip(earlier).map(|(a, b)| a - b).collect();
    let dd: f64 = d.iter().map(|x| x * x).sum();
    if dd == 0.0 {
        return None;
    }
    let h = back.iter().zip(&d).map(|(a, b)| a * b).sum::<f64>() / dd;
    let off: f64 = back.iter().zip(&d).map(|(a, b)| (a - h * b).powi(2)).sum::<f64>().sqrt();
    (off <= 1e-9 * dd.sqrt() * h.abs() && (0.25..=4.0).contains(&h)).then_some(h)
}

/// The linear blend `Σ_j w_j x^j` of vertex positions (the baseline mass-spring improves on).
pub fn linear_blend(targets: &[Vec<Point>], weights: &[f64]) -> Vec<Point> {
    (0..targets[0].len()).map(|v| std::array::from_fn(|c| blend_scalar(weights, |j| targets[j][v][c]))).collect()
}

/// `Σ_j w_j f(j)` in target order, skipping zero weights (so a blend with a zero weight is
/// bit-identical to the blend without that target).
fn blend_scalar(weights: &[f64], f: impl Fn(usize) -> f64) -> f64 {
    let mut s = 0.0;
    for (j, &w) in weights.iter().enumerate() {
        if w != 0.0 {
            s += w * f(j);
        }
    }
    s
}

/// Convex weights: one per target, each finite and non-negative, summing to 1.
pub fn check_weights(weights: &[f64], targets: usize, tolerance: f64) -> Result<()> {
    let list = || weights.iter().map(|w| w.to_string()).collect::<Vec<_>>().join(",");
    let fix = "give convex weights, one per target: each at least 0, all summing to 1 (e.g. 0.2,0.5,0.3)";
    if weights.len() != targets {
        return Err(Error::general(format!("{} weights ({}) for {targets} targets", weights.len(), list()), fix));
    }
    if let Some(j) = weights.iter().position(|w| !w.is_finite() || *w < 0.0) {
        return Err(Error::general(
            format!(
                "weight {} is {}: mass-spring blending takes convex weights only, so negative weights (extrapolation) are refused",
                j + 1,
                weights[j]
            ),
            fix,
        ));
    }
    let sum: f64 = weights.iter().sum();
    if (sum - 1.0).abs() > tolerance {
        return Err(Error::general(format!("the weights {} sum to {sum}, not 1", list()), fix));
    }
    Ok(())
}

fn check_settings(s: &Settings) -> Result<()> {
    let positive = [
        ("tolerance", s.tolerance),
        ("exact_below", s.exact_below),
        ("anchor_stiffness", s.anchor_stiffness),
        ("weight_tolerance", s.weight_tolerance),
    ];
    for (name, value) in positive {
        if value.is_nan() || value <= 0.0 || value.is_infinite() {
            return Err(Error::general(format!("mass-spring setting {name} = {value} is not a positive number"), format!("set {name} > 0")));
        }
    }
    for (name, value) in
        [("max_iterations", s.max_iterations), ("anchor_neighbours", s.anchor_neighbours), ("max_collision_rounds", s.max_collision_rounds)]
    {
        if value == 0 {
            return Err(Error::general(format!("mass-spring setting {name} is 0"), format!("set {name} to at least 1")));
        }
    }
    Ok(())
}

/// Returns the surface vertex count.
fn check_targets(t: &Targets) -> Result<usize> {
    let fail = |problem: String, fix: &str| Err(Error::general(problem, fix));
    let Some(first) = t.surface.first() else {
        return fail("no targets to blend".into(), "give at least one target mesh");
    };
    let n = first.len();
    if n == 0 || t.triangles.is_empty() {
        return fail("the targets have no vertices or no triangles".into(), "give triangle meshes");
    }
    for (j, s) in t.surface.iter().enumerate() {
        if s.len() != n {
            return fail(
                format!("target {j} has {} vertices but target 0 has {n}", s.len()),
                "every target must be the same mesh with moved vertices: export them from one object without remeshing",
            );
        }
        if let Some(v) = s.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
            return fail(format!("vertex {v} of target {j} is not finite"), "fix or delete the vertex in your modeling tool");
        }
    }
    if let Some((i, tri)) = t.triangles.iter().enumerate().find(|(_, tri)| tri.iter().any(|&v| v as usize >= n)) {
        return fail(format!("triangle {i} uses vertex {} but the targets have {n} vertices", tri.iter().max().unwrap()), "re-export the targets");
    }
    let size = bbox_diagonal(first);
    if let Some(body) = t.body {
        if body.positions.len() < n {
            return fail(
                format!("the body has {} nodes, fewer than the {n} surface vertices", body.positions.len()),
                "tetrahedralize target 0's surface with the TetGen bridge, which keeps the surface vertices as the first nodes",
            );
        }
        if let Some(v) = (0..n).find(|&v| norm(sub(body.positions[v], first[v])) > 1e-9 * size) {
            return fail(
                format!("body node {v} is at {:?}, not at surface vertex {v} of target 0 ({:?})", body.positions[v], first[v]),
                "tetrahedralize target 0's surface with the TetGen bridge, which keeps the surface vertices as the first nodes",
            );
        }
        if let Some(tet) = body.tets.iter().find(|tet| tet.iter().any(|&v| v as usize >= body.positions.len())) {
            return fail(format!("a tet uses node {} but the body has {} nodes", tet.iter().max().unwrap(), body.positions.len()), "re-run TetGen");
        }
        if let Some(poses) = t.body_poses {
            if poses.len() != t.surface.len() {
                return fail(format!("{} body poses for {} targets", poses.len(), t.surface.len()), "give one body pose per target, or none");
            }
            for (j, pose) in poses.iter().enumerate() {
                if pose.len() != body.positions.len() || (0..n).any(|v| pose[v] != t.surface[j][v]) {
                    return fail(
                        format!(
                            "body pose {j} does not have the body's {} nodes with the surface vertices of target {j} first",
                            body.positions.len()
                        ),
                        "give body poses whose first nodes are the targets' surface vertices",
                    );
                }
            }
        }
    } else if t.body_poses.is_some() {
        return fail("body poses were given without a body".into(), "give the body (tet mesh) too, or no poses");
    }
    Ok(n)
}

fn check_rest_lengths(springs: &Springs, rest: &[f64], target: usize) -> Result<()> {
    if let Some(q) = rest.iter().position(|&r| r.is_nan() || r <= 0.0) {
        let [i, j] = springs.ends[q];
        return Err(Error::general(
            format!("vertices {i} and {j} coincide in target {target}, so the spring between them has no rest length"),
            "weld or separate coincident vertices (and keep anchor points off the vertices)",
        ));
    }
    Ok(())
}

/// At least three points, not all on one line.
fn spans_a_plane(points: &[Point]) -> bool {
    let Some(&a) = points.first() else { return false };
    let Some(&b) = points.iter().max_by(|p, q| norm(sub(**p, a)).total_cmp(&norm(sub(**q, a)))) else { return false };
    let ab = sub(b, a);
    let l = norm(ab);
    l > 0.0 && points.iter().any(|&p| norm(crate::algorithms::geometry::cross(ab, sub(p, a))) > 1e-9 * l * l)
}
