//! Streaming vertex caches: a synthetic cache (a travelling wave on a grid of V vertices, F
//! frames at 30 fps) is written in every format and read back frame by frame, each in its own
//! process under `/usr/bin/time -v`. Printed per format: file size, write and read time, and
//! peak resident memory: the process's own (`VmHWM`) and `/usr/bin/time`'s maximum over the
//! process tree (which includes usd-core's Python for USD), beside the size of the whole cache
//! as f32, which a non-streaming reader would hold.
//!
//! `cargo bench --bench cache_io` (or `make bench-cache`). `BLENDSIM_BENCH_VERTICES` (100000)
//! and `BLENDSIM_BENCH_FRAMES` (300) set the size; text formats (OBJ sequence, usda) use at
//! most 30 frames (300 frames of 100k-vertex OBJ files are 2.4 GB). Files go to
//! `target/cache-bench` and are removed afterwards. The load average is printed: on a shared
//! machine the times are only as good as that number.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use blendsim::algorithms::frames::FrameSource;
use blendsim::algorithms::geometry::{Point, TriMesh};
use blendsim::formats::cache::{self, CacheOptions, VertexCache};
use blendsim::formats::mesh::obj;

const FPS: f64 = 30.0;

/// A travelling wave on a `side` x `side` grid, computed per frame (nothing stored).
struct Wave {
    side: usize,
    frames: usize,
}

impl FrameSource for Wave {
    fn vertex_count(&self) -> usize {
        self.side * self.side
    }

    fn frame_count(&self) -> usize {
        self.frames
    }

    fn time(&self, frame: usize) -> f64 {
        frame as f64 / FPS
    }

    fn read_frame(&mut self, frame: usize, out: &mut [Point]) -> blendsim::Result<()> {
        let t = self.time(frame);
        let h = 1.0 / self.side as f64;
        for (v, p) in out.iter_mut().enumerate() {
            let (x, y) = ((v % self.side) as f64 * h, (v / self.side) as f64 * h);
            *p = [x, y, 0.05 * (12.0 * x - 4.0 * t).sin() * (1.0 + y)];
        }
        Ok(())
    }
}

fn grid(side: usize) -> TriMesh {
    let mut triangles = Vec::with_capacity(2 * (side - 1) * (side - 1));
    for i in 0..side as u32 - 1 {
        for j in 0..side as u32 - 1 {
            let (a, n) = (i * side as u32 + j, side as u32);
            triangles.push([a, a + 1, a + n + 1]);
            triangles.push([a, a + n + 1, a + n]);
        }
    }
    let mut mesh = TriMesh { positions: vec![[0.0; 3]; side * side], triangles, attributes: None };
    Wave { side, frames: 1 }.read_frame(0, &mut mesh.positions).unwrap();
    mesh
}

fn vm_hwm_kb() -> u64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| s.lines().find_map(|l| l.strip_prefix("VmHWM:").and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())))
        .unwrap_or(0)
}

fn load() -> String {
    std::fs::read_to_string("/proc/loadavg").map(|l| l.split_whitespace().take(3).collect::<Vec<_>>().join(" ")).unwrap_or_default()
}

fn env_usize(name: &str, default: usize) -> usize {
    std::env::var(name).ok().and_then(|v| v.parse().ok()).unwrap_or(default)
}

/// Child: write `path` (`side`, `frames`), or read every frame of it; prints seconds and VmHWM.
fn child(args: &[String]) {
    let start = Instant::now();
    match args {
        [mode, path, side, frames] if mode == "--write-cache" => {
            let (side, frames) = (side.parse().unwrap(), frames.parse().unwrap());
            cache::write(Path::new(path), &grid(side), &mut Wave { side, frames }, FPS).unwrap_or_else(|e| panic!("{e}"));
            println!("{} {}", start.elapsed().as_secs_f64(), vm_hwm_kb());
        }
        [mode, path, rest] if mode == "--read-cache" => {
            let rest = (rest != "-").then(|| PathBuf::from(rest));
            let mut cache = VertexCache::open(Path::new(path), &CacheOptions { fps: Some(FPS), rest, ..CacheOptions::default() })
                .unwrap_or_else(|e| panic!("{e}"));
            let mut points = vec![[0.0; 3]; cache.frames.vertex_count()];
            let mut checksum = 0.0;
            for f in 0..cache.frame_count() {
                cache.frames.read_frame(f, &mut points).unwrap_or_else(|e| panic!("{e}"));
                checksum += points[f % points.len()][2];
            }
            std::hint::black_box(checksum);
            println!("{} {}", start.elapsed().as_secs_f64(), vm_hwm_kb());
        }
        _ => panic!("unknown child arguments {args:?}"),
    }
}

