//! Animated normals, measured: how far from the true normals of the animated surface each way
//! a consumer can get its normals is, and what morph-target NORMAL deltas would cost.
//!
//! `cargo test --release --test integration normals:: -- --nocapture` prints the table in the
//! README. At every frame, for every vertex (every split vertex where the surface has normal
//! creases), the angle between the true normal and:
//! - (a) the rest normals, which is what a renderer shows when the file carries `NORMAL` and no
//!   morph-target normals (three.js, engines: morphing moves positions only);
//! - (b) normals recomputed from the morphed positions on the file's vertices (three.js's
//!   `computeVertexNormals` on the glb's split vertices: area weighted, each seam copy seeing
//!   only its own triangles; Blender recomputes on its welded mesh, which is the truth);
//! - (c) glTF morph-target NORMAL deltas (each target's recomputed normals minus the base's),
//!   blended with the frame's weights and renormalized, as a shader does.
//!
//! The true normal is the area-weighted normal of the surface at that frame, over the corners
//! that share a rest normal (smooth across the surface, creased where the OBJ's `vn` crease).

use std::path::Path;

use blendsim::clip::BlendShapeClip;
use blendsim::mesh::attributes::split_at_seams;
use blendsim::mesh::{cross, norm, sub, Point};
use blendsim::stage::Animation;

use crate::common::assets::paper_scene;
use crate::common::cli::TempDir;
use crate::common::verify::library_animation;

/// Area-weighted normals of `triangles` over `vertices` (unit; zero where no area).
fn normals(points: &[Point], triangles: &[[u32; 3]], sources: &[u32]) -> Vec<Point> {
    let mut n = vec![[0.0; 3]; sources.len()];
    for t in triangles {
        let p = t.map(|i| points[sources[i as usize] as usize]);
        let f = cross(sub(p[1], p[0]), sub(p[2], p[0]));
        for &i in t {
            let x = &mut n[i as usize];
            *x = [x[0] + f[0], x[1] + f[1], x[2] + f[2]];
        }
    }
    n.iter().map(|x| unit(*x)).collect()
}

fn unit(x: Point) -> Point {
    let l = norm(x);
    if l > 0.0 { x.map(|c| c / l) } else { x }
}

fn degrees(a: Point, b: Point) -> f64 {
    (a[0] * b[0] + a[1] * b[1] + a[2] * b[2]).clamp(-1.0, 1.0).acos().to_degrees()
}

/// Angle errors in degrees: (max, 99th percentile, mean).
fn stats(mut e: Vec<f64>) -> (f64, f64, f64) {
    e.sort_by(f64::total_cmp);
    let mean = e.iter().sum::<f64>() / e.len() as f64;
    (*e.last().unwrap(), e[(e.len() - 1) * 99 / 100], mean)
}

/// One row: errors of (a), (b), (c), and the bytes of NORMAL deltas against the glb's.
struct Row {
    name: String,
    rest: (f64, f64, f64),
    recomputed: (f64, f64, f64),
    morph: (f64, f64, f64),
    delta_bytes: usize,
    position_bytes: usize,
}

