//! Cache bakes measured against the cache itself, through the CLI: frame counts from the
//! clip's own samples (f32 times just under a whole frame keep their last frame), full-frame
//! files that are the cache frame for frame, and the report's ratios against it.

use std::path::Path;

use blendsim::algorithms::frames::{FrameSource, MemoryFrames};
use blendsim::algorithms::geometry::{norm, sub, Point, TriMesh};
use blendsim::formats::cache::{CacheOptions, VertexCache};
use blendsim::formats::mesh::obj;
use serde_json::Value;

use crate::common::checkers::usd_probe;
use crate::common::cli::{read_json, run, TempDir};

/// An `n` x `n` grid in the xy plane, two triangles per square.
fn grid(n: u32) -> TriMesh {
    let positions = (0..n * n).map(|v| [(v % n) as f64, (v / n) as f64, 0.0]).collect();
    let mut triangles = Vec::new();
    for i in 0..n - 1 {
        for j in 0..n - 1 {
            let a = i * n + j;
            triangles.push([a, a + 1, a + n + 1]);
            triangles.push([a, a + n + 1, a + n]);
        }
    }
    TriMesh { positions, triangles, attributes: None }
}

/// `frames` frames at `fps` of `mesh` under a travelling wave, times `f / fps`.
fn wave(mesh: &TriMesh, frames: usize, fps: f64) -> MemoryFrames {
    let times: Vec<f64> = (0..frames).map(|f| f as f64 / fps).collect();
    let frames =
        times.iter().map(|&t| mesh.positions.iter().map(|p| [p[0], p[1], 0.4 * (0.9 * p[0] - 5.0 * t).sin() + 0.1 * p[1] * t]).collect()).collect();
    MemoryFrames { times, frames }
}

fn scene(path: &str, extra: &str) -> String {
    format!(
        "name = \"clip\"\n[cache]\npath = \"{path}\"\n{extra}keyframes = \"auto\"\ntolerance = 0.005\n[solver]\nmethod = \"fit\"\n[export]\nformats = [\"usda\", \"glb\"]\nfull_frame = true\n"
    )
}

fn max_distance(a: &[Point], b: &[Point]) -> f64 {
    a.iter().zip(b).map(|(p, q)| norm(sub(*p, *q))).fold(0.0, f64::max)
}

/// A hand-made PC2 of `frames` whose header says `start` and `rate` (frames between samples).
fn pc2(frames: &MemoryFrames, start: f32, rate: f32) -> Vec<u8> {
    let mut bytes = b"POINTCACHE2\0".to_vec();
    bytes.extend(1i32.to_le_bytes());
    bytes.extend((frames.vertex_count() as i32).to_le_bytes());
    bytes.extend(start.to_le_bytes());
    bytes.extend(rate.to_le_bytes());
    bytes.extend((frames.frame_count() as i32).to_le_bytes());
    for frame in &frames.frames {
        for p in frame {
            for x in p {
                bytes.extend((*x as f32).to_le_bytes());
            }
        }
    }
    bytes
}

/// Frames of the file at `path` read back as a cache at `fps`.
fn read_back(path: &Path, fps: f64) -> (usize, Vec<Point>) {
    let mut cache = VertexCache::open(path, &CacheOptions { fps: Some(fps), ..CacheOptions::default() }).unwrap();
    let count = cache.frames.frame_count();
    let mut last = vec![[0.0; 3]; cache.frames.vertex_count()];
    cache.frames.read_frame(count - 1, &mut last).unwrap();
    (count, last)
}

