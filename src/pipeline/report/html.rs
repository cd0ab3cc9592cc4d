//! `report.html`: the numbers of `report.md`, the plots as inline SVG, and the player; and
//! `summary.html` of `report --batch`. One self-contained page each: no script, style, font or
//! data is fetched, so it opens offline from `file://` in the output folder.

use std::fmt::Write;

use super::player::Player;
use super::plot::{escape, BarPlot, Line, LinePlot, Mark};
use super::Report;
use crate::pipeline::scene::Format;
use crate::pipeline::stage_file::OutputKind;

/// The largest `report.html` (bytes): the player's data is decimated to keep under it
/// ([`super::player::PLAYER_BYTES`]).
pub const HTML_LIMIT: usize = 2_000_000;

/// The player: hand-written 2D canvas drawing of the embedded data.
const PLAYER_JS: &str = include_str!("player.js");

/// The page's style (no external sheet, no inline `style` attributes).
const STYLE: &str = "body{font-family:sans-serif;max-width:1100px;margin:1em auto;padding:0 1em;color:#222}\
table{border-collapse:collapse;margin:0.6em 0}td,th{border:1px solid #ccc;padding:2px 8px;text-align:left}\
td.num,th.num{text-align:right}figure{margin:1em 0}figcaption{font-size:0.9em;color:#444;max-width:680px}\
.views{display:flex;gap:12px;flex-wrap:wrap}.view canvas{border:1px solid #ccc;background:#fafafa}\
#timeline{display:block;margin-top:4px}#scrub{width:644px}.note{color:#844}\
th[data-sort]{cursor:pointer;text-decoration:underline dotted}";

/// Standard base64 (with padding) of `bytes`.
pub fn base64(bytes: &[u8]) -> String {
    use base64::Engine as _;
    base64::engine::general_purpose::STANDARD.encode(bytes)
}

/// The head of a page titled `title`.
fn head(title: &str) -> String {
    format!(
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n<title>{}</title>\n<style>{STYLE}</style>\n</head>\n<body>\n",
        escape(title)
    )
}

/// Markdown as `report.md` writes it (headings, pipe tables, paragraphs) in HTML: the page shows
/// the same numbers as the Markdown file, from the same renderer.
fn markdown_to_html(md: &str) -> String {
    let mut out = String::new();
    let lines: Vec<&str> = md.lines().collect();
    let mut i = 0;
    let cells = |line: &str| -> Vec<String> { line.trim().trim_matches('|').split('|').map(|c| c.trim().to_string()).collect() };
    while i < lines.len() {
        let line = lines[i];
        if let Some(h) = line.strip_prefix("## ") {
            let _ = writeln!(out, "<h2>{}</h2>", escape(h));
        } else if let Some(h) = line.strip_prefix("# ") {
            let _ = writeln!(out, "<h1>{}</h1>", escape(h));
        } else if line.starts_with('|') {
            let header = cells(line);
            let align: Vec<bool> = lines.get(i + 1).map_or(Vec::new(), |l| cells(l).iter().map(|c| c.ends_with(':')).collect());
            i += 2;
            out.push_str("<table>\n");
            if header.iter().any(|h| !h.is_empty()) {
                out.push_str("<thead><tr>");
                for (k, h) in header.iter().enumerate() {
                    let class = if align.get(k) == Some(&true) { " class=\"num\"" } else { "" };
                    let _ = write!(out, "<th{class}>{}</th>", escape(h));
                }
                out.push_str("</tr></thead>\n");
            }
            out.push_str("<tbody>\n");
            while i < lines.len() && lines[i].starts_with('|') {
                out.push_str("<tr>");
                for (k, c) in cells(lines[i]).iter().enumerate() {
                    let class = if align.get(k) == Some(&true) { " class=\"num\"" } else { "" };
                    let _ = write!(out, "<td{class}>{}</td>", escape(c));
                }
                out.push_str("</tr>\n");
                i += 1;
            }
            out.push_str("</tbody>\n</table>\n");
            continue;
        } else if !line.trim().is_empty() {
            let _ = writeln!(out, "<p>{}</p>", escape(line));
        }
        i += 1;
    }
    out
}

