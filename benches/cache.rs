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
//! A second table compares what a user would do instead, per cache: the rapier3d bars (a
//! soft-body cache) and two caches made by code (`benches/common/clips.rs`: a morph clip of 7
//! overlapping targets on 1521 vertices, 200 frames; a skinned tube of 386 points and 3 bones
//! written with a vertex per triangle corner, 80 frames). Rows: bakes through the whole chain
//! with `fit` and the default `[export]` (the quantized glb, its max error read back from the
//! file, and `gltf_compression = "meshopt"`); on the bars also `fit` in both `[export] basis`
//! forms (principal and per-key) and `spacetime` (keys, rank, bytes, max error against the
//! cache, bake time per cache frame); the full-frame cache as glb / usda / usdc
//! (`cache::write`: the glb's one-hot weights are sparse, so it is smaller than our exporter's
//! full-frame glb); gltfpack 1.3.0 on that glb (`make deps-npm` installs it; bytes with `-cc`,
//! error measured without `-c`), and our default glb baked again with gltfpack's max error
//! as the tolerance (equal error); PCA at the tolerance and at our default glb's max error,
//! bytes as f32 (computed) and as those f32 compressed by zstd level 19 (on the distinct
//! vertices: a per-corner cache's copies dropped, as our weld drops them). A third table gives
//! the targets per cache: gltfpack `-cc` bytes over our default glb's (at least 2x, at equal or
//! lower max error: at the tolerance, and at gltfpack's error), our default glb over PCA+zstd at its error (at most 1.5x), and where our
//! glb's bytes go (indices, base, targets, animation, weld map). `BLENDSIM_BENCH_CACHE=text`
//! keeps the caches whose name contains it, in every table.
//!
//! A fourth table does the same for the keyframe scenes (the demo and the paper's, solved
//! once each): our default glb and its max error read back from the file against the f32
//! full-frame glb (`gltf_compression = "none"`: the solved trajectory at every frame, to 1e-7),
//! the meshopt glb, and gltfpack `-cc` on that f32 full-frame glb (error without `-c`). A
//! keyframe scene has no tolerance: its quantization budget is fixed (a tenth of the default
//! 0.005 of the diagonal) and no `[export]` setting changes it, so "ours at gltfpack's error"
//! is an estimate: the CUBICSPLINE writer's bytes at that error minus its bytes at the scene's
//! budget, added to our default (LINEAR) glb; the error is read back from that CUBICSPLINE file.
//! `BLENDSIM_BENCH_CACHE` picks these by name too ("demo twist", "paper spot", ...).

#[path = "../tests/integration/common/bar.rs"]
mod bar;
#[path = "common/clips.rs"]
mod clips;

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Instant;

use bar::{bar, BarCache, BarSettings};
use blendsim::algorithms::blendshape::clip::{BlendShapeClip, Weights};
use blendsim::algorithms::blendshape::fullframe::FullFrame;
use blendsim::algorithms::frames::deviation::cache_diagonal;
use blendsim::algorithms::frames::fit::{fit, FitSettings};
use blendsim::algorithms::frames::keyframes::{select, AutoKeys, AutoSettings};
use blendsim::algorithms::frames::{FrameSource, MemoryFrames};
use blendsim::algorithms::geometry::Axis;
use blendsim::algorithms::geometry::TriMesh;
use blendsim::formats::cache::{CacheOptions, VertexCache};
use blendsim::formats::export::glb::{self, Placement};
use blendsim::formats::export::texture;
use blendsim::formats::export::usda::{self, UsdSettings};
use blendsim::formats::mesh::obj;
use blendsim::pipeline::scene::{Format, GltfInterpolation, SceneFile};
use blendsim::pipeline::stages::Bake;
use blendsim::support::budget::Budget;
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

/// A PCA basis of a cache: mean + rank-r basis + per-frame weights.
struct Pca {
    rank: usize,
    /// The numbers as f32.
    f32_bytes: usize,
    /// Those f32 numbers, little-endian (mean, basis component by component, weights frame by
    /// frame), compressed by zstd level 19: what a file a user would write compresses to.
    zstd_bytes: usize,
    /// Of the cache's bbox diagonal.
    max: f64,
}