fn measure(name: &str, anim: &Animation) -> Row {
    let mesh = &anim.mesh;
    let n = mesh.positions.len();
    let attributes = mesh.attributes.clone().unwrap_or_default();
    let identity: Vec<u32> = (0..n as u32).collect();
    // The truth's vertices: split where the OBJ's normals crease (not at UV seams).
    let creases = blendsim::mesh::attributes::CornerAttributes { uvs: vec![], uv_corners: vec![], ..attributes.clone() };
    let truth_split = if creases.normal_corners.is_empty() { None } else { Some(split_at_seams(&mesh.triangles, n, &creases)) };
    let (truth_tris, truth_sources) = truth_split.as_ref().map_or((&mesh.triangles, &identity), |s| (&s.triangles, &s.sources));
    // The glb's vertices: split at UV and normal seams.
    let file_split = (!attributes.uv_corners.is_empty() || !attributes.normal_corners.is_empty()).then(|| split_at_seams(&mesh.triangles, n, &attributes));
    let (file_tris, file_sources) = file_split.as_ref().map_or((&mesh.triangles, &identity), |s| (&s.triangles, &s.sources));
    // Each file vertex's truth vertex: the truth split's copy with the same point and normal.
    let truth_of: Vec<usize> = {
        let mut at = vec![usize::MAX; file_sources.len()];
        for (ft, tt) in file_tris.iter().zip(truth_tris.iter()) {
            for k in 0..3 {
                at[ft[k] as usize] = tt[k] as usize;
            }
        }
        at
    };

    let clip = BlendShapeClip::new(&anim.trajectory, anim.scene.export.weights);
    let base: Vec<Point> = clip.base.iter().map(|p| p.map(f64::from)).collect();
    let rest = normals(&base, file_tris, file_sources);
    let deltas: Vec<Vec<Point>> = clip
        .targets
        .iter()
        .map(|t| {
            let mut shape = base.clone();
            for (&i, o) in t.indices.iter().zip(&t.offsets) {
                shape[i as usize] = [shape[i as usize][0] + o[0] as f64, shape[i as usize][1] + o[1] as f64, shape[i as usize][2] + o[2] as f64];
            }
            normals(&shape, file_tris, file_sources).iter().zip(&rest).map(|(a, b)| sub(*a, *b)).collect()
        })
        .collect();
    // glTF stores a delta target like a position target: sparse when smaller (u16 indices).
    let target_bytes = |moved: usize| if moved * 14 < 12 * file_sources.len() { moved * 14 } else { 12 * file_sources.len() };
    let delta_bytes: usize = deltas.iter().map(|d| target_bytes(d.iter().filter(|x| **x != [0.0; 3]).count())).sum();
    let position_bytes: usize = clip.targets.iter().map(|t| target_bytes(t.indices.len())).sum();

    let (mut ea, mut eb, mut ec) = (Vec::new(), Vec::new(), Vec::new());
    for (_, t) in anim.trajectory.frames(anim.scene.fps) {
        let points = anim.trajectory.evaluate(t);
        let truth = normals(&points, truth_tris, truth_sources);
        let recomputed = normals(&points, file_tris, file_sources);
        let w = clip.weights_at(t);
        for v in 0..file_sources.len() {
            let truth = truth[truth_of[v]];
            ea.push(degrees(rest[v], truth));
            eb.push(degrees(recomputed[v], truth));
            let mut m = rest[v];
            for (d, &wi) in deltas.iter().zip(&w) {
                m = [m[0] + wi * d[v][0], m[1] + wi * d[v][1], m[2] + wi * d[v][2]];
            }
            ec.push(degrees(unit(m), truth));
        }
    }
    Row { name: name.into(), rest: stats(ea), recomputed: stats(eb), morph: stats(ec), delta_bytes, position_bytes }
}

#[test]
fn animated_normals_error_table() {
    let mut rows = Vec::new();
    let demo = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/demo/twist.toml");
    rows.push(measure("demo (twist)", &library_animation(&demo)));
    if let Some(dino) = paper_scene("dino") {
        rows.push(measure("DINO (paper)", &library_animation(&dino)));
    }
    let dir = TempDir::new("normals-prism");
    crate::texture::textured_prism(&dir.path, "");
    rows.push(measure("textured prism (seams, creases)", &library_animation(&dir.join("scene.toml"))));
    let f = |s: (f64, f64, f64)| format!("{:.2} / {:.2} / {:.3}", s.0, s.1, s.2);
    eprintln!("| scene | (a) rest normals | (b) recomputed on the file's vertices | (c) morph NORMAL deltas | NORMAL deltas vs POSITION targets (bytes) |");
    eprintln!("|---|---|---|---|---|");
    for r in &rows {
        eprintln!(
            "| {} | {} | {} | {} | {:.1} KB vs {:.1} KB (+{:.0}%) |",
            r.name,
            f(r.rest),
            f(r.recomputed),
            f(r.morph),
            r.delta_bytes as f64 / 1000.0,
            r.position_bytes as f64 / 1000.0,
            100.0 * r.delta_bytes as f64 / r.position_bytes as f64
        );
    }
    for r in &rows {
        // Recomputing on the welded mesh is the truth itself; the morph blend is an
        // approximation that must beat ignoring the motion.
        assert!(r.morph.2 <= r.rest.2, "{}: morph deltas {:?} vs rest {:?}", r.name, r.morph, r.rest);
        assert!(r.recomputed.2 <= r.rest.2, "{}", r.name);
    }
    assert!(rows[0].recomputed.0 < 1e-6, "no seams in the demo: recomputing is the truth");
}
