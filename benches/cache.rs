//! Caches in, blendshapes out: on caches from an independent simulator (rapier3d FEM bars
//! swinging under gravity), the keys `keyframes = "auto"` chooses for tolerance 0.005, the
//! time to choose them and to fit, the error against the cache, and the bytes of the
//! blendshape clip against the full-frame cache and a PCA basis of the same error.
//!
//! `cargo bench --bench cache` (or `make bench`). Times are medians of repeated runs, printed
//! with the machine's load average: on a shared machine they are only as good as that number.
//!
//! Bytes: "f32" columns count the raw numbers a file must hold (blendshapes: base + sparse
//! targets as index + offset + f32 Hermite weight keys; full frame: every vertex of every frame;
//! PCA: mean + basis + per-frame weights), the glb/usda columns are our exporters' files. The
//! blendshapes are in the signed form (`[export] weights = "signed"`), whose weights are signed
//! like PCA's; the default Bernstein form costs one more shape per key with a velocity.
//! "passes" is frames read by the selection over the frame count; "held frames" the most
//! frames it held in memory at once.

#[path = "../tests/integration/common/bar.rs"]
mod bar;

use std::time::Instant;

use bar::{bar, BarCache, BarSettings};
use blendsim::cache::deviation::cache_diagonal;
use blendsim::cache::fit::{fit, FitSettings};
use blendsim::cache::keyframes::{select, AutoKeys, AutoSettings};
use blendsim::cache::{FrameSource, MemoryFrames};
use blendsim::clip::{BlendShapeClip, Weights};
use blendsim::internals::{glb, usda, FullFrame, Placement, UsdSettings};

const TOLERANCE: f64 = 0.005;

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn load() -> String {
    std::fs::read_to_string("/proc/loadavg").map(|l| l.split_whitespace().take(3).collect::<Vec<_>>().join(" ")).unwrap_or_default()
}

fn kb(bytes: usize) -> String {
    format!("{:.1}", bytes as f64 / 1024.0)
}

/// The smallest rank whose PCA reconstruction (mean + rank-r basis, f32 basis and weights)
/// meets `tolerance * diagonal` at every vertex of every frame; its rank, f32 bytes, max error.
fn pca_baseline(frames: &MemoryFrames, diagonal: f64) -> (usize, usize, f64) {
    let (f, n) = (frames.frames.len(), 3 * frames.frames[0].len());
    let mut mean = vec![0.0; n];
    for frame in &frames.frames {
        for (m, x) in mean.iter_mut().zip(frame.as_flattened()) {
            *m += x / f as f64;
        }
    }
    let x = faer::Mat::<f64>::from_fn(f, n, |r, c| frames.frames[r].as_flattened()[c] - mean[c]);
    let svd = x.thin_svd().expect("SVD converges");
    let (u, s, v) = (svd.U(), svd.S(), svd.V());
    let mut recon: Vec<Vec<f64>> = (0..f).map(|_| mean.clone()).collect();
    for r in 0..f.min(n) {
        // Add component r with f32-rounded basis and weights, as a file would store them.
        let basis: Vec<f64> = (0..n).map(|c| v[(c, r)] as f32 as f64).collect();
        for (i, row) in recon.iter_mut().enumerate() {
            let w = (u[(i, r)] * s[r]) as f32 as f64;
            for (x, b) in row.iter_mut().zip(&basis) {
                *x += w * b;
            }
        }
        let max = recon
            .iter()
            .zip(&frames.frames)
            .flat_map(|(row, frame)| row.chunks_exact(3).zip(frame).map(|(p, q)| ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt()))
            .fold(0.0, f64::max)
            / diagonal;
        if max <= TOLERANCE {
            let rank = r + 1;
            return (rank, 4 * (n + rank * n + f * rank), max);
        }
    }
    (f.min(n), 4 * (n + f * n), 0.0)
}

fn clip_f32_bytes(clip: &BlendShapeClip) -> usize {
    let targets: usize = clip.targets.iter().map(|t| 4 * t.indices.len() + 12 * t.offsets.len()).sum();
    12 * clip.base.len() + targets + 4 * clip.times.len() + 12 * clip.times.len() * clip.curves.len()
}

