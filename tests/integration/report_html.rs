//! `report.html` and `summary.html` as a user opens them: from `file://` in the output folder,
//! in headless Chromium (tests/checkers/report_check.mjs), with no network. The demo's page:
//! its plots with labelled axes, the player's two views in agreement at several frames and
//! apart between two, the scrubber, valid HTML, under the stated size; a bake of many frames
//! decimated, and saying so; a big surface drawn as points; a hermite bake without a W plot;
//! a cache bake's player against the cache; a batch's summary linking each report and sorting
//! by its columns.

use std::path::Path;

use blendsim::algorithms::geometry::TriMesh;
use blendsim::algorithms::procedural::icosphere;
use blendsim::formats::mesh::obj;
use blendsim::pipeline::report::html::HTML_LIMIT;
use serde_json::Value;

use crate::cache_bake::{scene as cache_scene, write_cache};
use crate::common::bar::{bar, BarSettings};
use crate::common::checkers::check_report_html;
use crate::common::cli::{copy_demo, read_json, run, TempDir};

/// The page without its wall-clock row (the only bytes that differ between runs).
fn without_time(path: &Path) -> String {
    std::fs::read_to_string(path).unwrap().lines().filter(|l| !l.starts_with("<tr><td>time</td>")).collect::<Vec<_>>().join("\n")
}

fn numbers(v: &Value) -> Vec<f64> {
    v.as_array().unwrap_or_else(|| panic!("not an array: {v}")).iter().map(|x| x.as_f64().unwrap()).collect()
}

#[test]
fn the_demo_report_html_plots_and_plays_offline_in_chromium() {
    let dir = TempDir::new("report-html-demo");
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/demo/twist.toml");
    run(&dir.path, &["bake", "-q", scene.to_str().unwrap(), "--out", "out"]).success();
    let html = dir.join("out/report.html");
    let summary = check_report_html(&html, Some(&dir.join("report.png")));
    eprintln!("{summary}");
    assert_eq!(summary["ok"], true, "{summary}");
    let ids: Vec<&str> = summary["plots"].as_array().unwrap().iter().map(|p| p["id"].as_str().unwrap()).collect();
    assert_eq!(ids, ["plot-energy", "plot-volume", "plot-error", "plot-bytes"]);
    assert_eq!(summary["agreement"].as_array().unwrap().len(), 5);
    let bytes = std::fs::metadata(&html).unwrap().len() as usize;
    assert!(bytes < HTML_LIMIT, "report.html is {bytes} bytes, over the stated {HTML_LIMIT}");
    // The demo is small: every frame and vertex, no decimation note.
    assert_eq!(summary["frames"], 121);
    let text = std::fs::read_to_string(&html).unwrap();
    assert!(!text.contains("id=\"decimated\""));
    assert!(text.contains("reference: full-frame"));

    // report.json's series: per frame, the plots' data.
    let r = read_json(&dir.join("out/report.json"));
    let s = &r["series"];
    let frames = r["frames"].as_u64().unwrap() as usize;
    assert_eq!(numbers(&s["frame_times"]).len(), frames);
    let (bake, hermite) = (numbers(&s["volume"]["animation"]), numbers(&s["volume"]["hermite"]));
    assert_eq!((bake.len(), hermite.len()), (frames, frames));
    let min = |v: &[f64]| v.iter().copied().fold(f64::INFINITY, f64::min);
    assert_eq!(min(&bake), r["volume"]["animation"]["min"].as_f64().unwrap(), "the series is what the range summarizes");
    assert_eq!(min(&hermite), r["volume"]["hermite"]["min"].as_f64().unwrap());
    assert!(min(&bake) > min(&hermite) + 0.1, "the physics keeps volume the hermite baseline loses");
    let keys = s["volume"]["keys"].as_array().unwrap();
    assert_eq!(keys.len(), 5);
    assert_eq!(keys[0]["input"].as_f64().unwrap(), 1.0, "the first key is the rest pose");
    assert_eq!(s["error"]["reference"], "full-frame");
    let error = numbers(&s["error"]["max"]);
    assert_eq!(error.len(), frames);
    assert_eq!(error.iter().copied().fold(0.0, f64::max), r["error"]["max"].as_f64().unwrap());
    let phases = s["energy_phases"].as_array().unwrap();
    assert_eq!(phases.iter().map(|p| p["name"].as_str().unwrap()).collect::<Vec<_>>(), ["local/global", "quasi-Newton"]);
    assert_eq!(phases.last().unwrap()["last"].as_u64().unwrap() as usize, r["solver"]["energy"].as_array().unwrap().len() - 1);

    // The same bake again: the same page but the wall-clock row.
    run(&dir.path, &["bake", "-q", scene.to_str().unwrap(), "--out", "again"]).success();
    assert_eq!(without_time(&html), without_time(&dir.join("again/report.html")));
}