/// Clips whose duration x fps falls just under a whole number in f32 (18 frames at 24 fps:
/// 17 / 24 s in f32 is 16.9999995 frames), as glTF, MDD (f32 times) and PC2 (an f32 sample
/// rate of 0.7 frames at 21 fps, 30 samples per second): every frame is in the report, the
/// USD layer ends at the last frame, and the last frame of the files is the cache's.
#[test]
fn a_duration_just_under_a_whole_frame_keeps_the_last_frame() {
    let mesh = grid(5);
    let dir = TempDir::new("cache-honest-frames");
    std::fs::write(dir.join("rest.obj"), obj::write(&mesh)).unwrap();
    let cases: [(&str, usize, f64, &str); 5] = [
        ("clip18.glb", 18, 24.0, "fps = 24\n"),
        ("clip217.glb", 217, 30.0, "fps = 30\n"),
        ("clip225.glb", 225, 24.0, "fps = 24\n"),
        ("clip18.mdd", 18, 24.0, "rest = \"../rest.obj\"\n"),
        ("clip17.pc2", 17, 30.0, "fps = 21\nrest = \"../rest.obj\"\n"),
    ];
    for (path, count, fps, extra) in cases {
        let frames = wave(&mesh, count, fps);
        let end = frames.times[count - 1];
        if path.ends_with(".pc2") {
            std::fs::write(dir.join(path), pc2(&frames, 0.0, 0.7)).unwrap();
        } else {
            blendsim::formats::cache::write(&dir.join(path), &mesh, &mut frames.clone(), fps).unwrap();
            assert!((end as f32 as f64) * fps < (count - 1) as f64, "{path}: the f32 end time is under the last frame");
        }
        let sub_dir = dir.join(path.replace('.', "-"));
        std::fs::create_dir_all(&sub_dir).unwrap();
        std::fs::write(sub_dir.join("scene.toml"), scene(&format!("../{path}"), extra)).unwrap();
        run(&sub_dir, &["bake", "scene.toml", "--out", "out", "--quiet"]).success();
        let out = sub_dir.join("out");
        let report = read_json(&out.join("report.json"));
        println!(
            "{path}: {count} frames; report frames {}, cache frames {}, keys {}",
            report["frames"], report["cache"]["frames"], report["cache"]["keys"]
        );
        assert_eq!(report["frames"], count, "{path}");
        assert_eq!(report["cache"]["frames"], count, "{path}");
        assert_eq!(report["cache"]["error"]["per_frame"].as_array().unwrap().len(), count, "{path}");
        check_ratios(&report, std::fs::metadata(dir.join(path)).unwrap().len(), path);
        let usda = std::fs::read_to_string(out.join("clip.usda")).unwrap();
        assert!(usda.contains(&format!("endTimeCode = {}\n", count - 1)), "{path}: {}", &usda[..400]);
        let full = std::fs::read_to_string(out.join("clip.full.usda")).unwrap();
        assert!(full.contains(&format!("endTimeCode = {}\n", count - 1)), "{path}");
        // The full-frame glb is the cache: every frame, the last one the cache's own.
        let last = frames.frames[count - 1].clone();
        let (n, full_last) = read_back(&out.join("clip.full.glb"), fps);
        assert_eq!(n, count, "{path}");
        // Within the quantization error the report states for that file (read back from it).
        let diagonal = report["cache"]["error"]["diagonal"].as_f64().unwrap();
        let stated = report["outputs"]
            .as_array()
            .unwrap()
            .iter()
            .find(|o| o["path"] == "clip.full.glb")
            .and_then(|o| o["quantization_error"].as_f64())
            .unwrap_or(0.0);
        let off = max_distance(&full_last, &last) / diagonal;
        assert!(off <= stated + 1e-7, "{path}: the full-frame glb's last frame is {off} of the diagonal off (stated {stated})");
        let (n, blend_last) = read_back(&out.join("clip.glb"), fps);
        assert_eq!(n, count, "{path}");
        assert!(max_distance(&blend_last, &last) / diagonal <= 0.005 + 1e-6, "{path}: the blendshape glb's last frame is off");
    }
}

fn bytes_of(report: &Value, file: &str) -> f64 {
    report["outputs"].as_array().unwrap().iter().find(|f| f["path"] == file).unwrap_or_else(|| panic!("no {file} in {report}"))["bytes"]
        .as_f64()
        .unwrap()
}