/// The smallest rank whose PCA reconstruction (mean + rank-r basis, f32 basis and weights)
/// meets `target * diagonal` at every vertex of every frame.
fn pca_baseline(frames: &MemoryFrames, diagonal: f64, target: f64) -> Pca {
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
    let mut max = f64::INFINITY;
    let mut rank = 0;
    for r in 0..f.min(n) {
        // Add component r with f32-rounded basis and weights, as a file would store them.
        let basis: Vec<f64> = (0..n).map(|c| v[(c, r)] as f32 as f64).collect();
        for (i, row) in recon.iter_mut().enumerate() {
            let w = (u[(i, r)] * s[r]) as f32 as f64;
            for (x, b) in row.iter_mut().zip(&basis) {
                *x += w * b;
            }
        }
        rank = r + 1;
        max = recon
            .iter()
            .zip(&frames.frames)
            .flat_map(|(row, frame)| {
                row.chunks_exact(3).zip(frame).map(|(p, q)| ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt())
            })
            .fold(0.0, f64::max)
            / diagonal;
        if max <= target {
            break;
        }
    }
    let mut numbers: Vec<f32> = mean.iter().map(|&m| m as f32).collect();
    for r in 0..rank {
        numbers.extend((0..n).map(|c| v[(c, r)] as f32));
    }
    for i in 0..f {
        numbers.extend((0..rank).map(|r| (u[(i, r)] * s[r]) as f32));
    }
    let bytes: Vec<u8> = numbers.iter().flat_map(|x| x.to_le_bytes()).collect();
    let zstd_bytes = zstd::bulk::compress(&bytes, 19).expect("zstd compresses").len();
    Pca { rank, f32_bytes: bytes.len(), zstd_bytes, max }
}

/// The cache on its distinct vertices: a vertex whose every frame equals an earlier vertex's
/// (a vertex per triangle corner) is dropped, as the bake's weld drops it, so PCA is not
/// charged for copies our files do not hold either.
fn distinct_vertices(frames: &MemoryFrames) -> MemoryFrames {
    let mut seen = std::collections::HashSet::new();
    let keep: Vec<usize> = (0..frames.frames[0].len())
        .filter(|&v| seen.insert(frames.frames.iter().flat_map(|frame| frame[v].map(f64::to_bits)).collect::<Vec<u64>>()))
        .collect();
    MemoryFrames { times: frames.times.clone(), frames: frames.frames.iter().map(|frame| keep.iter().map(|&v| frame[v]).collect()).collect() }
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
    let Pca { rank, f32_bytes: pca_bytes, max: pca_max, .. } = pca_baseline(&frames, diagonal, TOLERANCE);
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
/// our reader refuses it); last, the bytes of that run without `-c` (quantized only, as our
/// default glb). None when gltfpack is not installed.
fn gltfpack(full_glb: &Path, frames: &MemoryFrames, fps: f64, diagonal: f64) -> Option<Vec<(&'static str, u64, f64, u64)>> {
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
        rows.push((label, bytes, read_back_error(&plain, frames, fps, diagonal), std::fs::metadata(&plain).unwrap().len()));
    }
    Some(rows)
}

/// Max error (of the cache's bbox diagonal) of a glb clip read back as a cache against the
/// cache, at every cache frame (a resampled clip at its nearest frame). The file's vertices
/// may be reordered (gltfpack) or welded (ours): its vertex is matched to the cache's nearest
/// at the first frame; welded copies move alike, so any of them is the same.
fn read_back_error(glb: &Path, frames: &MemoryFrames, fps: f64, diagonal: f64) -> f64 {
    let mut read = VertexCache::open(glb, &CacheOptions { fps: Some(fps), ..CacheOptions::default() }).expect("read the glb back");
    let start = &frames.frames[0];
    let mut first = vec![[0.0; 3]; read.frames.vertex_count()];
    read.frames.read_frame(0, &mut first).unwrap();
    // Its vertex v is the cache's vertex map[v].
    let map: Vec<usize> =
        first.iter().map(|p| (0..start.len()).min_by(|&a, &b| dist(*p, start[a]).total_cmp(&dist(*p, start[b]))).unwrap()).collect();
    let mut got = vec![[0.0; 3]; first.len()];
    let mut max = 0.0f64;
    for (f, frame) in frames.frames.iter().enumerate() {
        let t = frames.times[f];
        let g = (0..read.frames.frame_count()).min_by(|&a, &b| (read.frames.time(a) - t).abs().total_cmp(&(read.frames.time(b) - t).abs())).unwrap();
        read.frames.read_frame(g, &mut got).unwrap();
        max = got.iter().zip(&map).map(|(p, &v)| dist(*p, frame[v])).fold(max, f64::max);
    }
    max / diagonal
}

fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// Where a glb's bytes go, from its JSON: the accessors of the indices, the base `POSITION`,
/// the other vertex attributes (UVs and normals, when there are any), the morph targets and the animation (key times and weights; each accessor's count times
/// its stride, sparse ones their indices and values), the rest of the BIN chunk (padding),
/// and the JSON chunk with, inside it, the weld map; in KB.
fn glb_parts(path: &Path) -> String {
    let bytes = std::fs::read(path).unwrap();
    let json_len = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
    let bin_len = bytes.get(20 + json_len..24 + json_len).map_or(0, |b| u32::from_le_bytes(b.try_into().unwrap()) as usize);
    let json: serde_json::Value = serde_json::from_slice(&bytes[20..20 + json_len]).unwrap();
    let component = |c: &serde_json::Value| match c.as_u64() {
        Some(5120 | 5121) => 1,
        Some(5122 | 5123) => 2,
        _ => 4,
    };
    let accessor_bytes = |a: &serde_json::Value| -> usize {
        let Some(a) = a.as_u64() else { return 0 };
        let acc = &json["accessors"][a as usize];
        let width = match acc["type"].as_str() {
            Some("SCALAR") => 1,
            Some("VEC2") => 2,
            Some("VEC3") => 3,
            Some("VEC4") => 4,
            _ => 16,
        } * component(&acc["componentType"]);
        let stride = acc["bufferView"].as_u64().and_then(|v| json["bufferViews"][v as usize]["byteStride"].as_u64()).map_or(width, |s| s as usize);
        let dense = if acc["bufferView"].is_u64() { acc["count"].as_u64().unwrap() as usize * stride } else { 0 };
        let sparse = &acc["sparse"];
        dense + sparse["count"].as_u64().map_or(0, |n| n as usize * (component(&sparse["indices"]["componentType"]) + width))
    };
    let (mut indices, mut base, mut targets, mut animation) = (0, 0, 0, 0);
    let primitives = json["meshes"][0]["primitives"].as_array().cloned().unwrap_or_default();
    for primitive in &primitives {
        indices += accessor_bytes(&primitive["indices"]);
        base += accessor_bytes(&primitive["attributes"]["POSITION"]);
        targets += primitive["targets"].as_array().into_iter().flatten().map(|t| accessor_bytes(&t["POSITION"])).sum::<usize>();
    }
    // Samplers may share their key times: count each accessor once.
    let mut seen = std::collections::HashSet::new();
    for sampler in json["animations"].as_array().into_iter().flatten().flat_map(|a| a["samplers"].as_array().cloned().unwrap_or_default()) {
        for a in [&sampler["input"], &sampler["output"]] {
            if seen.insert(a.as_u64()) {
                animation += accessor_bytes(a);
            }
        }
    }
    // The other vertex attributes (UVs, normals), shared by the primitives: each accessor once.
    let mut attributes = 0;
    let mut seen = std::collections::HashSet::new();
    for primitive in &primitives {
        for (name, a) in primitive["attributes"].as_object().into_iter().flatten() {
            if name != "POSITION" && seen.insert(a.as_u64()) {
                attributes += accessor_bytes(a);
            }
        }
    }
    let attributes_text = if attributes > 0 { format!("UVs and normals {}, ", kb(attributes)) } else { String::new() };
    let target_count = primitives.first().and_then(|p| p["targets"].as_array()).map_or(0, Vec::len);
    // The weld map: an accessor of its own in the BIN chunk, or the index list itself.
    let map = &json["meshes"][0]["extras"]["weldMap"];
    let indices_of = |p: &serde_json::Value| p["indices"].clone();
    let (weld_map, weld_text) = match map.as_u64() {
        None => (0, "none".to_string()),
        Some(_) if primitives.iter().any(|p| indices_of(p) == *map) => (0, "the index list".to_string()),
        Some(_) => (accessor_bytes(map), kb(accessor_bytes(map))),
    };
    format!(
        "indices {}, base {}, {attributes_text}{target_count} targets {}, animation {}, weld map {weld_text}, other BIN {}, JSON {}",
        kb(indices),
        kb(base),
        kb(targets),
        kb(animation),
        kb(bin_len.saturating_sub(indices + base + attributes + targets + animation + weld_map)),
        kb(json_len),
    )
}

