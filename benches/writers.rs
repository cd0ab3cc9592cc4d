//! The full-frame writers' speed beside the disk's: a twisting prism of about 90k vertices
//! over `FRAMES` frames (default 48) written as `.usda`, `.usdc` and `.glb` (f32, no
//! compression). Per format: the file's size, the writer's MB/s making the bytes (`.usda`
//! and `.glb` into a sink, `.usdc` into its file unsynced: it seeks back in it), the same
//! per CPU second (what the load of a shared machine does not change), and MB/s to a synced
//! file; then the three written at once, as the export stage does. The disk's line: a 256
//! MiB buffer written and synced. Medians of `REPEATS` (default 3); MB are 10^6 bytes.
//!
//! `cargo bench --bench writers` (`make bench-writers`). Mind the load average printed with
//! it: the machine is shared.

use std::io::Write;
use std::path::Path;
use std::time::Instant;

use blendsim::algorithms::blendshape::fullframe::FullFrame;
use blendsim::algorithms::geometry::Axis;
use blendsim::algorithms::procedural::{prism, twist, Twist};
use blendsim::formats::export::glb::{self, Encoding, Placement, Surface};
use blendsim::formats::export::usd::UsdSettings;
use blendsim::formats::export::{usda, usdc};

mod common;
use common::{cpu_seconds, load, median};

/// Write `bytes` to `path` and sync it: seconds.
fn to_disk(path: &Path, write: impl FnOnce(&mut std::fs::File)) -> f64 {
    let t = Instant::now();
    let mut file = std::fs::File::create(path).expect("create");
    write(&mut file);
    file.sync_all().expect("sync");
    t.elapsed().as_secs_f64()
}