/// The demo at 1200 fps (2401 frames): the player's data would pass its budget, so the page
/// shows every n-th frame, says so, stays under the stated size, and still plays in agreement.
/// At 60 fps by hermite: no W plot, and why.
#[test]
fn a_bake_with_many_frames_shows_every_nth_frame_and_a_hermite_bake_no_w_plot() {
    let dir = TempDir::new("report-html-decimated");
    copy_demo(&dir.path);
    let scene = std::fs::read_to_string(dir.join("twist.toml")).unwrap();
    assert!(scene.contains("\nfps = 60\n"));
    std::fs::write(dir.join("twist.toml"), scene.replace("\nfps = 60\n", "\nfps = 1200\n")).unwrap();
    run(&dir.path, &["bake", "-q", "twist.toml", "--out", "out"]).success();
    let html = dir.join("out/report.html");
    let summary = check_report_html(&html, None);
    eprintln!("{summary}");
    assert_eq!(summary["ok"], true, "{summary}");
    let bytes = std::fs::metadata(&html).unwrap().len() as usize;
    assert!(bytes < HTML_LIMIT, "report.html is {bytes} bytes, over the stated {HTML_LIMIT}");
    let r = read_json(&dir.join("out/report.json"));
    assert_eq!(r["frames"], 2401);
    // Every n-th frame, n the smallest that fits: the page names it and shows that many.
    let shown = summary["frames"].as_u64().unwrap();
    let stride = 2401u64.div_ceil(shown);
    assert!(stride > 1 && 2400 / stride + 1 == shown, "{shown} frames shown of 2401");
    let text = std::fs::read_to_string(&html).unwrap();
    let note = text.lines().find(|l| l.contains("id=\"decimated\"")).expect("the page says it is decimated");
    assert!(note.contains(&format!("of 2401 ({shown} shown)")) && !note.contains("vertex"), "{note}");
    // report.json keeps every frame: only the player is decimated.
    assert_eq!(numbers(&r["series"]["error"]["max"]).len(), 2401);

    // The same scene by hermite: one W, no iterations to plot, and the page says so.
    assert!(scene.contains("method = \"spacetime\""));
    std::fs::write(dir.join("hermite.toml"), scene.replace("method = \"spacetime\"", "method = \"hermite\"")).unwrap();
    run(&dir.path, &["bake", "-q", "hermite.toml", "--out", "hermite"]).success();
    let summary = check_report_html(&dir.join("hermite/report.html"), None);
    assert_eq!(summary["ok"], true, "{summary}");
    let ids: Vec<&str> = summary["plots"].as_array().unwrap().iter().map(|p| p["id"].as_str().unwrap()).collect();
    assert_eq!(ids, ["plot-volume", "plot-error", "plot-bytes"]);
    assert!(std::fs::read_to_string(dir.join("hermite/report.html")).unwrap().contains("<p>No plot of W: hermite does not iterate (W = "));
}

/// A surface of 10 242 vertices: its shapes alone would pass the player's budget, so the page
/// draws every n-th vertex as points, yet every frame of the second (the fewest it keeps).
#[test]
fn a_big_surface_is_drawn_as_every_nth_vertex_and_every_frame() {
    let dir = TempDir::new("report-html-points");
    let ball = icosphere(5);
    let squashed: Vec<_> = ball.positions.iter().map(|p| [1.2 * p[0], 0.7 * p[1], 1.2 * p[2]]).collect();
    std::fs::write(dir.join("rest.obj"), obj::write(&ball)).unwrap();
    std::fs::write(dir.join("squash.obj"), obj::write(&TriMesh { positions: squashed, triangles: ball.triangles.clone(), attributes: None }))
        .unwrap();
    let scene = "name = \"ball\"\nfps = 60\n[keyframes]\nmeshes = [\"rest.obj\", \"squash.obj\", \"rest.obj\"]\ntimes = [0.0, 0.5, 1.0]\n\
[tet]\nmax_volume = 0.05\n[solver]\nmethod = \"hermite\"\n[export]\nformats = [\"glb\"]\n";
    std::fs::write(dir.join("ball.toml"), scene).unwrap();
    run(&dir.path, &["bake", "-q", "ball.toml", "--out", "out"]).success();
    let html = dir.join("out/report.html");
    let summary = check_report_html(&html, None);
    eprintln!("{summary}");
    assert_eq!(summary["ok"], true, "{summary}");
    assert_eq!(summary["frames"], 61, "every frame of the second");
    let bytes = std::fs::metadata(&html).unwrap().len() as usize;
    assert!(bytes < HTML_LIMIT, "report.html is {bytes} bytes, over the stated {HTML_LIMIT}");
    let text = std::fs::read_to_string(&html).unwrap();
    let note = text.lines().find(|l| l.contains("id=\"decimated\"")).expect("the page says it is decimated");
    assert!(note.contains("vertex of 10242 drawn as points") && !note.contains("frame of"), "{note}");
}