/// One bake of the cache through the library's chain (as `blendsim bake`), `solver` and
/// `export` being the scene's lines in those tables: seconds, keys, rank (principal), the glb
/// and its bytes, usda and usdc bytes (when written), max error against the cache.
struct Baked {
    seconds: f64,
    keys: usize,
    rank: Option<usize>,
    glb: PathBuf,
    glb_bytes: u64,
    usda: Option<u64>,
    usdc: Option<u64>,
    max: f64,
}

fn bake(dir: &Path, fps: f64, tag: &str, solver: &str, export: &str, usd: bool, tolerance: f64) -> Baked {
    let formats = if usd { "[\"usda\", \"usdc\", \"glb\"]" } else { "[\"glb\"]" };
    let text = format!(
        "name = \"bar\"\n[cache]\npath = \"bar.pc2\"\nfps = {fps}\nrest = \"rest.obj\"\nkeyframes = \"auto\"\ntolerance = {tolerance}\n{solver}[export]\nformats = {formats}\nfull_frame = false\n{export}"
    );
    let scene_path = dir.join(format!("{tag}.toml"));
    std::fs::write(&scene_path, text).unwrap();
    let out = dir.join(format!("out-{tag}"));
    let _ = std::fs::remove_dir_all(&out);
    let t = Instant::now();
    let scene = SceneFile::load(&scene_path).unwrap_or_else(|e| panic!("{e}"));
    let mut staging = Staging::new(&out).unwrap();
    let report = blendsim::pipeline::stages::bake(&scene, None, &mut staging, &Progress::new(true)).unwrap_or_else(|e| panic!("{e}"));
    staging.commit().unwrap();
    let seconds = t.elapsed().as_secs_f64();
    let bytes = |ext: &str| std::fs::metadata(out.join(format!("bar.{ext}"))).unwrap().len();
    let c = report.cache.expect("a cache report");
    Baked {
        seconds,
        keys: c.keys.len(),
        rank: report.rank,
        glb: out.join("bar.glb"),
        glb_bytes: bytes("glb"),
        usda: usd.then(|| bytes("usda")),
        usdc: usd.then(|| bytes("usdc")),
        max: c.error.max,
    }
}

/// The targets for one cache: our default glb against gltfpack `-cc` and PCA+zstd at
/// the same max error.
struct Summary {
    name: String,
    ours: u64,
    ours_max: f64,
    meshopt: u64,
    gltfpack: Option<(u64, f64)>,
    /// Our default glb baked at gltfpack's max error (bytes, max error read back).
    at_gltfpack: Option<(u64, f64)>,
    pca: Pca,
    parts: String,
}