/// The three ratios of a cache bake: (c) the full-frame file of the same format, which is
/// the cache written per frame; (a) the input as given and (b) its full-frame version, both
/// the cache file.
fn check_ratios(report: &Value, cache_bytes: u64, path: &str) {
    for format in ["usda", "glb"] {
        let blend = bytes_of(report, &format!("clip.{format}"));
        let full = bytes_of(report, &format!("clip.full.{format}"));
        let fair = report["ratios"][format].as_f64().unwrap();
        assert!((fair - full / blend).abs() < 1e-9, "{path}: {format} ratio {fair} vs {full} / {blend}");
        assert_eq!(report["input_bytes"], cache_bytes, "{path}");
        assert_eq!(report["full_frame_input_bytes"], cache_bytes, "{path}");
        let input = report["input_ratios"][format].as_f64().unwrap();
        assert!((input - cache_bytes as f64 / blend).abs() < 1e-9, "{path}: {format} input ratio {input}");
        assert_eq!(report["full_frame_input_ratios"][format], report["input_ratios"][format], "{path}");
        println!(
            "{path}: {format} blendshape {blend} B; full-frame (the cache as {format}) {full} B: {fair:.2}x; cache {cache_bytes} B: {input:.2}x"
        );
    }
}

/// usd-core's view of a file's Mesh: its point count (at the first time code) and its
/// `blendsim:weldMap` (`null` when absent).
const USD_WELD_MAP: &str = r#"
import json, sys
from pxr import Usd, UsdGeom
stage = Usd.Stage.Open(sys.argv[1])
mesh = [p for p in stage.Traverse() if p.IsA(UsdGeom.Mesh)][0]
points = UsdGeom.Mesh(mesh).GetPointsAttr().Get(Usd.TimeCode(stage.GetStartTimeCode()))
attr = mesh.GetAttribute("blendsim:weldMap")
print(json.dumps({"points": len(points), "weldMap": list(attr.Get()) if attr and attr.HasValue() else None}))
"#;