/// The plots of `report`: W per iteration, volume, error per frame, bytes per format (each an
/// `<svg>` in a `<figure>` with its caption).
pub fn plots(report: &Report) -> Vec<(String, String)> {
    let mut figures = Vec::new();
    let sv = &report.solver;
    let series = report.series.as_ref();
    let phases = series.map_or(&[][..], |s| &s.energy_phases[..]);
    // `fit` solves exactly, and `hermite` and `mass-spring` have one W at most: no iterations to
    // plot (the page says so).
    if sv.energy.len() > 1 {
        let energy = LinePlot {
            id: "plot-energy".into(),
            title: "W per iteration".into(),
            x_label: "iteration".into(),
            y_label: "W (log scale)".into(),
            log_y: true,
            lines: vec![Line { name: "W".into(), points: sv.energy.iter().enumerate().map(|(i, w)| (i as f64, *w)).collect(), dots: false }],
            marks: phases.iter().map(|p| Mark { x: p.first as f64, label: p.name.clone() }).collect(),
        };
        let phase_text: Vec<String> = phases.iter().map(|p| format!("{} {}..{}", p.name, p.first, p.last)).collect();
        figures.push((
            energy.svg(),
            format!(
                "W (the time-integrated squared residual force) after each iteration of {}, from the hermite baseline at 0{}; dashed lines: where each phase starts.",
                sv.method,
                if phase_text.is_empty() { String::new() } else { format!(" ({})", phase_text.join(", ")) }
            ),
        ));
    }
    if let Some(v) = series.and_then(|s| s.volume.as_ref().map(|v| (s, v))) {
        let (s, v) = v;
        let line = |name: &str, ys: &[f64]| Line {
            name: name.into(),
            points: s.frame_times.iter().copied().zip(ys.iter().map(|y| 100.0 * y)).collect(),
            dots: false,
        };
        let plot = LinePlot {
            id: "plot-volume".into(),
            title: "Enclosed volume over time".into(),
            x_label: "time (s)".into(),
            y_label: "volume (% of rest)".into(),
            log_y: false,
            lines: vec![
                line("this bake", &v.animation),
                line("hermite baseline", &v.hermite),
                Line { name: "keys (bake)".into(), points: v.keys.iter().map(|k| (k.time, 100.0 * k.animation)).collect(), dots: true },
                Line { name: "keys (input)".into(), points: v.keys.iter().map(|k| (k.time, 100.0 * k.input)).collect(), dots: true },
            ],
            marks: v.keys.iter().enumerate().map(|(i, k)| Mark { x: k.time, label: format!("key {i}") }).collect(),
        };
        figures.push((
            plot.svg(),
            "Volume enclosed by the surface at each frame, as a percentage of the rest volume: this bake against the hermite baseline (the input keys joined with zero velocities), with the keys' own volumes (the bake's keys, moved by the physics, and the input keys).".into(),
        ));
    }
    if let Some(s) = series {
        let e = &s.error;
        let pts = |ys: &[f64]| e.times.iter().copied().zip(ys.iter().copied()).collect();
        let plot = LinePlot {
            id: "plot-error".into(),
            title: format!("Error per frame against the {}", if e.reference == "cache" { "input cache" } else { "full-frame evaluation" }),
            x_label: "time (s)".into(),
            y_label: "distance (of the bbox diagonal)".into(),
            log_y: false,
            lines: vec![Line { name: "max".into(), points: pts(&e.max), dots: false }, Line { name: "rms".into(), points: pts(&e.rms), dots: false }],
            marks: sv.times.iter().enumerate().map(|(i, t)| Mark { x: *t, label: format!("key {i}") }).collect(),
        };
        let what = if e.reference == "cache" {
            "the blendshape animation against every frame of the input cache (cache.error), relative to the diagonal of the cache's bounding box"
        } else {
            "the blendshape animation as the files store it (f32 shapes and weights) against the full-frame evaluation of the trajectory (error), relative to the rest bounding-box diagonal"
        };
        figures.push((plot.svg(), format!("Largest and rms vertex distance per frame: {what}.")));
    }
    let formats: Vec<Format> = [Format::Usda, Format::Usdc, Format::Glb]
        .into_iter()
        .filter(|f| report.outputs.iter().any(|o| o.format == *f && o.kind == OutputKind::Blendshape))
        .collect();
    let size = |format: Format, kind: OutputKind| report.outputs.iter().find(|o| o.format == format && o.kind == kind).map(|o| o.bytes as f64);
    let positive = |b: u64| (b > 0).then_some(b as f64);
    let cache = report.cache.is_some();
    let bytes = BarPlot {
        id: "plot-bytes".into(),
        title: "Bytes per format".into(),
        x_label: "format".into(),
        y_label: "bytes (log scale)".into(),
        series: vec![
            if cache { "input (the cache)".into() } else { "input (keyframe files)".into() },
            if cache { "full-frame (the cache)".into() } else { "full-frame (f32 PC2)".into() },
            "full-frame, this format".into(),
            "blendshape".into(),
        ],
        groups: formats
            .iter()
            .map(|&f| {
                (
                    f.to_string(),
                    vec![
                        positive(report.input_bytes),
                        positive(report.full_frame_input_bytes),
                        size(f, OutputKind::FullFrame),
                        size(f, OutputKind::Blendshape),
                    ],
                )
            })
            .collect(),
    };
    figures.push((
        bytes.svg(),
        "Bytes of the input as given, the input at every frame (the plainest vertex cache), the full-frame file written in each format (compressed and quantized as that format's blendshape file), and the blendshape file.".into(),
    ));
    figures
}