fn run(name: &str, cache: &BarCache) {
    let mut frames = cache.frames.clone();
    let settings = AutoSettings { tolerance: TOLERANCE, ..AutoSettings::default() };
    let (mut select_s, mut fit_s) = (Vec::new(), Vec::new());
    let mut auto: Option<AutoKeys> = None;
    for _ in 0..5 {
        let t = Instant::now();
        let a = select(&mut frames, &settings).expect("select");
        select_s.push(t.elapsed().as_secs_f64());
        let t = Instant::now();
        let tr = fit(&mut frames, &a.keys, &[], &FitSettings::default()).expect("fit");
        fit_s.push(t.elapsed().as_secs_f64());
        assert_eq!(tr, a.trajectory);
        if let Some(prev) = &auto {
            assert_eq!(prev.keys, a.keys, "same cache, same keys");
        }
        auto = Some(a);
    }
    let auto = auto.unwrap();
    let diagonal = cache_diagonal(&mut frames).unwrap();
    let clip = BlendShapeClip::new(&auto.trajectory, Weights::Signed);
    let triangles = &cache.surface.triangles;
    let placement = Placement { z_up: false, meters_per_unit: 1.0 };
    let usd = UsdSettings { name: name.replace(' ', "_"), fps: cache.settings.fps, up_axis: 'Y', meters_per_unit: 1.0 };
    let full = FullFrame {
        frames: (0..frames.frame_count() as i64).collect(),
        times: frames.times.clone(),
        points: frames.frames.iter().map(|f| f.iter().map(|p| [p[0] as f32, p[1] as f32, p[2] as f32]).collect()).collect(),
    };
    let bs_glb = glb::blendshapes(&clip, triangles, None, name, placement).len();
    let bs_usda = usda::blendshapes(&clip, triangles, None, &usd).len();
    let ff_glb = glb::full_frame(&full, triangles, None, name, placement).len();
    let ff_usda = usda::full_frame(&full, triangles, None, &usd).len();
    let ff_f32 = 12 * frames.frame_count() * frames.vertex_count();
    let (rank, pca_bytes, pca_max) = pca_baseline(&frames, diagonal);
    let (keys, n) = (auto.keys.len(), frames.frame_count());
    println!(
        "| {name} | {} | {} | {n} | {keys} | {:.3} | {:.4} | {:.1} | {} | {:.2e} | {:.2e} | {} | {} | {} | {} | {} | {} | {:.1}x | {:.1}x | {rank} | {} | {:.2e} | {} |",
        cache.body.tets.len(),
        frames.vertex_count(),
        median(select_s),
        median(fit_s),
        auto.stats.frame_reads as f64 / n as f64,
        auto.stats.window_frames,
        auto.deviation.max,
        auto.deviation.rms,
        kb(clip_f32_bytes(&clip)),
        kb(bs_glb),
        kb(bs_usda),
        kb(ff_f32),
        kb(ff_glb),
        kb(ff_usda),
        ff_glb as f64 / bs_glb as f64,
        ff_usda as f64 / bs_usda as f64,
        kb(pca_bytes),
        pca_max,
        load()
    );
}

fn main() {
    let cases: Vec<(&str, BarSettings)> = vec![
        ("bar 2 Hz", BarSettings::default()),
        ("soft bar 1 Hz", BarSettings { young_modulus: 2.5e6, ..BarSettings::default() }),
        ("bar 2 Hz, 6 s", BarSettings { duration: 6.0, ..BarSettings::default() }),
    ];
    println!("machine: {} threads, load average {}; tolerance {TOLERANCE} of the cache's bbox diagonal; sizes in KB", rayon::current_num_threads(), load());
    println!();
    println!("| cache | tets | vertices | frames | keys | select s | fit s | passes | held frames | max error | rms error | blendshape f32 | blendshape glb | blendshape usda | full-frame f32 | full-frame glb | full-frame usda | glb smaller | usda smaller | PCA rank | PCA f32 | PCA max error | load |");
    println!("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|");
    for (name, settings) in &cases {
        let t = Instant::now();
        let cache = bar(settings);
        eprintln!("{name}: cache ready in {:.1} s (simulated once, then read from target/)", t.elapsed().as_secs_f64());
        run(name, &cache);
    }
    println!();
    println!("load average after: {}", load());
}