#[test]
fn a_cache_bake_plays_against_the_cache_and_a_batch_summary_links_and_sorts() {
    let dir = TempDir::new("report-html-cache");
    let cache = bar(&BarSettings { duration: 0.25, ..BarSettings::default() });
    write_cache(&dir.path, &cache, "bar.pc2");
    let text = cache_scene("bar.pc2", "fps = 60\nrest = \"rest.obj\"\n", "fit", "keyframes = \"auto\"\ntolerance = 0.005");
    std::fs::write(dir.join("scene.toml"), text).unwrap();
    run(&dir.path, &["bake", "-q", "scene.toml", "--out", "bakes/cache"]).success();
    let html = dir.join("bakes/cache/report.html");
    let summary = check_report_html(&html, None);
    eprintln!("{summary}");
    assert_eq!(summary["ok"], true, "{summary}");
    let ids: Vec<&str> = summary["plots"].as_array().unwrap().iter().map(|p| p["id"].as_str().unwrap()).collect();
    // fit does not iterate: no W plot, and the page says why.
    assert_eq!(ids, ["plot-volume", "plot-error", "plot-bytes"]);
    let text = std::fs::read_to_string(&html).unwrap();
    assert!(text.contains("reference: cache") && text.contains("No plot of W: fit does not iterate"));
    let r = read_json(&dir.join("bakes/cache/report.json"));
    assert_eq!(r["series"]["error"]["reference"], "cache");
    assert_eq!(r["series"]["error"]["max"], r["cache"]["error"]["per_frame"]);
    // The player's frames are the cache's.
    assert_eq!(summary["frames"], r["cache"]["frames"]);

    // A second bake, then the batch: every report linked, sortable.
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/demo/twist.toml");
    run(&dir.path, &["bake", "-q", scene.to_str().unwrap(), "--out", "bakes/twist"]).success();
    run(&dir.path, &["report", "--out", "summary", "--batch", "bakes"]).success();
    let page = check_report_html(&dir.join("summary/summary.html"), None);
    eprintln!("{page}");
    assert_eq!(page["ok"], true, "{page}");
    assert_eq!(page["rows"], 2);
    assert!(page["links"].as_array().unwrap().iter().all(|l| l.as_str().unwrap().ends_with("/report.html")), "{page}");
    let sorted: Vec<&str> = page["sorted"].as_array().unwrap().iter().map(|s| s["column"].as_str().unwrap()).collect();
    for column in ["glb_ratio", "error_max", "seconds", "warnings"] {
        assert!(sorted.contains(&column), "{column} is not sortable: {sorted:?}");
    }
    // The new columns, as report.json has them.
    let csv = std::fs::read_to_string(dir.join("summary/summary.csv")).unwrap();
    let lines: Vec<&str> = csv.lines().collect();
    let header: Vec<&str> = lines[0].split(',').collect();
    let twist: Vec<&str> = lines[2].split(',').collect();
    let at = |name: &str| twist[header.iter().position(|h| *h == name).unwrap_or_else(|| panic!("no {name} column: {csv}"))];
    let t = read_json(&dir.join("bakes/twist/report.json"));
    assert_eq!(at("converged"), "true");
    assert_eq!(at("iterations"), t["solver"]["iterations"].to_string());
    assert_eq!(at("usdc_bytes"), t["outputs"][1]["bytes"].to_string());
    assert_eq!(
        at("key_movement").parse::<f64>().unwrap(),
        format!("{:.3e}", t["keyframe_deviation"]["max"].as_f64().unwrap()).parse::<f64>().unwrap()
    );
    assert_eq!(at("volume_loss"), format!("{:.4}", t["volume"]["animation"]["in_between_loss"].as_f64().unwrap()));
    assert!(!at("usdc_ratio").is_empty());
}