/// The player's data as JSON (numbers, and base64 of little-endian arrays) for the page's script.
fn player_json(p: &Player, report: &Report) -> String {
    let bytes_of = |v: &mut dyn Iterator<Item = [u8; 4]>| base64(&v.flatten().collect::<Vec<u8>>());
    let f32s = |v: &mut dyn Iterator<Item = f32>| bytes_of(&mut v.map(f32::to_le_bytes));
    let u32s = |v: &mut dyn Iterator<Item = u32>| bytes_of(&mut v.map(u32::to_le_bytes));
    // The reference, quantized to int16 over its bounding box.
    let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
    for p in p.frames.iter().flatten() {
        for d in 0..3 {
            lo[d] = lo[d].min(p[d]);
            hi[d] = hi[d].max(p[d]);
        }
    }
    let origin: Vec<f64> = (0..3).map(|d| if lo[d].is_finite() { 0.5 * (lo[d] as f64 + hi[d] as f64) } else { 0.0 }).collect();
    let half = (0..3).map(|d| if lo[d].is_finite() { 0.5 * (hi[d] as f64 - lo[d] as f64) } else { 0.0 }).fold(0.0, f64::max);
    let step = if half > 0.0 { half / 32767.0 } else { 1.0 };
    let origin_ref = &origin;
    let quantized: Vec<u8> = p
        .frames
        .iter()
        .flatten()
        .flat_map(|q| (0..3).map(move |d| (((q[d] as f64 - origin_ref[d]) / step).round().clamp(-32767.0, 32767.0) as i16).to_le_bytes()))
        .flatten()
        .collect();
    let max_distance = p.hermite_distance.iter().flatten().copied().fold(0.0f32, f32::max);
    let distance: Vec<u8> =
        p.hermite_distance.iter().flatten().map(|d| if max_distance > 0.0 { (255.0 * d / max_distance).round() as u8 } else { 0 }).collect();
    // The report's error at each shown frame, in scene units: how far the two views may differ.
    let error: Vec<f64> = report.series.as_ref().map_or(Vec::new(), |s| s.error.max.iter().step_by(p.frame_stride).map(|e| e * p.diagonal).collect());
    let shapes: Vec<serde_json::Value> = p
        .shapes
        .iter()
        .map(|(i, o)| serde_json::json!({ "indices": u32s(&mut i.iter().copied()), "offsets": f32s(&mut o.iter().flatten().copied()) }))
        .collect();
    serde_json::json!({
        "reference": p.reference,
        "times": p.times,
        "keyTimes": p.key_times,
        "frameStride": p.frame_stride,
        "totalFrames": p.total_frames,
        "vertexStride": p.vertex_stride,
        "totalVertices": p.total_vertices,
        "vertices": p.base.len(),
        "triangles": u32s(&mut p.triangles.iter().flatten().copied()),
        "base": f32s(&mut p.base.iter().flatten().copied()),
        "shapes": shapes,
        "weights": f32s(&mut p.weights.iter().flatten().copied()),
        "frames": { "origin": origin, "step": step, "positions": base64(&quantized) },
        "distance": { "max": max_distance, "values": base64(&distance) },
        "error": error,
    })
    .to_string()
    // Inside <script>: no `</` may close it early.
    .replace("</", "<\\/")
}

