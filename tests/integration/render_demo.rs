//! The demo as a user sees it: `blendsim bake fixtures/demo/twist.toml`, then its `.glb` (and
//! the full-frame `.glb`) rendered by three.js in headless Chromium, which must show the mesh
//! and show it move between the rest pose (0 s) and the left twist key (0.5 s).

use std::path::Path;

use crate::common::checkers::render_glb;
use crate::common::cli::{run, TempDir};

#[test]
fn demo_glb_renders_and_moves_in_chromium() {
    let dir = TempDir::new("render-demo");
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/demo/twist.toml");
    run(&dir.path, &["bake", "-q", scene.to_str().unwrap(), "--out", "out"]).success();
    for (file, png) in [("twist.glb", "png"), ("twist.full.glb", "png-full")] {
        // The demo loops (rest, left, rest, right, rest): 0 s and the middle are both the
        // rest pose, so compare the start with the left twist key.
        let summary = render_glb(&dir.join("out").join(file), &dir.join(png), Some([0.0, 0.5]));
        eprintln!("{file}: {summary}");
        assert_eq!(summary["ok"], true, "{summary}");
        let renders = summary["renders"].as_array().expect("render summaries");
        assert_eq!(renders.len(), 2);
        for r in renders {
            let coverage = r["coverage"].as_f64().unwrap();
            assert!(coverage > 0.02 && coverage < 0.9, "{file}: the mesh covers {coverage} of the image");
        }
        assert!(summary["changed"].as_f64().unwrap() >= 0.005, "{file}: {summary}");
        let shots = summary["screenshots"].as_array().unwrap();
        assert_eq!(shots.len(), 2);
        let images: Vec<Vec<u8>> = shots.iter().map(|p| std::fs::read(p.as_str().unwrap()).unwrap()).collect();
        for bytes in &images {
            assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n", "{file}: a PNG");
        }
        assert!(images[0] != images[1], "{file}: the two renders are different images");
    }
}