fn main() {
    let repeats: usize = std::env::var("REPEATS").ok().and_then(|r| r.parse().ok()).unwrap_or(3);
    let n_frames: usize = std::env::var("FRAMES").ok().and_then(|r| r.parse().ok()).unwrap_or(48);
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("target/writers-bench");
    std::fs::create_dir_all(&dir).unwrap();
    let rest = prism([1.0, 3.0, 1.0], [80, 240, 80]);
    let frames = FullFrame {
        frames: (0..n_frames as i64).collect(),
        times: (0..n_frames).map(|f| f as f64 / 24.0).collect(),
        points: (0..n_frames)
            .map(|f| {
                let degrees = 120.0 * f as f64 / (n_frames - 1).max(1) as f64;
                twist(&rest.positions, &Twist { axis: Axis::Y, degrees, axial_scale: 0.9 })
                    .iter()
                    .map(|p| [p[0] as f32, p[1] as f32, p[2] as f32])
                    .collect()
            })
            .collect(),
    };
    let triangles = &rest.triangles;
    let settings = UsdSettings { name: "prism".into(), fps: 24.0, up_axis: 'Y', meters_per_unit: 1.0 };
    let placement = Placement { z_up: false, meters_per_unit: 1.0 };
    println!(
        "full-frame writers: {} vertices, {} triangles, {n_frames} frames; medians of {repeats}; load average {}",
        rest.positions.len(),
        triangles.len(),
        load()
    );
    println!();
    println!("| writer | size MB | make MB/s | make MB per CPU s | to a synced file MB/s |");
    println!("|---|---:|---:|---:|---:|");

    let disk = vec![0x5au8; 256 << 20];
    let seconds: Vec<f64> = (0..repeats).map(|_| to_disk(&dir.join("disk.bin"), |f| f.write_all(&disk).unwrap())).collect();
    println!("| the disk (256 MiB, write + sync) | {:.0} | | | {:.0} |", disk.len() as f64 / 1e6, disk.len() as f64 / 1e6 / median(seconds));
    drop(disk);

    let mb = |bytes: usize, s: Vec<f64>| bytes as f64 / 1e6 / median(s);
    // usda streams: making it is formatting into a sink.
    let mut size = 0;
    let (make, cpu): (Vec<f64>, Vec<f64>) = (0..repeats)
        .map(|_| {
            let mut counted = Counted(0);
            let (t, c) = (Instant::now(), cpu_seconds());
            usda::write_full_frame(&frames, triangles, None, &settings, None, &mut counted).unwrap();
            size = counted.0;
            (t.elapsed().as_secs_f64(), cpu_seconds() - c)
        })
        .unzip();
    let disk: Vec<f64> = (0..repeats)
        .map(|_| to_disk(&dir.join("prism.full.usda"), |f| usda::write_full_frame(&frames, triangles, None, &settings, None, f).unwrap()))
        .collect();
    println!("| usda (streamed) | {:.1} | {:.0} | {:.0} | {:.0} |", size as f64 / 1e6, mb(size, make), mb(size, cpu), mb(size, disk));

    // usdc streams into its file (it seeks back to patch jumps and reads back equal frames):
    // making it is writing the file, unsynced.
    let usdc = |path: &Path| {
        let file = std::fs::File::options().read(true).write(true).create(true).truncate(true).open(path).expect("create");
        usdc::write_full_frame(&frames, triangles, None, &settings, None, path, file).unwrap();
    };
    let path = dir.join("prism.full.usdc");
    let (make, cpu): (Vec<f64>, Vec<f64>) = (0..repeats)
        .map(|_| {
            let (t, c) = (Instant::now(), cpu_seconds());
            usdc(&path);
            (t.elapsed().as_secs_f64(), cpu_seconds() - c)
        })
        .unzip();
    let size = std::fs::metadata(&path).unwrap().len() as usize;
    let disk: Vec<f64> = (0..repeats)
        .map(|_| {
            let t = Instant::now();
            usdc(&path);
            std::fs::File::open(&path).unwrap().sync_all().unwrap();
            t.elapsed().as_secs_f64()
        })
        .collect();
    println!("| usdc (streamed to its file) | {:.1} | {:.0} | {:.0} | {:.0} |", size as f64 / 1e6, mb(size, make), mb(size, cpu), mb(size, disk));
    // glb: the blocks are made, then written out from where they are into a sink.
    let glb = || glb::full_frame(&frames, Surface::plain(triangles), "prism", placement, Encoding::FLOAT);
    let mut size = 0;
    let (make, cpu): (Vec<f64>, Vec<f64>) = (0..repeats)
        .map(|_| {
            let (t, c) = (Instant::now(), cpu_seconds());
            let mut counted = Counted(0);
            glb().write_to(&mut counted).unwrap();
            size = counted.0;
            (t.elapsed().as_secs_f64(), cpu_seconds() - c)
        })
        .unzip();
    let disk: Vec<f64> =
        (0..repeats).map(|_| to_disk(&dir.join("prism.full.glb"), |f| glb().write_to(&mut std::io::BufWriter::new(f)).unwrap())).collect();
    println!("| glb, f32 (blocks written out) | {:.1} | {:.0} | {:.0} | {:.0} |", size as f64 / 1e6, mb(size, make), mb(size, cpu), mb(size, disk));
    // Beside them, the files made whole in memory and then written, as the writers did before
    // they streamed (the usdc writer's own in-memory path; the glb's parts copied into one
    // buffer): the same bytes.
    let whole = |name: &str, make: &dyn Fn() -> Vec<u8>| {
        let mut size = 0;
        let (made, cpu): (Vec<f64>, Vec<f64>) = (0..repeats)
            .map(|_| {
                let (t, c) = (Instant::now(), cpu_seconds());
                size = make().len();
                (t.elapsed().as_secs_f64(), cpu_seconds() - c)
            })
            .unzip();
        let disk: Vec<f64> = (0..repeats).map(|_| to_disk(&dir.join("whole.bin"), |f| f.write_all(&make()).unwrap())).collect();
        println!("| {name} | {:.1} | {:.0} | {:.0} | {:.0} |", size as f64 / 1e6, mb(size, made), mb(size, cpu), mb(size, disk));
    };
    whole("usdc, whole in memory, then written", &|| usdc::full_frame(&frames, triangles, None, &settings, None, &path).unwrap());
    whole("glb, f32, whole in memory, then written", &|| glb().to_vec());
    // The three at once, as the export stage writes them (each on a thread of the pool), to
    // synced files: their bytes over the wall time.
    let mut total = 0;
    let all: Vec<f64> = (0..repeats)
        .map(|_| {
            let t = Instant::now();
            rayon::scope(|s| {
                s.spawn(|_| {
                    to_disk(&dir.join("all.usda"), |f| {
                        let mut w = std::io::BufWriter::new(f);
                        usda::write_full_frame(&frames, triangles, None, &settings, None, &mut w).unwrap();
                        w.flush().unwrap();
                    });
                });
                s.spawn(|_| {
                    usdc(&dir.join("all.usdc"));
                    std::fs::File::open(dir.join("all.usdc")).unwrap().sync_all().unwrap();
                });
                s.spawn(|_| {
                    to_disk(&dir.join("all.glb"), |f| {
                        let mut w = std::io::BufWriter::new(f);
                        glb().write_to(&mut w).unwrap();
                        w.flush().unwrap();
                    });
                });
            });
            total = ["all.usda", "all.usdc", "all.glb"].iter().map(|n| std::fs::metadata(dir.join(n)).unwrap().len() as usize).sum();
            t.elapsed().as_secs_f64()
        })
        .collect();
    println!("| all three in parallel, to synced files | {:.1} | | | {:.0} |", total as f64 / 1e6, mb(total, all));
    println!();
    println!("load average after: {}", load());
    let _ = std::fs::remove_dir_all(&dir);
}

/// A sink that counts the bytes.
struct Counted(usize);

impl Write for Counted {
    fn write(&mut self, bytes: &[u8]) -> std::io::Result<usize> {
        self.0 += bytes.len();
        Ok(bytes.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}