/// The player section: two canvases, the timeline and its controls, the data and the script.
fn player_section(p: &Player, report: &Report) -> String {
    let mut s = String::from("<section id=\"player\">\n<h2>Player</h2>\n");
    let reference = if p.reference == "cache" { "the input cache" } else { "the full-frame evaluation (what the full-frame files hold)" };
    let _ = writeln!(
        s,
        "<p>Left: the blendshape animation as the files play it (base + shapes x weights, evaluated here). Right: {reference}. \
Both at the same time, drawn from the same viewpoint. Colour: each vertex's distance from the hermite baseline (the input keys joined with zero velocities), \
from blue (0) to red ({:.3e} scene units, the largest): where the physics moved things.</p>",
        p.hermite_distance.iter().flatten().copied().fold(0.0f32, f32::max)
    );
    let mut thinned = Vec::new();
    if p.frame_stride > 1 {
        thinned.push(format!("every {} frame of {} ({} shown)", ordinal(p.frame_stride), p.total_frames, p.times.len()));
    }
    if p.vertex_stride > 1 {
        thinned.push(format!("every {} vertex of {} drawn as points ({} shown)", ordinal(p.vertex_stride), p.total_vertices, p.base.len()));
    }
    if !thinned.is_empty() {
        let limit = HTML_LIMIT / 1_000_000;
        let _ = writeln!(s, "<p class=\"note\" id=\"decimated\">Decimated to keep this page under {limit} MB: {}.</p>", thinned.join(", "));
    }
    s.push_str(
        "<div class=\"views\">\n<figure class=\"view\"><canvas id=\"view-blendshape\" width=\"400\" height=\"360\"></canvas><figcaption>blendshape</figcaption></figure>\n",
    );
    let _ = writeln!(s, "<figure class=\"view\"><canvas id=\"view-reference\" width=\"400\" height=\"360\"></canvas><figcaption>reference: {}</figcaption></figure>\n</div>", p.reference);
    s.push_str("<div>\n<button type=\"button\" id=\"play\">play</button>\n<label for=\"scrub\">frame</label>\n");
    let _ = writeln!(
        s,
        "<input type=\"range\" id=\"scrub\" min=\"0\" max=\"{}\" value=\"0\" step=\"1\" list=\"key-frames\">",
        p.times.len().saturating_sub(1)
    );
    s.push_str("<output id=\"time\" for=\"scrub\">0.000 s</output>\n<datalist id=\"key-frames\">\n");
    for (i, t) in p.key_times.iter().enumerate() {
        let frame = p.times.iter().enumerate().min_by(|a, b| (a.1 - t).abs().total_cmp(&(b.1 - t).abs())).map_or(0, |f| f.0);
        let _ = writeln!(s, "<option value=\"{frame}\" label=\"key {i}\"></option>");
    }
    s.push_str("</datalist>\n<canvas id=\"timeline\" width=\"644\" height=\"24\"></canvas>\n</div>\n");
    let _ = writeln!(s, "<script type=\"application/json\" id=\"player-data\">{}</script>", player_json(p, report));
    let _ = writeln!(s, "<script>\n{PLAYER_JS}</script>\n</section>");
    s
}

/// `2nd`, `3rd`, `10th`.
fn ordinal(n: usize) -> String {
    let suffix = match (n % 10, n % 100) {
        (1, 11) | (2, 12) | (3, 13) => "th",
        (1, _) => "st",
        (2, _) => "nd",
        (3, _) => "rd",
        _ => "th",
    };
    format!("{n}{suffix}")
}