/// The comparison: per cache, bakes with the default `[export]` (quantized glb, and
/// meshopt) and, with `forms`, fit and spacetime bakes in each weights and basis form (keys,
/// bytes, max error, bake time per cache frame) against the full-frame files, gltfpack on the
/// full-frame glb, and PCA at the tolerance and at our default glb's max error.
fn compare(name: &str, surface: &TriMesh, cache: &MemoryFrames, fps: f64, forms: bool) -> Summary {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("target/cache-compare").join(name.replace([' ', ','], "_"));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("rest.obj"), obj::write(surface)).unwrap();
    for file in ["bar.pc2", "full.glb", "full.usda", "full.usdc"] {
        blendsim::formats::cache::write(&dir.join(file), surface, &mut cache.clone(), fps).unwrap();
    }
    let frames = cache.frame_count() as f64;
    let diagonal = cache_diagonal(&mut cache.clone()).unwrap();
    let size = |p: &str| std::fs::metadata(dir.join(p)).unwrap().len();
    let (full_glb, full_usda, full_usdc) = (size("full.glb"), size("full.usda"), size("full.usdc"));
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
    let fit = "[solver]\nmethod = \"fit\"\n";
    let ours = bake(&dir, fps, "default", fit, "", false, TOLERANCE);
    // The report's max error is the fit's; the file's (quantized) is read back.
    let ours_max = read_back_error(&ours.glb, cache, fps, diagonal);
    let rank = ours.rank.map_or("per-key shapes".into(), |r| format!("principal rank {r}"));
    row(
        &format!("blendsim fit, default [export] (quantized glb, {rank}; error read back)"),
        ours.keys.to_string(),
        ours.glb_bytes,
        None,
        None,
        ours_max,
        Some(1e3 * ours.seconds / frames),
    );
    let meshopt = bake(&dir, fps, "meshopt", fit, "gltf_compression = \"meshopt\"\n", false, TOLERANCE);
    row(
        "blendsim fit, gltf_compression = \"meshopt\"",
        meshopt.keys.to_string(),
        meshopt.glb_bytes,
        None,
        None,
        ours_max,
        Some(1e3 * meshopt.seconds / frames),
    );
    if forms {
        let physics = "[material]\ngravity = [0.0, -9.81, 0.0]\ndamping = 0.5\n[solver]\nmax_iterations = 15\n";
        for (method, weights, basis) in [
            ("fit", "bernstein", "principal"),
            ("fit", "signed", "principal"),
            ("fit", "bernstein", "keys"),
            ("fit", "signed", "keys"),
            ("spacetime", "bernstein", "keys"),
        ] {
            let solver = if method == "fit" { fit } else { physics };
            let export = format!("weights = \"{weights}\"\nbasis = \"{basis}\"\n");
            let b = bake(&dir, fps, &format!("{method}-{weights}-{basis}"), solver, &export, true, TOLERANCE);
            let form = match b.rank {
                Some(r) => format!("blendsim {method}, principal rank {r} ({weights} weights)"),
                None => format!("blendsim {method}, per-key shapes ({weights} weights)"),
            };
            row(&form, b.keys.to_string(), b.glb_bytes, b.usda, b.usdc, b.max, Some(1e3 * b.seconds / frames));
        }
    }
    let packed = gltfpack(&dir.join("full.glb"), cache, fps, diagonal);
    match &packed {
        Some(rows) => rows.iter().for_each(|(label, bytes, max, _)| row(label, "-".into(), *bytes, None, None, *max, None)),
        None => println!("| {name} | gltfpack not installed (make deps-npm) | | | | | | | | |"),
    }
    // Equal error: our default glb baked with gltfpack's (defaults) max error as the tolerance,
    // its error read back from the file.
    let at_gltfpack = packed.as_ref().and_then(|rows| rows.last()).map(|&(_, _, max, _)| {
        let b = bake(&dir, fps, "at-gltfpack-error", fit, "", false, max);
        let b_max = read_back_error(&b.glb, cache, fps, diagonal);
        let rank = b.rank.map_or("per-key shapes".into(), |r| format!("principal rank {r}"));
        row(
            &format!("blendsim fit, default [export], tolerance {max:.2e} (gltfpack's error; {rank}; error read back)"),
            b.keys.to_string(),
            b.glb_bytes,
            None,
            None,
            b_max,
            Some(1e3 * b.seconds / frames),
        );
        (b.glb_bytes, b_max)
    });
    let distinct = distinct_vertices(cache);
    let on =
        if distinct.vertex_count() < cache.vertex_count() { format!(" on the {} distinct vertices", distinct.vertex_count()) } else { String::new() };
    let pca = pca_baseline(&distinct, diagonal, TOLERANCE);
    row(&format!("PCA rank {}{on}, f32 (bytes computed)", pca.rank), "-".into(), pca.f32_bytes as u64, None, None, pca.max, None);
    let pca = pca_baseline(&distinct, diagonal, ours_max);
    row(&format!("PCA at our glb's error, rank {}{on}, f32 (bytes computed)", pca.rank), "-".into(), pca.f32_bytes as u64, None, None, pca.max, None);
    row(&format!("PCA at our glb's error, rank {}{on}, f32 + zstd -19", pca.rank), "-".into(), pca.zstd_bytes as u64, None, None, pca.max, None);
    Summary {
        name: name.into(),
        ours: ours.glb_bytes,
        ours_max,
        meshopt: meshopt.glb_bytes,
        // gltfpack at its defaults, as a user runs it.
        gltfpack: packed.and_then(|rows| rows.last().map(|&(_, bytes, max, _)| (bytes, max))),
        at_gltfpack,
        pca,
        parts: glb_parts(&ours.glb),
    }
}