/// Run this benchmark binary as a child under `/usr/bin/time -v`: (seconds, own peak KiB,
/// tree peak KiB).
fn timed(args: &[&str]) -> (f64, u64, u64) {
    let output = Command::new("/usr/bin/time")
        .arg("-v")
        .arg(std::env::current_exe().unwrap())
        .args(args)
        .output()
        .expect("run /usr/bin/time (apt-get install time)");
    let (stdout, stderr) = (String::from_utf8_lossy(&output.stdout), String::from_utf8_lossy(&output.stderr));
    assert!(output.status.success(), "{args:?} failed:\n{stdout}\n{stderr}");
    let mut own = stdout.split_whitespace();
    let seconds = own.next().unwrap().parse().unwrap();
    let hwm = own.next().unwrap().parse().unwrap();
    let tree = stderr.lines().find_map(|l| l.trim().strip_prefix("Maximum resident set size (kbytes): ")).unwrap().parse().unwrap();
    (seconds, hwm, tree)
}

fn size(path: &Path) -> u64 {
    if path.to_string_lossy().contains('#') {
        let dir = path.parent().unwrap();
        std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().metadata().unwrap().len()).sum()
    } else {
        std::fs::metadata(path).unwrap().len()
    }
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).filter(|a| a != "--bench").collect();
    if args.first().is_some_and(|a| a.ends_with("-cache")) {
        return child(&args);
    }
    let vertices = env_usize("BLENDSIM_BENCH_VERTICES", 100_000);
    let frames = env_usize("BLENDSIM_BENCH_FRAMES", 300);
    let side = (vertices as f64).sqrt().ceil() as usize;
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("target/cache-bench");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(dir.join("seq")).unwrap();
    let rest = dir.join("rest.obj");
    std::fs::write(&rest, obj::write(&grid(side))).unwrap();
    let mib = |b: u64| b as f64 / (1 << 20) as f64;
    println!("machine: load average {} (2 cores shared; times are only as good as that)", load());
    println!(
        "cache: {} vertices x {frames} frames at {FPS} fps; whole cache as f32 = {:.0} MiB\n",
        side * side,
        mib((side * side * frames * 12) as u64)
    );
    println!("| format | frames | file MiB | write s | write peak MiB (own / tree) | read s | read ms/frame | read peak MiB (own / tree) |");
    println!("|---|---|---|---|---|---|---|---|");
    let text_frames = frames.min(30);
    let cases = [
        ("pc2", dir.join("wave.pc2"), frames, true),
        ("mdd", dir.join("wave.mdd"), frames, true),
        ("glb", dir.join("wave.glb"), frames, false),
        ("usdc", dir.join("wave.usdc"), frames, false),
        ("usda", dir.join("wave.usda"), text_frames, false),
        ("obj sequence", dir.join("seq/wave_####.obj"), text_frames, false),
    ];
    for (name, path, count, needs_rest) in cases {
        let p = path.to_str().unwrap();
        let (write_s, write_own, write_tree) = timed(&["--write-cache", p, &side.to_string(), &count.to_string()]);
        let bytes = size(&path);
        let (read_s, read_own, read_tree) = timed(&["--read-cache", p, if needs_rest { rest.to_str().unwrap() } else { "-" }]);
        println!(
            "| {name} | {count} | {:.0} | {write_s:.1} | {:.0} / {:.0} | {read_s:.1} | {:.1} | {:.0} / {:.0} |",
            mib(bytes),
            write_own as f64 / 1024.0,
            write_tree as f64 / 1024.0,
            1e3 * read_s / count as f64,
            read_own as f64 / 1024.0,
            read_tree as f64 / 1024.0
        );
    }
    println!("\nmachine after: load average {}", load());
    std::fs::remove_dir_all(&dir).unwrap();
}