/// A clip with a vertex per triangle corner (as glTF exporters often write a skinned mesh):
/// welded on import by default, written on the welded vertices with the weld map in the files,
/// and kept as given with `weld = false`. The map gives back every input vertex's frames.
#[test]
fn a_vertex_per_corner_clip_is_welded_and_maps_back() {
    let mesh = grid(7);
    let corners = TriMesh {
        positions: mesh.triangles.iter().flat_map(|t| t.map(|v| mesh.positions[v as usize])).collect(),
        triangles: (0..mesh.triangles.len() as u32).map(|t| [3 * t, 3 * t + 1, 3 * t + 2]).collect(),
        attributes: None,
    };
    let frames = wave(&corners, 48, 30.0);
    let dir = TempDir::new("cache-honest-weld");
    blendsim::formats::cache::write(&dir.join("corners.glb"), &corners, &mut frames.clone(), 30.0).unwrap();
    let cache_bytes = std::fs::metadata(dir.join("corners.glb")).unwrap().len();
    let mut sizes = Vec::new();
    for weld in [true, false] {
        let sub_dir = dir.join(format!("weld-{weld}"));
        std::fs::create_dir_all(&sub_dir).unwrap();
        let extra = if weld { "fps = 30\n".to_string() } else { "fps = 30\nweld = false\n".to_string() };
        std::fs::write(sub_dir.join("scene.toml"), scene("../corners.glb", &extra)).unwrap();
        run(&sub_dir, &["bake", "scene.toml", "--out", "out", "--quiet"]).success();
        let out = sub_dir.join("out");
        let report = read_json(&out.join("report.json"));
        let c = &report["cache"];
        assert_eq!(c["input_vertices"], corners.positions.len());
        let expected = if weld { mesh.positions.len() } else { corners.positions.len() };
        assert_eq!((c["vertices"].as_u64().unwrap() as usize, report["vertices"].as_u64().unwrap() as usize), (expected, expected), "weld {weld}");
        check_ratios(&report, cache_bytes, &format!("weld {weld}"));
        // The blendshape glb read back, expanded through its weld map, against every input
        // vertex at every frame.
        let map = crate::weld_keys::glb_weld_map(&out.join("clip.glb"));
        assert_eq!(map.is_some(), weld, "a weld map only when welded");
        let map = map.unwrap_or_else(|| (0..corners.positions.len()).collect());
        assert_eq!(map.len(), corners.positions.len());
        let usda = std::fs::read_to_string(out.join("clip.usda")).unwrap();
        assert_eq!(usda.contains("uniform int[] blendsim:weldMap = ["), weld);
        // usd-core reads the same map on the Mesh of the blendshape and the streamed
        // full-frame USD files, over as many points as the files have.
        for file in ["clip.usda", "clip.full.usda"] {
            let v = usd_probe(USD_WELD_MAP, &out.join(file));
            assert_eq!(v["points"].as_u64(), Some(expected as u64), "{file}");
            let read: Option<Vec<usize>> = serde_json::from_value(v["weldMap"].clone()).unwrap();
            assert_eq!(read.is_some(), weld, "{file}: a weld map only when welded");
            if let Some(read) = read {
                assert_eq!(read, map, "{file}: the glb's weld map");
            }
        }
        let mut written = VertexCache::open(&out.join("clip.glb"), &CacheOptions { fps: Some(30.0), ..CacheOptions::default() }).unwrap();
        assert_eq!((written.frames.frame_count(), written.frames.vertex_count()), (48, expected));
        let diagonal = c["error"]["diagonal"].as_f64().unwrap();
        let mut pose = vec![[0.0; 3]; expected];
        let mut worst = 0.0f64;
        for (f, input) in frames.frames.iter().enumerate() {
            written.frames.read_frame(f, &mut pose).unwrap();
            let expanded: Vec<Point> = map.iter().map(|&w| pose[w]).collect();
            worst = worst.max(max_distance(&expanded, input) / diagonal);
        }
        assert!(worst <= 0.005 + 1e-6, "weld {weld}: the written glb expanded is {worst} from the input");
        println!(
            "weld {weld}: {} input vertices -> {expected}; keys {}; clip.glb {} B, clip.usda {} B, clip.full.glb {} B; max error {worst:.2e} (report {:.2e})",
            corners.positions.len(),
            c["keys"].as_array().unwrap().len(),
            bytes_of(&report, "clip.glb"),
            bytes_of(&report, "clip.usda"),
            bytes_of(&report, "clip.full.glb"),
            c["error"]["max"].as_f64().unwrap()
        );
        sizes.push((bytes_of(&report, "clip.glb"), bytes_of(&report, "clip.usda")));
    }
    assert!(sizes[0].0 < sizes[1].0 && sizes[0].1 < sizes[1].1, "welding makes the files smaller: {sizes:?}");
}