/// One keyframe scene against gltfpack: the bytes of our default and meshopt glb and of the
/// f32 full-frame glb, our default glb's max error, gltfpack's rows (as [`gltfpack`]), and
/// where our glb's bytes go.
struct SceneSummary {
    name: String,
    frames: usize,
    vertices: usize,
    ours: u64,
    ours_max: f64,
    meshopt: u64,
    full_f32: u64,
    packed: Option<Vec<(&'static str, u64, f64, u64)>>,
    /// Estimated bytes of our default glb at gltfpack `-af 0`'s max error, and the error read
    /// back from the CUBICSPLINE file the estimate writes.
    at_packed: Option<(u64, f64)>,
    parts: String,
    solve_s: f64,
}

/// Solve `toml` once (as `blendsim bake`), then export its glb three ways: the default,
/// meshopt, and f32 with the full-frame glb (the reference the errors are measured against,
/// and gltfpack's input).
fn keyframe_scene(name: &str, toml: &Path) -> SceneSummary {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("target/cache-compare/scenes").join(name.replace(' ', "_"));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let scene = SceneFile::load(toml).unwrap_or_else(|e| panic!("{e}"));
    let t = Instant::now();
    let animation = Bake::new(&scene, &Progress::new(true)).animation().unwrap_or_else(|e| panic!("{e}"));
    let solve_s = t.elapsed().as_secs_f64();
    let budget = Budget::new(None, None);
    let export = |tag: &str, compression: glb::Compression, full_frame: bool, interpolation: GltfInterpolation| -> PathBuf {
        let mut a = animation.clone();
        a.scene.export.gltf_interpolation = interpolation;
        a.scene.export.formats = vec![Format::Glb];
        a.scene.export.full_frame = full_frame;
        a.scene.export.gltf_compression = compression;
        let out = dir.join(tag);
        let mut staging = Staging::new(&out).unwrap();
        blendsim::pipeline::stages::export(&a, &budget, &mut staging).unwrap_or_else(|e| panic!("{e}"));
        staging.commit().unwrap();
        out
    };
    let file = |out: &Path, suffix: &str| out.join(format!("{}{suffix}.glb", animation.scene.name));
    let bytes = |p: &Path| std::fs::metadata(p).unwrap().len();
    let linear = GltfInterpolation::Linear;
    let ours = file(&export("default", glb::Compression::default(), false, linear), "");
    let meshopt = file(&export("meshopt", glb::Compression::Meshopt, false, linear), "");
    let full = file(&export("f32", glb::Compression::None, true, linear), ".full");
    let fps = animation.scene.fps;
    let mut read = VertexCache::open(&full, &CacheOptions { fps: Some(fps), ..CacheOptions::default() }).expect("read the f32 full-frame glb");
    let mut truth = MemoryFrames { times: Vec::new(), frames: Vec::new() };
    for f in 0..read.frames.frame_count() {
        let mut points = vec![[0.0; 3]; read.frames.vertex_count()];
        read.frames.read_frame(f, &mut points).unwrap();
        truth.times.push(read.frames.time(f));
        truth.frames.push(points);
    }
    let diagonal = cache_diagonal(&mut truth.clone()).unwrap();
    let packed = gltfpack(&full, &truth, fps, diagonal);
    // Ours at gltfpack `-af 0`'s error: no `[export]` setting sets a keyframe scene's
    // quantization budget, and the LINEAR writer is the crate's own; the CUBICSPLINE writer
    // (public, same grid rules for the base and the targets) is run at the scene's budget (the
    // export stage) and at gltfpack's error, and the difference is added to our default glb.
    let at_packed = packed.as_ref().map(|rows| {
        let cubic_default = bytes(&file(&export("cubic", glb::Compression::default(), false, GltfInterpolation::Cubicspline), ""));
        let (clip, _) = blendsim::pipeline::stages::blendshape_clip(&animation, None, &budget).unwrap_or_else(|e| panic!("{e}"));
        let attributes = animation.mesh.attributes.as_ref();
        let textures = texture::load(attributes.map_or(&[][..], |a| &a.textures), &budget).unwrap_or_else(|e| panic!("{e}"));
        let surface = glb::Surface {
            triangles: &animation.mesh.triangles,
            attributes,
            textures: &textures,
            morph_normals: false,
            weld_map: animation.weld_map(),
        };
        let meters = animation.scene.meters_per_unit();
        let placement = Placement { z_up: animation.scene.export.up_axis == Axis::Z, meters_per_unit: meters };
        // The read-back error is of the diagonal in the file's meters; the budget is in scene units.
        let encoding = glb::Encoding { compression: glb::Compression::Quantize, max_error: rows[0].2 * diagonal / meters };
        let path = dir.join("cubic-at-gltfpack.glb");
        std::fs::write(&path, glb::blendshapes(&clip, surface, &animation.scene.name, placement, encoding).to_vec()).unwrap();
        ((bytes(&ours) + bytes(&path)).saturating_sub(cubic_default), read_back_error(&path, &truth, fps, diagonal))
    });
    SceneSummary {
        name: name.into(),
        frames: truth.frame_count(),
        vertices: truth.vertex_count(),
        ours: bytes(&ours),
        ours_max: read_back_error(&ours, &truth, fps, diagonal),
        meshopt: bytes(&meshopt),
        full_f32: bytes(&full),
        packed,
        at_packed,
        parts: glb_parts(&ours),
        solve_s,
    }
}

/// The demo and the paper scenes against gltfpack `-cc` (the targets, as the last
/// table's for caches).
fn keyframe_scenes(only: &dyn Fn(&str) -> bool) {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures");
    let scenes: Vec<(String, PathBuf)> = std::iter::once(("demo twist".to_string(), root.join("demo/twist.toml")))
        .chain(["ball", "dino", "spot", "stretch", "twist"].map(|s| (format!("paper {s}"), root.join(format!("paper/{s}.toml")))))
        .filter(|(name, _)| only(name))
        .collect();
    if scenes.is_empty() {
        return;
    }
    let summaries: Vec<SceneSummary> = scenes.iter().map(|(name, toml)| keyframe_scene(name, toml)).collect();
    println!();
    println!("Keyframe scenes: gltfpack -cc on the f32 full-frame glb over our default glb (at least 2x, at equal or lower max error), gltfpack at its defaults (30 Hz resampling) and with -af 0 (every frame); max error of the bbox diagonal over every frame, against the f32 full-frame glb; KB; load average {}:", load());
    println!();
    println!("| scene | frames x vertices | solve s (one run) | full-frame f32 glb | default glb | its max error | meshopt glb | gltfpack -cc (error) | / ours | >= 2x at <= error | gltfpack -af 0 -cc (error) | / ours | >= 2x at <= error | gltfpack -af 0 without -c | ours at gltfpack -af 0's error (estimate; error read back) | gltfpack -af 0 -cc / that | >= 2x at <= error | our default glb holds |");
    println!("|---|---:|---:|---:|---:|---:|---:|---:|---:|---|---:|---:|---|---:|---:|---:|---|---|");
    for s in &summaries {
        let yes = |ok: bool| if ok { "yes" } else { "**no**" };
        let against = |bytes: u64, max: f64| {
            let ratio = bytes as f64 / s.ours as f64;
            let ok = format!("{} (error {})", yes(ratio >= 2.0 && s.ours_max <= max), if s.ours_max <= max { "lower" } else { "higher" });
            format!("{} ({max:.2e}) | {ratio:.2}x | {ok}", kb(bytes as usize))
        };
        let packed = match &s.packed {
            Some(rows) => {
                let (af0, defaults) = (rows[0], rows[rows.len() - 1]);
                let (at, at_ratio, at_ok) = match s.at_packed {
                    Some((bytes, max)) => {
                        let ratio = af0.1 as f64 / bytes as f64;
                        (format!("{} ({max:.2e})", kb(bytes as usize)), format!("{ratio:.2}x"), yes(ratio >= 2.0 && max <= af0.2))
                    }
                    None => ("-".into(), "-".into(), "-"),
                };
                format!("{} | {} | {} | {at} | {at_ratio} | {at_ok}", against(defaults.1, defaults.2), against(af0.1, af0.2), kb(af0.3 as usize))
            }
            None => "gltfpack not installed (make deps-npm) | | | | | | | | | |".into(),
        };
        println!(
            "| {} | {} x {} | {:.1} | {} | {} | {:.2e} | {} | {packed} | {} |",
            s.name,
            s.frames,
            s.vertices,
            s.solve_s,
            kb(s.full_f32 as usize),
            kb(s.ours as usize),
            s.ours_max,
            kb(s.meshopt as usize),
            s.parts
        );
    }
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
    let only = |name: &str| std::env::var("BLENDSIM_BENCH_CACHE").map_or(true, |only| name.contains(only.as_str()));
    for (name, settings) in cases.iter().filter(|(n, _)| only(n)) {
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
    let mut summaries = Vec::new();
    for (name, settings) in cases.iter().take(2).filter(|(n, _)| only(n)) {
        let cache = bar(settings);
        summaries.push(compare(name, &cache.surface, &cache.frames, cache.settings.fps, true));
    }
    for (name, make) in
        [("morph clip, 7 targets", clips::morph_clip as fn() -> clips::Clip), ("unwelded skinned clip, 3 bones", clips::unwelded_skinned_clip)]
    {
        if only(name) {
            let clip = make();
            summaries.push(compare(name, &clip.surface, &clip.frames, clip.fps, false));
        }
    }
    println!();
    println!("Targets per cache: gltfpack -cc (its defaults) on the full-frame glb over our default glb (at least 2x, at equal or lower max error), and our default glb over PCA+zstd at our glb's max error (at most 1.5x); load average {}:", load());
    println!();
    println!("| cache | default glb KB | meshopt glb KB | our max error | gltfpack -cc KB | its max error | gltfpack / ours | >= 2x at <= error | ours at gltfpack's error KB (error) | gltfpack / that | >= 2x at equal error | PCA+zstd KB (rank) | ours / PCA+zstd | <= 1.5x | meshopt / PCA+zstd | our default glb holds (KB) |");
    println!("|---|---:|---:|---:|---:|---:|---:|---|---:|---:|---|---:|---:|---|---:|---|");
    for s in &summaries {
        let yes = |ok: bool| if ok { "yes" } else { "**no**" };
        let (packed, packed_max, packed_ratio, packed_ok) = match s.gltfpack {
            Some((bytes, max)) => {
                let ratio = bytes as f64 / s.ours as f64;
                (
                    kb(bytes as usize),
                    format!("{max:.2e}"),
                    format!("{ratio:.2}x"),
                    format!("{} (error {})", yes(ratio >= 2.0 && s.ours_max <= max), if s.ours_max <= max { "lower" } else { "higher" }),
                )
            }
            None => ("-".into(), "-".into(), "-".into(), "-".into()),
        };
        let (equal, equal_ratio, equal_ok) = match (s.at_gltfpack, s.gltfpack) {
            (Some((bytes, max)), Some((packed, packed_max))) => {
                let ratio = packed as f64 / bytes as f64;
                (format!("{} ({max:.2e})", kb(bytes as usize)), format!("{ratio:.2}x"), yes(ratio >= 2.0 && max <= packed_max).to_string())
            }
            _ => ("-".into(), "-".into(), "-".into()),
        };
        let pca_ratio = s.ours as f64 / s.pca.zstd_bytes as f64;
        println!(
            "| {} | {} | {} | {:.2e} | {packed} | {packed_max} | {packed_ratio} | {packed_ok} | {equal} | {equal_ratio} | {equal_ok} | {} ({}) | {pca_ratio:.2}x | {} | {:.2}x | {} |",
            s.name,
            kb(s.ours as usize),
            kb(s.meshopt as usize),
            s.ours_max,
            kb(s.pca.zstd_bytes),
            s.pca.rank,
            yes(pca_ratio <= 1.5),
            s.meshopt as f64 / s.pca.zstd_bytes as f64,
            s.parts
        );
    }
    keyframe_scenes(&only);
    println!();
    println!("load average after: {}", load());
}
