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
//!
//! A second table compares what a user would do instead, per cache: bakes through the whole
//! chain with `fit` in both `[export] basis` forms (principal, the default, and per-key) and
//! `spacetime` (keys, rank, bytes, max error against the cache, bake time per cache frame), the full-frame cache as glb / usda (`cache::write`: the glb's one-hot weights
//! are sparse, so it is smaller than our exporter's full-frame glb), gltfpack 1.3.0 on that glb
//! (`make deps-npm` installs it; bytes with `-cc`, error measured without `-c`), and a PCA basis
//! meeting the same tolerance (bytes computed).

#[path = "../tests/integration/common/bar.rs"]
mod bar;

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Instant;

use bar::{bar, BarCache, BarSettings};
use blendsim::algorithms::blendshape::clip::{BlendShapeClip, Weights};
use blendsim::algorithms::blendshape::fullframe::FullFrame;
use blendsim::algorithms::frames::deviation::cache_diagonal;
use blendsim::algorithms::frames::fit::{fit, FitSettings};
use blendsim::algorithms::frames::keyframes::{select, AutoKeys, AutoSettings};
use blendsim::algorithms::frames::{FrameSource, MemoryFrames};
use blendsim::formats::cache::{CacheOptions, VertexCache};
use blendsim::formats::export::glb::{self, Placement};
use blendsim::formats::export::usda::{self, UsdSettings};
use blendsim::formats::mesh::obj;
use blendsim::pipeline::scene::SceneFile;
use blendsim::support::output::Staging;
use blendsim::support::progress::Progress;

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
            .flat_map(|(row, frame)| {
                row.chunks_exact(3).zip(frame).map(|(p, q)| ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt())
            })
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
    let bs_glb = glb::blendshapes(&clip, glb::Surface::plain(triangles), name, placement, glb::Encoding::FLOAT).len();
    let bs_usda = usda::blendshapes(&clip, triangles, None, &usd).len();
    let ff_glb = glb::full_frame(&full, glb::Surface::plain(triangles), name, placement, glb::Encoding::FLOAT).len();
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

/// Bytes and max error (of the cache's bbox diagonal) of what a user would do with the
/// full-frame glb: gltfpack 1.3.0 (npm, in tests/checkers), with `-af 0` (no resampling,
/// keeps every frame) and at its defaults (30 Hz resampling); bytes with `-cc`, error measured
/// on the same settings without `-c` (meshopt compression is lossless on the quantized data and
/// our reader refuses it). gltfpack reorders vertices: they are matched to the cache's by
/// nearest rest position. None when gltfpack is not installed.
fn gltfpack(full_glb: &Path, cache: &BarCache, diagonal: f64) -> Option<Vec<(&'static str, u64, f64)>> {
    let bin = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/checkers/node_modules/.bin/gltfpack");
    if !bin.is_file() {
        return None;
    }
    let dir = full_glb.parent().unwrap();
    let mut rows = Vec::new();
    for (label, flags) in [("gltfpack -af 0 -cc", &["-af", "0"][..]), ("gltfpack -cc (30 Hz)", &[][..])] {
        let packed = |extra: &[&str], name: &str| {
            let out = dir.join(name);
            let status = Command::new(&bin)
                .arg("-i")
                .arg(full_glb)
                .arg("-o")
                .arg(&out)
                .args(flags)
                .args(extra)
                .stdout(Stdio::null())
                .stderr(Stdio::null())
                .status()
                .expect("run gltfpack");
            assert!(status.success(), "gltfpack {flags:?} {extra:?} failed");
            out
        };
        let bytes = std::fs::metadata(packed(&["-cc"], "packed_cc.glb")).unwrap().len();
        let plain = packed(&[], "packed.glb");
        let mut read =
            VertexCache::open(&plain, &CacheOptions { fps: Some(cache.settings.fps), ..CacheOptions::default() }).expect("read gltfpack's output");
        let rest = &cache.frames.frames[0];
        let mut first = vec![[0.0; 3]; read.frames.vertex_count()];
        read.frames.read_frame(0, &mut first).unwrap();
        // Its vertex v is the cache's vertex map[v].
        let map: Vec<usize> =
            first.iter().map(|p| (0..rest.len()).min_by(|&a, &b| dist(*p, rest[a]).total_cmp(&dist(*p, rest[b]))).unwrap()).collect();
        let mut got = vec![[0.0; 3]; first.len()];
        let mut max = 0.0f64;
        for (f, frame) in cache.frames.frames.iter().enumerate() {
            // Resampled output: evaluate at the cache's frame times.
            let t = cache.frames.times[f];
            let g =
                (0..read.frames.frame_count()).min_by(|&a, &b| (read.frames.time(a) - t).abs().total_cmp(&(read.frames.time(b) - t).abs())).unwrap();
            read.frames.read_frame(g, &mut got).unwrap();
            max = got.iter().zip(&map).map(|(p, &v)| dist(*p, frame[v])).fold(max, f64::max);
        }
        rows.push((label, bytes, max / diagonal));
    }
    Some(rows)
}

fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// One bake of the cache through the library's chain (as `blendsim bake`) in `[export] basis`:
/// seconds, keys, rank (principal), blendshape glb, usda and usdc bytes, max error against the
/// cache.
fn bake(dir: &Path, method: &str, weights: &str, basis: &str) -> (f64, usize, Option<usize>, u64, u64, u64, f64) {
    let physics = if method == "fit" { "" } else { "[material]\ngravity = [0.0, -9.81, 0.0]\ndamping = 0.5\n[solver]\nmax_iterations = 15\n" };
    let text = format!(
        "name = \"bar\"\n[cache]\npath = \"bar.pc2\"\nfps = 60\nrest = \"rest.obj\"\nkeyframes = \"auto\"\ntolerance = {TOLERANCE}\n{}{physics}[export]\nformats = [\"usda\", \"usdc\", \"glb\"]\nfull_frame = false\nweights = \"{weights}\"\nbasis = \"{basis}\"\n",
        if method == "fit" { "[solver]\nmethod = \"fit\"\n" } else { "" }
    );
    let scene_path = dir.join(format!("{method}-{weights}-{basis}.toml"));
    std::fs::write(&scene_path, text).unwrap();
    let out = dir.join(format!("out-{method}-{weights}-{basis}"));
    let _ = std::fs::remove_dir_all(&out);
    let t = Instant::now();
    let scene = SceneFile::load(&scene_path).unwrap_or_else(|e| panic!("{e}"));
    let mut staging = Staging::new(&out).unwrap();
    let report = blendsim::pipeline::stages::bake(&scene, None, &mut staging, &Progress::new(true)).unwrap_or_else(|e| panic!("{e}"));
    staging.commit().unwrap();
    let seconds = t.elapsed().as_secs_f64();
    let bytes = |ext: &str| std::fs::metadata(out.join(format!("bar.{ext}"))).unwrap().len();
    let c = report.cache.expect("a cache report");
    (seconds, c.keys.len(), report.rank, bytes("glb"), bytes("usda"), bytes("usdc"), c.error.max)
}