/// A two-target morph clip on a 3 x 3 x 3 grid of points (two of them in triangles): two
/// shapes blended by cubic Hermite weight curves keyed at uneven frames (what a glTF morph clip
/// with CUBICSPLINE weights holds), 91 frames at 30 fps, exact for a fit on the curves' keys.
fn two_target_clip() -> (TriMesh, MemoryFrames) {
    let positions: Vec<Point> = (0..27).map(|i| [(i % 3) as f64 * 0.5, ((i / 3) % 3) as f64 * 0.5, (i / 9) as f64 * 0.5]).collect();
    let mesh = TriMesh { positions, triangles: vec![[0, 1, 3], [1, 4, 3]], attributes: None };
    let fps = 30.0;
    let keys = [0usize, 9, 23, 31, 52, 60, 77, 90];
    let times: Vec<f64> = keys.iter().map(|&f| f as f64 / fps).collect();
    let value = |k: usize| [((k * 7) % 5) as f64 / 4.0, ((k * 3) % 4) as f64 / 3.0];
    let slope = |k: usize| [((k * 5) % 3) as f64 - 1.0, 2.0 - ((k * 11) % 5) as f64];
    let weight = |c: usize, t: f64| {
        let i = times.partition_point(|&k| k <= t).clamp(1, times.len() - 1) - 1;
        let h = times[i + 1] - times[i];
        let s = (t - times[i]) / h;
        let (s2, s3) = (s * s, s * s * s);
        (2.0 * s3 - 3.0 * s2 + 1.0) * value(i)[c]
            + (s3 - 2.0 * s2 + s) * h * slope(i)[c]
            + (3.0 * s2 - 2.0 * s3) * value(i + 1)[c]
            + (s3 - s2) * h * slope(i + 1)[c]
    };
    let frame_times: Vec<f64> = (0..91).map(|f| f as f64 / fps).collect();
    let frames = frame_times
        .iter()
        .map(|&t| {
            let (a, b) = (weight(0, t), weight(1, t));
            mesh.positions
                .iter()
                .map(|p| {
                    let (d0, d1) = ([0.3 * p[1], 0.2 * p[0] * p[1], -0.1], [-0.05, 0.25 * p[1] * p[1], 0.15 * p[0]]);
                    std::array::from_fn(|d| p[d] + a * d0[d] + b * d1[d])
                })
                .collect()
        })
        .collect();
    (mesh, MemoryFrames { times: frame_times, frames })
}

/// `keyframes = "auto"` over a tolerance sweep, through the CLI: a tighter tolerance never
/// picks fewer keys nor gives a larger error, and every error (the report's, measured against
/// the cache) is within its tolerance. Before, 0.001 picked 9 keys for 8.3e-4 where 0.002
/// found the clip's 8 exact keys (error 6e-8).
#[test]
fn a_tighter_tolerance_never_picks_fewer_keys_nor_gives_a_larger_error() {
    let (mesh, frames) = two_target_clip();
    let dir = TempDir::new("cache-honest-tolerance");
    std::fs::write(dir.join("rest.obj"), obj::write(&mesh)).unwrap();
    std::fs::write(dir.join("clip.pc2"), pc2(&frames, 0.0, 1.0)).unwrap();
    let (mut keys, mut error) = (0, f64::INFINITY);
    for tolerance in ["0.02", "0.01", "0.005", "0.002", "0.001"] {
        let scene = format!(
            "name = \"clip\"\n[cache]\npath = \"clip.pc2\"\nfps = 30\nrest = \"rest.obj\"\nkeyframes = \"auto\"\ntolerance = {tolerance}\n[solver]\nmethod = \"fit\"\n[export]\nformats = [\"usda\"]\nfull_frame = false\n"
        );
        std::fs::write(dir.join("scene.toml"), scene).unwrap();
        let out = format!("out-{tolerance}");
        run(&dir.path, &["bake", "scene.toml", "--out", &out, "--quiet"]).success();
        let report = read_json(&dir.join(&out).join("report.json"));
        let n = report["cache"]["keys"].as_array().unwrap().len();
        let max = report["cache"]["error"]["max"].as_f64().unwrap();
        println!("tolerance {tolerance}: {n} keys {}, max error {max:.2e}", report["cache"]["keys"]);
        let tolerance: f64 = tolerance.parse().unwrap();
        assert!(max <= tolerance, "tolerance {tolerance}: max error {max}");
        assert!(n >= keys, "tolerance {tolerance}: {n} keys, fewer than the {keys} of a looser tolerance");
        assert!(max <= error, "tolerance {tolerance}: max error {max:.3e}, over the {error:.3e} of a looser tolerance");
        (keys, error) = (n, max);
    }
}