/// `report.html`.
pub fn render(report: &Report) -> String {
    let mut s = head(&format!("blendsim report: {}", report.scene));
    s.push_str("<section id=\"numbers\">\n");
    s.push_str(&markdown_to_html(&super::markdown::render(report)));
    s.push_str("</section>\n<section id=\"plots\">\n<h2>Plots</h2>\n");
    let (method, why) = (&report.solver.method, escape(&report.solver.stop_reason));
    match report.solver.energy[..] {
        [] => _ = writeln!(s, "<p>No plot of W: {method} does not iterate ({why}).</p>"),
        [w] => _ = writeln!(s, "<p>No plot of W: {method} does not iterate (W = {w:.4e}; {why}).</p>"),
        _ => {}
    }
    for (svg, caption) in plots(report) {
        let _ = writeln!(s, "<figure>{svg}<figcaption>{}</figcaption></figure>", escape(&caption));
    }
    s.push_str("</section>\n");
    if let Some(p) = &report.player {
        s.push_str(&player_section(p, report));
    }
    s.push_str("</body>\n</html>\n");
    s
}

/// The sorter of `summary.html`: a click on a sortable header orders the rows by that column
/// (numbers as numbers, empty last), a second click reverses.
const SORT_JS: &str = "for(const th of document.querySelectorAll('th[data-sort]')){th.addEventListener('click',()=>{\
const table=th.closest('table'),body=table.tBodies[0],k=th.cellIndex,dir=th.dataset.dir==='asc'?-1:1;\
for(const h of table.querySelectorAll('th'))delete h.dataset.dir;th.dataset.dir=dir>0?'asc':'desc';\
const key=r=>{const t=r.cells[k].dataset.value??r.cells[k].textContent;const x=parseFloat(t);return t===''?null:(isNaN(x)?t:x)};\
const rows=[...body.rows].sort((a,b)=>{const x=key(a),y=key(b);if(x===null)return 1;if(y===null)return -1;\
return (typeof x==='number'&&typeof y==='number'?x-y:String(x).localeCompare(String(y)))*dir});\
for(const r of rows)body.appendChild(r)})}\n";

/// `summary.html`: the summary's rows (`columns` and `rows` as in `summary.csv`), each bake's
/// name linking to its `report.html` (`links`, relative to the summary's folder), sortable by
/// the `sortable` columns.
pub fn summary(columns: &[&str], rows: &[Vec<String>], links: &[String], sortable: &[&str]) -> String {
    let mut s = head("blendsim batch summary");
    let _ = writeln!(
        s,
        "<h1>blendsim batch summary: {} bakes</h1>\n<p>error: against the cache for cache bakes (relative to its bounding-box diagonal), else blendshape vs full-frame. Click an underlined header to sort by it.</p>",
        rows.len()
    );
    s.push_str("<table id=\"summary\">\n<thead><tr>");
    for c in columns {
        if sortable.contains(c) {
            let _ = write!(s, "<th data-sort=\"{c}\">{c}</th>");
        } else {
            let _ = write!(s, "<th>{c}</th>");
        }
    }
    s.push_str("</tr></thead>\n<tbody>\n");
    for (row, link) in rows.iter().zip(links) {
        s.push_str("<tr>");
        for (k, cell) in row.iter().enumerate() {
            if k == 0 {
                let _ = write!(s, "<td><a href=\"{}\">{}</a></td>", escape(link), escape(cell));
            } else if columns[k] == "warnings" {
                // Sorted by how many.
                let n = cell.split_whitespace().count();
                let _ = write!(s, "<td data-value=\"{n}\">{}</td>", escape(cell));
            } else {
                let _ = write!(s, "<td>{}</td>", escape(cell));
            }
        }
        s.push_str("</tr>\n");
    }
    let _ = write!(s, "</tbody>\n</table>\n<script>\n{SORT_JS}</script>\n</body>\n</html>\n");
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_as_the_rfc_says() {
        assert_eq!(base64(b""), "");
        assert_eq!(base64(b"f"), "Zg==");
        assert_eq!(base64(b"fo"), "Zm8=");
        assert_eq!(base64(b"foobar"), "Zm9vYmFy");
    }

    #[test]
    fn markdown_tables_become_html() {
        let html = markdown_to_html("# t\n\n| a | b |\n|---|---:|\n| 1 | <2> |\n");
        assert!(html.contains("<h1>t</h1>") && html.contains("<td class=\"num\">&lt;2&gt;</td>"));
        assert_eq!(ordinal(2), "2nd");
        assert_eq!(ordinal(11), "11th");
    }
}