/// The comparison: per cache, fit and spacetime bakes (keys, bytes, max error, bake
/// time per cache frame) against the full-frame files, gltfpack on the full-frame glb, and PCA.
fn compare(name: &str, cache: &BarCache) {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("target/cache-compare").join(name.replace([' ', ','], "_"));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("rest.obj"), obj::write(&cache.surface)).unwrap();
    let fps = cache.settings.fps;
    blendsim::formats::cache::write(&dir.join("bar.pc2"), &cache.surface, &mut cache.frames.clone(), fps).unwrap();
    blendsim::formats::cache::write(&dir.join("full.glb"), &cache.surface, &mut cache.frames.clone(), fps).unwrap();
    blendsim::formats::cache::write(&dir.join("full.usda"), &cache.surface, &mut cache.frames.clone(), fps).unwrap();
    let frames = cache.frames.frame_count() as f64;
    let diagonal = cache_diagonal(&mut cache.frames.clone()).unwrap();
    let size = |p: &str| std::fs::metadata(dir.join(p)).unwrap().len();
    let (full_glb, full_usda) = (size("full.glb"), size("full.usda"));
    blendsim::formats::cache::write(&dir.join("full.usdc"), &cache.surface, &mut cache.frames.clone(), fps).unwrap();
    let full_usdc = size("full.usdc");
    let row = |what: &str, keys: String, glb: u64, usda: Option<u64>, usdc: Option<u64>, max: f64, ms: Option<f64>| {
        let smaller = |full: u64, x: Option<u64>| x.map_or("-".into(), |x| format!("{:.1}x", full as f64 / x as f64));
        println!(
            "| {name} | {what} | {keys} | {} | {} | {} | {:.2e} | {:.1}x | {} | {} | {} |",
            kb(glb as usize),
            usda.map_or("-".into(), |u| kb(u as usize)),
            usdc.map_or("-".into(), |u| kb(u as usize)),
            max,
            full_glb as f64 / glb as f64,
            smaller(full_usda, usda),
            smaller(full_usdc, usdc),
            ms.map_or("-".into(), |m| format!("{m:.2}"))
        )
    };
    row("full frame (the cache as glb / usda / usdc)", "-".into(), full_glb, Some(full_usda), Some(full_usdc), 0.0, None);
    for (method, weights, basis) in [
        ("fit", "bernstein", "principal"),
        ("fit", "signed", "principal"),
        ("fit", "bernstein", "keys"),
        ("fit", "signed", "keys"),
        ("spacetime", "bernstein", "keys"),
    ] {
        let (s, keys, rank, glb, usda, usdc, max) = bake(&dir, method, weights, basis);
        let form = match rank {
            Some(r) => format!("blendsim {method}, principal rank {r} ({weights} weights)"),
            None => format!("blendsim {method}, per-key shapes ({weights} weights)"),
        };
        row(&form, keys.to_string(), glb, Some(usda), Some(usdc), max, Some(1e3 * s / frames));
    }
    match gltfpack(&dir.join("full.glb"), cache, diagonal) {
        Some(rows) => rows.into_iter().for_each(|(label, bytes, max)| row(label, "-".into(), bytes, None, None, max, None)),
        None => println!("| {name} | gltfpack not installed (make deps-npm) | | | | | | | | |"),
    }
    let (rank, pca_bytes, pca_max) = pca_baseline(&cache.frames, diagonal);
    row(&format!("PCA rank {rank}, f32 (bytes computed)"), "-".into(), pca_bytes as u64, None, None, pca_max, None);
}

fn main() {
    let cases: Vec<(&str, BarSettings)> = vec![
        ("bar 2 Hz", BarSettings::default()),
        ("soft bar 1 Hz", BarSettings { young_modulus: 2.5e6, ..BarSettings::default() }),
        ("bar 2 Hz, 6 s", BarSettings { duration: 6.0, ..BarSettings::default() }),
    ];
    println!(
        "machine: {} threads, load average {}; tolerance {TOLERANCE} of the cache's bbox diagonal; sizes in KB",
        rayon::current_num_threads(),
        load()
    );
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
    println!("What a user would do instead (tolerance {TOLERANCE}; KB; \"smaller\" is the full-frame file of the same format over this; bake ms per cache frame, load average {}):", load());
    println!();
    println!("| cache | form | keys | glb KB | usda KB | usdc KB | max error | glb smaller | usda smaller | usdc smaller | bake ms/frame |");
    println!("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    for (name, settings) in cases.iter().take(2).filter(|(n, _)| std::env::var("BLENDSIM_BENCH_CACHE").map_or(true, |only| n.contains(only.as_str())))
    {
        compare(name, &bar(settings));
    }
    println!();
    println!("load average after: {}", load());
}
